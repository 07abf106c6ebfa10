//! From spectra to colour: the CIE 1931 2-degree standard observer and the CIE D65 illuminant as
//! Mitsuba 3.9 tabulates them (`src/core/spectrum.cpp`'s `cie1931_tbl` and
//! `include/mitsuba/core/spectrum.h`'s `d65_table`: 95 samples every 5 nm from 360 to 830 nm, read
//! with linear interpolation by `cie1931_xyz` and `cie_d65`, zero outside), and the projection of
//! a sampled reflectance spectrum to linear sRGB (docs/design.md section 9).
//!
//! A reflectance spectrum `s` given at wavelengths `l_0 < ... < l_{n-1}` is the piecewise-linear
//! function through those samples, zero outside `[l_0, l_{n-1}]`. Its linear sRGB value is
//! `XYZ_TO_SRGB * int x(l) D65(l) s(l) dl / int y(l) dl` (`x` the colour matching functions): the
//! reflectance seen under a white (D65) light, which is how Mitsuba turns a reflectance spectrum
//! into RGB (`spectrum_list_to_srgb` with `d65 = true`, what `Properties` does for spectral
//! reflectance in RGB variants) and what a spectral render of that reflectance under Mitsuba's
//! white emitters (D65 in spectral variants) converges to. Unlike `spectrum_list_to_srgb`, whose
//! 1000-point sum approximates it, the integral here is exact: on each interval between the
//! 5 nm grid and the sample wavelengths the integrand is a cubic, which Simpson's rule integrates
//! exactly. A constant spectrum of 1 over the whole range projects to white, (1, 1, 1) within
//! 3e-4 (the rounding of the constants in the tables).

use crate::error::{NbrdfError, Result};

/// The observer's range in nm (`MI_CIE_MIN`, `MI_CIE_MAX`) and its number of samples.
pub const CIE_MIN: f64 = 360.0;
pub const CIE_MAX: f64 = 830.0;
const CIE_SAMPLES: usize = 95;
const CIE_STEP: f64 = (CIE_MAX - CIE_MIN) / (CIE_SAMPLES - 1) as f64;

/// `MI_CIE_Y_NORMALIZATION`: a spectrum of 1 has luminance 1 (without the illuminant).
const Y_NORMALIZATION: f64 = 1.0 / 106.750_259_399_414_06;
/// `MI_CIE_D65_NORMALIZATION`: D65 scaled to luminance 1.
const D65_NORMALIZATION: f64 = 1.0 / 98.997_417_518_762_55;

/// CIE 1931 x, y, z colour matching functions at 360, 365, ..., 830 nm (Mitsuba's `cie1931_tbl`).
#[allow(clippy::excessive_precision)]
const CIE_1931: [[f32; CIE_SAMPLES]; 3] = [
    [
        0.0001299,
        0.0002321,
        0.0004149,
        0.0007416,
        0.001368,
        0.002236,
        0.004243,
        0.00765,
        0.01431,
        0.02319,
        0.04351,
        0.07763,
        0.13438,
        0.21477,
        0.2839,
        0.3285,
        0.34828,
        0.34806,
        0.3362,
        0.3187,
        0.2908,
        0.2511,
        0.19536,
        0.1421,
        0.09564,
        0.05795001,
        0.03201,
        0.0147,
        0.0049,
        0.0024,
        0.0093,
        0.0291,
        0.06327,
        0.1096,
        0.1655,
        0.2257499,
        0.2904,
        0.3597,
        0.4334499,
        0.5120501,
        0.5945,
        0.6784,
        0.7621,
        0.8425,
        0.9163,
        0.9786,
        1.0263,
        1.0567,
        1.0622,
        1.0456,
        1.0026,
        0.9384,
        0.8544499,
        0.7514,
        0.6424,
        0.5419,
        0.4479,
        0.3608,
        0.2835,
        0.2187,
        0.1649,
        0.1212,
        0.0874,
        0.0636,
        0.04677,
        0.0329,
        0.0227,
        0.01584,
        0.01135916,
        0.008110916,
        0.005790346,
        0.004109457,
        0.002899327,
        0.00204919,
        0.001439971,
        0.0009999493,
        0.0006900786,
        0.0004760213,
        0.0003323011,
        0.0002348261,
        0.0001661505,
        0.000117413,
        8.307527e-05,
        5.870652e-05,
        4.150994e-05,
        2.935326e-05,
        2.067383e-05,
        1.455977e-05,
        1.025398e-05,
        7.221456e-06,
        5.085868e-06,
        3.581652e-06,
        2.522525e-06,
        1.776509e-06,
        1.251141e-06,
    ],
    [
        3.917e-06, 6.965e-06, 1.239e-05, 2.202e-05, 3.9e-05, 6.4e-05, 0.00012, 0.000217, 0.000396,
        0.00064, 0.00121, 0.00218, 0.004, 0.0073, 0.0116, 0.01684, 0.023, 0.0298, 0.038, 0.048,
        0.06, 0.0739, 0.09098, 0.1126, 0.13902, 0.1693, 0.20802, 0.2586, 0.323, 0.4073, 0.503,
        0.6082, 0.71, 0.7932, 0.862, 0.9148501, 0.954, 0.9803, 0.9949501, 1.0, 0.995, 0.9786,
        0.952, 0.9154, 0.87, 0.8163, 0.757, 0.6949, 0.631, 0.5668, 0.503, 0.4412, 0.381, 0.321,
        0.265, 0.217, 0.175, 0.1382, 0.107, 0.0816, 0.061, 0.04458, 0.032, 0.0232, 0.017, 0.01192,
        0.00821, 0.005723, 0.004102, 0.002929, 0.002091, 0.001484, 0.001047, 0.00074, 0.00052,
        0.0003611, 0.0002492, 0.0001719, 0.00012, 8.48e-05, 6e-05, 4.24e-05, 3e-05, 2.12e-05,
        1.499e-05, 1.06e-05, 7.4657e-06, 5.2578e-06, 3.7029e-06, 2.6078e-06, 1.8366e-06,
        1.2934e-06, 9.1093e-07, 6.4153e-07, 4.5181e-07,
    ],
    [
        0.0006061,
        0.001086,
        0.001946,
        0.003486,
        0.006450001,
        0.01054999,
        0.02005001,
        0.03621,
        0.06785001,
        0.1102,
        0.2074,
        0.3713,
        0.6456,
        1.0390501,
        1.3856,
        1.62296,
        1.74706,
        1.7826,
        1.77211,
        1.7441,
        1.6692,
        1.5281,
        1.28764,
        1.0419,
        0.8129501,
        0.6162,
        0.46518,
        0.3533,
        0.272,
        0.2123,
        0.1582,
        0.1117,
        0.07824999,
        0.05725001,
        0.04216,
        0.02984,
        0.0203,
        0.0134,
        0.008749999,
        0.005749999,
        0.0039,
        0.002749999,
        0.0021,
        0.0018,
        0.001650001,
        0.0014,
        0.0011,
        0.001,
        0.0008,
        0.0006,
        0.00034,
        0.00024,
        0.00019,
        0.0001,
        4.999999e-05,
        3e-05,
        2e-05,
        1e-05,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
];

/// CIE D65, relative to its power at 560 nm, at 360, 365, ..., 830 nm (Mitsuba's `d65_table`).
#[allow(clippy::excessive_precision)]
const D65: [f32; CIE_SAMPLES] = [
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015, 82.7549, 87.1204,
    91.486, 92.4589, 93.4318, 90.057, 86.6823, 95.7736, 104.865, 110.936, 117.008, 117.41, 117.812,
    116.336, 114.861, 115.392, 115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802,
    106.296, 104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046, 102.023, 100.0, 98.1671,
    96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459, 90.0062, 89.8026, 89.5991, 88.6489,
    87.6987, 85.4936, 83.2886, 83.4939, 83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462,
    82.2778, 80.281, 78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765, 61.604,
    65.7448, 69.8856, 72.4863, 75.087, 69.3398, 63.5927, 55.0054, 46.4182, 56.6118, 66.8054,
    65.0941, 63.3828, 63.8434, 64.304, 61.8779, 59.4519, 55.7054, 51.959, 54.6998, 57.4406,
    58.8765, 60.3125,
];

/// XYZ to linear sRGB (ITU-R BT.709 primaries, D65 white), Mitsuba's `xyz_to_srgb`.
const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.240479, -1.537150, -0.498535],
    [-0.969256, 1.875991, 0.041556],
    [0.055648, -0.204043, 1.057311],
];

/// `x(l) D65(l)` for the three colour matching functions at wavelength `l` (nm), each table read
/// with linear interpolation as `cie1931_xyz` and `cie_d65` do; zero outside the observer's range.
pub(crate) fn weighted_cmf(l: f64) -> [f64; 3] {
    if !(CIE_MIN..=CIE_MAX).contains(&l) {
        return [0.0; 3];
    }
    let t = (l - CIE_MIN) / CIE_STEP;
    let i = (t as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i as f64;
    let lerp = |table: &[f32; CIE_SAMPLES]| {
        (1.0 - w1) * f64::from(table[i]) + w1 * f64::from(table[i + 1])
    };
    let d65 = lerp(&D65) * D65_NORMALIZATION;
    [0, 1, 2].map(|c| lerp(&CIE_1931[c]) * d65)
}

/// The 5 nm grid of the tables, where `weighted_cmf` changes formula.
pub(crate) fn cie_grid() -> impl Iterator<Item = f64> {
    (0..CIE_SAMPLES).map(|i| CIE_MIN + i as f64 * CIE_STEP)
}

/// Linear sRGB of the integral `int x(l) D65(l) s(l) dl` of some reflectance `s` (the sums of
/// `weighted_cmf` times `s` a quadrature made): normalised so that a unit spectrum is white.
pub(crate) fn srgb_of_weighted_integral(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_SRGB.map(|row| Y_NORMALIZATION * (0..3).map(|j| row[j] * xyz[j]).sum::<f64>())
}

/// The linear map from the samples of a reflectance spectrum to its linear sRGB value under D65
/// (see the module documentation): one RGB weight per sample wavelength.
#[derive(Clone, Debug, PartialEq)]
pub struct SrgbProjection {
    weights: Vec<[f64; 3]>,
}

impl SrgbProjection {
    /// The projection of spectra sampled at `wavelengths` (nm): at least two, finite, strictly
    /// increasing, and overlapping the observer's 360-830 nm (else nothing would be seen).
    pub fn new(wavelengths: &[f64]) -> Result<SrgbProjection> {
        check_wavelengths(wavelengths, CIE_MIN, CIE_MAX)?;
        Ok(SrgbProjection {
            weights: projection_weights(wavelengths),
        })
    }

    /// The RGB weight of each sample wavelength.
    pub fn weights(&self) -> &[[f64; 3]] {
        &self.weights
    }

    /// The linear sRGB value of the spectrum with samples `values` (one per wavelength; extra
    /// values or missing ones are ignored: the common prefix counts).
    pub fn project(&self, values: &[f32]) -> [f64; 3] {
        let mut rgb = [0.0; 3];
        for (w, &v) in self.weights.iter().zip(values) {
            for c in 0..3 {
                rgb[c] += w[c] * f64::from(v);
            }
        }
        rgb
    }
}

/// Checks sample wavelengths (nm): at least two, finite, strictly increasing, and overlapping
/// `[lo, hi]` (else nothing of the spectrum would be seen).
pub(crate) fn check_wavelengths(wavelengths: &[f64], lo: f64, hi: f64) -> Result<()> {
    let invalid = |what: String| Err(NbrdfError::InvalidArgument(what));
    if wavelengths.len() < 2 {
        return invalid(format!(
            "{} wavelength(s); a spectrum needs at least 2",
            wavelengths.len()
        ));
    }
    if let Some(l) = wavelengths.iter().find(|l| !l.is_finite()) {
        return invalid(format!("wavelength {l} is not finite"));
    }
    if let Some(w) = wavelengths.windows(2).find(|w| w[0] >= w[1]) {
        return invalid(format!(
            "wavelengths are not strictly increasing ({} then {})",
            w[0], w[1]
        ));
    }
    let (first, last) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    if last <= lo || first >= hi {
        return invalid(format!(
            "wavelengths {first}-{last} nm do not overlap the visible range \
             {lo}-{hi} nm (not in nanometres?)"
        ));
    }
    Ok(())
}

/// The interval ends where the integrand changes formula: the 5 nm grid and the sample
/// wavelengths, within both ranges.
fn breakpoints(wavelengths: &[f64]) -> Vec<f64> {
    let lo = wavelengths[0].max(CIE_MIN);
    let hi = wavelengths[wavelengths.len() - 1].min(CIE_MAX);
    let mut points: Vec<f64> = cie_grid()
        .chain(wavelengths.iter().copied())
        .filter(|l| (lo..=hi).contains(l))
        .chain([lo, hi])
        .collect();
    points.sort_by(f64::total_cmp);
    points.dedup();
    points
}

/// Per sample wavelength, `XYZ_TO_SRGB * int x D65 hat_k / int y`, `hat_k` the piecewise-linear
/// hat of sample `k`. The caller has checked the wavelengths (sorted, overlapping the range).
fn projection_weights(wavelengths: &[f64]) -> Vec<[f64; 3]> {
    let mut xyz = vec![[0.0f64; 3]; wavelengths.len()];
    let mut k = 0;
    for span in breakpoints(wavelengths).windows(2) {
        let (a, b) = (span[0], span[1]);
        // The sample interval [l_k, l_{k+1}] holding [a, b].
        while wavelengths[k + 1] < b {
            k += 1;
        }
        let (l0, l1) = (wavelengths[k], wavelengths[k + 1]);
        // Simpson's rule, exact for the cubic x(l) D65(l) hat(l) on [a, b].
        for (l, simpson) in [(a, 1.0), (0.5 * (a + b), 4.0), (b, 1.0)] {
            let weight = simpson * (b - a) / 6.0;
            let t = (l - l0) / (l1 - l0);
            let cmf = weighted_cmf(l);
            for c in 0..3 {
                xyz[k][c] += weight * (1.0 - t) * cmf[c];
                xyz[k + 1][c] += weight * t * cmf[c];
            }
        }
    }
    xyz.into_iter().map(srgb_of_weighted_integral).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables' own sums (the 5 nm trapezoid rule Mitsuba's normalisation constants come
    /// from): y integrates to about 106.86, and D65 at 560 nm is 100.
    #[test]
    fn tables_are_the_cie_ones() {
        let trapezoid = |t: &[f32]| {
            CIE_STEP
                * (t.iter().map(|v| f64::from(*v)).sum::<f64>()
                    - 0.5 * f64::from(t[0] + t[CIE_SAMPLES - 1]))
        };
        assert!((trapezoid(&CIE_1931[1]) - 106.857).abs() < 0.01);
        assert_eq!(D65[40], 100.0);
        assert_eq!(CIE_1931[1][40], 0.995);
    }

    #[test]
    fn a_unit_spectrum_is_white() {
        let p = SrgbProjection::new(&[300.0, 500.0, 1000.0]).unwrap();
        let rgb = p.project(&[1.0, 1.0, 1.0]);
        for c in rgb {
            assert!((c - 1.0).abs() < 3e-4, "{rgb:?}");
        }
    }

    /// Linear in the samples, and a spectrum refined with extra samples on the same line
    /// projects to the same colour (the integral does not depend on where the breakpoints are).
    #[test]
    fn refining_a_piecewise_linear_spectrum_changes_nothing() {
        let coarse = SrgbProjection::new(&[380.0, 550.0, 780.0]).unwrap();
        let fine = SrgbProjection::new(&[380.0, 401.3, 550.0, 612.5, 700.0, 780.0]).unwrap();
        let line = |l: f64| (0.2 + (l - 380.0) / 400.0) as f32;
        let a = coarse.project(&[0.2, line(550.0), line(780.0)]);
        let b = fine.project(&[380.0, 401.3, 550.0, 612.5, 700.0, 780.0].map(line));
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() < 1e-6 * a[c].abs().max(1.0),
                "{a:?} vs {b:?}"
            );
        }
    }

    /// A narrow measured range sees only its part of the spectrum (zero outside it).
    #[test]
    fn outside_the_samples_the_spectrum_is_zero() {
        let p = SrgbProjection::new(&[600.0, 700.0]).unwrap();
        let red = p.project(&[1.0, 1.0]);
        assert!(red[0] > 0.5 && red[2] < 0.05, "{red:?}");
        let ir = SrgbProjection::new(&[830.0, 1000.0]);
        assert!(ir.unwrap_err().to_string().contains("visible range"));
    }

    #[test]
    fn refuses_bad_wavelengths() {
        for (wavelengths, needle) in [
            (vec![500.0], "at least 2"),
            (vec![500.0, f64::NAN], "not finite"),
            (vec![500.0, 400.0], "strictly increasing"),
            (vec![500.0, 500.0], "strictly increasing"),
            (vec![0.4, 0.7], "nanometres"),
        ] {
            let message = SrgbProjection::new(&wavelengths).unwrap_err().to_string();
            assert!(message.contains(needle), "{wavelengths:?}: {message}");
        }
    }
}
