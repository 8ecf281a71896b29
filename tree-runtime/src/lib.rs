//! # tree-runtime
//!
//! Simulation of mechanical systems described as trees of frames (Johnson & Murphey): the
//! [`System`] trait that interpreted and generated systems share, its [`Terms`] and
//! [`ConstraintTerms`], the interpreted [`TreeSystem`], continuous [`dynamics`], the
//! integrators in [`integrate`], the recorded [`Trajectory`] and the errors ([`SimError`]).
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
pub mod context;
pub mod dynamics;
pub mod error;
pub mod evaluation;
pub mod integrate;
pub mod interpreted;
pub mod kinematics;
#[doc(hidden)]
pub mod linalg;
pub mod linearize;
pub mod memory;
pub mod reference;
pub mod report;
pub mod system;
pub mod trajectory;

pub use tree_kernel::{Order, Pose, Twist};
pub use tree_model;

pub use {
    dynamics::{Baumgarte, Dynamics, GeneralizedForce, ModelMotions, NoForce, Prescription},
    error::{Seconds, SimError},
    interpreted::TreeSystem,
    reference::{PaperEvaluation, PaperSystem},
    system::{ConstraintTerms, Matrix, System, Terms, Vector},
    trajectory::{CsvStream, Sample, Trajectory},
};

/// Re-exported for generated code and users: the linear-algebra crate of every vector.
pub use nalgebra;
