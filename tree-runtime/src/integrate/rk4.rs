//! The classical fixed-step fourth-order Runge–Kutta method on `(q, q̇)`.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::dynamics::{Dynamics, GeneralizedForce};
use crate::error::SimError;
use crate::system::{System, Vector};

/// RK4 workspace (nothing allocated per step).
#[derive(Clone, Debug)]
pub struct Rk4<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub dynamics: Dynamics<N>,
    kq: [Vector<N>; 4],
    kv: [Vector<N>; 4],
    q_stage: Vector<N>,
    v_stage: Vector<N>,
}

impl<N: Dim> Rk4<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub fn new(n: N) -> Self {
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        Rk4 {
            dynamics: Dynamics::new(n),
            kq: [z(), z(), z(), z()],
            kv: [z(), z(), z(), z()],
            q_stage: z(),
            v_stage: z(),
        }
    }

    /// Advances `(q, q̇)` from `t` by `dt`.
    pub fn step<S, F>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        step: usize,
        t: f64,
        dt: f64,
        q: &mut Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
        for s in 0..4 {
            self.q_stage.copy_from(q);
            self.v_stage.copy_from(dq);
            if s > 0 {
                self.q_stage.axpy(C[s] * dt, &self.kq[s - 1], 1.0);
                self.v_stage.axpy(C[s] * dt, &self.kv[s - 1], 1.0);
            }
            self.kq[s].copy_from(&self.v_stage);
            self.dynamics.acceleration(
                sys,
                force,
                step,
                t + C[s] * dt,
                &self.q_stage,
                &self.v_stage,
                &mut self.kv[s],
            )?;
        }
        for (k, w) in [1.0, 2.0, 2.0, 1.0].into_iter().enumerate() {
            q.axpy(w * dt / 6.0, &self.kq[k], 1.0);
            dq.axpy(w * dt / 6.0, &self.kv[k], 1.0);
        }
        Ok(())
    }
}
