//! Optimal control on the variational integrator (docs/derivations.md §10): the discrete
//! LQR ([`lqr::dare`]) and time-varying LQR ([`lqr::tvlqr`]) on a linearisation, and iLQR /
//! DDP with box limits ([`ilqr::solve`]) on [`ViDynamics`], the VI as `x_{k+1} = f(x_k, u_k)`
//! on `x = (q_d, p_d)` with the model's inputs as controls. Costs are [`Cost`]s
//! ([`QuadraticCost`] on the state and controls).

pub mod cost;
pub mod ilqr;
pub mod lqr;
pub mod vi_dynamics;

pub use cost::{Cost, Derivatives, QuadraticCost};
pub use ilqr::{cost_gradient, solve, IlqrSettings, Iteration, Solution, Solver};
pub use lqr::{dare, tvlqr, Lqr};
pub use vi_dynamics::ViDynamics;
