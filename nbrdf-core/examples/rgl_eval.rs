//! Evaluates an RGL `.bsdf` measurement with `nbrdf_core::rgl` (what `tests/test_rgl_reader.py`
//! compares with Mitsuba's `measured` plugin), or times it.
//!
//! `rgl_eval FILE < directions > values`: reads rows of six little-endian float32 (view xyz,
//! light xyz; view = Mitsuba's `si.wi`, light = its `wo`) from stdin and writes, per row, six
//! little-endian float64: Mitsuba's `eval` (`f_r cos(theta_light)`, RGB) then `f_r` (RGB).
//!
//! `rgl_eval --spectral FILE < rows > values`: for a spectral file (`*_spec.bsdf`), rows of ten
//! little-endian float32 (view xyz, light xyz, four wavelengths in nm, as a Mitsuba spectral
//! variant evaluates) and, per row, four little-endian float64: `f_r cos(theta_light)` at each.
//!
//! `rgl_eval --bench N FILE`: evaluates N random direction pairs in the upper hemisphere on all
//! cores (rayon) and prints evaluations per second.

use glam::Vec3;
use nbrdf_core::brdf::{Directions, RgbMut};
use nbrdf_core::rgl::RglMeasurement;
use std::io::{Read, Write};
use std::process::ExitCode;
use std::time::Instant;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.as_slice() {
        [flag, n, file] if flag == "--bench" => match n.parse() {
            Ok(n) => bench(file, n),
            Err(_) => Err(format!("--bench expects a count, got '{n}'")),
        },
        [flag, file] if flag == "--spectral" => eval_spectral_stdin(file),
        [file] => eval_stdin(file),
        _ => Err(
            "usage: rgl_eval FILE < directions   |   rgl_eval --spectral FILE < rows   |   \
             rgl_eval --bench N FILE"
                .into(),
        ),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// Stdin as rows of `width` little-endian float32.
fn read_rows(width: usize) -> Result<Vec<f32>, String> {
    let mut input = Vec::new();
    std::io::stdin()
        .read_to_end(&mut input)
        .map_err(|e| e.to_string())?;
    if input.len() % (4 * width) != 0 {
        return Err(format!(
            "{} bytes on stdin, not rows of {width} float32",
            input.len()
        ));
    }
    Ok(input
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

fn eval_spectral_stdin(file: &str) -> Result<(), String> {
    let measurement = RglMeasurement::load(file).map_err(|e| e.to_string())?;
    let floats = read_rows(10)?;
    let mut output = Vec::with_capacity(floats.len() / 10 * 32);
    let mut values = [0.0f32; 4];
    for row in floats.chunks_exact(10) {
        let view = Vec3::new(row[0], row[1], row[2]);
        let light = Vec3::new(row[3], row[4], row[5]);
        measurement
            .eval_spectrum_cos_f32(view, light, &row[6..], &mut values)
            .map_err(|e| e.to_string())?;
        for v in values {
            output.extend_from_slice(&(v as f64).to_le_bytes());
        }
    }
    std::io::stdout()
        .write_all(&output)
        .map_err(|e| e.to_string())
}

fn eval_stdin(file: &str) -> Result<(), String> {
    let measurement = RglMeasurement::load(file).map_err(|e| e.to_string())?;
    let floats = read_rows(6)?;
    let mut output = Vec::with_capacity(floats.len() / 6 * 48);
    for row in floats.chunks_exact(6) {
        let view = Vec3::new(row[0], row[1], row[2]);
        let light = Vec3::new(row[3], row[4], row[5]);
        let cosine_weighted = measurement.eval_cos_f32(view, light);
        let f_r = measurement.eval(view, light);
        for v in cosine_weighted.iter().map(|&v| v as f64).chain(f_r) {
            output.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::io::stdout()
        .write_all(&output)
        .map_err(|e| e.to_string())
}

/// Uniform directions on the upper hemisphere from a fixed-seed generator (no `rand` dependency).
fn random_directions(n: usize, seed: u64) -> Vec<f32> {
    let mut state = seed;
    let mut uniform = move || {
        // SplitMix64.
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut planar = vec![0.0f32; 3 * n];
    for i in 0..n {
        let z = uniform();
        let phi = 2.0 * std::f32::consts::PI * uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        planar[i] = r * phi.cos();
        planar[n + i] = r * phi.sin();
        planar[2 * n + i] = z;
    }
    planar
}

fn bench(file: &str, n: usize) -> Result<(), String> {
    let start = Instant::now();
    let measurement = RglMeasurement::load(file).map_err(|e| e.to_string())?;
    let load = start.elapsed();
    let views = random_directions(n, 1);
    let lights = random_directions(n, 2);
    let mut out = vec![0.0f32; 3 * n];
    let view = Directions::from_planar(&views).expect("planar");
    let light = Directions::from_planar(&lights).expect("planar");
    // One warm-up pass (page faults, thread pool start), then the timed one.
    measurement.eval_cos_batch_f32(view, light, RgbMut::from_planar(&mut out).expect("planar"));
    let start = Instant::now();
    measurement.eval_cos_batch_f32(view, light, RgbMut::from_planar(&mut out).expect("planar"));
    let elapsed = start.elapsed().as_secs_f64();
    let mean = out.iter().map(|&v| v as f64).sum::<f64>() / out.len().max(1) as f64;
    println!(
        "{}: load {:.1} ms; {n} evaluations in {:.3} s on {} threads: {:.2} M evals/s (mean value {mean:.4})",
        measurement.description(),
        load.as_secs_f64() * 1e3,
        elapsed,
        rayon::current_num_threads(),
        n as f64 / elapsed / 1e6
    );
    Ok(())
}
