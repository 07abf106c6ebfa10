//! Throughput of the renderer's hot paths: batched NBRDF evaluation (one thread and all threads),
//! the scalar evaluation for reference, and Blinn-Phong sampling. Criterion prints elements/s.
//!
//! Short run: `cargo bench --bench throughput -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use nbrdf_core::sampling::{pdf_batch, sample_batch, SamplingStrategy};
use nbrdf_core::{Brdf, Directions, DirectionsMut, RgbMut};

const BATCH: usize = 1 << 20;
const SCALAR_BATCH: usize = 1 << 14;

mod workload;
use workload::{bench_network, hemisphere_directions, uniforms};

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
    let net = bench_network(false);
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
    let net = bench_network(false);
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
