//! The smooth integrators and the unilateral rows (docs/derivations.md §13). RK4 and rk45
//! integrate the smooth equations of motion: while every gap stays open a limit, a contact or
//! a slack string exerts nothing and their answer is exact, so they run; the first step that
//! closes one ends the run with an error naming it — they cannot enforce it, and passing
//! through would be a silent wrong answer. Only the variational integrator enforces them.

use nalgebra::{allocator::Allocator, DefaultAllocator};

use crate::error::SimError;
use crate::system::{ConstraintTerms, System, Vector};

/// Watches a smooth run's unilateral gaps (allocated once, at setup; nothing per step).
#[derive(Clone, Debug)]
pub(crate) struct GapWatch {
    /// Each element's gap row and name (tangent rows are not gaps).
    rows: Vec<(usize, String)>,
    terms: ConstraintTerms,
    /// A smooth run's impulses: none (one zero a row, for the samples).
    zeros: Vec<f64>,
    /// The integrator's name, for the error.
    integrator: &'static str,
}

impl GapWatch {
    /// The watch for `sys`'s unilateral rows; `None` when it has none.
    pub(crate) fn new<S: System>(sys: &S, integrator: &'static str) -> Option<Self>
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        let gaps = sys.unilateral();
        if gaps.is_empty() {
            return None;
        }
        let mut rows = Vec::with_capacity(gaps.len());
        let mut row = 0;
        for g in gaps {
            let n = g.rows();
            rows.push((row, g.name));
            row += n;
        }
        Some(GapWatch {
            rows,
            terms: ConstraintTerms::zeros(row, sys.dof()),
            zeros: vec![0.0; row],
            integrator,
        })
    }

    /// `Ok` while every gap at `q` (step `step`, time `t`) is open; the first closed one is
    /// the error.
    pub(crate) fn check<S: System>(
        &mut self,
        sys: &mut S,
        q: &Vector<S::N>,
        step: usize,
        t: f64,
    ) -> Result<(), SimError>
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        sys.gaps(q, None, &mut self.terms);
        match self.rows.iter().find(|(r, _)| self.terms.h[*r] < 0.0) {
            None => Ok(()),
            Some((r, name)) => Err(SimError::Unenforced {
                step,
                t,
                element: name.clone(),
                gap: self.terms.h[*r],
                integrator: self.integrator,
            }),
        }
    }
}

impl GapWatch {
    /// A sample's impulses (none) and every row's value at `q`, as the VI's samples carry them.
    pub(crate) fn sample<S: System>(&mut self, sys: &mut S, q: &Vector<S::N>) -> (&[f64], &[f64])
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        sys.gaps(q, None, &mut self.terms);
        (&self.zeros, self.terms.h.as_slice())
    }
}
