//! Loading and validating a capture directory. Read-only: nothing in it is ever written.

use crate::CaptureError;
use crate::format::{CaptureFile, FORMAT, ThermalUnits};
use crate::image_io::{Image, read_float, read_gray16_png, read_mask, read_rgb};
use crate::planck::{ZERO_C_K, band_radiance, temperature_of};
use irmirror_geom::{Category, PinholeCamera, Rigid3};
use nalgebra::Vector3;
use std::path::{Component, Path, PathBuf};

/// Plausible scene temperatures, K: outside this the units are almost certainly wrong.
const PLAUSIBLE_K: std::ops::RangeInclusive<f64> = 200.0..=500.0;

/// Largest point spread a capture may state, pixels: beyond it a pixel is not an image point.
pub const MAX_PSF_SIGMA_PX: f64 = 5.0;

/// One object of the capture.
#[derive(Clone, Debug)]
pub struct CapturedObject {
    /// Shape category.
    pub category: Category,
    /// Mask in depth-camera pixels, if given.
    pub mask: Option<Image<bool>>,
}

/// A loaded, validated capture.
#[derive(Clone, Debug)]
pub struct Capture {
    /// The capture directory.
    pub dir: PathBuf,
    /// The parsed `capture.toml`.
    pub file: CaptureFile,
    /// Depth camera (the reconstruction frame).
    pub depth_camera: PinholeCamera,
    /// Thermal camera intrinsics.
    pub thermal_camera: PinholeCamera,
    /// Thermal-camera frame → depth-camera frame.
    pub depth_from_thermal: Rigid3<f64>,
    /// Depth along +Z, metres; NaN where the sensor gave no measurement.
    pub depth_m: Image<f32>,
    /// Thermal frame as brightness temperature, K.
    pub thermal_k: Image<f64>,
    /// Background frames (without the person), K.
    pub thermal_background_k: Vec<Image<f64>>,
    /// Objects, in file order.
    pub objects: Vec<CapturedObject>,
    /// Extra calibrated cameras: name, intrinsics, `depth_from_camera`.
    pub extra_cameras: Vec<(String, PinholeCamera, Rigid3<f64>)>,
    /// Unit "up" (against gravity) in the depth frame, when the capture gives one (IMU).
    pub up: Option<Vector3<f64>>,
}

impl Capture {
    /// Loads `dir/capture.toml` and every file it names, validating sizes, bit depths, units
    /// and calibration.
    pub fn load(dir: &Path) -> Result<Self, CaptureError> {
        let toml_path = dir.join("capture.toml");
        let text = std::fs::read_to_string(&toml_path).map_err(|e| {
            CaptureError::file(
                &toml_path,
                format!(
                    "cannot read ({e}); is {} a capture directory?",
                    dir.display()
                ),
            )
        })?;
        let file: CaptureFile =
            toml::from_str(&text).map_err(|e| CaptureError::file(&toml_path, e.to_string()))?;
        let field = |f: &str, r: String| CaptureError::Field {
            path: toml_path.clone(),
            field: f.into(),
            reason: r,
        };
        if file.format != FORMAT {
            return Err(field(
                "format",
                format!("`{}` is not `{FORMAT}`", file.format),
            ));
        }
        file.depth_camera
            .validate()
            .map_err(|e| field("depth_camera", e.to_string()))?;
        file.thermal_camera
            .intrinsics
            .validate()
            .map_err(|e| field("thermal_camera", e.to_string()))?;
        let depth_from_thermal = file
            .thermal_camera
            .depth_from_thermal
            .to_rigid()
            .map_err(|e| field("thermal_camera.depth_from_thermal", e.to_string()))?;
        if let Some(psf) = file.thermal_camera.psf_sigma_px
            && !(psf.is_finite() && (0.0..=MAX_PSF_SIGMA_PX).contains(&psf))
        {
            return Err(field(
                "thermal_camera.psf_sigma_px",
                format!("{psf} must be a Gaussian σ in pixels within 0–{MAX_PSF_SIGMA_PX}"),
            ));
        }
        if !(file.depth.units_m.is_finite() && file.depth.units_m > 0.0) {
            return Err(field(
                "depth.units_m",
                format!(
                    "{} must be a positive number of metres per count",
                    file.depth.units_m
                ),
            ));
        }
        let up = match file.depth.up {
            Some(u) => {
                let v = Vector3::from(u);
                if !(v.iter().all(|x| x.is_finite()) && v.norm() > 1e-9) {
                    return Err(field(
                        "depth.up",
                        format!("{u:?} must be a finite, non-zero vector"),
                    ));
                }
                Some(v.normalize())
            }
            None => None,
        };
        if let ThermalUnits::CountsLinear { gain, offset } = file.thermal.units
            && !(gain.is_finite() && gain > 0.0 && offset.is_finite())
        {
            return Err(field(
                "thermal.units",
                format!("gain {gain} must be positive and offset {offset} finite"),
            ));
        }
        if let ThermalUnits::CountsPlanck { r, b, f, o } = file.thermal.units
            && !(r > 0.0 && b > 0.0 && f.is_finite() && o.is_finite())
        {
            return Err(field(
                "thermal.units",
                format!(
                    "Planck constants need r > 0 and b > 0 (r = {r}, b = {b}, f = {f}, o = {o})"
                ),
            ));
        }
        if file.objects.is_empty() {
            return Err(field(
                "object",
                "the capture lists no objects (add [[object]] tables with a category)".into(),
            ));
        }
        let resolve = |f: &str, name: &str| -> Result<PathBuf, CaptureError> {
            let p = Path::new(name);
            if p.is_absolute()
                || p.components().any(|c| matches!(c, Component::ParentDir))
                || name.is_empty()
            {
                return Err(field(
                    f,
                    format!("`{name}` must be a path inside the capture directory"),
                ));
            }
            Ok(dir.join(p))
        };
        let (dc, tc) = (file.depth_camera, file.thermal_camera.intrinsics);
        let check_size = |path: &Path,
                          w: u32,
                          h: u32,
                          cam: &PinholeCamera,
                          what: &str|
         -> Result<(), CaptureError> {
            if (w, h) != (cam.width, cam.height) {
                return Err(CaptureError::file(
                    path,
                    format!(
                        "is {w}×{h}, but the {what} camera is {}×{}",
                        cam.width, cam.height
                    ),
                ));
            }
            Ok(())
        };

        let depth_path = resolve("depth.file", &file.depth.file)?;
        let raw = read_gray16_png(&depth_path)?;
        check_size(&depth_path, raw.width, raw.height, &dc, "depth")?;
        if raw.data.iter().all(|&v| v == 0) {
            return Err(CaptureError::file(
                &depth_path,
                "has no valid pixel (all zero)",
            ));
        }
        let units = file.depth.units_m;
        let depth_m = raw.map(|v| {
            if v == 0 {
                f32::NAN
            } else {
                (f64::from(v) * units) as f32
            }
        });

        let to_kelvin = |path: &Path| -> Result<Image<f64>, CaptureError> {
            let img = match file.thermal.units {
                ThermalUnits::CountsLinear { gain, offset } => {
                    // One inversion per distinct count (a frame has a few thousand): each
                    // costs a band integral, which per pixel was seconds on a 640×512 frame.
                    let mut memo = vec![f64::NAN; usize::from(u16::MAX) + 1];
                    read_gray16_png(path)?.map(|c| {
                        let m = &mut memo[usize::from(c)];
                        if m.is_nan() {
                            *m = temperature_of((f64::from(c) - offset) / gain);
                        }
                        *m
                    })
                }
                // Counts at or below the offset give NaN, reported below as non-finite.
                ThermalUnits::CountsPlanck { r, b, f, o } => {
                    read_gray16_png(path)?.map(|c| b / (r / (f64::from(c) - o) + f).ln())
                }
                ThermalUnits::Centikelvin => read_gray16_png(path)?.map(|c| f64::from(c) / 100.0),
                ThermalUnits::Kelvin => read_float(path)?,
                ThermalUnits::Celsius => read_float(path)?.map(|c| c + ZERO_C_K),
            };
            check_size(path, img.width, img.height, &tc, "thermal")?;
            if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
                return Err(CaptureError::file(
                    path,
                    format!(
                        "pixel {} (col {}, row {}) is not finite",
                        i,
                        i as u32 % img.width,
                        i as u32 / img.width
                    ),
                ));
            }
            if let Some(v) = img.data.iter().find(|v| !PLAUSIBLE_K.contains(*v)) {
                return Err(CaptureError::file(
                    path,
                    format!(
                        "a pixel reads {v:.1} K, outside {:.0}–{:.0} K: check `thermal.units`",
                        PLAUSIBLE_K.start(),
                        PLAUSIBLE_K.end()
                    ),
                ));
            }
            Ok(img)
        };
        let thermal_k = to_kelvin(&resolve("thermal.file", &file.thermal.file)?)?;
        let thermal_background_k = file
            .thermal
            .background
            .iter()
            .map(|b| to_kelvin(&resolve("thermal.background", b)?))
            .collect::<Result<Vec<_>, _>>()?;

        if let Some(rgb) = &file.rgb {
            let p = resolve("rgb.file", &rgb.file)?;
            let (w, h) = read_rgb(&p)?;
            check_size(&p, w, h, &dc, "depth")?;
        }
        let mut objects = Vec::new();
        for (k, o) in file.objects.iter().enumerate() {
            let mask = match &o.mask {
                Some(m) => {
                    let p = resolve(&format!("object[{k}].mask"), m)?;
                    let img = read_mask(&p)?;
                    check_size(&p, img.width, img.height, &dc, "depth")?;
                    if !img.data.iter().any(|&b| b) {
                        return Err(CaptureError::file(
                            &p,
                            "the mask is empty (no non-zero pixel)",
                        ));
                    }
                    Some(img)
                }
                None => None,
            };
            objects.push(CapturedObject {
                category: o.category,
                mask,
            });
        }
        let mut extra_cameras = Vec::new();
        for (k, c) in file.extra_cameras.iter().enumerate() {
            c.intrinsics
                .validate()
                .map_err(|e| field(&format!("extra_camera[{k}]"), e.to_string()))?;
            let t = c.depth_from_camera.to_rigid().map_err(|e| {
                field(
                    &format!("extra_camera[{k}].depth_from_camera"),
                    e.to_string(),
                )
            })?;
            extra_cameras.push((c.name.clone(), c.intrinsics, t));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            depth_camera: dc,
            thermal_camera: tc,
            depth_from_thermal,
            depth_m,
            thermal_k,
            thermal_background_k,
            objects,
            extra_cameras,
            up,
            file,
        })
    }

    /// The thermal optics' point spread (Gaussian σ, pixels; 0 when the capture states none).
    pub fn thermal_psf_sigma_px(&self) -> f64 {
        self.file.thermal_camera.psf_sigma_px.unwrap_or(0.0)
    }

    /// The thermal frame as band radiance, W m⁻² sr⁻¹.
    ///
    /// One band integral per distinct temperature: a frame in counts has a few thousand, and
    /// per pixel the integrals cost ≈ 2 s of a 640×512 frame (the report's preview).
    pub fn thermal_radiance(&self) -> Image<f64> {
        let mut memo = std::collections::HashMap::new();
        self.thermal_k
            .map(|t| *memo.entry(t.to_bits()).or_insert_with(|| band_radiance(t)))
    }
}
