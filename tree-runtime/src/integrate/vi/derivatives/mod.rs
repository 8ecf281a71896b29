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
//! The Jacobians are written once, over any [`Scalar`](tree_kernel::Scalar), into a sink
//! ([`jacobians`]): at the solution, straight into the pieces the first-order solve reads
//! (`R_z` into its factor's storage, `R_x` into the right-hand sides, which the solve turns
//! into `−dz/dx`); for the second
//! derivatives, whole, from the derivative parts of the terms evaluated over
//! [`Dual`](tree_kernel::Dual) numbers. Forces the caller
//! adds (a [`GeneralizedForce`]) are held fixed; the model's own (damping, dampers) and the
//! inputs are differentiated.
//!
//! The pieces: [`jacobians`] (`J`, `P` from the step's terms, into a sink), [`first`]
//! (`R_z`'s factor, the tangent, the first-derivative blocks), [`second`] (`D_j J`, `D_j P`
//! over dual numbers along each direction).

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim};

use super::MidpointVi;
use crate::context::StepContext;
use crate::dynamics::GeneralizedForce;
use crate::error::SimError;
use crate::integrate::discrete::DiscreteLagrangian;
use crate::system::{ConstraintTerms, Sparsity, System, Vector};

mod first;
mod jacobians;
mod second;

pub(crate) use first::Linearization;
use jacobians::{gather_rows, row_major_into, Shape};
pub(crate) use second::DualJacobians;

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
        self.linearize(cx, q1, p1, q2)?.first_into(out);
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
        if self.contact.as_ref().is_some_and(|c| !c.free) {
            return Err(SimError::Unsupported(
                "second derivatives of a step through contact are not formed (docs/derivations.md §13): use the first derivatives (a Gauss–Newton model)".into(),
            ));
        }
        let cached = self.dual_jacobians.take();
        let lin = self.linearize(cx, q1, p1, q2)?;
        lin.fill_tangent();
        let mut first = StepDerivatives::empty();
        lin.first_into(&mut first);
        let sh = lin.shape.clone();
        let (nd, m, x, rows) = (sh.nd(), sh.m, sh.x(), sh.rows());
        let mut second = StepSecondDerivatives {
            shape: sh.clone(),
            q2: vec![DMatrix::zeros(x, x); nd],
            p2: vec![DMatrix::zeros(x, x); nd],
            lambda: vec![DMatrix::zeros(x, x); m],
        };
        let mut duals = cached.unwrap_or_else(|| Box::new(DualJacobians::new(&sh, cx.sys)));
        let (mut g, mut scratch) = (vec![0.0; rows], vec![0.0; rows]);
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
                lin.lu.solve(&mut g, &mut scratch, false);
                for r in 0..nd {
                    second.q2[r][(i, j)] = -g[r];
                }
                for s in 0..m {
                    second.lambda[s][(i, j)] = -g[nd + s];
                }
                for r in 0..nd {
                    let pz = &lin.pz[r * nd..(r + 1) * nd];
                    let mut p = duals.p_times(r, di);
                    for (c, &x) in pz.iter().enumerate() {
                        p -= x * g[c];
                    }
                    second.p2[r][(i, j)] = p;
                }
            }
        }
        self.dual_jacobians = Some(duals);
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
        if self.contact.as_ref().is_some_and(|c| !c.free) {
            return Err(SimError::Unsupported(
                "second derivatives of a step through contact are not formed (docs/derivations.md §13): use the first derivatives (a Gauss–Newton model)".into(),
            ));
        }
        let cached = self.dual_jacobians.take();
        let lin = self.linearize(cx, q1, p1, q2)?;
        lin.fill_tangent();
        let sh = &lin.shape;
        let (nd, m, x) = (sh.nd(), sh.m, sh.x());
        // μ = −R_z⁻ᵀ (w_z + P_zᵀ w_p), w_z = (w_q, w_λ).
        let mu = &mut lin.column;
        for c in 0..nd {
            mu[c] = w.q2[c];
            for r in 0..nd {
                mu[c] += lin.pz[r * nd + c] * w.p2[r];
            }
        }
        for s in 0..m {
            mu[nd + s] = w.lambda[s];
        }
        lin.lu.solve(mu, &mut lin.scratch, true);
        mu.iter_mut().for_each(|v| *v = -*v);
        if out.shape() != (x, x) {
            *out = DMatrix::zeros(x, x);
        }
        let mut duals = cached.unwrap_or_else(|| Box::new(DualJacobians::new(&lin.shape, cx.sys)));
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
        self.dual_jacobians = Some(duals);
        Ok(())
    }

    /// Evaluates the step's terms at its solution into the workspace (made on the first
    /// call) and solves for the tangent.
    fn linearize<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q2: &Vector<N>,
    ) -> Result<&mut Linearization, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (a, dt) = (self.settings.alpha, cx.dt);
        let n = q1.len();
        let (left, plus) = self.settings.forcing.weights(a);
        let (left, plus) = (left * dt, plus * dt);
        let ld = DiscreteLagrangian { alpha: a, dt };
        let mut lin = self.linearization.take().unwrap_or_else(|| {
            let shape = Shape::new(
                n,
                (self.split.dynamic.clone(), self.split.kinematic.clone()),
                self.split.rows,
                (0..cx.sys.input_count())
                    .map(|k| cx.sys.input_variable(k))
                    .collect(),
                ld,
                (left, plus),
            );
            Box::new(Linearization::new(shape, ConstraintTerms::of(cx.sys)))
        });
        (lin.shape.ld, lin.shape.left, lin.shape.plus) = (ld, left, plus);
        let m = lin.shape.m;
        // Terms at the quadrature point, Dh(q₁), Dh(q₂) at the solution (the step's last
        // evaluation, when it was of second order at this point); Σ_s λ_s D²h_s(q₁).
        let evaluated =
            self.full_known && self.dt == cx.dt && self.full_q1 == *q1 && self.full_q2 == *q2;
        if m > 0 {
            (cx.sys).weighted_constraint_hessian(q1, self.lambda.as_slice(), &mut lin.c1);
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
        // Only the entries the evaluation wrote (its sparsity) hold force derivatives, and
        // only those are read.
        lin.forces = t.force_derivatives;
        match t.force_derivatives {
            Sparsity::Zero => {}
            Sparsity::Diagonal => {
                for &i in dynamic {
                    lin.fq[i * n + i] = 0.0;
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
        lin.lambda.copy_from_slice(self.lambda.as_slice());
        // Dh (m × n) row-major.
        row_major_into(self.dh1.as_slice(), m, &mut lin.dh1);
        row_major_into(self.constraint_terms.dh.as_slice(), m, &mut lin.dh2);
        lin.q1.copy_from_slice(q1.as_slice());
        lin.q2.copy_from_slice(q2.as_slice());
        if let Some(contact) = &self.contact {
            let nd = lin.shape.nd();
            let jacobian =
                (lin.contact).get_or_insert_with(|| super::contact::ContactJacobian::new(nd, n));
            contact
                .jacobian(&lin.shape.dynamic, jacobian)
                .map_err(|e| SimError::SingularJacobian {
                    step: cx.index,
                    t: cx.t,
                    variable: format!("the impulse of contact `{}`", contact.name(e)),
                })?;
        }
        let lin = self.linearization.insert(lin);
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
