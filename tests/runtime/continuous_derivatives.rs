//! The continuous linearisation (runtime::linearize) against central differences of the
//! accelerations and constraint forces: with constraints, kinematic inputs, springs, dampers,
//! damping and inputs.

use crate::common;

use nalgebra::Dyn;
use tree_mech::integrate::{project_initial_state, StepContext};
use tree_mech::model;
use tree_mech::runtime::dynamics::Split;
use tree_mech::runtime::linearize::continuous_derivatives;
use tree_mech::runtime::{Dynamics, ModelMotions, Prescription, Vector};
use tree_mech::{NoForce, Order, System, Terms, TreeSystem};

/// `(q̈_d, λ)` at `(q, q̇, u)`, t = 0.3.
fn accelerations(
    sys: &mut TreeSystem,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    u: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let mut dynamics = Dynamics::new(sys);
    let mut motion = ModelMotions::of(sys);
    let mut force = NoForce;
    let mut qdd = Vector::<Dyn>::zeros(q.len());
    let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.0);
    cx.u = u;
    dynamics
        .acceleration(cx.at(0, 0.3), q, dq, &mut qdd)
        .unwrap();
    let d = dynamics.split.dynamic.clone();
    (
        d.iter().map(|&i| qdd[i]).collect(),
        dynamics.lambda.iter().copied().collect(),
    )
}

#[test]
fn continuous_derivatives_match_finite_differences() {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut damped = common::load("humanoid.toml");
    damped.variables[3].damping = 0.7;
    // Every element without and with the constraints: the right sides by recursive
    // Newton–Euler and the constraints over jets (the fallback over dual numbers is held to
    // these below).
    let mut unconstrained =
        model::from_toml_file(format!("{root}/tests/models/elements.toml")).unwrap();
    unconstrained.constraints.clear();
    for (name, model) in [
        ("elements without constraints", unconstrained),
        (
            "elements",
            model::from_toml_file(format!("{root}/tests/models/elements.toml")).unwrap(),
        ),
        (
            "cart",
            model::from_toml_file(format!("{root}/tests/models/cart.toml")).unwrap(),
        ),
        (
            "string pendulum",
            model::from_toml_file(format!("{root}/tests/models/string-pendulum.toml")).unwrap(),
        ),
        ("humanoid", damped),
    ] {
        let mut sys = TreeSystem::new(&model).unwrap();
        let n = sys.dof();
        let (mut q, dq0) = sys.initial_state();
        let mut rng = common::Rng::new(5);
        let mut dq = dq0 + rng.vector(n, 0.5);
        let mut motion = ModelMotions::of(&sys);
        let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
        for &k in &kinematic {
            [q[k], dq[k], _] = motion.kinematic(k, 0.3);
        }
        let split = Split::of(&sys);
        project_initial_state(&mut sys, &split, &mut q, &mut dq).unwrap();
        let u: Vec<f64> = (0..sys.input_count())
            .map(|k| 0.4 * (k + 1) as f64)
            .collect();
        let mut force = NoForce;
        let mut motion = ModelMotions::of(&sys);
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
        cx.u = &u;
        let d = continuous_derivatives(cx.at(0, 0.3), &q, &dq).unwrap();
        let h = 1e-6;
        let columns = [("q", n), ("dq", n), ("u", u.len())];
        for (kind, count) in columns {
            for j in 0..count {
                let at = |sign: f64, sys: &mut TreeSystem| {
                    let (mut q, mut dq, mut u) = (q.clone(), dq.clone(), u.clone());
                    match kind {
                        "q" => q[j] += sign * h,
                        "dq" => dq[j] += sign * h,
                        _ => u[j] += sign * h,
                    }
                    accelerations(sys, &q, &dq, &u)
                };
                let ((ap, lp), (am, lm)) = (at(1.0, &mut sys), at(-1.0, &mut sys));
                let (eq, el) = match kind {
                    "q" => (&d.qdd_dq, &d.lambda_dq),
                    "dq" => (&d.qdd_ddq, &d.lambda_ddq),
                    _ => (&d.qdd_du, &d.lambda_du),
                };
                let (sq, sl) = (eq.amax().max(1.0), el.amax().max(1.0));
                for r in 0..ap.len() {
                    let fd = (ap[r] - am[r]) / (2.0 * h);
                    assert!(
                        (fd - eq[(r, j)]).abs() < 1e-5 * sq,
                        "{name}: q̈_d{kind}[{r}][{j}] = {} vs {fd}",
                        eq[(r, j)]
                    );
                }
                for r in 0..lp.len() {
                    let fd = (lp[r] - lm[r]) / (2.0 * h);
                    assert!(
                        (fd - el[(r, j)]).abs() < 1e-5 * sl,
                        "{name}: λ_d{kind}[{r}][{j}] = {} vs {fd}",
                        el[(r, j)]
                    );
                }
            }
        }
    }
}

/// RK4's and Dormand–Prince's step maps: RK4's `x₂` is the integrator's own step, both
/// derivatives against central differences of the step.
#[test]
fn explicit_step_map_derivatives_match_finite_differences() {
    use tree_mech::integrate::Rk4;
    use tree_mech::runtime::linearize::{explicit_step_derivatives, Tableau, DORMAND_PRINCE, RK4};
    let root = env!("CARGO_MANIFEST_DIR");
    for name in ["elements", "cart"] {
        let model = model::from_toml_file(format!("{root}/tests/models/{name}.toml")).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let (mut q, mut dq) = sys.initial_state();
        let split = Split::of(&sys);
        project_initial_state(&mut sys, &split, &mut q, &mut dq).unwrap();
        let dynamic = split.dynamic.clone();
        let nd = dynamic.len();
        let u: Vec<f64> = (0..sys.input_count()).map(|_| 0.7).collect();
        let (h, t) = (0.02, 0.1);
        let mut motion = ModelMotions::of(&sys);
        for &k in &split.kinematic {
            [q[k], dq[k], _] = motion.kinematic(k, t);
        }
        let derivatives = |sys: &mut TreeSystem,
                           q: &Vector<Dyn>,
                           dq: &Vector<Dyn>,
                           u: &[f64],
                           tableau: &Tableau| {
            let mut motion = ModelMotions::of(sys);
            let mut force = NoForce;
            let mut cx = StepContext::new(sys, &mut force, &mut motion, h);
            cx.u = u;
            explicit_step_derivatives(cx.at(0, t), q, dq, tableau).unwrap()
        };
        // RK4's x₂ is the integrator's step.
        {
            let mut rk = Rk4::new(&sys);
            let (mut q2, mut dq2) = (q.clone(), dq.clone());
            let mut motion = ModelMotions::of(&sys);
            let mut force = NoForce;
            let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, h);
            cx.u = &u;
            rk.step(cx.at(0, t), &mut q2, &mut dq2).unwrap();
            let d = derivatives(&mut sys, &q, &dq, &u, &RK4);
            for (r, &i) in dynamic.iter().enumerate() {
                assert!((d.x2[r] - q2[i]).abs() < 1e-13, "{name}: RK4 x2[{r}]");
                assert!(
                    (d.x2[nd + r] - dq2[i]).abs() < 1e-12,
                    "{name}: RK4 x2[{}]",
                    nd + r
                );
            }
        }
        for (method, tableau) in [("RK4", &RK4), ("Dormand–Prince", &DORMAND_PRINCE)] {
            let d = derivatives(&mut sys, &q, &dq, &u, tableau);
            let e = 1e-6;
            for c in 0..2 * nd + u.len() {
                let perturbed = |sign: f64, sys: &mut TreeSystem| {
                    let (mut q, mut dq, mut u) = (q.clone(), dq.clone(), u.clone());
                    if c < nd {
                        q[dynamic[c]] += sign * e;
                    } else if c < 2 * nd {
                        dq[dynamic[c - nd]] += sign * e;
                    } else {
                        u[c - 2 * nd] += sign * e;
                    }
                    derivatives(sys, &q, &dq, &u, tableau).x2
                };
                let (plus, minus) = (perturbed(1.0, &mut sys), perturbed(-1.0, &mut sys));
                for r in 0..2 * nd {
                    let fd = (plus[r] - minus[r]) / (2.0 * e);
                    let exact = if c < 2 * nd {
                        d.x2_dx1[(r, c)]
                    } else {
                        d.x2_du1[(r, c - 2 * nd)]
                    };
                    assert!(
                        (fd - exact).abs() < 1e-6 * d.x2_dx1.amax(),
                        "{name}, {method}: x2_dx1[{r}][{c}] = {exact} vs {fd}"
                    );
                }
            }
        }
        // The two methods' steps agree to their order, and differ.
        let (a, b) = (
            derivatives(&mut sys, &q, &dq, &u, &RK4),
            derivatives(&mut sys, &q, &dq, &u, &DORMAND_PRINCE),
        );
        let gap = (&a.x2 - &b.x2).amax();
        assert!(
            gap > 0.0 && gap < 1e-6,
            "{name}: RK4 vs Dormand–Prince {gap}"
        );
    }
}

/// The inverse dynamics over jets that the linearisation differentiates (recursive
/// Newton–Euler): its values are the Lagrangian's `M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q − F` on
/// random states of every model, springs, dampers and damping included, and each lane's
/// derivative is the central difference of those values along its direction.
#[test]
fn newton_euler_is_the_lagrangians_inverse_dynamics() {
    use tree_mech::kernel::{Jet, JetOutputs, LANES};
    use tree_mech::runtime::dynamics::inverse_dynamics;
    use tree_mech::runtime::Terms;
    let root = env!("CARGO_MANIFEST_DIR");
    let mut files = common::model_files();
    files.push(format!("{root}/tests/models/elements.toml").into());
    for (k, file) in files.iter().enumerate() {
        let model = model::from_toml_file(file).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let n = sys.dof();
        let mut rng = common::Rng::new(90 + k as u64);
        let (q, dq, qdd) = (rng.vector(n, 1.0), rng.vector(n, 1.5), rng.vector(n, 2.0));
        // The Lagrangian's τ at a state.
        let lagrangian = |sys: &mut TreeSystem, q: &Vector<Dyn>, dq: &Vector<Dyn>| {
            let mut terms = Terms::zeros(Dyn(n));
            let mut tau = Vector::<Dyn>::zeros(n);
            inverse_dynamics(sys, q, dq, &qdd, &mut terms, &mut tau).unwrap();
            tau
        };
        let want = lagrangian(&mut sys, &q, &dq);
        // Lane l seeds a random direction of (q, q̇).
        let dirs: Vec<(Vector<Dyn>, Vector<Dyn>)> = (0..LANES)
            .map(|_| (rng.vector(n, 1.0), rng.vector(n, 1.0)))
            .collect();
        // Lane l of entry i: the direction's component `part` (0: q, 1: q̇).
        let jets = |x: &Vector<Dyn>, part: usize| {
            (0..n)
                .map(|i| Jet {
                    v: x[i],
                    d: std::array::from_fn(|l| {
                        if part == 0 {
                            dirs[l].0[i]
                        } else {
                            dirs[l].1[i]
                        }
                    }),
                })
                .collect::<Vec<_>>()
        };
        let (qj, vj) = (jets(&q, 0), jets(&dq, 1));
        let mut out = JetOutputs::<LANES>::new(n, sys.constraint_count());
        assert!(sys.inverse_dynamics_jet(&qj, &vj, qdd.as_slice(), &mut out));
        let total = |i: usize| out.tau[i] - out.dl_dq[i] - out.force[i];
        let scale = want.amax().max(1.0);
        for i in 0..n {
            assert!(
                (total(i).v - want[i]).abs() <= 1e-12 * scale,
                "{}: τ[{i}] = {} by Newton–Euler, {} from the Lagrangian",
                model.name,
                total(i).v,
                want[i]
            );
        }
        let h = 1e-6;
        for (l, (dir_q, dir_dq)) in dirs.iter().enumerate() {
            let plus = lagrangian(&mut sys, &(&q + dir_q * h), &(&dq + dir_dq * h));
            let minus = lagrangian(&mut sys, &(&q - dir_q * h), &(&dq - dir_dq * h));
            for i in 0..n {
                let fd = (plus[i] - minus[i]) / (2.0 * h);
                assert!(
                    (total(i).d[l] - fd).abs() <= 1e-6 * scale.max(fd.abs()),
                    "{}: δτ[{i}] along lane {l}: {} vs {fd}",
                    model.name,
                    total(i).d[l]
                );
            }
        }
    }
}

/// A system that offers no evaluation over jets: the continuous linearisation falls back on
/// differentiating its whole evaluation over dual numbers, a direction at a time.
struct DualOnly {
    inner: TreeSystem,
}

impl System for DualOnly {
    type N = Dyn;
    delegate_description!(inner);
    fn lagrangian(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        self.inner.lagrangian(q, dq, order, out)
    }
}

/// The continuous linearisation of `sys` at `(q, q̇, u)`, t = 0.3.
fn linearize<S: System<N = Dyn>>(
    sys: &mut S,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    u: &[f64],
) -> tree_mech::runtime::linearize::ContinuousDerivatives {
    let (mut force, mut motion) = (NoForce, ModelMotions::of(&*sys));
    let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.0);
    cx.u = u;
    continuous_derivatives(cx.at(0, 0.3), q, dq).unwrap()
}

/// The linearisation's two ways to its right sides — over jets, eight directions a sweep, and
/// the fallback over dual numbers, a direction at a time — agree on every constrained and
/// unconstrained model with inputs, kinematic variables and every element.
#[test]
fn the_dual_fallback_equals_the_jets() {
    let root = env!("CARGO_MANIFEST_DIR");
    let files = [
        format!("{root}/tests/models/elements.toml"),
        format!("{root}/tests/models/cart.toml"),
        format!("{root}/tests/models/string-pendulum.toml"),
        format!("{root}/models/marionette.toml"),
        format!("{root}/models/humanoid.toml"),
    ];
    for file in files {
        let model = model::from_toml_file(&file).unwrap();
        let mut jets = TreeSystem::new(&model).unwrap();
        let mut duals = DualOnly {
            inner: TreeSystem::new(&model).unwrap(),
        };
        let n = jets.dof();
        let mut rng = common::Rng::new(31);
        let (q, dq) = (rng.vector(n, 0.4), rng.vector(n, 0.8));
        let u: Vec<f64> = (0..jets.input_count())
            .map(|k| 0.3 * k as f64 - 0.2)
            .collect();
        let a = linearize(&mut jets, &q, &dq, &u);
        let b = linearize(&mut duals, &q, &dq, &u);
        for (what, x, y) in [
            ("qdd_dq", &a.qdd_dq, &b.qdd_dq),
            ("qdd_ddq", &a.qdd_ddq, &b.qdd_ddq),
            ("qdd_du", &a.qdd_du, &b.qdd_du),
            ("lambda_dq", &a.lambda_dq, &b.lambda_dq),
            ("lambda_ddq", &a.lambda_ddq, &b.lambda_ddq),
            ("lambda_du", &a.lambda_du, &b.lambda_du),
        ] {
            let scale = y.amax().max(1.0);
            assert_eq!(x.shape(), y.shape(), "{file}: {what}");
            assert!(
                (x - y).amax() <= 1e-11 * scale,
                "{file}: {what} over jets and over dual numbers differ by {} (scale {scale})",
                (x - y).amax()
            );
        }
    }
}
