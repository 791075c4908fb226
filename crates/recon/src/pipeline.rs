//! The whole pipeline on one capture: stage 0 → stage 1 → reflected rays → stage 2.

use crate::ReconError;
use crate::human::radiometric::Radiometry;
use crate::human::{Floor, HumanConfig, HumanFit, HumanProblem, HumanState, fit_human};
use crate::objects::{Objects, Stage1Config, reconstruct_objects};
pub use crate::plane::{PLANE_BLOCK_M, PlaneOccluder, SeenPlane};
use crate::preprocess::{PreprocessConfig, Preprocessed, preprocess};
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::{Capture, Image};
use irmirror_geom::{PinholeCamera, Rigid3};
use irmirror_render::reflect::{
    Normals, ReflectedRays, reflect_camera, reflect_camera_at, reflect_footprint,
};
use irmirror_render::sphere_trace::{SurfaceMethod, TraceParams};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// The ablation switches of the paper's Table 1, and ours (`Radiometric`): each changes one
/// step only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Ablation {
    /// Uniform ray draws instead of the edge curriculum.
    EdgeSampling,
    /// Gradient projection of the coarse point instead of K = 3 sphere-tracing steps.
    SphereTracing,
    /// Raw SDF normals instead of the surface smoothing (a 2-mm ring about each hit).
    Smoothing,
    /// The binary mask's soft IoU (the paper's data term) instead of the thermal rise.
    Radiometric,
}

/// All settings of `reconstruct` (the `--config` TOML; every field optional).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReconConfig {
    /// Stage 0.
    pub preprocess: PreprocessConfig,
    /// Stage 1.
    pub objects: Stage1Config,
    /// Reflected rays: sphere tracing.
    pub trace: TraceParams,
    /// Reflected rays: a large object's mirror taken from the depth data where they agree.
    pub mirror: crate::depth_mirror::DepthMirror,
    /// Stage 2.
    pub human: HumanConfig,
    /// Ablations applied.
    pub ablate: Vec<Ablation>,
}

impl ReconConfig {
    /// The trace settings and normals after ablations.
    pub fn rays_settings(&self) -> (TraceParams, Normals) {
        let mut t = self.trace;
        if self.ablate.contains(&Ablation::SphereTracing) {
            t.method = SurfaceMethod::GradientProjection;
        }
        let n = if self.ablate.contains(&Ablation::Smoothing) {
            Normals::Raw
        } else {
            Normals::Smoothed
        };
        (t, n)
    }
    /// The stage-2 settings after ablations.
    pub fn human_settings(&self) -> HumanConfig {
        let mut h = self.human.clone();
        if self.ablate.contains(&Ablation::EdgeSampling) {
            h.edge_sampling = false;
        }
        if self.ablate.contains(&Ablation::Radiometric) {
            h.radiometric.enabled = false;
        }
        h
    }
}

/// Everything the pipeline produced.
pub struct Reconstruction {
    /// Stage 0.
    pub pre: Preprocessed,
    /// Stage 1.
    pub objects: Objects,
    /// Reflected rays of the thermal pixels on the fitted objects (depth frame).
    pub rays: ReflectedRays<f64>,
    /// Stage 2 summary.
    pub human: HumanFit,
    /// Stage-2 states, same order as `human.hypotheses`.
    pub states: Vec<HumanState>,
}

/// Stage reached callbacks (for progress bars).
pub trait Progress: Sync {
    /// A stage starts (`total` work units for the bar, 0 for a spinner).
    fn stage(&self, name: &str, total: u64);
    /// One unit done.
    fn tick(&self);
}

/// Reflected rays that see past every object and the support plane: a ray that hits a fitted
/// object (a bowl's own rim, a neighbouring mug) or the support plane where it is
/// ([`PlaneOccluder::blocks`]) cannot show the person, whatever their pose, so it is left out
/// of the fit (its pixel is neither evidence for nor against a body).
pub fn unblocked(
    rays: &ReflectedRays<f64>,
    objects: &[irmirror_render::sdf::PlacedSdf],
    plane: Option<&PlaneOccluder<'_>>,
    trace: &TraceParams,
) -> ReflectedRays<f64> {
    use rayon::prelude::*;
    let keep: Vec<bool> = (0..rays.len())
        .into_par_iter()
        .map(|i| {
            // Leave the surface by twice the tracer's coarse tolerance (which is relative to the
            // object's size) before testing, or the ray re-finds the point it leaves.
            let own = &objects[rays.object[i] as usize];
            let tol =
                trace.coarse_tol_rel * own.sdf.bounding_radius() * own.depth_from_object.scale;
            let o = rays.origin[i] + rays.normal[i] * (2.0 * tol + 2e-4);
            let ray = irmirror_geom::Ray {
                origin: o,
                dir: rays.dir[i],
            };
            if objects
                .iter()
                .any(|obj| irmirror_render::sphere_trace::trace(obj, &ray, trace).is_some())
            {
                return false;
            }
            !plane.is_some_and(|p| p.blocks(&o, &ray.dir, rays.pixel[i]))
        })
        .collect();
    let kept: Vec<usize> = keep
        .iter()
        .enumerate()
        .filter_map(|(i, k)| k.then_some(i))
        .collect();
    let mut out = ReflectedRays::default();
    rays.select_into(&kept, &mut out);
    out
}

/// The floor the person stands on: the ground under a fitted car, else `table_height_m` below
/// a support plane seen in the depth image; `None` without either (up alone gives no height).
pub fn floor(objects: &Objects, cfg: &HumanConfig) -> Option<Floor> {
    let up = objects.ground.n().normalize();
    let car = objects
        .objects
        .iter()
        .find(|o| matches!(o.shape, irmirror_render::shapes::Shape::Car { .. }));
    if let Some(car) = car {
        let s = &car.depth_from_object;
        let base = s.translation + s.rotation * Vector3::new(0.0, car.base_y(), 0.0) * s.scale;
        return Some(Floor {
            up,
            offset_m: up.dot(&base),
        });
    }
    objects.ground.plane.map(|plane| Floor {
        up,
        offset_m: plane.offset_m - cfg.table_height_m,
    })
}

/// The body model and the pose prior stage 2 fits with.
#[derive(Clone, Copy)]
pub struct BodyPriors<'a> {
    /// The body model.
    pub model: &'a BodyModel,
    /// The pose prior (VAE decoder).
    pub prior: &'a PosePrior,
}

/// Runs stages 0–2.
pub fn reconstruct(
    capture: &Capture,
    priors: BodyPriors<'_>,
    cfg: &ReconConfig,
    seed: u64,
    progress: &dyn Progress,
) -> Result<Reconstruction, ReconError> {
    progress.stage("thermal preprocessing", 0);
    let pre = preprocess(capture, &cfg.preprocess)?;
    progress.stage("object fit", 0);
    let objects = reconstruct_objects(capture, &cfg.objects, seed)?;
    reconstruct_human(capture, pre, objects, priors, cfg, seed, progress)
}

/// The unblocked reflected rays of every thermal pixel on the fitted objects (after ablations),
/// plus, for pixels of the reflection `mask` whose centre misses the fitted objects, a ray through
/// their footprint where one hits (a reflection hugging a mug's silhouette is otherwise lost to
/// a fit that is a fraction of a pixel small: 2 of 4 mug captures had no mask pixel left).
///
/// With the radiometric term on and a reflection mask of at most `footprint_max_mask_px`
/// pixels, every pixel near an object is sampled at a grid of sub-pixel nodes instead (its rays
/// next to each other; see [`footprint_rays`]). With `[mirror] enabled`, large objects' rays
/// are then re-reflected off the depth data where it agrees with the fit
/// ([`crate::depth_mirror`]).
pub fn reflected_rays(
    capture: &Capture,
    objects: &Objects,
    mask: &Image<bool>,
    cfg: &ReconConfig,
) -> ReflectedRays<f64> {
    let placed = objects.placed();
    let mut rays =
        reflected_rays_through(capture, &placed, objects.ground.plane.as_ref(), mask, cfg);
    let scales: Vec<f64> = objects
        .objects
        .iter()
        .map(|o| o.depth_from_object.scale)
        .collect();
    let t0 = std::time::Instant::now();
    let n = crate::depth_mirror::refine(
        &mut rays,
        &capture.depth_m,
        &capture.depth_camera,
        &capture.depth_from_thermal.translation,
        &scales,
        &cfg.mirror,
    );
    if cfg.mirror.enabled {
        tracing::debug!(
            "mirror from the depth data: {n} of {} rays re-reflected in {:.2} s",
            rays.len(),
            t0.elapsed().as_secs_f64()
        );
    }
    rays
}

/// [`reflected_rays`] through any placed objects (the simulator's true shapes, for the
/// benchmark's diagnosis), rays that `plane` blocks where the depth image shows it dropped
/// ([`PlaneOccluder`]).
pub fn reflected_rays_through(
    capture: &Capture,
    placed: &[irmirror_render::sdf::PlacedSdf],
    plane: Option<&crate::plane::Plane>,
    mask: &Image<bool>,
    cfg: &ReconConfig,
) -> ReflectedRays<f64> {
    let (trace, normals) = cfg.rays_settings();
    let hcfg = cfg.human_settings();
    let plane = plane.map(|plane| PlaneOccluder {
        plane,
        seen: Some(SeenPlane {
            depth_m: &capture.depth_m,
            camera: &capture.depth_camera,
            mask,
        }),
    });
    let plane = plane.as_ref();
    let mask_px = mask.data.iter().filter(|&&m| m).count();
    let max_px = hcfg.radiometric.footprint_max_mask_px;
    if hcfg.radiometric.enabled && max_px > 0 && mask_px <= max_px {
        let rays = footprint_rays(
            &capture.thermal_camera,
            &capture.depth_from_thermal,
            placed,
            &trace,
            normals,
            FootprintBudget::new(&hcfg.radiometric, mask_px),
        );
        return unblocked(&rays, placed, plane, &trace);
    }
    let mut all_rays = reflect_camera(
        &capture.thermal_camera,
        &capture.depth_from_thermal,
        placed,
        &trace,
        normals,
    );
    let mut covered = vec![false; mask.data.len()];
    for &p in &all_rays.pixel {
        covered[p as usize] = true;
    }
    let missed: Vec<u32> = (0..mask.data.len() as u32)
        .filter(|&p| mask.data[p as usize] && !covered[p as usize])
        .collect();
    if !missed.is_empty() {
        all_rays.extend(&reflect_footprint(
            &capture.thermal_camera,
            &capture.depth_from_thermal,
            placed,
            &trace,
            &missed,
        ));
    }
    unblocked(&all_rays, placed, plane, &trace)
}

/// Most nodes per axis of a pixel's footprint grid ([`footprint_offsets`]).
pub const FOOTPRINT_MAX_NODES: u32 = 4;

/// How finely [`footprint_rays`] samples each pixel: the finest `n × n` grid, 2 ≤ n ≤
/// `max_nodes`, whose rays fit `max_rays` (2 × 2 when none does).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootprintBudget {
    /// Most nodes per axis (at most [`FOOTPRINT_MAX_NODES`]).
    pub max_nodes: u32,
    /// Most rays over every pixel near an object.
    pub max_rays: usize,
}

impl FootprintBudget {
    /// The budget `cfg` gives a reflection mask of `mask_px` pixels
    /// (`footprint_fine_max_mask_px`, `footprint_max_rays`).
    pub fn new(cfg: &crate::human::radiometric::RadiometricConfig, mask_px: usize) -> Self {
        let max_px = cfg.footprint_fine_max_mask_px;
        let fine = max_px == 0 || mask_px <= max_px;
        Self {
            max_nodes: if fine { FOOTPRINT_MAX_NODES } else { 2 },
            max_rays: cfg.footprint_max_rays,
        }
    }
}

/// Where a pixel's box is sampled, pixels from its centre: the `n × n` midpoint grid
/// (`(i + ½)/n − ½`), x fastest. A reflection's edge crosses a pixel as a step, which a midpoint
/// grid integrates to `1/n²` of the pixel; against a simulator that integrates the box by 8 × 8
/// rays, the truth's data term through the true objects on the hard view's 30-mK captures was
/// 0.068 with 2 × 2 nodes and 0.005 (the noise) with 4 × 4. The optics' point spread is
/// applied to the samples' sums as a convolution (`radiometric`).
pub fn footprint_offsets(n: u32) -> Vec<(f64, f64)> {
    let n = n.max(1);
    let at = |i: u32| (f64::from(i) + 0.5) / f64::from(n) - 0.5;
    (0..n)
        .flat_map(|j| (0..n).map(move |i| (at(i), at(j))))
        .collect()
}

/// Every thermal pixel within reach of an object (a centre ray hits one in its 3 × 3
/// neighbourhood) sampled at the finest [`footprint_offsets`] grid `budget` allows, reflected;
/// a pixel's rays lie next to each other in pixel order, and a node that misses every object
/// has none (it counts as showing the room).
pub fn footprint_rays(
    cam: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    placed: &[irmirror_render::sdf::PlacedSdf],
    trace: &TraceParams,
    normals: Normals,
    budget: FootprintBudget,
) -> ReflectedRays<f64> {
    let centres = reflect_camera(cam, depth_from_camera, placed, trace, normals);
    let (w, h) = (cam.width as i64, cam.height as i64);
    let reach = 1;
    let mut near = vec![false; (w * h) as usize];
    for &p in &centres.pixel {
        let (x, y) = (i64::from(p) % w, i64::from(p) / w);
        for ny in (y - reach).max(0)..=(y + reach).min(h - 1) {
            for nx in (x - reach).max(0)..=(x + reach).min(w - 1) {
                near[(ny * w + nx) as usize] = true;
            }
        }
    }
    let reachable = near.iter().filter(|&&n| n).count();
    let nodes = (2..=budget.max_nodes.min(FOOTPRINT_MAX_NODES))
        .rev()
        .find(|&n| (n * n) as usize * reachable <= budget.max_rays)
        .unwrap_or(2);
    let offsets = footprint_offsets(nodes);
    let mut all = ReflectedRays {
        width: cam.width,
        height: cam.height,
        ..Default::default()
    };
    for &offset in &offsets {
        all.extend(&reflect_camera_at(
            cam,
            depth_from_camera,
            placed,
            trace,
            normals,
            offset,
            Some(&near),
        ));
    }
    // Pixel order, each pixel's nodes in offset order (a stable sort).
    let mut order: Vec<usize> = (0..all.len()).collect();
    order.sort_by_key(|&i| all.pixel[i]);
    let mut out = ReflectedRays::default();
    all.select_into(&order, &mut out);
    out.footprint = offsets.len() as u32;
    out
}

/// Stage 2's problem: the person seen through `rays`, the objects' centre (the person faces it,
/// roughly), the support plane's up and the floor.
pub fn human_problem<'a>(
    priors: BodyPriors<'a>,
    rays: &'a ReflectedRays<f64>,
    mask: &'a Image<bool>,
    objects: &Objects,
    hcfg: &HumanConfig,
    radiometry: Option<&'a Radiometry>,
) -> HumanProblem<'a> {
    let placed = objects.placed();
    let centre = placed
        .iter()
        .fold(Vector3::zeros(), |a, o| a + o.depth_from_object.translation)
        / placed.len().max(1) as f64;
    HumanProblem {
        model: priors.model,
        prior: priors.prior,
        rays,
        mask,
        up: objects.ground.n(),
        objects_centre: centre,
        // People at a table face it; pedestrians pass a car any way.
        faces_objects: !objects
            .objects
            .iter()
            .any(|o| o.category == irmirror_geom::category::Category::Car),
        floor: floor(objects, hcfg),
        radiometry,
        build: hcfg.build,
    }
}

/// The radiometric observations stage 2 fits, and the data term in words for the record:
/// `None` when the term is ablated or the capture cannot give it (no background frames: the
/// room's temperature is unknown), which is logged and recorded, never silent.
pub fn radiometry(
    pre: &Preprocessed,
    rays: &ReflectedRays<f64>,
    model: &irmirror_body::BodyModel,
    hcfg: &HumanConfig,
) -> Result<(Option<Radiometry>, String), ReconError> {
    if !hcfg.radiometric.enabled {
        return Ok((None, "mask".into()));
    }
    if let Some(t) = hcfg.radiometric.region_temperatures_c
        && t.iter().any(|x| !(-40.0..=80.0).contains(x))
    {
        return Err(ReconError::Config(format!(
            "[human.radiometric] region_temperatures_c = {t:?}: each must be a surface temperature in °C within −40…80"
        )));
    }
    match Radiometry::new(pre, rays, model) {
        Ok(r) => Ok((
            Some(match hcfg.radiometric.region_temperatures_c {
                Some(t) => r.centred_at(t),
                None => r,
            }),
            "radiometric".into(),
        )),
        Err(ReconError::Config(why)) => {
            tracing::warn!("stage 2 fits the binary mask: {why}");
            Ok((None, format!("mask (fallback: {why})")))
        }
        Err(e) => Err(e),
    }
}

/// The thermal rise (K) the radiometric model predicts for the best hypothesis, per thermal
/// pixel (0 off the rays), for the report; `None` when stage 2 fitted the mask.
pub fn predicted_rise(
    rec: &Reconstruction,
    priors: BodyPriors<'_>,
    cfg: &ReconConfig,
) -> Result<Option<Image<f64>>, ReconError> {
    let hcfg = cfg.human_settings();
    let (Some(st), (Some(rad), _)) = (
        rec.states.first(),
        radiometry(&rec.pre, &rec.rays, priors.model, &hcfg)?,
    ) else {
        return Ok(None);
    };
    let problem = human_problem(
        priors,
        &rec.rays,
        &rec.pre.mask,
        &rec.objects,
        &hcfg,
        Some(&rad),
    );
    let Some(per_pixel) = problem.predicted_rise(st, &hcfg)? else {
        return Ok(None);
    };
    let (w, h) = (rec.pre.rise_k.width, rec.pre.rise_k.height);
    let mut img = Image::filled(w, h, 0.0);
    for (p, y) in per_pixel {
        img.data[p as usize] = y;
    }
    Ok(Some(img))
}

/// Stage 2 (reflected rays, then the person) on given stage 0–1 results: the evaluation runs
/// the ablations of one capture from the same objects.
pub fn reconstruct_human(
    capture: &Capture,
    pre: Preprocessed,
    objects: Objects,
    priors: BodyPriors<'_>,
    cfg: &ReconConfig,
    seed: u64,
    progress: &dyn Progress,
) -> Result<Reconstruction, ReconError> {
    progress.stage("reflected rays", 0);
    cfg.mirror.check()?;
    let rays = reflected_rays(capture, &objects, &pre.mask, cfg);
    let hcfg = cfg.human_settings();
    let (rad, data_term) = radiometry(&pre, &rays, priors.model, &hcfg)?;
    let problem = human_problem(priors, &rays, &pre.mask, &objects, &hcfg, rad.as_ref());
    let passes = 1 + usize::from(problem.rise_pass(&hcfg).is_some());
    progress.stage("human fit", (passes * hcfg.inits) as u64);
    let (mut human, states) = fit_human(&problem, &hcfg, seed, &|_| progress.tick())?;
    human.data_term = data_term;
    Ok(Reconstruction {
        pre,
        objects,
        rays,
        human,
        states,
    })
}

#[cfg(test)]
mod tests {
    use super::{FOOTPRINT_MAX_NODES, FootprintBudget, footprint_offsets};

    /// Grids finer than 2 × 2 only on a reflection of at most `footprint_fine_max_mask_px`
    /// (0: on any).
    #[test]
    fn footprint_budget_is_fine_on_small_reflections_only() {
        let mut cfg = crate::human::radiometric::RadiometricConfig {
            footprint_fine_max_mask_px: 0,
            ..Default::default()
        };
        let at = |cfg: &_, px| FootprintBudget::new(cfg, px).max_nodes;
        assert_eq!(at(&cfg, 100_000), FOOTPRINT_MAX_NODES);
        cfg.footprint_fine_max_mask_px = 50;
        assert_eq!(at(&cfg, 50), FOOTPRINT_MAX_NODES);
        assert_eq!(at(&cfg, 51), 2);
        assert_eq!(
            FootprintBudget::new(&cfg, 0).max_rays,
            cfg.footprint_max_rays
        );
    }

    /// The midpoint grid: n² nodes inside the box, centred, and a step edge at any multiple of
    /// 1/n covers exactly its share of them (what a half-covered pixel's rise relies on).
    #[test]
    fn footprint_grid_is_centred_and_integrates_edges_on_its_lattice() {
        for n in 1..=4u32 {
            let nodes = footprint_offsets(n);
            assert_eq!(nodes.len(), (n * n) as usize);
            let (sx, sy) = nodes
                .iter()
                .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
            assert!(
                sx.abs() < 1e-12 && sy.abs() < 1e-12,
                "n {n}: mean ({sx}, {sy})"
            );
            assert!(nodes.iter().all(|(x, y)| x.abs() < 0.5 && y.abs() < 0.5));
            for k in 0..=n {
                let edge = f64::from(k) / f64::from(n) - 0.5;
                let share =
                    nodes.iter().filter(|(x, _)| *x < edge).count() as f64 / nodes.len() as f64;
                let rows =
                    nodes.iter().filter(|(_, y)| *y < edge).count() as f64 / nodes.len() as f64;
                assert_eq!(share, f64::from(k) / f64::from(n), "n {n}, edge {edge}");
                assert_eq!(rows, share, "n {n}: the grid is square");
            }
        }
    }
}
