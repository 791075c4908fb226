//! The fitted scene in 3-D: `scene.glb` (objects, hypotheses, cameras, the truth where known) for
//! any glTF viewer, and `scene.js`, the same meshes for the report's offline WebGL view
//! (`viewer.js`, written by hand: a few hundred lines instead of a vendored engine).

use crate::output::write_text;
use anyhow::Result;
use base64::Engine;
use irmirror_geom::gltf::{GlbPart, write_glb_scene};
use irmirror_geom::nalgebra::Vector3;
use irmirror_geom::{PinholeCamera, Rigid3, TriMesh};
use std::path::Path;

/// The report's 3-D viewer script (inlined into report.html).
pub const VIEWER_JS: &str = include_str!("viewer.js");

/// A lighter copy of an object's surface for the view: vertices clustered on a grid of 1/60 of
/// its bounding-box diagonal (marching tetrahedra give 30,000–50,000 vertices per object, more
/// than a view needs).
pub fn display_mesh(mesh: &TriMesh) -> TriMesh {
    match mesh.bounds() {
        Some((lo, hi)) => {
            let d = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
            if d > 0.0 {
                mesh.clustered(d / 60.0)
            } else {
                mesh.clone()
            }
        }
        None => mesh.clone(),
    }
}

/// One mesh of the scene.
pub struct Part {
    /// What the viewer lists.
    pub name: String,
    /// Depth frame, metres.
    pub mesh: TriMesh,
    /// Linear RGBA, 0–1.
    pub colour: [f32; 4],
    /// Shown when the view opens.
    pub visible: bool,
}

/// Colours shared by the 2-D views and the 3-D scene.
pub mod colour {
    /// Fitted objects (blue).
    pub const OBJECT: [f32; 4] = [0.35, 0.55, 0.9, 1.0];
    /// The best hypothesis (orange).
    pub const PERSON: [f32; 4] = [0.94, 0.59, 0.24, 1.0];
    /// Other hypotheses (grey).
    pub const OTHER: [f32; 4] = [0.6, 0.6, 0.6, 1.0];
    /// The true person (green, see-through).
    pub const TRUTH: [f32; 4] = [0.31, 0.78, 0.35, 0.55];
    /// True objects (green).
    pub const TRUE_OBJECT: [f32; 4] = [0.31, 0.78, 0.35, 0.55];
    /// Cameras (dark grey).
    pub const CAMERA: [f32; 4] = [0.25, 0.25, 0.25, 1.0];
}

/// A camera as a pyramid: apex at its centre, base the image rectangle `depth_m` in front, in
/// the depth frame.
pub fn camera_mesh(cam: &PinholeCamera, depth_from_cam: &Rigid3<f64>, depth_m: f64) -> TriMesh {
    let corner = |u: f64, v: f64| {
        let p = Vector3::new(
            (u - cam.cx) / cam.fx * depth_m,
            (v - cam.cy) / cam.fy * depth_m,
            depth_m,
        );
        let q = depth_from_cam.transform_point(&p);
        [q.x as f32, q.y as f32, q.z as f32]
    };
    let o = depth_from_cam.translation;
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let vertices = vec![
        [o.x as f32, o.y as f32, o.z as f32],
        corner(0.0, 0.0),
        corner(w, 0.0),
        corner(w, h),
        corner(0.0, h),
    ];
    let triangles = vec![
        [0, 2, 1],
        [0, 3, 2],
        [0, 4, 3],
        [0, 1, 4],
        [1, 2, 3],
        [1, 3, 4],
    ];
    TriMesh {
        vertices,
        triangles,
    }
}

/// Writes `scene.glb` and `scene.js` (the parts as base64 arrays for the viewer) to `dir`
/// with file names prefixed by `prefix`. `up` is the scene's up (depth frame).
pub fn write(dir: &Path, prefix: &str, parts: &[Part], up: &Vector3<f64>) -> Result<()> {
    let glb: Vec<GlbPart<'_>> = parts
        .iter()
        .map(|p| GlbPart {
            name: &p.name,
            mesh: &p.mesh,
            colour: p.colour,
        })
        .collect();
    write_glb_scene(&glb, &dir.join(format!("{prefix}scene.glb")))?;
    let b64 = base64::engine::general_purpose::STANDARD;
    let js_parts: Vec<serde_json::Value> = parts
        .iter()
        .map(|p| {
            let positions: Vec<u8> = p
                .mesh
                .vertices
                .iter()
                .flatten()
                .flat_map(|x| x.to_le_bytes())
                .collect();
            // 16-bit indices where they suffice (a body's 13,718 vertices): half the bytes.
            let short = p.mesh.vertices.len() <= usize::from(u16::MAX);
            let indices: Vec<u8> = p
                .mesh
                .triangles
                .iter()
                .flatten()
                .flat_map(|&x| {
                    if short {
                        (x as u16).to_le_bytes().to_vec()
                    } else {
                        x.to_le_bytes().to_vec()
                    }
                })
                .collect();
            serde_json::json!({
                "name": p.name,
                "colour": p.colour,
                "visible": p.visible,
                "frame": p.visible,
                "positions": b64.encode(positions),
                "indices": b64.encode(indices),
                "index_bits": if short { 16 } else { 32 },
            })
        })
        .collect();
    let scene = serde_json::json!({"up": [up.x, up.y, up.z], "parts": js_parts});
    write_text(
        &dir.join(format!("{prefix}scene.js")),
        &format!(
            "// The fitted scene for report.html's 3-D view (depth-camera frame, metres).\nwindow.IRMIRROR_SCENE = {scene};\n"
        ),
    )?;
    Ok(())
}

/// The report section holding the 3-D view (scripts under `prefix`).
pub fn section(prefix: &str) -> String {
    format!(
        r#"<h3>3-D view</h3>
<p>Drag to turn, wheel to zoom, shift-drag to pan; tick what to show. The same scene for any glTF
viewer: <a href="{prefix}scene.glb">scene.glb</a>.</p>
<canvas id="irmirror-3d" width="720" height="440" style="border:1px solid #ccc"></canvas>
<div id="irmirror-3d-parts"></div>
<script src="{prefix}scene.js"></script>
<script>{VIEWER_JS}</script>
"#
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pyramid's base corners are the image corners' rays at the stated depth.
    #[test]
    fn camera_pyramid_spans_the_image() {
        let cam = PinholeCamera::from_fov(160, 120, 60f64.to_radians()).unwrap();
        let m = camera_mesh(&cam, &Rigid3::identity(), 0.1);
        assert_eq!(m.vertices[0], [0.0, 0.0, 0.0]);
        let tan = (30f64.to_radians()).tan() as f32;
        // Horizontal field of view 60°: the left corners lie at x = −0.1 tan 30°.
        assert!(
            (m.vertices[1][0] + 0.1 * tan).abs() < 1e-6,
            "{:?}",
            m.vertices[1]
        );
        assert!((m.vertices[3][2] - 0.1).abs() < 1e-6);
        assert!(m.validate().is_ok());
    }
}
