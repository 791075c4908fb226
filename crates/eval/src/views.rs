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

/// The bounding box `[x0, y0, x1, y1]` (inclusive) of the largest 8-connected piece of `mask`
/// (`w × h`, row-major): the person's reflection, not a rim's streak. The whole image when the
/// mask is empty.
pub fn largest_piece_box(mask: &[bool], w: u32, h: u32) -> [u32; 4] {
    let mut seen = vec![false; (w * h) as usize];
    let mut best: Option<(usize, [u32; 4])> = None;
    for start in 0..w * h {
        if !mask[start as usize] || seen[start as usize] {
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
                if mask[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j as u32);
                }
            }
        }
        if best.is_none_or(|(m, _)| n > m) {
            best = Some((n, b));
        }
    }
    best.map_or([0, 0, w - 1, h - 1], |(_, b)| b)
}

/// The reflection enlarged (nearest neighbour): the box around the largest piece of observed ∪
/// fitted, 3 pixels around, ≈ 240 pixels high, in three panels separated by black bars: the
/// observed mask (green) over the rise, the fitted one (magenta), both (white where they agree).
pub fn reflection_zoom(rise_k: &Image<f64>, observed: &Image<bool>, fitted: &[bool]) -> RgbImage {
    let (w, h) = (rise_k.width, rise_k.height);
    let union: Vec<bool> = observed
        .data
        .iter()
        .zip(fitted)
        .map(|(a, b)| *a || *b)
        .collect();
    let crop = padded(largest_piece_box(&union, w, h), w, h);
    let [x0, y0, x1, y1] = crop;
    let peak = (y0..=y1)
        .flat_map(|y| (x0..=x1).map(move |x| (y * w + x) as usize))
        .map(|i| rise_k.data[i])
        .fold(1e-9, f64::max);
    three_panels(crop, w, 300, |panel, i| {
        let g = (rise_k.data[i].max(0.0) / peak * 160.0) as u8;
        match (panel, observed.data[i], fitted[i]) {
            (0, true, _) | (2, true, false) => Rgb([40, 220, 60]),
            (1, _, true) | (2, false, true) => Rgb([230, 40, 220]),
            (2, true, true) => Rgb([255, 255, 255]),
            _ => Rgb([g, g, g]),
        }
    })
}

/// `bx` grown by 3 pixels on every side, inside the `w × h` image.
fn padded([x0, y0, x1, y1]: [u32; 4], w: u32, h: u32) -> [u32; 4] {
    let pad = 3;
    [
        x0.saturating_sub(pad),
        y0.saturating_sub(pad),
        (x1 + pad).min(w - 1),
        (y1 + pad).min(h - 1),
    ]
}

/// Three panels of the image region `crop` (inclusive box; image width `w`) side by side,
/// enlarged by nearest neighbour to ≈ 240 pixels high and at most `max_w` wide each, separated
/// by 4-pixel black bars; `pixel(panel, i)` colours image pixel `i` in a panel.
fn three_panels(
    [x0, y0, x1, y1]: [u32; 4],
    w: u32,
    max_w: u32,
    pixel: impl Fn(u32, usize) -> Rgb<u8>,
) -> RgbImage {
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let k = (240 / ch).clamp(1, 24).min((max_w / cw).max(1));
    let (gap, pw) = (4, cw * k);
    RgbImage::from_fn(3 * pw + 2 * gap, ch * k, |x, y| {
        let panel = x / (pw + gap);
        let xin = x % (pw + gap);
        if xin >= pw {
            return Rgb([0, 0, 0]);
        }
        pixel(panel, ((y0 + y / k) * w + x0 + xin / k) as usize)
    })
}

/// `img` in grey, stretched between its 1st and 99th percentiles inside `region`
/// ([`irmirror_capture::image_io::stretch_percentiles`]).
pub fn stretched(img: &Image<f64>, region: &Image<bool>) -> RgbImage {
    let g = irmirror_capture::image_io::stretch_percentiles(img, region);
    RgbImage::from_fn(g.width, g.height, |x, y| {
        let v = g.data[(y * g.width + x) as usize];
        Rgb([v, v, v])
    })
}

/// The depth image's edges drawn over the thermal frame: every depth pixel next to a jump of
/// more than 3 % in depth (an object's outline, the table's edge) is lifted to 3-D, moved into
/// the thermal camera by `depth_from_thermal` and marked red (the near side of the jump). With a
/// right calibration the red outlines sit on the thermal image's own outlines; a wrong
/// extrinsic or focal length shows as a shift or a scale at a glance.
pub fn depth_edges_on_thermal(
    thermal_k: &Image<f64>,
    depth_m: &Image<f32>,
    depth_camera: &PinholeCamera,
    thermal_camera: &PinholeCamera,
    depth_from_thermal: &Rigid3<f64>,
) -> RgbImage {
    let all = Image::filled(thermal_k.width, thermal_k.height, true);
    let mut img = stretched(thermal_k, &all);
    let thermal_from_depth = depth_from_thermal.inverse();
    let (w, h) = (depth_m.width, depth_m.height);
    let z = |c: u32, r: u32| f64::from(depth_m.data[(r * w + c) as usize]);
    // A depth pixel covers about this many thermal pixels a side: mark them all, so that the
    // outline is a line, not dots.
    let side = (thermal_camera.fx / depth_camera.fx)
        .round()
        .clamp(1.0, 8.0) as i64;
    for r in 0..h {
        for c in 0..w {
            let zc = z(c, r);
            if !zc.is_finite() {
                continue;
            }
            let edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|&(dc, dr)| {
                    let (cc, rr) = (i64::from(c) + dc, i64::from(r) + dr);
                    if cc < 0 || rr < 0 || cc >= i64::from(w) || rr >= i64::from(h) {
                        return false;
                    }
                    let zn = z(cc as u32, rr as u32);
                    // The far side of a jump, or a hole, counts on the near side only.
                    !zn.is_finite() || zn > zc * 1.03
                });
            if !edge {
                continue;
            }
            let p = depth_camera.unproject(f64::from(c) + 0.5, f64::from(r) + 0.5, zc);
            if let Some((u, v)) = thermal_camera.project(&thermal_from_depth.transform_point(&p)) {
                for dy in 0..side {
                    for dx in 0..side {
                        let (x, y) = (
                            (u - side as f64 / 2.0).floor() as i64 + dx,
                            (v - side as f64 / 2.0).floor() as i64 + dy,
                        );
                        if x >= 0
                            && y >= 0
                            && x < i64::from(img.width())
                            && y < i64::from(img.height())
                        {
                            img.put_pixel(x as u32, y as u32, Rgb([255, 40, 40]));
                        }
                    }
                }
            }
        }
    }
    img
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
    let crop = padded(largest_piece_box(&mask.data, w, h), w, h);
    three_panels(crop, w, 400, |panel, i| {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(w: u32, h: u32, on: &[(u32, u32)]) -> Image<bool> {
        let mut m = Image::filled(w, h, false);
        for &(x, y) in on {
            m.data[(y * w + x) as usize] = true;
        }
        m
    }

    #[test]
    fn the_largest_piece_is_boxed() {
        // A 2-pixel streak and a 4-pixel blob (diagonal neighbours join it).
        let m = mask(
            20,
            10,
            &[(1, 1), (2, 1), (10, 5), (11, 6), (12, 6), (12, 7)],
        );
        assert_eq!(largest_piece_box(&m.data, 20, 10), [10, 5, 12, 7]);
        assert_eq!(largest_piece_box(&[false; 200], 20, 10), [0, 0, 19, 9]);
    }

    /// The zoom crops around observed ∪ fitted, enlarges by an integer factor and colours each
    /// panel's pixels by what it shows.
    #[test]
    fn reflection_zoom_shows_observed_fitted_and_both() {
        let (w, h) = (64, 48);
        let observed = mask(w, h, &[(30, 20), (31, 20)]);
        let fitted = mask(w, h, &[(31, 20), (32, 20)]).data;
        let rise = Image::filled(w, h, 0.0);
        let z = reflection_zoom(&rise, &observed, &fitted);
        // Box x 30–32, y 20–20, 3 pixels around: 9 × 7 pixels, enlarged 24×.
        let (cw, ch, k) = (9, 7, 24);
        assert_eq!((z.width(), z.height()), (3 * cw * k + 8, ch * k));
        let at = |panel: u32, x: u32, y: u32| {
            z.get_pixel(
                panel * (cw * k + 4) + (x - 27) * k + k / 2,
                (y - 17) * k + k / 2,
            )
            .0
        };
        assert_eq!(at(0, 30, 20), [40, 220, 60]);
        assert_eq!(
            at(0, 32, 20),
            [0, 0, 0],
            "panel 0 shows the observed mask only"
        );
        assert_eq!(at(1, 32, 20), [230, 40, 220]);
        assert_eq!(at(2, 30, 20), [40, 220, 60]);
        assert_eq!(at(2, 31, 20), [255, 255, 255]);
        assert_eq!(at(2, 32, 20), [230, 40, 220]);
    }
}
