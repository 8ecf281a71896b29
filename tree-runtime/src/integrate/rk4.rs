//! The classical fixed-step fourth-order Runge–Kutta method on the dynamic variables'
//! `(q, q̇)`; kinematic variables take their prescription at every stage.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::context::StepContext;
use crate::dynamics::{prescribe, Dynamics, GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::system::{System, Vector};

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
        const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
        const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];
        self.dissipated = 0.0;
        for s in 0..4 {
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
                cx.motion,
                ts,
                &mut self.q_stage,
                &mut self.v_stage,
                None,
            );
            self.kq[s].copy_from(&self.v_stage);
            // The stage's acceleration, at the stage's time.
            cx.t = ts;
            let stage =
                self.dynamics
                    .acceleration(cx, &self.q_stage, &self.v_stage, &mut self.kv[s]);
            cx.t = t;
            stage?;
            let power = self.dynamics.terms.force.dot(&self.v_stage);
            self.dissipated -= W[s] * dt / 6.0 * power;
        }
        for (k, w) in W.into_iter().enumerate() {
            q.axpy(w * dt / 6.0, &self.kq[k], 1.0);
            dq.axpy(w * dt / 6.0, &self.kv[k], 1.0);
        }
        prescribe(
            &self.dynamics.split.kinematic,
            cx.motion,
            t + dt,
            q,
            dq,
            None,
        );
        Ok(())
    }
}
