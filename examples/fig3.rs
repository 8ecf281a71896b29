//! The paper's Fig. 3 experiment: simulate the N-link pendulum (N = 1…19) for 10 s at
//! Δt = 0.01 with the midpoint VI, with and without caching, and print the wall times as a
//! Markdown table. Run: `cargo run --release --example fig3`.

use std::time::Instant;

use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::{tree_model, Caching, NoForce, System, TreeSystem};

fn time_run(sys: &mut impl System<N = tree_mech::nalgebra::Dyn>) -> (f64, usize) {
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 0.01,
        duration: 10.0,
    };
    // Best of a few runs, to keep scheduler noise out.
    let mut best = f64::INFINITY;
    let mut iterations = 0;
    for _ in 0..3 {
        let start = Instant::now();
        let traj = simulate(sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
        best = best.min(start.elapsed().as_secs_f64());
        iterations = traj.newton_iterations;
    }
    (best, iterations)
}

fn main() {
    println!("| N | cached [ms] | uncached [ms] | uncached / cached | Newton iterations / step |");
    println!("|---:|---:|---:|---:|---:|");
    for n in 1..=19 {
        let model = tree_model::n_link_pendulum(n);
        let (cached, iters) = time_run(&mut TreeSystem::new(&model, Caching::On).unwrap());
        let (uncached, _) = time_run(&mut TreeSystem::new(&model, Caching::Off).unwrap());
        println!(
            "| {n} | {:.2} | {:.2} | {:.1} | {:.2} |",
            cached * 1e3,
            uncached * 1e3,
            uncached / cached,
            iters as f64 / 1000.0
        );
    }
}
