//! Result directories that appear only when complete, run records, preview images.

use anyhow::{Context, Result};
use image::RgbImage;
use irmirror_geom::TriMesh;
use irmirror_geom::nalgebra::Matrix3;
use irmirror_geom::raster::render_orthographic;
use std::path::{Path, PathBuf};

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
    pub fn new(target: &Path, marker: &str) -> Result<Self> {
        let name = target
            .file_name()
            .with_context(|| format!("{} has no directory name", target.display()))?;
        if target.exists() {
            if !target.is_dir() {
                anyhow::bail!(
                    "{} exists and is not a directory; choose another --out",
                    target.display()
                );
            }
            let empty = std::fs::read_dir(target)
                .map(|mut d| d.next().is_none())
                .unwrap_or(false);
            if !empty && !target.join(marker).exists() {
                anyhow::bail!(
                    "{} exists and is not an irmirror result (no {marker} in it); choose another --out or remove it",
                    target.display()
                );
            }
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
        let tmp = parent.join(format!(
            ".{}.partial-{}",
            name.to_string_lossy(),
            std::process::id()
        ));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).ok();
        }
        std::fs::create_dir_all(&tmp)
            .with_context(|| format!("cannot create {}", tmp.display()))?;
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
    pub fn commit(mut self) -> Result<PathBuf> {
        if self.target.exists() {
            let old = self.tmp.with_extension("old");
            std::fs::rename(&self.target, &old)
                .with_context(|| format!("cannot replace {}", self.target.display()))?;
            std::fs::rename(&self.tmp, &self.target)?;
            std::fs::remove_dir_all(&old).ok();
        } else {
            std::fs::rename(&self.tmp, &self.target)
                .with_context(|| format!("cannot create {}", self.target.display()))?;
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

/// Front view of an Anny-frame mesh (Z up, −Y front): the viewer stands in front.
pub fn view_front() -> Matrix3<f32> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
}

/// Side view from the model's left (+X).
pub fn view_left() -> Matrix3<f32> {
    Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0)
}

/// Renders each mesh from the front (top row) and the left side (bottom row), one column per mesh.
pub fn preview_sheet(meshes: &[&TriMesh], size: u32) -> RgbImage {
    let mut sheet = RgbImage::from_pixel(
        size * meshes.len().max(1) as u32,
        2 * size,
        image::Rgb([255, 255, 255]),
    );
    for (i, m) in meshes.iter().enumerate() {
        let x = i64::from(size) * i as i64;
        image::imageops::replace(
            &mut sheet,
            &render_orthographic(m, &view_front(), size),
            x,
            0,
        );
        image::imageops::replace(
            &mut sheet,
            &render_orthographic(m, &view_left(), size),
            x,
            i64::from(size),
        );
    }
    sheet
}

/// Saves a PNG with context.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<()> {
    img.save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes text with context.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}
