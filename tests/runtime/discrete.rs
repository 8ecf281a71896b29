//! The discrete Lagrangian's slot derivatives (integrate::DiscreteLagrangian, eqs. (22)–(26))
//! against central finite differences of `L_d(q₁, q₂) = Δt L(q₁ + α(q₂ − q₁), (q₂ − q₁)/Δt)`
//! and of its first slot derivatives, at α = ½ and α ≠ ½, on models with every kind of term.

use crate::common;

use common::{load, Rng};
use nalgebra::{DMatrix, Dyn};
use tree_mech::integrate::DiscreteLagrangian;
use tree_mech::runtime::Vector;
use tree_mech::{Order, System, Terms, TreeSystem};

/// The terms of `L` at the quadrature point of `(q₁, q₂)`.
fn terms_at(
    sys: &mut TreeSystem,
    ld: &DiscreteLagrangian,
    q1: &Vector<Dyn>,
    q2: &Vector<Dyn>,
) -> Terms<Dyn> {
    let n = q1.len();
    let (mut qa, mut v) = (Vector::<Dyn>::zeros(n), Vector::<Dyn>::zeros(n));
    ld.point(q1, q2, &mut qa, &mut v);
    sys.evaluate(&qa, &v, Order::Full)
}

fn l_d(sys: &mut TreeSystem, ld: &DiscreteLagrangian, q1: &Vector<Dyn>, q2: &Vector<Dyn>) -> f64 {
    ld.dt * terms_at(sys, ld, q1, q2).l
}

/// `D₁L_d` (slot 1) or `D₂L_d` (slot 2) as a vector.
fn slot(
    sys: &mut TreeSystem,
    ld: &DiscreteLagrangian,
    q1: &Vector<Dyn>,
    q2: &Vector<Dyn>,
    which: usize,
) -> Vector<Dyn> {
    let t = terms_at(sys, ld, q1, q2);
    Vector::<Dyn>::from_fn(q1.len(), |i, _| {
        if which == 1 {
            ld.d1(&t, i)
        } else {
            ld.d2(&t, i)
        }
    })
}

#[test]
fn slot_derivatives_match_finite_differences() {
    let models = ["double-pendulum.toml", "humanoid.toml", "free-body.toml"];
    for (m, name) in models.iter().enumerate() {
        let mut sys = TreeSystem::new(&load(name)).unwrap();
        let n = sys.dof();
        let mut rng = Rng::new(40 + m as u64);
        for alpha in [0.5, 0.3] {
            let ld = DiscreteLagrangian { alpha, dt: 0.05 };
            let q1 = rng.vector(n, 1.0);
            let q2 = &q1 + rng.vector(n, 0.05);
            let h = 1e-6;
            // First slot derivatives against differences of L_d itself.
            for (which, (a, b)) in [(1, (&q1, &q2)), (2, (&q1, &q2))] {
                let exact = slot(&mut sys, &ld, a, b, which);
                for j in 0..n {
                    let (mut plus, mut minus) = if which == 1 {
                        (a.clone(), a.clone())
                    } else {
                        (b.clone(), b.clone())
                    };
                    plus[j] += h;
                    minus[j] -= h;
                    let fd = if which == 1 {
                        (l_d(&mut sys, &ld, &plus, b) - l_d(&mut sys, &ld, &minus, b)) / (2.0 * h)
                    } else {
                        (l_d(&mut sys, &ld, a, &plus) - l_d(&mut sys, &ld, a, &minus)) / (2.0 * h)
                    };
                    let scale = exact.amax().max(1.0);
                    assert!(
                        (fd - exact[j]).abs() < 1e-6 * scale,
                        "{name} α {alpha}: D{which}L_d[{j}] {} vs {fd}",
                        exact[j]
                    );
                }
            }
            // Second slot derivatives against differences of the first.
            let t = terms_at(&mut sys, &ld, &q1, &q2);
            let fill = |f: &dyn Fn(&Terms<Dyn>, &mut [f64])| {
                let mut m = DMatrix::<f64>::zeros(n, n);
                f(&t, m.as_mut_slice());
                m
            };
            let d2d1 = fill(&|t, o| ld.d2d1(t, o));
            let d1d1 = fill(&|t, o| ld.d1d1(t, o));
            let d2d2 = fill(&|t, o| ld.d2d2(t, o));
            for (what, exact, of, by) in [
                ("D₂D₁", &d2d1, 1, 2),
                ("D₁D₁", &d1d1, 1, 1),
                ("D₂D₂", &d2d2, 2, 2),
            ] {
                let scale = exact.amax().max(1.0);
                for j in 0..n {
                    let (mut p1, mut m1, mut p2, mut m2) =
                        (q1.clone(), q1.clone(), q2.clone(), q2.clone());
                    if by == 1 {
                        p1[j] += h;
                        m1[j] -= h;
                    } else {
                        p2[j] += h;
                        m2[j] -= h;
                    }
                    let fd = (slot(&mut sys, &ld, &p1, &p2, of)
                        - slot(&mut sys, &ld, &m1, &m2, of))
                        / (2.0 * h);
                    for i in 0..n {
                        assert!(
                            (fd[i] - exact[(i, j)]).abs() < 1e-5 * scale,
                            "{name} α {alpha}: {what}L_d[{i}][{j}] {} vs {}",
                            exact[(i, j)],
                            fd[i]
                        );
                    }
                }
            }
        }
    }
}
