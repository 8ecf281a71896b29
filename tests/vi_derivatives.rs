//! The VI step's first derivatives (MidpointVi::derivatives) against central differences of
//! the step itself, converged tightly: every block (q₁, p₁, u₁, k₂ → q₂, p₂, λ) on models with
//! constraints, kinematic inputs, damping, dampers, springs and inputs, both forcings, α = ½
//! and α ≠ ½.

mod common;

use nalgebra::{allocator::Allocator, DMatrix, DefaultAllocator, Dyn};
use tree_mech::integrate::{
    project_initial_state, Forcing, MidpointVi, StepContext, StepCovector, StepDerivatives,
    StepInput, StepOutput, StepSecondDerivatives, ViSettings,
};
use tree_mech::model::{self, Model};
use tree_mech::runtime::{ModelMotions, Prescription, Vector};
use tree_mech::{NoForce, System, TreeSystem};

struct Outcome {
    q2: Vector<Dyn>,
    p2: Vector<Dyn>,
    lambda: Vec<f64>,
}

/// One step of `dt` from `(q1, p1)` with inputs `u`, the kinematic variables at t₂ moved by
/// `dk`.
#[allow(clippy::too_many_arguments)] // the step's inputs, each perturbed in turn
fn step(
    sys: &mut TreeSystem,
    settings: ViSettings,
    dt: f64,
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
            if t > 0.5 * dt {
                if let Some(c) = kinematic.iter().position(|&k| k == i) {
                    x[0] += dk[c];
                }
            }
            x
        }
    };
    let mut vi = MidpointVi::new(sys, settings);
    vi.predict_from_rest();
    for (s, l) in lambda0.iter().enumerate() {
        vi.lambda[s] = *l;
    }
    let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
    let mut force = NoForce;
    let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
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

/// The model's start on its constraints and moving (its kinematic variables at their
/// prescription, 0.3 of its initial velocity, projected), its momentum, and an input value
/// per input: `(q₁, q̇₁, p₁, u)`.
#[allow(clippy::type_complexity)] // the start's four parts, named at each use
fn moving_start<S: System>(
    sys: &mut S,
    settings: ViSettings,
) -> (Vector<S::N>, Vector<S::N>, Vector<S::N>, Vec<f64>)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (mut q1, dq1) = sys.initial_state();
    let mut motion = ModelMotions::of(sys);
    for k in (0..sys.dof()).filter(|&i| sys.is_kinematic(i)) {
        q1[k] = motion.kinematic(k, 0.0)[0];
    }
    let mut dq1 = dq1 * 0.3;
    let split = tree_mech::runtime::dynamics::Split::of(sys);
    project_initial_state(sys, &split, &mut q1, &mut dq1).unwrap();
    let mut vi = MidpointVi::new(sys, settings);
    let p1 = vi.initial_momentum(sys, &q1, &dq1);
    let u = (0..sys.input_count()).map(|k| 0.5 + k as f64).collect();
    (q1, dq1, p1, u)
}

fn check(model: &Model, settings: ViSettings, what: &str) {
    check_at(model, settings, 0.1, 1e-6, what, |exact| {
        exact.amax().max(1.0)
    });
}

/// [`check`] for a step of `dt`, finite differences of step `h`, each block compared to
/// `2·10⁻⁵ · scale(block)`.
fn check_at(
    model: &Model,
    settings: ViSettings,
    dt: f64,
    h: f64,
    what: &str,
    scale: impl Fn(&DMatrix<f64>) -> f64,
) {
    let mut sys = TreeSystem::new(model).unwrap();
    let n = sys.dof();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let (q1, _, p1, u) = moving_start(&mut sys, settings);
    let nk = kinematic.len();
    let (base, mut vi) = step(&mut sys, settings, dt, &q1, &p1, &u, &vec![0.0; nk], &[]);
    let lambda0 = base.lambda.clone();
    // The analytic derivatives at the converged step (t₁ = 0).
    let mut motion = ModelMotions::of(&sys);
    let mut force = NoForce;
    let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, dt);
    cx.u = &u;
    let d = vi.derivatives(&mut cx, &q1, &p1, &base.q2).unwrap();
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
                step(sys, settings, dt, &q, &p, &uu, &dk, &lambda0).0
            };
            let (plus, minus) = (run(1.0, &mut sys), run(-1.0, &mut sys));
            let (aq, ap, al) = match kind {
                "q1" => (&d.q2_dq1, &d.p2_dq1, &d.lambda_dq1),
                "p1" => (&d.q2_dp1, &d.p2_dp1, &d.lambda_dp1),
                "u1" => (&d.q2_du1, &d.p2_du1, &d.lambda_du1),
                _ => (&d.q2_dk2, &d.p2_dk2, &d.lambda_dk2),
            };
            let compare = |exact: &DMatrix<f64>, fd: Vec<f64>, out: &str| {
                let scale = scale(exact);
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

/// Every model and setting the derivative checks run on: constraints, kinematic inputs,
/// damping, dampers, springs and inputs; both forcings, α = ½ and α ≠ ½.
fn cases() -> Vec<(Model, ViSettings, String)> {
    let root = env!("CARGO_MANIFEST_DIR");
    let file = |name: &str| model::from_toml_file(format!("{root}/tests/models/{name}")).unwrap();
    let mut damped = common::load("double-pendulum.toml");
    damped.variables[0].damping = 0.4;
    let models = [
        (file("elements.toml"), "elements"),
        (
            interleaved(),
            "elements, kinematic variables between dynamic ones",
        ),
        (file("cart.toml"), "cart"),
        (file("string-pendulum.toml"), "string pendulum"),
        (damped, "damped double pendulum"),
        (file("mimic.toml"), "mimic frames"),
    ];
    let mut out = Vec::new();
    for (model, name) in models {
        for (alpha, forcing) in [
            (0.5, Forcing::Split),
            (0.5, Forcing::Left),
            (0.3, Forcing::Split),
        ] {
            let what = format!("{name}, α {alpha}, {forcing:?}");
            out.push((model.clone(), tight(alpha, forcing), what));
        }
        // Steps that end on a second-order evaluation, which the derivatives then reuse.
        let settings = ViSettings {
            derivatives: true,
            ..tight(0.5, Forcing::Split)
        };
        out.push((
            model,
            settings,
            format!("{name}, reusing the step's evaluation"),
        ));
    }
    out
}

/// elements.toml with the hand's frames declared before the elbow, so that its kinematic
/// variables fall between dynamic ones (yaw, pitch, hand_x, hand_z, bend, slide, len): the
/// step's Jacobians are written a run of dynamic or kinematic variables at a time, and every
/// other model here has its kinematic variables last.
fn interleaved() -> Model {
    let root = env!("CARGO_MANIFEST_DIR");
    let text = std::fs::read_to_string(format!("{root}/tests/models/elements.toml")).unwrap();
    let hand = "[[frame]]\nname = \"hand\"\ntx = \"hand_x\"\n\n\
                [[frame]]\nname = \"hand_z\"\nparent = \"hand\"\ntz = \"hand_z\"\n\n";
    let elbow = "[[frame]]\nname = \"elbow\"";
    assert!(
        text.contains(hand) && text.contains(elbow),
        "elements.toml as this test knows it"
    );
    let moved = text
        .replace(hand, "")
        .replace(elbow, &format!("{hand}{elbow}"));
    let model = model::from_toml_str(&moved, None).expect("a valid model");
    let kinds: String = (model.variables.iter())
        .map(|v| if v.is_kinematic() { 'k' } else { 'd' })
        .collect();
    assert_eq!(
        kinds, "ddkkddk",
        "the kinematic variables between dynamic ones"
    );
    model
}

#[test]
fn vi_step_derivatives_match_finite_differences() {
    for (model, settings, what) in cases() {
        check(&model, settings, &what);
    }
}

tree_mech::tree_model!(struct Cart from "tests/models/cart.toml");

/// At a short step the unknowns of the derivatives' Newton matrix differ in scale by orders of
/// magnitude (momentum rows over Δt against multiplier columns times Δt: 10⁹ at Δt = 10⁻⁴),
/// which a singularity test relative to the whole matrix took for a singular one (this model
/// below Δt = 10⁻⁵, trep's Puppet below 10⁻³). Each block is compared relative to its own
/// size.
#[test]
fn constrained_step_derivatives_at_a_short_step_match_finite_differences() {
    let root = env!("CARGO_MANIFEST_DIR");
    let model = model::from_toml_file(format!("{root}/tests/models/string-pendulum.toml")).unwrap();
    for dt in [1e-3, 1e-5, 1e-6] {
        let what = format!("string pendulum, Δt = {dt}");
        check_at(
            &model,
            tight(0.5, Forcing::Split),
            dt,
            1e-5,
            &what,
            |exact| exact.amax().max(1e-300),
        );
    }
}

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

/// Every first derivative of the step side by side over `x = (q₁, p₁, u₁, k₂)`: one
/// `rows × x` matrix per output block.
fn flat(d: &StepDerivatives) -> Vec<DMatrix<f64>> {
    StepOutput::ALL
        .iter()
        .map(|&of| {
            let blocks: Vec<&DMatrix<f64>> =
                StepInput::ALL.iter().map(|&by| d.block(of, by)).collect();
            let rows = blocks[0].nrows();
            let width: usize = blocks.iter().map(|b| b.ncols()).sum();
            let mut out = DMatrix::zeros(rows, width);
            let mut c0 = 0;
            for b in blocks {
                out.view_mut((0, c0), (rows, b.ncols())).copy_from(b);
                c0 += b.ncols();
            }
            out
        })
        .collect()
}

/// The step from `(q1, p1, u, dk)` and its first (and second) derivatives.
fn step_and_derivatives(
    sys: &mut TreeSystem,
    settings: ViSettings,
    x: (&Vector<Dyn>, &Vector<Dyn>, &[f64], &[f64]),
    lambda0: &[f64],
) -> (StepDerivatives, StepSecondDerivatives) {
    let (q1, p1, u, dk) = x;
    let (out, mut vi) = step(sys, settings, 0.1, q1, p1, u, dk, lambda0);
    let mut motion = ModelMotions::of(sys);
    let mut force = NoForce;
    let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.1);
    cx.u = u;
    vi.second_derivatives(&mut cx, q1, p1, &out.q2).unwrap()
}

/// The second derivatives against central differences of the exact first ones, their
/// symmetry, and the contracted form against the full tensors.
fn check_second(model: &Model, settings: ViSettings, what: &str) {
    let mut sys = TreeSystem::new(model).unwrap();
    let n = sys.dof();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let (mut q1, dq1) = sys.initial_state();
    let mut motion = ModelMotions::of(&sys);
    for &k in &kinematic {
        q1[k] = motion.kinematic(k, 0.0)[0];
    }
    let mut dq1 = dq1 * 0.3;
    let split = tree_mech::runtime::dynamics::Split::of(&sys);
    project_initial_state(&mut sys, &split, &mut q1, &mut dq1).unwrap();
    let vi = MidpointVi::new(&sys, settings);
    let mut vi0 = vi.clone();
    let p1 = vi0.initial_momentum(&mut sys, &q1, &dq1);
    let u: Vec<f64> = (0..sys.input_count()).map(|k| 0.5 + k as f64).collect();
    let (nd, nu, nk) = (dynamic.len(), u.len(), kinematic.len());
    let zero_dk = vec![0.0; nk];
    let (base_first, base) =
        step_and_derivatives(&mut sys, settings, (&q1, &p1, &u, &zero_dk), &[]);
    let lambda0: Vec<f64> = {
        let (out, _) = step(&mut sys, settings, 0.1, &q1, &p1, &u, &zero_dk, &[]);
        out.lambda
    };
    let tensors = [&base.q2, &base.p2, &base.lambda];
    let x = n + nd + nu + nk;
    let mut worst = 0.0f64;
    let h = 1e-5;
    for j in 0..x {
        let run = |sign: f64, sys: &mut TreeSystem| {
            let (mut q, mut p, mut uu, mut dk) =
                (q1.clone(), p1.clone(), u.clone(), zero_dk.clone());
            match j {
                j if j < n => q[j] += sign * h,
                j if j < n + nd => p[dynamic[j - n]] += sign * h,
                j if j < n + nd + nu => uu[j - n - nd] += sign * h,
                j => dk[j - n - nd - nu] += sign * h,
            }
            flat(&step_and_derivatives(sys, settings, (&q, &p, &uu, &dk), &lambda0).0)
        };
        let (plus, minus) = (run(1.0, &mut sys), run(-1.0, &mut sys));
        for (o, exact) in tensors.iter().enumerate() {
            for (r, hess) in exact.iter().enumerate() {
                let scale = hess.amax().max(1.0);
                for i in 0..x {
                    let fd = (plus[o][(r, i)] - minus[o][(r, i)]) / (2.0 * h);
                    let err = (fd - hess[(i, j)]).abs() / scale;
                    worst = worst.max(err);
                    assert!(
                        err < 1e-7,
                        "{what}: {:?} row {r}, ∂²/∂x{i}∂x{j} = {} vs finite difference {fd}",
                        StepOutput::ALL[o],
                        hess[(i, j)]
                    );
                }
            }
        }
    }
    // Symmetric, and not trivially zero.
    let mut largest = 0.0f64;
    for hess in tensors.iter().flat_map(|t| t.iter()) {
        assert!(
            (hess - hess.transpose()).amax() <= 1e-9 * hess.amax().max(1.0),
            "{what}: asymmetric {hess}"
        );
        largest = largest.max(hess.amax());
    }
    assert!(largest > 1e-3, "{what}: second derivatives all ~0");
    // The contracted form equals the tensors contracted.
    let mut rng = common::Rng::new(11);
    let w = StepCovector {
        q2: nalgebra::DVector::from_column_slice(rng.vector(nd, 1.0).as_slice()),
        p2: nalgebra::DVector::from_column_slice(rng.vector(nd, 1.0).as_slice()),
        lambda: nalgebra::DVector::from_column_slice(rng.vector(base.lambda.len(), 1.0).as_slice()),
    };
    let mut expected = DMatrix::<f64>::zeros(x, x);
    for (r, hess) in base.q2.iter().enumerate() {
        expected += hess * w.q2[r];
    }
    for (r, hess) in base.p2.iter().enumerate() {
        expected += hess * w.p2[r];
    }
    for (s, hess) in base.lambda.iter().enumerate() {
        expected += hess * w.lambda[s];
    }
    let (out, mut vi) = step(&mut sys, settings, 0.1, &q1, &p1, &u, &zero_dk, &[]);
    let mut motion = ModelMotions::of(&sys);
    let mut force = NoForce;
    let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.1);
    cx.u = &u;
    let mut contracted = DMatrix::zeros(0, 0);
    vi.contracted_second_derivatives(&mut cx, &q1, &p1, &out.q2, &w, &mut contracted)
        .unwrap();
    assert!(
        (&contracted - &expected).amax() <= 1e-10 * expected.amax().max(1.0),
        "{what}: contracted {contracted} vs {expected}"
    );
    assert_eq!(
        flat(&base_first),
        flat(&vi.derivatives(&mut cx, &q1, &p1, &out.q2).unwrap())
    );
    eprintln!("{what}: worst relative error {worst:.1e}");
}

#[test]
fn vi_step_second_derivatives_match_finite_differences() {
    for (model, settings, what) in cases() {
        check_second(&model, settings, &what);
    }
}

tree_mech::tree_model!(struct Elements from "tests/models/elements.toml");

/// The compiled dual program against the interpreted kernel: the VI step's second
/// derivatives and the continuous linearisation, on a model with every element.
#[test]
fn compiled_and_interpreted_second_derivatives_agree() {
    use tree_mech::runtime::linearize::continuous_derivatives;
    let model = Elements::model();
    let mut interpreted = TreeSystem::new(&model).unwrap();
    let settings = tight(0.5, Forcing::Split);
    let mut run = |compiled: bool| -> Vec<DMatrix<f64>> {
        macro_rules! go {
            ($sys:expr) => {{
                let sys = $sys;
                let (q1, dq1, p1, _) = moving_start(sys, settings);
                let mut motion = ModelMotions::of(sys);
                let mut vi = MidpointVi::new(sys, settings);
                vi.predict_from(&dq1);
                let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
                let mut force = NoForce;
                let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.05);
                vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
                let (_, second) = vi.second_derivatives(&mut cx, &q1, &p1, &q).unwrap();
                let c = continuous_derivatives(cx.at(0, 0.0), &q1, &dq1).unwrap();
                let mut out: Vec<DMatrix<f64>> = second
                    .q2
                    .iter()
                    .chain(&second.p2)
                    .chain(&second.lambda)
                    .cloned()
                    .collect();
                out.extend([c.qdd_dq, c.qdd_ddq, c.lambda_dq, c.lambda_ddq]);
                out
            }};
        }
        if compiled {
            go!(&mut Elements)
        } else {
            go!(&mut interpreted)
        }
    };
    let (a, b) = (run(true), run(false));
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        let scale = y.amax().max(1.0);
        assert!(
            (x - y).amax() < 1e-12 * scale,
            "compiled {x} vs interpreted {y}"
        );
    }
    assert!(a.iter().any(|m| m.amax() > 1e-3));
}

/// A step that ends on a second-order evaluation hands it to its derivatives: they equal the
/// ones evaluated afresh at the solution (to the solve's rounding), on every model.
#[test]
fn derivatives_reuse_the_steps_last_evaluation() {
    for (model, settings, what) in cases() {
        if settings.derivatives {
            continue;
        }
        let mut sys = TreeSystem::new(&model).unwrap();
        let (q1, _, p1, u) = moving_start(&mut sys, settings);
        let nk = (0..sys.dof()).filter(|&i| sys.is_kinematic(i)).count();
        let first = |sys: &mut TreeSystem, derivatives: bool| {
            let settings = ViSettings {
                derivatives,
                ..settings
            };
            let (out, mut vi) = step(sys, settings, 0.1, &q1, &p1, &u, &vec![0.0; nk], &[]);
            let mut motion = ModelMotions::of(sys);
            let mut force = NoForce;
            let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.1);
            cx.u = &u;
            flat(&vi.derivatives(&mut cx, &q1, &p1, &out.q2).unwrap())
        };
        let (fresh, reused) = (first(&mut sys, false), first(&mut sys, true));
        for (a, b) in fresh.iter().zip(&reused) {
            let scale = a.amax().max(1.0);
            assert!(
                (a - b).amax() < 1e-10 * scale,
                "{what}: reused {b} vs fresh {a}"
            );
        }
    }
}

/// A Newton matrix that is singular names the unknown whose pivot vanished: the string
/// pendulum's string given twice makes the second string's multiplier dependent (the
/// elimination order's own mapping is tested beside it, `first.rs`). With the step and time,
/// on both forcings; the model as it is linearises at the same point.
#[test]
fn a_singular_newton_matrix_names_the_unknown_whose_pivot_vanished() {
    let root = env!("CARGO_MANIFEST_DIR");
    let text = std::fs::read_to_string(format!("{root}/tests/models/string-pendulum.toml"))
        .expect("the model");
    let twice = format!(
        "{text}\n[[constraint]]\nname = \"twin\"\nkind = \"distance\"\nframes = [\"bob\", \"anchor\"]\nlength = 1.5\n"
    );
    let cases = [(text, None), (twice, Some("the λ of constraint `twin`"))];
    for (source, singular) in cases {
        let model = model::from_toml_str(&source, None).expect("a valid model");
        let sys = &mut TreeSystem::new(&model).expect("a valid system");
        for forcing in [Forcing::Split, Forcing::Left] {
            let (q1, dq1) = sys.initial_state();
            let mut vi = MidpointVi::new(sys, tight(0.5, forcing));
            let p1 = vi.initial_momentum(sys, &q1, &dq1);
            let mut motion = ModelMotions::of(sys);
            let mut force = NoForce;
            let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.01);
            (cx.index, cx.t) = (7, 0.07);
            let q2 = q1.clone();
            match (vi.derivatives(&mut cx, &q1, &p1, &q2), singular) {
                (Ok(d), None) => {
                    assert!(d.q2_dq1.iter().all(|x| x.is_finite()) && d.q2_dq1.amax() > 0.0);
                }
                (Err(e), Some(unknown)) => {
                    let want = format!(
                        "step 7 (t = 0.07): variational integrator Newton matrix is singular (at {unknown})"
                    );
                    assert_eq!(e.to_string(), want, "{forcing:?}");
                    assert_eq!(e.when(), Some((7, 0.07)), "{forcing:?}");
                }
                (outcome, _) => panic!("{forcing:?}, {singular:?}: {:?}", outcome.map(|_| ())),
            }
        }
    }
}
