//! Result directories that appear only when complete, and the files written into them.

use crate::EvalError;
use image::RgbImage;
use std::path::{Path, PathBuf};

fn err(path: &Path, reason: &str) -> EvalError {
    EvalError::Output {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

fn io(path: &Path, what: &str, e: impl std::fmt::Display) -> EvalError {
    err(path, &format!("{what}: {e}"))
}

/// A directory being written: files go into a hidden sibling, renamed over the target by
/// [`Staging::commit`]. Dropped without commit, the partial directory is removed.
pub struct Staging {
    target: PathBuf,
    tmp: PathBuf,
    committed: bool,
}

impl Staging {
    /// Starts writing `target`. An existing `target` is replaced only if it is an earlier result
    /// (it holds `marker`, e.g. `run.toml`) or empty: never a user's file or other directory.
    pub fn new(target: &Path, marker: &str) -> Result<Self, EvalError> {
        let name = target
            .file_name()
            .ok_or_else(|| err(target, "has no directory name"))?;
        if target.exists() {
            if !target.is_dir() {
                return Err(err(
                    target,
                    "exists and is not a directory; choose another --out",
                ));
            }
            let empty = std::fs::read_dir(target)
                .map(|mut d| d.next().is_none())
                .unwrap_or(false);
            if !empty && !target.join(marker).exists() {
                return Err(err(
                    target,
                    &format!(
                        "exists and is not an irmirror result (no {marker} in it); choose another --out or remove it"
                    ),
                ));
            }
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| io(&parent, "cannot create", e))?;
        let tmp = parent.join(format!(
            ".{}.partial-{}",
            name.to_string_lossy(),
            std::process::id()
        ));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).ok();
        }
        std::fs::create_dir_all(&tmp).map_err(|e| io(&tmp, "cannot create", e))?;
        Ok(Self {
            target: target.to_path_buf(),
            tmp,
            committed: false,
        })
    }

    /// Path of a file inside the staged directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.tmp.join(name)
    }

    /// Moves the finished directory into place (replacing an older result).
    pub fn commit(mut self) -> Result<PathBuf, EvalError> {
        if self.target.exists() {
            let old = self.tmp.with_extension("old");
            std::fs::rename(&self.target, &old)
                .map_err(|e| io(&self.target, "cannot replace", e))?;
            std::fs::rename(&self.tmp, &self.target)
                .map_err(|e| io(&self.target, "cannot replace", e))?;
            std::fs::remove_dir_all(&old).ok();
        } else {
            std::fs::rename(&self.tmp, &self.target)
                .map_err(|e| io(&self.target, "cannot create", e))?;
        }
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            std::fs::remove_dir_all(&self.tmp).ok();
        }
    }
}

/// Saves a PNG, naming the file on failure.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<(), EvalError> {
    img.save(path).map_err(|e| io(path, "cannot write", e))
}

/// Writes text, naming the file on failure.
pub fn write_text(path: &Path, text: &str) -> Result<(), EvalError> {
    std::fs::write(path, text).map_err(|e| io(path, "cannot write", e))
}
