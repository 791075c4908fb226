//! Scene presets with a visible reflection: the simulator's, the demo's and the tests' scenes.

use crate::people::{random_phenotype, random_pose};
use crate::scene::{SceneFile, ThermalPreset, car, tabletop};
use crate::{Sensor, SimError};
use irmirror_body::BodyModel;
use irmirror_geom::Category;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Scene presets (the paper's setups).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// 1–3 bowls and mugs on a table seen from 0.7 m; the person 0.5–1.5 m behind the cameras.
    Tabletop,
    /// The side of a car; a pedestrian 2.5–8 m away.
    Car,
    /// 1–3 bowls and mugs side by side seen from 0.35–0.5 m ([`crate::scene::tabletop_close`]).
    TabletopClose,
}

/// Capture regimes: the rig (thermal camera, lens, distances) a scene is drawn for. Results are
/// reported per regime, never pooled (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Regime {
    /// Paper-like (default): a Boson-class 640×512, 50° thermal camera 0.35–0.5 m from 1–3 bowls
    /// and mugs, 6–35 cm above the table, so the objects fill much of its view; the person
    /// 0.5–2 m from the objects, behind the cameras.
    Tabletop,
    /// Paper-like: the side of a car seen by a Boson-class 640×512, 50° camera from 1.5–3 m; a
    /// pedestrian 2.5–8 m from the car, any facing.
    Car,
    /// Hard: a Lepton-class 160×120, 57° camera 0.55 m above and 0.45 m back from a table
    /// (1–3 objects spread over 40 cm); the person 0.5–1.5 m behind the cameras; reflections of
    /// 10–25 pixels.
    TabletopWide,
}

impl Regime {
    /// Every regime.
    pub const ALL: [Regime; 3] = [Regime::Tabletop, Regime::Car, Regime::TabletopWide];

    /// The name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Regime::Tabletop => "tabletop",
            Regime::Car => "car",
            Regime::TabletopWide => "tabletop-wide",
        }
    }

    /// The thermal camera of the regime.
    pub fn thermal(self) -> ThermalPreset {
        match self {
            Regime::Tabletop | Regime::Car => ThermalPreset::Boson,
            Regime::TabletopWide => ThermalPreset::Lepton,
        }
    }
}

impl std::fmt::Display for Regime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The scene of a regime for a seed whose reflection is visible (≥ [`MIN_REFLECTION_PIXELS`]
/// with an ideal sensor, else the last of [`ATTEMPTS`] draws).
pub fn regime_scene(
    model: &BodyModel,
    regime: Regime,
    shapes: Shapes,
    seed: u64,
) -> Result<SceneFile, SimError> {
    let mut scene = draw_regime(model, regime, shapes, seed, 0);
    for attempt in 1..ATTEMPTS {
        if visible(model, &scene)? {
            break;
        }
        scene = draw_regime(model, regime, shapes, seed, attempt);
    }
    Ok(scene)
}

/// The regimes' acceptance rule: the reflection covers ≥ [`MIN_REFLECTION_PIXELS`] (ideal
/// sensor) and neither camera sees the person directly.
fn visible(model: &BodyModel, scene: &SceneFile) -> Result<bool, SimError> {
    let mut probe = scene.clone();
    probe.sensor = Sensor::ideal();
    let p = crate::simulate::reflection_probe(model, &probe)?;
    Ok(p.pixels >= MIN_REFLECTION_PIXELS && !p.directly_visible)
}

fn draw_regime(
    model: &BodyModel,
    regime: Regime,
    shapes: Shapes,
    seed: u64,
    attempt: u64,
) -> SceneFile {
    match regime {
        Regime::TabletopWide => draw_scene(
            model,
            Preset::Tabletop,
            ThermalPreset::Lepton,
            shapes,
            seed,
            attempt,
        ),
        Regime::Car => {
            let mut scene = draw_scene(
                model,
                Preset::Car,
                ThermalPreset::Boson,
                shapes,
                seed,
                attempt,
            );
            // The car preset's cameras stand 1.5 m from the door; the regime's 1.5–3 m, always
            // between the car and the pedestrian (at least 2 m in front of them). Its own stream:
            // the rest of the scene is the preset's, draw for draw.
            let mut rng = irmirror_geom::rng::seeded(seed, 3000 + attempt);
            let person_from_door = crate::scene::CAR_SIDE_Y_M - scene.person.position_m[1];
            let room = (person_from_door - 1.5 - 2.0).clamp(0.0, 1.5);
            let back = rng.random_range(0.0..=room);
            if let Ok(pose) = scene.depth_camera.world_from_camera.to_rigid() {
                let eye = pose.translation - nalgebra::Vector3::new(0.0, back, 0.0);
                let target = nalgebra::Vector3::new(eye.x, 0.0, 0.8);
                scene.depth_camera.world_from_camera =
                    irmirror_geom::transform::RigidFile::from_rigid(&crate::scene::look_at(
                        eye, target,
                    ));
            }
            scene
        }
        Regime::Tabletop => draw_scene(
            model,
            Preset::TabletopClose,
            ThermalPreset::Boson,
            shapes,
            seed,
            attempt,
        ),
    }
}

/// Which shape families a preset's objects come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Shapes {
    /// The renderer's two-parameter shapes (`irmirror_render::shapes::Shape`).
    #[default]
    Simple,
    /// The richer procedural families the learned object priors were trained on
    /// (`irmirror_sdf::families`), each object about the size the simple preset would draw.
    Family,
    /// Shapes from outside those families (`irmirror_sdf::unseen`: polygonal and beaded
    /// bowls, barrel mugs with strap or ring handles, coupés, vans and pickups), sized the same
    /// way: what the fits are measured on out of family.
    Unseen,
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
        Preset::TabletopClose => {
            crate::scene::tabletop_close(&mut rng, (name, rotvecs), phenotype, thermal)
        }
    };
    family_shapes(&mut scene, shapes, seed, attempt);
    draw_temperatures(&mut scene.person, seed, attempt);
    scene
}

/// Draws the person's face, skin, hair and clothing temperatures uniformly in the cited ranges
/// of `irmirror_body::regions::THERMAL` (own random stream: the rest of the scene does not
/// depend on it).
fn draw_temperatures(person: &mut crate::scene::Person, seed: u64, attempt: u64) {
    let mut rng = irmirror_geom::rng::seeded(seed, 5000 + attempt);
    let mut draw = |r: irmirror_body::Region| {
        let [lo, hi] = r.thermal().temp_c;
        rng.random_range(lo..=hi)
    };
    use irmirror_body::Region::{Clothing, Face, Hair, Skin};
    person.clothing_c = draw(Clothing);
    person.skin_c = draw(Skin);
    person.face_c = Some(draw(Face));
    person.hair_c = Some(draw(Hair));
}

/// With [`Shapes::Family`] or [`Shapes::Unseen`], replaces each simple shape by one of about
/// its size from those shapes.
fn family_shapes(scene: &mut SceneFile, shapes: Shapes, seed: u64, attempt: u64) {
    if shapes != Shapes::Simple {
        // Its own stream: the rest of the scene is the simple preset's, draw for draw.
        let mut rng = irmirror_geom::rng::seeded(seed, 2000 + attempt);
        let unseen = shapes == Shapes::Unseen;
        for o in &mut scene.objects {
            if let Some((shape, scale_m)) = o.shape.replaced(o.scale_m, unseen, &mut rng) {
                (o.shape, o.scale_m) = (shape, scale_m);
            }
        }
    }
}

/// A cell of the benchmark: a regime, and for tabletop regimes the one object type its scenes
/// keep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Cell {
    /// Paper-like tabletop, bowls only.
    TabletopBowl,
    /// Paper-like tabletop, mugs only.
    TabletopMug,
    /// Paper-like car.
    Car,
    /// The hard wide-view tabletop (bowls and mugs).
    TabletopWide,
}

impl Cell {
    /// Every cell, in the table's row order.
    pub const ALL: [Cell; 4] = [
        Cell::TabletopBowl,
        Cell::TabletopMug,
        Cell::Car,
        Cell::TabletopWide,
    ];

    /// The regime.
    pub fn regime(self) -> Regime {
        match self {
            Cell::TabletopBowl | Cell::TabletopMug => Regime::Tabletop,
            Cell::Car => Regime::Car,
            Cell::TabletopWide => Regime::TabletopWide,
        }
    }

    /// The object type kept (`None`: all of the regime's objects).
    pub fn category(self) -> Option<Category> {
        match self {
            Cell::TabletopBowl => Some(Category::Bowl),
            Cell::TabletopMug => Some(Category::Mug),
            Cell::Car | Cell::TabletopWide => None,
        }
    }

    /// The name in tables and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Cell::TabletopBowl => "tabletop-bowl",
            Cell::TabletopMug => "tabletop-mug",
            Cell::Car => "car",
            Cell::TabletopWide => "tabletop-wide",
        }
    }
}

impl std::fmt::Display for Cell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The benchmark's scene of one cell: the regime's scene (objects from `shapes`) keeping only the
/// cell's object type, redrawn from draw `first_attempt` on until objects remain and the reflection shows (≥
/// [`MIN_REFLECTION_PIXELS`] with an ideal sensor); the scene and the draw that made it. The NETD
/// is set to `netd_mk`. The person's pose is a motion-capture pose
/// ([`irmirror_body::mocap::MocapSet::builtin`]), not one of the pose prior's templates.
pub fn benchmark_scene(
    model: &BodyModel,
    cell: Cell,
    shapes: Shapes,
    seed: u64,
    netd_mk: f64,
    first_attempt: u64,
) -> Result<(SceneFile, u64), SimError> {
    let mocap = irmirror_body::mocap::MocapSet::builtin()?;
    for attempt in first_attempt..BENCHMARK_ATTEMPTS {
        let mut scene = draw_regime(model, cell.regime(), shapes, seed, attempt);
        // The person's pose: real motion capture, not the pose prior's own generator (its own
        // stream: the rest of the scene is the regime's, draw for draw).
        let mut rng = irmirror_geom::rng::seeded(seed, 4000 + attempt);
        let k = rng.random_range(0..mocap.poses.len());
        scene.person.rotvec_rad = mocap.poses[k].clone();
        scene.person.pose_name = format!("mocap {}", mocap.sources[k]);
        if let Some(c) = cell.category() {
            scene.objects.retain(|o| o.shape.category() == c);
        }
        if !scene.objects.is_empty() && visible(model, &scene)? {
            scene.sensor.netd_mk = netd_mk;
            return Ok((scene, attempt));
        }
    }
    Err(SimError::Scene(format!(
        "no {cell} scene with a visible reflection from seed {seed} in {BENCHMARK_ATTEMPTS} draws"
    )))
}

/// Scene draws tried per benchmark capture (single-category scenes reflect the person less
/// often).
pub const BENCHMARK_ATTEMPTS: u64 = 200;
