//! # tree-mech
//!
//! Simulators for mechanical systems described as trees of frames (Johnson & Murphey, *Discrete and
//! Continuous Mechanics for Tree Representations of Mechanical Systems*, ICRA 2008).
//! This facade re-exports the model crate and the runtime; depend on `tree-mech` alone.
//!
//! ```
//! use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
//! use tree_mech::{model, NoForce, System, TreeSystem};
//!
//! // Compiled: the model unrolled into straight-line Rust for this one tree.
//! tree_mech::tree_model! {
//!     struct Pendulum;
//!     frame pivot = rx(theta) { frame bob = tz(-1.0) { mass = 1.0; } }
//!     variable theta { q0 = 0.5; }
//! }
//! // Interpreted: the same model read at run time.
//! let mut interpreted = TreeSystem::new(&Pendulum::model())?;
//! let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 1.0);
//! let (q0, dq0) = Pendulum.initial_state();
//! let a = simulate(&mut Pendulum, &q0, &dq0, &options, &mut NoForce, &mut |_| {})?;
//! let (q0, dq0) = interpreted.initial_state();
//! let b = simulate(&mut interpreted, &q0, &dq0, &options, &mut NoForce, &mut |_| {})?;
//! assert!((a.last_q()[0] - b.last_q()[0]).abs() < 1e-12);
//! assert!(a.max_energy_error() < 1e-3);
//! # let _ = model::n_link_pendulum(2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

// The expansion of `tree_model!` names `::tree_mech`; this lets it work inside this crate too.
extern crate self as tree_mech;

/// The model crate: model types, the TOML and URDF readers, the builder, validation.
/// (`::tree_model`: the crate alone, not also the macro of the same name.)
pub use ::tree_model as model;
/// Compiles a model into a type implementing [`System`]: the whole syntax is on the macro.
pub use tree_macros::tree_model;
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    control, integrate, ConstraintTerms, GeneralizedForce, NoForce, Order, PaperEvaluation,
    PaperSystem, SimError, System, Terms, Trajectory, TreeSystem,
};
