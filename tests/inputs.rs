//! Inputs `u`: generalized forces on dynamic variables, `B u`, from TOML, URDF and the inline
//! macro, held constant over each step, in every integrator, on both paths.

mod common;

use tree_mech::integrate::{run_with_inputs, InputSchedule, Method, SimOptions, ViSettings};
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
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(method, 0.01, duration);
    let mut motion = ModelMotions::of(sys);
    let mut last = Vec::new();
    run_with_inputs(
        sys,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut motion,
        inputs,
        &mut |s| {
            last = s.q.to_vec();
            Ok(())
        },
    )
    .unwrap();
    last
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
        "2 input values given a step; the system has 1 inputs (push)"
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
