//! `tree-mech optimize TASK.toml`: solve a task file's optimal-control problem with iLQR or
//! DDP, print each iteration and a summary, and write the optimal trajectory (CSV), a plot,
//! an animation, a JSON summary and the feedback gains.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use serde_json::json;
use tree_mech::control::{
    solve_task_until, BoxPhase, Control, Iteration, Solver, Stop, TaskOptions, TaskResult,
    TaskSolver, MAX_MU,
};
use tree_mech::model::{self, CostTerm, Model, Target, Task};
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::{CsvStream, Sample};
use tree_mech::runtime::{Pose, Seconds, Vector};
use tree_mech::{System, Terms, Trajectory, TreeSystem};

use super::animate;
use super::interrupt;
use super::output::OutputFile;
use super::plot::{plot_with, Panel};

/// What `optimize` was asked for: its command-line arguments.
#[derive(clap::Args)]
pub struct Request {
    /// Task file (TOML; its `model` is read relative to it).
    task: PathBuf,
    /// CSV of the optimal trajectory: t, q, q̇, energy, the controls (`u_<name>`), λ and
    /// the violation.
    #[arg(long)]
    out: Option<PathBuf>,
    /// PNG: the variables, the controls and the cost per iteration.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// GIF of the optimal motion (a picture every 1/25 s, as simulate's).
    #[arg(long)]
    animate: Option<PathBuf>,
    /// JSON summary: converged, iterations, cost, q_final, dq_final, frames,
    /// solve_seconds.
    #[arg(long)]
    json: Option<PathBuf>,
    /// JSON of the feedback gains and feed-forward terms per knot.
    #[arg(long)]
    gains: Option<PathBuf>,
    /// Iteration limit (default: the task's, else 100).
    #[arg(long)]
    max_iterations: Option<usize>,
    /// Solver (default: the task's, else ilqr).
    #[arg(long, value_enum)]
    solver: Option<SolverArg>,
    /// Print the summary only, not each iteration.
    #[arg(long)]
    quiet: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SolverArg {
    /// Iterative LQR (Gauss–Newton on the dynamics).
    Ilqr,
    /// Differential dynamic programming (the VI's second derivatives).
    Ddp,
}

/// Every output checked before the solve (directory, extension, no two the same, none the
/// task or its model).
struct Files {
    out: Option<OutputFile>,
    plot: Option<OutputFile>,
    animate: Option<OutputFile>,
    json: Option<OutputFile>,
    gains: Option<OutputFile>,
}

fn check_files(r: &Request, model_path: &Path) -> Result<Files, String> {
    let mut taken: Vec<&Path> = vec![&r.task, model_path];
    let mut files: [Option<OutputFile>; 5] = Default::default();
    for (k, (path, what, ext)) in [
        (&r.out, "out", None),
        (&r.plot, "plot", Some("png")),
        (&r.animate, "animate", Some("gif")),
        (&r.json, "json", Some("json")),
        (&r.gains, "gains", Some("json")),
    ]
    .into_iter()
    .enumerate()
    {
        if let Some(p) = path {
            files[k] = Some(OutputFile::new(p, what, ext, &taken)?);
            taken.push(p);
        }
    }
    let [out, plot, animate, json, gains] = files;
    Ok(Files {
        out,
        plot,
        animate,
        json,
        gains,
    })
}

pub fn run(r: Request) -> Result<(), String> {
    if r.max_iterations == Some(0) {
        return Err("--max-iterations must be at least 1".into());
    }
    let (task, model) = model::read_task(&r.task).map_err(|e| e.to_string())?;
    let files = check_files(&r, &task.model_path)?;
    let sys = TreeSystem::new(&model).map_err(|e| e.to_string())?;
    let options = TaskOptions {
        solver: r.solver.map(|s| match s {
            SolverArg::Ilqr => TaskSolver::Ilqr,
            SolverArg::Ddp => TaskSolver::Ddp,
        }),
        max_iterations: r.max_iterations,
    };
    let (mut count, mut failed) = (0, None);
    let mut print = |it: &Iteration| {
        count += 1;
        if !r.quiet {
            if let Err(e) = print_iteration(count, it) {
                failed = Some(e);
                return ControlFlow::Break(());
            }
        }
        // Ctrl-C: the solve stops after this iteration and its best plan is written.
        match interrupt::requested() {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        }
    };
    // The step is the task file's `dt`, not a command-line option.
    let result = solve_task_until(sys, &task, &model, &options, &mut print)
        .map_err(|e| e.to_string().replace("--dt", "the task's `dt`"))?;
    if let Some(e) = failed {
        return Err(e);
    }
    write_outputs(&r.task, &task, &model, &result, files)
}

/// One line of the iteration table (the header with the first: a task refused while setting
/// up prints nothing on standard output).
fn print_iteration(count: usize, it: &Iteration) -> Result<(), String> {
    if count == 1 {
        say!(
            "{:>5}  {:>14}  {:>8}  {:>9}  {:>10}  {:>5}  {:>6}{}",
            "iter",
            "cost",
            "step",
            "μ",
            "max |k|",
            "model",
            "limits",
            if it.kappa > 0.0 { "        κ" } else { "" }
        );
    }
    // The backward pass's model (DDP's full one, or Gauss–Newton) and how it took the limits
    // (clamped in the forward pass, or the box QP).
    let model = match it.model {
        Solver::Ddp => "ddp",
        Solver::Ilqr => "gn",
    };
    let limits = match it.limits {
        None => "—",
        Some(BoxPhase::Clamped) => "clamp",
        Some(BoxPhase::Boxed) => "box",
    };
    // Through contact, the relaxation the iteration stepped at.
    let kappa = match it.kappa > 0.0 {
        true => format!("  {:>7.1e}", it.kappa),
        false => String::new(),
    };
    say!(
        "{count:>5}  {:>14.8e}  {:>8.4}  {:>9.1e}  {:>10.3e}  {model:>5}  {limits:>6}{kappa}",
        it.cost,
        it.step,
        it.mu,
        it.gradient
    );
    Ok(())
}

fn write_outputs(
    path: &Path,
    task: &Task,
    model: &Model,
    res: &TaskResult,
    files: Files,
) -> Result<(), String> {
    let mut sys = TreeSystem::new(model).map_err(|e| e.to_string())?;
    let plan = Knots::new(&mut sys, task, model, res);
    if let Some(file) = &files.out {
        write_csv(&plan, file)?;
    }
    if let Some(file) = &files.plot {
        write_plot(&plan, model, file)?;
    }
    if let Some(file) = &files.animate {
        write_animation(&mut sys, &plan, model, file)?;
    }
    let frames = final_frames(&plan, model);
    if let Some(file) = &files.json {
        write_summary_json(&plan, &frames, file)?;
    }
    if let Some(file) = &files.gains {
        write_gains(&plan, file)?;
    }
    // Every output complete: now they take their names, then the summary says so.
    for mut file in [
        files.out,
        files.plot,
        files.animate,
        files.json,
        files.gains,
    ]
    .into_iter()
    .flatten()
    {
        file.commit()?;
    }
    print_summary(path, &plan, &frames)
}

/// The solved plan knot by knot, with the names and energies every output writes.
struct Knots<'a> {
    task: &'a Task,
    res: &'a TaskResult,
    names: Vec<String>,
    constraints: Vec<String>,
    controls: Vec<String>,
    energy: Vec<f64>,
}

impl<'a> Knots<'a> {
    fn new(sys: &mut TreeSystem, task: &'a Task, model: &Model, res: &'a TaskResult) -> Self {
        let names: Vec<String> = model.variables.iter().map(|v| v.name.clone()).collect();
        let mut terms = Terms::zeros(Dyn(names.len()));
        let energy = (0..=task.knots)
            .map(|k| {
                let (q, dq) = (
                    Vector::<Dyn>::from_column_slice(res.q[k].as_slice()),
                    Vector::<Dyn>::from_column_slice(res.dq[k].as_slice()),
                );
                sys.energy(&q, &dq, &mut terms)
            })
            .collect();
        Knots {
            task,
            res,
            names,
            constraints: model.constraint_row_names(),
            controls: (0..task.controls.len())
                .map(|c| task.control_name(model, c).to_string())
                .collect(),
            energy,
        }
    }

    /// Knot `k` as a trajectory sample: its controls are those applied from it (the last
    /// knot repeats the last control).
    fn sample(&self, k: usize) -> Sample<'_> {
        let res = self.res;
        Sample {
            step: k,
            t: res.t[k],
            q: res.q[k].as_slice(),
            dq: res.dq[k].as_slice(),
            p: None,
            energy: self.energy[k],
            lambda: res.lambda[k].as_slice(),
            violation: res.violation[k],
            u: res.solution.u[k.min(self.task.knots - 1)].as_slice(),
            impulse: &[],
            gap: &[],
        }
    }
}

/// `--out`: every knot as a CSV row.
fn write_csv(plan: &Knots, file: &OutputFile) -> Result<(), String> {
    let shown = file.path().display();
    let cannot = |e: std::io::Error| format!("cannot write `{shown}`: {e}");
    let w = std::fs::File::create(file.temp()).map_err(cannot)?;
    let mut csv = CsvStream::with_inputs(
        std::io::BufWriter::new(w),
        &plan.names,
        &plan.constraints,
        &plan.controls,
    )
    .map_err(cannot)?;
    for k in 0..=plan.task.knots {
        csv.write(&plan.sample(k)).map_err(cannot)?;
    }
    csv.finish().map_err(cannot)
}

/// `--plot`: simulate's panels, then the controls and the cost per iteration.
fn write_plot(plan: &Knots, model: &Model, file: &OutputFile) -> Result<(), String> {
    let (res, n) = (plan.res, plan.task.knots);
    let sol = &res.solution;
    let mut traj = Trajectory::new(plan.names.clone(), plan.constraints.clone(), n + 1);
    for k in 0..=n {
        traj.push(&plan.sample(k));
    }
    // The inputs held over each knot, in their units; kinematic controls are the prescribed
    // variables' values, drawn in their panel already.
    let inputs = plan
        .task
        .controls
        .iter()
        .enumerate()
        .filter_map(|(c, control)| match control {
            Control::Input(j) => Some((c, model.inputs[*j].variable)),
            Control::Kinematic(_) => None,
        });
    let control_panel = Panel {
        caption: "inputs (held over each knot)".into(),
        y_desc: "u [N or N·m]",
        series: inputs
            .map(|(c, variable)| {
                let points = (0..n)
                    .flat_map(|k| [(res.t[k], sol.u[k][c]), (res.t[k + 1], sol.u[k][c])])
                    .collect();
                let unit = if model.is_angle(variable) {
                    "N·m"
                } else {
                    "N"
                };
                (format!("{} [{unit}]", plan.controls[c]), points)
            })
            .collect(),
        x: Some(("t [s]", res.t[n])),
    };
    let history = Panel {
        caption: "total cost per iteration".into(),
        y_desc: "log10 cost",
        series: vec![(
            "cost".into(),
            (sol.history.iter().enumerate())
                .map(|(i, it)| ((i + 1) as f64, it.cost.max(f64::MIN_POSITIVE).log10()))
                .collect(),
        )],
        x: Some(("iteration", sol.history.len().max(1) as f64)),
    };
    plot_with(&traj, model, file, vec![control_panel, history])
}

/// `--animate`: as simulate's, a picture every 1/FPS s (every knot when they are further
/// apart), at most MAX_FRAMES, the last knot always.
fn write_animation(
    sys: &mut TreeSystem,
    plan: &Knots,
    model: &Model,
    file: &OutputFile,
) -> Result<(), String> {
    let (res, n) = (plan.res, plan.task.knots);
    let interval = (1.0 / animate::FPS).max(res.t[n] / animate::MAX_FRAMES as f64);
    let every = ((interval / plan.task.dt).round() as usize).max(1);
    let mut knots: Vec<usize> = (0..=n).step_by(every).collect();
    if knots.last() != Some(&n) {
        knots.push(n);
    }
    let mut poses = Vec::with_capacity(knots.len());
    for &k in &knots {
        let mut frame = vec![Pose::IDENTITY; sys.frame_count()];
        let q = Vector::<Dyn>::from_column_slice(res.q[k].as_slice());
        sys.poses(&q, &mut frame);
        poses.push(frame);
    }
    let times: Vec<f64> = knots.iter().map(|&k| res.t[k]).collect();
    let fixed = animate::CameraMode::Fixed;
    let targets = frame_targets(plan.task, &poses[0]);
    animate::write_gif(
        model,
        &times,
        &poses,
        file,
        fixed,
        &animate::Overlay {
            targets: &targets,
            ..Default::default()
        },
        &mut |_, _| {},
    )
}

/// Where the task's frame terms aim, in the world (an offset target from its frame's start
/// pose `start`), each once.
fn frame_targets(task: &Task, start: &[Pose]) -> Vec<[f64; 3]> {
    let mut targets: Vec<[f64; 3]> = Vec::new();
    for term in task.running.iter().chain(&task.terminal) {
        if let CostTerm::Frame { frame, target, .. } = term {
            let p = match target {
                Target::World(p) => *p,
                Target::Offset(d) => std::array::from_fn(|i| start[*frame].p[i] + d[i]),
            };
            if !targets.contains(&p) {
                targets.push(p);
            }
        }
    }
    targets
}

/// Where every frame a cost term names ends.
fn final_frames(plan: &Knots, model: &Model) -> serde_json::Map<String, serde_json::Value> {
    let task = plan.task;
    let named: std::collections::BTreeSet<usize> = (task.running.iter())
        .chain(&task.terminal)
        .filter_map(|t| t.frame())
        .collect();
    let origins = model.origins(plan.res.q[task.knots].as_slice());
    named
        .iter()
        .map(|&f| (model.frames[f].name.clone(), json!(origins[f])))
        .collect()
}

/// `--json`: the solve's summary.
fn write_summary_json(
    plan: &Knots,
    frames: &serde_json::Map<String, serde_json::Value>,
    file: &OutputFile,
) -> Result<(), String> {
    let (res, n) = (plan.res, plan.task.knots);
    let sol = &res.solution;
    let summary = json!({
        "converged": sol.converged,
        "stopped": sol.stop.name(),
        "iterations": sol.history.len(),
        "cost": sol.cost,
        "q_final": res.q[n].as_slice(),
        "dq_final": res.dq[n].as_slice(),
        "variables": plan.names,
        "controls": plan.controls,
        "frames": frames,
        "solve_seconds": res.solve_seconds,
        "kappa": plan.task.kappa,
        "continuation": res.continuation,
        "hard_replay": res.hard_replay.as_ref().map(replay_json),
        "policy_replay": res.policy_replay.as_ref().map(replay_json),
    });
    write_text(file, &format!("{summary:#}\n"))
}

/// A replay at hard contact in `--json`.
fn replay_json(r: &tree_mech::control::HardReplay) -> serde_json::Value {
    json!({
        "deviation": r.deviation,
        "penetration": r.penetration,
        "failure": r.failure,
        "q_end": r.end.as_slice(),
    })
}

/// `--gains`: the plan and its feedback gains, knot by knot.
fn write_gains(plan: &Knots, file: &OutputFile) -> Result<(), String> {
    let sol = &plan.res.solution;
    let gains = json!({
        "note": "u = u_plan[k] + K[k] (x − x_plan[k]) near the plan; x = (q_d, p_d or q̇_d, the controls' memory: inputs' previous values only with a control_rate term, kinematic controls' value and velocity)",
        "controls": plan.controls,
        "u_plan": sol.u.iter().map(|u| u.as_slice().to_vec()).collect::<Vec<_>>(),
        "x_plan": sol.x.iter().map(|x| x.as_slice().to_vec()).collect::<Vec<_>>(),
        "K": sol.gains.iter().map(|g| (0..g.nrows()).map(|r| g.row(r).iter().copied().collect::<Vec<_>>()).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "feedforward": sol.feedforward.iter().map(|k| k.as_slice().to_vec()).collect::<Vec<_>>(),
    });
    write_text(file, &format!("{gains}\n"))
}

/// The solve's one-line summary, and why it stopped when it did not converge.
fn print_summary(
    path: &Path,
    plan: &Knots,
    frames: &serde_json::Map<String, serde_json::Value>,
) -> Result<(), String> {
    let (task, res) = (plan.task, plan.res);
    let sol = &res.solution;
    let place = frames
        .iter()
        .map(|(name, p)| format!(" `{name}` ends at {p}."))
        .collect::<String>();
    say!(
        "{} `{}` ({} knots of {} s, {}) in {} iterations, {:.3} s: cost {:.6e}.{place}",
        if sol.converged {
            "Solved"
        } else {
            "Did not converge on"
        },
        path.display(),
        task.knots,
        Seconds(task.dt),
        task.integrator.name().to_uppercase(),
        sol.history.len(),
        res.solve_seconds,
        sol.cost,
    );
    match sol.stop {
        Stop::Converged => {}
        Stop::IterationLimit => {
            say!("The best trajectory found is written; raise --max-iterations to go on.")
        }
        Stop::Regularisation => say!(
            "The solver stopped: its regularisation passed {:e} (relative to the controls' \
             curvature) before the local model gave a step that lowers the cost — the cost is \
             not smooth enough about this trajectory for its quadratic model. The best \
             trajectory found is written.",
            MAX_MU
        ),
        // Ctrl-C (or SIGTERM) during the solve.
        Stop::Interrupted => {
            say!("The solve was interrupted; the best trajectory found is written.")
        }
    }
    if let Some(replay) = &res.hard_replay {
        // The relaxations the solve went through (fewer than the task's when it stopped).
        let mut went: Vec<f64> = sol.history.iter().map(|it| it.kappa).collect();
        went.dedup();
        let kappas = (went.iter())
            .map(|k| format!("{k:e}"))
            .collect::<Vec<_>>()
            .join(" → ");
        say!(
            "Through contact at κ = {kappas} m·N·s; the plan replayed at hard contact (κ = 0) keeps within {:.3e} of it (largest variable difference), deepest penetration {:.2e} m.",
            replay.deviation,
            replay.penetration
        );
        if let Some(policy) = &res.policy_replay {
            say!(
                "Its policy (the plan's controls with their feedback gains) at hard contact keeps within {:.3e}, deepest penetration {:.2e} m{}.",
                policy.deviation,
                policy.penetration,
                policy.failure.as_ref().map_or(String::new(), |f| format!("; it stopped: {f}"))
            );
        }
        if let Some(why) = &res.continuation {
            say!("Not converged: {}.", why.replace("--dt", "the task's `dt`"));
        }
        if let Some(failure) = &replay.failure {
            say!("The replay at hard contact stopped: {failure}");
        }
    }
    Ok(())
}

fn write_text(file: &OutputFile, text: &str) -> Result<(), String> {
    std::fs::write(file.temp(), text)
        .map_err(|e| format!("cannot write `{}`: {e}", file.path().display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_offset_target_is_marked_from_its_frame_at_the_start() {
        // The UR5 reach aims `ee_link` 0.1 m along x and 0.2 m up from where it starts.
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tasks/ur5-reach.toml");
        let (task, model) = model::read_task(path).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let mut start = vec![Pose::IDENTITY; sys.frame_count()];
        sys.poses(&Vector::<Dyn>::from_column_slice(&task.q0), &mut start);
        let ee = start[model.frame_index("ee_link").unwrap()].p;
        let targets = frame_targets(&task, &start);
        assert_eq!(targets.len(), 1);
        let want = [ee[0] + 0.1, ee[1], ee[2] + 0.2];
        for i in 0..3 {
            assert!(
                (targets[0][i] - want[i]).abs() < 1e-15,
                "{targets:?} vs {want:?}"
            );
        }
    }
}
