//! The second derivatives' pieces along one direction `j` of `x`: the step's terms over dual
//! numbers seeded with the tangent `Δ_j` (third derivatives of `L`, `D³h`, the forces' second
//! derivatives, all exact), then `D_j J`, `D_j P` as the Jacobians of the terms' derivative
//! parts (docs/derivations.md §9).

use nalgebra::{allocator::Allocator, DVectorView, DefaultAllocator};

use super::first::Linearization;
use super::jacobians::{jacobians_f64, row_major_into, Shape, StepTerms};
use crate::linalg::dot;
use crate::system::{row_variables, Order, Sparsity, System};
use tree_kernel::Field;
use tree_kernel::{Dual, DualOutputs};

/// Scratch for the Jacobians over dual numbers along one tangent direction.
#[derive(Clone, Debug)]
pub(crate) struct DualJacobians {
    /// At the quadrature point (Full), at `q₁` (`Dh` and `Σ_s λ_s D²h_s` alone), at `q₂`
    /// (constraints alone).
    at_alpha: DualOutputs,
    at_q1: DualOutputs,
    at_q2: DualOutputs,
    /// The seeded points and multipliers.
    q_alpha: Vec<Dual>,
    pub(super) v: Vec<Dual>,
    pub(super) q1: Vec<Dual>,
    pub(super) q2: Vec<Dual>,
    pub(super) rest: Vec<Dual>,
    pub(super) lambda: Vec<Dual>,
    /// The derivative parts of the step's terms along the direction, in the order of
    /// [`StepTerms`]: `L_qq`, `L_q̇q`, its transpose, `M`, `F_q`, `F_q̇`, `Dh(q₁)`,
    /// `Σ λ_s D²h_s(q₁)`, `Dh(q₂)`.
    along_terms: [Vec<f64>; 9],
    /// `D_j J`, `D_j P` (row-major): `J`, `P` are linear in the step's terms with constant
    /// coefficients, so they are [`jacobians`] of the terms' derivative parts, the constant
    /// entries (`∂r/∂p₁ = I`, the inputs' `left`, `plus`) zeroed.
    pub(super) jac: Vec<f64>,
    pub(super) pjac: Vec<f64>,
    /// `c_j = μᵀ D_jJ + w_pᵀ D_jP` (length w).
    pub(super) adjoint: Vec<f64>,
}

impl DualJacobians {
    pub(super) fn new<S: System>(sh: &Shape, sys: &S) -> Self
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let (n, m) = (sys.dof(), sys.constraint_count());
        let zeros = |k| vec![Dual::default(); k];
        // D²h (which the default weighted evaluation forms) cleared on each row's own
        // variables, where the system names them.
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
        }
    }

    /// The Jacobians' derivatives along the tangent's column `j` (`D_j J`, `D_j P`):
    /// the quadrature point moves by `δq_α = (1−α)δq₁ + αδq₂`, `δv = (δq₂ − δq₁)/Δt`.
    pub(super) fn along<S: System>(&mut self, sys: &mut S, lin: &Linearization, j: usize)
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
        for s in 0..m {
            self.lambda[s] = Dual::new(lin.lambda[s], dir[sh.w_lambda() + s]);
        }
        if m > 0 {
            // Dh(q₁) and Σ_s λ_s D²h_s(q₁), both moving along the direction; Dh(q₂).
            sys.weighted_constraint_hessian_dual(&self.q1, &self.lambda, &mut self.at_q1);
            sys.constraints_dual(&self.q2, &self.rest, Order::First, &mut self.at_q2);
        }
        let (t, c1, c2) = (&self.at_alpha, &self.at_q1, &self.at_q2);
        let sources = [
            t.field(Field::D2lDqDq),
            t.field(Field::D2lDdqDq),
            &[],
            t.field(Field::Mass),
            t.field(Field::DforceDq),
            t.field(Field::DforceDdq),
            c1.field(Field::Dh),
            // Read below: formed on the dynamic columns, wanted on the dynamic rows.
            &[],
            c2.field(Field::Dh),
        ];
        for (to, from) in self.along_terms.iter_mut().zip(sources) {
            for (x, y) in to.iter_mut().zip(from) {
                *x = y.d;
            }
        }
        let [lqq, lvq, lvq_t, mass, fq, fv, dh1, lambda_d2h1, dh2] = &mut self.along_terms;
        row_major_into(lvq, n, lvq_t);
        // Σ_s λ_s D²h_s is symmetric: its dynamic rows are its dynamic columns, transposed.
        let weighted = c1.field(Field::WeightedD2h);
        for (i, row) in lambda_d2h1.chunks_exact_mut(n).enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = weighted[j * n + i].d;
            }
        }
        let terms = StepTerms {
            lqq,
            lvq,
            lvq_t,
            mass,
            // The derivative parts are whole matrices (zero where the terms are constant).
            forces: match lin.forces {
                Sparsity::Zero => Sparsity::Zero,
                _ => Sparsity::Dense,
            },
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
    pub(super) fn times(&self, delta: DVectorView<f64>, out: &mut [f64]) {
        let w = delta.len();
        for (r, o) in out.iter_mut().enumerate() {
            *o = dot(&self.jac[r * w..(r + 1) * w], delta.as_slice());
        }
    }

    /// `((D_j P) δ)_r`.
    pub(super) fn p_times(&self, r: usize, delta: DVectorView<f64>) -> f64 {
        let w = delta.len();
        dot(&self.pjac[r * w..(r + 1) * w], delta.as_slice())
    }

    /// `c_j = μᵀ D_jJ + w_pᵀ D_jP`.
    pub(super) fn adjoint(&mut self, mu: &[f64], wp: &[f64]) {
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
    pub(super) fn dot_adjoint(&self, delta: DVectorView<f64>) -> f64 {
        dot(&self.adjoint, delta.as_slice())
    }
}
