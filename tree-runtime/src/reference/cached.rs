//! `PaperEvaluation::Cached`: after the outward sweep, the second derivatives of every frame's body
//! velocity are computed from its parent's (docs/derivations.md §2, paper eqs. (8), (9)) and cached;
//! then each mass reads what it needs.

use nalgebra::Dyn;

use super::accumulate::{add_mass_terms, FrameQuantities};
use super::{tri, PaperSystem};
use crate::system::{Order, Terms};
use tree_kernel::se3::{bracket_with_axis, Pose, Twist};
use tree_kernel::Body;

impl PaperSystem {
    /// `∂²v/∂q̇∂q` and `∂²v/∂q∂q` of every needed frame, from the outward sweep's columns.
    pub(crate) fn second_order_caches(&mut self, order: Order) {
        if order < Order::Dynamics {
            return;
        }
        for k in 0..self.plan.frames.len() {
            let f = &self.plan.frames[k];
            if !f.needed {
                continue;
            }
            let local = self.ws.local[k];
            let (np, pt) = match f.parent {
                Some(p) => (self.plan.frames[p].n, self.tri_offset[p]),
                None => (0, 0),
            };
            let (kc, kt, own) = (f.col_offset, self.tri_offset[k], f.own());
            // ∂²v/∂q̇_b∂q_a (b < a): transported, or [∂v/∂q̇_b, ξ_k] when a is the own
            // variable (∂ξ_k/∂q = 0 makes the rest zero).
            for a in 1..np {
                for b in 0..a {
                    self.d2v_ddq_dq[kt + tri(a, b)] =
                        local.ad_inverse(&self.d2v_ddq_dq[pt + tri(a, b)]);
                }
            }
            if let Some(d) = own {
                for b in 0..d {
                    self.d2v_ddq_dq[kt + tri(d, b)] =
                        bracket_with_axis(&self.ws.jac[kc + b], f.kind);
                }
            }
            if order < Order::Full {
                continue;
            }
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
                        bracket_with_axis(&self.ws.dv_dq[kc + b], f.kind);
                }
            }
        }
    }

    pub(crate) fn accumulate_cached(&mut self, order: Order, out: &mut Terms<Dyn>) {
        let gravity = self.plan.gravity;
        for k in 0..self.plan.frames.len() {
            // `PaperSystem::new` admits only principal bodies.
            let Some(Body::Principal { mass, moments }) = self.plan.frames[k].body else {
                continue;
            };
            let mut view = CachedFrame { sys: self, k };
            add_mass_terms(
                mass,
                &moments,
                &gravity,
                self.plan.ancestors(k),
                order,
                &mut view,
                out,
            );
        }
    }
}

/// Reads frame k's cached quantities.
struct CachedFrame<'a> {
    sys: &'a PaperSystem,
    k: usize,
}

impl FrameQuantities for CachedFrame<'_> {
    fn pose(&mut self) -> Pose {
        self.sys.ws.pose[self.k]
    }
    fn velocity(&mut self) -> Twist {
        self.sys.ws.velocity[self.k]
    }
    fn jac(&mut self, a: usize) -> Twist {
        self.sys.ws.jac[self.sys.plan.frames[self.k].col_offset + a]
    }
    fn dv_dq(&mut self, a: usize) -> Twist {
        self.sys.ws.dv_dq[self.sys.plan.frames[self.k].col_offset + a]
    }
    fn d2v_ddq_dq(&mut self, a: usize, b: usize) -> Twist {
        // Stored at tri(b, a) for a < b.
        self.sys.d2v_ddq_dq[self.sys.tri_offset[self.k] + tri(b, a)]
    }
    fn d2v_dq_dq(&mut self, a: usize, b: usize) -> Twist {
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        self.sys.d2v_dq_dq[self.sys.tri_offset[self.k] + tri(hi, lo)]
    }
}
