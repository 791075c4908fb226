//! Scene files and the presets that generate them from a seed.
//!
//! The scene's own frame ("world") is Z up, metres, floor at z = 0; cameras are placed by
//! `world_from_camera` (OpenCV camera axes). Everything is converted to the depth-camera frame
//! before rendering.

use crate::shapes::Shape;
use irmirror_body::{Phenotype, Region};
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_geom::transform::RigidFile;
use irmirror_geom::{PinholeCamera, Rigid3};
use irmirror_render::sdf::Sdf;
use irmirror_sdf::{Category, FamilyShape, UnseenShape};
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A complete scene description (TOML or JSON).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Room (walls, air) temperature, °C.
    pub ambient_c: f64,
    /// The depth camera (the reconstruction frame) and its pose in the world.
    pub depth_camera: PlacedCamera,
    /// The thermal camera's intrinsics and `depth_from_thermal`.
    pub thermal_camera: ThermalCamera,
    /// The evaluation camera that sees the person (written to `truth/` only).
    pub third_camera: PlacedCamera,
    /// Optional table (a horizontal rectangle).
    #[serde(default)]
    pub table: Option<Table>,
    /// The reflecting objects.
    pub objects: Vec<SceneObject>,
    /// The person.
    pub person: Person,
    /// Extra heat sources (black spheres).
    #[serde(default)]
    pub heat_sources: Vec<HeatSource>,
    /// Sensor models.
    #[serde(default)]
    pub sensor: Sensor,
}

/// A camera and its pose.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlacedCamera {
    /// Intrinsics.
    #[serde(flatten)]
    pub intrinsics: PinholeCamera,
    /// Camera frame → world frame.
    pub world_from_camera: RigidFile,
}

/// The thermal camera.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThermalCamera {
    /// Intrinsics.
    #[serde(flatten)]
    pub intrinsics: PinholeCamera,
    /// Thermal frame → depth frame.
    pub depth_from_thermal: RigidFile,
}

/// A table top.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// Height of the top, m.
    pub height_m: f64,
    /// Centre (x, y) in the world, m.
    pub centre_m: [f64; 2],
    /// Size (x, y), m.
    pub size_m: [f64; 2],
    /// Temperature, °C.
    pub temp_c: f64,
    /// LWIR emissivity (wood, laminate ≈ 0.9–0.95).
    pub emissivity: f64,
}

/// An object's shape: a member of the renderer's two-parameter families, or of the richer
/// procedural families the learned object priors were trained on (`irmirror_sdf::families`:
/// tapered mugs with varied handles, flared bowls with feet, sedans to SUVs), or from outside
/// them (`irmirror_sdf::unseen`). In a scene file each is a table with a `category`; the
/// parameter names tell them apart.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(
    untagged,
    expecting = "an object shape: `category` and its parameters (bowl: cut, wall; mug: aspect, wall; car: cabin, height; or the parameters of an irmirror_sdf::families or irmirror_sdf::unseen shape)"
)]
pub enum ObjectShape {
    /// [`Shape`] (normalised to the unit sphere).
    Simple(Shape),
    /// [`FamilyShape`] (normalised: bounding-box half-diagonal 0.9).
    Family(FamilyShape),
    /// [`UnseenShape`]: a shape from outside the priors' families (normalised the same way).
    Unseen(UnseenShape),
}

impl From<Shape> for ObjectShape {
    fn from(s: Shape) -> Self {
        ObjectShape::Simple(s)
    }
}

impl ObjectShape {
    /// The category.
    pub fn category(&self) -> Category {
        match self {
            ObjectShape::Simple(s) => s.category(),
            ObjectShape::Family(f) => f.category(),
            ObjectShape::Unseen(u) => u.category(),
        }
    }

    /// The signed distance field (object frame, +Y up).
    pub fn sdf(&self) -> Arc<dyn Sdf> {
        match self {
            ObjectShape::Simple(s) => s.sdf(),
            ObjectShape::Family(f) => Arc::new(f.prepare()),
            ObjectShape::Unseen(u) => Arc::new(u.prepare()),
        }
    }

    /// Lowest object-frame y of the surface.
    pub fn base_y(&self) -> f64 {
        match self {
            ObjectShape::Simple(s) => s.base_y(),
            ObjectShape::Family(f) => {
                let (lo, _) = f.raw_bounds();
                let (centre, k) = f.normalisation();
                (lo.y - centre.y) / k
            }
            ObjectShape::Unseen(u) => {
                let (lo, _) = u.raw_bounds();
                let (centre, k) = u.normalisation();
                (lo.y - centre.y) / k
            }
        }
    }

    /// A shape of the same category and about the same metric size (widest horizontal radius;
    /// a car's length), drawn from the priors' families (`unseen` false) or from the
    /// out-of-family generator (`irmirror_sdf::unseen`, true); returns the shape and its
    /// `scale_m`. `None` for categories without either (the sphere).
    pub fn replaced(
        &self,
        scale_m: f64,
        unseen: bool,
        rng: &mut impl Rng,
    ) -> Option<(ObjectShape, f64)> {
        let ObjectShape::Simple(simple) = *self else {
            return Some((*self, scale_m));
        };
        // The simple shape's widest radius (or half length), metres.
        let (category, half_m) = match simple {
            Shape::Sphere => return None,
            Shape::Bowl { wall, .. } => (Category::Bowl, 0.95 * (1.0 + 0.5 * wall) * scale_m),
            Shape::Mug { aspect, .. } => (
                Category::Mug,
                0.9 / (1.0f64 + aspect * aspect).sqrt() / 1.2 * scale_m,
            ),
            Shape::Car { .. } => (Category::Car, 0.95 * scale_m),
        };
        // `k` and the widest radius (half length) in raw units.
        let (shape, k, raw_half) = if unseen {
            let u = UnseenShape::sample(category, rng).ok()?;
            (
                ObjectShape::Unseen(u),
                u.normalisation().1,
                u.raw_half_size(),
            )
        } else {
            let family = FamilyShape::sample(category, rng).ok()?;
            let raw_half = match family {
                FamilyShape::Bowl(b) => 1.0 + b.flare + 0.5 * b.wall,
                FamilyShape::Mug(m) => 1.0 + m.taper.max(0.0),
                FamilyShape::Car(_) => 1.0,
            };
            (
                ObjectShape::Family(family),
                family.normalisation().1,
                raw_half,
            )
        };
        Some((shape, half_m / raw_half * k))
    }
}

/// A reflecting object.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneObject {
    /// Shape and parameters.
    pub shape: ObjectShape,
    /// Base centre (x, y) and the height it stands on (z), world, m.
    pub base_m: [f64; 3],
    /// Rotation about the world Z axis, rad.
    pub yaw_rad: f64,
    /// Metres per object unit (≈ half the object's size).
    pub scale_m: f64,
    /// LWIR emissivity (glazed ceramic 0.90–0.92, car paint 0.92–0.94, polished steel 0.07).
    pub emissivity: f64,
    /// Temperature, °C.
    pub temp_c: f64,
}

/// How the person stands.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Person {
    /// Body shape.
    pub phenotype: Phenotype,
    /// Joint rotation vectors (36 × 3, rad, world-aligned rest axes); root = global.
    pub rotvec_rad: Vec<[f64; 3]>,
    /// Name of the pose (documentation only).
    #[serde(default)]
    pub pose_name: String,
    /// Floor position (x, y) of the body's centre, world, m.
    pub position_m: [f64; 2],
    /// Heading about world Z, rad (0: the person faces −Y of the world).
    pub yaw_rad: f64,
    /// Exposed skin temperature, °C (≈ 34).
    pub skin_c: f64,
    /// Clothing surface temperature, °C (≈ 28–31).
    pub clothing_c: f64,
    /// Face temperature, °C; absent: `skin_c` (scene files written before the face had its own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_c: Option<f64>,
    /// Surface temperature of the hair on the scalp, °C; absent: the scalp is bare skin at
    /// `skin_c` (scene files written before hair was modelled).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hair_c: Option<f64>,
}

impl Person {
    /// Temperature (°C) and emissivity of a body region (`irmirror_body::regions`).
    pub fn region_temperature(&self, region: Region) -> (f64, f64) {
        let skin = Region::Skin.thermal().emissivity;
        match region {
            Region::Clothing => (self.clothing_c, region.thermal().emissivity),
            Region::Skin => (self.skin_c, skin),
            Region::Face => (self.face_c.unwrap_or(self.skin_c), skin),
            Region::Hair => match self.hair_c {
                Some(t) => (t, region.thermal().emissivity),
                None => (self.skin_c, skin),
            },
        }
    }
}

/// A heat source (black body sphere).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HeatSource {
    /// Centre, world, m.
    pub centre_m: [f64; 3],
    /// Radius, m.
    pub radius_m: f64,
    /// Temperature, °C.
    pub temp_c: f64,
}

/// Sensor models.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Sensor {
    /// Thermal noise-equivalent temperature difference, mK (Gaussian, per pixel).
    pub netd_mk: f64,
    /// Optics blur, Gaussian σ in pixels (0: none).
    pub blur_px: f64,
    /// Sub-pixel rays per axis (total s²) that integrate a thermal pixel's box where the image
    /// varies near it; flat neighbourhoods keep a 4 × 4 probe (`sensor::supersampled_adaptive`).
    /// 8 (default): a pixel's coverage by a small reflection to within ≈ 1/64 of the pixel.
    pub supersample: u32,
    /// ADC bits of the raw thermal counts.
    pub bits: u32,
    /// Depth noise σ = `depth_noise_per_m2 · z²`, m (structured light ≈ 1.5e-3).
    pub depth_noise_per_m2: f64,
    /// Depth dropouts where |cos(incidence)| is below this.
    pub depth_grazing_cos: f64,
    /// Probability of a hole at a depth discontinuity (> 3 cm between neighbours).
    pub depth_edge_hole: f64,
    /// Error of the IMU's "up" written into the capture, degrees (σ per tilt axis; consumer
    /// RGB-D IMUs after calibration ≈ 0.5°).
    pub imu_up_noise_deg: f64,
}

impl Default for Sensor {
    fn default() -> Self {
        Self {
            netd_mk: 50.0,
            blur_px: 0.5,
            supersample: 8,
            bits: 14,
            depth_noise_per_m2: 1.5e-3,
            depth_grazing_cos: 0.1,
            depth_edge_hole: 0.5,
            imu_up_noise_deg: 0.5,
        }
    }
}

impl Sensor {
    /// An ideal sensor (no noise, blur, dropouts; one ray per pixel) for tests.
    pub fn ideal() -> Self {
        Self {
            netd_mk: 0.0,
            blur_px: 0.0,
            supersample: 1,
            bits: 16,
            depth_noise_per_m2: 0.0,
            depth_grazing_cos: 0.0,
            depth_edge_hole: 0.0,
            imu_up_noise_deg: 0.0,
        }
    }
}

/// Thermal camera presets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ThermalPreset {
    /// FLIR Lepton 3.5-like: 160×120, 57° HFOV.
    Lepton,
    /// FLIR Boson-like: 640×512, 50° HFOV.
    Boson,
}

impl ThermalPreset {
    /// The intrinsics.
    pub fn camera(self) -> PinholeCamera {
        match self {
            ThermalPreset::Lepton => PinholeCamera::from_fov(160, 120, 57f64.to_radians()),
            ThermalPreset::Boson => PinholeCamera::from_fov(640, 512, 50f64.to_radians()),
        }
        .expect("preset intrinsics are valid")
    }
}

/// A camera at `eye` looking at `target` (world Z up), as `world_from_camera`.
pub fn look_at(eye: Vector3<f64>, target: Vector3<f64>) -> Rigid3<f64> {
    let z = (target - eye).normalize();
    let up = Vector3::z();
    let x = z.cross(&up).try_normalize(1e-9).unwrap_or_else(Vector3::x);
    let y = z.cross(&x);
    Rigid3 {
        rotation: Matrix3::from_columns(&[x, y, z]),
        translation: eye,
    }
}

fn small_baseline() -> RigidFile {
    // Thermal camera 4 cm to the right of the depth camera, parallel axes.
    RigidFile::from_rigid(&Rigid3 {
        rotation: Matrix3::identity(),
        translation: Vector3::new(0.04, 0.0, 0.0),
    })
}

/// The presets' table: 1.4 × 0.9 m, top at 0.75 m, 22 °C, ε 0.93.
const TABLE: Table = Table {
    height_m: 0.75,
    centre_m: [0.0, 0.0],
    size_m: [1.4, 0.9],
    temp_c: 22.0,
    emissivity: 0.93,
};

/// Where and how large a tabletop preset draws its glazed bowls and mugs (world, metres).
struct Layout {
    /// Bowl scale (rim radius) range.
    bowl_scale_m: std::ops::Range<f64>,
    /// Mug scale range.
    mug_scale_m: std::ops::Range<f64>,
    /// Base position ranges on the table.
    x_m: std::ops::Range<f64>,
    /// See `x_m`.
    y_m: std::ops::Range<f64>,
    /// Clearance between two objects' bounding circles.
    gap_m: f64,
}

/// The wide preset's layout: objects anywhere over 40 cm × 26 cm.
const SPREAD_LAYOUT: Layout = Layout {
    bowl_scale_m: 0.08..0.12,
    mug_scale_m: 0.06..0.08,
    x_m: -0.2..0.2,
    y_m: -0.18..0.08,
    gap_m: 0.02,
};

/// The close rig's layout: smaller objects side by side, a little depth between them.
const CLOSE_LAYOUT: Layout = Layout {
    bowl_scale_m: 0.06..0.09,
    mug_scale_m: 0.05..0.07,
    x_m: -0.13..0.13,
    y_m: -0.05..0.05,
    gap_m: 0.015,
};

/// Draws `n` non-overlapping glazed bowls and mugs (half each, on average) on the table, giving
/// up after `tries` draws.
fn place_objects(rng: &mut impl Rng, n: usize, layout: &Layout, tries: usize) -> Vec<SceneObject> {
    let mut objects: Vec<SceneObject> = Vec::new();
    let mut tried = 0;
    while objects.len() < n && tried < tries {
        tried += 1;
        let (shape, scale) = if rng.random_bool(0.5) {
            (
                Shape::Bowl {
                    cut: rng.random_range(-0.2..0.05),
                    wall: rng.random_range(0.04..0.08),
                },
                rng.random_range(layout.bowl_scale_m.clone()),
            )
        } else {
            (
                Shape::Mug {
                    aspect: rng.random_range(0.9..1.3),
                    wall: rng.random_range(0.08..0.14),
                },
                rng.random_range(layout.mug_scale_m.clone()),
            )
        };
        let base = [
            rng.random_range(layout.x_m.clone()),
            rng.random_range(layout.y_m.clone()),
            TABLE.height_m,
        ];
        if objects.iter().any(|o| {
            ((o.base_m[0] - base[0]).powi(2) + (o.base_m[1] - base[1]).powi(2)).sqrt()
                < o.scale_m + scale + layout.gap_m
        }) {
            continue;
        }
        objects.push(SceneObject {
            shape: shape.into(),
            base_m: base,
            yaw_rad: rng.random_range(-3.1..3.1),
            scale_m: scale,
            emissivity: 0.91,
            temp_c: 22.0,
        });
    }
    objects
}

/// A tabletop person at `position` (world floor, m) facing the table (−Y) ± 0.4 rad, and the
/// evaluation camera that sees them.
fn person_facing_table(
    rng: &mut impl Rng,
    pose: (String, Vec<[f64; 3]>),
    phenotype: Phenotype,
    position: [f64; 2],
) -> (Person, Rigid3<f64>) {
    let person = Person {
        phenotype,
        rotvec_rad: pose.1,
        pose_name: pose.0,
        position_m: position,
        yaw_rad: rng.random_range(-0.4..0.4),
        skin_c: 34.0,
        clothing_c: 30.0,
        face_c: None,
        hair_c: None,
    };
    let third = look_at(
        Vector3::new(position[0] + 2.5, position[1] - 1.5, 1.4),
        Vector3::new(position[0], position[1], 0.9),
    );
    (person, third)
}

/// The tabletop preset: 1–3 bowls and mugs on a table seen from above by the cameras, and a
/// person 1–3 m away, usually outside both cameras' view.
pub fn tabletop(
    rng: &mut impl Rng,
    pose: (String, Vec<[f64; 3]>),
    phenotype: Phenotype,
    thermal: ThermalPreset,
) -> SceneFile {
    // Cameras 0.55 m above the table, 0.45 m back, looking at the table centre.
    let eye = Vector3::new(0.0, 0.45, 0.75 + 0.55);
    let world_from_depth = look_at(eye, Vector3::new(0.0, -0.05, 0.75));
    let n_objects = rng.random_range(1..=3);
    let objects = place_objects(rng, n_objects, &SPREAD_LAYOUT, usize::MAX);
    // The person stands behind the cameras (so only reflections show them), 1–3 m from the table.
    let dist = rng.random_range(0.5..1.5);
    let angle: f64 = rng.random_range(-0.6..0.6);
    let position = [dist * angle.sin(), 0.45 + dist * angle.cos()];
    let (person, third) = person_facing_table(rng, pose, phenotype, position);
    assemble(
        22.0,
        &world_from_depth,
        &third,
        thermal,
        Some(TABLE),
        objects,
        person,
    )
}

/// The paper-like tabletop: 1–3 bowls and mugs close together on a table, seen from
/// 0.35–0.5 m by the cameras 6–35 cm above the table (a mug's side reflects near-horizontal rays),
/// so the objects fill much of a 50° view;
/// a person 0.5–2 m from the objects, behind the cameras (outside both views), facing the
/// table give or take 0.4 rad. The thermal camera is `thermal` (the regime uses the Boson-like
/// 640×512).
pub fn tabletop_close(
    rng: &mut impl Rng,
    pose: (String, Vec<[f64; 3]>),
    phenotype: Phenotype,
    thermal: ThermalPreset,
) -> SceneFile {
    let n_objects = rng.random_range(1..=3);
    let objects = place_objects(rng, n_objects, &CLOSE_LAYOUT, 200);
    let n = objects.len().max(1) as f64;
    let (cx, cy) = (
        objects.iter().map(|o| o.base_m[0]).sum::<f64>() / n,
        objects.iter().map(|o| o.base_m[1]).sum::<f64>() / n,
    );
    // Cameras on the person's side of the table (+Y), looking at the objects.
    let back = rng.random_range(0.35..0.5);
    let height = rng.random_range(0.06..0.35);
    let eye = Vector3::new(cx, cy + back, 0.75 + height);
    let world_from_depth = look_at(eye, Vector3::new(cx, cy, 0.8));
    // The person behind the cameras, 0.5–2 m from the objects and at least 0.5 m behind the
    // cameras (closer, their legs enter the cameras' view; scenes where either camera sees the
    // person are redrawn by the regime).
    let dist = rng.random_range(0.5..2.0f64).max(back + 0.5);
    let angle: f64 = rng.random_range(-0.5..0.5);
    let position = [cx + dist * angle.sin(), cy + dist * angle.cos()];
    let (person, third) = person_facing_table(rng, pose, phenotype, position);
    assemble(
        22.0,
        &world_from_depth,
        &third,
        thermal,
        Some(TABLE),
        objects,
        person,
    )
}

/// A scene with the presets' cameras: a 320×240, 70° depth camera, the thermal camera 4 cm to
/// its right, and a 320×240, 60° evaluation camera.
fn assemble(
    ambient_c: f64,
    world_from_depth: &Rigid3<f64>,
    world_from_third: &Rigid3<f64>,
    thermal: ThermalPreset,
    table: Option<Table>,
    objects: Vec<SceneObject>,
    person: Person,
) -> SceneFile {
    let camera = |fov_deg: f64, pose: &Rigid3<f64>| PlacedCamera {
        intrinsics: PinholeCamera::from_fov(320, 240, fov_deg.to_radians()).expect("valid"),
        world_from_camera: RigidFile::from_rigid(pose),
    };
    SceneFile {
        ambient_c,
        depth_camera: camera(70.0, world_from_depth),
        thermal_camera: ThermalCamera {
            intrinsics: thermal.camera(),
            depth_from_thermal: small_baseline(),
        },
        third_camera: camera(60.0, world_from_third),
        table,
        objects,
        person,
        heat_sources: vec![],
        sensor: Sensor::default(),
    }
}

/// The side of the presets' car nearest the cameras: world y, metres (the car is centred on the
/// origin, its length along x).
pub const CAR_SIDE_Y_M: f64 = -0.95;

/// The car preset: the side of a car seen from 2–3 m, a pedestrian 2–8 m away from the car.
pub fn car(
    rng: &mut impl Rng,
    pose: (String, Vec<[f64; 3]>),
    phenotype: Phenotype,
    thermal: ThermalPreset,
) -> SceneFile {
    let length = irmirror_geom::CAR_LENGTH_M;
    let car = SceneObject {
        shape: Shape::Car {
            cabin: rng.random_range(0.45..0.7),
            height: rng.random_range(0.28..0.36),
        }
        .into(),
        base_m: [0.0, 0.0, 0.0],
        yaw_rad: 0.0,
        scale_m: length / 1.9,
        emissivity: 0.93,
        temp_c: 20.0,
    };
    // Cameras 1.5 m from the car's side (`CAR_SIDE_Y_M`) at 1.2 m height, looking at the door.
    let eye = Vector3::new(rng.random_range(-0.5..0.5), -2.45, 1.2);
    let world_from_depth = look_at(eye, Vector3::new(eye.x, 0.0, 0.8));
    // Pedestrian behind the cameras, 2.5–8 m from the car, where the door's mirror image of
    // them falls inside the thermal camera's view (|Δx| < 0.4 × image distance).
    let dist = rng.random_range(2.5..8.0);
    let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let lateral: f64 = side * rng.random_range(0.5..(0.4 * (dist + 0.6f64)).max(0.6));
    let position = [eye.x + lateral, CAR_SIDE_Y_M - dist];
    let person = Person {
        phenotype,
        rotvec_rad: pose.1,
        pose_name: pose.0,
        position_m: position,
        yaw_rad: rng.random_range(-3.1..3.1),
        skin_c: 34.0,
        clothing_c: 28.0,
        face_c: None,
        hair_c: None,
    };
    let third = look_at(
        Vector3::new(position[0] + side * 3.0, position[1] - 2.0, 1.6),
        Vector3::new(position[0], position[1], 0.9),
    );
    assemble(
        18.0,
        &world_from_depth,
        &third,
        thermal,
        None,
        vec![car],
        person,
    )
}

/// A rotation about world Z.
pub fn yaw(angle_rad: f64) -> Matrix3<f64> {
    axis_angle_to_matrix(&Vector3::new(0.0, 0.0, angle_rad))
}
