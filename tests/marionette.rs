//! The marionette (models/marionette.toml): compiled equals interpreted on every output and
//! over a whole 10 s VI run, the strings hold to 1e-9 and stay taut, and RK4 drifts off them.

mod common;

use common::{interpreted, load, simulate_from_start, Rng};
use nalgebra::Const;
use tree_mech::integrate::{Method, SimOptions, StepContext, ViSettings};
use tree_mech::kernel::Field;
use tree_mech::kernel::{Dual, DualOutputs};
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::{Dynamics, ModelMotions, Vector};
use tree_mech::{tree_model, ConstraintTerms, NoForce, Order, System, Trajectory};

tree_model!(struct Marionette from "models/marionette.toml");

const N: usize = Marionette::DOF;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
}

#[test]
fn the_marionette_has_the_shape_the_issue_asks_for() {
    let model = load("marionette.toml");
    assert_eq!(N, 42);
    assert_eq!(model.kinematic().len(), 18);
    assert_eq!(Marionette::CONSTRAINTS.len(), 6);
    assert_eq!(model.springs.len(), 4);
    assert_eq!(model.dampers.len(), 1);
}

#[test]
fn compiled_marionette_equals_interpreted_on_every_output() {
    let mut generated = Marionette;
    let mut interp = interpreted(&Marionette::model());
    let m = Marionette::CONSTRAINTS.len();
    let mut rng = Rng::new(42);
    for trial in 0..5 {
        let qd = rng.vector(N, 1.0);
        let dqd = rng.vector(N, 1.0);
        let q = Vector::<Const<N>>::from_column_slice(qd.as_slice());
        let dq = Vector::<Const<N>>::from_column_slice(dqd.as_slice());
        for order in [Order::First, Order::Dynamics, Order::Full] {
            let a = generated.evaluate(&q, &dq, order);
            let b = interp.evaluate(&qd, &dqd, order);
            let what = format!("trial {trial} {order:?}");
            assert!(close(a.l, b.l, 1e-12), "L {what}");
            for i in 0..N {
                assert!(close(a.dl_dq[i], b.dl_dq[i], 1e-12), "dL/dq[{i}] {what}");
                assert!(close(a.dl_ddq[i], b.dl_ddq[i], 1e-12), "dL/dq̇[{i}] {what}");
                assert!(close(a.force[i], b.force[i], 1e-12), "F[{i}] {what}");
                for j in 0..N {
                    if order >= Order::Dynamics {
                        assert!(close(a.mass[(i, j)], b.mass[(i, j)], 1e-12), "M {what}");
                        assert!(
                            close(a.d2l_ddq_dq[(i, j)], b.d2l_ddq_dq[(i, j)], 1e-12),
                            "∂²L/∂q̇∂q {what}"
                        );
                        assert!(
                            close(a.dforce_ddq[(i, j)], b.dforce_ddq[(i, j)], 1e-12),
                            "∂F/∂q̇ {what}"
                        );
                    }
                    if order >= Order::Full {
                        assert!(
                            close(a.d2l_dq_dq[(i, j)], b.d2l_dq_dq[(i, j)], 1e-12),
                            "∂²L/∂q² {what}"
                        );
                        assert!(
                            close(a.dforce_dq[(i, j)], b.dforce_dq[(i, j)], 1e-12),
                            "∂F/∂q {what}"
                        );
                    }
                }
            }
            for r in 0..m {
                assert_eq!(
                    generated.constraint_variables(r),
                    interp.constraint_variables(r)
                );
            }
            let mut ca = ConstraintTerms::zeros(m, N);
            let mut cb = ConstraintTerms::zeros(m, N);
            generated.constraints(&q, &dq, order, &mut ca);
            interp.constraints(&qd, &dqd, order, &mut cb);
            for r in 0..m {
                assert!(close(ca.h[r], cb.h[r], 1e-12), "h[{r}] {what}");
                assert!(close(ca.dh_dot[r], cb.dh_dot[r], 1e-12), "q̇ᵀD²hq̇ {what}");
                for i in 0..N {
                    assert!(close(ca.dh[(r, i)], cb.dh[(r, i)], 1e-12), "Dh {what}");
                    if order >= Order::Full {
                        for j in 0..N {
                            assert!(close(ca.d2h[r][(i, j)], cb.d2h[r][(i, j)], 1e-12), "D²h");
                        }
                    }
                }
            }
        }
    }
}

fn ten_seconds(method: Method) -> (Trajectory, Trajectory) {
    let options = SimOptions::new(method, 0.01, 10.0);
    let a = simulate_from_start(&mut Marionette, &options);
    let b = simulate_from_start(&mut interpreted(&Marionette::model()), &options);
    (a, b)
}

#[test]
fn ten_seconds_of_vi_compiled_and_interpreted_agree_and_hold_the_strings() {
    let (a, b) = ten_seconds(Method::Vi(ViSettings::default()));
    assert_eq!(a.len(), 1001);
    assert_eq!(b.len(), 1001);
    assert_eq!(a.subdivided_steps, 0);
    for k in 0..a.len() {
        for i in 0..N {
            assert!(close(a.q(k)[i], b.q(k)[i], 1e-9), "q[{i}] at step {k}");
            assert!(close(a.dq(k)[i], b.dq(k)[i], 1e-9), "q̇[{i}] at step {k}");
        }
        for r in 0..6 {
            assert!(
                close(a.lambda(k)[r], b.lambda(k)[r], 1e-9),
                "λ[{r}] step {k}"
            );
            // The puppeteer keeps every string taut: λ < 0 in trep's sign convention.
            assert!(a.lambda(k)[r] < 0.0, "string {r} slack at step {k}");
        }
        assert!(
            a.violation[k] < 1e-9,
            "violation {} at step {k}",
            a.violation[k]
        );
        assert!(
            b.violation[k] < 1e-9,
            "violation {} at step {k}",
            b.violation[k]
        );
    }
}

/// RK4 integrates the same equations at the same Δt, but the constraints only through their
/// acceleration (q̇ᵀD²hq̇ + Dh q̈ = 0), so the strings' lengths drift: the violation grows far
/// past the VI's, though it stays small over 10 s.
#[test]
fn rk4_at_the_same_step_drifts_off_the_strings() {
    let (a, b) = ten_seconds(Method::Rk4);
    let worst = a.worst_violation();
    assert!(worst > 1e-7 && worst < 1e-3, "RK4 violation {worst}");
    for k in 0..a.len() {
        for i in 0..N {
            assert!(close(a.q(k)[i], b.q(k)[i], 1e-9), "RK4 q[{i}] at step {k}");
        }
    }
}

/// The marionette's compiled evaluation, pinned (see tests/generated.rs).
#[test]
fn the_marionettes_statement_count_is_pinned() {
    assert_eq!(Marionette::STATEMENTS, 12888);
}

/// `Σ_r w_r D²h_r` on the dynamic variables' columns (what a step's first derivatives read at
/// `q₁`), compiled, interpreted and by the trait's default (a wrapper that leaves the method
/// out): the rows' Hessians weighted and summed.
#[test]
fn the_weighted_constraint_hessian_is_the_rows_hessians_summed() {
    let model = load("marionette.toml");
    common::check_weighted_hessian(&mut Marionette, 5, 1e-13);
    common::check_weighted_hessian(&mut interpreted(&model), 5, 1e-13);
    common::check_weighted_hessian(
        &mut Summing {
            inner: interpreted(&model),
        },
        5,
        1e-13,
    );
}

/// The continuous dynamics' own terms (RK4's stages, the continuous linearisation) are kept
/// for the compiled evaluation: after its first acceleration the next skips clearing `M` — a
/// mark put on `M`'s zeros (small: `M` stays positive definite) survives it — while every
/// entry it writes is as a fresh workspace's, and with the zeros back `q̈` is a fresh
/// workspace's to the bit.
#[test]
fn the_continuous_dynamics_keep_their_terms_zeros() {
    let mut sys = Marionette;
    let mut rng = Rng::new(13);
    let mut motion = ModelMotions::of(&sys);
    let (q0, dq0) = sys.initial_state();
    let mut state = || {
        let (mut q, mut dq) = (q0, dq0);
        for i in (0..N).filter(|&i| !Marionette::KINEMATIC[i]) {
            q[i] += 0.2 * (rng.uniform() - 0.5);
            dq[i] += rng.uniform() - 0.5;
        }
        (q, dq)
    };
    let (a, b) = (state(), state());
    let (mut kept, mut fresh) = (Dynamics::new(&sys), Dynamics::new(&sys));
    let (mut qdd, mut expected) = (Vector::<Const<N>>::zeros(), Vector::<Const<N>>::zeros());
    let mut no_force = NoForce;
    let mut cx = StepContext::new(&mut sys, &mut no_force, &mut motion, 0.01);
    kept.acceleration(&mut cx, &a.0, &a.1, &mut qdd).unwrap();
    let (mut scratch, mark) = (kept.terms.mass, 1e-12);
    let zeros = common::mark_zeros(kept.terms.mass.as_mut_slice(), scratch.as_mut_slice(), mark);
    kept.acceleration(&mut cx, &b.0, &b.1, &mut qdd).unwrap();
    fresh
        .acceleration(&mut cx, &b.0, &b.1, &mut expected)
        .unwrap();
    let unwritten = common::unwritten(kept.terms.mass.as_mut_slice(), &zeros, mark);
    assert!(!unwritten.is_empty(), "the clearing was skipped");
    assert!(
        kept.terms == fresh.terms,
        "every written entry as fresh terms have it"
    );
    kept.acceleration(&mut cx, &b.0, &b.1, &mut qdd).unwrap();
    assert_eq!(qdd, expected);
}

/// Constraint terms kept for the compiled weighted sum (a linearisation's own,
/// `ConstraintTerms::keep_zeros`) skip clearing it only when the model's own sum wrote it
/// last: every entry the constraints reach is then as fresh terms have it, and an entry they
/// never reach keeps what another writer left; after `weigh` (what the interpreted and the
/// default evaluations begin with) the next sum clears all. Terms not kept are cleared on
/// every sum.
#[test]
fn kept_weighted_sums_skip_clearing_only_after_their_own_evaluation() {
    let mut sys = Marionette;
    let mut rng = Rng::new(11);
    let m = sys.constraint_count();
    let mut point = || {
        let q = Vector::<Const<N>>::from_fn(|_, _| rng.uniform() - 0.5);
        let w: Vec<f64> = (0..m).map(|_| rng.uniform() - 0.5).collect();
        (q, w)
    };
    let (a, b) = (point(), point());
    let sum =
        |sys: &mut Marionette, (q, w): &(Vector<Const<N>>, Vec<f64>), out: &mut ConstraintTerms| {
            sys.weighted_constraint_hessian(q, w, out);
        };
    let mut at_b = ConstraintTerms::of(&sys);
    sum(&mut sys, &b, &mut at_b);
    let mut kept = ConstraintTerms::of(&sys);
    kept.keep_zeros();
    let mut plain = ConstraintTerms::of(&sys);
    sum(&mut sys, &a, &mut kept);
    sum(&mut sys, &a, &mut plain);
    let (kept_sum, plain_sum) = (&mut kept.weighted_d2h, &mut plain.weighted_d2h);
    let zeros = common::mark_zeros(kept_sum.as_mut_slice(), plain_sum.as_mut_slice(), 7.0);
    sum(&mut sys, &b, &mut kept);
    sum(&mut sys, &b, &mut plain);
    assert!(
        plain.weighted_d2h == at_b.weighted_d2h,
        "terms not kept are cleared"
    );
    let unreached = common::unwritten(kept.weighted_d2h.as_mut_slice(), &zeros, 7.0);
    assert!(!unreached.is_empty(), "the clearing was skipped");
    assert!(
        kept.weighted_d2h == at_b.weighted_d2h,
        "every reached entry as fresh terms have it"
    );
    kept.weigh(&b.1, true);
    kept.weighted_d2h.as_mut_slice()[unreached[0]] = 7.0;
    sum(&mut sys, &b, &mut kept);
    assert!(kept.weighted_d2h == at_b.weighted_d2h, "after weigh");
}

/// A system that evaluates as the interpreted one but weighs constraint Hessians by the
/// trait's default.
struct Summing {
    inner: tree_mech::TreeSystem,
}

impl System for Summing {
    type N = nalgebra::Dyn;
    delegate_description!(inner);
    fn lagrangian(
        &mut self,
        q: &Vector<nalgebra::Dyn>,
        dq: &Vector<nalgebra::Dyn>,
        order: Order,
        out: &mut tree_mech::Terms<nalgebra::Dyn>,
    ) {
        self.inner.lagrangian(q, dq, order, out)
    }
}

/// The constraints alone over dual numbers (what a step's second derivatives differentiate at
/// `q₁` and `q₂`) are, compiled and interpreted, the whole dual evaluation's constraint
/// outputs, value and derivative, with the Lagrangian's left zero.
#[test]
fn constraints_over_duals_alone_are_the_whole_evaluations() {
    let model = load("marionette.toml");
    constraints_alone(&mut Marionette::new());
    constraints_alone(&mut interpreted(&model));
}

fn constraints_alone<S: System>(sys: &mut S)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut rng = Rng::new(17);
    let (q, dq) = (rng.vector(N, 0.5), rng.vector(N, 0.7));
    let (dir_q, dir_dq) = (rng.vector(N, 1.0), rng.vector(N, 1.0));
    let q = Dual::seed(q.as_slice(), dir_q.as_slice());
    let dq = Dual::seed(dq.as_slice(), dir_dq.as_slice());
    let rows = sys.constraint_count();
    for order in [Order::First, Order::Dynamics, Order::Full] {
        let (mut whole, mut alone) = (DualOutputs::new(N, rows), DualOutputs::new(N, rows));
        sys.evaluate_dual(&q, &dq, order, &mut whole);
        sys.constraints_dual(&q, &dq, order, &mut alone);
        for field in [Field::H, Field::Dh, Field::DhDot, Field::D2h] {
            for (a, b) in whole.field(field).iter().zip(alone.field(field)) {
                assert_eq!((a.v, a.d), (b.v, b.d), "{field:?} at {order:?}");
            }
        }
        if order == Order::Full {
            assert!(alone.field(Field::D2h).iter().any(|x| x.d != 0.0));
        }
        for field in [Field::L, Field::DlDq, Field::Mass, Field::D2lDqDq] {
            let zero = |x: &Dual| x.v == 0.0 && x.d == 0.0;
            assert!(
                alone.field(field).iter().all(zero),
                "{field:?} at {order:?}"
            );
        }
    }
}
