//! The midpoint variational integrator in momentum form (paper §VII; with constraints,
//! kinematic inputs and forcing as in docs/derivations.md §7).
//!
//! With `L_d(q₁, q₂) = Δt · L(q₁ + α(q₂ − q₁), (q₂ − q₁)/Δt)` (eq. (22)), a step solves, for
//! the dynamic part of `q₂` and the constraint forces `λ`,
//! `p₁ + D₁L_d(q₁, q₂) + f⁻ + Δt·Dh(q₁)ᵀλ = 0` (dynamic rows) and `h(q₂) = 0`, by Newton with
//! the exact Jacobian (eq. (26), the forces' derivatives, `Δt·Dh(q₁)ᵀ` and `Dh(q₂)`); the
//! kinematic part of `q₂` is its prescription at `t₂`. Then `p₂ = D₂L_d(q₁, q₂) + f⁺`.
//! The Newton system `[[J, B], [C, 0]]` (J over all variables, identity on the kinematic
//! ones; `B = Δt Dh(q₁)ᵀ`, `C = Dh(q₂)`) is solved by block elimination: the LU factor of the
//! fixed-size `J`, then the `m × m` Schur complement `C J⁻¹ B`. Without constraints that is
//! the plain Newton step on `J` alone.
//! In trep's notation `p₁ + D₁L_d + f⁻ − Dh(q₁)ᵀλ₁ = 0`, so trep's `λ₁ = −Δt·λ`: ours is a
//! force, comparable with the continuous multipliers.
//!
//! Forces `F + u` (the model's damping and dampers, plus the caller's `u`) are evaluated at
//! `(t₁ + αΔt, q_α, (q₂ − q₁)/Δt)`: [`Forcing::Split`] puts `f⁻ = (1−α)Δt F`, `f⁺ = αΔt F`
//! (second order), [`Forcing::Left`] `f⁻ = Δt F`, `f⁺ = 0` (trep's, first order in F).

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim, Dyn};

mod contact;
mod derivatives;

pub use derivatives::{
    StepCovector, StepDerivatives, StepInput, StepOutput, StepSecondDerivatives,
};

use super::discrete::DiscreteLagrangian;
use crate::context::StepContext;
use crate::dynamics::{prescribe, GeneralizedForce, Prescription, ReducedKkt, Split};
use crate::error::SimError;
use crate::linalg::{lu_factor_packed, lu_solve, lu_solve_packed, Pivots};
use crate::system::{ConstraintTerms, Matrix, Order, Sparsity, System, Terms, Vector};

/// A row's momentum scale is taken as at least this fraction of the largest row's: a row
/// whose terms nearly vanish (a variable at rest, no force on it) is then held to the step's
/// scale instead of to its own rounding noise. Relative, so the units still do not matter; a
/// body 1000× lighter than the heaviest is still converged on its own scale.
const FLOOR: f64 = 1e-3;

/// Below this relative residual (plus violation), the next exact Newton iterate is checked
/// with first derivatives before its Jacobian is evaluated.
const CHECK_FIRST_BELOW: f64 = 1e-3;

/// The largest turn of an angle a step may take (rad): a quarter turn.
pub(crate) const MAX_TURN: f64 = std::f64::consts::FRAC_PI_2;

/// When the VI's Newton iteration re-evaluates its exact Jacobian (eq. (26)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JacobianUpdate {
    /// Exact Newton: a full second-order evaluation and a fresh factorisation every iteration.
    EveryIteration,
    /// Evaluate and factor the exact Jacobian once per step, at the predicted point, and reuse
    /// it (a chord iteration: later iterations need only first derivatives and a solve);
    /// refreshed when the residual stops halving. From the predictor's O(Δt³) guess the
    /// chord contracts by orders of magnitude an iteration, so it reaches the same tolerance
    /// with one Jacobian and one factorisation a step instead of two (trep's Puppet: 2.1
    /// updates a step against 2.0, about a third less time compiled).
    #[default]
    OncePerStep,
}

/// The history the VI's predictor of `q_{k+1}` extrapolates from.
#[derive(Clone, Debug)]
struct Predictor<N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// `(v_k − v_{k−1}) / ((Δt_k + Δt_{k−1})/2)` for the last two steps' average velocities.
    acceleration: Vector<N>,
    /// The last step's length.
    dt: f64,
    /// The `q` the last step ended at.
    ended_at: Vector<N>,
    /// Whether `ended_at` and `dt` describe a step taken (not a fresh start).
    valid: bool,
}

impl<N: Dim> Predictor<N>
where
    DefaultAllocator: Allocator<N>,
{
    /// Whether a step from `q` continues the recorded one (else only `v_k` is used).
    fn continues_at(&self, q: &Vector<N>) -> bool {
        self.valid && self.ended_at == *q
    }

    /// Records a step of length `dt` whose average velocity was `v` after one of `v_last`
    /// (`continuing`: the two steps were consecutive).
    fn record(&mut self, continuing: bool, dt: f64, v_last: &Vector<N>, v: &Vector<N>) {
        if continuing {
            let scale = 2.0 / (self.dt + dt);
            for i in 0..v.len() {
                self.acceleration[i] = scale * (v[i] - v_last[i]);
            }
        } else {
            self.acceleration.as_mut_slice().fill(0.0);
        }
        self.dt = dt;
        self.valid = true;
    }
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

impl Forcing {
    /// `(w⁻, w⁺)` with `f⁻ = w⁻Δt F`, `f⁺ = w⁺Δt F` at quadrature point `α`.
    pub fn weights(self, alpha: f64) -> (f64, f64) {
        match self {
            Forcing::Split => (1.0 - alpha, alpha),
            Forcing::Left => (1.0, 0.0),
        }
    }
}

/// Settings of the variational integrator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViSettings {
    /// Quadrature point `α ∈ [0, 1]`; `½` is the second-order midpoint rule.
    pub alpha: f64,
    /// Newton stops when every dynamic row of the residual is below `tolerance` relative to
    /// that row's momentum scale (the sum of its terms' magnitudes) and every `|h_r(q₂)|` is
    /// below `constraint_tolerance`, or when the residual sits at its rounding floor: an
    /// update below the rounding of q, or an exact Newton update that fails to halve a
    /// residual already within `√tolerance` (docs/derivations.md §7, "The rounding floor").
    /// Relative, so a model in grams or in tonnes converges alike.
    pub tolerance: f64,
    /// Newton's tolerance on `max |h(q₂)|`.
    pub constraint_tolerance: f64,
    /// Newton iterations before a step fails (and is subdivided).
    pub max_iterations: usize,
    /// When Newton re-evaluates its Jacobian.
    pub jacobian: JacobianUpdate,
    /// How forces enter the discrete equations.
    pub forcing: Forcing,
    /// When Newton fails, retry the step as two half steps, recursively, this deep (0: never).
    pub max_subdivisions: usize,
    /// The relaxation of unilateral rows (docs/derivations.md §13): 0 for hard contact
    /// (complementarity driven to the tolerance), or `κ > 0` held on the central path
    /// (`φ γ = κ`, in metres times newton-seconds; smooth contact, whose step derivatives are
    /// those of a smooth system).
    pub kappa: f64,
    /// The largest turn of an angle a step may take before it is refused (and subdivided,
    /// where subdivisions are allowed), in radians: a quarter turn by default — beyond it
    /// the step does not resolve the motion and Newton can land on a spurious root of the
    /// discrete equations. `f64::INFINITY` takes any step, as trep's integrator does (the
    /// trep layer, which warns instead).
    pub max_turn: f64,
    /// Each step is followed by its derivatives ([`MidpointVi::derivatives_into`]): a Newton
    /// check expected to converge is of second order, so the derivatives find the terms at
    /// the solution already evaluated instead of evaluating them again (one expected to fail
    /// is of first order; after a first-order check that converges, the derivatives evaluate
    /// the terms themselves). With [`JacobianUpdate::OncePerStep`] the chord refactors the
    /// Jacobian whenever the chord, contracting as it last did, would not converge within
    /// two checks.
    pub derivatives: bool,
}

impl Default for ViSettings {
    fn default() -> Self {
        ViSettings {
            alpha: 0.5,
            tolerance: 1e-12,
            constraint_tolerance: 1e-12,
            max_iterations: 30,
            jacobian: JacobianUpdate::OncePerStep,
            forcing: Forcing::Split,
            max_subdivisions: 4,
            kappa: 0.0,
            max_turn: MAX_TURN,
            derivatives: false,
        }
    }
}

/// Variational-integrator workspace (nothing allocated per step).
#[derive(Clone, Debug)]
pub struct MidpointVi<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The settings in force.
    pub settings: ViSettings,
    /// The Lagrangian terms at the last quadrature point. Read them, do not write them: a
    /// compiled model's evaluations into them clear only the vectors when the last was its
    /// own at the same order (its structural zeros kept, `Terms::begin_assigned`).
    pub terms: Terms<N>,
    /// Constraints at the current guess `q₂` (and, after `velocity_and_energy`, at its `q`).
    pub constraint_terms: ConstraintTerms,
    /// The `q` at which `constraint_terms` hold `h` and `Dh` (when `constraints_known`), so a
    /// step's `Dh(q₁)` and a recorded state's reuse the evaluation at the last step's solution.
    constraints_at: Vector<N>,
    constraints_known: bool,
    /// `Dh(q₁)` of the step under way.
    dh1: DMatrix<f64>,
    /// Which variables are unknowns.
    pub split: Split,
    /// The dynamic variables that are angles (the quarter-turn guard of [`Self::step`]).
    angles: Vec<usize>,
    /// The constraint forces of the last step (see the module docs for trep's scaling).
    pub lambda: DVector<f64>,
    /// Dynamic rows of the residual (kinematic entries zero).
    residual: Vector<N>,
    /// Each dynamic row's momentum scale: the sum of the magnitudes of the terms that make up
    /// its residual (kinematic entries zero).
    row_scale: Vector<N>,
    /// `∂r/∂q₂`, identity on the kinematic variables.
    jacobian: Matrix<N>,
    factors: Matrix<N>,
    pivots: Pivots<N>,
    /// `J⁻¹B`, column by column, for the factor in `factors`.
    y: Vec<f64>,
    /// `Dh(q₂)`'s dynamic columns, packed: row r's entry for dynamic variable `c` at
    /// `r·n_d + c`.
    c_packed: Vec<f64>,
    column: Vector<N>,
    schur: DMatrix<f64>,
    /// Newton's update of λ.
    dlambda: DVector<f64>,
    q_alpha: Vector<N>,
    velocity: Vector<N>,
    force: Vector<N>,
    /// A zero velocity (constraints are evaluated at rest: `h`, `Dh` do not depend on q̇).
    zero: Vector<N>,
    reduced: ReducedKkt,
    /// Multipliers of the velocity projection in `velocity_and_energy`.
    projection: DVector<f64>,
    /// `λ` saved before a step, one per subdivision level (a failed step leaves q, p and the
    /// predictor untouched; only Newton's λ moves).
    saved_lambda: Vec<DVector<f64>>,
    /// The last step's average velocity `(q_{k+1} − q_k)/Δt`, used to predict the next (set
    /// it with [`Self::predict_from`]).
    last_velocity: Vector<N>,
    /// The predictor's history: the change of the average velocity between the last two
    /// steps per unit time (zero after one step), the last step's length, and the `q` the
    /// last step ended at (the history applies only to a step that starts there).
    predictor: Predictor<N>,
    /// The step length of the last residual.
    dt: f64,
    /// `terms` hold a second-order evaluation for the step from `full_q1` to `full_q2` over
    /// `dt` (the last residual's, with its Jacobian), when `full_known`.
    full_q1: Vector<N>,
    full_q2: Vector<N>,
    full_known: bool,
    /// Newton iterations of the last step (all its sub-steps).
    pub iterations: usize,
    /// Subdivisions the last step needed (0 when it went through whole).
    pub subdivisions: usize,
    /// Interior-point iterations of the last step's contact solves (all its sub-steps; a
    /// step solved free of contact takes none).
    pub contact_iterations: usize,
    /// The deepest any unilateral row went below zero at the last step's end (0: none did).
    pub penetration: f64,
    /// The derivatives' workspace, made on their first call.
    linearization: Option<Box<derivatives::Linearization>>,
    /// The second derivatives' scratch over dual numbers, made on their first use.
    dual_jacobians: Option<Box<derivatives::DualJacobians>>,
    /// The contact step's workspace (a system with unilateral rows only).
    contact: Option<Box<contact::ContactStep>>,
    /// The `q` the contact step's impulses and gaps were last solved at (its step's end).
    contact_at: Vector<N>,
    /// The energy the model's own forces (damping, dampers) took out over the last step:
    /// the discrete work `−F(q_α, v)·(q₂ − q₁)` of the force the step applied, summed over
    /// its sub-steps.
    pub dissipated: f64,
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// An integrator with buffers sized for `sys`.
    pub fn new<S: System<N = N>>(sys: &S, settings: ViSettings) -> Self {
        let n = sys.dim();
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        let split = Split::of(sys);
        let (nd, m) = (split.dynamic.len(), split.rows);
        MidpointVi {
            settings,
            terms: {
                let mut terms = Terms::zeros(n);
                terms.keep_zeros();
                terms
            },
            constraint_terms: ConstraintTerms::zeros(m, n.value()),
            constraints_at: z(),
            constraints_known: false,
            dh1: DMatrix::zeros(m, n.value()),
            lambda: DVector::zeros(m),
            residual: z(),
            row_scale: z(),
            jacobian: Matrix::zeros_generic(n, n),
            factors: Matrix::zeros_generic(n, n),
            pivots: Pivots::<N>::zeros_generic(n, nalgebra::U1),
            y: vec![0.0; nd * m],
            c_packed: vec![0.0; nd * m],
            column: z(),
            schur: DMatrix::zeros(m, m),
            dlambda: DVector::zeros(m),
            q_alpha: z(),
            velocity: z(),
            force: z(),
            zero: z(),
            reduced: ReducedKkt::new(nd, m),
            projection: DVector::zeros(m),
            saved_lambda: vec![DVector::zeros(m); settings.max_subdivisions + 1],
            last_velocity: z(),
            predictor: Predictor {
                acceleration: z(),
                dt: 0.0,
                ended_at: z(),
                valid: false,
            },
            dt: 0.0,
            full_q1: z(),
            full_q2: z(),
            full_known: false,
            iterations: 0,
            subdivisions: 0,
            contact_iterations: 0,
            penetration: 0.0,
            dissipated: 0.0,
            linearization: None,
            dual_jacobians: None,
            contact: contact::ContactStep::new(sys, nd, m),
            contact_at: z(),
            angles: split
                .dynamic
                .iter()
                .copied()
                .filter(|&i| sys.is_angle(i))
                .collect(),
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
        self.full_known = false;
        self.predict_from(dq0);
        self.terms.dl_ddq.clone()
    }

    /// Forgets the steps taken: the next step's predictor starts from `velocity` alone (a step
    /// then depends only on its own inputs).
    pub fn predict_from(&mut self, velocity: &Vector<N>) {
        self.last_velocity.copy_from(velocity);
        self.predictor.valid = false;
        self.constraints_known = false;
    }

    /// [`Self::predict_from`] a zero velocity.
    pub fn predict_from_rest(&mut self) {
        self.last_velocity.as_mut_slice().fill(0.0);
        self.predictor.valid = false;
        self.constraints_known = false;
    }

    /// Turns the continuous momentum `p(0)` at a constrained start into the discrete one the
    /// first step expects: `p₀⁻ = p(0) − ½Δt Dh(q₀)_dᵀλ(0)` (docs/derivations.md §7). The
    /// impulse `Δt Dh(q₁)ᵀλ` of a step stands for half a step either side of its node, but
    /// nothing came before `t = 0`: without this the first step's λ is half the force (its
    /// impulse covers only `[0, Δt/2]`). `dh0` and `lambda0` are the continuous equations'
    /// at `q₀`; λ is also kept as the first Newton guess.
    pub fn start_constrained(
        &mut self,
        dh0: &DMatrix<f64>,
        lambda0: &DVector<f64>,
        dt: f64,
        p: &mut Vector<N>,
    ) {
        self.lambda.copy_from(lambda0);
        for &i in &self.split.dynamic {
            for s in 0..self.split.rows {
                p[i] -= 0.5 * dt * dh0[(s, i)] * lambda0[s];
            }
        }
    }

    /// `h(q)` and `Dh(q)` into `constraint_terms`, unless they already hold them.
    fn constraints_at<S: System<N = N>>(&mut self, sys: &mut S, q: &Vector<N>) {
        if self.constraints_known && self.constraints_at == *q {
            return;
        }
        sys.constraints(q, &self.zero, Order::First, &mut self.constraint_terms);
        self.constraints_at.copy_from(q);
        self.constraints_known = true;
    }

    /// Evaluates `Dh(q₁)` for the step from `q₁` (before [`Self::residual`]).
    pub fn prepare<S: System<N = N>>(&mut self, sys: &mut S, q1: &Vector<N>) {
        if self.split.rows > 0 {
            self.constraints_at(sys, q1);
            self.dh1.copy_from(&self.constraint_terms.dh);
        }
    }

    /// The residual at the guess `(q₂, λ)` — dynamic rows `p₁ + D₁L_d + f⁻ + Δt Dh(q₁)ᵀλ`
    /// (eqs. (23), (25)), then `h(q₂)` — and, with `jacobian`, its exact derivative with
    /// respect to `(q₂_d, λ)` (eq. (26) plus the forces' derivatives and the constraint
    /// blocks). `q₂`'s kinematic entries must hold their prescription; `λ` is
    /// [`Self::lambda`]; [`Self::prepare`] must have been called for `q₁`. Leaves `terms`
    /// evaluated at `(q_α, v)`.
    pub fn residual<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        jacobian: bool,
    ) -> &Vector<N>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        self.evaluate_residual(cx, q1, p1, q2, jacobian);
        if jacobian {
            self.form_jacobian();
        }
        &self.residual
    }

    /// [`Self::residual`]'s evaluation: the residual, and with `second_order` the terms its
    /// Jacobian is formed from ([`Self::form_jacobian`], when a factor needs it: a converged
    /// check and a linearisation need only the terms).
    fn evaluate_residual<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        second_order: bool,
    ) where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (sys, force, t, dt) = (&mut *cx.sys, &mut *cx.force, cx.t, cx.dt);
        let a = self.settings.alpha;
        let (left, _) = self.settings.forcing.weights(a);
        let ld = DiscreteLagrangian { alpha: a, dt };
        ld.point(q1, q2, &mut self.q_alpha, &mut self.velocity);
        self.dt = dt;
        let order = if second_order {
            Order::Full
        } else {
            Order::First
        };
        sys.lagrangian(&self.q_alpha, &self.velocity, order, &mut self.terms);
        self.full_known = second_order;
        if second_order {
            self.full_q1.copy_from(q1);
            self.full_q2.copy_from(q2);
        }
        self.force.copy_from(&self.terms.force);
        force.add_force(t + a * dt, &self.q_alpha, &self.velocity, &mut self.force);
        // The inputs, held over the step: B u.
        for (k, &x) in cx.u.iter().enumerate() {
            self.force[sys.input_variable(k)] += x;
        }
        let (split, t2) = (&self.split, &self.terms);
        // p1 + D₁L_d + f⁻ + Δt Dh(q1)ᵀλ on the dynamic rows, and the sum of those terms'
        // magnitudes (the row's momentum scale).
        for &i in &split.dynamic {
            let f = left * dt * self.force[i];
            let mut x = p1[i] + ld.d1(t2, i) + f;
            let mut scale = p1[i].abs() + ld.d1_scale(t2, i) + f.abs();
            for s in 0..split.rows {
                let v = dt * self.dh1[(s, i)] * self.lambda[s];
                x += v;
                scale += v.abs();
            }
            self.residual[i] = x;
            self.row_scale[i] = scale;
        }
        if self.split.rows > 0 {
            self.constraints_at(sys, q2);
        }
    }

    /// `∂r/∂q₂ = D₂D₁L_d` (eq. (26)) `+ ∂f⁻/∂q₂`, `∂f⁻/∂q₂ = wΔt(α ∂F/∂q + ∂F/∂q̇ /Δt)`, into
    /// `jacobian` from the second-order terms the last evaluation left (at the current
    /// guess), with identity rows and columns on the kinematic variables.
    fn form_jacobian(&mut self) {
        debug_assert!(
            self.full_known,
            "the Jacobian is formed from second-order terms"
        );
        let (a, dt) = (self.settings.alpha, self.dt);
        let (left, _) = self.settings.forcing.weights(a);
        let ld = DiscreteLagrangian { alpha: a, dt };
        // Column-major slices: entry (i, j) is at j·n + i.
        let t = &self.terms;
        let n = self.jacobian.nrows();
        let jac = self.jacobian.as_mut_slice();
        ld.d2d1(t, jac);
        let (fq, fv) = (t.dforce_dq.as_slice(), t.dforce_ddq.as_slice());
        match t.force_derivatives {
            Sparsity::Zero => {}
            Sparsity::Diagonal => {
                for i in 0..n {
                    jac[i * n + i] += left * fv[i * n + i];
                }
            }
            Sparsity::Dense => {
                for ij in 0..n * n {
                    jac[ij] += left * (a * dt * fq[ij] + fv[ij]);
                }
            }
        }
        // Kinematic variables are not unknowns: identity rows and columns.
        for &k in &self.split.kinematic {
            for i in 0..n {
                jac[k * n + i] = 0.0;
                jac[i * n + k] = 0.0;
            }
            jac[k * n + k] = 1.0;
        }
    }

    /// The full Newton matrix of the last [`Self::residual`] call with `jacobian` set, rows and
    /// columns the dynamic variables then the constraints: `[[J_dd, Δt Dh(q₁)_dᵀ],
    /// [Dh(q₂)_d, 0]]`. Allocates (for tests and diagnostics; steps never form it).
    pub fn newton_matrix(&self) -> DMatrix<f64> {
        let (d, m) = (&self.split.dynamic, self.split.rows);
        let nd = d.len();
        DMatrix::from_fn(nd + m, nd + m, |r, c| match (r < nd, c < nd) {
            (true, true) => self.jacobian[(d[r], d[c])],
            (true, false) => self.dt * self.dh1[(c - nd, d[r])],
            (false, true) => self.constraint_terms.dh[(r - nd, d[c])],
            (false, false) => 0.0,
        })
    }

    /// The dynamic rows of the residual at the last guess, then `h(q₂)`, as one vector
    /// (allocates; for tests and diagnostics).
    pub fn residual_vector(&self) -> DVector<f64> {
        let d = &self.split.dynamic;
        DVector::from_iterator(
            d.len() + self.split.rows,
            d.iter()
                .map(|&i| self.residual[i])
                .chain(self.constraint_terms.h.iter().copied()),
        )
    }

    /// Factors `J` (and, with constraints, forms `Y = J⁻¹B`, `B = Δt Dh(q₁)ᵀ`). `J` is the
    /// identity on kinematic rows and columns, so only its dynamic block is factored, packed
    /// into the top of `factors` (18 of the marionette's 42 variables are kinematic: a 24×24
    /// factorisation instead of 42×42).
    fn factor<S: System<N = N>>(&mut self, sys: &S, step: usize, t: f64) -> Result<(), SimError> {
        self.form_jacobian();
        let dynamic = &self.split.dynamic;
        let (n, nd) = (self.jacobian.nrows(), dynamic.len());
        let (jac, packed) = (self.jacobian.as_slice(), self.factors.as_mut_slice());
        if nd == n {
            // Every variable dynamic: the block is the whole Jacobian, copied as it is.
            packed[..n * n].copy_from_slice(jac);
        } else {
            for (cj, &j) in dynamic.iter().enumerate() {
                for (ci, &i) in dynamic.iter().enumerate() {
                    packed[cj * nd + ci] = jac[j * n + i];
                }
            }
        }
        // Overflowed entries make every pivot NaN: that is the model's numbers, not a
        // singular matrix.
        if packed[..nd * nd].iter().any(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                step,
                t,
                what: "the VI's Newton matrix".into(),
            });
        }
        lu_factor_packed(packed, nd, self.pivots.as_mut_slice()).map_err(|c| {
            SimError::SingularJacobian {
                step,
                t,
                variable: format!("variable `{}`", sys.variable_name(dynamic[c])),
            }
        })?;
        let (packed, pivots) = (self.factors.as_slice(), self.pivots.as_slice());
        let column = self.column.as_mut_slice();
        for s in 0..self.split.rows {
            for (ci, &i) in dynamic.iter().enumerate() {
                column[ci] = self.dt * self.dh1[(s, i)];
            }
            lu_solve_packed(packed, nd, pivots, column);
            self.y[s * nd..(s + 1) * nd].copy_from_slice(&column[..nd]);
        }
        Ok(())
    }

    /// The Newton update: on exit `residual` holds `Δq₂` and `dlambda` `Δλ`, from
    /// `J Δq + B Δλ = −r`, `C Δq = −h` by the factor of `J` and the Schur complement `C Y`.
    /// Kinematic entries of `Δq₂` are zero (their rows of `J` are the identity, their
    /// residual zero).
    fn newton_update<S: System<N = N>>(
        &mut self,
        sys: &S,
        step: usize,
        t: f64,
    ) -> Result<(), SimError> {
        let dynamic = &self.split.dynamic;
        let column = self.column.as_mut_slice();
        for (ci, &i) in dynamic.iter().enumerate() {
            column[ci] = -self.residual[i];
        }
        lu_solve_packed(
            self.factors.as_slice(),
            dynamic.len(),
            self.pivots.as_slice(),
            column,
        );
        for &k in &self.split.kinematic {
            self.residual[k] = 0.0;
        }
        for (ci, &i) in dynamic.iter().enumerate() {
            self.residual[i] = column[ci];
        }
        let m = self.split.rows;
        if m == 0 {
            return Ok(());
        }
        // J Δq + B Δλ = −r, C Δq = −h: with z = −J⁻¹r, Δq = z − Y Δλ and (C Y) Δλ = h + C z.
        // Packed over the dynamic variables (Y by column, C by row), each entry a dot product
        // of two contiguous slices.
        let nd = dynamic.len();
        let c = &self.constraint_terms.dh;
        for r in 0..m {
            for (ci, &i) in dynamic.iter().enumerate() {
                self.c_packed[r * nd + ci] = c[(r, i)];
            }
        }
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let z = &column[..nd];
        for r in 0..m {
            let c_r = &self.c_packed[r * nd..(r + 1) * nd];
            for s in 0..m {
                self.schur[(r, s)] = dot(c_r, &self.y[s * nd..(s + 1) * nd]);
            }
            self.dlambda[r] = self.constraint_terms.h[r] + dot(c_r, z);
        }
        lu_solve::<Dyn>(&mut self.schur, &mut self.dlambda).map_err(|r| {
            SimError::SingularJacobian {
                step,
                t,
                variable: format!("the λ of constraint `{}`", sys.constraint_name(r)),
            }
        })?;
        for s in 0..m {
            let (y_s, dl) = (&self.y[s * nd..(s + 1) * nd], self.dlambda[s]);
            for (ci, &i) in dynamic.iter().enumerate() {
                self.residual[i] -= y_s[ci] * dl;
            }
        }
        Ok(())
    }

    /// `∂r/∂q₂` of the last [`Self::residual`] call with `jacobian` set (eq. (26) plus the
    /// forces' derivatives), over all variables with identity rows and columns on the kinematic
    /// ones; see [`Self::newton_matrix`] for the whole system with constraints.
    pub fn jacobian(&self) -> &Matrix<N> {
        &self.jacobian
    }

    /// Advances `(q_k, p_k)` from `cx.t` by `cx.dt` to `(q_{k+1}, p_{k+1})` in place. When
    /// Newton fails the step is retried as two half steps, recursively up to
    /// `max_subdivisions` deep. `cx.index` labels errors.
    pub fn step<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
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
        self.contact_iterations = 0;
        self.penetration = 0.0;
        self.dissipated = 0.0;
        let (t, dt) = (cx.t, cx.dt);
        let result = self.advance(cx, q, p, q_next, 0);
        (cx.t, cx.dt) = (t, dt);
        // A failure where the mass matrix is nearly singular names that cause.
        result.map_err(|mut e| {
            if let SimError::NewtonFailed { singular, .. }
            | SimError::ContactFailed { singular, .. } = &mut e
            {
                *singular = nearly_singular(cx.sys, q);
            }
            e
        })
    }

    /// The step from `cx.t` of length `cx.dt`, split in halves on failure (moving `cx.t`
    /// and `cx.dt` for the halves).
    fn advance<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
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
        if can_split && self.split.rows > 0 {
            self.saved_lambda[depth].copy_from(&self.lambda);
        }
        match self.step_once(cx, q, p, q_next) {
            Err(SimError::NewtonFailed { .. } | SimError::SingularJacobian { .. })
            | Err(SimError::NonFinite { .. } | SimError::StepTooCoarse { .. })
            | Err(SimError::ContactFailed { .. })
                if can_split =>
            {
                if self.split.rows > 0 {
                    self.lambda.copy_from(&self.saved_lambda[depth]);
                }
                self.subdivisions += 1;
                let (t, h) = (cx.t, 0.5 * cx.dt);
                cx.dt = h;
                self.advance(cx, q, p, q_next, depth + 1)?;
                cx.t = t + h;
                self.advance(cx, q, p, q_next, depth + 1)
            }
            other => other,
        }
    }

    /// One step of length `dt`, no subdivision. On failure `q`, `p` and the predictor are
    /// left as they were.
    fn step_once<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &mut Vector<N>,
        p: &mut Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        self.prepare(cx.sys, q);
        let continuing = self.predict(cx, q, q_next);
        let solved = if self.contact.is_some() {
            self.solve_contact(cx, q, p, q_next)
        } else {
            self.solve(cx, q, p, q_next)
        };
        if self.contact.is_some() && solved.is_ok() {
            self.contact_at.copy_from(q_next);
        }
        self.iterations += match solved {
            Ok(iterations) | Err((iterations, _)) => iterations,
        };
        if let Err((_, e)) = solved {
            return Err(e);
        }
        self.finish(cx, q, p, q_next, continuing)
    }

    /// Predicts `q_{k+1}` into `q_next`: the average velocities of the last two steps
    /// extrapolated (`q_k + Δt(2v_k − v_{k−1})` at a constant Δt, an error O(Δt³), so one
    /// exact Newton iteration usually converges); kinematic entries from their prescription.
    /// Whether the last step continues into this one (its velocity extrapolated).
    fn predict<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> bool
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (t, dt) = (cx.t, cx.dt);
        let continuing = self.predictor.continues_at(q);
        q_next.copy_from(q);
        q_next.axpy(dt, &self.last_velocity, 1.0);
        if continuing {
            let lead = 0.5 * (self.predictor.dt + dt) * dt;
            q_next.axpy(lead, &self.predictor.acceleration, 1.0);
        }
        for &i in &self.split.kinematic {
            q_next[i] = cx.motion.kinematic(i, t + dt)[0];
        }
        continuing
    }

    /// Newton on the discrete Euler–Lagrange equations (eq. (23)) and the constraints from
    /// the prediction in `q_next`: the exact Jacobian factored once and reused as a chord
    /// while it contracts (or every iteration), until the relative residual and the violation
    /// meet their tolerances or sit at their rounding floor. The iterations taken, also on
    /// failure.
    fn solve<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        p: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<usize, (usize, SimError)>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (step, t) = (cx.index, cx.t);
        // With derivatives to follow, a check expected to converge is of second order: it
        // leaves the terms the derivatives need at the solution, and a Jacobian to refactor.
        // One expected to fail is of first order (docs/derivations.md, "Predictor and chord").
        let derivatives = self.settings.derivatives;
        let reuse = self.settings.jacobian == JacobianUpdate::OncePerStep;
        let mut factored = false;
        let mut last_residual = f64::INFINITY;
        let mut expect_converged = false;
        // Whether the last update solved with a Jacobian factored at its own iterate, and the
        // smallest residual of the checks before this one.
        let mut exact_update = false;
        let mut smallest = f64::INFINITY;
        let mut iterations = 0;
        loop {
            let fresh = !(reuse && factored);
            // After an exact Newton update from a residual within √tol, the new residual is
            // (quadratically) within tol: check it with first derivatives alone, and
            // evaluate the Jacobian only if the check fails (the last full evaluation of a
            // step was otherwise thrown away).
            let check_first = fresh && last_residual <= CHECK_FIRST_BELOW && !derivatives;
            let full = if derivatives {
                fresh || expect_converged
            } else {
                fresh && !check_first
            };
            self.evaluate_residual(cx, q, p, q_next, full);
            let (residual, violation) = self.residual_norms();
            let mut relative = self.relative_residual();
            if !residual.is_finite() || !violation.is_finite() || !relative.is_finite() {
                let what = "discrete Euler–Lagrange residual".into();
                return Err((iterations, SimError::NonFinite { step, t, what }));
            }
            if relative <= self.settings.tolerance
                && violation <= self.settings.constraint_tolerance
            {
                break;
            }
            if iterations >= self.settings.max_iterations {
                let failed = SimError::NewtonFailed {
                    step,
                    t,
                    iterations,
                    residual: relative,
                    violation,
                    singular: None,
                };
                return Err((iterations, failed));
            }
            let mut refactor = fresh;
            if check_first {
                self.evaluate_residual(cx, q, p, q_next, true);
                relative = self.relative_residual();
            }
            // Relative residual and violation: both independent of the masses.
            let combined = relative + violation;
            // An exact Newton update squares a small residual; one that left it above half the
            // smallest so far found the residual at its rounding floor, where it wanders with
            // each update's rounding. The floor is set by sums that cancel inside a row (a
            // light limb hanging at rest: its row's terms are far smaller than the torques
            // summed into them), which a short step can hold above the tolerance; Newton
            // cannot improve on such a point.
            if exact_update
                && combined > 0.5 * smallest
                && combined <= self.settings.tolerance.sqrt()
            {
                break;
            }
            smallest = smallest.min(combined);
            // The chord, contracting as it did last iteration: its residual one and two
            // checks on. With derivatives to follow, refactor unless it converges within two
            // (first-order checks until then, a refactor costs a second-order evaluation).
            let rate = combined / last_residual;
            let chord_next = combined * rate;
            let chord_converges = chord_next * rate <= self.settings.tolerance;
            if !fresh && (combined > 0.5 * last_residual || (derivatives && !chord_converges)) {
                // The reused Jacobian has stopped paying: evaluate it here (a second-order
                // check already has).
                if !full {
                    self.evaluate_residual(cx, q, p, q_next, true);
                    relative = self.relative_residual();
                }
                refactor = true;
            }
            // Whether the next check converges: after an exact Newton update from within
            // CHECK_FIRST_BELOW, quadratically; after a chord update, by its contraction.
            expect_converged = if refactor {
                combined <= CHECK_FIRST_BELOW
            } else {
                chord_next <= self.settings.tolerance
            };
            if refactor {
                self.factor(cx.sys, step, t).map_err(|e| (0, e))?;
                factored = true;
            }
            exact_update = refactor;
            last_residual = relative + violation;
            iterations += 1;
            if self.apply_update(cx, q, p, q_next).map_err(|e| (0, e))? {
                break;
            }
        }
        Ok(iterations)
    }

    /// Solves for the Newton update and applies it to `q_next` and `λ`. `true` when the
    /// update was lost in the last bits of `q` (the residual is at its rounding floor,
    /// ≈ ε‖M‖‖q‖/Δt, which a large, stiff model can hold above the tolerance): the terms are
    /// then evaluated at the solution and Newton ends.
    fn apply_update<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        p: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<bool, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (step, t) = (cx.index, cx.t);
        self.newton_update(cx.sys, step, t)?;
        let mut largest: f64 = 0.0;
        for &i in &self.split.dynamic {
            q_next[i] += self.residual[i];
            let x = self.residual[i].abs();
            // (A plain comparison: f64::max's NaN test made each row wait on the last.)
            largest = if x > largest { x } else { largest };
        }
        if self.split.rows > 0 {
            self.lambda += &self.dlambda;
        }
        if below_rounding(largest, q_next) {
            self.evaluate_residual(cx, q, p, q_next, self.settings.derivatives);
            return Ok(true);
        }
        Ok(false)
    }

    /// The step's end: `p_{k+1}` (eq. (24)), checked finite and the turn of every angle
    /// within a quarter; the work of the model's forces; the predictor's record; `q ← q_{k+1}`.
    fn finish<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &mut Vector<N>,
        p: &mut Vector<N>,
        q_next: &mut Vector<N>,
        continuing: bool,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (step, t, dt) = (cx.index, cx.t, cx.dt);
        // p_{k+1} = D₂L_d + f⁺ (eq. (24)), terms at the solution.
        for i in 0..self.q_alpha.len() {
            self.q_alpha[i] = self.end_momentum(dt, i);
        }
        let p2 = &self.q_alpha;
        if q_next.iter().chain(p2.iter()).any(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                step,
                t: t + dt,
                what: "configuration or momentum".into(),
            });
        }
        // A joint turned by more than a quarter turn in one step is not resolved by the step
        // (and at such steps Newton can land on a spurious root of the discrete equations,
        // with an energy orders of magnitude off): refuse it, so the step is subdivided.
        if let Some(&i) = self
            .angles
            .iter()
            .find(|&&i| (q_next[i] - q[i]).abs() > self.settings.max_turn)
        {
            return Err(SimError::StepTooCoarse {
                step,
                t,
                dt,
                variable: cx.sys.variable_name(i).to_string(),
                turn: q_next[i] - q[i],
            });
        }
        p.copy_from(p2);
        // F·(q₂ − q₁) = Δt F·v: the work of the model's forces over the step.
        self.dissipated -= dt * self.terms.force.dot(&self.velocity);
        self.predictor
            .record(continuing, dt, &self.last_velocity, &self.velocity);
        self.last_velocity.copy_from(&self.velocity);
        std::mem::swap(q, q_next);
        self.predictor.ended_at.copy_from(q);
        Ok(())
    }

    /// Entry `i` of `p₂ = D₂L_d + f⁺` (eq. (24)) from the terms and forces of the last
    /// [`Self::residual`] (a step of length `dt`).
    fn end_momentum(&self, dt: f64, i: usize) -> f64 {
        let a = self.settings.alpha;
        let (_, plus) = self.settings.forcing.weights(a);
        DiscreteLagrangian { alpha: a, dt }.d2(&self.terms, i) + plus * dt * self.force[i]
    }

    /// `p₂ = D₂L_d(q₁, q₂) + f⁺` for the step from `q₁` at `cx.t` to `q₂` at `cx.t + cx.dt`,
    /// with this integrator's quadrature and forcing: the momentum a run that is given two
    /// configurations instead of a state starts from (trep's `initialize_from_configs`).
    pub fn momentum_after<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<Vector<N>, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        self.prepare(cx.sys, q1);
        // The residual's rows are not used: any p₁ will do.
        let p1 = self.zero.clone();
        self.residual(cx, q1, &p1, q2, false);
        let mut p2 = p1;
        for i in 0..p2.len() {
            p2[i] = self.end_momentum(cx.dt, i);
        }
        if p2.iter().any(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                step: cx.index,
                t: cx.t + cx.dt,
                what: "the momentum at the second configuration".into(),
            });
        }
        Ok(p2)
    }

    /// Each unilateral row's impulse over the last step and value at its end (γ and the gap;
    /// a friction component and a tangent coordinate at a tangent row); empty without
    /// unilateral rows.
    pub fn contact_rows(&self) -> (&[f64], &[f64]) {
        match &self.contact {
            Some(c) => (&c.impulses, &c.gap_values),
            None => (&[], &[]),
        }
    }

    /// Whether the model has unilateral rows (limits enforced, contacts, slack strings).
    pub fn has_contacts(&self) -> bool {
        self.contact.is_some()
    }

    /// Whether the last step went through contact: solved with unilateral rows in its
    /// equations (not a free step). Its second derivatives are then not formed
    /// ([`Self::second_derivatives`]); an optimiser takes the Gauss–Newton model there.
    pub fn through_contact(&self) -> bool {
        self.contact.as_ref().is_some_and(|c| !c.free)
    }

    /// Starts the contact rows' record at `q`: no impulse yet, the gaps there.
    pub fn contact_start<S: System<N = N>>(&mut self, sys: &mut S, q: &Vector<N>) {
        if let Some(c) = self.contact.as_mut() {
            c.start_record(sys, q);
            self.contact_at.copy_from(q);
        }
    }

    /// The largest dynamic row of the last residual relative to its momentum scale: `max_i
    /// |r_i| / s_i`, where `s_i = |p₁ᵢ| + |(1−α)Δt ∂L/∂qᵢ| + |∂L/∂q̇ᵢ| + |f⁻ᵢ| + Σ_r |Δt
    /// Dh(q₁)ᵣᵢ λᵣ|` sums the magnitudes of the terms `r_i` adds up. Every term scales with the
    /// masses, so this ratio does not (a row whose terms all vanish has `r_i = 0`: ratio 0). It
    /// lies in `[0, 1]`; Newton stops below [`ViSettings::tolerance`]. (Each `s_i` counts as
    /// at least a thousandth of the largest.)
    pub(crate) fn relative_residual(&self) -> f64 {
        // Plain comparisons (`if x > m`), which skip a NaN as `f64::max` does but take one
        // instruction where its NaN test made each row wait on the last longer.
        let largest = |m: f64, x: f64| if x > m { x } else { m };
        let dynamic = &self.split.dynamic;
        let floor = FLOOR
            * dynamic
                .iter()
                .fold(0.0, |m, &i| largest(m, self.row_scale[i]));
        let mut worst = 0.0f64;
        let mut nan = false;
        for &i in dynamic {
            let r = self.residual[i].abs();
            if r == 0.0 {
                continue;
            }
            let x = r / largest(floor, self.row_scale[i]);
            nan |= x.is_nan();
            worst = largest(worst, x);
        }
        if nan {
            f64::NAN
        } else {
            worst
        }
    }

    /// `max |h(q₂)|` at the end of the last step evaluated (0 without constraints).
    pub fn violation(&self) -> f64 {
        self.residual_norms().1
    }

    /// `(max |dynamic residual|, max |h(q₂)|)`.
    fn residual_norms(&self) -> (f64, f64) {
        let violation = if self.split.rows > 0 {
            self.constraint_terms.violation()
        } else {
            0.0
        };
        (self.residual.amax(), violation)
    }

    /// The continuous velocity and energy at `(q, p)` and time `cx.t`: kinematic `q̇` from the
    /// prescription, dynamic `q̇ = M_dd⁻¹(p_d − M_dk q̇_k)` (the Legendre transform), made
    /// consistent with the constraints (`Dh q̇ = 0`, projected in the `M_dd` metric); returns
    /// `E = ½ q̇ᵀM q̇ + V(q)`. Not conserved while kinematic inputs move.
    pub fn velocity_and_energy<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        p: &Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<f64, SimError>
    where
        S: System<N = N>,
        P: Prescription,
    {
        let (sys, motion, step, t) = (&mut *cx.sys, &mut *cx.motion, cx.index, cx.t);
        sys.mass_matrix(q, &mut self.terms);
        self.full_known = false;
        self.q_alpha.copy_from(q);
        prescribe(
            &self.split.kinematic,
            motion,
            t,
            &mut self.q_alpha,
            dq,
            None,
        );
        if self.split.rows > 0 {
            self.constraints_at(sys, q);
        }
        self.reduced.solve(
            sys,
            &self.split,
            &self.terms.mass,
            p,
            &self.constraint_terms.dh,
            |_| 0.0,
            dq,
            &mut self.projection,
            step,
            t,
        )?;
        // The contacts in force at q (the last step's end) hold their rows' velocity.
        if let Some(c) = self.contact.as_mut().filter(|_| self.contact_at == *q) {
            let closed = 1e3 * self.settings.constraint_tolerance * q.amax().max(1.0);
            let n = q.len();
            c.project_velocity(
                self.reduced.factor(),
                n,
                &self.split.dynamic,
                dq.as_mut_slice(),
                closed,
            );
        }
        // E = ½ q̇ᵀMq̇ − L(q, 0), and L(q, 0) = −V(q).
        self.q_alpha.gemv(1.0, &self.terms.mass, dq, 0.0);
        Ok(0.5 * dq.dot(&self.q_alpha) - self.terms.l)
    }
}

/// Below this `d/M_ii`, a failed step's mass matrix is called nearly singular: the motion
/// of that variable is all but another's (1 for independent ones; a floating base's
/// root_pitch 0.3° from ±90° gives 3e-5).
const NEARLY_SINGULAR: f64 = 1e-4;

/// The variable of the weakest pivot of the dynamic variables' mass matrix at `q`, and
/// `d/M_ii` there, when it is below [`NEARLY_SINGULAR`]: why a step failed, asked only
/// after it did (allocates).
/// Whether a Newton update whose largest entry is `largest` was lost in the rounding of `q`
/// (a few ulps of its largest entry, of 1 near zero): the residual is then at its floor, and
/// the smooth step, the contact mode and the interior point all stop there.
fn below_rounding<N: Dim>(largest: f64, q: &Vector<N>) -> bool
where
    DefaultAllocator: Allocator<N>,
{
    largest <= 4.0 * f64::EPSILON * q.amax().max(1.0)
}

fn nearly_singular<S: System>(sys: &mut S, q: &Vector<S::N>) -> Option<(String, f64)>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut terms = Terms::zeros(sys.dim());
    sys.mass_matrix(q, &mut terms);
    let dynamic: Vec<usize> = (0..sys.dof()).filter(|&i| !sys.is_kinematic(i)).collect();
    let n = dynamic.len();
    let mut m: Vec<f64> = (0..n * n)
        .map(|k| terms.mass[(dynamic[k % n], dynamic[k / n])])
        .collect();
    let (j, ratio) = crate::linalg::weakest_pivot(&mut m, n)?;
    (ratio < NEARLY_SINGULAR).then(|| (sys.variable_name(dynamic[j]).to_string(), ratio))
}
