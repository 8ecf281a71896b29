//! Terms from outside the model, added to an interpreted system's own: potentials, forces and
//! constraint rows a caller computes itself (the trep layer's elements defined in Python). The
//! system asks for them after its own terms, on every path — the Lagrangian's terms, the
//! constraints, the energy, and over dual numbers for the derivatives — so a step, its
//! derivatives and a linearisation see one system. The compiled systems have no such hook: a
//! term of Rust is a model element, written once over `Scalar`.

use std::fmt::Debug;
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

    /// Adds what `ask` names at `(q, q̇)` into `out`.
    pub(crate) fn add(&self, ask: Ask, q: &[f64], dq: &[f64], out: &mut impl Sink<f64>) {
        self.terms.add(ask, q, dq, None, &mut |at, v, _| {
            out.add(self.shifted(at), v)
        });
    }

    /// Adds what `ask` names at the dual point `(q, q̇)` into `out`, each output with its
    /// derivative along the point's direction.
    pub(crate) fn add_dual(&self, ask: Ask, q: &[Dual], dq: &[Dual], out: &mut impl Sink<Dual>) {
        let (q, dir_q) = split(q);
        let (dq, dir_dq) = split(dq);
        self.terms
            .add(ask, &q, &dq, Some((&dir_q, &dir_dq)), &mut |at, v, d| {
                out.add(self.shifted(at), Dual::new(v, d))
            });
    }

    /// Adds its rows' `h`, `Dh` and `Σ_r w_r D²h_r` on the `dynamic` columns (weights of
    /// every row, the model's first) into `out`, over any scalar — what a weighted
    /// constraint Hessian adds for them.
    pub(crate) fn add_weighted<S: Copy + std::ops::Mul<Output = S>>(
        &self,
        weights: &[S],
        dynamic: &[bool],
        value: impl Fn(f64, f64) -> S,
        run: impl FnOnce(&mut dyn FnMut(Output, f64, f64)),
        out: &mut impl Sink<S>,
    ) {
        run(&mut |at, v, d| match self.shifted(at) {
            Output::D2h(r, i, j) if dynamic[j] => {
                out.add(Output::WeightedD2h(i, j), weights[r] * value(v, d))
            }
            at @ (Output::H(_) | Output::Dh(..)) => out.add(at, value(v, d)),
            _ => {}
        });
    }
}

/// The values and the directions of dual numbers.
fn split(x: &[Dual]) -> (Vec<f64>, Vec<f64>) {
    (
        x.iter().map(|d| d.v).collect(),
        x.iter().map(|d| d.d).collect(),
    )
}
