//! Every derivative the interpreted system returns, against central finite differences, on
//! seeded random states of every model in `models/`; and caching on vs off.

use crate::common;

use common::{assert_close, model_files, Rng};
use nalgebra::Dyn;
use tree_mech::kernel::se3::{LocalTransform, Pose};
use tree_mech::model::{self, Joint, Model};
use tree_mech::runtime::{Order, PaperEvaluation, PaperSystem, System, Terms, TreeSystem, Vector};

const H: f64 = 1e-6;
const TOL: f64 = 2e-6;

fn eval<S: System<N = Dyn>>(sys: &mut S, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Terms<Dyn> {
    sys.evaluate(q, dq, Order::Full)
}

/// Central difference of `f` along coordinate `j` of `x`.
fn fd<T>(
    x: &Vector<Dyn>,
    j: usize,
    mut f: impl FnMut(&Vector<Dyn>) -> T,
    sub: impl Fn(&T, &T) -> f64,
) -> f64 {
    let mut xp = x.clone();
    let mut xm = x.clone();
    xp[j] += H;
    xm[j] -= H;
    sub(&f(&xp), &f(&xm)) / (2.0 * H)
}

/// The interpreted system and, for models of frames and masses only, the paper's reference
/// evaluations (uncached only on small trees: it is slow on deep ones).
fn check_model(model: &Model, seed: u64) {
    check_system(TreeSystem::new(model).unwrap(), model, seed);
    let paper_bodies = model
        .frames
        .iter()
        .all(|f| f.mass.is_none_or(|m| m.diagonal().is_some()));
    if !model.has_elements() && paper_bodies {
        check_system(
            PaperSystem::new(model, PaperEvaluation::Cached).unwrap(),
            model,
            seed,
        );
        if model.dof() <= 8 {
            let sys = PaperSystem::new(model, PaperEvaluation::Uncached).unwrap();
            check_system(sys, model, seed);
        }
    }
}

fn check_system<S: System<N = Dyn>>(mut sys: S, model: &Model, seed: u64) {
    let n = sys.dof();
    let mut rng = Rng::new(seed);
    for trial in 0..4 {
        let q = rng.vector(n, 1.5);
        let dq = rng.vector(n, 2.0);
        let t = eval(&mut sys, &q, &dq);
        let what =
            |s: &str, i: usize, j: usize| format!("{} trial {trial}: {s}[{i}][{j}]", model.name);
        for j in 0..n {
            let dl_dq = fd(&q, j, |x| eval(&mut sys, x, &dq), |a, b| a.l - b.l);
            assert_close(t.dl_dq[j], dl_dq, TOL, &what("dL/dq", j, 0));
            let dl_ddq = fd(&dq, j, |x| eval(&mut sys, &q, x), |a, b| a.l - b.l);
            assert_close(t.dl_ddq[j], dl_ddq, TOL, &what("dL/ddq", j, 0));
            for i in 0..n {
                let m = fd(
                    &dq,
                    j,
                    |x| eval(&mut sys, &q, x),
                    |a, b| a.dl_ddq[i] - b.dl_ddq[i],
                );
                assert_close(t.mass[(i, j)], m, TOL, &what("M", i, j));
                let x = fd(
                    &q,
                    j,
                    |x| eval(&mut sys, x, &dq),
                    |a, b| a.dl_ddq[i] - b.dl_ddq[i],
                );
                assert_close(t.d2l_ddq_dq[(i, j)], x, TOL, &what("d2L/ddq_i dq_j", i, j));
                let x = fd(
                    &q,
                    j,
                    |x| eval(&mut sys, x, &dq),
                    |a, b| a.dl_dq[i] - b.dl_dq[i],
                );
                assert_close(t.d2l_dq_dq[(i, j)], x, TOL, &what("d2L/dq dq", i, j));
            }
        }
        // The kinetic energy is ½ q̇ᵀ M q̇, so M q̇ = ∂L/∂q̇ exactly.
        let p = &t.mass * &dq;
        for i in 0..n {
            assert_close(p[i], t.dl_ddq[i], 1e-12, &what("M dq = dL/ddq", i, 0));
        }
    }
}

#[test]
fn lagrangian_derivatives_match_finite_differences_on_every_model() {
    for (k, file) in model_files().iter().enumerate() {
        let model = model::from_toml_file(file).unwrap();
        check_model(&model, 100 + k as u64);
    }
}

/// The compiler's test model: every primitive kind, constant chains, massless branches.
fn specialised() -> Model {
    model::from_toml_file(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/models/specialised.toml"),
    )
    .unwrap()
}

#[test]
fn lagrangian_derivatives_match_finite_differences_with_folded_constant_chains() {
    check_model(&specialised(), 77);
}

#[test]
fn lagrangian_derivatives_match_finite_differences_with_full_rigid_bodies() {
    let model = model::from_toml_file(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/models/bodies.toml"),
    )
    .unwrap();
    check_model(&model, 77);
}

#[test]
fn lagrangian_derivatives_match_finite_differences_on_a_long_chain() {
    check_model(&model::n_link_pendulum(7), 7);
}

/// An independent pose composition: 4×4 homogeneous matrices from textbook rotations.
fn reference_poses(model: &Model, q: &[f64]) -> Vec<nalgebra::Matrix4<f64>> {
    use nalgebra::{Matrix4, Rotation3, Translation3, Vector3};
    let mut out: Vec<Matrix4<f64>> = Vec::new();
    for f in &model.frames {
        let x = match f.joint {
            Joint::Constant(x) => x,
            Joint::Variable(i) => q[i],
            Joint::Mimic(m) => m.multiplier * q[m.variable] + m.offset,
        };
        let axis = [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()][f.primitive.axis()];
        let local = if f.primitive.is_rotation() {
            Rotation3::from_axis_angle(&axis, x).to_homogeneous()
        } else {
            Translation3::from(axis.into_inner() * x).to_homogeneous()
        };
        let parent = f.parent.map_or(Matrix4::identity(), |p| out[p]);
        out.push(parent * local);
    }
    out
}

fn pose_matrix(p: &Pose) -> nalgebra::Matrix4<f64> {
    let m = p.matrix();
    nalgebra::Matrix4::from_fn(|i, j| m[i][j])
}

#[test]
fn poses_match_an_independent_composition() {
    for (k, file) in model_files().iter().enumerate() {
        let model = model::from_toml_file(file).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let mut rng = Rng::new(k as u64);
        let q = rng.vector(sys.dof(), 2.0);
        let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
        sys.poses(&q, &mut poses);
        for (f, (a, b)) in poses
            .iter()
            .zip(reference_poses(&model, q.as_slice()))
            .enumerate()
        {
            let d = (pose_matrix(a) - b).amax();
            assert!(
                d < 1e-13,
                "{}: pose of frame `{}` off by {d:e}",
                model.name,
                model.frames[f].name
            );
        }
        // The model's own origins (used by validation) agree too.
        for (f, (o, b)) in model
            .origins(q.as_slice())
            .iter()
            .zip(reference_poses(&model, q.as_slice()))
            .enumerate()
        {
            let d = (0..3).fold(0.0f64, |m, i| m.max((o[i] - b[(i, 3)]).abs()));
            assert!(
                d < 1e-13,
                "{}: origin of `{}` off by {d:e}",
                model.name,
                model.frames[f].name
            );
        }
    }
}

#[test]
fn body_velocities_and_their_derivatives_match_finite_differences() {
    for (k, file) in model_files().iter().enumerate() {
        let model = model::from_toml_file(file).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let n = sys.dof();
        let mut rng = Rng::new(50 + k as u64);
        let q = rng.vector(n, 1.5);
        let dq = rng.vector(n, 2.0);
        let frames = sys.frame_velocities(&q, &dq);
        // The velocities alone (what `evaluate` reports) are the sweep's, to rounding.
        for (f, v) in sys.body_velocities(&q, &dq).iter().enumerate() {
            for c in 0..6 {
                assert_close(v[c], frames[f].0[c], 1e-14, "body_velocities");
            }
        }
        // v̂_k = g⁻¹ ġ with ġ by central differences of the pose along q̇.
        let poses_at = |sys: &mut TreeSystem, x: &Vector<Dyn>| {
            let mut p = vec![Pose::IDENTITY; sys.frame_count()];
            sys.poses(x, &mut p);
            p
        };
        let mut qp = q.clone();
        qp.axpy(H, &dq, 1.0);
        let mut qm = q.clone();
        qm.axpy(-H, &dq, 1.0);
        let (gp, gm, g) = (
            poses_at(&mut sys, &qp),
            poses_at(&mut sys, &qm),
            poses_at(&mut sys, &q),
        );
        for f in 0..sys.frame_count() {
            let gdot = (pose_matrix(&gp[f]) - pose_matrix(&gm[f])) / (2.0 * H);
            let vhat = pose_matrix(&g[f].inverse()) * gdot;
            let v = [
                vhat[(0, 3)],
                vhat[(1, 3)],
                vhat[(2, 3)],
                vhat[(2, 1)],
                vhat[(0, 2)],
                vhat[(1, 0)],
            ];
            for c in 0..6 {
                assert_close(
                    frames[f].0[c],
                    v[c],
                    TOL,
                    &format!("{}: v of `{}`", model.name, model.frames[f].name),
                );
            }
            // ∂v/∂q̇_i is v at q̇ = e_i; ∂v/∂q_i by differences of v in q.
            for &(i, jac, dv_dq) in &frames[f].1 {
                let mut e = Vector::<Dyn>::zeros(n);
                e[i] = 1.0;
                let at_e = sys.frame_velocities(&q, &e);
                let mut qp = q.clone();
                qp[i] += H;
                let mut qm = q.clone();
                qm[i] -= H;
                let vp = sys.frame_velocities(&qp, &dq)[f].0;
                let vm = sys.frame_velocities(&qm, &dq)[f].0;
                for c in 0..6 {
                    assert_close(jac[c], at_e[f].0[c], 1e-14, "dv/ddq");
                    assert_close(
                        dv_dq[c],
                        (vp[c] - vm[c]) / (2.0 * H),
                        TOL,
                        &format!("{}: dv/dq of `{}`", model.name, model.frames[f].name),
                    );
                }
            }
        }
    }
}

#[test]
fn all_evaluation_modes_agree_to_rounding() {
    let mut models: Vec<Model> = model_files()
        .iter()
        .map(|f| model::from_toml_file(f).unwrap())
        .collect();
    models.push(model::n_link_pendulum(6));
    models.push(specialised());
    for model in models.iter().filter(|m| !m.has_elements()) {
        let mut on = TreeSystem::new(model).unwrap();
        for other in [PaperEvaluation::Cached, PaperEvaluation::Uncached] {
            let mut off = PaperSystem::new(model, other).unwrap();
            let mut rng = Rng::new(9);
            for _ in 0..3 {
                let q = rng.vector(on.dof(), 2.0);
                let dq = rng.vector(on.dof(), 2.0);
                let a = eval(&mut on, &q, &dq);
                let b = eval(&mut off, &q, &dq);
                let scale = a.d2l_dq_dq.amax().max(a.mass.amax()).max(1.0);
                let diff = [
                    (a.l - b.l).abs(),
                    (&a.dl_dq - &b.dl_dq).amax(),
                    (&a.dl_ddq - &b.dl_ddq).amax(),
                    (&a.mass - &b.mass).amax(),
                    (&a.d2l_ddq_dq - &b.d2l_ddq_dq).amax(),
                    (&a.d2l_dq_dq - &b.d2l_dq_dq).amax(),
                ];
                for d in diff {
                    assert!(
                        d <= 1e-12 * scale,
                        "{}: sweeps vs {other:?} differ by {d:e}",
                        model.name
                    );
                }
            }
        }
    }
}

#[test]
fn local_transform_pose_is_the_primitive() {
    // g(x)⁻¹ = g(−x) for every primitive.
    for kind in model::PrimitiveKind::ALL {
        let g = LocalTransform::new(kind, 0.7).pose();
        let gi = LocalTransform::new(kind, -0.7).pose();
        let d = (pose_matrix(&g.compose(&gi)) - nalgebra::Matrix4::identity()).amax();
        assert!(d < 1e-15, "{kind}: g(x) g(-x) != I");
        assert!((pose_matrix(&g.inverse()) - pose_matrix(&gi)).amax() < 1e-15);
    }
}

#[test]
fn primitive_derivatives_and_inverses() {
    // g' = g ξ̂ and g'' = g ξ̂² against central differences; g⁻¹ = g(−x).
    let h = 1e-5;
    for kind in model::PrimitiveKind::ALL {
        for x in [-1.3, 0.0, 0.4, 2.5] {
            let g = |x: f64| LocalTransform::new(kind, x).pose().matrix();
            let (gp, gm, g0) = (g(x + h), g(x - h), g(x));
            let local = LocalTransform::new(kind, x);
            let (d1, d2) = (local.derivative(), local.second_derivative());
            for i in 0..4 {
                for j in 0..4 {
                    let fd1 = (gp[i][j] - gm[i][j]) / (2.0 * h);
                    let fd2 = (gp[i][j] - 2.0 * g0[i][j] + gm[i][j]) / (h * h);
                    assert!((d1[i][j] - fd1).abs() < 1e-9, "{kind} g'[{i}][{j}] at {x}");
                    assert!((d2[i][j] - fd2).abs() < 1e-5, "{kind} g''[{i}][{j}] at {x}");
                }
            }
            let inv = local.inverse().pose();
            assert!(
                (pose_matrix(&local.pose().compose(&inv)) - nalgebra::Matrix4::identity()).amax()
                    < 1e-15
            );
            assert_eq!(inv, LocalTransform::new(kind, -x).pose());
        }
    }
}
