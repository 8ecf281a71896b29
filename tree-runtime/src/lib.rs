//! # tree-runtime
//!
//! Simulation of mechanical systems described as trees of frames (Johnson & Murphey): SE(3)
//! primitives ([`se3`]), the [`System`] trait that interpreted and generated systems share,
//! the interpreted [`TreeSystem`], continuous [`dynamics`], the integrators in
//! [`integrate`] and the recorded [`Trajectory`].
//!
//! ```
//! use tree_runtime::{integrate::{simulate, Method, SimOptions, ViSettings}, Evaluation, NoForce, System, TreeSystem};
//! let model = tree_model::n_link_pendulum(2);
//! let mut sys = TreeSystem::new(&model, Evaluation::Sweeps).unwrap();
//! let (q0, dq0) = sys.initial_state();
//! let options = SimOptions { method: Method::Vi(ViSettings::default()), dt: 0.01, duration: 1.0 };
//! let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
//! assert_eq!(traj.len(), 101);
//! assert!(traj.max_energy_error() < 1e-2);
//! ```

// Integrator steps take the system, the force, the step's labels and the state as separate
// arguments on purpose.
#![allow(clippy::too_many_arguments)]

pub mod dynamics;
pub mod error;
pub mod integrate;
pub mod interpreted;
pub mod linalg;
pub mod order;
pub mod plan;
pub mod scalar;
pub mod se3;
pub mod sweeps;
pub mod system;
pub mod trajectory;

pub use dynamics::{Dynamics, GeneralizedForce, NoForce};
pub use error::SimError;
pub use interpreted::{Evaluation, TreeSystem};
pub use se3::{Pose, Twist};
pub use system::{Matrix, Order, System, Terms, Vector};
pub use trajectory::Trajectory;
pub use tree_model;

/// Re-exported for generated code and users: the linear-algebra crate of every vector.
pub use nalgebra;
