//! `irmirror simulate`: write a synthetic capture with ground truth.

use crate::output::Staging;
use crate::poses;
use anyhow::{Context, Result};
use clap::ValueEnum;
use irmirror_body::BodyModel;
use irmirror_sim::scene::{SceneFile, car, tabletop};
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

/// Thermal camera presets.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Thermal {
    /// FLIR Lepton 3.5-like, 160×120, 57° HFOV.
    Lepton,
    /// FLIR Boson-like, 640×512, 50° HFOV.
    Boson,
}

/// Presets redraw their scene (up to this many times) until the person's reflection covers at
/// least [`MIN_REFLECTION_PIXELS`] thermal pixels: small tabletop reflectors often show none.
const ATTEMPTS: u64 = 40;
/// See [`ATTEMPTS`].
pub const MIN_REFLECTION_PIXELS: usize = 12;

/// The scene for a preset and seed whose reflection is visible: draws scenes from the seed's
/// successive streams and keeps the first with ≥ 12 reflection pixels (or the last drawn).
pub fn preset_scene(model: &BodyModel, preset: Preset, thermal: Thermal, seed: u64) -> Result<SceneFile> {
    let mut scene = draw_scene(model, preset, thermal, seed, 0);
    for attempt in 1..ATTEMPTS {
        let mut probe = scene.clone();
        probe.sensor = irmirror_sim::Sensor::ideal();
        if irmirror_sim::simulate::reflection_pixels(model, &probe)? >= MIN_REFLECTION_PIXELS {
            break;
        }
        scene = draw_scene(model, preset, thermal, seed, attempt);
    }
    Ok(scene)
}

fn draw_scene(model: &BodyModel, preset: Preset, thermal: Thermal, seed: u64, attempt: u64) -> SceneFile {
    let mut rng = irmirror_geom::rng::seeded(seed, 1000 + attempt);
    let phenotype = poses::random_phenotype(&mut rng);
    let (name, rotvecs) = poses::random_pose(model, &mut rng);
    let t = match thermal {
        Thermal::Lepton => ThermalPreset::Lepton,
        Thermal::Boson => ThermalPreset::Boson,
    };
    match preset {
        Preset::Tabletop => tabletop(&mut rng, (name, rotvecs), phenotype, t),
        Preset::Car => car(&mut rng, (name, rotvecs), phenotype, t),
    }
}

/// Simulates into `out` (atomically) and returns the figures.
pub fn run(model: &BodyModel, scene: &SceneFile, out: &Path, seed: u64) -> Result<(SimReport, PathBuf)> {
    let stage = Staging::new(out, "capture.toml")?;
    let sim = simulate(model, scene, seed)?;
    sim.write(model, &stage.path(""), seed)?;
    let dir = stage.commit()?;
    Ok((sim.report, dir))
}

/// Loads a scene file (TOML).
pub fn load_scene(path: &Path) -> Result<SceneFile> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read scene {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("scene {}", path.display()))
}
