//! Calibration views: a checkerboard held in front of the rig, seen by the thermal camera (a
//! heated board whose dark squares are aluminium foil, so the pattern shows in the LWIR) and by
//! the depth camera's registered grey image, with the sensor's blur, NETD and quantisation.
//! The truth (rig and board poses) is known, so `capture calibrate` can be tested.

use crate::scene::{Sensor, ThermalPreset};
use crate::sensor::{blur, supersampled, thermal_counts};
use irmirror_capture::Image;
use irmirror_capture::planck::{ZERO_C_K, band_radiance};
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_geom::{PinholeCamera, Rigid3};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// A printed checkerboard on a board with a margin of one square.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckerBoard {
    /// Inner corners along x (squares − 1).
    pub cols: u32,
    /// Inner corners along y.
    pub rows: u32,
    /// Side of a square, m.
    pub square_m: f64,
}

impl Default for CheckerBoard {
    /// 8 × 6 squares of 35 mm (7 × 5 inner corners): an A4 print.
    fn default() -> Self {
        Self {
            cols: 7,
            rows: 5,
            square_m: 0.035,
        }
    }
}

/// What a board point is: outside the board, a light (paper) or a dark (foil) square.
#[derive(Clone, Copy, PartialEq)]
enum Patch {
    Outside,
    Light,
    Dark,
}

impl CheckerBoard {
    /// The patch at board coordinates (x, y), m; inner corner (0, 0) at the origin.
    fn patch(&self, x: f64, y: f64) -> Patch {
        let s = self.square_m;
        let (i, j) = ((x / s).floor() as i64, (y / s).floor() as i64);
        let (nx, ny) = (i64::from(self.cols), i64::from(self.rows));
        // Squares −1 … cols − 1 (cols + 1 of them, so `cols` inner corners), a margin square
        // around them.
        if i < -2 || j < -2 || i > nx || j > ny {
            Patch::Outside
        } else if i < -1 || j < -1 || i > nx - 1 || j > ny - 1 || (i + j).rem_euclid(2) == 1 {
            Patch::Light
        } else {
            Patch::Dark
        }
    }

    /// The board's outline corners (margin included) in the board frame.
    fn outline(&self) -> [Vector3<f64>; 4] {
        let s = self.square_m;
        let (x0, y0) = (-2.0 * s, -2.0 * s);
        let (x1, y1) = (
            (f64::from(self.cols) + 1.0) * s,
            (f64::from(self.rows) + 1.0) * s,
        );
        [
            Vector3::new(x0, y0, 0.0),
            Vector3::new(x1, y0, 0.0),
            Vector3::new(x0, y1, 0.0),
            Vector3::new(x1, y1, 0.0),
        ]
    }
}

/// A thermal + RGB-D rig to calibrate.
#[derive(Clone, Debug)]
pub struct Rig {
    /// The thermal camera.
    pub thermal: PinholeCamera,
    /// The depth camera (its registered grey image has the same intrinsics).
    pub depth: PinholeCamera,
    /// Thermal frame → depth frame.
    pub depth_from_thermal: Rigid3<f64>,
    /// The thermal sensor.
    pub sensor: Sensor,
}

impl Rig {
    /// The presets' cameras (a 320×240, 70° depth camera; the thermal camera 4 cm to its right)
    /// mounted slightly off: the thermal camera turned by ≈ 1° and 6 mm lower than nominal, as a
    /// hand-built bracket would be.
    pub fn preset(thermal: ThermalPreset) -> Self {
        Self {
            thermal: thermal.camera(),
            depth: PinholeCamera::from_fov(320, 240, 70f64.to_radians()).expect("valid"),
            depth_from_thermal: Rigid3 {
                rotation: axis_angle_to_matrix(&Vector3::new(0.009, -0.014, 0.004)),
                translation: Vector3::new(0.041, 0.006, -0.003),
            },
            sensor: Sensor::default(),
        }
    }
}

/// Temperatures of the scene, °C.
const AMBIENT_C: f64 = 22.0;
/// The board warmed ~15 K above the room (a heat lamp or sunlight).
const BOARD_C: f64 = 37.0;
/// Paper's and foil's LWIR emissivity (paper ≈ 0.9; polished aluminium ≈ 0.05).
const PAPER_EMISSIVITY: f64 = 0.92;
const FOIL_EMISSIVITY: f64 = 0.05;

/// Board poses (`depth_from_board`) a person would hold for calibration: 0.45–0.8 m away, tilted
/// up to ±35° about both axes, rolled up to ±12°, the whole board inside both images.
pub fn poses(
    rig: &Rig,
    board: &CheckerBoard,
    count: usize,
    rng: &mut impl Rng,
) -> Vec<Rigid3<f64>> {
    let thermal_from_depth = rig.depth_from_thermal.inverse();
    let inside = |cam: &PinholeCamera, p: Vector3<f64>| {
        cam.project(&p).is_some_and(|(u, v)| {
            u > 6.0 && v > 6.0 && u < f64::from(cam.width) - 6.0 && v < f64::from(cam.height) - 6.0
        })
    };
    let centre = Vector3::new(
        f64::from(board.cols - 1) * board.square_m / 2.0,
        f64::from(board.rows - 1) * board.square_m / 2.0,
        0.0,
    );
    let mut out = Vec::with_capacity(count);
    for _ in 0..count * 1000 {
        if out.len() == count {
            break;
        }
        let tilt = Vector3::new(
            rng.random_range(-0.6..0.6),
            rng.random_range(-0.6..0.6),
            rng.random_range(-0.2..0.2),
        );
        let z = rng.random_range(0.45..0.8);
        let at = Vector3::new(
            rng.random_range(-0.25..0.25) * z,
            rng.random_range(-0.2..0.2) * z,
            z,
        );
        let rotation = axis_angle_to_matrix(&tilt);
        let pose = Rigid3 {
            rotation,
            translation: at - rotation * centre,
        };
        let ok = board.outline().iter().all(|c| {
            let p = pose.transform_point(c);
            inside(&rig.depth, p) && inside(&rig.thermal, thermal_from_depth.transform_point(&p))
        });
        if ok {
            out.push(pose);
        }
    }
    out
}

/// Mean of `value(patch)` over 4 × 4 sub-pixel rays per pixel of `camera` looking at the
/// board placed by `camera_from_board`.
fn render(
    board: &CheckerBoard,
    camera: &PinholeCamera,
    camera_from_board: &Rigid3<f64>,
    value: impl Fn(Patch) -> f64 + Sync,
) -> Image<f64> {
    let board_from_camera = camera_from_board.inverse();
    supersampled(camera, 4, |u, v| {
        let ray = board_from_camera.transform_ray(&camera.ray_at::<f64>(u, v));
        let t = -ray.origin.z / ray.dir.z;
        value(if ray.dir.z.abs() > 1e-12 && t > 0.0 {
            let q = ray.origin + ray.dir * t;
            board.patch(q.x, q.y)
        } else {
            Patch::Outside
        })
    })
}

/// The thermal frame (raw counts, the sensor's linear calibration `sensor::calibration`) of
/// the board at `depth_from_board`.
pub fn thermal_view(
    rig: &Rig,
    board: &CheckerBoard,
    depth_from_board: &Rigid3<f64>,
    rng: &mut impl Rng,
) -> Image<u16> {
    let (room, warm) = (
        band_radiance(AMBIENT_C + ZERO_C_K),
        band_radiance(BOARD_C + ZERO_C_K),
    );
    let seen = |e: f64| e * warm + (1.0 - e) * room;
    let pose = rig.depth_from_thermal.inverse() * *depth_from_board;
    let radiance = render(board, &rig.thermal, &pose, |p| match p {
        Patch::Outside => room,
        Patch::Light => seen(PAPER_EMISSIVITY),
        Patch::Dark => seen(FOIL_EMISSIVITY),
    });
    thermal_counts(&radiance, &rig.sensor, AMBIENT_C + ZERO_C_K, rng)
}

/// The depth camera's registered grey image (8-bit) of the board: black and white squares on a
/// grey wall, 0.5 px of blur and 1 % noise.
pub fn grey_view(
    rig: &Rig,
    board: &CheckerBoard,
    depth_from_board: &Rigid3<f64>,
    rng: &mut impl Rng,
) -> Image<u8> {
    let img = render(board, &rig.depth, depth_from_board, |p| match p {
        Patch::Outside => 0.45,
        Patch::Light => 0.9,
        Patch::Dark => 0.08,
    });
    let img = blur(&img, 0.5);
    let noise = Normal::new(0.0, 0.01).expect("finite σ");
    let data = img
        .data
        .iter()
        .map(|v| ((v + noise.sample(rng)) * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect();
    Image {
        width: img.width,
        height: img.height,
        data,
    }
}
