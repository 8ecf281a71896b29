//! Integrators — fixed-step RK4, adaptive Dormand–Prince 5(4), the midpoint variational
//! integrator — and [`simulate`], which runs any of them on any [`System`] and records a
//! [`Trajectory`].

mod rk4;
mod rk45;
mod vi;

pub use rk4::Rk4;
pub use rk45::{Rk45, Tolerance};
pub use vi::{JacobianUpdate, MidpointVi, ViSettings};

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::dynamics::GeneralizedForce;
use crate::error::SimError;
use crate::system::{Order, System, Terms, Vector};
use crate::trajectory::Trajectory;

/// Which integrator to run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    Rk4,
    /// Adaptive; records every accepted step, `dt` is the first step tried.
    Rk45(Tolerance),
    Vi(ViSettings),
}

/// What to simulate for how long.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    pub method: Method,
    pub dt: f64,
    pub duration: f64,
}

fn check_options(o: &SimOptions) -> Result<(), SimError> {
    if !(o.dt > 0.0 && o.dt.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "time step must be positive, got {}",
            o.dt
        )));
    }
    if !(o.duration >= 0.0 && o.duration.is_finite()) {
        return Err(SimError::InvalidInput(format!(
            "duration must be non-negative, got {}",
            o.duration
        )));
    }
    if let Method::Vi(s) = o.method {
        if !(0.0..=1.0).contains(&s.alpha) {
            return Err(SimError::InvalidInput(format!(
                "VI alpha must lie in [0, 1], got {}",
                s.alpha
            )));
        }
    }
    if let Method::Rk45(t) = o.method {
        if !(t.rtol > 0.0 || t.atol > 0.0) {
            return Err(SimError::InvalidInput(
                "rk45 needs a positive tolerance".into(),
            ));
        }
    }
    Ok(())
}

/// Simulates from `(q0, q̇0)` and records every step. `progress` is called with the time
/// reached after each step.
pub fn simulate<S, F>(
    sys: &mut S,
    q0: &Vector<S::N>,
    dq0: &Vector<S::N>,
    options: &SimOptions,
    force: &mut F,
    progress: &mut dyn FnMut(f64),
) -> Result<Trajectory, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    check_options(options)?;
    let n = sys.dim();
    if q0.len() != n.value() || dq0.len() != n.value() {
        return Err(SimError::InvalidInput(format!(
            "initial state has {} and {} entries; the system has {} variables",
            q0.len(),
            dq0.len(),
            n.value()
        )));
    }
    if q0.iter().chain(dq0.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step: 0,
            t: 0.0,
            what: "initial state".into(),
        });
    }
    let steps = (options.duration / options.dt).round() as usize;
    let names = (0..n.value())
        .map(|i| sys.variable_name(i).to_string())
        .collect();
    let mut traj = Trajectory::new(names, steps + 1);
    let mut q = q0.clone();
    let mut dq = dq0.clone();
    let mut terms = Terms::zeros(n);
    let mut energy = |sys: &mut S, q: &Vector<S::N>, dq: &Vector<S::N>| {
        sys.lagrangian(q, dq, Order::First, &mut terms);
        terms.energy(dq)
    };
    match options.method {
        Method::Rk4 => {
            let mut rk = Rk4::new(n);
            traj.push(0.0, q.as_slice(), dq.as_slice(), None, energy(sys, &q, &dq));
            for k in 0..steps {
                let t = k as f64 * options.dt;
                rk.step(sys, force, k, t, options.dt, &mut q, &mut dq)?;
                check_finite(k + 1, t + options.dt, &q, &dq)?;
                let t = (k + 1) as f64 * options.dt;
                traj.push(t, q.as_slice(), dq.as_slice(), None, energy(sys, &q, &dq));
                progress(t);
            }
        }
        Method::Rk45(tol) => {
            let mut rk = Rk45::new(n, tol);
            traj.push(0.0, q.as_slice(), dq.as_slice(), None, energy(sys, &q, &dq));
            let (mut t, mut dt, mut k) = (0.0, options.dt, 0);
            let t_end = options.duration;
            while t < t_end {
                let h = rk.step(sys, force, k, t, t_end, &mut dt, &mut q, &mut dq)?;
                t = if t + h >= t_end * (1.0 - 1e-15) {
                    t_end
                } else {
                    t + h
                };
                k += 1;
                check_finite(k, t, &q, &dq)?;
                traj.push(t, q.as_slice(), dq.as_slice(), None, energy(sys, &q, &dq));
                progress(t);
            }
        }
        Method::Vi(settings) => {
            let mut vi = MidpointVi::new(n, settings);
            let mut p = vi.initial_momentum(sys, &q, &dq);
            let mut q_next = q.clone();
            traj.push(
                0.0,
                q.as_slice(),
                dq.as_slice(),
                Some(p.as_slice()),
                energy(sys, &q, &dq),
            );
            for k in 0..steps {
                let t = k as f64 * options.dt;
                vi.step(sys, force, k, t, options.dt, &mut q, &mut p, &mut q_next)?;
                traj.newton_iterations += vi.iterations;
                let t = (k + 1) as f64 * options.dt;
                let e = vi.velocity_and_energy(sys, k + 1, t, &q, &p, &mut dq)?;
                traj.push(t, q.as_slice(), dq.as_slice(), Some(p.as_slice()), e);
                progress(t);
            }
        }
    }
    Ok(traj)
}

fn check_finite<N: Dim>(step: usize, t: f64, q: &Vector<N>, dq: &Vector<N>) -> Result<(), SimError>
where
    DefaultAllocator: Allocator<N>,
{
    if q.iter().chain(dq.iter()).any(|x| !x.is_finite()) {
        return Err(SimError::NonFinite {
            step,
            t,
            what: "state (q, q̇)".into(),
        });
    }
    Ok(())
}
