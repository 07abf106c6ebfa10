//! Status codes, the last error and the version (the plumbing is nbrdf-ffi-common's, shared with
//! libnbrdf_train).

use nbrdf_ffi_common::{FailureKind, FfiResult, Status};
use std::ffi::c_char;

/// Status code returned (as `int32_t`) by every fallible function. On any value other than
/// `NBRDF_OK`, `nbrdf_last_error()` describes the failure.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfStatus {
    /// Success.
    NBRDF_OK = 0,
    /// A required pointer argument was null; the message names the argument.
    NBRDF_ERROR_NULL_POINTER = 1,
    /// An argument is outside its domain (sampler parameters, misaligned arrays, sizes).
    NBRDF_ERROR_INVALID_ARGUMENT = 2,
    /// A file could not be opened or read; the message names the file.
    NBRDF_ERROR_IO = 3,
    /// A file was read but is not a valid network or MERL table; the message names the file.
    NBRDF_ERROR_FORMAT = 4,
    /// The library caught an internal panic (a bug); the message carries the panic message.
    NBRDF_ERROR_PANIC = 5,
}

impl Status for NbrdfStatus {
    const OK: i32 = NbrdfStatus::NBRDF_OK as i32;

    fn code(kind: FailureKind) -> i32 {
        (match kind {
            FailureKind::NullPointer => NbrdfStatus::NBRDF_ERROR_NULL_POINTER,
            FailureKind::InvalidArgument => NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT,
            FailureKind::Io => NbrdfStatus::NBRDF_ERROR_IO,
            FailureKind::Format => NbrdfStatus::NBRDF_ERROR_FORMAT,
            FailureKind::Panic => NbrdfStatus::NBRDF_ERROR_PANIC,
        }) as i32
    }
}

/// Runs `body`, catching panics; returns the status code and records the message of a failure
/// (prefixed with `function`) for `nbrdf_last_error`.
pub(crate) fn guard(function: &str, body: impl FnOnce() -> FfiResult<()>) -> i32 {
    nbrdf_ffi_common::guard::<NbrdfStatus>(function, body)
}

/// Message of the last failed call on this thread, prefixed with the name of the function that
/// failed; an empty string when no call has failed on this thread. Successful calls leave it
/// unchanged. The pointer stays valid until the next call into this library on the same thread.
#[no_mangle]
pub extern "C" fn nbrdf_last_error() -> *const c_char {
    nbrdf_ffi_common::last_error()
}

/// Version of the library (the crate version, e.g. "0.1.0"); a static string.
#[no_mangle]
pub extern "C" fn nbrdf_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nbrdf_core::NbrdfError;
    use nbrdf_ffi_common::Failure;
    use std::ffi::CStr;

    fn last_error() -> String {
        // SAFETY: the library returns a valid NUL-terminated string.
        unsafe { CStr::from_ptr(nbrdf_last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn guarded_failures_return_the_status_and_set_the_message() {
        let status = guard("some_function", || panic!("boom {}", 42));
        assert_eq!(status, NbrdfStatus::NBRDF_ERROR_PANIC as i32);
        assert!(
            last_error().starts_with("some_function: internal error (panic): boom 42"),
            "{}",
            last_error()
        );
        guard("f", || Err(Failure::invalid("bad")));
        assert_eq!(guard("g", || Ok(())), NbrdfStatus::NBRDF_OK as i32);
        assert_eq!(last_error(), "f: bad");
    }

    #[test]
    fn core_errors_map_to_status_codes() {
        let status = |error: NbrdfError| guard("f", || Err(error.into()));
        let io = NbrdfError::io("x.json", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(status(io), NbrdfStatus::NBRDF_ERROR_IO as i32);
        let binary = NbrdfError::io(
            "x.json",
            std::io::Error::from(std::io::ErrorKind::InvalidData),
        );
        assert_eq!(status(binary), NbrdfStatus::NBRDF_ERROR_FORMAT as i32);
        let format = NbrdfError::format("x.json", "bad");
        assert_eq!(status(format), NbrdfStatus::NBRDF_ERROR_FORMAT as i32);
        let invalid = NbrdfError::InvalidArgument("n".into());
        assert_eq!(
            status(invalid),
            NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT as i32
        );
        assert_eq!(
            guard("f", || Err(Failure::null("x"))),
            NbrdfStatus::NBRDF_ERROR_NULL_POINTER as i32
        );
    }
}
