//! # tree-mech
//!
//! Simulators for mechanical systems described as trees of frames (Johnson & Murphey, *Discrete and
//! Continuous Mechanics for Tree Representations of Mechanical Systems*, ICRA 2008).
//! This facade re-exports the model crate and the runtime; depend on `tree-mech` alone.

// The expansion of `tree_model!` names `::tree_mech`; this lets it work inside this crate too.
extern crate self as tree_mech;

/// Compiles a model into a type implementing [`System`] (see the README).
pub use tree_macros::tree_model;
/// The model crate: model types, the TOML reader, the builder, validation.
pub use tree_model as model;
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    integrate, ConstraintTerms, GeneralizedForce, NoForce, Order, PaperEvaluation, PaperSystem,
    SimError, System, Terms, Trajectory, TreeSystem,
};
