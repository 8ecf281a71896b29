//! In-place dense factorisations for any nalgebra dimension: nothing allocated, so a
//! fixed-size system stays on the stack and an interpreted one reuses its buffers. They work
//! on the column-major storage directly (`a[j * n + i]` is row i, column j).

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::system::{Matrix, Vector};

mod products;

pub use products::{mul_into, tr_mul_into, tr_mul_into_symmetric, Packing};

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
        // Column j of the factor: a[i][j] −= Σ_k L[i][k] L[j][k] for i ≥ j.
        for k in 0..j {
            let col_k = &done[k * n..(k + 1) * n];
            let ljk = col_k[j];
            for i in j..n {
                col_j[i] -= col_k[i] * ljk;
            }
        }
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

/// Solves `L Lᵀ x = b` with the factor from [`cholesky_factor`]; `b` becomes `x`.
pub fn cholesky_substitute<N: Dim>(a: &Matrix<N>, b: &mut Vector<N>)
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

/// Solves `A x = b` by LU with partial pivoting, overwriting `a` and `b` (`b` becomes `x`).
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

/// On a zero pivot returns its column.
pub fn lu_solve<N: Dim>(a: &mut Matrix<N>, b: &mut Vector<N>) -> Result<(), usize>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = b.len();
    let b = b.as_mut_slice();
    lu_core_factor(a.as_mut_slice(), n, |j, p| b.swap(j, p))?;
    forward_backward(a.as_slice(), n, b);
    Ok(())
}

/// Row interchanges of an LU factorisation.
pub type Pivots<N> = nalgebra::OVector<usize, N>;

/// Factors the `n × n` column-major matrix in `a[..n²]` in place (`P A = L U`, partial
/// pivoting), recording the interchanges in `pivots[..n]`. The caller may pack a smaller
/// system into larger fixed-size storage. On failure returns the column whose pivot vanished.
pub fn lu_factor_packed(a: &mut [f64], n: usize, pivots: &mut [usize]) -> Result<(), usize> {
    lu_core_factor(&mut a[..n * n], n, |j, p| pivots[j] = p)
}

/// Solves `A x = b[..n]` with the factors from [`lu_factor_packed`]; `b` becomes `x`.
pub fn lu_solve_packed(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64]) {
    for (j, &p) in pivots[..n].iter().enumerate() {
        b.swap(p, j);
    }
    forward_backward(&a[..n * n], n, &mut b[..n]);
}

/// Solves `A X = B` for `k` right-hand sides at once with the factors from
/// [`lu_factor_packed`]: `b` holds `B` row-major (`n × k`, row i at `i·k`) and becomes `X`.
/// Each elimination updates a whole row of right-hand sides (one contiguous pass), where `k`
/// calls of [`lu_solve_packed`] would walk the factor `k` times. Compiled also for AVX and
/// chosen at run time (as [`mul_into`]'s kernel).
#[multiversion::multiversion(targets("x86_64+avx"))]
pub fn lu_solve_packed_rows(a: &[f64], n: usize, pivots: &[usize], b: &mut [f64], k: usize) {
    let b = &mut b[..n * k];
    for (j, &p) in pivots[..n].iter().enumerate() {
        if p != j {
            for c in 0..k {
                b.swap(p * k + c, j * k + c);
            }
        }
    }
    for j in 0..n {
        let col = &a[j * n..(j + 1) * n];
        let (done, rest) = b.split_at_mut((j + 1) * k);
        let bj = &done[j * k..];
        for (bi, &l) in rest.chunks_exact_mut(k).zip(&col[j + 1..]) {
            if l != 0.0 {
                for (x, y) in bi.iter_mut().zip(bj) {
                    *x -= l * y;
                }
            }
        }
    }
    for j in (0..n).rev() {
        let col = &a[j * n..(j + 1) * n];
        let (head, tail) = b.split_at_mut(j * k);
        let bj = &mut tail[..k];
        let inverse = 1.0 / col[j];
        for x in bj.iter_mut() {
            *x *= inverse;
        }
        for (row, &u) in head.chunks_exact_mut(k).zip(&col[..j]) {
            if u != 0.0 {
                for (x, y) in row.iter_mut().zip(bj.iter()) {
                    *x -= u * y;
                }
            }
        }
    }
}

/// `C += A D` for row-major `C` (rows of `k`) and `D` (row `s` at `s·k`), where row `r` of `A`
/// is row `r` of the row-major `a` (rows of `w`) read at the columns `cols` (column `s` of `A`
/// is `a`'s column `cols[s]`): each row of `C` gains a combination of `D`'s rows, zero
/// coefficients skipped. Compiled also for AVX and chosen at run time (as [`mul_into`]'s
/// kernel).
#[multiversion::multiversion(targets("x86_64+avx"))]
pub fn combine_rows(c: &mut [f64], k: usize, a: &[f64], w: usize, cols: &[usize], d: &[f64]) {
    for (out, arow) in c.chunks_exact_mut(k).zip(a.chunks_exact(w)) {
        for (s, &col) in cols.iter().enumerate() {
            let coefficient = arow[col];
            if coefficient != 0.0 {
                for (o, x) in out.iter_mut().zip(&d[s * k..(s + 1) * k]) {
                    *o += coefficient * x;
                }
            }
        }
    }
}

/// `L y = b` (unit lower), then `U x = y`, on column-major factors.
fn forward_backward(a: &[f64], n: usize, b: &mut [f64]) {
    for j in 0..n {
        let col = &a[j * n + j + 1..(j + 1) * n];
        let (head, below) = b.split_at_mut(j + 1);
        let bj = head[j];
        for (x, l) in below.iter_mut().zip(col) {
            *x -= l * bj;
        }
    }
    for j in (0..n).rev() {
        let col = &a[j * n..j * n + j + 1];
        let (above, rest) = b.split_at_mut(j);
        rest[0] /= col[j];
        let bj = rest[0];
        for (x, u) in above.iter_mut().zip(col) {
            *x -= u * bj;
        }
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
/// swapped into row j. Compiled also for AVX and chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx"))]
fn lu_core_factor(
    a: &mut [f64],
    n: usize,
    mut swapped: impl FnMut(usize, usize),
) -> Result<(), usize> {
    for j in 0..n {
        // Pivot: the largest entry of column j at or below the diagonal.
        let col = &a[j * n..(j + 1) * n];
        let mut p = j;
        for i in j + 1..n {
            if col[i].abs() > col[p].abs() {
                p = i;
            }
        }
        let pivot = col[p];
        // Singular when the pivot is lost in the rounding of its own column (U's part
        // above included): relative per column, so an unknown in other units (a multiplier
        // scaled by Δt beside momenta over Δt) is not taken for a singular one.
        let scale = largest_magnitude(col).max(f64::MIN_POSITIVE);
        if !pivot.is_finite() || pivot.abs() <= 1e-14 * scale {
            return Err(j);
        }
        swapped(j, p);
        if p != j {
            for c in 0..n {
                a.swap(c * n + p, c * n + j);
            }
        }
        // Multipliers below the pivot, then update the trailing columns.
        let inverse = 1.0 / pivot;
        a[j * n + j + 1..(j + 1) * n]
            .iter_mut()
            .for_each(|x| *x *= inverse);
        let (left, right) = a.split_at_mut((j + 1) * n);
        let mult = &left[j * n + j + 1..(j + 1) * n];
        for col in right.chunks_exact_mut(n) {
            let (head, below) = col.split_at_mut(j + 1);
            let ajc = head[j];
            if ajc != 0.0 {
                for (x, m) in below.iter_mut().zip(mult) {
                    *x -= m * ajc;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// Several right-hand sides at once give what one solve each gives, and `A X = B` holds
    /// (a matrix whose first pivot must be swapped).
    #[test]
    fn many_right_hand_sides_solve_as_one_each() {
        let n = 5;
        let a: Vec<f64> = (0..n * n)
            .map(|k| {
                if k == 0 {
                    0.0
                } else {
                    ((k * 7 % 11) as f64 - 5.0) / 3.0 + (k % 6 == 0) as u8 as f64 * 4.0
                }
            })
            .collect();
        let (mut factor, mut pivots) = (a.clone(), vec![0; n]);
        lu_factor_packed(&mut factor, n, &mut pivots).expect("regular");
        assert_ne!(pivots[0], 0, "the first pivot is swapped");
        let k = 3;
        let b: Vec<f64> = (0..n * k).map(|i| (i as f64).sin()).collect();
        let mut x = b.clone();
        lu_solve_packed_rows(&factor, n, &pivots, &mut x, k);
        for c in 0..k {
            let mut one: Vec<f64> = (0..n).map(|r| b[r * k + c]).collect();
            lu_solve_packed(&factor, n, &pivots, &mut one);
            for r in 0..n {
                assert!((x[r * k + c] - one[r]).abs() < 1e-13, "column {c}, row {r}");
                // A (column-major) times x's column c gives b's.
                let ax: f64 = (0..n).map(|j| a[j * n + r] * x[j * k + c]).sum();
                assert!((ax - b[r * k + c]).abs() < 1e-12, "residual at ({r}, {c})");
            }
        }
    }

    /// `combine_rows` is `C + A D` with `A` read at chosen columns of a wider row-major matrix;
    /// `largest_magnitude` finds the largest entry wherever it sits (any length, NaN skipped).
    #[test]
    fn row_combination_and_largest_magnitude() {
        let (rows, w, k) = (3, 6, 5);
        let a: Vec<f64> = (0..rows * w).map(|x| (x as f64 * 0.7).sin()).collect();
        let d: Vec<f64> = (0..4 * k).map(|x| (x as f64 * 1.3).cos()).collect();
        let cols = [4, 0, 5, 2];
        let mut c: Vec<f64> = (0..rows * k).map(|x| x as f64).collect();
        let start = c.clone();
        combine_rows(&mut c, k, &a, w, &cols, &d);
        for r in 0..rows {
            for j in 0..k {
                let sum: f64 = (0..4).map(|s| a[r * w + cols[s]] * d[s * k + j]).sum();
                assert!((c[r * k + j] - start[r * k + j] - sum).abs() < 1e-14);
            }
        }
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
