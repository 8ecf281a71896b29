//! The midpoint VI as a discrete control system: the state `x = (q_d, p_d)` of the dynamic
//! variables (the VI's own state, docs/derivations.md §9), the controls the model's inputs
//! (held over a step), the kinematic variables on their prescription; one step and its
//! Jacobians `A = ∂x₂/∂x₁`, `B = ∂x₂/∂u₁` from [`MidpointVi::derivatives_into`], and for DDP
//! the step's second derivatives contracted with a covector on `x₂`.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use crate::context::StepContext;
use crate::dynamics::{ModelMotions, NoForce, Prescription};
use crate::error::SimError;
use crate::integrate::{MidpointVi, StepCovector, StepDerivatives, ViSettings};
use crate::system::{Order, System, Terms, Vector};

/// One VI step as `x_{k+1} = f(x_k, u_k)`, with its buffers (nothing allocated per step).
pub struct ViDynamics<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// The system.
    pub sys: S,
    /// The integrator (its settings: α, forcing, tolerances).
    pub vi: MidpointVi<S::N>,
    motion: ModelMotions,
    /// The step length.
    pub dt: f64,
    /// The time of knot 0.
    pub t0: f64,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    q1: Vector<S::N>,
    p1: Vector<S::N>,
    q2: Vector<S::N>,
    p2: Vector<S::N>,
    next: Vector<S::N>,
    first: StepDerivatives,
    hessian: DMatrix<f64>,
    covector: StepCovector,
}

/// `q` of state `x` at time `t`: the dynamic part from `x`, the kinematic part on the
/// prescription.
fn place<N: nalgebra::Dim>(
    dynamic: &[usize],
    kinematic: &[usize],
    motion: &mut ModelMotions,
    t: f64,
    x: &[f64],
    q: &mut Vector<N>,
) where
    DefaultAllocator: Allocator<N>,
{
    for (r, &i) in dynamic.iter().enumerate() {
        q[i] = x[r];
    }
    for &i in kinematic {
        q[i] = motion.kinematic(i, t)[0];
    }
}

impl<S: System> ViDynamics<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// The VI of `sys` at step `dt` from time `t0`, kinematic variables on the model's
    /// prescription.
    pub fn new(sys: S, settings: ViSettings, dt: f64, t0: f64) -> Self {
        let vi = MidpointVi::new(&sys, settings);
        let n = sys.dof();
        let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
        let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
        let z = sys.zero_vector();
        let nd = dynamic.len();
        ViDynamics {
            motion: ModelMotions::of(&sys),
            covector: StepCovector {
                q2: DVector::zeros(nd),
                p2: DVector::zeros(nd),
                lambda: DVector::zeros(sys.constraint_count()),
            },
            sys,
            vi,
            dt,
            t0,
            dynamic,
            kinematic,
            q1: z.clone(),
            p1: z.clone(),
            q2: z.clone(),
            p2: z.clone(),
            next: z,
            first: StepDerivatives::empty(),
            hessian: DMatrix::zeros(0, 0),
        }
    }

    /// States: `2 n_d`.
    pub fn states(&self) -> usize {
        2 * self.dynamic.len()
    }

    /// Controls: the model's inputs.
    pub fn controls(&self) -> usize {
        self.sys.input_count()
    }

    /// The state `(q_d, p_d)` of `(q, q̇)` (`p = ∂L/∂q̇`).
    pub fn state_of(&mut self, q: &Vector<S::N>, dq: &Vector<S::N>) -> DVector<f64> {
        let p = self.vi.initial_momentum(&mut self.sys, q, dq);
        let nd = self.dynamic.len();
        DVector::from_fn(2 * nd, |r, _| {
            if r < nd {
                q[self.dynamic[r]]
            } else {
                p[self.dynamic[r - nd]]
            }
        })
    }

    /// The configuration at knot `k` of state `x`: its dynamic part, the kinematic part on
    /// the prescription at `t0 + k Δt`.
    pub fn configuration(&mut self, k: usize, x: &[f64], q: &mut Vector<S::N>) {
        let t = self.t0 + k as f64 * self.dt;
        place(&self.dynamic, &self.kinematic, &mut self.motion, t, x, q);
    }

    /// The inputs that hold configuration `q` at rest against gravity and springs (the
    /// potential's force on each input's variable: `u = −∂L/∂q` at q̇ = 0 there).
    pub fn gravity_compensation(&mut self, q: &Vector<S::N>) -> DVector<f64> {
        let mut terms = Terms::zeros(self.sys.dim());
        let zero = self.sys.zero_vector();
        self.sys.lagrangian(q, &zero, Order::First, &mut terms);
        DVector::from_fn(self.controls(), |k, _| {
            -terms.dl_dq[self.sys.input_variable(k)]
        })
    }

    /// `x₂ = f(x₁, u)` from knot `k`; with `jacobians`, also `A`, `B`.
    pub fn step(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        x2: &mut [f64],
        jacobians: Option<(&mut DMatrix<f64>, &mut DMatrix<f64>)>,
    ) -> Result<(), SimError> {
        let nd = self.dynamic.len();
        let t = self.t0 + k as f64 * self.dt;
        place(
            &self.dynamic,
            &self.kinematic,
            &mut self.motion,
            t,
            x,
            &mut self.q1,
        );
        self.p1.fill(0.0);
        for (r, &i) in self.dynamic.iter().enumerate() {
            self.p1[i] = x[nd + r];
        }
        self.q2.copy_from(&self.q1);
        self.p2.copy_from(&self.p1);
        self.vi.last_velocity.fill(0.0);
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut self.motion, self.dt);
        cx.u = u;
        cx.at(k, t);
        self.vi
            .step(&mut cx, &mut self.q2, &mut self.p2, &mut self.next)?;
        for (r, &i) in self.dynamic.iter().enumerate() {
            x2[r] = self.q2[i];
            x2[nd + r] = self.p2[i];
        }
        if let Some((a, b)) = jacobians {
            self.vi
                .derivatives_into(&mut cx, &self.q1, &self.p1, &self.q2, &mut self.first)?;
            let d = &self.first;
            for r in 0..nd {
                for (c, &j) in self.dynamic.iter().enumerate() {
                    a[(r, c)] = d.q2_dq1[(r, j)];
                    a[(nd + r, c)] = d.p2_dq1[(r, j)];
                    a[(r, nd + c)] = d.q2_dp1[(r, c)];
                    a[(nd + r, nd + c)] = d.p2_dp1[(r, c)];
                }
                for c in 0..u.len() {
                    b[(r, c)] = d.q2_du1[(r, c)];
                    b[(nd + r, c)] = d.p2_du1[(r, c)];
                }
            }
        }
        Ok(())
    }

    /// After [`Self::step`] from knot `k` with `(x, u)`: the step's second derivatives
    /// contracted with `v` on `x₂` (DDP's `V_x'·f_xx` terms), into `hxx` (states²), `huu`
    /// (controls²) and `hux` (controls × states).
    pub fn contracted(
        &mut self,
        k: usize,
        u: &[f64],
        v: &[f64],
        hxx: &mut DMatrix<f64>,
        huu: &mut DMatrix<f64>,
        hux: &mut DMatrix<f64>,
    ) -> Result<(), SimError> {
        let nd = self.dynamic.len();
        let n = self.sys.dof();
        for r in 0..nd {
            self.covector.q2[r] = v[r];
            self.covector.p2[r] = v[nd + r];
        }
        let t = self.t0 + k as f64 * self.dt;
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut self.motion, self.dt);
        cx.u = u;
        cx.at(k, t);
        self.vi.contracted_second_derivatives(
            &mut cx,
            &self.q1,
            &self.p1,
            &self.q2,
            &self.covector,
            &mut self.hessian,
        )?;
        // x's columns in the step's (q₁, p₁, u₁, k₂): dynamic q₁, then p₁; u after both.
        let state = |c: usize| if c < nd { self.dynamic[c] } else { n + c - nd };
        let nu = u.len();
        for r in 0..2 * nd {
            for c in 0..2 * nd {
                hxx[(r, c)] = self.hessian[(state(r), state(c))];
            }
        }
        for a in 0..nu {
            for b in 0..nu {
                huu[(a, b)] = self.hessian[(n + nd + a, n + nd + b)];
            }
            for c in 0..2 * nd {
                hux[(a, c)] = self.hessian[(n + nd + a, state(c))];
            }
        }
        Ok(())
    }
}
