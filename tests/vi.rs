//! The variational integrator's Newton iteration: its exact Jacobian (paper eq. (26), with
//! damping) against finite differences of its residual, and the Jacobian-reuse option.

mod common;

use common::{interpreted, load, Rng};
use nalgebra::Dyn;
use tree_mech::integrate::{simulate, JacobianUpdate, Method, MidpointVi, SimOptions, ViSettings};
use tree_mech::runtime::{Pose, Vector};
use tree_mech::{NoForce, Order, System, Terms, TreeSystem};

#[test]
fn newton_jacobian_is_the_derivative_of_the_residual() {
    for (name, alpha) in [
        ("humanoid.toml", 0.5),
        ("double-pendulum.toml", 0.3),
        ("free-body.toml", 0.8),
    ] {
        let mut sys = interpreted(&load(name));
        let n = sys.dof();
        let mut rng = Rng::new(11);
        let q1 = rng.vector(n, 1.0);
        let p1 = rng.vector(n, 1.0);
        let q2 = &q1 + rng.vector(n, 0.05);
        let dt = 0.01;
        let settings = ViSettings {
            alpha,
            ..ViSettings::default()
        };
        let mut vi = MidpointVi::new(Dyn(n), settings);
        vi.residual(&mut sys, &mut NoForce, 0.0, dt, &q1, &p1, &q2, true);
        let jacobian = vi.jacobian().clone();
        let h = 1e-7;
        for j in 0..n {
            let (mut qp, mut qm) = (q2.clone(), q2.clone());
            qp[j] += h;
            qm[j] -= h;
            let fp = vi
                .residual(&mut sys, &mut NoForce, 0.0, dt, &q1, &p1, &qp, false)
                .clone();
            let fm = vi
                .residual(&mut sys, &mut NoForce, 0.0, dt, &q1, &p1, &qm, false)
                .clone();
            for i in 0..n {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let scale = jacobian.amax();
                assert!(
                    (jacobian[(i, j)] - fd).abs() < 1e-6 * scale,
                    "{name}: J[{i}][{j}] = {} vs {fd}",
                    jacobian[(i, j)]
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
    fn dim(&self) -> Dyn {
        self.inner.dim()
    }
    fn variable_name(&self, i: usize) -> &str {
        self.inner.variable_name(i)
    }
    fn frame_count(&self) -> usize {
        self.inner.frame_count()
    }
    fn frame_name(&self, k: usize) -> &str {
        self.inner.frame_name(k)
    }
    fn initial(&self, i: usize) -> (f64, f64) {
        self.inner.initial(i)
    }
    fn damping(&self, i: usize) -> f64 {
        self.inner.damping(i)
    }
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
    fn poses(&mut self, q: &Vector<Dyn>, out: &mut [Pose]) {
        self.inner.poses(q, out)
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
            let settings = ViSettings {
                jacobian,
                ..ViSettings::default()
            };
            let options = SimOptions {
                method: Method::Vi(settings),
                dt: 0.01,
                duration: 2.0,
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
            reuse.1 * 2 < exact.1,
            "{name}: {} full evaluations reused vs {} exact",
            reuse.1,
            exact.1
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
    let mut sys = TreeSystem::new(&model, tree_mech::Evaluation::Sweeps).unwrap();
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 1e-3,
        duration: 3.0,
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
