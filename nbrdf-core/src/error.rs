//! One error type for the crate; every variant names what went wrong and, for files, which file.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum NbrdfError {
    /// The file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its content is not a valid table or network.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// A caller passed a value outside the documented domain.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A setting (a size, a count) outside its documented range (docs/hardening.md) or options
    /// that do not go together: a usage error, which the CLI reports with exit status 2 like
    /// clap's own.
    #[error("{0}")]
    Usage(String),
    /// A material name that the embedded fit catalogue does not hold.
    #[error("unknown material '{name}' (run `nbrdf list-materials` for the 100 MERL names)")]
    UnknownMaterial { name: String },
}

pub type Result<T> = std::result::Result<T, NbrdfError>;

/// The largest JSON file read (networks, autoencoders, predictors; docs/hardening.md): a
/// width-4096 network (the training limit) is about 17 million parameters, some 400 MB of JSON;
/// the paper's width-21 ones are 20 kB.
pub const MAX_JSON_BYTES: u64 = 512 << 20;

/// The size of the regular file at `path`, checked before it is opened: a FIFO would block the
/// open and a device (`/dev/zero`) would be read without end. `max_bytes` bounds what a reader
/// will load; `what` names the expected content in the message.
pub fn regular_file_size(path: &Path, max_bytes: u64, what: &str) -> Result<u64> {
    let metadata = std::fs::metadata(path).map_err(|e| NbrdfError::io(path, e))?;
    if !metadata.is_file() {
        let kind = if metadata.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, socket or device?)"
        };
        return Err(NbrdfError::format(path, format!("{kind}; expected {what}")));
    }
    let size = metadata.len();
    if size > max_bytes {
        return Err(NbrdfError::format(
            path,
            format!("{size} bytes, more than the {max_bytes} bytes of the largest {what} read"),
        ));
    }
    Ok(size)
}

impl NbrdfError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        NbrdfError::Io {
            path: path.into(),
            source,
        }
    }

    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        NbrdfError::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}
