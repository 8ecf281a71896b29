//! The interface between the dynamics and the costs: a [`Knot`] (the state with `q`, `q̇`
//! and their derivatives by it, what every cost is written on) and the [`Needs`] a cost
//! states (what the discrete system must compute at each knot beyond the state). The
//! discrete system fills knots, costs read them; neither knows the other.

use nalgebra::{DMatrix, DVector};

/// What a cost reads at a knot beyond the state: the knot's velocity (for the VI, from the
/// momentum), the gravity compensation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// [`Knot::dq`] and [`Knot::dq_x`] beyond the state itself (always filled; this asks
    /// that they be exact, which the VI pays a solve for).
    pub velocity: bool,
    /// [`Knot::gravity`] and [`Knot::gravity_x`].
    pub gravity: bool,
    /// [`Knot::previous`] of inputs: the state must remember them
    /// ([`DiscreteSystem::with_input_memory`](crate::DiscreteSystem::with_input_memory)); the
    /// optimiser refuses a system that does not.
    pub input_memory: bool,
}

/// The configuration, velocity and their derivatives by the state at a knot: what costs
/// are written on.
#[derive(Clone, Debug, PartialEq)]
pub struct Knot {
    /// The state.
    pub x: DVector<f64>,
    /// Every variable's value.
    pub q: DVector<f64>,
    /// Every variable's velocity (for the VI, the one consistent with the momentum).
    pub dq: DVector<f64>,
    /// `∂q/∂x` (n × states).
    pub q_x: DMatrix<f64>,
    /// `∂q̇/∂x` (n × states).
    pub dq_x: DMatrix<f64>,
    /// Per control: the input that holds `q` at rest, `g(q) = −∂L/∂q` at `q̇ = 0` on its
    /// variable (zero for kinematic controls).
    pub gravity: DVector<f64>,
    /// `∂g/∂x` (controls × states).
    pub gravity_x: DMatrix<f64>,
    /// Per control: its previous value (the memory part of `x`; 0 for an input the state
    /// does not remember).
    pub previous: DVector<f64>,
    /// Where each control's previous value sits in `x` (None: an input not remembered).
    pub previous_at: Vec<Option<usize>>,
}

impl Knot {
    /// An empty knot, sized by [`DiscreteSystem::knot`](crate::DiscreteSystem::knot) on first use.
    pub fn empty() -> Self {
        Knot {
            x: DVector::zeros(0),
            q: DVector::zeros(0),
            dq: DVector::zeros(0),
            q_x: DMatrix::zeros(0, 0),
            dq_x: DMatrix::zeros(0, 0),
            gravity: DVector::zeros(0),
            gravity_x: DMatrix::zeros(0, 0),
            previous: DVector::zeros(0),
            previous_at: Vec::new(),
        }
    }
}
