//! One evaluation of a model: the tree's sweeps ([`crate::sweeps`]), then its springs,
//! dampers and constraints ([`crate::elements`]) from the kinematics the sweeps leave. Both
//! paths run these functions: the interpreted system over `f64`, `tree_model!` over its
//! tracing scalar.

use crate::elements::{self, Scratch};
use crate::newton_euler::{self, NewtonEuler};
use crate::order::Order;
use crate::outputs::{Contract, Output, Sink, Weighted};
use crate::plan::TreePlan;
use crate::scalar::Scalar;
use crate::sweeps::{self, Workspace};

/// The storage one evaluation works in (allocated once, reused): the tree's workspace and,
/// beside it, the elements' scratch.
#[derive(Clone, Debug)]
pub struct Kernel<S: Scalar> {
    /// Per-frame values of the sweeps.
    pub tree: Workspace<S>,
    /// Per-variable scratch of the elements.
    pub elements: Scratch<S>,
    /// The inverse dynamics' per-frame values.
    pub(crate) newton_euler: NewtonEuler<S>,
    /// The state in full coordinates, where the tree has mimic frames.
    full: FullState<S>,
}

/// The state in full coordinates — the model's variables, then each mimic frame's
/// ([`crate::Follower`], docs/derivations.md §12) — that the sweeps run in; empty for a
/// tree without mimic frames, whose full coordinates are its own.
#[derive(Clone, Debug)]
struct FullState<S> {
    q: Vec<S>,
    dq: Vec<S>,
    qdd: Vec<S>,
}

impl<S: Scalar> FullState<S> {
    fn new(plan: &TreePlan) -> Self {
        let n = if plan.followers.is_empty() {
            0
        } else {
            plan.full_dof()
        };
        let zeros = || vec![S::zero(); n];
        FullState {
            q: zeros(),
            dq: zeros(),
            qdd: zeros(),
        }
    }

    /// `(q, q̇)` in full coordinates: as given, without followers.
    #[inline(always)]
    fn state<'a>(&'a mut self, plan: &TreePlan, q: &'a [S], dq: &'a [S]) -> (&'a [S], &'a [S]) {
        if plan.followers.is_empty() {
            return (q, dq);
        }
        plan.extend(q, true, &mut self.q);
        plan.extend(dq, false, &mut self.dq);
        (&self.q, &self.dq)
    }

    /// `(q, q̇, q̈)` in full coordinates.
    fn motion<'a>(
        &'a mut self,
        plan: &TreePlan,
        q: &'a [S],
        dq: &'a [S],
        qdd: &'a [S],
    ) -> (&'a [S], &'a [S], &'a [S]) {
        if plan.followers.is_empty() {
            return (q, dq, qdd);
        }
        plan.extend(q, true, &mut self.q);
        plan.extend(dq, false, &mut self.dq);
        plan.extend(qdd, false, &mut self.qdd);
        (&self.q, &self.dq, &self.qdd)
    }
}

impl<S: Scalar> Kernel<S> {
    /// Buffers sized for `plan`.
    pub fn new(plan: &TreePlan) -> Self {
        Kernel {
            tree: Workspace::new(plan),
            // The elements' scratch is n × n: none without elements (a 40 000-joint robot
            // would otherwise ask for 12.8 GB it never uses).
            elements: Scratch::new(if plan.has_elements() {
                plan.full_dof()
            } else {
                0
            }),
            newton_euler: NewtonEuler::new(plan),
            full: FullState::new(plan),
        }
    }
}

/// All Lagrangian terms up to `order` at `(q, q̇)` — the tree's by the two sweeps, then the
/// springs' potentials — and the model's own forces (damping, dampers) with their
/// derivatives.
#[inline(always)]
pub fn evaluate<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let (q, dq) = k.full.state(plan, q, dq);
    let out = &mut Contract::new(plan, out);
    sweeps::evaluate(plan, &mut k.tree, q, dq, order, out);
    elements::springs(plan, &k.tree, &mut k.elements, q, order, out);
    elements::forces(plan, &k.tree, &mut k.elements, dq, order, out);
}

/// The total energy `E = T + V` at `(q, q̇)` into [`Output::Energy`]: the tree's from the
/// outward sweep's body velocities and the first mass moments carried inward
/// ([`sweeps::energy`]), then the springs' potentials
/// ([`elements::potential`]) — what a recorded sample reports, at a fraction of an
/// [`Order::First`] evaluation's cost.
#[inline(always)]
pub fn energy<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    out: &mut impl Sink<S>,
) {
    let (q, dq) = k.full.state(plan, q, dq);
    let tree = sweeps::energy(plan, &mut k.tree, q, dq);
    out.set(Output::Energy, tree + elements::potential(plan, &k.tree, q));
}

/// The mass matrix `M(q)` and `L(q, 0) = −V(q)` (the springs' potentials included) of the
/// model at rest: [`sweeps::mass`], then the springs at [`Order::First`] (which also add
/// their `∂L/∂q`).
pub fn mass<S: Scalar>(plan: &TreePlan, k: &mut Kernel<S>, q: &[S], out: &mut impl Sink<S>) {
    let (q, _) = k.full.state(plan, q, q);
    let out = &mut Contract::new(plan, out);
    sweeps::mass(plan, &mut k.tree, q, out);
    elements::springs(plan, &k.tree, &mut k.elements, q, Order::First, out);
}

/// The outward sweep at `(q, q̇)` and, from it, the model's own generalized forces without
/// the tree's terms: the springs' `L` and `∂L/∂q`, the damping's and dampers' forces (what the
/// articulated-body algorithm, [`crate::articulated`], takes as its inputs besides `τ`).
#[inline(always)]
pub fn elements_at<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    out: &mut impl Sink<S>,
) {
    let (q, dq) = k.full.state(plan, q, dq);
    let out = &mut Contract::new(plan, out);
    sweeps::forward_inline(plan, &mut k.tree, q, dq, sweeps::Reach::Motion);
    elements::springs(plan, &k.tree, &mut k.elements, q, Order::First, out);
    elements::forces(plan, &k.tree, &mut k.elements, dq, Order::First, out);
}

/// The inverse dynamics' terms at `(q, q̇)` and accelerations `qdd` (every variable): the
/// bodies' `τ` by recursive Newton–Euler ([`Output::Tau`]) and, as [`elements_at`] gives
/// them, the springs' `∂L/∂q` and the model's own forces — so that
/// `Tau − DlDq − Force` is `M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q − F` of the whole model (the
/// generalized force the accelerations need).
pub fn inverse_dynamics<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    qdd: &[S],
    out: &mut impl Sink<S>,
) {
    let (q, dq, qdd) = k.full.motion(plan, q, dq, qdd);
    let out = &mut Contract::new(plan, out);
    sweeps::forward_inline(plan, &mut k.tree, q, dq, sweeps::Reach::Motion);
    elements::springs(plan, &k.tree, &mut k.elements, q, Order::First, out);
    elements::forces(plan, &k.tree, &mut k.elements, dq, Order::First, out);
    let ne = &mut k.newton_euler;
    newton_euler::generalized_forces(plan, &k.tree, ne, dq, qdd);
    for (i, &t) in ne.tau.iter().enumerate() {
        out.set(Output::Tau(i), t);
    }
}

/// The constraints `h`, `Dh` and, from `Order::Dynamics` on, `q̇ᵀD²h q̇` (and at `Order::Full`
/// all of `D²h`) at `(q, q̇)`.
pub fn constraints<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let (q, dq) = k.full.state(plan, q, dq);
    let out = &mut Contract::new(plan, out);
    sweeps::forward(plan, &mut k.tree, q, dq, sweeps::Reach::Attachments);
    elements::constraints(plan, &k.tree, &mut k.elements, q, dq, order, out);
}

/// `h`, `Dh` and `Σ_r w_r D²h_r` on the `columns` kept at `q`: the constraints at
/// `Order::Full` through [`Weighted`] (`dq` is read for `q̇ᵀD²h q̇` alone, which is dropped).
pub fn weighted_constraint_hessian<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    dq: &[S],
    weights: &[S],
    columns: &[bool],
    out: &mut impl Sink<S>,
) {
    let inner = &mut Weighted {
        weights,
        columns,
        inner: out,
    };
    constraints(plan, k, q, dq, Order::Full, inner);
}

/// The unilateral rows ([`crate::gaps`]) `φ`, `Dφ` and at `Order::Full` `D²φ` at `q`, into
/// the same outputs as constraint rows (their own terms).
pub fn gaps<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let (q, dq) = k.full.state(plan, q, q);
    let out = &mut Contract::new(plan, out);
    sweeps::forward(plan, &mut k.tree, q, dq, sweeps::Reach::Attachments);
    crate::gaps::gaps(plan, &k.tree, &mut k.elements, q, order, out);
}

/// `φ`, `Dφ` and `Σ_r w_r D²φ_r` on the `columns` kept at `q` ([`gaps`] through [`Weighted`]):
/// the impulses' term `Σ γ_j D²φ_j + Σ β_k D²τ_k` of the contact step's Newton matrix.
pub fn weighted_gap_hessian<S: Scalar>(
    plan: &TreePlan,
    k: &mut Kernel<S>,
    q: &[S],
    weights: &[S],
    columns: &[bool],
    out: &mut impl Sink<S>,
) {
    let inner = &mut Weighted {
        weights,
        columns,
        inner: out,
    };
    gaps(plan, k, q, Order::Full, inner);
}
