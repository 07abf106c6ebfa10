//! Branch-free `f32` arithmetic for the training kernels.
//!
//! `std`'s `ln` is a library call that stops the loops over a batch from vectorising, and the
//! loss needs one per output channel. The Cephes single-precision polynomial below is built from
//! arithmetic, bit casts and selects only, so it vectorises, and it is within a few ulp of `std`
//! (the tests check). The exponential is the evaluator's own ([`crate::network::fast_expm1`]).
//!
//! [`MulAdd`] lets the same kernel source compile to fused multiply-adds in the AVX2+FMA copy and
//! to separate multiplies and adds in the portable copy (where `f32::mul_add` would be a slow
//! library call).

/// `a * b + c`, fused or not.
pub trait MulAdd {
    fn mul_add(a: f32, b: f32, c: f32) -> f32;
}

/// Fused multiply-add, for code compiled with the `fma` target feature.
pub struct Fused;
/// Separate multiply and add, for any target.
pub struct Unfused;

impl MulAdd for Fused {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
}

impl MulAdd for Unfused {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
}

const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// Arguments of [`ln`] are clamped to at least this (a normal number), so that `ln(0)` is finite.
const LN_MIN_ARG: f32 = 1e-30;

/// Natural logarithm of `max(x, 1e-30)` for finite `x`.
#[inline(always)]
pub fn ln(x: f32) -> f32 {
    let x = x.max(LN_MIN_ARG);
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 126;
    // Mantissa in [0.5, 1).
    let m = f32::from_bits((bits & 0x807f_ffff) | 0x3f00_0000);
    let small = m < SQRT_HALF;
    e -= small as i32;
    let m = if small { m + m - 1.0 } else { m - 1.0 };
    let z = m * m;
    let mut y = 7.037_683_6e-2_f32;
    y = y * m - 1.151_461e-1;
    y = y * m + 1.167_699_9e-1;
    y = y * m - 1.242_014_1e-1;
    y = y * m + 1.424_932_3e-1;
    y = y * m - 1.666_805_8e-1;
    y = y * m + 2.000_071_4e-1;
    y = y * m - 2.499_999_4e-1;
    y = y * m + 3.333_333e-1;
    y *= m * z;
    let ef = e as f32;
    y += ef * -2.121_944_4e-4;
    y += -0.5 * z;
    m + y + ef * 0.693_359_4
}

/// `ln(1 + u)` for `u > -1`, accurate also for tiny `u`: with `q = 1 + u` rounded,
/// `ln(1 + u) = ln(q) + (u - (q - 1)) / q` to first order, the correction restoring what the
/// rounding of `q` lost (fdlibm's trick). Unlike the usual `u / (q - 1)` rescaling it needs no
/// branch, which keeps the loss loop vectorised.
#[inline(always)]
pub fn ln_1p(u: f32) -> f32 {
    let q = 1.0 + u;
    ln(q) + (u - (q - 1.0)) / q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_matches_std() {
        let mut x = 1e-30f32;
        while x < 1e30 {
            assert!(
                (ln(x) - x.ln()).abs() < 4e-7 * x.ln().abs().max(1.0),
                "ln({x})"
            );
            x *= 1.013;
        }
        assert!(ln(0.0).is_finite());
    }

    #[test]
    fn ln_1p_is_accurate_for_small_arguments() {
        for &u in &[1e-12f32, 3e-8, 1e-6, 1e-3, 0.5, 10.0, 1e6, -0.5, -0.999] {
            let expect = (u as f64).ln_1p();
            assert!(
                ((ln_1p(u) as f64 - expect) / expect).abs() < 1e-6,
                "ln_1p({u})"
            );
        }
    }
}
