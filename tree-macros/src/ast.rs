//! The macro's input: a header naming the generated type, then either a model file or the
//! inline tree syntax. Every piece keeps its span so validation errors point at it.

use proc_macro2::Span;
use syn::parse::{Parse, ParseStream};
use syn::{braced, bracketed, parenthesized, Ident, LitStr, Token, Visibility};

mod kw {
    syn::custom_keyword!(from);
    syn::custom_keyword!(floating_base);
    syn::custom_keyword!(contacts);
    syn::custom_keyword!(lean);
    syn::custom_keyword!(gravity);
    syn::custom_keyword!(frame);
    syn::custom_keyword!(mass);
    syn::custom_keyword!(inertia);
    syn::custom_keyword!(com);
    syn::custom_keyword!(variable);
    syn::custom_keyword!(constraint);
    syn::custom_keyword!(spring);
    syn::custom_keyword!(damper);
    syn::custom_keyword!(input);
    syn::custom_keyword!(ground);
    syn::custom_keyword!(contact);
    syn::custom_keyword!(enforce_limits);
}

/// `tree_model!(pub struct Name from "file.toml")` or `tree_model! { pub struct Name; … }`.
pub struct Input {
    /// Outer attributes (doc comments) for the generated struct.
    pub attrs: Vec<syn::Attribute>,
    pub vis: Visibility,
    pub name: Ident,
    pub source: Source,
    /// `lean` / `lean = false` after a file's path: whether the model is compiled lean
    /// (`expand::LEAN_ABOVE`); `None` decides by its size.
    pub lean: Option<bool>,
    /// `contacts from "file.toml"` after a file's path: the ground, contacts and enforced
    /// limits that TOML file writes (a task file's, say), added to the model.
    pub contacts: Option<LitStr>,
    /// `enforce_limits = false` (or `true`) after a file's path: whether the variables'
    /// limits are enforced, as the TOML key says (applied after `contacts from`).
    pub enforce_limits: Option<bool>,
}

pub enum Source {
    /// A model file (TOML, or URDF by its extension), and for URDF whether to add a
    /// floating base (`from "robot.urdf", floating_base`).
    File(LitStr, bool),
    Inline(InlineModel),
}

/// The inline tree.
pub struct InlineModel {
    pub gravity: Option<([f64; 3], Span)>,
    /// `enforce_limits = true;`
    pub enforce_limits: Option<bool>,
    pub frames: Vec<InlineFrame>,
    pub variables: Vec<InlineVariable>,
    /// Constraints, springs, dampers, inputs, the ground and contacts, each list in the order
    /// written.
    pub elements: Vec<InlineElement>,
}

/// Which list an inline element belongs to.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum ElementKind {
    Constraint,
    Spring,
    Damper,
    Input,
    Ground,
    Contact,
}

/// `constraint NAME = KIND(a, b) { … }`, `spring(a, b) { … }` or `spring(var) { … }`,
/// `damper(a, b) { … }`, `input NAME = VARIABLE { … }`, `ground { … }`,
/// `contact NAME = sphere(frame) { … }`: what the TOML `[[constraint]]`, `[[spring]]`,
/// `[[damper]]`, `[[input]]`, `[ground]` and `[[contact]]` tables say.
pub struct InlineElement {
    pub element: ElementKind,
    /// The keyword (`constraint`, `spring`, `damper`): where whole-element errors point.
    pub keyword: Span,
    pub name: Option<Ident>,
    /// A constraint's kind (`distance`, `plane`, `point`).
    pub kind: Option<Ident>,
    /// The frames (or, for a one-argument spring, the variable) in the parentheses.
    pub arguments: Vec<Ident>,
    pub settings: Vec<(Ident, Setting)>,
}

/// A number with the span it was written at.
#[derive(Clone, Copy)]
pub struct Number {
    pub value: f64,
    pub span: Span,
}

/// `frame name = rx(theta) { mass = 1.0; com = [..]; inertia = [..]; frame … }`
pub struct InlineFrame {
    pub name: Ident,
    pub primitive: Ident,
    pub argument: Argument,
    pub mass: Option<Number>,
    /// Three (principal) or six numbers, checked by the validator.
    pub inertia: Option<(Vec<f64>, Span)>,
    pub com: Option<([f64; 3], Span)>,
    pub children: Vec<InlineFrame>,
}

pub enum Argument {
    Variable(Ident),
    Constant(Number),
    /// `mimic(leader, multiplier = m, offset = o, damping = c)`, the settings optional.
    Mimic(Ident, Vec<(Ident, Number)>),
}

/// `variable theta { q0 = 0.5; dq0 = 0.0; damping = 0.1; }`
pub struct InlineVariable {
    pub name: Ident,
    pub settings: Vec<(Ident, Setting)>,
}

/// A setting's value: `1.0`, `true`, `name`, `"xyz"`, `[1.0, 0.0, 0.0]`, `[[t, q], …]` or
/// `sine(offset = …, amplitude = …, frequency = …, phase = …)`.
pub enum Setting {
    Number(Number),
    Bool(bool, Span),
    Name(Ident),
    Text(LitStr),
    Vector(Vec<Number>, Span),
    Pairs(Vec<[f64; 2]>, Span),
    Sine(Vec<(Ident, Number)>, Span),
}

impl Setting {
    /// Where the value was written.
    pub fn span(&self) -> Span {
        match self {
            Setting::Number(n) => n.span,
            Setting::Bool(_, s) => *s,
            Setting::Name(i) => i.span(),
            Setting::Text(t) => t.span(),
            Setting::Vector(_, s) | Setting::Pairs(_, s) | Setting::Sine(_, s) => *s,
        }
    }
}

/// `mimic(leader, multiplier = m, offset = o, damping = c)`: a transform following another
/// frame's variable (what TOML writes `{ mimic = "leader", … }`).
fn parse_mimic(input: ParseStream) -> syn::Result<Argument> {
    let word: Ident = input.parse()?;
    if word != "mimic" {
        return Err(syn::Error::new(
            word.span(),
            format!("expected a variable name, a number or `mimic(variable, …)`, not `{word}(…)`"),
        ));
    }
    let content;
    parenthesized!(content in input);
    let leader: Ident = content.parse()?;
    let mut settings: Vec<(Ident, Number)> = Vec::new();
    while !content.is_empty() {
        content.parse::<Token![,]>()?;
        if content.is_empty() {
            break;
        }
        let key: Ident = content.parse()?;
        if !["multiplier", "offset", "damping"].contains(&key.to_string().as_str()) {
            return Err(syn::Error::new(
                key.span(),
                format!("unknown mimic setting `{key}`: expected multiplier, offset or damping"),
            ));
        }
        if settings.iter().any(|(k, _)| *k == key) {
            return Err(syn::Error::new(
                key.span(),
                format!("`{key}` is given twice"),
            ));
        }
        content.parse::<Token![=]>()?;
        settings.push((key, parse_number(&content)?));
    }
    Ok(Argument::Mimic(leader, settings))
}

fn parse_number(input: ParseStream) -> syn::Result<Number> {
    let negative = input.parse::<Option<Token![-]>>()?.is_some();
    let lookahead = input.lookahead1();
    let (value, span) = if lookahead.peek(syn::LitFloat) {
        let lit: syn::LitFloat = input.parse()?;
        (lit.base10_parse::<f64>()?, lit.span())
    } else if lookahead.peek(syn::LitInt) {
        let lit: syn::LitInt = input.parse()?;
        (lit.base10_parse::<f64>()?, lit.span())
    } else {
        return Err(lookahead.error());
    };
    Ok(Number {
        value: if negative { -value } else { value },
        span,
    })
}

fn parse_vector3(input: ParseStream) -> syn::Result<([f64; 3], Span)> {
    let content;
    let bracket = bracketed!(content in input);
    let items = content.parse_terminated(parse_number, Token![,])?;
    if items.len() != 3 {
        return Err(syn::Error::new(
            bracket.span.join(),
            format!("expected three numbers, found {}", items.len()),
        ));
    }
    let v: Vec<f64> = items.iter().map(|n| n.value).collect();
    Ok(([v[0], v[1], v[2]], bracket.span.join()))
}

impl Parse for Input {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(syn::Attribute::parse_outer)?;
        let vis: Visibility = input.parse()?;
        input.parse::<Token![struct]>()?;
        let name: Ident = input.parse()?;
        if input.peek(kw::from) {
            input.parse::<kw::from>()?;
            let path: LitStr = input.parse()?;
            let (mut floating_base, mut lean, mut contacts) = (false, None, None);
            let mut enforce_limits = None;
            while input.peek(Token![,]) {
                input.parse::<Token![,]>()?;
                let lookahead = input.lookahead1();
                if lookahead.peek(kw::floating_base) {
                    input.parse::<kw::floating_base>()?;
                    floating_base = true;
                } else if lookahead.peek(kw::lean) {
                    input.parse::<kw::lean>()?;
                    let mut value = true;
                    if input.peek(Token![=]) {
                        input.parse::<Token![=]>()?;
                        value = input.parse::<syn::LitBool>()?.value;
                    }
                    lean = Some(value);
                } else if lookahead.peek(kw::contacts) {
                    input.parse::<kw::contacts>()?;
                    input.parse::<kw::from>()?;
                    contacts = Some(input.parse::<LitStr>()?);
                } else if lookahead.peek(kw::enforce_limits) {
                    let kw: kw::enforce_limits = input.parse()?;
                    if !input.peek(Token![=]) {
                        let message = "`enforce_limits` takes a value: `enforce_limits = false` leaves the variables' limits unenforced, `= true` enforces them (the default)";
                        return Err(syn::Error::new(kw.span, message));
                    }
                    input.parse::<Token![=]>()?;
                    enforce_limits = Some(input.parse::<syn::LitBool>()?.value);
                } else {
                    return Err(lookahead.error());
                }
            }
            input.parse::<Option<Token![;]>>()?;
            if !input.is_empty() {
                return Err(input.error("unexpected tokens after the model file path"));
            }
            return Ok(Input {
                attrs,
                vis,
                name,
                source: Source::File(path, floating_base),
                lean,
                contacts,
                enforce_limits,
            });
        }
        input.parse::<Token![;]>()?;
        let mut model = InlineModel {
            gravity: None,
            enforce_limits: None,
            frames: Vec::new(),
            variables: Vec::new(),
            elements: Vec::new(),
        };
        while !input.is_empty() {
            let lookahead = input.lookahead1();
            if lookahead.peek(kw::gravity) {
                let kw: kw::gravity = input.parse()?;
                if model.gravity.is_some() {
                    return Err(syn::Error::new(kw.span, "gravity is given twice"));
                }
                input.parse::<Token![=]>()?;
                model.gravity = Some(parse_vector3(input)?);
                input.parse::<Token![;]>()?;
            } else if lookahead.peek(kw::enforce_limits) {
                let kw: kw::enforce_limits = input.parse()?;
                if model.enforce_limits.is_some() {
                    return Err(syn::Error::new(kw.span, "enforce_limits is given twice"));
                }
                input.parse::<Token![=]>()?;
                model.enforce_limits = Some(input.parse::<syn::LitBool>()?.value);
                input.parse::<Token![;]>()?;
            } else if lookahead.peek(kw::frame) {
                model.frames.push(input.parse()?);
            } else if lookahead.peek(kw::variable) {
                model.variables.push(input.parse()?);
            } else if lookahead.peek(kw::constraint)
                || lookahead.peek(kw::spring)
                || lookahead.peek(kw::damper)
                || lookahead.peek(kw::input)
                || lookahead.peek(kw::ground)
                || lookahead.peek(kw::contact)
            {
                model.elements.push(input.parse()?);
            } else {
                return Err(lookahead.error());
            }
        }
        Ok(Input {
            attrs,
            vis,
            name,
            source: Source::Inline(model),
            lean: None,
            contacts: None,
            enforce_limits: None,
        })
    }
}

impl Parse for InlineFrame {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        input.parse::<kw::frame>()?;
        let name: Ident = input.parse()?;
        input.parse::<Token![=]>()?;
        let primitive: Ident = input.parse()?;
        if tree_model::PrimitiveKind::from_keyword(&primitive.to_string()).is_none() {
            return Err(syn::Error::new(
                primitive.span(),
                format!("unknown primitive `{primitive}`: expected one of tx ty tz rx ry rz"),
            ));
        }
        let content;
        parenthesized!(content in input);
        let argument = if content.peek(Ident) && content.peek2(syn::token::Paren) {
            parse_mimic(&content)?
        } else if content.peek(Ident) {
            Argument::Variable(content.parse()?)
        } else {
            Argument::Constant(parse_number(&content)?)
        };
        if !content.is_empty() {
            return Err(content.error("expected one variable name or one number"));
        }
        let mut frame = InlineFrame {
            name,
            primitive,
            argument,
            mass: None,
            inertia: None,
            com: None,
            children: Vec::new(),
        };
        if input.peek(Token![;]) {
            input.parse::<Token![;]>()?;
            return Ok(frame);
        }
        let body;
        braced!(body in input);
        while !body.is_empty() {
            let lookahead = body.lookahead1();
            if lookahead.peek(kw::mass) {
                let kw: kw::mass = body.parse()?;
                setting_once(&mut frame.mass, kw.span, "mass", &body, parse_number)?;
            } else if lookahead.peek(kw::inertia) {
                let kw: kw::inertia = body.parse()?;
                setting_once(&mut frame.inertia, kw.span, "inertia", &body, |input| {
                    let content;
                    let bracket = bracketed!(content in input);
                    let items = content.parse_terminated(parse_number, Token![,])?;
                    Ok((items.iter().map(|n| n.value).collect(), bracket.span.join()))
                })?;
            } else if lookahead.peek(kw::com) {
                let kw: kw::com = body.parse()?;
                setting_once(&mut frame.com, kw.span, "com", &body, parse_vector3)?;
            } else if lookahead.peek(kw::frame) {
                frame.children.push(body.parse()?);
            } else {
                return Err(lookahead.error());
            }
        }
        Ok(frame)
    }
}

/// `= value;` after a frame setting's keyword (at `keyword`), stored in `slot`; a second one
/// is an error at it.
fn setting_once<T>(
    slot: &mut Option<T>,
    keyword: Span,
    name: &str,
    input: ParseStream,
    value: impl FnOnce(ParseStream) -> syn::Result<T>,
) -> syn::Result<()> {
    if slot.is_some() {
        return Err(syn::Error::new(keyword, format!("{name} is given twice")));
    }
    input.parse::<Token![=]>()?;
    *slot = Some(value(input)?);
    input.parse::<Token![;]>()?;
    Ok(())
}

impl Parse for InlineVariable {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        input.parse::<kw::variable>()?;
        let name: Ident = input.parse()?;
        let settings = parse_settings(input)?;
        Ok(InlineVariable { name, settings })
    }
}

impl Parse for InlineElement {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let lookahead = input.lookahead1();
        let (element, keyword, name, kind) = if lookahead.peek(kw::constraint) {
            let k: kw::constraint = input.parse()?;
            let name: Ident = input.parse()?;
            input.parse::<Token![=]>()?;
            let kind: Ident = input.parse()?;
            (ElementKind::Constraint, k.span, Some(name), Some(kind))
        } else if lookahead.peek(kw::contact) {
            // `contact NAME = sphere(frame) { radius = …; friction = …; collide = …; }`
            let k: kw::contact = input.parse()?;
            let name: Ident = input.parse()?;
            input.parse::<Token![=]>()?;
            let kind: Ident = input.parse()?;
            if kind != "sphere" {
                return Err(syn::Error::new(
                    kind.span(),
                    format!("unknown contact shape `{kind}`: expected sphere(frame)"),
                ));
            }
            (ElementKind::Contact, k.span, Some(name), Some(kind))
        } else if lookahead.peek(kw::ground) {
            // `ground { height = …; normal = […]; friction = …; }` or `ground;`
            let k: kw::ground = input.parse()?;
            return Ok(InlineElement {
                element: ElementKind::Ground,
                keyword: k.span,
                name: None,
                kind: None,
                arguments: Vec::new(),
                settings: parse_settings_or_end(input)?,
            });
        } else if lookahead.peek(kw::spring) {
            let k: kw::spring = input.parse()?;
            (ElementKind::Spring, k.span, None, None)
        } else if lookahead.peek(kw::damper) {
            let k: kw::damper = input.parse()?;
            (ElementKind::Damper, k.span, None, None)
        } else if lookahead.peek(kw::input) {
            // `input NAME = VARIABLE { limits = [lo, hi]; }` or `input NAME = VARIABLE;`
            let k: kw::input = input.parse()?;
            let name: Ident = input.parse()?;
            input.parse::<Token![=]>()?;
            let variable: Ident = input.parse()?;
            return Ok(InlineElement {
                element: ElementKind::Input,
                keyword: k.span,
                name: Some(name),
                kind: None,
                arguments: vec![variable],
                settings: parse_settings_or_end(input)?,
            });
        } else {
            return Err(lookahead.error());
        };
        let content;
        parenthesized!(content in input);
        let arguments = content.parse_terminated(Ident::parse, Token![,])?;
        let settings = parse_settings(input)?;
        Ok(InlineElement {
            element,
            keyword,
            name,
            kind,
            arguments: arguments.into_iter().collect(),
            settings,
        })
    }
}

/// `{ key = value; … }`, or `;` for none.
fn parse_settings_or_end(input: ParseStream) -> syn::Result<Vec<(Ident, Setting)>> {
    if input.peek(Token![;]) {
        input.parse::<Token![;]>()?;
        return Ok(Vec::new());
    }
    parse_settings(input)
}

/// `{ key = value; … }`
fn parse_settings(input: ParseStream) -> syn::Result<Vec<(Ident, Setting)>> {
    let body;
    braced!(body in input);
    let mut settings = Vec::new();
    while !body.is_empty() {
        let key: Ident = body.parse()?;
        body.parse::<Token![=]>()?;
        let value = parse_setting(&body)?;
        body.parse::<Token![;]>()?;
        settings.push((key, value));
    }
    Ok(settings)
}

fn parse_setting(input: ParseStream) -> syn::Result<Setting> {
    if input.peek(syn::LitBool) {
        let b: syn::LitBool = input.parse()?;
        return Ok(Setting::Bool(b.value, b.span));
    }
    if input.peek(LitStr) {
        return Ok(Setting::Text(input.parse()?));
    }
    if input.peek(Ident) && input.peek2(syn::token::Paren) {
        let function: Ident = input.parse()?;
        if function != "sine" {
            return Err(syn::Error::new(
                function.span(),
                format!("unknown motion `{function}`: expected sine(offset = …, amplitude = …, frequency = …, phase = …)"),
            ));
        }
        let content;
        let paren = parenthesized!(content in input);
        let mut terms = Vec::new();
        while !content.is_empty() {
            let key: Ident = content.parse()?;
            content.parse::<Token![=]>()?;
            terms.push((key, parse_number(&content)?));
            if !content.is_empty() {
                content.parse::<Token![,]>()?;
            }
        }
        return Ok(Setting::Sine(terms, paren.span.join()));
    }
    if input.peek(Ident) {
        return Ok(Setting::Name(input.parse()?));
    }
    if input.peek(syn::token::Bracket) {
        let content;
        let bracket = bracketed!(content in input);
        let span = bracket.span.join();
        if content.peek(syn::token::Bracket) {
            let mut pairs = Vec::new();
            while !content.is_empty() {
                let inner;
                let b = bracketed!(inner in content);
                let items = inner.parse_terminated(parse_number, Token![,])?;
                if items.len() != 2 {
                    return Err(syn::Error::new(
                        b.span.join(),
                        format!("expected a pair [t, q], found {} numbers", items.len()),
                    ));
                }
                pairs.push([items[0].value, items[1].value]);
                if !content.is_empty() {
                    content.parse::<Token![,]>()?;
                }
            }
            return Ok(Setting::Pairs(pairs, span));
        }
        let items = content.parse_terminated(parse_number, Token![,])?;
        return Ok(Setting::Vector(items.into_iter().collect(), span));
    }
    Ok(Setting::Number(parse_number(input)?))
}
