//! Binary glTF 2.0 (`.glb`) export: one mesh, positions + normals + u32 indices, one node.
//!
//! irmirror meshes are in OpenCV-style camera frames (+Y down, +Z forward); glTF viewers
//! expect +Y up, +Z toward the viewer. The node carries a 180° rotation about X so the scene
//! looks upright in a viewer while the stored positions stay in the irmirror frame.

use crate::{GeomError, TriMesh};
use serde_json::json;
use std::path::Path;

/// Writes `mesh` as a single-mesh `.glb`.
pub fn write_glb(mesh: &TriMesh, path: &Path) -> Result<(), GeomError> {
    mesh.validate()?;
    let normals = mesh.vertex_normals();
    let (lo, hi) = mesh.bounds().unwrap_or(([0.0; 3], [0.0; 3]));
    let mut bin: Vec<u8> = Vec::new();
    for v in &mesh.vertices {
        v.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    let normals_offset = bin.len();
    for n in &normals {
        n.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    let index_offset = bin.len();
    for t in &mesh.triangles {
        t.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    let nv = mesh.vertices.len();
    let doc = json!({
        "asset": {"version": "2.0", "generator": "irmirror"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "rotation": [1.0, 0.0, 0.0, 0.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": normals_offset, "target": 34962},
            {"buffer": 0, "byteOffset": normals_offset, "byteLength": index_offset - normals_offset, "target": 34962},
            {"buffer": 0, "byteOffset": index_offset, "byteLength": bin.len() - index_offset, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5126, "count": nv, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5125, "count": mesh.triangles.len() * 3, "type": "SCALAR"}
        ]
    });
    let mut json_bytes = serde_json::to_vec(&doc).expect("a JSON value always serialises");
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    std::fs::write(path, out).map_err(|e| GeomError::io(path, e))
}

#[cfg(test)]
mod tests {
    use crate::mesh::unit_cube;

    #[test]
    fn glb_has_valid_container_and_accessors() {
        let p = std::env::temp_dir().join(format!("irmirror-glb-{}.glb", std::process::id()));
        let cube = unit_cube();
        cube.write(&p).unwrap();
        let b = std::fs::read(&p).unwrap();
        assert_eq!(&b[0..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize,
            b.len()
        );
        let jlen = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        assert_eq!(jlen % 4, 0);
        let doc: serde_json::Value = serde_json::from_slice(&b[20..20 + jlen]).unwrap();
        assert_eq!(doc["accessors"][0]["count"], 8);
        assert_eq!(doc["accessors"][2]["count"], 36);
        let blen = u32::from_le_bytes(b[20 + jlen..24 + jlen].try_into().unwrap()) as usize;
        assert_eq!(blen, 8 * 12 * 2 + 36 * 4);
        assert_eq!(doc["buffers"][0]["byteLength"], blen);
        std::fs::remove_file(&p).ok();
    }
}
