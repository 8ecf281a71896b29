//! trep's own Puppet (tools/reference/trep-puppet.toml, written from
//! `trep.puppets.Puppet(string_constraints=True)`) against trep 1.0.2's midpoint VI: the
//! configuration every 10 of 100 steps from rest, from tests/fixtures/trep-puppet.json
//! (tools/reference/trep_puppet.py). trep's forcing is `left`; its Newton tolerance is
//! absolute, ours relative, so the two agree to the solvers' tolerance, not to rounding.

use tree_mech::integrate::{simulate, Forcing, Method, SimOptions, ViSettings};
use tree_mech::{model, tree_model, NoForce, System, TreeSystem};

tree_model!(struct TrepPuppet from "tools/reference/trep-puppet.toml");

fn fixture() -> serde_json::Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/trep-puppet.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn check<S: System>(sys: &mut S, what: &str)
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let reference = fixture();
    let names: Vec<&str> = reference["variables"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 40);
    let index: Vec<usize> = names
        .iter()
        .map(|n| {
            (0..sys.dof())
                .find(|&i| sys.variable_name(i) == *n)
                .unwrap()
        })
        .collect();
    let settings = ViSettings {
        forcing: Forcing::Left,
        ..ViSettings::default()
    };
    let options = SimOptions::new(Method::Vi(settings), 0.01, 1.0);
    let (q0, dq0) = sys.initial_state();
    let traj = simulate(sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
    let mut worst = 0.0f64;
    let mut moved = 0.0f64;
    for sample in reference["samples"].as_array().unwrap() {
        let step = sample["step"].as_u64().unwrap() as usize;
        assert!((traj.t[step] - sample["t"].as_f64().unwrap()).abs() < 1e-12);
        for (k, q) in sample["q"].as_array().unwrap().iter().enumerate() {
            let (ours, theirs) = (traj.q(step)[index[k]], q.as_f64().unwrap());
            worst = worst.max((ours - theirs).abs());
            moved = moved.max((theirs - q0[index[k]]).abs());
        }
    }
    assert!(moved > 0.05, "{what}: the puppet moves ({moved})");
    assert!(worst < 1e-9, "{what}: q differs from trep's by {worst:e}");
}

/// The Puppet read at run time from its TOML file.
fn interpreted_puppet() -> TreeSystem {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tools/reference/trep-puppet.toml"
    );
    TreeSystem::new(&model::from_toml_file(path).unwrap()).unwrap()
}

#[test]
fn the_puppet_moves_as_trep_moves_it_interpreted() {
    let mut sys = interpreted_puppet();
    check(&mut sys, "interpreted");
}

#[test]
fn the_puppet_moves_as_trep_moves_it_compiled() {
    check(&mut TrepPuppet, "compiled");
}

/// From rest, the Puppet's light limbs hang with rows whose terms are far smaller than the
/// torques summed into them: at short steps the residual's rounding floor lies above the
/// relative tolerance (at Δt = 10⁻³ about 6·10⁻¹¹, growing as 1/Δt²). Newton must recognise
/// the floor (an exact update that cannot lower the residual) instead of failing the step —
/// here with subdivision off, so a failed step is an error.
fn short_steps_converge<S: System>(sys: &mut S, what: &str)
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    for dt in [1e-3, 1e-4, 1e-5] {
        let settings = ViSettings {
            max_subdivisions: 0,
            ..ViSettings::default()
        };
        let options = SimOptions::new(Method::Vi(settings), dt, 20.0 * dt);
        let traj = simulate(sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})
            .unwrap_or_else(|e| panic!("{what}, Δt = {dt}: {e}"));
        assert_eq!(traj.t.len(), 21, "{what}, Δt = {dt}");
        let violation = traj.violation.iter().fold(0.0f64, |m, &v| m.max(v));
        assert!(
            violation < 1e-12,
            "{what}, Δt = {dt}: violation {violation:e}"
        );
    }
}

#[test]
fn the_puppet_steps_from_rest_at_short_steps_interpreted() {
    let mut sys = interpreted_puppet();
    short_steps_converge(&mut sys, "interpreted");
}

#[test]
fn the_puppet_steps_from_rest_at_short_steps_compiled() {
    short_steps_converge(&mut TrepPuppet, "compiled");
}
