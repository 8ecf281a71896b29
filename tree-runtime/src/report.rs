//! A state's linearisation as named entries — the continuous derivatives (§9), and one step
//! as a map (the VI with trep's names and scaling, or an explicit tableau) — what
//! `tree-mech linearize` prints as JSON and the Python package's `Model.linearize` returns
//! as arrays. One place computes them; each front end only formats.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dyn};

use crate::context::StepContext;
use crate::dynamics::{ModelMotions, NoForce, Prescription};
use crate::error::SimError;
use crate::integrate::{Forcing, MidpointVi, StepInput, StepOutput, ViSettings};
use crate::linearize::{
    continuous_derivatives, explicit_step_derivatives, ContinuousDerivatives, DORMAND_PRINCE, RK4,
};
use crate::system::{ConstraintTerms, Order, System, Vector};

/// One named value.
#[derive(Clone, Debug, PartialEq)]
pub enum Entry {
    /// A number.
    Scalar(f64),
    /// A vector.
    Vector(Vec<f64>),
    /// A matrix.
    Matrix(DMatrix<f64>),
    /// One matrix per output row (second derivatives, indexed (output, input₁, input₂)).
    Stack(Vec<DMatrix<f64>>),
}

/// Named entries, in order.
pub(crate) type Entries = Vec<(String, Entry)>;

/// An explicit step to linearise instead of the VI's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Explicit {
    /// Classical RK4.
    Rk4,
    /// Dormand–Prince's fifth-order step of the given length.
    Rk45,
}

impl Explicit {
    /// The explicit step `integrator` takes: `None` for the VI.
    pub fn of(integrator: tree_model::Integrator) -> Option<Explicit> {
        match integrator {
            tree_model::Integrator::Vi => None,
            tree_model::Integrator::Rk4 => Some(Explicit::Rk4),
            tree_model::Integrator::Rk45 => Some(Explicit::Rk45),
        }
    }
}

/// What to linearise.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    /// The time (kinematic variables take their prescription at it).
    pub t: f64,
    /// The inputs (empty: zero).
    pub u: Vec<f64>,
    /// With a step: its length.
    pub dt: Option<f64>,
    /// The VI step's start momenta of the dynamic variables (default `∂L/∂q̇` at the state).
    pub p: Option<Vec<f64>>,
    /// The VI's forcing.
    pub forcing: Forcing,
    /// The VI's quadrature point.
    pub alpha: f64,
    /// An explicit step instead of the VI's.
    pub explicit: Option<Explicit>,
    /// Also the VI step's second derivatives (trep's 30).
    pub second_order: bool,
    /// The VI's contact relaxation κ (`ViSettings::kappa`).
    pub kappa: f64,
}

/// The report: the continuous entries, and the step's under its key (`vi`, `rk4`, `rk45`).
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// `q`, `dq`, `u`, `qdd`, `qdd_dq`, … (the kinematic entries of q, q̇ as prescribed).
    pub continuous: Entries,
    /// The step's entries under its key.
    pub step: Option<(&'static str, Entries)>,
}

fn name(s: &str, e: Entry) -> (String, Entry) {
    (s.to_string(), e)
}

/// Linearises `sys` at `(q, q̇)` as `request` says, the kinematic variables following the
/// model's prescription. Errors name the part that failed.
pub fn linearize<S: System<N = Dyn>>(
    sys: &mut S,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    request: &Request,
) -> Result<Report, SimError>
where
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    let mut motion = ModelMotions::of(sys);
    linearize_with(sys, q, dq, request, &mut motion)
}

/// A violation a typed-in configuration can carry without being the cause of a failed step
/// (model units): below it, a failed step's message does not point at the constraints.
const OFF_THE_CONSTRAINTS: f64 = 1e-9;

/// The constraint `q` violates most, and by how much, when that is more than
/// [`OFF_THE_CONSTRAINTS`].
fn off_the_constraints<S: System<N = Dyn>>(sys: &mut S, q: &Vector<Dyn>) -> Option<(String, f64)>
where
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    let m = sys.constraint_count();
    let mut c = ConstraintTerms::zeros(m, q.len());
    let zero = sys.zero_vector();
    sys.constraints(q, &zero, Order::First, &mut c);
    let worst = (0..m).max_by(|&a, &b| c.h[a].abs().total_cmp(&c.h[b].abs()))?;
    (c.h[worst].abs() > OFF_THE_CONSTRAINTS)
        .then(|| (sys.constraint_name(worst).to_string(), c.h[worst]))
}

/// [`linearize`] with the kinematic variables' `[q, q̇, q̈]` from `motion`.
pub fn linearize_with<S: System<N = Dyn>, P: Prescription>(
    sys: &mut S,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    request: &Request,
    motion: &mut P,
) -> Result<Report, SimError>
where
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    check_request(request)?;
    // The continuous equations know no contact: with unilateral rows only a VI step (which
    // enforces them) is a linearisation of the model.
    if !sys.unilateral().is_empty() && (request.dt.is_none() || request.explicit.is_some()) {
        return Err(SimError::Unsupported(
            "the model has unilateral rows (limits enforced, contacts or slack strings), which the continuous dynamics and RK4/rk45 do not know: linearise one VI step (--dt, the VI), whose derivatives go through the contacts".into(),
        ));
    }
    let (mut q, mut dq) = (q.clone(), dq.clone());
    let t = request.t;
    for k in (0..sys.dof()).filter(|&i| sys.is_kinematic(i)) {
        [q[k], dq[k], _] = motion.kinematic(k, t);
    }
    let mut force = NoForce;
    let names = sys.input_names();
    let inputs: &[f64] = &request.u;
    let mut cx = StepContext::new(sys, &mut force, motion, 0.0);
    cx.u = inputs;
    let d = continuous_derivatives(cx.at(0, t), &q, &dq)
        .map_err(|e| SimError::InvalidInput(e.under_inputs(&names, inputs).at_this_state()))?;
    let continuous = continuous_entries(&q, &dq, request, &d);
    let step = match (request.dt, request.explicit) {
        (None, _) => None,
        (Some(dt), Some(method)) => {
            cx.dt = dt;
            Some(explicit_step(&mut cx, &q, &dq, t, method)?)
        }
        (Some(dt), None) => {
            cx.dt = dt;
            Some(("vi", vi_step(&mut cx, &q, &dq, request, &d.lambda)?))
        }
    };
    Ok(Report { continuous, step })
}

/// A request's own numbers: second derivatives only for the VI with a step, a finite time,
/// a positive step.
fn check_request(request: &Request) -> Result<(), SimError> {
    let bad = |m: String| Err(SimError::InvalidInput(m));
    if request.second_order && (request.explicit.is_some() || request.dt.is_none()) {
        return bad("second-order derivatives are for the VI step: give a step length (and not an explicit integrator)".into());
    }
    if !request.t.is_finite() {
        return bad(format!("the time {} is not finite", request.t));
    }
    if !(request.kappa.is_finite() && request.kappa >= 0.0) {
        return bad(format!(
            "the contact relaxation κ must be finite and not negative, got {}",
            request.kappa
        ));
    }
    if let Some(dt) = request.dt {
        if !(dt > 0.0 && dt.is_finite()) {
            return bad(format!(
                "the step must be a positive number, got {}",
                tree_model::Given(dt)
            ));
        }
    }
    Ok(())
}

/// The continuous linearisation's entries.
fn continuous_entries(
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    request: &Request,
    d: &ContinuousDerivatives,
) -> Entries {
    vec![
        name("q", Entry::Vector(q.as_slice().to_vec())),
        name("dq", Entry::Vector(dq.as_slice().to_vec())),
        name("u", Entry::Vector(request.u.clone())),
        name("qdd", Entry::Vector(d.qdd.as_slice().to_vec())),
        name("qdd_dq", Entry::Matrix(d.qdd_dq.clone())),
        name("qdd_ddq", Entry::Matrix(d.qdd_ddq.clone())),
        name("qdd_du", Entry::Matrix(d.qdd_du.clone())),
        name("lambda", Entry::Vector(d.lambda.as_slice().to_vec())),
        name("lambda_dq", Entry::Matrix(d.lambda_dq.clone())),
        name("lambda_ddq", Entry::Matrix(d.lambda_ddq.clone())),
        name("lambda_du", Entry::Matrix(d.lambda_du.clone())),
    ]
}

/// One explicit step of length `cx.dt` and its derivatives, under its key.
fn explicit_step<S, P>(
    cx: &mut StepContext<S, NoForce, P>,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    t: f64,
    method: Explicit,
) -> Result<(&'static str, Entries), SimError>
where
    S: System<N = Dyn>,
    P: Prescription,
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    let dt = cx.dt;
    let (key, tableau, what) = match method {
        Explicit::Rk4 => ("rk4", &RK4, "the RK4 step"),
        Explicit::Rk45 => ("rk45", &DORMAND_PRINCE, "the Dormand–Prince step"),
    };
    let d = explicit_step_derivatives(cx.at(0, t), q, dq, tableau)
        .map_err(|e| SimError::InvalidInput(format!("{what}: {e}")))?;
    let step = vec![
        name("t2", Entry::Scalar(t + dt)),
        name("x2", Entry::Vector(d.x2.as_slice().to_vec())),
        name("x2_dx1", Entry::Matrix(d.x2_dx1)),
        name("x2_du1", Entry::Matrix(d.x2_du1)),
    ];
    Ok((key, step))
}

/// One VI step of length `cx.dt` from `(q, p₁)` (`p₁` the request's or `∂L/∂q̇`), its first
/// (and, asked, second) derivatives as trep names them.
fn vi_step<S, P>(
    cx: &mut StepContext<S, NoForce, P>,
    q: &Vector<Dyn>,
    dq: &Vector<Dyn>,
    request: &Request,
    lambda: &DVector<f64>,
) -> Result<Entries, SimError>
where
    S: System<N = Dyn>,
    P: Prescription,
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    let (t, dt) = (request.t, cx.dt);
    let bad = |m: String| Err(SimError::InvalidInput(m));
    if !(0.0..=1.0).contains(&request.alpha) {
        return bad(format!(
            "VI alpha must lie in [0, 1], got {}",
            tree_model::Given(request.alpha)
        ));
    }
    let settings = ViSettings {
        alpha: request.alpha,
        forcing: request.forcing,
        max_subdivisions: 0,
        derivatives: true,
        kappa: request.kappa,
        ..ViSettings::default()
    };
    let dynamic: Vec<usize> = (0..q.len()).filter(|&i| !cx.sys.is_kinematic(i)).collect();
    let mut vi = MidpointVi::new(&*cx.sys, settings);
    let mut p1 = vi.initial_momentum(cx.sys, q, dq);
    if let Some(p) = &request.p {
        given_momentum(&*cx.sys, &dynamic, p, &mut p1)?;
    }
    // A guess for λ: the continuous equations'.
    vi.lambda.copy_from(lambda);
    let (mut q2, mut p2, mut next) = (q.clone(), p1.clone(), q.clone());
    let failed = |e: SimError| SimError::InvalidInput(format!("the VI step: {e}"));
    if let Err(e) = vi.step(cx.at(0, t), &mut q2, &mut p2, &mut next) {
        return Err(off_the_constraints(cx.sys, q).map_or_else(
            || failed(e.clone()),
            |(name, h)| {
                SimError::InvalidInput(format!(
                    "the VI step: {e}; the configuration is off constraint `{name}` by {h:e}, \
                     which the step must close within Δt: linearise at a configuration on the \
                     constraints (simulate projects its start onto them)"
                ))
            },
        ));
    }
    let (s, second) = if request.second_order {
        let (s, second) = vi
            .second_derivatives(cx.at(0, t), q, &p1, &q2)
            .map_err(failed)?;
        (s, Some(second))
    } else {
        (
            vi.derivatives(cx.at(0, t), q, &p1, &q2).map_err(failed)?,
            None,
        )
    };
    // trep's λ₁ is −Δt times this integrator's force-scaled λ.
    let trep = |m: &DMatrix<f64>| Entry::Matrix(m * -dt);
    let mut step = vec![
        name("t2", Entry::Scalar(t + dt)),
        name("q2", Entry::Vector(q2.as_slice().to_vec())),
        name(
            "p2",
            Entry::Vector(dynamic.iter().map(|&i| p2[i]).collect()),
        ),
        name("lambda", Entry::Vector(vi.lambda.as_slice().to_vec())),
        name(
            "lambda1",
            Entry::Vector(vi.lambda.iter().map(|l| -dt * l).collect()),
        ),
    ];
    for of in StepOutput::ALL {
        for by in StepInput::ALL {
            let m = s.block(of, by);
            let entry = match of {
                StepOutput::Lambda => trep(m),
                _ => Entry::Matrix(m.clone()),
            };
            step.push((format!("{}_d{}", of.name(), by.name()), entry));
        }
    }
    if let Some(second) = second {
        // Each unordered pair of input blocks once (`dq1dp1`, not also `dp1dq1`), x's order.
        for of in StepOutput::ALL {
            let scale = if of == StepOutput::Lambda { -dt } else { 1.0 };
            for (k, &a) in StepInput::ALL.iter().enumerate() {
                for &b in &StepInput::ALL[k..] {
                    let rows = second.block(of, a, b).iter().map(|h| h * scale).collect();
                    step.push((
                        format!("{}_d{}d{}", of.name(), a.name(), b.name()),
                        Entry::Stack(rows),
                    ));
                }
            }
        }
    }
    Ok(step)
}

/// The request's momenta of the dynamic variables into `p1`: one finite number each.
fn given_momentum<S: System<N = Dyn>>(
    sys: &S,
    dynamic: &[usize],
    p: &[f64],
    p1: &mut Vector<Dyn>,
) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<Dyn> + Allocator<Dyn, Dyn>,
{
    let bad = |m: String| Err(SimError::InvalidInput(m));
    if p.len() != dynamic.len() {
        let noun = match dynamic.len() {
            1 => "dynamic variable",
            _ => "dynamic variables",
        };
        return bad(format!(
            "p has {} entries; the model has {} {noun}",
            p.len(),
            dynamic.len()
        ));
    }
    if let Some((c, x)) = p.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return bad(format!(
            "p[{c}] (the momentum of `{}`) is {x}: every entry must be a finite number",
            sys.variable_name(dynamic[c])
        ));
    }
    for (c, &i) in dynamic.iter().enumerate() {
        p1[i] = p[c];
    }
    Ok(())
}
