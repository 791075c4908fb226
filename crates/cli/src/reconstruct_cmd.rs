//! `irmirror reconstruct`: the pipeline on a capture. Built so far: stage 0 (thermal
//! preprocessing); the object and human fits follow with the object priors.

use crate::output::{Staging, write_text};
use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use irmirror_capture::{Capture, Image, write_gray8_png};
use irmirror_recon::{PreprocessConfig, preprocess};
use std::path::Path;

/// How far to run.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Stage {
    /// Stage 0: reflection mask and edge map, with every intermediate in debug/.
    Preprocess,
    /// Stage 1: object fits (not built yet).
    Objects,
    /// Stages 1 and 2: objects and the person (not built yet).
    Full,
}

fn mask_png(img: &Image<bool>, path: &Path) -> Result<()> {
    write_gray8_png(&img.map(|b| if b { 255 } else { 0 }), path)?;
    Ok(())
}

/// Runs the pipeline up to `stage` on `capture_dir`, writing `out` atomically.
pub fn run(capture_dir: &Path, out: &Path, stage: Stage, config: Option<&Path>) -> Result<()> {
    if !matches!(stage, Stage::Preprocess) {
        bail!("only `--stage preprocess` is built so far: the object and human fits need the object priors (open issues 4, 7, 8)");
    }
    let cfg: PreprocessConfig = match config {
        Some(p) => toml::from_str(&std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?)
            .with_context(|| format!("config {}", p.display()))?,
        None => PreprocessConfig::default(),
    };
    let capture = Capture::load(capture_dir)?;
    let pre = preprocess(&capture, &cfg).with_context(|| format!("capture {}", capture_dir.display()))?;
    let stage_dir = Staging::new(out, "run.toml")?;
    std::fs::create_dir_all(stage_dir.path("debug"))?;
    let max = pre.rise_k.data.iter().copied().fold(1e-9, f64::max);
    write_gray8_png(&pre.rise_k.map(|r| (r / max * 255.0).clamp(0.0, 255.0) as u8), &stage_dir.path("debug/rise.png"))?;
    mask_png(&pre.object_pixels, &stage_dir.path("debug/object_pixels.png"))?;
    mask_png(&pre.raw_mask, &stage_dir.path("debug/mask_raw.png"))?;
    mask_png(&pre.mask, &stage_dir.path("reflection_mask.png"))?;
    mask_png(&pre.edges, &stage_dir.path("debug/edges.png"))?;
    let n = pre.mask.data.iter().filter(|m| **m).count();
    let record = toml::to_string(&serde_json::json!({
        "command": "reconstruct",
        "version": env!("CARGO_PKG_VERSION"),
        "capture": capture_dir.display().to_string(),
        "stage": "preprocess",
        "preprocess": cfg,
        "threshold_k": pre.threshold_k,
        "noise_k": pre.noise_k,
        "reflection_pixels": n,
    }))?;
    write_text(&stage_dir.path("run.toml"), &record)?;
    let dir = stage_dir.commit()?;
    println!(
        "stage 0: {n} reflection pixels (threshold {:.3} K over a noise of {:.3} K) on {} object pixels; wrote {}",
        pre.threshold_k,
        pre.noise_k,
        pre.object_pixels.data.iter().filter(|m| **m).count(),
        dir.display()
    );
    Ok(())
}
