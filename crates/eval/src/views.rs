//! What reports show: fitted meshes, posed bodies of stage-2 states, reflection overlays, and
//! ray-cast views of bodies and objects from a calibrated camera.

use crate::EvalError;
use image::{Rgb, RgbImage};
use irmirror_capture::Image;
use irmirror_geom::{PinholeCamera, Rigid3, TriMesh};
use irmirror_recon::objects::FittedObject;
use irmirror_render::bvh::Bvh;
use irmirror_render::hard::first_hit;
use irmirror_render::sdf::PlacedSdf;
use irmirror_render::sphere_trace::{TraceParams, trace};
use nalgebra::Vector3;

/// A fitted object's surface as a mesh in the depth frame (marching tetrahedra, 64³).
pub fn object_mesh(obj: &FittedObject) -> Result<TriMesh, EvalError> {
    Ok(obj.mesh(64)?)
}

/// Observed (green) vs fitted (magenta; white where both) reflection over the rise image,
/// upscaled 4×.
pub fn overlay(rise_k: &Image<f64>, observed: &Image<bool>, fitted: &[bool]) -> RgbImage {
    let max = rise_k.data.iter().copied().fold(1e-9, f64::max);
    let (w, h) = (rise_k.width, rise_k.height);
    let k = 4;
    RgbImage::from_fn(w * k, h * k, |x, y| {
        let i = ((y / k) * w + x / k) as usize;
        let g = (rise_k.data[i].max(0.0) / max * 160.0) as u8;
        match (observed.data[i], fitted[i]) {
            (true, true) => Rgb([255, 255, 255]),
            (true, false) => Rgb([40, 220, 60]),
            (false, true) => Rgb([230, 40, 220]),
            _ => Rgb([g, g, g]),
        }
    })
}

/// A body mesh to draw, depth frame.
pub struct Drawn<'a> {
    /// Vertices.
    pub vertices: &'a [Vector3<f64>],
    /// Triangles.
    pub triangles: &'a [[u32; 3]],
    /// Base colour.
    pub colour: [u8; 3],
}

/// Ray-casts bodies and objects from a calibrated camera (Lambert shading from the eye).
pub fn render_view(
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    bodies: &[Drawn<'_>],
    objects: &[PlacedSdf],
) -> RgbImage {
    use rayon::prelude::*;
    let bvhs: Vec<Bvh<f64>> = bodies
        .iter()
        .map(|b| Bvh::build(b.vertices, b.triangles))
        .collect();
    let tp = TraceParams {
        coarse_tol_rel: 1.0 / 256.0,
        ..TraceParams::default()
    };
    let (w, h) = (camera.width, camera.height);
    let px: Vec<[u8; 3]> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let ray = depth_from_camera.transform_ray(&camera.pixel_ray::<f64>(p % w, p / w));
            let mut best: Option<(f64, f64, [u8; 3])> = None;
            for (b, bvh) in bodies.iter().zip(&bvhs) {
                if let Some((t, tri)) =
                    first_hit(bvh, b.vertices, b.triangles, &ray.origin, &ray.dir)
                {
                    let [i, j, k] = b.triangles[tri as usize].map(|x| x as usize);
                    let n = (b.vertices[j] - b.vertices[i])
                        .cross(&(b.vertices[k] - b.vertices[i]))
                        .normalize();
                    if best.is_none_or(|x| t < x.0) {
                        best = Some((t, n.dot(&ray.dir).abs(), b.colour));
                    }
                }
            }
            for o in objects {
                if let Some(hit) = trace(o, &ray, &tp) {
                    let t = (hit.point - ray.origin).norm();
                    if best.is_none_or(|x| t < x.0) {
                        best = Some((t, hit.normal.dot(&ray.dir).abs(), [150, 170, 200]));
                    }
                }
            }
            match best {
                Some((_, lambert, c)) => c.map(|v| (f64::from(v) * (0.35 + 0.65 * lambert)) as u8),
                None => [245, 245, 245],
            }
        })
        .collect();
    RgbImage::from_fn(w, h, |x, y| Rgb(px[(y * w + x) as usize]))
}
