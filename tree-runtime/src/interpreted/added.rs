//! Terms from outside the model, added to an interpreted system's own: potentials, forces and
//! constraint rows a caller computes itself (the trep layer's elements defined in Python). The
//! system asks for them after its own terms, on every path — the Lagrangian's terms, the
//! constraints, the energy, and over dual numbers for the derivatives — so a step, its
//! derivatives and a linearisation see one system. The compiled systems have no such hook: a
//! term of Rust is a model element, written once over `Scalar`.

use std::borrow::Cow;
use std::fmt::Debug;
use std::ops::Mul;
use std::sync::Arc;

use tree_kernel::{Dual, Order, Output, Sink};

/// What a system asks of its [`AddedTerms`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ask {
    /// `L` alone (its potentials' `−V`): the energy and `L(q, 0)`.
    Lagrangian,
    /// The Lagrangian's outputs up to an order: `L`, `∂L/∂q` and the force `F` from
    /// [`Order::First`]; `∂²L/∂q∂q`, `∂F/∂q` and `∂F/∂q̇` at [`Order::Full`]. (Potentials and
    /// forces only: nothing added to `∂L/∂q̇` or `M`.)
    Terms(Order),
    /// Its constraint rows up to an order: `h` and `Dh`; `q̇ᵀD²h q̇` from [`Order::Dynamics`];
    /// `D²h` at [`Order::Full`]. Rows are numbered from 0 among its own.
    Constraints(Order),
}

/// A caller's terms, added to an interpreted system's own
/// ([`TreeSystem::with_added`](crate::TreeSystem::with_added)).
pub trait AddedTerms: Send + Sync + Debug {
    /// The names of the constraint rows it adds, after the model's.
    fn constraint_names(&self) -> Vec<String>;

    /// Hands each output `ask` names at `(q, q̇)` (model order) to `out(output, value,
    /// derivative)`; the derivative is along `along = (δq, δq̇)` when given (the dual-number
    /// evaluations: `∂²L/∂q∂q` along δq needs the potential's third derivatives), else 0.
    /// A failure is reported by handing NaN, which the integrators and evaluations refuse
    /// (the caller keeps its own account of why).
    fn add(
        &self,
        ask: Ask,
        q: &[f64],
        dq: &[f64],
        along: Option<(&[f64], &[f64])>,
        out: &mut dyn FnMut(Output, f64, f64),
    );
}

/// The added terms of a system and where its own constraint rows end.
#[derive(Clone, Debug)]
pub(crate) struct Added {
    pub(crate) terms: Arc<dyn AddedTerms>,
    /// The model's constraint rows: the added ones are numbered after them.
    pub(crate) first_row: usize,
    /// How many rows the terms add (none: constraints are never asked of them).
    pub(crate) rows: usize,
}

/// A scalar the added terms are evaluated over: `f64`, or a dual number (its value and its
/// direction handed to the terms, the derivatives they return put back).
pub(crate) trait Point: Copy + Mul<Output = Self> {
    /// The values of `x`, and their directions for dual numbers.
    fn split(x: &[Self]) -> (Cow<'_, [f64]>, Option<Vec<f64>>);
    /// The scalar of a value and its derivative.
    fn make(v: f64, d: f64) -> Self;
}

impl Point for f64 {
    fn split(x: &[f64]) -> (Cow<'_, [f64]>, Option<Vec<f64>>) {
        (Cow::Borrowed(x), None)
    }
    fn make(v: f64, _: f64) -> f64 {
        v
    }
}

impl Point for Dual {
    fn split(x: &[Dual]) -> (Cow<'_, [f64]>, Option<Vec<f64>>) {
        (
            Cow::Owned(x.iter().map(|d| d.v).collect()),
            Some(x.iter().map(|d| d.d).collect()),
        )
    }
    fn make(v: f64, d: f64) -> Dual {
        Dual::new(v, d)
    }
}

impl Added {
    /// `at` with the added rows numbered after the model's.
    fn shifted(&self, at: Output) -> Output {
        let r0 = self.first_row;
        match at {
            Output::H(r) => Output::H(r0 + r),
            Output::Dh(r, i) => Output::Dh(r0 + r, i),
            Output::DhDot(r) => Output::DhDot(r0 + r),
            Output::D2h(r, i, j) => Output::D2h(r0 + r, i, j),
            other => other,
        }
    }

    /// Asks the terms for `ask` at `(q, q̇)` (with their directions, over dual numbers) and
    /// hands each output, its rows numbered after the model's, to `out`.
    fn each<S: Point>(&self, ask: Ask, q: &[S], dq: &[S], out: &mut dyn FnMut(Output, S)) {
        if matches!(ask, Ask::Constraints(_)) && self.rows == 0 {
            return;
        }
        let ((q, dir_q), (dq, dir_dq)) = (S::split(q), S::split(dq));
        let along = dir_q.as_deref().zip(dir_dq.as_deref());
        self.terms.add(ask, &q, &dq, along, &mut |at, v, d| {
            out(self.shifted(at), S::make(v, d))
        });
    }

    /// Adds what `ask` names at `(q, q̇)` into `out`.
    pub(crate) fn add<S: Point>(&self, ask: Ask, q: &[S], dq: &[S], out: &mut impl Sink<S>) {
        self.each(ask, q, dq, &mut |at, x| out.add(at, x));
    }

    /// The added `L` at `(q, q̇)`: its potentials' `−V`.
    pub(crate) fn lagrangian(&self, q: &[f64], dq: &[f64]) -> f64 {
        let mut l = 0.0;
        self.each(Ask::Lagrangian, q, dq, &mut |at, x| {
            if at == Output::L {
                l += x;
            }
        });
        l
    }

    /// Adds its rows' `h`, `Dh` and `Σ_r w_r D²h_r` on the `dynamic` columns at `q` (the
    /// weights of every row, the model's first) into `out` — what a weighted constraint
    /// Hessian adds for them.
    pub(crate) fn add_weighted<S: Point>(
        &self,
        q: &[S],
        weights: &[S],
        dynamic: &[bool],
        out: &mut impl Sink<S>,
    ) {
        // `q̇ᵀD²h q̇` is not an output here: any velocity will do.
        self.each(Ask::Constraints(Order::Full), q, q, &mut |at, x| match at {
            Output::D2h(r, i, j) if dynamic[j] => {
                out.add(Output::WeightedD2h(i, j), weights[r] * x)
            }
            Output::H(_) | Output::Dh(..) => out.add(at, x),
            _ => {}
        });
    }
}
