//! A small orthographic z-buffer rasteriser for previews (body sheets, report thumbnails).
//! Not the reflection renderer: that lives in the `render` crate.

use crate::TriMesh;
use image::{Rgb, RgbImage};
use nalgebra::{Matrix3, Vector3};

/// Renders `mesh` seen along `view_from_mesh` (view axes: +X right, +Y down, camera looks along
/// +Z), orthographically, fitted into a `size`×`size` image with a margin. Returns a shaded
/// image: Lambertian grey by facing ratio, white background.
pub fn render_orthographic(mesh: &TriMesh, view_from_mesh: &Matrix3<f32>, size: u32) -> RgbImage {
    let pts: Vec<Vector3<f32>> = mesh
        .vertices
        .iter()
        .map(|v| view_from_mesh * Vector3::from(*v))
        .collect();
    let mut img = RgbImage::from_pixel(size, size, Rgb([255, 255, 255]));
    if pts.is_empty() {
        return img;
    }
    let (mut lo, mut hi) = (pts[0], pts[0]);
    for p in &pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi.x - lo.x).max(hi.y - lo.y).max(1e-6);
    let scale = 0.9 * size as f32 / extent;
    let centre = (lo + hi) * 0.5;
    let to_px = |p: &Vector3<f32>| {
        let half = size as f32 / 2.0;
        (
            (p.x - centre.x) * scale + half,
            (p.y - centre.y) * scale + half,
            p.z,
        )
    };
    let mut zbuf = vec![f32::INFINITY; (size * size) as usize];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| pts[i as usize]);
        let n = (b - a).cross(&(c - a));
        let len = n.norm();
        if len == 0.0 {
            continue;
        }
        // Facing the viewer means the normal points toward −Z.
        let shade = (-n.z / len).abs();
        let grey = (60.0 + 180.0 * shade) as u8;
        let [pa, pb, pc] = [to_px(&a), to_px(&b), to_px(&c)];
        let xmin = pa.0.min(pb.0).min(pc.0).floor().max(0.0) as u32;
        let xmax = (pa.0.max(pb.0).max(pc.0).ceil() as u32).min(size - 1);
        let ymin = pa.1.min(pb.1).min(pc.1).floor().max(0.0) as u32;
        let ymax = (pa.1.max(pb.1).max(pc.1).ceil() as u32).min(size - 1);
        let area = (pb.0 - pa.0) * (pc.1 - pa.1) - (pb.1 - pa.1) * (pc.0 - pa.0);
        if area.abs() < 1e-12 {
            continue;
        }
        for y in ymin..=ymax {
            for x in xmin..=xmax {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let w0 = ((pb.0 - px) * (pc.1 - py) - (pb.1 - py) * (pc.0 - px)) / area;
                let w1 = ((pc.0 - px) * (pa.1 - py) - (pc.1 - py) * (pa.0 - px)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * pa.2 + w1 * pb.2 + w2 * pc.2;
                let k = (y * size + x) as usize;
                if z < zbuf[k] {
                    zbuf[k] = z;
                    img.put_pixel(x, y, Rgb([grey, grey, grey]));
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::unit_cube;

    #[test]
    fn cube_fills_the_centre_and_not_the_corners() {
        let img = render_orthographic(&unit_cube(), &Matrix3::identity(), 64);
        assert_ne!(img.get_pixel(32, 32), &Rgb([255, 255, 255]));
        assert_eq!(img.get_pixel(0, 0), &Rgb([255, 255, 255]));
        // A face seen head-on is shaded brightest.
        assert_eq!(img.get_pixel(32, 32), &Rgb([240, 240, 240]));
    }
}
