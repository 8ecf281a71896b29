//! Many rollouts (runtime::batch): each equals its own single run bitwise, the results do
//! not depend on the number of threads, compiled systems too, inputs per rollout, a
//! failing rollout fails alone, and a watched batch counts what it finished and stops when
//! told.

use std::sync::atomic::Ordering;
use tree_mech::integrate::{run_with_inputs, InputSchedule, Method, SimOptions, ViSettings};

use tree_mech::runtime::batch::{
    rollouts, rollouts_watched, run_in_lanes, stopped, trajectory, Rollout, StepLinearizer, Watch,
};
use tree_mech::runtime::ModelMotions;
use tree_mech::{model, tree_model, NoForce, System, Trajectory, TreeSystem};

tree_model!(struct Cart from "tests/models/cart.toml");

fn starts(n: usize) -> Vec<Rollout> {
    (0..n)
        .map(|k| Rollout {
            q0: vec![0.0, 0.2 + 0.1 * k as f64],
            dq0: vec![0.05 * k as f64, 0.0],
            inputs: InputSchedule::constant(vec![0.3 * k as f64 - 1.0]),
        })
        .collect()
}

/// Every number of every sample, as bits.
fn bits(t: &Trajectory) -> Vec<u64> {
    (0..t.len())
        .flat_map(|k| {
            t.q(k)
                .iter()
                .chain(t.dq(k))
                .chain(t.lambda(k))
                .chain(t.u(k))
                .chain([&t.t[k], &t.energy[k]])
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn rollouts_equal_single_runs_bitwise_whatever_the_thread_count() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let m = model::from_toml_file(path).unwrap();
    let sys = TreeSystem::new(&m).unwrap();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 1.0);
    let starts = starts(9);
    let one = rollouts(&sys, &starts, &options, 1).unwrap();
    // A mistyped thread count is refused with a sentence, not started.
    let refused = rollouts(&sys, &starts, &options, 1_000_000).unwrap_err();
    assert!(
        refused.to_string().contains("1000000 threads asked for"),
        "{refused}"
    );
    for threads in [2, 3, 0] {
        let many = rollouts(&sys, &starts, &options, threads).unwrap();
        for (a, b) in one.iter().zip(&many) {
            assert_eq!(
                bits(a.as_ref().unwrap()),
                bits(b.as_ref().unwrap()),
                "{threads} threads"
            );
        }
    }
    // Each is the single run from its start with its inputs.
    for (start, got) in starts.iter().zip(&one) {
        let mut sys = sys.clone();
        let mut single = Trajectory::new(vec!["x".into(), "theta".into()], vec![], 0);
        let (q0, dq0) = (
            tree_mech::nalgebra::DVector::from_column_slice(&start.q0),
            tree_mech::nalgebra::DVector::from_column_slice(&start.dq0),
        );
        let mut motion = ModelMotions::of(&sys);
        run_with_inputs(
            &mut sys,
            &q0,
            &dq0,
            &options,
            &mut NoForce,
            &mut motion,
            &start.inputs,
            &mut |s| {
                single.push(s);
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(bits(&single), bits(got.as_ref().unwrap()));
    }
    // The pushes differ, so the rollouts do.
    let ends: Vec<f64> = one
        .iter()
        .map(|r| r.as_ref().unwrap().last_q()[0])
        .collect();
    assert!(ends.windows(2).all(|w| w[0] != w[1]), "{ends:?}");
    assert_eq!(one[2].as_ref().unwrap().u(0), &[-0.4]);
}

#[test]
fn compiled_rollouts_match_interpreted_and_a_bad_start_fails_alone() {
    let sys = TreeSystem::new(&Cart::model()).unwrap();
    let options = SimOptions::new(Method::Rk4, 0.01, 0.5);
    let mut starts = starts(4);
    starts[1].q0 = vec![0.0];
    starts[2].dq0[0] = f64::NAN;
    let a = rollouts(&Cart, &starts, &options, 2).unwrap();
    let b = rollouts(&sys, &starts, &options, 2).unwrap();
    let e = a[1].as_ref().unwrap_err().to_string();
    assert!(e.contains("1 positions and 2 velocities"), "{e}");
    let e = a[2].as_ref().unwrap_err().to_string();
    assert!(e.contains("not finite"), "{e}");
    for k in [0, 3] {
        let (x, y) = (a[k].as_ref().unwrap(), b[k].as_ref().unwrap());
        assert_eq!(x.len(), 51);
        for s in 0..x.len() {
            for (p, q) in x.q(s).iter().zip(y.q(s)) {
                assert!((p - q).abs() < 1e-12, "{p} vs {q}");
            }
        }
    }
}

/// A parameter sweep: the pendulum's rod set per rollout; the small-swing period grows as
/// √l (the 4 m rod's is twice the 1 m rod's, to 0.2%).
#[test]
fn a_sweep_runs_each_rollout_on_its_own_parameters() {
    use tree_mech::runtime::batch::rollouts_of;
    let base = model::n_link_pendulum(1);
    let rod = base
        .frames
        .iter()
        .find(|f| matches!(f.joint, tree_mech::model::Joint::Constant(_)))
        .unwrap()
        .name
        .clone();
    let lengths = [1.0, 2.0, 4.0];
    let systems: Vec<TreeSystem> = lengths
        .iter()
        .map(|&l| {
            let mut m = base.clone();
            m.set_constant(&rod, -l).unwrap();
            TreeSystem::new(&m).unwrap()
        })
        .collect();
    let starts: Vec<Rollout> = lengths
        .iter()
        .map(|_| Rollout {
            q0: vec![0.05],
            dq0: vec![0.0],
            inputs: InputSchedule::default(),
        })
        .collect();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.001, 6.0);
    let runs = rollouts_of(systems, &starts, &options, 2).unwrap();
    // The first downward zero crossing, interpolated: a quarter period.
    let quarter = |t: &Trajectory| {
        let k = (1..t.len()).find(|&k| t.q(k)[0] <= 0.0).unwrap();
        let (a, b) = (t.q(k - 1)[0], t.q(k)[0]);
        t.t[k - 1] + (t.t[k] - t.t[k - 1]) * a / (a - b)
    };
    let periods: Vec<f64> = runs
        .iter()
        .map(|r| 4.0 * quarter(r.as_ref().unwrap()))
        .collect();
    assert!((periods[2] / periods[0] - 2.0).abs() < 2e-3, "{periods:?}");
    assert!(
        (periods[1] / periods[0] - 2f64.sqrt()).abs() < 2e-3,
        "{periods:?}"
    );
    // Parameters that cannot be: named.
    let mut m = base.clone();
    assert!(m
        .set_mass("nowhere", 1.0)
        .unwrap_err()
        .contains("no frame `nowhere`"));
    assert!(m
        .set_mass(&rod, -1.0)
        .unwrap_err()
        .contains("finite and positive"));
    let driven = base
        .frames
        .iter()
        .find(|f| matches!(f.joint, tree_mech::model::Joint::Variable(_)))
        .unwrap()
        .name
        .clone();
    assert!(m
        .set_constant(&driven, 1.0)
        .unwrap_err()
        .contains("driven by variable"));
    let err = rollouts_of(vec![TreeSystem::new(&base).unwrap()], &[], &options, 1).unwrap_err();
    assert!(
        err.to_string().contains("1 systems for 0 rollouts"),
        "{err}"
    );
}

/// A trajectory's steps linearised at once (`linearize_trajectory`) are each step's own
/// derivatives: taken again from its recorded start (`λ` of the step as Newton's guess) and
/// linearised right after it (`MidpointVi::derivatives`, the documented use), they agree to
/// the step's tolerance — on a model with a constraint, a moving kinematic hand, an input
/// that changes every step, damping and a spring, both forcings. Any thread count gives the
/// same bits; a run recorded every second step, one of another integrator and another
/// model's are refused with a sentence.
#[test]
fn trajectories_linearise_step_by_step_whatever_the_thread_count() {
    use tree_mech::integrate::{Forcing, MidpointVi, StepContext};
    use tree_mech::runtime::batch::{linearize_trajectory, trajectory};
    use tree_mech::runtime::{ConstraintTerms, Order};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/trep-vi.toml");
    let mut sys = TreeSystem::new(&model::from_toml_file(path).unwrap()).unwrap();
    let rows = (0..30).map(|k| (0.01 * k as f64, vec![(0.7 * k as f64).sin()]));
    let start = Rollout {
        q0: sys.initial_state().0.as_slice().to_vec(),
        dq0: vec![0.0; sys.dof()],
        inputs: InputSchedule::from_rows(rows.collect()).unwrap(),
    };
    for forcing in [Forcing::Split, Forcing::Left] {
        let settings = ViSettings {
            forcing,
            ..ViSettings::default()
        };
        let options = SimOptions::new(Method::Vi(settings), 0.01, 0.25);
        let run = trajectory(&mut sys, &start, &options, &mut |_| Ok(())).unwrap();
        let steps = linearize_trajectory(&sys, &run, &settings, 1).unwrap();
        assert_eq!(steps.len(), run.len() - 1);
        for threads in [2, 0] {
            let again = linearize_trajectory(&sys, &run, &settings, threads).unwrap();
            assert_eq!(again, steps, "{threads} threads");
        }
        let mut vi = MidpointVi::new(
            &sys,
            ViSettings {
                derivatives: true,
                ..settings
            },
        );
        let mut motion = ModelMotions::of(&sys);
        let vector = |x: &[f64]| tree_mech::nalgebra::DVector::from_column_slice(x);
        for (k, step) in steps.iter().enumerate() {
            let (q1, mut p1) = (vector(run.q(k)), vector(run.p(k).unwrap()));
            if k == 0 {
                // The run's first step starts from p₀⁻, not the p(0) recorded (a constraint).
                let mut c = ConstraintTerms::zeros(1, sys.dof());
                sys.constraints(&q1, &q1.map(|_| 0.0), Order::First, &mut c);
                let lambda0 = vector(run.lambda(0));
                vi.start_constrained(&c.dh, &lambda0, 0.01, &mut p1);
            }
            let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
            vi.lambda.copy_from_slice(run.lambda(k + 1));
            vi.predict_from(&vector(run.dq(k)));
            let mut force = NoForce;
            let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.01);
            (cx.index, cx.t, cx.u) = (k, run.t[k], run.u(k));
            vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
            let own = vi.derivatives(&mut cx, &q1, &p1, &q).unwrap();
            for (a, b) in [
                (&own.q2_dq1, &step.q2_dq1),
                (&own.p2_dp1, &step.p2_dp1),
                (&own.q2_du1, &step.q2_du1),
                (&own.p2_dk2, &step.p2_dk2),
                (&own.lambda_dq1, &step.lambda_dq1),
            ] {
                let scale = a.amax().max(1.0);
                assert!((a - b).amax() < 1e-8 * scale, "step {k}: {a} against {b}");
            }
        }
    }
    // Samples every second step, RK4's samples (no momenta), another model's.
    let settings = ViSettings::default();
    let every = SimOptions {
        every: 2,
        ..SimOptions::new(Method::Vi(settings), 0.01, 0.1)
    };
    let sparse = trajectory(&mut sys, &start, &every, &mut |_| Ok(())).unwrap();
    for threads in [1, 2] {
        // Each worker stops at its own first bad step; the earliest is reported.
        let e = linearize_trajectory(&sys, &sparse, &settings, threads).unwrap_err();
        assert!(
            e.to_string()
                .contains("step 0 of the trajectory (t = 0) does not solve"),
            "{threads} threads: {e}"
        );
    }
    let rk4 = SimOptions::new(Method::Rk4, 0.01, 0.1);
    let explicit = trajectory(&mut sys, &start, &rk4, &mut |_| Ok(())).unwrap();
    let e = linearize_trajectory(&sys, &explicit, &settings, 1).unwrap_err();
    assert!(e.to_string().contains("record one with the VI"), "{e}");
    let cart_path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let cart = TreeSystem::new(&model::from_toml_file(cart_path).unwrap()).unwrap();
    let e = linearize_trajectory(&cart, &sparse, &settings, 1).unwrap_err();
    assert!(e.to_string().contains("are not the system's"), "{e}");
    // The system's variables but no constraint rows: refused before any step.
    let names: Vec<String> = (0..sys.dof())
        .map(|i| sys.variable_name(i).to_string())
        .collect();
    let mut bare = Trajectory::new(names, Vec::new(), 2);
    for k in 0..2 {
        bare.push(&tree_mech::runtime::Sample {
            step: k,
            t: 0.01 * k as f64,
            q: sparse.q(k),
            dq: sparse.dq(k),
            p: sparse.p(k),
            energy: 0.0,
            lambda: &[],
            violation: 0.0,
            u: &[],
            impulse: &[],
            gap: &[],
        });
    }
    let e = linearize_trajectory(&sys, &bare, &settings, 1).unwrap_err();
    assert!(
        e.to_string()
            .contains("the trajectory has 0 constraint rows, the system 1"),
        "{e}"
    );
}

#[test]
fn a_watched_batch_counts_its_rollouts_and_stops_when_told() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/cart.toml");
    let sys = TreeSystem::new(&model::from_toml_file(path).unwrap()).unwrap();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 0.5);
    let starts = starts(12);
    // Watched to the end: every rollout counted, the results those of the unwatched batch.
    let watch = Watch::default();
    let watched = rollouts_watched(&sys, &starts, &options, 2, &watch).unwrap();
    assert_eq!(watch.done.load(Ordering::Relaxed), 12);
    let plain = rollouts(&sys, &starts, &options, 2).unwrap();
    for (a, b) in watched.iter().zip(&plain) {
        assert_eq!(bits(a.as_ref().unwrap()), bits(b.as_ref().unwrap()));
    }
    // Stopped before it starts: nothing runs, the batch says it was stopped.
    let watch = Watch::default();
    watch.stop.store(true, Ordering::Relaxed);
    let e = rollouts_watched(&sys, &starts, &options, 2, &watch).unwrap_err();
    assert_eq!(e, stopped());
    assert!(e.to_string().contains("stopped before it finished"), "{e}");
    // Stopped from another thread once the first rollout is done: the batch ends early.
    let long = SimOptions::new(Method::Vi(ViSettings::default()), 0.001, 20.0);
    let many = self::starts(64);
    let watch = Watch::default();
    let result = std::thread::scope(|scope| {
        scope.spawn(|| {
            while watch.done.load(Ordering::Relaxed) == 0 {
                std::thread::yield_now();
            }
            watch.stop.store(true, Ordering::Relaxed);
        });
        rollouts_watched(&sys, &many, &long, 2, &watch)
    });
    assert_eq!(result.unwrap_err(), stopped());
    // An RK4 batch (run in lanes, four at a time) counts each rollout once too.
    let watch = Watch::default();
    let rk4 = SimOptions::new(Method::Rk4, 0.01, 0.5);
    rollouts_watched(&sys, &starts, &rk4, 2, &watch).unwrap();
    assert_eq!(watch.done.load(Ordering::Relaxed), 12);
    // Linearising a trajectory counts its steps, and stops when told.
    let settings = ViSettings::default();
    let run =
        tree_mech::runtime::batch::trajectory(&mut sys.clone(), &starts[3], &options, &mut |_| {
            Ok(())
        })
        .unwrap();
    let mut linearizer = StepLinearizer::new(&sys, &settings, 2).unwrap();
    let (watch, mut steps) = (Watch::default(), Vec::new());
    linearizer
        .linearize_into_watched(&run, &mut steps, &watch)
        .unwrap();
    assert_eq!(watch.done.load(Ordering::Relaxed), 50);
    assert_eq!(steps.len(), 50);
    watch.stop.store(true, Ordering::Relaxed);
    let e = linearizer.linearize_into_watched(&run, &mut steps, &watch);
    assert_eq!(e.unwrap_err(), stopped());
}

/// The elements model (tests/models/elements.toml: springs, a damper, damping, kinematic
/// variables moved by a sinusoid and a spline) without its constraints, with two inputs.
fn elements_unconstrained() -> model::Model {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/elements.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let mut kept = String::new();
    for block in text.split("\n[") {
        let block = if kept.is_empty() {
            block.to_string()
        } else {
            format!("\n[{block}")
        };
        if !block.starts_with("\n[[constraint]]") && !block.starts_with("\n[variables.len]") {
            kept += &block;
        }
    }
    kept += "\n[[input]]\nname = \"turn\"\nvariable = \"yaw\"\n[[input]]\nname = \"lift\"\nvariable = \"slide\"\n";
    model::from_toml_str(&kept, None).unwrap()
}

/// Limits left as bounds nobody enforces (`enforce_limits = false`).
fn no_limits() -> model::ContactsSpec {
    model::ContactsSpec {
        enforce_limits: Some(false),
        ..Default::default()
    }
}

/// A batch of RK4 rollouts runs four at a time in SIMD lanes (`runtime::lanes`), and each
/// result is still its own single run's, bit for bit — on the 8-link chain, the UR5 (full
/// inertias) and the elements model (springs, a damper, damping, kinematic variables,
/// inputs per rollout as a schedule), every 3rd step recorded over a duration no multiple of
/// the step, groups of four and a padded group of three; any thread count gives the same.
/// A group with a failing rollout, or a model with constraints, runs each alone.
#[test]
fn rk4_rollouts_run_in_lanes_and_equal_single_runs_bitwise() {
    let root = env!("CARGO_MANIFEST_DIR");
    let models = [
        model::from_toml_file(format!("{root}/benches/models/pendulum-8.toml")).unwrap(),
        // RK4 cannot enforce limits: the UR5's left off.
        model::from_urdf_file(format!("{root}/models/ur5.urdf"), Default::default())
            .and_then(|m| m.with_contacts(&no_limits()))
            .unwrap(),
        elements_unconstrained(),
    ];
    let mut options = SimOptions::new(Method::Rk4, 0.01, 0.735);
    options.every = 3;
    for m in &models {
        let sys = TreeSystem::new(m).unwrap();
        let n = m.variables.len();
        let starts: Vec<Rollout> = (0..7)
            .map(|k| {
                let wave = |s: f64| (0..n).map(move |i| 0.3 * (1.7 * (i + 3 * k) as f64 + s).sin());
                let inputs = (0..sys.input_count())
                    .map(|i| 0.5 * (k as f64 - 2.0) + i as f64)
                    .collect::<Vec<_>>();
                let later = inputs.iter().map(|u| -0.5 * u).collect();
                Rollout {
                    q0: wave(0.1).map(|x| x + 0.2).collect(),
                    dq0: wave(0.9).collect(),
                    inputs: InputSchedule::from_rows(vec![(0.0, inputs), (0.31, later)]).unwrap(),
                }
            })
            .collect();
        let alone: Vec<Trajectory> = (starts.iter())
            .map(|s| trajectory(&mut sys.clone(), s, &options, &mut |_| Ok(())).unwrap())
            .collect();
        let same = |a: &Trajectory, b: &Trajectory| {
            bits(a) == bits(b) && a.dissipated.to_bits() == b.dissipated.to_bits()
        };
        // The laned run itself, for each group.
        for group in [&starts[..4], &starts[4..]] {
            let first = if group.len() == 4 { 0 } else { 4 };
            let laned =
                run_in_lanes(&mut sys.clone(), group, &options).expect("the group runs in lanes");
            assert_eq!(laned.len(), group.len());
            for (k, t) in laned.iter().enumerate() {
                assert_eq!(t.len(), 26, "{}", m.name);
                assert!(
                    same(t, &alone[first + k]),
                    "{} rollout {}",
                    m.name,
                    first + k
                );
            }
        }
        for threads in [1, 2] {
            let batch = rollouts(&sys, &starts, &options, threads).unwrap();
            for (k, got) in batch.iter().enumerate() {
                assert!(
                    same(got.as_ref().unwrap(), &alone[k]),
                    "{} rollout {k}",
                    m.name
                );
            }
        }
        // The rollouts differ, and the model's own forces took energy out where it has them.
        assert!(alone.windows(2).all(|w| w[0].last_q() != w[1].last_q()));
        assert_eq!(
            alone[0].dissipated != 0.0,
            m.name == "elements",
            "{}",
            m.name
        );
    }
    // A rollout whose state overflows fails alone, with its single run's error; the laned run
    // of its group gives up.
    let sys = TreeSystem::new(&models[0]).unwrap();
    let mut starts: Vec<Rollout> = (0..4)
        .map(|k| Rollout {
            q0: vec![0.1 * k as f64; 8],
            dq0: vec![0.0; 8],
            inputs: InputSchedule::default(),
        })
        .collect();
    starts[2].dq0[3] = 1e200;
    assert!(run_in_lanes(&mut sys.clone(), &starts, &options).is_none());
    // So does a group with a start of the wrong size (refused alone, with its sentence).
    let mut short = starts.clone();
    short[1].q0.pop();
    assert!(run_in_lanes(&mut sys.clone(), &short[..2], &options).is_none());
    let batch = rollouts(&sys, &short[..2], &options, 1).unwrap();
    let e = batch[1].as_ref().unwrap_err().to_string();
    assert!(e.contains("7 positions and 8 velocities"), "{e}");
    assert!(batch[0].is_ok());
    let batch = rollouts(&sys, &starts, &options, 2).unwrap();
    let alone = trajectory(&mut sys.clone(), &starts[2], &options, &mut |_| Ok(())).unwrap_err();
    assert_eq!(
        batch[2].as_ref().unwrap_err().to_string(),
        alone.to_string()
    );
    assert!(alone.to_string().contains("not finite"), "{alone}");
    for k in [0, 1, 3] {
        let single = trajectory(&mut sys.clone(), &starts[k], &options, &mut |_| Ok(())).unwrap();
        assert_eq!(bits(batch[k].as_ref().unwrap()), bits(&single));
    }
    // Constraints: each alone (the elements model as it is).
    let path = format!("{}/tests/models/elements.toml", env!("CARGO_MANIFEST_DIR"));
    let constrained = TreeSystem::new(&model::from_toml_file(path).unwrap()).unwrap();
    let (q0, dq0) = constrained.initial_state();
    let start = Rollout {
        q0: q0.as_slice().to_vec(),
        dq0: dq0.as_slice().to_vec(),
        inputs: InputSchedule::default(),
    };
    assert!(run_in_lanes(&mut constrained.clone(), &[start.clone(), start], &options).is_none());
    // VI batches run one at a time.
    let vi = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 0.1);
    assert!(run_in_lanes(&mut sys.clone(), &starts[..2], &vi).is_none());
}
