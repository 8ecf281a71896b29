//! Integrators — fixed-step RK4, adaptive Dormand–Prince 5(4), the midpoint variational
//! integrator — and [`run`], which drives any of them on any [`System`], projects the start
//! onto the constraints and hands every recorded step to an observer ([`simulate`] collects
//! them into a [`Trajectory`]).

mod discrete;
pub(crate) mod laned;
mod projection;
mod rk4;
pub(crate) mod rk45;
mod stepper;
mod vi;
mod watch;

pub use crate::context::StepContext;
pub use discrete::DiscreteLagrangian;
pub use projection::{project_initial_state, Moved};
pub use rk4::Rk4;
pub use rk45::{Rk45, Tolerance};
pub use stepper::Stepper;
pub use vi::{
    Forcing, JacobianUpdate, MidpointVi, StepCovector, StepDerivatives, StepInput, StepOutput,
    StepSecondDerivatives, ViSettings,
};

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::dynamics::{
    prescribe, Baumgarte, Dynamics, GeneralizedForce, ModelMotions, Prescription, Split,
};
use crate::error::{Seconds, SimError};
use crate::system::{System, Terms, Vector};
use crate::trajectory::{Sample, Trajectory};
use watch::GapWatch;

/// The most steps a fixed-step run may take.
pub(crate) const MAX_STEPS: f64 = 1e9;

/// The default step budget of an adaptive run ([`SimOptions::max_steps`]).
pub const DEFAULT_MAX_ADAPTIVE_STEPS: usize = 1_000_000;

/// Which integrator to run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Classical fixed-step fourth-order Runge–Kutta.
    Rk4,
    /// Adaptive; records every accepted step, `dt` is the first step tried.
    Rk45(Tolerance),
    /// The midpoint variational integrator.
    Vi(ViSettings),
}

/// What to simulate for how long, and what to record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// The integrator.
    pub method: Method,
    /// Time step (the first one tried, for rk45).
    pub dt: f64,
    /// Simulated time, s.
    pub duration: f64,
    /// Record every K-th step (the first and the last are always recorded).
    pub every: usize,
    /// Stabilisation of the continuous methods' constraints.
    pub baumgarte: Baumgarte,
    /// The most steps an adaptive (rk45) run may take: it stops with
    /// [`SimError::StepBudget`] when it has taken them, or as soon as the step size it has
    /// reached would need more (a stiff model). Fixed-step runs are bounded by 10⁹ steps.
    pub max_steps: usize,
}

impl SimOptions {
    /// `method` for `duration` seconds at step `dt`, every step recorded, no stabilisation.
    pub fn new(method: Method, dt: f64, duration: f64) -> Self {
        SimOptions {
            method,
            dt,
            duration,
            every: 1,
            baumgarte: Baumgarte::default(),
            max_steps: DEFAULT_MAX_ADAPTIVE_STEPS,
        }
    }
}

impl Default for SimOptions {
    /// The VI for 10 s at Δt = 0.01, every step recorded.
    fn default() -> Self {
        SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 10.0)
    }
}

/// What a run did, besides the samples it handed out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunSummary {
    /// Steps taken.
    pub steps: usize,
    /// Samples handed to the observer.
    pub recorded: usize,
    /// Newton iterations over the run (VI).
    pub newton_iterations: usize,
    /// VI steps that Newton could only take in pieces.
    pub subdivided_steps: usize,
    /// The largest `max |h|` over the recorded samples.
    pub worst_violation: f64,
    /// The energy the model's own forces (damping, dampers) took out over the run, by each
    /// integrator's own quadrature of `−∫ F·q̇ dt`: with no kinematic inputs,
    /// `ΔE + dissipated` is the integrator's energy error.
    pub dissipated: f64,
    /// What the projection of the initial state onto the constraints moved.
    pub moved: Vec<Moved>,
    /// Interior-point iterations of the VI's contact steps over the run.
    pub contact_iterations: usize,
    /// The deepest any unilateral row (limit, contact, string) went below zero at a step's
    /// end over the run, in its own unit (m or rad); 0 when none did.
    pub worst_penetration: f64,
}

fn check_options(o: &SimOptions) -> Result<usize, SimError> {
    if !(o.dt > 0.0 && o.dt.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "time step must be a positive finite number, got {}",
            Seconds(o.dt)
        )));
    }
    if !(o.duration > 0.0 && o.duration.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "duration must be a positive finite number of seconds, got {} s",
            Seconds(o.duration)
        )));
    }
    if o.every == 0 {
        return Err(SimError::InvalidInput(
            "record every K-th step needs K ≥ 1".into(),
        ));
    }
    // Tolerances are positive numbers: zero, negative or NaN would switch a test off.
    let positive = |x: f64, what: &str| {
        if x > 0.0 && x.is_finite() {
            Ok(())
        } else {
            Err(SimError::InvalidInput(format!(
                "{what} must be a positive number, got {}",
                tree_model::Given(x)
            )))
        }
    };
    if let Method::Vi(s) = o.method {
        if o.baumgarte.a != 0.0 || o.baumgarte.b != 0.0 {
            return Err(SimError::InvalidInput(
                "Baumgarte stabilisation is for the explicit integrators (rk4, rk45), whose \
                 constraints drift; the VI holds its constraints at every step, so it would \
                 be ignored"
                    .into(),
            ));
        }
        if !(0.0..=1.0).contains(&s.alpha) {
            return Err(SimError::InvalidInput(format!(
                "VI alpha must lie in [0, 1], got {}",
                tree_model::Given(s.alpha)
            )));
        }
        positive(s.tolerance, "the VI's Newton tolerance")?;
        positive(s.constraint_tolerance, "the VI's constraint tolerance")?;
        for (x, what) in [
            (s.tolerance, "Newton tolerance"),
            (s.constraint_tolerance, "constraint tolerance"),
        ] {
            if x > LOOSEST_NEWTON_TOLERANCE {
                return Err(SimError::InvalidInput(loose_tolerance(what, x)));
            }
        }
        if !(s.kappa.is_finite() && s.kappa >= 0.0) {
            return Err(SimError::InvalidInput(format!(
                "the contact relaxation κ must be finite and not negative, got {}",
                s.kappa
            )));
        }
        if s.max_iterations == 0 {
            return Err(SimError::InvalidInput(
                "the VI needs at least one Newton iteration a step".into(),
            ));
        }
    }
    if let Method::Rk45(t) = o.method {
        positive(t.rtol, "rk45's relative tolerance")?;
        positive(t.atol, "rk45's absolute tolerance")?;
        if o.max_steps == 0 {
            return Err(SimError::InvalidInput(
                "rk45's step budget must be at least one step".into(),
            ));
        }
    }
    let steps = (o.duration / o.dt).round();
    if steps > MAX_STEPS {
        return Err(SimError::TooManySteps { steps });
    }
    // One rule for every front end: a run no longer than one step simulates nothing the
    // user asked for (a duration of 1 s at a step of 2 s would end at t = 2).
    if (steps < 1.0 || o.duration < o.dt) && !matches!(o.method, Method::Rk45(_)) {
        return Err(SimError::InvalidInput(format!(
            "the duration {} s is shorter than one step of {} s: nothing would be simulated",
            Seconds(o.duration),
            Seconds(o.dt)
        )));
    }
    Ok(steps as usize)
}

/// The loosest Newton tolerance the VI accepts: looser, Newton can accept its predictor and
/// a run gains or loses energy unseen; at this one a step is solved to well below the
/// integrator's own error (docs/derivations.md §7).
pub const LOOSEST_NEWTON_TOLERANCE: f64 = 1e-6;

/// The sentence refusing a tolerance looser than [`LOOSEST_NEWTON_TOLERANCE`].
pub fn loose_tolerance(what: &str, x: f64) -> String {
    format!(
        "the VI's {what} {x:e} is looser than {LOOSEST_NEWTON_TOLERANCE:e}: Newton would stop \
         short of the step's solution and the run would gain or lose energy unseen; use at \
         most {LOOSEST_NEWTON_TOLERANCE:e} (the default is 1e-12)"
    )
}

/// Simulates from `(q0, q̇0)` with the model's own prescriptions and no external force
/// beyond `force`, and collects every recorded step. `progress` is called with the time
/// reached at each recorded step.
pub fn simulate<S, F>(
    sys: &mut S,
    q0: &Vector<S::N>,
    dq0: &Vector<S::N>,
    options: &SimOptions,
    force: &mut F,
    progress: &mut dyn FnMut(f64),
) -> Result<Trajectory, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut motion = ModelMotions::of(sys);
    let mut traj = recording(sys, options)?;
    let summary = run(sys, q0, dq0, options, force, &mut motion, &mut |s| {
        traj.push(s);
        progress(s.t);
        Ok(())
    })?;
    finish(&mut traj, &summary);
    Ok(traj)
}

/// The samples a run under `options` records.
fn recorded_samples(options: &SimOptions) -> f64 {
    (options.duration / options.dt / options.every.max(1) as f64).ceil() + 2.0
}

/// `Ok` when `runs` recorded runs of `sys` under `options` fit in memory (each sample: the
/// time, q, q̇, p, energy, λ, the violation and u), else an error saying how to ask for less.
pub(crate) fn check_recordings<S>(
    sys: &S,
    options: &SimOptions,
    runs: usize,
) -> Result<(), SimError>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    // The options first: a step of 0 or 1e-300 is a bad option, not a lack of memory.
    check_options(options)?;
    let numbers = 3 * sys.dof() + sys.constraint_count() + sys.input_count() + 3;
    let samples = recorded_samples(options);
    let bytes = runs as f64 * samples * numbers as f64 * 8.0;
    let what = || match runs {
        1 => format!("the run's {samples:.3e} recorded samples of {numbers} numbers"),
        _ => format!("{runs} runs of {samples:.3e} recorded samples of {numbers} numbers"),
    };
    crate::memory::check(
        bytes,
        what,
        "record every K-th step (`every`), shorten the run, or run fewer at once",
    )
}

/// An empty trajectory of `sys`'s variables and constraints, with room for the samples a run
/// under `options` records (checked to fit in memory first).
pub(crate) fn recording<S>(sys: &S, options: &SimOptions) -> Result<Trajectory, SimError>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    check_recordings(sys, options, 1)?;
    let names = (0..sys.dof())
        .map(|i| sys.variable_name(i).to_string())
        .collect();
    let constraints = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    // Room for every sample at once (checked above): no doubling past what was checked.
    let samples = recorded_samples(options) as usize;
    let mut traj = Trajectory::new(names, constraints, samples);
    traj.unilateral = unilateral_row_names(sys);
    Ok(traj)
}

/// Each unilateral row's name: an element's, and `name.t1`, `name.t2` for a ground contact's
/// tangent rows (allocates; at setup).
pub fn unilateral_row_names<S: System>(sys: &S) -> Vec<String>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut names = Vec::new();
    for g in sys.unilateral() {
        if g.rows() == 3 {
            names.extend([
                g.name.clone(),
                format!("{}.t1", g.name),
                format!("{}.t2", g.name),
            ]);
        } else {
            names.push(g.name);
        }
    }
    names
}

/// A recorded run's totals, from its summary.
pub(crate) fn finish(traj: &mut Trajectory, summary: &RunSummary) {
    traj.newton_iterations = summary.newton_iterations;
    traj.subdivided_steps = summary.subdivided_steps;
    traj.dissipated = summary.dissipated;
}

/// Runs `options.method` from `(q0, q̇0)` — first projected onto the constraints, kinematic
/// variables set from `motion` — and hands every `options.every`-th step to `observe`
/// (which may stop the run by returning an error). Nothing is kept in memory.
pub fn run<S, F, P>(
    sys: &mut S,
    q0: &Vector<S::N>,
    dq0: &Vector<S::N>,
    options: &SimOptions,
    force: &mut F,
    motion: &mut P,
    observe: &mut dyn FnMut(&Sample) -> Result<(), SimError>,
) -> Result<RunSummary, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let none = InputSchedule::default();
    run_with_inputs(sys, q0, dq0, options, force, motion, &none, observe)
}

/// `width` input values a step (0: none, all zero) for `sys`'s inputs.
fn check_input_width<S: System>(sys: &S, width: usize) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if width != 0 && width != sys.input_count() {
        return Err(SimError::InvalidInput(format!(
            "{width} input values given a step; the system has {} ({})",
            tree_model::Counted(sys.input_count(), "input"),
            sys.input_names().join(", ")
        )));
    }
    Ok(())
}

/// A start `(q0, q̇0)` of `q0` and `dq0` entries: one a variable each.
fn check_start<S: System>(sys: &S, q0: usize, dq0: usize) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    if q0 != n || dq0 != n {
        return Err(SimError::InvalidInput(format!(
            "initial state has {q0} and {dq0} entries; the system has {}",
            tree_model::Counted(n, "variable")
        )));
    }
    Ok(())
}

/// [`run`] with the system's inputs `u` given by `inputs` (held over each step; an empty
/// schedule: all zero).
#[allow(clippy::too_many_arguments)] // run's, and the inputs
pub fn run_with_inputs<S, F, P>(
    sys: &mut S,
    q0: &Vector<S::N>,
    dq0: &Vector<S::N>,
    options: &SimOptions,
    force: &mut F,
    motion: &mut P,
    inputs: &InputSchedule,
    observe: &mut dyn FnMut(&Sample) -> Result<(), SimError>,
) -> Result<RunSummary, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let steps = check_options(options)?;
    check_input_width(sys, if inputs.is_empty() { 0 } else { inputs.width() })?;
    check_start(sys, q0.len(), dq0.len())?;
    let n = sys.dim();
    let mut q = q0.clone();
    let mut dq = dq0.clone();
    let mut dynamics = Dynamics::new(sys);
    dynamics.baumgarte = options.baumgarte;
    let moved = start_state(sys, &dynamics.split, motion, &mut q, &mut dq)?;
    let mut rec = Recorder {
        summary: RunSummary {
            moved,
            ..RunSummary::default()
        },
        observe,
        constraints: (0..sys.constraint_count())
            .map(|r| sys.constraint_name(r).to_string())
            .collect(),
        terms: Terms::zeros(n),
        qdd: sys.zero_vector(),
        dynamics,
        every: options.every,
        watch: match options.method {
            Method::Rk4 => GapWatch::new(sys, "rk4"),
            Method::Rk45(_) => GapWatch::new(sys, "rk45"),
            Method::Vi(_) => None,
        },
    };
    let mut cx = StepContext::new(sys, force, motion, options.dt);
    // One line per integrator: what it is driven as.
    match options.method {
        Method::Rk4 => {
            let mut rk = Rk4::new(cx.sys);
            rk.dynamics.baumgarte = options.baumgarte;
            drive(
                &mut Fixed(rk, steps),
                &mut cx,
                inputs,
                &mut rec,
                &mut q,
                &mut dq,
            )
        }
        Method::Rk45(tol) => {
            let mut rk = Rk45::new(cx.sys, tol);
            rk.dynamics.baumgarte = options.baumgarte;
            let adaptive = Adaptive(rk, options.duration, options.max_steps);
            drive(
                &mut { adaptive },
                &mut cx,
                inputs,
                &mut rec,
                &mut q,
                &mut dq,
            )
        }
        Method::Vi(settings) => {
            let vi = MidpointVi::new(cx.sys, settings);
            let p = cx.sys.zero_vector();
            let variational = Variational {
                vi,
                steps,
                p,
                q_next: q.clone(),
            };
            drive(
                &mut { variational },
                &mut cx,
                inputs,
                &mut rec,
                &mut q,
                &mut dq,
            )
        }
    }
    .map_err(|e| {
        let t = e.when().map_or(0.0, |(_, t)| t);
        e.under_inputs(&sys.input_names(), inputs.at(t))
    })?;
    Ok(rec.summary)
}

/// The start of a run: `(q0, q̇0)` with the kinematic entries set from `motion` at `t = 0`,
/// checked finite, and projected onto the constraints (what moved is returned).
fn start_state<S, P>(
    sys: &mut S,
    split: &Split,
    motion: &mut P,
    q: &mut Vector<S::N>,
    dq: &mut Vector<S::N>,
) -> Result<Vec<Moved>, SimError>
where
    S: System,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    prescribe(&split.kinematic, motion, 0.0, q, dq, None);
    if q.iter().chain(dq.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step: 0,
            t: 0.0,
            what: "initial state".into(),
        });
    }
    let mut moved = projection::start_within_gaps(sys, q)?;
    moved.extend(project_initial_state(sys, split, q, dq)?);
    Ok(moved)
}

/// An integrator as [`run`] drives it: it hands out its start, then steps, saying when it
/// has reached the end, and hands out the state after the steps the run records.
trait Driven<S: System, F: GeneralizedForce<S::N>, P: Prescription>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// Hands out the start `(q, q̇)` and gets ready to step from it (default: a continuous
    /// method's state as it stands).
    fn begin(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(), SimError> {
        rec.continuous(cx, q, dq)
    }

    /// Step `cx.index` from `cx.t`: the time it reaches, and whether that ends the run.
    fn advance(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(f64, bool), SimError>;

    /// Hands out the state reached (`cx` is at the step just taken, `cx.t` its end;
    /// default: a continuous method's `(q, q̇)`).
    fn sample(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(), SimError> {
        rec.continuous(cx, q, dq)
    }
}

/// Runs `it` from `(q, q̇)` to the end, handing out every recorded step; each step, and
/// each sample, sees the inputs in force from its time on.
fn drive<'a, S, F: GeneralizedForce<S::N>, P: Prescription>(
    it: &mut impl Driven<S, F, P>,
    cx: &mut StepContext<'a, S, F, P>,
    inputs: &'a InputSchedule,
    rec: &mut Recorder<S::N>,
    q: &mut Vector<S::N>,
    dq: &mut Vector<S::N>,
) -> Result<(), SimError>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    cx.u = inputs.at(0.0);
    it.begin(cx.at(0, 0.0), rec, q, dq)?;
    let (mut k, mut t) = (0, 0.0);
    loop {
        cx.u = inputs.at(t);
        let (reached, last) = it.advance(cx.at(k, t), rec, q, dq)?;
        (k, t) = (k + 1, reached);
        if let Some(w) = rec.watch.as_mut() {
            w.check(cx.sys, q, k, t)?;
        }
        if k.is_multiple_of(rec.every) || last {
            cx.u = inputs.at(t);
            it.sample(cx.at(k, t), rec, q, dq)?;
        }
        if last {
            rec.summary.steps = k;
            return Ok(());
        }
    }
}

/// RK4 for a fixed number of steps.
struct Fixed<N: Dim>(Rk4<N>, usize)
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>;

impl<S, F, P> Driven<S, F, P> for Fixed<S::N>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    fn advance(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(f64, bool), SimError> {
        self.0.step(cx, q, dq)?;
        rec.summary.dissipated += self.0.dissipated;
        let k = cx.index + 1;
        let t = k as f64 * cx.dt;
        check_finite(k, t, q, dq)?;
        Ok((t, k == self.1))
    }
}

/// Dormand–Prince 5(4) to `t_end`, within a step budget.
struct Adaptive<N: Dim>(Rk45<N>, f64, usize)
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>;

impl<S, F, P> Driven<S, F, P> for Adaptive<S::N>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    fn advance(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(f64, bool), SimError> {
        let (k, t, t_end) = (cx.index, cx.t, self.1);
        if k % 1000 == 999 || k >= self.2 {
            budget(k, t, t_end, cx.dt, self.2)?;
        }
        let h = self.0.step(cx, t_end, q, dq)?;
        rec.summary.dissipated += self.0.dissipated;
        let reached = if t + h >= t_end * (1.0 - 1e-15) {
            t_end
        } else {
            t + h
        };
        check_finite(k + 1, reached, q, dq)?;
        Ok((reached, reached >= t_end))
    }
}

/// The midpoint VI for a fixed number of steps, on `(q, p)`; q̇ is made from p for samples.
struct Variational<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    vi: MidpointVi<N>,
    steps: usize,
    p: Vector<N>,
    q_next: Vector<N>,
}

impl<S, F, P> Driven<S, F, P> for Variational<S::N>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    fn begin(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(), SimError> {
        self.p = self.vi.initial_momentum(cx.sys, q, dq);
        self.vi.contact_start(cx.sys, q);
        // The start as the continuous equations see it, λ included.
        let (energy, violation) = rec.state(cx, q, dq)?;
        let lambda = rec.dynamics.lambda.clone();
        let (impulse, gap) = self.vi.contact_rows();
        rec.record(&Sample {
            step: 0,
            t: 0.0,
            q: q.as_slice(),
            dq: dq.as_slice(),
            p: Some(self.p.as_slice()),
            energy,
            lambda: lambda.as_slice(),
            violation,
            u: cx.u,
            impulse,
            gap,
        })?;
        if rec.dynamics.split.rows > 0 {
            let dh0 = &rec.dynamics.constraint_terms.dh;
            self.vi
                .start_constrained(dh0, &rec.dynamics.lambda, cx.dt, &mut self.p);
        }
        Ok(())
    }

    fn advance(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        _: &mut Vector<S::N>,
    ) -> Result<(f64, bool), SimError> {
        self.vi.step(cx, q, &mut self.p, &mut self.q_next)?;
        rec.summary.newton_iterations += self.vi.iterations;
        rec.summary.dissipated += self.vi.dissipated;
        rec.summary.contact_iterations += self.vi.contact_iterations;
        let deepest = rec.summary.worst_penetration.max(self.vi.penetration);
        rec.summary.worst_penetration = deepest;
        rec.summary.subdivided_steps += (self.vi.subdivisions > 0) as usize;
        let k = cx.index + 1;
        Ok((k as f64 * cx.dt, k == self.steps))
    }

    fn sample(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        rec: &mut Recorder<S::N>,
        q: &mut Vector<S::N>,
        dq: &mut Vector<S::N>,
    ) -> Result<(), SimError> {
        let (k, t) = (cx.index, cx.t);
        let violation = self.vi.constraint_terms.violation();
        let energy = self.vi.velocity_and_energy(cx, q, &self.p, dq)?;
        let (impulse, gap) = self.vi.contact_rows();
        rec.record(&Sample {
            step: k,
            t,
            q: q.as_slice(),
            dq: dq.as_slice(),
            p: Some(self.p.as_slice()),
            energy,
            lambda: self.vi.lambda.as_slice(),
            violation,
            u: cx.u,
            impulse,
            gap,
        })
    }
}

/// Hands samples to the caller's observer and keeps the run's summary.
struct Recorder<'a, N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    summary: RunSummary,
    observe: &'a mut dyn FnMut(&Sample) -> Result<(), SimError>,
    /// Constraint names, for errors.
    constraints: Vec<String>,
    terms: Terms<N>,
    qdd: Vector<N>,
    /// The continuous equations, for the energy and λ of a recorded state.
    dynamics: Dynamics<N>,
    /// Record every `every`-th step.
    every: usize,
    /// A smooth integrator's watch on the unilateral rows it cannot enforce.
    watch: Option<GapWatch>,
}

impl<N: Dim> Recorder<'_, N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// Hands `s` on — unless something in it is not finite, which ends the run with an error
    /// naming it (a state can be finite while its energy overflows: q̇ = 1e200).
    fn record(&mut self, s: &Sample) -> Result<(), SimError> {
        let what = if !s.energy.is_finite() {
            Some(format!("the energy E = T + V ({})", s.energy))
        } else if let Some(r) = s.lambda.iter().position(|l| !l.is_finite()) {
            Some(format!(
                "the force λ of constraint `{}`",
                self.constraints[r]
            ))
        } else if !s.violation.is_finite() {
            Some("the constraint violation".to_string())
        } else {
            None
        };
        if let Some(what) = what {
            return Err(SimError::NonFinite {
                step: s.step,
                t: s.t,
                what,
            });
        }
        self.summary.recorded += 1;
        self.summary.worst_violation = self.summary.worst_violation.max(s.violation);
        (self.observe)(s)
    }

    /// Energy and constraint violation at `(q, q̇)` at `cx.t`; with constraints the forces
    /// `λ` are left in `self.dynamics.lambda` (from the continuous equations).
    fn state<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        dq: &Vector<N>,
    ) -> Result<(f64, f64), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        if self.dynamics.split.rows == 0 {
            return Ok((cx.sys.energy(q, dq, &mut self.terms), 0.0));
        }
        // With constraints the accelerations (for λ) evaluate the Lagrangian's terms, whose
        // Legendre transform is the energy.
        self.dynamics.acceleration(cx, q, dq, &mut self.qdd)?;
        let energy = self.dynamics.terms.energy(dq);
        Ok((energy, self.dynamics.constraint_terms.violation()))
    }

    /// Records a continuous method's state at `cx.t` (step `cx.index`).
    fn continuous<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        dq: &Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (energy, violation) = self.state(cx, q, dq)?;
        let lambda = std::mem::take(&mut self.dynamics.lambda);
        // A smooth run of a model with unilateral rows reports their gaps and no impulse.
        let mut watch = self.watch.take();
        let (impulse, gap) = match watch.as_mut() {
            Some(w) => w.sample(cx.sys, q),
            None => (&[][..], &[][..]),
        };
        let result = self.record(&Sample {
            step: cx.index,
            t: cx.t,
            q: q.as_slice(),
            dq: dq.as_slice(),
            p: None,
            energy,
            lambda: lambda.as_slice(),
            violation,
            u: cx.u,
            impulse,
            gap,
        });
        self.watch = watch;
        self.dynamics.lambda = lambda;
        result
    }
}

/// The inputs `u` over a run, held constant over each step: rows `(t, u)` in time order,
/// each in force from its time until the next row's (before the first row, the first row's).
/// A constant `u` is one row; an empty schedule means no inputs (all zero).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InputSchedule {
    times: Vec<f64>,
    /// Row-major, `width` values a row.
    values: Vec<f64>,
    width: usize,
}

impl InputSchedule {
    /// `u` for the whole run.
    pub fn constant(u: Vec<f64>) -> Self {
        InputSchedule {
            times: vec![0.0],
            width: u.len(),
            values: u,
        }
    }

    /// Rows `(t, u)`: times strictly increasing and finite, the first at the run's start
    /// (t = 0; or before it), every `u` of one width and finite.
    pub fn from_rows(rows: Vec<(f64, Vec<f64>)>) -> Result<Self, SimError> {
        if let Some(&(first, _)) = rows.first().filter(|(t, _)| *t > 1e-9) {
            return Err(SimError::InvalidInput(format!(
                "input row 1 is at t = {first} s, after the run's start at t = 0: the inputs \
                 before it would be unknown; give a row at t = 0"
            )));
        }
        let width = rows.first().map_or(0, |r| r.1.len());
        let mut schedule = InputSchedule {
            width,
            ..Self::default()
        };
        for (k, (t, u)) in rows.into_iter().enumerate() {
            if !t.is_finite() || schedule.times.last().is_some_and(|&last| t <= last) {
                return Err(SimError::InvalidInput(format!(
                    "input row {}: time {t} must be finite and later than the row before",
                    k + 1
                )));
            }
            if u.len() != width || u.iter().any(|x| !x.is_finite()) {
                return Err(SimError::InvalidInput(format!(
                    "input row {}: {} values where the first row has {width}, all finite",
                    k + 1,
                    u.len()
                )));
            }
            schedule.times.push(t);
            schedule.values.extend(u);
        }
        Ok(schedule)
    }

    /// Whether there are no inputs.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// Values a row.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The inputs in force at `t`: the last row whose time is at or before it (to rounding:
    /// a row at 0.03 is in force for the step that starts at 3 × 0.01).
    pub fn at(&self, t: f64) -> &[f64] {
        if self.times.is_empty() {
            return &[];
        }
        let slack = 1e-9 * t.abs().max(1e-300);
        let k = self.times.partition_point(|&r| r <= t + slack).max(1) - 1;
        &self.values[k * self.width..(k + 1) * self.width]
    }
}

/// An adaptive run's step budget: it fails once it has taken `max_steps`, or as soon as the
/// step size `dt` it has reached at `t` would need more than `max_steps` to reach `t_end`.
fn budget(k: usize, t: f64, t_end: f64, dt: f64, max_steps: usize) -> Result<(), SimError> {
    let needed = k as f64 + (t_end - t) / dt;
    if k >= max_steps || needed > max_steps as f64 {
        return Err(SimError::StepBudget {
            step: k,
            t,
            dt,
            needed,
            max_steps,
        });
    }
    Ok(())
}

fn check_finite<N: Dim>(step: usize, t: f64, q: &Vector<N>, dq: &Vector<N>) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<N>,
{
    if q.iter().chain(dq.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step,
            t,
            what: "state (q, q̇)".into(),
        });
    }
    Ok(())
}
