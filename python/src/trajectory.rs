//! `Trajectory`: a run's samples as numpy arrays.

use pyo3::prelude::*;
use tree_mech::Trajectory as CoreTrajectory;

use crate::arrays::{rows, vector};

/// A run's samples as arrays.
#[pyclass(module = "tree_mech", frozen, get_all)]
pub(crate) struct Trajectory {
    /// Sample times (samples,).
    pub(crate) t: Py<PyAny>,
    /// Configurations (samples, n).
    pub(crate) q: Py<PyAny>,
    /// Velocities (samples, n).
    pub(crate) dq: Py<PyAny>,
    /// The VI's discrete momenta (samples, n); None for another integrator.
    pub(crate) p: Py<PyAny>,
    /// Total energy (samples,).
    pub(crate) energy: Py<PyAny>,
    /// Constraint forces (samples, constraint rows).
    pub(crate) lam: Py<PyAny>,
    /// max |h| (samples,).
    pub(crate) violation: Py<PyAny>,
    /// Inputs in force (samples, inputs).
    pub(crate) u: Py<PyAny>,
    /// Each unilateral row's impulse over the step ending at each sample (samples, rows).
    pub(crate) impulse: Py<PyAny>,
    /// Each unilateral row's gap at each sample (samples, rows).
    pub(crate) gap: Py<PyAny>,
    /// The unilateral rows' names (limits, contacts with `.t1`/`.t2` tangent rows, strings).
    pub(crate) unilateral: Vec<String>,
    /// Variable names.
    pub(crate) variables: Vec<String>,
    /// Newton iterations over the run (VI).
    pub(crate) newton_iterations: usize,
    /// Energy taken out by damping.
    pub(crate) dissipated: f64,
}

impl Trajectory {
    pub(crate) fn of(py: Python<'_>, t: &CoreTrajectory, inputs: usize) -> Self {
        let (len, n, m) = (t.len(), t.dof(), t.constraints.len());
        Trajectory {
            t: vector(py, &t.t),
            q: rows(py, len, n, |k| t.q(k).to_vec()),
            dq: rows(py, len, n, |k| t.dq(k).to_vec()),
            p: match t.p(len.saturating_sub(1)) {
                Some(_) => rows(py, len, n, |k| {
                    t.p(k).map_or(vec![f64::NAN; n], <[f64]>::to_vec)
                }),
                None => py.None(),
            },
            energy: vector(py, &t.energy),
            lam: rows(py, len, m, |k| t.lambda(k).to_vec()),
            violation: vector(py, &t.violation),
            u: rows(py, len, inputs, |k| {
                let u = t.u(k);
                if u.is_empty() {
                    vec![0.0; inputs]
                } else {
                    u.to_vec()
                }
            }),
            impulse: rows(py, len, t.unilateral.len(), |k| t.impulse(k).to_vec()),
            gap: rows(py, len, t.unilateral.len(), |k| t.gap(k).to_vec()),
            unilateral: t.unilateral.clone(),
            variables: t.variables.clone(),
            newton_iterations: t.newton_iterations,
            dissipated: t.dissipated,
        }
    }
}

#[pymethods]
impl Trajectory {
    fn __len__(&self, py: Python<'_>) -> PyResult<usize> {
        self.t.bind(py).len()
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Trajectory({} samples of {} variables)",
            self.__len__(py)?,
            self.variables.len()
        ))
    }
}
