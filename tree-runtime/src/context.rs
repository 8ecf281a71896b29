//! What one integrator step works with besides its state.

/// The system a step advances, the forces on it, how its kinematic variables move, and where
/// in the run the step is. Every integrator's `step` takes one; sub-steps (the VI's
/// subdivision) move its `t` and `dt`.
pub struct StepContext<'a, S, F, P> {
    /// The system.
    pub sys: &'a mut S,
    /// External generalized forces, beyond the model's own.
    pub force: &'a mut F,
    /// The kinematic variables' motion.
    pub motion: &'a mut P,
    /// The step's index in the run (errors name it).
    pub index: usize,
    /// The time the step starts at.
    pub t: f64,
    /// Its length (for rk45, the length to try first; the step leaves its next proposal).
    pub dt: f64,
    /// The system's inputs over the step, one per [`crate::System::input_count`] (held
    /// constant over it; empty: all zero). They push as `B u` beside `force`.
    pub u: &'a [f64],
}

impl<'a, S: crate::System, F, P> StepContext<'a, S, F, P>
where
    nalgebra::DefaultAllocator:
        nalgebra::allocator::Allocator<S::N> + nalgebra::allocator::Allocator<S::N, S::N>,
{
    /// Adds the inputs' generalized force `B u` into `f`.
    #[inline]
    pub(crate) fn add_inputs(&self, f: &mut crate::Vector<S::N>) {
        for (k, &x) in self.u.iter().enumerate() {
            f[self.sys.input_variable(k)] += x;
        }
    }
}

impl<'a, S, F, P> StepContext<'a, S, F, P> {
    /// Step 0 at `t = 0` of length `dt`.
    pub fn new(sys: &'a mut S, force: &'a mut F, motion: &'a mut P, dt: f64) -> Self {
        StepContext {
            sys,
            force,
            motion,
            index: 0,
            t: 0.0,
            dt,
            u: &[],
        }
    }

    /// Moves to step `index` starting at `t`.
    pub fn at(&mut self, index: usize, t: f64) -> &mut Self {
        self.index = index;
        self.t = t;
        self
    }
}
