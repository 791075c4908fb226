//! The renderer benchmark scene `assets/bench/scene_sphere160.json` (DESIGN.md §7): a
//! 160×120 camera, a mirror sphere, the 26,756-triangle MakeHuman body, σ, and masks.

use crate::sdf::{PlacedSdf, Sphere};
use crate::{OccupancyParams, RenderError};
use irmirror_geom::{PinholeCamera, Similarity3};
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

#[derive(Deserialize)]
struct File {
    camera: Camera,
    reflector: Reflector,
    occupancy: Occ,
    target: Target,
    mesh: Mesh,
    reference_hard_mask: String,
}
#[derive(Deserialize)]
struct Camera {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}
#[derive(Deserialize)]
struct Reflector {
    r#type: String,
    center: [f64; 3],
    radius: f64,
}
#[derive(Deserialize)]
struct Occ {
    sigma_m2: f64,
}
#[derive(Deserialize)]
struct Target {
    file: String,
}
#[derive(Deserialize)]
struct Mesh {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

/// The loaded scene.
pub struct BenchScene {
    /// Thermal camera at the depth-frame origin.
    pub camera: PinholeCamera,
    /// The mirror sphere.
    pub sphere: PlacedSdf,
    /// Sphere centre (m) and radius (m), for closed-form checks.
    pub sphere_center_radius: (Vector3<f64>, f64),
    /// Occupancy settings (σ from the file, ε = 1e-4).
    pub occupancy: OccupancyParams,
    /// Body vertices, m, camera frame.
    pub vertices: Vec<Vector3<f64>>,
    /// Body triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Target mask, row-major `[H, W]`, 0/1.
    pub target: Vec<f64>,
    /// Reference hard mask of the unshifted body, `[H, W]`, 0/1.
    pub reference_hard: Vec<f64>,
}

impl BenchScene {
    /// Reads the scene JSON and the masks it names (paths relative to the JSON).
    pub fn load(path: &Path) -> Result<Self, RenderError> {
        let fail = |r: String| RenderError::File {
            path: path.into(),
            reason: r,
        };
        let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
        let f: File = serde_json::from_str(&text).map_err(|e| fail(e.to_string()))?;
        if f.reflector.r#type != "sphere" {
            return Err(fail(format!(
                "reflector type `{}` is not supported (sphere only)",
                f.reflector.r#type
            )));
        }
        let camera = PinholeCamera {
            width: f.camera.width,
            height: f.camera.height,
            fx: f.camera.fx,
            fy: f.camera.fy,
            cx: f.camera.cx,
            cy: f.camera.cy,
        };
        camera.validate().map_err(|e| fail(e.to_string()))?;
        let centre = Vector3::from(f.reflector.center);
        let sphere = PlacedSdf {
            sdf: Arc::new(Sphere { radius: 1.0 }),
            depth_from_object: Similarity3::new(Matrix3::identity(), centre, f.reflector.radius)
                .map_err(|e| fail(e.to_string()))?,
        };
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let (h, w) = (camera.height as usize, camera.width as usize);
        let mask = |name: &str| -> Result<Vec<f64>, RenderError> {
            let (mh, mw, data) = crate::npy::read_2d(&dir.join(name))?;
            if (mh, mw) != (h, w) {
                return Err(fail(format!("{name} is {mh}×{mw}, the camera is {h}×{w}")));
            }
            Ok(data)
        };
        let nv = f.mesh.vertices.len() as u32;
        if f.mesh.faces.iter().flatten().any(|&i| i >= nv) {
            return Err(fail("a face indexes a missing vertex".into()));
        }
        Ok(Self {
            camera,
            sphere,
            sphere_center_radius: (centre, f.reflector.radius),
            occupancy: OccupancyParams {
                sigma_m2: f.occupancy.sigma_m2,
                epsilon: 1e-4,
                ..Default::default()
            },
            vertices: f.mesh.vertices.iter().map(|v| Vector3::from(*v)).collect(),
            triangles: f.mesh.faces,
            target: mask(&f.target.file)?,
            // "file.npy (comment…)": the file name is the first word.
            reference_hard: mask(
                f.reference_hard_mask
                    .split_whitespace()
                    .next()
                    .unwrap_or(""),
            )?,
        })
    }
}
