//! `irmirror simulate`: write a synthetic capture with ground truth.

use crate::output::Staging;
use anyhow::{Context, Result};
use irmirror_body::BodyModel;
use irmirror_sim::presets::{Regime, Shapes};
use irmirror_sim::scene::SceneFile;
use irmirror_sim::{SimReport, simulate};
use std::path::{Path, PathBuf};

/// The scene of a regime for a seed whose reflection is visible (see
/// [`irmirror_sim::presets::regime_scene`]).
pub fn regime_scene(
    model: &BodyModel,
    regime: Regime,
    shapes: Shapes,
    seed: u64,
) -> Result<SceneFile> {
    Ok(irmirror_sim::presets::regime_scene(
        model, regime, shapes, seed,
    )?)
}

/// Simulates into `out` (atomically) and returns the figures.
pub fn run(
    model: &BodyModel,
    scene: &SceneFile,
    out: &Path,
    seed: u64,
) -> Result<(SimReport, PathBuf)> {
    let stage = Staging::new(out, "capture.toml")?;
    let sim = simulate(model, scene, seed)?;
    sim.write(model, &stage.path(""), seed)?;
    let dir = stage.commit()?;
    Ok((sim.report, dir))
}

/// Loads a scene file (TOML).
pub fn load_scene(path: &Path) -> Result<SceneFile> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read scene {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("scene {}", path.display()))
}
