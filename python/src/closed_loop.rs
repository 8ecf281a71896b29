//! `Model.stepper` and `Stepper`: a run one step at a time for closed-loop control — read the
//! state, compute the inputs, step — over the runtime's `integrate::Stepper` (the VI keeps its
//! discrete momentum between steps, so the run is the one `simulate` takes with those inputs).

use numpy::Ix1;
use pyo3::prelude::*;
use tree_mech::integrate::{Method, Stepper as CoreStepper};
use tree_mech::{SimError, TreeSystem};

use crate::arrays::vector;
use crate::errors::{bad, in_python_words, sim_error, SimulationError};
use crate::model::Model;
use crate::numbers::{Numbers, PerVariable};
use crate::simulate::method;

/// A model stepped by fixed steps of `dt` under inputs given a step at a time, from
/// `Model.stepper`. After a failed step it refuses to go on until `reset`.
#[pyclass(module = "tree_mech")]
pub(crate) struct Stepper {
    stepper: CoreStepper<TreeSystem>,
    model: Py<Model>,
    /// The inputs of the next step (reused: a step allocates nothing in Rust).
    u: Vec<f64>,
}

#[pymethods]
impl Model {
    /// A stepper at `(q0, dq0)` (default the model's start) and `t = 0`, stepping by `dt` with
    /// `integrator` "vi" or "rk4" (rk45 chooses its own steps) and the options of `simulate`.
    #[pyo3(signature = (dt, integrator="vi", q0=None, dq0=None, alpha=0.5, forcing="split", newton_tol=None))]
    #[allow(clippy::too_many_arguments)]
    fn stepper(
        slf: Bound<'_, Self>,
        dt: f64,
        integrator: &str,
        q0: Option<PerVariable<'_>>,
        dq0: Option<PerVariable<'_>>,
        alpha: f64,
        forcing: &str,
        newton_tol: Option<f64>,
    ) -> PyResult<Stepper> {
        let py = slf.py();
        let this = slf.borrow();
        let method: Method = method(integrator, alpha, forcing, newton_tol, 1e-8, 1e-10, 0.0)?;
        let (q0, dq0) = this.start(q0, dq0)?;
        let stepper =
            CoreStepper::new(this.system(), method, dt, &q0, &dq0).map_err(|e| refused(py, &e))?;
        Ok(Stepper {
            stepper,
            u: vec![0.0; this.model.inputs.len()],
            model: slf.clone().unbind(),
        })
    }
}

/// A caller's bad option is a `ValueError`; the runtime refusing a start a `SimulationError`.
fn refused(py: Python<'_>, e: &SimError) -> PyErr {
    match e {
        SimError::InvalidInput(m) => bad(m.clone()),
        _ => sim_error(py, e),
    }
}

#[pymethods]
impl Stepper {
    /// One step of `dt` with the inputs `u` (one a model input; None: zero) held over it. The
    /// GIL is released while it runs.
    #[pyo3(signature = (u=None))]
    fn step(&mut self, py: Python<'_>, u: Option<Numbers<'_, Ix1>>) -> PyResult<()> {
        if let Some(why) = self.stepper.stopped() {
            return Err(SimulationError::new_err(format!(
                "the stepper stopped ({}); start it again with reset",
                in_python_words(why)
            )));
        }
        match u {
            None => self.u.fill(0.0),
            Some(u) => {
                let u = u.as_array();
                if u.len() != self.u.len() {
                    let model = self.model.borrow(py);
                    return Err(bad(format!(
                        "u has {}; the model has {}",
                        tree_mech::model::Counted(u.len(), "entry"),
                        model.inputs_phrase()
                    )));
                }
                self.u.iter_mut().zip(u.iter()).for_each(|(a, &b)| *a = b);
            }
        }
        let (stepper, u) = (&mut self.stepper, &self.u);
        py.detach(|| stepper.step(u)).map_err(|e| refused(py, &e))
    }

    /// Starts again from `(q0, dq0)` (default the model's start) at `t = 0`.
    #[pyo3(signature = (q0=None, dq0=None))]
    fn reset(
        &mut self,
        py: Python<'_>,
        q0: Option<PerVariable<'_>>,
        dq0: Option<PerVariable<'_>>,
    ) -> PyResult<()> {
        let (q0, dq0) = self.model.borrow(py).start(q0, dq0)?;
        self.stepper.reset(&q0, &dq0).map_err(|e| refused(py, &e))
    }

    /// The time reached, s (steps × dt).
    #[getter]
    fn t(&self) -> f64 {
        self.stepper.t()
    }

    /// The configuration reached, one entry a variable.
    #[getter]
    fn q(&self, py: Python<'_>) -> Py<PyAny> {
        vector(py, self.stepper.q().as_slice())
    }

    /// The velocity reached (the VI's: the continuous velocity its momentum stands for).
    #[getter]
    fn dq(&self, py: Python<'_>) -> Py<PyAny> {
        vector(py, self.stepper.dq().as_slice())
    }

    /// The VI's discrete momentum reached, one entry a variable (None for rk4).
    #[getter]
    fn p(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.stepper.p().map(|p| vector(py, p.as_slice()))
    }

    /// The energy T + V at the state reached, J.
    #[getter]
    fn energy(&mut self) -> f64 {
        self.stepper.energy()
    }

    /// The step, s.
    #[getter]
    fn dt(&self) -> f64 {
        self.stepper.dt()
    }

    /// Steps taken since the start.
    #[getter]
    fn steps(&self) -> usize {
        self.stepper.steps()
    }

    fn __repr__(&self) -> String {
        format!(
            "Stepper(t={}, steps={}, dt={})",
            self.stepper.t(),
            self.stepper.steps(),
            self.stepper.dt()
        )
    }
}
