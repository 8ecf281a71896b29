//! iLQR and DDP on the VI with box limits on the controls (docs/derivations.md §10): a
//! rollout; a backward pass `Q_x = ℓ_x + AᵀV_x`, `Q_u = ℓ_u + BᵀV_x`,
//! `Q_xx = ℓ_xx + AᵀV_xxA`, `Q_uu = ℓ_uu + BᵀV_xxB + μI`, `Q_ux = ℓ_ux + BᵀV_xxA` (DDP adds
//! the step's second derivatives contracted with `V_x`); the control QP solved by projected
//! Newton within the limits (box-DDP: clamped controls get no feedback); a forward pass with
//! a backtracking line search on the true cost; Levenberg–Marquardt `μ` raised when `Q_uu` is
//! not positive definite or no step length lowers the cost, lowered after a success.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use super::cost::Cost;
use super::vi_dynamics::ViDynamics;
use crate::error::SimError;
use crate::system::System;

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
    /// Converged when the largest feed-forward change is below this.
    pub gradient_tolerance: f64,
    /// Box limits per control `[lo, hi]` (None: unbounded).
    pub limits: Option<(DVector<f64>, DVector<f64>)>,
    /// The first regularisation.
    pub mu: f64,
}

impl Default for IlqrSettings {
    fn default() -> Self {
        IlqrSettings {
            solver: Solver::Ilqr,
            max_iterations: 100,
            cost_tolerance: 1e-9,
            gradient_tolerance: 1e-8,
            limits: None,
            mu: 1e-6,
        }
    }
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
    /// Whether a convergence test was met (otherwise the best trajectory found).
    pub converged: bool,
    /// Every iteration.
    pub history: Vec<Iteration>,
}

/// Per-knot buffers, allocated once per solve.
struct Knots {
    a: Vec<DMatrix<f64>>,
    b: Vec<DMatrix<f64>>,
    k: Vec<DVector<f64>>,
    gain: Vec<DMatrix<f64>>,
}

/// Optimises the controls of `dynamics` over `knots` steps from `x0`, starting from `u`.
pub fn solve<S: System>(
    dynamics: &mut ViDynamics<S>,
    cost: &dyn Cost,
    x0: &DVector<f64>,
    mut u: Vec<DVector<f64>>,
    settings: &IlqrSettings,
) -> Result<Solution, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nx, nu, n) = (dynamics.states(), dynamics.controls(), u.len());
    check(nx, nu, cost, x0, &u)?;
    let settled = |x: f64| x.is_finite() && x >= 0.0;
    if !(settled(settings.cost_tolerance)
        && settled(settings.gradient_tolerance)
        && settled(settings.mu))
    {
        return Err(SimError::InvalidInput(format!(
            "the optimiser's cost tolerance ({}), gradient tolerance ({}) and regularisation ({}) must be finite and non-negative",
            settings.cost_tolerance, settings.gradient_tolerance, settings.mu
        )));
    }
    if let Some((lo, hi)) = &settings.limits {
        if lo.len() != nu || hi.len() != nu {
            return Err(SimError::InvalidInput(format!(
                "the limits have {} lower and {} upper bounds; the problem has {nu} controls",
                lo.len(),
                hi.len()
            )));
        }
    }
    if let Some((lo, hi)) = &settings.limits {
        for uk in u.iter_mut() {
            for c in 0..nu {
                if lo[c].is_nan() || hi[c].is_nan() || lo[c] > hi[c] {
                    return Err(SimError::InvalidInput(format!(
                        "the limits of control {c} are [{}, {}]: the lower must not exceed the upper",
                        lo[c], hi[c]
                    )));
                }
                uk[c] = uk[c].clamp(lo[c], hi[c]);
            }
        }
    }
    let mut knots = Knots {
        a: vec![DMatrix::zeros(nx, nx); n],
        b: vec![DMatrix::zeros(nx, nu); n],
        k: vec![DVector::zeros(nu); n],
        gain: vec![DMatrix::zeros(nu, nx); n],
    };
    let mut x = vec![x0.clone(); n + 1];
    let mut total = rollout(dynamics, cost, &mut x, &u, Some(&mut knots))?;
    let (mut x_new, mut u_new) = (x.clone(), u.clone());
    let mut mu = settings.mu;
    let mut history = Vec::new();
    let mut converged = false;
    for _ in 0..settings.max_iterations {
        let backward = backward(dynamics, cost, &x, &u, &mut knots, mu, settings);
        let gradient = match backward {
            Ok(g) => g,
            Err(_) => {
                mu = (mu * 10.0).max(1e-6);
                if mu > 1e10 {
                    break;
                }
                continue;
            }
        };
        if gradient < settings.gradient_tolerance {
            converged = true;
            history.push(Iteration {
                cost: total,
                step: 0.0,
                mu,
                gradient,
            });
            break;
        }
        // Forward pass: the first step length that lowers the true cost.
        let mut accepted = 0.0;
        let mut alpha = 1.0;
        while alpha > 1e-4 {
            x_new[0].copy_from(x0);
            let mut trial = 0.0;
            let mut ok = true;
            for k in 0..n {
                let dx = &x_new[k] - &x[k];
                u_new[k] = &u[k] + &knots.k[k] * alpha + &knots.gain[k] * dx;
                if let Some((lo, hi)) = &settings.limits {
                    for c in 0..nu {
                        u_new[k][c] = u_new[k][c].clamp(lo[c], hi[c]);
                    }
                }
                trial += cost.running(k, &x_new[k], &u_new[k], None);
                let (head, tail) = x_new.split_at_mut(k + 1);
                if dynamics
                    .step(
                        k,
                        head[k].as_slice(),
                        u_new[k].as_slice(),
                        tail[0].as_mut_slice(),
                        None,
                    )
                    .is_err()
                {
                    ok = false;
                    break;
                }
            }
            if ok {
                trial += cost.terminal(&x_new[n], None);
                if trial.is_finite() && trial < total {
                    accepted = alpha;
                    break;
                }
            }
            alpha *= 0.5;
        }
        if accepted == 0.0 {
            mu = (mu * 10.0).max(1e-6);
            history.push(Iteration {
                cost: total,
                step: 0.0,
                mu,
                gradient,
            });
            if mu > 1e10 {
                break;
            }
            continue;
        }
        std::mem::swap(&mut x, &mut x_new);
        std::mem::swap(&mut u, &mut u_new);
        let previous = total;
        total = rollout(dynamics, cost, &mut x, &u, Some(&mut knots))?;
        mu = (mu * 0.1).max(1e-12);
        history.push(Iteration {
            cost: total,
            step: accepted,
            mu,
            gradient,
        });
        if previous - total < settings.cost_tolerance * previous.abs().max(f64::MIN_POSITIVE) {
            converged = true;
            break;
        }
    }
    Ok(Solution {
        gains: knots.gain,
        feedforward: knots.k,
        x,
        u,
        cost: total,
        converged,
        history,
    })
}

/// Refuses a problem whose sizes do not fit the dynamics: `x0` of `nx` entries, at least one
/// knot, every `u_k` of `nu`, and a cost that fits.
fn check(
    nx: usize,
    nu: usize,
    cost: &dyn Cost,
    x0: &DVector<f64>,
    u: &[DVector<f64>],
) -> Result<(), SimError> {
    let bad = |m: String| Err(SimError::InvalidInput(m));
    if x0.len() != nx {
        return bad(format!(
            "the start state has {} entries; the system's state (q_d, p_d) has {nx}",
            x0.len()
        ));
    }
    if u.is_empty() {
        return bad("the horizon needs at least one knot (one control)".into());
    }
    if let Some((k, uk)) = u.iter().enumerate().find(|(_, uk)| uk.len() != nu) {
        return bad(format!(
            "the control at knot {k} has {} entries; the system has {nu} inputs",
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
    dynamics: &mut ViDynamics<S>,
    cost: &dyn Cost,
    x0: &DVector<f64>,
    u: &[DVector<f64>],
) -> Result<(f64, Vec<DVector<f64>>), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nx, nu, n) = (dynamics.states(), dynamics.controls(), u.len());
    check(nx, nu, cost, x0, u)?;
    let mut knots = Knots {
        a: vec![DMatrix::zeros(nx, nx); n],
        b: vec![DMatrix::zeros(nx, nu); n],
        k: Vec::new(),
        gain: Vec::new(),
    };
    let mut x = vec![x0.clone(); n + 1];
    let total = rollout(dynamics, cost, &mut x, u, Some(&mut knots))?;
    let mut d = super::cost::Derivatives::zeros(nx, nu);
    cost.terminal(&x[n], Some(&mut d));
    let mut adjoint = d.lx.clone();
    let mut gradient = vec![DVector::zeros(nu); n];
    for k in (0..n).rev() {
        cost.running(k, &x[k], &u[k], Some(&mut d));
        gradient[k] = &d.lu + knots.b[k].tr_mul(&adjoint);
        adjoint = &d.lx + knots.a[k].tr_mul(&adjoint);
    }
    Ok((total, gradient))
}

/// Rolls `u` out from `x[0]` (filling `x`), returns the total cost; with `knots`, also each
/// step's `A`, `B`.
fn rollout<S: System>(
    dynamics: &mut ViDynamics<S>,
    cost: &dyn Cost,
    x: &mut [DVector<f64>],
    u: &[DVector<f64>],
    knots: Option<&mut Knots>,
) -> Result<f64, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = u.len();
    let mut total = 0.0;
    let mut knots = knots;
    for k in 0..n {
        total += cost.running(k, &x[k], &u[k], None);
        let (head, tail) = x.split_at_mut(k + 1);
        let jac = knots.as_mut().map(|kn| {
            let Knots { a, b, .. } = &mut **kn;
            (&mut a[k], &mut b[k])
        });
        dynamics.step(
            k,
            head[k].as_slice(),
            u[k].as_slice(),
            tail[0].as_mut_slice(),
            jac,
        )?;
    }
    Ok(total + cost.terminal(&x[n], None))
}

/// The backward pass: fills the gains and feed-forward terms; returns `max |k|`, or an error
/// when some `Q_uu` is not positive definite at this `μ`.
fn backward<S: System>(
    dynamics: &mut ViDynamics<S>,
    cost: &dyn Cost,
    x: &[DVector<f64>],
    u: &[DVector<f64>],
    knots: &mut Knots,
    mu: f64,
    settings: &IlqrSettings,
) -> Result<f64, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = u.len();
    let (nx, nu) = (dynamics.states(), dynamics.controls());
    let mut d = super::cost::Derivatives::zeros(nx, nu);
    cost.terminal(&x[n], Some(&mut d));
    let (mut vx, mut vxx) = (d.lx.clone(), d.lxx.clone());
    let mut gradient = 0.0f64;
    let (mut hxx, mut huu, mut hux) = (
        DMatrix::zeros(nx, nx),
        DMatrix::zeros(nu, nu),
        DMatrix::zeros(nu, nx),
    );
    for k in (0..n).rev() {
        cost.running(k, &x[k], &u[k], Some(&mut d));
        let (a, b) = (&knots.a[k], &knots.b[k]);
        let qx = &d.lx + a.tr_mul(&vx);
        let qu = &d.lu + b.tr_mul(&vx);
        let mut qxx = &d.lxx + a.tr_mul(&(&vxx * a));
        let mut quu = &d.luu + b.tr_mul(&(&vxx * b));
        let mut qux = &d.lux + b.tr_mul(&(&vxx * a));
        if settings.solver == Solver::Ddp {
            // The rollout left the VI at the last step; redo step k for its second derivatives.
            let mut x2 = DVector::zeros(nx);
            dynamics.step(k, x[k].as_slice(), u[k].as_slice(), x2.as_mut_slice(), None)?;
            dynamics.contracted(
                k,
                u[k].as_slice(),
                vx.as_slice(),
                &mut hxx,
                &mut huu,
                &mut hux,
            )?;
            qxx += &hxx;
            quu += &huu;
            qux += &hux;
        }
        let reg = &quu + DMatrix::identity(nu, nu) * mu;
        let (kk, gain) = control_qp(&reg, &qu, &qux, &u[k], settings)?;
        gradient = gradient.max(kk.amax());
        // V_x = Q_x + KᵀQ_uu k + KᵀQ_u + Q_uxᵀk, V_xx = Q_xx + KᵀQ_uuK + KᵀQ_ux + Q_uxᵀK.
        vx = &qx + gain.tr_mul(&(&quu * &kk)) + gain.tr_mul(&qu) + qux.tr_mul(&kk);
        let v = &qxx + gain.tr_mul(&(&quu * &gain)) + gain.tr_mul(&qux) + qux.tr_mul(&gain);
        vxx = (&v + v.transpose()) * 0.5;
        knots.k[k] = kk;
        knots.gain[k] = gain;
    }
    Ok(gradient)
}

/// The control QP `min ½δuᵀHδu + gᵀδu` within the limits shifted by `u`: projected Newton
/// (Bertsekas; Tassa et al. 2014's box-DDP). Returns the feed-forward and the feedback (zero
/// on the clamped controls: `−H_ff⁻¹ Q_ux,f` on the free ones).
fn control_qp(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    qux: &DMatrix<f64>,
    u: &DVector<f64>,
    settings: &IlqrSettings,
) -> Result<(DVector<f64>, DMatrix<f64>), SimError> {
    let nu = g.len();
    let not_pd = || SimError::InvalidInput("Q_uu is not positive definite".into());
    let Some((lo, hi)) = &settings.limits else {
        let chol = h.clone().cholesky().ok_or_else(not_pd)?;
        return Ok((-chol.solve(g), -chol.solve(qux)));
    };
    let (lo, hi) = (lo - u, hi - u);
    let mut x = DVector::zeros(nu);
    let value = |x: &DVector<f64>| 0.5 * x.dot(&(h * x)) + g.dot(x);
    let mut free = vec![true; nu];
    for _ in 0..100 {
        let grad = g + h * &x;
        for c in 0..nu {
            free[c] = !((x[c] <= lo[c] && grad[c] > 0.0) || (x[c] >= hi[c] && grad[c] < 0.0));
        }
        let idx: Vec<usize> = (0..nu).filter(|&c| free[c]).collect();
        if idx.is_empty() {
            break;
        }
        let hff = DMatrix::from_fn(idx.len(), idx.len(), |r, c| h[(idx[r], idx[c])]);
        let gf = DVector::from_fn(idx.len(), |r, _| grad[idx[r]]);
        if gf.amax() < 1e-13 * g.amax().max(1.0) {
            break;
        }
        let step = -hff.cholesky().ok_or_else(not_pd)?.solve(&gf);
        // Projected backtracking.
        let (f0, mut alpha, mut moved) = (value(&x), 1.0, false);
        while alpha > 1e-10 {
            let mut y = x.clone();
            for (r, &c) in idx.iter().enumerate() {
                y[c] = (x[c] + alpha * step[r]).clamp(lo[c], hi[c]);
            }
            if value(&y) < f0 - 1e-14 * f0.abs() {
                x = y;
                moved = true;
                break;
            }
            alpha *= 0.5;
        }
        if !moved {
            break;
        }
    }
    let idx: Vec<usize> = (0..nu).filter(|&c| free[c]).collect();
    let mut gain = DMatrix::zeros(nu, qux.ncols());
    if !idx.is_empty() {
        let hff = DMatrix::from_fn(idx.len(), idx.len(), |r, c| h[(idx[r], idx[c])]);
        let chol = hff.cholesky().ok_or_else(not_pd)?;
        let rows = DMatrix::from_fn(idx.len(), qux.ncols(), |r, c| qux[(idx[r], c)]);
        let kf = -chol.solve(&rows);
        for (r, &c) in idx.iter().enumerate() {
            gain.set_row(c, &kf.row(r));
        }
    }
    Ok((x, gain))
}
