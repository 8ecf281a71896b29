//! One midpoint-VI step and all of its derivatives against trep 1.0.2's `MidpointVI`
//! (tests/fixtures/trep-vi-derivatives.json, written by tools/reference/trep_vi_derivatives.py
//! on the model tests/models/trep-vi.toml): q₂, p₂, λ₁, trep's 12 first derivatives and 30
//! second derivatives, on a model with a constraint, a kinematic input, damping, a spring and
//! an input, with trep's forcing (`left`), compiled and interpreted.
//!
//! Conventions: trep's `λ₁` multiplies its constraint row `h_dq` with the opposite sign and Δt
//! folded in; so `λ₁ = −Δt r λ` with `r` the ratio of our row to trep's, read from the
//! fixture's `h_dq` and our `Dh` at q₁ (1 for this distance constraint: `d·d − ℓ²` in both).
//! Both solvers converge to rounding here, and the two
//! agree to ~1e-15 (asserted to 1e-12).

mod common;

use common::numbers;
use nalgebra::{allocator::Allocator, DMatrix, DefaultAllocator};
use serde_json::Value;
use tree_mech::integrate::{Forcing, MidpointVi, StepContext, StepInput, StepOutput, ViSettings};
use tree_mech::runtime::{ConstraintTerms, Vector};
use tree_mech::{tree_model, NoForce, Order, System, TreeSystem};

tree_model!(struct TrepVi from "tests/models/trep-vi.toml");

fn fixture() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/trep-vi-derivatives.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = v.as_array().unwrap().iter().map(numbers).collect();
    let cols = rows.first().map_or(0, |r| r.len());
    DMatrix::from_fn(rows.len(), cols, |r, c| rows[r][c])
}

/// `|a − b| ≤ tol` relative to the larger of the two matrices (and 1).
#[track_caller]
fn close(ours: &DMatrix<f64>, trep: &DMatrix<f64>, tol: f64, what: &str) -> f64 {
    assert_eq!(ours.shape(), trep.shape(), "{what}: shape");
    let scale = ours.amax().max(trep.amax()).max(1.0);
    let err = (ours - trep).amax() / scale;
    assert!(
        err <= tol,
        "{what}: ours {ours} vs trep {trep} (relative {err:.1e})"
    );
    err
}

fn check<S: System>(sys: &mut S, what: &str)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let fx = fixture();
    let names: Vec<String> = fx["configs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect();
    let n = sys.dof();
    // The same variables in the same order (trep's: dynamic, then kinematic).
    assert_eq!(
        names,
        (0..n)
            .map(|i| sys.variable_name(i).to_string())
            .collect::<Vec<_>>()
    );
    let dt = fx["dt"].as_f64().unwrap();
    let nd = fx["dynamic"].as_array().unwrap().len();
    let settings = ViSettings {
        forcing: Forcing::Left,
        tolerance: 1e-14,
        constraint_tolerance: 1e-15,
        max_iterations: 60,
        max_subdivisions: 0,
        ..ViSettings::default()
    };
    let mut worst = [0.0f64; 2];
    for (k, step) in fx["steps"].as_array().unwrap().iter().enumerate() {
        let what = |x: &str| format!("{what}, step {k}: {x}");
        let vector = |x: &[f64]| {
            let mut v = sys.zero_vector();
            for (i, &xi) in x.iter().enumerate() {
                v[i] = xi;
            }
            v
        };
        let t1 = step["t1"].as_f64().unwrap();
        let q1 = vector(&numbers(&step["q1"]));
        let p1 = vector(&numbers(&step["p1"]));
        let (u1, k2) = (numbers(&step["u1"]), numbers(&step["k2"]));
        // The kinematic variables: q₁'s values at t₁, k₂ at t₂.
        let q1_k: Vec<f64> = (nd..n).map(|i| q1[i]).collect();
        let mut motion = |i: usize, t: f64| {
            let x = if t > t1 + 0.5 * dt {
                k2[i - nd]
            } else {
                q1_k[i - nd]
            };
            [x, 0.0, 0.0]
        };
        let mut vi = MidpointVi::new(sys, settings);
        vi.predict_from_rest();
        let (mut q2, mut p2, mut next) = (q1.clone(), p1.clone(), q1.clone());
        let mut force = NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
        cx.u = &u1;
        vi.step(cx.at(0, t1), &mut q2, &mut p2, &mut next).unwrap();
        let (first, second) = vi.second_derivatives(cx.at(0, t1), &q1, &p1, &q2).unwrap();
        // r: our constraint row over trep's, at q₁.
        let mut c1 = ConstraintTerms::zeros(cx.sys.constraint_count(), n);
        let zero: Vector<S::N> = cx.sys.zero_vector();
        cx.sys.constraints(&q1, &zero, Order::First, &mut c1);
        let h_dq = matrix(&step["h_dq"]);
        let ratio: Vec<f64> = (0..c1.rows())
            .map(|s| {
                let j = (0..n)
                    .max_by(|&a, &b| h_dq[(s, a)].abs().total_cmp(&h_dq[(s, b)].abs()))
                    .unwrap();
                c1.dh[(s, j)] / h_dq[(s, j)]
            })
            .collect();
        let lambda_scale = |s: usize| -dt * ratio[s];
        // The step itself.
        let row = |x: Vec<f64>| DMatrix::from_row_slice(1, x.len(), &x);
        close(
            &row(q2.iter().copied().collect()),
            &row(numbers(&step["q2"])),
            1e-12,
            &what("q2"),
        );
        close(
            &row((0..nd).map(|i| p2[i]).collect()),
            &row(numbers(&step["p2"])),
            1e-12,
            &what("p2"),
        );
        let lambda1: Vec<f64> = (0..ratio.len())
            .map(|s| lambda_scale(s) * vi.lambda[s])
            .collect();
        close(
            &row(lambda1),
            &row(numbers(&step["lambda1"])),
            1e-12,
            &what("lambda1"),
        );
        let trep_name = |of: StepOutput| match of {
            StepOutput::Q2 => "q2",
            StepOutput::P2 => "p2",
            StepOutput::Lambda => "lambda1",
        };
        let scaled = |of: StepOutput, m: &DMatrix<f64>, r: usize| match of {
            StepOutput::Lambda => m * lambda_scale(r),
            _ => m.clone(),
        };
        for of in StepOutput::ALL {
            for by in StepInput::ALL {
                let key = format!("{}_d{}", trep_name(of), by.name());
                let mut ours = first.block(of, by).clone();
                if of == StepOutput::Lambda {
                    for r in 0..ours.nrows() {
                        let s = lambda_scale(r);
                        ours.row_mut(r).scale_mut(s);
                    }
                }
                let err = close(&ours, &matrix(&step[&key]), 1e-12, &what(&key));
                worst[0] = worst[0].max(err);
            }
            for (i, &a) in StepInput::ALL.iter().enumerate() {
                for &b in &StepInput::ALL[i..] {
                    let key = format!("{}_d{}d{}", trep_name(of), a.name(), b.name());
                    let theirs = step[&key].as_array().unwrap();
                    let ours = second.block(of, a, b);
                    assert_eq!(ours.len(), theirs.len(), "{}", what(&key));
                    for (r, h) in ours.iter().enumerate() {
                        let err = close(
                            &scaled(of, h, r),
                            &matrix(&theirs[r]),
                            1e-12,
                            &what(&format!("{key}[{r}]")),
                        );
                        worst[1] = worst[1].max(err);
                    }
                }
            }
        }
    }
    eprintln!(
        "{what}: worst relative difference from trep: first {:.1e}, second {:.1e}",
        worst[0], worst[1]
    );
}

#[test]
fn interpreted_step_derivatives_match_trep() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/trep-vi.toml");
    let model = tree_mech::model::from_toml_file(path).unwrap();
    check(&mut TreeSystem::new(&model).unwrap(), "interpreted");
}

#[test]
fn compiled_step_derivatives_match_trep() {
    check(&mut TrepVi, "compiled");
}
