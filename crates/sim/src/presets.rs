//! Scene presets with a visible reflection: the simulator's, the demo's and the tests' scenes.

use crate::people::{random_phenotype, random_pose};
use crate::scene::{SceneFile, ThermalPreset, car, tabletop};
use crate::{SimError, Sensor};
use irmirror_body::BodyModel;
use serde::{Deserialize, Serialize};

/// Scene presets (the paper's setups).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// 1–3 bowls and mugs on a table; the person 0.5–1.5 m behind the cameras.
    Tabletop,
    /// The side of a car; a pedestrian 2.5–8 m away.
    Car,
}

/// Presets redraw their scene (up to this many times) until the person's reflection covers at
/// least [`MIN_REFLECTION_PIXELS`] thermal pixels: small tabletop reflectors often show none.
pub const ATTEMPTS: u64 = 40;
/// See [`ATTEMPTS`].
pub const MIN_REFLECTION_PIXELS: usize = 12;

/// The scene for a preset and seed whose reflection is visible: draws scenes from the seed's
/// successive streams and keeps the first with ≥ [`MIN_REFLECTION_PIXELS`] reflection pixels
/// (or the last drawn).
pub fn preset_scene(model: &BodyModel, preset: Preset, thermal: ThermalPreset, seed: u64) -> Result<SceneFile, SimError> {
    let mut scene = draw_scene(model, preset, thermal, seed, 0);
    for attempt in 1..ATTEMPTS {
        let mut probe = scene.clone();
        probe.sensor = Sensor::ideal();
        if crate::simulate::reflection_pixels(model, &probe)? >= MIN_REFLECTION_PIXELS {
            break;
        }
        scene = draw_scene(model, preset, thermal, seed, attempt);
    }
    Ok(scene)
}

fn draw_scene(model: &BodyModel, preset: Preset, thermal: ThermalPreset, seed: u64, attempt: u64) -> SceneFile {
    let mut rng = irmirror_geom::rng::seeded(seed, 1000 + attempt);
    let phenotype = random_phenotype(&mut rng);
    let (name, rotvecs) = random_pose(model, &mut rng);
    match preset {
        Preset::Tabletop => tabletop(&mut rng, (name, rotvecs), phenotype, thermal),
        Preset::Car => car(&mut rng, (name, rotvecs), phenotype, thermal),
    }
}
