//! Convergence does not depend on the units: scaling every mass, inertia, stiffness and
//! damping of a model by `s` leaves its trajectory unchanged (q, q̇) and scales its momenta and
//! constraint forces by `s`. The VI's Newton test is relative to each row's momentum scale;
//! with an absolute one a 1e-13 kg pendulum stood still.

use crate::common;

use common::load;
use tree_mech::integrate::{Method, SimOptions, ViSettings};
use tree_mech::model::{self, Model};
use tree_mech::runtime::TreeSystem;
use tree_mech::Trajectory;

/// The model with every inertial and force parameter multiplied by `s`.
fn scaled(model: &Model, s: f64) -> Model {
    let mut m = model.clone();
    for f in &mut m.frames {
        if let Some(body) = &mut f.mass {
            body.mass *= s;
            body.inertia.iter_mut().flatten().for_each(|i| *i *= s);
        }
    }
    for v in &mut m.variables {
        v.damping *= s;
    }
    m.springs.iter_mut().for_each(|k| k.stiffness *= s);
    m.dampers.iter_mut().for_each(|d| d.damping *= s);
    m
}

fn run(model: &Model, method: Method, steps: usize) -> Trajectory {
    let mut sys = TreeSystem::new(model).unwrap();
    let options = SimOptions::new(method, 0.01, steps as f64 * 0.01);
    common::simulate_from_start(&mut sys, &options)
}

/// Every sample of `a` equals `b`'s to `tol` relative to the largest magnitude in `b`.
#[track_caller]
fn assert_rows_close(a: &[Vec<f64>], b: &[Vec<f64>], tol: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: sample counts");
    let scale = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for (k, (ra, rb)) in a.iter().zip(b).enumerate() {
        for (i, (x, y)) in ra.iter().zip(rb).enumerate() {
            assert!(
                (x - y).abs() <= tol * scale,
                "{what} of sample {k}, entry {i}: {x} vs {y} (scale {scale:e})"
            );
        }
    }
}

/// Each sample's `f` as a row, divided by `s`.
fn rows(t: &Trajectory, s: f64, f: impl Fn(&Trajectory, usize) -> Vec<f64>) -> Vec<Vec<f64>> {
    (0..t.len())
        .map(|k| f(t, k).iter().map(|x| x / s).collect())
        .collect()
}

fn assert_same_motion(model: &Model, method: Method, steps: usize) {
    let base = run(model, method, steps);
    assert_eq!(base.len(), steps + 1);
    for s in [1e-12, 1e12] {
        let other = run(&scaled(model, s), method, steps);
        let what = |x: &str| format!("{} with masses ×{s:e}: {x}", model.name);
        let q = |t: &Trajectory, k| t.q(k).to_vec();
        let dq = |t: &Trajectory, k| t.dq(k).to_vec();
        let lambda = |t: &Trajectory, k| t.lambda(k).to_vec();
        let energy = |t: &Trajectory, k: usize| vec![t.energy[k]];
        assert_rows_close(
            &rows(&other, 1.0, q),
            &rows(&base, 1.0, q),
            1e-9,
            &what("q"),
        );
        assert_rows_close(
            &rows(&other, 1.0, dq),
            &rows(&base, 1.0, dq),
            1e-9,
            &what("q̇"),
        );
        // Forces and energies scale with the masses.
        assert_rows_close(
            &rows(&other, s, lambda),
            &rows(&base, 1.0, lambda),
            1e-9,
            &what("λ/s"),
        );
        assert_rows_close(
            &rows(&other, s, energy),
            &rows(&base, 1.0, energy),
            1e-9,
            &what("E/s"),
        );
    }
}

fn models() -> Vec<Model> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut v: Vec<Model> = ["pendulum.toml", "double-pendulum.toml", "free-body.toml"]
        .into_iter()
        .map(load)
        .collect();
    for file in ["tests/models/elements.toml", "tests/models/bodies.toml"] {
        v.push(model::from_toml_file(dir.join(file)).unwrap());
    }
    v.push(model::from_urdf_file(dir.join("models/ur5.urdf"), Default::default()).unwrap());
    v
}

#[test]
fn vi_trajectories_do_not_depend_on_the_mass_unit() {
    for model in models() {
        assert_same_motion(&model, Method::Vi(ViSettings::default()), 200);
    }
}

#[test]
fn the_marionette_moves_the_same_in_milligrams_and_in_megatonnes() {
    assert_same_motion(
        &load("marionette.toml"),
        Method::Vi(ViSettings::default()),
        100,
    );
}

#[test]
fn rk4_trajectories_do_not_depend_on_the_mass_unit() {
    for model in models() {
        assert_same_motion(&model, Method::Rk4, 200);
    }
}

#[test]
fn a_pendulum_of_a_tenth_of_a_picogram_swings_like_one_of_a_kilogram() {
    // The probe's case: θ stood still under the VI with an absolute tolerance.
    let base = load("pendulum.toml");
    let light = scaled(&base, 1e-13);
    let method = Method::Vi(ViSettings::default());
    let (a, b) = (run(&light, method, 100), run(&base, method, 100));
    let (qa, qb) = (a.last_q()[0], b.last_q()[0]);
    assert!((qb - b.q(0)[0]).abs() > 0.1, "the reference swings");
    assert!((qa - qb).abs() < 1e-9, "{qa} vs {qb}");
}
