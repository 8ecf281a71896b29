//! Optimal-control tasks: every cost term's exact gradient (through the VI and RK4, with
//! inputs and kinematic controls, a constraint, damping and a spring) against central
//! differences of the total cost; the shipped tasks reach what they promise (the cart-pole
//! upright and then held there by LQR, the UR5's tool within 1 mm), compiled ≡ interpreted;
//! every task-file error named with its line.

use std::path::Path;

use tree_mech::control::{
    cost_gradient, dare, solve_task, BoxPhase, Control, DiscreteSystem, Solver, TaskCost,
    TaskOptions, TaskResult,
};
use tree_mech::integrate::ViSettings;
use tree_mech::model::{self, task_from_str};
use tree_mech::nalgebra::{DMatrix, DVector};
use tree_mech::{tree_model, System, TreeSystem};

#[path = "tasks/contact.rs"]
mod contact;

tree_model!(struct CartPole from "models/cartpole.toml");

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A task on tests/models/trep-vi.toml using every kind of term (`control_rate` only with
/// `rate`).
fn every_term(controls: &str, integrator: &str, rate: bool) -> String {
    let rate = if rate {
        "[[cost]]\nkind = \"control_rate\"\nweight = 0.001"
    } else {
        ""
    };
    format!(
        r#"
model = "trep-vi.toml"
dt = 0.02
knots = 12
integrator = "{integrator}"
controls = {controls}

[[cost]]
kind = "state"
q_weight = [1.0, 2.0, 0.5, 0.0]
dq_weight = {{ slide = 0.3, theta1 = 0.2, theta2 = 0.1 }}
q_ref = {{ theta1 = 0.2 }}

[[cost]]
kind = "control"
weight = 0.05
about = "gravity"

{rate}

[[cost]]
kind = "frame"
frame = "tip"
target = [0.1, 0.2, -0.9]
weight = [3.0, 2.0, 1.0]

[[cost]]
kind = "orientation"
frame = "upper"
rpy = [0.3, 0.0, 0.1]
weight = 1.5

[[terminal]]
kind = "frame"
frame = "tip"
offset = [0.0, 0.1, 0.05]
weight = 50.0

[[terminal]]
kind = "orientation"
frame = "elbow"
weight = [1.0, 2.0, 3.0]

[[terminal]]
kind = "state"
q_weight = 0.0
dq_weight = 5.0
"#
    )
}

/// The adjoint gradient of the total cost against central differences; without `rate`, the
/// state leaves the inputs' memory out (a kinematic control's memory then sits right after
/// the momenta).
fn gradient_matches(controls: &str, integrator: &str, rate: bool) {
    let base = Path::new(ROOT).join("tests/models");
    let text = every_term(controls, integrator, rate);
    let (task, model) = task_from_str(&text, None, &base).unwrap();
    let sys = TreeSystem::new(&model).unwrap();
    let tight = ViSettings {
        tolerance: 1e-15,
        constraint_tolerance: 1e-15,
        ..ViSettings::default()
    };
    let mut dynamics = match integrator {
        "vi" => DiscreteSystem::vi(sys, tight, task.dt, 0.0, task.controls.clone()).unwrap(),
        _ => DiscreteSystem::rk4(sys, task.dt, 0.0, task.controls.clone()).unwrap(),
    }
    .with_input_memory(rate);
    let mut cost = TaskCost::new(&task, &model).unwrap();
    let q0 = DVector::from_column_slice(&task.q0);
    let dq0 = DVector::from_column_slice(&task.dq0);
    let nu = task.controls.len();
    let x0 = dynamics.state_of(&q0, &dq0, &vec![0.1; nu]);
    // Controls that move: a torque and the hand around its start.
    let u: Vec<DVector<f64>> = (0..task.knots)
        .map(|k| {
            DVector::from_fn(nu, |c, _| match task.controls[c] {
                Control::Input(_) => 0.5 * (0.7 * k as f64).sin(),
                Control::Kinematic(i) => task.q0[i] + 0.02 * k as f64,
            })
        })
        .collect();
    let (total, gradient) = cost_gradient(&mut dynamics, &mut cost, &x0, &u).unwrap();
    assert!(total > 0.0);
    let h = 1e-6;
    let mut largest = 0.0f64;
    for k in 0..u.len() {
        for c in 0..nu {
            let mut at = |s: f64| {
                let mut v = u.clone();
                v[k][c] += s;
                cost_gradient(&mut dynamics, &mut cost, &x0, &v).unwrap().0
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            let scale = fd.abs().max(1e-2);
            assert!(
                (fd - gradient[k][c]).abs() < 1e-6 * scale,
                "{integrator}, knot {k}, control {c}: {} vs {fd}",
                gradient[k][c]
            );
            largest = largest.max(fd.abs());
        }
    }
    assert!(largest > 1e-2, "the test must see a gradient: {largest}");
}

#[test]
fn every_cost_term_has_its_exact_gradient_through_the_vi_with_a_kinematic_control() {
    gradient_matches(r#"["torque", "hand_y"]"#, "vi", true);
}

#[test]
fn without_the_inputs_memory_every_other_term_keeps_its_exact_gradient() {
    gradient_matches(r#"["torque", "hand_y"]"#, "vi", false);
    gradient_matches(r#"["torque"]"#, "rk4", false);
}

/// A `control_rate` term on an input needs the state to remember it: refused, not read as 0.
#[test]
fn a_rate_cost_on_a_system_that_forgets_its_inputs_is_refused() {
    let base = Path::new(ROOT).join("tests/models");
    let text = every_term(r#"["torque"]"#, "vi", true);
    let (task, model) = task_from_str(&text, None, &base).unwrap();
    let sys = TreeSystem::new(&model).unwrap();
    let mut dynamics = DiscreteSystem::vi(
        sys,
        ViSettings::default(),
        task.dt,
        0.0,
        task.controls.clone(),
    )
    .unwrap()
    .with_input_memory(false);
    let mut cost = TaskCost::new(&task, &model).unwrap();
    let q0 = DVector::from_column_slice(&task.q0);
    let dq0 = DVector::from_column_slice(&task.dq0);
    let x0 = dynamics.state_of(&q0, &dq0, &[]);
    let u = vec![DVector::zeros(1); task.knots];
    let err = cost_gradient(&mut dynamics, &mut cost, &x0, &u)
        .unwrap_err()
        .to_string();
    assert!(err.contains("does not remember"), "{err}");
}

#[test]
fn every_cost_term_has_its_exact_gradient_through_rk4() {
    gradient_matches(r#"["torque"]"#, "rk4", true);
}

/// `task` solved on `m` interpreted.
fn interpreted(task: &model::Task, m: &model::Model, options: &TaskOptions) -> TaskResult {
    solve_task(TreeSystem::new(m).unwrap(), task, m, options, &mut |_| {}).unwrap()
}

fn read(task: &str) -> (model::Task, model::Model) {
    model::read_task(Path::new(ROOT).join(task)).unwrap()
}

#[test]
fn the_cartpole_swings_up_and_lqr_holds_it_there() {
    let (task, m) = read("tasks/cartpole-swingup.toml");
    let sys = TreeSystem::new(&m).unwrap();
    let res = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {}).unwrap();
    assert!(res.solution.converged);
    let n = task.knots;
    let (q, dq) = (&res.q[n], &res.dq[n]);
    assert!(
        q[0].abs() < 0.02 && q[1].abs() < 0.02 && dq.amax() < 0.05,
        "ends at q = {q}, q̇ = {dq}"
    );
    for u in &res.solution.u {
        assert!(u[0].abs() <= 20.0 + 1e-12, "push {} beyond ±20 N", u[0]);
    }
    // Compiled: the same iterates.
    let compiled = solve_task(CartPole, &task, &m, &TaskOptions::default(), &mut |_| {}).unwrap();
    assert_eq!(compiled.solution.history.len(), res.solution.history.len());
    for (a, b) in compiled.solution.u.iter().zip(&res.solution.u) {
        assert!((a - b).amax() < 1e-9, "{a} vs {b}");
    }
    // LQR at the top from where the plan ends (the task's state: no input memory, as no
    // `control_rate` term reads it): it stays upright for 4 s.
    let mut dynamics = DiscreteSystem::new(
        TreeSystem::new(&m).unwrap(),
        ViSettings::default(),
        task.dt,
        0.0,
    )
    .unwrap()
    .with_input_memory(false);
    let (mut a, mut b) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
    let mut x2 = [0.0; 4];
    dynamics
        .step(0, &[0.0; 4], &[0.0], &mut x2, Some((&mut a, &mut b)))
        .unwrap();
    let qw = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 10.0, 0.1, 0.1]));
    let lqr = dare(&a, &b, &qw, &(DMatrix::identity(1, 1) * 0.1)).unwrap();
    let mut x = res.solution.x[n].clone();
    for k in 0..200 {
        let u = (-(&lqr.k * &x)[0]).clamp(-20.0, 20.0);
        dynamics.step(k, x.as_slice(), &[u], &mut x2, None).unwrap();
        x.copy_from_slice(&x2);
        assert!(x[1].abs() < 0.05, "the pole fell to {} at step {k}", x[1]);
    }
    assert!(x[1].abs() < 1e-3 && x[0].abs() < 1e-2, "held at {x}");
}

/// Solves a shipped reach interpreted and holds it to its task and to Crocoddyl 3.2.1's
/// solution of the same problem (symplectic Euler instead of the VI; `fixture` written by
/// tools/reference/crocoddyl_reach.py): the tool within 1 mm of its target and at rest, the
/// same optimum within 1%, the tool at the same place within 0.1 mm. Returns the solve.
fn reach_agrees_with_crocoddyl(task_file: &str, fixture: &str) -> (model::Task, TaskResult) {
    let (task, m) = read(task_file);
    let res = interpreted(&task, &m, &TaskOptions::default());
    let f = m.frame_index("ee_link").unwrap();
    let start = m.origins(&task.q0)[f];
    let end = m.origins(res.q[task.knots].as_slice())[f];
    let target = [start[0] + 0.1, start[1], start[2] + 0.2];
    let distance =
        |a: [f64; 3], b: &[f64]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let miss = distance(end, &target);
    assert!(miss < 1e-3, "the tool misses its target by {miss} m");
    assert!(
        res.dq[task.knots].amax() < 0.05,
        "not at rest: {}",
        res.dq[task.knots]
    );
    let path = Path::new(ROOT).join("tests/fixtures").join(fixture);
    let croc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let theirs = croc["cost"].as_f64().unwrap();
    let ours = res.solution.cost;
    assert!(
        (ours - theirs).abs() < 0.01 * theirs,
        "cost {ours} against Crocoddyl's {theirs}"
    );
    let their_end: Vec<f64> = croc["ee_final"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let apart = distance(end, &their_end);
    assert!(apart < 1e-4, "the tools end {apart} m apart");
    (task, res)
}

/// The UR5 within its effort limits, against Crocoddyl's box-FDDP.
#[test]
fn the_ur5_reaches_within_a_millimetre() {
    let (task, res) = reach_agrees_with_crocoddyl("tasks/ur5-reach.toml", "crocoddyl-reach.json");
    // The limits bind far from the optimum only: clamped in the forward pass until the steps
    // shorten, the solve takes a handful of iterations (63 with the box QP from the start,
    // Crocoddyl's box-FDDP 27; docs/derivations.md §10, "Limits in two phases").
    let iterations = res.solution.history.len();
    assert!(iterations <= 12, "{iterations} iterations");
    for u in &res.solution.u {
        for (c, v) in u.iter().enumerate() {
            let [lo, hi] = task.limits[c].unwrap();
            assert!((lo..=hi).contains(v), "torque {v} beyond [{lo}, {hi}]");
        }
    }
}

/// The UR10 without limits (`model_limits = false` drops its URDF's effort limits), against
/// Crocoddyl's plain FDDP, where Crocoddyl is at its best.
#[test]
fn the_ur10_reaches_without_limits_as_crocoddyl_does() {
    let (task, res) =
        reach_agrees_with_crocoddyl("tasks/ur10-reach.toml", "crocoddyl-reach-ur10.json");
    assert!(task.limits.iter().all(Option::is_none), "{:?}", task.limits);
    // Without the flag the limits are the URDF's; a limit the file gives still holds.
    let text = std::fs::read_to_string(Path::new(ROOT).join("tasks/ur10-reach.toml")).unwrap();
    let base = Path::new(ROOT).join("tasks");
    let (limited, _) =
        model::task_from_str(&text.replace("model_limits = false", ""), None, &base).unwrap();
    assert_eq!(limited.limits[0], Some([-330.0, 330.0]));
    let (one, _) = model::task_from_str(
        &format!("{text}\n[limits]\nelbow_joint = [-90.0, 90.0]\n"),
        None,
        &base,
    )
    .unwrap();
    assert_eq!(one.limits[0], None);
    assert_eq!(one.limits[2], Some([-90.0, 90.0]));
    let iterations = res.solution.history.len();
    assert!(iterations <= 8, "{iterations} iterations");
}

/// DDP on the shipped reach converges to iLQR's optimum in a handful of iterations: where its
/// full model is indefinite (far from the optimum) a pass takes the Gauss–Newton one instead
/// of a regularisation large enough to hide it (without that: 65 iterations, not converged).
#[test]
fn ddp_converges_on_the_reach_to_the_ilqr_optimum() {
    let (task, m) = read("tasks/ur5-reach.toml");
    let ddp = TaskOptions {
        solver: Some(model::TaskSolver::Ddp),
        ..TaskOptions::default()
    };
    let res = interpreted(&task, &m, &ddp);
    let ilqr = interpreted(&task, &m, &TaskOptions::default());
    let iterations = res.solution.history.len();
    assert!(
        res.solution.converged,
        "not converged in {iterations} iterations"
    );
    assert!(iterations <= 12, "{iterations} iterations");
    let (a, b) = (res.solution.cost, ilqr.solution.cost);
    assert!(
        (a - b).abs() < 1e-6 * b,
        "DDP's cost {a} against iLQR's {b}"
    );
    // Each iteration says which model its pass used: Gauss–Newton far from the optimum, the
    // full one near it; and how it took the UR5's effort limits (clamped from the guess).
    let history = &res.solution.history;
    assert_eq!(history[0].model, Solver::Ilqr);
    assert_eq!(history[iterations - 1].model, Solver::Ddp);
    assert_eq!(history[0].limits, Some(BoxPhase::Clamped));
    assert!(ilqr
        .solution
        .history
        .iter()
        .all(|it| it.model == Solver::Ilqr));
}

/// Every mistake in a task file is a sentence with its line.
#[test]
fn task_file_errors_name_the_problem_and_line() {
    let base = Path::new(ROOT).join("tests/models");
    let good = "model = \"trep-vi.toml\"\ndt = 0.02\nknots = 10\n";
    let cost = "[[cost]]\nkind = \"control\"\nweight = 1.0\n";
    let cases: &[(&str, &str)] = &[
        ("model = \"missing.toml\"\ndt = 0.1\nknots = 3\n", "t.toml:1: the task's model"),
        ("model = \"trep-vi.toml\"\ndt = -0.1\nknots = 3\n[[terminal]]\nkind = \"state\"\nq_weight = 1.0\n", "t.toml:2: `dt` must be positive"),
        ("model = \"trep-vi.toml\"\ndt = 0.1\nknots = 0\n[[terminal]]\nkind = \"state\"\nq_weight = 1.0\n", "t.toml:3: `knots` must be between"),
        (&format!("{good}controls = [\"torque\", \"nope\"]\n{cost}"), "t.toml:4: control `nope` is neither an input nor a variable"),
        (&format!("{good}controls = [\"theta1\"]\n{cost}"), "t.toml:4: control `theta1` is a dynamic variable with no input"),
        (&format!("{good}controls = [\"torque\", \"torque\"]\n{cost}"), "listed twice"),
        (&format!("{good}integrator = \"rk4\"\ncontrols = [\"hand_y\"]\n{cost}"), "kinematic control `hand_y` needs the VI"),
        (&format!("{good}integrator = \"euler\"\n{cost}"), "t.toml:4: `integrator` is `euler`"),
        (&format!("{good}[[cost]]\nkind = \"frame\"\nframe = \"nowhere\"\ntarget = [0.0, 0.0, 0.0]\nweight = 1.0\n"), "t.toml:6: frame `nowhere` is not in the model"),
        // A typo is offered its fix first.
        (&format!("{good}[[cost]]\nkind = \"frame\"\nframe = \"hnad\"\ntarget = [0.0, 0.0, 0.0]\nweight = 1.0\n"), "frame `hnad` is not in the model; the nearest of its 7 names are `hand`"),
        (&format!("{good}[[cost]]\nkind = \"state\"\nq_weight = [1.0, 2.0]\n"), "t.toml:6: `q_weight` has 2 entries; it needs 4"),
        (&format!("{good}[[cost]]\nkind = \"state\"\nq_weight = {{ theta9 = 1.0 }}\n"), "names `theta9`, which is not one of"),
        (&format!("{good}[[cost]]\nkind = \"control\"\nweight = -1.0\n"), "t.toml:6: `weight` must not be negative"),
        (&format!("{good}[[cost]]\nkind = \"spin\"\n"), "t.toml:5: cost kind `spin` is unknown"),
        (&format!("{good}[[cost]]\nkind = \"control\"\nweight = 1.0\nframe = \"tip\"\n"), "a `control` term takes no `frame`"),
        (&format!("{good}[[terminal]]\nkind = \"control\"\nweight = 1.0\n"), "can only be a running cost"),
        (&format!("{good}[[cost]]\nkind = \"frame\"\nframe = \"tip\"\nweight = 1.0\n"), "exactly one of `offset` and `target`"),
        (&format!("{good}[[cost]]\nkind = \"control\"\nabout = \"up\"\nweight = 1.0\n"), "`about` is `up`"),
        (&format!("{good}{cost}[limits]\nslide = [-1.0, 1.0]\n"), "limits are given for `slide`, which is not a control"),
        (&format!("{good}{cost}[limits]\ntorque = [1.0, -1.0]\n"), "t.toml:8: the limits of `torque` must be [lo, hi]"),
        (&format!("{good}controls = [\"hand_y\"]\n{cost}[limits]\nhand_y = [0.5, 1.0]\n"), "t.toml:9: the limits [0.5, 1] of `hand_y` exclude its start value 0.1"),
        (good, "the task has no cost"),
        (&format!("{good}colour = 3\n{cost}"), "t.toml:4: TOML error: unknown field `colour`"),
        (&format!("{good}[start]\nq = [0.0]\n{cost}"), "t.toml:5: `start.q` has 1 entry; it needs 4"),
    ];
    for (text, want) in cases {
        let err = task_from_str(text, Some("t.toml"), &base)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(want),
            "expected «{want}» in «{err}» for\n{text}"
        );
    }
    // Limits that cannot hold the start against gravity (5.6 N·m): found when solving.
    let text = "model = \"trep-vi.toml\"\ndt = 0.02\nknots = 5\n[[cost]]\nkind = \"control\"\nweight = 1.0\n[limits]\ntorque = [10.0, 11.0]\n";
    let (task, m) = task_from_str(text, Some("t.toml"), &base).unwrap();
    let sys = TreeSystem::new(&m).unwrap();
    let err = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("(line 8) exclude the") && err.contains("holds the start against gravity"),
        "{err}"
    );
}

#[test]
fn the_marionette_raises_its_hand_by_its_strings_alone_every_string_taut() {
    let (task, m) = read("tasks/marionette-wave.toml");
    assert_eq!(task.controls.len(), 18);
    assert!(task
        .controls
        .iter()
        .all(|c| matches!(c, Control::Kinematic(_))));
    let sys = TreeSystem::new(&m).unwrap();
    let res = solve_task(sys, &task, &m, &TaskOptions::default(), &mut |_| {}).unwrap();
    let f = m.frame_index("right_hand").unwrap();
    let start = m.origins(&task.q0)[f];
    let end = m.origins(res.q[task.knots].as_slice())[f];
    let target = [start[0], start[1], start[2] + 0.15];
    let miss = (0..3)
        .map(|i| (end[i] - target[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(miss < 0.01, "the hand misses its target by {miss} m");
    for (k, lambda) in res.lambda.iter().enumerate() {
        assert!(
            lambda.iter().all(|l| *l < 0.0),
            "a string went slack at knot {k}: λ = {lambda}"
        );
    }
}

/// DDP's contracted second derivatives of one discrete step, read onto `(x, u)` — with an
/// input, a kinematic control (its memory columns) and a string constraint — against central
/// differences of `Aᵀv` and `Bᵀv`.
#[test]
fn the_contracted_step_hessian_matches_differences_of_the_jacobians() {
    let path = Path::new(ROOT).join("tests/models/trep-vi.toml");
    let m = model::from_toml_file(path).unwrap();
    let hand = m.variable_index("hand_y").unwrap();
    let controls = vec![Control::Input(0), Control::Kinematic(hand)];
    let tight = ViSettings {
        tolerance: 1e-15,
        constraint_tolerance: 1e-15,
        ..ViSettings::default()
    };
    let mut d =
        DiscreteSystem::vi(TreeSystem::new(&m).unwrap(), tight, 0.02, 0.0, controls).unwrap();
    let (q0, dq0) = d.sys.initial_state();
    // A knot after one step (the start is not on the string: its first step jumps).
    let x0 = d.state_of(&q0, &dq0, &[0.2, 0.0]);
    let mut x = vec![0.0; x0.len()];
    d.step(0, x0.as_slice(), &[0.2, 0.12], &mut x, None)
        .unwrap();
    let (nx, nu) = (x.len(), 2);
    let u = [0.4, 0.15];
    let v: Vec<f64> = (0..nx).map(|i| 0.3 + 0.1 * i as f64).collect();
    let (mut hxx, mut huu, mut hux) = (
        DMatrix::zeros(nx, nx),
        DMatrix::zeros(nu, nu),
        DMatrix::zeros(nu, nx),
    );
    let mut x2 = vec![0.0; nx];
    let formed = d.contracted(1, &x, &u, &v, &mut x2, &mut hxx, &mut huu, &mut hux);
    assert!(formed.unwrap(), "a smooth step's curvature is formed");
    // Aᵀv and Bᵀv at (x, u).
    let mut jv = |x: &[f64], u: &[f64]| {
        let (mut a, mut b) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
        let mut x2 = vec![0.0; nx];
        d.step(1, x, u, &mut x2, Some((&mut a, &mut b))).unwrap();
        let v = DVector::from_column_slice(&v);
        (a.tr_mul(&v), b.tr_mul(&v))
    };
    let h = 1e-6;
    let scale = hxx.amax().max(huu.amax()).max(hux.amax());
    let close = |fd: f64, ours: f64, what: &str| {
        assert!(
            (fd - ours).abs() < 1e-6 * scale,
            "{what}: {ours} vs {fd} (scale {scale})"
        );
    };
    for c in 0..nx {
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[c] += h;
        xm[c] -= h;
        let ((ap, bp), (am, bm)) = (jv(&xp, &u), jv(&xm, &u));
        for r in 0..nx {
            close(
                (ap[r] - am[r]) / (2.0 * h),
                hxx[(r, c)],
                &format!("hxx[{r}, {c}]"),
            );
        }
        for a in 0..nu {
            close(
                (bp[a] - bm[a]) / (2.0 * h),
                hux[(a, c)],
                &format!("hux[{a}, {c}]"),
            );
        }
    }
    for c in 0..nu {
        let (mut up, mut um) = (u, u);
        up[c] += h;
        um[c] -= h;
        let ((_, bp), (_, bm)) = (jv(&x, &up), jv(&x, &um));
        for a in 0..nu {
            close(
                (bp[a] - bm[a]) / (2.0 * h),
                huu[(a, c)],
                &format!("huu[{a}, {c}]"),
            );
        }
    }
    // A, B at a known converged step (the optimiser's path after a line search) equal the
    // step's own.
    let (mut a1, mut b1) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    let mut stepped = vec![0.0; nx];
    d.step(1, &x, &u, &mut stepped, Some((&mut a1, &mut b1)))
        .unwrap();
    let lambda = d.multipliers().to_vec();
    let (mut a2, mut b2) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    d.jacobians(1, &x, &u, &mut stepped, &lambda, &mut a2, &mut b2)
        .unwrap();
    assert!((&a1 - &a2).amax() < 1e-10 * a1.amax() && (&b1 - &b2).amax() < 1e-10 * b1.amax());
    assert!(
        b1.column(1).amax() > 0.1,
        "the kinematic control moves the step"
    );
    // The kinematic control's value column and its decision carry curvature: the test sees
    // the column map.
    let memory = nx - 2;
    assert!(hxx.column(memory).amax() > 1e-3 * scale && huu[(1, 1)].abs() > 1e-3 * scale);
}

/// The trajectory read back reports the constraint violation at each knot: the start is
/// off the string by what the frames say, every later knot on it.
#[test]
fn a_solved_task_reports_the_constraint_violation_at_every_knot() {
    let base = Path::new(ROOT).join("tests/models");
    let text = "model = \"trep-vi.toml\"\ndt = 0.02\nknots = 5\n[[cost]]\nkind = \"control\"\nweight = 1.0\n";
    let (task, m) = task_from_str(text, None, &base).unwrap();
    let res = interpreted(&task, &m, &TaskOptions::default());
    let origins = m.origins(&task.q0);
    let (tip, hand) = (
        m.frame_index("tip").unwrap(),
        m.frame_index("hand_point").unwrap(),
    );
    let d2: f64 = (0..3)
        .map(|i| (origins[tip][i] - origins[hand][i]).powi(2))
        .sum();
    let h0 = (d2 - 0.6 * 0.6).abs();
    assert!(
        h0 > 1e-3,
        "the start must be off the string for this test: {h0}"
    );
    assert!(
        (res.violation[0] - h0).abs() < 1e-9 * h0,
        "{} vs {h0}",
        res.violation[0]
    );
    for (k, v) in res.violation.iter().enumerate().skip(1) {
        assert!(*v < 1e-8, "knot {k} is off the string by {v}");
    }
}
