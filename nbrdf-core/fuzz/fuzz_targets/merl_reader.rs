//! Arbitrary bytes as a MERL file. Small inputs exercise the header and size checks; the
//! full-size tables seed.sh puts in the corpus (run with `-max_len` of at least 34992012, as
//! run.sh does) let mutations reach the value checks and the lookup.

#![no_main]

use libfuzzer_sys::fuzz_target;
use nbrdf_core::merl::MerlTable;
use nbrdf_core_fuzz::{
    assert_acceptable_merl, check_error_names_origin, check_evaluations, fixed_pairs,
};
use std::path::Path;

const ORIGIN: &str = "fuzz/input.binary";

fuzz_target!(|data: &[u8]| {
    match MerlTable::from_bytes(data, Path::new(ORIGIN)) {
        Ok(table) => {
            let bound = assert_acceptable_merl(data);
            check_evaluations(&table, &fixed_pairs(), Some(bound));
        }
        Err(error) => check_error_names_origin(&error, ORIGIN),
    }
});
