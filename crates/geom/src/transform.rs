//! Rigid and similarity transforms, named by the frames they connect.
//!
//! A value called `depth_from_thermal` maps thermal-camera coordinates to depth-camera
//! coordinates: `depth_from_thermal.transform_point(&p_thermal)` is `p_depth`. Composition reads
//! right to left: `depth_from_object = depth_from_world * world_from_object`.

use crate::{GeomError, Ray, Real};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::ops::Mul;

/// Orthonormality tolerance for rotations read from files (absolute, on `RᵀR − I`).
const ROTATION_TOL: f64 = 1e-4;

/// `p_a = rotation · p_b + translation` (translation in metres, frame a).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid3<T: Real> {
    /// Rotation from frame b to frame a.
    pub rotation: Matrix3<T>,
    /// Origin of frame b expressed in frame a, metres.
    pub translation: Vector3<T>,
}

impl<T: Real> Rigid3<T> {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// A rigid transform; fails if `rotation` is not a proper rotation (within 1e-4) or a value is
    /// not finite.
    pub fn new(rotation: Matrix3<T>, translation: Vector3<T>) -> Result<Self, GeomError> {
        check_rotation(&rotation)?;
        if translation.iter().any(|x| !x.is_finite()) {
            return Err(GeomError::InvalidTransform(
                "translation is not finite".into(),
            ));
        }
        Ok(Self {
            rotation,
            translation,
        })
    }

    /// Maps a point of frame b to frame a.
    #[inline]
    pub fn transform_point(&self, p_b: &Vector3<T>) -> Vector3<T> {
        self.rotation * p_b + self.translation
    }

    /// Maps a direction of frame b to frame a (no translation).
    #[inline]
    pub fn transform_vector(&self, v_b: &Vector3<T>) -> Vector3<T> {
        self.rotation * v_b
    }

    /// Maps a ray of frame b to frame a.
    #[inline]
    pub fn transform_ray(&self, ray_b: &Ray<T>) -> Ray<T> {
        Ray {
            origin: self.transform_point(&ray_b.origin),
            dir: self.transform_vector(&ray_b.dir),
        }
    }

    /// `b_from_a` from `a_from_b`.
    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        Self {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// Converts the scalar type.
    pub fn cast<U: Real>(&self) -> Rigid3<U> {
        Rigid3 {
            rotation: self.rotation.map(|x| U::of(x.to_f64())),
            translation: self.translation.map(|x| U::of(x.to_f64())),
        }
    }
}

impl<T: Real> Mul for Rigid3<T> {
    type Output = Rigid3<T>;
    /// `a_from_b * b_from_c = a_from_c`.
    fn mul(self, rhs: Rigid3<T>) -> Rigid3<T> {
        Rigid3 {
            rotation: self.rotation * rhs.rotation,
            translation: self.rotation * rhs.translation + self.translation,
        }
    }
}

/// `p_a = scale · rotation · p_b + translation`: places a normalised object frame in the scene.
/// Distances scale: a distance `d_b` in frame b is `scale · d_b` in frame a.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity3<T: Real> {
    /// Rotation from frame b to frame a.
    pub rotation: Matrix3<T>,
    /// Origin of frame b in frame a, metres (of frame a).
    pub translation: Vector3<T>,
    /// Length of one unit of frame b, in units of frame a (> 0).
    pub scale: T,
}

impl<T: Real> Similarity3<T> {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
            scale: T::one(),
        }
    }

    /// A similarity; fails on a non-rotation, a non-positive or non-finite scale.
    pub fn new(rotation: Matrix3<T>, translation: Vector3<T>, scale: T) -> Result<Self, GeomError> {
        check_rotation(&rotation)?;
        if !(scale.is_finite() && scale > T::zero()) {
            return Err(GeomError::InvalidTransform(format!(
                "scale must be positive, got {scale:?}"
            )));
        }
        if translation.iter().any(|x| !x.is_finite()) {
            return Err(GeomError::InvalidTransform(
                "translation is not finite".into(),
            ));
        }
        Ok(Self {
            rotation,
            translation,
            scale,
        })
    }

    /// Maps a point of frame b to frame a.
    #[inline]
    pub fn transform_point(&self, p_b: &Vector3<T>) -> Vector3<T> {
        self.rotation * p_b * self.scale + self.translation
    }

    /// Maps a direction of frame b to frame a, keeping unit length (rotation only).
    #[inline]
    pub fn transform_dir(&self, d_b: &Vector3<T>) -> Vector3<T> {
        self.rotation * d_b
    }

    /// Maps a point of frame a to frame b.
    #[inline]
    pub fn inverse_transform_point(&self, p_a: &Vector3<T>) -> Vector3<T> {
        self.rotation.tr_mul(&(p_a - self.translation)) / self.scale
    }

    /// `b_from_a` from `a_from_b`.
    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        let inv_s = T::one() / self.scale;
        Self {
            rotation: rt,
            translation: -(rt * self.translation) * inv_s,
            scale: inv_s,
        }
    }

    /// Maps a ray of frame b to frame a; the direction stays unit length, so ray parameters
    /// scale by `scale`.
    #[inline]
    pub fn transform_ray(&self, ray_b: &Ray<T>) -> Ray<T> {
        Ray {
            origin: self.transform_point(&ray_b.origin),
            dir: self.transform_dir(&ray_b.dir),
        }
    }
}

impl Similarity3<f64> {
    /// The similarity `b_from_a` that best maps points `a` onto `b` in least squares (Umeyama
    /// 1991: rotation by SVD of the cross-covariance, reflection excluded; scale included when
    /// `with_scale`). `None` for fewer than 3 pairs, unequal lengths or a degenerate set.
    pub fn umeyama(a: &[Vector3<f64>], b: &[Vector3<f64>], with_scale: bool) -> Option<Self> {
        if a.len() != b.len() || a.len() < 3 {
            return None;
        }
        let n = a.len() as f64;
        let ma = a.iter().sum::<Vector3<f64>>() / n;
        let mb = b.iter().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix3::zeros();
        let mut var_a = 0.0;
        for (x, y) in a.iter().zip(b) {
            let (da, db) = (x - ma, y - mb);
            cov += db * da.transpose();
            var_a += da.norm_squared();
        }
        if var_a.is_nan() || var_a <= 1e-18 {
            return None;
        }
        let svd = cov.svd(true, true);
        let (u, vt) = (svd.u?, svd.v_t?);
        let mut d = Matrix3::identity();
        if (u * vt).determinant() < 0.0 {
            d[(2, 2)] = -1.0;
        }
        let rotation = u * d * vt;
        let scale = if with_scale {
            svd.singular_values.component_mul(&d.diagonal()).sum() / var_a
        } else {
            1.0
        };
        Self::new(rotation, mb - rotation * ma * scale, scale).ok()
    }
}

impl<T: Real> Mul for Similarity3<T> {
    type Output = Similarity3<T>;
    /// `a_from_b * b_from_c = a_from_c`.
    fn mul(self, rhs: Similarity3<T>) -> Similarity3<T> {
        Similarity3 {
            rotation: self.rotation * rhs.rotation,
            translation: self.rotation * rhs.translation * self.scale + self.translation,
            scale: self.scale * rhs.scale,
        }
    }
}

fn check_rotation<T: Real>(r: &Matrix3<T>) -> Result<(), GeomError> {
    if r.iter().any(|x| !x.is_finite()) {
        return Err(GeomError::InvalidTransform(
            "rotation has non-finite entries".into(),
        ));
    }
    let err = (r.transpose() * r - Matrix3::identity())
        .abs()
        .max()
        .to_f64();
    let det = r.determinant().to_f64();
    if err > ROTATION_TOL || (det - 1.0).abs() > ROTATION_TOL {
        return Err(GeomError::InvalidTransform(format!(
            "not a rotation: max |RᵀR − I| = {err:.2e}, det = {det:.6}"
        )));
    }
    Ok(())
}

/// File form of a rigid transform: row-major 3×3 rotation and a translation in metres.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigidFile {
    /// Rotation, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation, metres.
    pub translation_m: [f64; 3],
}

impl RigidFile {
    /// Validates and converts.
    pub fn to_rigid(&self) -> Result<Rigid3<f64>, GeomError> {
        let r = Matrix3::from_fn(|i, j| self.rotation[i][j]);
        Rigid3::new(r, Vector3::from(self.translation_m))
    }
    /// The file form of `t`.
    pub fn from_rigid<T: Real>(t: &Rigid3<T>) -> Self {
        Self {
            rotation: std::array::from_fn(|i| std::array::from_fn(|j| t.rotation[(i, j)].to_f64())),
            translation_m: std::array::from_fn(|i| t.translation[i].to_f64()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::axis_angle_to_matrix;

    fn rot(x: f64, y: f64, z: f64) -> Matrix3<f64> {
        axis_angle_to_matrix(&Vector3::new(x, y, z))
    }

    #[test]
    fn compose_and_inverse_round_trip() {
        let a_from_b = Rigid3::new(rot(0.3, -0.2, 1.1), Vector3::new(1.0, 2.0, -0.5)).unwrap();
        let b_from_c = Rigid3::new(rot(-0.7, 0.4, 0.1), Vector3::new(-0.3, 0.0, 0.9)).unwrap();
        let p_c = Vector3::new(0.2, -1.5, 3.0);
        let via = a_from_b.transform_point(&b_from_c.transform_point(&p_c));
        let direct = (a_from_b * b_from_c).transform_point(&p_c);
        assert!((via - direct).norm() < 1e-12);
        let back = a_from_b
            .inverse()
            .transform_point(&a_from_b.transform_point(&p_c));
        assert!((back - p_c).norm() < 1e-12);
    }

    #[test]
    fn similarity_scales_distances() {
        let s = Similarity3::new(rot(0.1, 0.5, -0.3), Vector3::new(0.0, 0.1, 0.6), 0.08).unwrap();
        let (p, q) = (Vector3::new(0.3, 0.1, -0.2), Vector3::new(-0.5, 0.4, 0.1));
        let d_b = (p - q).norm();
        let d_a = (s.transform_point(&p) - s.transform_point(&q)).norm();
        assert!((d_a - 0.08 * d_b).abs() < 1e-12);
        assert!((s.inverse_transform_point(&s.transform_point(&p)) - p).norm() < 1e-12);
        assert!((s.inverse().transform_point(&s.transform_point(&q)) - q).norm() < 1e-12);
        let t = Similarity3::new(rot(1.0, 0.0, 0.2), Vector3::new(1.0, 0.0, 0.0), 2.0).unwrap();
        let composed = (s * t).transform_point(&p);
        assert!((composed - s.transform_point(&t.transform_point(&p))).norm() < 1e-12);
    }

    #[test]
    fn rejects_non_rotations_and_bad_scale() {
        let shear = Matrix3::new(1.0, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(Rigid3::new(shear, Vector3::zeros()).is_err());
        let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        assert!(Rigid3::new(reflection, Vector3::zeros()).is_err());
        assert!(Similarity3::new(Matrix3::identity(), Vector3::zeros(), -1.0).is_err());
        assert!(Similarity3::new(Matrix3::identity(), Vector3::zeros(), f64::NAN).is_err());
        let f = RigidFile {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation_m: [f64::INFINITY, 0.0, 0.0],
        };
        assert!(f.to_rigid().is_err());
    }

    /// Umeyama recovers a known rigid motion exactly (scale 1 when not asked for), a known
    /// similarity with scale, never a mirror image, and refuses too few or unequal points.
    #[test]
    fn umeyama_recovers_known_alignments() {
        let a: Vec<Vector3<f64>> = [
            [0.0, 0.0, 0.0],
            [1.0, 0.2, -0.3],
            [0.4, 1.5, 0.2],
            [-0.6, 0.3, 0.9],
            [0.2, -0.8, 0.5],
        ]
        .map(Vector3::from)
        .to_vec();
        let r = rot(0.4, -0.9, 0.6);
        let t = Vector3::new(0.5, -1.0, 2.0);
        for (scale, with_scale) in [(1.0, false), (2.5, true)] {
            let b: Vec<_> = a.iter().map(|p| r * p * scale + t).collect();
            let s = Similarity3::umeyama(&a, &b, with_scale).unwrap();
            assert!((s.rotation - r).norm() < 1e-9 && (s.translation - t).norm() < 1e-9);
            assert!((s.scale - scale).abs() < 1e-9);
        }
        // A mirror image: the best proper rotation, not the reflection.
        let m: Vec<_> = a.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let s = Similarity3::umeyama(&a, &m, false).unwrap();
        assert!((s.rotation.determinant() - 1.0).abs() < 1e-9);
        assert!(Similarity3::umeyama(&a[..2], &m[..2], false).is_none());
        assert!(Similarity3::umeyama(&a, &m[..4], false).is_none());
        assert!(Similarity3::umeyama(&[a[0]; 4], &m[..4], false).is_none());
    }
}
