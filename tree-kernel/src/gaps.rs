//! The unilateral rows — gaps `φ(q) ≥ 0` and friction's tangent rows — written once over any
//! [`Scalar`], so the interpreted system evaluates them and `tree_model!` compiles them
//! (docs/derivations.md §13). Each row is emitted as a constraint row is
//! ([`Output::H`], [`Output::Dh`], at `Order::Full` [`Output::D2h`]) into its own terms:
//! * a limit: `φ = q_i − lo` or `hi − q_i`;
//! * a sphere of radius r on frame f over the ground `n·x = height`: `φ = n·p_f − height − r`,
//!   and with friction the tangent rows `τ_k = t_k·p_f` (k = 1, 2), whose change over a step is
//!   the centre's tangential displacement;
//! * two spheres: `φ = ‖p_a − p_b‖ − r_a − r_b`;
//! * a slack string of length ℓ: `φ = ℓ − ‖p_a − p_b‖`.
//!
//! A distance `ρ = ‖d‖`, `d = p_a − p_b`, is differentiated from `s = d·d`:
//! `∂ρ = ∂s/(2ρ)` and `∂²ρ = ∂²s/(2ρ) − ∂ρ ∂ρᵀ/ρ`.

use tree_model::{GapKind, Parameter};

use crate::elements::{
    add_point_hessian, dot3, emit_row, pair, squared_distance_hessian, At, Scratch,
};
use crate::order::Order;
use crate::outputs::{Output, Sink};
use crate::plan::TreePlan;
use crate::scalar::Scalar;
use crate::sweeps::Workspace;

/// Every unilateral row at `q` with `Dh` and, at `Order::Full`, `D²h` (rows in
/// [`TreePlan::gaps`] order, a frictional contact's gap before its two tangent rows).
pub fn gaps<S: Scalar>(
    plan: &TreePlan,
    tree: &Workspace<S>,
    scratch: &mut Scratch<S>,
    q: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let ws = &mut At { tree, scratch };
    let full = order >= Order::Full;
    let mut r = 0;
    for gap in &plan.gaps {
        match gap.kind {
            GapKind::Lower { variable, bound } => {
                limit_row(ws, r, variable, q[variable] - S::constant(bound), 1.0, out);
            }
            GapKind::Upper { variable, bound } => {
                limit_row(ws, r, variable, S::constant(bound) - q[variable], -1.0, out);
            }
            GapKind::Ground {
                frame,
                radius,
                ground,
                tangents,
            } => {
                let offset = S::constant(ground.height + radius);
                point_row(plan, ws, r, frame, &ground.normal, offset, full, out);
                if gap.friction > 0.0 {
                    for (k, t) in tangents.iter().enumerate() {
                        point_row(plan, ws, r + 1 + k, frame, t, S::zero(), full, out);
                    }
                }
            }
            GapKind::Spheres { frames, radii } => {
                let offset = S::constant(radii);
                distance_row(plan, ws, r, frames, offset, 1.0, full, out);
            }
            GapKind::String { frames, length } => {
                let (ell, variable) = match length {
                    Parameter::Constant(l) => (S::constant(l), None),
                    Parameter::Variable(i) => (q[i], Some(i)),
                };
                distance_row(plan, ws, r, frames, ell, -1.0, full, out);
                if let Some(i) = variable {
                    // φ = ℓ − ρ: the length's own column.
                    out.add(Output::Dh(r, i), S::constant(1.0));
                }
            }
        }
        r += gap.rows();
    }
}

/// A limit's row: `φ` and its one derivative `sign`.
fn limit_row<S: Scalar>(
    ws: &mut At<'_, S>,
    r: usize,
    i: usize,
    phi: S,
    sign: f64,
    out: &mut impl Sink<S>,
) {
    ws.scratch.reset();
    ws.scratch.involve(i);
    ws.scratch.grad[i] = S::constant(sign);
    emit_row(ws, r, phi, S::zero(), Order::First, out);
}

/// `c·p_f − offset` (c a constant world vector) with its derivatives, as row `r`.
#[allow(clippy::too_many_arguments)]
fn point_row<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    r: usize,
    f: usize,
    c: &[f64; 3],
    offset: S,
    full: bool,
    out: &mut impl Sink<S>,
) {
    let c = c.map(S::constant);
    // A pair with the frame itself, read as one point: `Dd` is then `J_f`, `d = 0`.
    let p = single(plan, ws, f);
    let sc = &mut ws.scratch;
    for x in 0..sc.vars.len() {
        let i = sc.vars[x];
        sc.grad[i] = dot3(&c, &sc.dd[i]);
    }
    if full {
        add_point_hessian(plan, ws, f, &c, S::constant(1.0));
    }
    let order = if full { Order::Full } else { Order::First };
    emit_row(ws, r, dot3(&c, &p) - offset, S::zero(), order, out);
}

/// Starts an element on frame `f` alone: returns `p_f` and fills `Dd` with `J_f`.
fn single<S: Scalar>(plan: &TreePlan, ws: &mut At<'_, S>, f: usize) -> [S; 3] {
    ws.scratch.reset();
    let (col, vars) = crate::elements::columns(plan, f);
    for (ia, &i) in vars.iter().enumerate() {
        ws.scratch.involve(i);
        ws.scratch.dd[i] = ws.tree.point_jac[col + ia];
    }
    ws.tree.pose[f].p
}

/// `sign·(ρ − offset)`, `ρ = ‖p_a − p_b‖`, with its derivatives as row `r`.
#[allow(clippy::too_many_arguments)]
fn distance_row<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    r: usize,
    [a, b]: [usize; 2],
    offset: S,
    sign: f64,
    full: bool,
    out: &mut impl Sink<S>,
) {
    let d = pair(plan, ws, a, b);
    let rho = dot3(&d, &d).sqrt();
    let inverse = rho.recip();
    let s = S::constant(sign);
    // ∂(sign ρ) = sign (d·Dd_i)/ρ.
    let sc = &mut ws.scratch;
    for x in 0..sc.vars.len() {
        let i = sc.vars[x];
        sc.grad[i] = s * dot3(&d, &sc.dd[i]) * inverse;
    }
    if full {
        // ∂²s/(2ρ) − ∂ρ ∂ρᵀ/ρ, times sign: the Hessian of s scaled, then the outer product.
        squared_distance_hessian(plan, ws, a, b, &d);
        let half = S::constant(0.5 * sign) * inverse;
        let sc = &mut ws.scratch;
        for x in 0..sc.vars.len() {
            for y in 0..sc.vars.len() {
                let (i, j) = (sc.vars[x], sc.vars[y]);
                let h = sc.hess_at(i, j);
                // grad = sign ∂ρ, so ∂ρ_i ∂ρ_j = grad_i grad_j (sign² = 1).
                let outer = sc.grad[i] * sc.grad[j] * inverse;
                let value = half * h - s * outer;
                sc.add_hess(i, j, value - h);
            }
        }
    }
    let order = if full { Order::Full } else { Order::First };
    emit_row(ws, r, s * (rho - offset), S::zero(), order, out);
}
