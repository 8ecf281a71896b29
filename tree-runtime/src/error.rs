//! Run-time errors: each says which step, at what time, and why.

use std::fmt;

/// A simulation or evaluation failure.
#[derive(Clone, PartialEq)]
pub enum SimError {
    /// `M(q)` is not positive definite (Cholesky failed at this variable's pivot).
    SingularMassMatrix {
        /// The step at which it happened (0: the initial state).
        step: usize,
        /// The simulated time then.
        t: f64,
        /// The variable whose pivot failed.
        variable: String,
        /// The pivot's value.
        pivot: f64,
    },
    /// The constraints' Jacobian has lost rank (redundant or degenerate constraints): the
    /// Schur complement `Dh M⁻¹ Dhᵀ` is singular at this constraint's pivot.
    SingularConstraints {
        /// The step at which it happened.
        step: usize,
        /// The simulated time then.
        t: f64,
        /// The constraint equation whose pivot failed.
        constraint: String,
    },
    /// The initial configuration cannot be brought onto `h(q) = 0` by moving the dynamic
    /// variables.
    Unsatisfiable {
        /// The constraint equation left violated.
        constraint: String,
        /// Its `|h|` after the projection gave up.
        violation: f64,
    },
    /// What was asked would need more memory than the machine has free (checked before it is
    /// taken: [`crate::memory::check`]).
    OutOfMemory {
        /// What needs it, as a phrase.
        what: String,
        /// The bytes it needs.
        bytes: f64,
        /// The bytes free.
        available: f64,
        /// How to ask for less.
        advice: String,
    },
    /// The run would take more steps than can be stored or finished.
    TooManySteps {
        /// The steps the run would take.
        steps: f64,
    },
    /// The VI's Newton iteration matrix (eq. (26)) is singular.
    SingularJacobian {
        /// The step at which it happened.
        step: usize,
        /// The simulated time then.
        t: f64,
        /// The unknown whose pivot vanished, as the message names it: ``variable `x` `` or
        /// ``the λ of constraint `c` ``.
        variable: String,
    },
    /// Newton did not reach the tolerance on the discrete Euler–Lagrange residual.
    NewtonFailed {
        /// The step that failed.
        step: usize,
        /// The simulated time at its start.
        t: f64,
        /// The iterations tried.
        iterations: usize,
        /// The largest residual row relative to its momentum scale at the end.
        residual: f64,
        /// The largest `|h(q₂)|` at the end.
        violation: f64,
        /// Where the mass matrix at the step's start is nearly singular, the variable of its
        /// weakest pivot and `d/M_ii` there (`linalg::weakest_pivot`): the cause, not the step.
        singular: Option<(String, f64)>,
    },
    /// The contact step's interior point did not converge (docs/derivations.md §13).
    ContactFailed {
        /// The step that failed.
        step: usize,
        /// The simulated time at its start.
        t: f64,
        /// The iterations tried.
        iterations: usize,
        /// The unilateral element furthest from converged (a contact, limit or string).
        contact: String,
        /// Its gap at the last iterate.
        gap: f64,
        /// The dynamic rows' relative residual at the end.
        residual: f64,
        /// The largest complementarity (relative) at the end.
        complementarity: f64,
        /// Where the mass matrix at the step's start is nearly singular (as for
        /// [`SimError::NewtonFailed`]): a limit holding a joint at a gimbal lock.
        singular: Option<(String, f64)>,
    },
    /// A smooth integrator (RK4, rk45) closed a unilateral row it cannot enforce.
    Unenforced {
        /// The step that closed it.
        step: usize,
        /// The simulated time at its end.
        t: f64,
        /// The limit, contact or string closed.
        element: String,
        /// Its gap there (negative).
        gap: f64,
        /// The integrator's name.
        integrator: &'static str,
    },
    /// A VI step turned a joint by more than a quarter turn:
    /// the step is too long for the motion.
    StepTooCoarse {
        /// The step that failed.
        step: usize,
        /// The simulated time at its start.
        t: f64,
        /// The length of the (sub)step tried.
        dt: f64,
        /// The angle that turned too far.
        variable: String,
        /// How far it turned, rad.
        turn: f64,
    },
    /// A state or derivative stopped being finite.
    NonFinite {
        /// The step at which it happened.
        step: usize,
        /// The simulated time then.
        t: f64,
        /// What was not finite.
        what: String,
    },
    /// The adaptive step size fell below what floating point can resolve.
    StepSizeTooSmall {
        /// The step at which it happened.
        step: usize,
        /// The simulated time then.
        t: f64,
        /// The step size reached.
        dt: f64,
    },
    /// An adaptive run would take more steps than its budget
    /// ([`crate::integrate::SimOptions::max_steps`]): a stiff model.
    StepBudget {
        /// The steps taken.
        step: usize,
        /// The simulated time reached.
        t: f64,
        /// The step size reached.
        dt: f64,
        /// The steps the run would need at that step size.
        needed: f64,
        /// The budget.
        max_steps: usize,
    },
    /// Bad arguments (sizes, step, tolerances).
    InvalidInput(String),
    /// The model uses something this runtime does not do yet.
    Unsupported(String),
}

impl SimError {
    /// The step the error happened at, when it names one (0: the initial state).
    pub fn step(&self) -> Option<usize> {
        self.when().map(|(step, _)| step)
    }

    /// The step and time the error happened at, when it names them.
    pub fn when(&self) -> Option<(usize, f64)> {
        match self {
            SimError::SingularMassMatrix { step, t, .. }
            | SimError::SingularConstraints { step, t, .. }
            | SimError::SingularJacobian { step, t, .. }
            | SimError::NewtonFailed { step, t, .. }
            | SimError::ContactFailed { step, t, .. }
            | SimError::Unenforced { step, t, .. }
            | SimError::StepTooCoarse { step, t, .. }
            | SimError::NonFinite { step, t, .. }
            | SimError::StepSizeTooSmall { step, t, .. }
            | SimError::StepBudget { step, t, .. } => Some((*step, *t)),
            SimError::Unsatisfiable { .. }
            | SimError::TooManySteps { .. }
            | SimError::OutOfMemory { .. }
            | SimError::InvalidInput(_)
            | SimError::Unsupported(_) => None,
        }
    }

    /// A state or residual that stopped being finite while inputs `u` (named `names`) were in
    /// force names them: an input too large for the model (a push of 1e308 N) overflows the
    /// first step, and the message should point at it rather than at the residual alone.
    pub(crate) fn under_inputs(self, names: &[String], u: &[f64]) -> SimError {
        match self {
            SimError::NonFinite { step, t, what } if u.iter().any(|&x| x != 0.0) => {
                let list = names
                    .iter()
                    .zip(u)
                    .map(|(name, &x)| format!("{name} = {}", tree_model::Given(x)))
                    .collect::<Vec<_>>()
                    .join(", ");
                SimError::NonFinite {
                    step,
                    t,
                    what: format!("{what}, under the inputs {list},"),
                }
            }
            e => e,
        }
    }

    /// The message as an evaluation at one given state reports it: without the step a run
    /// would name (`at this state, the mass matrix is not positive definite …`).
    pub(crate) fn at_this_state(&self) -> String {
        format!("at this state, {}", Detail(self))
    }
}

/// What went wrong, without the step it went wrong at.
struct Detail<'a>(&'a SimError);

impl fmt::Display for Detail<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            SimError::SingularMassMatrix { variable, pivot, .. } => write!(
                f,
                "mass matrix is not positive definite (pivot {pivot:e} at variable `{variable}`): a variable that moves no mass, or a singular configuration where two variables move alike (rotations whose axes line up: a gimbal lock)"
            ),
            SimError::SingularConstraints { constraint, .. } => write!(
                f,
                "the constraint Jacobian has lost rank at constraint `{constraint}` (redundant or degenerate constraints)"
            ),
            SimError::Unsatisfiable { constraint, violation } => write!(
                f,
                "cannot satisfy constraint `{constraint}` at the start by moving the dynamic variables (it stays violated by {violation:e})"
            ),
            SimError::OutOfMemory {
                what,
                bytes,
                available,
                advice,
            } => write!(
                f,
                "{what} would need about {} GB of memory, more than the {} GB free: {advice}",
                tree_model::Rounded(bytes / 1e9, 3),
                tree_model::Rounded(available / 1e9, 3)
            ),
            SimError::TooManySteps { steps } => write!(
                f,
                "the run needs {steps:.2e} steps, more than the limit of 1e9: lengthen --dt or shorten --duration"
            ),
            SimError::SingularJacobian { variable, .. } => write!(
                f,
                "variational integrator Newton matrix is singular (at {variable})"
            ),
            SimError::NewtonFailed { iterations, residual, violation, singular, .. } => {
                write!(
                    f,
                    "Newton did not converge in {iterations} iterations (relative residual {residual:e}, constraint violation {violation:e})"
                )?;
                match singular {
                    Some((variable, ratio)) => write!(
                        f,
                        ": the mass matrix is nearly singular here (its pivot at `{variable}` is {ratio:.1e} of its diagonal entry), a configuration where two variables move alike — rotations whose axes line up, as a floating base's root_pitch at ±90° (a gimbal lock of its Euler angles); a shorter step will not pass it: start away from it"
                    ),
                    None => f.write_str(": the step may be too long for the motion here; lower --dt"),
                }
            }
            SimError::ContactFailed { iterations, contact, gap, residual, complementarity, singular, .. } => {
                write!(
                    f,
                    "the contact step did not converge in {iterations} iterations: `{contact}` is furthest (gap {gap:e}, relative residual {residual:e}, complementarity {complementarity:e})"
                )?;
                match singular {
                    Some((variable, ratio)) => write!(
                        f,
                        "; the mass matrix is nearly singular here (its pivot at `{variable}` is {ratio:.1e} of its diagonal entry), two variables moving alike — rotations whose axes line up (a gimbal lock), which a limit or contact may hold it at; a shorter step will not pass it"
                    ),
                    None => f.write_str("; the step may be too long for the impact, lower --dt"),
                }
            }
            SimError::Unenforced { element, gap, integrator, .. } => write!(
                f,
                "`{element}` closed (gap {gap:.3e}): {integrator} integrates the smooth equations of motion and cannot enforce a limit, a contact or a taut string, only the variational integrator does; use the VI (--integrator vi), or drop the element (--no-limits or enforce_limits = false for a limit; no [ground], [[contact]] or slack string)"
            ),
            SimError::StepTooCoarse { dt, variable, turn, .. } => write!(
                f,
                "`{variable}` turned {turn:.3e} rad in a step of {dt:e} s, more than a quarter turn: the motion is too fast for this step; lower --dt"
            ),
            SimError::NonFinite { step, what, .. } => {
                write!(f, "{what} is not finite")?;
                // Finite at the start and not after: the run diverged (the state ran away
                // within a step: on a stiff model, strong damping on light links, an explicit
                // step longer than its fastest time constant grows without bound).
                if *step > 0 {
                    f.write_str(
                        " (the run diverged, the state running away: lower --dt, or take \
                         rk45, which chooses a step the motion allows, or the VI)",
                    )?;
                } else {
                    f.write_str(
                        " at the start: the start state, or the model's masses, inertias or \
                         lengths, overflow double precision (the largest number is 1.8e308)",
                    )?;
                }
                Ok(())
            }
            SimError::StepSizeTooSmall { dt, .. } => {
                write!(f, "adaptive step size {dt:e} is too small")
            }
            SimError::StepBudget { dt, needed, max_steps, .. } => write!(
                f,
                "the adaptive step size fell to {dt:.3e} s, so the run would need about {needed:.2e} steps, more than its budget of {max_steps}: the model is stiff here; use --integrator vi (or rk4 with a small --dt), or raise --max-steps"
            ),
            SimError::InvalidInput(m) | SimError::Unsupported(m) => f.write_str(m),
        }
    }
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some((step, t)) = self.when() {
            write!(f, "step {step} (t = {t}): ", t = Seconds(t))?;
        }
        Detail(self).fmt(f)
    }
}

/// A time in seconds as the messages and summaries print it: to 12 significant digits,
/// trailing zeros dropped (a subdivided step's `0.5624999999999999` reads `0.5625`); below a
/// microsecond and from 10⁹ s on, in exponent form (`3e-7`, `1e300`, never three hundred
/// digits). [`tree_model::Rounded`], named for what it prints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seconds(pub f64);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        tree_model::Rounded(self.0, 12).fmt(f)
    }
}

/// The message itself, so `?` out of a user's `main` (which prints with `{:?}`) shows the
/// sentence.
impl fmt::Debug for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl std::error::Error for SimError {}

#[cfg(test)]
mod tests {
    use super::Seconds;

    #[test]
    fn times_print_as_rounded_numbers() {
        // tree_model::Rounded's rules (tested there), named for a time.
        assert_eq!(Seconds(0.5624999999999999).to_string(), "0.5625");
        assert_eq!(Seconds(1e300).to_string(), "1e300");
    }
}
