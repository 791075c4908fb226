//! A fit's rendered depth along one camera ray, and its rendered outline against its mask:
//! every mask pixel's and every ring pixel's camera ray traced into a fit. The loss sees the
//! ring only through a few fixed samples along a subsample of its rays, which a thin part (a
//! mug's 1 cm handle tube, a shallow bowl's rim) can fall between; the count of pixels a fit's
//! outline gets wrong does not.

use irmirror_capture::Image;
use irmirror_geom::{PinholeCamera, Similarity3};
use irmirror_render::sdf::Sdf;
use irmirror_render::sphere_trace::march;
use nalgebra::Vector3;

/// Sphere-traces the unit ray `d` from `o` (both in the object frame) into `sdf`: the hit
/// distance (object units), or `None` on a miss. Marches to 1e-7 object units (a depth error
/// far below the sensor's), 200 steps at most.
pub(super) fn render_depth(sdf: &dyn Sdf, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    march(sdf, o, d, 1e-7, 200)
}

/// One depth pixel's camera ray (depth frame, from the camera's centre).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SilhouetteRay {
    /// Unit direction.
    pub dir: Vector3<f64>,
    /// Where the camera saw a surface along it (metres along `dir`), if it did.
    pub seen_m: Option<f64>,
    /// Inside the object's mask (the fit should be hit) or in the ring around it (the fit must
    /// not stand in front of what the camera saw).
    pub inside: bool,
}

/// The rays of the mask's pixels with a valid depth and of the ring's pixels (`ring` minus the
/// mask).
pub fn silhouette_rays(
    depth_m: &Image<f32>,
    camera: &PinholeCamera,
    mask: &Image<bool>,
    ring: &Image<bool>,
) -> Vec<SilhouetteRay> {
    let w = depth_m.width;
    (0..depth_m.data.len())
        .filter_map(|i| {
            let (inside, around) = (mask.data[i], ring.data[i]);
            let z = f64::from(depth_m.data[i]);
            let valid = z.is_finite() && z > 0.0;
            if !(inside && valid || around && !inside) {
                return None;
            }
            let (u, v) = ((i as u32 % w) as f64 + 0.5, (i as u32 / w) as f64 + 0.5);
            let at = camera.unproject(u, v, if valid { z } else { 1.0 });
            let dir = at.normalize();
            Some(SilhouetteRay {
                dir,
                seen_m: valid.then(|| at.norm()),
                inside,
            })
        })
        .collect()
}

/// How many of `rays` the object `sdf` placed by `sim` gets wrong: a mask ray that misses it,
/// or a ring ray that meets it more than `margin_m` in front of what the camera saw there (any
/// meeting where the camera saw nothing).
pub fn outline_errors(
    sdf: &dyn Sdf,
    sim: &Similarity3<f64>,
    rays: &[SilhouetteRay],
    margin_m: f64,
) -> usize {
    let camera = sim.inverse_transform_point(&Vector3::zeros());
    rays.iter()
        .filter(|ray| {
            let hit =
                render_depth(sdf, &camera, &sim.rotation.tr_mul(&ray.dir)).map(|t| t * sim.scale);
            match (ray.inside, hit, ray.seen_m) {
                (true, hit, _) => hit.is_none(),
                (false, Some(t), Some(seen)) => t < seen - margin_m,
                (false, Some(_), None) => true,
                (false, None, _) => false,
            }
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::Family;
    use crate::objects::loss::State;
    use irmirror_geom::rotation::axis_angle_to_matrix;
    use irmirror_render::sdf::Sphere;

    /// Rendered depth of a placed unit sphere against the closed-form ray–sphere intersection,
    /// for rays hitting it (centre, off-centre) and missing it.
    #[test]
    fn rendered_depth_is_the_ray_sphere_intersection() {
        let st = State {
            rotation: axis_angle_to_matrix(&Vector3::new(0.3, -0.2, 0.5)),
            translation: Vector3::new(0.05, -0.02, 0.8),
            log_scale: 0.1f64.ln(),
            u: [0.0; 2],
        };
        let sdf = Family::Sphere.shape(&[]).sdf();
        let s = st.log_scale.exp();
        let camera = st.rotation.tr_mul(&(-st.translation)) / s;
        for (k, target) in [
            Vector3::new(0.05, -0.02, 0.8),
            Vector3::new(0.12, 0.03, 0.8),
            Vector3::new(-0.2, 0.0, 0.8),
        ]
        .iter()
        .enumerate()
        {
            let ray = target.normalize();
            let (c, r) = (st.translation, 0.1);
            let b = ray.dot(&c);
            let disc = b * b - (c.norm_squared() - r * r);
            let got = render_depth(sdf.as_ref(), &camera, &st.rotation.tr_mul(&ray));
            if disc < 0.0 {
                assert!(
                    got.is_none(),
                    "ray {k} misses the sphere but rendered {got:?}"
                );
            } else {
                let t = got.unwrap_or_else(|| panic!("ray {k} hits the sphere")) * s;
                assert!(
                    (t - (b - disc.sqrt())).abs() < 1e-7 && ((ray * t - c).norm() - r).abs() < 1e-7,
                    "ray {k}: t {t}, closed form {}",
                    b - disc.sqrt()
                );
            }
        }
    }

    /// A unit sphere 1 m ahead, scaled to 0.1 m: a ray through its centre is inside, one 0.2 m
    /// off misses it; a ring ray that meets it in front of a farther surface is an error, one
    /// whose surface is nearer than the sphere is not.
    #[test]
    fn outline_errors_count_misses_and_occluders() {
        let sphere = Sphere { radius: 1.0 };
        let sim = Similarity3::new(
            nalgebra::Matrix3::identity(),
            Vector3::new(0.0, 0.0, 1.0),
            0.1,
        )
        .unwrap();
        let ray = |x: f64, seen_m: Option<f64>, inside: bool| SilhouetteRay {
            dir: Vector3::new(x, 0.0, 1.0).normalize(),
            seen_m,
            inside,
        };
        let count = |rays: &[SilhouetteRay]| outline_errors(&sphere, &sim, rays, 0.01);
        assert_eq!(count(&[ray(0.0, Some(0.9), true)]), 0);
        assert_eq!(count(&[ray(0.2, Some(2.0), true)]), 1);
        assert_eq!(count(&[ray(0.05, Some(2.0), false)]), 1);
        assert_eq!(count(&[ray(0.05, None, false)]), 1);
        assert_eq!(count(&[ray(0.05, Some(0.9), false)]), 0);
        assert_eq!(count(&[ray(0.2, None, false)]), 0);
    }
}
