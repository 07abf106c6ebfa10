//! An RGL measurement described structurally: table sizes, angle grids, table contents and a
//! few patched values, written with `write_tensor_file`. Byte mutation of a tensor file mostly
//! breaks its header; this target always produces a well-formed container, so every input
//! reaches the field validation and most reach the interpolants and the evaluation (with
//! fuzzer-chosen directions).

#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use nbrdf_core::rgl::tensor::{write_tensor_file, DType, TensorFile};
use nbrdf_core::rgl::RglMeasurement;
use nbrdf_core_fuzz::{
    check_error_names_origin, check_rgl_measurement, fixed_pairs, pairs_from_components,
};
use std::f32::consts::{FRAC_PI_2, PI};

const ORIGIN: &str = "fuzz/structured.bsdf";
/// Table dimensions stay small (at most this), so that one input is cheap to build and check.
const MAX_SIDE: usize = 9;

#[derive(Arbitrary, Debug)]
enum Angles {
    /// `n` values evenly spread over `[0, span]` (the files' layout).
    Even,
    /// Evenly spread over a fuzzer-chosen span (e.g. a half or a quarter circle of azimuths).
    Span(f32),
    /// Raw values (unsorted, repeated, huge...).
    Raw(Vec<f32>),
}

#[derive(Arbitrary, Debug)]
enum Fill {
    Constant(f32),
    /// `base + amplitude * u` with `u` in [0, 1) varying from entry to entry.
    Varying { base: f32, amplitude: f32 },
    Raw(Vec<f32>),
}

#[derive(Arbitrary, Debug)]
struct Patch {
    /// Which table (ndf, sigma, vndf, luminance, rgb), modulo 5.
    table: u8,
    position: u16,
    value: f32,
}

#[derive(Arbitrary, Debug)]
struct Input {
    n_theta: u8,
    n_phi: u8,
    theta: Angles,
    phi: Angles,
    ndf: [u8; 2],
    sigma: [u8; 2],
    vndf: [u8; 2],
    rgb_res: u8,
    jacobian: u8,
    fills: [Fill; 5],
    patches: Vec<Patch>,
    /// A spectral file: these wavelengths (`Angles` spread over 360-830 nm, or raw) and a
    /// `spectra` table with `n_wavelengths` channels (which may disagree with them) in place
    /// of `rgb`.
    spectral: Option<(Angles, u8)>,
    /// Leave one field out (by index into the field list), or none.
    drop_field: Option<u8>,
    directions: Vec<[f32; 6]>,
}

fn side(n: u8) -> usize {
    usize::from(n) % (MAX_SIDE + 1)
}

fn angles(kind: &Angles, n: usize, span: f32) -> Vec<f32> {
    let even = |span: f32| -> Vec<f32> {
        (0..n)
            .map(|i| if n > 1 { span * i as f32 / (n - 1) as f32 } else { 0.0 })
            .collect()
    };
    match kind {
        Angles::Even => even(span),
        Angles::Span(s) => even(*s),
        Angles::Raw(values) => values.iter().copied().take(MAX_SIDE).collect(),
    }
}

fn fill(kind: &Fill, n: usize) -> Vec<f32> {
    match kind {
        Fill::Constant(x) => vec![*x; n],
        Fill::Varying { base, amplitude } => (0..n)
            .map(|k| {
                let u = ((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f32
                    / (1u64 << 24) as f32;
                base + amplitude * u
            })
            .collect(),
        Fill::Raw(values) if !values.is_empty() => (0..n).map(|k| values[k % values.len()]).collect(),
        Fill::Raw(_) => vec![0.0; n],
    }
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn build(input: &Input) -> Vec<u8> {
    let n_theta = side(input.n_theta);
    let n_phi = side(input.n_phi);
    let theta = angles(&input.theta, n_theta, FRAC_PI_2);
    let phi = angles(&input.phi, n_phi, 2.0 * PI);
    let res = side(input.rgb_res);
    let wavelengths = input.spectral.as_ref().map(|(kind, n)| {
        let values = angles(kind, side(*n), 470.0);
        let shift = if matches!(kind, Angles::Raw(_)) { 0.0 } else { 360.0 };
        values.iter().map(|l| l + shift).collect::<Vec<f32>>()
    });
    let channels = match (&input.spectral, &wavelengths) {
        (Some((Angles::Raw(_), n)), _) => side(*n),
        (_, Some(w)) => w.len(),
        _ => 3,
    };
    let shapes: [Vec<usize>; 5] = [
        vec![side(input.ndf[0]), side(input.ndf[1])],
        vec![side(input.sigma[0]), side(input.sigma[1])],
        vec![phi.len(), theta.len(), side(input.vndf[0]), side(input.vndf[1])],
        vec![phi.len(), theta.len(), res, res],
        vec![phi.len(), theta.len(), channels, res, res],
    ];
    let mut tables: Vec<Vec<f32>> = shapes
        .iter()
        .zip(&input.fills)
        .map(|(shape, kind)| fill(kind, shape.iter().product()))
        .collect();
    for patch in input.patches.iter().take(32) {
        let table = &mut tables[usize::from(patch.table) % 5];
        if !table.is_empty() {
            let k = usize::from(patch.position) % table.len();
            table[k] = patch.value;
        }
    }
    let values = if wavelengths.is_some() { "spectra" } else { "rgb" };
    let names = ["ndf", "sigma", "vndf", "luminance", values];
    let mut fields: Vec<(&str, DType, Vec<usize>, Vec<u8>)> = vec![
        ("description", DType::UInt8, vec![4], b"fuzz".to_vec()),
        ("theta_i", DType::Float32, vec![theta.len()], f32_bytes(&theta)),
        ("phi_i", DType::Float32, vec![phi.len()], f32_bytes(&phi)),
        ("jacobian", DType::UInt8, vec![1], vec![input.jacobian % 3]),
    ];
    for ((name, shape), values) in names.iter().zip(shapes).zip(&tables) {
        fields.push((name, DType::Float32, shape, f32_bytes(values)));
    }
    if let Some(w) = &wavelengths {
        fields.push(("wavelengths", DType::Float32, vec![w.len()], f32_bytes(w)));
    }
    if let Some(k) = input.drop_field {
        let k = usize::from(k);
        if k < fields.len() {
            fields.remove(k);
        }
    }
    let refs: Vec<(&str, DType, &[usize], &[u8])> = fields
        .iter()
        .map(|(n, d, s, b)| (*n, *d, s.as_slice(), b.as_slice()))
        .collect();
    write_tensor_file(&refs)
}

fuzz_target!(|input: Input| {
    let bytes = build(&input);
    let parsed = TensorFile::parse(bytes, ORIGIN)
        .and_then(|file| RglMeasurement::from_tensor_file(&file));
    match parsed {
        Ok(measurement) => {
            let mut pairs = fixed_pairs();
            pairs.extend(pairs_from_components(
                &input.directions[..input.directions.len().min(16)],
            ));
            check_rgl_measurement(&measurement, &pairs);
        }
        Err(error) => check_error_names_origin(&error, ORIGIN),
    }
});
