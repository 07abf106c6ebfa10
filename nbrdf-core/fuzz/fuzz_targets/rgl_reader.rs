//! Arbitrary bytes as an RGL `.bsdf` tensor file. The committed seeds are small synthetic
//! measurements that parse (and seed.sh adds the real ones from `../shared` when present), so
//! mutations reach the field checks, the interpolants and the evaluation, not only the header.

#![no_main]

use libfuzzer_sys::fuzz_target;
use nbrdf_core::rgl::tensor::TensorFile;
use nbrdf_core::rgl::RglMeasurement;
use nbrdf_core_fuzz::{check_error_names_origin, check_rgl_measurement, fixed_pairs};

const ORIGIN: &str = "fuzz/input.bsdf";

fuzz_target!(|data: &[u8]| {
    let parsed = TensorFile::parse(data.to_vec(), ORIGIN)
        .and_then(|file| RglMeasurement::from_tensor_file(&file));
    match parsed {
        Ok(measurement) => check_rgl_measurement(&measurement, &fixed_pairs()),
        Err(error) => check_error_names_origin(&error, ORIGIN),
    }
});
