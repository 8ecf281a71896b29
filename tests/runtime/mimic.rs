//! Mimic frames (a transform driven by `multiplier·q + offset` of another frame's variable)
//! against the same tree with each mimic frame given a variable of its own: at
//! `q_full = A q + b`, `q̇_full = A q̇`, the Lagrangian is the same number and every derivative
//! is the full model's contracted by `A` — `∂L/∂q = Aᵀ ∂L_full/∂q_full`, `M = Aᵀ M_full A`, and
//! so on for the forces and the constraints (docs/derivations.md §12). The full model is
//! evaluated by the sweeps as any model is, so the contraction is checked against an
//! evaluation that has no mimic in it.

use crate::common::{assert_close, Rng};
use nalgebra::{DMatrix, DVector};
use tree_mech::model::{self, Model};
use tree_mech::{ConstraintTerms, Order, System, Terms, TreeSystem};

const MIMIC: &str = include_str!("../models/mimic.toml");

/// Each mimic of tests/models/mimic.toml: its table, and the variable that replaces it in the
/// full model, with the multiplier, offset and damping the table says.
const MIMICS: [(&str, &str, f64, f64, f64); 2] = [
    (
        r#"{ mimic = "reach", multiplier = -0.5, offset = 0.2, damping = 0.3 }"#,
        "tilt_q",
        -0.5,
        0.2,
        0.3,
    ),
    (
        r#"{ mimic = "grip", multiplier = -1.0 }"#,
        "finger_q",
        -1.0,
        0.0,
        0.0,
    ),
];

/// A distance constraint from the mirrored finger to the post (so `Dh` and `D²h` reach the
/// follower), appended to both models.
const STRING: &str = "\n[[constraint]]\nname = \"string\"\nkind = \"distance\"\nframes = [\"finger_b\", \"post\"]\nlength = 0.7\n";

fn models() -> (Model, Model) {
    let mimic = model::from_toml_str(&format!("{MIMIC}{STRING}"), None).unwrap();
    let mut text = MIMIC.to_string();
    for (table, name, _, _, damping) in MIMICS {
        assert!(text.contains(table), "mimic.toml as this test knows it");
        text = text.replace(table, &format!("\"{name}\""));
        text += &format!("\n[variables.{name}]\ndamping = {damping}\n");
    }
    let full = model::from_toml_str(&format!("{text}{STRING}"), None).unwrap();
    (mimic, full)
}

/// `A`: the full model's variables (rows) as the mimic model's (columns).
fn contraction(mimic: &Model, full: &Model) -> (DMatrix<f64>, DVector<f64>) {
    let (n, nf) = (mimic.variables.len(), full.variables.len());
    let mut a = DMatrix::zeros(nf, n);
    let mut b = DVector::zeros(nf);
    for (r, v) in full.variables.iter().enumerate() {
        match mimic.variable_index(&v.name) {
            Some(c) => a[(r, c)] = 1.0,
            None => {
                let (_, _, leader, m, o) = MIMICS
                    .iter()
                    .map(|&(t, name, m, o, _)| (t, name, leader_of(t), m, o))
                    .find(|x| x.1 == v.name)
                    .unwrap();
                a[(r, mimic.variable_index(leader).unwrap())] = m;
                b[r] = o;
            }
        }
    }
    (a, b)
}

fn leader_of(table: &str) -> &str {
    table.split('"').nth(1).unwrap()
}

#[track_caller]
fn same(ours: &DMatrix<f64>, contracted: &DMatrix<f64>, what: &str) {
    let scale = contracted.amax().max(1.0);
    for (x, y) in ours.iter().zip(contracted.iter()) {
        assert_close(*x, *y, 1e-12 * scale, what);
    }
}

#[test]
fn a_mimic_model_is_its_full_model_contracted() {
    let (mimic, full) = models();
    let (a, b) = contraction(&mimic, &full);
    let (n, nf) = (a.ncols(), a.nrows());
    assert_eq!((n, nf), (3, 5));
    let mut sys = TreeSystem::new(&mimic).unwrap();
    let mut whole = TreeSystem::new(&full).unwrap();
    let mut rng = Rng::new(12);
    for trial in 0..4 {
        let what = |x: &str| format!("trial {trial}: {x}");
        let (q, dq) = (rng.vector(n, 1.0), rng.vector(n, 2.0));
        let (qf, dqf) = (&a * &q + &b, &a * &dq);
        let mut t = Terms::zeros(sys.dim());
        let mut tf = Terms::zeros(whole.dim());
        sys.lagrangian(&q, &dq, Order::Full, &mut t);
        whole.lagrangian(&qf, &dqf, Order::Full, &mut tf);
        assert_close(t.l, tf.l, 1e-12, &what("L"));
        let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
        let at = a.transpose();
        same(
            &column(&t.dl_dq),
            &(&at * column(&tf.dl_dq)),
            &what("∂L/∂q"),
        );
        same(
            &column(&t.dl_ddq),
            &(&at * column(&tf.dl_ddq)),
            &what("∂L/∂q̇"),
        );
        same(&column(&t.force), &(&at * column(&tf.force)), &what("F"));
        for (ours, theirs, name) in [
            (&t.mass, &tf.mass, "M"),
            (&t.d2l_ddq_dq, &tf.d2l_ddq_dq, "∂²L/∂q̇∂q"),
            (&t.d2l_dq_dq, &tf.d2l_dq_dq, "∂²L/∂q²"),
            (&t.dforce_dq, &tf.dforce_dq, "∂F/∂q"),
            (&t.dforce_ddq, &tf.dforce_ddq, "∂F/∂q̇"),
        ] {
            same(ours, &(&at * theirs * &a), &what(name));
        }
        let mut c = ConstraintTerms::zeros(1, n);
        let mut cf = ConstraintTerms::zeros(1, nf);
        sys.constraints(&q, &dq, Order::Full, &mut c);
        whole.constraints(&qf, &dqf, Order::Full, &mut cf);
        assert_close(c.h[0], cf.h[0], 1e-12, &what("h"));
        assert_close(c.dh_dot[0], cf.dh_dot[0], 1e-12, &what("q̇ᵀD²h q̇"));
        same(&c.dh, &(&cf.dh * &a), &what("Dh"));
        same(&c.d2h[0], &(&at * &cf.d2h[0] * &a), &what("D²h"));
        // The energy and the poses, the same numbers.
        let e = sys.energy(&q, &dq, &mut t);
        assert_close(e, whole.energy(&qf, &dqf, &mut tf), 1e-12, &what("energy"));
        let mut poses = vec![tree_mech::runtime::Pose::IDENTITY; sys.frame_count()];
        let mut poses_full = poses.clone();
        sys.poses(&q, &mut poses);
        whole.poses(&qf, &mut poses_full);
        for (p, pf) in poses.iter().zip(&poses_full) {
            for (x, y) in p
                .matrix()
                .iter()
                .flatten()
                .zip(pf.matrix().iter().flatten())
            {
                assert_close(*x, *y, 1e-14, &what("pose"));
            }
        }
    }
}

/// The frames' body velocities and Jacobian columns (`frame_velocities`, the kinematics'
/// Jacobians) fold a mimic frame's column into its leader's: the velocity is `J q̇` with the
/// model's `q̇`.
#[test]
fn a_mimic_frames_jacobian_folds_into_its_leaders_column() {
    let (mimic, full) = models();
    let (a, b) = contraction(&mimic, &full);
    let mut kin = tree_mech::runtime::kinematics::Kinematics::new(&mimic).unwrap();
    let mut kin_full = tree_mech::runtime::kinematics::Kinematics::new(&full).unwrap();
    let mut rng = Rng::new(3);
    let (q, dq) = (rng.vector(3, 1.0), rng.vector(3, 1.0));
    let (qf, dqf) = (&a * &q + &b, &a * &dq);
    kin.update(q.as_slice(), Some(dq.as_slice()), None).unwrap();
    kin_full
        .update(qf.as_slice(), Some(dqf.as_slice()), None)
        .unwrap();
    let reference = tree_mech::runtime::kinematics::Reference::LocalWorldAligned;
    for name in ["finger_a", "finger_b", "arm"] {
        let (f, ff) = (kin.frame(name).unwrap(), kin_full.frame(name).unwrap());
        let j = kin.jacobian(f, reference);
        same(&j, &(kin_full.jacobian(ff, reference) * &a), name);
        let v = kin.velocity(f, reference);
        let jv = &j * &dq;
        for r in 0..6 {
            assert_close(v[r], jv[r], 1e-12, &format!("{name}: J q̇"));
        }
    }
    same(
        &kin.com_jacobian(),
        &(kin_full.com_jacobian() * &a),
        "∂c/∂q",
    );
}

/// Every way a mimic is refused names the frame and what is wrong.
#[test]
fn a_mimic_that_cannot_be_is_refused_naming_it() {
    let cases = [
        (
            MIMIC.replace(r#"mimic = "grip""#, r#"mimic = "gripp""#),
            "frame `finger_b` mimics variable `gripp`, which drives no frame",
        ),
        (
            MIMIC.replace("multiplier = -1.0 }", "multiplier = nan }"),
            "frame `finger_b`: the mimic's multiplier NaN is not finite",
        ),
        (
            MIMIC.replace("damping = 0.3", "damping = -0.3"),
            "frame `tilt`: the mimic's damping -0.3 must be a finite number, not negative",
        ),
        (
            MIMIC.replace("multiplier = -1.0 }", "multiplier = -1.0, gain = 2 }"),
            "unknown field `gain`, expected one of `mimic`, `multiplier`, `offset`, `damping`",
        ),
    ];
    for (text, expected) in cases {
        let err = model::from_toml_str(&text, None).unwrap_err().to_string();
        assert!(err.contains(expected), "{err}\n  expected: {expected}");
        assert!(err.contains("line "), "the line is named: {err}");
    }
}
