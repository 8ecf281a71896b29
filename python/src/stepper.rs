//! `VariationalStepper`: the midpoint VI one step at a time as trep's `MidpointVI` steps, with
//! the step's first and second derivatives under trep's names.

use numpy::ndarray::Ix1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::integrate::{
    loose_tolerance, MidpointVi, StepContext, StepDerivatives, StepInput, StepOutput,
    StepSecondDerivatives, ViSettings, LOOSEST_NEWTON_TOLERANCE,
};
use tree_mech::nalgebra::{DMatrix, Dyn};
use tree_mech::runtime::report::Entry;
use tree_mech::runtime::Vector;
use tree_mech::{SimError, System, TreeSystem};

use crate::arrays::{entry, matrix, vector};
use crate::errors::{bad, sim_error};
use crate::model::Model;
use crate::numbers::Numbers;

/// The midpoint VI one step at a time with everything given by the caller — `q₁` (the
/// kinematic entries too), the dynamic momenta `p₁`, the inputs `u₁` and the kinematic values
/// `k₂` at `t₂` — as trep's `MidpointVI` steps (forcing `left`, trep's, by default). The
/// workspace is kept between steps; the GIL is released while a step runs.
#[pyclass(module = "tree_mech")]
pub(crate) struct VariationalStepper {
    pub(crate) sys: TreeSystem,
    pub(crate) vi: MidpointVi<Dyn>,
    pub(crate) dynamic: Vec<usize>,
    pub(crate) kinematic: Vec<usize>,
    /// The last step's `q₂`: a step from it keeps the VI's predictor history.
    pub(crate) last: Vec<f64>,
    /// The largest turn of an angle over the last step (rad): what the trep layer warns of
    /// past a quarter turn when `max_turn` lets such a step through.
    #[pyo3(get)]
    pub(crate) largest_turn: f64,
}

#[pymethods]
impl VariationalStepper {
    #[new]
    /// `max_turn`: the largest turn of an angle a step may take (rad; a quarter turn by
    /// default, `inf` to take any step as trep does — the trep layer then warns).
    #[pyo3(signature = (model, forcing="left", tolerance=None, max_turn=None))]
    fn new(
        model: &Model,
        forcing: &str,
        tolerance: Option<f64>,
        max_turn: Option<f64>,
    ) -> PyResult<Self> {
        let forcing = crate::simulate::forcing(forcing)?;
        let mut settings = ViSettings {
            forcing,
            max_subdivisions: 0,
            ..ViSettings::default()
        };
        if let Some(turn) = max_turn {
            if turn.is_nan() || turn <= 0.0 {
                return Err(bad(format!(
                    "max_turn must be a positive number of radians (or inf), got {}",
                    tree_mech::model::Given(turn)
                )));
            }
            settings.max_turn = turn;
        }
        if let Some(tol) = tolerance {
            if !(tol > 0.0 && tol.is_finite()) {
                return Err(bad(format!(
                    "the tolerance must be a positive number, got {}",
                    tree_mech::model::Given(tol)
                )));
            }
            if tol > LOOSEST_NEWTON_TOLERANCE {
                return Err(bad(loose_tolerance("tolerance", tol)));
            }
            settings.tolerance = tol;
        }
        let sys = model.system();
        let vi = MidpointVi::new(&sys, settings);
        let n = model.n();
        Ok(VariationalStepper {
            dynamic: (0..n).filter(|&i| !sys.is_kinematic(i)).collect(),
            kinematic: (0..n).filter(|&i| sys.is_kinematic(i)).collect(),
            sys,
            vi,
            last: Vec::new(),
            largest_turn: 0.0,
        })
    }

    /// One step from `(t1, q1, p1)` to `t2` with inputs `u1` and kinematic values `k2` (model
    /// order); `lam` is Newton's first guess for λ. Returns `(q2, p2, lam, iterations,
    /// derivatives)`: `q2` every variable, `p2` the dynamic momenta, `lam` this integrator's
    /// multipliers (forces; trep's `lambda1` is `−Δt` times them for its own row scaling),
    /// and with `order` 1 or 2 a dict of the step's derivatives under trep's names (q2_dq1 …,
    /// lambda1_* with the `−Δt` scaling), second ones as (output, input₁, input₂) stacks.
    #[pyo3(signature = (t1, q1, p1, t2, u1, k2, lam, order=0))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        t1: f64,
        q1: Numbers<'_, Ix1>,
        p1: Numbers<'_, Ix1>,
        t2: f64,
        u1: Numbers<'_, Ix1>,
        k2: Numbers<'_, Ix1>,
        lam: Numbers<'_, Ix1>,
        order: u8,
    ) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        let step = self.request(t1, t2, [q1, p1, u1, k2, lam], order)?;
        let dt = step.dt;
        let (sys, vi) = (&mut self.sys, &mut self.vi);
        // Terms written in Python are called back with the GIL: kept for the step (taking
        // it back for every call costs more than the step), released otherwise.
        let solved = if sys.has_added() {
            step.solve(sys, vi)
        } else {
            py.detach(|| step.solve(sys, vi))
        };
        let (q2, p2, lambda, iterations, derivatives) = solved.map_err(|e| sim_error(py, &e))?;
        self.largest_turn = (0..q2.len())
            .filter(|&i| sys.is_angle(i))
            .map(|i| (q2[i] - step.q1[i]).abs())
            .fold(0.0, f64::max);
        self.last = q2.as_slice().to_vec();
        let p2: Vec<f64> = self.dynamic.iter().map(|&i| p2[i]).collect();
        let out = step_derivatives(py, derivatives, dt)?;
        (
            vector(py, q2.as_slice()),
            vector(py, &p2),
            vector(py, lambda.as_slice()),
            iterations,
            out,
        )
            .into_pyobject(py)
    }

    /// `p₂ = D₂L_d(q₁, q₂) + f⁺` for the step from `(t1, q1)` to `(t2, q2)` (model order; the
    /// dynamic momenta): how trep's `initialize_from_configs` starts from two configurations.
    fn momentum<'py>(
        &mut self,
        py: Python<'py>,
        t1: f64,
        q1: Numbers<'_, Ix1>,
        t2: f64,
        q2: Numbers<'_, Ix1>,
    ) -> PyResult<Py<PyAny>> {
        let n = self.sys.dof();
        let (q1, q2) = (q1.as_array().to_vec(), q2.as_array().to_vec());
        if q1.len() != n || q2.len() != n {
            return Err(bad(format!("q1 and q2 need {n} entries each")));
        }
        let dt = t2 - t1;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(bad(format!(
                "t2 must come after t1 (got t1 = {t1}, t2 = {t2})"
            )));
        }
        let (q1, q2) = (
            Vector::<Dyn>::from_column_slice(&q1),
            Vector::<Dyn>::from_column_slice(&q2),
        );
        let (mut force, mut motion) = (tree_mech::NoForce, |_: usize, _: f64| [0.0; 3]);
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, dt);
        let p = self
            .vi
            .momentum_after(cx.at(0, t1), &q1, &q2)
            .map_err(|e| sim_error(py, &e))?;
        let p: Vec<f64> = self.dynamic.iter().map(|&i| p[i]).collect();
        Ok(vector(py, &p))
    }
}

#[pymethods]
impl VariationalStepper {
    /// The discrete Euler–Lagrange residual at a given step (trep's `calc_f`): from `(t1, q1,
    /// p1)` to `(t2, q2)` with inputs `u1` and this integrator's multipliers `lam` (model
    /// order; `p1` the dynamic momenta), the dynamic rows `p₁ + D₁L_d + f⁻ + Δt Dh(q₁)ᵀλ`
    /// (eqs. (23), (25)) in the model's dynamic order, then `h(q₂)`. Zero for a step the
    /// integrator took; otherwise what is left over (inverse dynamics reads the inputs off it).
    #[pyo3(signature = (t1, q1, p1, t2, q2, u1, lam))]
    #[allow(clippy::too_many_arguments)]
    fn residual<'py>(
        &mut self,
        py: Python<'py>,
        t1: f64,
        q1: Numbers<'_, Ix1>,
        p1: Numbers<'_, Ix1>,
        t2: f64,
        q2: Numbers<'_, Ix1>,
        u1: Numbers<'_, Ix1>,
        lam: Numbers<'_, Ix1>,
    ) -> PyResult<Py<PyAny>> {
        let q2 = q2.as_array().to_vec();
        if q2.len() != self.sys.dof() {
            return Err(bad(format!(
                "q2 has {} entries; the step needs {}",
                q2.len(),
                self.sys.dof()
            )));
        }
        let k2: Vec<f64> = self.kinematic.iter().map(|&i| q2[i]).collect();
        let given = [q1, p1, u1, lam].map(|a| a.as_array().to_vec());
        let [q1, p1, u1, lam] = given;
        let step = self.request_of(t1, t2, [q1, p1, u1, k2, lam], 0)?;
        let q2 = Vector::<Dyn>::from_vec(q2);
        let (mut force, mut motion) = (tree_mech::NoForce, |_: usize, _: f64| [0.0; 3]);
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, step.dt);
        cx.u = &step.u1;
        self.vi.lambda.copy_from_slice(&step.lambda);
        self.vi.prepare(cx.sys, &step.q1);
        self.vi
            .residual(cx.at(0, t1), &step.q1, &step.p1, &q2, false);
        let r = self.vi.residual_vector();
        if let Some(x) = r.iter().find(|x| !x.is_finite()) {
            return Err(sim_error(
                py,
                &SimError::NonFinite {
                    step: 0,
                    t: t1,
                    what: format!("the step's residual ({x})"),
                },
            ));
        }
        Ok(vector(py, r.as_slice()))
    }
}

/// One step's arguments, checked, in model order (`p1` and `k2` spread over every variable).
struct StepRequest {
    t1: f64,
    dt: f64,
    q1: Vector<Dyn>,
    p1: Vector<Dyn>,
    u1: Vec<f64>,
    /// The kinematic variables' values at `t₂` (every variable's slot; the others 0).
    k2: Vec<f64>,
    lambda: Vec<f64>,
    order: u8,
    /// Whether the step continues from the last one's `q₂` (the predictor's history kept).
    continuing: bool,
}

/// A step's result: `q₂`, `p₂`, λ, Newton's iterations and the derivatives asked for.
type StepResult = (
    Vector<Dyn>,
    Vector<Dyn>,
    Vector<Dyn>,
    usize,
    Option<(StepDerivatives, Option<StepSecondDerivatives>)>,
);

impl VariationalStepper {
    /// The arguments `[q1, p1, u1, k2, lam]` checked against the model (a `ValueError` names
    /// the first of the wrong size), `t2` after `t1`, and `order` 0, 1 or 2.
    fn request(
        &self,
        t1: f64,
        t2: f64,
        given: [Numbers<'_, Ix1>; 5],
        order: u8,
    ) -> PyResult<StepRequest> {
        self.request_of(t1, t2, given.map(|a| a.as_array().to_vec()), order)
    }

    /// [`Self::request`] of arguments already read.
    fn request_of(
        &self,
        t1: f64,
        t2: f64,
        given: [Vec<f64>; 5],
        order: u8,
    ) -> PyResult<StepRequest> {
        let [q1, p1, u1, k2, lam] = given;
        let n = self.sys.dof();
        let sizes = [
            ("q1", q1.len(), n),
            ("p1", p1.len(), self.dynamic.len()),
            ("u1", u1.len(), self.sys.input_count()),
            ("k2", k2.len(), self.kinematic.len()),
            ("lambda", lam.len(), self.sys.constraint_count()),
        ];
        if let Some((what, got, want)) = sizes.iter().find(|(_, got, want)| got != want) {
            return Err(bad(format!(
                "{what} has {got} entries; the step needs {want}"
            )));
        }
        let dt = t2 - t1;
        if !(dt > 0.0 && dt.is_finite() && t1.is_finite()) {
            return Err(bad(format!(
                "t2 must come after t1 (got t1 = {t1}, t2 = {t2})"
            )));
        }
        if order > 2 {
            return Err(bad("order is 0, 1 or 2"));
        }
        let spread = |values: &[f64], over: &[usize]| {
            let mut all = vec![0.0; n];
            over.iter().zip(values).for_each(|(&i, &x)| all[i] = x);
            all
        };
        Ok(StepRequest {
            t1,
            dt,
            continuing: self.last == q1 && order == 0,
            q1: Vector::<Dyn>::from_vec(q1),
            p1: Vector::<Dyn>::from_vec(spread(&p1, &self.dynamic)),
            u1,
            k2: spread(&k2, &self.kinematic),
            lambda: lam,
            order,
        })
    }
}

impl StepRequest {
    /// The step solved by `vi` (and differentiated to `order`), the kinematic variables at
    /// q₁'s values up to the midpoint and at k₂'s after it (the step asks for nothing else).
    fn solve(
        &self,
        sys: &mut TreeSystem,
        vi: &mut MidpointVi<Dyn>,
    ) -> Result<StepResult, SimError> {
        let (t1, dt, q1, p1) = (self.t1, self.dt, &self.q1, &self.p1);
        let half = t1 + 0.5 * dt;
        let mut motion = |i: usize, t: f64| {
            if t > half {
                [self.k2[i], 0.0, 0.0]
            } else {
                [q1[i], 0.0, 0.0]
            }
        };
        let mut force = tree_mech::NoForce;
        let mut cx = StepContext::new(sys, &mut force, &mut motion, dt);
        cx.u = &self.u1;
        vi.lambda.copy_from_slice(&self.lambda);
        if !self.continuing {
            vi.predict_from_rest();
        }
        let (mut q2, mut p, mut next) = (q1.clone(), p1.clone(), q1.clone());
        vi.step(cx.at(0, t1), &mut q2, &mut p, &mut next)?;
        let iterations = vi.iterations;
        let derivatives = match self.order {
            0 => None,
            1 => Some((vi.derivatives(cx.at(0, t1), q1, p1, &q2)?, None)),
            _ => {
                let (first, second) = vi.second_derivatives(cx.at(0, t1), q1, p1, &q2)?;
                Some((first, Some(second)))
            }
        };
        Ok((q2, p, vi.lambda.clone(), iterations, derivatives))
    }
}

/// trep's name of a step output.
pub(crate) fn step_output_name(of: StepOutput) -> &'static str {
    match of {
        StepOutput::Q2 => "q2",
        StepOutput::P2 => "p2",
        StepOutput::Lambda => "lambda1",
    }
}

/// A step's derivatives as a dict under trep's names (`q2_dq1` …, `lambda1_*` scaled by
/// `−Δt`), second ones as (output, input₁, input₂) stacks; empty without derivatives.
pub(crate) fn step_derivatives<'py>(
    py: Python<'py>,
    derivatives: Option<(StepDerivatives, Option<StepSecondDerivatives>)>,
    dt: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    if let Some((first, second)) = derivatives {
        for of in StepOutput::ALL {
            let scale = if of == StepOutput::Lambda { -dt } else { 1.0 };
            for by in StepInput::ALL {
                let name = format!("{}_d{}", step_output_name(of), by.name());
                out.set_item(name, matrix(py, &(first.block(of, by) * scale)))?;
            }
            if let Some(second) = &second {
                for (k, &a) in StepInput::ALL.iter().enumerate() {
                    for &b in &StepInput::ALL[k..] {
                        let rows: Vec<DMatrix<f64>> =
                            second.block(of, a, b).iter().map(|h| h * scale).collect();
                        let name = format!("{}_d{}d{}", step_output_name(of), a.name(), b.name());
                        out.set_item(name, entry(py, &Entry::Stack(rows)))?;
                    }
                }
            }
        }
    }
    Ok(out)
}
