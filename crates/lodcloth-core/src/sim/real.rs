//! The two precisions the spring kernel runs in.
//!
//! f64 is the precision of every simulation today and always of estimation:
//! it differentiates recorded positions twice ((x₊ − 2x + x₋)/dt² at
//! dt ≈ 1e-4 s), and in f32 that second difference would be rounding noise
//! of the order of gravity itself. f32 holds twice the lanes per vector
//! register and half the bytes per node, for live instances that only need
//! to look right and stay within their level's error.
//!
//! Both precisions keep the kernel's promise: every operation is exactly
//! rounded IEEE arithmetic (`mul_add` is one fused multiply-add, in hardware
//! or in software), so every instruction set gives the same bits.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// A floating-point precision of the spring kernel: `f64` or `f32`.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + private::Sealed
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// −∞.
    const NEG_INFINITY: Self;
    /// The kernel's block width: springs evaluated together, one AVX-512
    /// register (8 f64, 16 f32), or two AVX2 registers.
    const LANES: usize;
    /// Name in tables and logs.
    const NAME: &'static str;

    /// `self · a + b` with one rounding.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// √self, exactly rounded (IEEE: the same bits on every instruction set).
    /// The kernel divides by it rather than use an approximate reciprocal
    /// square root (`vrsqrt14ps` and kin), whose bits are not specified and
    /// differ between instruction sets and vendors.
    fn sqrt(self) -> Self;
    /// The nearest value of this precision.
    fn from_f64(x: f64) -> Self;
    /// The exact f64 value.
    fn to_f64(self) -> f64;
}

mod private {
    pub trait Sealed {}
    impl Sealed for f64 {}
    impl Sealed for f32 {}
}

impl Real for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    const NEG_INFINITY: f64 = f64::NEG_INFINITY;
    const LANES: usize = 8;
    const NAME: &'static str = "f64";

    #[inline(always)]
    fn mul_add(self, a: f64, b: f64) -> f64 {
        f64::mul_add(self, a, b)
    }

    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }

    #[inline(always)]
    fn from_f64(x: f64) -> f64 {
        x
    }

    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
}

impl Real for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    const NEG_INFINITY: f32 = f32::NEG_INFINITY;
    const LANES: usize = 16;
    const NAME: &'static str = "f32";

    #[inline(always)]
    fn mul_add(self, a: f32, b: f32) -> f32 {
        f32::mul_add(self, a, b)
    }

    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }

    #[inline(always)]
    fn from_f64(x: f64) -> f32 {
        x as f32
    }

    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}
