//! The cost of distilling a textured source: trains on a synthetic blend of a Lambertian and a
//! glossy BRDF by a weight per texel, then bakes 256 x 256 and 1024 x 1024 parameter images
//! (one lobe, 64 representatives, the default lobe search) and prints each stage's time.
//!
//! `cargo run --release -p nbrdf-core --example distillation_cost`

use glam::DVec3;
use nbrdf_core::brdf::Directions;
use nbrdf_core::distillation::{
    bake, train_textured, BakeConfig, BakeStage, ParameterImage, TargetKind, TargetValues,
    TexturedSamples, TexturedTrainConfig,
};
use nbrdf_core::rng::SplitMix64;
use std::f64::consts::PI;
use std::time::Instant;

/// `f_r` of the source with blend weight `p`.
fn source(p: f64, view: DVec3, light: DVec3) -> [f64; 3] {
    let cos_h = (view + light).normalize().z.max(0.0);
    let spec = 0.6 * 32.0 / (2.0 * PI) * cos_h.powf(30.0);
    let (a, b) = ([0.8, 0.5, 0.2], [0.05, 0.05, 0.05]);
    std::array::from_fn(|c| (1.0 - p) * a[c] / PI + p * (b[c] / PI + spec))
}

fn main() -> nbrdf_core::Result<()> {
    let n = 100_000;
    let mut rng = SplitMix64::from_state(1);
    let mut params = Vec::with_capacity(n);
    let mut dirs: [Vec<f32>; 6] = Default::default();
    let mut target: [Vec<f32>; 3] = Default::default();
    for _ in 0..n {
        let p = rng.next_f64();
        let mut dir = || nbrdf_core::sampling::uniform_hemisphere(rng.next_f64(), rng.next_f64());
        let (view, light) = (dir(), dir());
        params.push(p as f32);
        for (d, v) in dirs
            .iter_mut()
            .zip(view.to_array().iter().chain(&light.to_array()))
        {
            d.push(*v as f32);
        }
        for (t, f) in target.iter_mut().zip(source(p, view, light)) {
            t.push((f * light.z) as f32);
        }
    }
    let param_slices: [&[f32]; 1] = [&params];
    let samples = TexturedSamples {
        params: &param_slices,
        view: Directions {
            x: &dirs[0],
            y: &dirs[1],
            z: &dirs[2],
        },
        light: Directions {
            x: &dirs[3],
            y: &dirs[4],
            z: &dirs[5],
        },
        target: TargetValues::Rgb([&target[0], &target[1], &target[2]]),
        target_kind: TargetKind::BrdfCos,
    };
    let config = TexturedTrainConfig::default();
    let model = train_textured(&samples, &config, &mut |_| {})?;
    println!(
        "training: {n} samples, {} epochs, {} latent channels: {:.2} s (validation loss {:.5})",
        config.epochs, config.channels, model.report.seconds, model.report.best_validation_loss
    );
    for side in [256usize, 1024] {
        let values: Vec<f32> = (0..side * side)
            .map(|t| ((t % side) + (t / side)) as f32 / (2 * side - 2) as f32)
            .collect();
        let image = ParameterImage {
            width: side,
            height: side,
            channels: 1,
            values: &values,
        };
        let start = Instant::now();
        let mut marks = Vec::new();
        let material = bake(&model, &image, &BakeConfig::new("blend"), &mut |stage| {
            if !matches!(stage, BakeStage::Clustering { .. }) {
                marks.push((stage, start.elapsed().as_secs_f64()));
            }
        })?;
        let total = start.elapsed().as_secs_f64();
        let encoded = marks.first().map_or(0.0, |m| m.1);
        let lobes = marks.last().map_or(0.0, |m| m.1);
        println!(
            "bake {side} x {side}: {total:.2} s (encoding {encoded:.3} s, clustering and {} lobe \
             fits to {lobes:.2} s, assignment and texture {:.3} s); {} channels",
            marks.len().saturating_sub(1),
            total - lobes,
            material.texture().channel_count()
        );
    }
    Ok(())
}
