//! The expansion: a unit struct with named constants for its variables and frames, and an
//! `impl System` whose evaluations are the runtime's recursions traced for this one tree.

use std::collections::HashMap;

use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use tree_model::{Joint, Model};
use tree_runtime::plan::TreePlan;
use tree_runtime::se3::Pose;
use tree_runtime::sweeps::{self, TermsSink, Workspace};
use tree_runtime::Order;

use crate::ast::{Input, Source};
use crate::lower;
use crate::program::{constant, Program};
use crate::trace::{self, Term};

/// Collects `(target, value)` pairs as the recursions hand out their results.
#[derive(Default)]
struct Recorder(Vec<(TokenStream, Term)>);

impl TermsSink<Term> for Recorder {
    fn set_l(&mut self, l: Term) {
        self.0.push((quote!(out.l), l));
    }
    fn set_dl_dq(&mut self, i: usize, x: Term) {
        self.0.push((quote!(out.dl_dq[#i]), x));
    }
    fn set_dl_ddq(&mut self, i: usize, x: Term) {
        self.0.push((quote!(out.dl_ddq[#i]), x));
    }
    fn set_mass(&mut self, i: usize, j: usize, x: Term) {
        self.0.push((quote!(out.mass[(#i, #j)]), x));
    }
    fn set_d2l_ddq_dq(&mut self, i: usize, j: usize, x: Term) {
        self.0.push((quote!(out.d2l_ddq_dq[(#i, #j)]), x));
    }
    fn set_d2l_dq_dq(&mut self, i: usize, j: usize, x: Term) {
        self.0.push((quote!(out.d2l_dq_dq[(#i, #j)]), x));
    }
}

/// The Lagrangian terms up to `order`, traced.
fn lagrangian_program(plan: &TreePlan, order: Order) -> Program {
    let n = plan.dof();
    let (nodes, outputs) = trace::record(|| {
        let q: Vec<Term> = (0..n).map(trace::q).collect();
        let dq: Vec<Term> = (0..n).map(trace::dq).collect();
        let mut ws = Workspace::<Term>::new(plan);
        let mut out = Recorder::default();
        sweeps::evaluate(plan, &mut ws, &q, &dq, order, &mut out);
        out.0
    });
    Program { nodes, outputs }
}

/// Every frame's pose, traced.
fn poses_program(plan: &TreePlan) -> Program {
    let n = plan.dof();
    let (nodes, outputs) = trace::record(|| {
        let q: Vec<Term> = (0..n).map(trace::q).collect();
        let mut poses = vec![Pose::<Term>::identity(); plan.pose_frames.len()];
        sweeps::poses(plan, &q, &mut poses);
        let mut outputs = Vec::new();
        for (k, g) in poses.iter().enumerate() {
            for i in 0..3 {
                for j in 0..3 {
                    outputs.push((quote!(out[#k].r[#i][#j]), g.r[i][j]));
                }
                outputs.push((quote!(out[#k].p[#i]), g.p[i]));
            }
        }
        outputs
    });
    Program { nodes, outputs }
}

/// `theta1` → `THETA1`; anything not alphanumeric becomes `_`.
fn constant_name(prefix: &str, name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_uppercase()
            } else {
                '_'
            }
        })
        .collect();
    if prefix.is_empty() && s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    format!("{prefix}{s}")
}

/// Associated items the expansion defines itself.
const RESERVED: [&str; 7] = [
    "DOF",
    "VARIABLES",
    "FRAMES",
    "Q0",
    "DQ0",
    "DAMPING",
    "STATEMENTS",
];

/// Named index constants, failing on two names that map to one constant or on a reserved one.
fn index_constants(
    prefix: &str,
    names: &[&str],
    what: &str,
    span: Span,
) -> syn::Result<TokenStream> {
    let mut seen: HashMap<String, &str> = HashMap::new();
    let mut out = TokenStream::new();
    for (i, name) in names.iter().enumerate() {
        let c = constant_name(prefix, name);
        if RESERVED.contains(&c.as_str()) {
            return Err(syn::Error::new(
                span,
                format!("{what} `{name}` would become the constant `{c}`, which tree_model! already defines; rename it"),
            ));
        }
        if let Some(other) = seen.insert(c.clone(), name) {
            return Err(syn::Error::new(
                span,
                format!(
                    "{what}s `{other}` and `{name}` both become the constant `{c}`; rename one"
                ),
            ));
        }
        let id = format_ident!("{}", c);
        let doc = format!("Index of {what} `{name}`.");
        out.extend(quote!(#[doc = #doc] pub const #id: usize = #i;));
    }
    Ok(out)
}

/// `Model` rebuilt by the builder, so `Name::model()` gives the interpreted twin.
fn model_constructor(model: &Model) -> TokenStream {
    let name = &model.name;
    let g = model.gravity.map(constant);
    let mut calls = quote!(.gravity([#(#g),*]));
    for f in &model.frames {
        let fname = &f.name;
        let parent = f.parent.map_or("world", |p| model.frames[p].name.as_str());
        let kind = format_ident!("{}", format!("{:?}", f.primitive));
        let value = match f.joint {
            Joint::Constant(x) => constant(x),
            Joint::Variable(i) => {
                let v = &model.variables[i].name;
                quote!(#v)
            }
        };
        calls.extend(
            quote!(.frame(#fname, #parent, ::tree_mech::tree_model::PrimitiveKind::#kind, #value)),
        );
        if let Some(m) = f.mass {
            let (mass, inertia) = (constant(m.mass), m.inertia.map(constant));
            calls.extend(quote!(.mass(#fname, #mass, [#(#inertia),*])));
        }
    }
    for v in &model.variables {
        let (vname, q0, dq0, c) = (
            &v.name,
            constant(v.q0),
            constant(v.dq0),
            constant(v.damping),
        );
        calls.extend(quote!(.initial(#vname, #q0, #dq0).damping(#vname, #c)));
    }
    quote! {
        ::tree_mech::tree_model::ModelBuilder::new(#name)
            #calls
            .build()
            .expect("the model was validated when it was compiled")
    }
}

pub fn expand(input: Input) -> syn::Result<TokenStream> {
    let (model, file) = match &input.source {
        Source::File(path) => {
            let (model, full) = lower::from_file(path)?;
            (model, Some(full))
        }
        Source::Inline(inline) => (lower::from_inline(&input.name, inline)?, None),
    };
    let (attrs, vis, name) = (&input.attrs, &input.vis, &input.name);
    let plan = TreePlan::folded(&model);
    let n = model.dof();
    let nf = model.frames.len();

    let var_names: Vec<&str> = model.variables.iter().map(|v| v.name.as_str()).collect();
    let frame_names: Vec<&str> = model.frames.iter().map(|f| f.name.as_str()).collect();
    let var_consts = index_constants("", &var_names, "variable", name.span())?;
    let frame_consts = index_constants("FRAME_", &frame_names, "frame", name.span())?;
    let q0: Vec<TokenStream> = model.variables.iter().map(|v| constant(v.q0)).collect();
    let dq0: Vec<TokenStream> = model.variables.iter().map(|v| constant(v.dq0)).collect();
    let damping: Vec<TokenStream> = model
        .variables
        .iter()
        .map(|v| constant(v.damping))
        .collect();

    let terms_ty = quote!(::tree_mech::runtime::Terms<::tree_mech::runtime::nalgebra::Const<#n>>);
    let first = lagrangian_program(&plan, Order::First).emit("__first", n, &terms_ty);
    let dynamics = lagrangian_program(&plan, Order::Dynamics).emit("__dynamics", n, &terms_ty);
    let full = lagrangian_program(&plan, Order::Full).emit("__full", n, &terms_ty);
    let poses = poses_program(&plan).emit("__poses", n, &quote!([::tree_mech::runtime::Pose]));
    let functions = [
        &first.functions,
        &dynamics.functions,
        &full.functions,
        &poses.functions,
    ];
    let (first_body, dynamics_body, full_body, poses_body) =
        (&first.body, &dynamics.body, &full.body, &poses.body);
    let statements = full.statements;
    let constructor = model_constructor(&model);
    let rebuild = file.map(|path| {
        let path = path.to_string_lossy().into_owned();
        quote!(
            const _: &[u8] = include_bytes!(#path);
        )
    });
    let doc = format!(
        "The `{}` model compiled by `tree_model!`: {} variables ({}), {} frames. Its full \
         evaluation is {} straight-line statements.",
        model.name,
        n,
        var_names.join(", "),
        nf,
        statements
    );

    Ok(quote! {
        #(#attrs)*
        #[doc = #doc]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        #vis struct #name;

        #rebuild

        impl #name {
            /// Number of configuration variables.
            pub const DOF: usize = #n;
            /// Variable names, in the order of every vector and matrix.
            pub const VARIABLES: [&'static str; #n] = [#(#var_names),*];
            /// Frame names, parents before children.
            pub const FRAMES: [&'static str; #nf] = [#(#frame_names),*];
            /// Initial configuration from the model.
            pub const Q0: [f64; #n] = [#(#q0),*];
            /// Initial velocity from the model.
            pub const DQ0: [f64; #n] = [#(#dq0),*];
            /// Damping coefficients.
            pub const DAMPING: [f64; #n] = [#(#damping),*];
            /// Statements in one full (second-order) evaluation.
            pub const STATEMENTS: usize = #statements;
            #var_consts
            #frame_consts

            /// The system (it holds no state: everything lives on the stack per evaluation).
            pub const fn new() -> Self {
                #name
            }

            /// The same model for the interpreted runtime (`TreeSystem::new(&Self::model(), …)`).
            pub fn model() -> ::tree_mech::tree_model::Model {
                #constructor
            }

            #(#functions)*
        }

        impl ::tree_mech::runtime::System for #name {
            type N = ::tree_mech::runtime::nalgebra::Const<#n>;

            fn dim(&self) -> Self::N {
                ::tree_mech::runtime::nalgebra::Const::<#n>
            }

            fn variable_name(&self, i: usize) -> &str {
                Self::VARIABLES[i]
            }

            fn frame_count(&self) -> usize {
                #nf
            }

            fn frame_name(&self, k: usize) -> &str {
                Self::FRAMES[k]
            }

            fn initial(&self, i: usize) -> (f64, f64) {
                (Self::Q0[i], Self::DQ0[i])
            }

            fn damping(&self, i: usize) -> f64 {
                Self::DAMPING[i]
            }

            fn lagrangian(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                dq: &::tree_mech::runtime::Vector<Self::N>,
                order: ::tree_mech::runtime::Order,
                out: &mut ::tree_mech::runtime::Terms<Self::N>,
            ) {
                out.clear(order);
                let q: &[f64; #n] = &q.data.0[0];
                let dq: &[f64; #n] = &dq.data.0[0];
                match order {
                    ::tree_mech::runtime::Order::First => { #first_body }
                    ::tree_mech::runtime::Order::Dynamics => { #dynamics_body }
                    ::tree_mech::runtime::Order::Full => { #full_body }
                }
            }

            fn poses(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                out: &mut [::tree_mech::runtime::Pose],
            ) {
                assert_eq!(out.len(), #nf, "poses() needs one slot per frame");
                let q: &[f64; #n] = &q.data.0[0];
                let dq = q;
                #poses_body
            }
        }
    })
}
