//! Optimal control (runtime::control): DARE against the scalar Riccati equation's root and
//! its residual; iLQR on a linear-quadratic problem (a spring-mass pushed by an input, whose
//! VI step is linear) converging in one iteration to the time-varying LQR; iLQR and DDP on
//! the cart-pole with limits: cost never increasing, limits held, compiled ≡ interpreted.

mod common;

use tree_mech::control::{
    cost_gradient, dare, solve, solve_until, tvlqr, Control, Cost, Derivatives, DiscreteSystem,
    IlqrSettings, Knot, QuadraticCost, Solver, Stop,
};
use tree_mech::integrate::{Forcing, ViSettings};
use tree_mech::model;
use tree_mech::nalgebra::{DMatrix, DVector};
use tree_mech::{tree_model, System, TreeSystem};

tree_model!(struct Cart from "tests/models/cart.toml");

/// `sys` discretised by the VI at `dt` (`settings`), and its model's start as a state.
fn at_start<S: System>(sys: S, settings: ViSettings, dt: f64) -> (DiscreteSystem<S>, DVector<f64>)
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let mut dynamics = DiscreteSystem::new(sys, settings, dt, 0.0).unwrap();
    let (q0, dq0) = dynamics.sys.initial_state();
    let x0 = dynamics.state_of(&q0, &dq0, &[]);
    (dynamics, x0)
}

#[test]
fn dare_matches_the_scalar_riccati_root_and_solves_the_equation() {
    let (a, b, q, r) = (1.1, 0.5, 2.0, 1.0);
    let m = |x: f64| DMatrix::from_element(1, 1, x);
    let lqr = dare(&m(a), &m(b), &m(q), &m(r)).unwrap();
    // b²P² + (r − q b² − a² r) P − q r = 0, the positive root.
    let (qa, qb, qc) = (b * b, r - q * b * b - a * a * r, -q * r);
    let p = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
    assert!(
        (lqr.p[(0, 0)] - p).abs() < 1e-10 * p,
        "{} vs {p}",
        lqr.p[(0, 0)]
    );
    let k = a * b * p / (r + b * b * p);
    assert!((lqr.k[(0, 0)] - k).abs() < 1e-10 * k);
    // A double integrator: the equation holds and the loop is stable.
    let dt = 0.1;
    let a = DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.5 * dt * dt, dt]);
    let (q, r) = (DMatrix::identity(2, 2), DMatrix::identity(1, 1) * 0.1);
    let lqr = dare(&a, &b, &q, &r).unwrap();
    let p = &lqr.p;
    let s = &r + b.transpose() * p * &b;
    let residual = &q + a.transpose() * p * &a
        - a.transpose() * p * &b * s.try_inverse().unwrap() * b.transpose() * p * &a
        - p;
    assert!(residual.amax() < 1e-9 * p.amax(), "{residual}");
    let closed = &a - &b * &lqr.k;
    let radius = closed
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    assert!(radius < 1.0, "closed loop radius {radius}");
    // Not stabilisable: an unstable mode the input cannot reach.
    let a = DMatrix::from_row_slice(2, 2, &[2.0, 0.0, 0.0, 0.5]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let err = dare(&a, &b, &q, &r).unwrap_err().to_string();
    assert!(err.contains("cannot be stabilised"), "{err}");
}

const SPRING: &str = r#"
name = "spring-mass"
gravity = [0.0, 0.0, 0.0]
[[frame]]
name = "mass"
tx = "x"
mass = 2.0
[variables.x]
q0 = 1.0
[[spring]]
variable = "x"
stiffness = 4.0
rest = 0.0
[[input]]
name = "push"
variable = "x"
"#;

#[test]
fn ilqr_solves_a_linear_quadratic_problem_in_one_iteration_as_the_riccati_recursion() {
    let m = model::from_toml_str(SPRING, None).unwrap();
    let sys = TreeSystem::new(&m).unwrap();
    let (dt, knots) = (0.05, 40);
    let settings = ViSettings {
        forcing: Forcing::Left,
        tolerance: 1e-14,
        ..ViSettings::default()
    };
    let (mut dynamics, x0) = at_start(sys, settings, dt);
    let cost = QuadraticCost {
        dt,
        x_ref: DVector::zeros(3),
        x_weight: DVector::from_vec(vec![1.0, 0.5, 0.0]),
        u_ref: DVector::zeros(1),
        u_weight: DVector::from_vec(vec![0.2]),
        terminal_ref: DVector::zeros(3),
        terminal_weight: DVector::from_vec(vec![10.0, 10.0, 0.0]),
    };
    let options = IlqrSettings {
        mu: 0.0,
        ..IlqrSettings::default()
    };
    let u0 = vec![DVector::zeros(1); knots];
    let sol = solve(&mut dynamics, &mut cost.clone(), &x0, u0, &options).unwrap();
    assert!(sol.converged);
    // The first accepted iteration reached the optimum: a full step, and nothing after.
    assert_eq!(sol.history[0].step, 1.0);
    let optimum = sol.history[0].cost;
    assert!(
        (sol.cost - optimum).abs() <= 1e-10 * optimum,
        "{} vs {optimum}",
        sol.cost
    );
    // The gains are the time-varying LQR's on the (constant) linear step.
    // The state is (x, p, the previous push).
    let (mut a, mut b) = (DMatrix::zeros(3, 3), DMatrix::zeros(3, 1));
    let mut x2 = [0.0; 3];
    dynamics
        .step(0, x0.as_slice(), &[0.0], &mut x2, Some((&mut a, &mut b)))
        .unwrap();
    let q = DMatrix::from_diagonal(&(&cost.x_weight * dt));
    let r = DMatrix::from_diagonal(&(&cost.u_weight * dt));
    let qf = DMatrix::from_diagonal(&cost.terminal_weight);
    let reference = tvlqr(&vec![a; knots], &vec![b; knots], &q, &r, &qf).unwrap();
    for (k, lqr) in reference.iter().enumerate() {
        let ours = -&sol.gains[k];
        assert!(
            (&ours - &lqr.k).amax() < 1e-8 * lqr.k.amax().max(1.0),
            "knot {k}: {ours} vs {}",
            lqr.k
        );
    }
    // The optimal controls obey u_k = −K_k x_k along the plan.
    for k in 0..knots {
        let u = -(&reference[k].k * &sol.x[k])[0];
        assert!(
            (u - sol.u[k][0]).abs() < 1e-8,
            "knot {k}: {} vs {u}",
            sol.u[k][0]
        );
    }
}

/// The cart pushed to x = 0.5, pendulum down, within [−2, 2] N.
fn cart_problem<S: System>(sys: S, solver: Solver) -> tree_mech::control::Solution
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let (dt, knots) = (0.02, 60);
    let (mut dynamics, x0) = at_start(sys, ViSettings::default(), dt);
    let mut cost = common::cart_to_half_metre(dt);
    let options = IlqrSettings {
        solver,
        limits: Some((DVector::from_vec(vec![-2.0]), DVector::from_vec(vec![2.0]))),
        max_iterations: 60,
        ..IlqrSettings::default()
    };
    let u0 = vec![DVector::zeros(1); knots];
    solve(&mut dynamics, &mut cost, &x0, u0, &options).unwrap()
}

#[test]
fn ilqr_and_ddp_lower_the_cost_every_iteration_within_the_limits() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let m = model::from_toml_file(path).unwrap();
    for solver in [Solver::Ilqr, Solver::Ddp] {
        let sol = cart_problem(TreeSystem::new(&m).unwrap(), solver);
        let mut last = f64::INFINITY;
        for it in &sol.history {
            assert!(
                it.cost <= last,
                "{solver:?}: cost rose to {} from {last}",
                it.cost
            );
            last = it.cost;
        }
        assert!(sol.history.len() > 1 && sol.history[0].cost > sol.cost);
        let mut at_limit = 0;
        for u in &sol.u {
            assert!(
                u[0].abs() <= 2.0 + 1e-12,
                "{solver:?}: {} out of [−2, 2]",
                u[0]
            );
            at_limit += (u[0].abs() > 2.0 - 1e-9) as usize;
        }
        assert!(
            at_limit > 0,
            "{solver:?}: the limits never bind, the test would not see them"
        );
        let end = sol.x.last().unwrap();
        assert!(
            (end[0] - 0.5).abs() < 0.05,
            "{solver:?}: the cart ends at {}",
            end[0]
        );
        eprintln!(
            "{solver:?}: {} iterations, cost {:.6}, converged {}",
            sol.history.len(),
            sol.cost,
            sol.converged
        );
    }
}

/// The iLQR optimum of the limited cart problem is a KKT point of the true cost: at every knot
/// the exact gradient `∂J/∂u_k` (the adjoint recursion) vanishes on a free control and points
/// out of the box on a control at a bound. The solve starts with the limits only clamped in
/// the forward pass and ends with the box QP; without that last phase the gradient at the
/// clamped knots is what stops it.
#[test]
fn the_limited_optimum_is_a_kkt_point_of_the_true_cost() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let m = model::from_toml_file(path).unwrap();
    let sol = cart_problem(TreeSystem::new(&m).unwrap(), Solver::Ilqr);
    let mut dynamics = DiscreteSystem::new(
        TreeSystem::new(&m).unwrap(),
        ViSettings::default(),
        0.02,
        0.0,
    )
    .unwrap();
    let mut cost = common::cart_to_half_metre(0.02);
    let u0 = vec![DVector::zeros(1); sol.u.len()];
    let (_, start) = cost_gradient(&mut dynamics, &mut cost, &sol.x[0], &u0).unwrap();
    let scale = start.iter().fold(0.0f64, |s, g| s.max(g.amax()));
    let (_, gradient) = cost_gradient(&mut dynamics, &mut cost, &sol.x[0], &sol.u).unwrap();
    let (mut free, mut bound) = (0, 0);
    for (k, (u, g)) in sol.u.iter().zip(&gradient).enumerate() {
        let (u, g) = (u[0], g[0] / scale);
        if u >= 2.0 - 1e-9 {
            bound += 1;
            assert!(
                g < 1e-4,
                "knot {k}: at the upper bound, the gradient {g} points inside"
            );
        } else if u <= -2.0 + 1e-9 {
            bound += 1;
            assert!(
                g > -1e-4,
                "knot {k}: at the lower bound, the gradient {g} points inside"
            );
        } else {
            free += 1;
            assert!(g.abs() < 1e-4, "knot {k}: a free control's gradient is {g}");
        }
    }
    assert!(free > 0 && bound > 0, "{free} free and {bound} bound knots");
}

#[test]
fn compiled_and_interpreted_iterates_agree() {
    let a = cart_problem(Cart, Solver::Ilqr);
    let b = cart_problem(TreeSystem::new(&Cart::model()).unwrap(), Solver::Ilqr);
    assert_eq!(a.history.len(), b.history.len());
    for (x, y) in a.u.iter().zip(&b.u) {
        assert!((x - y).amax() < 1e-9, "{x} vs {y}");
    }
    assert!((a.cost - b.cost).abs() < 1e-9 * a.cost);
}

/// The adjoint gradient of the total cost against central differences, on the cart-pole
/// (nonlinear, with the pendulum swinging).
#[test]
fn the_cost_gradient_matches_finite_differences() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let m = model::from_toml_file(path).unwrap();
    let dt = 0.02;
    let settings = ViSettings {
        tolerance: 1e-14,
        constraint_tolerance: 1e-14,
        ..ViSettings::default()
    };
    let (mut dynamics, x0) = at_start(TreeSystem::new(&m).unwrap(), settings, dt);
    let mut cost = QuadraticCost {
        dt,
        x_ref: DVector::from_vec(vec![0.5, 0.3, 0.0, 0.0, 0.0]),
        x_weight: DVector::from_vec(vec![1.0, 2.0, 0.1, 0.1, 0.5]),
        u_ref: DVector::from_vec(vec![0.2]),
        u_weight: DVector::from_vec(vec![1e-2]),
        terminal_ref: DVector::zeros(5),
        terminal_weight: DVector::from_vec(vec![10.0, 10.0, 1.0, 1.0, 0.0]),
    };
    let u: Vec<DVector<f64>> = (0..25)
        .map(|k| DVector::from_element(1, (0.3 * k as f64).sin()))
        .collect();
    let (total, gradient) = cost_gradient(&mut dynamics, &mut cost, &x0, &u).unwrap();
    let h = 1e-6;
    let mut largest = 0.0f64;
    for k in 0..u.len() {
        let mut shifted = |s: f64| {
            let mut v = u.clone();
            v[k][0] += s;
            cost_gradient(&mut dynamics, &mut cost, &x0, &v).unwrap().0
        };
        let fd = (shifted(h) - shifted(-h)) / (2.0 * h);
        assert!(
            (fd - gradient[k][0]).abs() < 1e-6 * fd.abs().max(1e-3),
            "knot {k}: {} vs {fd}",
            gradient[k][0]
        );
        largest = largest.max(fd.abs());
    }
    assert!(largest > 1e-3 && total > 0.0);
}

/// The cart-pole upright: the DARE gain on the VI step linearised at the top brings a pushed
/// pole back (and the open loop, the same push, falls).
#[test]
fn lqr_holds_the_cartpole_upright_from_a_push() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/cartpole.toml");
    let m = model::from_toml_file(path).unwrap();
    let dt = 0.02;
    let mut dynamics =
        DiscreteSystem::new(TreeSystem::new(&m).unwrap(), ViSettings::default(), dt, 0.0).unwrap();
    // The state is (q_d, p_d, the previous push).
    let (mut a, mut b) = (DMatrix::zeros(5, 5), DMatrix::zeros(5, 1));
    let mut x2 = [0.0; 5];
    dynamics
        .step(0, &[0.0; 5], &[0.0], &mut x2, Some((&mut a, &mut b)))
        .unwrap();
    assert!(
        x2.iter().all(|v| v.abs() < 1e-12),
        "upright is an equilibrium: {x2:?}"
    );
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 10.0, 0.1, 0.1, 0.0]));
    let r = DMatrix::identity(1, 1) * 0.1;
    let lqr = dare(&a, &b, &q, &r).unwrap();
    let run = |dynamics: &mut DiscreteSystem<TreeSystem>, closed: bool| {
        let mut x = DVector::from_vec(vec![0.0, 0.2, 0.0, 0.0, 0.0]);
        let mut next = [0.0; 5];
        let mut largest_push = 0.0f64;
        for k in 0..400 {
            let u = if closed {
                (-(&lqr.k * &x)[0]).clamp(-20.0, 20.0)
            } else {
                0.0
            };
            largest_push = largest_push.max(u.abs());
            if dynamics
                .step(k, x.as_slice(), &[u], &mut next, None)
                .is_err()
            {
                break;
            }
            x.copy_from_slice(&next);
        }
        (x, largest_push)
    };
    let (end, push) = run(&mut dynamics, true);
    assert!(
        end[1].abs() < 1e-3 && end[0].abs() < 1e-2,
        "closed loop ends at {end}"
    );
    assert!(push > 1.0, "the controller pushed {push} N");
    let (open, _) = run(&mut dynamics, false);
    assert!(
        open[1].abs() > 1.0,
        "without control the pole falls: {open}"
    );
}

/// Problems that do not fit the system are refused with a sentence, never a panic.
#[test]
fn mismatched_problems_are_refused_with_a_sentence() {
    let m = model::from_toml_str(SPRING, None).unwrap();
    // Systems that cannot be built: a bad step, a control that is not one.
    let sys = || TreeSystem::new(&m).unwrap();
    let refused = |r: Result<DiscreteSystem<TreeSystem>, tree_mech::SimError>| match r {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    };
    let e = refused(DiscreteSystem::new(sys(), ViSettings::default(), -0.1, 0.0));
    assert!(
        e.contains("step must be positive") && e.contains("-0.1"),
        "{e}"
    );
    let e = refused(DiscreteSystem::vi(
        sys(),
        ViSettings::default(),
        0.1,
        0.0,
        vec![Control::Kinematic(0)],
    ));
    assert!(
        e.contains("control variable 0 (not kinematic) is not a control"),
        "{e}"
    );
    let e = refused(DiscreteSystem::rk4(
        sys(),
        0.1,
        0.0,
        vec![Control::Input(3)],
    ));
    assert!(e.contains("control input 3 is not a control"), "{e}");
    let mut dynamics = DiscreteSystem::new(
        TreeSystem::new(&m).unwrap(),
        ViSettings::default(),
        0.05,
        0.0,
    )
    .unwrap();
    let good = QuadraticCost {
        dt: 0.05,
        x_ref: DVector::zeros(3),
        x_weight: DVector::from_element(3, 1.0),
        u_ref: DVector::zeros(1),
        u_weight: DVector::from_element(1, 1.0),
        terminal_ref: DVector::zeros(3),
        terminal_weight: DVector::from_element(3, 1.0),
    };
    let x0 = DVector::zeros(3);
    let u = vec![DVector::zeros(1); 5];
    let settings = IlqrSettings::default();
    let mut err =
        |cost: &QuadraticCost, x0: &DVector<f64>, u: Vec<DVector<f64>>, s: &IlqrSettings| {
            solve(&mut dynamics, &mut cost.clone(), x0, u, s)
                .unwrap_err()
                .to_string()
        };
    let e = err(&good, &DVector::zeros(4), u.clone(), &settings);
    assert!(e.contains("start state has 4 entries"), "{e}");
    let e = err(&good, &x0, vec![], &settings);
    assert!(e.contains("at least one knot"), "{e}");
    let e = err(&good, &x0, vec![DVector::zeros(2); 3], &settings);
    assert!(e.contains("knot 0 has 2 entries"), "{e}");
    let mut bad = good.clone();
    bad.u_weight = DVector::from_element(1, -1.0);
    let e = err(&bad, &x0, u.clone(), &settings);
    assert!(e.contains("non-negative"), "{e}");
    let mut bad = good.clone();
    bad.x_ref = DVector::zeros(5);
    let e = err(&bad, &x0, u.clone(), &settings);
    assert!(e.contains("x_ref has 5 entries"), "{e}");
    let limited = IlqrSettings {
        limits: Some((
            DVector::from_element(1, 1.0),
            DVector::from_element(1, -1.0),
        )),
        ..IlqrSettings::default()
    };
    let e = err(&good, &x0, u.clone(), &limited);
    assert!(e.contains("lower must not exceed the upper"), "{e}");
    let wrong = IlqrSettings {
        limits: Some((DVector::zeros(2), DVector::zeros(2))),
        ..IlqrSettings::default()
    };
    let e = err(&good, &x0, u.clone(), &wrong);
    assert!(e.contains("problem has 1 controls"), "{e}");
    let loose = IlqrSettings {
        cost_tolerance: f64::NAN,
        ..IlqrSettings::default()
    };
    let e = err(&good, &x0, u.clone(), &loose);
    assert!(e.contains("must be finite and non-negative"), "{e}");
    for min_step in [0.0, 1.5, f64::NAN] {
        let search = IlqrSettings {
            min_step,
            ..IlqrSettings::default()
        };
        let e = err(&good, &x0, u.clone(), &search);
        assert!(e.contains("smallest step (min_step = "), "{e}");
    }
}

/// A knot's velocity and gravity compensation by the state (`dq_x`, `gravity_x`) against
/// central differences of the knot itself, on a pole whose cart is a kinematic control: the
/// VI's velocity `q̇_d = M_dd⁻¹(p_d − M_dk q̇_k)` depends on the cart's velocity (the
/// controls' memory) through `M_dk`, and the pole's input compensates gravity.
#[test]
fn knot_derivatives_match_finite_differences() {
    use tree_mech::control::{Knot, Needs};
    let text = r#"
name = "kinematic-cart"
[[frame]]
name = "cart"
tx = "x"
mass = 1.0
[[frame]]
name = "pivot"
parent = "cart"
ry = "theta"
[[frame]]
name = "pole"
parent = "pivot"
tz = 0.5
mass = 0.3
inertia = [0.006, 0.006, 0.0005]
[variables.x]
kinematic = true
[variables.theta]
q0 = 0.7
[[input]]
name = "hold"
variable = "theta"
"#;
    let m = model::from_toml_str(text, None).unwrap();
    let cart = m.variable_index("x").unwrap();
    let controls = vec![Control::Input(0), Control::Kinematic(cart)];
    let sys = TreeSystem::new(&m).unwrap();
    let mut d = DiscreteSystem::vi(sys, ViSettings::default(), 0.01, 0.0, controls).unwrap();
    let (q0, mut dq0) = d.sys.initial_state();
    dq0[cart] = 0.8;
    dq0[m.variable_index("theta").unwrap()] = -0.4;
    let x = d.state_of(&q0, &dq0, &[0.3, 0.1]);
    let needs = Needs {
        velocity: true,
        gravity: true,
        ..Needs::default()
    };
    let mut knot = Knot::empty();
    d.knot(1, x.as_slice(), &mut knot, true, needs).unwrap();
    let (dq_x, gravity_x) = (knot.dq_x.clone(), knot.gravity_x.clone());
    assert!(
        dq_x.amax() > 0.1 && gravity_x.amax() > 0.1,
        "the derivatives are not trivial: {dq_x} {gravity_x}"
    );
    let h = 1e-6;
    for c in 0..x.len() {
        let mut at = |s: f64| {
            let mut y = x.clone();
            y[c] += s * h;
            d.knot(1, y.as_slice(), &mut knot, false, needs).unwrap();
            (knot.dq.clone(), knot.gravity.clone())
        };
        let ((dq_p, g_p), (dq_m, g_m)) = (at(1.0), at(-1.0));
        let fd_dq = (dq_p - dq_m) / (2.0 * h);
        let fd_g = (g_p - g_m) / (2.0 * h);
        assert!(
            (&fd_dq - dq_x.column(c)).amax() < 1e-6 * dq_x.amax(),
            "∂q̇/∂x column {c}: {fd_dq} against {}",
            dq_x.column(c)
        );
        assert!(
            (&fd_g - gravity_x.column(c)).amax() < 1e-6 * gravity_x.amax(),
            "∂g/∂x column {c}: {fd_g} against {}",
            gravity_x.column(c)
        );
    }
}

/// iLQR on `dynamics` over `knots` from `x0` and zero controls, unlimited, 60 iterations at most.
fn unlimited<S: System>(
    mut dynamics: DiscreteSystem<S>,
    mut cost: QuadraticCost,
    x0: &DVector<f64>,
    knots: usize,
) -> tree_mech::control::Solution
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let options = IlqrSettings {
        max_iterations: 60,
        ..IlqrSettings::default()
    };
    let u0 = vec![DVector::zeros(dynamics.controls()); knots];
    solve(&mut dynamics, &mut cost, x0, u0, &options).unwrap()
}

/// The cart problem with every weight scaled by `scale`, unlimited, iLQR.
fn scaled_cart(scale: f64) -> tree_mech::control::Solution {
    let (dt, knots) = (0.02, 60);
    let (dynamics, x0) = at_start(Cart, ViSettings::default(), dt);
    let mut cost = common::cart_to_half_metre(dt);
    for w in [
        &mut cost.x_weight,
        &mut cost.u_weight,
        &mut cost.terminal_weight,
    ] {
        *w *= scale;
    }
    unlimited(dynamics, cost, &x0, knots)
}

#[test]
fn a_task_in_other_units_takes_the_same_steps() {
    // The regularisation is relative to the controls' curvature: weights scaled by 1e-30 or
    // 1e30 (a cost in other units) give the same iterations and the same plan, where an
    // absolute μ = 1e-6 would vanish against a curvature of 1e30 (and stop at once).
    let plain = scaled_cart(1.0);
    assert!(plain.converged && plain.stop == Stop::Converged);
    for scale in [1e-30, 1e30] {
        let other = scaled_cart(scale);
        assert_eq!(other.stop, Stop::Converged, "scale {scale:e}");
        assert_eq!(other.history.len(), plain.history.len(), "scale {scale:e}");
        assert!(
            (other.cost / scale - plain.cost).abs() <= 1e-9 * plain.cost,
            "scale {scale:e}: cost {} against {}",
            other.cost / scale,
            plain.cost
        );
        for (a, b) in other.u.iter().zip(&plain.u) {
            assert!((a - b).amax() <= 1e-9 * (1.0 + b.amax()), "scale {scale:e}");
        }
    }
}

/// The cart problem with the model written in units of `length` metres (`x`, the bob's
/// offset and gravity divided by it; forces and momenta with it) and every weight converted,
/// so the cost is the same function of the same motion: unlimited, iLQR.
fn cart_in_units(length: f64) -> tree_mech::control::Solution {
    let l = length;
    let text = format!(
        "name = \"cart\"\ngravity = [0.0, 0.0, {g:e}]\n\
         [[frame]]\nname = \"cart\"\ntx = \"x\"\nmass = 1.0\n\
         [[frame]]\nname = \"pivot\"\nparent = \"cart\"\nry = \"theta\"\n\
         [[frame]]\nname = \"bob\"\nparent = \"pivot\"\ntz = {tz:e}\nmass = 0.2\n\
         [variables.theta]\nq0 = 0.1\n\
         [[input]]\nname = \"push\"\nvariable = \"x\"\n",
        g = -9.81 / l,
        tz = -0.5 / l
    );
    let m = model::from_toml_str(&text, None).unwrap();
    let (dt, knots) = (0.02, 60);
    let (dynamics, x0) = at_start(TreeSystem::new(&m).unwrap(), ViSettings::default(), dt);
    let mut cost = common::cart_to_half_metre(dt);
    // State (x, θ, p_x, p_θ, the push's memory): a length scales x, p_x and the push by 1/l,
    // p_θ by 1/l², so their weights gain l², l², l⁴, l².
    let per_entry = DVector::from_vec(vec![l * l, 1.0, l * l, l.powi(4), l * l]);
    cost.x_weight.component_mul_assign(&per_entry);
    cost.terminal_weight.component_mul_assign(&per_entry);
    cost.x_ref[0] /= l;
    cost.terminal_ref[0] /= l;
    cost.u_weight *= l * l;
    unlimited(dynamics, cost, &x0, knots)
}

#[test]
fn a_model_in_other_units_stops_alike() {
    // The convergence test is relative to the cost and in its units: the same cart in
    // gigametres (its push in 10⁻⁹ N, every feed-forward below 10⁻⁸ from the start) or in
    // nanometres takes the same iterations to the same plan, where a bound on max |k| in the
    // controls' units stopped the first at iteration 0.
    let plain = cart_in_units(1.0);
    assert_eq!(plain.stop, Stop::Converged);
    assert!(
        plain.history.len() > 2,
        "{} iterations",
        plain.history.len()
    );
    for l in [1e9, 1e-9] {
        let other = cart_in_units(l);
        assert_eq!(other.stop, Stop::Converged, "length unit {l:e} m");
        assert_eq!(
            other.history.len(),
            plain.history.len(),
            "length unit {l:e} m"
        );
        assert!(
            (other.cost - plain.cost).abs() <= 1e-8 * plain.cost,
            "length unit {l:e} m: cost {} against {}",
            other.cost,
            plain.cost
        );
        for (a, b) in other.u.iter().zip(&plain.u) {
            assert!(
                (a[0] * l - b[0]).abs() <= 1e-7 * (1.0 + b[0].abs()),
                "length unit {l:e} m: push {} N against {} N",
                a[0] * l,
                b[0]
            );
        }
    }
}

/// A cost whose derivatives point the wrong way (its gradient negated): no step of the local
/// model lowers it.
struct Misleading(QuadraticCost);

impl Cost for Misleading {
    fn running(
        &mut self,
        k: usize,
        x: &Knot,
        u: &DVector<f64>,
        mut d: Option<&mut Derivatives>,
    ) -> f64 {
        let value = self.0.running(k, x, u, d.as_deref_mut());
        if let Some(d) = d {
            d.lx.neg_mut();
            d.lu.neg_mut();
        }
        value
    }

    fn terminal(&mut self, x: &Knot, mut d: Option<&mut Derivatives>) -> f64 {
        let value = self.0.terminal(x, d.as_deref_mut());
        if let Some(d) = d {
            d.lx.neg_mut();
        }
        value
    }
}

#[test]
fn a_solve_whose_model_never_lowers_the_cost_stops_on_the_regularisation() {
    let (dt, knots) = (0.02, 30);
    let (mut dynamics, x0) = at_start(Cart, ViSettings::default(), dt);
    let mut cost = Misleading(common::cart_to_half_metre(dt));
    let options = IlqrSettings {
        max_iterations: 100,
        ..IlqrSettings::default()
    };
    let u0 = vec![DVector::zeros(1); knots];
    let sol = solve(&mut dynamics, &mut cost, &x0, u0, &options).unwrap();
    assert_eq!(sol.stop, Stop::Regularisation);
    assert!(!sol.converged && sol.history.len() < 100);
    // The start is kept: nothing lowered its cost.
    assert!(sol.u.iter().all(|u| u[0] == 0.0));
}

#[test]
fn a_report_that_asks_to_stop_ends_the_solve_with_its_best_trajectory() {
    let (dt, knots) = (0.02, 60);
    let (mut dynamics, x0) = at_start(Cart, ViSettings::default(), dt);
    let mut cost = common::cart_to_half_metre(dt);
    let mut seen = 0;
    let sol = solve_until(
        &mut dynamics,
        &mut cost,
        &x0,
        vec![DVector::zeros(1); knots],
        &IlqrSettings::default(),
        &mut |_| {
            seen += 1;
            if seen == 2 {
                std::ops::ControlFlow::Break(())
            } else {
                std::ops::ControlFlow::Continue(())
            }
        },
    )
    .unwrap();
    assert_eq!(sol.stop, Stop::Interrupted);
    assert!(!sol.converged);
    assert_eq!(sol.history.len(), 2);
    assert_eq!(sol.cost, sol.history[1].cost);
    // The full solve goes on from there to a lower cost.
    let (dynamics, _) = at_start(Cart, ViSettings::default(), dt);
    let full = unlimited(dynamics, common::cart_to_half_metre(dt), &x0, knots);
    assert!(full.history.len() > 2 && full.cost < sol.cost);
}

/// MPC on the cart's plan (towards x = 0.5 within ±2 N): started with a push the plan never
/// saw (0.2 N·s on the cart), re-planned over 10 knots every knot with one iteration a tick,
/// the cart stays within 3 cm of the plan's (2.4 cm, at the end, where the reference stops
/// dead beyond the plan) within the limits; the plan's controls played open loop from the
/// same push end 20 cm off. Wrong sizes, a zero horizon or tick and a plant of another step
/// are refused in sentences.
#[test]
fn mpc_tracks_a_plan_through_a_push_the_plan_never_saw() {
    use tree_mech::control::{Mpc, MpcSettings};
    let plan = cart_problem(Cart, Solver::Ilqr);
    let limits = (DVector::from_vec(vec![-2.0]), DVector::from_vec(vec![2.0]));
    let settings = |horizon: usize| MpcSettings {
        horizon,
        ilqr: IlqrSettings {
            max_iterations: 1,
            limits: Some(limits.clone()),
            ..IlqrSettings::default()
        },
        x_weight: DVector::from_vec(vec![100.0, 100.0, 1.0, 1.0, 0.0]),
        u_weight: DVector::from_vec(vec![1e-3]),
        terminal_weight: DVector::from_vec(vec![1e3, 1e3, 10.0, 10.0, 0.0]),
    };
    let (dynamics, x0) = at_start(Cart, ViSettings::default(), 0.02);
    assert_eq!((&plan.x[0] - &x0).amax(), 0.0);
    let mut mpc = Mpc::new(dynamics, plan.x.clone(), plan.u.clone(), settings(10)).unwrap();
    let (mut plant, _) = at_start(Cart, ViSettings::default(), 0.02);
    let mut pushed = x0.clone();
    pushed[2] += 0.2;
    let knots = plan.u.len();
    let run = mpc
        .closed_loop(&mut plant, &pushed, knots, 1, &mut |_, _| {})
        .unwrap();
    assert_eq!((run.x.len(), run.tick_seconds.len()), (knots + 1, knots));
    // The largest distance of the cart from the plan's over the run, and at the end.
    let off = |x: &[DVector<f64>]| {
        let d: Vec<f64> = (0..=knots)
            .map(|k| (x[k][0] - plan.x[k][0]).abs())
            .collect();
        (d.iter().copied().fold(0.0, f64::max), d[knots])
    };
    let (worst, last) = off(&run.x);
    assert!(run.u.iter().all(|u| u[0].abs() <= 2.0));
    // Open loop from the same push.
    let mut open = vec![pushed.clone()];
    for k in 0..knots {
        let mut next = pushed.clone();
        let x = open[k].as_slice();
        plant
            .step(k, x, plan.u[k].as_slice(), next.as_mut_slice(), None)
            .unwrap();
        open.push(next);
    }
    let (_, open_last) = off(&open);
    assert!(
        worst < 3e-2 && open_last > 5.0 * worst,
        "MPC off the plan by {worst} m at worst ({last} at the end); open loop by {open_last} at the end"
    );
    let refused = |x_ref: Vec<DVector<f64>>, s: MpcSettings| {
        let (dynamics, _) = at_start(Cart, ViSettings::default(), 0.02);
        match Mpc::new(dynamics, x_ref, plan.u.clone(), s) {
            Ok(_) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    };
    let mut ragged = plan.x.clone();
    ragged[7] = DVector::zeros(4);
    let e = refused(ragged, settings(10));
    assert!(
        e.contains("the MPC's reference state has 4 entries; the problem has 5"),
        "{e}"
    );
    let short = plan.x[..knots].to_vec();
    assert!(refused(short, settings(10)).contains("one more state than controls"));
    assert!(refused(plan.x.clone(), settings(0)).contains("horizon and its iterations"));
    let mut wide = settings(10);
    wide.u_weight = DVector::zeros(2);
    assert!(refused(plan.x.clone(), wide).contains("u_weight has 2 entries; the problem has 1"));
    let (mut other, _) = at_start(Cart, ViSettings::default(), 0.01);
    let err = mpc
        .closed_loop(&mut other, &pushed, 5, 1, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("Δt = 0.01 s and the planner 0.02 s"), "{err}");
    let err = mpc
        .closed_loop(&mut plant, &pushed, 5, 0, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("at least every knot (every ≥ 1)"), "{err}");
}
