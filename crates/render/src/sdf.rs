//! Signed distance functions in a normalised object frame, and their placement in the scene.
//!
//! Object frames are **+Y up** (ShapeNet/DeepSDF convention), object units, surface inside the
//! sphere of radius [`Sdf::bounding_radius`] about the origin. A [`PlacedSdf`] puts one into the
//! depth-camera frame with a similarity `depth_from_object` (R, t, s): distances scale,
//! `d_depth = s · d_object`.

use irmirror_geom::Similarity3;
use nalgebra::{Vector2, Vector3};
use std::sync::Arc;

/// A signed distance field (negative inside), object frame and units.
pub trait Sdf: Send + Sync {
    /// Signed distance at `p`.
    fn distance(&self, p: &Vector3<f64>) -> f64;
    /// Gradient of the distance (unit length where the field is exact). The default uses central
    /// differences (h = 1e-6), accurate to ~1e-9 for smooth fields; analytic shapes override it.
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let h = 1e-6;
        Vector3::from_fn(|k, _| {
            let mut e = Vector3::zeros();
            e[k] = h;
            (self.distance(&(p + e)) - self.distance(&(p - e))) / (2.0 * h)
        })
    }
    /// Radius of an origin-centred sphere containing the whole surface.
    fn bounding_radius(&self) -> f64;
    /// The longest step a sphere tracer may take on this field, object units: the width of
    /// the band about the surface where the field is a distance. An exact SDF has no limit; a
    /// network trained on clamped distances (DeepSDF) is a distance only within its clamp, and
    /// beyond it may rise twice as fast as one, so a step by its value there crosses the surface.
    fn max_step(&self) -> f64 {
        f64::INFINITY
    }
}

/// A sphere of `radius` about the origin.
#[derive(Clone, Copy, Debug)]
pub struct Sphere {
    /// Radius, object units.
    pub radius: f64,
}

impl Sdf for Sphere {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        p.norm() - self.radius
    }
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let n = p.norm();
        if n > 0.0 { p / n } else { Vector3::y() }
    }
    fn bounding_radius(&self) -> f64 {
        self.radius
    }
}

/// A capsule: all points within `radius` of the segment from `a` to `b`.
#[derive(Clone, Copy, Debug)]
pub struct Capsule {
    /// Segment start.
    pub a: Vector3<f64>,
    /// Segment end.
    pub b: Vector3<f64>,
    /// Radius.
    pub radius: f64,
}

impl Capsule {
    fn closest(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let ab = self.b - self.a;
        let l2 = ab.norm_squared();
        let u = if l2 > 0.0 {
            ((p - self.a).dot(&ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.a + ab * u
    }
}

impl Sdf for Capsule {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        (p - self.closest(p)).norm() - self.radius
    }
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let d = p - self.closest(p);
        let n = d.norm();
        if n > 0.0 { d / n } else { Vector3::y() }
    }
    fn bounding_radius(&self) -> f64 {
        self.a.norm().max(self.b.norm()) + self.radius
    }
}

/// A cylinder about +Y with rounded rims (Quilez): core radius `radius`, rim rounding
/// `rounding`, half height `half_height` (rounding included).
#[derive(Clone, Copy, Debug)]
pub struct RoundedCylinder {
    /// Outer radius.
    pub radius: f64,
    /// Rounding radius of the rims (≤ radius, ≤ half height).
    pub rounding: f64,
    /// Half the height.
    pub half_height: f64,
}

impl Sdf for RoundedCylinder {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        let r = self.rounding;
        let d = Vector2::new(
            Vector2::new(p.x, p.z).norm() - self.radius + r,
            p.y.abs() - self.half_height + r,
        );
        d.x.max(d.y).min(0.0) + Vector2::new(d.x.max(0.0), d.y.max(0.0)).norm() - r
    }
    fn bounding_radius(&self) -> f64 {
        self.radius.hypot(self.half_height)
    }
}

/// A thin-walled bowl: the part of a spherical shell (radius `radius`, wall half-thickness
/// `half_thickness`) below the plane `y = cut_height` (Quilez's cut hollow sphere), opening
/// towards +Y. `cut_height` in (−radius, radius): negative is shallow, positive deeper than a
/// hemisphere.
#[derive(Clone, Copy, Debug)]
pub struct Bowl {
    /// Mid-wall radius of the spherical shell.
    pub radius: f64,
    /// Height of the rim plane relative to the sphere centre.
    pub cut_height: f64,
    /// Half the wall thickness.
    pub half_thickness: f64,
}

impl Bowl {
    fn rim_radius(&self) -> f64 {
        (self.radius * self.radius - self.cut_height * self.cut_height)
            .max(0.0)
            .sqrt()
    }
}

impl Sdf for Bowl {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        let w = self.rim_radius();
        let q = Vector2::new(Vector2::new(p.x, p.z).norm(), p.y);
        let d = if self.cut_height * q.x < w * q.y {
            (q - Vector2::new(w, self.cut_height)).norm()
        } else {
            (q.norm() - self.radius).abs()
        };
        d - self.half_thickness
    }
    /// Analytic: from the rim circle where the rim is nearer, else along the radius of the
    /// shell's sphere; one evaluation instead of central differences' six.
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let w = self.rim_radius();
        let rho = Vector2::new(p.x, p.z).norm();
        let q = Vector2::new(rho, p.y);
        let g = if self.cut_height * q.x < w * q.y {
            let e = q - Vector2::new(w, self.cut_height);
            let n = e.norm();
            if n > 0.0 { e / n } else { Vector2::zeros() }
        } else {
            let n = q.norm();
            let s = if n >= self.radius { 1.0 } else { -1.0 };
            if n > 0.0 {
                q * (s / n)
            } else {
                Vector2::zeros()
            }
        };
        // ∂ρ/∂(x, z); none on the axis (central differences give 0 there too).
        let (ax, az) = if rho > 0.0 {
            (p.x / rho, p.z / rho)
        } else {
            (0.0, 0.0)
        };
        Vector3::new(g.x * ax, g.y, g.x * az)
    }
    fn bounding_radius(&self) -> f64 {
        self.radius + self.half_thickness
    }
}

/// An SDF placed in the depth-camera frame.
#[derive(Clone)]
pub struct PlacedSdf {
    /// The shape.
    pub sdf: Arc<dyn Sdf>,
    /// Object frame → depth frame (similarity; scale in metres per object unit).
    pub depth_from_object: Similarity3<f64>,
}

impl PlacedSdf {
    /// Signed distance at a depth-frame point, metres.
    pub fn distance(&self, p_depth: &Vector3<f64>) -> f64 {
        self.depth_from_object.scale
            * self
                .sdf
                .distance(&self.depth_from_object.inverse_transform_point(p_depth))
    }
    /// Unit outward normal at a depth-frame point (the rotated, normalised SDF gradient).
    pub fn normal(&self, p_depth: &Vector3<f64>) -> Vector3<f64> {
        let g = self
            .sdf
            .gradient(&self.depth_from_object.inverse_transform_point(p_depth));
        (self.depth_from_object.rotation * g)
            .try_normalize(0.0)
            .unwrap_or_else(Vector3::y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_gradients_match_finite_differences_and_are_unit() {
        let shapes: Vec<Box<dyn Sdf>> = vec![
            Box::new(Sphere { radius: 0.7 }),
            Box::new(Capsule {
                a: Vector3::new(-0.3, 0.0, 0.1),
                b: Vector3::new(0.4, 0.2, 0.0),
                radius: 0.2,
            }),
            Box::new(RoundedCylinder {
                radius: 0.5,
                rounding: 0.1,
                half_height: 0.6,
            }),
            Box::new(Bowl {
                radius: 0.8,
                cut_height: 0.2,
                half_thickness: 0.03,
            }),
        ];
        // Generic points (not on a medial axis or a crease of the field).
        let pts = [
            Vector3::new(0.31, -0.52, 0.17),
            Vector3::new(-0.9, 0.25, 0.4),
            Vector3::new(0.1, 0.9, -0.35),
        ];
        for s in &shapes {
            for p in &pts {
                let g = s.gradient(p);
                let h = 1e-6;
                let fd = Vector3::from_fn(|k, _| {
                    let mut e = Vector3::zeros();
                    e[k] = h;
                    (s.distance(&(p + e)) - s.distance(&(p - e))) / (2.0 * h)
                });
                assert!((g - fd).norm() < 1e-6, "{g:?} vs {fd:?}");
                assert!(
                    (g.norm() - 1.0).abs() < 1e-6,
                    "exact SDFs have unit gradients"
                );
            }
        }
    }

    #[test]
    fn bowl_is_hollow_and_open_at_the_top() {
        let b = Bowl {
            radius: 1.0,
            cut_height: 0.0,
            half_thickness: 0.02,
        };
        assert!(
            b.distance(&Vector3::new(0.0, -1.0, 0.0)) < 0.0,
            "the bottom wall is solid"
        );
        assert!(
            (b.distance(&Vector3::new(0.0, -0.5, 0.0)) - 0.48).abs() < 1e-12,
            "the inside is empty"
        );
        assert!(b.distance(&Vector3::new(0.0, 0.5, 0.0)) > 0.4, "no lid");
    }

    #[test]
    fn placement_scales_distances() {
        let placed = PlacedSdf {
            sdf: Arc::new(Sphere { radius: 1.0 }),
            depth_from_object: Similarity3::new(
                nalgebra::Matrix3::identity(),
                Vector3::new(0.0, 0.0, 0.5),
                0.15,
            )
            .unwrap(),
        };
        assert!((placed.distance(&Vector3::new(0.0, 0.0, 0.0)) - 0.35).abs() < 1e-12);
        assert!(
            (placed.normal(&Vector3::new(0.0, 0.0, 0.2)) - Vector3::new(0.0, 0.0, -1.0)).norm()
                < 1e-12
        );
    }
}
