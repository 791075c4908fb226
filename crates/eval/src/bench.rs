//! The Table-1 benchmark on simulated captures (DESIGN.md §5).
//!
//! Each capture is simulated deterministically from its seed, reconstructed once up to stage 1,
//! then stage 2 runs four times from the same objects: without edge sampling, without sphere
//! tracing, without surface smoothing, and the full model. The **Random** baseline puts random
//! pose-prior samples (N(0, I) latents, [`RANDOM_DRAWS`] per capture) at the true root position
//! and orientation, as the paper's HumanEva draw. Writes `table.md` (Table 1 layout, means with
//! 95 % intervals), `results.json` (per capture), `report.html` (with thumbnails) and `run.toml`.

use crate::EvalError;
use crate::metrics::mean_ci95;
use crate::output::{Staging, save_png, write_text};
use crate::score::{Evaluation, evaluate, facing_error_deg, fitted_mask, third_view};
use crate::views::{object_mesh, overlay, posed_body};
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::Capture;
use irmirror_recon::human::{HumanProblem, HumanState};
use irmirror_recon::objects::{FittedObject, Objects, reconstruct_objects};
use irmirror_recon::pipeline::{
    Ablation, BodyPriors, ReconConfig, Reconstruction, reconstruct_human, reflected_rays,
};
use irmirror_recon::{Preprocessed, ReconError, preprocess};
use irmirror_sim::presets::{Cell, benchmark_scene};
use irmirror_sim::scene::ObjectShape;
use irmirror_sim::{SceneFile, Simulation};
use nalgebra::Vector3;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Benchmark sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Set {
    /// 8 captures per cell (32); the ablation columns on the first 2 of each cell.
    Quick,
    /// 60 captures per cell (240), NETD varied; the ablation columns on the first 10 of each.
    Full,
}

impl Set {
    /// Captures per cell.
    pub fn per_cell(self) -> usize {
        match self {
            Set::Quick => 8,
            Set::Full => 60,
        }
    }

    /// The first this many captures of each cell also run the ablations.
    pub fn ablated_per_cell(self) -> usize {
        match self {
            Set::Quick => 2,
            Set::Full => 10,
        }
    }
}

/// One capture of a set.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    /// Identifier (`<cell>_<index>`).
    pub id: String,
    /// The cell.
    pub cell: Cell,
    /// Index within its cell.
    pub index: usize,
    /// Scene seed.
    pub seed: u64,
    /// Thermal NETD, mK.
    pub netd_mk: f64,
}

/// A stage-2 variant: Table 1's columns (ablations, then the full model).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// Without edge sampling.
    NoEdgeSampling,
    /// Without sphere tracing.
    NoSphereTracing,
    /// Without surface smoothing.
    NoSmoothing,
    /// The full model.
    Full,
}

impl Variant {
    /// Every variant, in the table's column order.
    pub const ALL: [Variant; 4] = [
        Variant::NoEdgeSampling,
        Variant::NoSphereTracing,
        Variant::NoSmoothing,
        Variant::Full,
    ];

    /// The column heading.
    pub fn heading(self) -> &'static str {
        match self {
            Variant::NoEdgeSampling => "w/o edge sampling",
            Variant::NoSphereTracing => "w/o sphere tracing",
            Variant::NoSmoothing => "w/o surface smoothing",
            Variant::Full => "full model",
        }
    }

    /// The ablation it switches on (`None`: the full model).
    pub fn ablation(self) -> Option<Ablation> {
        match self {
            Variant::NoEdgeSampling => Some(Ablation::EdgeSampling),
            Variant::NoSphereTracing => Some(Ablation::SphereTracing),
            Variant::NoSmoothing => Some(Ablation::Smoothing),
            Variant::Full => None,
        }
    }
}
/// Random pose draws per capture for the baseline.
pub const RANDOM_DRAWS: usize = 8;
/// Seeds of the benchmark start here (held out from the demo's and tests' small seeds).
pub const SEED_BASE: u64 = 10_000;

/// One stage-2 run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantResult {
    /// Figures (`None` when the reconstruction failed).
    pub eval: Option<Evaluation>,
    /// Why the reconstruction failed (a failure is a result, not an abort).
    pub error: Option<String>,
    /// Stage-2 seconds (rays + fit).
    pub time_s: f64,
}

/// One capture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaptureResult {
    /// Identifier (`<cell>_<index>`).
    pub id: String,
    /// The benchmark cell (regime and object type).
    pub cell: Cell,
    /// Scene seed.
    pub seed: u64,
    /// Thermal NETD, mK.
    pub netd_mk: f64,
    /// Thermal image width, pixels (160: Lepton-like, 640: Boson-like).
    pub thermal_width: u32,
    /// Reflection size in the truth, thermal pixels.
    pub reflection_pixels: usize,
    /// True root distance from the depth camera, m.
    pub person_distance_m: f64,
    /// Stage 0–1 seconds.
    pub objects_time_s: f64,
    /// Chamfer between fitted and true object meshes, mm² (mean of both directions' mean
    /// squared point-to-surface distances), per object.
    pub object_chamfer_mm2: Vec<f64>,
    /// Per variant.
    pub variants: BTreeMap<Variant, VariantResult>,
    /// Random baseline draws.
    pub random: Vec<Evaluation>,
    /// The full model's failure diagnosis (`None` when it failed).
    pub diagnosis: Option<Diagnosis>,
}

/// What a capture's full-model fit says about why it is off (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FailureClass {
    /// The best hypothesis is within [`SUCCESS_ROOT_M`] and [`SUCCESS_FACING_DEG`] of the truth.
    Success,
    /// Off, and the true body scores a lower loss than the fit: the optimiser did not find what
    /// its loss prefers.
    Search,
    /// Off, yet the fit scores at least as low as the truth: the observation (or the model) does
    /// not tell them apart.
    Information,
}

impl FailureClass {
    /// Every class, in the table's column order.
    pub const ALL: [FailureClass; 3] = [
        FailureClass::Success,
        FailureClass::Search,
        FailureClass::Information,
    ];

    /// The column heading.
    pub fn heading(self) -> &'static str {
        match self {
            FailureClass::Success => "success",
            FailureClass::Search => "search failure",
            FailureClass::Information => "information / model failure",
        }
    }
}

/// A fit within this root distance of the truth…
pub const SUCCESS_ROOT_M: f64 = 0.15;
/// …and this facing angle is a success.
pub const SUCCESS_FACING_DEG: f64 = 30.0;

/// The full model's fit against the true body, both scored by stage 2's data term
/// (`1 − soft IoU` on all rays at the final σ) through the *fitted* objects.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// The true body mesh's data term.
    pub truth_loss: f64,
    /// The true body's data term through the *true* objects (rays traced against the
    /// simulator's shapes; `None` for shapes stage 1 cannot represent): low here but high through
    /// the fitted objects means stage 1's mirror, not the optimiser or the observation, is off.
    #[serde(default)]
    pub truth_loss_true_objects: Option<f64>,
    /// Every reported hypothesis' data term, best first.
    pub hypothesis_losses: Vec<f64>,
    /// Root error of every reported hypothesis, m.
    pub hypothesis_root_errors_m: Vec<f64>,
    /// Root error of the hypothesis nearest the truth, m.
    pub nearest_root_error_m: f64,
    /// The class.
    pub class: FailureClass,
}

impl Diagnosis {
    /// Classifies from the best hypothesis' root and facing errors and the losses.
    pub fn classify(
        truth_loss: f64,
        best_loss: f64,
        root_error_m: f64,
        facing_error_deg: Option<f64>,
    ) -> FailureClass {
        let facing_ok = facing_error_deg.is_none_or(|f| f <= SUCCESS_FACING_DEG);
        if root_error_m <= SUCCESS_ROOT_M && facing_ok {
            FailureClass::Success
        } else if truth_loss < best_loss {
            FailureClass::Search
        } else {
            FailureClass::Information
        }
    }
}

/// The whole report (what `results.json` holds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Set.
    pub set: Set,
    /// Version.
    pub version: String,
    /// Per capture.
    pub captures: Vec<CaptureResult>,
}

/// The metric rows of the table: name and accessor.
type Metric = (&'static str, fn(&Evaluation) -> Option<f64>);
const METRICS: [Metric; 8] = [
    ("2-D keypoints, normalised", |e| e.keypoints_2d_normalised),
    ("3-D keypoints, normalised", |e| e.keypoints_3d_normalised),
    ("root error (m)", |e| Some(e.root_error_m)),
    ("MPJPE (m)", |e| e.mpjpe_m),
    ("PA-MPJPE (m)", |e| e.pa_mpjpe_m),
    ("mean per-vertex error (m)", |e| e.vertex_error_m),
    ("facing error (°)", |e| e.facing_error_deg),
    ("reflection IoU", |e| Some(e.reflection_iou)),
];

struct Silent;
impl irmirror_recon::pipeline::Progress for Silent {
    fn stage(&self, _: &str, _: u64) {}
    fn tick(&self) {}
}

/// The benchmark's captures, cell by cell.
pub fn captures(set: Set) -> Vec<Planned> {
    let mut out = Vec::new();
    for (c, cell) in Cell::ALL.iter().enumerate() {
        for index in 0..set.per_cell() {
            let netd_mk = match set {
                Set::Quick => 50.0,
                Set::Full => [30.0, 50.0, 80.0][index % 3],
            };
            out.push(Planned {
                id: format!("{cell}_{index:02}"),
                cell: *cell,
                index,
                seed: SEED_BASE + 1000 * c as u64 + index as u64,
                netd_mk,
            });
        }
    }
    out
}

fn chamfer_mm2(a: &irmirror_geom::TriMesh, b: &irmirror_geom::TriMesh) -> f64 {
    irmirror_sdf::quality::chamfer(a, b, 5000, 0) * 1e6
}

/// Which part of a set to run.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Only the first N captures of each object type.
    pub limit: Option<usize>,
    /// Only this cell.
    pub cell: Option<Cell>,
    /// Only the full model.
    pub full_only: bool,
}

/// What the runner reports while it works.
pub trait BenchProgress {
    /// The number of stage-2 runs ahead.
    fn start(&self, runs: u64);
    /// A capture begins.
    fn capture(&self, id: &str);
    /// `n` stage-2 runs finished (or were skipped after a failed stage 1).
    fn runs_done(&self, n: u64);
}

/// Everything one capture's runs share.
struct Prepared {
    scene: SceneFile,
    sim: Simulation,
    capture: Capture,
    pre: Preprocessed,
    /// When stage 0 started (stage 0–1 time).
    t0: Instant,
}

/// The captures of `selection`, in the set's order.
pub fn selected(set: Set, selection: &Selection) -> Result<Vec<Planned>, EvalError> {
    if selection.limit == Some(0) {
        return Err(EvalError::Selection(
            "--limit 0 selects no capture; give at least 1".into(),
        ));
    }
    let mut list = captures(set);
    if let Some(l) = selection.limit {
        list.retain(|p| p.index < l);
    }
    if let Some(c) = selection.cell {
        list.retain(|p| p.cell == c);
    }
    Ok(list)
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
    // The ablation columns run on the first captures of each cell (all of them unless
    // --full-only): the full model on every capture.
    let variants_of = |plan: &Planned| -> Vec<Variant> {
        let ablate = !selection.full_only && plan.index < set.ablated_per_cell();
        Variant::ALL
            .iter()
            .copied()
            .filter(|v| ablate || *v == Variant::Full)
            .collect()
    };
    progress.start(list.iter().map(|p| variants_of(p).len() as u64).sum());
    let scratch = stage.path("scratch");
    let mut results = Vec::new();
    for plan in &list {
        let id = &plan.id;
        progress.capture(id);
        let p = prepare(&model, plan, &scratch)?;
        let thumbs = stage.path(&format!("captures/{id}"));
        std::fs::create_dir_all(&thumbs).map_err(|e| EvalError::Output {
            path: thumbs.clone(),
            reason: e.to_string(),
        })?;
        results.push(run_capture(
            &p,
            plan,
            priors,
            &variants_of(plan),
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
    let record = serde_json::json!({ "command": "eval", "set": set, "limit": selection.limit.map(|l| l as i64).unwrap_or(-1), "cell": selection.cell.map_or("all", Cell::name), "ablated_per_cell": set.ablated_per_cell(), "full_only": selection.full_only, "version": env!("CARGO_PKG_VERSION"), "config": ReconConfig::default(), "random_draws": RANDOM_DRAWS });
    write_text(
        &stage.path("run.toml"),
        &toml::to_string(&record).map_err(|e| ser(&e))?,
    )?;
    let dir = stage.commit()?;
    Ok((report, table, dir))
}

/// Simulates the capture, reads it back through the loader and runs stage 0, drawing again until
/// stage 0 sees the reflection through the sensor noise: the benchmark measures reconstruction
/// from a visible reflection.
fn prepare(model: &BodyModel, plan: &Planned, scratch: &Path) -> Result<Prepared, EvalError> {
    let cfg = ReconConfig::default();
    let (seed, mut first) = (plan.seed, 0);
    loop {
        let (scene, attempt) = benchmark_scene(model, plan.cell, seed, plan.netd_mk, first)?;
        let sim = irmirror_sim::simulate(model, &scene, seed)?;
        let dir = scratch.join(&plan.id);
        sim.write(model, &dir, seed)?;
        let capture = Capture::load(&dir)?;
        std::fs::remove_dir_all(&dir).ok();
        let t0 = Instant::now();
        match preprocess(&capture, &cfg.preprocess) {
            Ok(pre) => {
                return Ok(Prepared {
                    scene,
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
    variants: &[Variant],
    thumbs: &Path,
    progress: &dyn BenchProgress,
) -> Result<CaptureResult, EvalError> {
    let BodyPriors { model, prior } = priors;
    let cfg = ReconConfig::default();
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
        let cfg = ReconConfig {
            ablate: variant.ablation().into_iter().collect(),
            ..ReconConfig::default()
        };
        let t0 = Instant::now();
        let rec = match reconstruct_human(
            &p.capture,
            p.pre.clone(),
            objects.clone(),
            priors,
            &cfg,
            seed,
            &Silent,
        ) {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!("{id}: stage 2 ({}) failed: {e}", variant.heading());
                let failed = VariantResult {
                    eval: None,
                    error: Some(e.to_string()),
                    time_s: t0.elapsed().as_secs_f64(),
                };
                result.variants.insert(variant, failed);
                progress.runs_done(1);
                continue;
            }
        };
        let time_s = t0.elapsed().as_secs_f64();
        let body = posed_body(model, prior, &rec.states[0])?;
        let mask = fitted_mask(model, &rec.rays, &body);
        let eval = Some(evaluate(&p.sim, &body, &mask, &rec.objects)?);
        if variant == Variant::Full {
            result.diagnosis = Some(diagnose(p, priors, &rec)?);
            save_png(
                &overlay(&rec.pre.rise_k, &rec.pre.mask, &mask),
                &thumbs.join("overlay.png"),
            )?;
            let view = third_view(&p.sim, model, &body, &rec.objects)?;
            save_png(
                &image::imageops::thumbnail(&view, 160, 120),
                &thumbs.join("third.png"),
            )?;
        }
        let done = VariantResult {
            eval,
            error: None,
            time_s,
        };
        result.variants.insert(variant, done);
        progress.runs_done(1);
    }
    result.random = random_baseline(p, priors, &objects, seed)?;
    Ok(result)
}

/// The full model's failure diagnosis: the true body and every reported hypothesis scored by
/// stage 2's data term through the fitted objects.
fn diagnose(
    p: &Prepared,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
) -> Result<Diagnosis, EvalError> {
    let BodyPriors { model, prior } = priors;
    let hcfg = ReconConfig::default().human_settings();
    let problem = HumanProblem {
        model,
        prior,
        rays: &rec.rays,
        mask: &rec.pre.mask,
        up: rec.objects.ground.n(),
        objects_centre: Vector3::zeros(),
        floor: None,
    };
    let truth: Vec<Vector3<f64>> = p
        .sim
        .body
        .mesh
        .vertices
        .iter()
        .map(|v| Vector3::from(v.map(f64::from)))
        .collect();
    let (truth_loss, _) = problem.mesh_data_loss(&truth, &model.asset.faces, &hcfg);
    let truth_loss_true_objects = true_objects(p, &rec.objects).map(|objects| {
        let cfg = ReconConfig::default();
        let rays = reflected_rays(&p.capture, &objects, &rec.pre.mask, &cfg);
        let through_truth = HumanProblem {
            rays: &rays,
            ..problem
        };
        through_truth
            .mesh_data_loss(&truth, &model.asset.faces, &hcfg)
            .0
    });
    let hypothesis_losses: Vec<f64> = rec
        .human
        .hypotheses
        .iter()
        .map(|h| 1.0 - h.soft_iou)
        .collect();
    let true_root = p.sim.body.joints[0];
    let hypothesis_root_errors_m: Vec<f64> = rec
        .states
        .iter()
        .map(|st| posed_body(model, prior, st).map(|b| (b.joints[0] - true_root).norm()))
        .collect::<Result<_, _>>()?;
    let best = posed_body(model, prior, &rec.states[0])?;
    let facing = facing_error_deg(&best.keypoints, &p.sim.body.keypoints);
    let class = Diagnosis::classify(
        truth_loss,
        hypothesis_losses[0],
        hypothesis_root_errors_m[0],
        facing,
    );
    Ok(Diagnosis {
        truth_loss,
        truth_loss_true_objects,
        nearest_root_error_m: hypothesis_root_errors_m
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min),
        hypothesis_losses,
        hypothesis_root_errors_m,
        class,
    })
}

/// The simulator's objects as stage-1 results (same ground and masks as `fitted`), when every
/// one is a two-parameter shape stage 1 can represent.
fn true_objects(p: &Prepared, fitted: &Objects) -> Option<Objects> {
    let objects = p
        .scene
        .objects
        .iter()
        .zip(&p.sim.object_poses)
        .map(|(o, pose)| match o.shape {
            ObjectShape::Simple(shape) => Some(FittedObject {
                category: shape.category(),
                shape,
                depth_from_object: *pose,
                loss: 0.0,
                mean_surface_error_m: 0.0,
                points: 0,
                loss_curve: vec![],
                learned: None,
            }),
            ObjectShape::Family(_) => None,
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Objects {
        objects,
        ..fitted.clone()
    })
}

/// The Random baseline: [`RANDOM_DRAWS`] pose-prior samples at the true root position and
/// orientation.
fn random_baseline(
    p: &Prepared,
    priors: BodyPriors<'_>,
    objects: &Objects,
    seed: u64,
) -> Result<Vec<Evaluation>, EvalError> {
    let BodyPriors { model, prior } = priors;
    let mut rng = irmirror_geom::rng::seeded(seed, 99);
    let truth_root = p.sim.body.depth_from_anny.rotation
        * irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(
            p.scene.person.rotvec_rad[0],
        ));
    let cfg = ReconConfig::default();
    let rays = irmirror_recon::pipeline::reflected_rays(&p.capture, objects, &p.pre.mask, &cfg);
    (0..RANDOM_DRAWS)
        .map(|_| {
            let latent: Vec<f64> = (0..irmirror_body::prior::LATENT)
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let st = HumanState {
                translation: p.sim.body.joints[0],
                rotation: truth_root,
                latent,
            };
            let body = posed_body(model, prior, &st)?;
            let mask = fitted_mask(model, &rays, &body);
            evaluate(&p.sim, &body, &mask, objects)
        })
        .collect()
}

/// Mean ± 95 % interval; with the count when it differs from the row's `n` (ablation columns
/// run on a subset).
fn cell(values: &[f64], n: usize) -> String {
    let m = match mean_ci95(values) {
        Some((m, h)) => format!("{m:.3} ± {h:.3}"),
        None => "n/a".into(),
    };
    if values.len() == n || values.is_empty() {
        m
    } else {
        format!("{m} (n = {})", values.len())
    }
}

/// The captures of one cell.
fn of_cell(r: &Report, c: Cell) -> Vec<&CaptureResult> {
    r.captures.iter().filter(|x| x.cell == c).collect()
}

/// Table 1's layout per cell (rows metric × cell; columns the ablations, the full model and
/// Random), then failures, the failure diagnosis counts, and the objects.
pub fn markdown_table(r: &Report) -> String {
    let mut s = String::from("| metric | cell | n |");
    for v in Variant::ALL {
        s.push_str(&format!(" {} |", v.heading()));
    }
    s.push_str(" random |\n|---|---|---|");
    s.push_str(&"---|".repeat(Variant::ALL.len() + 1));
    s.push('\n');
    for (metric, get) in METRICS {
        for c in Cell::ALL {
            let caps = of_cell(r, c);
            if caps.is_empty() {
                continue;
            }
            let n = caps.len();
            s.push_str(&format!("| {metric} | {c} | {n} |"));
            for variant in Variant::ALL {
                let v: Vec<f64> = caps
                    .iter()
                    .filter_map(|x| {
                        x.variants
                            .get(&variant)
                            .and_then(|y| y.eval.as_ref())
                            .and_then(get)
                    })
                    .collect();
                s.push_str(&format!(" {} |", cell(&v, n)));
            }
            // Random: the per-capture mean over draws, then the mean over captures.
            let v: Vec<f64> = caps
                .iter()
                .filter_map(|x| {
                    let d: Vec<f64> = x.random.iter().filter_map(get).collect();
                    (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
                })
                .collect();
            s.push_str(&format!(" {} |\n", cell(&v, n)));
        }
    }
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        s.push_str(&format!(
            "| failed reconstructions | {c} | {} |",
            caps.len()
        ));
        for variant in Variant::ALL {
            let ran: Vec<&&CaptureResult> = caps
                .iter()
                .filter(|x| x.variants.contains_key(&variant))
                .collect();
            // A variant left out (`--full-only`) did not fail: it did not run.
            if ran.is_empty() {
                s.push_str(" – |");
            } else {
                let failed = ran
                    .iter()
                    .filter(|x| x.variants[&variant].eval.is_none())
                    .count();
                s.push_str(&format!(" {failed} of {} |", ran.len()));
            }
        }
        s.push_str(" – |\n");
    }
    s.push_str(&diagnosis_table(r));
    s.push_str(&objects_table(r));
    s
}

/// Counts of the full model's failure classes per cell.
pub fn diagnosis_table(r: &Report) -> String {
    let mut s = String::from("\n| cell | n |");
    for k in FailureClass::ALL {
        s.push_str(&format!(" {} |", k.heading()));
    }
    s.push_str(" full model failed | data term, median: fit / truth / truth through the true objects |\n|---|---|---|---|---|---|---|\n");
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        s.push_str(&format!("| {c} | {} |", caps.len()));
        for k in FailureClass::ALL {
            let n = caps
                .iter()
                .filter(|x| x.diagnosis.as_ref().is_some_and(|d| d.class == k))
                .count();
            s.push_str(&format!(" {n} |"));
        }
        let failed = caps.iter().filter(|x| x.diagnosis.is_none()).count();
        let ds: Vec<&Diagnosis> = caps.iter().filter_map(|x| x.diagnosis.as_ref()).collect();
        let fit: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.hypothesis_losses.first().copied())
            .collect();
        let truth: Vec<f64> = ds.iter().map(|d| d.truth_loss).collect();
        let through: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.truth_loss_true_objects)
            .collect();
        s.push_str(&format!(
            " {failed} | {} / {} / {} |\n",
            median(&fit),
            median(&truth),
            median(&through)
        ));
    }
    s
}

/// The median to 3 decimals, or "–".
fn median(v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => "–".into(),
        n => format!("{:.3}", s[n / 2]),
    }
}

/// Stage-1 figures and times per cell.
fn objects_table(r: &Report) -> String {
    let mut s = String::from(
        "\n| cell | objects: translation error (mm) | scale error (%) | Chamfer (mm²) | stage 0–1 time (s) | stage 2 time, full model (s) |\n|---|---|---|---|---|---|\n",
    );
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        let full = |x: &&CaptureResult| x.variants.get(&Variant::Full).cloned();
        let evals: Vec<Evaluation> = caps
            .iter()
            .filter_map(full)
            .filter_map(|v| v.eval)
            .collect();
        let t: Vec<f64> = evals
            .iter()
            .flat_map(|e| e.object_translation_error_m.iter().map(|x| x * 1e3))
            .collect();
        let sc: Vec<f64> = evals
            .iter()
            .flat_map(|e| e.object_scale_error_pct.iter().copied())
            .collect();
        let ch: Vec<f64> = caps
            .iter()
            .flat_map(|x| x.object_chamfer_mm2.iter().copied())
            .collect();
        let t1: Vec<f64> = caps.iter().map(|x| x.objects_time_s).collect();
        let t2: Vec<f64> = caps.iter().filter_map(full).map(|v| v.time_s).collect();
        let cells = [&t, &sc, &ch, &t1, &t2].map(|v| cell(v, v.len()));
        s.push_str(&format!("| {c} | {} |\n", cells.join(" | ")));
    }
    s
}

fn html(r: &Report, table: &str) -> String {
    let mut rows = String::new();
    for c in &r.captures {
        let full = c.variants.get(&Variant::Full).and_then(|v| v.eval.as_ref());
        let f = |x: Option<f64>| x.map_or("n/a".into(), |v| format!("{v:.3}"));
        let diag = c.diagnosis.as_ref().map_or("failed".to_string(), |d| {
            format!(
                "{} (truth {:.3}, fit {:.3})",
                d.class.heading(),
                d.truth_loss,
                d.hypothesis_losses.first().copied().unwrap_or(f64::NAN)
            )
        });
        rows.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td><img src=\"captures/{}/overlay.png\" width=\"160\"></td><td><img src=\"captures/{}/third.png\" width=\"160\"></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            c.id,
            c.reflection_pixels,
            c.person_distance_m,
            c.id,
            c.id,
            f(full.and_then(|e| e.keypoints_2d_normalised)),
            f(full.map(|e| e.root_error_m)),
            f(full.and_then(|e| e.vertex_error_m)),
            diag,
        ));
    }
    let table_html: String = table
        .lines()
        .filter(|l| l.starts_with('|') && !l.starts_with("|---"))
        .map(|l| {
            format!(
                "<tr>{}</tr>\n",
                l.trim_matches('|')
                    .split('|')
                    .map(|c| format!("<td>{}</td>", c.trim()))
                    .collect::<String>()
            )
        })
        .collect();
    format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>irmirror eval ({:?})</title>\
         <style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}td{{padding:2px 8px;border-bottom:1px solid #ddd}}</style></head><body>\
         <h1>irmirror eval — {} captures</h1>\
         <p>Synthetic captures (simulator): cells tabletop-bowl, tabletop-mug and car are the paper-like regimes (Boson-class 640×512, 50°), tabletop-wide the hard one (Lepton-class 160×120, 57°); means with 95 % intervals (Student t). \
         Random: {RANDOM_DRAWS} pose-prior samples per capture at the true root position and orientation. \
         Overlay: observed reflection green, fitted magenta, both white. Third view: fitted body orange, truth green.</p>\
         <table>{table_html}</table><h2>Per capture (full model)</h2>\
         <table><tr><th>capture</th><th>reflection px</th><th>distance (m)</th><th>observed vs fitted</th><th>third camera</th><th>2-D</th><th>root error (m)</th><th>per-vertex error (m)</th><th>diagnosis (data term: truth, fit)</th></tr>{rows}</table></body></html>",
        r.set,
        r.captures.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(x: f64) -> Evaluation {
        Evaluation {
            root_error_m: x,
            person_distance_m: 2.0,
            keypoints_2d_normalised: Some(x),
            keypoints_3d_normalised: None,
            mpjpe_m: Some(x),
            pa_mpjpe_m: Some(x / 2.0),
            vertex_error_m: Some(x),
            facing_error_deg: Some(10.0 * x),
            reflection_iou: 0.5,
            object_translation_error_m: vec![0.001],
            object_scale_error_pct: vec![1.0],
        }
    }

    fn diagnosis(class: FailureClass) -> Diagnosis {
        Diagnosis {
            truth_loss: 0.2,
            truth_loss_true_objects: Some(0.1),
            hypothesis_losses: vec![0.3],
            hypothesis_root_errors_m: vec![0.4],
            nearest_root_error_m: 0.4,
            class,
        }
    }

    #[test]
    fn report_round_trips_and_the_table_has_every_cell() {
        let captures = (0..3)
            .map(|k| CaptureResult {
                id: format!("tabletop-mug_{k:02}"),
                cell: Cell::TabletopMug,
                seed: k,
                netd_mk: 50.0,
                thermal_width: 640,
                reflection_pixels: 200,
                person_distance_m: 2.0,
                objects_time_s: 0.5,
                object_chamfer_mm2: vec![0.25],
                variants: Variant::ALL
                    .iter()
                    // The ablations ran on the first two captures only.
                    .filter(|&&v| v == Variant::Full || k < 2)
                    .map(|&v| {
                        // One failure: the full model on the last capture.
                        let failed = v == Variant::Full && k == 2;
                        (
                            v,
                            VariantResult {
                                eval: (!failed).then(|| eval(k as f64)),
                                error: failed.then(|| "x".to_string()),
                                time_s: 1.0,
                            },
                        )
                    })
                    .collect(),
                random: vec![eval(1.0), eval(3.0)],
                diagnosis: (k < 2)
                    .then(|| diagnosis([FailureClass::Search, FailureClass::Success][k as usize])),
            })
            .collect();
        let r = Report {
            set: Set::Quick,
            version: "x".into(),
            captures,
        };
        let json = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<Report>(&json).unwrap(), r);
        let t = markdown_table(&r);
        // Ablations on captures 0 and 1: mean 0.5, sd 0.707, t(1) 12.706 → ± 6.353, n = 2 shown.
        // The full model failed on capture 2: its mean is over the two others too; Random: mean
        // of (1 + 3)/2 = 2 on all three.
        assert!(
            t.contains("| root error (m) | tabletop-mug | 3 | 0.500 ± 6.353 (n = 2) |"),
            "{t}"
        );
        assert!(
            t.contains("| 0.500 ± 6.353 (n = 2) | 2.000 ± 0.000 |"),
            "{t}"
        );
        assert!(
            t.contains("| failed reconstructions | tabletop-mug | 3 | 0 of 2 | 0 of 2 | 0 of 2 | 1 of 3 | – |"),
            "{t}"
        );
        assert!(
            t.contains("| mean per-vertex error (m) | tabletop-mug | 3 |"),
            "{t}"
        );
        assert!(
            t.contains("| 3-D keypoints, normalised | tabletop-mug | 3 | n/a |"),
            "{t}"
        );
        // Diagnosis counts: one success, one search failure, none by information, one failed.
        assert!(
            t.contains("| tabletop-mug | 3 | 1 | 1 | 0 | 1 | 0.300 / 0.200 / 0.100 |"),
            "{t}"
        );
        assert!(!t.contains("| car |"), "rows without captures are left out");
        assert!(html(&r, &t).contains("captures/tabletop-mug_02/overlay.png"));
    }

    #[test]
    fn failures_are_classified_by_distance_then_loss() {
        use FailureClass::*;
        assert_eq!(Diagnosis::classify(0.1, 0.2, 0.05, Some(10.0)), Success);
        assert_eq!(Diagnosis::classify(0.1, 0.2, 0.5, Some(10.0)), Search);
        assert_eq!(Diagnosis::classify(0.3, 0.2, 0.5, Some(10.0)), Information);
        assert_eq!(
            Diagnosis::classify(0.3, 0.2, 0.05, Some(150.0)),
            Information
        );
        assert_eq!(Diagnosis::classify(0.1, 0.2, 0.05, Some(150.0)), Search);
    }

    #[test]
    fn benchmark_sets_are_fixed() {
        assert_eq!(captures(Set::Quick).len(), 32);
        assert_eq!(captures(Set::Full).len(), 240);
        let mug = &captures(Set::Quick)[8];
        assert_eq!(
            (mug.id.as_str(), mug.cell, mug.seed, mug.netd_mk),
            ("tabletop-mug_00", Cell::TabletopMug, SEED_BASE + 1000, 50.0)
        );
        let limited = Selection {
            limit: Some(2),
            cell: Some(Cell::Car),
            full_only: false,
        };
        assert_eq!(selected(Set::Quick, &limited).unwrap().len(), 2);
        let none = Selection {
            limit: Some(0),
            ..Selection::default()
        };
        assert!(selected(Set::Quick, &none).is_err());
    }
}
