//! Before a run: bring the initial state onto the constraints by moving the dynamic
//! variables only — `q` onto `h(q) = 0` by minimum-norm Newton steps
//! `Δq_d = −Dh_dᵀ(Dh_d Dh_dᵀ)⁻¹ h`, then `q̇_d` onto `Dh q̇ = 0` by the minimum-norm correction.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dyn};

use crate::dynamics::Split;
use crate::error::SimError;
use crate::linalg::cholesky_solve;
use crate::system::{ConstraintTerms, Order, System, Vector};
use tree_model::GapKind;

/// A variable the projection changed.
#[derive(Clone, Debug, PartialEq)]
pub struct Moved {
    /// The variable moved.
    pub variable: String,
    /// `true` for its velocity, `false` for its value.
    pub velocity: bool,
    /// Its value before.
    pub from: f64,
    /// Its value after.
    pub to: f64,
}

const ITERATIONS: usize = 50;
const TOLERANCE: f64 = 1e-13;

/// Projects `(q, q̇)` onto the constraints (kinematic entries untouched) and says what moved.
/// An unsatisfiable constraint is an error naming it.
pub fn project_initial_state<S: System>(
    sys: &mut S,
    split: &Split,
    q: &mut Vector<S::N>,
    dq: &mut Vector<S::N>,
) -> Result<Vec<Moved>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let m = split.rows;
    if m == 0 {
        return Ok(Vec::new());
    }
    let (q_before, dq_before) = (q.clone(), dq.clone());
    let mut c = ConstraintTerms::zeros(m, q.len());
    let zero = sys.zero_vector();
    let mut gram = DMatrix::<f64>::zeros(m, m);
    let mut y = DVector::<f64>::zeros(m);
    // Gram matrix A Aᵀ of the dynamic columns, and a solve with it.
    let solve = |c: &ConstraintTerms, gram: &mut DMatrix<f64>, y: &mut DVector<f64>| {
        for r in 0..m {
            for s in 0..m {
                gram[(r, s)] = split
                    .dynamic
                    .iter()
                    .map(|&i| c.dh[(r, i)] * c.dh[(s, i)])
                    .sum();
            }
        }
        cholesky_solve::<Dyn>(gram, y)
    };
    let worst = |sys: &S, c: &ConstraintTerms| {
        let r = (0..m)
            .max_by(|&a, &b| c.h[a].abs().total_cmp(&c.h[b].abs()))
            .unwrap_or(0);
        (sys.constraint_name(r).to_string(), c.h[r].abs())
    };
    for _ in 0..ITERATIONS {
        sys.constraints(q, &zero, Order::First, &mut c);
        if !c.h.iter().all(|x| x.is_finite()) {
            let (constraint, violation) = worst(sys, &c);
            return Err(SimError::Unsatisfiable {
                constraint,
                violation,
            });
        }
        if c.violation() <= TOLERANCE {
            break;
        }
        y.copy_from(&c.h);
        if let Err((r, _)) = solve(&c, &mut gram, &mut y) {
            // A row no dynamic variable moves cannot be satisfied; rows that depend on
            // each other (two planes facing each other, a string given twice) are redundant.
            let moved = split.dynamic.iter().any(|&i| c.dh[(r, i)] != 0.0);
            return Err(if moved {
                SimError::SingularConstraints {
                    step: 0,
                    t: 0.0,
                    constraint: sys.constraint_name(r).to_string(),
                }
            } else {
                SimError::Unsatisfiable {
                    constraint: sys.constraint_name(r).to_string(),
                    violation: c.h[r].abs(),
                }
            });
        }
        for &i in &split.dynamic {
            q[i] -= (0..m).map(|r| c.dh[(r, i)] * y[r]).sum::<f64>();
        }
    }
    sys.constraints(q, &zero, Order::First, &mut c);
    if c.violation() > 1e3 * TOLERANCE || !c.violation().is_finite() {
        let (constraint, violation) = worst(sys, &c);
        return Err(SimError::Unsatisfiable {
            constraint,
            violation,
        });
    }
    // Velocities: Dh q̇ = 0.
    for r in 0..m {
        y[r] = (0..dq.len()).map(|i| c.dh[(r, i)] * dq[i]).sum();
    }
    if y.amax() > 0.0 {
        if let Err((r, _)) = solve(&c, &mut gram, &mut y) {
            return Err(SimError::SingularConstraints {
                step: 0,
                t: 0.0,
                constraint: sys.constraint_name(r).to_string(),
            });
        }
        for &i in &split.dynamic {
            dq[i] -= (0..m).map(|r| c.dh[(r, i)] * y[r]).sum::<f64>();
        }
    }
    let mut moved = Vec::new();
    for &i in &split.dynamic {
        for (velocity, before, after) in [(false, q_before[i], q[i]), (true, dq_before[i], dq[i])] {
            if (after - before).abs() > 1e-12 * before.abs().max(1.0) {
                moved.push(Moved {
                    variable: sys.variable_name(i).to_string(),
                    velocity,
                    from: before,
                    to: after,
                });
            }
        }
    }
    Ok(moved)
}

/// A start outside the unilateral rows (docs/derivations.md §13): a dynamic variable beyond an
/// enforced limit is moved onto it (and said); a contact or string that starts violated by
/// more than `1e-9·max(1, ‖q‖∞)` is an error naming it and the depth — the step would push
/// it out in one impulse, an explosion of energy nobody asked for.
pub(crate) fn start_within_gaps<S: System>(
    sys: &mut S,
    q: &mut Vector<S::N>,
) -> Result<Vec<Moved>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let gaps = sys.unilateral();
    let mut moved = Vec::new();
    for g in &gaps {
        let (i, bound, beyond) = match g.kind {
            GapKind::Lower { variable, bound } => (variable, bound, q[variable] < bound),
            GapKind::Upper { variable, bound } => (variable, bound, q[variable] > bound),
            _ => continue,
        };
        if beyond {
            moved.push(Moved {
                variable: sys.variable_name(i).to_string(),
                velocity: false,
                from: q[i],
                to: bound,
            });
            q[i] = bound;
        }
    }
    let rows: usize = gaps.iter().map(|g| g.rows()).sum();
    if rows == 0 {
        return Ok(moved);
    }
    let mut terms = ConstraintTerms::zeros(rows, sys.dof());
    sys.gaps(q, None, &mut terms);
    let tolerance = 1e-9 * q.amax().max(1.0);
    let mut r = 0;
    for g in &gaps {
        let phi = terms.h[r];
        r += g.rows();
        if phi < -tolerance {
            let what = match g.kind {
                GapKind::String { .. } => "is stretched",
                _ => "penetrates",
            };
            return Err(SimError::InvalidInput(format!(
                "the start violates `{}`: it {what} by {:.3e} (its gap is {phi:.3e}); start the model clear of it (move it up or apart), or shorten the string's length",
                g.name, -phi
            )));
        }
    }
    Ok(moved)
}
