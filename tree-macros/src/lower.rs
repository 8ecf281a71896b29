//! From the macro input to a validated [`Model`]: a file is read and validated by
//! `tree-model` exactly as at run time; the inline tree becomes a [`ModelSpec`] for the same
//! validator. Every problem becomes a compile error at the token (or file line) at fault.

use std::path::PathBuf;

use proc_macro2::Span;
use syn::LitStr;
use tree_model::{
    FrameField, FrameSpec, Model, ModelSpec, Primitive, PrimitiveKind, Site, Value, VariableSpec,
};

use crate::ast::{Argument, InlineFrame, InlineModel, Setting};

/// Collects errors and fails with all of them (the serde_derive `Ctxt` pattern).
#[derive(Default)]
struct Errors(Option<syn::Error>);

impl Errors {
    fn push(&mut self, span: Span, message: impl std::fmt::Display) {
        let e = syn::Error::new(span, message);
        match &mut self.0 {
            Some(all) => all.combine(e),
            None => self.0 = Some(e),
        }
    }
    fn finish(self) -> syn::Result<()> {
        self.0.map_or(Ok(()), Err)
    }
}

/// A model read from a file: the model and the absolute path, so the expansion can make
/// cargo rebuild when the file changes.
pub fn from_file(path: &LitStr) -> syn::Result<(Model, PathBuf)> {
    let written = path.value();
    let base = std::env::var_os("CARGO_MANIFEST_DIR_OVERRIDE")
        .or_else(|| std::env::var_os("CARGO_MANIFEST_DIR"))
        .map(PathBuf::from)
        .unwrap_or_default();
    let full = base.join(&written);
    let text = std::fs::read_to_string(&full).map_err(|e| {
        syn::Error::new(
            path.span(),
            format!("cannot read model file `{written}`: {e}"),
        )
    })?;
    let model = tree_model::from_toml_str(&text, Some(&written)).map_err(|e| {
        let mut errors = Errors::default();
        for line in e.to_string().lines() {
            errors.push(path.span(), line);
        }
        errors.0.expect("a model error has at least one problem")
    })?;
    Ok((model, full))
}

/// Spans of one inline frame's parts, by [`FrameField`].
struct FrameSpans {
    name: Span,
    parent: Span,
    primitive: Span,
    mass: Option<Span>,
    inertia: Option<Span>,
}

fn flatten(
    frame: &InlineFrame,
    parent: Option<&InlineFrame>,
    specs: &mut Vec<FrameSpec>,
    spans: &mut Vec<FrameSpans>,
) {
    let kind =
        PrimitiveKind::from_keyword(&frame.primitive.to_string()).expect("checked while parsing");
    let (value, arg_span) = match &frame.argument {
        Argument::Variable(v) => (Value::Variable(v.to_string()), v.span()),
        Argument::Constant(n) => (Value::Constant(n.value), n.span),
    };
    specs.push(FrameSpec {
        name: frame.name.to_string(),
        parent: parent.map(|p| p.name.to_string()),
        primitives: vec![Primitive { kind, value }],
        mass: frame.mass.map(|m| m.value),
        inertia: frame.inertia.map(|i| i.0),
    });
    spans.push(FrameSpans {
        name: frame.name.span(),
        parent: parent.map_or(frame.name.span(), |p| p.name.span()),
        primitive: arg_span,
        mass: frame.mass.map(|m| m.span),
        inertia: frame.inertia.map(|i| i.1),
    });
    for child in &frame.children {
        flatten(child, Some(frame), specs, spans);
    }
}

/// Builds and validates the inline model named `name`.
pub fn from_inline(name: &syn::Ident, inline: &InlineModel) -> syn::Result<Model> {
    let mut errors = Errors::default();
    let mut frames = Vec::new();
    let mut spans = Vec::new();
    for f in &inline.frames {
        flatten(f, None, &mut frames, &mut spans);
    }
    let mut variables = Vec::new();
    let mut variable_spans = Vec::new();
    for v in &inline.variables {
        let mut spec = VariableSpec {
            name: v.name.to_string(),
            ..VariableSpec::default()
        };
        for (key, value) in &v.settings {
            match (key.to_string().as_str(), value) {
                ("q0", Setting::Number(n)) => spec.q0 = Some(n.value),
                ("dq0", Setting::Number(n)) => spec.dq0 = Some(n.value),
                ("damping", Setting::Number(n)) => spec.damping = Some(n.value),
                ("kinematic", Setting::Bool(b)) => spec.kinematic = Some(*b),
                ("q0" | "dq0" | "damping", Setting::Bool(_)) => {
                    errors.push(key.span(), format!("`{key}` takes a number"))
                }
                ("kinematic", Setting::Number(_)) => {
                    errors.push(key.span(), "`kinematic` takes true or false")
                }
                _ => errors.push(
                    key.span(),
                    format!(
                        "unknown variable setting `{key}`: expected q0, dq0, damping or kinematic"
                    ),
                ),
            }
        }
        variables.push(spec);
        variable_spans.push((v.name.to_string(), v.name.span()));
    }
    let spec = ModelSpec {
        name: name.to_string(),
        gravity: inline.gravity.map(|g| g.0),
        frames,
        variables,
        constraints: Vec::new(),
        springs: Vec::new(),
        dampers: Vec::new(),
    };
    let model = tree_model::validate(&spec);
    if let Err(problems) = &model {
        for p in problems {
            let span = match &p.site {
                Site::Model => name.span(),
                Site::VariableSettings { name: v } => variable_spans
                    .iter()
                    .find(|(n, _)| n == v)
                    .map_or(name.span(), |s| s.1),
                Site::Element { .. } => name.span(),
                Site::Frame { index, field } => {
                    let s = &spans[*index];
                    match field {
                        FrameField::Whole | FrameField::Name => s.name,
                        FrameField::Parent => s.parent,
                        FrameField::Primitive => s.primitive,
                        FrameField::Mass => s.mass.unwrap_or(s.name),
                        FrameField::Inertia => s.inertia.unwrap_or(s.name),
                    }
                }
            };
            errors.push(span, &p.message);
        }
    }
    errors.finish()?;
    Ok(model.expect("no problems were reported"))
}
