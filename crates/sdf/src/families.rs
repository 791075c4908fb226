//! Procedural shape families: the training data of the object priors (ShapeNet is not
//! redistributable). Each family is an analytic signed distance field with documented
//! parameters and ranges; [`FamilyShape::mesh`] extracts a watertight, outward-oriented mesh in
//! the normalised object frame (+Y up, +X front, inside the unit sphere).
//!
//! Raw units: bowl rim radius 1, mug base radius 1, car length 2. The normalisation (bounding-box
//! centre to the origin, half-diagonal to [`NORMALISED_RADIUS`]) removes the overall size, which
//! stage 1 fits as the similarity's scale.

use crate::SdfError;
use irmirror_geom::TriMesh;
use irmirror_render::sdf::Sdf;
use nalgebra::{Vector2, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Half-diagonal of a normalised shape's bounding box (the surface lies inside this sphere).
pub const NORMALISED_RADIUS: f64 = 0.9;

pub use irmirror_geom::Category;

/// Bowl parameters (raw units: rim radius 1). The wall is a shell of constant thickness around
/// the profile curve `ρ(s) = s (1 + flare s⁶)`, `y(s) = depth sᵉ`, s ∈ [0, 1], revolved about +Y.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BowlParams {
    /// Rim height above the bottom, 0.25 (plate-like) … 0.85 (deep).
    pub depth: f64,
    /// Wall thickness, 0.06 … 0.12.
    pub wall: f64,
    /// Profile exponent e: 1.6 (round) … 3.5 (flat bottom, steep wall).
    pub exponent: f64,
    /// Outward turn of the rim, 0 … 0.25.
    pub flare: f64,
    /// Foot ring height, 0 (none) … 0.1.
    pub foot_height: f64,
    /// Foot ring radius, 0.3 … 0.6.
    pub foot_radius: f64,
}

/// Mug parameters (raw units: base radius 1). A cup of revolution (outer radius 1 at the base,
/// `1 + taper` at the rim), a solid base, and a handle swept as a tube along a half ellipse in
/// the XY plane on the +X side.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MugParams {
    /// Height over base diameter, 0.7 … 1.4.
    pub aspect: f64,
    /// Rim radius minus base radius, −0.05 … 0.25 (tapered cups).
    pub taper: f64,
    /// Wall thickness, 0.06 … 0.12.
    pub wall: f64,
    /// Base thickness, 0.08 … 0.25.
    pub base: f64,
    /// Handle height over cup height, 0.45 … 0.8.
    pub handle_height: f64,
    /// Handle reach beyond the wall, 0.35 … 0.7.
    pub handle_reach: f64,
    /// Handle tube radius, 0.06 … 0.12.
    pub handle_tube: f64,
}

/// Car parameters (raw units: length 2 along X, +X front, ground at y = 0). A side profile
/// (bumpers, hood, windshield, roof, rear window, trunk) extruded across the width with
/// rounded edges, wheel arches cut out and wheels put in.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CarParams {
    /// Roof height, 0.5 (sedan) … 0.8 (SUV).
    pub roof: f64,
    /// Belt line (hood/trunk height), 0.26 … 0.4.
    pub belt: f64,
    /// Ground clearance, 0.08 … 0.16.
    pub clearance: f64,
    /// Windshield base x, 0.15 … 0.55 (smaller: shorter hood).
    pub windshield: f64,
    /// Windshield run (horizontal extent), 0.25 … 0.45.
    pub rake: f64,
    /// Roof rear x, −0.75 … −0.3.
    pub roof_rear: f64,
    /// Trunk: 0 (hatchback/SUV: the tail drops almost vertically) … 1 (sedan: a trunk deck).
    pub trunk: f64,
    /// Half width, 0.36 … 0.45.
    pub half_width: f64,
    /// Wheel radius, 0.15 … 0.2.
    pub wheel: f64,
    /// Wheel x position, ±(0.55 … 0.7).
    pub wheelbase: f64,
}

/// One member of a family.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "category", rename_all = "kebab-case")]
pub enum FamilyShape {
    /// A bowl.
    Bowl(BowlParams),
    /// A mug.
    Mug(MugParams),
    /// A car.
    Car(CarParams),
}

pub(crate) fn sd_box2(p: Vector2<f64>, centre: Vector2<f64>, half: Vector2<f64>) -> f64 {
    let q = (p - centre).abs() - half;
    Vector2::new(q.x.max(0.0), q.y.max(0.0)).norm() + q.x.max(q.y).min(0.0)
}

/// Exact distance to an open polyline.
pub(crate) fn polyline_distance(p: Vector2<f64>, pts: &[Vector2<f64>]) -> f64 {
    let mut best = f64::INFINITY;
    for w in pts.windows(2) {
        let e = w[1] - w[0];
        let t = ((p - w[0]).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
        best = best.min((p - w[0] - e * t).norm_squared());
    }
    best.sqrt()
}

/// Exact signed distance to a simple closed polygon (Quilez), negative inside.
pub(crate) fn polygon_distance(p: Vector2<f64>, v: &[Vector2<f64>]) -> f64 {
    let n = v.len();
    let mut d = (p - v[0]).norm_squared();
    let mut s = 1.0;
    for i in 0..n {
        let j = (i + n - 1) % n;
        let e = v[j] - v[i];
        let w = p - v[i];
        let b = w - e * (w.dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
        d = d.min(b.norm_squared());
        let c = [p.y >= v[i].y, p.y < v[j].y, e.x * w.y > e.y * w.x];
        if c.iter().all(|x| *x) || c.iter().all(|x| !*x) {
            s = -s;
        }
    }
    s * d.sqrt()
}

/// A car's wheel: a rounded disc about the Z axis through `hub` (x, y), centred at
/// `|z| = hub_z`, put in after its arch (a cylinder `arch_margin` wider, where
/// `|z| > arch_z`) is cut out of the body.
pub(crate) struct Wheel {
    pub hub: Vector2<f64>,
    pub radius: f64,
    pub arch_margin: f64,
    pub arch_z: f64,
    pub hub_z: f64,
    pub half_thickness: f64,
    pub rounding: f64,
}

impl Wheel {
    /// `body` (a signed distance at `p`) with the arch cut and the wheel added.
    pub(crate) fn fitted(&self, body: f64, p: &Vector3<f64>) -> f64 {
        let r = (Vector2::new(p.x, p.y) - self.hub).norm();
        let arch = (r - (self.radius + self.arch_margin)).max(self.arch_z - p.z.abs());
        let wheel = sd_box2(
            Vector2::new(r, p.z.abs()),
            Vector2::new(0.0, self.hub_z),
            Vector2::new(self.radius - self.rounding, self.half_thickness),
        ) - self.rounding;
        body.max(-arch).min(wheel)
    }
}

/// Polynomial smooth minimum (radius k): keeps unions smooth, as mirrors need.
pub(crate) fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

pub(crate) fn uniform(rng: &mut impl Rng, lo: f64, hi: f64) -> f64 {
    rng.random_range(lo..=hi)
}

impl BowlParams {
    fn profile(&self) -> Vec<Vector2<f64>> {
        (0..=64)
            .map(|i| {
                let s = i as f64 / 64.0;
                Vector2::new(
                    s * (1.0 + self.flare * s.powi(6)),
                    self.depth * s.powf(self.exponent),
                )
            })
            .collect()
    }
}

impl MugParams {
    fn height(&self) -> f64 {
        2.0 * self.aspect
    }
    /// Half ellipse of the handle's centre line (x, y), from the rim side down.
    fn handle_curve(&self) -> Vec<Vector2<f64>> {
        let h = self.height();
        let yc = 0.55 * h;
        let x0 = 1.0 + self.taper * yc / h - 0.5 * self.wall;
        let b = 0.5 * self.handle_height * h;
        (0..=32)
            .map(|i| {
                let th = std::f64::consts::PI * (0.5 - i as f64 / 32.0);
                Vector2::new(
                    x0 + (self.handle_reach + 0.5 * self.wall) * th.cos(),
                    yc + b * th.sin(),
                )
            })
            .collect()
    }
    fn section(&self) -> Vec<Vector2<f64>> {
        // Symmetric about the axis so that the revolved distance is exact near it.
        let (h, t, w, b) = (self.height(), self.taper, self.wall, self.base);
        let inner_bottom = 1.0 - w + t * b / h;
        vec![
            Vector2::new(-1.0, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(1.0 + t, h),
            Vector2::new(1.0 + t - w, h),
            Vector2::new(inner_bottom, b),
            Vector2::new(-inner_bottom, b),
            Vector2::new(-(1.0 + t - w), h),
            Vector2::new(-(1.0 + t), h),
        ]
    }
}

impl CarParams {
    fn profile(&self) -> Vec<Vector2<f64>> {
        let (c, b, r) = (self.clearance, self.belt, self.roof);
        let tail = (-0.96f64).max(self.roof_rear - 0.05) * (1.0 - self.trunk)
            + (self.roof_rear - 0.3).max(-0.9) * self.trunk;
        let tail_y = b + 0.03 * self.trunk + (1.0 - self.trunk) * 0.5 * (r - b);
        vec![
            Vector2::new(-1.0, c + 0.05),
            Vector2::new(-0.96, c),
            Vector2::new(0.96, c),
            Vector2::new(1.0, c + 0.05),
            Vector2::new(1.0, b - 0.06),
            Vector2::new(0.9, b),
            Vector2::new(self.windshield, b + 0.03),
            Vector2::new(self.windshield - self.rake, r),
            Vector2::new(self.roof_rear, r),
            Vector2::new(tail, tail_y),
            Vector2::new(-0.98, b),
        ]
    }
}

impl FamilyShape {
    /// The category.
    pub fn category(&self) -> Category {
        match self {
            FamilyShape::Bowl(_) => Category::Bowl,
            FamilyShape::Mug(_) => Category::Mug,
            FamilyShape::Car(_) => Category::Car,
        }
    }

    /// A member drawn uniformly from the documented parameter ranges (categories with a
    /// learned prior only).
    pub fn sample(category: Category, rng: &mut impl Rng) -> Result<Self, SdfError> {
        Ok(match category {
            Category::Bowl => {
                let foot = rng.random_bool(0.6);
                FamilyShape::Bowl(BowlParams {
                    depth: uniform(rng, 0.25, 0.85),
                    wall: uniform(rng, 0.06, 0.12),
                    exponent: uniform(rng, 1.6, 3.5),
                    flare: uniform(rng, 0.0, 0.25),
                    foot_height: if foot { uniform(rng, 0.03, 0.1) } else { 0.0 },
                    foot_radius: uniform(rng, 0.3, 0.6),
                })
            }
            Category::Mug => FamilyShape::Mug(MugParams {
                aspect: uniform(rng, 0.7, 1.4),
                taper: uniform(rng, -0.05, 0.25),
                wall: uniform(rng, 0.06, 0.12),
                base: uniform(rng, 0.08, 0.25),
                handle_height: uniform(rng, 0.45, 0.8),
                handle_reach: uniform(rng, 0.35, 0.7),
                handle_tube: uniform(rng, 0.06, 0.12),
            }),
            Category::Car => {
                let roof = uniform(rng, 0.5, 0.8);
                FamilyShape::Car(CarParams {
                    roof,
                    belt: uniform(rng, 0.26, 0.4).min(roof - 0.15),
                    clearance: uniform(rng, 0.08, 0.16),
                    windshield: uniform(rng, 0.15, 0.55),
                    rake: uniform(rng, 0.25, 0.45),
                    roof_rear: uniform(rng, -0.75, -0.3),
                    trunk: if rng.random_bool(0.5) {
                        uniform(rng, 0.6, 1.0)
                    } else {
                        uniform(rng, 0.0, 0.3)
                    },
                    half_width: uniform(rng, 0.36, 0.45),
                    wheel: uniform(rng, 0.17, 0.2),
                    wheelbase: uniform(rng, 0.55, 0.7),
                })
            }
            Category::Sphere => return Err(SdfError::NoPrior(category)),
        })
    }

    /// Raw-unit bounding box `(lo, hi)` of the surface.
    pub fn raw_bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            FamilyShape::Bowl(b) => {
                let r = 1.0 + b.flare + 0.5 * b.wall;
                (
                    Vector3::new(-r, -0.5 * b.wall - b.foot_height - 0.02, -r),
                    Vector3::new(r, b.depth + 0.5 * b.wall, r),
                )
            }
            FamilyShape::Mug(m) => {
                let r = 1.0 + m.taper.max(0.0) + 0.01;
                let x_max = m.handle_curve().iter().map(|q| q.x).fold(r, f64::max) + m.handle_tube;
                (
                    Vector3::new(-r, -0.01, -r),
                    Vector3::new(x_max, m.height() + 0.01, r),
                )
            }
            FamilyShape::Car(c) => (
                Vector3::new(-1.0, 0.0, -c.half_width),
                Vector3::new(1.0, c.roof, c.half_width),
            ),
        }
    }

    /// `(centre, k)`: raw point = centre + k · normalised point.
    pub fn normalisation(&self) -> (Vector3<f64>, f64) {
        let (lo, hi) = self.raw_bounds();
        ((lo + hi) / 2.0, (hi - lo).norm() / 2.0 / NORMALISED_RADIUS)
    }

    /// Signed distance in the normalised object frame. Builds the curves on every call: for many
    /// queries use [`FamilyShape::prepare`].
    pub fn distance(&self, q: &Vector3<f64>) -> f64 {
        self.prepare().distance(q)
    }

    /// The shape with its curves and normalisation computed once.
    pub fn prepare(&self) -> PreparedShape {
        let (centre, k) = self.normalisation();
        let (curve, polygon) = match self {
            FamilyShape::Bowl(b) => (b.profile(), Vec::new()),
            FamilyShape::Mug(m) => (m.handle_curve(), m.section()),
            FamilyShape::Car(c) => (Vec::new(), c.profile()),
        };
        PreparedShape {
            shape: *self,
            centre,
            k,
            curve,
            polygon,
        }
    }

    /// The surface as a watertight, outward-oriented mesh in the normalised frame: marching
    /// tetrahedra over a cube around the padded bounding box, `resolution` cells per side.
    pub fn mesh(&self, resolution: usize) -> TriMesh {
        let prepared = self.prepare();
        mesh_in_bounds(
            |q| prepared.distance(q),
            self.raw_bounds(),
            (prepared.centre, prepared.k),
            resolution,
        )
    }
}

/// Marching tetrahedra over a cube around the padded raw bounds `(lo, hi)`, mapped to the
/// normalised frame by `(centre, k)` (raw = centre + k · normalised); `distance` in the
/// normalised frame.
pub(crate) fn mesh_in_bounds(
    distance: impl Fn(&Vector3<f64>) -> f64 + Sync,
    (lo, hi): (Vector3<f64>, Vector3<f64>),
    (c, k): (Vector3<f64>, f64),
    resolution: usize,
) -> TriMesh {
    let pad = Vector3::repeat(0.03 * k.max(1.0));
    // (Kept in this exact arithmetic: the shipped priors were trained on these grids.)
    let (lo, hi) = ((lo - c) / k - pad / k, (hi - c) / k + pad / k);
    let cell = (hi - lo).max() / resolution as f64;
    let half = Vector3::repeat(cell * resolution as f64 / 2.0);
    let centre = (lo + hi) / 2.0;
    irmirror_geom::isosurface::isosurface(distance, centre - half, centre + half, resolution)
}

/// A family member ready for many distance queries (meshing evaluates millions).
#[derive(Clone, Debug)]
pub struct PreparedShape {
    shape: FamilyShape,
    centre: Vector3<f64>,
    k: f64,
    /// Bowl: the profile; mug: the handle's centre line.
    curve: Vec<Vector2<f64>>,
    /// Mug: the cup's cross-section; car: the side profile.
    polygon: Vec<Vector2<f64>>,
}

impl PreparedShape {
    /// Signed distance in raw units.
    pub fn raw_distance(&self, p: &Vector3<f64>) -> f64 {
        let rho = Vector2::new(p.x, p.z).norm();
        match &self.shape {
            FamilyShape::Bowl(b) => {
                let q = Vector2::new(rho, p.y);
                let shell = polyline_distance(q, &self.curve) - 0.5 * b.wall;
                if b.foot_height > 0.0 {
                    let foot = sd_box2(
                        q,
                        Vector2::new(b.foot_radius, -0.25 * b.wall - 0.5 * b.foot_height),
                        Vector2::new(0.4 * b.wall, 0.5 * b.foot_height + 0.25 * b.wall),
                    ) - 0.1 * b.wall;
                    smin(shell, foot, 0.04)
                } else {
                    shell
                }
            }
            FamilyShape::Mug(m) => {
                let cup = polygon_distance(Vector2::new(rho, p.y), &self.polygon) - 0.01;
                let d2 = polyline_distance(Vector2::new(p.x, p.y), &self.curve);
                let x_wall = self.curve[0].x;
                let handle = ((d2 * d2 + p.z * p.z).sqrt() - m.handle_tube).max(x_wall - p.x);
                smin(cup, handle, 0.05)
            }
            FamilyShape::Car(c) => {
                let d2 = polygon_distance(Vector2::new(p.x, p.y), &self.polygon);
                let r_edge = 0.08;
                let w = Vector2::new(d2 + r_edge, p.z.abs() - c.half_width + r_edge);
                let mut body = w.x.max(w.y).min(0.0)
                    + Vector2::new(w.x.max(0.0), w.y.max(0.0)).norm()
                    - r_edge;
                for xw in [c.wheelbase, -c.wheelbase] {
                    let wheel = Wheel {
                        hub: Vector2::new(xw, c.wheel),
                        radius: c.wheel,
                        arch_margin: 0.03,
                        arch_z: c.half_width - 0.14,
                        hub_z: c.half_width - 0.08,
                        half_thickness: 0.06,
                        rounding: 0.02,
                    };
                    body = wheel.fitted(body, p);
                }
                body
            }
        }
    }

    /// Signed distance in the normalised object frame.
    pub fn distance(&self, q: &Vector3<f64>) -> f64 {
        self.raw_distance(&(self.centre + q * self.k)) / self.k
    }
}

impl Sdf for PreparedShape {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        PreparedShape::distance(self, p)
    }
    fn bounding_radius(&self) -> f64 {
        NORMALISED_RADIUS + 0.05
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_distance_is_exact_on_a_square() {
        let sq = [
            Vector2::new(-1.0, -1.0),
            Vector2::new(1.0, -1.0),
            Vector2::new(1.0, 1.0),
            Vector2::new(-1.0, 1.0),
        ];
        assert!((polygon_distance(Vector2::new(0.0, 0.0), &sq) + 1.0).abs() < 1e-12);
        assert!((polygon_distance(Vector2::new(3.0, 0.0), &sq) - 2.0).abs() < 1e-12);
        assert!((polygon_distance(Vector2::new(2.0, 2.0), &sq) - 2f64.sqrt()).abs() < 1e-12);
    }
}
