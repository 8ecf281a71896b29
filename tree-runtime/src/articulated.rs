//! Forward dynamics by the articulated-body algorithm (Featherstone, *Rigid Body Dynamics
//! Algorithms*, 2008, §7.3), in the sweeps' conventions: body twists `(v, ω)` in each frame's
//! axes, one primitive per frame (docs/derivations.md §6). It gives `q̈` of a model without
//! constraints in O(frames), where forming `M` is O(frames · depth) and factoring it
//! O(n³); kinematic variables enter with their prescribed `q̈` (hybrid dynamics).
//!
//! After the outward sweep ([`crate::sweeps::forward`] at [`Reach::Lagrangian`](crate::sweeps::Reach::Lagrangian)`(First)`:
//! poses, body velocities `v_k` and each frame's own column `∂v_k/∂q_k = [Ad v_par, ξ_k]`):
//! 1. inward, each subtree's articulated inertia `I^A` and bias wrench `p^A`, starting from
//!    the body's `I_k` and `v_k ×* I_k v_k`; at a frame driven by a dynamic variable with
//!    `U = I^A ξ`, `D = ξ·U`, `u = τ − ξ·p^A` the parent receives `I^A − U Uᵀ/D` and
//!    `p^A + I^a c + U u/D` (`c = ∂v/∂q_k q̇_k`, the velocity-product acceleration); a
//!    kinematic variable passes on `I^A` and `p^A + I^A (c + ξ q̈_k)`;
//! 2. outward, each frame's acceleration `a = Ad_{g⁻¹} a_par + c + ξ q̈` with
//!    `q̈ = (u − U·(Ad_{g⁻¹} a_par + c))/D`, from the world's `a_0 = (−γ, 0)` (gravity as an
//!    upward acceleration of the base).

use crate::plan::{Body, TreePlan};
use crate::se3::{component, cross, dot, inertia_times, zero6, SpatialInertia, Twist, Wrench};
use crate::sweeps::Workspace;
use tree_model::Joint;

/// Per-frame storage of the algorithm (allocated once, reused).
#[derive(Clone, Debug)]
pub struct Articulated {
    /// Articulated inertia `I^A` of each subtree at its root.
    inertia: Vec<SpatialInertia>,
    /// Bias wrench `p^A`.
    bias: Vec<Wrench>,
    /// `U = I^A ξ` at a frame driven by a dynamic variable.
    column: Vec<Wrench>,
    /// `D = ξ·U`.
    pivot: Vec<f64>,
    /// `u = τ − ξ·p^A`.
    force: Vec<f64>,
    /// The velocity-product acceleration `c`.
    bias_acceleration: Vec<Twist>,
    /// Each frame's acceleration.
    acceleration: Vec<Twist>,
}

impl Articulated {
    /// Buffers sized for `plan`.
    pub fn new(plan: &TreePlan) -> Self {
        let nf = plan.frames.len();
        Articulated {
            inertia: vec![SpatialInertia::default(); nf],
            bias: vec![zero6(); nf],
            column: vec![zero6(); nf],
            pivot: vec![0.0; nf],
            force: vec![0.0; nf],
            bias_acceleration: vec![zero6(); nf],
            acceleration: vec![zero6(); nf],
        }
    }
}

/// `v ×* w = (ω × f, v × f + ω × τ)`: the rate of change of a momentum `w = (f, τ)` carried by
/// a body moving with twist `v = (v, ω)` (body-frame Newton–Euler).
fn cross_force(v: &Twist, w: &Wrench) -> Wrench {
    let (lin, ang) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    let (f, tau) = ([w[0], w[1], w[2]], [w[3], w[4], w[5]]);
    let a = cross(&ang, &f);
    let b = cross(&lin, &f);
    let e = cross(&ang, &tau);
    [a[0], a[1], a[2], b[0] + e[0], b[1] + e[1], b[2] + e[2]]
}

fn add6(a: &mut [f64; 6], b: &[f64; 6]) {
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

/// `q̈` into `qdd` for every dynamic variable, by the articulated-body algorithm on the
/// outward sweep `ws` at `(q, q̇)`: `tau` the generalized forces on every variable, `qdd`'s
/// kinematic entries (`kinematic[i]`) their prescribed accelerations. Returns `false`, with
/// `qdd`'s dynamic entries unspecified, when a pivot vanishes (a variable with no inertia
/// below it along its axis) or a dynamic variable moves no frame with mass below it.
pub fn accelerations(
    plan: &TreePlan,
    ws: &Workspace<f64>,
    art: &mut Articulated,
    dq: &[f64],
    tau: &[f64],
    kinematic: &[bool],
    qdd: &mut [f64],
) -> bool {
    // A dynamic variable that moves no frame, or no frame the sweeps visit, has no inertia.
    let unresolved =
        |(f, &k): (&Option<usize>, &bool)| !k && f.is_none_or(|f| !plan.frames[f].needed);
    if plan.variable_frames.iter().zip(kinematic).any(unresolved) {
        return false;
    }
    // The bodies' own inertias and bias wrenches.
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let v = &ws.velocity[k];
        let (inertia, momentum) = match f.body {
            Some(Body::Principal { mass, moments }) => (
                SpatialInertia::diagonal(mass, &moments),
                inertia_times(mass, &moments, v),
            ),
            Some(Body::Full { inertia, .. }) => (inertia, inertia.times(v)),
            None => (SpatialInertia::default(), zero6()),
        };
        art.inertia[k] = inertia;
        art.bias[k] = cross_force(v, &momentum);
        art.bias_acceleration[k] = match f.own() {
            Some(d) => {
                let Joint::Variable(i) = f.joint else {
                    unreachable!("a frame with an own column is driven")
                };
                ws.dv_dq[f.col_offset + d].map(|x| x * dq[i])
            }
            None => zero6(),
        };
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
        if let Joint::Variable(i) = f.joint {
            if kinematic[i] {
                let mut a = c;
                let axis = f.kind.axis() + if f.kind.is_rotation() { 3 } else { 0 };
                a[axis] += qdd[i];
                add6(&mut bias, &inertia.times(&a));
            } else {
                let u_col = inertia.column(f.kind);
                let d = component(&u_col, f.kind);
                // D against the largest diagonal entry of its block (angular for a
                // rotation, linear for a translation): at a singular configuration (gimbal
                // lock) D falls to rounding while the other directions keep their inertia.
                let block = if f.kind.is_rotation() {
                    &inertia.ww
                } else {
                    &inertia.vv
                };
                let scale = block[0][0].max(block[1][1]).max(block[2][2]);
                if lost(d, scale) {
                    return false;
                }
                let u = tau[i] - component(&bias, f.kind);
                art.column[k] = u_col;
                art.pivot[k] = d;
                art.force[k] = u;
                inertia.sub_outer(&u_col, 1.0 / d);
                add6(&mut bias, &inertia.times(&c));
                add6(&mut bias, &u_col.map(|x| x * (u / d)));
            }
        }
        let Some(p) = f.parent else { continue };
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
    let g = plan.gravity;
    let base = [-g[0], -g[1], -g[2], 0.0, 0.0, 0.0];
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let mut a = f.parent.map_or(base, |p| art.acceleration[p]);
        if let Some(pre) = &f.pre {
            a = pre.ad_inverse(&a);
        }
        a = ws.local[k].ad_inverse(&a);
        add6(&mut a, &art.bias_acceleration[k]);
        if let Joint::Variable(i) = f.joint {
            if !kinematic[i] {
                qdd[i] = (art.force[k] - dot(&art.column[k], &a)) / art.pivot[k];
            }
            let axis = f.kind.axis() + if f.kind.is_rotation() { 3 } else { 0 };
            a[axis] += qdd[i];
        }
        art.acceleration[k] = a;
    }
    true
}
