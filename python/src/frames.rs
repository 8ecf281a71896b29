//! A model's frames: poses, Jacobians, twists and accelerations in a named reference, and the
//! centre of mass (Pinocchio's names where it has them).

use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::nalgebra::DMatrix;
use tree_mech::runtime::kinematics::Reference;

use crate::arrays::{matrix, vector};
use crate::errors::bad;
use crate::model::Model;
use crate::numbers::PerVariable;

/// A frame reference by its name, or a `ValueError` naming the three.
pub(crate) fn parse_reference(name: &str) -> PyResult<Reference> {
    Reference::parse(name).ok_or_else(|| {
        bad(format!(
            "reference `{name}` is not one of \"local\", \"local_world_aligned\", \"world\""
        ))
    })
}

#[pymethods]
impl Model {
    /// Frame `frame`'s pose in the world at `q` (default the model's q0): 4 × 4, homogeneous
    /// (as `evaluate()["poses"][frame]`, alone).
    #[pyo3(signature = (frame, q=None))]
    fn frame_pose(
        &self,
        py: Python<'_>,
        frame: &str,
        q: Option<PerVariable<'_>>,
    ) -> PyResult<Py<PyAny>> {
        let (k, f) = self.frame_at(frame, q, None, None)?;
        let m = k.pose(f).matrix();
        Ok(matrix(py, &DMatrix::from_fn(4, 4, |i, j| m[i][j])))
    }

    /// Frame `frame`'s Jacobian at `q`: 6 × (variables), linear rows first, in `reference`
    /// — "local" (the frame's axes), "local_world_aligned" (world axes at the frame's
    /// origin: the origin's velocity and the angular velocity) or "world" (the spatial
    /// twist) — so that `frame_velocity` is `J @ dq` (Pinocchio's `getFrameJacobian`).
    #[pyo3(signature = (frame, q=None, reference="local_world_aligned"))]
    fn frame_jacobian(
        &self,
        py: Python<'_>,
        frame: &str,
        q: Option<PerVariable<'_>>,
        reference: &str,
    ) -> PyResult<Py<PyAny>> {
        let reference = parse_reference(reference)?;
        let (k, f) = self.frame_at(frame, q, None, None)?;
        Ok(matrix(py, &k.jacobian(f, reference)))
    }

    /// Frame `frame`'s twist (v, ω) at `(q, dq)` in `reference` (see `frame_jacobian`;
    /// Pinocchio's `getFrameVelocity`).
    #[pyo3(signature = (frame, q=None, dq=None, reference="local_world_aligned"))]
    fn frame_velocity(
        &self,
        py: Python<'_>,
        frame: &str,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        reference: &str,
    ) -> PyResult<Py<PyAny>> {
        let reference = parse_reference(reference)?;
        let (k, f) = self.frame_at(frame, q, dq, None)?;
        Ok(vector(py, &k.velocity(f, reference)))
    }

    /// Frame `frame`'s acceleration at `(q, dq, ddq)` (`ddq` default zero; every variable,
    /// kinematic ones included): with `classical=False` the spatial acceleration — the
    /// rate of its twist — in `reference` (Pinocchio's `getFrameAcceleration`); with
    /// `classical=True` the acceleration of its origin in world axes, 3 entries (whatever
    /// `reference` says).
    #[pyo3(signature = (frame, q=None, dq=None, ddq=None, reference="local_world_aligned", classical=false))]
    #[allow(clippy::too_many_arguments)]
    fn frame_acceleration(
        &self,
        py: Python<'_>,
        frame: &str,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        ddq: Option<PerVariable<'_>>,
        reference: &str,
        classical: bool,
    ) -> PyResult<Py<PyAny>> {
        let reference = parse_reference(reference)?;
        let (k, f) = self.frame_at(frame, q, dq, ddq)?;
        Ok(if classical {
            vector(py, &k.classical_acceleration(f))
        } else {
            vector(py, &k.acceleration(f, reference))
        })
    }

    /// The centre of mass of every body (those welded to the world too, which Pinocchio
    /// leaves out) at `(q, dq, ddq)`: a dict with `mass`, `com`, `vcom`, `acom` (world).
    #[pyo3(signature = (q=None, dq=None, ddq=None))]
    fn center_of_mass<'py>(
        &self,
        py: Python<'py>,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let k = self.frames_at(q, dq, ddq)?;
        let c = k.center_of_mass();
        let out = PyDict::new(py);
        out.set_item("mass", c.mass)?;
        out.set_item("com", vector(py, &c.position))?;
        out.set_item("vcom", vector(py, &c.velocity))?;
        out.set_item("acom", vector(py, &c.acceleration))?;
        Ok(out)
    }

    /// The centre of mass's Jacobian at `q`: 3 × (variables), `vcom = J @ dq` (Pinocchio's
    /// `jacobianCenterOfMass`, every body counted).
    #[pyo3(signature = (q=None))]
    fn com_jacobian(&self, py: Python<'_>, q: Option<PerVariable<'_>>) -> PyResult<Py<PyAny>> {
        let k = self.frames_at(q, None, None)?;
        Ok(matrix(py, &k.com_jacobian()))
    }
}
