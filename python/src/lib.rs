//! `tree_mech._native`: the Python package's compiled core over the interpreted runtime —
//! models read at run time, numpy arrays in and out, long calls without the GIL. The
//! package's `tree_mech/__init__.py` re-exports it with docs and type stubs.

mod numbers;

use std::borrow::Cow;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use numpy::ndarray::{s, Array1, Array2, Array3, ArrayView2, Axis, Ix1, Ix2};
use numpy::{
    AllowTypeChange, IntoPyArray, PyArrayLike1, PyArrayLike2, PyArrayLike3, PyReadonlyArray1,
    PyReadonlyArray2,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::control::{solve_task_until, TaskOptions, TaskSolver};
use tree_mech::integrate::{
    Forcing, InputSchedule, Method, MidpointVi, SimOptions, StepContext, StepInput, StepOutput,
    Tolerance, ViSettings,
};
use tree_mech::model::{self, Integrator, ModelError as CoreModelError};
use tree_mech::nalgebra::{DMatrix, DVector, Dyn};
use tree_mech::runtime::batch::{
    rollouts_of_watched, rollouts_watched, trajectory, Rollout, StepLinearizer, Watch,
};
use tree_mech::runtime::dynamics::inverse_dynamics;
use tree_mech::runtime::evaluation::{continuous_dynamics, evaluate_state_with};
use tree_mech::runtime::kinematics::{Kinematics as FrameKinematics, Reference};
use tree_mech::runtime::report::{self, Entry, Explicit, Request as ReportRequest};
use tree_mech::runtime::trajectory::Sample;
use tree_mech::runtime::Vector;
use tree_mech::runtime::{ModelMotions, Prescription};
use tree_mech::{
    ConstraintTerms, Order, SimError, System, Terms, Trajectory as CoreTrajectory, TreeSystem,
};

use numbers::Numbers;

pyo3::create_exception!(
    _native,
    ModelError,
    PyValueError,
    "A model or task file is wrong: the message names the problem and its place; `file` and `line` say where (None when unknown)."
);
pyo3::create_exception!(
    _native,
    SimulationError,
    PyRuntimeError,
    "A simulation or solve failed: the message names the cause; `step` is the step it failed at (None when it names none)."
);

/// A `ModelError` exception with `file` and `line` set from the first problem.
fn model_error(py: Python<'_>, e: &CoreModelError) -> PyErr {
    let err = ModelError::new_err(e.to_string());
    let value = err.value(py);
    let line = e.problems.first().and_then(|p| p.line);
    let _ = value.setattr("file", e.source_name.clone());
    let _ = value.setattr("line", line);
    err
}

/// A run's error message with the command line's options named as this package's keyword
/// arguments (`lower --dt` reads `lower dt`).
fn in_python_terms(e: &SimError) -> String {
    [
        ("--integrator vi", "integrator=\"vi\""),
        ("--max-steps", "max_steps"),
        ("--duration", "duration"),
        ("--dt", "dt"),
    ]
    .iter()
    .fold(e.to_string(), |m, (flag, argument)| {
        m.replace(flag, argument)
    })
}

/// A `SimulationError` with `step` set.
fn sim_error(py: Python<'_>, e: &SimError) -> PyErr {
    let err = SimulationError::new_err(in_python_terms(e));
    let _ = err.value(py).setattr("step", e.step());
    err
}

fn bad(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// Runs a batch (`run`, under `watch`) on a thread of its own with the GIL released, while
/// this thread waits for it: every 50 ms, and when it finishes, Ctrl-C is checked and
/// `progress(done, batch)` called with the GIL taken back for the moment. Ctrl-C or an
/// exception from `progress` stops the batch (`watch.stop`) and is returned.
fn watched<T: Send>(
    py: Python<'_>,
    run: impl FnOnce() -> T + Send,
    watch: &Watch,
    batch: usize,
    progress: Option<&Py<PyAny>>,
) -> PyResult<T> {
    let mut raised: Option<PyErr> = None;
    let result = py.detach(|| {
        let finished = AtomicBool::new(false);
        let waiting = std::thread::current();
        std::thread::scope(|scope| {
            let worker = scope.spawn(|| {
                let result = run();
                // Set before the wake-up: a wait that starts after it returns at once.
                finished.store(true, Ordering::Release);
                waiting.unpark();
                result
            });
            let mut reported = None;
            loop {
                let finished = finished.load(Ordering::Acquire);
                let done = watch.done.load(Ordering::Relaxed);
                let checked = Python::attach(|py| {
                    py.check_signals()?;
                    match progress {
                        Some(f) if reported != Some(done) => f.call1(py, (done, batch)).map(drop),
                        _ => Ok(()),
                    }
                });
                reported = Some(done);
                if let Err(e) = checked {
                    raised = Some(e);
                    watch.stop.store(true, Ordering::Relaxed);
                    break;
                }
                if finished {
                    break;
                }
                std::thread::park_timeout(std::time::Duration::from_millis(50));
            }
            worker.join()
        })
    });
    match (raised, result) {
        (Some(e), _) => Err(e),
        (None, Ok(result)) => Ok(result),
        (None, Err(_)) => Err(PyRuntimeError::new_err("a batch's thread panicked")),
    }
}

/// An array's shape as Python writes it: `(3, 1)`, `(4,)`.
fn shape_text(shape: &[usize]) -> String {
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
fn count(what: &str, x: i64, least: usize) -> PyResult<usize> {
    match usize::try_from(x) {
        Ok(k) if k >= least => Ok(k),
        _ => Err(bad(format!("{what} must be at least {least}, got {x}"))),
    }
}

/// A `ValueError` naming the first entry of `values` that is not finite (`names[i]` says
/// whose it is): states and inputs are numbers, and a NaN would otherwise surface later as a
/// misleading failure of the dynamics.
fn check_finite(what: &str, values: &[f64], names: &[String]) -> PyResult<()> {
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
fn steps_of(duration: f64, dt: f64) -> Option<usize> {
    let steps = (duration / dt).round();
    (1.0..=1e9).contains(&steps).then_some(steps as usize)
}

/// Per-step inputs have one row a step: a different count (a mixed-up `dt`, a schedule for
/// another horizon) is a `ValueError`, not inputs silently cut short or held.
fn check_rows(rows: usize, duration: f64, dt: f64) -> PyResult<()> {
    match steps_of(duration, dt) {
        Some(steps) if steps != rows => Err(bad(format!(
            "u has {rows} rows of inputs, one a step; the run has {steps} steps (duration / dt)"
        ))),
        _ => Ok(()),
    }
}

/// A model read at run time, with its interpreted system.
#[pyclass(module = "tree_mech", frozen)]
struct Model {
    model: model::Model,
    sys: Mutex<TreeSystem>,
    /// The frames' kinematics (`frame_jacobian` and the rest).
    frames: Mutex<FrameKinematics>,
}

impl Model {
    fn of(model: model::Model) -> PyResult<Self> {
        let sys = TreeSystem::new(&model).map_err(|e| ModelError::new_err(e.to_string()))?;
        let frames =
            FrameKinematics::new(&model).map_err(|e| ModelError::new_err(e.to_string()))?;
        Ok(Model {
            model,
            sys: Mutex::new(sys),
            frames: Mutex::new(frames),
        })
    }

    /// The frames' kinematics at `(q, dq, ddq)` (defaults: the model's q0, dq0 and zero).
    fn frames_at(
        &self,
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
    ) -> PyResult<std::sync::MutexGuard<'_, FrameKinematics>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let ddq = self.vector("ddq", ddq, |_| 0.0)?;
        let mut k = self.frames.lock().expect("no panic holds the lock");
        k.update(q.as_slice(), Some(dq.as_slice()), Some(ddq.as_slice()))
            .map_err(|e| bad(e.to_string()))?;
        Ok(k)
    }

    /// The frame `name`'s kinematics at `(q, dq, ddq)` and its index.
    fn frame_at(
        &self,
        name: &str,
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
    ) -> PyResult<(std::sync::MutexGuard<'_, FrameKinematics>, usize)> {
        let k = self.frames_at(q, dq, ddq)?;
        let f = k.frame(name).map_err(|e| bad(e.to_string()))?;
        Ok((k, f))
    }

    fn system(&self) -> TreeSystem {
        self.sys.lock().expect("no panic holds the lock").clone()
    }

    /// A dict naming the model's parts in order (`variables`, `dynamic`, `kinematic`,
    /// `inputs`, `constraints`): how a linearisation's dict begins.
    fn named_parts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        out.set_item("variables", self.names())?;
        out.set_item("dynamic", self.dynamic())?;
        out.set_item("kinematic", self.kinematic())?;
        out.set_item("inputs", self.inputs())?;
        out.set_item("constraints", self.constraints())?;
        Ok(out)
    }

    /// The run `trajectory` holds, back as the runtime's (what `linearize_trajectory` reads:
    /// times, q, q̇, the VI's momenta, λ and the inputs of every sample).
    fn core_trajectory(&self, py: Python<'_>, trajectory: &Trajectory) -> PyResult<CoreTrajectory> {
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
        let mut run =
            CoreTrajectory::new(trajectory.variables.clone(), self.constraints(), samples);
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
            });
        }
        Ok(run)
    }

    fn n(&self) -> usize {
        self.model.variables.len()
    }

    /// A vector of every variable, or the model's default.
    fn vector(
        &self,
        what: &str,
        given: Option<Numbers<'_, Ix1>>,
        default: impl Fn(usize) -> f64,
    ) -> PyResult<Vector<Dyn>> {
        let n = self.n();
        match given {
            None => Ok(Vector::<Dyn>::from_fn(n, |i, _| default(i))),
            Some(a) => {
                let v = a.as_array();
                if v.len() != n {
                    return Err(bad(format!(
                        "{what} has {} entries; the model has {n} variables ({})",
                        v.len(),
                        self.names().join(", ")
                    )));
                }
                let v: Vec<f64> = v.iter().copied().collect();
                check_finite(what, &v, &self.names())?;
                Ok(Vector::<Dyn>::from_vec(v))
            }
        }
    }

    /// One number per variable, as a numpy array.
    fn per_variable(&self, py: Python<'_>, of: impl Fn(&model::Variable) -> f64) -> Py<PyAny> {
        vector(py, &self.model.variables.iter().map(of).collect::<Vec<_>>())
    }

    fn input_names(&self) -> Vec<String> {
        self.model.inputs.iter().map(|u| u.name.clone()).collect()
    }

    /// The inputs at one state: one finite value per input, or zeros.
    fn input_vector(&self, given: Option<Numbers<'_, Ix1>>) -> PyResult<Vec<f64>> {
        match given {
            None => Ok(vec![0.0; self.model.inputs.len()]),
            Some(u) => self.checked_inputs(u.as_array().to_vec()),
        }
    }

    /// `u` if it holds one finite value per input, else a `ValueError` naming the inputs.
    fn checked_inputs(&self, u: Vec<f64>) -> PyResult<Vec<f64>> {
        if u.len() != self.model.inputs.len() {
            return Err(bad(format!(
                "u has {} entries; the model has {}",
                u.len(),
                self.inputs_phrase()
            )));
        }
        check_finite("u", &u, &self.input_names())?;
        Ok(u)
    }

    /// "no inputs", or "2 inputs (push, pull)".
    fn inputs_phrase(&self) -> String {
        match self.model.inputs.len() {
            0 => "no inputs".to_string(),
            n => format!("{n} inputs ({})", self.input_names().join(", ")),
        }
    }

    /// The kinematic variables' motion for a call at one state: the model's prescription, or
    /// with `ddq` given, held at the given `q`, `dq` and `ddq`.
    fn kinematics(
        &self,
        sys: &TreeSystem,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        ddq: Option<Numbers<'_, Ix1>>,
    ) -> PyResult<Kinematics> {
        Ok(match ddq {
            None => Kinematics::Model(ModelMotions::of(sys)),
            Some(ddq) => {
                let ddq = self.vector("ddq", Some(ddq), |_| 0.0)?;
                Kinematics::Given(q.clone(), dq.clone(), ddq)
            }
        })
    }

    fn names(&self) -> Vec<String> {
        self.model
            .variables
            .iter()
            .map(|v| v.name.clone())
            .collect()
    }

    /// The names of variables `list`.
    fn named(&self, list: &[usize]) -> Vec<String> {
        list.iter()
            .map(|&i| self.model.variables[i].name.clone())
            .collect()
    }

    /// The inputs: none (zero), constant (inputs,), or per step (steps, inputs) at `dt`.
    fn schedule(
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

/// The integrator named by `integrator` with the options of `simulate`.
#[allow(clippy::too_many_arguments)]
fn method(
    integrator: &str,
    alpha: f64,
    forcing: &str,
    newton_tol: Option<f64>,
    rtol: f64,
    atol: f64,
) -> PyResult<Method> {
    Ok(match integrator.parse().map_err(bad)? {
        Integrator::Vi => Method::Vi(ViSettings {
            alpha,
            forcing: match forcing {
                "split" => Forcing::Split,
                "left" => Forcing::Left,
                other => return Err(bad(format!("forcing `{other}`: use `split` or `left`"))),
            },
            tolerance: newton_tol.unwrap_or(ViSettings::default().tolerance),
            ..ViSettings::default()
        }),
        Integrator::Rk4 => Method::Rk4,
        Integrator::Rk45 => Method::Rk45(Tolerance { rtol, atol }),
    })
}

/// A run's samples as arrays.
#[pyclass(module = "tree_mech", frozen, get_all)]
struct Trajectory {
    /// Sample times (samples,).
    t: Py<PyAny>,
    /// Configurations (samples, n).
    q: Py<PyAny>,
    /// Velocities (samples, n).
    dq: Py<PyAny>,
    /// The VI's discrete momenta (samples, n); None for another integrator.
    p: Py<PyAny>,
    /// Total energy (samples,).
    energy: Py<PyAny>,
    /// Constraint forces (samples, constraint rows).
    lam: Py<PyAny>,
    /// max |h| (samples,).
    violation: Py<PyAny>,
    /// Inputs in force (samples, inputs).
    u: Py<PyAny>,
    /// Variable names.
    variables: Vec<String>,
    /// Newton iterations over the run (VI).
    newton_iterations: usize,
    /// Energy taken out by damping.
    dissipated: f64,
}

fn rows(py: Python<'_>, len: usize, width: usize, row: impl Fn(usize) -> Vec<f64>) -> Py<PyAny> {
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

/// A frame reference by its name, or a `ValueError` naming the three.
fn parse_reference(name: &str) -> PyResult<Reference> {
    Reference::parse(name).ok_or_else(|| {
        bad(format!(
            "reference `{name}` is not one of \"local\", \"local_world_aligned\", \"world\""
        ))
    })
}

fn vector(py: Python<'_>, v: &[f64]) -> Py<PyAny> {
    Array1::from(v.to_vec())
        .into_pyarray(py)
        .into_any()
        .unbind()
}

fn matrix(py: Python<'_>, m: &DMatrix<f64>) -> Py<PyAny> {
    let (r, c) = m.shape();
    Array2::from_shape_fn((r, c), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
        .unbind()
}

impl Trajectory {
    fn of(py: Python<'_>, t: &CoreTrajectory, inputs: usize) -> Self {
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

/// Many rollouts: shared times, per-rollout arrays, per-rollout errors.
#[pyclass(module = "tree_mech", frozen, get_all)]
struct Rollouts {
    /// Sample times (samples,): those of the longest successful rollout.
    t: Py<PyAny>,
    /// Configurations (batch, samples, n); a failed rollout's rows are NaN from its failure on.
    q: Py<PyAny>,
    /// Velocities (batch, samples, n).
    dq: Py<PyAny>,
    /// Energies (batch, samples).
    energy: Py<PyAny>,
    /// Per rollout: None, or the error's message.
    errors: Vec<Option<String>>,
}

#[pymethods]
impl Model {
    /// The model's name.
    #[getter]
    fn name(&self) -> String {
        self.model.name.clone()
    }

    /// Every variable's name, in order (the order of q).
    #[getter]
    fn variables(&self) -> Vec<String> {
        self.names()
    }

    /// The dynamic (simulated) variables' names.
    #[getter]
    fn dynamic(&self) -> Vec<String> {
        self.named(&self.model.dynamic())
    }

    /// The kinematic (prescribed) variables' names.
    #[getter]
    fn kinematic(&self) -> Vec<String> {
        self.named(&self.model.kinematic())
    }

    /// The inputs' names (u's order).
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.model.inputs.iter().map(|i| i.name.clone()).collect()
    }

    /// The constraint equations' names (λ's order).
    #[getter]
    fn constraints(&self) -> Vec<String> {
        self.model.constraint_row_names()
    }

    /// The frames' names.
    #[getter]
    fn frames(&self) -> Vec<String> {
        self.model.frames.iter().map(|f| f.name.clone()).collect()
    }

    /// The initial configuration.
    #[getter]
    fn q0(&self, py: Python<'_>) -> Py<PyAny> {
        self.per_variable(py, |v| v.q0)
    }

    /// The initial velocity.
    #[getter]
    fn dq0(&self, py: Python<'_>) -> Py<PyAny> {
        self.per_variable(py, |v| v.dq0)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({:?}: {} variables, {} frames, {} inputs, {} constraint rows)",
            self.model.name,
            self.n(),
            self.model.frames.len(),
            self.model.inputs.len(),
            self.model.constraint_rows()
        )
    }

    /// Everything at one state (the keys of `tree-mech eval`): L, energy, dL_dq, dL_ddq, M,
    /// d2L_ddqdq, d2L_dqdq, qdd (dynamic variables), lambda, h, dh_dq, poses (frame → 4×4).
    #[pyo3(signature = (q=None, dq=None, t=0.0, u=None, ddq=None))]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        t: f64,
        u: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        t: f64,
        u: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
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
    /// `d2h_dqdq` (equations × variables × variables), without the dynamics (so also where
    /// those have no solution).
    #[pyo3(signature = (q=None))]
    fn constraints_at<'py>(
        &self,
        py: Python<'py>,
        q: Option<Numbers<'_, Ix1>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        let mut c = ConstraintTerms::zeros(sys.constraint_count(), self.n());
        sys.constraints(&q, &Vector::<Dyn>::zeros(self.n()), Order::Full, &mut c);
        let curvature = c.d2h.iter().flat_map(|m| m.iter());
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
        let n = self.n();
        let d2h = Array3::from_shape_fn((c.d2h.len(), n, n), |(r, i, j)| c.d2h[r][(i, j)]);
        out.set_item("d2h_dqdq", d2h.into_pyarray(py))?;
        Ok(out)
    }

    /// The mass matrix M(q), every variable (`evaluate()["M"]` alone; Pinocchio's `crba`).
    #[pyo3(signature = (q=None))]
    fn mass_matrix(&self, py: Python<'_>, q: Option<Numbers<'_, Ix1>>) -> PyResult<Py<PyAny>> {
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

    /// Frame `frame`'s pose in the world at `q` (default the model's q0): 4 × 4, homogeneous
    /// (as `evaluate()["poses"][frame]`, alone).
    #[pyo3(signature = (frame, q=None))]
    fn frame_pose(
        &self,
        py: Python<'_>,
        frame: &str,
        q: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
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
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        ddq: Option<Numbers<'_, Ix1>>,
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
    fn com_jacobian(&self, py: Python<'_>, q: Option<Numbers<'_, Ix1>>) -> PyResult<Py<PyAny>> {
        let k = self.frames_at(q, None, None)?;
        Ok(matrix(py, &k.com_jacobian()))
    }

    /// Simulates from (q0, dq0) (default the model's) for `duration` s at step `dt`; `u`
    /// None, constant (inputs,) or per step (steps, inputs). Returns a `Trajectory`. The GIL
    /// is released while it runs; about a hundred times a run Ctrl-C is honoured and
    /// `progress(t, duration)`, if given, is called (a tqdm bar's `update`, say).
    #[pyo3(signature = (duration, dt, integrator="vi", q0=None, dq0=None, u=None, every=1, alpha=0.5, forcing="split", newton_tol=None, rtol=1e-8, atol=1e-10, max_steps=1_000_000, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn simulate(
        &self,
        py: Python<'_>,
        duration: f64,
        dt: f64,
        integrator: &str,
        q0: Option<Numbers<'_, Ix1>>,
        dq0: Option<Numbers<'_, Ix1>>,
        u: Option<&Bound<'_, PyAny>>,
        every: i64,
        alpha: f64,
        forcing: &str,
        newton_tol: Option<f64>,
        rtol: f64,
        atol: f64,
        max_steps: i64,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Trajectory> {
        let every = count("every", every, 1)?;
        let max_steps = count("max_steps", max_steps, 1)?;
        let q0 = self.vector("q0", q0, |i| self.model.variables[i].q0)?;
        let dq0 = self.vector("dq0", dq0, |i| self.model.variables[i].dq0)?;
        let inputs = self.schedule(u, duration, dt)?;
        let options = SimOptions {
            every,
            max_steps,
            ..SimOptions::new(
                method(integrator, alpha, forcing, newton_tol, rtol, atol)?,
                dt,
                duration,
            )
        };
        let mut sys = self.system();
        // A hundred times a run (at recorded samples): Ctrl-C is checked and `progress(t,
        // duration)` called, each with the GIL taken back for the moment; an exception from
        // either ends the run and is raised.
        let mut raised: Option<PyErr> = None;
        let start = Rollout {
            q0: q0.as_slice().to_vec(),
            dq0: dq0.as_slice().to_vec(),
            inputs,
        };
        let result = py.detach(|| {
            let mut next = 0.0;
            trajectory(&mut sys, &start, &options, &mut |t| {
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
        if let Some(e) = raised {
            return Err(e);
        }
        let traj = result.map_err(|e| sim_error(py, &e))?;
        Ok(Trajectory::of(py, &traj, self.model.inputs.len()))
    }

    /// The exact linearisation at a state (the keys of `tree-mech linearize`): `qdd`,
    /// `qdd_dq`, `qdd_ddq`, `qdd_du`, `lambda`, `lambda_dq`, …; with `dt`, one step as a map
    /// under `vi` (trep's names: `q2_dq1` …, `lambda1` = −Δt λ; with `second_order`, trep's
    /// 30 second derivatives as (output, input₁, input₂)) or, with `integrator` "rk4" or
    /// "rk45", under that key (`x2_dx1`, `x2_du1` on (q_d, q̇_d)).
    #[pyo3(signature = (q=None, dq=None, u=None, t=0.0, dt=None, p=None, integrator="vi", forcing="split", alpha=0.5, second_order=false, ddq=None))]
    #[allow(clippy::too_many_arguments)]
    fn linearize<'py>(
        &self,
        py: Python<'py>,
        q: Option<Numbers<'_, Ix1>>,
        dq: Option<Numbers<'_, Ix1>>,
        u: Option<Numbers<'_, Ix1>>,
        t: f64,
        dt: Option<f64>,
        p: Option<Numbers<'_, Ix1>>,
        integrator: &str,
        forcing: &str,
        alpha: f64,
        second_order: bool,
        ddq: Option<Numbers<'_, Ix1>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let u = self.input_vector(u)?;
        let request = ReportRequest {
            t,
            u,
            dt,
            p: p.map(|p| p.as_array().to_vec()),
            forcing: match forcing {
                "split" => Forcing::Split,
                "left" => Forcing::Left,
                other => return Err(bad(format!("forcing `{other}`: use `split` or `left`"))),
            },
            alpha,
            explicit: Explicit::of(integrator.parse().map_err(bad)?),
            second_order,
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
        let Method::Vi(settings) = method("vi", alpha, forcing, newton_tol, 0.0, 0.0)? else {
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

    /// A copy with other parameters: `masses` {frame: kg} (its centre of mass and inertia
    /// kept), `constants` {frame: the value of its constant primitive, m or rad},
    /// `gravity` [x, y, z] — a parameter sweep's model (`rollouts(..., models=[…])`).
    #[pyo3(signature = (masses=None, constants=None, gravity=None))]
    fn with_parameters(
        &self,
        masses: Option<std::collections::BTreeMap<String, f64>>,
        constants: Option<std::collections::BTreeMap<String, f64>>,
        gravity: Option<[f64; 3]>,
    ) -> PyResult<Model> {
        let mut m = self.model.clone();
        for (frame, mass) in masses.iter().flatten() {
            m.set_mass(frame, *mass).map_err(bad)?;
        }
        for (frame, value) in constants.iter().flatten() {
            m.set_constant(frame, *value).map_err(bad)?;
        }
        if let Some(g) = gravity {
            if g.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("gravity must be finite, got {g:?}")));
            }
            m.gravity = g;
        }
        Model::of(m)
    }

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
        let (q0, dq0) = (q0.as_array(), dq0.as_array());
        let (batch, n) = (q0.nrows(), self.n());
        if q0.ncols() != n || dq0.shape() != q0.shape() {
            return Err(bad(format!(
                "q0 and dq0 must both be (batch, {n}); got {} and {}",
                shape_text(q0.shape()),
                shape_text(dq0.shape())
            )));
        }
        let schedules = input_schedules(
            u,
            batch,
            self.model.inputs.len(),
            &self.input_names(),
            (duration, dt),
        )?;
        let starts: Vec<Rollout> = (0..batch)
            .map(|b| Rollout {
                q0: q0.row(b).to_vec(),
                dq0: dq0.row(b).to_vec(),
                inputs: schedules[b].clone(),
            })
            .collect();
        let options = SimOptions {
            every,
            ..SimOptions::new(
                method(integrator, 0.5, "split", None, 1e-8, 1e-10)?,
                dt,
                duration,
            )
        };
        let threads = threads.unwrap_or(0);
        let watch = Watch::default();
        let results = match models {
            None => {
                let sys = self.system();
                let run = || rollouts_watched(&sys, &starts, &options, threads, &watch);
                watched(py, run, &watch, batch, progress.as_ref())?
            }
            Some(models) => {
                if models.len() != batch {
                    return Err(bad(format!("{} models for {batch} rollouts: give one each", models.len())));
                }
                if let Some(m) = models.iter().find(|m| m.names() != self.names()) {
                    return Err(bad(format!(
                        "model `{}` has other variables than this one: a sweep changes parameters, not structure",
                        m.model.name
                    )));
                }
                let systems: Vec<TreeSystem> = models.iter().map(|m| m.system()).collect();
                let run = || rollouts_of_watched(systems, &starts, &options, threads, &watch);
                watched(py, run, &watch, batch, progress.as_ref())?
            }
        }
        .map_err(|e| sim_error(py, &e))?;
        Ok(gathered(py, &results, n))
    }
}

/// The midpoint VI one step at a time with everything given by the caller — `q₁` (the
/// kinematic entries too), the dynamic momenta `p₁`, the inputs `u₁` and the kinematic values
/// `k₂` at `t₂` — as trep's `MidpointVI` steps (forcing `left`, trep's, by default). The
/// workspace is kept between steps; the GIL is released while a step runs.
#[pyclass(module = "tree_mech")]
struct VariationalStepper {
    sys: TreeSystem,
    vi: MidpointVi<Dyn>,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    /// The last step's `q₂`: a step from it keeps the VI's predictor history.
    last: Vec<f64>,
}

#[pymethods]
impl VariationalStepper {
    #[new]
    #[pyo3(signature = (model, forcing="left", tolerance=None))]
    fn new(model: &Model, forcing: &str, tolerance: Option<f64>) -> PyResult<Self> {
        let forcing = match forcing {
            "left" => Forcing::Left,
            "split" => Forcing::Split,
            other => {
                return Err(bad(format!(
                    "forcing must be `left` or `split`, got `{other}`"
                )))
            }
        };
        let mut settings = ViSettings {
            forcing,
            max_subdivisions: 0,
            ..ViSettings::default()
        };
        if let Some(tol) = tolerance {
            if !(tol > 0.0 && tol.is_finite()) {
                return Err(bad(format!(
                    "the tolerance must be a positive number, got {tol}"
                )));
            }
            settings.tolerance = tol;
        }
        let sys = model.system();
        let vi = MidpointVi::new(&sys, settings);
        let n = model.n();
        Ok(VariationalStepper {
            dynamic: (0..n).filter(|&i| !sys.is_kinematic(i)).collect(),
            kinematic: (0..n).filter(|&i| sys.is_kinematic(i)).collect(),
            sys,
            vi,
            last: Vec::new(),
        })
    }

    /// One step from `(t1, q1, p1)` to `t2` with inputs `u1` and kinematic values `k2` (model
    /// order); `lam` is Newton's first guess for λ. Returns `(q2, p2, lam, iterations,
    /// derivatives)`: `q2` every variable, `p2` the dynamic momenta, `lam` this integrator's
    /// multipliers (forces; trep's `lambda1` is `−Δt` times them for its own row scaling),
    /// and with `order` 1 or 2 a dict of the step's derivatives under trep's names (q2_dq1 …,
    /// lambda1_* with the `−Δt` scaling), second ones as (output, input₁, input₂) stacks.
    #[pyo3(signature = (t1, q1, p1, t2, u1, k2, lam, order=0))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        t1: f64,
        q1: Numbers<'_, Ix1>,
        p1: Numbers<'_, Ix1>,
        t2: f64,
        u1: Numbers<'_, Ix1>,
        k2: Numbers<'_, Ix1>,
        lam: Numbers<'_, Ix1>,
        order: u8,
    ) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        let n = self.sys.dof();
        let (nd, nk, m) = (
            self.dynamic.len(),
            self.kinematic.len(),
            self.sys.constraint_count(),
        );
        let (q1, p1, u1, k2, lam) = (
            q1.as_array().to_vec(),
            p1.as_array().to_vec(),
            u1.as_array().to_vec(),
            k2.as_array().to_vec(),
            lam.as_array().to_vec(),
        );
        let sizes = [
            ("q1", q1.len(), n),
            ("p1", p1.len(), nd),
            ("u1", u1.len(), self.sys.input_count()),
            ("k2", k2.len(), nk),
            ("lambda", lam.len(), m),
        ];
        if let Some((what, got, want)) = sizes.iter().find(|(_, got, want)| got != want) {
            return Err(bad(format!(
                "{what} has {got} entries; the step needs {want}"
            )));
        }
        let dt = t2 - t1;
        if !(dt > 0.0 && dt.is_finite() && t1.is_finite()) {
            return Err(bad(format!(
                "t2 must come after t1 (got t1 = {t1}, t2 = {t2})"
            )));
        }
        if order > 2 {
            return Err(bad("order is 0, 1 or 2"));
        }
        let (dynamic, kinematic) = (&self.dynamic, &self.kinematic);
        let continuing = self.last == q1 && order == 0;
        let (sys, vi) = (&mut self.sys, &mut self.vi);
        let result = py.detach(|| -> Result<_, SimError> {
            let q1 = Vector::<Dyn>::from_column_slice(&q1);
            let mut p = Vector::<Dyn>::zeros(n);
            for (c, &i) in dynamic.iter().enumerate() {
                p[i] = p1[c];
            }
            let p1v = p.clone();
            // The kinematic values: q₁'s at t₁, k₂ at t₂ (the step asks for nothing else).
            let mut k_at = vec![0.0; n];
            for (c, &i) in kinematic.iter().enumerate() {
                k_at[i] = k2[c];
            }
            let half = t1 + 0.5 * dt;
            let q1k = q1.clone();
            let mut motion = move |i: usize, t: f64| {
                if t > half {
                    [k_at[i], 0.0, 0.0]
                } else {
                    [q1k[i], 0.0, 0.0]
                }
            };
            let mut force = tree_mech::NoForce;
            let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
            cx.u = &u1;
            vi.lambda.copy_from_slice(&lam);
            if !continuing {
                vi.predict_from_rest();
            }
            let (mut q2, mut next) = (q1.clone(), q1.clone());
            vi.step(cx.at(0, t1), &mut q2, &mut p, &mut next)?;
            let iterations = vi.iterations;
            let derivatives = match order {
                0 => None,
                1 => Some((vi.derivatives(cx.at(0, t1), &q1, &p1v, &q2)?, None)),
                _ => {
                    let (first, second) = vi.second_derivatives(cx.at(0, t1), &q1, &p1v, &q2)?;
                    Some((first, Some(second)))
                }
            };
            Ok((q2, p, vi.lambda.clone(), iterations, derivatives))
        });
        let (q2, p2, lambda, iterations, derivatives) = result.map_err(|e| sim_error(py, &e))?;
        self.last = q2.as_slice().to_vec();
        let p2: Vec<f64> = self.dynamic.iter().map(|&i| p2[i]).collect();
        let out = step_derivatives(py, derivatives, dt)?;
        (
            vector(py, q2.as_slice()),
            vector(py, &p2),
            vector(py, lambda.as_slice()),
            iterations,
            out,
        )
            .into_pyobject(py)
    }

    /// `p₂ = D₂L_d(q₁, q₂) + f⁺` for the step from `(t1, q1)` to `(t2, q2)` (model order; the
    /// dynamic momenta): how trep's `initialize_from_configs` starts from two configurations.
    fn momentum<'py>(
        &mut self,
        py: Python<'py>,
        t1: f64,
        q1: Numbers<'_, Ix1>,
        t2: f64,
        q2: Numbers<'_, Ix1>,
    ) -> PyResult<Py<PyAny>> {
        let n = self.sys.dof();
        let (q1, q2) = (q1.as_array().to_vec(), q2.as_array().to_vec());
        if q1.len() != n || q2.len() != n {
            return Err(bad(format!("q1 and q2 need {n} entries each")));
        }
        let dt = t2 - t1;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(bad(format!(
                "t2 must come after t1 (got t1 = {t1}, t2 = {t2})"
            )));
        }
        let (q1, q2) = (
            Vector::<Dyn>::from_column_slice(&q1),
            Vector::<Dyn>::from_column_slice(&q2),
        );
        let (mut force, mut motion) = (tree_mech::NoForce, |_: usize, _: f64| [0.0; 3]);
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, dt);
        let p = self
            .vi
            .momentum_after(cx.at(0, t1), &q1, &q2)
            .map_err(|e| sim_error(py, &e))?;
        let p: Vec<f64> = self.dynamic.iter().map(|&i| p[i]).collect();
        Ok(vector(py, &p))
    }
}

/// The kinematic variables' motion at one state: the model's prescription at `t`, or the
/// caller's own `(q, dq, ddq)` (trep's way: `ddq=` given).
enum Kinematics {
    Model(ModelMotions),
    Given(Vector<Dyn>, Vector<Dyn>, Vector<Dyn>),
}

impl Prescription for Kinematics {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        match self {
            Kinematics::Model(m) => m.kinematic(i, t),
            Kinematics::Given(q, dq, ddq) => [q[i], dq[i], ddq[i]],
        }
    }
}

/// trep's name of a step output.
fn step_output_name(of: StepOutput) -> &'static str {
    match of {
        StepOutput::Q2 => "q2",
        StepOutput::P2 => "p2",
        StepOutput::Lambda => "lambda1",
    }
}

/// A report entry as a Python value: a float or a numpy array.
fn entry(py: Python<'_>, e: &Entry) -> Py<PyAny> {
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

/// Reads a model file (TOML, or URDF by its extension).
#[pyfunction]
#[pyo3(signature = (path, floating_base=false))]
fn load(py: Python<'_>, path: PathBuf, floating_base: bool) -> PyResult<Model> {
    let m = model::from_file(&path, model::UrdfOptions { floating_base })
        .map_err(|e| model_error(py, &e))?;
    Model::of(m)
}

/// Reads a model from text: `format` "toml" or "urdf".
#[pyfunction]
#[pyo3(signature = (text, format="toml", floating_base=false))]
fn loads(py: Python<'_>, text: &str, format: &str, floating_base: bool) -> PyResult<Model> {
    let m = match format {
        "toml" => model::from_toml_str(text, None),
        "urdf" => model::from_urdf_str(text, None, model::UrdfOptions { floating_base }),
        other => return Err(bad(format!("format `{other}`: use `toml` or `urdf`"))),
    }
    .map_err(|e| model_error(py, &e))?;
    Model::of(m)
}

/// Solves a task (the text of a task file; its `model` relative to `base`): returns a dict
/// with the summary of `tree-mech optimize --json` and the trajectory and gains as arrays.
/// The GIL is released while it runs; after every iteration Ctrl-C is honoured and
/// `progress(iteration, cost)`, if given, is called (an exception from either ends the
/// solve and is raised).
#[pyfunction]
#[pyo3(signature = (text, base, source=None, solver=None, max_iterations=None, progress=None))]
fn optimize_text<'py>(
    py: Python<'py>,
    text: &str,
    base: PathBuf,
    source: Option<String>,
    solver: Option<&str>,
    max_iterations: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (task, m) = model::task_from_str(text, source.as_deref(), Path::new(&base))
        .map_err(|e| model_error(py, &e))?;
    let solver = match solver {
        None => None,
        Some("ilqr") => Some(TaskSolver::Ilqr),
        Some("ddp") => Some(TaskSolver::Ddp),
        Some(other) => return Err(bad(format!("solver `{other}`: use `ilqr` or `ddp`"))),
    };
    let sys = TreeSystem::new(&m).map_err(|e| ModelError::new_err(e.to_string()))?;
    let options = TaskOptions {
        solver,
        max_iterations,
    };
    let mut raised: Option<PyErr> = None;
    let res = py.detach(|| {
        let mut iteration = 0usize;
        solve_task_until(sys, &task, &m, &options, &mut |it| {
            iteration += 1;
            let checked = Python::attach(|py| {
                py.check_signals()?;
                if let Some(f) = &progress {
                    f.call1(py, (iteration, it.cost))?;
                }
                Ok::<_, PyErr>(())
            });
            match checked {
                Ok(()) => ControlFlow::Continue(()),
                Err(e) => {
                    raised = Some(e);
                    ControlFlow::Break(())
                }
            }
        })
    });
    if let Some(e) = raised {
        return Err(e);
    }
    let res = res.map_err(|e| sim_error(py, &e))?;
    let sol = &res.solution;
    let n = task.knots;
    let out = PyDict::new(py);
    out.set_item("converged", sol.converged)?;
    out.set_item("stopped", sol.stop.name())?;
    out.set_item("iterations", sol.history.len())?;
    out.set_item("cost", sol.cost)?;
    out.set_item("solve_seconds", res.solve_seconds)?;
    out.set_item(
        "variables",
        m.variables
            .iter()
            .map(|v| v.name.clone())
            .collect::<Vec<_>>(),
    )?;
    out.set_item(
        "controls",
        (0..task.controls.len())
            .map(|c| task.control_name(&m, c).to_string())
            .collect::<Vec<_>>(),
    )?;
    out.set_item("q_final", vector(py, res.q[n].as_slice()))?;
    out.set_item("dq_final", vector(py, res.dq[n].as_slice()))?;
    let origins = m.origins(res.q[n].as_slice());
    let frames = PyDict::new(py);
    for term in task.running.iter().chain(&task.terminal) {
        if let Some(f) = term.frame() {
            frames.set_item(&m.frames[f].name, vector(py, &origins[f]))?;
        }
    }
    out.set_item("frames", frames)?;
    let dvec = |v: &[DVector<f64>]| {
        let w = v.first().map_or(0, |x| x.len());
        rows(py, v.len(), w, |k| v[k].as_slice().to_vec())
    };
    out.set_item("t", vector(py, &res.t))?;
    out.set_item("q", dvec(&res.q))?;
    out.set_item("dq", dvec(&res.dq))?;
    out.set_item("lam", dvec(&res.lambda))?;
    out.set_item("u", dvec(&sol.u))?;
    out.set_item("x", dvec(&sol.x))?;
    let (nu, nx) = sol.gains.first().map_or((0, 0), |g| g.shape());
    let gains = Array3::from_shape_fn((n, nu, nx), |(k, i, j)| sol.gains[k][(i, j)]);
    out.set_item("K", gains.into_pyarray(py))?;
    out.set_item("feedforward", dvec(&sol.feedforward))?;
    out.set_item(
        "cost_history",
        sol.history.iter().map(|h| h.cost).collect::<Vec<_>>(),
    )?;
    Ok(out)
}

/// The compiled core of the `tree_mech` package.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Trajectory>()?;
    m.add_class::<Rollouts>()?;
    m.add_class::<VariationalStepper>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(loads, m)?)?;
    m.add_function(wrap_pyfunction!(optimize_text, m)?)?;
    m.add("ModelError", m.py().get_type::<ModelError>())?;
    m.add("SimulationError", m.py().get_type::<SimulationError>())?;
    Ok(())
}

/// Each rollout's inputs from `u`: none, a row each held constant, or a row each a step
/// (`(batch, steps, width)`); the error says which shapes fit.
fn input_schedules(
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
fn gathered(
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

/// A step's derivatives as a dict under trep's names (`q2_dq1` …, `lambda1_*` scaled by
/// `−Δt`), second ones as (output, input₁, input₂) stacks; empty without derivatives.
fn step_derivatives<'py>(
    py: Python<'py>,
    derivatives: Option<(
        tree_mech::integrate::StepDerivatives,
        Option<tree_mech::integrate::StepSecondDerivatives>,
    )>,
    dt: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    if let Some((first, second)) = derivatives {
        for of in StepOutput::ALL {
            let scale = if of == StepOutput::Lambda { -dt } else { 1.0 };
            for by in StepInput::ALL {
                let name = format!("{}_d{}", step_output_name(of), by.name());
                out.set_item(name, matrix(py, &(first.block(of, by) * scale)))?;
            }
            if let Some(second) = &second {
                for (k, &a) in StepInput::ALL.iter().enumerate() {
                    for &b in &StepInput::ALL[k..] {
                        let rows: Vec<DMatrix<f64>> =
                            second.block(of, a, b).iter().map(|h| h * scale).collect();
                        let name = format!("{}_d{}d{}", step_output_name(of), a.name(), b.name());
                        out.set_item(name, entry(py, &Entry::Stack(rows)))?;
                    }
                }
            }
        }
    }
    Ok(out)
}
