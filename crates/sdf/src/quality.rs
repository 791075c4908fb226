//! Quality figures of a prior (issue 4, DeepSDF's protocol): Chamfer distance after latent
//! inference, the eikonal error near the surface, evaluation throughput; and mesh extraction.

use crate::SdfError;
use crate::infer::InferConfig;
use crate::mesh_sdf::MeshSdf;
use crate::net::{LatentSdf, SdfNet};
use irmirror_geom::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// The zero level set of latent `z` as a mesh (marching tetrahedra over [−1, 1]³, `resolution`
/// cells per axis, batched network evaluation; normals outward).
pub fn extract_mesh(net: &SdfNet, z: &[f64], resolution: usize) -> Result<TriMesh, SdfError> {
    let (lo, hi) = (Vector3::repeat(-1.0), Vector3::repeat(1.0));
    let values = net.eval_batch(
        z,
        &irmirror_geom::isosurface::grid_points(lo, hi, resolution),
    )?;
    Ok(irmirror_geom::isosurface::isosurface_grid(
        &values, lo, hi, resolution,
    ))
}

/// Pieces of an extracted mesh smaller than this fraction of the largest piece's volume are
/// dropped as spurious ([`TriMesh::main_components`]). The mug prior's handles often come out
/// cut off from the cup at a junction thinner than a cell: 1.6–5.5 % of the cup's volume on six
/// held-out mugs (whose meshes had no other piece).
pub const MAIN_PART_FRACTION: f64 = 0.005;

/// Held-out figures of a prior.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HeldOutFigures {
    /// Held-out procedural shapes.
    pub shapes: usize,
    /// SDF samples per shape given to latent inference.
    pub samples: usize,
    /// Chamfer ×10³ (see [`chamfer`]), mean over shapes.
    pub chamfer_x1e3_mean: f64,
    /// Chamfer ×10³, median.
    pub chamfer_x1e3_median: f64,
    /// Mean `| |∇f| − 1 |` at samples within 0.05 of the surface.
    pub eikonal_error: f64,
    /// Largest bounding-box face offset between the fitted and the true mesh (unit-sphere units),
    /// mean over shapes: Chamfer barely sees a thin part (a mug's handle) drawn short; this does.
    #[serde(default)]
    pub bbox_error_mean: f64,
    /// Clamped L1 of the inferred latent on its samples.
    pub inference_l1: f64,
    /// Seconds per shape for latent inference.
    pub inference_s: f64,
    /// Single-point value + gradient evaluations per second on all cores ([`LatentSdf`]).
    pub points_per_s: f64,
    /// Batched value evaluations per second ([`SdfNet::eval_batch`]; candle until session 49).
    pub batched_points_per_s: f64,
}

/// Evaluates `net` on `n` held-out procedural shapes (stream 2 of `seed`; training uses
/// stream 1): latent inference from `samples` SDF samples, mesh extraction, Chamfer to the true
/// mesh (30k points each way), eikonal error, throughput.
pub fn held_out(
    net: &Arc<SdfNet>,
    n: usize,
    samples: usize,
    seed: u64,
    cfg: &InferConfig,
    mut progress: impl FnMut(usize),
) -> Result<HeldOutFigures, SdfError> {
    let truth = crate::train::procedural(net.category, n, seed, 2, 112)?;
    let (mut ch, mut eik, mut l1, mut t_inf, mut bbox) = (Vec::new(), 0.0, 0.0, 0.0, 0.0);
    let (mut pps, mut bpps) = (0.0, 0.0);
    for (k, (_, mesh)) in truth.iter().enumerate() {
        let s = MeshSdf::new(mesh).samples(
            samples,
            &mut irmirror_geom::rng::seeded(seed, 5000 + k as u64),
        );
        let t0 = Instant::now();
        let inf = crate::infer::from_samples(net, &s, cfg)?;
        t_inf += t0.elapsed().as_secs_f64();
        l1 += inf.loss;
        let shape = net.shape(&inf.latent)?;
        let near: Vec<[f32; 3]> = s
            .points
            .iter()
            .zip(&s.sdf)
            .filter(|(_, d)| d.abs() < 0.05)
            .map(|(p, _)| *p)
            .collect();
        let t0 = Instant::now();
        eik += eikonal_error(&shape, &near);
        pps += near.len() as f64 / t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let fitted = extract_mesh(net, &inf.latent, 96)?;
        bpps += 97f64.powi(3) / t0.elapsed().as_secs_f64();
        ch.push(1e3 * chamfer(&fitted, mesh, 30_000, seed));
        bbox += bbox_error(&fitted.main_components(MAIN_PART_FRACTION), mesh);
        progress(k + 1);
    }
    let nf = n.max(1) as f64;
    let mut sorted = ch.clone();
    sorted.sort_by(f64::total_cmp);
    Ok(HeldOutFigures {
        shapes: n,
        samples,
        chamfer_x1e3_mean: ch.iter().sum::<f64>() / nf,
        chamfer_x1e3_median: sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN),
        eikonal_error: eik / nf,
        bbox_error_mean: bbox / nf,
        inference_l1: l1 / nf,
        inference_s: t_inf / nf,
        points_per_s: pps / nf,
        batched_points_per_s: bpps / nf,
    })
}

/// Chamfer distance as DeepSDF reports it, but averaged: the mean of both directions' mean
/// squared distances, from `n` area-uniform surface samples of one mesh to the other mesh's
/// surface (point-to-surface, not point-to-point: no sample-density bias). Infinite when a mesh
/// is empty.
pub fn chamfer(a: &TriMesh, b: &TriMesh, n: usize, seed: u64) -> f64 {
    if a.triangles.is_empty() || b.triangles.is_empty() {
        return f64::INFINITY;
    }
    let (sa, sb) = (MeshSdf::new(a), MeshSdf::new(b));
    let one_way = |from: &MeshSdf, to: &MeshSdf, stream: u64| {
        let mut rng = irmirror_geom::rng::seeded(seed, stream);
        let pts: Vec<Vector3<f64>> = (0..n).map(|_| from.surface_point(&mut rng)).collect();
        pts.par_iter()
            .map(|p| to.unsigned_distance(p).powi(2))
            .sum::<f64>()
            / n as f64
    };
    0.5 * (one_way(&sa, &sb, 1) + one_way(&sb, &sa, 2))
}

/// The largest of the six bounding-box face offsets between `a` and `b`; infinite when either is
/// empty.
pub fn bbox_error(a: &TriMesh, b: &TriMesh) -> f64 {
    match (a.bounds(), b.bounds()) {
        (Some((alo, ahi)), Some((blo, bhi))) => (0..3)
            .map(|k| f64::from((alo[k] - blo[k]).abs().max((ahi[k] - bhi[k]).abs())))
            .fold(0.0, f64::max),
        _ => f64::INFINITY,
    }
}

/// Mean `| |∇f| − 1 |` over `points` (e.g. samples within 0.05 of the surface).
pub fn eikonal_error(shape: &LatentSdf, points: &[[f32; 3]]) -> f64 {
    let s: f64 = points
        .par_iter()
        .map(|p| {
            (shape
                .value_grad(&Vector3::new(
                    f64::from(p[0]),
                    f64::from(p[1]),
                    f64::from(p[2]),
                ))
                .1
                .norm()
                - 1.0)
                .abs()
        })
        .sum();
    s / points.len().max(1) as f64
}
