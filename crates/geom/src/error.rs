//! Errors of the geometry crate.

use std::path::PathBuf;

/// What can go wrong reading, writing or validating geometry.
#[derive(Debug, thiserror::Error)]
pub enum GeomError {
    /// An I/O error on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file that does not follow its format.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, in words.
        reason: String,
    },
    /// A mesh that is not usable (NaN vertex, index out of range, …).
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// Camera intrinsics that cannot describe a real camera.
    #[error("invalid camera: {0}")]
    InvalidCamera(String),
    /// A transform that is not a rotation (or similarity) within tolerance.
    #[error("invalid transform: {0}")]
    InvalidTransform(String),
}

impl GeomError {
    /// Wraps an I/O error with its file name.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
    /// A format error with its file name.
    pub fn format(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            reason: reason.into(),
        }
    }
}
