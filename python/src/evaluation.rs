//! A model at one state: everything `tree-mech eval` reports, and the pieces alone — forward
//! and inverse dynamics, the constraints, the mass matrix.

use numpy::ndarray::{Array3, Ix1};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::nalgebra::{DMatrix, Dyn};
use tree_mech::runtime::dynamics::inverse_dynamics;
use tree_mech::runtime::evaluation::{continuous_dynamics, evaluate_state_with};
use tree_mech::runtime::Vector;
use tree_mech::{ConstraintTerms, Order, System, Terms};

use crate::arrays::{matrix, vector};
use crate::errors::{bad, sim_error};
use crate::model::Model;
use crate::numbers::{Numbers, PerVariable};

#[pymethods]
impl Model {
    /// Everything at one state (the keys of `tree-mech eval`): L, energy, dL_dq, dL_ddq, M,
    /// d2L_ddqdq, d2L_dqdq, qdd (dynamic variables), lambda, h, dh_dq, poses (frame → 4×4).
    #[pyo3(signature = (q=None, dq=None, t=0.0, u=None, ddq=None))]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        t: f64,
        u: Option<Numbers<'_, Ix1>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let u = self.input_vector(u)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut motion = self.kinematics(&sys, &q, &dq, ddq)?;
        let e = evaluate_state_with(&mut *sys, t, &q, &dq, &u, &mut motion)
            .map_err(|e| sim_error(py, &e))?;
        let out = PyDict::new(py);
        let square = |m: &tree_mech::runtime::Matrix<Dyn>| {
            DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
        };
        out.set_item("variables", self.names())?;
        out.set_item("q", vector(py, q.as_slice()))?;
        out.set_item("dq", vector(py, dq.as_slice()))?;
        out.set_item("L", e.terms.l)?;
        out.set_item("energy", e.energy)?;
        out.set_item("dL_dq", vector(py, e.terms.dl_dq.as_slice()))?;
        out.set_item("dL_ddq", vector(py, e.terms.dl_ddq.as_slice()))?;
        out.set_item("M", matrix(py, &square(&e.terms.mass)))?;
        out.set_item("d2L_ddqdq", matrix(py, &square(&e.terms.d2l_ddq_dq)))?;
        out.set_item("d2L_dqdq", matrix(py, &square(&e.terms.d2l_dq_dq)))?;
        let dynamic = self.model.dynamic();
        out.set_item(
            "qdd",
            vector(py, &dynamic.iter().map(|&i| e.qdd[i]).collect::<Vec<_>>()),
        )?;
        out.set_item("lambda", vector(py, e.lambda.as_slice()))?;
        out.set_item("h", vector(py, e.constraints.h.as_slice()))?;
        out.set_item("dh_dq", matrix(py, &e.constraints.dh))?;
        let poses = PyDict::new(py);
        for (f, p) in self.model.frames.iter().zip(&e.poses) {
            let m = p.matrix();
            poses.set_item(&f.name, matrix(py, &DMatrix::from_fn(4, 4, |i, j| m[i][j])))?;
        }
        out.set_item("poses", poses)?;
        let velocities = PyDict::new(py);
        for (f, v) in self.model.frames.iter().zip(&sys.body_velocities(&q, &dq)) {
            velocities.set_item(&f.name, vector(py, v))?;
        }
        out.set_item("body_velocities", velocities)?;
        Ok(out)
    }

    /// q̈ of the dynamic variables at one state — `evaluate()["qdd"]` alone (Pinocchio's
    /// `aba`): by the articulated-body algorithm where the model has no constraints, without
    /// the rest of an evaluation, for a loop that needs only the dynamics. `ddq` gives the
    /// kinematic variables' accelerations (default: their prescription's).
    #[pyo3(signature = (q=None, dq=None, t=0.0, u=None, ddq=None))]
    fn forward_dynamics(
        &self,
        py: Python<'_>,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        t: f64,
        u: Option<Numbers<'_, Ix1>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<Py<PyAny>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let u = self.input_vector(u)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut motion = self.kinematics(&sys, &q, &dq, ddq)?;
        let (qdd, _) = continuous_dynamics(&mut *sys, t, &q, &dq, &u, &mut motion)
            .map_err(|e| sim_error(py, &e))?;
        let dynamic = self.model.dynamic();
        Ok(vector(
            py,
            &dynamic.iter().map(|&i| qdd[i]).collect::<Vec<_>>(),
        ))
    }

    /// Inverse dynamics (Pinocchio's `rnea`): the generalized force on every variable that
    /// gives it the acceleration `ddq` at `(q, dq)` (default: the model's q0, dq0 and zero),
    /// `M ddq + (∂²L/∂q̇∂q) dq − ∂L/∂q − F` with the model's damping and dampers in `F` and
    /// constraint forces left out. With `dq = ddq = 0`, gravity compensation (and the
    /// springs' hold).
    #[pyo3(signature = (q=None, dq=None, ddq=None))]
    fn inverse_dynamics(
        &self,
        py: Python<'_>,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<Py<PyAny>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let ddq = self.vector("ddq", ddq, |_| 0.0)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut terms = Terms::zeros(Dyn(self.n()));
        let mut tau = Vector::<Dyn>::zeros(self.n());
        inverse_dynamics(&mut *sys, &q, &dq, &ddq, &mut terms, &mut tau)
            .map_err(|e| sim_error(py, &e))?;
        Ok(vector(py, tau.as_slice()))
    }

    /// The constraints alone at `q` (default the model's q0): a dict with `h` (one entry per
    /// constraint equation), `dh_dq` (equations × variables), as `evaluate()` has them, and
    /// with `second` (the default) `d2h_dqdq` (equations × variables × variables), without
    /// the dynamics (so also where those have no solution). `second=False` evaluates no
    /// second derivatives (a constraint written in Python is not asked for them).
    #[pyo3(signature = (q=None, second=true))]
    fn constraints_at<'py>(
        &self,
        py: Python<'py>,
        q: Option<PerVariable<'_>>,
        second: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut c = ConstraintTerms::zeros(sys.constraint_count(), self.n());
        let order = if second { Order::Full } else { Order::First };
        sys.constraints(&q, &Vector::<Dyn>::zeros(self.n()), order, &mut c);
        let curvature = c.d2h.iter().flat_map(|m| m.iter()).filter(|_| second);
        if c.h
            .iter()
            .chain(c.dh.iter())
            .chain(curvature)
            .any(|x| !x.is_finite())
        {
            return Err(bad(
                "at this q, the constraints are not finite (they overflowed a floating-point number)",
            ));
        }
        let out = PyDict::new(py);
        out.set_item("h", vector(py, c.h.as_slice()))?;
        out.set_item("dh_dq", matrix(py, &c.dh))?;
        if second {
            let n = self.n();
            let d2h = Array3::from_shape_fn((c.d2h.len(), n, n), |(r, i, j)| c.d2h[r][(i, j)]);
            out.set_item("d2h_dqdq", d2h.into_pyarray(py))?;
        }
        Ok(out)
    }

    /// The mass matrix M(q), every variable (`evaluate()["M"]` alone; Pinocchio's `crba`).
    #[pyo3(signature = (q=None))]
    fn mass_matrix(&self, py: Python<'_>, q: Option<PerVariable<'_>>) -> PyResult<Py<PyAny>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut terms = Terms::zeros(Dyn(self.n()));
        sys.mass_matrix(&q, &mut terms);
        if terms.mass.iter().any(|x| !x.is_finite()) {
            return Err(bad(
                "at this q, M is not finite (it overflowed a floating-point number)",
            ));
        }
        Ok(matrix(
            py,
            &DMatrix::from_fn(self.n(), self.n(), |i, j| terms.mass[(i, j)]),
        ))
    }
}
