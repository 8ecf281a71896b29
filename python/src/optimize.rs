//! `optimize_text`: a task file solved (`tree-mech optimize`), its summary and plan as a dict.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use numpy::ndarray::Array3;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::control::{solve_task_until, HardReplay, Task, TaskOptions, TaskResult, TaskSolver};
use tree_mech::model;
use tree_mech::nalgebra::DVector;
use tree_mech::TreeSystem;

use crate::arrays::{rows, vector};
use crate::errors::{bad, model_error, sim_error, system_error};

/// Solves a task (the text of a task file; its `model` relative to `base`): returns a dict
/// with the summary of `tree-mech optimize --json` and the trajectory and gains as arrays.
/// The GIL is released while it runs; after every iteration Ctrl-C is honoured and
/// `progress(iteration, cost)`, if given, is called (an exception from either ends the
/// solve and is raised).
#[pyfunction]
#[pyo3(signature = (text, base, source=None, solver=None, max_iterations=None, progress=None))]
pub(crate) fn optimize_text<'py>(
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
    let sys = TreeSystem::new(&m).map_err(|e| system_error(&e))?;
    let options = TaskOptions {
        solver,
        max_iterations,
    };
    let res = solve_watched(py, sys, &task, &m, &options, progress)?;
    solution_dict(py, &task, &m, &res)
}

/// The summary of `tree-mech optimize --json` and the trajectory and gains as arrays.
fn solution_dict<'py>(
    py: Python<'py>,
    task: &Task,
    m: &model::Model,
    res: &TaskResult,
) -> PyResult<Bound<'py, PyDict>> {
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
            .map(|c| task.control_name(m, c).to_string())
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
    contact_items(py, task, res, &out)?;
    Ok(out)
}

/// Through contact: the task's relaxations, each iteration's, why a continuation stopped,
/// and the plan replayed at hard contact open loop and with its feedback (`None` without
/// contact).
fn contact_items(
    py: Python<'_>,
    task: &Task,
    res: &TaskResult,
    out: &Bound<'_, PyDict>,
) -> PyResult<()> {
    out.set_item("kappa", task.kappa.clone())?;
    let history = res.solution.history.iter().map(|h| h.kappa);
    out.set_item("kappa_history", history.collect::<Vec<_>>())?;
    out.set_item("continuation", res.continuation.clone())?;
    let replay = |r: &Option<HardReplay>| -> PyResult<Option<Bound<'_, PyDict>>> {
        let Some(r) = r else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("deviation", r.deviation)?;
        d.set_item("penetration", r.penetration)?;
        d.set_item("failure", r.failure.clone())?;
        d.set_item("q_end", vector(py, r.end.as_slice()))?;
        Ok(Some(d))
    };
    out.set_item("hard_replay", replay(&res.hard_replay)?)?;
    out.set_item("policy_replay", replay(&res.policy_replay)?)?;
    Ok(())
}

/// The task solved without the GIL: after every iteration Ctrl-C is checked and
/// `progress(iteration, cost)` called with the GIL taken back; an exception from either ends
/// the solve and is raised.
fn solve_watched(
    py: Python<'_>,
    sys: TreeSystem,
    task: &Task,
    m: &model::Model,
    options: &TaskOptions,
    progress: Option<Py<PyAny>>,
) -> PyResult<TaskResult> {
    let mut raised: Option<PyErr> = None;
    let res = py.detach(|| {
        let mut iteration = 0usize;
        solve_task_until(sys, task, m, options, &mut |it| {
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
    res.map_err(|e| sim_error(py, &e))
}
