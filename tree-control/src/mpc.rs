//! Model-predictive control (docs/derivations.md §14, "Re-planning"): at every tick the plan
//! over the next `horizon` knots is improved from the measured state — warm-started from the
//! last tick's controls shifted by the knots elapsed, a fixed number of solver iterations a
//! tick (the real-time iteration of Diehl, Bock and Schlöder, 2005) — tracking a reference
//! (an offline plan's states and controls, held at its last knot beyond its end). Through
//! contact the planner steps at its `κ` and needs no contact schedule: the measured state
//! says which feet press.

use std::time::Instant;

use nalgebra::{allocator::Allocator, DVector, DefaultAllocator};
use tree_runtime::{SimError, System};

use crate::cost::{check_sizes_and_weights, quadratic, running_quadratic, Cost, Derivatives};
use crate::discrete::DiscreteSystem;
use crate::ilqr::{solve, IlqrSettings, Solution};
use crate::knot::Knot;

/// What a tracking MPC weighs and computes.
#[derive(Clone, Debug)]
pub struct MpcSettings {
    /// Knots planned at each tick.
    pub horizon: usize,
    /// The solver; its `max_iterations` is the iterations a tick.
    pub ilqr: IlqrSettings,
    /// Per-entry weights of the state's deviation from the reference at each knot (its
    /// running term is `½ Δt Σ w (x − x_ref)²`).
    pub x_weight: DVector<f64>,
    /// Per-entry weights of the controls' deviation from the reference's.
    pub u_weight: DVector<f64>,
    /// Per-entry weights of the state's deviation at the horizon's end (`½ Σ w (x − x_ref)²`).
    pub terminal_weight: DVector<f64>,
}

/// The tracking cost over one tick's horizon: the reference from knot `from` on.
struct Tracking {
    x: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    from: usize,
    horizon: usize,
    dt: f64,
    x_weight: DVector<f64>,
    u_weight: DVector<f64>,
    terminal_weight: DVector<f64>,
}

impl Tracking {
    /// The reference state at reference knot `k` (the last beyond the end).
    fn state(&self, k: usize) -> &DVector<f64> {
        &self.x[k.min(self.x.len() - 1)]
    }

    /// The reference control at reference knot `k` (the last beyond the end).
    fn control(&self, k: usize) -> &DVector<f64> {
        &self.u[k.min(self.u.len() - 1)]
    }
}

impl Cost for Tracking {
    fn running(
        &mut self,
        k: usize,
        x: &Knot,
        u: &DVector<f64>,
        d: Option<&mut Derivatives>,
    ) -> f64 {
        let (xr, ur) = (self.state(self.from + k), self.control(self.from + k));
        let (xs, us) = ((&x.x, xr, &self.x_weight), (u, ur, &self.u_weight));
        running_quadratic(self.dt, xs, us, d)
    }

    fn terminal(&mut self, x: &Knot, d: Option<&mut Derivatives>) -> f64 {
        let lx = d.map(|d| (&mut d.lx, &mut d.lxx));
        let xr = self.state(self.from + self.horizon);
        quadratic(&x.x, xr, &self.terminal_weight, 1.0, lx)
    }

    fn check(&self, nx: usize, nu: usize) -> Result<(), String> {
        // The reference's odd one out, if any (else its first), and the weights.
        let odd = |v: &[DVector<f64>], want: usize| {
            v.iter()
                .map(|e| e.len())
                .find(|&n| n != want)
                .unwrap_or(v[0].len())
        };
        let sizes = [
            ("reference state", odd(&self.x, nx), nx),
            ("reference control", odd(&self.u, nu), nu),
            ("x_weight", self.x_weight.len(), nx),
            ("u_weight", self.u_weight.len(), nu),
            ("terminal_weight", self.terminal_weight.len(), nx),
        ];
        let weights = (self.x_weight.iter())
            .chain(self.u_weight.iter())
            .chain(self.terminal_weight.iter());
        check_sizes_and_weights("the MPC's", &sizes, weights)
    }
}

/// A tick's outcome: the plan from the measured state, and the seconds it took.
pub struct Tick<'a> {
    /// The horizon's plan (states from the measured one, controls, feedback gains).
    pub plan: &'a Solution,
    /// Wall-clock seconds of the re-plan.
    pub seconds: f64,
}

/// A receding-horizon controller tracking a reference on a discrete system (module docs).
pub struct Mpc<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    dynamics: DiscreteSystem<S>,
    cost: Tracking,
    ilqr: IlqrSettings,
    /// The time of reference knot 0.
    t0: f64,
    /// The last plan and the reference knot it started at.
    plan: Option<(usize, Solution)>,
}

impl<S: System> Mpc<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// An MPC planning on `dynamics` (its `Δt`, its `κ` through contact) to track the
    /// reference states `x_ref` (knots `0 … N`) and controls `u_ref` (`0 … N−1`) — an
    /// offline [`Solution`]'s `x` and `u`, say; knot 0 at the dynamics' `t0`.
    pub fn new(
        dynamics: DiscreteSystem<S>,
        x_ref: Vec<DVector<f64>>,
        u_ref: Vec<DVector<f64>>,
        settings: MpcSettings,
    ) -> Result<Self, SimError> {
        let invalid = |m: String| Err(SimError::InvalidInput(m));
        if u_ref.is_empty() || x_ref.len() != u_ref.len() + 1 {
            return invalid(format!(
                "the MPC's reference needs one more state than controls, and a control: it has {} states and {} controls",
                x_ref.len(),
                u_ref.len()
            ));
        }
        if settings.horizon == 0 || settings.ilqr.max_iterations == 0 {
            return invalid(
                "the MPC's horizon and its iterations a tick must be at least 1".into(),
            );
        }
        let cost = Tracking {
            x: x_ref,
            u: u_ref,
            from: 0,
            horizon: settings.horizon,
            dt: dynamics.dt,
            x_weight: settings.x_weight,
            u_weight: settings.u_weight,
            terminal_weight: settings.terminal_weight,
        };
        let (nx, nu) = (dynamics.states(), dynamics.controls());
        cost.check(nx, nu).map_err(SimError::InvalidInput)?;
        let t0 = dynamics.t0;
        Ok(Mpc {
            dynamics,
            cost,
            ilqr: settings.ilqr,
            t0,
            plan: None,
        })
    }

    /// Re-plans from the state `x` measured at reference knot `knot`: the horizon's controls
    /// warm-started from the last plan shifted to `knot` (the reference's where it has
    /// none), improved by the solver's iterations.
    pub fn tick(&mut self, knot: usize, x: &DVector<f64>) -> Result<Tick<'_>, SimError> {
        let start = Instant::now();
        let guess = self.warm_start(knot);
        self.cost.from = knot;
        self.dynamics.t0 = self.t0 + knot as f64 * self.dynamics.dt;
        let plan = solve(&mut self.dynamics, &mut self.cost, x, guess, &self.ilqr)?;
        let seconds = start.elapsed().as_secs_f64();
        let (_, plan) = self.plan.insert((knot, plan));
        Ok(Tick { plan, seconds })
    }

    /// The controls to start from at reference knot `knot`: the last plan's from `knot` on,
    /// then the reference's.
    fn warm_start(&self, knot: usize) -> Vec<DVector<f64>> {
        let last = |k: usize| {
            let (from, plan) = self.plan.as_ref()?;
            let i = k.checked_sub(*from)?;
            plan.u.get(i)
        };
        (knot..knot + self.cost.horizon)
            .map(|k| last(k).unwrap_or_else(|| self.cost.control(k)).clone())
            .collect()
    }

    /// The control at reference knot `knot` for the measured state `x`: the last plan's
    /// policy there (its control with its feedback, within the solver's limits), the
    /// reference's control before any plan or beyond the last one's horizon.
    pub fn control(&self, knot: usize, x: &DVector<f64>) -> DVector<f64> {
        let Some((from, plan)) = &self.plan else {
            return self.cost.control(knot).clone();
        };
        match knot.checked_sub(*from).filter(|&i| i < plan.u.len()) {
            Some(i) => plan.policy(i, x, self.ilqr.limits.as_ref()),
            None => self.cost.control(knot).clone(),
        }
    }

    /// The planner's discrete system (its `κ`, its state layout).
    pub fn dynamics(&mut self) -> &mut DiscreteSystem<S> {
        &mut self.dynamics
    }

    /// The closed loop over `knots` steps of `plant` (its `Δt` the planner's; at hard
    /// contact, say) from `x0` at reference knot 0: a tick every `every` knots from the
    /// plant's state, each knot's control [`Self::control`]; `disturb(k, x)` may change the
    /// plant's state before knot `k`'s control (a push).
    pub fn closed_loop<P: System>(
        &mut self,
        plant: &mut DiscreteSystem<P>,
        x0: &DVector<f64>,
        knots: usize,
        every: usize,
        disturb: &mut dyn FnMut(usize, &mut DVector<f64>),
    ) -> Result<ClosedLoop, SimError>
    where
        DefaultAllocator: Allocator<P::N> + Allocator<P::N, P::N>,
    {
        if every == 0 {
            return Err(SimError::InvalidInput(
                "the closed loop must tick at least every knot (every ≥ 1), not every 0".into(),
            ));
        }
        if (plant.dt - self.dynamics.dt).abs() > 1e-12 * plant.dt {
            return Err(SimError::InvalidInput(format!(
                "the plant steps Δt = {} s and the planner {} s: the closed loop needs them equal",
                plant.dt, self.dynamics.dt
            )));
        }
        let mut seconds = Vec::with_capacity(knots.div_ceil(every));
        let mut policy = |k: usize, x: &DVector<f64>| {
            if k.is_multiple_of(every) {
                seconds.push(self.tick(k, x)?.seconds);
            }
            Ok(self.control(k, x))
        };
        let mut run = run_closed_loop(plant, x0, knots, disturb, &mut policy)?;
        run.tick_seconds = seconds;
        Ok(run)
    }
}

/// A closed loop's policy: the control at knot `k` for the state `x` there.
pub type Policy<'a> = dyn FnMut(usize, &DVector<f64>) -> Result<DVector<f64>, SimError> + 'a;

/// `plant` run for `knots` steps from `x0` under `policy(k, x)`, the control at knot `k` for
/// the state there; `disturb(k, x)` may change the state first (a push). An MPC's loop
/// ([`Mpc::closed_loop`]), or a fixed plan's feedback law ([`Solution::policy`]).
pub fn run_closed_loop<P: System>(
    plant: &mut DiscreteSystem<P>,
    x0: &DVector<f64>,
    knots: usize,
    disturb: &mut dyn FnMut(usize, &mut DVector<f64>),
    policy: &mut Policy<'_>,
) -> Result<ClosedLoop, SimError>
where
    DefaultAllocator: Allocator<P::N> + Allocator<P::N, P::N>,
{
    let mut run = ClosedLoop {
        x: vec![x0.clone()],
        u: Vec::with_capacity(knots),
        tick_seconds: Vec::new(),
        penetration: 0.0,
    };
    let (mut x, mut next) = (x0.clone(), x0.clone());
    for k in 0..knots {
        disturb(k, &mut x);
        let u = policy(k, &x)?;
        plant.step(k, x.as_slice(), u.as_slice(), next.as_mut_slice(), None)?;
        run.penetration = run.penetration.max(plant.penetration());
        std::mem::swap(&mut x, &mut next);
        run.x.push(x.clone());
        run.u.push(u);
    }
    Ok(run)
}

/// A closed loop's record.
#[derive(Clone, Debug)]
pub struct ClosedLoop {
    /// The plant's states at knots `0 … N` (after any disturbance at the knot for the knots
    /// after it: `x[k]` is the state the step from knot `k − 1` reached).
    pub x: Vec<DVector<f64>>,
    /// The controls applied at knots `0 … N−1`.
    pub u: Vec<DVector<f64>>,
    /// Each tick's re-plan, wall-clock seconds (empty for a fixed policy).
    pub tick_seconds: Vec<f64>,
    /// The plant's deepest penetration of a unilateral row over the run (m or rad; 0
    /// without contact).
    pub penetration: f64,
}
