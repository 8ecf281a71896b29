//! Contact against its analytic answers, tree-mech's side of the comparison with MuJoCo
//! (`tools/reference/mujoco_contact.py` runs MuJoCo's side on the same models and, with
//! `--cargo`, this bench first, and prints both in one table). Each case runs compiled
//! (`tree_model!`) and interpreted (`TreeSystem`) at hard contact, Δt = 1 ms, one step at a
//! time through [`Stepper`] (the Solo-12's PD inputs computed from each step's start state, as a
//! 1 kHz controller would; each case's rate the best of three runs, as MuJoCo's): the ball drop, the box sliding from 1 m/s, the box on slopes of
//! 0.3 and 0.6 rad, the Solo-12 dropped 5 cm with its joints held by PD, and 27 balls poured
//! on the ground. It also times a linearised contact step of the Solo-12 (the step's `A`,
//! `B` through its four foot contacts at κ = 10⁻⁶), what MuJoCo's `mjd_transitionFD` gives.
//!
//! Run: `cargo bench --bench contact` (a table); `-- --json` prints one JSON object a row;
//! words choose cases: `-- solo` (the drop and the linearised step), `-- balls`, `-- slope`.

use std::time::Instant;

use tree_mech::control::DiscreteSystem;
use tree_mech::integrate::{Method, Stepper, ViSettings};
use tree_mech::nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};
use tree_mech::{model, tree_model, ConstraintTerms, System, TreeSystem};

tree_model!(struct Ball from "tests/models/ball.toml");
tree_model!(struct Cube from "tests/models/box.toml");
tree_model!(struct Sticks from "benches/models/slope-0.3.toml");
tree_model!(struct Slides from "benches/models/slope-0.6.toml");
tree_model!(struct Balls from "benches/models/balls-27.toml");
tree_model!(struct Solo from "models/solo12.urdf", floating_base, contacts from "tasks/solo12-stand.toml");

const DT: f64 = 1e-3;
const G: f64 = 9.81;
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// One case on one path: what it measured against the answer, and its speed.
struct Row {
    case: &'static str,
    path: &'static str,
    /// The case's measure of accuracy, its name and the analytic value it is held to.
    measure: (&'static str, f64, f64),
    /// The deepest penetration over the run (m).
    penetration: f64,
    /// The largest rise of the energy above its start (J).
    energy_gain: f64,
    steps_per_second: f64,
}

/// A run's states and energies, and its wall time.
struct Run {
    q: Vec<Vec<f64>>,
    energy: Vec<f64>,
    seconds: f64,
}

/// The inputs from a step's start state `(q, q̇)`, into `u`.
type Policy = dyn FnMut(&[f64], &[f64], &mut [f64]);

/// The fastest of three [`run_once`]s, as MuJoCo's side takes the best of three: one run of a
/// millisecond-step case lasts tens of milliseconds, and this machine's pace moves 15–25%
/// between such runs.
fn run<S: System + Clone>(sys: S, q0: &[f64], steps: usize, policy: &mut Policy) -> Run
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut best = run_once(sys.clone(), q0, steps, policy);
    for _ in 1..3 {
        let next = run_once(sys.clone(), q0, steps, policy);
        if next.seconds < best.seconds {
            best = next;
        }
    }
    best
}

/// Runs `sys` from `q0` (at the model's velocities) for `steps`, the inputs from `policy(q, q̇)` at each step's start.
fn run_once<S: System>(sys: S, q0: &[f64], steps: usize, policy: &mut Policy) -> Run
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let dq0: Vec<f64> = (0..q0.len()).map(|i| sys.initial(i).1).collect();
    let mut u = vec![0.0; sys.input_count()];
    let vi = Method::Vi(ViSettings::default());
    let mut stepper = Stepper::new(sys, vi, DT, q0, &dq0).expect("the start is admissible");
    let (mut q, mut energy) = (Vec::with_capacity(steps + 1), Vec::with_capacity(steps + 1));
    let mut seconds = 0.0;
    for _ in 0..steps {
        q.push(stepper.q().as_slice().to_vec());
        energy.push(stepper.energy());
        let start = Instant::now();
        policy(stepper.q().as_slice(), stepper.dq().as_slice(), &mut u);
        stepper.step(&u).expect("the step converges");
        seconds += start.elapsed().as_secs_f64();
    }
    q.push(stepper.q().as_slice().to_vec());
    energy.push(stepper.energy());
    Run { q, energy, seconds }
}

fn no_inputs(_: &[f64], _: &[f64], _: &mut [f64]) {}

fn energy_gain(run: &Run) -> f64 {
    let e0 = run.energy[0];
    run.energy.iter().fold(0.0, |m, e| m.max(e - e0))
}

/// The deepest any gap of `model` (a sphere into the ground or into another) closes over
/// the run (its friction rows have no gap).
fn penetration(model: &model::Model, run: &Run) -> f64 {
    let mut sys = TreeSystem::new(model).expect("it builds");
    let gaps = sys.unilateral();
    let rows: usize = gaps.iter().map(|g| g.rows()).sum();
    let normal: Vec<usize> = (gaps.iter())
        .scan(0, |r, g| {
            let at = *r;
            *r += g.rows();
            Some(at)
        })
        .collect();
    let mut out = ConstraintTerms::zeros(rows, model.dof());
    let mut deepest = 0.0f64;
    for q in &run.q {
        sys.gaps(&DVector::from_column_slice(q), None, &mut out);
        for &r in &normal {
            deepest = deepest.max(-out.h[r]);
        }
    }
    deepest
}

fn q0(m: &model::Model) -> Vec<f64> {
    m.variables.iter().map(|v| v.q0).collect()
}

fn rate(run: &Run) -> f64 {
    (run.q.len() - 1) as f64 / run.seconds
}

fn interpreted(path: &str) -> (model::Model, TreeSystem) {
    let m = model::from_file(format!("{ROOT}/{path}"), Default::default()).expect("it reads");
    let sys = TreeSystem::new(&m).expect("it builds");
    (m, sys)
}

/// Each case on `path`, from its system (compiled or interpreted).
fn ball<S: System + Clone>(sys: S, m: &model::Model, path: &'static str) -> Row
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let r = run(sys, &q0(m), 1000, &mut no_inputs);
    let landed =
        r.q.iter()
            .position(|q| q[2] - 0.1 <= 1e-9)
            .expect("it lands");
    Row {
        case: "ball drop: landing time (s)",
        path,
        measure: ("t", landed as f64 * DT, (2.0 / G).sqrt()),
        penetration: penetration(m, &r),
        energy_gain: energy_gain(&r),
        steps_per_second: rate(&r),
    }
}

fn slide<S: System + Clone>(sys: S, m: &model::Model, path: &'static str) -> Row
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (mu, v0) = (0.5, 1.0);
    let r = run(sys, &q0(m), 400, &mut no_inputs);
    Row {
        case: "box slide: stopping distance (m)",
        path,
        measure: ("x", r.q.last().unwrap()[0], v0 * v0 / (2.0 * mu * G)),
        penetration: penetration(m, &r),
        energy_gain: energy_gain(&r),
        steps_per_second: rate(&r),
    }
}

/// On a slope: the distance slid in 0.5 s against `½ g(sin θ − μ cos θ) t²` (0 when it sticks).
fn slope<S: System + Clone>(sys: S, m: &model::Model, theta: f64, path: &'static str) -> Row
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let r = run(sys, &q0(m), 500, &mut no_inputs);
    let a = (G * (theta.sin() - 0.5 * theta.cos())).max(0.0);
    Row {
        case: if theta < 0.4 {
            "slope 0.3 rad (sticks): distance (m)"
        } else {
            "slope 0.6 rad (slides): distance (m)"
        },
        path,
        measure: ("x", r.q.last().unwrap()[0], 0.5 * a * 0.25),
        penetration: penetration(m, &r),
        energy_gain: energy_gain(&r),
        steps_per_second: rate(&r),
    }
}

/// The crouch the Solo-12's joints are held towards, and the PD gains (N·m/rad, N·m·s/rad).
const CROUCH: [f64; 12] = [
    0.0, 0.8, -1.6, 0.0, 0.8, -1.6, 0.0, -0.8, 1.6, 0.0, -0.8, 1.6,
];
const KP: f64 = 10.0;
const KD: f64 = 0.3;
const FEET: [&str; 4] = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"];

/// The Solo-12 in the crouch with its lowest foot sphere 5 cm above the ground.
fn solo_start(m: &model::Model) -> Vec<f64> {
    let mut q0 = vec![0.0; m.dof()];
    q0[6..].copy_from_slice(&CROUCH);
    let origins = m.origins(&q0);
    let lowest = (FEET.iter())
        .map(|f| origins[m.frame_index(f).unwrap()][2] - 0.016)
        .fold(f64::INFINITY, f64::min);
    q0[2] = 0.05 - lowest;
    q0
}

fn pd(q: &[f64], dq: &[f64], u: &mut [f64]) {
    for (k, u) in u.iter_mut().enumerate() {
        *u = KP * (CROUCH[k] - q[6 + k]) - KD * dq[6 + k];
    }
}

fn solo<S: System + Clone>(sys: S, m: &model::Model, path: &'static str) -> Row
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let r = run(sys, &solo_start(m), 1000, &mut pd);
    Row {
        case: "Solo-12 drop, PD: base height at 1 s (m)",
        path,
        measure: ("z", r.q.last().unwrap()[2], f64::NAN),
        penetration: penetration(m, &r),
        energy_gain: energy_gain(&r),
        steps_per_second: rate(&r),
    }
}

fn balls<S: System + Clone>(sys: S, m: &model::Model, path: &'static str) -> Row
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let r = run(sys, &q0(m), 1000, &mut no_inputs);
    let lowest = (r.q.last().unwrap().chunks(3))
        .map(|p| p[2])
        .fold(f64::INFINITY, f64::min);
    Row {
        case: "27 balls poured: lowest centre at 1 s (m)",
        path,
        measure: ("z", lowest, 0.05),
        penetration: penetration(m, &r),
        energy_gain: energy_gain(&r),
        steps_per_second: rate(&r),
    }
}

/// Microseconds for one linearised contact step of the Solo-12 (`x₂`, `A`, `B`) at κ = 10⁻⁶
/// from the crouch standing on its feet, best of three rounds of `calls`.
fn linearised_step<S: System>(sys: S, m: &model::Model) -> f64
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let settings = ViSettings {
        kappa: 1e-6,
        ..Default::default()
    };
    let mut d = DiscreteSystem::new(sys, settings, DT, 0.0).expect("it builds");
    let mut q0 = solo_start(m);
    q0[2] -= 0.05;
    let x: Vec<f64> = q0.iter().copied().chain(vec![0.0; q0.len()]).collect();
    let u = vec![0.0; d.controls()];
    let (mut x2, n) = (vec![0.0; d.states()], d.states());
    let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, d.controls()));
    let calls = 200;
    let mut best = f64::MAX;
    for _ in 0..3 {
        let start = Instant::now();
        for _ in 0..calls {
            d.step(0, &x, &u, &mut x2, Some((&mut a, &mut b)))
                .expect("the step converges");
        }
        best = best.min(start.elapsed().as_secs_f64() / calls as f64);
    }
    1e6 * best
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let json = args.iter().any(|a| a == "--json");
    // Words (not flags) choose the cases whose names contain one: `-- solo balls`.
    let words: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let wanted = |case: &str| words.is_empty() || words.iter().any(|w| case.contains(w.as_str()));
    let mut rows = Vec::new();
    if wanted("ball drop") {
        let (m, sys) = interpreted("tests/models/ball.toml");
        rows.push(ball(Ball, &m, "compiled"));
        rows.push(ball(sys, &m, "interpreted"));
    }
    if wanted("box slide") {
        let (m, sys) = interpreted("tests/models/box.toml");
        rows.push(slide(Cube, &m, "compiled"));
        rows.push(slide(sys, &m, "interpreted"));
    }
    if wanted("slope") {
        let (m, sys) = interpreted("benches/models/slope-0.3.toml");
        rows.push(slope(Sticks, &m, 0.3, "compiled"));
        rows.push(slope(sys, &m, 0.3, "interpreted"));
        let (m, sys) = interpreted("benches/models/slope-0.6.toml");
        rows.push(slope(Slides, &m, 0.6, "compiled"));
        rows.push(slope(sys, &m, 0.6, "interpreted"));
    }
    let m = Solo::model();
    if wanted("solo drop") {
        rows.push(solo(Solo, &m, "compiled"));
        rows.push(solo(TreeSystem::new(&m).unwrap(), &m, "interpreted"));
    }
    if wanted("balls") {
        let (m, sys) = interpreted("benches/models/balls-27.toml");
        rows.push(balls(Balls, &m, "compiled"));
        rows.push(balls(sys, &m, "interpreted"));
    }
    let linearised = wanted("solo linearised").then(|| {
        let compiled = linearised_step(Solo, &m);
        [compiled, linearised_step(TreeSystem::new(&m).unwrap(), &m)]
    });
    report(&rows, json, linearised);
}

fn report(rows: &[Row], json: bool, linearised: Option<[f64; 2]>) {
    if json {
        for r in rows {
            let v = serde_json::json!({
                "case": r.case, "path": r.path, "value": r.measure.1, "answer": r.measure.2,
                "penetration": r.penetration, "energy_gain": r.energy_gain,
                "steps_per_second": r.steps_per_second,
            });
            println!("{v}");
        }
        for (path, us) in ["compiled", "interpreted"]
            .iter()
            .zip(linearised.iter().flatten())
        {
            println!(
                "{}",
                serde_json::json!({"case": "Solo-12 linearised contact step (µs)", "path": path, "microseconds": us})
            );
        }
        return;
    }
    println!(
        "{:<44} {:<12} {:>12} {:>12} {:>11} {:>11} {:>12}",
        "case", "path", "value", "answer", "penetr. m", "E gain J", "steps/s"
    );
    for r in rows {
        println!(
            "{:<44} {:<12} {:>12.6} {:>12.6} {:>11.2e} {:>11.2e} {:>12.0}",
            r.case,
            r.path,
            r.measure.1,
            r.measure.2,
            r.penetration,
            r.energy_gain,
            r.steps_per_second
        );
    }
    if let Some([compiled, interpreted]) = linearised {
        println!(
            "Solo-12 linearised contact step (x₂, A, B at κ = 1e-6): compiled {compiled:.1} µs, interpreted {interpreted:.1} µs"
        );
    }
}
