//! Surface points of SDF objects along camera rays (paper §3.4): a conservative coarse march
//! from the bounding sphere, then K sphere-tracing steps — or, for the "w/o sphere tracing"
//! ablation, a projection of the coarse point along the SDF gradient (Zakharov et al. 2020).

use crate::sdf::{PlacedSdf, Sdf};
use irmirror_geom::Ray;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// How the coarse point is refined onto the surface.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum SurfaceMethod {
    /// `steps` sphere-tracing steps `t += d(o + t r)` along the ray (the paper uses 3).
    SphereTrace {
        /// Number of steps K.
        steps: usize,
    },
    /// One projection `p − d(p) ∇d(p)` of the coarse point (leaves the ray).
    GradientProjection,
}

/// Sphere-tracing settings (object-relative, so they fit any object size).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TraceParams {
    /// The coarse march stops where `d < coarse_tol_rel · bounding radius` (1/64: a 64-cell
    /// grid's resolution, the paper's coarse stage).
    pub coarse_tol_rel: f64,
    /// Refinement of the coarse point.
    pub method: SurfaceMethod,
    /// March iterations at most.
    pub max_iters: usize,
}

impl Default for TraceParams {
    fn default() -> Self {
        Self {
            coarse_tol_rel: 1.0 / 64.0,
            method: SurfaceMethod::SphereTrace { steps: 3 },
            max_iters: 512,
        }
    }
}

/// A ray's surface point on one object, depth frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Distance along the (unit) ray to the coarse point, metres (for nearest-object tests).
    pub t_m: f64,
    /// Surface point, depth frame, metres.
    pub point: Vector3<f64>,
    /// Unit outward normal (SDF gradient), depth frame.
    pub normal: Vector3<f64>,
}

/// Finds where `ray_depth` (unit direction) meets `object`, or `None`.
pub fn trace(object: &PlacedSdf, ray_depth: &Ray<f64>, params: &TraceParams) -> Option<SurfaceHit> {
    let sim = &object.depth_from_object;
    // March in the object frame: unit direction there too, so t_object = t_depth / s.
    let o = sim.inverse_transform_point(&ray_depth.origin);
    let r = sim.rotation.tr_mul(&ray_depth.dir);
    let tol = params.coarse_tol_rel * object.sdf.bounding_radius();
    let mut t = march(object.sdf.as_ref(), &o, &r, tol, params.max_iters)?;
    let t_coarse = t;
    let p_object = match params.method {
        SurfaceMethod::SphereTrace { steps } => {
            for _ in 0..steps {
                t += object.sdf.distance(&(o + r * t));
            }
            o + r * t
        }
        SurfaceMethod::GradientProjection => {
            let p = o + r * t;
            let g = object.sdf.gradient(&p);
            p - g * (object.sdf.distance(&p) / g.norm_squared().max(1e-12))
        }
    };
    let point = sim.transform_point(&p_object);
    Some(SurfaceHit {
        t_m: t_coarse * sim.scale,
        point,
        normal: object.normal(&point),
    })
}

/// Sphere-traces the unit ray `o + t r` (object frame, `t ≥ 0`) into `sdf` from where it enters
/// the bounding sphere, stepping `t += min(d, max_step)` until `d < tol` (object units): the
/// distance `t` there, or `None` when the ray misses the bounding sphere, leaves it, or
/// `max_iters` steps pass. A step that lands inside (`d < 0`: the field rose faster than a
/// distance, as a network's may) is undone by bisecting back to the crossing.
/// [`trace`]'s coarse march (a loose `tol`, then refinement) and stage 1's rendered depth (a
/// tight `tol`) both use it.
pub fn march(
    sdf: &dyn Sdf,
    o: &Vector3<f64>,
    r: &Vector3<f64>,
    tol: f64,
    max_iters: usize,
) -> Option<f64> {
    let radius = sdf.bounding_radius();
    // Bounding-sphere entry and exit.
    let b = o.dot(r);
    let c = o.norm_squared() - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let (t_exit, mut t) = (-b + sq, (-b - sq).max(0.0));
    if t_exit < 0.0 {
        return None;
    }
    let max_step = sdf.max_step();
    // The last point found outside, if any step was taken.
    let mut outside = None;
    for _ in 0..max_iters {
        let d = sdf.distance(&(o + r * t));
        if d < tol {
            return Some(match outside {
                Some(lo) if d < 0.0 => crossing(sdf, o, r, tol, (lo, t)),
                _ => t,
            });
        }
        outside = Some(t);
        // Stepping by d never crosses the surface of a 1-Lipschitz field.
        t += d.min(max_step);
        if t > t_exit {
            return None;
        }
    }
    None
}

/// Bisects `(lo, hi)` (the field positive at `lo`, negative at `hi`) to a `t` where
/// `0 ≤ d < tol`, or to the outside end of a bracket 2⁻⁵⁰ as wide.
fn crossing(
    sdf: &dyn Sdf,
    o: &Vector3<f64>,
    r: &Vector3<f64>,
    tol: f64,
    (mut lo, mut hi): (f64, f64),
) -> f64 {
    // 50 halvings: below 1e-12 of any step a march takes.
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        let d = sdf.distance(&(o + r * mid));
        if d < 0.0 {
            hi = mid;
        } else if d < tol {
            return mid;
        } else {
            lo = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::{Bowl, Capsule};
    use irmirror_geom::Similarity3;
    use irmirror_geom::rotation::axis_angle_to_matrix;
    use std::sync::Arc;

    /// A sphere of radius 0.5 about (0.3, 0, 0) in the object frame (a zero-length capsule, so
    /// the bounding sphere, radius 0.8, is not the surface), rotated, scaled and moved.
    fn placed_sphere(scale: f64) -> PlacedSdf {
        let rot = axis_angle_to_matrix(&Vector3::new(0.3, -1.1, 0.4));
        let c = Vector3::new(0.3, 0.0, 0.0);
        PlacedSdf {
            sdf: Arc::new(Capsule {
                a: c,
                b: c,
                radius: 0.5,
            }),
            depth_from_object: Similarity3::new(rot, Vector3::new(0.02, -0.01, 0.5), scale)
                .unwrap(),
        }
    }

    fn centre(scale: f64) -> Vector3<f64> {
        placed_sphere(scale)
            .depth_from_object
            .transform_point(&Vector3::new(0.3, 0.0, 0.0))
    }

    /// Closed form: |o + t r − c|² = ρ² with ρ = 0.5 · scale.
    fn analytic(ray: &Ray<f64>, scale: f64) -> Option<Vector3<f64>> {
        let c = centre(scale);
        let scale = 0.5 * scale;
        let oc = ray.origin - c;
        let b = oc.dot(&ray.dir);
        let disc = b * b - (oc.norm_squared() - scale * scale);
        (disc >= 0.0).then(|| ray.at(-b - disc.sqrt()))
    }

    #[test]
    fn sphere_tracing_a_rotated_scaled_sphere_matches_closed_form() {
        for scale in [0.15, 0.05, 2.0] {
            let obj = placed_sphere(scale);
            let tight = TraceParams {
                coarse_tol_rel: 1e-7,
                method: SurfaceMethod::SphereTrace { steps: 3 },
                max_iters: 2000,
            };
            let mut n = 0;
            for i in 0..40 {
                let aim = centre(scale) - Vector3::new(0.0, 0.0, 0.0);
                let dir = aim / aim.z
                    + Vector3::new(-0.6 + 0.03 * i as f64, 0.2 - 0.008 * i as f64, 0.0) * scale
                        / aim.z;
                let ray = Ray::new(Vector3::zeros(), dir);
                match (trace(&obj, &ray, &tight), analytic(&ray, scale)) {
                    (Some(h), Some(p)) => {
                        n += 1;
                        assert!(
                            (h.point - p).norm() < 1e-6 * scale,
                            "{:?} vs {p:?}",
                            h.point
                        );
                        let normal = (p - centre(scale)) / (0.5 * scale);
                        assert!((h.normal - normal).norm() < 1e-6);
                    }
                    (None, None) => {}
                    (a, b) => panic!("hit mismatch: traced {a:?}, closed form {b:?}"),
                }
            }
            assert!(n > 5);
        }
    }

    /// A unit sphere's distance within `band` of its surface, rising twice as fast beyond it
    /// (like a network trained on distances clamped at `band`), traced at most `max_step` a step.
    struct Steep {
        band: f64,
        max_step: f64,
        slope: f64,
    }

    impl Sdf for Steep {
        fn distance(&self, p: &Vector3<f64>) -> f64 {
            let x = p.norm() - 1.0;
            let x = if x > self.band {
                self.band + 2.0 * (x - self.band)
            } else {
                x
            };
            self.slope * x
        }
        fn bounding_radius(&self) -> f64 {
            3.0
        }
        fn max_step(&self) -> f64 {
            self.max_step
        }
    }

    #[test]
    fn a_field_steeper_than_a_distance_is_traced_to_its_surface() {
        // From (0, 0, −2.9) along +z: the sphere at t = 1.9.
        let (o, r) = (Vector3::new(0.0, 0.0, -2.9), Vector3::z());
        let tol = 1e-9;
        let capped = Steep {
            band: 0.1,
            max_step: 0.1,
            slope: 1.0,
        };
        let t = march(&capped, &o, &r, tol, 200).unwrap();
        assert!((t - 1.9).abs() < 1e-8, "{t}");
        // Uncapped, the march's first step (2.7) ends inside; bisection brings it back.
        let t = march(
            &Steep {
                max_step: f64::INFINITY,
                ..capped
            },
            &o,
            &r,
            tol,
            200,
        )
        .unwrap();
        assert!((t - 1.9).abs() < 1e-8, "{t}");
        // Steeper near the surface too (1.5 × a distance): every step overshoots.
        let steep = Steep {
            slope: 1.5,
            ..capped
        };
        let t = march(&steep, &o, &r, tol, 200).unwrap();
        assert!(
            (t - 1.9).abs() < 1e-8 && steep.distance(&(o + r * t)) >= 0.0,
            "{t}"
        );
    }

    #[test]
    fn three_steps_refine_and_projection_is_the_cruder_ablation() {
        let obj = placed_sphere(0.15);
        let ray = Ray::new(Vector3::zeros(), Vector3::new(0.05, 0.02, 1.0));
        let exact = analytic(&ray, 0.15).unwrap();
        let coarse = TraceParams {
            method: SurfaceMethod::SphereTrace { steps: 0 },
            ..TraceParams::default()
        };
        let err = |p: &TraceParams| (trace(&obj, &ray, p).unwrap().point - exact).norm();
        let e0 = err(&coarse);
        let e3 = err(&TraceParams::default());
        let eproj = err(&TraceParams {
            method: SurfaceMethod::GradientProjection,
            ..TraceParams::default()
        });
        assert!(e0 > 1e-4 && e3 < e0 * 1e-3, "coarse {e0}, K=3 {e3}");
        // The projection lands on the surface but off the ray.
        assert!(
            obj.distance(
                &trace(
                    &obj,
                    &ray,
                    &TraceParams {
                        method: SurfaceMethod::GradientProjection,
                        ..TraceParams::default()
                    }
                )
                .unwrap()
                .point
            )
            .abs()
                < 1e-9
        );
        assert!(eproj > e3, "projection {eproj} vs K=3 {e3}");
    }

    #[test]
    fn rays_see_the_inside_of_a_bowl_from_above() {
        // Bowl of radius 0.1 m, opening towards −Y of the depth frame (up in a camera with +Y down).
        let flip = axis_angle_to_matrix(&Vector3::new(std::f64::consts::PI, 0.0, 0.0));
        let bowl = PlacedSdf {
            sdf: Arc::new(Bowl {
                radius: 1.0,
                cut_height: 0.0,
                half_thickness: 0.02,
            }),
            depth_from_object: Similarity3::new(flip, Vector3::new(0.0, 0.0, 0.0), 0.1).unwrap(),
        };
        // Looking straight down (+Y in the depth frame) at the centre: hits the inner bottom.
        let ray = Ray::new(Vector3::new(0.0, -0.5, 0.0), Vector3::new(0.0, 1.0, 0.0));
        let h = trace(&bowl, &ray, &TraceParams::default()).unwrap();
        assert!((h.point.y - 0.098).abs() < 1e-4, "{:?}", h.point);
        assert!(
            h.normal.y < -0.99,
            "the inner surface faces the viewer: {:?}",
            h.normal
        );
        // A ray passing beside the bowl misses.
        assert!(
            trace(
                &bowl,
                &Ray::new(Vector3::new(0.2, -0.5, 0.0), Vector3::new(0.0, 1.0, 0.0)),
                &TraceParams::default()
            )
            .is_none()
        );
    }
}
