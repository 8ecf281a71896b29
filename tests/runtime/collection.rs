//! The whole robot collection people load first: example-robot-data 6.0.0's URDF files
//! (tests/robots/example-robot-data, BSD-3 with each robot's own licence; meshes left out),
//! each against Pinocchio 4.1 (tests/fixtures/pinocchio-collection.json, written by
//! tools/reference/robot_collection.py) with a fixed base and, where its root is free, a
//! floating one: every file Pinocchio loads loads here and agrees to 1e-9 of each quantity's
//! scale (M, gravity, the nonlinear effects, the forward dynamics, the kinetic and potential
//! energies, every link's pose), and runs 1 s of VI steps at Δt = 1e-3 from its start and
//! three seeded states with its joint limits enforced (the default) and held, without a
//! failure — or is refused for a reason named in [`REFUSED`] or [`ILL_POSED`].

use std::path::{Path, PathBuf};

use crate::common::{numbers, Rng};
use nalgebra::{DMatrix, DVector};
use serde_json::Value;
use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
use tree_mech::model::{self, Joint, Model, UrdfOptions};
use tree_mech::{NoForce, Order, System, Terms, TreeSystem};

/// Files Pinocchio loads that tree-mech refuses, and the words its error must hold: a
/// robot whose dynamics no simulator can step.
const REFUSED: [(&str, Bases, &str); 5] = [
    // One rigid body, no joint: fixed to the world, nothing moves (Pinocchio's model has no
    // coordinates); with a floating base it loads and flies.
    (
        "hector_description/robots/quadrotor_base.urdf",
        Bases::Fixed,
        "has no moving joint",
    ),
    (
        "iris_description/robots/iris_simple.urdf",
        Bases::Fixed,
        "has no moving joint",
    ),
    // Two links whose inertia breaks the triangle inequality (a principal moment 6.6e-3
    // above the sum of the others, 1.3e-3): no rigid body has it.
    (
        "romeo_description/urdf/romeo_small.urdf",
        Bases::Both,
        "frame `RShoulderYawLink`: inertia [0.000742356, 0.00649989, 0.000664209, 0.000617202, 0.00000598521, -0.00000107417] breaks the triangle inequality",
    ),
    // Every link of its hands is massless: the hands' joints move no mass (Pinocchio's ABA
    // is NaN there).
    (
        "romeo_description/urdf/romeo.urdf",
        Bases::Both,
        "variable `LHand` moves no mass",
    ),
    // Its body's inertia has a negative principal moment, −2.1e-2 (ABA NaN as well).
    (
        "romeo_description/urdf/romeo_laas_small.urdf",
        Bases::Both,
        "frame `body`: inertia [0.0564204, 0.0521042, 0.021185, 0.0000726322, -0.0575115, -0.0000339086] is not positive semi-definite",
    ),
];

/// Which of a file's entries a refusal covers.
#[derive(PartialEq)]
enum Bases {
    Fixed,
    Both,
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests")
}

fn fixture() -> Value {
    let text = std::fs::read_to_string(root().join("fixtures/pinocchio-collection.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The entry's robot as the fixture loaded it, and why not.
fn load(entry: &Value) -> Result<Model, String> {
    let file = entry["file"].as_str().unwrap();
    let options = UrdfOptions {
        floating_base: entry["floating_base"].as_bool().unwrap(),
        independent_mimics: !entry["mimic"].as_bool().unwrap(),
        ..Default::default()
    };
    let path = root().join("robots/example-robot-data").join(file);
    model::from_file(path, options).map_err(|e| e.to_string())
}

/// `m` without damping: Pinocchio's dynamics has none.
fn undamped(mut m: Model) -> Model {
    m.variables.iter_mut().for_each(|v| v.damping = 0.0);
    for f in &mut m.frames {
        if let Joint::Mimic(mimic) = &mut f.joint {
            mimic.damping = 0.0;
        }
    }
    m
}

fn scale(x: &[f64]) -> f64 {
    x.iter().fold(1.0f64, |m, v| m.max(v.abs()))
}

/// The worst difference of `ours` from `theirs` relative to `theirs`' scale.
fn worst(ours: &[f64], theirs: &[f64]) -> f64 {
    let s = scale(theirs);
    ours.iter()
        .zip(theirs)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / s))
}

/// Every quantity of the entry against ours: the worst relative difference of each.
fn compare(m: &Model, entry: &Value) -> Vec<(&'static str, f64)> {
    let mut sys = TreeSystem::new(m).unwrap();
    let n = sys.dof();
    let names: Vec<&str> = entry["variables"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(n, names.len(), "{}: variables", m.name);
    let perm: Vec<usize> = (names.iter())
        .map(|name| {
            m.variable_index(name)
                .unwrap_or_else(|| panic!("no `{name}`"))
        })
        .collect();
    let ours = |x: &[f64]| {
        let mut v = DVector::zeros(n);
        perm.iter().zip(x).for_each(|(&i, &x)| v[i] = x);
        v
    };
    let theirs = |key: &str| numbers(&entry[key]);
    let (q, v, tau) = (ours(&theirs("q")), ours(&theirs("v")), ours(&theirs("tau")));
    let pinocchio_order = |x: &DVector<f64>| perm.iter().map(|&i| x[i]).collect::<Vec<_>>();
    let mut t = Terms::zeros(sys.dim());
    sys.lagrangian(&q, &v, Order::Dynamics, &mut t);
    let m_pin: Vec<f64> = (entry["M"].as_array().unwrap().iter())
        .flat_map(numbers)
        .collect();
    let m_ours: Vec<f64> = (0..n * n)
        .map(|k| t.mass[(perm[k / n], perm[k % n])])
        .collect();
    let nle = &t.d2l_ddq_dq * &v - &t.dl_dq;
    let kinetic = 0.5 * t.dl_ddq.dot(&v);
    let mut out = vec![
        ("M", worst(&m_ours, &m_pin)),
        ("nle", worst(&pinocchio_order(&nle), &theirs("nle"))),
    ];
    let t_pin = entry["kinetic"].as_f64().unwrap();
    out.push((
        "kinetic energy",
        (kinetic - t_pin).abs() / t_pin.abs().max(1.0),
    ));
    // q̈ = M⁻¹(τ − nle), with the library's own solve.
    let mass = DMatrix::from_iterator(n, n, t.mass.iter().copied());
    let qdd = mass
        .cholesky()
        .expect("M positive definite")
        .solve(&(&tau - &nle));
    out.push(("q̈", worst(&pinocchio_order(&qdd), &theirs("ddq"))));
    let zero = DVector::zeros(n);
    sys.lagrangian(&q, &zero, Order::First, &mut t);
    let potential_at_q = -t.l;
    out.push((
        "gravity",
        worst(&pinocchio_order(&(-&t.dl_dq)), &theirs("g")),
    ));
    if let Some(v_pin) = entry["potential"].as_f64() {
        sys.lagrangian(&zero, &zero, Order::First, &mut t);
        let v_ours = potential_at_q + t.l;
        out.push((
            "potential energy",
            (v_ours - v_pin).abs() / v_pin.abs().max(1.0),
        ));
    }
    let mut poses = vec![tree_mech::runtime::Pose::IDENTITY; sys.frame_count()];
    sys.poses(&q, &mut poses);
    let mut pose_error = 0.0f64;
    for (link, h) in entry["poses"].as_object().unwrap() {
        if let Some(k) = m.frame_index(link) {
            let g: Vec<f64> = poses[k].matrix().into_iter().flatten().collect();
            pose_error = pose_error.max(worst(&g, &numbers(h)));
        }
    }
    out.push(("poses", pose_error));
    out
}

/// Robots that load and agree, whose dynamics the VI cannot step as written, which bases,
/// and the words its error must hold.
const ILL_POSED: [(&str, Bases, &[&str]); 2] = [
    // The neck's yaw link has inertia entries of ±1e-20 kg·m² and no mass (rounding noise in
    // the file, taken as a point mass): the joint moves nothing, M's pivot is 3.6e-18
    // (Pinocchio's ABA divides by the same).
    (
        "icub_description/robots/icub.urdf",
        Bases::Both,
        &[
            "mass matrix is not positive definite",
            "at variable `neck_yaw`",
        ],
    ),
    // Each hip is three revolutes, Z then X then Y, and `hip_X`'s upper limit is π/2 — where
    // the Y axis lines up with the Z axis (a gimbal lock: M loses rank). Collapsing from its
    // start, the left leg meets that limit at t = 0.45 s still turning about the axis the lock
    // takes away; its momentum there has nowhere to go but into unbounded hip rates, and the
    // contact step says so. With a floating base the body falls and the leg never gets there.
    (
        "human_description/robots/human.urdf",
        Bases::Fixed,
        &[
            "the contact step did not converge",
            "gimbal lock",
            "left_hip_",
        ],
    ),
];

/// 1 s of VI steps at Δt = 1e-3 from the start and from three seeded states (q within ±0.5
/// of the start, at rest, projected into the limits), with the file's damping: how many
/// steps ended with a limit pushing, or the failure — a limit passed by more than 1e-9 rad
/// (or m) is one.
fn steps(m: &Model, seed: u64) -> Result<usize, String> {
    let mut sys = TreeSystem::new(m).unwrap();
    let n = sys.dof();
    let options = SimOptions {
        method: Method::Vi(ViSettings::default()),
        dt: 1e-3,
        duration: 1.0,
        ..Default::default()
    };
    let (q0, dq0) = sys.initial_state();
    let mut rng = Rng::new(seed);
    let mut pushing = 0;
    for start in 0..4 {
        let (q, dq) = match start {
            0 => (q0.clone(), dq0.clone()),
            _ => (&q0 + rng.vector(n, 0.5), DVector::zeros(n)),
        };
        let traj = simulate(&mut sys, &q, &dq, &options, &mut NoForce, &mut |_| {})
            .map_err(|e| format!("start {start}: {e}"))?;
        for k in 0..traj.len() {
            let deepest = traj.gap(k).iter().copied().fold(0.0, f64::min);
            if deepest < -1e-9 {
                return Err(format!(
                    "start {start}: a limit passed by {deepest:e} at step {k}"
                ));
            }
            pushing += traj.impulse(k).iter().any(|&g| g > 0.0) as usize;
        }
    }
    Ok(pushing)
}

#[test]
fn every_robot_of_the_collection_loads_agrees_with_pinocchio_and_steps() {
    let fx = fixture();
    let entries = fx["entries"].as_array().unwrap();
    assert!(entries.len() >= 120, "the collection's entries");
    let mut problems = Vec::new();
    let (mut compared, mut held) = (0, 0);
    for (k, entry) in entries.iter().enumerate() {
        let file = entry["file"].as_str().unwrap();
        let label = match entry["floating_base"].as_bool().unwrap() {
            true => format!("{file} (floating)"),
            false => file.to_string(),
        };
        let floating = entry["floating_base"].as_bool().unwrap();
        let listed = (REFUSED.iter()).find(|r| r.0 == file && (r.1 == Bases::Both || !floating));
        let model = match (load(entry), listed) {
            (Ok(m), None) => m,
            (Err(e), Some((_, _, why))) if e.contains(why) => continue,
            (Err(e), _) => {
                problems.push(format!("{label}: refused: {e}"));
                continue;
            }
            (Ok(_), Some(_)) => {
                problems.push(format!("{label}: loads, though listed as refused"));
                continue;
            }
        };
        for (what, error) in compare(&undamped(model.clone()), entry) {
            if error.is_nan() || error > 1e-9 {
                problems.push(format!(
                    "{label}: {what} differs from Pinocchio's by {error:.1e}"
                ));
            }
        }
        let ill_posed =
            (ILL_POSED.iter()).find(|r| r.0 == file && (r.1 == Bases::Both || !floating));
        match (steps(&model, k as u64), ill_posed) {
            (Ok(pushing), None) => {
                held += (pushing > 0) as usize;
            }
            (Err(e), Some((_, _, words))) if words.iter().all(|w| e.contains(w)) => {}
            (Err(e), _) => problems.push(format!("{label}: the VI failed: {e}")),
            (Ok(_), Some(_)) => {
                problems.push(format!("{label}: steps, though listed as ill-posed"))
            }
        }
        compared += 1;
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(
        compared + 2 * REFUSED.len() >= entries.len(),
        "{compared} compared"
    );
    assert!(compared >= 115, "{compared} compared");
    // Most robots fold onto their limits within the second, and the limits hold them.
    assert!(held >= 60, "{held} of {compared} robots met a limit");
}
