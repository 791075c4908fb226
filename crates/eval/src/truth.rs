//! The truth a simulated capture carries (`truth/`), in the form the figures need: from a
//! [`Simulation`] in memory, or read back from a capture directory so that any result can be
//! scored against it (`irmirror score`, `reconstruct` on a simulated capture).

use crate::EvalError;
use irmirror_body::BodyModel;
use irmirror_capture::Image;
use irmirror_capture::image_io::read_mask;
use irmirror_geom::transform::RigidFile;
use irmirror_geom::{PinholeCamera, Rigid3, Similarity3, TriMesh};
use irmirror_sim::Simulation;
use nalgebra::Vector3;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The evaluation camera: a third view that sees the person (not part of the capture's input).
#[derive(Clone, Debug)]
pub struct TruthCamera {
    /// Intrinsics.
    pub intrinsics: PinholeCamera,
    /// Camera frame → depth-camera frame.
    pub depth_from_camera: Rigid3<f64>,
    /// The true person's keypoints in it, pixels (`None`: behind the camera), model order.
    pub keypoints_px: Vec<Option<(f64, f64)>>,
}

/// The simulator's truth, depth-camera frame, metres.
#[derive(Clone, Debug)]
pub struct Truth {
    /// Joints in the body model's bone order.
    pub joints: Vec<Vector3<f64>>,
    /// Keypoints in the body model's keypoint order.
    pub keypoints: Vec<Vector3<f64>>,
    /// The placed body mesh (the body model's topology).
    pub mesh: TriMesh,
    /// Thermal pixels whose reflection shows the person.
    pub reflection_mask: Image<bool>,
    /// The evaluation camera.
    pub third: TruthCamera,
    /// Object placements, in the capture's object order.
    pub object_poses: Vec<Similarity3<f64>>,
    /// Object surfaces, depth frame, same order.
    pub object_meshes: Vec<TriMesh>,
}

#[derive(Deserialize)]
struct BodyJson {
    joints_m: BTreeMap<String, [f64; 3]>,
    keypoints_m: BTreeMap<String, [f64; 3]>,
}

#[derive(Deserialize)]
struct CameraJson {
    intrinsics: PinholeCamera,
    depth_from_camera: RigidFile,
    keypoints_px: BTreeMap<String, Option<[f64; 2]>>,
}

#[derive(Deserialize)]
struct PoseJson {
    rotation: [[f64; 3]; 3],
    translation_m: [f64; 3],
    scale_m: f64,
}

#[derive(Deserialize)]
struct ObjectJson {
    depth_from_object: PoseJson,
    mesh: String,
}

/// A `Similarity3` from its file form, checked.
pub fn similarity(
    rotation: &[[f64; 3]; 3],
    translation_m: [f64; 3],
    scale_m: f64,
) -> Result<Similarity3<f64>, String> {
    let rigid = RigidFile {
        rotation: *rotation,
        translation_m,
    }
    .to_rigid()
    .map_err(|e| e.to_string())?;
    if !(scale_m.is_finite() && scale_m > 0.0) {
        return Err(format!("scale {scale_m} must be positive"));
    }
    Ok(Similarity3 {
        rotation: rigid.rotation,
        translation: rigid.translation,
        scale: scale_m,
    })
}

fn bad(path: &Path, reason: impl Into<String>) -> EvalError {
    EvalError::Input {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    serde_json::from_str(&text).map_err(|e| bad(path, e.to_string()))
}

/// `names` looked up in `map`, in order.
fn by_name<T: Clone>(
    path: &Path,
    what: &str,
    map: &BTreeMap<String, T>,
    names: &[String],
) -> Result<Vec<T>, EvalError> {
    names
        .iter()
        .map(|n| {
            map.get(n).cloned().ok_or_else(|| {
                bad(
                    path,
                    format!("{what} `{n}` is missing (not a capture of this body model?)"),
                )
            })
        })
        .collect()
}

impl Truth {
    /// The truth of a simulation in memory.
    pub fn from_simulation(sim: &Simulation) -> Result<Self, EvalError> {
        let depth_from_camera = sim
            .scene
            .depth_camera
            .world_from_camera
            .to_rigid()?
            .inverse()
            * sim.scene.third_camera.world_from_camera.to_rigid()?;
        Ok(Self {
            joints: sim.body.joints.clone(),
            keypoints: sim.body.keypoints.clone(),
            mesh: sim.body.mesh.clone(),
            reflection_mask: sim.reflection_mask.clone(),
            third: TruthCamera {
                intrinsics: sim.scene.third_camera.intrinsics,
                depth_from_camera,
                keypoints_px: sim.third_view.1.clone(),
            },
            object_poses: sim.object_poses.clone(),
            object_meshes: sim.object_meshes.clone(),
        })
    }

    /// Whether `capture` holds a simulator's truth (`truth/body.json`).
    pub fn exists(capture: &Path) -> bool {
        capture.join("truth/body.json").is_file()
    }

    /// Reads `capture/truth/` as the simulator writes it.
    pub fn load(capture: &Path, model: &BodyModel) -> Result<Self, EvalError> {
        let dir = capture.join("truth");
        let p = |name: &str| -> PathBuf { dir.join(name) };
        let body: BodyJson = read_json(&p("body.json"))?;
        let meta = &model.asset.meta;
        let v3 = |a: [f64; 3]| Vector3::from(a);
        let joints = by_name(&p("body.json"), "joint", &body.joints_m, &meta.bone_names)?
            .into_iter()
            .map(v3)
            .collect();
        let keypoints = by_name(
            &p("body.json"),
            "keypoint",
            &body.keypoints_m,
            &meta.keypoint_labels,
        )?
        .into_iter()
        .map(v3)
        .collect();
        let mesh = TriMesh::read(&p("body.ply")).map_err(|e| bad(&p("body.ply"), e.to_string()))?;
        if mesh.vertices.len() != model.asset.mean_vertices.len() {
            return Err(bad(
                &p("body.ply"),
                format!(
                    "{} vertices, the body model has {}",
                    mesh.vertices.len(),
                    model.asset.mean_vertices.len()
                ),
            ));
        }
        let reflection_mask = read_mask(&p("reflection_mask.png"))?;
        let cam: CameraJson = read_json(&p("third_camera.json"))?;
        cam.intrinsics
            .validate()
            .map_err(|e| bad(&p("third_camera.json"), e.to_string()))?;
        let depth_from_camera = cam
            .depth_from_camera
            .to_rigid()
            .map_err(|e| bad(&p("third_camera.json"), e.to_string()))?;
        let keypoints_px = by_name(
            &p("third_camera.json"),
            "keypoint",
            &cam.keypoints_px,
            &meta.keypoint_labels,
        )?
        .into_iter()
        .map(|k| k.map(|[u, v]| (u, v)))
        .collect();
        let objects: Vec<ObjectJson> = read_json(&p("objects.json"))?;
        let object_poses = objects
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let d = &o.depth_from_object;
                similarity(&d.rotation, d.translation_m, d.scale_m)
                    .map_err(|e| bad(&p("objects.json"), format!("object {k}: {e}")))
            })
            .collect::<Result<_, _>>()?;
        let object_meshes = objects
            .iter()
            .map(|o| {
                let path = p(&o.mesh);
                if Path::new(&o.mesh).is_absolute() || o.mesh.contains("..") {
                    return Err(bad(
                        &p("objects.json"),
                        format!("mesh `{}` must lie inside truth/", o.mesh),
                    ));
                }
                TriMesh::read(&path).map_err(|e| bad(&path, e.to_string()))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            joints,
            keypoints,
            mesh,
            reflection_mask,
            third: TruthCamera {
                intrinsics: cam.intrinsics,
                depth_from_camera,
                keypoints_px,
            },
            object_poses,
            object_meshes,
        })
    }

    /// The true body's vertices as f64.
    pub fn vertices(&self) -> Vec<Vector3<f64>> {
        self.mesh
            .vertices
            .iter()
            .map(|v| Vector3::from(v.map(f64::from)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use irmirror_sim::presets::{Regime, Shapes, regime_scene};

    /// What `score` reads back from a capture's `truth/` is what the simulator had in memory.
    #[test]
    fn truth_read_back_equals_the_simulation() {
        let model = BodyModel::builtin().unwrap();
        let scene = regime_scene(&model, Regime::TabletopWide, Shapes::Simple, 3).unwrap();
        let sim = irmirror_sim::simulate(&model, &scene, 3).unwrap();
        let dir = std::env::temp_dir().join(format!("irmirror-truth-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        sim.write(&model, &dir, 3).unwrap();
        let (a, b) = (
            Truth::from_simulation(&sim).unwrap(),
            Truth::load(&dir, &model).unwrap(),
        );
        // JSON numbers round-trip to within an ulp or two (serde_json's fast float parsing).
        let close = |x: &[Vector3<f64>], y: &[Vector3<f64>]| {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| (p - q).norm() < 1e-12)
        };
        assert!(close(&a.joints, &b.joints));
        assert!(close(&a.keypoints, &b.keypoints));
        assert_eq!(a.mesh.triangles, b.mesh.triangles);
        assert_eq!(a.mesh.vertices, b.mesh.vertices);
        assert_eq!(a.reflection_mask, b.reflection_mask);
        assert_eq!(a.third.intrinsics, b.third.intrinsics);
        assert_eq!(a.third.keypoints_px.len(), b.third.keypoints_px.len());
        for (p, q) in a.third.keypoints_px.iter().zip(&b.third.keypoints_px) {
            match (p, q) {
                (Some(p), Some(q)) => assert!((p.0 - q.0).abs() + (p.1 - q.1).abs() < 1e-9),
                (None, None) => {}
                _ => panic!("{p:?} vs {q:?}"),
            }
        }
        let d = a.third.depth_from_camera.inverse() * b.third.depth_from_camera;
        assert!(d.translation.norm() < 1e-9 && (d.rotation.trace() - 3.0).abs() < 1e-9);
        assert_eq!(a.object_poses.len(), b.object_poses.len());
        for (p, q) in a.object_poses.iter().zip(&b.object_poses) {
            assert!((p.translation - q.translation).norm() < 1e-12);
            assert!((p.scale - q.scale).abs() < 1e-12);
            assert!((p.rotation - q.rotation).norm() < 1e-9);
        }
        assert_eq!(
            a.object_meshes[0].triangles.len(),
            b.object_meshes[0].triangles.len()
        );
        // A truth without the body model's joints is refused with the file named.
        let body = dir.join("truth/body.json");
        let text = std::fs::read_to_string(&body).unwrap();
        std::fs::write(&body, text.replace("\"head\"", "\"hat\"")).unwrap();
        let e = Truth::load(&dir, &model).unwrap_err().to_string();
        assert!(e.contains("body.json") && e.contains("`head`"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
