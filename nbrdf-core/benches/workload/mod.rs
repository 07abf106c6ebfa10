//! The inputs every speed measurement of the renderer's paths shares (benches/throughput.rs,
//! examples/kernel_speed.rs), so that their figures are of the same work.

#![allow(dead_code)] // each user takes its own subset

use nbrdf_core::rng::SplitMix64;
use nbrdf_core::Nbrdf;

/// Planar `[x.., y.., z..]` directions, uniform on the upper hemisphere.
pub fn hemisphere_directions(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64::from_state(seed);
    let mut planar = vec![0.0f32; 3 * n];
    for i in 0..n {
        let z = rng.next_f64();
        let r = (1.0 - z * z).sqrt();
        let phi = std::f64::consts::TAU * rng.next_f64();
        planar[i] = (r * phi.cos()) as f32;
        planar[n + i] = (r * phi.sin()) as f32;
        planar[2 * n + i] = z as f32;
    }
    planar
}

/// `3 n` uniforms in [0, 1).
pub fn uniforms(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64::from_state(seed);
    (0..3 * n).map(|_| rng.next_f32()).collect()
}

/// A network with trained-like magnitudes (the paper's init gives outputs near 0, which would
/// not exercise the exp range); the cost does not depend on the values otherwise.
pub fn bench_network(anisotropic: bool) -> Nbrdf {
    let mut net = Nbrdf::random("bench", 21, 1);
    for layer in net.layers.iter_mut() {
        let scale = 30.0 / (layer.inputs as f32).sqrt();
        layer.weights.iter_mut().for_each(|w| *w *= scale);
    }
    net.anisotropic = anisotropic;
    net
}
