//! The number type the tree recursions are written over. `f64` evaluates them; the
//! `tree_model!` compiler runs the very same code over a tracing scalar that records each
//! operation, folding constants and dropping structural zeros, and emits the record as
//! straight-line Rust.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A real number as the recursions use it.
pub trait Scalar:
    Copy
    + Debug
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    /// A constant known when the model is built (a link length, a mass, 0, 1).
    fn constant(x: f64) -> Self;

    /// `(sin x, cos x)`.
    fn sin_cos(self) -> (Self, Self);

    /// `√x` (distances of springs and dampers).
    fn sqrt(self) -> Self;

    /// `1/x`.
    fn recip(self) -> Self;

    /// `0`.
    #[inline(always)]
    fn zero() -> Self {
        Self::constant(0.0)
    }

    /// `self·a + b`; with `FUSED`, rounded once where the number type can (`f64`: a fused
    /// multiply-add, for code compiled for a CPU that has one — elsewhere it is a library
    /// call).
    #[inline(always)]
    fn multiply_add<const FUSED: bool>(self, a: Self, b: Self) -> Self {
        self * a + b
    }
}

impl Scalar for f64 {
    #[inline(always)]
    fn constant(x: f64) -> Self {
        x
    }

    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }

    #[inline(always)]
    fn recip(self) -> Self {
        1.0 / self
    }

    #[inline(always)]
    fn multiply_add<const FUSED: bool>(self, a: Self, b: Self) -> Self {
        if FUSED {
            f64::mul_add(self, a, b)
        } else {
            self * a + b
        }
    }
}
