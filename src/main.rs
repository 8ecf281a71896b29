//! The `tree-mech` command line: simulate a model, evaluate it at a state, check it.

mod animate;
mod linearize;
mod optimize;
mod output;
mod plot;

use std::path::{Path, PathBuf};

use output::OutputFile;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use tree_mech::integrate::{
    run_with_inputs, Forcing, InputSchedule, JacobianUpdate, Method, SimOptions, Tolerance,
    ViSettings,
};
use tree_mech::model::{self, Given, Rounded};
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::evaluation::evaluate_state;
use tree_mech::runtime::kinematics::{Kinematics, Reference};
use tree_mech::runtime::{Baumgarte, CsvStream, ModelMotions, Prescription, Seconds, Vector};
use tree_mech::{NoForce, PaperEvaluation, PaperSystem, SimError, System, Trajectory, TreeSystem};

#[derive(Parser)]
#[command(
    name = "tree-mech",
    version,
    about = "Simulate mechanical systems described as trees of frames"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// URDF models: add a floating base (root_x root_y root_z root_yaw root_pitch root_roll:
    /// tx ty tz rz ry rx) between the world and the root link.
    #[arg(long, global = true)]
    floating_base: bool,
    /// Hold a variable still as a constant, at its q0 or at VALUE: `--lock NAME[=VALUE]`,
    /// repeated or comma-separated (as Pinocchio's reduced model locks joints).
    #[arg(
        long,
        global = true,
        value_name = "NAME[=VALUE]",
        value_delimiter = ','
    )]
    lock: Vec<String>,
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
enum ForcingArg {
    /// f⁻ = f⁺ = ½Δt F at the midpoint (second order).
    Split,
    /// f⁻ = Δt F, f⁺ = 0 (trep's; first order in the force).
    Left,
}

#[derive(Clone, Copy, ValueEnum)]
enum StepArg {
    /// The midpoint variational integrator.
    Vi,
    /// Classical RK4.
    Rk4,
    /// One Dormand–Prince 5(4) step (rk45's) of length --dt.
    Rk45,
}

#[derive(Clone, Copy, ValueEnum)]
enum CameraArg {
    /// Fixed on the start's workspace.
    Fixed,
    /// Following the root at a fixed scale.
    Track,
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
        /// Model file (TOML, or URDF by its .urdf extension).
        model: PathBuf,
        #[arg(long, value_enum, default_value = "vi")]
        integrator: Integrator,
        /// Time step (the first step tried, for rk45).
        #[arg(long, default_value_t = 0.01)]
        dt: f64,
        /// Simulated time in seconds (at least one step).
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// CSV output, written while the run goes: `t,<var…>,d<var…>,energy`, then with
        /// constraints `lambda_<constraint…>,violation`.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Record every K-th step (the first and last are always recorded).
        #[arg(long, default_value_t = 1)]
        every: usize,
        /// VI forcing: split (second order) or left (trep's, first order in the force).
        #[arg(long, value_enum, default_value = "split")]
        forcing: ForcingArg,
        /// VI: fail at once when Newton fails instead of retrying the step in halves.
        #[arg(long)]
        no_subdivide: bool,
        /// Baumgarte stabilisation of the constraints for rk4/rk45: `a,b` in ḧ + 2aḣ + b²h = 0.
        #[arg(long, allow_hyphen_values = true)]
        baumgarte: Option<String>,
        /// PNG plot: the variables by kind (angles, lengths, prescribed), the energy and, with
        /// constraints, their forces.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// GIF animation of the figure in perspective, 640×480, up to 25 frames per simulated
        /// second (at most 500 frames), played in real time.
        #[arg(long)]
        animate: Option<PathBuf>,
        /// The animation's camera: fixed on the start's workspace, or tracking the root (a
        /// free body's torso) at the same scale.
        #[arg(long, value_enum, default_value = "fixed")]
        camera: CameraArg,
        /// VI quadrature point α (½ is second order).
        #[arg(long, default_value_t = 0.5)]
        alpha: f64,
        /// VI Newton tolerance: each residual row relative to its momentum scale.
        #[arg(long, default_value = "1e-12")]
        newton_tol: f64,
        /// VI Newton Jacobian: exact, evaluated and factored once per step at the predicted
        /// point and reused while the residual at least halves (a chord iteration), or
        /// re-evaluated every iteration (plain Newton). Both converge to the same tolerance.
        #[arg(long, value_enum, default_value = "once-per-step")]
        jacobian: JacobianArg,
        /// rk45 relative tolerance.
        #[arg(long, default_value = "1e-8")]
        rtol: f64,
        /// rk45 absolute tolerance.
        #[arg(long, default_value = "1e-10")]
        atol: f64,
        /// rk45: the most steps the run may take; it stops with an error once the step size
        /// it has reached would need more (a stiff model).
        #[arg(long, default_value_t = tree_mech::integrate::DEFAULT_MAX_ADAPTIVE_STEPS)]
        max_steps: usize,
        /// Constant inputs `u`, comma-separated in the model's input order.
        #[arg(long, allow_hyphen_values = true, conflicts_with = "inputs")]
        u: Option<String>,
        /// Inputs over time: a CSV with a column `t` and one per input (by name, or
        /// `u_<name>` as simulate's and optimize's CSVs name it: a plan replays), each row in
        /// force from its time to the next row's (held over every step that starts in it).
        #[arg(long)]
        inputs: Option<PathBuf>,
        /// Start configuration, comma-separated in variable order (default: the model's q0;
        /// kinematic entries follow their prescription; projected onto the constraints).
        #[arg(long, allow_hyphen_values = true)]
        q0: Option<String>,
        /// Start velocity, comma-separated in variable order (default: the model's dq0).
        #[arg(long, allow_hyphen_values = true)]
        dq0: Option<String>,
        /// How the interpreted system evaluates: composite sweeps (fastest), the paper's
        /// per-mass sums with caching, or without caching (the paper's Fig. 3 comparison).
        #[arg(long, value_enum, default_value = "sweeps")]
        evaluation: EvaluationArg,
    },
    /// Evaluate L, its derivatives, q̈ and every pose at a state; prints JSON.
    Eval {
        /// Model file (TOML, or URDF by its .urdf extension).
        model: PathBuf,
        /// Configuration, comma-separated, in variable order (default: the model's q0).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Velocity, comma-separated (default: the model's dq0).
        #[arg(long, allow_hyphen_values = true)]
        dq: Option<String>,
        /// Time at which the kinematic variables' accelerations are taken.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        t: f64,
        /// Inputs `u`, comma-separated in the model's input order (default: zero).
        #[arg(long, allow_hyphen_values = true)]
        u: Option<String>,
        /// A frame whose kinematics to add under `frames` (repeatable): its pose, Jacobian,
        /// twist and accelerations at this state, q̈ from the dynamics.
        #[arg(long = "frame", value_name = "NAME")]
        frames: Vec<String>,
    },
    /// Linearise the dynamics at a state (exact derivatives of q̈ and λ), and with --dt one
    /// midpoint-VI step as a map; prints JSON.
    #[command(allow_negative_numbers = true)]
    Linearize {
        /// Model file (TOML, or URDF by its .urdf extension).
        model: PathBuf,
        /// Configuration, comma-separated, in variable order (default: the model's q0; with
        /// neither --q nor --dq, the start projected onto the constraints as simulate takes
        /// it).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Velocity, comma-separated (default: the model's dq0, projected with q0).
        #[arg(long, allow_hyphen_values = true)]
        dq: Option<String>,
        /// Inputs, comma-separated in input order (default: zero).
        #[arg(long, allow_hyphen_values = true)]
        u: Option<String>,
        /// Time (the kinematic variables' prescription is taken at it).
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        t: f64,
        /// Also one VI step of this length from (t, q, p), and its derivatives.
        #[arg(long)]
        dt: Option<f64>,
        /// The VI step's starting momenta of the dynamic variables (default ∂L/∂q̇ at q, q̇).
        #[arg(long, allow_hyphen_values = true)]
        p: Option<String>,
        /// VI forcing: split (second order) or left (trep's).
        #[arg(long, value_enum, default_value = "split")]
        forcing: ForcingArg,
        /// VI quadrature point α.
        #[arg(long, default_value_t = 0.5)]
        alpha: f64,
        /// The step to linearise with --dt: the VI (state (q, p)), or RK4 or rk45's
        /// Dormand–Prince step (state (q, q̇)).
        #[arg(long, value_enum, default_value = "vi")]
        integrator: StepArg,
        /// With --dt (VI): also the step's 30 second derivatives, `q2_dq1dp1` … as
        /// [output][input1][input2].
        #[arg(long)]
        second_order: bool,
    },
    /// Solve an optimal-control task file (iLQR or DDP) and write the optimal trajectory.
    Optimize(optimize::Request),
    /// Validate a model and print a summary with the tree drawn as text.
    Check {
        /// Model file (TOML, or URDF by its .urdf extension).
        model: PathBuf,
    },
}

fn main() -> ExitCode {
    tree_mech::quiet_on_closed_stdout();
    let cli = Cli::parse();
    let source = Source {
        urdf: model::UrdfOptions {
            floating_base: cli.floating_base,
        },
        locks: cli.lock,
    };
    let result = match cli.command {
        Command::Simulate {
            model,
            integrator,
            dt,
            duration,
            out,
            every,
            forcing,
            no_subdivide,
            baumgarte,
            plot,
            animate,
            camera,
            alpha,
            newton_tol,
            jacobian,
            rtol,
            atol,
            max_steps,
            u,
            inputs,
            q0,
            dq0,
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
                    forcing: match forcing {
                        ForcingArg::Split => Forcing::Split,
                        ForcingArg::Left => Forcing::Left,
                    },
                    max_subdivisions: if no_subdivide {
                        0
                    } else {
                        ViSettings::default().max_subdivisions
                    },
                    ..ViSettings::default()
                }),
                Integrator::Rk4 => Method::Rk4,
                Integrator::Rk45 => Method::Rk45(Tolerance { rtol, atol }),
            };
            parse_baumgarte(baumgarte.as_deref()).and_then(|baumgarte| {
                let options = SimOptions {
                    every,
                    baumgarte,
                    max_steps,
                    ..SimOptions::new(method, dt, duration)
                };
                let mut outputs = Outputs::check(&model, &out, &plot, &animate)?;
                outputs.camera = match camera {
                    CameraArg::Fixed => animate::CameraMode::Fixed,
                    CameraArg::Track => animate::CameraMode::Track,
                };
                let model = source.model(&model)?;
                outputs.inputs = input_schedule(&model, u.as_deref(), inputs.as_deref())?;
                outputs.start = [q0, dq0];
                let paper = |mode| PaperSystem::new(&model, mode).map_err(|e| e.to_string());
                match evaluation {
                    EvaluationArg::Sweeps => {
                        let sys = TreeSystem::new(&model).map_err(|e| e.to_string())?;
                        run_simulate(sys, &model, options, outputs)
                    }
                    EvaluationArg::Cached => {
                        run_simulate(paper(PaperEvaluation::Cached)?, &model, options, outputs)
                    }
                    EvaluationArg::Uncached => {
                        run_simulate(paper(PaperEvaluation::Uncached)?, &model, options, outputs)
                    }
                }
            })
        }
        Command::Eval {
            model,
            q,
            dq,
            t,
            u,
            frames,
        } => run_eval(
            &model,
            &source,
            EvalState {
                q: q.as_deref(),
                dq: dq.as_deref(),
                u: u.as_deref(),
                t,
            },
            &frames,
        ),
        Command::Check { model } => run_check(&model, &source),
        Command::Optimize(request) => {
            if source.urdf.floating_base || !source.locks.is_empty() {
                Err("--floating-base and --lock do not apply to optimize: say `floating_base = true` in the task file, and lock joints in the model".into())
            } else {
                optimize::run(request)
            }
        }
        Command::Linearize {
            model,
            q,
            dq,
            u,
            t,
            dt,
            p,
            forcing,
            alpha,
            integrator,
            second_order,
        } => linearize::run(
            &model,
            &source,
            linearize::Request {
                q: q.as_deref(),
                dq: dq.as_deref(),
                u: u.as_deref(),
                p: p.as_deref(),
                t,
                dt,
                forcing: match forcing {
                    ForcingArg::Split => Forcing::Split,
                    ForcingArg::Left => Forcing::Left,
                },
                alpha,
                explicit: match integrator {
                    StepArg::Vi => None,
                    StepArg::Rk4 => Some(tree_mech::runtime::report::Explicit::Rk4),
                    StepArg::Rk45 => Some(tree_mech::runtime::report::Explicit::Rk45),
                },
                second_order,
            },
        ),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// How every command reads its model: the URDF options and the variables to lock.
struct Source {
    urdf: model::UrdfOptions,
    locks: Vec<String>,
}

impl Source {
    /// The model at `path`, with the locked variables held.
    fn model(&self, path: &Path) -> Result<model::Model, String> {
        let model = model::from_file(path, self.urdf).map_err(|e| e.to_string())?;
        if self.locks.is_empty() {
            return Ok(model);
        }
        let locks = self
            .locks
            .iter()
            .map(|l| model::Lock::parse(l))
            .collect::<Result<Vec<_>, _>>()?;
        model.locked(&locks).map_err(|e| e.to_string())
    }

    fn system(&self, path: &Path) -> Result<TreeSystem, String> {
        TreeSystem::new(&self.model(path)?).map_err(|e| e.to_string())
    }
}

/// `a,b` for Baumgarte stabilisation.
fn parse_baumgarte(text: Option<&str>) -> Result<Baumgarte, String> {
    let Some(text) = text else {
        return Ok(Baumgarte::default());
    };
    let v: Vec<f64> = text
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x >= 0.0)
        })
        .collect::<Option<_>>()
        .ok_or_else(|| format!("--baumgarte: `{text}` is not two non-negative numbers a,b"))?;
    match v[..] {
        [a, b] => Ok(Baumgarte { a, b }),
        _ => Err(format!("--baumgarte: `{text}` is not two numbers a,b")),
    }
}

/// `1 frame`, `2 frames`, `1 mass`, `3 masses`.
fn counted(n: usize, noun: &str) -> String {
    match (n, noun.ends_with('s')) {
        (1, _) => format!("1 {noun}"),
        (_, true) => format!("{n} {noun}es"),
        (_, false) => format!("{n} {noun}s"),
    }
}

/// A number for the summary: plain when moderate, scientific when huge or tiny.
fn num(x: f64) -> String {
    if x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
        format!("{x:.9}")
    } else {
        format!("{x:.6e}")
    }
}

/// Most samples kept in memory for the picture (the CSV gets every recorded step).
const PLOT_SAMPLES: usize = 20_000;

/// Where `simulate` writes what it produces.
struct Outputs {
    csv: Option<OutputFile>,
    plot: Option<OutputFile>,
    animate: Option<OutputFile>,
    /// The animation's camera.
    camera: animate::CameraMode,
    /// The inputs over the run.
    inputs: InputSchedule,
    /// `--q0`, `--dq0` as given (None: the model's).
    start: [Option<String>; 2],
}

impl Outputs {
    /// Every output checked before the run: its directory and extension, and that no two
    /// paths (the model's included) are one file.
    fn check(
        model: &Path,
        csv: &Option<PathBuf>,
        plot: &Option<PathBuf>,
        animate: &Option<PathBuf>,
    ) -> Result<Self, String> {
        let mut taken: Vec<&Path> = vec![model];
        let mut files = [None, None, None];
        for (k, (path, what, ext)) in [
            (csv, "out", None),
            (plot, "plot", Some("png")),
            (animate, "animate", Some("gif")),
        ]
        .into_iter()
        .enumerate()
        {
            if let Some(p) = path {
                files[k] = Some(OutputFile::new(p, what, ext, &taken)?);
                taken.push(p);
            }
        }
        let [csv, plot, animate] = files;
        Ok(Outputs {
            csv,
            plot,
            animate,
            camera: animate::CameraMode::default(),
            inputs: InputSchedule::default(),
            start: [None, None],
        })
    }
}

/// The largest CSV written without a note first, in bytes.
const LARGE_OUTPUT: f64 = 1e9;

fn run_simulate<S: System<N = Dyn>>(
    mut sys: S,
    model: &model::Model,
    options: SimOptions,
    outputs: Outputs,
) -> Result<(), String> {
    let name = model.name.as_str();
    let Outputs {
        csv: out,
        plot: plot_path,
        animate: animate_path,
        camera,
        inputs,
        start: [q0_given, dq0_given],
    } = outputs;
    let (mut q0, mut dq0) = sys.initial_state();
    let names: Vec<String> = (0..sys.dof())
        .map(|i| sys.variable_name(i).to_string())
        .collect();
    if let Some(text) = &q0_given {
        q0 = parse_vector(text, sys.dof(), "q0", &names)?;
    }
    if let Some(text) = &dq0_given {
        dq0 = parse_vector(text, sys.dof(), "dq0", &names)?;
    }
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% t = {msg} s  ({elapsed})")
            .map_err(|e| e.to_string())?,
    );
    let duration = options.duration.max(f64::MIN_POSITIVE);
    let start = Instant::now();
    let mut last_tick = 0;
    let constraints: Vec<String> = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let input_names: Vec<String> = sys.input_names();
    let mut csv = match &out {
        Some(file) => {
            let shown = file.path().display();
            let f = std::fs::File::create(file.temp())
                .map_err(|e| format!("cannot write `{shown}`: {e}"))?;
            Some(
                CsvStream::with_inputs(
                    std::io::BufWriter::new(f),
                    &names,
                    &constraints,
                    &input_names,
                )
                .map_err(|e| format!("cannot write `{shown}`: {e}"))?,
            )
        }
        None => None,
    };
    if let Some(file) = &out {
        // Said up front: a fixed-step run's rows are known (an adaptive one's are bounded by
        // its step budget).
        let rows = match options.method {
            Method::Rk45(_) => options.max_steps as f64,
            _ => options.duration / options.dt / options.every as f64,
        };
        let columns =
            2 + 2 * names.len() + constraints.len() + usize::from(!constraints.is_empty());
        let bytes = rows * columns as f64 * 20.0;
        if bytes > LARGE_OUTPUT {
            eprintln!(
                "note: `{}` may grow to about {:.1} GB ({:.2e} rows of {columns} numbers); --every K records every K-th step",
                file.path().display(),
                bytes / 1e9,
                rows
            );
        }
    }
    // The picture keeps at most PLOT_SAMPLES samples: every `thin`-th recorded one.
    let recorded = (options.duration / options.dt / options.every as f64).max(1.0);
    let thin = (recorded / PLOT_SAMPLES as f64).ceil().max(1.0) as usize;
    let mut picture = Trajectory::new(names.clone(), constraints.clone(), 0);
    let (mut e0, mut e_end, mut t_end, mut k) = (f64::NAN, f64::NAN, 0.0, 0usize);
    let mut motion = ModelMotions::of(&sys);
    // The animation keeps the configuration at every 1/FPS s of simulated time (fewer for
    // long runs); poses are computed after the run.
    let frame_interval = (1.0 / animate::FPS).max(options.duration / animate::MAX_FRAMES as f64);
    let (mut frame_times, mut frame_q) = (Vec::new(), Vec::new());
    let summary = run_with_inputs(
        &mut sys,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut motion,
        &inputs,
        &mut |sample| {
            if let Some(csv) = csv.as_mut() {
                csv.write(sample).map_err(|e| {
                    SimError::InvalidInput(format!("cannot write the trajectory: {e}"))
                })?;
            }
            if plot_path.is_some() && k.is_multiple_of(thin) {
                picture.push(sample);
            }
            let next_frame = frame_times.len() as f64 * frame_interval;
            if animate_path.is_some() && sample.t >= next_frame - 1e-9 * frame_interval {
                frame_times.push(sample.t);
                frame_q.push(sample.q.to_vec());
            }
            k += 1;
            if e0.is_nan() {
                e0 = sample.energy;
            }
            (e_end, t_end) = (sample.energy, sample.t);
            // Show the bar only for runs long enough to watch.
            if start.elapsed().as_millis() > 300 {
                let tick = (1000.0 * sample.t / duration) as u64;
                if tick != last_tick {
                    last_tick = tick;
                    bar.set_position(tick);
                    bar.set_message(format!("{:.3}", sample.t));
                }
            }
            Ok(())
        },
    )
    .map_err(|e| e.to_string())?;
    bar.finish_and_clear();
    let wall = start.elapsed();
    if let Some(csv) = csv {
        csv.finish()
            .map_err(|e| format!("cannot write the trajectory: {e}"))?;
    }
    if let Some(p) = &plot_path {
        plot::plot(&picture, model, p)?;
    }
    if let Some(path) = &animate_path {
        let mut poses = Vec::with_capacity(frame_q.len());
        for q in &frame_q {
            let mut frame = vec![tree_mech::runtime::Pose::IDENTITY; sys.frame_count()];
            sys.poses(&Vector::<Dyn>::from_column_slice(q), &mut frame);
            poses.push(frame);
        }
        let bar = ProgressBar::new(poses.len() as u64);
        bar.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} GIF frames  ({elapsed})")
                .map_err(|e| e.to_string())?,
        );
        let encoding = Instant::now();
        animate::write_gif(model, &frame_times, &poses, path, camera, &mut |k, _| {
            if encoding.elapsed().as_millis() > 300 {
                bar.set_position(k as u64);
            }
        })?;
        bar.finish_and_clear();
    }
    for m in &summary.moved {
        println!(
            "Initial {} of `{}` moved from {} to {} to satisfy the constraints.",
            if m.velocity { "velocity" } else { "value" },
            m.variable,
            m.from,
            m.to
        );
    }
    let method = match options.method {
        Method::Vi(s) => format!("the midpoint variational integrator (α = {})", s.alpha),
        Method::Rk4 => "RK4".into(),
        Method::Rk45(_) => "adaptive Dormand–Prince 5(4)".into(),
    };
    let newton = if summary.newton_iterations > 0 {
        format!(
            ", {:.2} Newton iterations per step",
            summary.newton_iterations as f64 / summary.steps.max(1) as f64
        )
    } else {
        String::new()
    };
    let subdivided = if summary.subdivided_steps > 0 {
        format!(
            " {} steps needed subdividing (at full length Newton failed or a joint turned more than a quarter turn).",
            summary.subdivided_steps
        )
    } else {
        String::new()
    };
    let constrained = if constraints.is_empty() {
        String::new()
    } else {
        format!(
            " Worst constraint violation {:.3e}.",
            summary.worst_violation
        )
    };
    let kinematic = (0..sys.dof()).any(|i| sys.is_kinematic(i));
    let dissipated = summary.dissipated;
    let balance = e_end - e0 + dissipated;
    let energy = match (kinematic, dissipated != 0.0) {
        (false, false) => format!("drift {balance:+.3e} J"),
        (false, true) => format!(
            "damping took out {} J, so ΔE + dissipated = {balance:+.3e} J is the integrator's error",
            num(dissipated)
        ),
        (true, false) => format!(
            "not conserved: kinematic inputs did {} J of work",
            num(balance)
        ),
        (true, true) => format!(
            "damping took out {} J; kinematic inputs did ΔE + dissipated = {} J of work",
            num(dissipated),
            num(balance)
        ),
    };
    let variables = if sys.dof() == 1 {
        "variable"
    } else {
        "variables"
    };
    println!(
        "Simulated `{name}` ({} {variables}) for {} s with {method}: {} steps in {:.3} s of wall time{newton}.{subdivided} \
         Energy went from {} to {} J ({energy}).{constrained}{}{}{}",
        sys.dof(),
        Seconds(t_end),
        summary.steps,
        wall.as_secs_f64(),
        num(e0),
        num(e_end),
        shown(&out, "Trajectory"),
        shown(&plot_path, "Plot"),
        shown(&animate_path, "Animation"),
    );
    // Every output complete: now they take their names.
    for file in [out, plot_path, animate_path].into_iter().flatten() {
        file.commit()?;
    }
    Ok(())
}

/// The inputs of a run: none, constant (`--u`), or from a CSV file (`--inputs`) with a column
/// `t` and one per input by name.
fn input_schedule(
    model: &model::Model,
    u: Option<&str>,
    file: Option<&Path>,
) -> Result<InputSchedule, String> {
    let names: Vec<String> = model.inputs.iter().map(|u| u.name.clone()).collect();
    if (u.is_some() || file.is_some()) && names.is_empty() {
        return Err(format!(
            "model `{}` has no inputs: declare [[input]] entries (or use a URDF robot's joints)",
            model.name
        ));
    }
    if let Some(text) = u {
        let values = parse_list(text, names.len(), "u", &names, "inputs")?;
        return Ok(InputSchedule::constant(values));
    }
    let Some(path) = file else {
        return Ok(InputSchedule::default());
    };
    let shown = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read `{shown}`: {e}"))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(format!(
            "`{shown}` is empty: expected a header `t,{}`",
            names.join(",")
        ));
    };
    let header: Vec<&str> = header
        .split(',')
        .map(|h| h.trim().trim_matches('"'))
        .collect();
    let column = |name: &str| header.iter().position(|h| *h == name);
    let t_column = column("t").ok_or_else(|| format!("`{shown}`:1: no column `t`"))?;
    let columns: Vec<usize> = names
        .iter()
        // `u_<name>` is how simulate's and optimize's CSVs name it (beside a variable that may
        // bear the input's own name, a joint's): where it is there, it is the input.
        .map(|n| {
            column(&format!("u_{n}"))
                .or_else(|| column(n))
                .ok_or_else(|| format!("`{shown}`:1: no column for input `{n}` (or `u_{n}`)"))
        })
        .collect::<Result<_, _>>()?;
    let mut rows: Vec<(f64, Vec<f64>)> = Vec::new();
    for (i, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != header.len() {
            return Err(format!(
                "`{shown}`:{}: {} fields where the header has {}",
                i + 1,
                fields.len(),
                header.len()
            ));
        }
        let number = |c: usize| -> Result<f64, String> {
            fields
                .get(c)
                .and_then(|f| f.parse::<f64>().ok())
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    format!(
                        "`{shown}`:{}: column {} is not a finite number",
                        i + 1,
                        c + 1
                    )
                })
        };
        let t = number(t_column)?;
        if let Some(&(before, _)) = rows.last() {
            if t <= before {
                return Err(format!(
                    "`{shown}`:{}: time {t} must be later than the row before ({before})",
                    i + 1
                ));
            }
        }
        let u = columns
            .iter()
            .map(|&c| number(c))
            .collect::<Result<Vec<_>, _>>()?;
        rows.push((t, u));
    }
    if rows.is_empty() {
        return Err(format!("`{shown}` has a header but no rows"));
    }
    InputSchedule::from_rows(rows).map_err(|e| format!("`{shown}`: {e}"))
}

/// ` Label: path.` for the summary.
fn shown(file: &Option<OutputFile>, label: &str) -> String {
    file.as_ref()
        .map(|f| format!(" {label}: {}.", f.path().display()))
        .unwrap_or_default()
}

/// Parses a comma-separated vector of exactly `n` numbers.
fn parse_vector(text: &str, n: usize, what: &str, names: &[String]) -> Result<Vector<Dyn>, String> {
    parse_list(text, n, what, names, "variables").map(Vector::<Dyn>::from_vec)
}

/// Parses a comma-separated list of exactly `n` finite numbers for option `--{what}`, one per
/// entry of `names` (the model's `kind`).
fn parse_list(
    text: &str,
    n: usize,
    what: &str,
    names: &[String],
    kind: &str,
) -> Result<Vec<f64>, String> {
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
            "--{what} has {} values; the model has {n} {kind} ({})",
            values.len(),
            names.join(", ")
        ));
    }
    Ok(values)
}

/// The state `eval` is asked about, as given on the command line.
struct EvalState<'a> {
    q: Option<&'a str>,
    dq: Option<&'a str>,
    u: Option<&'a str>,
    t: f64,
}

fn run_eval(
    path: &Path,
    source: &Source,
    state: EvalState<'_>,
    frames: &[String],
) -> Result<(), String> {
    let EvalState { q, dq, u, t: time } = state;
    let mut sys = source.system(path)?;
    let n = sys.dof();
    let names: Vec<String> = (0..n).map(|i| sys.variable_name(i).to_string()).collect();
    let (q0, dq0) = sys.initial_state();
    let q = q.map_or(Ok(q0), |s| parse_vector(s, n, "q", &names))?;
    let dq = dq.map_or(Ok(dq0), |s| parse_vector(s, n, "dq", &names))?;
    if !time.is_finite() {
        return Err(format!("--t: `{time}` is not a finite time"));
    }
    let input_names: Vec<String> = sys.input_names();
    let u = match u {
        Some(text) => parse_list(text, input_names.len(), "u", &input_names, "inputs")?,
        None => vec![0.0; sys.input_count()],
    };
    let e = evaluate_state(&mut sys, time, &q, &dq, &u).map_err(|e| e.to_string())?;
    let (t, c) = (&e.terms, &e.constraints);
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let rows = sys.constraint_count();
    let mut motion = ModelMotions::of(&sys);
    let name_list =
        |list: &[usize]| -> Vec<String> { list.iter().map(|&i| names[i].clone()).collect() };
    let constraint_names: Vec<String> = (0..rows)
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let dh: Vec<Vec<f64>> = (0..rows)
        .map(|r| (0..n).map(|i| c.dh[(r, i)]).collect())
        .collect();
    let kinematic_motion: serde_json::Map<String, serde_json::Value> = kinematic
        .iter()
        .map(|&i| (names[i].clone(), json!(motion.kinematic(i, time))))
        .collect();
    let matrix = |m: &tree_mech::runtime::Matrix<Dyn>| -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| (0..n).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let poses: serde_json::Map<String, serde_json::Value> = e
        .poses
        .iter()
        .enumerate()
        .map(|(k, p)| (sys.frame_name(k).to_string(), json!(p.matrix())))
        .collect();
    // The frames' kinematics at the state, q̈ from the dynamics (kinematic variables'
    // from their prescription), in world axes at each frame's origin.
    let mut kinematics = Kinematics::new(sys.model()).map_err(|e| e.to_string())?;
    kinematics
        .update(q.as_slice(), Some(dq.as_slice()), Some(e.qdd.as_slice()))
        .map_err(|e| e.to_string())?;
    let mut frame_entries = serde_json::Map::new();
    for name in frames {
        let f = kinematics
            .frame(name)
            .map_err(|e| format!("--frame: {e}"))?;
        let jacobian = kinematics.jacobian(f, Reference::LocalWorldAligned);
        frame_entries.insert(
            name.clone(),
            json!({
                "pose": kinematics.pose(f).matrix(),
                "jacobian": (0..6)
                    .map(|r| (0..n).map(|c| jacobian[(r, c)]).collect::<Vec<_>>())
                    .collect::<Vec<_>>(),
                "velocity": kinematics.velocity(f, Reference::LocalWorldAligned),
                "acceleration": kinematics.acceleration(f, Reference::LocalWorldAligned),
                "classical_acceleration": kinematics.classical_acceleration(f),
            }),
        );
    }
    let com = kinematics.center_of_mass();
    let out = json!({
        "variables": names,
        "q": q.as_slice(),
        "dq": dq.as_slice(),
        "L": t.l,
        "energy": e.energy,
        "dL_dq": t.dl_dq.as_slice(),
        "dL_ddq": t.dl_ddq.as_slice(),
        "M": matrix(&t.mass),
        "d2L_ddqdq": matrix(&t.d2l_ddq_dq),
        "d2L_dqdq": matrix(&t.d2l_dq_dq),
        "dynamic": name_list(&dynamic),
        "kinematic": name_list(&kinematic),
        "kinematic_motion": kinematic_motion,
        "qdd": dynamic.iter().map(|&i| e.qdd[i]).collect::<Vec<_>>(),
        "constraints": constraint_names,
        "h": c.h.as_slice(),
        "dh_dq": dh,
        "lambda": e.lambda.as_slice(),
        "inputs": input_names,
        "u": u,
        "poses": poses,
        "center_of_mass": {
            "mass": com.mass,
            "com": com.position,
            "vcom": com.velocity,
            "acom": com.acceleration,
        },
        "frames": frame_entries,
    });
    println!(
        "{}",
        serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
    );
    Ok(())
}

fn run_check(path: &Path, source: &Source) -> Result<(), String> {
    let model = source.model(path)?;
    let sys = TreeSystem::new(&model).map_err(|e| e.to_string())?;
    println!("model `{}`: valid", model.name);
    if !source.locks.is_empty() {
        println!("locked (held as constants): {}", source.locks.join(", "));
    }
    println!(
        "gravity: [{}, {}, {}]",
        Given(model.gravity[0]),
        Given(model.gravity[1]),
        Given(model.gravity[2])
    );
    println!(
        "{}, {}:",
        counted(model.frames.len(), "frame"),
        counted(sys.dof(), "variable")
    );
    for v in &model.variables {
        let drives = match v.frame {
            Some(f) => format!(
                "drives `{}` by {}",
                model.frames[f].name, model.frames[f].primitive
            ),
            None => "sets a constraint length".to_string(),
        };
        let how = match &v.motion {
            None => format!("dynamic, damping = {}", Given(v.damping)),
            Some(model::Motion::Steady { q0, dq0 }) => {
                format!(
                    "kinematic, held at q0 = {} moving at {}",
                    Given(*q0),
                    Given(*dq0)
                )
            }
            Some(model::Motion::Sine {
                offset,
                amplitude,
                frequency,
                phase,
            }) => format!(
                "kinematic, {} + {}·sin(2π·{}·t + {})",
                Given(*offset),
                Given(*amplitude),
                Given(*frequency),
                Given(*phase)
            ),
            Some(model::Motion::Spline(s)) => {
                let (a, b) = s.span();
                format!(
                    "kinematic, spline through samples on [{}, {}] s",
                    Given(a),
                    Given(b)
                )
            }
        };
        let limits = v
            .limits
            .map(|[lo, hi]| format!("; limits [{}, {}] (not enforced)", Given(lo), Given(hi)))
            .unwrap_or_default();
        println!(
            "  {:<20} {drives}; q0 = {}, dq0 = {}; {how}{limits}",
            v.name,
            Given(v.q0),
            Given(v.dq0)
        );
    }
    if !model.constraints.is_empty() {
        println!("{}:", counted(model.constraints.len(), "constraint"));
        for c in &model.constraints {
            let [a, b] = c.frames.map(|f| model.frames[f].name.as_str());
            let what = match &c.kind {
                model::ConstraintKind::Distance { length } => match length {
                    model::Parameter::Constant(l) => format!("distance {}", Given(*l)),
                    model::Parameter::Variable(i) => {
                        format!("distance `{}`", model.variables[*i].name)
                    }
                },
                model::ConstraintKind::Plane { normal } => {
                    format!("plane, normal {normal:?} in `{a}`")
                }
                model::ConstraintKind::Point { axes } => format!(
                    "point, axes {}",
                    axes.iter().map(|&k| ["x", "y", "z"][k]).collect::<String>()
                ),
            };
            println!("  {:<20} {what} between `{a}` and `{b}`", c.name);
        }
    }
    if !model.inputs.is_empty() {
        println!(
            "{} (generalized forces u):",
            counted(model.inputs.len(), "input")
        );
        for u in &model.inputs {
            let limits = u
                .limits
                .map(|[lo, hi]| format!("; limits [{}, {}] (not enforced)", Given(lo), Given(hi)))
                .unwrap_or_default();
            println!(
                "  {:<20} on `{}`{limits}",
                u.name, model.variables[u.variable].name
            );
        }
    }
    for s in &model.springs {
        match s.kind {
            model::SpringKind::Frames([a, b]) => println!(
                "spring between `{}` and `{}`: k = {}, rest = {}",
                model.frames[a].name,
                model.frames[b].name,
                Given(s.stiffness),
                Given(s.rest)
            ),
            model::SpringKind::Variable(i) => println!(
                "spring on `{}`: k = {}, rest = {}",
                model.variables[i].name,
                Given(s.stiffness),
                Given(s.rest)
            ),
        }
    }
    for d in &model.dampers {
        println!(
            "damper between `{}` and `{}`: c = {}",
            model.frames[d.frames[0]].name,
            model.frames[d.frames[1]].name,
            Given(d.damping)
        );
    }
    let masses: Vec<_> = model.frames.iter().filter(|f| f.mass.is_some()).collect();
    println!(
        "{}, total mass {} kg:",
        counted(masses.len(), "mass"),
        Rounded(model.total_mass(), 12)
    );
    for f in masses {
        let m = f.mass.unwrap();
        println!("  {:<20} {}", f.name, m.describe());
    }
    println!("tree:\n{}", model.tree_text().trim_end());
    Ok(())
}
