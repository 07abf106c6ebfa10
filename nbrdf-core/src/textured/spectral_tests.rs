//! Spectral materials (a version-4 file with a `"spectral"` object): values per wavelength
//! against a float64 oracle of the B-spline sum (Cox-de Boor's recursion, written here), the RGB
//! value against `M c`, the file's round trip and its refusals.

use super::file_tests::scratch;
use super::tests::{decoder_layers, mapping, oracle_outputs_cos, uniform};
use super::*;
use crate::network::Spectral;
use crate::rng::SplitMix64;
use crate::spectral_basis::SpectralBasis;
use serde_json::{json, Value};

fn basis(count: usize, min_nm: f64, max_nm: f64) -> SpectralBasis {
    SpectralBasis {
        count,
        min_nm,
        max_nm,
        ..SpectralBasis::default()
    }
}

/// A `width x height` spectral material of 3 latent channels and one lobe.
fn spectral_material(basis: SpectralBasis, seed: u64) -> TexturedNbrdf {
    let (width, height, channels) = (6, 5, 3);
    let mut rng = SplitMix64::from_state(seed);
    let sampling = SamplingChannels::one_lobe();
    let mut texels = Vec::new();
    for _ in 0..width * height {
        texels.extend((0..channels).map(|_| uniform(&mut rng, -1.0, 1.0) as f32));
        texels.extend([encode_exponent(uniform(&mut rng, 4.0, 60.0)), 0.5]);
    }
    let names = TexturedNbrdf::channel_names_for(channels, &sampling);
    let texture = LatentTexture::new(width, height, names, texels).unwrap();
    let layers = decoder_layers(channels, &[16, 12], basis.count, seed + 1);
    let spectral = Spectral::new(basis).unwrap();
    let decoder = Decoder::new(layers, channels, false, Some(spectral)).unwrap();
    let mapping = mapping(WrapMode::Repeat, FilterMode::Bilinear);
    TexturedNbrdf::new("spectral", decoder, texture, mapping, sampling, "s.exr").unwrap()
}

/// `B_k(lambda)` of the clamped uniform cubic B-spline by Cox-de Boor's recursion over the knots
/// `[min]*3 + linspace(min, max, count - 2) + [max]*3` (0/0 taken as 0; the last interval
/// closed at `max`): 0 outside the range and at non-finite wavelengths.
fn oracle_basis(b: &SpectralBasis, lambda: f64) -> Vec<f64> {
    let count = b.count;
    let inner = count - 2;
    let mut knots = vec![b.min_nm; 3];
    knots.extend(
        (0..inner).map(|i| b.min_nm + (b.max_nm - b.min_nm) * i as f64 / (inner - 1) as f64),
    );
    knots.extend([b.max_nm; 3]);
    if !(b.min_nm..=b.max_nm).contains(&lambda) {
        return vec![0.0; count];
    }
    let last = knots.len() - 5; // the last interval of positive length
    let mut n: Vec<f64> = (0..knots.len() - 1)
        .map(|i| {
            let inside = knots[i] <= lambda && lambda < knots[i + 1];
            f64::from(u8::from(inside || (i == last && lambda == b.max_nm)))
        })
        .collect();
    for p in 1..=3 {
        let ratio = |a: f64, d: f64| if d == 0.0 { 0.0 } else { a / d };
        n = (0..n.len() - 1)
            .map(|i| {
                ratio(lambda - knots[i], knots[i + p] - knots[i]) * n[i]
                    + ratio(knots[i + p + 1] - lambda, knots[i + p + 1] - knots[i + 1]) * n[i + 1]
            })
            .collect();
    }
    n.truncate(count);
    n
}

/// Random hits: UVs over and beyond the texture, views and lights over the hemisphere (some
/// below the horizon), planar as the batch entry points read them.
fn hits(n: usize, seed: u64) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = SplitMix64::from_state(seed);
    let mut uv = vec![0.0; 2 * n];
    let (mut view, mut light) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    for i in 0..n {
        uv[i] = uniform(&mut rng, -1.5, 2.5) as f32;
        uv[n + i] = uniform(&mut rng, -1.5, 2.5) as f32;
        for d in [&mut view, &mut light] {
            for a in 0..3 {
                d[a * n + i] = uniform(&mut rng, -1.0, 1.0) as f32;
            }
            d[2 * n + i] = uniform(&mut rng, -0.1, 1.0) as f32;
        }
    }
    (uv, view, light)
}

fn planar3(a: &[f32]) -> crate::brdf::Directions<'_> {
    let n = a.len() / 3;
    crate::brdf::Directions {
        x: &a[..n],
        y: &a[n..2 * n],
        z: &a[2 * n..],
    }
}

fn uvs(a: &[f32]) -> Uvs<'_> {
    let n = a.len() / 2;
    Uvs {
        u: &a[..n],
        v: &a[n..],
    }
}

#[test]
fn spectral_values_and_their_rgb_match_the_float64_oracle() {
    for (b, seed) in [(SpectralBasis::default(), 3), (basis(7, 400.0, 700.0), 4)] {
        let m = spectral_material(b.clone(), seed);
        let n = 300;
        let (uv, view, light) = hits(n, seed + 10);
        let mut rng = SplitMix64::from_state(seed + 20);
        // Three wavelengths per hit: two in the range, one anywhere (outside it is 0).
        let mut wavelengths = vec![0.0f32; 3 * n];
        for (j, w) in wavelengths.iter_mut().enumerate() {
            let (lo, hi) = if j < 2 * n {
                (b.min_nm, b.max_nm)
            } else {
                (300.0, 900.0)
            };
            *w = uniform(&mut rng, lo, hi) as f32;
        }
        wavelengths[0] = b.min_nm as f32;
        wavelengths[1] = b.max_nm as f32;
        wavelengths[2] = f32::NAN;
        let mut out = vec![-1.0f32; 3 * n];
        m.eval_spectral_cos_batch(
            uvs(&uv),
            planar3(&view),
            planar3(&light),
            &wavelengths,
            &mut out,
        )
        .unwrap();
        let mut rgb = vec![-1.0f32; 3 * n];
        m.eval_cos_batch(
            uvs(&uv),
            planar3(&view),
            planar3(&light),
            crate::brdf::RgbMut::from_planar(&mut rgb).unwrap(),
        );
        let matrix = m.decoder().spectral().unwrap().srgb_matrix();
        let mut nonzero = 0;
        for i in 0..n {
            let hit = [uv[i], uv[n + i]];
            let (v, l) = (planar3(&view).get(i), planar3(&light).get(i));
            let c = oracle_outputs_cos(&m, hit, v, l);
            let scale = c.iter().fold(0.0f64, |a, &x| a.max(x.abs()));
            for j in 0..3 {
                let lambda = f64::from(wavelengths[j * n + i]);
                let want: f64 = oracle_basis(&b, lambda)
                    .iter()
                    .zip(&c)
                    .map(|(b, c)| b * c)
                    .sum();
                let got = f64::from(out[j * n + i]);
                assert!(
                    (got - want).abs() <= 2e-5 * scale + 1e-7,
                    "hit {i} lambda {lambda}: {got} vs {want}"
                );
                nonzero += usize::from(want > 0.0);
            }
            for k in 0..3 {
                let want: f64 = (0..b.count).map(|q| matrix[k * b.count + q] * c[q]).sum();
                let got = f64::from(rgb[k * n + i]);
                assert!(
                    (got - want).abs() <= 2e-5 * scale + 1e-7,
                    "hit {i} channel {k}: {got} vs {want}"
                );
            }
            assert_eq!(m.eval_cos(hit, v, l), [rgb[i], rgb[n + i], rgb[2 * n + i]]);
        }
        assert!(nonzero > n, "{nonzero}");
    }
}

#[test]
fn the_oracle_basis_is_the_closed_form_at_interior_knots() {
    let b = SpectralBasis::default();
    let h = 470.0 / 13.0;
    let v = oracle_basis(&b, 360.0 + 6.0 * h);
    for (k, expected) in [(6, 1.0 / 6.0), (7, 2.0 / 3.0), (8, 1.0 / 6.0)] {
        assert!((v[k] - expected).abs() < 1e-12, "{v:?}");
    }
    assert!((oracle_basis(&b, 830.0)[15] - 1.0).abs() < 1e-12);
}

#[test]
fn samples_weigh_the_rgb_projection_by_the_lobes_pdf() {
    let m = spectral_material(SpectralBasis::default(), 5);
    let mut rng = SplitMix64::from_state(6);
    for _ in 0..50 {
        let uv = [rng.next_f32(), rng.next_f32()];
        let view = crate::sampling::uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        let s = m.sample(uv, view, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
        assert_eq!(s.pdf, m.pdf(uv, view, s.light));
        let mut weight = [[0.0f32; 1]; 3];
        let mut light = [[0.0f32; 1]; 3];
        let mut pdf = [0.0f32];
        let [lx, ly, lz] = &mut light;
        let [r, g, b] = &mut weight;
        m.sample_batch(
            Uvs {
                u: &[uv[0]],
                v: &[uv[1]],
            },
            crate::brdf::Directions {
                x: &[view.x],
                y: &[view.y],
                z: &[view.z],
            },
            crate::brdf::Directions {
                x: &[0.3],
                y: &[0.6],
                z: &[0.9],
            },
            crate::brdf::DirectionsMut {
                x: lx,
                y: ly,
                z: lz,
            },
            crate::brdf::RgbMut { r, g, b },
            &mut pdf,
        );
        let l = glam::Vec3::new(light[0][0], light[1][0], light[2][0]);
        let f = m.eval_cos(uv, view, l);
        for c in 0..3 {
            let want = if pdf[0] > 0.0 { f[c] / pdf[0] } else { 0.0 };
            assert!(
                (weight[c][0] - want).abs() <= 1e-6 * want.abs().max(1.0),
                "{weight:?} vs {f:?} / {pdf:?}"
            );
        }
    }
}

#[test]
fn spectral_files_round_trip_and_rgb_files_carry_no_spectral_object() {
    let dir = scratch("spectral-round-trip");
    let m = spectral_material(basis(12, 380.0, 780.0), 7);
    let path = dir.join("s.nbrdf.json");
    m.save(&path, TexturePrecision::Float).unwrap();
    assert_eq!(TexturedNbrdf::load(&path).unwrap(), m);
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(
        json["spectral"],
        json!({"basis": "cubic_bspline", "count": 12, "min_nm": 380.0, "max_nm": 780.0})
    );
    assert_eq!(json["version"], 4);
    let rgb = super::tests::material(3, 2, 2, SamplingChannels::cosine(), UvMapping::default(), 8);
    let json: Value = serde_json::from_str(&rgb.to_json_string()).unwrap();
    assert!(json.get("spectral").is_none(), "{json}");
}

#[test]
fn bad_spectral_objects_are_refused_naming_the_file_and_the_field() {
    let dir = scratch("spectral-refusals");
    let m = spectral_material(SpectralBasis::default(), 9);
    m.save(dir.join("s.nbrdf.json"), TexturePrecision::Half)
        .unwrap();
    let rgb = super::tests::material(
        6,
        5,
        3,
        SamplingChannels::one_lobe(),
        UvMapping::default(),
        9,
    );
    type Edit = fn(&mut Value);
    let cases: Vec<(bool, Edit, &str)> = vec![
        (
            true,
            |j| j["spectral"]["count"] = json!(12),
            "has 16 outputs, expected 12 (spectral.count)",
        ),
        (
            false,
            |j| {
                j["spectral"] =
                    json!({"basis": "cubic_bspline", "count": 16, "min_nm": 360.0, "max_nm": 830.0})
            },
            "has 3 outputs, expected 16 (spectral.count)",
        ),
        (
            true,
            |j| j["spectral"]["basis"] = json!("fourier"),
            "spectral basis 'fourier' is unknown",
        ),
        (
            true,
            |j| j["spectral"]["count"] = json!(3),
            "spectral count 3 must be in [4, 64]",
        ),
        (
            true,
            |j| j["spectral"]["min_nm"] = json!(900.0),
            "spectral min_nm 900 and max_nm 830",
        ),
        (
            true,
            |j| {
                j["spectral"].as_object_mut().unwrap().remove("count");
            },
            "spectral: missing field `count`",
        ),
        (
            true,
            |j| j["spectral"] = json!(16),
            "spectral: invalid type",
        ),
    ];
    rgb.texture()
        .write_exr(&dir.join("r.exr"), TexturePrecision::Half)
        .unwrap();
    for (spectral, edit, message) in cases {
        let path = dir.join("edited.nbrdf.json");
        let source = if spectral { &m } else { &rgb };
        let mut json: Value = serde_json::from_str(&source.to_json_string()).unwrap();
        json["latent"]["path"] = json!(if spectral { "s.exr" } else { "r.exr" });
        edit(&mut json);
        std::fs::write(&path, serde_json::to_string(&json).unwrap()).unwrap();
        let error = TexturedNbrdf::load(&path).unwrap_err().to_string();
        assert!(
            error.contains("edited.nbrdf.json") && error.contains(message),
            "{error} lacks {message}"
        );
    }
}

#[test]
fn spectral_evaluation_refuses_rgb_materials_and_bad_layouts() {
    let rgb = super::tests::material(3, 2, 2, SamplingChannels::cosine(), UvMapping::default(), 8);
    let (uv, view, light) = hits(4, 1);
    let mut out = vec![0.0; 8];
    let error = rgb
        .eval_spectral_cos_batch(
            uvs(&uv),
            planar3(&view),
            planar3(&light),
            &[500.0; 8],
            &mut out,
        )
        .unwrap_err()
        .to_string();
    assert!(error.contains("RGB spatially varying material"), "{error}");
    let m = spectral_material(SpectralBasis::default(), 2);
    for (wavelengths, outputs) in [(8, 4), (6, 6), (4, 8)] {
        let mut out = vec![0.0; outputs];
        let error = m
            .eval_spectral_cos_batch(
                uvs(&uv),
                planar3(&view),
                planar3(&light),
                &vec![500.0; wavelengths],
                &mut out,
            )
            .unwrap_err()
            .to_string();
        assert!(error.contains("both must be m n"), "{error}");
    }
}
