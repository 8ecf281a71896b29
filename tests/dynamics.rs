//! Continuous dynamics and the integrators against analytic cases, closed-form equations of
//! motion, conservation laws and each other.

mod common;

use common::{interpreted, load, Rng};
use nalgebra::Dyn;
use tree_mech::integrate::{simulate, Method, SimOptions, StepContext, Tolerance, ViSettings};
use tree_mech::model::{ModelBuilder, PrimitiveKind};
use tree_mech::runtime::dynamics::inverse_dynamics;
use tree_mech::runtime::evaluation::continuous_dynamics;
use tree_mech::runtime::{Dynamics, ModelMotions, Prescription, Vector};
use tree_mech::{
    tree_model, ConstraintTerms, NoForce, Order, System, Terms, Trajectory, TreeSystem,
};

fn run(
    sys: &mut TreeSystem,
    q0: &Vector<Dyn>,
    dq0: &Vector<Dyn>,
    method: Method,
    dt: f64,
    duration: f64,
) -> Trajectory {
    let options = SimOptions {
        method,
        dt,
        duration,
        ..Default::default()
    };
    simulate(sys, q0, dq0, &options, &mut NoForce, &mut |_| {}).unwrap()
}

fn vi(alpha: f64) -> Method {
    Method::Vi(ViSettings {
        alpha,
        ..ViSettings::default()
    })
}

/// Times at which `x` crosses zero upwards, by linear interpolation.
fn upward_crossings(traj: &Trajectory, i: usize) -> Vec<f64> {
    (1..traj.len())
        .filter_map(|k| {
            let (a, b) = (traj.q(k - 1)[i], traj.q(k)[i]);
            (a < 0.0 && b >= 0.0)
                .then(|| traj.t[k - 1] + (traj.t[k] - traj.t[k - 1]) * (-a) / (b - a))
        })
        .collect()
}

#[test]
fn simple_pendulum_small_angle_period_is_two_pi_sqrt_l_over_g() {
    let mut sys = interpreted(&load("pendulum.toml"));
    let q0 = Vector::<Dyn>::from_vec(vec![0.01]);
    let dq0 = Vector::<Dyn>::zeros(1);
    let expected = 2.0 * std::f64::consts::PI * (1.0f64 / 9.81).sqrt();
    for method in [Method::Rk4, vi(0.5)] {
        let traj = run(&mut sys, &q0, &dq0, method, 1e-3, 10.0);
        let c = upward_crossings(&traj, 0);
        assert!(c.len() >= 4);
        let period = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        // Finite amplitude lengthens the period by θ0²/16 ≈ 6e-6 relative.
        assert!(
            (period / expected - 1.0).abs() < 2e-5,
            "{method:?}: period {period} vs {expected}"
        );
    }
}

#[test]
fn point_mass_falls_by_half_g_t_squared() {
    let model = ModelBuilder::new("drop")
        .frame("height", "world", PrimitiveKind::Tz, "z")
        .mass("height", 2.0, [0.0; 3])
        .build()
        .unwrap();
    let mut sys = interpreted(&model);
    let q0 = Vector::<Dyn>::from_vec(vec![10.0]);
    let dq0 = Vector::<Dyn>::from_vec(vec![1.5]);
    for method in [Method::Rk4, vi(0.5), Method::Rk45(Tolerance::default())] {
        let traj = run(&mut sys, &q0, &dq0, method, 0.01, 1.3);
        let t = *traj.t.last().unwrap();
        let z = 10.0 + 1.5 * t - 0.5 * 9.81 * t * t;
        let dz = 1.5 - 9.81 * t;
        assert!((t - 1.3).abs() < 1e-12);
        assert!(
            (traj.last_q()[0] - z).abs() < 1e-10,
            "{method:?}: z = {} vs {z}",
            traj.last_q()[0]
        );
        assert!(
            (traj.dq(traj.len() - 1)[0] - dz).abs() < 1e-9,
            "{method:?}: velocity"
        );
    }
}

/// The double pendulum's textbook equations of motion in absolute angles φ1 = θ1,
/// φ2 = θ1 + θ2 (unit masses and lengths), solved for the relative-angle accelerations.
fn textbook_double_pendulum(q: &[f64], dq: &[f64], g: f64) -> [f64; 2] {
    let (p1, p2) = (q[0], q[0] + q[1]);
    let (w1, w2) = (dq[0], dq[0] + dq[1]);
    let d = p1 - p2;
    // 2 φ1'' + cos(d) φ2'' = −w2² sin(d) − 2 g sin φ1
    // cos(d) φ1'' + φ2'' = w1² sin(d) − g sin φ2
    let (a, b, c, e) = (2.0, d.cos(), d.cos(), 1.0);
    let r1 = -w2 * w2 * d.sin() - 2.0 * g * p1.sin();
    let r2 = w1 * w1 * d.sin() - g * p2.sin();
    let det = a * e - b * c;
    let a1 = (r1 * e - b * r2) / det;
    let a2 = (a * r2 - c * r1) / det;
    [a1, a2 - a1]
}

#[test]
fn double_pendulum_dynamics_match_the_textbook_equations() {
    let mut sys = interpreted(&load("double-pendulum.toml"));
    let mut dynamics = Dynamics::new(&sys);
    let mut motion = tree_mech::runtime::ModelMotions::of(&sys);
    let mut rng = Rng::new(3);
    for _ in 0..20 {
        let q = rng.vector(2, 3.0);
        let dq = rng.vector(2, 4.0);
        let mut qdd = Vector::<Dyn>::zeros(2);
        let mut no_force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut no_force, &mut motion, 0.0);
        dynamics.acceleration(&mut cx, &q, &dq, &mut qdd).unwrap();
        let expected = textbook_double_pendulum(q.as_slice(), dq.as_slice(), 9.81);
        for i in 0..2 {
            assert!(
                (qdd[i] - expected[i]).abs() < 1e-11 * expected[i].abs().max(1.0),
                "q̈{i}: {} vs {}",
                qdd[i],
                expected[i]
            );
        }
    }
}

#[test]
fn vi_energy_error_stays_bounded_without_drift_over_1e5_steps() {
    let mut sys = interpreted(&load("double-pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let traj = run(&mut sys, &q0, &dq0, vi(0.5), 0.01, 1000.0);
    assert_eq!(traj.len(), 100_001);
    let e0 = traj.energy[0];
    let err: Vec<f64> = traj.energy.iter().map(|e| e - e0).collect();
    let max = err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    // Bounded: the oscillation seen over the first 10 s is all there is after 1000 s.
    let first = err[..1001].iter().fold(0.0f64, |m, e| m.max(e.abs()));
    assert!(max < 2e-3, "energy error {max:e}");
    assert!(
        max < 3.0 * first,
        "energy error grew from {first:e} to {max:e}"
    );
    // No drift: the mean error of the first and last tenth agree.
    let tenth = err.len() / 10;
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let (a, b) = (mean(&err[..tenth]), mean(&err[err.len() - tenth..]));
    assert!(
        (a - b).abs() < 2e-4,
        "mean energy error drifted from {a:e} to {b:e}"
    );
    // RK4 at the same step drifts instead.
    let rk = run(&mut sys, &q0, &dq0, Method::Rk4, 0.01, 1000.0);
    let rk_drift = (rk.energy.last().unwrap() - e0).abs();
    assert!(
        rk_drift > 10.0 * (a - b).abs(),
        "RK4 drift {rk_drift:e} should exceed the VI's"
    );
}

/// Spatial linear and angular momentum (about the world origin) of the free body, from its
/// pose and body velocity.
fn free_body_momenta(sys: &mut TreeSystem, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> [f64; 6] {
    let body = sys.model().frame_index("body").unwrap();
    let m = sys.model().frames[body].mass.unwrap();
    let v = sys.frame_velocities(q, dq)[body].0;
    let mut poses = vec![tree_mech::runtime::Pose::IDENTITY; sys.frame_count()];
    sys.poses(q, &mut poses);
    let g = nalgebra::Matrix3::from_fn(|i, j| poses[body].r[i][j]);
    let p = nalgebra::Vector3::from_column_slice(&poses[body].p);
    let lin = g * nalgebra::Vector3::new(v[0], v[1], v[2]) * m.mass;
    let inertia = m.diagonal().expect("the free body is centred on its frame");
    let ang_body = nalgebra::Vector3::new(inertia[0] * v[3], inertia[1] * v[4], inertia[2] * v[5]);
    let ang = g * ang_body + p.cross(&lin);
    [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z]
}

/// Largest deviation of the spatial momenta over a VI run of the free body; also checks
/// that the cyclic coordinates' discrete momenta are exact invariants.
fn free_body_run(dt: f64) -> f64 {
    let mut sys = interpreted(&load("free-body.toml"));
    let (q0, dq0) = sys.initial_state();
    let traj = run(&mut sys, &q0, &dq0, vi(0.5), dt, 3.0);
    let p0 = traj.p(0).unwrap().to_vec();
    let h0 = free_body_momenta(&mut sys, &q0, &dq0);
    // The cyclic momenta are the spatial ones: p_x = m ẋ, p_ψ = vertical angular momentum.
    assert!((p0[0] - h0[0]).abs() < 1e-12 && (p0[3] - h0[5]).abs() < 1e-12);
    let mut worst_h: f64 = 0.0;
    for k in 0..traj.len() {
        let p = traj.p(k).unwrap();
        // x, y, z and the yaw ψ are cyclic: their discrete momenta are exact invariants.
        for i in [0, 1, 2, 3] {
            assert!(
                (p[i] - p0[i]).abs() < 1e-10,
                "momentum of `{}` drifted at step {k}: {} vs {}",
                traj.variables[i],
                p[i],
                p0[i]
            );
        }
        let q = Vector::<Dyn>::from_column_slice(traj.q(k));
        let dq = Vector::<Dyn>::from_column_slice(traj.dq(k));
        let h = free_body_momenta(&mut sys, &q, &dq);
        for c in 0..6 {
            worst_h = worst_h.max((h[c] - h0[c]).abs());
        }
    }
    worst_h
}

#[test]
fn vi_conserves_the_free_bodys_momenta() {
    // The remaining components of angular momentum are conserved to the method's
    // O(Δt²) accuracy (Euler angles break the SO(3) symmetry of the discretisation).
    let coarse = free_body_run(0.01);
    let fine = free_body_run(0.005);
    assert!(coarse < 3e-2, "spatial momentum varied by {coarse:e}");
    let order = (coarse / fine).log2();
    assert!(
        (order - 2.0).abs() < 0.3,
        "momentum error shrinks with order {order} ({coarse:e}, {fine:e})"
    );
}

fn final_error(traj: &Trajectory, reference: &[f64]) -> f64 {
    traj.last_q()
        .iter()
        .zip(reference)
        .fold(0.0, |m, (a, b)| m.max((a - b).abs()))
}

#[test]
fn vi_converges_with_order_two_at_midpoint_and_one_elsewhere() {
    let mut sys = interpreted(&load("double-pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let reference = run(&mut sys, &q0, &dq0, Method::Rk4, 1e-4, 1.0)
        .last_q()
        .to_vec();
    for (alpha, order) in [(0.5, 2.0), (0.3, 1.0)] {
        let errors: Vec<f64> = [0.02, 0.01, 0.005]
            .iter()
            .map(|&dt| final_error(&run(&mut sys, &q0, &dq0, vi(alpha), dt, 1.0), &reference))
            .collect();
        for w in errors.windows(2) {
            let observed = (w[0] / w[1]).log2();
            assert!(
                (observed - order).abs() < 0.25,
                "α = {alpha}: observed order {observed} (errors {errors:?})"
            );
        }
    }
}

#[test]
fn rk4_and_vi_agree_on_short_horizons() {
    for name in ["double-pendulum.toml", "humanoid.toml", "free-body.toml"] {
        let mut sys = interpreted(&load(name));
        let (q0, dq0) = sys.initial_state();
        let a = run(&mut sys, &q0, &dq0, Method::Rk4, 1e-3, 0.5);
        let b = run(&mut sys, &q0, &dq0, vi(0.5), 1e-3, 0.5);
        let d = final_error(&a, b.last_q());
        assert!(d < 1e-5, "{name}: RK4 and VI differ by {d:e}");
    }
}

#[test]
fn rk45_meets_its_tolerance_against_a_fine_rk4_reference() {
    let mut sys = interpreted(&load("double-pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let reference = run(&mut sys, &q0, &dq0, Method::Rk4, 1e-4, 2.0);
    for (rtol, bound) in [(1e-6, 1e-4), (1e-9, 1e-7)] {
        let tol = Tolerance {
            rtol,
            atol: rtol * 1e-2,
        };
        let traj = run(&mut sys, &q0, &dq0, Method::Rk45(tol), 0.01, 2.0);
        assert!((traj.t.last().unwrap() - 2.0).abs() < 1e-12);
        let e = final_error(&traj, reference.last_q());
        assert!(e < bound, "rtol {rtol}: error {e:e}");
        assert!(
            e > 1e-13,
            "a zero error would mean the test compares nothing"
        );
    }
}

#[test]
fn damping_removes_energy_monotonically() {
    let model = ModelBuilder::new("damped")
        .frame("pivot", "world", PrimitiveKind::Rx, "theta")
        .frame("bob", "pivot", PrimitiveKind::Tz, -1.0)
        .mass("bob", 1.0, [0.0; 3])
        .initial("theta", 1.0, 0.0)
        .damping("theta", 0.5)
        .build()
        .unwrap();
    let mut sys = interpreted(&model);
    let (q0, dq0) = sys.initial_state();
    for method in [Method::Rk4, vi(0.5)] {
        let traj = run(&mut sys, &q0, &dq0, method, 1e-3, 5.0);
        for w in traj.energy.windows(2) {
            assert!(w[1] <= w[0] + 1e-9, "{method:?}: energy rose");
        }
        assert!(traj.energy.last().unwrap() < &(traj.energy[0] - 1.0));
    }
}

/// `System::mass_matrix` (the interpreted system runs only the sweeps it needs: poses,
/// `∂v/∂q̇` columns, composite inertias) gives the `M` and `L = −V` of the full evaluation at
/// rest, on every shipped and test model (springs, dampers, constraints, kinematic inputs) at
/// random configurations. Garbage left in the output beforehand must not survive.
#[test]
fn the_mass_matrix_evaluation_is_the_lagrangians_at_rest() {
    let mut rng = Rng::new(41);
    for path in common::every_model_file() {
        let model = tree_mech::model::from_toml_file(&path).unwrap();
        let mut sys = interpreted(&model);
        let n = sys.dof();
        let rest = Vector::<Dyn>::zeros(n);
        for _ in 0..3 {
            let q = rng.vector(n, 1.0);
            let full = sys.evaluate(&q, &rest, tree_mech::runtime::Order::Dynamics);
            let mut mass = tree_mech::runtime::Terms::zeros(Dyn(n));
            mass.l = 1e9;
            mass.mass.fill(1e9);
            sys.mass_matrix(&q, &mut mass);
            let what = path.display();
            let scale = full.mass.amax().max(1.0);
            assert!(
                (mass.l - full.l).abs() <= 1e-13 * full.l.abs().max(1.0),
                "{what}: L {} against {}",
                mass.l,
                full.l
            );
            let diff = (&mass.mass - &full.mass).amax();
            assert!(diff <= 1e-14 * scale, "{what}: M differs by {diff:e}");
        }
    }
}

/// `System::energy` (the interpreted system runs only the outward sweep's poses and
/// velocities, then the springs' potentials) is the Legendre transform `q̇·∂L/∂q̇ − L` of the
/// full evaluation on every shipped and test model (springs between frames and on variables,
/// dampers, constraints, kinematic inputs, full inertias) at random states, and so is the
/// energy an RK4 run records at each sample.
#[test]
fn the_energy_evaluation_is_the_legendre_transform_of_the_lagrangian() {
    let mut rng = Rng::new(43);
    for path in common::every_model_file() {
        let model = tree_mech::model::from_toml_file(&path).unwrap();
        let mut sys = interpreted(&model);
        let n = sys.dof();
        for _ in 0..3 {
            let (q, dq) = (rng.vector(n, 1.0), rng.vector(n, 2.0));
            let full = sys.evaluate(&q, &dq, tree_mech::runtime::Order::First);
            let legendre = full.energy(&dq);
            let mut out = tree_mech::runtime::Terms::zeros(Dyn(n));
            out.total_energy = 1e9;
            let e = sys.energy(&q, &dq, &mut out);
            let what = path.display();
            assert_eq!(e, out.total_energy, "{what}: E returned and stored");
            // The terms' scale: the kinetic part and the potential's pieces can cancel.
            let scale = legendre.abs().max(full.l.abs()).max(1.0);
            assert!(
                (e - legendre).abs() <= 1e-13 * scale,
                "{what}: E = {e} against the Legendre transform {legendre}"
            );
        }
        // What an RK4 run records at each sample (`System::energy` without constraints, the
        // accelerations' own evaluation with them) is the same transform at that sample (the
        // VI's, for a model with contact, which RK4 refuses).
        let method = match sys.unilateral().is_empty() {
            true => Method::Rk4,
            false => Method::Vi(Default::default()),
        };
        let options = SimOptions::new(method, 0.01, 0.05);
        let traj = common::simulate_from_start(&mut sys, &options);
        for k in 0..traj.len() {
            let (q, dq) = (
                Vector::<Dyn>::from_column_slice(traj.q(k)),
                Vector::<Dyn>::from_column_slice(traj.dq(k)),
            );
            let full = sys.evaluate(&q, &dq, tree_mech::runtime::Order::First);
            let legendre = full.energy(&dq);
            let scale = legendre.abs().max(full.l.abs()).max(1.0);
            assert!(
                (traj.energy[k] - legendre).abs() <= 1e-13 * scale,
                "{}: sample {k} recorded E = {} against {legendre}",
                path.display(),
                traj.energy[k]
            );
        }
    }
}

/// The articulated-body algorithm's `q̈` equals the mass matrix's `M⁻¹(…)` on every model
/// without constraints (springs, dampers, damping, kinematic inputs, inputs, full inertias)
/// at random states, to 1e-11 relative; and it is the path taken on every one of them.
#[test]
fn articulated_body_accelerations_equal_the_mass_matrix_solve() {
    let mut rng = Rng::new(5);
    let mut used = 0;
    for path in common::every_model_file() {
        let model = tree_mech::model::from_toml_file(&path).unwrap();
        // A mimic couples two joints: the algorithm declines (tests/generated.rs holds both
        // paths to that).
        let mimic =
            (model.frames.iter()).any(|f| matches!(f.joint, tree_mech::model::Joint::Mimic(_)));
        if !model.constraints.is_empty() || mimic {
            continue;
        }
        let mut sys = interpreted(&model);
        let n = sys.dof();
        let mut motion = tree_mech::runtime::ModelMotions::of(&sys);
        let mut fast = Dynamics::new(&sys);
        let mut plain = Dynamics::new(&sys);
        plain.articulated = false;
        for _ in 0..4 {
            let (q, dq) = (rng.vector(n, 1.0), rng.vector(n, 2.0));
            let u: Vec<f64> = (0..sys.input_count()).map(|_| rng.uniform()).collect();
            let (mut a, mut b) = (Vector::<Dyn>::zeros(n), Vector::<Dyn>::zeros(n));
            let mut no_force = NoForce;
            let mut cx = StepContext::new(&mut sys, &mut no_force, &mut motion, 0.01);
            cx.u = &u;
            fast.acceleration(&mut cx, &q, &dq, &mut a).unwrap();
            plain.acceleration(&mut cx, &q, &dq, &mut b).unwrap();
            let scale = b.amax().max(1.0);
            let diff = (&a - &b).amax();
            assert!(
                diff <= 1e-11 * scale,
                "{}: q̈ differs by {diff:e} (scale {scale:e})",
                path.display()
            );
            // The force the integrators' energy balance reads is the model's own.
            assert!((&fast.terms.force - &plain.terms.force).amax() <= 1e-13 * scale);
        }
        let mut own = tree_mech::runtime::Terms::zeros(Dyn(n));
        let (q, dq) = (rng.vector(n, 1.0), rng.vector(n, 1.0));
        let tau = Vector::<Dyn>::zeros(n);
        let mut qdd = Vector::<Dyn>::zeros(n);
        assert!(
            sys.articulated_acceleration(&q, &dq, &tau, &mut qdd, &mut own),
            "{}: the articulated-body algorithm declined",
            path.display()
        );
        used += 1;
    }
    assert!(used >= 8, "only {used} models without constraints");
}

tree_model!(struct Cart from "tests/models/cart.toml");

/// `τ = ID(q, q̇, FD(q, q̇, u))` on the dynamic rows against the forces forward dynamics was
/// given, `B u + Dhᵀλ` (docs/derivations.md §4's sign), at seeded random states of `sys`.
fn inverse_undoes_forward<S: System>(sys: &mut S, label: &str)
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let n = sys.dof();
    let mut rng = Rng::new(11);
    let mut motion = ModelMotions::of(sys);
    let (mut q, mut dq) = (sys.zero_vector(), sys.zero_vector());
    let (mut tau, mut terms) = (sys.zero_vector(), Terms::zeros(sys.dim()));
    let mut c = ConstraintTerms::zeros(sys.constraint_count(), n);
    for s in 0..5 {
        let t = 0.1 * s as f64;
        let (q0, _) = sys.initial_state();
        for i in 0..n {
            q[i] = q0[i] + 0.3 * rng.uniform();
            dq[i] = rng.uniform();
            if sys.is_kinematic(i) {
                [q[i], dq[i], _] = motion.kinematic(i, t);
            }
        }
        let u: Vec<f64> = (0..sys.input_count())
            .map(|_| 5.0 * rng.uniform())
            .collect();
        let (qdd, lambda) = continuous_dynamics(sys, t, &q, &dq, &u, &mut motion).unwrap();
        inverse_dynamics(sys, &q, &dq, &qdd, &mut terms, &mut tau).unwrap();
        sys.constraints(&q, &dq, Order::First, &mut c);
        let mut given = vec![0.0; n];
        for (k, &uk) in u.iter().enumerate() {
            given[sys.input_variable(k)] += uk;
        }
        for (r, &l) in lambda.iter().enumerate() {
            for (i, g) in given.iter_mut().enumerate() {
                *g += c.dh[(r, i)] * l;
            }
        }
        let scale =
            terms.mass.amax() * qdd.amax() + given.iter().fold(1.0f64, |m, g| m.max(g.abs()));
        for i in (0..n).filter(|&i| !sys.is_kinematic(i)) {
            assert!(
                (tau[i] - given[i]).abs() <= 1e-11 * scale,
                "{label} state {s}: τ[{}] = {} against {}",
                sys.variable_name(i),
                tau[i],
                given[i]
            );
        }
    }
}

#[test]
fn inverse_dynamics_returns_the_forces_forward_dynamics_was_given() {
    // Springs, a damper, damping, kinematic variables and constraints (elements.toml), and a
    // cart pushed by an input, compiled and interpreted.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/elements.toml");
    let elements = tree_mech::model::from_toml_file(path).unwrap();
    inverse_undoes_forward(&mut interpreted(&elements), "elements");
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let cart = tree_mech::model::from_toml_file(path).unwrap();
    inverse_undoes_forward(&mut interpreted(&cart), "cart (interpreted)");
    inverse_undoes_forward(&mut Cart, "cart (compiled)");
}
