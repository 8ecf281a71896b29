//! Forward dynamics by the articulated-body algorithm (Featherstone, *Rigid Body Dynamics
//! Algorithms*, 2008, §7.3), in the sweeps' conventions: body twists `(v, ω)` in each frame's
//! axes, one primitive per frame (docs/derivations.md §6). It gives `q̈` of a model without
//! constraints in O(frames), where forming `M` is O(frames · depth) and factoring it
//! O(n³); kinematic variables enter with their prescribed `q̈` (hybrid dynamics).
//!
//! After the outward sweep ([`crate::sweeps::forward`] at [`Reach::Motion`](crate::sweeps::Reach::Motion):
//! body velocities `v_k` and each frame's own column `∂v_k/∂q_k = [Ad v_par, ξ_k]`):
//! 1. inward, each subtree's articulated inertia `I^A` and bias wrench `p^A`, starting from
//!    the body's `I_k` and `v_k ×* I_k v_k`; at a frame driven by a dynamic variable with
//!    `U = I^A ξ`, `D = ξ·U`, `u = τ − ξ·p^A` the parent receives `I^A − U Uᵀ/D` and
//!    `p^A + I^a c + U u/D` (`c = ∂v/∂q_k q̇_k`, the velocity-product acceleration); a
//!    kinematic variable passes on `I^A` and `p^A + I^A (c + ξ q̈_k)`;
//! 2. outward, each frame's acceleration `a = Ad_{g⁻¹} a_par + c + ξ q̈` with
//!    `q̈ = (u − U·(Ad_{g⁻¹} a_par + c))/D`, from the world's `a_0 = (−γ, 0)` (gravity as an
//!    upward acceleration of the base).

use crate::plan::{Body, FramePlan, TreePlan};
use crate::scalar::Scalar;
use crate::se3::{
    component, cross, dot, inertia_times, twist_index, zero6, SpatialInertia, Twist, Wrench,
};
use crate::sweeps::Workspace;
use tree_model::Joint;

/// Per-frame storage of the algorithm (allocated once, reused), over any [`Scalar`]: `f64`
/// for the interpreted system, traced by `tree_model!` into straight-line code.
#[derive(Clone, Debug)]
pub struct Articulated<S: Scalar = f64> {
    /// Articulated inertia `I^A` of each subtree at its root.
    inertia: Vec<SpatialInertia<S>>,
    /// Bias wrench `p^A`.
    bias: Vec<Wrench<S>>,
    /// `U = I^A ξ` at a frame driven by a dynamic variable.
    column: Vec<Wrench<S>>,
    /// `D = ξ·U`.
    pub pivot: Vec<S>,
    /// What `D` is judged against: the trace of `I^A`'s block along the primitive (angular
    /// for a rotation, linear for a translation).
    pub pivot_scale: Vec<S>,
    /// `u = τ − ξ·p^A`.
    force: Vec<S>,
    /// The velocity-product acceleration `c`.
    bias_acceleration: Vec<Twist<S>>,
    /// Each frame's acceleration.
    acceleration: Vec<Twist<S>>,
}

impl<S: Scalar> Articulated<S> {
    /// Buffers sized for `plan`.
    pub fn new(plan: &TreePlan) -> Self {
        let nf = plan.frames.len();
        Articulated {
            inertia: vec![SpatialInertia::default(); nf],
            bias: vec![zero6(); nf],
            column: vec![zero6(); nf],
            pivot: vec![S::zero(); nf],
            pivot_scale: vec![S::zero(); nf],
            force: vec![S::zero(); nf],
            bias_acceleration: vec![zero6(); nf],
            acceleration: vec![zero6(); nf],
        }
    }
}

/// `v ×* w = (ω × f, v × f + ω × τ)`: the rate of change of a momentum `w = (f, τ)` carried by
/// a body moving with twist `v = (v, ω)` (body-frame Newton–Euler).
#[inline(always)]
pub(crate) fn cross_force<S: Scalar>(v: &Twist<S>, w: &Wrench<S>) -> Wrench<S> {
    let (lin, ang) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    let (f, tau) = ([w[0], w[1], w[2]], [w[3], w[4], w[5]]);
    let a = cross(&ang, &f);
    let b = cross(&lin, &f);
    let e = cross(&ang, &tau);
    [a[0], a[1], a[2], b[0] + e[0], b[1] + e[1], b[2] + e[2]]
}

/// The world's acceleration `(−γ, 0)`: gravity as an upward acceleration of the base, so
/// that every body's inertial wrench carries its weight.
pub(crate) fn base_acceleration<S: Scalar>(plan: &TreePlan) -> Twist<S> {
    let g = plan.gravity;
    let c = S::constant;
    [
        c(-g[0]),
        c(-g[1]),
        c(-g[2]),
        S::zero(),
        S::zero(),
        S::zero(),
    ]
}

/// The parent's acceleration `a_par` (`base` for a root) seen from frame `k`:
/// `Ad_{g_k⁻¹} a_par`, through the folded constant transform first.
#[inline(always)]
pub(crate) fn from_parent<S: Scalar>(
    plan: &TreePlan,
    ws: &Workspace<S>,
    k: usize,
    accelerations: &[Twist<S>],
    base: Twist<S>,
) -> Twist<S> {
    let f = &plan.frames[k];
    let mut a = f.parent.map_or(base, |p| accelerations[p]);
    if let Some(pre) = &f.pre {
        a = pre.ad_inverse(&a);
    }
    ws.local[k].ad_inverse(&a)
}

/// `c_k = (∂v_k/∂q_k) q̇_k`: the acceleration frame `k`'s own joint adds at constant speed
/// (the velocity-product term); zero for a constant frame.
#[inline(always)]
pub(crate) fn velocity_product<S: Scalar>(f: &FramePlan, ws: &Workspace<S>, dq: &[S]) -> Twist<S> {
    match (f.own(), f.joint) {
        (Some(d), Joint::Variable(i)) => scaled(&ws.dv_dq[f.col_offset + d], dq[i]),
        _ => zero6(),
    }
}

/// Frame `k`'s acceleration at known joint accelerations, outward from `base`:
/// `a_k = Ad_{g_k⁻¹} a_par + c_k + ξ_k q̈_k` (the recursive Newton–Euler algorithm's outward
/// pass; the frame kinematics' from a base at rest).
pub fn outward_acceleration<S: Scalar>(
    plan: &TreePlan,
    ws: &Workspace<S>,
    k: usize,
    accelerations: &[Twist<S>],
    base: Twist<S>,
    dq: &[S],
    qdd: &[S],
) -> Twist<S> {
    let f = &plan.frames[k];
    let mut a = from_parent(plan, ws, k, accelerations, base);
    add6(&mut a, &velocity_product(f, ws, dq));
    if let Joint::Variable(i) = f.joint {
        a[twist_index(f.kind)] += qdd[i];
    }
    a
}

/// `a s` (an array's `map` is left as a call over a wide scalar such as
/// [`crate::lanes::Lanes`]).
#[inline(always)]
fn scaled<S: Scalar>(a: &[S; 6], s: S) -> [S; 6] {
    let mut out = *a;
    for x in &mut out {
        *x = *x * s;
    }
    out
}

/// `a += b`.
#[inline(always)]
pub(crate) fn add6<S: Scalar>(a: &mut [S; 6], b: &[S; 6]) {
    for (x, y) in a.iter_mut().zip(b) {
        *x += *y;
    }
}

/// Whether a pivot `D` is too small to divide by: not positive, or lost to rounding against
/// the articulated inertia it came from (the mass matrix's Cholesky uses the same relative
/// threshold). Then the caller solves with `M` instead, which reports the variable.
fn lost(d: f64, scale: f64) -> bool {
    !(d.is_finite() && d > 1e-13 * scale.abs().max(f64::MIN_POSITIVE))
}

/// Whether every dynamic variable moves a frame the sweeps visit (else it has no inertia and
/// the algorithm cannot resolve it), and no frame follows another's variable (a mimic
/// couples two joints, which the algorithm's one-joint-at-a-time recursion cannot): known
/// from the plan alone.
pub fn resolvable(plan: &TreePlan, kinematic: &[bool]) -> bool {
    let unresolved =
        |(f, &k): (&Option<usize>, &bool)| !k && f.is_none_or(|f| !plan.frames[f].needed);
    plan.followers.is_empty() && !plan.variable_frames.iter().zip(kinematic).any(unresolved)
}

/// `q̈` into `qdd` for every dynamic variable, by the articulated-body algorithm on the
/// outward sweep `ws` at `(q, q̇)`: `tau` the generalized forces on every variable, `qdd`'s
/// kinematic entries (`kinematic[i]`) their prescribed accelerations. Each dynamic
/// variable's pivot `D` and its scale are left in `art.pivot`, `art.pivot_scale` (by frame)
/// for the caller to judge ([`pivots_hold`]); a lost pivot makes `qdd` meaningless. Over any
/// scalar, with no branch on a value, so that `tree_model!` unrolls it.
#[inline(always)]
pub fn accelerations<S: Scalar>(
    plan: &TreePlan,
    ws: &Workspace<S>,
    art: &mut Articulated<S>,
    dq: &[S],
    tau: &[S],
    kinematic: &[bool],
    qdd: &mut [S],
) {
    // The bodies' own inertias and bias wrenches.
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let v = &ws.velocity[k];
        let (inertia, bias) = match f.body {
            Some(Body::Principal { mass, moments }) => (
                SpatialInertia::diagonal(mass, &moments),
                cross_force(v, &inertia_times(mass, &moments, v)),
            ),
            Some(Body::Full { inertia, .. }) => {
                let inertia = inertia.constant::<S>();
                (inertia, cross_force(v, &inertia.times(v)))
            }
            // No body: nothing of its own (its subtree's arrive inward).
            None => (SpatialInertia::default(), zero6()),
        };
        art.inertia[k] = inertia;
        art.bias[k] = bias;
        art.bias_acceleration[k] = velocity_product(f, ws, dq);
    }
    // Inward: articulate each subtree at its root and hand it to the parent.
    for k in (0..plan.frames.len()).rev() {
        let f = &plan.frames[k];
        if !f.needed {
            continue;
        }
        let c = art.bias_acceleration[k];
        let mut bias = art.bias[k];
        // Articulated in place (the outward sweep reads only the columns and pivots).
        let inertia = &mut art.inertia[k];
        // A dynamic variable's column, pivot and force.
        let dynamic = match f.joint {
            Joint::Variable(i) if !kinematic[i] => {
                let u_col = inertia.column(f.kind);
                let d = component(&u_col, f.kind);
                // D against its block's trace (angular for a rotation, linear for a
                // translation): at a singular configuration (gimbal lock) D falls to
                // rounding while the other directions keep their inertia.
                let block = if f.kind.is_rotation() {
                    &inertia.ww
                } else {
                    &inertia.vv
                };
                art.pivot_scale[k] = block[0][0] + block[1][1] + block[2][2];
                let u = tau[i] - component(&bias, f.kind);
                art.column[k] = u_col;
                art.pivot[k] = d;
                art.force[k] = u;
                Some((u_col, u, d.recip()))
            }
            _ => None,
        };
        // A root hands nothing on.
        let Some(p) = f.parent else { continue };
        match (dynamic, f.joint) {
            (Some((u_col, u, inverse)), _) => {
                inertia.sub_outer(&u_col, inverse);
                add6(&mut bias, &inertia.times(&c));
                add6(&mut bias, &scaled(&u_col, u * inverse));
            }
            // A kinematic variable: its prescribed acceleration is known.
            (None, Joint::Variable(i)) => {
                let mut a = c;
                a[twist_index(f.kind)] += qdd[i];
                add6(&mut bias, &inertia.times(&a));
            }
            // (A plan's mimic frames are variables of their own, in full coordinates.)
            (None, Joint::Constant(_) | Joint::Mimic(_)) => {}
        }
        let local = &ws.local[k];
        let (mut i_up, mut p_up) = (
            local.inertia_to_parent(inertia),
            local.wrench_to_parent(&bias),
        );
        if let Some(pre) = &f.pre {
            i_up = pre.inertia_to_parent(&i_up);
            p_up = pre.wrench_to_parent(&p_up);
        }
        art.inertia[p].add(&i_up);
        add6(&mut art.bias[p], &p_up);
    }
    // Outward: accelerations from the base's `(−γ, 0)`.
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let mut a = from_parent(plan, ws, k, &art.acceleration, base_acceleration(plan));
        add6(&mut a, &art.bias_acceleration[k]);
        if let Joint::Variable(i) = f.joint {
            if !kinematic[i] {
                qdd[i] = (art.force[k] - dot(&art.column[k], &a)) * art.pivot[k].recip();
            }
            let axis = twist_index(f.kind);
            a[axis] += qdd[i];
        }
        art.acceleration[k] = a;
    }
}

/// [`accelerations`] in `f64` with its pivots judged: `false` (and `qdd`'s dynamic entries
/// unspecified) when a dynamic variable moves no frame with mass below it or a pivot is
/// lost, the cases the caller solves with `M` instead. Compiled also for AVX2 and chosen at
/// run time (wider registers and three-operand instructions; no fused multiply-adds, so the
/// generic body's bits).
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
pub fn accelerations_checked(
    plan: &TreePlan,
    ws: &Workspace<f64>,
    art: &mut Articulated,
    dq: &[f64],
    tau: &[f64],
    kinematic: &[bool],
    qdd: &mut [f64],
) -> bool {
    if !resolvable(plan, kinematic) {
        return false;
    }
    accelerations(plan, ws, art, dq, tau, kinematic, qdd);
    pivots_hold(kinematic, |i| {
        let k = plan.variable_frames[i].expect("a resolvable variable drives a frame");
        (art.pivot[k], art.pivot_scale[k])
    })
}

/// Whether every dynamic variable's pivot holds (`pivot(i)`: variable `i`'s `(D, scale)`,
/// read only for dynamic variables): the one judgement of the interpreted system and of the
/// code `tree_model!` generates.
pub fn pivots_hold(kinematic: &[bool], pivot: impl Fn(usize) -> (f64, f64)) -> bool {
    (0..kinematic.len()).filter(|&i| !kinematic[i]).all(|i| {
        let (d, scale) = pivot(i);
        !lost(d, scale)
    })
}

/// What the code `tree_model!` generates for [`accelerations`] reads and writes, on the stack:
/// the generalized forces and the kinematic variables' prescribed accelerations in, every
/// variable's `q̈` and each dynamic variable's pivot and its scale out (by variable).
#[derive(Clone, Copy, Debug)]
pub struct ArticulatedIo<const N: usize> {
    /// `τ`, every variable's generalized force (inputs, springs and the model's forces).
    pub tau: [f64; N],
    /// The kinematic variables' prescribed `q̈` (other entries unread).
    pub qdd_in: [f64; N],
    /// The dynamic variables' `q̈` (other entries unwritten).
    pub qdd: [f64; N],
    /// Each dynamic variable's pivot `D`.
    pub pivot: [f64; N],
    /// What it is judged against ([`pivots_hold`]).
    pub pivot_scale: [f64; N],
    /// The model's own generalized forces (damping, dampers) and its springs' `∂L/∂q`, as
    /// the system hands them back in `own.force`, `own.dl_dq`.
    pub force: [f64; N],
    /// See `force`.
    pub dl_dq: [f64; N],
}

impl<const N: usize> Default for ArticulatedIo<N> {
    fn default() -> Self {
        ArticulatedIo {
            tau: [0.0; N],
            qdd_in: [0.0; N],
            qdd: [0.0; N],
            pivot: [0.0; N],
            pivot_scale: [0.0; N],
            force: [0.0; N],
            dl_dq: [0.0; N],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::Kernel;
    use crate::sweeps::Reach;

    /// The dispatched build (AVX2 where the CPU has it) gives the generic body's bits: no
    /// fused multiply-adds, no reassociation, only wider registers.
    #[test]
    fn the_dispatched_build_gives_the_same_bits() {
        let models = [crate::plan::tests::joined(), tree_model::n_link_pendulum(8)];
        for model in models {
            let plan = TreePlan::folded(&model);
            let n = model.variables.len();
            let kinematic: Vec<bool> = model.variables.iter().map(|v| v.is_kinematic()).collect();
            let mut k = Kernel::<f64>::new(&plan);
            let (mut a, mut b) = (Articulated::new(&plan), Articulated::new(&plan));
            for trial in 0..3 {
                let x = |i: usize, s: f64| (1.7 * (i + 3 * trial) as f64 + s).sin() * 1.5;
                let q: Vec<f64> = (0..n).map(|i| x(i, 0.1)).collect();
                let dq: Vec<f64> = (0..n).map(|i| x(i, 0.7)).collect();
                let tau: Vec<f64> = (0..n).map(|i| x(i, 1.3)).collect();
                let mut qdd_a: Vec<f64> = (0..n).map(|i| x(i, 2.1)).collect();
                let mut qdd_b = qdd_a.clone();
                crate::sweeps::forward(&plan, &mut k.tree, &q, &dq, Reach::Motion);
                accelerations(&plan, &k.tree, &mut a, &dq, &tau, &kinematic, &mut qdd_a);
                let held = accelerations_checked(
                    &plan, &k.tree, &mut b, &dq, &tau, &kinematic, &mut qdd_b,
                );
                assert!(held);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&qdd_a), bits(&qdd_b), "{} trial {trial}", model.name);
                assert!(qdd_a.iter().all(|x| x.is_finite()));
            }
        }
    }
}
