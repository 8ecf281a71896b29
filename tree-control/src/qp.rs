//! The control QP of one backward-pass knot, `min ½δuᵀHδu + gᵀδu` within box limits shifted
//! by the current control: projected Newton (Bertsekas 1982; Tassa, Mansard & Todorov 2014,
//! box-DDP), in buffers sized once per solve (nothing allocated per knot).

use nalgebra::{DMatrix, DVector};

use tree_runtime::linalg::{
    cholesky_backward, cholesky_factor_packed, cholesky_forward, cholesky_solve_rows,
};

/// Box limits per control `(lo, hi)`.
pub(crate) type Limits = (DVector<f64>, DVector<f64>);

/// Buffers of [`ControlQp::solve`], for `nu` controls.
#[derive(Clone, Debug)]
pub(crate) struct ControlQp {
    /// The iterate `δu`, and a trial one.
    x: Vec<f64>,
    y: Vec<f64>,
    /// `g + H δu`.
    grad: Vec<f64>,
    /// Which controls are free (not held at a bound by the gradient), and their indices.
    free: Vec<bool>,
    idx: Vec<usize>,
    /// `H` on the free controls, factored (column-major, packed), and a right-hand side.
    factor: Vec<f64>,
    rhs: Vec<f64>,
    /// The free rows of `Q_ux` (row by row), solved into the gain's.
    rows: Vec<f64>,
    /// The bounds shifted by `u`.
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl ControlQp {
    pub(crate) fn new(nu: usize, nx: usize) -> Self {
        ControlQp {
            x: vec![0.0; nu],
            y: vec![0.0; nu],
            grad: vec![0.0; nu],
            free: vec![true; nu],
            idx: Vec::with_capacity(nu),
            factor: vec![0.0; nu * nu],
            rhs: vec![0.0; nu],
            rows: vec![0.0; nu * nx],
            lo: vec![0.0; nu],
            hi: vec![0.0; nu],
        }
    }

    /// `H` on the controls in `idx`, factored; `false` when it is not positive definite.
    fn factor_free(&mut self, h: &DMatrix<f64>) -> bool {
        let nf = self.idx.len();
        for (c, &j) in self.idx.iter().enumerate() {
            for (r, &i) in self.idx.iter().enumerate() {
                self.factor[c * nf + r] = h[(i, j)];
            }
        }
        cholesky_factor_packed(&mut self.factor, nf).is_ok()
    }

    /// `rhs[..nf] = H_ff⁻¹ rhs[..nf]` with the factor of [`Self::factor_free`].
    fn solve_free(&mut self) {
        let nf = self.idx.len();
        cholesky_forward(&self.factor[..nf * nf], nf, &mut self.rhs[..nf]);
        cholesky_backward(&self.factor[..nf * nf], nf, &mut self.rhs[..nf]);
    }

    /// `½xᵀHx + gᵀx`.
    fn value(h: &DMatrix<f64>, g: &DVector<f64>, x: &[f64]) -> f64 {
        let nu = x.len();
        let mut v = 0.0;
        for i in 0..nu {
            let hx: f64 = (0..nu).map(|j| h[(i, j)] * x[j]).sum();
            v += 0.5 * x[i] * hx + g[i] * x[i];
        }
        v
    }

    /// Solves the QP for `H = h`, `g`, with the limits shifted by `u`: the feed-forward into
    /// `k`, the feedback into `gain` (zero on the clamped controls, `−H_ff⁻¹ Q_ux,f` on the
    /// free ones). `false` when `H` (or its free block) is not positive definite.
    #[allow(clippy::too_many_arguments)] // the QP's data, its limits and its two results
    pub(crate) fn solve(
        &mut self,
        h: &DMatrix<f64>,
        g: &DVector<f64>,
        qux: &DMatrix<f64>,
        u: &DVector<f64>,
        limits: Option<&Limits>,
        k: &mut DVector<f64>,
        gain: &mut DMatrix<f64>,
    ) -> bool {
        let (nu, nx) = (g.len(), qux.ncols());
        self.x.as_mut_slice().fill(0.0);
        self.free.fill(true);
        if let Some((lo, hi)) = limits {
            for c in 0..nu {
                (self.lo[c], self.hi[c]) = (lo[c] - u[c], hi[c] - u[c]);
            }
            if !self.projected_newton(h, g) {
                return false;
            }
        } else {
            self.idx.clear();
            self.idx.extend(0..nu);
            if !self.factor_free(h) {
                return false;
            }
            self.rhs[..nu].copy_from_slice(g.as_slice());
            self.solve_free();
            for c in 0..nu {
                self.x[c] = -self.rhs[c];
            }
        }
        k.as_mut_slice().copy_from_slice(&self.x);
        // The feedback on the free controls: −H_ff⁻¹ Q_ux,f, column by column.
        gain.as_mut_slice().fill(0.0);
        self.idx.clear();
        self.idx.extend((0..nu).filter(|&c| self.free[c]));
        if self.idx.is_empty() {
            return true;
        }
        if limits.is_some() && !self.factor_free(h) {
            return false;
        }
        // Every column of the gain at once: the free rows of Q_ux, solved by rows.
        let nf = self.idx.len();
        let rows = &mut self.rows[..nf * nx];
        for (row, &c) in rows.chunks_exact_mut(nx.max(1)).zip(&self.idx) {
            for (col, x) in row.iter_mut().enumerate() {
                *x = qux[(c, col)];
            }
        }
        cholesky_solve_rows(&self.factor[..nf * nf], nf, rows, nx);
        for (row, &c) in rows.chunks_exact(nx.max(1)).zip(&self.idx) {
            for (col, &x) in row.iter().enumerate() {
                gain[(c, col)] = -x;
            }
        }
        true
    }

    /// Projected Newton from `δu = 0` within `[lo, hi]`: free the controls whose gradient
    /// points inside, take the Newton step on them, backtrack along the projected path.
    fn projected_newton(&mut self, h: &DMatrix<f64>, g: &DVector<f64>) -> bool {
        let nu = g.len();
        let g_scale = g.amax().max(1.0);
        for _ in 0..100 {
            for i in 0..nu {
                self.grad[i] = g[i] + (0..nu).map(|j| h[(i, j)] * self.x[j]).sum::<f64>();
            }
            for c in 0..nu {
                let (x, gr) = (self.x[c], self.grad[c]);
                self.free[c] = !((x <= self.lo[c] && gr > 0.0) || (x >= self.hi[c] && gr < 0.0));
            }
            self.idx.clear();
            self.idx.extend((0..nu).filter(|&c| self.free[c]));
            if self.idx.is_empty() {
                break;
            }
            let largest = self
                .idx
                .iter()
                .fold(0.0f64, |m, &c| m.max(self.grad[c].abs()));
            if largest < 1e-13 * g_scale {
                break;
            }
            if !self.factor_free(h) {
                return false;
            }
            for (r, &c) in self.idx.iter().enumerate() {
                self.rhs[r] = self.grad[c];
            }
            self.solve_free();
            // Projected backtracking along −H_ff⁻¹ ∇_f.
            let f0 = Self::value(h, g, &self.x);
            let (mut alpha, mut moved) = (1.0, false);
            while alpha > 1e-10 {
                self.y.copy_from_slice(&self.x);
                for (r, &c) in self.idx.iter().enumerate() {
                    self.y[c] = (self.x[c] - alpha * self.rhs[r]).clamp(self.lo[c], self.hi[c]);
                }
                if Self::value(h, g, &self.y) < f0 - 1e-14 * f0.abs() {
                    std::mem::swap(&mut self.x, &mut self.y);
                    moved = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !moved {
                break;
            }
        }
        true
    }
}
