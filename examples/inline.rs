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
            frame upper = tz(-1.0) {
                mass = 1.0;
                inertia = [0.08, 0.08, 0.0];
                frame elbow = rx(theta2) {
                    frame lower = tz(-1.0) { mass = 1.0; }
                }
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

/// The example's physics, run by `cargo test` (`test = true` in Cargo.toml).
#[cfg(test)]
mod tests {
    use super::SlidingDoublePendulum as P;
    use tree_mech::nalgebra::SVector;
    use tree_mech::{Order, System};

    /// The mass matrix against its closed form: the cart (2 kg) under two unit masses on unit
    /// rods, the upper rod with Ixx = 0.08 about its hinge axis; s the slide, θ₁ and θ₂ the
    /// hinges (θ₂ from the upper rod).
    #[test]
    fn mass_matrix_is_the_cart_and_double_pendulums() {
        let mut q = SVector::<f64, 3>::zeros();
        q[P::SLIDE] = 0.1;
        q[P::THETA1] = 0.4;
        q[P::THETA2] = -0.7;
        let m = P::new().evaluate(&q, &SVector::zeros(), Order::Full).mass;
        let (t1, t2) = (0.4f64, -0.7f64);
        let (s, a, b) = (P::SLIDE, P::THETA1, P::THETA2);
        let expected = [
            (s, s, 4.0),
            (s, a, 2.0 * t1.cos() + (t1 + t2).cos()),
            (s, b, (t1 + t2).cos()),
            (a, a, 3.08 + 2.0 * t2.cos()),
            (a, b, 1.0 + t2.cos()),
            (b, b, 1.0),
        ];
        for (i, j, value) in expected {
            assert!(
                (m[(i, j)] - value).abs() < 1e-12,
                "M[{i}][{j}] = {} ≠ {value}",
                m[(i, j)]
            );
            assert!((m[(j, i)] - value).abs() < 1e-12);
        }
    }

    /// The run the example prints: damping on the slide only takes energy out, so the
    /// energy at the end is below the start, and the VI keeps it within 1e-3 J of falling.
    #[test]
    fn the_run_loses_energy_to_the_slides_damping() {
        use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
        let mut sys = P::new();
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 5.0);
        let traj = simulate(
            &mut sys,
            &q0,
            &dq0,
            &options,
            &mut tree_mech::NoForce,
            &mut |_| {},
        )
        .expect("the example runs");
        let (first, last) = (traj.energy[0], *traj.energy.last().unwrap());
        assert!(last < first, "energy {first} → {last}");
        let peak = traj.energy.iter().cloned().fold(f64::MIN, f64::max);
        assert!(peak - first < 1e-3, "energy rose by {}", peak - first);
    }
}
