//! The `tree-mech` command line: simulate a model, evaluate it at a state, check it.

mod plot;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use tree_mech::integrate::{simulate, JacobianUpdate, Method, SimOptions, Tolerance, ViSettings};
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::se3::Pose;
use tree_mech::runtime::{Dynamics, Vector};
use tree_mech::{tree_model, Evaluation, NoForce, Order, System, TreeSystem};

#[derive(Parser)]
#[command(
    name = "tree-mech",
    version,
    about = "Simulate mechanical systems described as trees of frames"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum Integrator {
    /// Midpoint variational integrator (energy-stable, momentum-conserving).
    Vi,
    /// Fixed-step fourth-order Runge–Kutta.
    Rk4,
    /// Adaptive Dormand–Prince 5(4).
    Rk45,
}

#[derive(Clone, Copy, ValueEnum)]
enum JacobianArg {
    EveryIteration,
    OncePerStep,
}

#[derive(Clone, Copy, ValueEnum)]
enum EvaluationArg {
    Sweeps,
    Cached,
    Uncached,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a model and write its trajectory (CSV) and a picture (PNG).
    #[command(allow_negative_numbers = true)]
    Simulate {
        /// Model file (TOML).
        model: PathBuf,
        #[arg(long, value_enum, default_value = "vi")]
        integrator: Integrator,
        /// Time step (the first step tried, for rk45).
        #[arg(long, default_value_t = 0.01)]
        dt: f64,
        /// Simulated time in seconds.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// CSV output: `t,<var…>,d<var…>,energy`.
        #[arg(long)]
        out: Option<PathBuf>,
        /// PNG plot of the variables and the energy.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// VI quadrature point α (½ is second order).
        #[arg(long, default_value_t = 0.5)]
        alpha: f64,
        /// VI Newton tolerance.
        #[arg(long, default_value_t = 1e-12)]
        newton_tol: f64,
        /// VI Newton Jacobian: re-evaluated every iteration (exact Newton) or once per step.
        #[arg(long, value_enum, default_value = "every-iteration")]
        jacobian: JacobianArg,
        /// rk45 relative tolerance.
        #[arg(long, default_value_t = 1e-8)]
        rtol: f64,
        /// rk45 absolute tolerance.
        #[arg(long, default_value_t = 1e-10)]
        atol: f64,
        /// How the interpreted system evaluates: composite sweeps (fastest), the paper's
        /// per-mass sums with caching, or without caching (the paper's Fig. 3 comparison).
        #[arg(long, value_enum, default_value = "sweeps")]
        evaluation: EvaluationArg,
    },
    /// Evaluate L, its derivatives, q̈ and every pose at a state; prints JSON.
    Eval {
        model: PathBuf,
        /// Configuration, comma-separated, in variable order (default: the model's q0).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Velocity, comma-separated (default: the model's dq0).
        #[arg(long, allow_hyphen_values = true)]
        dq: Option<String>,
    },
    /// Validate a model and print a summary with the tree drawn as text.
    Check { model: PathBuf },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate {
            model,
            integrator,
            dt,
            duration,
            out,
            plot,
            alpha,
            newton_tol,
            jacobian,
            rtol,
            atol,
            evaluation,
        } => {
            let method = match integrator {
                Integrator::Vi => Method::Vi(ViSettings {
                    alpha,
                    tolerance: newton_tol,
                    jacobian: match jacobian {
                        JacobianArg::EveryIteration => JacobianUpdate::EveryIteration,
                        JacobianArg::OncePerStep => JacobianUpdate::OncePerStep,
                    },
                    ..ViSettings::default()
                }),
                Integrator::Rk4 => Method::Rk4,
                Integrator::Rk45 => Method::Rk45(Tolerance { rtol, atol }),
            };
            let evaluation = match evaluation {
                EvaluationArg::Sweeps => Evaluation::Sweeps,
                EvaluationArg::Cached => Evaluation::Cached,
                EvaluationArg::Uncached => Evaluation::Uncached,
            };
            run_simulate(
                &model,
                SimOptions {
                    method,
                    dt,
                    duration,
                },
                evaluation,
                out.as_deref(),
                plot.as_deref(),
            )
        }
        Command::Eval { model, q, dq } => run_eval(&model, q.as_deref(), dq.as_deref()),
        Command::Check { model } => run_check(&model),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn load(path: &Path, evaluation: Evaluation) -> Result<TreeSystem, String> {
    let model = tree_model::from_toml_file(path).map_err(|e| e.to_string())?;
    TreeSystem::new(&model, evaluation).map_err(|e| e.to_string())
}

fn run_simulate(
    path: &Path,
    options: SimOptions,
    evaluation: Evaluation,
    out: Option<&Path>,
    plot_path: Option<&Path>,
) -> Result<(), String> {
    let mut sys = load(path, evaluation)?;
    let (q0, dq0) = sys.initial_state();
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% t = {msg} s  ({elapsed})")
            .map_err(|e| e.to_string())?,
    );
    let duration = options.duration.max(f64::MIN_POSITIVE);
    let start = Instant::now();
    let mut last_tick = 0;
    let mut progress = |t: f64| {
        // Show the bar only for runs long enough to watch.
        if start.elapsed().as_millis() > 300 {
            let tick = (1000.0 * t / duration) as u64;
            if tick != last_tick {
                last_tick = tick;
                bar.set_position(tick);
                bar.set_message(format!("{t:.3}"));
            }
        }
    };
    let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut progress)
        .map_err(|e| e.to_string())?;
    bar.finish_and_clear();
    let wall = start.elapsed();
    if let Some(out) = out {
        let file = std::fs::File::create(out)
            .map_err(|e| format!("cannot write `{}`: {e}", out.display()))?;
        traj.write_csv(std::io::BufWriter::new(file))
            .map_err(|e| format!("cannot write `{}`: {e}", out.display()))?;
    }
    if let Some(p) = plot_path {
        plot::plot(&traj, &sys.model().name, p)?;
    }
    let e0 = traj.energy[0];
    let e_end = *traj.energy.last().unwrap();
    let method = match options.method {
        Method::Vi(s) => format!("the midpoint variational integrator (α = {})", s.alpha),
        Method::Rk4 => "RK4".into(),
        Method::Rk45(_) => "adaptive Dormand–Prince 5(4)".into(),
    };
    let newton = if traj.newton_iterations > 0 {
        format!(
            ", {:.2} Newton iterations per step",
            traj.newton_iterations as f64 / (traj.len() - 1).max(1) as f64
        )
    } else {
        String::new()
    };
    println!(
        "Simulated `{}` ({} variables) for {} s with {method}: {} steps in {:.3} s of wall time{newton}. \
         Energy went from {e0:.9} to {e_end:.9} J (drift {:+.3e} J, largest deviation {:.3e} J).{}{}",
        sys.model().name,
        sys.dof(),
        traj.t.last().unwrap(),
        traj.len() - 1,
        wall.as_secs_f64(),
        e_end - e0,
        traj.max_energy_error(),
        out.map(|p| format!(" Trajectory: {}.", p.display())).unwrap_or_default(),
        plot_path.map(|p| format!(" Plot: {}.", p.display())).unwrap_or_default(),
    );
    Ok(())
}

/// Parses a comma-separated vector of exactly `n` numbers.
fn parse_vector(text: &str, n: usize, what: &str, names: &[String]) -> Result<Vector<Dyn>, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("--{what}: `{s}` is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    if values.len() != n {
        return Err(format!(
            "--{what} has {} values; the model has {n} variables ({})",
            values.len(),
            names.join(", ")
        ));
    }
    Ok(Vector::<Dyn>::from_vec(values))
}

fn run_eval(path: &Path, q: Option<&str>, dq: Option<&str>) -> Result<(), String> {
    let mut sys = load(path, Evaluation::Sweeps)?;
    let n = sys.dof();
    let names: Vec<String> = (0..n).map(|i| sys.variable_name(i).to_string()).collect();
    let (q0, dq0) = sys.initial_state();
    let q = q.map_or(Ok(q0), |s| parse_vector(s, n, "q", &names))?;
    let dq = dq.map_or(Ok(dq0), |s| parse_vector(s, n, "dq", &names))?;
    let t = sys.evaluate(&q, &dq, Order::Full);
    let mut qdd = Vector::<Dyn>::zeros(n);
    let qdd_json =
        match Dynamics::new(Dyn(n)).acceleration(&mut sys, &mut NoForce, 0, 0.0, &q, &dq, &mut qdd)
        {
            Ok(()) => json!(qdd.as_slice()),
            Err(e) => json!({ "error": e.to_string() }),
        };
    let matrix = |m: &tree_mech::runtime::Matrix<Dyn>| -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| (0..n).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
    sys.poses(&q, &mut poses);
    let poses: serde_json::Map<String, serde_json::Value> = poses
        .iter()
        .enumerate()
        .map(|(k, p)| (sys.frame_name(k).to_string(), json!(p.matrix())))
        .collect();
    let out = json!({
        "variables": names,
        "q": q.as_slice(),
        "dq": dq.as_slice(),
        "L": t.l,
        "energy": t.energy(&dq),
        "dL_dq": t.dl_dq.as_slice(),
        "dL_ddq": t.dl_ddq.as_slice(),
        "M": matrix(&t.mass),
        "d2L_ddqdq": matrix(&t.d2l_ddq_dq),
        "d2L_dqdq": matrix(&t.d2l_dq_dq),
        "qdd": qdd_json,
        "poses": poses,
    });
    println!(
        "{}",
        serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
    );
    Ok(())
}

fn run_check(path: &Path) -> Result<(), String> {
    let model = tree_model::from_toml_file(path).map_err(|e| e.to_string())?;
    let sys = TreeSystem::new(&model, Evaluation::Sweeps).map_err(|e| e.to_string())?;
    println!("model `{}`: valid", model.name);
    println!(
        "gravity: [{}, {}, {}]",
        model.gravity[0], model.gravity[1], model.gravity[2]
    );
    println!("{} frames, {} variables:", model.frames.len(), sys.dof());
    for v in &model.variables {
        println!(
            "  {:<20} drives `{}` by {}; q0 = {}, dq0 = {}, damping = {}",
            v.name,
            model.frames[v.frame].name,
            model.frames[v.frame].primitive,
            v.q0,
            v.dq0,
            v.damping
        );
    }
    let masses: Vec<_> = model.frames.iter().filter(|f| f.mass.is_some()).collect();
    println!(
        "{} masses, total mass {} kg:",
        masses.len(),
        model.total_mass()
    );
    for f in masses {
        let m = f.mass.unwrap();
        println!(
            "  {:<20} m = {}, I = ({}, {}, {})",
            f.name, m.mass, m.inertia[0], m.inertia[1], m.inertia[2]
        );
    }
    println!("tree:\n{}", model.tree_text().trim_end());
    Ok(())
}
