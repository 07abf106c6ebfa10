//! The texture lookup and the decoder against float64 oracles written here from the definitions
//! (docs/textured.md), batches against single hits, bad texels and extreme UVs.
//! Validation and files: `file_tests.rs`; sampling: `sampling_tests.rs`.

use super::*;
use crate::network::Layer;
use crate::rng::SplitMix64;
use glam::DVec3;

/// A uniform value in `[lo, hi)`.
pub(super) fn uniform(rng: &mut SplitMix64, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.next_f64()
}

/// A decoder `6 + channels -> widths... -> 3` with weights uniform in `[-scale, scale]` and
/// output biases 0.3, so that `f_r` is positive over much of the domain.
pub(super) fn decoder(channels: usize, widths: &[usize], anisotropic: bool, seed: u64) -> Decoder {
    let layers = decoder_layers(channels, widths, 3, seed);
    Decoder::new(layers, channels, anisotropic, None).unwrap()
}

/// The layers of [`decoder`] with `outputs` outputs.
pub(super) fn decoder_layers(
    channels: usize,
    widths: &[usize],
    outputs: usize,
    seed: u64,
) -> Vec<Layer> {
    let mut rng = SplitMix64::from_state(seed);
    let mut sizes = vec![6 + channels];
    sizes.extend_from_slice(widths);
    sizes.push(outputs);
    sizes
        .windows(2)
        .enumerate()
        .map(|(k, io)| {
            let scale = 1.0 / (io[0] as f64).sqrt();
            Layer {
                inputs: io[0],
                outputs: io[1],
                weights: (0..io[0] * io[1])
                    .map(|_| uniform(&mut rng, -scale, scale) as f32)
                    .collect(),
                bias: (0..io[1])
                    .map(|_| if k + 2 == sizes.len() { 0.3 } else { 0.1 })
                    .collect(),
            }
        })
        .collect()
}

/// Per-texel lobe values: exponents in `[4, 60]` (encoded), weights in `[0.2, 0.8]`, the two
/// weights of two lobes summing to at most 0.9.
pub(super) fn lobe_values(rng: &mut SplitMix64, lobes: usize) -> Vec<f32> {
    match lobes {
        0 => vec![],
        1 => vec![
            encode_exponent(uniform(rng, 4.0, 60.0)),
            uniform(rng, 0.2, 0.8) as f32,
        ],
        _ => vec![
            encode_exponent(uniform(rng, 20.0, 60.0)),
            uniform(rng, 0.2, 0.5) as f32,
            encode_exponent(uniform(rng, 2.0, 10.0)),
            uniform(rng, 0.1, 0.4) as f32,
        ],
    }
}

/// A `width x height` material with `channels` latent channels uniform in `[-1, 1]`.
pub(super) fn material(
    width: usize,
    height: usize,
    channels: usize,
    sampling: SamplingChannels,
    mapping: UvMapping,
    seed: u64,
) -> TexturedNbrdf {
    let mut rng = SplitMix64::from_state(seed);
    let lobes = sampling.lobes().len();
    let mut texels = Vec::new();
    for _ in 0..width * height {
        texels.extend((0..channels).map(|_| uniform(&mut rng, -1.0, 1.0) as f32));
        texels.extend(lobe_values(&mut rng, lobes));
    }
    let names = TexturedNbrdf::channel_names_for(channels, &sampling);
    let texture = LatentTexture::new(width, height, names, texels).unwrap();
    let decoder = decoder(channels, &[16, 12], false, seed + 1);
    TexturedNbrdf::new("test", decoder, texture, mapping, sampling, "test.exr").unwrap()
}

pub(super) fn mapping(wrap: WrapMode, filter: FilterMode) -> UvMapping {
    UvMapping {
        to_uv: UvTransform::IDENTITY,
        wrap,
        filter,
    }
}

/// Texel index `i` wrapped into `[0, n)`: periodic; mirrored as `i = p n + r`, `r` read as is
/// in even periods `p` and reflected (`n - 1 - r`) in odd ones; or clamped.
fn oracle_wrap(i: i128, n: i128, wrap: WrapMode) -> usize {
    let wrapped = match wrap {
        WrapMode::Repeat => ((i % n) + n) % n,
        WrapMode::Mirror => {
            let (p, r) = (i.div_euclid(n), i.rem_euclid(n));
            if p % 2 == 0 {
                r
            } else {
                n - 1 - r
            }
        }
        WrapMode::Clamp => i.clamp(0, n - 1),
    };
    wrapped as usize
}

/// Mitsuba's `bitmap` lookup in float64: `(u', v')` = `to_uv (u, v, 1)`; bilinear reads the
/// texels whose centres `(i + 1/2) / width` surround `u' width`, weighted by distance, nearest
/// the texel `u' width` falls in; indices wrapped. The position `u' width - 1/2` is rounded to
/// float32 once, as the format defines it (Dr.Jit's float32 `fmadd`). `None` for non-finite
/// positions or values.
pub(super) fn oracle_lookup(
    texture: &LatentTexture,
    mapping: &UvMapping,
    uv: [f32; 2],
) -> Option<Vec<f64>> {
    let m = mapping.to_uv.matrix.map(|row| row.map(f64::from));
    let (u, v) = (f64::from(uv[0]), f64::from(uv[1]));
    let mapped = [
        m[0][0] * u + m[0][1] * v + m[0][2],
        m[1][0] * u + m[1][1] * v + m[1][2],
    ];
    let bilinear = mapping.filter == FilterMode::Bilinear;
    let sizes = [texture.width(), texture.height()];
    let mut axes = Vec::new();
    for (coord, size) in mapped.into_iter().zip(sizes) {
        let offset = if bilinear { 0.5 } else { 0.0 };
        let position = f64::from((coord * size as f64 - offset) as f32);
        if !position.is_finite() {
            return None;
        }
        let base = position.floor();
        let frac = position - base;
        let wrap = |i: f64| oracle_wrap(i as i128, size as i128, mapping.wrap);
        axes.push(if bilinear {
            vec![(wrap(base), 1.0 - frac), (wrap(base + 1.0), frac)]
        } else {
            vec![(wrap(base), 1.0)]
        });
    }
    let mut out = vec![0.0; texture.channel_count()];
    for &(y, wy) in &axes[1] {
        for &(x, wx) in &axes[0] {
            for (o, &c) in out.iter_mut().zip(texture.texel(x, y)) {
                *o += wx * wy * f64::from(c);
            }
        }
    }
    out.iter().all(|c| c.is_finite()).then_some(out)
}

/// `f_r cos` in float64: the oracle's code, the input `[h, d]` of docs/design.md sections 2 and
/// 4 from [`crate::coords::half_diff`] (`phi_h` dropped unless anisotropic), dense layers with
/// ReLU, `max(exp(z) - 1, 0)`, times `cos theta_l`.
pub(super) fn oracle_eval_cos(
    m: &TexturedNbrdf,
    uv: [f32; 2],
    view: Vec3,
    light: Vec3,
) -> [f64; 3] {
    let x = oracle_outputs_cos(m, uv, view, light);
    [x[0], x[1], x[2]]
}

/// [`oracle_eval_cos`] for every output of the decoder (a spectral decoder's coefficients).
pub(super) fn oracle_outputs_cos(
    m: &TexturedNbrdf,
    uv: [f32; 2],
    view: Vec3,
    light: Vec3,
) -> Vec<f64> {
    let zero = vec![0.0; m.decoder().output_count()];
    let (v, l) = (view.as_dvec3().normalize(), light.as_dvec3().normalize());
    let Some(code) = oracle_lookup(m.texture(), m.mapping(), uv) else {
        return zero;
    };
    if v.z <= 0.0 || l.z <= 0.0 {
        return zero;
    }
    let hd = crate::coords::half_diff(v, l);
    let (h, d) = (hd.half, hd.diff);
    let mut x = if m.decoder().anisotropic() {
        vec![h.x, h.y, h.z, d.x, d.y, d.z]
    } else {
        vec![h.x.hypot(h.y), 0.0, h.z, d.x, d.y, d.z]
    };
    x.extend_from_slice(&code[..m.decoder().latent_channels()]);
    let layers = m.decoder().layers();
    for (k, layer) in layers.iter().enumerate() {
        let y: Vec<f64> = (0..layer.outputs)
            .map(|o| {
                let z = f64::from(layer.bias[o])
                    + (0..layer.inputs)
                        .map(|i| x[i] * f64::from(layer.weights[i * layer.outputs + o]))
                        .sum::<f64>();
                if k + 1 < layers.len() {
                    z.max(0.0)
                } else {
                    (z.exp() - 1.0).max(0.0) * l.z
                }
            })
            .collect();
        x = y;
    }
    x
}

/// A few UVs far outside `[0, 1]` at which float32 positions are exact (dyadic fractions).
const FAR_UVS: [[f32; 2]; 6] = [
    [1e6, -1e6],
    [-1e6 - 0.375, 1e6 + 0.25],
    [12345.125, -777.5],
    [1e30, -1e30],
    [-3.25, 40.0625],
    [1.0, 0.0],
];

/// Whether `to_uv (uv)` lies within 1e-4 texel of a texel edge.
fn near_texel_edge(to_uv: &UvTransform, sizes: [usize; 2], uv: [f32; 2]) -> bool {
    let m = to_uv.matrix.map(|row| row.map(f64::from));
    let (u, v) = (f64::from(uv[0]), f64::from(uv[1]));
    let mapped = [
        m[0][0] * u + m[0][1] * v + m[0][2],
        m[1][0] * u + m[1][1] * v + m[1][2],
    ];
    mapped.iter().zip(sizes).any(|(c, size)| {
        let p = c * size as f64;
        (p - p.round()).abs() < 1e-4
    })
}

#[test]
fn lookup_matches_the_float64_oracle_for_each_wrap_and_filter() {
    let mut rng = SplitMix64::from_state(3);
    let transforms = [
        UvTransform::IDENTITY,
        UvTransform {
            matrix: [[2.5, 0.5, 0.125], [-0.75, 1.5, -0.3], [0.0, 0.0, 1.0]],
        },
    ];
    for (width, height) in [(8, 8), (5, 3)] {
        for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
            for filter in [FilterMode::Bilinear, FilterMode::Nearest] {
                for to_uv in transforms {
                    let mapping = UvMapping {
                        to_uv,
                        wrap,
                        filter,
                    };
                    let m = material(width, height, 4, SamplingChannels::one_lobe(), mapping, 9);
                    let mut uvs: Vec<[f32; 2]> = (0..400)
                        .map(|_| [uniform(&mut rng, -3.0, 4.0), uniform(&mut rng, -3.0, 4.0)])
                        .map(|uv| uv.map(|c| c as f32))
                        .collect();
                    if to_uv == UvTransform::IDENTITY {
                        uvs.extend(FAR_UVS);
                    }
                    for uv in uvs {
                        let got = m.texture().lookup(m.mapping(), uv).unwrap();
                        let want = oracle_lookup(m.texture(), m.mapping(), uv).unwrap();
                        // Nearest flips texel where the float32 and float64 `to_uv` straddle
                        // a texel edge; elsewhere only rounding separates them.
                        let near_edge = filter == FilterMode::Nearest
                            && near_texel_edge(&to_uv, [width, height], uv);
                        for (g, w) in got.iter().zip(&want) {
                            let close = (f64::from(*g) - w).abs() <= 1e-5 * (1.0 + w.abs());
                            assert!(
                                close || near_edge,
                                "{width}x{height} {wrap:?} {filter:?} {to_uv:?} uv {uv:?}: \
                                 {got:?} vs {want:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn texel_centres_read_the_texel_and_wrap_modes_differ_outside() {
    let m = material(5, 3, 4, SamplingChannels::cosine(), UvMapping::default(), 4);
    let t = m.texture();
    let centre = |x: usize, y: usize| [(x as f32 + 0.5) / 5.0, (y as f32 + 0.5) / 3.0];
    for filter in [FilterMode::Bilinear, FilterMode::Nearest] {
        let mapping = mapping(WrapMode::Repeat, filter);
        assert_eq!(t.lookup(&mapping, centre(2, 1)).unwrap(), t.texel(2, 1));
    }
    // The centre one period to the left: texel 4 repeating, texel 0 mirrored, 0 clamped.
    let left = [-0.5 / 5.0, 0.5 / 3.0];
    let read = |wrap| t.lookup(&mapping(wrap, FilterMode::Nearest), left).unwrap();
    assert_eq!(read(WrapMode::Repeat), t.texel(4, 0));
    assert_eq!(read(WrapMode::Mirror), t.texel(0, 0));
    assert_eq!(read(WrapMode::Clamp), t.texel(0, 0));
    let far_left = [-1.5 / 5.0, 0.5 / 3.0];
    let read = |wrap| {
        t.lookup(&mapping(wrap, FilterMode::Nearest), far_left)
            .unwrap()
    };
    assert_eq!(read(WrapMode::Repeat), t.texel(3, 0));
    assert_eq!(read(WrapMode::Mirror), t.texel(1, 0));
    assert_eq!(read(WrapMode::Clamp), t.texel(0, 0));
}

#[test]
fn eval_matches_the_float64_forward_pass() {
    let mut rng = SplitMix64::from_state(8);
    for anisotropic in [false, true] {
        for filter in [FilterMode::Bilinear, FilterMode::Nearest] {
            let mut m = material(
                8,
                8,
                4,
                SamplingChannels::one_lobe(),
                mapping(WrapMode::Mirror, filter),
                5,
            );
            m.decoder = decoder(4, &[16, 12], anisotropic, 6);
            let mut positive = 0;
            for k in 0..500 {
                let uv = [
                    uniform(&mut rng, -2.0, 3.0) as f32,
                    uniform(&mut rng, -2.0, 3.0) as f32,
                ];
                let hemisphere = |rng: &mut SplitMix64| {
                    let d = crate::sampling::uniform_hemisphere(rng.next_f64(), rng.next_f64());
                    // Some directions below the horizon, some not of unit length.
                    let flip = if k % 7 == 0 { -1.0 } else { 1.0 };
                    (DVec3::new(d.x, d.y, flip * d.z) * (0.5 + 2.0 * rng.next_f64())).as_vec3()
                };
                let (view, light) = (hemisphere(&mut rng), hemisphere(&mut rng));
                let got = m.eval_cos(uv, view, light);
                let want = oracle_eval_cos(&m, uv, view, light);
                for (g, w) in got.iter().zip(want) {
                    assert!(
                        (f64::from(*g) - w).abs() <= 1e-4 * w.abs() + 1e-6,
                        "aniso {anisotropic} {filter:?} uv {uv:?} {view} {light}: {got:?} vs {want:?}"
                    );
                }
                positive += usize::from(got.iter().all(|&c| c > 0.0));
            }
            assert!(positive > 200, "only {positive} positive values");
        }
    }
}

#[test]
fn a_non_finite_texel_makes_its_footprint_zero_and_nothing_else() {
    let m = material(
        8,
        8,
        4,
        SamplingChannels::one_lobe(),
        UvMapping::default(),
        7,
    );
    let (width, channels) = (8, m.texture().channel_count());
    let mut texels = m.texture().texels().to_vec();
    texels[(3 * width + 5) * channels + 2] = f32::NAN;
    texels[(6 * width + 1) * channels] = f32::INFINITY;
    let names = m.texture().channel_names().to_vec();
    let texture = LatentTexture::new(8, 8, names, texels).unwrap();
    let bad = TexturedNbrdf::new(
        "bad",
        m.decoder().clone(),
        texture,
        *m.mapping(),
        SamplingChannels::one_lobe(),
        "x.exr",
    )
    .unwrap();
    let (view, light) = (Vec3::new(0.3, 0.1, 0.9), Vec3::new(-0.2, 0.4, 0.8));
    let mut zero = 0;
    for j in 0..64 {
        for i in 0..64 {
            let uv = [(i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 64.0];
            let value = bad.eval_cos(uv, view, light);
            let reads_bad = bad.footprint(uv).is_some_and(|f| {
                f.texels()
                    .iter()
                    .any(|&t| t == 3 * width + 5 || t == 6 * width + 1)
            });
            if reads_bad {
                assert_eq!(value, [0.0; 3], "uv {uv:?}");
                zero += 1;
            } else {
                assert_eq!(value, m.eval_cos(uv, view, light), "uv {uv:?}");
            }
            assert!(bad.pdf(uv, view, light).is_finite());
        }
    }
    // Each bad texel's bilinear footprint spans two texels' width each way.
    assert!(zero >= 2 * 16 * 16, "{zero}");
}

#[test]
fn extreme_uvs_and_directions_give_finite_values() {
    let m = material(
        8,
        8,
        4,
        SamplingChannels::two_lobes(),
        UvMapping::default(),
        11,
    );
    let extremes = [
        0.0,
        1.0,
        1e6,
        -1e6,
        1e30,
        -1e30,
        f32::MAX,
        f32::MIN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        1e-45,
    ];
    let directions = [
        Vec3::new(0.3, 0.2, 0.9),
        Vec3::new(1e30, 0.0, 1e20),
        Vec3::new(1e-30, 0.0, 1e-30),
        Vec3::ZERO,
        Vec3::new(f32::NAN, 0.0, 1.0),
        Vec3::new(0.0, 0.0, f32::INFINITY),
    ];
    for u in extremes {
        for v in extremes {
            let uv = [u, v];
            for view in directions {
                for light in directions {
                    let value = m.eval_cos(uv, view, light);
                    assert!(
                        value.iter().all(|c| c.is_finite() && *c >= 0.0),
                        "{uv:?}: {value:?}"
                    );
                    let s = m.sample(uv, view, [0.3, 0.6, 0.9]);
                    assert!(s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0);
                    assert!(m.pdf(uv, view, light).is_finite());
                }
            }
            if !(u.is_finite() && v.is_finite()) {
                assert_eq!(m.eval_cos(uv, directions[0], directions[0]), [0.0; 3]);
                assert_eq!(m.sampling_strategy(uv), SamplingStrategy::Cosine);
            }
        }
    }
}

#[test]
fn batches_equal_single_hits() {
    let m = material(
        8,
        8,
        4,
        SamplingChannels::two_lobes(),
        UvMapping::default(),
        13,
    );
    let n = 2 * TASK_LANES + 300;
    let mut rng = SplitMix64::from_state(14);
    let mut planar = |lo: f64, hi: f64| -> Vec<f32> {
        (0..n).map(|_| uniform(&mut rng, lo, hi) as f32).collect()
    };
    let (u, v) = (planar(-2.0, 3.0), planar(-2.0, 3.0));
    let (vx, vy, vz) = (planar(-1.0, 1.0), planar(-1.0, 1.0), planar(-0.2, 1.0));
    let (lx, ly, lz) = (planar(-1.0, 1.0), planar(-1.0, 1.0), planar(-0.2, 1.0));
    let (u0, u1, u2) = (planar(0.0, 1.0), planar(0.0, 1.0), planar(0.0, 1.0));
    let mut u = u;
    u[5] = f32::NAN;
    u[TASK_LANES + 1] = 1e30;
    let uv = Uvs { u: &u, v: &v };
    let view = Directions {
        x: &vx,
        y: &vy,
        z: &vz,
    };
    let light = Directions {
        x: &lx,
        y: &ly,
        z: &lz,
    };
    let uniforms = Directions {
        x: &u0,
        y: &u1,
        z: &u2,
    };

    let mut rgb = vec![-1.0f32; 3 * n];
    m.eval_cos_batch(uv, view, light, RgbMut::from_planar(&mut rgb).unwrap());
    let mut pdf = vec![-1.0f32; n];
    m.pdf_batch(uv, view, light, &mut pdf);
    let (mut sampled, mut weight, mut sampled_pdf) =
        (vec![0.0f32; 3 * n], vec![0.0f32; 3 * n], vec![0.0f32; n]);
    m.sample_batch(
        uv,
        view,
        uniforms,
        DirectionsMut::from_planar(&mut sampled).unwrap(),
        RgbMut::from_planar(&mut weight).unwrap(),
        &mut sampled_pdf,
    );
    for i in 0..n {
        let (uv, view, light) = (uv.get(i), view.get(i), light.get(i));
        let f = m.eval_cos(uv, view, light);
        assert_eq!([rgb[i], rgb[n + i], rgb[2 * n + i]], f, "lane {i}");
        assert_eq!(pdf[i], m.pdf(uv, view, light), "lane {i}");
        let s = m.sample(uv, view, uniforms.get(i).to_array());
        assert_eq!(
            [sampled[i], sampled[n + i], sampled[2 * n + i]],
            s.light.to_array()
        );
        assert_eq!(sampled_pdf[i], s.pdf);
        let f = m.eval_cos(uv, view, s.light);
        let want = f.map(|c| crate::sampling::sample_weight(c, s.pdf));
        assert_eq!(
            [weight[i], weight[n + i], weight[2 * n + i]],
            want,
            "lane {i}"
        );
    }
}
