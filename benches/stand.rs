//! The Solo-12 stand-up (tasks/solo12-stand.toml, planned through contact) side by side in
//! one run: solved compiled (`tree_model!` with `contacts from` the task file), interpreted
//! (`TreeSystem`) and through the CLI (`tree-mech optimize`, a child process, when the binary
//! is built). The rounds alternate the sides; each side reports its best round.
//!
//! Run: `cargo build --release && cargo bench --bench stand`.

use std::process::Command;
use std::time::Instant;

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
    for round in 0..ROUNDS {
        let options = TaskOptions::default();
        let res = solve_task(SoloStand, &task, &m, &options, &mut |_| {}).expect("it solves");
        compiled = compiled.min(res.solve_seconds);
        let c = (res.solution.history.len(), res.solution.cost);
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
}
