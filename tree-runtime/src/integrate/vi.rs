//! The midpoint variational integrator in momentum form (paper §VII; with constraints,
//! kinematic inputs and forcing as in docs/derivations.md §7).
//!
//! With `L_d(q₁, q₂) = Δt · L(q₁ + α(q₂ − q₁), (q₂ − q₁)/Δt)` (eq. (22)), a step solves, for
//! the dynamic part of `q₂` and the constraint forces `λ`,
//! `p₁ + D₁L_d(q₁, q₂) + f⁻ + Δt·Dh(q₁)ᵀλ = 0` (dynamic rows) and `h(q₂) = 0`, by Newton with
//! the exact Jacobian (eq. (26), the forces' derivatives, `Δt·Dh(q₁)ᵀ` and `Dh(q₂)`); the
//! kinematic part of `q₂` is its prescription at `t₂`. Then `p₂ = D₂L_d(q₁, q₂) + f⁺`.
//! In trep's notation `p₁ + D₁L_d + f⁻ − Dh(q₁)ᵀλ₁ = 0`, so trep's `λ₁ = −Δt·λ`: ours is a
//! force, comparable with the continuous multipliers.
//!
//! Forces `F + u` (the model's damping and dampers, plus the caller's `u`) are evaluated at
//! `(t₁ + αΔt, q_α, (q₂ − q₁)/Δt)`: [`Forcing::Split`] puts `f⁻ = (1−α)Δt F`, `f⁺ = αΔt F`
//! (second order), [`Forcing::Left`] `f⁻ = Δt F`, `f⁺ = 0` (trep's, first order in F).

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim, Dyn};

use crate::dynamics::{
    prescribe, solve_reduced, GeneralizedForce, Prescription, ReducedKkt, Split,
};
use crate::error::SimError;
use crate::linalg::{lu_factor, lu_solve_factored, Pivots};
use crate::system::{ConstraintTerms, Order, System, Terms, Vector};

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

/// How the forces enter the discrete equations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Forcing {
    /// `f⁻ = (1−α)Δt F`, `f⁺ = αΔt F`: second order at α = ½.
    #[default]
    Split,
    /// `f⁻ = Δt F`, `f⁺ = 0`: trep's convention, first order in the force.
    Left,
}

/// Settings of the variational integrator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViSettings {
    /// Quadrature point `α ∈ [0, 1]`; `½` is the second-order midpoint rule.
    pub alpha: f64,
    /// Newton stops when `‖residual‖∞ ≤ tolerance · max(1, ‖p_k‖∞)` and every `|h_r(q₂)|` is
    /// below `constraint_tolerance`, or when an update is below the rounding of q (the
    /// residual then sits at its floor).
    pub tolerance: f64,
    pub constraint_tolerance: f64,
    pub max_iterations: usize,
    pub jacobian: JacobianUpdate,
    pub forcing: Forcing,
    /// When Newton fails, retry the step as two half steps, recursively, this deep (0: never).
    pub max_subdivisions: usize,
}

impl Default for ViSettings {
    fn default() -> Self {
        ViSettings {
            alpha: 0.5,
            tolerance: 1e-12,
            constraint_tolerance: 1e-12,
            max_iterations: 30,
            jacobian: JacobianUpdate::EveryIteration,
            forcing: Forcing::Split,
            max_subdivisions: 4,
        }
    }
}

/// A state saved before a step that may be subdivided: `(q, p, last velocity, λ)`.
type SavedState<N> = (Vector<N>, Vector<N>, Vector<N>, DVector<f64>);

/// Variational-integrator workspace (nothing allocated per step).
#[derive(Clone, Debug)]
pub struct MidpointVi<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub settings: ViSettings,
    pub terms: Terms<N>,
    /// Constraints at the current guess `q₂` (and, after `velocity_and_energy`, at its `q`).
    pub constraint_terms: ConstraintTerms,
    /// `Dh(q₁)` of the step under way.
    dh1: DMatrix<f64>,
    pub split: Split,
    /// The constraint forces of the last step (see the module docs for trep's scaling).
    pub lambda: DVector<f64>,
    residual: DVector<f64>,
    jacobian: DMatrix<f64>,
    factors: DMatrix<f64>,
    pivots: Pivots<Dyn>,
    q_alpha: Vector<N>,
    velocity: Vector<N>,
    force: Vector<N>,
    reduced: ReducedKkt,
    /// Multipliers of the velocity projection in `velocity_and_energy`.
    projection: DVector<f64>,
    /// States saved before a step, one per subdivision level: `(q, p, last velocity, λ)`.
    saved: Vec<SavedState<N>>,
    /// The last step's average velocity `(q_{k+1} − q_k)/Δt`, used to predict the next.
    pub last_velocity: Vector<N>,
    /// Newton iterations of the last step (all its sub-steps).
    pub iterations: usize,
    /// Subdivisions the last step needed (0 when it went through whole).
    pub subdivisions: usize,
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub fn new<S: System<N = N>>(sys: &S, settings: ViSettings) -> Self {
        let n = sys.dim();
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        let split = Split::of(sys);
        let (nd, m) = (split.dynamic.len(), split.rows);
        MidpointVi {
            settings,
            terms: Terms::zeros(n),
            constraint_terms: ConstraintTerms::zeros(m, n.value()),
            dh1: DMatrix::zeros(m, n.value()),
            lambda: DVector::zeros(m),
            residual: DVector::zeros(nd + m),
            jacobian: DMatrix::zeros(nd + m, nd + m),
            factors: DMatrix::zeros(nd + m, nd + m),
            pivots: Pivots::<Dyn>::zeros_generic(Dyn(nd + m), nalgebra::U1),
            q_alpha: z(),
            velocity: z(),
            force: z(),
            reduced: ReducedKkt::new(nd, m),
            projection: DVector::zeros(m),
            saved: (0..=settings.max_subdivisions)
                .map(|_| (z(), z(), z(), DVector::zeros(m)))
                .collect(),
            last_velocity: z(),
            iterations: 0,
            subdivisions: 0,
            split,
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

    /// Evaluates `Dh(q₁)` for the step from `q₁` (before [`Self::residual`]).
    pub fn prepare<S: System<N = N>>(&mut self, sys: &mut S, q1: &Vector<N>) {
        if self.split.rows > 0 {
            self.velocity.fill(0.0);
            sys.constraints(q1, &self.velocity, Order::First, &mut self.constraint_terms);
            self.dh1.copy_from(&self.constraint_terms.dh);
        }
    }

    /// The residual at the guess `(q₂, λ)` — dynamic rows `p₁ + D₁L_d + f⁻ + Δt Dh(q₁)ᵀλ`
    /// (eqs. (23), (25)), then `h(q₂)` — and, with `jacobian`, its exact derivative with
    /// respect to `(q₂_d, λ)` (eq. (26) plus the forces' derivatives and the constraint
    /// blocks). `q₂`'s kinematic entries must hold their prescription; `λ` is
    /// [`Self::lambda`]; [`Self::prepare`] must have been called for `q₁`. Leaves `terms`
    /// evaluated at `(q_α, v)`.
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
    ) -> &DVector<f64>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let a = self.settings.alpha;
        let left = match self.settings.forcing {
            Forcing::Split => 1.0 - a,
            Forcing::Left => 1.0,
        };
        // q_α = q1 + α(q2 − q1), v = (q2 − q1)/Δt
        self.velocity.copy_from(q2);
        self.velocity -= q1;
        self.velocity /= dt;
        self.q_alpha.copy_from(q1);
        self.q_alpha.axpy(a * dt, &self.velocity, 1.0);
        let order = if jacobian { Order::Full } else { Order::First };
        sys.lagrangian(&self.q_alpha, &self.velocity, order, &mut self.terms);
        self.force.copy_from(&self.terms.force);
        force.add_force(t + a * dt, &self.q_alpha, &self.velocity, &mut self.force);
        let (split, t2) = (&self.split, &self.terms);
        let nd = split.dynamic.len();
        // p1 + (1−α)Δt ∂L/∂q − ∂L/∂q̇ + f⁻ + Δt Dh(q1)ᵀλ
        for (r, &i) in split.dynamic.iter().enumerate() {
            let mut x =
                p1[i] + (1.0 - a) * dt * t2.dl_dq[i] - t2.dl_ddq[i] + left * dt * self.force[i];
            for s in 0..split.rows {
                x += dt * self.dh1[(s, i)] * self.lambda[s];
            }
            self.residual[r] = x;
        }
        if split.rows > 0 {
            let zero = &mut self.q_alpha;
            zero.fill(0.0);
            sys.constraints(q2, zero, Order::First, &mut self.constraint_terms);
            for s in 0..split.rows {
                self.residual[nd + s] = self.constraint_terms.h[s];
            }
        }
        if jacobian {
            let t = &self.terms;
            // D2 D1 L_d = (1−α)αΔt L_qq + (1−α) (L_q̇q)ᵀ − α L_q̇q − M/Δt,
            // L_q̇q[i][j] = ∂²L/∂q̇_i∂q_j; plus ∂f⁻/∂q2 = wΔt(α ∂F/∂q + ∂F/∂q̇ /Δt).
            for (r, &i) in split.dynamic.iter().enumerate() {
                for (c, &j) in split.dynamic.iter().enumerate() {
                    self.jacobian[(r, c)] = (1.0 - a) * a * dt * t.d2l_dq_dq[(i, j)]
                        + (1.0 - a) * t.d2l_ddq_dq[(j, i)]
                        - a * t.d2l_ddq_dq[(i, j)]
                        - t.mass[(i, j)] / dt
                        + left * (a * dt * t.dforce_dq[(i, j)] + t.dforce_ddq[(i, j)]);
                }
                for s in 0..split.rows {
                    self.jacobian[(r, nd + s)] = dt * self.dh1[(s, i)];
                }
            }
            for s in 0..split.rows {
                for (c, &j) in split.dynamic.iter().enumerate() {
                    self.jacobian[(nd + s, c)] = self.constraint_terms.dh[(s, j)];
                }
                for s2 in 0..split.rows {
                    self.jacobian[(nd + s, nd + s2)] = 0.0;
                }
            }
        }
        &self.residual
    }

    /// The Newton Jacobian of the last [`Self::residual`] call with `jacobian` set: rows and
    /// columns are the dynamic variables, then the constraints.
    pub fn jacobian(&self) -> &DMatrix<f64> {
        &self.jacobian
    }

    /// Advances `(q_k, p_k)` to `(q_{k+1}, p_{k+1})` in place. When Newton fails the step is
    /// retried as two half steps, recursively up to `max_subdivisions` deep. `step` labels
    /// errors.
    pub fn step<S, F, P>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        motion: &mut P,
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
        P: Prescription,
    {
        self.iterations = 0;
        self.subdivisions = 0;
        self.advance(sys, force, motion, step, t, dt, q, p, q_next, 0)
    }

    fn advance<S, F, P>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        motion: &mut P,
        step: usize,
        t: f64,
        dt: f64,
        q: &mut Vector<N>,
        p: &mut Vector<N>,
        q_next: &mut Vector<N>,
        depth: usize,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let can_split = depth < self.settings.max_subdivisions;
        if can_split {
            let saved = &mut self.saved[depth];
            saved.0.copy_from(q);
            saved.1.copy_from(p);
            saved.2.copy_from(&self.last_velocity);
            saved.3.copy_from(&self.lambda);
        }
        match self.step_once(sys, force, motion, step, t, dt, q, p, q_next) {
            Err(SimError::NewtonFailed { .. } | SimError::SingularJacobian { .. })
            | Err(SimError::NonFinite { .. })
                if can_split =>
            {
                let saved = &self.saved[depth];
                q.copy_from(&saved.0);
                p.copy_from(&saved.1);
                self.last_velocity.copy_from(&saved.2);
                self.lambda.copy_from(&saved.3);
                self.subdivisions += 1;
                let h = 0.5 * dt;
                self.advance(sys, force, motion, step, t, h, q, p, q_next, depth + 1)?;
                self.advance(sys, force, motion, step, t + h, h, q, p, q_next, depth + 1)
            }
            other => other,
        }
    }

    /// One step of length `dt`, no subdivision.
    fn step_once<S, F, P>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        motion: &mut P,
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
        P: Prescription,
    {
        self.prepare(sys, q);
        // Predict q_{k+1} = q_k + Δt v_last; kinematic entries from their prescription.
        q_next.copy_from(q);
        q_next.axpy(dt, &self.last_velocity, 1.0);
        for &i in &self.split.kinematic {
            q_next[i] = motion.kinematic(i, t + dt)[0];
        }
        let nd = self.split.dynamic.len();
        let scale = self
            .split
            .dynamic
            .iter()
            .fold(1.0f64, |m, &i| m.max(p[i].abs()));
        let reuse = self.settings.jacobian == JacobianUpdate::OncePerStep;
        let mut factored = false;
        let mut last_residual = f64::INFINITY;
        let mut iterations = 0;
        loop {
            let fresh = !(reuse && factored);
            self.residual(sys, force, t, dt, q, p, q_next, fresh);
            let (mut residual, violation) = self.residual_norms(nd);
            if !residual.is_finite() || !violation.is_finite() {
                self.iterations += iterations;
                return Err(SimError::NonFinite {
                    step,
                    t,
                    what: "discrete Euler–Lagrange residual".into(),
                });
            }
            if residual <= self.settings.tolerance * scale
                && violation <= self.settings.constraint_tolerance
            {
                break;
            }
            if iterations >= self.settings.max_iterations {
                self.iterations += iterations;
                return Err(SimError::NewtonFailed {
                    step,
                    t,
                    iterations,
                    residual: residual.max(violation),
                });
            }
            let mut refactor = fresh;
            let combined = residual + violation;
            if !fresh && combined > 0.5 * last_residual {
                // The reused Jacobian has stopped paying: evaluate it here.
                self.residual(sys, force, t, dt, q, p, q_next, true);
                residual = self.residual_norms(nd).0;
                refactor = true;
            }
            if refactor {
                self.factors.copy_from(&self.jacobian);
                lu_factor::<Dyn>(&mut self.factors, &mut self.pivots).map_err(|i| {
                    SimError::SingularJacobian {
                        step,
                        t,
                        variable: if i < nd {
                            sys.variable_name(self.split.dynamic[i]).to_string()
                        } else {
                            format!("λ of constraint `{}`", sys.constraint_name(i - nd))
                        },
                    }
                })?;
                factored = true;
            }
            last_residual = residual + violation;
            iterations += 1;
            // Newton: J Δ = −f
            self.residual.neg_mut();
            lu_solve_factored::<Dyn>(&self.factors, &self.pivots, &mut self.residual);
            let mut largest: f64 = 0.0;
            for (r, &i) in self.split.dynamic.iter().enumerate() {
                q_next[i] += self.residual[r];
                largest = largest.max(self.residual[r].abs());
            }
            for s in 0..self.split.rows {
                self.lambda[s] += self.residual[nd + s];
            }
            // An update lost in the last bits of q: the residual is at its rounding floor
            // (≈ ε‖M‖‖q‖/Δt), which a large, stiff model can hold above the tolerance.
            if largest <= 4.0 * f64::EPSILON * q_next.amax().max(1.0) {
                self.residual(sys, force, t, dt, q, p, q_next, false);
                break;
            }
        }
        self.iterations += iterations;
        // p_{k+1} = αΔt ∂L/∂q + ∂L/∂q̇ + f⁺   (eq. (24)), terms at the solution.
        let a = self.settings.alpha;
        let plus = match self.settings.forcing {
            Forcing::Split => a * dt,
            Forcing::Left => 0.0,
        };
        p.copy_from(&self.terms.dl_ddq);
        p.axpy(a * dt, &self.terms.dl_dq, 1.0);
        p.axpy(plus, &self.force, 1.0);
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

    /// `(max |dynamic residual|, max |h|)` of the residual vector.
    fn residual_norms(&self, nd: usize) -> (f64, f64) {
        let r = self.residual.as_slice();
        let amax = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        (amax(&r[..nd]), amax(&r[nd..]))
    }

    /// The continuous velocity and energy at `(q, p)` and time `t`: kinematic `q̇` from the
    /// prescription, dynamic `q̇ = M_dd⁻¹(p_d − M_dk q̇_k)` (the Legendre transform), made
    /// consistent with the constraints (`Dh q̇ = 0`, projected in the `M_dd` metric); returns
    /// `E = ½ q̇ᵀM q̇ + V(q)`. Not conserved while kinematic inputs move.
    pub fn velocity_and_energy<S, P>(
        &mut self,
        sys: &mut S,
        motion: &mut P,
        step: usize,
        t: f64,
        q: &Vector<N>,
        p: &Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<f64, SimError>
    where
        S: System<N = N>,
        P: Prescription,
    {
        self.velocity.fill(0.0);
        sys.lagrangian(q, &self.velocity, Order::Dynamics, &mut self.terms);
        self.q_alpha.copy_from(q);
        prescribe(
            &self.split.kinematic,
            motion,
            t,
            &mut self.q_alpha,
            dq,
            None,
        );
        let split = &self.split;
        let k = &mut self.reduced;
        let mass = &self.terms.mass;
        for (r, &i) in split.dynamic.iter().enumerate() {
            let mut x = p[i];
            for &j in &split.kinematic {
                x -= mass[(i, j)] * dq[j];
            }
            k.rhs[r] = x;
            for (c, &j) in split.dynamic.iter().enumerate() {
                k.mdd[(r, c)] = mass[(i, j)];
            }
        }
        if split.rows > 0 {
            let c = &mut self.constraint_terms;
            sys.constraints(q, &self.velocity, Order::First, c);
            for r in 0..split.rows {
                k.gamma[r] = -split
                    .kinematic
                    .iter()
                    .map(|&j| c.dh[(r, j)] * dq[j])
                    .sum::<f64>();
                for (col, &j) in split.dynamic.iter().enumerate() {
                    k.a[(r, col)] = c.dh[(r, j)];
                }
            }
        }
        solve_reduced(k, &mut self.projection, sys, split, step, t)?;
        for (r, &i) in split.dynamic.iter().enumerate() {
            dq[i] = k.rhs[r];
        }
        // E = ½ q̇ᵀMq̇ − L(q, 0), and L(q, 0) = −V(q).
        self.q_alpha.gemv(1.0, &self.terms.mass, dq, 0.0);
        Ok(0.5 * dq.dot(&self.q_alpha) - self.terms.l)
    }
}
