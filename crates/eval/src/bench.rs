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
use crate::score::{Evaluation, evaluate, fitted_mask, third_view};
use crate::views::{object_mesh, overlay, posed_body};
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::Capture;
use irmirror_geom::Category;
use irmirror_recon::human::HumanState;
use irmirror_recon::objects::{Objects, reconstruct_objects};
use irmirror_recon::pipeline::{Ablation, BodyPriors, ReconConfig, reconstruct_human};
use irmirror_recon::{Preprocessed, ReconError, preprocess};
use irmirror_sim::presets::benchmark_scene;
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
    /// 4 captures per object type (12), ≈ 6 minutes on 2 cores.
    Quick,
    /// 60 captures per object type (180), NETD varied.
    Full,
}

/// Object types, as the rows of Table 1.
pub const CATEGORIES: [Category; 3] = [Category::Bowl, Category::Mug, Category::Car];

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
    /// Identifier (`<type>_<index>`).
    pub id: String,
    /// Object type.
    pub category: Category,
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
const METRICS: [Metric; 6] = [
    ("2-D keypoints, normalised", |e| e.keypoints_2d_normalised),
    ("3-D keypoints, normalised", |e| e.keypoints_3d_normalised),
    ("root error (m)", |e| Some(e.root_error_m)),
    ("MPJPE (m)", |e| e.mpjpe_m),
    ("PA-MPJPE (m)", |e| e.pa_mpjpe_m),
    ("reflection IoU", |e| Some(e.reflection_iou)),
];

struct Silent;
impl irmirror_recon::pipeline::Progress for Silent {
    fn stage(&self, _: &str, _: u64) {}
    fn tick(&self) {}
}

/// The benchmark's captures: `(id, category, seed, netd_mk)`.
pub fn captures(set: Set) -> Vec<(String, Category, u64, f64)> {
    let n = match set {
        Set::Quick => 4,
        Set::Full => 60,
    };
    let mut out = Vec::new();
    for (c, cat) in CATEGORIES.iter().enumerate() {
        for i in 0..n {
            let netd = match set {
                Set::Quick => 50.0,
                Set::Full => [30.0, 50.0, 80.0][i % 3],
            };
            out.push((
                format!("{cat}_{i:02}"),
                *cat,
                SEED_BASE + 1000 * c as u64 + i as u64,
                netd,
            ));
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
    /// Only this object type.
    pub category: Option<Category>,
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
pub fn selected(
    set: Set,
    selection: &Selection,
) -> Result<Vec<(String, Category, u64, f64)>, EvalError> {
    if let Some(c) = selection.category
        && !CATEGORIES.contains(&c)
    {
        return Err(EvalError::Sim(irmirror_sim::SimError::Scene(format!(
            "--category {c}: the benchmark has bowl, mug and car"
        ))));
    }
    let mut list = captures(set);
    if let Some(l) = selection.limit {
        let per = list.len() / CATEGORIES.len();
        list = list
            .into_iter()
            .enumerate()
            .filter(|(k, _)| k % per < l)
            .map(|(_, c)| c)
            .collect();
    }
    if let Some(c) = selection.category {
        list.retain(|x| x.1 == c);
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
    let variants: Vec<Variant> = Variant::ALL
        .iter()
        .copied()
        .filter(|v| !selection.full_only || *v == Variant::Full)
        .collect();
    progress.start((list.len() * variants.len()) as u64);
    let scratch = stage.path("scratch");
    let mut results = Vec::new();
    for (id, category, seed, netd) in &list {
        progress.capture(id);
        let p = prepare(&model, id, *category, *seed, *netd, &scratch)?;
        let thumbs = stage.path(&format!("captures/{id}"));
        std::fs::create_dir_all(&thumbs).map_err(|e| EvalError::Output {
            path: thumbs.clone(),
            reason: e.to_string(),
        })?;
        results.push(run_capture(
            &p,
            (id, *category, *seed, *netd),
            priors,
            &variants,
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
    let record = serde_json::json!({ "command": "eval", "set": set, "limit": selection.limit.map(|l| l as i64).unwrap_or(-1), "category": selection.category.map_or("all", Category::name), "full_only": selection.full_only, "version": env!("CARGO_PKG_VERSION"), "config": ReconConfig::default(), "random_draws": RANDOM_DRAWS });
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
fn prepare(
    model: &BodyModel,
    id: &str,
    category: Category,
    seed: u64,
    netd_mk: f64,
    scratch: &Path,
) -> Result<Prepared, EvalError> {
    let cfg = ReconConfig::default();
    let mut first = 0;
    loop {
        let (scene, attempt) = benchmark_scene(model, category, seed, netd_mk, first)?;
        let sim = irmirror_sim::simulate(model, &scene, seed)?;
        let dir = scratch.join(id);
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
    (id, category, seed, netd_mk): (&str, Category, u64, f64),
    priors: BodyPriors<'_>,
    variants: &[Variant],
    thumbs: &Path,
    progress: &dyn BenchProgress,
) -> Result<CaptureResult, EvalError> {
    let BodyPriors { model, prior } = priors;
    let cfg = ReconConfig::default();
    let mut result = CaptureResult {
        id: id.to_string(),
        category,
        seed,
        netd_mk,
        thermal_width: p.capture.thermal_camera.width,
        reflection_pixels: p.sim.report.reflection_pixels,
        person_distance_m: p.sim.body.joints[0].norm(),
        objects_time_s: 0.0,
        object_chamfer_mm2: vec![],
        variants: BTreeMap::new(),
        random: vec![],
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

fn cell(values: &[f64]) -> String {
    match mean_ci95(values) {
        Some((m, h)) => format!("{m:.3} ± {h:.3}"),
        None => "n/a".into(),
    }
}

/// Table 1's layout: rows metric × object type, columns the ablations, the full model and Random.
pub fn markdown_table(r: &Report) -> String {
    let mut s = String::from("| metric | object | n |");
    for v in Variant::ALL {
        s.push_str(&format!(" {} |", v.heading()));
    }
    s.push_str(" random |\n|---|---|---|");
    s.push_str(&"---|".repeat(Variant::ALL.len() + 1));
    s.push('\n');
    for (metric, get) in METRICS {
        for cat in CATEGORIES {
            let caps: Vec<&CaptureResult> =
                r.captures.iter().filter(|c| c.category == cat).collect();
            if caps.is_empty() {
                continue;
            }
            s.push_str(&format!("| {metric} | {cat} | {} |", caps.len()));
            for variant in Variant::ALL {
                let v: Vec<f64> = caps
                    .iter()
                    .filter_map(|c| {
                        c.variants
                            .get(&variant)
                            .and_then(|x| x.eval.as_ref())
                            .and_then(get)
                    })
                    .collect();
                s.push_str(&format!(" {} |", cell(&v)));
            }
            // Random: the per-capture mean over draws, then the mean over captures.
            let v: Vec<f64> = caps
                .iter()
                .filter_map(|c| {
                    let d: Vec<f64> = c.random.iter().filter_map(get).collect();
                    (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
                })
                .collect();
            s.push_str(&format!(" {} |\n", cell(&v)));
        }
    }
    for cat in CATEGORIES {
        let caps: Vec<&CaptureResult> = r.captures.iter().filter(|c| c.category == cat).collect();
        if caps.is_empty() {
            continue;
        }
        s.push_str(&format!(
            "| failed reconstructions | {cat} | {} |",
            caps.len()
        ));
        for variant in Variant::ALL {
            // A variant left out (`--full-only`) did not fail: it did not run.
            if caps.iter().all(|c| !c.variants.contains_key(&variant)) {
                s.push_str(" – |");
            } else {
                s.push_str(&format!(
                    " {} |",
                    caps.iter()
                        .filter(|c| c.variants.get(&variant).is_some_and(|v| v.eval.is_none()))
                        .count()
                ));
            }
        }
        s.push_str(" – |\n");
    }
    s.push_str("\n| object | objects: translation error (mm) | scale error (%) | Chamfer (mm²) | stage 0–1 time (s) | stage 2 time, full model (s) |\n|---|---|---|---|---|---|\n");
    for cat in CATEGORIES {
        let caps: Vec<&CaptureResult> = r.captures.iter().filter(|c| c.category == cat).collect();
        if caps.is_empty() {
            continue;
        }
        let full = |c: &&CaptureResult| c.variants.get(&Variant::Full).cloned();
        let full_eval = |c: &&CaptureResult| full(c).and_then(|v| v.eval);
        let t: Vec<f64> = caps
            .iter()
            .filter_map(full_eval)
            .flat_map(|e| {
                e.object_translation_error_m
                    .iter()
                    .map(|x| x * 1e3)
                    .collect::<Vec<_>>()
            })
            .collect();
        let sc: Vec<f64> = caps
            .iter()
            .filter_map(full_eval)
            .flat_map(|e| e.object_scale_error_pct)
            .collect();
        let ch: Vec<f64> = caps
            .iter()
            .flat_map(|c| c.object_chamfer_mm2.clone())
            .collect();
        let t1: Vec<f64> = caps.iter().map(|c| c.objects_time_s).collect();
        let t2: Vec<f64> = caps.iter().filter_map(full).map(|v| v.time_s).collect();
        s.push_str(&format!(
            "| {cat} | {} | {} | {} | {} | {} |\n",
            cell(&t),
            cell(&sc),
            cell(&ch),
            cell(&t1),
            cell(&t2)
        ));
    }
    s
}

fn html(r: &Report, table: &str) -> String {
    let mut rows = String::new();
    for c in &r.captures {
        let full = c.variants.get(&Variant::Full).and_then(|v| v.eval.as_ref());
        let f = |x: Option<f64>| x.map_or("n/a".into(), |v| format!("{v:.3}"));
        rows.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td><img src=\"captures/{}/overlay.png\" width=\"160\"></td><td><img src=\"captures/{}/third.png\" width=\"160\"></td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            c.id,
            c.reflection_pixels,
            c.person_distance_m,
            c.id,
            c.id,
            f(full.and_then(|e| e.keypoints_2d_normalised)),
            f(full.and_then(|e| e.keypoints_3d_normalised)),
            f(full.map(|e| e.root_error_m)),
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
         <p>Synthetic captures (simulator, Lepton 160×120); means with 95 % intervals (Student t). \
         Random: {RANDOM_DRAWS} pose-prior samples per capture at the true root position and orientation. \
         Overlay: observed reflection green, fitted magenta, both white. Third view: fitted body orange, truth green.</p>\
         <table>{table_html}</table><h2>Per capture (full model)</h2>\
         <table><tr><th>capture</th><th>reflection px</th><th>distance (m)</th><th>observed vs fitted</th><th>third camera</th><th>2-D</th><th>3-D</th><th>root error (m)</th></tr>{rows}</table></body></html>",
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
            reflection_iou: 0.5,
            object_translation_error_m: vec![0.001],
            object_scale_error_pct: vec![1.0],
        }
    }

    #[test]
    fn report_round_trips_and_the_table_has_every_cell() {
        let captures = (0..3)
            .map(|k| CaptureResult {
                id: format!("mug_{k:02}"),
                category: Category::Mug,
                seed: k,
                netd_mk: 50.0,
                thermal_width: 160,
                reflection_pixels: 20,
                person_distance_m: 2.0,
                objects_time_s: 0.5,
                object_chamfer_mm2: vec![0.25],
                variants: Variant::ALL
                    .iter()
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
        // Values 0, 1, 2: mean 1, sd 1, t(2) 4.303 → ± 2.484; random: mean of (1 + 3)/2 = 2.
        assert!(
            t.contains("| root error (m) | mug | 3 | 1.000 ± 2.484 |"),
            "{t}"
        );
        // The full model failed once: its mean is over the two others (0, 1), and it is counted.
        assert!(t.contains("| 0.500 ± 6.353 | 2.000 ± 0.000 |"), "{t}");
        assert!(
            t.contains("| failed reconstructions | mug | 3 | 0 | 0 | 0 | 1 | – |"),
            "{t}"
        );
        assert!(t.contains("2.000 ± 0.000 |"), "{t}");
        assert!(
            t.contains("| 3-D keypoints, normalised | mug | 3 | n/a |"),
            "{t}"
        );
        assert!(
            !t.contains("| bowl |"),
            "rows without captures are left out"
        );
        assert!(html(&r, &t).contains("captures/mug_02/overlay.png"));
    }

    #[test]
    fn benchmark_sets_are_fixed() {
        assert_eq!(captures(Set::Quick).len(), 12);
        assert_eq!(captures(Set::Full).len(), 180);
        assert_eq!(
            captures(Set::Quick)[4],
            ("mug_00".to_string(), Category::Mug, SEED_BASE + 1000, 50.0)
        );
    }
}
