//! Contact in the variational integrator (docs/derivations.md §13): analytic cases.

use nalgebra::Dyn;
use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::model::{self, Model};
use tree_mech::runtime::Vector;
use tree_mech::{ConstraintTerms, NoForce, System, Trajectory, TreeSystem};

fn load(path: &str) -> Model {
    model::from_toml_file(path).unwrap()
}

fn vi(dt: f64, duration: f64) -> SimOptions {
    SimOptions::new(Method::Vi(ViSettings::default()), dt, duration)
}

/// The model run from its own start on the hard-contact VI, unforced.
fn run(model: &Model, dt: f64, duration: f64) -> Trajectory {
    let mut sys = TreeSystem::new(model).unwrap();
    let (q0, dq0) = sys.initial_state();
    run_from(&mut sys, &q0, &dq0, dt, duration)
}

/// `sys` run from `(q0, q̇0)` on the hard-contact VI, unforced.
fn run_from(
    sys: &mut TreeSystem,
    q0: &Vector<Dyn>,
    dq0: &Vector<Dyn>,
    dt: f64,
    duration: f64,
) -> Trajectory {
    simulate(sys, q0, dq0, &vi(dt, duration), &mut NoForce, &mut |_| {}).unwrap()
}

/// A ball dropped from 1 m above the ground touches it at √(2h/g) and rests at its radius.
#[test]
fn a_dropped_ball_lands_on_time_and_rests_at_its_radius() {
    let model = load("tests/models/ball.toml");
    let dt = 1e-3;
    let traj = run(&model, dt, 1.0);
    let z: Vec<f64> = (0..traj.len()).map(|k| traj.q(k)[2]).collect();
    let landing = (0..z.len()).find(|&k| z[k] <= 0.1 + 1e-9).unwrap();
    let expected = (2.0 * 1.0 / 9.81f64).sqrt();
    let t = traj.t[landing];
    eprintln!(
        "landed at {t} (expected {expected}), rests at {}",
        z.last().unwrap()
    );
    assert!(
        (t - expected).abs() <= 2.0 * dt,
        "landed at {t}, expected {expected}"
    );
    let lowest = z.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(lowest >= 0.1 - 1e-9, "penetrated to {lowest}");
    assert!(
        (z.last().unwrap() - 0.1).abs() <= 1e-9,
        "rests at {}",
        z.last().unwrap()
    );
    // At rest it reports rest (the contact holds the velocity the step's momentum would
    // give, −gΔt/2), and its energy is m g r from then on.
    let last = traj.len() - 1;
    assert!(traj.dq(last)[2].abs() < 1e-9, "reports {:?}", traj.dq(last));
    let e = traj.energy[last];
    assert!((e - 9.81 * 0.1).abs() < 1e-9, "E = {e}");
    // Its impulses and gaps: resting, each step's impulse is its weight's, m g Δt, its gap 0,
    // no friction; at the start none, and the gap is the drop.
    assert_eq!(traj.unilateral, ["ball", "ball.t1", "ball.t2"]);
    let (impulse, gap) = (traj.impulse(last), traj.gap(last));
    assert!(
        (impulse[0] - 9.81 * dt).abs() < 1e-9 * 9.81 * dt,
        "γ = {}",
        impulse[0]
    );
    assert!(gap[0].abs() < 1e-9 && impulse[1].abs() < 1e-12 && impulse[2].abs() < 1e-12);
    assert_eq!(traj.impulse(0), [0.0; 3]);
    assert!((traj.gap(0)[0] - 1.0).abs() < 1e-12);
}

/// A cube sliding at v₀ on its four lower corners with friction μ stops after v₀²/(2μg), at
/// t = v₀/(μg), without tipping or leaving the ground.
#[test]
fn a_sliding_box_stops_where_coulomb_says() {
    let model = load("tests/models/box.toml");
    let dt = 1e-3;
    let traj = run(&model, dt, 0.4);
    let (mu, g, v0) = (0.5, 9.81, 1.0);
    let (distance, time) = (v0 * v0 / (2.0 * mu * g), v0 / (mu * g));
    let x: Vec<f64> = (0..traj.len()).map(|k| traj.q(k)[0]).collect();
    let end = *x.last().unwrap();
    let stop = (1..x.len())
        .find(|&k| (x[k] - x[k - 1]).abs() < 1e-12)
        .unwrap();
    eprintln!(
        "stopped at x = {end} after t = {} (expected {distance}, {time})",
        traj.t[stop]
    );
    assert!(
        (end - distance).abs() <= 5e-3 * distance,
        "stopped at {end}, expected {distance}"
    );
    assert!(
        (traj.t[stop] - time).abs() <= 2.0 * dt,
        "stopped at t = {}",
        traj.t[stop]
    );
    for k in 0..traj.len() {
        let q = traj.q(k);
        assert!((q[2] - 0.1).abs() < 1e-9, "z = {} at step {k}", q[2]);
        assert!(
            q[3..].iter().all(|a| a.abs() < 1e-9),
            "turned: {:?}",
            &q[3..]
        );
    }
}

/// The cube on a slope (gravity tilted by θ): it sticks when tan θ < μ and slides with
/// g(sin θ − μ cos θ) otherwise.
#[test]
fn a_box_on_a_slope_sticks_or_slides_as_coulomb_says() {
    let text = std::fs::read_to_string("tests/models/box.toml").unwrap();
    let text = text.replace("[variables.x]\ndq0 = 1.0\n", "");
    for theta in [0.3f64, 0.6] {
        let g = 9.81;
        let gravity = format!(
            "gravity = [{}, 0.0, {}]\n",
            g * theta.sin(),
            -g * theta.cos()
        );
        let model = model::from_toml_str(&format!("{gravity}{text}"), Some("slope.toml")).unwrap();
        let (dt, duration) = (1e-3, 0.5);
        let traj = run(&model, dt, duration);
        let x = traj.q(traj.len() - 1)[0];
        let a = g * (theta.sin() - 0.5 * theta.cos());
        if theta.tan() < 0.5 {
            assert!(x.abs() < 1e-9, "θ = {theta}: slid to {x}");
            // Its reported velocity is the rest it is at: the eight sticking corners' 24
            // rows, dependent on 6 degrees of freedom, once had it reported at 8 m/s.
            let fastest = (0..traj.len())
                .flat_map(|k| traj.dq(k).to_vec())
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(fastest < 1e-9, "θ = {theta}: reported moving at {fastest}");
        } else {
            let expected = 0.5 * a * duration * duration;
            eprintln!("θ = {theta}: slid {x}, expected {expected}");
            assert!(
                (x - expected).abs() <= 5e-3 * expected,
                "θ = {theta}: slid {x}, expected {expected}"
            );
        }
    }
}

/// The Panda (its URDF's limits enforced, by default) collapses from its home pose under
/// gravity onto its limits — wrist, elbow and fingers pressing at once, the fingers' impulses
/// 10⁴ times the arm's smaller — and the limits hold to rounding; its steps stay in their
/// modes: at most three Newton updates a step on average over 3 s (ten before a mode step
/// at its rounding floor counted as converged, as the interior point's does).
#[test]
fn the_panda_collapses_onto_its_limits_in_its_modes() {
    let model = model::from_urdf_file("models/panda.urdf", Default::default()).unwrap();
    assert!(model.contacts.enforce_limits);
    let traj = run(&model, 1e-3, 3.0);
    let deepest = (0..traj.len())
        .flat_map(|k| traj.gap(k).to_vec())
        .fold(0.0, f64::min);
    assert!(deepest > -1e-12, "a limit passed by {deepest:e}");
    let pressing: Vec<&str> = (0..traj.unilateral.len())
        .filter(|&r| (0..traj.len()).any(|k| traj.impulse(k)[r] > 0.0))
        .map(|r| traj.unilateral[r].as_str())
        .collect();
    assert!(
        pressing.len() >= 8 && pressing.iter().any(|r| r.contains("finger")),
        "{pressing:?}"
    );
    let per_step = traj.newton_iterations as f64 / (traj.len() - 1) as f64;
    assert!(per_step <= 3.0, "{per_step} Newton updates a step");
}

/// A pendulum thrown at its limit never passes it and never gains energy — enforced by
/// default (the file does not say); with `enforce_limits = false` it swings through.
#[test]
fn a_pendulum_thrown_at_its_limit_never_passes_it() {
    let model = load("tests/models/limited-pendulum.toml");
    let mut free = model.clone();
    free.contacts.enforce_limits = false;
    let through = run(&free, 1e-3, 2.0);
    assert!((0..through.len()).any(|k| through.q(k)[0] > 0.6));
    let traj = run(&model, 1e-3, 2.0);
    let theta: Vec<f64> = (0..traj.len()).map(|k| traj.q(k)[0]).collect();
    let (lowest, highest) = theta
        .iter()
        .fold((0.0f64, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
    assert!(
        lowest >= -0.5 - 1e-9 && highest <= 0.5 + 1e-9,
        "θ in [{lowest}, {highest}]"
    );
    assert!(
        highest > 0.5 - 1e-9 && lowest < -0.5 + 1e-9,
        "it reached both limits"
    );
    let e0 = traj.energy[0];
    let gained = traj
        .energy
        .iter()
        .map(|e| e - e0)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(gained <= 1e-9 * e0.abs().max(1.0), "gained {gained}");
}

/// A mass on a slack string falls freely (½gt²) until the string is taut, then hangs at its
/// length.
#[test]
fn a_mass_on_a_slack_string_falls_freely_until_taut() {
    let model = load("tests/models/string-drop.toml");
    let dt = 1e-3;
    let traj = run(&model, dt, 1.0);
    let taut = (2.0 * 0.5 / 9.81f64).sqrt();
    for k in 0..traj.len() {
        let (t, z) = (traj.t[k], traj.q(k)[0]);
        assert!(z >= -1.0 - 1e-9, "the string stretched to {z} at t = {t}");
        if t < taut - dt {
            let free = -0.5 - 0.5 * 9.81 * t * t;
            assert!(
                (z - free).abs() < 1e-9,
                "z = {z} at t = {t}, free fall gives {free}"
            );
        }
    }
    assert!((traj.q(traj.len() - 1)[0] + 1.0).abs() < 1e-9);
}

/// Two equal balls in a head-on inelastic collision move on together at the mean velocity.
#[test]
fn two_balls_meeting_head_on_move_on_together() {
    let model = load("tests/models/two-balls.toml");
    let traj = run(&model, 1e-3, 0.5);
    let last = traj.len() - 1;
    let (q, dq) = (traj.q(last), traj.dq(last));
    eprintln!("apart {} at velocities {dq:?}", q[1] - q[0]);
    assert!((q[1] - q[0] - 0.2).abs() < 1e-9, "apart {}", q[1] - q[0]);
    assert!(
        (dq[0] - 1.0).abs() < 1e-9 && (dq[1] - 1.0).abs() < 1e-9,
        "{dq:?}"
    );
    let lowest = (0..traj.len())
        .map(|k| traj.q(k)[1] - traj.q(k)[0])
        .fold(f64::INFINITY, f64::min);
    assert!(lowest >= 0.2 - 1e-9, "overlapped to {lowest}");
}

tree_mech::tree_model!(struct Contacts from "tests/models/contacts.toml");

/// `φ`, `Dφ` and `Σ w D²φ` at `q` (rows × dof; the weighted Hessian with `weights`).
fn gaps_at<S: System>(
    sys: &mut S,
    q: &[f64],
    weights: &[f64],
) -> (Vec<f64>, nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>)
where
    nalgebra::DefaultAllocator:
        nalgebra::allocator::Allocator<S::N> + nalgebra::allocator::Allocator<S::N, S::N>,
{
    let q = Vector::<S::N>::from_column_slice_generic(sys.dim(), nalgebra::U1, q);
    let rows = weights.len();
    let mut out = ConstraintTerms::zeros(rows, sys.dof());
    sys.gaps(&q, None, &mut out);
    let (h, dh) = (out.h.as_slice().to_vec(), out.dh.clone());
    sys.gaps(&q, Some(weights), &mut out);
    (h, dh, out.weighted_d2h.clone())
}

/// Every kind of row — limits, ground with friction (tangent rows), two spheres, a string of
/// variable length — against central differences, and compiled equal to interpreted.
#[test]
fn gaps_match_differences_and_compile_equal() {
    let model = load("tests/models/contacts.toml");
    let rows = model.gap_rows();
    // 4 limit rows, two ground contacts with friction (3 each), the pair, the string.
    assert_eq!(rows, 4 + 6 + 1 + 1);
    let mut interp = TreeSystem::new(&model).unwrap();
    let mut compiled = Contacts;
    let n = model.dof();
    let mut seed = 0.37f64;
    let mut next = || {
        seed = (seed * 9301.0 + 0.49297).fract();
        2.0 * seed - 1.0
    };
    for _ in 0..4 {
        let q: Vec<f64> = (0..n).map(|_| next()).collect();
        let w: Vec<f64> = (0..rows).map(|_| next()).collect();
        let (h, dh, wh) = gaps_at(&mut interp, &q, &w);
        let (hc, dhc, whc) = gaps_at(&mut compiled, &q, &w);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0);
        for r in 0..rows {
            assert!(close(h[r], hc[r]), "φ[{r}]: {} vs {}", h[r], hc[r]);
            for i in 0..n {
                assert!(close(dh[(r, i)], dhc[(r, i)]), "Dφ[{r}, {i}]");
            }
        }
        for (a, b) in wh.iter().zip(whc.iter()) {
            assert!(close(*a, *b), "Σ w D²φ: {a} vs {b}");
        }
        let step = 1e-6;
        let kinematic = model
            .variables
            .iter()
            .map(|v| v.is_kinematic())
            .collect::<Vec<_>>();
        for j in 0..n {
            let (mut qp, mut qm) = (q.clone(), q.clone());
            qp[j] += step;
            qm[j] -= step;
            let (hp, dhp, _) = gaps_at(&mut interp, &qp, &w);
            let (hm, dhm, _) = gaps_at(&mut interp, &qm, &w);
            for r in 0..rows {
                let fd = (hp[r] - hm[r]) / (2.0 * step);
                assert!(
                    (dh[(r, j)] - fd).abs() <= 1e-7,
                    "Dφ[{r}, {j}] {} vs {fd}",
                    dh[(r, j)]
                );
            }
            if kinematic[j] {
                continue;
            }
            for i in 0..n {
                let fd: f64 = (0..rows)
                    .map(|r| w[r] * (dhp[(r, i)] - dhm[(r, i)]) / (2.0 * step))
                    .sum();
                assert!(
                    (wh[(i, j)] - fd).abs() <= 1e-6,
                    "Σ w D²φ[{i}, {j}] {} vs {fd}",
                    wh[(i, j)]
                );
            }
        }
    }
}

tree_mech::tree_model!(struct SlidingBox from "tests/models/box.toml");

tree_mech::tree_model! {
    /// tests/models/ball.toml in the inline syntax, with a slack string to a fixed hook and
    /// the drop limited, neither reached (a string of 3.5 m from 3 m up): every kind of
    /// contact setting the macro reads, and the same run as the file's.
    struct InlineBall;
    enforce_limits = true;
    frame bx = tx(x) { frame by = ty(y) { frame ball = tz(z) {
        mass = 1.0; inertia = [0.004, 0.004, 0.004];
    } } }
    frame hook = tz(3.0);
    variable z { q0 = 1.1; limits = [-5.0, 5.0]; }
    ground { height = 0.0; normal = [0.0, 0.0, 1.0]; friction = 0.5; }
    contact ball = sphere(ball) { radius = 0.1; collide = true; }
    constraint string = distance(ball, hook) { length = 3.5; slack = true; }
}

/// The compiled step equals the interpreted with contacts in force: per step to 1e-12, over
/// a thousand steps to 1e-9 (the box sliding to rest, and every kind of row at once).
#[test]
fn compiled_contact_steps_equal_interpreted() {
    fn run<S: System>(sys: &mut S, steps: usize) -> Vec<Vec<f64>>
    where
        nalgebra::DefaultAllocator:
            nalgebra::allocator::Allocator<S::N> + nalgebra::allocator::Allocator<S::N, S::N>,
    {
        let (q0, dq0) = sys.initial_state();
        let duration = steps as f64 * 1e-3;
        let traj = simulate(
            sys,
            &q0,
            &dq0,
            &vi(1e-3, duration),
            &mut NoForce,
            &mut |_| {},
        )
        .unwrap();
        (0..traj.len()).map(|k| traj.q(k).to_vec()).collect()
    }
    for (name, a, b) in [
        (
            "box",
            run(&mut SlidingBox, 1000),
            run(
                &mut TreeSystem::new(&load("tests/models/box.toml")).unwrap(),
                1000,
            ),
        ),
        (
            "inline ball",
            run(&mut InlineBall, 1000),
            run(
                &mut TreeSystem::new(&load("tests/models/ball.toml")).unwrap(),
                1000,
            ),
        ),
        (
            "contacts",
            run(&mut Contacts, 1000),
            run(
                &mut TreeSystem::new(&load("tests/models/contacts.toml")).unwrap(),
                1000,
            ),
        ),
    ] {
        let worst = a
            .iter()
            .zip(&b)
            .flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs()))
            .fold(0.0, f64::max);
        let first = a[1]
            .iter()
            .zip(&b[1])
            .map(|(u, v)| (u - v).abs())
            .fold(0.0, f64::max);
        eprintln!("{name}: first step {first:e}, worst {worst:e}");
        assert!(
            first <= 1e-12,
            "{name}: the first step differs by {first:e}"
        );
        assert!(worst <= 1e-9, "{name}: differs by {worst:e}");
    }
}

/// RK4 and rk45 integrate the fall exactly while the ball is in the air (nothing acts), and
/// stop at the step that reaches the ground, naming it and pointing to the VI — never passing
/// through; so does a stepper.
#[test]
fn the_smooth_integrators_run_until_a_gap_closes_then_stop() {
    use tree_mech::integrate::{Stepper, Tolerance};
    let model = load("tests/models/ball.toml");
    let mut sys = TreeSystem::new(&model).unwrap();
    let (q0, dq0) = sys.initial_state();
    let (g, z0, r): (f64, f64, f64) = (9.81, 1.1, 0.1);
    let landing = (2.0 * (z0 - r) / g).sqrt();
    for method in [Method::Rk4, Method::Rk45(Tolerance::default())] {
        let flight = SimOptions::new(method, 1e-3, 0.3);
        let traj = simulate(&mut sys, &q0, &dq0, &flight, &mut NoForce, &mut |_| {}).unwrap();
        let last = traj.len() - 1;
        let z = traj.q(last)[2];
        assert!((z - (z0 - 0.5 * g * 0.09)).abs() < 1e-9, "{z}");
        // Its samples carry the rows' gaps, and no impulse.
        assert!((traj.gap(last)[0] - (z - r)).abs() < 1e-12);
        assert!((0..traj.len()).all(|k| traj.impulse(k).iter().all(|&x| x == 0.0)));
        let options = SimOptions::new(method, 1e-3, 1.0);
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("`ball` closed") && text.contains("only the variational integrator"),
            "{text}"
        );
        let (_, t) = err.when().unwrap();
        // RK4 stops at the step that lands; rk45, whose free fall is exact, at the end of the
        // long step it took through the ground.
        let late = if method == Method::Rk4 { 0.01 } else { 1.0 };
        assert!(
            t >= landing && t < landing + late,
            "stopped at {t}, landing {landing}"
        );
    }
    let mut stepper = Stepper::new(sys, Method::Rk4, 1e-3, q0.as_slice(), dq0.as_slice()).unwrap();
    let mut stopped = None;
    for _ in 0..1000 {
        if let Err(e) = stepper.step(&[]) {
            stopped = Some(e.to_string());
            break;
        }
    }
    assert!(stopped.unwrap().contains("`ball` closed"));
}

mod derivatives {
    use super::*;
    use nalgebra::{DMatrix, Dyn};
    use tree_mech::integrate::{MidpointVi, StepContext, StepDerivatives};
    use tree_mech::runtime::ModelMotions;

    /// A tightly converged step at κ from `(q1, p1)`: `(q₂, p₂)`, and the integrator.
    fn step(
        sys: &mut TreeSystem,
        settings: ViSettings,
        dt: f64,
        q1: &Vector<Dyn>,
        p1: &Vector<Dyn>,
    ) -> (Vector<Dyn>, Vector<Dyn>, MidpointVi<Dyn>) {
        let mut motion = ModelMotions::of(sys);
        let mut vi = MidpointVi::new(sys, settings);
        vi.predict_from_rest();
        let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
        vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
        (q, p, vi)
    }

    fn derivatives(
        sys: &mut TreeSystem,
        settings: ViSettings,
        dt: f64,
        q1: &Vector<Dyn>,
        p1: &Vector<Dyn>,
    ) -> StepDerivatives {
        let (q2, _, mut vi) = step(sys, settings, dt, q1, p1);
        let mut motion = ModelMotions::of(sys);
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
        vi.derivatives(&mut cx, q1, p1, &q2).unwrap()
    }

    /// `∂(q₂, p₂)/∂(q₁, p₁)` against central differences of tightly converged steps at κ,
    /// relative to each block's largest entry.
    fn check(model: &Model, q1: Vec<f64>, dq1: Vec<f64>, kappa: f64, what: &str) {
        let mut sys = TreeSystem::new(model).unwrap();
        let settings = ViSettings {
            kappa,
            tolerance: 1e-14,
            ..ViSettings::default()
        };
        let dt = 1e-3;
        let n = sys.dof();
        let q1 = Vector::<Dyn>::from_vec(q1);
        let dq1 = Vector::<Dyn>::from_vec(dq1);
        let mut vi = MidpointVi::new(&sys, settings);
        let p1 = vi.initial_momentum(&mut sys, &q1, &dq1);
        let d = derivatives(&mut sys, settings, dt, &q1, &p1);
        let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
        let h = 1e-7;
        for (block, by_p) in [("q1", false), ("p1", true)] {
            let columns: Vec<usize> = if by_p {
                dynamic.clone()
            } else {
                (0..n).collect()
            };
            let mut fd_q = DMatrix::zeros(dynamic.len(), columns.len());
            let mut fd_p = DMatrix::zeros(dynamic.len(), columns.len());
            for (c, &j) in columns.iter().enumerate() {
                let (mut qp, mut qm, mut pp, mut pm) =
                    (q1.clone(), q1.clone(), p1.clone(), p1.clone());
                if by_p {
                    pp[j] += h;
                    pm[j] -= h;
                } else {
                    qp[j] += h;
                    qm[j] -= h;
                }
                let (q2p, p2p, _) = step(&mut sys, settings, dt, &qp, &pp);
                let (q2m, p2m, _) = step(&mut sys, settings, dt, &qm, &pm);
                for (r, &i) in dynamic.iter().enumerate() {
                    fd_q[(r, c)] = (q2p[i] - q2m[i]) / (2.0 * h);
                    fd_p[(r, c)] = (p2p[i] - p2m[i]) / (2.0 * h);
                }
            }
            let (aq, ap) = if by_p {
                (&d.q2_dp1, &d.p2_dp1)
            } else {
                (&d.q2_dq1, &d.p2_dq1)
            };
            for (name, exact, fd) in [("q2", aq, &fd_q), ("p2", ap, &fd_p)] {
                let cols = fd.ncols();
                // A block that nearly vanishes (free flight: p₂ hardly sees q₁) is held to 1e-5
                // absolute, the differences' own noise.
                let scale = fd.amax().max(1.0);
                let worst = (0..fd.nrows())
                    .flat_map(|r| (0..cols).map(move |c| (r, c)))
                    .map(|(r, c)| (exact[(r, c)] - fd[(r, c)]).abs())
                    .fold(0.0, f64::max);
                eprintln!("{what}: d{name}/d{block} worst {:e} of {scale:e}", worst);
                assert!(
                    worst <= 1e-5 * scale,
                    "{what}: d{name}/d{block} off by {worst:e} (scale {scale:e})"
                );
            }
        }
    }

    /// Sticking, sliding and separating, with friction, at κ > 0; and every kind of row.
    #[test]
    fn step_derivatives_through_contact_match_differences() {
        let cube = load("tests/models/box.toml");
        let mut q = vec![0.0; cube.dof()];
        q[2] = 0.1;
        let mut sliding = vec![0.0; cube.dof()];
        sliding[0] = 1.0;
        sliding[1] = 0.3;
        check(&cube, q.clone(), sliding, 1e-6, "sliding");
        check(&cube, q.clone(), vec![0.0; cube.dof()], 1e-6, "resting");
        let mut tilted = q.clone();
        tilted[3] = 0.2;
        tilted[4] = 0.1;
        let mut turning = vec![0.0; cube.dof()];
        turning[0] = 0.01;
        turning[5] = 0.5;
        check(&cube, tilted, turning, 1e-6, "rocking");
        let mut above = q.clone();
        above[2] = 0.3;
        check(
            &cube,
            above,
            vec![0.5, 0.0, -0.2, 0.1, 0.0, 0.0],
            1e-6,
            "separated",
        );
        let every = load("tests/models/contacts.toml");
        let q0: Vec<f64> = every.variables.iter().map(|v| v.q0).collect();
        let dq0 = vec![0.3, -0.2, 0.1, 0.2, -0.4, 0.0];
        check(&every, q0, dq0, 1e-6, "every kind");
    }
}

/// A start through the ground is refused naming the contact and the depth; one beyond a limit
/// is moved onto it and said.
#[test]
fn a_start_inside_the_ground_is_refused_and_one_beyond_a_limit_moved() {
    let model = load("tests/models/ball.toml");
    let mut sys = TreeSystem::new(&model).unwrap();
    let (mut q0, dq0) = sys.initial_state();
    q0[2] = 0.05;
    let err = simulate(
        &mut sys,
        &q0,
        &dq0,
        &vi(1e-3, 0.01),
        &mut NoForce,
        &mut |_| {},
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("`ball`") && text.contains("penetrates by 5.000e-2"),
        "{text}"
    );
    let model = load("tests/models/limited-pendulum.toml");
    let mut sys = TreeSystem::new(&model).unwrap();
    let (mut q0, dq0) = sys.initial_state();
    q0[0] = 0.7;
    let mut motion = tree_mech::runtime::ModelMotions::of(&sys);
    let summary = tree_mech::integrate::run(
        &mut sys,
        &q0,
        &dq0,
        &vi(1e-3, 0.01),
        &mut NoForce,
        &mut motion,
        &mut |_| Ok(()),
    )
    .unwrap();
    let moved = &summary.moved[0];
    assert_eq!(
        (moved.variable.as_str(), moved.from, moved.to),
        ("theta", 0.7, 0.5)
    );
}

/// A URDF robot's `<collision><sphere>` elements become contacts when asked: the Go1's four
/// feet (radius 0.02 m each, on the foot links), which then land on the ground a setting adds
/// with no penetration beyond 1e-9 m. A sphere off its link's origin sits on a child frame
/// there; a bad radius is a sentence with its line.
#[test]
fn a_urdf_robot_s_collision_spheres_become_contacts() {
    use tree_mech::model::{ContactsSpec, GroundSpec, UrdfOptions};
    let path = "tests/robots/example-robot-data/go1_description/urdf/go1.urdf";
    let options = UrdfOptions {
        floating_base: true,
        collision_spheres: true,
        ..Default::default()
    };
    let model = model::from_urdf_file(path, options).unwrap();
    let feet: Vec<_> = (model.contacts.spheres.iter())
        .map(|s| (s.name.as_str(), model.frames[s.frame].name.as_str()))
        .collect();
    let expected = ["FR_foot", "FL_foot", "RR_foot", "RL_foot"].map(|f| (f, f));
    assert_eq!(feet, expected, "{feet:?}");
    assert!((model.contacts.spheres.iter()).all(|s| s.radius == 0.02 && !s.collide));
    let plain = UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    assert!((model::from_urdf_file(path, plain).unwrap().contacts.spheres).is_empty());
    let ground = ContactsSpec {
        ground: Some(GroundSpec::default()),
        ..Default::default()
    };
    let model = model.with_contacts(&ground).unwrap();
    let mut sys = TreeSystem::new(&model).unwrap();
    let (mut q0, dq0) = sys.initial_state();
    q0[2] = 0.45; // root_z: the feet some 0.1 m above the ground
    let traj = run_from(&mut sys, &q0, &dq0, 1e-3, 0.25);
    // The ground is frictionless: a foot's row is its gap (no tangent rows), after the 12
    // joints' enforced limits, two rows each.
    assert_eq!(traj.unilateral.len(), 24 + 4);
    let feet: Vec<usize> = (0..traj.unilateral.len())
        .filter(|&r| traj.unilateral[r].ends_with("_foot"))
        .collect();
    assert_eq!(feet.len(), 4, "{:?}", traj.unilateral);
    let deepest = (0..traj.len())
        .flat_map(|k| traj.gap(k).to_vec())
        .fold(f64::INFINITY, f64::min);
    let landed = (0..traj.len()).any(|k| feet.iter().any(|&r| traj.impulse(k)[r] > 0.0));
    assert!(
        deepest > -1e-9 && landed,
        "deepest gap {deepest:e}, landed {landed}"
    );

    // Off the link's origin: a child frame at the offset; a negative radius refused.
    let arm = |collision: &str| {
        format!(
            r#"<robot name="arm"><link name="base"/>
  <link name="upper"><inertial><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    {collision}</link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
</robot>"#
        )
    };
    let text = arm(
        r#"<collision name="tip"><origin xyz="0 0 -0.5"/><geometry><sphere radius="0.05"/></geometry></collision>"#,
    );
    let model = model::from_urdf_str(&text, Some("arm.urdf"), options).unwrap();
    let tip = &model.contacts.spheres[0];
    assert_eq!((tip.name.as_str(), tip.radius), ("tip", 0.05));
    assert_eq!(model.frames[tip.frame].name, "tip#sphere1");
    // Asked of a robot without spheres, or of a TOML model, it is refused, not ignored.
    let none = model::from_urdf_str(&arm(""), Some("arm.urdf"), options).unwrap_err();
    assert!(
        none.to_string().contains("has no <collision><sphere>"),
        "{none}"
    );
    let spheres_only = UrdfOptions {
        collision_spheres: true,
        ..Default::default()
    };
    let toml = model::from_file("tests/models/ball.toml", spheres_only).unwrap_err();
    assert!(
        toml.to_string().contains("read from URDF models only"),
        "{toml}"
    );
    let text = arm(r#"<collision><geometry><sphere radius="-1"/></geometry></collision>"#);
    let err = model::from_urdf_str(&text, Some("arm.urdf"), options)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("arm.urdf:4") && err.contains("radius `-1` is not a finite number ≥ 0"),
        "{err}"
    );
}

/// The marionette over a floor (models/marionette-floor.toml): it hangs from its strings with
/// its feet just above the floor; paid out from t = 1 s, the strings let it down onto its feet
/// and go slack as it collapses — feet, knees, hands and torso on the floor, none through it
/// (1e-9 m), no string ever pushing (its gap never below −1e-9).
#[test]
fn the_marionette_settles_on_the_floor_as_its_strings_are_lowered() {
    let model = load("models/marionette-floor.toml");
    let traj = run(&model, 1e-3, 4.0);
    let rows = &traj.unilateral;
    let row = |name: &str| rows.iter().position(|r| r == name).unwrap();
    let gaps: Vec<usize> = (0..rows.len())
        .filter(|&r| !rows[r].contains(".t"))
        .collect();
    let deepest = (0..traj.len())
        .flat_map(|k| gaps.iter().map(move |&r| (k, r)))
        .map(|(k, r)| traj.gap(k)[r])
        .fold(f64::INFINITY, f64::min);
    assert!(deepest > -1e-9, "deepest gap {deepest:e}");
    let at = |t: f64| ((t / 1e-3).round() as usize).min(traj.len() - 1);
    let strings = [
        "left-shoulder-string",
        "right-shoulder-string",
        "left-hand-string",
    ];
    let feet = ["left_foot", "right_foot"];
    // Hanging: the strings pull, the feet are off the floor.
    let k = at(0.9);
    for s in strings {
        assert!(
            traj.impulse(k)[row(s)] > 0.0 && traj.gap(k)[row(s)] < 1e-9,
            "{s} at 0.9 s"
        );
    }
    for f in feet {
        assert!(traj.gap(k)[row(f)] > 1e-3, "{f} at 0.9 s");
    }
    // Standing: the feet on the floor, the strings still holding it up.
    let k = at(1.3);
    for f in feet {
        assert!(
            traj.gap(k)[row(f)] < 1e-9 && traj.impulse(k)[row(f)] > 0.0,
            "{f} at 1.3 s"
        );
    }
    assert!(traj.impulse(k)[row("left-shoulder-string")] > 0.0);
    // Collapsed: every string slack (no impulse beyond 1e-12 N·s; the puppet's weight is
    // 5e-3 N·s a step), feet, knees, hands and torso on the floor, the torso's
    // centre its radius above it.
    let end = traj.len() - 1;
    for s in strings {
        assert!(
            traj.gap(end)[row(s)] > 0.1 && traj.impulse(end)[row(s)] < 1e-12,
            "{s} at 4 s"
        );
    }
    for side in ["left", "right"] {
        for part in ["foot", "knee", "hand"] {
            let name = format!("{side}_{part}");
            assert!(
                traj.gap(end)[row(&name)].abs() < 1e-9,
                "{name} on the floor at 4 s"
            );
        }
    }
    let floor = model.contacts.ground.unwrap().height;
    assert!(
        (traj.q(end)[2] - (floor + 0.05)).abs() < 1e-9,
        "torso at {}",
        traj.q(end)[2]
    );
}

/// The limp Solo-12 dropped from a crouch onto the ground with spheres at its feet, knees and
/// belly (nine contacts, μ = 0.8, and the 36 pairs between them), at hard contact and at
/// κ = 10⁻⁴ and 10⁻⁶ with Δt = 0.02 s: every step converges (the interior point jammed at
/// t = 0.2 s before its neighbourhood guard, docs/derivations.md §13), and the robot ends on
/// its belly sphere, at hard contact at rest with no penetration.
#[test]
fn a_limp_quadruped_collapses_onto_its_belly_without_a_jam() {
    use tree_mech::model::{ContactSpec, ContactsSpec, GroundSpec, UrdfOptions};
    let options = UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    let robot = model::from_urdf_file("models/solo12.urdf", options).unwrap();
    let sphere = |frame: String, radius: f64| ContactSpec {
        frame,
        radius: Some(radius),
        ..Default::default()
    };
    let mut contacts = vec![sphere("base_link".into(), 0.05)];
    for leg in ["FL", "FR", "HL", "HR"] {
        contacts.push(sphere(format!("{leg}_FOOT"), 0.016));
        contacts.push(sphere(format!("{leg}_LOWER_LEG"), 0.02));
    }
    let spec = ContactsSpec {
        ground: Some(GroundSpec {
            friction: Some(0.8),
            ..Default::default()
        }),
        contacts,
        ..Default::default()
    };
    let model = robot.with_contacts(&spec).unwrap();
    let mut sys = TreeSystem::new(&model).unwrap();
    let (mut q0, dq0) = sys.initial_state();
    // Base 0.1325 m up, hips ±1.2 and knees ∓2.4: crouched, feet on the ground.
    let crouch = [
        0.0, 1.2, -2.4, 0.0, 1.2, -2.4, 0.0, -1.2, 2.4, 0.0, -1.2, 2.4,
    ];
    q0[2] = 0.1325;
    q0.as_mut_slice()[6..].copy_from_slice(&crouch);
    for kappa in [0.0, 1e-4, 1e-6] {
        let settings = ViSettings {
            kappa,
            ..Default::default()
        };
        let options = SimOptions::new(Method::Vi(settings), 0.02, 1.0);
        let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})
            .unwrap_or_else(|e| panic!("κ = {kappa:e}: {e}"));
        let last = traj.len() - 1;
        let height = traj.q(last)[2];
        let speed = traj.dq(last).iter().fold(0.0f64, |a, v| a.max(v.abs()));
        // The gap rows (not the friction rows' tangential positions, `name.t1`, `name.t2`).
        let gaps: Vec<usize> = (0..traj.unilateral.len())
            .filter(|&r| {
                !traj.unilateral[r].ends_with(".t1") && !traj.unilateral[r].ends_with(".t2")
            })
            .collect();
        let deepest = (0..traj.len())
            .flat_map(|k| gaps.iter().map(move |&r| (k, r)))
            .map(|(k, r)| traj.gap(k)[r])
            .fold(f64::INFINITY, f64::min);
        let lost = traj.energy[0] - traj.energy[last];
        println!(
            "κ = {kappa:e}: base at {height}, speed {speed:e}, deepest gap {deepest:e}, \
             {} subdivided steps, energy lost {lost}",
            traj.subdivided_steps
        );
        assert!(
            (height - 0.05).abs() < 2e-3,
            "κ = {kappa:e}: base at {height} m"
        );
        assert!(lost > 1.0, "κ = {kappa:e}: energy lost {lost} J");
        if kappa == 0.0 {
            assert!(deepest > -1e-9 && speed < 1e-6, "{deepest:e}, {speed:e}");
        }
    }
}

/// Resting and sliding contact go by their last mode (tree-runtime `vi/contact/mode.rs`): a
/// ball at rest on the ground (pressing and sticking: its gap and both tangent rows as
/// equations) takes one Newton update a step where the interior point took three, and its
/// impulse is the exact statics, `m g Δt`, its gap zero; the box sliding on four corners
/// (dependent rows; friction on the cone's edge) takes under two a step where the interior
/// point took eight, and still stops where Coulomb says.
#[test]
fn resting_and_sliding_contact_are_solved_in_their_mode() {
    let ball = load("tests/models/ball.toml");
    let mut sys = TreeSystem::new(&ball).unwrap();
    let (mut q0, dq0) = sys.initial_state();
    q0[2] = 0.1;
    let steps = 500;
    let traj = run_from(&mut sys, &q0, &dq0, 1e-3, steps as f64 * 1e-3);
    let per_step = traj.newton_iterations as f64 / steps as f64;
    eprintln!("ball at rest: {per_step} Newton iterations a step");
    assert!(per_step <= 1.1, "{per_step} Newton iterations a step");
    let last = traj.len() - 1;
    let gamma = traj.impulse(last)[0];
    assert!((gamma - 9.81e-3).abs() <= 1e-12 * 9.81e-3, "γ = {gamma}");
    assert!(
        traj.gap(last)[0].abs() <= 1e-12,
        "gap {}",
        traj.gap(last)[0]
    );
    let cube = load("tests/models/box.toml");
    let traj = run(&cube, 1e-3, 0.4);
    let per_step = traj.newton_iterations as f64 / 400.0;
    eprintln!("box sliding: {per_step} Newton iterations a step");
    assert!(per_step <= 2.0, "{per_step} Newton iterations a step");
    let x = traj.q(traj.len() - 1)[0];
    let distance = 1.0 / (2.0 * 0.5 * 9.81);
    assert!((x - distance).abs() <= 1e-6 * distance, "stopped at {x}");
}
