//! The committed C header must match what cbindgen generates from `src/lib.rs`.
//! `NBRDF_BLESS=1 cargo test -p nbrdf-train-ffi --test header` rewrites it.

use std::path::Path;

const BLESS: &str = "run `NBRDF_BLESS=1 cargo test -p nbrdf-train-ffi --test header` to update";

fn generate(crate_dir: &Path) -> String {
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml"))
        .expect("cbindgen.toml is readable and valid");
    let bindings = cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header from src/lib.rs");
    let mut bytes = Vec::new();
    bindings.write(&mut bytes);
    String::from_utf8(bytes).expect("the header is UTF-8")
}

#[test]
fn committed_header_is_up_to_date() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = crate_dir.join("include").join("nbrdf_train.h");
    let generated = generate(crate_dir);
    if std::env::var_os("NBRDF_BLESS").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &generated)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        return;
    }
    let committed = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}; {BLESS}", path.display()));
    if committed != generated {
        let (line, ours, theirs) = committed
            .lines()
            .chain(std::iter::repeat("<end of file>"))
            .zip(generated.lines().chain(std::iter::repeat("<end of file>")))
            .enumerate()
            .find(|(_, (a, b))| a != b)
            .map(|(i, (a, b))| (i + 1, a, b))
            .unwrap_or((0, "", ""));
        panic!(
            "{} is out of date with src/lib.rs (first difference at line {line}:\n  committed: {ours}\n  generated: {theirs}\n); {BLESS}",
            path.display()
        );
    }
}

#[test]
fn header_declares_the_contract() {
    let header = generate(Path::new(env!("CARGO_MANIFEST_DIR")));
    for needle in [
        "#ifndef NBRDF_TRAIN_H",
        "typedef enum NbrdfTrainStatus",
        "NBRDF_TRAIN_OK = 0",
        "typedef struct NbrdfTrainConfig",
        "typedef struct NbrdfEpochStats",
        "const char *nbrdf_train_last_error(void);",
        "int32_t nbrdf_train_config_default(",
        "int32_t nbrdf_train_directions(",
        "int32_t nbrdf_train_from_arrays(",
        "void nbrdf_train_string_free(",
    ] {
        assert!(
            header.contains(needle),
            "the generated header lacks `{needle}`:\n{header}"
        );
    }
}
