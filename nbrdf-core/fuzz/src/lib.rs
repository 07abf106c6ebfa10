//! Shared checks of the fuzz targets: every reflectance the readers accept must evaluate, single
//! and batched, to finite non-negative values at any pair of directions (the `Brdf` contract),
//! degenerate directions included.

use glam::Vec3;
use nbrdf_core::{Brdf, Directions, RgbMut};

/// `(light, view)` pairs every accepted table or network is evaluated at: ordinary ones, the
/// specular configuration, grazing and below-horizon ones, and degenerate vectors (zero,
/// non-unit, huge, tiny, NaN, infinite) that callers may pass.
pub fn fixed_pairs() -> Vec<(Vec3, Vec3)> {
    let up = Vec3::new(0.0, 0.0, 1.0);
    let a = Vec3::new(0.3, 0.2, 0.932_737_9);
    let b = Vec3::new(-0.5, 0.1, 0.860_232_5);
    let mirror = Vec3::new(-a.x, -a.y, a.z);
    let grazing = Vec3::new(1.0, 0.0, 1e-7);
    vec![
        (a, b),
        (b, a),
        (up, up),
        (a, mirror),
        (a, a),
        (grazing, up),
        (up, grazing),
        (grazing, Vec3::new(-1.0, 0.0, 1e-7)),
        (Vec3::new(0.0, 0.0, -1.0), up),
        (a, Vec3::new(0.3, 0.1, -0.2)),
        (Vec3::ZERO, up),
        (up, Vec3::ZERO),
        (3.0 * a, 0.25 * b),
        (1e30 * a, b),
        (a, 1e-30 * b),
        (Vec3::new(f32::MAX, 0.0, f32::MAX), up),
        (Vec3::new(f32::MIN_POSITIVE, 0.0, f32::MIN_POSITIVE), up),
        (Vec3::new(f32::NAN, 0.0, 1.0), up),
        (up, Vec3::new(0.0, f32::INFINITY, 1.0)),
        (Vec3::new(0.0, 0.0, f32::INFINITY), up),
    ]
}

/// Evaluates `brdf` at `pairs` one by one and as one batch; panics (a fuzzer finding) if any
/// value is negative, NaN or infinite, or above `max` (when the caller knows a bound).
/// Returns the single and the batched (cosine-weighted) values for further checks.
pub fn check_evaluations(
    brdf: &dyn Brdf,
    pairs: &[(Vec3, Vec3)],
    max: Option<f64>,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let in_range = |x: f32| x.is_finite() && x >= 0.0 && max.is_none_or(|m| f64::from(x) <= m);
    let single: Vec<[f32; 3]> = pairs
        .iter()
        .map(|&(light, view)| {
            let f = brdf.eval(view, light);
            assert!(
                f.iter().all(|&x| in_range(x)),
                "eval(light {light}, view {view}) = {f:?} (bound {max:?})"
            );
            f
        })
        .collect();
    let n = pairs.len();
    let mut light = vec![0.0f32; 3 * n];
    let mut view = vec![0.0f32; 3 * n];
    for (i, (l, v)) in pairs.iter().enumerate() {
        for k in 0..3 {
            light[k * n + i] = l[k];
            view[k * n + i] = v[k];
        }
    }
    let mut out = vec![-1.0f32; 3 * n];
    brdf.eval_cos_batch(
        Directions::from_planar(&view).expect("3 n long"),
        Directions::from_planar(&light).expect("3 n long"),
        RgbMut::from_planar(&mut out).expect("3 n long"),
    );
    let batch: Vec<[f32; 3]> = (0..n)
        .map(|i| [out[i], out[n + i], out[2 * n + i]])
        .collect();
    for (i, f) in batch.iter().enumerate() {
        assert!(
            f.iter().all(|&x| in_range(x)),
            "eval_cos_batch lane {i} (light {}, view {}) = {f:?} (bound {max:?})",
            pairs[i].0,
            pairs[i].1
        );
    }
    (single, batch)
}

/// Leaving out the hidden units that never fire changes no value: the pruned network of an
/// accepted one evaluates to the same numbers at every pair (`network/pruning.rs` proves units
/// dead for directions above the horizon; its float32 guards are what this checks).
pub fn check_pruning(net: &nbrdf_core::network::Nbrdf, pairs: &[(Vec3, Vec3)]) {
    let pruned = net.without_inactive_units();
    for &(light, view) in pairs {
        if !(light.is_finite() && view.is_finite() && light.z > 0.0 && view.z > 0.0) {
            continue;
        }
        let (full, fewer) = (net.eval(view, light), pruned.eval(view, light));
        assert!(
            full.iter().zip(&fewer).all(|(a, b)| a == b),
            "pruned {fewer:?}, full {full:?} at light {light}, view {view}"
        );
    }
}

/// A deterministic value in `(-1, 1)` for parameter `k` of a network drawn from `seed`
/// (splitmix64-like hash), so that a few input bytes describe hundreds of weights.
pub fn unit_value(seed: u64, k: u64) -> f32 {
    let mut z = seed.wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
}

/// `(light, view)` pairs near the horizon and near the normal at several azimuths: where a unit
/// alive only in a sliver of the domain would fire.
pub fn grazing_pairs() -> Vec<(Vec3, Vec3)> {
    let elevations = [1e-6f32, 1e-3, 0.05, 0.6, 1.5, std::f32::consts::FRAC_PI_2];
    let azimuths = [0.0f32, 1.0, std::f32::consts::PI, 4.0];
    let direction = |e: f32, a: f32| Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
    let mut pairs = Vec::new();
    for &el in &elevations {
        for &ev in &elevations {
            for &a in &azimuths {
                pairs.push((direction(el, a), direction(ev, 0.0)));
            }
        }
    }
    pairs
}

/// Directions from fuzzer-chosen components, so that odd values (NaN, subnormal, huge, signed
/// zeros) reach the evaluators beside [`fixed_pairs`].
pub fn pairs_from_components(components: &[[f32; 6]]) -> Vec<(Vec3, Vec3)> {
    components
        .iter()
        .map(|c| (Vec3::new(c[0], c[1], c[2]), Vec3::new(c[3], c[4], c[5])))
        .collect()
}

/// An error must say which file it is about (the reader is told a path; every message names it).
pub fn check_error_names_origin(error: &dyn std::fmt::Display, origin: &str) {
    let text = error.to_string();
    assert!(
        text.contains(origin),
        "error does not name the file {origin}: {text}"
    );
}

/// MERL grid: `theta_h x theta_d x phi_d` cells, three float64 channels after a 12-byte header.
pub const MERL_HEADER: [i32; 3] = [90, 90, 180];
pub const MERL_CELLS: usize = 90 * 90 * 180;
pub const MERL_FILE_SIZE: usize = 12 + 3 * MERL_CELLS * 8;
/// The largest of MERL's per-channel scale factors (blue: 1.66 / 1500), part of the format.
const MERL_MAX_SCALE: f64 = 1.66 / 1500.0;

/// The stored values of a MERL file (after the header), as float64.
pub fn merl_values(bytes: &[u8]) -> impl Iterator<Item = f64> + '_ {
    bytes[12..].chunks_exact(8).map(|chunk| {
        let mut raw = [0u8; 8];
        raw.copy_from_slice(chunk);
        f64::from_le_bytes(raw)
    })
}

/// What an accepted MERL file must be: the (90, 90, 180) header, exactly the right size, and
/// only finite values (negative ones mean "not measured"). Returns an upper bound of any
/// reflectance the table can return: interpolation only blends valid (non-negative) stored
/// values, so nothing may exceed the largest of them times the largest channel scale (with a
/// margin for rounding to float32).
pub fn assert_acceptable_merl(bytes: &[u8]) -> f64 {
    assert_eq!(
        bytes.len(),
        MERL_FILE_SIZE,
        "accepted a file of the wrong size"
    );
    let header: Vec<i32> = bytes[..12]
        .chunks_exact(4)
        .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    assert_eq!(header, MERL_HEADER, "accepted a wrong header");
    let mut largest = 0.0f64;
    for (k, v) in merl_values(bytes).enumerate() {
        assert!(
            v.is_finite(),
            "accepted the non-finite value {v} at value index {k}"
        );
        if v > largest {
            largest = v;
        }
    }
    largest * MERL_MAX_SCALE * (1.0 + 1e-6)
}

/// What an accepted RGL measurement must do: evaluate at `pairs` (degenerate ones included)
/// through the `Brdf` trait to finite non-negative values, single and batched alike (the trainer
/// and the plugins read it there), and, for unit directions, give Mitsuba's raw (possibly
/// slightly negative) `eval` finite values too.
pub fn check_rgl_measurement(
    measurement: &nbrdf_core::rgl::RglMeasurement,
    pairs: &[(Vec3, Vec3)],
) {
    let (single, batch) = check_evaluations(measurement, pairs, None);
    for (i, ((s, b), (light, view))) in single.iter().zip(&batch).zip(pairs).enumerate() {
        // The batch is cosine weighted; both clamp the same raw value, so zero must agree.
        assert_eq!(
            s.iter().map(|x| *x == 0.0).collect::<Vec<_>>(),
            b.iter().map(|x| *x == 0.0).collect::<Vec<_>>(),
            "pair {i} (light {light}, view {view}): eval {s:?} vs eval_cos_batch {b:?}"
        );
        let (view, light) = (view.normalize_or_zero(), light.normalize_or_zero());
        let raw = measurement.eval_cos_f32(view, light);
        assert!(
            raw.iter().all(|x| x.is_finite()),
            "eval_cos_f32(light {light}, view {view}) = {raw:?}"
        );
        check_spectral(measurement, view, light);
    }
}

/// A spectral measurement evaluated per wavelength: finite everywhere, and zero at wavelengths
/// outside the measured range or not finite.
fn check_spectral(measurement: &nbrdf_core::rgl::RglMeasurement, view: Vec3, light: Vec3) {
    let Some(spectra) = measurement.spectra() else {
        return;
    };
    let measured = spectra.wavelengths();
    let (first, last) = (measured[0], measured[measured.len() - 1]);
    let outside = [first - 1.0, last + 1.0, f32::NAN, f32::INFINITY, -f32::INFINITY];
    let inside = [first, last, 0.5 * (first + last), measured[measured.len() / 2]];
    let queries: Vec<f32> = outside.iter().chain(&inside).copied().collect();
    let mut out = vec![f32::NAN; queries.len()];
    measurement
        .eval_spectrum_cos_f32(view, light, &queries, &mut out)
        .expect("a spectral measurement evaluates per wavelength");
    assert!(
        out.iter().all(|x| x.is_finite()),
        "eval_spectrum_cos_f32(light {light}, view {view}, {queries:?}) = {out:?}"
    );
    for (q, v) in queries.iter().zip(&out) {
        assert!(
            (first..=last).contains(q) || *v == 0.0,
            "wavelength {q} outside {first}..{last} gave {v}"
        );
    }
}
