//! One VI step as a map `x = (q₁, p₁, u₁, k₂) ↦ (q₂, p₂, λ)` and its exact first and second
//! derivatives (docs/derivations.md §9), from the implicit function theorem on the converged
//! step.
//!
//! With `w = (q₁, q₂, p₁, u₁, λ)` every quantity the step touches, the step's equations
//! `R(w) = (r_d, h(q₂)) = 0` (the residual's dynamic rows, then the constraints at `q₂`) and
//! its end momentum `p₂(w) = D₂L_d + f⁺`, let `J = ∂R/∂w`, `P = ∂p₂/∂w` and `R_z` the columns
//! of `J` for the unknowns `z = (q₂_d, λ)` (the Newton matrix). Then:
//!
//! * first order: `dz/dx = −R_z⁻¹ R_x`; the tangent `Δ = dw/dx` stacks the identity on the
//!   `x` coordinates and `dz/dx` on the unknowns; `dp₂/dx = P Δ`;
//! * second order, along each direction `j` of `x`: the derivative `D_j J` of the Jacobian
//!   along the tangent `Δ_j` (the same Jacobian evaluated over dual numbers seeded with
//!   `Δ_j`: third derivatives of `L`, `D³h`, the forces' second derivatives, all exact),
//!   then `z_ij = −R_z⁻¹ (D_j J Δ_i)` and `p₂,ij = P_z z_ij + D_j P Δ_i`;
//! * contracted: for a covector `(w_q, w_p, w_λ)` over `(q₂_d, p₂, λ)`,
//!   `Σ w ∂²/∂x_i∂x_j = (μᵀ D_j J + w_pᵀ D_j P) Δ_i` with
//!   `μ = −R_z⁻ᵀ (w_z + P_zᵀ w_p)`: one transposed solve, no tensor.
//!
//! The Jacobians are written once, over any [`Scalar`] ([`jacobians`]): over `f64` at the
//! solution for the first derivatives, over [`Dual`] for their derivatives. Forces the caller
//! adds (a [`GeneralizedForce`]) are held fixed; the model's own (damping, dampers) and the
//! inputs are differentiated.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim};

use super::{Forcing, MidpointVi};
use crate::context::StepContext;
use crate::dual::{Dual, DualOutputs};
use crate::dynamics::GeneralizedForce;
use crate::error::SimError;
use crate::integrate::discrete::{DiscreteLagrangian, Slots};
use crate::outputs::Field;
use crate::scalar::Scalar;
use crate::system::{ConstraintTerms, Order, Sparsity, System, Vector};

/// A block of the step's inputs `x = (q₁, p₁, u₁, k₂)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepInput {
    /// `q₁`, every variable.
    Q1,
    /// `p₁`, the dynamic variables' momenta.
    P1,
    /// `u₁`, the inputs.
    U1,
    /// `k₂`, the kinematic variables at `t₂`.
    K2,
}

impl StepInput {
    /// Every block, in `x`'s order.
    pub const ALL: [StepInput; 4] = [StepInput::Q1, StepInput::P1, StepInput::U1, StepInput::K2];

    /// trep's name of the block (`q1`, `p1`, `u1`, `k2`).
    pub fn name(self) -> &'static str {
        match self {
            StepInput::Q1 => "q1",
            StepInput::P1 => "p1",
            StepInput::U1 => "u1",
            StepInput::K2 => "k2",
        }
    }
}

/// A block of the step's outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepOutput {
    /// `q₂`'s dynamic variables.
    Q2,
    /// `p₂`.
    P2,
    /// `λ`, one per constraint equation (this integrator's force-scaled multiplier).
    Lambda,
}

impl StepOutput {
    /// Every block.
    pub const ALL: [StepOutput; 3] = [StepOutput::Q2, StepOutput::P2, StepOutput::Lambda];
}

/// Sizes of one step and where each block sits in `w = (q₁, q₂, p₁, u₁, λ)` and in `x`.
#[derive(Clone, Debug, PartialEq)]
struct Shape {
    n: usize,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    /// Constraint equations.
    m: usize,
    /// The variable each input pushes on.
    inputs: Vec<usize>,
    ld: DiscreteLagrangian,
    /// `f⁻ = left·F`, `f⁺ = plus·F` (Δt included).
    left: f64,
    plus: f64,
}

impl Shape {
    fn nd(&self) -> usize {
        self.dynamic.len()
    }
    fn nu(&self) -> usize {
        self.inputs.len()
    }
    /// `R`'s rows: the dynamic residuals, then `h(q₂)`.
    fn rows(&self) -> usize {
        self.nd() + self.m
    }
    /// Offsets of `q₂`, `p₁`, `u₁`, `λ` in `w` (`q₁` at 0).
    fn w_q2(&self) -> usize {
        self.n
    }
    fn w_p1(&self) -> usize {
        2 * self.n
    }
    fn w_u1(&self) -> usize {
        2 * self.n + self.nd()
    }
    fn w_lambda(&self) -> usize {
        2 * self.n + self.nd() + self.nu()
    }
    fn w(&self) -> usize {
        self.w_lambda() + self.m
    }
    /// Where block `b` sits in `x`, and its width.
    fn x_block(&self, b: StepInput) -> (usize, usize) {
        let (n, nd, nu) = (self.n, self.nd(), self.nu());
        match b {
            StepInput::Q1 => (0, n),
            StepInput::P1 => (n, nd),
            StepInput::U1 => (n + nd, nu),
            StepInput::K2 => (n + nd + nu, self.kinematic.len()),
        }
    }
    fn x(&self) -> usize {
        self.n + self.nd() + self.nu() + self.kinematic.len()
    }
}

/// What the step's Jacobians are built from, over a scalar: the continuous terms at the
/// quadrature point (`L_qq`, `L_q̇q`, `M`, `F_q`, `F_q̇`, row-major n × n), `Dh(q₁)`,
/// `D²h(q₁)` (m × n × n), `Dh(q₂)` and `λ`.
struct StepTerms<'a, T> {
    lqq: &'a [T],
    lvq: &'a [T],
    mass: &'a [T],
    fq: &'a [T],
    fv: &'a [T],
    dh1: &'a [T],
    d2h1: &'a [T],
    dh2: &'a [T],
    lambda: &'a [T],
}

/// `J = ∂R/∂w` (rows × w) and `P = ∂p₂/∂w` (n_d × w), row-major, from the step's terms:
///
/// * `∂r_i/∂q₁ⱼ = D₁D₁L_d + f⁻·∂F/∂q₁ + Δt Σ_s λ_s D²h_s(q₁)`, `∂r_i/∂q₂ⱼ = D₂D₁L_d +
///   f⁻·∂F/∂q₂`, `∂r_i/∂p₁ = I`, `∂r_i/∂u_k = left·B`, `∂r_i/∂λ_s = Δt Dh_s(q₁)ᵢ`;
/// * `∂h_s/∂q₂ = Dh_s(q₂)`;
/// * `∂p₂ᵢ/∂q₁ⱼ = (D₂D₁L_d)ⱼᵢ + f⁺·∂F/∂q₁`, `∂p₂ᵢ/∂q₂ⱼ = D₂D₂L_d + f⁺·∂F/∂q₂`,
///   `∂p₂ᵢ/∂u_k = plus·B`,
///
/// with `∂F/∂q₁ = (1−α)F_q − F_q̇/Δt`, `∂F/∂q₂ = αF_q + F_q̇/Δt` (F at `(q_α, v)`).
fn jacobians<T: Scalar>(sh: &Shape, st: &StepTerms<T>, jac: &mut [T], pjac: &mut [T]) {
    let (n, m, w) = (sh.n, sh.m, sh.w());
    let (a, dt) = (sh.ld.alpha, sh.ld.dt);
    let c = T::constant;
    jac.fill(T::zero());
    pjac.fill(T::zero());
    let (by_q1_q, by_q1_v, by_q2_q, by_q2_v) = (c(1.0 - a), c(-1.0 / dt), c(a), c(1.0 / dt));
    for (r, &i) in sh.dynamic.iter().enumerate() {
        let (row, prow) = (&mut jac[r * w..(r + 1) * w], &mut pjac[r * w..(r + 1) * w]);
        for j in 0..n {
            let (ij, ji) = (i * n + j, j * n + i);
            let second = |slots, ij: usize, ji: usize| {
                sh.ld
                    .second(slots, st.lqq[ij], st.lvq[ij], st.lvq[ji], st.mass[ij])
            };
            let f1 = by_q1_q * st.fq[ij] + by_q1_v * st.fv[ij];
            let f2 = by_q2_q * st.fq[ij] + by_q2_v * st.fv[ij];
            let mut multiplier = T::zero();
            for s in 0..m {
                multiplier += st.lambda[s] * st.d2h1[(s * n + i) * n + j];
            }
            row[j] = second(Slots::D1D1, ij, ji) + c(sh.left) * f1 + c(dt) * multiplier;
            row[sh.w_q2() + j] = second(Slots::D2D1, ij, ji) + c(sh.left) * f2;
            // D₁D₂L_d = (D₂D₁L_d)ᵀ: entry (j, i) of D₂D₁.
            prow[j] = second(Slots::D2D1, ji, ij) + c(sh.plus) * f1;
            prow[sh.w_q2() + j] = second(Slots::D2D2, ij, ji) + c(sh.plus) * f2;
        }
        row[sh.w_p1() + r] = c(1.0);
        for (k, &v) in sh.inputs.iter().enumerate() {
            if v == i {
                row[sh.w_u1() + k] = c(sh.left);
                prow[sh.w_u1() + k] = c(sh.plus);
            }
        }
        for s in 0..m {
            row[sh.w_lambda() + s] = c(dt) * st.dh1[s * n + i];
        }
    }
    for s in 0..m {
        let row = &mut jac[(sh.nd() + s) * w..(sh.nd() + s + 1) * w];
        for j in 0..n {
            row[sh.w_q2() + j] = st.dh2[s * n + j];
        }
    }
}

/// The step's first derivatives as blocks (trep's `q2_dq1` …). Rows: the dynamic variables
/// (`q₂`, `p₂`) or the constraint equations (`λ`, this integrator's force-scaled multiplier:
/// trep's `λ₁ = −Δt λ`); columns: all variables (`q₁`), the dynamic ones (`p₁`), the inputs
/// (`u₁`), the kinematic ones (`k₂`, the kinematic part of `q₂`). docs/derivations.md §9.
#[derive(Clone, Debug, PartialEq)]
pub struct StepDerivatives {
    /// `∂q₂/∂q₁`.
    pub q2_dq1: DMatrix<f64>,
    /// `∂q₂/∂p₁`.
    pub q2_dp1: DMatrix<f64>,
    /// `∂q₂/∂u₁`.
    pub q2_du1: DMatrix<f64>,
    /// `∂q₂/∂k₂`.
    pub q2_dk2: DMatrix<f64>,
    /// `∂p₂/∂q₁`.
    pub p2_dq1: DMatrix<f64>,
    /// `∂p₂/∂p₁`.
    pub p2_dp1: DMatrix<f64>,
    /// `∂p₂/∂u₁`.
    pub p2_du1: DMatrix<f64>,
    /// `∂p₂/∂k₂`.
    pub p2_dk2: DMatrix<f64>,
    /// `∂λ/∂q₁`.
    pub lambda_dq1: DMatrix<f64>,
    /// `∂λ/∂p₁`.
    pub lambda_dp1: DMatrix<f64>,
    /// `∂λ/∂u₁`.
    pub lambda_du1: DMatrix<f64>,
    /// `∂λ/∂k₂`.
    pub lambda_dk2: DMatrix<f64>,
}

impl StepDerivatives {
    /// The block `∂of/∂by`.
    pub fn block(&self, of: StepOutput, by: StepInput) -> &DMatrix<f64> {
        use StepInput::*;
        match (of, by) {
            (StepOutput::Q2, Q1) => &self.q2_dq1,
            (StepOutput::Q2, P1) => &self.q2_dp1,
            (StepOutput::Q2, U1) => &self.q2_du1,
            (StepOutput::Q2, K2) => &self.q2_dk2,
            (StepOutput::P2, Q1) => &self.p2_dq1,
            (StepOutput::P2, P1) => &self.p2_dp1,
            (StepOutput::P2, U1) => &self.p2_du1,
            (StepOutput::P2, K2) => &self.p2_dk2,
            (StepOutput::Lambda, Q1) => &self.lambda_dq1,
            (StepOutput::Lambda, P1) => &self.lambda_dp1,
            (StepOutput::Lambda, U1) => &self.lambda_du1,
            (StepOutput::Lambda, K2) => &self.lambda_dk2,
        }
    }
}

/// The step's second derivatives (trep's 30, `q2_dq1dp1` …): for each output row, the
/// symmetric matrix over all of `x = (q₁, p₁, u₁, k₂)`; [`Self::block`] cuts out one pair of
/// input blocks.
#[derive(Clone, Debug, PartialEq)]
pub struct StepSecondDerivatives {
    shape: Shape,
    /// `∂²q₂ᵢ/∂x∂x`, one x × x matrix per dynamic variable.
    pub q2: Vec<DMatrix<f64>>,
    /// `∂²p₂ᵢ/∂x∂x`.
    pub p2: Vec<DMatrix<f64>>,
    /// `∂²λ_s/∂x∂x`.
    pub lambda: Vec<DMatrix<f64>>,
}

impl StepSecondDerivatives {
    /// `∂²of/∂a∂b`: one `|a| × |b|` matrix per row of `of`.
    pub fn block(&self, of: StepOutput, a: StepInput, b: StepInput) -> Vec<DMatrix<f64>> {
        let ((ra, wa), (rb, wb)) = (self.shape.x_block(a), self.shape.x_block(b));
        let rows = match of {
            StepOutput::Q2 => &self.q2,
            StepOutput::P2 => &self.p2,
            StepOutput::Lambda => &self.lambda,
        };
        rows.iter()
            .map(|h| h.view((ra, rb), (wa, wb)).into_owned())
            .collect()
    }
}

/// A covector over the step's outputs, `(w_q, w_p, w_λ)` on `(q₂_d, p₂, λ)`: what
/// [`MidpointVi::contracted_second_derivatives`] contracts the second derivatives with.
#[derive(Clone, Debug, PartialEq)]
pub struct StepCovector {
    /// On the dynamic variables of `q₂`.
    pub q2: DVector<f64>,
    /// On `p₂`.
    pub p2: DVector<f64>,
    /// On `λ`.
    pub lambda: DVector<f64>,
}

/// The step linearised at its solution: the Jacobians, the tangent and the factor of `R_z`.
struct Linearised {
    shape: Shape,
    /// `P` (n_d × w).
    pjac: DMatrix<f64>,
    /// `Δ = dw/dx` (w × x).
    tangent: DMatrix<f64>,
    /// `R_z`, rows × (n_d + m): `J`'s columns for `q₂_d`, then `λ`.
    r_z: DMatrix<f64>,
    /// The point: `q₁`, `q₂` (all variables) and `λ`.
    q1: Vec<f64>,
    q2: Vec<f64>,
    lambda: Vec<f64>,
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The first derivatives of the step from `(q₁, p₁)` at `cx.t` over `cx.dt`, with inputs
    /// `cx.u`, that converged to `q₂` with the multipliers [`Self::lambda`] (call it right
    /// after [`Self::step`], with that step's `q₁`, `p₁` and result). Allocates its matrices.
    pub fn derivatives<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<StepDerivatives, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let lin = self.linearise(cx, q1, p1, q2)?;
        Ok(lin.first())
    }

    /// The first and second derivatives of the step (see [`Self::derivatives`]): trep's 30
    /// second derivatives, from one evaluation over dual numbers per input direction.
    /// Allocates.
    pub fn second_derivatives<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<(StepDerivatives, StepSecondDerivatives), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let lin = self.linearise(cx, q1, p1, q2)?;
        let sh = &lin.shape;
        let (nd, m, x) = (sh.nd(), sh.m, sh.x());
        let lu = lin.r_z.clone().lu();
        let mut second = StepSecondDerivatives {
            shape: sh.clone(),
            q2: vec![DMatrix::zeros(x, x); nd],
            p2: vec![DMatrix::zeros(x, x); nd],
            lambda: vec![DMatrix::zeros(x, x); m],
        };
        let p_z = DMatrix::from_fn(nd, nd, |r, c| lin.pjac[(r, sh.w_q2() + sh.dynamic[c])]);
        let mut duals = DualJacobians::new(sh, cx.sys.dof(), cx.sys.constraint_count());
        for j in 0..x {
            let (dj, dp) = duals.along(cx.sys, &lin, j);
            // G = D_jJ Δ, z_·j = −R_z⁻¹ G, p₂_·j = P_z z_·j + D_jP Δ.
            let g = &dj * &lin.tangent;
            let z = -lu.solve(&g).ok_or_else(|| singular(cx.index, cx.t))?;
            let p = &p_z * z.rows(0, nd) + &dp * &lin.tangent;
            for i in 0..x {
                for r in 0..nd {
                    second.q2[r][(i, j)] = z[(r, i)];
                    second.p2[r][(i, j)] = p[(r, i)];
                }
                for s in 0..m {
                    second.lambda[s][(i, j)] = z[(nd + s, i)];
                }
            }
        }
        Ok((lin.first(), second))
    }

    /// `Σ_o w_o ∂²o/∂x∂x` over the step's outputs `o ∈ (q₂_d, p₂, λ)` for the covector `w`
    /// (x × x, x = (q₁, p₁, u₁, k₂)), without forming the second-derivative tensors: one
    /// transposed solve for the adjoint `μ`, then one dual evaluation per direction (the
    /// module docs). What DDP needs. Allocates.
    pub fn contracted_second_derivatives<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        w: &StepCovector,
    ) -> Result<DMatrix<f64>, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let lin = self.linearise(cx, q1, p1, q2)?;
        let sh = &lin.shape;
        let (nd, m, x) = (sh.nd(), sh.m, sh.x());
        // μ = −R_z⁻ᵀ (w_z + P_zᵀ w_p), w_z = (w_q, w_λ).
        let mut rhs = DVector::<f64>::zeros(nd + m);
        for c in 0..nd {
            rhs[c] = w.q2[c];
            for r in 0..nd {
                rhs[c] += lin.pjac[(r, sh.w_q2() + sh.dynamic[c])] * w.p2[r];
            }
        }
        for s in 0..m {
            rhs[nd + s] = w.lambda[s];
        }
        let mu = -lin
            .r_z
            .transpose()
            .lu()
            .solve(&rhs)
            .ok_or_else(|| singular(cx.index, cx.t))?;
        let mut out = DMatrix::<f64>::zeros(x, x);
        let mut duals = DualJacobians::new(sh, cx.sys.dof(), cx.sys.constraint_count());
        for j in 0..x {
            let (dj, dp) = duals.along(cx.sys, &lin, j);
            // c_j = μᵀ D_jJ + w_pᵀ D_jP, then column j = Δᵀ c_j.
            let c = dj.tr_mul(&mu) + dp.tr_mul(&w.p2);
            out.set_column(j, &lin.tangent.tr_mul(&c));
        }
        Ok(out)
    }

    /// The step's shape, `P` at the solution, the tangent and `R_z`.
    fn linearise<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<Linearised, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (a, dt) = (self.settings.alpha, cx.dt);
        let n = q1.len();
        let (left, plus) = match self.settings.forcing {
            Forcing::Split => ((1.0 - a) * dt, a * dt),
            Forcing::Left => (dt, 0.0),
        };
        let shape = Shape {
            n,
            dynamic: self.split.dynamic.clone(),
            kinematic: self.split.kinematic.clone(),
            m: self.split.rows,
            inputs: (0..cx.u.len()).map(|k| cx.sys.input_variable(k)).collect(),
            ld: DiscreteLagrangian { alpha: a, dt },
            left,
            plus,
        };
        let (nd, m, w, x) = (shape.nd(), shape.m, shape.w(), shape.x());
        // Terms at the quadrature point, Dh(q₁), Dh(q₂) at the solution; D²h(q₁).
        self.prepare(cx.sys, q1);
        self.residual(cx, q1, p1, q2, true);
        let mut c1 = ConstraintTerms::zeros(m, n);
        if m > 0 {
            let zero = Vector::<N>::zeros_generic(cx.sys.dim(), nalgebra::U1);
            cx.sys.constraints(q1, &zero, Order::Full, &mut c1);
        }
        let t = &self.terms;
        let row_major = |f: &dyn Fn(usize, usize) -> f64| {
            (0..n * n).map(|ij| f(ij / n, ij % n)).collect::<Vec<f64>>()
        };
        // Only the entries the evaluation wrote (its sparsity) hold force derivatives.
        let (fq, fv) = match t.force_derivatives {
            Sparsity::Zero => (vec![0.0; n * n], vec![0.0; n * n]),
            Sparsity::Diagonal => (
                vec![0.0; n * n],
                row_major(&|i, j| if i == j { t.dforce_ddq[(i, i)] } else { 0.0 }),
            ),
            Sparsity::Dense => (
                row_major(&|i, j| t.dforce_dq[(i, j)]),
                row_major(&|i, j| t.dforce_ddq[(i, j)]),
            ),
        };
        let constraint_rows =
            |d: &DMatrix<f64>| (0..m * n).map(|k| d[(k / n, k % n)]).collect::<Vec<f64>>();
        let d2h1: Vec<f64> = (0..m * n * n)
            .map(|k| c1.d2h[k / (n * n)][((k / n) % n, k % n)])
            .collect();
        let lambda: Vec<f64> = self.lambda.iter().copied().collect();
        let (lqq, lvq, mass) = (
            row_major(&|i, j| t.d2l_dq_dq[(i, j)]),
            row_major(&|i, j| t.d2l_ddq_dq[(i, j)]),
            row_major(&|i, j| t.mass[(i, j)]),
        );
        let (dh1, dh2) = (
            constraint_rows(&self.dh1),
            constraint_rows(&self.constraint_terms.dh),
        );
        let terms = StepTerms {
            lqq: &lqq,
            lvq: &lvq,
            mass: &mass,
            fq: &fq,
            fv: &fv,
            dh1: &dh1,
            d2h1: &d2h1,
            dh2: &dh2,
            lambda: &lambda,
        };
        let (mut jac, mut pjac) = (vec![0.0; (nd + m) * w], vec![0.0; nd * w]);
        jacobians(&shape, &terms, &mut jac, &mut pjac);
        let jac = DMatrix::from_row_slice(nd + m, w, &jac);
        let pjac = DMatrix::from_row_slice(nd, w, &pjac);
        // R_z: the columns of q₂_d and λ; R_x: those of q₁, p₁, u₁ and q₂_k.
        let z_columns: Vec<usize> = (shape.dynamic.iter().map(|&i| shape.w_q2() + i))
            .chain((0..m).map(|s| shape.w_lambda() + s))
            .collect();
        let x_columns: Vec<usize> = (0..n)
            .chain((0..nd).map(|r| shape.w_p1() + r))
            .chain((0..shape.nu()).map(|k| shape.w_u1() + k))
            .chain(shape.kinematic.iter().map(|&k| shape.w_q2() + k))
            .collect();
        let r_z = DMatrix::from_fn(nd + m, nd + m, |r, c| jac[(r, z_columns[c])]);
        let r_x = DMatrix::from_fn(nd + m, x, |r, c| jac[(r, x_columns[c])]);
        let dz = -r_z
            .clone()
            .lu()
            .solve(&r_x)
            .ok_or_else(|| singular(cx.index, cx.t))?;
        // Δ: the identity on x's own coordinates, dz/dx on the unknowns.
        let mut tangent = DMatrix::<f64>::zeros(w, x);
        for (c, &col) in x_columns.iter().enumerate() {
            tangent[(col, c)] = 1.0;
        }
        for (r, &col) in z_columns.iter().enumerate() {
            tangent.set_row(col, &dz.row(r));
        }
        Ok(Linearised {
            shape,
            pjac,
            tangent,
            r_z,
            q1: q1.iter().copied().collect(),
            q2: q2.iter().copied().collect(),
            lambda,
        })
    }
}

/// A singular Newton matrix at a converged step (constraints that became dependent).
fn singular(step: usize, t: f64) -> SimError {
    SimError::SingularJacobian {
        step,
        t,
        variable: "the step's Newton matrix, for its derivatives".into(),
    }
}

impl Linearised {
    /// The first-derivative blocks: `dq₂/dx` from the tangent's `q₂` rows, `dλ/dx` from its
    /// `λ` rows, `dp₂/dx = P Δ`.
    fn first(&self) -> StepDerivatives {
        let sh = &self.shape;
        let dp2 = &self.pjac * &self.tangent;
        let q2 = |b| {
            let (c0, wc) = sh.x_block(b);
            DMatrix::from_fn(sh.nd(), wc, |r, c| {
                self.tangent[(sh.w_q2() + sh.dynamic[r], c0 + c)]
            })
        };
        let p2 = |b| {
            let (c0, wc) = sh.x_block(b);
            dp2.view((0, c0), (sh.nd(), wc)).into_owned()
        };
        let lambda = |b| {
            let (c0, wc) = sh.x_block(b);
            self.tangent
                .view((sh.w_lambda(), c0), (sh.m, wc))
                .into_owned()
        };
        use StepInput::*;
        StepDerivatives {
            q2_dq1: q2(Q1),
            q2_dp1: q2(P1),
            q2_du1: q2(U1),
            q2_dk2: q2(K2),
            p2_dq1: p2(Q1),
            p2_dp1: p2(P1),
            p2_du1: p2(U1),
            p2_dk2: p2(K2),
            lambda_dq1: lambda(Q1),
            lambda_dp1: lambda(P1),
            lambda_du1: lambda(U1),
            lambda_dk2: lambda(K2),
        }
    }
}

/// Scratch for the Jacobians over dual numbers along one tangent direction.
struct DualJacobians {
    /// At the quadrature point (Full), at `q₁` (constraints, Full), at `q₂` (constraints).
    at_alpha: DualOutputs,
    at_q1: DualOutputs,
    at_q2: DualOutputs,
    jac: Vec<Dual>,
    pjac: Vec<Dual>,
}

impl DualJacobians {
    fn new(sh: &Shape, n: usize, m: usize) -> Self {
        DualJacobians {
            at_alpha: DualOutputs::new(n, m),
            at_q1: DualOutputs::new(n, m),
            at_q2: DualOutputs::new(n, m),
            jac: vec![Dual::default(); sh.rows() * sh.w()],
            pjac: vec![Dual::default(); sh.nd() * sh.w()],
        }
    }

    /// `(D_j J, D_j P)`: the Jacobians' derivatives along the tangent's column `j`.
    fn along<S: System>(
        &mut self,
        sys: &mut S,
        lin: &Linearised,
        j: usize,
    ) -> (DMatrix<f64>, DMatrix<f64>)
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let sh = &lin.shape;
        let (n, m, w) = (sh.n, sh.m, sh.w());
        let (a, dt) = (sh.ld.alpha, sh.ld.dt);
        let dir = lin.tangent.column(j);
        let (dq1, dq2) = (dir.rows(0, n), dir.rows(sh.w_q2(), n));
        // The quadrature point and its motion along the direction.
        let q_alpha: Vec<Dual> = (0..n)
            .map(|i| {
                Dual::new(
                    lin.q1[i] + a * (lin.q2[i] - lin.q1[i]),
                    (1.0 - a) * dq1[i] + a * dq2[i],
                )
            })
            .collect();
        let v: Vec<Dual> = (0..n)
            .map(|i| Dual::new((lin.q2[i] - lin.q1[i]) / dt, (dq2[i] - dq1[i]) / dt))
            .collect();
        sys.evaluate_dual(&q_alpha, &v, Order::Full, &mut self.at_alpha);
        let rest = vec![Dual::default(); n];
        if m > 0 {
            let q1: Vec<Dual> = (0..n).map(|i| Dual::new(lin.q1[i], dq1[i])).collect();
            let q2: Vec<Dual> = (0..n).map(|i| Dual::new(lin.q2[i], dq2[i])).collect();
            sys.evaluate_dual(&q1, &rest, Order::Full, &mut self.at_q1);
            sys.evaluate_dual(&q2, &rest, Order::First, &mut self.at_q2);
        }
        let lambda: Vec<Dual> = (0..m)
            .map(|s| Dual::new(lin.lambda[s], dir[sh.w_lambda() + s]))
            .collect();
        let (t, c1, c2) = (&self.at_alpha, &self.at_q1, &self.at_q2);
        let terms = StepTerms {
            lqq: t.field(Field::D2lDqDq),
            lvq: t.field(Field::D2lDdqDq),
            mass: t.field(Field::Mass),
            fq: t.field(Field::DforceDq),
            fv: t.field(Field::DforceDdq),
            dh1: c1.field(Field::Dh),
            d2h1: c1.field(Field::D2h),
            dh2: c2.field(Field::Dh),
            lambda: &lambda,
        };
        jacobians(sh, &terms, &mut self.jac, &mut self.pjac);
        (
            DMatrix::from_fn(sh.rows(), w, |r, c| self.jac[r * w + c].d),
            DMatrix::from_fn(sh.nd(), w, |r, c| self.pjac[r * w + c].d),
        )
    }
}
