//! Everything about one state at once — the Lagrangian and its derivatives, the energy, the
//! accelerations and multipliers of the continuous dynamics under given inputs, the
//! constraints, every frame's pose — checked finite: what `tree-mech eval` prints and the
//! Python package's `Model.evaluate` returns.

use nalgebra::{allocator::Allocator, DVector, DefaultAllocator};

use crate::context::StepContext;
use crate::dynamics::{Dynamics, ModelMotions, NoForce, Prescription};
use crate::error::SimError;
use crate::system::{ConstraintTerms, Order, System, Terms, Vector};
use tree_kernel::se3::Pose;

/// One state's evaluation.
#[derive(Clone, Debug)]
pub struct Evaluation<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// `L` and every first and second derivative.
    pub terms: Terms<N>,
    /// `E = T + V`.
    pub energy: f64,
    /// `q̈` of every variable (kinematic ones: their prescription's).
    pub qdd: Vector<N>,
    /// The constraint multipliers `λ`.
    pub lambda: DVector<f64>,
    /// `h`, `Dh`, ….
    pub constraints: ConstraintTerms,
    /// Every frame's pose in the world.
    pub poses: Vec<Pose>,
}

/// Evaluates `sys` at `(t, q, q̇)` with inputs `u` (empty: zero), the kinematic variables'
/// accelerations from the model's prescription. Fails, naming it, when the dynamics have no
/// solution there or any output is not finite.
pub fn evaluate_state<S: System>(
    sys: &mut S,
    t: f64,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    u: &[f64],
) -> Result<Evaluation<S::N>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut motion = ModelMotions::of(sys);
    evaluate_state_with(sys, t, q, dq, u, &mut motion)
}

/// [`evaluate_state`] with the kinematic variables' `[q, q̇, q̈]` from `motion` (trep's way:
/// a closure returning the caller's own values).
pub fn evaluate_state_with<S: System, P: Prescription>(
    sys: &mut S,
    t: f64,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    u: &[f64],
    motion: &mut P,
) -> Result<Evaluation<S::N>, SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    let (qdd, lambda) = continuous_dynamics(sys, t, q, dq, u, motion)?;
    let terms = sys.evaluate(q, dq, Order::Full);
    let mut constraints = ConstraintTerms::zeros(sys.constraint_count(), n);
    sys.constraints(q, dq, Order::First, &mut constraints);
    let energy = terms.energy(dq);
    // q̈ and λ were checked where they were solved for (the acceleration fails on either).
    let outputs: [(&str, &[f64]); 9] = [
        ("L", std::slice::from_ref(&terms.l)),
        ("the energy", std::slice::from_ref(&energy)),
        ("dL_dq", terms.dl_dq.as_slice()),
        ("dL_ddq", terms.dl_ddq.as_slice()),
        ("M", terms.mass.as_slice()),
        ("d2L_ddqdq", terms.d2l_ddq_dq.as_slice()),
        ("d2L_dqdq", terms.d2l_dq_dq.as_slice()),
        ("h", constraints.h.as_slice()),
        ("dh_dq", constraints.dh.as_slice()),
    ];
    if let Some((name, _)) = outputs
        .iter()
        .find(|(_, v)| v.iter().any(|x| !x.is_finite()))
    {
        return Err(SimError::InvalidInput(format!(
            "at this state, {name} is not finite (it overflowed a floating-point number)"
        )));
    }
    let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
    sys.poses(q, &mut poses);
    Ok(Evaluation {
        terms,
        energy,
        qdd,
        lambda,
        constraints,
        poses,
    })
}

/// The continuous dynamics alone at `(t, q, q̇)` under inputs `u` (empty: zero), the kinematic
/// variables' `[q, q̇, q̈]` from `motion`: `q̈` of every variable (kinematic ones their
/// prescription's) and the multipliers `λ` (eq. (14)), by the articulated-body algorithm
/// where the model has no constraints — what [`evaluate_state_with`] reports beside the rest,
/// and the Python package's `Model.forward_dynamics` alone. Fails, naming it, when the
/// state does not fit, the dynamics have no solution there, or `q̈` is not finite.
pub fn continuous_dynamics<S: System, P: Prescription>(
    sys: &mut S,
    t: f64,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    u: &[f64],
    motion: &mut P,
) -> Result<(Vector<S::N>, DVector<f64>), SimError>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    if q.len() != n || dq.len() != n || !(u.is_empty() || u.len() == sys.input_count()) {
        return Err(SimError::InvalidInput(format!(
            "the state has {} positions, {} velocities and {} inputs; the system has {n} variables and {} inputs",
            q.len(),
            dq.len(),
            u.len(),
            sys.input_count()
        )));
    }
    if !t.is_finite() {
        return Err(SimError::InvalidInput(format!(
            "the time {t} is not finite"
        )));
    }
    let mut qdd = sys.zero_vector();
    let mut dynamics = Dynamics::new(sys);
    let mut force = NoForce;
    let mut cx = StepContext::new(sys, &mut force, motion, 0.0);
    cx.u = u;
    // A q̈ or λ that is not finite is the acceleration's own error.
    dynamics
        .acceleration(cx.at(0, t), q, dq, &mut qdd)
        .map_err(|e| {
            SimError::InvalidInput(e.under_inputs(&sys.input_names(), u).at_this_state())
        })?;
    Ok((qdd, dynamics.lambda.clone()))
}
