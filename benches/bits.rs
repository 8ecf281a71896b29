//! Not a timing: a fingerprint of what the compiled shipped models compute, for a change meant
//! to keep every bit (a renovation, a move between crates). Prints one hash a model: VI and
//! RK4 runs of the marionette, the humanoid, the UR5, the Panda and the Solo-12 (every sample's
//! q, q̇, λ, energy and violation), and the iLQR solves of the cart-pole swing-up and the UR5
//! reach (every iterate's states, controls, gains and cost), all compiled by `tree_model!`.
//! Run it before and after; equal lines mean the same bits on this CPU.
//!
//! Run: `cargo bench --bench bits`.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};

use tree_mech::control::{solve_task, TaskOptions};
use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::{model, tree_model, NoForce, System};

tree_model!(struct Marionette from "models/marionette.toml");
tree_model!(struct Humanoid from "models/humanoid.toml");
// The robots' limits unenforced: these figures time the smooth dynamics, as Pinocchio's and
// MuJoCo's compared here (and the tasks, which leave them off).
tree_model!(struct Ur5 from "models/ur5.urdf", enforce_limits = false);
tree_model!(struct Panda from "models/panda.urdf", enforce_limits = false);
tree_model!(struct Solo12 from "models/solo12.urdf", floating_base, enforce_limits = false);
tree_model!(struct Cartpole from "models/cartpole.toml");

/// A hash of a value's debug text: Rust prints each `f64` as its shortest round trip, so equal
/// text is equal bits (the sign of zero included).
fn fingerprint(value: &impl std::fmt::Debug) -> u64 {
    let mut h = DefaultHasher::new();
    format!("{value:?}").hash(&mut h);
    h.finish()
}

/// 200 VI steps and 200 RK4 steps from the model's initial state.
fn runs<S: System>(name: &str, mut sys: S)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let mut prints = Vec::new();
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let options = SimOptions::new(method, 0.005, 1.0);
        let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let rows: Vec<_> = (0..traj.len())
            .map(|k| (traj.q(k), traj.dq(k), traj.lambda(k)))
            .collect();
        prints.push(fingerprint(&(rows, &traj.energy, &traj.violation)));
    }
    println!("{name:<12} vi {:016x}  rk4 {:016x}", prints[0], prints[1]);
}

/// The task's iLQR solve, every iterate reported.
fn solve<S: System>(name: &str, sys: S, file: &str)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (task, model) = model::read_task(file).unwrap_or_else(|e| panic!("{file}: {e}"));
    let mut iterates = Vec::new();
    let res = solve_task(sys, &task, &model, &TaskOptions::default(), &mut |it| {
        iterates.push((it.cost, it.step, it.gradient))
    })
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    let s = &res.solution;
    let print = fingerprint(&(iterates, &s.x, &s.u, &s.gains, s.cost, &res.lambda));
    println!("{name:<12} ilqr {print:016x}");
}

fn main() {
    runs("marionette", Marionette::new());
    runs("humanoid", Humanoid::new());
    runs("ur5", Ur5::new());
    runs("panda", Panda::new());
    runs("solo12", Solo12::new());
    solve("cartpole", Cartpole::new(), "tasks/cartpole-swingup.toml");
    solve("ur5-reach", Ur5::new(), "tasks/ur5-reach.toml");
}
