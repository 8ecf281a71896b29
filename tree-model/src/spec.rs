//! The model as written, before validation: what the TOML reader, the builder and the
//! `tree_model!` macro all produce, so that one validator gives every path one meaning.

use crate::primitive::Primitive;

/// A frame as written: a name, a parent name and the primitives given for it (validation
/// requires exactly one).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSpec {
    /// The frame's name.
    pub name: String,
    /// `None` means the world frame.
    pub parent: Option<String>,
    /// Every primitive written for it.
    pub primitives: Vec<Primitive>,
    /// Mass in kg.
    pub mass: Option<f64>,
    /// The centre of mass in the frame's axes.
    pub com: Option<[f64; 3]>,
    /// About the centre of mass in the frame's axes: `[ixx, iyy, izz]` (principal axes along
    /// the frame's) or `[ixx, iyy, izz, ixy, ixz, iyz]` (validated).
    pub inertia: Option<Vec<f64>>,
}

/// Per-variable settings as written; every field optional.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VariableSpec {
    /// The variable's name.
    pub name: String,
    /// Initial value.
    pub q0: Option<f64>,
    /// Initial velocity.
    pub dq0: Option<f64>,
    /// Viscous damping coefficient.
    pub damping: Option<f64>,
    /// Whether the variable is prescribed rather than simulated.
    pub kinematic: Option<bool>,
    /// A sinusoidal prescription (kinematic variables only).
    pub motion: Option<SineSpec>,
    /// Samples `(t, q)` of a spline prescription (kinematic variables only).
    pub samples: Option<Vec<[f64; 2]>>,
    /// `[lower, upper]` joint limits (a dynamic variable's enforced by the VI unless the model
    /// says `enforce_limits = false`).
    pub limits: Option<[f64; 2]>,
}

/// A whole model as written.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    /// The model's name.
    pub name: String,
    /// Gravity (default (0, 0, −9.81)).
    pub gravity: Option<[f64; 3]>,
    /// Frames in order, parents first.
    pub frames: Vec<FrameSpec>,
    /// Per-variable settings.
    pub variables: Vec<VariableSpec>,
    /// `[[constraint]]` entries.
    pub constraints: Vec<ConstraintSpec>,
    /// `[[spring]]` entries.
    pub springs: Vec<SpringSpec>,
    /// `[[damper]]` entries.
    pub dampers: Vec<DamperSpec>,
    /// `[[input]]` entries.
    pub inputs: Vec<InputSpec>,
    /// `[ground]`, `[[contact]]` and `enforce_limits`.
    pub contacts: crate::contact::ContactsSpec,
}

impl ModelSpec {
    /// A model named `name` with nothing in it yet (default gravity).
    pub fn new(name: impl Into<String>) -> Self {
        ModelSpec {
            name: name.into(),
            gravity: None,
            frames: Vec::new(),
            variables: Vec::new(),
            constraints: Vec::new(),
            springs: Vec::new(),
            dampers: Vec::new(),
            inputs: Vec::new(),
            contacts: Default::default(),
        }
    }
}

/// A prescribed sinusoid as written: `q = offset + amplitude·sin(2πf t + phase)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SineSpec {
    /// Mean value (default 0).
    pub offset: Option<f64>,
    /// Amplitude (default 0).
    pub amplitude: Option<f64>,
    /// Frequency in Hz (default 0).
    pub frequency: Option<f64>,
    /// Phase in rad (default 0).
    pub phase: Option<f64>,
}

/// A constraint's length as written: a number or a variable name.
#[derive(Clone, Debug, PartialEq)]
pub enum ParameterSpec {
    /// A fixed length.
    Constant(f64),
    /// A variable's name.
    Variable(String),
}

/// A `[[constraint]]` as written; which fields belong depends on `kind` (validated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConstraintSpec {
    /// Name (default `constraint<n>`).
    pub name: Option<String>,
    /// `distance`, `plane` or `point`.
    pub kind: String,
    /// The two frames, by name.
    pub frames: Vec<String>,
    /// A distance constraint's length.
    pub length: Option<ParameterSpec>,
    /// A plane constraint's normal, in frame a's axes.
    pub normal: Option<[f64; 3]>,
    /// A point constraint's world axes, e.g. `"xz"`.
    pub axes: Option<String>,
    /// A distance constraint that is a string: `‖p_a − p_b‖ ≤ length`, pulling only.
    pub slack: Option<bool>,
}

/// A `[[spring]]` as written: between two frames, or on one variable.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SpringSpec {
    /// Two frames, for a spring between them.
    pub frames: Option<Vec<String>>,
    /// One variable, for a spring on it.
    pub variable: Option<String>,
    /// Stiffness k.
    pub stiffness: Option<f64>,
    /// Rest length or value (default 0).
    pub rest: Option<f64>,
}

/// An `[[input]]` as written: a generalized force on one dynamic variable.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InputSpec {
    /// Unique name.
    pub name: String,
    /// The dynamic variable it is a generalized force on, by name.
    pub variable: Option<String>,
    /// `[lo, hi]` bounds (kept for controllers; a simulation applies what it is given).
    pub limits: Option<[f64; 2]>,
}

/// A `[[damper]]` as written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DamperSpec {
    /// The two frames, by name.
    pub frames: Vec<String>,
    /// Damping coefficient c.
    pub damping: Option<f64>,
}
