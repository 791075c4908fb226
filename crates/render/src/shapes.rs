//! Procedural object families: analytic SDFs in the normalised object frame (+Y up, unit
//! sphere), with documented parameters. The simulator builds its scenes from them and stage 1
//! fits them (a low-dimensional shape prior until the learned DeepSDF priors of issue 4 land).

use crate::sdf::{Bowl, Sdf};
use irmirror_geom::Category;
use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A shape and its parameters (object units; the object is scaled to metres when placed).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "category", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    /// A sphere of radius 1 (a mirror ball; the renderer benchmark's reflector).
    Sphere,
    /// Thin-walled bowl: a spherical shell cut by the rim plane.
    Bowl {
        /// Rim height above the sphere centre, in shell radii (−0.6 shallow … 0.3 deep).
        cut: f64,
        /// Wall thickness, in shell radii.
        wall: f64,
    },
    /// Cylindrical mug with a bottom and a torus handle.
    Mug {
        /// Height over diameter.
        aspect: f64,
        /// Wall thickness over radius.
        wall: f64,
    },
    /// A car body: lower body and cabin, smoothly joined; +X is the front.
    Car {
        /// Cabin length over body length (sedan ≈ 0.5, hatchback ≈ 0.6, SUV ≈ 0.7).
        cabin: f64,
        /// Height over length.
        height: f64,
    },
}

/// In words, for logs and reports: `bowl (rim 0.12 above the centre, wall 0.07)`.
impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Shape::Sphere => write!(f, "sphere"),
            Shape::Bowl { cut, wall } => write!(
                f,
                "bowl (rim {cut:+.2} above the centre, wall {wall:.3}, in shell radii)"
            ),
            Shape::Mug { aspect, wall } => write!(
                f,
                "mug (height {aspect:.2} × the diameter, wall {wall:.3} of the radius)"
            ),
            Shape::Car { cabin, height } => write!(
                f,
                "car (cabin {cabin:.2} of the length, height {height:.2} × the length)"
            ),
        }
    }
}

impl Shape {
    /// The category.
    pub fn category(&self) -> Category {
        match self {
            Shape::Sphere => Category::Sphere,
            Shape::Bowl { .. } => Category::Bowl,
            Shape::Mug { .. } => Category::Mug,
            Shape::Car { .. } => Category::Car,
        }
    }

    /// The signed distance field.
    pub fn sdf(&self) -> Arc<dyn Sdf> {
        match *self {
            Shape::Sphere => Arc::new(crate::sdf::Sphere { radius: 1.0 }),
            Shape::Bowl { cut, wall } => {
                // Shell radius so that the bowl fits the unit sphere.
                let r = 0.95;
                Arc::new(Bowl {
                    radius: r,
                    cut_height: cut * r,
                    half_thickness: 0.5 * wall * r,
                })
            }
            Shape::Mug { .. } => Arc::new(self.mug().expect("a mug")),
            Shape::Car { cabin, height } => Arc::new(Car { cabin, height }),
        }
    }

    /// The mug's geometry (None for other shapes): height 2h and radius ρ (with the handle)
    /// fitted into the unit sphere.
    pub fn mug(&self) -> Option<Mug> {
        match *self {
            Shape::Mug { aspect, wall } => {
                let rho = 0.9 / (1.0f64 + aspect * aspect).sqrt() / 1.2;
                Some(Mug {
                    radius: rho,
                    half_height: aspect * rho,
                    wall: wall * rho,
                })
            }
            _ => None,
        }
    }

    /// Lowest object-frame y of the surface (to stand the object on a support plane).
    pub fn base_y(&self) -> f64 {
        match *self {
            Shape::Sphere => -1.0,
            Shape::Bowl { wall, .. } => -0.95 - 0.5 * wall * 0.95,
            Shape::Mug { aspect, .. } => -aspect * 0.9 / (1.0f64 + aspect * aspect).sqrt() / 1.2,
            Shape::Car { height, .. } => -height * 0.95,
        }
    }
}

/// Signed distance to the solid cylinder about +Y of `radius` between heights `y0` and `y1`, at
/// the point `(rho, y)` — `rho` its distance from the axis, which coaxial cylinders share.
#[inline]
fn capped_cylinder_at(rho: f64, y: f64, radius: f64, y0: f64, y1: f64) -> f64 {
    let d = Vector2::new(rho - radius, (y - 0.5 * (y0 + y1)).abs() - 0.5 * (y1 - y0));
    d.x.max(d.y).min(0.0) + Vector2::new(d.x.max(0.0), d.y.max(0.0)).norm()
}

/// [`capped_cylinder_at`]'s derivatives in `(rho, y)`: the gradient of whichever part sets
/// it (outside a corner: the corner's direction; inside: the nearer face).
#[inline]
fn capped_cylinder_grad(rho: f64, y: f64, radius: f64, y0: f64, y1: f64) -> (f64, f64) {
    let yc = y - 0.5 * (y0 + y1);
    let d = Vector2::new(rho - radius, yc.abs() - 0.5 * (y1 - y0));
    let sy = if yc < 0.0 { -1.0 } else { 1.0 };
    if d.x > 0.0 && d.y > 0.0 {
        let n = d.norm();
        (d.x / n, sy * d.y / n)
    } else if d.x > d.y {
        (1.0, 0.0)
    } else {
        (0.0, sy)
    }
}

/// Cylindrical mug, +Y up, bottom at `−half_height`, open at the top, handle towards +X.
#[derive(Clone, Copy, Debug)]
pub struct Mug {
    /// Outer radius.
    pub radius: f64,
    /// Half the height.
    pub half_height: f64,
    /// Wall (and bottom) thickness.
    pub wall: f64,
}

impl Mug {
    /// Signed distance to the cup alone (the mug without its handle).
    pub fn cup_distance(&self, p: &Vector3<f64>) -> f64 {
        let h = self.half_height;
        let rho = Vector2::new(p.x, p.z).norm();
        let outer = capped_cylinder_at(rho, p.y, self.radius, -h, h);
        let cavity = capped_cylinder_at(rho, p.y, self.radius - self.wall, -h + self.wall, h + 1.0);
        outer.max(-cavity)
    }
}

impl Sdf for Mug {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        let h = self.half_height;
        let shell = self.cup_distance(p);
        // Handle: a torus in the XY plane beside the wall, clipped to outside the wall. The clip
        // bounds it from below, so where the clip alone is no nearer than the cup the minimum
        // is the cup's (most points: the mug's other side), without the torus.
        let clip = self.radius - 0.5 * self.wall - p.x;
        if clip >= shell {
            return shell;
        }
        let c = Vector2::new(self.radius, 0.0);
        let big = 0.45 * h;
        let q = Vector2::new((Vector2::new(p.x, p.y) - c).norm() - big, p.z);
        let handle = (q.norm() - 0.35 * self.wall.max(0.05)).max(clip);
        shell.min(handle)
    }
    /// Analytic: the gradient of the piece that sets the distance (cup wall, cavity, handle
    /// tube or its clip plane); one evaluation instead of central differences' six.
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let h = self.half_height;
        let rho = Vector2::new(p.x, p.z).norm();
        // ∂ρ/∂(x, z); none on the axis (central differences give 0 there too).
        let (ax, az) = if rho > 0.0 {
            (p.x / rho, p.z / rho)
        } else {
            (0.0, 0.0)
        };
        let cyl = |(gr, gy): (f64, f64)| Vector3::new(gr * ax, gy, gr * az);
        let outer = capped_cylinder_at(rho, p.y, self.radius, -h, h);
        let (rc, c0, c1) = (self.radius - self.wall, -h + self.wall, h + 1.0);
        let cavity = capped_cylinder_at(rho, p.y, rc, c0, c1);
        let (shell, g_shell) = if outer >= -cavity {
            (
                outer,
                cyl(capped_cylinder_grad(rho, p.y, self.radius, -h, h)),
            )
        } else {
            (-cavity, -cyl(capped_cylinder_grad(rho, p.y, rc, c0, c1)))
        };
        let clip = self.radius - 0.5 * self.wall - p.x;
        if clip >= shell {
            return g_shell;
        }
        let w = Vector2::new(p.x - self.radius, p.y);
        let wn = w.norm();
        let q = Vector2::new(wn - 0.45 * h, p.z);
        let qn = q.norm();
        let torus = qn - 0.35 * self.wall.max(0.05);
        let (handle, g_handle) = if torus >= clip {
            let g = if wn > 0.0 && qn > 0.0 {
                let k = q.x / (qn * wn);
                Vector3::new(k * w.x, k * w.y, q.y / qn)
            } else {
                Vector3::zeros()
            };
            (torus, g)
        } else {
            (clip, Vector3::new(-1.0, 0.0, 0.0))
        };
        if shell <= handle { g_shell } else { g_handle }
    }
    fn bounding_radius(&self) -> f64 {
        ((self.radius + 0.45 * self.half_height + 0.1).powi(2) + self.half_height.powi(2)).sqrt()
    }
}

fn rounded_box(p: &Vector3<f64>, half: &Vector3<f64>, r: f64) -> f64 {
    let q = p.abs() - half + Vector3::repeat(r);
    q.sup(&Vector3::zeros()).norm() + q.x.max(q.y.max(q.z)).min(0.0) - r
}

/// A smooth car body in the unit sphere: length 1.9 along X (+X front), +Y up.
#[derive(Clone, Copy, Debug)]
pub struct Car {
    /// Cabin length over body length.
    pub cabin: f64,
    /// Total height over length.
    pub height: f64,
}

impl Sdf for Car {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        let (len, h) = (0.95, self.height * 0.95 * 2.0);
        let lower_h = 0.55 * h;
        let body = rounded_box(
            &(p - Vector3::new(0.0, -h / 2.0 + lower_h / 2.0, 0.0)),
            &Vector3::new(len, lower_h / 2.0, 0.4),
            0.12,
        );
        let cab_h = h - lower_h;
        let cabin = rounded_box(
            &(p - Vector3::new(-0.1 * len, -h / 2.0 + lower_h + cab_h / 2.0 - 0.05, 0.0)),
            &Vector3::new(self.cabin * len, cab_h / 2.0 + 0.05, 0.36),
            0.15,
        );
        // Polynomial smooth union (k = 0.12): keeps the body a smooth mirror.
        let k = 0.12;
        let hh = (k - (body - cabin).abs()).max(0.0) / k;
        body.min(cabin) - hh * hh * k * 0.25
    }
    fn bounding_radius(&self) -> f64 {
        1.1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Logs and reports show a shape in words with its parameters, not Rust's debug syntax.
    #[test]
    fn shapes_read_as_words() {
        let m = Shape::Mug {
            aspect: 1.1971,
            wall: 0.1246,
        }
        .to_string();
        assert_eq!(
            m,
            "mug (height 1.20 × the diameter, wall 0.125 of the radius)"
        );
        let b = Shape::Bowl {
            cut: -0.1153,
            wall: 0.068,
        }
        .to_string();
        assert!(b.starts_with("bowl (rim -0.12") && !b.contains('{'), "{b}");
    }

    #[test]
    fn shapes_fit_the_unit_sphere_and_stand_on_their_base() {
        for s in [
            Shape::Bowl {
                cut: 0.0,
                wall: 0.06,
            },
            Shape::Mug {
                aspect: 1.1,
                wall: 0.1,
            },
            Shape::Car {
                cabin: 0.5,
                height: 0.3,
            },
        ] {
            let sdf = s.sdf();
            // Far points are outside; the base point is on the surface.
            assert!(sdf.distance(&Vector3::new(0.0, 0.0, 1.2)) > 0.0);
            let r = sdf.bounding_radius();
            for dir in [
                Vector3::x(),
                Vector3::y(),
                Vector3::z(),
                -Vector3::x(),
                -Vector3::y(),
                -Vector3::z(),
            ] {
                assert!(
                    sdf.distance(&(dir * (r + 1e-3))) > 0.0,
                    "{s:?} pokes out of its bounding sphere"
                );
            }
            let m = irmirror_geom::isosurface::isosurface(
                |p| sdf.distance(p),
                Vector3::repeat(-1.0),
                Vector3::repeat(1.0),
                48,
            );
            let ymin = m
                .vertices
                .iter()
                .map(|v| f64::from(v[1]))
                .fold(f64::MAX, f64::min);
            assert!(
                (ymin - s.base_y()).abs() < 0.03,
                "{s:?}: base {ymin} vs {}",
                s.base_y()
            );
            assert!(m.signed_volume() > 0.0);
        }
    }

    #[test]
    fn mug_is_open_and_hollow() {
        let m = Mug {
            radius: 0.5,
            half_height: 0.5,
            wall: 0.05,
        };
        assert!(m.distance(&Vector3::new(0.0, 0.0, 0.0)) > 0.3, "cavity");
        assert!(m.distance(&Vector3::new(0.0, -0.49, 0.0)) < 0.0, "bottom");
        assert!(m.distance(&Vector3::new(0.0, 0.6, 0.0)) > 0.0, "open top");
    }

    /// Calls `f` at 500 uniform points in the unit cube about each of 40 mugs of the shapes the
    /// fit draws (random aspect and wall), with the generator for any further draws.
    fn for_random_mug_points(
        seed: u64,
        mut f: impl FnMut(&Mug, Vector3<f64>, &mut rand_chacha::ChaCha8Rng),
    ) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for _ in 0..40 {
            let m = Shape::Mug {
                aspect: rng.random_range(0.6..1.8),
                wall: rng.random_range(0.04..0.3),
            }
            .mug()
            .unwrap();
            for _ in 0..500 {
                let p = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
                f(&m, p, &mut rng);
            }
        }
    }

    /// The mug's distance skips the handle's torus where the cup is nearer than the handle's
    /// clip plane: the same value, to the bit, as the union written out in full, in and around
    /// mugs of every shape the fit draws (handle side, far side, inside, on the surface).
    #[test]
    fn mug_distance_equals_the_full_union() {
        use rand::Rng;
        let full = |m: &Mug, p: &Vector3<f64>| {
            let h = m.half_height;
            let rho = Vector2::new(p.x, p.z).norm();
            let cyl = |radius: f64, y0: f64, y1: f64| {
                let d = Vector2::new(
                    rho - radius,
                    (p.y - 0.5 * (y0 + y1)).abs() - 0.5 * (y1 - y0),
                );
                d.x.max(d.y).min(0.0) + Vector2::new(d.x.max(0.0), d.y.max(0.0)).norm()
            };
            let shell = cyl(m.radius, -h, h).max(-cyl(m.radius - m.wall, -h + m.wall, h + 1.0));
            let c = Vector2::new(m.radius, 0.0);
            let q = Vector2::new((Vector2::new(p.x, p.y) - c).norm() - 0.45 * h, p.z);
            let handle = (q.norm() - 0.35 * m.wall.max(0.05)).max(m.radius - 0.5 * m.wall - p.x);
            shell.min(handle)
        };
        let (mut skipped, mut torus) = (0, 0);
        for_random_mug_points(3, |m, p, rng| {
            let p = p * if rng.random_bool(0.5) { 1.0 } else { 0.6 };
            let (a, b) = (m.distance(&p), full(m, &p));
            assert_eq!(a.to_bits(), b.to_bits(), "{m:?} at {p:?}: {a} vs {b}");
            if m.radius - 0.5 * m.wall - p.x >= m.cup_distance(&p) {
                skipped += 1;
            } else {
                torus += 1;
            }
        });
        // Both branches are exercised.
        assert!(
            skipped > 1000 && torus > 1000,
            "{skipped} skipped, {torus} with the torus"
        );
    }

    /// The mug's analytic gradient against central differences, wherever the field is smooth
    /// (differences at two step sizes agree: not within a step of a crease, where differences
    /// average two sides), near the surface and away from it; and it has unit length there.
    #[test]
    fn mug_gradient_matches_central_differences() {
        use rand::Rng;
        let fd = |m: &Mug, p: &Vector3<f64>, h: f64| {
            Vector3::from_fn(|k, _| {
                let mut e = Vector3::zeros();
                e[k] = h;
                (m.distance(&(p + e)) - m.distance(&(p - e))) / (2.0 * h)
            })
        };
        let (mut smooth, mut creased) = (0, 0);
        for_random_mug_points(5, |m, mut p, rng| {
            if rng.random_bool(0.5) {
                // Onto the surface, where the fit's points lie.
                for _ in 0..4 {
                    p -= fd(m, &p, 1e-6) * m.distance(&p);
                }
            }
            let (a, b) = (fd(m, &p, 1e-5), fd(m, &p, 1e-6));
            if (a - b).norm() > 1e-7 {
                creased += 1;
                return;
            }
            smooth += 1;
            let g = m.gradient(&p);
            assert!((g - b).norm() < 1e-6, "{m:?} at {p:?}: {g:?} vs {b:?}");
            assert!(
                (g.norm() - 1.0).abs() < 1e-9,
                "{m:?} at {p:?}: |g| = {}",
                g.norm()
            );
        });
        // Most points count (the rest lie within a step of a rim, wall end or the handle's
        // clip, where half the points projected onto the surface gather).
        assert!(
            smooth > 15_000 && creased < smooth / 3,
            "{smooth} smooth, {creased} creased"
        );
    }
}
