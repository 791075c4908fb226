//! User meshes for training: OBJ / PLY (via `irmirror_geom`) and STL (binary or ASCII, read
//! here), normalised like the procedural families, with a watertightness check.

use crate::SdfError;
use crate::families::NORMALISED_RADIUS;
use irmirror_geom::TriMesh;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn bad(path: &Path, reason: impl Into<String>) -> SdfError {
    SdfError::Mesh {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// Reads an OBJ, PLY or STL mesh and checks it is usable (finite, non-empty).
pub fn read_mesh(path: &Path) -> Result<TriMesh, SdfError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mesh = match ext.as_deref() {
        Some("stl") => read_stl(path)?,
        Some("obj" | "ply") => TriMesh::read(path).map_err(|e| bad(path, e.to_string()))?,
        _ => return Err(bad(path, "unknown mesh extension (use .obj, .ply or .stl)")),
    };
    mesh.validate().map_err(|e| bad(path, e.to_string()))?;
    if mesh.triangles.is_empty() {
        return Err(bad(path, "the mesh has no triangles"));
    }
    // Normalisation divides by the extent and sampling by the area: a mesh of one point or of
    // collinear vertices has neither.
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let v = |i: u32| {
                let p = mesh.vertices[i as usize];
                nalgebra::Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
            };
            0.5 * (v(t[1]) - v(t[0])).cross(&(v(t[2]) - v(t[0]))).norm()
        })
        .sum();
    if area.is_nan() || area <= 0.0 {
        return Err(bad(
            path,
            "the mesh has zero surface area (every triangle is degenerate)",
        ));
    }
    Ok(mesh)
}

/// Every `.obj`, `.ply` and `.stl` file in `dir` (not recursive), sorted by name.
pub fn mesh_files(dir: &Path) -> Result<Vec<PathBuf>, SdfError> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| bad(dir, format!("cannot list the directory: {e}")))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && matches!(
                    p.extension()
                        .and_then(|e| e.to_str())
                        .map(str::to_ascii_lowercase)
                        .as_deref(),
                    Some("obj" | "ply" | "stl")
                )
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(bad(dir, "no .obj, .ply or .stl files"));
    }
    Ok(files)
}

fn read_stl(path: &Path) -> Result<TriMesh, SdfError> {
    let bytes = std::fs::read(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    let binary_len = |n: usize| 84 + 50 * n;
    let mut corners: Vec<[f32; 3]> = Vec::new();
    if bytes.len() >= 84
        && binary_len(u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize)
            == bytes.len()
    {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        for t in 0..n {
            let base = 84 + 50 * t + 12;
            for k in 0..3 {
                let f = |i: usize| {
                    let o = base + 12 * k + 4 * i;
                    f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]])
                };
                corners.push([f(0), f(1), f(2)]);
            }
        }
    } else {
        let text = std::str::from_utf8(&bytes)
            .map_err(|_| bad(path, "neither a binary STL (size mismatch) nor ASCII text"))?;
        if !text.trim_start().starts_with("solid") {
            return Err(bad(
                path,
                "neither a binary STL (size mismatch) nor an ASCII STL (no `solid`)",
            ));
        }
        for line in text.lines() {
            let mut it = line.split_whitespace();
            if it.next() == Some("vertex") {
                let v: Vec<f32> = it
                    .map(|s| s.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| bad(path, format!("bad vertex line `{line}`: {e}")))?;
                if v.len() != 3 {
                    return Err(bad(path, format!("bad vertex line `{line}`")));
                }
                corners.push([v[0], v[1], v[2]]);
            }
        }
        if !corners.len().is_multiple_of(3) {
            return Err(bad(path, "the number of vertices is not a multiple of 3"));
        }
    }
    // Weld identical corners so that edges are shared (STL stores triangle soup).
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for tri in corners.chunks(3) {
        let t = [0, 1, 2].map(|k| {
            let key = tri[k].map(f32::to_bits);
            *index.entry(key).or_insert_with(|| {
                vertices.push(tri[k]);
                (vertices.len() - 1) as u32
            })
        });
        triangles.push(t);
    }
    Ok(TriMesh {
        vertices,
        triangles,
    })
}

/// Centres the bounding box on the origin and scales its half-diagonal to
/// [`NORMALISED_RADIUS`] (the families' normalisation).
pub fn normalise(mesh: &mut TriMesh) {
    let Some((lo, hi)) = mesh.bounds() else {
        return;
    };
    let c = [0, 1, 2].map(|k| 0.5 * (f64::from(lo[k]) + f64::from(hi[k])));
    let half = (0..3)
        .map(|k| (f64::from(hi[k]) - f64::from(lo[k])).powi(2))
        .sum::<f64>()
        .sqrt()
        / 2.0;
    let s = if half > 0.0 {
        NORMALISED_RADIUS / half
    } else {
        1.0
    };
    mesh.map_vertices(|v| [0, 1, 2].map(|k| ((f64::from(v[k]) - c[k]) * s) as f32));
}

/// The mesh's largest bounding-box dimension (in its file's units) against `typical_m`: a
/// warning when it is 10× larger or smaller (a file in millimetres, centimetres or inches), or
/// `None`. Training normalises every mesh, so its size never enters the prior; the warning
/// says so.
pub fn size_warning(mesh: &TriMesh, typical_m: f64) -> Option<String> {
    let (lo, hi) = mesh.bounds()?;
    let extent = (0..3)
        .map(|k| f64::from(hi[k]) - f64::from(lo[k]))
        .fold(0.0, f64::max);
    let ratio = extent / typical_m;
    (!(0.1..=10.0).contains(&ratio)).then(|| {
        format!(
            "{extent:.4} units across, {ratio:.3}× a typical one of {typical_m} m: not in metres? \
             Used as it is: training scales every mesh to the prior's unit sphere, so only its \
             shape enters the prior"
        )
    })
}

/// Edges not shared by exactly two triangles (0 for a closed manifold mesh).
pub fn open_edges(mesh: &TriMesh) -> usize {
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    count.values().filter(|&&c| c != 2).count()
}
