//! Figures of one reconstructed body against the simulator's truth (DESIGN.md §5): what `demo`,
//! `eval` and the benchmark report.

use crate::EvalError;
use crate::metrics::{mpjpe, normalised_distance, pa_mpjpe};
use crate::truth::Truth;
use crate::views::{Drawn, render_view};
use irmirror_body::{BodyModel, PosedBody};
use irmirror_geom::Similarity3;
use irmirror_recon::objects::Objects;
use irmirror_render::ReflectedRays;
use irmirror_render::hard::hard_mask;
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

/// One figure of an [`Evaluation`] in words: its name, its value with units, and what to
/// compare it with.
#[derive(Clone, Debug, PartialEq)]
pub struct FigureRow {
    /// What is measured.
    pub name: &'static str,
    /// The value, with units.
    pub value: String,
    /// What to compare it with (the paper, the Random baseline, our benchmark).
    pub yardstick: &'static str,
}

impl Evaluation {
    /// The figures in words, in a fixed order, each with its yardstick. The benchmark medians
    /// quoted are the README's held-out `irmirror eval --preset full` (24 captures a cell, the
    /// hard view 60; 2026-12-07, session 86).
    pub fn rows(&self) -> Vec<FigureRow> {
        let opt = |x: Option<f64>, unit: &str, digits: usize| {
            x.map_or("n/a".to_string(), |v| format!("{v:.digits$}{unit}"))
        };
        let list = |xs: &[f64], k: f64, unit: &str| {
            if xs.is_empty() {
                "none".to_string()
            } else {
                xs.iter()
                    .map(|x| format!("{:.1}", x * k))
                    .collect::<Vec<_>>()
                    .join(", ")
                    + unit
            }
        };
        vec![
            FigureRow {
                name: "root (pelvis) position error",
                value: format!(
                    "{:.3} m ({:.1} % of the person's {:.2} m from the camera)",
                    self.root_error_m,
                    100.0 * self.root_error_m / self.person_distance_m.max(1e-9),
                    self.person_distance_m
                ),
                yardstick: "goal ≤ 0.10 m tabletop, ≤ 5 % car; benchmark median 0.15 m bowls, 0.15 m mugs, 0.16 m car, 0.14 m wide",
            },
            FigureRow {
                name: "2-D keypoints, evaluation camera (normalised)",
                value: opt(self.keypoints_2d_normalised, "", 3),
                yardstick: "paper Table 1, real captures: 0.116 bowl, 0.094 mug (random HumanEva pose 0.35–0.37); our random pose at the true root ≈ 0.26",
            },
            FigureRow {
                name: "3-D keypoints (normalised)",
                value: opt(self.keypoints_3d_normalised, "", 3),
                yardstick: "paper Table 1 (3-D skeleton): 0.152 bowl, 0.126 mug (random 0.32)",
            },
            FigureRow {
                name: "MPJPE",
                value: opt(self.mpjpe_m, " m", 3),
                yardstick: "mean joint distance, root error included",
            },
            FigureRow {
                name: "PA-MPJPE",
                value: opt(self.pa_mpjpe_m, " m", 3),
                yardstick: "after similarity alignment: pose alone",
            },
            FigureRow {
                name: "mean per-vertex error",
                value: opt(self.vertex_error_m, " m", 3),
                yardstick: "goal ≤ 0.12 m; random pose at the true root and facing ≈ 0.26 m; benchmark median 0.35 bowls, 0.51 mugs, 0.30 car, 0.26 wide",
            },
            FigureRow {
                name: "facing error",
                value: opt(self.facing_error_deg, "°", 0),
                yardstick: "≤ 30° counts as facing right; 180° = turned around",
            },
            FigureRow {
                name: "reflection IoU (fitted vs true mask)",
                value: format!("{:.2}", self.reflection_iou),
                yardstick: "1 = the fitted body reflects on exactly the true pixels",
            },
            FigureRow {
                name: "object translation error",
                value: list(&self.object_translation_error_m, 1e3, " mm"),
                yardstick: "goal ≤ 5 mm bowls and mugs, ≤ 10 mm car",
            },
            FigureRow {
                name: "object scale error",
                value: list(&self.object_scale_error_pct, 1.0, " %"),
                yardstick: "goal ≤ 3 %",
            },
        ]
    }

    /// [`Self::rows`] as an aligned plain-text table.
    pub fn text_table(&self) -> String {
        let rows = self.rows();
        let w0 = rows
            .iter()
            .map(|r| r.name.chars().count())
            .max()
            .unwrap_or(0);
        let w1 = rows
            .iter()
            .map(|r| r.value.chars().count())
            .max()
            .unwrap_or(0);
        let pad = |s: &str, w: usize| format!("{s}{}", " ".repeat(w - s.chars().count()));
        rows.iter()
            .map(|r| {
                format!(
                    "{}  {}  {}\n",
                    pad(r.name, w0),
                    pad(&r.value, w1),
                    r.yardstick
                )
            })
            .collect()
    }
}

/// The figures of one reported hypothesis (any of them, not only the best).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HypothesisScore {
    /// Its stage-2 loss.
    pub loss: f64,
    /// Root error, m.
    pub root_error_m: f64,
    /// Facing error, degrees.
    pub facing_error_deg: Option<f64>,
    /// Mean per-vertex error, m.
    pub vertex_error_m: Option<f64>,
}

/// A result scored against the truth: every figure of the best hypothesis, and the root, facing
/// and per-vertex errors of every reported one (`eval.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scored {
    /// The best hypothesis (the first reported).
    pub best: Evaluation,
    /// Every reported hypothesis, in the result's order.
    pub hypotheses: Vec<HypothesisScore>,
}

/// Scores the reported hypotheses (`(loss, body)`, best first), the best one's reflection
/// `mask` and the fitted objects' placements against `truth`.
pub fn score(
    truth: &Truth,
    hypotheses: &[(f64, PosedBody<f64>)],
    mask: &[bool],
    objects: &[Similarity3<f64>],
) -> Result<Scored, EvalError> {
    let (_, best) = hypotheses
        .first()
        .ok_or_else(|| EvalError::Selection("the result has no hypothesis".into()))?;
    let best = evaluate(truth, best, mask, objects)?;
    let hypotheses = hypotheses
        .iter()
        .map(|(loss, b)| HypothesisScore {
            loss: *loss,
            root_error_m: (b.joints[0] - truth.joints[0]).norm(),
            facing_error_deg: facing_error_deg(&b.keypoints, &truth.keypoints),
            vertex_error_m: vertex_error(&b.vertices, &truth.mesh.vertices),
        })
        .collect();
    Ok(Scored { best, hypotheses })
}

impl Scored {
    /// The best hypothesis' table, then one line per hypothesis.
    pub fn text(&self) -> String {
        let mut s = self.best.text_table();
        s += "hypotheses (best first, as ranked): loss, root error, facing error, per-vertex error\n";
        for (k, h) in self.hypotheses.iter().enumerate() {
            s += &format!(
                "  #{k}: {:.3}, {:.3} m, {}, {}\n",
                h.loss,
                h.root_error_m,
                h.facing_error_deg
                    .map_or("n/a".into(), |v| format!("{v:.0}°")),
                h.vertex_error_m
                    .map_or("n/a".into(), |v| format!("{v:.3} m")),
            );
        }
        s
    }
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

/// The evaluation camera's view: fitted body (orange), true body (green), fitted objects.
pub fn third_view(
    truth: &Truth,
    model: &BodyModel,
    body: &PosedBody<f64>,
    objects: &Objects,
) -> image::RgbImage {
    let true_vertices = truth.vertices();
    render_view(
        &truth.third.intrinsics,
        &truth.third.depth_from_camera,
        &[
            Drawn {
                vertices: &body.vertices,
                triangles: &model.asset.faces,
                colour: [240, 150, 60],
            },
            Drawn {
                vertices: &true_vertices,
                triangles: &truth.mesh.triangles,
                colour: [80, 200, 90],
            },
        ],
        &objects.placed(),
    )
}

/// The placements of fitted objects, in their order.
pub fn object_poses(objects: &Objects) -> Vec<Similarity3<f64>> {
    objects
        .objects
        .iter()
        .map(|o| o.depth_from_object)
        .collect()
}

/// Evaluates `body` (with its reflection `mask`, thermal pixels row-major) and the fitted
/// objects' placements (`objects`, capture order) against `truth`.
pub fn evaluate(
    truth: &Truth,
    body: &PosedBody<f64>,
    mask: &[bool],
    objects: &[Similarity3<f64>],
) -> Result<Evaluation, EvalError> {
    let truth_mask = &truth.reflection_mask;
    if truth_mask.data.len() != mask.len() {
        return Err(EvalError::Selection(format!(
            "the fitted reflection mask has {} pixels, the true one {}×{}: not a result of this capture",
            mask.len(),
            truth_mask.width,
            truth_mask.height
        )));
    }
    if objects.len() != truth.object_poses.len() {
        return Err(EvalError::Selection(format!(
            "{} fitted objects, the capture has {}: not a result of this capture",
            objects.len(),
            truth.object_poses.len()
        )));
    }
    let third = &truth.third;
    let third_from_depth = third.depth_from_camera.inverse();
    let v3 = |p: &Vector3<f64>| vec![p.x, p.y, p.z];
    let (mut kp_fit, mut kp_true) = (Vec::new(), Vec::new());
    for (k, t) in third.keypoints_px.iter().enumerate() {
        if let (Some((u, v)), Some((a, b))) = (
            t,
            third
                .intrinsics
                .project(&third_from_depth.transform_point(&body.keypoints[k])),
        ) {
            kp_true.push(vec![*u, *v]);
            kp_fit.push(vec![a, b]);
        }
    }
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
    for (o, p) in objects.iter().zip(&truth.object_poses) {
        t_err.push((o.translation - p.translation).norm());
        s_err.push((o.scale / p.scale - 1.0).abs() * 100.0);
    }
    let joints = |j: &[Vector3<f64>]| j.iter().map(v3).collect::<Vec<_>>();
    Ok(Evaluation {
        root_error_m: (body.joints[0] - truth.joints[0]).norm(),
        person_distance_m: truth.joints[0].norm(),
        keypoints_2d_normalised: normalised_distance(&kp_fit, &kp_true),
        keypoints_3d_normalised: normalised_distance(
            &joints(&body.keypoints),
            &joints(&truth.keypoints),
        ),
        mpjpe_m: mpjpe(&joints(&body.joints), &joints(&truth.joints)),
        vertex_error_m: vertex_error(&body.vertices, &truth.mesh.vertices),
        facing_error_deg: facing_error_deg(&body.keypoints, &truth.keypoints),
        pa_mpjpe_m: pa_mpjpe(&joints(&body.joints), &joints(&truth.joints)),
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
