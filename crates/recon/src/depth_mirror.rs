//! The mirror where the depth camera sees it: a large object's reflected rays re-reflected off
//! the surface fitted to the depth points around where each ray meets them.
//!
//! A shape prior draws a car's door to within a few centimetres (the learned car prior's held-out
//! Chamfer ×10³ is 0.2, ≈ 3 cm RMS on a 4.5 m car), and that turns its normals by degrees: the
//! fitted mirror sends the reflection's rays 7.5° (median) from the true ones, 0.7 m at the
//! person (family cars, `eval --shapes family`). The depth camera sees the same door at a few
//! millimetres a pixel. So each ray of a car is followed to where it meets the depth surface
//! (from the fit's hit, the ray's point at the depth of the pixel it projects to, until that
//! pixel stays: the two cameras are centimetres apart), a **quadric height field** over the
//! window's plane (`h = quadratic(a, b)` in the frame of the points' principal axes) is fitted to
//! the depth points in a ±[`DepthMirror::radius_rel`] × size window about that point, and the ray
//! is intersected with the quadric and reflected off its normal there. A plane (the first
//! version) is wrong wherever the surface bends within the window; a quadric in the surface's own
//! frame follows it to second order with no perspective in the way (on a sphere its height field
//! has no odd terms at all), while a quadric of the inverse depth in image coordinates —
//! symmetric windows, but perspective's third-order terms — was 0.3° off on a noise-free 2 m
//! sphere with a ±18 cm window (the height field: 0.002°).
//!
//! Where the data disagree with the fit the fit's ray stays: the depth surface more than
//! [`DepthMirror::gate_m`] from the fit's hit (another object, the ground), points off their
//! quadric by more than [`DepthMirror::max_rms_m`] RMS (a window across an edge), a normal more
//! than [`DepthMirror::max_turn_deg`] from the fit's, a window less than half full or whose
//! centroid lies more than half its size from the point (the image's border, holes).
//!
//! The windows' sums come from summed-area tables of the points' moments up to degree 4 (O(1) a
//! window, any size), taken about the points' mean so that they stay small; a window's moments in
//! its own frame follow by expanding the frame's coordinates as polynomials.

use irmirror_capture::Image;
use irmirror_geom::PinholeCamera;
use irmirror_render::reflect::{ReflectedRays, reflect};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Settings (`[mirror]` in the config TOML).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthMirror {
    /// Re-reflect large objects' rays off the depth data.
    pub enabled: bool,
    /// Objects at least this large (the fitted similarity's scale, m) are refined: cars, not
    /// tabletop objects, whose walls a window of a few pixels spans.
    pub min_scale_m: f64,
    /// The window's half-size, relative to the object's scale.
    pub radius_rel: f64,
    /// The depth at a hit's pixel must lie this close to the hit (m).
    pub gate_m: f64,
    /// The window's points must lie this close to their plane (RMS, m).
    pub max_rms_m: f64,
    /// The plane's normal must lie this close to the fit's (degrees).
    pub max_turn_deg: f64,
}

impl Default for DepthMirror {
    fn default() -> Self {
        Self {
            enabled: false,
            min_scale_m: 1.0,
            radius_rel: 0.04,
            gate_m: 0.1,
            max_rms_m: 0.02,
            max_turn_deg: 30.0,
        }
    }
}

impl DepthMirror {
    /// Refuses settings no refinement can run with (a `--config` TOML is user input): when
    /// enabled, a size, gate or RMS not a finite number > 0, a turn outside (0°, 90°].
    pub fn check(&self) -> Result<(), crate::ReconError> {
        if !self.enabled {
            return Ok(());
        }
        let positive = [
            ("min_scale_m", self.min_scale_m),
            ("radius_rel", self.radius_rel),
            ("gate_m", self.gate_m),
            ("max_rms_m", self.max_rms_m),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::ReconError::Config(format!(
                    "[mirror] {name} = {v}: must be a finite number > 0"
                )));
            }
        }
        if !(self.max_turn_deg > 0.0 && self.max_turn_deg <= 90.0) {
            return Err(crate::ReconError::Config(format!(
                "[mirror] max_turn_deg = {}: must lie in (0, 90]",
                self.max_turn_deg
            )));
        }
        Ok(())
    }
}

/// The hit must lie within the middle of its window's data: the window's centroid at most this
/// fraction of its half-size from the hit along the surface (a window cut by the image's border
/// or by holes extrapolates its quadric, whose slope is noisier there).
const OFF_CENTRE: f64 = 0.5;

/// Exponents `(i, j, k)` of the monomials `xⁱ yʲ zᵏ` of degree ≤ 4, by degree.
const EXPONENTS: [(u8, u8, u8); 35] = {
    let mut out = [(0, 0, 0); 35];
    let mut n = 0;
    let mut degree = 0;
    while degree <= 4 {
        let mut i = degree;
        loop {
            let mut j = degree - i;
            loop {
                out[n] = (i, j, degree - i - j);
                n += 1;
                if j == 0 {
                    break;
                }
                j -= 1;
            }
            if i == 0 {
                break;
            }
            i -= 1;
        }
        degree += 1;
    }
    out
};

/// The index in [`EXPONENTS`] of `xⁱ yʲ zᵏ`.
fn monomial(i: u8, j: u8, k: u8) -> usize {
    EXPONENTS
        .iter()
        .position(|&e| e == (i, j, k))
        .expect("degree ≤ 4")
}

/// The monomials of [`EXPONENTS`] at `q`: a point's contribution to the moments.
fn monomials(q: &Vector3<f64>) -> Poly {
    EXPONENTS.map(|(i, j, k)| q.x.powi(i.into()) * q.y.powi(j.into()) * q.z.powi(k.into()))
}

/// A polynomial of degree ≤ 4 in three variables, by [`EXPONENTS`].
type Poly = [f64; 35];

/// `p` times the linear form `l · (x, y, z)` (its terms of degree 4 dropped: callers stay ≤ 4).
fn times_linear(p: &Poly, l: &Vector3<f64>, table: &Table) -> Poly {
    let mut out = [0.0; 35];
    for (m, &c) in p.iter().enumerate() {
        if c != 0.0 {
            for (axis, next) in table.up[m].iter().enumerate() {
                if let Some(next) = next {
                    out[*next] += c * l[axis];
                }
            }
        }
    }
    out
}

/// For each monomial, the monomial times x, y or z (when of degree ≤ 4).
struct Table {
    up: [[Option<usize>; 3]; 35],
}

impl Table {
    fn new() -> Self {
        let up = std::array::from_fn(|m| {
            let (i, j, k) = EXPONENTS[m];
            let fits = i + j + k < 4;
            [
                fits.then(|| monomial(i + 1, j, k)),
                fits.then(|| monomial(i, j + 1, k)),
                fits.then(|| monomial(i, j, k + 1)),
            ]
        });
        Self { up }
    }
}

/// Summed-area tables of the depth points' moments up to degree 4, the points taken relative
/// to their mean (`origin`) so that the sums stay small.
struct Moments {
    width: usize,
    height: usize,
    origin: Vector3<f64>,
    /// `(width + 1) × (height + 1)` entries of 35 sums each.
    sums: Vec<Poly>,
}

impl Moments {
    fn new(depth: &Image<f32>, camera: &PinholeCamera) -> Self {
        let (w, h) = (depth.width as usize, depth.height as usize);
        let point = |x: usize, y: usize| {
            let z = f64::from(depth.data[y * w + x]);
            (z.is_finite() && z > 0.0).then(|| camera.unproject(x as f64 + 0.5, y as f64 + 0.5, z))
        };
        let (mut origin, mut n) = (Vector3::zeros(), 0.0);
        for y in 0..h {
            for x in 0..w {
                if let Some(p) = point(x, y) {
                    origin += p;
                    n += 1.0;
                }
            }
        }
        if n > 0.0 {
            origin /= n;
        }
        let mut sums = vec![[0.0; 35]; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = [0.0; 35];
            for x in 0..w {
                if let Some(p) = point(x, y) {
                    let q = p - origin;
                    for (r, v) in row.iter_mut().zip(monomials(&q)) {
                        *r += v;
                    }
                }
                let above = sums[y * (w + 1) + x + 1];
                let cell = &mut sums[(y + 1) * (w + 1) + x + 1];
                for m in 0..35 {
                    cell[m] = above[m] + row[m];
                }
            }
        }
        Self {
            width: w,
            height: h,
            origin,
            sums,
        }
    }

    /// The sums over pixels `x0..x1 × y0..y1`.
    fn window(&self, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> Poly {
        let at = |x: usize, y: usize| &self.sums[y * (self.width + 1) + x];
        let (a, b, c, d) = (at(x1, y1), at(x0, y1), at(x1, y0), at(x0, y0));
        std::array::from_fn(|k| a[k] - b[k] - c[k] + d[k])
    }
}

/// A window's surface as a height field over its plane: `h(a, b) = Σ cₖ φₖ(a / r, b / r)`,
/// `φ = (1, a, b, a², ab, b²)`, `(a, b, h)` the coordinates along `frame`'s columns (two in the
/// plane, its normal) about `centre`, `r` the window's half-size in metres.
struct HeightField {
    c: [f64; 6],
    centre: Vector3<f64>,
    frame: nalgebra::Matrix3<f64>,
    r: f64,
    /// RMS of the points' heights about the fit (m).
    rms: f64,
    /// The points' centroid in the plane, relative to `centre` (m).
    centroid_offset: f64,
}

impl HeightField {
    /// The least-squares height field of a window's sums (points relative to the tables'
    /// origin) about `centre` (same frame); `None` if singular.
    fn fit(m: &Poly, centre: Vector3<f64>, r: f64, table: &Table) -> Option<Self> {
        let n = m[0];
        let sum = |i, j, k| m[monomial(i, j, k)];
        let c = Vector3::new(sum(1, 0, 0), sum(0, 1, 0), sum(0, 0, 1)) / n;
        let cov = nalgebra::Matrix3::from_fn(|a, b| {
            let mut e = [0u8; 3];
            e[a] += 1;
            e[b] += 1;
            sum(e[0], e[1], e[2]) / n - c[a] * c[b]
        });
        let eig = nalgebra::SymmetricEigen::new(cov);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let col = |k: usize| eig.eigenvectors.column(order[k]).into_owned();
        let (e1, e2) = (col(0), col(1));
        let frame = nalgebra::Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]);
        // Local coordinate (a, b or h) of a point q: l · q − l · centre.
        let local = |axis: usize| -> Poly {
            let l = frame.column(axis).into_owned();
            let mut p = [0.0; 35];
            p[0] = -l.dot(&centre);
            p[1..4].copy_from_slice(l.as_slice());
            p
        };
        let (pa, pb, ph) = (local(0), local(1), local(2));
        let product = |p: &Poly, q: &Poly| -> Poly {
            // q is linear (constant + three terms).
            let mut out = times_linear(p, &Vector3::new(q[1], q[2], q[3]), table);
            for (o, v) in out.iter_mut().zip(p) {
                *o += q[0] * v;
            }
            out
        };
        let dot = |p: &Poly| p.iter().zip(m).map(|(a, b)| a * b).sum::<f64>();
        // Σ aⁱ bʲ (i + j ≤ 4) and Σ h aⁱ bʲ (i + j ≤ 2), scaled by the half-size.
        let mut ab = [[0.0f64; 5]; 5];
        let mut hab = [[0.0f64; 3]; 3];
        let mut one = [0.0; 35];
        one[0] = 1.0;
        let mut row = one;
        for i in 0..=4usize {
            let mut p = row;
            for j in 0..=(4 - i) {
                ab[i][j] = dot(&p) / r.powi((i + j) as i32);
                if i + j <= 2 {
                    hab[i][j] = dot(&product(&p, &ph)) / r.powi((i + j) as i32);
                }
                if j < 4 - i {
                    p = product(&p, &pb);
                }
            }
            if i < 4 {
                row = product(&row, &pa);
            }
        }
        let hh = dot(&product(&ph, &ph));
        const PHI: [(usize, usize); 6] = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)];
        let a = nalgebra::Matrix6::from_fn(|u, v| ab[PHI[u].0 + PHI[v].0][PHI[u].1 + PHI[v].1]);
        let b = nalgebra::Vector6::from_fn(|u, _| hab[PHI[u].0][PHI[u].1]);
        let coef = a.cholesky()?.solve(&b);
        let ss = (hh - coef.dot(&b)).max(0.0);
        Some(Self {
            c: coef.into(),
            centre,
            frame,
            r,
            rms: (ss / n).sqrt(),
            centroid_offset: (ab[1][0].powi(2) + ab[0][1].powi(2)).sqrt() / n * r,
        })
    }

    /// The surface's point and unit normal (along the frame's third axis' side) above the
    /// point `q`'s projection onto the plane.
    fn at(&self, q: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let l = self.frame.transpose() * (q - self.centre);
        let (s, t) = (l.x / self.r, l.y / self.r);
        let c = &self.c;
        let h = c[0] + c[1] * s + c[2] * t + c[3] * s * s + c[4] * s * t + c[5] * t * t;
        let ha = (c[1] + 2.0 * c[3] * s + c[4] * t) / self.r;
        let hb = (c[2] + c[4] * s + 2.0 * c[5] * t) / self.r;
        let point = self.centre + self.frame * Vector3::new(l.x, l.y, h);
        let normal = (self.frame * Vector3::new(-ha, -hb, 1.0)).normalize();
        (point, normal)
    }
}

/// Re-reflects the rays of objects at least `cfg.min_scale_m` large (`scales[object]`, m) off the
/// depth points' local surfaces where they agree with the fit (module docs); `camera_centre` is
/// the thermal camera's centre, depth frame. Returns how many rays were re-reflected.
pub fn refine(
    rays: &mut ReflectedRays<f64>,
    depth: &Image<f32>,
    depth_camera: &PinholeCamera,
    camera_centre: &Vector3<f64>,
    scales: &[f64],
    cfg: &DepthMirror,
) -> usize {
    use rayon::prelude::*;
    if !cfg.enabled || !scales.iter().any(|s| *s >= cfg.min_scale_m) {
        return 0;
    }
    let moments = Moments::new(depth, depth_camera);
    let table = Table::new();
    let max_turn_cos = cfg.max_turn_deg.to_radians().cos();
    // Per ray, when re-reflected: origin, direction, normal.
    type Ray3 = (Vector3<f64>, Vector3<f64>, Vector3<f64>);
    let refined: Vec<Option<Ray3>> = (0..rays.len())
        .into_par_iter()
        .map(|i| {
            let scale = scales[rays.object[i] as usize];
            if scale < cfg.min_scale_m {
                return None;
            }
            let hit = rays.origin[i];
            let d = (hit - camera_centre).try_normalize(1e-12)?;
            // Where the thermal pixel's ray meets the depth surface, from the fit's hit: the
            // ray's point at the depth of the pixel it projects to, until that pixel stays (the
            // cameras are centimetres apart, so the ray's image moves little).
            let mut t = (hit - camera_centre).norm();
            let mut at = None;
            for _ in 0..8 {
                let (x, y) = depth_camera.project_to_pixel(&(camera_centre + d * t))?;
                let z = f64::from(depth.data[y as usize * moments.width + x as usize]);
                if !(z.is_finite() && z > 0.0) || d.z < 1e-3 {
                    return None;
                }
                t = (z - camera_centre.z) / d.z;
                if at == Some((x, y)) {
                    break;
                }
                at = Some((x, y));
            }
            let (x, y) = at?;
            let seen = camera_centre + d * t;
            if (seen - hit).norm() > cfg.gate_m {
                return None;
            }
            // The window: ±radius_rel × the object's size about the seen point.
            let k = (cfg.radius_rel * scale * depth_camera.fx / seen.z).round() as usize;
            if k < 2 {
                return None;
            }
            let (x, y) = (x as usize, y as usize);
            let xs = (x.saturating_sub(k), (x + k + 1).min(moments.width));
            let ys = (y.saturating_sub(k), (y + k + 1).min(moments.height));
            let m = moments.window(xs, ys);
            // Half the window's pixels at least (holes, the image's border).
            if m[0] < 0.5 * ((2 * k + 1) * (2 * k + 1)) as f64 {
                return None;
            }
            let r = k as f64 * seen.z / depth_camera.fx;
            let o = moments.origin;
            let f = HeightField::fit(&m, seen - o, r, &table)?;
            if f.rms > cfg.max_rms_m || f.centroid_offset > OFF_CENTRE * r {
                return None;
            }
            // The thermal pixel's ray meets the surface: intersect it with the tangent plane
            // above the current point, a few times.
            let c = camera_centre - o;
            let meet = |p: &Vector3<f64>, n: &Vector3<f64>| {
                let dn = d.dot(n);
                (dn.abs() > 1e-9).then(|| c + d * ((p - c).dot(n) / dn))
            };
            let (mut p, mut n) = f.at(&(seen - o));
            for _ in 0..3 {
                (p, n) = f.at(&meet(&p, &n)?);
            }
            let fit_n = rays.normal[i];
            let n = if n.dot(&fit_n) < 0.0 { -n } else { n };
            if n.dot(&fit_n) < max_turn_cos || d.dot(&n) >= -1e-6 {
                return None;
            }
            let p = meet(&p, &n)? + o;
            if (p - hit).norm() > cfg.gate_m {
                return None;
            }
            Some((p, reflect(&d, &n).normalize(), n))
        })
        .collect();
    let mut count = 0;
    for (i, r) in refined.into_iter().enumerate() {
        if let Some((p, dir, n)) = r {
            rays.origin[i] = p;
            rays.dir[i] = dir;
            rays.normal[i] = n;
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A depth camera looking at a surface (`surface`: unit camera-frame ray → its first point
    /// and normal there, NaN where it misses); for every 29th of its points, the ray of a
    /// thermal camera 5 cm to the side reflected off a fitted normal turned by `turn` (radians).
    /// `noise`: the depth's σ per m² of depth (a structured-light sensor's ≈ 1.5e-3), then
    /// rounded to millimetres as a 16-bit depth image is; 0: exact f32 depths.
    fn scene(
        surface: impl Fn(&Vector3<f64>) -> (Vector3<f64>, Vector3<f64>),
        turn: f64,
        noise: f64,
    ) -> (Image<f32>, PinholeCamera, Vector3<f64>, ReflectedRays<f64>) {
        use rand::{Rng, SeedableRng};
        let (w, h) = (640u32, 480u32);
        let cam = PinholeCamera::from_fov(w, h, 1.0).unwrap();
        let mut depth = Image {
            width: w,
            height: h,
            data: vec![f32::NAN; (w * h) as usize],
        };
        let centre = Vector3::new(0.05, 0.0, 0.0);
        let mut rays = ReflectedRays {
            width: w,
            height: h,
            ..Default::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for y in 0..h {
            for x in 0..w {
                let (p, n) = surface(&cam.pixel_ray::<f64>(x, y).dir.normalize());
                // A miss: no depth (NaN), no ray.
                depth.data[(y * w + x) as usize] = if noise > 0.0 {
                    let e: f64 = rng.sample(rand_distr::StandardNormal);
                    ((p.z + e * noise * p.z * p.z) * 1000.0).round() as f32 / 1000.0
                } else {
                    p.z as f32
                };
                if p.z.is_finite() && (x + 3 * y) % 29 == 0 {
                    // The thermal camera's ray to the same point (it sees it too).
                    let d = (p - centre).normalize();
                    let wrong = nalgebra::Rotation3::new(Vector3::y() * turn) * n;
                    rays.push(y * w + x, 0, p, reflect(&d, &wrong), wrong);
                }
            }
        }
        (depth, cam, centre, rays)
    }

    /// On a tilted plane (f32 depths, no noise) every ray is re-reflected off the true normal
    /// and the reflection is exact; the fit's hits 5 cm short of the plane along their rays
    /// move onto it (the ray is followed to the depth surface).
    #[test]
    fn rays_on_a_plane_take_the_planes_normal() {
        let n = Vector3::new(0.3, -0.2, -1.0).normalize();
        // n·p = n·(0, 0, 2.2), seen from the origin.
        let plane = |r: &Vector3<f64>| (r * (n.z * 2.2 / n.dot(r)), n);
        let (depth, cam, centre, mut rays) = scene(plane, 10f64.to_radians(), 0.0);
        let on_plane = rays.origin.clone();
        for o in &mut rays.origin {
            *o -= (*o - centre).normalize() * 0.05;
        }
        let before = rays.clone();
        let cfg = DepthMirror {
            enabled: true,
            ..DepthMirror::default()
        };
        let count = refine(&mut rays, &depth, &cam, &centre, &[2.0], &cfg);
        // All but the windows cut by the image's border.
        assert!(count > rays.len() * 8 / 10, "{count} of {}", rays.len());
        let mut moved = 0;
        for i in 0..rays.len() {
            if rays.normal[i] == before.normal[i] {
                continue;
            }
            moved += 1;
            assert!(rays.normal[i].angle(&n).to_degrees() < 0.01, "{i}");
            let d = (on_plane[i] - centre).normalize();
            let expected = reflect(&d, &n);
            assert!(rays.dir[i].angle(&expected).to_degrees() < 0.02, "{i}");
            assert!((rays.origin[i] - on_plane[i]).norm() < 1e-4, "{i}");
        }
        assert_eq!(moved, count);
    }

    /// Median / 90th percentile / max of the angle (degrees) between each re-reflected ray's
    /// normal and a sphere's (centre `c`) at its origin, and how many were re-reflected.
    fn sphere_normals(c: Vector3<f64>, radius: f64, scale: f64, noise: f64) -> [f64; 4] {
        let sphere = |r: &Vector3<f64>| {
            let b = r.dot(&c);
            let p = r * (b - (b * b - (c.norm_squared() - radius * radius)).sqrt());
            (p, (p - c).normalize())
        };
        let (depth, cam, centre, mut rays) = scene(sphere, 8f64.to_radians(), noise);
        let before = rays.clone();
        let cfg = DepthMirror {
            enabled: true,
            ..DepthMirror::default()
        };
        let count = refine(&mut rays, &depth, &cam, &centre, &[scale], &cfg);
        // Not near the silhouette, where the window leaves the sphere.
        assert!(count > rays.len() * 7 / 10, "{count} of {}", rays.len());
        let mut angles: Vec<f64> = (0..rays.len())
            .filter(|&i| rays.normal[i] != before.normal[i])
            .map(|i| {
                let truth = (rays.origin[i] - c).normalize();
                rays.normal[i].angle(&truth).to_degrees()
            })
            .collect();
        angles.sort_by(f64::total_cmp);
        let q = |f: f64| angles[((angles.len() - 1) as f64 * f) as usize];
        [q(0.5), q(0.9), q(1.0), count as f64]
    }

    /// On a sphere of radius 2 m seen from 2 m (more curved than a door), exact depths: the
    /// quadric over the window's plane has the sphere's normal at the ray's hit (its height
    /// field has no third-order term), ±8 cm and ±18 cm windows alike. Measured: 0.0001° /
    /// 0.001° / 0.01° and 0.002° / 0.014° / 0.036° (the window's plane alone: 0.076° / 0.23° /
    /// 0.95° at ±8 cm; the inverse depth's quadric in image coordinates 0.30° at ±18 cm).
    #[test]
    fn rays_on_a_curve_take_its_normal() {
        let c = Vector3::new(0.0, 0.0, 4.0);
        for (scale, bound) in [(2.0, [0.002, 0.01, 0.05]), (4.5, [0.01, 0.05, 0.1])] {
            let [median, p90, max, _] = sphere_normals(c, 2.0, scale, 0.0);
            assert!(
                median < bound[0] && p90 < bound[1] && max < bound[2],
                "±{} m: {median} / {p90} / {max}",
                0.04 * scale
            );
        }
    }

    /// The same sphere seen through a structured-light sensor's noise (σ = 1.5e-3 z², ≈ 6 mm at
    /// 2 m) rounded to millimetres: a larger window averages more of it away. Measured (normal,
    /// median / p90 / max): ±8 cm 0.37° / 0.57° / 1.6°, ±18 cm 0.072° / 0.12° / 0.39°, ±36 cm
    /// 0.027° / 0.081° / 0.23°.
    #[test]
    fn noisy_depth_is_averaged_over_the_window() {
        let c = Vector3::new(0.0, 0.0, 4.0);
        let [small, ..] = sphere_normals(c, 2.0, 2.0, 1.5e-3);
        let [median, p90, max, _] = sphere_normals(c, 2.0, 4.5, 1.5e-3);
        assert!(small > 0.25 && small < 0.5, "±8 cm: {small}");
        assert!(
            median < 0.1 && p90 < 0.2 && max < 0.6,
            "±18 cm: {median} / {p90} / {max}"
        );
    }

    /// The window's moments expanded into its own frame: points on a paraboloid patch
    /// (h = 0.8 (a² + b²) − 0.3 a b… in its axes), turned and moved anywhere, their sums taken
    /// directly; the height field fitted about an off-axis point on it reproduces the surface
    /// and its normal there to rounding.
    #[test]
    fn a_quadric_patch_is_fitted_exactly_in_any_frame() {
        let rot = nalgebra::Rotation3::new(Vector3::new(0.4, -0.9, 0.3));
        let shift = Vector3::new(0.7, -0.4, 2.3);
        let h = |a: f64, b: f64| 0.8 * a * a + 0.6 * b * b - 0.3 * a * b;
        let world = |a: f64, b: f64| rot * Vector3::new(a, b, h(a, b)) + shift;
        let table = Table::new();
        let mut m = [0.0; 35];
        let origin = Vector3::new(0.5, -0.2, 2.0);
        for i in -20..=20 {
            for j in -20..=20 {
                let q = world(f64::from(i) * 0.005, f64::from(j) * 0.005) - origin;
                for (s, v) in m.iter_mut().zip(monomials(&q)) {
                    *s += v;
                }
            }
        }
        let (a0, b0) = (0.02, -0.015);
        let centre = world(a0, b0) - origin;
        let f = HeightField::fit(&m, centre, 0.1, &table).unwrap();
        // (Σ h² − cᵀb loses the last digits: 1.5e-8 measured.)
        assert!(f.rms < 1e-6, "{}", f.rms);
        for (a, b) in [(a0, b0), (-0.05, 0.07), (0.09, 0.0)] {
            let p = world(a, b) - origin;
            let (on, n) = f.at(&p);
            assert!((on - p).norm() < 1e-9, "{:?}", on - p);
            let truth = rot * Vector3::new(-(1.6 * a - 0.3 * b), -(1.2 * b - 0.3 * a), 1.0);
            assert!(n.cross(&truth.normalize()).norm() < 1e-8, "{n:?}");
        }
    }

    /// Settings no refinement can run with are a clear error naming the field, when enabled.
    #[test]
    fn impossible_settings_are_refused() {
        let on = DepthMirror {
            enabled: true,
            ..DepthMirror::default()
        };
        assert!(on.check().is_ok());
        for (bad, field) in [
            (
                DepthMirror {
                    radius_rel: -0.1,
                    ..on.clone()
                },
                "radius_rel",
            ),
            (
                DepthMirror {
                    gate_m: f64::NAN,
                    ..on.clone()
                },
                "gate_m",
            ),
            (
                DepthMirror {
                    max_turn_deg: 120.0,
                    ..on.clone()
                },
                "max_turn_deg",
            ),
        ] {
            let e = bad.check().unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
            // Off, nothing is used, nothing refused.
            let off = DepthMirror {
                enabled: false,
                ..bad
            };
            assert!(off.check().is_ok());
        }
    }

    /// Left alone: rays where the depth disagrees with the fit (beyond the gate), small
    /// objects, a normal the data turn too far, and everything when switched off.
    #[test]
    fn rays_the_depth_does_not_support_are_left_alone() {
        let n = Vector3::new(0.0, 0.0, -1.0);
        let plane = |r: &Vector3<f64>| (r * (2.0 / r.z), n);
        let on = DepthMirror {
            enabled: true,
            ..DepthMirror::default()
        };
        let (depth, cam, centre, rays) = scene(plane, 10f64.to_radians(), 0.0);
        let run = |rays: &ReflectedRays<f64>, scales: &[f64], cfg: &DepthMirror| {
            let mut r = rays.clone();
            (refine(&mut r, &depth, &cam, &centre, scales, cfg), r)
        };
        assert!(run(&rays, &[2.0], &on).0 > 0);
        assert_eq!(run(&rays, &[0.2], &on).0, 0, "a tabletop-sized object");
        assert_eq!(run(&rays, &[2.0], &DepthMirror::default()).0, 0, "off");
        let strict = DepthMirror {
            max_turn_deg: 5.0,
            ..on.clone()
        };
        assert_eq!(run(&rays, &[2.0], &strict).0, 0, "turned 10° > 5°");
        // The fit 0.3 m in front of the depth data.
        let mut off = rays.clone();
        for o in &mut off.origin {
            o.z -= 0.3;
        }
        let (count, r) = run(&off, &[2.0], &on);
        assert_eq!(count, 0);
        assert_eq!(r.dir, off.dir);
    }
}
