//! `irmirror body check`: compares the model against reference vectors made with the real
//! `anny` package in float64 (`assets/body/test_vectors_body36.json`).

use crate::{BodyError, BodyModel, Phenotype, Pose};
use nalgebra::Vector3;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Deserialize)]
struct VectorsFile {
    bone_names: Vec<String>,
    parents: Vec<i32>,
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    phenotype: BTreeMap<String, f64>,
    rotvec: Vec<[f64; 3]>,
    translation: [f64; 3],
    rest_joint_heads: Vec<[f64; 3]>,
    rest_frames: Vec<[[f64; 3]; 3]>,
    rest_height: f64,
    posed_joint_positions: Vec<[f64; 3]>,
    vertex_indices: Vec<usize>,
    posed_vertices: Vec<[f64; 3]>,
    coco: Vec<[f64; 3]>,
}

/// Maximum absolute errors of one case, metres (frames: max entry difference).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CaseErrors {
    /// Rest joint positions.
    pub rest_joints_m: f64,
    /// Rest Blender frames (unitless).
    pub rest_frames: f64,
    /// Rest body height.
    pub rest_height_m: f64,
    /// Posed joints.
    pub posed_joints_m: f64,
    /// Posed sample vertices.
    pub posed_vertices_m: f64,
    /// Posed keypoints.
    pub keypoints_m: f64,
}

impl CaseErrors {
    /// The largest of the metric errors.
    pub fn max_m(&self) -> f64 {
        self.rest_joints_m
            .max(self.rest_height_m)
            .max(self.posed_joints_m)
            .max(self.posed_vertices_m)
            .max(self.keypoints_m)
    }
}

/// The outcome of one case.
#[derive(Clone, Debug, serde::Serialize)]
pub enum CaseOutcome {
    /// Compared.
    Checked(CaseErrors),
    /// Not comparable with this asset (e.g. a child phenotype against the adult asset).
    Skipped(String),
}

/// Checks every case; fails only on unreadable vectors or a rig mismatch.
pub fn check_vectors(model: &BodyModel, path: &Path) -> Result<Vec<CaseOutcome>, BodyError> {
    let bad = |r: String| BodyError::Vectors {
        path: path.into(),
        reason: r,
    };
    let text = std::fs::read_to_string(path).map_err(|e| BodyError::Io {
        path: path.into(),
        source: e,
    })?;
    let file: VectorsFile = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    if file.bone_names != model.asset.meta.bone_names || file.parents != model.asset.parents {
        return Err(bad(
            "bone names or parents differ from the asset's rig".into()
        ));
    }
    let mut out = Vec::new();
    for (i, case) in file.cases.iter().enumerate() {
        // Anny's defaults are 0.5 for every phenotype value.
        let get = |k: &str| case.phenotype.get(k).copied().unwrap_or(0.5);
        let ph = Phenotype::from_values(
            ["gender", "age", "muscle", "weight", "height", "proportions"].map(get),
        );
        if let Err(e) = ph.validate(&model.asset) {
            out.push(CaseOutcome::Skipped(e.to_string()));
            continue;
        }
        let j = model.n_joints();
        if case.rotvec.len() != j
            || case.rest_joint_heads.len() != j
            || case.vertex_indices.len() != case.posed_vertices.len()
        {
            return Err(bad(format!("case {i}: array lengths do not match the rig")));
        }
        let shaped = model.shaped_phenotype::<f64>(&ph)?;
        let pose = Pose::from_axis_angles(&case.rotvec, Vector3::from(case.translation));
        let posed = model.pose(&shaped, &pose)?;
        let maxdist = |a: &[Vector3<f64>], b: &[[f64; 3]]| {
            a.iter()
                .zip(b)
                .map(|(p, q)| (p - Vector3::from(*q)).norm())
                .fold(0.0, f64::max)
        };
        let frames = model.rest_frames(&shaped);
        let (zmin, zmax) = shaped
            .vertices
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), v| {
                (lo.min(v.z), hi.max(v.z))
            });
        let sample: Vec<Vector3<f64>> = case
            .vertex_indices
            .iter()
            .map(|&v| {
                posed
                    .vertices
                    .get(v)
                    .copied()
                    .ok_or_else(|| bad(format!("case {i}: vertex {v} out of range")))
            })
            .collect::<Result<_, _>>()?;
        out.push(CaseOutcome::Checked(CaseErrors {
            rest_joints_m: maxdist(&shaped.joint_heads, &case.rest_joint_heads),
            rest_frames: frames
                .iter()
                .zip(&case.rest_frames)
                .map(|(r, q)| {
                    (0..9)
                        .map(|k| (r[(k / 3, k % 3)] - q[k / 3][k % 3]).abs())
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max),
            rest_height_m: ((zmax - zmin) - case.rest_height).abs(),
            posed_joints_m: maxdist(&posed.joints, &case.posed_joint_positions),
            posed_vertices_m: maxdist(&sample, &case.posed_vertices),
            keypoints_m: maxdist(&posed.keypoints, &case.coco),
        }));
    }
    Ok(out)
}
