//! Object segmentation when the capture gives no masks: depth → points → support plane →
//! Euclidean clustering of the points above it (neighbouring pixels join when their 3-D points
//! are closer than a range-dependent tolerance, and any two points join when they are that
//! close seen from above the plane) → one depth-pixel mask per object. Objects that
//! touch join into one cluster; when the capture names more objects than there are clusters,
//! [`split`] divides the largest.

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
        Self {
            min_height_m: 0.008,
            max_height_m: 2.5,
            join_m: 0.006,
            join_rel: 0.01,
            min_pixels: 40,
        }
    }
}

/// Depth-frame point of every valid depth pixel.
pub fn depth_points(depth_m: &Image<f32>, camera: &PinholeCamera) -> Vec<Option<Vector3<f64>>> {
    let w = depth_m.width;
    depth_m
        .data
        .iter()
        .enumerate()
        .map(|(i, &z)| {
            (z.is_finite() && z > 0.0).then(|| {
                camera.unproject(
                    (i as u32 % w) as f64 + 0.5,
                    (i as u32 / w) as f64 + 0.5,
                    f64::from(z),
                )
            })
        })
        .collect()
}

/// Clusters of points above `plane`, largest first, as depth-pixel masks. Pixels in `exclude`
/// (objects with given masks) are left out.
pub fn segment(
    points: &[Option<Vector3<f64>>],
    width: u32,
    height: u32,
    plane: &Plane,
    exclude: &[bool],
    cfg: &SegmentConfig,
) -> Vec<Image<bool>> {
    let (w, h) = (width as usize, height as usize);
    let candidate: Vec<bool> = points
        .iter()
        .zip(exclude)
        .map(|(p, &ex)| {
            !ex && p
                .is_some_and(|p| (cfg.min_height_m..cfg.max_height_m).contains(&plane.height(&p)))
        })
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
    // Pieces of one object the image separates — a bowl's near outer wall is cut from its
    // inside by the rim's depth jump — overlap seen from above: join candidates whose positions
    // across the plane are within `join_m` (objects stand side by side, not stacked). Buckets
    // of `join_m` on the plane; neighbouring buckets are compared point by point.
    let n = plane.n();
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let e1 = (helper - n * n.dot(&helper)).normalize();
    let e2 = n.cross(&e1);
    let cell = |p: &Vector3<f64>| {
        (
            (e1.dot(p) / cfg.join_m).floor() as i64,
            (e2.dot(p) / cfg.join_m).floor() as i64,
        )
    };
    let mut buckets: std::collections::HashMap<(i64, i64), Vec<u32>> = Default::default();
    for (i, p) in points.iter().enumerate() {
        if candidate[i] {
            buckets
                .entry(cell(&p.expect("candidate has a point")))
                .or_default()
                .push(i as u32);
        }
    }
    let mut keys: Vec<(i64, i64)> = buckets.keys().copied().collect();
    keys.sort_unstable();
    for &(cx, cy) in &keys {
        for (dx, dy) in [(0i64, 0i64), (1, 0), (0, 1), (1, 1), (-1, 1)] {
            let (Some(a), Some(b)) = (buckets.get(&(cx, cy)), buckets.get(&(cx + dx, cy + dy)))
            else {
                continue;
            };
            for &i in a {
                let pi = points[i as usize].expect("candidate");
                let (ui, vi) = (e1.dot(&pi), e2.dot(&pi));
                for &j in b {
                    if find(&mut parent, i) == find(&mut parent, j) {
                        continue;
                    }
                    let pj = points[j as usize].expect("candidate");
                    if (ui - e1.dot(&pj)).hypot(vi - e2.dot(&pj)) < cfg.join_m {
                        let (ra, rb) = (find(&mut parent, i), find(&mut parent, j));
                        parent[ra.max(rb) as usize] = ra.min(rb);
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
    let mut clusters: Vec<Vec<usize>> = members
        .into_values()
        .filter(|m| m.len() >= cfg.min_pixels)
        .collect();
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

/// Splits a cluster of touching objects in two: 2-means on the points' positions across the
/// support plane (objects stand side by side on it; they are not stacked), started from the two
/// extremes along the cluster's principal horizontal axis. Returns `None` for a cluster too small
/// to hold two objects of `min_pixels` each.
pub fn split(
    points: &[Option<Vector3<f64>>],
    cluster: &Image<bool>,
    plane: &Plane,
    cfg: &SegmentConfig,
) -> Option<(Image<bool>, Image<bool>)> {
    let n = plane.n();
    let flat = |p: &Vector3<f64>| p - n * n.dot(p);
    let idx: Vec<usize> = (0..cluster.data.len())
        .filter(|&i| cluster.data[i] && points[i].is_some())
        .collect();
    if idx.len() < 2 * cfg.min_pixels {
        return None;
    }
    let q: Vec<Vector3<f64>> = idx
        .iter()
        .map(|&i| flat(&points[i].expect("filtered")))
        .collect();
    let mean = q.iter().sum::<Vector3<f64>>() / q.len() as f64;
    let cov = q.iter().fold(nalgebra::Matrix3::zeros(), |c, p| {
        c + (p - mean) * (p - mean).transpose()
    });
    let eig = cov.symmetric_eigen();
    let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    let along: Vec<f64> = q.iter().map(|p| axis.dot(&(p - mean))).collect();
    let pick = |f: fn(f64, f64) -> bool| {
        (0..q.len())
            .reduce(|a, b| if f(along[b], along[a]) { b } else { a })
            .expect("non-empty")
    };
    let mut centres = [q[pick(|a, b| a < b)], q[pick(|a, b| a > b)]];
    let mut label = vec![false; q.len()];
    for _ in 0..50 {
        let next: Vec<bool> = q
            .iter()
            .map(|p| (p - centres[1]).norm_squared() < (p - centres[0]).norm_squared())
            .collect();
        let changed = next != label;
        label = next;
        for (k, c) in centres.iter_mut().enumerate() {
            let members: Vec<&Vector3<f64>> = q
                .iter()
                .zip(&label)
                .filter(|(_, l)| **l == (k == 1))
                .map(|(p, _)| p)
                .collect();
            if !members.is_empty() {
                *c = members.iter().copied().sum::<Vector3<f64>>() / members.len() as f64;
            }
        }
        if !changed {
            break;
        }
    }
    let count = label.iter().filter(|&&l| l).count();
    if count < cfg.min_pixels || q.len() - count < cfg.min_pixels {
        return None;
    }
    let (mut a, mut b) = (
        Image::filled(cluster.width, cluster.height, false),
        Image::filled(cluster.width, cluster.height, false),
    );
    for (&i, &l) in idx.iter().zip(&label) {
        if l {
            b.data[i] = true
        } else {
            a.data[i] = true
        }
    }
    Some((a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two discs of points side by side, touching, on the plane y = 0 seen from above: one
    /// cluster, split into the two discs exactly.
    #[test]
    fn split_separates_two_touching_discs() {
        let (w, h) = (80u32, 40u32);
        let plane = Plane {
            normal: [0.0, -1.0, 0.0],
            offset_m: 0.0,
            inlier_fraction: 1.0,
        };
        let mut points = vec![None; (w * h) as usize];
        let mut cluster = Image::filled(w, h, false);
        let mut truth = vec![0u8; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                // A 2 mm grid in the plane (x, z); discs of radius 38 mm centred 76 mm apart.
                let p = Vector3::new(f64::from(x) * 0.002, -0.01, f64::from(y) * 0.002);
                let i = (y * w + x) as usize;
                for (k, cx) in [(1u8, 0.039), (2u8, 0.115)] {
                    if (p.x - cx).hypot(p.z - 0.039) <= 0.038 {
                        points[i] = Some(p);
                        cluster.data[i] = true;
                        truth[i] = k;
                    }
                }
            }
        }
        let cfg = SegmentConfig::default();
        // The discs touch: segmentation alone sees one object.
        assert_eq!(
            segment(&points, w, h, &plane, &vec![false; points.len()], &cfg).len(),
            1
        );
        let (a, b) = split(&points, &cluster, &plane, &cfg).expect("two halves");
        let label_of = |m: &Image<bool>| {
            (0..truth.len())
                .filter(|&i| m.data[i])
                .map(|i| truth[i])
                .collect::<std::collections::BTreeSet<u8>>()
        };
        let (la, lb) = (label_of(&a), label_of(&b));
        assert!(
            la.len() == 1 && lb.len() == 1 && la != lb,
            "halves mix the discs: {la:?} {lb:?}"
        );
        let sizes = (
            a.data.iter().filter(|&&v| v).count(),
            b.data.iter().filter(|&&v| v).count(),
        );
        assert_eq!(sizes.0 + sizes.1, truth.iter().filter(|&&t| t > 0).count());
        // Too small to hold two objects: no split.
        let tiny = SegmentConfig {
            min_pixels: sizes.0.max(sizes.1) + 1,
            ..cfg
        };
        assert!(split(&points, &cluster, &plane, &tiny).is_none());
    }
}
