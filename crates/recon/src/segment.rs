//! Object segmentation when the capture gives no masks: depth → points → support plane →
//! Euclidean clustering of the points above it (neighbouring pixels join when their 3-D points
//! are closer than a range-dependent tolerance) → one depth-pixel mask per object.

use crate::plane::Plane;
use irmirror_capture::Image;
use irmirror_geom::PinholeCamera;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Segmentation settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SegmentConfig {
    /// Points at least this high above the plane are object candidates, metres.
    pub min_height_m: f64,
    /// … and at most this high (people and walls are not objects), metres.
    pub max_height_m: f64,
    /// Neighbouring points closer than `join_m + join_rel · depth` belong together, metres.
    pub join_m: f64,
    /// Range-proportional part of the joining distance.
    pub join_rel: f64,
    /// Clusters smaller than this are dropped, pixels.
    pub min_pixels: usize,
}

impl Default for SegmentConfig {
    fn default() -> Self {
        Self { min_height_m: 0.008, max_height_m: 2.5, join_m: 0.006, join_rel: 0.01, min_pixels: 40 }
    }
}

/// Depth-frame point of every valid depth pixel.
pub fn depth_points(depth_m: &Image<f32>, camera: &PinholeCamera) -> Vec<Option<Vector3<f64>>> {
    let w = depth_m.width;
    depth_m
        .data
        .iter()
        .enumerate()
        .map(|(i, &z)| (z.is_finite() && z > 0.0).then(|| camera.unproject((i as u32 % w) as f64 + 0.5, (i as u32 / w) as f64 + 0.5, f64::from(z))))
        .collect()
}

/// Clusters of points above `plane`, largest first, as depth-pixel masks. Pixels in `exclude`
/// (objects with given masks) are left out.
pub fn segment(points: &[Option<Vector3<f64>>], width: u32, height: u32, plane: &Plane, exclude: &[bool], cfg: &SegmentConfig) -> Vec<Image<bool>> {
    let (w, h) = (width as usize, height as usize);
    let candidate: Vec<bool> = points
        .iter()
        .zip(exclude)
        .map(|(p, &ex)| !ex && p.is_some_and(|p| (cfg.min_height_m..cfg.max_height_m).contains(&plane.height(&p))))
        .collect();
    // Union–find over 8-neighbours.
    let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !candidate[i] {
                continue;
            }
            let p = points[i].expect("candidate has a point");
            for (dx, dy) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let j = ny as usize * w + nx as usize;
                if !candidate[j] {
                    continue;
                }
                let q = points[j].expect("candidate has a point");
                if (p - q).norm() < cfg.join_m + cfg.join_rel * p.z.min(q.z) {
                    let (a, b) = (find(&mut parent, i as u32), find(&mut parent, j as u32));
                    if a != b {
                        parent[a.max(b) as usize] = a.min(b);
                    }
                }
            }
        }
    }
    let mut members: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for i in 0..w * h {
        if candidate[i] {
            let r = find(&mut parent, i as u32);
            members.entry(r).or_default().push(i);
        }
    }
    let mut clusters: Vec<Vec<usize>> = members.into_values().filter(|m| m.len() >= cfg.min_pixels).collect();
    clusters.sort_by(|a, b| b.len().cmp(&a.len()).then(a[0].cmp(&b[0])));
    clusters
        .into_iter()
        .map(|m| {
            let mut img = Image::filled(width, height, false);
            for i in m {
                img.data[i] = true;
            }
            img
        })
        .collect()
}
