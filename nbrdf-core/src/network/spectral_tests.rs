//! Spectral networks against independent float64 oracles: the forward pass and the B-spline
//! written afresh (Cox-de Boor's recursion on the knot vector, not de Boor's triangle).

use super::*;
use crate::brdf::Brdf;
use crate::coords::network_input_for;
use crate::rng::SplitMix64;
use crate::spectral_basis::SpectralBasis;
use glam::Vec3;
use std::path::Path;

const COUNT: usize = 16;

/// A spectral network with weights like a trained one (outputs from ~1e-2 to ~10).
pub(crate) fn spectral_net(hidden: usize, seed: u64) -> Nbrdf {
    let mut rng = SplitMix64::from_state(seed);
    let mut net = Nbrdf::random("spectral", hidden, seed);
    net.layers[2] = crate::network::Layer {
        inputs: hidden,
        outputs: COUNT,
        weights: vec![0.0; hidden * COUNT],
        bias: vec![0.0; COUNT],
    };
    for layer in net.layers.iter_mut() {
        let scale = 1.5 / (layer.inputs as f32).sqrt();
        layer
            .weights
            .iter_mut()
            .for_each(|w| *w = (rng.next_f32() * 2.0 - 1.0) * scale);
        layer
            .bias
            .iter_mut()
            .for_each(|b| *b = (rng.next_f32() * 2.0 - 1.0) * 0.5);
    }
    net.spectral = Some(Spectral::new(SpectralBasis::default()).unwrap());
    net.validate().unwrap();
    net
}

/// The network's outputs in float64.
fn coefficients_f64(net: &Nbrdf, x: [f32; 6]) -> Vec<f64> {
    let mut a: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
    for (k, layer) in net.layers.iter().enumerate() {
        let y: Vec<f64> = (0..layer.outputs)
            .map(|o| {
                let s = f64::from(layer.bias[o])
                    + (0..layer.inputs)
                        .map(|i| f64::from(layer.weights[i * layer.outputs + o]) * a[i])
                        .sum::<f64>();
                if k < 2 {
                    s.max(0.0)
                } else {
                    s.exp_m1().max(0.0)
                }
            })
            .collect();
        a = y;
    }
    a
}

/// `B_k(l)` by the Cox-de Boor recursion on the clamped knot vector (right end inclusive).
fn bspline(k: usize, degree: usize, knots: &[f64], l: f64) -> f64 {
    if degree == 0 {
        let last = knots[knots.len() - 1];
        let (a, b) = (knots[k], knots[k + 1]);
        return f64::from(u8::from(
            (a <= l && l < b) || (l == last && b == last && a < b),
        ));
    }
    let term = |num: f64, den: f64, v: f64| if den > 0.0 { num / den * v } else { 0.0 };
    term(
        l - knots[k],
        knots[k + degree] - knots[k],
        bspline(k, degree - 1, knots, l),
    ) + term(
        knots[k + degree + 1] - l,
        knots[k + degree + 1] - knots[k + 1],
        bspline(k + 1, degree - 1, knots, l),
    )
}

fn knots() -> Vec<f64> {
    let inner = (0..=13).map(|i| 360.0 + 470.0 * f64::from(i) / 13.0);
    [360.0; 3]
        .into_iter()
        .chain(inner)
        .chain([830.0; 3])
        .collect()
}

fn spectrum_f64(c: &[f64], l: f64) -> f64 {
    if !(360.0..=830.0).contains(&l) {
        return 0.0;
    }
    let knots = knots();
    (0..COUNT).map(|k| c[k] * bspline(k, 3, &knots, l)).sum()
}

fn random_pairs(n: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = SplitMix64::from_state(seed);
    let mut planar = |below: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; 3 * n];
        for i in 0..n {
            let (theta, phi) = (rng.next_f64() * 1.5, rng.next_f64() * std::f64::consts::TAU);
            let d = crate::coords::spherical_direction(theta, phi);
            let z = if below && i % 7 == 3 { -d.z } else { d.z };
            for (k, c) in [d.x, d.y, z].into_iter().enumerate() {
                out[k * n + i] = c as f32;
            }
        }
        out
    };
    (planar(false), planar(true))
}

fn direction(planar: &[f32], n: usize, i: usize) -> Vec3 {
    Vec3::new(planar[i], planar[n + i], planar[2 * n + i])
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 2e-4 * want.abs() + 1e-6
}

#[test]
fn spectral_values_match_a_float64_oracle() {
    let net = spectral_net(21, 5);
    let n = 200;
    let (view, light) = random_pairs(n, 6);
    let m = 3;
    let mut rng = SplitMix64::from_state(7);
    let mut wavelengths: Vec<f32> = (0..m * n).map(|_| 340.0 + 510.0 * rng.next_f32()).collect();
    // Knots and ends exactly, and wavelengths that must give 0.
    wavelengths[..6].copy_from_slice(&[
        360.0,
        830.0,
        360.0 + 470.0 / 13.0,
        f32::NAN,
        f32::INFINITY,
        -1.0,
    ]);
    let mut out = vec![-1.0f32; m * n];
    let (v, l) = (
        crate::brdf::Directions::from_planar(&view).unwrap(),
        crate::brdf::Directions::from_planar(&light).unwrap(),
    );
    net.eval_spectral_cos_batch(v, l, &wavelengths, &mut out)
        .unwrap();
    for i in 0..n {
        let (vi, li) = (direction(&view, n, i), direction(&light, n, i));
        let cos = if li.z > 0.0 && vi.z > 0.0 {
            f64::from(li.normalize().z)
        } else {
            0.0
        };
        let c = coefficients_f64(&net, network_input_for(false, vi, li));
        for j in 0..m {
            let lambda = f64::from(wavelengths[j * n + i]);
            let want = if lambda.is_finite() {
                spectrum_f64(&c, lambda) * cos
            } else {
                0.0
            };
            let got = f64::from(out[j * n + i]);
            assert!(
                close(got, want),
                "pair {i} lambda {lambda}: {got} vs {want}"
            );
        }
    }
    assert!(out[3..6].iter().all(|v| *v == 0.0));
}

/// The RGB value of a spectral network is `M c`, in the batched and the single path.
#[test]
fn rgb_value_is_the_srgb_matrix_times_the_coefficients() {
    let net = spectral_net(12, 8);
    let matrix = net.spectral.as_ref().unwrap().srgb_matrix();
    let n = 150;
    let (view, light) = random_pairs(n, 9);
    let mut rgb = vec![0.0f32; 3 * n];
    net.eval_cos_batch(
        crate::brdf::Directions::from_planar(&view).unwrap(),
        crate::brdf::Directions::from_planar(&light).unwrap(),
        crate::brdf::RgbMut::from_planar(&mut rgb).unwrap(),
    );
    for i in 0..n {
        let (vi, li) = (direction(&view, n, i), direction(&light, n, i));
        let above = li.z > 0.0 && vi.z > 0.0;
        let cos = if above {
            f64::from(li.normalize().z)
        } else {
            0.0
        };
        let c = coefficients_f64(&net, network_input_for(false, vi, li));
        let single = net.eval(vi, li);
        for ch in 0..3 {
            let want: f64 = (0..COUNT).map(|k| matrix[ch * COUNT + k] * c[k]).sum();
            let got = f64::from(rgb[ch * n + i]);
            assert!(
                close(got, want * cos),
                "pair {i} channel {ch}: {got} vs {}",
                want * cos
            );
            if above {
                assert!(close(f64::from(single[ch]), want), "single {i} {ch}");
            }
        }
    }
}

#[test]
fn rgb_networks_are_refused_by_the_spectral_evaluation() {
    let net = Nbrdf::random("rgb", 8, 1);
    let d = [0.0f32, 0.0, 1.0];
    let dirs = crate::brdf::Directions::from_planar(&d).unwrap();
    let err = net
        .eval_spectral_cos_batch(dirs, dirs, &[500.0], &mut [0.0])
        .unwrap_err();
    assert!(err.to_string().contains("RGB network"), "{err}");
    let spectral = spectral_net(8, 2);
    let err = spectral
        .eval_spectral_cos_batch(dirs, dirs, &[500.0, 600.0], &mut [0.0])
        .unwrap_err();
    assert!(err.to_string().contains("m n"), "{err}");
}

#[test]
fn version_3_round_trips_and_older_versions_stay() {
    let net = spectral_net(10, 3);
    let text = net.to_json_string();
    let root: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(root["version"], 3);
    assert_eq!(root["spectral"]["basis"], "cubic_bspline");
    assert_eq!(root["spectral"]["count"], 16);
    assert_eq!(root["layers"][2]["outputs"], 16);
    let back = Nbrdf::from_json_str(&text, Path::new("x.nbrdf.json")).unwrap();
    assert_eq!(back, net);
    let rgb = Nbrdf::random("rgb", 4, 1);
    let root: serde_json::Value = serde_json::from_str(&rgb.to_json_string()).unwrap();
    assert_eq!(root["version"], 1);
    assert!(root.get("spectral").is_none());
    let mut aniso = rgb.clone();
    aniso.anisotropic = true;
    let root: serde_json::Value = serde_json::from_str(&aniso.to_json_string()).unwrap();
    assert_eq!(root["version"], 2);
}

type Edit<'a> = &'a dyn Fn(&mut serde_json::Value);

#[test]
fn version_3_refusals_name_the_field() {
    let text = spectral_net(6, 4).to_json_string();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut root: serde_json::Value = serde_json::from_str(&text).unwrap();
        f(&mut root);
        Nbrdf::from_json_str(&root.to_string(), Path::new("bad.nbrdf.json"))
            .unwrap_err()
            .to_string()
    };
    let cases: [(Edit, &str); 7] = [
        (&|r| r["spectral"]["basis"] = "fourier".into(), "basis"),
        (&|r| r["spectral"]["count"] = 3.into(), "count"),
        (&|r| r["spectral"]["count"] = 65.into(), "count"),
        (&|r| r["spectral"]["max_nm"] = 300.0.into(), "min_nm"),
        (&|r| r["spectral"]["count"] = 17.into(), "layer 3"),
        (
            &|r| r["version"] = 2.into(),
            "\"spectral\" needs format version 3",
        ),
        (
            &|r| {
                r.as_object_mut().unwrap().remove("spectral");
            },
            "missing field \"spectral\"",
        ),
    ];
    for (f, needle) in cases {
        let message = edit(f);
        assert!(
            message.contains(needle) && message.contains("bad.nbrdf.json"),
            "{needle}: {message}"
        );
    }
}

/// Units made dead (a large negative bias) are found by the proof and dropping them changes no
/// spectral value.
#[test]
fn pruning_keeps_spectral_values() {
    let mut net = spectral_net(16, 11);
    for unit in [2, 5, 9] {
        net.layers[0].bias[unit] = -1e3;
    }
    let active = net.active_units();
    assert!([2, 5, 9].iter().all(|&u| !active.hidden1[u]));
    let pruned = net.without_inactive_units();
    assert_eq!(pruned.layers[2].outputs, COUNT);
    let n = 64;
    let (view, light) = random_pairs(n, 12);
    let wavelengths: Vec<f32> = (0..n).map(|i| 360.0 + 7.3 * i as f32).collect();
    let (mut a, mut b) = (vec![0.0f32; n], vec![0.0f32; n]);
    for (net, out) in [(&net, &mut a), (&pruned, &mut b)] {
        net.eval_spectral_cos_batch(
            crate::brdf::Directions::from_planar(&view).unwrap(),
            crate::brdf::Directions::from_planar(&light).unwrap(),
            &wavelengths,
            out,
        )
        .unwrap();
    }
    for (x, y) in a.iter().zip(&b) {
        assert!(close(f64::from(*y), f64::from(*x)), "{x} vs {y}");
    }
}
