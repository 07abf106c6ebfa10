//! Gives the C library an ELF SONAME (`libnbrdf_ffi.so.<major>`), so that programs linked with
//! `-lnbrdf_ffi` record the versioned name and `make install` can ship the usual
//! `libnbrdf_ffi.so.<major> -> libnbrdf_ffi.so` pair. Other platforms keep the linker's default.

fn main() {
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if matches!(
        os.as_str(),
        "linux" | "android" | "freebsd" | "netbsd" | "openbsd" | "dragonfly"
    ) {
        let major = std::env::var("CARGO_PKG_VERSION_MAJOR").unwrap_or_else(|_| "0".into());
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libnbrdf_ffi.so.{major}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
