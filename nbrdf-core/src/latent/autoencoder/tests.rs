//! The autoencoder against closed forms and finite differences; training on tiny sets.

use super::data::{find_network, LossViews};
use super::phases::{lobe_loss, mixtures};
use super::*;

fn material(seed: u64, bias: [f32; 3]) -> Vec<f32> {
    let mut net = Nbrdf::random("m", 21, seed);
    for l in &mut net.layers {
        l.weights.iter_mut().for_each(|v| *v *= 10.0);
    }
    net.layers[2].bias = bias.to_vec();
    net.to_flat()
}

/// Two visible materials, both trained on and validated on.
fn two_materials() -> (Vec<(String, Vec<f32>)>, Split) {
    let mats = vec![
        ("a".to_string(), material(1, [0.5, 0.2, -0.3])),
        ("b".to_string(), material(2, [-0.4, 0.1, 0.6])),
    ];
    let split = Split {
        train: vec!["a".into(), "b".into()],
        test: vec![],
        validation: vec!["a".into(), "b".into()],
    };
    (mats, split)
}

#[test]
fn lobe_loss_gradients_match_finite_differences() {
    let head = Mlp::new(&[CODE_SIZE, 2], 3, 5 << 32);
    let code: Vec<f32> = (0..CODE_SIZE).map(|k| (k as f32 * 0.37).sin()).collect();
    let target = [0.8f32, -1.3];
    let mut g_head = vec![0.0f32; head.parameter_count()];
    let (loss, g_code) = lobe_loss(&head, &code, &target, 0.7, &mut g_head);
    let eps = 1e-2f32;
    let f =
        |h: &Mlp, c: &[f32]| lobe_loss(h, c, &target, 0.7, &mut vec![0.0; h.parameter_count()]).0;
    assert!((f(&head, &code) - loss).abs() < 1e-12);
    for k in [0, 7, 31] {
        let (mut up, mut down) = (code.clone(), code.clone());
        up[k] += eps;
        down[k] -= eps;
        let fd = (f(&head, &up) - f(&head, &down)) / (2.0 * eps as f64);
        assert!(
            (fd - g_code[k] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
            "code {k}: {fd} vs {}",
            g_code[k]
        );
    }
    let flat = head.to_flat();
    for k in [0, 5, 40, 64, 65] {
        let (mut up, mut down) = (head.clone(), head.clone());
        let mut p = flat.clone();
        p[k] += eps;
        up.set_flat(&p);
        p[k] -= 2.0 * eps;
        down.set_flat(&p);
        let fd = (f(&up, &code) - f(&down, &code)) / (2.0 * eps as f64);
        assert!(
            (fd - g_head[k] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
            "param {k}: {fd} vs {}",
            g_head[k]
        );
    }
}

#[test]
fn lobe_loss_needs_every_training_lobe_and_is_off_at_weight_zero() {
    let (mats, split) = two_materials();
    let config = AeConfig {
        hidden: 8,
        max_epochs: 6,
        warmup_epochs: 3,
        batch: 2,
        augment: false,
        image_size: 16,
        lobe_weight: 1.0,
        mixup: 0,
        ..AeConfig::default()
    };
    let only_a = [("a".to_string(), 30.0, 0.5)];
    let err = AutoEncoder::train(&mats, &only_a, 21, split.clone(), &config, |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("'b'"), "{err}");
    let both = [("a".to_string(), 30.0, 0.5), ("b".to_string(), 3000.0, 0.9)];
    let (with, _) = AutoEncoder::train(&mats, &both, 21, split.clone(), &config, |_| {}).unwrap();
    let off = AeConfig {
        lobe_weight: 0.0,
        ..config
    };
    let (plain, _) = AutoEncoder::train(&mats, &[], 21, split.clone(), &off, |_| {}).unwrap();
    let (labelled_off, _) = AutoEncoder::train(&mats, &both, 21, split, &off, |_| {}).unwrap();
    // Weight 0 is the paper's loss exactly, labels or not; the lobe term changes training.
    assert_eq!(plain.encoder, labelled_off.encoder);
    assert_ne!(plain.encoder, with.encoder);
}

#[test]
fn permutation_swaps_the_rendered_channels() {
    let r = SphereRenderer::new(8, 45f64.to_radians(), 21);
    let f = material(1, [0.5, 0.0, -0.5]);
    let p = [2, 0, 1];
    let (a, b) = (
        r.render(&f, &mut r.scratch()),
        r.render(&permute_outputs(&f, 21, p), &mut r.scratch()),
    );
    for k in 0..3 {
        assert_eq!(&b[k * 64..(k + 1) * 64], &a[p[k] * 64..(p[k] + 1) * 64]);
    }
}

#[test]
fn tiny_autoencoder_overfits_two_materials() {
    let (mats, split) = two_materials();
    let config = AeConfig {
        hidden: 8,
        max_epochs: 250,
        warmup_epochs: 120,
        patience: 1000,
        batch: 2,
        learning_rate: 3e-3,
        augment: false,
        input_noise: 0.0,
        weight_decay: 0.0,
        image_size: 16,
        mixup: 0,
        ..AeConfig::default()
    };
    let (ae, history) = AutoEncoder::train(&mats, &[], 21, split, &config, |_| {}).unwrap();
    let first_image = history.iter().find(|e| e.phase == "image").unwrap();
    let last = history.last().unwrap();
    assert!(
        last.validation_image_loss < 1e-4,
        "final image loss {} (first image epoch {})",
        last.validation_image_loss,
        first_image.validation_image_loss
    );
    // Codes decode to valid networks and are deterministic.
    let code = ae.encode_flat(&mats[0].1);
    assert_eq!(code.len(), CODE_SIZE);
    ae.decode(&code, "a").unwrap();
    let (ae2, _) = AutoEncoder::train(&mats, &[], 21, ae.split.clone(), &config, |_| {}).unwrap();
    assert_eq!(ae.decoder, ae2.decoder);
}

#[test]
fn mixup_examples_lie_between_two_training_networks_and_target_their_own_sphere() {
    let (mats, _) = two_materials();
    let (ae, _) = small_autoencoder(2, 1);
    let flats: Vec<Vec<f32>> = mats.iter().map(|m| m.1.clone()).collect();
    let config = AeConfig {
        mixup: 12,
        image_size: 16,
        ..AeConfig::default()
    };
    let theta = super::super::sphere::LIGHT_THETA_DEG.to_radians();
    let views = LossViews(vec![SphereRenderer::new(16, theta, 21)]);
    let mixed = mixtures(&flats, &config, 3, Some(&views), &ae);
    assert_eq!(mixed.len(), 12);
    let (a, b) = (&flats[0], &flats[1]);
    let mut strictly_between = 0;
    for (standardised, targets) in &mixed {
        let flat = ae.destandardise(standardised);
        // Each mixture is a, b, or (1 - t) a + t b with one t for every weight.
        let candidates = [(a, a), (b, b), (a, b), (b, a)];
        let on_segment = candidates.iter().any(|(p, q)| {
            let (k, d) = (0..flat.len())
                .map(|k| (k, q[k] - p[k]))
                .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
                .unwrap();
            let t = if d.abs() < 1e-6 {
                0.0
            } else {
                (flat[k] - p[k]) / d
            };
            (-1e-4..=1.0 + 1e-4).contains(&t)
                && flat
                    .iter()
                    .zip(p.iter().zip(q.iter()))
                    .all(|(f, (p, q))| (f - ((1.0 - t) * p + t * q)).abs() < 1e-3)
        });
        assert!(on_segment, "a mixture off the segment between the networks");
        if flat.iter().zip(a).any(|(f, x)| (f - x).abs() > 1e-3)
            && flat.iter().zip(b).any(|(f, y)| (f - y).abs() > 1e-3)
        {
            strictly_between += 1;
        }
        let want = views.targets(&flat);
        let err = targets[0]
            .iter()
            .zip(&want[0])
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(err < 1e-3, "target off the mixture's own sphere by {err}");
    }
    assert!(strictly_between > 0, "no mixture strictly between a and b");
    // Deterministic per epoch, fresh between epochs.
    let again = mixtures(&flats, &config, 3, Some(&views), &ae);
    assert_eq!(mixed, again);
    assert_ne!(mixed, mixtures(&flats, &config, 4, Some(&views), &ae));
}

/// A small autoencoder of the two-material fixture after `epochs` epochs, `warmup` of
/// them in weight space.
fn small_autoencoder(epochs: usize, warmup: usize) -> (AutoEncoder, Vec<(String, Vec<f32>)>) {
    let (mats, split) = two_materials();
    let config = AeConfig {
        hidden: 8,
        max_epochs: epochs,
        warmup_epochs: warmup,
        batch: 2,
        augment: false,
        input_noise: 0.0,
        image_size: 16,
        mixup: 0,
        ..AeConfig::default()
    };
    let (ae, _) = AutoEncoder::train(&mats, &[], 21, split, &config, |_| {}).unwrap();
    (ae, mats)
}

/// The image loss of a code's decoded network against the sphere of `flat`.
fn code_loss(ae: &AutoEncoder, flat: &[f32], code: &[f32]) -> f64 {
    let r = SphereRenderer::standard();
    let mut s = r.scratch();
    let target = r.render_toned(flat, &mut s);
    r.loss(&ae.decode_flat(code), &target, &mut s, None)
}

#[test]
fn refining_a_code_lowers_the_image_loss_and_zero_steps_keep_it() {
    // A barely trained autoencoder: its codes are poor, so refinement has work to do.
    let (ae, mats) = small_autoencoder(4, 3);
    let flat = &mats[1].1;
    let code = ae.encode_flat(flat);
    let loss = |c: &[f32]| code_loss(&ae, flat, c);
    assert_eq!(ae.refine_code(flat, &code, 0), code);
    let refined = ae.refine_code(flat, &code, 10);
    let (before, after) = (loss(&code), loss(&refined));
    assert!(
        after < 0.7 * before,
        "refined loss {after} vs encoder's {before}"
    );
}

#[test]
fn refined_validation_loss_is_the_mean_loss_of_the_validation_materials() {
    let (ae, mats) = small_autoencoder(4, 3);
    assert!(!ae.split.validation.is_empty());
    let flat_of = |name: &String| find_network(&mats, name).unwrap();
    let encoder_only: f64 = ae
        .split
        .validation
        .iter()
        .map(|n| code_loss(&ae, flat_of(n), &ae.encode_flat(flat_of(n))))
        .sum::<f64>()
        / ae.split.validation.len() as f64;
    let at_zero = ae.refined_validation_loss(&mats, 0).unwrap();
    assert!((at_zero - encoder_only).abs() <= 1e-9 * encoder_only.max(1e-30));
    let refined = ae.refined_validation_loss(&mats, 10).unwrap();
    assert!(refined < 0.7 * at_zero, "{refined} vs {at_zero}");
    let missing: Vec<(String, Vec<f32>)> = Vec::new();
    assert!(ae.refined_validation_loss(&missing, 1).is_err());
}

#[test]
fn refinement_also_starts_from_the_closest_training_codes() {
    let (ae, mats) = small_autoencoder(40, 30);
    // One anchor per training example, each the encoder's code of that example.
    assert_eq!(ae.anchors.len(), 2);
    assert_eq!(ae.anchors[1], ae.encode_flat(&mats[1].1));
    let flat = &mats[1].1;
    let loss = |c: &[f32]| code_loss(&ae, flat, c);
    // A start far off the manifold: alone it stays poor, the anchors rescue it.
    let far: Vec<f32> = ae.anchors[1].iter().map(|v| v + 40.0).collect();
    let mut alone = ae.clone();
    alone.anchors.clear();
    let (single, multi) = (
        loss(&alone.refine_code(flat, &far, 3)),
        loss(&ae.refine_code(flat, &far, 3)),
    );
    let at_anchor = loss(&ae.anchors[1]);
    assert!(multi <= at_anchor, "{multi} vs the anchor's {at_anchor}");
    assert!(
        multi < 0.5 * single,
        "multi-start {multi} vs single start {single}"
    );
}

#[test]
fn fixed_split_is_80_20_and_stable() {
    let names: Vec<String> = (0..100).map(|i| format!("m{i:03}")).collect();
    let s = Split::fixed(&names);
    assert_eq!(
        (s.train.len(), s.test.len(), s.validation.len()),
        (80, 20, 8)
    );
    assert!(s.validation.iter().all(|v| s.train.contains(v)));
    let mut rev = names.clone();
    rev.reverse();
    assert_eq!(Split::fixed(&rev), s);
    // python/materials.py's rule: sorted(names)[2::5].
    let expected: Vec<String> = names.iter().skip(2).step_by(5).cloned().collect();
    assert_eq!(s.test, expected);
    assert!(s.test.iter().all(|t| !s.train.contains(t)));
}

#[test]
fn anisotropic_networks_are_refused_with_one_line() {
    let (ae, _) = small_autoencoder(1, 1);
    let mut net = Nbrdf::random("brushed", 21, 5);
    assert!(ae.encode(&net).is_ok());
    net.anisotropic = true;
    let message = ae.encode(&net).unwrap_err().to_string();
    assert!(message.contains("'brushed' is anisotropic"), "{message}");
    assert!(!message.contains('\n'), "{message}");
    assert!(ae.encode_refined(&net, 2).is_err());
}
