//! The Solo-12 stand-up (tasks/solo12-stand.toml, planned through contact) side by side in
//! one run: solved compiled (`tree_model!` with `contacts from` the task file), interpreted
//! (`TreeSystem`) and through the CLI (`tree-mech optimize`, a child process, when the binary
//! is built). The rounds alternate the sides; each side reports its best round. Then the
//! MPC loop of examples/solo12_mpc.rs on the compiled plan (re-planned over 0.1 s every
//! 10 ms, one iteration a tick, a push at t = 0.3 s), compiled and interpreted: each tick's
//! time against the 10 ms it has.
//!
//! Run: `cargo build --release && cargo bench --bench stand`.

use std::process::Command;
use std::time::Instant;

#[path = "../examples/shared/stand_mpc.rs"]
#[allow(dead_code)] // the example's comparison with the offline policy is not timed here
mod stand_mpc;

use tree_mech::control::{solve_task, TaskOptions};
use tree_mech::{model, tree_model, TreeSystem};

tree_model!(struct SoloStand from "models/solo12.urdf", floating_base, contacts from "tasks/solo12-stand.toml");

const ROUNDS: usize = 2;
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn main() {
    let path = format!("{ROOT}/tasks/solo12-stand.toml");
    let (task, m) = model::read_task(&path).expect("the stand-up task reads");
    let cli = format!("{ROOT}/target/release/tree-mech");
    let has_cli = std::path::Path::new(&cli).exists();
    let (mut compiled, mut interpreted, mut command) = (f64::MAX, f64::MAX, f64::MAX);
    let mut plan = None;
    for round in 0..ROUNDS {
        let options = TaskOptions::default();
        let res = solve_task(SoloStand, &task, &m, &options, &mut |_| {}).expect("it solves");
        compiled = compiled.min(res.solve_seconds);
        let c = (res.solution.history.len(), res.solution.cost);
        plan.get_or_insert(res.solution);
        let sys = TreeSystem::new(&m).expect("the model builds");
        let res = solve_task(sys, &task, &m, &options, &mut |_| {}).expect("it solves");
        interpreted = interpreted.min(res.solve_seconds);
        let i = (res.solution.history.len(), res.solution.cost);
        println!("round {round}: compiled {c:?}, interpreted {i:?} (iterations, cost)");
        if has_cli {
            let start = Instant::now();
            let out = Command::new(&cli)
                .args(["optimize", path.as_str(), "--quiet"])
                .output()
                .expect("the CLI runs");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            command = command.min(start.elapsed().as_secs_f64());
        }
    }
    println!("Solo-12 stand-up, best of {ROUNDS} rounds:");
    println!("  compiled     {compiled:8.2} s");
    println!(
        "  interpreted  {interpreted:8.2} s  ({:.2}× the compiled)",
        interpreted / compiled
    );
    if has_cli {
        println!(
            "  CLI          {command:8.2} s  ({:.2}× the compiled; whole process)",
            command / compiled
        );
    }
    mpc(&task, &m, &plan.expect("a round ran"));
}

/// The MPC loop's ticks, compiled and interpreted alternately, each side's best round: the
/// mean and worst tick against the period.
fn mpc(task: &model::Task, m: &model::Model, plan: &tree_mech::control::Solution) {
    let (mut compiled, mut interpreted) = ([f64::MAX; 2], [f64::MAX; 2]);
    let summary = |ticks: &[f64]| {
        let mean = ticks.iter().sum::<f64>() / ticks.len() as f64;
        [mean, ticks.iter().copied().fold(0.0, f64::max)]
    };
    let best = |a: [f64; 2], b: [f64; 2]| if b[0] < a[0] { b } else { a };
    for _ in 0..ROUNDS {
        let run = stand_mpc::stand_mpc(SoloStand, SoloStand, task, plan, stand_mpc::PUSH)
            .expect("the loop runs");
        compiled = best(compiled, summary(&run.tick_seconds));
        let sys = || TreeSystem::new(m).expect("the model builds");
        let run =
            stand_mpc::stand_mpc(sys(), sys(), task, plan, stand_mpc::PUSH).expect("the loop runs");
        interpreted = best(interpreted, summary(&run.tick_seconds));
    }
    let period = stand_mpc::EVERY as f64 * task.dt;
    println!(
        "MPC ({} knots re-planned every {:.0} ms, one iteration a tick), best of {ROUNDS} rounds:",
        stand_mpc::HORIZON,
        1e3 * period
    );
    for (side, [mean, worst]) in [("compiled", compiled), ("interpreted", interpreted)] {
        println!(
            "  {side:<12} {:6.2} ms a tick ({:.2} ms at worst): {:.2}× real time",
            1e3 * mean,
            1e3 * worst,
            period / mean
        );
    }
}
