//! An LU factor's non-zero entries gathered in the order the many-right-hand-side solve
//! reads them, so a sparse factor (a tree's, eliminated leaves first) costs its non-zeros
//! and no branch per entry.
//!
//! [`lu_solve_packed_rows`](super::lu_solve_packed_rows) sums each pair of rows over the
//! solved unknowns before them (forward) or after them (backward) and skips the unknowns
//! where both rows' coefficients are zero — a test per entry, per block of right-hand sides,
//! whose outcome the branch predictor learns badly when half the factor is zero.
//! [`CompactFactor`] makes those lists once per factorisation; [`lu_solve_compact_rows`]
//! then takes the same terms in the same order (so the same bits) with no test at all.
//! [`CompactCombination`] and [`combine_compact_rows`] do the same for a product `C −= A D`
//! (the step derivatives' `P_z·dz/dx`).

use super::{block, blocks, interchange_rows, substitute, subtract_scaled_pair, RowTerms, BLOCK};

/// One term of a pair of rows: the unknown `j` and the two rows' coefficients on it.
type Term = (usize, [f64; 2]);

/// The non-zero terms of a sequence of row pairs, each pair's ending at its `ends` entry.
/// A term is written whether or not it is zero and kept by counting it (no branch to
/// mispredict); `terms` grows to the most terms gathered and stays.
#[derive(Clone, Debug, Default)]
struct Pairs {
    terms: Vec<Term>,
    kept: usize,
    ends: Vec<usize>,
}

impl Pairs {
    /// Empties the pairs, with room for `most` terms.
    fn clear(&mut self, most: usize) {
        if self.terms.len() < most {
            self.terms.resize(most, (0, [0.0; 2]));
        }
        self.kept = 0;
        self.ends.clear();
    }

    /// Adds a pair: the terms `(j, coefficients(j))` for `j` in `js`, but those with both
    /// coefficients zero. The count is kept in a register (in `self` it would be stored and
    /// reloaded at each term, on the loop's critical path).
    #[inline(always)]
    fn pair(&mut self, js: std::ops::Range<usize>, coefficients: impl Fn(usize) -> [f64; 2]) {
        let mut kept = self.kept;
        let terms = &mut self.terms[..];
        for j in js {
            let l = coefficients(j);
            terms[kept] = (j, l);
            kept += usize::from((l[0] != 0.0) | (l[1] != 0.0));
        }
        self.kept = kept;
        self.ends.push(kept);
    }

    /// The pairs' terms, one slice after another in order.
    fn spans(&self) -> impl Iterator<Item = &[Term]> {
        let starts = std::iter::once(0).chain(self.ends.iter().copied());
        starts
            .zip(&self.ends)
            .map(|(from, &end)| &self.terms[from..end])
    }
}

/// The off-diagonal non-zeros of an `n × n` LU factor by row pair, in the order the
/// substitutions take them: forward, rows `(0, 1), (2, 3), …` over `j < i`; backward, rows
/// `(n−1, n−2), (n−3, n−4), …` over `j > i` (an odd last row paired with itself). The pairs
/// fall within the blocks of a tree's leaves-first order (four variables to a limb), so their
/// union of non-zeros is little more than each row's. Buffers grow to the largest factor
/// gathered and are reused.
#[derive(Clone, Debug, Default)]
pub(crate) struct CompactFactor {
    n: usize,
    pairs: Pairs,
}

impl CompactFactor {
    /// Gathers the non-zeros of the factor in `a[..n²]` (column-major, from
    /// [`lu_factor_packed`](super::lu_factor_packed) or its threshold form).
    pub fn gather(&mut self, a: &[f64], n: usize) {
        self.n = n;
        let (a, pairs) = (&a[..n * n], &mut self.pairs);
        pairs.clear(n * n);
        // Rows r0 and r1 over the unknowns `js` (a row alone paired with itself), in the
        // order of the substitutions.
        let two = |r0: usize, r1: usize| move |j: usize| [a[j * n + r0], a[j * n + r1]];
        let mut i = 0;
        while i < n {
            pairs.pair(0..i, two(i, (i + 1).min(n - 1)));
            i += 2;
        }
        let mut i = n;
        while i > 0 {
            let (hi, lo) = (i - 1, (i - 1).saturating_sub(1));
            pairs.pair(i..n, two(hi, lo));
            i = lo;
        }
    }

    /// The share of the factor's off-diagonal entries gathered (about 1 for a dense factor).
    #[cfg(test)]
    fn density(&self) -> f64 {
        let off = self.n * self.n.saturating_sub(1);
        self.pairs.kept as f64 / (off / 2).max(1) as f64
    }
}

/// [`lu_solve_packed_rows`](super::lu_solve_packed_rows) with the factor's non-zeros
/// gathered in `compact` (from the same `a`): the same operations in the same order, so
/// the same result to the bit, without testing each entry for zero. `b` holds the
/// right-hand sides row-major (`n × k`) and becomes the solutions.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
pub(crate) fn lu_solve_compact_rows(
    a: &[f64],
    n: usize,
    pivots: &[usize],
    compact: &CompactFactor,
    b: &mut [f64],
    k: usize,
) {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        solve_compact::<true>(a, n, pivots, compact, b, k);
    } else {
        solve_compact::<false>(a, n, pivots, compact, b, k);
    }
}

/// [`lu_solve_compact_rows`] with fused multiply-adds or without.
#[inline(always)]
fn solve_compact<const FUSED: bool>(
    a: &[f64],
    n: usize,
    pivots: &[usize],
    compact: &CompactFactor,
    b: &mut [f64],
    k: usize,
) {
    assert_eq!(compact.n, n, "the compact factor is of this factor");
    let b = interchange_rows(pivots, n, b, k);
    let a = &a[..n * n];
    for (c0, width) in blocks(k) {
        let terms = &mut Gathered {
            spans: compact.pairs.spans(),
        };
        match width {
            BLOCK => substitute::<BLOCK, FUSED>(a, n, terms, b, (k, c0)),
            4 => substitute::<4, FUSED>(a, n, terms, b, (k, c0)),
            _ => substitute::<1, FUSED>(a, n, terms, b, (k, c0)),
        }
    }
}

/// A compact factor's pairs of rows, read in the substitutions' order (one pass per block of
/// right-hand sides).
struct Gathered<'a, I: Iterator<Item = &'a [Term]>> {
    spans: I,
}

impl<'a, I: Iterator<Item = &'a [Term]>> RowTerms for Gathered<'a, I> {
    #[inline(always)]
    fn subtract<const W: usize, const FUSED: bool>(
        &mut self,
        b: &[f64],
        (k, c0): (usize, usize),
        acc: &mut [[f64; W]; 2],
        _: (usize, usize),
        _: std::ops::Range<usize>,
    ) {
        for &(j, l) in self.spans.next().expect("a pair of the factor") {
            subtract_scaled_pair::<W, FUSED>(acc, (l[0], l[1]), &b[j * k + c0..j * k + c0 + W]);
        }
    }
}

/// `A`'s non-zeros for [`combine_compact_rows`], by pairs of rows `(0, 1), (2, 3), …` (an
/// odd last row paired with itself), each over the rows of `D` in order, gathered once per
/// `A`.
#[derive(Clone, Debug, Default)]
pub(crate) struct CompactCombination {
    rows: usize,
    pairs: Pairs,
}

impl CompactCombination {
    /// Gathers `A` (`rows` rows), whose row `r` is row `r` of the row-major `a` (rows of
    /// `w`) read at the columns `cols` (column `s` of `A` is `a`'s column `cols[s]`).
    pub fn gather(&mut self, rows: usize, a: &[f64], w: usize, cols: &[usize]) {
        self.rows = rows;
        let pairs = &mut self.pairs;
        pairs.clear(rows.div_ceil(2) * cols.len());
        // A last row alone is paired with itself.
        for r in (0..rows).step_by(2) {
            let row = &a[r * w..(r + 1) * w];
            let next = &a[(r + 1).min(rows - 1) * w..][..w];
            pairs.pair(0..cols.len(), |s| [row[cols[s]], next[cols[s]]]);
        }
    }
}

/// `C −= A D` for row-major `C` (rows of `k`) and `D` (row `s` at `s·k`) with `A`'s
/// non-zeros gathered in `compact`: two rows of `C` at a time, each block of both summing its
/// combination of `D`'s rows in registers (one load of `D` for both), `D`'s rows in order.
/// Compiled also for AVX2 with fused multiply-adds and for AVX, chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
pub(crate) fn combine_compact_rows(
    c: &mut [f64],
    k: usize,
    compact: &CompactCombination,
    d: &[f64],
) {
    if multiversion::target::target_cfg_f!(target_feature = "fma") {
        combine_compact::<true>(c, k, compact, d);
    } else {
        combine_compact::<false>(c, k, compact, d);
    }
}

/// [`combine_compact_rows`] with fused multiply-adds or without.
#[inline(always)]
fn combine_compact<const FUSED: bool>(
    c: &mut [f64],
    k: usize,
    compact: &CompactCombination,
    d: &[f64],
) {
    let rows = compact.rows;
    for (r, span) in (0..rows).step_by(2).zip(compact.pairs.spans()) {
        // A last row alone is its own pair (computed twice, stored once).
        let pair = (r, (r + 1).min(rows - 1));
        for (c0, width) in blocks(k) {
            match width {
                BLOCK => combine_pair::<BLOCK, FUSED>(c, pair, span, d, k, c0),
                4 => combine_pair::<4, FUSED>(c, pair, span, d, k, c0),
                _ => combine_pair::<1, FUSED>(c, pair, span, d, k, c0),
            }
        }
    }
}

/// Columns `c0..c0 + W` of rows `r0`, `r1` of [`combine_compact_rows`].
#[inline(always)]
fn combine_pair<const W: usize, const FUSED: bool>(
    c: &mut [f64],
    (r0, r1): (usize, usize),
    span: &[Term],
    d: &[f64],
    k: usize,
    c0: usize,
) {
    let mut acc = [block::<W>(&c[r0 * k..], c0), block::<W>(&c[r1 * k..], c0)];
    for &(s, x) in span {
        subtract_scaled_pair::<W, FUSED>(&mut acc, (x[0], x[1]), &d[s * k + c0..s * k + c0 + W]);
    }
    c[r1 * k + c0..r1 * k + c0 + W].copy_from_slice(&acc[1]);
    c[r0 * k + c0..r0 * k + c0 + W].copy_from_slice(&acc[0]);
}

#[cfg(test)]
mod tests {
    use super::super::{lu_factor_packed, lu_factor_packed_threshold, solve_rows};
    use super::*;

    /// A tree's matrix, leaves first: three 4 × 4 blocks each coupled to the last 4 rows and
    /// columns (a floating base), the rest zero; the base's rows heavier in the blocks'
    /// columns than the blocks' diagonals, so that partial pivoting swaps them up.
    fn arrow() -> (Vec<f64>, usize) {
        let n = 16;
        let base = |i: usize| i >= 12;
        let a = (0..n * n)
            .map(|at| {
                let (i, j) = (at % n, at / n);
                let coupled = base(i) || base(j) || i / 4 == j / 4;
                let diagonal = if i == j {
                    2.0 + 38.0 * base(i) as u8 as f64
                } else {
                    0.0
                };
                let heavy = if base(i) && !base(j) { 6.0 } else { 1.0 };
                let x = heavy * (((i * 5 + j * 3) % 7) as f64 * 0.3 - 0.7) + diagonal;
                coupled as u8 as f64 * x
            })
            .collect();
        (a, n)
    }

    /// The compact solve gives the dense kernel's bits (both roundings and the dispatched
    /// one), for partial and threshold pivoting, on the arrow matrix and a denser one; the
    /// threshold keeps the arrow's zeros (partial pivoting fills them).
    #[test]
    fn the_compact_solve_is_the_dense_one_to_the_bit() {
        let (arrow, n) = arrow();
        let dense = super::super::tests::scattered(n);
        for (name, a) in [("arrow", &arrow), ("dense", &dense)] {
            let mut kept = Vec::new();
            for threshold in [1.0, 0.1] {
                let (mut factor, mut pivots) = (a.clone(), vec![0; n]);
                lu_factor_packed_threshold(&mut factor, n, &mut pivots, threshold)
                    .expect("regular");
                let mut compact = CompactFactor::default();
                compact.gather(&factor, n);
                kept.push(compact.density());
                for k in [1, 3, 7, 21, 37] {
                    let b: Vec<f64> = (0..n * k).map(|i| (i as f64).sin()).collect();
                    let (mut x, mut y, mut z, mut w) = (b.clone(), b.clone(), b.clone(), b.clone());
                    solve_rows::<false>(&factor, n, &pivots, &mut x, k);
                    solve_compact::<false>(&factor, n, &pivots, &compact, &mut y, k);
                    solve_rows::<true>(&factor, n, &pivots, &mut z, k);
                    solve_compact::<true>(&factor, n, &pivots, &compact, &mut w, k);
                    let mut dispatched = b.clone();
                    lu_solve_compact_rows(&factor, n, &pivots, &compact, &mut dispatched, k);
                    assert_eq!(x, y, "{name}, {threshold}, k {k}");
                    assert_eq!(z, w, "{name}, {threshold}, k {k}");
                    assert!(dispatched == x || dispatched == z);
                    for (r, c) in (0..n).flat_map(|r| (0..k).map(move |c| (r, c))) {
                        let ax: f64 = (0..n).map(|j| a[j * n + r] * x[j * k + c]).sum();
                        assert!((ax - b[r * k + c]).abs() < 1e-11, "{name} ({r}, {c})");
                    }
                }
            }
            if name == "arrow" {
                // Partial pivoting fills the factor; the threshold keeps the tree's zeros.
                assert!(kept[1] < 0.6 && kept[1] < 0.8 * kept[0], "{kept:?}");
            }
        }
        // A compact factor of another size is refused.
        let (mut factor, mut pivots) = (dense.clone(), vec![0; n]);
        lu_factor_packed(&mut factor, n, &mut pivots).expect("regular");
        let mut small = CompactFactor::default();
        small.gather(&factor[..4], 2);
        let wrong = std::panic::catch_unwind(|| {
            let mut b = vec![1.0; n];
            lu_solve_compact_rows(&factor, n, &pivots, &small, &mut b, 1);
        });
        assert!(wrong.is_err());
    }

    /// The compact combination is `C − A D` (both roundings and the dispatched kernel), an
    /// odd last row and zero coefficients (left out) included; the two roundings differ only
    /// in the last bits.
    #[test]
    fn the_compact_combination_subtracts_the_product() {
        for rows in 1..6 {
            for k in [1, 5, 21, 37] {
                let w = 7;
                let a: Vec<f64> = (0..rows * w)
                    .map(|x| {
                        if x % 3 == 1 {
                            0.0
                        } else {
                            (x as f64 * 0.7).sin()
                        }
                    })
                    .collect();
                let d: Vec<f64> = (0..4 * k).map(|x| (x as f64 * 1.3).cos()).collect();
                let cols = [4, 0, 6, 2];
                let start: Vec<f64> = (0..rows * k).map(|x| x as f64).collect();
                let mut compact = CompactCombination::default();
                compact.gather(rows, &a, w, &cols);
                let (mut unfused, mut fused, mut dispatched) =
                    (start.clone(), start.clone(), start.clone());
                combine_compact::<false>(&mut unfused, k, &compact, &d);
                combine_compact::<true>(&mut fused, k, &compact, &d);
                combine_compact_rows(&mut dispatched, k, &compact, &d);
                assert!(dispatched == fused || dispatched == unfused);
                for r in 0..rows {
                    for j in 0..k {
                        let sum: f64 = (0..4).map(|s| a[r * w + cols[s]] * d[s * k + j]).sum();
                        for c in [&unfused, &fused] {
                            let got = start[r * k + j] - c[r * k + j];
                            assert!((got - sum).abs() < 1e-13, "rows {rows}, k {k}, ({r}, {j})");
                        }
                    }
                }
            }
        }
    }
}
