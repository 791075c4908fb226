//! Scene presets with a visible reflection: the simulator's, the demo's and the tests' scenes.

use crate::people::{random_phenotype, random_pose};
use crate::scene::{SceneFile, ThermalPreset, car, tabletop};
use crate::{Sensor, SimError};
use irmirror_body::BodyModel;
use irmirror_geom::Category;
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

/// Which shape families a preset's objects come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shapes {
    /// The renderer's two-parameter shapes ([`crate::shapes::Shape`]).
    #[default]
    Simple,
    /// The richer procedural families the learned object priors were trained on
    /// (`irmirror_sdf::families`), each object about the size the simple preset would draw.
    Family,
}

/// Presets redraw their scene (up to this many times) until the person's reflection covers at
/// least [`MIN_REFLECTION_PIXELS`] thermal pixels: small tabletop reflectors often show none.
pub const ATTEMPTS: u64 = 40;
/// See [`ATTEMPTS`].
pub const MIN_REFLECTION_PIXELS: usize = 12;

/// The scene for a preset and seed whose reflection is visible: draws scenes from the seed's
/// successive streams and keeps the first with ≥ [`MIN_REFLECTION_PIXELS`] reflection pixels
/// (or the last drawn).
pub fn preset_scene(
    model: &BodyModel,
    preset: Preset,
    thermal: ThermalPreset,
    seed: u64,
) -> Result<SceneFile, SimError> {
    preset_scene_with(model, preset, thermal, Shapes::Simple, seed)
}

/// [`preset_scene`] with the objects' shapes drawn from `shapes`.
pub fn preset_scene_with(
    model: &BodyModel,
    preset: Preset,
    thermal: ThermalPreset,
    shapes: Shapes,
    seed: u64,
) -> Result<SceneFile, SimError> {
    let mut scene = draw_scene(model, preset, thermal, shapes, seed, 0);
    for attempt in 1..ATTEMPTS {
        let mut probe = scene.clone();
        probe.sensor = Sensor::ideal();
        if crate::simulate::reflection_pixels(model, &probe)? >= MIN_REFLECTION_PIXELS {
            break;
        }
        scene = draw_scene(model, preset, thermal, shapes, seed, attempt);
    }
    Ok(scene)
}

fn draw_scene(
    model: &BodyModel,
    preset: Preset,
    thermal: ThermalPreset,
    shapes: Shapes,
    seed: u64,
    attempt: u64,
) -> SceneFile {
    let mut rng = irmirror_geom::rng::seeded(seed, 1000 + attempt);
    let phenotype = random_phenotype(&mut rng);
    let (name, rotvecs) = random_pose(model, &mut rng);
    let mut scene = match preset {
        Preset::Tabletop => tabletop(&mut rng, (name, rotvecs), phenotype, thermal),
        Preset::Car => car(&mut rng, (name, rotvecs), phenotype, thermal),
    };
    if shapes == Shapes::Family {
        // Its own stream: the rest of the scene is the simple preset's, draw for draw.
        let mut rng = irmirror_geom::rng::seeded(seed, 2000 + attempt);
        for o in &mut scene.objects {
            if let Some((shape, scale_m)) = o.shape.family_like(o.scale_m, &mut rng) {
                (o.shape, o.scale_m) = (shape, scale_m);
            }
        }
    }
    scene
}

/// The benchmark's scene of one category: the car preset, or the tabletop preset keeping only
/// objects of the category (mugs: a lower rig and the Boson-like camera), redrawn from draw
/// `first_attempt` on until the reflection shows (≥ [`MIN_REFLECTION_PIXELS`] with an ideal
/// sensor); the scene and the draw that made it. The NETD is set to `netd_mk`.
pub fn benchmark_scene(
    model: &BodyModel,
    category: Category,
    seed: u64,
    netd_mk: f64,
    first_attempt: u64,
) -> Result<(SceneFile, u64), SimError> {
    for attempt in first_attempt..BENCHMARK_ATTEMPTS {
        let mut rng = irmirror_geom::rng::seeded(seed, 1000 + attempt);
        let phenotype = random_phenotype(&mut rng);
        let pose = random_pose(model, &mut rng);
        let mut scene = if category == Category::Car {
            crate::scene::car(&mut rng, pose, phenotype, ThermalPreset::Lepton)
        } else {
            let mut sc = crate::scene::tabletop(&mut rng, pose, phenotype, ThermalPreset::Lepton);
            sc.objects.retain(|o| o.shape.category() == category);
            if category == Category::Mug && !sc.objects.is_empty() {
                // A mug's side reflects near-horizontal rays only: from the preset's camera
                // (55 cm above the table) they pass over the person's head. Lower the rig to
                // 20 cm above the table, 40 cm from the mugs, as one films a mug; and a mug is a
                // small convex mirror: the person covers 1–3 Lepton pixels, so mug scenes use
                // the Boson-like 640×512 camera.
                let n = sc.objects.len() as f64;
                let (cx, cy) = (
                    sc.objects.iter().map(|o| o.base_m[0]).sum::<f64>() / n,
                    sc.objects.iter().map(|o| o.base_m[1]).sum::<f64>() / n,
                );
                let pose = crate::scene::look_at(
                    nalgebra::Vector3::new(cx, cy + 0.4, 0.95),
                    nalgebra::Vector3::new(cx, cy, 0.8),
                );
                sc.depth_camera.world_from_camera =
                    irmirror_geom::transform::RigidFile::from_rigid(&pose);
                sc.thermal_camera.intrinsics = ThermalPreset::Boson.camera();
            }
            sc
        };
        if scene.objects.is_empty() {
            continue;
        }
        let mut probe = scene.clone();
        probe.sensor = Sensor::ideal();
        if crate::simulate::reflection_pixels(model, &probe)? >= MIN_REFLECTION_PIXELS {
            scene.sensor.netd_mk = netd_mk;
            return Ok((scene, attempt));
        }
    }
    Err(SimError::Scene(format!(
        "no {category} scene with a visible reflection from seed {seed} in {BENCHMARK_ATTEMPTS} draws"
    )))
}

/// Scene draws tried per benchmark capture (single-category tabletop scenes reflect the person
/// less often).
pub const BENCHMARK_ATTEMPTS: u64 = 200;
