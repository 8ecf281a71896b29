//! One module per topic (each was a test binary of its own).

mod added;
#[cfg(feature = "cli")]
mod cli;
#[cfg(all(feature = "cli", unix))]
mod cli_edges;
mod collection;
mod constraints;
mod contact;
mod continuous_derivatives;
mod derivatives;
mod discrete;
mod errors;
mod forcing;
mod fuzz;
mod kinematics;
mod mimic;
mod units;
mod vi;
