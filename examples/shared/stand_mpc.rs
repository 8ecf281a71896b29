//! The Solo-12 stand-up tracked by MPC (examples/solo12_mpc.rs; shared with
//! benches/stand.rs and tests/tasks/contact.rs): the offline plan of tasks/solo12-stand.toml
//! re-planned over the next `HORIZON` knots from the measured state every `EVERY` knots, one
//! iteration a tick, the plant stepping at hard contact.

use tree_mech::control::{
    run_closed_loop, task_settings, task_system, ClosedLoop, DiscreteSystem, IlqrSettings, Mpc,
    MpcSettings, Solution, TaskOptions,
};
use tree_mech::model::{Model, Task};
use tree_mech::nalgebra::{allocator::Allocator, DVector, DefaultAllocator};
use tree_mech::{SimError, System};

/// Knots planned at each tick: 0.1 s at the task's 5 ms.
pub const HORIZON: usize = 20;
/// Knots between ticks: a re-plan every 10 ms.
pub const EVERY: usize = 2;
/// The push: the base's momentum along x changed by this much (N·s) at `PUSH_KNOT`.
pub const PUSH: f64 = 0.5;
/// The knot of the push (t = 0.3 s).
pub const PUSH_KNOT: usize = 60;

/// The tracking weights on the state `(q, p)` of the Solo's 18 dynamic variables: its base
/// position and attitude held hardest, the joints' angles and every momentum lightly; the
/// torques' deviation from the plan's; at the horizon's end ten times the running weights.
pub fn settings(task: &Task) -> MpcSettings {
    let nd = 18;
    let x_weight = DVector::from_fn(2 * nd, |i, _| match i {
        0..=2 => 1e4,
        3..=5 => 1e3,
        i if i < nd => 10.0,
        _ => 1.0,
    });
    let options = TaskOptions {
        max_iterations: Some(1),
        ..TaskOptions::default()
    };
    MpcSettings {
        horizon: HORIZON,
        // At most four rollouts in the line search (1, ½, ¼, ⅛): a tick's time bounded.
        ilqr: IlqrSettings {
            min_step: 0.125,
            ..task_settings(task, &options)
        },
        terminal_weight: &x_weight * 10.0,
        x_weight,
        u_weight: DVector::from_element(task.controls.len(), 1e-2),
    }
}

/// The Solo at hard contact stepped as a simulation steps (a step Newton cannot take
/// retried in halves): the plant.
fn hard_plant<P: System>(plant: P, task: &Task) -> Result<DiscreteSystem<P>, SimError>
where
    DefaultAllocator: Allocator<P::N> + Allocator<P::N, P::N>,
{
    let mut hard = task_system(plant, task)?.with_subdivisions(4);
    hard.set_kappa(0.0)?;
    Ok(hard)
}

/// The push: `push` N·s on root_x's momentum at `PUSH_KNOT`.
fn pushed(push: f64) -> impl FnMut(usize, &mut DVector<f64>) {
    move |k, x| {
        if k == PUSH_KNOT {
            x[18] += push;
        }
    }
}

/// The closed loop of `task`'s plan `plan` with `push` N·s along x at `PUSH_KNOT`: planned on
/// `planner` at the task's last `κ`, stepped on `plant` at hard contact.
pub fn stand_mpc<S: System, P: System>(
    planner: S,
    plant: P,
    task: &Task,
    plan: &Solution,
    push: f64,
) -> Result<ClosedLoop, SimError>
where
    DefaultAllocator:
        Allocator<S::N> + Allocator<S::N, S::N> + Allocator<P::N> + Allocator<P::N, P::N>,
{
    let dynamics = task_system(planner, task)?;
    let mut mpc = Mpc::new(dynamics, plan.x.clone(), plan.u.clone(), settings(task))?;
    let mut hard = hard_plant(plant, task)?;
    mpc.closed_loop(&mut hard, &plan.x[0], task.knots, EVERY, &mut pushed(push))
}

/// The offline plan's own policy `u_k + K_k (x − x_k)` (within the task's limits) at hard
/// contact through the same push: never re-planned.
pub fn policy_only<P: System>(
    plant: P,
    task: &Task,
    plan: &Solution,
    push: f64,
) -> Result<ClosedLoop, SimError>
where
    DefaultAllocator: Allocator<P::N> + Allocator<P::N, P::N>,
{
    let mut hard = hard_plant(plant, task)?;
    let limits = task_settings(task, &TaskOptions::default()).limits;
    let mut policy = |k: usize, x: &DVector<f64>| Ok(plan.policy(k, x, limits.as_ref()));
    run_closed_loop(
        &mut hard,
        &plan.x[0],
        task.knots,
        &mut pushed(push),
        &mut policy,
    )
}

/// Where a closed loop ends and how its feet did: the base's final `(x, z)`, how far any foot
/// moved over the ground from the start, and the lowest foot centre over the run.
pub fn outcome(model: &Model, run: &ClosedLoop) -> ([f64; 2], f64, f64) {
    let feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
        .map(|f| model.frame_index(f).expect("the Solo's feet"));
    let q = |x: &DVector<f64>| x.as_slice()[..18].to_vec();
    let start = model.origins(&q(&run.x[0]));
    let (mut slip, mut lowest) = (0.0f64, f64::INFINITY);
    for x in &run.x {
        let o = model.origins(&q(x));
        for &f in &feet {
            slip = slip.max((o[f][0] - start[f][0]).hypot(o[f][1] - start[f][1]));
            lowest = lowest.min(o[f][2]);
        }
    }
    let end = run.x.last().expect("a run has a state");
    ([end[0], end[2]], slip, lowest)
}
