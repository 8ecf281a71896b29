//! # tree-mech
//!
//! Simulators for mechanical systems described as trees of frames (Johnson & Murphey, *Scalable
//! Variational Integrators for Constrained Mechanical Systems in Generalized Coordinates*).
//! This facade re-exports the model crate and the runtime; depend on `tree-mech` alone.

// The expansion of `tree_model!` names `::tree_mech`; this lets it work inside this crate too.
extern crate self as tree_mech;

pub use tree_macros::tree_model;
pub extern crate tree_model;
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    integrate, Evaluation, GeneralizedForce, NoForce, Order, SimError, System, Terms, Trajectory,
    TreeSystem,
};
