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
    /// `(Ixx, Iyy, Izz)` about the frame's own axes.
    pub inertia: Option<[f64; 3]>,
}

/// Per-variable settings as written; every field optional.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VariableSpec {
    pub name: String,
    pub q0: Option<f64>,
    pub dq0: Option<f64>,
    pub damping: Option<f64>,
    pub kinematic: Option<bool>,
}

/// A whole model as written.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    pub name: String,
    pub gravity: Option<[f64; 3]>,
    pub frames: Vec<FrameSpec>,
    pub variables: Vec<VariableSpec>,
}
