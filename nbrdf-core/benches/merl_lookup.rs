//! MERL trilinear lookups per second on a synthesised table (an SGD fit of the catalogue),
//! for random light/view pairs over the upper hemisphere: one at a time on one thread
//! (`Brdf::eval`), and batched (`Brdf::eval_cos_batch`) on one rayon thread and on all of them.

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nbrdf_core::analytic::{AnalyticBrdf, ModelKind};
use nbrdf_core::rng::SplitMix64;
use nbrdf_core::{Brdf, Directions, MerlTable, RgbMut};

const PAIRS: usize = 1 << 16;

/// Uniform over the hemisphere (z uniform in [0, 1) by Archimedes), from a fixed stream so every
/// run looks up the same directions.
fn hemisphere(rng: &mut SplitMix64) -> [f32; 3] {
    let z = rng.next_f32();
    let phi = std::f32::consts::TAU * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    [r * phi.cos(), r * phi.sin(), z]
}

/// `n` directions, planar `[x.., y.., z..]`.
fn planar_directions(rng: &mut SplitMix64, n: usize) -> Vec<f32> {
    let mut out = vec![0.0; 3 * n];
    for i in 0..n {
        let d = hemisphere(rng);
        for k in 0..3 {
            out[k * n + i] = d[k];
        }
    }
    out
}

fn table() -> MerlTable {
    AnalyticBrdf::from_catalogue(ModelKind::Sgd, "gold-metallic-paint")
        .expect("catalogue material")
        .tabulate()
}

fn bench_lookup(c: &mut Criterion) {
    let table = table();
    let mut rng = SplitMix64::from_state(7);
    let light = planar_directions(&mut rng, PAIRS);
    let view = planar_directions(&mut rng, PAIRS);
    let (l, v) = (
        Directions::from_planar(&light).expect("planar"),
        Directions::from_planar(&view).expect("planar"),
    );
    let mut out = vec![0.0f32; 3 * PAIRS];

    let mut group = c.benchmark_group("merl_trilinear_lookup");
    group.throughput(Throughput::Elements(PAIRS as u64));

    group.bench_function("eval/1-thread", |b| {
        b.iter(|| {
            let mut acc = 0.0f32;
            for i in 0..PAIRS {
                acc += black_box(&table).eval(v.get(i), l.get(i))[1];
            }
            acc
        })
    });

    let all = rayon::current_num_threads();
    let thread_counts = if all > 1 { vec![1, all] } else { vec![1] };
    for threads in thread_counts {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("rayon pool");
        group.bench_with_input(
            BenchmarkId::new("eval_cos_batch/threads", threads),
            &threads,
            |b, _| {
                b.iter(|| {
                    pool.install(|| {
                        let out = RgbMut::from_planar(&mut out).expect("planar");
                        black_box(&table).eval_cos_batch(v, l, out);
                    })
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, bench_lookup);
criterion_main!(benches);
