//! In-place dense factorisations for any nalgebra dimension: nothing allocated, so a
//! fixed-size system stays on the stack and an interpreted one reuses its buffers.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::system::{Matrix, Vector};

/// Solves `A x = b` for symmetric positive definite `A` by Cholesky, overwriting `a` with
/// its factor and `b` with `x`. On failure returns the pivot index and value.
pub fn cholesky_solve<N: Dim>(a: &mut Matrix<N>, b: &mut Vector<N>) -> Result<(), (usize, f64)>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = b.len();
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        // Relative threshold: a pivot lost to rounding is as singular as a zero one.
        let scale = a[(j, j)].abs().max(f64::MIN_POSITIVE);
        if !d.is_finite() || d <= 1e-13 * scale {
            return Err((j, d));
        }
        let d = d.sqrt();
        a[(j, j)] = d;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[(i, k)] * b[k];
        }
        b[i] = s / a[(i, i)];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[(k, i)] * b[k];
        }
        b[i] = s / a[(i, i)];
    }
    Ok(())
}

/// Solves `A x = b` by LU with partial pivoting, overwriting `a` and `b` (`b` becomes `x`).
/// On a zero pivot returns its column.
pub fn lu_solve<N: Dim>(a: &mut Matrix<N>, b: &mut Vector<N>) -> Result<(), usize>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    let n = b.len();
    let scale = a
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    for j in 0..n {
        let mut p = j;
        for i in j + 1..n {
            if a[(i, j)].abs() > a[(p, j)].abs() {
                p = i;
            }
        }
        let pivot = a[(p, j)];
        if !pivot.is_finite() || pivot.abs() <= 1e-14 * scale {
            return Err(j);
        }
        if p != j {
            a.swap_rows(p, j);
            b.swap_rows(p, j);
        }
        for i in j + 1..n {
            let f = a[(i, j)] / pivot;
            a[(i, j)] = f;
            for k in j + 1..n {
                a[(i, k)] -= f * a[(j, k)];
            }
            b[i] -= f * b[j];
        }
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[(i, k)] * b[k];
        }
        b[i] = s / a[(i, i)];
    }
    Ok(())
}
