//! Times the batched RGB evaluation of a network (`Brdf::eval_cos_batch`, the inference kernel of
//! `network/kernel.rs`) on one thread, in wall and CPU seconds, so that two builds of the library
//! can be compared interleaved on a loaded machine (criterion reports wall time only, which
//! other jobs inflate).
//!
//! `kernel_speed [BATCHES] [--anisotropic]`: evaluates BATCHES (default 20) batches of 2^20
//! direction pairs and prints one line: `wall_s cpu_s evaluations_per_cpu_s checksum`. The CPU
//! seconds are this process's user + system time over the timed loop (`/proc/self/stat`, 10 ms
//! ticks), `nan` where that file cannot be read. The network is the throughput bench's
//! (`benches/workload`), the same in every build.

use nbrdf_core::{Brdf, Directions, RgbMut};
use std::process::ExitCode;
use std::time::Instant;

const BATCH: usize = 1 << 20;

#[path = "../benches/workload/mod.rs"]
mod workload;
use workload::{bench_network, hemisphere_directions};

/// User + system seconds of this process so far.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name (which may hold spaces) start at field 3; utime, stime
    // are fields 14 and 15, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    match (fields.get(11), fields.get(12)) {
        (Some(u), Some(s)) => match (u.parse::<f64>(), s.parse::<f64>()) {
            (Ok(u), Ok(s)) => (u + s) / 100.0,
            _ => f64::NAN,
        },
        _ => f64::NAN,
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let anisotropic = args.iter().any(|a| a == "--anisotropic");
    let batches = match args.iter().find(|a| !a.starts_with("--")) {
        None => 20,
        Some(n) => match n.parse::<usize>() {
            Ok(n) => n,
            Err(_) => {
                eprintln!("kernel_speed: BATCHES must be a count, got '{n}'");
                return ExitCode::FAILURE;
            }
        },
    };
    let net = bench_network(anisotropic);
    let view = hemisphere_directions(BATCH, 1);
    let light = hemisphere_directions(BATCH, 2);
    let mut out = vec![0.0f32; 3 * BATCH];
    let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(1).build() else {
        eprintln!("kernel_speed: cannot build a one-thread pool");
        return ExitCode::FAILURE;
    };
    let (Some(v), Some(l)) = (
        Directions::from_planar(&view),
        Directions::from_planar(&light),
    ) else {
        eprintln!("kernel_speed: bad direction buffers");
        return ExitCode::FAILURE;
    };
    let (cpu0, wall0) = (cpu_seconds(), Instant::now());
    let mut checksum = 0.0f64;
    for _ in 0..batches {
        let Some(rgb) = RgbMut::from_planar(&mut out) else {
            eprintln!("kernel_speed: bad output buffer");
            return ExitCode::FAILURE;
        };
        pool.install(|| net.eval_cos_batch(v, l, rgb));
        // Every 4096th output: shows that both builds compute the same values.
        checksum += out.iter().step_by(4096).map(|&v| f64::from(v)).sum::<f64>();
    }
    let (wall, cpu) = (wall0.elapsed().as_secs_f64(), cpu_seconds() - cpu0);
    let evaluations = (batches * BATCH) as f64;
    println!(
        "{wall:.3} {cpu:.2} {:.4e} {checksum:.6e}",
        evaluations / cpu
    );
    ExitCode::SUCCESS
}
