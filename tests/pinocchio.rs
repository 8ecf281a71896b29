//! Every shipped URDF against Pinocchio 4.1 (tests/fixtures/pinocchio-*.json, written by
//! tools/reference/pinocchio_fixtures.py), compiled and interpreted (the UR10 interpreted):
//! computeABADerivatives' ∂q̈/∂q, ∂q̈/∂v, M⁻¹; mass matrix, generalized gravity, nonlinear
//! effects, forward dynamics (ABA), inverse dynamics (RNEA; also through
//! `dynamics::inverse_dynamics`), every link's pose, kinetic and
//! potential energy, at seeded random states — interpreted and compiled, to 1e-9 relative;
//! and `runtime::kinematics` against Pinocchio's frame functions: every link's Jacobian,
//! velocity and acceleration in its three references, its classical acceleration, and the
//! centre of mass with its velocity, acceleration and Jacobian.
//!
//! The mapping: `M = ∂²L/∂q̇²`, `nle = (∂²L/∂q̇∂q) q̇ − ∂L/∂q`, `g = −∂L/∂q` at q̇ = 0,
//! `τ = u`. Pinocchio's ABA has no joint damping, so the damping force is cancelled; its
//! potential energy leaves out bodies welded to the ground, so potentials are compared
//! relative to the first state.

mod common;

use common::numbers;
use nalgebra::{allocator::Allocator, DefaultAllocator};
use serde_json::Value;
use tree_mech::integrate::StepContext;
use tree_mech::model::{self, UrdfOptions};
use tree_mech::runtime::dynamics::inverse_dynamics;
use tree_mech::runtime::kinematics::{Kinematics, Reference};
use tree_mech::runtime::linearize::continuous_derivatives;
use tree_mech::runtime::{Dynamics, ModelMotions, Pose, Vector};
use tree_mech::{tree_model, Order, System, Terms, TreeSystem};

tree_model!(struct Ur5 from "models/ur5.urdf");
tree_model!(struct Panda from "models/panda.urdf");
tree_model!(struct Solo12 from "models/solo12.urdf", floating_base);

struct Fixture {
    file: String,
    floating_base: bool,
    variables: Vec<String>,
    states: Vec<Value>,
}

fn fixture(name: &str) -> Fixture {
    let path = format!(
        "{}/tests/fixtures/pinocchio-{name}.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    Fixture {
        file: v["file"].as_str().unwrap().to_string(),
        floating_base: v["floating_base"].as_bool().unwrap(),
        variables: v["variables"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_str().unwrap().to_string())
            .collect(),
        states: v["states"].as_array().unwrap().clone(),
    }
}

/// `|a − b| ≤ tol · scale` with the scale of the quantity compared.
#[track_caller]
fn close(a: f64, b: f64, scale: f64, what: &str) {
    let tol = 1e-9 * scale.max(1e-12);
    assert!(
        (a - b).abs() <= tol,
        "{what}: {a} vs Pinocchio {b} (scale {scale})"
    );
}

fn scale(x: &[f64]) -> f64 {
    x.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1.0)
}

/// Compares `sys` with every state of the fixture. `perm[k]` is our index of Pinocchio's
/// variable k.
fn compare<S: System>(mut sys: S, fx: &Fixture, label: &str)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    assert_eq!(n, fx.variables.len(), "{label}: variable count");
    let perm: Vec<usize> = fx
        .variables
        .iter()
        .map(|name| {
            (0..n)
                .find(|&i| sys.variable_name(i) == name)
                .unwrap_or_else(|| panic!("{label}: no variable `{name}`"))
        })
        .collect();
    let damping: Vec<f64> = (0..n).map(|i| sys.damping(i)).collect();
    let mut terms = Terms::zeros(sys.dim());
    let mut dynamics = Dynamics::new(&sys);
    let mut motion = ModelMotions::of(&sys);
    let ours = |x: &[f64]| {
        let mut v = sys_vector::<S>(n);
        for (k, &i) in perm.iter().enumerate() {
            v[i] = x[k];
        }
        v
    };
    let mut offset = None;
    for (s, state) in fx.states.iter().enumerate() {
        let what = |q: &str| format!("{label} state {s}: {q}");
        let (q, v, tau, a) = (
            ours(&numbers(&state["q"])),
            ours(&numbers(&state["v"])),
            numbers(&state["tau"]),
            numbers(&state["a"]),
        );
        sys.lagrangian(&q, &v, Order::Dynamics, &mut terms);
        let m_pin: Vec<Vec<f64>> = state["M"].as_array().unwrap().iter().map(numbers).collect();
        let m_scale = scale(&m_pin.concat());
        for i in 0..n {
            for j in 0..n {
                close(
                    terms.mass[(perm[i], perm[j])],
                    m_pin[i][j],
                    m_scale,
                    &what("M"),
                );
            }
        }
        let nle_pin = numbers(&state["nle"]);
        let nle: Vec<f64> = (0..n)
            .map(|i| {
                let r = perm[i];
                (0..n).map(|j| terms.d2l_ddq_dq[(r, j)] * v[j]).sum::<f64>() - terms.dl_dq[r]
            })
            .collect();
        let nle_scale = scale(&nle_pin);
        for i in 0..n {
            close(nle[i], nle_pin[i], nle_scale, &what("nle"));
        }
        // RNEA through the library's inverse dynamics, less the damping force it includes.
        let rnea_pin = numbers(&state["rnea"]);
        let mut tau_ours = sys_vector::<S>(n);
        let mut id_terms = Terms::zeros(sys.dim());
        inverse_dynamics(&mut sys, &q, &v, &ours(&a), &mut id_terms, &mut tau_ours).unwrap();
        for i in 0..n {
            let r = perm[i];
            let ma: f64 = (0..n).map(|j| terms.mass[(r, perm[j])] * a[j]).sum();
            close(ma + nle[i], rnea_pin[i], scale(&rnea_pin), &what("rnea"));
            close(
                tau_ours[r] - damping[r] * v[r],
                rnea_pin[i],
                scale(&rnea_pin),
                &what("inverse_dynamics"),
            );
        }
        let kinetic: f64 = 0.5 * (0..n).map(|i| terms.dl_ddq[i] * v[i]).sum::<f64>();
        let potential = kinetic - terms.l;
        let (t_pin, v_pin) = (
            state["kinetic"].as_f64().unwrap(),
            state["potential"].as_f64().unwrap(),
        );
        close(
            kinetic,
            t_pin,
            t_pin.abs().max(1.0),
            &what("kinetic energy"),
        );
        // Pinocchio leaves out bodies welded to the ground (a constant): compare the
        // potential relative to the first state.
        let (v0, v0_pin) = *offset.get_or_insert((potential, v_pin));
        close(
            potential - v0,
            v_pin - v0_pin,
            v_pin.abs().max(1.0),
            &what("potential energy"),
        );
        // Gravity: −∂L/∂q at rest.
        let zero = sys_vector::<S>(n);
        sys.lagrangian(&q, &zero, Order::First, &mut terms);
        let g_pin = numbers(&state["g"]);
        for i in 0..n {
            close(
                -terms.dl_dq[perm[i]],
                g_pin[i],
                scale(&g_pin),
                &what("gravity"),
            );
        }
        // Forward dynamics through the library's own path, damping cancelled.
        let mut u_ours = ours(&tau);
        for i in 0..n {
            u_ours[i] += damping[i] * v[i];
        }
        let mut qdd = sys_vector::<S>(n);
        let mut force = |_t: f64, _q: &Vector<S::N>, _dq: &Vector<S::N>, u: &mut Vector<S::N>| {
            *u += &u_ours;
        };
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
        dynamics.acceleration(&mut cx, &q, &v, &mut qdd).unwrap();
        let ddq_pin = numbers(&state["ddq"]);
        for i in 0..n {
            close(qdd[perm[i]], ddq_pin[i], scale(&ddq_pin), &what("ABA q̈"));
        }
        // computeABADerivatives: ∂q̈/∂q, ∂q̈/∂v (ours also holds −M⁻¹c of the damping the
        // fixed force above cancels only in value) and ∂q̈/∂τ = M⁻¹ on the actuated joints.
        let u = vec![0.0; cx.sys.input_count()];
        cx.u = &u;
        let d = continuous_derivatives(&mut cx, &q, &v).unwrap();
        let matrix = |key: &str| -> Vec<Vec<f64>> {
            state[key].as_array().unwrap().iter().map(numbers).collect()
        };
        let (dq_pin, dv_pin, minv) = (matrix("ddq_dq"), matrix("ddq_dv"), matrix("minv"));
        let (sq, sv, sm) = (
            scale(&dq_pin.concat()),
            scale(&dv_pin.concat()),
            scale(&minv.concat()),
        );
        for i in 0..n {
            for j in 0..n {
                let (r, c) = (perm[i], perm[j]);
                close(d.qdd_dq[(r, c)], dq_pin[i][j], sq, &what("∂q̈/∂q"));
                let damped = dv_pin[i][j] - minv[i][j] * damping[c];
                close(d.qdd_ddq[(r, c)], damped, sv, &what("∂q̈/∂v"));
            }
        }
        for k in 0..u.len() {
            let var = cx.sys.input_variable(k);
            let j = perm.iter().position(|&p| p == var).unwrap();
            for i in 0..n {
                close(d.qdd_du[(perm[i], k)], minv[i][j], sm, &what("∂q̈/∂τ"));
            }
        }
        assert!(sq > 1.0 && u.len() + if fx.floating_base { 6 } else { 0 } == n);
        compare_poses(&mut sys, &q, state, &what(""));
    }
}

/// Every link's pose at `q` against the state's `poses` (all but at most one link named:
/// the root fixed to the world may have no frame here).
fn compare_poses<S: System>(sys: &mut S, q: &Vector<S::N>, state: &Value, what: &str)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let frames: Vec<String> = (0..sys.frame_count())
        .map(|k| sys.frame_name(k).to_string())
        .collect();
    let mut poses = vec![Pose::IDENTITY; frames.len()];
    sys.poses(q, &mut poses);
    let mut compared = 0;
    for (link, pin_pose) in state["poses"].as_object().unwrap() {
        let Some(k) = frames.iter().position(|f| f == link) else {
            continue;
        };
        let (h, g) = (numbers(pin_pose), poses[k].matrix());
        for r in 0..4 {
            for c in 0..4 {
                close(
                    g[r][c],
                    h[4 * r + c],
                    1.0,
                    &format!("{what}pose of `{link}`"),
                );
            }
        }
        compared += 1;
    }
    assert!(
        compared + 1 >= state["poses"].as_object().unwrap().len(),
        "{what}poses compared"
    );
}

fn sys_vector<S: System>(n: usize) -> Vector<S::N>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    Vector::<S::N>::from_iterator_generic(
        <S::N as nalgebra::Dim>::from_usize(n),
        nalgebra::U1,
        std::iter::repeat_n(0.0, n),
    )
}

fn robot(fx: &Fixture) -> model::Model {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(&fx.file);
    let options = UrdfOptions {
        floating_base: fx.floating_base,
        ..Default::default()
    };
    model::from_file(path, options).unwrap()
}

fn interpreted(fx: &Fixture) -> TreeSystem {
    TreeSystem::new(&robot(fx)).unwrap()
}

/// `runtime::kinematics` against Pinocchio's frame functions on the fixture's states that
/// carry them (each link's Jacobian, velocity and acceleration in LOCAL,
/// LOCAL_WORLD_ALIGNED and WORLD, its classical acceleration; the centre of mass, its
/// velocity, acceleration and Jacobian), to 1e-9 of each quantity's scale.
fn compare_kinematics(fx: &Fixture, label: &str) {
    let m = robot(fx);
    let mut k = Kinematics::new(&m).unwrap();
    let n = m.variables.len();
    let perm: Vec<usize> = fx
        .variables
        .iter()
        .map(|name| m.variables.iter().position(|v| &v.name == name).unwrap())
        .collect();
    let ours = |x: &[f64]| {
        let mut v = vec![0.0; n];
        for (j, &i) in perm.iter().enumerate() {
            v[i] = x[j];
        }
        v
    };
    let references = [
        ("local", Reference::Local),
        ("local_world_aligned", Reference::LocalWorldAligned),
        ("world", Reference::World),
    ];
    let mut states = 0;
    for (s, state) in fx.states.iter().enumerate() {
        let Some(links) = state.get("frames").and_then(Value::as_object) else {
            continue;
        };
        states += 1;
        let what = |q: &str| format!("{label} state {s}: {q}");
        let (q, v, a) = (
            ours(&numbers(&state["q"])),
            ours(&numbers(&state["v"])),
            ours(&numbers(&state["a"])),
        );
        k.update(&q, Some(&v), Some(&a)).unwrap();
        let mut compared = 0;
        for (link, entry) in links {
            let Ok(f) = k.frame(link) else { continue };
            compared += 1;
            for (name, reference) in references {
                let rows: Vec<Vec<f64>> = entry[format!("jacobian_{name}")]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(numbers)
                    .collect();
                let j = k.jacobian(f, reference);
                let sj = scale(&rows.concat());
                for (r, row) in rows.iter().enumerate() {
                    for (c, &x) in row.iter().enumerate() {
                        let w = what(&format!("`{link}`'s {name} Jacobian ({r}, {c})"));
                        close(j[(r, perm[c])], x, sj, &w);
                    }
                }
                for (key, ours) in [
                    ("velocity", k.velocity(f, reference)),
                    ("acceleration", k.acceleration(f, reference)),
                ] {
                    let theirs = numbers(&entry[format!("{key}_{name}")]);
                    for r in 0..6 {
                        let w = what(&format!("`{link}`'s {name} {key} [{r}]"));
                        close(ours[r], theirs[r], scale(&theirs), &w);
                    }
                }
            }
            let theirs = numbers(&entry["classical_acceleration"]);
            let ours = k.classical_acceleration(f);
            for r in 0..3 {
                let w = what(&format!("`{link}`'s classical acceleration [{r}]"));
                close(ours[r], theirs[r], scale(&theirs), &w);
            }
        }
        assert!(compared + 1 >= links.len(), "{label}: links compared");
        // Pinocchio's centre of mass leaves out the bodies welded to the world (its
        // universe's); ours is every body's: the welded ones are put back into Pinocchio's
        // (they do not move: its velocity, acceleration and Jacobian scale by m_moving/m).
        let (mut welded_mass, mut welded_moment) = (0.0, [0.0; 3]);
        for (f, frame) in m.frames.iter().enumerate() {
            let moves = std::iter::successors(Some(f), |&a| m.frames[a].parent).any(|a| {
                matches!(
                    m.frames[a].joint,
                    model::Joint::Variable(_) | model::Joint::Mimic(_)
                )
            });
            let Some(body) = frame.mass.as_ref().filter(|_| !moves) else {
                continue;
            };
            let pose = k.pose(f);
            let at = pose.rotate(&body.com);
            welded_mass += body.mass;
            for r in 0..3 {
                welded_moment[r] += body.mass * (pose.p[r] + at[r]);
            }
        }
        let com = k.center_of_mass();
        let moving = (com.mass - welded_mass) / com.mass;
        for (key, ours) in [
            ("com", com.position),
            ("vcom", com.velocity),
            ("acom", com.acceleration),
        ] {
            let theirs = numbers(&state[key]);
            for r in 0..3 {
                let welded = if key == "com" {
                    welded_moment[r] / com.mass
                } else {
                    0.0
                };
                let expected = moving * theirs[r] + welded;
                close(ours[r], expected, scale(&theirs), &what(key));
            }
        }
        assert!(
            !fx.floating_base || welded_mass == 0.0,
            "{label}: welded mass"
        );
        let rows: Vec<Vec<f64>> = state["jcom"]
            .as_array()
            .unwrap()
            .iter()
            .map(numbers)
            .collect();
        let j = k.com_jacobian();
        for (r, row) in rows.iter().enumerate() {
            for (c, &x) in row.iter().enumerate() {
                close(
                    j[(r, perm[c])],
                    moving * x,
                    scale(&rows.concat()),
                    &what("jcom"),
                );
            }
        }
    }
    assert!(states >= 2, "{label}: states with kinematics");
}

#[test]
fn ur5_matches_pinocchio() {
    let fx = fixture("ur5");
    compare(interpreted(&fx), &fx, "ur5 interpreted");
    compare(Ur5, &fx, "ur5 compiled");
    compare_kinematics(&fx, "ur5");
}

/// The UR10 of the reach without limits (tasks/ur10-reach.toml), interpreted (its compiled
/// form is the UR5's code with other numbers; benches/reach.rs compiles it).
#[test]
fn ur10_matches_pinocchio() {
    let fx = fixture("ur10");
    compare(interpreted(&fx), &fx, "ur10 interpreted");
    compare_kinematics(&fx, "ur10");
}

#[test]
fn panda_matches_pinocchio() {
    let fx = fixture("panda");
    compare(interpreted(&fx), &fx, "panda interpreted");
    compare(Panda, &fx, "panda compiled");
    compare_kinematics(&fx, "panda");
}

#[test]
fn solo12_with_a_floating_base_matches_pinocchio() {
    let fx = fixture("solo12");
    compare(interpreted(&fx), &fx, "solo12 interpreted");
    compare(Solo12, &fx, "solo12 compiled");
    compare_kinematics(&fx, "solo12");
}

/// The robots' compiled evaluations, pinned (see tests/generated.rs).
#[test]
fn the_robots_statement_counts_are_pinned() {
    assert_eq!(
        [Ur5::STATEMENTS, Panda::STATEMENTS, Solo12::STATEMENTS],
        [1669, 4786, 7317]
    );
}

/// A mimic fixture (tools/reference/pinocchio_mimic.py): the robot without damping (Pinocchio's
/// mimic model has none), the variables in Pinocchio's order, the states.
fn mimic_fixture(name: &str) -> (model::Model, Fixture) {
    let path = format!(
        "{}/tests/fixtures/pinocchio-mimic-{name}.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let fx = Fixture {
        file: v["file"].as_str().unwrap().to_string(),
        floating_base: false,
        variables: v["variables"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_str().unwrap().to_string())
            .collect(),
        states: v["states"].as_array().unwrap().clone(),
    };
    let mut m = robot(&fx);
    assert!(
        m.frames
            .iter()
            .any(|f| matches!(f.joint, tree_mech::model::Joint::Mimic(_))),
        "{name} has mimic joints"
    );
    m.variables.iter_mut().for_each(|v| v.damping = 0.0);
    for f in &mut m.frames {
        if let tree_mech::model::Joint::Mimic(mimic) = &mut f.joint {
            mimic.damping = 0.0;
        }
    }
    (m, fx)
}

/// Against Pinocchio 4.1's mimic joints: M (CRBA), the nonlinear effects and gravity (RNEA),
/// the forward dynamics `M⁻¹(τ − nle)` through the library's own path, the kinetic energy and
/// every link's pose, to 1e-9 of each quantity's scale.
fn compare_mimic<S: System>(mut sys: S, fx: &Fixture, label: &str)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    assert_eq!(n, fx.variables.len(), "{label}: variable count");
    let perm: Vec<usize> = (fx.variables.iter())
        .map(|name| (0..n).find(|&i| sys.variable_name(i) == name).unwrap())
        .collect();
    let mut terms = Terms::zeros(sys.dim());
    let mut dynamics = Dynamics::new(&sys);
    let mut motion = ModelMotions::of(&sys);
    let ours = |x: &[f64]| {
        let mut v = sys_vector::<S>(n);
        for (k, &i) in perm.iter().enumerate() {
            v[i] = x[k];
        }
        v
    };
    for (s, state) in fx.states.iter().enumerate() {
        let what = |q: &str| format!("{label} state {s}: {q}");
        let (q, v, tau) = (
            ours(&numbers(&state["q"])),
            ours(&numbers(&state["v"])),
            ours(&numbers(&state["tau"])),
        );
        sys.lagrangian(&q, &v, Order::Dynamics, &mut terms);
        let m_pin: Vec<Vec<f64>> = state["M"].as_array().unwrap().iter().map(numbers).collect();
        let m_scale = scale(&m_pin.concat());
        for i in 0..n {
            for j in 0..n {
                let ours = terms.mass[(perm[i], perm[j])];
                close(ours, m_pin[i][j], m_scale, &what("M"));
            }
        }
        let nle_pin = numbers(&state["nle"]);
        for i in 0..n {
            let r = perm[i];
            let nle = (0..n).map(|j| terms.d2l_ddq_dq[(r, j)] * v[j]).sum::<f64>() - terms.dl_dq[r];
            close(nle, nle_pin[i], scale(&nle_pin), &what("nle"));
        }
        let kinetic: f64 = 0.5 * (0..n).map(|i| terms.dl_ddq[i] * v[i]).sum::<f64>();
        let t_pin = state["kinetic"].as_f64().unwrap();
        close(
            kinetic,
            t_pin,
            t_pin.abs().max(1.0),
            &what("kinetic energy"),
        );
        let zero = sys_vector::<S>(n);
        sys.lagrangian(&q, &zero, Order::First, &mut terms);
        let g_pin = numbers(&state["g"]);
        for i in 0..n {
            close(
                -terms.dl_dq[perm[i]],
                g_pin[i],
                scale(&g_pin),
                &what("gravity"),
            );
        }
        let mut qdd = sys_vector::<S>(n);
        let mut force = |_t: f64, _q: &Vector<S::N>, _dq: &Vector<S::N>, u: &mut Vector<S::N>| {
            *u += &tau;
        };
        let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
        dynamics.acceleration(&mut cx, &q, &v, &mut qdd).unwrap();
        let ddq_pin = numbers(&state["ddq"]);
        for i in 0..n {
            close(qdd[perm[i]], ddq_pin[i], scale(&ddq_pin), &what("q̈"));
        }
        compare_poses(&mut sys, &q, state, &what(""));
    }
}

/// The Panda with its hand, the second finger following the first (`<mimic>`), against
/// Pinocchio's mimic joints (interpreted; tests/generated.rs holds the compiled Panda with
/// its hand equal to the interpreted).
#[test]
fn panda_with_its_mimic_hand_matches_pinocchio() {
    let (m, fx) = mimic_fixture("panda-hand");
    compare_mimic(TreeSystem::new(&m).unwrap(), &fx, "panda-hand interpreted");
}

/// Baxter: two grippers, each finger mirrored (multiplier −1), interpreted.
#[test]
fn baxter_with_mimic_grippers_matches_pinocchio() {
    let (m, fx) = mimic_fixture("baxter");
    compare_mimic(TreeSystem::new(&m).unwrap(), &fx, "baxter interpreted");
}
