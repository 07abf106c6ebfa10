//! Training throughput: samples per second through forward, backward and Adam at width 21,
//! on one thread and on all threads (`cargo bench -p nbrdf-core --bench train`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nbrdf_core::coords::RusinkiewiczAngles;
use nbrdf_core::fit::phong::PhongParams;
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::dataset::{self, AngularSampling};
use nbrdf_core::train::rng::Stream;
use nbrdf_core::train::Trainer;

const SAMPLES: usize = 65_536;

fn glossy(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
    let p = PhongParams {
        kd: [0.4, 0.3, 0.2],
        ks: [0.5, 0.5, 0.5],
        exponent: 200.0,
    };
    Some(p.eval(a.theta_h.cos()))
}

fn bench_train(c: &mut Criterion) {
    let set = dataset::draw(
        &glossy,
        AngularSampling::Adaptive,
        false,
        SAMPLES,
        1,
        Stream::TrainSamples,
    )
    .expect("an analytic target is valid everywhere");
    let mut group = c.benchmark_group("train_epoch_width21");
    group.throughput(Throughput::Elements(SAMPLES as u64));
    group.sample_size(10);
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        let mut trainer = Trainer::new(21, 512, AdamConfig::default(), 7);
        let mut order = Vec::new();
        let mut epoch = 0;
        group.bench_function(format!("{threads}_threads"), |b| {
            b.iter(|| {
                epoch += 1;
                pool.install(|| trainer.epoch(&set.samples, &mut order, 7, epoch))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_train);
criterion_main!(benches);
