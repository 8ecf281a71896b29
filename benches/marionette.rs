//! The marionette (models/marionette.toml, 42 variables, six strings) and trep's own Puppet
//! (tools/reference/trep-puppet.toml, 40 variables, six strings): 10 s at Δt = 0.01 with the
//! VI and with RK4, compiled by `tree_model!` and interpreted, side by side in one run (best of
//! 7 runs each). Prints a Markdown table. Run: `cargo bench --bench marionette`.

use std::time::Instant;

use tree_mech::integrate::{run, Method, SimOptions, ViSettings};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::ModelMotions;
use tree_mech::{tree_model, NoForce, System, TreeSystem};

tree_model!(struct Marionette from "models/marionette.toml");
tree_model!(struct TrepPuppet from "tools/reference/trep-puppet.toml");

/// Best wall time of 10 s of `method`, in ms, and the Newton iterations per step.
fn ten_seconds<S: System>(sys: &mut S, method: Method) -> (f64, f64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(method, 0.01, 10.0);
    let (mut best, mut iterations) = (f64::INFINITY, 0.0);
    for _ in 0..7 {
        let mut motion = ModelMotions::of(sys);
        let start = Instant::now();
        let summary = run(
            sys,
            &q0,
            &dq0,
            &options,
            &mut NoForce,
            &mut motion,
            &mut |_| Ok(()),
        )
        .expect("the marionette runs");
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
        iterations = summary.newton_iterations as f64 / summary.steps as f64;
    }
    (best, iterations)
}

fn main() {
    println!("| 10 s, Δt = 0.01 | compiled [ms] | interpreted [ms] | interpreted / compiled | compiled per step [µs] | interpreted per step [µs] | Newton iterations / step |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    rows("marionette", &mut Marionette, &Marionette::model());
    rows("trep's Puppet", &mut TrepPuppet, &TrepPuppet::model());
}

/// The VI and RK4 rows for one model, compiled (`sys`) and interpreted (from `model`).
fn rows<S: System>(name: &str, sys: &mut S, model: &tree_mech::model::Model)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut interpreted = TreeSystem::new(model).expect("valid model");
    for (label, method) in [
        ("midpoint VI", Method::Vi(ViSettings::default())),
        ("RK4", Method::Rk4),
    ] {
        let (c, iterations) = ten_seconds(sys, method);
        let (i, _) = interpreted_ten_seconds(&mut interpreted, method);
        let newton = if iterations > 0.0 {
            format!("{iterations:.2}")
        } else {
            "—".into()
        };
        // 1000 steps: ms per run = µs per step.
        println!(
            "| {name}, {label} | {c:.1} | {i:.1} | {:.1}× | {c:.1} | {i:.1} | {newton} |",
            i / c
        );
    }
}

/// [`ten_seconds`] on the interpreted system (outside `rows`, whose allocator bounds on a
/// generic `S` would hide `Dyn`'s).
fn interpreted_ten_seconds(sys: &mut TreeSystem, method: Method) -> (f64, f64) {
    ten_seconds(sys, method)
}
