//! `irmirror simulate`: write a synthetic capture with ground truth.

use crate::output::Staging;
use anyhow::{Context, Result};
use clap::ValueEnum;
use irmirror_body::BodyModel;
use irmirror_sim::scene::SceneFile;
use irmirror_sim::{SimReport, ThermalPreset, simulate};
use std::path::{Path, PathBuf};

/// Scene presets (the paper's setups).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Preset {
    /// 1–3 bowls and mugs on a table; the person 1–2.2 m away, behind the cameras.
    Tabletop,
    /// The side of a car; a pedestrian 2–8 m away.
    Car,
}

/// Which shape families the preset's objects come from.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ShapeSet {
    /// The renderer's two-parameter bowls, mugs and cars.
    Simple,
    /// The richer procedural families the learned object priors were trained on (tapered mugs
    /// with varied handles, flared bowls with feet, sedans to SUVs).
    Family,
}

impl From<ShapeSet> for irmirror_sim::presets::Shapes {
    fn from(s: ShapeSet) -> Self {
        match s {
            ShapeSet::Simple => Self::Simple,
            ShapeSet::Family => Self::Family,
        }
    }
}

/// Thermal camera presets.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Thermal {
    /// FLIR Lepton 3.5-like, 160×120, 57° HFOV.
    Lepton,
    /// FLIR Boson-like, 640×512, 50° HFOV.
    Boson,
}

/// The scene for a preset and seed whose reflection is visible (see
/// [`irmirror_sim::presets::preset_scene`]).
pub fn preset_scene(
    model: &BodyModel,
    preset: Preset,
    thermal: Thermal,
    seed: u64,
) -> Result<SceneFile> {
    preset_scene_with(
        model,
        preset,
        thermal,
        irmirror_sim::presets::Shapes::Simple,
        seed,
    )
}

/// [`preset_scene`] with the objects drawn from `shapes`.
pub fn preset_scene_with(
    model: &BodyModel,
    preset: Preset,
    thermal: Thermal,
    shapes: irmirror_sim::presets::Shapes,
    seed: u64,
) -> Result<SceneFile> {
    let p = match preset {
        Preset::Tabletop => irmirror_sim::presets::Preset::Tabletop,
        Preset::Car => irmirror_sim::presets::Preset::Car,
    };
    let t = match thermal {
        Thermal::Lepton => ThermalPreset::Lepton,
        Thermal::Boson => ThermalPreset::Boson,
    };
    Ok(irmirror_sim::presets::preset_scene_with(
        model, p, t, shapes, seed,
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
