//! The stage-1 driver: ground (support plane, or up alone), masks (given, or segmented above the
//! plane with touching objects split), one fit per object, split objects refitted on
//! re-assigned points, then the learned prior where asked.

use super::family::Family;
use super::fit::{fit_family, fit_learned};
use super::observation::{ObjectObservation, observe};
use super::{FittedObject, ObjectPrior, Objects, Stage1Config};
use crate::ReconError;
use crate::plane::Ground;
use irmirror_capture::{Capture, Image};
use irmirror_render::sdf::PlacedSdf;
use nalgebra::Vector3;

/// Stage 1 on a loaded capture: support plane, masks (given or segmented), one fit per object.
pub fn reconstruct_objects(
    capture: &Capture,
    cfg: &Stage1Config,
    seed: u64,
) -> Result<Objects, ReconError> {
    let points = crate::segment::depth_points(&capture.depth_m, &capture.depth_camera);
    let families: Vec<Family> = capture
        .objects
        .iter()
        .map(|o| Family::of(o.category))
        .collect();
    let mut given = vec![false; points.len()];
    for o in &capture.objects {
        if let Some(m) = &o.mask {
            for (g, &b) in given.iter_mut().zip(&m.data) {
                *g |= b;
            }
        }
    }
    let ground = find_ground(capture, &points, &given, cfg, seed);
    let (mut masks, groups) = object_masks(capture, &points, &given, &ground, cfg)?;
    let segmented: Vec<bool> = groups.iter().map(Option::is_some).collect();
    // Segmented clusters come largest first, not in capture order: give each cluster the
    // family (among the mask-less objects' categories) that fits it best.
    let mut options: Vec<Family> = Vec::new();
    for (_, f) in capture
        .objects
        .iter()
        .zip(&families)
        .filter(|(o, _)| o.mask.is_none())
    {
        if !options.contains(f) {
            options.push(*f);
        }
    }
    let (depth, cam) = (&capture.depth_m, &capture.depth_camera);
    let mut objects = Vec::with_capacity(masks.len());
    let mut observations = Vec::with_capacity(masks.len());
    for (k, mask) in masks.iter().enumerate() {
        let obs = observe(depth, cam, mask, &cfg.fit)?;
        let fit = if segmented[k] {
            let fits = options
                .iter()
                .map(|f| fit_family(*f, &obs, &ground, &cfg.fit))
                .collect::<Result<Vec<_>, _>>()?;
            fits.into_iter()
                .min_by(|a, b| a.loss.total_cmp(&b.loss))
                .expect("one option per segmented object")
        } else {
            fit_family(families[k], &obs, &ground, &cfg.fit)?
        };
        objects.push(fit);
        observations.push(obs);
    }
    let mut fits = Fits {
        objects,
        observations,
        masks: &mut masks,
    };
    refit_split(capture, &points, &groups, &ground, cfg, &mut fits)?;
    let Fits {
        mut objects,
        observations,
        ..
    } = fits;
    // The learned prior starts from the final family fits (after any split).
    if cfg.fit.prior == ObjectPrior::Learned {
        objects = objects
            .into_iter()
            .zip(&observations)
            .enumerate()
            .map(|(k, (o, obs))| {
                fit_learned(o, obs, &ground, &cfg.fit, seed.wrapping_add(k as u64))
            })
            .collect::<Result<_, _>>()?;
    }
    Ok(Objects {
        ground,
        objects,
        masks,
        segmented,
    })
}

/// The support plane by RANSAC over the depth points no given mask covers; without one, up from
/// the capture's IMU, else the camera's −Y.
fn find_ground(
    capture: &Capture,
    points: &[Option<Vector3<f64>>],
    given: &[bool],
    cfg: &Stage1Config,
    seed: u64,
) -> Ground {
    let candidates: Vec<Vector3<f64>> = points
        .iter()
        .zip(given)
        .filter_map(|(p, &g)| if g { None } else { *p })
        .collect();
    let stride = candidates.len().div_ceil(20_000).max(1);
    let sub: Vec<Vector3<f64>> = candidates.into_iter().step_by(stride).collect();
    let mut rng = irmirror_geom::rng::seeded(seed, 11);
    match crate::plane::fit_plane(&sub, capture.up.as_ref(), &cfg.plane, &mut rng) {
        Some(plane) => Ground::plane(plane),
        None => Ground::up_only(capture.up.unwrap_or(-Vector3::y())),
    }
}

/// Per capture object: its mask (given, or a cluster above the support plane), and for
/// segmented ones the cluster it came from (two touching objects share one).
type Masks = (Vec<Image<bool>>, Vec<Option<usize>>);

fn object_masks(
    capture: &Capture,
    points: &[Option<Vector3<f64>>],
    given: &[bool],
    ground: &Ground,
    cfg: &Stage1Config,
) -> Result<Masks, ReconError> {
    let missing = capture.objects.iter().filter(|o| o.mask.is_none()).count();
    let mut clusters: Vec<(Image<bool>, usize)> = Vec::new();
    if missing > 0 {
        let plane = ground.plane.as_ref().ok_or(ReconError::NoSupportPlane)?;
        let depth = &capture.depth_m;
        // (mask, the cluster it was split from), largest first.
        clusters = crate::segment::segment(
            points,
            depth.width,
            depth.height,
            plane,
            given,
            &cfg.segment,
        )
        .into_iter()
        .enumerate()
        .map(|(g, m)| (m, g))
        .collect();
        // Touching objects join into one cluster: split the largest until there are enough (or
        // none can be split).
        while clusters.len() < missing
            && let Some((a, b)) = clusters
                .first()
                .and_then(|(c, _)| crate::segment::split(points, c, plane, &cfg.segment))
        {
            let (_, g) = clusters.remove(0);
            clusters.extend([(a, g), (b, g)]);
            clusters.sort_by_cached_key(|(m, _)| {
                std::cmp::Reverse(m.data.iter().filter(|&&v| v).count())
            });
        }
    }
    if clusters.len() < missing {
        return Err(ReconError::Segmentation {
            wanted: missing,
            found: clusters.len(),
        });
    }
    let mut clusters = clusters.into_iter();
    Ok(capture
        .objects
        .iter()
        .map(|o| match &o.mask {
            Some(m) => (m.clone(), None),
            None => {
                let (m, g) = clusters
                    .next()
                    .expect("one cluster per object without a mask");
                (m, Some(g))
            }
        })
        .unzip())
}

/// The fits so far, with what each was fitted to.
struct Fits<'a> {
    objects: Vec<FittedObject>,
    observations: Vec<ObjectObservation>,
    masks: &'a mut Vec<Image<bool>>,
}

/// Objects split from one cluster: the split's straight cut is only a first guess. Give every
/// point of the cluster to the fitted surface nearest to it, and refit on those masks.
fn refit_split(
    capture: &Capture,
    points: &[Option<Vector3<f64>>],
    groups: &[Option<usize>],
    ground: &Ground,
    cfg: &Stage1Config,
    fits: &mut Fits,
) -> Result<(), ReconError> {
    let (depth, cam) = (&capture.depth_m, &capture.depth_camera);
    let mut split_from: Vec<usize> = groups.iter().flatten().copied().collect();
    split_from.sort_unstable();
    split_from.dedup();
    for g in split_from {
        let members: Vec<usize> = (0..groups.len())
            .filter(|&j| groups[j] == Some(g))
            .collect();
        if members.len() < 2 {
            continue;
        }
        let placed: Vec<PlacedSdf> = members.iter().map(|&j| fits.objects[j].placed()).collect();
        let mut new: Vec<Image<bool>> = members
            .iter()
            .map(|_| Image::filled(depth.width, depth.height, false))
            .collect();
        for i in 0..points.len() {
            if let Some(p) = points[i]
                && members.iter().any(|&j| fits.masks[j].data[i])
            {
                let best = (0..members.len())
                    .min_by(|&a, &b| {
                        placed[a]
                            .distance(&p)
                            .abs()
                            .total_cmp(&placed[b].distance(&p).abs())
                    })
                    .expect("members");
                new[best].data[i] = true;
            }
        }
        for (&j, m) in members.iter().zip(new) {
            let Ok(obs) = observe(depth, cam, &m, &cfg.fit) else {
                continue;
            };
            let family = Family::of(fits.objects[j].category);
            fits.objects[j] = fit_family(family, &obs, ground, &cfg.fit)?;
            fits.observations[j] = obs;
            fits.masks[j] = m;
        }
    }
    Ok(())
}
