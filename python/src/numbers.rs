//! Array arguments of numbers: numpy's conversion of anything array-like, with a wrong number
//! of dimensions refused in a sentence (numpy's own reads "dimensionality mismatch: from=3,
//! to=2"; pyo3 adds which argument it was).

use std::ops::Deref;

use numpy::ndarray::Dimension;
use numpy::{AllowTypeChange, PyArrayLike};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyString};

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
        refuse_what_is_not_numbers(&ob)?;
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

/// Text and bytes are not numbers, though numpy reads bytes as their codes (`b"ab"` as
/// [97, 98]); a masked array's masked entries have no value to use (numpy would use what
/// lies under the mask).
fn refuse_what_is_not_numbers(ob: &Borrowed<'_, '_, PyAny>) -> PyResult<()> {
    if ob.is_instance_of::<PyBytes>()
        || ob.is_instance_of::<PyByteArray>()
        || ob.is_instance_of::<PyString>()
    {
        let kind = ob.get_type().name()?;
        return Err(PyTypeError::new_err(format!(
            "expected an array of numbers, got {kind}"
        )));
    }
    // Only a masked array has a mask: the common arguments pay one attribute lookup.
    let masked = ob.hasattr("mask").unwrap_or(false)
        && ob
            .py()
            .import("numpy.ma")
            .and_then(|ma| ma.call_method1("is_masked", (&**ob,)))
            .and_then(|m| m.extract::<bool>())
            .unwrap_or(false);
    if masked {
        return Err(PyValueError::new_err(
            "the masked array has masked entries, which have no value: fill them first \
             (a.filled(x)) or pass a.data to use what lies under the mask",
        ));
    }
    Ok(())
}

/// A number per variable: an array in the model's order, or a dict by name (`{"theta":
/// 0.3}`, as task files allow) whose missing variables keep their default.
pub(crate) enum PerVariable<'py> {
    /// Every variable, in order.
    Array(Numbers<'py, numpy::Ix1>),
    /// Some variables by name.
    Named(Vec<(String, f64)>),
}

impl<'a, 'py> FromPyObject<'a, 'py> for PerVariable<'py> {
    type Error = PyErr;

    fn extract(ob: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let Ok(dict) = ob.cast::<pyo3::types::PyDict>() else {
            return ob
                .extract::<Numbers<'py, numpy::Ix1>>()
                .map(PerVariable::Array);
        };
        let mut named = Vec::with_capacity(dict.len());
        for (key, value) in dict.iter() {
            let name: String = key.extract().map_err(|_| {
                PyTypeError::new_err("a dict of values per variable is keyed by variable name")
            })?;
            let x: f64 = value.extract().map_err(|_| {
                PyTypeError::new_err(format!("the value of `{name}` must be a number"))
            })?;
            named.push((name, x));
        }
        Ok(PerVariable::Named(named))
    }
}
