//! `nbrdf_train_textured` as a C caller sees it: a textured source (a blend of a Lambertian and
//! a glossy BRDF by a weight that grows with `u`) distilled into a material file that the core's
//! loader reads back and that matches the source at texels it was baked at, in RGB and from
//! spectra; the same files for a seed on any thread count; progress callbacks; and bad calls
//! that return an error status with a message.

use glam::Vec3;
use nbrdf_core::rng::SplitMix64;
use nbrdf_core::sampling::uniform_hemisphere;
use nbrdf_core::textured::TexturedNbrdf;
use nbrdf_train::*;
use std::f32::consts::PI;
use std::ffi::{c_void, CString};
use std::path::{Path, PathBuf};
use std::ptr::{null, null_mut};

mod common;
use common::{last_error, INVALID, NULL, OK};

const IO: i32 = NbrdfTrainStatus::NBRDF_TRAIN_ERROR_IO as i32;
/// The parameter image's size: `u` varies along its width, so a transposed or flipped bake
/// would not match.
const WIDTH: usize = 8;
const HEIGHT: usize = 2;

/// `f_r` of the source with blend weight `p`.
fn source(p: f32, view: Vec3, light: Vec3) -> [f32; 3] {
    let cos_h = (view + light).normalize().z.max(0.0);
    let spec = 0.5 * 22.0 / (2.0 * PI) * cos_h.powf(20.0);
    let (a, b) = ([0.7, 0.45, 0.2], [0.04, 0.04, 0.04]);
    std::array::from_fn(|c| (1.0 - p) * a[c] / PI + p * (b[c] / PI + spec))
}

/// The weight at texel column `x`.
fn weight(x: usize) -> f32 {
    x as f32 / (WIDTH - 1) as f32
}

/// Samples at random texels (one parameter, the weight) and uniform directions, planar: RGB
/// values, or with `wavelengths` the values at each (`eval_cos[j n + i]`).
struct Samples {
    params: Vec<f32>,
    view: Vec<f32>,
    light: Vec<f32>,
    wavelengths: Vec<f32>,
    eval_cos: Vec<f32>,
    n: usize,
}

fn samples(n: usize) -> Samples {
    let mut rng = SplitMix64::from_state(3);
    let mut s = Samples {
        params: vec![0.0; n],
        view: vec![0.0; 3 * n],
        light: vec![0.0; 3 * n],
        wavelengths: Vec::new(),
        eval_cos: vec![0.0; 3 * n],
        n,
    };
    for i in 0..n {
        let p = weight(i % WIDTH);
        let mut dir = || uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        let (view, light) = (dir(), dir());
        let f = source(p, view, light);
        s.params[i] = p;
        for a in 0..3 {
            s.view[a * n + i] = view[a];
            s.light[a * n + i] = light[a];
            s.eval_cos[a * n + i] = f[a] * light.z;
        }
    }
    s
}

/// The weight of every texel, texel-major (row 0 first).
fn image() -> Vec<f32> {
    (0..WIDTH * HEIGHT).map(|t| weight(t % WIDTH)).collect()
}

fn small_config(threads: usize) -> NbrdfTexturedConfig {
    let mut config = std::mem::MaybeUninit::<NbrdfTexturedConfig>::uninit();
    // SAFETY: a writable config.
    let status = unsafe { nbrdf_train_textured_config_default(config.as_mut_ptr()) };
    assert_eq!(status, OK);
    // SAFETY: initialised by the call above.
    let mut config = unsafe { config.assume_init() };
    config.channels = 4;
    config.encoder_hidden = 16;
    config.decoder_hidden = 24;
    config.epochs = 30;
    config.batch = 256;
    config.learning_rate = 5e-3;
    config.representatives = 2;
    config.threads = threads;
    config
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "nbrdf-train-textured-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// What the callbacks saw: epochs, and the bake's (stage, done, total) reports.
#[derive(Default)]
struct Seen {
    epochs: Vec<usize>,
    bake: Vec<(i32, usize, usize)>,
}

unsafe extern "C" fn on_epoch(user: *mut c_void, stats: *const NbrdfEpochStats) {
    // SAFETY: `user` is the `Seen` of `distil`, alive during the call; `stats` is valid.
    unsafe { (*user.cast::<Seen>()).epochs.push((*stats).epoch) };
}

unsafe extern "C" fn on_bake(user: *mut c_void, progress: *const NbrdfBakeProgress) {
    // SAFETY: as `on_epoch`.
    let p = unsafe { *progress };
    unsafe { (*user.cast::<Seen>()).bake.push((p.stage, p.done, p.total)) };
}

/// Calls `nbrdf_train_textured` writing `path`; the status and what the callbacks saw.
fn distil(
    config: &NbrdfTexturedConfig,
    s: &Samples,
    parameters: usize,
    (image, width, height): (&[f32], usize, usize),
    path: &Path,
) -> (i32, Seen) {
    let path = CString::new(path.to_str().unwrap()).unwrap();
    let mut seen = Seen::default();
    // SAFETY: the arrays hold the sizes the call is given; strings are NUL-terminated.
    let status = unsafe {
        nbrdf_train_textured(
            config,
            s.params.as_ptr(),
            parameters,
            s.view.as_ptr(),
            s.light.as_ptr(),
            s.wavelengths.as_ptr(),
            s.wavelengths.len(),
            s.eval_cos.as_ptr(),
            s.n,
            image.as_ptr(),
            width,
            height,
            path.as_ptr(),
            c"blend".as_ptr(),
            c"closed-form blend".as_ptr(),
            c"{\"renderer\": \"test\"}".as_ptr(),
            Some(on_epoch),
            Some(on_bake),
            (&mut seen as *mut Seen).cast(),
        )
    };
    (status, seen)
}

#[test]
fn a_textured_source_becomes_a_material_that_matches_it_at_its_texels() {
    let dir = temp_dir("match");
    let path = dir.join("blend.nbrdf.json");
    let config = small_config(2);
    let s = samples(40_000);
    let (status, seen) = distil(&config, &s, 1, (&image(), WIDTH, HEIGHT), &path);
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(seen.epochs, (1..=30).collect::<Vec<_>>());
    let encoded = NbrdfBakeStage::NBRDF_BAKE_ENCODED as i32;
    let fitting = NbrdfBakeStage::NBRDF_BAKE_FITTING_LOBES as i32;
    assert_eq!(seen.bake.first(), Some(&(encoded, 16, 16)));
    assert_eq!(seen.bake.last(), Some(&(fitting, 2, 2)));
    assert!(dir.join("blend.latent.exr").is_file());

    let material = TexturedNbrdf::load(&path).unwrap();
    assert_eq!(material.name(), "blend");
    assert_eq!(material.texture_path(), "blend.latent.exr");
    assert_eq!(
        (material.texture().width(), material.texture().height()),
        (WIDTH, HEIGHT)
    );
    assert_eq!(material.decoder().latent_channels(), 4);
    assert_eq!(material.sampling_channels().lobes().len(), 1);
    let p = material.provenance();
    assert_eq!(p["source"], "closed-form blend");
    assert_eq!(p["distilled_from"]["renderer"], "test");
    assert_eq!(p["parameters"], 1);

    // At texel centres of every column, against the source of that column's weight: the error
    // of the right column is a fraction of that of the mirrored column (u flipped).
    let mut rng = SplitMix64::from_state(11);
    let (mut right, mut mirrored, mut total) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..2000 {
        let x = (rng.next_f64() * WIDTH as f64) as usize % WIDTH;
        let uv = [(x as f32 + 0.5) / WIDTH as f32, 0.25];
        let mut dir = || uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        let (view, light) = (dir(), dir());
        let got = material.eval_cos(uv, view, light);
        let want = source(weight(x), view, light).map(|f| f * light.z);
        let flipped = source(weight(WIDTH - 1 - x), view, light).map(|f| f * light.z);
        for c in 0..3 {
            right += f64::from((got[c] - want[c]).abs());
            mirrored += f64::from((got[c] - flipped[c]).abs());
            total += f64::from(want[c]);
        }
    }
    assert!(right < 0.03 * total, "error {right} of {total}");
    assert!(right < 0.1 * mirrored, "error {right}, mirrored {mirrored}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_seed_gives_the_same_files_on_any_thread_count() {
    let dir = temp_dir("determinism");
    let config = NbrdfTexturedConfig {
        epochs: 3,
        representatives: 1,
        ..small_config(1)
    };
    for (kind, s) in [
        ("rgb", samples(6_000)),
        ("spectral", spectral_samples(3_000)),
    ] {
        let mut files = Vec::new();
        for (k, threads) in [1, 2, 1].into_iter().enumerate() {
            let path = dir.join(format!("{kind}{k}.nbrdf.json"));
            let config = NbrdfTexturedConfig { threads, ..config };
            let (status, _) = distil(&config, &s, 1, (&image(), WIDTH, HEIGHT), &path);
            assert_eq!(status, OK, "{}", last_error());
            let mut json: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            // The run's duration is the one field that may differ.
            json["provenance"]
                .as_object_mut()
                .unwrap()
                .remove("seconds");
            json["latent"]["path"] = "".into();
            let texture = std::fs::read(dir.join(format!("{kind}{k}.latent.exr"))).unwrap();
            files.push((json, texture));
        }
        assert!(files[0] == files[1] && files[0] == files[2], "{kind}");
        let other = NbrdfTexturedConfig { seed: 1, ..config };
        let path = dir.join(format!("{kind}-seed1.nbrdf.json"));
        let (status, _) = distil(&other, &s, 1, (&image(), WIDTH, HEIGHT), &path);
        assert_eq!(status, OK, "{}", last_error());
        let texture = std::fs::read(dir.join(format!("{kind}-seed1.latent.exr"))).unwrap();
        assert_ne!(texture, files[0].1, "{kind}");
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bad_calls_return_an_error_status_with_a_message() {
    let dir = temp_dir("bad");
    let path = dir.join("bad.nbrdf.json");
    let s = samples(500);
    let image = image();
    let config = NbrdfTexturedConfig {
        epochs: 1,
        lobes: 0,
        ..small_config(1)
    };
    let expect = |status: i32, wanted: i32, words: &str| {
        assert_eq!(status, wanted, "{}", last_error());
        let message = last_error();
        assert!(
            message.starts_with("nbrdf_train_textured") && message.contains(words),
            "{message}"
        );
    };
    let (status, _) = distil(&config, &s, 0, (&image, WIDTH, HEIGHT), &path);
    expect(status, INVALID, "no textures");
    let (status, _) = distil(&config, &s, 1, (&image, 0, HEIGHT), &path);
    expect(status, INVALID, "width and height");
    let bad = [
        (NbrdfTexturedConfig { lobes: 3, ..config }, "config.lobes"),
        (
            NbrdfTexturedConfig {
                representatives: 0,
                ..config
            },
            "config.representatives",
        ),
        (
            NbrdfTexturedConfig {
                channels: 33,
                ..config
            },
            "latent channels",
        ),
        (
            NbrdfTexturedConfig {
                anisotropic: 2,
                ..config
            },
            "config.anisotropic",
        ),
        (
            NbrdfTexturedConfig {
                epochs: 0,
                ..config
            },
            "epochs",
        ),
    ];
    for (config, words) in bad {
        let (status, _) = distil(&config, &s, 1, (&image, WIDTH, HEIGHT), &path);
        expect(status, INVALID, words);
    }
    let mut nan = image.clone();
    nan[3] = f32::NAN;
    let (status, _) = distil(&config, &s, 1, (&nan, WIDTH, HEIGHT), &path);
    expect(status, INVALID, "texel (x 3, y 0)");
    let unwritable = dir.join("no-such-folder").join("bad.nbrdf.json");
    let (status, _) = distil(&config, &s, 1, (&image, WIDTH, HEIGHT), &unwritable);
    expect(status, IO, "no-such-folder");
    assert!(!path.exists());
    // Null pointers.
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: null where the test says so, valid sizes elsewhere.
    let status = unsafe {
        nbrdf_train_textured(
            null(),
            s.params.as_ptr(),
            1,
            s.view.as_ptr(),
            s.light.as_ptr(),
            s.wavelengths.as_ptr(),
            s.wavelengths.len(),
            s.eval_cos.as_ptr(),
            s.n,
            image.as_ptr(),
            WIDTH,
            HEIGHT,
            c_path.as_ptr(),
            c"x".as_ptr(),
            c"x".as_ptr(),
            null(),
            None,
            None,
            null_mut(),
        )
    };
    expect(status, NULL, "config");
    for (light, details, wanted, words) in [
        (null(), null(), NULL, "light"),
        (
            s.light.as_ptr(),
            c"not json".as_ptr(),
            INVALID,
            "details_json",
        ),
    ] {
        // SAFETY: as above.
        let status = unsafe {
            nbrdf_train_textured(
                &config,
                s.params.as_ptr(),
                1,
                s.view.as_ptr(),
                light,
                null(),
                0,
                s.eval_cos.as_ptr(),
                s.n,
                image.as_ptr(),
                WIDTH,
                HEIGHT,
                c_path.as_ptr(),
                c"x".as_ptr(),
                c"x".as_ptr(),
                details,
                None,
                None,
                null_mut(),
            )
        };
        expect(status, wanted, words);
    }
    // SAFETY: a null output.
    let status = unsafe { nbrdf_train_textured_config_default(null_mut()) };
    assert_eq!(status, NULL);
    std::fs::remove_dir_all(dir).unwrap();
}

/// The spectral source: a blend by `p` of a diffuse reflector of spectrum `a` and a glossy one
/// of spectrum `b`, `f_r(lambda) cos(theta_light)`.
fn spectral_source(p: f32, view: Vec3, light: Vec3, lambda: f32) -> f32 {
    let cos_h = (view + light).normalize().z.max(0.0);
    let spec = 0.4 * 22.0 / (2.0 * PI) * cos_h.powf(20.0);
    let a = 0.1 + 0.7 / (1.0 + (-(lambda - 580.0) / 25.0).exp());
    let b = 0.5 + 0.3 * (lambda / 60.0).sin();
    ((1.0 - p) * a / PI + p * (0.1 * b / PI + b * spec)) * light.z
}

fn planes3(d: &[f32]) -> nbrdf_core::brdf::Directions<'_> {
    nbrdf_core::brdf::Directions::from_planar(d).unwrap()
}

/// [`samples`] with spectral values every 10 nm over 360-830 nm.
fn spectral_samples(n: usize) -> Samples {
    let mut s = samples(n);
    s.wavelengths = (0..48).map(|j| 360.0 + 10.0 * j as f32).collect();
    s.eval_cos = vec![0.0; 48 * n];
    for i in 0..n {
        let v = Vec3::new(s.view[i], s.view[n + i], s.view[2 * n + i]);
        let l = Vec3::new(s.light[i], s.light[n + i], s.light[2 * n + i]);
        for (j, &lambda) in s.wavelengths.iter().enumerate() {
            s.eval_cos[j * n + i] = spectral_source(s.params[i], v, l, lambda);
        }
    }
    s
}

#[test]
fn spectral_values_give_a_spectral_material_that_matches_them() {
    let dir = temp_dir("spectral");
    let path = dir.join("spectral.nbrdf.json");
    let config = NbrdfTexturedConfig {
        epochs: 20,
        ..small_config(2)
    };
    let s = spectral_samples(20_000);
    let (status, _) = distil(&config, &s, 1, (&image(), WIDTH, HEIGHT), &path);
    assert_eq!(status, OK, "{}", last_error());
    let material = TexturedNbrdf::load(&path).unwrap();
    let spectral = material.decoder().spectral().expect("a spectral material");
    assert_eq!(spectral.count(), 16);
    assert_eq!(material.provenance()["spectral_target"]["wavelengths"], 48);

    // At texel centres of every column and random wavelengths, against the source of that
    // column's weight, and of the mirrored column.
    let mut rng = SplitMix64::from_state(12);
    let (mut right, mut mirrored, mut total) = (0.0f64, 0.0f64, 0.0f64);
    let n = 1000;
    let (mut u, v) = (vec![0.0; n], vec![0.25; n]);
    let (mut view, mut light) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    let mut columns = vec![0; n];
    let wavelengths: Vec<f32> = (0..n).map(|_| 380.0 + 420.0 * rng.next_f32()).collect();
    for i in 0..n {
        columns[i] = (rng.next_f64() * WIDTH as f64) as usize % WIDTH;
        u[i] = (columns[i] as f32 + 0.5) / WIDTH as f32;
        let mut dir = || uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        let (a, b) = (dir(), dir());
        for k in 0..3 {
            view[k * n + i] = a[k];
            light[k * n + i] = b[k];
        }
    }
    let mut got = vec![0.0f32; n];
    let uv = nbrdf_core::textured::Uvs { u: &u, v: &v };
    material
        .eval_spectral_cos_batch(uv, planes3(&view), planes3(&light), &wavelengths, &mut got)
        .unwrap();
    for i in 0..n {
        let a = Vec3::new(view[i], view[n + i], view[2 * n + i]);
        let b = Vec3::new(light[i], light[n + i], light[2 * n + i]);
        let x = columns[i];
        let want = spectral_source(weight(x), a, b, wavelengths[i]);
        let flipped = spectral_source(weight(WIDTH - 1 - x), a, b, wavelengths[i]);
        right += f64::from((got[i] - want).abs());
        mirrored += f64::from((got[i] - flipped).abs());
        total += f64::from(want);
    }
    assert!(right < 0.05 * total, "error {right} of {total}");
    assert!(
        right < 0.15 * mirrored,
        "error {right}, mirrored {mirrored}"
    );

    // Bad wavelengths are refused, naming the problem.
    let mut bad = spectral_samples(200);
    bad.wavelengths.swap(3, 4);
    let config = NbrdfTexturedConfig {
        epochs: 1,
        ..config
    };
    let (status, _) = distil(&config, &bad, 1, (&image(), WIDTH, HEIGHT), &path);
    assert_eq!(status, INVALID);
    assert!(
        last_error().contains("strictly increasing"),
        "{}",
        last_error()
    );
    std::fs::remove_dir_all(dir).unwrap();
}
