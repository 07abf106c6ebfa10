//! The committed C header must match what cbindgen generates from `src/lib.rs`.
//! `NBRDF_BLESS=1 cargo test -p nbrdf-ffi --test header` rewrites it.

use nbrdf_ffi_common::header::{assert_declares, check_committed};
use std::path::Path;

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn committed_header_is_up_to_date() {
    check_committed(crate_dir(), "nbrdf-ffi", "nbrdf.h");
}

#[test]
fn header_declares_the_contract() {
    assert_declares(
        crate_dir(),
        &[
            "typedef enum NbrdfStatus",
            "NBRDF_OK = 0",
            "NBRDF_ERROR_PANIC",
            "typedef enum NbrdfSamplingKind",
            "NBRDF_SAMPLING_PHONG = 2",
            "typedef struct NbrdfNetwork NbrdfNetwork;",
            "typedef struct NbrdfMerl NbrdfMerl;",
            "typedef struct NbrdfSampler",
            "typedef struct NbrdfNetworkInfo",
            "const char *nbrdf_last_error(void);",
            "int32_t nbrdf_network_eval(",
            "int32_t nbrdf_merl_sample(",
            "int32_t nbrdf_sampler_pdf(",
            "NBRDF_SAMPLING_TWO_LOBE = 3",
            "typedef struct NbrdfMixtureSampler",
            "int32_t nbrdf_network_sample_mixture(",
            "int32_t nbrdf_network_stored_sampler(",
            "#ifndef NBRDF_H",
        ],
    );
}
