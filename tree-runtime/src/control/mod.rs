//! Optimal control (docs/derivations.md §10): the discrete LQR ([`lqr::dare`]) and
//! time-varying LQR ([`lqr::tvlqr`]) on a linearisation, and iLQR / DDP with box limits
//! ([`ilqr::solve`]) on a [`DiscreteSystem`] — the VI (or RK4) as `x_{k+1} = f(x_k, u_k)`
//! whose controls are inputs and kinematic variables. Costs are [`Cost`]s: a
//! [`QuadraticCost`] on the state and controls, or the [`TaskCost`] of a task file (state,
//! control, control-rate, frame and orientation terms).

pub mod cost;
pub mod discrete;
pub mod frames;
pub mod ilqr;
pub mod lqr;
mod qp;
pub mod task_cost;
pub mod task_solve;

pub use cost::{Cost, Derivatives, Needs, QuadraticCost};
pub use discrete::{DiscreteSystem, Knot};
pub use ilqr::{
    cost_gradient, solve, solve_until, solve_with, BoxPhase, IlqrSettings, Iteration, Solution,
    Solver, Stop, MAX_MU,
};
pub use lqr::{dare, tvlqr, Lqr};
pub use task_cost::TaskCost;
pub use task_solve::{solve_task, solve_task_until, task_system, TaskOptions, TaskResult};
pub use tree_model::{About, Control, CostTerm, Target, Task, TaskIntegrator, TaskSolver};
