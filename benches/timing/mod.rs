//! What the robot benches share: the timer and the state Pinocchio is timed at
//! (tools/reference/pinocchio_bench.cpp sets the same).

use std::time::Instant;

use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::runtime::Vector;
use tree_mech::System;

/// Mean ns per call of `f` over `calls` calls: the best of 5 batches.
pub fn time_ns(calls: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let start = Instant::now();
        for _ in 0..calls {
            f();
        }
        best = best.min(start.elapsed().as_secs_f64() * 1e9 / calls as f64);
    }
    best
}

/// `q_i = 0.3 sin(0.7 i)`, `q̇_i = 0.5 cos(1.3 i)`: the state Pinocchio is timed at.
pub fn timed_state<S: System>(sys: &S) -> (Vector<S::N>, Vector<S::N>)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (mut q, mut dq) = (sys.zero_vector(), sys.zero_vector());
    for i in 0..sys.dof() {
        q[i] = 0.3 * (0.7 * i as f64).sin();
        dq[i] = 0.5 * (1.3 * i as f64).cos();
    }
    (q, dq)
}
