//! What nbrdf's two C libraries share (`libnbrdf_ffi`, nbrdf-ffi, and `libnbrdf_train`,
//! nbrdf-ffi/train): failures and their status codes, the thread-local last error, the panic
//! guard, and the checks of pointer and length arguments; with the feature `header`, the check
//! of a committed cbindgen header (`header`).
//!
//! Each library keeps its own C-visible status enum (cbindgen reads it from the library's
//! `lib.rs`) and maps the failure kinds onto it through [`Status`]. Each cdylib links its own
//! copy of this crate, so each keeps its own last error and panic hook.

#![deny(unsafe_op_in_unsafe_fn)]

#[cfg(feature = "header")]
pub mod header;

use nbrdf_core::NbrdfError;
use std::any::Any;
use std::cell::{Cell, RefCell};
use std::ffi::{c_char, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Once;

/// What went wrong in a call, before a library turns it into its status code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailureKind {
    /// A required pointer argument was null.
    NullPointer,
    /// An argument is outside its domain.
    InvalidArgument,
    /// A file could not be opened or read.
    Io,
    /// A file was read but its content is not valid.
    Format,
    /// An internal panic was caught.
    Panic,
}

/// A library's C status codes.
pub trait Status {
    /// The code of success.
    const OK: i32;
    /// The code of a failure of `kind`.
    fn code(kind: FailureKind) -> i32;
}

/// A failed call: what went wrong and the message for the library's last error.
#[derive(Debug)]
pub struct Failure {
    pub kind: FailureKind,
    pub message: String,
}

pub type FfiResult<T> = Result<T, Failure>;

impl Failure {
    pub fn null(argument: &str) -> Self {
        Failure {
            kind: FailureKind::NullPointer,
            message: format!("argument `{argument}` is a null pointer"),
        }
    }

    pub fn invalid(message: impl Into<String>) -> Self {
        Failure {
            kind: FailureKind::InvalidArgument,
            message: message.into(),
        }
    }
}

impl From<NbrdfError> for Failure {
    fn from(error: NbrdfError) -> Self {
        let kind = match &error {
            // Reading text that is not UTF-8 fails with InvalidData: the file was readable but
            // its content is wrong, which is a format error to the caller.
            NbrdfError::Io { source, .. } if source.kind() == std::io::ErrorKind::InvalidData => {
                FailureKind::Format
            }
            NbrdfError::Io { .. } => FailureKind::Io,
            NbrdfError::Format { .. } => FailureKind::Format,
            _ => FailureKind::InvalidArgument,
        };
        Failure {
            kind,
            message: error.to_string(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The last error and the panic guard.

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
    /// True while this thread runs inside [`guard`].
    static IN_GUARD: Cell<bool> = const { Cell::new(false) };
    /// Where the last panic inside [`guard`] on this thread happened.
    static PANIC_LOCATION: RefCell<Option<String>> = const { RefCell::new(None) };
}

static PANIC_HOOK: Once = Once::new();

fn set_last_error(message: String) {
    let message = CString::new(message.replace('\0', "\\0")).unwrap_or_default();
    // `try_with` fails only while the thread is being torn down; there is nobody to tell then.
    let _ = LAST_ERROR.try_with(|cell| *cell.borrow_mut() = message);
}

/// The message of the last failed call on this thread (empty when none failed), valid until the
/// next failure recorded on this thread: what `nbrdf_last_error` and `nbrdf_train_last_error`
/// return.
pub fn last_error() -> *const c_char {
    LAST_ERROR
        .try_with(|cell| cell.borrow().as_ptr())
        .unwrap_or(c"".as_ptr())
}

fn panic_message(payload: &(dyn Any + Send)) -> &str {
    if let Some(message) = payload.downcast_ref::<&'static str>() {
        message
    } else if let Some(message) = payload.downcast_ref::<String>() {
        message
    } else {
        "(panic payload is not a string)"
    }
}

/// Chains a panic hook that keeps panics caught by [`guard`] quiet (their message and location
/// go to the last error instead of the host's stderr); other panics, and all of them when
/// `RUST_BACKTRACE` is set to anything but 0, still reach the previous hook.
fn install_panic_hook() {
    PANIC_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        let verbose = std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0");
        std::panic::set_hook(Box::new(move |info| {
            let guarded = IN_GUARD.try_with(Cell::get).unwrap_or(false);
            if guarded {
                let location = info.location().map(|l| l.to_string());
                let _ = PANIC_LOCATION.try_with(|cell| *cell.borrow_mut() = location);
            }
            if !guarded || verbose {
                previous(info);
            }
        }));
    });
}

/// Runs `body`, catching panics; returns the status code of `S` and records the message of a
/// failure (prefixed with `function`) as the last error.
pub fn guard<S: Status>(function: &str, body: impl FnOnce() -> FfiResult<()>) -> i32 {
    install_panic_hook();
    let outer = IN_GUARD.with(|g| g.replace(true));
    let result = catch_unwind(AssertUnwindSafe(body));
    IN_GUARD.with(|g| g.set(outer));
    let failure = match result {
        Ok(Ok(())) => return S::OK,
        Ok(Err(failure)) => failure,
        Err(payload) => {
            let location = PANIC_LOCATION.with(|cell| cell.borrow_mut().take());
            let at = location.map(|l| format!(" (at {l})")).unwrap_or_default();
            Failure {
                kind: FailureKind::Panic,
                message: format!(
                    "internal error (panic): {}{at}",
                    panic_message(payload.as_ref())
                ),
            }
        }
    };
    set_last_error(format!("{function}: {}", failure.message));
    S::code(failure.kind)
}

// ---------------------------------------------------------------------------------------------
// Pointer and slice checks.

/// Checks a pointer argument for null and alignment.
pub fn check_pointer<T>(ptr: *const T, argument: &str) -> FfiResult<()> {
    if ptr.is_null() {
        return Err(Failure::null(argument));
    }
    if !ptr.is_aligned() {
        return Err(Failure::invalid(format!(
            "argument `{argument}` is not aligned to {} bytes",
            align_of::<T>()
        )));
    }
    Ok(())
}

/// A shared reference to `*ptr`, or an error naming `argument` when null or misaligned.
///
/// # Safety
/// A non-null `ptr` must point to a live, initialised `T` for the lifetime `'a`.
pub unsafe fn reference<'a, T>(ptr: *const T, argument: &str) -> FfiResult<&'a T> {
    check_pointer(ptr, argument)?;
    // SAFETY: non-null and aligned; validity is the caller's contract.
    Ok(unsafe { &*ptr })
}

/// `factor * n` floats, checked against overflow and the largest possible allocation.
pub fn array_len(n: usize, factor: usize) -> FfiResult<usize> {
    n.checked_mul(factor)
        .filter(|len| {
            len.checked_mul(size_of::<f32>())
                .is_some_and(|bytes| bytes <= isize::MAX as usize)
        })
        .ok_or_else(|| Failure::invalid(format!("batch size n = {n} is too large")))
}

/// # Safety
/// `ptr` passed [`check_pointer`] and points to `len` readable floats.
pub unsafe fn input<'a>(ptr: *const f32, len: usize) -> &'a [f32] {
    // SAFETY: the caller's contract; `len` fits in isize (array_len).
    unsafe { std::slice::from_raw_parts(ptr, len) }
}

/// # Safety
/// `ptr` passed [`check_pointer`] and points to `len` writable floats that no other slice
/// aliases.
pub unsafe fn output<'a>(ptr: *mut f32, len: usize) -> &'a mut [f32] {
    // SAFETY: the caller's contract; `len` fits in isize (array_len).
    unsafe { std::slice::from_raw_parts_mut(ptr, len) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CStr;

    /// Codes that tell the kinds apart, as a library's status enum does.
    struct Codes;

    impl Status for Codes {
        const OK: i32 = 0;
        fn code(kind: FailureKind) -> i32 {
            kind as i32 + 1
        }
    }

    fn message() -> String {
        // SAFETY: `last_error` returns a valid NUL-terminated string.
        unsafe { CStr::from_ptr(last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn guard_catches_panics_with_their_message() {
        let status = guard::<Codes>("some_function", || panic!("boom {}", 42));
        assert_eq!(status, Codes::code(FailureKind::Panic));
        let expected =
            "some_function: internal error (panic): boom 42 (at nbrdf-ffi/common/src/lib.rs:";
        assert!(message().starts_with(expected), "{}", message());
        let status = guard::<Codes>("other", || std::panic::panic_any(7_u8));
        assert_eq!(status, Codes::code(FailureKind::Panic));
        assert!(message().contains("not a string"), "{}", message());
    }

    #[test]
    fn guard_keeps_the_last_failure_across_successes() {
        let status = guard::<Codes>("f", || Err(Failure::invalid("bad")));
        assert_eq!(status, Codes::code(FailureKind::InvalidArgument));
        assert_eq!(guard::<Codes>("g", || Ok(())), Codes::OK);
        assert_eq!(message(), "f: bad");
    }

    #[test]
    fn messages_with_nul_bytes_survive() {
        guard::<Codes>("f", || Err(Failure::invalid("a\0b")));
        assert_eq!(message(), "f: a\\0b");
    }

    #[test]
    fn core_errors_map_to_failure_kinds() {
        let kind = |error: NbrdfError| Failure::from(error).kind;
        let io = |kind| NbrdfError::io("x.json", std::io::Error::from(kind));
        assert_eq!(kind(io(std::io::ErrorKind::NotFound)), FailureKind::Io);
        assert_eq!(
            kind(io(std::io::ErrorKind::InvalidData)),
            FailureKind::Format
        );
        assert_eq!(
            kind(NbrdfError::format("x.json", "bad")),
            FailureKind::Format
        );
        assert_eq!(
            kind(NbrdfError::InvalidArgument("n".into())),
            FailureKind::InvalidArgument
        );
    }

    #[test]
    fn pointers_are_checked_for_null_and_alignment() {
        let value = 1.0_f32;
        assert!(check_pointer(&value, "x").is_ok());
        let null = check_pointer(std::ptr::null::<f32>(), "x").unwrap_err();
        assert_eq!(
            (null.kind, null.message.as_str()),
            (FailureKind::NullPointer, "argument `x` is a null pointer")
        );
        let misaligned = (&value as *const f32)
            .cast::<u8>()
            .wrapping_add(1)
            .cast::<f32>();
        let error = check_pointer(misaligned, "x").unwrap_err();
        assert_eq!(error.kind, FailureKind::InvalidArgument);
        assert!(
            error.message.contains("`x` is not aligned to 4 bytes"),
            "{}",
            error.message
        );
    }

    #[test]
    fn array_len_rejects_overflow() {
        assert_eq!(array_len(4, 3).unwrap(), 12);
        assert!(array_len(usize::MAX / 2, 3).is_err());
        assert!(array_len(usize::MAX / 4, 1).is_err());
        assert!(array_len(usize::MAX / 8, 1).is_ok());
    }
}
