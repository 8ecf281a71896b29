//! The interpreted tree system: walks the validated model at run time, with the
//! recursions of DESIGN.md §3, in one of three [`Evaluation`] modes.

mod accumulate;
mod cached;
mod sweeps;
mod uncached;

use nalgebra::Dyn;
use tree_model::{Joint, Mass, Model, PrimitiveKind};

use crate::error::SimError;
use crate::se3::{LocalTransform, Pose, SpatialInertia, Twist, Wrench};
use crate::system::{Order, System, Terms, Vector};

/// How the interpreted system evaluates the Lagrangian terms. All three give the same
/// numbers (to rounding); they differ in cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Evaluation {
    /// Outward and inward sweeps with composite bodies: every per-frame quantity once, every
    /// derivative entry O(1). The default, and what `tree_model!` unrolls.
    #[default]
    Sweeps,
    /// The paper's per-mass sums (eqs. (15)–(18)) over per-frame quantities computed once per
    /// evaluation and cached, second derivatives of the body velocities included.
    Cached,
    /// The same sums with every quantity recomputed from the root on demand, as a symbolic
    /// expansion would (caching off; the paper's Fig. 3 comparison).
    Uncached,
}

/// One frame as the runtime needs it.
#[derive(Clone, Debug)]
pub(crate) struct FrameInfo {
    pub parent: Option<usize>,
    pub kind: PrimitiveKind,
    pub joint: Joint,
    /// Ancestor variables (root first, own last when driven): `vars[var_start..var_start+n]`.
    pub var_start: usize,
    pub n: usize,
    /// Offset of this frame's `n` twists in the column buffers.
    pub col_offset: usize,
    /// Offset of this frame's `n(n+1)/2` twists in the triangular buffers.
    pub tri_offset: usize,
    /// Whether this frame or a descendant carries mass (else it is skipped).
    pub needed: bool,
    pub mass: Option<Mass>,
}

impl FrameInfo {
    /// Position of the own variable in the ancestor list, when the frame is driven.
    pub fn own(&self) -> Option<usize> {
        matches!(self.joint, Joint::Variable(_)).then(|| self.n - 1)
    }
}

/// Index of `(a, b)`, `a ≥ b`, in a packed lower triangle.
#[inline(always)]
pub(crate) fn tri(a: usize, b: usize) -> usize {
    a * (a + 1) / 2 + b
}

/// A frame's body velocity and, for each variable i that moves it, `(i, ∂v/∂q̇_i, ∂v/∂q_i)`.
pub type FrameVelocity = (Twist, Vec<(usize, Twist, Twist)>);

/// The interpreted system.
#[derive(Clone, Debug)]
pub struct TreeSystem {
    model: Model,
    evaluation: Evaluation,
    frames: Vec<FrameInfo>,
    vars: Vec<usize>,
    // Per-evaluation caches (DESIGN.md §3): poses, body velocities, ∂v/∂q̇, ∂v/∂q,
    // ∂²v/∂q̇∂q (strictly lower: a > b holds ∂²v/∂q̇_b∂q_a), ∂²v/∂q∂q (lower triangle).
    pose: Vec<Pose>,
    velocity: Vec<Twist>,
    jac: Vec<Twist>,
    dv_dq: Vec<Twist>,
    d2v_ddq_dq: Vec<Twist>,
    d2v_dq_dq: Vec<Twist>,
    // Sweeps: local transforms, and per subtree its composite inertia, momentum wrench,
    // first mass moment and (constant) mass, all in the subtree root's frame.
    local: Vec<LocalTransform>,
    inertia: Vec<SpatialInertia>,
    wrench: Vec<Wrench>,
    moment: Vec<[f64; 3]>,
    subtree_mass: Vec<f64>,
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
        let has_mass = model.subtree_has_mass();
        let mut frames: Vec<FrameInfo> = Vec::with_capacity(model.frames.len());
        let mut vars = Vec::new();
        let (mut cols, mut tris) = (0, 0);
        for (k, f) in model.frames.iter().enumerate() {
            let var_start = vars.len();
            if let Some(p) = f.parent {
                let (s, n) = (frames[p].var_start, frames[p].n);
                vars.extend_from_within(s..s + n);
            }
            if let Joint::Variable(i) = f.joint {
                vars.push(i);
            }
            let n = vars.len() - var_start;
            frames.push(FrameInfo {
                parent: f.parent,
                kind: f.primitive,
                joint: f.joint,
                var_start,
                n,
                col_offset: cols,
                tri_offset: tris,
                needed: has_mass[k],
                mass: f.mass.filter(|m| m.is_nonzero()),
            });
            cols += n;
            tris += n * (n + 1) / 2;
        }
        let nf = model.frames.len();
        let mut subtree_mass = vec![0.0; nf];
        for k in (0..nf).rev() {
            subtree_mass[k] += model.frames[k].mass.map_or(0.0, |m| m.mass);
            if let Some(p) = model.frames[k].parent {
                subtree_mass[p] += subtree_mass[k];
            }
        }
        Ok(TreeSystem {
            model: model.clone(),
            evaluation,
            frames,
            vars,
            pose: vec![Pose::IDENTITY; model.frames.len()],
            velocity: vec![[0.0; 6]; model.frames.len()],
            jac: vec![[0.0; 6]; cols],
            dv_dq: vec![[0.0; 6]; cols],
            d2v_ddq_dq: vec![[0.0; 6]; tris],
            d2v_dq_dq: vec![[0.0; 6]; tris],
            local: model
                .frames
                .iter()
                .map(|f| LocalTransform::new(f.primitive, 0.0))
                .collect(),
            inertia: vec![SpatialInertia::default(); nf],
            wrench: vec![[0.0; 6]; nf],
            moment: vec![[0.0; 3]; nf],
            subtree_mass,
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

    /// Body velocity `v_k` and body Jacobian column `∂v_k/∂q̇_i` of every frame, for
    /// checking against finite differences: `(v_k, [(i, ∂v_k/∂q̇_i, ∂v_k/∂q_i)])`.
    pub fn frame_velocities(&mut self, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Vec<FrameVelocity> {
        self.forward(q.as_slice(), dq.as_slice(), Order::First, true);
        (0..self.frames.len())
            .map(|k| {
                let f = &self.frames[k];
                let cols = (0..f.n)
                    .map(|a| {
                        (
                            self.vars[f.var_start + a],
                            self.jac[f.col_offset + a],
                            self.dv_dq[f.col_offset + a],
                        )
                    })
                    .collect();
                (self.velocity[k], cols)
            })
            .collect()
    }

    fn joint_value(&self, joint: Joint, q: &[f64]) -> f64 {
        match joint {
            Joint::Constant(x) => x,
            Joint::Variable(i) => q[i],
        }
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
        match self.evaluation {
            Evaluation::Sweeps => self.evaluate_sweeps(q.as_slice(), dq.as_slice(), order, out),
            Evaluation::Cached => {
                self.forward(q.as_slice(), dq.as_slice(), order, false);
                self.accumulate_cached(order, out);
            }
            Evaluation::Uncached => {
                self.accumulate_uncached(q.as_slice(), dq.as_slice(), order, out)
            }
        }
    }

    fn poses(&mut self, q: &Vector<Dyn>, out: &mut [Pose]) {
        for (k, f) in self.frames.iter().enumerate() {
            let local =
                crate::se3::LocalTransform::new(f.kind, self.joint_value(f.joint, q.as_slice()));
            let parent = f.parent.map_or(Pose::IDENTITY, |p| out[p]);
            out[k] = local.compose_onto(&parent);
        }
    }
}
