//! `tree-mech simulate`: a run of a model with the chosen integrator, written as it goes to
//! a CSV, then a plot and an animation.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};
use tree_mech::integrate::{
    run_with_inputs, InputSchedule, JacobianUpdate, Method, RunSummary, SimOptions, Tolerance,
    ViSettings,
};
use tree_mech::model::{self, Integrator};
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::{Baumgarte, CsvStream, ModelMotions, Sample, Seconds, Vector};
use tree_mech::{NoForce, PaperEvaluation, PaperSystem, SimError, System, Trajectory, TreeSystem};

use super::interrupt;
use super::output::OutputFile;
use super::{animate, forces, integrator_arg, parse_list, parse_vector, plot, ForcingArg, Source};

/// What `simulate` was asked for: its command-line arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Model file (TOML, or URDF by its .urdf extension).
    model: PathBuf,
    /// The integrator.
    #[arg(long, default_value = "vi", value_parser = integrator_arg())]
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
    /// With --animate: draw each contact's force as an arrow at its point (a ground
    /// contact's push and friction, two spheres' push, a slack string's pull), the run's
    /// largest a quarter of the view long.
    #[arg(long)]
    forces: bool,
    /// VI quadrature point α (½ is second order).
    #[arg(long, default_value_t = 0.5)]
    alpha: f64,
    /// VI Newton tolerance: each residual row relative to its momentum scale.
    #[arg(long, default_value = "1e-12")]
    newton_tol: f64,
    /// VI contact relaxation κ (gap × impulse, m·N·s): 0 drives each contact's
    /// complementarity to the tolerance (hard contact); κ > 0 holds it there (smooth).
    #[arg(long, default_value_t = 0.0)]
    kappa: f64,
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
}

#[derive(Clone, Copy, ValueEnum)]
enum JacobianArg {
    EveryIteration,
    OncePerStep,
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

/// Runs `simulate` with the model read as `source` says.
pub fn run(args: Args, source: &Source) -> Result<(), String> {
    let Args {
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
        forces,
        alpha,
        newton_tol,
        kappa,
        jacobian,
        rtol,
        atol,
        max_steps,
        u,
        inputs,
        q0,
        dq0,
        evaluation,
    } = args;
    let method = match integrator {
        Integrator::Vi => Method::Vi(ViSettings {
            alpha,
            tolerance: newton_tol,
            kappa,
            jacobian: match jacobian {
                JacobianArg::EveryIteration => JacobianUpdate::EveryIteration,
                JacobianArg::OncePerStep => JacobianUpdate::OncePerStep,
            },
            forcing: forcing.into(),
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
        if forces && outputs.animate.is_none() {
            return Err(
                "--forces draws the contact forces on the animation: give --animate \
                        FILE.gif too"
                    .into(),
            );
        }
        if forces && model.gaps().is_empty() {
            return Err(format!(
                "--forces: `{}` has no contacts, limits or slack strings whose forces could be \
                 drawn",
                model.name
            ));
        }
        outputs.forces = forces;
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
    /// Whether the animation draws the contact forces.
    forces: bool,
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
            forces: false,
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
    mut outputs: Outputs,
) -> Result<(), String> {
    let (q0, dq0) = start_state(&sys, &outputs.start)?;
    let names = variable_names(&sys);
    let constraints: Vec<String> = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let unilateral = tree_mech::integrate::unilateral_row_names(&sys);
    let mut csv = open_csv(
        outputs.csv.as_ref(),
        [&names, &constraints, &unilateral],
        &sys.input_names(),
    )?;
    if let Some(file) = &outputs.csv {
        note_a_large_csv(file, &options, names.len(), constraints.len());
    }
    let mut record = Record::new(&options, &names, &constraints, &outputs)?;
    let mut motion = ModelMotions::of(&sys);
    let start = Instant::now();
    let summary = run_with_inputs(
        &mut sys,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut motion,
        &outputs.inputs,
        &mut |sample| {
            interrupt::check().map_err(SimError::InvalidInput)?;
            if let Some(csv) = csv.as_mut() {
                csv.write(sample).map_err(|e| {
                    SimError::InvalidInput(format!("cannot write the trajectory: {e}"))
                })?;
            }
            record.sample(sample, start);
            Ok(())
        },
    )
    .map_err(|e| match interrupt::requested() {
        true => "the run was interrupted: no output was written".to_string(),
        false => e.to_string(),
    })?;
    record.bar.finish_and_clear();
    let wall = start.elapsed().as_secs_f64();
    if let Some(csv) = csv {
        csv.finish()
            .map_err(|e| format!("cannot write the trajectory: {e}"))?;
    }
    draw(&mut sys, model, &record, &outputs)?;
    // Every output complete: now they take their names, then the summary names them.
    for file in [&mut outputs.csv, &mut outputs.plot, &mut outputs.animate]
        .into_iter()
        .flatten()
    {
        file.commit()?;
    }
    print_summary(&sys, model, &options, &summary, &record, wall, &outputs)
}

/// The variables' names, in order.
fn variable_names<S: System<N = Dyn>>(sys: &S) -> Vec<String> {
    (0..sys.dof())
        .map(|i| sys.variable_name(i).to_string())
        .collect()
}

/// The start: the model's, or `--q0`, `--dq0` as given.
fn start_state<S: System<N = Dyn>>(
    sys: &S,
    [q0_given, dq0_given]: &[Option<String>; 2],
) -> Result<(Vector<Dyn>, Vector<Dyn>), String> {
    let (mut q0, mut dq0) = sys.initial_state();
    let names = variable_names(sys);
    if let Some(text) = q0_given {
        q0 = parse_vector(text, sys.dof(), "q0", &names)?;
    }
    if let Some(text) = dq0_given {
        dq0 = parse_vector(text, sys.dof(), "dq0", &names)?;
    }
    Ok((q0, dq0))
}

/// The CSV stream into `--out`'s temporary file, its header written.
fn open_csv(
    out: Option<&OutputFile>,
    [names, constraints, unilateral]: [&[String]; 3],
    inputs: &[String],
) -> Result<Option<CsvStream<std::io::BufWriter<std::fs::File>>>, String> {
    let Some(file) = out else {
        return Ok(None);
    };
    let shown = file.path().display();
    let f =
        std::fs::File::create(file.temp()).map_err(|e| format!("cannot write `{shown}`: {e}"))?;
    let f = std::io::BufWriter::new(f);
    CsvStream::with_all(f, names, constraints, inputs, unilateral)
        .map(Some)
        .map_err(|e| format!("cannot write `{shown}`: {e}"))
}

/// Says up front when the CSV may pass [`LARGE_OUTPUT`]: a fixed-step run's rows are known
/// (an adaptive one's are bounded by its step budget).
fn note_a_large_csv(file: &OutputFile, options: &SimOptions, n: usize, rows_of_h: usize) {
    let rows = match options.method {
        Method::Rk45(_) => options.max_steps as f64,
        _ => options.duration / options.dt / options.every as f64,
    };
    let columns = 2 + 2 * n + rows_of_h + usize::from(rows_of_h > 0);
    let bytes = rows * columns as f64 * 20.0;
    // Not finite: the options are bad (a step of 0), which the run refuses in a sentence.
    if bytes > LARGE_OUTPUT && bytes.is_finite() {
        eprintln!(
            "note: `{}` may grow to about {} GB ({:.2e} rows of {columns} numbers); --every K records every K-th step",
            file.path().display(),
            tree_mech::model::Rounded(bytes / 1e9, 3),
            rows
        );
    }
}

/// What a run keeps beside the CSV as it goes: the plot's samples (every `thin`-th), the
/// animation's frames (one every `frame_interval` of simulated time), the energy at
/// the start and the end, and the progress bar.
/// The animation's samples: their times, configurations and unilateral rows' impulses.
#[derive(Default)]
struct Frames {
    times: Vec<f64>,
    q: Vec<Vec<f64>>,
    impulse: Vec<Vec<f64>>,
}

struct Record {
    bar: ProgressBar,
    duration: f64,
    last_tick: u64,
    picture: Option<Trajectory>,
    thin: usize,
    frames: Option<Frames>,
    frame_interval: f64,
    samples: usize,
    e0: f64,
    e_end: f64,
    t_end: f64,
}

impl Record {
    fn new(
        options: &SimOptions,
        names: &[String],
        constraints: &[String],
        outputs: &Outputs,
    ) -> Result<Self, String> {
        let bar = ProgressBar::new(1000);
        bar.set_style(
            ProgressStyle::with_template("{bar:40} {percent:>3}% t = {msg} s  ({elapsed})")
                .map_err(|e| e.to_string())?,
        );
        // The picture keeps at most PLOT_SAMPLES samples.
        let recorded = (options.duration / options.dt / options.every as f64).max(1.0);
        let picture = (outputs.plot.as_ref())
            .map(|_| Trajectory::new(names.to_vec(), constraints.to_vec(), 0));
        Ok(Record {
            bar,
            duration: options.duration.max(f64::MIN_POSITIVE),
            last_tick: 0,
            picture,
            thin: (recorded / PLOT_SAMPLES as f64).ceil().max(1.0) as usize,
            frames: outputs.animate.as_ref().map(|_| Frames::default()),
            // Fewer frames a second for long runs; poses are computed after the run.
            frame_interval: (1.0 / animate::FPS).max(options.duration / animate::MAX_FRAMES as f64),
            samples: 0,
            e0: f64::NAN,
            e_end: f64::NAN,
            t_end: 0.0,
        })
    }

    /// Keeps what the picture, the animation and the summary need of `sample`; moves the
    /// bar for runs long enough to watch.
    fn sample(&mut self, sample: &Sample, start: Instant) {
        if let Some(picture) = self.picture.as_mut() {
            if self.samples.is_multiple_of(self.thin) {
                picture.push(sample);
            }
        }
        if let Some(f) = self.frames.as_mut() {
            let next_frame = f.times.len() as f64 * self.frame_interval;
            if sample.t >= next_frame - 1e-9 * self.frame_interval {
                f.times.push(sample.t);
                f.q.push(sample.q.to_vec());
                f.impulse.push(sample.impulse.to_vec());
            }
        }
        self.samples += 1;
        if self.e0.is_nan() {
            self.e0 = sample.energy;
        }
        (self.e_end, self.t_end) = (sample.energy, sample.t);
        if start.elapsed().as_millis() > 300 {
            let tick = (1000.0 * sample.t / self.duration) as u64;
            if tick != self.last_tick {
                self.last_tick = tick;
                self.bar.set_position(tick);
                self.bar.set_message(format!("{:.3}", sample.t));
            }
        }
    }
}

/// The plot and the animation (the frames' poses computed here, after the run).
fn draw<S: System<N = Dyn>>(
    sys: &mut S,
    model: &model::Model,
    record: &Record,
    outputs: &Outputs,
) -> Result<(), String> {
    if let (Some(path), Some(picture)) = (&outputs.plot, &record.picture) {
        plot::plot(picture, model, path)?;
    }
    let (Some(path), Some(frames)) = (&outputs.animate, &record.frames) else {
        return Ok(());
    };
    let mut poses = Vec::with_capacity(frames.q.len());
    for q in &frames.q {
        let mut frame = vec![tree_mech::runtime::Pose::IDENTITY; sys.frame_count()];
        sys.poses(&Vector::<Dyn>::from_column_slice(q), &mut frame);
        poses.push(frame);
    }
    let arrows: Vec<Vec<forces::Arrow>> = match outputs.forces {
        true => (poses.iter().zip(&frames.impulse))
            .map(|(p, impulse)| forces::arrows(model, p, impulse))
            .collect(),
        false => Vec::new(),
    };
    let bar = ProgressBar::new(poses.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} GIF frames  ({elapsed})")
            .map_err(|e| e.to_string())?,
    );
    let encoding = Instant::now();
    let camera = outputs.camera;
    animate::write_gif(
        model,
        &frames.times,
        &poses,
        path,
        camera,
        &animate::Overlay {
            arrows: &arrows,
            ..Default::default()
        },
        &mut |k, _| {
            if encoding.elapsed().as_millis() > 300 {
                bar.set_position(k as u64);
            }
        },
    )?;
    bar.finish_and_clear();
    Ok(())
}

/// The run's one-paragraph summary, after any start value the constraints moved.
fn print_summary<S: System<N = Dyn>>(
    sys: &S,
    model: &model::Model,
    options: &SimOptions,
    summary: &RunSummary,
    record: &Record,
    wall: f64,
    outputs: &Outputs,
) -> Result<(), String> {
    for m in &summary.moved {
        say!(
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
    let constrained = if sys.constraint_count() == 0 {
        String::new()
    } else {
        format!(
            " Worst constraint violation {:.3e}.",
            summary.worst_violation
        )
    };
    let (e0, e_end) = (record.e0, record.e_end);
    let contact = !sys.unilateral().is_empty();
    let mut energy = energy_account(sys, e_end - e0 + summary.dissipated, summary.dissipated);
    let vi = matches!(options.method, Method::Vi(_));
    if contact && vi && !(0..sys.dof()).any(|i| sys.is_kinematic(i)) {
        // With contacts in force the balance is what impacts and friction took out (the VI's
        // own drift, bounded and small, included).
        let lost = -(e_end - e0 + summary.dissipated);
        energy = match summary.dissipated != 0.0 {
            false => format!("impacts and friction took out {} J", num(lost)),
            true => format!(
                "damping took out {} J, impacts and friction {} J",
                num(summary.dissipated),
                num(lost)
            ),
        };
    }
    let contact = if contact && vi {
        format!(
            " Contact: deepest penetration {:.3e} (m or rad), {:.2} interior-point iterations per step.",
            summary.worst_penetration,
            summary.contact_iterations as f64 / summary.steps.max(1) as f64
        )
    } else {
        String::new()
    };
    let variables = if sys.dof() == 1 {
        "variable"
    } else {
        "variables"
    };
    say!(
        "Simulated `{}` ({} {variables}) for {} s with {method}: {} steps in {:.3} s of wall time{newton}.{subdivided} \
         Energy went from {} to {} J ({energy}).{constrained}{contact}{}{}{}",
        model.name,
        sys.dof(),
        Seconds(record.t_end),
        summary.steps,
        wall,
        num(e0),
        num(e_end),
        shown(&outputs.csv, "Trajectory"),
        shown(&outputs.plot, "Plot"),
        shown(&outputs.animate, "Animation"),
    );
    Ok(())
}

/// Where the energy went: a drift, damping's share, or kinematic inputs' work.
fn energy_account<S: System<N = Dyn>>(sys: &S, balance: f64, dissipated: f64) -> String {
    let kinematic = (0..sys.dof()).any(|i| sys.is_kinematic(i));
    match (kinematic, dissipated != 0.0) {
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
    }
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
        let values = parse_list(text, names.len(), "u", &names, "input")?;
        return Ok(InputSchedule::constant(values));
    }
    let Some(path) = file else {
        return Ok(InputSchedule::default());
    };
    read_input_csv(path, &names)
}

/// An input schedule from a CSV file: a header naming `t` and each input (as `u_NAME`, or
/// `NAME` where that is not the time), then rows of numbers, times increasing from 0.
fn read_input_csv(path: &Path, names: &[String]) -> Result<InputSchedule, String> {
    let shown = path.display();
    let text = read_capped(path, MAX_INPUT_FILE)?;
    // A UTF-8 byte-order mark (spreadsheets write one) is not part of the first name.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
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
    let (t_column, columns) =
        input_columns(&header, names).map_err(|e| format!("`{shown}`:1: {e}"))?;
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

/// The columns of the time and of each input in `header`. A name twice is refused (which
/// would be meant?); an input is its `u_NAME` column (how simulate's and optimize's CSVs
/// name it, beside a variable that may bear the input's own name, a joint's), or else its
/// `NAME` column unless that is the time's.
fn input_columns(header: &[&str], names: &[String]) -> Result<(usize, Vec<usize>), String> {
    for (i, h) in header.iter().enumerate() {
        if let Some(j) = header[i + 1..].iter().position(|o| o == h) {
            return Err(format!(
                "column `{h}` appears twice (columns {} and {}): name each once",
                i + 1,
                i + j + 2
            ));
        }
    }
    let column = |name: &str| header.iter().position(|h| *h == name);
    let t_column = column("t").ok_or("no column `t`")?;
    let columns = names
        .iter()
        .map(|n| {
            column(&format!("u_{n}"))
                .or_else(|| column(n).filter(|&c| c != t_column))
                .ok_or_else(|| match n.as_str() {
                    "t" => "no column `u_t` for input `t` (the column `t` is the time)".to_string(),
                    _ => format!("no column for input `{n}` (or `u_{n}`)"),
                })
        })
        .collect::<Result<_, _>>()?;
    Ok((t_column, columns))
}

/// The most an input file may hold: far more than any schedule, and a bound on a file that
/// never ends (`--inputs /dev/zero`).
const MAX_INPUT_FILE: u64 = 256 << 20;

/// The text of `path`, refused past `cap` bytes (read no further) or when not UTF-8.
fn read_capped(path: &Path, cap: u64) -> Result<String, String> {
    use std::io::Read;
    let shown = path.display();
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read `{shown}`: {e}"))?;
    let mut bytes = Vec::new();
    file.take(cap + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read `{shown}`: {e}"))?;
    if bytes.len() as u64 > cap {
        return Err(format!(
            "`{shown}` is larger than {} MB: an input schedule is far smaller (is it the right file?)",
            cap >> 20
        ));
    }
    String::from_utf8(bytes).map_err(|_| format!("cannot read `{shown}`: it is not UTF-8 text"))
}

/// ` Label: path.` for the summary.
fn shown(file: &Option<OutputFile>, label: &str) -> String {
    file.as_ref()
        .map(|f| format!(" {label}: {}.", f.path().display()))
        .unwrap_or_default()
}
