//! The package's two exceptions and how the runtime's errors become them: a model's problem
//! as `ModelError` with its file and line, a run's as `SimulationError` with its step, a
//! caller's wrong argument as `ValueError`.

use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use tree_mech::model::ModelError as CoreModelError;
use tree_mech::SimError;

pyo3::create_exception!(
    _native,
    ModelError,
    PyValueError,
    "A model or task file is wrong: the message names the problem and its place; `file` and `line` say where (None when unknown)."
);
pyo3::create_exception!(
    _native,
    SimulationError,
    PyRuntimeError,
    "A simulation or solve failed: the message names the cause; `step` is the step it failed at (None when it names none)."
);

/// A `ModelError` exception with `file` and `line` set from the first problem.
pub(crate) fn model_error(py: Python<'_>, e: &CoreModelError) -> PyErr {
    let err = ModelError::new_err(e.to_string());
    let value = err.value(py);
    let line = e.problems.first().and_then(|p| p.line);
    let _ = value.setattr("file", e.source_name.clone());
    let _ = value.setattr("line", line);
    err
}

/// A run's error message with the command line's options named as this package's keyword
/// arguments (`lower --dt` reads `lower dt`).
pub(crate) fn in_python_terms(e: &SimError) -> String {
    in_python_words(&e.to_string())
}

/// A message with the command line's options named as keyword arguments.
pub(crate) fn in_python_words(message: &str) -> String {
    [
        ("--integrator vi", "integrator=\"vi\""),
        ("--max-steps", "max_steps"),
        ("--duration", "duration"),
        ("--dt", "dt"),
    ]
    .iter()
    .fold(message.to_string(), |m, (flag, argument)| {
        m.replace(flag, argument)
    })
}

/// A `SimulationError` with `step` set (a request too large for memory: Python's
/// `MemoryError`, checked before anything was taken).
pub(crate) fn sim_error(py: Python<'_>, e: &SimError) -> PyErr {
    // Terms written in Python that failed are the cause of what the runtime then refused.
    if let Some(failure) = crate::added::take_failure() {
        return failure;
    }
    if let SimError::OutOfMemory { .. } = e {
        return PyMemoryError::new_err(in_python_terms(e));
    }
    let err = SimulationError::new_err(in_python_terms(e));
    let _ = err.value(py).setattr("step", e.step());
    err
}

pub(crate) fn bad(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// A system that cannot be built for a model: `MemoryError` when it would not fit, else a
/// `ModelError`.
pub(crate) fn system_error(e: &SimError) -> PyErr {
    match e {
        SimError::OutOfMemory { .. } => PyMemoryError::new_err(e.to_string()),
        _ => ModelError::new_err(e.to_string()),
    }
}
