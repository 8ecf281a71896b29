//! Frames' world poses and their Jacobians by `q`, read off the model's tree (eq. (1) and
//! its derivative): what `frame` and `orientation` cost terms are written on. Each variable
//! drives one primitive, so column `j` of a frame's Jacobian is that primitive's unit twist
//! seen from the world, when the frame hangs below it.

use nalgebra::{DMatrix, Matrix3, Vector3};
use tree_model::{Joint, Model};

/// Every frame's world rotation and origin at `q`.
pub fn world_poses(model: &Model, q: &[f64]) -> Vec<(Matrix3<f64>, Vector3<f64>)> {
    let mut out = Vec::with_capacity(model.frames.len());
    world_poses_into(model, q, &mut out);
    out
}

/// [`world_poses`] into `out` (cleared; no allocation once it has the capacity).
pub fn world_poses_into(model: &Model, q: &[f64], out: &mut Vec<(Matrix3<f64>, Vector3<f64>)>) {
    out.clear();
    for f in &model.frames {
        let (r, p) = f
            .parent
            .map_or((Matrix3::identity(), Vector3::zeros()), |k| out[k]);
        let x = match f.joint {
            Joint::Constant(x) => x,
            Joint::Variable(i) => q[i],
        };
        let axis = f.primitive.axis();
        out.push(if f.primitive.is_rotation() {
            let turn = nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Unit::new_unchecked(Vector3::ith(axis, 1.0)),
                x,
            );
            (r * turn.matrix(), p)
        } else {
            (r, p + r.column(axis) * x)
        });
    }
}

/// Frame `f`'s world position Jacobian `∂p_f/∂q` and angular Jacobian `J_ω` (world
/// components: `ω = J_ω q̇`), each 3 × n, from the poses of [`world_poses`], into `jp`, `jw`.
pub fn frame_jacobians(
    model: &Model,
    poses: &[(Matrix3<f64>, Vector3<f64>)],
    f: usize,
    jp: &mut DMatrix<f64>,
    jw: &mut DMatrix<f64>,
) {
    jp.fill(0.0);
    jw.fill(0.0);
    let pf = poses[f].1;
    let mut a = Some(f);
    while let Some(k) = a {
        let frame = &model.frames[k];
        if let Joint::Variable(j) = frame.joint {
            let (r, p) = poses[k];
            let e = r.column(frame.primitive.axis()).into_owned();
            if frame.primitive.is_rotation() {
                let v = e.cross(&(pf - p));
                for row in 0..3 {
                    jp[(row, j)] += v[row];
                    jw[(row, j)] += e[row];
                }
            } else {
                for row in 0..3 {
                    jp[(row, j)] += e[row];
                }
            }
        }
        a = frame.parent;
    }
}

/// `log(R)`: the rotation vector `φ` with `R = exp([φ]×)`, `|φ| ≤ π`.
pub fn log_so3(r: &Matrix3<f64>) -> Vector3<f64> {
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
pub fn right_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
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
