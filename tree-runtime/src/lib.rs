//! # tree-runtime
//!
//! Simulation of mechanical systems described as trees of frames (Johnson & Murphey): the
//! [`System`] trait that interpreted and generated systems share, its [`Terms`] and
//! [`ConstraintTerms`], the interpreted [`TreeSystem`], continuous [`dynamics`], the
//! integrators in [`integrate`], the recorded [`Trajectory`] and the errors ([`SimError`]);
//! and [`cone`], the second-order cone's algebra the contact solver is to use.
//!
//! Beneath them, the kernel (`tree-kernel`): the recursions over any scalar, evaluated here
//! over `f64`, dual numbers and SIMD lanes, and compiled by `tree_model!` with a tracing
//! scalar. Optimal control on these systems is `tree-control`'s.
//!
//! ```
//! use tree_runtime::{integrate::{simulate, Method, SimOptions, ViSettings}, NoForce, System, TreeSystem};
//! let model = tree_model::n_link_pendulum(2);
//! let mut sys = TreeSystem::new(&model).unwrap();
//! let (q0, dq0) = sys.initial_state();
//! let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 1.0);
//! let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
//! assert_eq!(traj.len(), 101);
//! assert!(traj.max_energy_error() < 1e-2);
//! ```
#![warn(missing_docs)]

pub mod batch;
pub mod cone;
mod context;
pub mod dynamics;
mod error;
pub mod evaluation;
pub mod integrate;
mod interpreted;
pub mod kinematics;
#[doc(hidden)]
pub mod linalg;
pub mod linearize;
pub mod memory;
mod reference;
pub mod report;
mod system;
mod trajectory;

pub use tree_kernel::{Order, Pose, Twist};
pub use tree_model;

pub use {
    context::StepContext,
    dynamics::{Baumgarte, Dynamics, GeneralizedForce, ModelMotions, NoForce, Prescription},
    error::{Seconds, SimError},
    interpreted::{columns_fit, AddedTerms, Ask, TreeSystem},
    reference::{PaperEvaluation, PaperSystem},
    system::{ConstraintTerms, Matrix, Sparsity, System, Terms, Vector},
    trajectory::{CsvStream, Sample, Trajectory},
};

/// Re-exported for generated code and users: the linear-algebra crate of every vector.
pub use nalgebra;
