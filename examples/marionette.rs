//! The marionette compiled with `tree_model!`, its strings driven from Rust: the puppeteer
//! here walks the puppet forward (the control bar moves along y at 5 cm/s) while it marches
//! as the model file prescribes. Prints a few samples and what the run cost.
//!
//! Run: `cargo run --release --example marionette`.

use std::time::Instant;

use tree_mech::integrate::{run, Method, SimOptions, ViSettings};
use tree_mech::runtime::{ModelMotions, Prescription};
use tree_mech::{tree_model, NoForce, System};

tree_model!(pub struct Marionette from "models/marionette.toml");

/// The file's motions, with every control point's y carried forward at `speed`.
struct WalkForward {
    file: ModelMotions,
    speed: f64,
}

impl Prescription for WalkForward {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        let [q, v, a] = self.file.kinematic(i, t);
        // Asked for kinematic variables only: the control points' y (`left_hand_y`, …).
        if Marionette::KINEMATIC[i] && Marionette::VARIABLES[i].ends_with("_y") {
            // Start at rest: the walk ramps in smoothly, s(t) = speed·(t − (1 − e^{−t})).
            let e = (-t).exp();
            [
                q + self.speed * (t - 1.0 + e),
                v + self.speed * (1.0 - e),
                a + self.speed * e,
            ]
        } else {
            [q, v, a]
        }
    }
}

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let mut sys = Marionette::new();
    let (q0, dq0) = sys.initial_state();
    let mut strings = WalkForward {
        file: ModelMotions::of(&sys),
        speed: 0.05,
    };
    let options = SimOptions {
        every: 100,
        ..SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 10.0)
    };
    println!("   t    torso y   torso z   left knee  right knee  |h|max     λ left hand");
    let start = Instant::now();
    let summary = run(
        &mut sys,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut strings,
        &mut |s| {
            println!(
                "{:>5.1}  {:>8.4}  {:>8.4}  {:>9.4}  {:>10.4}  {:>8.1e}  {:>8.4}",
                s.t,
                s.q[Marionette::TORSO_Y],
                s.q[Marionette::TORSO_Z],
                s.q[Marionette::LEFT_KNEE],
                s.q[Marionette::RIGHT_KNEE],
                s.violation,
                s.lambda[1],
            );
            Ok(())
        },
    )?;
    println!(
        "{} VI steps of {} variables ({} prescribed, {} strings) in {:.1} ms; \
         {:.2} Newton iterations a step; worst violation {:.1e}",
        summary.steps,
        Marionette::DOF,
        Marionette::KINEMATIC.iter().filter(|&&k| k).count(),
        Marionette::CONSTRAINTS.len(),
        start.elapsed().as_secs_f64() * 1e3,
        summary.newton_iterations as f64 / summary.steps as f64,
        summary.worst_violation
    );
    Ok(())
}
