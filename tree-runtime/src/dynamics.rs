//! Continuous Euler–Lagrange dynamics (paper eq. (14), docs/derivations.md §6) with the
//! model's forces, kinematic inputs and holonomic constraints:
//! `M q̈ = F + u + ∂L/∂q − (∂²L/∂q̇∂q) q̇ + Dhᵀλ` on the dynamic rows, `q̈_k` prescribed, and
//! `Dh q̈ + q̇ᵀD²h q̇ = 0` (optionally stabilised, Baumgarte: `+ 2a ḣ + b² h`).

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim, Dyn};
use tree_model::Motion;

use crate::context::StepContext;
use crate::error::SimError;
use crate::linalg::{cholesky_backward, cholesky_factor, cholesky_forward, cholesky_solve};
use crate::system::{ConstraintTerms, Matrix, Order, System, Terms, Vector};

/// An external generalized force `u(t, q, q̇)` (joint torques, actuators, …), added to the
/// model's own forces (damping, dampers).
pub trait GeneralizedForce<N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// Adds `u(t, q, q̇)` into `u`.
    fn add_force(&mut self, t: f64, q: &Vector<N>, dq: &Vector<N>, u: &mut Vector<N>);
}

/// No external force.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoForce;

impl<N: Dim> GeneralizedForce<N> for NoForce
where
    DefaultAllocator: Allocator<N>,
{
    fn add_force(&mut self, _: f64, _: &Vector<N>, _: &Vector<N>, _: &mut Vector<N>) {}
}

/// Any closure `|t, q, q̇, u| …` that adds its force into `u`.
impl<N: Dim, F> GeneralizedForce<N> for F
where
    DefaultAllocator: Allocator<N>,
    F: FnMut(f64, &Vector<N>, &Vector<N>, &mut Vector<N>),
{
    fn add_force(&mut self, t: f64, q: &Vector<N>, dq: &Vector<N>, u: &mut Vector<N>) {
        self(t, q, dq, u)
    }
}

/// How the kinematic (prescribed) variables move: `t ↦ (q, q̇, q̈)` of variable `i`.
pub trait Prescription {
    /// `[q, q̇, q̈]` of kinematic variable `i` at time `t`.
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3];
}

/// Any closure `|i, t| [q, q̇, q̈]`.
impl<F: FnMut(usize, f64) -> [f64; 3]> Prescription for F {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        self(i, t)
    }
}

/// The motions the model prescribes (a file's `motion`, `samples`, or `q0`/`dq0`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelMotions(pub Vec<Option<Motion>>);

impl ModelMotions {
    /// The motions of `sys`'s kinematic variables.
    pub fn of<S: System>(sys: &S) -> Self
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        ModelMotions((0..sys.dof()).map(|i| sys.motion(i)).collect())
    }
}

impl Prescription for ModelMotions {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        self.0[i].as_ref().map_or([0.0; 3], |m| m.at(t))
    }
}

/// Sets the kinematic entries of `q`, `q̇` (and `q̈`) to their prescription at `t`.
pub fn prescribe<N: Dim>(
    kinematic: &[usize],
    motion: &mut impl Prescription,
    t: f64,
    q: &mut Vector<N>,
    dq: &mut Vector<N>,
    ddq: Option<&mut Vector<N>>,
) where
    DefaultAllocator: Allocator<N>,
{
    let mut ddq = ddq;
    for &i in kinematic {
        let [x, v, a] = motion.kinematic(i, t);
        q[i] = x;
        dq[i] = v;
        if let Some(ddq) = ddq.as_deref_mut() {
            ddq[i] = a;
        }
    }
}

/// Which variables are simulated and which prescribed, and how many constraint rows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Split {
    /// Indices of the simulated variables.
    pub dynamic: Vec<usize>,
    /// Indices of the prescribed variables.
    pub kinematic: Vec<usize>,
    /// Number of constraint equations.
    pub rows: usize,
}

impl Split {
    /// The split of `sys`'s variables and its constraint count.
    pub fn of<S: System>(sys: &S) -> Self
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let (kinematic, dynamic) = (0..sys.dof()).partition(|&i| sys.is_kinematic(i));
        Split {
            dynamic,
            kinematic,
            rows: sys.constraint_count(),
        }
    }

    /// Nothing prescribed and nothing constrained: the plain `M q̈ = rhs` path.
    pub(crate) fn is_plain(&self) -> bool {
        self.kinematic.is_empty() && self.rows == 0
    }
}

/// Baumgarte stabilisation of the acceleration-level constraint: `ḧ + 2a ḣ + b² h = 0`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Baumgarte {
    /// Damping rate a.
    pub a: f64,
    /// Stiffness rate b.
    pub b: f64,
}

/// Workspace for evaluating accelerations without allocating.
#[derive(Clone, Debug)]
pub struct Dynamics<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The Lagrangian terms of the last evaluation (after an articulated-body solve, only
    /// the model's own forces: `force` and the springs' `dl_dq`). Read them, do not write
    /// them: a compiled model's evaluations into them clear only the vectors when the last
    /// was its own at the same order (its structural zeros kept, `Terms::begin_assigned`).
    pub terms: Terms<N>,
    /// The constraint terms of the last evaluation.
    pub constraint_terms: ConstraintTerms,
    /// The constraint forces `λ` of the last evaluation.
    pub lambda: DVector<f64>,
    /// Constraint stabilisation (off by default).
    pub baumgarte: Baumgarte,
    /// Which variables are simulated.
    pub split: Split,
    /// Whether [`Self::acceleration`] may use the system's articulated-body algorithm
    /// (models without constraints); off, it always forms `M` (and leaves the terms of a
    /// [`Order::Dynamics`] evaluation in [`Self::terms`], as the linearisation needs).
    pub articulated: bool,
    factor: Matrix<N>,
    rhs: Vector<N>,
    reduced: ReducedKkt,
}

/// Scratch for the reduced system of the dynamic variables (see [`ReducedKkt::solve`]).
#[derive(Clone, Debug)]
pub(crate) struct ReducedKkt {
    mdd: DMatrix<f64>,
    rhs: DVector<f64>,
    a: DMatrix<f64>,
    /// `Z = L⁻¹ Dh_dᵀ` for the Cholesky factor `M_dd = L Lᵀ`, column by column.
    z: DMatrix<f64>,
    column: DVector<f64>,
    schur: DMatrix<f64>,
    gamma: DVector<f64>,
}

impl ReducedKkt {
    pub(crate) fn new(nd: usize, m: usize) -> Self {
        ReducedKkt {
            mdd: DMatrix::zeros(nd, nd),
            rhs: DVector::zeros(nd),
            a: DMatrix::zeros(m, nd),
            z: DMatrix::zeros(nd, m),
            column: DVector::zeros(nd),
            schur: DMatrix::zeros(m, m),
            gamma: DVector::zeros(m),
        }
    }

    /// The Cholesky factor `L` of `M_dd = L Lᵀ` (column-major, dynamic × dynamic) the last
    /// [`Self::solve`] formed.
    pub(crate) fn factor(&self) -> &[f64] {
        self.mdd.as_slice()
    }

    /// Solves for the dynamic entries of `x` (its kinematic entries given)
    /// `M_dd x_d − Dh_dᵀλ = b_d − M_dk x_k` and `Dh_d x_d = γ − Dh_k x_k`, by the Cholesky
    /// factor of `M_dd` and the Schur complement `Dh_d M_dd⁻¹ Dh_dᵀ` (docs/derivations.md §6).
    /// Without constraints `dh` and `gamma` are not read. Errors name the dynamic variable or
    /// the constraint at fault.
    #[allow(clippy::too_many_arguments)] // the two blocks of the system and their right sides
    pub(crate) fn solve<S: System>(
        &mut self,
        sys: &S,
        split: &Split,
        mass: &Matrix<S::N>,
        b: &Vector<S::N>,
        dh: &DMatrix<f64>,
        gamma: impl Fn(usize) -> f64,
        x: &mut Vector<S::N>,
        lambda: &mut DVector<f64>,
        step: usize,
        t: f64,
    ) -> Result<(), SimError>
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        // Column-major storage throughout: gather column by column.
        let (n, nd) = (mass.nrows(), split.dynamic.len());
        let (m, mdd) = (mass.as_slice(), self.mdd.as_mut_slice());
        for (c, &j) in split.dynamic.iter().enumerate() {
            let (from, to) = (&m[j * n..(j + 1) * n], &mut mdd[c * nd..(c + 1) * nd]);
            for (x, &i) in to.iter_mut().zip(&split.dynamic) {
                *x = from[i];
            }
        }
        for (r, &i) in split.dynamic.iter().enumerate() {
            self.rhs[r] = b[i];
        }
        for &k in &split.kinematic {
            let (column, xk) = (&m[k * n..(k + 1) * n], x[k]);
            for (r, &i) in split.dynamic.iter().enumerate() {
                self.rhs[r] -= column[i] * xk;
            }
        }
        for r in 0..split.rows {
            self.gamma[r] = gamma(r)
                - split
                    .kinematic
                    .iter()
                    .map(|&k| dh[(r, k)] * x[k])
                    .sum::<f64>();
            for (c, &j) in split.dynamic.iter().enumerate() {
                self.a[(r, c)] = dh[(r, j)];
            }
        }
        cholesky_factor::<Dyn>(&mut self.mdd).map_err(|(i, pivot)| {
            SimError::SingularMassMatrix {
                step,
                t,
                variable: sys.variable_name(split.dynamic[i]).to_string(),
                pivot,
            }
        })?;
        // With M_dd = L Lᵀ, w = L⁻¹ b and Z = L⁻¹ Dh_dᵀ: the Schur complement
        // Dh_d M_dd⁻¹ Dh_dᵀ = ZᵀZ, Dh_d x_free = Zᵀw, and x_d = L⁻ᵀ(w + Zλ) — forward
        // substitutions for every column, one backward one for x.
        let (nd, factor) = (split.dynamic.len(), self.mdd.as_slice());
        cholesky_forward(factor, nd, self.rhs.as_mut_slice());
        if split.rows > 0 {
            for r in 0..split.rows {
                for (c, v) in self.column.iter_mut().enumerate() {
                    *v = self.a[(r, c)];
                }
                cholesky_forward(factor, nd, self.column.as_mut_slice());
                self.z.set_column(r, &self.column);
            }
            // (ZᵀZ) λ = γ − Zᵀw, then w + Zλ.
            self.schur.gemm_tr(1.0, &self.z, &self.z, 0.0);
            lambda.copy_from(&self.gamma);
            lambda.gemv_tr(-1.0, &self.z, &self.rhs, 1.0);
            cholesky_solve::<Dyn>(&mut self.schur, lambda).map_err(|(r, _)| {
                SimError::SingularConstraints {
                    step,
                    t,
                    constraint: sys.constraint_name(r).to_string(),
                }
            })?;
            self.rhs.gemv(1.0, &self.z, lambda, 1.0);
        }
        cholesky_backward(factor, nd, self.rhs.as_mut_slice());
        for (r, &i) in split.dynamic.iter().enumerate() {
            x[i] = self.rhs[r];
        }
        Ok(())
    }
}

impl<N: Dim> Dynamics<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// Buffers sized for `sys`.
    pub fn new<S: System<N = N>>(sys: &S) -> Self {
        let n = sys.dim();
        let split = Split::of(sys);
        let (nd, m) = (split.dynamic.len(), split.rows);
        Dynamics {
            terms: {
                let mut terms = Terms::zeros(n);
                terms.keep_zeros();
                terms
            },
            constraint_terms: ConstraintTerms::zeros(m, n.value()),
            lambda: DVector::zeros(m),
            baumgarte: Baumgarte::default(),
            articulated: true,
            factor: Matrix::zeros_generic(n, n),
            rhs: Vector::zeros_generic(n, nalgebra::U1),
            reduced: ReducedKkt::new(nd, m),
            split,
        }
    }

    /// Whether the articulated-body algorithm is to give `q̈` (asked for, and the model has
    /// no constraints); if so, its inputs at `(cx.t, q, q̇)`: the generalized force from
    /// outside the model (the caller's force, `B u`) into [`Self::external_force`], the
    /// kinematic variables' prescribed `q̈` into `qdd`.
    pub(crate) fn articulated_inputs<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        dq: &Vector<N>,
        qdd: &mut Vector<N>,
    ) -> bool
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        if !self.articulated || self.split.rows > 0 {
            return false;
        }
        self.rhs.as_mut_slice().fill(0.0);
        cx.force.add_force(cx.t, q, dq, &mut self.rhs);
        cx.add_inputs(&mut self.rhs);
        for &i in &self.split.kinematic {
            qdd[i] = cx.motion.kinematic(i, cx.t)[2];
        }
        true
    }

    /// The generalized force from outside the model that [`Self::articulated_inputs`] left.
    pub(crate) fn external_force(&self) -> &Vector<N> {
        &self.rhs
    }

    /// `q̈` at `(cx.t, q, q̇)` into `qdd` (eq. (14)); the kinematic entries of `q`, `q̇` must
    /// hold their prescription at `cx.t`, and `qdd`'s kinematic entries are set from it.
    /// `cx.index` labels errors.
    pub fn acceleration<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &Vector<N>,
        dq: &Vector<N>,
        qdd: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        // The articulated-body algorithm, O(frames), where the system has it (else, or when
        // a pivot is lost, M is formed and factored below).
        if self.articulated_inputs(cx, q, dq, qdd)
            && cx
                .sys
                .articulated_acceleration(q, dq, &self.rhs, qdd, &mut self.terms)
        {
            return finite(qdd, &self.lambda, cx.index, cx.t);
        }
        cx.sys.lagrangian(q, dq, Order::Dynamics, &mut self.terms);
        // rhs = F + u + B u_inputs + ∂L/∂q − (∂²L/∂q̇∂q) q̇
        self.rhs.copy_from(&self.terms.force);
        cx.force.add_force(cx.t, q, dq, &mut self.rhs);
        cx.add_inputs(&mut self.rhs);
        let (sys, motion) = (&mut *cx.sys, &mut *cx.motion);
        let (step, t) = (cx.index, cx.t);
        self.rhs += &self.terms.dl_dq;
        self.rhs.gemv(-1.0, &self.terms.d2l_ddq_dq, dq, 1.0);
        if self.split.is_plain() {
            qdd.copy_from(&self.rhs);
            self.factor.copy_from(&self.terms.mass);
            cholesky_solve(&mut self.factor, qdd).map_err(|(i, pivot)| {
                SimError::SingularMassMatrix {
                    step,
                    t,
                    variable: sys.variable_name(i).to_string(),
                    pivot,
                }
            })?;
        } else {
            for &i in &self.split.kinematic {
                qdd[i] = motion.kinematic(i, t)[2];
            }
            let c = &mut self.constraint_terms;
            if self.split.rows > 0 {
                sys.constraints(q, dq, Order::Dynamics, c);
            }
            // γ = −q̇ᵀD²h q̇ − 2a ḣ − b² h (the Dh_k q̈_k part is the solver's).
            let b = self.baumgarte;
            let gamma = |r: usize| {
                let rate: f64 = (0..dq.len()).map(|i| c.dh[(r, i)] * dq[i]).sum();
                -c.dh_dot[r] - 2.0 * b.a * rate - b.b * b.b * c.h[r]
            };
            self.reduced.solve(
                sys,
                &self.split,
                &self.terms.mass,
                &self.rhs,
                &c.dh,
                gamma,
                qdd,
                &mut self.lambda,
                step,
                t,
            )?;
        }
        finite(qdd, &self.lambda, step, t)
    }
}

/// Inverse dynamics: the generalized forces `τ` that give every variable the acceleration
/// `q̈` at `(q, q̇)` — eq. (14) solved for the force,
/// `τ = M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q − F(q, q̇)`, with `F` the model's own forces (damping,
/// dampers) and the constraint forces `Dhᵀλ` left out (what Pinocchio's RNEA returns, here
/// from the Lagrangian's terms). On a dynamic variable it is the force an input there must
/// supply (with `q̇ = q̈ = 0`: gravity compensation); on a kinematic one, the force that
/// drives it as given. `terms` is scratch; fails when `τ` is not finite.
pub fn inverse_dynamics<S: System>(
    sys: &mut S,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    qdd: &Vector<S::N>,
    terms: &mut Terms<S::N>,
    tau: &mut Vector<S::N>,
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    sys.lagrangian(q, dq, Order::Dynamics, terms);
    tau.gemv(1.0, &terms.mass, qdd, 0.0);
    tau.gemv(1.0, &terms.d2l_ddq_dq, dq, 1.0);
    *tau -= &terms.dl_dq;
    *tau -= &terms.force;
    if tau.iter().any(|x| !x.is_finite()) {
        return Err(SimError::InvalidInput(
            "at this state, the inverse dynamics' forces are not finite (they overflowed a floating-point number)".into(),
        ));
    }
    Ok(())
}

/// `q̈` and `λ` finite, or the error naming the step.
pub(crate) fn finite<N: Dim>(
    qdd: &Vector<N>,
    lambda: &DVector<f64>,
    step: usize,
    t: f64,
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<N>,
{
    if qdd.iter().chain(lambda.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step,
            t,
            what: "acceleration q̈".into(),
        });
    }
    Ok(())
}
