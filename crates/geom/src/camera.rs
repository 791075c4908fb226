//! Pinhole cameras in OpenCV axes (+X right, +Y down, +Z forward).
//!
//! Image coordinates are continuous: pixel (col i, row j) covers `[i, i+1) × [j, j+1)` and has
//! its centre at `(i + 0.5, j + 0.5)`. A point `p` (camera frame, metres, `z > 0`) projects to
//! `u = fx · x/z + cx`, `v = fy · y/z + cy`.

use crate::{GeomError, Ray, Real};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Intrinsics of a pinhole camera without distortion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinholeCamera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (continuous coordinates: image centre is `width / 2`).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl PinholeCamera {
    /// A camera with the principal point at the image centre and square pixels of a horizontal
    /// field of view `fov_x_rad`.
    pub fn from_fov(width: u32, height: u32, fov_x_rad: f64) -> Result<Self, GeomError> {
        let fx = f64::from(width) / 2.0 / (fov_x_rad / 2.0).tan();
        let cam = Self {
            width,
            height,
            fx,
            fy: fx,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// Checks that the intrinsics describe a real camera (positive size of at most
    /// [`MAX_SIDE_PX`] a side, positive focal lengths, finite values, principal point inside the
    /// image). A size beyond any camera's would otherwise surface as an allocation failure when
    /// an image of it is drawn.
    pub fn validate(&self) -> Result<(), GeomError> {
        let bad = |s: String| Err(GeomError::InvalidCamera(s));
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image size {}×{} must be positive",
                self.width, self.height
            ));
        }
        if self.width > MAX_SIDE_PX || self.height > MAX_SIDE_PX {
            return bad(format!(
                "image size {}×{} exceeds {MAX_SIDE_PX} pixels a side (no thermal, depth or \
                 RGB camera is that large; a typo?)",
                self.width, self.height
            ));
        }
        for (name, v) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
        ] {
            if !v.is_finite() {
                return bad(format!("{name} = {v} is not finite"));
            }
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return bad(format!(
                "focal lengths must be positive (fx = {}, fy = {})",
                self.fx, self.fy
            ));
        }
        if !(0.0..=f64::from(self.width)).contains(&self.cx)
            || !(0.0..=f64::from(self.height)).contains(&self.cy)
        {
            return bad(format!(
                "principal point ({}, {}) lies outside the {}×{} image",
                self.cx, self.cy, self.width, self.height
            ));
        }
        Ok(())
    }

    /// Unit ray (camera frame) through continuous image point `(u, v)`.
    pub fn ray_at<T: Real>(&self, u: f64, v: f64) -> Ray<T> {
        let d = Vector3::new(
            T::of((u - self.cx) / self.fx),
            T::of((v - self.cy) / self.fy),
            T::one(),
        );
        Ray::new(Vector3::zeros(), d)
    }

    /// Unit ray (camera frame) through the centre of pixel (`col`, `row`).
    pub fn pixel_ray<T: Real>(&self, col: u32, row: u32) -> Ray<T> {
        self.ray_at(f64::from(col) + 0.5, f64::from(row) + 0.5)
    }

    /// Continuous image coordinates of a camera-frame point, or `None` behind the camera.
    pub fn project<T: Real>(&self, p_cam: &Vector3<T>) -> Option<(f64, f64)> {
        let z = p_cam.z.to_f64();
        if z <= 0.0 {
            return None;
        }
        Some((
            self.fx * p_cam.x.to_f64() / z + self.cx,
            self.fy * p_cam.y.to_f64() / z + self.cy,
        ))
    }

    /// The pixel (col, row) containing a camera-frame point, if it projects inside the image.
    pub fn project_to_pixel<T: Real>(&self, p_cam: &Vector3<T>) -> Option<(u32, u32)> {
        let (u, v) = self.project(p_cam)?;
        (u >= 0.0 && v >= 0.0 && u < f64::from(self.width) && v < f64::from(self.height))
            .then(|| (u.floor() as u32, v.floor() as u32))
    }

    /// Camera-frame point at depth `z_m` (metres along +Z, not along the ray) under image point `(u, v)`.
    pub fn unproject(&self, u: f64, v: f64, z_m: f64) -> Vector3<f64> {
        Vector3::new(
            (u - self.cx) / self.fx * z_m,
            (v - self.cy) / self.fy * z_m,
            z_m,
        )
    }
}

/// The largest image side a camera may state, pixels (16K: beyond any thermal, depth or RGB
/// sensor in use, and an RGB image of it is 0.8 GB).
pub const MAX_SIDE_PX: u32 = 16_384;

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> PinholeCamera {
        PinholeCamera {
            width: 160,
            height: 120,
            fx: 150.0,
            fy: 152.0,
            cx: 80.0,
            cy: 60.0,
        }
    }

    #[test]
    fn pixel_centres_are_at_half_integers() {
        let c = cam();
        // The ray through pixel (79, 59) passes half a pixel left and up of the principal point.
        let r: Ray<f64> = c.pixel_ray(79, 59);
        let (u, v) = c.project(&r.at(2.0)).unwrap();
        assert!((u - 79.5).abs() < 1e-12 && (v - 59.5).abs() < 1e-12);
        assert_eq!(c.project_to_pixel(&r.at(3.0)), Some((79, 59)));
        assert!((r.dir.norm() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn project_unproject_round_trip() {
        let c = cam();
        for (u, v, z) in [
            (0.0, 0.0, 0.5),
            (159.9, 119.9, 3.0),
            (80.0, 60.0, 1.0),
            (12.25, 100.5, 0.01),
        ] {
            let p = c.unproject(u, v, z);
            let (u2, v2) = c.project(&p).unwrap();
            assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9);
        }
        assert_eq!(c.project(&Vector3::new(0.0, 0.0, -1.0)), None);
        assert_eq!(c.project_to_pixel(&Vector3::new(10.0, 0.0, 1.0)), None);
    }

    #[test]
    fn validation_rejects_impossible_intrinsics() {
        let mut c = cam();
        c.fx = -150.0;
        assert!(c.validate().is_err());
        let mut c = cam();
        c.cx = 500.0;
        assert!(c.validate().is_err());
        let mut c = cam();
        c.width = 0;
        assert!(c.validate().is_err());
        let mut c = cam();
        c.fy = f64::NAN;
        assert!(c.validate().is_err());
        // 4e9 × 4e9 (issue 22: accepted, then a panic drawing a view after the whole run).
        let mut c = cam();
        (c.width, c.height, c.cx, c.cy) = (4_000_000_000, 4_000_000_000, 2e9, 2e9);
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("exceeds 16384"), "{e}");
        // FLIR Lepton-like: 160 px over 57° gives fx ≈ 147.4 px.
        let lepton = PinholeCamera::from_fov(160, 120, 57f64.to_radians()).unwrap();
        assert!((lepton.fx - 147.36).abs() < 0.05, "{}", lepton.fx);
    }
}
