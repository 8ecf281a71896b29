//! Declare a model inline with `tree_model!`, simulate it with the variational integrator and
//! print a few samples. Run: `cargo run --release --example inline`.

use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::{tree_model, NoForce, System};

tree_model! {
    /// A double pendulum hanging from a joint that can also slide sideways.
    pub struct SlidingDoublePendulum;
    gravity = [0.0, 0.0, -9.81];
    frame cart = ty(slide) {
        mass = 2.0;
        frame shoulder = rx(theta1) {
            frame upper = tz(-1.0) { mass = 1.0; inertia = [0.08, 0.08, 0.0]; }
            frame elbow = rx(theta2) {
                frame lower = tz(-1.0) { mass = 1.0; }
            }
        }
    }
    variable theta1 { q0 = 1.0; }
    variable theta2 { q0 = -0.5; dq0 = 0.5; }
    variable slide { damping = 0.2; }
}

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let mut sys = SlidingDoublePendulum::new();
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 0.01,
        duration: 5.0,
        ..Default::default()
    };
    let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})?;
    println!("t       slide     theta1    theta2    energy");
    for k in (0..traj.len()).step_by(50) {
        let q = traj.q(k);
        println!(
            "{:<6.2}  {:>8.4}  {:>8.4}  {:>8.4}  {:>10.6}",
            traj.t[k],
            q[SlidingDoublePendulum::SLIDE],
            q[SlidingDoublePendulum::THETA1],
            q[SlidingDoublePendulum::THETA2],
            traj.energy[k]
        );
    }
    println!(
        "{} steps, {:.2} Newton iterations per step; {} straight-line statements per full evaluation",
        traj.len() - 1,
        traj.newton_iterations as f64 / (traj.len() - 1) as f64,
        SlidingDoublePendulum::STATEMENTS
    );
    Ok(())
}
