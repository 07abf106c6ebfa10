//! Spatially varying materials through the C ABI: `nbrdf_material_eval_uv` and
//! `nbrdf_material_sample_uv` against nbrdf-core's `TexturedNbrdf` called directly on the same
//! file, the kind and shape in `nbrdf_material_info`, the homogeneous functions' refusal, the UV
//! functions on homogeneous materials against their own functions, and bad input.

mod support;

use glam::Vec3;
use nbrdf_core::network::Layer;
use nbrdf_core::rng::SplitMix64;
use nbrdf_core::textured::{
    encode_exponent, Decoder, FilterMode, LatentTexture, SamplingChannels, TexturePrecision,
    TexturedNbrdf, UvMapping, UvTransform, Uvs, WrapMode,
};
use nbrdf_core::{Directions, DirectionsMut, RgbMut};
use nbrdf_ffi::*;
use std::path::{Path, PathBuf};
use std::ptr::{null, null_mut};
use support::*;

const CHANNELS: usize = 4;
const WIDTH: usize = 6;
const HEIGHT: usize = 5;

/// A decoder `6 + CHANNELS -> 12 -> 8 -> 3`, weights uniform in `[-1/sqrt(inputs), ..]`, output
/// biases 0.3 so that `f_r` is positive over much of the domain.
fn decoder(rng: &mut SplitMix64) -> Decoder {
    let sizes = [6 + CHANNELS, 12, 8, 3];
    let layers = sizes
        .windows(2)
        .map(|io| {
            let scale = 1.0 / (io[0] as f32).sqrt();
            Layer {
                inputs: io[0],
                outputs: io[1],
                weights: (0..io[0] * io[1])
                    .map(|_| scale * (2.0 * rng.next_f32() - 1.0))
                    .collect(),
                bias: vec![if io[1] == 3 { 0.3 } else { 0.1 }; io[1]],
            }
        })
        .collect();
    Decoder::new(layers, CHANNELS, false, None).unwrap()
}

/// A `WIDTH x HEIGHT` material with one Blinn-Phong lobe per texel (exponents 5 to 60, weights
/// 0.2 to 0.8), `bad_texel` (if any) holding NaN in its first latent channel, written with its
/// texture into a scratch folder; returns the JSON file.
fn write_material(name: &str, mapping: UvMapping, bad_texel: Option<usize>) -> PathBuf {
    let mut rng = SplitMix64::from_state(7);
    let sampling = SamplingChannels::one_lobe();
    let mut texels = Vec::new();
    for texel in 0..WIDTH * HEIGHT {
        let latent: Vec<f32> = (0..CHANNELS).map(|_| 2.0 * rng.next_f32() - 1.0).collect();
        texels.extend(latent);
        if bad_texel == Some(texel) {
            texels[texel * (CHANNELS + 2)] = f32::NAN;
        }
        texels.push(encode_exponent(5.0 + 55.0 * f64::from(rng.next_f32())));
        texels.push(0.2 + 0.6 * rng.next_f32());
    }
    let names = TexturedNbrdf::channel_names_for(CHANNELS, &sampling);
    let texture = LatentTexture::new(WIDTH, HEIGHT, names, texels).unwrap();
    let material = TexturedNbrdf::new(
        "ffi-textured",
        decoder(&mut rng),
        texture,
        mapping,
        sampling,
        "latent.exr",
    )
    .unwrap();
    let path = scratch(name).join("material.nbrdf.json");
    material.save(&path, TexturePrecision::Float).unwrap();
    path
}

/// The material through the C ABI and as nbrdf-core reads the same file.
fn load_both(path: &Path) -> (Material, TexturedNbrdf) {
    (load_material(path), TexturedNbrdf::load(path).unwrap())
}

fn textured(name: &str) -> (Material, TexturedNbrdf) {
    load_both(&write_material(name, UvMapping::default(), None))
}

/// `n` hits: UVs over and beyond `[0, 1]^2`, views and lights over the whole sphere (some below
/// the horizon), uniforms in `[0, 1)`; planar.
struct Hits {
    n: usize,
    uv: Vec<f32>,
    view: Vec<f32>,
    light: Vec<f32>,
    u: Vec<f32>,
}

fn hits(n: usize, seed: u64) -> Hits {
    let mut rng = SplitMix64::from_state(seed);
    let direction = |rng: &mut SplitMix64| {
        let z = 1.2 * rng.next_f32() - 0.2;
        let phi = std::f32::consts::TAU * rng.next_f32();
        let r = (1.0 - z * z).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    let views: Vec<Vec3> = (0..n).map(|_| direction(&mut rng)).collect();
    let lights: Vec<Vec3> = (0..n).map(|_| direction(&mut rng)).collect();
    let uv: Vec<f32> = (0..2 * n).map(|_| 3.0 * rng.next_f32() - 1.0).collect();
    let u: Vec<f32> = (0..3 * n).map(|_| rng.next_f32()).collect();
    Hits {
        n,
        uv,
        view: planar(views.into_iter()),
        light: planar(lights.into_iter()),
        u,
    }
}

fn uvs(uv: &[f32]) -> Uvs<'_> {
    let (u, v) = uv.split_at(uv.len() / 2);
    Uvs { u, v }
}

fn dirs(planar: &[f32]) -> Directions<'_> {
    Directions::from_planar(planar).unwrap()
}

/// `nbrdf_material_eval_uv` with a pdf: status, RGB, pdf.
fn eval_uv(material: &Material, uv: &[f32], view: &[f32], light: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let n = view.len() / 3;
    let (mut rgb, mut pdf) = (vec![-1.0; 3 * n], vec![-1.0; n]);
    // SAFETY: live handle, arrays of the documented sizes.
    let status = unsafe {
        nbrdf_material_eval_uv(
            material.ptr(),
            uv.as_ptr(),
            view.as_ptr(),
            light.as_ptr(),
            n,
            rgb.as_mut_ptr(),
            pdf.as_mut_ptr(),
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    (rgb, pdf)
}

/// `nbrdf_material_sample_uv`: light, weight, pdf.
fn sample_uv(material: &Material, uv: &[f32], view: &[f32], u: &[f32]) -> [Vec<f32>; 3] {
    let n = view.len() / 3;
    let (mut light, mut weight, mut pdf) = (vec![-1.0; 3 * n], vec![-1.0; 3 * n], vec![-1.0; n]);
    // SAFETY: live handle, arrays of the documented sizes.
    let status = unsafe {
        nbrdf_material_sample_uv(
            material.ptr(),
            uv.as_ptr(),
            view.as_ptr(),
            u.as_ptr(),
            n,
            light.as_mut_ptr(),
            weight.as_mut_ptr(),
            pdf.as_mut_ptr(),
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    [light, weight, pdf]
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn eval_uv_and_its_pdf_are_the_core_ones() {
    let (material, core) = textured("eval");
    let h = hits(3000, 1);
    let (rgb, pdf) = eval_uv(&material, &h.uv, &h.view, &h.light);
    let mut want_rgb = vec![0.0; 3 * h.n];
    let mut want_pdf = vec![0.0; h.n];
    core.eval_cos_batch(
        uvs(&h.uv),
        dirs(&h.view),
        dirs(&h.light),
        RgbMut::from_planar(&mut want_rgb).unwrap(),
    );
    core.pdf_batch(uvs(&h.uv), dirs(&h.view), dirs(&h.light), &mut want_pdf);
    assert_eq!(bits(&rgb), bits(&want_rgb));
    assert_eq!(bits(&pdf), bits(&want_pdf));
    // Not a vacuous comparison: the material has values and its lobes vary over the texture.
    assert!(rgb.iter().filter(|&&f| f > 0.0).count() > h.n, "{rgb:?}");
    let i = (0..h.n).find(|&i| pdf[i] > 0.0).unwrap();
    let (v, l) = (lane(&h.view, h.n, i), lane(&h.light, h.n, i));
    assert_ne!(core.pdf([0.1, 0.1], v, l), core.pdf([0.6, 0.5], v, l));

    // Without out_pdf, the same colours.
    let mut again = vec![0.0; 3 * h.n];
    // SAFETY: as in `eval_uv`, out_pdf NULL.
    let status = unsafe {
        nbrdf_material_eval_uv(
            material.ptr(),
            h.uv.as_ptr(),
            h.view.as_ptr(),
            h.light.as_ptr(),
            h.n,
            again.as_mut_ptr(),
            null_mut(),
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(bits(&again), bits(&rgb));
}

#[test]
fn sample_uv_is_the_core_sampling_and_its_pdf_is_eval_uv_pdf() {
    let (material, core) = textured("sample");
    let h = hits(3000, 2);
    let [light, weight, pdf] = sample_uv(&material, &h.uv, &h.view, &h.u);
    let mut want = [vec![0.0; 3 * h.n], vec![0.0; 3 * h.n], vec![0.0; h.n]];
    let [want_light, want_weight, want_pdf] = &mut want;
    core.sample_batch(
        uvs(&h.uv),
        dirs(&h.view),
        dirs(&h.u),
        DirectionsMut::from_planar(want_light).unwrap(),
        RgbMut::from_planar(want_weight).unwrap(),
        want_pdf,
    );
    assert_eq!(bits(&light), bits(want_light));
    assert_eq!(bits(&weight), bits(want_weight));
    assert_eq!(bits(&pdf), bits(want_pdf));

    // The pdf a sample reports is eval_uv's at the sampled direction, and its weight is
    // f_r cos / pdf, as MIS requires.
    let (rgb, pdf_again) = eval_uv(&material, &h.uv, &h.view, &light);
    let mut valid = 0;
    for i in 0..h.n {
        assert_close(pdf[i], pdf_again[i], &format!("pdf of sample {i}"));
        if pdf[i] > 0.0 {
            valid += 1;
            for c in 0..3 {
                let j = c * h.n + i;
                assert_close(
                    weight[j],
                    rgb[j] / pdf[i],
                    &format!("weight {c} of sample {i}"),
                );
            }
        } else {
            assert_eq!([weight[i], weight[h.n + i], weight[2 * h.n + i]], [0.0; 3]);
        }
    }
    assert!(valid > h.n / 2, "{valid} valid samples");
}

#[test]
fn info_reports_the_textured_kind_and_shape() {
    let (material, _) = textured("info");
    let info = material.info();
    assert_eq!(info.kind, NbrdfMaterialKind::NBRDF_MATERIAL_TEXTURED as i32);
    assert_eq!(info.latent_channels, CHANNELS as u32);
    assert_eq!(info.texture_size, [WIDTH as u32, HEIGHT as u32]);
    assert_eq!(info.anisotropic, 0);
    // SAFETY: a NUL-terminated string owned by the live handle.
    let name = unsafe { std::ffi::CStr::from_ptr(info.name) };
    assert_eq!(name.to_str().unwrap(), "ffi-textured");
    assert_eq!(
        (info.hidden_width, info.parameter_count),
        (0, 0),
        "the fields of homogeneous networks"
    );
    assert_eq!((info.layer_inputs, info.layer_outputs), ([0; 3], [0; 3]));
    assert_eq!(info.stored_sampling, NbrdfSamplerParams::cosine());
    assert_eq!((info.default_sampling, info.spectral_count), (-1, 0));

    let (network, _) = load_network(4);
    let info = network.info();
    assert_eq!(info.kind, NbrdfMaterialKind::NBRDF_MATERIAL_NETWORK as i32);
    assert_eq!((info.latent_channels, info.texture_size), (0, [0, 0]));
}

/// Asserts that `status` refuses a textured material with a message naming the UV functions.
fn assert_refused(status: i32, function: &str) {
    let message = last_error();
    assert_eq!(status, INVALID, "{function}: {message}");
    assert!(
        message.starts_with(function) && message.contains("spatially varying"),
        "{message}"
    );
}

#[test]
fn homogeneous_functions_refuse_textured_materials() {
    let (material, _) = textured("refuse");
    let m = material.ptr();
    let cosine = sampler(null(), &NbrdfSamplerParams::cosine());
    let mut buf = [0.5_f32; 12];
    let p = buf.as_mut_ptr();
    let mut active = [0_u8; 8];
    // SAFETY: live handles, buffers large enough for n = 1 (or n = 0).
    unsafe {
        for n in [0, 1] {
            assert_refused(
                nbrdf_material_eval(m, p, p.add(3), n, p.add(6)),
                "nbrdf_material_eval",
            );
            assert!(last_error().contains("nbrdf_material_eval_uv"));
            assert_refused(
                nbrdf_material_sample(m, cosine.ptr(), p, p, n, p.add(3), p.add(6), p.add(9)),
                "nbrdf_material_sample",
            );
        }
        assert_refused(
            nbrdf_material_network(m, p, 12, active.as_mut_ptr(), 8),
            "nbrdf_material_network",
        );
        assert_refused(
            nbrdf_material_active_units(m, p, 12, active.as_mut_ptr(), 8),
            "nbrdf_material_active_units",
        );
        assert_refused(
            nbrdf_material_eval_spectral(m, p, p, p, p, 1, 1, p.add(6)),
            "nbrdf_material_eval_spectral",
        );
        assert_refused(
            nbrdf_material_spectral_srgb(m, p, 12),
            "nbrdf_material_spectral_srgb",
        );
    }
    let (status, made) = try_sampler(m, &params(NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED));
    assert_refused(status, "nbrdf_sampler_create");
    assert!(made.0.is_null());
}

#[test]
fn uv_functions_on_homogeneous_materials_ignore_the_uvs() {
    let (network, _) = load_network(8);
    let stored = sampler(null(), &network.info().stored_sampling);
    let h = hits(200, 3);
    let n = h.n;
    let mut want_rgb = vec![0.0; 3 * n];
    let mut want_pdf = vec![0.0; n];
    let mut want = [vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0.0; n]];
    // SAFETY: live handles, arrays of the documented sizes.
    unsafe {
        let v = h.view.as_ptr();
        assert_eq!(
            nbrdf_material_eval(network.ptr(), v, h.light.as_ptr(), n, want_rgb.as_mut_ptr()),
            OK
        );
        assert_eq!(
            nbrdf_sampler_pdf(stored.ptr(), v, h.light.as_ptr(), n, want_pdf.as_mut_ptr()),
            OK
        );
        let [l, w, p] = &mut want;
        let (l, w, p) = (l.as_mut_ptr(), w.as_mut_ptr(), p.as_mut_ptr());
        assert_eq!(
            nbrdf_material_sample(network.ptr(), stored.ptr(), v, h.u.as_ptr(), n, l, w, p),
            OK
        );
    }
    assert!(want_pdf.iter().any(|&p| p > 0.0) && want_rgb.iter().any(|&f| f > 0.0));
    for uv in [h.uv.clone(), vec![f32::NAN; 2 * n]] {
        let (rgb, pdf) = eval_uv(&network, &uv, &h.view, &h.light);
        assert_eq!((bits(&rgb), bits(&pdf)), (bits(&want_rgb), bits(&want_pdf)));
        let sampled = sample_uv(&network, &uv, &h.view, &h.u);
        assert_eq!(sampled.map(|s| bits(&s)), want.clone().map(|s| bits(&s)));
    }
}

#[test]
fn uv_functions_on_tables_sample_the_cosine_lobe() {
    let (table, _) = load_smooth_merl();
    let cosine = sampler(null(), &NbrdfSamplerParams::cosine());
    let h = hits(100, 4);
    let n = h.n;
    let (mut want_rgb, mut want_pdf) = (vec![0.0; 3 * n], vec![0.0; n]);
    // SAFETY: live handles, arrays of the documented sizes.
    unsafe {
        let (v, l) = (h.view.as_ptr(), h.light.as_ptr());
        assert_eq!(
            nbrdf_material_eval(table.ptr(), v, l, n, want_rgb.as_mut_ptr()),
            OK
        );
        assert_eq!(
            nbrdf_sampler_pdf(cosine.ptr(), v, l, n, want_pdf.as_mut_ptr()),
            OK
        );
    }
    let (rgb, pdf) = eval_uv(&table, &h.uv, &h.view, &h.light);
    assert_eq!((bits(&rgb), bits(&pdf)), (bits(&want_rgb), bits(&want_pdf)));
    let [light, _, pdf] = sample_uv(&table, &h.uv, &h.view, &h.u);
    assert!(pdf.iter().any(|&p| p > 0.0));
    for (i, &pdf) in pdf.iter().enumerate() {
        let (v, l) = (lane(&h.view, n, i), lane(&light, n, i));
        let cosine_pdf = if v.z > 0.0 {
            l.z.max(0.0) / std::f32::consts::PI
        } else {
            0.0
        };
        assert_close(pdf, cosine_pdf, &format!("pdf of sample {i}"));
    }
}

/// Every value finite.
fn assert_harmless(values: &[f32], what: &str) {
    assert!(values.iter().all(|v| v.is_finite()), "{what}: {values:?}");
}

#[test]
fn bad_uvs_and_directions_give_finite_values() {
    let (material, core) = textured("bad-uvs");
    let specials = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MAX,
        -f32::MAX,
        1e30,
        -1e30,
        1e7 + 0.5,
        -3.25,
        0.5,
    ];
    let mut uv_u = Vec::new();
    let mut uv_v = Vec::new();
    for &a in &specials {
        for &b in &specials {
            uv_u.push(a);
            uv_v.push(b);
        }
    }
    let n = uv_u.len();
    let uv: Vec<f32> = uv_u.iter().chain(&uv_v).copied().collect();
    let mut view = planar((0..n).map(|i| Vec3::new(0.3, -0.2 + 0.01 * i as f32, 0.8)));
    view[0] = f32::NAN; // one lane with a non-finite view and one with a zero view
    view[2 * n + 1] = 0.0;
    view[1] = 0.0;
    view[n + 1] = 0.0;
    let light = planar((0..n).map(|i| Vec3::new(-0.1 * (i % 7) as f32, 0.25, 0.9)));
    let u: Vec<f32> = (0..3 * n)
        .map(|i| ((i * 37) % 100) as f32 / 100.0)
        .collect();

    let (rgb, pdf) = eval_uv(&material, &uv, &view, &light);
    assert_harmless(&rgb, "rgb");
    assert_harmless(&pdf, "pdf");
    let [sampled, weight, sample_pdf] = sample_uv(&material, &uv, &view, &u);
    assert_harmless(&sampled, "light");
    assert_harmless(&weight, "weight");
    assert_harmless(&sample_pdf, "pdf");
    assert!(rgb.iter().chain(&pdf).chain(&weight).all(|&x| x >= 0.0));
    for i in 0..n {
        let hit = [uv_u[i], uv_v[i]];
        if !(hit[0].is_finite() && hit[1].is_finite()) {
            assert_eq!([rgb[i], rgb[n + i], rgb[2 * n + i]], [0.0; 3], "uv {hit:?}");
        }
        let (v, l) = (lane(&view, n, i), lane(&light, n, i));
        let want = core.eval_cos(hit, v, l);
        assert_eq!(
            [rgb[i], rgb[n + i], rgb[2 * n + i]].map(f32::to_bits),
            want.map(f32::to_bits),
            "uv {hit:?}"
        );
        assert_eq!(
            pdf[i].to_bits(),
            core.pdf(hit, v, l).to_bits(),
            "uv {hit:?}"
        );
    }
}

#[test]
fn a_nan_texel_is_zero_and_harmless() {
    let mapping = UvMapping {
        to_uv: UvTransform::IDENTITY,
        wrap: WrapMode::Clamp,
        filter: FilterMode::Nearest,
    };
    let bad = 2 * WIDTH + 3; // texel (3, 2)
    let (material, core) = load_both(&write_material("nan-texel", mapping, Some(bad)));
    let centre = |x: usize, y: usize| {
        [
            (x as f32 + 0.5) / WIDTH as f32,
            (y as f32 + 0.5) / HEIGHT as f32,
        ]
    };
    let hits_uv = [centre(3, 2), centre(1, 1)];
    let uv = vec![hits_uv[0][0], hits_uv[1][0], hits_uv[0][1], hits_uv[1][1]];
    let view = planar([Vec3::new(0.2, 0.1, 0.9); 2].into_iter());
    let light = planar([Vec3::new(-0.2, -0.1, 0.9); 2].into_iter());
    let u = vec![0.3, 0.7, 0.4, 0.2, 0.6, 0.9];
    let (rgb, pdf) = eval_uv(&material, &uv, &view, &light);
    assert_eq!([rgb[0], rgb[2], rgb[4]], [0.0; 3]);
    assert!(rgb[1] > 0.0, "the neighbouring texel has a value: {rgb:?}");
    assert_harmless(&pdf, "pdf");
    let [sampled, weight, sample_pdf] = sample_uv(&material, &uv, &view, &u);
    assert_harmless(&sampled, "light");
    assert_eq!([weight[0], weight[2], weight[4]], [0.0; 3]);
    assert_harmless(&weight, "weight");
    assert_harmless(&sample_pdf, "pdf");
    // The bad texel's lobes still draw the light, with the core's pdf.
    let want = core.sample(hits_uv[0], lane(&view, 2, 0), [u[0], u[2], u[4]]);
    assert_eq!(lane(&sampled, 2, 0), want.light);
    assert_eq!(sample_pdf[0], want.pdf);
    assert!(sample_pdf[0] > 0.0);
}

#[test]
fn null_pointers_and_sizes_are_refused_and_empty_batches_are_ok() {
    let (material, _) = textured("null");
    let m = material.ptr();
    let buf = [0.5_f32; 16];
    let mut out = [0.0_f32; 16];
    let (p, o) = (buf.as_ptr(), out.as_mut_ptr());
    // SAFETY: null arguments are rejected before any access; valid buffers otherwise.
    unsafe {
        let eval_cases: [(i32, &str); 6] = [
            (
                nbrdf_material_eval_uv(null(), p, p, p, 1, o, o.add(3)),
                "material",
            ),
            (
                nbrdf_material_eval_uv(m, null(), p, p, 1, o, o.add(3)),
                "uv",
            ),
            (
                nbrdf_material_eval_uv(m, p, null(), p, 1, o, o.add(3)),
                "view",
            ),
            (
                nbrdf_material_eval_uv(m, p, p, null(), 1, o, o.add(3)),
                "light",
            ),
            (
                nbrdf_material_eval_uv(m, p, p, p, 1, null_mut(), o),
                "out_rgb",
            ),
            (
                nbrdf_material_eval_uv(m, p, p, p, 0, null_mut(), o),
                "out_rgb",
            ),
        ];
        for (status, argument) in eval_cases {
            assert_eq!(status, NULL, "{argument}");
        }
        let sample = |m, uv, view, u, light, weight, pdf| {
            let status = nbrdf_material_sample_uv(m, uv, view, u, 1, light, weight, pdf);
            (status, last_error())
        };
        for (result, argument) in [
            (sample(null(), p, p, p, o, o, o), "material"),
            (sample(m, null(), p, p, o, o, o), "uv"),
            (sample(m, p, null(), p, o, o, o), "view"),
            (sample(m, p, p, null(), o, o, o), "u"),
            (sample(m, p, p, p, null_mut(), o, o), "out_light"),
            (sample(m, p, p, p, o, null_mut(), o), "out_weight"),
            (sample(m, p, p, p, o, o, null_mut()), "out_pdf"),
        ] {
            assert_eq!(result.0, NULL, "{argument}");
            assert!(
                result.1.starts_with("nbrdf_material_sample_uv")
                    && result.1.contains(&format!("`{argument}`")),
                "{argument}: {}",
                result.1
            );
        }

        // n = 0 touches nothing.
        out = [7.0; 16];
        let o = out.as_mut_ptr();
        assert_eq!(nbrdf_material_eval_uv(m, p, p, p, 0, o, null_mut()), OK);
        assert_eq!(nbrdf_material_sample_uv(m, p, p, p, 0, o, o, o), OK);
        assert_eq!(out, [7.0; 16]);

        let misaligned = p.cast::<u8>().wrapping_add(1).cast::<f32>();
        assert_eq!(
            nbrdf_material_eval_uv(m, misaligned, p, p, 1, o, null_mut()),
            INVALID
        );
        assert!(last_error().contains("`uv`"), "{}", last_error());
        let misaligned_out = o.cast::<u8>().wrapping_add(1).cast::<f32>();
        assert_eq!(
            nbrdf_material_eval_uv(m, p, p, p, 1, o, misaligned_out),
            INVALID
        );
        assert!(last_error().contains("`out_pdf`"), "{}", last_error());
        for n in [usize::MAX / 2, usize::MAX / 3 + 1] {
            assert_eq!(
                nbrdf_material_eval_uv(m, p, p, p, n, o, null_mut()),
                INVALID
            );
            assert_eq!(nbrdf_material_sample_uv(m, p, p, p, n, o, o, o), INVALID);
        }
    }
}

/// Loads `path` through the C ABI, expecting a failure: the status and the message.
fn load_failure(path: &Path) -> (i32, String) {
    let mut handle = 1 as *mut NbrdfMaterial; // must be overwritten with null
                                              // SAFETY: valid path and out pointer.
    let status = unsafe { nbrdf_material_load(c_path(path).as_ptr(), &mut handle) };
    assert!(handle.is_null());
    (status, last_error())
}

#[test]
fn missing_or_wrong_textures_are_errors_naming_the_files() {
    let path = write_material("missing-texture", UvMapping::default(), None);
    let texture = path.with_file_name("latent.exr");

    std::fs::write(&texture, b"not an EXR file").unwrap();
    let (status, message) = load_failure(&path);
    assert_eq!(status, FORMAT, "{message}");
    assert!(
        message.starts_with("nbrdf_material_load: ")
            && message.contains(path.to_str().unwrap())
            && message.contains("latent.path \"latent.exr\""),
        "{message}"
    );

    std::fs::remove_file(&texture).unwrap();
    let (status, message) = load_failure(&path);
    assert_eq!(status, FORMAT, "{message}");
    assert!(
        message.contains(path.to_str().unwrap()) && message.contains("latent.exr"),
        "{message}"
    );

    // A texture of another material's shape: the width the JSON file states is not the file's.
    let json = std::fs::read_to_string(&path).unwrap();
    let other = write_material("other-texture", UvMapping::default(), None);
    std::fs::copy(other.with_file_name("latent.exr"), &texture).unwrap();
    std::fs::write(&path, json.replace("\"width\": 6", "\"width\": 7")).unwrap();
    let (status, message) = load_failure(&path);
    assert_eq!(status, FORMAT, "{message}");
    assert!(
        message.contains(path.to_str().unwrap()) && message.contains("latent.exr"),
        "{message}"
    );
}
