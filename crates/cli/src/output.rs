//! Preview images; result directories and their files come from `irmirror_eval::output`.

use anyhow::{Context, Result, bail};
use image::RgbImage;
pub use irmirror_eval::output::{Staging, save_png, write_text};
use std::path::Path;

/// A file the repository ships (reference data the commands use by default), at the path of the
/// checkout the binary was built from.
pub fn shipped(relative: &str) -> std::path::PathBuf {
    let crate_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    crate_dir
        .ancestors()
        .nth(2)
        .unwrap_or(crate_dir)
        .join(relative)
}
use irmirror_geom::TriMesh;
use irmirror_geom::nalgebra::Matrix3;
use irmirror_geom::raster::render_orthographic;

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

/// Writes `text` to `path` whole or not at all, refusing a path inside any of `inputs` (`flag`
/// names the option in messages).
pub fn write_file_atomic(path: &Path, flag: &str, inputs: &[&Path], text: &str) -> Result<()> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let parent = parent
        .canonicalize()
        .with_context(|| format!("{flag} {}: its directory does not exist", path.display()))?;
    for input in inputs {
        if let Ok(i) = input.canonicalize()
            && parent.starts_with(&i)
        {
            bail!(
                "{flag} {} lies inside the input {}: inputs are never modified",
                path.display(),
                input.display()
            );
        }
    }
    let name = path
        .file_name()
        .with_context(|| format!("{flag} {} names no file", path.display()))?;
    let tmp = parent.join(format!(
        ".{}.partial-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    write_text(&tmp, text)?;
    std::fs::rename(&tmp, parent.join(name))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}
