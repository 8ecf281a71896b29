//! The validated model: a tree of frames in topological order, variables numbered in the
//! order they first appear in the frame list.

use crate::primitive::PrimitiveKind;

/// Standard gravity along −Z, the default.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// A mass at a frame's origin, principal axes along the frame's axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mass {
    pub mass: f64,
    /// `(Ixx, Iyy, Izz)`.
    pub inertia: [f64; 3],
}

impl Mass {
    /// A point mass.
    pub fn point(mass: f64) -> Self {
        Mass {
            mass,
            inertia: [0.0; 3],
        }
    }

    /// True when it has positive mass or any positive inertia.
    pub fn is_nonzero(&self) -> bool {
        self.mass > 0.0 || self.inertia.iter().any(|&i| i > 0.0)
    }
}

/// The parameter of a frame's primitive after validation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Joint {
    Constant(f64),
    /// Index into [`Model::variables`].
    Variable(usize),
}

/// A frame of the validated tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub name: String,
    /// Index of the parent frame; `None` for a child of the world frame. Always smaller
    /// than this frame's own index.
    pub parent: Option<usize>,
    pub primitive: PrimitiveKind,
    pub joint: Joint,
    pub mass: Option<Mass>,
}

/// A configuration variable and its settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable {
    pub name: String,
    /// The one frame this variable drives.
    pub frame: usize,
    pub q0: f64,
    pub dq0: f64,
    /// Viscous damping coefficient: generalized force `−c q̇`.
    pub damping: f64,
    /// Reserved: prescribed (kinematic) variables come in a later release.
    pub kinematic: bool,
}

/// A validated tree model.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    pub name: String,
    pub gravity: [f64; 3],
    /// Frames in topological order (every parent before its children).
    pub frames: Vec<Frame>,
    /// Variables in the order they first appear in `frames`.
    pub variables: Vec<Variable>,
}

impl Model {
    /// Number of configuration variables.
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// Index of the frame with this name.
    pub fn frame_index(&self, name: &str) -> Option<usize> {
        self.frames.iter().position(|f| f.name == name)
    }

    /// Index of the variable with this name.
    pub fn variable_index(&self, name: &str) -> Option<usize> {
        self.variables.iter().position(|v| v.name == name)
    }

    /// For each frame, whether it or any descendant carries a non-zero mass.
    pub fn subtree_has_mass(&self) -> Vec<bool> {
        let mut has = vec![false; self.frames.len()];
        for k in (0..self.frames.len()).rev() {
            if self.frames[k].mass.is_some_and(|m| m.is_nonzero()) {
                has[k] = true;
            }
            if has[k] {
                if let Some(p) = self.frames[k].parent {
                    has[p] = true;
                }
            }
        }
        has
    }

    /// The sum of all masses.
    pub fn total_mass(&self) -> f64 {
        self.frames
            .iter()
            .filter_map(|f| f.mass.map(|m| m.mass))
            .sum()
    }

    /// The tree drawn as indented text, one frame a line.
    pub fn tree_text(&self) -> String {
        let mut out = String::from("world\n");
        let mut depth = vec![0usize; self.frames.len()];
        for (k, f) in self.frames.iter().enumerate() {
            depth[k] = f.parent.map_or(1, |p| depth[p] + 1);
        }
        for (k, f) in self.frames.iter().enumerate() {
            let param = match f.joint {
                Joint::Constant(x) => format!("{x}"),
                Joint::Variable(i) => self.variables[i].name.clone(),
            };
            let mass = match f.mass {
                Some(m) => format!(
                    "  [m = {}, I = ({}, {}, {})]",
                    m.mass, m.inertia[0], m.inertia[1], m.inertia[2]
                ),
                None => String::new(),
            };
            out.push_str(&format!(
                "{}└─ {} = {}({}){}\n",
                "   ".repeat(depth[k] - 1),
                f.name,
                f.primitive,
                param,
                mass
            ));
        }
        out
    }
}
