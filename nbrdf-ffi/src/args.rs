//! Checks and conversions of the exported functions' arguments that the handles share: paths,
//! out-pointers, exact buffer lengths and planar arrays (the pointer and length checks
//! themselves are nbrdf-ffi-common's).

use nbrdf_core::brdf::Directions;
use nbrdf_core::textured::Uvs;
use nbrdf_ffi_common::{check_pointer, Failure, FfiResult};
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;

/// A path argument: bytes on Unix (any encoding), UTF-8 elsewhere.
///
/// # Safety
/// A non-null `path` must point to a NUL-terminated string.
pub(crate) unsafe fn read_path(path: *const c_char) -> FfiResult<PathBuf> {
    if path.is_null() {
        return Err(Failure::null("path"));
    }
    // SAFETY: non-null, NUL-terminated by contract.
    let bytes = unsafe { CStr::from_ptr(path) }.to_bytes();
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(PathBuf::from(std::ffi::OsStr::from_bytes(bytes)))
    }
    #[cfg(not(unix))]
    {
        std::str::from_utf8(bytes)
            .map(PathBuf::from)
            .map_err(|_| Failure::invalid("path is not valid UTF-8"))
    }
}

/// Writes `value` to the out-pointer `out` (named `argument` in errors).
///
/// # Safety
/// A non-null, aligned `out` must be writable.
pub(crate) unsafe fn write<T>(out: *mut T, argument: &str, value: T) -> FfiResult<()> {
    check_pointer(out, argument)?;
    // SAFETY: non-null and aligned (checked), writable by contract.
    unsafe { out.write(value) };
    Ok(())
}

/// Checks that the caller's buffer `argument` holds exactly the `expected` values the call
/// fills, saying where the expected size comes from.
pub(crate) fn exact_len(argument: &str, len: usize, expected: usize, from: &str) -> FfiResult<()> {
    if len == expected {
        return Ok(());
    }
    Err(Failure::invalid(format!(
        "`{argument}` has {len} values, expected {expected} ({from})"
    )))
}

/// A planar `3 n` buffer as directions; the callers sized it with `array_len(n, 3)`.
pub(crate) fn directions(buffer: &[f32]) -> Directions<'_> {
    Directions::from_planar(buffer).expect("planar buffers have length 3 n")
}

/// A planar `2 n` buffer `[u0.., v0..]` as UVs.
pub(crate) fn uvs(buffer: &[f32]) -> Uvs<'_> {
    let (u, v) = buffer.split_at(buffer.len() / 2);
    Uvs { u, v }
}

/// Frees a boxed handle given back by C; null is ignored.
///
/// # Safety
/// `handle` is null or came from `Box::into_raw` of this library and was not freed yet.
pub(crate) unsafe fn free_boxed<H>(handle: *mut H) {
    if !handle.is_null() {
        // Dropping plain data cannot panic, but no unwind may ever cross the boundary.
        // SAFETY: ownership returns from C, by contract.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(handle) })));
    }
}
