//! The macro's input: a header naming the generated type, then either a model file or the
//! inline tree syntax. Every piece keeps its span so validation errors point at it.

use proc_macro2::Span;
use syn::parse::{Parse, ParseStream};
use syn::{braced, bracketed, parenthesized, Ident, LitStr, Token, Visibility};

mod kw {
    syn::custom_keyword!(from);
    syn::custom_keyword!(gravity);
    syn::custom_keyword!(frame);
    syn::custom_keyword!(mass);
    syn::custom_keyword!(inertia);
    syn::custom_keyword!(variable);
}

/// `tree_model!(pub struct Name from "file.toml")` or `tree_model! { pub struct Name; … }`.
pub struct Input {
    /// Outer attributes (doc comments) for the generated struct.
    pub attrs: Vec<syn::Attribute>,
    pub vis: Visibility,
    pub name: Ident,
    pub source: Source,
}

pub enum Source {
    File(LitStr),
    Inline(InlineModel),
}

/// The inline tree.
pub struct InlineModel {
    pub gravity: Option<([f64; 3], Span)>,
    pub frames: Vec<InlineFrame>,
    pub variables: Vec<InlineVariable>,
}

/// A number with the span it was written at.
#[derive(Clone, Copy)]
pub struct Number {
    pub value: f64,
    pub span: Span,
}

/// `frame name = rx(theta) { mass = 1.0; inertia = [..]; frame … }`
pub struct InlineFrame {
    pub name: Ident,
    pub primitive: Ident,
    pub argument: Argument,
    pub mass: Option<Number>,
    pub inertia: Option<([f64; 3], Span)>,
    pub children: Vec<InlineFrame>,
}

pub enum Argument {
    Variable(Ident),
    Constant(Number),
}

/// `variable theta { q0 = 0.5; dq0 = 0.0; damping = 0.1; }`
pub struct InlineVariable {
    pub name: Ident,
    pub settings: Vec<(Ident, Setting)>,
}

pub enum Setting {
    Number(Number),
    Bool(bool),
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
            input.parse::<Option<Token![;]>>()?;
            if !input.is_empty() {
                return Err(input.error("unexpected tokens after the model file path"));
            }
            return Ok(Input {
                attrs,
                vis,
                name,
                source: Source::File(path),
            });
        }
        input.parse::<Token![;]>()?;
        let mut model = InlineModel {
            gravity: None,
            frames: Vec::new(),
            variables: Vec::new(),
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
            } else if lookahead.peek(kw::frame) {
                model.frames.push(input.parse()?);
            } else if lookahead.peek(kw::variable) {
                model.variables.push(input.parse()?);
            } else {
                return Err(lookahead.error());
            }
        }
        Ok(Input {
            attrs,
            vis,
            name,
            source: Source::Inline(model),
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
        let argument = if content.peek(Ident) {
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
                if frame.mass.is_some() {
                    return Err(syn::Error::new(kw.span, "mass is given twice"));
                }
                body.parse::<Token![=]>()?;
                frame.mass = Some(parse_number(&body)?);
                body.parse::<Token![;]>()?;
            } else if lookahead.peek(kw::inertia) {
                let kw: kw::inertia = body.parse()?;
                if frame.inertia.is_some() {
                    return Err(syn::Error::new(kw.span, "inertia is given twice"));
                }
                body.parse::<Token![=]>()?;
                frame.inertia = Some(parse_vector3(&body)?);
                body.parse::<Token![;]>()?;
            } else if lookahead.peek(kw::frame) {
                frame.children.push(body.parse()?);
            } else {
                return Err(lookahead.error());
            }
        }
        Ok(frame)
    }
}

impl Parse for InlineVariable {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        input.parse::<kw::variable>()?;
        let name: Ident = input.parse()?;
        let body;
        braced!(body in input);
        let mut settings = Vec::new();
        while !body.is_empty() {
            let key: Ident = body.parse()?;
            body.parse::<Token![=]>()?;
            let value = if body.peek(syn::LitBool) {
                Setting::Bool(body.parse::<syn::LitBool>()?.value)
            } else {
                Setting::Number(parse_number(&body)?)
            };
            body.parse::<Token![;]>()?;
            settings.push((key, value));
        }
        Ok(InlineVariable { name, settings })
    }
}
