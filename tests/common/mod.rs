//! Helpers shared by the integration tests: the model files, a seeded generator, finite
//! differences.
#![allow(dead_code)]

use std::path::PathBuf;

use nalgebra::{allocator::Allocator, DefaultAllocator, Dyn};
use tree_mech::integrate::{simulate, SimOptions};
use tree_mech::model::{self, Model};
use tree_mech::runtime::{TreeSystem, Vector};
use tree_mech::{NoForce, System, Trajectory};

/// Every model file in `models/`.
pub fn model_files() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 5, "models/ holds the five required models");
    files
}

/// Every `.toml` model of `models/` and `tests/models/`.
pub fn every_model_file() -> Vec<PathBuf> {
    let test_models = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/models");
    let mut files = model_files();
    files.extend(
        std::fs::read_dir(test_models)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml")),
    );
    files
}

pub fn load(name: &str) -> Model {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("models")
        .join(name);
    model::from_toml_file(path).unwrap()
}

pub fn interpreted(model: &Model) -> TreeSystem {
    TreeSystem::new(model).unwrap()
}

/// A small deterministic generator (xorshift64*), so tests need no extra crate.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Uniform in `[-1, 1)`.
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        2.0 * (x as f64 / (1u64 << 53) as f64) - 1.0
    }
    pub fn vector(&mut self, n: usize, scale: f64) -> Vector<Dyn> {
        Vector::<Dyn>::from_fn(n, |_, _| scale * self.uniform())
    }
}

/// `|a − b| ≤ tol · max(1, |b|)`, with a message naming what is compared.
#[track_caller]
pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!(
        (a - b).abs() <= tol * b.abs().max(1.0),
        "{what}: {a} vs {b} (difference {:e})",
        (a - b).abs()
    );
}

/// Simulates `sys` from its model's initial state, with no external force.
pub fn simulate_from_start<S: System>(sys: &mut S, options: &SimOptions) -> Trajectory
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    simulate(sys, &q0, &dq0, options, &mut NoForce, &mut |_| {}).unwrap()
}

/// A JSON array of numbers (a fixture's vector).
pub fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The cart-pole of `tests/models/cart.toml` pushed to x = 0.5 with its pendulum down: a
/// quadratic cost on its VI state `(x, θ, p_x, p_θ, previous push)` and the push.
pub fn cart_to_half_metre(dt: f64) -> tree_mech::control::QuadraticCost {
    use tree_mech::nalgebra::DVector;
    let target = DVector::from_vec(vec![0.5, 0.0, 0.0, 0.0, 0.0]);
    tree_mech::control::QuadraticCost {
        dt,
        x_ref: target.clone(),
        x_weight: DVector::from_vec(vec![1.0, 1.0, 0.1, 0.1, 0.0]),
        u_ref: DVector::zeros(1),
        u_weight: DVector::from_vec(vec![1e-3]),
        terminal_ref: target,
        terminal_weight: DVector::from_vec(vec![100.0, 10.0, 10.0, 10.0, 0.0]),
    }
}

/// The `System` methods that describe a model (names, counts, initial state, motions),
/// delegated to the system in field `$inner`: for test wrappers that change only how a
/// system evaluates (`impl System for W { type N = Dyn; delegate_description!(inner); … }`).
#[macro_export]
macro_rules! delegate_description {
    ($inner:ident) => {
        fn dim(&self) -> nalgebra::Dyn {
            self.$inner.dim()
        }
        fn variable_name(&self, i: usize) -> &str {
            self.$inner.variable_name(i)
        }
        fn frame_count(&self) -> usize {
            self.$inner.frame_count()
        }
        fn frame_name(&self, k: usize) -> &str {
            self.$inner.frame_name(k)
        }
        fn initial(&self, i: usize) -> (f64, f64) {
            self.$inner.initial(i)
        }
        fn damping(&self, i: usize) -> f64 {
            self.$inner.damping(i)
        }
        fn is_angle(&self, i: usize) -> bool {
            self.$inner.is_angle(i)
        }
        fn input_count(&self) -> usize {
            self.$inner.input_count()
        }
        fn input_name(&self, k: usize) -> &str {
            self.$inner.input_name(k)
        }
        fn input_variable(&self, k: usize) -> usize {
            self.$inner.input_variable(k)
        }
        fn motion(&self, i: usize) -> Option<tree_mech::model::Motion> {
            self.$inner.motion(i)
        }
        fn constraint_count(&self) -> usize {
            self.$inner.constraint_count()
        }
        fn constraint_name(&self, r: usize) -> &str {
            self.$inner.constraint_name(r)
        }
        fn constraints(
            &mut self,
            q: &tree_mech::runtime::Vector<nalgebra::Dyn>,
            dq: &tree_mech::runtime::Vector<nalgebra::Dyn>,
            order: tree_mech::Order,
            out: &mut tree_mech::ConstraintTerms,
        ) {
            self.$inner.constraints(q, dq, order, out)
        }
        fn poses(
            &mut self,
            q: &tree_mech::runtime::Vector<nalgebra::Dyn>,
            out: &mut [tree_mech::runtime::Pose],
        ) {
            self.$inner.poses(q, out)
        }
        fn evaluate_dual(
            &mut self,
            q: &[tree_mech::kernel::Dual],
            dq: &[tree_mech::kernel::Dual],
            order: tree_mech::Order,
            out: &mut tree_mech::kernel::DualOutputs,
        ) {
            self.$inner.evaluate_dual(q, dq, order, out)
        }
    };
}

/// `sys`'s weighted constraint Hessian (`System::weighted_constraint_hessian`) at a random
/// `q` against the rows' Hessians of its `Order::Full` constraints weighted and summed, on
/// the dynamic variables' columns (the kinematic ones left zero), to `tol` relative; `h` and
/// `Dh` as the constraints give them. Garbage left in the dynamic columns by an earlier call
/// is overwritten, not added to. The same over dual numbers
/// For outputs kept between a compiled model's evaluations (`keep_zeros`): the zero entries
/// of `kept` (column-major storage), each set to `mark` there and in `plain` (the same
/// output, not kept) — garbage where an evaluation does not write, to see whether the next
/// one clears it.
pub fn mark_zeros(kept: &mut [f64], plain: &mut [f64], mark: f64) -> Vec<usize> {
    let zeros: Vec<usize> = (0..kept.len()).filter(|&e| kept[e] == 0.0).collect();
    for &e in &zeros {
        kept[e] = mark;
        plain[e] = mark;
    }
    zeros
}

/// Of the entries `mark_zeros` marked, those an evaluation since left as marked (it does not
/// write them), each set back to zero.
pub fn unwritten(kept: &mut [f64], marked: &[usize], mark: f64) -> Vec<usize> {
    let left: Vec<usize> = (marked.iter().copied())
        .filter(|&e| kept[e] == mark)
        .collect();
    for &e in &left {
        kept[e] = 0.0;
    }
    left
}

/// (`System::weighted_constraint_hessian_dual`), `q` and the weights seeded.
pub fn check_weighted_hessian<S: System>(sys: &mut S, seed: u64, tol: f64)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (n, m) = (sys.dof(), sys.constraint_count());
    assert!(m > 0, "a model with constraints");
    let mut rng = Rng::new(seed);
    let (mut q, mut dq) = (sys.zero_vector(), sys.zero_vector());
    for i in 0..n {
        q[i] = rng.uniform();
        dq[i] = rng.uniform();
    }
    let weights: Vec<f64> = (0..m).map(|_| 3.0 * rng.uniform()).collect();
    let mut full = tree_mech::ConstraintTerms::zeros(m, n);
    sys.constraints(&q, &dq, tree_mech::Order::Full, &mut full);
    let mut weighted = tree_mech::ConstraintTerms::zeros(m, n);
    // An earlier call's sum, and garbage, in the dynamic columns.
    sys.weighted_constraint_hessian(&q, &vec![1.0; m], &mut weighted);
    for j in (0..n).filter(|&j| !sys.is_kinematic(j)) {
        weighted.weighted_d2h.column_mut(j).fill(1e9);
    }
    sys.weighted_constraint_hessian(&q, &weights, &mut weighted);
    let scale = full.d2h.iter().fold(1.0f64, |s, h| s.max(h.amax())) * 3.0 * m as f64;
    let mut reached = 0;
    for j in 0..n {
        for i in 0..n {
            let want = if sys.is_kinematic(j) {
                0.0
            } else {
                (0..m).map(|r| weights[r] * full.d2h[r][(i, j)]).sum()
            };
            let got = weighted.weighted_d2h[(i, j)];
            assert!(
                (got - want).abs() <= tol * scale,
                "Σ w D²h ({i}, {j}): {got} against {want}"
            );
            reached += (want != 0.0) as usize;
        }
    }
    assert!(reached > 0, "some row's Hessian reaches a dynamic column");
    assert!((&weighted.h - &full.h).amax() <= tol * scale);
    assert!((&weighted.dh - &full.dh).amax() <= tol * scale);
    // Over dual numbers, q and the weights both moving: the value and the derivative of
    // Σ_r w_r D²h_r (product rule) against the rows' dual Hessians, and `h`, `Dh` as the
    // dual constraints give them; an earlier call's sum overwritten.
    use tree_mech::kernel::{Dual, DualOutputs};
    use tree_mech::kernel::{Field, Output};
    let seeded = |x: f64, rng: &mut Rng| Dual::new(x, rng.uniform());
    let qd: Vec<Dual> = (0..n).map(|i| seeded(q[i], &mut rng)).collect();
    let wd: Vec<Dual> = weights.iter().map(|&w| seeded(w, &mut rng)).collect();
    let mut rows = DualOutputs::new(n, m);
    sys.constraints_dual(&qd, &qd, tree_mech::Order::Full, &mut rows);
    let mut sums = DualOutputs::new(n, m);
    sys.weighted_constraint_hessian_dual(&qd, &vec![Dual::new(1.0, 1.0); m], &mut sums);
    sys.weighted_constraint_hessian_dual(&qd, &wd, &mut sums);
    for j in (0..n).filter(|&j| !sys.is_kinematic(j)) {
        for i in 0..n {
            let want = (0..m).fold(Dual::default(), |s, r| {
                s + wd[r] * rows.get(Output::D2h(r, i, j))
            });
            let got = sums.get(Output::WeightedD2h(i, j));
            assert!(
                (got.v - want.v).abs() <= tol * scale && (got.d - want.d).abs() <= tol * scale,
                "Σ w D²h over duals ({i}, {j}): {got:?} against {want:?}"
            );
        }
    }
    for f in [Field::H, Field::Dh] {
        for (a, b) in sums.field(f).iter().zip(rows.field(f)) {
            assert!((a.v - b.v).abs() <= tol * scale && (a.d - b.d).abs() <= tol * scale);
        }
    }
}
