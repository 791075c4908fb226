//! Out-of-family shapes (issue 21): bowls, mugs and cars written apart from
//! [`crate::families`], with other profile curves and other parts, so that stage 1 can be
//! measured on objects its priors never saw. Nothing here trains a prior.
//!
//! | | the families (training data) | here |
//! |---|---|---|
//! | bowl | revolved power-law profile `y = d sᵉ` with a rim flare, constant wall, foot ring | flat bottom and a cubic Bézier wall, the wall thicker at the base than at the rim, a rolled rim bead, round or polygonal (4–8 rounded sides) in plan |
//! | mug | straight or conically tapered cup, round tube handle on a half ellipse | barrel (bulging) or flared-lip cup, a flat strap handle on a rounded-rectangle loop or a ring (teacup) |
//! | car | polygonal side profile (sedan … SUV) extruded with flat sides | coupé, van or pickup profile smoothed by corner cutting (Chaikin), doors that bulge, sides that lean in above the belt line (tumblehome) |
//!
//! Same frame and raw units as the families (+Y up, +X front or handle; bowl rim radius 1, mug
//! base radius 1, car length 2 on the ground y = 0) and the same normalisation (bounding-box
//! centre to the origin, half-diagonal to [`NORMALISED_RADIUS`]). The distances are exact or
//! divided by a bound of their gradient (a field a sphere tracer may trust: test
//! `unseen_fields_are_one_lipschitz`).

use crate::SdfError;
use crate::families::{
    Category, NORMALISED_RADIUS, Wheel, mesh_in_bounds, polygon_distance, polyline_distance,
    sd_box2, smin, uniform,
};
use irmirror_geom::TriMesh;
use irmirror_render::sdf::Sdf;
use nalgebra::{Vector2, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// An out-of-family bowl (raw units: rim radius 1 on the wall's mid-surface).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnseenBowl {
    /// Sides in plan: 0 round, else 4 … 8.
    pub sides: u32,
    /// How polygonal the sides are: 0 round … 1 straight sides (0.5 … 0.9).
    pub corner: f64,
    /// Rim height above the bottom's mid-surface, 0.3 … 0.75.
    pub rim_height: f64,
    /// Radius of the flat bottom, 0.15 … 0.55.
    pub bottom: f64,
    /// Fullness of the Bézier wall: 0 (nearly conical) … 1 (round shoulder).
    pub fullness: f64,
    /// Wall thickness at the rim, 0.04 … 0.08.
    pub rim_wall: f64,
    /// Wall thickness at the bottom, 0.08 … 0.16 (easing to the rim's with height).
    pub base_wall: f64,
    /// Radius of the rolled bead on the rim, 0 (none) or 0.04 … 0.07.
    pub bead: f64,
}

/// The handle of an out-of-family mug.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HandleKind {
    /// A loop along a rounded rectangle, from `strap_top` down to `strap_bottom`.
    Loop,
    /// A ring below `strap_top` (a teacup's).
    Ring,
}

/// An out-of-family mug (raw units: base radius 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnseenMug {
    /// Height, 1.5 … 2.6.
    pub cup_height: f64,
    /// Barrel: the radius grows by this at mid-height, −0.08 … 0.2.
    pub bulge: f64,
    /// Lip: the radius grows by this at the rim over the top quarter, 0 … 0.12.
    pub lip: f64,
    /// Wall thickness, 0.05 … 0.1.
    pub side_wall: f64,
    /// Bottom thickness, 0.1 … 0.2.
    pub bottom_wall: f64,
    /// Handle shape.
    pub handle: HandleKind,
    /// Top of the handle over the height, 0.7 … 0.88.
    pub strap_top: f64,
    /// Bottom of a loop handle over the height, 0.2 … 0.4.
    pub strap_bottom: f64,
    /// Reach beyond the wall, 0.35 … 0.65.
    pub strap_reach: f64,
    /// Half width of the strap (along Z), 0.1 … 0.16.
    pub strap_width: f64,
    /// Half thickness of the strap (in the XY plane), 0.035 … 0.06.
    pub strap_thickness: f64,
}

/// The body style of an out-of-family car.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CarKind {
    /// Low roof, long hood, fastback.
    Coupe,
    /// Tall roof, short hood, vertical tail.
    Van,
    /// Cab, then a covered bed at the belt line.
    Pickup,
}

/// An out-of-family car (raw units: length 2 along X, +X front, ground at y = 0).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnseenCar {
    /// Body style.
    pub style: CarKind,
    /// Roof height: coupé 0.5 … 0.58, pickup 0.62 … 0.78, van 0.8 … 0.95.
    pub roof_height: f64,
    /// Belt line, 0.27 … 0.4 (below the roof by 0.15 at least).
    pub belt_line: f64,
    /// Underbody height, 0.07 … 0.16.
    pub underbody: f64,
    /// Windshield base x: coupé 0.1 … 0.3, pickup 0.3 … 0.45, van 0.6 … 0.75.
    pub cowl: f64,
    /// Windshield run, 0.15 … 0.45 (at most `cowl − roof_end − 0.2`, at least 0.1).
    pub screen_run: f64,
    /// Roof's rear end x: coupé −0.45 … −0.2, pickup −0.25 … −0.05 (cab), van −0.95 … −0.88.
    pub roof_end: f64,
    /// Half width at the doors, 0.36 … 0.46.
    pub half_width: f64,
    /// The doors' bulge: half width × (1 − bulge x²), 0 … 0.08.
    pub door_bulge: f64,
    /// Inward lean of the sides above the belt line (run over rise), 0.05 … 0.3.
    pub tumblehome: f64,
    /// Wheel radius, 0.15 … 0.21.
    pub wheel_radius: f64,
    /// Axle x, ±(0.55 … 0.72).
    pub axle: f64,
}

/// One out-of-family shape.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "category", rename_all = "kebab-case", deny_unknown_fields)]
pub enum UnseenShape {
    /// A bowl.
    Bowl(UnseenBowl),
    /// A mug.
    Mug(UnseenMug),
    /// A car.
    Car(UnseenCar),
}

/// Chaikin's corner cutting of a closed polygon, `rounds` times: a quadratic B-spline's
/// control polygon refined, inside the original's convex hull.
fn chaikin(mut v: Vec<Vector2<f64>>, rounds: usize) -> Vec<Vector2<f64>> {
    for _ in 0..rounds {
        let n = v.len();
        v = (0..n)
            .flat_map(|i| {
                let (a, b) = (v[i], v[(i + 1) % n]);
                [a * 0.75 + b * 0.25, a * 0.25 + b * 0.75]
            })
            .collect();
    }
    v
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl UnseenBowl {
    /// The wall's mid-surface in (ρ, y): the flat bottom, then the Bézier wall to the rim.
    fn profile(&self) -> Vec<Vector2<f64>> {
        let (b, h) = (self.bottom, self.rim_height);
        let k = 0.15 + 0.6 * self.fullness;
        let c = [
            Vector2::new(b, 0.0),
            Vector2::new(b + k * (1.0 - b), 0.0),
            Vector2::new(1.0, h * (1.0 - k)),
            Vector2::new(1.0, h),
        ];
        let mut pts = vec![Vector2::new(0.0, 0.0)];
        pts.extend((0..=40).map(|i| {
            let t = i as f64 / 40.0;
            let u = 1.0 - t;
            c[0] * u * u * u + c[1] * 3.0 * u * u * t + c[2] * 3.0 * u * t * t + c[3] * t * t * t
        }));
        pts
    }

    /// Bound of |∇ρ_eff| (radially at most `m_max` = ρ_eff / ρ on a side's middle, around
    /// the axis `corner · tan(π / sides)`).
    fn plan_slope(&self) -> f64 {
        if self.sides == 0 {
            return 1.0;
        }
        let half = PI / f64::from(self.sides);
        let m_max = 1.0 - self.corner + self.corner / half.cos();
        (m_max * m_max + (self.corner * half.tan()).powi(2)).sqrt()
    }

    /// Radial coordinate in which the plan is round: the polygon's corners on the unit circle,
    /// its sides pulled in towards their inscribed circle by `corner`.
    fn rho_eff(&self, x: f64, z: f64) -> f64 {
        let rho = x.hypot(z);
        if self.sides == 0 {
            return rho;
        }
        let sector = 2.0 * PI / f64::from(self.sides);
        let local = z.atan2(x).rem_euclid(sector) - sector / 2.0;
        rho * (1.0 - self.corner + self.corner * local.cos() / (sector / 2.0).cos())
    }
}

impl UnseenMug {
    fn radius(&self, y: f64) -> f64 {
        let s = (y / self.cup_height).clamp(0.0, 1.0);
        1.0 + self.bulge * (PI * s).sin() + self.lip * ((s - 0.75).max(0.0) / 0.25).powi(2)
    }

    /// Bound of |dr/dy|.
    fn radius_slope(&self) -> f64 {
        (self.bulge.abs() * PI + self.lip * 8.0) / self.cup_height
    }

    /// The cup's cross-section in (ρ, y), mirrored about the axis (exact near it).
    fn section(&self) -> Vec<Vector2<f64>> {
        let (h, w, b) = (self.cup_height, self.side_wall, self.bottom_wall);
        let n = 24;
        let outer: Vec<Vector2<f64>> = (0..=n)
            .map(|i| {
                let y = h * i as f64 / n as f64;
                Vector2::new(self.radius(y), y)
            })
            .collect();
        let inner: Vec<Vector2<f64>> = (0..=n)
            .rev()
            .map(|i| {
                let y = b + (h - b) * i as f64 / n as f64;
                Vector2::new(self.radius(y) - w, y)
            })
            .collect();
        let right: Vec<Vector2<f64>> = outer.into_iter().chain(inner).collect();
        let mirror = |q: &Vector2<f64>| Vector2::new(-q.x, q.y);
        let mut poly: Vec<Vector2<f64>> = right.clone();
        poly.extend(right.iter().rev().map(mirror));
        poly
    }

    /// The handle's centre line in the XY plane (computed once per shape: distance queries
    /// only measure to it).
    fn handle_line(&self) -> HandleLine {
        let h = self.cup_height;
        let top = self.strap_top * h;
        match self.handle {
            HandleKind::Loop => {
                let bottom = self.strap_bottom * h;
                // The loop's inner side lies in the wall wherever the cup narrows.
                let x0 = (0..=16)
                    .map(|i| self.radius(bottom + (top - bottom) * f64::from(i) / 16.0))
                    .fold(f64::INFINITY, f64::min)
                    - self.side_wall
                    - self.strap_thickness;
                let x1 = self.radius(bottom).max(self.radius(top)) + self.strap_reach;
                let half = Vector2::new((x1 - x0) / 2.0, (top - bottom) / 2.0);
                HandleLine::Loop {
                    centre: Vector2::new((x0 + x1) / 2.0, (top + bottom) / 2.0),
                    half,
                    corner: 0.45 * half.x.min(half.y),
                }
            }
            HandleKind::Ring => {
                let r = 0.5 * self.strap_reach + 0.15;
                HandleLine::Ring {
                    centre: Vector2::new(
                        self.radius(top - r) + 0.5 * self.strap_reach - 0.1,
                        top - r,
                    ),
                    radius: r,
                }
            }
        }
    }
}

/// A mug handle's centre line in the XY plane.
#[derive(Clone, Copy, Debug)]
enum HandleLine {
    /// A rounded rectangle.
    Loop {
        centre: Vector2<f64>,
        half: Vector2<f64>,
        corner: f64,
    },
    /// A circle.
    Ring { centre: Vector2<f64>, radius: f64 },
}

impl HandleLine {
    /// Unsigned distance to the line.
    fn distance(&self, p: Vector2<f64>) -> f64 {
        match *self {
            HandleLine::Loop {
                centre,
                half,
                corner,
            } => (sd_box2(p, centre, half - Vector2::repeat(corner)) - corner).abs(),
            HandleLine::Ring { centre, radius } => ((p - centre).norm() - radius).abs(),
        }
    }

    /// Largest x of the line.
    fn reach_x(&self) -> f64 {
        match *self {
            HandleLine::Loop { centre, half, .. } => centre.x + half.x,
            HandleLine::Ring { centre, radius } => centre.x + radius,
        }
    }
}

impl UnseenCar {
    /// The side profile (x, y), a closed polygon smoothed by corner cutting.
    fn profile(&self) -> Vec<Vector2<f64>> {
        let (c, b, r) = (self.underbody, self.belt_line, self.roof_height);
        let (cowl, run, end) = (self.cowl, self.screen_run, self.roof_end);
        let mut v = vec![
            Vector2::new(-0.97, c),
            Vector2::new(0.97, c),
            Vector2::new(1.0, c + 0.6 * (b - c)),
            Vector2::new(0.93, b),
            Vector2::new(cowl, b + 0.04),
            Vector2::new(cowl - run, r),
        ];
        match self.style {
            CarKind::Coupe => {
                // Fastback: the roof slopes down to a short deck.
                v.extend([Vector2::new(end, r), Vector2::new(-0.85, b + 0.08)]);
            }
            CarKind::Van => {
                v.extend([Vector2::new(end, r), Vector2::new(-1.0, r - 0.05)]);
            }
            CarKind::Pickup => {
                // The cab's back wall, then the covered bed at the belt line.
                v.extend([
                    Vector2::new(end, r),
                    Vector2::new(end - 0.04, b + 0.06),
                    Vector2::new(-0.98, b + 0.06),
                ]);
            }
        }
        v.push(Vector2::new(-1.0, c + 0.5 * (b - c)));
        chaikin(v, 3)
    }

    fn half_width_at(&self, x: f64, y: f64) -> f64 {
        self.half_width * (1.0 - self.door_bulge * x * x)
            - self.tumblehome * (y - self.belt_line).max(0.0)
    }

    /// Bound of the gradient of `|z| − half_width_at(x, y)`.
    fn side_slope(&self) -> f64 {
        (1.0 + (2.0 * self.half_width * self.door_bulge).powi(2) + self.tumblehome.powi(2)).sqrt()
    }
}

impl UnseenShape {
    /// The category.
    pub fn category(&self) -> Category {
        match self {
            UnseenShape::Bowl(_) => Category::Bowl,
            UnseenShape::Mug(_) => Category::Mug,
            UnseenShape::Car(_) => Category::Car,
        }
    }

    /// A shape drawn uniformly from the documented ranges (bowls, mugs and cars only).
    pub fn sample(category: Category, rng: &mut impl Rng) -> Result<Self, SdfError> {
        Ok(match category {
            Category::Bowl => UnseenShape::Bowl(UnseenBowl {
                sides: if rng.random_bool(0.5) {
                    0
                } else {
                    rng.random_range(4..=8)
                },
                corner: uniform(rng, 0.5, 0.9),
                rim_height: uniform(rng, 0.3, 0.75),
                bottom: uniform(rng, 0.15, 0.55),
                fullness: uniform(rng, 0.0, 1.0),
                rim_wall: uniform(rng, 0.04, 0.08),
                base_wall: uniform(rng, 0.08, 0.16),
                bead: if rng.random_bool(0.5) {
                    uniform(rng, 0.04, 0.07)
                } else {
                    0.0
                },
            }),
            Category::Mug => UnseenShape::Mug(UnseenMug {
                cup_height: uniform(rng, 1.5, 2.6),
                bulge: uniform(rng, -0.08, 0.2),
                lip: uniform(rng, 0.0, 0.12),
                side_wall: uniform(rng, 0.05, 0.1),
                bottom_wall: uniform(rng, 0.1, 0.2),
                handle: if rng.random_bool(0.6) {
                    HandleKind::Loop
                } else {
                    HandleKind::Ring
                },
                strap_top: uniform(rng, 0.7, 0.88),
                strap_bottom: uniform(rng, 0.2, 0.4),
                strap_reach: uniform(rng, 0.35, 0.65),
                strap_width: uniform(rng, 0.1, 0.16),
                strap_thickness: uniform(rng, 0.035, 0.06),
            }),
            Category::Car => {
                let style = [CarKind::Coupe, CarKind::Van, CarKind::Pickup][rng.random_range(0..3)];
                let (roof, cowl, end) = match style {
                    CarKind::Coupe => ((0.5, 0.58), (0.1, 0.3), (-0.45, -0.2)),
                    CarKind::Pickup => ((0.62, 0.78), (0.3, 0.45), (-0.25, -0.05)),
                    CarKind::Van => ((0.8, 0.95), (0.6, 0.75), (-0.95, -0.88)),
                };
                let roof_height = uniform(rng, roof.0, roof.1);
                let (cowl, roof_end) = (uniform(rng, cowl.0, cowl.1), uniform(rng, end.0, end.1));
                UnseenShape::Car(UnseenCar {
                    style,
                    roof_height,
                    belt_line: uniform(rng, 0.27, 0.4).min(roof_height - 0.15),
                    underbody: uniform(rng, 0.07, 0.16),
                    cowl,
                    // The roof keeps at least 0.1 of length.
                    screen_run: uniform(rng, 0.15, 0.45).min(cowl - roof_end - 0.2).max(0.1),
                    roof_end,
                    half_width: uniform(rng, 0.36, 0.46),
                    door_bulge: uniform(rng, 0.0, 0.08),
                    tumblehome: uniform(rng, 0.05, 0.3),
                    wheel_radius: uniform(rng, 0.15, 0.21),
                    axle: uniform(rng, 0.55, 0.72),
                })
            }
            Category::Sphere => return Err(SdfError::NoPrior(category)),
        })
    }

    /// Every parameter finite and within its documented range (a scene file may hold any
    /// numbers; outside the ranges the fields' slope bounds and bounds no longer hold).
    pub fn check(&self) -> Result<(), SdfError> {
        let ranges: Vec<(&str, f64, f64, f64)> = match self {
            UnseenShape::Bowl(b) => vec![
                ("corner", b.corner, 0.0, 1.0),
                ("rim_height", b.rim_height, 0.3, 0.75),
                ("bottom", b.bottom, 0.15, 0.55),
                ("fullness", b.fullness, 0.0, 1.0),
                ("rim_wall", b.rim_wall, 0.04, 0.08),
                ("base_wall", b.base_wall, 0.08, 0.16),
                ("bead", b.bead, 0.0, 0.07),
            ],
            UnseenShape::Mug(m) => vec![
                ("cup_height", m.cup_height, 1.5, 2.6),
                ("bulge", m.bulge, -0.08, 0.2),
                ("lip", m.lip, 0.0, 0.12),
                ("side_wall", m.side_wall, 0.05, 0.1),
                ("bottom_wall", m.bottom_wall, 0.1, 0.2),
                ("strap_top", m.strap_top, 0.7, 0.88),
                ("strap_bottom", m.strap_bottom, 0.2, 0.4),
                ("strap_reach", m.strap_reach, 0.35, 0.65),
                ("strap_width", m.strap_width, 0.1, 0.16),
                ("strap_thickness", m.strap_thickness, 0.035, 0.06),
            ],
            UnseenShape::Car(c) => vec![
                ("roof_height", c.roof_height, 0.5, 0.95),
                ("belt_line", c.belt_line, 0.27, c.roof_height - 0.15),
                ("underbody", c.underbody, 0.07, 0.16),
                ("cowl", c.cowl, 0.1, 0.75),
                ("screen_run", c.screen_run, 0.1, 0.45),
                ("roof_end", c.roof_end, -0.95, c.cowl - c.screen_run - 0.1),
                ("half_width", c.half_width, 0.36, 0.46),
                ("door_bulge", c.door_bulge, 0.0, 0.08),
                ("tumblehome", c.tumblehome, 0.05, 0.3),
                ("wheel_radius", c.wheel_radius, 0.15, 0.21),
                ("axle", c.axle, 0.55, 0.72),
            ],
        };
        for (name, v, lo, hi) in ranges {
            // (A little slack: a scene file's decimals.)
            if !(v >= lo - 1e-9 && v <= hi + 1e-9) {
                return Err(SdfError::Invalid(format!(
                    "{} {name} = {v} outside {lo:.3} … {hi:.3}",
                    self.category().name()
                )));
            }
        }
        if let UnseenShape::Bowl(b) = self
            && b.sides != 0
            && !(4..=8).contains(&b.sides)
        {
            return Err(SdfError::Invalid(format!(
                "bowl sides = {} (0 for round, else 4 … 8)",
                b.sides
            )));
        }
        Ok(())
    }

    /// Raw-unit box `(lo, hi)` around the surface; its bottom is the surface's lowest point
    /// (objects stand on it).
    pub fn raw_bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            UnseenShape::Bowl(b) => {
                let r = 1.0 + 0.5 * b.rim_wall.max(b.base_wall) + b.bead;
                (
                    Vector3::new(-r, -0.5 * b.base_wall, -r),
                    Vector3::new(r, b.rim_height + 0.5 * b.rim_wall + b.bead, r),
                )
            }
            UnseenShape::Mug(m) => {
                let r = (0..=32)
                    .map(|i| m.radius(m.cup_height * f64::from(i) / 32.0))
                    .fold(1.0, f64::max)
                    + 0.01;
                let x = m.handle_line().reach_x() + m.strap_thickness + 0.02;
                (
                    Vector3::new(-r, 0.0, -r),
                    Vector3::new(x.max(r), m.cup_height + 0.01, r),
                )
            }
            UnseenShape::Car(c) => (
                Vector3::new(-1.0, 0.0, -c.half_width),
                Vector3::new(1.0, c.roof_height, c.half_width),
            ),
        }
    }

    /// The widest horizontal radius of the body (a car: half its length), raw units: what the
    /// simulator matches to the size of the object it replaces.
    pub fn raw_half_size(&self) -> f64 {
        match self {
            UnseenShape::Bowl(b) => 1.0 + 0.5 * b.rim_wall + b.bead,
            UnseenShape::Mug(_) => self.raw_bounds().1.z,
            UnseenShape::Car(_) => 1.0,
        }
    }

    /// `(centre, k)`: raw point = centre + k · normalised point.
    pub fn normalisation(&self) -> (Vector3<f64>, f64) {
        let (lo, hi) = self.raw_bounds();
        ((lo + hi) / 2.0, (hi - lo).norm() / 2.0 / NORMALISED_RADIUS)
    }

    /// The shape with its curves computed once (what distance queries use).
    pub fn prepare(&self) -> PreparedUnseen {
        let (centre, k) = self.normalisation();
        let curve = match self {
            UnseenShape::Bowl(b) => b.profile(),
            UnseenShape::Mug(m) => m.section(),
            UnseenShape::Car(c) => c.profile(),
        };
        let handle = match self {
            UnseenShape::Mug(m) => Some(m.handle_line()),
            UnseenShape::Bowl(_) | UnseenShape::Car(_) => None,
        };
        PreparedUnseen {
            shape: *self,
            centre,
            k,
            curve,
            handle,
        }
    }

    /// The surface as a watertight, outward mesh in the normalised frame (marching
    /// tetrahedra, `resolution` cells on the longest side).
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

/// An out-of-family shape ready for many distance queries.
#[derive(Clone, Debug)]
pub struct PreparedUnseen {
    shape: UnseenShape,
    centre: Vector3<f64>,
    k: f64,
    /// Bowl: the mid-surface profile; mug: the cup's section; car: the side profile.
    curve: Vec<Vector2<f64>>,
    /// Mug: the handle's centre line.
    handle: Option<HandleLine>,
}

impl PreparedUnseen {
    /// Signed distance in raw units (a lower bound where not exact).
    pub fn raw_distance(&self, p: &Vector3<f64>) -> f64 {
        match &self.shape {
            UnseenShape::Bowl(b) => {
                let lip = b.plan_slope();
                let q = Vector2::new(b.rho_eff(p.x, p.z), p.y);
                // Thickness: the base's at the bottom, easing to the rim's with height.
                let t = b.base_wall + (b.rim_wall - b.base_wall) * smoothstep(p.y / b.rim_height);
                let mut shell = polyline_distance(q, &self.curve) - 0.5 * t;
                if b.bead > 0.0 {
                    let bead = (q - Vector2::new(1.0, b.rim_height)).norm() - b.bead;
                    shell = smin(shell, bead, 0.03);
                }
                // ρ_eff stretches distances by up to `lip`, the thickness' slope adds ½ Δt ×
                // smoothstep's 1.5 over the rim height.
                let slope = 0.75 * (b.base_wall - b.rim_wall).abs() / b.rim_height;
                shell / (lip + slope)
            }
            UnseenShape::Mug(m) => {
                let rho = p.x.hypot(p.z);
                let cup = polygon_distance(Vector2::new(rho, p.y), &self.curve) - 0.005;
                let line = self
                    .handle
                    .expect("a prepared mug has its handle")
                    .distance(Vector2::new(p.x, p.y));
                let strap = sd_box2(
                    Vector2::new(line, p.z.abs()),
                    Vector2::zeros(),
                    Vector2::new(m.strap_thickness - 0.01, m.strap_width - 0.01),
                ) - 0.01;
                // Only outside the wall's mid-surface (the loop's inner side lies in the cup).
                let clip = (m.radius(p.y) - 0.5 * m.side_wall - p.x)
                    / (1.0 + m.radius_slope().powi(2)).sqrt();
                smin(cup, strap.max(clip), 0.04)
            }
            UnseenShape::Car(c) => {
                let d2 = polygon_distance(Vector2::new(p.x, p.y), &self.curve);
                let side = (p.z.abs() - c.half_width_at(p.x, p.y)) / c.side_slope();
                let r_edge = 0.06;
                let w = Vector2::new(d2 + r_edge, side + r_edge);
                // Rounding two fields whose gradients are not orthogonal (the lean and bulge
                // tilt the side's) steepens the result by up to √(1 + cos of their angle).
                let cos = (c.side_slope().powi(2) - 1.0).sqrt() / c.side_slope();
                let mut body = (w.x.max(w.y).min(0.0)
                    + Vector2::new(w.x.max(0.0), w.y.max(0.0)).norm()
                    - r_edge)
                    / (1.0 + cos).sqrt();
                for xw in [c.axle, -c.axle] {
                    let hw = c.half_width_at(xw, c.wheel_radius);
                    let wheel = Wheel {
                        hub: Vector2::new(xw, c.wheel_radius),
                        radius: c.wheel_radius,
                        arch_margin: 0.035,
                        arch_z: hw - 0.15,
                        hub_z: hw - 0.09,
                        half_thickness: 0.065,
                        rounding: 0.025,
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

impl Sdf for PreparedUnseen {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        PreparedUnseen::distance(self, p)
    }
    fn bounding_radius(&self) -> f64 {
        NORMALISED_RADIUS + 0.05
    }
}
