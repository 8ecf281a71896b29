//! A batch of RK4 rollouts on one thread: the interpreted system four at a time in SIMD lanes
//! (`runtime::batch::rollouts`, what the Python package runs) against the same rollouts one
//! at a time (`batch::trajectory` for each start), and the compiled system one at a time for
//! scale — 64 rollouts of 1000 steps at Δt = 0.01, every step recorded, on the 8-link chain,
//! the 40-link chain and the UR5. The three are alternated over five rounds and the best of
//! each kept; prints millions of steps a second and the lanes' gain as a Markdown table.
//! Run: `cargo bench --bench rollouts`.

use std::time::Instant;

use tree_mech::integrate::{Method, SimOptions};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::batch::{rollouts, trajectory, Rollout};
use tree_mech::{model, tree_model, System, TreeSystem};

tree_model!(struct P8 from "benches/models/pendulum-8.toml");
// Compiled in full (it passes the size at which a model is lean by default), as the
// earlier rows of this table were.
tree_model!(struct P40 from "benches/models/pendulum-40.toml", lean = false);
// The robots' limits unenforced: these figures time the smooth dynamics, as Pinocchio's and
// MuJoCo's compared here (and the tasks, which leave them off).
tree_model!(struct Ur5 from "models/ur5.urdf", enforce_limits = false);

const BATCH: usize = 64;
const STEPS: usize = 1000;
const DT: f64 = 0.01;

/// Starts spread about the model's initial state.
fn starts(n: usize, q0: &[f64]) -> Vec<Rollout> {
    (0..BATCH)
        .map(|k| Rollout {
            q0: (0..n)
                .map(|i| q0[i] + 0.1 * ((k * n + i) as f64).sin())
                .collect(),
            dq0: vec![0.0; n],
            ..Rollout::default()
        })
        .collect()
}

/// Seconds `run` takes.
fn timed(run: impl Fn()) -> f64 {
    let start = Instant::now();
    run();
    start.elapsed().as_secs_f64()
}

/// Each start run by itself on a copy of `sys`.
fn one_at_a_time<S: System + Clone>(sys: &S, starts: &[Rollout], options: &SimOptions)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    for start in starts {
        let mut sys = sys.clone();
        trajectory(&mut sys, start, options, &mut |_| Ok(())).expect("the rollout runs");
    }
}

fn row(name: &str, interpreted: &TreeSystem, compiled: &dyn Fn(&[Rollout], &SimOptions)) {
    let options = SimOptions::new(Method::Rk4, DT, STEPS as f64 * DT);
    let (q0, _) = interpreted.initial_state();
    let starts = starts(interpreted.dof(), q0.as_slice());
    let mut best = [f64::INFINITY; 3];
    for _ in 0..5 {
        let lanes = timed(|| {
            let runs = rollouts(interpreted, &starts, &options, 1).expect("the batch runs");
            assert!(runs.iter().all(Result::is_ok));
        });
        let one = timed(|| one_at_a_time(interpreted, &starts, &options));
        let generated = timed(|| compiled(&starts, &options));
        for (b, t) in best.iter_mut().zip([lanes, one, generated]) {
            *b = b.min(t);
        }
    }
    let rate = |s: f64| (BATCH * STEPS) as f64 / s / 1e6;
    println!(
        "| {name} | {:.3} | {:.3} | {:.2}× | {:.3} |",
        rate(best[0]),
        rate(best[1]),
        best[1] / best[0],
        rate(best[2])
    );
}

fn main() {
    let root = env!("CARGO_MANIFEST_DIR");
    println!("RK4, 64 rollouts × 1000 steps, one thread; millions of steps a second (best of 5).");
    println!();
    println!("| model | interpreted, in lanes | interpreted, one at a time | lanes' gain | compiled, one at a time |");
    println!("|---|---:|---:|---:|---:|");
    let p8 = model::from_toml_file(format!("{root}/benches/models/pendulum-8.toml")).unwrap();
    row("8-link chain", &TreeSystem::new(&p8).unwrap(), &|s, o| {
        one_at_a_time(&P8, s, o)
    });
    let p40 = model::from_toml_file(format!("{root}/benches/models/pendulum-40.toml")).unwrap();
    row("40-link chain", &TreeSystem::new(&p40).unwrap(), &|s, o| {
        one_at_a_time(&P40, s, o)
    });
    row("UR5", &TreeSystem::new(&Ur5::model()).unwrap(), &|s, o| {
        one_at_a_time(&Ur5, s, o)
    });
}
