//! A controller written once for any [`System`]: the compiled model (`tree_model!`, sizes
//! known at compile time) and the interpreted one (`TreeSystem`, sizes read at run time) run
//! the same code. Run: `cargo run --release --example generic`.
//!
//! nalgebra sizes a system's vectors by its dimension type `S::N` (`Const<2>` compiled,
//! `Dyn` interpreted), so code generic over `S: System` states the bound under which those
//! vectors and matrices exist — the same two lines everywhere:
//!
//! ```text
//! where
//!     DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
//! ```

use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator, Dim};
use tree_mech::runtime::Vector;
use tree_mech::{tree_model, GeneralizedForce, SimError, System, TreeSystem};

tree_model! {
    /// A double pendulum: the elbow hangs under the upper rod.
    pub struct DoublePendulum;
    frame shoulder = rx(theta1) {
        frame upper = tz(-1.0) {
            mass = 1.0;
            frame elbow = rx(theta2) {
                frame lower = tz(-1.0) { mass = 1.0; }
            }
        }
    }
    variable theta1 { q0 = 1.0; }
    variable theta2 { q0 = -0.5; }
}

/// A joint-space PD controller to `target`: `u = −Kp (q − q*) − Kd q̇`, for any dimension.
pub struct Pd {
    /// The configuration it drives to.
    pub target: Vec<f64>,
    /// Stiffness gain, N·m/rad.
    pub kp: f64,
    /// Damping gain, N·m·s/rad.
    pub kd: f64,
}

impl<N: Dim> GeneralizedForce<N> for Pd
where
    DefaultAllocator: Allocator<N>,
{
    fn add_force(&mut self, _t: f64, q: &Vector<N>, dq: &Vector<N>, u: &mut Vector<N>) {
        for i in 0..q.len() {
            u[i] += -self.kp * (q[i] - self.target[i]) - self.kd * dq[i];
        }
    }
}

/// Runs `sys` from its model's start under `controller` for `duration` s; returns the last
/// configuration. One function for compiled and interpreted systems alike.
pub fn settle<S: System>(
    sys: &mut S,
    controller: &mut Pd,
    duration: f64,
) -> Result<Vec<f64>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, duration);
    let traj = simulate(sys, &q0, &dq0, &options, controller, &mut |_| {})?;
    Ok(traj.q(traj.len() - 1).to_vec())
}

/// How long the controller is given, s.
const DURATION: f64 = 10.0;

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let pd = || Pd {
        target: vec![0.0, 0.0],
        kp: 50.0,
        kd: 20.0,
    };
    let compiled = settle(&mut DoublePendulum::new(), &mut pd(), DURATION)?;
    let interpreted = settle(
        &mut TreeSystem::new(&DoublePendulum::model())?,
        &mut pd(),
        DURATION,
    )?;
    println!("after {DURATION} s under PD to hanging rest:");
    println!(
        "  compiled    q = [{:+.3e}, {:+.3e}]",
        compiled[0], compiled[1]
    );
    println!(
        "  interpreted q = [{:+.3e}, {:+.3e}]",
        interpreted[0], interpreted[1]
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_controller_drives_compiled_and_interpreted_alike_to_rest() {
        let pd = || Pd {
            target: vec![0.0, 0.0],
            kp: 50.0,
            kd: 20.0,
        };
        let compiled = settle(&mut DoublePendulum::new(), &mut pd(), DURATION).unwrap();
        let mut interpreted = TreeSystem::new(&DoublePendulum::model()).unwrap();
        let interpreted = settle(&mut interpreted, &mut pd(), DURATION).unwrap();
        for i in 0..2 {
            assert!((compiled[i] - interpreted[i]).abs() < 1e-12);
            // Started 1 rad out; a PD with this damping brings it to rest under gravity.
            assert!(compiled[i].abs() < 1e-6, "{compiled:?}");
        }
        // Uncontrolled, it keeps swinging (the controller is what brought it to rest).
        let free = settle(
            &mut DoublePendulum::new(),
            &mut Pd {
                target: vec![0.0; 2],
                kp: 0.0,
                kd: 0.0,
            },
            DURATION,
        )
        .unwrap();
        assert!(free[0].abs() + free[1].abs() > 1e-2, "{free:?}");
    }
}
