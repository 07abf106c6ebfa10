//! Spectral networks (file format version 3) and spectral spatially varying materials (version
//! 4 with a `spectral` object) through the C ABI: the info fields, per-wavelength evaluation, the
//! sRGB matrix, and the refusals.

mod support;

use glam::Vec3;
use nbrdf_core::brdf::Directions;
use nbrdf_core::network::{Layer, Spectral};
use nbrdf_core::spectral_basis::SpectralBasis;
use nbrdf_core::textured::{
    Decoder, LatentTexture, SamplingChannels, TexturePrecision, TexturedNbrdf, UvMapping, Uvs,
};
use nbrdf_core::Nbrdf;
use nbrdf_ffi::*;
use std::ptr::{null, null_mut};
use support::*;

const COUNT: usize = 16;

/// A spectral network with weights like a trained one, as the core builds it.
fn spectral_net() -> Nbrdf {
    let hidden = 10;
    let mut net = Nbrdf::random("spectral", hidden, 3);
    net.layers[2] = Layer {
        inputs: hidden,
        outputs: COUNT,
        weights: (0..hidden * COUNT)
            .map(|i| ((i * 37 % 23) as f32 / 23.0 - 0.5) * 0.8)
            .collect(),
        bias: (0..COUNT).map(|k| 0.1 * (k as f32).sin()).collect(),
    };
    for layer in &mut net.layers[..2] {
        for (i, w) in layer.weights.iter_mut().enumerate() {
            *w = ((i * 29 % 17) as f32 / 17.0 - 0.5) * 1.2;
        }
    }
    net.spectral = Some(Spectral::new(SpectralBasis::default()).unwrap());
    net
}

/// `nbrdf_material_eval_spectral` over whole buffers, `uv` NULL where `None` and
/// `wavelengths.len() / n` wavelengths a hit: its status and output (-1 where nothing was written).
fn eval_spectral(
    material: &Material,
    uv: Option<&[f32]>,
    view: &[f32],
    light: &[f32],
    wavelengths: &[f32],
    n: usize,
) -> (i32, Vec<f32>) {
    let mut out = vec![-1.0f32; wavelengths.len()];
    // SAFETY: buffers of the sizes passed (`uv` 2 n, the directions 3 n, the rest m n).
    let status = unsafe {
        nbrdf_material_eval_spectral(
            material.ptr(),
            uv.map_or(null(), <[f32]>::as_ptr),
            view.as_ptr(),
            light.as_ptr(),
            wavelengths.as_ptr(),
            n,
            wavelengths.len() / n,
            out.as_mut_ptr(),
        )
    };
    (status, out)
}

fn pairs() -> (Vec<Vec3>, Vec<Vec3>) {
    let dir = |t: f32, p: f32| Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
    let mut view: Vec<Vec3> = (0..20)
        .map(|i| dir(0.07 * i as f32, 0.3 * i as f32))
        .collect();
    let mut light: Vec<Vec3> = (0..20)
        .map(|i| dir(1.4 - 0.06 * i as f32, 2.0 + 0.2 * i as f32))
        .collect();
    view.push(Vec3::Z);
    light.push(Vec3::new(0.3, 0.0, -0.5)); // below the horizon
    (view, light)
}

#[test]
fn info_reports_the_spectral_basis() {
    let net = spectral_net();
    let (material, _) = load_network_text(&net.to_json_string(), "spectral-info");
    let info = material.info();
    assert_eq!(info.spectral_count, 16);
    assert_eq!(info.spectral_range_nm, [360.0, 830.0]);
    assert_eq!(info.layer_outputs, [10, 10, 16]);
    assert_eq!(
        info.parameter_count as usize,
        10 * 10 + 10 * 6 + 20 + 16 * 10 + 16
    );
    let mut params = vec![0.0f32; info.parameter_count as usize];
    let mut active = vec![0u8; 20];
    // SAFETY: buffers of the sizes passed.
    let status = unsafe {
        nbrdf_material_network(
            material.ptr(),
            params.as_mut_ptr(),
            params.len(),
            active.as_mut_ptr(),
            20,
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(params, net.to_flat());
    let mut again = vec![0u8; 20];
    // SAFETY: as above.
    let status = unsafe {
        nbrdf_material_active_units(
            material.ptr(),
            params.as_ptr(),
            params.len(),
            again.as_mut_ptr(),
            20,
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    assert_eq!(again, active);
    let (rgb, _) = load_network(8);
    assert_eq!(rgb.info().spectral_count, 0);
    assert_eq!(rgb.info().spectral_range_nm, [0.0, 0.0]);
}

#[test]
fn spectral_eval_and_rgb_eval_agree_with_the_core() {
    let net = spectral_net();
    let (material, _) = load_network_text(&net.to_json_string(), "spectral-eval");
    let (view, light) = pairs();
    let n = view.len();
    let (v, l) = (planar(view.iter().copied()), planar(light.iter().copied()));
    let m = 4;
    let mut wavelengths: Vec<f32> = (0..m * n).map(|k| 350.0 + 6.1 * k as f32).collect();
    wavelengths[1] = f32::NAN;
    wavelengths[2] = f32::INFINITY;
    let (status, out) = eval_spectral(&material, None, &v, &l, &wavelengths, n);
    assert_eq!(status, OK, "{}", last_error());
    let mut want = vec![0.0f32; m * n];
    let dirs = |p| Directions::from_planar(p).unwrap();
    net.eval_spectral_cos_batch(dirs(&v), dirs(&l), &wavelengths, &mut want)
        .unwrap();
    for (k, (a, b)) in out.iter().zip(&want).enumerate() {
        assert_close(*a, *b, &format!("value {k}"));
    }
    assert_eq!(&out[1..3], &[0.0, 0.0]);
    assert_eq!(out[0], 0.0, "350 nm is outside the basis");
    assert!(
        (0..m).all(|j| out[j * n + n - 1] == 0.0),
        "below the horizon"
    );
    assert!(out.iter().any(|v| *v > 0.0));

    // RGB: M times the coefficients (times the cosine).
    let mut matrix = vec![0.0f32; 3 * COUNT];
    // SAFETY: a buffer of the size passed.
    let status =
        unsafe { nbrdf_material_spectral_srgb(material.ptr(), matrix.as_mut_ptr(), 3 * COUNT) };
    assert_eq!(status, OK, "{}", last_error());
    let mut rgb = vec![0.0f32; 3 * n];
    // SAFETY: buffers of the sizes passed.
    let status =
        unsafe { nbrdf_material_eval(material.ptr(), v.as_ptr(), l.as_ptr(), n, rgb.as_mut_ptr()) };
    assert_eq!(status, OK, "{}", last_error());
    let mut coefficients = vec![0.0f32; n * COUNT];
    net.eval_outputs_cos_batch(dirs(&v), dirs(&l), &mut coefficients);
    for i in 0..n {
        for c in 0..3 {
            let want: f32 = (0..COUNT)
                .map(|k| matrix[c * COUNT + k] * coefficients[i * COUNT + k])
                .sum();
            assert_close(rgb[c * n + i], want, &format!("rgb {i} {c}"));
        }
    }
    // All-ones coefficients are white.
    for c in 0..3 {
        let sum: f32 = matrix[c * COUNT..(c + 1) * COUNT].iter().sum();
        assert!((sum - 1.0).abs() < 1e-3, "{sum}");
    }
}

#[test]
fn spectral_calls_refuse_bad_arguments() {
    let (material, _) = load_network_text(&spectral_net().to_json_string(), "spectral-refuse");
    let d = [0.0f32, 0.0, 1.0];
    let mut out = [0.0f32; 48];
    // SAFETY: each call passes valid buffers except the pointer under test.
    unsafe {
        assert_eq!(
            nbrdf_material_eval_spectral(
                null(),
                null(),
                d.as_ptr(),
                d.as_ptr(),
                d.as_ptr(),
                1,
                1,
                out.as_mut_ptr()
            ),
            NULL
        );
        assert_eq!(
            nbrdf_material_eval_spectral(
                material.ptr(),
                null(),
                null(),
                d.as_ptr(),
                d.as_ptr(),
                1,
                1,
                out.as_mut_ptr()
            ),
            NULL
        );
        assert_eq!(
            nbrdf_material_eval_spectral(
                material.ptr(),
                null(),
                d.as_ptr(),
                d.as_ptr(),
                null(),
                1,
                1,
                out.as_mut_ptr()
            ),
            NULL
        );
        assert_eq!(
            nbrdf_material_eval_spectral(
                material.ptr(),
                null(),
                d.as_ptr(),
                d.as_ptr(),
                d.as_ptr(),
                1,
                1,
                null_mut()
            ),
            NULL
        );
        assert_eq!(
            nbrdf_material_spectral_srgb(material.ptr(), null_mut(), 48),
            NULL
        );
        assert_eq!(
            nbrdf_material_spectral_srgb(material.ptr(), out.as_mut_ptr(), 47),
            INVALID
        );
        assert!(
            last_error().contains("3 NbrdfMaterialInfo::spectral_count"),
            "{}",
            last_error()
        );
    }
    let (rgb, _) = load_network(8);
    // SAFETY: valid buffers.
    unsafe {
        assert_eq!(
            nbrdf_material_eval_spectral(
                rgb.ptr(),
                null(),
                d.as_ptr(),
                d.as_ptr(),
                d.as_ptr(),
                1,
                1,
                out.as_mut_ptr()
            ),
            INVALID
        );
        assert!(last_error().contains("RGB network"), "{}", last_error());
        assert_eq!(
            nbrdf_material_spectral_srgb(rgb.ptr(), out.as_mut_ptr(), 48),
            INVALID
        );
    }
}

/// A spectral spatially varying material (format version 4 with a `spectral` object): 3 latent
/// channels over 4 x 3 texels, cosine sampling; saved, and loaded by the core.
fn spectral_textured() -> (Material, TexturedNbrdf) {
    let channels = 3;
    let mut rng = nbrdf_core::rng::SplitMix64::from_state(11);
    let mut uniform = |scale: f32| scale * (2.0 * rng.next_f32() - 1.0);
    let layers = [(6 + channels, 10), (10, COUNT)]
        .iter()
        .map(|&(inputs, outputs)| Layer {
            inputs,
            outputs,
            weights: (0..inputs * outputs).map(|_| uniform(0.4)).collect(),
            bias: (0..outputs).map(|_| 0.2 + uniform(0.1)).collect(),
        })
        .collect();
    let spectral = Spectral::new(SpectralBasis::default()).unwrap();
    let decoder = Decoder::new(layers, channels, false, Some(spectral)).unwrap();
    let sampling = SamplingChannels::cosine();
    let names = TexturedNbrdf::channel_names_for(channels, &sampling);
    let texels = (0..4 * 3 * channels).map(|_| uniform(1.0)).collect();
    let texture = LatentTexture::new(4, 3, names, texels).unwrap();
    let material = TexturedNbrdf::new(
        "spectral-textured",
        decoder,
        texture,
        UvMapping::default(),
        sampling,
        "latent.exr",
    )
    .unwrap();
    let path = scratch("spectral-textured").join("m.nbrdf.json");
    material.save(&path, TexturePrecision::Float).unwrap();
    (load_material(&path), TexturedNbrdf::load(&path).unwrap())
}

#[test]
fn textured_spectral_materials_evaluate_at_their_uvs() {
    let (material, core) = spectral_textured();
    let info = material.info();
    assert_eq!(info.kind, NbrdfMaterialKind::NBRDF_MATERIAL_TEXTURED as i32);
    assert_eq!(info.spectral_count as usize, COUNT);
    assert_eq!(info.spectral_range_nm, [360.0, 830.0]);
    let (view, light) = pairs();
    let n = view.len();
    let (v, l) = (planar(view.iter().copied()), planar(light.iter().copied()));
    let uv: Vec<f32> = (0..2 * n).map(|k| 0.37 * k as f32 - 2.0).collect();
    let m = 3;
    let wavelengths: Vec<f32> = (0..m * n).map(|k| 365.0 + 7.3 * k as f32).collect();
    let (status, out) = eval_spectral(&material, Some(&uv), &v, &l, &wavelengths, n);
    assert_eq!(status, OK, "{}", last_error());
    let mut want = vec![0.0f32; m * n];
    let dirs = |p| Directions::from_planar(p).unwrap();
    let uvs = Uvs {
        u: &uv[..n],
        v: &uv[n..],
    };
    core.eval_spectral_cos_batch(uvs, dirs(&v), dirs(&l), &wavelengths, &mut want)
        .unwrap();
    assert_eq!(out, want);
    assert!(out.iter().filter(|v| **v > 0.0).count() > n);

    // The sRGB matrix is the basis' and what eval_uv projects with.
    let mut matrix = vec![0.0f32; 3 * COUNT];
    // SAFETY: a buffer of the size passed.
    let status =
        unsafe { nbrdf_material_spectral_srgb(material.ptr(), matrix.as_mut_ptr(), 3 * COUNT) };
    assert_eq!(status, OK, "{}", last_error());
    let basis = Spectral::new(SpectralBasis::default()).unwrap();
    for (a, b) in matrix.iter().zip(basis.srgb_matrix()) {
        assert_eq!(*a, b as f32);
    }

    // Without UVs a textured material is refused, naming the argument.
    let (status, _) = eval_spectral(&material, None, &v, &l, &wavelengths, n);
    assert_eq!(status, NULL);
    assert!(
        last_error().contains("`uv`") && last_error().contains("texture coordinates"),
        "{}",
        last_error()
    );
}
