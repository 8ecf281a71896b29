//! From the macro input to a validated [`Model`]: a file is read and validated by
//! `tree-model` exactly as at run time; the inline tree becomes a [`ModelSpec`] for the same
//! validator. Every problem becomes a compile error at the token (or file line) at fault.

use std::path::PathBuf;

use proc_macro2::Span;
use syn::LitStr;
use tree_model::{
    ConstraintSpec, ContactSpec, ContactsSpec, DamperSpec, FrameField, FrameSpec, GroundSpec,
    InputSpec, MimicSpec, Model, ModelSpec, ParameterSpec, Primitive, PrimitiveKind, Section,
    SineSpec, Site, SpringSpec, Value, VariableSpec,
};

use crate::ast::{Argument, ElementKind, InlineElement, InlineFrame, InlineModel, Setting};

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
    /// How many errors so far.
    fn count(&self) -> usize {
        self.0.as_ref().map_or(0, |e| e.into_iter().count())
    }
    fn finish(self) -> syn::Result<()> {
        self.0.map_or(Ok(()), Err)
    }
}

/// Whether a model file is URDF (by its extension).
pub fn is_urdf(path: &str) -> bool {
    std::path::Path::new(path)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
}

/// A model read from a file (TOML, or URDF by extension, with a floating base when asked):
/// the model and the absolute path, so the expansion can make cargo rebuild when the file
/// changes.
/// A path as written in the macro, from the crate's root (its `CARGO_MANIFEST_DIR`).
fn from_crate_root(written: &str) -> PathBuf {
    let base = std::env::var_os("CARGO_MANIFEST_DIR_OVERRIDE")
        .or_else(|| std::env::var_os("CARGO_MANIFEST_DIR"))
        .map(PathBuf::from)
        .unwrap_or_default();
    base.join(written)
}

/// `model` with its limits enforced or not (`enforce_limits = …` after a file's path).
pub fn with_enforced_limits(mut model: Model, enforce: bool) -> Model {
    model.contacts.enforce_limits = enforce;
    model
}

/// `model` with the contact tables of the TOML file at `path` (`contacts from "…"`), and
/// that file's full path; a mistake in it is a compile error at the path, with its line.
pub fn with_contacts_from(model: Model, path: &LitStr) -> syn::Result<(Model, PathBuf)> {
    let (written, full, text) = read_file(path, "contacts")?;
    let model = model
        .with_contacts_from_toml_str(&text, Some(&written))
        .map_err(|e| at_path(path, &e))?;
    Ok((model, full))
}

/// The file at `path` (as written, in full, its text); unreadable, a compile error at the
/// path naming `what` file it is.
fn read_file(path: &LitStr, what: &str) -> syn::Result<(String, PathBuf, String)> {
    let written = path.value();
    let full = from_crate_root(&written);
    let text = std::fs::read_to_string(&full).map_err(|e| {
        syn::Error::new(
            path.span(),
            format!("cannot read {what} file `{written}`: {e}"),
        )
    })?;
    Ok((written, full, text))
}

/// A model error as compile errors at the file's path, one per line of its message.
fn at_path(path: &LitStr, e: &tree_model::ModelError) -> syn::Error {
    let mut errors = Errors::default();
    for line in e.to_string().lines() {
        errors.push(path.span(), line);
    }
    errors.0.expect("a model error has at least one problem")
}

pub fn from_file(path: &LitStr, floating_base: bool) -> syn::Result<(Model, PathBuf)> {
    let (written, full, text) = read_file(path, "model")?;
    let model = if is_urdf(&written) {
        let options = tree_model::UrdfOptions {
            floating_base,
            ..Default::default()
        };
        tree_model::from_urdf_str(&text, Some(&written), options)
    } else if floating_base {
        return Err(syn::Error::new(
            path.span(),
            "`floating_base` applies to URDF models only; a TOML model declares its own base variables",
        ));
    } else {
        tree_model::from_toml_str(&text, Some(&written))
    };
    let model = model.map_err(|e| at_path(path, &e))?;
    Ok((model, full))
}

/// Spans of one inline frame's parts, by [`FrameField`].
struct FrameSpans {
    name: Span,
    parent: Span,
    primitive: Span,
    mass: Option<Span>,
    inertia: Option<Span>,
    com: Option<Span>,
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
        Argument::Mimic(leader, settings) => {
            let mut m = MimicSpec::new(leader.to_string());
            for (key, x) in settings {
                match key.to_string().as_str() {
                    "multiplier" => m.multiplier = x.value,
                    "offset" => m.offset = x.value,
                    _ => m.damping = x.value,
                }
            }
            (Value::Mimic(m), leader.span())
        }
    };
    specs.push(FrameSpec {
        name: frame.name.to_string(),
        parent: parent.map(|p| p.name.to_string()),
        primitives: vec![Primitive { kind, value }],
        mass: frame.mass.map(|m| m.value),
        com: frame.com.map(|c| c.0),
        inertia: frame.inertia.as_ref().map(|i| i.0.clone()),
    });
    spans.push(FrameSpans {
        name: frame.name.span(),
        parent: parent.map_or(frame.name.span(), |p| p.name.span()),
        primitive: arg_span,
        mass: frame.mass.map(|m| m.span),
        inertia: frame.inertia.as_ref().map(|i| i.1),
        com: frame.com.map(|c| c.1),
    });
    for child in &frame.children {
        flatten(child, Some(frame), specs, spans);
    }
}

/// A variable's settings as a [`VariableSpec`]; wrong keys and values are errors at them.
fn variable_spec(
    name: &syn::Ident,
    settings: &[(syn::Ident, Setting)],
    errors: &mut Errors,
) -> VariableSpec {
    let mut spec = VariableSpec {
        name: name.to_string(),
        ..VariableSpec::default()
    };
    for (key, value) in settings {
        match (key.to_string().as_str(), value) {
            ("q0", Setting::Number(n)) => spec.q0 = Some(n.value),
            ("dq0", Setting::Number(n)) => spec.dq0 = Some(n.value),
            ("damping", Setting::Number(n)) => spec.damping = Some(n.value),
            ("kinematic", Setting::Bool(b, _)) => spec.kinematic = Some(*b),
            ("motion", Setting::Sine(terms, _)) => {
                let mut sine = SineSpec::default();
                for (k, n) in terms {
                    let slot = match k.to_string().as_str() {
                        "offset" => &mut sine.offset,
                        "amplitude" => &mut sine.amplitude,
                        "frequency" => &mut sine.frequency,
                        "phase" => &mut sine.phase,
                        _ => {
                            errors.push(k.span(), format!("unknown sine parameter `{k}`: expected offset, amplitude, frequency or phase"));
                            continue;
                        }
                    };
                    *slot = Some(n.value);
                }
                spec.motion = Some(sine);
            }
            ("samples", Setting::Pairs(pairs, _)) => spec.samples = Some(pairs.clone()),
            ("limits", Setting::Vector(v, _)) if v.len() == 2 => {
                spec.limits = Some([v[0].value, v[1].value])
            }
            ("limits", v) => errors.push(v.span(), "`limits` takes two numbers [lower, upper]"),
            ("q0" | "dq0" | "damping", v) => errors.push(v.span(), format!("`{key}` takes a number")),
            ("kinematic", v) => errors.push(v.span(), "`kinematic` takes true or false"),
            ("motion", v) => errors.push(
                v.span(),
                "`motion` takes sine(offset = …, amplitude = …, frequency = …, phase = …)",
            ),
            ("samples", v) => errors.push(v.span(), "`samples` takes pairs [[t, q], …]"),
            _ => errors.push(
                key.span(),
                format!(
                    "unknown variable setting `{key}`: expected q0, dq0, damping, kinematic, motion, samples or limits"
                ),
            ),
        }
    }
    spec
}

/// Where an inline element's parts were written, so the validator's problems point there.
struct ElementSpans {
    keyword: Span,
    name: Option<Span>,
    kind: Option<Span>,
    arguments: Vec<(String, Span)>,
    settings: Vec<(String, Span)>,
}

impl ElementSpans {
    /// The span for a problem with `field` and `message`: the frame or variable the message
    /// names, the setting's key, or the keyword.
    fn of(&self, field: Option<&str>, message: &str) -> Span {
        match field {
            Some("frames" | "variable" | "frame") => self
                .arguments
                .iter()
                .find(|(name, _)| message.contains(&format!("`{name}`")))
                .or(self.arguments.first())
                .map_or(self.keyword, |a| a.1),
            Some("kind") => self.kind.unwrap_or(self.keyword),
            Some("name") => self.name.unwrap_or(self.keyword),
            Some(f) => self
                .settings
                .iter()
                .find(|(k, _)| k == f)
                .map_or(self.keyword, |s| s.1),
            None => self.keyword,
        }
    }
}

/// The spec lists an inline element adds to, and its spans.
fn element_spec(
    e: &InlineElement,
    spec: &mut ModelSpec,
    errors: &mut Errors,
) -> (Section, ElementSpans) {
    let names: Vec<String> = e.arguments.iter().map(|a| a.to_string()).collect();
    let spans = ElementSpans {
        keyword: e.keyword,
        name: e.name.as_ref().map(|n| n.span()),
        kind: e.kind.as_ref().map(|k| k.span()),
        arguments: names
            .iter()
            .cloned()
            .zip(e.arguments.iter().map(|a| a.span()))
            .collect(),
        settings: e
            .settings
            .iter()
            .map(|(k, _)| (k.to_string(), k.span()))
            .collect(),
    };
    let number = |key: &syn::Ident, v: &Setting, errors: &mut Errors| match v {
        Setting::Number(n) => Some(n.value),
        other => {
            errors.push(other.span(), format!("`{key}` takes a number"));
            None
        }
    };
    match e.element {
        ElementKind::Constraint => {
            spec.constraints.push(constraint_spec(e, names, errors));
            (Section::Constraint, spans)
        }
        ElementKind::Spring => {
            let mut s = SpringSpec::default();
            match names.len() {
                1 => s.variable = Some(names[0].clone()),
                _ => s.frames = Some(names),
            }
            for (key, value) in &e.settings {
                match key.to_string().as_str() {
                    "stiffness" => s.stiffness = number(key, value, errors),
                    "rest" => s.rest = number(key, value, errors),
                    _ => unknown(key, "spring", "stiffness or rest", errors),
                }
            }
            spec.springs.push(s);
            (Section::Spring, spans)
        }
        ElementKind::Damper => {
            let mut d = DamperSpec {
                frames: names,
                damping: None,
            };
            for (key, value) in &e.settings {
                match key.to_string().as_str() {
                    "damping" => d.damping = number(key, value, errors),
                    _ => unknown(key, "damper", "damping", errors),
                }
            }
            spec.dampers.push(d);
            (Section::Damper, spans)
        }
        ElementKind::Input => {
            spec.inputs.push(input_spec(e, names, errors));
            (Section::Input, spans)
        }
        ElementKind::Ground => {
            let mut g = GroundSpec::default();
            for (key, value) in &e.settings {
                match (key.to_string().as_str(), value) {
                    ("height", v) => g.height = number(key, v, errors),
                    ("friction", v) => g.friction = number(key, v, errors),
                    ("normal", Setting::Vector(n, span)) => match n[..] {
                        [x, y, z] => g.normal = Some([x.value, y.value, z.value]),
                        _ => {
                            errors.push(*span, format!("expected three numbers, found {}", n.len()))
                        }
                    },
                    ("normal", v) => {
                        errors.push(v.span(), "`normal` takes three numbers [x, y, z]")
                    }
                    _ => unknown(key, "ground", "height, normal or friction", errors),
                }
            }
            if spec.contacts.ground.replace(g).is_some() {
                errors.push(e.keyword, "the ground is given twice");
            }
            (Section::Ground, spans)
        }
        ElementKind::Contact => {
            let mut c = ContactSpec {
                name: e.name.as_ref().map(|n| n.to_string()),
                frame: names.first().cloned().unwrap_or_default(),
                ..ContactSpec::default()
            };
            if names.len() != 1 {
                errors.push(
                    e.keyword,
                    format!("a contact sphere sits on one frame, found {}", names.len()),
                );
            }
            for (key, value) in &e.settings {
                match (key.to_string().as_str(), value) {
                    ("radius", v) => c.radius = number(key, v, errors),
                    ("friction", v) => c.friction = number(key, v, errors),
                    ("collide", Setting::Bool(b, _)) => c.collide = Some(*b),
                    ("collide", v) => errors.push(v.span(), "`collide` takes true or false"),
                    _ => unknown(key, "contact", "radius, friction or collide", errors),
                }
            }
            spec.contacts.contacts.push(c);
            (Section::Contact, spans)
        }
    }
}

/// An unknown setting of an element, named with the ones it takes.
fn unknown(key: &syn::Ident, what: &str, expected: &str, errors: &mut Errors) {
    errors.push(
        key.span(),
        format!("unknown {what} setting `{key}`: expected {expected}"),
    );
}

/// `constraint(a, b) { length = …; normal = […]; axes = …; }` as a spec.
fn constraint_spec(e: &InlineElement, names: Vec<String>, errors: &mut Errors) -> ConstraintSpec {
    let mut c = ConstraintSpec {
        name: e.name.as_ref().map(|n| n.to_string()),
        kind: e.kind.as_ref().map(|k| k.to_string()).unwrap_or_default(),
        frames: names,
        ..ConstraintSpec::default()
    };
    for (key, value) in &e.settings {
        match (key.to_string().as_str(), value) {
            ("length", Setting::Number(n)) => c.length = Some(ParameterSpec::Constant(n.value)),
            ("length", Setting::Name(v)) => c.length = Some(ParameterSpec::Variable(v.to_string())),
            ("length", v) => errors.push(v.span(), "`length` takes a number or a variable name"),
            ("normal", Setting::Vector(n, span)) => {
                if n.len() == 3 {
                    c.normal = Some([n[0].value, n[1].value, n[2].value]);
                } else {
                    errors.push(*span, format!("expected three numbers, found {}", n.len()));
                }
            }
            ("normal", v) => errors.push(v.span(), "`normal` takes three numbers [x, y, z]"),
            ("axes", Setting::Text(t)) => c.axes = Some(t.value()),
            ("axes", Setting::Name(t)) => c.axes = Some(t.to_string()),
            ("axes", v) => errors.push(v.span(), "`axes` takes some of x, y, z (e.g. xz)"),
            ("slack", Setting::Bool(b, _)) => c.slack = Some(*b),
            ("slack", v) => errors.push(v.span(), "`slack` takes true or false"),
            _ => unknown(key, "constraint", "length, normal, axes or slack", errors),
        }
    }
    c
}

/// `input name(variable) { limits = [lo, hi]; }` as a spec.
fn input_spec(e: &InlineElement, names: Vec<String>, errors: &mut Errors) -> InputSpec {
    let mut u = InputSpec {
        name: e.name.as_ref().map(|n| n.to_string()).unwrap_or_default(),
        variable: names.first().cloned(),
        limits: None,
    };
    for (key, value) in &e.settings {
        match (key.to_string().as_str(), value) {
            ("limits", Setting::Vector(v, span)) => {
                if v.len() == 2 {
                    u.limits = Some([v[0].value, v[1].value]);
                } else {
                    errors.push(
                        *span,
                        format!("expected two numbers [lo, hi], found {}", v.len()),
                    );
                }
            }
            ("limits", v) => errors.push(v.span(), "`limits` takes two numbers [lo, hi]"),
            _ => unknown(key, "input", "limits", errors),
        }
    }
    u
}

/// Builds and validates the inline model named `name`; returns the spec too, from which the
/// expansion rebuilds the same model at run time.
pub fn from_inline(name: &syn::Ident, inline: &InlineModel) -> syn::Result<(Model, ModelSpec)> {
    let mut errors = Errors::default();
    let mut frames = Vec::new();
    let mut spans = Vec::new();
    for f in &inline.frames {
        flatten(f, None, &mut frames, &mut spans);
    }
    let mut variables = Vec::new();
    let mut variable_spans = Vec::new();
    // A value the lowering already refused is left out of the spec; the validator's
    // complaints about it (a missing field, say) would only repeat the error, so they are
    // dropped for that variable or element.
    let mut tainted_variables = Vec::new();
    for v in &inline.variables {
        let before = errors.count();
        variables.push(variable_spec(&v.name, &v.settings, &mut errors));
        variable_spans.push((v.name.to_string(), v.name.span()));
        if errors.count() > before {
            tainted_variables.push(v.name.to_string());
        }
    }
    let mut spec = ModelSpec {
        gravity: inline.gravity.map(|g| g.0),
        contacts: ContactsSpec {
            enforce_limits: inline.enforce_limits,
            ..ContactsSpec::default()
        },
        frames,
        variables,
        ..ModelSpec::new(name.to_string())
    };
    let mut element_spans: Vec<(Section, ElementSpans, bool)> = Vec::new();
    for e in &inline.elements {
        let before = errors.count();
        let (section, spans) = element_spec(e, &mut spec, &mut errors);
        element_spans.push((section, spans, errors.count() > before));
    }
    let model = tree_model::validate(&spec);
    if let Err(problems) = &model {
        for p in problems {
            let repeats = match &p.site {
                Site::VariableSettings { name } => tainted_variables.contains(name),
                Site::Element { section, index, .. } => element_spans
                    .iter()
                    .filter(|(s, ..)| s == section)
                    .nth(*index)
                    .is_some_and(|e| e.2),
                _ => false,
            };
            if repeats {
                continue;
            }
            let span = match &p.site {
                Site::Model => name.span(),
                Site::Gravity => inline.gravity.map_or(name.span(), |g| g.1),
                Site::VariableSettings { name: v } => variable_spans
                    .iter()
                    .find(|(n, _)| n == v)
                    .map_or(name.span(), |s| s.1),
                Site::Element {
                    section,
                    index,
                    field,
                } => element_spans
                    .iter()
                    .filter(|(s, ..)| s == section)
                    .nth(*index)
                    .map_or(name.span(), |(_, s, _)| s.of(*field, &p.message)),
                Site::Frame { index, field } => {
                    let s = &spans[*index];
                    match field {
                        FrameField::Whole | FrameField::Name => s.name,
                        FrameField::Parent => s.parent,
                        FrameField::Primitive => s.primitive,
                        FrameField::Mass => s.mass.unwrap_or(s.name),
                        FrameField::Inertia => s.inertia.unwrap_or(s.name),
                        FrameField::Com => s.com.unwrap_or(s.name),
                    }
                }
            };
            errors.push(span, &p.message);
        }
    }
    errors.finish()?;
    Ok((model.expect("no problems were reported"), spec))
}
