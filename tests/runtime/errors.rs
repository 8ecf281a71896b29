//! Failures are errors that name the step and the cause — never a panic or a NaN trajectory.

use crate::common;

use common::{interpreted, load};
use nalgebra::Dyn;
use tree_mech::integrate::{simulate, Method, SimOptions, Tolerance, ViSettings};
use tree_mech::runtime::Vector;
use tree_mech::{NoForce, SimError, System};

fn methods() -> [Method; 3] {
    [
        Method::Rk4,
        Method::Rk45(Tolerance::default()),
        Method::Vi(ViSettings::default()),
    ]
}

#[test]
fn a_singular_mass_matrix_is_an_error_naming_the_step() {
    // ZYX Euler angles at pitch π/2: gimbal lock, M loses rank.
    let mut sys = interpreted(&load("free-body.toml"));
    let (mut q0, dq0) = sys.initial_state();
    q0[4] = std::f64::consts::FRAC_PI_2;
    for method in [Method::Rk4, Method::Rk45(Tolerance::default())] {
        let options = SimOptions {
            method,
            dt: 0.01,
            duration: 1.0,
            ..Default::default()
        };
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        assert!(
            matches!(err, SimError::SingularMassMatrix { step: 0, .. }),
            "{err:?}"
        );
        let msg = err.to_string();
        assert!(
            msg.starts_with("step 0 (t = 0)")
                && msg.contains("mass matrix is not positive definite")
                && msg.contains("gimbal lock"),
            "{msg}"
        );
    }
}

#[test]
fn newton_failure_reports_step_and_residual() {
    let mut sys = interpreted(&load("double-pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let settings = ViSettings {
        max_iterations: 1,
        tolerance: 1e-15,
        ..ViSettings::default()
    };
    let options = SimOptions {
        method: Method::Vi(settings),
        dt: 0.05,
        duration: 1.0,
        ..Default::default()
    };
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
    match &err {
        SimError::NewtonFailed {
            step,
            iterations,
            residual,
            ..
        } => {
            assert_eq!(*step, 0);
            assert_eq!(*iterations, 1);
            assert!(*residual > 0.0 && residual.is_finite());
        }
        other => panic!("expected a Newton failure, got {other:?}"),
    }
    assert!(err
        .to_string()
        .contains("Newton did not converge in 1 iterations"));
}

#[test]
fn a_non_finite_force_stops_the_run_with_an_error() {
    let mut sys = interpreted(&load("pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    for method in methods() {
        let mut force = |t: f64, _: &Vector<Dyn>, _: &Vector<Dyn>, u: &mut Vector<Dyn>| {
            if t > 0.25 {
                u[0] += f64::NAN;
            }
        };
        let options = SimOptions {
            method,
            dt: 0.01,
            duration: 1.0,
            ..Default::default()
        };
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut force, &mut |_| {}).unwrap_err();
        match err {
            SimError::NonFinite { step, t, .. } => assert!(
                step > 0 && t > 0.24 && t < 0.3,
                "{method:?}: step {step}, t {t}"
            ),
            other => panic!("{method:?}: expected NonFinite, got {other:?}"),
        }
    }
}

#[test]
fn bad_arguments_are_errors() {
    let mut sys = interpreted(&load("pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let short = Vector::<Dyn>::zeros(3);
    let ok = SimOptions {
        method: Method::Rk4,
        dt: 0.01,
        duration: 1.0,
        ..Default::default()
    };
    let e = simulate(&mut sys, &short, &dq0, &ok, &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("the system has 1 variable"), "{e}");
    // A duration shorter than one step: refused by every front end (it would end at t = dt).
    for (dt, duration) in [
        (0.0, 1.0),
        (-0.1, 1.0),
        (f64::NAN, 1.0),
        (0.1, -1.0),
        (2.0, 1.0),
    ] {
        let o = SimOptions { dt, duration, ..ok };
        assert!(matches!(
            simulate(&mut sys, &q0, &dq0, &o, &mut NoForce, &mut |_| {}),
            Err(SimError::InvalidInput(_))
        ));
    }
    let bad_alpha = SimOptions {
        method: Method::Vi(ViSettings {
            alpha: 1.5,
            ..ViSettings::default()
        }),
        ..ok
    };
    assert!(matches!(
        simulate(&mut sys, &q0, &dq0, &bad_alpha, &mut NoForce, &mut |_| {}),
        Err(SimError::InvalidInput(_))
    ));
    let mut nan_q = q0.clone();
    nan_q[0] = f64::NAN;
    assert!(matches!(
        simulate(&mut sys, &nan_q, &dq0, &ok, &mut NoForce, &mut |_| {}),
        Err(SimError::NonFinite { step: 0, .. })
    ));
}

/// The string pendulum of tests/models with extra constraints appended.
fn string_pendulum_with(extra: &str) -> tree_mech::model::Model {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/models/string-pendulum.toml"
    );
    let text = std::fs::read_to_string(path).unwrap() + extra;
    tree_mech::model::from_toml_str(&text, None).unwrap()
}

#[test]
fn a_run_that_cannot_finish_is_refused_up_front() {
    let mut sys = interpreted(&load("pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Rk4, 1e-300, 1.0);
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(
        matches!(err, SimError::TooManySteps { steps } if steps > 0.99e300),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("1.00e300 steps, more than the limit of 1e9"),
        "{err}"
    );
    let every = SimOptions {
        every: 0,
        ..SimOptions::new(Method::Rk4, 0.01, 1.0)
    };
    let err = simulate(&mut sys, &q0, &dq0, &every, &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("K ≥ 1"), "{err}");
}

#[test]
fn an_unsatisfiable_constraint_is_named() {
    // A second string from the anchor to a fixed point 2 m away that must be 3 m long:
    // no dynamic variable moves either end.
    let model = string_pendulum_with(
        "[[frame]]\nname = \"post\"\nty = 2.0\n\
         [[constraint]]\nname = \"impossible\"\nkind = \"distance\"\nframes = [\"anchor\", \"post\"]\nlength = 3.0\n",
    );
    for method in methods() {
        let mut sys = interpreted(&model);
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(method, 0.01, 0.1);
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        match &err {
            SimError::Unsatisfiable {
                constraint,
                violation,
            } => {
                assert_eq!(constraint, "impossible");
                assert!(
                    (violation - 5.0).abs() < 1e-12,
                    "h = 2² − 3² = −5, got {violation}"
                );
            }
            other => panic!("{method:?}: expected Unsatisfiable, got {other:?}"),
        }
        assert!(err
            .to_string()
            .contains("cannot satisfy constraint `impossible`"));
    }
}

#[test]
fn redundant_constraints_are_an_error_naming_one() {
    let model = string_pendulum_with(
        "[[constraint]]\nname = \"again\"\nkind = \"distance\"\nframes = [\"bob\", \"anchor\"]\nlength = 1.5\n",
    );
    for method in methods() {
        let mut sys = interpreted(&model);
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(method, 0.01, 0.1);
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        match &err {
            SimError::SingularConstraints {
                step, constraint, ..
            } => {
                assert_eq!((*step, constraint.as_str()), (0, "again"), "{method:?}");
            }
            other => panic!("{method:?}: expected SingularConstraints, got {other:?}"),
        }
    }
}

#[test]
fn a_step_that_turns_a_joint_more_than_a_quarter_turn_is_refused_then_subdivided() {
    // 300 rad/s at Δt = 0.01: three radians a step, not resolved (and where Newton may land
    // on a spurious root). Without subdivision the step is refused, naming the joint.
    let mut model = load("pendulum.toml");
    model.variables[0].dq0 = 300.0;
    let mut sys = interpreted(&model);
    let (q0, dq0) = sys.initial_state();
    let options = |max_subdivisions| SimOptions {
        method: Method::Vi(ViSettings {
            max_subdivisions,
            ..ViSettings::default()
        }),
        dt: 0.01,
        duration: 0.1,
        ..Default::default()
    };
    let err = simulate(&mut sys, &q0, &dq0, &options(0), &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(
        matches!(err, SimError::StepTooCoarse { step: 0, .. }),
        "{err}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("`theta` turned") && msg.contains("quarter turn"),
        "{msg}"
    );
    let traj = simulate(&mut sys, &q0, &dq0, &options(4), &mut NoForce, &mut |_| {}).unwrap();
    assert!(
        traj.subdivided_steps == 10,
        "{} subdivided",
        traj.subdivided_steps
    );
    // Subdivided, the spin is resolved: 0.1 s at ≈ 300 rad/s.
    let turned = traj.last_q()[0] - q0[0];
    assert!((turned - 30.0).abs() < 1.0, "turned {turned}");
}

#[test]
fn tolerances_must_be_positive_numbers_and_runs_at_least_one_step() {
    let mut sys = interpreted(&load("pendulum.toml"));
    let (q0, dq0) = sys.initial_state();
    let vi = |tolerance| {
        Method::Vi(ViSettings {
            tolerance,
            ..ViSettings::default()
        })
    };
    let rk45 = |rtol, atol| Method::Rk45(Tolerance { rtol, atol });
    for (method, expected) in [
        (
            vi(0.0),
            "the VI's Newton tolerance must be a positive number, got 0",
        ),
        (
            vi(-1.0),
            "the VI's Newton tolerance must be a positive number, got -1",
        ),
        (
            vi(f64::NAN),
            "the VI's Newton tolerance must be a positive number, got NaN",
        ),
        (
            rk45(-1.0, 1e-10),
            "rk45's relative tolerance must be a positive number, got -1",
        ),
        (
            rk45(f64::NAN, 1e-10),
            "rk45's relative tolerance must be a positive number, got NaN",
        ),
        (
            rk45(1e-8, -1.0),
            "rk45's absolute tolerance must be a positive number, got -1",
        ),
    ] {
        let options = SimOptions::new(method, 0.01, 1.0);
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        assert_eq!(err.to_string(), expected);
    }
    for method in [Method::Rk4, Method::Vi(ViSettings::default())] {
        let options = SimOptions::new(method, 0.01, 0.004);
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
        assert_eq!(
            err.to_string(),
            "the duration 0.004 s is shorter than one step of 0.01 s: nothing would be simulated"
        );
    }
}

#[test]
fn a_stiff_adaptive_run_stops_at_its_step_budget_with_the_step_size_reached() {
    // Damping 1e9 on a 1 kg pendulum: rk45 is stable only below Δt ≈ 2e-9 s, so 1 s needs
    // some 10⁹ steps; the run stops within its first thousands of steps.
    let mut model = load("pendulum.toml");
    model.variables[0].damping = 1e9;
    let mut sys = interpreted(&model);
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Rk45(Tolerance::default()), 0.01, 1.0);
    let mut recorded = 0;
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {
        recorded += 1
    })
    .unwrap_err();
    match &err {
        SimError::StepBudget {
            step,
            dt,
            needed,
            max_steps,
            ..
        } => {
            assert!(*step < 10_000, "stopped at step {step}");
            assert!(*dt < 1e-8, "step size {dt}");
            assert!(*needed > 1e8 && *max_steps == 1_000_000);
        }
        other => panic!("expected a step budget error, got {other}"),
    }
    assert!(recorded < 10_000);
    assert!(err.to_string().contains("use --integrator vi"), "{err}");
    // The VI takes it in its stride.
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 1.0);
    simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
}

#[test]
fn an_energy_that_overflows_is_an_error_naming_it_and_the_step() {
    // q̇ = 1e200 is a finite state whose kinetic energy is not.
    let mut model = load("pendulum.toml");
    model.variables[0].dq0 = 1e200;
    for method in methods() {
        let mut sys = interpreted(&model);
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(method, 0.01, 0.1);
        let mut recorded = 0;
        let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {
            recorded += 1
        })
        .unwrap_err();
        assert_eq!(recorded, 0, "{method:?}: nothing non-finite is handed out");
        let msg = err.to_string();
        assert!(
            msg.starts_with("step 0 (t = 0): the energy E = T + V (")
                && msg.contains(") is not finite at the start"),
            "{method:?}: {msg}"
        );
    }
}

#[test]
fn opposite_planes_that_agree_are_redundant_not_unsatisfiable() {
    // Two planes through the anchor with opposite normals hold the same x = 0.
    let model = string_pendulum_with(
        "[[constraint]]\nname = \"front\"\nkind = \"plane\"\nframes = [\"anchor\", \"bob\"]\nnormal = [1.0, 0.0, 0.0]\n\
         [[constraint]]\nname = \"back\"\nkind = \"plane\"\nframes = [\"anchor\", \"bob\"]\nnormal = [-1.0, 0.0, 0.0]\n\
         [variables.x]\nq0 = 0.1\n",
    );
    let mut sys = interpreted(&model);
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 0.1);
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(
        matches!(&err, SimError::SingularConstraints { constraint, .. } if constraint == "back"),
        "{err}"
    );
    assert!(err.to_string().contains("redundant"), "{err}");
}

#[test]
fn errors_print_as_sentences_also_through_debug() {
    // `fn main() -> Result<(), Box<dyn Error>>` prints the error with `{:?}`.
    let err =
        tree_mech::model::from_toml_str("[[frame]]\nname = \"\"\n", Some("m.toml")).unwrap_err();
    assert_eq!(format!("{err:?}"), err.to_string());
    assert!(err.to_string().starts_with("m.toml:2: frame name"), "{err}");
    let err = SimError::NonFinite {
        step: 3,
        t: 0.03,
        what: "the energy E = T + V (inf)".into(),
    };
    assert_eq!(
        format!("{err:?}"),
        "step 3 (t = 0.03): the energy E = T + V (inf) is not finite (the run diverged, the state \
         running away: lower --dt, or take rk45, which chooses a step the motion allows, or the VI)"
    );
}

#[test]
fn numbers_that_overflow_are_named_as_overflow_not_as_a_singular_matrix() {
    // An inertia of 1e308: M and the Newton matrix overflow. Said as what it is, at step 0.
    let text = "name = \"big\"\n[[frame]]\nname = \"arm\"\nrx = \"theta\"\n[[frame]]\nname = \"bob\"\nparent = \"arm\"\ntz = -1.0\nmass = 1.0\ninertia = [1e308, 1e308, 1e308]\n[variables.theta]\nq0 = 0.5\n";
    let mut sys = interpreted(&tree_mech::model::from_toml_str(text, None).unwrap());
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 0.1);
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap_err();
    assert!(
        matches!(err, SimError::NonFinite { step: 0, .. }),
        "{err:?}"
    );
    assert!(
        err.to_string().contains("overflow double precision"),
        "{err}"
    );
}

/// A floating base whose Euler angles reach a gimbal lock (root_pitch at −90°): Newton fails
/// and the message says why — the mass matrix nearly singular, naming the variable of its
/// weakest pivot — instead of sending the user to a shorter step that cannot help.
#[test]
fn a_newton_failure_at_a_gimbal_lock_says_so() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/robots/example-robot-data/kinova_description/robots/kinova.urdf");
    let options = tree_mech::model::UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    // Its arm's limits left off, so the arm flails as before and the base turns to the lock.
    let free = tree_mech::model::ContactsSpec {
        enforce_limits: Some(false),
        ..Default::default()
    };
    let robot = tree_mech::model::from_file(path, options).unwrap();
    let mut sys = tree_mech::TreeSystem::new(&robot.with_contacts(&free).unwrap()).unwrap();
    let q0 = nalgebra::DVector::from_column_slice(&[
        -2.399516, -0.877988, -2.553569, 0.625331, -1.505676, -1.480697, -1.329974, -2.527627,
        1.513899, 0.946703, 0.66921, -2.927678,
    ]);
    let dq0 = nalgebra::DVector::from_column_slice(&[
        -0.141072, 0.370407, -0.687307, -0.228684, -0.960332, -0.836284, -0.567093, -0.1707,
        -0.07352, 0.769043, -0.366683, -0.957072,
    ]);
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 1e-3,
        duration: 0.2,
        ..Default::default()
    };
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("Newton did not converge")
            && err.contains("the mass matrix is nearly singular here (its pivot at `root_roll`")
            && err.contains("gimbal lock")
            && !err.contains("lower --dt"),
        "{err}"
    );
}

/// A limit that holds a joint at a gimbal lock: the fixed-base human collapsing onto its
/// enforced limits reaches `hip_X`'s upper limit, π/2, where its hip's outer revolutes line
/// up; the contact step fails and says the mass matrix is nearly singular there, naming a
/// hip variable, instead of sending the user to a shorter step (derivations §13).
#[test]
fn a_contact_failure_at_a_gimbal_lock_says_so() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/robots/example-robot-data/human_description/robots/human.urdf");
    let robot =
        tree_mech::model::from_file(path, tree_mech::model::UrdfOptions::default()).unwrap();
    assert!(
        robot.contacts.enforce_limits,
        "a URDF's limits are enforced by default"
    );
    let mut sys = tree_mech::TreeSystem::new(&robot).unwrap();
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 1e-3,
        duration: 1.0,
        ..Default::default()
    };
    let err = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("the contact step did not converge")
            && err.contains("the mass matrix is nearly singular here (its pivot at `")
            && err.contains("_hip_")
            && err.contains("gimbal lock")
            && !err.contains("lower --dt"),
        "{err}"
    );
}
