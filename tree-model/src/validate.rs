//! Validation: turn a [`ModelSpec`] into a [`Model`], collecting every problem before
//! failing (each names the frame or variable at fault).

use std::collections::HashMap;

use crate::error::{FrameField, Problem, Site};
use crate::model::{Frame, Joint, Mass, Model, Variable, DEFAULT_GRAVITY};
use crate::primitive::{PrimitiveKind, Value};
use crate::spec::ModelSpec;

/// Collects problems; `finish` fails if there are any.
struct Problems(Vec<Problem>);

impl Problems {
    fn push(&mut self, site: Site, message: String) {
        self.0.push(Problem {
            site,
            message,
            line: None,
        });
    }
    fn frame(&mut self, index: usize, field: FrameField, message: String) {
        self.push(Site::Frame { index, field }, message);
    }
}

/// Validates a model specification. On failure, every problem found is returned.
pub fn validate(spec: &ModelSpec) -> Result<Model, Vec<Problem>> {
    let mut errs = Problems(Vec::new());

    let gravity = spec.gravity.unwrap_or(DEFAULT_GRAVITY);
    if gravity.iter().any(|g| !g.is_finite()) {
        errs.push(Site::Model, "gravity must be three finite numbers".into());
    }

    // Frame names: unique, not "world".
    let mut index_of: HashMap<&str, usize> = HashMap::new();
    for (k, f) in spec.frames.iter().enumerate() {
        if f.name.is_empty() || f.name == "world" {
            errs.frame(
                k,
                FrameField::Name,
                format!("frame name `{}` is reserved or empty", f.name),
            );
        } else if let Some(&first) = index_of.get(f.name.as_str()) {
            errs.frame(
                k,
                FrameField::Name,
                format!(
                    "duplicate frame name `{}` (frame {} and frame {} of the list)",
                    f.name,
                    first + 1,
                    k + 1
                ),
            );
        } else {
            index_of.insert(&f.name, k);
        }
    }

    let mut frames = Vec::with_capacity(spec.frames.len());
    let mut variables: Vec<Variable> = Vec::new();
    let mut var_index: HashMap<&str, usize> = HashMap::new();
    for (k, f) in spec.frames.iter().enumerate() {
        let parent = match f.parent.as_deref() {
            None | Some("world") => None,
            Some(p) => match index_of.get(p) {
                Some(&pi) if pi < k => Some(pi),
                Some(&pi) if pi == k => {
                    errs.frame(
                        k,
                        FrameField::Parent,
                        format!("frame `{}` is its own parent", f.name),
                    );
                    None
                }
                Some(_) => {
                    errs.frame(
                        k,
                        FrameField::Parent,
                        format!(
                            "frame `{}`: parent `{p}` is listed after its child; list every parent before its children",
                            f.name
                        ),
                    );
                    None
                }
                None => {
                    errs.frame(
                        k,
                        FrameField::Parent,
                        format!("frame `{}` has unknown parent `{p}`", f.name),
                    );
                    None
                }
            },
        };

        let (primitive, joint) = match f.primitives.as_slice() {
            [] => {
                errs.frame(
                    k,
                    FrameField::Whole,
                    format!(
                        "frame `{}` has no transform: give exactly one of tx ty tz rx ry rz",
                        f.name
                    ),
                );
                (PrimitiveKind::Tx, Joint::Constant(0.0))
            }
            [p] => {
                let joint = match &p.value {
                    Value::Constant(x) => {
                        if !x.is_finite() {
                            errs.frame(
                                k,
                                FrameField::Primitive,
                                format!("frame `{}`: {} value {x} is not finite", f.name, p.kind),
                            );
                        }
                        Joint::Constant(*x)
                    }
                    Value::Variable(name) => match var_index.get(name.as_str()) {
                        Some(&i) => {
                            errs.frame(
                                k,
                                FrameField::Primitive,
                                format!(
                                    "variable `{name}` drives frames `{}` and `{}`: a variable drives exactly one transform",
                                    spec.frames[variables[i].frame].name, f.name
                                ),
                            );
                            Joint::Variable(i)
                        }
                        None => {
                            let i = variables.len();
                            var_index.insert(name, i);
                            variables.push(Variable {
                                name: name.clone(),
                                frame: k,
                                q0: 0.0,
                                dq0: 0.0,
                                damping: 0.0,
                                kinematic: false,
                            });
                            Joint::Variable(i)
                        }
                    },
                };
                (p.kind, joint)
            }
            several => {
                let kinds: Vec<&str> = several.iter().map(|p| p.kind.keyword()).collect();
                errs.frame(
                    k,
                    FrameField::Primitive,
                    format!(
                        "frame `{}` has several transforms ({}): give exactly one; chain frames for more",
                        f.name,
                        kinds.join(", ")
                    ),
                );
                (several[0].kind, Joint::Constant(0.0))
            }
        };

        let mass = mass_of(k, f.name.as_str(), f.mass, f.inertia, &mut errs);
        frames.push(Frame {
            name: f.name.clone(),
            parent,
            primitive,
            joint,
            mass,
        });
    }

    // Per-variable settings.
    for v in &spec.variables {
        let site = || Site::VariableSettings {
            name: v.name.clone(),
        };
        let Some(&i) = var_index.get(v.name.as_str()) else {
            errs.push(
                site(),
                format!(
                    "settings for variable `{}`, which drives no transform",
                    v.name
                ),
            );
            continue;
        };
        for (what, value) in [("q0", v.q0), ("dq0", v.dq0), ("damping", v.damping)] {
            if value.is_some_and(|x| !x.is_finite()) {
                errs.push(
                    site(),
                    format!("variable `{}`: {what} is not finite", v.name),
                );
            }
        }
        if v.damping.is_some_and(|c| c < 0.0) {
            errs.push(
                site(),
                format!("variable `{}`: damping must not be negative", v.name),
            );
        }
        if v.kinematic == Some(true) {
            errs.push(
                site(),
                format!(
                    "variable `{}`: kinematic (prescribed) variables are not supported yet",
                    v.name
                ),
            );
        }
        let var = &mut variables[i];
        var.q0 = v.q0.unwrap_or(0.0);
        var.dq0 = v.dq0.unwrap_or(0.0);
        var.damping = v.damping.unwrap_or(0.0);
        var.kinematic = v.kinematic.unwrap_or(false);
    }

    if variables.is_empty() && !spec.frames.is_empty() {
        errs.push(
            Site::Model,
            "model has no configuration variables: drive at least one transform by a named variable".into(),
        );
    } else if spec.frames.is_empty() {
        errs.push(Site::Model, "model has no frames".into());
    }

    if errs.0.is_empty() {
        let model = Model {
            name: spec.name.clone(),
            gravity,
            frames,
            variables,
        };
        for (i, v) in model.variables.iter().enumerate() {
            if !variable_moves_mass(&model, i) {
                errs.frame(
                    v.frame,
                    FrameField::Primitive,
                    format!(
                        "variable `{}` moves no mass: nothing at or below frame `{}` has mass or inertia that it moves (its mass-matrix column would be zero)",
                        v.name, model.frames[v.frame].name
                    ),
                );
            }
        }
        if errs.0.is_empty() {
            return Ok(model);
        }
    }
    Err(errs.0)
}

fn mass_of(
    k: usize,
    name: &str,
    mass: Option<f64>,
    inertia: Option<[f64; 3]>,
    errs: &mut Problems,
) -> Option<Mass> {
    if mass.is_none() && inertia.is_none() {
        return None;
    }
    let m = mass.unwrap_or(0.0);
    let inertia = inertia.unwrap_or([0.0; 3]);
    if !m.is_finite() || m < 0.0 {
        errs.frame(
            k,
            FrameField::Mass,
            format!("frame `{name}`: mass {m} must be finite and not negative"),
        );
    }
    if inertia.iter().any(|i| !i.is_finite() || *i < 0.0) {
        errs.frame(
            k,
            FrameField::Inertia,
            format!(
                "frame `{name}`: inertia [{}, {}, {}] must be finite and not negative",
                inertia[0], inertia[1], inertia[2]
            ),
        );
    }
    Some(Mass { mass: m, inertia })
}

/// Whether variable `i` moves some mass. A translation moves any mass below it; a rotation
/// moves a body with inertia, or a mass reached through some translation. (A mass exactly on
/// the rotation axis slips through; the runtime then reports a singular mass matrix.)
fn variable_moves_mass(model: &Model, i: usize) -> bool {
    let f = model.variables[i].frame;
    let rotation = model.frames[f].primitive.is_rotation();
    // offset[k]: whether the path from f down to k contains a non-trivial translation.
    let mut offset = vec![false; model.frames.len()];
    let mut inside = vec![false; model.frames.len()];
    for k in f..model.frames.len() {
        let frame = &model.frames[k];
        if k == f {
            inside[k] = true;
        } else if let Some(p) = frame.parent.filter(|&p| inside[p]) {
            inside[k] = true;
            let translates = !frame.primitive.is_rotation()
                && !matches!(frame.joint, Joint::Constant(x) if x == 0.0);
            offset[k] = offset[p] || translates;
        } else {
            continue;
        }
        if let Some(m) = frame.mass {
            let moved = if !rotation {
                m.is_nonzero()
            } else {
                m.inertia.iter().any(|&x| x > 0.0) || (offset[k] && m.mass > 0.0)
            };
            if moved {
                return true;
            }
        }
    }
    false
}
