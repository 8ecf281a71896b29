//! Optimal control through contact (docs/derivations.md §14): the cart-pole swung up against
//! its rail's end stops with κ continuation, compiled ≡ interpreted, replayed at hard
//! contact; the cost gradient through an active stop against central differences; DDP takes
//! the Gauss–Newton model through contact; a task's contact settings and their errors; the
//! Solo-12 stands up from a crouch on its feet.

use std::path::Path;

use tree_mech::control::{
    cost_gradient, solve_task, DiscreteSystem, Solution, Solver, TaskCost, TaskOptions, TaskResult,
};
use tree_mech::integrate::ViSettings;
use tree_mech::model::{task_from_str, TaskSolver};
use tree_mech::nalgebra::DVector;
use tree_mech::{tree_model, TreeSystem};

use super::{read, ROOT};

#[path = "../../examples/shared/stand_mpc.rs"]
mod stand_mpc;

tree_model!(struct CartPoleRail from "models/cartpole-rail.toml");

// The Solo-12 with the ground and feet its stand-up task adds, compiled.
tree_model!(struct SoloStand from "models/solo12.urdf", floating_base, contacts from "tasks/solo12-stand.toml");

/// The rail's end stops, m.
const RAIL: f64 = 0.3;

#[test]
fn the_cartpole_swings_up_against_its_rail_stops_and_replays_at_hard_contact() {
    let (task, m) = read("tasks/cartpole-rail.toml");
    assert_eq!(task.kappa, vec![1e-2, 1e-3, 1e-4, 1e-5, 1e-6]);
    let sys = TreeSystem::new(&m).unwrap();
    let res = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {}).unwrap();
    assert!(res.solution.converged, "stopped: {:?}", res.solution.stop);
    // Every stage ran, largest κ first, each iteration recording its own.
    let mut stages: Vec<f64> = res.solution.history.iter().map(|it| it.kappa).collect();
    stages.dedup();
    assert_eq!(stages, task.kappa);
    let n = task.knots;
    let (q, dq) = (&res.q[n], &res.dq[n]);
    assert!(
        q[0].abs() < 0.02 && q[1].abs() < 0.02 && dq.amax() < 0.05,
        "ends at q = {q}, q̇ = {dq}"
    );
    // The optimum uses the stops: the cart sits at an end (within the relaxation's gap) at
    // some knot, and never passes one.
    let reach = res.q.iter().map(|q| q[0].abs()).fold(0.0, f64::max);
    assert!(
        reach > RAIL - 1e-3 && reach <= RAIL,
        "the cart reaches {reach} m"
    );
    for u in &res.solution.u {
        assert!(u[0].abs() <= 20.0 + 1e-12, "push {} beyond ±20 N", u[0]);
    }
    // Replayed open loop at hard contact, it keeps to the plan.
    let replay = res
        .hard_replay
        .as_ref()
        .expect("a contact task is replayed");
    assert!(replay.failure.is_none(), "{:?}", replay.failure);
    assert!(
        replay.deviation < 1e-2,
        "the replay strays {}",
        replay.deviation
    );
    // Its policy (the plan's controls with their feedback) at hard contact keeps closer.
    let policy = res.policy_replay.as_ref().expect("and so is its policy");
    assert!(policy.failure.is_none(), "{:?}", policy.failure);
    assert!(
        policy.deviation < replay.deviation && policy.penetration < 1e-9,
        "the policy strays {}, sinks {}",
        policy.deviation,
        policy.penetration
    );
    assert!(
        replay.penetration <= 1e-6,
        "penetration {}",
        replay.penetration
    );
    // Compiled: the same iterates. A swing-up amplifies the last bits of each contact solve
    // (converged to 1e-12, not bit for bit), so the costs part at 1e-9 after ten iterations and
    // the two solves end at different iteration counts; the first iterations agree.
    let options = TaskOptions {
        max_iterations: Some(8),
        ..TaskOptions::default()
    };
    let mut first = task.clone();
    first.kappa.truncate(1);
    let sys = TreeSystem::new(&m).unwrap();
    let a = solve_task(sys, &first, &m, &options, &mut |_| {}).unwrap();
    let b = solve_task(CartPoleRail, &first, &m, &options, &mut |_| {}).unwrap();
    assert_same_iterates(&a, &b, 8);
}

/// A whole solve through contact, compiled and interpreted: the rail's swing-up, every
/// relaxation to κ = 1e-6, on both paths. Their iterates part at 1e-9 after ten iterations
/// (the swing-up amplifies each contact solve's last bits), and each path then converges to
/// its own local optimum (measured: 362 iterations to cost 0.14796 interpreted, 372 to
/// 0.15476 compiled) — so what both must do is the task: converge, end upright and still,
/// reach a stop without passing it, cost within 10% of each other.
#[test]
fn the_rail_swing_up_converges_compiled_as_interpreted() {
    let (task, m) = read("tasks/cartpole-rail.toml");
    let options = TaskOptions::default();
    let sys = TreeSystem::new(&m).unwrap();
    let a = solve_task(sys, &task, &m, &options, &mut |_| {}).unwrap();
    let b = solve_task(CartPoleRail, &task, &m, &options, &mut |_| {}).unwrap();
    eprintln!(
        "interpreted: {} iterations, cost {}; compiled: {} iterations, cost {}",
        a.solution.history.len(),
        a.solution.cost,
        b.solution.history.len(),
        b.solution.cost
    );
    let n = task.knots;
    for (path, r) in [("interpreted", &a), ("compiled", &b)] {
        assert!(r.solution.converged, "{path}: {:?}", r.solution.stop);
        let (q, dq) = (&r.q[n], &r.dq[n]);
        assert!(
            q[0].abs() < 0.02 && q[1].abs() < 0.02 && dq.amax() < 0.05,
            "{path} ends at q = {q}, q̇ = {dq}"
        );
        let reach = r.q.iter().map(|q| q[0].abs()).fold(0.0, f64::max);
        assert!(
            reach > RAIL - 1e-3 && reach <= RAIL,
            "{path}: reaches {reach} m"
        );
    }
    let (x, y) = (a.solution.cost, b.solution.cost);
    assert!((x - y).abs() <= 0.1 * x, "costs {x} and {y}");
}

/// The Solo-12 rises from a crouch to its base at 0.25 m in 1 s through contact at κ = 1e-6
/// then 1e-7 (tasks/solo12-stand.toml), no contact schedule given: converged; the base ends
/// within 5 mm of its height and level; no foot sinks or moves more than 3 mm over the
/// ground; the torques stay within ±2.7 N·m. The plan's policy (its controls with their
/// feedback) run at hard contact goes through without sinking and ends standing, the feet
/// where they stood. Open loop it cannot: a rising robot is unstable (the summary says so).
#[test]
fn the_solo12_stands_up_from_a_crouch_on_its_feet() {
    let (task, m) = read("tasks/solo12-stand.toml");
    assert_eq!(task.kappa, vec![1e-6, 1e-7]);
    let sys = TreeSystem::new(&m).unwrap();
    let res = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {}).unwrap();
    assert!(res.solution.converged, "stopped: {:?}", res.solution.stop);
    let feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
        .map(|f| m.frames.iter().position(|frame| frame.name == f).unwrap());
    let start = m.origins(res.q[0].as_slice());
    // How far the feet moved over the ground at `q`, and the lowest foot centre.
    let feet_at = |q: &[f64]| {
        let o = m.origins(q);
        let slip = (feet.iter())
            .map(|&f| (o[f][0] - start[f][0]).hypot(o[f][1] - start[f][1]))
            .fold(0.0, f64::max);
        let lowest = feet.iter().map(|&f| o[f][2]).fold(f64::INFINITY, f64::min);
        (slip, lowest)
    };
    let radius = 0.016;
    for (k, q) in res.q.iter().enumerate() {
        let (slip, lowest) = feet_at(q.as_slice());
        assert!(
            slip < 3e-3 && lowest > radius - 1e-6,
            "knot {k}: feet moved {slip} m, lowest at {lowest} m"
        );
    }
    let end = &res.q[task.knots];
    assert!(
        (end[2] - 0.25).abs() < 5e-3 && end[4].abs() < 0.02 && end[5].abs() < 0.02,
        "the base ends at z = {}, pitch {}, roll {}",
        end[2],
        end[4],
        end[5]
    );
    for u in &res.solution.u {
        assert!(u.amax() <= 2.7 + 1e-12, "a torque beyond ±2.7 N·m: {u}");
    }
    let policy = res
        .policy_replay
        .as_ref()
        .expect("a contact task's policy is replayed");
    assert!(policy.failure.is_none(), "{:?}", policy.failure);
    assert!(policy.penetration < 1e-6, "sinks {}", policy.penetration);
    let (slip, lowest) = feet_at(policy.end.as_slice());
    assert!(
        (policy.end[2] - 0.25).abs() < 1e-2 && slip < 5e-3 && lowest > radius - 1e-6,
        "the policy at hard contact ends with the base at {} m, the feet moved {slip} m",
        policy.end[2]
    );
    tracked_by_mpc(&task, &m, &res.solution);
}

/// The stand-up tracked at hard contact by MPC (examples/solo12_mpc.rs): re-planned over
/// 0.1 s from the measured state every 10 ms, one iteration a tick, through a push of 0.5 N·s
/// along x at t = 0.3 s (0.2 m/s to the base) — it ends standing where the plan ends, the feet
/// slid at most 2 cm under the push (11.6 mm measured; 1.6 mm without it), nothing sinking.
/// The offline plan's own policy through the same push does not recover: it leaves the
/// ground (its base ends 0.45 m up, its feet 0.43 m away).
fn tracked_by_mpc(task: &tree_mech::model::Task, m: &tree_mech::model::Model, plan: &Solution) {
    let (planner, plant) = (TreeSystem::new(m).unwrap(), TreeSystem::new(m).unwrap());
    let run = stand_mpc::stand_mpc(planner, plant, task, plan, stand_mpc::PUSH).unwrap();
    assert_eq!(run.tick_seconds.len(), task.knots / stand_mpc::EVERY);
    let ([x, z], slip, lowest) = stand_mpc::outcome(m, &run);
    let end = &plan.x[task.knots];
    assert!(
        run.penetration < 1e-6
            && (z - end[2]).abs() < 5e-3
            && (x - end[0]).abs() < 1e-2
            && slip < 2e-2
            && lowest > 0.016 - 1e-6,
        "MPC: the base ends at x = {x}, z = {z} (the plan's {}, {}), the feet moved {slip} m, the lowest at {lowest} m, penetration {}",
        end[0],
        end[2],
        run.penetration
    );
    let plant = TreeSystem::new(m).unwrap();
    let alone = stand_mpc::policy_only(plant, task, plan, stand_mpc::PUSH).unwrap();
    let ([_, z], slip, _) = stand_mpc::outcome(m, &alone);
    assert!(
        (z - end[2]).abs() > 0.05 || slip > 0.05,
        "the offline policy recovers from the push too: the base ends at z = {z}, the feet moved {slip} m"
    );
}

/// The stand-up compiled (`contacts from` the task file): the same model as the task's, and
/// the same first iterations as the interpreted solve (costs to 1e-10 relative, controls to
/// 1e-8 N·m).
#[test]
fn the_solo12_stand_up_compiled_iterates_as_interpreted() {
    let (task, m) = read("tasks/solo12-stand.toml");
    let compiled = SoloStand::model();
    assert_eq!(compiled.gaps(), m.gaps());
    let options = TaskOptions {
        max_iterations: Some(5),
        ..TaskOptions::default()
    };
    let mut first = task.clone();
    first.kappa.truncate(1);
    let sys = TreeSystem::new(&m).unwrap();
    let a = solve_task(sys, &first, &m, &options, &mut |_| {}).unwrap();
    let b = solve_task(SoloStand, &first, &m, &options, &mut |_| {}).unwrap();
    assert_same_iterates(&a, &b, 5);
}

/// Two solves (interpreted `a`, compiled `b`) take the same `iterations`: each iteration's
/// cost to 1e-10 relative, the controls to 1e-8.
fn assert_same_iterates(a: &TaskResult, b: &TaskResult, iterations: usize) {
    assert_eq!(a.solution.history.len(), iterations);
    for (x, y) in a.solution.history.iter().zip(&b.solution.history) {
        assert!(
            (x.cost - y.cost).abs() < 1e-10 * x.cost,
            "{} vs {}",
            x.cost,
            y.cost
        );
    }
    for (x, y) in a.solution.u.iter().zip(&b.solution.u) {
        assert!((x - y).amax() < 1e-8, "{x} vs {y}");
    }
}

/// The adjoint gradient of the total cost through the rail's stop against central
/// differences of tightly converged steps at κ > 0: pushes that drive the cart into its
/// end and hold it there.
#[test]
fn the_cost_gradient_through_an_active_stop_matches_central_differences() {
    let (mut task, m) = read("tasks/cartpole-rail.toml");
    task.knots = 30;
    let kappa = 1e-3;
    let tight = ViSettings {
        tolerance: 1e-15,
        constraint_tolerance: 1e-15,
        kappa,
        ..ViSettings::default()
    };
    let sys = TreeSystem::new(&m).unwrap();
    let mut dynamics = DiscreteSystem::vi(sys, tight, task.dt, 0.0, task.controls.clone())
        .unwrap()
        .with_input_memory(false);
    let mut cost = TaskCost::new(&task, &m).unwrap();
    let (q0, dq0) = (DVector::from_vec(task.q0.clone()), DVector::zeros(2));
    let x0 = dynamics.state_of(&q0, &dq0, &[]);
    let u: Vec<DVector<f64>> = (0..task.knots)
        .map(|k| {
            DVector::from_element(
                1,
                if k < 20 {
                    15.0
                } else {
                    3.0 * (0.5 * k as f64).sin()
                },
            )
        })
        .collect();
    let (_, gradient) = cost_gradient(&mut dynamics, &mut cost, &x0, &u).unwrap();
    // The cart is held at its stop for part of the run (κ/γ ≈ 3 mm off it: the smooth
    // contact acts at that distance).
    let mut x = x0.clone();
    let mut x2 = DVector::zeros(x.len());
    let mut pressed = 0;
    for (k, uk) in u.iter().enumerate() {
        dynamics
            .step(k, x.as_slice(), uk.as_slice(), x2.as_mut_slice(), None)
            .unwrap();
        pressed += usize::from(x2[0] > RAIL - 5e-3);
        std::mem::swap(&mut x, &mut x2);
    }
    assert!(pressed >= 5, "the cart is at its stop for {pressed} knots");
    // Central differences of steps converged to 1e-15 carry ~1e-11 of the cost's noise over
    // h: they are held to 1e-6 of the gradient's largest entry.
    let h = 1e-5;
    let fd: Vec<f64> = (0..task.knots)
        .map(|k| {
            let mut at = |s: f64| {
                let mut v = u.clone();
                v[k][0] += s;
                cost_gradient(&mut dynamics, &mut cost, &x0, &v).unwrap().0
            };
            (at(h) - at(-h)) / (2.0 * h)
        })
        .collect();
    let largest = fd.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(largest > 1.0, "the test must see a gradient: {largest}");
    for (k, fd) in fd.iter().enumerate() {
        assert!(
            (fd - gradient[k][0]).abs() < 1e-6 * largest,
            "knot {k}: {} against {fd}",
            gradient[k][0]
        );
    }
}

/// DDP's second derivatives are not formed through contact: at κ > 0 every step of a model
/// with unilateral rows goes through it, so every pass is Gauss–Newton (and says so).
#[test]
fn ddp_through_contact_takes_the_gauss_newton_model() {
    let (mut task, m) = read("tasks/cartpole-rail.toml");
    task.kappa = vec![1e-2];
    let options = TaskOptions {
        solver: Some(TaskSolver::Ddp),
        max_iterations: Some(5),
    };
    let sys = TreeSystem::new(&m).unwrap();
    let res = solve_task(sys, &task, &m, &options, &mut |_| {}).unwrap();
    assert_eq!(res.solution.history.len(), 5);
    assert!(res
        .solution
        .history
        .iter()
        .all(|it| it.model == Solver::Ilqr));
    assert!(res.solution.cost < res.solution.history[0].cost * 2.0);
}

/// A task adds a ground, contacts and enforced limits to its model as a model file writes
/// them; κ is named, decreasing, and only where there is contact; each error at its line.
#[test]
fn a_task_says_where_contact_is_and_its_relaxations() {
    let base = Path::new(ROOT).join("models");
    let head = "model = \"cartpole.toml\"\ndt = 0.02\nknots = 10\n";
    let cost = "[[cost]]\nkind = \"control\"\nweight = 1.0\n";
    let ground =
        "[ground]\nheight = -0.6\nfriction = 0.5\n[[contact]]\nframe = \"pole\"\nradius = 0.05\n";
    let text = format!("{head}kappa = [1e-3, 1e-5]\n{cost}{ground}");
    let (task, m) = task_from_str(&text, Some("t.toml"), &base).unwrap();
    assert_eq!(task.kappa, vec![1e-3, 1e-5]);
    // The pole's sphere on the ground, with the ground's friction.
    assert_eq!(m.gaps().len(), 1);
    assert_eq!(m.gaps()[0].friction, 0.5);
    let cases = [
        (
            format!("{head}{cost}{ground}"),
            "name the relaxations the optimiser goes through",
        ),
        (
            format!("{head}kappa = 1e-3\n{cost}"),
            "t.toml:4: `kappa` relaxes unilateral rows, and the model has none",
        ),
        (
            format!("{head}kappa = [1e-3, 1e-2]\n{cost}{ground}"),
            "t.toml:4: `kappa` must decrease: entry 2",
        ),
        (
            format!("{head}kappa = [1e-3, -1.0]\n{cost}{ground}"),
            "`kappa` entry 2 must be a positive number",
        ),
        (
            format!("{head}integrator = \"rk4\"\nkappa = 1e-3\n{cost}{ground}"),
            "t.toml:4: a task through contact steps with the VI",
        ),
        (
            format!("{head}kappa = 1e-3\n{cost}[[contact]]\nframe = \"hand\"\n"),
            "t.toml:9: contact `contact1`: unknown frame `hand`",
        ),
        (
            format!(
                "{head}kappa = 1e-3\n{cost}{ground}[[contact]]\nframe = \"cart\"\nradius = -1.0\n"
            ),
            "t.toml:16: contact `contact2`: radius -1",
        ),
    ];
    for (text, want) in cases {
        let err = task_from_str(&text, Some("t.toml"), &base)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(want),
            "expected «{want}» in «{err}» for\n{text}"
        );
    }
}

/// A URDF robot's limits are enforced by default, so a task on it names its relaxations or
/// says `enforce_limits = false` — and the message offers both; a system whose unilateral
/// rows are not the task's model's (compiled without the task's setting) is refused.
#[test]
fn a_task_on_a_limited_robot_says_how_to_go_on_and_its_system_must_match() {
    let base = Path::new(ROOT).join("tasks");
    let reach = std::fs::read_to_string(base.join("ur5-reach.toml")).unwrap();
    let enforced = reach.replace("enforce_limits = false", "enforce_limits = true");
    assert_ne!(enforced, reach);
    let err = task_from_str(&enforced, Some("t.toml"), &base)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("the model has 12 unilateral rows")
            && err.contains(
                "or plan without enforcing its 12 joint limits (`enforce_limits = false`)"
            ),
        "{err}"
    );
    let (task, m) = task_from_str(&reach, Some("t.toml"), &base).unwrap();
    assert!(m.gaps().is_empty());
    let mut limited = m.clone();
    limited.contacts.enforce_limits = true;
    let sys = TreeSystem::new(&limited).unwrap();
    let err = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("the system has 12 unilateral elements")
            && err.contains("but the task's model has 0"),
        "{err}"
    );
}
