//! From camera pixels to reflected rays: nearest object surface per pixel, normals (optionally
//! smoothed over a small patch of the surface, paper §3.4 "surface smoothing"), mirror
//! reflection `r' = r − 2 (r·n) n`. Computed once per capture: objects are fixed in stage 2.

use crate::sdf::PlacedSdf;
use crate::sphere_trace::{SurfaceHit, TraceParams, trace};
use irmirror_geom::{PinholeCamera, Real, Rigid3};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Surface normals used for reflection.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Normals {
    /// The SDF gradient at the pixel's own surface point.
    Raw,
    /// Mean of the object's normals at the hit and at 8 points around it on its tangent plane,
    /// [`smoothing_radius`] away (the paper's surface smoothing: 8 rays around the main one,
    /// against a learned surface's ripples at the millimetre scale).
    Smoothed,
}

/// Radius of the surface smoothing's ring, relative to the object's bounding radius (0.7 mm on
/// a 7-cm bowl), at most [`SMOOTHING_RADIUS_MAX`]. A fixed patch of the surface, not of the
/// image: the 3 × 3 neighbouring pixels used before spanned 0.5–1 cm of a bowl at 160 × 120
/// (more at its rim), and their mean moved the reflected rays so far that the true body,
/// rendered through the true objects, missed 11–28 % of the simulator's noise-free rise on the
/// hard view's captures (1–3 % with unsmoothed normals; EXPERIMENTS.md, "Forty-second run").
pub const SMOOTHING_RADIUS_REL: f64 = 0.01;

/// The ring's largest radius in metres: the scale of a learned surface's ripples. Uncapped, 1 %
/// of a car's radius is 2.3 cm, which averaged across the fitted car's rounded edges and made
/// every figure of the car cell worse (EXPERIMENTS.md, "Forty-second run").
pub const SMOOTHING_RADIUS_MAX: f64 = 0.002;

/// The surface smoothing ring's radius for `object`, in the depth frame's metres.
pub fn smoothing_radius(object: &PlacedSdf) -> f64 {
    (SMOOTHING_RADIUS_REL * object.sdf.bounding_radius() * object.depth_from_object.scale)
        .min(SMOOTHING_RADIUS_MAX)
}

/// The mean of `object`'s unit normals at `point` (normal `n`) and at 8 points on a ring of
/// [`smoothing_radius`] about it in the tangent plane. On a sphere it is `n` itself (by
/// symmetry); on a surface with ripples shorter than the ring it is their average.
pub fn smoothed_normal(object: &PlacedSdf, point: &Vector3<f64>, n: &Vector3<f64>) -> Vector3<f64> {
    let r = smoothing_radius(object);
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&helper).normalize();
    let t2 = n.cross(&t1);
    let mut sum = *n;
    for j in 0..8 {
        let a = f64::from(j) * std::f64::consts::FRAC_PI_4;
        sum += object.normal(&(point + (t1 * a.cos() + t2 * a.sin()) * r));
    }
    sum.try_normalize(1e-12).unwrap_or(*n)
}

/// Mirror reflection of direction `r` about unit normal `n`.
#[inline]
pub fn reflect<T: Real>(r: &Vector3<T>, n: &Vector3<T>) -> Vector3<T> {
    r - n * ((T::one() + T::one()) * r.dot(n))
}

/// Reflected half-lines, one per camera pixel that sees an object.
#[derive(Clone, Debug, Default)]
pub struct ReflectedRays<T: Real> {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Row-major pixel index of each ray.
    pub pixel: Vec<u32>,
    /// Object each ray reflects off.
    pub object: Vec<u16>,
    /// Ray origins (the surface points), depth frame, metres.
    pub origin: Vec<Vector3<T>>,
    /// Unit reflected directions, depth frame.
    pub dir: Vec<Vector3<T>>,
    /// Normals used, depth frame.
    pub normal: Vec<Vector3<T>>,
    /// Rays per pixel when each pixel's footprint is sampled at fixed sub-pixel points (its rays
    /// then lie next to each other, in pixel order; a point that misses every object has
    /// none); 0 or 1: at most one ray per pixel.
    pub footprint: u32,
}

impl<T: Real> ReflectedRays<T> {
    /// Number of rays.
    pub fn len(&self) -> usize {
        self.pixel.len()
    }
    /// True if no pixel sees an object.
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// The rays at `indices` (in that order) into `out`, reusing its buffers.
    pub fn select_into(&self, indices: &[usize], out: &mut ReflectedRays<T>) {
        out.width = self.width;
        out.height = self.height;
        out.footprint = self.footprint;
        out.pixel.clear();
        out.object.clear();
        out.origin.clear();
        out.dir.clear();
        out.normal.clear();
        for &i in indices {
            out.push(
                self.pixel[i],
                self.object[i],
                self.origin[i],
                self.dir[i],
                self.normal[i],
            );
        }
    }

    /// Appends one ray.
    pub fn push(
        &mut self,
        pixel: u32,
        object: u16,
        origin: Vector3<T>,
        dir: Vector3<T>,
        normal: Vector3<T>,
    ) {
        self.pixel.push(pixel);
        self.object.push(object);
        self.origin.push(origin);
        self.dir.push(dir);
        self.normal.push(normal);
    }

    /// Converts the scalar type.
    pub fn cast<U: Real>(&self) -> ReflectedRays<U> {
        let c = |v: &Vec<Vector3<T>>| v.iter().map(|x| x.map(|a| U::of(a.to_f64()))).collect();
        ReflectedRays {
            width: self.width,
            height: self.height,
            pixel: self.pixel.clone(),
            object: self.object.clone(),
            origin: c(&self.origin),
            dir: c(&self.dir),
            normal: c(&self.normal),
            footprint: self.footprint,
        }
    }
}

/// Casts one ray per pixel centre of `camera` (placed by `depth_from_camera`) at `objects`,
/// keeps the nearest surface, and reflects.
pub fn reflect_camera(
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    objects: &[PlacedSdf],
    trace_params: &TraceParams,
    normals: Normals,
) -> ReflectedRays<f64> {
    reflect_camera_at(
        camera,
        depth_from_camera,
        objects,
        trace_params,
        normals,
        (0.0, 0.0),
        None,
    )
}

/// [`reflect_camera`] with every ray shifted by `offset` (pixels) from its pixel's centre, for
/// the pixels where `only` (row-major, one per pixel) is true, or all. A pixel's footprint
/// sampled at several offsets is what the radiometric fit integrates.
pub fn reflect_camera_at(
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    objects: &[PlacedSdf],
    trace_params: &TraceParams,
    normals: Normals,
    offset: (f64, f64),
    only: Option<&[bool]>,
) -> ReflectedRays<f64> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let (du, dv) = offset;
    // Per pixel: (object, camera ray direction, hit, the normal it reflects about).
    type PixelHit = (u16, Vector3<f64>, SurfaceHit, Vector3<f64>);
    let hits: Vec<Option<PixelHit>> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            if only.is_some_and(|o| !o[p]) {
                return None;
            }
            let (u, v) = ((p % w) as f64 + 0.5 + du, (p / w) as f64 + 0.5 + dv);
            let ray = depth_from_camera.transform_ray(&camera.ray_at::<f64>(u, v));
            let (k, hit) = nearest_hit(objects, &ray, trace_params)?;
            let n = match normals {
                Normals::Raw => hit.normal,
                Normals::Smoothed => smoothed_normal(&objects[k as usize], &hit.point, &hit.normal),
            };
            Some((k, ray.dir, hit, n))
        })
        .collect();
    let mut out = ReflectedRays {
        width: camera.width,
        height: camera.height,
        ..Default::default()
    };
    for (p, hit) in hits.iter().enumerate() {
        let Some((k, dir, hit, n)) = hit else {
            continue;
        };
        out.push(p as u32, *k, hit.point, reflect(dir, n).normalize(), *n);
    }
    out
}

/// The nearest surface along `ray` among `objects`: (object index, hit).
fn nearest_hit(
    objects: &[PlacedSdf],
    ray: &irmirror_geom::Ray<f64>,
    trace_params: &TraceParams,
) -> Option<(u16, SurfaceHit)> {
    objects
        .iter()
        .enumerate()
        .filter_map(|(k, obj)| trace(obj, ray, trace_params).map(|hit| (k as u16, hit)))
        .min_by(|a, b| a.1.t_m.total_cmp(&b.1.t_m))
}

/// Sub-pixel offsets tried by [`reflect_footprint`], nearest the centre first (pixel units).
const FOOTPRINT: [(f64, f64); 8] = [
    (0.3, 0.0),
    (-0.3, 0.0),
    (0.0, 0.3),
    (0.0, -0.3),
    (0.3, 0.3),
    (-0.3, 0.3),
    (0.3, -0.3),
    (-0.3, -0.3),
];

/// For each of `pixels` (row-major indices) whose centre ray misses every object, the first ray
/// through its footprint (offsets ±0.3 px, nearest first) that hits one, reflected with the raw
/// normal. A pixel integrates over its footprint, so a silhouette pixel whose centre misses can
/// still show a reflection (a mug's thin rim): these rays let such a pixel count. Pixels whose
/// centre hits, or whose whole footprint misses, give no ray.
pub fn reflect_footprint(
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    objects: &[PlacedSdf],
    trace_params: &TraceParams,
    pixels: &[u32],
) -> ReflectedRays<f64> {
    let w = camera.width;
    let nearest = |ray: &irmirror_geom::Ray<f64>| nearest_hit(objects, ray, trace_params);
    // Per pixel: (pixel, object, camera ray direction, hit).
    type Found = Option<(u32, u16, Vector3<f64>, SurfaceHit)>;
    let found: Vec<Found> = pixels
        .par_iter()
        .map(|&p| {
            let (u, v) = (f64::from(p % w) + 0.5, f64::from(p / w) + 0.5);
            let centre = depth_from_camera.transform_ray(&camera.ray_at::<f64>(u, v));
            if nearest(&centre).is_some() {
                return None;
            }
            FOOTPRINT.iter().find_map(|&(du, dv)| {
                let ray = depth_from_camera.transform_ray(&camera.ray_at::<f64>(u + du, v + dv));
                nearest(&ray).map(|(k, hit)| (p, k, ray.dir, hit))
            })
        })
        .collect();
    let mut out = ReflectedRays {
        width: camera.width,
        height: camera.height,
        ..Default::default()
    };
    for (p, k, dir, hit) in found.into_iter().flatten() {
        out.push(
            p,
            k,
            hit.point,
            reflect(&dir, &hit.normal).normalize(),
            hit.normal,
        );
    }
    out
}

impl<T: Real> ReflectedRays<T> {
    /// Appends `other`'s rays (same image size).
    pub fn extend(&mut self, other: &ReflectedRays<T>) {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        self.pixel.extend_from_slice(&other.pixel);
        self.object.extend_from_slice(&other.object);
        self.origin.extend_from_slice(&other.origin);
        self.dir.extend_from_slice(&other.dir);
        self.normal.extend_from_slice(&other.normal);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::Sphere;
    use irmirror_geom::Similarity3;
    use nalgebra::Matrix3;
    use std::sync::Arc;

    /// A mirror sphere of radius 0.15 m at (0, 0, 0.5), a 32×24 camera at the origin looking at
    /// it, and trace settings tight enough for closed-form comparisons.
    fn mirror_sphere() -> (Vector3<f64>, PlacedSdf, PinholeCamera, TraceParams) {
        let c = Vector3::new(0.0, 0.0, 0.5);
        let obj = PlacedSdf {
            sdf: Arc::new(Sphere { radius: 1.0 }),
            depth_from_object: Similarity3::new(Matrix3::identity(), c, 0.15).unwrap(),
        };
        let cam = PinholeCamera {
            width: 32,
            height: 24,
            fx: 30.0,
            fy: 30.0,
            cx: 16.0,
            cy: 12.0,
        };
        (
            c,
            obj,
            cam,
            TraceParams {
                coarse_tol_rel: 1e-9,
                max_iters: 4000,
                ..TraceParams::default()
            },
        )
    }

    #[test]
    fn mirror_sphere_reflection_matches_closed_form() {
        // For a camera ray hitting p, n = (p − c)/ρ and the reflection is r − 2 (r·n) n; check
        // point, direction, and the law of reflection.
        let (c, obj, cam, tight) = mirror_sphere();
        let rays = reflect_camera(
            &cam,
            &Rigid3::identity(),
            std::slice::from_ref(&obj),
            &tight,
            Normals::Raw,
        );
        assert!(rays.len() > 50);
        for i in 0..rays.len() {
            let p = rays.pixel[i];
            let d: irmirror_geom::Ray<f64> = cam.pixel_ray(p % 32, p / 32);
            let b = d.dir.dot(&(-c));
            let t = -b - (b * b - (c.norm_squared() - 0.0225)).sqrt();
            let hit = d.at(t);
            let n = (hit - c) / 0.15;
            let r = d.dir - n * (2.0 * d.dir.dot(&n));
            assert!((rays.origin[i] - hit).norm() < 1e-8);
            assert!((rays.dir[i] - r).norm() < 1e-7);
            // Angle of incidence equals angle of reflection.
            assert!((rays.dir[i].dot(&n) + d.dir.dot(&n)).abs() < 1e-7);
        }
        // The centre pixel looks straight at the sphere and is reflected straight back.
        let i = rays.pixel.iter().position(|&p| p == 12 * 32 + 16).unwrap();
        assert!(rays.dir[i].z < -0.99);
    }

    /// Rays shifted from the pixel centres, on a subset of pixels: each is the analytic
    /// reflection of the camera ray through its shifted point, and only chosen pixels have one.
    #[test]
    fn offset_rays_match_the_closed_form_on_chosen_pixels() {
        let (c, obj, cam, tight) = mirror_sphere();
        let (du, dv) = (0.37, -0.21);
        // Every other column. Column 25 of row 12 has its centre 9.5 px from the sphere's
        // centre, outside its 9.43 px silhouette; shifted +0.37 px it stays outside.
        let only: Vec<bool> = (0..32 * 24).map(|p| p % 2 == 1).collect();
        let rays = reflect_camera_at(
            &cam,
            &Rigid3::identity(),
            std::slice::from_ref(&obj),
            &tight,
            Normals::Raw,
            (du, dv),
            Some(&only),
        );
        assert!(rays.len() > 30);
        assert!(!rays.pixel.contains(&(12 * 32 + 25)));
        for i in 0..rays.len() {
            let p = rays.pixel[i];
            assert!(only[p as usize]);
            let d: irmirror_geom::Ray<f64> =
                cam.ray_at(f64::from(p % 32) + 0.5 + du, f64::from(p / 32) + 0.5 + dv);
            let dir = d.dir.normalize();
            let b = dir.dot(&(-c));
            let t = -b - (b * b - (c.norm_squared() - 0.0225)).sqrt();
            let hit = dir * t;
            let n = (hit - c) / 0.15;
            assert!((rays.origin[i] - hit).norm() < 1e-8);
            assert!((rays.dir[i] - (dir - n * (2.0 * dir.dot(&n)))).norm() < 1e-7);
        }
        // Shifting inwards instead reaches a pixel whose centre misses.
        let inward = reflect_camera_at(
            &cam,
            &Rigid3::identity(),
            std::slice::from_ref(&obj),
            &tight,
            Normals::Raw,
            (-0.37, 0.0),
            Some(&only),
        );
        assert!(inward.pixel.contains(&(12 * 32 + 25)));
    }

    /// A pixel whose centre ray passes just outside a mirror sphere but whose footprint grazes it
    /// gets the analytic reflection at the sub-pixel ray that hits; a pixel whose centre hits,
    /// and one far from the sphere, get none.
    #[test]
    fn footprint_rays_match_the_closed_form() {
        let (c, obj, cam, tight) = mirror_sphere();
        let centres = reflect_camera(
            &cam,
            &Rigid3::identity(),
            std::slice::from_ref(&obj),
            &tight,
            Normals::Raw,
        );
        // The sphere's silhouette radius in pixels: 30 · tan(asin(0.15 / 0.5)) ≈ 9.43, so on
        // row 12 (through the centre) column 16 + 9 = 25 has its centre 9.5 px out (a miss)
        // and its footprint reaches 9.2 px (a hit).
        let edge = 12 * 32 + 25;
        assert!(!centres.pixel.contains(&edge));
        let rays = reflect_footprint(
            &cam,
            &Rigid3::identity(),
            std::slice::from_ref(&obj),
            &tight,
            &[edge, 12 * 32 + 16, 12 * 32 + 31],
        );
        assert_eq!(rays.pixel, vec![edge]);
        let hit = rays.origin[0];
        let n = (hit - c) / 0.15;
        assert!((hit - c).norm() - 0.15 < 1e-7, "on the sphere");
        let d = hit.normalize();
        let (u, v) = cam.project(&hit).unwrap();
        assert!(
            (u - 25.5).abs() <= 0.3 + 1e-9 && (v - 12.5).abs() <= 0.3 + 1e-9,
            "inside the footprint: {u}, {v}"
        );
        assert!((rays.dir[0] - (d - n * (2.0 * d.dot(&n)))).norm() < 1e-6);
    }

    /// A unit sphere with ripples of `amp` and wavelength `2π / freq` on its surface (a learned
    /// surface's small-scale noise).
    struct Rippled {
        amp: f64,
        freq: f64,
    }

    impl crate::sdf::Sdf for Rippled {
        fn distance(&self, p: &Vector3<f64>) -> f64 {
            p.norm() - 1.0 - self.amp * (self.freq * p.x).sin() * (self.freq * p.y).sin()
        }
        fn bounding_radius(&self) -> f64 {
            1.0 + self.amp
        }
    }

    fn smoothing_pair(sdf: Arc<dyn crate::sdf::Sdf>) -> (ReflectedRays<f64>, ReflectedRays<f64>) {
        let obj = PlacedSdf {
            sdf,
            depth_from_object: Similarity3::new(
                Matrix3::identity(),
                Vector3::new(0.0, 0.0, 0.5),
                0.15,
            )
            .unwrap(),
        };
        let cam = PinholeCamera {
            width: 32,
            height: 24,
            fx: 30.0,
            fy: 30.0,
            cx: 16.0,
            cy: 12.0,
        };
        let p = TraceParams::default();
        let rays = |n| reflect_camera(&cam, &Rigid3::identity(), std::slice::from_ref(&obj), &p, n);
        (rays(Normals::Raw), rays(Normals::Smoothed))
    }

    #[test]
    fn smoothing_leaves_a_sphere_alone_and_changes_only_normals() {
        let (raw, smooth) = smoothing_pair(Arc::new(Sphere { radius: 1.0 }));
        assert_eq!(raw.pixel, smooth.pixel);
        assert_eq!(raw.origin, smooth.origin);
        assert!(raw.len() > 100);
        // The ring's normals on a sphere average to the centre's, at every pixel, the rim's
        // included (the 3 × 3 pixel mean it replaces moved them by up to 0.05 here).
        for i in 0..raw.len() {
            let diff = (raw.normal[i] - smooth.normal[i]).norm();
            assert!(diff < 1e-9, "pixel {}: {diff}", raw.pixel[i]);
            assert!((smooth.normal[i].norm() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn smoothing_ring_is_relative_then_capped() {
        let ring = |radius: f64, scale: f64| {
            smoothing_radius(&PlacedSdf {
                sdf: Arc::new(Sphere { radius }),
                depth_from_object: Similarity3::new(Matrix3::identity(), Vector3::zeros(), scale)
                    .unwrap(),
            })
        };
        // A 7-cm bowl: 1 % of its radius; a 2.3-m car, or a small shape scaled up: the cap.
        assert!((ring(0.07, 1.0) - 7e-4).abs() < 1e-12);
        assert!((ring(0.035, 2.0) - 7e-4).abs() < 1e-12);
        assert_eq!(ring(2.3, 1.0), SMOOTHING_RADIUS_MAX);
        assert_eq!(ring(0.5, 1.0), SMOOTHING_RADIUS_MAX);
    }

    #[test]
    fn smoothing_averages_out_ripples_shorter_than_its_ring() {
        // Ripples of 0.3 × the ring's radius r (the cap on this 1-m sphere) with a wavelength of
        // twice the ring's diameter (freq = π / (2 r)): its 8 points sample them half a period
        // apart.
        let r = SMOOTHING_RADIUS_MAX;
        let freq = std::f64::consts::PI / (2.0 * r);
        let (raw, smooth) = smoothing_pair(Arc::new(Rippled { amp: 0.3 * r, freq }));
        let base = |i: usize| (raw.origin[i] - Vector3::new(0.0, 0.0, 0.5)).normalize();
        let err = |n: &[Vector3<f64>]| {
            (0..raw.len()).map(|i| (n[i] - base(i)).norm()).sum::<f64>() / raw.len() as f64
        };
        let (e_raw, e_smooth) = (err(&raw.normal), err(&smooth.normal));
        assert!(e_raw > 0.1, "the ripples tilt the raw normals: {e_raw}");
        assert!(e_smooth < 0.5 * e_raw, "raw {e_raw}, smoothed {e_smooth}");
    }
}
