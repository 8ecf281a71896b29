//! Continuous Euler–Lagrange dynamics (paper eq. (14)):
//! `M(q) q̈ = u(t, q, q̇) + ∂L/∂q − (∂²L/∂q̇∂q) q̇`, solved by Cholesky.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::error::SimError;
use crate::linalg::cholesky_solve;
use crate::system::{Matrix, Order, System, Terms, Vector};

/// An external generalized force `u(t, q, q̇)` (joint torques, actuators, …), added to the
/// model's damping.
pub trait GeneralizedForce<N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// Adds `u(t, q, q̇)` into `u`.
    fn add_force(&mut self, t: f64, q: &Vector<N>, dq: &Vector<N>, u: &mut Vector<N>);
}

/// No external force.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoForce;

impl<N: Dim> GeneralizedForce<N> for NoForce
where
    DefaultAllocator: Allocator<N>,
{
    fn add_force(&mut self, _: f64, _: &Vector<N>, _: &Vector<N>, _: &mut Vector<N>) {}
}

/// Any closure `|t, q, q̇, u| …` that adds its force into `u`.
impl<N: Dim, F> GeneralizedForce<N> for F
where
    DefaultAllocator: Allocator<N>,
    F: FnMut(f64, &Vector<N>, &Vector<N>, &mut Vector<N>),
{
    fn add_force(&mut self, t: f64, q: &Vector<N>, dq: &Vector<N>, u: &mut Vector<N>) {
        self(t, q, dq, u)
    }
}

/// Fills `u` with the total generalized force: damping `−c_i q̇_i` plus the external force.
pub fn total_force<S: System, F: GeneralizedForce<S::N>>(
    sys: &S,
    force: &mut F,
    t: f64,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    u: &mut Vector<S::N>,
) where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    for i in 0..u.len() {
        u[i] = -sys.damping(i) * dq[i];
    }
    force.add_force(t, q, dq, u);
}

/// Workspace for evaluating accelerations without allocating.
#[derive(Clone, Debug)]
pub struct Dynamics<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub terms: Terms<N>,
    factor: Matrix<N>,
}

impl<N: Dim> Dynamics<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    pub fn new(n: N) -> Self {
        Dynamics {
            terms: Terms::zeros(n),
            factor: Matrix::zeros_generic(n, n),
        }
    }

    /// `q̈` at `(t, q, q̇)` into `qdd` (eq. (14)). `step` labels errors.
    pub fn acceleration<S, F>(
        &mut self,
        sys: &mut S,
        force: &mut F,
        step: usize,
        t: f64,
        q: &Vector<N>,
        dq: &Vector<N>,
        qdd: &mut Vector<N>,
    ) -> Result<(), SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
    {
        sys.lagrangian(q, dq, Order::Dynamics, &mut self.terms);
        total_force(sys, force, t, q, dq, qdd);
        // rhs = u + ∂L/∂q − (∂²L/∂q̇∂q) q̇
        *qdd += &self.terms.dl_dq;
        qdd.gemv(-1.0, &self.terms.d2l_ddq_dq, dq, 1.0);
        self.factor.copy_from(&self.terms.mass);
        cholesky_solve(&mut self.factor, qdd).map_err(|(i, pivot)| {
            SimError::SingularMassMatrix {
                step,
                t,
                variable: sys.variable_name(i).to_string(),
                pivot,
            }
        })?;
        if qdd.iter().any(|x| !x.is_finite()) {
            return Err(SimError::NonFinite {
                step,
                t,
                what: "acceleration q̈".into(),
            });
        }
        Ok(())
    }
}
