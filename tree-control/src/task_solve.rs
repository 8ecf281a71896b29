//! Solving a [`Task`] (a task file) on a system: the discretisation it names, the start
//! state, the initial guess (the start held at rest: gravity compensation on inputs,
//! kinematic controls on their prescription), the limits, the solve, and the optimal
//! trajectory read back knot by knot (`q`, `q̇`, the controls, `λ`).

use std::ops::ControlFlow;
use std::time::Instant;

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};
use tree_model::{Control, Model, Task, TaskIntegrator, TaskSolver};

use crate::cost::{Cost, Derivatives};
use crate::discrete::DiscreteSystem;
use crate::ilqr::{solve_until, IlqrSettings, Iteration, Solution, Solver, Stop};
use crate::knot::Knot;
use crate::knot::Needs;
use crate::task_cost::TaskCost;
use tree_runtime::dynamics::{ModelMotions, Prescription};
use tree_runtime::integrate::ViSettings;
use tree_runtime::SimError;
use tree_runtime::{ConstraintTerms, Order, System, Vector};

/// A solved task: the solver's result and the trajectory at every knot.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskResult {
    /// The optimiser's result (states, controls, gains, cost, history).
    pub solution: Solution,
    /// Knot times `t_0 … t_N`.
    pub t: Vec<f64>,
    /// Every variable's value at each knot.
    pub q: Vec<DVector<f64>>,
    /// Every variable's velocity at each knot (VI: consistent with the momentum).
    pub dq: Vec<DVector<f64>>,
    /// The constraint forces `λ` of the step leaving each knot (the last knot repeats the
    /// last step's).
    pub lambda: Vec<DVector<f64>>,
    /// `max |h(q)|` at each knot (0 without constraints).
    pub violation: Vec<f64>,
    /// Wall time of the solve.
    pub solve_seconds: f64,
    /// Through contact: the plan's controls replayed open loop at hard contact (κ = 0).
    pub hard_replay: Option<HardReplay>,
    /// Through contact: the plan's policy `u = u_k + K_k (x − x_k)` (clamped to the limits)
    /// run at hard contact — what a controller executing the plan meets where the motion
    /// is unstable (a robot rising on its feet), which open loop it cannot follow.
    pub policy_replay: Option<HardReplay>,
    /// Through contact, when a relaxation could not be reached: which, why, and the `κ`
    /// whose plan this is (`None`: the plan is the task's last `κ`'s).
    pub continuation: Option<String>,
}

/// A plan optimised at a relaxation `κ > 0` replayed at hard contact: how far it lands from
/// where the optimiser said, and how deep anything sank.
#[derive(Clone, Debug, PartialEq)]
pub struct HardReplay {
    /// The largest difference of a dynamic variable between the replay and the plan, over
    /// every knot (in the variable's units).
    pub deviation: f64,
    /// The deepest penetration of a unilateral row at any knot of the replay.
    pub penetration: f64,
    /// The step that could not be taken at hard contact, if any (the replay stops there).
    pub failure: Option<String>,
    /// Every variable's value where the replay ended (the last knot it reached).
    pub end: DVector<f64>,
}

/// Settings beyond the task file: what the CLI's options override.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TaskOptions {
    /// The solver (default: the task's).
    pub solver: Option<TaskSolver>,
    /// The iteration limit (default: the task's, else 100).
    pub max_iterations: Option<usize>,
}

/// The discretised system of `task` on `sys` (remembering inputs only when a `control_rate`
/// term reads them; through contact at the task's last relaxation `κ`, the plan's).
pub fn task_system<S: System>(sys: S, task: &Task) -> Result<DiscreteSystem<S>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let dynamics = match task.integrator {
        TaskIntegrator::Vi => DiscreteSystem::vi(
            sys,
            ViSettings {
                kappa: task.kappa.last().copied().unwrap_or(0.0),
                ..ViSettings::default()
            },
            task.dt,
            0.0,
            task.controls.clone(),
        ),
        TaskIntegrator::Rk4 => DiscreteSystem::rk4(sys, task.dt, 0.0, task.controls.clone()),
        TaskIntegrator::Rk45 => Err(SimError::InvalidInput(
            "a task steps with `vi` or `rk4`: an adaptive step (`rk45`) is no discrete system"
                .into(),
        )),
    }?;
    Ok(dynamics.with_input_memory(task.reads_previous_inputs()))
}

/// Solves `task` (read with `model`) on `sys` (that model, compiled or interpreted),
/// calling `report` after every iteration.
pub fn solve_task<S: System>(
    sys: S,
    task: &Task,
    model: &Model,
    options: &TaskOptions,
    report: &mut dyn FnMut(&Iteration),
) -> Result<TaskResult, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    solve_task_until(sys, task, model, options, &mut |it| {
        report(it);
        ControlFlow::Continue(())
    })
}

/// `Ok` when the solve's knots fit in memory: each holds its state and controls, the step's
/// Jacobians and the cost's and value function's quadratic models, about
/// `nx² + 3 nx nu + nu²` numbers.
fn check_task_memory(task: &Task, dof: usize) -> Result<(), SimError> {
    let (nx, nu) = ((2 * dof) as f64, task.controls.len() as f64);
    let per_knot = 8.0 * (nx * nx + 3.0 * nx * nu + nu * nu + 6.0 * nx + 4.0 * nu);
    tree_runtime::memory::check(
        (task.knots + 1) as f64 * per_knot,
        || format!("the task's {} knots", task.knots),
        "take fewer knots (a longer dt, or a shorter horizon)",
    )
}

/// [`solve_task`] whose `report` may end the solve ([`solve_until`]): the result is then the
/// best trajectory found, its `solution.stop` [`Stop::Interrupted`](super::Stop::Interrupted).
pub fn solve_task_until<S: System>(
    sys: S,
    task: &Task,
    model: &Model,
    options: &TaskOptions,
    report: &mut dyn FnMut(&Iteration) -> ControlFlow<()>,
) -> Result<TaskResult, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if sys.dof() != model.variables.len() {
        return Err(SimError::InvalidInput(format!(
            "the system has {} variables but the task's model has {}",
            sys.dof(),
            model.variables.len()
        )));
    }
    let (held, written) = (sys.unilateral().len(), model.gaps().len());
    if held != written {
        return Err(SimError::InvalidInput(format!(
            "the system has {held} unilateral elements (enforced limits, contacts, slack strings) but the task's model has {written}: compile it with the task's (`contacts from \"task.toml\"`, `enforce_limits = false` as the task says)"
        )));
    }
    check_task_memory(task, sys.dof())?;
    let mut dynamics = task_system(sys, task)?;
    let (x0, guess) = initial_guess(&mut dynamics, task, model)?;
    let settings = task_settings(task, options);
    let mut cost = TaskCost::new(task, model)?;
    let start = Instant::now();
    let (solution, continuation) = solve_stages(
        &mut dynamics,
        &mut cost,
        &x0,
        guess,
        &settings,
        task,
        report,
    )?;
    let solve_seconds = start.elapsed().as_secs_f64();
    let plan = read_back(&mut dynamics, task, &solution)?;
    let (hard_replay, policy_replay) = if task.kappa.is_empty() {
        (None, None)
    } else {
        let open = replay_hard(&mut dynamics, &solution, None)?;
        let policy = replay_hard(&mut dynamics, &solution, Some(&settings))?;
        (Some(open), Some(policy))
    };
    Ok(TaskResult {
        hard_replay,
        policy_replay,
        continuation,
        t: (0..=task.knots).map(|k| k as f64 * task.dt).collect(),
        q: plan.q,
        dq: plan.dq,
        lambda: plan.lambda,
        violation: plan.violation,
        solution,
        solve_seconds,
    })
}

/// The start state and the initial guess: the start held at rest (every input at the
/// gravity compensation of the start, refused when its limits exclude it), kinematic
/// controls on their prescription.
fn initial_guess<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    task: &Task,
    model: &Model,
) -> Result<(DVector<f64>, Vec<DVector<f64>>), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (mut q0, mut dq0) = (dynamics.sys.zero_vector(), dynamics.sys.zero_vector());
    for i in 0..q0.len() {
        (q0[i], dq0[i]) = (task.q0[i], task.dq0[i]);
    }
    let hold = dynamics.holding_inputs(&q0);
    let nu = task.controls.len();
    for (c, control) in task.controls.iter().enumerate() {
        if let (Control::Input(_), Some([lo, hi])) = (control, task.limits[c]) {
            if !(lo..=hi).contains(&hold[c]) {
                let at = task.limit_lines[c].map_or(String::new(), |l| format!(" (line {l})"));
                return Err(SimError::InvalidInput(format!(
                    "the limits [{lo}, {hi}] of `{}`{at} exclude the {} that holds the start against gravity",
                    task.control_name(model, c),
                    hold[c]
                )));
            }
        }
    }
    let mut motion = ModelMotions::of(&dynamics.sys);
    let guess: Vec<DVector<f64>> = (0..task.knots)
        .map(|k| {
            DVector::from_fn(nu, |c, _| match task.controls[c] {
                Control::Input(_) => hold[c],
                Control::Kinematic(i) => motion.kinematic(i, (k + 1) as f64 * task.dt)[0],
            })
        })
        .collect();
    let x0 = dynamics.state_of(&q0, &dq0, hold.as_slice());
    Ok((x0, guess))
}

/// The solver's settings for `task` with `options`: the solver and iteration limit (the
/// options', else the task's), the controls' box limits (an [`crate::Mpc`] on a task's plan
/// takes these).
pub fn task_settings(task: &Task, options: &TaskOptions) -> IlqrSettings {
    let nu = task.controls.len();
    let bounded = task.limits.iter().any(Option::is_some);
    let limits = bounded.then(|| {
        (
            DVector::from_fn(nu, |c, _| {
                task.limits[c].map_or(f64::NEG_INFINITY, |l| l[0])
            }),
            DVector::from_fn(nu, |c, _| task.limits[c].map_or(f64::INFINITY, |l| l[1])),
        )
    });
    IlqrSettings {
        solver: match options.solver.unwrap_or(task.solver) {
            TaskSolver::Ilqr => Solver::Ilqr,
            TaskSolver::Ddp => Solver::Ddp,
        },
        max_iterations: options
            .max_iterations
            .or(task.max_iterations)
            .unwrap_or(100),
        limits,
        ..IlqrSettings::default()
    }
}

/// The plan knot by knot: every variable's `q`, `q̇`, the violation, and the `λ` of the
/// step leaving each knot (the last knot repeats the last step's).
struct PlanKnots {
    q: Vec<DVector<f64>>,
    dq: Vec<DVector<f64>>,
    lambda: Vec<DVector<f64>>,
    violation: Vec<f64>,
}

/// Reads `solution` back knot by knot (each step taken again for its `λ`).
fn read_back<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    task: &Task,
    solution: &Solution,
) -> Result<PlanKnots, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut knot = Knot::empty();
    let needs = Needs {
        velocity: true,
        ..Needs::default()
    };
    let mut plan = PlanKnots {
        q: Vec::new(),
        dq: Vec::new(),
        lambda: Vec::new(),
        violation: Vec::new(),
    };
    let mut x2 = vec![0.0; dynamics.states()];
    let mut h = ConstraintTerms::zeros(dynamics.sys.constraint_count(), dynamics.sys.dof());
    let (mut qv, mut dqv) = (dynamics.sys.zero_vector(), dynamics.sys.zero_vector());
    for k in 0..=task.knots {
        let x = solution.x[k].as_slice();
        dynamics.knot(k, x, &mut knot, false, needs)?;
        qv.as_mut_slice().copy_from_slice(knot.q.as_slice());
        dqv.as_mut_slice().copy_from_slice(knot.dq.as_slice());
        dynamics.sys.constraints(&qv, &dqv, Order::First, &mut h);
        plan.violation.push(h.violation());
        plan.q.push(knot.q.clone());
        plan.dq.push(knot.dq.clone());
        if k < task.knots {
            dynamics.step(k, x, solution.u[k].as_slice(), &mut x2, None)?;
            plan.lambda
                .push(DVector::from_column_slice(dynamics.multipliers()));
        }
    }
    plan.lambda
        .push(plan.lambda.last().cloned().unwrap_or_default());
    Ok(plan)
}

/// The solve, once, or through the task's relaxations `κ` largest first, each stage
/// warm-started from the last one's plan and feedback (continuation on the central path:
/// Howell et al., "Trajectory optimization with optimization-based dynamics", RA-L 2022):
/// the last stage's solution, with every stage's iterations in its history (each records
/// its `κ`). When a stage cannot even start (a step of its first rollout fails), the last
/// finished stage's plan is the answer, the dynamics are put back at its `κ`, and the
/// second value says so.
fn solve_stages<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut TaskCost,
    x0: &DVector<f64>,
    guess: Vec<DVector<f64>>,
    settings: &IlqrSettings,
    task: &Task,
    report: &mut dyn FnMut(&Iteration) -> ControlFlow<()>,
) -> Result<(Solution, Option<String>), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if task.kappa.is_empty() {
        return Ok((
            solve_until(dynamics, cost, x0, guess, settings, report)?,
            None,
        ));
    }
    let (mut u, mut history) = (guess, Vec::new());
    let mut done: Option<(f64, Solution)> = None;
    for &kappa in &task.kappa {
        dynamics.set_kappa(kappa)?;
        match &done {
            Some((_, last)) => {
                closed_loop(
                    dynamics,
                    x0,
                    (&last.x, &last.u, &last.gains),
                    settings,
                    &mut u,
                );
            }
            None => {
                // Held by feedback where that runs through, else the guess open loop.
                let mut q0 = dynamics.sys.zero_vector();
                q0.as_mut_slice().copy_from_slice(&task.q0);
                let (x, gains) = held_start(dynamics, cost, (&q0, x0), &u, task.dt)?;
                let open = u.clone();
                if !closed_loop(dynamics, x0, (&x, &open, &gains), settings, &mut u) {
                    u = open;
                }
            }
        }
        let stage = match solve_until(dynamics, cost, x0, std::mem::take(&mut u), settings, report)
        {
            Ok(stage) => stage,
            Err(e) => {
                let Some((reached, last)) = done else {
                    return Err(e);
                };
                dynamics.set_kappa(reached)?;
                let why = format!(
                    "the continuation stopped at κ = {kappa:e}, whose first rollout failed ({e}); the plan is κ = {reached:e}'s"
                );
                let solution = Solution {
                    history,
                    converged: false,
                    ..last
                };
                return Ok((solution, Some(why)));
            }
        };
        history.extend(stage.history.iter().copied());
        let interrupted = stage.stop == Stop::Interrupted;
        done = Some((kappa, stage));
        if interrupted {
            // The caller asked to stop: this stage's plan is the answer.
            break;
        }
    }
    let (reached, last) = done.expect("κ is not empty");
    let complete = reached == task.kappa[task.kappa.len() - 1];
    let solution = Solution {
        history,
        converged: last.converged && complete,
        ..last
    };
    Ok((solution, None))
}

/// A held start's states and feedback gains, knot by knot ([`held_start`]).
type HeldStart = (Vec<DVector<f64>>, Vec<DMatrix<f64>>);

/// A plan's states, controls and feedback gains at knots `0 … N−1` (and the last state).
type Policy<'a> = (&'a [DVector<f64>], &'a [DVector<f64>], &'a [DMatrix<f64>]);

/// The first relaxation's plan where the start touches something (a robot standing or
/// crouched on the ground): its first guess (the inputs that hold the start,
/// [`DiscreteSystem::holding_inputs`]) with the feedback of the time-varying LQR about the
/// start held — the step linearised at `(x₀, u₀)` and the task's
/// own running and terminal curvature at `x₀`. A crouched robot on its feet is an unstable
/// equilibrium: open loop, its held start splays within a few tenths of a second into
/// motions the contact step cannot follow; with this feedback the first rollout stays near
/// the start. The states (each `x₀`) and the gains (`−K_k`; zero where nothing touches).
fn held_start<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut TaskCost,
    (q0, x0): (&Vector<S::N>, &DVector<f64>),
    guess: &[DVector<f64>],
    dt: f64,
) -> Result<HeldStart, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nx, nu, n) = (x0.len(), dynamics.controls(), guess.len());
    let states = vec![x0.clone(); n + 1];
    if dynamics.touching(q0).0.is_empty() || n == 0 {
        return Ok((states, vec![DMatrix::zeros(nu, nx); n]));
    }
    let (mut a, mut b) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    let mut x2 = vec![0.0; nx];
    dynamics.step(
        0,
        x0.as_slice(),
        guess[0].as_slice(),
        &mut x2,
        Some((&mut a, &mut b)),
    )?;
    let needs = cost.needs();
    let mut knot = Knot::empty();
    let mut d = Derivatives::zeros(nx, nu);
    dynamics.knot(0, x0.as_slice(), &mut knot, true, needs)?;
    cost.running(0, &knot, &guess[0], Some(&mut d));
    // Every configuration entry held as firmly, per step, as the task's running cost holds
    // its most-weighted one per second (its weight w: `ℓ_xx = Δt w`): a task weighting only
    // the base's pose would leave the legs free to splay.
    let (mut q, r) = (d.lxx.clone(), d.luu.clone());
    let nd = dynamics.dynamic_count();
    let firmest = (0..nd).map(|i| q[(i, i)]).fold(0.0, f64::max) / dt;
    for i in 0..nd {
        q[(i, i)] += firmest;
    }
    dynamics.knot(n, x0.as_slice(), &mut knot, true, needs)?;
    cost.terminal(&knot, Some(&mut d));
    let lqr = crate::lqr::tvlqr(&vec![a; n], &vec![b; n], &q, &r, &d.lxx)?;
    Ok((states, lqr.into_iter().map(|l| -l.k).collect()))
}

/// The controls of a plan's policy `u = u_k + K_k (x − x_k)` (clamped to the limits) along
/// its rollout on `dynamics` from `x0` into `u`: the next relaxation's first guess. Open
/// loop, a plan for one `κ` drifts on another wherever the motion is unstable (a pole
/// balanced upright); its feedback keeps it near. Where a step fails the plan's own
/// controls are taken from there on (the solve's first rollout then reports it). Whether
/// every step went through.
fn closed_loop<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    x0: &DVector<f64>,
    (states, controls, gains): Policy,
    settings: &IlqrSettings,
    u: &mut Vec<DVector<f64>>,
) -> bool
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    u.clear();
    let mut x = x0.clone();
    let mut x2 = DVector::zeros(x0.len());
    for (k, planned) in controls.iter().enumerate() {
        let mut uk = planned + &gains[k] * (&x - &states[k]);
        if let Some((lo, hi)) = &settings.limits {
            for c in 0..uk.len() {
                uk[c] = uk[c].clamp(lo[c], hi[c]);
            }
        }
        if dynamics
            .step(k, x.as_slice(), uk.as_slice(), x2.as_mut_slice(), None)
            .is_err()
        {
            u.extend(controls[k..].iter().cloned());
            return false;
        }
        u.push(uk);
        std::mem::swap(&mut x, &mut x2);
    }
    true
}

/// The plan replayed at hard contact (κ = 0) from its start — its controls open loop, or
/// with `feedback` its policy `u_k + K_k (x − x_k)` clamped to those settings' limits: the
/// largest difference of a dynamic variable from the plan and the deepest penetration
/// (the dynamics are left at κ = 0).
fn replay_hard<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    plan: &Solution,
    feedback: Option<&IlqrSettings>,
) -> Result<HardReplay, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    dynamics.set_kappa(0.0)?;
    let nd = dynamics.dynamic_count();
    let mut x = plan.x[0].as_slice().to_vec();
    let mut x2 = vec![0.0; x.len()];
    let mut replay = HardReplay {
        deviation: 0.0,
        penetration: 0.0,
        failure: None,
        end: DVector::zeros(0),
    };
    let mut reached = 0;
    let mut u = DVector::zeros(dynamics.controls());
    for k in 0..plan.u.len() {
        u.copy_from(&plan.u[k]);
        if let Some(settings) = feedback {
            let dx = DVector::from_fn(x.len(), |i, _| x[i] - plan.x[k][i]);
            u.gemv(1.0, &plan.gains[k], &dx, 1.0);
            if let Some((lo, hi)) = &settings.limits {
                for c in 0..u.len() {
                    u[c] = u[c].clamp(lo[c], hi[c]);
                }
            }
        }
        if let Err(e) = dynamics.step(k, &x, u.as_slice(), &mut x2, None) {
            replay.failure = Some(e.to_string());
            break;
        }
        replay.penetration = replay.penetration.max(dynamics.penetration());
        let planned = &plan.x[k + 1];
        for r in 0..nd {
            replay.deviation = replay.deviation.max((x2[r] - planned[r]).abs());
        }
        std::mem::swap(&mut x, &mut x2);
        reached = k + 1;
    }
    let mut knot = Knot::empty();
    dynamics.knot(reached, &x, &mut knot, false, Needs::default())?;
    replay.end = knot.q.clone();
    Ok(replay)
}
