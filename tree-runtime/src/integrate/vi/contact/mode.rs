//! The hard contact step by the last step's mode (docs/derivations.md §13, "Resting
//! contact"). Where the last step left every element open (no impulse), pressing and
//! sticking, or pressing without friction — a robot standing, a box at rest, a pendulum held
//! at its limit — this step is first tried in the same mode, as equations: a pressing
//! element's gap `φ(q₂) = 0` with its `γ` as multiplier, a sticking one's tangential
//! displacement `τ(q₂) − τ(q₁) = 0` with its `b`, an open one's impulse zero. That is the
//! VI's Newton with those rows as bilateral ones, warm-started from the last impulses, and
//! takes one or two iterations (at least one) where the interior point takes about six. Its solution is
//! kept only when it solves the complementarity problem the interior point solves — every
//! `γ ≥ 0`, every sticking `‖b‖ ≤ μγ` (so `b·δ` is minimal over the cone at `δ = 0`), every
//! other gap open at `q₂` — and then it is that problem's solution with the closed gaps at
//! zero; otherwise the interior point solves the step from the same prediction. A contact
//! that slid (its friction at the cone's edge) is tried sliding: `b = −μγ δ/‖δ‖`, kept while
//! `δ` does not vanish (one about to stop goes to the interior point). The rows bordering
//! the matrix are regularised so that dependent ones (a box's four lower corners, 12 rows on
//! 6 degrees of freedom, impulses not unique) do not make it singular ([`REGULARISATION`]).

use super::*;

/// Newton iterations the mode may take before the interior point is asked instead.
const MODE_ITERATIONS: usize = 6;

/// A friction impulse beyond this fraction of its cone (`‖b‖ ≥ STICKING μγ`) is sliding.
const STICKING: f64 = 1.0 - 1e-6;

/// A sliding element's displacement must exceed this many constraint tolerances for its
/// direction to mean anything (a contact about to stop goes to the interior point).
const SLIP_FLOOR: f64 = 1e3;

/// The mode's rows bordering the Newton matrix are regularised by `−ε` on their diagonal,
/// `ε` this fraction of the inverse of the matrix's largest diagonal entry: the equations are
/// solved exactly (the residual has no `ε`), but dependent rows — a box's four lower corners
/// on the ground, 12 rows on 6 degrees of freedom — no longer make the matrix singular, and
/// their impulses, not unique, move least from the last step's.
const REGULARISATION: f64 = 1e-10;

impl ContactStep {
    /// The last step's mode as this step's rows: each element that pressed (`γ` above
    /// `negligible`), its unknowns packed from `first` (`γ`, then `b` when it has friction),
    /// sliding when its friction was at the cone's edge; `false` when none pressed.
    fn choose_mode(&mut self, first: usize, negligible: f64) -> bool {
        self.mode.clear();
        self.sliding.clear();
        let mut base = first;
        for e in &self.all {
            let gamma = self.impulses[e.row];
            self.in_mode[e.index] = gamma > negligible;
            if gamma <= negligible {
                continue;
            }
            let slid = e.has_friction() && {
                let b = self.impulses[e.row + 1].hypot(self.impulses[e.row + 2]);
                b >= STICKING * e.friction * gamma
            };
            self.sliding.push(slid);
            self.mode.push(Element { base, ..e.clone() });
            base += e.rows();
        }
        self.mode_nz = base;
        !self.mode.is_empty()
    }

    /// A mode element's displacement over the step `δ = τ(q₂) − τ(q₁)`, its length and
    /// direction (zero for a vanishing `δ`).
    fn slip(&self, e: &Element) -> ([f64; 2], f64, [f64; 2]) {
        let r = e.row + 1;
        let d = [0, 1].map(|t| self.gaps.h[r + t] - self.at_start[r + t]);
        let n = d[0].hypot(d[1]);
        let u = if n > 0.0 { d.map(|x| x / n) } else { [0.0; 2] };
        (d, n, u)
    }

    /// Whether the mode's solution solves the complementarity problem: impulses pressing and
    /// inside their cones (a sliding one on its edge against a displacement that did not
    /// vanish), every other element's gap open at `q₂`.
    fn mode_holds(&self, slip_floor: f64) -> bool {
        let w = &self.weights;
        let inside = self.mode.iter().zip(&self.sliding).all(|(e, &sliding)| {
            let gamma = w[e.row];
            let b = || w[e.row + 1].hypot(w[e.row + 2]);
            gamma >= 0.0
                && match (e.has_friction(), sliding) {
                    (false, _) => true,
                    (true, false) => b() <= e.friction * gamma,
                    (true, true) => self.slip(e).1 > slip_floor,
                }
        });
        let open = (self.all.iter())
            .filter(|e| !self.in_mode[e.index])
            .all(|e| self.gaps.h[e.row] >= 0.0);
        inside && open
    }
}

impl<N: Dim> MidpointVi<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The hard step in the last step's mode from the predicted `q₂` in `q_next` (module
    /// docs): `Ok(iterations)` when its solution holds, else `q_next` and `λ` put back as
    /// predicted and the iterations spent as the error.
    pub(super) fn mode_step<S, F, P>(
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
    {
        // Nothing pressed in the last step (a landing's first contact step): no mode, and
        // no evaluation spent on finding that out.
        if self.settings.kappa > 0.0
            || self.settings.derivatives
            || c.free
            || c.impulses.iter().all(|&x| x == 0.0)
        {
            return Err(0);
        }
        let first = self.split.dynamic.len() + self.split.rows;
        self.evaluate_residual(cx, q1, p1, q_next, true);
        let negligible = self.settings.tolerance * self.momentum_scale();
        if !c.choose_mode(first, negligible) {
            return Err(0);
        }
        c.save_prediction(q_next.as_slice(), self.lambda.as_slice());
        // The gaps at q₁: the last step's at its end, where it ended here.
        if self.contact_at == *q1 {
            c.at_start.copy_from_slice(&c.gap_values);
        } else {
            cx.sys.gaps(q1, None, &mut c.gaps);
            c.at_start.copy_from_slice(c.gaps.h.as_slice());
        }
        // The last impulses as the mode's first guess, every other row's zero.
        c.weights.fill(0.0);
        for e in &c.mode {
            for r in e.row..e.row + e.rows() {
                c.weights[r] = c.impulses[r];
            }
        }
        let (converged, iterations) = self.mode_newton(c, cx, q1, p1, q_next);
        if converged && c.mode_holds(SLIP_FLOOR * self.settings.constraint_tolerance) {
            c.impulses.copy_from_slice(&c.weights);
            c.gap_values.copy_from_slice(c.gaps.h.as_slice());
            c.quiet = (c.mode.iter()).all(|e| c.weights[e.row] <= negligible);
            return Ok(iterations);
        }
        c.restore_prediction(q_next.as_mut_slice(), self.lambda.as_mut_slice());
        Err(iterations)
    }

    /// Newton on the mode's equations from the prediction, the second-order terms there
    /// already evaluated: whether it converged, and the updates taken (at least one: a warm
    /// start within the tolerance is still a tolerance away, and one update squares that).
    /// Each check after an update is of first order (no Jacobian, no gap Hessians); the
    /// second-order terms are evaluated only when another update follows.
    fn mode_newton<S, F, P>(
        &mut self,
        c: &mut ContactStep,
        cx: &mut StepContext<S, F, P>,
        q1: &Vector<N>,
        p1: &Vector<N>,
        q_next: &mut Vector<N>,
    ) -> (bool, usize)
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        let (tol, constraint_tol) = (self.settings.tolerance, self.settings.constraint_tolerance);
        cx.sys.gaps(q_next, Some(&c.weights), &mut c.gaps);
        for iterations in 1..=MODE_ITERATIONS {
            let (relative, violation) = self.mode_residual(c);
            if !(relative.is_finite() && violation.is_finite()) {
                return (false, iterations - 1);
            }
            self.form_jacobian();
            self.mode_matrix(c);
            let nz = c.mode_nz;
            if lu_factor_packed(&mut c.matrix[..nz * nz], nz, &mut c.pivots).is_err() {
                return (false, iterations - 1);
            }
            for k in 0..nz {
                c.direction[k] = -c.residual[k];
            }
            lu_solve_packed(&c.matrix[..nz * nz], nz, &c.pivots, &mut c.direction[..nz]);
            let at_floor = self.apply_mode_update(c, q_next);
            self.evaluate_residual(cx, q1, p1, q_next, false);
            cx.sys.gaps(q_next, None, &mut c.gaps);
            let (relative, violation) = self.mode_residual(c);
            // Once an update is lost in the rounding of q, the residual is at its floor
            // (≈ ε‖M‖‖q‖/Δt against the momentum scale): within √tol it has converged, as
            // in the interior point and the smooth step.
            let within = relative <= tol || (at_floor && relative <= tol.sqrt());
            if within && violation <= constraint_tol {
                return (true, iterations);
            }
            self.evaluate_residual(cx, q1, p1, q_next, true);
            cx.sys.gaps(q_next, Some(&c.weights), &mut c.gaps);
        }
        (false, MODE_ITERATIONS)
    }

    /// The mode's equations into `c.residual`: the dynamic rows with the impulses, the
    /// bilateral rows, each mode element's gap and its friction's — a sticking one's
    /// displacement `δ = 0`, a sliding one's `b + μγ δ/‖δ‖ = 0`. The relative residual (the
    /// dynamic rows', and a sliding friction's relative to `μγ`) and the largest violation.
    fn mode_residual(&mut self, c: &mut ContactStep) -> (f64, f64) {
        let (mut relative, mut violation) = self.impulse_rows(c);
        for (e, &sliding) in c.mode.iter().zip(&c.sliding) {
            let phi = c.gaps.h[e.row];
            c.residual[e.base] = phi;
            violation = violation.max(phi.abs());
            if !e.has_friction() {
                continue;
            }
            let (d, _, u) = c.slip(e);
            let w = &c.weights;
            for t in 0..2 {
                if sliding {
                    let limit = e.friction * w[e.row];
                    let x = w[e.row + 1 + t] + limit * u[t];
                    c.residual[e.base + 1 + t] = x;
                    relative = relative.max(x.abs() / limit.abs().max(f64::MIN_POSITIVE));
                } else {
                    c.residual[e.base + 1 + t] = d[t];
                    violation = violation.max(d[t].abs());
                }
            }
        }
        (relative, violation)
    }

    /// The mode's Newton matrix into `c.matrix`: the smooth block; each gap and sticking row
    /// `N` or `T` beside its impulse's column, regularised ([`REGULARISATION`]); a sliding
    /// friction's rows `∂(b + μγ û)/∂(q₂, γ, b)` with `∂û/∂δ = (I − ûûᵀ)/‖δ‖`.
    fn mode_matrix(&self, c: &mut ContactStep) {
        let (dynamic, nz) = (&self.split.dynamic, c.mode_nz);
        self.smooth_block(c, nz);
        let largest = (0..dynamic.len())
            .map(|ci| c.matrix[ci * nz + ci].abs())
            .fold(f64::MIN_POSITIVE, f64::max);
        let epsilon = REGULARISATION / largest;
        for (e, &sliding) in c.mode.iter().zip(&c.sliding) {
            let rows = e.rows();
            let (_, n, u) = match e.has_friction() {
                true => c.slip(e),
                false => ([0.0; 2], 0.0, [0.0; 2]),
            };
            let (g, k) = (&c.gaps, &mut c.matrix);
            for t in 0..rows {
                let at = e.base + t;
                for (ci, &i) in dynamic.iter().enumerate() {
                    k[at * nz + ci] = g.dh[(e.row + t, i)];
                }
                if t == 0 || !sliding {
                    for (ci, &i) in dynamic.iter().enumerate() {
                        k[ci * nz + at] = g.dh[(e.row + t, i)];
                    }
                    k[at * nz + at] = -epsilon;
                    continue;
                }
                // b_t + μγ û_t: by b_t, by γ, and by q₂ through δ.
                let (s, limit) = (t - 1, e.friction * c.weights[e.row]);
                k[at * nz + at] = 1.0;
                k[e.base * nz + at] = e.friction * u[s];
                for (ci, &i) in dynamic.iter().enumerate() {
                    let mut x = 0.0;
                    for r in 0..2 {
                        let projector = f64::from(u8::from(r == s)) - u[s] * u[r];
                        x += projector * g.dh[(e.row + 1 + r, i)];
                    }
                    k[ci * nz + at] = limit * x / n.max(f64::MIN_POSITIVE);
                }
            }
        }
    }

    /// The mode's Newton direction in `c.direction` onto `q₂`, `λ` and the impulses:
    /// whether the update of `q₂` was below the rounding of `q`.
    fn apply_mode_update(&mut self, c: &mut ContactStep, q_next: &mut Vector<N>) -> bool {
        let nd = self.split.dynamic.len();
        let mut largest: f64 = 0.0;
        for (ci, &i) in self.split.dynamic.iter().enumerate() {
            q_next[i] += c.direction[ci];
            largest = largest.max(c.direction[ci].abs());
        }
        for r in 0..self.split.rows {
            self.lambda[r] += c.direction[nd + r];
        }
        for e in &c.mode {
            for t in 0..e.rows() {
                c.weights[e.row + t] += c.direction[e.base + t];
            }
        }
        below_rounding(largest, q_next)
    }
}
