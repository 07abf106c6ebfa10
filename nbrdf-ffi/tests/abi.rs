//! The C ABI as a C caller sees it: status codes, messages, null pointers, planar layouts.

mod support;

use glam::Vec3;
use nbrdf_core::brdf::Brdf;
use nbrdf_core::{Nbrdf, SamplingStrategy};
use nbrdf_ffi::*;
use std::ffi::{c_char, CStr};
use std::ptr::{null, null_mut};
use support::*;

/// Directions on the upper hemisphere plus grazing and degenerate ones.
fn direction_pairs() -> Vec<(Vec3, Vec3)> {
    let dir = |theta: f32, phi: f32| {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    };
    let mut pairs = Vec::new();
    for i in 0..7 {
        for j in 0..5 {
            let v = dir(0.2 * i as f32, 0.9 * j as f32);
            let l = dir(0.25 * j as f32 + 0.05, 2.0 - 0.7 * i as f32);
            pairs.push((v, l));
        }
    }
    pairs.push((Vec3::Z, Vec3::Z));
    let grazing = std::f32::consts::FRAC_PI_2 - 1e-4;
    pairs.push((dir(grazing, 0.0), dir(grazing, std::f32::consts::PI)));
    pairs.push((Vec3::new(0.0, 0.0, 2.0), Vec3::new(1.0, 0.0, 1.0)));
    pairs.push((Vec3::Z, Vec3::new(0.3, 0.0, -0.5)));
    pairs
}

#[test]
fn version_and_fresh_thread_error_are_strings() {
    // SAFETY: static strings.
    let version = unsafe { CStr::from_ptr(nbrdf_version()) }.to_str().unwrap();
    assert_eq!(version, env!("CARGO_PKG_VERSION"));
    std::thread::spawn(|| assert_eq!(last_error(), ""))
        .join()
        .unwrap();
}

#[test]
fn missing_files_are_io_errors_naming_the_file() {
    let path = scratch("missing").join("does-not-exist.nbrdf.json");
    let c = c_path(&path);
    let mut network = 1 as *mut NbrdfNetwork; // must be overwritten with null
                                              // SAFETY: valid pointers.
    assert_eq!(unsafe { nbrdf_network_load(c.as_ptr(), &mut network) }, IO);
    assert!(network.is_null());
    let message = last_error();
    assert!(message.starts_with("nbrdf_network_load: "), "{message}");
    assert!(message.contains("does-not-exist.nbrdf.json"), "{message}");

    let path = scratch("missing").join("nothing.binary");
    let mut merl = null_mut();
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_merl_load(c_path(&path).as_ptr(), &mut merl) },
        IO
    );
    assert!(merl.is_null());
    assert!(last_error().contains("nothing.binary"), "{}", last_error());
}

#[test]
fn malformed_files_are_format_errors_naming_the_file() {
    let dir = scratch("malformed");
    let json = dir.join("broken.nbrdf.json");
    std::fs::write(
        &json,
        "{\"format\": \"nbrdf\", \"version\": 1, \"layers\": [",
    )
    .unwrap();
    let mut network = null_mut();
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_network_load(c_path(&json).as_ptr(), &mut network) },
        FORMAT
    );
    assert!(network.is_null());
    assert!(
        last_error().contains("broken.nbrdf.json"),
        "{}",
        last_error()
    );

    let binary = dir.join("short.binary");
    std::fs::write(
        &binary,
        [90_i32, 90, 180]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    let mut merl = null_mut();
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_merl_load(c_path(&binary).as_ptr(), &mut merl) },
        FORMAT
    );
    assert!(merl.is_null());
    assert!(last_error().contains("short.binary"), "{}", last_error());
}

#[test]
fn null_pointers_name_the_argument() {
    let (network, path) = load_network(4);
    let net = network.0.cast_const();
    let sampler = NbrdfSampler {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_COSINE,
        exponent: 0.0,
        specular_weight: 0.0,
    };
    let v = [0.0_f32, 0.0, 1.0];
    let mut out = [0.0_f32; 3];
    let mut pdf = [0.0_f32; 1];
    let mut info = NbrdfNetworkInfo::default();
    let mut name: *const c_char = null();
    let mut handle = null_mut();
    let c = c_path(&path);

    let check = |status: i32, argument: &str| {
        assert_eq!(status, NULL, "argument {argument}: {}", last_error());
        let message = last_error();
        assert!(message.contains(&format!("`{argument}`")), "{message}");
    };
    // SAFETY: every pointer is either null or valid.
    unsafe {
        check(nbrdf_network_load(null(), &mut handle), "path");
        check(nbrdf_network_load(c.as_ptr(), null_mut()), "out");
        check(nbrdf_merl_load(null(), &mut null_mut()), "path");
        check(nbrdf_merl_load(c.as_ptr(), null_mut()), "out");
        check(nbrdf_network_info(null(), &mut info), "network");
        check(nbrdf_network_info(net, null_mut()), "out");
        check(nbrdf_network_name(null(), &mut name), "network");
        check(nbrdf_network_name(net, null_mut()), "out_name");

        check(
            nbrdf_network_eval(null(), v.as_ptr(), v.as_ptr(), 1, out.as_mut_ptr()),
            "network",
        );
        check(
            nbrdf_network_eval(net, null(), v.as_ptr(), 1, out.as_mut_ptr()),
            "view",
        );
        check(
            nbrdf_network_eval(net, v.as_ptr(), null(), 1, out.as_mut_ptr()),
            "light",
        );
        check(
            nbrdf_network_eval(net, v.as_ptr(), v.as_ptr(), 1, null_mut()),
            "out_rgb",
        );
        check(
            nbrdf_network_eval(net, v.as_ptr(), v.as_ptr(), 0, null_mut()),
            "out_rgb",
        );
        check(
            nbrdf_merl_eval(null(), v.as_ptr(), v.as_ptr(), 1, out.as_mut_ptr()),
            "merl",
        );

        let mut l = [0.0_f32; 3];
        let mut w = [0.0_f32; 3];
        let s = &sampler as *const NbrdfSampler;
        let sample = |net, s, view, u, light, weight, pdf| {
            nbrdf_network_sample(net, s, view, u, 1, light, weight, pdf)
        };
        let (vp, lp, wp, pp) = (v.as_ptr(), l.as_mut_ptr(), w.as_mut_ptr(), pdf.as_mut_ptr());
        check(sample(null(), s, vp, vp, lp, wp, pp), "network");
        check(sample(net, null(), vp, vp, lp, wp, pp), "sampler");
        check(sample(net, s, null(), vp, lp, wp, pp), "view");
        check(sample(net, s, vp, null(), lp, wp, pp), "u");
        check(sample(net, s, vp, vp, null_mut(), wp, pp), "out_light");
        check(sample(net, s, vp, vp, lp, null_mut(), pp), "out_weight");
        check(sample(net, s, vp, vp, lp, wp, null_mut()), "out_pdf");
        check(nbrdf_merl_sample(null(), s, vp, vp, 1, lp, wp, pp), "merl");

        check(nbrdf_sampler_pdf(null(), vp, vp, 1, pp), "sampler");
        check(nbrdf_sampler_pdf(s, null(), vp, 1, pp), "view");
        check(nbrdf_sampler_pdf(s, vp, null(), 1, pp), "light");
        check(nbrdf_sampler_pdf(s, vp, vp, 1, null_mut()), "out_pdf");
        check(nbrdf_sampler_validate(null()), "sampler");

        // Freeing null is a no-op.
        nbrdf_network_free(null_mut());
        nbrdf_merl_free(null_mut());
    }
}

#[test]
fn bad_samplers_are_invalid_arguments() {
    let v = [0.0_f32, 0.0, 1.0];
    let mut pdf = [0.0_f32];
    let phong = |exponent: f32, specular_weight: f32| NbrdfSampler {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_PHONG,
        exponent,
        specular_weight,
    };
    for bad in [
        phong(-1.0, 0.5),
        phong(f32::NAN, 0.5),
        phong(f32::INFINITY, 0.5),
        phong(10.0, 1.5),
        phong(10.0, -0.1),
    ] {
        // SAFETY: valid pointers.
        unsafe {
            assert_eq!(nbrdf_sampler_validate(&bad), INVALID, "{bad:?}");
            assert!(
                last_error().starts_with("nbrdf_sampler_validate: "),
                "{}",
                last_error()
            );
            assert_eq!(
                nbrdf_sampler_pdf(&bad, v.as_ptr(), v.as_ptr(), 1, pdf.as_mut_ptr()),
                INVALID,
                "{bad:?}"
            );
        }
    }
    // An out-of-range kind written by C.
    let mut raw = [0_i32; 3];
    raw[0] = 7;
    let sampler = raw.as_ptr().cast::<NbrdfSampler>();
    // SAFETY: same size and alignment as NbrdfSampler; the kind is read as an integer.
    unsafe {
        assert_eq!(nbrdf_sampler_validate(sampler), INVALID);
        assert!(
            last_error().contains("unknown sampling kind 7"),
            "{}",
            last_error()
        );
    }
    for good in [
        phong(0.0, 0.0),
        phong(1e6, 1.0),
        NbrdfSampler {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM,
            exponent: f32::NAN,
            specular_weight: -3.0,
        },
    ] {
        // SAFETY: valid pointer.
        assert_eq!(
            unsafe { nbrdf_sampler_validate(&good) },
            OK,
            "{good:?}: {}",
            last_error()
        );
    }
}

#[test]
fn empty_batches_are_ok() {
    let (network, _) = load_network(4);
    let sampler = NbrdfSampler {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_PHONG,
        exponent: 10.0,
        specular_weight: 0.5,
    };
    let mut buf = [0.0_f32; 3];
    let p = buf.as_mut_ptr();
    // SAFETY: valid pointers, n = 0.
    unsafe {
        assert_eq!(nbrdf_network_eval(network.0, p, p, 0, p), OK);
        assert_eq!(
            nbrdf_network_sample(network.0, &sampler, p, p, 0, p, p, p),
            OK
        );
        assert_eq!(nbrdf_sampler_pdf(&sampler, p, p, 0, p), OK);
    }
}

#[test]
fn misaligned_and_oversized_arrays_are_rejected() {
    let (network, _) = load_network(4);
    let buf = [0.0_f32; 8];
    let mut out = [0.0_f32; 8];
    let misaligned = buf.as_ptr().cast::<u8>().wrapping_add(1).cast::<f32>();
    // SAFETY: rejected before any access.
    unsafe {
        assert_eq!(
            nbrdf_network_eval(network.0, misaligned, buf.as_ptr(), 1, out.as_mut_ptr()),
            INVALID
        );
        assert!(last_error().contains("`view`"), "{}", last_error());
        assert_eq!(
            nbrdf_network_eval(
                network.0,
                buf.as_ptr(),
                buf.as_ptr(),
                usize::MAX / 2,
                out.as_mut_ptr()
            ),
            INVALID
        );
    }
}

#[test]
fn network_info_and_name() {
    for hidden in [4, 9] {
        let (network, _) = load_network(hidden);
        let mut info = NbrdfNetworkInfo::default();
        let mut name: *const c_char = null();
        // SAFETY: valid pointers.
        unsafe {
            assert_eq!(nbrdf_network_info(network.0, &mut info), OK);
            assert_eq!(nbrdf_network_name(network.0, &mut name), OK);
            assert_eq!(CStr::from_ptr(name).to_str().unwrap(), "ffi-test");
        }
        let expected = 6 * hidden + hidden + hidden * hidden + hidden + hidden * 3 + 3;
        assert_eq!(
            info,
            NbrdfNetworkInfo {
                hidden_width: hidden as u32,
                parameter_count: expected as u32,
                has_sampling: 1,
                exponent: 40.0,
                specular_weight: 0.25
            }
        );
    }
}

/// `eval(view, light, n, out_rgb)` through the C ABI.
type EvalFn<'a> = &'a dyn Fn(&[f32], &[f32], usize, &mut [f32]) -> i32;
/// `sample(sampler, view, u, n, out_light, out_weight, out_pdf)` through the C ABI.
type SampleFn<'a> =
    &'a dyn Fn(&NbrdfSampler, &[f32], &[f32], usize, &mut [f32], &mut [f32], &mut [f32]) -> i32;

/// The planar batch entry points agree lane by lane with the core's single-direction functions.
fn check_layouts(brdf: &dyn Brdf, eval: EvalFn<'_>, sample: SampleFn<'_>) {
    let pairs = direction_pairs();
    let n = pairs.len();
    let view = planar(pairs.iter().map(|p| p.0));
    let light = planar(pairs.iter().map(|p| p.1));
    let mut rgb = vec![f32::NAN; 3 * n];
    assert_eq!(eval(&view, &light, n, &mut rgb), OK, "{}", last_error());
    for (i, &(v, l)) in pairs.iter().enumerate() {
        let f = brdf.eval(v, l);
        let cos = nbrdf_core::brdf::cos_theta_light(l);
        for c in 0..3 {
            assert_close(
                rgb[c * n + i],
                f[c] * cos,
                &format!("eval lane {i} channel {c}"),
            );
        }
    }

    let u = planar((0..n).map(|i| {
        let t = i as f32 / (n - 1) as f32;
        Vec3::new(t, (t * 7.3).fract(), (t * 3.1 + 0.2).fract())
    }));
    let samplers = [
        (
            NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM,
            SamplingStrategy::Uniform,
        ),
        (
            NbrdfSamplingKind::NBRDF_SAMPLING_COSINE,
            SamplingStrategy::Cosine,
        ),
        (
            NbrdfSamplingKind::NBRDF_SAMPLING_PHONG,
            SamplingStrategy::Phong {
                exponent: 40.0,
                specular_weight: 0.3,
            },
        ),
    ];
    for (kind, strategy) in samplers {
        let sampler = NbrdfSampler {
            kind,
            exponent: 40.0,
            specular_weight: 0.3,
        };
        let (mut l_out, mut w_out, mut pdf_out) = (
            vec![f32::NAN; 3 * n],
            vec![f32::NAN; 3 * n],
            vec![f32::NAN; n],
        );
        assert_eq!(
            sample(&sampler, &view, &u, n, &mut l_out, &mut w_out, &mut pdf_out),
            OK,
            "{}",
            last_error()
        );
        let mut pdf_again = vec![f32::NAN; n];
        // SAFETY: buffers of 3 n and n floats.
        let status = unsafe {
            nbrdf_sampler_pdf(
                &sampler,
                view.as_ptr(),
                l_out.as_ptr(),
                n,
                pdf_again.as_mut_ptr(),
            )
        };
        assert_eq!(status, OK, "{}", last_error());
        for i in 0..n {
            let v = Vec3::new(view[i], view[n + i], view[2 * n + i]);
            let expected = strategy.sample(v, [u[i], u[n + i], u[2 * n + i]]);
            let what = format!("{kind:?} lane {i}");
            assert_close(pdf_out[i], expected.pdf, &what);
            if expected.pdf > 0.0 {
                let l = Vec3::new(l_out[i], l_out[n + i], l_out[2 * n + i]);
                assert!(
                    (l - expected.light).length() < 1e-5,
                    "{what}: {l} vs {}",
                    expected.light
                );
                assert_close(pdf_again[i], strategy.pdf(v, l), &what);
                let f = brdf.eval(v, l);
                let cos = nbrdf_core::brdf::cos_theta_light(l);
                for c in 0..3 {
                    assert_close(
                        w_out[c * n + i],
                        f[c] * cos / expected.pdf,
                        &format!("{what} weight {c}"),
                    );
                }
            } else {
                assert!(
                    (0..3).all(|c| w_out[c * n + i] == 0.0),
                    "{what}: invalid sample with weight"
                );
            }
        }
    }
}

#[test]
fn network_batches_are_planar() {
    let (network, path) = load_network(5);
    let core = Nbrdf::load(&path).unwrap();
    let handle = network.0.cast_const();
    check_layouts(
        &core,
        // SAFETY: slices of the documented sizes.
        &|view, light, n, rgb| unsafe {
            nbrdf_network_eval(handle, view.as_ptr(), light.as_ptr(), n, rgb.as_mut_ptr())
        },
        &|s, view, u, n, l, w, p| unsafe {
            nbrdf_network_sample(
                handle,
                s,
                view.as_ptr(),
                u.as_ptr(),
                n,
                l.as_mut_ptr(),
                w.as_mut_ptr(),
                p.as_mut_ptr(),
            )
        },
    );
}

#[test]
fn merl_batches_are_planar() {
    let (merl, table) = load_smooth_merl();
    let handle = merl.0.cast_const();
    check_layouts(
        &table,
        // SAFETY: slices of the documented sizes.
        &|view, light, n, rgb| unsafe {
            nbrdf_merl_eval(handle, view.as_ptr(), light.as_ptr(), n, rgb.as_mut_ptr())
        },
        &|s, view, u, n, l, w, p| unsafe {
            nbrdf_merl_sample(
                handle,
                s,
                view.as_ptr(),
                u.as_ptr(),
                n,
                l.as_mut_ptr(),
                w.as_mut_ptr(),
                p.as_mut_ptr(),
            )
        },
    );
}

/// Samples `sampler` for `views` through `nbrdf_network_sample_mixture`, asks the pdfs of the
/// samples again through `nbrdf_mixture_sampler_pdf`, and checks both lane by lane against the
/// core's `expected` strategy.
fn check_mixture_sampling(
    sampler: &NbrdfMixtureSampler,
    expected: &SamplingStrategy,
    views: &[Vec3],
) {
    let (network, _) = load_network(4);
    let n = views.len();
    let us: Vec<Vec3> = (0..n)
        .map(|i| {
            let k = i as f32;
            Vec3::new((k * 0.37).fract(), (k * 0.61).fract(), (k * 0.83).fract())
        })
        .collect();
    let (view, u) = (planar(views.iter().copied()), planar(us.iter().copied()));
    let (mut light, mut weight, mut pdf) = (vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0.0; n]);
    let mut pdf_again = vec![0.0; n];
    // SAFETY: valid pointers and sizes.
    unsafe {
        assert_eq!(
            nbrdf_mixture_sampler_validate(sampler),
            OK,
            "{}",
            last_error()
        );
        assert_eq!(
            nbrdf_network_sample_mixture(
                network.0,
                sampler,
                view.as_ptr(),
                u.as_ptr(),
                n,
                light.as_mut_ptr(),
                weight.as_mut_ptr(),
                pdf.as_mut_ptr()
            ),
            OK,
            "{}",
            last_error()
        );
        assert_eq!(
            nbrdf_mixture_sampler_pdf(
                sampler,
                view.as_ptr(),
                light.as_ptr(),
                n,
                pdf_again.as_mut_ptr()
            ),
            OK
        );
    }
    assert_eq!(pdf, pdf_again);
    for i in 0..n {
        let s = expected.sample(views[i], us[i].to_array());
        assert_eq!(s.light, lane(&light, n, i), "lane {i}");
        assert_eq!(s.pdf, pdf[i], "lane {i}");
    }
}

/// `kind` needs the fields of an `NbrdfMixtureSampler`: the one-lobe struct refuses it.
fn assert_one_lobe_struct_refuses(kind: NbrdfSamplingKind) {
    let one = NbrdfSampler {
        kind,
        exponent: 10.0,
        specular_weight: 0.5,
    };
    // SAFETY: a valid pointer.
    assert_eq!(unsafe { nbrdf_sampler_validate(&one) }, INVALID);
    assert!(
        last_error().contains("NbrdfMixtureSampler"),
        "{}",
        last_error()
    );
}

/// `bad` variations of a mixture sampler are invalid arguments.
fn assert_invalid_mixtures(bad: &[NbrdfMixtureSampler]) {
    for bad in bad {
        // SAFETY: a valid pointer.
        assert_eq!(
            unsafe { nbrdf_mixture_sampler_validate(bad) },
            INVALID,
            "{bad:?}"
        );
        assert!(
            last_error().starts_with("nbrdf_mixture_sampler_validate: "),
            "{}",
            last_error()
        );
    }
}

/// What `nbrdf_network_stored_sampler` reports for the network file `json`.
fn stored_sampler(json: &str, name: &str) -> NbrdfMixtureSampler {
    let (network, _) = load_network_text(json, name);
    let mut stored = std::mem::MaybeUninit::<NbrdfMixtureSampler>::uninit();
    // SAFETY: a live handle and a writable sampler; initialised by a successful call.
    unsafe {
        assert_eq!(
            nbrdf_network_stored_sampler(network.0, stored.as_mut_ptr()),
            OK,
            "{}",
            last_error()
        );
        assert_eq!(nbrdf_network_stored_sampler(network.0, null_mut()), NULL);
        stored.assume_init()
    }
}

#[test]
fn two_lobe_samplers_go_through_the_mixture_functions() {
    let two = NbrdfMixtureSampler {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE,
        exponent: 2000.0,
        specular_weight: 0.4,
        exponent2: 20.0,
        specular_weight2: 0.35,
    };
    let core = SamplingStrategy::TwoLobe {
        exponent1: 2000.0,
        weight1: f64::from(0.4f32),
        exponent2: 20.0,
        weight2: f64::from(0.35f32),
    };
    let n = 64;
    let views: Vec<Vec3> = (0..n)
        .map(|i| {
            let t = 1.5 * i as f32 / n as f32;
            Vec3::new(t.sin(), 0.0, t.cos())
        })
        .collect();
    check_mixture_sampling(&two, &core, &views);
    assert_one_lobe_struct_refuses(NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE);
    assert_invalid_mixtures(&[
        NbrdfMixtureSampler {
            specular_weight2: 0.7,
            ..two
        },
        NbrdfMixtureSampler {
            exponent2: 2e6,
            ..two
        },
        NbrdfMixtureSampler {
            exponent: f32::NAN,
            ..two
        },
    ]);
    // What the file stores: one lobe here, two after adding a second lobe.
    let stored = stored_sampler(&network_json(4), "one-lobe");
    assert_eq!(stored.kind, NbrdfSamplingKind::NBRDF_SAMPLING_PHONG);
    assert_eq!((stored.exponent, stored.specular_weight), (40.0, 0.25));
    assert_eq!((stored.exponent2, stored.specular_weight2), (0.0, 0.0));
    let text = network_json(4).replace(
        r#""source": "manual"}"#,
        r#""source": "manual", "second_lobe": {"exponent": 8.0, "specular_weight": 0.5}}"#,
    );
    let stored = stored_sampler(&text, "two-lobe");
    assert_eq!(stored.kind, NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE);
    assert_eq!((stored.exponent2, stored.specular_weight2), (8.0, 0.5));
}

#[test]
fn anisotropic_samplers_go_through_the_mixture_functions() {
    let aniso = NbrdfMixtureSampler {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG,
        exponent: 1000.0,
        specular_weight: 0.6,
        exponent2: 10.0,
        specular_weight2: 0.0,
    };
    let core = SamplingStrategy::anisotropic(1000.0, 10.0, f64::from(0.6f32));
    let n = 64;
    let views: Vec<Vec3> = (0..n)
        .map(|i| {
            let (t, p) = (1.5 * i as f32 / n as f32, 0.3 * i as f32);
            Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
        })
        .collect();
    check_mixture_sampling(&aniso, &core, &views);
    assert_one_lobe_struct_refuses(NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG);
    assert_invalid_mixtures(&[NbrdfMixtureSampler {
        exponent2: 2e6,
        ..aniso
    }]);
    // A file storing exponent_v reports the anisotropic kind with n_v in exponent2.
    let text = network_json(4)
        .replace(r#""version": 1,"#, r#""version": 2, "anisotropic": true,"#)
        .replace(
            r#""source": "manual"}"#,
            r#""source": "manual", "exponent_v": 7.5}"#,
        );
    let stored = stored_sampler(&text, "aniso-lobe");
    assert_eq!(
        stored.kind,
        NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG
    );
    assert_eq!(
        (stored.exponent, stored.specular_weight, stored.exponent2),
        (40.0, 0.25, 7.5)
    );
}

#[test]
fn active_units_are_the_library_proof_and_handles_evaluate_without_the_others() {
    let mut net = Nbrdf::random("units", 6, 11);
    for layer in net.layers.iter_mut() {
        for (k, w) in layer.weights.iter_mut().enumerate() {
            *w = 1.5 * ((k as f32 * 0.37).sin());
        }
    }
    net.layers[0].bias[2] = -100.0; // never fires
    net.layers[1].bias[4] = -1e4; // never fires
    let flat = net.to_flat();
    let mut out = vec![7u8; 12];
    // SAFETY: valid pointers of the documented sizes.
    let status = unsafe {
        nbrdf_network_active_units(flat.as_ptr(), flat.len(), 6, 0, out.as_mut_ptr(), out.len())
    };
    assert_eq!(status, OK, "{}", last_error());
    let active = net.active_units();
    let expected: Vec<u8> = active
        .hidden1
        .iter()
        .chain(&active.hidden2)
        .map(|&a| u8::from(a))
        .collect();
    assert_eq!(out, expected);
    assert_eq!((out[2], out[6 + 4]), (0, 0));

    // A handle of that network evaluates what the full network does.
    let (handle, path) = load_network_text(&net.to_json_string(), "active-units");
    let core = Nbrdf::load(&path).unwrap();
    let pairs = direction_pairs();
    let n = pairs.len();
    let view = planar(pairs.iter().map(|p| p.0));
    let light = planar(pairs.iter().map(|p| p.1));
    let mut rgb = vec![0.0f32; 3 * n];
    // SAFETY: slices of the documented sizes.
    let status =
        unsafe { nbrdf_network_eval(handle.0, view.as_ptr(), light.as_ptr(), n, rgb.as_mut_ptr()) };
    assert_eq!(status, OK, "{}", last_error());
    for (i, (v, l)) in pairs.iter().enumerate() {
        let want = core.eval(*v, *l);
        let cos = (l.z / l.length()).max(0.0);
        for c in 0..3 {
            assert_close(
                rgb[c * n + i],
                want[c] * cos,
                "pruned handle vs full network",
            );
        }
    }

    // Wrong sizes, non-finite parameters and null pointers are refused with a message.
    let call = |params: &[f32], count: usize, hidden: usize, out: &mut [u8], len: usize| {
        // SAFETY: the slices are at least as long as the sizes passed where the call is valid.
        unsafe {
            nbrdf_network_active_units(params.as_ptr(), count, hidden, 0, out.as_mut_ptr(), len)
        }
    };
    assert_eq!(call(&flat, flat.len() - 1, 6, &mut out, 12), INVALID);
    assert!(last_error().contains("count is"), "{}", last_error());
    assert_eq!(call(&flat, flat.len(), 6, &mut out, 11), INVALID);
    assert!(last_error().contains("out_len is 11"), "{}", last_error());
    assert_eq!(call(&flat, flat.len(), usize::MAX, &mut out, 12), INVALID);
    let mut bad = flat.clone();
    bad[3] = f32::NAN;
    assert_eq!(call(&bad, bad.len(), 6, &mut out, 12), INVALID);
    // SAFETY: null pointers are what is tested.
    unsafe {
        assert_eq!(
            nbrdf_network_active_units(null(), flat.len(), 6, 0, out.as_mut_ptr(), 12),
            NULL
        );
        assert!(last_error().contains("params"), "{}", last_error());
        assert_eq!(
            nbrdf_network_active_units(flat.as_ptr(), flat.len(), 6, 0, null_mut(), 12),
            NULL
        );
    }
}
