//! The C ABI as a C caller sees it: status codes, messages, null pointers, planar layouts.

mod support;

use glam::Vec3;
use nbrdf_core::brdf::Brdf;
use nbrdf_core::{Nbrdf, SamplingStrategy};
use nbrdf_ffi::*;
use std::ffi::CStr;
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
    let mut material = 1 as *mut NbrdfMaterial; // must be overwritten with null
                                                // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_material_load(c.as_ptr(), &mut material) },
        IO
    );
    assert!(material.is_null());
    let message = last_error();
    assert!(message.starts_with("nbrdf_material_load: "), "{message}");
    assert!(message.contains("does-not-exist.nbrdf.json"), "{message}");

    let path = scratch("missing").join("nothing.binary");
    let mut merl = null_mut();
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_material_load(c_path(&path).as_ptr(), &mut merl) },
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
        unsafe { nbrdf_material_load(c_path(&json).as_ptr(), &mut network) },
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
        unsafe { nbrdf_material_load(c_path(&binary).as_ptr(), &mut merl) },
        FORMAT
    );
    assert!(merl.is_null());
    assert!(last_error().contains("short.binary"), "{}", last_error());
    // The header picked the table reader, which names what is wrong.
    assert!(last_error().contains("truncated"), "{}", last_error());
}

#[test]
fn null_pointers_name_the_argument() {
    let (network, path) = load_network(4);
    let net = network.ptr();
    let cosine = params(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE);
    let sampler = sampler(null(), &cosine);
    let v = [0.0_f32, 0.0, 1.0];
    let mut out = [0.0_f32; 3];
    let mut pdf = [0.0_f32; 1];
    let mut info = std::mem::MaybeUninit::<NbrdfMaterialInfo>::uninit();
    let mut sampler_info = NbrdfSamplerInfo::default();
    let mut handle = null_mut();
    let mut made = null_mut();
    let c = c_path(&path);

    let check = |status: i32, argument: &str| {
        assert_eq!(status, NULL, "argument {argument}: {}", last_error());
        let message = last_error();
        assert!(message.contains(&format!("`{argument}`")), "{message}");
    };
    // SAFETY: every pointer is either null or valid.
    unsafe {
        check(nbrdf_material_load(null(), &mut handle), "path");
        check(nbrdf_material_load(c.as_ptr(), null_mut()), "out");
        check(nbrdf_material_info(null(), info.as_mut_ptr()), "material");
        check(nbrdf_material_info(net, null_mut()), "out");

        check(
            nbrdf_material_eval(null(), v.as_ptr(), v.as_ptr(), 1, out.as_mut_ptr()),
            "material",
        );
        check(
            nbrdf_material_eval(net, null(), v.as_ptr(), 1, out.as_mut_ptr()),
            "view",
        );
        check(
            nbrdf_material_eval(net, v.as_ptr(), null(), 1, out.as_mut_ptr()),
            "light",
        );
        check(
            nbrdf_material_eval(net, v.as_ptr(), v.as_ptr(), 1, null_mut()),
            "out_rgb",
        );
        check(
            nbrdf_material_eval(net, v.as_ptr(), v.as_ptr(), 0, null_mut()),
            "out_rgb",
        );

        let mut l = [0.0_f32; 3];
        let mut w = [0.0_f32; 3];
        let s = sampler.ptr();
        let sample = |net, s, view, u, light, weight, pdf| {
            nbrdf_material_sample(net, s, view, u, 1, light, weight, pdf)
        };
        let (vp, lp, wp, pp) = (v.as_ptr(), l.as_mut_ptr(), w.as_mut_ptr(), pdf.as_mut_ptr());
        check(sample(null(), s, vp, vp, lp, wp, pp), "material");
        check(sample(net, null(), vp, vp, lp, wp, pp), "sampler");
        check(sample(net, s, null(), vp, lp, wp, pp), "view");
        check(sample(net, s, vp, null(), lp, wp, pp), "u");
        check(sample(net, s, vp, vp, null_mut(), wp, pp), "out_light");
        check(sample(net, s, vp, vp, lp, null_mut(), pp), "out_weight");
        check(sample(net, s, vp, vp, lp, wp, null_mut()), "out_pdf");

        check(nbrdf_sampler_pdf(null(), vp, vp, 1, pp), "sampler");
        check(nbrdf_sampler_pdf(s, null(), vp, 1, pp), "view");
        check(nbrdf_sampler_pdf(s, vp, null(), 1, pp), "light");
        check(nbrdf_sampler_pdf(s, vp, vp, 1, null_mut()), "out_pdf");
        check(nbrdf_sampler_create(net, null(), &mut made), "params");
        check(nbrdf_sampler_create(net, &cosine, null_mut()), "out");
        check(nbrdf_sampler_info(null(), &mut sampler_info), "sampler");
        check(nbrdf_sampler_info(s, null_mut()), "out");
        check(nbrdf_sampling_kind_name(0, null_mut()), "out_name");

        // Freeing null is a no-op.
        nbrdf_material_free(null_mut());
        nbrdf_sampler_free(null_mut());
    }
}

#[test]
fn bad_samplers_are_invalid_arguments() {
    let check = |bad: &NbrdfSamplerParams| {
        let (status, _) = try_sampler(null(), bad);
        assert_eq!(status, INVALID, "{bad:?}");
        assert!(
            last_error().starts_with("nbrdf_sampler_create: "),
            "{}",
            last_error()
        );
    };
    for bad in [
        phong(-1.0, 0.5),
        phong(f32::NAN, 0.5),
        phong(f32::INFINITY, 0.5),
        phong(10.0, 1.5),
        phong(10.0, -0.1),
        phong(2e6, 0.5),
    ] {
        check(&bad);
    }
    // An out-of-range kind written by C.
    for kind in [6, 7, -1, i32::MAX] {
        check(&NbrdfSamplerParams {
            kind,
            ..phong(10.0, 0.5)
        });
        assert!(
            last_error().contains(&format!("unknown sampling kind {kind}")),
            "{}",
            last_error()
        );
    }
    for good in [
        phong(0.0, 0.0),
        phong(1e6, 1.0),
        NbrdfSamplerParams {
            exponent: f32::NAN,
            specular_weight: -3.0,
            exponent2: f32::INFINITY,
            exponent_v: -1.0,
            ..params(NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM)
        },
        // The one-lobe kind reads neither the second lobe nor n_v.
        NbrdfSamplerParams {
            exponent2: f32::NAN,
            specular_weight2: 7.0,
            exponent_v: f32::NAN,
            ..phong(10.0, 0.5)
        },
    ] {
        sampler(null(), &good);
    }
}

#[test]
fn kind_names_are_the_core_vocabulary() {
    let name = |code: i32| {
        let mut out = c"stale".as_ptr();
        // SAFETY: a valid out pointer.
        let status = unsafe { nbrdf_sampling_kind_name(code, &mut out) };
        // SAFETY: a static NUL-terminated string when the call succeeds.
        (status == OK).then(|| unsafe { CStr::from_ptr(out) }.to_str().unwrap())
    };
    let names: Vec<&str> = (0..).map_while(name).collect();
    assert_eq!(
        names,
        [
            "uniform",
            "cosine",
            "phong",
            "two_lobe",
            "tabulated",
            "anisotropic_phong"
        ]
    );
    assert_eq!(name(-1), None);
    assert!(
        last_error().contains("unknown sampling kind -1"),
        "{}",
        last_error()
    );
}

#[test]
fn empty_batches_are_ok() {
    let (network, _) = load_network(4);
    let sampler = sampler(null(), &phong(10.0, 0.5));
    let mut buf = [0.0_f32; 3];
    let p = buf.as_mut_ptr();
    // SAFETY: valid pointers, n = 0.
    unsafe {
        assert_eq!(nbrdf_material_eval(network.0, p, p, 0, p), OK);
        assert_eq!(
            nbrdf_material_sample(network.0, sampler.0, p, p, 0, p, p, p),
            OK
        );
        assert_eq!(nbrdf_sampler_pdf(sampler.0, p, p, 0, p), OK);
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
            nbrdf_material_eval(network.0, misaligned, buf.as_ptr(), 1, out.as_mut_ptr()),
            INVALID
        );
        assert!(last_error().contains("`view`"), "{}", last_error());
        assert_eq!(
            nbrdf_material_eval(
                network.0,
                buf.as_ptr(),
                buf.as_ptr(),
                usize::MAX / 2,
                out.as_mut_ptr()
            ),
            INVALID
        );
        let misaligned_params = buf
            .as_ptr()
            .cast::<u8>()
            .wrapping_add(1)
            .cast::<NbrdfSamplerParams>();
        let mut made = null_mut();
        assert_eq!(
            nbrdf_sampler_create(null(), misaligned_params, &mut made),
            INVALID
        );
        assert!(last_error().contains("`params`"), "{}", last_error());
    }
}

#[test]
fn material_info_of_networks_and_tables() {
    for hidden in [4, 9] {
        let (network, _) = load_network(hidden);
        let info = network.info();
        // SAFETY: the name lives as long as the handle.
        let name = unsafe { CStr::from_ptr(info.name) }.to_str().unwrap();
        assert_eq!(name, "ffi-test");
        let expected = 6 * hidden + hidden + hidden * hidden + hidden + hidden * 3 + 3;
        let h = hidden as u32;
        assert_eq!(
            (
                info.kind,
                info.anisotropic,
                info.hidden_width,
                info.parameter_count
            ),
            (
                NbrdfMaterialKind::NBRDF_MATERIAL_NETWORK as i32,
                0,
                h,
                expected as u32
            )
        );
        assert_eq!(
            (info.layer_inputs, info.layer_outputs),
            ([6, h, h], [h, h, 3])
        );
        assert_eq!(info.stored_sampling, phong(40.0, 0.25));
        assert_eq!(info.default_sampling, -1);
    }
    let (merl, _) = load_smooth_merl();
    let info = merl.info();
    // SAFETY: as above.
    assert_eq!(unsafe { CStr::from_ptr(info.name) }.to_bytes(), b"");
    assert_eq!(
        (
            info.kind,
            info.hidden_width,
            info.parameter_count,
            info.layer_inputs
        ),
        (NbrdfMaterialKind::NBRDF_MATERIAL_MERL as i32, 0, 0, [0; 3])
    );
    assert_eq!(
        (info.stored_sampling, info.default_sampling),
        (NbrdfSamplerParams::cosine(), -1)
    );
}

/// `eval(view, light, n, out_rgb)` through the C ABI.
type EvalFn<'a> = &'a dyn Fn(&[f32], &[f32], usize, &mut [f32]) -> i32;
/// `sample(sampler, view, u, n, out_light, out_weight, out_pdf)` through the C ABI.
type SampleFn<'a> =
    &'a dyn Fn(&Sampler, &[f32], &[f32], usize, &mut [f32], &mut [f32], &mut [f32]) -> i32;

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
            params(NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM),
            SamplingStrategy::Uniform,
        ),
        (
            params(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE),
            SamplingStrategy::Cosine,
        ),
        (
            phong(40.0, 0.3),
            SamplingStrategy::Phong {
                exponent: 40.0,
                specular_weight: f64::from(0.3f32),
            },
        ),
    ];
    for (params, strategy) in samplers {
        let sampler = sampler(null(), &params);
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
                sampler.0,
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
            let what = format!("kind {} lane {i}", params.kind);
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

/// `check_layouts` of a material handle.
fn check_material_layouts(material: &Material, brdf: &dyn Brdf) {
    let handle = material.ptr();
    check_layouts(
        brdf,
        // SAFETY: slices of the documented sizes.
        &|view, light, n, rgb| unsafe {
            nbrdf_material_eval(handle, view.as_ptr(), light.as_ptr(), n, rgb.as_mut_ptr())
        },
        &|s, view, u, n, l, w, p| unsafe {
            nbrdf_material_sample(
                handle,
                s.ptr(),
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
fn network_batches_are_planar() {
    let (network, path) = load_network(5);
    check_material_layouts(&network, &Nbrdf::load(&path).unwrap());
}

#[test]
fn merl_batches_are_planar() {
    let (merl, table) = load_smooth_merl();
    check_material_layouts(&merl, &table);
}

/// Samples `params` for `views` through `nbrdf_material_sample`, asks the pdfs of the samples
/// again through `nbrdf_sampler_pdf`, and checks both lane by lane against the core's
/// `expected` strategy.
fn check_mixture_sampling(
    params: &NbrdfSamplerParams,
    expected: &SamplingStrategy,
    views: &[Vec3],
) {
    let (network, _) = load_network(4);
    let sampler = sampler(network.ptr(), params);
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
            nbrdf_material_sample(
                network.0,
                sampler.0,
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
            nbrdf_sampler_pdf(
                sampler.0,
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

/// `bad` variations of sampler parameters are invalid arguments.
fn assert_invalid(bad: &[NbrdfSamplerParams]) {
    for bad in bad {
        assert_eq!(try_sampler(null(), bad).0, INVALID, "{bad:?}");
        assert!(
            last_error().starts_with("nbrdf_sampler_create: "),
            "{}",
            last_error()
        );
    }
}

/// What `NbrdfMaterialInfo::stored_sampling` reports for the network file `json`.
fn stored_sampling(json: &str, name: &str) -> NbrdfSamplerParams {
    load_network_text(json, name).0.info().stored_sampling
}

#[test]
fn two_lobe_samplers() {
    let two = NbrdfSamplerParams {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE as i32,
        exponent: 2000.0,
        specular_weight: 0.4,
        exponent2: 20.0,
        specular_weight2: 0.35,
        exponent_v: f32::NAN, // not read
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
    assert_invalid(&[
        NbrdfSamplerParams {
            specular_weight2: 0.7,
            ..two
        },
        NbrdfSamplerParams {
            exponent2: 2e6,
            ..two
        },
        NbrdfSamplerParams {
            exponent: f32::NAN,
            ..two
        },
    ]);
    // What the file stores: one lobe here, two after adding a second lobe.
    let stored = stored_sampling(&network_json(4), "one-lobe");
    assert_eq!(stored, phong(40.0, 0.25));
    let text = network_json(4).replace(
        r#""source": "manual"}"#,
        r#""source": "manual", "second_lobe": {"exponent": 8.0, "specular_weight": 0.5}}"#,
    );
    let stored = stored_sampling(&text, "two-lobe");
    assert_eq!(
        stored.kind,
        NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE as i32
    );
    assert_eq!((stored.exponent2, stored.specular_weight2), (8.0, 0.5));
}

#[test]
fn anisotropic_samplers() {
    let aniso = NbrdfSamplerParams {
        kind: NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG as i32,
        exponent: 1000.0,
        specular_weight: 0.6,
        exponent_v: 10.0,
        exponent2: f32::NAN, // not read
        specular_weight2: f32::NAN,
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
    assert_invalid(&[
        NbrdfSamplerParams {
            exponent_v: 2e6,
            ..aniso
        },
        NbrdfSamplerParams {
            exponent_v: f32::NAN,
            ..aniso
        },
    ]);
    // A file storing exponent_v reports the anisotropic kind with n_v in exponent_v.
    let text = network_json(4)
        .replace(r#""version": 1,"#, r#""version": 2, "anisotropic": true,"#)
        .replace(
            r#""source": "manual"}"#,
            r#""source": "manual", "exponent_v": 7.5}"#,
        );
    let (network, _) = load_network_text(&text, "aniso-lobe");
    let info = network.info();
    assert_eq!(info.anisotropic, 1);
    assert_eq!(
        info.stored_sampling,
        NbrdfSamplerParams {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG as i32,
            exponent_v: 7.5,
            ..phong(40.0, 0.25)
        }
    );
}

/// `nbrdf_material_active_units` of `params` for `material`: the status and the bytes.
fn active_units(material: &Material, params: &[f32], len: usize) -> (i32, Vec<u8>) {
    let mut out = vec![7u8; len];
    // SAFETY: valid pointers of the sizes passed.
    let status = unsafe {
        nbrdf_material_active_units(
            material.ptr(),
            params.as_ptr(),
            params.len(),
            out.as_mut_ptr(),
            len,
        )
    };
    (status, out)
}

#[test]
fn the_loaded_proof_and_parameters_are_the_core_ones_and_handles_evaluate_without_the_others() {
    let mut net = Nbrdf::random("units", 6, 11);
    for layer in net.layers.iter_mut() {
        for (k, w) in layer.weights.iter_mut().enumerate() {
            *w = 1.5 * ((k as f32 * 0.37).sin());
        }
    }
    net.layers[0].bias[2] = -100.0; // never fires
    net.layers[1].bias[4] = -1e4; // never fires
    let flat = net.to_flat();
    let active = net.active_units();
    let expected: Vec<u8> = active
        .hidden1
        .iter()
        .chain(&active.hidden2)
        .map(|&a| u8::from(a))
        .collect();
    assert_eq!((expected[2], expected[6 + 4]), (0, 0));

    let (handle, path) = load_network_text(&net.to_json_string(), "active-units");
    // What the handle proved at load time, and the parameters as the file stores them.
    let mut params = vec![f32::NAN; flat.len()];
    let mut out = vec![7u8; 12];
    // SAFETY: buffers of the sizes passed.
    let status = unsafe {
        nbrdf_material_network(
            handle.ptr(),
            params.as_mut_ptr(),
            params.len(),
            out.as_mut_ptr(),
            out.len(),
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(out, expected);
    assert_eq!(params, Nbrdf::load(&path).unwrap().to_flat());
    // The parameters alone (no proof asked for): NULL flags of length 0.
    let mut alone = vec![f32::NAN; flat.len()];
    // SAFETY: a buffer of the size passed; no flags.
    let status = unsafe {
        nbrdf_material_network(handle.ptr(), alone.as_mut_ptr(), alone.len(), null_mut(), 0)
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(alone, params);
    // New weights are proved again, through the same material.
    assert_eq!(active_units(&handle, &flat, 12), (OK, expected.clone()));
    let mut all_fire = flat.clone();
    let b1 = 6 * 6;
    all_fire[b1 + 2] = 100.0;
    let (status, again) = active_units(&handle, &all_fire, 12);
    assert_eq!(status, OK);
    assert_eq!(again[2], 1);

    // The handle evaluates what the full network does.
    let core = Nbrdf::load(&path).unwrap();
    let pairs = direction_pairs();
    let n = pairs.len();
    let view = planar(pairs.iter().map(|p| p.0));
    let light = planar(pairs.iter().map(|p| p.1));
    let mut rgb = vec![0.0f32; 3 * n];
    // SAFETY: slices of the documented sizes.
    let status = unsafe {
        nbrdf_material_eval(handle.0, view.as_ptr(), light.as_ptr(), n, rgb.as_mut_ptr())
    };
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

    // Wrong sizes, non-finite parameters, tables and null pointers are refused with a message.
    assert_eq!(active_units(&handle, &flat[1..], 12).0, INVALID);
    assert!(last_error().contains("`params` has"), "{}", last_error());
    assert_eq!(active_units(&handle, &flat, 11).0, INVALID);
    assert!(
        last_error().contains("`out_active` has 11"),
        "{}",
        last_error()
    );
    let mut bad = flat.clone();
    bad[3] = f32::NAN;
    assert_eq!(active_units(&handle, &bad, 12).0, INVALID);
    let (merl, _) = load_smooth_merl();
    assert_eq!(active_units(&merl, &flat, 12).0, INVALID);
    assert!(last_error().contains("MERL table"), "{}", last_error());
    // SAFETY: null pointers and short lengths are what is tested; nothing is written.
    unsafe {
        assert_eq!(
            nbrdf_material_active_units(handle.ptr(), null(), flat.len(), out.as_mut_ptr(), 12),
            NULL
        );
        assert!(last_error().contains("params"), "{}", last_error());
        assert_eq!(
            nbrdf_material_active_units(handle.ptr(), flat.as_ptr(), flat.len(), null_mut(), 12),
            NULL
        );
        let p = params.as_mut_ptr();
        assert_eq!(
            nbrdf_material_network(handle.ptr(), p, params.len() - 1, out.as_mut_ptr(), 12),
            INVALID
        );
        assert!(last_error().contains("`out_params`"), "{}", last_error());
        assert_eq!(
            nbrdf_material_network(handle.ptr(), p, params.len(), out.as_mut_ptr(), 13),
            INVALID
        );
        assert_eq!(
            nbrdf_material_network(handle.ptr(), null_mut(), params.len(), out.as_mut_ptr(), 12),
            NULL
        );
        assert_eq!(
            nbrdf_material_network(merl.ptr(), p, params.len(), out.as_mut_ptr(), 12),
            INVALID
        );
        assert_eq!(
            nbrdf_material_network(null(), p, params.len(), out.as_mut_ptr(), 12),
            NULL
        );
    }
}

#[test]
fn files_are_told_apart_by_their_header() {
    // A table's header makes a table; anything else is read as a network, whose reader names
    // the problem.
    let (merl, _) = load_smooth_merl();
    assert_eq!(
        merl.info().kind,
        NbrdfMaterialKind::NBRDF_MATERIAL_MERL as i32
    );
    let dir = scratch("kinds");
    let odd = dir.join("odd.binary");
    std::fs::write(&odd, [1u8, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 0xff]).unwrap();
    let mut handle = null_mut();
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_material_load(c_path(&odd).as_ptr(), &mut handle) },
        FORMAT
    );
    assert!(last_error().contains("odd.binary"), "{}", last_error());
    // Directories are refused without blocking, by the network reader's checks.
    // SAFETY: valid pointers.
    assert_eq!(
        unsafe { nbrdf_material_load(c_path(&dir).as_ptr(), &mut handle) },
        FORMAT
    );
    assert!(last_error().contains("directory"), "{}", last_error());
    assert!(handle.is_null());
}

#[test]
fn material_base_is_the_files_dictionary_or_null() {
    let base_of = |material: &Material| {
        let mut out = null();
        // SAFETY: a live handle and a writable pointer.
        let status = unsafe { nbrdf_material_base(material.ptr(), &mut out) };
        assert_eq!(status, OK, "{}", last_error());
        // SAFETY: NULL or a NUL-terminated string owned by the handle.
        (!out.is_null()).then(|| unsafe { CStr::from_ptr(out) }.to_str().unwrap().to_string())
    };
    let (plain, _) = load_network(4);
    assert_eq!(base_of(&plain), None);
    let (merl, _) = load_smooth_merl();
    assert_eq!(base_of(&merl), None);
    let text = network_json(4).replacen(
        "\"provenance\"",
        r#""base": {"type": "roughconductor", "alpha": 0.2}, "provenance""#,
        1,
    );
    let (with_base, _) = load_network_text(&text, "net-base");
    let base: serde_json::Value = serde_json::from_str(&base_of(&with_base).unwrap()).unwrap();
    assert_eq!(
        base,
        serde_json::json!({"type": "roughconductor", "alpha": 0.2})
    );
    // The library evaluates the network alone: the same values as without the base.
    let (view, light) = (Vec3::new(0.3, 0.1, 0.9).normalize(), Vec3::Z);
    let eval = |m: &Material| {
        let mut out = [0.0f32; 3];
        let (v, l) = ([view.x, view.y, view.z], [light.x, light.y, light.z]);
        // SAFETY: one pair, planar arrays of 3 floats.
        let status =
            unsafe { nbrdf_material_eval(m.ptr(), v.as_ptr(), l.as_ptr(), 1, out.as_mut_ptr()) };
        assert_eq!(status, OK, "{}", last_error());
        out
    };
    assert_eq!(eval(&with_base), eval(&plain));
    // SAFETY: NULL arguments are reported, not dereferenced.
    unsafe {
        let mut out = null();
        assert_ne!(nbrdf_material_base(null(), &mut out), OK);
        assert!(last_error().contains("material"));
        assert_ne!(nbrdf_material_base(plain.ptr(), null_mut()), OK);
        assert!(last_error().contains("out"));
    }
}
