//! `PaperEvaluation::Uncached`: every quantity a mass needs is recomputed from the root by recursion, with
//! nothing stored between uses — the cost a symbolic expansion of the same formulas pays.

use nalgebra::Dyn;
use tree_model::Joint;

use super::accumulate::{add_mass_terms, FrameQuantities};
use super::PaperSystem;
use crate::system::{Order, Terms};
use tree_kernel::se3::{bracket_with_axis, LocalTransform, Pose, Twist, ZERO};
use tree_kernel::{Body, FramePlan};

impl PaperSystem {
    pub(crate) fn accumulate_uncached(
        &self,
        q: &[f64],
        dq: &[f64],
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        for (k, f) in self.plan.frames.iter().enumerate() {
            // `PaperSystem::new` admits only principal bodies.
            let Some(Body::Principal { mass, moments }) = f.body else {
                continue;
            };
            let mut view = Recompute {
                frames: &self.plan.frames,
                q,
                dq,
                k,
            };
            add_mass_terms(
                mass,
                &moments,
                &self.plan.gravity,
                self.plan.ancestors(k),
                order,
                &mut view,
                out,
            );
        }
    }
}

/// Frame k's quantities, each recomputed recursively on every request.
struct Recompute<'a> {
    frames: &'a [FramePlan],
    q: &'a [f64],
    dq: &'a [f64],
    k: usize,
}

impl Recompute<'_> {
    fn local(&self, k: usize) -> LocalTransform {
        let f = &self.frames[k];
        let x = f.joint.value(self.q);
        LocalTransform::new(f.kind, x)
    }

    fn pose_of(&self, k: usize) -> Pose {
        let parent = self.frames[k]
            .parent
            .map_or(Pose::IDENTITY, |p| self.pose_of(p));
        self.local(k).compose_onto(&parent)
    }

    /// `Ad_{g_k⁻¹} v_par(k)`.
    fn transported_velocity(&self, k: usize) -> Twist {
        match self.frames[k].parent {
            Some(p) => self.local(k).ad_inverse(&self.velocity_of(p)),
            None => ZERO,
        }
    }

    fn velocity_of(&self, k: usize) -> Twist {
        let f = &self.frames[k];
        let mut v = self.transported_velocity(k);
        if let Joint::Variable(i) = f.joint {
            for (vc, x) in v.iter_mut().zip(f.kind.twist()) {
                *vc += x * self.dq[i];
            }
        }
        v
    }

    fn parent_transport(&self, k: usize, column: impl Fn(usize) -> Twist) -> Twist {
        let p = self.frames[k]
            .parent
            .expect("an ancestor variable implies a parent");
        self.local(k).ad_inverse(&column(p))
    }

    fn jac_of(&self, k: usize, a: usize) -> Twist {
        let f = &self.frames[k];
        if f.own() == Some(a) {
            f.kind.twist()
        } else {
            self.parent_transport(k, |p| self.jac_of(p, a))
        }
    }

    fn dv_dq_of(&self, k: usize, a: usize) -> Twist {
        let f = &self.frames[k];
        if f.own() == Some(a) {
            bracket_with_axis(&self.transported_velocity(k), f.kind)
        } else {
            self.parent_transport(k, |p| self.dv_dq_of(p, a))
        }
    }

    /// `∂²v_k/∂q̇_a∂q_b` for `a < b`.
    fn d2v_ddq_dq_of(&self, k: usize, a: usize, b: usize) -> Twist {
        let f = &self.frames[k];
        if f.own() == Some(b) {
            bracket_with_axis(&self.jac_of(k, a), f.kind)
        } else {
            self.parent_transport(k, |p| self.d2v_ddq_dq_of(p, a, b))
        }
    }

    /// `∂²v_k/∂q_a∂q_b` for `a ≥ b`.
    fn d2v_dq_dq_of(&self, k: usize, a: usize, b: usize) -> Twist {
        let f = &self.frames[k];
        if f.own() == Some(a) {
            bracket_with_axis(&self.dv_dq_of(k, b), f.kind)
        } else {
            self.parent_transport(k, |p| self.d2v_dq_dq_of(p, a, b))
        }
    }
}

impl FrameQuantities for Recompute<'_> {
    fn pose(&mut self) -> Pose {
        self.pose_of(self.k)
    }
    fn velocity(&mut self) -> Twist {
        self.velocity_of(self.k)
    }
    fn jac(&mut self, a: usize) -> Twist {
        self.jac_of(self.k, a)
    }
    fn dv_dq(&mut self, a: usize) -> Twist {
        self.dv_dq_of(self.k, a)
    }
    fn d2v_ddq_dq(&mut self, a: usize, b: usize) -> Twist {
        self.d2v_ddq_dq_of(self.k, a, b)
    }
    fn d2v_dq_dq(&mut self, a: usize, b: usize) -> Twist {
        if a >= b {
            self.d2v_dq_dq_of(self.k, a, b)
        } else {
            self.d2v_dq_dq_of(self.k, b, a)
        }
    }
}
