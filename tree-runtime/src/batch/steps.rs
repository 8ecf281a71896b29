//! The first derivatives of every step of a recorded VI trajectory, over threads — trep's
//! `DSystem.linearize_trajectory`, and what iLQR's backward pass reads. Each step is
//! linearised from its own samples alone (docs/derivations.md §9), so the steps are shared
//! out in contiguous runs, one per worker, each worker with its own system and integrator,
//! and the results are bitwise the same whatever the number of threads.

use nalgebra::{allocator::Allocator, DVector, DefaultAllocator};
use rayon::prelude::*;

use std::sync::atomic::Ordering;

use super::{pool, stopped, Watch};
use crate::context::StepContext;
use crate::dynamics::{ModelMotions, NoForce};
use crate::error::SimError;
use crate::integrate::{MidpointVi, StepDerivatives, ViSettings};
use crate::system::{ConstraintTerms, Order, System, Vector};
use crate::trajectory::Trajectory;

/// The first derivatives of every step of `run`, a trajectory recorded by the midpoint VI
/// with `settings` (every step: [`crate::integrate::SimOptions::every`] 1), on `threads`
/// threads (0: one per core). One call of a [`StepLinearizer`]; see there.
///
/// ```
/// use tree_runtime::batch::{linearize_trajectory, trajectory, Rollout};
/// use tree_runtime::integrate::{Method, SimOptions, ViSettings};
/// use tree_runtime::TreeSystem;
/// let model = tree_runtime::tree_model::n_link_pendulum(2);
/// let mut sys = TreeSystem::new(&model).unwrap();
/// let start = Rollout { q0: vec![0.3, 0.0], dq0: vec![0.0, 0.0], ..Rollout::default() };
/// let settings = ViSettings::default();
/// let options = SimOptions::new(Method::Vi(settings.clone()), 0.01, 0.1);
/// let run = trajectory(&mut sys, &start, &options, &mut |_| Ok(())).unwrap();
/// let steps = linearize_trajectory(&sys, &run, &settings, 2).unwrap();
/// assert_eq!(steps.len(), 10);
/// assert_eq!(steps[0].q2_dq1.shape(), (2, 2));
/// ```
pub fn linearize_trajectory<S>(
    sys: &S,
    run: &Trajectory,
    settings: &ViSettings,
    threads: usize,
) -> Result<Vec<StepDerivatives>, SimError>
where
    S: System + Clone + Send,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    MidpointVi<S::N>: Send,
    Vector<S::N>: Send,
{
    let mut out = Vec::new();
    StepLinearizer::new(sys, settings, threads)?.linearize_into(run, &mut out)?;
    Ok(out)
}

/// Linearises the steps of recorded VI trajectories of one system, over a pool of threads
/// made once: after the first call with a given number of steps, a call allocates nothing.
/// Step k, from sample k to k + 1, is linearised at its recorded `q_k`, `p_k`, `q_{k+1}`,
/// its multipliers (recorded with sample k + 1) and the inputs in force from sample k
/// ([`MidpointVi::derivatives_into`]: the model's own forces, no others); a constrained run's
/// first step at the `p₀⁻` it took ([`MidpointVi::start_constrained`]). A step whose recorded
/// end does not solve its discrete equations to the square root of the tolerances (the
/// loosest a converged step ends at) — a run of other settings or of another model, a step
/// the VI subdivided, samples recorded less often than every step — is refused with its
/// index (the first such step).
pub struct StepLinearizer<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// None: one thread, the caller's.
    pool: Option<rayon::ThreadPool>,
    workers: Vec<StepWorker<S>>,
}

impl<S> StepLinearizer<S>
where
    S: System + Clone + Send,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    MidpointVi<S::N>: Send,
    Vector<S::N>: Send,
{
    /// One worker (a copy of `sys` and a VI with `settings`) per thread; `threads` 0: one per
    /// core.
    pub fn new(sys: &S, settings: &ViSettings, threads: usize) -> Result<Self, SimError> {
        let settings = ViSettings {
            derivatives: true,
            ..*settings
        };
        let pool = match threads {
            1 => None,
            _ => Some(pool(threads)?),
        };
        let count = pool.as_ref().map_or(1, |p| p.current_num_threads());
        Ok(StepLinearizer {
            pool,
            workers: (0..count)
                .map(|_| StepWorker::new(sys.clone(), &settings))
                .collect(),
        })
    }

    /// Every step's first derivatives into `out` (resized to the steps; each entry's
    /// matrices reused).
    pub fn linearize_into(
        &mut self,
        run: &Trajectory,
        out: &mut Vec<StepDerivatives>,
    ) -> Result<(), SimError> {
        self.linearize_into_watched(run, out, &Watch::default())
    }

    /// [`Self::linearize_into`] under `watch`: `watch.done` counts the steps linearised as
    /// they are, and setting `watch.stop` (from another thread) ends the call early with
    /// [`stopped`] (each worker looks before each step).
    pub fn linearize_into_watched(
        &mut self,
        run: &Trajectory,
        out: &mut Vec<StepDerivatives>,
        watch: &Watch,
    ) -> Result<(), SimError> {
        self.workers[0].fits(run)?;
        let steps = run.len() - 1;
        out.resize_with(steps, StepDerivatives::empty);
        let share = steps.div_ceil(self.workers.len()).max(1);
        // Worker c takes steps c·share.. (a worker left without steps takes none), and keeps
        // the error that stopped it.
        let each = |(c, (worker, outs)): (usize, (&mut StepWorker<S>, &mut [StepDerivatives]))| {
            let first = c * share;
            worker.error = (outs.iter_mut().enumerate())
                .try_for_each(|(i, o)| {
                    if watch.stop.load(Ordering::Relaxed) {
                        return Err(stopped());
                    }
                    worker.linearize_into(run, first + i, o)?;
                    watch.done.fetch_add(1, Ordering::Relaxed);
                    Ok(())
                })
                .err();
        };
        self.workers.iter_mut().for_each(|w| w.error = None);
        match &self.pool {
            None => each((0, (&mut self.workers[0], out.as_mut_slice()))),
            Some(pool) => {
                let work = self.workers.par_iter_mut().zip(out.par_chunks_mut(share));
                pool.install(|| work.enumerate().for_each(each));
            }
        }
        if watch.stop.load(Ordering::Relaxed) {
            return Err(stopped());
        }
        // The runs are in step order: the first error is the earliest step's.
        match self.workers.iter_mut().find_map(|w| w.error.take()) {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// One thread's share: its system, integrator and buffers.
struct StepWorker<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    vi: MidpointVi<S::N>,
    motion: ModelMotions,
    q1: Vector<S::N>,
    p1: Vector<S::N>,
    q2: Vector<S::N>,
    /// The constraints and multipliers at the start (the first step's momentum).
    start: ConstraintTerms,
    lambda0: DVector<f64>,
    zero: Vector<S::N>,
    /// What stopped this worker's last share.
    error: Option<SimError>,
    sys: S,
}

impl<S: System> StepWorker<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    fn new(sys: S, settings: &ViSettings) -> Self {
        let (n, m) = (sys.dof(), sys.constraint_count());
        StepWorker {
            vi: MidpointVi::new(&sys, *settings),
            motion: ModelMotions::of(&sys),
            q1: sys.zero_vector(),
            p1: sys.zero_vector(),
            q2: sys.zero_vector(),
            start: ConstraintTerms::zeros(m, n),
            lambda0: DVector::zeros(m),
            zero: sys.zero_vector(),
            error: None,
            sys,
        }
    }

    /// Whether `run` is a VI run of this system with a step to linearise.
    fn fits(&self, run: &Trajectory) -> Result<(), SimError> {
        let (sys, n, m) = (&self.sys, self.sys.dof(), self.sys.constraint_count());
        let names = (0..n).map(|i| sys.variable_name(i));
        if run.dof() != n || !names.eq(run.variables.iter().map(String::as_str)) {
            return Err(SimError::InvalidInput(format!(
                "the trajectory's variables ({}) are not the system's ({n}, in its order)",
                run.dof()
            )));
        }
        if run.len() < 2 || run.p(run.len() - 1).is_none() {
            return Err(SimError::InvalidInput(
                "the trajectory has no step with its momenta: record one with the VI".into(),
            ));
        }
        if run.constraints.len() != m {
            return Err(SimError::InvalidInput(format!(
                "the trajectory has {} constraint rows, the system {m}",
                run.constraints.len()
            )));
        }
        Ok(())
    }

    /// Step k's first derivatives into `out`, once its end is checked to solve its equations.
    fn linearize_into(
        &mut self,
        run: &Trajectory,
        k: usize,
        out: &mut StepDerivatives,
    ) -> Result<(), SimError> {
        self.q1.as_mut_slice().copy_from_slice(run.q(k));
        self.q2.as_mut_slice().copy_from_slice(run.q(k + 1));
        let p1 = run.p(k).ok_or_else(|| {
            SimError::InvalidInput(format!("sample {k} of the trajectory has no momenta"))
        })?;
        self.p1.as_mut_slice().copy_from_slice(p1);
        let (t, dt) = (run.t[k], run.t[k + 1] - run.t[k]);
        if k == 0 && !run.constraints.is_empty() {
            // The start records the continuous momentum p(0); a constrained run's first step
            // took p₀⁻ = p(0) − ½Δt Dh(q₀)_dᵀλ(0), formed again here.
            (self.sys).constraints(&self.q1, &self.zero, Order::First, &mut self.start);
            self.lambda0.copy_from_slice(run.lambda(0));
            (self.vi).start_constrained(&self.start.dh, &self.lambda0, dt, &mut self.p1);
        }
        self.vi.lambda.copy_from_slice(run.lambda(k + 1));
        let mut force = NoForce;
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut self.motion, dt);
        (cx.index, cx.t, cx.u) = (k, t, run.u(k));
        (self.vi).derivatives_into(&mut cx, &self.q1, &self.p1, &self.q2, out)?;
        let (residual, violation) = (self.vi.relative_residual(), self.vi.violation());
        let tolerances = &self.vi.settings;
        if !(residual <= tolerances.tolerance.sqrt()
            && violation <= tolerances.constraint_tolerance.sqrt())
        {
            return Err(SimError::InvalidInput(format!(
                "step {k} of the trajectory (t = {t}) does not solve the VI's equations \
                 (relative residual {residual:.1e}, violation {violation:.1e}): record every \
                 step of a run with these settings, none subdivided"
            )));
        }
        Ok(())
    }
}
