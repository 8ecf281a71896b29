//! Terms added to an interpreted system from outside its model (`TreeSystem::with_added`,
//! what the trep layer's Python-defined elements use): a model without its springs, damper
//! and constraint, given them back as added terms, is the model with them — its evaluations,
//! its dual-number evaluations, its VI steps, their first and second derivatives, and RK4 runs.

use std::sync::{Arc, Mutex};

use nalgebra::{DMatrix, Dyn};
use tree_mech::integrate::{simulate, Method, MidpointVi, SimOptions, StepContext, ViSettings};
use tree_mech::kernel::{Dual, DualOutputs, Output};
use tree_mech::model;
use tree_mech::runtime::AddedTerms;
use tree_mech::runtime::{Ask, ConstraintTerms, ModelMotions, Terms, Vector};
use tree_mech::{NoForce, Order, System, TreeSystem};

/// A cart carrying a double pendulum; `elements` are the springs, damper and constraint.
fn model(elements: bool) -> model::Model {
    let mut text = String::from(
        r#"
gravity = [0.0, 0.0, -9.81]
[[frame]]
name = "anchor"
ty = 0.4
[[frame]]
name = "cart"
ty = "x"
mass = 2.0
[[frame]]
name = "shoulder"
parent = "cart"
rx = "a"
[[frame]]
name = "upper"
parent = "shoulder"
tz = -1.0
mass = 1.0
[[frame]]
name = "elbow"
parent = "upper"
rx = "b"
[[frame]]
name = "lower"
parent = "elbow"
tz = -0.8
mass = 0.7
[variables.x]
q0 = 0.1
dq0 = 0.3
[variables.a]
q0 = 0.6
damping = 0.05
[variables.b]
q0 = -0.4
dq0 = 0.8
"#,
    );
    if elements {
        text.push_str(
            r#"
[[spring]]
frames = ["anchor", "lower"]
stiffness = 30.0
rest = 0.5
[[spring]]
variable = "b"
stiffness = 4.0
rest = 0.2
[[damper]]
frames = ["anchor", "upper"]
damping = 1.5
[[constraint]]
name = "reach"
kind = "distance"
frames = ["anchor", "lower"]
length = 1.7
"#,
        );
    }
    model::from_toml_str(&text, None).unwrap()
}

/// The springs, damper and constraint as added terms: the whole model's outputs less the bare
/// model's (their masses cancel), and the whole model's constraint rows.
#[derive(Debug)]
struct Difference {
    whole: Mutex<TreeSystem>,
    bare: Mutex<TreeSystem>,
}

/// Every output of the Lagrangian `Ask::Terms` names, at an order.
fn lagrangian_outputs(n: usize, order: Order) -> Vec<Output> {
    let mut outs = vec![Output::L];
    for i in 0..n {
        outs.extend([Output::DlDq(i), Output::Force(i)]);
        if order == Order::Full {
            for j in 0..n {
                outs.extend([
                    Output::D2lDqDq(i, j),
                    Output::DforceDq(i, j),
                    Output::DforceDdq(i, j),
                ]);
            }
        }
    }
    outs
}

impl AddedTerms for Difference {
    fn constraint_names(&self) -> Vec<String> {
        vec!["added reach".into()]
    }

    fn add(
        &self,
        ask: Ask,
        q: &[f64],
        dq: &[f64],
        along: Option<(&[f64], &[f64])>,
        out: &mut dyn FnMut(Output, f64, f64),
    ) {
        let n = q.len();
        let (dir_q, dir_dq) = along.unwrap_or((&[], &[]));
        let zeros = vec![0.0; n];
        let (dir_q, dir_dq) = if along.is_some() {
            (dir_q, dir_dq)
        } else {
            (&zeros[..], &zeros[..])
        };
        let (qd, dqd) = (Dual::seed(q, dir_q), Dual::seed(dq, dir_dq));
        let eval = |sys: &Mutex<TreeSystem>, order: Order| {
            let mut o = DualOutputs::new(n, 1);
            sys.lock().unwrap().evaluate_dual(&qd, &dqd, order, &mut o);
            o
        };
        match ask {
            Ask::Lagrangian | Ask::Terms(_) => {
                let order = match ask {
                    Ask::Terms(order) => order,
                    _ => Order::First,
                };
                let (w, b) = (eval(&self.whole, order), eval(&self.bare, order));
                let outs = match ask {
                    Ask::Lagrangian => vec![Output::L],
                    _ => lagrangian_outputs(n, order),
                };
                for at in outs {
                    let (x, y) = (w.get(at), b.get(at));
                    out(at, x.v - y.v, x.d - y.d);
                }
            }
            Ask::Constraints(order) => {
                let w = eval(&self.whole, order);
                let mut outs = vec![Output::H(0), Output::DhDot(0)];
                for i in 0..n {
                    outs.push(Output::Dh(0, i));
                    if order == Order::Full {
                        outs.extend((0..n).map(|j| Output::D2h(0, i, j)));
                    }
                }
                for at in outs {
                    out(at, w.get(at).v, w.get(at).d);
                }
            }
        }
    }
}

fn systems() -> (TreeSystem, TreeSystem) {
    let whole = TreeSystem::new(&model(true)).unwrap();
    let difference = Difference {
        whole: Mutex::new(whole.clone()),
        bare: Mutex::new(TreeSystem::new(&model(false)).unwrap()),
    };
    let added = TreeSystem::new(&model(false))
        .unwrap()
        .with_added(Arc::new(difference));
    (whole, added)
}

fn close(a: &DMatrix<f64>, b: &DMatrix<f64>, what: &str) {
    let scale = a.amax().max(1.0);
    let gap = (a - b).amax();
    assert!(
        gap <= 1e-12 * scale,
        "{what}: {gap:e} apart (scale {scale:e})\n{a}\n{b}"
    );
}

fn state() -> (Vector<Dyn>, Vector<Dyn>) {
    (
        Vector::<Dyn>::from_vec(vec![0.1, 0.6, -0.4]),
        Vector::<Dyn>::from_vec(vec![0.3, -0.2, 0.8]),
    )
}

#[test]
fn added_terms_evaluate_as_the_model_elements_they_replace() {
    let (mut whole, mut added) = systems();
    assert_eq!(added.constraint_count(), 1);
    assert_eq!(added.constraint_name(0), "added reach");
    let (q, dq) = state();
    let (a, b) = (
        whole.evaluate(&q, &dq, Order::Full),
        added.evaluate(&q, &dq, Order::Full),
    );
    let v = |x: f64| DMatrix::from_element(1, 1, x);
    close(&v(a.l), &v(b.l), "L");
    for (x, y, what) in [
        (&a.dl_dq, &b.dl_dq, "∂L/∂q"),
        (&a.dl_ddq, &b.dl_ddq, "∂L/∂q̇"),
        (&a.force, &b.force, "F"),
    ] {
        close(
            &DMatrix::from_column_slice(3, 1, x.as_slice()),
            &DMatrix::from_column_slice(3, 1, y.as_slice()),
            what,
        );
    }
    for (x, y, what) in [
        (&a.mass, &b.mass, "M"),
        (&a.d2l_dq_dq, &b.d2l_dq_dq, "∂²L/∂q²"),
        (&a.d2l_ddq_dq, &b.d2l_ddq_dq, "∂²L/∂q̇∂q"),
        (&a.dforce_dq, &b.dforce_dq, "∂F/∂q"),
        (&a.dforce_ddq, &b.dforce_ddq, "∂F/∂q̇"),
    ] {
        close(
            &DMatrix::from_column_slice(3, 3, x.as_slice()),
            &DMatrix::from_column_slice(3, 3, y.as_slice()),
            what,
        );
    }
    let (mut ta, mut tb) = (Terms::zeros(Dyn(3)), Terms::zeros(Dyn(3)));
    close(
        &v(whole.energy(&q, &dq, &mut ta)),
        &v(added.energy(&q, &dq, &mut tb)),
        "energy",
    );
    whole.mass_matrix(&q, &mut ta);
    added.mass_matrix(&q, &mut tb);
    close(&v(ta.l), &v(tb.l), "L(q, 0)");
    let (mut ca, mut cb) = (ConstraintTerms::zeros(1, 3), ConstraintTerms::zeros(1, 3));
    whole.constraints(&q, &dq, Order::Full, &mut ca);
    added.constraints(&q, &dq, Order::Full, &mut cb);
    close(&ca.dh, &cb.dh, "Dh");
    close(&ca.d2h[0], &cb.d2h[0], "D²h");
    whole.weighted_constraint_hessian(&q, &[0.7], &mut ca);
    added.weighted_constraint_hessian(&q, &[0.7], &mut cb);
    close(&ca.weighted_d2h, &cb.weighted_d2h, "Σ w D²h");
    // Over dual numbers, along a direction: what the second derivatives differentiate.
    let (dir_q, dir_dq) = ([0.3, -1.1, 0.4], [0.9, 0.2, -0.5]);
    let (da, db) = (
        whole.directional(q.as_slice(), dq.as_slice(), &dir_q, &dir_dq, Order::Full),
        added.directional(q.as_slice(), dq.as_slice(), &dir_q, &dir_dq, Order::Full),
    );
    let mut outs = lagrangian_outputs(3, Order::Full);
    outs.extend([
        Output::H(0),
        Output::DhDot(0),
        Output::Dh(0, 2),
        Output::D2h(0, 1, 2),
    ]);
    for at in outs {
        let (x, y) = (da.get(at), db.get(at));
        let gap = (x.v - y.v).abs().max((x.d - y.d).abs());
        assert!(
            gap <= 1e-12 * x.v.abs().max(x.d.abs()).max(1.0),
            "{at:?}: {x:?} against {y:?}"
        );
    }
}

#[test]
fn added_terms_step_and_differentiate_as_the_model_elements_they_replace() {
    let (mut whole, mut added) = systems();
    // Runs: the VI (its Newton, the constraint) and RK4 (the articulated-body path steps aside).
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let options = SimOptions::new(method, 0.01, 1.0);
        let (q0, dq0) = whole.initial_state();
        let a = simulate(&mut whole, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
        let b = simulate(&mut added, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
        let (x, y) = (a.last_q(), b.last_q());
        for i in 0..3 {
            assert!(
                (x[i] - y[i]).abs() < 1e-10,
                "{method:?}: {x:?} against {y:?}"
            );
        }
    }
    // One step's first and second derivatives.
    let (q1, _) = state();
    let derivatives = |sys: &mut TreeSystem| {
        let mut vi = MidpointVi::new(sys, ViSettings::default());
        vi.predict_from_rest();
        let mut motion = ModelMotions::of(sys);
        let mut force = NoForce;
        let p1 = Vector::<Dyn>::from_vec(vec![0.5, -0.2, 0.3]);
        let mut cx = StepContext::new(sys, &mut force, &mut motion, 0.05);
        let (mut q, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
        vi.step(&mut cx, &mut q, &mut p, &mut next).unwrap();
        let (first, second) = vi.second_derivatives(&mut cx, &q1, &p1, &q).unwrap();
        (first, second)
    };
    let ((fa, sa), (fb, sb)) = (derivatives(&mut whole), derivatives(&mut added));
    close(&fa.q2_dq1, &fb.q2_dq1, "∂q₂/∂q₁");
    close(&fa.p2_dp1, &fb.p2_dp1, "∂p₂/∂p₁");
    close(&fa.lambda_dq1, &fb.lambda_dq1, "∂λ/∂q₁");
    for k in 0..sa.q2.len() {
        let scale = sa.q2[k].amax().max(1.0);
        assert!(
            (&sa.q2[k] - &sb.q2[k]).amax() < 1e-9 * scale,
            "∂²q₂ block {k}"
        );
        assert!(
            (&sa.p2[k] - &sb.p2[k]).amax() < 1e-9 * scale,
            "∂²p₂ block {k}"
        );
    }
}
