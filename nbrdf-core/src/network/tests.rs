//! The network's tests: the scalar and batched paths against an independent float64 reference,
//! the file format's round trip and error messages.

use super::kernel::{
    eval_input_generic, eval_task_generic, Packed, RgbSink, MAX_STACK_HIDDEN, TASK_LANES,
};
use super::*;
use crate::coords::network_input;
use crate::fastmath::Unfused;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Unit roundoff of float32.
const U32: f64 = 1.0 / (1u64 << 24) as f64;

/// Independent float64 reference: plain loops over the row-major file layout, std exp. Also
/// returns, per channel, a rigorous bound on the rounding error any float32 evaluation of
/// the same sums can make (`(n + 1) u` times the sum of absolute terms, propagated through
/// the layers and through exp): where an output is a cancellation of O(1) terms (a value of
/// 1e-6 from terms of size 1), no float32 kernel can reach 1e-5 relative accuracy.
fn reference_f64(net: &Nbrdf, x: [f32; 6]) -> Reference {
    let mut a: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
    let mut e = vec![0.0f64; a.len()];
    let mut out = Reference {
        value: [0.0; 3],
        rounding: [0.0; 3],
    };
    for (k, layer) in net.layers.iter().enumerate() {
        let (mut y, mut ey) = (vec![0.0f64; layer.outputs], vec![0.0f64; layer.outputs]);
        for o in 0..layer.outputs {
            let mut s = f64::from(layer.bias[o]);
            let mut magnitude = s.abs();
            let mut propagated = 0.0;
            for i in 0..layer.inputs {
                let w = f64::from(layer.weights[i * layer.outputs + o]);
                s += w * a[i];
                magnitude += (w * a[i]).abs();
                propagated += w.abs() * e[i];
            }
            let err = propagated + (layer.inputs + 1) as f64 * U32 * (magnitude + propagated);
            if k < 2 {
                (y[o], ey[o]) = (s.max(0.0), err);
            } else {
                out.value[o] = s.exp_m1().max(0.0);
                out.rounding[o] = s.min(80.0).exp() * err;
            }
        }
        (a, e) = (y, ey);
    }
    out
}

struct Reference {
    value: [f64; 3],
    rounding: [f64; 3],
}

impl Reference {
    fn scaled(self, factor: f64) -> Self {
        Reference {
            value: self.value.map(|v| v * factor),
            rounding: self.rounding.map(|v| v * factor),
        }
    }

    /// 1e-5 relative plus a 1e-7 floor plus the float32 rounding bound of the sums.
    fn tolerance(&self, c: usize) -> f64 {
        1e-5 * self.value[c].abs() + 1e-7 + self.rounding[c]
    }
}

/// Counts values that miss plain `1e-5 relative + 1e-7` (allowed only where the sums are
/// ill-conditioned, and then rarely).
#[derive(Default)]
struct Tally {
    checked: usize,
    beyond_plain: usize,
}

impl Tally {
    fn check(&mut self, got: f32, want: &Reference, c: usize, context: &dyn std::fmt::Display) {
        let (got, value) = (f64::from(got), want.value[c]);
        assert!(got.is_finite() && got >= 0.0, "{context}: {got}");
        assert!(
            (got - value).abs() <= want.tolerance(c),
            "{context}: channel {c}: {got} vs {value}"
        );
        self.checked += 1;
        self.beyond_plain += usize::from((got - value).abs() > 1e-5 * value.abs() + 1e-7);
    }

    fn assert_rare(&self) {
        assert!(
            self.beyond_plain * 200 <= self.checked,
            "{} of {} values miss 1e-5 relative",
            self.beyond_plain,
            self.checked
        );
    }
}

/// Reference `f_r cos` of a direction pair: float64 normalisation and cosine, network input
/// from the documented encoding (whose float32 accuracy `coords` tests).
fn reference_cos(net: &Nbrdf, v: Vec3, l: Vec3) -> Reference {
    let (l64, v64) = (l.as_dvec3(), v.as_dvec3());
    let (ln, vn) = (l64 / l64.length(), v64 / v64.length());
    if !(ln.z > 0.0 && vn.z > 0.0) {
        return Reference {
            value: [0.0; 3],
            rounding: [0.0; 3],
        };
    }
    reference_f64(net, network_input_for(net.anisotropic, v, l)).scaled(ln.z)
}

/// A network with weights like a trained one: fan-in scaled, biases non-zero, outputs from
/// ~1e-3 to ~10 so that exp and the clamp at 0 are both exercised.
fn test_net(hidden: usize, seed: u64) -> Nbrdf {
    let mut rng = SplitMix64::from_state(seed);
    let mut net = Nbrdf::random("test", hidden, seed);
    for layer in net.layers.iter_mut() {
        let scale = 1.5 / (layer.inputs as f32).sqrt();
        for w in layer.weights.iter_mut() {
            *w = (rng.next_f32() * 2.0 - 1.0) * scale;
        }
        for b in layer.bias.iter_mut() {
            *b = (rng.next_f32() * 2.0 - 1.0) * 0.5;
        }
    }
    net.layers[2].bias = vec![0.3, -0.2, 1.5];
    net
}

fn hemisphere(theta: f64, phi: f64) -> Vec3 {
    crate::coords::spherical_direction(theta, phi).as_vec3()
}

/// Random pairs over the whole hemisphere plus grazing, mirror and degenerate ones.
fn direction_pairs(count: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut rng = SplitMix64::from_state(seed);
    let mut pairs = Vec::new();
    for _ in 0..count {
        let dir =
            |rng: &mut SplitMix64| hemisphere(rng.next_f64().acos(), 2.0 * PI * rng.next_f64());
        let (l, v) = (dir(&mut rng), dir(&mut rng));
        pairs.push((l, v));
        // Grazing: 1e-6 .. 1e-2 above the horizon.
        let t = 0.5 * PI - 10f64.powf(-6.0 + 4.0 * rng.next_f64());
        pairs.push((hemisphere(t, 2.0 * PI * rng.next_f64()), v));
        pairs.push((l, hemisphere(t, 1.0)));
        pairs.push((l, Vec3::new(-l.x, -l.y, l.z))); // mirror: theta_h = 0
        pairs.push((l * 3.0, v * 0.25)); // not unit length
    }
    pairs.extend([
        (Vec3::Z, Vec3::Z),
        (Vec3::X, Vec3::Z),
        (Vec3::new(0.0, 0.0, -1.0), Vec3::Z),
        (Vec3::ZERO, Vec3::Z),
        (Vec3::new(f32::NAN, 0.0, 1.0), Vec3::Z),
        (Vec3::new(f32::INFINITY, 0.0, 1.0), Vec3::Z),
        (Vec3::Z, Vec3::new(0.0, f32::NEG_INFINITY, 1.0)),
    ]);
    pairs
}

fn eval_batch(net: &Nbrdf, pairs: &[(Vec3, Vec3)]) -> Vec<[f32; 3]> {
    let n = pairs.len();
    let mut view = vec![0.0f32; 3 * n];
    let mut light = vec![0.0f32; 3 * n];
    for (i, (l, v)) in pairs.iter().enumerate() {
        for k in 0..3 {
            light[k * n + i] = l[k];
            view[k * n + i] = v[k];
        }
    }
    let mut out = vec![0.0f32; 3 * n];
    net.eval_cos_batch(
        Directions::from_planar(&view).unwrap(),
        Directions::from_planar(&light).unwrap(),
        RgbMut::from_planar(&mut out).unwrap(),
    );
    (0..n)
        .map(|i| [out[i], out[n + i], out[2 * n + i]])
        .collect()
}

#[test]
fn eval_input_matches_f64_reference() {
    for hidden in [4, 21, 40, 100] {
        let net = test_net(hidden, 7 + hidden as u64);
        let mut tally = Tally::default();
        for (l, v) in direction_pairs(300, hidden as u64) {
            let x = network_input(v, l);
            if !x.iter().all(|c| c.is_finite()) {
                // Non-finite directions are rejected before the network (tested below).
                continue;
            }
            let got = net.eval_input(x);
            let want = reference_f64(&net, x);
            let context = format!("width {hidden} {x:?}");
            for (c, &g) in got.iter().enumerate() {
                tally.check(g, &want, c, &context);
            }
        }
        tally.assert_rare();
    }
}

#[test]
fn tabulation_holds_the_network_at_cell_centres_and_nothing_below_the_horizon() {
    let net = test_net(21, 11);
    let table = net.tabulate();
    let mut tally = Tally::default();
    let (mut valid, mut invalid) = (0, 0);
    for cell in (0..crate::merl::CELLS).step_by(997) {
        let (h, d, p) = crate::merl::cell_coordinates(cell);
        let angles = crate::merl::cell_centre_angles(h, d, p);
        let (v, l) = crate::coords::from_rusinkiewicz(&angles);
        match table.cell(cell) {
            None => {
                assert!(
                    l.z <= 0.0 || v.z <= 0.0,
                    "cell {cell} invalid above the horizon"
                );
                invalid += 1;
            }
            Some(rgb) => {
                assert!(
                    l.z > 0.0 && v.z > 0.0,
                    "cell {cell} valid below the horizon"
                );
                // The input written out from the angles (phi_h = 0), in float64.
                let (st, ct) = angles.theta_h.sin_cos();
                let (sd, cd) = angles.theta_d.sin_cos();
                let (sp, cp) = angles.phi_d.sin_cos();
                let x = [st, 0.0, ct, sd * cp, sd * sp, cd].map(|v| v as f32);
                let want = reference_f64(&net, x);
                for (c, &got) in rgb.iter().enumerate() {
                    // The table stores float64 of the float32 value: compare as float32.
                    tally.check(got as f32, &want, c, &format!("cell {cell}"));
                }
                valid += 1;
            }
        }
    }
    assert!(
        valid > 1000 && invalid > 100,
        "{valid} valid, {invalid} invalid"
    );
    tally.assert_rare();
}

#[test]
fn batched_eval_matches_f64_reference_and_eval_input() {
    let widths = [
        (4, false),
        (21, false),
        (40, false),
        (100, false),
        (21, true),
        (40, true),
    ];
    for (hidden, anisotropic) in widths {
        let mut net = test_net(hidden, 11 + hidden as u64);
        net.anisotropic = anisotropic;
        // More lanes than one rayon task so that the threaded split and the tail both run.
        let mut pairs = direction_pairs(1700, 3 * hidden as u64);
        pairs.truncate(TASK_LANES + LANES + 13);
        let got = eval_batch(&net, &pairs);
        let mut nonzero = 0;
        let (mut tally, mut tally_single) = (Tally::default(), Tally::default());
        for ((l, v), g) in pairs.iter().zip(&got) {
            let want = reference_cos(&net, *v, *l);
            // Same input vector: the scalar path must agree with the batched one.
            let single = net.eval_input(network_input_for(anisotropic, *v, *l));
            let cos = crate::brdf::cos_theta_light(*l);
            let context = format!("width {hidden} l={l} v={v}: {g:?} vs {:?}", want.value);
            for c in 0..3 {
                tally.check(g[c], &want, c, &context);
                tally_single.check(single[c] * cos, &want, c, &context);
                nonzero += usize::from(g[c] > 0.0);
            }
        }
        tally.assert_rare();
        tally_single.assert_rare();
        assert!(
            nonzero > pairs.len(),
            "the test network should mostly be non-zero"
        );
    }
}

/// On an AVX2 machine the public entry points take the FMA kernels; the portable ones (used
/// elsewhere) are checked here directly.
#[test]
fn portable_kernels_match_reference() {
    for (hidden, anisotropic) in [(4, false), (21, false), (100, false), (21, true)] {
        let mut net = test_net(hidden, 5 + hidden as u64);
        net.anisotropic = anisotropic;
        let packed = Packed::new(&net).unwrap();
        let mut pairs = direction_pairs(60, hidden as u64);
        pairs.push((Vec3::new(1e-25, 0.0, 2e-25), Vec3::new(3e20, 0.0, 1e25)));
        let n = pairs.len();
        let mut planar = vec![0.0f32; 6 * n];
        for (i, (l, v)) in pairs.iter().enumerate() {
            for k in 0..3 {
                planar[k * n + i] = l[k];
                planar[(3 + k) * n + i] = v[k];
            }
        }
        let (light, view) = planar.split_at(3 * n);
        let mut out = vec![0.0f32; 3 * n];
        let [r, g, b] = {
            let (r, rest) = out.split_at_mut(n);
            let (g, b) = rest.split_at_mut(n);
            [r, g, b]
        };
        eval_task_generic::<Unfused, _>(
            &packed,
            Directions::from_planar(view).unwrap(),
            Directions::from_planar(light).unwrap(),
            &mut RgbSink::new([&mut *r, &mut *g, &mut *b]),
        );
        let widest = hidden.max(1);
        let (mut h1, mut h2) = (vec![0.0; widest], vec![0.0; widest]);
        let mut tally = Tally::default();
        for (i, (l, v)) in pairs.iter().enumerate() {
            let context = format!("width {hidden} l={l} v={v}");
            if i + 1 == n {
                // Extreme lengths: rescaled, so compare with the normalising scalar eval.
                let want = net.eval(*v, *l).map(|f| f64::from(f) * 2.0 / 5f64.sqrt());
                let got = [r[i], g[i], b[i]].map(f64::from);
                assert!(
                    (0..3).all(|c| (got[c] - want[c]).abs() <= 1e-4 * want[c] + 1e-7),
                    "{context}"
                );
                continue;
            }
            let want = reference_cos(&net, *v, *l);
            for (c, got) in [r[i], g[i], b[i]].into_iter().enumerate() {
                tally.check(got, &want, c, &context);
            }
            let x = network_input_for(anisotropic, *v, *l);
            if x.iter().all(|c| c.is_finite()) {
                let mut single = [0.0f32; 3];
                eval_input_generic::<Unfused>(&net.layers, &x, &mut h1, &mut h2, &mut single);
                let want = reference_f64(&net, x);
                for (c, got) in single.into_iter().enumerate() {
                    tally.check(got, &want, c, &context);
                }
            }
        }
        tally.assert_rare();
    }
}

#[test]
fn horizon_and_bad_input_give_zero() {
    let net = test_net(21, 1);
    let cases = [
        (Vec3::new(1.0, 0.0, 0.0), Vec3::Z),
        (Vec3::new(0.3, 0.0, -0.1), Vec3::Z),
        (Vec3::Z, Vec3::new(0.5, 0.0, -1e-3)),
        (Vec3::ZERO, Vec3::Z),
        (Vec3::new(f32::NAN, 0.0, 1.0), Vec3::Z),
        (Vec3::Z, Vec3::new(0.0, 0.0, f32::INFINITY)),
    ];
    for (l, v) in cases {
        assert_eq!(net.eval(v, l), [0.0; 3], "{l} {v}");
    }
    for g in eval_batch(&net, &cases) {
        assert_eq!(g, [0.0; 3]);
    }
    // Huge weights cannot produce inf or NaN.
    let mut hot = net.clone();
    hot.layers[2].bias = vec![1e30, -1e30, 0.0];
    hot.layers[1].weights.iter_mut().for_each(|w| *w *= 1e20);
    for g in eval_batch(&hot, &direction_pairs(50, 5)) {
        assert!(g.iter().all(|c| c.is_finite() && *c >= 0.0), "{g:?}");
    }
}

#[test]
fn extreme_lengths_are_normalised_like_unit_vectors() {
    let net = test_net(21, 4);
    let (l, v) = (hemisphere(0.7, 0.3), hemisphere(0.4, 2.5));
    let want = net.eval(v, l).map(|f| f64::from(f) * f64::from(l.z));
    assert!(want.iter().any(|&f| f > 1e-3));
    let scales = [1e-25f32, 1e-18, 1e-3, 1.0, 7.0, 1e18, 1e25];
    let pairs: Vec<_> = scales
        .iter()
        .flat_map(|&a| scales.map(|b| (l * a, v * b)))
        .collect();
    for (pair, g) in pairs.iter().zip(eval_batch(&net, &pairs)) {
        let single = net
            .eval(pair.1, pair.0)
            .map(|f| f64::from(f) * f64::from(l.z));
        for c in 0..3 {
            let tol = 1e-4 * want[c] + 1e-7;
            assert!(
                (f64::from(g[c]) - want[c]).abs() <= tol,
                "{pair:?}: {g:?} vs {want:?}"
            );
            assert!(
                (single[c] - want[c]).abs() <= tol,
                "{pair:?}: {single:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn broken_shapes_evaluate_to_zero_without_panicking() {
    let mut net = test_net(21, 1);
    net.layers[1].weights.pop();
    assert_eq!(net.eval(Vec3::Z, Vec3::Z), [0.0; 3]);
    assert_eq!(eval_batch(&net, &[(Vec3::Z, Vec3::Z)]), vec![[0.0; 3]]);
    assert!(net.validate().is_err());
}

#[test]
fn flat_round_trip_and_parameter_count() {
    let net = Nbrdf::random("r", DEFAULT_HIDDEN, 42);
    assert_eq!(net.parameter_count(), 675);
    assert_eq!(parameter_count_for(21), 675);
    // Widths whose count overflows saturate, so a user-given width is an error, not an overflow.
    assert_eq!(parameter_count_for(1 << 40), usize::MAX);
    assert!(Nbrdf::from_flat("huge", 1 << 40, &[0.0; 675]).is_err());
    let flat = net.to_flat();
    assert_eq!(flat.len(), 675);
    assert!(flat.iter().all(|w| (-0.05..0.05).contains(w)));
    assert_eq!(&flat[..126], &net.layers[0].weights[..]);
    assert_eq!(&flat[126..147], &[0.0; 21]);
    let back = Nbrdf::from_flat("r", 21, &flat).unwrap();
    assert_eq!(back.layers, net.layers);
    assert_eq!(back.to_flat(), flat);
    assert!(Nbrdf::from_flat("r", 21, &flat[1..]).is_err());
    assert!(Nbrdf::from_flat("r", 0, &[]).is_err());
    let mut bad = flat.clone();
    bad[300] = f32::NAN;
    assert!(Nbrdf::from_flat("r", 21, &bad).is_err());
    for hidden in [1, 4, 40, 100] {
        let n = Nbrdf::random("r", hidden, 1);
        assert_eq!(n.parameter_count(), parameter_count_for(hidden));
        assert_eq!(
            Nbrdf::from_flat("r", hidden, &n.to_flat()).unwrap().layers,
            n.layers
        );
    }
    // Deterministic per seed, different across seeds.
    assert_eq!(Nbrdf::random("r", 21, 42).layers, net.layers);
    assert_ne!(Nbrdf::random("r", 21, 43).layers, net.layers);
}

fn temp_path(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "nbrdf-net-test-{}-{tag}.nbrdf.json",
        std::process::id()
    ))
}

#[test]
fn json_round_trip_is_exact() {
    let mut net = test_net(21, 3);
    // Values whose shortest decimal forms are long or extreme.
    net.layers[0].weights[0] = f32::MIN_POSITIVE;
    net.layers[0].weights[1] = 1.0e-45;
    net.layers[0].weights[2] = f32::MAX;
    net.layers[0].weights[3] = -0.1;
    net.layers[0].weights[4] = 16_777_217.0;
    net.sampling = Some(SamplingParams {
        model: "blinn-phong".into(),
        exponent: 210.0,
        specular_weight: 0.31,
        source: "fit".into(),
        second_lobe: None,
        exponent_v: None,
        relative_variance: None,
        default: None,
        table_cosine_weight: None,
    });
    net.provenance = serde_json::json!({"epochs": 12, "loss": 0.0123, "table": "gold.binary"});
    let path = temp_path("roundtrip");
    net.save(&path).unwrap();
    let back = Nbrdf::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(back, net);
    let text = net.to_json_string();
    assert!(text.contains("\"format\": \"nbrdf\"") && text.contains("\"version\": 1"));
    // Sampling and provenance are optional.
    let mut plain: serde_json::Value = serde_json::from_str(&text).unwrap();
    plain.as_object_mut().unwrap().remove("sampling");
    plain.as_object_mut().unwrap().remove("provenance");
    let back = Nbrdf::from_json_str(&plain.to_string(), Path::new("p")).unwrap();
    assert_eq!(back.sampling, None);
    assert_eq!(back.provenance, serde_json::json!({}));
    assert_eq!(back.layers, net.layers);
    assert_eq!(
        net.sampling_strategy(),
        Some(SamplingStrategy::Phong {
            exponent: 210.0,
            specular_weight: f64::from(0.31f32)
        })
    );
}

/// Isotropic networks stay version-1 files (no `anisotropic` key); anisotropic ones are version 2
/// and round-trip; a version-2 file without the key is isotropic.
#[test]
fn anisotropic_networks_are_version_2_and_isotropic_ones_version_1() {
    let iso = test_net(21, 4);
    let iso_text = iso.to_json_string();
    assert!(iso_text.contains("\"version\": 1") && !iso_text.contains("anisotropic"));
    let mut aniso = iso.clone();
    aniso.anisotropic = true;
    let text = aniso.to_json_string();
    assert!(text.contains("\"version\": 2") && text.contains("\"anisotropic\": true"));
    let back = Nbrdf::from_json_str(&text, Path::new("a")).unwrap();
    assert_eq!(back, aniso);
    let mut v2: serde_json::Value = serde_json::from_str(&iso_text).unwrap();
    v2["version"] = 2.into();
    let back = Nbrdf::from_json_str(&v2.to_string(), Path::new("b")).unwrap();
    assert_eq!(back, iso);
}

/// The anisotropic input is the half vector's full Cartesian form: rotating view and light
/// together about the normal changes an anisotropic network's value exactly as feeding it the
/// rotated half vector does, and leaves an isotropic network's value unchanged.
#[test]
fn rotation_about_the_normal_moves_only_anisotropic_networks() {
    let iso = test_net(21, 8);
    let mut aniso = iso.clone();
    aniso.anisotropic = true;
    let (v, l) = (hemisphere(0.5, 0.3), hemisphere(0.6, 2.9));
    let mut moved = 0.0f32;
    for k in 1..8 {
        let rot = glam::Quat::from_rotation_z(k as f32 * 0.7);
        let (rv, rl) = (rot * v, rot * l);
        let (a, b) = (iso.eval(v, l), iso.eval(rv, rl));
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 1e-4 * a[c].abs() + 1e-6,
                "{a:?} {b:?}"
            );
        }
        // Closed form of the rotated input: half vector rotated, difference vector unchanged.
        let hd = crate::coords::half_diff(v.as_dvec3(), l.as_dvec3());
        let (s, c) = (f64::from(k as f32 * 0.7)).sin_cos();
        let h = hd.half;
        let x = [
            c * h.x - s * h.y,
            s * h.x + c * h.y,
            h.z,
            hd.diff.x,
            hd.diff.y,
            hd.diff.z,
        ]
        .map(|t| t as f32);
        let want = reference_f64(&aniso, x).value;
        let got = aniso.eval(rv, rl);
        for ch in 0..3 {
            assert!(
                (f64::from(got[ch]) - want[ch]).abs() <= 1e-3 * want[ch] + 1e-5,
                "{k}: {got:?} vs {want:?}"
            );
        }
        let base = aniso.eval(v, l);
        moved = moved.max((got[0] - base[0]).abs() / base[0].max(1e-6));
    }
    assert!(
        moved > 0.05,
        "the anisotropic network hardly depends on phi_h: {moved}"
    );
}

#[test]
fn malformed_files_are_rejected_with_the_file_name() {
    let good: serde_json::Value = serde_json::from_str(&{
        let mut n = test_net(4, 1);
        n.sampling = Some(SamplingParams {
            model: "blinn-phong".into(),
            exponent: 10.0,
            specular_weight: 0.5,
            source: "manual".into(),
            second_lobe: None,
            exponent_v: None,
            relative_variance: None,
            default: None,
            table_cosine_weight: None,
        });
        n.to_json_string()
    })
    .unwrap();
    type Edit = fn(&mut serde_json::Value);
    let cases: Vec<(&str, Edit)> = vec![
        ("format is \"keras\"", |v| v["format"] = "keras".into()),
        ("missing field \"format\"", |v| {
            v.as_object_mut().unwrap().remove("format");
        }),
        ("unsupported version 4", |v| v["version"] = 4.into()),
        ("needs format version 2", |v| v["anisotropic"] = true.into()),
        ("invalid type: string \"yes\", expected a boolean", |v| {
            v["version"] = 2.into();
            v["anisotropic"] = "yes".into();
        }),
        ("unsupported version \"1\"", |v| v["version"] = "1".into()),
        ("expected 3 layers, found 2", |v| {
            v["layers"].as_array_mut().unwrap().pop();
        }),
        ("layer 1 has 5 inputs", |v| {
            v["layers"][0]["inputs"] = 5.into()
        }),
        ("layer 3 has 4 outputs", |v| {
            v["layers"][2]["outputs"] = 4.into()
        }),
        ("do not chain", |v| v["layers"][1]["inputs"] = 5.into()),
        ("layer 2 has 15 weights", |v| {
            v["layers"][1]["weights"].as_array_mut().unwrap().pop();
        }),
        ("layer 3 has 2 bias values", |v| {
            v["layers"][2]["bias"].as_array_mut().unwrap().pop();
        }),
        ("layer 1 weight 3 is not finite", |v| {
            v["layers"][0]["weights"][3] = serde_json::json!(1e39)
        }),
        ("layer 2 bias 1 is not finite", |v| {
            v["layers"][1]["bias"][1] = serde_json::json!(-1e300)
        }),
        ("invalid type", |v| {
            v["layers"][0]["weights"][0] = "x".into()
        }),
        ("missing field `name`", |v| {
            v.as_object_mut().unwrap().remove("name");
        }),
        ("exponent -1 must be", |v| {
            v["sampling"]["exponent"] = (-1.0).into()
        }),
        ("exponent inf must be", |v| {
            v["sampling"]["exponent"] = serde_json::json!(1e40)
        }),
        ("specular_weight 1.5", |v| {
            v["sampling"]["specular_weight"] = 1.5.into()
        }),
        ("unknown sampling model 'ggx'", |v| {
            v["sampling"]["model"] = "ggx".into()
        }),
        ("two-lobe weights 0.5 + 0.75", |v| {
            v["sampling"]["second_lobe"] =
                serde_json::json!({"exponent": 5.0, "specular_weight": 0.75})
        }),
        ("two-lobe exponent2 2000000", |v| {
            v["sampling"]["second_lobe"] =
                serde_json::json!({"exponent": 2e6, "specular_weight": 0.1})
        }),
        ("top level is not a JSON object", |v| {
            *v = serde_json::json!([1, 2])
        }),
    ];
    let origin = Path::new("materials/broken.nbrdf.json");
    for (needle, edit) in cases {
        let mut v = good.clone();
        edit(&mut v);
        let err = Nbrdf::from_json_str(&v.to_string(), origin).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(&err, NbrdfError::Format { path, .. } if path == origin),
            "{needle}: {err:?}"
        );
        assert!(text.starts_with("materials/broken.nbrdf.json: "), "{text}");
        assert!(text.contains(needle), "expected '{needle}' in: {text}");
    }
    // Truncated and non-JSON text, through a real file.
    let text = serde_json::to_string(&good).unwrap();
    let path = temp_path("truncated");
    for body in [&text[..text.len() / 2], "not json at all", ""] {
        std::fs::write(&path, body).unwrap();
        let err = Nbrdf::load(&path).unwrap_err().to_string();
        assert!(
            err.contains(&*path.to_string_lossy()) && err.contains("not valid JSON"),
            "{err}"
        );
    }
    std::fs::remove_file(&path).ok();
    let missing = temp_path("missing");
    let err = Nbrdf::load(&missing).unwrap_err();
    assert!(matches!(err, NbrdfError::Io { .. }) && err.to_string().contains("missing"));
    // The unmodified file loads.
    assert!(Nbrdf::from_json_str(&text, origin).is_ok());
}

#[test]
fn wide_and_narrow_networks_use_the_right_scratch() {
    // Width above the stack limit, and unequal hidden widths (allowed by the format).
    let net = test_net(MAX_STACK_HIDDEN + 1, 9);
    let pairs = direction_pairs(20, 1);
    for ((l, v), g) in pairs.iter().zip(eval_batch(&net, &pairs)) {
        let want = reference_cos(&net, *v, *l);
        (0..3).for_each(|c| Tally::default().check(g[c], &want, c, &"wide"));
    }
    let mut uneven = test_net(5, 2);
    let other = test_net(8, 3);
    uneven.layers[1] = Layer {
        inputs: 5,
        outputs: 8,
        weights: other.layers[1].weights[..40].to_vec(),
        bias: other.layers[1].bias.clone(),
    };
    uneven.layers[2] = other.layers[2].clone();
    uneven.validate().unwrap();
    for ((l, v), g) in pairs.iter().zip(eval_batch(&uneven, &pairs)) {
        let want = reference_cos(&uneven, *v, *l);
        (0..3).for_each(|c| Tally::default().check(g[c], &want, c, &"uneven"));
    }
}

#[test]
fn two_lobe_sampling_round_trips_and_one_lobe_files_are_unchanged() {
    let mut net = test_net(4, 2);
    let one = SamplingParams {
        model: "blinn-phong".into(),
        exponent: 900.0,
        specular_weight: 0.5,
        source: "fit".into(),
        second_lobe: None,
        exponent_v: None,
        relative_variance: None,
        default: None,
        table_cosine_weight: None,
    };
    net.sampling = Some(one.clone());
    // A one-lobe file writes no new fields and samples with the one-lobe mixture.
    let text = net.to_json_string();
    assert!(!text.contains("second_lobe") && !text.contains("relative_variance"));
    assert_eq!(
        net.sampling_strategy(),
        Some(SamplingStrategy::Phong {
            exponent: 900.0,
            specular_weight: 0.5
        })
    );
    net.sampling = Some(SamplingParams {
        second_lobe: Some(super::SecondLobe {
            exponent: 40.0,
            specular_weight: 0.3,
        }),
        relative_variance: Some(super::SamplingVariances {
            one_lobe: 2.5,
            two_lobe: Some(1.25),
            anisotropic: None,
            cosine: 40.0,
            tabulated: None,
        }),
        ..one
    });
    let back = Nbrdf::from_json_str(&net.to_json_string(), Path::new("t")).unwrap();
    assert_eq!(back, net);
    assert_eq!(
        back.sampling_strategy(),
        Some(SamplingStrategy::TwoLobe {
            exponent1: 900.0,
            weight1: 0.5,
            exponent2: 40.0,
            weight2: f64::from(0.3f32),
        })
    );
}

#[test]
fn table_cosine_weight_round_trips_and_is_checked_on_load() {
    let mut net = test_net(4, 3);
    let lobe = SamplingParams {
        model: "blinn-phong".into(),
        exponent: 40.0,
        specular_weight: 0.5,
        source: "fit".into(),
        second_lobe: None,
        exponent_v: None,
        relative_variance: None,
        default: Some(SamplingKind::Tabulated),
        table_cosine_weight: Some(0.02),
    };
    net.sampling = Some(lobe.clone());
    let back = Nbrdf::from_json_str(&net.to_json_string(), Path::new("t")).unwrap();
    assert_eq!(back, net);
    let config = back.table_config();
    assert_eq!(config.cosine_weight, f64::from(0.02f32));
    for bad in [0.0, -0.1, 1.0, 3.0] {
        net.sampling = Some(SamplingParams {
            table_cosine_weight: Some(bad),
            ..lobe.clone()
        });
        let err = Nbrdf::from_json_str(&net.to_json_string(), Path::new("t")).unwrap_err();
        assert!(err.to_string().contains("table_cosine_weight"), "{err}");
    }
    // Without it (older files) the table mixes the default 0.1.
    net.sampling = Some(SamplingParams {
        table_cosine_weight: None,
        ..lobe
    });
    let config = net.table_config();
    assert_eq!(config.cosine_weight, 0.1);
}

#[test]
fn anisotropic_sampling_lobe_round_trips_and_is_checked_on_load() {
    let mut net = test_net(4, 3);
    net.anisotropic = true;
    let lobe = SamplingParams {
        model: "blinn-phong".into(),
        exponent: 400.0,
        specular_weight: 0.6,
        source: "fit".into(),
        second_lobe: None,
        exponent_v: Some(25.0),
        relative_variance: None,
        default: None,
        table_cosine_weight: None,
    };
    net.sampling = Some(lobe.clone());
    let back = Nbrdf::from_json_str(&net.to_json_string(), Path::new("t")).unwrap();
    assert_eq!(back, net);
    assert_eq!(
        back.sampling_strategy(),
        Some(SamplingStrategy::anisotropic(
            400.0,
            25.0,
            f64::from(0.6f32)
        ))
    );
    let refused = |n: &Nbrdf, want: &str| {
        let err = Nbrdf::from_json_str(&n.to_json_string(), Path::new("t")).unwrap_err();
        assert!(err.to_string().contains(want), "{err}");
        assert!(n.validate().is_err());
    };
    for bad in [-1.0, f32::NAN, f32::INFINITY, 2e6] {
        net.sampling = Some(SamplingParams {
            exponent_v: Some(bad),
            ..lobe.clone()
        });
        if bad.is_finite() {
            refused(&net, "exponent_v");
        } else {
            // JSON has no NaN or infinity: the in-memory check refuses them.
            assert!(net.validate().is_err());
        }
    }
    net.sampling = Some(SamplingParams {
        second_lobe: Some(super::SecondLobe {
            exponent: 40.0,
            specular_weight: 0.3,
        }),
        ..lobe.clone()
    });
    refused(&net, "do not combine");
    net.sampling = Some(lobe);
    net.anisotropic = false;
    refused(&net, "needs an anisotropic network");
}

/// `test_net` with planted units in the first hidden layer: 0 never fires (bias -10), 1 fires
/// only within 0.1 degree of `theta_d = 0` (a sliver random directions almost never reach),
/// 2 fires only where `sin theta_h + sin theta_d cos phi_d > 1.7`, which needs a direction
/// below the horizon (the largest value above it is sqrt 2); unit 0 of the second hidden layer
/// never fires (bias -100, far below any sum of its inputs).
fn planted_net(seed: u64) -> Nbrdf {
    let mut net = test_net(DEFAULT_HIDDEN, seed);
    let outputs = net.layers[0].outputs;
    let mut plant = |unit: usize, weights: [f32; INPUTS], bias: f32| {
        for (i, w) in weights.into_iter().enumerate() {
            net.layers[0].weights[i * outputs + unit] = w;
        }
        net.layers[0].bias[unit] = bias;
    };
    plant(0, [0.1; INPUTS], -10.0);
    plant(1, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0], -0.999_998_5);
    plant(2, [1.0, 0.0, 0.0, 1.0, 0.0, 0.0], -1.7);
    net.layers[1].bias[0] = -100.0;
    net
}

/// Float64 pre-activations of both hidden layers for a direction pair, independent of the
/// pruning module's own (from the network input of `coords`).
fn hidden_pre_activations(net: &Nbrdf, v: Vec3, l: Vec3) -> [Vec<f64>; 2] {
    let x = network_input_for(net.anisotropic, v, l);
    let affine = |layer: &Layer, x: &[f64]| -> Vec<f64> {
        (0..layer.outputs)
            .map(|o| {
                (0..layer.inputs).fold(f64::from(layer.bias[o]), |s, i| {
                    s + f64::from(layer.weights[i * layer.outputs + o]) * x[i]
                })
            })
            .collect()
    };
    let x: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
    let first = affine(&net.layers[0], &x);
    let relu: Vec<f64> = first.iter().map(|&z| z.max(0.0)).collect();
    let second = affine(&net.layers[1], &relu);
    [first, second]
}

/// Direction pairs for the pruning tests: `direction_pairs`, the sliver (view = light, so
/// `theta_d = 0`, at every elevation) and pairs on the edge of the horizon.
fn pruning_pairs(seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut pairs = direction_pairs(4000, seed);
    let mut rng = SplitMix64::from_state(seed ^ 0x5eed);
    for k in 0..400 {
        let theta = 0.5 * PI * f64::from(k) / 400.0;
        let v = hemisphere(theta, 2.0 * PI * rng.next_f64());
        pairs.push((v, v));
        let grazing = 0.5 * PI - 1e-5 * rng.next_f64();
        let l = hemisphere(grazing, 2.0 * PI * rng.next_f64());
        pairs.push((l, hemisphere(grazing, 2.0 * PI * rng.next_f64())));
    }
    pairs
}

#[test]
fn pruning_keeps_slivers_and_drops_units_dead_above_the_horizon() {
    for seed in [3, 17] {
        let net = planted_net(seed);
        let active = net.active_units();
        assert!(
            !active.hidden1[0],
            "seed {seed}: a unit with bias -10 never fires"
        );
        assert!(
            active.hidden1[1],
            "seed {seed}: the sliver at theta_d = 0 fires"
        );
        assert!(
            !active.hidden1[2],
            "seed {seed}: fires only below the horizon"
        );
        assert!(
            !active.hidden2[0],
            "seed {seed}: a unit with bias -100 never fires"
        );
        // The sliver is real: pairs with view = light switch it on.
        let v = hemisphere(0.3, 1.0);
        assert!(hidden_pre_activations(&net, v, v)[0][1] > 0.0);
        // Every unit called inactive is at or below 0 on every pair above the horizon.
        for (l, v) in pruning_pairs(seed) {
            let (vn, ln) = (v.normalize_or_zero(), l.normalize_or_zero());
            if !(vn.z > 0.0 && ln.z > 0.0 && v.is_finite() && l.is_finite()) {
                continue;
            }
            let z = hidden_pre_activations(&net, v, l);
            for (layer, flags) in [&active.hidden1, &active.hidden2].into_iter().enumerate() {
                for (unit, &flag) in flags.iter().enumerate() {
                    assert!(
                        flag || z[layer][unit] <= 0.0,
                        "seed {seed}: layer {} unit {unit} called inactive is {} at {v} {l}",
                        layer + 1,
                        z[layer][unit]
                    );
                }
            }
        }
    }
}

/// Interval bounds prove nothing with a parameter that is not finite (the loaders refuse such
/// networks; `active_units` takes any layers): every unit stays.
#[test]
fn pruning_keeps_every_unit_of_layers_with_non_finite_parameters() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for (layer, index) in [(0, 5), (1, 0), (2, 1)] {
            let mut net = planted_net(3);
            net.layers[layer].weights[index] = bad;
            let active = crate::network::active_units(&net.layers, false);
            assert!(
                active.hidden1.iter().chain(&active.hidden2).all(|&a| a),
                "{bad} in layer {layer}"
            );
        }
    }
}

/// A second-layer unit whose exact sum is negative everywhere but whose float32 sum overflows:
/// its first term, 3.45e5 times a first-layer unit `1e38 (cos theta_d - 0.99999)`, passes
/// float32's largest value within 0.03 degrees of `theta_d = 0` (closer than any centre of the
/// proof's boxes) before six constant units of 3e38 subtract 1.8e39, so the renderer's sum is
/// `+inf` there. The interval proof alone drops it (its bound is below 0 from the first box
/// on); the overflow guard keeps every unit, so pruned and full networks still agree.
#[test]
fn pruning_keeps_every_unit_where_float32_sums_may_overflow() {
    let mut net = planted_net(3);
    let h1 = net.layers[0].outputs;
    let mut plant = |unit: usize, x5: f32, bias: f32| {
        for i in 0..INPUTS {
            net.layers[0].weights[i * h1 + unit] = if i == 5 { x5 } else { 0.0 };
        }
        net.layers[0].bias[unit] = bias;
    };
    plant(1, 1e38, -0.999_99e38);
    let constants = 3..=8;
    for unit in constants.clone() {
        plant(unit, 0.0, 3e38);
    }
    let h2 = net.layers[1].outputs;
    let overflowing = 1;
    for i in 0..h1 {
        for o in 0..h2 {
            let w = &mut net.layers[1].weights[i * h2 + o];
            let large = i == 1 || constants.contains(&i);
            *w = match (i, o == overflowing) {
                (1, true) => 3.45e5,
                (_, true) if large => -1.0,
                // The large units feed nothing else (those sums would overflow too).
                (_, false) if large => 0.0,
                (_, true) => 0.0,
                _ => *w,
            };
        }
    }
    net.layers[1].bias[overflowing] = 0.0;
    let v = hemisphere(0.4, 0.7);
    assert!(
        hidden_pre_activations(&net, v, v)[1][overflowing] < -1e39,
        "exactly, the unit is far below 0"
    );
    let pruned = net.without_inactive_units();
    for (l, v) in pruning_pairs(7) {
        let (full, fewer) = (net.eval(v, l), pruned.eval(v, l));
        assert!(
            full.iter()
                .zip(&fewer)
                .all(|(a, b)| a == b || (a.is_nan() && b.is_nan())),
            "pruned {fewer:?}, full {full:?} at {v} {l}"
        );
    }
    let active = net.active_units();
    assert!(
        active.hidden1.iter().chain(&active.hidden2).all(|&a| a),
        "nothing is proved where float32 sums may overflow: {active:?}"
    );
}

#[test]
fn pruned_networks_evaluate_exactly_like_the_full_ones() {
    let anisotropic = |seed| {
        let mut net = planted_net(seed);
        net.anisotropic = true;
        net
    };
    let mut all_dead = test_net(DEFAULT_HIDDEN, 5);
    all_dead.layers[0].bias = vec![-50.0; DEFAULT_HIDDEN];
    let trained = ["roughconductor-on", "roughconductor-off"].map(|name| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../docs/results/anisotropic/work")
            .join(format!("{name}.nbrdf.json"));
        Nbrdf::load(&path).expect("the anisotropic report's networks are in the repository")
    });
    let nets = [planted_net(3), planted_net(17), anisotropic(23), all_dead]
        .into_iter()
        .chain(trained);
    let mut dropped = 0;
    for (k, net) in nets.enumerate() {
        let pruned = net.without_inactive_units();
        assert!(pruned.validate().is_ok());
        let widths = [pruned.layers[0].outputs, pruned.layers[1].outputs];
        assert_eq!(
            widths,
            net.active_units()
                .hidden1
                .iter()
                .zip(&net.active_units().hidden2)
                .fold([0, 0], |[a, b], (&x, &y)| [
                    a + usize::from(x),
                    b + usize::from(y)
                ]),
            "network {k}"
        );
        assert!(
            widths[0] >= 1 && widths[1] >= 1,
            "network {k}: a layer keeps a width"
        );
        dropped += 2 * DEFAULT_HIDDEN - widths[0] - widths[1];
        let pairs = pruning_pairs(100 + k as u64);
        let (full, fewer) = (eval_batch(&net, &pairs), eval_batch(&pruned, &pairs));
        for ((got, want), (l, v)) in fewer.iter().zip(&full).zip(&pairs) {
            assert_eq!(
                got, want,
                "network {k}: pruned {got:?}, full {want:?} at {v} {l}"
            );
            assert_eq!(
                pruned.eval(*v, *l),
                net.eval(*v, *l),
                "network {k} at {v} {l}"
            );
        }
    }
    assert!(
        dropped >= 4 * 4,
        "the planted units and the trained networks' dead ones: {dropped}"
    );
}

#[test]
fn wide_networks_prove_within_a_work_budget() {
    use super::pruning::box_budget;
    // The paper's width keeps the full box budget; wider networks get fewer boxes, so that
    // their proofs stay within the work budget instead of taking minutes.
    assert_eq!(box_budget([21, 21]), 200_000);
    let cost = |h: usize| 6 * h + h * h + 3 * h;
    for h in [96, 512, 4096] {
        let boxes = box_budget([h, h]);
        assert!(
            boxes < 200_000 && boxes * cost(h) <= 200_000_000,
            "{h}: {boxes}"
        );
    }
    assert_eq!(box_budget([usize::MAX, usize::MAX]), 1);
    // A wide network's proof still only drops units that change no value.
    let net = test_net(160, 3);
    let pruned = net.without_inactive_units();
    let [d1, _] = net.active_units().inactive_counts();
    assert!(
        d1 > 0,
        "a random 160-wide network has dead first-layer units"
    );
    let pairs = pruning_pairs(5);
    let (full, fewer) = (eval_batch(&net, &pairs), eval_batch(&pruned, &pairs));
    for ((got, want), (l, v)) in fewer.iter().zip(&full).zip(&pairs) {
        assert_eq!(got, want, "pruned {got:?}, full {want:?} at {v} {l}");
    }
}

/// `sampling.default` as a file spells it: canonical names and the old spellings load as the
/// canonical kind and are written back canonical; an unknown name and a default without the
/// parameters it samples with are refused.
#[test]
fn sampling_default_loads_old_spellings_as_the_canonical_kind() {
    let mut net = test_net(4, 3);
    net.sampling = Some(SamplingParams {
        model: "blinn-phong".into(),
        exponent: 40.0,
        specular_weight: 0.5,
        source: "fit".into(),
        second_lobe: Some(SecondLobe {
            exponent: 4.0,
            specular_weight: 0.2,
        }),
        exponent_v: None,
        relative_variance: None,
        default: None,
        table_cosine_weight: None,
    });
    let with_default = |name: &str| {
        let mut doc: serde_json::Value = serde_json::from_str(&net.to_json_string()).unwrap();
        doc["sampling"]["default"] = serde_json::Value::String(name.into());
        Nbrdf::from_json_str(&doc.to_string(), Path::new("t"))
    };
    let cases = [
        ("tabulated", "tabulated"),
        ("two_lobe", "two_lobe"),
        ("two-lobe", "two_lobe"),
        ("blinn_phong", "phong"),
        ("phong-fit", "phong"),
        ("Cosine", "cosine"),
    ];
    for (spelling, canonical) in cases {
        let loaded = with_default(spelling).unwrap();
        let written: serde_json::Value = serde_json::from_str(&loaded.to_json_string()).unwrap();
        assert_eq!(written["sampling"]["default"], canonical, "{spelling}");
    }
    let err = with_default("ggx").unwrap_err().to_string();
    assert!(err.contains("unknown sampling default 'ggx'"), "{err}");
    let err = with_default("anisotropic-phong").unwrap_err().to_string();
    assert!(err.contains("needs an exponent_v"), "{err}");
}

#[test]
fn analytic_base_round_trips_and_is_checked_on_load() {
    let mut net = test_net(4, 3);
    let base = serde_json::json!({"type": "roughconductor", "alpha": 0.12,
        "specular_reflectance": {"type": "rgb", "value": [0.9, 0.8, 0.5]}});
    net.base = Some(base.clone());
    let text = net.to_json_string();
    let back = Nbrdf::from_json_str(&text, Path::new("t")).unwrap();
    assert_eq!(back.base, Some(base));
    assert_eq!(back, net);
    // Kept through a rewrite (what fit-phong does) and absent from files without one.
    assert!(back.to_json_string().contains("\"roughconductor\""));
    net.base = None;
    assert!(!net.to_json_string().contains("\"base\""));
    for (bad, needle) in [
        (
            serde_json::json!("roughconductor"),
            "must be a BSDF dictionary",
        ),
        (serde_json::json!({"alpha": 0.1}), "string \"type\""),
        (serde_json::json!({"type": 3}), "string \"type\""),
        (serde_json::json!({"type": ""}), "string \"type\""),
    ] {
        net.base = Some(bad);
        let err = Nbrdf::from_json_str(&net.to_json_string(), Path::new("t")).unwrap_err();
        assert!(err.to_string().contains(needle), "{err}");
        assert!(net.validate().is_err());
    }
}
