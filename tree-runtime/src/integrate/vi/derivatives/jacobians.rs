//! The step's Jacobians `J = ∂R/∂w` and `P = ∂p₂/∂w` from its terms, written once over any
//! [`Scalar`] (docs/derivations.md §9): over `f64` at the solution for the first derivatives,
//! over dual numbers for their derivatives.

use super::StepInput;
use crate::integrate::discrete::{DiscreteLagrangian, SecondSlot, Slots};
use crate::system::Sparsity;
use tree_kernel::Scalar;

/// Sizes of one step and where each block sits in `w = (q₁, q₂, p₁, u₁, λ)` and in `x`.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Shape {
    pub(super) n: usize,
    pub(super) dynamic: Vec<usize>,
    pub(super) kinematic: Vec<usize>,
    /// The variables in runs of consecutive dynamic or kinematic ones (one of each where the
    /// kinematic variables come last, as in most models): where a row of the Jacobians is
    /// written to, a run at a time.
    pub(super) segments: Vec<Segment>,
    /// Constraint equations.
    pub(super) m: usize,
    /// The variable each input pushes on.
    pub(super) inputs: Vec<usize>,
    pub(super) ld: DiscreteLagrangian,
    /// `f⁻ = left·F`, `f⁺ = plus·F` (Δt included).
    pub(super) left: f64,
    pub(super) plus: f64,
}

impl Shape {
    /// The shape of a step over `n` variables split into `dynamic` and `kinematic`, with `m`
    /// constraint equations and inputs on `inputs`' variables, `f⁻ = left·F`, `f⁺ = plus·F`.
    pub(super) fn new(
        n: usize,
        (dynamic, kinematic): (Vec<usize>, Vec<usize>),
        m: usize,
        inputs: Vec<usize>,
        ld: DiscreteLagrangian,
        (left, plus): (f64, f64),
    ) -> Self {
        let mut segments: Vec<Segment> = Vec::new();
        for j in 0..n {
            let (is_dynamic, place) = match dynamic.iter().position(|&d| d == j) {
                Some(c) => (true, c),
                None => (false, kinematic.iter().position(|&v| v == j).unwrap_or(0)),
            };
            match segments.last_mut() {
                Some(last) if last.dynamic == is_dynamic && last.columns.end == j => {
                    last.columns.end += 1
                }
                _ => segments.push(Segment {
                    columns: j..j + 1,
                    dynamic: is_dynamic,
                    place,
                }),
            }
        }
        Shape {
            n,
            dynamic,
            kinematic,
            segments,
            m,
            inputs,
            ld,
            left,
            plus,
        }
    }

    pub(super) fn nd(&self) -> usize {
        self.dynamic.len()
    }
    pub(super) fn nu(&self) -> usize {
        self.inputs.len()
    }
    /// `R`'s rows: the dynamic residuals, then `h(q₂)`.
    pub(super) fn rows(&self) -> usize {
        self.nd() + self.m
    }
    /// Offsets of `q₂`, `p₁`, `u₁`, `λ` in `w` (`q₁` at 0).
    pub(super) fn w_q2(&self) -> usize {
        self.n
    }
    pub(super) fn w_p1(&self) -> usize {
        2 * self.n
    }
    pub(super) fn w_u1(&self) -> usize {
        2 * self.n + self.nd()
    }
    pub(super) fn w_lambda(&self) -> usize {
        2 * self.n + self.nd() + self.nu()
    }
    pub(super) fn w(&self) -> usize {
        self.w_lambda() + self.m
    }
    /// Where block `b` sits in `x`, and its width.
    pub(super) fn x_block(&self, b: StepInput) -> (usize, usize) {
        let (n, nd, nu) = (self.n, self.nd(), self.nu());
        match b {
            StepInput::Q1 => (0, n),
            StepInput::P1 => (n, nd),
            StepInput::U1 => (n + nd, nu),
            StepInput::K2 => (n + nd + nu, self.kinematic.len()),
        }
    }
    pub(super) fn x(&self) -> usize {
        self.n + self.nd() + self.nu() + self.kinematic.len()
    }
}

/// A run of consecutive variables, all dynamic or all kinematic, and the place of its first
/// in its list ([`Shape::dynamic`] or [`Shape::kinematic`]).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Segment {
    pub(super) columns: std::ops::Range<usize>,
    pub(super) dynamic: bool,
    pub(super) place: usize,
}

/// What the step's Jacobians are built from, over a scalar: the continuous terms at the
/// quadrature point (`L_qq`, `L_q̇q` and its transpose, `M`, `F_q`, `F_q̇`, row-major n × n;
/// `forces`: where `F_q`, `F_q̇` may be non-zero, and are read), `Dh(q₁)`, `Σ_s λ_s D²h_s(q₁)`
/// (n × n, read on the dynamic variables' rows: `System::weighted_constraint_hessian` and its
/// dual form) and `Dh(q₂)`.
pub(super) struct StepTerms<'a, T> {
    pub(super) lqq: &'a [T],
    pub(super) lvq: &'a [T],
    pub(super) lvq_t: &'a [T],
    pub(super) mass: &'a [T],
    pub(super) forces: Sparsity,
    pub(super) fq: &'a [T],
    pub(super) fv: &'a [T],
    pub(super) dh1: &'a [T],
    pub(super) lambda_d2h1: &'a [T],
    pub(super) dh2: &'a [T],
}

/// Where [`jacobians`] puts `J` and `P`: whole ([`Whole`]: the second derivatives' `D_jJ`,
/// `D_jP`), or cut into the first derivatives' pieces where the solve reads them (the
/// first-order linearisation's sink). Each dynamic row `r` is written as four rows over all
/// variables — `∂r_r/∂q₁`, `∂r_r/∂q₂`, `∂p₂,r/∂q₁`, `∂p₂,r/∂q₂` — then [`Self::end_row`];
/// the constant and sparse entries are given one by one.
pub(super) trait JacobianSink<T> {
    /// Row `r`'s four rows, by runs of variables where the sink keeps them apart: the
    /// sink calls [`RowWriter::write`] with each run and the four rows' slices over it.
    fn row<const FUSED: bool>(&mut self, r: usize, writer: &RowWriter<T, FUSED>);
    /// Row `r` written (its `∂r_r/∂p₁ = e_r` is the sink's to place).
    fn end_row(&mut self, r: usize);
    /// `∂r_r/∂u_k = left`, `∂p₂,r/∂u_k = plus` (input `k` pushes on row `r`'s variable).
    fn input(&mut self, r: usize, k: usize, left: T, plus: T);
    /// `∂r_r/∂λ_s`.
    fn multiplier(&mut self, r: usize, s: usize, x: T);
    /// `∂h_s/∂q₂ = Dh_s(q₂)`, over all variables.
    fn constraint(&mut self, s: usize, dh2: &[T]);
}

/// `J` (rows × w) and `P` (n_d × w), row-major, whole. Entries never written (`J`'s `q₁`
/// columns on the constraint rows, …) stay as the buffers were made: zero.
pub(super) struct Whole<'a, T> {
    pub(super) w: usize,
    pub(super) n: usize,
    /// Offsets of `p₁`, `u₁`, `λ` in `w`.
    pub(super) p1: usize,
    pub(super) u1: usize,
    pub(super) lambda: usize,
    pub(super) nd: usize,
    pub(super) jac: &'a mut [T],
    pub(super) pjac: &'a mut [T],
}

impl<'a, T> Whole<'a, T> {
    pub(super) fn new(sh: &Shape, jac: &'a mut [T], pjac: &'a mut [T]) -> Self {
        let (w, n, nd) = (sh.w(), sh.n, sh.nd());
        let (p1, u1, lambda) = (sh.w_p1(), sh.w_u1(), sh.w_lambda());
        Whole {
            w,
            n,
            p1,
            u1,
            lambda,
            nd,
            jac,
            pjac,
        }
    }
}

impl<T: Scalar> JacobianSink<T> for Whole<'_, T> {
    #[inline(always)]
    fn row<const FUSED: bool>(&mut self, r: usize, writer: &RowWriter<T, FUSED>) {
        let (w, n) = (self.w, self.n);
        let (by_q1, rest) = self.jac[r * w..(r + 1) * w].split_at_mut(n);
        let (p_by_q1, p_rest) = self.pjac[r * w..(r + 1) * w].split_at_mut(n);
        writer.write(0..n, [by_q1, &mut rest[..n], p_by_q1, &mut p_rest[..n]]);
    }
    #[inline(always)]
    fn end_row(&mut self, r: usize) {
        self.jac[r * self.w + self.p1 + r] = T::constant(1.0);
    }
    fn input(&mut self, r: usize, k: usize, left: T, plus: T) {
        self.jac[r * self.w + self.u1 + k] = left;
        self.pjac[r * self.w + self.u1 + k] = plus;
    }
    #[inline(always)]
    fn multiplier(&mut self, r: usize, s: usize, x: T) {
        self.jac[r * self.w + self.lambda + s] = x;
    }
    fn constraint(&mut self, s: usize, dh2: &[T]) {
        let row = &mut self.jac[(self.nd + s) * self.w..(self.nd + s + 1) * self.w];
        row[self.n..2 * self.n].copy_from_slice(dh2);
    }
}

/// One dynamic row `i` of `J` and `P` on `q₁` and `q₂` from the terms' rows `i`, written
/// into a sink's slices a run of variables at a time ([`JacobianSink::row`]).
pub(super) struct RowWriter<'a, T, const FUSED: bool> {
    /// Rows `i` of `L_qq`, `L_q̇q`, its transpose, `M`, `Σ_s λ_s D²h_s(q₁)`.
    terms: [&'a [T]; 5],
    /// Rows `i` of `F_q`, `F_q̇`, read on the variables `forced`.
    forces: (&'a [T], &'a [T]),
    forced: std::ops::Range<usize>,
    /// `D₁D₁L_d`, `D₂D₁L_d`, `D₂D₂L_d`.
    slots: [SecondSlot<T>; 3],
    /// `Δt`, `left`, `plus`, `1 − α`, `1/Δt`, `α`.
    constants: [T; 6],
}

impl<T: Scalar, const FUSED: bool> RowWriter<'_, T, FUSED> {
    /// The row on the variables `columns` into `[∂r_i/∂q₁, ∂r_i/∂q₂, ∂p₂,i/∂q₁, ∂p₂,i/∂q₂]`
    /// (each as long as `columns`).
    #[inline(always)]
    pub(super) fn write(&self, columns: std::ops::Range<usize>, outs: [&mut [T]; 4]) {
        let [cdt, left, plus, q1_q, v1, q2_q] = self.constants;
        let (j0, width) = (columns.start, columns.len());
        let terms = self.terms.map(|t| &t[columns.clone()]);
        let [by_q1, by_q2, p_by_q1, p_by_q2] = outs;
        let (by_q1, by_q2) = (&mut by_q1[..width], &mut by_q2[..width]);
        let (p_by_q1, p_by_q2) = (&mut p_by_q1[..width], &mut p_by_q2[..width]);
        let constants = (self.slots, cdt);
        entries::<T, FUSED>(terms, constants, by_q1, by_q2, p_by_q1, p_by_q2);
        // ∂F/∂q₁ = (1−α)F_q − F_q̇/Δt, ∂F/∂q₂ = αF_q + F_q̇/Δt.
        let (fq, fv) = self.forces;
        for j in self.forced.start.max(j0)..self.forced.end.min(columns.end) {
            let f1 = q1_q * fq[j] - v1 * fv[j];
            let f2 = q2_q * fq[j] + v1 * fv[j];
            let o = j - j0;
            by_q1[o] += left * f1;
            by_q2[o] += left * f2;
            p_by_q1[o] += plus * f1;
            p_by_q2[o] += plus * f2;
        }
    }
}

/// [`RowWriter::write`]'s four rows on a run of variables from the terms' rows on it. Each
/// output is a parameter of its own: the compiler may then take it for overlapping nothing
/// else and vectorises the loop with no run-time overlap checks (a quarter of the
/// Jacobians' time when the slices came from one struct).
#[inline(always)]
fn entries<T: Scalar, const FUSED: bool>(
    [lqq, lvq, lvq_t, mass, l_d2h]: [&[T]; 5],
    ([d1d1, d2d1, d2d2], cdt): ([SecondSlot<T>; 3], T),
    by_q1: &mut [T],
    by_q2: &mut [T],
    p_by_q1: &mut [T],
    p_by_q2: &mut [T],
) {
    // One length for every output (the caller's slices already are): the bounds are then
    // checked once, before the loop.
    let width = by_q1.len();
    let (by_q2, p_by_q1, p_by_q2) = (
        &mut by_q2[..width],
        &mut p_by_q1[..width],
        &mut p_by_q2[..width],
    );
    for o in 0..width {
        let (qq, vq, vq_t, mm) = (lqq[o], lvq[o], lvq_t[o], mass[o]);
        let d1d1 = d1d1.at_fused::<FUSED>(qq, vq, vq_t, mm);
        by_q1[o] = cdt.multiply_add::<FUSED>(l_d2h[o], d1d1);
        by_q2[o] = d2d1.at_fused::<FUSED>(qq, vq, vq_t, mm);
        // D₁D₂L_d = (D₂D₁L_d)ᵀ: entry (j, i) of D₂D₁ (L_qq and M symmetric).
        p_by_q1[o] = d2d1.at_fused::<FUSED>(qq, vq_t, vq, mm);
        p_by_q2[o] = d2d2.at_fused::<FUSED>(qq, vq, vq_t, mm);
    }
}

/// `J = ∂R/∂w` (rows × w) and `P = ∂p₂/∂w` (n_d × w) into `sink`, from the step's terms:
///
/// * `∂r_i/∂q₁ⱼ = D₁D₁L_d + f⁻·∂F/∂q₁ + Δt Σ_s λ_s D²h_s(q₁)`, `∂r_i/∂q₂ⱼ = D₂D₁L_d +
///   f⁻·∂F/∂q₂`, `∂r_i/∂p₁ = I`, `∂r_i/∂u_k = left·B`, `∂r_i/∂λ_s = Δt Dh_s(q₁)ᵢ`;
/// * `∂h_s/∂q₂ = Dh_s(q₂)`;
/// * `∂p₂ᵢ/∂q₁ⱼ = (D₂D₁L_d)ⱼᵢ + f⁺·∂F/∂q₁`, `∂p₂ᵢ/∂q₂ⱼ = D₂D₂L_d + f⁺·∂F/∂q₂`,
///   `∂p₂ᵢ/∂u_k = plus·B`,
///
/// with `∂F/∂q₁ = (1−α)F_q − F_q̇/Δt`, `∂F/∂q₂ = αF_q + F_q̇/Δt` (F at `(q_α, v)`).
#[inline(always)]
pub(super) fn jacobians<T: Scalar, const FUSED: bool>(
    sh: &Shape,
    st: &StepTerms<T>,
    sink: &mut impl JacobianSink<T>,
) {
    let (n, m) = (sh.n, sh.m);
    let (a, dt) = (sh.ld.alpha, sh.ld.dt);
    let c = T::constant;
    // Every entry this writes is written on every call; the others are the sink's.
    let [d1d1, d2d1, d2d2] = [Slots::D1D1, Slots::D2D1, Slots::D2D2].map(|s| sh.ld.slot::<T>(s));
    let (cdt, left, plus) = (c(dt), c(sh.left), c(sh.plus));
    // Row i of an n × n term (the transpose's row is the term's column).
    pub(super) fn row<T>(x: &[T], i: usize, n: usize) -> &[T] {
        &x[i * n..(i + 1) * n]
    }
    let (q1_q, v1, q2_q) = (c(1.0 - a), c(1.0 / dt), c(a));
    for (r, &i) in sh.dynamic.iter().enumerate() {
        let at = |x| row(x, i, n);
        let writer = RowWriter::<T, FUSED> {
            terms: [
                at(st.lqq),
                at(st.lvq),
                at(st.lvq_t),
                at(st.mass),
                at(st.lambda_d2h1),
            ],
            forces: (at(st.fq), at(st.fv)),
            // On the diagonal alone for per-variable damping.
            forced: match st.forces {
                Sparsity::Zero => 0..0,
                Sparsity::Diagonal => i..i + 1,
                Sparsity::Dense => 0..n,
            },
            slots: [d1d1, d2d1, d2d2],
            constants: [cdt, left, plus, q1_q, v1, q2_q],
        };
        sink.row(r, &writer);
        sink.end_row(r);
        for (k, &v) in sh.inputs.iter().enumerate() {
            if v == i {
                sink.input(r, k, left, plus);
            }
        }
        for s in 0..m {
            sink.multiplier(r, s, cdt * st.dh1[s * n + i]);
        }
    }
    for s in 0..m {
        sink.constraint(s, &st.dh2[s * n..(s + 1) * n]);
    }
}

/// [`jacobians`] over `f64`, whole, compiled also for AVX2 with fused multiply-adds and for
/// AVX, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
pub(super) fn jacobians_f64(sh: &Shape, st: &StepTerms<f64>, jac: &mut [f64], pjac: &mut [f64]) {
    let whole = &mut Whole::new(sh, jac, pjac);
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        jacobians::<f64, true>(sh, st, whole);
    } else {
        jacobians::<f64, false>(sh, st, whole);
    }
}

/// Rows `rows` of the matrix of `height` rows stored column-major in `a`, into the same rows
/// of the row-major `out` (rows as long as `a` has columns; other rows untouched).
pub(super) fn gather_rows<T: Copy>(
    a: &[T],
    height: usize,
    rows: impl IntoIterator<Item = usize>,
    out: &mut [T],
) {
    let width = a.len().checked_div(height).unwrap_or(0);
    for i in rows {
        for (j, o) in out[i * width..(i + 1) * width].iter_mut().enumerate() {
            *o = a[j * height + i];
        }
    }
}

/// `out` = the matrix of `height` rows stored column-major in `a`, stored row-major (its
/// transpose's storage).
pub(super) fn row_major_into<T: Copy>(a: &[T], height: usize, out: &mut [T]) {
    gather_rows(a, height, 0..height, out);
}
