//! The support plane (table top, ground) under the objects: RANSAC over depth points, refined by
//! least squares on the inliers. Its normal is the objects' "up" in stage 1 and the person's in
//! stage 2.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// A plane `normal · p = offset` in the depth frame; `normal` is a unit vector pointing to the
/// camera's side (up, for a camera above the plane).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    /// Unit normal, depth frame.
    pub normal: [f64; 3],
    /// `normal · p` for points on the plane, metres.
    pub offset_m: f64,
    /// Fraction of the candidate points within the inlier band.
    pub inlier_fraction: f64,
}

/// What stage 1 knows of the ground: "up" always (the support plane's normal, else the IMU's up,
/// else the camera's −Y), and the support plane where the depth image shows one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Ground {
    /// Unit vector against gravity, depth frame.
    pub up: [f64; 3],
    /// The support plane (table top, ground), if one was found.
    pub plane: Option<Plane>,
}

impl Ground {
    /// A found support plane: up is its normal.
    pub fn plane(plane: Plane) -> Self {
        Self {
            up: plane.normal,
            plane: Some(plane),
        }
    }

    /// No support plane, up known (IMU): the direction only, no height.
    pub fn up_only(up: Vector3<f64>) -> Self {
        Self {
            up: up.normalize().into(),
            plane: None,
        }
    }

    /// No support plane and no IMU: up = the camera's −Y.
    pub fn camera_up() -> Self {
        Self::up_only(-Vector3::y())
    }

    /// Up as a vector.
    pub fn n(&self) -> Vector3<f64> {
        Vector3::from(self.up)
    }
}

impl Plane {
    /// The normal as a vector.
    pub fn n(&self) -> Vector3<f64> {
        Vector3::from(self.normal)
    }
    /// Signed height of `p` above the plane, metres.
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.n().dot(p) - self.offset_m
    }
}

/// Reach of the support plane as an occluder of reflected rays, metres (tables are finite; the
/// floor under a car is not, but nobody stands under it).
pub const PLANE_BLOCK_M: f64 = 0.6;

/// The support plane as an occluder of the objects' reflected rays, known where the depth camera
/// sees it. A table is finite and its edge is often out of the cameras' view: on the paper-like
/// tabletop the cameras stand near the table's edge, and a mug's side sends rays back over that
/// edge, below the depth camera's view, to a person's hands and hips (EXPERIMENTS.md, "Eleventh
/// run": every mask pixel of tuning mug 21000 was dropped so, "nobody there").
#[derive(Clone, Copy)]
pub struct PlaneOccluder<'a> {
    /// The plane (depth frame).
    pub plane: &'a Plane,
    /// Where it is seen: the depth image (metres, 0 or NaN for none), its camera (depth frame),
    /// and the thermal reflection mask; `None`: the plane blocks wherever a ray meets it within
    /// [`PLANE_BLOCK_M`].
    pub seen: Option<SeenPlane<'a>>,
}

/// What tells where a plane is (see [`PlaneOccluder`]).
#[derive(Clone, Copy)]
pub struct SeenPlane<'a> {
    /// Depth image, metres along the optical axis.
    pub depth_m: &'a irmirror_capture::Image<f32>,
    /// Its camera (depth frame).
    pub camera: &'a irmirror_geom::PinholeCamera,
    /// The thermal reflection mask (row-major, one per thermal pixel).
    pub mask: &'a irmirror_capture::Image<bool>,
}

impl PlaneOccluder<'_> {
    /// Whether the plane blocks the ray from `origin` along unit `dir` of thermal pixel `pixel`
    /// before it leaves the plane's reach: where the ray meets the plane within
    /// [`PLANE_BLOCK_M`], the plane blocks it unless the depth camera sees past that point (the
    /// table ends there), or — the point out of its view or hidden — the pixel shows the
    /// reflection (its warmth says the ray passed; a cold pixel's ray may be blocked, so it is
    /// left out, as before). Not "out of view = no table": the table runs on under the cameras
    /// out of view, and letting every such ray pass raised the truth's data term on 24 tuning
    /// mugs from 0.074 to 0.445 (median; EXPERIMENTS.md, "Thirty-second run").
    pub fn blocks(&self, origin: &Vector3<f64>, dir: &Vector3<f64>, pixel: u32) -> bool {
        let n = self.plane.n();
        let denom = n.dot(dir);
        if denom >= -1e-9 {
            return false;
        }
        let t = (self.plane.offset_m - n.dot(origin)) / denom;
        if t <= 0.0 || t >= PLANE_BLOCK_M {
            return false;
        }
        let Some(seen) = self.seen else {
            return true;
        };
        let x = origin + dir * t;
        let seen_depth = seen.camera.project_to_pixel(&x).and_then(|(u, v)| {
            let d = f64::from(seen.depth_m.data[(v * seen.camera.width + u) as usize]);
            (d.is_finite() && d > 0.0).then_some(d)
        });
        match seen_depth {
            // Seen past the plane by more than the depth's noise and the plane's fit: no table.
            Some(d) if d > x.z + SEEN_PAST_M + SEEN_PAST_REL * x.z => false,
            Some(d) if d >= x.z - SEEN_PAST_M - SEEN_PAST_REL * x.z => true,
            // Out of view, no depth, or hidden behind something nearer.
            _ => !seen.mask.data[pixel as usize],
        }
    }
}

/// How far past a plane point the depth must see for the plane not to be there: a margin
/// above the depth noise (σ = 1.5 mm × (z / 1 m)² on the simulated sensors) and the plane fit's
/// inlier band.
const SEEN_PAST_M: f64 = 0.02;
/// See [`SEEN_PAST_M`]: its range-proportional part.
const SEEN_PAST_REL: f64 = 0.03;

/// RANSAC settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlaneConfig {
    /// Hypotheses drawn.
    pub iterations: u32,
    /// Inlier band: `tolerance_m + tolerance_rel · depth`, metres (depth noise grows with range).
    pub tolerance_m: f64,
    /// Range-proportional part of the band.
    pub tolerance_rel: f64,
    /// Planes whose normal makes more than this angle with the camera's −Y are rejected, so a
    /// wall or a car's flank is not taken for the floor (degrees; wide, since the camera's
    /// pitch is unknown).
    pub max_tilt_deg: f64,
    /// The same gate about the capture's IMU "up", when it has one (degrees; tight, since up
    /// is then known).
    pub max_tilt_imu_deg: f64,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        Self {
            iterations: 300,
            tolerance_m: 0.006,
            tolerance_rel: 0.004,
            max_tilt_deg: 75.0,
            max_tilt_imu_deg: 20.0,
        }
    }
}

/// Fits the dominant near-horizontal plane to `points` (depth frame): its normal within
/// `max_tilt_imu_deg` of `imu_up` when given, else within `max_tilt_deg` of the camera's −Y.
/// `None` if there are fewer than 3 points or no hypothesis passes the tilt test.
pub fn fit_plane(
    points: &[Vector3<f64>],
    imu_up: Option<&Vector3<f64>>,
    cfg: &PlaneConfig,
    rng: &mut impl Rng,
) -> Option<Plane> {
    if points.len() < 3 {
        return None;
    }
    let (up, max_tilt) = match imu_up {
        Some(u) => (u.normalize(), cfg.max_tilt_imu_deg),
        None => (-Vector3::y(), cfg.max_tilt_deg),
    };
    let min_up = max_tilt.to_radians().cos();
    let band = |p: &Vector3<f64>| cfg.tolerance_m + cfg.tolerance_rel * p.z.abs();
    let orient = |n: Vector3<f64>, c: f64| if c > 0.0 { (-n, -c) } else { (n, c) };
    let mut best: Option<(usize, Vector3<f64>, f64)> = None;
    for _ in 0..cfg.iterations {
        let (a, b, c) = (
            points[rng.random_range(0..points.len())],
            points[rng.random_range(0..points.len())],
            points[rng.random_range(0..points.len())],
        );
        let Some(n) = (b - a).cross(&(c - a)).try_normalize(1e-12) else {
            continue;
        };
        // Orient towards the camera (origin): n · (0 − a) > 0 ⇔ offset n·a < 0.
        let (n, off) = orient(n, n.dot(&a));
        if n.dot(&up) < min_up {
            continue;
        }
        let count = points
            .iter()
            .filter(|p| (n.dot(p) - off).abs() < band(p))
            .count();
        if best.as_ref().is_none_or(|b| count > b.0) {
            best = Some((count, n, off));
        }
    }
    let (_, n, off) = best?;
    // Least-squares refinement on the inliers (smallest-eigenvalue direction of the scatter).
    let inliers: Vec<&Vector3<f64>> = points
        .iter()
        .filter(|p| (n.dot(p) - off).abs() < band(p))
        .collect();
    let centroid = inliers.iter().fold(Vector3::zeros(), |s, p| s + *p) / inliers.len() as f64;
    let mut scatter = Matrix3::zeros();
    for p in &inliers {
        let d = *p - centroid;
        scatter += d * d.transpose();
    }
    let eig = SymmetricEigen::new(scatter);
    let k = eig.eigenvalues.imin();
    let mut m = eig.eigenvectors.column(k).into_owned();
    if m.dot(&n) < 0.0 {
        m = -m;
    }
    let (m, off) = orient(m, m.dot(&centroid));
    let inliers = points
        .iter()
        .filter(|p| (m.dot(p) - off).abs() < band(p))
        .count();
    Some(Plane {
        normal: m.into(),
        offset_m: off,
        inlier_fraction: inliers as f64 / points.len() as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_tilted_plane_among_outliers() {
        let mut rng = irmirror_geom::rng::seeded(1, 0);
        // Plane through (0, 0.3, 1) with normal towards the camera and up (−Y).
        let n = Vector3::new(0.1, -0.8, -0.5).normalize();
        let p0 = Vector3::new(0.0, 0.3, 1.0);
        let (u, v) = (
            n.cross(&Vector3::x()).normalize(),
            n.cross(&n.cross(&Vector3::x())).normalize(),
        );
        let mut pts: Vec<Vector3<f64>> = (0..600)
            .map(|_| {
                p0 + u * rng.random_range(-0.4..0.4)
                    + v * rng.random_range(-0.4..0.4)
                    + n * rng.random_range(-0.002..0.002)
            })
            .collect();
        pts.extend((0..300).map(|_| {
            Vector3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(0.5..1.5),
            )
        }));
        let plane = fit_plane(&pts, None, &PlaneConfig::default(), &mut rng).expect("plane");
        assert!(plane.n().dot(&n) > 0.999, "normal {:?}", plane.normal);
        assert!((plane.height(&p0)).abs() < 2e-3);
        assert!(
            plane.inlier_fraction > 0.6 && plane.inlier_fraction < 0.75,
            "{}",
            plane.inlier_fraction
        );
    }

    #[test]
    fn a_wall_is_not_a_floor() {
        let mut rng = irmirror_geom::rng::seeded(2, 0);
        // A fronto-parallel wall at z = 2 only.
        let pts: Vec<Vector3<f64>> = (0..200)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    2.0,
                )
            })
            .collect();
        assert!(fit_plane(&pts, None, &PlaneConfig::default(), &mut rng).is_none());
    }

    /// With the IMU's up, a wall 40° from horizontal (the camera looks down 50°) is not a
    /// floor, while the horizontal floor in the same view is found.
    #[test]
    fn the_imu_gate_is_tight() {
        let mut rng = irmirror_geom::rng::seeded(3, 0);
        let pitch = 50f64.to_radians();
        let up = Vector3::new(0.0, -pitch.cos(), -pitch.sin());
        let wall: Vec<Vector3<f64>> = (0..200)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    2.0,
                )
            })
            .collect();
        assert!(fit_plane(&wall, Some(&up), &PlaneConfig::default(), &mut rng).is_none());
        // The floor 1.2 m below the camera: points p with up · p = −1.2.
        let (a, b) = (Vector3::x(), up.cross(&Vector3::x()).normalize());
        let floor: Vec<Vector3<f64>> = (0..200)
            .map(|_| -up * 1.2 + a * rng.random_range(-1.0..1.0) + b * rng.random_range(-1.0..1.0))
            .collect();
        let plane =
            fit_plane(&floor, Some(&up), &PlaneConfig::default(), &mut rng).expect("the floor");
        assert!(
            plane.n().dot(&up) > 0.9999 && (plane.offset_m + 1.2).abs() < 1e-6,
            "{plane:?}"
        );
    }

    /// A table 0.2 m below the camera that ends 1 m ahead (a floor seen past it): a ray that
    /// meets it where the depth camera sees it is blocked, one that meets it past its seen end
    /// is not, one that meets it below the camera's view is kept only for a reflection pixel;
    /// without the depth image the plane blocks all three, and beyond its reach none.
    #[test]
    fn the_plane_blocks_where_it_is_seen() {
        use irmirror_capture::Image;
        let plane = Plane {
            normal: [0.0, -1.0, 0.0],
            offset_m: -0.2,
            inlier_fraction: 1.0,
        };
        let camera = irmirror_geom::PinholeCamera::from_fov(40, 40, 60f64.to_radians()).unwrap();
        let mut depth_m = Image::filled(40, 40, f32::NAN);
        for v in 0..40 {
            for u in 0..40 {
                let d = camera
                    .ray_at::<f64>(f64::from(u) + 0.5, f64::from(v) + 0.5)
                    .dir;
                if d.y > 0.0 {
                    let z = (d * (0.2 / d.y)).z;
                    depth_m.data[(v * 40 + u) as usize] = if z < 1.0 { z as f32 } else { 5.0 };
                }
            }
        }
        let mut mask = Image::filled(2, 1, false);
        mask.data[1] = true;
        let seen = PlaneOccluder {
            plane: &plane,
            seen: Some(SeenPlane {
                depth_m: &depth_m,
                camera: &camera,
                mask: &mask,
            }),
        };
        let blind = PlaneOccluder {
            plane: &plane,
            seen: None,
        };
        // Rays that meet the plane at `x` after `t` metres along `d`.
        let down_back = Vector3::new(0.0, 1.0, -1.0).normalize();
        let ray = |x: Vector3<f64>, t: f64| (x - down_back * t, down_back);
        let on_table = ray(Vector3::new(0.0, 0.2, 0.8), 0.3);
        let past_edge = ray(Vector3::new(0.0, 0.2, 1.2), 0.3);
        let below_view = ray(Vector3::new(0.0, 0.2, 0.2), 0.3);
        let beyond_reach = ray(Vector3::new(0.0, 0.2, 0.8), PLANE_BLOCK_M + 0.1);
        for pixel in [0, 1] {
            assert!(seen.blocks(&on_table.0, &on_table.1, pixel));
            assert!(!seen.blocks(&past_edge.0, &past_edge.1, pixel));
            assert_eq!(seen.blocks(&below_view.0, &below_view.1, pixel), pixel == 0);
            assert!(!seen.blocks(&beyond_reach.0, &beyond_reach.1, pixel));
            for r in [on_table, past_edge, below_view] {
                assert!(blind.blocks(&r.0, &r.1, pixel));
            }
            assert!(!blind.blocks(&beyond_reach.0, &beyond_reach.1, pixel));
        }
        // Upwards, away from the plane: never blocked.
        assert!(!blind.blocks(&on_table.0, &-down_back, 0));
    }
}
