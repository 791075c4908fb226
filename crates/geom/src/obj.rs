//! Wavefront OBJ: positions and faces only (normals and UVs are not written or read).

use crate::{GeomError, TriMesh};
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `v` and `f` lines (1-based indices).
pub fn write_obj(mesh: &TriMesh, path: &Path) -> Result<(), GeomError> {
    let io = |e| GeomError::io(path, e);
    let mut w = BufWriter::new(std::fs::File::create(path).map_err(io)?);
    writeln!(
        w,
        "# irmirror mesh, metres\n# {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    )
    .map_err(io)?;
    for v in &mesh.vertices {
        writeln!(w, "v {} {} {}", v[0], v[1], v[2]).map_err(io)?;
    }
    for t in &mesh.triangles {
        writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).map_err(io)?;
    }
    w.flush().map_err(io)
}

/// Reads `v` and `f` lines (`f a/b/c …`, negative indices allowed); polygons are fan-triangulated.
pub fn read_obj(path: &Path) -> Result<TriMesh, GeomError> {
    let text = std::fs::read_to_string(path).map_err(|e| GeomError::io(path, e))?;
    let mut mesh = TriMesh::default();
    for (ln, line) in text.lines().enumerate() {
        let fail = |r: &str| GeomError::format(path, format!("line {}: {r}", ln + 1));
        let mut tok = line.split_whitespace();
        match tok.next() {
            Some("v") => {
                let xyz: Vec<f32> = tok
                    .take(3)
                    .map(|s| s.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| fail("bad vertex"))?;
                if xyz.len() != 3 {
                    return Err(fail("vertex needs three coordinates"));
                }
                mesh.vertices.push([xyz[0], xyz[1], xyz[2]]);
            }
            Some("f") => {
                let n = mesh.vertices.len() as i64;
                let idx: Vec<u32> = tok
                    .map(|s| {
                        let i: i64 = s
                            .split('/')
                            .next()
                            .unwrap_or("")
                            .parse()
                            .map_err(|_| fail("bad face index"))?;
                        let i = if i < 0 { n + i } else { i - 1 };
                        u32::try_from(i).map_err(|_| fail("face index out of range"))
                    })
                    .collect::<Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(fail("face needs at least three vertices"));
                }
                for k in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use crate::TriMesh;
    use crate::mesh::unit_cube;

    #[test]
    fn obj_round_trip() {
        let p = std::env::temp_dir().join(format!("irmirror-obj-{}.obj", std::process::id()));
        let cube = unit_cube();
        cube.write(&p).unwrap();
        assert_eq!(TriMesh::read(&p).unwrap(), cube);
        std::fs::write(&p, "v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap();
        assert!(TriMesh::read(&p).is_err());
        std::fs::remove_file(&p).ok();
    }
}
