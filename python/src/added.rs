//! Terms written in Python, added to a model's interpreted system (`Model.add_python_terms`):
//! what the trep layer's potentials, forces and constraints defined by subclassing become.
//! The runtime asks for them on every evaluation (`tree_mech::runtime::AddedTerms`), taking
//! the GIL for the call (a VI step of such a model keeps it: `stepper.rs`).

use std::cell::RefCell;
use std::sync::Arc;

use pyo3::prelude::*;
use pyo3::types::PyList;
use tree_mech::kernel::Output;
use tree_mech::runtime::{AddedTerms, Ask};
use tree_mech::Order;

use crate::arrays::vector;
use crate::errors::bad;
use crate::model::Model;

/// A Python callable `terms(kind, order, q, dq, along)` with the rows it adds (`q`, `q̇`
/// lists, `along` arrays). `kind` is
/// `"lagrangian"`, `"terms"` or `"constraints"`, `order` 0, 1 or 2 (first, dynamics, full),
/// `along` `None` or `(δq, δq̇)`; it returns `[(key, values, derivatives or None), …]` with
/// `key` one of `L`, `dL_dq`, `F`, `d2L_dqdq`, `dF_dq`, `dF_ddq`, `h`, `Dh`, `dh_dot`, `D2h`
/// and the values flattened row-major (model order). `None` (the callable failed, keeping its
/// own account of why), an exception, an unknown key or a wrong length hands NaN, which the
/// runtime refuses; the last three are then raised in place of its "not finite".
#[derive(Debug)]
struct PythonTerms {
    callback: Py<PyAny>,
    names: Vec<String>,
}

/// The output of entry `k` of a flattened `key` over `n` variables.
fn output(key: &str, k: usize, n: usize) -> Option<Output> {
    let (a, b, c) = (k / (n * n), (k / n) % n, k % n);
    Some(match key {
        "L" => Output::L,
        "dL_dq" => Output::DlDq(k),
        "F" => Output::Force(k),
        "d2L_dqdq" => Output::D2lDqDq(k / n, k % n),
        "dF_dq" => Output::DforceDq(k / n, k % n),
        "dF_ddq" => Output::DforceDdq(k / n, k % n),
        "h" => Output::H(k),
        "Dh" => Output::Dh(k / n, k % n),
        "dh_dot" => Output::DhDot(k),
        "D2h" => Output::D2h(a, b, c),
        _ => return None,
    })
}

/// How many entries output `key` has over `n` variables and `rows` added rows; `None` for
/// a key it does not know.
fn length(key: &str, n: usize, rows: usize) -> Option<usize> {
    Some(match key {
        "L" => 1,
        "dL_dq" | "F" => n,
        "d2L_dqdq" | "dF_dq" | "dF_ddq" => n * n,
        "h" | "dh_dot" => rows,
        "Dh" => rows * n,
        "D2h" => rows * n * n,
        _ => return None,
    })
}

/// Entries the callable handed back: (key, values, derivatives or none).
type Entries = Vec<(String, Vec<f64>, Option<Vec<f64>>)>;

/// `entries` checked against their keys' lengths, or a sentence naming the first wrong one.
fn checked(entries: Entries, n: usize, rows: usize) -> PyResult<Entries> {
    for (key, values, derivatives) in &entries {
        let Some(want) = length(key, n, rows) else {
            return Err(bad(format!(
                "add_python_terms: the callable handed back `{key}`, which is none of L, \
                 dL_dq, F, d2L_dqdq, dF_dq, dF_ddq, h, Dh, dh_dot, D2h"
            )));
        };
        let lengths = [Some(values.len()), derivatives.as_ref().map(Vec::len)];
        if let Some(got) = lengths.into_iter().flatten().find(|&got| got != want) {
            return Err(bad(format!(
                "add_python_terms: `{key}` has {got} entries; over {n} variables and {rows} \
                 added rows it has {want}"
            )));
        }
    }
    Ok(entries)
}

thread_local! {
    /// Why the last call back into Python failed, for the error the failed evaluation raises
    /// ([`take_failure`]): the callable's own exception, or the shape it handed back.
    static FAILURE: RefCell<Option<PyErr>> = const { RefCell::new(None) };
}

/// The reason a call back into Python failed since the last one taken, if any: raised in
/// place of the runtime's "not finite", which only sees the NaN it handed over.
pub(crate) fn take_failure() -> Option<PyErr> {
    FAILURE.with(|f| f.borrow_mut().take())
}

/// What a failed call hands: NaN where the runtime reads first.
fn failed(ask: Ask, out: &mut dyn FnMut(Output, f64, f64)) {
    match ask {
        Ask::Constraints(_) => out(Output::H(0), f64::NAN, f64::NAN),
        _ => {
            out(Output::L, f64::NAN, f64::NAN);
            out(Output::DlDq(0), f64::NAN, f64::NAN);
        }
    }
}

impl AddedTerms for PythonTerms {
    fn constraint_names(&self) -> Vec<String> {
        self.names.clone()
    }

    fn add(
        &self,
        ask: Ask,
        q: &[f64],
        dq: &[f64],
        along: Option<(&[f64], &[f64])>,
        out: &mut dyn FnMut(Output, f64, f64),
    ) {
        let level = |o: Order| match o {
            Order::First => 0,
            Order::Dynamics => 1,
            Order::Full => 2,
        };
        let (kind, order) = match ask {
            Ask::Lagrangian => ("lagrangian", 0),
            Ask::Terms(o) => ("terms", level(o)),
            Ask::Constraints(o) => ("constraints", level(o)),
        };
        let (n, rows) = (q.len(), self.names.len());
        let result: Option<Entries> = Python::attach(|py| {
            let along = along.map(|(a, b)| (vector(py, a), vector(py, b)));
            // The state as lists: the script's methods read it entry by entry, which a list
            // serves several times faster than an array.
            let (q, dq) = (PyList::new(py, q), PyList::new(py, dq));
            let (Ok(q), Ok(dq)) = (q, dq) else {
                return None;
            };
            let args = (kind, order, q, dq, along);
            self.callback
                .call1(py, args)
                .and_then(|r| {
                    r.extract::<Option<Entries>>(py).map_err(|_| {
                        bad(format!(
                            "add_python_terms: the callable must hand back None or a list of \
                             (key, values, derivatives or None), got {}",
                            r.bind(py).repr().map_or("?".into(), |s| s.to_string())
                        ))
                    })
                })
                .and_then(|r| r.map(|e| checked(e, n, rows)).transpose())
                .unwrap_or_else(|e| {
                    // The first reason is kept: what follows from its NaN is no news.
                    FAILURE.with(|f| {
                        f.borrow_mut().get_or_insert(e);
                    });
                    None
                })
        });
        let Some(entries) = result else {
            return failed(ask, out);
        };
        for (key, values, derivatives) in entries {
            for (k, &v) in values.iter().enumerate() {
                let d = derivatives.as_ref().map_or(0.0, |d| d[k]);
                if let Some(at) = output(&key, k, n) {
                    out(at, v, d);
                }
            }
        }
    }
}

#[pymethods]
impl Model {
    /// Adds terms computed in Python to this model's interpreted system (every evaluation,
    /// step and derivative after this call asks for them): `terms(kind, order, q, dq, along)`
    /// as described in `python/src/added.rs`, adding the constraint rows `constraints` after
    /// the model's. What the trep layer's Python-defined potentials, forces and constraints
    /// use; replaces terms added before.
    #[pyo3(signature = (terms, constraints=Vec::new()))]
    fn add_python_terms(&self, terms: Py<PyAny>, constraints: Vec<String>) {
        let added = PythonTerms {
            callback: terms,
            names: constraints,
        };
        take_failure(); // a stale reason belongs to terms no longer called
        let mut sys = self.sys.lock().expect("no panic holds the lock");
        *sys = sys.clone().with_added(Arc::new(added));
    }
}
