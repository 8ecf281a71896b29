//! The validated model: a tree of frames in topological order, variables numbered in the
//! order they first appear in the frame list.

use crate::motion::Motion;
use crate::number::Given;
use crate::primitive::PrimitiveKind;

/// Standard gravity along −Z, the default.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// A frame's rigid body: its mass, centre of mass and inertia tensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mass {
    /// Mass in kg.
    pub mass: f64,
    /// The centre of mass in the frame's axes (the frame origin by default).
    pub com: [f64; 3],
    /// The inertia tensor about the centre of mass, in the frame's axes (symmetric).
    pub inertia: [[f64; 3]; 3],
}

impl Mass {
    /// A point mass at the frame origin.
    pub fn point(mass: f64) -> Self {
        Mass::principal(mass, [0.0; 3])
    }

    /// A body centred at the frame origin with principal axes along the frame's axes.
    pub fn principal(mass: f64, moments: [f64; 3]) -> Self {
        let mut inertia = [[0.0; 3]; 3];
        for k in 0..3 {
            inertia[k][k] = moments[k];
        }
        Mass {
            mass,
            com: [0.0; 3],
            inertia,
        }
    }

    /// `(Ixx, Iyy, Izz)` when the body is centred at the frame origin with principal axes
    /// along the frame's (the paper's bodies); `None` otherwise.
    pub fn diagonal(&self) -> Option<[f64; 3]> {
        let i = &self.inertia;
        let off = [i[0][1], i[0][2], i[1][2]];
        (self.com == [0.0; 3] && off == [0.0; 3]).then_some([i[0][0], i[1][1], i[2][2]])
    }

    /// The tensor as written in files: `[ixx, iyy, izz, ixy, ixz, iyz]`.
    pub fn inertia6(&self) -> [f64; 6] {
        let i = &self.inertia;
        [i[0][0], i[1][1], i[2][2], i[0][1], i[0][2], i[1][2]]
    }

    /// `m = …, I = (…)`, with the centre of mass and products of inertia when present.
    pub fn describe(&self) -> String {
        let [xx, yy, zz, xy, xz, yz] = self.inertia6().map(Given);
        let mut s = match self.diagonal() {
            Some(_) => format!("m = {}, I = ({xx}, {yy}, {zz})", Given(self.mass)),
            None => format!(
                "m = {}, I = (xx {xx}, yy {yy}, zz {zz}, xy {xy}, xz {xz}, yz {yz})",
                Given(self.mass)
            ),
        };
        if self.com != [0.0; 3] {
            let [x, y, z] = self.com.map(Given);
            s += &format!(", com = ({x}, {y}, {z})");
        }
        s
    }

    /// True when it has positive mass or any non-zero inertia.
    pub fn is_nonzero(&self) -> bool {
        self.mass > 0.0 || self.inertia.iter().flatten().any(|&i| i != 0.0)
    }
}

/// The parameter of a frame's primitive after validation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Joint {
    /// A fixed parameter (m or rad).
    Constant(f64),
    /// Index into [`Model::variables`].
    Variable(usize),
    /// Driven by another frame's variable (a URDF mimic joint): `multiplier·q_i + offset`.
    Mimic(Mimic),
}

impl Joint {
    /// The parameter at configuration `q`.
    pub fn value(&self, q: &[f64]) -> f64 {
        match *self {
            Joint::Constant(x) => x,
            Joint::Variable(i) => q[i],
            Joint::Mimic(m) => m.multiplier * q[m.variable] + m.offset,
        }
    }

    /// The variable that moves the transform and `∂x/∂q_i`, the factor its rate enters
    /// with (1, or a mimic's multiplier); `None` for a constant.
    pub fn driver(&self) -> Option<(usize, f64)> {
        match *self {
            Joint::Constant(_) => None,
            Joint::Variable(i) => Some((i, 1.0)),
            Joint::Mimic(m) => Some((m.variable, m.multiplier)),
        }
    }
}

/// A transform that follows a variable of another frame, `x = multiplier·q_i + offset`: the
/// paper's assumption 2 (one variable, one transform) lifted to an affine function of one
/// variable, so `∂x/∂q_i = multiplier` (docs/derivations.md §11).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index into [`Model::variables`] of the variable it follows.
    pub variable: usize,
    /// `∂x/∂q_i`.
    pub multiplier: f64,
    /// `x` at `q_i = 0`.
    pub offset: f64,
    /// Viscous damping on the follower's own motion: generalized force `−c ẋ` on it, so
    /// `−multiplier²·c·q̇_i` on the variable it follows.
    pub damping: f64,
}

impl Mimic {
    /// How it reads in `check` and the tree: `"-1·finger + 0.01"`.
    pub fn describe(&self, variable: &str) -> String {
        let mut s = match self.multiplier {
            1.0 => variable.to_string(),
            m => format!("{}·{variable}", Given(m)),
        };
        if self.offset != 0.0 {
            s += &format!(" + {}", Given(self.offset));
        }
        s
    }
}

/// A frame of the validated tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Unique name.
    pub name: String,
    /// Index of the parent frame; `None` for a child of the world frame. Always smaller
    /// than this frame's own index.
    pub parent: Option<usize>,
    /// The transform by which it hangs off its parent.
    pub primitive: PrimitiveKind,
    /// The transform's parameter: a constant or a variable.
    pub joint: Joint,
    /// The rigid body it carries, if any.
    pub mass: Option<Mass>,
}

/// A configuration variable and its settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable {
    /// Unique name.
    pub name: String,
    /// The one frame this variable drives; `None` for a variable that only sets a constraint's
    /// length (always kinematic).
    pub frame: Option<usize>,
    /// Initial value.
    pub q0: f64,
    /// Initial velocity.
    pub dq0: f64,
    /// Viscous damping coefficient: generalized force `−c q̇`.
    pub damping: f64,
    /// A prescribed variable's motion (`None`: a dynamic variable, simulated).
    pub motion: Option<Motion>,
    /// `[lower, upper]` joint limits (from URDF or `limits = [..]`): a dynamic variable's are
    /// enforced by the variational integrator when [`crate::Contacts::enforce_limits`] (the
    /// default).
    pub limits: Option<[f64; 2]>,
}

impl Variable {
    /// Whether the variable is prescribed rather than simulated.
    pub fn is_kinematic(&self) -> bool {
        self.motion.is_some()
    }
}

/// A scalar that is a constant or a configuration variable (a constraint's length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Parameter {
    /// A fixed length.
    Constant(f64),
    /// Index into [`Model::variables`].
    Variable(usize),
}

/// What a holonomic constraint `h(q) = 0` holds between its two frames' origins `p_a`, `p_b`.
#[derive(Clone, Debug, PartialEq)]
pub enum ConstraintKind {
    /// `h = ‖p_a − p_b‖² − ℓ²`.
    Distance {
        /// The length ℓ: a number or a (usually kinematic) variable.
        length: Parameter,
    },
    /// `h = n·(p_b − p_a)` with `n` fixed in frame a's axes (unit length after validation).
    Plane {
        /// The unit normal, in frame a's axes.
        normal: [f64; 3],
    },
    /// `h_i = e_i·(p_a − p_b)` for each listed world axis (0, 1, 2 for x, y, z): one row each.
    Point {
        /// World axes held equal, each 0, 1 or 2.
        axes: Vec<usize>,
    },
}

/// A holonomic constraint between two frames.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    /// Unique name (the rows of a point constraint are `name.x` …).
    pub name: String,
    /// What it holds.
    pub kind: ConstraintKind,
    /// Frames `a` and `b` (indices into [`Model::frames`]).
    pub frames: [usize; 2],
}

impl Constraint {
    /// Number of scalar equations (rows of `h`).
    pub fn rows(&self) -> usize {
        match &self.kind {
            ConstraintKind::Point { axes } => axes.len(),
            _ => 1,
        }
    }

    /// The name of each row: the constraint's name, with `.x` … for a point constraint.
    pub fn row_names(&self) -> Vec<String> {
        match &self.kind {
            ConstraintKind::Point { axes } => axes
                .iter()
                .map(|&a| format!("{}.{}", self.name, ["x", "y", "z"][a]))
                .collect(),
            _ => vec![self.name.clone()],
        }
    }

    /// What it holds, in words (`tree-mech check` prints it): "distance 0.5", "distance
    /// \`len\`" (a variable's length), "plane, normal [0, 0, 1] in \`a\`", "point, axes xz";
    /// `model` names its frames and variables.
    pub fn describe(&self, model: &Model) -> String {
        let a = &model.frames[self.frames[0]].name;
        match &self.kind {
            ConstraintKind::Distance { length } => match length {
                Parameter::Constant(l) => format!("distance {}", crate::Given(*l)),
                Parameter::Variable(i) => format!("distance `{}`", model.variables[*i].name),
            },
            ConstraintKind::Plane { normal } => format!("plane, normal {normal:?} in `{a}`"),
            ConstraintKind::Point { axes } => format!(
                "point, axes {}",
                axes.iter().map(|&k| ["x", "y", "z"][k]).collect::<String>()
            ),
        }
    }
}

/// What a spring stretches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SpringKind {
    /// The distance between two frames' origins.
    Frames([usize; 2]),
    /// One configuration variable.
    Variable(usize),
}

/// A linear spring with potential `½k(x − rest)²`, part of the Lagrangian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    /// Between two frames, or on one variable.
    pub kind: SpringKind,
    /// Stiffness k (N/m, or N·m/rad on a rotation).
    pub stiffness: f64,
    /// Rest length or rest value.
    pub rest: f64,
}

/// A linear damper between two frames' origins: force `−c·ḋ` along the line joining them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Damper {
    /// The two frames (indices into [`Model::frames`]).
    pub frames: [usize; 2],
    /// Damping coefficient c (N·s/m).
    pub damping: f64,
}

/// An input: a generalized force `u` on one dynamic variable (the model's `B u` has one
/// column per input, a 1 in its variable's row).
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    /// Unique name.
    pub name: String,
    /// Index into [`Model::variables`] of the dynamic variable it acts on.
    pub variable: usize,
    /// `[lo, hi]` bounds, for controllers (a simulation applies what it is given).
    pub limits: Option<[f64; 2]>,
}

/// A validated tree model.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// The model's name.
    pub name: String,
    /// Gravity in world axes (m/s²).
    pub gravity: [f64; 3],
    /// Frames in topological order (every parent before its children).
    pub frames: Vec<Frame>,
    /// Variables in the order they first appear in `frames`, then in `constraints`.
    pub variables: Vec<Variable>,
    /// Holonomic constraints `h(q) = 0`.
    pub constraints: Vec<Constraint>,
    /// Springs: potentials inside L.
    pub springs: Vec<Spring>,
    /// Dampers between frames: forces.
    pub dampers: Vec<Damper>,
    /// Inputs `u`, in declaration order: generalized forces on dynamic variables.
    pub inputs: Vec<Input>,
    /// Limits enforced, the ground, contact spheres and slack strings: the unilateral rows
    /// ([`Model::gaps`]).
    pub contacts: crate::contact::Contacts,
}

impl Model {
    /// Number of configuration variables.
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// Indices of the dynamic (simulated) variables, in order.
    pub fn dynamic(&self) -> Vec<usize> {
        (0..self.dof())
            .filter(|&i| !self.variables[i].is_kinematic())
            .collect()
    }

    /// Indices of the kinematic (prescribed) variables, in order.
    pub fn kinematic(&self) -> Vec<usize> {
        (0..self.dof())
            .filter(|&i| self.variables[i].is_kinematic())
            .collect()
    }

    /// Number of constraint rows.
    pub fn constraint_rows(&self) -> usize {
        self.constraints.iter().map(Constraint::rows).sum()
    }

    /// The name of every constraint row, in order.
    pub fn constraint_row_names(&self) -> Vec<String> {
        self.constraints
            .iter()
            .flat_map(Constraint::row_names)
            .collect()
    }

    /// Whether the model has anything beyond the tree's Lagrangian: kinematic variables,
    /// constraints, springs, dampers.
    pub fn has_elements(&self) -> bool {
        !self.constraints.is_empty()
            || !self.springs.is_empty()
            || !self.dampers.is_empty()
            || self
                .variables
                .iter()
                .any(|v| v.is_kinematic() || v.frame.is_none())
    }

    /// The frames a constraint, spring or damper attaches to, each once, in frame order.
    pub fn attached_frames(&self) -> Vec<usize> {
        let mut used = vec![false; self.frames.len()];
        for c in &self.constraints {
            c.frames.iter().for_each(|&f| used[f] = true);
        }
        for s in &self.springs {
            if let SpringKind::Frames(fr) = s.kind {
                fr.iter().for_each(|&f| used[f] = true);
            }
        }
        for d in &self.dampers {
            d.frames.iter().for_each(|&f| used[f] = true);
        }
        for g in self.gaps() {
            g.frames().into_iter().for_each(|f| used[f] = true);
        }
        (0..self.frames.len()).filter(|&k| used[k]).collect()
    }

    /// Whether variable `i` drives a rotation (`rx ry rz`): an angle, in rad.
    pub fn is_angle(&self, i: usize) -> bool {
        self.variables[i]
            .frame
            .is_some_and(|f| self.frames[f].primitive.is_rotation())
    }

    /// Every frame's origin in world coordinates at configuration `q`, by composing the
    /// primitives down the tree (for checks and pictures; the runtime has the fast path).
    pub fn origins(&self, q: &[f64]) -> Vec<[f64; 3]> {
        // (rotation, translation) of each frame in the world.
        let mut poses: Vec<([[f64; 3]; 3], [f64; 3])> = Vec::with_capacity(self.frames.len());
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for f in &self.frames {
            let (r, p) = f.parent.map_or((identity, [0.0; 3]), |k| poses[k]);
            let x = f.joint.value(q);
            let axis = f.primitive.axis();
            let pose = if f.primitive.is_rotation() {
                // R_child = R · rot(axis, x): columns (a, b) of the plane turned by x.
                let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                let (s, c) = x.sin_cos();
                let mut out = r;
                for row in 0..3 {
                    out[row][a] = c * r[row][a] + s * r[row][b];
                    out[row][b] = -s * r[row][a] + c * r[row][b];
                }
                (out, p)
            } else {
                (r, [0, 1, 2].map(|row| p[row] + r[row][axis] * x))
            };
            poses.push(pose);
        }
        poses.into_iter().map(|(_, p)| p).collect()
    }

    /// Index of the frame with this name.
    pub fn frame_index(&self, name: &str) -> Option<usize> {
        self.frames.iter().position(|f| f.name == name)
    }

    /// Index of the variable with this name.
    pub fn variable_index(&self, name: &str) -> Option<usize> {
        self.variables.iter().position(|v| v.name == name)
    }

    /// Sets frame `frame`'s mass, keeping its centre of mass and inertia (a frame without a
    /// body gets a point mass): a parameter changed without touching the structure (a
    /// sweep's). Refuses an unknown frame or a mass that is not finite and positive.
    pub fn set_mass(&mut self, frame: &str, mass: f64) -> Result<(), String> {
        let f = self.frame_for_change(frame)?;
        if !(mass.is_finite() && mass > 0.0) {
            return Err(format!(
                "the mass of frame `{frame}` must be finite and positive, got {}",
                crate::Given(mass)
            ));
        }
        let body = self.frames[f].mass.get_or_insert(Mass::point(mass));
        body.mass = mass;
        Ok(())
    }

    /// Sets the constant parameter of frame `frame`'s primitive (a length in m or an angle in
    /// rad): a sweep's parameter. Refuses an unknown frame, a frame driven by a variable and
    /// a value that is not finite.
    pub fn set_constant(&mut self, frame: &str, value: f64) -> Result<(), String> {
        let f = self.frame_for_change(frame)?;
        if !value.is_finite() {
            return Err(format!(
                "the parameter of frame `{frame}` must be finite, got {}",
                crate::Given(value)
            ));
        }
        match &mut self.frames[f].joint {
            Joint::Constant(x) => {
                *x = value;
                Ok(())
            }
            Joint::Variable(i) | Joint::Mimic(Mimic { variable: i, .. }) => Err(format!(
                "frame `{frame}` is driven by variable `{}`, not a constant",
                self.variables[*i].name
            )),
        }
    }

    fn frame_for_change(&self, frame: &str) -> Result<usize, String> {
        self.frame_index(frame)
            .ok_or_else(|| format!("the model has no frame `{frame}`"))
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
                Joint::Constant(x) => Given(x).to_string(),
                Joint::Variable(i) => self.variables[i].name.clone(),
                Joint::Mimic(m) => m.describe(&self.variables[m.variable].name),
            };
            let mass = match f.mass {
                Some(m) => format!("  [{}]", m.describe()),
                None => String::new(),
            };
            // Deep trees are indented up to 24 levels, then labelled with their depth.
            let indent = if depth[k] <= 24 {
                "   ".repeat(depth[k] - 1)
            } else {
                format!("{}[depth {}] ", "   ".repeat(23), depth[k])
            };
            out.push_str(&format!(
                "{indent}└─ {} = {}({}){}\n",
                f.name, f.primitive, param, mass
            ));
        }
        out
    }
}
