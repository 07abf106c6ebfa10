//! The trainer's C ABI as a C caller sees it: directions, training from arrays, and bad calls
//! that must return an error status with a message, never panic.

use nbrdf_core::Nbrdf;
use nbrdf_train::*;
use std::ffi::{c_char, c_void, CStr, CString};
use std::path::Path;
use std::ptr::{null, null_mut};

mod common;
use common::{directions, last_error, planar_pairs, small_config, INVALID, NULL, OK};

/// Planar directions and Lambertian `f cos_light` values (albedo 0.6, 0.4, 0.2) for `config`.
struct Arrays {
    view: Vec<f32>,
    light: Vec<f32>,
    values: Vec<f32>,
    n: usize,
    n_validation: usize,
}

fn arrays(config: &NbrdfTrainConfig) -> Arrays {
    let (view, light, n, n_validation) = directions(config);
    let albedo = [0.6f32, 0.4, 0.2];
    let mut values = vec![0.0; 3 * n];
    for c in 0..3 {
        for i in 0..n {
            values[c * n + i] = albedo[c] / std::f32::consts::PI * light[2 * n + i];
        }
    }
    Arrays {
        view,
        light,
        values,
        n,
        n_validation,
    }
}

/// Calls `nbrdf_train_from_arrays`; the JSON text on success.
fn train(config: &NbrdfTrainConfig, a: &Arrays, name: *const c_char) -> Result<String, i32> {
    let source = c"closed-form Lambertian";
    let mut out: *mut c_char = null_mut();
    // SAFETY: the arrays hold 3 n floats each; strings are NUL-terminated.
    let status = unsafe {
        nbrdf_train_from_arrays(
            config,
            0,
            a.view.as_ptr(),
            a.light.as_ptr(),
            a.values.as_ptr(),
            null(),
            a.n,
            a.n_validation,
            name,
            source.as_ptr(),
            c"{\"renderer\": \"test\"}".as_ptr(),
            None,
            null_mut(),
            &mut out,
        )
    };
    if status != OK {
        assert!(out.is_null());
        return Err(status);
    }
    // SAFETY: a string from the library, freed once.
    let text = unsafe { CStr::from_ptr(out) }.to_str().unwrap().to_owned();
    unsafe { nbrdf_train_string_free(out) };
    Ok(text)
}

#[test]
fn directions_are_planar_unit_vectors_above_the_horizon() {
    let config = small_config();
    let a = arrays(&config);
    assert_eq!((a.n, a.n_validation), (2200, 200));
    for i in 0..a.n {
        for d in [&a.view, &a.light] {
            let (x, y, z) = (d[i], d[a.n + i], d[2 * a.n + i]);
            assert!(z > 0.0 && ((x * x + y * y + z * z).sqrt() - 1.0).abs() < 1e-5);
        }
    }
    let mut wrong = vec![0.0; 3 * (a.n - 1)];
    let mut wrong2 = wrong.clone();
    // SAFETY: 3 (n - 1) floats each.
    let status = unsafe {
        nbrdf_train_directions(&config, 0, a.n - 1, wrong.as_mut_ptr(), wrong2.as_mut_ptr())
    };
    assert_eq!(status, INVALID);
    assert!(
        last_error().contains("nbrdf_train_directions"),
        "{}",
        last_error()
    );
}

#[test]
fn arrays_of_a_lambertian_train_a_network_that_matches_it() {
    let config = NbrdfTrainConfig {
        max_epochs: 40,
        ..small_config()
    };
    let text = train(&config, &arrays(&config), c"lambert".as_ptr()).unwrap();
    let network = Nbrdf::from_json_str(&text, Path::new("ffi")).unwrap();
    assert_eq!(network.name, "lambert");
    let p = &network.provenance;
    assert_eq!(p["source_kind"], "distilled");
    assert_eq!(p["source"], "closed-form Lambertian");
    assert_eq!(p["distilled_from"]["renderer"], "test");
    assert_eq!(p["samples"], 2000);
    assert_eq!(p["validation_samples"], 200);
    // f_r at a few directions against albedo / pi.
    for (theta_v, theta_l, phi) in [(0.2f32, 0.5f32, 1.0f32), (0.9, 0.3, 2.5), (1.2, 1.0, 0.3)] {
        let view = glam::Vec3::new(theta_v.sin(), 0.0, theta_v.cos());
        let light = glam::Vec3::new(
            theta_l.sin() * phi.cos(),
            theta_l.sin() * phi.sin(),
            theta_l.cos(),
        );
        let f = network.eval_input(nbrdf_core::coords::network_input(view, light));
        for (c, albedo) in [0.6f32, 0.4, 0.2].iter().enumerate() {
            let expect = albedo / std::f32::consts::PI;
            assert!(
                (f[c] - expect).abs() < 0.15 * expect,
                "{f:?} at {theta_v} {theta_l} {phi}"
            );
        }
    }
}

/// Half vectors off the x-z plane among the first `n` pairs of planar directions.
fn off_plane_half_vectors(a: &Arrays) -> usize {
    planar_pairs(&a.view, &a.light, a.n)
        .into_iter()
        .filter(|&(v, l)| (v + l).normalize().y.abs() > 0.1)
        .count()
}

#[test]
fn an_anisotropic_config_draws_phi_h_and_trains_an_anisotropic_network() {
    let mut config = small_config();
    // SAFETY: a valid config.
    let status = unsafe { nbrdf_train_config_for_anisotropy(&mut config, 1, 1) };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!((config.anisotropic, config.samples), (1, 5 * 2000));
    let mut unscaled = small_config();
    // SAFETY: a valid config.
    assert_eq!(
        unsafe { nbrdf_train_config_for_anisotropy(&mut unscaled, 1, 0) },
        OK
    );
    assert_eq!((unscaled.anisotropic, unscaled.samples), (1, 2000));
    // Adaptive isotropic pairs keep the half vector in the x-z plane; anisotropic ones do not.
    let isotropic = arrays(&small_config());
    assert_eq!(off_plane_half_vectors(&isotropic), 0);
    let a = arrays(&unscaled);
    assert!(
        off_plane_half_vectors(&a) > a.n / 2,
        "{}",
        off_plane_half_vectors(&a)
    );
    let text = train(&unscaled, &a, c"aniso".as_ptr()).unwrap();
    let network = Nbrdf::from_json_str(&text, Path::new("ffi")).unwrap();
    assert!(network.anisotropic);
    let text = train(&small_config(), &isotropic, c"iso".as_ptr()).unwrap();
    assert!(
        !Nbrdf::from_json_str(&text, Path::new("ffi"))
            .unwrap()
            .anisotropic
    );
    // Bad flags are errors that leave the config as it was.
    let before = unscaled;
    // SAFETY: a valid config; null is rejected.
    unsafe {
        assert_eq!(
            nbrdf_train_config_for_anisotropy(&mut unscaled, 2, 0),
            INVALID
        );
        assert!(last_error().contains("anisotropic"), "{}", last_error());
        assert_eq!(
            nbrdf_train_config_for_anisotropy(&mut unscaled, 0, -1),
            INVALID
        );
        assert_eq!(nbrdf_train_config_for_anisotropy(null_mut(), 0, 0), NULL);
    }
    assert_eq!(unscaled, before);
}

#[test]
fn bad_calls_return_an_error_status_with_a_message() {
    let config = small_config();
    let good = arrays(&config);
    let name = c"x";
    let mut out: *mut c_char = null_mut();
    let call = |config: *const NbrdfTrainConfig,
                fold: i32,
                view: *const f32,
                light: *const f32,
                values: *const f32,
                n: usize,
                n_validation: usize,
                out: *mut *mut c_char| {
        // SAFETY: the arrays are valid for 3 n floats or null (which the library rejects).
        unsafe {
            nbrdf_train_from_arrays(
                config,
                fold,
                view,
                light,
                values,
                null(),
                n,
                n_validation,
                name.as_ptr(),
                c"s".as_ptr(),
                null(),
                None,
                null_mut(),
                out,
            )
        }
    };
    let (v, l, f) = (
        good.view.as_ptr(),
        good.light.as_ptr(),
        good.values.as_ptr(),
    );
    let (n, nv) = (good.n, good.n_validation);
    let out_ptr: *mut *mut c_char = &mut out;
    type Case<'a> = (Box<dyn Fn() -> i32 + 'a>, i32, &'a str);
    let cases: Vec<Case> = vec![
        (
            boxed(|| call(null(), 0, v, l, f, n, nv, out_ptr)),
            NULL,
            "config",
        ),
        (
            boxed(|| call(&config, 0, null(), l, f, n, nv, out_ptr)),
            NULL,
            "view",
        ),
        (
            boxed(|| call(&config, 0, v, l, null(), n, nv, out_ptr)),
            NULL,
            "eval_cos",
        ),
        (
            boxed(|| call(&config, 0, v, l, f, n, nv, null_mut())),
            NULL,
            "out_json",
        ),
        (
            boxed(|| call(&config, 0, v, l, f, 0, 0, out_ptr)),
            INVALID,
            "validation",
        ),
        (
            boxed(|| call(&config, 0, v, l, f, n, 0, out_ptr)),
            INVALID,
            "validation",
        ),
        (
            boxed(|| call(&config, 0, v, l, f, n, n, out_ptr)),
            INVALID,
            "validation",
        ),
        (
            boxed(|| call(&config, 7, v, l, f, n, nv, out_ptr)),
            INVALID,
            "fold",
        ),
        // The reciprocal mean without the swapped values.
        (
            boxed(|| call(&config, 1, v, l, f, n, nv, out_ptr)),
            NULL,
            "swapped_eval_cos",
        ),
        (
            boxed(|| call(&config, 0, v, l, f, usize::MAX, nv, out_ptr)),
            INVALID,
            "too large",
        ),
    ];
    for (i, (case, expect, needle)) in cases.into_iter().enumerate() {
        let status = case();
        assert_eq!(status, expect, "case {i}: {}", last_error());
        let message = last_error();
        assert!(
            message.starts_with("nbrdf_train_from_arrays: ") && message.contains(needle),
            "case {i}: {message}"
        );
        assert!(out.is_null());
    }
    // NaN from the source: an error naming the pair, no network.
    let mut nan = arrays(&config);
    nan.values[good.n + 17] = f32::NAN;
    assert_eq!(train(&config, &nan, name.as_ptr()), Err(INVALID));
    assert!(last_error().contains("pair 17"), "{}", last_error());
    // Settings out of range, a bad sampling, an empty name, bad details JSON.
    for bad in [
        NbrdfTrainConfig {
            hidden: 0,
            ..config
        },
        NbrdfTrainConfig {
            learning_rate: f32::NAN,
            ..config
        },
        NbrdfTrainConfig {
            sampling: 9,
            ..config
        },
        NbrdfTrainConfig {
            anisotropic: 2,
            ..config
        },
    ] {
        assert_eq!(train(&bad, &good, name.as_ptr()), Err(INVALID));
        assert!(!last_error().is_empty());
    }
    assert_eq!(train(&config, &good, c"".as_ptr()), Err(INVALID));
    assert_eq!(train(&config, &good, null()), Err(NULL));
    let mut counts = (0usize, 0usize);
    let bad_fraction = NbrdfTrainConfig {
        validation_fraction: 0.0,
        ..config
    };
    // SAFETY: valid pointers.
    let status = unsafe { nbrdf_train_sample_counts(&bad_fraction, &mut counts.0, &mut counts.1) };
    assert_eq!(status, INVALID);
    assert!(
        last_error().contains("validation fraction"),
        "{}",
        last_error()
    );
    // SAFETY: null outputs are rejected.
    assert_eq!(
        unsafe { nbrdf_train_sample_counts(&config, null_mut(), &mut counts.1) },
        NULL
    );
    assert_eq!(unsafe { nbrdf_train_config_default(null_mut()) }, NULL);
    // SAFETY: null is accepted.
    unsafe { nbrdf_train_string_free(null_mut()) };
}

fn boxed<'a>(f: impl Fn() -> i32 + 'a) -> Box<dyn Fn() -> i32 + 'a> {
    Box::new(f)
}

unsafe extern "C" fn count_epochs(user: *mut c_void, stats: *const NbrdfEpochStats) {
    // SAFETY: the test passes a &mut Vec<usize> and the library a valid stats pointer.
    unsafe { (*(user as *mut Vec<usize>)).push((*stats).epoch) };
}

#[test]
fn the_callback_sees_every_epoch() {
    let config = small_config();
    let a = arrays(&config);
    // A Lambertian's swapped value f(light, view) cos_view.
    let mut swapped = a.values.clone();
    for c in 0..3 {
        for i in 0..a.n {
            swapped[c * a.n + i] *= a.view[2 * a.n + i] / a.light[2 * a.n + i];
        }
    }
    let mut epochs: Vec<usize> = Vec::new();
    let mut out: *mut c_char = null_mut();
    // SAFETY: valid arrays, strings and callback.
    let status = unsafe {
        nbrdf_train_from_arrays(
            &config,
            1,
            a.view.as_ptr(),
            a.light.as_ptr(),
            a.values.as_ptr(),
            swapped.as_ptr(),
            a.n,
            a.n_validation,
            c"cb".as_ptr(),
            c"s".as_ptr(),
            null(),
            Some(count_epochs),
            (&mut epochs as *mut Vec<usize>).cast(),
            &mut out,
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(epochs, vec![1, 2, 3]);
    let text = unsafe { CStr::from_ptr(out) }.to_str().unwrap().to_owned();
    unsafe { nbrdf_train_string_free(out) };
    assert!(
        text.contains("\"reciprocity\": \"reciprocal-mean\""),
        "{text}"
    );
    let _ = CString::new(text).unwrap();
}
