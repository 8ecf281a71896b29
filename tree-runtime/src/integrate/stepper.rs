//! [`Stepper`]: a run one step at a time, for closed-loop control — the caller reads the
//! state, computes the inputs, and steps; the integrator keeps its workspace (and the VI its
//! discrete momentum and Newton's predictor) between steps, so a run stepped here is the run
//! [`super::run_with_inputs`] takes with the same inputs.

use nalgebra::{allocator::Allocator, DefaultAllocator};

use super::watch::GapWatch;
use super::{
    check_finite, check_input_width, check_options, check_start, start_state, Method, MidpointVi,
    Rk4, SimOptions,
};
use crate::context::StepContext;
use crate::dynamics::{Dynamics, ModelMotions, NoForce};
use crate::error::SimError;
use crate::system::{System, Terms, Vector};

/// The integrator's state between steps.
enum Stepping<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// RK4, and its watch on the unilateral rows it cannot enforce.
    Rk4(Box<Rk4<S::N>>, Option<Box<GapWatch>>),
    /// The VI on `(q, p)`; `q_next` is its buffer for the next configuration.
    Vi {
        vi: Box<MidpointVi<S::N>>,
        p: Vector<S::N>,
        q_next: Vector<S::N>,
    },
}

/// A system advanced by fixed steps of `dt` under inputs given a step at a time. The
/// kinematic variables follow the model's prescriptions; the start is projected onto the
/// constraints. After a failed step the stepper refuses to go on until [`Stepper::reset`].
///
/// ```
/// use tree_runtime::integrate::{Method, Stepper, ViSettings};
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// // The pendulum of models/pendulum.toml with a torque on its joint.
/// let text = "[[frame]]\nname = \"pivot\"\nrx = \"theta\"\n\
///             [[frame]]\nname = \"bob\"\nparent = \"pivot\"\ntz = -1.0\nmass = 1.0\n\
///             [[input]]\nname = \"torque\"\nvariable = \"theta\"\n";
/// let sys = tree_runtime::TreeSystem::new(&tree_model::from_toml_str(text, None)?)?;
/// let vi = Method::Vi(ViSettings::default());
/// let mut stepper = Stepper::new(sys, vi, 0.01, &[0.5], &[0.0])?;
/// for _ in 0..1000 {
///     // PD to the hanging rest, from the state this step starts at.
///     let u = -20.0 * stepper.q()[0] - 8.0 * stepper.dq()[0];
///     stepper.step(&[u])?;
/// }
/// assert!(stepper.q()[0].abs() < 1e-6 && (stepper.t() - 10.0).abs() < 1e-12);
/// # Ok(()) }
/// ```
pub struct Stepper<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    sys: S,
    motion: ModelMotions,
    dt: f64,
    /// Steps taken since the start.
    steps: usize,
    q: Vector<S::N>,
    /// The continuous velocity at `q` (the VI's: the Legendre transform of its momentum).
    dq: Vector<S::N>,
    stepping: Stepping<S>,
    /// For [`Stepper::energy`].
    terms: Terms<S::N>,
    /// Why the last step failed, if it did.
    failed: Option<String>,
}

impl<S: System> Stepper<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// `sys` at `(q0, q̇0)` and `t = 0`, to be stepped by `method` (RK4 or the VI: rk45 chooses
    /// its own steps and is refused) at steps of `dt`.
    pub fn new(sys: S, method: Method, dt: f64, q0: &[f64], dq0: &[f64]) -> Result<Self, SimError> {
        check_options(&SimOptions::new(method, dt, dt))?;
        let stepping = match method {
            Method::Rk4 => Stepping::Rk4(
                Box::new(Rk4::new(&sys)),
                GapWatch::new(&sys, "rk4").map(Box::new),
            ),
            Method::Vi(settings) => Stepping::Vi {
                vi: Box::new(MidpointVi::new(&sys, settings)),
                p: sys.zero_vector(),
                q_next: sys.zero_vector(),
            },
            Method::Rk45(_) => {
                return Err(SimError::InvalidInput(
                    "a stepper advances by fixed steps of dt, and rk45 chooses its own: use \
                     rk4 or the VI"
                        .into(),
                ))
            }
        };
        let mut stepper = Stepper {
            motion: ModelMotions::of(&sys),
            dt,
            steps: 0,
            q: sys.zero_vector(),
            dq: sys.zero_vector(),
            terms: Terms::zeros(sys.dim()),
            stepping,
            failed: None,
            sys,
        };
        stepper.reset(q0, dq0)?;
        Ok(stepper)
    }

    /// Starts again from `(q0, q̇0)` at `t = 0` (kinematic entries from their prescription,
    /// the rest projected onto the constraints), forgetting the steps taken.
    pub fn reset(&mut self, q0: &[f64], dq0: &[f64]) -> Result<(), SimError> {
        check_start(&self.sys, q0.len(), dq0.len())?;
        self.failed = Some("the start was refused".into());
        self.q.copy_from_slice(q0);
        self.dq.copy_from_slice(dq0);
        self.steps = 0;
        let mut dynamics = Dynamics::new(&self.sys);
        start_state(
            &mut self.sys,
            &dynamics.split,
            &mut self.motion,
            &mut self.q,
            &mut self.dq,
        )?;
        if let Stepping::Vi { vi, p, .. } = &mut self.stepping {
            *p = vi.initial_momentum(&mut self.sys, &self.q, &self.dq);
            if dynamics.split.rows > 0 {
                // λ(0) from the continuous equations: the first step's impulse needs it.
                let mut qdd = self.sys.zero_vector();
                let (mut force, dt) = (NoForce, self.dt);
                let mut cx = StepContext::new(&mut self.sys, &mut force, &mut self.motion, dt);
                dynamics.acceleration(&mut cx, &self.q, &self.dq, &mut qdd)?;
                vi.start_constrained(&dynamics.constraint_terms.dh, &dynamics.lambda, dt, p);
            }
        }
        self.failed = None;
        Ok(())
    }

    /// Why the stepper stopped (a step failed; [`Stepper::reset`] starts it again), if it did.
    pub fn stopped(&self) -> Option<&str> {
        self.failed.as_deref()
    }

    /// Advances one step of `dt` with the inputs `u` held over it (one a
    /// [`System::input_count`]; empty: all zero).
    pub fn step(&mut self, u: &[f64]) -> Result<(), SimError> {
        if let Some(why) = &self.failed {
            return Err(SimError::InvalidInput(format!(
                "the stepper stopped ({why}); start it again with reset"
            )));
        }
        check_input_width(&self.sys, u.len())?;
        if let Some(k) = u.iter().position(|x| !x.is_finite()) {
            return Err(SimError::InvalidInput(format!(
                "input `{}` is {}, not a finite number",
                self.sys.input_names()[k],
                u[k]
            )));
        }
        let result = self.advance(u);
        if let Err(e) = &result {
            self.failed = Some(format!("step {} failed: {e}", self.steps + 1));
        }
        result.map_err(|e| e.under_inputs(&self.sys.input_names(), u))
    }

    /// One step from `t` to `t + dt`, the state left at its end.
    fn advance(&mut self, u: &[f64]) -> Result<(), SimError> {
        let (k, dt) = (self.steps, self.dt);
        let (t, reached) = (k as f64 * dt, (k + 1) as f64 * dt);
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut self.motion, dt);
        cx.u = u;
        match &mut self.stepping {
            Stepping::Rk4(rk, _) => rk.step(cx.at(k, t), &mut self.q, &mut self.dq)?,
            Stepping::Vi { vi, p, q_next } => {
                vi.step(cx.at(k, t), &mut self.q, p, q_next)?;
                vi.velocity_and_energy(cx.at(k + 1, reached), &self.q, p, &mut self.dq)?;
            }
        }
        check_finite(k + 1, reached, &self.q, &self.dq)?;
        if let Stepping::Rk4(_, Some(w)) = &mut self.stepping {
            w.check(&mut self.sys, &self.q, k + 1, reached)?;
        }
        self.steps = k + 1;
        Ok(())
    }

    /// The time reached, s: steps taken × `dt`.
    pub fn t(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// The configuration reached.
    pub fn q(&self) -> &Vector<S::N> {
        &self.q
    }

    /// The velocity reached (the VI's: the continuous velocity its momentum stands for).
    pub fn dq(&self) -> &Vector<S::N> {
        &self.dq
    }

    /// The VI's discrete momentum `p` reached (`None` for RK4).
    pub fn p(&self) -> Option<&Vector<S::N>> {
        match &self.stepping {
            Stepping::Vi { p, .. } => Some(p),
            Stepping::Rk4(..) => None,
        }
    }

    /// The step, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Steps taken since the start.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The energy `E = ½ q̇ᵀM q̇ + V(q)` at the state reached.
    pub fn energy(&mut self) -> f64 {
        self.sys.energy(&self.q, &self.dq, &mut self.terms)
    }

    /// The VI's Newton iterations on the last step (0 for RK4).
    pub fn newton_iterations(&self) -> usize {
        match &self.stepping {
            Stepping::Vi { vi, .. } => vi.iterations,
            Stepping::Rk4(..) => 0,
        }
    }

    /// The system stepped.
    pub fn system(&self) -> &S {
        &self.sys
    }
}

impl<S: System> std::fmt::Debug for Stepper<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Stepper")
            .field("t", &self.t())
            .field("q", &self.q.as_slice())
            .field("dq", &self.dq.as_slice())
            .finish_non_exhaustive()
    }
}
