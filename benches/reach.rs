//! The two reaches against Crocoddyl 3.2.1, side by side in one run: the UR5 within its effort
//! limits (tasks/ur5-reach.toml; Crocoddyl's box-FDDP) and the UR10 without limits
//! (tasks/ur10-reach.toml; Crocoddyl's plain FDDP, where it is at its best). Each round solves
//! every reach compiled (`tree_model!`), interpreted (`TreeSystem`) and, when
//! `CROCODDYL_PYTHON` names a Python with Crocoddyl (tools/reference/crocoddyl_reach.py's
//! docstring), by Crocoddyl in a child process; every side takes the best of 5 solves from the
//! same guess, and the rounds alternate the sides.
//!
//! Run: `CROCODDYL_PYTHON=croc/bin/python cargo bench --bench reach`.

use std::process::Command;

use tree_mech::control::{solve_task, TaskOptions, TaskResult};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::{model, tree_model, System, TreeSystem};

// The robots' limits unenforced: these figures time the smooth dynamics, as Pinocchio's and
// MuJoCo's compared here (and the tasks, which leave them off).
tree_model!(struct Ur5 from "models/ur5.urdf", enforce_limits = false);
tree_model!(struct Ur10 from "models/ur10.urdf", enforce_limits = false);

const ROUNDS: usize = 3;
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The best of 5 solves of `task` on a fresh `sys()` each: (iterations, cost, seconds).
fn best_of_5<S: System>(
    sys: impl Fn() -> S,
    task: &model::Task,
    m: &model::Model,
) -> (usize, f64, f64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut best: Option<TaskResult> = None;
    for _ in 0..5 {
        let res = solve_task(sys(), task, m, &TaskOptions::default(), &mut |_| {})
            .expect("the reach solves");
        if best
            .as_ref()
            .is_none_or(|b| res.solve_seconds < b.solve_seconds)
        {
            best = Some(res);
        }
    }
    let best = best.expect("five solves");
    (
        best.solution.history.len(),
        best.solution.cost,
        best.solve_seconds,
    )
}

/// Crocoddyl's (iterations, cost, seconds) per reach, from one run of the reference script.
fn crocoddyl(python: &str) -> Vec<(usize, f64, f64)> {
    let script = format!("{ROOT}/tools/reference/crocoddyl_reach.py");
    let out = Command::new(python)
        .args([script.as_str(), "--print"])
        .output()
        .expect("the Crocoddyl Python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0] as usize, v[1], v[2])
        })
        .collect()
}

fn main() {
    let python = std::env::var("CROCODDYL_PYTHON").ok();
    let reaches = ["ur5", "ur10"];
    let tasks: Vec<_> = reaches
        .iter()
        .map(|r| model::read_task(format!("{ROOT}/tasks/{r}-reach.toml")).unwrap())
        .collect();
    // rows[reach][side] = every round's (iterations, cost, seconds)
    let mut rows = vec![vec![Vec::new(); 3]; reaches.len()];
    for _ in 0..ROUNDS {
        let (task, m) = &tasks[0];
        rows[0][0].push(best_of_5(Ur5::new, task, m));
        let (task, m) = &tasks[1];
        rows[1][0].push(best_of_5(Ur10::new, task, m));
        for (r, (task, m)) in tasks.iter().enumerate() {
            rows[r][1].push(best_of_5(|| TreeSystem::new(m).unwrap(), task, m));
        }
        if let Some(python) = &python {
            for (r, row) in crocoddyl(python).into_iter().enumerate() {
                rows[r][2].push(row);
            }
        }
    }
    println!("| reach | solver | iterations | cost | best solve [ms] per round | ×Crocoddyl |");
    println!("|---|---|---:|---:|---|---|");
    let sides = [
        "tree-mech compiled",
        "tree-mech interpreted",
        "Crocoddyl 3.2.1",
    ];
    for (r, reach) in reaches.iter().enumerate() {
        for (s, side) in sides.iter().enumerate() {
            let runs = &rows[r][s];
            let Some(&(iterations, cost, _)) = runs.first() else {
                continue;
            };
            let ms: Vec<String> = runs.iter().map(|x| format!("{:.1}", x.2 * 1e3)).collect();
            let ratio: Vec<String> = rows[r][2]
                .iter()
                .zip(runs)
                .map(|(c, x)| format!("{:.2}", c.2 / x.2))
                .collect();
            println!(
                "| {reach} | {side} | {iterations} | {cost:.4e} | {} | {} |",
                ms.join(", "),
                ratio.join(", ")
            );
        }
    }
}
