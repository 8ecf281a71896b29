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
//! zero; otherwise the interior point solves the step from the same prediction. A mode with
//! a sliding contact is not tried (its friction is not a linear row). Dependent rows (a box
//! sticking on its four lower corners: 12 rows on 6 degrees of freedom, impulses not
//! unique) make the mode's matrix singular: its factor fails, and the interior point solves
//! the step.

use super::*;

/// Newton iterations the mode may take before the interior point is asked instead.
const MODE_ITERATIONS: usize = 6;

/// A friction impulse beyond this fraction of its cone (`‖b‖ ≥ STICKING μγ`) is sliding.
const STICKING: f64 = 1.0 - 1e-6;

impl ContactStep {
    /// The last step's mode as this step's rows: each element that pressed (`γ` above
    /// `negligible`), its unknowns packed from `first` (`γ`, then `b` when it has friction);
    /// `false` when none pressed or one slid.
    fn choose_mode(&mut self, first: usize, negligible: f64) -> bool {
        self.mode.clear();
        let mut base = first;
        for e in &self.all {
            let gamma = self.impulses[e.row];
            if gamma <= negligible {
                continue;
            }
            if e.has_friction() {
                let b = self.impulses[e.row + 1].hypot(self.impulses[e.row + 2]);
                if b >= STICKING * e.friction * gamma {
                    return false;
                }
            }
            self.mode.push(Element { base, ..e.clone() });
            base += if e.has_friction() { 3 } else { 1 };
        }
        self.mode_nz = base;
        !self.mode.is_empty()
    }

    /// Whether the mode's solution solves the complementarity problem: impulses pressing and
    /// inside their cones, every other element's gap open at `q₂`.
    fn mode_holds(&self) -> bool {
        let w = &self.weights;
        let inside = self.mode.iter().all(|e| {
            let gamma = w[e.row];
            gamma >= 0.0
                && (!e.has_friction() || w[e.row + 1].hypot(w[e.row + 2]) <= e.friction * gamma)
        });
        let open = (self.all.iter())
            .filter(|e| !self.mode.iter().any(|m| m.index == e.index))
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
        if self.settings.kappa > 0.0 || self.settings.derivatives || c.free {
            return Err(0);
        }
        let first = self.split.dynamic.len() + self.split.rows;
        self.evaluate_residual(cx, q1, p1, q_next, true);
        let negligible = self.settings.tolerance * self.momentum_scale();
        if !c.choose_mode(first, negligible) {
            return Err(0);
        }
        c.predicted.copy_from_slice(q_next.as_slice());
        c.saved_lambda.copy_from_slice(self.lambda.as_slice());
        cx.sys.gaps(q1, None, &mut c.gaps);
        c.at_start.copy_from_slice(c.gaps.h.as_slice());
        // The last impulses as the mode's first guess, every other row's zero.
        c.weights.fill(0.0);
        for e in &c.mode {
            let rows = if e.has_friction() { 3 } else { 1 };
            for r in e.row..e.row + rows {
                c.weights[r] = c.impulses[r];
            }
        }
        let mut iterations = 0;
        let converged = loop {
            if iterations > 0 {
                self.evaluate_residual(cx, q1, p1, q_next, true);
            }
            cx.sys.gaps(q_next, Some(&c.weights), &mut c.gaps);
            let (relative, violation) = self.mode_residual(c);
            if !(relative.is_finite() && violation.is_finite()) {
                break false;
            }
            // At least one update, as the interior point takes: a warm start within the
            // tolerance is still a tolerance away, and one Newton update squares that.
            if iterations > 0
                && relative <= self.settings.tolerance
                && violation <= self.settings.constraint_tolerance
            {
                break true;
            }
            if iterations >= MODE_ITERATIONS {
                break false;
            }
            iterations += 1;
            self.form_jacobian();
            self.mode_matrix(c);
            let nz = c.mode_nz;
            if lu_factor_packed(&mut c.matrix[..nz * nz], nz, &mut c.pivots).is_err() {
                break false;
            }
            for k in 0..nz {
                c.direction[k] = -c.residual[k];
            }
            lu_solve_packed(&c.matrix[..nz * nz], nz, &c.pivots, &mut c.direction[..nz]);
            self.apply_mode_update(c, q_next);
        };
        if converged && c.mode_holds() {
            c.impulses.copy_from_slice(&c.weights);
            c.gap_values.copy_from_slice(c.gaps.h.as_slice());
            c.quiet = (c.mode.iter()).all(|e| c.weights[e.row] <= negligible);
            return Ok(iterations);
        }
        q_next.as_mut_slice().copy_from_slice(&c.predicted);
        self.lambda.as_mut_slice().copy_from_slice(&c.saved_lambda);
        Err(iterations)
    }

    /// The mode's equations into `c.residual`: the dynamic rows with the impulses, the
    /// bilateral rows, each mode element's gap and (sticking) its tangential displacement.
    /// The dynamic rows' relative residual and the largest violation.
    fn mode_residual(&mut self, c: &mut ContactStep) -> (f64, f64) {
        let (relative, mut violation) = self.impulse_rows(c);
        let g = &c.gaps;
        for e in &c.mode {
            c.residual[e.base] = g.h[e.row];
            violation = violation.max(g.h[e.row].abs());
            if e.has_friction() {
                for t in 0..2 {
                    let r = e.row + 1 + t;
                    let d = g.h[r] - c.at_start[r];
                    c.residual[e.base + 1 + t] = d;
                    violation = violation.max(d.abs());
                }
            }
        }
        (relative, violation)
    }

    /// The mode's Newton matrix into `c.matrix`: the smooth block, and each mode row `N` or
    /// `T` beside its impulse's column.
    fn mode_matrix(&self, c: &mut ContactStep) {
        let (dynamic, nz) = (&self.split.dynamic, c.mode_nz);
        self.smooth_block(c, nz);
        let (g, k) = (&c.gaps, &mut c.matrix);
        for e in &c.mode {
            let rows = if e.has_friction() { 3 } else { 1 };
            for t in 0..rows {
                let at = e.base + t;
                for (ci, &i) in dynamic.iter().enumerate() {
                    k[at * nz + ci] = g.dh[(e.row + t, i)];
                    k[ci * nz + at] = g.dh[(e.row + t, i)];
                }
            }
        }
    }

    /// The mode's Newton direction in `c.direction` onto `q₂`, `λ` and the impulses.
    fn apply_mode_update(&mut self, c: &mut ContactStep, q_next: &mut Vector<N>) {
        let nd = self.split.dynamic.len();
        for (ci, &i) in self.split.dynamic.iter().enumerate() {
            q_next[i] += c.direction[ci];
        }
        for r in 0..self.split.rows {
            self.lambda[r] += c.direction[nd + r];
        }
        for e in &c.mode {
            let rows = if e.has_friction() { 3 } else { 1 };
            for t in 0..rows {
                c.weights[e.row + t] += c.direction[e.base + t];
            }
        }
    }
}
