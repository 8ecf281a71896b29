//! The first derivatives of a converged step: `R_z`'s LU factor, `dz/dx = −R_z⁻¹ R_x` for
//! every input direction in one solve, `dp₂/dx = P Δ`, and the blocks (trep's `q2_dq1` …)
//! copied out (docs/derivations.md §9).
//!
//! `R_z` is factored with its unknowns (and their equations) in the tree's elimination
//! order: the dynamic variables last to first — each after every variable below it in the
//! tree, so eliminating it couples only its ancestors, which already are — then the
//! multipliers ([`OrderedFactor`]). With threshold pivoting the rows stay in that order and
//! the factor keeps the tree's zeros (about half of trep's Puppet's: a floating torso and
//! four limbs), which the solve then skips.

use nalgebra::DMatrix;

use super::jacobians::{jacobians_f64, Shape, StepTerms};
use super::second::DualJacobians;
use super::{StepDerivatives, StepInput};
use crate::linalg::{
    combine_compact_rows, lu_factor_packed_threshold, lu_solve_compact_rows, lu_solve_packed,
    lu_solve_transposed_packed, CompactCombination, CompactFactor,
};
use crate::system::ConstraintTerms;

/// The step linearised at its solution, and the buffers for it: sized on the first call,
/// reused after (nothing allocated per step).
#[derive(Clone, Debug)]
pub(crate) struct Linearisation {
    pub(super) shape: Shape,
    /// `L_q̇q` at the quadrature point, row-major n × n (the dynamic variables' rows).
    pub(super) lvq: Vec<f64>,
    /// Whether the model has forces with derivatives (`fq`, `fv` are read only then).
    pub(super) forces: bool,
    pub(super) fq: Vec<f64>,
    pub(super) fv: Vec<f64>,
    /// `Dh(q₁)`, `Σ_s λ_s D²h_s(q₁)` (the dynamic variables' rows), `Dh(q₂)` row-major,
    /// and λ.
    pub(super) dh1: Vec<f64>,
    pub(super) lambda_d2h1: Vec<f64>,
    pub(super) dh2: Vec<f64>,
    pub(super) lambda: Vec<f64>,
    /// Whether each variable is dynamic (the rows `Σ_s λ_s D²h_s(q₁)` is formed on).
    pub(super) is_dynamic: Vec<bool>,
    /// The constraints at `q₁` up to `D²h`.
    pub(super) c1: ConstraintTerms,
    /// `J` (rows × w) and `P` (n_d × w), row-major.
    pub(super) jac: Vec<f64>,
    pub(super) pjac: Vec<f64>,
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
    /// `R_z` factored in the elimination order (a contraction's adjoint solves with `R_zᵀ`
    /// from the same factors).
    pub(super) lu: OrderedFactor,
    /// `z_columns` in the elimination order: the column of `w` of each row of `dz/dx` as
    /// the solve leaves it.
    ordered_z: Vec<usize>,
    /// `Δ = dw/dx` (w × x), filled from `rhs` when second derivatives ask for it.
    pub(super) tangent: DMatrix<f64>,
    tangent_ready: bool,
    pub(super) column: Vec<f64>,
    /// Scratch of one vector's solve in the elimination order.
    pub(super) scratch: Vec<f64>,
    /// `−R_x`, then `dz/dx`, over the solved columns: row-major `rows × solved` (all
    /// right-hand sides of one solve), its rows in the elimination order.
    rhs: Vec<f64>,
    /// `dp₂/dx = P Δ` over the solved columns, row-major `n_d × solved`.
    dp2: Vec<f64>,
    /// `P_z`'s non-zeros (the tree's, as `R_z`'s) for the product `P_z dz/dx`.
    combination: CompactCombination,
    /// The point: `q₁`, `q₂` (all variables).
    pub(super) q1: Vec<f64>,
    pub(super) q2: Vec<f64>,
    /// For the second derivatives, made on their first use.
    pub(super) duals: Option<DualJacobians>,
}

impl Linearisation {
    pub(super) fn new(shape: Shape) -> Self {
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
        let lu = OrderedFactor::new(shape.nd(), m);
        let ordered_z = lu.order.iter().map(|&o| z_columns[o]).collect();
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
            lu,
            ordered_z,
            tangent,
            tangent_ready: false,
            column: vec![0.0; rows],
            scratch: vec![0.0; rows],
            rhs: vec![0.0; rows * ks],
            dp2: vec![0.0; nd * ks],
            combination: CompactCombination::default(),
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
    pub(super) fn solve(&mut self, in_place: (&[f64], &[f64], &[f64])) -> Result<(), usize> {
        let (lqq, mass, lvq_t) = in_place;
        let sh = &self.shape;
        let (w, nd) = (sh.w(), sh.nd());
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
        // R_z, column-major in the elimination order, factored.
        self.lu.factor(|r, c| self.jac[r * w + self.z_columns[c]])?;
        self.tangent_ready = false;
        // dz/dx = −R_z⁻¹ R_x on the solved columns, all in one solve (the equations, then
        // the unknowns, in the elimination order).
        let k = self.solved.len();
        for (r, &equation) in self.lu.order.iter().enumerate() {
            let row = &self.jac[equation * w..(equation + 1) * w];
            let out = &mut self.rhs[r * k..(r + 1) * k];
            for &(from, to, len) in &self.solved_runs {
                for (o, &x) in out[to..to + len].iter_mut().zip(&row[from..from + len]) {
                    *o = -x;
                }
            }
        }
        self.lu.solve_rows(&mut self.rhs, k);
        // dp₂/dx = P Δ = P_x + P_z dz/dx (P is zero on the p₁ and λ columns; only q₂_d of z):
        // P_x's rows, then each dz/dx row (contiguous in `rhs`) scaled into them.
        for r in 0..nd {
            let prow = &self.pjac[r * w..(r + 1) * w];
            let out = &mut self.dp2[r * k..(r + 1) * k];
            for &(from, to, len) in &self.solved_runs {
                out[to..to + len].copy_from_slice(&prow[from..from + len]);
            }
        }
        (self.combination).gather(nd, &self.pjac[..nd * w], w, &self.ordered_z[..nd]);
        combine_compact_rows(&mut self.dp2[..nd * k], k, &self.combination, &self.rhs);
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
        let (k, r) = (self.solved.len(), self.lu.position[r]);
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
    pub(super) fn input_direction(&self, j: usize) -> Option<Option<usize>> {
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
    pub(super) fn fill_tangent(&mut self) {
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
    pub(super) fn first_into(&self, out: &mut StepDerivatives) {
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
            let solved = |r| self.lu.position[r];
            transpose_into(&self.rhs, k, s0, q2.as_mut_slice(), nd, solved);
            transpose_into(&self.dp2, k, s0, p2.as_mut_slice(), nd, |r| r);
            let multiplier = |s| self.lu.position[nd + s];
            transpose_into(&self.rhs, k, s0, lambda.as_mut_slice(), m, multiplier);
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

/// `to` (column-major, `rows` rows) = the `rows × (to.len()/rows)` block of the row-major
/// `from` (row stride `k`) starting at column `s0`, row `r` of `to` from row `row_of(r)`.
fn transpose_into(
    from: &[f64],
    k: usize,
    s0: usize,
    to: &mut [f64],
    rows: usize,
    row_of: impl Fn(usize) -> usize,
) {
    if rows == 0 {
        return;
    }
    let cols = to.len() / rows;
    let row = |r: usize| &from[row_of(r) * k + s0..row_of(r) * k + s0 + cols];
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

/// Multipliers at most this many times the largest in their column (threshold pivoting,
/// [`lu_factor_packed_threshold`]): the sparse solvers' usual 0.1.
const PIVOT_THRESHOLD: f64 = 0.1;

/// `R_z` factored with its unknowns and equations in the elimination order (the module
/// docs): `P Π R_z Πᵀ = L U` with `Π` the order, by threshold pivoting, and the factor's
/// non-zeros gathered for the solve by rows.
#[derive(Clone, Debug)]
pub(crate) struct OrderedFactor {
    rows: usize,
    /// The unknown (and its equation) at each position: `q₂_d`'s dynamic variables last to
    /// first, then the multipliers.
    order: Vec<usize>,
    /// Each unknown's position (`order`'s inverse).
    position: Vec<usize>,
    /// The factor (column-major) and its interchanges.
    factor: Vec<f64>,
    pivots: Vec<usize>,
    compact: CompactFactor,
}

impl OrderedFactor {
    fn new(nd: usize, m: usize) -> Self {
        let rows = nd + m;
        let order: Vec<usize> = (0..nd).rev().chain(nd..rows).collect();
        let mut position = vec![0; rows];
        for (i, &o) in order.iter().enumerate() {
            position[o] = i;
        }
        OrderedFactor {
            rows,
            order,
            position,
            factor: vec![0.0; rows * rows],
            pivots: vec![0; rows],
            compact: CompactFactor::default(),
        }
    }

    /// Factors the matrix whose entry `(equation, unknown)` is `entry(equation, unknown)`.
    /// On a vanished pivot, the unknown (in `z`'s order) whose it was.
    fn factor(&mut self, entry: impl Fn(usize, usize) -> f64) -> Result<(), usize> {
        let rows = self.rows;
        for (c, &unknown) in self.order.iter().enumerate() {
            for (r, &equation) in self.order.iter().enumerate() {
                self.factor[c * rows + r] = entry(equation, unknown);
            }
        }
        lu_factor_packed_threshold(&mut self.factor, rows, &mut self.pivots, PIVOT_THRESHOLD)
            .map_err(|c| self.order[c])?;
        self.compact.gather(&self.factor, rows);
        Ok(())
    }

    /// Solves for `k` right-hand sides at once, row-major, rows in the elimination order.
    fn solve_rows(&self, b: &mut [f64], k: usize) {
        lu_solve_compact_rows(&self.factor, self.rows, &self.pivots, &self.compact, b, k);
    }

    /// Solves `R_z x = b` (`transposed`: `R_zᵀ x = b`), `b` in `z`'s order, `scratch` as
    /// long: `Π R_z Πᵀ` is what is factored, so `b` is put in the elimination order and the
    /// solution taken back out of it.
    pub(super) fn solve(&self, b: &mut [f64], scratch: &mut [f64], transposed: bool) {
        let rows = self.rows;
        for (s, &o) in scratch[..rows].iter_mut().zip(&self.order) {
            *s = b[o];
        }
        if transposed {
            lu_solve_transposed_packed(&self.factor, rows, &self.pivots, scratch);
        } else {
            lu_solve_packed(&self.factor, rows, &self.pivots, scratch);
        }
        for (&s, &o) in scratch[..rows].iter().zip(&self.order) {
            b[o] = s;
        }
    }
}
