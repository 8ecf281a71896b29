//! The midpoint variational integrator in momentum form (paper §VII, DESIGN.md §4).
//!
//! With `L_d(q_k, q_{k+1}) = Δt · L(q_k + α(q_{k+1} − q_k), (q_{k+1} − q_k)/Δt)` (eq. (22)),
//! a step solves `p_k + D1 L_d(q_k, q_{k+1}) + f⁻ = 0` for `q_{k+1}` by Newton with the exact
//! Jacobian `D2 D1 L_d` (eq. (26)), then sets `p_{k+1} = D2 L_d(q_k, q_{k+1}) + f⁺`. Forces
//! `u` (damping and inputs) enter as discrete forces `f⁻ = (1−α)Δt u`, `f⁺ = αΔt u`, evaluated
//! at `(t_k + αΔt, q_α, (q_{k+1} − q_k)/Δt)`.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::dynamics::{total_force, GeneralizedForce};
use crate::error::SimError;
use crate::linalg::{cholesky_solve, lu_factor, lu_solve_factored, Pivots};
use crate::system::{Matrix, Order, System, Terms, Vector};

/// When the VI's Newton iteration re-evaluates its exact Jacobian (eq. (26)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JacobianUpdate {
    /// Exact Newton: a full second-order evaluation and a fresh factorisation every iteration.
    #[default]
    EveryIteration,
    /// Evaluate and factor the exact Jacobian once per step, at the predicted point, and reuse
    /// it (a chord iteration: later iterations need only first derivatives); refreshed when
    /// the residual stops halving. Converges to the same solution, usually in fewer full
    /// evaluations.
    OncePerStep,
}

/// Settings of the variational integrator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViSettings {
    /// Quadrature point `α ∈ [0, 1]`; `½` is the second-order midpoint rule.
    pub alpha: f64,
    /// Newton stops when `‖residual‖∞ ≤ tolerance · max(1, ‖p_k‖∞)`, or when an update is
    /// below the rounding of q (the residual then sits at its floor).
    pub tolerance: f64,
    pub max_iterations: usize,
    pub jacobian: JacobianUpdate,
}

impl Default for ViSettings {
    fn default() -> Self {
        ViSettings {
            alpha: 0.5,
            tolerance: 1e-12,
            max_iterations: 30,
            jacobian: JacobianUpdate::EveryIteration,
        }
    }
}

/// Variational-integrator workspace (nothing allocated per step).
#[derive(Clone, Debug)]
pub struct MidpointVi<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub settings: ViSettings,
    pub terms: Terms<N>,
    residual: Vector<N>,
    jacobian: Matrix<N>,
    factors: Matrix<N>,
    pivots: Pivots<N>,
    q_alpha: Vector<N>,
    velocity: Vector<N>,
    force: Vector<N>,
    /// The last step's average velocity `(q_{k+1} − q_k)/Δt`, used to predict the next.
    pub last_velocity: Vector<N>,
    /// Newton iterations of the last step.
    pub iterations: usize,
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub fn new(n: N, settings: ViSettings) -> Self {
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        MidpointVi {
            settings,
            terms: Terms::zeros(n),
            residual: z(),
            jacobian: Matrix::zeros_generic(n, n),
            factors: Matrix::zeros_generic(n, n),
            pivots: Pivots::<N>::zeros_generic(n, nalgebra::U1),
            q_alpha: z(),
            velocity: z(),
            force: z(),
            last_velocity: z(),
            iterations: 0,
        }
    }

    /// Starts from `(q0, q̇0)`: returns `p_0 = ∂L/∂q̇(q0, q̇0)` and primes the predictor.
    pub fn initial_momentum<S: System<N = N>>(
        &mut self,
        sys: &mut S,
        q0: &Vector<N>,
        dq0: &Vector<N>,
    ) -> Vector<N> {
        sys.lagrangian(q0, dq0, Order::First, &mut self.terms);
        self.last_velocity.copy_from(dq0);
        self.terms.dl_ddq.clone()
    }

    /// The residual `p_k + D1 L_d + f⁻` (eqs. (23), (25)) at the guess `q2`, and, with
    /// `jacobian`, its exact derivative with respect to `q2` (eq. (26) plus the damping
    /// term). Leaves `terms` evaluated at `(q_α, v)`.
    pub fn residual<S, F>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        t: f64,
        dt: f64,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        jacobian: bool,
    ) -> &Vector<N>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let a = self.settings.alpha;
        // q_α = q1 + α(q2 − q1), v = (q2 − q1)/Δt
        self.velocity.copy_from(q2);
        self.velocity -= q1;
        self.velocity /= dt;
        self.q_alpha.copy_from(q1);
        self.q_alpha.axpy(a * dt, &self.velocity, 1.0);
        let order = if jacobian { Order::Full } else { Order::First };
        sys.lagrangian(&self.q_alpha, &self.velocity, order, &mut self.terms);
        total_force(
            sys,
            force,
            t + a * dt,
            &self.q_alpha,
            &self.velocity,
            &mut self.force,
        );
        // p1 + (1−α)Δt ∂L/∂q − ∂L/∂q̇ + (1−α)Δt u
        self.residual.copy_from(p1);
        self.residual.axpy((1.0 - a) * dt, &self.terms.dl_dq, 1.0);
        self.residual -= &self.terms.dl_ddq;
        self.residual.axpy((1.0 - a) * dt, &self.force, 1.0);
        if jacobian {
            // D2 D1 L_d = (1−α)αΔt L_qq + (1−α) (L_q̇q)ᵀ − α L_q̇q − M/Δt, L_q̇q[i][j] = ∂²L/∂q̇_i∂q_j.
            let n = q1.len();
            let t = &self.terms;
            for i in 0..n {
                for j in 0..n {
                    self.jacobian[(i, j)] = (1.0 - a) * a * dt * t.d2l_dq_dq[(i, j)]
                        + (1.0 - a) * t.d2l_ddq_dq[(j, i)]
                        - a * t.d2l_ddq_dq[(i, j)]
                        - t.mass[(i, j)] / dt;
                }
                // Damping −c v: ∂f⁻_i/∂q2_i = −(1−α) c_i.
                self.jacobian[(i, i)] -= (1.0 - a) * sys.damping(i);
            }
        }
        &self.residual
    }

    /// The last computed Jacobian of the residual.
    pub fn jacobian(&self) -> &Matrix<N> {
        &self.jacobian
    }

    /// Advances `(q_k, p_k)` to `(q_{k+1}, p_{k+1})` in place. `step` labels errors.
    pub fn step<S, F>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        step: usize,
        t: f64,
        dt: f64,
        q: &mut Vector<N>,
        p: &mut Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        // Predict q_{k+1} = q_k + Δt v_last.
        q_next.copy_from(q);
        q_next.axpy(dt, &self.last_velocity, 1.0);
        let scale = p.amax().max(1.0);
        let reuse = self.settings.jacobian == JacobianUpdate::OncePerStep;
        let mut factored = false;
        let mut last_residual = f64::INFINITY;
        self.iterations = 0;
        loop {
            let fresh = !(reuse && factored);
            self.residual(sys, force, t, dt, q, p, q_next, fresh);
            let mut residual = self.residual.amax();
            if !residual.is_finite() {
                return Err(SimError::NonFinite {
                    step,
                    t,
                    what: "discrete Euler–Lagrange residual".into(),
                });
            }
            if residual <= self.settings.tolerance * scale {
                break;
            }
            if self.iterations >= self.settings.max_iterations {
                return Err(SimError::NewtonFailed {
                    step,
                    t,
                    iterations: self.iterations,
                    residual,
                });
            }
            let mut refactor = fresh;
            if !fresh && residual > 0.5 * last_residual {
                // The reused Jacobian has stopped paying: evaluate it here.
                self.residual(sys, force, t, dt, q, p, q_next, true);
                residual = self.residual.amax();
                refactor = true;
            }
            if refactor {
                self.factors.copy_from(&self.jacobian);
                lu_factor(&mut self.factors, &mut self.pivots).map_err(|i| {
                    SimError::SingularJacobian {
                        step,
                        t,
                        variable: sys.variable_name(i).to_string(),
                    }
                })?;
                factored = true;
            }
            last_residual = residual;
            self.iterations += 1;
            // Newton: J Δ = −f
            self.residual.neg_mut();
            lu_solve_factored(&self.factors, &self.pivots, &mut self.residual);
            *q_next += &self.residual;
            // An update lost in the last bits of q: the residual is at its rounding floor
            // (≈ ε‖M‖‖q‖/Δt), which a large, stiff model can hold above the tolerance.
            if self.residual.amax() <= 4.0 * f64::EPSILON * q_next.amax().max(1.0) {
                self.residual(sys, force, t, dt, q, p, q_next, false);
                break;
            }
        }
        // p_{k+1} = αΔt ∂L/∂q + ∂L/∂q̇ + αΔt u   (eq. (24) plus f⁺), terms at the solution.
        let a = self.settings.alpha;
        p.copy_from(&self.terms.dl_ddq);
        p.axpy(a * dt, &self.terms.dl_dq, 1.0);
        p.axpy(a * dt, &self.force, 1.0);
        self.last_velocity.copy_from(&self.velocity);
        std::mem::swap(q, q_next);
        if q.iter().chain(p.iter()).any(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                step,
                t: t + dt,
                what: "configuration or momentum".into(),
            });
        }
        Ok(())
    }

    /// The continuous velocity and energy at `(q, p)`: solves `M(q) q̇ = p` (the Legendre
    /// transform of a Lagrangian quadratic in q̇) and returns `E = ½ q̇·p + V(q)`.
    pub fn velocity_and_energy<S: System<N = N>>(
        &mut self,
        sys: &mut S,
        step: usize,
        t: f64,
        q: &Vector<N>,
        p: &Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<f64, SimError> {
        self.velocity.fill(0.0);
        sys.lagrangian(q, &self.velocity, Order::Dynamics, &mut self.terms);
        self.jacobian.copy_from(&self.terms.mass);
        dq.copy_from(p);
        cholesky_solve(&mut self.jacobian, dq).map_err(|(i, pivot)| {
            SimError::SingularMassMatrix {
                step,
                t,
                variable: sys.variable_name(i).to_string(),
                pivot,
            }
        })?;
        // L(q, 0) = −V(q)
        Ok(0.5 * dq.dot(p) - self.terms.l)
    }
}
