//! The VI step's first derivatives (MidpointVi::derivatives) against central differences of
//! the step itself, converged tightly: every block (q₁, p₁, u₁, k₂ → q₂, p₂, λ) on models with
//! constraints, kinematic inputs, damping, dampers, springs and inputs, both forcings, α = ½
//! and α ≠ ½.

mod common;

use nalgebra::{DMatrix, Dyn};
use tree_mech::integrate::{project_initial_state, Forcing, MidpointVi, StepContext, ViSettings};
use tree_mech::model::{self, Model};
use tree_mech::runtime::{ModelMotions, Prescription, Vector};
use tree_mech::{NoForce, System, TreeSystem};

struct Outcome {
    q2: Vector<Dyn>,
    p2: Vector<Dyn>,
    lambda: Vec<f64>,
}

/// One step from `(q1, p1)` with inputs `u`, the kinematic variables at t₂ moved by `dk`.
fn step(
    sys: &mut TreeSystem,
    settings: ViSettings,
    q1: &Vector<Dyn>,
    p1: &Vector<Dyn>,
    u: &[f64],
    dk: &[f64],
    lambda0: &[f64],
) -> (Outcome, MidpointVi<Dyn>) {
    let kinematic: Vec<usize> = (0..sys.dof()).filter(|&i| sys.is_kinematic(i)).collect();
    let base = ModelMotions::of(sys);
    let mut motion = {
        let kinematic = kinematic.clone();
        let dk = dk.to_vec();
        let mut base = base;
        move |i: usize, t: f64| {
            let mut x = base.kinematic(i, t);
            if t > 0.05 {
                if let Some(c) = kinematic.iter().position(|&k| k == i) {
                    x[0] += dk[c];
                }
            }
            x
        }
    };
    let mut vi = MidpointVi::new(sys, settings);
    vi.last_velocity.fill(0.0);
    for (s, l) in lambda0.iter().enumerate() {
        vi.lambda[s] = *l;
    }
    let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
    let mut force = NoForce;
    let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.1);
    cx.u = u;
    vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
    (
        Outcome {
            q2: q,
            p2: p,
            lambda: vi.lambda.iter().copied().collect(),
        },
        vi,
    )
}

fn check(model: &Model, settings: ViSettings, what: &str) {
    let mut sys = TreeSystem::new(model).unwrap();
    let n = sys.dof();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let (q1, dq1) = sys.initial_state();
    let mut q1 = q1;
    let mut motion = ModelMotions::of(&sys);
    for &k in &kinematic {
        q1[k] = motion.kinematic(k, 0.0)[0];
    }
    // On the constraints, moving.
    let mut dq1 = dq1 * 0.3;
    let split = tree_mech::runtime::dynamics::Split::of(&sys);
    project_initial_state(&mut sys, &split, &mut q1, &mut dq1).unwrap();
    let mut vi = MidpointVi::new(&sys, settings);
    let p1 = vi.initial_momentum(&mut sys, &q1, &dq1);
    let u: Vec<f64> = (0..sys.input_count()).map(|k| 0.5 + k as f64).collect();
    let nk = kinematic.len();
    let (base, mut vi) = step(&mut sys, settings, &q1, &p1, &u, &vec![0.0; nk], &[]);
    let lambda0 = base.lambda.clone();
    // The analytic derivatives at the converged step (t₁ = 0, Δt = 0.1).
    let mut motion = ModelMotions::of(&sys);
    let mut force = NoForce;
    let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.1);
    cx.u = &u;
    let d = vi.derivatives(&mut cx, &q1, &p1, &base.q2).unwrap();
    let h = 1e-6;
    // Each input kind: its size and how to perturb it.
    let kinds: [(&str, usize); 4] = [
        ("q1", n),
        ("p1", dynamic.len()),
        ("u1", u.len()),
        ("k2", nk),
    ];
    for (kind, count) in kinds {
        for c in 0..count {
            let run = |sign: f64, sys: &mut TreeSystem| {
                let (mut q, mut p, mut uu, mut dk) =
                    (q1.clone(), p1.clone(), u.clone(), vec![0.0; nk]);
                match kind {
                    "q1" => q[c] += sign * h,
                    "p1" => p[dynamic[c]] += sign * h,
                    "u1" => uu[c] += sign * h,
                    _ => dk[c] += sign * h,
                }
                step(sys, settings, &q, &p, &uu, &dk, &lambda0).0
            };
            let (plus, minus) = (run(1.0, &mut sys), run(-1.0, &mut sys));
            let (aq, ap, al) = match kind {
                "q1" => (&d.q2_dq1, &d.p2_dq1, &d.lambda_dq1),
                "p1" => (&d.q2_dp1, &d.p2_dp1, &d.lambda_dp1),
                "u1" => (&d.q2_du1, &d.p2_du1, &d.lambda_du1),
                _ => (&d.q2_dk2, &d.p2_dk2, &d.lambda_dk2),
            };
            let compare = |exact: &DMatrix<f64>, fd: Vec<f64>, out: &str| {
                let scale = exact.amax().max(1.0);
                for (r, x) in fd.iter().enumerate() {
                    assert!(
                        (x - exact[(r, c)]).abs() < 2e-5 * scale,
                        "{what}: {out}_d{kind}[{r}][{c}] = {} vs finite difference {x}",
                        exact[(r, c)]
                    );
                }
            };
            let fd = |a: &Vector<Dyn>, b: &Vector<Dyn>| {
                dynamic
                    .iter()
                    .map(|&i| (a[i] - b[i]) / (2.0 * h))
                    .collect::<Vec<_>>()
            };
            compare(aq, fd(&plus.q2, &minus.q2), "q2");
            compare(ap, fd(&plus.p2, &minus.p2), "p2");
            let fl = plus
                .lambda
                .iter()
                .zip(&minus.lambda)
                .map(|(a, b)| (a - b) / (2.0 * h))
                .collect();
            compare(al, fl, "lambda");
        }
    }
}

fn tight(alpha: f64, forcing: Forcing) -> ViSettings {
    ViSettings {
        alpha,
        forcing,
        tolerance: 1e-14,
        constraint_tolerance: 1e-14,
        max_iterations: 60,
        ..ViSettings::default()
    }
}

#[test]
fn vi_step_derivatives_match_finite_differences() {
    let root = env!("CARGO_MANIFEST_DIR");
    let elements = model::from_toml_file(format!("{root}/tests/models/elements.toml")).unwrap();
    let cart = model::from_toml_file(format!("{root}/tests/models/cart.toml")).unwrap();
    let string =
        model::from_toml_file(format!("{root}/tests/models/string-pendulum.toml")).unwrap();
    let mut damped = common::load("double-pendulum.toml");
    damped.variables[0].damping = 0.4;
    for (model, name) in [
        (&elements, "elements"),
        (&cart, "cart"),
        (&string, "string pendulum"),
        (&damped, "damped double pendulum"),
    ] {
        for (alpha, forcing) in [
            (0.5, Forcing::Split),
            (0.5, Forcing::Left),
            (0.3, Forcing::Split),
        ] {
            check(
                model,
                tight(alpha, forcing),
                &format!("{name}, α {alpha}, {forcing:?}"),
            );
        }
    }
}

tree_mech::tree_model!(struct Cart from "tests/models/cart.toml");

#[test]
fn compiled_and_interpreted_step_derivatives_agree() {
    let model = Cart::model();
    let mut interpreted = TreeSystem::new(&model).unwrap();
    let settings = tight(0.5, Forcing::Split);
    let mut run = |compiled: bool| -> Vec<DMatrix<f64>> {
        let u = [1.5];
        macro_rules! go {
            ($sys:expr) => {{
                let sys = $sys;
                let (q1, dq1) = sys.initial_state();
                let mut vi = MidpointVi::new(sys, settings);
                let p1 = vi.initial_momentum(sys, &q1, &dq1);
                let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
                let mut motion = ModelMotions::of(sys);
                let mut force = NoForce;
                let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.05);
                cx.u = &u;
                vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
                let d = vi.derivatives(&mut cx, &q1, &p1, &q).unwrap();
                let to = |m: &DMatrix<f64>| m.clone();
                vec![
                    to(&d.q2_dq1),
                    to(&d.q2_dp1),
                    to(&d.q2_du1),
                    to(&d.p2_dq1),
                    to(&d.p2_dp1),
                    to(&d.p2_du1),
                ]
            }};
        }
        if compiled {
            go!(&mut Cart)
        } else {
            go!(&mut interpreted)
        }
    };
    let (a, b) = (run(true), run(false));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).amax() < 1e-12, "compiled {x} vs interpreted {y}");
        assert!(x.amax() > 0.0);
    }
}
