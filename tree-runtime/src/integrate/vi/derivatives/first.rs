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

use super::jacobians::{jacobians, JacobianSink, RowWriter, Segment, Shape, StepTerms};
use super::{StepDerivatives, StepInput};
use crate::linalg::{
    combine_compact_rows, lu_factor_packed_threshold, lu_solve_compact_rows, lu_solve_packed,
    lu_solve_transposed_packed, CompactCombination, CompactFactor,
};
use crate::system::{ConstraintTerms, Sparsity};

/// The step linearised at its solution, and the buffers for it: sized on the first call,
/// reused after (nothing allocated per step).
#[derive(Clone, Debug)]
pub(crate) struct Linearization {
    pub(super) shape: Shape,
    /// `L_q̇q` at the quadrature point, row-major n × n (the dynamic variables' rows).
    pub(super) lvq: Vec<f64>,
    /// Where the model's forces have derivatives (`fq`, `fv` are read there only: nowhere,
    /// `fv`'s diagonal, or everywhere).
    pub(super) forces: Sparsity,
    pub(super) fq: Vec<f64>,
    pub(super) fv: Vec<f64>,
    /// `Dh(q₁)`, `Dh(q₂)` row-major, and λ.
    pub(super) dh1: Vec<f64>,
    pub(super) dh2: Vec<f64>,
    pub(super) lambda: Vec<f64>,
    /// The constraints at `q₁`: `Dh` and `Σ_s λ_s D²h_s(q₁)` on the dynamic variables'
    /// columns (`weighted_d2h`, n × n, zero without constraints; symmetric, so its column i
    /// is row i).
    pub(super) c1: ConstraintTerms,
    /// `P_z = ∂p₂/∂q₂` on the dynamic variables, row-major n_d × n_d (`J` and `P` are
    /// otherwise formed only where the solve reads them: [`Pieces`]).
    pub(super) pz: Vec<f64>,
    /// `∂r/∂q₂` of a row on the dynamic variables, as [`jacobians`] writes it.
    rows_scratch: Vec<f64>,
    /// The columns of `w` that are the unknowns `z`, and the number of columns of `x` the
    /// solve works for: `q₁`, `p₁`, `k₂` (an input's column is `left` times its variable's
    /// `p₁` column, since `∂R/∂u_k = left·∂R/∂p₁` there and `∂p₂/∂p₁ = 0`).
    z_columns: Vec<usize>,
    solved: usize,
    /// Each input's variable as a dynamic row (its `p₁` column), if it is dynamic.
    input_rows: Vec<Option<usize>>,
    /// `R_z` factored in the elimination order (a contraction's adjoint solves with `R_zᵀ`
    /// from the same factors).
    pub(super) lu: OrderedFactor,
    /// `Δ = dw/dx` (w × x), filled from `rhs` when second derivatives ask for it.
    pub(super) tangent: DMatrix<f64>,
    tangent_ready: bool,
    pub(super) column: Vec<f64>,
    /// Scratch of one vector's solve in the elimination order.
    pub(super) scratch: Vec<f64>,
    /// `R_x`, then `R_z⁻¹ R_x = −dz/dx`, over the solved columns: row-major `rows × solved`
    /// (all right-hand sides of one solve), its rows in the elimination order.
    rhs: Vec<f64>,
    /// `dp₂/dx = P Δ` over the solved columns, row-major `n_d × solved`.
    dp2: Vec<f64>,
    /// `P_z`'s non-zeros (the tree's, as `R_z`'s) for the product `P_z dz/dx`.
    combination: CompactCombination,
    /// The point: `q₁`, `q₂` (all variables).
    pub(super) q1: Vec<f64>,
    pub(super) q2: Vec<f64>,
    /// The contact impulses' force differentiated (a step with unilateral rows), added to
    /// `R_z` and `R_x` before the factorisation.
    pub(super) contact: Option<crate::integrate::vi::contact::ContactJacobian>,
}

impl Linearization {
    /// Buffers for `shape`'s step; `c1` holds the constraints at `q₁` (`ConstraintTerms::of`
    /// the system, so that `D²h` is cleared on each row's own variables where the default
    /// weighted evaluation forms it), its weighted Hessian sized here: zero where nothing
    /// writes it (every entry without constraints).
    pub(super) fn new(shape: Shape, mut c1: ConstraintTerms) -> Self {
        let (n, m, nd) = (shape.n, shape.m, shape.nd());
        c1.weighted_d2h = DMatrix::zeros(n, n);
        c1.keep_zeros();
        let (rows, w, x) = (shape.rows(), shape.w(), shape.x());
        let z_columns: Vec<usize> = (shape.dynamic.iter().map(|&i| shape.w_q2() + i))
            .chain((0..m).map(|s| shape.w_lambda() + s))
            .collect();
        let x_columns: Vec<usize> = (0..n)
            .chain((0..nd).map(|r| shape.w_p1() + r))
            .chain((0..shape.nu()).map(|k| shape.w_u1() + k))
            .chain(shape.kinematic.iter().map(|&k| shape.w_q2() + k))
            .collect();
        let solved = n + nd + shape.kinematic.len();
        let input_rows = (shape.inputs.iter())
            .map(|v| shape.dynamic.iter().position(|d| d == v))
            .collect();
        // Δ's rows for x's own coordinates: the identity (`fill_tangent` adds the unknowns').
        let mut tangent = DMatrix::zeros(w, x);
        for (c, &xc) in x_columns.iter().enumerate() {
            tangent[(xc, c)] = 1.0;
        }
        let lu = OrderedFactor::new(shape.nd(), m);
        Linearization {
            lvq: vec![0.0; n * n],
            forces: Sparsity::Zero,
            fq: vec![0.0; n * n],
            fv: vec![0.0; n * n],
            dh1: vec![0.0; m * n],
            dh2: vec![0.0; m * n],
            lambda: vec![0.0; m],
            c1,
            pz: vec![0.0; nd * nd],
            rows_scratch: vec![0.0; nd],
            z_columns,
            solved,
            input_rows,
            lu,
            tangent,
            tangent_ready: false,
            column: vec![0.0; rows],
            scratch: vec![0.0; rows],
            rhs: vec![0.0; rows * solved],
            dp2: vec![0.0; nd * solved],
            combination: CompactCombination::default(),
            q1: vec![0.0; n],
            q2: vec![0.0; n],
            contact: None,
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
        let (nd, k) = (sh.nd(), self.solved);
        let terms = StepTerms {
            lqq,
            lvq: &self.lvq,
            lvq_t,
            mass,
            forces: self.forces,
            fq: &self.fq,
            fv: &self.fv,
            dh1: &self.dh1,
            lambda_d2h1: self.c1.weighted_d2h.as_slice(),
            dh2: &self.dh2,
        };
        // R_z into the factor's storage, R_x into the right-hand sides (the equations and
        // unknowns in the elimination order), P_x into dp₂/dx, P_z: then R_z factored.
        let (factor, position) = self.lu.storage();
        let mut pieces = Pieces {
            n: sh.n,
            nd,
            k,
            segments: &sh.segments,
            kinematic: &sh.kinematic,
            position,
            factor,
            rhs: &mut self.rhs,
            dp2: &mut self.dp2,
            pz: &mut self.pz,
            scratch: &mut self.rows_scratch,
        };
        jacobians_in_pieces(sh, &terms, &mut pieces);
        if let Some(c) = &self.contact {
            add_contact(sh, k, c, &mut self.lu, &mut self.rhs);
        }
        self.lu.factor()?;
        self.tangent_ready = false;
        // R_z⁻¹ R_x = −dz/dx on the solved columns, all in one solve.
        self.lu.solve_rows(&mut self.rhs, k);
        // dp₂/dx = P Δ = P_x + P_z dz/dx = P_x − P_z R_z⁻¹ R_x (P is zero on the p₁ and λ
        // columns; only q₂_d of z), the solution's rows in the elimination order (the dynamic
        // ones first).
        (self.combination).gather(nd, &self.pz, nd, &self.lu.order[..nd]);
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
        let (k, r) = (self.solved, self.lu.position[r]);
        match self.source(c) {
            Some(Source::Solved(s)) => -self.rhs[r * k + s],
            Some(Source::Input(s, _)) => self.shape.left * -self.rhs[r * k + s],
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
        let (nd, m, k) = (sh.nd(), sh.m, self.solved);
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
            // Solved columns c0.. (after the inputs: less nu), transposed (dz/dx negated).
            let s0 = if b == K2 { c0 - sh.nu() } else { c0 };
            let solved = |r| self.lu.position[r];
            transpose_into::<true>(&self.rhs, k, s0, q2.as_mut_slice(), nd, solved);
            transpose_into::<false>(&self.dp2, k, s0, p2.as_mut_slice(), nd, |r| r);
            let multiplier = |s| self.lu.position[nd + s];
            transpose_into::<true>(&self.rhs, k, s0, lambda.as_mut_slice(), m, multiplier);
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

/// Where a column of `x` is found among the solved ones ([`Linearization::source`]).
#[derive(Clone, Copy, Debug)]
enum Source {
    /// Solved column `s`.
    Solved(usize),
    /// `left` times solved column `s` (the `p₁` column of dynamic row `r`), plus `plus` on
    /// `p₂`'s row `r`.
    Input(usize, usize),
}

/// `to` (column-major, `rows` rows) = the `rows × (to.len()/rows)` block of the row-major
/// `from` (row stride `k`) starting at column `s0`, row `r` of `to` from row `row_of(r)`;
/// negated if `NEGATE`.
fn transpose_into<const NEGATE: bool>(
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
    let sign = |x: f64| if NEGATE { -x } else { x };
    // Four rows at a time, each read in order, each column's four entries stored together
    // (a column at a time, the reads strided by a whole row, cost twice as much).
    let mut r = 0;
    while r + 4 <= rows {
        let (a, b, c, d) = (row(r), row(r + 1), row(r + 2), row(r + 3));
        for ((((column, &a), &b), &c), &d) in to.chunks_exact_mut(rows).zip(a).zip(b).zip(c).zip(d)
        {
            column[r..r + 4].copy_from_slice(&[sign(a), sign(b), sign(c), sign(d)]);
        }
        r += 4;
    }
    for r in r..rows {
        for (column, &x) in to.chunks_exact_mut(rows).zip(row(r)) {
            column[r] = sign(x);
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

    /// The matrix's storage (column-major, entry `(equation, unknown)` at
    /// `position[unknown]·rows + position[equation]`) and the positions, to be written
    /// whole before [`Self::factor`].
    fn storage(&mut self) -> (&mut [f64], &[usize]) {
        (&mut self.factor, &self.position)
    }

    /// Factors the matrix written into [`Self::storage`]. On a vanished pivot, the unknown
    /// (in `z`'s order) whose it was.
    fn factor(&mut self) -> Result<(), usize> {
        let rows = self.rows;
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

/// The first derivatives' [`JacobianSink`]: `R_z` straight into the factor's storage and
/// `R_x` on the solved columns (`q₁`, `p₁`, `k₂`) into the right-hand sides' rows, both in
/// the elimination order; `P_x` into `dp₂/dx`'s rows, `P_z` into `pz`. Each run of dynamic
/// or kinematic variables ([`Segment`]) of a row is written where it goes, but `R_z`'s
/// (kept in `scratch` until the row ends: the factor is stored by columns). Every entry the
/// solve reads is written on every call, zeros included, and nothing else of `J` and `P` is
/// formed.
struct Pieces<'a> {
    n: usize,
    nd: usize,
    /// Solved columns.
    k: usize,
    segments: &'a [Segment],
    kinematic: &'a [usize],
    position: &'a [usize],
    factor: &'a mut [f64],
    rhs: &'a mut [f64],
    dp2: &'a mut [f64],
    pz: &'a mut [f64],
    /// `∂r/∂q₂` of the row being written, on its dynamic variables.
    scratch: &'a mut [f64],
}

impl Pieces<'_> {
    /// Where entry `(equation, unknown)` of `R_z` is stored.
    #[inline(always)]
    fn at(&self, equation: usize, unknown: usize) -> usize {
        self.position[unknown] * self.position.len() + self.position[equation]
    }
}

impl JacobianSink<f64> for Pieces<'_> {
    #[inline(always)]
    fn row<const FUSED: bool>(&mut self, r: usize, writer: &RowWriter<f64, FUSED>) {
        let (n, nd, k) = (self.n, self.nd, self.k);
        // The right-hand side's row: R_x's q₁, p₁, k₂ columns; dp₂/dx's: P_x's.
        let rhs = &mut self.rhs[self.position[r] * k..(self.position[r] + 1) * k];
        let (r_q1, rest) = rhs.split_at_mut(n);
        let r_k2 = &mut rest[nd..];
        let (p_q1, rest) = self.dp2[r * k..(r + 1) * k].split_at_mut(n);
        let p_k2 = &mut rest[nd..];
        let pz = &mut self.pz[r * nd..(r + 1) * nd];
        for s in self.segments {
            let (columns, at, len) = (s.columns.clone(), s.place, s.columns.len());
            let (r_q2, p_q2) = if s.dynamic {
                (&mut self.scratch[at..at + len], &mut pz[at..at + len])
            } else {
                (&mut r_k2[at..at + len], &mut p_k2[at..at + len])
            };
            writer.write(
                columns.clone(),
                [&mut r_q1[columns.clone()], r_q2, &mut p_q1[columns], p_q2],
            );
        }
    }

    #[inline(always)]
    fn end_row(&mut self, r: usize) {
        let (n, nd, k) = (self.n, self.nd, self.k);
        let (rows, equation) = (self.position.len(), self.position[r]);
        for (c, &x) in self.scratch[..nd].iter().enumerate() {
            self.factor[self.position[c] * rows + equation] = x;
        }
        // ∂r_r/∂p₁ = e_r; P is zero on p₁.
        let p1 = &mut self.rhs[equation * k + n..equation * k + n + nd];
        p1.fill(0.0);
        p1[r] = 1.0;
        self.dp2[r * k + n..r * k + n + nd].fill(0.0);
    }

    /// An input's columns are not solved for (its `p₁` column's, scaled).
    fn input(&mut self, _: usize, _: usize, _: f64, _: f64) {}

    #[inline(always)]
    fn multiplier(&mut self, r: usize, s: usize, x: f64) {
        let at = self.at(r, self.nd + s);
        self.factor[at] = x;
    }

    fn constraint(&mut self, s: usize, dh2: &[f64]) {
        let (n, nd, k) = (self.n, self.nd, self.k);
        let equation = nd + s;
        for segment in self.segments.iter().filter(|s| s.dynamic) {
            for (o, &x) in dh2[segment.columns.clone()].iter().enumerate() {
                let at = self.at(equation, segment.place + o);
                self.factor[at] = x;
            }
        }
        // h does not depend on the multipliers.
        for unknown in nd..self.position.len() {
            let at = self.at(equation, unknown);
            self.factor[at] = 0.0;
        }
        let out = &mut self.rhs[self.position[equation] * k..(self.position[equation] + 1) * k];
        let (q1_p1, k2) = out.split_at_mut(n + nd);
        q1_p1.fill(0.0);
        k2.iter_mut()
            .zip(self.kinematic)
            .for_each(|(o, &v)| *o = dh2[v]);
    }
}

/// The contact force's derivatives into `R_z` (its `q₂` block) and `R_x` (the `q₁` and `k₂`
/// columns) of the dynamic rows: the residual is `r_d + f_c(q₁, q₂)`.
fn add_contact(
    sh: &Shape,
    k: usize,
    c: &crate::integrate::vi::contact::ContactJacobian,
    lu: &mut OrderedFactor,
    rhs: &mut [f64],
) {
    let (n, nd) = (sh.n, sh.nd());
    let (factor, position) = lu.storage();
    let rows = position.len();
    for r in 0..nd {
        let equation = position[r];
        for (cj, &j) in sh.dynamic.iter().enumerate() {
            factor[position[cj] * rows + equation] += c.dq2[(r, j)];
        }
        let row = &mut rhs[equation * k..(equation + 1) * k];
        for j in 0..n {
            row[j] += c.dq1[(r, j)];
        }
        for (kk, &j) in sh.kinematic.iter().enumerate() {
            row[n + nd + kk] += c.dq2[(r, j)];
        }
    }
}

/// [`jacobians`] into [`Pieces`], compiled also for AVX2 with fused multiply-adds and for
/// AVX, chosen at run time (as [`jacobians_f64`](super::jacobians::jacobians_f64)).
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn jacobians_in_pieces(sh: &Shape, st: &StepTerms<f64>, pieces: &mut Pieces) {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        jacobians::<f64, true>(sh, st, pieces);
    } else {
        jacobians::<f64, false>(sh, st, pieces);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The matrix `R_z` of `rows` unknowns (`nd` dynamic), column-major in `z`'s order.
    fn matrix(nd: usize, rows: usize) -> Vec<f64> {
        (0..rows * rows)
            .map(|at| {
                let (r, c) = (at % rows, at / rows);
                let x = ((r * 7 + c * 3) % 11) as f64 * 0.1 - 0.5;
                // A dynamic block heavy on its diagonal, a zero multipliers' block.
                match (r < nd, c < nd) {
                    (true, true) => x + if r == c { 4.0 } else { 0.0 },
                    (false, false) => 0.0,
                    _ => x + 0.3,
                }
            })
            .collect()
    }

    fn factored(a: &[f64], nd: usize, rows: usize) -> (OrderedFactor, Result<(), usize>) {
        let mut lu = OrderedFactor::new(nd, rows - nd);
        let (storage, position) = lu.storage();
        for (e, u) in (0..rows).flat_map(|e| (0..rows).map(move |u| (e, u))) {
            storage[position[u] * rows + position[e]] = a[u * rows + e];
        }
        let done = lu.factor();
        (lu, done)
    }

    /// Solves with `R_z` and `R_zᵀ` through the elimination order give `z`'s order back
    /// (the residual of the matrix as written), the order puts the last dynamic variable first
    /// and the multipliers last, and a vanished pivot is named in `z`'s order.
    #[test]
    fn the_elimination_order_is_undone_in_every_solve_and_error() {
        let (nd, rows) = (4, 6);
        let a = matrix(nd, rows);
        let (lu, done) = factored(&a, nd, rows);
        assert_eq!(done, Ok(()));
        assert_eq!(lu.order, [3, 2, 1, 0, 4, 5]);
        let b: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.9).sin()).collect();
        let mut scratch = vec![0.0; rows];
        for transposed in [false, true] {
            let mut x = b.clone();
            lu.solve(&mut x, &mut scratch, transposed);
            for r in 0..rows {
                let entry = |r: usize, c: usize| {
                    if transposed {
                        a[r * rows + c]
                    } else {
                        a[c * rows + r]
                    }
                };
                let ax: f64 = (0..rows).map(|c| entry(r, c) * x[c]).sum();
                assert!(
                    (ax - b[r]).abs() < 1e-12,
                    "transposed {transposed}, row {r}"
                );
            }
        }
        // The rows solve too: b's rows put in the order, the solution's read through it.
        let k = 3;
        let mut rows_b = vec![0.0; rows * k];
        for (i, &o) in lu.order.iter().enumerate() {
            for c in 0..k {
                rows_b[i * k + c] = b[o] * (c + 1) as f64;
            }
        }
        lu.solve_rows(&mut rows_b, k);
        let mut one = b.clone();
        lu.solve(&mut one, &mut scratch, false);
        for u in 0..rows {
            for c in 0..k {
                let got = rows_b[lu.position[u] * k + c];
                assert!(
                    (got - one[u] * (c + 1) as f64).abs() < 1e-12,
                    "unknown {u}, column {c}"
                );
            }
        }
        // Unknown 3's column zero (the last dynamic variable: eliminated first), then a
        // multiplier's dependent on the other's.
        let mut zero = a.clone();
        zero[3 * rows..4 * rows].fill(0.0);
        assert_eq!(factored(&zero, nd, rows).1, Err(3));
        let mut twin = a.clone();
        for r in 0..nd {
            twin[5 * rows + r] = twin[4 * rows + r];
            twin[r * rows + 5] = twin[r * rows + 4];
        }
        assert_eq!(factored(&twin, nd, rows).1, Err(5));
    }
}
