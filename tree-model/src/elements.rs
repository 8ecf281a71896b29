//! Validation of the elements a model has besides its tree: constraints, springs, dampers.
//! Every problem names the element and the field at fault.

use std::collections::HashMap;

use crate::error::{Problem, Section, Site};
use crate::model::{Constraint, ConstraintKind, Damper, Parameter, Spring, SpringKind, Variable};
use crate::spec::{ConstraintSpec, ModelSpec, ParameterSpec};

/// Collects element problems into the validator's list.
struct Report<'a> {
    problems: &'a mut Vec<Problem>,
    section: Section,
    index: usize,
}

impl Report<'_> {
    fn at(&mut self, field: Option<&'static str>, message: String) {
        self.problems.push(Problem {
            site: Site::Element {
                section: self.section,
                index: self.index,
                field,
            },
            message,
            line: None,
        });
    }
}

/// The two frames an element attaches to, by name.
fn two_frames(
    names: &[String],
    what: &str,
    index_of: &HashMap<&str, usize>,
    report: &mut Report,
) -> Option<[usize; 2]> {
    if names.len() != 2 {
        report.at(
            Some("frames"),
            format!(
                "{what}: `frames` must name exactly two frames, found {}",
                names.len()
            ),
        );
        return None;
    }
    let mut out = [0; 2];
    let mut ok = true;
    for (slot, name) in out.iter_mut().zip(names) {
        match index_of.get(name.as_str()) {
            Some(&k) => *slot = k,
            None => {
                report.at(Some("frames"), format!("{what}: unknown frame `{name}`"));
                ok = false;
            }
        }
    }
    if ok && out[0] == out[1] {
        report.at(
            Some("frames"),
            format!("{what}: connects frame `{}` to itself", names[0]),
        );
        ok = false;
    }
    ok.then_some(out)
}

/// A number that must be finite and not negative.
fn non_negative(x: f64, what: &str, field: &'static str, report: &mut Report) {
    if !x.is_finite() || x < 0.0 {
        report.at(
            Some(field),
            format!("{what}: {field} {x} must be finite and not negative"),
        );
    }
}

/// Checks and resolves every constraint, spring and damper.
pub(crate) fn validate_elements(
    spec: &ModelSpec,
    index_of: &HashMap<&str, usize>,
    var_index: &HashMap<&str, usize>,
    variables: &[Variable],
    problems: &mut Vec<Problem>,
) -> (Vec<Constraint>, Vec<Spring>, Vec<Damper>) {
    let constraints = constraints_of(spec, index_of, var_index, problems);
    let springs = springs_of(spec, index_of, var_index, variables, problems);
    let dampers = dampers_of(spec, index_of, problems);
    (constraints, springs, dampers)
}

/// The constraints: unique names, two frames each, and the fields of their kind only.
fn constraints_of(
    spec: &ModelSpec,
    index_of: &HashMap<&str, usize>,
    var_index: &HashMap<&str, usize>,
    problems: &mut Vec<Problem>,
) -> Vec<Constraint> {
    let mut constraints = Vec::new();
    let mut names: HashMap<String, usize> = HashMap::new();
    for (index, c) in spec.constraints.iter().enumerate() {
        let report = &mut Report {
            problems,
            section: Section::Constraint,
            index,
        };
        let name = c
            .name
            .clone()
            .unwrap_or_else(|| format!("constraint{}", index + 1));
        let what = format!("constraint `{name}`");
        if let Some(first) = names.insert(name.clone(), index) {
            report.at(
                Some("name"),
                format!(
                    "duplicate constraint name `{name}` (constraints {} and {} of the list)",
                    first + 1,
                    index + 1
                ),
            );
        }
        let frames = two_frames(&c.frames, &what, index_of, report);
        let Some(kind) = constraint_kind(c, &what, var_index, report) else {
            continue;
        };
        if let Some(frames) = frames {
            constraints.push(Constraint { name, kind, frames });
        }
    }
    constraints
}

/// A constraint's kind with its own fields checked (a field of another kind is refused);
/// `None` for an unknown kind.
fn constraint_kind(
    c: &ConstraintSpec,
    what: &str,
    var_index: &HashMap<&str, usize>,
    report: &mut Report,
) -> Option<ConstraintKind> {
    let foreign = |field: &'static str, given: bool, report: &mut Report| {
        if given {
            report.at(
                Some(field),
                format!(
                    "{what}: `{field}` does not belong to a {} constraint",
                    c.kind
                ),
            );
        }
    };
    Some(match c.kind.as_str() {
        "distance" => {
            foreign("normal", c.normal.is_some(), report);
            foreign("axes", c.axes.is_some(), report);
            let length = match &c.length {
                None => {
                    report.at(
                        None,
                        format!(
                            "{what}: a distance constraint needs `length` (a number or a variable)"
                        ),
                    );
                    Parameter::Constant(0.0)
                }
                Some(ParameterSpec::Constant(x)) => {
                    non_negative(*x, what, "length", report);
                    Parameter::Constant(*x)
                }
                Some(ParameterSpec::Variable(v)) => match var_index.get(v.as_str()) {
                    Some(&i) => Parameter::Variable(i),
                    // Reported where frame-less variables are created.
                    None => Parameter::Constant(0.0),
                },
            };
            ConstraintKind::Distance { length }
        }
        "plane" => {
            foreign("slack", c.slack.is_some(), report);
            foreign("length", c.length.is_some(), report);
            foreign("axes", c.axes.is_some(), report);
            let normal = match c.normal {
                None => {
                    report.at(
                    None,
                    format!("{what}: a plane constraint needs `normal` (three numbers in frame a's axes)"),
                );
                    [0.0, 0.0, 1.0]
                }
                Some(n) => {
                    let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    if !(norm.is_finite() && norm > 0.0) {
                        report.at(
                            Some("normal"),
                            format!(
                                "{what}: normal [{}, {}, {}] must be finite and not zero",
                                n[0], n[1], n[2]
                            ),
                        );
                        [0.0, 0.0, 1.0]
                    } else {
                        n.map(|x| x / norm)
                    }
                }
            };
            ConstraintKind::Plane { normal }
        }
        "point" => {
            foreign("slack", c.slack.is_some(), report);
            foreign("length", c.length.is_some(), report);
            foreign("normal", c.normal.is_some(), report);
            let text = c.axes.as_deref().unwrap_or("xyz");
            let mut axes = Vec::new();
            for ch in text.chars() {
                match "xyz".find(ch) {
                    Some(a) if !axes.contains(&a) => axes.push(a),
                    _ => {
                        axes.clear();
                        break;
                    }
                }
            }
            if axes.is_empty() {
                report.at(
                    Some("axes"),
                    format!("{what}: axes `{text}` must list some of x, y, z, each once"),
                );
            }
            ConstraintKind::Point { axes }
        }
        other => {
            report.at(
                Some("kind"),
                format!("{what}: unknown kind `{other}`: expected distance, plane or point"),
            );
            return None;
        }
    })
}

/// The springs: between two frames or on one dynamic variable, stiffness and rest checked.
fn springs_of(
    spec: &ModelSpec,
    index_of: &HashMap<&str, usize>,
    var_index: &HashMap<&str, usize>,
    variables: &[Variable],
    problems: &mut Vec<Problem>,
) -> Vec<Spring> {
    let mut springs = Vec::new();
    for (index, s) in spec.springs.iter().enumerate() {
        let report = &mut Report {
            problems,
            section: Section::Spring,
            index,
        };
        let what = format!("spring {}", index + 1);
        let stiffness = s.stiffness.unwrap_or_else(|| {
            report.at(None, format!("{what}: `stiffness` is missing"));
            0.0
        });
        non_negative(stiffness, &what, "stiffness", report);
        let rest = s.rest.unwrap_or(0.0);
        let kind = match (&s.frames, &s.variable) {
            (Some(frames), None) => {
                non_negative(rest, &what, "rest", report);
                two_frames(frames, &what, index_of, report).map(SpringKind::Frames)
            }
            (None, Some(v)) => {
                if !rest.is_finite() {
                    report.at(Some("rest"), format!("{what}: rest {rest} is not finite"));
                }
                match var_index.get(v.as_str()) {
                    None => {
                        report.at(Some("variable"), format!("{what}: unknown variable `{v}`"));
                        None
                    }
                    Some(&i) if variables[i].is_kinematic() => {
                        report.at(
                            Some("variable"),
                            format!("{what}: variable `{v}` is kinematic; a spring on a prescribed variable does nothing"),
                        );
                        None
                    }
                    Some(&i) => Some(SpringKind::Variable(i)),
                }
            }
            _ => {
                report.at(
                    None,
                    format!("{what}: give either `frames` (two frames) or `variable`, not both or neither"),
                );
                None
            }
        };
        if let Some(kind) = kind {
            springs.push(Spring {
                kind,
                stiffness,
                rest,
            });
        }
    }
    springs
}

/// The dampers: between two frames, damping checked.
fn dampers_of(
    spec: &ModelSpec,
    index_of: &HashMap<&str, usize>,
    problems: &mut Vec<Problem>,
) -> Vec<Damper> {
    let mut dampers = Vec::new();
    for (index, d) in spec.dampers.iter().enumerate() {
        let report = &mut Report {
            problems,
            section: Section::Damper,
            index,
        };
        let what = format!("damper {}", index + 1);
        let damping = d.damping.unwrap_or_else(|| {
            report.at(None, format!("{what}: `damping` is missing"));
            0.0
        });
        non_negative(damping, &what, "damping", report);
        if let Some(frames) = two_frames(&d.frames, &what, index_of, report) {
            dampers.push(Damper { frames, damping });
        }
    }
    dampers
}
