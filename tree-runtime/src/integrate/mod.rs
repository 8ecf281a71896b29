//! Integrators — fixed-step RK4, adaptive Dormand–Prince 5(4), the midpoint variational
//! integrator — and [`run`], which drives any of them on any [`System`], projects the start
//! onto the constraints and hands every recorded step to an observer ([`simulate`] collects
//! them into a [`Trajectory`]).

mod discrete;
mod projection;
mod rk4;
mod rk45;
mod vi;

pub use discrete::DiscreteLagrangian;
pub use projection::{project_initial_state, Moved};
pub use rk4::Rk4;
pub use rk45::{Rk45, Tolerance};
pub use vi::{Forcing, JacobianUpdate, MidpointVi, ViSettings, MAX_TURN};

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::dynamics::{
    prescribe, Baumgarte, Dynamics, GeneralizedForce, ModelMotions, Prescription,
};
use crate::error::SimError;
use crate::system::{Order, System, Terms, Vector};
use crate::trajectory::{Sample, Trajectory};

/// The most steps a fixed-step run may take.
pub const MAX_STEPS: f64 = 1e9;

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
    /// reached would need more (a stiff model). Fixed-step runs are bounded by [`MAX_STEPS`].
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
}

fn check_options(o: &SimOptions) -> Result<usize, SimError> {
    if !(o.dt > 0.0 && o.dt.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "time step must be positive, got {}",
            o.dt
        )));
    }
    if !(o.duration > 0.0 && o.duration.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "duration must be positive, got {} s",
            o.duration
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
                "{what} must be a positive number, got {x}"
            )))
        }
    };
    if let Method::Vi(s) = o.method {
        if !(0.0..=1.0).contains(&s.alpha) {
            return Err(SimError::InvalidInput(format!(
                "VI alpha must lie in [0, 1], got {}",
                s.alpha
            )));
        }
        positive(s.tolerance, "the VI's Newton tolerance")?;
        positive(s.constraint_tolerance, "the VI's constraint tolerance")?;
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
    if steps < 1.0 && !matches!(o.method, Method::Rk45(_)) {
        return Err(SimError::InvalidInput(format!(
            "the duration {} s is shorter than one step of {} s: nothing would be simulated",
            o.duration, o.dt
        )));
    }
    Ok(steps as usize)
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
    let names = (0..sys.dof())
        .map(|i| sys.variable_name(i).to_string())
        .collect();
    let constraints = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let capacity =
        (options.duration / options.dt / options.every.max(1) as f64).clamp(0.0, 1e6) as usize + 2;
    let mut traj = Trajectory::new(names, constraints, capacity);
    let summary = run(sys, q0, dq0, options, force, &mut motion, &mut |s| {
        traj.push(s);
        progress(s.t);
        Ok(())
    })?;
    traj.newton_iterations = summary.newton_iterations;
    traj.subdivided_steps = summary.subdivided_steps;
    traj.dissipated = summary.dissipated;
    Ok(traj)
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
    let steps = check_options(options)?;
    let n = sys.dim();
    if q0.len() != n.value() || dq0.len() != n.value() {
        return Err(SimError::InvalidInput(format!(
            "initial state has {} and {} entries; the system has {} variables",
            q0.len(),
            dq0.len(),
            n.value()
        )));
    }
    let mut q = q0.clone();
    let mut dq = dq0.clone();
    let mut dynamics = Dynamics::new(sys);
    dynamics.baumgarte = options.baumgarte;
    prescribe(
        &dynamics.split.kinematic,
        motion,
        0.0,
        &mut q,
        &mut dq,
        None,
    );
    if q.iter().chain(dq.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step: 0,
            t: 0.0,
            what: "initial state".into(),
        });
    }
    let moved = project_initial_state(sys, &dynamics.split, &mut q, &mut dq)?;
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
    };
    let every = options.every;
    let recorded = |k: usize, last: bool| k.is_multiple_of(every) || last;
    match options.method {
        Method::Rk4 => {
            let mut rk = Rk4::new(sys);
            rk.dynamics.baumgarte = options.baumgarte;
            rec.continuous(sys, &mut dynamics, force, motion, 0, 0.0, &q, &dq)?;
            for k in 0..steps {
                let t = k as f64 * options.dt;
                rk.step(sys, force, motion, k, t, options.dt, &mut q, &mut dq)?;
                rec.summary.dissipated += rk.dissipated;
                let t = (k + 1) as f64 * options.dt;
                check_finite(k + 1, t, &q, &dq)?;
                if recorded(k + 1, k + 1 == steps) {
                    rec.continuous(sys, &mut dynamics, force, motion, k + 1, t, &q, &dq)?;
                }
            }
            rec.summary.steps = steps;
        }
        Method::Rk45(tol) => {
            let mut rk = Rk45::new(sys, tol);
            rk.dynamics.baumgarte = options.baumgarte;
            rec.continuous(sys, &mut dynamics, force, motion, 0, 0.0, &q, &dq)?;
            let (mut t, mut dt, mut k) = (0.0, options.dt, 0);
            let t_end = options.duration;
            while t < t_end {
                if k % 1000 == 999 || k >= options.max_steps {
                    budget(k, t, t_end, dt, options.max_steps)?;
                }
                let h = rk.step(sys, force, motion, k, t, t_end, &mut dt, &mut q, &mut dq)?;
                rec.summary.dissipated += rk.dissipated;
                t = if t + h >= t_end * (1.0 - 1e-15) {
                    t_end
                } else {
                    t + h
                };
                k += 1;
                check_finite(k, t, &q, &dq)?;
                if recorded(k, t >= t_end) {
                    rec.continuous(sys, &mut dynamics, force, motion, k, t, &q, &dq)?;
                }
            }
            rec.summary.steps = k;
        }
        Method::Vi(settings) => {
            let mut vi = MidpointVi::new(sys, settings);
            let mut p = vi.initial_momentum(sys, &q, &dq);
            let mut q_next = q.clone();
            // The start as the continuous equations see it, λ included.
            let (energy, violation) =
                rec.state(sys, &mut dynamics, force, motion, 0, 0.0, &q, &dq)?;
            rec.record(&Sample {
                step: 0,
                t: 0.0,
                q: q.as_slice(),
                dq: dq.as_slice(),
                p: Some(p.as_slice()),
                energy,
                lambda: dynamics.lambda.as_slice(),
                violation,
            })?;
            if dynamics.split.rows > 0 {
                let dh0 = &dynamics.constraint_terms.dh;
                vi.start_constrained(dh0, &dynamics.lambda, options.dt, &mut p);
            }
            for k in 0..steps {
                let t = k as f64 * options.dt;
                vi.step(
                    sys,
                    force,
                    motion,
                    k,
                    t,
                    options.dt,
                    &mut q,
                    &mut p,
                    &mut q_next,
                )?;
                rec.summary.newton_iterations += vi.iterations;
                rec.summary.dissipated += vi.dissipated;
                rec.summary.subdivided_steps += (vi.subdivisions > 0) as usize;
                if recorded(k + 1, k + 1 == steps) {
                    let t = (k + 1) as f64 * options.dt;
                    let violation = vi.constraint_terms.violation();
                    let energy = vi.velocity_and_energy(sys, motion, k + 1, t, &q, &p, &mut dq)?;
                    rec.record(&Sample {
                        step: k + 1,
                        t,
                        q: q.as_slice(),
                        dq: dq.as_slice(),
                        p: Some(p.as_slice()),
                        energy,
                        lambda: vi.lambda.as_slice(),
                        violation,
                    })?;
                }
            }
            rec.summary.steps = steps;
        }
    }
    Ok(rec.summary)
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

    /// Energy and constraint violation at `(q, q̇)`; with constraints the forces `λ` are left
    /// in `dynamics.lambda` (from the continuous equations).
    fn state<S, F, P>(
        &mut self,
        sys: &mut S,
        dynamics: &mut Dynamics<N>,
        force: &mut F,
        motion: &mut P,
        step: usize,
        t: f64,
        q: &Vector<N>,
        dq: &Vector<N>,
    ) -> Result<(f64, f64), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        sys.lagrangian(q, dq, Order::First, &mut self.terms);
        let energy = self.terms.energy(dq);
        if dynamics.split.rows == 0 {
            return Ok((energy, 0.0));
        }
        dynamics.acceleration(sys, force, motion, step, t, q, dq, &mut self.qdd)?;
        Ok((energy, dynamics.constraint_terms.violation()))
    }

    /// Records a continuous method's state.
    fn continuous<S, F, P>(
        &mut self,
        sys: &mut S,
        dynamics: &mut Dynamics<N>,
        force: &mut F,
        motion: &mut P,
        step: usize,
        t: f64,
        q: &Vector<N>,
        dq: &Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (energy, violation) = self.state(sys, dynamics, force, motion, step, t, q, dq)?;
        self.record(&Sample {
            step,
            t,
            q: q.as_slice(),
            dq: dq.as_slice(),
            p: None,
            energy,
            lambda: dynamics.lambda.as_slice(),
            violation,
        })
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
