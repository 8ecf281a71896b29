//! Constraints, springs, dampers and kinematic variables: derivatives against finite
//! differences, compiled equal to interpreted, and analytic cases.

use crate::common;

use common::{assert_close, interpreted, simulate_from_start, Rng};
use nalgebra::Dyn;
use tree_mech::integrate::{run, simulate, Method, SimOptions, Tolerance, ViSettings};
use tree_mech::model::{self, Model};
use tree_mech::runtime::{ModelMotions, Vector};
use tree_mech::{tree_model as compile, ConstraintTerms, NoForce, Order, System, Terms};

compile!(struct Elements from "tests/models/elements.toml");
compile!(struct StringPendulum from "tests/models/string-pendulum.toml");

fn elements() -> Model {
    Elements::model()
}

const H: f64 = 1e-6;

fn constraints_at<S: System<N = Dyn>>(
    sys: &mut S,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
) -> ConstraintTerms {
    let mut c = ConstraintTerms::zeros(sys.constraint_count(), sys.dof());
    sys.constraints(q, dq, Order::Full, &mut c);
    c
}

fn terms_at<S: System<N = Dyn>>(sys: &mut S, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Terms<Dyn> {
    sys.evaluate(q, dq, Order::Full)
}

#[test]
fn constraint_derivatives_match_finite_differences() {
    for model in [elements(), StringPendulum::model()] {
        let mut sys = interpreted(&model);
        let (n, m) = (sys.dof(), sys.constraint_count());
        let mut rng = Rng::new(5);
        for trial in 0..3 {
            let q = rng.vector(n, 1.0);
            let dq = rng.vector(n, 1.0);
            let c = constraints_at(&mut sys, &q, &dq);
            for j in 0..n {
                let (mut qp, mut qm) = (q.clone(), q.clone());
                qp[j] += H;
                qm[j] -= H;
                let (cp, cm) = (
                    constraints_at(&mut sys, &qp, &dq),
                    constraints_at(&mut sys, &qm, &dq),
                );
                for r in 0..m {
                    let what = format!("{} trial {trial} row {r} column {j}", model.name);
                    let fd = (cp.h[r] - cm.h[r]) / (2.0 * H);
                    assert_close(c.dh[(r, j)], fd, 1e-6, &format!("Dh {what}"));
                    for i in 0..n {
                        let fd = (cp.dh[(r, i)] - cm.dh[(r, i)]) / (2.0 * H);
                        assert_close(c.d2h[r][(i, j)], fd, 1e-6, &format!("D2h[{i}] {what}"));
                    }
                }
            }
            for r in 0..m {
                let expected = dq.dot(&(&c.d2h[r] * &dq));
                assert_close(c.dh_dot[r], expected, 1e-12, "q̇ᵀD²h q̇");
            }
        }
    }
}

#[test]
fn springs_and_forces_match_finite_differences() {
    let model = elements();
    let mut sys = interpreted(&model);
    let n = sys.dof();
    let mut rng = Rng::new(8);
    for _ in 0..3 {
        let q = rng.vector(n, 1.0);
        let dq = rng.vector(n, 1.0);
        let t = terms_at(&mut sys, &q, &dq);
        for j in 0..n {
            for (x, is_q) in [(&q, true), (&dq, false)] {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[j] += H;
                xm[j] -= H;
                let (tp, tm) = if is_q {
                    (terms_at(&mut sys, &xp, &dq), terms_at(&mut sys, &xm, &dq))
                } else {
                    (terms_at(&mut sys, &q, &xp), terms_at(&mut sys, &q, &xm))
                };
                let fd_l = (tp.l - tm.l) / (2.0 * H);
                let l = if is_q { t.dl_dq[j] } else { t.dl_ddq[j] };
                assert_close(
                    l,
                    fd_l,
                    1e-6,
                    &format!("dL/d{} [{j}]", if is_q { "q" } else { "q̇" }),
                );
                for i in 0..n {
                    let fd = (tp.force[i] - tm.force[i]) / (2.0 * H);
                    let d = if is_q {
                        t.dforce_dq[(i, j)]
                    } else {
                        t.dforce_ddq[(i, j)]
                    };
                    assert_close(
                        d,
                        fd,
                        1e-6,
                        &format!("dF[{i}]/d{} [{j}]", if is_q { "q" } else { "q̇" }),
                    );
                    if is_q {
                        let fd = (tp.dl_dq[i] - tm.dl_dq[i]) / (2.0 * H);
                        assert_close(t.d2l_dq_dq[(i, j)], fd, 1e-6, &format!("d2L/dq2[{i}][{j}]"));
                    }
                }
            }
        }
    }
}

#[test]
fn compiled_elements_equal_interpreted() {
    let mut rng = Rng::new(21);
    let mut generated = Elements;
    let mut interp = interpreted(&elements());
    let n = Elements::DOF;
    for _ in 0..5 {
        let qd = rng.vector(n, 1.0);
        let dqd = rng.vector(n, 1.0);
        let q = tree_mech::runtime::Vector::<nalgebra::Const<7>>::from_column_slice(qd.as_slice());
        let dq =
            tree_mech::runtime::Vector::<nalgebra::Const<7>>::from_column_slice(dqd.as_slice());
        for order in [Order::First, Order::Dynamics, Order::Full] {
            let a = generated.evaluate(&q, &dq, order);
            let b = interp.evaluate(&qd, &dqd, order);
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
            assert!(close(a.l, b.l));
            for i in 0..n {
                assert!(close(a.dl_dq[i], b.dl_dq[i]) && close(a.force[i], b.force[i]));
                for j in 0..n {
                    assert!(close(a.d2l_dq_dq[(i, j)], b.d2l_dq_dq[(i, j)]));
                    assert!(close(a.dforce_dq[(i, j)], b.dforce_dq[(i, j)]));
                    assert!(close(a.dforce_ddq[(i, j)], b.dforce_ddq[(i, j)]));
                }
            }
            let mut ca = ConstraintTerms::zeros(3, n);
            let mut cb = ConstraintTerms::zeros(3, n);
            generated.constraints(&q, &dq, order, &mut ca);
            interp.constraints(&qd, &dqd, order, &mut cb);
            let scale = cb.d2h.iter().fold(1.0f64, |s, m| s.max(m.amax()));
            assert!((&ca.h - &cb.h).amax() <= 1e-12 * scale);
            assert!((&ca.dh - &cb.dh).amax() <= 1e-12 * scale);
            assert!((&ca.dh_dot - &cb.dh_dot).amax() <= 1e-12 * scale);
            for r in 0..3 {
                assert!((&ca.d2h[r] - &cb.d2h[r]).amax() <= 1e-12 * scale);
            }
        }
    }
    assert_eq!(Elements::CONSTRAINTS, ["string", "wall", "rail.x"]);
}

/// Every constraint row's `Dh` and `D²h` are zero outside the variables the system names
/// for it (checked with fully cleared terms at random states of every model with
/// constraints); terms made with those variables (`ConstraintTerms::of`) clear and fill each
/// row's block alone, equal to fully cleared ones there, and leave what is outside as it was.
/// The compiled systems name the same variables as the interpreted ones.
#[test]
fn constraint_rows_depend_on_their_named_variables_alone() {
    let files = common::every_model_file();
    let mut rng = Rng::new(77);
    let mut checked = 0;
    for path in files {
        let model = model::from_toml_file(&path).unwrap();
        let mut sys = interpreted(&model);
        let (n, m) = (sys.dof(), sys.constraint_count());
        if m == 0 {
            continue;
        }
        checked += 1;
        let what = path.display();
        let vars: Vec<Vec<usize>> = (0..m)
            .map(|r| sys.constraint_variables(r).expect("known").to_vec())
            .collect();
        for _ in 0..3 {
            let (q, dq) = (rng.vector(n, 1.0), rng.vector(n, 1.0));
            let full = constraints_at(&mut sys, &q, &dq);
            // Garbage everywhere beforehand: inside the blocks it is cleared, outside kept.
            let mut own = ConstraintTerms::of(&sys);
            own.h.fill(7.0);
            own.dh.fill(7.0);
            own.d2h.iter_mut().for_each(|b| b.fill(7.0));
            sys.constraints(&q, &dq, Order::Full, &mut own);
            assert_eq!((&own.h, &own.dh), (&full.h, &full.dh), "{what}");
            for (r, vars) in vars.iter().enumerate() {
                assert!(vars.windows(2).all(|w| w[0] < w[1]), "{what}: ascending");
                assert_eq!(own.variables(r), Some(vars.as_slice()));
                for i in 0..n {
                    let inside_i = vars.contains(&i);
                    if !inside_i {
                        assert_eq!(full.dh[(r, i)], 0.0, "{what}: Dh[{r}][{i}] outside");
                    }
                    for j in 0..n {
                        if inside_i && vars.contains(&j) {
                            assert_eq!(own.d2h[r][(i, j)], full.d2h[r][(i, j)], "{what}");
                        } else {
                            assert_eq!(full.d2h[r][(i, j)], 0.0, "{what}: D²h[{r}] outside");
                            assert_eq!(own.d2h[r][(i, j)], 7.0, "{what}: left as it was");
                        }
                    }
                }
            }
        }
    }
    assert!(checked >= 3, "the models with constraints: {checked}");
    // The compiled systems name the same variables.
    let (elements, string_pendulum) = (
        interpreted(&elements()),
        interpreted(&StringPendulum::model()),
    );
    for r in 0..Elements::CONSTRAINTS.len() {
        assert_eq!(
            Elements.constraint_variables(r),
            elements.constraint_variables(r)
        );
    }
    for r in 0..StringPendulum::CONSTRAINTS.len() {
        assert_eq!(
            StringPendulum.constraint_variables(r),
            string_pendulum.constraint_variables(r)
        );
    }
}

#[test]
fn compiled_constrained_trajectory_equals_interpreted() {
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 2.0);
    let a = simulate_from_start(&mut StringPendulum, &options);
    let b = simulate_from_start(&mut interpreted(&StringPendulum::model()), &options);
    for k in 0..a.len() {
        for i in 0..3 {
            assert!((a.q(k)[i] - b.q(k)[i]).abs() < 1e-9);
        }
        assert!((a.lambda(k)[0] - b.lambda(k)[0]).abs() < 1e-9);
        assert!(
            a.violation[k] < 1e-11,
            "violation {} at step {k}",
            a.violation[k]
        );
    }
}

/// The bob on a string swings like the rx pendulum: angle θ with y = ℓ sin θ, z = −ℓ cos θ.
#[test]
fn a_point_on_a_string_swings_like_the_pendulum_of_that_length() {
    let l = 1.5;
    let pendulum = model::ModelBuilder::new("rx")
        .frame("pivot", "world", model::PrimitiveKind::Rx, "theta")
        .frame("bob", "pivot", model::PrimitiveKind::Tz, -l)
        .mass("bob", 1.0, [0.0; 3])
        .initial("theta", 0.5, 0.0)
        .build()
        .unwrap();
    let tight = Method::Rk45(Tolerance {
        rtol: 1e-11,
        atol: 1e-12,
    });
    let options = SimOptions::new(tight, 0.01, 1.0);
    let mut reference = interpreted(&pendulum);
    let (q0, dq0) = reference.initial_state();
    let theta = simulate(
        &mut reference,
        &q0,
        &dq0,
        &options,
        &mut NoForce,
        &mut |_| {},
    )
    .unwrap();
    let theta_end = theta.last_q()[0];
    for method in [tight, Method::Vi(ViSettings::default())] {
        let dt = if matches!(method, Method::Vi(_)) {
            1e-3
        } else {
            0.01
        };
        let mut sys = interpreted(&StringPendulum::model());
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(method, dt, 1.0);
        let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
        let q = traj.last_q();
        assert!(
            (q[1] - l * theta_end.sin()).abs() < 1e-6,
            "{method:?}: y {} vs {}",
            q[1],
            l * theta_end.sin()
        );
        assert!((q[2] + l * theta_end.cos()).abs() < 1e-6, "{method:?}: z");
        assert!(q[0].abs() < 1e-9, "{method:?}: no motion along x");
    }
}

#[test]
fn a_mass_hanging_at_rest_has_two_l_lambda_equal_to_minus_m_g() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/models/string-pendulum.toml"
    ))
    .unwrap()
    .replace("q0 = 0.7191383079063045   # 1.5 sin 0.5", "q0 = 0.0")
    .replace("q0 = -1.3163738428355591  # -1.5 cos 0.5", "q0 = -1.5");
    let model = model::from_toml_str(&text, None).unwrap();
    for method in [Method::Rk4, Method::Vi(ViSettings::default())] {
        let mut sys = interpreted(&model);
        let (q0, dq0) = sys.initial_state();
        let traj = simulate(
            &mut sys,
            &q0,
            &dq0,
            &SimOptions::new(method, 0.01, 1.0),
            &mut NoForce,
            &mut |_| {},
        )
        .unwrap();
        // Every sample, the first VI step's included (its impulse spans a whole step only when
        // the start momentum is the discrete one, `start_constrained`).
        for k in 0..traj.len() {
            // Sign convention: d/dt ∂L/∂q̇ − ∂L/∂q = u + Dhᵀλ, so a taut string has λ < 0.
            assert_close(
                2.0 * 1.5 * traj.lambda(k)[0],
                -9.81,
                1e-9,
                &format!("{method:?} sample {k}"),
            );
        }
    }
}

#[test]
fn kinematic_variables_follow_their_prescription_exactly() {
    let model = elements();
    let mut sys = interpreted(&model);
    let (q0, dq0) = sys.initial_state();
    let mut motion = ModelMotions::of(&sys);
    let kinematic = model.kinematic();
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let mut reference = motion.clone();
        let options = SimOptions::new(method, 0.01, 0.5);
        let mut checked = 0;
        let result = run(
            &mut sys,
            &q0,
            &dq0,
            &options,
            &mut NoForce,
            &mut motion,
            &mut |s| {
                for &i in &kinematic {
                    let [x, v, _] =
                        tree_mech::runtime::Prescription::kinematic(&mut reference, i, s.t);
                    assert!(
                        (s.q[i] - x).abs() < 1e-14 && (s.dq[i] - v).abs() < 1e-12,
                        "{method:?} t {}",
                        s.t
                    );
                }
                checked += 1;
                Ok(())
            },
        );
        result.unwrap();
        assert_eq!(checked, 51);
    }
}

compile! {
    /// tests/models/elements.toml written inline: every element, motion and spline.
    struct InlineElements;
    frame base = rz(yaw) {
        frame shoulder = ry(pitch) {
            frame upper = tz(0.5) {
                mass = 1.0;
                inertia = [0.02, 0.03, 0.01];
                frame elbow = rx(bend) {
                    frame lower = ty(0.4) {
                        mass = 0.5;
                        inertia = [0.01, 0.005, 0.01];
                        frame tip = tx(slide) { mass = 0.2; }
                    }
                }
            }
        }
    }
    frame hand = tx(hand_x) { frame hand_z = tz(hand_z); }
    frame floor = tz(-1.0);
    variable yaw { q0 = 0.2; }
    variable bend { q0 = 0.3; }
    variable pitch { damping = 0.2; }
    variable hand_x {
        kinematic = true;
        motion = sine(offset = 0.3, amplitude = 0.1, frequency = 0.5, phase = 0.3);
    }
    variable hand_z { kinematic = true; samples = [[0.0, 1.2], [0.5, 1.3], [1.0, 1.15], [2.0, 1.25]]; }
    variable len { kinematic = true; motion = sine(offset = 0.9, amplitude = 0.05, frequency = 1.0); }
    constraint string = distance(tip, hand_z) { length = len; }
    constraint wall = plane(upper, tip) { normal = [0.0, 1.0, 1.0]; }
    constraint rail = point(lower, floor) { axes = "x"; }
    spring(upper, hand_z) { stiffness = 20.0; rest = 0.3; }
    spring(bend) { stiffness = 5.0; rest = 0.1; }
    damper(lower, hand_z) { damping = 0.7; }
}

#[test]
fn inline_elements_compile_to_the_same_model_and_system_as_the_file() {
    let mut file = elements();
    let mut inline = InlineElements::model();
    file.name.clear();
    inline.name.clear();
    assert_eq!(inline, file, "the inline model is the file's");
    assert_eq!(InlineElements::CONSTRAINTS, Elements::CONSTRAINTS);
    assert_eq!(InlineElements::KINEMATIC, Elements::KINEMATIC);
    let mut rng = Rng::new(31);
    let (mut a, mut b) = (InlineElements, Elements);
    for _ in 0..3 {
        let qd = rng.vector(7, 1.0);
        let q = tree_mech::runtime::Vector::<nalgebra::Const<7>>::from_column_slice(qd.as_slice());
        let ta = a.evaluate(&q, &q, Order::Full);
        let tb = b.evaluate(&q, &q, Order::Full);
        assert_eq!(ta.l, tb.l);
        assert_eq!(ta.d2l_dq_dq, tb.d2l_dq_dq);
        assert_eq!(ta.dforce_dq, tb.dforce_dq);
        let mut ca = ConstraintTerms::zeros(3, 7);
        let mut cb = ConstraintTerms::zeros(3, 7);
        a.constraints(&q, &q, Order::Full, &mut ca);
        b.constraints(&q, &q, Order::Full, &mut cb);
        assert_eq!(ca.dh, cb.dh);
        assert_eq!(ca.d2h, cb.d2h);
    }
    for i in 0..7 {
        assert_eq!(a.motion(i), b.motion(i), "motion of variable {i}");
    }
}

compile! {
    /// The README's inline example.
    pub struct Swing;
    frame x = tx(x) { frame y = ty(y) { frame bob = tz(z) { mass = 1.0; } } }
    frame hand = ty(hand) { frame hand_top = tz(1.0); }
    frame wall = tz(0.0);
    variable z { q0 = -0.5; damping = 0.1; }
    variable hand { kinematic = true; motion = sine(amplitude = 0.2, frequency = 0.5); }
    variable len { kinematic = true; samples = [[0.0, 1.5], [2.0, 1.2], [4.0, 1.5]]; }
    constraint string = distance(bob, hand_top) { length = len; }
    constraint wall = plane(wall, bob) { normal = [1.0, 0.0, 0.0]; }
    spring(bob, hand_top) { stiffness = 20.0; rest = 0.3; }
    spring(z) { stiffness = 5.0; }
    damper(bob, hand_top) { damping = 0.7; }
}

#[test]
fn the_readme_inline_example_runs_on_its_constraints() {
    let mut sys = Swing;
    let (q0, dq0) = sys.initial_state();
    let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 4.0);
    let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
    assert_eq!(Swing::CONSTRAINTS, ["string", "wall"]);
    assert!(traj.worst_violation() < 1e-9, "{}", traj.worst_violation());
    for k in 0..traj.len() {
        assert!(traj.q(k)[Swing::X].abs() < 1e-9, "the wall holds x = 0");
        let hand = 0.2 * (std::f64::consts::PI * traj.t[k]).sin();
        assert!((traj.q(k)[Swing::HAND] - hand).abs() < 1e-12);
    }
}
