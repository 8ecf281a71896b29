//! The compiled systems equal the interpreted ones: every `System` output on seeded random
//! states to 1e-12 relative, whole 1000-step VI and RK4 trajectories to 1e-9.

mod common;

use common::Rng;
use nalgebra::{allocator::Allocator, DefaultAllocator, Dyn};
use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::runtime::{Pose, Vector};
use tree_mech::{tree_model, NoForce, Order, System, Trajectory, TreeSystem};

tree_model!(struct Pendulum from "models/pendulum.toml");
tree_model!(struct DoublePendulum from "models/double-pendulum.toml");
tree_model!(struct Pendulum19 from "models/pendulum-19.toml");
tree_model!(struct Humanoid from "models/humanoid.toml");
tree_model!(struct FreeBody from "models/free-body.toml");
tree_model!(struct Specialised from "tests/models/specialised.toml");
tree_model!(struct Elements from "tests/models/elements.toml");
tree_model!(struct Mimic from "tests/models/mimic.toml");
// Its limits left off: RK4 runs it too, which cannot enforce them.
tree_model!(struct PandaHand from "models/panda-hand.urdf", enforce_limits = false);
// The same models compiled lean (as a large model is by default): one variant of the code,
// the evaluations over dual numbers and jets the interpreted runtime's.
tree_model!(struct LeanHumanoid from "models/humanoid.toml", lean);
tree_model!(struct LeanElements from "tests/models/elements.toml", lean);
tree_model!(struct UnabridgedPendulum from "models/pendulum.toml", lean = false);

tree_model! {
    /// Declared inline.
    pub struct InlineArm;
    gravity = [0.0, -9.81, 0.0];
    frame base = rz(yaw) {
        frame shoulder = ry(pitch) {
            frame upper = tz(0.4) {
                mass = 1.5;
                inertia = [0.02, 0.02, 0.001];
                frame elbow = ry(bend) {
                    frame forearm = tz(0.3) { mass = 0.8; }
                    frame tool = tx(extend) { mass = 0.2; inertia = [0.001, 0.001, 0.001]; }
                }
            }
        }
        frame counterweight = tx(-0.2);
    }
    variable yaw { q0 = 0.1; dq0 = 0.5; }
    variable bend { q0 = 0.7; damping = 0.05; }
}

tree_model! {
    /// Three constant translations in a row.
    struct ChainOfThree;
    frame a = rx(q) { frame b = tz(0.1) { frame c = tz(0.2) { frame d = tz(0.3) { mass = 1.0; } } } }
}

tree_model! {
    /// The same chain written as one translation.
    struct ChainOfOne;
    frame a = rx(q) { frame d = tz(0.6) { mass = 1.0; } }
}

tree_model! {
    /// The same, with massless branches hanging off it.
    struct ChainWithMasslessBranches;
    frame a = rx(q) {
        frame sensor = ty(0.2) { frame lens = rz(0.1) { frame tip = tx(0.05); } }
        frame d = tz(0.6) { mass = 1.0; frame marker = ry(0.3); }
    }
}

/// `|a − b| ≤ tol · max(1, |a|, |b|)` entry by entry.
fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
}

fn to_dyn<S: System>(x: &Vector<S::N>) -> Vector<Dyn>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    Vector::<Dyn>::from_column_slice(x.as_slice())
}

/// Every output of a generated system against the interpreted one built from its model.
fn check_equal<S: System>(generated: S, model: &tree_mech::model::Model, seed: u64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    check_equal_over(generated, model, seed, 5.0);
}

/// [`check_equal`] with whole trajectories of `duration` (a chaotic robot's, falling from
/// rest, part in rounding in a few seconds: the evaluations are held to 1e-12 all the same).
fn check_equal_over<S: System>(
    mut generated: S,
    model: &tree_mech::model::Model,
    seed: u64,
    duration: f64,
) where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut interpreted = TreeSystem::new(model).unwrap();
    let n = generated.dof();
    assert_eq!(n, interpreted.dof());
    for i in 0..n {
        assert_eq!(generated.variable_name(i), interpreted.variable_name(i));
        assert_eq!(generated.initial(i), interpreted.initial(i));
        assert_eq!(generated.damping(i), interpreted.damping(i));
    }
    assert_eq!(generated.frame_count(), interpreted.frame_count());
    let mut rng = Rng::new(seed);
    let mut taken = 0;
    for _ in 0..10 {
        let mut q = generated.zero_vector();
        let mut dq = generated.zero_vector();
        for i in 0..n {
            q[i] = 2.0 * rng.uniform();
            dq[i] = 3.0 * rng.uniform();
        }
        for order in [Order::First, Order::Dynamics, Order::Full] {
            let g = generated.evaluate(&q, &dq, order);
            let t = interpreted.evaluate(&to_dyn::<S>(&q), &to_dyn::<S>(&dq), order);
            assert!(
                close(g.l, t.l, 1e-12),
                "{}: L {} vs {}",
                model.name,
                g.l,
                t.l
            );
            for i in 0..n {
                assert!(
                    close(g.dl_dq[i], t.dl_dq[i], 1e-12),
                    "{}: dL/dq[{i}]",
                    model.name
                );
                assert!(
                    close(g.dl_ddq[i], t.dl_ddq[i], 1e-12),
                    "{}: dL/ddq[{i}]",
                    model.name
                );
                for j in 0..n {
                    if order >= Order::Dynamics {
                        assert!(
                            close(g.mass[(i, j)], t.mass[(i, j)], 1e-12),
                            "{}: M[{i}][{j}]",
                            model.name
                        );
                        assert!(
                            close(g.d2l_ddq_dq[(i, j)], t.d2l_ddq_dq[(i, j)], 1e-12),
                            "{}: d2L/ddqdq",
                            model.name
                        );
                    }
                    if order >= Order::Full {
                        assert!(
                            close(g.d2l_dq_dq[(i, j)], t.d2l_dq_dq[(i, j)], 1e-12),
                            "{}: d2L/dqdq",
                            model.name
                        );
                    }
                }
            }
        }
        // M(q) and L(q, 0) alone, garbage in the output beforehand overwritten.
        let mut mass_g = tree_mech::Terms::zeros(generated.dim());
        let mut mass_t = tree_mech::Terms::<Dyn>::zeros(Dyn(n));
        mass_g.l = 1e9;
        mass_g.mass.fill(1e9);
        generated.mass_matrix(&q, &mut mass_g);
        interpreted.mass_matrix(&to_dyn::<S>(&q), &mut mass_t);
        assert!(
            close(mass_g.l, mass_t.l, 1e-12),
            "{}: L at rest",
            model.name
        );
        for i in 0..n {
            for j in 0..n {
                assert!(
                    close(mass_g.mass[(i, j)], mass_t.mass[(i, j)], 1e-12),
                    "{}: mass_matrix M[{i}][{j}] {} vs {}",
                    model.name,
                    mass_g.mass[(i, j)],
                    mass_t.mass[(i, j)]
                );
            }
        }
        // E = T + V alone (poses and velocities only), against the interpreted one and the
        // Legendre transform q̇·∂L/∂q̇ − L of the full evaluation; garbage beforehand ignored.
        let mut energy_g = tree_mech::Terms::zeros(generated.dim());
        energy_g.total_energy = 1e9;
        let e_g = generated.energy(&q, &dq, &mut energy_g);
        let (q_t, dq_t) = (to_dyn::<S>(&q), to_dyn::<S>(&dq));
        let mut energy_t = tree_mech::Terms::<Dyn>::zeros(Dyn(n));
        let e_t = interpreted.energy(&q_t, &dq_t, &mut energy_t);
        let legendre = interpreted
            .evaluate(&q_t, &dq_t, Order::First)
            .energy(&dq_t);
        assert!(
            e_g == energy_g.total_energy && close(e_g, e_t, 1e-12) && close(e_t, legendre, 1e-12),
            "{}: E = T + V {e_g} (compiled), {e_t} (interpreted), Legendre transform {legendre}",
            model.name
        );
        // q̈ by the articulated-body algorithm (elements' forces included): the compiled one
        // is the interpreted one unrolled, and both take or decline a state alike.
        let (mut tau, mut qdd_g) = (generated.zero_vector(), generated.zero_vector());
        for i in 0..n {
            tau[i] = rng.uniform() - 0.5;
            qdd_g[i] = rng.uniform() - 0.5; // read for kinematic variables only
        }
        let mut qdd_t = to_dyn::<S>(&qdd_g);
        let mut own_g = tree_mech::Terms::zeros(generated.dim());
        let mut own_t = tree_mech::Terms::<Dyn>::zeros(Dyn(n));
        let took_g = generated.articulated_acceleration(&q, &dq, &tau, &mut qdd_g, &mut own_g);
        let took_t = interpreted.articulated_acceleration(
            &to_dyn::<S>(&q),
            &to_dyn::<S>(&dq),
            &to_dyn::<S>(&tau),
            &mut qdd_t,
            &mut own_t,
        );
        assert_eq!(
            took_g, took_t,
            "{}: articulated-body step taken",
            model.name
        );
        if took_g {
            taken += 1;
            for i in 0..n {
                // The model's own forces come back as the energy balance reads them.
                assert!(
                    close(own_g.force[i], own_t.force[i], 1e-12)
                        && close(own_g.dl_dq[i], own_t.dl_dq[i], 1e-12),
                    "{}: the model's own force on {i}",
                    model.name
                );
                assert!(
                    close(qdd_g[i], qdd_t[i], 1e-12),
                    "{}: articulated q̈[{i}] {} vs {}",
                    model.name,
                    qdd_g[i],
                    qdd_t[i]
                );
            }
        }
        // The inverse dynamics and the constraints over jets (the continuous linearisation's
        // sweep): values and derivatives along random directions alike.
        {
            use tree_mech::kernel::{Jet, JetOutputs, LANES};
            let mut seed = |x: &[f64]| -> Vec<Jet<LANES>> {
                x.iter()
                    .map(|&v| Jet {
                        v,
                        d: std::array::from_fn(|_| rng.uniform() - 0.5),
                    })
                    .collect()
            };
            let (qj, vj) = (seed(q.as_slice()), seed(dq.as_slice()));
            let acc: Vec<f64> = (0..n).map(|_| rng.uniform() - 0.5).collect();
            let m = interpreted.constraint_count();
            let (mut jg, mut jt) = (JetOutputs::new(n, m), JetOutputs::new(n, m));
            let offered_g = generated.inverse_dynamics_jet(&qj, &vj, &acc, &mut jg);
            let offered_t = interpreted.inverse_dynamics_jet(&qj, &vj, &acc, &mut jt);
            assert!(offered_g, "{}: compiled inverse dynamics", model.name);
            assert!(offered_t, "{}: interpreted inverse dynamics", model.name);
            let pairs = (0..n)
                .flat_map(|i| {
                    [
                        ("tau", jg.tau[i], jt.tau[i]),
                        ("dl_dq", jg.dl_dq[i], jt.dl_dq[i]),
                        ("force", jg.force[i], jt.force[i]),
                    ]
                })
                .chain((0..m * n).map(|x| ("dh", jg.dh[x], jt.dh[x])))
                .chain((0..m).map(|r| ("dh_dot", jg.dh_dot[r], jt.dh_dot[r])));
            for (at, (what, a, b)) in pairs.enumerate() {
                let same = close(a.v, b.v, 1e-12)
                    && a.d.iter().zip(&b.d).all(|(&x, &y)| close(x, y, 1e-12));
                assert!(same, "{}: {what} (output {at}) {a:?} vs {b:?}", model.name);
            }
        }
        let mut pg = vec![Pose::IDENTITY; generated.frame_count()];
        let mut pt = pg.clone();
        generated.poses(&q, &mut pg);
        interpreted.poses(&to_dyn::<S>(&q), &mut pt);
        for (a, b) in pg.iter().zip(&pt) {
            let (a, b) = (a.matrix(), b.matrix());
            for i in 0..4 {
                for j in 0..4 {
                    assert!(close(a[i][j], b[i][j], 1e-12), "{}: pose", model.name);
                }
            }
        }
    }
    // A mimic couples two joints, which the articulated-body recursion cannot take: both
    // step aside, to the mass matrix.
    let mimic = (model.frames.iter()).any(|f| matches!(f.joint, tree_mech::model::Joint::Mimic(_)));
    assert!(
        (taken > 0) != (mimic || !model.constraints.is_empty()),
        "{}: the articulated-body step taken {taken} times",
        model.name
    );
    // Whole trajectories.
    let (q0, dq0) = generated.initial_state();
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let options = SimOptions {
            method,
            dt: 0.005,
            duration,
            ..Default::default()
        };
        let a: Trajectory = simulate(
            &mut generated,
            &q0,
            &dq0,
            &options,
            &mut NoForce,
            &mut |_| {},
        )
        .unwrap();
        let b = interpreted_run(&mut interpreted, q0.as_slice(), dq0.as_slice(), &options);
        assert_eq!(a.len(), (duration / 0.005).round() as usize + 1);
        assert_eq!(a.len(), b.len());
        for k in 0..a.len() {
            for i in 0..n {
                assert!(
                    close(a.q(k)[i], b.q(k)[i], 1e-9),
                    "{}: {method:?} q[{i}] at step {k}",
                    model.name
                );
                assert!(
                    close(a.dq(k)[i], b.dq(k)[i], 1e-9),
                    "{}: {method:?} dq[{i}] at step {k}",
                    model.name
                );
            }
        }
    }
}

/// Kept out of the generic `check_equal`, whose allocator bounds would capture the inference.
fn interpreted_run(
    sys: &mut TreeSystem,
    q0: &[f64],
    dq0: &[f64],
    options: &SimOptions,
) -> Trajectory {
    let (q0, dq0) = (
        Vector::<Dyn>::from_column_slice(q0),
        Vector::<Dyn>::from_column_slice(dq0),
    );
    simulate(sys, &q0, &dq0, options, &mut NoForce, &mut |_| {}).unwrap()
}

fn file_model(path: &str) -> tree_mech::model::Model {
    tree_mech::model::from_toml_file(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path))
        .unwrap()
}

#[test]
fn generated_equals_interpreted_on_every_model() {
    check_equal(Pendulum, &file_model("models/pendulum.toml"), 1);
    check_equal(
        DoublePendulum,
        &file_model("models/double-pendulum.toml"),
        2,
    );
    check_equal(Pendulum19, &file_model("models/pendulum-19.toml"), 3);
    check_equal(Humanoid, &file_model("models/humanoid.toml"), 4);
    check_equal(FreeBody, &file_model("models/free-body.toml"), 5);
}

/// A model compiled lean equals the interpreted runtime as a full one does (its own f64
/// programs; its dual-number and jet evaluations, constraints' and weighted Hessians'
/// included, through its interpreted twin), and the macro says which it is.
#[test]
fn a_model_compiled_lean_equals_the_interpreted() {
    const { assert!(LeanHumanoid::LEAN && LeanElements::LEAN) };
    const { assert!(!Humanoid::LEAN && !Elements::LEAN && !UnabridgedPendulum::LEAN) };
    assert_eq!(LeanHumanoid::STATEMENTS, Humanoid::STATEMENTS);
    check_equal(LeanHumanoid, &file_model("models/humanoid.toml"), 4);
    check_equal(LeanElements, &file_model("tests/models/elements.toml"), 7);
    common::check_weighted_hessian(&mut LeanElements, 7, 1e-13);
    check_equal(UnabridgedPendulum, &file_model("models/pendulum.toml"), 1);
}

/// Mimic frames (a transform following another's variable): the compiled code runs the
/// same contraction (tests/models/mimic.toml: a follower above its leader, with an offset
/// and damping, a mirrored finger under a spring and a damper; the Panda with its hand).
#[test]
fn generated_equals_interpreted_with_mimic_joints() {
    check_equal(Mimic, &file_model("tests/models/mimic.toml"), 6);
    let panda = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/panda-hand.urdf");
    let mut panda = tree_mech::model::from_file(panda, Default::default()).unwrap();
    assert!(panda.contacts.enforce_limits && !PandaHand::model().contacts.enforce_limits);
    panda.contacts.enforce_limits = false;
    check_equal_over(PandaHand, &panda, 7, 0.5);
}

/// The recorded variant of the compiled code and its fused one (AVX2 with fused
/// multiply-adds, run where the CPU has them: `tree_mech::kernel::cpu`) both equal the
/// interpreted runtime — every output, whole trajectories, constraints, their weighted
/// Hessian — and, on a CPU that
/// runs the fused variant, differ from each other in the last bits (so both ran). The switch
/// is process-wide: the other tests here compare to tolerances, whichever variant they get.
#[test]
fn both_variants_of_the_compiled_code_equal_the_interpreted() {
    use tree_mech::kernel::cpu;
    use tree_mech::ConstraintTerms;
    let fused_here = cpu::fused();
    #[cfg(target_arch = "x86_64")]
    assert_eq!(
        fused_here,
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    );
    let mut rng = Rng::new(17);
    let q = Vector::<nalgebra::Const<7>>::from_fn(|_, _| rng.uniform());
    let dq = Vector::<nalgebra::Const<7>>::from_fn(|_, _| rng.uniform());
    let elements = file_model("tests/models/elements.toml");
    let mut interpreted = TreeSystem::new(&elements).unwrap();
    let (qd, dqd) = (to_dyn::<Elements>(&q), to_dyn::<Elements>(&dq));
    let m = elements.constraints.len();
    let (mut ct, mut c) = (ConstraintTerms::zeros(m, 7), ConstraintTerms::zeros(m, 7));
    interpreted.constraints(&qd, &dqd, Order::Full, &mut ct);
    let mut outputs = Vec::new();
    for plain in [true, false] {
        cpu::force_plain(plain);
        check_equal(Humanoid, &file_model("models/humanoid.toml"), 4);
        check_equal(Specialised, &file_model("tests/models/specialised.toml"), 6);
        check_equal(Elements, &elements, 7);
        Elements.constraints(&q, &dq, Order::Full, &mut c);
        let scale = ct.d2h.iter().fold(1.0f64, |s, d| s.max(d.amax()));
        assert!((&c.h - &ct.h).amax() <= 1e-12 * scale);
        assert!((&c.dh - &ct.dh).amax() <= 1e-12 * scale);
        assert!((&c.dh_dot - &ct.dh_dot).amax() <= 1e-12 * scale);
        for r in 0..m {
            assert!((&c.d2h[r] - &ct.d2h[r]).amax() <= 1e-12 * scale);
        }
        // The rows' Hessians weighted as they are formed, in either variant.
        common::check_weighted_hessian(&mut Elements, 7, 1e-13);
        type HumanoidVector = Vector<nalgebra::Const<{ Humanoid::DOF }>>;
        let t = Humanoid.evaluate(
            &HumanoidVector::from_fn(|i, _| 0.1 * i as f64),
            &HumanoidVector::from_fn(|i, _| 0.3 - 0.05 * i as f64),
            Order::Full,
        );
        outputs.push((t.l, t.d2l_dq_dq, c.d2h.clone()));
    }
    cpu::force_plain(false);
    assert_eq!(cpu::fused(), fused_here);
    if fused_here && !cpu::FUSED_ONLY {
        assert_ne!(
            outputs[0], outputs[1],
            "the fused variant computed the same bits"
        );
    } else {
        assert_eq!(outputs[0], outputs[1], "one variant ran");
    }
}

#[test]
fn generated_equals_interpreted_with_every_specialisation() {
    check_equal(Specialised, &file_model("tests/models/specialised.toml"), 6);
}

#[test]
fn inline_model_equals_interpreted_and_its_model_round_trips() {
    check_equal(InlineArm, &InlineArm::model(), 7);
    // The file form rebuilds exactly the model the runtime reads.
    assert_eq!(
        Humanoid::model().frames,
        file_model("models/humanoid.toml").frames
    );
    assert_eq!(
        Humanoid::model().variables,
        file_model("models/humanoid.toml").variables
    );
}

#[test]
fn named_constants_and_initial_state() {
    assert_eq!(DoublePendulum::DOF, 2);
    assert_eq!(DoublePendulum::VARIABLES, ["theta1", "theta2"]);
    assert_eq!(DoublePendulum::THETA2, 1);
    assert_eq!(DoublePendulum::FRAME_LOWER, 3);
    assert_eq!(InlineArm::VARIABLES, ["yaw", "pitch", "bend", "extend"]);
    assert_eq!(InlineArm::BEND, 2);
    assert_eq!(InlineArm::DAMPING[InlineArm::BEND], 0.05);
    let (q0, dq0) = DoublePendulum.initial_state();
    assert_eq!((q0[0], q0[1], dq0[1]), (1.0, -0.5, 0.5));
    assert_eq!(Humanoid::DOF, 22);
    const { assert!(Humanoid::STATEMENTS > 0) };
}

#[test]
fn constant_chains_fold_and_massless_branches_cost_nothing() {
    // A chain of constant transforms compiles to one constant transform ...
    assert_eq!(ChainOfThree::STATEMENTS, ChainOfOne::STATEMENTS);
    // ... and massless branches add no statement to the Lagrangian terms.
    assert_eq!(
        ChainWithMasslessBranches::STATEMENTS,
        ChainOfOne::STATEMENTS
    );
    // The folded chain computes the same numbers as the chain.
    let q = tree_mech::runtime::nalgebra::SVector::<f64, 1>::new(0.4);
    let dq = tree_mech::runtime::nalgebra::SVector::<f64, 1>::new(-1.3);
    let a = ChainOfThree.evaluate(&q, &dq, Order::Full);
    let b = ChainOfOne.evaluate(&q, &dq, Order::Full);
    assert!(close(a.l, b.l, 1e-14) && close(a.d2l_dq_dq[(0, 0)], b.d2l_dq_dq[(0, 0)], 1e-14));
    // Poses still cover every frame, folded or not.
    let mut poses = vec![Pose::IDENTITY; 4];
    ChainOfThree.poses(&q, &mut poses);
    assert!(close(poses[3].p[1], -0.6 * 0.4f64.sin(), 1e-15));
}

/// The size of every shipped model's compiled evaluation, pinned: a refactor of the kernel
/// (issue 12's seams) must leave the generated code as it is; a change that means to alter
/// it updates these numbers on purpose. (Stop 30: a massive constant frame joins its driven
/// parent's body — the pendulum 17 → 12, the 19-link chain 6312 → 6465 and the humanoid
/// 8108 → 8183, where a composite body's offset centre of mass costs the Lagrangian a few
/// more products than a frame of its own, which the interpreted sweeps no longer walk; then
/// the spatial inertias' symmetric blocks formed from their upper triangles — 19-link 6309,
/// humanoid 7518, free body 331 → 274, specialised 1102 → 971.)
#[test]
fn the_statement_counts_of_the_shipped_models_are_pinned() {
    assert_eq!(
        [
            Pendulum::STATEMENTS,
            DoublePendulum::STATEMENTS,
            Pendulum19::STATEMENTS,
            Humanoid::STATEMENTS,
            FreeBody::STATEMENTS,
            Specialised::STATEMENTS,
        ],
        [12, 85, 6309, 7518, 274, 971]
    );
}

/// Terms kept for a compiled evaluation (an integrator's own, `Terms::keep_zeros`) skip
/// clearing `M`, `∂²L/∂q̇∂q` and `∂²L/∂q²` only when the model's own evaluation at the same
/// order wrote them last: every entry it writes is then as fresh terms have it, and an entry
/// it never writes keeps what another writer left there — which an evaluation at another
/// order or `Terms::clear` clears first. Terms not kept are cleared on every evaluation.
#[test]
fn kept_terms_skip_clearing_only_after_their_own_evaluation() {
    let mut sys = Humanoid;
    let mut rng = Rng::new(7);
    let mut state = || {
        let (mut q, mut dq) = (sys.zero_vector(), sys.zero_vector());
        for i in 0..q.len() {
            (q[i], dq[i]) = (2.0 * rng.uniform(), 3.0 * rng.uniform());
        }
        (q, dq)
    };
    let (a, b, c) = (state(), state(), state());
    let at_b = sys.evaluate(&b.0, &b.1, Order::Full);
    let mut kept = tree_mech::Terms::zeros(sys.dim());
    kept.keep_zeros();
    let mut plain = tree_mech::Terms::zeros(sys.dim());
    sys.lagrangian(&a.0, &a.1, Order::Full, &mut kept);
    sys.lagrangian(&a.0, &a.1, Order::Full, &mut plain);
    assert!(
        kept == sys.evaluate(&a.0, &a.1, Order::Full),
        "a first evaluation"
    );
    // Garbage on the zeros of M: where the model's next evaluation writes, overwritten; where
    // it does not (its limbs do not couple), kept — a first-order evaluation between leaves
    // the matrices alone. Terms not kept are cleared.
    let zeros = common::mark_zeros(kept.mass.as_mut_slice(), plain.mass.as_mut_slice(), 7.0);
    sys.lagrangian(&c.0, &c.1, Order::First, &mut kept);
    sys.lagrangian(&b.0, &b.1, Order::Full, &mut kept);
    sys.lagrangian(&b.0, &b.1, Order::Full, &mut plain);
    assert!(plain == at_b, "terms not kept are cleared");
    let unwritten = common::unwritten(kept.mass.as_mut_slice(), &zeros, 7.0);
    assert!(!unwritten.is_empty(), "the clearing was skipped");
    assert!(kept == at_b, "every written entry as fresh terms have it");
    // Another order's evaluation between, or a clear of the matrices (then a writer that
    // accumulates, as the interpreted system does), and the next clears all; clearing the
    // first order's outputs alone leaves the matrices and the mark.
    let e = (unwritten[0] % sys.dof(), unwritten[0] / sys.dof());
    for between in [Some(Order::Dynamics), Some(Order::First), None] {
        match between {
            Some(Order::First) => kept.clear(Order::First),
            Some(order) => sys.lagrangian(&c.0, &c.1, order, &mut kept),
            None => kept.clear(Order::Full),
        }
        kept.mass[e] = 7.0;
        kept.d2l_dq_dq[e] = 7.0;
        sys.lagrangian(&b.0, &b.1, Order::Full, &mut kept);
        if between == Some(Order::First) {
            assert_eq!((kept.mass[e], kept.d2l_dq_dq[e]), (7.0, 7.0));
        } else {
            assert!(kept == at_b, "after {between:?}");
        }
    }
}
