//! Binary glTF 2.0 (`.glb`) export: one mesh, or a scene of named, coloured meshes; positions +
//! normals + u32 indices per mesh.
//!
//! irmirror meshes are in OpenCV-style camera frames (+Y down, +Z forward); glTF viewers
//! expect +Y up, +Z toward the viewer. The node carries a 180° rotation about X so the scene
//! looks upright in a viewer while the stored positions stay in the irmirror frame.

use crate::{GeomError, TriMesh};
use serde_json::json;
use std::path::Path;

/// One named, coloured mesh of a scene.
pub struct GlbPart<'a> {
    /// Node and mesh name (what a viewer lists).
    pub name: &'a str,
    /// The mesh.
    pub mesh: &'a TriMesh,
    /// Base colour, linear RGBA in 0–1 (alpha < 1 is drawn blended).
    pub colour: [f32; 4],
}

/// Writes `mesh` as a single-mesh `.glb`.
pub fn write_glb(mesh: &TriMesh, path: &Path) -> Result<(), GeomError> {
    write_glb_scene(
        &[GlbPart {
            name: "mesh",
            mesh,
            colour: [0.8, 0.8, 0.8, 1.0],
        }],
        path,
    )
}

/// Writes several meshes as one `.glb` scene: a node, a mesh and a material per part, all under
/// one root node that turns the irmirror frame upright.
pub fn write_glb_scene(parts: &[GlbPart<'_>], path: &Path) -> Result<(), GeomError> {
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut materials, mut nodes) =
        (vec![], vec![], vec![], vec![], vec![]);
    let mut view = |bin: &mut Vec<u8>, bytes: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len(), "target": target}),
        );
        views.len() - 1
    };
    for (k, part) in parts.iter().enumerate() {
        let mesh = part.mesh;
        mesh.validate()?;
        let le = |xs: &mut dyn Iterator<Item = [u8; 4]>| xs.flatten().collect::<Vec<u8>>();
        let positions = le(&mut mesh.vertices.iter().flatten().map(|x| x.to_le_bytes()));
        let normals = le(&mut mesh
            .vertex_normals()
            .into_iter()
            .flatten()
            .map(|x| x.to_le_bytes()));
        let indices = le(&mut mesh.triangles.iter().flatten().map(|x| x.to_le_bytes()));
        let (lo, hi) = mesh.bounds().unwrap_or(([0.0; 3], [0.0; 3]));
        let nv = mesh.vertices.len();
        let vp = view(&mut bin, &positions, 34962);
        let vn = view(&mut bin, &normals, 34962);
        let vi = view(&mut bin, &indices, 34963);
        let a = accessors.len();
        accessors.push(json!({"bufferView": vp, "componentType": 5126, "count": nv, "type": "VEC3", "min": lo, "max": hi}));
        accessors
            .push(json!({"bufferView": vn, "componentType": 5126, "count": nv, "type": "VEC3"}));
        accessors.push(json!({"bufferView": vi, "componentType": 5125, "count": mesh.triangles.len() * 3, "type": "SCALAR"}));
        let blend = part.colour[3] < 1.0;
        materials.push(json!({
            "name": part.name,
            "pbrMetallicRoughness": {"baseColorFactor": part.colour, "metallicFactor": 0.0, "roughnessFactor": 0.8},
            "alphaMode": if blend { "BLEND" } else { "OPAQUE" },
            "doubleSided": true
        }));
        meshes.push(json!({"name": part.name, "primitives": [{"attributes": {"POSITION": a, "NORMAL": a + 1}, "indices": a + 2, "material": k}]}));
        nodes.push(json!({"name": part.name, "mesh": k}));
    }
    let children: Vec<usize> = (1..=parts.len()).collect();
    let mut all_nodes = vec![
        json!({"name": "irmirror depth-camera frame (OpenCV axes), metres", "rotation": [1.0, 0.0, 0.0, 0.0], "children": children}),
    ];
    all_nodes.extend(nodes);
    let doc = json!({
        "asset": {"version": "2.0", "generator": "irmirror"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": all_nodes,
        "meshes": meshes,
        "materials": materials,
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": views,
        "accessors": accessors
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

    #[test]
    fn glb_scene_has_a_node_mesh_and_material_per_part() {
        let p = std::env::temp_dir().join(format!("irmirror-scene-{}.glb", std::process::id()));
        let cube = unit_cube();
        let parts = [
            super::GlbPart {
                name: "a",
                mesh: &cube,
                colour: [1.0, 0.0, 0.0, 1.0],
            },
            super::GlbPart {
                name: "b",
                mesh: &cube,
                colour: [0.0, 1.0, 0.0, 0.5],
            },
        ];
        super::write_glb_scene(&parts, &p).unwrap();
        let b = std::fs::read(&p).unwrap();
        let jlen = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let doc: serde_json::Value = serde_json::from_slice(&b[20..20 + jlen]).unwrap();
        assert_eq!(doc["nodes"][0]["children"], serde_json::json!([1, 2]));
        assert_eq!(doc["nodes"][2]["name"], "b");
        assert_eq!(doc["meshes"][1]["primitives"][0]["indices"], 5);
        assert_eq!(doc["materials"][1]["alphaMode"], "BLEND");
        assert_eq!(doc["accessors"][5]["count"], 36);
        // Every view lies inside the buffer, 4-byte aligned.
        let blen = doc["buffers"][0]["byteLength"].as_u64().unwrap();
        for v in doc["bufferViews"].as_array().unwrap() {
            let (o, l) = (
                v["byteOffset"].as_u64().unwrap(),
                v["byteLength"].as_u64().unwrap(),
            );
            assert!(o % 4 == 0 && o + l <= blen, "{v}");
        }
        std::fs::remove_file(&p).ok();
    }
}
