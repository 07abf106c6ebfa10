//! Branch-free `f32` arithmetic shared by the evaluation and training kernels: the exponential
//! of the network's output layer and the logarithm of the training loss.
//!
//! `std`'s `exp` and `ln` are library calls that stop the loops over a batch from vectorising.
//! The versions here are built from arithmetic, bit casts and selects only, so they vectorise,
//! and they are within a few ulp of `std` (the tests check).
//!
//! [`MulAdd`] lets the same kernel source compile to fused multiply-adds in the AVX2+FMA copy and
//! to separate multiplies and adds in the portable copy (where `f32::mul_add` would be a slow
//! library call).

/// `a * b + c`, fused or not, on one value or on eight.
pub trait MulAdd {
    /// Eight `f32` lanes: an AVX register in the fused copy on x86-64, an array elsewhere.
    type V8: Copy;
    fn mul_add(a: f32, b: f32, c: f32) -> f32;
    /// # Safety
    /// For [`Fused`] on x86-64 the CPU has AVX2 and FMA (its eight-lane operations are those
    /// instructions).
    unsafe fn splat8(a: f32) -> Self::V8;
    /// # Safety
    /// `p` must point to 8 readable `f32`; the CPU as for [`MulAdd::splat8`].
    unsafe fn load8(p: *const f32) -> Self::V8;
    /// `a * b + c` per lane, each lane exactly [`MulAdd::mul_add`].
    ///
    /// # Safety
    /// The CPU as for [`MulAdd::splat8`].
    unsafe fn mul_add8(a: Self::V8, b: Self::V8, c: Self::V8) -> Self::V8;
    fn to_array8(v: Self::V8) -> [f32; 8];
}

/// Fused multiply-add, for code compiled with the `fma` target feature (one rounding, one
/// instruction). Its eight-lane operations are AVX2 and FMA instructions on x86-64, so they are
/// `unsafe`: only code compiled for and dispatched to AVX2 and FMA calls them.
pub struct Fused;
/// Separate multiply and add, for any target.
pub struct Unfused;

impl MulAdd for Fused {
    #[cfg(target_arch = "x86_64")]
    type V8 = core::arch::x86_64::__m256;
    #[cfg(not(target_arch = "x86_64"))]
    type V8 = [f32; 8];

    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }

    #[inline(always)]
    unsafe fn splat8(a: f32) -> Self::V8 {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX2, by the caller's contract.
        unsafe {
            core::arch::x86_64::_mm256_set1_ps(a)
        }
        #[cfg(not(target_arch = "x86_64"))]
        [a; 8]
    }

    #[inline(always)]
    unsafe fn load8(p: *const f32) -> Self::V8 {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the caller's 8 readable floats; AVX2 by the caller's contract.
        unsafe {
            core::arch::x86_64::_mm256_loadu_ps(p)
        }
        #[cfg(not(target_arch = "x86_64"))]
        // SAFETY: the caller's 8 readable floats.
        unsafe {
            p.cast::<[f32; 8]>().read_unaligned()
        }
    }

    #[inline(always)]
    unsafe fn mul_add8(a: Self::V8, b: Self::V8, c: Self::V8) -> Self::V8 {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: FMA, by the caller's contract.
        unsafe {
            core::arch::x86_64::_mm256_fmadd_ps(a, b, c)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut out = c;
            for q in 0..8 {
                out[q] = a[q].mul_add(b[q], c[q]);
            }
            out
        }
    }

    #[inline(always)]
    fn to_array8(v: Self::V8) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `__m256` and `[f32; 8]` have the same size, any bits are valid for both.
        unsafe {
            std::mem::transmute::<Self::V8, [f32; 8]>(v)
        }
        #[cfg(not(target_arch = "x86_64"))]
        v
    }
}

impl MulAdd for Unfused {
    type V8 = [f32; 8];

    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }

    #[inline(always)]
    unsafe fn splat8(a: f32) -> Self::V8 {
        [a; 8]
    }

    #[inline(always)]
    unsafe fn load8(p: *const f32) -> Self::V8 {
        // SAFETY: the caller's 8 readable floats.
        unsafe { p.cast::<[f32; 8]>().read_unaligned() }
    }

    #[inline(always)]
    unsafe fn mul_add8(a: Self::V8, b: Self::V8, c: Self::V8) -> Self::V8 {
        let mut out = c;
        for q in 0..8 {
            out[q] = a[q] * b[q] + c[q];
        }
        out
    }

    #[inline(always)]
    fn to_array8(v: Self::V8) -> [f32; 8] {
        v
    }
}

/// The exp argument is clamped here so that the output can never overflow to infinity
/// (`e^80 ~ 5.5e34`, far above any physical reflectance, far below `f32::MAX`).
pub const EXP_ARG_MAX: f32 = 80.0;
/// Below this `2^k` of the range reduction would leave the normal range.
pub const EXP_ARG_MIN: f32 = -87.0;

/// `1.5 * 2^23`: adding it rounds a float of magnitude below `2^22` to an integer and leaves that
/// integer in the low mantissa bits, which avoids a float-to-int conversion.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// `ln 2` split so that `k * LN2_HI` is exact for `|k| < 2^15` (Cody-Waite reduction).
const LN2_HI: f32 = 355.0 / 512.0;
const LN2_LO: f32 = -2.121_944_4e-4;

/// Clamps to the exp range; NaN goes to the lower end so that the result stays finite.
#[inline(always)]
fn clamp_exp_arg(z: f32) -> f32 {
    let z = if z > EXP_ARG_MIN { z } else { EXP_ARG_MIN };
    if z < EXP_ARG_MAX {
        z
    } else {
        EXP_ARG_MAX
    }
}

/// `z = k ln 2 + r` with `|r| <= ln 2 / 2`: returns `(2^k, expm1(r))`. Branch-free and
/// integer-conversion-free so that it vectorises; `expm1(r)` (not `exp(r)`) keeps full relative
/// accuracy for `z` near 0, where `exp(z) - 1` would cancel.
#[inline(always)]
fn exp_reduce<M: MulAdd>(z: f32) -> (f32, f32) {
    let z = clamp_exp_arg(z);
    let t = M::mul_add(z, std::f32::consts::LOG2_E, ROUND_MAGIC);
    let k = t - ROUND_MAGIC;
    let k_int = t.to_bits().wrapping_sub(ROUND_MAGIC.to_bits()) as i32;
    let scale = f32::from_bits((k_int.wrapping_add(127) as u32) << 23);
    let r = M::mul_add(-k, LN2_LO, M::mul_add(-k, LN2_HI, z));
    // Taylor series of expm1 to degree 7: the truncation error at |r| = ln 2 / 2 is ~1e-8 of the
    // result, below float32 rounding.
    let mut p = 1.0 / 5040.0;
    p = M::mul_add(p, r, 1.0 / 720.0);
    p = M::mul_add(p, r, 1.0 / 120.0);
    p = M::mul_add(p, r, 1.0 / 24.0);
    p = M::mul_add(p, r, 1.0 / 6.0);
    p = M::mul_add(p, r, 0.5);
    let expm1_r = M::mul_add(p * r, r, r);
    (scale, expm1_r)
}

/// `exp(z) - 1` as `2^k expm1(r) + (2^k - 1)`, with the multiply-adds of `M`.
#[inline(always)]
pub fn expm1_with<M: MulAdd>(z: f32) -> f32 {
    let (scale, expm1_r) = exp_reduce::<M>(z);
    M::mul_add(scale, expm1_r, scale - 1.0)
}

/// `exp(z) - 1` in float32, about 1e-7 relative error, with `z` clamped to
/// `[EXP_ARG_MIN, EXP_ARG_MAX]` (NaN to the lower end). Vectorises in loops over lanes.
#[inline]
pub fn fast_expm1(z: f32) -> f32 {
    expm1_with::<Unfused>(z)
}

/// `exp(z)` in float32, about 1e-7 relative error, same clamping as [`fast_expm1`].
#[inline]
pub fn fast_exp(z: f32) -> f32 {
    let (scale, expm1_r) = exp_reduce::<Unfused>(z);
    scale * expm1_r + scale
}

/// `max(v, 0)` written as a compare-select so that it maps to one `maxps` (NaN becomes 0).
#[inline(always)]
pub fn relu(v: f32) -> f32 {
    if v > 0.0 {
        v
    } else {
        0.0
    }
}

const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// Arguments of [`ln`] are clamped to at least this (a normal number), so that `ln(0)` is finite.
const LN_MIN_ARG: f32 = 1e-30;

/// Natural logarithm of `max(x, 1e-30)` for finite `x` (the Cephes single-precision polynomial).
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
    fn fast_exp_matches_f64_over_its_range() {
        let mut worst_exp = 0.0f64;
        let mut worst_expm1 = 0.0f64;
        let steps = 2_000_000;
        for s in 0..=steps {
            let z = (-87.0 + 167.0 * s as f64 / steps as f64) as f32;
            let z64 = f64::from(z);
            let e = f64::from(fast_exp(z));
            worst_exp = worst_exp.max((e - z64.exp()).abs() / z64.exp());
            let m = f64::from(fast_expm1(z));
            worst_expm1 =
                worst_expm1.max((m - z64.exp_m1()).abs() / z64.exp_m1().abs().max(1e-300));
        }
        // Tiny arguments, where exp(z) - 1 would lose everything.
        for z in [1e-30f32, -1e-20, 1e-7, -3e-5, 0.01, -0.3, 0.35] {
            let m = f64::from(fast_expm1(z));
            let want = f64::from(z).exp_m1();
            worst_expm1 = worst_expm1.max((m - want).abs() / want.abs());
        }
        assert!(worst_exp < 3e-7, "exp relative error {worst_exp:e}");
        assert!(worst_expm1 < 3e-7, "expm1 relative error {worst_expm1:e}");
        assert_eq!(fast_expm1(0.0), 0.0);
        assert!(fast_exp(f32::INFINITY).is_finite() && fast_exp(f32::NAN).is_finite());
        assert!(fast_expm1(1e30).is_finite() && fast_expm1(-1e30) >= -1.0);
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
