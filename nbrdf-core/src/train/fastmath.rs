//! Branch-free `f32` arithmetic for the training kernels.
//!
//! `std`'s `exp` and `ln` are library calls that stop the loops over a batch from vectorising, and
//! the loss needs one of each per output channel. The Cephes single-precision polynomials below
//! are built from arithmetic, bit casts and selects only, so they vectorise, and they are within
//! a few ulp of `std` (the tests check), far below the noise of stochastic gradient descent.
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

/// Largest argument of [`exp`]: `2^127` is the largest power of two the bit construction can
/// build, so larger arguments are clamped (the network output then saturates, see
/// [`crate::train::mlp_grad`]).
pub const EXP_MAX_ARG: f32 = 88.0;
const EXP_MIN_ARG: f32 = -87.0;
/// `1.5 * 2^23`: adding it rounds to the nearest integer, which also lands in the low mantissa bits.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// `e^x`, `x` clamped to `[-87, 88]`.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    let x = x.clamp(EXP_MIN_ARG, EXP_MAX_ARG);
    let t = x * std::f32::consts::LOG2_E + ROUND_MAGIC;
    let n_bits = t.to_bits().wrapping_sub(ROUND_MAGIC.to_bits()) as i32;
    let n = t - ROUND_MAGIC;
    // x - n ln 2 in two parts (Cody-Waite) keeps the reduced argument exact to f32 precision.
    let r = x - n * 0.693_359_4 + n * 2.121_944_4e-4;
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e_r = p * r * r + r + 1.0;
    let scale = f32::from_bits(((n_bits + 127) as u32) << 23);
    e_r * scale
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

/// `ln(1 + u)` for `u > -1`, accurate also for tiny `u` (Goldberg's trick: the rounding of
/// `1 + u` cancels in `u / ((1 + u) - 1)`), so that the log-loss of nearly black materials is not
/// swamped by the rounding of `1 + f cos`.
#[inline(always)]
pub fn ln_1p(u: f32) -> f32 {
    let q = 1.0 + u;
    let d = q - 1.0;
    if d == 0.0 {
        u
    } else {
        ln(q) * (u / d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f32, b: f32) -> f32 {
        ((a - b) / b.abs().max(f32::MIN_POSITIVE)).abs()
    }

    #[test]
    fn exp_matches_std() {
        let mut x = -87.0f32;
        while x <= 88.0 {
            assert!(
                rel(exp(x), x.exp()) < 4e-7,
                "exp({x}) = {} vs {}",
                exp(x),
                x.exp()
            );
            x += 0.0137;
        }
        assert!(exp(1000.0).is_finite() && exp(-1000.0) >= 0.0);
    }

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
