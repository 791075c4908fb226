//! Running the benchmark: simulate each capture, stage 0–1 once, stage 2 per variant, the
//! Random baseline and the diagnosis, then the report files.

use super::basin::BasinProbe;
use super::diagnosis::{ceiling, diagnose};
use super::table::{html, markdown_table};
use super::{
    BenchProgress, CaptureResult, Planned, RANDOM_DRAWS, Report, Selection, Set, Variant,
    VariantResult, selected,
};
use crate::EvalError;
use crate::output::{Staging, save_png, write_text};
use crate::score::{Evaluation, evaluate, fitted_mask, object_poses, third_view};
use crate::truth::Truth;
use crate::views::{object_mesh, overlay};
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::Capture;
use irmirror_recon::human::HumanState;
use irmirror_recon::human::posed_body;
use irmirror_recon::objects::{Objects, reconstruct_objects};
use irmirror_recon::pipeline::{BodyPriors, ReconConfig, reconstruct_human};
use irmirror_recon::{Preprocessed, ReconError, preprocess};
use irmirror_sim::presets::{Cell, Shapes, benchmark_scene};
use irmirror_sim::scene::ObjectShape;
use irmirror_sim::{SceneFile, Simulation};
use nalgebra::Vector3;
use rand_distr::{Distribution, StandardNormal};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

struct Silent;
impl irmirror_recon::pipeline::Progress for Silent {
    fn stage(&self, _: &str, _: u64) {}
    fn tick(&self) {}
}

fn chamfer_mm2(a: &irmirror_geom::TriMesh, b: &irmirror_geom::TriMesh) -> f64 {
    irmirror_sdf::quality::chamfer(a, b, 5000, 0) * 1e6
}

/// Everything one capture's runs share.
pub(super) struct Prepared {
    pub(super) scene: SceneFile,
    pub(super) sim: Simulation,
    pub(super) truth: Truth,
    pub(super) capture: Capture,
    pub(super) pre: Preprocessed,
    /// When stage 0 started (stage 0–1 time).
    t0: Instant,
}

/// Runs the benchmark (the `selection` of it) into `out`; returns the report, its Markdown
/// table and the directory written.
pub fn run(
    set: Set,
    out: &Path,
    selection: &Selection,
    progress: &dyn BenchProgress,
) -> Result<(Report, String, PathBuf), EvalError> {
    let list = selected(set, selection)?;
    let model = BodyModel::builtin()?;
    let prior = PosePrior::builtin_f64()?;
    let priors = BodyPriors {
        model: &model,
        prior: &prior,
    };
    let stage = Staging::new(out, "table.md")?;
    // The ablation columns run on the first captures of each cell, the full model and the
    // paper's mask term on every capture (--full-only: the full model alone).
    let variants_of = |plan: &Planned| -> Vec<Variant> {
        let ablate = !selection.full_only && plan.index < set.ablated_per_cell();
        Variant::ALL
            .iter()
            .copied()
            .filter(|v| {
                let asked = selection.variants.contains(v);
                if v.on_request_only() {
                    return asked;
                }
                (*v == Variant::Full || (!selection.full_only && v.on_every_capture()) || ablate)
                    && (selection.variants.is_empty() || asked)
            })
            .collect()
    };
    progress.start(list.iter().map(|p| variants_of(p).len() as u64).sum());
    let scratch = stage.path("scratch");
    let mut results = Vec::new();
    for plan in &list {
        let id = &plan.id;
        progress.capture(id);
        let thumbs = stage.path(&format!("captures/{id}"));
        std::fs::create_dir_all(&thumbs).map_err(|e| EvalError::Output {
            path: thumbs.clone(),
            reason: e.to_string(),
        })?;
        let keep = selection.keep_captures.then(|| thumbs.join("capture"));
        let p = prepare(
            &model,
            plan,
            selection.shapes,
            &scratch,
            keep.as_deref(),
            &selection.config,
        )?;
        results.push(run_capture(
            &p,
            plan,
            priors,
            (
                &variants_of(plan),
                &selection.config,
                selection.basin.as_ref(),
            ),
            &thumbs,
            progress,
        )?);
    }
    std::fs::remove_dir_all(&scratch).ok();
    let report = Report {
        set,
        version: env!("CARGO_PKG_VERSION").into(),
        captures: results,
    };
    let table = markdown_table(&report);
    let ser = |e: &dyn std::fmt::Display| EvalError::Serialise(e.to_string());
    write_text(
        &stage.path("results.json"),
        &serde_json::to_string_pretty(&report).map_err(|e| ser(&e))?,
    )?;
    write_text(&stage.path("table.md"), &table)?;
    write_text(&stage.path("report.html"), &html(&report, &table))?;
    let mut record = serde_json::json!({ "command": "eval", "set": set, "limit": selection.limit.map(|l| l as i64).unwrap_or(-1), "only": selection.only, "cell": selection.cell.map_or("all", Cell::name), "shapes": selection.shapes, "ablated_per_cell": set.ablated_per_cell(), "full_only": selection.full_only, "variants": selection.variants, "keep_captures": selection.keep_captures, "version": env!("CARGO_PKG_VERSION"), "config": selection.config, "random_draws": RANDOM_DRAWS });
    // TOML has no null: the basin probe's settings only when it ran.
    if let Some(b) = &selection.basin {
        record["basin"] = serde_json::json!(b);
    }
    write_text(
        &stage.path("run.toml"),
        &toml::to_string(&record).map_err(|e| ser(&e))?,
    )?;
    let dir = stage.commit()?;
    Ok((report, table, dir))
}

/// Simulates the capture, reads it back through the loader and runs stage 0, drawing again until
/// stage 0 sees the reflection through the sensor noise: the benchmark measures reconstruction
/// from a visible reflection. With `keep`, the capture directory is written there (for
/// `irmirror reconstruct`), else into `scratch` and removed.
fn prepare(
    model: &BodyModel,
    plan: &Planned,
    shapes: Shapes,
    scratch: &Path,
    keep: Option<&Path>,
    cfg: &ReconConfig,
) -> Result<Prepared, EvalError> {
    let (seed, mut first) = (plan.seed, 0);
    loop {
        let (scene, attempt) =
            benchmark_scene(model, plan.cell, shapes, seed, plan.netd_mk, first)?;
        let sim = irmirror_sim::simulate(model, &scene, seed)?;
        let dir = keep.map_or_else(|| scratch.join(&plan.id), Path::to_path_buf);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).ok();
        }
        sim.write(model, &dir, seed)?;
        let capture = Capture::load(&dir)?;
        if keep.is_none() {
            std::fs::remove_dir_all(&dir).ok();
        }
        let t0 = Instant::now();
        match preprocess(&capture, &cfg.preprocess) {
            Ok(pre) => {
                return Ok(Prepared {
                    scene,
                    truth: Truth::from_simulation(&sim)?,
                    sim,
                    capture,
                    pre,
                    t0,
                });
            }
            Err(ReconError::NoReflection { .. }) => first = attempt + 1,
            Err(e) => return Err(e.into()),
        }
    }
}

/// Stage 1 once, stage 2 per variant, and the Random baseline, for one prepared capture.
fn run_capture(
    p: &Prepared,
    plan: &Planned,
    priors: BodyPriors<'_>,
    (variants, base, basin): (&[Variant], &ReconConfig, Option<&BasinProbe>),
    thumbs: &Path,
    progress: &dyn BenchProgress,
) -> Result<CaptureResult, EvalError> {
    let BodyPriors { model, prior } = priors;
    let cfg = base;
    let (id, seed) = (plan.id.as_str(), plan.seed);
    let mut result = CaptureResult {
        id: id.to_string(),
        cell: plan.cell,
        seed,
        netd_mk: plan.netd_mk,
        thermal_width: p.capture.thermal_camera.width,
        reflection_pixels: p.sim.report.reflection_pixels,
        person_distance_m: p.sim.body.joints[0].norm(),
        objects_time_s: 0.0,
        object_chamfer_mm2: vec![],
        variants: BTreeMap::new(),
        random: vec![],
        diagnosis: None,
    };
    let objects = reconstruct_objects(&p.capture, &cfg.objects, seed);
    result.objects_time_s = p.t0.elapsed().as_secs_f64();
    let objects = match objects {
        Ok(o) => o,
        Err(e) => {
            tracing::warn!("{id}: stage 1 failed: {e}");
            let failed = VariantResult {
                eval: None,
                error: Some(format!("stage 1: {e}")),
                time_s: 0.0,
                ceiling: None,
            };
            result.variants = variants.iter().map(|&v| (v, failed.clone())).collect();
            progress.runs_done(variants.len() as u64);
            return Ok(result);
        }
    };
    result.object_chamfer_mm2 = objects
        .objects
        .iter()
        .zip(&p.sim.object_meshes)
        .map(|(o, m)| Ok(chamfer_mm2(&object_mesh(o)?, m)))
        .collect::<Result<_, EvalError>>()?;
    for &variant in variants {
        let mut cfg = base.clone();
        cfg.ablate.extend(variant.ablation());
        let truth = p.scene.person.phenotype;
        if matches!(variant, Variant::TrueShape | Variant::TrueBuild) {
            cfg.human.build = truth;
            cfg.human.search.builds.clear();
        }
        if matches!(variant, Variant::TrueShape | Variant::TrueHeight) {
            cfg.human.height_prior[0] = truth.height;
        }
        if variant == Variant::TrueRadiometry {
            let person = &p.scene.person;
            cfg.human.radiometric.region_temperatures_c =
                Some(irmirror_body::regions::Region::ALL.map(|r| person.region_temperature(r).0));
        }
        let t0 = Instant::now();
        // The oracle sees the simulator's objects; every other variant stage 1's.
        let seen = match variant {
            Variant::TrueObjects => true_objects_as_fitted(p, &objects),
            _ => Ok(objects.clone()),
        };
        let rec = seen.and_then(|seen| {
            reconstruct_human(&p.capture, p.pre.clone(), seen, priors, &cfg, seed, &Silent)
                .map_err(|e| e.to_string())
        });
        let rec = match rec {
            Ok(r) => r,
            Err(reason) => {
                tracing::warn!("{id}: stage 2 ({}) failed: {reason}", variant.heading());
                let failed = VariantResult {
                    eval: None,
                    error: Some(reason),
                    time_s: t0.elapsed().as_secs_f64(),
                    ceiling: None,
                };
                result.variants.insert(variant, failed);
                progress.runs_done(1);
                continue;
            }
        };
        let time_s = t0.elapsed().as_secs_f64();
        let body = posed_body(model, prior, &rec.states[0])?;
        let mask = fitted_mask(model, &rec.rays, &body);
        let eval = Some(evaluate(
            &p.truth,
            &body,
            &mask,
            &object_poses(&rec.objects),
        )?);
        if variant == Variant::Full {
            result.diagnosis = Some(diagnose(p, priors, &rec, (seed, &cfg), basin)?);
            save_png(
                &overlay(&rec.pre.rise_k, &rec.pre.mask, &mask),
                &thumbs.join("overlay.png"),
            )?;
            let view = third_view(&p.truth, model, &body, &rec.objects);
            save_png(
                &image::imageops::thumbnail(&view, 160, 120),
                &thumbs.join("third.png"),
            )?;
        }
        // An oracle's ceiling: what its settings and objects let the loss keep of the truth.
        let own_ceiling = if variant.on_request_only() {
            ceiling(p, priors, &rec, (seed, &cfg))?
        } else {
            None
        };
        let done = VariantResult {
            eval,
            error: None,
            time_s,
            ceiling: own_ceiling,
        };
        result.variants.insert(variant, done);
        progress.runs_done(1);
    }
    result.random = random_baseline(p, priors, &objects, (seed, base))?;
    Ok(result)
}

/// Stage 1's result with each object's shape and pose replaced by the simulator's (the
/// support plane and masks kept): what stage 2 would do with a perfect mirror. Only the
/// two-parameter shapes have a fitted counterpart; other shape sets are refused.
fn true_objects_as_fitted(p: &Prepared, fitted: &Objects) -> Result<Objects, String> {
    let mut objects = fitted.clone();
    if objects.objects.len() != p.scene.objects.len() {
        return Err(format!(
            "true objects: stage 1 found {} objects, the scene has {}",
            objects.objects.len(),
            p.scene.objects.len()
        ));
    }
    for ((o, truth), pose) in objects
        .objects
        .iter_mut()
        .zip(&p.scene.objects)
        .zip(&p.sim.object_poses)
    {
        let ObjectShape::Simple(shape) = &truth.shape else {
            return Err("true objects: only the two-parameter shapes (`--shapes simple`)".into());
        };
        o.shape = *shape;
        o.depth_from_object = *pose;
        o.learned = None;
    }
    Ok(objects)
}

/// The Random baseline: [`RANDOM_DRAWS`] pose-prior samples at the true root position and
/// orientation.
fn random_baseline(
    p: &Prepared,
    priors: BodyPriors<'_>,
    objects: &Objects,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Vec<Evaluation>, EvalError> {
    let BodyPriors { model, prior } = priors;
    let mut rng = irmirror_geom::rng::seeded(seed, 99);
    let truth_root = p.sim.body.depth_from_anny.rotation
        * irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(
            p.scene.person.rotvec_rad[0],
        ));
    let rays = irmirror_recon::pipeline::reflected_rays(&p.capture, objects, &p.pre.mask, cfg);
    let poses = object_poses(objects);
    (0..RANDOM_DRAWS)
        .map(|_| {
            let latent: Vec<f64> = (0..irmirror_body::prior::LATENT)
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let st = HumanState {
                translation: p.sim.body.joints[0],
                rotation: truth_root,
                height: irmirror_recon::human::HEIGHT_MEAN,
                build: cfg.human.build,
                latent,
                residual: Vec::new(),
            };
            let body = posed_body(model, prior, &st)?;
            let mask = fitted_mask(model, &rays, &body);
            evaluate(&p.truth, &body, &mask, &poses)
        })
        .collect()
}
