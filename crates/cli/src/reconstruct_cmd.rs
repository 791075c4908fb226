//! `irmirror reconstruct`: the pipeline on a capture (stages 0–2, or up to a stage).

use crate::output::{Staging, write_text};
use anyhow::{Context, Result};
use clap::ValueEnum;
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::{Capture, Image, write_gray8_png};
use irmirror_eval::Truth;
use irmirror_recon::objects::reconstruct_objects;
use irmirror_recon::pipeline::{
    Ablation, BodyPriors, Progress, ReconConfig, Reconstruction, reconstruct,
};
use irmirror_recon::preprocess;
use std::path::Path;
use std::time::Instant;

/// How far to run.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Stage {
    /// Stage 0: reflection mask and edge map, with every intermediate in debug/.
    Preprocess,
    /// Stages 0–1 without the person: support plane, object masks and fitted objects.
    Objects,
    /// Stages 0–2: objects and the person.
    Full,
}

/// Ablation switches on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum AblateArg {
    /// Uniform ray draws instead of the edge curriculum.
    EdgeSampling,
    /// Gradient projection instead of K = 3 sphere-tracing steps.
    SphereTracing,
    /// Raw SDF normals instead of the surface smoothing (a 2-mm ring about each hit).
    Smoothing,
    /// Fit the binary reflection mask (the paper's data term) instead of the thermal rise.
    Radiometric,
}

impl From<AblateArg> for Ablation {
    fn from(a: AblateArg) -> Self {
        match a {
            AblateArg::EdgeSampling => Ablation::EdgeSampling,
            AblateArg::SphereTracing => Ablation::SphereTracing,
            AblateArg::Smoothing => Ablation::Smoothing,
            AblateArg::Radiometric => Ablation::Radiometric,
        }
    }
}

fn mask_png(img: &Image<bool>, path: &Path) -> Result<()> {
    write_gray8_png(&img.map(|b| if b { 255 } else { 0 }), path)?;
    Ok(())
}

/// Progress bars for the pipeline's stages.
pub struct Bars {
    bar: indicatif::ProgressBar,
}

impl Bars {
    /// Bars on stderr, or hidden.
    pub fn new(show: bool) -> Self {
        let bar = if show {
            indicatif::ProgressBar::new(0)
        } else {
            indicatif::ProgressBar::hidden()
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template("{msg:24} {bar:30} {pos}/{len} {elapsed}")
                .expect("valid template"),
        );
        Self { bar }
    }
    /// Clears the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for Bars {
    fn stage(&self, name: &str, total: u64) {
        self.bar.set_message(name.to_string());
        self.bar.set_length(total.max(1));
        self.bar.set_position(0);
    }
    fn tick(&self) {
        self.bar.inc(1);
    }
}

/// Reads `--config` (TOML, every field optional) and applies the ablations.
pub fn load_config(config: Option<&Path>, ablate: &[AblateArg]) -> Result<ReconConfig> {
    let mut cfg: ReconConfig = match config {
        Some(p) => toml::from_str(
            &std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
        )
        .with_context(|| format!("config {}", p.display()))?,
        None => ReconConfig::default(),
    };
    for a in ablate {
        let a = Ablation::from(*a);
        if !cfg.ablate.contains(&a) {
            cfg.ablate.push(a);
        }
    }
    Ok(cfg)
}

/// Runs the pipeline up to `stage` on `capture_dir`, writing `out` atomically.
pub fn run(
    capture_dir: &Path,
    out: &Path,
    stage: Stage,
    config: Option<&Path>,
    ablate: &[AblateArg],
    seed: u64,
    progress: bool,
) -> Result<()> {
    let t0 = Instant::now();
    let cfg = load_config(config, ablate)?;
    let capture = Capture::load(capture_dir)?;
    let ctx = || format!("capture {}", capture_dir.display());
    // Refuse an unusable --out before the work, not after it.
    let st = Staging::new(out, "run.toml")?;
    match stage {
        Stage::Preprocess => {
            let pre = preprocess(&capture, &cfg.preprocess).with_context(ctx)?;
            std::fs::create_dir_all(st.path("debug"))?;
            crate::result::write_stage0(&capture, &pre, &|n| st.path(n))?;
            let n = pre.mask.data.iter().filter(|m| **m).count();
            write_record(
                &st,
                capture_dir,
                "preprocess",
                &cfg,
                seed,
                serde_json::json!({"threshold_k": pre.threshold_k, "noise_k": pre.noise_k, "reflection_pixels": n}),
            )?;
            let dir = st.commit()?;
            println!(
                "stage 0: {n} reflection pixels (threshold {:.3} K over a noise of {:.3} K) on {} object pixels; wrote {}",
                pre.threshold_k,
                pre.noise_k,
                pre.object_pixels.data.iter().filter(|m| **m).count(),
                dir.display()
            );
        }
        Stage::Objects => {
            let objs = reconstruct_objects(&capture, &cfg.objects, seed).with_context(ctx)?;
            std::fs::create_dir_all(st.path("objects"))?;
            for (k, o) in objs.objects.iter().enumerate() {
                let m = irmirror_eval::views::object_mesh(o)?;
                m.write(&st.path(&format!("objects/object_{k}.ply")))?;
                m.write(&st.path(&format!("objects/object_{k}.glb")))?;
                mask_png(
                    &objs.masks[k],
                    &st.path(&format!("objects/object_{k}_mask.png")),
                )?;
            }
            let params = serde_json::json!({"frame": "depth camera (OpenCV axes), metres", "up": objs.ground.up, "support_plane": objs.ground.plane, "objects": objs.objects, "segmented": objs.segmented});
            write_text(
                &st.path("objects.json"),
                &serde_json::to_string_pretty(&params)?,
            )?;
            write_record(
                &st,
                capture_dir,
                "objects",
                &cfg,
                seed,
                serde_json::json!({}),
            )?;
            let dir = st.commit()?;
            for (k, o) in objs.objects.iter().enumerate() {
                let t = o.depth_from_object.translation;
                println!(
                    "object {k}: {} at ({:.3}, {:.3}, {:.3}) m, scale {:.3} m, mean surface error {:.1} mm",
                    o.shape,
                    t.x,
                    t.y,
                    t.z,
                    o.depth_from_object.scale,
                    o.mean_surface_error_m * 1e3
                );
            }
            println!(
                "wrote {} in {:.1} s",
                dir.display(),
                t0.elapsed().as_secs_f64()
            );
        }
        Stage::Full => {
            let model = BodyModel::builtin()?;
            let prior = PosePrior::builtin_f64()?;
            let bars = Bars::new(progress);
            let rec = reconstruct(
                &capture,
                BodyPriors {
                    model: &model,
                    prior: &prior,
                },
                &cfg,
                seed,
                &bars,
            )
            .with_context(ctx)?;
            bars.finish();
            // A simulated capture carries its truth: score against it (read only here). A
            // truth that does not read leaves the reconstruction unscored, not unwritten.
            let (truth, unscored) = if Truth::exists(capture_dir) {
                match Truth::load(capture_dir, &model) {
                    Ok(t) => (Some(t), None),
                    Err(e) => (None, Some(e.to_string())),
                }
            } else {
                (None, None)
            };
            let (_, scored) = crate::result::write_scored(
                &st,
                "",
                &crate::result::ResultInputs {
                    capture: &capture,
                    rec: &rec,
                    priors: BodyPriors {
                        model: &model,
                        prior: &prior,
                    },
                    cfg: &cfg,
                    truth: truth.as_ref(),
                },
            )?;
            let html = format!(
                "{}<h1>irmirror reconstruction</h1><p>Capture: <code>{}</code>; reconstruction seed {seed}; irmirror {}. \
                 Settings: <a href=\"run.toml\">run.toml</a>.</p>{}{}</body></html>",
                html_head("irmirror reconstruction"),
                crate::result::esc(&capture_dir.display().to_string()),
                env!("CARGO_PKG_VERSION"),
                scored
                    .as_ref()
                    .map_or(String::new(), |s| crate::result::score_section("", s)),
                crate::result::report_section("", &capture, &rec)
            );
            write_text(&st.path("report.html"), &html)?;
            let secs = t0.elapsed().as_secs_f64();
            write_record(&st, capture_dir, "full", &cfg, seed, serde_json::json!({}))?;
            let dir = st.commit()?;
            print_summary(&rec);
            if let Some(scored) = &scored {
                println!("against the capture's truth:\n{}", scored.text());
            }
            if let Some(why) = unscored {
                println!("note: not scored against the capture's truth: {why}");
            }
            println!("wrote {} in {secs:.1} s (open report.html)", dir.display());
        }
    }
    Ok(())
}

/// One-paragraph summary of a reconstruction.
pub fn print_summary(rec: &Reconstruction) {
    let n = rec.pre.mask.data.iter().filter(|m| **m).count();
    println!(
        "stage 0: {n} reflection pixels (threshold {:.3} K)",
        rec.pre.threshold_k
    );
    for (k, o) in rec.objects.objects.iter().enumerate() {
        println!(
            "stage 1: object {k}: {}, scale {:.3} m, mean surface error {:.1} mm",
            o.shape,
            o.depth_from_object.scale,
            o.mean_surface_error_m * 1e3
        );
    }
    for (k, h) in rec.human.hypotheses.iter().enumerate() {
        let t = h.translation_m;
        println!(
            "stage 2: hypothesis {k}: loss {:.3} (soft IoU {:.2}), root at ({:.2}, {:.2}, {:.2}) m, {:.2} m from the camera, stature {:.2} m",
            h.loss,
            h.soft_iou,
            t[0],
            t[1],
            t[2],
            (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt(),
            h.stature_m
        );
    }
    for note in crate::result::notes(rec) {
        println!("note: {note}");
    }
}

/// The HTML head shared by reports.
pub fn html_head(title: &str) -> String {
    format!(
        r#"<!doctype html><html><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;max-width:70em;margin:2em auto;line-height:1.4}}td,th{{padding:2px 10px;text-align:left;vertical-align:top}}
figure{{display:inline-block;margin:0 1em 1em 0;vertical-align:top}}img{{image-rendering:pixelated}}pre{{background:#f4f4f4;padding:1em;overflow:auto;max-height:20em}}
.note{{background:#fff6d6;border-left:4px solid #e0b000;padding:4px 8px}}.yard{{color:#555;font-size:90%}}</style>
<script>
// The page records on its root element whether it rendered: scripts' errors and images that
// did not load (data-errors, data-broken-images), as a headless browser test reads them.
(function () {{
  var root = document.documentElement, errors = 0;
  function fail() {{ errors += 1; root.setAttribute("data-errors", String(errors)); }}
  window.addEventListener("error", fail, true);
  var log = console.error;
  console.error = function () {{ fail(); log.apply(console, arguments); }};
  window.addEventListener("load", function () {{
    var broken = 0;
    for (var i = 0; i < document.images.length; i++) {{
      if (!document.images[i].complete || document.images[i].naturalWidth === 0) {{ broken += 1; }}
    }}
    root.setAttribute("data-images", String(document.images.length));
    root.setAttribute("data-broken-images", String(broken));
    root.setAttribute("data-errors", String(errors));
  }});
}})();
</script></head><body>"#
    )
}

fn write_record(
    st: &Staging,
    capture_dir: &Path,
    stage: &str,
    cfg: &ReconConfig,
    seed: u64,
    extra: serde_json::Value,
) -> Result<()> {
    let record = serde_json::json!({
        "command": "reconstruct",
        "version": env!("CARGO_PKG_VERSION"),
        "capture": capture_dir.display().to_string(),
        "stage": stage,
        "seed": seed,
        "config": cfg,
        "figures": extra,
    });
    Ok(write_text(
        &st.path("run.toml"),
        &toml::to_string(&record)?,
    )?)
}
