//! # tree-kernel
//!
//! The recursions of a tree of frames (Johnson & Murphey), written once over any
//! [`Scalar`]: evaluated over `f64` by the interpreted system of
//! `tree-runtime`, over dual numbers and jets for the linearisations, over SIMD lanes for
//! batches, and over a tracing scalar by `tree_model!`, which records them into straight-line
//! Rust for one fixed tree. Nothing here allocates per evaluation or knows of nalgebra.
//!
//! Bottom up (the modules that hold one thing are private, their items exported here; the
//! layers and topics are modules):
//! * [`Scalar`] — the arithmetic every recursion is written over; [`Order`] — how many
//!   derivatives an evaluation takes;
//! * [`se3`] — poses, twists and the primitive transforms' derivatives (eqs. (1)–(14));
//! * [`TreePlan`] — the tree as the recursions walk it (constant frames folded into their
//!   parents, [`Body`]s, elements);
//! * [`Output`] — what an evaluation hands out, and [`Sink`] where it goes;
//! * [`sweeps`] — the kinematic sweeps and the Lagrangian's derivatives (eqs. (15)–(18));
//!   [`elements`] — constraints, springs, dampers; [`kernel`] — them run together, with
//!   inverse dynamics by recursive Newton–Euler;
//! * [`articulated`] — forward dynamics by the articulated-body algorithm;
//! * [`Dual`] numbers and [`Jet`]s, SIMD [`Lanes`], [`cpu`] — which variant of the
//!   generated code this CPU runs.
//!
//! The crate is the engine room of `tree-mech`; its interface follows what the runtime and
//! the compiler need and is not a stable one. Depend on `tree-mech`.
#![warn(missing_docs)]

pub mod articulated;
pub mod cpu;
mod dual;
pub mod elements;
pub mod gaps;
pub mod kernel;
mod lanes;
mod newton_euler;
mod order;
mod outputs;
mod plan;
mod scalar;
pub mod se3;
pub mod sweeps;

pub use dual::{Dual, DualOutputs, Jet, JetOutputs, LANES};
pub use lanes::{ElementForces, EnergySink, Lanes, WIDTH};
pub use order::Order;
pub use outputs::{clear_among, Contract, Field, Index, Output, Scratch, Sink, Weighted};
pub use plan::{column_count, Body, Follower, FramePlan, PoseFrame, TreePlan, MAX_COLUMNS};
pub use scalar::Scalar;
pub use se3::{Pose, Twist};
pub use tree_model;
