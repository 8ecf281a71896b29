//! The expansion: a unit struct with named constants for its variables and frames, and an
//! `impl System` whose evaluations are the runtime's recursions traced for this one tree.

use std::collections::HashMap;

use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use tree_model::{ModelSpec, ParameterSpec, Value};
use tree_runtime::articulated::{self, Articulated};
use tree_runtime::kernel::{self, Kernel};
use tree_runtime::outputs::{Index, Output, Sink};
use tree_runtime::plan::TreePlan;
use tree_runtime::se3::Pose;
use tree_runtime::sweeps;
use tree_runtime::Order;

use crate::ast::{Input, Source};
use crate::lower;
use crate::program::{constant, identifier_part, Flavour, Program};
use crate::trace::{self, Term};

/// Collects what the recursions hand out, summing the contributions to each output, in the
/// order the outputs first appear.
#[derive(Default)]
struct Recorder {
    slots: HashMap<Output, usize>,
    values: Vec<(Output, Term)>,
}

impl Sink<Term> for Recorder {
    fn add(&mut self, at: Output, x: Term) {
        match self.slots.get(&at) {
            Some(&k) => self.values[k].1 += x,
            None => {
                self.slots.insert(at, self.values.len());
                self.values.push((at, x));
            }
        }
    }
}

impl Recorder {
    /// The value recorded for `at`, if anything contributed to it.
    fn get(&self, at: Output) -> Option<Term> {
        self.slots.get(&at).map(|&k| self.values[k].1)
    }
}

/// The traced inputs `q` and `q̇` of a tree with `n` variables.
fn state_inputs(n: usize) -> (Vec<Term>, Vec<Term>) {
    (
        (0..n).map(trace::q).collect(),
        (0..n).map(trace::dq).collect(),
    )
}

/// A traced evaluation: the tape and the value that lands in each output.
#[derive(Clone)]
struct Traced {
    nodes: Vec<trace::Node>,
    outputs: Vec<(Output, Term)>,
}

impl Traced {
    /// The program that assigns every output to its storage (`out.mass[(0, 1)] = …`, the
    /// one table of outputs and their storage) — for [`Flavour::F64`].
    fn assigning(&self) -> Program {
        let outputs = self
            .outputs
            .iter()
            .map(|&(at, x)| {
                let (field, index) = at.slot();
                let field = proc_macro2::Ident::new(field.name(), proc_macro2::Span::call_site());
                let target = match index {
                    Index::Scalar => quote!(out.#field),
                    Index::Entry(i) => quote!(out.#field[#i]),
                    Index::Pair(i, j) => quote!(out.#field[(#i, #j)]),
                    Index::Stacked(r, i, j) => quote!(out.#field[#r][(#i, #j)]),
                };
                (target, x)
            })
            .collect();
        Program {
            nodes: self.nodes.clone(),
            outputs,
        }
    }

    /// The program that hands every output to a sink by name (`Output::Mass(0, 1)`) — for
    /// [`Flavour::Generic`].
    fn naming(&self) -> Program {
        let outputs = self
            .outputs
            .iter()
            .map(|&(at, x)| {
                // An output's derived `Debug` is its constructor expression.
                let path = format!("::tree_mech::runtime::outputs::Output::{at:?}");
                let target: TokenStream = path.parse().expect("an output names a constructor");
                (target, x)
            })
            .collect();
        Program {
            nodes: self.nodes.clone(),
            outputs,
        }
    }
}

/// One of the runtime's evaluations over the tree (`sweeps::evaluate`, `sweeps::constraints`).
type Evaluation = fn(&TreePlan, &mut Kernel<Term>, &[Term], &[Term], Order, &mut Recorder);

/// `evaluation` up to `order`, traced.
fn traced(plan: &TreePlan, order: Order, evaluation: Evaluation) -> Traced {
    let n = plan.dof();
    let (nodes, outputs) = trace::record(|| {
        let (q, dq) = state_inputs(n);
        let mut ws = Kernel::<Term>::new(plan);
        let mut out = Recorder::default();
        evaluation(plan, &mut ws, &q, &dq, order, &mut out);
        out.values
    });
    Traced { nodes, outputs }
}

/// The constraints' `h`, `Dh` and `Σ_r w_r D²h_r` on the dynamic variables' columns
/// (`kernel::weighted_constraint_hessian`, the weights `out.weights[r]` an input), the
/// entries some row's Hessian reaches assigned — the others cleared first unless the terms
/// are kept from this model's last evaluation (`ConstraintTerms::weigh_assigned`) — for
/// [`Flavour::F64`]; and the same evaluation handing its outputs to a sink by name
/// (accumulated: the sink is cleared first), for [`Flavour::Generic`]. `None` without
/// constraints.
fn weighted_program(plan: &TreePlan, kinematic: &[bool]) -> Option<(Program, Program)> {
    if plan.rows == 0 {
        return None;
    }
    let n = plan.dof();
    let columns: Vec<bool> = kinematic.iter().map(|&k| !k).collect();
    let (nodes, outputs) = trace::record(|| {
        let (q, _) = state_inputs(n);
        let weights: Vec<Term> = (0..plan.rows).map(trace::weight).collect();
        let mut k = Kernel::<Term>::new(plan);
        let mut out = Recorder::default();
        kernel::weighted_constraint_hessian(plan, &mut k, &q, &q, &weights, &columns, &mut out);
        out.values
    });
    // Assigned or handed to a sink that accumulates, a zero is the cleared entry's own.
    let nonzero = (outputs.into_iter())
        .filter(|(_, t)| !matches!(t, Term::Const(c) if *c == 0.0))
        .collect();
    let traced = Traced {
        nodes,
        outputs: nonzero,
    };
    Some((traced.clone().assigning(), traced.naming()))
}

/// The articulated-body step traced as the interpreted system runs it: the elements' forces
/// (`kernel::elements_at`, its outward sweep included) added to `τ`, then
/// `articulated::accelerations` — each dynamic variable's `q̈`, pivot and pivot scale into
/// an `ArticulatedIo`. `None` with constraints (their multipliers need the KKT system) or a
/// dynamic variable the algorithm cannot resolve: the default then solves with `M`.
fn articulated_program(plan: &TreePlan, kinematic: &[bool]) -> Option<Program> {
    if plan.rows > 0 || !articulated::resolvable(plan, kinematic) {
        return None;
    }
    let n = plan.dof();
    let (nodes, outputs) = trace::record(|| {
        let (q, dq) = state_inputs(n);
        let mut k = Kernel::<Term>::new(plan);
        let mut own = Recorder::default();
        kernel::elements_at(plan, &mut k, &q, &dq, &mut own);
        let own_term = |at: Output| own.get(at).unwrap_or(Term::Const(0.0));
        // τ + F + ∂L/∂q of the elements, in the interpreted system's order.
        let tau: Vec<Term> = (0..n)
            .map(|i| trace::tau(i) + own_term(Output::Force(i)) + own_term(Output::DlDq(i)))
            .collect();
        let mut qdd: Vec<Term> = (0..n)
            .map(|i| match kinematic[i] {
                true => trace::kinematic_qdd(i),
                false => Term::Const(0.0),
            })
            .collect();
        let mut art = Articulated::<Term>::new(plan);
        articulated::accelerations(plan, &k.tree, &mut art, &dq, &tau, kinematic, &mut qdd);
        let mut outputs = Vec::new();
        for i in 0..n {
            for (at, field) in [
                (Output::Force(i), quote!(force)),
                (Output::DlDq(i), quote!(dl_dq)),
            ] {
                if let Some(x) = own.get(at) {
                    outputs.push((quote!(out.#field[#i]), x));
                }
            }
        }
        for (i, f) in plan.variable_frames.iter().enumerate() {
            if let (false, Some(f)) = (kinematic[i], *f) {
                outputs.push((quote!(out.qdd[#i]), qdd[i]));
                outputs.push((quote!(out.pivot[#i]), art.pivot[f]));
                outputs.push((quote!(out.pivot_scale[#i]), art.pivot_scale[f]));
            }
        }
        outputs
    });
    Some(Program { nodes, outputs })
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
    let mut s = identifier_part(name).to_uppercase();
    if prefix.is_empty() && s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    format!("{prefix}{s}")
}

/// Associated items the expansion defines itself.
const RESERVED: [&str; 11] = [
    "DOF",
    "INPUTS",
    "INPUT_VARIABLES",
    "VARIABLES",
    "FRAMES",
    "Q0",
    "DQ0",
    "DAMPING",
    "STATEMENTS",
    "CONSTRAINTS",
    "KINEMATIC",
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

/// `Model` rebuilt at run time, so `Name::model()` gives the interpreted twin: a file model
/// is read again from the text compiled in, an inline one validated again from its spec —
/// either way through the one validator, so every field the spec has is carried over.
fn model_constructor(
    spec: Option<&ModelSpec>,
    file: Option<(&str, &str)>,
    floating_base: bool,
) -> TokenStream {
    if let Some((path, shown)) = file {
        if lower::is_urdf(shown) {
            return quote! {
                ::tree_mech::model::from_urdf_str(
                    include_str!(#path),
                    Some(#shown),
                    ::tree_mech::model::UrdfOptions { floating_base: #floating_base },
                )
                .expect("the model was validated when it was compiled")
            };
        }
        return quote! {
            ::tree_mech::model::from_toml_str(include_str!(#path), Some(#shown))
                .expect("the model was validated when it was compiled")
        };
    }
    let spec = spec_tokens(spec.expect("an inline model has its spec"));
    quote! {
        ::tree_mech::model::validate(&#spec)
            .ok()
            .expect("the model was validated when it was compiled")
    }
}

/// Rust tokens that build `spec` (a `ModelSpec` literal).
fn spec_tokens(spec: &ModelSpec) -> TokenStream {
    let m = quote!(::tree_mech::model);
    let opt = |x: Option<f64>| match x {
        Some(x) => {
            let x = constant(x);
            quote!(Some(#x))
        }
        None => quote!(None),
    };
    let opt3 = |x: Option<[f64; 3]>| match x {
        Some(v) => {
            let v = v.map(constant);
            quote!(Some([#(#v),*]))
        }
        None => quote!(None),
    };
    let string = |x: &str| quote!(::std::string::String::from(#x));
    let opt_string = |x: Option<&str>| match x {
        Some(x) => {
            let x = string(x);
            quote!(Some(#x))
        }
        None => quote!(None),
    };
    let strings = |xs: &[String]| {
        let xs = xs.iter().map(|x| string(x));
        quote!(::std::vec![#(#xs),*])
    };
    let frames = spec.frames.iter().map(|f| {
        let primitives = f.primitives.iter().map(|p| {
            let kind = format_ident!("{}", format!("{:?}", p.kind));
            let value = match &p.value {
                Value::Constant(x) => {
                    let x = constant(*x);
                    quote!(#m::Value::Constant(#x))
                }
                Value::Variable(v) => {
                    let v = string(v);
                    quote!(#m::Value::Variable(#v))
                }
            };
            quote!(#m::Primitive { kind: #m::PrimitiveKind::#kind, value: #value })
        });
        let (name, parent) = (string(&f.name), opt_string(f.parent.as_deref()));
        let (mass, com) = (opt(f.mass), opt3(f.com));
        let inertia = match &f.inertia {
            Some(v) => {
                let v = v.iter().map(|x| constant(*x));
                quote!(Some(::std::vec![#(#v),*]))
            }
            None => quote!(None),
        };
        quote!(#m::FrameSpec {
            name: #name,
            parent: #parent,
            primitives: ::std::vec![#(#primitives),*],
            mass: #mass,
            com: #com,
            inertia: #inertia,
        })
    });
    let variables = spec.variables.iter().map(|v| {
        let name = string(&v.name);
        let (q0, dq0, damping) = (opt(v.q0), opt(v.dq0), opt(v.damping));
        let kinematic = match v.kinematic {
            Some(b) => quote!(Some(#b)),
            None => quote!(None),
        };
        let motion = match &v.motion {
            Some(s) => {
                let (o, a, f, p) = (
                    opt(s.offset),
                    opt(s.amplitude),
                    opt(s.frequency),
                    opt(s.phase),
                );
                quote!(Some(#m::SineSpec { offset: #o, amplitude: #a, frequency: #f, phase: #p }))
            }
            None => quote!(None),
        };
        let samples = match &v.samples {
            Some(pairs) => {
                let pairs = pairs.iter().map(|[t, q]| {
                    let (t, q) = (constant(*t), constant(*q));
                    quote!([#t, #q])
                });
                quote!(Some(::std::vec![#(#pairs),*]))
            }
            None => quote!(None),
        };
        let limits = match v.limits {
            Some([lo, hi]) => {
                let (lo, hi) = (constant(lo), constant(hi));
                quote!(Some([#lo, #hi]))
            }
            None => quote!(None),
        };
        quote!(#m::VariableSpec {
            name: #name, q0: #q0, dq0: #dq0, damping: #damping, kinematic: #kinematic,
            motion: #motion, samples: #samples, limits: #limits,
        })
    });
    let constraints = spec.constraints.iter().map(|c| {
        let (name, kind, frames) = (opt_string(c.name.as_deref()), string(&c.kind), strings(&c.frames));
        let length = match &c.length {
            Some(ParameterSpec::Constant(x)) => {
                let x = constant(*x);
                quote!(Some(#m::ParameterSpec::Constant(#x)))
            }
            Some(ParameterSpec::Variable(v)) => {
                let v = string(v);
                quote!(Some(#m::ParameterSpec::Variable(#v)))
            }
            None => quote!(None),
        };
        let (normal, axes) = (opt3(c.normal), opt_string(c.axes.as_deref()));
        quote!(#m::ConstraintSpec {
            name: #name, kind: #kind, frames: #frames, length: #length, normal: #normal, axes: #axes,
        })
    });
    let springs = spec.springs.iter().map(|s| {
        let frames = match &s.frames {
            Some(f) => {
                let f = strings(f);
                quote!(Some(#f))
            }
            None => quote!(None),
        };
        let variable = opt_string(s.variable.as_deref());
        let (stiffness, rest) = (opt(s.stiffness), opt(s.rest));
        quote!(#m::SpringSpec { frames: #frames, variable: #variable, stiffness: #stiffness, rest: #rest })
    });
    let dampers = spec.dampers.iter().map(|d| {
        let (frames, damping) = (strings(&d.frames), opt(d.damping));
        quote!(#m::DamperSpec { frames: #frames, damping: #damping })
    });
    let inputs = spec.inputs.iter().map(|u| {
        let (name, variable) = (string(&u.name), opt_string(u.variable.as_deref()));
        let limits = match u.limits {
            Some(l) => {
                let [lo, hi] = l.map(constant);
                quote!(Some([#lo, #hi]))
            }
            None => quote!(None),
        };
        quote!(#m::InputSpec { name: #name, variable: #variable, limits: #limits })
    });
    let name = string(&spec.name);
    let gravity = opt3(spec.gravity);
    quote!(#m::ModelSpec {
        name: #name,
        gravity: #gravity,
        frames: ::std::vec![#(#frames),*],
        variables: ::std::vec![#(#variables),*],
        constraints: ::std::vec![#(#constraints),*],
        springs: ::std::vec![#(#springs),*],
        dampers: ::std::vec![#(#dampers),*],
        inputs: ::std::vec![#(#inputs),*],
    })
}

pub fn expand(input: Input) -> syn::Result<TokenStream> {
    let (model, spec, file) = match &input.source {
        Source::File(path, floating_base) => {
            let (model, full) = lower::from_file(path, *floating_base)?;
            (model, None, Some((full, path.value())))
        }
        Source::Inline(inline) => {
            let (model, spec) = lower::from_inline(&input.name, inline)?;
            (model, Some(spec), None)
        }
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
    let constraint_ty = quote!(::tree_mech::runtime::ConstraintTerms);
    let (f64_terms, f64_constraints, generic) = (
        Flavour::F64 {
            out_ty: &terms_ty,
            scratch: true,
        },
        Flavour::F64 {
            out_ty: &constraint_ty,
            scratch: true,
        },
        Flavour::Generic,
    );
    let lagrangian: Evaluation = kernel::evaluate;
    let constraints: Evaluation = kernel::constraints;
    // `M(q)` and `L(q, 0)` alone (`System::mass_matrix`): the sweeps at rest, no velocity.
    let mass: Evaluation = |plan, k, q, _, _, out| kernel::mass(plan, k, q, out);
    // `E = T + V` alone (`System::energy`): velocities and first moments, no columns.
    let energy: Evaluation = |plan, k, q, dq, _, out| kernel::energy(plan, k, q, dq, out);
    // Every evaluation over f64; those the linearisations differentiate also generic (only
    // instantiated, over dual numbers, where a program differentiates this model).
    let [l_first, l_dynamics, l_full] =
        [Order::First, Order::Dynamics, Order::Full].map(|o| traced(&plan, o, lagrangian));
    let [c_first, c_dynamics, c_full] =
        [Order::First, Order::Dynamics, Order::Full].map(|o| traced(&plan, o, constraints));
    let first = l_first.assigning().emit("__first", &var_names, f64_terms);
    let mass = traced(&plan, Order::Dynamics, mass)
        .assigning()
        .emit("__mass", &var_names, f64_terms);
    let energy = traced(&plan, Order::First, energy)
        .assigning()
        .emit("__energy", &var_names, f64_terms);
    let dynamics = l_dynamics
        .assigning()
        .emit("__dynamics", &var_names, f64_terms);
    let full = l_full.assigning().emit("__full", &var_names, f64_terms);
    let d_dynamics = l_dynamics
        .naming()
        .emit("__d_dynamics", &var_names, generic);
    let d_full = l_full.naming().emit("__d_full", &var_names, generic);
    let poses = poses_program(&plan).emit(
        "__poses",
        &var_names,
        Flavour::F64 {
            out_ty: &quote!([::tree_mech::runtime::Pose]),
            scratch: false,
        },
    );
    let dc_dynamics = c_dynamics
        .naming()
        .emit("__dc_dynamics", &var_names, generic);
    let dc_full = c_full.naming().emit("__dc_full", &var_names, generic);
    let c_first = c_first
        .assigning()
        .emit("__c_first", &var_names, f64_constraints);
    let c_dynamics = c_dynamics
        .assigning()
        .emit("__c_dynamics", &var_names, f64_constraints);
    let c_full = c_full
        .assigning()
        .emit("__c_full", &var_names, f64_constraints);
    let kinematic: Vec<bool> = model.variables.iter().map(|v| v.is_kinematic()).collect();
    let weighted_program = weighted_program(&plan, &kinematic);
    let weighted = (weighted_program.as_ref())
        .map(|(assigning, _)| assigning.emit("__c_weighted", &var_names, f64_constraints));
    let weighted_dual = (weighted_program.as_ref())
        .map(|(_, naming)| naming.emit("__dc_weighted", &var_names, generic));
    let weighted_functions = weighted.as_ref().map(|e| e.functions.clone());
    let weighted_dual_functions = weighted_dual.as_ref().map(|e| e.functions.clone());
    let weighted_dual_method = weighted_dual.as_ref().map(|e| {
        let body = &e.body;
        let arrays = {
            let wrong = "weighted_constraint_hessian_dual takes one dual number per variable ({})";
            quote! {
                let q: &[::tree_mech::runtime::dual::Dual; #n] = match q.try_into() {
                    Ok(q) => q,
                    _ => panic!(#wrong, #n),
                };
            }
        };
        quote! {
            fn weighted_constraint_hessian_dual(
                &mut self,
                q: &[::tree_mech::runtime::dual::Dual],
                weights: &[::tree_mech::runtime::dual::Dual],
                out: &mut ::tree_mech::runtime::dual::DualOutputs,
            ) {
                out.weigh(weights);
                #arrays
                // The traced sweeps read no velocity.
                let dq = q;
                #body
            }
        }
    });
    let weighted_method = weighted.as_ref().map(|e| {
        let body = &e.body;
        quote! {
            fn weighted_constraint_hessian(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                weights: &[f64],
                out: &mut ::tree_mech::runtime::ConstraintTerms,
            ) {
                // The entries the constraints reach are assigned, the rest cleared unless
                // kept from this model's last evaluation (`weigh_assigned`). A static's
                // address is this model's own.
                static MODEL: u8 = 0;
                out.weigh_assigned(weights, ::core::ptr::addr_of!(MODEL) as usize);
                let q: &[f64; #n] = &q.data.0[0];
                // The traced sweeps read no velocity.
                let dq = q;
                #body
            }
        }
    });
    let functions = [
        &first.functions,
        &mass.functions,
        &energy.functions,
        &dynamics.functions,
        &full.functions,
        &poses.functions,
        &c_first.functions,
        &c_dynamics.functions,
        &c_full.functions,
        &d_dynamics.functions,
        &d_full.functions,
        &dc_dynamics.functions,
        &dc_full.functions,
    ];
    let (d_dynamics_body, d_full_body, dc_dynamics_body, dc_full_body) = (
        &d_dynamics.body,
        &d_full.body,
        &dc_dynamics.body,
        &dc_full.body,
    );
    let (c_first_body, c_dynamics_body, c_full_body) =
        (&c_first.body, &c_dynamics.body, &c_full.body);
    let rows = plan.rows;
    let constraint_names = model.constraint_row_names();
    let constraint_variables = plan.constraint_variables();
    let inputs = model.inputs.len();
    let input_names: Vec<&str> = model.inputs.iter().map(|u| u.name.as_str()).collect();
    let input_variables: Vec<usize> = model.inputs.iter().map(|u| u.variable).collect();
    let (first_body, dynamics_body, full_body, poses_body, mass_body, energy_body) = (
        &first.body,
        &dynamics.body,
        &full.body,
        &poses.body,
        &mass.body,
        &energy.body,
    );
    let statements = full.statements;
    // Where the Full evaluation writes force derivatives (elements::forces): dampers fill
    // both matrices, per-variable damping only ∂F/∂q̇'s diagonal.
    let sparsity = if !plan.dampers.is_empty() {
        Some(quote!(Dense))
    } else if plan.damping.iter().any(|&c| c != 0.0) {
        Some(quote!(Diagonal))
    } else {
        None
    };
    let mark_force_derivatives = sparsity
        .map(|s| quote!(out.force_derivatives = ::tree_mech::runtime::system::Sparsity::#s;));
    // A dual evaluation's slices as arrays of the model's size (a panic naming the method
    // otherwise).
    let dual_arrays = |method: &str| {
        let wrong = format!("{method} takes one dual number per variable ({{}})");
        quote! {
            let (q, dq): (&[::tree_mech::runtime::dual::Dual; #n], &[::tree_mech::runtime::dual::Dual; #n]) =
                match (q.try_into(), dq.try_into()) {
                    (Ok(q), Ok(dq)) => (q, dq),
                    _ => panic!(#wrong, #n),
                };
        }
    };
    let (evaluate_arrays, constraints_arrays) = (
        dual_arrays("evaluate_dual"),
        dual_arrays("constraints_dual"),
    );
    // A dual evaluation by its order: `clear` (a `DualOutputs` method) zeroes what that
    // order accumulates, then the body runs (first-order outputs are among the Dynamics
    // evaluation's).
    let dual_by_order = |clear: &str, dynamics: &TokenStream, full: &TokenStream| {
        let clear = format_ident!("{clear}");
        quote! {
            match order {
                ::tree_mech::runtime::Order::First | ::tree_mech::runtime::Order::Dynamics => {
                    out.#clear(::tree_mech::runtime::Order::Dynamics);
                    #dynamics
                }
                ::tree_mech::runtime::Order::Full => {
                    out.#clear(::tree_mech::runtime::Order::Full);
                    #full
                }
            }
        }
    };
    let lagrangian_dual = dual_by_order("clear_lagrangian", d_dynamics_body, d_full_body);
    let constraints_dual = dual_by_order("clear_constraints", dc_dynamics_body, dc_full_body);
    let articulated = articulated_program(&plan, &kinematic).map(|program| {
        program.emit(
            "__articulated",
            &var_names,
            Flavour::F64 {
                out_ty: &quote!(::tree_mech::runtime::articulated::ArticulatedIo<#n>),
                scratch: false,
            },
        )
    });
    let articulated_functions = articulated.as_ref().map(|e| e.functions.clone());
    // The inverse dynamics over a generic scalar with the accelerations as inputs, and the
    // constraints' `Dh` and `q̇ᵀD²h q̇`, for the continuous linearisation's sweeps over jets
    // (`System::inverse_dynamics_jet`).
    let inverse = {
        let evaluation: Evaluation = |plan, k, q, dq, _, out| {
            let qdd: Vec<Term> = (0..plan.dof()).map(trace::qdd).collect();
            kernel::inverse_dynamics(plan, k, q, dq, &qdd, out);
            if plan.rows > 0 {
                kernel::constraints(plan, k, q, dq, Order::Dynamics, out);
            }
        };
        traced(&plan, Order::First, evaluation)
            .naming()
            .emit("__d_inverse", &var_names, generic)
    };
    let inverse_functions = &inverse.functions;
    let inverse_method = {
        let body = &inverse.body;
        quote! {
            #[inline]
            fn inverse_dynamics_jet(
                &mut self,
                q: &[::tree_mech::runtime::dual::Jet<{ ::tree_mech::runtime::dual::LANES }>],
                dq: &[::tree_mech::runtime::dual::Jet<{ ::tree_mech::runtime::dual::LANES }>],
                qdd: &[f64],
                out: &mut ::tree_mech::runtime::dual::JetOutputs<{ ::tree_mech::runtime::dual::LANES }>,
            ) -> bool {
                out.clear();
                out.accelerations.copy_from_slice(qdd);
                let (q, dq): (
                    &[::tree_mech::runtime::dual::Jet<{ ::tree_mech::runtime::dual::LANES }>; #n],
                    &[::tree_mech::runtime::dual::Jet<{ ::tree_mech::runtime::dual::LANES }>; #n],
                ) = match (q.try_into(), dq.try_into()) {
                    (Ok(q), Ok(dq)) => (q, dq),
                    _ => panic!("inverse_dynamics_jet takes one jet per variable ({})", #n),
                };
                #body
                true
            }
        }
    };
    let articulated_method = articulated.as_ref().map(|e| {
        let body = &e.body;
        quote! {
            fn articulated_acceleration(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                dq: &::tree_mech::runtime::Vector<Self::N>,
                tau: &::tree_mech::runtime::Vector<Self::N>,
                qdd: &mut ::tree_mech::runtime::Vector<Self::N>,
                own: &mut ::tree_mech::runtime::Terms<Self::N>,
            ) -> bool {
                let mut io = ::tree_mech::runtime::articulated::ArticulatedIo::<#n>::default();
                io.tau.copy_from_slice(tau.as_slice());
                io.qdd_in.copy_from_slice(qdd.as_slice());
                {
                    let out = &mut io;
                    let q: &[f64; #n] = &q.data.0[0];
                    let dq: &[f64; #n] = &dq.data.0[0];
                    #body
                }
                // The model's own forces, as the interpreted system leaves them.
                own.force.as_mut_slice().copy_from_slice(&io.force);
                own.dl_dq.as_mut_slice().copy_from_slice(&io.dl_dq);
                let held = ::tree_mech::runtime::articulated::pivots_hold(&Self::KINEMATIC, |i| {
                    (io.pivot[i], io.pivot_scale[i])
                });
                if held {
                    for i in (0..#n).filter(|&i| !Self::KINEMATIC[i]) {
                        qdd[i] = io.qdd[i];
                    }
                }
                held
            }
        }
    });
    let full_path = file
        .as_ref()
        .map(|(full, shown)| (full.to_string_lossy().into_owned(), shown.clone()));
    let floating_base = matches!(input.source, Source::File(_, true));
    let constructor = model_constructor(
        spec.as_ref(),
        full_path.as_ref().map(|(p, s)| (p.as_str(), s.as_str())),
        floating_base,
    );
    let rebuild = full_path.as_ref().map(|(path, _)| {
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
            /// Which variables are kinematic (prescribed).
            pub const KINEMATIC: [bool; #n] = [#(#kinematic),*];
            /// Constraint equation names, in order.
            pub const CONSTRAINTS: [&'static str; #rows] = [#(#constraint_names),*];
            /// Input names, in order (`u`; the generalized force is `B u`).
            pub const INPUTS: [&'static str; #inputs] = [#(#input_names),*];
            /// The variable each input pushes on.
            pub const INPUT_VARIABLES: [usize; #inputs] = [#(#input_variables),*];
            /// Statements in one full (second-order) evaluation.
            pub const STATEMENTS: usize = #statements;
            #var_consts
            #frame_consts

            /// The system (it holds no state: everything lives on the stack per evaluation).
            pub const fn new() -> Self {
                #name
            }

            /// The same model for the interpreted runtime (`TreeSystem::new(&Self::model(), …)`).
            pub fn model() -> ::tree_mech::model::Model {
                Self::model_ref().clone()
            }

            /// The model, built once (a file model is parsed on first use only).
            fn model_ref() -> &'static ::tree_mech::model::Model {
                static MODEL: ::std::sync::OnceLock<::tree_mech::model::Model> =
                    ::std::sync::OnceLock::new();
                MODEL.get_or_init(|| #constructor)
            }

            #(#functions)*
            #articulated_functions
            #weighted_functions
            #weighted_dual_functions
            #inverse_functions
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

            fn is_angle(&self, i: usize) -> bool {
                Self::model_ref().is_angle(i)
            }

            fn input_count(&self) -> usize {
                Self::INPUTS.len()
            }

            fn input_name(&self, k: usize) -> &str {
                Self::INPUTS[k]
            }

            fn input_variable(&self, k: usize) -> usize {
                Self::INPUT_VARIABLES[k]
            }

            /// Read from the model (allocates): call it when setting up, not per step.
            fn motion(&self, i: usize) -> Option<::tree_mech::model::Motion> {
                if Self::KINEMATIC[i] {
                    Self::model_ref().variables[i].motion.clone()
                } else {
                    None
                }
            }

            fn is_kinematic(&self, i: usize) -> bool {
                Self::KINEMATIC[i]
            }

            fn constraint_count(&self) -> usize {
                #rows
            }

            fn constraint_name(&self, r: usize) -> &str {
                Self::CONSTRAINTS[r]
            }

            fn constraint_variables(&self, r: usize) -> Option<&[usize]> {
                const VARIABLES: [&[usize]; #rows] = [#(&[#(#constraint_variables),*]),*];
                VARIABLES.get(r).copied()
            }

            fn constraints(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                dq: &::tree_mech::runtime::Vector<Self::N>,
                order: ::tree_mech::runtime::Order,
                out: &mut ::tree_mech::runtime::ConstraintTerms,
            ) {
                out.clear(order);
                let q: &[f64; #n] = &q.data.0[0];
                let dq: &[f64; #n] = &dq.data.0[0];
                match order {
                    ::tree_mech::runtime::Order::First => { #c_first_body }
                    ::tree_mech::runtime::Order::Dynamics => { #c_dynamics_body }
                    ::tree_mech::runtime::Order::Full => { #c_full_body }
                }
            }

            fn lagrangian(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                dq: &::tree_mech::runtime::Vector<Self::N>,
                order: ::tree_mech::runtime::Order,
                out: &mut ::tree_mech::runtime::Terms<Self::N>,
            ) {
                // Each order's program assigns the same entries on every call: terms kept
                // for it clear only what it does not (`Terms::begin_assigned`). A static's
                // address is this model's own.
                static MODEL: u8 = 0;
                let key = ::core::ptr::addr_of!(MODEL) as usize;
                out.begin_assigned(key, order);
                let q: &[f64; #n] = &q.data.0[0];
                let dq: &[f64; #n] = &dq.data.0[0];
                match order {
                    ::tree_mech::runtime::Order::First => { #first_body }
                    ::tree_mech::runtime::Order::Dynamics => { #dynamics_body }
                    ::tree_mech::runtime::Order::Full => { #full_body #mark_force_derivatives }
                }
                out.end_assigned(key, order);
            }

            fn mass_matrix(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                out: &mut ::tree_mech::runtime::Terms<Self::N>,
            ) {
                out.clear(::tree_mech::runtime::Order::Dynamics);
                let q: &[f64; #n] = &q.data.0[0];
                // The traced sweeps read no velocity.
                let dq = q;
                #mass_body
            }

            fn energy(
                &mut self,
                q: &::tree_mech::runtime::Vector<Self::N>,
                dq: &::tree_mech::runtime::Vector<Self::N>,
                out: &mut ::tree_mech::runtime::Terms<Self::N>,
            ) -> f64 {
                let q: &[f64; #n] = &q.data.0[0];
                let dq: &[f64; #n] = &dq.data.0[0];
                out.total_energy = 0.0;
                #energy_body
                out.total_energy
            }

            #articulated_method
            #weighted_method
            #weighted_dual_method
            #inverse_method

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

            #[inline]
            fn evaluate_dual(
                &mut self,
                q: &[::tree_mech::runtime::dual::Dual],
                dq: &[::tree_mech::runtime::dual::Dual],
                order: ::tree_mech::runtime::Order,
                out: &mut ::tree_mech::runtime::dual::DualOutputs,
            ) {
                // The constraints first (that call zeroes their outputs), then the Lagrangian.
                <Self as ::tree_mech::runtime::System>::constraints_dual(self, q, dq, order, out);
                #evaluate_arrays
                #lagrangian_dual
            }

            fn constraints_dual(
                &mut self,
                q: &[::tree_mech::runtime::dual::Dual],
                dq: &[::tree_mech::runtime::dual::Dual],
                order: ::tree_mech::runtime::Order,
                out: &mut ::tree_mech::runtime::dual::DualOutputs,
            ) {
                #constraints_arrays
                #constraints_dual
            }
        }
    })
}
