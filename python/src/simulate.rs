//! `Model.simulate`: one run from a start, its integrator and inputs named as the CLI names
//! them, Ctrl-C and progress honoured while it runs.

use numpy::{AllowTypeChange, PyArrayLike1, PyArrayLike2};
use pyo3::prelude::*;
use tree_mech::integrate::{Forcing, InputSchedule, Method, SimOptions, Tolerance, ViSettings};
use tree_mech::model::Integrator;
use tree_mech::runtime::batch::{trajectory, Rollout};
use tree_mech::{SimError, Trajectory as CoreTrajectory, TreeSystem};

use crate::arrays::{check_rows, count};
use crate::errors::{bad, sim_error};
use crate::model::Model;
use crate::numbers::PerVariable;
use crate::trajectory::Trajectory;

/// The integrator named by `integrator` with the options of `simulate`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn method(
    integrator: &str,
    alpha: f64,
    forcing_name: &str,
    newton_tol: Option<f64>,
    rtol: f64,
    atol: f64,
    kappa: f64,
) -> PyResult<Method> {
    Ok(match integrator.parse().map_err(bad)? {
        Integrator::Vi => Method::Vi(ViSettings {
            alpha,
            forcing: forcing(forcing_name)?,
            tolerance: newton_tol.unwrap_or(ViSettings::default().tolerance),
            kappa,
            ..ViSettings::default()
        }),
        Integrator::Rk4 => Method::Rk4,
        Integrator::Rk45 => Method::Rk45(Tolerance { rtol, atol }),
    })
}

impl Model {
    /// The inputs: none (zero), constant (inputs,), or per step (steps, inputs) at `dt`.
    pub(crate) fn schedule(
        &self,
        u: Option<&Bound<'_, PyAny>>,
        duration: f64,
        dt: f64,
    ) -> PyResult<InputSchedule> {
        let width = self.model.inputs.len();
        let Some(u) = u else {
            return Ok(InputSchedule::default());
        };
        if u.is_none() {
            return Ok(InputSchedule::default());
        }
        if let Ok(a) = u.extract::<PyArrayLike1<f64, AllowTypeChange>>() {
            let v = self.checked_inputs(a.as_array().to_vec())?;
            return Ok(InputSchedule::constant(v));
        }
        let a = u
            .extract::<PyArrayLike2<f64, AllowTypeChange>>()
            .map_err(|_| bad("u must be None, a vector (inputs,) or an array (steps, inputs)"))?;
        let a = a.as_array();
        if a.ncols() != width {
            return Err(bad(format!(
                "u has {} columns; the model has {}",
                a.ncols(),
                self.inputs_phrase()
            )));
        }
        check_rows(a.nrows(), duration, dt)?;
        let rows = (0..a.nrows())
            .map(|k| (k as f64 * dt, a.row(k).to_vec()))
            .collect();
        InputSchedule::from_rows(rows).map_err(|e| bad(e.to_string()))
    }
}

#[pymethods]
impl Model {
    /// Simulates from (q0, dq0) (default the model's) for `duration` s at step `dt`; `u`
    /// None, constant (inputs,) or per step (steps, inputs). Returns a `Trajectory`. The GIL
    /// is released while it runs; about a hundred times a run Ctrl-C is honoured and
    /// `progress(t, duration)`, if given, is called (a tqdm bar's `update`, say). `kappa`: the
    /// VI's contact relaxation (0, the default: hard contact; κ > 0: smooth, `φγ = κ`).
    #[pyo3(signature = (duration, dt, integrator="vi", q0=None, dq0=None, u=None, every=1, alpha=0.5, forcing="split", newton_tol=None, rtol=1e-8, atol=1e-10, max_steps=1_000_000, progress=None, kappa=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn simulate(
        &self,
        py: Python<'_>,
        duration: f64,
        dt: f64,
        integrator: &str,
        q0: Option<PerVariable<'_>>,
        dq0: Option<PerVariable<'_>>,
        u: Option<&Bound<'_, PyAny>>,
        every: i64,
        alpha: f64,
        forcing: &str,
        newton_tol: Option<f64>,
        rtol: f64,
        atol: f64,
        max_steps: i64,
        progress: Option<Py<PyAny>>,
        kappa: f64,
    ) -> PyResult<Trajectory> {
        let every = count("every", every, 1)?;
        let max_steps = count("max_steps", max_steps, 1)?;
        let (q0, dq0) = self.start(q0, dq0)?;
        let inputs = self.schedule(u, duration, dt)?;
        let options = SimOptions {
            every,
            max_steps,
            ..SimOptions::new(
                method(integrator, alpha, forcing, newton_tol, rtol, atol, kappa)?,
                dt,
                duration,
            )
        };
        let start = Rollout { q0, dq0, inputs };
        let traj = run_watched(py, self.system(), &start, &options, progress)?;
        Ok(Trajectory::of(py, &traj, self.model.inputs.len()))
    }
}

/// One run without the GIL. A hundred times a run (at recorded samples) Ctrl-C is checked and
/// `progress(t, duration)` called, each with the GIL taken back for the moment; an exception
/// from either ends the run and is raised.
fn run_watched(
    py: Python<'_>,
    mut sys: TreeSystem,
    start: &Rollout,
    options: &SimOptions,
    progress: Option<Py<PyAny>>,
) -> PyResult<CoreTrajectory> {
    let duration = options.duration;
    let mut raised: Option<PyErr> = None;
    let result = py.detach(|| {
        let mut next = 0.0;
        trajectory(&mut sys, start, options, &mut |t| {
            if t < next {
                return Ok(());
            }
            next = t + 0.01 * duration;
            let checked = Python::attach(|py| {
                py.check_signals()?;
                if let Some(f) = &progress {
                    f.call1(py, (t, duration))?;
                }
                Ok::<_, PyErr>(())
            });
            checked.map_err(|e| {
                raised = Some(e);
                SimError::InvalidInput("interrupted".into())
            })
        })
    });
    match raised {
        Some(e) => Err(e),
        None => result.map_err(|e| sim_error(py, &e)),
    }
}

/// The VI's forcing by its name: `split` (the midpoint's) or `left` (trep's).
pub(crate) fn forcing(name: &str) -> PyResult<Forcing> {
    match name {
        "split" => Ok(Forcing::Split),
        "left" => Ok(Forcing::Left),
        other => Err(bad(format!("forcing `{other}`: use `split` or `left`"))),
    }
}
