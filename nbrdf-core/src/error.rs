//! One error type for the crate; every variant names what went wrong and, for files, which file.

use std::path::PathBuf;

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
    /// A material name that the embedded fit catalogue does not hold.
    #[error("unknown material '{name}' (run `nbrdf list-materials` for the 100 MERL names)")]
    UnknownMaterial { name: String },
}

pub type Result<T> = std::result::Result<T, NbrdfError>;

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
