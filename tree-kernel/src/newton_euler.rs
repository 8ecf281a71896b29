//! Inverse dynamics by the recursive Newton–Euler algorithm (Featherstone, *Rigid Body
//! Dynamics Algorithms*, 2008, §5.3), in the sweeps' conventions: body twists `(v, ω)` in each
//! frame's axes, one primitive per frame (docs/derivations.md §6). For accelerations `q̈` at
//! `(q, q̇)` it gives the generalized forces the tree's bodies need,
//! `τ = M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q` of the bodies' own Lagrangian (gravity included; springs,
//! damping and dampers are the caller's), in O(frames) where forming `M` is O(frames · depth).
//! Written over any [`Scalar`]: over jets (a value with derivatives along several directions,
//! [`crate::dual::Jet`]) it gives the directional derivatives of `τ` the continuous
//! linearisation needs (`tree_runtime::linearize`), one sweep for eight directions.
//!
//! After the outward sweep ([`crate::sweeps::forward`] at
//! [`Reach::Motion`](crate::sweeps::Reach::Motion): body velocities `v_k` and each frame's own
//! column `∂v_k/∂q_k`):
//! 1. outward, each frame's acceleration `a_k = Ad_{g⁻¹} a_par + c_k + ξ_k q̈_k` from the
//!    world's `a_0 = (−γ, 0)` (gravity as an upward acceleration of the base), with
//!    `c_k = (∂v_k/∂q_k) q̇_k`, and the wrench its body needs, `f_k = I_k a_k + v_k ×* I_k v_k`;
//! 2. inward, each subtree's wrench at its root, `f_par += Ad_{g⁻¹}ᵀ f_k`, and at a frame
//!    driven by variable `i`, `τ_i = ξ_k · f_k`.

use crate::articulated::{add6, base_acceleration, cross_force, outward_acceleration};
use crate::plan::{Body, TreePlan};
use crate::scalar::Scalar;
use crate::se3::{component, inertia_times, zero6, Twist, Wrench};
use crate::sweeps::Workspace;
use tree_model::Joint;

/// Per-frame storage of the algorithm (allocated once, reused), over any [`Scalar`].
#[derive(Clone, Debug)]
pub(crate) struct NewtonEuler<S: Scalar = f64> {
    /// Each frame's acceleration `a_k`.
    acceleration: Vec<Twist<S>>,
    /// The wrench on each subtree at its root.
    wrench: Vec<Wrench<S>>,
    /// The result: every variable's `τ`.
    pub tau: Vec<S>,
}

impl<S: Scalar> NewtonEuler<S> {
    /// Buffers sized for `plan`.
    pub fn new(plan: &TreePlan) -> Self {
        let nf = plan.frames.len();
        NewtonEuler {
            acceleration: vec![zero6(); nf],
            wrench: vec![zero6(); nf],
            tau: vec![S::zero(); plan.full_dof()],
        }
    }
}

/// `τ` into `ne.tau` (every variable; zero for one that moves no massive frame) for the
/// accelerations `qdd` (every variable) on the outward sweep `ws` at `(q, q̇)`: the bodies'
/// `M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q`. No branch on a value, so `tree_model!` unrolls it.
pub(crate) fn generalized_forces<S: Scalar>(
    plan: &TreePlan,
    ws: &Workspace<S>,
    ne: &mut NewtonEuler<S>,
    dq: &[S],
    qdd: &[S],
) {
    ne.tau.iter_mut().for_each(|x| *x = S::zero());
    // Outward: accelerations from the base's `(−γ, 0)`, and the wrench each body needs.
    let base = base_acceleration(plan);
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let a = outward_acceleration(plan, ws, k, &ne.acceleration, base, dq, qdd);
        ne.acceleration[k] = a;
        let v = &ws.velocity[k];
        ne.wrench[k] = match f.body {
            Some(Body::Principal { mass, moments }) => {
                let mut w = inertia_times(mass, &moments, &a);
                add6(&mut w, &cross_force(v, &inertia_times(mass, &moments, v)));
                w
            }
            Some(Body::Full { inertia, .. }) => {
                let inertia = inertia.constant::<S>();
                let mut w = inertia.times(&a);
                add6(&mut w, &cross_force(v, &inertia.times(v)));
                w
            }
            None => zero6(),
        };
    }
    // Inward: each subtree's wrench at its root; a driven frame's τ is its component.
    for k in (0..plan.frames.len()).rev() {
        let f = &plan.frames[k];
        if !f.needed {
            continue;
        }
        let w = ne.wrench[k];
        if let Joint::Variable(i) = f.joint {
            ne.tau[i] = component(&w, f.kind);
        }
        let Some(p) = f.parent else { continue };
        let mut up = ws.local[k].wrench_to_parent(&w);
        if let Some(pre) = &f.pre {
            up = pre.wrench_to_parent(&up);
        }
        add6(&mut ne.wrench[p], &up);
    }
}
