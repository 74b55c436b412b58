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
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

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
    /// 1/√self for positive normal values, to about an ulp, from exactly
    /// rounded operations only (the same bits on every instruction set).
    fn inv_sqrt(self) -> Self;
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

/// First guess of 1/√x for f64 (Lomont's constant for the classic bit trick):
/// halving the exponent bits of x and subtracting from this constant gives
/// 1/√x within 3.5% for every positive normal x.
const INV_SQRT_MAGIC_64: u64 = 0x5FE6_EB50_C7B5_37A9;
/// The same constant for f32 (Lomont).
const INV_SQRT_MAGIC_32: u32 = 0x5F37_5A86;

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

    /// The kernel used `sqrt` and a division; 8-wide f64 `vsqrtpd`/`vdivpd`
    /// take ~16 cycles each and bounded the whole kernel. This uses only
    /// integer ops on the bits, multiplies and FMAs, which pipeline: four
    /// Newton steps from the bit-trick guess take the relative error
    /// 3.5e-2 → 1.8e-3 → 4.6e-6 → 3e-11 → below f64 rounding. No
    /// approximate-reciprocal instructions (`vrsqrt14pd`): their results are
    /// not specified to the bit and differ between instruction sets.
    #[inline(always)]
    fn inv_sqrt(self) -> f64 {
        let mut y = f64::from_bits(INV_SQRT_MAGIC_64 - (self.to_bits() >> 1));
        let half = 0.5 * self;
        for _ in 0..4 {
            // y ← y + y·(½ − ½x·y²): the correction form rounds better than
            // y·(3/2 − ½x·y²) once y is close.
            let e = (-half * y).mul_add(y, 0.5);
            y = y.mul_add(e, y);
        }
        y
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

    /// As for f64, three Newton steps: 3.5e-2 → 1.8e-3 → 4.6e-6 → 3e-11,
    /// below f32 rounding (6e-8).
    #[inline(always)]
    fn inv_sqrt(self) -> f32 {
        let mut y = f32::from_bits(INV_SQRT_MAGIC_32 - (self.to_bits() >> 1));
        let half = 0.5 * self;
        for _ in 0..3 {
            let e = (-half * y).mul_add(y, 0.5);
            y = y.mul_add(e, y);
        }
        y
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

#[cfg(test)]
mod tests {
    use super::Real;

    /// Largest relative error of `R::inv_sqrt` against 1/√x computed in
    /// f64 over many decades and mantissas.
    fn worst<R: Real>(decades: (f64, f64)) -> f64 {
        let mut worst: f64 = 0.0;
        let mut x = decades.0;
        while x < decades.1 {
            for m in [1.0, 1.234_567, 1.5, 1.999_999, 2.5, 3.999_999_9] {
                let v = R::from_f64(x * m);
                let exact = 1.0 / v.to_f64().sqrt();
                worst = worst.max(((v.inv_sqrt().to_f64() - exact) / exact).abs());
            }
            x *= 4.0;
        }
        worst
    }

    #[test]
    fn inv_sqrt_is_within_an_ulp_or_two_over_the_exponent_range() {
        let w64 = worst::<f64>((1e-24, 1e24));
        eprintln!("f64 inv_sqrt: largest relative error {w64:.2e}");
        assert!(w64 < 4.0 * f64::EPSILON, "{w64:e}");
        // f32 normals span 1e-38..3e38; squared lengths of a cloth stay far inside.
        let w32 = worst::<f32>((1e-30, 1e30));
        eprintln!("f32 inv_sqrt: largest relative error {w32:.2e}");
        assert!(w32 < 4.0 * f64::from(f32::EPSILON), "{w32:e}");
    }
}
