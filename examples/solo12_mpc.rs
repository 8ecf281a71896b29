//! Model-predictive control of the Solo-12 stand-up (tasks/solo12-stand.toml): the stand-up
//! planned offline through contact, then tracked at hard contact by an MPC that re-plans the
//! next 0.1 s from the measured state every 10 ms (one iteration a tick, warm-started from
//! the last plan) — through a push of 0.5 N·s along x at t = 0.3 s. Beside it, the offline
//! plan's own policy (its controls with their feedback gains, never re-planned) through the
//! same push. Prints each tick's time against the 10 ms it has, and where the robot ends.
//!
//! Run: `cargo run --release --example solo12_mpc`.

#[path = "shared/stand_mpc.rs"]
mod stand_mpc;

use stand_mpc::{outcome, stand_mpc, EVERY, HORIZON, PUSH};
use tree_mech::control::{solve_task, ClosedLoop, TaskOptions};
use tree_mech::{model, tree_model};

tree_model!(pub struct SoloStand from "models/solo12.urdf", floating_base, contacts from "tasks/solo12-stand.toml");

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tasks/solo12-stand.toml");
    let (task, m) = model::read_task(path)?;
    println!(
        "Planning the stand-up offline (compiled, {} knots)…",
        task.knots
    );
    let res = solve_task(SoloStand, &task, &m, &TaskOptions::default(), &mut |_| {})?;
    println!(
        "  {} iterations in {:.2} s, cost {:.6}",
        res.solution.history.len(),
        res.solve_seconds,
        res.solution.cost
    );
    let period = EVERY as f64 * task.dt;
    println!(
        "MPC: {HORIZON} knots ({:.2} s) re-planned every {:.0} ms, one iteration a tick, a push of {PUSH} N·s at t = 0.3 s",
        HORIZON as f64 * task.dt,
        1e3 * period
    );
    let run = stand_mpc(SoloStand, SoloStand, &task, &res.solution, PUSH)?;
    report("MPC", &m, &run);
    let ticks = &run.tick_seconds;
    let mean = ticks.iter().sum::<f64>() / ticks.len() as f64;
    let worst = ticks.iter().copied().fold(0.0, f64::max);
    println!(
        "  {} ticks: {:.2} ms a tick on average, {:.2} ms at worst, against {:.0} ms: {:.2}× real time",
        ticks.len(),
        1e3 * mean,
        1e3 * worst,
        1e3 * period,
        period / mean
    );
    // The offline policy alone: an MPC that never re-plans is its plan's feedback law.
    let policy = stand_mpc::policy_only(SoloStand, &task, &res.solution, PUSH)?;
    report("the offline policy", &m, &policy);
    Ok(())
}

fn report(what: &str, m: &model::Model, run: &ClosedLoop) {
    let ([x, z], slip, lowest) = outcome(m, run);
    println!(
        "{what}: the base ends at x = {x:+.4} m, z = {z:.4} m (target 0.25); the feet moved {:.2} mm over the ground, the lowest foot centre {:.2} mm up (radius 16 mm), deepest penetration {:.1e} m",
        1e3 * slip,
        1e3 * lowest,
        run.penetration
    );
}
