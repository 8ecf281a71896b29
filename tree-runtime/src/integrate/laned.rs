//! RK4 runs of [`WIDTH`] starts in lockstep, their stages' accelerations evaluated together
//! in the lanes of [`Lanes`] ([`System::articulated_acceleration_lanes`]): the batch's fast
//! path for a model without constraints. Each lane is [`run_with_inputs`](super::run_with_inputs)
//! for its start, step for step — the same RK4 stages ([`Rk4`]'s own), the same samples
//! through the same [`Recorder`] — and its evaluations have the bits of the one-state ones,
//! so each run's samples are those the run alone records. Whatever that run would do
//! differently — an error, a pivot the articulated-body algorithm loses (the run alone then
//! solves with `M`), an observer that stops it — makes this give up (`None`), and the caller
//! runs each start alone.

use nalgebra::{allocator::Allocator, DefaultAllocator};

use super::{check_finite, check_options, InputSchedule, Method, Recorder, RunSummary, Sample};
use super::{Rk4, SimOptions};
use crate::context::StepContext;
use crate::dynamics::{prescribe, Dynamics, ModelMotions, NoForce};
use crate::error::SimError;
use crate::system::{System, Terms, Vector};
use tree_kernel::{ElementForces, Lanes, WIDTH};

/// One lane's start.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneStart<'a> {
    pub q0: &'a [f64],
    pub dq0: &'a [f64],
    pub inputs: &'a InputSchedule,
}

/// What each lane hands its samples to.
pub(crate) type Observer<'a> = &'a mut dyn FnMut(&Sample) -> Result<(), SimError>;

/// One lane's run: its state, its RK4 (stages and dissipated energy), its recorder.
struct Lane<'a, 'o, S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    q: Vector<S::N>,
    dq: Vector<S::N>,
    rk: Rk4<S::N>,
    rec: Recorder<'o, S::N>,
    inputs: &'a InputSchedule,
}

/// The laned evaluation's buffers: every entry one variable, every lane one run.
struct Packed {
    q: Vec<Lanes>,
    dq: Vec<Lanes>,
    tau: Vec<Lanes>,
    qdd: Vec<Lanes>,
    own: ElementForces,
}

impl Packed {
    fn new(n: usize) -> Self {
        let z = || vec![Lanes::default(); n];
        Packed {
            q: z(),
            dq: z(),
            tau: z(),
            qdd: z(),
            own: ElementForces::zeros(n),
        }
    }
}

/// Writes `x` (one lane's values) into lane `l` of `out`.
fn pack(out: &mut [Lanes], l: usize, x: &[f64]) {
    for (o, &v) in out.iter_mut().zip(x) {
        o.0[l] = v;
    }
}

/// Lane `l` of `from` into `x`.
fn unpack(from: &[Lanes], l: usize, x: &mut [f64]) {
    for (v, o) in x.iter_mut().zip(from) {
        *v = o.0[l];
    }
}

/// Runs RK4 (`options.method` must be it) from each of `starts` on `sys`, every lane's
/// samples to its `observe`, each as [`super::run_with_inputs`] with no force from outside
/// would — or `None`, having handed out some samples perhaps, when any run would not go as
/// one laned run does (see the module): the caller then runs each start alone, afresh.
pub(crate) fn rk4_lanes<'o, S: System>(
    sys: &mut S,
    starts: [LaneStart<'_>; WIDTH],
    options: &SimOptions,
    observe: [Observer<'o>; WIDTH],
) -> Option<[RunSummary; WIDTH]>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    if !matches!(options.method, Method::Rk4) || !sys.has_lanes() {
        return None;
    }
    let steps = check_options(options).ok()?;
    // A smooth run watches its unilateral rows (watch.rs); lanes leave it to single runs.
    if !sys.unilateral().is_empty() {
        return None;
    }
    let n = sys.dof();
    let fits = |s: &LaneStart| {
        s.q0.len() == n
            && s.dq0.len() == n
            && (s.inputs.is_empty() || s.inputs.width() == sys.input_count())
    };
    if !starts.iter().all(fits) {
        return None;
    }
    let mut motion = ModelMotions::of(sys);
    let mut lanes = Vec::with_capacity(WIDTH);
    for (start, observe) in starts.into_iter().zip(observe) {
        let (mut q, mut dq) = (sys.zero_vector(), sys.zero_vector());
        q.as_mut_slice().copy_from_slice(start.q0);
        dq.as_mut_slice().copy_from_slice(start.dq0);
        let mut rk = Rk4::new(sys);
        rk.dynamics.baumgarte = options.baumgarte;
        prescribe(
            &rk.dynamics.split.kinematic,
            &mut motion,
            0.0,
            &mut q,
            &mut dq,
            None,
        );
        if q.iter().chain(dq.iter()).any(|x| !x.is_finite()) {
            return None;
        }
        let rec = Recorder {
            summary: RunSummary::default(),
            observe,
            constraints: Vec::new(),
            terms: Terms::zeros(sys.dim()),
            qdd: sys.zero_vector(),
            dynamics: Dynamics::new(sys),
            every: options.every,
            watch: None,
        };
        lanes.push(Lane {
            q,
            dq,
            rk,
            rec,
            inputs: start.inputs,
        });
    }
    let mut packed = Packed::new(n);
    let dt = options.dt;
    record(sys, &mut lanes, &mut packed, 0, 0.0)?;
    let (mut k, mut t) = (0, 0.0);
    loop {
        step(sys, &mut motion, &mut lanes, &mut packed, k, t, dt)?;
        for lane in lanes.iter_mut() {
            lane.rec.summary.dissipated += lane.rk.dissipated;
        }
        (k, t) = (k + 1, (k + 1) as f64 * dt);
        for lane in &lanes {
            check_finite(k, t, &lane.q, &lane.dq).ok()?;
        }
        let last = k == steps;
        if k.is_multiple_of(options.every) || last {
            record(sys, &mut lanes, &mut packed, k, t)?;
        }
        if last {
            let mut summaries = lanes.into_iter().map(|lane| lane.rec.summary);
            return Some(std::array::from_fn(|_| {
                let mut s = summaries.next().expect("one summary a lane");
                s.steps = k;
                s
            }));
        }
    }
}

/// Every lane's sample at step `k`, time `t`: its state and its energy (evaluated in lanes),
/// under the inputs in force from `t`.
fn record<S: System>(
    sys: &mut S,
    lanes: &mut [Lane<'_, '_, S>],
    packed: &mut Packed,
    k: usize,
    t: f64,
) -> Option<()>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    for (l, lane) in lanes.iter().enumerate() {
        pack(&mut packed.q, l, lane.q.as_slice());
        pack(&mut packed.dq, l, lane.dq.as_slice());
    }
    let energy = sys.energy_lanes(&packed.q, &packed.dq)?;
    for (l, lane) in lanes.iter_mut().enumerate() {
        let sample = Sample {
            step: k,
            t,
            q: lane.q.as_slice(),
            dq: lane.dq.as_slice(),
            p: None,
            energy: energy.0[l],
            lambda: &[],
            violation: 0.0,
            u: lane.inputs.at(t),
            impulse: &[],
            gap: &[],
        };
        lane.rec.record(&sample).ok()?;
    }
    Some(())
}

/// One RK4 step of every lane from `t` ([`Rk4::step`], its stages' accelerations evaluated
/// together).
fn step<S: System>(
    sys: &mut S,
    motion: &mut ModelMotions,
    lanes: &mut [Lane<'_, '_, S>],
    packed: &mut Packed,
    k: usize,
    t: f64,
    dt: f64,
) -> Option<()>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    for lane in lanes.iter_mut() {
        lane.rk.dissipated = 0.0;
    }
    let mut none = NoForce;
    for s in 0..4 {
        let mut ts = t;
        for (l, lane) in lanes.iter_mut().enumerate() {
            ts = lane.rk.stage_state(s, motion, t, dt, &lane.q, &lane.dq);
            let mut cx = StepContext::new(sys, &mut none, motion, dt);
            cx.u = lane.inputs.at(t);
            if !lane.rk.stage_inputs(s, cx.at(k, ts)) {
                return None;
            }
            let [q, dq, qdd, tau] = lane.rk.stage_parts(s);
            pack(&mut packed.q, l, q.as_slice());
            pack(&mut packed.dq, l, dq.as_slice());
            pack(&mut packed.qdd, l, qdd.as_slice());
            pack(&mut packed.tau, l, tau.as_slice());
        }
        let held = sys.articulated_acceleration_lanes(
            &packed.q,
            &packed.dq,
            &packed.tau,
            &mut packed.qdd,
            &mut packed.own,
        )?;
        for (l, lane) in lanes.iter_mut().enumerate() {
            if !held[l] {
                return None;
            }
            let fill = |qdd: &mut Vector<S::N>, force: &mut Vector<S::N>| {
                unpack(&packed.qdd, l, qdd.as_mut_slice());
                unpack(&packed.own.force, l, force.as_mut_slice());
            };
            lane.rk.end_stage((s, k, ts, dt), fill).ok()?;
        }
    }
    for lane in lanes.iter_mut() {
        lane.rk.combine(motion, t, dt, &mut lane.q, &mut lane.dq);
    }
    Some(())
}
