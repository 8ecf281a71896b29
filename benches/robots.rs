//! The URDF robots (UR5, Panda, Solo-12 with a floating base) against Pinocchio: tree-mech's
//! mass matrix (`System::mass_matrix`: M(q) and L(q, 0), as CRBA gives M), q̈ (the library's
//! dynamics), a full second-order evaluation, one VI step and one RK4 step, compiled and
//! interpreted; beside them Pinocchio's CRBA, RNEA (nonlinear effects), ABA and ABA
//! derivatives from `target/pinocchio-timing.json` when `tools/reference/pinocchio_bench.sh`
//! has written it; then the derivatives: the continuous linearisation (∂q̈/∂(q, q̇, u)), one VI
//! step with its first derivatives, and the step's contracted second derivatives, against
//! Pinocchio's `computeABADerivatives`. Same timing method on both sides: best of 5 batches,
//! mean per call.
//! Run: `cargo bench --bench robots`. `cargo bench --bench robots -- variants` times the
//! compiled robots with the generated code's recorded variant and its AVX2-and-FMA one
//! (`tree_mech::kernel::cpu`), alternated, side by side.

use std::hint::black_box;

use tree_mech::integrate::{MidpointVi, Rk4, StepContext, StepCovector, ViSettings};
use tree_mech::model::{self, UrdfOptions};
use tree_mech::nalgebra::DVector;
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::linearize::continuous_derivatives;
use tree_mech::runtime::{Dynamics, ModelMotions, Vector};
use tree_mech::{tree_model, NoForce, Order, System, Terms, TreeSystem};

mod timing;
use timing::{time_ns, timed_state};

// The robots' limits unenforced: these figures time the smooth dynamics, as Pinocchio's and
// MuJoCo's compared here (and the tasks, which leave them off).
tree_model!(struct Ur5 from "models/ur5.urdf", enforce_limits = false);
tree_model!(struct Panda from "models/panda.urdf", enforce_limits = false);
tree_model!(struct Solo12 from "models/solo12.urdf", floating_base, enforce_limits = false);

/// `[M, q̈, full evaluation, VI step, RK4 step, continuous derivatives, VI step + first
/// derivatives, contracted second derivatives]` in ns, at the state Pinocchio is timed at.
fn measure<S: System>(mut sys: S) -> [f64; 8]
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    let (q, dq) = timed_state(&sys);
    let calls = 20_000;
    let mut terms = Terms::zeros(sys.dim());
    let mass = time_ns(calls, || {
        sys.mass_matrix(black_box(&q), &mut terms);
        black_box(terms.mass[(0, 0)]);
    });
    let full = time_ns(calls, || {
        sys.lagrangian(black_box(&q), black_box(&dq), Order::Full, &mut terms);
        black_box(terms.d2l_dq_dq[(0, 0)]);
    });
    let mut dynamics = Dynamics::new(&sys);
    let mut motion = ModelMotions::of(&sys);
    let mut qdd = sys.zero_vector();
    let accel = time_ns(calls, || {
        let mut no_force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut no_force, &mut motion, 0.0);
        dynamics.acceleration(&mut cx, &q, &dq, &mut qdd).unwrap();
        black_box(qdd[0]);
    });
    let mut vi = MidpointVi::new(&sys, ViSettings::default());
    let p0 = vi.initial_momentum(&mut sys, &q, &dq);
    let (mut qk, mut pk, mut next) = (q.clone(), p0.clone(), q.clone());
    let vi_step = time_ns(calls / 10, || {
        qk.copy_from(&q);
        pk.copy_from(&p0);
        vi.predict_from(&dq);
        vi.step(
            &mut StepContext::new(&mut sys, &mut NoForce, &mut motion, 0.001),
            &mut qk,
            &mut pk,
            &mut next,
        )
        .unwrap();
    });
    let mut rk = Rk4::new(&sys);
    let (mut qr, mut vr): (Vector<S::N>, Vector<S::N>) = (q.clone(), dq.clone());
    let rk4 = time_ns(calls / 10, || {
        qr.copy_from(&q);
        vr.copy_from(&dq);
        rk.step(
            &mut StepContext::new(&mut sys, &mut NoForce, &mut motion, 0.001),
            &mut qr,
            &mut vr,
        )
        .unwrap();
    });
    let u = vec![0.0; sys.input_count()];
    let continuous = time_ns(calls / 10, || {
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
        cx.u = &u;
        black_box(continuous_derivatives(&mut cx, &q, &dq).unwrap());
    });
    let mut first = tree_mech::integrate::StepDerivatives::empty();
    // Steps whose derivatives follow: Newton's last check leaves the terms they need.
    let mut vi = MidpointVi::new(
        &sys,
        ViSettings {
            derivatives: true,
            ..ViSettings::default()
        },
    );
    let vi_first = time_ns(calls / 10, || {
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
    let nd = (0..n).filter(|&i| !sys.is_kinematic(i)).count();
    let w = StepCovector {
        q2: DVector::from_element(nd, 1.0),
        p2: DVector::from_element(nd, 0.5),
        lambda: DVector::zeros(sys.constraint_count()),
    };
    let mut hessian = tree_mech::nalgebra::DMatrix::zeros(0, 0);
    let contracted = time_ns(calls / 100, || {
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.001);
        cx.u = &u;
        vi.contracted_second_derivatives(&mut cx, &q, &p0, &qk, &w, &mut hessian)
            .unwrap();
        black_box(hessian[(0, 0)]);
    });
    [
        mass, accel, full, vi_step, rk4, continuous, vi_first, contracted,
    ]
}

fn interpreted(file: &str, floating_base: bool) -> TreeSystem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let options = UrdfOptions {
        floating_base,
        ..Default::default()
    };
    let mut robot = model::from_file(path, options).unwrap();
    robot.contacts.enforce_limits = false; // as the compiled ones
    TreeSystem::new(&robot).unwrap()
}

/// Pinocchio's `[crba, nle, aba, aba_derivatives]` for `label`, if measured.
fn pinocchio(label: &str) -> Option<[f64; 4]> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/pinocchio-timing.json");
    let text = std::fs::read_to_string(path).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let r = &v[label];
    let get = |k: &str| r[k].as_f64();
    Some([
        get("crba_ns")?,
        get("nle_ns")?,
        get("aba_ns")?,
        get("aba_derivatives_ns")?,
    ])
}

/// The compiled robots with the recorded variant of the generated code and with the fused
/// one, alternated three times (best of each): every figure of [`measure`], and the ratio.
fn variants() {
    use tree_mech::kernel::cpu;
    if !cpu::fused() || cpu::FUSED_ONLY {
        println!("one variant runs here (fused: {})", cpu::fused());
        return;
    }
    let names = [
        "M",
        "q̈",
        "full evaluation",
        "VI step",
        "RK4 step",
        "∂q̈/∂(q, q̇, u)",
        "VI step + first derivatives",
        "contracted second derivatives",
    ];
    println!("| robot | | {} |", names.join(" | "));
    println!("|---|---|{}", "---:|".repeat(names.len()));
    for (robot, run) in [
        ("UR5", (|| measure(Ur5)) as fn() -> [f64; 8]),
        ("Panda", || measure(Panda)),
        ("Solo-12", || measure(Solo12)),
    ] {
        let (mut plain, mut fused) = ([f64::INFINITY; 8], [f64::INFINITY; 8]);
        for _ in 0..3 {
            for (forced, best) in [(true, &mut plain), (false, &mut fused)] {
                cpu::force_plain(forced);
                for (b, t) in best.iter_mut().zip(run()) {
                    *b = b.min(t);
                }
            }
        }
        let row = |x: &[f64; 8]| {
            (x.iter().map(|t| format!("{:.2} µs", t / 1e3)))
                .collect::<Vec<_>>()
                .join(" | ")
        };
        println!("| {robot} | recorded | {} |", row(&plain));
        println!("| | fused (AVX2, FMA) | {} |", row(&fused));
        let ratios: Vec<String> = (plain.iter().zip(&fused))
            .map(|(p, f)| format!("{:.2}×", f / p))
            .collect();
        println!("| | fused / recorded | {} |", ratios.join(" | "));
    }
}

fn main() {
    if std::env::args().any(|a| a == "variants") {
        variants();
        return;
    }
    let rows = [
        (
            "UR5 (6)",
            "ur5",
            measure(Ur5),
            measure(interpreted("models/ur5.urdf", false)),
        ),
        (
            "Panda (9)",
            "panda",
            measure(Panda),
            measure(interpreted("models/panda.urdf", false)),
        ),
        (
            "Solo-12, floating base (18)",
            "solo12",
            measure(Solo12),
            measure(interpreted("models/solo12.urdf", true)),
        ),
    ];
    println!("| robot (dof) | | M | q̈ | full 2nd-order evaluation | VI step | RK4 step |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    for (name, label, generated, interp) in &rows {
        let f = |x: &[f64; 8]| {
            x[..5]
                .iter()
                .map(|t| format!("{t:.0} ns"))
                .collect::<Vec<_>>()
                .join(" | ")
        };
        println!("| {name} | tree-mech compiled | {} |", f(generated));
        println!("| | tree-mech interpreted | {} |", f(interp));
        if let Some([crba, nle, aba, abad]) = pinocchio(label) {
            println!(
                "| | Pinocchio (C++) | CRBA {crba:.0} ns (nle {nle:.0} ns) | ABA {aba:.0} ns | ABA derivatives {abad:.0} ns | — | — |"
            );
            println!(
                "| | compiled / Pinocchio | {:.2}× CRBA | {:.2}× ABA | {:.2}× ABA derivatives | | |",
                generated[0] / crba,
                generated[1] / aba,
                generated[2] / abad
            );
        }
    }
    println!();
    println!("| robot (dof) | | ∂q̈/∂(q, q̇, u) | VI step + first derivatives | contracted second derivatives |");
    println!("|---|---|---:|---:|---:|");
    for (name, label, generated, interp) in &rows {
        let f = |x: &[f64; 8]| {
            x[5..]
                .iter()
                .map(|t| format!("{:.1} µs", t / 1e3))
                .collect::<Vec<_>>()
                .join(" | ")
        };
        println!("| {name} | tree-mech compiled | {} |", f(generated));
        println!("| | tree-mech interpreted | {} |", f(interp));
        if let Some([_, _, _, abad]) = pinocchio(label) {
            println!(
                "| | Pinocchio computeABADerivatives | {:.1} µs | — | — |",
                abad / 1e3
            );
            println!(
                "| | compiled / Pinocchio | {:.2}× | {:.2}× | {:.1}× |",
                generated[5] / abad,
                generated[6] / abad,
                generated[7] / abad
            );
        }
    }
}
