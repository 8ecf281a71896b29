//! The expansion: a unit struct with named constants for its variables and frames, and an
//! `impl System` whose evaluations are the runtime's recursions traced for this one tree.

use std::collections::HashMap;

use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use tree_kernel::articulated::{self, Articulated};
use tree_kernel::kernel::{self, Kernel};
use tree_kernel::se3::Pose;
use tree_kernel::sweeps;
use tree_kernel::Order;
use tree_kernel::TreePlan;
use tree_kernel::{Index, Output, Sink};
use tree_model::{Model, ModelSpec, ParameterSpec, Value};

use crate::ast::{Input, Source};
use crate::lower;
use crate::program::{
    constant, identifier_part, DualPrograms, Flavour, Program, Programs, Variants,
};
use crate::system_impl;
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
                let path = format!("::tree_mech::__private::Output::{at:?}");
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
fn weighted_program(plan: &TreePlan, kinematic: &[bool]) -> Option<Traced> {
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
    Some(Traced {
        nodes,
        outputs: nonzero,
    })
}

/// The unilateral rows' `φ` and `Dφ` (`kernel::gaps` at `Order::First`) and, with the
/// impulses as weights (an input, `out.weights[r]`), `Σ_r w_r D²φ_r` on the dynamic
/// variables' columns (`kernel::weighted_gap_hessian`): what the contact step evaluates at
/// each iterate. `None` without unilateral rows.
fn gap_programs(plan: &TreePlan, kinematic: &[bool]) -> Option<(Traced, Traced)> {
    if plan.gap_rows == 0 {
        return None;
    }
    let first: Evaluation = |plan, k, q, _, _, out| kernel::gaps(plan, k, q, Order::First, out);
    let n = plan.dof();
    let columns: Vec<bool> = kinematic.iter().map(|&k| !k).collect();
    let (nodes, outputs) = trace::record(|| {
        let (q, _) = state_inputs(n);
        let weights: Vec<Term> = (0..plan.gap_rows).map(trace::weight).collect();
        let mut k = Kernel::<Term>::new(plan);
        let mut out = Recorder::default();
        kernel::weighted_gap_hessian(plan, &mut k, &q, &weights, &columns, &mut out);
        out.values
    });
    let nonzero = (outputs.into_iter())
        .filter(|(_, t)| !matches!(t, Term::Const(c) if *c == 0.0))
        .collect();
    let weighted = Traced {
        nodes,
        outputs: nonzero,
    };
    Some((traced(plan, Order::First, first), weighted))
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
const RESERVED: [&str; 12] = [
    "DOF",
    "INPUTS",
    "INPUT_VARIABLES",
    "VARIABLES",
    "FRAMES",
    "Q0",
    "DQ0",
    "DAMPING",
    "STATEMENTS",
    "LEAN",
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
                ::tree_mech::__private::model::from_urdf_str(
                    include_str!(#path),
                    Some(#shown),
                    ::tree_mech::__private::model::UrdfOptions { floating_base: #floating_base, ..::core::default::Default::default() },
                )
                .expect("the model was validated when it was compiled")
            };
        }
        return quote! {
            ::tree_mech::__private::model::from_toml_str(include_str!(#path), Some(#shown))
                .expect("the model was validated when it was compiled")
        };
    }
    let spec = spec_tokens(spec.expect("an inline model has its spec"));
    quote! {
        ::tree_mech::__private::model::validate(&#spec)
            .ok()
            .expect("the model was validated when it was compiled")
    }
}

/// Rust tokens that build `spec` (a `ModelSpec` literal).
fn spec_tokens(spec: &ModelSpec) -> TokenStream {
    let m = quote!(::tree_mech::__private::model);
    let frames = spec.frames.iter().map(|f| frame_spec(&m, f));
    let variables = spec.variables.iter().map(|v| variable_spec(&m, v));
    let constraints = spec.constraints.iter().map(|c| constraint_spec(&m, c));
    let springs = spec.springs.iter().map(|s| {
        let (frames, variable) = (s.frames.literal(), s.variable.literal());
        let (stiffness, rest) = (s.stiffness.literal(), s.rest.literal());
        quote!(#m::SpringSpec { frames: #frames, variable: #variable, stiffness: #stiffness, rest: #rest })
    });
    let dampers = spec.dampers.iter().map(|d| {
        let (frames, damping) = (d.frames.literal(), d.damping.literal());
        quote!(#m::DamperSpec { frames: #frames, damping: #damping })
    });
    let inputs = spec.inputs.iter().map(|u| {
        let (name, variable, limits) = (u.name.literal(), u.variable.literal(), u.limits.literal());
        quote!(#m::InputSpec { name: #name, variable: #variable, limits: #limits })
    });
    let (name, gravity) = (spec.name.literal(), spec.gravity.literal());
    let contacts = contacts_spec(&m, &spec.contacts);
    quote!(#m::ModelSpec {
        name: #name,
        gravity: #gravity,
        frames: ::std::vec![#(#frames),*],
        variables: ::std::vec![#(#variables),*],
        constraints: ::std::vec![#(#constraints),*],
        springs: ::std::vec![#(#springs),*],
        dampers: ::std::vec![#(#dampers),*],
        inputs: ::std::vec![#(#inputs),*],
        contacts: #contacts,
    })
}

/// The ground, the contacts and whether limits are enforced, as a literal.
fn contacts_spec(m: &TokenStream, c: &tree_model::ContactsSpec) -> TokenStream {
    let enforce = c.enforce_limits.literal();
    let ground = match &c.ground {
        Some(g) => {
            let (h, n, f) = (g.height.literal(), g.normal.literal(), g.friction.literal());
            quote!(Some(#m::GroundSpec { height: #h, normal: #n, friction: #f }))
        }
        None => quote!(None),
    };
    let contacts = c.contacts.iter().map(|c| {
        let (name, frame, radius) = (c.name.literal(), c.frame.literal(), c.radius.literal());
        let (friction, collide) = (c.friction.literal(), c.collide.literal());
        quote!(#m::ContactSpec {
            name: #name, frame: #frame, radius: #radius, friction: #friction, collide: #collide,
        })
    });
    quote!(#m::ContactsSpec {
        enforce_limits: #enforce,
        ground: #ground,
        contacts: ::std::vec![#(#contacts),*],
    })
}

/// A frame's spec as a literal.
fn frame_spec(m: &TokenStream, f: &tree_model::FrameSpec) -> TokenStream {
    let primitives = f.primitives.iter().map(|p| {
        let kind = format_ident!("{}", format!("{:?}", p.kind));
        let value = match &p.value {
            Value::Constant(x) => {
                let x = x.literal();
                quote!(#m::Value::Constant(#x))
            }
            Value::Variable(v) => {
                let v = v.literal();
                quote!(#m::Value::Variable(#v))
            }
            Value::Mimic(s) => {
                let v = s.variable.literal();
                let (k, o, c) = (
                    s.multiplier.literal(),
                    s.offset.literal(),
                    s.damping.literal(),
                );
                quote!(#m::Value::Mimic(#m::MimicSpec {
                    variable: #v, multiplier: #k, offset: #o, damping: #c,
                }))
            }
        };
        quote!(#m::Primitive { kind: #m::PrimitiveKind::#kind, value: #value })
    });
    let (name, parent) = (f.name.literal(), f.parent.literal());
    let (mass, com, inertia) = (f.mass.literal(), f.com.literal(), f.inertia.literal());
    quote!(#m::FrameSpec {
        name: #name,
        parent: #parent,
        primitives: ::std::vec![#(#primitives),*],
        mass: #mass,
        com: #com,
        inertia: #inertia,
    })
}

/// A variable's settings as a literal.
fn variable_spec(m: &TokenStream, v: &tree_model::VariableSpec) -> TokenStream {
    let name = v.name.literal();
    let (q0, dq0, damping) = (v.q0.literal(), v.dq0.literal(), v.damping.literal());
    let kinematic = v.kinematic.literal();
    let motion = match &v.motion {
        Some(s) => {
            let (o, a) = (s.offset.literal(), s.amplitude.literal());
            let (f, p) = (s.frequency.literal(), s.phase.literal());
            quote!(Some(#m::SineSpec { offset: #o, amplitude: #a, frequency: #f, phase: #p }))
        }
        None => quote!(None),
    };
    let (samples, limits) = (v.samples.literal(), v.limits.literal());
    quote!(#m::VariableSpec {
        name: #name, q0: #q0, dq0: #dq0, damping: #damping, kinematic: #kinematic,
        motion: #motion, samples: #samples, limits: #limits,
    })
}

/// A constraint's spec as a literal.
fn constraint_spec(m: &TokenStream, c: &tree_model::ConstraintSpec) -> TokenStream {
    let (name, kind, frames) = (c.name.literal(), c.kind.literal(), c.frames.literal());
    let length = match &c.length {
        Some(ParameterSpec::Constant(x)) => {
            let x = x.literal();
            quote!(Some(#m::ParameterSpec::Constant(#x)))
        }
        Some(ParameterSpec::Variable(v)) => {
            let v = v.literal();
            quote!(Some(#m::ParameterSpec::Variable(#v)))
        }
        None => quote!(None),
    };
    let (normal, axes, slack) = (c.normal.literal(), c.axes.literal(), c.slack.literal());
    quote!(#m::ConstraintSpec {
        name: #name, kind: #kind, frames: #frames, length: #length, normal: #normal, axes: #axes,
        slack: #slack,
    })
}

/// A value written back as the Rust expression that builds it.
trait Literal {
    fn literal(&self) -> TokenStream;
}

impl Literal for f64 {
    fn literal(&self) -> TokenStream {
        constant(*self)
    }
}

impl Literal for bool {
    fn literal(&self) -> TokenStream {
        quote!(#self)
    }
}

impl Literal for String {
    fn literal(&self) -> TokenStream {
        quote!(::std::string::String::from(#self))
    }
}

impl<T: Literal> Literal for Option<T> {
    fn literal(&self) -> TokenStream {
        match self {
            Some(x) => {
                let x = x.literal();
                quote!(Some(#x))
            }
            None => quote!(None),
        }
    }
}

impl<T: Literal, const N: usize> Literal for [T; N] {
    fn literal(&self) -> TokenStream {
        let items = self.iter().map(Literal::literal);
        quote!([#(#items),*])
    }
}

impl<T: Literal> Literal for Vec<T> {
    fn literal(&self) -> TokenStream {
        let items = self.iter().map(Literal::literal);
        quote!(::std::vec![#(#items),*])
    }
}

/// The expansion of one `tree_model!`, as named stages: read the model, trace and emit its
/// programs, then declare the type, its constants and the `System` impl around them.
pub fn expand(input: Input) -> syn::Result<TokenStream> {
    let loaded = load(&input)?;
    let plan = TreePlan::folded(&loaded.model);
    let programs = Programs::emit(&plan, &loaded.model, input.lean);
    let declaration = declaration(&input, &loaded, programs.full.statements);
    let inherent = inherent_impl(&input.name, &loaded, &programs)?;
    let system = system_impl::system_impl(&input.name, &loaded.model, &plan, &programs);
    Ok(quote! {
        #declaration
        #inherent
        #system
    })
}

/// The model a `tree_model!` names, with where it came from.
pub(crate) struct Loaded {
    pub(crate) model: Model,
    /// An inline model's spec (rebuilt at run time by `Name::model()`).
    spec: Option<ModelSpec>,
    /// A file model's full path and the path as written.
    file: Option<(String, String)>,
    floating_base: bool,
    /// The contacts file's (`contacts from "…"`) full path and the path as written.
    contacts: Option<(String, String)>,
    /// `enforce_limits = …` after the path.
    enforce_limits: Option<bool>,
}

/// Reads the model from its file or lowers the inline syntax (a compile error at the token
/// at fault otherwise).
fn load(input: &Input) -> syn::Result<Loaded> {
    Ok(match &input.source {
        Source::File(path, floating_base) => {
            let (mut model, full) = lower::from_file(path, *floating_base)?;
            let mut contacts = None;
            if let Some(file) = &input.contacts {
                let (with, full) = lower::with_contacts_from(model, file)?;
                model = with;
                contacts = Some((full.to_string_lossy().into_owned(), file.value()));
            }
            if let Some(enforce) = input.enforce_limits {
                model = lower::with_enforced_limits(model, enforce);
            }
            Loaded {
                model,
                spec: None,
                file: Some((full.to_string_lossy().into_owned(), path.value())),
                floating_base: *floating_base,
                contacts,
                enforce_limits: input.enforce_limits,
            }
        }
        Source::Inline(inline) => {
            let (model, spec) = lower::from_inline(&input.name, inline)?;
            Loaded {
                model,
                spec: Some(spec),
                file: None,
                floating_base: false,
                contacts: None,
                enforce_limits: None,
            }
        }
    })
}

/// Above this many statements in a full evaluation a model is large (lean, unless the macro
/// says `lean = false`; `lean` makes a smaller one so): its programs are
/// compiled as recorded only (no variant for AVX2 and FMA) and its evaluations over dual
/// numbers and jets are the interpreted runtime's, which keeps a 50-joint robot's build under
/// a minute (docs/benchmarks.md, "The largest robots": the G1 with hands, 29 s). The dual
/// numbers' evaluations are 40% of such a model's code and the slowest to build; its
/// compiled step with first derivatives keeps some 1.7× over the interpreted one.
const LEAN_ABOVE: usize = 20_000;

impl Programs {
    /// Traces and emits every program of `model`'s plan, lean where `lean` says (by its size
    /// where it says nothing).
    fn emit(plan: &TreePlan, model: &Model, lean: Option<bool>) -> Self {
        let n = model.dof();
        let var_names: Vec<&str> = model.variables.iter().map(|v| v.name.as_str()).collect();
        let vars = &var_names[..];
        let kinematic: Vec<bool> = model.variables.iter().map(|v| v.is_kinematic()).collect();
        let terms_ty = quote!(::tree_mech::__private::Terms<::tree_mech::__private::Const<#n>>);
        let constraint_ty = quote!(::tree_mech::__private::ConstraintTerms);
        let (f64_terms, f64_constraints) = (
            Flavour::F64 {
                out_ty: &terms_ty,
                scratch: true,
            },
            Flavour::F64 {
                out_ty: &constraint_ty,
                scratch: true,
            },
        );
        let lagrangian: Evaluation = kernel::evaluate;
        let constraints: Evaluation = kernel::constraints;
        // `M(q)` and `L(q, 0)` alone (`System::mass_matrix`): the sweeps at rest, no velocity.
        let mass: Evaluation = |plan, k, q, _, _, out| kernel::mass(plan, k, q, out);
        // `E = T + V` alone (`System::energy`): velocities and first moments, no columns.
        let energy: Evaluation = |plan, k, q, dq, _, out| kernel::energy(plan, k, q, dq, out);
        let [l_first, l_dynamics, l_full] =
            [Order::First, Order::Dynamics, Order::Full].map(|o| traced(plan, o, lagrangian));
        let [c_first, c_dynamics, c_full] =
            [Order::First, Order::Dynamics, Order::Full].map(|o| traced(plan, o, constraints));
        let full = l_full.assigning();
        let lean = lean.unwrap_or(full.kept() > LEAN_ABOVE);
        let variants = if lean {
            Variants::RecordedOnly
        } else {
            Variants::Both
        };
        let emit =
            |program: Program, prefix: &str, flavour| program.emit(prefix, vars, flavour, variants);
        let poses = Flavour::F64 {
            out_ty: &quote!([::tree_mech::__private::Pose]),
            scratch: false,
        };
        let articulated = Flavour::F64 {
            out_ty: &quote!(::tree_mech::__private::ArticulatedIo<#n>),
            scratch: false,
        };
        let weighted = weighted_program(plan, &kinematic);
        let duals = (!lean).then(|| DualPrograms {
            d_dynamics: emit(l_dynamics.naming(), "__d_dynamics", Flavour::Generic),
            d_full: emit(l_full.naming(), "__d_full", Flavour::Generic),
            dc_dynamics: emit(c_dynamics.naming(), "__dc_dynamics", Flavour::Generic),
            dc_full: emit(c_full.naming(), "__dc_full", Flavour::Generic),
            weighted: (weighted.as_ref())
                .map(|w| emit(w.naming(), "__dc_weighted", Flavour::Generic)),
            inverse: emit(inverse_program(plan), "__d_inverse", Flavour::Generic),
        });
        Programs {
            first: emit(l_first.assigning(), "__first", f64_terms),
            mass: emit(
                traced(plan, Order::Dynamics, mass).assigning(),
                "__mass",
                f64_terms,
            ),
            energy: emit(
                traced(plan, Order::First, energy).assigning(),
                "__energy",
                f64_terms,
            ),
            dynamics: emit(l_dynamics.assigning(), "__dynamics", f64_terms),
            full: emit(full, "__full", f64_terms),
            poses: emit(poses_program(plan), "__poses", poses),
            c_first: emit(c_first.assigning(), "__c_first", f64_constraints),
            c_dynamics: emit(c_dynamics.assigning(), "__c_dynamics", f64_constraints),
            c_full: emit(c_full.assigning(), "__c_full", f64_constraints),
            weighted: (weighted.as_ref())
                .map(|w| emit(w.assigning(), "__c_weighted", f64_constraints)),
            articulated: articulated_program(plan, &kinematic)
                .map(|program| emit(program, "__articulated", articulated)),
            gaps: gap_programs(plan, &kinematic).map(|(first, weighted)| {
                (
                    emit(first.assigning(), "__g_first", f64_constraints),
                    emit(weighted.assigning(), "__g_weighted", f64_constraints),
                )
            }),
            duals,
        }
    }
}

/// A large model's twin in the interpreted runtime, built once per thread from the model:
/// what its evaluations over dual numbers and jets call (`system_impl`).
fn interpreted_twin() -> TokenStream {
    quote! {
        /// Runs `f` on this thread's interpreted twin of the model.
        fn __interpreted<R>(
            f: impl FnOnce(&mut ::tree_mech::__private::TreeSystem) -> R,
        ) -> R {
            ::std::thread_local! {
                static TWIN: ::core::cell::RefCell<Option<::tree_mech::__private::TreeSystem>> =
                    const { ::core::cell::RefCell::new(None) };
            }
            TWIN.with(|twin| {
                let mut twin = twin.borrow_mut();
                let twin = twin.get_or_insert_with(|| {
                    ::tree_mech::__private::TreeSystem::new(Self::model_ref())
                        .expect("a model tree_model! compiled builds in the interpreted runtime")
                });
                f(twin)
            })
        }
    }
}

/// The inverse dynamics over a generic scalar with the accelerations as inputs, and the
/// constraints' `Dh` and `q̇ᵀD²h q̇`, for the continuous linearisation's sweeps over jets
/// (`System::inverse_dynamics_jet`).
fn inverse_program(plan: &TreePlan) -> Program {
    let evaluation: Evaluation = |plan, k, q, dq, _, out| {
        let qdd: Vec<Term> = (0..plan.dof()).map(trace::qdd).collect();
        kernel::inverse_dynamics(plan, k, q, dq, &qdd, out);
        if plan.rows > 0 {
            kernel::constraints(plan, k, q, dq, Order::Dynamics, out);
        }
    };
    traced(plan, Order::First, evaluation).naming()
}

/// The unit struct with its documentation, and (for a file model) the file compiled in, so
/// that editing it rebuilds the crate.
fn declaration(input: &Input, loaded: &Loaded, statements: usize) -> TokenStream {
    let (attrs, vis, name) = (&input.attrs, &input.vis, &input.name);
    let model = &loaded.model;
    let var_names: Vec<&str> = model.variables.iter().map(|v| v.name.as_str()).collect();
    let doc = format!(
        "The `{}` model compiled by `tree_model!`: {} variables ({}), {} frames. Its full \
         evaluation is {} straight-line statements.",
        model.name,
        model.dof(),
        var_names.join(", "),
        model.frames.len(),
        statements
    );
    let rebuild = loaded.file.as_ref().map(|(path, _)| {
        quote!(
            const _: &[u8] = include_bytes!(#path);
        )
    });
    quote! {
        #(#attrs)*
        #[doc = #doc]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        #vis struct #name;

        #rebuild
    }
}

/// The type's own items: its constants (sizes, names, the model's initial values, an index
/// per variable and frame), `new`, `model()` and every program's functions.
fn inherent_impl(
    name: &syn::Ident,
    loaded: &Loaded,
    programs: &Programs,
) -> syn::Result<TokenStream> {
    let model = &loaded.model;
    let (n, nf, rows, inputs) = (
        model.dof(),
        model.frames.len(),
        model.constraint_row_names().len(),
        model.inputs.len(),
    );
    let var_names: Vec<&str> = model.variables.iter().map(|v| v.name.as_str()).collect();
    let frame_names: Vec<&str> = model.frames.iter().map(|f| f.name.as_str()).collect();
    let var_consts = index_constants("", &var_names, "variable", name.span())?;
    let frame_consts = index_constants("FRAME_", &frame_names, "frame", name.span())?;
    let per_variable = |f: fn(&tree_model::Variable) -> f64| -> Vec<TokenStream> {
        model.variables.iter().map(|v| constant(f(v))).collect()
    };
    let (q0, dq0, damping) = (
        per_variable(|v| v.q0),
        per_variable(|v| v.dq0),
        per_variable(|v| v.damping),
    );
    let kinematic: Vec<bool> = model.variables.iter().map(|v| v.is_kinematic()).collect();
    let constraint_names = model.constraint_row_names();
    let input_names: Vec<&str> = model.inputs.iter().map(|u| u.name.as_str()).collect();
    let input_variables: Vec<usize> = model.inputs.iter().map(|u| u.variable).collect();
    let statements = programs.full.statements;
    let mut constructor = model_constructor(
        loaded.spec.as_ref(),
        (loaded.file.as_ref()).map(|(p, s)| (p.as_str(), s.as_str())),
        loaded.floating_base,
    );
    if let Some((path, shown)) = &loaded.contacts {
        constructor = quote! {
            #constructor
                .with_contacts_from_toml_str(include_str!(#path), Some(#shown))
                .expect("the contacts were validated when the model was compiled")
        };
    }
    if let Some(enforce) = loaded.enforce_limits {
        constructor = quote! {
            #constructor
                .with_contacts(&::tree_mech::__private::model::ContactsSpec {
                    enforce_limits: Some(#enforce),
                    ..::core::default::Default::default()
                })
                .expect("the limits were validated when the model was compiled")
        };
    }
    let functions = programs.functions();
    let lean = programs.duals.is_none();
    let interpreted = lean.then(interpreted_twin);
    Ok(quote! {
        impl #name {
            /// Number of configuration variables.
            pub const DOF: usize = #n;
            /// Whether the model is compiled lean: one variant of its code (no AVX2 and FMA
            /// copy), its evaluations over dual numbers and jets the interpreted runtime's
            /// (large models, or `lean` after the file's path).
            pub const LEAN: bool = #lean;
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
            pub fn model() -> ::tree_mech::__private::model::Model {
                Self::model_ref().clone()
            }

            /// The model, built once (a file model is parsed on first use only).
            fn model_ref() -> &'static ::tree_mech::__private::model::Model {
                static MODEL: ::std::sync::OnceLock<::tree_mech::__private::model::Model> =
                    ::std::sync::OnceLock::new();
                MODEL.get_or_init(|| #constructor)
            }

            #interpreted

            #(#functions)*
        }
    })
}
