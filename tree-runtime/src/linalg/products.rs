//! Dense products `C = A B + βC` and `C = AᵀB + βC` without allocation, for a control
//! problem's backward pass (`V_xx A`, `Aᵀ(V_xx A)`, `KᵀY`, a cost's `JᵀWJ`).
//!
//! Register-blocked, as in a BLAS: both factors are first copied into a [`Packing`], the
//! left in tiles of 8 rows and the right in blocks of 4 columns, each `k`-major, so that a
//! tile of `C` (8 × 4) sums over the shared dimension with its 32 running sums in eight
//! vector registers — per `k`, two loads of the left factor and four of the right feed 32
//! multiply-adds (an axpy loop loads and stores `C` at every step: the backward pass's
//! products ran several times slower so). Each tile sums only over the span of `k` where
//! both its packed factors are not zero, first to last: the step Jacobians' memory blocks
//! and a cost's unread entries cost nothing.
//!
//! Compiled also for AVX2 with fused multiply-adds and for AVX, chosen at run time
//! (`multiversion`); a fused sum rounds once per term, so the last bits depend on the CPU.

use nalgebra::DMatrix;

/// Rows of a tile of `C` (two four-wide vectors).
const ROWS: usize = 8;
/// Columns of a tile of `C`.
const COLS: usize = 4;

/// Both factors of a product copied tile by tile, so that the tile reads each contiguously:
/// the scratch of every product here. Grows to the largest product it has served, then
/// allocates no more.
#[derive(Clone, Debug, Default)]
pub struct Packing {
    /// The left factor in tiles of [`ROWS`] rows (zero-padded), each `p × ROWS`, `k`-major.
    left: Vec<f64>,
    /// Per tile of `left`, the span of the shared dimension where it is not zero.
    left_spans: Vec<Span>,
    /// The right factor in blocks of [`COLS`] columns (zero-padded), each `p × COLS`.
    right: Vec<f64>,
    /// Per block of `right`, its span.
    right_spans: Vec<Span>,
}

/// A half-open range `lo..hi` of the shared dimension (empty when `lo ≥ hi`).
type Span = (usize, usize);

/// Resizes `buffer` to `len` (allocating only to grow) and returns it.
fn fit(buffer: &mut Vec<f64>, len: usize) -> &mut [f64] {
    if buffer.len() < len {
        buffer.resize(len, 0.0);
    }
    &mut buffer[..len]
}

/// Which way the left factor is stored.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Left {
    /// `A` (m × p).
    Plain,
    /// `A` is given as its transpose (p × m).
    Transposed,
}

impl Packing {
    /// Copies the left factor (`m × p`, stored as `how` says) into tiles and finds their spans.
    fn pack_left(&mut self, a: &[f64], (m, p): (usize, usize), how: Left) {
        let packed = fit(&mut self.left, m.div_ceil(ROWS) * p * ROWS);
        self.left_spans.clear();
        for (t, tile) in packed.chunks_exact_mut(p * ROWS).enumerate() {
            let i0 = t * ROWS;
            match how {
                Left::Plain if i0 + ROWS <= m => {
                    for (row, column) in tile.chunks_exact_mut(ROWS).zip(a.chunks_exact(m)) {
                        row.copy_from_slice(&column[i0..i0 + ROWS]);
                    }
                }
                Left::Plain => {
                    for (row, column) in tile.chunks_exact_mut(ROWS).zip(a.chunks_exact(m)) {
                        for (r, x) in row.iter_mut().enumerate() {
                            *x = column.get(i0 + r).copied().unwrap_or(0.0);
                        }
                    }
                }
                // Entry (k, r) of the tile is entry k of the given A's column i0 + r.
                Left::Transposed => transpose_into::<ROWS>(tile, a, p, i0, m),
            }
            self.left_spans.push(nonzero_span(tile, ROWS));
        }
    }

    /// Copies the right factor (`p × n`, column-major) into blocks and finds their spans.
    fn pack_right(&mut self, b: &[f64], (p, n): (usize, usize)) {
        let packed = fit(&mut self.right, n.div_ceil(COLS) * p * COLS);
        self.right_spans.clear();
        for (t, block) in packed.chunks_exact_mut(p * COLS).enumerate() {
            transpose_into::<COLS>(block, b, p, t * COLS, n);
            self.right_spans.push(nonzero_span(block, COLS));
        }
    }
}

/// Entry `(k, w)` of `block` (`p` rows of `W`) set to entry `k` of column `first + w` of
/// `source` (columns of length `p`, `count` of them), zero past the last column. A block of
/// whole columns is written a row at a time, its `W` columns read side by side.
fn transpose_into<const W: usize>(
    block: &mut [f64],
    source: &[f64],
    p: usize,
    first: usize,
    count: usize,
) {
    if first + W <= count {
        let columns: [&[f64]; W] =
            std::array::from_fn(|w| &source[(first + w) * p..(first + w + 1) * p]);
        for (k, row) in block[..p * W].chunks_exact_mut(W).enumerate() {
            for (x, column) in row.iter_mut().zip(&columns) {
                *x = column[k];
            }
        }
        return;
    }
    for w in 0..W {
        let rows = block.chunks_exact_mut(W);
        if first + w < count {
            let column = &source[(first + w) * p..(first + w + 1) * p];
            rows.zip(column).for_each(|(row, &x)| row[w] = x);
        } else {
            rows.for_each(|row| row[w] = 0.0);
        }
    }
}

/// The rows of `packed` (rows of `width` entries) with a non-zero entry, first to last
/// (`(0, 0)` when all are zero).
fn nonzero_span(packed: &[f64], width: usize) -> Span {
    let nonzero = |row: &[f64]| row.iter().any(|&v| v != 0.0);
    match packed.chunks_exact(width).position(nonzero) {
        None => (0, 0),
        Some(lo) => (
            lo,
            packed
                .chunks_exact(width)
                .rposition(nonzero)
                .map_or(lo, |r| r + 1),
        ),
    }
}

/// `C = A B + β C` for column-major dense matrices (`C` m × n, `A` m × p, `B` p × n). `β = 0`
/// overwrites `C` (whatever it held, NaN included).
pub fn mul_into(
    c: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    packing: &mut Packing,
) {
    let (m, n, p) = (a.nrows(), b.ncols(), a.ncols());
    assert!(
        b.nrows() == p && c.nrows() == m && c.ncols() == n,
        "mul_into: shapes"
    );
    product(c, b, beta, packing, false, |packing| {
        packing.pack_left(a.as_slice(), (m, p), Left::Plain)
    });
}

/// `C = Aᵀ B + β C` (`C` m × n, `A` p × m, `B` p × n).
pub fn tr_mul_into(
    c: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    packing: &mut Packing,
) {
    tr_mul(c, a, b, beta, packing, false);
}

/// [`tr_mul_into`] for a product known to be symmetric (`C` and `AᵀB` both symmetric, as
/// `AᵀWA` with `B = WA`): the tiles on and above the diagonal computed, the lower triangle
/// mirrored from the upper — about half the work.
pub fn tr_mul_into_symmetric(
    c: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    packing: &mut Packing,
) {
    tr_mul(c, a, b, beta, packing, true);
    mirror_upper(c);
}

/// The lower triangle of the square `c` set from its upper one.
fn mirror_upper(c: &mut DMatrix<f64>) {
    let m = c.nrows();
    let c = c.as_mut_slice();
    for j in 0..m {
        for i in j + 1..m {
            c[j * m + i] = c[i * m + j];
        }
    }
}

/// `C₁ = A B₁` and `C₂ = A B₂` (each overwritten), `A` packed once for both: the backward
/// pass's `V_xx A` and `V_xx B`. The same sums as two [`mul_into`] calls with `β = 0`.
pub fn mul_into_pair(
    [c1, c2]: [&mut DMatrix<f64>; 2],
    a: &DMatrix<f64>,
    [b1, b2]: [&DMatrix<f64>; 2],
    packing: &mut Packing,
) {
    let (m, p) = a.shape();
    if m > 0 && p > 0 {
        packing.pack_left(a.as_slice(), (m, p), Left::Plain);
    }
    for (c, b) in [(c1, b1), (c2, b2)] {
        let n = b.ncols();
        assert!(
            b.nrows() == p && c.nrows() == m && c.ncols() == n,
            "mul_into_pair: shapes"
        );
        c.as_mut_slice().fill(0.0);
        if m > 0 && n > 0 && p > 0 {
            packing.pack_right(b.as_slice(), (p, n));
            tiles(c.as_mut_slice(), (m, n, p), packing, false);
        }
    }
}

/// `S += A_sᵀ B` for a product known to be symmetric (as [`tr_mul_into_symmetric`]) and
/// `C += Aᵀ B`, `B` packed once for both: the backward pass's `Q_xx += Aᵀ(V_xx A)` and
/// `Q_ux += Bᵀ(V_xx A)`. The same sums as the two calls with `β = 1`.
pub fn tr_mul_into_pair(
    (s, a_s): (&mut DMatrix<f64>, &DMatrix<f64>),
    (c, a): (&mut DMatrix<f64>, &DMatrix<f64>),
    b: &DMatrix<f64>,
    packing: &mut Packing,
) {
    let (p, n) = b.shape();
    assert!(
        a_s.nrows() == p
            && a.nrows() == p
            && s.shape() == (a_s.ncols(), n)
            && c.shape() == (a.ncols(), n),
        "tr_mul_into_pair: shapes"
    );
    if n > 0 && p > 0 {
        packing.pack_right(b.as_slice(), (p, n));
        for (out, left, upper) in [(&mut *s, a_s, true), (&mut *c, a, false)] {
            let m = left.ncols();
            if m > 0 {
                packing.pack_left(left.as_slice(), (m, p), Left::Transposed);
                tiles(out.as_mut_slice(), (m, n, p), packing, upper);
            }
        }
    }
    mirror_upper(s);
}

fn tr_mul(
    c: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    packing: &mut Packing,
    upper: bool,
) {
    let (m, n, p) = (a.ncols(), b.ncols(), a.nrows());
    assert!(
        b.nrows() == p && c.nrows() == m && c.ncols() == n,
        "tr_mul_into: shapes"
    );
    product(c, b, beta, packing, upper, |packing| {
        packing.pack_left(a.as_slice(), (m, p), Left::Transposed)
    });
}

/// `C = L B + β C` with `L` packed by `pack_left`; with `upper`, only the tiles that reach
/// the diagonal or above it.
fn product(
    c: &mut DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    packing: &mut Packing,
    upper: bool,
    pack_left: impl FnOnce(&mut Packing),
) {
    let (m, n, p) = (c.nrows(), c.ncols(), b.nrows());
    let c = c.as_mut_slice();
    if beta == 0.0 {
        c.fill(0.0);
    } else if beta != 1.0 {
        c.iter_mut().for_each(|x| *x *= beta);
    }
    if m == 0 || n == 0 || p == 0 {
        return;
    }
    pack_left(packing);
    packing.pack_right(b.as_slice(), (p, n));
    tiles(c, (m, n, p), packing, upper);
}

/// `C += L B`, tile by tile.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn tiles(c: &mut [f64], (m, n, p): (usize, usize, usize), packing: &Packing, upper: bool) {
    let fused = multiversion::target::target_cfg_f!(target_feature = "fma");
    for (jb, (right, &right_span)) in packing
        .right
        .chunks_exact(p * COLS)
        .zip(&packing.right_spans)
        .enumerate()
    {
        let j0 = jb * COLS;
        let cols = COLS.min(n - j0);
        for (ib, (left, &left_span)) in packing
            .left
            .chunks_exact(p * ROWS)
            .zip(&packing.left_spans)
            .enumerate()
        {
            let i0 = ib * ROWS;
            // Tiles below the diagonal are left to the mirror.
            if upper && i0 >= j0 + cols {
                break;
            }
            let (lo, hi) = (left_span.0.max(right_span.0), left_span.1.min(right_span.1));
            if lo >= hi {
                continue;
            }
            let (x, y) = (&left[lo * ROWS..hi * ROWS], &right[lo * COLS..hi * COLS]);
            let sums = if fused {
                tile::<true>(x, y)
            } else {
                tile::<false>(x, y)
            };
            let rows = ROWS.min(m - i0);
            for (j, column) in sums.iter().take(cols).enumerate() {
                let out = &mut c[(j0 + j) * m + i0..][..rows];
                for (o, s) in out.iter_mut().zip(column) {
                    *o += s;
                }
            }
        }
    }
}

/// `Σ_k x_k y_kᵀ` over the packed rows `x_k` (ROWS entries) and `y_k` (COLS entries): one
/// tile of `C`, its running sums held in registers.
#[inline(always)]
fn tile<const FUSED: bool>(x: &[f64], y: &[f64]) -> [[f64; ROWS]; COLS] {
    let mut sums = [[0.0f64; ROWS]; COLS];
    for (x, y) in x.chunks_exact(ROWS).zip(y.chunks_exact(COLS)) {
        for (column, &yj) in sums.iter_mut().zip(y) {
            for (s, &xr) in column.iter_mut().zip(x) {
                *s = if FUSED {
                    xr.mul_add(yj, *s)
                } else {
                    *s + xr * yj
                };
            }
        }
    }
    sums
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked products equal nalgebra's, with and without accumulation, transposed or
    /// not, at sizes that leave partial tiles of every shape.
    #[test]
    fn blocked_products_equal_nalgebras() {
        let mut packing = Packing::default();
        for (m, n, p) in [
            (4, 5, 3),
            (1, 1, 1),
            (3, 2, 0),
            (0, 2, 3),
            (9, 7, 11),
            (21, 18, 13),
            (84, 18, 84),
        ] {
            let a = DMatrix::from_fn(m, p, |i, j| ((i * p + j) as f64 * 0.7).sin());
            let b = DMatrix::from_fn(p, n, |i, j| ((i * n + j) as f64 * 0.3).cos());
            let at = a.transpose();
            let c0 = DMatrix::from_fn(m, n, |i, j| (i + 2 * j) as f64);
            let tol = 1e-13 * (p + 1) as f64;
            let mut c = c0.clone();
            mul_into(&mut c, &a, &b, 0.5, &mut packing);
            assert!((&c - (&a * &b + &c0 * 0.5)).amax() < tol, "{m}×{n}×{p}");
            let mut c = c0.clone();
            tr_mul_into(&mut c, &at, &b, 2.0, &mut packing);
            assert!((&c - (&a * &b + &c0 * 2.0)).amax() < tol, "{m}×{n}×{p}");
            let mut c = DMatrix::from_element(m, n, f64::NAN);
            mul_into(&mut c, &a, &b, 0.0, &mut packing);
            assert!((&c - &a * &b).amax() < tol, "β = 0 overwrites");
            let mut c = DMatrix::from_element(m, n, f64::NAN);
            tr_mul_into(&mut c, &at, &b, 0.0, &mut packing);
            assert!((&c - &a * &b).amax() < tol, "β = 0 overwrites");
            // A symmetric product AᵀWA: upper tiles and the mirror.
            let w = DMatrix::from_fn(m, m, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
            let wa = &w * &a;
            let c0 = DMatrix::from_fn(p, p, |i, j| (i * j) as f64);
            let mut c = c0.clone();
            tr_mul_into_symmetric(&mut c, &a, &wa, 1.0, &mut packing);
            assert!((&c - (a.transpose() * &wa + &c0)).amax() < tol, "{m}×{p}");
        }
    }

    /// The paired products (one factor packed for two) give the single products' sums bit
    /// for bit, on shapes with empty dimensions too.
    #[test]
    fn paired_products_equal_the_single_ones() {
        let mut packing = Packing::default();
        for (m, n1, n2, p) in [
            (84, 84, 18, 84),
            (9, 7, 3, 11),
            (5, 0, 2, 4),
            (3, 2, 2, 0),
            (0, 3, 1, 2),
        ] {
            let f = |r: usize, c: usize, s: f64| {
                DMatrix::from_fn(r, c, |i, j| ((i * c + j) as f64 * s).sin())
            };
            let (a, b1, b2) = (f(m, p, 0.7), f(p, n1, 0.3), f(p, n2, 0.9));
            let (mut c1, mut c2) = (f(m, n1, 0.1), f(m, n2, 0.2));
            mul_into_pair([&mut c1, &mut c2], &a, [&b1, &b2], &mut packing);
            let (mut e1, mut e2) = (DMatrix::zeros(m, n1), DMatrix::zeros(m, n2));
            mul_into(&mut e1, &a, &b1, 0.0, &mut packing);
            mul_into(&mut e2, &a, &b2, 0.0, &mut packing);
            assert_eq!((&c1, &c2), (&e1, &e2), "{m}×{n1}, {n2}×{p}");
            // S += A_sᵀ B (B = W A_s, symmetric), C += Aᵀ B.
            let w = DMatrix::from_fn(p, p, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
            let (a_s, a2) = (f(p, n1, 0.4), f(p, n2, 0.5));
            let b = &w * &a_s;
            let s0 = DMatrix::from_fn(n1, n1, |i, j| (i * j) as f64);
            let c0 = f(n2, n1, 0.6);
            let (mut s, mut c) = (s0.clone(), c0.clone());
            tr_mul_into_pair((&mut s, &a_s), (&mut c, &a2), &b, &mut packing);
            let (mut es, mut ec) = (s0, c0);
            tr_mul_into_symmetric(&mut es, &a_s, &b, 1.0, &mut packing);
            tr_mul_into(&mut ec, &a2, &b, 1.0, &mut packing);
            assert_eq!((&s, &c), (&es, &ec), "{n1}, {n2}×{p}");
        }
    }

    /// Columns with leading and trailing zeros, and all-zero ones, in either factor: the sums
    /// skip them and lose nothing.
    #[test]
    fn zero_spans_are_skipped_exactly() {
        let mut packing = Packing::default();
        let (p, m, n) = (23, 13, 10);
        let a = DMatrix::from_fn(p, m, |i, j| match j {
            0 | 9 => 0.0,
            _ if i < j || i + j > 27 => 0.0,
            _ => ((i * m + j) as f64 * 0.7).sin(),
        });
        let b = DMatrix::from_fn(p, n, |i, j| match j {
            3 => 0.0,
            _ if i + 2 * j < 6 || i > 15 + j => 0.0,
            _ => ((i * n + j) as f64 * 0.3).cos(),
        });
        let mut c = DMatrix::from_element(m, n, f64::NAN);
        tr_mul_into(&mut c, &a, &b, 0.0, &mut packing);
        assert!((&c - a.transpose() * &b).amax() < 1e-13);
        let mut c = DMatrix::from_element(p, n, 1.0);
        let aat = &a * a.transpose();
        mul_into(&mut c, &aat, &b, 1.0, &mut packing);
        assert!((&c - (&aat * &b).add_scalar(1.0)).amax() < 1e-12);
        let w = DMatrix::from_fn(p, p, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
        let wa = &w * &a;
        let mut c = DMatrix::from_element(m, m, f64::NAN);
        tr_mul_into_symmetric(&mut c, &a, &wa, 0.0, &mut packing);
        assert!((&c - a.transpose() * &wa).amax() < 1e-13);
    }
}
