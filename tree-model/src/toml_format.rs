//! The TOML model format (see README): parse with source spans, so that every validation
//! problem names its line.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use crate::error::{FrameField, ModelError, Site};
use crate::model::Model;
use crate::primitive::{Primitive, PrimitiveKind, Value};
use crate::spec::{FrameSpec, ModelSpec, VariableSpec};
use crate::validate::validate;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    name: Option<String>,
    gravity: Option<[f64; 3]>,
    #[serde(default)]
    frame: Vec<Spanned<RawFrame>>,
    #[serde(default)]
    variables: BTreeMap<String, Spanned<RawVariable>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFrame {
    name: Spanned<String>,
    parent: Option<Spanned<String>>,
    tx: Option<Spanned<RawValue>>,
    ty: Option<Spanned<RawValue>>,
    tz: Option<Spanned<RawValue>>,
    rx: Option<Spanned<RawValue>>,
    ry: Option<Spanned<RawValue>>,
    rz: Option<Spanned<RawValue>>,
    mass: Option<Spanned<f64>>,
    inertia: Option<Spanned<[f64; 3]>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawValue {
    Number(f64),
    Name(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariable {
    q0: Option<f64>,
    dq0: Option<f64>,
    damping: Option<f64>,
    kinematic: Option<bool>,
}

/// 1-based line of a byte offset.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Lines of each frame's fields, for pointing problems at the source.
struct FrameLines {
    whole: usize,
    name: usize,
    parent: Option<usize>,
    primitive: Option<usize>,
    mass: Option<usize>,
    inertia: Option<usize>,
}

/// Parses and validates a model from TOML text. `source_name` (a file name) prefixes every
/// message; when the model has no `name`, it is taken from the file stem.
pub fn from_toml_str(text: &str, source_name: Option<&str>) -> Result<Model, ModelError> {
    let src = source_name.map(str::to_string);
    let raw: RawModel = toml::from_str(text).map_err(|e| {
        let line = e.span().map(|s| line_of(text, s.start));
        let msg = e.message().trim().to_string();
        ModelError::single(src.clone(), format!("TOML error: {msg}"), line)
    })?;

    let mut lines = Vec::new();
    let mut frames = Vec::new();
    for f in &raw.frame {
        let at = |s: std::ops::Range<usize>| line_of(text, s.start);
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
                    RawValue::Number(x) => Value::Constant(*x),
                    RawValue::Name(n) => Value::Variable(n.clone()),
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
        });
        frames.push(FrameSpec {
            name: rf.name.get_ref().clone(),
            parent: rf.parent.as_ref().map(|p| p.get_ref().clone()),
            primitives,
            mass: rf.mass.as_ref().map(|m| *m.get_ref()),
            inertia: rf.inertia.as_ref().map(|m| *m.get_ref()),
        });
    }
    let mut variable_lines = BTreeMap::new();
    let variables = raw
        .variables
        .iter()
        .map(|(name, v)| {
            variable_lines.insert(name.clone(), line_of(text, v.span().start));
            let v = v.get_ref();
            VariableSpec {
                name: name.clone(),
                q0: v.q0,
                dq0: v.dq0,
                damping: v.damping,
                kinematic: v.kinematic,
            }
        })
        .collect();
    let name = raw.name.clone().unwrap_or_else(|| {
        source_name
            .and_then(|s| Path::new(s).file_stem())
            .map_or("model".into(), |s| s.to_string_lossy().into_owned())
    });
    let spec = ModelSpec {
        name,
        gravity: raw.gravity,
        frames,
        variables,
    };
    validate(&spec).map_err(|mut problems| {
        for p in &mut problems {
            p.line = match &p.site {
                Site::Model => None,
                Site::VariableSettings { name } => variable_lines.get(name).copied(),
                Site::Frame { index, field } => {
                    let l = &lines[*index];
                    let specific = match field {
                        FrameField::Whole => None,
                        FrameField::Name => Some(l.name),
                        FrameField::Parent => l.parent,
                        FrameField::Primitive => l.primitive,
                        FrameField::Mass => l.mass,
                        FrameField::Inertia => l.inertia,
                    };
                    Some(specific.unwrap_or(l.whole))
                }
            };
        }
        ModelError {
            source_name: src.clone(),
            problems,
        }
    })
}

/// Reads, parses and validates a model file.
pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Model, ModelError> {
    let path = path.as_ref();
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| {
        ModelError::single(None, format!("cannot read model file `{shown}`: {e}"), None)
    })?;
    from_toml_str(&text, Some(&shown))
}
