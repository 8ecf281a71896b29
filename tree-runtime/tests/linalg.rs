//! The in-place solvers against nalgebra's, and their singularity reports.

use nalgebra::{DMatrix, DVector, Dyn, SMatrix, SVector};
use tree_runtime::linalg::{cholesky_solve, lu_solve};

fn matrix(n: usize, seed: u64) -> DMatrix<f64> {
    let mut s = seed;
    DMatrix::from_fn(n, n, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    })
}

#[test]
fn cholesky_and_lu_solve_like_nalgebra() {
    for n in [1, 2, 5, 19, 40] {
        let a = matrix(n, n as u64);
        let spd = &a * a.transpose() + DMatrix::identity(n, n) * 0.1;
        let b = DVector::from_fn(n, |i, _| (i as f64).sin());
        let mut f = spd.clone();
        let mut x = b.clone();
        cholesky_solve::<Dyn>(&mut f, &mut x).unwrap();
        let reference = spd.clone().cholesky().unwrap().solve(&b);
        assert!(
            (&x - &reference).amax() < 1e-10 * reference.amax().max(1.0),
            "cholesky n = {n}"
        );
        let mut f = a.clone();
        let mut x = b.clone();
        lu_solve::<Dyn>(&mut f, &mut x).unwrap();
        let reference = a.clone().lu().solve(&b).unwrap();
        assert!(
            (&x - &reference).amax() < 1e-9 * reference.amax().max(1.0),
            "lu n = {n}"
        );
        assert!((&a * &x - &b).amax() < 1e-10, "lu residual n = {n}");
    }
}

#[test]
fn fixed_size_works_too() {
    let a = SMatrix::<f64, 3, 3>::new(4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0);
    let b = SVector::<f64, 3>::new(1.0, 2.0, 3.0);
    let (mut f, mut x) = (a, b);
    cholesky_solve(&mut f, &mut x).unwrap();
    assert!((a * x - b).amax() < 1e-14);
    let (mut f, mut x) = (a, b);
    lu_solve(&mut f, &mut x).unwrap();
    assert!((a * x - b).amax() < 1e-14);
}

#[test]
fn singular_matrices_are_reported_with_their_pivot() {
    // Rank 1: the second pivot vanishes.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
    let b = DVector::from_vec(vec![1.0, 1.0]);
    let (mut f, mut x) = (a.clone(), b.clone());
    assert_eq!(cholesky_solve::<Dyn>(&mut f, &mut x).unwrap_err().0, 1);
    let (mut f, mut x) = (a, b.clone());
    assert_eq!(lu_solve::<Dyn>(&mut f, &mut x).unwrap_err(), 1);
    // Indefinite: Cholesky refuses it at once, LU solves it.
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 1.0]);
    let (mut f, mut x) = (a.clone(), b.clone());
    assert_eq!(cholesky_solve::<Dyn>(&mut f, &mut x).unwrap_err().0, 0);
    let (mut f, mut x) = (a, b);
    lu_solve::<Dyn>(&mut f, &mut x).unwrap();
    assert_eq!(x.as_slice(), &[-1.0, 1.0]);
}
