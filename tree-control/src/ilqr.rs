//! iLQR and DDP on the VI (or RK4) with box limits on the controls (docs/derivations.md §10): a
//! rollout; a backward pass `Q_x = ℓ_x + AᵀV_x`, `Q_u = ℓ_u + BᵀV_x`,
//! `Q_xx = ℓ_xx + AᵀV_xxA`, `Q_uu = ℓ_uu + BᵀV_xxB + μI`, `Q_ux = ℓ_ux + BᵀV_xxA` (DDP adds
//! the step's second derivatives contracted with `V_x`); the control QP solved by projected
//! Newton within the limits (box-DDP: clamped controls get no feedback) once the solve is
//! near its optimum, and without them, clamped in the forward pass, until then (`BoxPhase`);
//! a forward pass with a backtracking line search on the true cost; Levenberg–Marquardt `μ`
//! raised when `Q_uu` is not positive definite (for DDP: when even the Gauss–Newton model's
//! is not, which a pass falls back to when the full one's is not), no step length lowers the
//! cost or the accepted one is under ¼, lowered after a longer accepted step.

use std::ops::ControlFlow;

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use crate::cost::{Cost, Derivatives};
use crate::discrete::DiscreteSystem;
use crate::knot::Knot;
use crate::knot::Needs;
use crate::qp::{ControlQp, Limits};
use tree_runtime::linalg::{
    mul_into, mul_into_pair, tr_mul_into, tr_mul_into_pair, tr_mul_into_symmetric, Packing,
};
use tree_runtime::SimError;
use tree_runtime::System;

/// How many iterations' records a solve reserves before it starts (more grow the list).
const HISTORY_RESERVE: usize = 4096;

/// Which second-order model of the dynamics the backward pass uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Solver {
    /// Gauss–Newton: the dynamics to first order.
    #[default]
    Ilqr,
    /// Full DDP: plus the step's second derivatives contracted with `V_x`.
    Ddp,
}

/// Settings of the optimiser.
#[derive(Clone, Debug, PartialEq)]
pub struct IlqrSettings {
    /// iLQR or DDP.
    pub solver: Solver,
    /// Iterations before giving up (the best trajectory is still returned).
    pub max_iterations: usize,
    /// Converged when an accepted step lowers the cost by less than this, relative to it.
    pub cost_tolerance: f64,
    /// Converged, before a line search, when the full step is predicted to lower the cost by
    /// less than this, relative to it: the local model's decrease `−Σ_k (k_kᵀQ_u + ½ k_kᵀQ_uu
    /// k_k)` (Tassa, Erez, Todorov 2012, eq. (14)) is in the cost's units, so a task whose
    /// controls or cost are in other units stops alike (a test on `max |k|` would read the
    /// controls' units).
    pub decrease_tolerance: f64,
    /// Box limits per control `[lo, hi]` (None: unbounded).
    pub limits: Option<(DVector<f64>, DVector<f64>)>,
    /// The first regularisation, relative: each knot's `Q_uu` gains `μ s I` with `s` its
    /// largest diagonal entry, so a cost in other units takes the same steps.
    pub mu: f64,
    /// The line search tries step lengths 1, ½, ¼, … down to this one (10⁻⁴, fourteen
    /// rollouts at most); an MPC bounds its time a tick with a larger one.
    pub min_step: f64,
}

impl Default for IlqrSettings {
    fn default() -> Self {
        IlqrSettings {
            solver: Solver::Ilqr,
            max_iterations: 100,
            cost_tolerance: 1e-6,
            decrease_tolerance: 1e-12,
            limits: None,
            mu: 1e-6,
            min_step: 1e-4,
        }
    }
}

/// How the backward pass treats the controls' box limits (docs/derivations.md §10, "Limits
/// in two phases"). The box QP's policy — clamped controls get no feedback — is right near
/// the plan it was computed on; a long step moves the states away from where the clamps were
/// decided, and controls held at a bound then no longer react to the state (the UR5 reach's
/// first full box step: a cost 65× the start's). So a solve starts `Clamped` (the
/// unconstrained `k`, `K`, the controls clamped in the forward pass, where the clamps are
/// decided at the states actually reached) and goes `Boxed` for good once a step is shorter
/// than ½ or none is accepted: from there the box QP gives the constrained Newton step, and
/// `max |k|` vanishes at a constrained optimum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoxPhase {
    /// Unconstrained gains; limits only by clamping in the forward pass.
    Clamped,
    /// The box QP's gains.
    Boxed,
}

/// One iteration's record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iteration {
    /// The total cost after the iteration.
    pub cost: f64,
    /// The accepted step length (0 when none was accepted).
    pub step: f64,
    /// The regularisation after the iteration.
    pub mu: f64,
    /// The largest feed-forward entry `max |k|`.
    pub gradient: f64,
    /// The model the backward pass used: [`Solver::Ddp`]'s full one, or the Gauss–Newton
    /// model ([`Solver::Ilqr`]: iLQR's, and DDP's where its full model was indefinite or
    /// every step went through contact).
    pub model: Solver,
    /// With limits, how the pass treated them (`None` without limits).
    pub limits: Option<BoxPhase>,
    /// The contacts' relaxation `κ` of the steps (0: hard, or no unilateral rows).
    pub kappa: f64,
}

/// Why [`solve`] stopped iterating.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// A convergence test was met: the cost decrease, or the decrease the local model predicts
    /// for the full step, fell below its tolerance relative to the cost.
    Converged,
    /// `max_iterations` ran out first.
    IterationLimit,
    /// The regularisation μ (relative to each knot's control curvature) passed [`MAX_MU`]
    /// without a step that lowers the cost, or with `Q_uu + μ s I` still not positive
    /// definite: the local model is not trusted any nearer.
    Regularisation,
    /// The caller's report asked to stop ([`solve_until`]).
    Interrupted,
}

impl Stop {
    /// As the summaries name it.
    pub fn name(self) -> &'static str {
        match self {
            Stop::Converged => "converged",
            Stop::IterationLimit => "iteration limit",
            Stop::Regularisation => "regularisation",
            Stop::Interrupted => "interrupted",
        }
    }
}

/// The regularisation past which [`solve`] stops ([`Stop::Regularisation`]).
pub const MAX_MU: f64 = 1e10;

/// μ after a step the model was not trusted for: ten times more, from at least 1e-6.
fn raised(mu: f64) -> f64 {
    (mu * 10.0).max(1e-6)
}

/// The optimised trajectory and its controller.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// States at knots `0 … N`.
    pub x: Vec<DVector<f64>>,
    /// Controls at knots `0 … N−1`.
    pub u: Vec<DVector<f64>>,
    /// Feedback gains: `u = u_k + k_k + K_k (x − x_k)` near the plan (`K` controls × states).
    pub gains: Vec<DMatrix<f64>>,
    /// The last backward pass's feed-forward terms.
    pub feedforward: Vec<DVector<f64>>,
    /// The total cost.
    pub cost: f64,
    /// Whether a convergence test was met (otherwise the best trajectory found): `stop` is
    /// [`Stop::Converged`].
    pub converged: bool,
    /// Why the iterations stopped.
    pub stop: Stop,
    /// Every iteration.
    pub history: Vec<Iteration>,
}

impl Solution {
    /// The plan's policy at knot `k` for the state `x`: `u_k + K_k (x − x_k)`, clamped to
    /// `limits` (a solve's box limits) when given.
    pub fn policy(
        &self,
        k: usize,
        x: &DVector<f64>,
        limits: Option<&(DVector<f64>, DVector<f64>)>,
    ) -> DVector<f64> {
        let mut u = &self.u[k] + &self.gains[k] * (x - &self.x[k]);
        if let Some((lo, hi)) = limits {
            for c in 0..u.len() {
                u[c] = u[c].clamp(lo[c], hi[c]);
            }
        }
        u
    }
}

/// Optimises the controls of `dynamics` over `u.len()` steps from `x0`, starting from `u`.
/// Returns the best trajectory found with its gains, converged or not; fails only when the
/// first rollout does (the start cannot be simulated) or the problem does not fit.
pub fn solve<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x0: &DVector<f64>,
    u: Vec<DVector<f64>>,
    settings: &IlqrSettings,
) -> Result<Solution, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    solve_with(dynamics, cost, x0, u, settings, &mut |_| {})
}

/// [`solve`], calling `report` after every iteration (progress printing).
pub fn solve_with<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x0: &DVector<f64>,
    u: Vec<DVector<f64>>,
    settings: &IlqrSettings,
    report: &mut dyn FnMut(&Iteration),
) -> Result<Solution, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    solve_until(dynamics, cost, x0, u, settings, &mut |it| {
        report(it);
        ControlFlow::Continue(())
    })
}

/// [`solve_with`] whose `report` may also end the solve: on `ControlFlow::Break` it stops
/// after that iteration with the best trajectory found ([`Stop::Interrupted`]) — a caller's
/// Ctrl-C, say.
pub fn solve_until<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x0: &DVector<f64>,
    mut u: Vec<DVector<f64>>,
    settings: &IlqrSettings,
    report: &mut dyn FnMut(&Iteration) -> ControlFlow<()>,
) -> Result<Solution, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    check(dynamics, cost, x0, &u)?;
    check_settings(dynamics, settings)?;
    if let Some(limits) = &settings.limits {
        clamp_into(limits, &mut u);
    }
    let (nx, nu, n) = (dynamics.states(), dynamics.controls(), u.len());
    let mut work = Work::new(nx, nu, n, cost.needs());
    let mut x = vec![x0.clone(); n + 1];
    let total = rollout(dynamics, cost, &mut x, &mut u, &mut work, true, None)?;
    let mut it = Iterate {
        x_new: x.clone(),
        u_new: u.clone(),
        x,
        u,
        total,
    };
    let mut mu = settings.mu;
    // Reserved up to a cap so ordinary solves allocate nothing per iteration; past the
    // cap it grows: `max_iterations` is a bound, not a size (4e9 would abort).
    let mut history = Vec::with_capacity(settings.max_iterations.min(HISTORY_RESERVE));
    let has_limits = settings.limits.is_some();
    let kappa = dynamics.kappa();
    let mut record = |cost: f64, step: f64, mu: f64, gradient: f64, pass: (Solver, BoxPhase)| {
        let it = Iteration {
            kappa,
            cost,
            step,
            mu,
            gradient,
            model: pass.0,
            limits: has_limits.then_some(pass.1),
        };
        history.push(it);
        report(&it)
    };
    let mut stop = Stop::IterationLimit;
    let mut phase = BoxPhase::Clamped;
    for _ in 0..settings.max_iterations {
        let Some(direction) =
            compute_direction(dynamics, cost, &it, &mut work, settings, mu, phase)?
        else {
            // Some Q_uu + μ s I is not positive definite: regularise more.
            mu = raised(mu);
            if mu > MAX_MU {
                stop = Stop::Regularisation;
                break;
            }
            continue;
        };
        let (gradient, used) = (direction.outcome.gradient, (direction.model, phase));
        // A small predicted decrease is convergence only while the regularisation is small
        // too: a large μ shrinks the step whatever the gradient (a model that keeps failing
        // its line search), and that ends on the regularisation's ceiling instead.
        let decrease = direction.outcome.decrease;
        if decrease <= settings.decrease_tolerance * it.total.abs() && mu <= settings.mu.max(1e-6) {
            stop = Stop::Converged;
            let _ = record(it.total, 0.0, mu, gradient, used);
            break;
        }
        let (accepted, trial_total) = try_step(dynamics, cost, x0, &mut it, &mut work, settings);
        if accepted < 0.5 {
            phase = BoxPhase::Boxed;
        }
        if accepted == 0.0 {
            mu = raised(mu);
            let flow = record(it.total, 0.0, mu, gradient, used);
            if mu > MAX_MU {
                stop = Stop::Regularisation;
                break;
            }
            if flow.is_break() {
                stop = Stop::Interrupted;
                break;
            }
            continue;
        }
        let previous = it.total;
        accept_step(dynamics, &mut it, trial_total, &mut work)?;
        // A short step means the model was trusted too far: regularise more next time.
        mu = if accepted < 0.25 {
            raised(mu)
        } else {
            (mu * 0.1).max(1e-12)
        };
        let flow = record(it.total, accepted, mu, gradient, used);
        let change = previous - it.total;
        if change < settings.cost_tolerance * previous.abs().max(f64::MIN_POSITIVE) {
            stop = Stop::Converged;
            break;
        }
        if flow.is_break() {
            stop = Stop::Interrupted;
            break;
        }
    }
    Ok(Solution {
        gains: work.gain,
        feedforward: work.k,
        x: it.x,
        u: it.u,
        cost: it.total,
        converged: stop == Stop::Converged,
        stop,
        history,
    })
}

/// The solve's own settings: tolerances and regularisation finite and non-negative, DDP
/// only on the VI, limits of the right size with lower ≤ upper.
fn check_settings<S: System>(
    dynamics: &DiscreteSystem<S>,
    settings: &IlqrSettings,
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let nu = dynamics.controls();
    let settled = |x: f64| x.is_finite() && x >= 0.0;
    if !(settled(settings.cost_tolerance)
        && settled(settings.decrease_tolerance)
        && settled(settings.mu))
    {
        return Err(SimError::InvalidInput(format!(
            "the optimiser's cost tolerance ({}), decrease tolerance ({}) and regularisation ({}) must be finite and non-negative",
            tree_model::Given(settings.cost_tolerance),
            tree_model::Given(settings.decrease_tolerance),
            tree_model::Given(settings.mu)
        )));
    }
    if settings.max_iterations == 0 {
        return Err(SimError::InvalidInput(
            "the optimiser needs at least one iteration (max_iterations ≥ 1)".into(),
        ));
    }
    if !(settings.min_step > 0.0 && settings.min_step <= 1.0) {
        return Err(SimError::InvalidInput(format!(
            "the line search's smallest step (min_step = {}) must be in (0, 1]",
            tree_model::Given(settings.min_step)
        )));
    }
    if settings.solver == Solver::Ddp && !dynamics.is_vi() {
        return Err(SimError::InvalidInput(
            "DDP needs the VI's second derivatives: use iLQR with RK4".into(),
        ));
    }
    let Some((lo, hi)) = &settings.limits else {
        return Ok(());
    };
    if lo.len() != nu || hi.len() != nu {
        return Err(SimError::InvalidInput(format!(
            "the limits have {} lower and {} upper bounds; the problem has {nu} controls",
            lo.len(),
            hi.len()
        )));
    }
    for c in 0..nu {
        if lo[c].is_nan() || hi[c].is_nan() || lo[c] > hi[c] {
            return Err(SimError::InvalidInput(format!(
                "the limits of control {c} are [{}, {}]: the lower must not exceed the upper",
                lo[c], hi[c]
            )));
        }
    }
    Ok(())
}

/// The initial guess clamped into the limits.
fn clamp_into((lo, hi): &Limits, u: &mut [DVector<f64>]) {
    for uk in u.iter_mut() {
        for c in 0..uk.len() {
            uk[c] = uk[c].clamp(lo[c], hi[c]);
        }
    }
}

/// The current iterate (states, controls, total cost) and the trial one the line search
/// fills.
struct Iterate {
    x: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    x_new: Vec<DVector<f64>>,
    u_new: Vec<DVector<f64>>,
    total: f64,
}

/// A backward pass's result and the model it used.
struct Direction {
    outcome: Outcome,
    model: Solver,
}

/// The backward pass at `mu` (the box QP once the phase is boxed): the feedback gains and
/// feed-forward in `work`. Where DDP's model is indefinite (the step's curvature contracted
/// with V_x, far from the optimum) this pass takes the Gauss–Newton model at the same μ
/// rather than a μ large enough to hide it, which would turn the steps into a crawl. `None`:
/// some `Q_uu + μ s I` is not positive definite.
fn compute_direction<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    it: &Iterate,
    work: &mut Work,
    settings: &IlqrSettings,
    mu: f64,
    phase: BoxPhase,
) -> Result<Option<Direction>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let pass = Pass {
        solver: settings.solver,
        mu,
        limits: match phase {
            BoxPhase::Clamped => None,
            BoxPhase::Boxed => settings.limits.as_ref(),
        },
    };
    let outcome = backward(dynamics, cost, &it.x, &it.u, work, &pass)?;
    if outcome.is_some() || pass.solver != Solver::Ddp {
        // DDP whose every step went through contact took the Gauss–Newton model throughout.
        return Ok(outcome.map(|outcome| Direction {
            model: match outcome.curved {
                0 => Solver::Ilqr,
                _ => pass.solver,
            },
            outcome,
        }));
    }
    let gauss_newton = Pass {
        solver: Solver::Ilqr,
        ..pass
    };
    let outcome = backward(dynamics, cost, &it.x, &it.u, work, &gauss_newton)?;
    Ok(outcome.map(|outcome| Direction {
        outcome,
        model: Solver::Ilqr,
    }))
}

/// The forward pass: the first step length (1, ½, ¼, … down to the settings' `min_step`)
/// whose rollout lowers the true cost, into the trial iterate; `(0, total)` when none does.
fn try_step<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x0: &DVector<f64>,
    it: &mut Iterate,
    work: &mut Work,
    settings: &IlqrSettings,
) -> (f64, f64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut alpha = 1.0;
    while alpha >= settings.min_step {
        for k in 0..it.u.len() {
            it.u_new[k].copy_from(&it.u[k]);
            it.u_new[k].axpy(alpha, &work.k[k], 1.0);
        }
        it.x_new[0].copy_from(x0);
        let policy = Some((it.x.as_slice(), settings.limits.as_ref()));
        if let Ok(trial) = rollout(
            dynamics,
            cost,
            &mut it.x_new,
            &mut it.u_new,
            work,
            false,
            policy,
        ) {
            if trial.is_finite() && trial < it.total {
                return (alpha, trial);
            }
        }
        alpha *= 0.5;
    }
    (0.0, it.total)
}

/// The trial iterate becomes the current one, with its step Jacobians at its converged
/// steps.
fn accept_step<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    it: &mut Iterate,
    total: f64,
    work: &mut Work,
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    std::mem::swap(&mut it.x, &mut it.x_new);
    std::mem::swap(&mut it.u, &mut it.u_new);
    it.total = total;
    for k in 0..it.u.len() {
        let (head, tail) = it.x.split_at_mut(k + 1);
        dynamics.jacobians(
            k,
            head[k].as_slice(),
            it.u[k].as_slice(),
            tail[0].as_mut_slice(),
            &work.lambda[k],
            &mut work.a[k],
            &mut work.b[k],
        )?;
    }
    Ok(())
}

/// Per-knot buffers and the knot workspace, allocated once per solve.
struct Work {
    a: Vec<DMatrix<f64>>,
    b: Vec<DMatrix<f64>>,
    k: Vec<DVector<f64>>,
    gain: Vec<DMatrix<f64>>,
    knot: Knot,
    needs: Needs,
    /// `x − x_plan` in the forward pass.
    dx: DVector<f64>,
    /// Each step's multipliers in the last rollout (for its Jacobians without re-stepping).
    lambda: Vec<Vec<f64>>,
    backward: Backward,
}

impl Work {
    /// Buffers for `n` knots of `nx` states and `nu` controls.
    fn new(nx: usize, nu: usize, n: usize, needs: Needs) -> Self {
        Work {
            a: vec![DMatrix::zeros(nx, nx); n],
            b: vec![DMatrix::zeros(nx, nu); n],
            k: vec![DVector::zeros(nu); n],
            gain: vec![DMatrix::zeros(nu, nx); n],
            knot: Knot::empty(),
            needs,
            dx: DVector::zeros(nx),
            lambda: vec![Vec::new(); n],
            backward: Backward::new(nx, nu),
        }
    }
}

/// Refuses a problem that does not fit the dynamics: `x0` of `nx` entries, at least one
/// knot, every `u_k` of `nu`, a cost that fits, and a state that remembers the inputs when
/// the cost reads their previous values.
fn check<S: System>(
    dynamics: &DiscreteSystem<S>,
    cost: &dyn Cost,
    x0: &DVector<f64>,
    u: &[DVector<f64>],
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nx, nu) = (dynamics.states(), dynamics.controls());
    let bad = |m: String| Err(SimError::InvalidInput(m));
    if cost.needs().input_memory && !dynamics.has_input_memory() {
        return bad(
            "the cost differences inputs against their previous values (a `control_rate` term), but the system's state does not remember them: build it with `with_input_memory(true)`".into(),
        );
    }
    if x0.len() != nx {
        return bad(format!(
            "the start state has {} entries; the system's state has {nx}",
            x0.len()
        ));
    }
    if u.is_empty() {
        return bad("the horizon needs at least one knot (one control)".into());
    }
    if let Some((k, uk)) = u.iter().enumerate().find(|(_, uk)| uk.len() != nu) {
        return bad(format!(
            "the control at knot {k} has {} entries; the system has {nu} controls",
            uk.len()
        ));
    }
    if let Some(k) = u.iter().position(|uk| uk.iter().any(|v| !v.is_finite())) {
        return bad(format!("the control at knot {k} is not finite"));
    }
    cost.check(nx, nu).or_else(bad)
}

/// The total cost of the controls `u` from `x0` and its exact gradient with respect to every
/// `u_k`, by the adjoint recursion `λ_N = ℓ_N,x`, `λ_k = ℓ_x + A_kᵀλ_{k+1}`,
/// `∂J/∂u_k = ℓ_u + B_kᵀλ_{k+1}` on the rollout (docs/derivations.md §10).
pub fn cost_gradient<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x0: &DVector<f64>,
    u: &[DVector<f64>],
) -> Result<(f64, Vec<DVector<f64>>), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nx, nu, n) = (dynamics.states(), dynamics.controls(), u.len());
    check(dynamics, cost, x0, u)?;
    let mut work = Work {
        a: vec![DMatrix::zeros(nx, nx); n],
        b: vec![DMatrix::zeros(nx, nu); n],
        k: Vec::new(),
        gain: Vec::new(),
        knot: Knot::empty(),
        needs: cost.needs(),
        dx: DVector::zeros(0),
        lambda: vec![Vec::new(); n],
        backward: Backward::new(0, 0),
    };
    let mut x = vec![x0.clone(); n + 1];
    let total = rollout(
        dynamics,
        cost,
        &mut x,
        &mut u.to_vec(),
        &mut work,
        true,
        None,
    )?;
    let mut d = super::cost::Derivatives::zeros(nx, nu);
    dynamics.knot(n, x[n].as_slice(), &mut work.knot, true, work.needs)?;
    cost.terminal(&work.knot, Some(&mut d));
    let mut adjoint = d.lx.clone();
    let mut gradient = vec![DVector::zeros(nu); n];
    for k in (0..n).rev() {
        dynamics.knot(k, x[k].as_slice(), &mut work.knot, true, work.needs)?;
        cost.running(k, &work.knot, &u[k], Some(&mut d));
        gradient[k] = &d.lu + work.b[k].tr_mul(&adjoint);
        adjoint = &d.lx + work.a[k].tr_mul(&adjoint);
    }
    Ok((total, gradient))
}

/// Box limits on the controls, `(lower, upper)`.
/// Rolls `u` out from `x[0]` (filling `x`), returns the total cost; with `jacobians`, also
/// each step's `A`, `B`. With a `policy` `(x_plan, limits)` (the forward pass), each control
/// first gets the feedback `u_k += K_k (x_k − x_plan,k)` and is clamped to the limits.
fn rollout<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x: &mut [DVector<f64>],
    u: &mut [DVector<f64>],
    work: &mut Work,
    jacobians: bool,
    policy: Option<(&[DVector<f64>], Option<&Limits>)>,
) -> Result<f64, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = u.len();
    let mut total = 0.0;
    for k in 0..n {
        if let Some((plan, limits)) = policy {
            work.dx.copy_from(&x[k]);
            work.dx -= &plan[k];
            u[k].gemv(1.0, &work.gain[k], &work.dx, 1.0);
            if let Some((lo, hi)) = limits {
                for c in 0..u[k].len() {
                    u[k][c] = u[k][c].clamp(lo[c], hi[c]);
                }
            }
        }
        dynamics.knot(k, x[k].as_slice(), &mut work.knot, false, work.needs)?;
        total += cost.running(k, &work.knot, &u[k], None);
        // A forward pass's non-finite cost rejects its step; the start's has no fallback.
        if policy.is_none() && !total.is_finite() {
            return Err(not_finite(dynamics, k));
        }
        let (head, tail) = x.split_at_mut(k + 1);
        let jac = jacobians.then(|| (&mut work.a[k], &mut work.b[k]));
        dynamics.step(
            k,
            head[k].as_slice(),
            u[k].as_slice(),
            tail[0].as_mut_slice(),
            jac,
        )?;
        work.lambda[k].clear();
        work.lambda[k].extend_from_slice(dynamics.multipliers());
    }
    dynamics.knot(n, x[n].as_slice(), &mut work.knot, false, work.needs)?;
    let total = total + cost.terminal(&work.knot, None);
    if policy.is_none() && !total.is_finite() {
        return Err(not_finite(dynamics, n));
    }
    Ok(total)
}

/// The error of a starting rollout whose cost stops being finite at knot `k` (a motion too
/// fast for the step, or a cost that overflows).
fn not_finite<S: System>(dynamics: &DiscreteSystem<S>, k: usize) -> SimError
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    SimError::NonFinite {
        step: k,
        t: dynamics.t0 + k as f64 * dynamics.dt,
        what: "the cost of the initial guess rolled out".into(),
    }
}

/// The backward pass's buffers (sized once per solve): the value function `V_x`, `V_xx`,
/// the `Q` blocks, the cost's and (DDP) the dynamics' second-order terms, products.
struct Backward {
    d: Derivatives,
    vx: DVector<f64>,
    vxx: DMatrix<f64>,
    qx: DVector<f64>,
    qu: DVector<f64>,
    qxx: DMatrix<f64>,
    quu: DMatrix<f64>,
    qux: DMatrix<f64>,
    hxx: DMatrix<f64>,
    huu: DMatrix<f64>,
    hux: DMatrix<f64>,
    /// `V_xx A`, `V_xx B`, `Y = ½Q_uuK + Q_ux`, `Q_uu k`, and `Z = KᵀY`.
    vxx_a: DMatrix<f64>,
    vxx_b: DMatrix<f64>,
    quu_gain: DMatrix<f64>,
    quu_k: DVector<f64>,
    v: DMatrix<f64>,
    x2: Vec<f64>,
    qp: ControlQp,
    /// The factors of the dense products, packed.
    packing: Packing,
}

impl Backward {
    fn new(nx: usize, nu: usize) -> Self {
        Backward {
            d: Derivatives::zeros(nx, nu),
            vx: DVector::zeros(nx),
            vxx: DMatrix::zeros(nx, nx),
            qx: DVector::zeros(nx),
            qu: DVector::zeros(nu),
            qxx: DMatrix::zeros(nx, nx),
            quu: DMatrix::zeros(nu, nu),
            qux: DMatrix::zeros(nu, nx),
            hxx: DMatrix::zeros(nx, nx),
            huu: DMatrix::zeros(nu, nu),
            hux: DMatrix::zeros(nu, nx),
            vxx_a: DMatrix::zeros(nx, nx),
            vxx_b: DMatrix::zeros(nx, nu),
            quu_gain: DMatrix::zeros(nu, nx),
            quu_k: DVector::zeros(nu),
            v: DMatrix::zeros(nx, nx),
            x2: vec![0.0; nx],
            qp: ControlQp::new(nu, nx),
            packing: Packing::default(),
        }
    }
}

/// One backward pass's choices: the solver, the regularisation and the limits its control QP
/// keeps (none in the clamped phase).
struct Pass<'a> {
    solver: Solver,
    mu: f64,
    limits: Option<&'a Limits>,
}

/// What a backward pass tells the iteration.
struct Outcome {
    /// The largest feed-forward entry `max |k|` (reported).
    gradient: f64,
    /// The cost decrease the local model predicts for the full step (the convergence test).
    decrease: f64,
    /// Knots whose step's curvature entered (DDP's full model; 0 when every step went
    /// through contact, or for iLQR).
    curved: usize,
}

/// The backward pass: fills the gains and feed-forward terms, within the pass's limits;
/// returns `max |k|` and the predicted decrease, or `None` when some `Q_uu + μ s I` is not
/// positive definite (docs/derivations.md §10).
fn backward<S: System>(
    dynamics: &mut DiscreteSystem<S>,
    cost: &mut dyn Cost,
    x: &[DVector<f64>],
    u: &[DVector<f64>],
    work: &mut Work,
    pass: &Pass,
) -> Result<Option<Outcome>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = u.len();
    let bw = &mut work.backward;
    dynamics.knot(n, x[n].as_slice(), &mut work.knot, true, work.needs)?;
    cost.terminal(&work.knot, Some(&mut bw.d));
    bw.vx.copy_from(&bw.d.lx);
    bw.vxx.copy_from(&bw.d.lxx);
    let (mut gradient, mut decrease, mut curved) = (0.0f64, 0.0, 0);
    for k in (0..n).rev() {
        dynamics.knot(k, x[k].as_slice(), &mut work.knot, true, work.needs)?;
        cost.running(k, &work.knot, &u[k], Some(&mut bw.d));
        let (a, b) = (&work.a[k], &work.b[k]);
        // Q_x = ℓ_x + AᵀV_x, Q_u = ℓ_u + BᵀV_x, Q_xx = ℓ_xx + AᵀV_xxA, Q_uu = ℓ_uu + BᵀV_xxB,
        // Q_ux = ℓ_ux + BᵀV_xxA (our blocked products: nalgebra's gemm allocates).
        bw.qx.copy_from(&bw.d.lx);
        bw.qx.gemv_tr(1.0, a, &bw.vx, 1.0);
        bw.qu.copy_from(&bw.d.lu);
        bw.qu.gemv_tr(1.0, b, &bw.vx, 1.0);
        // V_xx packed once for V_xx A and V_xx B, V_xx A once for Q_xx and Q_ux.
        let pair = [&mut bw.vxx_a, &mut bw.vxx_b];
        mul_into_pair(pair, &bw.vxx, [a, b], &mut bw.packing);
        bw.qxx.copy_from(&bw.d.lxx);
        bw.qux.copy_from(&bw.d.lux);
        let (qxx, qux) = ((&mut bw.qxx, a), (&mut bw.qux, b));
        tr_mul_into_pair(qxx, qux, &bw.vxx_a, &mut bw.packing);
        bw.quu.copy_from(&bw.d.luu);
        tr_mul_into_symmetric(&mut bw.quu, b, &bw.vxx_b, 1.0, &mut bw.packing);
        // Through contact the step's curvature is not formed: Gauss–Newton at that knot.
        if pass.solver == Solver::Ddp
            && dynamics.contracted(
                k,
                x[k].as_slice(),
                u[k].as_slice(),
                bw.vx.as_slice(),
                &mut bw.x2,
                &mut bw.hxx,
                &mut bw.huu,
                &mut bw.hux,
            )?
        {
            curved += 1;
            bw.qxx += &bw.hxx;
            bw.quu += &bw.huu;
            bw.qux += &bw.hux;
        }
        // The regularised Q_uu + μ s I, in huu (free after the DDP terms are added), with
        // `s` the largest of Q_uu's diagonal: μ is relative, so a task whose weights are all
        // scaled by any factor takes the same steps (a Q_uu of zero is regularised by μ).
        bw.huu.copy_from(&bw.quu);
        let scale = (0..bw.huu.nrows()).fold(0.0f64, |s, c| s.max(bw.huu[(c, c)].abs()));
        let scale = if scale > 0.0 && scale.is_finite() {
            scale
        } else {
            1.0
        };
        for c in 0..bw.huu.nrows() {
            bw.huu[(c, c)] += pass.mu * scale;
        }
        let (kk, gain) = (&mut work.k[k], &mut work.gain[k]);
        if !bw
            .qp
            .solve(&bw.huu, &bw.qu, &bw.qux, &u[k], pass.limits, kk, gain)
        {
            return Ok(None);
        }
        gradient = gradient.max(kk.amax());
        // V_x = Q_x + KᵀQ_uu k + KᵀQ_u + Q_uxᵀk, V_xx = Q_xx + KᵀQ_uuK + KᵀQ_ux + Q_uxᵀK.
        bw.quu_k.gemv(1.0, &bw.quu, kk, 0.0);
        decrease -= kk.dot(&bw.qu) + 0.5 * kk.dot(&bw.quu_k);
        bw.vx.copy_from(&bw.qx);
        bw.vx.gemv_tr(1.0, gain, &bw.quu_k, 1.0);
        bw.vx.gemv_tr(1.0, gain, &bw.qu, 1.0);
        bw.vx.gemv_tr(1.0, &bw.qux, kk, 1.0);
        // KᵀQ_uuK + KᵀQ_ux + Q_uxᵀK = Z + Zᵀ with Z = KᵀY, Y = ½Q_uuK + Q_ux: one product
        // over the controls instead of three.
        mul_into(&mut bw.quu_gain, &bw.quu, gain, 0.0, &mut bw.packing);
        bw.quu_gain.scale_mut(0.5);
        bw.quu_gain += &bw.qux;
        tr_mul_into(&mut bw.v, gain, &bw.quu_gain, 0.0, &mut bw.packing);
        // Symmetric: each entry of the upper triangle formed once, mirrored (column-major).
        let nx = bw.v.nrows();
        let (qxx, v, vxx) = (bw.qxx.as_slice(), bw.v.as_slice(), bw.vxx.as_mut_slice());
        for j in 0..nx {
            for i in 0..=j {
                let (ij, ji) = (j * nx + i, i * nx + j);
                let x = 0.5 * (qxx[ij] + qxx[ji]) + (v[ij] + v[ji]);
                vxx[ij] = x;
                vxx[ji] = x;
            }
        }
    }
    Ok(Some(Outcome {
        gradient,
        decrease,
        curved,
    }))
}
