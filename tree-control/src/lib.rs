//! # tree-control
//!
//! Optimal control on tree-mech systems (docs/derivations.md §10): the discrete LQR ([`dare`]) and
//! time-varying LQR ([`tvlqr`]) on a linearisation, and iLQR / DDP with box limits
//! ([`solve`]) on a [`DiscreteSystem`] — the VI (or RK4) as `x_{k+1} = f(x_k, u_k)`
//! whose controls are inputs and kinematic variables. Costs are [`Cost`]s: a
//! [`QuadraticCost`] on the state and controls, or the [`TaskCost`] of a task file (state,
//! control, control-rate, frame and orientation terms). [`Mpc`] re-plans a receding horizon
//! from each measured state, tracking a reference (an offline plan).
#![warn(missing_docs)]

mod cost;
mod discrete;
mod frames;
mod ilqr;
mod knot;
mod lqr;
mod mpc;
mod qp;
mod task_cost;
mod task_solve;

pub use cost::{Cost, Derivatives, QuadraticCost};
pub use discrete::DiscreteSystem;
pub use ilqr::{
    cost_gradient, solve, solve_until, solve_with, BoxPhase, IlqrSettings, Iteration, Solution,
    Solver, Stop, MAX_MU,
};
pub use knot::{Knot, Needs};
pub use lqr::{dare, tvlqr, Lqr};
pub use mpc::{run_closed_loop, ClosedLoop, Mpc, MpcSettings, Policy, Tick};
pub use task_cost::TaskCost;
pub use task_solve::{
    solve_task, solve_task_until, task_settings, task_system, HardReplay, TaskOptions, TaskResult,
};
pub use tree_model::{About, Control, CostTerm, Target, Task, TaskIntegrator, TaskSolver};
