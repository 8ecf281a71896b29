//! Linear-quadratic regulators on a discrete linear model `x_{k+1} = A x_k + B u_k` with the
//! cost `Σ ½(xᵀQx + uᵀRu)`: the infinite-horizon gain from the discrete algebraic Riccati
//! equation, and the time-varying gains along a trajectory by the backward Riccati recursion
//! (docs/derivations.md §10).

use nalgebra::DMatrix;

use tree_runtime::SimError;

/// A feedback `u = −K x` and the cost-to-go `½ xᵀ P x`.
#[derive(Clone, Debug, PartialEq)]
pub struct Lqr {
    /// The gain (inputs × states).
    pub k: DMatrix<f64>,
    /// The cost-to-go matrix (states × states, symmetric).
    pub p: DMatrix<f64>,
}

/// One Riccati step back from `P_{k+1}`: `K = (R + BᵀPB)⁻¹ BᵀPA`,
/// `P_k = Q + AᵀP(A − BK)` (symmetrised).
fn riccati_step(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    p: &DMatrix<f64>,
) -> Result<Lqr, SimError> {
    let pb = p * b;
    let s = r + b.transpose() * &pb;
    let k = s
        .cholesky()
        .ok_or_else(|| {
            SimError::InvalidInput(
                "the Riccati recursion met R + BᵀPB that is not positive definite (is R positive definite?)"
                    .into(),
            )
        })?
        .solve(&(pb.transpose() * a));
    let next = q + a.transpose() * p * (a - b * &k);
    let p = (&next + next.transpose()) * 0.5;
    Ok(Lqr { k, p })
}

/// The infinite-horizon discrete LQR: iterates the Riccati recursion from `P = Q` until `P`
/// changes by less than `1e-12` relative to its size (at most 100 000 steps). Fails with a
/// sentence when `(A, B)` cannot be stabilised (the recursion diverges or does not settle).
pub fn dare(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<Lqr, SimError> {
    let n = a.nrows();
    let m = b.ncols();
    if a.shape() != (n, n) || b.nrows() != n || q.shape() != (n, n) || r.shape() != (m, m) {
        return Err(SimError::InvalidInput(format!(
            "the LQR needs A n × n, B n × m, Q n × n and R m × m; got A {:?}, B {:?}, Q {:?}, R {:?}",
            a.shape(),
            b.shape(),
            q.shape(),
            r.shape()
        )));
    }
    let mut lqr = Lqr {
        k: DMatrix::zeros(b.ncols(), n),
        p: q.clone(),
    };
    for _ in 0..100_000 {
        let next = riccati_step(a, b, q, r, &lqr.p)?;
        let change = (&next.p - &lqr.p).amax();
        let size = next.p.amax().max(f64::MIN_POSITIVE);
        if !size.is_finite() {
            break;
        }
        lqr = next;
        if change <= 1e-12 * size {
            return Ok(lqr);
        }
    }
    Err(SimError::InvalidInput(
        "the discrete Riccati equation did not settle: the linearised system cannot be stabilised by these inputs (or Q, R are badly scaled)".into(),
    ))
}

/// Time-varying LQR along a horizon: `P_N = Q_f`, then one Riccati step back per knot with
/// that knot's `(A_k, B_k)`. Returns the gains and cost-to-go of knots `0 … N−1`.
pub fn tvlqr(
    a: &[DMatrix<f64>],
    b: &[DMatrix<f64>],
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    q_final: &DMatrix<f64>,
) -> Result<Vec<Lqr>, SimError> {
    if a.len() != b.len() {
        return Err(SimError::InvalidInput(format!(
            "the time-varying LQR needs one B per A; got {} A and {} B",
            a.len(),
            b.len()
        )));
    }
    let mut p = q_final.clone();
    let mut out = Vec::with_capacity(a.len());
    for (ak, bk) in a.iter().zip(b).rev() {
        let step = riccati_step(ak, bk, q, r, &p)?;
        p = step.p.clone();
        out.push(step);
    }
    out.reverse();
    Ok(out)
}
