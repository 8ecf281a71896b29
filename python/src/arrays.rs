//! Arrays in and out: counts and finite numbers checked with the argument named, rows, vectors
//! and matrices as numpy arrays, a report's entries as Python values.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use tree_mech::nalgebra::DMatrix;
use tree_mech::runtime::report::Entry;

use crate::errors::bad;

/// An array's shape as Python writes it: `(3, 1)`, `(4,)`.
pub(crate) fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => {
            let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
            format!("({})", parts.join(", "))
        }
    }
}

/// A count the caller gives (`every`, `max_steps`, `threads`) as a `usize`, or a `ValueError`
/// naming it — for the whole call, not an error per rollout, and not Python's
/// `OverflowError` for a negative one.
pub(crate) fn count(what: &str, x: i64, least: usize) -> PyResult<usize> {
    match usize::try_from(x) {
        Ok(k) if k >= least => Ok(k),
        _ => Err(bad(format!("{what} must be at least {least}, got {x}"))),
    }
}

/// A `ValueError` naming the first entry of `values` that is not finite (`names[i]` says
/// whose it is): states and inputs are numbers, and a NaN would otherwise surface later as a
/// misleading failure of the dynamics.
pub(crate) fn check_finite(what: &str, values: &[f64], names: &[String]) -> PyResult<()> {
    match values.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(i) => Err(bad(format!(
            "{what}[{i}] (`{}`) is {}: every entry must be a finite number",
            names.get(i).map_or("?", |n| n.as_str()),
            values[i]
        ))),
    }
}

/// The number of steps of a run of `duration` at `dt` (as the integrators count them), which a
/// per-step input array must match row for row.
pub(crate) fn steps_of(duration: f64, dt: f64) -> Option<usize> {
    let steps = (duration / dt).round();
    (1.0..=1e9).contains(&steps).then_some(steps as usize)
}

/// Per-step inputs have one row a step: a different count (a mixed-up `dt`, a schedule for
/// another horizon) is a `ValueError`, not inputs silently cut short or held.
pub(crate) fn check_rows(rows: usize, duration: f64, dt: f64) -> PyResult<()> {
    match steps_of(duration, dt) {
        Some(steps) if steps != rows => Err(bad(format!(
            "u has {rows} rows of inputs, one a step; the run has {steps} steps (duration / dt)"
        ))),
        _ => Ok(()),
    }
}

pub(crate) fn rows(
    py: Python<'_>,
    len: usize,
    width: usize,
    row: impl Fn(usize) -> Vec<f64>,
) -> Py<PyAny> {
    let mut data = Vec::with_capacity(len * width);
    for k in 0..len {
        data.extend(row(k));
    }
    Array2::from_shape_vec((len, width), data)
        .expect("rows of one width")
        .into_pyarray(py)
        .into_any()
        .unbind()
}

pub(crate) fn vector(py: Python<'_>, v: &[f64]) -> Py<PyAny> {
    Array1::from(v.to_vec())
        .into_pyarray(py)
        .into_any()
        .unbind()
}

pub(crate) fn matrix(py: Python<'_>, m: &DMatrix<f64>) -> Py<PyAny> {
    let (r, c) = m.shape();
    Array2::from_shape_fn((r, c), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
        .unbind()
}

/// A report entry as a Python value: a float or a numpy array.
pub(crate) fn entry(py: Python<'_>, e: &Entry) -> Py<PyAny> {
    match e {
        Entry::Scalar(x) => x.into_pyobject(py).expect("a float").into_any().unbind(),
        Entry::Vector(v) => vector(py, v),
        Entry::Matrix(m) => matrix(py, m),
        Entry::Stack(rows) => {
            let (r, c) = rows.first().map_or((0, 0), |m| m.shape());
            Array3::from_shape_fn((rows.len(), r, c), |(k, i, j)| rows[k][(i, j)])
                .into_pyarray(py)
                .into_any()
                .unbind()
        }
    }
}
