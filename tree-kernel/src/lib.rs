//! # tree-kernel
//!
//! The recursions of a tree of frames (Johnson & Murphey), written once over any
//! [`Scalar`](scalar::Scalar): evaluated over `f64` by the interpreted system of
//! `tree-runtime`, over dual numbers and jets for the linearisations, over SIMD lanes for
//! batches, and over a tracing scalar by `tree_model!`, which records them into straight-line
//! Rust for one fixed tree. Nothing here allocates per evaluation or knows of nalgebra.
//!
//! Bottom up:
//! * [`scalar`] — the arithmetic every recursion is written over; [`order`] — how many
//!   derivatives an evaluation takes;
//! * [`se3`] — poses, twists and the primitive transforms' derivatives (eqs. (1)–(14));
//! * [`plan`] — the tree as the recursions walk it (constant frames folded into their
//!   parents, bodies, elements);
//! * [`outputs`] — what an evaluation hands out ([`Output`](outputs::Output)) and where
//!   it goes ([`Sink`](outputs::Sink));
//! * [`sweeps`] — the kinematic sweeps and the Lagrangian's derivatives (eqs. (15)–(18));
//!   [`elements`] — constraints, springs, dampers; [`kernel`] — them run together;
//! * [`articulated`] — forward dynamics by the articulated-body algorithm;
//!   [`newton_euler`] — inverse dynamics by recursive Newton–Euler;
//! * [`dual`] — dual numbers and jets, [`lanes`] — SIMD lanes, [`cpu`] — which variant of
//!   the generated code this CPU runs.
//!
//! The crate is the engine room of `tree-mech`; its interface follows what the runtime and
//! the compiler need and is not a stable one. Depend on `tree-mech`.
#![warn(missing_docs)]

pub mod articulated;
pub mod cpu;
pub mod dual;
pub mod elements;
pub mod kernel;
pub mod lanes;
pub mod newton_euler;
pub mod order;
pub mod outputs;
pub mod plan;
pub mod scalar;
pub mod se3;
pub mod sweeps;

pub use order::Order;
pub use se3::{Pose, Twist};
pub use tree_model;
