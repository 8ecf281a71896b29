//! The TOML model format (see README): parse with source spans, so that every validation
//! problem names its line.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use crate::contact::{ContactSpec, ContactsSpec, GroundSpec};
use crate::error::{FrameField, ModelError, Section, Site};
use crate::model::Model;
use crate::primitive::{MimicSpec, Primitive, PrimitiveKind, Value};
use crate::source::LineIndex;
use crate::spec::{
    ConstraintSpec, DamperSpec, FrameSpec, InputSpec, ModelSpec, ParameterSpec, SineSpec,
    SpringSpec, VariableSpec,
};
use crate::validate::validate;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    name: Option<String>,
    gravity: Option<Spanned<[f64; 3]>>,
    #[serde(default)]
    frame: Vec<Spanned<RawFrame>>,
    #[serde(default)]
    variables: BTreeMap<String, Spanned<RawVariable>>,
    #[serde(default)]
    constraint: Vec<Spanned<RawConstraint>>,
    #[serde(default)]
    spring: Vec<Spanned<RawSpring>>,
    #[serde(default)]
    damper: Vec<Spanned<RawDamper>>,
    #[serde(default)]
    input: Vec<Spanned<RawInput>>,
    enforce_limits: Option<bool>,
    ground: Option<Spanned<RawGround>>,
    #[serde(default)]
    contact: Vec<Spanned<RawContact>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGround {
    height: Option<Spanned<f64>>,
    normal: Option<Spanned<[f64; 3]>>,
    friction: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawContact {
    name: Option<Spanned<String>>,
    frame: Spanned<String>,
    radius: Option<Spanned<f64>>,
    friction: Option<Spanned<f64>>,
    collide: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInput {
    name: Spanned<String>,
    variable: Option<Spanned<String>>,
    limits: Option<Spanned<[f64; 2]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConstraint {
    name: Option<Spanned<String>>,
    kind: Spanned<String>,
    frames: Spanned<Vec<String>>,
    length: Option<Spanned<RawValue>>,
    normal: Option<Spanned<[f64; 3]>>,
    axes: Option<Spanned<String>>,
    slack: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpring {
    frames: Option<Spanned<Vec<String>>>,
    variable: Option<Spanned<String>>,
    stiffness: Option<Spanned<f64>>,
    rest: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDamper {
    frames: Spanned<Vec<String>>,
    damping: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotion {
    offset: Option<f64>,
    amplitude: Option<f64>,
    frequency: Option<f64>,
    phase: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFrame {
    name: Spanned<String>,
    parent: Option<Spanned<String>>,
    tx: Option<Spanned<RawPrimitive>>,
    ty: Option<Spanned<RawPrimitive>>,
    tz: Option<Spanned<RawPrimitive>>,
    rx: Option<Spanned<RawPrimitive>>,
    ry: Option<Spanned<RawPrimitive>>,
    rz: Option<Spanned<RawPrimitive>>,
    mass: Option<Spanned<f64>>,
    com: Option<Spanned<[f64; 3]>>,
    inertia: Option<Spanned<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawValue {
    Number(f64),
    Name(String),
}

/// A primitive's parameter: a number, a variable's name, or a mimic table
/// `{ mimic = "q", multiplier = …, offset = …, damping = … }` (read by hand, so that a
/// table's own error — an unknown key — reaches the user, which serde's untagged enums
/// replace by "did not match any variant").
enum RawPrimitive {
    Number(f64),
    Name(String),
    Mimic(RawMimic),
}

impl<'de> Deserialize<'de> for RawPrimitive {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = RawPrimitive;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number, a variable's name or a table { mimic = \"variable\", … }")
            }
            fn visit_f64<E>(self, x: f64) -> Result<RawPrimitive, E> {
                Ok(RawPrimitive::Number(x))
            }
            fn visit_i64<E>(self, x: i64) -> Result<RawPrimitive, E> {
                Ok(RawPrimitive::Number(x as f64))
            }
            fn visit_u64<E>(self, x: u64) -> Result<RawPrimitive, E> {
                Ok(RawPrimitive::Number(x as f64))
            }
            fn visit_str<E>(self, s: &str) -> Result<RawPrimitive, E> {
                Ok(RawPrimitive::Name(s.to_string()))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> Result<RawPrimitive, A::Error> {
                let d = serde::de::value::MapAccessDeserializer::new(map);
                RawMimic::deserialize(d).map(RawPrimitive::Mimic)
            }
        }
        d.deserialize_any(Visitor)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMimic {
    mimic: String,
    multiplier: Option<f64>,
    offset: Option<f64>,
    damping: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariable {
    q0: Option<f64>,
    dq0: Option<f64>,
    damping: Option<f64>,
    kinematic: Option<bool>,
    motion: Option<RawMotion>,
    /// Rows checked to be pairs below (serde would read the first two of a longer row).
    samples: Option<Spanned<Vec<Vec<f64>>>>,
    limits: Option<[f64; 2]>,
}

/// Lines of one constraint, spring or damper: the entry's first line and each field's.
#[derive(Default)]
struct ElementLines {
    whole: usize,
    fields: Vec<(&'static str, usize)>,
}

impl ElementLines {
    fn new(lines: &LineIndex, whole: std::ops::Range<usize>) -> Self {
        ElementLines {
            whole: lines.of(whole.start),
            fields: Vec::new(),
        }
    }
    fn field<T>(&mut self, lines: &LineIndex, name: &'static str, value: &Option<Spanned<T>>) {
        if let Some(v) = value {
            self.fields.push((name, lines.of(v.span().start)));
        }
    }
    fn line(&self, field: Option<&str>) -> usize {
        field
            .and_then(|f| self.fields.iter().find(|(n, _)| *n == f))
            .map_or(self.whole, |(_, l)| *l)
    }
}

/// Lines of each frame's fields, for pointing problems at the source.
struct FrameLines {
    whole: usize,
    name: usize,
    parent: Option<usize>,
    primitive: Option<usize>,
    mass: Option<usize>,
    inertia: Option<usize>,
    com: Option<usize>,
}

/// Parses and validates a model from TOML text. `source_name` (a file name) prefixes every
/// message; when the model has no `name`, it is taken from the file stem.
pub fn from_toml_str(text: &str, source_name: Option<&str>) -> Result<Model, ModelError> {
    let src = source_name.map(str::to_string);
    // One table of the text's newlines: every line below is a lookup in it.
    let line_index = LineIndex::new(text);
    let raw: RawModel = toml::from_str(text).map_err(|e| {
        let line = e.span().map(|s| line_index.of(s.start));
        let msg = e.message().trim().to_string();
        let hint = e
            .span()
            .map_or(String::new(), |s| unquoted_name_hint(text, s.start));
        ModelError::single(src.clone(), format!("TOML error: {msg}{hint}"), line)
    })?;
    check_samples(&raw, &line_index)
        .map_err(|(message, line)| ModelError::single(src.clone(), message, Some(line)))?;
    let mut lines = Lines {
        gravity: raw.gravity.as_ref().map(|g| line_index.of(g.span().start)),
        ..Lines::default()
    };
    let name = raw.name.clone().unwrap_or_else(|| {
        source_name
            .and_then(|s| Path::new(s).file_stem())
            .map_or("model".into(), |s| s.to_string_lossy().into_owned())
    });
    let spec = ModelSpec {
        name,
        gravity: raw.gravity.as_ref().map(|g| *g.get_ref()),
        frames: frames_of(&raw, &line_index, &mut lines.frames),
        variables: variables_of(&raw, &line_index, &mut lines.variables),
        constraints: constraints_of(&raw, &line_index, &mut lines.constraints),
        springs: springs_of(&raw, &line_index, &mut lines.springs),
        dampers: dampers_of(&raw, &line_index, &mut lines.dampers),
        inputs: inputs_of(&raw, &line_index, &mut lines.inputs),
        contacts: contacts_of(
            (raw.enforce_limits, raw.ground.as_ref(), &raw.contact),
            &line_index,
            &mut lines.contact,
        ),
    };
    validate(&spec).map_err(|mut problems| {
        for p in &mut problems {
            p.line = lines.of(&p.site);
        }
        ModelError {
            source_name: src.clone(),
            problems,
        }
    })
}

/// When the value at `offset` is a bare word (`rx = theta`), TOML read it as a misspelt
/// `true`/`false`/`inf`: the hint says a name is written in quotes.
fn unquoted_name_hint(text: &str, offset: usize) -> String {
    let start = text[..offset.min(text.len())]
        .rfind('\n')
        .map_or(0, |i| i + 1);
    let line = text[start..].lines().next().unwrap_or("");
    let value = line
        .split_once('=')
        .map(|(_, v)| v.split('#').next().unwrap_or("").trim());
    let Some(word) = value else {
        return String::new();
    };
    let bare = word
        .chars()
        .next()
        .is_some_and(|c| c.is_alphabetic() || c == '_')
        && word
            .chars()
            .all(|c| c.is_alphanumeric() || c == '_' || c == '-');
    if bare && !matches!(word, "true" | "false" | "inf" | "nan") {
        format!(" (a name is text in TOML: write \"{word}\" in quotes)")
    } else {
        String::new()
    }
}

/// Where each part of the model was written, for pointing problems at the source.
#[derive(Default)]
struct Lines {
    gravity: Option<usize>,
    frames: Vec<FrameLines>,
    variables: BTreeMap<String, usize>,
    constraints: Vec<ElementLines>,
    springs: Vec<ElementLines>,
    dampers: Vec<ElementLines>,
    inputs: Vec<ElementLines>,
    contact: ContactLines,
}

/// The contact tables a TOML file writes — `enforce_limits`, `[ground]`, `[[contact]]`, as a
/// model or a task file writes them; its other keys are not read.
#[derive(Deserialize)]
struct ContactTables {
    enforce_limits: Option<bool>,
    ground: Option<Spanned<RawGround>>,
    #[serde(default)]
    contact: Vec<Spanned<RawContact>>,
}

impl Model {
    /// This model with the ground, contacts and enforced limits a TOML text writes (a task
    /// file's, say: `tree_model!`'s `contacts from "tasks/solo12-stand.toml"` on a URDF
    /// robot), each mistake at its line of that text.
    pub fn with_contacts_from_toml_str(
        self,
        text: &str,
        source_name: Option<&str>,
    ) -> Result<Model, ModelError> {
        let src = source_name.map(str::to_string);
        let lines = LineIndex::new(text);
        let raw: ContactTables = toml::from_str(text).map_err(|e| toml_error(&e, &lines, &src))?;
        let written = (
            raw.enforce_limits,
            raw.ground.as_ref(),
            raw.contact.as_slice(),
        );
        with_written_contacts(self, written, &lines, &src)
    }
}

/// A TOML syntax or shape error as a model error at its line.
pub(crate) fn toml_error(
    e: &toml::de::Error,
    lines: &LineIndex,
    src: &Option<String>,
) -> ModelError {
    let line = e.span().map(|s| lines.of(s.start));
    let msg = e.message().trim().to_string();
    ModelError::single(src.clone(), format!("TOML error: {msg}"), line)
}

/// `model` with the contact tables as written (a task's or a contacts file's), each
/// mistake at its line.
pub(crate) fn with_written_contacts(
    model: Model,
    written: RawContacts,
    lines: &LineIndex,
    src: &Option<String>,
) -> Result<Model, ModelError> {
    let mut contact_lines = ContactLines::default();
    let spec = contacts_of(written, lines, &mut contact_lines);
    model.with_contacts(&spec).map_err(|mut e| {
        for p in &mut e.problems {
            p.line = contact_lines.of(&p.site);
        }
        e.source_name = src.clone();
        e
    })
}

/// Lines of the ground's and each contact's fields (a model's, or a task's additions).
#[derive(Default)]
pub(crate) struct ContactLines {
    contacts: Vec<ElementLines>,
    ground: Vec<ElementLines>,
}

impl ContactLines {
    /// The line of a problem at a contact or the ground (none elsewhere).
    pub(crate) fn of(&self, site: &Site) -> Option<usize> {
        let Site::Element {
            section,
            index,
            field,
        } = site
        else {
            return None;
        };
        let lines = match section {
            Section::Contact => &self.contacts,
            Section::Ground => &self.ground,
            _ => return None,
        };
        lines.get(*index).map(|l| l.line(*field))
    }
}

impl Lines {
    /// The line of a problem's site (none for the model as a whole).
    fn of(&self, site: &Site) -> Option<usize> {
        match site {
            Site::Model => None,
            Site::Gravity => self.gravity,
            Site::VariableSettings { name } => self.variables.get(name).copied(),
            Site::Element {
                section,
                index,
                field,
            } => {
                let lines = match section {
                    Section::Constraint => &self.constraints,
                    Section::Spring => &self.springs,
                    Section::Damper => &self.dampers,
                    Section::Input => &self.inputs,
                    Section::Contact | Section::Ground => return self.contact.of(site),
                };
                Some(lines[*index].line(*field))
            }
            Site::Frame { index, field } => {
                let l = &self.frames[*index];
                let specific = match field {
                    FrameField::Whole => None,
                    FrameField::Name => Some(l.name),
                    FrameField::Parent => l.parent,
                    FrameField::Primitive => l.primitive,
                    FrameField::Mass => l.mass,
                    FrameField::Inertia => l.inertia,
                    FrameField::Com => l.com,
                };
                Some(specific.unwrap_or(l.whole))
            }
        }
    }
}

/// The frames, with the line of each one's fields.
fn frames_of(
    raw: &RawModel,
    line_index: &LineIndex,
    lines: &mut Vec<FrameLines>,
) -> Vec<FrameSpec> {
    let mut frames = Vec::new();
    for f in &raw.frame {
        let at = |s: std::ops::Range<usize>| line_index.of(s.start);
        let rf = f.get_ref();
        let mut primitives = Vec::new();
        let mut primitive_line = None;
        for (kind, value) in [
            (PrimitiveKind::Tx, &rf.tx),
            (PrimitiveKind::Ty, &rf.ty),
            (PrimitiveKind::Tz, &rf.tz),
            (PrimitiveKind::Rx, &rf.rx),
            (PrimitiveKind::Ry, &rf.ry),
            (PrimitiveKind::Rz, &rf.rz),
        ] {
            if let Some(v) = value {
                primitive_line.get_or_insert(at(v.span()));
                let value = match v.get_ref() {
                    RawPrimitive::Number(x) => Value::Constant(*x),
                    RawPrimitive::Name(n) => Value::Variable(n.clone()),
                    RawPrimitive::Mimic(m) => Value::Mimic(MimicSpec {
                        variable: m.mimic.clone(),
                        multiplier: m.multiplier.unwrap_or(1.0),
                        offset: m.offset.unwrap_or(0.0),
                        damping: m.damping.unwrap_or(0.0),
                    }),
                };
                primitives.push(Primitive { kind, value });
            }
        }
        lines.push(FrameLines {
            whole: at(f.span()),
            name: at(rf.name.span()),
            parent: rf.parent.as_ref().map(|p| at(p.span())),
            primitive: primitive_line,
            mass: rf.mass.as_ref().map(|m| at(m.span())),
            inertia: rf.inertia.as_ref().map(|m| at(m.span())),
            com: rf.com.as_ref().map(|m| at(m.span())),
        });
        frames.push(FrameSpec {
            name: rf.name.get_ref().clone(),
            parent: rf.parent.as_ref().map(|p| p.get_ref().clone()),
            primitives,
            mass: rf.mass.as_ref().map(|m| *m.get_ref()),
            com: rf.com.as_ref().map(|m| *m.get_ref()),
            inertia: rf.inertia.as_ref().map(|m| m.get_ref().clone()),
        });
    }
    frames
}

/// Each sample of a spline is a pair `[t, q]` (the error and its line).
fn check_samples(raw: &RawModel, line_index: &LineIndex) -> Result<(), (String, usize)> {
    for (name, v) in &raw.variables {
        let Some(samples) = &v.get_ref().samples else {
            continue;
        };
        let rows = samples.get_ref().iter();
        if let Some((k, row)) = rows.enumerate().find(|(_, r)| r.len() != 2) {
            return Err((
                format!(
                    "variable `{name}`: sample {} has {} numbers; each sample is a pair [t, q]",
                    k + 1,
                    row.len()
                ),
                line_index.of(samples.span().start),
            ));
        }
    }
    Ok(())
}

/// The variables' settings, with the line of each.
fn variables_of(
    raw: &RawModel,
    line_index: &LineIndex,
    variable_lines: &mut BTreeMap<String, usize>,
) -> Vec<VariableSpec> {
    let variables = raw
        .variables
        .iter()
        .map(|(name, v)| {
            variable_lines.insert(name.clone(), line_index.of(v.span().start));
            let v = v.get_ref();
            VariableSpec {
                name: name.clone(),
                q0: v.q0,
                dq0: v.dq0,
                damping: v.damping,
                kinematic: v.kinematic,
                motion: v.motion.as_ref().map(|m| SineSpec {
                    offset: m.offset,
                    amplitude: m.amplitude,
                    frequency: m.frequency,
                    phase: m.phase,
                }),
                samples: v
                    .samples
                    .as_ref()
                    .map(|rows| rows.get_ref().iter().map(|r| [r[0], r[1]]).collect()),
                limits: v.limits,
            }
        })
        .collect();
    variables
}

/// `enforce_limits`, `[ground]` and `[[contact]]` as written (a model's or a task's).
pub(crate) type RawContacts<'a> = (
    Option<bool>,
    Option<&'a Spanned<RawGround>>,
    &'a [Spanned<RawContact>],
);

/// The ground and the contacts, with the line of each one's fields.
pub(crate) fn contacts_of(
    (enforce_limits, ground, contact): RawContacts,
    line_index: &LineIndex,
    lines: &mut ContactLines,
) -> ContactsSpec {
    let value = |x: &Option<Spanned<f64>>| x.as_ref().map(|x| *x.get_ref());
    let ground = ground.map(|g| {
        let mut l = ElementLines::new(line_index, g.span());
        let g = g.get_ref();
        l.field(line_index, "height", &g.height);
        l.field(line_index, "normal", &g.normal);
        l.field(line_index, "friction", &g.friction);
        lines.ground.push(l);
        GroundSpec {
            height: value(&g.height),
            normal: g.normal.as_ref().map(|n| *n.get_ref()),
            friction: value(&g.friction),
        }
    });
    let contacts = (contact.iter())
        .map(|c| {
            let mut l = ElementLines::new(line_index, c.span());
            let c = c.get_ref();
            l.field(line_index, "name", &c.name);
            l.field(line_index, "frame", &Some(c.frame.clone()));
            l.field(line_index, "radius", &c.radius);
            l.field(line_index, "friction", &c.friction);
            l.field(line_index, "collide", &c.collide);
            lines.contacts.push(l);
            ContactSpec {
                name: c.name.as_ref().map(|n| n.get_ref().clone()),
                frame: c.frame.get_ref().clone(),
                radius: value(&c.radius),
                friction: value(&c.friction),
                collide: c.collide.as_ref().map(|x| *x.get_ref()),
            }
        })
        .collect();
    ContactsSpec {
        enforce_limits,
        ground,
        contacts,
    }
}

/// The constraints, with the line of each one's fields.
fn constraints_of(
    raw: &RawModel,
    line_index: &LineIndex,
    constraint_lines: &mut Vec<ElementLines>,
) -> Vec<ConstraintSpec> {
    let value = |v: &RawValue| match v {
        RawValue::Number(x) => ParameterSpec::Constant(*x),
        RawValue::Name(n) => ParameterSpec::Variable(n.clone()),
    };
    let constraints = raw
        .constraint
        .iter()
        .map(|c| {
            let mut lines = ElementLines::new(line_index, c.span());
            let c = c.get_ref();
            lines.field(line_index, "name", &c.name);
            lines.field(line_index, "kind", &Some(c.kind.clone()));
            lines.field(line_index, "frames", &Some(c.frames.clone()));
            lines.field(line_index, "length", &c.length);
            lines.field(line_index, "normal", &c.normal);
            lines.field(line_index, "axes", &c.axes);
            lines.field(line_index, "slack", &c.slack);
            constraint_lines.push(lines);
            ConstraintSpec {
                name: c.name.as_ref().map(|n| n.get_ref().clone()),
                kind: c.kind.get_ref().clone(),
                frames: c.frames.get_ref().clone(),
                length: c.length.as_ref().map(|l| value(l.get_ref())),
                normal: c.normal.as_ref().map(|n| *n.get_ref()),
                axes: c.axes.as_ref().map(|a| a.get_ref().clone()),
                slack: c.slack.as_ref().map(|s| *s.get_ref()),
            }
        })
        .collect();
    constraints
}

/// The springs, with the line of each one's fields.
fn springs_of(
    raw: &RawModel,
    line_index: &LineIndex,
    spring_lines: &mut Vec<ElementLines>,
) -> Vec<SpringSpec> {
    let springs = raw
        .spring
        .iter()
        .map(|s| {
            let mut lines = ElementLines::new(line_index, s.span());
            let s = s.get_ref();
            lines.field(line_index, "frames", &s.frames);
            lines.field(line_index, "variable", &s.variable);
            lines.field(line_index, "stiffness", &s.stiffness);
            lines.field(line_index, "rest", &s.rest);
            spring_lines.push(lines);
            SpringSpec {
                frames: s.frames.as_ref().map(|f| f.get_ref().clone()),
                variable: s.variable.as_ref().map(|v| v.get_ref().clone()),
                stiffness: s.stiffness.as_ref().map(|x| *x.get_ref()),
                rest: s.rest.as_ref().map(|x| *x.get_ref()),
            }
        })
        .collect();
    springs
}

/// The dampers, with the line of each one's fields.
fn dampers_of(
    raw: &RawModel,
    line_index: &LineIndex,
    damper_lines: &mut Vec<ElementLines>,
) -> Vec<DamperSpec> {
    let dampers = raw
        .damper
        .iter()
        .map(|d| {
            let mut lines = ElementLines::new(line_index, d.span());
            let d = d.get_ref();
            lines.field(line_index, "frames", &Some(d.frames.clone()));
            lines.field(line_index, "damping", &d.damping);
            damper_lines.push(lines);
            DamperSpec {
                frames: d.frames.get_ref().clone(),
                damping: d.damping.as_ref().map(|x| *x.get_ref()),
            }
        })
        .collect();
    dampers
}

/// The inputs, with the line of each one's fields.
fn inputs_of(
    raw: &RawModel,
    line_index: &LineIndex,
    input_lines: &mut Vec<ElementLines>,
) -> Vec<InputSpec> {
    let inputs = raw
        .input
        .iter()
        .map(|u| {
            let mut lines = ElementLines::new(line_index, u.span());
            let u = u.get_ref();
            lines.field(line_index, "name", &Some(u.name.clone()));
            lines.field(line_index, "variable", &u.variable);
            lines.field(line_index, "limits", &u.limits);
            input_lines.push(lines);
            InputSpec {
                name: u.name.get_ref().clone(),
                variable: u.variable.as_ref().map(|v| v.get_ref().clone()),
                limits: u.limits.as_ref().map(|l| *l.get_ref()),
            }
        })
        .collect();
    inputs
}

/// Reads, parses and validates a model file.
pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Model, ModelError> {
    let path = path.as_ref();
    let shown = path.display().to_string();
    let text = crate::source::read_model_file(path)?;
    from_toml_str(&text, Some(&shown))
}
