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
//!   `x` coordinates and `dz/dx` on the unknowns; `dp₂/dx = P Δ`. Only the `q₁`, `p₁`, `k₂`
//!   columns are solved for: an input's column of `R_x` is `left` times its variable's `p₁`
//!   column, so its derivatives are that column's scaled (plus `plus` on `p₂`'s own row);
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

use nalgebra::{allocator::Allocator, DMatrix, DVector, DVectorView, DefaultAllocator, Dim};

use super::MidpointVi;
use crate::context::StepContext;
use crate::dual::{Dual, DualOutputs};
use crate::dynamics::GeneralizedForce;
use crate::error::SimError;
use crate::integrate::discrete::{DiscreteLagrangian, Slots};
use crate::linalg::{
    combine_rows, dot, lu_factor_packed, lu_solve_packed, lu_solve_packed_rows,
    lu_solve_transposed_packed,
};
use crate::outputs::Field;
use crate::scalar::Scalar;
use crate::system::{row_variables, ConstraintTerms, Order, Sparsity, System, Vector};

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

    /// trep's name of the block (`q2`, `p2`, `lambda1`: trep's `λ₁` is −Δt times this
    /// integrator's force-scaled λ, as the reports scale it).
    pub fn name(self) -> &'static str {
        match self {
            StepOutput::Q2 => "q2",
            StepOutput::P2 => "p2",
            StepOutput::Lambda => "lambda1",
        }
    }
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
/// quadrature point (`L_qq`, `L_q̇q` and its transpose, `M`, `F_q`, `F_q̇`, row-major n × n;
/// `forces`: whether `F_q`, `F_q̇` may be non-zero), `Dh(q₁)`, `Σ_s λ_s D²h_s(q₁)` (n × n,
/// [`contract`]) and `Dh(q₂)`.
struct StepTerms<'a, T> {
    lqq: &'a [T],
    lvq: &'a [T],
    lvq_t: &'a [T],
    mass: &'a [T],
    forces: bool,
    fq: &'a [T],
    fv: &'a [T],
    dh1: &'a [T],
    lambda_d2h1: &'a [T],
    dh2: &'a [T],
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
#[inline(always)]
fn jacobians<T: Scalar>(sh: &Shape, st: &StepTerms<T>, jac: &mut [T], pjac: &mut [T]) {
    let (n, m, w) = (sh.n, sh.m, sh.w());
    let (a, dt) = (sh.ld.alpha, sh.ld.dt);
    let c = T::constant;
    // Every entry this writes is written on every call; the others stay zero from the
    // buffers' making (so nothing is cleared here).
    let [d1d1, d2d1, d2d2] = [Slots::D1D1, Slots::D2D1, Slots::D2D2].map(|s| sh.ld.slot::<T>(s));
    let (cdt, left, plus) = (c(dt), c(sh.left), c(sh.plus));
    // Row i of an n × n term (the transpose's row is the term's column).
    fn row<T>(x: &[T], i: usize, n: usize) -> &[T] {
        &x[i * n..(i + 1) * n]
    }
    for (r, &i) in sh.dynamic.iter().enumerate() {
        let at = |x| row(x, i, n);
        let (lqq, lvq, lvq_t, mass, l_d2h) = (
            at(st.lqq),
            at(st.lvq),
            at(st.lvq_t),
            at(st.mass),
            at(st.lambda_d2h1),
        );
        let (by_q1, rest) = jac[r * w..(r + 1) * w].split_at_mut(n);
        let (by_q2, rest) = rest.split_at_mut(n);
        rest[r] = c(1.0);
        let (p_by_q1, p_rest) = pjac[r * w..(r + 1) * w].split_at_mut(n);
        let p_by_q2 = &mut p_rest[..n];
        for j in 0..n {
            let (qq, vq, vq_t, mm) = (lqq[j], lvq[j], lvq_t[j], mass[j]);
            by_q1[j] = d1d1.at(qq, vq, vq_t, mm) + cdt * l_d2h[j];
            by_q2[j] = d2d1.at(qq, vq, vq_t, mm);
            // D₁D₂L_d = (D₂D₁L_d)ᵀ: entry (j, i) of D₂D₁ (L_qq and M symmetric).
            p_by_q1[j] = d2d1.at(qq, vq_t, vq, mm);
            p_by_q2[j] = d2d2.at(qq, vq, vq_t, mm);
        }
        if st.forces {
            // ∂F/∂q₁ = (1−α)F_q − F_q̇/Δt, ∂F/∂q₂ = αF_q + F_q̇/Δt.
            let (fq, fv) = (at(st.fq), at(st.fv));
            let (q1_q, v1, q2_q) = (c(1.0 - a), c(1.0 / dt), c(a));
            for j in 0..n {
                let f1 = q1_q * fq[j] - v1 * fv[j];
                let f2 = q2_q * fq[j] + v1 * fv[j];
                by_q1[j] += left * f1;
                by_q2[j] += left * f2;
                p_by_q1[j] += plus * f1;
                p_by_q2[j] += plus * f2;
            }
        }
        for (k, &v) in sh.inputs.iter().enumerate() {
            if v == i {
                jac[r * w + sh.w_u1() + k] = left;
                pjac[r * w + sh.w_u1() + k] = plus;
            }
        }
        for s in 0..m {
            jac[r * w + sh.w_lambda() + s] = cdt * st.dh1[s * n + i];
        }
    }
    for s in 0..m {
        let row = &mut jac[(sh.nd() + s) * w..(sh.nd() + s + 1) * w];
        row[sh.w_q2()..sh.w_q2() + n].copy_from_slice(&st.dh2[s * n..(s + 1) * n]);
    }
}

/// `Σ_s λ_s D²h_s` into `out`'s rows chosen by `rows[i]` (row-major, rows of `n`; D²h_s is
/// symmetric, so its row i is its column-major column i): the multipliers' term of
/// `∂r/∂q₁`. `d2h` holds one n × n block per constraint row, zero outside the row's
/// variables where `variables(s)` names them; `add(o, λ, x)` is `o += λx`. A multiplier at
/// zero adds nothing. Over `f64` at the solution ([`contract_hessians`]) and over dual
/// numbers along each direction of the second derivatives.
#[inline(always)]
fn contract_on_rows<'a, T: Scalar + PartialEq + 'a>(
    out: &mut [T],
    n: usize,
    rows: &[bool],
    lambda: &[T],
    d2h: impl Iterator<Item = &'a [T]>,
    variables: impl Fn(usize) -> Option<&'a [usize]>,
    add: impl Fn(&mut T, T, T),
) {
    for i in (0..n).filter(|&i| rows[i]) {
        out[i * n..(i + 1) * n].fill(T::zero());
    }
    for (s, (&l, h)) in lambda.iter().zip(d2h).enumerate() {
        if l == T::zero() {
            continue;
        }
        match variables(s) {
            // Only the rows and columns of the row's own variables.
            Some(vars) => {
                for &i in vars.iter().filter(|&&i| rows[i]) {
                    for &j in vars {
                        add(&mut out[i * n + j], l, h[i * n + j]);
                    }
                }
            }
            None => {
                for i in (0..n).filter(|&i| rows[i]) {
                    let (row, column) = (&mut out[i * n..(i + 1) * n], &h[i * n..(i + 1) * n]);
                    row.iter_mut().zip(column).for_each(|(o, &x)| add(o, l, x));
                }
            }
        }
    }
}

/// [`contract_on_rows`] over `f64` on the dynamic rows (`dynamic[i]`), from the constraints'
/// terms. Compiled also for AVX2 with fused multiply-adds and for AVX, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn contract_hessians(
    out: &mut [f64],
    n: usize,
    dynamic: &[bool],
    lambda: &[f64],
    c: &ConstraintTerms,
) {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        contract_hessians_with::<true>(out, n, dynamic, lambda, c);
    } else {
        contract_hessians_with::<false>(out, n, dynamic, lambda, c);
    }
}

/// [`contract_hessians`] with fused multiply-adds or without (both tested on any CPU).
#[inline(always)]
fn contract_hessians_with<const FUSED: bool>(
    out: &mut [f64],
    n: usize,
    dynamic: &[bool],
    lambda: &[f64],
    c: &ConstraintTerms,
) {
    let blocks = c.d2h.iter().map(|h| h.as_slice());
    contract_on_rows(
        out,
        n,
        dynamic,
        lambda,
        blocks,
        |s| c.variables(s),
        |o, l, x| *o = if FUSED { l.mul_add(x, *o) } else { *o + l * x },
    );
}

/// [`jacobians`] over `f64`, compiled also for AVX and chosen at run time (the same
/// operations in the same order on every CPU: no fused multiply-adds here).
#[multiversion::multiversion(targets("x86_64+avx"))]
fn jacobians_f64(sh: &Shape, st: &StepTerms<f64>, jac: &mut [f64], pjac: &mut [f64]) {
    jacobians(sh, st, jac, pjac);
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

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The first derivatives of the step from `(q₁, p₁)` at `cx.t` over `cx.dt`, with inputs
    /// `cx.u` (missing ones zero; the `u₁` columns are every input of the model), that
    /// converged to `q₂` with the multipliers [`Self::lambda`] (call it right after
    /// [`Self::step`], with that step's `q₁`, `p₁` and result). Allocates the result; see
    /// [`Self::derivatives_into`].
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
        let mut out = StepDerivatives::empty();
        self.derivatives_into(cx, q1, p1, q2, &mut out)?;
        Ok(out)
    }

    /// [`Self::derivatives`] into `out`: after the first call (which sizes the workspace and
    /// `out`), nothing is allocated.
    pub fn derivatives_into<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        out: &mut StepDerivatives,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        self.linearise(cx, q1, p1, q2)?.first_into(out);
        Ok(())
    }

    /// The first and second derivatives of the step (see [`Self::derivatives`]): trep's 30
    /// second derivatives, from one evaluation over dual numbers per input direction.
    /// Allocates the result.
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
        lin.fill_tangent();
        let mut first = StepDerivatives::empty();
        lin.first_into(&mut first);
        let sh = lin.shape.clone();
        let (nd, m, x, rows, wl) = (sh.nd(), sh.m, sh.x(), sh.rows(), sh.w());
        let mut second = StepSecondDerivatives {
            shape: sh.clone(),
            q2: vec![DMatrix::zeros(x, x); nd],
            p2: vec![DMatrix::zeros(x, x); nd],
            lambda: vec![DMatrix::zeros(x, x); m],
        };
        let mut duals = lin
            .duals
            .take()
            .unwrap_or_else(|| DualJacobians::new(&sh, cx.sys));
        let mut g = vec![0.0; rows];
        for j in 0..x {
            if let Some(from) = lin.input_direction(j) {
                // An input's direction moves J and P as `left` times its variable's p₁
                // direction (or not at all): its columns are that one's, scaled.
                let scale = |h: &mut DMatrix<f64>| {
                    for i in 0..x {
                        h[(i, j)] = from.map_or(0.0, |s| sh.left * h[(i, s)]);
                    }
                };
                second.q2.iter_mut().for_each(scale);
                second.p2.iter_mut().for_each(scale);
                second.lambda.iter_mut().for_each(scale);
                continue;
            }
            duals.along(cx.sys, lin, j);
            // For each i: G = D_jJ Δ_i, z_ij = −R_z⁻¹ G, p₂,ij = P_z z_ij + D_jP Δ_i.
            for i in 0..x {
                let di = lin.tangent.column(i);
                duals.times(di, &mut g);
                lu_solve_packed(&lin.factor, rows, &lin.pivots, &mut g);
                for r in 0..nd {
                    second.q2[r][(i, j)] = -g[r];
                }
                for s in 0..m {
                    second.lambda[s][(i, j)] = -g[nd + s];
                }
                for r in 0..nd {
                    let prow = &lin.pjac[r * wl..(r + 1) * wl];
                    let mut p = duals.p_times(r, di);
                    for (c, &k) in sh.dynamic.iter().enumerate() {
                        p -= prow[sh.w_q2() + k] * g[c];
                    }
                    second.p2[r][(i, j)] = p;
                }
            }
        }
        lin.duals = Some(duals);
        Ok((first, second))
    }

    /// `Σ_o w_o ∂²o/∂x∂x` over the step's outputs `o ∈ (q₂_d, p₂, λ)` for the covector `w`
    /// into `out` (x × x, x = (q₁, p₁, u₁, k₂); resized only when its shape differs), without
    /// forming the second-derivative tensors: one transposed solve for the adjoint `μ`, then
    /// one dual evaluation per direction (the module docs). What DDP needs; after the first
    /// call nothing is allocated.
    pub fn contracted_second_derivatives<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
        w: &StepCovector,
        out: &mut DMatrix<f64>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let lin = self.linearise(cx, q1, p1, q2)?;
        lin.fill_tangent();
        let sh = &lin.shape;
        let (nd, m, x, rows, wl) = (sh.nd(), sh.m, sh.x(), sh.rows(), sh.w());
        // μ = −R_z⁻ᵀ (w_z + P_zᵀ w_p), w_z = (w_q, w_λ).
        let mu = &mut lin.column;
        for (c, &k) in sh.dynamic.iter().enumerate() {
            mu[c] = w.q2[c];
            for r in 0..nd {
                mu[c] += lin.pjac[r * wl + sh.w_q2() + k] * w.p2[r];
            }
        }
        for s in 0..m {
            mu[nd + s] = w.lambda[s];
        }
        lu_solve_transposed_packed(&lin.factor, rows, &lin.pivots, mu);
        mu.iter_mut().for_each(|v| *v = -*v);
        if out.shape() != (x, x) {
            *out = DMatrix::zeros(x, x);
        }
        let mut duals = lin
            .duals
            .take()
            .unwrap_or_else(|| DualJacobians::new(&lin.shape, cx.sys));
        for j in 0..x {
            if let Some(from) = lin.input_direction(j) {
                // As in `second_derivatives`: an input's column is its variable's p₁ one,
                // scaled by `left`.
                for i in 0..x {
                    out[(i, j)] = from.map_or(0.0, |s| lin.shape.left * out[(i, s)]);
                }
                continue;
            }
            duals.along(cx.sys, lin, j);
            // c_j = μᵀ D_jJ + w_pᵀ D_jP, then column j = Δᵀ c_j.
            duals.adjoint(&lin.column, w.p2.as_slice());
            for i in 0..x {
                out[(i, j)] = duals.dot_adjoint(lin.tangent.column(i));
            }
        }
        lin.duals = Some(duals);
        Ok(())
    }

    /// Evaluates the step's terms at its solution into the workspace (made on the first
    /// call) and solves for the tangent.
    fn linearise<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<&mut Linearisation, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (a, dt) = (self.settings.alpha, cx.dt);
        let n = q1.len();
        let (left, plus) = self.settings.forcing.weights(a);
        let (left, plus) = (left * dt, plus * dt);
        let ld = DiscreteLagrangian { alpha: a, dt };
        let mut lin = self.linearisation.take().unwrap_or_else(|| {
            let mut lin = Box::new(Linearisation::new(Shape {
                n,
                dynamic: self.split.dynamic.clone(),
                kinematic: self.split.kinematic.clone(),
                m: self.split.rows,
                inputs: (0..cx.sys.input_count())
                    .map(|k| cx.sys.input_variable(k))
                    .collect(),
                ld,
                left,
                plus,
            }));
            // D²h(q₁) cleared on each row's own variables, where the system names them.
            lin.c1 = ConstraintTerms::of(cx.sys);
            lin
        });
        (lin.shape.ld, lin.shape.left, lin.shape.plus) = (ld, left, plus);
        let m = lin.shape.m;
        // Terms at the quadrature point, Dh(q₁), Dh(q₂) at the solution (the step's last
        // evaluation, when it was of second order at this point); D²h(q₁).
        let evaluated =
            self.full_known && self.dt == cx.dt && self.full_q1 == *q1 && self.full_q2 == *q2;
        if m > 0 {
            cx.sys.constraints(q1, &self.zero, Order::Full, &mut lin.c1);
        }
        if evaluated {
            if m > 0 {
                self.constraints_at(cx.sys, q2);
            }
        } else {
            // `Dh(q₁)` from the second-order evaluation just made (what `prepare` forms).
            self.dh1.copy_from(&lin.c1.dh);
            self.evaluate_residual(cx, q1, p1, q2, true);
        }
        // The Jacobians read only the dynamic variables' rows of the n × n terms, row-major:
        // L_qq, M (symmetric: their column-major storage is their row-major one) and L_q̇q's
        // transpose are read in place; L_q̇q's own rows, the forces' derivatives and
        // Σ_s λ_s D²h_s(q₁) are gathered for those rows only.
        let t = &self.terms;
        let dynamic = &lin.shape.dynamic;
        gather_rows(
            t.d2l_ddq_dq.as_slice(),
            n,
            dynamic.iter().copied(),
            &mut lin.lvq,
        );
        // Only the entries the evaluation wrote (its sparsity) hold force derivatives.
        lin.forces = t.force_derivatives != Sparsity::Zero;
        match t.force_derivatives {
            Sparsity::Zero => {}
            Sparsity::Diagonal => {
                for &i in dynamic {
                    lin.fq[i * n..(i + 1) * n].fill(0.0);
                    lin.fv[i * n..(i + 1) * n].fill(0.0);
                    lin.fv[i * n + i] = t.dforce_ddq[(i, i)];
                }
            }
            Sparsity::Dense => {
                gather_rows(
                    t.dforce_dq.as_slice(),
                    n,
                    dynamic.iter().copied(),
                    &mut lin.fq,
                );
                gather_rows(
                    t.dforce_ddq.as_slice(),
                    n,
                    dynamic.iter().copied(),
                    &mut lin.fv,
                );
            }
        }
        for s in 0..m {
            lin.lambda[s] = self.lambda[s];
            for i in 0..n {
                lin.dh1[s * n + i] = self.dh1[(s, i)];
                lin.dh2[s * n + i] = self.constraint_terms.dh[(s, i)];
            }
        }
        contract_hessians(
            &mut lin.lambda_d2h1,
            n,
            &lin.is_dynamic,
            self.lambda.as_slice(),
            &lin.c1,
        );
        lin.q1.copy_from_slice(q1.as_slice());
        lin.q2.copy_from_slice(q2.as_slice());
        let lin = self.linearisation.insert(lin);
        let in_place = (
            t.d2l_dq_dq.as_slice(),
            t.mass.as_slice(),
            t.d2l_ddq_dq.as_slice(),
        );
        lin.solve(in_place)
            .map_err(|c| singular(cx, &lin.shape, c))?;
        Ok(lin)
    }
}

/// The step linearised at its solution, and the buffers for it: sized on the first call,
/// reused after (nothing allocated per step).
#[derive(Clone, Debug)]
pub(crate) struct Linearisation {
    shape: Shape,
    /// `L_q̇q` at the quadrature point, row-major n × n (the dynamic variables' rows).
    lvq: Vec<f64>,
    /// Whether the model has forces with derivatives (`fq`, `fv` are read only then).
    forces: bool,
    fq: Vec<f64>,
    fv: Vec<f64>,
    /// `Dh(q₁)`, `Σ_s λ_s D²h_s(q₁)` (the dynamic variables' rows), `Dh(q₂)` row-major,
    /// and λ.
    dh1: Vec<f64>,
    lambda_d2h1: Vec<f64>,
    dh2: Vec<f64>,
    lambda: Vec<f64>,
    /// Whether each variable is dynamic (the rows `Σ_s λ_s D²h_s(q₁)` is formed on).
    is_dynamic: Vec<bool>,
    /// The constraints at `q₁` up to `D²h`.
    c1: ConstraintTerms,
    /// `J` (rows × w) and `P` (n_d × w), row-major.
    jac: Vec<f64>,
    pjac: Vec<f64>,
    /// The columns of `w` that are the unknowns `z`, and those of `x` the solve
    /// works for (`q₁`, `p₁`, `k₂`: an input's column is `left` times its variable's `p₁`
    /// column, since `∂R/∂u_k = left·∂R/∂p₁` there and `∂p₂/∂p₁ = 0`).
    z_columns: Vec<usize>,
    solved: Vec<usize>,
    /// `solved` as runs of consecutive columns `(first column of w, first solved index,
    /// length)`: the right-hand sides are gathered a run at a time.
    solved_runs: Vec<(usize, usize, usize)>,
    /// Each input's variable as a dynamic row (its `p₁` column), if it is dynamic.
    input_rows: Vec<Option<usize>>,
    /// `R_z`'s LU factor (column-major, packed) and its pivots (a contraction's adjoint solves
    /// with `R_zᵀ` from the same factors).
    factor: Vec<f64>,
    pivots: Vec<usize>,
    /// `Δ = dw/dx` (w × x), filled from `rhs` when second derivatives ask for it.
    tangent: DMatrix<f64>,
    tangent_ready: bool,
    column: Vec<f64>,
    /// `−R_x`, then `dz/dx`, over the solved columns: row-major `rows × solved` (all
    /// right-hand sides of one solve).
    rhs: Vec<f64>,
    /// `dp₂/dx = P Δ` over the solved columns, row-major `n_d × solved`.
    dp2: Vec<f64>,
    /// The point: `q₁`, `q₂` (all variables).
    q1: Vec<f64>,
    q2: Vec<f64>,
    /// For the second derivatives, made on their first use.
    duals: Option<DualJacobians>,
}

impl Linearisation {
    fn new(shape: Shape) -> Self {
        let (n, m, nd) = (shape.n, shape.m, shape.nd());
        let (rows, w, x) = (shape.rows(), shape.w(), shape.x());
        let z_columns: Vec<usize> = (shape.dynamic.iter().map(|&i| shape.w_q2() + i))
            .chain((0..m).map(|s| shape.w_lambda() + s))
            .collect();
        let x_columns: Vec<usize> = (0..n)
            .chain((0..nd).map(|r| shape.w_p1() + r))
            .chain((0..shape.nu()).map(|k| shape.w_u1() + k))
            .chain(shape.kinematic.iter().map(|&k| shape.w_q2() + k))
            .collect();
        let solved: Vec<usize> = (0..n)
            .chain((0..nd).map(|r| shape.w_p1() + r))
            .chain(shape.kinematic.iter().map(|&k| shape.w_q2() + k))
            .collect();
        let input_rows = (shape.inputs.iter())
            .map(|v| shape.dynamic.iter().position(|d| d == v))
            .collect();
        // Δ's rows for x's own coordinates: the identity (`fill_tangent` adds the unknowns').
        let mut tangent = DMatrix::zeros(w, x);
        for (c, &xc) in x_columns.iter().enumerate() {
            tangent[(xc, c)] = 1.0;
        }
        let ks = solved.len();
        let mut solved_runs: Vec<(usize, usize, usize)> = Vec::new();
        for (c, &xc) in solved.iter().enumerate() {
            match solved_runs.last_mut() {
                Some((from, _, len)) if *from + *len == xc => *len += 1,
                _ => solved_runs.push((xc, c, 1)),
            }
        }
        Linearisation {
            lvq: vec![0.0; n * n],
            forces: false,
            fq: vec![0.0; n * n],
            fv: vec![0.0; n * n],
            dh1: vec![0.0; m * n],
            lambda_d2h1: vec![0.0; n * n],
            dh2: vec![0.0; m * n],
            lambda: vec![0.0; m],
            is_dynamic: (0..n).map(|i| shape.dynamic.contains(&i)).collect(),
            c1: ConstraintTerms::zeros(m, n),
            jac: vec![0.0; rows * w],
            pjac: vec![0.0; nd * w],
            z_columns,
            solved,
            solved_runs,
            input_rows,
            factor: vec![0.0; rows * rows],
            pivots: vec![0; rows],
            tangent,
            tangent_ready: false,
            column: vec![0.0; rows],
            rhs: vec![0.0; rows * ks],
            dp2: vec![0.0; nd * ks],
            q1: vec![0.0; n],
            q2: vec![0.0; n],
            duals: None,
            shape,
        }
    }

    /// From the terms the step left (at its solution), the Jacobians, `R_z`'s factor, the
    /// tangent `Δ` and `dp₂/dx` (docs/derivations.md §9).
    /// On a singular `R_z`, the unknown (its column) whose pivot vanished.
    /// `L_qq`, `M` and `L_q̇q`'s transpose are the evaluation's row-major storage
    /// (`in_place`), read where they are.
    fn solve(&mut self, in_place: (&[f64], &[f64], &[f64])) -> Result<(), usize> {
        let (lqq, mass, lvq_t) = in_place;
        let sh = &self.shape;
        let (rows, w, nd) = (sh.rows(), sh.w(), sh.nd());
        let terms = StepTerms {
            lqq,
            lvq: &self.lvq,
            lvq_t,
            mass,
            forces: self.forces,
            fq: &self.fq,
            fv: &self.fv,
            dh1: &self.dh1,
            lambda_d2h1: &self.lambda_d2h1,
            dh2: &self.dh2,
        };
        jacobians_f64(sh, &terms, &mut self.jac, &mut self.pjac);
        // R_z, column-major, factored.
        for (c, &zc) in self.z_columns.iter().enumerate() {
            for r in 0..rows {
                self.factor[c * rows + r] = self.jac[r * w + zc];
            }
        }
        lu_factor_packed(&mut self.factor, rows, &mut self.pivots)?;
        self.tangent_ready = false;
        // dz/dx = −R_z⁻¹ R_x on the solved columns, all in one solve.
        let k = self.solved.len();
        for r in 0..rows {
            let row = &self.jac[r * w..(r + 1) * w];
            let out = &mut self.rhs[r * k..(r + 1) * k];
            for &(from, to, len) in &self.solved_runs {
                for (o, &x) in out[to..to + len].iter_mut().zip(&row[from..from + len]) {
                    *o = -x;
                }
            }
        }
        lu_solve_packed_rows(&self.factor, rows, &self.pivots, &mut self.rhs, k);
        // dp₂/dx = P Δ = P_x + P_z dz/dx (P is zero on the p₁ and λ columns; only q₂_d of z):
        // P_x's rows, then each dz/dx row (contiguous in `rhs`) scaled into them.
        for r in 0..nd {
            let prow = &self.pjac[r * w..(r + 1) * w];
            let out = &mut self.dp2[r * k..(r + 1) * k];
            for &(from, to, len) in &self.solved_runs {
                out[to..to + len].copy_from_slice(&prow[from..from + len]);
            }
        }
        combine_rows(
            &mut self.dp2[..nd * k],
            k,
            &self.pjac[..nd * w],
            w,
            &self.z_columns[..nd],
            &self.rhs,
        );
        Ok(())
    }

    /// Where column `c` of `x` comes from: a solved column, or (an input's) `left` times a
    /// solved `p₁` column with `plus` on `p₂`'s own row — `None` for an input on no dynamic
    /// variable (a zero column).
    fn source(&self, c: usize) -> Option<Source> {
        let sh = &self.shape;
        let (u0, nu) = sh.x_block(StepInput::U1);
        if c < u0 {
            Some(Source::Solved(c))
        } else if c >= u0 + nu {
            Some(Source::Solved(c - nu))
        } else {
            let r = self.input_rows[c - u0]?;
            Some(Source::Input(sh.x_block(StepInput::P1).0 + r, r))
        }
    }

    /// Entry `(r, c)` of `dz/dx` (`r` over the unknowns: `q₂_d`, then `λ`).
    fn dz(&self, r: usize, c: usize) -> f64 {
        let k = self.solved.len();
        match self.source(c) {
            Some(Source::Solved(s)) => self.rhs[r * k + s],
            Some(Source::Input(s, _)) => self.shape.left * self.rhs[r * k + s],
            None => 0.0,
        }
    }

    /// For a direction `j` of `x` that is an input's: `Some(the p₁ direction it follows, if
    /// its variable is dynamic)`. `J` and `P` depend on `w` only through `q₁`, `q₂` and `λ`,
    /// where an input's tangent is `left` times its variable's `p₁` tangent, so their
    /// derivatives along it are that direction's, scaled by `left`. `None` for other
    /// directions.
    fn input_direction(&self, j: usize) -> Option<Option<usize>> {
        let (u0, nu) = self.shape.x_block(StepInput::U1);
        if !(u0..u0 + nu).contains(&j) {
            return None;
        }
        Some(match self.source(j) {
            Some(Source::Input(s, _)) => Some(s),
            _ => None,
        })
    }

    /// The tangent `Δ`'s unknowns' rows from `dz/dx` (once per linearisation; only second
    /// derivatives read `Δ`).
    fn fill_tangent(&mut self) {
        if self.tangent_ready {
            return;
        }
        for c in 0..self.shape.x() {
            for r in 0..self.z_columns.len() {
                self.tangent[(self.z_columns[r], c)] = self.dz(r, c);
            }
        }
        self.tangent_ready = true;
    }

    /// The first-derivative blocks into `out` (resized only when its shape differs): `dq₂/dx`
    /// from the tangent's `q₂` rows, `dλ/dx` from its `λ` rows, `dp₂/dx = P Δ`.
    fn first_into(&self, out: &mut StepDerivatives) {
        let sh = &self.shape;
        let (nd, m, k) = (sh.nd(), sh.m, self.solved.len());
        use StepInput::*;
        let fit = |mat: &mut DMatrix<f64>, rows: usize, columns: usize| {
            if mat.shape() != (rows, columns) {
                *mat = DMatrix::zeros(rows, columns);
            }
        };
        for (b, q2, p2, lambda) in [
            (Q1, &mut out.q2_dq1, &mut out.p2_dq1, &mut out.lambda_dq1),
            (P1, &mut out.q2_dp1, &mut out.p2_dp1, &mut out.lambda_dp1),
            (K2, &mut out.q2_dk2, &mut out.p2_dk2, &mut out.lambda_dk2),
        ] {
            let (c0, wc) = sh.x_block(b);
            fit(q2, nd, wc);
            fit(p2, nd, wc);
            fit(lambda, m, wc);
            // Solved columns c0.. (after the inputs: less nu) as they are, transposed.
            let s0 = if b == K2 { c0 - sh.nu() } else { c0 };
            transpose_into(&self.rhs, k, s0, q2.as_mut_slice(), nd);
            transpose_into(&self.dp2, k, s0, p2.as_mut_slice(), nd);
            transpose_into(&self.rhs[nd * k..], k, s0, lambda.as_mut_slice(), m);
        }
        // Column c of the input block: `left` times its variable's p₁ column (plus `plus` on
        // p₂'s own row), zero for an input on no dynamic variable — read from the p₁ blocks
        // just written, where the column is contiguous.
        let (u0, nu) = sh.x_block(U1);
        let p1 = (&out.q2_dp1, &out.p2_dp1, &out.lambda_dp1);
        let (q2, p2, lambda) = (&mut out.q2_du1, &mut out.p2_du1, &mut out.lambda_du1);
        fit(q2, nd, nu);
        fit(p2, nd, nu);
        fit(lambda, m, nu);
        for c in 0..nu {
            let own = match self.source(u0 + c) {
                Some(Source::Input(_, own)) => Some(own),
                _ => None,
            };
            let scaled = |from: &DMatrix<f64>, to: &mut DMatrix<f64>| {
                let rows = to.nrows();
                let to = &mut to.as_mut_slice()[c * rows..(c + 1) * rows];
                match own {
                    Some(r) => (to.iter_mut())
                        .zip(&from.as_slice()[r * rows..(r + 1) * rows])
                        .for_each(|(o, &x)| *o = sh.left * x),
                    None => to.fill(0.0),
                }
            };
            scaled(p1.0, q2);
            scaled(p1.1, p2);
            scaled(p1.2, lambda);
            if let Some(r) = own {
                p2[(r, c)] += sh.plus;
            }
        }
    }
}

/// Where a column of `x` is found among the solved ones ([`Linearisation::source`]).
#[derive(Clone, Copy, Debug)]
enum Source {
    /// Solved column `s`.
    Solved(usize),
    /// `left` times solved column `s` (the `p₁` column of dynamic row `r`), plus `plus` on
    /// `p₂`'s row `r`.
    Input(usize, usize),
}

impl StepDerivatives {
    /// Empty blocks (sized by the first [`MidpointVi::derivatives_into`]).
    pub fn empty() -> Self {
        let z = || DMatrix::zeros(0, 0);
        StepDerivatives {
            q2_dq1: z(),
            q2_dp1: z(),
            q2_du1: z(),
            q2_dk2: z(),
            p2_dq1: z(),
            p2_dp1: z(),
            p2_du1: z(),
            p2_dk2: z(),
            lambda_dq1: z(),
            lambda_dp1: z(),
            lambda_du1: z(),
            lambda_dk2: z(),
        }
    }
}

/// `to` (column-major, `rows` rows) = the `rows × (to.len()/rows)` block of the row-major
/// `from` (row stride `k`) starting at column `s0`.
fn transpose_into(from: &[f64], k: usize, s0: usize, to: &mut [f64], rows: usize) {
    if rows == 0 {
        return;
    }
    let cols = to.len() / rows;
    let row = |r: usize| &from[r * k + s0..r * k + s0 + cols];
    // Four rows at a time, each read in order, each column's four entries stored together
    // (a column at a time, the reads strided by a whole row, cost twice as much).
    let mut r = 0;
    while r + 4 <= rows {
        let (a, b, c, d) = (row(r), row(r + 1), row(r + 2), row(r + 3));
        for ((((column, &a), &b), &c), &d) in to.chunks_exact_mut(rows).zip(a).zip(b).zip(c).zip(d)
        {
            column[r..r + 4].copy_from_slice(&[a, b, c, d]);
        }
        r += 4;
    }
    for r in r..rows {
        for (column, &x) in to.chunks_exact_mut(rows).zip(row(r)) {
            column[r] = x;
        }
    }
}

/// Rows `rows` of the n × n matrix stored column-major in `a`, into the same rows of the
/// row-major `out` (other rows untouched).
fn gather_rows<T: Copy>(a: &[T], n: usize, rows: impl IntoIterator<Item = usize>, out: &mut [T]) {
    for i in rows {
        for (j, o) in out[i * n..(i + 1) * n].iter_mut().enumerate() {
            *o = a[j * n + i];
        }
    }
}

/// `out` = the n × n matrix stored column-major in `a`, stored row-major (its transpose).
fn row_major_into<T: Copy>(a: &[T], n: usize, out: &mut [T]) {
    gather_rows(a, n, 0..n, out);
}

/// `R_z` singular at a converged step (constraints that became dependent), at unknown `c`
/// (`q₂`'s dynamic variables, then the multipliers), while linearising the step of `cx`.
fn singular<S, F, P>(cx: &StepContext<S, F, P>, sh: &Shape, c: usize) -> SimError
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let variable = match sh.dynamic.get(c) {
        Some(&i) => format!("variable `{}`", cx.sys.variable_name(i)),
        None => format!(
            "the λ of constraint `{}`",
            cx.sys.constraint_name(c - sh.nd())
        ),
    };
    SimError::SingularJacobian {
        step: cx.index,
        t: cx.t,
        variable,
    }
}

/// Scratch for the Jacobians over dual numbers along one tangent direction.
#[derive(Clone, Debug)]
struct DualJacobians {
    /// At the quadrature point (Full), at `q₁` (constraints alone, Full), at `q₂`
    /// (constraints alone).
    at_alpha: DualOutputs,
    at_q1: DualOutputs,
    at_q2: DualOutputs,
    /// The seeded points and multipliers.
    q_alpha: Vec<Dual>,
    v: Vec<Dual>,
    q1: Vec<Dual>,
    q2: Vec<Dual>,
    rest: Vec<Dual>,
    lambda: Vec<Dual>,
    /// `Σ_s λ_s D²h_s(q₁)` over duals.
    lambda_d2h1: Vec<Dual>,
    /// The derivative parts of the step's terms along the direction, in the order of
    /// [`StepTerms`]: `L_qq`, `L_q̇q`, its transpose, `M`, `F_q`, `F_q̇`, `Dh(q₁)`,
    /// `Σ λ_s D²h_s(q₁)`, `Dh(q₂)`.
    along_terms: [Vec<f64>; 9],
    /// `D_j J`, `D_j P` (row-major): `J`, `P` are linear in the step's terms with constant
    /// coefficients, so they are [`jacobians`] of the terms' derivative parts, the constant
    /// entries (`∂r/∂p₁ = I`, the inputs' `left`, `plus`) zeroed.
    jac: Vec<f64>,
    pjac: Vec<f64>,
    /// `c_j = μᵀ D_jJ + w_pᵀ D_jP` (length w).
    adjoint: Vec<f64>,
    /// Each constraint row's variables, where the system names them (empty: unknown).
    variables: Vec<Vec<usize>>,
    /// Every variable (`Σ_s λ_s D²h_s` over duals is formed on every row).
    every_row: Vec<bool>,
}

impl DualJacobians {
    fn new<S: System>(sh: &Shape, sys: &S) -> Self
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let (n, m) = (sys.dof(), sys.constraint_count());
        let zeros = |k| vec![Dual::default(); k];
        // D²h cleared on each row's own variables, where the system names them.
        let variables = row_variables(sys);
        let outputs = || DualOutputs::new(n, m).with_constraint_variables(variables.clone());
        DualJacobians {
            at_alpha: outputs(),
            at_q1: outputs(),
            at_q2: outputs(),
            q_alpha: zeros(n),
            v: zeros(n),
            q1: zeros(n),
            q2: zeros(n),
            rest: zeros(n),
            lambda: zeros(m),
            lambda_d2h1: zeros(n * n),
            along_terms: [
                n * n,
                n * n,
                n * n,
                n * n,
                n * n,
                n * n,
                m * n,
                n * n,
                m * n,
            ]
            .map(|len| vec![0.0; len]),
            jac: vec![0.0; sh.rows() * sh.w()],
            pjac: vec![0.0; sh.nd() * sh.w()],
            adjoint: vec![0.0; sh.w()],
            variables,
            every_row: vec![true; n],
        }
    }

    /// The Jacobians' derivatives along the tangent's column `j` (`D_j J`, `D_j P`):
    /// the quadrature point moves by `δq_α = (1−α)δq₁ + αδq₂`, `δv = (δq₂ − δq₁)/Δt`.
    fn along<S: System>(&mut self, sys: &mut S, lin: &Linearisation, j: usize)
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let sh = &lin.shape;
        let (n, m) = (sh.n, sh.m);
        let (a, dt) = (sh.ld.alpha, sh.ld.dt);
        let dir = lin.tangent.column(j);
        for i in 0..n {
            let (d1, d2) = (dir[i], dir[sh.w_q2() + i]);
            let (x1, x2) = (lin.q1[i], lin.q2[i]);
            self.q_alpha[i] = Dual::new(x1 + a * (x2 - x1), (1.0 - a) * d1 + a * d2);
            self.v[i] = Dual::new((x2 - x1) / dt, (d2 - d1) / dt);
            self.q1[i] = Dual::new(x1, d1);
            self.q2[i] = Dual::new(x2, d2);
        }
        sys.evaluate_dual(&self.q_alpha, &self.v, Order::Full, &mut self.at_alpha);
        if m > 0 {
            sys.constraints_dual(&self.q1, &self.rest, Order::Full, &mut self.at_q1);
            sys.constraints_dual(&self.q2, &self.rest, Order::First, &mut self.at_q2);
        }
        for s in 0..m {
            self.lambda[s] = Dual::new(lin.lambda[s], dir[sh.w_lambda() + s]);
        }
        let variables = &self.variables;
        contract_on_rows(
            &mut self.lambda_d2h1,
            n,
            &self.every_row,
            &self.lambda,
            self.at_q1.field(Field::D2h).chunks_exact(n * n),
            |s| variables.get(s).map(Vec::as_slice),
            |o, l, x| *o += l * x,
        );
        let (t, c1, c2) = (&self.at_alpha, &self.at_q1, &self.at_q2);
        let sources = [
            t.field(Field::D2lDqDq),
            t.field(Field::D2lDdqDq),
            &[],
            t.field(Field::Mass),
            t.field(Field::DforceDq),
            t.field(Field::DforceDdq),
            c1.field(Field::Dh),
            &self.lambda_d2h1,
            c2.field(Field::Dh),
        ];
        for (to, from) in self.along_terms.iter_mut().zip(sources) {
            for (x, y) in to.iter_mut().zip(from) {
                *x = y.d;
            }
        }
        let [lqq, lvq, lvq_t, mass, fq, fv, dh1, lambda_d2h1, dh2] = &mut self.along_terms;
        row_major_into(lvq, n, lvq_t);
        let terms = StepTerms {
            lqq,
            lvq,
            lvq_t,
            mass,
            forces: lin.forces,
            fq,
            fv,
            dh1,
            lambda_d2h1,
            dh2,
        };
        jacobians_f64(sh, &terms, &mut self.jac, &mut self.pjac);
        // The constant entries' derivatives are zero.
        let w = sh.w();
        for r in 0..sh.nd() {
            self.jac[r * w + sh.w_p1() + r] = 0.0;
            for k in 0..sh.nu() {
                self.jac[r * w + sh.w_u1() + k] = 0.0;
                self.pjac[r * w + sh.w_u1() + k] = 0.0;
            }
        }
    }

    /// `out = (D_j J) δ`.
    fn times(&self, delta: DVectorView<f64>, out: &mut [f64]) {
        let w = delta.len();
        for (r, o) in out.iter_mut().enumerate() {
            *o = dot(&self.jac[r * w..(r + 1) * w], delta.as_slice());
        }
    }

    /// `((D_j P) δ)_r`.
    fn p_times(&self, r: usize, delta: DVectorView<f64>) -> f64 {
        let w = delta.len();
        dot(&self.pjac[r * w..(r + 1) * w], delta.as_slice())
    }

    /// `c_j = μᵀ D_jJ + w_pᵀ D_jP`.
    fn adjoint(&mut self, mu: &[f64], wp: &[f64]) {
        let w = self.adjoint.len();
        self.adjoint.as_mut_slice().fill(0.0);
        for (r, &m) in mu.iter().enumerate() {
            for (c, x) in self.jac[r * w..(r + 1) * w].iter().enumerate() {
                self.adjoint[c] += m * x;
            }
        }
        for (r, &p) in wp.iter().enumerate() {
            for (c, x) in self.pjac[r * w..(r + 1) * w].iter().enumerate() {
                self.adjoint[c] += p * x;
            }
        }
    }

    /// `c_j · δ`.
    fn dot_adjoint(&self, delta: DVectorView<f64>) -> f64 {
        dot(&self.adjoint, delta.as_slice())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Σ_s λ_s D²h_s` on the chosen rows, both roundings and the dispatched kernel, against
    /// the sum written out, with the rows' variables unknown and known (each block zero
    /// outside them); rows not chosen are left as they were, a zero multiplier adds nothing.
    #[test]
    fn hessians_contract_on_the_dynamic_rows() {
        let n = 5;
        let variables = vec![vec![0, 2, 3], vec![1, 2], vec![1, 2, 4]];
        let d2h: Vec<DMatrix<f64>> = (0..3)
            .map(|s| {
                DMatrix::from_fn(n, n, |i, j| {
                    let inside = variables[s].contains(&i) && variables[s].contains(&j);
                    inside as u8 as f64 * ((i + j + 3 * s) as f64 * 0.7).sin()
                })
            })
            .map(|h| &h + h.transpose())
            .collect();
        let mut dense = ConstraintTerms::zeros(3, n);
        dense.d2h.clone_from(&d2h);
        let sparse = dense.clone().with_variables(variables.clone());
        let lambda = [0.5, 0.0, -2.0];
        let dynamic = [true, false, true, true, false];
        let expected = |i: usize, j: usize| 0.5 * d2h[0][(i, j)] - 2.0 * d2h[2][(i, j)];
        type Kernel = fn(&mut [f64], usize, &[bool], &[f64], &ConstraintTerms);
        let kernels: [Kernel; 3] = [
            contract_hessians_with::<false>,
            contract_hessians_with::<true>,
            contract_hessians,
        ];
        for (kernel, c) in kernels.iter().flat_map(|k| [(k, &dense), (k, &sparse)]) {
            let mut out = vec![7.0; n * n];
            kernel(&mut out, n, &dynamic, &lambda, c);
            for i in 0..n {
                for j in 0..n {
                    let want = if dynamic[i] { expected(i, j) } else { 7.0 };
                    assert!((out[i * n + j] - want).abs() < 1e-14, "({i}, {j})");
                }
            }
        }
        // Over dual numbers on every row (the second derivatives' form): the value part is
        // the same sum, the derivative part the multipliers' derivatives' sum.
        let blocks: Vec<Vec<Dual>> = (d2h.iter())
            .map(|h| h.iter().map(|&x| Dual::new(x, 0.0)).collect())
            .collect();
        let lambda_d = [
            Dual::new(0.5, 1.0),
            Dual::new(0.0, 0.0),
            Dual::new(-2.0, 3.0),
        ];
        let mut out = vec![Dual::new(7.0, 7.0); n * n];
        contract_on_rows(
            &mut out,
            n,
            &[true; 5],
            &lambda_d,
            blocks.iter().map(Vec::as_slice),
            |s| variables.get(s).map(Vec::as_slice),
            |o, l, x| *o += l * x,
        );
        for i in 0..n {
            for j in 0..n {
                let d = d2h[0][(i, j)] + 3.0 * d2h[2][(i, j)];
                let got = out[i * n + j];
                assert!((got.v - expected(i, j)).abs() < 1e-14 && (got.d - d).abs() < 1e-14);
            }
        }
    }
}
