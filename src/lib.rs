//! # tree-mech
//!
//! Simulators for mechanical systems described as trees of frames (Johnson & Murphey, *Scalable
//! Variational Integrators for Constrained Mechanical Systems in Generalized Coordinates*).
//! This facade re-exports the model crate and the runtime; depend on `tree-mech` alone.

pub use tree_model;
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    integrate, Evaluation, GeneralizedForce, NoForce, Order, SimError, System, Terms, Trajectory,
    TreeSystem,
};
