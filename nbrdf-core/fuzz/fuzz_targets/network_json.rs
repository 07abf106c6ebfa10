//! Arbitrary bytes as an `*.nbrdf.json` network. Seeded with valid networks and broken ones
//! (NaN, wrong shapes, huge widths, deep nesting); a network that loads must evaluate to finite,
//! non-negative values at every direction pair.

#![no_main]

use libfuzzer_sys::fuzz_target;
use nbrdf_core::network::Nbrdf;
use nbrdf_core_fuzz::{check_error_names_origin, check_evaluations, fixed_pairs};
use std::path::Path;

const ORIGIN: &str = "fuzz/input.nbrdf.json";

fuzz_target!(|data: &[u8]| {
    // The reader takes text; files are read with `read_to_string`, which stops at invalid UTF-8.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Nbrdf::from_json_str(text, Path::new(ORIGIN)) {
        Ok(net) => {
            check_evaluations(&net, &fixed_pairs(), None);
        }
        Err(error) => check_error_names_origin(&error, ORIGIN),
    }
});
