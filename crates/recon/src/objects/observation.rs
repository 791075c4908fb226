//! What one object's fit sees: the depth points inside its mask, and free-space points in front
//! of them and along the rays of a ring of pixels around the mask.

use super::ObjectConfig;
use super::silhouette::{SilhouetteRay, silhouette_rays};
use crate::ReconError;
use crate::morphology::dilate;
use irmirror_capture::Image;
use irmirror_geom::PinholeCamera;
use nalgebra::Vector3;

/// What one object's fit sees (depth frame, metres).
#[derive(Clone, Debug, Default)]
pub struct ObjectObservation {
    /// Observed surface points.
    pub surface: Vec<Vector3<f64>>,
    /// Points that must be outside the object (in front of the surface, or on rays that saw past
    /// it).
    pub free: Vec<Vector3<f64>>,
    /// Every mask and ring pixel's camera ray, for the fits' outlines
    /// ([`super::silhouette::outline_errors`]).
    pub silhouette: Vec<SilhouetteRay>,
}

/// Lifts a depth-pixel mask to the observation of one object.
pub fn observe(
    depth_m: &Image<f32>,
    camera: &PinholeCamera,
    mask: &Image<bool>,
    cfg: &ObjectConfig,
) -> Result<ObjectObservation, ReconError> {
    let (w, h) = (depth_m.width, depth_m.height);
    let valid = |i: usize| depth_m.data[i].is_finite() && depth_m.data[i] > 0.0;
    let idx: Vec<usize> = (0..(w * h) as usize)
        .filter(|&i| mask.data[i] && valid(i))
        .collect();
    if idx.len() < 10 {
        return Err(ReconError::EmptyObject { pixels: idx.len() });
    }
    let stride = idx.len().div_ceil(cfg.max_points).max(1);
    let point = |i: usize| {
        camera.unproject(
            (i as u32 % w) as f64 + 0.5,
            (i as u32 / w) as f64 + 0.5,
            f64::from(depth_m.data[i]),
        )
    };
    let surface: Vec<Vector3<f64>> = idx.iter().step_by(stride).map(|&i| point(i)).collect();
    let zs: Vec<f64> = surface.iter().map(|p| p.z).collect();
    let (zmin, zmax) = zs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
    let extent = (zmax - zmin).max(0.02);
    let mut free = Vec::new();
    // In front of the surface by 5 % of the object's depth extent, along the camera ray.
    for p in &surface {
        free.push(p * (1.0 - 0.05 * extent / p.z));
    }
    // The ring: the camera saw past (or missed) the object there.
    let ring = dilate(mask, cfg.ring_px);
    let ring_idx: Vec<usize> = (0..(w * h) as usize)
        .filter(|&i| ring.data[i] && !mask.data[i])
        .collect();
    let ring_stride = ring_idx.len().div_ceil(cfg.max_points / 2).max(1);
    for &i in ring_idx.iter().step_by(ring_stride) {
        let far = if valid(i) {
            f64::from(depth_m.data[i]) - 0.02 * extent
        } else {
            zmax + extent
        };
        for k in 0..RING_SAMPLES {
            let z = zmin - 0.25 * extent
                + (zmax - zmin + 0.5 * extent) * k as f64 / (RING_SAMPLES - 1) as f64;
            if z < far {
                free.push(camera.unproject(
                    (i as u32 % w) as f64 + 0.5,
                    (i as u32 / w) as f64 + 0.5,
                    z,
                ));
            }
        }
    }
    let silhouette = silhouette_rays(depth_m, camera, mask, &ring);
    Ok(ObjectObservation {
        surface,
        free,
        silhouette,
    })
}

/// Free-space samples along each ring ray (dense enough not to fall through a thin wall into a
/// cavity).
const RING_SAMPLES: usize = 12;
