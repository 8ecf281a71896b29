//! Many rollouts (runtime::batch): each equals its own single run bitwise, the results do
//! not depend on the number of threads, compiled systems too, inputs per rollout, and a
//! failing rollout fails alone.

use tree_mech::integrate::{run_with_inputs, InputSchedule, Method, SimOptions, ViSettings};
use tree_mech::runtime::batch::{rollouts, Rollout};
use tree_mech::runtime::ModelMotions;
use tree_mech::{model, tree_model, NoForce, Trajectory, TreeSystem};

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
