//! Validation: turn a [`ModelSpec`] into a [`Model`], collecting every problem before
//! failing (each names the frame or variable at fault).

use std::collections::HashMap;

use crate::error::{FrameField, Problem, Section, Site};
use crate::model::{
    Frame, Input, Joint, Mass, Mimic, Model, SpringKind, Variable, DEFAULT_GRAVITY,
};
use crate::motion::{CubicSpline, Motion};
use crate::primitive::{MimicSpec, PrimitiveKind, Value};
use crate::spec::{FrameSpec, ModelSpec, ParameterSpec, VariableSpec};

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
    fn element(&mut self, index: usize, field: &'static str, message: String) {
        self.push(
            Site::Element {
                section: crate::error::Section::Constraint,
                index,
                field: Some(field),
            },
            message,
        );
    }
}

/// Validates a model specification. On failure, every problem found is returned.
pub fn validate(spec: &ModelSpec) -> Result<Model, Vec<Problem>> {
    let mut errs = Problems(Vec::new());
    let gravity = spec.gravity.unwrap_or(DEFAULT_GRAVITY);
    if gravity.iter().any(|g| !g.is_finite()) {
        errs.push(
            Site::Gravity,
            format!(
                "gravity must be three finite numbers, got [{}, {}, {}]",
                crate::Given(gravity[0]),
                crate::Given(gravity[1]),
                crate::Given(gravity[2])
            ),
        );
    }
    let index_of = frame_names(spec, &mut errs);
    let mut vars = Variables::default();
    let frames: Vec<Frame> = (0..spec.frames.len())
        .map(|k| {
            let f = &spec.frames[k];
            let parent = parent_of(k, f, &index_of, &mut errs);
            let (primitive, joint) = joint_of(k, spec, &mut vars, &mut errs);
            let mass = mass_of(k, f, &mut errs);
            Frame {
                name: f.name.clone(),
                parent,
                primitive,
                joint,
                mass,
            }
        })
        .collect();
    let mut frames = frames;
    resolve_mimics(spec, &mut frames, &vars, &mut errs);
    check_rigid_bodies(&frames, spec, &mut errs);
    constraint_length_variables(spec, &mut vars, &mut errs);
    for v in &spec.variables {
        apply_settings(v, &mut vars, &mut errs);
    }
    check_variables(spec, &vars.list, &mut errs);
    let (constraints, springs, dampers) =
        crate::elements::validate_elements(spec, &index_of, &vars.index, &vars.list, &mut errs.0);
    let inputs = validate_inputs(spec, &vars.index, &vars.list, &mut errs);
    let (ground, spheres) =
        crate::contact::validate_contacts(&spec.contacts, &index_of, &mut errs.0);
    if !errs.0.is_empty() {
        return Err(errs.0);
    }
    // Every constraint validated: one per entry, in order. The slack ones are strings.
    let (strings, constraints): (Vec<_>, Vec<_>) = constraints
        .into_iter()
        .zip(&spec.constraints)
        .partition(|(_, c)| c.slack == Some(true));
    let model = Model {
        name: spec.name.clone(),
        gravity,
        frames,
        variables: vars.list,
        constraints: constraints.into_iter().map(|(c, _)| c).collect(),
        springs,
        dampers,
        inputs,
        contacts: crate::contact::Contacts {
            enforce_limits: spec.contacts.enforce_limits.unwrap_or(true),
            ground,
            spheres,
            strings: strings.into_iter().map(|(c, _)| c).collect(),
        },
    };
    check_directions(&model, &mut errs);
    check_moves_mass(&model, &mut errs);
    check_totals(&model, &mut errs);
    match errs.0.is_empty() {
        true => Ok(model),
        false => Err(errs.0),
    }
}

/// The variables found so far, in order, and their indices by name.
#[derive(Default)]
struct Variables<'a> {
    list: Vec<Variable>,
    index: HashMap<&'a str, usize>,
}

/// Frame names: unique, not "world"; each name's index.
fn frame_names<'a>(spec: &'a ModelSpec, errs: &mut Problems) -> HashMap<&'a str, usize> {
    let mut index_of: HashMap<&str, usize> = HashMap::new();
    for (k, f) in spec.frames.iter().enumerate() {
        if !name_ok(&f.name) || f.name == "world" {
            errs.frame(
                k,
                FrameField::Name,
                format!(
                    "frame name `{}` is reserved, empty or holds a control character",
                    f.name.escape_debug()
                ),
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

    index_of
}

/// Frame `k`'s parent: the world, or a frame listed before it.
fn parent_of(
    k: usize,
    f: &FrameSpec,
    index_of: &HashMap<&str, usize>,
    errs: &mut Problems,
) -> Option<usize> {
    match f.parent.as_deref() {
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
    }
}

/// Frame `k`'s one primitive and what drives it: a constant, or a variable (created by the
/// first frame it drives).
fn joint_of<'a>(
    k: usize,
    spec: &'a ModelSpec,
    vars: &mut Variables<'a>,
    errs: &mut Problems,
) -> (PrimitiveKind, Joint) {
    let f = &spec.frames[k];
    match f.primitives.as_slice() {
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
                // The variable it follows may drive a frame listed later: resolved after all
                // frames ([`resolve_mimics`]).
                Value::Mimic(m) => Joint::Mimic(Mimic {
                    variable: usize::MAX,
                    multiplier: m.multiplier,
                    offset: m.offset,
                    damping: m.damping,
                }),
                Value::Variable(name) if !name_ok(name) => {
                    errs.frame(
                        k,
                        FrameField::Primitive,
                        format!(
                            "frame `{}`: variable name `{}` is empty or holds a control character",
                            f.name,
                            name.escape_debug()
                        ),
                    );
                    Joint::Constant(0.0)
                }
                Value::Variable(name) => match vars.index.get(name.as_str()) {
                    Some(&i) => {
                        errs.frame(
                            k,
                            FrameField::Primitive,
                            format!(
                                "variable `{name}` drives frames `{}` and `{}`: a variable drives exactly one transform",
                                vars.list[i].frame.map_or("?", |k| spec.frames[k].name.as_str()),
                                f.name
                            ),
                        );
                        Joint::Variable(i)
                    }
                    None => {
                        let i = vars.list.len();
                        vars.index.insert(name, i);
                        vars.list.push(Variable {
                            name: name.clone(),
                            frame: Some(k),
                            q0: 0.0,
                            dq0: 0.0,
                            damping: 0.0,
                            motion: None,
                            limits: None,
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
    }
}

/// Each mimic frame's variable, once every frame has made its own: a variable that drives a
/// frame (a mimic of a mimic names the variable at the chain's head), with a finite
/// multiplier and offset and a finite damping not negative.
fn resolve_mimics(spec: &ModelSpec, frames: &mut [Frame], vars: &Variables, errs: &mut Problems) {
    for (k, f) in spec.frames.iter().enumerate() {
        let [crate::primitive::Primitive {
            value: Value::Mimic(m),
            ..
        }] = f.primitives.as_slice()
        else {
            continue;
        };
        let Joint::Mimic(joint) = &mut frames[k].joint else {
            continue;
        };
        let name = &f.name;
        let MimicSpec {
            variable,
            multiplier,
            offset,
            damping,
        } = m;
        match vars.index.get(variable.as_str()) {
            Some(&i) => joint.variable = i,
            None => {
                let known: Vec<&str> = vars.index.keys().copied().collect();
                let hint = crate::suggest::nearest(variable, &known);
                errs.frame(
                    k,
                    FrameField::Primitive,
                    format!(
                        "frame `{name}` mimics variable `{}`, which drives no frame: a mimic follows a variable that drives a transform of its own{hint}",
                        variable.escape_debug()
                    ),
                );
                joint.variable = 0;
            }
        }
        for (what, x) in [("multiplier", multiplier), ("offset", offset)] {
            if !x.is_finite() {
                errs.frame(
                    k,
                    FrameField::Primitive,
                    format!(
                        "frame `{name}`: the mimic's {what} {} is not finite",
                        crate::Given(*x)
                    ),
                );
            }
        }
        if !(damping.is_finite() && *damping >= 0.0) {
            errs.frame(
                k,
                FrameField::Primitive,
                format!(
                    "frame `{name}`: the mimic's damping {} must be a finite number, not negative",
                    crate::Given(*damping)
                ),
            );
        }
    }
}

/// Variables that only set a constraint's length come after the frames' own, in
/// constraint order.
fn constraint_length_variables<'a>(
    spec: &'a ModelSpec,
    vars: &mut Variables<'a>,
    errs: &mut Problems,
) {
    let settings: HashMap<&str, &VariableSpec> = spec
        .variables
        .iter()
        .map(|v| (v.name.as_str(), v))
        .collect();
    for (c, con) in spec.constraints.iter().enumerate() {
        if let Some(ParameterSpec::Variable(name)) = &con.length {
            if vars.index.contains_key(name.as_str()) {
                continue;
            }
            if settings.contains_key(name.as_str()) {
                vars.index.insert(name, vars.list.len());
                vars.list.push(Variable {
                    name: name.clone(),
                    frame: None,
                    q0: 0.0,
                    dq0: 0.0,
                    damping: 0.0,
                    motion: None,
                    limits: None,
                });
            } else {
                errs.element(
                    c,
                    "length",
                    format!("constraint length `{name}` is not a variable: it drives no frame and has no settings (declare it kinematic)"),
                );
            }
        }
    }
}

/// One variable's settings, checked and applied: start, damping, limits, and for a
/// kinematic variable its prescribed motion (where it then starts).
fn apply_settings(v: &VariableSpec, vars: &mut Variables, errs: &mut Problems) {
    let site = || Site::VariableSettings {
        name: v.name.clone(),
    };
    let Some(&i) = vars.index.get(v.name.as_str()) else {
        errs.push(
            site(),
            format!(
                "settings for variable `{}`, which drives no transform and sets no constraint length",
                v.name
            ),
        );
        return;
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
    if let Some([lo, hi]) = v.limits {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            errs.push(
                site(),
                format!(
                    "variable `{}`: limits [{lo}, {hi}] must be finite with lower ≤ upper",
                    v.name
                ),
            );
        }
    }
    let kinematic = v.kinematic.unwrap_or(false);
    let var = &mut vars.list[i];
    var.limits = v.limits;
    var.q0 = v.q0.unwrap_or(0.0);
    var.dq0 = v.dq0.unwrap_or(0.0);
    var.damping = v.damping.unwrap_or(0.0);
    if !kinematic {
        if v.motion.is_some() || v.samples.is_some() {
            errs.push(
                site(),
                format!(
                    "variable `{}` has a prescribed motion but is dynamic: add `kinematic = true`, or remove the motion",
                    v.name
                ),
            );
        }
        return;
    }
    if v.damping.is_some_and(|c| c != 0.0) {
        errs.push(
            site(),
            format!(
                "variable `{}` is kinematic: damping has no effect on a prescribed variable",
                v.name
            ),
        );
    }
    var.motion = prescribed_motion(v, var, errs);
    if let Some(m) = &var.motion {
        // A prescribed variable starts where its motion does.
        [var.q0, var.dq0, _] = m.at(0.0);
    }
}

/// A kinematic variable's motion: a sine, a spline through samples, or (neither given)
/// `q0 + dq0·t`.
fn prescribed_motion(v: &VariableSpec, var: &Variable, errs: &mut Problems) -> Option<Motion> {
    let site = || Site::VariableSettings {
        name: v.name.clone(),
    };
    match (&v.motion, &v.samples) {
        (Some(_), Some(_)) => {
            errs.push(
                site(),
                format!(
                    "variable `{}`: give `motion` or `samples`, not both",
                    v.name
                ),
            );
            None
        }
        (Some(m), None) => {
            let sine = [m.offset, m.amplitude, m.frequency, m.phase].map(|x| x.unwrap_or(0.0));
            if sine.iter().any(|x| !x.is_finite()) {
                errs.push(
                    site(),
                    format!("variable `{}`: motion has a non-finite number", v.name),
                );
            } else if sine[2] < 0.0 {
                errs.push(
                    site(),
                    format!(
                        "variable `{}`: motion frequency must not be negative",
                        v.name
                    ),
                );
            } else {
                // q̈ peaks at a·(2πf)²: it must be a number, or every step overflows.
                let w = 2.0 * std::f64::consts::PI * sine[2];
                if !(sine[1] * w * w).is_finite() || !(sine[0].abs() + sine[1].abs()).is_finite() {
                    errs.push(
                        site(),
                        format!(
                            "variable `{}`: motion with amplitude {} and frequency {} has an acceleration a·(2πf)² that overflows",
                            v.name, short(sine[1]), short(sine[2])
                        ),
                    );
                }
            }
            Some(Motion::Sine {
                offset: sine[0],
                amplitude: sine[1],
                frequency: sine[2],
                phase: sine[3],
            })
        }
        (None, Some(samples)) => match CubicSpline::new(samples) {
            Some(spline) => Some(Motion::Spline(spline)),
            None => {
                errs.push(
                    site(),
                    format!(
                        "variable `{}`: samples must be at least two finite [t, q] pairs with t strictly increasing, and a curve through them that stays finite (samples near ±1e308 overflow between them)",
                        v.name
                    ),
                );
                None
            }
        },
        (None, None) => Some(Motion::Steady {
            q0: var.q0,
            dq0: var.dq0,
        }),
    }
}

/// A variable that sets a constraint length and drives no frame must be prescribed; a
/// model needs frames and a variable.
fn check_variables(spec: &ModelSpec, variables: &[Variable], errs: &mut Problems) {
    for v in variables {
        if v.frame.is_none() && !v.is_kinematic() {
            errs.push(
                Site::VariableSettings {
                    name: v.name.clone(),
                },
                format!(
                    "variable `{}` sets a constraint length but drives no frame: it must be kinematic",
                    v.name
                ),
            );
        }
    }

    if variables.is_empty() && !spec.frames.is_empty() {
        errs.push(
            Site::Model,
            "model has no configuration variables: drive at least one transform by a named variable".into(),
        );
    } else if spec.frames.is_empty() {
        errs.push(Site::Model, "model has no frames".into());
    }
}

/// A spring with a rest length, or a damper, between frames that coincide at the start has
/// no direction: its force is 0/0 at the first step.
fn check_directions(model: &Model, errs: &mut Problems) {
    let q0: Vec<f64> = model.variables.iter().map(|v| v.q0).collect();
    let origins = model.origins(&q0);
    let apart = |[a, b]: [usize; 2]| {
        let (pa, pb) = (origins[a], origins[b]);
        let d = [0, 1, 2].map(|k| pa[k] - pb[k]);
        let scale = pa.iter().chain(&pb).fold(0.0f64, |m, x| m.max(x.abs()));
        d.iter()
            .any(|x| x.abs() > 1e-12 * scale.max(f64::MIN_POSITIVE))
    };
    let name = |k: usize| model.frames[k].name.as_str();
    for (index, s) in model.springs.iter().enumerate() {
        if let SpringKind::Frames(fr) = s.kind {
            if s.rest != 0.0 && !apart(fr) {
                errs.push(
                    Site::Element { section: Section::Spring, index, field: Some("frames") },
                    format!(
                        "spring {}: frames `{}` and `{}` coincide at the initial configuration, where a spring of rest length {} has no direction; start them apart (or use rest = 0)",
                        index + 1, name(fr[0]), name(fr[1]), s.rest
                    ),
                );
            }
        }
    }
    for (index, d) in model.dampers.iter().enumerate() {
        if !apart(d.frames) {
            errs.push(
                Site::Element { section: Section::Damper, index, field: Some("frames") },
                format!(
                    "damper {}: frames `{}` and `{}` coincide at the initial configuration, where a damper has no direction; start them apart",
                    index + 1, name(d.frames[0]), name(d.frames[1])
                ),
            );
        }
    }
}

/// Every dynamic variable moves some mass (else its mass-matrix column is zero): through
/// its own frame or a frame that mimics it.
fn check_moves_mass(model: &Model, errs: &mut Problems) {
    // The frames each variable moves (its own, then its followers'), in one pass.
    let mut driven: Vec<Vec<usize>> = vec![Vec::new(); model.variables.len()];
    for (f, frame) in model.frames.iter().enumerate() {
        if let Some((i, factor)) = frame.joint.driver() {
            if factor != 0.0 {
                driven[i].push(f);
            }
        }
    }
    for (i, v) in model.variables.iter().enumerate() {
        if v.is_kinematic() {
            continue;
        }
        let Some(frame) = v.frame else { continue };
        if !driven[i].iter().any(|&f| frame_moves_mass(model, f)) {
            errs.frame(
                frame,
                FrameField::Primitive,
                format!(
                    "variable `{}` moves no mass: nothing at or below frame `{}` has mass or inertia that it moves (its mass-matrix column would be zero)",
                    v.name, model.frames[frame].name
                ),
            );
        }
    }
}

/// The total mass is a number, and there are no more constraint equations than dynamic
/// variables.
fn check_totals(model: &Model, errs: &mut Problems) {
    if !model.total_mass().is_finite() {
        errs.push(
            Site::Model,
            "the masses add up to more than a floating-point number holds (the total mass overflows)".into(),
        );
    }
    let dynamic = model.dynamic().len();
    let rows = model.constraint_rows();
    if rows > dynamic {
        errs.push(
            Site::Model,
            format!("the model has {rows} constraint equations but only {dynamic} dynamic variables: at most one equation per dynamic variable"),
        );
    }
}

/// The frame's body, checked: mass finite and not negative, centre of mass finite, inertia
/// three or six finite numbers forming a tensor that a real body can have (positive
/// semi-definite, principal moments obeying the triangle inequalities).
fn mass_of(k: usize, f: &FrameSpec, errs: &mut Problems) -> Option<Mass> {
    if f.mass.is_none() && f.inertia.is_none() && f.com.is_none() {
        return None;
    }
    let name = &f.name;
    let m = f.mass.unwrap_or(0.0);
    if !m.is_finite() || m < 0.0 {
        errs.frame(
            k,
            FrameField::Mass,
            format!("frame `{name}`: mass {m} must be finite and not negative"),
        );
    }
    let com = f.com.unwrap_or([0.0; 3]);
    if com.iter().any(|x| !x.is_finite()) {
        errs.frame(
            k,
            FrameField::Com,
            format!(
                "frame `{name}`: com [{}, {}, {}] must be finite",
                com[0], com[1], com[2]
            ),
        );
    }
    let written = f.inertia.clone().unwrap_or_else(|| vec![0.0; 3]);
    let shown = written
        .iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let six = match written[..] {
        [a, b, c] => [a, b, c, 0.0, 0.0, 0.0],
        [a, b, c, d, e, g] => [a, b, c, d, e, g],
        _ => {
            errs.frame(
                k,
                FrameField::Inertia,
                format!(
                    "frame `{name}`: inertia has {} numbers; give 3 (ixx, iyy, izz) or 6 (ixx, iyy, izz, ixy, ixz, iyz)",
                    written.len()
                ),
            );
            [0.0; 6]
        }
    };
    let mut body = Mass::point(m);
    body.com = com;
    body.inertia = [
        [six[0], six[3], six[4]],
        [six[3], six[1], six[5]],
        [six[4], six[5], six[2]],
    ];
    if six.iter().any(|x| !x.is_finite()) {
        errs.frame(
            k,
            FrameField::Inertia,
            format!("frame `{name}`: inertia [{shown}] must be finite"),
        );
    }
    // Whether it is a body a rigid body can have is judged with the bodies it is welded to
    // ([`check_rigid_bodies`]).
    Some(body)
}

/// Every rigid body the dynamics sees — the bodies of frames joined by constant transforms,
/// fused ([`crate::rigid`]) — is one a rigid body can have. A piece that is not physical
/// alone (a placeholder link's made-up tensor) passes when its fused body is: the dynamics
/// only ever sees the sum. The error names the piece as written, and the fused body.
fn check_rigid_bodies(frames: &[Frame], spec: &ModelSpec, errs: &mut Problems) {
    let pieces: Vec<(usize, String)> = (frames.iter().enumerate())
        .filter_map(|(k, f)| {
            let body = f.mass?;
            physical_inertia(&body.inertia, body.mass)
                .err()
                .map(|why| (k, why))
        })
        .collect();
    if pieces.is_empty() {
        return;
    }
    let ks: Vec<usize> = pieces.iter().map(|p| p.0).collect();
    let fused = crate::rigid::fused_bodies(frames, &ks);
    for ((k, why), (whole, members)) in pieces.into_iter().zip(fused) {
        let whole_why = physical_inertia(&whole.inertia, whole.mass).err();
        if members.len() > 1 && whole_why.is_none() {
            continue; // the dynamics sees only the sum, and it is physical
        }
        let shown = spec.frames[k].inertia.as_ref().map_or_else(
            || "0, 0, 0".to_string(),
            |w| {
                w.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            },
        );
        let mut message = format!("frame `{}`: inertia [{shown}] {why}", frames[k].name);
        if let (true, Some(whole_why)) = (members.len() > 1, whole_why) {
            let names: Vec<&str> = members.iter().map(|&m| frames[m].name.as_str()).collect();
            message += &format!(
                "; and the rigid body it is welded into (frames {}, fused across constant \
                 transforms, {} kg) {whole_why}",
                names.join(", "),
                crate::Rounded(whole.mass, 6)
            );
        }
        errs.frame(k, FrameField::Inertia, message);
    }
}

/// Whether a symmetric tensor is one a rigid body of `mass` can have: its principal moments
/// (the eigenvalues) are not negative and each is at most the sum of the other two — within
/// rounding of the tensor's own scale, and within `mass·(1 µm)²`, what the mass has a
/// micrometre from its centre: a tensor written as zeros with noise (iCub's `±1.4e-20`) is
/// a point mass, not an error.
fn physical_inertia(i: &[[f64; 3]; 3], mass: f64) -> Result<(), String> {
    let moments = symmetric_eigenvalues(i);
    let scale = moments.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    let slack = 1e-9 * scale + MICROMETRE * MICROMETRE * mass.abs();
    if moments.iter().any(|&x| x < -slack) {
        return Err(format!(
            "is not positive semi-definite (principal moments {}, {}, {})",
            short(moments[0]),
            short(moments[1]),
            short(moments[2])
        ));
    }
    for k in 0..3 {
        let (a, b, c) = (moments[k], moments[(k + 1) % 3], moments[(k + 2) % 3]);
        if a > b + c + slack {
            let (a, b, c) = (short(a), short(b), short(c));
            return Err(format!(
                "breaks the triangle inequality: principal moment {a} exceeds the sum of the others ({b} + {c})"
            ));
        }
    }
    Ok(())
}

/// The radius below which a body's extent is rounding, m.
const MICROMETRE: f64 = 1e-6;

/// A computed number to six significant digits, for messages.
fn short(x: f64) -> String {
    let s = format!("{x:.5e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let m = m.trim_end_matches('0').trim_end_matches('.');
            if e == "0" {
                m.to_string()
            } else {
                format!("{m}e{e}")
            }
        }
        None => s,
    }
}

/// Eigenvalues of a symmetric 3×3 matrix, in increasing order (the trigonometric solution of
/// the characteristic cubic).
fn symmetric_eigenvalues(a: &[[f64; 3]; 3]) -> [f64; 3] {
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    if p1 == 0.0 {
        let mut d = [a[0][0], a[1][1], a[2][2]];
        d.sort_by(f64::total_cmp);
        return d;
    }
    let p2 = (a[0][0] - q).powi(2) + (a[1][1] - q).powi(2) + (a[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let b = |i: usize, j: usize| (a[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [smallest, 3.0 * q - largest - smallest, largest]
}

/// Whether the transform of frame `f` moves some mass. A translation moves any mass below
/// it; a rotation moves a body with inertia, or a mass reached through some translation. (A
/// mass exactly on the rotation axis slips through; the runtime then reports a singular mass
/// matrix.)
fn frame_moves_mass(model: &Model, f: usize) -> bool {
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
            let off_axis = offset[k] || m.com != [0.0; 3];
            let moved = if !rotation {
                m.is_nonzero()
            } else {
                m.inertia.iter().flatten().any(|&x| x != 0.0) || (off_axis && m.mass > 0.0)
            };
            if moved {
                return true;
            }
        }
    }
    false
}

/// A name is usable in every output (CSV headers, `check`, JSON keys): not empty, no control
/// characters (a newline would split a CSV header).
fn name_ok(name: &str) -> bool {
    !name.is_empty() && !name.chars().any(char::is_control)
}

/// The inputs: each a unique name on one dynamic variable (not two on one variable), with
/// finite `lo ≤ hi` limits if any.
fn validate_inputs(
    spec: &ModelSpec,
    var_index: &HashMap<&str, usize>,
    variables: &[Variable],
    errs: &mut Problems,
) -> Vec<Input> {
    let mut inputs: Vec<Input> = Vec::new();
    let mut names: HashMap<&str, usize> = HashMap::new();
    for (index, u) in spec.inputs.iter().enumerate() {
        let site = |field| Site::Element {
            section: Section::Input,
            index,
            field,
        };
        let what = format!("input `{}`", u.name);
        if !name_ok(&u.name) {
            errs.push(
                site(Some("name")),
                format!(
                    "input {}: its name is empty or holds a control character",
                    index + 1
                ),
            );
        } else if let Some(first) = names.insert(&u.name, index) {
            errs.push(
                site(Some("name")),
                format!(
                    "{what} is declared twice (inputs {} and {})",
                    first + 1,
                    index + 1
                ),
            );
        }
        let variable = match u.variable.as_deref() {
            None => {
                errs.push(site(None), format!("{what}: `variable` is missing"));
                None
            }
            Some(v) => match var_index.get(v) {
                None => {
                    errs.push(
                        site(Some("variable")),
                        format!("{what}: unknown variable `{v}`"),
                    );
                    None
                }
                Some(&i) if variables[i].is_kinematic() => {
                    errs.push(
                        site(Some("variable")),
                        format!("{what}: variable `{v}` is kinematic; an input is a force on a dynamic variable"),
                    );
                    None
                }
                Some(&i) => Some(i),
            },
        };
        if let Some([lo, hi]) = u.limits {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                errs.push(
                    site(Some("limits")),
                    format!("{what}: limits [{lo}, {hi}] must be two finite numbers with lo ≤ hi"),
                );
            }
        }
        if let Some(i) = variable {
            if let Some(other) = inputs.iter().find(|x| x.variable == i) {
                errs.push(
                    site(Some("variable")),
                    format!(
                        "{what}: variable `{}` already has input `{}`; one input per variable",
                        variables[i].name, other.name
                    ),
                );
            } else {
                inputs.push(Input {
                    name: u.name.clone(),
                    variable: i,
                    limits: u.limits,
                });
            }
        }
    }
    inputs
}
