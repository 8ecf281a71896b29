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
/// Optimal control: costs, LQR, iLQR/DDP with box limits, task files (`tree-control`).
pub use tree_control as control;
/// The recursions over any scalar that both the interpreted and the compiled systems run
/// (`tree-kernel`): poses, twists, the tree's plan, dual numbers and SIMD lanes.
pub use tree_kernel as kernel;
/// Compiles a model into a type implementing [`System`]: the whole syntax is on the macro.
pub use tree_macros::tree_model;
/// The runtime (`tree-runtime`): the [`System`] trait, the interpreted system, dynamics,
/// integrators and their derivatives, batches.
pub use tree_runtime as runtime;
pub use tree_runtime::nalgebra;
pub use tree_runtime::{
    integrate, ConstraintTerms, GeneralizedForce, NoForce, Order, PaperEvaluation, PaperSystem,
    SimError, System, Terms, Trajectory, TreeSystem,
};

/// README.md's Rust examples, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeExamples;

/// docs/model-format.md's Rust examples, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/model-format.md")]
struct ModelFormatExamples;

/// docs/library.md's Rust examples, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/library.md")]
struct LibraryExamples;

/// What the code `tree_model!` generates names, and nothing else: its one door into the
/// crates beneath (as thiserror's `__private`). Not a public interface; it changes with the
/// macro.
#[doc(hidden)]
pub mod __private {
    pub use tree_kernel::articulated::{pivots_hold, ArticulatedIo};
    pub use tree_kernel::cpu::{fused, Fused, MulAdd, Plain};
    pub use tree_kernel::Scalar;
    pub use tree_kernel::{__unless_fused_only, Order, Pose};
    pub use tree_kernel::{Dual, DualOutputs, Jet, JetOutputs, LANES};
    pub use tree_kernel::{Output, Sink};
    pub use tree_model as model;
    pub use tree_runtime::nalgebra::Const;
    pub use tree_runtime::Sparsity;
    pub use tree_runtime::{ConstraintTerms, System, Terms, TreeSystem, Vector};
}

/// Runs a program's `main` the way a command-line tool should end: an error is printed to
/// stderr as its sentence (`error: …`, not its `Debug` form) with a failing exit code, and a
/// closed standard output (`… | head`) ends the process quietly instead of panicking in
/// `println!` (Rust ignores `SIGPIPE`; this restores its default disposition, on Unix). The
/// examples' `main`, before any thread starts:
///
/// ```no_run
/// fn main() -> std::process::ExitCode {
///     tree_mech::run_main(example)
/// }
///
/// fn example() -> Result<(), Box<dyn std::error::Error>> {
///     let model = tree_mech::model::from_toml_file("models/pendulum.toml")?;
///     println!("{} variables", model.variables.len());
///     Ok(())
/// }
/// ```
pub fn run_main(
    main: impl FnOnce() -> Result<(), Box<dyn std::error::Error>>,
) -> std::process::ExitCode {
    quiet_on_closed_stdout();
    match main() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Restores `SIGPIPE`'s default disposition (on Unix; elsewhere nothing): a write to a closed
/// standard output then ends the process quietly, as for other command-line tools, instead
/// of a panic in `println!`. [`run_main`] calls it; call it first in a `main` of your own.
#[cfg(unix)]
pub fn quiet_on_closed_stdout() {
    extern "C" {
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const SIGPIPE: i32 = 13;
    const SIG_DFL: usize = 0;
    // SAFETY: restoring the default disposition of one signal, before any thread starts.
    unsafe {
        signal(SIGPIPE, SIG_DFL);
    }
}

/// Restores `SIGPIPE`'s default disposition (on Unix; elsewhere nothing).
#[cfg(not(unix))]
pub fn quiet_on_closed_stdout() {}
