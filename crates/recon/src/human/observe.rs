//! The radiometric term's observation operator: which rays each thermal pixel integrates, and
//! with what weight (its footprint's samples through the optics' point spread), and the
//! batches drawn from it.

use super::radiometric::Radiometry;
use irmirror_render::reflect::ReflectedRays;

/// The linear map from rays to pixels ([`Radiometry`]'s `pixel`, `object`, `starts`,
/// `entries`).
pub(super) struct Operator {
    pub pixel: Vec<u32>,
    pub object: Vec<u16>,
    pub starts: Vec<u32>,
    pub entries: Vec<(u32, f64)>,
}

/// A pixel's prediction as a weighted sum of rays: with one ray per pixel, that ray; with
/// footprint rays (`rays.footprint` per pixel, next to each other), their mean, convolved
/// with the optics' Gaussian point spread `psf_sigma_px` (kernel cut where it falls below
/// 1/1000 of its peak: ±1 pixel at σ = 0.5). The capture's point spread spreads a reflection a
/// pixel wide into its neighbours; thin limbs on a small reflection are mostly that spread.
pub(super) fn observation_operator(rays: &ReflectedRays<f64>, psf_sigma_px: f64) -> Operator {
    if rays.footprint <= 1 {
        return Operator {
            pixel: rays.pixel.clone(),
            object: rays.object.clone(),
            starts: (0..=rays.len() as u32).collect(),
            entries: (0..rays.len() as u32).map(|i| (i, 1.0)).collect(),
        };
    }
    let per_pixel = f64::from(rays.footprint);
    let radius = if psf_sigma_px > 0.0 {
        (psf_sigma_px * (2.0 * 1000f64.ln()).sqrt()).floor() as i64
    } else {
        0
    };
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-((d * d) as f64) / (2.0 * psf_sigma_px * psf_sigma_px).max(1e-300)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / total).collect();
    // Each pixel's run of rays.
    let mut runs = std::collections::HashMap::new();
    let mut i = 0;
    while i < rays.len() {
        let mut j = i + 1;
        while j < rays.len() && rays.pixel[j] == rays.pixel[i] {
            j += 1;
        }
        runs.insert(rays.pixel[i], (i as u32, j as u32));
        i = j;
    }
    let (w, h) = (i64::from(rays.width), i64::from(rays.height));
    let near = |p: u32| {
        let (x, y) = (i64::from(p) % w, i64::from(p) / w);
        (-radius..=radius).flat_map(move |dy| {
            (-radius..=radius).filter_map(move |dx| {
                let (nx, ny) = (x + dx, y + dy);
                (nx >= 0 && ny >= 0 && nx < w && ny < h).then_some((
                    (ny * w + nx) as u32,
                    (dx + radius) as usize,
                    (dy + radius) as usize,
                ))
            })
        })
    };
    let scored: std::collections::BTreeSet<u32> = runs
        .keys()
        .flat_map(|&p| near(p).map(|(q, _, _)| q))
        .collect();
    let mut op = Operator {
        pixel: Vec::with_capacity(scored.len()),
        object: Vec::with_capacity(scored.len()),
        starts: vec![0],
        entries: Vec::new(),
    };
    for p in scored {
        let mut by_object: Vec<(u16, f64)> = Vec::new();
        for (q, kx, ky) in near(p) {
            let Some(&(a, b)) = runs.get(&q) else {
                continue;
            };
            let wq = kernel[kx] * kernel[ky] / per_pixel;
            for r in a..b {
                op.entries.push((r, wq));
                let k = rays.object[r as usize];
                match by_object.iter_mut().find(|(o, _)| *o == k) {
                    Some(e) => e.1 += wq,
                    None => by_object.push((k, wq)),
                }
            }
        }
        op.pixel.push(p);
        op.object.push(
            by_object
                .iter()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |e| e.0),
        );
        op.starts.push(op.entries.len() as u32);
    }
    op
}

/// A batch's thermal pixels: observed rise and the observation operator over the batch's
/// rays (see [`Radiometry`]).
#[derive(Clone, Copy, Debug)]
pub struct Rise<'a> {
    /// Observed rise per pixel, K.
    pub rise_k: &'a [f64],
    /// The object whose reflectance each pixel's prediction takes.
    pub object: &'a [u16],
    /// Pixel `p`'s prediction weighs `entries[starts[p]..starts[p + 1]]`.
    pub starts: &'a [u32],
    /// `(ray among the batch's rays, weight)`.
    pub entries: &'a [(u32, f64)],
    /// Importance weight per pixel (`None`: 1).
    pub weight: Option<&'a [f64]>,
}

/// Some of a [`Radiometry`]'s pixels with the rays their predictions need
/// ([`Radiometry::select`]); buffers reused across draws.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// The rays, as indices among the problem's rays.
    pub rays: Vec<usize>,
    /// Per ray: the first selected pixel (its place in the selection) that needs it.
    pub owner: Vec<u32>,
    rise_k: Vec<f64>,
    object: Vec<u16>,
    starts: Vec<u32>,
    entries: Vec<(u32, f64)>,
    /// Per problem ray: its index in `rays` (`u32::MAX`: not drawn).
    slot: Vec<u32>,
}

impl Selection {
    /// The selected pixels as a batch's rise, with per-pixel importance `weight`.
    pub fn rise<'a>(&'a self, weight: Option<&'a [f64]>) -> Rise<'a> {
        Rise {
            rise_k: &self.rise_k,
            object: &self.object,
            starts: &self.starts,
            entries: &self.entries,
            weight,
        }
    }
}

impl Radiometry {
    /// Pixels the term scores.
    pub fn pixels(&self) -> usize {
        self.rise_k.len()
    }

    /// All pixels over all of the problem's rays.
    pub fn rise(&self) -> Rise<'_> {
        Rise {
            rise_k: &self.rise_k,
            object: &self.object,
            starts: &self.starts,
            entries: &self.entries,
            weight: None,
        }
    }

    /// `pixels` (indices of this term's pixels), in that order, and every ray their
    /// predictions weigh, into `out`.
    pub fn select(&self, pixels: &[usize], out: &mut Selection) {
        for &r in &out.rays {
            out.slot[r] = u32::MAX;
        }
        out.rays.clear();
        out.owner.clear();
        out.rise_k.clear();
        out.object.clear();
        out.entries.clear();
        out.starts.clear();
        out.starts.push(0);
        for (k, &p) in pixels.iter().enumerate() {
            for &(r, w) in &self.entries[self.starts[p] as usize..self.starts[p + 1] as usize] {
                // Grown on demand: a scan of every entry per draw would cost more than the draw.
                if r as usize >= out.slot.len() {
                    out.slot.resize(r as usize + 1, u32::MAX);
                }
                let slot = &mut out.slot[r as usize];
                if *slot == u32::MAX {
                    *slot = out.rays.len() as u32;
                    out.rays.push(r as usize);
                    out.owner.push(k as u32);
                }
                out.entries.push((*slot, w));
            }
            out.starts.push(out.entries.len() as u32);
            out.rise_k.push(self.rise_k[p]);
            out.object.push(self.object[p]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// 4 rays on each of the central 3 × 3 pixels of a 5 × 5 image (object 1 on the middle
    /// column, 0 elsewhere).
    fn rays() -> ReflectedRays<f64> {
        let mut r = ReflectedRays {
            width: 5,
            height: 5,
            footprint: 4,
            ..Default::default()
        };
        for y in 1..4u32 {
            for x in 1..4u32 {
                for _ in 0..4 {
                    let z = Vector3::zeros();
                    r.push(y * 5 + x, u16::from(x == 2), z, z, z);
                }
            }
        }
        r
    }

    /// With a point spread every pixel within its reach is scored; a pixel whose whole
    /// neighbourhood is sampled weighs its rays by the kernel summing to 1, the mean of its own
    /// footprint weighing most; without one each pixel is the mean of its own rays.
    #[test]
    fn operator_is_the_footprint_mean_convolved_with_the_point_spread() {
        let r = rays();
        let op = observation_operator(&r, 0.5);
        assert_eq!(op.pixel, (0..25).collect::<Vec<u32>>());
        let weights = |p: usize| &op.entries[op.starts[p] as usize..op.starts[p + 1] as usize];
        let sum = |p: usize| weights(p).iter().map(|e| e.1).sum::<f64>();
        assert!((sum(12) - 1.0).abs() < 1e-12, "{}", sum(12));
        assert_eq!(weights(12).len(), 36);
        let k1 = (-2.0f64).exp();
        let k = [k1, 1.0, k1].map(|x| x / (1.0 + 2.0 * k1));
        assert!(
            (weights(12)[16].1 - k[1] * k[1] / 4.0).abs() < 1e-12,
            "own ray"
        );
        // A corner pixel sees only the ray of its diagonal neighbour, at the kernel's corner.
        assert_eq!(weights(0).len(), 4);
        assert!((sum(0) - k[0] * k[0]).abs() < 1e-12);
        // The middle column's object has most of pixel 12's weight.
        assert_eq!(op.object[12], 1);
        assert_eq!(op.object[11], 0);
        let plain = observation_operator(&r, 0.0);
        assert_eq!(plain.pixel.len(), 9);
        for p in 0..9 {
            let w = &plain.entries[plain.starts[p] as usize..plain.starts[p + 1] as usize];
            assert_eq!(w.len(), 4);
            assert!(
                w.iter()
                    .all(|e| e.1 == 0.25 && r.pixel[e.0 as usize] == plain.pixel[p])
            );
        }
    }

    /// A selection holds each needed ray once, its entries point at them, and a second draw
    /// reuses the buffers without stale rays.
    #[test]
    fn selection_remaps_shared_rays() {
        let r = rays();
        let op = observation_operator(&r, 0.5);
        let rad = Radiometry {
            rise_k: (0..op.pixel.len()).map(|p| p as f64).collect(),
            pixel: op.pixel,
            object: op.object,
            starts: op.starts,
            entries: op.entries,
            noise_k: 0.05,
            ambient_k: 295.0,
            objects: 2,
            contrast_at: [[1.0, 0.0]; super::super::radiometric::REGIONS],
            vertex_region: vec![],
            triangle_region: vec![],
        };
        let mut sel = Selection::default();
        for pixels in [vec![12, 13], vec![0, 24]] {
            rad.select(&pixels, &mut sel);
            let rise = sel.rise(None);
            assert_eq!(
                rise.rise_k,
                pixels.iter().map(|&p| p as f64).collect::<Vec<_>>()
            );
            let mut seen = sel.rays.clone();
            seen.sort_unstable();
            seen.dedup();
            assert_eq!(seen.len(), sel.rays.len(), "each ray once");
            for (k, &p) in pixels.iter().enumerate() {
                let mine = &rise.entries[rise.starts[k] as usize..rise.starts[k + 1] as usize];
                let all = &rad.entries[rad.starts[p] as usize..rad.starts[p + 1] as usize];
                assert_eq!(mine.len(), all.len());
                for (a, b) in mine.iter().zip(all) {
                    assert_eq!(sel.rays[a.0 as usize], b.0 as usize);
                    assert_eq!(a.1, b.1);
                }
            }
        }
        // Pixels 0 and 24 share no ray: 4 rays each.
        assert_eq!(sel.rays.len(), 8);
        assert_eq!(sel.owner, vec![0, 0, 0, 0, 1, 1, 1, 1]);
    }
}
