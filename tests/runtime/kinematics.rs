//! `runtime::kinematics` on every shipped model (every primitive, point and full bodies,
//! kinematic variables) and a URDF robot, against finite differences of its own poses and
//! velocities along a path `q(t) = q + t q̇ + ½t² q̈`: each frame's velocity is the rate of
//! its pose, its Jacobian times q̇ is that velocity in every reference, its spatial
//! acceleration is the rate of its body twist and its classical acceleration the second
//! rate of its origin; the centre of mass likewise. Pinocchio's numbers for the same
//! functions are in tests/pinocchio.rs.

use crate::common;

use common::{model_files, Rng};
use tree_mech::model::{self, Model, UrdfOptions};
use tree_mech::runtime::kinematics::{Kinematics, Reference};
use tree_mech::runtime::Pose;

const REFERENCES: [Reference; 3] = [
    Reference::Local,
    Reference::LocalWorldAligned,
    Reference::World,
];

/// The state at time `t` along the path.
fn at(k: &mut Kinematics, q: &[f64], dq: &[f64], ddq: &[f64], t: f64) {
    let qt: Vec<f64> = (0..q.len())
        .map(|i| q[i] + t * dq[i] + 0.5 * t * t * ddq[i])
        .collect();
    let dqt: Vec<f64> = (0..q.len()).map(|i| dq[i] + t * ddq[i]).collect();
    k.update(&qt, Some(&dqt), Some(ddq)).unwrap();
}

/// `ω` with `R_b R_aᵀ ≈ I + [ω]× Δ` over the step `Δ` between two poses (world axes).
fn angular_rate(a: &Pose, b: &Pose, step: f64) -> [f64; 3] {
    let m = |i: usize, j: usize| (0..3).map(|k| b.r[i][k] * a.r[j][k]).sum::<f64>();
    [
        (m(2, 1) - m(1, 2)) / (2.0 * step),
        (m(0, 2) - m(2, 0)) / (2.0 * step),
        (m(1, 0) - m(0, 1)) / (2.0 * step),
    ]
}

#[track_caller]
fn near(a: f64, b: f64, scale: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-6 * scale.max(1.0),
        "{what}: {a} against differences {b}"
    );
}

fn check(m: &Model, label: &str) {
    let n = m.variables.len();
    let mut k = Kinematics::new(m).unwrap();
    let mut rng = Rng::new(17);
    let q: Vec<f64> = rng.vector(n, 1.0).iter().copied().collect();
    let dq: Vec<f64> = rng.vector(n, 1.0).iter().copied().collect();
    let ddq: Vec<f64> = rng.vector(n, 1.0).iter().copied().collect();
    let h = 1e-5;
    let frames = m.frames.len();
    let snapshot = |k: &Kinematics| {
        let poses: Vec<Pose> = (0..frames).map(|f| k.pose(f)).collect();
        let local: Vec<[f64; 6]> = (0..frames)
            .map(|f| k.velocity(f, Reference::Local))
            .collect();
        let aligned: Vec<[f64; 6]> = (0..frames)
            .map(|f| k.velocity(f, Reference::LocalWorldAligned))
            .collect();
        (poses, local, aligned, k.center_of_mass())
    };
    at(&mut k, &q, &dq, &ddq, -h);
    let before = snapshot(&k);
    at(&mut k, &q, &dq, &ddq, h);
    let after = snapshot(&k);
    at(&mut k, &q, &dq, &ddq, 0.0);
    let rate = |a: f64, b: f64| (b - a) / (2.0 * h);
    for f in 0..frames {
        let name = &m.frames[f].name;
        let what = |x: &str| format!("{label}: `{name}`'s {x}");
        // The velocity is the rate of the pose (world axes at the origin).
        let v = k.velocity(f, Reference::LocalWorldAligned);
        let (pa, pb) = (&before.0[f], &after.0[f]);
        let w = angular_rate(pa, pb, 2.0 * h);
        for r in 0..3 {
            near(v[r], rate(pa.p[r], pb.p[r]), 1.0, &what("origin velocity"));
            near(v[3 + r], w[r], 1.0, &what("angular velocity"));
        }
        // J q̇ is the velocity in every reference.
        for reference in REFERENCES {
            let j = k.jacobian(f, reference);
            let v = k.velocity(f, reference);
            for r in 0..6 {
                let jv: f64 = (0..n).map(|c| j[(r, c)] * dq[c]).sum();
                assert!(
                    (jv - v[r]).abs() <= 1e-12 * (1.0 + v[r].abs()),
                    "{}: {jv} vs {}",
                    what(&format!("{reference:?} J q̇")),
                    v[r]
                );
            }
        }
        // The spatial acceleration is the rate of the twist in the frame's own axes; the
        // classical one the rate of the origin's velocity.
        let a = k.acceleration(f, Reference::Local);
        let classical = k.classical_acceleration(f);
        for r in 0..6 {
            near(
                a[r],
                rate(before.1[f][r], after.1[f][r]),
                1.0,
                &what("spatial acceleration"),
            );
        }
        for r in 0..3 {
            near(
                classical[r],
                rate(before.2[f][r], after.2[f][r]),
                1.0,
                &what("classical acceleration"),
            );
        }
    }
    let com = k.center_of_mass();
    let jcom = k.com_jacobian();
    let (ca, cb) = (&before.3, &after.3);
    assert!(com.mass > 0.0, "{label}: mass");
    for r in 0..3 {
        near(
            com.velocity[r],
            rate(ca.position[r], cb.position[r]),
            1.0,
            &format!("{label}: centre of mass velocity"),
        );
        near(
            com.acceleration[r],
            rate(ca.velocity[r], cb.velocity[r]),
            1.0,
            &format!("{label}: centre of mass acceleration"),
        );
        let jv: f64 = (0..n).map(|c| jcom[(r, c)] * dq[c]).sum();
        assert!(
            (jv - com.velocity[r]).abs() <= 1e-12 * (1.0 + jv.abs()),
            "{label}: J_com q̇ {jv} vs ċ {}",
            com.velocity[r]
        );
    }
}

#[test]
fn every_shipped_model_matches_differences_of_its_poses() {
    for path in model_files() {
        let m = model::from_toml_file(&path).unwrap();
        check(&m, &path.display().to_string());
    }
}

#[test]
fn a_floating_urdf_robot_matches_differences_of_its_poses() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/solo12.urdf");
    let m = model::from_file(
        path,
        UrdfOptions {
            floating_base: true,
            ..Default::default()
        },
    )
    .unwrap();
    check(&m, "solo12");
}

/// Bad input is a sentence naming it, never a panic.
#[test]
fn bad_input_is_a_clear_error() {
    let m = common::load("double-pendulum.toml");
    let mut k = Kinematics::new(&m).unwrap();
    let e = k.frame("hand").unwrap_err().to_string();
    assert!(
        e.contains("there is no frame `hand`; the frames are `"),
        "{e}"
    );
    let e = k.update(&[0.0], None, None).unwrap_err().to_string();
    assert!(
        e.contains("q has 1 entry; the model has 2 variables"),
        "{e}"
    );
    let e = k
        .update(&[0.0, 0.0], Some(&[0.0, f64::NAN]), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("q̇'s entry 1 (`theta2`) is NaN, not a finite number"),
        "{e}"
    );
    assert_eq!(Reference::parse("World"), Some(Reference::World));
    assert_eq!(Reference::parse("body"), None);
}
