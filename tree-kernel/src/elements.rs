//! Springs, dampers and holonomic constraints, written once over any [`Scalar`] so that the
//! interpreted system evaluates them and `tree_model!` compiles them (docs/derivations.md §5).
//!
//! Everything here is built from the world kinematics of the frames an element attaches to,
//! which the outward sweep leaves in the workspace: the origin `p_f`, the point Jacobian
//! columns `J_a = ∂p_f/∂q_a` and the world axes `w_a` of the variables above f. For a
//! variable ia at or above ib (both moving f), `∂²p_f/∂q_ia∂q_ib = w_ia × J_ib`, and a vector `n`
//! fixed in f's axes has `∂n/∂q_ia = w_ia × n`, `∂²n/∂q_ia∂q_ib = w_ia × (w_ib × n)`. A pair of
//! frames a, b gives `d = p_a − p_b` and its derivative columns `Dd_i`; every element is a
//! scalar function of `d` (and of frame a's axes, for a plane), differentiated by the chain
//! rule.
//!
//! Sign conventions: springs' potentials are subtracted from `L`; forces are generalized
//! forces `F(q, q̇)` on the right of `d/dt ∂L/∂q̇ − ∂L/∂q = F + u + Dhᵀλ`.

use tree_model::{ConstraintKind, Parameter, SpringKind};

use crate::order::Order;
use crate::outputs::{Output, Sink};
use crate::plan::TreePlan;
use crate::scalar::Scalar;
use crate::se3::cross;
use crate::sweeps::Workspace;

/// What the elements read — the outward sweep's kinematics, in the tree's workspace — and
/// write: their own scratch, kept beside that workspace.
pub(crate) struct At<'a, S: Scalar> {
    pub(crate) tree: &'a Workspace<S>,
    pub(crate) scratch: &'a mut Scratch<S>,
}

/// Per-variable scratch for the elements (allocated once, beside the tree's workspace).
#[derive(Clone, Debug)]
pub struct Scratch<S> {
    n: usize,
    /// `Dd_i = ∂(p_a − p_b)/∂q_i`.
    pub(crate) dd: Vec<[S; 3]>,
    /// Gradient of the element's scalar function.
    pub(crate) grad: Vec<S>,
    /// Its Hessian, row-major `n × n`; zero outside the pairs of `vars`.
    hess: Vec<S>,
    /// The variables the current element depends on.
    pub(crate) vars: Vec<usize>,
    involved: Vec<bool>,
    /// Whether the current element wrote into `hess` (so `reset` must clear it).
    hess_used: bool,
}

impl<S: Scalar> Scratch<S> {
    /// Empty, for `n` variables.
    pub fn new(n: usize) -> Self {
        Scratch {
            n,
            dd: vec![[S::zero(); 3]; n],
            grad: vec![S::zero(); n],
            hess: vec![S::zero(); n * n],
            vars: Vec::with_capacity(n),
            involved: vec![false; n],
            hess_used: false,
        }
    }

    /// Forgets the last element: zeroes what it touched.
    pub(crate) fn reset(&mut self) {
        for &i in &self.vars {
            self.dd[i] = [S::zero(); 3];
            self.grad[i] = S::zero();
            self.involved[i] = false;
            if self.hess_used {
                for &j in &self.vars {
                    self.hess[i * self.n + j] = S::zero();
                }
            }
        }
        self.hess_used = false;
        self.vars.clear();
    }

    pub(crate) fn involve(&mut self, i: usize) {
        if !self.involved[i] {
            self.involved[i] = true;
            self.vars.push(i);
        }
    }

    pub(crate) fn add_hess(&mut self, i: usize, j: usize, x: S) {
        self.hess_used = true;
        self.hess[i * self.n + j] += x;
    }

    /// Adds `x` at `(i, j)` and, off the diagonal, at `(j, i)`.
    pub(crate) fn add_hess_sym(&mut self, i: usize, j: usize, x: S) {
        self.add_hess(i, j, x);
        if i != j {
            self.add_hess(j, i, x);
        }
    }

    pub(crate) fn hess_at(&self, i: usize, j: usize) -> S {
        self.hess[i * self.n + j]
    }
}

#[inline(always)]
pub(crate) fn dot3<S: Scalar>(a: &[S; 3], b: &[S; 3]) -> S {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn sub3<S: Scalar>(a: &[S; 3], b: &[S; 3]) -> [S; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `(plan column offset, ancestor variables)` of plan frame `f`.
pub(crate) fn columns(plan: &TreePlan, f: usize) -> (usize, &[usize]) {
    (plan.frames[f].col_offset, plan.ancestors(f))
}

/// Starts an element on the pair `(a, b)`: returns `d = p_a − p_b` and fills `Dd`.
pub(crate) fn pair<S: Scalar>(plan: &TreePlan, ws: &mut At<'_, S>, a: usize, b: usize) -> [S; 3] {
    ws.scratch.reset();
    for (f, sign) in [(a, 1.0), (b, -1.0)] {
        let (col, vars) = columns(plan, f);
        for (ia, &i) in vars.iter().enumerate() {
            ws.scratch.involve(i);
            let j = ws.tree.point_jac[col + ia];
            let s = S::constant(sign);
            for c in 0..3 {
                ws.scratch.dd[i][c] += s * j[c];
            }
        }
    }
    sub3(&ws.tree.pose[a].p, &ws.tree.pose[b].p)
}

/// Adds `scale · c·∂²p_f/∂q∂q` (c a world vector) into the Hessian scratch.
pub(crate) fn add_point_hessian<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    f: usize,
    c: &[S; 3],
    scale: S,
) {
    let (col, vars) = columns(plan, f);
    for ia in 0..vars.len() {
        for ib in ia..vars.len() {
            let x = dot3(
                c,
                &cross(&ws.tree.axis[col + ia], &ws.tree.point_jac[col + ib]),
            );
            ws.scratch.add_hess_sym(vars[ia], vars[ib], scale * x);
        }
    }
}

/// `Σ_{a,b} q̇_a q̇_b X_ab` for the pattern `X_ab = w_a × x_b` (`a` at or above `b`, and
/// symmetric) over frame `f`'s variables, `x_b = column(b)`: `Σ_b q̇_b (2Ω_b + q̇_b w_b) × x_b`
/// with `Ω_b = Σ_{a above b} q̇_a w_a`. With `x_b = J_b` it is `q̇ᵀ(∂²p_f/∂q²)q̇`, the
/// acceleration of f's origin at `q̈ = 0`; with `x_b = w_b × n`, `q̇ᵀ(∂²n/∂q²)q̇` for a vector
/// `n` fixed in f. O(depth), where the Hessian's pairs are O(depth²).
fn curvature_along<S: Scalar>(
    plan: &TreePlan,
    ws: &At<'_, S>,
    f: usize,
    dq: &[S],
    column: impl Fn(usize) -> [S; 3],
) -> [S; 3] {
    let (col, vars) = columns(plan, f);
    let two = S::constant(2.0);
    let mut above = [S::zero(); 3];
    let mut sum = [S::zero(); 3];
    for (ib, &b) in vars.iter().enumerate() {
        let w = ws.tree.axis[col + ib];
        let lead: [S; 3] = std::array::from_fn(|c| two * above[c] + dq[b] * w[c]);
        let x = cross(&lead, &column(ib));
        for c in 0..3 {
            sum[c] += dq[b] * x[c];
            above[c] += dq[b] * w[c];
        }
    }
    sum
}

/// `q̇ᵀ(∂²p_f/∂q²)q̇` (world): frame `f`'s origin's acceleration at `q̈ = 0` ([`curvature_along`]).
fn point_curvature<S: Scalar>(plan: &TreePlan, ws: &At<'_, S>, f: usize, dq: &[S]) -> [S; 3] {
    let col = plan.frames[f].col_offset;
    curvature_along(plan, ws, f, dq, |b| ws.tree.point_jac[col + b])
}

/// `ḋ = Σ_i Dd_i q̇_i` of the current pair.
fn pair_rate<S: Scalar>(ws: &At<'_, S>, dq: &[S]) -> [S; 3] {
    let sc = &ws.scratch;
    let mut rate = [S::zero(); 3];
    for &i in &sc.vars {
        for c in 0..3 {
            rate[c] += sc.dd[i][c] * dq[i];
        }
    }
    rate
}

/// Hessian of `s = d·d` into the scratch: `2 Dd_i·Dd_j + 2 d·∂²d/∂q_i∂q_j`.
pub(crate) fn squared_distance_hessian<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    a: usize,
    b: usize,
    d: &[S; 3],
) {
    let two = S::constant(2.0);
    let sc = &mut ws.scratch;
    for x in 0..sc.vars.len() {
        for y in x..sc.vars.len() {
            let (i, j) = (sc.vars[x], sc.vars[y]);
            let v = two * dot3(&sc.dd[i], &sc.dd[j]);
            sc.add_hess_sym(i, j, v);
        }
    }
    add_point_hessian(plan, ws, a, d, two);
    add_point_hessian(plan, ws, b, d, -two);
}

/// Emits the current element's value, gradient, `q̇ᵀD²h q̇` (`curvature`, from
/// `Order::Dynamics` on) and Hessian (at `Order::Full`) as constraint row `r`.
pub(crate) fn emit_row<S: Scalar>(
    ws: &At<'_, S>,
    r: usize,
    h: S,
    curvature: S,
    order: Order,
    out: &mut impl Sink<S>,
) {
    let sc = &ws.scratch;
    out.add(Output::H(r), h);
    for &i in &sc.vars {
        out.add(Output::Dh(r, i), sc.grad[i]);
    }
    if order < Order::Dynamics {
        return;
    }
    out.add(Output::DhDot(r), curvature);
    if order >= Order::Full {
        for &i in &sc.vars {
            for &j in &sc.vars {
                out.add(Output::D2h(r, i, j), sc.hess_at(i, j));
            }
        }
    }
}

/// Every constraint row `h_r(q)` with its derivatives (docs/derivations.md §5.1):
/// * distance: `h = d·d − ℓ²`;
/// * plane: `h = n·(p_b − p_a)`, `n = R_a n_a` turning with frame a;
/// * point: `h = e_k·d` for each listed world axis k.
pub fn constraints<S: Scalar>(
    plan: &TreePlan,
    tree: &Workspace<S>,
    scratch: &mut Scratch<S>,
    q: &[S],
    dq: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let ws = &mut At { tree, scratch };
    let mut r = 0;
    for con in &plan.constraints {
        let row = Row {
            frames: con.frames,
            first: r,
            order,
        };
        r += match &con.kind {
            ConstraintKind::Distance { length } => distance_row(plan, ws, &row, length, q, dq, out),
            ConstraintKind::Plane { normal } => plane_row(plan, ws, &row, normal, dq, out),
            ConstraintKind::Point { axes } => point_rows(plan, ws, &row, axes, dq, out),
        };
    }
}

/// Where a constraint's rows go: its two frames, its first row, and the evaluation's order
/// (`q̇ᵀD²h q̇` from `Order::Dynamics` on, by the frames' curvatures, O(depth); the whole
/// Hessian `D²h` only at `Order::Full`).
struct Row {
    frames: [usize; 2],
    first: usize,
    order: Order,
}

/// A distance constraint's row `h = ‖p_a − p_b‖² − ℓ²` (docs/derivations.md §5);
/// the rows written (one).
fn distance_row<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    row: &Row,
    length: &Parameter,
    q: &[S],
    dq: &[S],
    out: &mut impl Sink<S>,
) -> usize {
    let ([a, b], r, order) = (row.frames, row.first, row.order);
    let (second, full) = (order >= Order::Dynamics, order >= Order::Full);
    let two = S::constant(2.0);
    // q̇ᵀD²h q̇ = 2ḋ·ḋ + 2d·(κ_a − κ_b) − 2q̇_ℓ² (κ: the points' curvatures).
    let d = pair(plan, ws, a, b);
    let mut curvature = S::zero();
    if second {
        let rate = pair_rate(ws, dq);
        let (ka, kb) = (
            point_curvature(plan, ws, a, dq),
            point_curvature(plan, ws, b, dq),
        );
        curvature = two * (dot3(&rate, &rate) + dot3(&d, &sub3(&ka, &kb)));
    }
    let sc = &mut ws.scratch;
    for x in 0..sc.vars.len() {
        let i = sc.vars[x];
        sc.grad[i] = two * dot3(&d, &sc.dd[i]);
    }
    let l = match *length {
        Parameter::Constant(l) => S::constant(l),
        Parameter::Variable(i) => {
            sc.involve(i);
            sc.grad[i] -= two * q[i];
            if full {
                sc.add_hess(i, i, -two);
            }
            curvature -= two * dq[i] * dq[i];
            q[i]
        }
    };
    if full {
        squared_distance_hessian(plan, ws, a, b, &d);
    }
    emit_row(ws, r, dot3(&d, &d) - l * l, curvature, order, out);
    1
}

/// A plane constraint's row `h = n·(p_b − p_a)`, `n` fixed in frame a's axes; the rows
/// written (one).
fn plane_row<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    row: &Row,
    normal: &[f64; 3],
    dq: &[S],
    out: &mut impl Sink<S>,
) -> usize {
    let ([a, b], r, order) = (row.frames, row.first, row.order);
    let (second, full) = (order >= Order::Dynamics, order >= Order::Full);
    let two = S::constant(2.0);
    let d = pair(plan, ws, a, b);
    let e = [-d[0], -d[1], -d[2]];
    let n = ws.tree.pose[a].rotate(&normal.map(S::constant));
    let n_cross_e = cross(&n, &e);
    let (col, anc) = columns(plan, a);
    // q̇ᵀD²h q̇ = n·(κ_b − κ_a) + 2ṅ·ė + (q̇ᵀ∂²n q̇)·e, ṅ = ω_a × n, ė = −ḋ.
    let mut curvature = S::zero();
    if second {
        let rate = pair_rate(ws, dq);
        let mut omega = [S::zero(); 3];
        for (ia, &i) in anc.iter().enumerate() {
            let w = ws.tree.axis[col + ia];
            for c in 0..3 {
                omega[c] += dq[i] * w[c];
            }
        }
        let n_rate = cross(&omega, &n);
        let n_curvature = curvature_along(plan, ws, a, dq, |ib| cross(&ws.tree.axis[col + ib], &n));
        let (ka, kb) = (
            point_curvature(plan, ws, a, dq),
            point_curvature(plan, ws, b, dq),
        );
        curvature = dot3(&n, &sub3(&kb, &ka)) - two * dot3(&n_rate, &rate) + dot3(&n_curvature, &e);
    }
    let sc = &mut ws.scratch;
    for x in 0..sc.vars.len() {
        let i = sc.vars[x];
        sc.grad[i] = -dot3(&n, &sc.dd[i]);
    }
    // ∂n/∂q_i · e = (w_i × n)·e = w_i·(n × e).
    for (ia, &i) in anc.iter().enumerate() {
        sc.grad[i] += dot3(&ws.tree.axis[col + ia], &n_cross_e);
    }
    if full {
        // n·∂²e = n·(∂²p_b − ∂²p_a).
        add_point_hessian(plan, ws, b, &n, S::constant(1.0));
        add_point_hessian(plan, ws, a, &n, S::constant(-1.0));
        let (col, anc) = columns(plan, a);
        for ia in 0..anc.len() {
            let w_a = ws.tree.axis[col + ia];
            let dn = cross(&w_a, &n);
            // ∂²n·e over pairs of frame a's variables.
            for ib in ia..anc.len() {
                let x = dot3(&cross(&w_a, &cross(&ws.tree.axis[col + ib], &n)), &e);
                ws.scratch.add_hess_sym(anc[ia], anc[ib], x);
            }
            // ∂n_i·∂e_j + ∂n_j·∂e_i, with ∂e = −Dd.
            let sc = &mut ws.scratch;
            for y in 0..sc.vars.len() {
                let j = sc.vars[y];
                let x = -dot3(&dn, &sc.dd[j]);
                sc.add_hess(anc[ia], j, x);
                sc.add_hess(j, anc[ia], x);
            }
        }
    }
    emit_row(ws, r, dot3(&n, &e), curvature, order, out);
    1
}

/// A point constraint's rows `h_k = e_k·(p_a − p_b)`, one per listed world axis; the rows
/// written.
fn point_rows<S: Scalar>(
    plan: &TreePlan,
    ws: &mut At<'_, S>,
    row: &Row,
    axes: &[usize],
    dq: &[S],
    out: &mut impl Sink<S>,
) -> usize {
    let ([a, b], mut r, order) = (row.frames, row.first, row.order);
    let (second, full) = (order >= Order::Dynamics, order >= Order::Full);
    // q̇ᵀD²h q̇ = e_k·(κ_a − κ_b).
    let relative = if second {
        sub3(
            &point_curvature(plan, ws, a, dq),
            &point_curvature(plan, ws, b, dq),
        )
    } else {
        [S::zero(); 3]
    };
    for &k in axes {
        let d = pair(plan, ws, a, b);
        let sc = &mut ws.scratch;
        for x in 0..sc.vars.len() {
            let i = sc.vars[x];
            sc.grad[i] = sc.dd[i][k];
        }
        if full {
            let mut e = [S::zero(); 3];
            e[k] = S::constant(1.0);
            add_point_hessian(plan, ws, a, &e, S::constant(1.0));
            add_point_hessian(plan, ws, b, &e, S::constant(-1.0));
        }
        emit_row(ws, r, d[k], relative[k], order, out);
        r += 1;
    }
    axes.len()
}

/// Springs' potentials `V` subtracted from `L`, `∂L/∂q` and (at `Order::Full`) `∂²L/∂q²`.
/// Between frames `V = ½k(r − r₀)²` with `r = ‖d‖`: `∂V/∂q_i = kib d·Dd_i` and
/// `∂²V/∂q_i∂q_j = k[(r₀/r³)(d·Dd_i)(d·Dd_j) + ib(Dd_i·Dd_j + d·∂²d/∂q_i∂q_j)]`, `ib = 1 − r₀/r`.
pub fn springs<S: Scalar>(
    plan: &TreePlan,
    tree: &Workspace<S>,
    scratch: &mut Scratch<S>,
    q: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let ws = &mut At { tree, scratch };
    let full = order >= Order::Full;
    for spring in &plan.springs {
        let k = S::constant(spring.stiffness);
        let rest = S::constant(spring.rest);
        match spring.kind {
            SpringKind::Variable(i) => {
                let x = q[i] - rest;
                out.add(Output::L, -(S::constant(0.5) * k * x * x));
                out.add(Output::DlDq(i), -(k * x));
                if full {
                    out.add(Output::D2lDqDq(i, i), -k);
                }
            }
            SpringKind::Frames([a, b]) => {
                let d = pair(plan, ws, a, b);
                let (potential, beta, rest_over_r3) = distance_spring(spring, dot3(&d, &d));
                out.add(Output::L, -potential);
                let sc = &mut ws.scratch;
                for x in 0..sc.vars.len() {
                    let i = sc.vars[x];
                    sc.grad[i] = dot3(&d, &sc.dd[i]);
                    out.add(Output::DlDq(i), -(k * beta * sc.grad[i]));
                }
                if full {
                    // ib·∂²(½ d·d) first, then the r₀/r³ outer product.
                    squared_distance_hessian(plan, ws, a, b, &d);
                    let sc = &ws.scratch;
                    let half = S::constant(0.5);
                    for &i in &sc.vars {
                        for &j in &sc.vars {
                            let h = k
                                * (rest_over_r3 * sc.grad[i] * sc.grad[j]
                                    + beta * half * sc.hess_at(i, j));
                            out.add(Output::D2lDqDq(i, j), -h);
                        }
                    }
                }
            }
        }
    }
}

/// A spring between frames at squared distance `s = d·d`: its potential `½k(r − r₀)²`, and
/// `ib = 1 − r₀/r`, `r₀/r³` for its derivatives ([`springs`]); with zero rest length
/// `V = ½k d·d`, smooth through `d = 0`.
fn distance_spring<S: Scalar>(spring: &tree_model::Spring, s: S) -> (S, S, S) {
    let (k, rest) = (S::constant(spring.stiffness), S::constant(spring.rest));
    if spring.rest == 0.0 {
        return (S::constant(0.5) * k * s, S::constant(1.0), S::zero());
    }
    let r = s.sqrt();
    let inv = r.recip();
    let stretch = r - rest;
    (
        S::constant(0.5) * k * stretch * stretch,
        S::constant(1.0) - rest * inv,
        rest * inv * inv * inv,
    )
}

/// The springs' potential energy `V` (as [`springs`] subtracts it from `L`) from the outward
/// sweep's poses alone, without its derivatives: what the total energy needs.
pub fn potential<S: Scalar>(plan: &TreePlan, tree: &Workspace<S>, q: &[S]) -> S {
    let mut v = S::zero();
    for spring in &plan.springs {
        v += match spring.kind {
            SpringKind::Variable(i) => {
                let x = q[i] - S::constant(spring.rest);
                S::constant(0.5) * S::constant(spring.stiffness) * x * x
            }
            SpringKind::Frames([a, b]) => {
                let d = sub3(&tree.pose[a].p, &tree.pose[b].p);
                distance_spring(spring, dot3(&d, &d)).0
            }
        };
    }
    v
}

/// The model's own generalized forces: per-variable damping `−c_i q̇_i` and dampers
/// `F = −c ṙ ∇r` (`r = ‖d‖`, `ṙ = ∇r·q̇`), with `∂F/∂q̇ = −c ∇r∇rᵀ` and
/// `∂F/∂q = −c(∇r (∇²r q̇)ᵀ + ṙ ∇²r)` at `Order::Full` (for the VI's Newton Jacobian).
pub fn forces<S: Scalar>(
    plan: &TreePlan,
    tree: &Workspace<S>,
    scratch: &mut Scratch<S>,
    dq: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    let ws = &mut At { tree, scratch };
    let full = order >= Order::Full;
    for (i, &c) in plan.damping.iter().enumerate() {
        if c != 0.0 {
            out.add(Output::Force(i), -(S::constant(c) * dq[i]));
            if full {
                out.add(Output::DforceDdq(i, i), S::constant(-c));
            }
        }
    }
    for damper in &plan.dampers {
        let [a, b] = damper.frames;
        let c = S::constant(damper.damping);
        let d = pair(plan, ws, a, b);
        let r = dot3(&d, &d).sqrt();
        let inv = r.recip();
        let sc = &mut ws.scratch;
        // ∇r_i = d·Dd_i / r
        let mut rate = S::zero();
        for x in 0..sc.vars.len() {
            let i = sc.vars[x];
            sc.grad[i] = dot3(&d, &sc.dd[i]) * inv;
            rate += sc.grad[i] * dq[i];
        }
        for &i in &sc.vars {
            out.add(Output::Force(i), -(c * rate * sc.grad[i]));
        }
        if !full {
            continue;
        }
        // ∇²r = (∂²(½ d·d) − ∇r∇rᵀ)/r
        squared_distance_hessian(plan, ws, a, b, &d);
        let sc = &mut ws.scratch;
        let half = S::constant(0.5);
        for x in 0..sc.vars.len() {
            for y in 0..sc.vars.len() {
                let (i, j) = (sc.vars[x], sc.vars[y]);
                let v = (half * sc.hess_at(i, j) - sc.grad[i] * sc.grad[j]) * inv;
                sc.hess[i * sc.n + j] = v;
                sc.hess_used = true;
            }
        }
        let sc = &ws.scratch;
        for &j in &sc.vars {
            // (∇²r q̇)_j
            let mut rho = S::zero();
            for &i in &sc.vars {
                rho += sc.hess_at(i, j) * dq[i];
            }
            for &i in &sc.vars {
                out.add(Output::DforceDdq(i, j), -(c * sc.grad[i] * sc.grad[j]));
                out.add(
                    Output::DforceDq(i, j),
                    -(c * (sc.grad[i] * rho + rate * sc.hess_at(i, j))),
                );
            }
        }
    }
}
