//! The model as written, before validation: what the TOML reader, the builder and the
//! `tree_model!` macro all produce, so that one validator gives every path one meaning.

use crate::primitive::Primitive;

/// A frame as written: a name, a parent name and the primitives given for it (validation
/// requires exactly one).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSpec {
    pub name: String,
    /// `None` means the world frame.
    pub parent: Option<String>,
    pub primitives: Vec<Primitive>,
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
    pub name: String,
    pub q0: Option<f64>,
    pub dq0: Option<f64>,
    pub damping: Option<f64>,
    pub kinematic: Option<bool>,
    /// A sinusoidal prescription (kinematic variables only).
    pub motion: Option<SineSpec>,
    /// Samples `(t, q)` of a spline prescription (kinematic variables only).
    pub samples: Option<Vec<[f64; 2]>>,
    /// `[lower, upper]` joint limits: kept and reported, not enforced.
    pub limits: Option<[f64; 2]>,
}

/// A whole model as written.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    pub name: String,
    pub gravity: Option<[f64; 3]>,
    pub frames: Vec<FrameSpec>,
    pub variables: Vec<VariableSpec>,
    pub constraints: Vec<ConstraintSpec>,
    pub springs: Vec<SpringSpec>,
    pub dampers: Vec<DamperSpec>,
}

/// A prescribed sinusoid as written: `q = offset + amplitude·sin(2πf t + phase)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SineSpec {
    pub offset: Option<f64>,
    pub amplitude: Option<f64>,
    pub frequency: Option<f64>,
    pub phase: Option<f64>,
}

/// A constraint's length as written: a number or a variable name.
#[derive(Clone, Debug, PartialEq)]
pub enum ParameterSpec {
    Constant(f64),
    Variable(String),
}

/// A `[[constraint]]` as written; which fields belong depends on `kind` (validated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConstraintSpec {
    pub name: Option<String>,
    pub kind: String,
    pub frames: Vec<String>,
    pub length: Option<ParameterSpec>,
    pub normal: Option<[f64; 3]>,
    pub axes: Option<String>,
}

/// A `[[spring]]` as written: between two frames, or on one variable.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SpringSpec {
    pub frames: Option<Vec<String>>,
    pub variable: Option<String>,
    pub stiffness: Option<f64>,
    pub rest: Option<f64>,
}

/// A `[[damper]]` as written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DamperSpec {
    pub frames: Vec<String>,
    pub damping: Option<f64>,
}
