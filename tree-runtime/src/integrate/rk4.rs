//! The classical fixed-step fourth-order Runge–Kutta method on the dynamic variables'
//! `(q, q̇)`; kinematic variables take their prescription at every stage.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::context::StepContext;
use crate::dynamics::{finite, prescribe, Dynamics, GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::system::{System, Vector};

/// The stages' times, as fractions of the step.
const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
/// The stages' weights (over 6).
const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];

/// RK4 workspace (nothing allocated per step).
#[derive(Clone, Debug)]
pub struct Rk4<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The accelerations' solver (its Baumgarte setting applies).
    pub dynamics: Dynamics<N>,
    kq: [Vector<N>; 4],
    kv: [Vector<N>; 4],
    q_stage: Vector<N>,
    v_stage: Vector<N>,
    /// The energy the model's own forces (damping, dampers) took out over the last step:
    /// `−∫ F·q̇ dt` by the step's own quadrature (RK4's weights on its stages' power).
    pub dissipated: f64,
}

impl<N: Dim> Rk4<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// An integrator with buffers sized for `sys`.
    pub fn new<S: System<N = N>>(sys: &S) -> Self {
        let n = sys.dim();
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        Rk4 {
            dynamics: Dynamics::new(sys),
            kq: [z(), z(), z(), z()],
            kv: [z(), z(), z(), z()],
            q_stage: z(),
            v_stage: z(),
            dissipated: 0.0,
        }
    }

    /// Advances `(q, q̇)` from `cx.t` by `cx.dt`.
    pub fn step<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        q: &mut Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (t, dt) = (cx.t, cx.dt);
        self.dissipated = 0.0;
        for s in 0..4 {
            let ts = self.stage_state(s, &mut *cx.motion, t, dt, q, dq);
            // The stage's acceleration, at the stage's time.
            cx.t = ts;
            let stage =
                self.dynamics
                    .acceleration(cx, &self.q_stage, &self.v_stage, &mut self.kv[s]);
            cx.t = t;
            stage?;
            self.add_stage_power(s, dt);
        }
        self.combine(&mut *cx.motion, t, dt, q, dq);
        Ok(())
    }

    /// Stage `s`'s state from the step's start `(q, q̇)` at `t`: `(q, q̇) + C_s Δt k_{s−1}`
    /// into the stage's buffers ([`Self::stage_parts`]), the kinematic variables prescribed,
    /// and its velocity kept as the stage's `k_q`. Returns the stage's time `t + C_s Δt`.
    pub(crate) fn stage_state(
        &mut self,
        s: usize,
        motion: &mut impl Prescription,
        t: f64,
        dt: f64,
        q: &Vector<N>,
        dq: &Vector<N>,
    ) -> f64 {
        self.q_stage.copy_from(q);
        self.v_stage.copy_from(dq);
        if s > 0 {
            self.q_stage.axpy(C[s] * dt, &self.kq[s - 1], 1.0);
            self.v_stage.axpy(C[s] * dt, &self.kv[s - 1], 1.0);
        }
        let ts = t + C[s] * dt;
        let kinematic = &self.dynamics.split.kinematic;
        prescribe(
            kinematic,
            motion,
            ts,
            &mut self.q_stage,
            &mut self.v_stage,
            None,
        );
        self.kq[s].copy_from(&self.v_stage);
        ts
    }

    /// Stage `s`'s inputs to the articulated-body algorithm at `cx` (its time the stage's;
    /// [`Dynamics::articulated_inputs`]): `false` when that algorithm does not give `q̈`.
    pub(crate) fn stage_inputs<S, F, P>(&mut self, s: usize, cx: &mut StepContext<S, F, P>) -> bool
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (q, dq) = (&self.q_stage, &self.v_stage);
        self.dynamics.articulated_inputs(cx, q, dq, &mut self.kv[s])
    }

    /// Stage `s`'s `q`, `q̇`, `q̈` (its kinematic entries prescribed) and the generalized
    /// force from outside the model, as [`Self::stage_inputs`] left them.
    pub(crate) fn stage_parts(&self, s: usize) -> [&Vector<N>; 4] {
        let force = self.dynamics.external_force();
        [&self.q_stage, &self.v_stage, &self.kv[s], force]
    }

    /// Ends stage `s` (step `k`, its time `ts`) with its acceleration and the model's own
    /// forces written by `fill(q̈, F)`: `q̈` checked finite, the forces' power added to
    /// [`Self::dissipated`].
    pub(crate) fn end_stage(
        &mut self,
        (s, k, ts, dt): (usize, usize, f64, f64),
        fill: impl FnOnce(&mut Vector<N>, &mut Vector<N>),
    ) -> Result<(), SimError> {
        fill(&mut self.kv[s], &mut self.dynamics.terms.force);
        finite(&self.kv[s], &self.dynamics.lambda, k, ts)?;
        self.add_stage_power(s, dt);
        Ok(())
    }

    /// Adds stage `s`'s share of the dissipated energy: RK4's weight on the power of the
    /// model's own forces (left in `dynamics.terms.force` by the stage's acceleration).
    fn add_stage_power(&mut self, s: usize, dt: f64) {
        let power = self.dynamics.terms.force.dot(&self.v_stage);
        self.dissipated -= W[s] * dt / 6.0 * power;
    }

    /// The step's end: `(q, q̇) += Δt/6 Σ W_s k_s`, the kinematic variables prescribed at
    /// `t + Δt`.
    pub(crate) fn combine(
        &mut self,
        motion: &mut impl Prescription,
        t: f64,
        dt: f64,
        q: &mut Vector<N>,
        dq: &mut Vector<N>,
    ) {
        for (k, w) in W.into_iter().enumerate() {
            q.axpy(w * dt / 6.0, &self.kq[k], 1.0);
            dq.axpy(w * dt / 6.0, &self.kv[k], 1.0);
        }
        prescribe(&self.dynamics.split.kinematic, motion, t + dt, q, dq, None);
    }
}
