//! The variational integrator's Newton iteration: its exact Jacobian (paper eq. (26), with
//! damping) against finite differences of its residual, and the Jacobian-reuse option.

use crate::common;

use common::{interpreted, load, Rng};
use nalgebra::Dyn;
use tree_mech::integrate::{
    simulate, Forcing, JacobianUpdate, Method, MidpointVi, SimOptions, StepContext, ViSettings,
};
use tree_mech::model;
use tree_mech::runtime::Vector;
use tree_mech::{NoForce, Order, PaperEvaluation, PaperSystem, System, Terms, TreeSystem};

#[test]
fn newton_jacobian_is_the_derivative_of_the_residual() {
    let elements = model::from_toml_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/models/elements.toml"
    ))
    .unwrap();
    for (model, alpha, forcing) in [
        (load("humanoid.toml"), 0.5, Forcing::Split),
        (load("double-pendulum.toml"), 0.3, Forcing::Split),
        (load("free-body.toml"), 0.8, Forcing::Left),
        (elements.clone(), 0.5, Forcing::Split),
        (elements, 0.4, Forcing::Left),
    ] {
        check_newton_matrix(interpreted(&model), &model.name, alpha, forcing);
    }
    // The paper's reference evaluation feeds the same Newton matrix (humanoid: damped).
    let humanoid = load("humanoid.toml");
    let reference = PaperSystem::new(&humanoid, PaperEvaluation::Cached).unwrap();
    check_newton_matrix(reference, "humanoid (reference)", 0.5, Forcing::Split);
}

/// The Newton matrix against central differences of the residual in `(q₂_d, λ)`.
fn check_newton_matrix<S: System<N = Dyn>>(mut sys: S, name: &str, alpha: f64, forcing: Forcing) {
    {
        let n = sys.dof();
        let mut rng = Rng::new(11);
        let q1 = rng.vector(n, 1.0);
        let p1 = rng.vector(n, 1.0);
        let q2 = &q1 + rng.vector(n, 0.05);
        let dt = 0.01;
        let settings = ViSettings {
            alpha,
            forcing,
            ..ViSettings::default()
        };
        let mut vi = MidpointVi::new(&sys, settings);
        let dynamic = vi.split.dynamic.clone();
        let (nd, m) = (dynamic.len(), vi.split.rows);
        for s in 0..m {
            vi.lambda[s] = rng.uniform();
        }
        vi.prepare(&mut sys, &q1);
        let mut motion = |_: usize, _: f64| [0.0; 3];
        let mut no_force = NoForce;
        let mut cx = StepContext::new(&mut sys, &mut no_force, &mut motion, dt);
        vi.residual(&mut cx, &q1, &p1, &q2, true);
        let jacobian = vi.newton_matrix();
        assert_eq!(jacobian.nrows(), nd + m);
        let h = 1e-7;
        // Unknowns: the dynamic part of q2, then λ.
        for col in 0..nd + m {
            let residual_at =
                |vi: &mut MidpointVi<Dyn>, cx: &mut StepContext<_, _, _>, step: f64| {
                    let mut q = q2.clone();
                    let saved = vi.lambda.clone();
                    if col < nd {
                        q[dynamic[col]] += step;
                    } else {
                        vi.lambda[col - nd] += step;
                    }
                    vi.residual(cx, &q1, &p1, &q, false);
                    vi.lambda = saved;
                    vi.residual_vector()
                };
            let fp = residual_at(&mut vi, &mut cx, h);
            let fm = residual_at(&mut vi, &mut cx, -h);
            for row in 0..nd + m {
                let fd = (fp[row] - fm[row]) / (2.0 * h);
                let scale = jacobian.amax();
                assert!(
                    (jacobian[(row, col)] - fd).abs() < 1e-6 * scale,
                    "{name}: J[{row}][{col}] = {} vs {fd}",
                    jacobian[(row, col)]
                );
            }
        }
    }
}

/// Counts evaluations by order, delegating to an interpreted system.
struct Counting {
    inner: TreeSystem,
    full: usize,
    first: usize,
}

impl System for Counting {
    type N = Dyn;
    delegate_description!(inner);
    fn lagrangian(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        match order {
            Order::Full => self.full += 1,
            Order::First => self.first += 1,
            Order::Dynamics => {}
        }
        self.inner.lagrangian(q, dq, order, out)
    }
}

#[test]
fn reusing_the_jacobian_reaches_the_same_solution_with_fewer_full_evaluations() {
    for name in ["double-pendulum.toml", "humanoid.toml", "pendulum-19.toml"] {
        let model = load(name);
        let mut runs = Vec::new();
        for jacobian in [JacobianUpdate::EveryIteration, JacobianUpdate::OncePerStep] {
            let mut sys = Counting {
                inner: interpreted(&model),
                full: 0,
                first: 0,
            };
            let (q0, dq0) = sys.initial_state();
            // Both converged tightly: the chord iteration converges linearly, so at the
            // default tolerance its solutions differ from exact Newton's by ~1e-10 a step.
            let settings = ViSettings {
                jacobian,
                tolerance: 1e-12,
                ..ViSettings::default()
            };
            let options = SimOptions {
                method: Method::Vi(settings),
                dt: 0.01,
                duration: 2.0,
                ..Default::default()
            };
            let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
            runs.push((traj, sys.full, sys.first));
        }
        let (exact, reuse) = (&runs[0], &runs[1]);
        for k in 0..exact.0.len() {
            for i in 0..exact.0.dof() {
                let (a, b) = (exact.0.q(k)[i], reuse.0.q(k)[i]);
                assert!((a - b).abs() < 1e-9, "{name}: step {k}, q[{i}]: {a} vs {b}");
            }
        }
        assert!(
            reuse.1 < exact.1,
            "{name}: {} full evaluations reused vs {} exact",
            reuse.1,
            exact.1
        );
        // Exact Newton evaluates the Jacobian once per update: the last residual of a step,
        // near convergence, is checked with first derivatives (all but a few steps).
        let updates = exact.0.newton_iterations as f64;
        assert!(
            (exact.1 as f64) < 1.15 * updates && exact.2 >= 150,
            "{name}: {} full and {} first-order evaluations for {updates} updates",
            exact.1,
            exact.2
        );
        assert!(
            reuse.1 >= 200,
            "{name}: at least one full evaluation per step"
        );
    }
}

#[test]
fn damped_vi_loses_exactly_the_work_done_by_damping_in_the_limit() {
    // Damping c on a single pendulum: E(T) − E(0) = −∫ c θ̇² dt, checked by the trapezoid
    // rule on the recorded velocities; the VI's discrete forcing agrees to O(Δt²).
    let mut model = load("pendulum.toml");
    model.variables[0].damping = 0.3;
    let mut sys = TreeSystem::new(&model).unwrap();
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 1e-3,
        duration: 3.0,
        ..Default::default()
    };
    let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
    let mut work = 0.0;
    for k in 1..traj.len() {
        let (a, b) = (traj.dq(k - 1)[0], traj.dq(k)[0]);
        work += 0.5 * (a * a + b * b) * 0.3 * 1e-3;
    }
    let lost = traj.energy[0] - traj.energy.last().unwrap();
    assert!(lost > 0.1, "damping must remove energy");
    assert!(
        (lost - work).abs() < 1e-3 * lost,
        "lost {lost} vs dissipated {work}"
    );
}
