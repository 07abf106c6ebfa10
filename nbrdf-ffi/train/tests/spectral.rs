//! `nbrdf_train_spectral_from_arrays` as a C caller sees it: a short run gives a version-3
//! network that loads and matches a closed form per wavelength; bad calls return an error
//! status with a message naming the problem, never panic.

use nbrdf_core::brdf::Directions;
use nbrdf_core::Nbrdf;
use nbrdf_train::*;
use std::ffi::{c_char, CStr};
use std::path::Path;
use std::ptr::{null, null_mut};

mod common;
use common::{directions, last_error, small_config, INVALID, NULL, OK};

/// A Lambertian whose albedo rises linearly from 0.1 at 360 nm to 0.7 at 830 nm.
fn albedo(lambda: f32) -> f32 {
    0.1 + 0.6 * (lambda - 360.0) / 470.0
}

/// Planar directions, 48 wavelengths (every 10 nm) and `f cos_light` at `[j n + i]`.
struct Spectra {
    view: Vec<f32>,
    light: Vec<f32>,
    wavelengths: Vec<f32>,
    values: Vec<f32>,
    n: usize,
    n_validation: usize,
}

fn spectra(config: &NbrdfTrainConfig) -> Spectra {
    let (view, light, n, n_validation) = directions(config);
    let wavelengths: Vec<f32> = (0..48).map(|j| 360.0 + 10.0 * j as f32).collect();
    let values = wavelengths
        .iter()
        .flat_map(|&l| {
            let light = &light;
            (0..n).map(move |i| albedo(l) / std::f32::consts::PI * light[2 * n + i])
        })
        .collect();
    Spectra {
        view,
        light,
        wavelengths,
        values,
        n,
        n_validation,
    }
}

/// The pointers and sizes of one call, each replaceable by a bad one.
#[derive(Clone, Copy)]
struct Call {
    config: *const NbrdfTrainConfig,
    fold: i32,
    view: *const f32,
    light: *const f32,
    wavelengths: *const f32,
    m: usize,
    eval_cos: *const f32,
    swapped: *const f32,
    n: usize,
    n_validation: usize,
    name: *const c_char,
    source: *const c_char,
    out_json: *mut *mut c_char,
}

impl Call {
    fn new(config: &NbrdfTrainConfig, s: &Spectra, out: &mut *mut c_char) -> Call {
        Call {
            config,
            fold: 0,
            view: s.view.as_ptr(),
            light: s.light.as_ptr(),
            wavelengths: s.wavelengths.as_ptr(),
            m: s.wavelengths.len(),
            eval_cos: s.values.as_ptr(),
            swapped: null(),
            n: s.n,
            n_validation: s.n_validation,
            name: c"spectral lambert".as_ptr(),
            source: c"closed form".as_ptr(),
            out_json: out,
        }
    }

    /// The status, and the JSON text on success.
    fn run(self) -> (i32, Option<String>) {
        // SAFETY: the pointers are valid for the sizes given, or null.
        let status = unsafe {
            nbrdf_train_spectral_from_arrays(
                self.config,
                self.fold,
                self.view,
                self.light,
                self.wavelengths,
                self.m,
                self.eval_cos,
                self.swapped,
                self.n,
                self.n_validation,
                self.name,
                self.source,
                c"{\"renderer\": \"test\"}".as_ptr(),
                None,
                null_mut(),
                self.out_json,
            )
        };
        if status != OK || self.out_json.is_null() {
            return (status, None);
        }
        // SAFETY: a string from the library, freed once.
        let out = unsafe { *self.out_json };
        let text = unsafe { CStr::from_ptr(out) }.to_str().unwrap().to_owned();
        unsafe { nbrdf_train_string_free(out) };
        (status, Some(text))
    }
}

#[test]
fn a_short_run_writes_a_version_3_network_that_matches_the_spectrum() {
    let config = NbrdfTrainConfig {
        max_epochs: 40,
        ..small_config()
    };
    let s = spectra(&config);
    let mut out = null_mut();
    let (status, text) = Call::new(&config, &s, &mut out).run();
    assert_eq!(status, OK, "{}", last_error());
    let text = text.unwrap();
    let raw: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(raw["version"], 3);
    assert_eq!(raw["spectral"]["count"], 16);
    let network = Nbrdf::from_json_str(&text, Path::new("ffi")).unwrap();
    assert_eq!(network.output_count(), 16);
    let p = &network.provenance;
    assert_eq!(p["source_kind"], "distilled");
    assert_eq!(p["spectral_target"]["wavelengths"], 48);
    // f_r cos at wavelengths between the samples, against the closed form.
    let (theta_v, theta_l, phi) = (0.4f32, 0.7f32, 2.0f32);
    let view = [theta_v.sin(), 0.0, theta_v.cos()];
    let light = [
        theta_l.sin() * phi.cos(),
        theta_l.sin() * phi.sin(),
        theta_l.cos(),
    ];
    let lambdas = [415.0f32, 502.5, 598.0, 733.0];
    let mut values = [0.0f32; 4];
    let d = |v: &[f32; 3]| [[v[0]], [v[1]], [v[2]]];
    let (vd, ld) = (d(&view), d(&light));
    fn dirs(a: &[[f32; 1]; 3]) -> Directions<'_> {
        Directions {
            x: &a[0],
            y: &a[1],
            z: &a[2],
        }
    }
    network
        .eval_spectral_cos_batch(dirs(&vd), dirs(&ld), &lambdas, &mut values)
        .unwrap();
    for (l, v) in lambdas.iter().zip(values) {
        let expect = albedo(*l) / std::f32::consts::PI * light[2];
        assert!(
            (v - expect).abs() < 0.15 * expect,
            "{l} nm: {v} vs {expect}"
        );
    }
}

#[test]
fn bad_calls_return_an_error_status_naming_the_problem() {
    let config = small_config();
    let s = spectra(&config);
    let mut out = null_mut();
    let good = Call::new(&config, &s, &mut out);
    let check = |call: Call, status: i32, message: &str| {
        let (got, text) = call.run();
        assert_eq!(got, status, "{message}: {}", last_error());
        assert!(text.is_none());
        let error = last_error();
        assert!(
            error.contains("nbrdf_train_spectral_from_arrays") && error.contains(message),
            "{message}: {error}"
        );
    };
    check(
        Call {
            config: null(),
            ..good
        },
        NULL,
        "config",
    );
    check(
        Call {
            view: null(),
            ..good
        },
        NULL,
        "view",
    );
    check(
        Call {
            light: null(),
            ..good
        },
        NULL,
        "light",
    );
    check(
        Call {
            wavelengths: null(),
            ..good
        },
        NULL,
        "wavelengths",
    );
    check(
        Call {
            eval_cos: null(),
            ..good
        },
        NULL,
        "eval_cos",
    );
    check(Call { fold: 1, ..good }, NULL, "swapped_eval_cos");
    check(
        Call {
            name: null(),
            ..good
        },
        NULL,
        "name",
    );
    check(
        Call {
            source: null(),
            ..good
        },
        NULL,
        "source",
    );
    check(
        Call {
            out_json: null_mut(),
            ..good
        },
        NULL,
        "out_json",
    );
    check(Call { m: 0, ..good }, INVALID, "m = 0");
    check(Call { fold: 7, ..good }, INVALID, "fold 7");
    check(
        Call {
            n_validation: 0,
            ..good
        },
        INVALID,
        "validation",
    );
    let with = |change: fn(&mut Vec<f32>)| {
        let mut w = s.wavelengths.clone();
        change(&mut w);
        w
    };
    let swapped = with(|w| w.swap(10, 11));
    let nan = with(|w| w[4] = f32::NAN);
    let infrared = with(|w| w.iter_mut().for_each(|l| *l += 1000.0));
    for (w, message) in [
        (&swapped, "strictly increasing"),
        (&nan, "not finite"),
        (&infrared, "overlap"),
    ] {
        check(
            Call {
                wavelengths: w.as_ptr(),
                ..good
            },
            INVALID,
            message,
        );
    }
    let mut bad_values = s.values.clone();
    bad_values[5 * s.n + 9] = f32::NAN;
    check(
        Call {
            eval_cos: bad_values.as_ptr(),
            ..good
        },
        INVALID,
        "pair 9",
    );
}
