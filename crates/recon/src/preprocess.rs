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
    // Robust noise: MAD of the rises (the reflection is a small minority of object pixels).
    let med = median(&mut on.clone());
    let mut dev: Vec<f64> = on.iter().map(|r| (r - med).abs()).collect();
    let noise = 1.4826 * median(&mut dev);
    let threshold_k = match cfg.threshold {
        Threshold::DeltaK(k) => k,
        Threshold::Otsu { noise_sigmas } => otsu(&on).max(med + noise_sigmas * noise).max(1e-6),
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

    #[test]
    fn otsu_splits_two_clusters() {
        let mut v: Vec<f64> = (0..900).map(|i| 0.01 * (i % 10) as f64).collect();
        v.extend((0..100).map(|i| 1.0 + 0.01 * (i % 10) as f64));
        let t = otsu(&v);
        assert!(t > 0.09 && t < 1.0, "{t}");
    }
}
