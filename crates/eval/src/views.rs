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

/// Observed rise, fitted rise and their residual side by side, cropped to the reflection (the
/// mask's largest connected piece, 3 pixels around) and enlarged
/// by nearest neighbour to ≈ 240 pixels high. Rises share one grey scale (0 to the observed
/// peak); the residual (observed − fitted) is blue (negative) – white – red (positive) over
/// ± half the peak. Separated by 4-pixel black bars.
pub fn rise_panels(observed: &Image<f64>, fitted: &Image<f64>, mask: &Image<bool>) -> RgbImage {
    let (w, h) = (observed.width, observed.height);
    let peak = observed
        .data
        .iter()
        .zip(&mask.data)
        .filter(|(_, m)| **m)
        .map(|(r, _)| *r)
        .fold(1e-9, f64::max);
    // The bounding box of the mask's largest 8-connected piece (the person; a rim's streak is
    // another piece).
    let mut seen = vec![false; (w * h) as usize];
    let mut best: Option<(usize, [u32; 4])> = None;
    for start in 0..w * h {
        if !mask.data[start as usize] || seen[start as usize] {
            continue;
        }
        let (mut stack, mut n, mut b) = (vec![start], 0, [w, h, 0, 0]);
        seen[start as usize] = true;
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            n += 1;
            b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let j = (ny as u32 * w + nx as u32) as usize;
                if mask.data[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j as u32);
                }
            }
        }
        if best.is_none_or(|(m, _)| n > m) {
            best = Some((n, b));
        }
    }
    let [x0, y0, x1, y1] = best.map_or([0, 0, w - 1, h - 1], |(_, b)| b);
    let pad = 3;
    let (x0, y0) = (x0.saturating_sub(pad), y0.saturating_sub(pad));
    let (x1, y1) = ((x1 + pad).min(w - 1), (y1 + pad).min(h - 1));
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let k = (240 / ch).clamp(1, 24).min((400 / cw).max(1));
    let gap = 4;
    let pw = cw * k;
    RgbImage::from_fn(3 * pw + 2 * gap, ch * k, |x, y| {
        let panel = x / (pw + gap);
        let xin = x % (pw + gap);
        if xin >= pw {
            return Rgb([0, 0, 0]);
        }
        let i = ((y0 + y / k) * w + x0 + xin / k) as usize;
        let grey = |v: f64| {
            let g = (v.max(0.0) / peak * 255.0).min(255.0) as u8;
            Rgb([g, g, g])
        };
        match panel {
            0 => grey(observed.data[i]),
            1 => grey(fitted.data[i]),
            _ => {
                let r = ((observed.data[i] - fitted.data[i]) / (0.5 * peak)).clamp(-1.0, 1.0);
                let f = |t: f64| (255.0 * (1.0 - t.abs())) as u8;
                if r >= 0.0 {
                    Rgb([255, f(r), f(r)])
                } else {
                    Rgb([f(r), f(r), 255])
                }
            }
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
