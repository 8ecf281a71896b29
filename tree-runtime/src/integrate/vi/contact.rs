//! The contact step: the discrete Euler–Lagrange equations with unilateral rows, solved by a
//! primal-dual interior point inside the VI's Newton iteration (docs/derivations.md §13).
//!
//! Unknowns, in order: the dynamic part of `q₂`, the bilateral constraints' `λ`, then per
//! unilateral element its normal impulse `γ` and gap slack `s` and, for a ground contact with
//! friction, its friction impulse `b ∈ ℝ²` and the cone point `η = (ψ, δ)`. Equations:
//! * `r_d(q₂) + Nᵀγ + Tᵀb = 0` (`N = Dφ(q₂)`, `T` the tangent rows at `q₂`: the impulses
//!   act at the step's end configuration, where the gap is measured);
//! * `h(q₂) = 0`;
//! * `s − φ(q₂) = 0` and `s γ = κ` (`s, γ > 0`);
//! * `δ − (τ(q₂) − τ(q₁)) = 0`, the contact's tangential displacement over the step, and
//!   `(μγ, b) ∘ (ψ, δ) = κ e` with both points inside the second-order cone: Coulomb friction
//!   by maximum dissipation (`b` minimises `b·δ` over `‖b‖ ≤ μγ`), the exact cone.
//!
//! Each iteration forms the whole Newton matrix with the exact Jacobian (the VI's eq. (26)
//! plus the impulses' `Σ γ D²φ + Σ b·D²τ`), factors it once and solves twice: Mehrotra's
//! predictor (the affine direction, `κ = 0`) and corrector (centring `σμ`, `σ = (μ_aff/μ)³`,
//! with the second-order term `Δs_aff Δγ_aff`), each step kept inside the cones by a fraction
//! 0.99 of the way to their boundary (nearer 1 only once the residuals are small) and inside
//! the central path's wide neighbourhood (no pair's complementarity below 10⁻³ of the mean);
//! a short step is followed by a pure centring one. Without those two guards an iterate can
//! reach a cone's boundary far from the solution and jam there, each step shrinking by the
//! fraction (docs/derivations.md §13). Hard contact drives the complementarity to the
//! tolerance; a user's `κ > 0` (`ViSettings::kappa`) stops on its central path instead.

use nalgebra::{allocator::Allocator, DMatrix, DefaultAllocator, Dim};

use super::{below_rounding, MidpointVi};
use crate::cone::{self, Point};
use crate::context::StepContext;
use crate::dynamics::{GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::linalg::{
    cholesky_backward, cholesky_forward_many, lu_factor_packed, lu_factor_packed_unguarded,
    lu_solve_packed, semidefinite_solve,
};

mod mode;
use crate::system::{ConstraintTerms, System, Vector};

/// Iterations a contact step may take before it fails.
const MAX_ITERATIONS: usize = 60;

/// How far towards a cone's boundary a step goes.
const FRACTION_TO_BOUNDARY: f64 = 0.99;

/// The largest fraction of the way to a cone's boundary a step goes (never onto it: a point
/// on the boundary makes the Newton matrix singular).
const LAST_FRACTION: f64 = 1.0 - 1e-6;

/// The wide neighbourhood of the central path the iterates keep to: after a step every
/// pair's complementarity (a cone pair's `√(det x det y)`) is at least this fraction of the
/// mean. Off it, a point nears a cone's boundary with a Newton direction pointing out, and
/// the fraction to the boundary shrinks towards zero step after step (a jam).
const NEIGHBOURHOOD: f64 = 1e-3;

/// A step shorter than this fraction of its direction is followed by a centring one
/// (`σ = 1`, no second-order term), which moves back towards the central path.
const SHORT_STEP: f64 = 0.1;

/// Halvings of a step kept in the neighbourhood before it is taken as it is.
const NEIGHBOURHOOD_HALVINGS: usize = 40;

/// The complementarity a fresh step starts from, as a gap in metres (or radians) times the
/// step's momentum scale.
const START_GAP: f64 = 1e-3;

/// One unilateral element's place in the step.
#[derive(Clone, Debug)]
struct Element {
    /// Its place in the model's list (names, `forced`).
    index: usize,
    /// Its gap's row in the gap terms (its tangent rows follow).
    row: usize,
    /// Index of its `γ` among the unknowns (`s` next; with friction `b` and `η` after).
    base: usize,
    /// Coulomb coefficient (0: no friction unknowns).
    friction: f64,
}

impl Element {
    fn has_friction(&self) -> bool {
        self.friction > 0.0
    }

    /// Its gap rows: the gap, and the two tangent rows with friction.
    fn rows(&self) -> usize {
        if self.has_friction() {
            3
        } else {
            1
        }
    }
}

/// The contact step's workspace (allocated once; nothing per step).
#[derive(Clone, Debug)]
pub(crate) struct ContactStep {
    /// Every unilateral element of the model.
    all: Vec<Element>,
    /// The elements the current step solves for, their unknowns packed after `q₂` and `λ`
    /// (every one at κ > 0; at hard contact those a step could close, see [`Self::select`]).
    elements: Vec<Element>,
    /// Elements a hard step found closed though left out, taken in for the rest of it.
    forced: Vec<bool>,
    /// Whether each element is among `elements` this step.
    selected: Vec<bool>,
    /// The elements' names, for errors.
    names: Vec<String>,
    /// Number of unknowns of the current step (at most `q₂`, `λ` and every element's).
    nz: usize,
    /// The last step's mode as this step's rows ([`mode`]), their unknowns packed after
    /// `q₂` and `λ`, and how many unknowns that makes.
    mode: Vec<Element>,
    /// Whether each mode element slides (its friction on the cone's edge).
    sliding: Vec<bool>,
    /// Whether each element of the model is in the mode.
    in_mode: Vec<bool>,
    mode_nz: usize,
    /// φ, Dφ and the weighted Hessian at the current `q₂`.
    gaps: ConstraintTerms,
    /// Every gap row's value at `q₁` (the tangent rows' `τ(q₁)`) and its derivative.
    at_start: Vec<f64>,
    dh_start: DMatrix<f64>,
    /// The impulses as the gap rows' weights: `γ` at a gap row, `b` at its tangent rows.
    weights: Vec<f64>,
    /// Unknowns (the `q₂` and `λ` entries are updates' scratch; the contact ones persist).
    z: Vec<f64>,
    residual: Vec<f64>,
    matrix: Vec<f64>,
    pivots: Vec<usize>,
    affine: Vec<f64>,
    direction: Vec<f64>,
    /// The last step was short ([`SHORT_STEP`]): the next direction only centres.
    centre: bool,
    /// The last step's impulses per gap row (γ, then b at tangent rows) and gaps at `q₂`.
    pub(crate) impulses: Vec<f64>,
    pub(crate) gap_values: Vec<f64>,
    /// The last step was solved free: every gap open at its end with no impulse — exact for
    /// hard contact, whose open rows carry none (its derivatives see no contact).
    pub(crate) free: bool,
    /// The last step's impulses were all negligible (the next hard step tries free first).
    quiet: bool,
    /// The predicted `q₂` and the `λ` a free attempt started from, to start again from.
    predicted: Vec<f64>,
    saved_lambda: Vec<f64>,
    /// The velocity projection's workspace: the rows held, `L⁻¹Aᵀ` by rows, the small
    /// system, the velocity change.
    held: Vec<usize>,
    velocity: Vec<f64>,
    solved: Vec<f64>,
    small: Vec<f64>,
    small_pivots: Vec<usize>,
    rhs: Vec<f64>,
}

impl ContactStep {
    /// The workspace for `sys`'s unilateral rows, `nd` dynamic variables and `m` bilateral
    /// rows; `None` without unilateral rows.
    pub(crate) fn new<S: System>(sys: &S, nd: usize, m: usize) -> Option<Box<Self>>
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let gaps = sys.unilateral();
        if gaps.is_empty() {
            return None;
        }
        let (mut row, mut base) = (0, nd + m);
        let mut elements = Vec::with_capacity(gaps.len());
        for (index, g) in gaps.iter().enumerate() {
            elements.push(Element {
                index,
                row,
                base,
                friction: g.friction,
            });
            row += g.rows();
            base += if g.friction > 0.0 { 7 } else { 2 };
        }
        let (rows, nz) = (row, base);
        let count = elements.len();
        // Sized here, so the first contact step allocates nothing either: the weighted
        // Hessian of the gaps and the weights it keeps.
        let mut gap_terms = ConstraintTerms::zeros(rows, sys.dof());
        gap_terms.weigh(&vec![0.0; rows], true);
        Some(Box::new(ContactStep {
            all: elements.clone(),
            forced: vec![false; count],
            selected: vec![false; count],
            elements,
            names: gaps.into_iter().map(|g| g.name).collect(),
            nz,
            mode: Vec::with_capacity(rows),
            sliding: Vec::with_capacity(rows),
            in_mode: vec![false; count],
            mode_nz: 0,
            gaps: gap_terms,
            at_start: vec![0.0; rows],
            dh_start: DMatrix::zeros(rows, sys.dof()),
            weights: vec![0.0; rows],
            z: vec![0.0; nz],
            residual: vec![0.0; nz],
            matrix: vec![0.0; nz * nz],
            pivots: vec![0; nz],
            affine: vec![0.0; nz],
            direction: vec![0.0; nz],
            centre: false,
            impulses: vec![0.0; rows],
            gap_values: vec![0.0; rows],
            free: false,
            quiet: true,
            predicted: vec![0.0; sys.dim().value()],
            saved_lambda: vec![0.0; m],
            held: Vec::with_capacity(rows),
            velocity: vec![0.0; nd],
            solved: vec![0.0; nd * rows],
            small: vec![0.0; rows * rows],
            small_pivots: vec![0; rows],
            rhs: vec![0.0; rows],
        }))
    }
}

/// `(μγ, b)` and `η` of a frictional element in the unknowns `z`.
fn cone_points(e: &Element, z: &[f64]) -> (Point, Point) {
    let b = e.base;
    (
        [e.friction * z[b], z[b + 2], z[b + 3]],
        [z[b + 4], z[b + 5], z[b + 6]],
    )
}

/// The mean complementarity `(Σ sγ + Σ (μγ, b)·η) / count` of the unknowns `z`.
fn mean_complementarity(elements: &[Element], z: &[f64]) -> f64 {
    let mut sum = 0.0;
    let mut count = 0;
    for e in elements {
        sum += z[e.base] * z[e.base + 1];
        count += 1;
        if e.has_friction() {
            let (x, y) = cone_points(e, z);
            sum += x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
            count += 1;
        }
    }
    if count == 0 {
        return 0.0;
    }
    sum / count as f64
}

/// The largest `α ∈ (0, limit]` keeping `z + α·dz` inside every cone (the way to the
/// nearest boundary).
fn step_length(elements: &[Element], z: &[f64], dz: &[f64], limit: f64) -> f64 {
    let mut alpha: f64 = limit;
    for e in elements {
        for k in [e.base, e.base + 1] {
            if dz[k] < 0.0 {
                alpha = alpha.min(-z[k] / dz[k]);
            }
        }
        if e.has_friction() {
            let (x, y) = cone_points(e, z);
            let (dx, dy) = cone_points(e, dz);
            alpha = alpha.min(cone::step_within(&x, &dx, limit));
            alpha = alpha.min(cone::step_within(&y, &dy, limit));
        }
    }
    alpha
}

/// The contact impulses' generalized force `f_c = Σ_r w_r Dφ_r(q₂)` differentiated at a
/// converged step, the impulses eliminated element by element (each one's unknowns are a
/// smooth function of its gap and displacement at κ > 0): rows the dynamic variables,
/// columns every variable (docs/derivations.md §13).
#[derive(Clone, Debug)]
pub(crate) struct ContactJacobian {
    /// `∂f_c/∂q₂ = Σ w D²φ + Σ_e A_eᵀ S_e A_e`, `A_e = (N_e; T_e)` at `q₂` and `S_e` the
    /// element's `∂(γ, b)/∂(φ, δ)`.
    pub(crate) dq2: DMatrix<f64>,
    /// `∂f_c/∂q₁ = −Σ_e A_eᵀ S_e^δ T_e(q₁)` (friction's displacement starts at `q₁`).
    pub(crate) dq1: DMatrix<f64>,
    /// One element's block and right-hand sides (7 × 7, 7 × 3).
    local: Vec<f64>,
    pivots: Vec<usize>,
    sensitivity: Vec<f64>,
}

impl ContactJacobian {
    /// Zeros for `nd` dynamic rows over `n` variables.
    pub(crate) fn new(nd: usize, n: usize) -> Self {
        ContactJacobian {
            dq2: DMatrix::zeros(nd, n),
            dq1: DMatrix::zeros(nd, n),
            local: vec![0.0; 49],
            pivots: vec![0; 7],
            sensitivity: vec![0.0; 21],
        }
    }
}

impl ContactStep {
    /// Chooses the elements the step solves for, their unknowns packed from `first`: all of
    /// them when `every` (κ > 0: each carries `κ/φ`), else — hard contact — those a step could
    /// close: a gap at `q₁` or at the predicted `q₂` (in `gaps`) within twice its change over
    /// the step, those that pressed in the last step, and those found closed before. The
    /// rest are open at the step's end (checked) and carry no impulse: exactly the
    /// complementarity's solution, and their derivatives vanish nearby. A robot far from its
    /// limits solves for none of them.
    fn select(&mut self, every: bool, first: usize) {
        self.elements.clear();
        let mut base = first;
        for e in &self.all {
            let (before, after) = (self.at_start[e.row], self.gaps.h[e.row]);
            let near = before.min(after) <= 2.0 * (after - before).abs();
            let pressed = self.impulses[e.row] > 0.0;
            let take = every || near || pressed || self.forced[e.index];
            self.selected[e.index] = take;
            if take {
                self.elements.push(Element { base, ..e.clone() });
                base += if e.has_friction() { 7 } else { 2 };
            }
        }
        self.nz = base;
    }

    /// Keeps the predicted `q₂` and `λ` a solve starts from, to start again from.
    fn save_prediction(&mut self, q: &[f64], lambda: &[f64]) {
        self.predicted.copy_from_slice(q);
        self.saved_lambda.copy_from_slice(lambda);
    }

    /// Puts back the predicted `q₂` and `λ` after a solve that was not kept.
    fn restore_prediction(&self, q: &mut [f64], lambda: &mut [f64]) {
        q.copy_from_slice(&self.predicted);
        lambda.copy_from_slice(&self.saved_lambda);
    }

    /// A step solved with every row open (`gaps` at its end): no impulse, derivatives free of
    /// contact, the next hard step tried free first.
    fn open_step(&mut self) {
        self.impulses.fill(0.0);
        self.weights.fill(0.0);
        self.gap_values.copy_from_slice(self.gaps.h.as_slice());
        (self.free, self.quiet) = (true, true);
    }

    /// No impulses yet, and the gaps at `q` (a run's first sample).
    pub(crate) fn start_record<S: System>(&mut self, sys: &mut S, q: &Vector<S::N>)
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        sys.gaps(q, None, &mut self.gaps);
        self.gap_values.copy_from_slice(self.gaps.h.as_slice());
        self.impulses.fill(0.0);
        (self.free, self.quiet) = (false, true);
    }

    /// Element `e`'s name.
    pub(crate) fn name(&self, e: usize) -> &str {
        &self.names[e]
    }

    /// The contact force's derivatives at the step just converged into `out`; the element
    /// whose block is singular on failure.
    pub(crate) fn jacobian(
        &self,
        dynamic: &[usize],
        out: &mut ContactJacobian,
    ) -> Result<(), usize> {
        let (g, z) = (&self.gaps, &self.z);
        let n = g.dh.ncols();
        out.dq2.fill(0.0);
        out.dq1.fill(0.0);
        if self.free {
            return Ok(());
        }
        for (ci, &i) in dynamic.iter().enumerate() {
            for j in 0..n {
                // Σ w D²φ is formed on the dynamic columns; symmetric, its kinematic ones are
                // the kinematic rows'.
                out.dq2[(ci, j)] = if dynamic.contains(&j) {
                    g.weighted_d2h[(i, j)]
                } else {
                    g.weighted_d2h[(j, i)]
                };
            }
        }
        for e in &self.elements {
            let size = if e.has_friction() { 7 } else { 2 };
            local_block(e, z, &mut out.local[..size * size]);
            lu_factor_packed_unguarded(&mut out.local[..size * size], size, &mut out.pivots)
                .map_err(|_| e.index)?;
            // dv = G⁻¹ (e_gap dφ + e_fric,k dδ_k): columns φ, δ₁, δ₂.
            let columns = e.rows();
            for col in 0..columns {
                let rhs = &mut out.sensitivity[col * 7..col * 7 + size];
                rhs.fill(0.0);
                rhs[if col == 0 { 0 } else { 1 + col }] = 1.0;
                lu_solve_packed(&out.local[..size * size], size, &out.pivots, rhs);
            }
            // S (rows γ, b₁, b₂ = local unknowns 0, 2, 3) against A = (N; T) rows.
            let unknowns = [0, 2, 3];
            let rows_of = |r: usize| e.row + r;
            for a in 0..columns {
                for col in 0..columns {
                    let s_ac = out.sensitivity[col * 7 + unknowns[a]];
                    if s_ac == 0.0 {
                        continue;
                    }
                    for (ci, &i) in dynamic.iter().enumerate() {
                        let left = g.dh[(rows_of(a), i)] * s_ac;
                        if left == 0.0 {
                            continue;
                        }
                        for j in 0..n {
                            out.dq2[(ci, j)] += left * g.dh[(rows_of(col), j)];
                            if col > 0 {
                                out.dq1[(ci, j)] -= left * self.dh_start[(rows_of(col), j)];
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// Below this fraction of the largest diagonal a held row's pivot in the velocity
/// projection's Gram matrix marks it dependent on the rows taken before it.
const DEPENDENT: f64 = 1e-10;

impl ContactStep {
    /// The velocity at the last step's end made consistent with the contacts in force
    /// (docs/derivations.md §13): among the elements closed at `q₂` (gap within `closed`) and
    /// pressing (`γ > 0`), those the velocity `q̇` would drive in (`N q̇ < 0`), with the
    /// tangent rows of those that stick (`‖b‖ < μγ`), are held at zero velocity by the
    /// projection in `M_dd`'s metric, `q̇_d ← q̇_d − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁻¹A q̇` — as the bilateral
    /// rows are. Without it a ball at rest on the ground reports the `−gΔt/2` of its step's
    /// momentum. `factor` is `M_dd(q₂)`'s Cholesky factor `L` (column-major, the velocity
    /// solve's); nothing is allocated.
    pub(crate) fn project_velocity(
        &mut self,
        factor: &[f64],
        n: usize,
        dynamic: &[usize],
        dq: &mut [f64],
        closed: f64,
    ) {
        let g = &self.gaps;
        let row_speed = |r: usize, dq: &[f64]| (0..n).map(|j| g.dh[(r, j)] * dq[j]).sum::<f64>();
        self.held.clear();
        for e in &self.all {
            let (gamma, gap) = (self.impulses[e.row], self.gap_values[e.row]);
            if gamma <= 0.0 || gap > closed || row_speed(e.row, dq) >= 0.0 {
                continue;
            }
            self.held.push(e.row);
            if e.has_friction() {
                let b =
                    (self.impulses[e.row + 1].powi(2) + self.impulses[e.row + 2].powi(2)).sqrt();
                if b < (1.0 - 1e-6) * e.friction * gamma {
                    self.held.extend([e.row + 1, e.row + 2]);
                }
            }
        }
        let (r, nd) = (self.held.len(), dynamic.len());
        if r == 0 {
            return;
        }
        // With M_dd = L Lᵀ: Y = L⁻¹Aᵀ, S = A M⁻¹ Aᵀ = YᵀY, y = S⁻¹ A q̇, q̇_d −= L⁻ᵀ (Y y).
        for (k, &row) in self.held.iter().enumerate() {
            let x = &mut self.solved[k * nd..(k + 1) * nd];
            for (ci, &i) in dynamic.iter().enumerate() {
                x[ci] = g.dh[(row, i)];
            }
            self.rhs[k] = row_speed(row, dq);
        }
        cholesky_forward_many(factor, nd, &mut self.solved, r);
        for a in 0..r {
            for k in 0..=a {
                let (ya, yk) = (
                    &self.solved[a * nd..(a + 1) * nd],
                    &self.solved[k * nd..(k + 1) * nd],
                );
                let s: f64 = ya.iter().zip(yk).map(|(x, y)| x * y).sum();
                (self.small[k * r + a], self.small[a * r + k]) = (s, s);
            }
        }
        // The held rows may be dependent (a box's eight corners sticking: 24 rows on 6
        // degrees of freedom); S's pivoted factor takes a basis of them.
        semidefinite_solve(
            &mut self.small[..r * r],
            r,
            &mut self.small_pivots,
            &mut self.rhs[..r],
            DEPENDENT,
        );
        let v = &mut self.velocity[..nd];
        v.fill(0.0);
        for k in 0..r {
            let (x, y) = (&self.solved[k * nd..(k + 1) * nd], self.rhs[k]);
            for (vi, xi) in v.iter_mut().zip(x) {
                *vi += xi * y;
            }
        }
        cholesky_backward(factor, nd, v);
        for (ci, &i) in dynamic.iter().enumerate() {
            dq[i] -= v[ci];
        }
    }
}

/// Element `e`'s own block of the Newton matrix (its equations in its unknowns, column-major:
/// `γ, s[, b₁, b₂, ψ, δ₁, δ₂]`) at the unknowns `z`.
fn local_block(e: &Element, z: &[f64], out: &mut [f64]) {
    let b = e.base;
    let size = if e.has_friction() { 7 } else { 2 };
    out.fill(0.0);
    let at = |row: usize, col: usize| col * size + row;
    // s − φ: ∂/∂s = 1; s γ: ∂/∂γ = s, ∂/∂s = γ.
    out[at(0, 1)] = 1.0;
    out[at(1, 0)] = z[b + 1];
    out[at(1, 1)] = z[b];
    if size == 2 {
        return;
    }
    // δ − Δτ: ∂/∂δ = 1.
    out[at(2, 5)] = 1.0;
    out[at(3, 6)] = 1.0;
    let (x, y) = cone_points(e, z);
    let columns: [(usize, Point); 6] = [
        (0, [e.friction * y[0], e.friction * y[1], e.friction * y[2]]),
        (2, [y[1], y[0], 0.0]),
        (3, [y[2], 0.0, y[0]]),
        (4, x),
        (5, [x[1], x[0], 0.0]),
        (6, [x[2], 0.0, x[0]]),
    ];
    for (col, v) in columns {
        for (r, &x) in v.iter().enumerate() {
            out[at(4 + r, col)] = x;
        }
    }
}

/// Where the contact step stands after an evaluation.
struct Measures {
    /// The dynamic rows' residual relative to their momentum scale.
    relative: f64,
    /// The largest bilateral violation, gap-slack and displacement mismatch.
    violation: f64,
    /// The largest complementarity relative to the step's momentum scale (hard contact), or
    /// the largest departure from the central path at κ relative to κ.
    complementarity: f64,
    /// The element with the largest complementarity or violation, for errors.
    worst: usize,
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The contact step from `(q₁, p₁)`, `q₂` predicted in `q_next`: interior-point Newton on
    /// the equations of the module docs. The iterations taken, also on failure.
    pub(super) fn solve_contact<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<usize, (usize, SimError)>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let mut c = self
            .contact
            .take()
            .expect("a contact step has its workspace");
        let mut tried = 0;
        let free_or_mode = match self.free_step(&mut c, cx, q1, p1, q_next) {
            Ok(iterations) => Ok(iterations),
            Err(free) => {
                let mode = self.mode_step(&mut c, cx, q1, p1, q_next);
                self.contact_iterations += match mode {
                    Ok(k) | Err(k) => k,
                };
                mode.map(|k| k + free).map_err(|k| k + free)
            }
        };
        let result = match free_or_mode {
            Ok(iterations) => Ok(iterations),
            Err(iterations) => {
                tried = iterations;
                let result = self.contact_newton(&mut c, cx, q1, p1, q_next);
                self.contact_iterations += match result {
                    Ok(k) | Err((k, _)) => k,
                };
                result
            }
        };
        let deepest = (c.all.iter())
            .map(|e| -c.gap_values[e.row])
            .fold(0.0, f64::max);
        self.penetration = self.penetration.max(deepest);
        self.contact = Some(c);
        result.map(|k| k + tried).map_err(|(k, e)| (k + tried, e))
    }

    /// Hard contact after a step with no impulse: the smooth step first (every row open,
    /// `γ = 0`), kept when every gap at its end is open — then it is the contact step's
    /// solution exactly, at the cost of one gap evaluation. Otherwise `q_next` and `λ` are
    /// put back as predicted and the iterations spent are the error.
    fn free_step<S, F, P>(
        &mut self,
        c: &mut ContactStep,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<usize, usize>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        c.free = false;
        if self.settings.kappa > 0.0 || !c.quiet {
            return Err(0);
        }
        c.save_prediction(q_next.as_slice(), self.lambda.as_slice());
        let (iterations, solved) = match self.solve(cx, q1, p1, q_next) {
            Ok(k) => (k, true),
            Err((k, _)) => (k, false),
        };
        if solved {
            cx.sys.gaps(q_next, None, &mut c.gaps);
        }
        if solved && (c.all.iter()).all(|e| c.gaps.h[e.row] >= 0.0) {
            c.open_step();
            return Ok(iterations);
        }
        c.restore_prediction(q_next.as_mut_slice(), self.lambda.as_mut_slice());
        Err(iterations)
    }

    fn contact_newton<S, F, P>(
        &mut self,
        c: &mut ContactStep,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<usize, (usize, SimError)>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        cx.sys.gaps(q1, None, &mut c.gaps);
        c.at_start.copy_from_slice(c.gaps.h.as_slice());
        c.dh_start.copy_from(&c.gaps.dh);
        c.save_prediction(q_next.as_slice(), self.lambda.as_slice());
        c.forced.fill(false);
        let first = self.split.dynamic.len() + self.split.rows;
        let mut total = 0;
        loop {
            cx.sys.gaps(q_next, None, &mut c.gaps);
            c.select(self.settings.kappa > 0.0, first);
            let k = if c.elements.is_empty() {
                // Nothing near: the smooth step, every row open (checked below).
                let k = self
                    .solve(cx, q1, p1, q_next)
                    .map_err(|(k, e)| (total + k, e))?;
                cx.sys.gaps(q_next, None, &mut c.gaps);
                k
            } else {
                self.interior_point(c, cx, q1, p1, q_next)
                    .map_err(|(k, e)| (total + k, e))?
            };
            total += k;
            // Left-out elements closed at the end are taken in, and the step solved again.
            let mut closed = false;
            for e in &c.all {
                if !c.selected[e.index] && c.gaps.h[e.row] < 0.0 {
                    (c.forced[e.index], closed) = (true, true);
                }
            }
            if !closed {
                if c.elements.is_empty() {
                    c.open_step();
                }
                return Ok(total);
            }
            c.restore_prediction(q_next.as_mut_slice(), self.lambda.as_mut_slice());
        }
    }

    /// The interior point for the selected elements from the predicted `q₂` in `q_next`
    /// (`c.at_start` holding the gaps at `q₁`): the iterations taken, also on failure.
    fn interior_point<S, F, P>(
        &mut self,
        c: &mut ContactStep,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> Result<usize, (usize, SimError)>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (step, t) = (cx.index, cx.t);
        c.weights.fill(0.0);
        self.evaluate_residual(cx, q1, p1, q_next, true);
        let scale = self.momentum_scale();
        self.start_contact(c, cx, q_next, scale);
        let kappa = self.settings.kappa;
        c.centre = false;
        let mut iterations = 0;
        let mut at_floor = false;
        loop {
            if iterations > 0 {
                self.evaluate_residual(cx, q1, p1, q_next, true);
            }
            self.form_jacobian();
            weights_of(c);
            cx.sys.gaps(q_next, Some(&c.weights), &mut c.gaps);
            let m = self.contact_residual(c, scale, kappa, 0.0);
            if !(m.relative.is_finite() && m.violation.is_finite() && m.complementarity.is_finite())
            {
                let what = "the contact step's residual".into();
                return Err((iterations, SimError::NonFinite { step, t, what }));
            }
            let tol = self.settings.tolerance;
            // Once the last update was lost in the rounding of q, the residual and the
            // complementarity are at their floor (≈ ε‖M‖‖q‖/Δt, and a gap's rounding against
            // its own size), as in the smooth step: within √tol they are converged.
            let within = |x: f64| x <= tol || (at_floor && x <= tol.sqrt());
            if m.violation <= self.settings.constraint_tolerance
                && within(m.relative)
                && within(m.complementarity)
            {
                break;
            }
            if iterations >= MAX_ITERATIONS {
                let e = &c.elements[m.worst];
                return Err((
                    iterations,
                    SimError::ContactFailed {
                        step,
                        t,
                        iterations,
                        contact: c.names[e.index].clone(),
                        gap: c.gaps.h[e.row],
                        residual: m.relative,
                        complementarity: m.complementarity,
                        singular: None,
                    },
                ));
            }
            iterations += 1;
            self.contact_matrix(c);
            let nz = c.nz;
            lu_factor_packed_unguarded(&mut c.matrix[..nz * nz], nz, &mut c.pivots)
                .map_err(|k| (iterations, self.singular_unknown(c, cx.sys, k, step, t)))?;
            self.mehrotra(c, scale, kappa);
            let distance = (m.relative).max(m.violation);
            at_floor = self.apply_contact_update(c, q_next, scale, distance);
        }
        for (k, w) in c.weights.iter().enumerate() {
            c.impulses[k] = *w;
        }
        c.gap_values.copy_from_slice(c.gaps.h.as_slice());
        let negligible = self.settings.tolerance * scale;
        c.quiet = (c.elements.iter()).all(|e| c.z[e.base] <= negligible);
        Ok(iterations)
    }

    /// The step's momentum scale: the largest dynamic row's (at least the smallest normal
    /// float, for a model at rest without forces).
    fn momentum_scale(&self) -> f64 {
        (self.split.dynamic.iter())
            .map(|&i| self.row_scale[i])
            .fold(f64::MIN_POSITIVE, f64::max)
    }

    /// A fresh step's contact unknowns at the predicted `q₂`: `s = max(φ, d₀)`, `γ` with
    /// `sγ = d₀·P`; with friction `b = 0`, `δ` the predicted displacement and `ψ` with
    /// `μγψ = d₀·P` beyond `‖δ‖`.
    fn start_contact<S, F, P>(
        &mut self,
        c: &mut ContactStep,
        cx: &mut StepContext<S, F, P>,
        q2: &Vector<N>,
        scale: f64,
    ) where
        S: System<N = N>,
    {
        cx.sys.gaps(q2, None, &mut c.gaps);
        let target = START_GAP * scale;
        for e in &c.elements {
            let (b, phi) = (e.base, c.gaps.h[e.row]);
            let s = phi.max(START_GAP);
            c.z[b + 1] = s;
            c.z[b] = target / s;
            if e.has_friction() {
                let d = [1, 2].map(|k| c.gaps.h[e.row + k] - c.at_start[e.row + k]);
                let norm = (d[0] * d[0] + d[1] * d[1]).sqrt();
                c.z[b + 2] = 0.0;
                c.z[b + 3] = 0.0;
                c.z[b + 4] = norm + target / (e.friction * c.z[b]);
                c.z[b + 5] = d[0];
                c.z[b + 6] = d[1];
            }
        }
        for (k, &l) in self.lambda.iter().enumerate() {
            c.z[self.split.dynamic.len() + k] = l;
        }
    }

    /// The dynamic rows with the impulses, `r_d + Nᵀγ + Tᵀb` (the gap rows' weights), and
    /// the bilateral rows `h(q₂)` into `c.residual`: the dynamic rows' residual relative to
    /// their momentum scale (impulses' terms included) and the largest violation.
    fn impulse_rows(&mut self, c: &mut ContactStep) -> (f64, f64) {
        let (dynamic, nd, m) = (
            &self.split.dynamic,
            self.split.dynamic.len(),
            self.split.rows,
        );
        let g = &c.gaps;
        let mut largest: f64 = 0.0;
        for (ci, &i) in dynamic.iter().enumerate() {
            let (mut x, mut s) = (self.residual[i], self.row_scale[i]);
            for (r, &w) in c.weights.iter().enumerate() {
                let v = g.dh[(r, i)] * w;
                x += v;
                s += v.abs();
            }
            c.residual[ci] = x;
            self.column[ci] = s;
            largest = largest.max(s);
        }
        let floor = super::FLOOR * largest;
        let relative = (0..nd)
            .map(|ci| c.residual[ci].abs() / self.column[ci].max(floor).max(f64::MIN_POSITIVE))
            .fold(0.0, f64::max);
        let mut violation: f64 = 0.0;
        for r in 0..m {
            c.residual[nd + r] = self.constraint_terms.h[r];
            violation = violation.max(self.constraint_terms.h[r].abs());
        }
        (relative, violation)
    }

    /// The residual of every equation at the current unknowns into `c.residual`, the
    /// complementarity rows against `target` (`κ`'s or the centring's), and the measures.
    fn contact_residual(
        &mut self,
        c: &mut ContactStep,
        scale: f64,
        kappa: f64,
        target: f64,
    ) -> Measures {
        let (relative, mut violation) = self.impulse_rows(c);
        let g = &c.gaps;
        let (mut complementarity, mut worst, mut worst_value): (f64, usize, f64) = (0.0, 0, -1.0);
        for (k, e) in c.elements.iter().enumerate() {
            let (b, z) = (e.base, &c.z);
            let gap = z[b + 1] - g.h[e.row];
            c.residual[b] = gap;
            c.residual[b + 1] = z[b] * z[b + 1] - target;
            let mut v = gap.abs() / z[b + 1].abs().max(1.0);
            let mut comp = if kappa > 0.0 {
                central(z[b] * z[b + 1], scale, kappa)
            } else {
                // Hard contact: the gap closed or the impulse gone (the smaller of the two,
                // each relative: a resting contact that carries no load has both small).
                z[b + 1].min(z[b] / scale)
            };
            if e.has_friction() {
                for k in 0..2 {
                    let d = z[b + 5 + k] - (g.h[e.row + 1 + k] - c.at_start[e.row + 1 + k]);
                    c.residual[b + 2 + k] = d;
                    v = v.max(d.abs() / z[b + 5 + k].abs().max(1.0));
                }
                let (x, y) = cone_points(e, z);
                let p = cone::product(&x, &y);
                c.residual[b + 4] = p[0] - target;
                c.residual[b + 5] = p[1];
                c.residual[b + 6] = p[2];
                comp = comp.max(cone_central(&p, scale, kappa));
            }
            violation = violation.max(v);
            complementarity = complementarity.max(comp);
            if comp.max(v) > worst_value {
                (worst, worst_value) = (k, comp.max(v));
            }
        }
        Measures {
            relative,
            violation,
            complementarity,
            worst,
        }
    }

    /// The Newton matrix's `q₂` and `λ` block into `c.matrix` (`nz` unknowns, column-major,
    /// the rest zeroed): the VI's Jacobian plus the impulses' `Σ w D²φ` in the dynamic rows,
    /// the bilateral rows and their multipliers' columns.
    fn smooth_block(&self, c: &mut ContactStep, nz: usize) {
        let (dynamic, nd, m) = (
            &self.split.dynamic,
            self.split.dynamic.len(),
            self.split.rows,
        );
        let (g, k) = (&c.gaps, &mut c.matrix);
        k[..nz * nz].fill(0.0);
        let n = self.jacobian.nrows();
        let jac = self.jacobian.as_slice();
        let w = &g.weighted_d2h;
        for (cj, &j) in dynamic.iter().enumerate() {
            for (ci, &i) in dynamic.iter().enumerate() {
                k[cj * nz + ci] = jac[j * n + i] + w[(i, j)];
            }
            for r in 0..m {
                k[cj * nz + nd + r] = self.constraint_terms.dh[(r, j)];
            }
        }
        for r in 0..m {
            for (ci, &i) in dynamic.iter().enumerate() {
                k[(nd + r) * nz + ci] = self.dt * self.dh1[(r, i)];
            }
        }
    }

    /// The Newton matrix of every equation in the unknowns, column-major, into `c.matrix`.
    fn contact_matrix(&self, c: &mut ContactStep) {
        let (dynamic, nz) = (&self.split.dynamic, c.nz);
        self.smooth_block(c, nz);
        let (g, k) = (&c.gaps, &mut c.matrix);
        let z = &c.z;
        for e in &c.elements {
            let b = e.base;
            for (ci, &i) in dynamic.iter().enumerate() {
                // ∂r_d/∂γ = N, and the gap row's −N in q₂'s columns.
                k[b * nz + ci] = g.dh[(e.row, i)];
                k[ci * nz + b] = -g.dh[(e.row, i)];
            }
            k[(b + 1) * nz + b] = 1.0;
            // s γ: ∂/∂γ = s, ∂/∂s = γ.
            k[b * nz + b + 1] = z[b + 1];
            k[(b + 1) * nz + b + 1] = z[b];
            if !e.has_friction() {
                continue;
            }
            for t in 0..2 {
                let (row, col) = (b + 2 + t, b + 2 + t);
                for (ci, &i) in dynamic.iter().enumerate() {
                    k[col * nz + ci] = g.dh[(e.row + 1 + t, i)];
                    k[ci * nz + row] = -g.dh[(e.row + 1 + t, i)];
                }
                k[(b + 5 + t) * nz + row] = 1.0;
            }
            // (μγ, b) ∘ η: by γ (through μγ), b and η.
            let (x, y) = cone_points(e, z);
            let rows = [b + 4, b + 5, b + 6];
            let columns: [(usize, Point); 6] = [
                (b, [e.friction * y[0], e.friction * y[1], e.friction * y[2]]),
                (b + 2, [y[1], y[0], 0.0]),
                (b + 3, [y[2], 0.0, y[0]]),
                (b + 4, [x[0], x[1], x[2]]),
                (b + 5, [x[1], x[0], 0.0]),
                (b + 6, [x[2], 0.0, x[0]]),
            ];
            for (col, v) in columns {
                for (r, &row) in rows.iter().enumerate() {
                    k[col * nz + row] = v[r];
                }
            }
        }
    }

    /// Mehrotra's predictor and corrector from the factored matrix: the direction into
    /// `c.direction`.
    fn mehrotra(&mut self, c: &mut ContactStep, scale: f64, kappa: f64) {
        let nz = c.nz;
        // The predictor: every complementarity towards zero.
        for k in 0..nz {
            c.affine[k] = -c.residual[k];
        }
        for e in &c.elements {
            c.affine[e.base + 1] = -c.z[e.base] * c.z[e.base + 1];
            if e.has_friction() {
                let (x, y) = cone_points(e, &c.z);
                let p = cone::product(&x, &y);
                for r in 0..3 {
                    c.affine[e.base + 4 + r] = -p[r];
                }
            }
        }
        lu_solve_packed(&c.matrix[..nz * nz], nz, &c.pivots, &mut c.affine[..nz]);
        let mu = mean_complementarity(&c.elements, &c.z);
        let alpha = step_length(&c.elements, &c.z, &c.affine, 1.0);
        for k in 0..nz {
            c.direction[k] = c.z[k] + alpha * c.affine[k];
        }
        let mu_affine = mean_complementarity(&c.elements, &c.direction);
        let sigma = if c.centre {
            1.0
        } else {
            (mu_affine / mu).clamp(0.0, 1.0).powi(3)
        };
        let _ = scale;
        // The corrector: centred at `target`, with the predictor's second-order term — or,
        // once the centring reaches a user's κ, plain Newton onto its central path (the
        // predictor's term, heading for zero, would only spoil that convergence).
        let on_path = kappa > 0.0 && sigma * mu <= kappa;

        let (target, second) = if on_path {
            (kappa, 0.0)
        } else if c.centre {
            (mu, 0.0)
        } else {
            (sigma * mu, 1.0)
        };
        corrector(c, target, second);
    }

    /// Takes the corrector's direction a fraction of the way to the cones' boundary — the
    /// fraction nearer 1 as the complementarity and the residuals (`distance`, relative)
    /// vanish, so the last iterations converge as Newton's — and within the central path's
    /// neighbourhood, to `q₂`, `λ` and the contact unknowns. Whether the update of `q₂` was
    /// below the rounding of `q`.
    fn apply_contact_update(
        &mut self,
        c: &mut ContactStep,
        q_next: &mut Vector<N>,
        scale: f64,
        distance: f64,
    ) -> bool {
        let mu = mean_complementarity(&c.elements, &c.z) / scale;
        let fraction = FRACTION_TO_BOUNDARY
            .max(1.0 - mu.max(distance))
            .min(LAST_FRACTION);
        let room = step_length(&c.elements, &c.z, &c.direction, 1.0 / fraction);
        let alpha = within_neighbourhood(c, (fraction * room).min(1.0));
        c.centre = alpha < SHORT_STEP;
        let nd = self.split.dynamic.len();
        let mut largest: f64 = 0.0;
        for (ci, &i) in self.split.dynamic.iter().enumerate() {
            let dq = alpha * c.direction[ci];
            q_next[i] += dq;
            largest = largest.max(dq.abs());
        }
        for r in 0..self.split.rows {
            self.lambda[r] += alpha * c.direction[nd + r];
        }
        for k in nd + self.split.rows..c.nz {
            c.z[k] += alpha * c.direction[k];
        }
        below_rounding(largest, q_next)
    }

    /// The error for a zero pivot at unknown `k`.
    fn singular_unknown<S: System<N = N>>(
        &self,
        c: &ContactStep,
        sys: &S,
        k: usize,
        step: usize,
        t: f64,
    ) -> SimError {
        let (nd, m) = (self.split.dynamic.len(), self.split.rows);
        let variable = if k < nd {
            format!("variable `{}`", sys.variable_name(self.split.dynamic[k]))
        } else if k < nd + m {
            format!("the λ of constraint `{}`", sys.constraint_name(k - nd))
        } else {
            let e = c.elements.iter().rposition(|e| e.base <= k).unwrap_or(0);
            format!("the impulse of contact `{}`", c.names[c.elements[e].index])
        };
        SimError::SingularJacobian { step, t, variable }
    }
}

/// The smallest pair's complementarity over the mean at the unknowns `z` (1: every pair
/// alike, as on the central path; 0: a pair on its cone's boundary).
fn centrality(elements: &[Element], z: &[f64]) -> f64 {
    let mean = mean_complementarity(elements, z);
    if mean.is_nan() || mean <= 0.0 {
        return 0.0;
    }
    let mut least = f64::INFINITY;
    for e in elements {
        least = least.min(z[e.base] * z[e.base + 1]);
        if e.has_friction() {
            let (x, y) = cone_points(e, z);
            least = least.min((cone::det(&x).max(0.0) * cone::det(&y).max(0.0)).sqrt());
        }
    }
    least / mean
}

/// `alpha` halved until the step along `c.direction` ends within the central path's
/// neighbourhood ([`NEIGHBOURHOOD`], or no less central than it starts when it starts
/// outside). The trial points go into `c.affine`, free once the corrector is formed.
fn within_neighbourhood(c: &mut ContactStep, alpha: f64) -> f64 {
    let least = NEIGHBOURHOOD.min(centrality(&c.elements, &c.z));
    let mut alpha = alpha;
    for _ in 0..NEIGHBOURHOOD_HALVINGS {
        for e in &c.elements {
            let width = if e.has_friction() { 7 } else { 2 };
            for k in e.base..e.base + width {
                c.affine[k] = c.z[k] + alpha * c.direction[k];
            }
        }
        if centrality(&c.elements, &c.affine) >= least {
            break;
        }
        alpha *= 0.5;
    }
    alpha
}

/// The corrector's direction into `c.direction` from the factored matrix: every residual
/// cancelled, each complementarity aimed at `target` with `second` times the predictor's
/// second-order term.
fn corrector(c: &mut ContactStep, target: f64, second: f64) {
    let nz = c.nz;
    for k in 0..nz {
        c.direction[k] = -c.residual[k];
    }
    for e in &c.elements {
        let (b, a) = (e.base, &c.affine);
        c.direction[b + 1] = -(c.z[b] * c.z[b + 1] - target + second * a[b] * a[b + 1]);
        if e.has_friction() {
            let (x, y) = cone_points(e, &c.z);
            let (dx, dy) = cone_points(e, a);
            let p = cone::product(&x, &y);
            let dp = cone::product(&dx, &dy);
            c.direction[b + 4] = -(p[0] - target + second * dp[0]);
            c.direction[b + 5] = -(p[1] + second * dp[1]);
            c.direction[b + 6] = -(p[2] + second * dp[2]);
        }
    }
    lu_solve_packed(&c.matrix[..nz * nz], nz, &c.pivots, &mut c.direction[..nz]);
}

/// The impulses as gap-row weights: `γ` at each gap row, `b` at its tangent rows.
fn weights_of(c: &mut ContactStep) {
    for e in &c.elements {
        c.weights[e.row] = c.z[e.base];
        if e.has_friction() {
            c.weights[e.row + 1] = c.z[e.base + 2];
            c.weights[e.row + 2] = c.z[e.base + 3];
        }
    }
}

/// [`central`] for a cone's product `p = (μγ, b) ∘ η`, whose target is `κ e`.
fn cone_central(p: &Point, scale: f64, kappa: f64) -> f64 {
    let off = p[1].abs().max(p[2].abs());
    if kappa > 0.0 {
        central(p[0], scale, kappa).max(off / kappa)
    } else {
        p[0].abs().max(off) / scale
    }
}

/// How far a complementarity `x` is from done: relative to the momentum scale for hard
/// contact (`κ = 0`), from `κ` relative to `κ` on the central path.
fn central(x: f64, scale: f64, kappa: f64) -> f64 {
    if kappa > 0.0 {
        (x - kappa).abs() / kappa
    } else {
        x.abs() / scale
    }
}
