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
}
