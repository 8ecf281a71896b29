//! `tree_mech._native`: the Python package's compiled core over the interpreted runtime —
//! models read at run time, numpy arrays in and out, long calls without the GIL. The
//! package's `tree_mech/__init__.py` re-exports it with docs and type stubs.
//!
//! One module a topic: `errors` (the two exceptions), `numbers` and `arrays` (arguments in,
//! arrays out), `progress` (Ctrl-C and progress while the GIL is released), `model` (a model
//! and what it is made of), then what a model computes — `evaluation`, `frames`, `simulate`
//! with `trajectory`, `linearize`, `rollouts`, `closed_loop` (a model stepped under inputs
//! given a step at a time) — and `stepper` (trep's VI a step at a time), `optimize` (a
//! task file solved) and `added` (terms written in Python, for the trep layer's elements). `Model`'s Python methods sit in the topic's module, each
//! a `#[pymethods]` block of its own.

mod added;
mod arrays;
mod closed_loop;
mod errors;
mod evaluation;
mod frames;
mod linearize;
mod model;
mod numbers;
mod optimize;
mod progress;
mod rollouts;
mod simulate;
mod stepper;
mod trajectory;

use pyo3::prelude::*;

use errors::{ModelError, SimulationError};
use model::Model;
use rollouts::Rollouts;
use stepper::VariationalStepper;
use trajectory::Trajectory;

/// The compiled core of the `tree_mech` package.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Trajectory>()?;
    m.add_class::<Rollouts>()?;
    m.add_class::<VariationalStepper>()?;
    m.add_class::<closed_loop::Stepper>()?;
    m.add_function(wrap_pyfunction!(model::load, m)?)?;
    m.add_function(wrap_pyfunction!(model::loads, m)?)?;
    m.add_function(wrap_pyfunction!(optimize::optimize_text, m)?)?;
    m.add("ModelError", m.py().get_type::<ModelError>())?;
    m.add("SimulationError", m.py().get_type::<SimulationError>())?;
    Ok(())
}
