//! The committed C header must match what cbindgen generates from `src/`.
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
            "#ifndef NBRDF_H",
            "typedef enum NbrdfStatus",
            "NBRDF_OK = 0",
            "NBRDF_ERROR_PANIC",
            "typedef enum NbrdfSamplingKind",
            "NBRDF_SAMPLING_PHONG = 2",
            "NBRDF_SAMPLING_TWO_LOBE = 3",
            "NBRDF_SAMPLING_TABULATED = 4",
            "NBRDF_SAMPLING_ANISOTROPIC_PHONG = 5",
            "typedef enum NbrdfMaterialKind",
            "NBRDF_MATERIAL_TEXTURED = 2",
            "typedef struct NbrdfMaterial NbrdfMaterial;",
            "typedef struct NbrdfSampler NbrdfSampler;",
            "typedef struct NbrdfSamplerParams",
            "float exponent_v;",
            "typedef struct NbrdfMaterialInfo",
            "uint32_t latent_channels;",
            "uint32_t texture_size[2];",
            "typedef struct NbrdfSamplerInfo",
            "const char *nbrdf_last_error(void);",
            "int32_t nbrdf_sampling_kind_name(",
            "int32_t nbrdf_material_load(",
            "int32_t nbrdf_material_eval(",
            "int32_t nbrdf_material_sample(",
            "int32_t nbrdf_material_eval_uv(",
            "int32_t nbrdf_material_sample_uv(",
            "int32_t nbrdf_material_network(",
            "int32_t nbrdf_material_active_units(",
            "int32_t nbrdf_sampler_create(",
            "int32_t nbrdf_sampler_pdf(",
            "int32_t nbrdf_sampler_table(",
        ],
    );
}

/// One entry point per operation: the library exports few functions, each declared once.
#[test]
fn header_declares_at_most_twenty_functions() {
    let header = nbrdf_ffi_common::header::generate(crate_dir());
    let functions: Vec<&str> = header
        .lines()
        .filter(|line| !line.starts_with(['/', ' ', '*']))
        .filter_map(|line| {
            line.split_once(" nbrdf_")
                .or_else(|| line.split_once("*nbrdf_"))
                .map(|(_, rest)| rest)
        })
        .filter_map(|rest| rest.split_once('(').map(|(name, _)| name))
        .collect();
    assert!((15..=20).contains(&functions.len()), "{functions:?}");
    assert!(
        !functions
            .iter()
            .any(|f| f.starts_with("network_") || f.starts_with("merl_")),
        "{functions:?}"
    );
}
