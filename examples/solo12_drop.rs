//! The Solo-12 dropped on the ground: a floating base, four point-like feet (spheres of
//! 1.6 cm) on the ground with μ = 0.8, every joint held towards a crouch by PD gains (a
//! spring `k(q* − q)` and a damper `−c q̇` on each joint: exact inside the variational
//! integrator's Newton matrix). It falls 5 cm, lands on its four feet, and stands.
//! Run: `cargo run --release --example solo12_drop`.

use std::time::Instant;

use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::model::{self, ContactSpec, ContactsSpec, GroundSpec, Spring, SpringKind};
use tree_mech::{NoForce, SimError, System, Trajectory, TreeSystem};

/// The feet, their radius (m) and the ground's friction.
const FEET: [&str; 4] = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"];
const RADIUS: f64 = 0.016;
const FRICTION: f64 = 0.8;

/// The crouch the joints are held towards (HAA, HFE, KFE per leg; front legs bend forward).
const CROUCH: [f64; 12] = [
    0.0, 0.8, -1.6, 0.0, 0.8, -1.6, 0.0, -0.8, 1.6, 0.0, -0.8, 1.6,
];
/// PD gains: N·m/rad and N·m·s/rad.
const KP: f64 = 10.0;
const KD: f64 = 0.3;

/// The Solo-12 with a floating base, the ground, its feet and PD-held joints, started in the
/// crouch with its lowest foot `drop` above the ground.
pub fn solo12(drop: f64) -> Result<(model::Model, Vec<f64>), String> {
    let options = model::UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    let robot = model::from_urdf_file("models/solo12.urdf", options).map_err(|e| e.to_string())?;
    let contacts = ContactsSpec {
        ground: Some(GroundSpec {
            friction: Some(FRICTION),
            ..Default::default()
        }),
        contacts: FEET
            .iter()
            .map(|f| ContactSpec {
                frame: f.to_string(),
                radius: Some(RADIUS),
                collide: Some(false),
                ..Default::default()
            })
            .collect(),
        // The URDF's limits are ±10 rad placeholders, and MuJoCo's model (compared with in
        // docs/benchmarks.md) has none.
        enforce_limits: Some(false),
    };
    let mut model = robot.with_contacts(&contacts).map_err(|e| e.to_string())?;
    for (k, &rest) in CROUCH.iter().enumerate() {
        let i = 6 + k;
        model.springs.push(Spring {
            kind: SpringKind::Variable(i),
            stiffness: KP,
            rest,
        });
        model.variables[i].damping = KD;
    }
    let mut q0 = vec![0.0; model.dof()];
    q0[6..].copy_from_slice(&CROUCH);
    // Lift the base so the lowest foot is `drop` above the ground.
    let origins = model.origins(&q0);
    let lowest = FEET
        .iter()
        .map(|f| origins[model.frame_index(f).unwrap()][2] - RADIUS)
        .fold(f64::INFINITY, f64::min);
    q0[2] = drop - lowest;
    Ok((model, q0))
}

/// Drops the robot for `duration` seconds at Δt = 1 ms (interpreted).
pub fn drop(duration: f64) -> Result<(model::Model, Trajectory, f64), SimError> {
    let (model, q0) = solo12(0.05).map_err(SimError::InvalidInput)?;
    let mut sys = TreeSystem::new(&model)?;
    let q0 = tree_mech::runtime::Vector::<tree_mech::nalgebra::Dyn>::from_column_slice(&q0);
    let dq0 = sys.zero_vector();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 1e-3, duration);
    let start = Instant::now();
    let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})?;
    Ok((model, traj, start.elapsed().as_secs_f64()))
}

/// Each foot's height above the ground (its sphere's lowest point) at sample `k`.
pub fn foot_heights(model: &model::Model, traj: &Trajectory, k: usize) -> [f64; 4] {
    let origins = model.origins(traj.q(k));
    FEET.map(|f| origins[model.frame_index(f).unwrap()][2] - RADIUS)
}

fn main() -> Result<(), SimError> {
    let (model, traj, wall) = drop(2.0)?;
    let last = traj.len() - 1;
    let lowest = (0..traj.len())
        .flat_map(|k| foot_heights(&model, &traj, k))
        .fold(f64::INFINITY, f64::min);
    println!(
        "Solo-12 dropped 5 cm: {} steps in {wall:.3} s ({:.1} µs a step, interpreted); base at {:.4} m after 2 s; deepest penetration {:.2e} m; Newton iterations {:.2} a step",
        last,
        1e6 * wall / last as f64,
        traj.q(last)[2],
        (-lowest).max(0.0),
        traj.newton_iterations as f64 / last as f64
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// It lands on its four feet and stands: no foot below the ground by more than 1e-9 m,
    /// every foot on it at the end, the base still and above the ground, no foot slipping once
    /// it stands.
    #[test]
    fn the_solo12_lands_on_its_feet_and_stands() {
        let (model, traj, _) = drop(1.5).unwrap();
        let last = traj.len() - 1;
        for k in 0..traj.len() {
            for h in foot_heights(&model, &traj, k) {
                assert!(h >= -1e-9, "a foot {h} m in the ground at sample {k}");
            }
        }
        for h in foot_heights(&model, &traj, last) {
            assert!(h.abs() < 1e-6, "a foot {h} m off the ground at the end");
        }
        let base = traj.q(last)[2];
        assert!(base > 0.1 && base < 0.35, "the base at {base} m");
        // Still: the last step's average velocity (the reported q̇ is the Legendre transform
        // of the step's momentum, not yet projected on the contacts in force).
        let (a, b) = (traj.q(last - 1), traj.q(last));
        let speed = a
            .iter()
            .zip(b)
            .map(|(x, y)| ((y - x) / 1e-3).abs())
            .fold(0.0, f64::max);
        assert!(speed < 1e-3, "still moving at {speed}");
        // Feet positions from 1 s on: standing, not sliding.
        let at = |k: usize| {
            let origins = model.origins(traj.q(k));
            FEET.map(|f| origins[model.frame_index(f).unwrap()])
        };
        let (a, b) = (at(1000), at(last));
        for (x, y) in a.iter().zip(&b) {
            let slip = ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2)).sqrt();
            assert!(slip < 1e-6, "a foot slipped {slip} m");
        }
    }
}
