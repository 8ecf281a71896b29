//! The contact forces of a sample as arrows in world space (`simulate --animate --forces`):
//! each unilateral row's impulse turned back into the force on the body it acts on, from
//! the gap it belongs to (docs/derivations.md §13). A ground contact pushes along the
//! ground's normal `γ n` and rubs along its tangents `b₁ t₁ + b₂ t₂`, at the sphere's lowest
//! point; two spheres push apart along the line between their centres, at the point where
//! they touch (one arrow on each); a slack string pulls its two ends together. A limit acts
//! in a joint, not at a point, and is not drawn. Impulses over the step are forces times Δt:
//! the arrows are scaled to the largest of the run, so Δt drops out.

use tree_mech::model::{GapKind, Model};
use tree_mech::runtime::Pose;

/// A force `force` (any consistent unit: the picture scales it) at the world point `at`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arrow {
    pub at: [f64; 3],
    pub force: [f64; 3],
}

fn scaled(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|x| s * x)
}

fn plus(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn minus(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `d / ‖d‖`, or `None` for a zero `d`.
fn direction(d: [f64; 3]) -> Option<[f64; 3]> {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    (n > 0.0).then(|| scaled(d, 1.0 / n))
}

/// A contact sphere's radius by its frame (0 for a frame without one).
fn radius(model: &Model, frame: usize) -> f64 {
    (model.contacts.spheres.iter())
        .find(|s| s.frame == frame)
        .map_or(0.0, |s| s.radius)
}

/// The arrows of one sample: the frames at `poses`, the unilateral rows' `impulse` (in the
/// rows' order, [`Model::gaps`]). Rows without impulse draw nothing.
pub fn arrows(model: &Model, poses: &[Pose], impulse: &[f64]) -> Vec<Arrow> {
    let mut out = Vec::new();
    let mut row = 0;
    for gap in model.gaps() {
        let (gamma, rows) = (impulse.get(row).copied().unwrap_or(0.0), gap.rows());
        let friction = |k: usize| impulse.get(row + k).copied().unwrap_or(0.0);
        match &gap.kind {
            GapKind::Ground {
                frame,
                radius,
                ground,
                tangents,
            } if gamma != 0.0 || (rows == 3 && (friction(1) != 0.0 || friction(2) != 0.0)) => {
                let n = ground.normal;
                let mut force = scaled(n, gamma);
                if rows == 3 {
                    force = plus(force, scaled(tangents[0], friction(1)));
                    force = plus(force, scaled(tangents[1], friction(2)));
                }
                let at = minus(poses[*frame].p, scaled(n, *radius));
                out.push(Arrow { at, force });
            }
            GapKind::Spheres { frames: [a, b], .. } if gamma != 0.0 => {
                let (pa, pb) = (poses[*a].p, poses[*b].p);
                if let Some(u) = direction(minus(pa, pb)) {
                    let at = minus(pa, scaled(u, radius(model, *a)));
                    out.push(Arrow {
                        at,
                        force: scaled(u, gamma),
                    });
                    out.push(Arrow {
                        at,
                        force: scaled(u, -gamma),
                    });
                }
            }
            GapKind::String { frames: [a, b], .. } if gamma != 0.0 => {
                let (pa, pb) = (poses[*a].p, poses[*b].p);
                if let Some(u) = direction(minus(pb, pa)) {
                    out.push(Arrow {
                        at: pa,
                        force: scaled(u, gamma),
                    });
                    out.push(Arrow {
                        at: pb,
                        force: scaled(u, -gamma),
                    });
                }
            }
            _ => {}
        }
        row += rows;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use tree_mech::{System, TreeSystem};

    /// The ball of tests/models/ball.toml resting on the ground with impulse `(γ, b₁, b₂)`:
    /// one arrow at its lowest point, `γ` up plus the friction along the ground's tangents.
    #[test]
    fn a_ground_contact_pushes_up_at_the_sphere_s_lowest_point() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/ball.toml");
        let model = tree_mech::model::from_toml_file(path).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let (mut q, _) = sys.initial_state();
        q[2] = 0.1;
        let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
        sys.poses(&q, &mut poses);
        let gap = &model.gaps()[0];
        let GapKind::Ground { tangents, .. } = gap.kind else {
            panic!("the ball's row is a ground contact");
        };
        let drawn = arrows(&model, &poses, &[2.0, 0.5, -0.25]);
        assert_eq!(drawn.len(), 1);
        let expected = plus(
            [0.0, 0.0, 2.0],
            plus(scaled(tangents[0], 0.5), scaled(tangents[1], -0.25)),
        );
        for k in 0..3 {
            assert!((drawn[0].force[k] - expected[k]).abs() < 1e-15);
        }
        assert!(drawn[0].at[2].abs() < 1e-15, "at {:?}", drawn[0].at);
        assert!(arrows(&model, &poses, &[0.0; 3]).is_empty());
    }
}
