//! Inputs `u`: generalized forces on dynamic variables, `B u`, from TOML, URDF and the inline
//! macro, held constant over each step, in every integrator, on both paths.

mod common;

use tree_mech::integrate::{
    run_with_inputs, InputSchedule, Method, SimOptions, Stepper, ViSettings,
};
use tree_mech::model::{self, Model};
use tree_mech::runtime::ModelMotions;
use tree_mech::{tree_model, NoForce, System, TreeSystem};

tree_model!(struct Cart from "tests/models/cart.toml");

tree_model! {
    struct Slider;
    frame slide = tx(x) { mass = 2.0; }
    variable x { q0 = 0.0; }
    input push = x { limits = [-5.0, 5.0]; }
}

fn cart() -> Model {
    model::from_toml_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/models/cart.toml"
    ))
    .unwrap()
}

/// A recorded sample: `(t, q, q̇, E)`.
type Recorded = (f64, Vec<f64>, Vec<f64>, f64);

/// Every sample of a run of `sys` from its start at Δt = 0.01 with `inputs`.
fn run<S: System>(
    sys: &mut S,
    method: Method,
    duration: f64,
    inputs: &InputSchedule,
) -> Vec<Recorded>
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(method, 0.01, duration);
    let mut motion = ModelMotions::of(sys);
    let mut out = Vec::new();
    run_with_inputs(
        sys,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut motion,
        inputs,
        &mut |s| {
            out.push((s.t, s.q.to_vec(), s.dq.to_vec(), s.energy));
            Ok(())
        },
    )
    .unwrap();
    out
}

/// The final q of a run with `inputs`.
fn final_q<S: System>(
    sys: &mut S,
    method: Method,
    duration: f64,
    inputs: &InputSchedule,
) -> Vec<f64>
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    run(sys, method, duration, inputs).pop().unwrap().1
}

#[test]
fn a_constant_push_accelerates_a_free_mass_by_f_over_m() {
    // x(t) = ½ (F/m) t² exactly for the VI (a constant force) and RK4: F = 3 N on 2 kg.
    let push = InputSchedule::constant(vec![3.0]);
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let x = final_q(&mut Slider, method, 1.0, &push)[0];
        assert!((x - 0.75).abs() < 1e-9, "{method:?}: x = {x}");
        let mut interpreted = TreeSystem::new(&Slider::model()).unwrap();
        let y = final_q(&mut interpreted, method, 1.0, &push)[0];
        assert!((x - y).abs() < 1e-12, "compiled {x} vs interpreted {y}");
    }
    assert_eq!(Slider::INPUTS, ["push"]);
    assert_eq!(Slider::INPUT_VARIABLES, [Slider::X]);
    assert_eq!(Slider::model().inputs[0].limits, Some([-5.0, 5.0]));
}

#[test]
fn inputs_are_held_over_each_step_and_switch_at_their_rows() {
    // +3 N for 0.5 s then −3 N: x(1) = ½·1.5·0.25 + (0.75·0.5 − ½·1.5·0.25) = 0.375.
    let schedule = InputSchedule::from_rows(vec![(0.0, vec![3.0]), (0.5, vec![-3.0])]).unwrap();
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let x = final_q(&mut Slider, method, 1.0, &schedule)[0];
        assert!((x - 0.375).abs() < 1e-9, "{method:?}: x = {x}");
    }
    // Bad schedules are refused.
    assert!(InputSchedule::from_rows(vec![(0.0, vec![1.0]), (0.0, vec![2.0])]).is_err());
    assert!(InputSchedule::from_rows(vec![(0.0, vec![1.0]), (1.0, vec![2.0, 3.0])]).is_err());
}

#[test]
fn the_cart_is_pushed_the_same_compiled_and_interpreted() {
    let model = cart();
    assert_eq!(model.inputs.len(), 1);
    let mut interpreted = TreeSystem::new(&model).unwrap();
    let push = InputSchedule::constant(vec![2.0]);
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let a = final_q(&mut Cart, method, 2.0, &push);
        let b = final_q(&mut interpreted, method, 2.0, &push);
        let free = final_q(&mut Cart, method, 2.0, &InputSchedule::default());
        for i in 0..2 {
            assert!(
                (a[i] - b[i]).abs() < 1e-9,
                "{method:?}: q[{i}] {} vs {}",
                a[i],
                b[i]
            );
        }
        assert!(
            a[0] - free[0] > 1.0,
            "the push moves the cart: {} vs {}",
            a[0],
            free[0]
        );
    }
    // A schedule of the wrong width is refused, naming the inputs.
    let (q0, dq0) = interpreted.initial_state();
    let wrong = InputSchedule::constant(vec![1.0, 2.0]);
    let options = SimOptions::new(Method::Rk4, 0.01, 0.1);
    let mut motion = ModelMotions::of(&interpreted);
    let err = run_with_inputs(
        &mut interpreted,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut motion,
        &wrong,
        &mut |_| Ok(()),
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "2 input values given a step; the system has 1 input (push)"
    );
}

#[test]
fn urdf_joints_are_inputs_with_their_effort_as_limits() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/ur5.urdf");
    let ur5 = model::from_urdf_file(path, Default::default()).unwrap();
    assert_eq!(ur5.inputs.len(), 6);
    for u in &ur5.inputs {
        assert_eq!(u.name, ur5.variables[u.variable].name);
    }
    assert_eq!(ur5.inputs[0].limits, Some([-150.0, 150.0]));
    let floating = model::from_urdf_file(
        concat!(env!("CARGO_MANIFEST_DIR"), "/models/solo12.urdf"),
        model::UrdfOptions {
            floating_base: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(
        floating.inputs.len(),
        12,
        "the floating base is not actuated"
    );
}

#[test]
fn input_errors_name_the_entry_and_its_line() {
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/models/cart.toml"
    ))
    .unwrap();
    let err = |extra: &str| {
        model::from_toml_str(&(base.clone() + extra), Some("c.toml"))
            .unwrap_err()
            .to_string()
    };
    let input = |body: &str| format!("\n[[input]]\n{body}\n");
    assert!(
        err(&input("name = \"other\"\nvariable = \"nope\""))
            .contains("c.toml:30: input `other`: unknown variable `nope`"),
        "{}",
        err(&input("name = \"other\"\nvariable = \"nope\""))
    );
    assert!(err(&input("name = \"push\"\nvariable = \"theta\""))
        .contains("input `push` is declared twice (inputs 1 and 2)"));
    assert!(err(&input("name = \"again\"\nvariable = \"x\""))
        .contains("variable `x` already has input `push`; one input per variable"));
    assert!(err(&input(
        "name = \"wide\"\nvariable = \"theta\"\nlimits = [1.0, -1.0]"
    ))
    .contains("c.toml:31: input `wide`: limits [1, -1] must be two finite numbers with lo ≤ hi"));
    assert!(err(&input("name = \"v\"")).contains("input `v`: `variable` is missing"));
    let kinematic = base.replace(
        "[variables.theta]\nq0 = 0.1",
        "[variables.theta]\nkinematic = true",
    );
    let e = model::from_toml_str(
        &(kinematic + &input("name = \"k\"\nvariable = \"theta\"")),
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("input `k`: variable `theta` is kinematic"),
        "{e}"
    );
}

tree_model!(struct TrepVi from "tests/models/trep-vi.toml");

/// Every sample of a run of `sys` from its start under `u_k` at step k.
fn samples<S: System>(sys: &mut S, method: Method, u: &[f64]) -> Vec<Recorded>
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let rows = u.iter().enumerate();
    let rows = rows.map(|(k, &x)| (k as f64 * 0.01, vec![x])).collect();
    let schedule = InputSchedule::from_rows(rows).unwrap();
    run(sys, method, 0.01 * u.len() as f64, &schedule)
}

/// A stepper under `u_k` at step k hands out what a run under the same schedule records.
fn stepped_like_a_run<S: System>(mut sys: S, method: Method, what: &str)
where
    tree_mech::nalgebra::DefaultAllocator: tree_mech::nalgebra::allocator::Allocator<S::N>
        + tree_mech::nalgebra::allocator::Allocator<S::N, S::N>,
{
    let u: Vec<f64> = (0..200).map(|k| 2.0 * (0.05 * k as f64).sin()).collect();
    let run = samples(&mut sys, method, &u);
    let (q0, dq0) = sys.initial_state();
    let mut stepper = Stepper::new(sys, method, 0.01, q0.as_slice(), dq0.as_slice()).unwrap();
    let close = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= 1e-13 * (1.0 + y.abs()))
    };
    for (k, (t, q, dq, energy)) in run.iter().enumerate() {
        assert!(
            (stepper.t() - t).abs() < 1e-12,
            "{what}: t {} vs {t}",
            stepper.t()
        );
        assert!(
            close(stepper.q().as_slice(), q),
            "{what} step {k}: q {:?} vs {q:?}",
            stepper.q()
        );
        assert!(
            close(stepper.dq().as_slice(), dq),
            "{what} step {k}: dq {:?} vs {dq:?}",
            stepper.dq()
        );
        let e = stepper.energy();
        assert!(
            (e - energy).abs() <= 1e-12 * (1.0 + energy.abs()),
            "{what} step {k}: E {e} vs {energy}"
        );
        if k < u.len() {
            stepper.step(&[u[k]]).unwrap();
        }
    }
    assert_eq!(stepper.steps(), u.len());
    // The string holds: the VI's constraint and the start's projection act in the stepper too.
    assert_eq!(
        stepper.p().is_some(),
        matches!(method, Method::Vi(_)),
        "{what}"
    );
}

#[test]
fn a_stepper_steps_as_a_run_under_the_same_inputs() {
    // A kinematic hand on a prescribed motion, a string constraint, damping, a spring and an
    // input: each in force a step at a time as over a whole run, compiled and interpreted.
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        stepped_like_a_run(TrepVi, method, &format!("compiled {method:?}"));
        let interpreted = TreeSystem::new(&TrepVi::model()).unwrap();
        stepped_like_a_run(interpreted, method, &format!("interpreted {method:?}"));
    }
}

#[test]
fn a_stepper_refuses_what_it_cannot_step_and_stops_after_a_failure() {
    #[track_caller]
    fn err(r: Result<(), tree_mech::SimError>) -> String {
        r.unwrap_err().to_string()
    }
    let vi = Method::Vi(ViSettings::default());
    let (q0, dq0) = Slider.initial_state();
    let (q0, dq0) = (q0.as_slice().to_vec(), dq0.as_slice().to_vec());
    let rk45 = Method::Rk45(Default::default());
    assert_eq!(
        Stepper::new(Slider, rk45, 0.01, &q0, &dq0)
            .unwrap_err()
            .to_string(),
        "a stepper advances by fixed steps of dt, and rk45 chooses its own: use rk4 or the VI"
    );
    assert!(Stepper::new(Slider, vi, 0.0, &q0, &dq0)
        .unwrap_err()
        .to_string()
        .contains("time step must be a positive finite number"));
    let mut s = Stepper::new(Slider, vi, 0.01, &q0, &dq0).unwrap();
    assert_eq!(
        err(s.step(&[1.0, 2.0])),
        "2 input values given a step; the system has 1 input (push)"
    );
    assert_eq!(
        err(s.step(&[f64::NAN])),
        "input `push` is NaN, not a finite number"
    );
    assert_eq!(s.steps(), 0, "a refused step is not taken");
    // No input: zero. F = 3 N on 2 kg from rest: x = ¾ t² exactly.
    s.step(&[]).unwrap();
    for _ in 0..100 {
        s.step(&[3.0]).unwrap();
    }
    assert!((s.q()[0] - 0.75).abs() < 1e-9, "x = {}", s.q()[0]);
    // A push that overflows the velocity (by 5e305 m/s a step) fails a step; the stepper
    // then refuses until it is reset.
    let failed = (0..1000).find_map(|_| s.step(&[1e308]).err()).unwrap();
    let e = failed.to_string();
    assert!(e.contains("not finite"), "{e}");
    let k = s.steps() + 1;
    assert!(k > 102, "{k}");
    let e = err(s.step(&[0.0]));
    assert!(
        e.starts_with(&format!("the stepper stopped (step {k} failed: ")),
        "{e}"
    );
    assert!(e.ends_with("; start it again with reset"), "{e}");
    assert!(s
        .stopped()
        .is_some_and(|why| why.starts_with(&format!("step {k} failed: "))));
    assert_eq!(
        err(s.reset(&[0.0, 1.0], &dq0)),
        "initial state has 2 and 1 entries; the system has 1 variable"
    );
    s.reset(&q0, &dq0).unwrap();
    s.step(&[3.0]).unwrap();
    assert_eq!((s.steps(), s.q()[0]), (1, 0.75 * 0.01 * 0.01));
}
