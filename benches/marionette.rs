//! The marionette (models/marionette.toml, 42 variables, six strings) and trep's own Puppet
//! (tools/reference/trep-puppet.toml, 40 variables, six strings): 10 s at Δt = 0.01 with the
//! VI and with RK4, compiled by `tree_model!` and interpreted, side by side in one run (best of
//! 7 runs each). Then one VI step, the step with its first derivatives, the contracted
//! second derivatives and the continuous linearisation, on both and on the N-link pendulum
//! (interpreted) as N grows. Prints
//! Markdown tables. Run: `cargo bench --bench marionette`.

use std::time::Instant;

use tree_mech::integrate::{
    run, JacobianUpdate, Method, MidpointVi, SimOptions, StepContext, StepCovector,
    StepDerivatives, ViSettings,
};
use tree_mech::nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};
use tree_mech::runtime::batch::{trajectory, Rollout, StepLinearizer};
use tree_mech::runtime::linearize::{
    continuous_derivatives_into, ContinuousDerivatives, ContinuousWorkspace,
};
use tree_mech::runtime::ModelMotions;
use tree_mech::{tree_model, NoForce, System, TreeSystem};

tree_model!(struct Marionette from "models/marionette.toml");
tree_model!(struct TrepPuppet from "tools/reference/trep-puppet.toml");

/// Best wall time of 10 s of `method`, in ms, and the Newton iterations per step.
fn ten_seconds<S: System>(sys: &mut S, method: Method) -> (f64, f64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(method, 0.01, 10.0);
    let (mut best, mut iterations) = (f64::INFINITY, 0.0);
    for _ in 0..7 {
        let mut motion = ModelMotions::of(sys);
        let start = Instant::now();
        let summary = run(
            sys,
            &q0,
            &dq0,
            &options,
            &mut NoForce,
            &mut motion,
            &mut |_| Ok(()),
        )
        .expect("the marionette runs");
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
        iterations = summary.newton_iterations as f64 / summary.steps as f64;
    }
    (best, iterations)
}

fn main() {
    // `cargo bench --bench marionette -- puppet`: only trep's Puppet over 10 s, compiled and
    // interpreted (what tools/reference/trep_puppet_bench.sh puts beside trep).
    if std::env::args().any(|a| a == "puppet") {
        let mut interpreted = TreeSystem::new(&TrepPuppet::model()).expect("valid model");
        let method = Method::Vi(ViSettings::default());
        let (c, _) = ten_seconds(&mut TrepPuppet, method);
        let (i, _) = interpreted_ten_seconds(&mut interpreted, method);
        println!("compiled_ms {c:.1}");
        println!("interpreted_ms {i:.1}");
        return;
    }
    // `cargo bench --bench marionette -- linearize`: trep's Puppet's trajectory linearised
    // step by step, compiled and interpreted (what tools/reference/trep_linearize_bench.sh
    // puts beside trep's `DSystem.linearize_trajectory`).
    if std::env::args().any(|a| a == "linearize") {
        let mut interpreted = TreeSystem::new(&TrepPuppet::model()).expect("valid model");
        println!("compiled_us {:.2}", linearize_trajectory(&mut TrepPuppet));
        println!(
            "interpreted_us {:.2}",
            linearize_trajectory(&mut interpreted)
        );
        // The same through `batch::linearize_trajectory` (a recorded run, its steps checked,
        // the thread pool made per call): on one thread and on two.
        for threads in [1, 2] {
            println!(
                "compiled_batch_{threads}_us {:.2}",
                batch_linearize(&TrepPuppet, threads)
            );
            println!(
                "interpreted_batch_{threads}_us {:.2}",
                batch_linearize(&interpreted, threads)
            );
        }
        return;
    }
    println!("| 10 s, Δt = 0.01 | compiled [ms] | interpreted [ms] | interpreted / compiled | compiled per step [µs] | interpreted per step [µs] | Newton iterations / step |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    rows("marionette", &mut Marionette, &Marionette::model());
    rows("trep's Puppet", &mut TrepPuppet, &TrepPuppet::model());
    println!();
    println!("| one VI step at the start (Δt = 0.01) | step [µs] | step + first derivatives [µs] | contracted second derivatives [µs] | continuous linearisation [µs] |");
    println!("|---|---:|---:|---:|---:|");
    let row = |name: &str, [a, b, c, d]: [f64; 4]| {
        println!("| {name} | {a:.1} | {b:.1} | {c:.1} | {d:.1} |")
    };
    row("marionette, compiled", derivatives(&mut Marionette));
    row(
        "marionette, interpreted",
        derivatives(&mut TreeSystem::new(&Marionette::model()).unwrap()),
    );
    row("trep's Puppet, compiled", derivatives(&mut TrepPuppet));
    row(
        "trep's Puppet, interpreted",
        derivatives(&mut TreeSystem::new(&TrepPuppet::model()).unwrap()),
    );
    for n in [2, 4, 8, 16, 32] {
        let model = tree_mech::model::n_link_pendulum(n);
        row(
            &format!("{n}-link pendulum, interpreted"),
            derivatives(&mut TreeSystem::new(&model).unwrap()),
        );
    }
    println!();
    println!(
        "| linearising a 1 s trajectory (Δt = 0.01), per step | compiled [µs] | interpreted [µs] |"
    );
    println!("|---|---:|---:|");
    for (name, c, i) in [
        (
            "marionette",
            linearize_trajectory(&mut Marionette),
            linearize_trajectory(&mut TreeSystem::new(&Marionette::model()).unwrap()),
        ),
        (
            "trep's Puppet",
            linearize_trajectory(&mut TrepPuppet),
            linearize_trajectory(&mut TreeSystem::new(&TrepPuppet::model()).unwrap()),
        ),
    ] {
        println!("| {name} | {c:.1} | {i:.1} |");
    }
}

/// Best mean µs of `f` over 5 batches of `calls`.
fn time_us(calls: usize, f: impl FnMut()) -> f64 {
    best_of(5, calls, f)
}

/// Best mean µs of `f` over `batches` batches of `calls` (the least disturbed by the machine).
fn best_of(batches: usize, calls: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..batches {
        let start = Instant::now();
        for _ in 0..calls {
            f();
        }
        best = best.min(start.elapsed().as_secs_f64() * 1e6 / calls as f64);
    }
    best
}

/// Mean µs per step (best of 30 passes) of linearising a 1 s VI trajectory from the model's start
/// at Δt = 0.01, the task of trep's `DSystem.linearize_trajectory`: given each step's start
/// `(q₁, p₁)`, its end `q₂` and its multipliers λ (a trajectory records them), the step's
/// first derivatives — the model evaluated at the step (nothing cached from the step before),
/// the Newton matrix factored and solved for every input direction, as iLQR's backward pass
/// does (`DiscreteSystem::jacobians`). trep, whose state has no λ, takes each step again from
/// its recorded end as a hint.
fn linearize_trajectory<S: System>(sys: &mut S) -> f64
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    const DT: f64 = 0.01;
    let (q0, dq0) = sys.initial_state();
    let mut motion = ModelMotions::of(sys);
    let settings = ViSettings {
        derivatives: true,
        ..ViSettings::default()
    };
    let mut vi = MidpointVi::new(sys, settings);
    let p0 = vi.initial_momentum(sys, &q0, &dq0);
    // The trajectory: 100 steps, (q_k, p_k) at every knot and each step's λ.
    let (mut q, mut p, mut next) = (q0.clone(), p0.clone(), q0.clone());
    let mut knots = vec![(q.clone(), p.clone())];
    let mut lambdas = Vec::new();
    for k in 0..100 {
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, DT);
        cx.index = k;
        cx.t = k as f64 * DT;
        vi.step(&mut cx, &mut q, &mut p, &mut next)
            .expect("the trajectory steps");
        knots.push((q.clone(), p.clone()));
        lambdas.push(vi.lambda.clone());
    }
    let mut first = StepDerivatives::empty();
    best_of(30, 1, || {
        for k in 0..100 {
            let ((q1, p1), (q2, _)) = (&knots[k], &knots[k + 1]);
            vi.lambda.copy_from(&lambdas[k]);
            let mut force = NoForce;
            let mut cx = StepContext::new(sys, &mut force, &mut motion, DT);
            cx.index = k;
            cx.t = k as f64 * DT;
            vi.derivatives_into(&mut cx, q1, p1, q2, &mut first)
                .expect("the step's derivatives");
        }
    }) / 100.0
}

/// Mean µs per step (best of 30 calls) of a `batch::StepLinearizer` on `threads` threads
/// over a 1 s VI run of the model from its start at Δt = 0.01 (made once, as iLQR would).
fn batch_linearize<S>(sys: &S, threads: usize) -> f64
where
    S: System + Clone + Send + Sync,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    MidpointVi<S::N>: Send,
    tree_mech::runtime::Vector<S::N>: Send,
{
    let settings = ViSettings::default();
    let (q0, dq0) = sys.initial_state();
    let start = Rollout {
        q0: q0.as_slice().to_vec(),
        dq0: dq0.as_slice().to_vec(),
        ..Rollout::default()
    };
    let options = SimOptions::new(Method::Vi(settings), 0.01, 1.0);
    let run = trajectory(&mut sys.clone(), &start, &options, &mut |_| Ok(())).expect("the run");
    let steps = (run.len() - 1) as f64;
    let mut linearizer = StepLinearizer::new(sys, &settings, threads).expect("the threads");
    let mut out = Vec::new();
    best_of(30, 1, || {
        linearizer
            .linearize_into(&run, &mut out)
            .expect("the steps");
    }) / steps
}

/// `[step, step + first derivatives, contracted second derivatives, continuous
/// linearisation]` in µs, from the model's start (the last: `∂q̈/∂(q, q̇, u)` and
/// `∂λ/∂(q, q̇, u)` at the start state, `linearize::continuous_derivatives_into`).
fn derivatives<S: System>(sys: &mut S) -> [f64; 4]
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q, dq) = sys.initial_state();
    let mut vi = MidpointVi::new(sys, ViSettings::default());
    let p = vi.initial_momentum(sys, &q, &dq);
    let (mut q2, mut p2, mut next) = (q.clone(), p.clone(), q.clone());
    let mut motion = ModelMotions::of(sys);
    let mut first = StepDerivatives::empty();
    let mut hessian = DMatrix::zeros(0, 0);
    let nd = vi.split.dynamic.len();
    let w = StepCovector {
        q2: DVector::from_element(nd, 1.0),
        p2: DVector::from_element(nd, 0.5),
        lambda: DVector::from_element(sys.constraint_count(), 0.1),
    };
    let mut go = |sys: &mut S, with: u8| {
        q2.copy_from(&q);
        p2.copy_from(&p);
        vi.predict_from(&dq);
        // A step whose derivatives follow ends on the evaluation they reuse.
        vi.settings.derivatives = with >= 1;
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.01);
        vi.step(&mut cx, &mut q2, &mut p2, &mut next)
            .expect("the step converges");
        if with >= 1 {
            vi.derivatives_into(&mut cx, &q, &p, &q2, &mut first)
                .expect("the step's derivatives");
        }
        if with >= 2 {
            vi.contracted_second_derivatives(&mut cx, &q, &p, &q2, &w, &mut hessian)
                .expect("the contraction");
        }
    };
    let step = time_us(200, || go(sys, 0));
    let with_first = time_us(200, || go(sys, 1));
    let with_second = time_us(20, || go(sys, 2));
    let mut workspace = ContinuousWorkspace::new(sys);
    let mut continuous = ContinuousDerivatives::empty();
    let linearize = time_us(20, || {
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.0);
        continuous_derivatives_into(&mut cx, &q, &dq, &mut workspace, &mut continuous)
            .expect("the linearisation");
    });
    [step, with_first, with_second - with_first, linearize]
}

/// The VI and RK4 rows for one model, compiled (`sys`) and interpreted (from `model`).
fn rows<S: System>(name: &str, sys: &mut S, model: &tree_mech::model::Model)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut interpreted = TreeSystem::new(model).expect("valid model");
    for (label, method) in [
        ("midpoint VI", Method::Vi(ViSettings::default())),
        (
            "midpoint VI, exact Newton",
            Method::Vi(ViSettings {
                jacobian: JacobianUpdate::EveryIteration,
                ..ViSettings::default()
            }),
        ),
        ("RK4", Method::Rk4),
    ] {
        let (c, iterations) = ten_seconds(sys, method);
        let (i, _) = interpreted_ten_seconds(&mut interpreted, method);
        let newton = if iterations > 0.0 {
            format!("{iterations:.2}")
        } else {
            "—".into()
        };
        // 1000 steps: ms per run = µs per step.
        println!(
            "| {name}, {label} | {c:.1} | {i:.1} | {:.1}× | {c:.1} | {i:.1} | {newton} |",
            i / c
        );
    }
}

/// [`ten_seconds`] on the interpreted system (outside `rows`, whose allocator bounds on a
/// generic `S` would hide `Dyn`'s).
fn interpreted_ten_seconds(sys: &mut TreeSystem, method: Method) -> (f64, f64) {
    ten_seconds(sys, method)
}
