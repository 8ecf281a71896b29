//! The interpreted tree system: walks the validated model at run time, with the
//! recursions of DESIGN.md §3, in one of three [`Evaluation`] modes.

mod accumulate;
mod cached;
mod uncached;

use nalgebra::Dyn;
use tree_model::Model;

use crate::error::SimError;
use crate::plan::TreePlan;
use crate::se3::{Pose, Twist};
use crate::sweeps::{self, Workspace};
use crate::system::{Order, System, Terms, Vector};

/// How the interpreted system evaluates the Lagrangian terms. All three give the same
/// numbers (to rounding); they differ in cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Evaluation {
    /// Outward and inward sweeps with composite bodies ([`crate::sweeps`]): every per-frame
    /// quantity once, every derivative entry O(1). The default, and what `tree_model!` unrolls.
    #[default]
    Sweeps,
    /// The paper's per-mass sums (eqs. (15)–(18)) over per-frame quantities computed once per
    /// evaluation and cached, second derivatives of the body velocities included.
    Cached,
    /// The same sums with every quantity recomputed from the root on demand, as a symbolic
    /// expansion would (caching off; the paper's Fig. 3 comparison).
    Uncached,
}

/// A frame's body velocity and, for each variable i that moves it, `(i, ∂v/∂q̇_i, ∂v/∂q_i)`.
pub type FrameVelocity = (Twist, Vec<(usize, Twist, Twist)>);

/// Index of `(a, b)`, `a ≥ b`, in a packed lower triangle.
#[inline(always)]
pub(crate) fn tri(a: usize, b: usize) -> usize {
    a * (a + 1) / 2 + b
}

/// The interpreted system.
#[derive(Clone, Debug)]
pub struct TreeSystem {
    model: Model,
    evaluation: Evaluation,
    /// Every frame as modelled (the paper's modes, body velocities for tests).
    plan: TreePlan,
    ws: Workspace<f64>,
    /// Constant chains folded (the sweeps, as `tree_model!` compiles them).
    folded: TreePlan,
    folded_ws: Workspace<f64>,
    // `Evaluation::Cached` only: per frame, ∂²v/∂q̇_b∂q_a (b < a, at tri(a, b)) and
    // ∂²v/∂q_a∂q_b (a ≥ b), in packed triangles starting at `tri_offset[k]`.
    tri_offset: Vec<usize>,
    d2v_ddq_dq: Vec<Twist>,
    d2v_dq_dq: Vec<Twist>,
}

impl TreeSystem {
    /// Builds the interpreted system for a validated model.
    pub fn new(model: &Model, evaluation: Evaluation) -> Result<Self, SimError> {
        if let Some(v) = model.variables.iter().find(|v| v.kinematic) {
            return Err(SimError::Unsupported(format!(
                "variable `{}` is kinematic; prescribed variables are not supported yet",
                v.name
            )));
        }
        let plan = TreePlan::new(model);
        let mut tri_offset = Vec::with_capacity(plan.frames.len());
        let mut tris = 0;
        for f in &plan.frames {
            tri_offset.push(tris);
            tris += f.n * (f.n + 1) / 2;
        }
        let folded = TreePlan::folded(model);
        Ok(TreeSystem {
            model: model.clone(),
            evaluation,
            ws: Workspace::new(&plan),
            folded_ws: Workspace::new(&folded),
            folded,
            plan,
            tri_offset,
            d2v_ddq_dq: vec![[0.0; 6]; tris],
            d2v_dq_dq: vec![[0.0; 6]; tris],
        })
    }

    /// The model this system was built from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The evaluation mode.
    pub fn evaluation(&self) -> Evaluation {
        self.evaluation
    }

    /// Switches the evaluation mode.
    pub fn set_evaluation(&mut self, evaluation: Evaluation) {
        self.evaluation = evaluation;
    }

    /// Every frame's body velocity `v_k` and its columns, for checking against finite
    /// differences.
    pub fn frame_velocities(&mut self, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Vec<FrameVelocity> {
        sweeps::forward(&self.plan, &mut self.ws, q.as_slice(), dq.as_slice(), true);
        (0..self.plan.frames.len())
            .map(|k| {
                let f = &self.plan.frames[k];
                let cols = (0..f.n)
                    .map(|a| {
                        (
                            self.plan.vars[f.var_start + a],
                            self.ws.jac[f.col_offset + a],
                            self.ws.dv_dq[f.col_offset + a],
                        )
                    })
                    .collect();
                (self.ws.velocity[k], cols)
            })
            .collect()
    }
}

impl System for TreeSystem {
    type N = Dyn;

    fn dim(&self) -> Dyn {
        Dyn(self.model.variables.len())
    }

    fn variable_name(&self, i: usize) -> &str {
        &self.model.variables[i].name
    }

    fn frame_count(&self) -> usize {
        self.model.frames.len()
    }

    fn frame_name(&self, k: usize) -> &str {
        &self.model.frames[k].name
    }

    fn initial(&self, i: usize) -> (f64, f64) {
        let v = &self.model.variables[i];
        (v.q0, v.dq0)
    }

    fn damping(&self, i: usize) -> f64 {
        self.model.variables[i].damping
    }

    fn lagrangian(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        out.clear(order);
        let (q, dq) = (q.as_slice(), dq.as_slice());
        match self.evaluation {
            Evaluation::Sweeps => {
                sweeps::evaluate(&self.folded, &mut self.folded_ws, q, dq, order, out)
            }
            Evaluation::Cached => {
                sweeps::forward(&self.plan, &mut self.ws, q, dq, false);
                self.second_order_caches(order);
                self.accumulate_cached(order, out);
            }
            Evaluation::Uncached => self.accumulate_uncached(q, dq, order, out),
        }
    }

    fn poses(&mut self, q: &Vector<Dyn>, out: &mut [Pose]) {
        sweeps::poses(&self.plan, q.as_slice(), out);
    }
}
