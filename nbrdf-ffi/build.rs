//! Gives the C library an ELF SONAME (`libnbrdf_ffi.so.<SOVERSION>`), so that programs linked
//! with `-lnbrdf_ffi` record the versioned name and `make install` can ship the usual
//! `libnbrdf_ffi.so.<SOVERSION> -> libnbrdf_ffi.so` pair. Other platforms keep the linker's
//! default.

/// The ABI's major version: raised whenever a program built against the previous header could
/// no longer run (functions removed or changed), independently of the crate version. The
/// Makefile reads it from here. 1: one material and one sampler handle.
const SOVERSION: &str = "1";

fn main() {
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if matches!(
        os.as_str(),
        "linux" | "android" | "freebsd" | "netbsd" | "openbsd" | "dragonfly"
    ) {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libnbrdf_ffi.so.{SOVERSION}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
