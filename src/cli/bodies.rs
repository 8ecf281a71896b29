//! What an animation draws of a model beyond its frames: each rigid body as the uniform box
//! with its mass and inertia, and each slider's rail over the travel it makes in a run.

use tree_mech::model::{Joint, Mass, Model};
use tree_mech::nalgebra::{Matrix3, SymmetricEigen};
use tree_mech::runtime::Pose;

/// A body drawn as its equivalent box: the uniform box of the same mass and inertia about
/// the centre of mass — sides `a² = 6 (I_yy + I_zz − I_xx) / m` and the two like it along the
/// tensor's principal axes (a thin rod is a long thin box; a point mass has no box). An
/// inertia no solid of its size has — a box lighter than [`LIGHTEST`], as the UR5 file's
/// wrists (1.2 kg as a 1 m disc) — is not drawn as one: its body is a dot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyBox {
    /// The frame carrying the body.
    pub frame: usize,
    /// The centre of mass, in the frame's axes.
    pub com: [f64; 3],
    /// The principal axes (columns) in the frame's axes.
    pub axes: [[f64; 3]; 3],
    /// Half the box's sides along them, m.
    pub half: [f64; 3],
}

/// The lightest equivalent box drawn, kg/m³ (a light foam's density).
pub const LIGHTEST: f64 = 20.0;

impl BodyBox {
    /// The box of the body on `frame`, or `None` for a point mass (or a tensor no box has).
    pub fn of(frame: usize, body: &Mass) -> Option<BodyBox> {
        let tensor = Matrix3::from_fn(|i, j| body.inertia[i][j]);
        if body.mass.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || tensor.iter().any(|x| !x.is_finite())
        {
            return None;
        }
        let eigen = SymmetricEigen::new(tensor);
        let i = eigen.eigenvalues;
        let side2 = |k: usize| {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            (6.0 * (i[a] + i[b] - i[k]) / body.mass).max(0.0)
        };
        let half = [0, 1, 2].map(|k| 0.5 * side2(k).sqrt());
        let density = body.mass / (8.0 * half[0] * half[1] * half[2]);
        if half.iter().all(|&h| h == 0.0) || density < LIGHTEST {
            return None;
        }
        let v = eigen.eigenvectors;
        Some(BodyBox {
            frame,
            com: body.com,
            axes: [0, 1, 2].map(|r| [0, 1, 2].map(|c| v[(r, c)])),
            half,
        })
    }

    /// The box's eight corners in the world, with its frame at `pose`.
    pub fn corners(&self, pose: &Pose) -> [[f64; 3]; 8] {
        std::array::from_fn(|n| {
            let local: [f64; 3] = std::array::from_fn(|r| {
                self.com[r]
                    + (0..3)
                        .map(|c| {
                            let sign = if n >> c & 1 == 1 { 1.0 } else { -1.0 };
                            self.axes[r][c] * sign * self.half[c]
                        })
                        .sum::<f64>()
            });
            world(pose, local)
        })
    }

    /// The twelve edges, as pairs of [`BodyBox::corners`] indices.
    pub const EDGES: [(usize, usize); 12] = [
        (0, 1),
        (2, 3),
        (4, 5),
        (6, 7),
        (0, 2),
        (1, 3),
        (4, 6),
        (5, 7),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ];
}

/// `pose · x`.
pub fn world(pose: &Pose, x: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| pose.p[r] + (0..3).map(|c| pose.r[r][c] * x[c]).sum::<f64>())
}

/// A slider's rail: a frame moved along an axis of its parent by a variable and carrying a
/// body itself (a cart; a floating base's massless translations are not rails), drawn over
/// the travel the run makes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rail {
    /// The slider's parent frame (`None`: the world).
    pub parent: Option<usize>,
    /// The axis, in the parent's axes.
    pub axis: [f64; 3],
    /// The travel along it, from the parent's origin, m (with a margin either side: 15% of
    /// the travel and the body's largest side).
    pub from: f64,
    /// …to here.
    pub to: f64,
}

impl Rail {
    /// The rails of `model`'s sliders over the run whose frame poses are `pictures`.
    pub fn of(model: &Model, pictures: &[Vec<Pose>]) -> Vec<Rail> {
        let mut rails = Vec::new();
        for (k, frame) in model.frames.iter().enumerate() {
            let variable = matches!(frame.joint, Joint::Variable(_));
            if frame.primitive.is_rotation() || !variable || frame.mass.is_none() {
                continue;
            }
            let mut axis = [0.0; 3];
            axis[frame.primitive.axis()] = 1.0;
            let travel = pictures.iter().map(|poses| {
                let origin = frame.parent.map_or(Pose::IDENTITY, |p| poses[p]);
                let d: [f64; 3] = std::array::from_fn(|i| poses[k].p[i] - origin.p[i]);
                // Along the axis in the parent's axes: (Rᵀ d)·e.
                (0..3)
                    .map(|i| (0..3).map(|j| origin.r[j][i] * d[j]).sum::<f64>() * axis[i])
                    .sum::<f64>()
            });
            let (lo, hi) = travel
                .filter(|s| s.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                    (lo.min(s), hi.max(s))
                });
            if lo > hi {
                continue;
            }
            // Beyond the travel by a little of it and the body's own size: a cart at rest
            // still sits on a rail as long as itself either side.
            let size = frame.mass.as_ref().and_then(|m| BodyBox::of(k, m));
            let side = size.map_or(0.0, |b| {
                2.0 * b.half.iter().fold(0.0, |a: f64, &h| a.max(h))
            });
            let margin = 0.15 * (hi - lo) + side;
            rails.push(Rail {
                parent: frame.parent,
                axis,
                from: lo - margin,
                to: hi + margin,
            });
        }
        rails
    }

    /// The rail's two ends in the world, with the parent at its pose in `poses`.
    pub fn ends(&self, poses: &[Pose]) -> [[f64; 3]; 2] {
        let origin = self.parent.map_or(Pose::IDENTITY, |p| poses[p]);
        [self.from, self.to].map(|s| world(&origin, self.axis.map(|a| a * s)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uniform_box_is_its_own_equivalent_box() {
        // 2 kg, sides 0.2 × 0.4 × 1.0 m: I_xx = m (b² + c²)/12 and so on.
        let (m, [a, b, c]) = (2.0, [0.2f64, 0.4, 1.0]);
        let body = Mass::principal(
            m,
            [
                m * (b * b + c * c) / 12.0,
                m * (a * a + c * c) / 12.0,
                m * (a * a + b * b) / 12.0,
            ],
        );
        let found = BodyBox::of(3, &body).unwrap();
        let mut sides: Vec<f64> = found.half.iter().map(|h| 2.0 * h).collect();
        sides.sort_by(f64::total_cmp);
        for (got, want) in sides.iter().zip([a, b, c]) {
            assert!((got - want).abs() < 1e-12, "{sides:?}");
        }
        assert!(BodyBox::of(0, &Mass::point(1.0)).is_none());
        // The UR5 file's wrist: 1.219 kg with the inertia of a 1 m disc, 9 kg/m³.
        let wrist = Mass::principal(1.219, [0.111172755531, 0.111172755531, 0.21942]);
        assert!(BodyBox::of(0, &wrist).is_none());
        // The corners span the box about the centre of mass.
        let corners = found.corners(&Pose::IDENTITY);
        let span = |i: usize| {
            let xs = corners.iter().map(|p| p[i]);
            xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
        };
        for (i, want) in [a, b, c].into_iter().enumerate() {
            assert!((span(i) - want).abs() < 1e-12, "axis {i}: {}", span(i));
        }
    }

    #[test]
    fn a_cart_rides_a_rail_over_its_travel_and_its_length_either_side() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/cartpole.toml");
        let model = tree_mech::model::from_toml_file(path).unwrap();
        let at = |x: f64| {
            let mut poses = vec![Pose::IDENTITY; model.frames.len()];
            poses[0].p = [x, 0.0, 0.0];
            poses
        };
        let rails = Rail::of(&model, &[at(-0.1), at(0.3)]);
        assert_eq!(rails.len(), 1, "the cart's slide; the pole turns");
        // The cart: 1 kg, inertia 0.01 about each axis → a cube of side √0.06.
        let (travel, side) = (0.4, 0.06f64.sqrt());
        let margin = 0.15 * travel + side;
        assert_eq!(rails[0].axis, [1.0, 0.0, 0.0]);
        assert!(
            (rails[0].from - (-0.1 - margin)).abs() < 1e-12,
            "{:?}",
            rails[0]
        );
        assert!(
            (rails[0].to - (0.3 + margin)).abs() < 1e-12,
            "{:?}",
            rails[0]
        );
    }
}
