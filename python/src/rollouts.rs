//! `Model.rollouts`: many runs at once over threads (and SIMD lanes), each with its own start,
//! inputs or model, each one's error reported beside the others' results.

use numpy::ndarray::{s, Array2, Array3, Ix2};
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike2, PyArrayLike3};
use pyo3::prelude::*;
use tree_mech::integrate::{InputSchedule, SimOptions};
use tree_mech::runtime::batch::{rollouts_of_watched, rollouts_watched, Rollout, Watch};
use tree_mech::{SimError, TreeSystem};

use crate::arrays::{check_finite, check_rows, count, shape_text, vector};
use crate::errors::{bad, in_python_terms, sim_error};
use crate::model::Model;
use crate::numbers::Numbers;
use crate::progress::watched;
use crate::simulate::method;

/// Many rollouts: shared times, per-rollout arrays, per-rollout errors.
#[pyclass(module = "tree_mech", frozen, get_all)]
pub(crate) struct Rollouts {
    /// Sample times (samples,): those of the longest successful rollout.
    pub(crate) t: Py<PyAny>,
    /// Configurations (batch, samples, n); a failed rollout's rows are NaN from its failure on.
    pub(crate) q: Py<PyAny>,
    /// Velocities (batch, samples, n).
    pub(crate) dq: Py<PyAny>,
    /// Energies (batch, samples).
    pub(crate) energy: Py<PyAny>,
    /// Per rollout: None, or the error's message.
    pub(crate) errors: Vec<Option<String>>,
}

#[pymethods]
impl Model {
    /// Runs a batch: q0, dq0 of shape (batch, n); u None, (batch, inputs) constant or
    /// (batch, steps, inputs) per step; `threads` None: every core. Each rollout's error is
    /// reported in `errors`, not raised. `models`: one model per rollout (this one's
    /// variables, other parameters: `with_parameters`). The GIL is released while it runs;
    /// results are the same whatever the thread count, each rollout's those of `simulate`
    /// from its start. With `integrator="rk4"` on a model without constraints, four
    /// rollouts run at a time in SIMD lanes (the same numbers, about 1.7× the throughput).
    /// `progress(done, batch)`, if given, is called as rollouts finish (at most every 50 ms,
    /// and once at the end); Ctrl-C, or an exception from `progress`, stops the batch and is
    /// raised.
    #[pyo3(signature = (q0, dq0, duration, dt, integrator="vi", u=None, threads=None, every=1, models=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn rollouts(
        &self,
        py: Python<'_>,
        q0: Numbers<'_, Ix2>,
        dq0: Numbers<'_, Ix2>,
        duration: f64,
        dt: f64,
        integrator: &str,
        u: Option<&Bound<'_, PyAny>>,
        threads: Option<i64>,
        every: i64,
        models: Option<Vec<PyRef<'_, Model>>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Rollouts> {
        let every = count("every", every, 1)?;
        let threads = threads.map(|k| count("threads", k, 1)).transpose()?;
        let starts = self.starts(q0, dq0, u, (duration, dt))?;
        let (batch, n) = (starts.len(), self.n());
        let options = SimOptions {
            every,
            ..SimOptions::new(
                method(integrator, 0.5, "split", None, 1e-8, 1e-10, 0.0)?,
                dt,
                duration,
            )
        };
        let threads = threads.unwrap_or(0);
        let watch = Watch::default();
        let systems = self.sweep(models, batch)?;
        let results = match systems {
            None => {
                let sys = self.system();
                let run = || rollouts_watched(&sys, &starts, &options, threads, &watch);
                watched(py, run, &watch, batch, progress.as_ref())?
            }
            Some(systems) => {
                let run = || rollouts_of_watched(systems, &starts, &options, threads, &watch);
                watched(py, run, &watch, batch, progress.as_ref())?
            }
        }
        .map_err(|e| sim_error(py, &e))?;
        Ok(gathered(py, &results, n))
    }
}

impl Model {
    /// Each rollout's start: a row of `q0` and of `dq0` (both (batch, n)) and its inputs.
    fn starts(
        &self,
        q0: Numbers<'_, Ix2>,
        dq0: Numbers<'_, Ix2>,
        u: Option<&Bound<'_, PyAny>>,
        horizon: (f64, f64),
    ) -> PyResult<Vec<Rollout>> {
        let (q0, dq0) = (q0.as_array(), dq0.as_array());
        let (batch, n) = (q0.nrows(), self.n());
        if q0.ncols() != n || dq0.shape() != q0.shape() {
            return Err(bad(format!(
                "q0 and dq0 must both be (batch, {n}); got {} and {}",
                shape_text(q0.shape()),
                shape_text(dq0.shape())
            )));
        }
        let width = self.model.inputs.len();
        let schedules = input_schedules(u, batch, width, &self.input_names(), horizon)?;
        Ok(schedules
            .into_iter()
            .enumerate()
            .map(|(b, inputs)| Rollout {
                q0: q0.row(b).to_vec(),
                dq0: dq0.row(b).to_vec(),
                inputs,
            })
            .collect())
    }

    /// A parameter sweep's systems, one a rollout, each with this model's variables (None
    /// without `models`: every rollout runs this model).
    fn sweep(
        &self,
        models: Option<Vec<PyRef<'_, Model>>>,
        batch: usize,
    ) -> PyResult<Option<Vec<TreeSystem>>> {
        let Some(models) = models else {
            return Ok(None);
        };
        if models.len() != batch {
            return Err(bad(format!(
                "{} models for {batch} rollouts: give one each",
                models.len()
            )));
        }
        if let Some(m) = models.iter().find(|m| m.names() != self.names()) {
            return Err(bad(format!(
                "model `{}` has other variables than this one: a sweep changes parameters, not structure",
                m.model.name
            )));
        }
        Ok(Some(models.iter().map(|m| m.system()).collect()))
    }
}

/// Each rollout's inputs from `u`: none, a row each held constant, or a row each a step
/// (`(batch, steps, width)`); the error says which shapes fit.
pub(crate) fn input_schedules(
    u: Option<&Bound<'_, PyAny>>,
    batch: usize,
    width: usize,
    names: &[String],
    (duration, dt): (f64, f64),
) -> PyResult<Vec<InputSchedule>> {
    // What `u` may be, said in the error of a wrong one.
    let expected = if width == 0 {
        format!("the model has no inputs: leave u out, or give ({batch}, 0)")
    } else {
        format!("u must be ({batch}, {width}) or ({batch}, steps, {width})")
    };
    Ok(match u {
        None => vec![InputSchedule::default(); batch],
        Some(u) if u.is_none() => vec![InputSchedule::default(); batch],
        Some(u) => {
            if let Ok(a) = u.extract::<PyArrayLike2<f64, AllowTypeChange>>() {
                let a = a.as_array();
                if a.shape() != [batch, width] {
                    return Err(bad(format!("{expected}; got {}", shape_text(a.shape()))));
                }
                (0..batch)
                    .map(|b| {
                        let row = a.row(b).to_vec();
                        check_finite(&format!("u[{b}]"), &row, names)?;
                        Ok(InputSchedule::constant(row))
                    })
                    .collect::<PyResult<_>>()?
            } else {
                let a = u
                    .extract::<PyArrayLike3<f64, AllowTypeChange>>()
                    .map_err(|_| bad(format!("{expected}; got no array of numbers")))?;
                let a = a.as_array();
                if a.shape()[0] != batch || a.shape()[2] != width {
                    return Err(bad(format!("{expected}; got {}", shape_text(a.shape()))));
                }
                check_rows(a.shape()[1], duration, dt)?;
                let mut out = Vec::with_capacity(batch);
                for b in 0..batch {
                    let rows = (0..a.shape()[1])
                        .map(|k| {
                            (
                                k as f64 * dt,
                                a.slice(numpy::ndarray::s![b, k, ..]).to_vec(),
                            )
                        })
                        .collect();
                    out.push(InputSchedule::from_rows(rows).map_err(|e| bad(e.to_string()))?);
                }
                out
            }
        }
    })
}

/// The rollouts as arrays: every one padded with NaN to the longest's samples, and each
/// one's error (None where it ran through).
pub(crate) fn gathered(
    py: Python<'_>,
    results: &[Result<tree_mech::Trajectory, SimError>],
    n: usize,
) -> Rollouts {
    let batch = results.len();
    let longest = results
        .iter()
        .filter_map(|r| r.as_ref().ok())
        .max_by_key(|t| t.len());
    let t: Vec<f64> = longest.map_or_else(Vec::new, |l| l.t.clone());
    let samples = t.len();
    let mut q = Array3::from_elem((batch, samples, n), f64::NAN);
    let mut dq = Array3::from_elem((batch, samples, n), f64::NAN);
    let mut energy = Array2::from_elem((batch, samples), f64::NAN);
    let mut errors = Vec::with_capacity(batch);
    for (b, r) in results.iter().enumerate() {
        match r {
            Ok(traj) => {
                // Each rollout's samples are contiguous on both sides: one copy each.
                let k = traj.len().min(samples);
                let rows = |a: &mut Array3<f64>, from: &[f64]| {
                    let mut to = a.slice_mut(s![b, ..k, ..]);
                    match to.as_slice_mut() {
                        Some(to) => to.copy_from_slice(&from[..k * n]),
                        None => to.iter_mut().zip(from).for_each(|(o, &x)| *o = x),
                    }
                };
                rows(&mut q, traj.q_rows());
                rows(&mut dq, traj.dq_rows());
                energy
                    .slice_mut(s![b, ..k])
                    .iter_mut()
                    .zip(&traj.energy)
                    .for_each(|(e, &x)| *e = x);
                errors.push(None);
            }
            Err(e) => errors.push(Some(in_python_terms(e))),
        }
    }
    Rollouts {
        t: vector(py, &t),
        q: q.into_pyarray(py).into_any().unbind(),
        dq: dq.into_pyarray(py).into_any().unbind(),
        energy: energy.into_pyarray(py).into_any().unbind(),
        errors,
    }
}
