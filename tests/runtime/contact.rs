//! Contact in the variational integrator (docs/derivations.md §13): analytic cases.

use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::model::{self, Model};
use tree_mech::{NoForce, System, TreeSystem};

fn load(path: &str) -> Model {
    model::from_toml_file(path).unwrap()
}

fn vi(dt: f64, duration: f64) -> SimOptions {
    SimOptions::new(Method::Vi(ViSettings::default()), dt, duration)
}

/// A ball dropped from 1 m above the ground touches it at √(2h/g) and rests at its radius.
#[test]
fn a_dropped_ball_lands_on_time_and_rests_at_its_radius() {
    let model = load("tests/models/ball.toml");
    let mut sys = TreeSystem::new(&model).unwrap();
    let (q0, dq0) = sys.initial_state();
    let dt = 1e-3;
    let traj = simulate(&mut sys, &q0, &dq0, &vi(dt, 1.0), &mut NoForce, &mut |_| {}).unwrap();
    let z: Vec<f64> = (0..traj.len()).map(|k| traj.q(k)[2]).collect();
    let landing = (0..z.len()).find(|&k| z[k] <= 0.1 + 1e-9).unwrap();
    let expected = (2.0 * 1.0 / 9.81f64).sqrt();
    let t = traj.t[landing];
    eprintln!("landed at {t} (expected {expected}), rests at {}", z.last().unwrap());
    assert!((t - expected).abs() <= 2.0 * dt, "landed at {t}, expected {expected}");
    let lowest = z.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(lowest >= 0.1 - 1e-9, "penetrated to {lowest}");
    assert!((z.last().unwrap() - 0.1).abs() <= 1e-9, "rests at {}", z.last().unwrap());
}
