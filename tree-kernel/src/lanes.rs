//! Several states evaluated at once: [`Lanes`] is a [`Scalar`] of [`WIDTH`] independent
//! `f64`s, one per lane, each operation applied lane by lane. The kernel run over it walks
//! the plan once for all of them — one branch on a frame's kind, one load of its constants —
//! and the compiler gives the lanes' arithmetic to SIMD registers. Every lane goes through
//! exactly the operations an `f64` evaluation of its state does (IEEE-754 operations are
//! correctly rounded, and `sin_cos` is the same library call), so each lane's result has the
//! bits of that evaluation: batching changes the speed, never the numbers.
//!
//! ```
//! use tree_kernel::Lanes;
//! use tree_kernel::Scalar;
//! let x = Lanes([0.1, 0.7, -2.0, 1e3]);
//! let (s, c) = (x * x + Lanes::splat(0.5)).sin_cos();
//! for (k, &v) in x.0.iter().enumerate() {
//!     let (s1, c1) = (v * v + 0.5).sin_cos();
//!     assert_eq!((s.0[k].to_bits(), c.0[k].to_bits()), (s1.to_bits(), c1.to_bits()));
//! }
//! ```

use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

use crate::outputs::{Output, Sink};
use crate::scalar::Scalar;

/// How many states a [`Lanes`] carries: four `f64`s, one AVX2 register.
pub const WIDTH: usize = 4;

/// [`WIDTH`] independent values, operated on lane by lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(align(32))]
pub struct Lanes(pub [f64; WIDTH]);

impl Lanes {
    /// Every lane `x`.
    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        Lanes([x; WIDTH])
    }

    #[inline(always)]
    fn zip(self, o: Lanes, f: impl Fn(f64, f64) -> f64) -> Lanes {
        let mut out = self.0;
        for (x, y) in out.iter_mut().zip(o.0) {
            *x = f(*x, y);
        }
        Lanes(out)
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Lanes {
        let mut out = self.0;
        for x in &mut out {
            *x = f(*x);
        }
        Lanes(out)
    }
}

impl Add for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn add(self, o: Lanes) -> Lanes {
        self.zip(o, |x, y| x + y)
    }
}

impl Sub for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn sub(self, o: Lanes) -> Lanes {
        self.zip(o, |x, y| x - y)
    }
}

impl Mul for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn mul(self, o: Lanes) -> Lanes {
        self.zip(o, |x, y| x * y)
    }
}

impl Neg for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn neg(self) -> Lanes {
        self.map(|x| -x)
    }
}

impl AddAssign for Lanes {
    #[inline(always)]
    fn add_assign(&mut self, o: Lanes) {
        *self = *self + o;
    }
}

impl SubAssign for Lanes {
    #[inline(always)]
    fn sub_assign(&mut self, o: Lanes) {
        *self = *self - o;
    }
}

impl Scalar for Lanes {
    #[inline(always)]
    fn constant(x: f64) -> Self {
        Lanes::splat(x)
    }

    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (mut s, mut c) = ([0.0; WIDTH], [0.0; WIDTH]);
        for (k, x) in self.0.into_iter().enumerate() {
            (s[k], c[k]) = x.sin_cos();
        }
        (Lanes(s), Lanes(c))
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }

    #[inline(always)]
    fn recip(self) -> Self {
        self.map(|x| 1.0 / x)
    }
}

/// What the articulated-body step takes from the elements besides `τ`, in lanes: the model's
/// own generalized forces `F` (damping, dampers) and its springs' `∂L/∂q` (what
/// [`crate::kernel::elements_at`] adds; its other outputs are not kept).
#[derive(Clone, Debug)]
pub struct ElementForces {
    /// `F_i`, by variable.
    pub force: Vec<Lanes>,
    /// `∂L/∂q_i` of the springs, by variable.
    pub dl_dq: Vec<Lanes>,
}

impl ElementForces {
    /// Zeros for `n` variables.
    pub fn zeros(n: usize) -> Self {
        ElementForces {
            force: vec![Lanes::default(); n],
            dl_dq: vec![Lanes::default(); n],
        }
    }

    /// Every entry back to zero.
    pub fn clear(&mut self) {
        self.force.fill(Lanes::default());
        self.dl_dq.fill(Lanes::default());
    }
}

impl Sink<Lanes> for ElementForces {
    #[inline(always)]
    fn add(&mut self, at: Output, x: Lanes) {
        match at {
            Output::Force(i) => self.force[i] += x,
            Output::DlDq(i) => self.dl_dq[i] += x,
            _ => {}
        }
    }

    #[inline(always)]
    fn set(&mut self, at: Output, x: Lanes) {
        // As `Terms` does: written, not added (so a −0 stays −0, the same bits).
        match at {
            Output::Force(i) => self.force[i] = x,
            Output::DlDq(i) => self.dl_dq[i] = x,
            _ => {}
        }
    }
}

/// The energy alone, in lanes ([`crate::kernel::energy`]'s one output).
#[derive(Clone, Copy, Debug, Default)]
pub struct EnergySink(pub Lanes);

impl Sink<Lanes> for EnergySink {
    #[inline(always)]
    fn add(&mut self, at: Output, x: Lanes) {
        if at == Output::Energy {
            self.0 += x;
        }
    }

    #[inline(always)]
    fn set(&mut self, at: Output, x: Lanes) {
        if at == Output::Energy {
            self.0 = x;
        }
    }
}
