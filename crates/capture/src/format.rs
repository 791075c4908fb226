//! `capture.toml`: the schema, with documented units. Unknown keys are errors.

use irmirror_geom::transform::RigidFile;
use irmirror_geom::{Category, PinholeCamera};
use serde::{Deserialize, Serialize};

/// The format tag every `capture.toml` starts with.
pub const FORMAT: &str = "irmirror-capture-1";

/// The whole file.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaptureFile {
    /// Must be [`FORMAT`].
    pub format: String,
    /// The depth camera: its frame is the reconstruction frame.
    pub depth_camera: CameraSpec,
    /// The depth image.
    pub depth: DepthSpec,
    /// The thermal camera and its pose.
    pub thermal_camera: ThermalCameraSpec,
    /// The thermal frame(s).
    pub thermal: ThermalSpec,
    /// Optional RGB image, registered to the depth camera (same size and intrinsics).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rgb: Option<RgbSpec>,
    /// The reflecting objects, in order.
    #[serde(default, rename = "object")]
    pub objects: Vec<ObjectSpec>,
    /// Further calibrated cameras (for renders of the result), never read as input images.
    #[serde(
        default,
        rename = "extra_camera",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub extra_cameras: Vec<ExtraCamera>,
    /// Free-form description (rig, scene, simulator seed …).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
}

/// Pinhole intrinsics in pixels (pixel centres at +0.5).
pub type CameraSpec = PinholeCamera;

/// The thermal camera: intrinsics plus `depth_from_thermal`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThermalCameraSpec {
    /// Intrinsics.
    #[serde(flatten)]
    pub intrinsics: PinholeCamera,
    /// Thermal-camera frame → depth-camera frame.
    pub depth_from_thermal: RigidFile,
    /// The optics' point spread as a Gaussian σ in pixels, when known (from the lens' MTF or
    /// a knife-edge measurement); the radiometric fit integrates each pixel's footprint over it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf_sigma_px: Option<f64>,
}

/// The depth image.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DepthSpec {
    /// 16-bit grayscale PNG, relative to the capture directory.
    pub file: String,
    /// Metres per count (0.001 for millimetres). 0 counts = no measurement.
    pub units_m: f64,
    /// Optional "up" (against gravity) in the depth-camera frame, from the camera's IMU (Azure
    /// Kinect, RealSense D435i/D455 and phones report it); any length, normalised on load.
    /// Stage 1 uses it when the depth image shows no support plane (the side of a car).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
}

/// Units of the thermal images.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ThermalUnits {
    /// Raw counts linear in 8–14 µm band radiance: `L = (counts − offset) / gain`
    /// (W m⁻² sr⁻¹); 16-bit PNG or TIFF.
    CountsLinear {
        /// Counts per W m⁻² sr⁻¹.
        gain: f64,
        /// Counts at zero radiance.
        offset: f64,
    },
    /// Raw counts with a FLIR-style Planck calibration: `T = b / ln(r / (counts − o) + f)` (K);
    /// 16-bit PNG or TIFF.
    CountsPlanck {
        /// Planck R (counts · …), > 0.
        r: f64,
        /// Planck B, K, > 0.
        b: f64,
        /// Planck F (typically 1).
        f: f64,
        /// Offset O, counts.
        o: f64,
    },
    /// Counts = 100 × kelvin (FLIR Lepton TLinear); 16-bit PNG or TIFF.
    Centikelvin,
    /// Kelvin, float `.npy` or 32-bit float TIFF.
    Kelvin,
    /// Degrees Celsius, float `.npy` or 32-bit float TIFF.
    Celsius,
}

/// The thermal frame and optional background frames (same camera, same units).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThermalSpec {
    /// The frame with the person present.
    pub file: String,
    /// Pixel units.
    pub units: ThermalUnits,
    /// Frames of the same scene without the person.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub background: Vec<String>,
}

/// RGB image.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RgbSpec {
    /// 8-bit RGB PNG, depth-camera size.
    pub file: String,
}

/// One reflecting object.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// Shape category (`bowl`, `mug` or `cup`, `car`, `sphere` or `ball`): selects the shape
    /// prior.
    pub category: Category,
    /// Optional mask in depth-camera pixels (PNG, non-zero = object).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
}

/// A further calibrated camera.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ExtraCamera {
    /// Name used in output file names.
    pub name: String,
    /// Intrinsics.
    #[serde(flatten)]
    pub intrinsics: PinholeCamera,
    /// This camera's frame → depth-camera frame.
    pub depth_from_camera: RigidFile,
}

/// `rig.toml`, written by `irmirror capture calibrate` and read by `irmirror capture import`:
/// capture.toml's two camera tables (copy them into a capture.toml as they are) and how well the
/// calibration fits.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    /// The depth camera, as given to the calibration.
    pub depth_camera: CameraSpec,
    /// The thermal camera: intrinsics and `depth_from_thermal`, as calibrated.
    pub thermal_camera: ThermalCameraSpec,
    /// The calibration's fit (absent when the file was written by hand).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<RigFit>,
}

/// How well a calibration fits its views.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigFit {
    /// Views used (both cameras saw the whole board).
    pub views: usize,
    /// Views skipped, with the reason.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub skipped: Vec<String>,
    /// The board: inner corners and square size.
    pub board: String,
    /// RMS reprojection error of the thermal corners, pixels.
    pub rms_thermal_px: f64,
    /// RMS reprojection error of the depth camera's corners, pixels.
    pub rms_depth_px: f64,
    /// One-σ uncertainty of fx, fy, cx, cy, pixels.
    pub intrinsics_sd_px: [f64; 4],
    /// One-σ uncertainty of the extrinsic's rotation, degrees (largest axis).
    pub rotation_sd_deg: f64,
    /// One-σ uncertainty of the extrinsic's translation, millimetres (largest axis).
    pub translation_sd_mm: f64,
}
