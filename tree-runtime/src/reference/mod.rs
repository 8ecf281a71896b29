//! The paper's own evaluation, kept as a reference: the per-mass sums of eqs. (15)–(18)
//! over per-frame quantities either computed once and cached (`Cached`) or recomputed from
//! the root on demand (`Uncached`, what a symbolic expansion pays — the paper's Fig. 3
//! comparison). It serves the Fig. 3 reproduction and the tests as an independent oracle for
//! the tree's Lagrangian; the main path is [`crate::TreeSystem`] (composite sweeps), which
//! also carries constraints, springs, dampers and kinematic variables. Models with any of
//! those are refused here.

mod accumulate;
mod cached;
mod uncached;

use nalgebra::{DVector, Dyn};
use tree_model::{Joint, Model, Motion};

use crate::error::SimError;
use crate::system::{ConstraintTerms, Order, System, Terms, Vector};
use tree_kernel::kernel::{self, Kernel};
use tree_kernel::se3::{Pose, Twist};
use tree_kernel::sweeps::{self, Workspace};
use tree_kernel::TreePlan;
use tree_kernel::{Dual, DualOutputs};
use tree_kernel::{Output, Sink};

/// How the reference system evaluates the paper's sums.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PaperEvaluation {
    /// Per-frame quantities (second derivatives of the body velocities included) computed
    /// once per evaluation and cached.
    #[default]
    Cached,
    /// Every quantity recomputed from the root on demand (caching off).
    Uncached,
}

/// Index of `(a, b)`, `a ≥ b`, in a packed lower triangle.
#[inline(always)]
pub(crate) fn tri(a: usize, b: usize) -> usize {
    a * (a + 1) / 2 + b
}

/// The tree's Lagrangian by the paper's per-mass sums.
#[derive(Clone, Debug)]
pub struct PaperSystem {
    model: Model,
    evaluation: PaperEvaluation,
    plan: TreePlan,
    ws: Workspace<f64>,
    // Per frame, ∂²v/∂q̇_b∂q_a (b < a, at tri(a, b)) and ∂²v/∂q_a∂q_b (a ≥ b), in packed
    // triangles starting at `tri_offset[k]`.
    tri_offset: Vec<usize>,
    d2v_ddq_dq: Vec<Twist>,
    d2v_dq_dq: Vec<Twist>,
    /// A zero velocity, for [`System::mass_matrix`] (the Lagrangian at rest).
    rest: DVector<f64>,
}

impl PaperSystem {
    /// The reference system for a model of frames and masses only.
    pub fn new(model: &Model, evaluation: PaperEvaluation) -> Result<Self, SimError> {
        if model.has_elements() {
            return Err(SimError::Unsupported(format!(
                "model `{}` has constraints, springs, dampers or kinematic variables; the paper's reference evaluation covers the tree's Lagrangian only (the default evaluation handles them: TreeSystem, or `--evaluation sweeps`)",
                model.name
            )));
        }
        if let Some(f) = model
            .frames
            .iter()
            .find(|f| f.mass.is_some_and(|m| m.diagonal().is_none()))
        {
            return Err(SimError::Unsupported(format!(
                "frame `{}` of model `{}` has a centre of mass off its origin or products of inertia; the paper's per-mass sums take masses at frame origins with principal axes along the frame (the default evaluation handles any body: TreeSystem, or `--evaluation sweeps`)",
                f.name, model.name
            )));
        }
        if let Some(f) = (model.frames.iter()).find(|f| matches!(f.joint, Joint::Mimic(_))) {
            return Err(SimError::Unsupported(format!(
                "frame `{}` of model `{}` follows another frame's variable (a mimic); the paper's per-mass sums take one variable per transform, its assumption 2 (the default evaluation handles mimics: TreeSystem, or `--evaluation sweeps`)",
                f.name, model.name
            )));
        }
        let plan = TreePlan::new(model);
        let mut tri_offset = Vec::with_capacity(plan.frames.len());
        let mut tris = 0;
        for f in &plan.frames {
            tri_offset.push(tris);
            tris += f.n * (f.n + 1) / 2;
        }
        Ok(PaperSystem {
            model: model.clone(),
            evaluation,
            ws: Workspace::new(&plan),
            plan,
            tri_offset,
            d2v_ddq_dq: vec![[0.0; 6]; tris],
            d2v_dq_dq: vec![[0.0; 6]; tris],
            rest: DVector::zeros(model.variables.len()),
        })
    }

    /// The evaluation mode.
    pub fn evaluation(&self) -> PaperEvaluation {
        self.evaluation
    }
}

impl System for PaperSystem {
    type N = Dyn;

    crate::system::described_by_model!();

    fn motion(&self, _: usize) -> Option<Motion> {
        None
    }

    fn constraint_count(&self) -> usize {
        0
    }

    fn constraint_name(&self, r: usize) -> &str {
        panic!("constraint {r} of a model without constraints")
    }

    fn constraints(&mut self, _: &Vector<Dyn>, _: &Vector<Dyn>, _: Order, _: &mut ConstraintTerms) {
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
            PaperEvaluation::Cached => {
                sweeps::forward(
                    &self.plan,
                    &mut self.ws,
                    q,
                    dq,
                    sweeps::Reach::Lagrangian(Order::Full),
                );
                self.second_order_caches(order);
                self.accumulate_cached(order, out);
            }
            PaperEvaluation::Uncached => self.accumulate_uncached(q, dq, order, out),
        }
        // Damping, through the same sink as the interpreted system's forces.
        for (i, v) in self.model.variables.iter().enumerate() {
            if v.damping != 0.0 {
                out.add(Output::Force(i), -v.damping * dq[i]);
                if order >= Order::Full {
                    out.add(Output::DforceDdq(i, i), -v.damping);
                }
            }
        }
    }

    fn mass_matrix(&mut self, q: &Vector<Dyn>, out: &mut Terms<Dyn>) {
        // The paper's own sums at rest (taken out for the call: no allocation).
        let rest = std::mem::take(&mut self.rest);
        self.lagrangian(q, &rest, Order::Dynamics, out);
        self.rest = rest;
    }

    fn poses(&mut self, q: &Vector<Dyn>, out: &mut [Pose]) {
        sweeps::poses(&self.plan, q.as_slice(), out);
    }

    /// The paper's sums are written for `f64`; over dual numbers this is the composite
    /// sweeps' kernel on the same plan (for these models, the tree's Lagrangian alone).
    /// Allocates its kernel.
    fn evaluate_dual(&mut self, q: &[Dual], dq: &[Dual], order: Order, out: &mut DualOutputs) {
        out.clear();
        let mut kernel = Kernel::<Dual>::new(&self.plan);
        kernel::evaluate(&self.plan, &mut kernel, q, dq, order, out);
    }
}
