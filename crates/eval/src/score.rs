//! Figures of one reconstructed body against the simulator's truth (DESIGN.md §5): what `demo`,
//! `eval` and the benchmark report.

use crate::EvalError;
use crate::metrics::{mpjpe, normalised_distance, pa_mpjpe};
use crate::views::{Drawn, render_view};
use irmirror_body::{BodyModel, PosedBody};
use irmirror_geom::Rigid3;
use irmirror_recon::objects::Objects;
use irmirror_render::ReflectedRays;
use irmirror_render::hard::hard_mask;
use irmirror_sim::Simulation;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Figures of one reconstruction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Distance between fitted and true root joints, m.
    pub root_error_m: f64,
    /// Distance of the true root from the depth camera, m.
    pub person_distance_m: f64,
    /// Normalised 2-D keypoint distance in the third camera (paper Table 1).
    pub keypoints_2d_normalised: Option<f64>,
    /// Normalised 3-D keypoint distance (paper Table 1).
    pub keypoints_3d_normalised: Option<f64>,
    /// Mean per-joint position error, m.
    pub mpjpe_m: Option<f64>,
    /// MPJPE after Procrustes (similarity) alignment, m.
    pub pa_mpjpe_m: Option<f64>,
    /// Mean distance between corresponding vertices of the fitted and true body meshes (same
    /// topology), m; `None` if the meshes differ in size.
    #[serde(default)]
    pub vertex_error_m: Option<f64>,
    /// Angle between the fitted and true facing directions about the true body's up, degrees
    /// (facing from the shoulder and hip keypoints); `None` for a degenerate skeleton.
    #[serde(default)]
    pub facing_error_deg: Option<f64>,
    /// IoU of the fitted and true reflection masks (thermal pixels).
    pub reflection_iou: f64,
    /// Per object: fitted vs true translation, m.
    pub object_translation_error_m: Vec<f64>,
    /// Per object: fitted vs true scale, %.
    pub object_scale_error_pct: Vec<f64>,
}

/// The thermal pixels whose (unblocked) reflected ray hits `body`.
pub fn fitted_mask(
    model: &BodyModel,
    rays: &ReflectedRays<f64>,
    body: &PosedBody<f64>,
) -> Vec<bool> {
    let bvh = irmirror_render::Bvh::build(&body.vertices, &model.asset.faces);
    hard_mask(rays, &bvh, &body.vertices, &model.asset.faces)
}

/// The simulator's evaluation camera relative to the depth camera.
pub fn depth_from_third(sim: &Simulation) -> Result<Rigid3<f64>, EvalError> {
    Ok(sim
        .scene
        .depth_camera
        .world_from_camera
        .to_rigid()?
        .inverse()
        * sim.scene.third_camera.world_from_camera.to_rigid()?)
}

/// The third camera's view: fitted body (orange), true body (green), fitted objects.
pub fn third_view(
    sim: &Simulation,
    model: &BodyModel,
    body: &PosedBody<f64>,
    objects: &Objects,
) -> Result<image::RgbImage, EvalError> {
    let truth: Vec<Vector3<f64>> = sim
        .body
        .mesh
        .vertices
        .iter()
        .map(|v| Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])))
        .collect();
    Ok(render_view(
        &sim.scene.third_camera.intrinsics,
        &depth_from_third(sim)?,
        &[
            Drawn {
                vertices: &body.vertices,
                triangles: &model.asset.faces,
                colour: [240, 150, 60],
            },
            Drawn {
                vertices: &truth,
                triangles: &sim.body.mesh.triangles,
                colour: [80, 200, 90],
            },
        ],
        &objects.placed(),
    ))
}

/// Evaluates `body` (with its reflection `mask`) and the fitted `objects` against `sim`.
pub fn evaluate(
    sim: &Simulation,
    body: &PosedBody<f64>,
    mask: &[bool],
    objects: &Objects,
) -> Result<Evaluation, EvalError> {
    let third = &sim.scene.third_camera;
    let third_from_depth = depth_from_third(sim)?.inverse();
    let v3 = |p: &Vector3<f64>| vec![p.x, p.y, p.z];
    let (mut kp_fit, mut kp_true) = (Vec::new(), Vec::new());
    for (k, truth) in sim.third_view.1.iter().enumerate() {
        if let (Some((u, v)), Some((a, b))) = (
            truth,
            third
                .intrinsics
                .project(&third_from_depth.transform_point(&body.keypoints[k])),
        ) {
            kp_true.push(vec![*u, *v]);
            kp_fit.push(vec![a, b]);
        }
    }
    let truth_mask = &sim.reflection_mask;
    let inter = truth_mask
        .data
        .iter()
        .zip(mask)
        .filter(|(a, b)| **a && **b)
        .count();
    let union = truth_mask
        .data
        .iter()
        .zip(mask)
        .filter(|(a, b)| **a || **b)
        .count();
    let (mut t_err, mut s_err) = (Vec::new(), Vec::new());
    for (o, p) in objects.objects.iter().zip(&sim.object_poses) {
        t_err.push((o.depth_from_object.translation - p.translation).norm());
        s_err.push((o.depth_from_object.scale / p.scale - 1.0).abs() * 100.0);
    }
    let joints = |j: &[Vector3<f64>]| j.iter().map(v3).collect::<Vec<_>>();
    Ok(Evaluation {
        root_error_m: (body.joints[0] - sim.body.joints[0]).norm(),
        person_distance_m: sim.body.joints[0].norm(),
        keypoints_2d_normalised: normalised_distance(&kp_fit, &kp_true),
        keypoints_3d_normalised: normalised_distance(
            &joints(&body.keypoints),
            &joints(&sim.body.keypoints),
        ),
        mpjpe_m: mpjpe(&joints(&body.joints), &joints(&sim.body.joints)),
        vertex_error_m: vertex_error(&body.vertices, &sim.body.mesh.vertices),
        facing_error_deg: facing_error_deg(&body.keypoints, &sim.body.keypoints),
        pa_mpjpe_m: pa_mpjpe(&joints(&body.joints), &joints(&sim.body.joints)),
        reflection_iou: inter as f64 / union.max(1) as f64,
        object_translation_error_m: t_err,
        object_scale_error_pct: s_err,
    })
}

/// Mean per-vertex distance between a fitted mesh and the true one (same topology), m.
pub fn vertex_error(fitted: &[Vector3<f64>], truth: &[[f32; 3]]) -> Option<f64> {
    (fitted.len() == truth.len() && !fitted.is_empty()).then(|| {
        fitted
            .iter()
            .zip(truth)
            .map(|(a, b)| (a - Vector3::from(b.map(f64::from))).norm())
            .sum::<f64>()
            / fitted.len() as f64
    })
}

/// COCO-17 keypoint indices: left and right shoulder, left and right hip.
const SHOULDERS_HIPS: [usize; 4] = [5, 6, 11, 12];

/// The body's up (hips → shoulders) and facing (across the shoulders and hips × up) from its
/// COCO keypoints; `None` when degenerate.
fn up_and_facing(kp: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let [ls, rs, lh, rh] = SHOULDERS_HIPS.map(|i| kp.get(i).copied());
    let (ls, rs, lh, rh) = (ls?, rs?, lh?, rh?);
    let up = ((ls + rs) - (lh + rh)).try_normalize(1e-9)?;
    let across = (ls - rs) + (lh - rh);
    let facing = across.cross(&up).try_normalize(1e-9)?;
    Some((up, facing))
}

/// Angle between the fitted and true facing directions, both projected onto the plane normal to
/// the true body's up, degrees.
pub fn facing_error_deg(fitted_kp: &[Vector3<f64>], true_kp: &[Vector3<f64>]) -> Option<f64> {
    let (up, f_true) = up_and_facing(true_kp)?;
    let (_, f_fit) = up_and_facing(fitted_kp)?;
    let flat = |f: Vector3<f64>| (f - up * up.dot(&f)).try_normalize(1e-9);
    let (a, b) = (flat(f_fit)?, flat(f_true)?);
    Some(a.dot(&b).clamp(-1.0, 1.0).acos().to_degrees())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A skeleton's four torso keypoints, facing +X with up +Z, turned by `yaw` about Z.
    fn torso(yaw: f64) -> Vec<Vector3<f64>> {
        let r = irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::new(0.0, 0.0, yaw));
        let mut kp = vec![Vector3::zeros(); 17];
        // Left is +Y for a body facing +X with up +Z (left = up × facing).
        kp[5] = r * Vector3::new(0.0, 0.2, 1.5);
        kp[6] = r * Vector3::new(0.0, -0.2, 1.5);
        kp[11] = r * Vector3::new(0.0, 0.1, 1.0);
        kp[12] = r * Vector3::new(0.0, -0.1, 1.0);
        kp
    }

    #[test]
    fn facing_error_is_the_yaw_between_bodies() {
        for yaw_deg in [0.0f64, 30.0, 90.0, 150.0, 180.0] {
            let e = facing_error_deg(&torso(yaw_deg.to_radians()), &torso(0.0)).unwrap();
            assert!((e - yaw_deg).abs() < 1e-9, "{yaw_deg}: {e}");
        }
        assert!(facing_error_deg(&vec![Vector3::zeros(); 17], &torso(0.0)).is_none());
    }

    #[test]
    fn vertex_error_is_the_mean_distance() {
        let fitted = [Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 3.0, 0.0)];
        let truth = [[0.0f32, 0.0, 0.0], [0.0, 0.0, 0.0]];
        assert_eq!(vertex_error(&fitted, &truth), Some(2.0));
        assert_eq!(vertex_error(&fitted, &truth[..1]), None);
    }
}
