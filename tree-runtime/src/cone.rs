//! The second-order cone `K = {(a, b) ∈ ℝ × ℝ²: ‖b‖ ≤ a}` and its Jordan algebra: what the
//! interior-point contact solver of docs/derivations.md §13 needs for Coulomb friction as the
//! exact cone (`(μγ, β) ∈ K`, `(ψ, v) ∈ K`, `(μγ, β) ∘ (ψ, v) = κ e` on the central path).
//!
//! A point is `[a, b₁, b₂]`. The Jordan product `x ∘ y = (xᵀy, x₀ y₁ + y₀ x₁)` has the
//! identity `e = (1, 0)`; `det x = x₀² − ‖x₁‖²` is positive inside the cone and zero on its
//! boundary. Nesterov–Todd scaling (as in CVXOPT's `coneprog` notes, written here from the
//! cone's algebra): for `s`, `z` inside the cone there is one `W`, symmetric positive definite
//! and mapping the cone onto itself, with `W s = W⁻¹ z` — the scaled point `λ` at which the
//! primal-dual Newton system is symmetric.

/// A point of `ℝ × ℝ²`, `[a, b₁, b₂]`.
pub type Point = [f64; 3];

/// A 3 × 3 matrix, by rows.
pub type Matrix3 = [[f64; 3]; 3];

/// A Nesterov–Todd scaling ([`nesterov_todd`]): `W`, `W⁻¹` and the scaled point
/// `λ = W s = W⁻¹ z`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scaling {
    /// `W`, symmetric positive definite.
    pub w: Matrix3,
    /// `W⁻¹`.
    pub inverse: Matrix3,
    /// `λ`.
    pub lambda: Point,
}

/// The cone's identity `e = (1, 0, 0)`.
pub const IDENTITY: Point = [1.0, 0.0, 0.0];

/// `x ∘ y = (xᵀy, x₀ y₁ + y₀ x₁)`.
pub fn product(x: &Point, y: &Point) -> Point {
    [
        x[0] * y[0] + x[1] * y[1] + x[2] * y[2],
        x[0] * y[1] + y[0] * x[1],
        x[0] * y[2] + y[0] * x[2],
    ]
}

/// `det x = x₀² − ‖x₁‖²`: positive inside the cone, zero on its boundary.
pub fn det(x: &Point) -> f64 {
    x[0] * x[0] - x[1] * x[1] - x[2] * x[2]
}

/// Whether `x` is strictly inside the cone.
pub fn inside(x: &Point) -> bool {
    x[0] > 0.0 && det(x) > 0.0
}

/// `x⁻¹ = (x₀, −x₁)/det x`, the inverse for `∘` (`x ∘ x⁻¹ = e`); `None` on the boundary.
pub fn inverse(x: &Point) -> Option<Point> {
    let d = det(x);
    (d != 0.0).then(|| [x[0] / d, -x[1] / d, -x[2] / d])
}

/// The largest `α ∈ [0, 1]` with `x + α dx` in the (closed) cone, for `x` strictly inside:
/// the smallest positive root of `det(x + α dx) = 0` on the cone's own sheet (`a > 0`).
pub fn step_to_boundary(x: &Point, dx: &Point) -> f64 {
    step_within(x, dx, 1.0)
}

/// [`step_to_boundary`] with `α ∈ [0, limit]`.
pub fn step_within(x: &Point, dx: &Point, limit: f64) -> f64 {
    // det(x + α dx) = det x + 2α ⟨x, J dx⟩ + α² det dx, J = diag(1, −1, −1).
    let (c, b, a) = (det(x), x[0] * dx[0] - x[1] * dx[1] - x[2] * dx[2], det(dx));
    let mut alpha: f64 = limit;
    // The first sheet's apex line a = 0 bounds the step too.
    if dx[0] < 0.0 {
        alpha = alpha.min(-x[0] / dx[0]);
    }
    let mut bound = |r: f64| {
        if r > 0.0 {
            alpha = alpha.min(r);
        }
    };
    if a.abs() <= f64::EPSILON * (b.abs() + c.abs()) {
        // Linear: 2bα + c = 0.
        if b < 0.0 {
            bound(-c / (2.0 * b));
        }
    } else {
        let disc = b * b - a * c;
        if disc >= 0.0 {
            // The roots of aα² + 2bα + c, each computed without cancellation.
            let q = -(b + b.signum() * disc.sqrt());
            bound(q / a);
            if q != 0.0 {
                bound(c / q);
            }
        }
    }
    alpha.max(0.0)
}

/// The Nesterov–Todd scaling of `s`, `z` strictly inside the cone: `W, W⁻¹, λ` with `W`
/// symmetric positive definite, `W s = W⁻¹ z = λ`. With `s̄ = s/√det s`, `z̄ = z/√det z`,
/// `γ = √((1 + s̄ᵀz̄)/2)`, `w̄ = (z̄ + J s̄)/(2γ)` (`J = diag(1, −1, −1)`, `det w̄ = 1`) and
/// `η = (det z/det s)^{1/4}`: `W = η [[w̄₀, w̄₁ᵀ], [w̄₁, I + w̄₁w̄₁ᵀ/(1 + w̄₀)]]`, and `W⁻¹` the
/// same with `1/η` and `−w̄₁`. `None` unless both points are strictly inside.
pub fn nesterov_todd(s: &Point, z: &Point) -> Option<Scaling> {
    if !inside(s) || !inside(z) {
        return None;
    }
    let (ds, dz) = (det(s).sqrt(), det(z).sqrt());
    let sb = [s[0] / ds, s[1] / ds, s[2] / ds];
    let zb = [z[0] / dz, z[1] / dz, z[2] / dz];
    let gamma = ((1.0 + sb[0] * zb[0] + sb[1] * zb[1] + sb[2] * zb[2]) / 2.0).sqrt();
    let w = [
        (zb[0] + sb[0]) / (2.0 * gamma),
        (zb[1] - sb[1]) / (2.0 * gamma),
        (zb[2] - sb[2]) / (2.0 * gamma),
    ];
    let eta = (dz / ds).sqrt();
    let block = |sign: f64, scale: f64| {
        let mut m = [[0.0; 3]; 3];
        m[0][0] = w[0];
        for i in 1..3 {
            m[0][i] = sign * w[i];
            m[i][0] = sign * w[i];
            for j in 1..3 {
                let identity = if i == j { 1.0 } else { 0.0 };
                m[i][j] = identity + w[i] * w[j] / (1.0 + w[0]);
            }
        }
        m.map(|row| row.map(|x| scale * x))
    };
    let (w, inverse) = (block(1.0, eta), block(-1.0, 1.0 / eta));
    let lambda = apply(&w, s);
    Some(Scaling { w, inverse, lambda })
}

/// `m x` for a 3 × 3 matrix.
pub fn apply(m: &Matrix3, x: &Point) -> Point {
    m.map(|row| row[0] * x[0] + row[1] * x[1] + row[2] * x[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed spread of points strictly inside the cone, near its axis and near its wall.
    fn interior() -> Vec<Point> {
        let mut out = Vec::new();
        for (k, &(a, r)) in [
            (1.0, 0.0),
            (2.0, 1.9),
            (0.3, 0.1),
            (5.0, 4.999),
            (1e-3, 5e-4),
        ]
        .iter()
        .enumerate()
        {
            let angle = 0.7 + 1.3 * k as f64;
            out.push([a, r * angle.cos(), r * angle.sin()]);
        }
        out
    }

    fn close(x: &Point, y: &Point, tol: f64) -> bool {
        let scale = 1.0 + x.iter().chain(y).fold(0.0f64, |m, v| m.max(v.abs()));
        x.iter().zip(y).all(|(a, b)| (a - b).abs() <= tol * scale)
    }

    #[test]
    fn the_identity_and_the_inverse_are_the_jordan_products() {
        for x in interior() {
            assert!(close(&product(&x, &IDENTITY), &x, 1e-15));
            let inv = inverse(&x).unwrap();
            assert!(close(&product(&x, &inv), &IDENTITY, 1e-9), "{x:?}");
        }
        assert!(inverse(&[1.0, 1.0, 0.0]).is_none());
    }

    #[test]
    fn a_step_to_the_boundary_lands_on_it_and_never_beyond() {
        let directions = [
            [-1.0, 0.3, 0.2],
            [0.0, 3.0, -1.0],
            [1.0, 0.0, 0.0],
            [-5.0, -5.0, 0.0],
        ];
        for x in interior() {
            for dx in directions {
                let alpha = step_to_boundary(&x, &dx);
                let end = [
                    x[0] + alpha * dx[0],
                    x[1] + alpha * dx[1],
                    x[2] + alpha * dx[2],
                ];
                let scale = end[0].abs().max(1e-300);
                // Inside or on the boundary, up to rounding of the cone's scale.
                assert!(end[0] >= -1e-12 * x[0].abs(), "{x:?} {dx:?} {alpha}");
                assert!(det(&end) >= -1e-9 * scale * scale, "{x:?} {dx:?} {alpha}");
                if alpha < 1.0 {
                    // Stopped by the boundary: a step further is outside.
                    let beyond = alpha * (1.0 + 1e-6) + 1e-12;
                    let past = [
                        x[0] + beyond * dx[0],
                        x[1] + beyond * dx[1],
                        x[2] + beyond * dx[2],
                    ];
                    assert!(!inside(&past), "{x:?} {dx:?} {alpha}");
                }
            }
        }
    }

    #[test]
    fn the_nesterov_todd_scaling_meets_in_the_middle() {
        let points = interior();
        for s in &points {
            for z in &points {
                let Scaling {
                    w,
                    inverse: winv,
                    lambda,
                } = nesterov_todd(s, z).unwrap();
                assert!(close(&apply(&w, s), &lambda, 1e-9), "W s = λ");
                assert!(
                    close(&apply(&winv, z), &lambda, 1e-9),
                    "W⁻¹ z = λ: {s:?} {z:?}"
                );
                for (i, row) in w.iter().enumerate() {
                    let back = apply(&winv, row);
                    let mut e = [0.0; 3];
                    e[i] = 1.0;
                    assert!(close(&back, &e, 1e-9), "W⁻¹ W = I");
                    for j in 0..3 {
                        assert_eq!(w[i][j], w[j][i], "W is symmetric");
                    }
                }
                assert!(inside(&lambda));
                // λ ∘ λ = (W s) ∘ (W⁻¹ z) has s ∘ z's "μ": λᵀλ = sᵀz.
                let sz = s[0] * z[0] + s[1] * z[1] + s[2] * z[2];
                assert!((product(&lambda, &lambda)[0] - sz).abs() <= 1e-9 * sz.abs().max(1.0));
            }
        }
        assert!(nesterov_todd(&[1.0, 1.0, 0.0], &IDENTITY).is_none());
    }
}
