//! The check of a library's committed C header against what cbindgen generates from its
//! `src/lib.rs` and `cbindgen.toml` (each library's `tests/header.rs`); `NBRDF_BLESS=1` rewrites
//! the committed header instead.

use std::path::Path;

/// The header cbindgen generates for the crate in `crate_dir`.
pub fn generate(crate_dir: &Path) -> String {
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

/// Panics, naming the first differing line, when `include/<header>` of the crate `package` in
/// `crate_dir` is not what cbindgen generates; with `NBRDF_BLESS=1`, writes it.
pub fn check_committed(crate_dir: &Path, package: &str, header: &str) {
    let bless = format!("run `NBRDF_BLESS=1 cargo test -p {package} --test header` to update");
    let path = crate_dir.join("include").join(header);
    let generated = generate(crate_dir);
    if std::env::var_os("NBRDF_BLESS").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &generated)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        return;
    }
    let committed = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}; {bless}", path.display()));
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
            "{} is out of date with src/lib.rs (first difference at line {line}:\n  committed: {ours}\n  generated: {theirs}\n); {bless}",
            path.display()
        );
    }
}

/// Panics when the header generated for `crate_dir` lacks one of `needles`.
pub fn assert_declares(crate_dir: &Path, needles: &[&str]) {
    let header = generate(crate_dir);
    for needle in needles {
        assert!(
            header.contains(needle),
            "the generated header lacks `{needle}`:\n{header}"
        );
    }
}
