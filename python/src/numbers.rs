//! Array arguments of numbers: numpy's conversion of anything array-like, with a wrong number
//! of dimensions refused in a sentence (numpy's own reads "dimensionality mismatch: from=3,
//! to=2"; pyo3 adds which argument it was).

use std::ops::Deref;

use numpy::ndarray::Dimension;
use numpy::{AllowTypeChange, PyArrayLike};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

/// A `D`-dimensional array argument of numbers (a list, a nested list or any numpy array,
/// converted to `float64`).
pub(crate) struct Numbers<'py, D: Dimension>(PyArrayLike<'py, f64, D, AllowTypeChange>);

impl<'py, D: Dimension> Deref for Numbers<'py, D> {
    type Target = PyArrayLike<'py, f64, D, AllowTypeChange>;

    fn deref(&self) -> &Self::Target {
        &self.0
    }
}

impl<'a, 'py, D: Dimension + 'py> FromPyObject<'a, 'py> for Numbers<'py, D> {
    type Error = PyErr;

    fn extract(ob: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let error = match ob.extract::<PyArrayLike<'py, f64, D, AllowTypeChange>>() {
            Ok(array) => return Ok(Numbers(array)),
            Err(e) => e,
        };
        let want = D::NDIM.unwrap_or(0);
        let got = ob
            .py()
            .import("numpy")
            .and_then(|np| np.call_method1("ndim", (&*ob,)))
            .and_then(|n| n.extract::<usize>());
        match got {
            Ok(got) if got != want => Err(PyTypeError::new_err(format!(
                "expected a {want}-D array of numbers, got a {got}-D one"
            ))),
            _ => Err(error),
        }
    }
}
