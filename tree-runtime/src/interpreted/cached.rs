//! `Evaluation::Cached`: one outward pass computes every frame's quantities from its parent's
//! (DESIGN.md §3), then each mass reads them.

use nalgebra::Dyn;

use super::accumulate::{add_mass_terms, FrameQuantities};
use super::{tri, TreeSystem};
use crate::se3::{bracket_with_axis, LocalTransform, Pose, Twist, ZERO};
use crate::system::{Order, Terms};

impl TreeSystem {
    /// The outward pass: poses, body velocities and their derivatives up to `order`, for
    /// every frame that carries or leads to mass (every frame when `all`).
    pub(crate) fn forward(&mut self, q: &[f64], dq: &[f64], order: Order, all: bool) {
        for k in 0..self.frames.len() {
            let f = &self.frames[k];
            if !f.needed && !all {
                continue;
            }
            let local = LocalTransform::new(f.kind, self.joint_value(f.joint, q));
            let (parent_pose, parent_vel, np, pc, pt) = match f.parent {
                Some(p) => {
                    let pf = &self.frames[p];
                    (
                        self.pose[p],
                        self.velocity[p],
                        pf.n,
                        pf.col_offset,
                        pf.tri_offset,
                    )
                }
                None => (Pose::IDENTITY, ZERO, 0, 0, 0),
            };
            let (kc, kt, own) = (f.col_offset, f.tri_offset, f.own());
            self.local[k] = local;
            self.pose[k] = local.compose_onto(&parent_pose);
            // v_k = Ad_{g_k⁻¹} v_par + ξ_k q̇_k (eq. (6)).
            let transported = local.ad_inverse(&parent_vel);
            let mut v = transported;
            let xi = f.kind.twist();
            if let tree_model::Joint::Variable(i) = f.joint {
                for (vc, x) in v.iter_mut().zip(xi) {
                    *vc += x * dq[i];
                }
            }
            self.velocity[k] = v;
            // Columns above k transport; the own column is ξ_k and [Ad v_par, ξ_k] (eqs. (7), (10)).
            for a in 0..np {
                self.jac[kc + a] = local.ad_inverse(&self.jac[pc + a]);
                self.dv_dq[kc + a] = local.ad_inverse(&self.dv_dq[pc + a]);
            }
            if let Some(d) = own {
                self.jac[kc + d] = xi;
                self.dv_dq[kc + d] = bracket_with_axis(&transported, f.kind);
            }
            if order >= Order::Dynamics {
                // ∂²v/∂q̇_b∂q_a (b < a), stored at tri(a, b): transported, or [∂v/∂q̇_b, ξ_k]
                // when a is the own variable (∂ξ_k/∂q = 0 gives zeros elsewhere).
                for a in 1..np {
                    for b in 0..a {
                        self.d2v_ddq_dq[kt + tri(a, b)] =
                            local.ad_inverse(&self.d2v_ddq_dq[pt + tri(a, b)]);
                    }
                }
                if let Some(d) = own {
                    for b in 0..d {
                        self.d2v_ddq_dq[kt + tri(d, b)] =
                            bracket_with_axis(&self.jac[kc + b], f.kind);
                    }
                }
            }
            if order >= Order::Full {
                // ∂²v/∂q_a∂q_b (a ≥ b): transported, or [∂v/∂q_b, ξ_k] when a is own (eq. (8)).
                for a in 0..np {
                    for b in 0..=a {
                        self.d2v_dq_dq[kt + tri(a, b)] =
                            local.ad_inverse(&self.d2v_dq_dq[pt + tri(a, b)]);
                    }
                }
                if let Some(d) = own {
                    for b in 0..=d {
                        self.d2v_dq_dq[kt + tri(d, b)] =
                            bracket_with_axis(&self.dv_dq[kc + b], f.kind);
                    }
                }
            }
        }
    }

    pub(crate) fn accumulate_cached(&mut self, order: Order, out: &mut Terms<Dyn>) {
        let gravity = self.model.gravity;
        for k in 0..self.frames.len() {
            let f = &self.frames[k];
            let Some(m) = f.mass else { continue };
            let mut view = CachedFrame { sys: self, k };
            let vars = &self.vars[f.var_start..f.var_start + f.n];
            add_mass_terms(&m, &gravity, vars, order, &mut view, out);
        }
    }
}

/// Reads frame k's cached quantities.
struct CachedFrame<'a> {
    sys: &'a TreeSystem,
    k: usize,
}

impl FrameQuantities for CachedFrame<'_> {
    fn pose(&mut self) -> Pose {
        self.sys.pose[self.k]
    }
    fn velocity(&mut self) -> Twist {
        self.sys.velocity[self.k]
    }
    fn jac(&mut self, a: usize) -> Twist {
        self.sys.jac[self.sys.frames[self.k].col_offset + a]
    }
    fn dv_dq(&mut self, a: usize) -> Twist {
        self.sys.dv_dq[self.sys.frames[self.k].col_offset + a]
    }
    fn d2v_ddq_dq(&mut self, a: usize, b: usize) -> Twist {
        // Stored at tri(b, a) for a < b.
        self.sys.d2v_ddq_dq[self.sys.frames[self.k].tri_offset + tri(b, a)]
    }
    fn d2v_dq_dq(&mut self, a: usize, b: usize) -> Twist {
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        self.sys.d2v_dq_dq[self.sys.frames[self.k].tri_offset + tri(hi, lo)]
    }
}
