//! # tree-mech
//!
//! Simulators for mechanical systems described as trees of frames (Johnson & Murphey, *Discrete and
//! Continuous Mechanics for Tree Representations of Mechanical Systems*, ICRA 2008).
//! This facade re-exports the model crate and the runtime; depend on `tree-mech` alone.

// The expansion of `tree_model!` names `::tree_mech`; this lets it work inside this crate too.
extern crate self as tree_mech;

pub use tree_macros::tree_model;
pub extern crate tree_model;
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    integrate, ConstraintTerms, GeneralizedForce, NoForce, Order, PaperEvaluation, PaperSystem,
    SimError, System, Terms, Trajectory, TreeSystem,
};
