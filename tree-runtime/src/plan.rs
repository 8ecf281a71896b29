//! The structure of a validated model as the recursions walk it: for each frame its parent,
//! primitive, parameter, the variables that move it, where its columns live, and whether any
//! mass hangs at or below it. Built once; shared by every evaluation mode and by the compiler.

use tree_model::{Joint, Mass, Model, PrimitiveKind};

/// One frame of the plan.
#[derive(Clone, Debug, PartialEq)]
pub struct FramePlan {
    pub parent: Option<usize>,
    pub kind: PrimitiveKind,
    pub joint: Joint,
    /// The variables that move this frame, root first (own last when driven):
    /// `TreePlan::vars[var_start..var_start + n]`. A parent's list is a prefix of its child's.
    pub var_start: usize,
    pub n: usize,
    /// Offset of this frame's `n` columns (`∂v/∂q̇_i`, `∂v/∂q_i`) in the column buffers.
    pub col_offset: usize,
    /// Whether this frame or a descendant carries mass; other frames are skipped.
    pub needed: bool,
    /// A non-zero mass at this frame's origin.
    pub mass: Option<Mass>,
    /// Total mass of the subtree rooted here.
    pub subtree_mass: f64,
}

impl FramePlan {
    /// Position of the own variable in the ancestor list, when the frame is driven.
    pub fn own(&self) -> Option<usize> {
        matches!(self.joint, Joint::Variable(_)).then(|| self.n - 1)
    }
}

/// The plan of a whole tree.
#[derive(Clone, Debug, PartialEq)]
pub struct TreePlan {
    pub frames: Vec<FramePlan>,
    /// Concatenated ancestor-variable lists.
    pub vars: Vec<usize>,
    /// The frame each variable drives.
    pub variable_frames: Vec<usize>,
    pub gravity: [f64; 3],
    /// Total number of columns over all frames.
    pub columns: usize,
}

impl TreePlan {
    pub fn new(model: &Model) -> Self {
        let has_mass = model.subtree_has_mass();
        let mut frames: Vec<FramePlan> = Vec::with_capacity(model.frames.len());
        let mut vars = Vec::new();
        let mut columns = 0;
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
            frames.push(FramePlan {
                parent: f.parent,
                kind: f.primitive,
                joint: f.joint,
                var_start,
                n,
                col_offset: columns,
                needed: has_mass[k],
                mass: f.mass.filter(|m| m.is_nonzero()),
                subtree_mass: 0.0,
            });
            columns += n;
        }
        for k in (0..frames.len()).rev() {
            frames[k].subtree_mass += frames[k].mass.map_or(0.0, |m| m.mass);
            if let Some(p) = frames[k].parent {
                frames[p].subtree_mass += frames[k].subtree_mass;
            }
        }
        TreePlan {
            frames,
            vars,
            variable_frames: model.variables.iter().map(|v| v.frame).collect(),
            gravity: model.gravity,
            columns,
        }
    }

    /// The variables that move frame `k`, root first.
    pub fn ancestors(&self, k: usize) -> &[usize] {
        let f = &self.frames[k];
        &self.vars[f.var_start..f.var_start + f.n]
    }

    /// Number of configuration variables.
    pub fn dof(&self) -> usize {
        self.variable_frames.len()
    }
}
