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
            // An earlier result is replaced whole: only if it holds nothing irmirror did not
            // write (results from before the listing existed are replaced as they are).
            if let Ok(listed) = std::fs::read_to_string(target.join(LISTING)) {
                let listed: std::collections::BTreeSet<&str> = listed.lines().collect();
                let extra: Vec<String> = files_under(target)
                    .into_iter()
                    .filter(|f| f != LISTING && !listed.contains(f.as_str()))
                    .collect();
                if !extra.is_empty() {
                    let shown = extra.iter().take(3).cloned().collect::<Vec<_>>().join(", ");
                    let more = if extra.len() > 3 {
                        format!(" and {} more", extra.len() - 3)
                    } else {
                        String::new()
                    };
                    return Err(err(
                        target,
                        &format!(
                            "is an earlier result that now holds files irmirror did not write ({shown}{more}); move them or choose another --out"
                        ),
                    ));
                }
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

    /// Moves the finished directory into place (replacing an older result), with the list of
    /// the files it wrote.
    pub fn commit(mut self) -> Result<PathBuf, EvalError> {
        let mut listing = files_under(&self.tmp).join("\n");
        listing.push('\n');
        write_text(&self.path(LISTING), &listing)?;
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

/// The file in every result directory that lists the files irmirror wrote there.
pub const LISTING: &str = ".irmirror-files";

/// Every file under `dir`, as `/`-separated paths relative to it, sorted.
fn files_under(dir: &Path) -> Vec<String> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(base, &p, out);
            } else if let Ok(rel) = p.strip_prefix(base) {
                let parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                out.push(parts.join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A result directory is replaced by the next run, unless someone added a file to it: then
    /// the run is refused, naming the file, and nothing is lost.
    #[test]
    fn a_result_with_added_files_is_not_replaced() {
        let dir = std::env::temp_dir().join(format!("irmirror-staging-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let target = dir.join("result");
        for round in 0..2 {
            let st = Staging::new(&target, "run.toml").unwrap();
            std::fs::create_dir_all(st.path("views")).unwrap();
            write_text(&st.path("run.toml"), "x").unwrap();
            write_text(&st.path("views/a.png"), &format!("{round}")).unwrap();
            st.commit().unwrap();
        }
        assert_eq!(
            std::fs::read_to_string(target.join(LISTING)).unwrap(),
            "run.toml\nviews/a.png\n"
        );
        std::fs::write(target.join("views/notes.txt"), "mine").unwrap();
        let e = Staging::new(&target, "run.toml").err().unwrap().to_string();
        assert!(e.contains("views/notes.txt"), "{e}");
        assert!(target.join("views/notes.txt").exists());
        std::fs::remove_dir_all(&dir).ok();
    }
}
