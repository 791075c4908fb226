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
        pa_mpjpe_m: pa_mpjpe(&joints(&body.joints), &joints(&sim.body.joints)),
        reflection_iou: inter as f64 / union.max(1) as f64,
        object_translation_error_m: t_err,
        object_scale_error_pct: s_err,
    })
}
