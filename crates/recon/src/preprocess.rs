//! Stage 0 (paper §3.5, DESIGN.md §1): from the radiometric frame to a binary reflection mask on
//! the objects and its edge map.

use crate::ReconError;
use crate::morphology::{close, dilate, edges, open, remove_small_components};
use irmirror_capture::{Capture, Image};
use serde::{Deserialize, Serialize};

/// How the rise over the background is thresholded.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Threshold {
    /// Otsu's threshold over the object pixels' rises, but never below `noise_sigmas` robust
    /// standard deviations of the noise (so a frame without reflection gives no mask).
    Otsu {
        /// Floor in noise standard deviations (MAD-estimated).
        noise_sigmas: f64,
    },
    /// A fixed rise, K.
    DeltaK(f64),
}

/// Stage-0 settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PreprocessConfig {
    /// Threshold rule.
    pub threshold: Threshold,
    /// Opening radius, pixels (0: off).
    pub open_px: u32,
    /// Closing radius, pixels (0: off).
    pub close_px: u32,
    /// Median window (pixels, odd) of the local background used when the capture has no
    /// background frame.
    pub local_background_px: u32,
    /// Connected regions smaller than this (pixels) are dropped as noise.
    pub min_region_px: u32,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        Self {
            threshold: Threshold::Otsu { noise_sigmas: 4.0 },
            open_px: 0,
            close_px: 0,
            local_background_px: 15,
            min_region_px: 3,
        }
    }
}

/// Stage-0 products (thermal-camera pixels).
#[derive(Clone, Debug)]
pub struct Preprocessed {
    /// Apparent-temperature rise over the background, K.
    pub rise_k: Image<f64>,
    /// Thermal pixels that see an object (from depth + masks).
    pub object_pixels: Image<bool>,
    /// Thresholded rise on object pixels, before morphology.
    pub raw_mask: Image<bool>,
    /// The reflection mask.
    pub mask: Image<bool>,
    /// Its edge pixels (for edge sampling).
    pub edges: Image<bool>,
    /// Threshold used, K.
    pub threshold_k: f64,
    /// Robust noise estimate of the rise on object pixels, K.
    pub noise_k: f64,
    /// Median apparent temperature of the background frames on object pixels, K (what a mirror
    /// shows of the room where the person is not); `None` without background frames.
    pub background_k: Option<f64>,
    /// The thermal optics' point spread, Gaussian σ in pixels (0: not stated by the capture).
    pub psf_sigma_px: f64,
}

/// Median of a copy of `v` (0 for empty input).
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Object pixels farther than this from the thresholded reflection give the data term's noise
/// σ (the blur's halo below the threshold lies within it: the captures' point spread is
/// σ ≈ 0.5 px).
const QUIET_MARGIN_PX: u32 = 2;

/// Fewer quiet object pixels than this: the MAD of all of them gives the noise σ.
const MIN_QUIET_PX: usize = 50;

/// The MAD's σ of `values` about `med`: 1.4826 · median |v − med|, the normal's σ from a median
/// that a minority of outliers (the reflection's pixels) does not move.
fn mad_sigma(values: &[f64], med: f64) -> f64 {
    let mut dev: Vec<f64> = values.iter().map(|v| (v - med).abs()).collect();
    1.4826 * median(&mut dev)
}

/// The rises' noise σ about their median `med`, where they are (nearly) all noise: the MAD's
/// σ, then twice the standard deviation of the values within 3σ (scaled by the 3σ-truncated
/// normal's 0.98658), which reflection pixels within 3σ would inflate — hence the quiet pixels
/// only. The MAD alone is a quantile of values on the ADC's lattice (one count ≈ 15 mK near
/// room temperature at 14 bits over −40…150 °C, and a rise is the difference of two such
/// values), so it snaps to a multiple of the count: at 50 mK NETD it read 5 % low, at 30 mK 4 %
/// high, and the data term's noise floor with it (EXPERIMENTS.md, "Forty-fourth run"). 0 when
/// more than half the values equal the median.
fn noise_sigma(on: &[f64], med: f64) -> f64 {
    /// √(1 − 2·3·φ(3) / (2Φ(3) − 1)): the σ of a standard normal truncated at ±3.
    const TRUNCATED_3: f64 = 0.986_58;
    let dev: Vec<f64> = on.iter().map(|r| (r - med).abs()).collect();
    let mut sigma = mad_sigma(on, med);
    for _ in 0..2 {
        if sigma <= 0.0 {
            break;
        }
        let (n, ss) = dev
            .iter()
            .filter(|d| **d <= 3.0 * sigma)
            .fold((0usize, 0.0), |(n, ss), d| (n + 1, ss + d * d));
        sigma = (ss / n.max(1) as f64).sqrt() / TRUNCATED_3;
    }
    sigma
}

fn local_median(img: &Image<f64>, window: u32) -> Image<f64> {
    let r = i64::from(window / 2);
    let (w, h) = (img.width as i64, img.height as i64);
    let mut buf = Vec::new();
    let data = (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            buf.clear();
            for yy in (y - r).max(0)..=(y + r).min(h - 1) {
                for xx in (x - r).max(0)..=(x + r).min(w - 1) {
                    buf.push(img.data[(yy * w + xx) as usize]);
                }
            }
            median(&mut buf)
        })
        .collect();
    Image {
        width: img.width,
        height: img.height,
        data,
    }
}

/// Otsu's threshold of `values` (256 bins between min and max).
pub fn otsu(values: &[f64]) -> f64 {
    let (lo, hi) = values
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if values.is_empty() || hi <= lo {
        return hi;
    }
    let bins = 256;
    let mut hist = vec![0usize; bins];
    for &v in values {
        hist[(((v - lo) / (hi - lo)) * (bins - 1) as f64).round() as usize] += 1;
    }
    let total = values.len() as f64;
    let sum_all: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut w0, mut sum0, mut best, mut best_i) = (0.0, 0.0, -1.0, 0);
    for (i, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += i as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum_all - sum0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            best_i = i;
        }
    }
    lo + (best_i as f64 + 0.5) / (bins - 1) as f64 * (hi - lo)
}

/// Thermal pixels that see an object: depth pixels inside an object mask (all valid depth
/// pixels when no object has a mask), lifted to 3-D and projected into the thermal camera,
/// then closed over one pixel to bridge the two cameras' sampling.
pub fn object_pixels(capture: &Capture) -> Image<bool> {
    let (dc, tc) = (&capture.depth_camera, &capture.thermal_camera);
    let thermal_from_depth = capture.depth_from_thermal.inverse();
    let masks: Vec<&Image<bool>> = capture
        .objects
        .iter()
        .filter_map(|o| o.mask.as_ref())
        .collect();
    let mut out = Image::filled(tc.width, tc.height, false);
    for row in 0..dc.height {
        for col in 0..dc.width {
            let p = (row * dc.width + col) as usize;
            let z = f64::from(capture.depth_m.data[p]);
            if !z.is_finite() || (!masks.is_empty() && !masks.iter().any(|m| m.data[p])) {
                continue;
            }
            let p_depth = dc.unproject(f64::from(col) + 0.5, f64::from(row) + 0.5, z);
            let p_thermal = thermal_from_depth.transform_point(&p_depth);
            if let Some((u, v)) = tc.project_to_pixel(&p_thermal) {
                out.data[(v * tc.width + u) as usize] = true;
            }
        }
    }
    close(&dilate(&out, 1), 1)
}

/// Runs stage 0 on a capture.
pub fn preprocess(capture: &Capture, cfg: &PreprocessConfig) -> Result<Preprocessed, ReconError> {
    let t = &capture.thermal_k;
    let background = if capture.thermal_background_k.is_empty() {
        local_median(t, cfg.local_background_px.max(3) | 1)
    } else {
        let n = capture.thermal_background_k.len() as f64;
        let mut mean = Image::filled(t.width, t.height, 0.0);
        for b in &capture.thermal_background_k {
            mean.data
                .iter_mut()
                .zip(&b.data)
                .for_each(|(m, v)| *m += v / n);
        }
        mean
    };
    let rise = Image {
        width: t.width,
        height: t.height,
        data: t
            .data
            .iter()
            .zip(&background.data)
            .map(|(a, b)| a - b)
            .collect(),
    };
    let objects = object_pixels(capture);
    let on: Vec<f64> = rise
        .data
        .iter()
        .zip(&objects.data)
        .filter(|(_, o)| **o)
        .map(|(r, _)| *r)
        .collect();
    if on.is_empty() {
        return Err(ReconError::NoObjectPixels);
    }
    let max_rise = on.iter().copied().fold(f64::MIN, f64::max);
    let background_k = (!capture.thermal_background_k.is_empty()).then(|| {
        let mut b: Vec<f64> = background
            .data
            .iter()
            .zip(&objects.data)
            .filter(|(_, o)| **o)
            .map(|(b, _)| *b)
            .collect();
        median(&mut b)
    });
    let med = median(&mut on.clone());
    // The threshold's robust σ: the MAD, which the reflection (a small minority of object
    // pixels) does not move.
    let mad = mad_sigma(&on, med);
    let threshold_k = match cfg.threshold {
        Threshold::DeltaK(k) => k,
        Threshold::Otsu { noise_sigmas } => otsu(&on).max(med + noise_sigmas * mad).max(1e-6),
    };
    let raw = Image {
        width: t.width,
        height: t.height,
        data: rise
            .data
            .iter()
            .zip(&objects.data)
            .map(|(r, o)| *o && *r > threshold_k)
            .collect(),
    };
    // The data term's σ: away from the reflection and its blur, off the ADC's lattice.
    let near = dilate(&raw, QUIET_MARGIN_PX);
    let quiet: Vec<f64> = rise
        .data
        .iter()
        .zip(&objects.data)
        .zip(&near.data)
        .filter(|((_, o), n)| **o && !**n)
        .map(|((r, _), _)| *r)
        .collect();
    let noise = if quiet.len() >= MIN_QUIET_PX {
        let m = median(&mut quiet.clone());
        noise_sigma(&quiet, m)
    } else {
        mad
    };
    let mask = remove_small_components(
        &close(&open(&raw, cfg.open_px), cfg.close_px),
        cfg.min_region_px as usize,
    );
    // Closing may reach past the object silhouette: keep the mask on objects.
    let mask = Image {
        width: t.width,
        height: t.height,
        data: mask
            .data
            .iter()
            .zip(&objects.data)
            .map(|(m, o)| *m && *o)
            .collect(),
    };
    if !mask.data.iter().any(|&m| m) {
        return Err(ReconError::NoReflection {
            threshold_k,
            max_rise_k: max_rise,
        });
    }
    let edges = edges(&mask);
    Ok(Preprocessed {
        rise_k: rise,
        object_pixels: objects,
        raw_mask: raw,
        mask,
        edges,
        threshold_k,
        noise_k: noise,
        background_k,
        psf_sigma_px: capture.thermal_psf_sigma_px(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rises as the ADC makes them (two frames, each rounded to a count of `q`), and 1 % of
    /// reflection pixels far above: the estimate within 2 % of the sample's σ at every NETD,
    /// where the MAD alone was off by up to 5 %.
    #[test]
    fn noise_sigma_sees_through_the_adc_lattice() {
        use rand::SeedableRng;
        let q = 0.0153;
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut mad_worst: f64 = 0.0;
        for netd in [0.03, 0.05, 0.08] {
            let count = |rng: &mut rand::rngs::StdRng| {
                let z: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng);
                q * (netd * z / q).round()
            };
            let noise: Vec<f64> = (0..3000)
                .map(|_| count(&mut rng) - count(&mut rng))
                .collect();
            let truth = (noise.iter().map(|r| r * r).sum::<f64>() / noise.len() as f64).sqrt();
            let mut on = noise.clone();
            on.extend((0..30).map(|i| 0.5 + 0.01 * f64::from(i)));
            let med = median(&mut on.clone());
            let est = noise_sigma(&on, med);
            assert!(
                (est / truth - 1.0).abs() < 0.02,
                "NETD {netd}: {est} vs {truth}"
            );
            mad_worst = mad_worst.max((mad_sigma(&on, med) / truth - 1.0).abs());
        }
        // What the estimate is there for: the lattice's bias in the MAD.
        assert!(mad_worst > 0.03, "{mad_worst}");
        assert_eq!(noise_sigma(&[0.1; 9], 0.1), 0.0);
    }

    #[test]
    fn otsu_splits_two_clusters() {
        let mut v: Vec<f64> = (0..900).map(|i| 0.01 * (i % 10) as f64).collect();
        v.extend((0..100).map(|i| 1.0 + 0.01 * (i % 10) as f64));
        let t = otsu(&v);
        assert!(t > 0.09 && t < 1.0, "{t}");
    }
}
