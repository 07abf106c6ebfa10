//! Throughput of the renderer's hot paths: batched NBRDF evaluation (one thread and all threads),
//! the scalar evaluation for reference, and Blinn-Phong sampling. Criterion prints elements/s.
//!
//! Short run: `cargo bench --bench throughput -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use nbrdf_core::rng::SplitMix64;
use nbrdf_core::sampling::{pdf_batch, sample_batch, SamplingStrategy};
use nbrdf_core::{Brdf, Directions, DirectionsMut, Nbrdf, RgbMut};

const BATCH: usize = 1 << 20;
const SCALAR_BATCH: usize = 1 << 14;

/// Planar `[x.., y.., z..]` directions, uniform on the upper hemisphere.
fn hemisphere_directions(n: usize, seed: u64) -> Vec<f32> {
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

fn uniforms(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64::from_state(seed);
    (0..3 * n).map(|_| rng.next_f32()).collect()
}

/// A network with trained-like magnitudes (the paper's init gives outputs near 0, which would
/// not exercise the exp range); the cost does not depend on the values otherwise.
fn bench_network() -> Nbrdf {
    let mut net = Nbrdf::random("bench", 21, 1);
    for layer in net.layers.iter_mut() {
        let scale = 30.0 / (layer.inputs as f32).sqrt();
        layer.weights.iter_mut().for_each(|w| *w *= scale);
    }
    net
}

fn dirs(planar: &[f32]) -> Directions<'_> {
    Directions::from_planar(planar).expect("planar buffer")
}

fn single_thread_pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool")
}

fn network_eval(c: &mut Criterion) {
    let net = bench_network();
    let view = hemisphere_directions(BATCH, 1);
    let light = hemisphere_directions(BATCH, 2);
    let mut out = vec![0.0f32; 3 * BATCH];
    let one = single_thread_pool();
    let threads = rayon::current_num_threads();

    let mut group = c.benchmark_group("nbrdf_eval_cos_batch");
    group.sample_size(10);
    group.throughput(Throughput::Elements(BATCH as u64));
    group.bench_function("1_thread", |b| {
        b.iter(|| {
            one.install(|| {
                net.eval_cos_batch(
                    dirs(&view),
                    dirs(&light),
                    RgbMut::from_planar(&mut out).expect("planar"),
                )
            })
        })
    });
    group.bench_function(format!("{threads}_threads"), |b| {
        b.iter(|| {
            net.eval_cos_batch(
                dirs(&view),
                dirs(&light),
                RgbMut::from_planar(&mut out).expect("planar"),
            )
        })
    });
    group.finish();

    let mut group = c.benchmark_group("nbrdf_eval_scalar");
    group.sample_size(10);
    group.throughput(Throughput::Elements(SCALAR_BATCH as u64));
    let (v, l) = (dirs(&view), dirs(&light));
    group.bench_function("1_thread", |b| {
        b.iter(|| {
            let mut sum = 0.0f32;
            for i in 0..SCALAR_BATCH {
                sum += net.eval(black_box(v.get(i)), black_box(l.get(i)))[0];
            }
            sum
        })
    });
    group.finish();
}

fn blinn_phong_sampling(c: &mut Criterion) {
    let net = bench_network();
    let strategy = SamplingStrategy::Phong {
        exponent: 210.0,
        specular_weight: 0.31,
    };
    let view = hemisphere_directions(BATCH, 3);
    let u = uniforms(BATCH, 4);
    let mut light = vec![0.0f32; 3 * BATCH];
    let mut weight = vec![0.0f32; 3 * BATCH];
    let mut pdf = vec![0.0f32; BATCH];
    let one = single_thread_pool();
    let threads = rayon::current_num_threads();

    let mut group = c.benchmark_group("blinn_phong");
    group.sample_size(10);
    group.throughput(Throughput::Elements(BATCH as u64));
    let mut run_sample_batch = || {
        sample_batch(
            &strategy,
            &net,
            dirs(&view),
            dirs(&u),
            DirectionsMut::from_planar(&mut light).expect("planar"),
            RgbMut::from_planar(&mut weight).expect("planar"),
            &mut pdf,
        )
    };
    group.bench_function("sample_batch_with_nbrdf_weight_1_thread", |b| {
        b.iter(|| one.install(&mut run_sample_batch))
    });
    group.bench_function(
        format!("sample_batch_with_nbrdf_weight_{threads}_threads"),
        |b| b.iter(&mut run_sample_batch),
    );
    let sampled = light.clone();
    group.bench_function(format!("pdf_batch_{threads}_threads"), |b| {
        b.iter(|| pdf_batch(&strategy, dirs(&view), dirs(&sampled), &mut pdf))
    });
    group.finish();

    let mut group = c.benchmark_group("blinn_phong_scalar");
    group.sample_size(10);
    group.throughput(Throughput::Elements(SCALAR_BATCH as u64));
    let (v, uu) = (dirs(&view), dirs(&u));
    group.bench_function("sample_1_thread", |b| {
        b.iter(|| {
            let mut acc = Vec3::ZERO;
            for i in 0..SCALAR_BATCH {
                let s = strategy.sample(black_box(v.get(i)), black_box(uu.get(i).to_array()));
                acc += s.light * s.pdf;
            }
            acc
        })
    });
    group.finish();
}

criterion_group!(benches, network_eval, blinn_phong_sampling);
criterion_main!(benches);
