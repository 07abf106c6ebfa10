//! The committed C header must match what cbindgen generates from `src/lib.rs`.
//! `NBRDF_BLESS=1 cargo test -p nbrdf-train-ffi --test header` rewrites it.

use nbrdf_ffi_common::header::{assert_declares, check_committed};
use std::path::Path;

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn committed_header_is_up_to_date() {
    check_committed(crate_dir(), "nbrdf-train-ffi", "nbrdf_train.h");
}

#[test]
fn header_declares_the_contract() {
    assert_declares(
        crate_dir(),
        &[
            "#ifndef NBRDF_TRAIN_H",
            "typedef enum NbrdfTrainStatus",
            "NBRDF_TRAIN_OK = 0",
            "typedef struct NbrdfTrainConfig",
            "typedef struct NbrdfEpochStats",
            "const char *nbrdf_train_last_error(void);",
            "int32_t nbrdf_train_config_default(",
            "int32_t nbrdf_train_directions(",
            "int32_t nbrdf_train_from_arrays(",
            "int32_t nbrdf_train_spectral_from_arrays(",
            "void nbrdf_train_string_free(",
            "typedef struct NbrdfTexturedConfig",
            "typedef enum NbrdfBakeStage",
            "NBRDF_TRAIN_ERROR_IO = 3",
            "int32_t nbrdf_train_textured_config_default(",
            "int32_t nbrdf_train_textured(",
        ],
    );
}
