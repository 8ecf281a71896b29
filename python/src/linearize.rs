//! Linearisations: the exact one at a state (`tree-mech linearize`'s keys) and the VI's step
//! derivatives along a recorded run (trep's `linearize_trajectory`).

use std::borrow::Cow;

use numpy::ndarray::{Array3, ArrayView2, Axis, Ix1};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::integrate::{Method, StepInput, StepOutput};
use tree_mech::runtime::batch::{StepLinearizer, Watch};
use tree_mech::runtime::report::{self, Explicit, Request as ReportRequest};
use tree_mech::runtime::Sample;
use tree_mech::{Trajectory as CoreTrajectory, TreeSystem};

use crate::arrays::{count, entry};
use crate::errors::{bad, sim_error};
use crate::model::Model;
use crate::numbers::{Numbers, PerVariable};
use crate::progress::watched;
use crate::simulate::method;
use crate::trajectory::Trajectory;

impl Model {
    /// The run `trajectory` holds, back as the runtime's (what `linearize_trajectory` reads:
    /// times, q, q̇, the VI's momenta, λ and the inputs of every sample).
    pub(crate) fn core_trajectory(
        &self,
        py: Python<'_>,
        trajectory: &Trajectory,
    ) -> PyResult<CoreTrajectory> {
        let table = |what: &str, a: &Py<PyAny>| -> PyResult<PyReadonlyArray2<'_, f64>> {
            a.bind(py).extract().map_err(|_| {
                bad(format!(
                    "the trajectory's `{what}` is not a 2-D array of floats"
                ))
            })
        };
        if trajectory.p.is_none(py) {
            return Err(bad(
                "the trajectory has no momenta: linearise a run of simulate(..., integrator=\"vi\")",
            ));
        }
        let t: PyReadonlyArray1<'_, f64> = trajectory.t.bind(py).extract()?;
        let t = t.as_array();
        let (q, dq, p) = (
            table("q", &trajectory.q)?,
            table("dq", &trajectory.dq)?,
            table("p", &trajectory.p)?,
        );
        let (lam, u) = (table("lam", &trajectory.lam)?, table("u", &trajectory.u)?);
        let (q, dq, p, lam, u) = (
            q.as_array(),
            dq.as_array(),
            p.as_array(),
            lam.as_array(),
            u.as_array(),
        );
        let (samples, n) = (t.len(), self.n());
        let fits = |a: &ArrayView2<'_, f64>, width: usize| a.dim() == (samples, width);
        let m = self.model.constraint_row_names().len();
        let inputs = self.model.inputs.len();
        if !(fits(&q, n) && fits(&dq, n) && fits(&p, n) && fits(&lam, m) && fits(&u, inputs)) {
            return Err(bad(format!(
                "the trajectory's arrays do not fit this model: q, dq and p must be \
                 ({samples}, {n}), lam ({samples}, {m}) and u ({samples}, {inputs})"
            )));
        }
        let mut run = CoreTrajectory::new(
            trajectory.variables.clone(),
            self.model.constraint_row_names(),
            samples,
        );
        // Each row read where it lies (the package's arrays are contiguous) and copied once,
        // into the run.
        fn row<'a>(a: &ArrayView2<'a, f64>, k: usize) -> Cow<'a, [f64]> {
            let r = a.index_axis_move(Axis(0), k);
            r.to_slice()
                .map_or_else(|| Cow::Owned(r.to_vec()), Cow::Borrowed)
        }
        for k in 0..samples {
            run.push(&Sample {
                step: k,
                t: t[k],
                q: &row(&q, k),
                dq: &row(&dq, k),
                p: Some(&row(&p, k)),
                energy: 0.0,
                lambda: &row(&lam, k),
                violation: 0.0,
                u: &row(&u, k),
                impulse: &[],
                gap: &[],
            });
        }
        Ok(run)
    }
}

#[pymethods]
impl Model {
    /// The exact linearisation at a state (the keys of `tree-mech linearize`): `qdd`,
    /// `qdd_dq`, `qdd_ddq`, `qdd_du`, `lambda`, `lambda_dq`, …; with `dt`, one step as a map
    /// under `vi` (trep's names: `q2_dq1` …, `lambda1` = −Δt λ; with `second_order`, trep's
    /// 30 second derivatives as (output, input₁, input₂)) or, with `integrator` "rk4" or
    /// "rk45", under that key (`x2_dx1`, `x2_du1` on (q_d, q̇_d)).
    #[pyo3(signature = (q=None, dq=None, u=None, t=0.0, dt=None, p=None, integrator="vi", forcing="split", alpha=0.5, second_order=false, ddq=None, kappa=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn linearize<'py>(
        &self,
        py: Python<'py>,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        u: Option<Numbers<'_, Ix1>>,
        t: f64,
        dt: Option<f64>,
        p: Option<Numbers<'_, Ix1>>,
        integrator: &str,
        forcing: &str,
        alpha: f64,
        second_order: bool,
        ddq: Option<PerVariable<'_>>,
        kappa: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let u = self.input_vector(u)?;
        let request = ReportRequest {
            t,
            u,
            dt,
            p: p.map(|p| p.as_array().to_vec()),
            forcing: crate::simulate::forcing(forcing)?,
            alpha,
            explicit: Explicit::of(integrator.parse().map_err(bad)?),
            second_order,
            kappa,
        };
        // The model's own system, whose workspaces (the jets' kernel among them) stay warm
        // between calls.
        let mut guard = self.sys.lock().expect("no panic holds the lock");
        let sys: &mut TreeSystem = &mut guard;
        let mut motion = self.kinematics(sys, &q, &dq, ddq)?;
        let r = py
            .detach(move || report::linearize_with(sys, &q, &dq, &request, &mut motion))
            .map_err(|e| sim_error(py, &e))?;
        drop(guard);
        let out = self.named_parts(py)?;
        for (key, e) in &r.continuous {
            out.set_item(key, entry(py, e))?;
        }
        if let Some((key, entries)) = &r.step {
            let step = PyDict::new(py);
            for (name, e) in entries {
                step.set_item(name, entry(py, e))?;
            }
            out.set_item(*key, step)?;
        }
        Ok(out)
    }

    /// The first derivatives of every step of `trajectory`, a run of this model by the VI
    /// (`simulate(..., integrator="vi")`, every step recorded, the same `alpha`, `forcing`,
    /// `newton_tol`) — trep's `DSystem.linearize_trajectory`: a dict with the names of the
    /// variables, dynamic, kinematic, inputs and constraints, and trep's `q2_dq1` …
    /// `lambda1_dk2` (as `linearize`'s `vi` block), each stacked over the steps (steps,
    /// rows, columns). The steps are shared out over `threads` threads (None: every core;
    /// the same numbers whatever the count), the GIL released. A step whose recorded end
    /// does not solve its equations (samples every second step, a subdivided step, other
    /// settings) raises `SimulationError` naming it. `progress(done, steps)`, if given, is
    /// called as steps are linearised (at most every 50 ms, and once at the end); Ctrl-C, or
    /// an exception from `progress`, stops the call and is raised.
    #[pyo3(signature = (trajectory, alpha=0.5, forcing="split", newton_tol=None, threads=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn linearize_trajectory<'py>(
        &self,
        py: Python<'py>,
        trajectory: PyRef<'_, Trajectory>,
        alpha: f64,
        forcing: &str,
        newton_tol: Option<f64>,
        threads: Option<i64>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let threads = threads.map(|k| count("threads", k, 1)).transpose()?;
        let Method::Vi(settings) = method("vi", alpha, forcing, newton_tol, 0.0, 0.0, 0.0)? else {
            unreachable!("the VI's settings")
        };
        let run = self.core_trajectory(py, &trajectory)?;
        let sys = self.system();
        let watch = Watch::default();
        let linearize = || {
            let mut steps = Vec::new();
            StepLinearizer::new(&sys, &settings, threads.unwrap_or(0))?
                .linearize_into_watched(&run, &mut steps, &watch)
                .map(|()| steps)
        };
        let count = run.len().saturating_sub(1);
        let steps = watched(py, linearize, &watch, count, progress.as_ref())?
            .map_err(|e| sim_error(py, &e))?;
        let out = self.named_parts(py)?;
        for of in StepOutput::ALL {
            for by in StepInput::ALL {
                let (rows, columns) = steps.first().map_or((0, 0), |s| s.block(of, by).shape());
                // trep's λ₁ is −Δt times this integrator's force-scaled λ.
                let scale = |k: usize| match of {
                    StepOutput::Lambda => run.t[k] - run.t[k + 1],
                    _ => 1.0,
                };
                let stack = Array3::from_shape_fn((steps.len(), rows, columns), |(k, i, j)| {
                    scale(k) * steps[k].block(of, by)[(i, j)]
                });
                let key = format!("{}_d{}", of.name(), by.name());
                out.set_item(key, stack.into_pyarray(py))?;
            }
        }
        Ok(out)
    }
}
