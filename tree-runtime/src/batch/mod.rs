//! Many rollouts at once: one [`run_with_inputs`] per start state and input schedule, spread
//! over a pool of threads (rayon), each worker with its own copy of the system. Every
//! rollout is computed by one thread from its own inputs alone, so the results are bitwise
//! the same whatever the number of threads; each rollout's failure is its own. Likewise the
//! first derivatives of every step of a VI trajectory ([`linearize_trajectory`]).
//!
//! ```
//! use tree_runtime::batch::{rollouts, Rollout};
//! use tree_runtime::integrate::{InputSchedule, Method, SimOptions, ViSettings};
//! use tree_runtime::TreeSystem;
//! let model = tree_runtime::tree_model::n_link_pendulum(2);
//! let sys = TreeSystem::new(&model).unwrap();
//! let starts: Vec<Rollout> = (0..4)
//!     .map(|k| Rollout {
//!         q0: vec![0.1 * k as f64, 0.0],
//!         dq0: vec![0.0, 0.0],
//!         inputs: InputSchedule::default(),
//!     })
//!     .collect();
//! let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 0.5);
//! let runs = rollouts(&sys, &starts, &options, 2).unwrap();
//! assert_eq!(runs.len(), 4);
//! assert_eq!(runs[3].as_ref().unwrap().len(), 51);
//! ```

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use nalgebra::{allocator::Allocator, DefaultAllocator};
use rayon::prelude::*;

use crate::dynamics::{ModelMotions, NoForce};
use crate::error::SimError;
use crate::integrate::laned::{rk4_lanes, LaneStart, Observer};
use crate::integrate::{
    check_recordings, finish, recording, run_with_inputs, InputSchedule, Method, SimOptions,
};
use crate::system::System;
use crate::trajectory::{Sample, Trajectory};
use tree_kernel::WIDTH;

mod steps;

pub use steps::{linearize_trajectory, StepLinearizer};

/// One rollout's start and inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rollout {
    /// The initial configuration (every variable).
    pub q0: Vec<f64>,
    /// The initial velocity.
    pub dq0: Vec<f64>,
    /// The inputs over the run (empty: none).
    pub inputs: InputSchedule,
}

/// A running batch's progress, and its caller's way to stop it: shared between the caller's
/// thread and the workers (a progress bar reads `done`; Ctrl-C sets `stop`). A batch of
/// rollouts counts rollouts, [`StepLinearizer::linearize_into_watched`] steps.
#[derive(Debug, Default)]
pub struct Watch {
    /// Rollouts (or steps) finished so far (for rollouts, their result known: failed ones,
    /// and once stopped the ones skipped, too).
    pub done: AtomicUsize,
    /// Set to stop the batch: a rollout not yet started is not run, a running one ends at
    /// its next recorded sample, and the batch returns [`stopped`].
    pub stop: AtomicBool,
}

impl Watch {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// What a rollout under watch hears at each sample: the stopped error once stopped.
    fn tick(&self) -> Result<(), SimError> {
        if self.stopped() {
            Err(stopped())
        } else {
            Ok(())
        }
    }

    /// One rollout under watch: not started once stopped, ended at a sample once stopped,
    /// counted when done.
    fn run(
        &self,
        go: impl FnOnce(&mut Tick) -> Result<Trajectory, SimError>,
    ) -> Result<Trajectory, SimError> {
        let result = if self.stopped() {
            Err(stopped())
        } else {
            go(&mut |_| self.tick())
        };
        self.done.fetch_add(1, Ordering::Relaxed);
        result
    }

    /// The batch's results, or [`stopped`] for the whole of a stopped one.
    fn close(
        &self,
        results: Vec<Result<Trajectory, SimError>>,
    ) -> Result<Vec<Result<Trajectory, SimError>>, SimError> {
        if self.stopped() {
            Err(stopped())
        } else {
            Ok(results)
        }
    }
}

/// What a rollout calls at each recorded sample (its time); an error ends it
/// ([`trajectory`]'s `tick`).
type Tick<'a> = dyn FnMut(f64) -> Result<(), SimError> + 'a;

/// The error of a batch stopped through its [`Watch`].
pub fn stopped() -> SimError {
    SimError::InvalidInput("the batch was stopped before it finished".into())
}

/// Runs every rollout of `sys` under `options` on `threads` threads (0: as many as the
/// machine has). Returns one result per rollout, in order: its recorded trajectory, or the
/// error that ended it. Fails as a whole only when the thread pool cannot be made.
pub fn rollouts<S>(
    sys: &S,
    starts: &[Rollout],
    options: &SimOptions,
    threads: usize,
) -> Result<Vec<Result<Trajectory, SimError>>, SimError>
where
    S: System + Clone + Send + Sync,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    rollouts_watched(sys, starts, options, threads, &Watch::default())
}

/// [`rollouts`] under `watch`: `watch.done` counts the rollouts finished as they finish, and
/// setting `watch.stop` (from another thread) ends the batch early with [`stopped`].
pub fn rollouts_watched<S>(
    sys: &S,
    starts: &[Rollout],
    options: &SimOptions,
    threads: usize,
    watch: &Watch,
) -> Result<Vec<Result<Trajectory, SimError>>, SimError>
where
    S: System + Clone + Send + Sync,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    check_recordings(sys, options, starts.len())?;
    let pool = pool(threads)?;
    let alone = |sys: &mut S, start| watch.run(|tick| trajectory(sys, start, options, tick));
    let results = pool.install(|| {
        if in_lanes(sys, options) {
            starts
                .par_chunks(WIDTH)
                .map_init(
                    || sys.clone(),
                    |sys, group| run_group(sys, group, options, watch),
                )
                .flat_map_iter(|group| group.into_iter())
                .collect()
        } else {
            starts.par_iter().map_init(|| sys.clone(), alone).collect()
        }
    });
    watch.close(results)
}

/// Whether a batch of `sys` under `options` runs its rollouts in lanes: RK4, on a system with
/// a laned evaluation (which a model with constraints has not).
fn in_lanes<S>(sys: &S, options: &SimOptions) -> bool
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    matches!(options.method, Method::Rk4) && sys.has_lanes()
}

/// A group of at most [`WIDTH`] rollouts of one system: run together in SIMD lanes where
/// they can be ([`crate::integrate::laned`]: RK4 on a system with a laned evaluation, a model
/// without constraints), else — and whenever a laned run gives up — one at a time. Either
/// way each result is the one its rollout alone gives, bit for bit.
fn run_group<S>(
    sys: &mut S,
    group: &[Rollout],
    options: &SimOptions,
    watch: &Watch,
) -> Vec<Result<Trajectory, SimError>>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    // Four lanes take about the time of two rollouts alone (`cargo bench --bench
    // rollouts`): a group of three gains, one of two does not.
    if group.len() > WIDTH / 2 && !watch.stopped() {
        if let Some(runs) = laned(sys, group, options, watch) {
            watch.done.fetch_add(group.len(), Ordering::Relaxed);
            return runs.into_iter().map(Ok).collect();
        }
    }
    let one = |start| watch.run(|tick| trajectory(sys, start, options, tick));
    group.iter().map(one).collect()
}

/// Runs `group` (at most [`WIDTH`] rollouts; padded with copies of its first) together in
/// SIMD lanes, RK4 stage by stage, each recorded as [`trajectory`] records it and with its
/// bits — what [`rollouts`] does with each group of an RK4 batch. `None` when the laned run
/// does not apply (an empty group or one of more than [`WIDTH`], another method, a model
/// with constraints, a system without a laned evaluation) or gives up (a rollout that fails
/// or whose articulated-body pivot is lost): then [`rollouts`] runs each alone.
pub fn run_in_lanes<S>(
    sys: &mut S,
    group: &[Rollout],
    options: &SimOptions,
) -> Option<Vec<Trajectory>>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if group.is_empty() || group.len() > WIDTH || !in_lanes(sys, options) {
        return None;
    }
    laned(sys, group, options, &Watch::default())
}

/// [`run_in_lanes`] under a watch.
fn laned<S>(
    sys: &mut S,
    group: &[Rollout],
    options: &SimOptions,
    watch: &Watch,
) -> Option<Vec<Trajectory>>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let start = |l: usize| {
        let r = group.get(l).unwrap_or(&group[0]);
        LaneStart {
            q0: &r.q0,
            dq0: &r.dq0,
            inputs: &r.inputs,
        }
    };
    // (A recording too large for memory: not in lanes; alone, the run says so.)
    let mut runs: Vec<Trajectory> = (0..WIDTH)
        .map(|_| recording(sys, options))
        .collect::<Result<_, _>>()
        .ok()?;
    let mut observers: Vec<_> = (runs.iter_mut())
        .map(|traj| {
            move |s: &Sample| {
                traj.push(s);
                watch.tick()
            }
        })
        .collect();
    let mut each = observers.iter_mut();
    let observe: [Observer; WIDTH] =
        std::array::from_fn(|_| each.next().expect("an observer a lane") as Observer);
    let summaries = rk4_lanes(sys, std::array::from_fn(start), options, observe)?;
    drop(observers);
    for (traj, summary) in runs.iter_mut().zip(&summaries) {
        finish(traj, summary);
    }
    runs.truncate(group.len());
    Some(runs)
}

/// [`rollouts`] with a system of its own per rollout (`systems[k]` runs `starts[k]`): a
/// parameter sweep (the same model with other masses or lengths, `Model::set_mass`,
/// `Model::set_constant`).
pub fn rollouts_of<S>(
    systems: Vec<S>,
    starts: &[Rollout],
    options: &SimOptions,
    threads: usize,
) -> Result<Vec<Result<Trajectory, SimError>>, SimError>
where
    S: System + Send,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    rollouts_of_watched(systems, starts, options, threads, &Watch::default())
}

/// [`rollouts_of`] under `watch` (as [`rollouts_watched`]).
pub fn rollouts_of_watched<S>(
    systems: Vec<S>,
    starts: &[Rollout],
    options: &SimOptions,
    threads: usize,
    watch: &Watch,
) -> Result<Vec<Result<Trajectory, SimError>>, SimError>
where
    S: System + Send,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if systems.len() != starts.len() {
        return Err(SimError::InvalidInput(format!(
            "{} systems for {} rollouts: give one each",
            systems.len(),
            starts.len()
        )));
    }
    if let Some(sys) = systems.first() {
        check_recordings(sys, options, starts.len())?;
    }
    let pool = pool(threads)?;
    let results = pool.install(|| {
        systems
            .into_par_iter()
            .zip(starts.par_iter())
            .map(|(mut sys, start)| watch.run(|tick| trajectory(&mut sys, start, options, tick)))
            .collect()
    });
    watch.close(results)
}

/// The most threads a batch starts per core: more only add switching, and a mistyped count
/// (a million) would try to start that many.
const THREADS_PER_CORE: usize = 8;

pub(crate) fn pool(threads: usize) -> Result<rayon::ThreadPool, SimError> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let most = (THREADS_PER_CORE * cores).max(64);
    if threads > most {
        return Err(SimError::InvalidInput(format!(
            "{threads} threads asked for, on {cores} cores: give at most {most} (or 0 for one per core)"
        )));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| SimError::InvalidInput(format!("cannot start {threads} threads: {e}")))
}

/// One run of `sys` from `start` recorded into a trajectory (every rollout's; the Python
/// package's `simulate`). `tick(t)` hears of each recorded sample; an error from it ends the
/// run with that error.
pub fn trajectory<S>(
    sys: &mut S,
    start: &Rollout,
    options: &SimOptions,
    tick: &mut dyn FnMut(f64) -> Result<(), SimError>,
) -> Result<Trajectory, SimError>
where
    S: System,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = sys.dof();
    if start.q0.len() != n || start.dq0.len() != n {
        return Err(SimError::InvalidInput(format!(
            "the start has {} positions and {} velocities; the system has {n} variables",
            start.q0.len(),
            start.dq0.len()
        )));
    }
    let (mut q0, mut dq0) = (sys.zero_vector(), sys.zero_vector());
    q0.as_mut_slice().copy_from_slice(&start.q0);
    dq0.as_mut_slice().copy_from_slice(&start.dq0);
    let mut traj = recording(sys, options)?;
    let mut motion = ModelMotions::of(sys);
    let summary = run_with_inputs(
        sys,
        &q0,
        &dq0,
        options,
        &mut NoForce,
        &mut motion,
        &start.inputs,
        &mut |s| {
            traj.push(s);
            tick(s.t)
        },
    )?;
    finish(&mut traj, &summary);
    Ok(traj)
}
