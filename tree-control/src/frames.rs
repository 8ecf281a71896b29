//! The rotation algebra the `orientation` cost term is written in: `log` on SO(3) and the
//! inverse of its right Jacobian (the frames' poses and Jacobians themselves come from
//! [`tree_runtime::kinematics`]).

use nalgebra::{Matrix3, Vector3};

/// `log(R)`: the rotation vector `φ` with `R = exp([φ]×)`, `|φ| ≤ π`.
pub(crate) fn log_so3(r: &Matrix3<f64>) -> Vector3<f64> {
    let cos = ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = cos.acos();
    let skew = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    );
    if theta < 1e-6 {
        // θ/(2 sin θ) = ½(1 + θ²/6 + …).
        return skew * (0.5 * (1.0 + theta * theta / 6.0));
    }
    if std::f64::consts::PI - theta > 1e-6 {
        return skew * (theta / (2.0 * theta.sin()));
    }
    // Near π: the axis from the largest diagonal entry of (R + I)/2 = a aᵀ.
    let b = (r + Matrix3::identity()) * 0.5;
    let i = (0..3)
        .max_by(|&x, &y| b[(x, x)].total_cmp(&b[(y, y)]))
        .unwrap_or(0);
    let mut axis = b.column(i).into_owned() / b[(i, i)].max(1e-300).sqrt();
    if axis.dot(&skew) < 0.0 {
        axis = -axis;
    }
    axis.normalize() * theta
}

/// The inverse right Jacobian of SO(3) at `φ`: `d log(R exp([δ]×)) = J_r⁻¹(φ) δ`.
pub(crate) fn right_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    let c = if theta < 1e-6 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    Matrix3::identity() + k * 0.5 + k * k * c
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// `log` inverts `exp` near 0, at moderate angles and near π (each branch of `log_so3`).
    #[test]
    fn log_inverts_exp_on_every_branch() {
        for angle in [1e-9, 1e-4, 0.7, 2.5, std::f64::consts::PI - 1e-8] {
            let phi = Vector3::new(0.3, -0.5, 0.8).normalize() * angle;
            let r = Rotation3::from_scaled_axis(phi);
            let back = log_so3(r.matrix());
            assert!(
                (back - phi).norm() < 1e-7 * angle.max(1e-3),
                "{angle}: {back} vs {phi}"
            );
        }
    }

    /// `J_r⁻¹(φ)` against differences of `log(R exp([δ]×))`.
    #[test]
    fn the_inverse_right_jacobian_matches_differences() {
        let phi = Vector3::new(0.4, -1.1, 0.6);
        let r = Rotation3::from_scaled_axis(phi);
        let jr = right_jacobian_inverse(&phi);
        let h = 1e-6;
        for c in 0..3 {
            let d = Vector3::ith(c, h);
            let plus = log_so3((r * Rotation3::from_scaled_axis(d)).matrix());
            let minus = log_so3((r * Rotation3::from_scaled_axis(-d)).matrix());
            let fd = (plus - minus) / (2.0 * h);
            assert!(
                (fd - jr.column(c)).norm() < 1e-8,
                "{fd} vs {}",
                jr.column(c)
            );
        }
    }
}
