//! In-place dense factorisations for any nalgebra dimension: nothing allocated, so a
//! fixed-size system stays on the stack and an interpreted one reuses its buffers. They work
//! on the column-major storage directly (`a[j * n + i]` is row i, column j).

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::system::{Matrix, Vector};

mod compact;
mod products;

pub(crate) use compact::{
    combine_compact_rows, lu_solve_compact_rows, CompactCombination, CompactFactor,
};
pub use products::{
    mul_into, mul_into_pair, tr_mul_into, tr_mul_into_pair, tr_mul_into_symmetric, Packing,
};

/// Solves `A x = b` for symmetric positive definite `A` by Cholesky, overwriting the lower
/// triangle of `a` with the factor and `b` with `x`. On failure returns the pivot index and
/// value.
pub fn cholesky_solve<N: Dim>(a: &mut Matrix<N>, b: &mut Vector<N>) -> Result<(), (usize, f64)>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    cholesky_factor(a)?;
    cholesky_substitute(a, b);
    Ok(())
}

/// Factors symmetric positive definite `A = L Lᵀ` in place (the lower triangle of `a`
/// becomes `L`). On failure returns the pivot index and value.
pub fn cholesky_factor<N: Dim>(a: &mut Matrix<N>) -> Result<(), (usize, f64)>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = a.nrows();
    cholesky_factor_packed(a.as_mut_slice(), n)
}

/// [`cholesky_factor`] of the `n × n` column-major matrix in `a[..n²]` (a smaller system
/// packed into larger storage).
pub fn cholesky_factor_packed(a: &mut [f64], n: usize) -> Result<(), (usize, f64)> {
    let a = &mut a[..n * n];
    for j in 0..n {
        let (done, rest) = a.split_at_mut(j * n);
        let col_j = &mut rest[..n];
        let original = col_j[j];
        eliminate(done, col_j, j, n);
        let d = col_j[j];
        // Relative threshold: a pivot lost to rounding is as singular as a zero one.
        let scale = original.abs().max(f64::MIN_POSITIVE);
        if !d.is_finite() || d <= 1e-13 * scale {
            return Err((j, d));
        }
        let d = d.sqrt();
        col_j[j] = d;
        for x in &mut col_j[j + 1..n] {
            *x /= d;
        }
    }
    Ok(())
}

/// Column `j` of a Cholesky factor from the columns `done` before it:
/// `a[i][j] −= Σ_k L[i][k] L[j][k]` for `i ≥ j`.
#[inline(always)]
fn eliminate(done: &[f64], col_j: &mut [f64], j: usize, n: usize) {
    for k in 0..j {
        let col_k = &done[k * n..(k + 1) * n];
        let ljk = col_k[j];
        for i in j..n {
            col_j[i] -= col_k[i] * ljk;
        }
    }
}

/// The weakest pivot of symmetric `A` (`n × n`, column-major in `a[..n²]`, overwritten by
/// its factor): the smallest `d_j / A_jj` of its Cholesky factorisation `A = L D Lᵀ` and
/// its index — 1 for a diagonal matrix, near 0 where a variable's motion is nearly another's
/// (a gimbal lock), ≤ 0 at a singular one. `None` for `n = 0`.
pub(crate) fn weakest_pivot(a: &mut [f64], n: usize) -> Option<(usize, f64)> {
    let a = &mut a[..n * n];
    let mut weakest: Option<(usize, f64)> = None;
    for j in 0..n {
        let (done, rest) = a.split_at_mut(j * n);
        let col_j = &mut rest[..n];
        let original = col_j[j];
        eliminate(done, col_j, j, n);
        let ratio = col_j[j] / original.abs().max(f64::MIN_POSITIVE);
        if weakest.is_none_or(|(_, r)| ratio < r) {
            weakest = Some((j, ratio));
        }
        if !(col_j[j] > 0.0 && col_j[j].is_finite()) {
            break;
        }
        let d = col_j[j].sqrt();
        col_j[j] = d;
        for x in &mut col_j[j + 1..n] {
            *x /= d;
        }
    }
    weakest
}

/// Solves `L Lᵀ x = b` with the factor from [`cholesky_factor`]; `b` becomes `x`.
pub(crate) fn cholesky_substitute<N: Dim>(a: &Matrix<N>, b: &mut Vector<N>)
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = b.len();
    cholesky_forward(a.as_slice(), n, b.as_mut_slice());
    cholesky_backward(a.as_slice(), n, b.as_mut_slice());
}

/// Solves `L y = b` for the factor `L` of [`cholesky_factor`] (column-major `n × n` in `a`);
/// `b` becomes `y`.
pub fn cholesky_forward(a: &[f64], n: usize, b: &mut [f64]) {
    for j in 0..n {
        let col = &a[j * n..(j + 1) * n];
        b[j] /= col[j];
        let bj = b[j];
        for i in j + 1..n {
            b[i] -= col[i] * bj;
        }
    }
}

/// [`cholesky_forward`] for `k` right sides at once, each `n` long and stored one after the
/// other in `b[..k·n]`: one division a column, and the sides' substitutions interleaved (a
/// single side's is a chain of dependent divisions and updates).
pub fn cholesky_forward_many(a: &[f64], n: usize, b: &mut [f64], k: usize) {
    for j in 0..n {
        let col = &a[j * n..(j + 1) * n];
        let inverse = 1.0 / col[j];
        for side in b[..k * n].chunks_exact_mut(n) {
            side[j] *= inverse;
            let bj = side[j];
            for i in j + 1..n {
                side[i] -= col[i] * bj;
            }
        }
    }
}

/// Solves `Lᵀ x = y` for the factor `L` of [`cholesky_factor`]; `b` (holding `y`) becomes
/// `x`.
pub fn cholesky_backward(a: &[f64], n: usize, b: &mut [f64]) {
    for j in (0..n).rev() {
        let col = &a[j * n..(j + 1) * n];
        let mut s = b[j];
        for i in j + 1..n {
            s -= col[i] * b[i];
        }
        b[j] = s / col[j];
    }
}

/// Solves `L Lᵀ X = B` for many right-hand sides at once, with the factor `L` of
/// [`cholesky_factor_packed`] (`n × n` in `a`). `B` is stored by rows: row r, one entry per
/// right-hand side, at `rows[r * w..(r + 1) * w]`; it becomes `X`. Each step of the two
/// substitutions is one row update across every right-hand side (vectorised), the same
/// operations in the same order as [`cholesky_forward`] and [`cholesky_backward`] on each.
pub fn cholesky_solve_rows(a: &[f64], n: usize, rows: &mut [f64], w: usize) {
    if w == 0 {
        return;
    }
    let rows = &mut rows[..n * w];
    for j in 0..n {
        let (done, rest) = rows.split_at_mut((j + 1) * w);
        let row_j = &mut done[j * w..];
        let d = a[j * n + j];
        row_j.iter_mut().for_each(|x| *x /= d);
        for (i, row_i) in (j + 1..n).zip(rest.chunks_exact_mut(w)) {
            let lij = a[j * n + i];
            for (x, &y) in row_i.iter_mut().zip(row_j.iter()) {
                *x -= lij * y;
            }
        }
    }
    for j in (0..n).rev() {
        let (done, rest) = rows.split_at_mut((j + 1) * w);
        let row_j = &mut done[j * w..];
        for (i, row_i) in (j + 1..n).zip(rest.chunks_exact(w)) {
            let lij = a[j * n + i];
            for (x, &y) in row_j.iter_mut().zip(row_i) {
                *x -= lij * y;
            }
        }
        let d = a[j * n + j];
        row_j.iter_mut().for_each(|x| *x /= d);
    }
}

/// Solves `A x = b` by LU with partial pivoting, overwriting `a` and `b` (`b` becomes `x`).
/// On a zero pivot returns its column.
pub fn lu_solve<N: Dim>(a: &mut Matrix<N>, b: &mut Vector<N>) -> Result<(), usize>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = b.len();
    let b = b.as_mut_slice();
    lu_core_factor(a.as_mut_slice(), n, 1.0, LOST, |j, p| b.swap(j, p))?;
    forward_backward(a.as_slice(), n, b);
    Ok(())
}

/// Row interchanges of an LU factorisation.
pub(crate) type Pivots<N> = nalgebra::OVector<usize, N>;

/// Factors the `n × n` column-major matrix in `a[..n²]` in place (`P A = L U`, partial
/// pivoting), recording the interchanges in `pivots[..n]`. The caller may pack a smaller
/// system into larger fixed-size storage. On failure returns the column whose pivot vanished.
pub fn lu_factor_packed(a: &mut [f64], n: usize, pivots: &mut [usize]) -> Result<(), usize> {
    lu_core_factor(&mut a[..n * n], n, 1.0, LOST, |j, p| pivots[j] = p)
}

/// [`lu_factor_packed`] with threshold pivoting: the diagonal entry stays the pivot while
/// its magnitude is at least `threshold` (in (0, 1]) times the largest below it, else the
/// first of the largest is swapped in. Each multiplier is then at most `1/threshold` in
/// magnitude (partial pivoting's bound is 1, its `threshold` 1), and the rows stay in the
/// order the caller chose: a matrix ordered so that elimination makes no fill (a tree's
/// variables, leaves first) keeps its zeros in the factor, where partial pivoting would
/// swap a heavier row up and fill it (the sparse solvers' rule, with 0.1 their usual
/// threshold).
pub(crate) fn lu_factor_packed_threshold(
    a: &mut [f64],
    n: usize,
    pivots: &mut [usize],
    threshold: f64,
) -> Result<(), usize> {
    lu_core_factor(&mut a[..n * n], n, threshold, LOST, |j, p| pivots[j] = p)
}

/// Solves `A x = b[..n]` with the factors from [`lu_factor_packed`]; `b` becomes `x`.
pub fn lu_solve_packed(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64]) {
    for (j, &p) in pivots[..n].iter().enumerate() {
        b.swap(p, j);
    }
    forward_backward(&a[..n * n], n, &mut b[..n]);
}

/// `a · b` in four running sums (one would wait on each addition; four vectorise).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut sums = [0.0f64; 4];
    for (a, b) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for l in 0..4 {
            sums[l] += a[l] * b[l];
        }
    }
    let tail = a.len().min(b.len()) / 4 * 4;
    let rest: f64 = a[tail..].iter().zip(&b[tail..]).map(|(a, b)| a * b).sum();
    (sums[0] + sums[1]) + (sums[2] + sums[3]) + rest
}

/// Solves `Aᵀ x = b[..n]` with the factors of `A` from [`lu_factor_packed`] (`P A = L U`, so
/// `Aᵀ = Uᵀ Lᵀ P`): `Uᵀ w = b` forward, `Lᵀ y = w` backward — both reading U's and L's
/// columns, contiguous in the column-major factor, as dot products — then `x = Pᵀ y`, the
/// interchanges undone in reverse order. `b` becomes `x`. No factor of `Aᵀ` is needed.
pub(crate) fn lu_solve_transposed_packed(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64]) {
    let (a, b) = (&a[..n * n], &mut b[..n]);
    for i in 0..n {
        let s = dot(&a[i * n..i * n + i], &b[..i]);
        b[i] = (b[i] - s) / a[i * n + i];
    }
    for i in (0..n).rev() {
        b[i] -= dot(&a[i * n + i + 1..(i + 1) * n], &b[i + 1..]);
    }
    for (j, &p) in pivots[..n].iter().enumerate().rev() {
        b.swap(p, j);
    }
}

/// Solves `A X = B` for `k` right-hand sides at once with the factors from
/// [`lu_factor_packed`]: `b` holds `B` row-major (`n × k`, row i at `i·k`) and becomes `X`.
/// Both substitutions are taken in dot-product form, two rows at a time, on blocks of up to
/// 16 right-hand sides: `x_i = b_i − Σ_{j<i} L_ij x_j`, then
/// `x_i = (y_i − Σ_{j>i} U_ij x_j) / U_ii`, each block of a row summed in registers and
/// stored once (an update row by row would load and store it at every `j`); zero entries of
/// the factor are skipped. Compiled also for AVX2 with fused multiply-adds and for AVX,
/// chosen at run time (as [`mul_into`]'s kernel; the last bits then depend on the CPU).
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
pub fn lu_solve_packed_rows(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64], k: usize) {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        solve_rows::<true>(a, n, pivots, b, k);
    } else {
        solve_rows::<false>(a, n, pivots, b, k);
    }
}

/// [`lu_solve_packed_rows`] with fused multiply-adds or without (both tested on any CPU).
#[inline(always)]
fn solve_rows<const FUSED: bool>(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64], k: usize) {
    let b = interchange_rows(pivots, n, b, k);
    let a = &a[..n * n];
    for (c0, width) in blocks(k) {
        let terms = &mut InFactor { a, n };
        match width {
            BLOCK => substitute::<BLOCK, FUSED>(a, n, terms, b, (k, c0)),
            4 => substitute::<4, FUSED>(a, n, terms, b, (k, c0)),
            _ => substitute::<1, FUSED>(a, n, terms, b, (k, c0)),
        }
    }
}

/// The factorisation's row interchanges applied in order to the `n × k` row-major `b`;
/// returns `b`'s `n × k` part.
#[inline(always)]
fn interchange_rows<'b>(pivots: &[usize], n: usize, b: &'b mut [f64], k: usize) -> &'b mut [f64] {
    let b = &mut b[..n * k];
    for (j, &p) in pivots[..n].iter().enumerate() {
        if p != j {
            for c in 0..k {
                b.swap(p * k + c, j * k + c);
            }
        }
    }
    b
}

/// Right-hand sides summed in registers at once by the row kernels (four AVX vectors).
const BLOCK: usize = 16;

/// `0..k` in blocks of [`BLOCK`], then 4, then 1: `(start, width)`. (The kernels call their
/// blocks from their own bodies: a closure would not inherit their target features.)
fn blocks(k: usize) -> impl Iterator<Item = (usize, usize)> {
    let width = move |c0: usize| match k - c0 {
        w if w >= BLOCK => BLOCK,
        w if w >= 4 => 4,
        _ => 1,
    };
    std::iter::successors((k > 0).then(|| (0, width(0))), move |&(c0, w)| {
        (c0 + w < k).then(|| (c0 + w, width(c0 + w)))
    })
}

/// Entries `c0..c0 + W` of a row.
#[inline(always)]
fn block<const W: usize>(row: &[f64], c0: usize) -> [f64; W] {
    row[c0..c0 + W].try_into().expect("a block of the row")
}

/// `acc −= s x` (one rounding per entry when `FUSED`).
#[inline(always)]
fn subtract_scaled<const W: usize, const FUSED: bool>(acc: &mut [f64; W], s: f64, x: &[f64]) {
    let x: &[f64; W] = x.try_into().expect("a block of the row");
    for (o, &v) in acc.iter_mut().zip(x) {
        *o = if FUSED {
            (-s).mul_add(v, *o)
        } else {
            *o - s * v
        };
    }
}

/// `(acc₀, acc₁) −= (s₀ x, s₁ x)`: two rows' blocks updated from one load of `x`.
#[inline(always)]
fn subtract_scaled_pair<const W: usize, const FUSED: bool>(
    acc: &mut [[f64; W]; 2],
    (s0, s1): (f64, f64),
    x: &[f64],
) {
    let x: &[f64; W] = x.try_into().expect("a block of the row");
    let [a0, a1] = acc;
    for ((o0, o1), &v) in a0.iter_mut().zip(a1.iter_mut()).zip(x) {
        if FUSED {
            *o0 = (-s0).mul_add(v, *o0);
            *o1 = (-s1).mul_add(v, *o1);
        } else {
            *o0 -= s0 * v;
            *o1 -= s1 * v;
        }
    }
}

/// Where the substitutions find the terms of a pair of rows: the factor itself, each entry
/// tested for zero ([`InFactor`]), or its non-zeros gathered beforehand
/// ([`CompactFactor`]). Either way each row sums its non-zero terms in the order of the
/// unknowns, so both give the same bits.
pub(crate) trait RowTerms {
    /// `acc −= (L or U)_{r, j} x_j` over the unknowns `js` for the `rows` `(r0, r1)` (a row
    /// alone is paired with itself), `x_j` the `columns` `(k, c0)`: `c0..c0 + W` of `b`'s row
    /// `j` (row-major, rows of `k`).
    fn subtract<const W: usize, const FUSED: bool>(
        &mut self,
        b: &[f64],
        columns: (usize, usize),
        acc: &mut [[f64; W]; 2],
        rows: (usize, usize),
        js: std::ops::Range<usize>,
    );
}

/// The factor's own entries, read as the substitutions go, zero pairs skipped.
struct InFactor<'a> {
    a: &'a [f64],
    n: usize,
}

impl RowTerms for InFactor<'_> {
    #[inline(always)]
    fn subtract<const W: usize, const FUSED: bool>(
        &mut self,
        b: &[f64],
        (k, c0): (usize, usize),
        acc: &mut [[f64; W]; 2],
        (r0, r1): (usize, usize),
        js: std::ops::Range<usize>,
    ) {
        let (a, n) = (self.a, self.n);
        for j in js {
            let (l0, l1) = (a[j * n + r0], a[j * n + r1]);
            if l0 != 0.0 || l1 != 0.0 {
                subtract_scaled_pair::<W, FUSED>(acc, (l0, l1), &b[j * k + c0..j * k + c0 + W]);
            }
        }
    }
}

/// The substitutions of [`lu_solve_packed_rows`] on columns `c0..c0 + W` of `b`, two rows at
/// a time: each loaded row of solved unknowns feeds both rows' sums, and the two sums are
/// independent chains of multiply-adds (one row's would wait on each addition). The terms
/// come from `terms`; the diagonal and the pair's own term from the factor `a`.
#[inline(always)]
fn substitute<const W: usize, const FUSED: bool>(
    a: &[f64],
    n: usize,
    terms: &mut impl RowTerms,
    b: &mut [f64],
    (k, c0): (usize, usize),
) {
    let at = |b: &[f64], r: usize| block::<W>(&b[r * k..], c0);
    let store = |b: &mut [f64], r: usize, x: &[f64; W]| {
        b[r * k + c0..r * k + c0 + W].copy_from_slice(x);
    };
    // L y = b (unit lower, L_ij = a[j n + i]): rows i and i + 1 over j < i, then row i + 1's
    // own term in y_i (an odd last row alone).
    let mut i = 0;
    while i < n {
        let next = (i + 1).min(n - 1);
        let mut acc = [at(b, i), at(b, next)];
        terms.subtract::<W, FUSED>(b, (k, c0), &mut acc, (i, next), 0..i);
        if next != i {
            let first = acc[0];
            subtract_scaled::<W, FUSED>(&mut acc[1], a[i * n + next], &first);
            store(b, next, &acc[1]);
        }
        store(b, i, &acc[0]);
        i += 2;
    }
    // U x = y (U_ij = a[j n + i], j ≥ i): rows hi and lo = hi − 1 over j > hi, hi divided by
    // its pivot, then row lo's own term in x_hi and its pivot (row 0 alone last for odd n).
    let mut i = n;
    while i > 0 {
        let hi = i - 1;
        let lo = hi.saturating_sub(1);
        let mut acc = [at(b, hi), at(b, lo)];
        terms.subtract::<W, FUSED>(b, (k, c0), &mut acc, (hi, lo), i..n);
        let inverse = 1.0 / a[hi * n + hi];
        acc[0].iter_mut().for_each(|x| *x *= inverse);
        if lo != hi {
            let first = acc[0];
            subtract_scaled::<W, FUSED>(&mut acc[1], a[hi * n + lo], &first);
            let inverse = 1.0 / a[lo * n + lo];
            acc[1].iter_mut().for_each(|x| *x *= inverse);
            store(b, lo, &acc[1]);
        }
        store(b, hi, &acc[0]);
        i = lo;
    }
}

/// `L y = b` (unit lower), then `U x = y`, on column-major factors, two columns a step:
/// each entry below (above) takes both columns' terms in one pass, in the order of a pass
/// per column (the same sums), so the loop runs, and the solved entries come back from
/// memory, half as often. `U`'s diagonal divides by its reciprocal, formed ahead of the
/// chain of substitutions (a division's latency would sit on it).
fn forward_backward(a: &[f64], n: usize, b: &mut [f64]) {
    let mut j = 0;
    while j + 1 < n {
        let (head, below) = b.split_at_mut(j + 2);
        let b0 = head[j];
        head[j + 1] -= a[j * n + j + 1] * b0;
        let b1 = head[j + 1];
        let l0 = &a[j * n + j + 2..(j + 1) * n];
        let l1 = &a[(j + 1) * n + j + 2..(j + 2) * n];
        for ((x, u), v) in below.iter_mut().zip(l0).zip(l1) {
            *x = *x - u * b0 - v * b1;
        }
        j += 2;
    }
    let mut j = n;
    while j >= 2 {
        let (hi, lo) = (j - 1, j - 2);
        let (r_hi, r_lo) = (1.0 / a[hi * n + hi], 1.0 / a[lo * n + lo]);
        let (above, rest) = b.split_at_mut(lo);
        let x1 = rest[1] * r_hi;
        rest[1] = x1;
        let x0 = (rest[0] - a[hi * n + lo] * x1) * r_lo;
        rest[0] = x0;
        let u1 = &a[hi * n..hi * n + lo];
        let u0 = &a[lo * n..lo * n + lo];
        for ((x, u), v) in above.iter_mut().zip(u1).zip(u0) {
            *x = *x - u * x1 - v * x0;
        }
        j -= 2;
    }
    if j == 1 {
        b[0] *= 1.0 / a[0];
    }
}

/// `max |x|` in four lanes (which the compiler vectorises); a NaN entry is skipped, as the
/// `f64::max` fold this replaces skipped it.
fn largest_magnitude(x: &[f64]) -> f64 {
    let mut lanes = [0.0f64; 4];
    let chunks = x.chunks_exact(4);
    let tail = chunks
        .remainder()
        .iter()
        .fold(0.0f64, |m, v| if v.abs() > m { v.abs() } else { m });
    for c in chunks {
        for l in 0..4 {
            let v = c[l].abs();
            lanes[l] = if v > lanes[l] { v } else { lanes[l] };
        }
    }
    lanes.iter().fold(tail, |m, &v| if v > m { v } else { m })
}

/// LU with partial pivoting on column-major storage; `swapped(j, p)` is told that row p was
/// swapped into row j. Columns are eliminated two at a time: the pair is factored, then each
/// trailing column takes both rank-one updates in one pass (one load and store of an entry
/// for two multiply-adds). Compiled also for AVX2 with fused multiply-adds and for AVX,
/// chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn lu_core_factor(
    a: &mut [f64],
    n: usize,
    threshold: f64,
    lost: f64,
    swapped: impl FnMut(usize, usize),
) -> Result<(), usize> {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        factor_with::<true>(a, n, threshold, lost, swapped)
    } else {
        factor_with::<false>(a, n, threshold, lost, swapped)
    }
}

/// A pivot at most this fraction of its column's largest entry is lost in rounding: the
/// matrix is singular there.
const LOST: f64 = 1e-14;

/// Solves `S y = b` for symmetric positive semi-definite `S` (`n × n`, row-major in
/// `s[..n²]`, overwritten) whose rows may be linearly dependent — the Gram matrix `A M⁻¹ Aᵀ`
/// of redundant contact rows (eight corners of a box on the ground: 24 rows on 6 degrees of
/// freedom). Cholesky with diagonal pivoting: a pivot below `relative` times the largest
/// diagonal ends the factorisation, and the rows left are dependent on those taken; their
/// `y` is 0. For `b` in `S`'s range (`b = A v`) this `y` solves `S y = b` exactly, and
/// `Aᵀ y` is the unique projection. `order` (`n` long) receives the pivots' order; `b`
/// becomes `y`. Returns the rank.
pub(crate) fn semidefinite_solve(
    s: &mut [f64],
    n: usize,
    order: &mut [usize],
    b: &mut [f64],
    relative: f64,
) -> usize {
    let at = |i: usize, j: usize| i * n + j;
    for (k, o) in order[..n].iter_mut().enumerate() {
        *o = k;
    }
    let largest = (0..n).map(|i| s[at(i, i)]).fold(0.0, f64::max);
    let mut rank = 0;
    while rank < n {
        let k = rank;
        let p = (k..n)
            .max_by(|&a, &c| s[at(order[a], order[a])].total_cmp(&s[at(order[c], order[c])]))
            .expect("k < n");
        let i = order[p];
        let d = s[at(i, i)];
        if d.is_nan() || d <= relative * largest {
            break;
        }
        order.swap(k, p);
        let l = d.sqrt();
        s[at(i, i)] = l;
        for &j in &order[k + 1..n] {
            s[at(j, i)] /= l;
        }
        // Update the trailing block (its lower triangle and diagonal; row-major at (j, m)).
        for a in k + 1..n {
            let j = order[a];
            for &m in &order[k + 1..=a] {
                s[at(j, m)] -= s[at(j, i)] * s[at(m, i)];
                s[at(m, j)] = s[at(j, m)];
            }
        }
        rank += 1;
    }
    // L z = b on the pivots taken, then Lᵀ y = z; the dependent rows' y is 0.
    for k in 0..rank {
        let i = order[k];
        let sum: f64 = (0..k).map(|l| s[at(i, order[l])] * b[order[l]]).sum();
        b[i] = (b[i] - sum) / s[at(i, i)];
    }
    for &i in &order[rank..n] {
        b[i] = 0.0;
    }
    for k in (0..rank).rev() {
        let i = order[k];
        let sum: f64 = (k + 1..rank)
            .map(|l| s[at(order[l], i)] * b[order[l]])
            .sum();
        b[i] = (b[i] - sum) / s[at(i, i)];
    }
    rank
}

/// [`lu_factor_packed`] that refuses only a zero or non-finite pivot: for an interior
/// point's Newton matrix, ill-conditioned by design near the solution (an impulse and its
/// gap tending to zero together), whose direction is still accurate where it matters.
pub(crate) fn lu_factor_packed_unguarded(
    a: &mut [f64],
    n: usize,
    pivots: &mut [usize],
) -> Result<(), usize> {
    lu_core_factor(&mut a[..n * n], n, 1.0, 0.0, |j, p| pivots[j] = p)
}

/// [`lu_core_factor`] with fused multiply-adds or without (both tested on any CPU).
#[inline(always)]
fn factor_with<const FUSED: bool>(
    a: &mut [f64],
    n: usize,
    threshold: f64,
    lost: f64,
    mut swapped: impl FnMut(usize, usize),
) -> Result<(), usize> {
    let mut j = 0;
    while j < n {
        pivot_column(a, n, j, threshold, lost, &mut swapped)?;
        if j + 1 == n {
            break;
        }
        // Column j + 1 takes column j's update, then is factored itself.
        let (left, right) = a.split_at_mut((j + 1) * n);
        let m0 = &left[j * n + j + 1..(j + 1) * n];
        let next = &mut right[..n];
        let t0 = next[j];
        if t0 != 0.0 {
            for (x, m) in next[j + 1..].iter_mut().zip(m0) {
                *x -= m * t0;
            }
        }
        pivot_column(a, n, j + 1, threshold, lost, &mut swapped)?;
        // The trailing columns: entry j + 1 from entry j, then both updates below.
        let (left, right) = a.split_at_mut((j + 2) * n);
        let m0 = &left[j * n + j + 2..(j + 1) * n];
        let m01 = left[j * n + j + 1];
        let m1 = &left[(j + 1) * n + j + 2..(j + 2) * n];
        // Trailing columns two at a time while the entries below fill vectors (one load of
        // the multipliers for four updates), else (and the last) one at a time.
        let singles = if n - (j + 2) >= 8 {
            let mut pairs = right.chunks_exact_mut(2 * n);
            for pair in &mut pairs {
                let (c0, c1) = pair.split_at_mut(n);
                let (h0, b0) = c0.split_at_mut(j + 2);
                let (h1, b1) = c1.split_at_mut(j + 2);
                h0[j + 1] -= m01 * h0[j];
                h1[j + 1] -= m01 * h1[j];
                let (s0, s1, r0, r1) = (h0[j], h0[j + 1], h1[j], h1[j + 1]);
                if [s0, s1, r0, r1] == [0.0; 4] {
                    // Columns the pair does not reach (a sparse factor's): nothing to add.
                    continue;
                }
                for (((x, y), &u), &v) in b0.iter_mut().zip(b1.iter_mut()).zip(m0).zip(m1) {
                    if FUSED {
                        *x = (-v).mul_add(s1, (-u).mul_add(s0, *x));
                        *y = (-v).mul_add(r1, (-u).mul_add(r0, *y));
                    } else {
                        *x = *x - u * s0 - v * s1;
                        *y = *y - u * r0 - v * r1;
                    }
                }
            }
            pairs.into_remainder()
        } else {
            right
        };
        for col in singles.chunks_exact_mut(n) {
            let (head, below) = col.split_at_mut(j + 2);
            let t0 = head[j];
            head[j + 1] -= m01 * t0;
            let t1 = head[j + 1];
            if t0 != 0.0 || t1 != 0.0 {
                if FUSED {
                    for ((x, &u), &v) in below.iter_mut().zip(m0).zip(m1) {
                        *x = (-v).mul_add(t1, (-u).mul_add(t0, *x));
                    }
                } else {
                    for ((x, &u), &v) in below.iter_mut().zip(m0).zip(m1) {
                        *x = *x - u * t0 - v * t1;
                    }
                }
            }
        }
        j += 2;
    }
    Ok(())
}

/// Column `j` of [`lu_core_factor`], updated by every column before it: its pivot chosen and
/// judged, the rows swapped (whole rows), and the multipliers below the pivot formed.
#[inline(always)]
fn pivot_column(
    a: &mut [f64],
    n: usize,
    j: usize,
    threshold: f64,
    lost: f64,
    swapped: &mut impl FnMut(usize, usize),
) -> Result<(), usize> {
    // Pivot: the diagonal entry when it is within `threshold` of the largest at or below it
    // (a NaN there is kept, and refused below), else the first of the largest, found as the
    // largest magnitude, then where it is: two passes the compiler vectorises, where one
    // comparing as it goes waits on each comparison.
    let col = &a[j * n..(j + 1) * n];
    let largest_below = largest_magnitude(&col[j..]);
    let p = if col[j].is_nan() || col[j].abs() >= threshold * largest_below {
        j
    } else {
        (j..n).find(|&i| col[i].abs() == largest_below).unwrap_or(j)
    };
    let pivot = col[p];
    // Singular when the pivot is lost in the rounding of its own column (U's part above
    // included): relative per column, so an unknown in other units (a multiplier scaled by
    // Δt beside momenta over Δt) is not taken for a singular one.
    let scale = largest_magnitude(&col[..j])
        .max(largest_below)
        .max(f64::MIN_POSITIVE);
    if !pivot.is_finite() || pivot.abs() <= lost * scale {
        return Err(j);
    }
    swapped(j, p);
    if p != j {
        for c in 0..n {
            a.swap(c * n + p, c * n + j);
        }
    }
    let inverse = 1.0 / pivot;
    a[j * n + j + 1..(j + 1) * n]
        .iter_mut()
        .for_each(|x| *x *= inverse);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Redundant rows (24 rows of rank 6, as a box's eight frictional corners): the pivoted
    /// solve finds the rank, and its `y` solves `S y = b` for `b` in the range.
    #[test]
    fn a_semidefinite_gram_matrix_of_dependent_rows_is_solved_on_its_range() {
        let (r, n) = (24, 6);
        let base: Vec<f64> = (0..n * n)
            .map(|x| (x as f64 * 0.71).sin() + if x % 7 == 0 { 2.0 } else { 0.0 })
            .collect();
        // Row k of A: a combination of the n base rows.
        let a: Vec<f64> = (0..r * n)
            .map(|x| {
                let (k, j) = (x / n, x % n);
                (0..n)
                    .map(|b| (((k * n + b) * (k * n + b)) as f64 * 0.013).sin() * base[b * n + j])
                    .sum()
            })
            .collect();
        let gram = |i: usize, j: usize| (0..n).map(|c| a[i * n + c] * a[j * n + c]).sum::<f64>();
        let s0: Vec<f64> = (0..r * r).map(|x| gram(x / r, x % r)).collect();
        let v: Vec<f64> = (0..n).map(|j| 1.0 + j as f64).collect();
        let b0: Vec<f64> = (0..r)
            .map(|i| (0..n).map(|c| a[i * n + c] * v[c]).sum())
            .collect();
        let (mut s, mut y, mut order) = (s0.clone(), b0.clone(), vec![0; r]);
        assert_eq!(semidefinite_solve(&mut s, r, &mut order, &mut y, 1e-10), n);
        let scale = b0.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for i in 0..r {
            let sy: f64 = (0..r).map(|j| s0[i * r + j] * y[j]).sum();
            assert!(
                (sy - b0[i]).abs() < 1e-9 * scale,
                "row {i}: {sy} against {}",
                b0[i]
            );
        }
    }

    /// Forward substitution for several sides at once solves `L y = b` for each (to the
    /// rounding of one multiplication by the pivot's inverse in place of a division).
    #[test]
    fn forward_substitution_of_many_sides_solves_each() {
        let n = 7;
        let mut a: Vec<f64> = (0..n * n)
            .map(|x| ((x * x) as f64 * 0.37).cos() * 0.3)
            .collect();
        for i in 0..n {
            a[i * n + i] += 3.0 + i as f64;
        }
        let spd: Vec<f64> = (0..n * n)
            .map(|x| {
                (0..n)
                    .map(|k| a[(x / n) * n + k] * a[(x % n) * n + k])
                    .sum()
            })
            .collect();
        let mut l = spd.clone();
        cholesky_factor_packed(&mut l, n).expect("positive definite");
        let k = 5;
        let b: Vec<f64> = (0..k * n).map(|x| (x as f64 * 1.3).sin()).collect();
        let mut many = b.clone();
        cholesky_forward_many(&l, n, &mut many, k);
        for side in 0..k {
            let mut one = b[side * n..(side + 1) * n].to_vec();
            cholesky_forward(&l, n, &mut one);
            for (x, y) in one.iter().zip(&many[side * n..(side + 1) * n]) {
                assert!((x - y).abs() <= 1e-14 * x.abs().max(1.0), "{x} against {y}");
            }
        }
    }

    /// The Cholesky solve by rows gives, bit for bit, what one solve per right-hand side
    /// gives, and `A X = B` holds.
    #[test]
    fn cholesky_by_rows_equals_one_solve_each() {
        let (n, w) = (5, 7);
        let m: Vec<f64> = (0..n * n).map(|x| (x as f64 * 0.37).sin()).collect();
        // A = M Mᵀ + n I, symmetric positive definite.
        let a: Vec<f64> = (0..n * n)
            .map(|x| {
                let (i, j) = (x % n, x / n);
                let s: f64 = (0..n).map(|k| m[k * n + i] * m[k * n + j]).sum();
                s + if i == j { n as f64 } else { 0.0 }
            })
            .collect();
        let mut factor = a.clone();
        cholesky_factor_packed(&mut factor, n).unwrap();
        let b: Vec<f64> = (0..n * w).map(|x| (x as f64 * 0.91).cos()).collect();
        let mut rows = b.clone();
        cholesky_solve_rows(&factor, n, &mut rows, w);
        for c in 0..w {
            let mut x: Vec<f64> = (0..n).map(|r| b[r * w + c]).collect();
            cholesky_forward(&factor, n, &mut x);
            cholesky_backward(&factor, n, &mut x);
            for r in 0..n {
                assert_eq!(rows[r * w + c], x[r], "column {c}, row {r}");
                let ax: f64 = (0..n).map(|k| a[k * n + r] * rows[k * w + c]).sum();
                assert!((ax - b[r * w + c]).abs() < 1e-13);
            }
        }
    }

    /// A test matrix of order `n` with zeros scattered through it and a zero first entry, so
    /// that pivots are swapped and the kernels' zero skips are taken.
    pub(super) fn scattered(n: usize) -> Vec<f64> {
        (0..n * n)
            .map(|k| {
                let diagonal = k % (n + 1) == 0;
                if (k == 0 && n > 1) || (k % 5 == 3 && !diagonal) {
                    0.0
                } else {
                    ((k * 7 % 11) as f64 - 5.0) / 3.0 + diagonal as u8 as f64 * 6.0
                }
            })
            .collect()
    }

    /// Several right-hand sides at once give what one solve each gives, and `A X = B` holds,
    /// for orders odd and even (the substitutions take rows in pairs) and widths that leave
    /// every block size of the kernels (16, 4, 1); `P A = L U` holds for the factors. Both
    /// roundings (with fused multiply-adds and without) are run, whatever this CPU has.
    #[test]
    fn many_right_hand_sides_solve_as_one_each() {
        many_right_hand_sides::<false>();
        many_right_hand_sides::<true>();
        // The dispatched kernels too.
        let n = 7;
        let a = scattered(n);
        let (mut factor, mut pivots) = (a.clone(), vec![0; n]);
        lu_factor_packed(&mut factor, n, &mut pivots).expect("regular");
        let b: Vec<f64> = (0..n * 21).map(|i| (i as f64).cos()).collect();
        let mut x = b.clone();
        lu_solve_packed_rows(&factor, n, &pivots, &mut x, 21);
        for (r, c) in (0..n).flat_map(|r| (0..21).map(move |c| (r, c))) {
            let ax: f64 = (0..n).map(|j| a[j * n + r] * x[j * 21 + c]).sum();
            assert!((ax - b[r * 21 + c]).abs() < 1e-11, "residual at ({r}, {c})");
        }
    }

    fn many_right_hand_sides<const FUSED: bool>() {
        for n in [1, 2, 5, 8, 19] {
            let a = scattered(n);
            let (mut factor, mut pivots) = (a.clone(), vec![0; n]);
            factor_with::<FUSED>(&mut factor, n, 1.0, LOST, |j, p| pivots[j] = p).expect("regular");
            if n > 1 {
                assert_ne!(pivots[0], 0, "the first pivot is swapped");
            }
            // P A = L U: apply the interchanges to A's rows in order, compare with L U.
            let mut pa = a.clone();
            for (j, &p) in pivots.iter().enumerate() {
                for c in 0..n {
                    pa.swap(c * n + p, c * n + j);
                }
            }
            for r in 0..n {
                for c in 0..n {
                    let lu: f64 = (0..=r.min(c))
                        .map(|k| {
                            let l = if k == r { 1.0 } else { factor[k * n + r] };
                            l * factor[c * n + k]
                        })
                        .sum();
                    assert!(
                        (lu - pa[c * n + r]).abs() < 1e-12,
                        "P A = L U at ({r}, {c})"
                    );
                }
            }
            for k in [1, 3, 7, 21, 37] {
                let b: Vec<f64> = (0..n * k).map(|i| (i as f64).sin()).collect();
                let mut x = b.clone();
                solve_rows::<FUSED>(&factor, n, &pivots, &mut x, k);
                for c in 0..k {
                    let mut one: Vec<f64> = (0..n).map(|r| b[r * k + c]).collect();
                    lu_solve_packed(&factor, n, &pivots, &mut one);
                    for r in 0..n {
                        let at = format!("fused {FUSED}, n {n}, k {k}, column {c}, row {r}");
                        assert!((x[r * k + c] - one[r]).abs() < 1e-12, "{at}");
                        // A (column-major) times x's column c gives b's.
                        let ax: f64 = (0..n).map(|j| a[j * n + r] * x[j * k + c]).sum();
                        assert!((ax - b[r * k + c]).abs() < 1e-11, "residual at {at}");
                    }
                }
            }
        }
    }

    /// The pivot is the first of the largest entries at or below the diagonal (a NaN below
    /// is passed over); a NaN on the diagonal, or a pivot lost in its column's rounding, is
    /// refused with its column.
    #[test]
    fn pivots_are_the_first_largest_and_bad_ones_are_refused() {
        // Column 0 (column-major): 1, −3, 3, NaN: rows 1 and 2 tie; row 1 comes first.
        let mut a = vec![
            1.0,
            -3.0,
            3.0,
            f64::NAN,
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0,
        ];
        let mut pivots = vec![0; 4];
        // The NaN stays in L's first column (the columns after it have zeros in the pivot
        // row), so the factorisation goes through; its first pivot is row 1.
        assert_eq!(lu_factor_packed(&mut a, 4, &mut pivots), Ok(()));
        assert_eq!(pivots[0], 1, "the first of the two largest");
        let mut nan_diagonal = vec![f64::NAN, 5.0, 1.0, 1.0];
        assert_eq!(lu_factor_packed(&mut nan_diagonal, 2, &mut pivots), Err(0));
        // A second column that is the first's times (1 + 1e-16): its pivot is rounding.
        let mut rounding = vec![1.0, 2.0, 1.0 + 1e-16, 2.0 + 2e-16];
        assert_eq!(lu_factor_packed(&mut rounding, 2, &mut pivots), Err(1));
    }

    /// Threshold pivoting keeps a diagonal within the threshold of the largest below it and
    /// swaps one under it (for the first of the largest); `P A = L U` either way, each
    /// multiplier at most 1/threshold; threshold 1 is partial pivoting.
    #[test]
    fn threshold_pivoting_keeps_the_diagonal_within_the_threshold() {
        // Column 0: 0.5 on the diagonal against 4 below (within 0.1 of it); column 1's
        // diagonal, once updated, is 0.001 against 1 below (outside 0.1, within 0.0001).
        let a = [0.5, 4.0, 1.0, 1.0, 8.001, 3.0, 2.0, 1.0, 5.0];
        let n = 3;
        for (threshold, want) in [(0.1, [0, 2, 2]), (1.0, [1, 2, 2]), (0.0001, [0, 1, 2])] {
            let (mut factor, mut pivots) = (a.to_vec(), vec![0; n]);
            lu_factor_packed_threshold(&mut factor, n, &mut pivots, threshold).expect("regular");
            assert_eq!(pivots, want, "threshold {threshold}");
            let mut pa = a.to_vec();
            for (j, &p) in pivots.iter().enumerate() {
                for c in 0..n {
                    pa.swap(c * n + p, c * n + j);
                }
            }
            for (r, c) in (0..n).flat_map(|r| (0..n).map(move |c| (r, c))) {
                let l = |k: usize| if k == r { 1.0 } else { factor[k * n + r] };
                let lu: f64 = (0..=r.min(c)).map(|k| l(k) * factor[c * n + k]).sum();
                assert!(
                    (lu - pa[c * n + r]).abs() < 1e-12,
                    "{threshold}: ({r}, {c})"
                );
                if r > c {
                    assert!(factor[c * n + r].abs() <= 1.0 / threshold + 1e-12);
                }
            }
        }
        let (mut partial, mut pivots) = (a.to_vec(), vec![0; n]);
        lu_factor_packed(&mut partial, n, &mut pivots).expect("regular");
        let mut threshold_one = a.to_vec();
        lu_factor_packed_threshold(&mut threshold_one, n, &mut pivots, 1.0).expect("regular");
        assert_eq!(partial, threshold_one);
    }

    /// The four-sum dot product equals the sum written out at every length (whole chunks,
    /// tails, empty).
    #[test]
    fn dot_products_in_four_sums() {
        for len in 0..11 {
            let a: Vec<f64> = (0..len).map(|i| (i as f64 * 0.7).sin()).collect();
            let b: Vec<f64> = (0..len).map(|i| 1.0 + i as f64 * 0.3).collect();
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert!((dot(&a, &b) - plain).abs() < 1e-14, "length {len}");
        }
    }

    /// The transposed solve with `A`'s factors solves `Aᵀ x = b`, for orders with row
    /// interchanges (the scattered matrices swap their first pivot) and without.
    #[test]
    fn transposed_solve_uses_the_factors_of_a() {
        for n in [1, 2, 5, 8, 19] {
            let a = scattered(n);
            let (mut factor, mut pivots) = (a.clone(), vec![0; n]);
            lu_factor_packed(&mut factor, n, &mut pivots).expect("regular");
            let b: Vec<f64> = (0..n).map(|i| (1.0 + i as f64).ln() - 0.4).collect();
            let mut x = b.clone();
            lu_solve_transposed_packed(&factor, n, &pivots, &mut x);
            for (r, &br) in b.iter().enumerate() {
                // Row r of Aᵀ is column r of A.
                let atx: f64 = (0..n).map(|j| a[r * n + j] * x[j]).sum();
                assert!(
                    (atx - br).abs() < 1e-12,
                    "order {n}, row {r}: {atx} against {br}"
                );
            }
        }
    }

    /// `largest_magnitude` finds the largest entry wherever it sits (any length, NaN skipped).
    #[test]
    fn largest_magnitude_anywhere() {
        for len in 1..11 {
            for at in 0..len {
                let mut x: Vec<f64> = (0..len).map(|i| 0.1 * i as f64).collect();
                x[at] = -7.0;
                if at + 1 < len {
                    x[at + 1] = f64::NAN;
                }
                assert_eq!(largest_magnitude(&x), 7.0, "length {len}, at {at}");
            }
        }
    }
}
