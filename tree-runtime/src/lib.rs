//! # tree-runtime
//!
//! Simulation of mechanical systems described as trees of frames (Johnson & Murphey): the
//! [`System`] trait that interpreted and generated systems share, its [`Terms`] and
//! [`ConstraintTerms`], the interpreted [`TreeSystem`], continuous [`dynamics`], the
//! integrators in [`integrate`], the recorded [`Trajectory`] and the errors ([`SimError`]).
//!
//! Beneath them, the kernel: SE(3) primitives (`se3`), the tree as the recursions walk it
//! (`plan`), the recursions over any scalar (`sweeps`, `elements`, run together by `kernel`,
//! their results named in `outputs`) — evaluated here with `f64`, compiled by `tree_model!`
//! with a tracing scalar. The kernel is public for the macro's generated code and hidden from
//! the documentation; it is not a stable interface.
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

// The kernel: the recursions, over any scalar (what `tree_model!` needs), hidden from the
// documented API. Bottom up: scalar, order, se3, plan, outputs, sweeps, elements, kernel.
#[doc(hidden)]
pub mod cpu;
#[doc(hidden)]
pub mod dual;
#[doc(hidden)]
pub mod elements;
#[doc(hidden)]
pub mod kernel;
pub mod lanes;
pub mod order;
#[doc(hidden)]
pub mod outputs;
#[doc(hidden)]
pub mod plan;
#[doc(hidden)]
pub mod scalar;
#[doc(hidden)]
pub mod se3;
#[doc(hidden)]
pub mod sweeps;
// Forward dynamics by the articulated-body algorithm, over any scalar (the interpreted
// system's in f64, unrolled by `tree_model!`).
#[doc(hidden)]
pub mod articulated;
// Inverse dynamics by recursive Newton–Euler, over any scalar (dual numbers for the
// continuous linearisation).
#[doc(hidden)]
pub mod newton_euler;

// Simulation (needs nalgebra).
#[cfg(feature = "simulate")]
pub mod batch;
#[cfg(feature = "simulate")]
pub mod context;
#[cfg(feature = "simulate")]
pub mod control;
#[cfg(feature = "simulate")]
pub mod dynamics;
#[cfg(feature = "simulate")]
pub mod error;
#[cfg(feature = "simulate")]
pub mod evaluation;
#[cfg(feature = "simulate")]
pub mod integrate;
#[cfg(feature = "simulate")]
pub mod interpreted;
#[cfg(feature = "simulate")]
pub mod kinematics;
#[cfg(feature = "simulate")]
#[doc(hidden)]
pub mod linalg;
#[cfg(feature = "simulate")]
pub mod linearize;
#[cfg(feature = "simulate")]
pub mod reference;
#[cfg(feature = "simulate")]
pub mod report;
#[cfg(feature = "simulate")]
pub mod system;
#[cfg(feature = "simulate")]
pub mod trajectory;

pub use order::Order;
pub use se3::{Pose, Twist};
pub use tree_model;

#[cfg(feature = "simulate")]
pub use {
    dynamics::{Baumgarte, Dynamics, GeneralizedForce, ModelMotions, NoForce, Prescription},
    error::{Seconds, SimError},
    interpreted::TreeSystem,
    reference::{PaperEvaluation, PaperSystem},
    system::{ConstraintTerms, Matrix, System, Terms, Vector},
    trajectory::{CsvStream, Sample, Trajectory},
};

/// Re-exported for generated code and users: the linear-algebra crate of every vector.
#[cfg(feature = "simulate")]
pub use nalgebra;
