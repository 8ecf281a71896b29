//! Full rigid-body inertias: a centre of mass off the frame origin is the same body on a
//! constant translation; products of inertia are the same body on rotated principal axes;
//! compiled equals interpreted on such bodies.

mod common;

use common::{interpreted, Rng};
use nalgebra::Dyn;
use tree_mech::model::{ModelBuilder, PrimitiveKind::*};
use tree_mech::runtime::Vector;
use tree_mech::{tree_model, Order, System, Terms};

tree_model!(struct Bodies from "tests/models/bodies.toml");

fn terms<S: System<N = Dyn>>(sys: &mut S, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Terms<Dyn> {
    sys.evaluate(q, dq, Order::Full)
}

/// Every Lagrangian term of `a` and `b` at seeded random states, to 1e-12 relative.
fn assert_same_lagrangian(a: &tree_mech::model::Model, b: &tree_mech::model::Model) {
    let (mut sa, mut sb) = (interpreted(a), interpreted(b));
    let n = sa.dof();
    let mut rng = Rng::new(17);
    for _ in 0..5 {
        let q = rng.vector(n, 1.5);
        let dq = rng.vector(n, 2.0);
        let (ta, tb) = (terms(&mut sa, &q, &dq), terms(&mut sb, &q, &dq));
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
        assert!(close(ta.l, tb.l), "L {} vs {}", ta.l, tb.l);
        for i in 0..n {
            assert!(close(ta.dl_dq[i], tb.dl_dq[i]), "dL/dq[{i}]");
            assert!(close(ta.dl_ddq[i], tb.dl_ddq[i]), "dL/dq̇[{i}]");
            for j in 0..n {
                assert!(close(ta.mass[(i, j)], tb.mass[(i, j)]), "M[{i}][{j}]");
                assert!(
                    close(ta.d2l_ddq_dq[(i, j)], tb.d2l_ddq_dq[(i, j)]),
                    "∂²L/∂q̇∂q"
                );
                assert!(close(ta.d2l_dq_dq[(i, j)], tb.d2l_dq_dq[(i, j)]), "∂²L/∂q²");
            }
        }
    }
}

/// An arm on a sliding base: rz, ry, rx joints, so every component of a body matters.
fn arm(last: impl FnOnce(ModelBuilder) -> ModelBuilder) -> tree_mech::model::Model {
    let b = ModelBuilder::new("arm")
        .frame("slide", "world", Ty, "s")
        .frame("yaw", "slide", Rz, "yaw")
        .frame("pitch", "yaw", Ry, "pitch")
        .mass("pitch", 1.0, [0.01, 0.02, 0.03])
        .frame("upper", "pitch", Tz, 0.5)
        .frame("roll", "upper", Rx, "roll");
    last(b).build().unwrap()
}

#[test]
fn a_centre_of_mass_off_the_origin_is_the_body_on_a_constant_translation() {
    let com = [0.1, -0.2, 0.3];
    let moments = [0.02, 0.05, 0.04];
    let offset = arm(|b| b.body("roll", 2.0, com, &moments));
    let chained = arm(|b| {
        b.frame("cx", "roll", Tx, com[0])
            .frame("cy", "cx", Ty, com[1])
            .frame("cz", "cy", Tz, com[2])
            .mass("cz", 2.0, moments)
    });
    assert_same_lagrangian(&offset, &chained);
}

#[test]
fn products_of_inertia_are_the_body_on_rotated_principal_axes() {
    // I = R D Rᵀ with R a rotation by θ about z, then one about x: written in the frame's
    // axes it has every product of inertia.
    let (d, theta, phi) = ([0.03, 0.01, 0.025], 0.4, -0.7);
    let rz = |a: f64| {
        [
            [a.cos(), -a.sin(), 0.0],
            [a.sin(), a.cos(), 0.0],
            [0.0, 0.0, 1.0],
        ]
    };
    let rx = |a: f64| {
        [
            [1.0, 0.0, 0.0],
            [0.0, a.cos(), -a.sin()],
            [0.0, a.sin(), a.cos()],
        ]
    };
    let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
        let mut c = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        c
    };
    let r = mul(rz(theta), rx(phi));
    let mut i = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            i[a][b] = (0..3).map(|k| r[a][k] * d[k] * r[b][k]).sum();
        }
    }
    let six = [i[0][0], i[1][1], i[2][2], i[0][1], i[0][2], i[1][2]];
    assert!(six[3].abs() > 1e-3 && six[4].abs() > 1e-3 && six[5].abs() > 1e-3);
    let tensor = arm(|b| b.body("roll", 1.5, [0.0, 0.0, 0.2], &six));
    let rotated = arm(|b| {
        b.frame("at", "roll", Tz, 0.2)
            .frame("turn", "at", Rz, theta)
            .frame("principal", "turn", Rx, phi)
            .mass("principal", 1.5, d)
    });
    assert_same_lagrangian(&tensor, &rotated);
}

#[test]
fn compiled_full_bodies_equal_interpreted() {
    let mut generated = Bodies;
    let mut interp = interpreted(&Bodies::model());
    let mut rng = Rng::new(3);
    for _ in 0..5 {
        let (qd, dqd) = (rng.vector(4, 1.0), rng.vector(4, 1.0));
        let q = Vector::<nalgebra::Const<4>>::from_column_slice(qd.as_slice());
        let dq = Vector::<nalgebra::Const<4>>::from_column_slice(dqd.as_slice());
        let a = generated.evaluate(&q, &dq, Order::Full);
        let b = interp.evaluate(&qd, &dqd, Order::Full);
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
        assert!(close(a.l, b.l));
        for i in 0..4 {
            assert!(close(a.dl_dq[i], b.dl_dq[i]));
            for j in 0..4 {
                assert!(close(a.mass[(i, j)], b.mass[(i, j)]));
                assert!(close(a.d2l_ddq_dq[(i, j)], b.d2l_ddq_dq[(i, j)]));
                assert!(close(a.d2l_dq_dq[(i, j)], b.d2l_dq_dq[(i, j)]));
            }
        }
    }
}

#[test]
fn the_paper_evaluation_refuses_bodies_it_cannot_sum() {
    let err = tree_mech::PaperSystem::new(&Bodies::model(), tree_mech::PaperEvaluation::Cached)
        .expect_err("refused");
    assert!(err.to_string().contains("frame `base`"), "{err}");
}
