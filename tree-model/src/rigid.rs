//! Rigid bodies as the dynamics sees them: the bodies of frames joined by constant transforms
//! move as one, fused about their centre of mass as Pinocchio fuses links across fixed
//! joints — so a 1 µg placeholder link with a made-up tensor on a fixed joint is not the
//! robot's problem when the body it is welded into is physical.

use std::collections::HashMap;

use crate::model::{Frame, Joint, Mass};
use crate::primitive::PrimitiveKind;

type Rotation = [[f64; 3]; 3];

/// A constant pose: `x ↦ R x + p`.
#[derive(Clone, Copy)]
struct Pose {
    r: Rotation,
    p: [f64; 3],
}

const IDENTITY: Pose = Pose {
    r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    p: [0.0; 3],
};

impl Pose {
    /// The primitive `kind` at the constant `x` (paper eq. (1)'s six transforms).
    fn primitive(kind: PrimitiveKind, x: f64) -> Pose {
        let mut pose = IDENTITY;
        let a = kind.axis();
        if kind.is_rotation() {
            let (s, c) = x.sin_cos();
            let (i, j) = ((a + 1) % 3, (a + 2) % 3);
            pose.r[i][i] = c;
            pose.r[j][j] = c;
            pose.r[i][j] = -s;
            pose.r[j][i] = s;
        } else {
            pose.p[a] = x;
        }
        pose
    }

    /// `self ∘ inner`.
    fn then(&self, inner: &Pose) -> Pose {
        let r = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| self.r[i][k] * inner.r[k][j]).sum())
        });
        Pose {
            r,
            p: self.apply(inner.p),
        }
    }

    fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| self.p[i] + (0..3).map(|k| self.r[i][k] * x[k]).sum::<f64>())
    }

    /// `R I Rᵀ`.
    fn turn(&self, inertia: &Rotation) -> Rotation {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                (0..3)
                    .flat_map(|k| (0..3).map(move |l| (k, l)))
                    .map(|(k, l)| self.r[i][k] * inertia[k][l] * self.r[j][l])
                    .sum()
            })
        })
    }
}

/// Each frame's rigid group: the nearest frame at or above it driven by a variable (`None`:
/// welded to the world), and its constant pose in that frame.
fn groups(frames: &[Frame]) -> Vec<(Option<usize>, Pose)> {
    let mut out: Vec<(Option<usize>, Pose)> = Vec::with_capacity(frames.len());
    for f in frames {
        out.push(match f.joint {
            Joint::Variable(_) | Joint::Mimic(_) => (None, IDENTITY), // its own root, set below
            Joint::Constant(x) => {
                let (root, above) = f.parent.map_or((None, IDENTITY), |p| out[p]);
                (root, above.then(&Pose::primitive(f.primitive, x)))
            }
        });
        if let Joint::Variable(_) | Joint::Mimic(_) = f.joint {
            let k = out.len() - 1;
            out[k].0 = Some(k);
        }
    }
    out
}

/// For each frame of `pieces` (each carrying a body), the rigid body it belongs to, fused
/// about its centre of mass in its group root's axes, and the frames with a body it fuses
/// (in order, the piece among them). One pass over the tree, whatever the pieces.
pub(crate) fn fused_bodies(frames: &[Frame], pieces: &[usize]) -> Vec<(Mass, Vec<usize>)> {
    let groups = groups(frames);
    let mut parts: HashMap<Option<usize>, Vec<(usize, Mass, Pose)>> = HashMap::new();
    for (k, f) in frames.iter().enumerate() {
        if let Some(body) = f.mass {
            parts
                .entry(groups[k].0)
                .or_default()
                .push((k, body, groups[k].1));
        }
    }
    pieces
        .iter()
        .map(|&k| {
            let group = &parts[&groups[k].0];
            (fuse(group), group.iter().map(|p| p.0).collect())
        })
        .collect()
}

/// `Σ` of bodies at constant poses: total mass, centre of mass, and
/// `Σ R I Rᵀ + m (|d|² 1 − d dᵀ)` about it (the parallel-axis theorem).
fn fuse(parts: &[(usize, Mass, Pose)]) -> Mass {
    let total: f64 = parts.iter().map(|p| p.1.mass).sum();
    let coms: Vec<[f64; 3]> = parts.iter().map(|(_, m, pose)| pose.apply(m.com)).collect();
    let com: [f64; 3] = std::array::from_fn(|i| {
        let moment: f64 = parts.iter().zip(&coms).map(|(p, c)| p.1.mass * c[i]).sum();
        if total > 0.0 {
            moment / total
        } else {
            0.0
        }
    });
    let mut inertia = [[0.0; 3]; 3];
    for ((_, body, pose), c) in parts.iter().zip(&coms) {
        let turned = pose.turn(&body.inertia);
        let d: [f64; 3] = std::array::from_fn(|i| c[i] - com[i]);
        let d2: f64 = d.iter().map(|x| x * x).sum();
        for i in 0..3 {
            for j in 0..3 {
                let shift = if i == j { d2 } else { 0.0 } - d[i] * d[j];
                inertia[i][j] += turned[i][j] + body.mass * shift;
            }
        }
    }
    Mass {
        mass: total,
        com,
        inertia,
    }
}
