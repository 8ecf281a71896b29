//! The largest robots of example-robot-data, compiled by `tree_model!` and interpreted, beside
//! Pinocchio (C++): Talos (reduced, 32 joints) and the Unitree G1 with its hands (43 joints),
//! both with a floating base. For each: the mass matrix (against CRBA), `q̈` (against ABA), one
//! VI step and one VI step with its first derivatives (against ABA's derivatives), best of 5
//! batches, mean per call. Pinocchio's figures come from `target/pinocchio-timing.json`, which
//! `tools/reference/pinocchio_bench.sh` writes. Their build time is the price of compiling:
//! `touch benches/largest.rs && time cargo build --release --features largest-robots --bench
//! largest` (opt-in: two minutes and 4–5 GB of compiler memory, kept out of CI).
//! Run: `cargo bench --features largest-robots --bench largest`.

use std::hint::black_box;

use tree_mech::integrate::{MidpointVi, StepContext, ViSettings};
use tree_mech::model::{self, UrdfOptions};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::{Dynamics, ModelMotions};
use tree_mech::{tree_model, NoForce, System, Terms, TreeSystem};

mod timing;
use timing::{time_ns, timed_state};

// The robots' limits unenforced: these figures time the smooth dynamics, as Pinocchio's and
// MuJoCo's compared here (and the tasks, which leave them off).
tree_model!(struct Talos from "tests/robots/example-robot-data/talos_data/robots/talos_reduced.urdf", floating_base, enforce_limits = false);
tree_model!(struct G1 from "tests/robots/example-robot-data/g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf", floating_base, enforce_limits = false);

/// `[M, q̈, VI step, VI step + first derivatives]` in ns, at the state Pinocchio is timed at.
fn measure<S: System>(mut sys: S) -> [f64; 4]
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q, dq) = timed_state(&sys);
    let mut terms = Terms::zeros(sys.dim());
    let mass = time_ns(2000, || {
        sys.mass_matrix(black_box(&q), &mut terms);
        black_box(terms.mass[(0, 0)]);
    });
    let mut motion = ModelMotions::of(&sys);
    let mut dynamics = Dynamics::new(&sys);
    let mut qdd = sys.zero_vector();
    let accel = time_ns(2000, || {
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
        dynamics.acceleration(&mut cx, &q, &dq, &mut qdd).unwrap();
        black_box(qdd[0]);
    });
    let mut vi = MidpointVi::new(&sys, ViSettings::default());
    let p0 = vi.initial_momentum(&mut sys, &q, &dq);
    let (mut qk, mut pk, mut next) = (q.clone(), p0.clone(), q.clone());
    let vi_step = time_ns(500, || {
        qk.copy_from(&q);
        pk.copy_from(&p0);
        vi.predict_from(&dq);
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.001);
        vi.step(&mut cx, &mut qk, &mut pk, &mut next).unwrap();
    });
    let u = vec![0.0; sys.input_count()];
    let mut first = tree_mech::integrate::StepDerivatives::empty();
    let mut vi = MidpointVi::new(
        &sys,
        ViSettings {
            derivatives: true,
            ..ViSettings::default()
        },
    );
    let vi_first = time_ns(200, || {
        qk.copy_from(&q);
        pk.copy_from(&p0);
        vi.predict_from(&dq);
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.001);
        cx.u = &u;
        vi.step(&mut cx, &mut qk, &mut pk, &mut next).unwrap();
        vi.derivatives_into(&mut cx, &q, &p0, &qk, &mut first)
            .unwrap();
        black_box(first.q2_dq1[(0, 0)]);
    });
    [mass, accel, vi_step, vi_first]
}

fn interpreted(file: &str) -> TreeSystem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let options = UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    let mut robot = model::from_file(path, options).unwrap();
    robot.contacts.enforce_limits = false; // as the compiled ones
    TreeSystem::new(&robot).unwrap()
}

/// Pinocchio's `[crba, aba, aba_derivatives]` for `label`, if measured.
fn pinocchio(label: &str) -> Option<[f64; 3]> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/pinocchio-timing.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    let get = |k: &str| v[label][k].as_f64();
    Some([get("crba_ns")?, get("aba_ns")?, get("aba_derivatives_ns")?])
}

fn main() {
    const ROBOTS: &str = "tests/robots/example-robot-data";
    let rows = [
        (
            "Talos reduced, floating base",
            "talos",
            Talos::DOF,
            Talos::STATEMENTS,
            measure(Talos),
            measure(interpreted(&format!(
                "{ROBOTS}/talos_data/robots/talos_reduced.urdf"
            ))),
        ),
        (
            "G1 with hands, floating base",
            "g1",
            G1::DOF,
            G1::STATEMENTS,
            measure(G1),
            measure(interpreted(&format!(
                "{ROBOTS}/g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf"
            ))),
        ),
    ];
    println!("| robot (variables, statements) | | M | q̈ | VI step | VI step + first derivatives |");
    println!("|---|---|---:|---:|---:|---:|");
    for (name, label, dof, statements, compiled, interp) in &rows {
        let f = |x: &[f64; 4]| {
            x.iter()
                .map(|t| format!("{:.2} µs", t / 1e3))
                .collect::<Vec<_>>()
                .join(" | ")
        };
        println!(
            "| {name} ({dof}, {statements}) | compiled | {} |",
            f(compiled)
        );
        println!("| | interpreted | {} |", f(interp));
        let ratio: Vec<String> = (compiled.iter().zip(interp))
            .map(|(c, i)| format!("{:.2}×", c / i))
            .collect();
        println!("| | compiled / interpreted | {} |", ratio.join(" | "));
        if let Some([crba, aba, abad]) = pinocchio(label) {
            println!(
                "| | Pinocchio (C++) | CRBA {:.2} µs | ABA {:.2} µs | — | ABA derivatives {:.2} µs |",
                crba / 1e3,
                aba / 1e3,
                abad / 1e3
            );
            println!(
                "| | compiled / Pinocchio | {:.2}× | {:.2}× | | {:.2}× |",
                compiled[0] / crba,
                compiled[1] / aba,
                compiled[3] / abad
            );
        }
    }
}
