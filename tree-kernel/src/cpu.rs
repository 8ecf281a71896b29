//! Which variant of the generated code this CPU runs. `tree_model!` compiles each program
//! twice from one body per function ([`MulAdd`]; a lean model, once): as recorded, and on
//! x86-64 for AVX2 and FMA — over `f64` with every
//! product that one sum alone reads fused into it (`a·b + c` rounded once, `f64::mul_add`),
//! over dual numbers and jets as recorded. The second ("fused") variant runs where the CPU
//! has those instructions (every aarch64 CPU has them); both equal the interpreted runtime
//! to rounding (tests/generated.rs runs both).

use std::sync::atomic::{AtomicU8, Ordering};

const UNKNOWN: u8 = 0;
const PLAIN: u8 = 1;
const FUSED: u8 = 2;

/// The choice, made on the first call (or forced by [`force_plain`]).
static CHOICE: AtomicU8 = AtomicU8::new(UNKNOWN);

/// Keeps the one item or statement it wraps only where some CPU the build targets lacks the
/// fused variant's instructions; elsewhere (aarch64, or x86-64 built for AVX2 and FMA, e.g.
/// `-C target-cpu=x86-64-v3`) it is not compiled. `tree_model!` wraps each function of the
/// recorded variant and its call in it, and [`FUSED_ONLY`] is read from it: the condition is
/// written here alone.
#[doc(hidden)]
#[macro_export]
macro_rules! __unless_fused_only {
    ($($one_item_or_statement:tt)*) => {
        #[cfg(not(any(
            target_arch = "aarch64",
            all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma")
        )))]
        $($one_item_or_statement)*
    };
}

/// Whether every CPU this build targets runs the fused variant (aarch64, or x86-64 built
/// for AVX2 and FMA): `tree_model!` then compiles that variant alone, which halves the
/// generated code's build time.
pub const FUSED_ONLY: bool = !recorded_variant_compiled();

/// Whether [`__unless_fused_only`] keeps what it wraps.
#[allow(unused_mut, unused_assignments)]
const fn recorded_variant_compiled() -> bool {
    let mut compiled = false;
    crate::__unless_fused_only! { { compiled = true; } }
    compiled
}

/// Whether the generated code's fused variant runs here: detected once, then one load.
#[inline]
pub fn fused() -> bool {
    if FUSED_ONLY {
        return true;
    }
    match CHOICE.load(Ordering::Relaxed) {
        FUSED => true,
        PLAIN => false,
        _ => {
            let choice = if detected() { FUSED } else { PLAIN };
            CHOICE.store(choice, Ordering::Relaxed);
            choice == FUSED
        }
    }
}

/// Whether the CPU runs the fused variant: AVX2 and FMA on x86-64; always on aarch64.
fn detected() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(target_arch = "aarch64")]
    {
        true
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        false
    }
}

/// Runs the recorded (unfused) variant from now on (`true`), or the one the CPU supports
/// again (`false`): for tests that compare the two. Process-wide; no effect where
/// [`FUSED_ONLY`] (there is no recorded variant).
pub fn force_plain(plain: bool) {
    let choice = if !plain && detected() { FUSED } else { PLAIN };
    CHOICE.store(choice, Ordering::Relaxed);
}

/// How a generated function's fused multiply-adds are computed: its body is written once,
/// generic over this, and compiled twice — `a·b + c` rounded twice ([`Plain`], the recorded
/// operations) and once ([`Fused`], inside a function built for AVX2 and FMA). One body
/// halves what the compiler checks.
#[doc(hidden)]
pub trait MulAdd {
    /// `a·b + c`.
    fn mul_add(a: f64, b: f64, c: f64) -> f64;
}

/// `a·b + c` as two operations, each rounded: the recorded computation.
#[doc(hidden)]
pub struct Plain;

/// `a·b + c` rounded once (`f64::mul_add`: one instruction where the caller is built for FMA).
#[doc(hidden)]
pub struct Fused;

impl MulAdd for Plain {
    #[inline(always)]
    fn mul_add(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

impl MulAdd for Fused {
    #[inline(always)]
    fn mul_add(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}
