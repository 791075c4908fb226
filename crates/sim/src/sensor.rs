//! Images from the world: supersampled thermal radiance, depth with structured-light
//! artefacts, shaded RGB, object masks; and the thermal sensor (blur, NETD, ADC).

use crate::scene::Sensor;
use crate::world::{Surface, World};
use irmirror_capture::Image;
use irmirror_capture::planck::band_radiance;
use irmirror_geom::{PinholeCamera, Ray, Rigid3};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// Reflection bounces followed from object surfaces (object → object → …).
const BOUNCES: u32 = 3;

/// Sub-pixel rays per axis of the probe that decides where a pixel needs its full grid.
const PROBE: u32 = 4;

/// Mean band radiance over each pixel's box of `camera` (placed by `depth_from_camera`):
/// `s × s` sub-pixel rays where the image varies by more than `tol` within a pixel's
/// neighbourhood, a 4 × 4 probe where it does not (see [`supersampled_adaptive`]).
pub fn thermal_radiance(
    world: &World,
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    supersample: u32,
    tol: f64,
) -> Image<f64> {
    supersampled_adaptive(camera, supersample, tol, |u, v| {
        let ray = depth_from_camera.transform_ray(&camera.ray_at::<f64>(u, v));
        world.radiance(&ray, BOUNCES)
    })
}

/// Mean of `value(u, v)` over an `s × s` grid of sub-pixel points in pixel `(col, row)`
/// (pixel centres at +0.5), and the samples' min and max.
fn pixel_grid(col: u32, row: u32, s: u32, value: &impl Fn(f64, f64) -> f64) -> (f64, f64, f64) {
    let (mut sum, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
    for a in 0..s {
        for b in 0..s {
            let u = f64::from(col) + (f64::from(a) + 0.5) / f64::from(s);
            let v = f64::from(row) + (f64::from(b) + 0.5) / f64::from(s);
            let x = value(u, v);
            sum += x;
            lo = lo.min(x);
            hi = hi.max(x);
        }
    }
    (sum / f64::from(s * s), lo, hi)
}

/// Per pixel of `camera`, the mean of `value(u, v)` over an `s × s` grid of sub-pixel image
/// points (pixel centres at +0.5), in parallel.
pub fn supersampled(
    camera: &PinholeCamera,
    supersample: u32,
    value: impl Fn(f64, f64) -> f64 + Sync,
) -> Image<f64> {
    let s = supersample.max(1);
    let (w, h) = (camera.width, camera.height);
    let data = (0..w * h)
        .into_par_iter()
        .map(|p| pixel_grid(p % w, p / w, s, &value).0)
        .collect();
    Image {
        width: w,
        height: h,
        data,
    }
}

/// [`supersampled`] at `s × s`, adaptively: every pixel is probed by 4 × 4 points; a pixel
/// takes the full grid only where, in its 3 × 3 neighbourhood, some pixel's probe samples
/// spread by more than `tol` or a probe mean differs from its own by more than `tol`. Elsewhere
/// the image is flat to within `tol` at the probe's resolution and the probe mean stands. A
/// feature narrower than a quarter pixel that touches no probe point within a pixel of it can
/// be missed (a sliver of reflection along a bowl's rim, parallel to the probe's rows: on
/// tabletop seed 7, 10 of 327,680 pixels differ from the full 8 × 8 grid, by ≤ 0.07 K; a 2 × 2
/// probe missed 65). With `s ≤ 4` this is [`supersampled`].
pub fn supersampled_adaptive(
    camera: &PinholeCamera,
    supersample: u32,
    tol: f64,
    value: impl Fn(f64, f64) -> f64 + Sync,
) -> Image<f64> {
    let s = supersample.max(1);
    if s <= PROBE {
        return supersampled(camera, s, value);
    }
    let (w, h) = (camera.width, camera.height);
    let probe: Vec<(f64, f64, f64)> = (0..w * h)
        .into_par_iter()
        .map(|p| pixel_grid(p % w, p / w, PROBE, &value))
        .collect();
    let data = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (col, row) = (p % w, p / w);
            let mean = probe[p as usize].0;
            let varies = (row.saturating_sub(1)..(row + 2).min(h)).any(|r| {
                (col.saturating_sub(1)..(col + 2).min(w)).any(|c| {
                    let (m, lo, hi) = probe[(r * w + c) as usize];
                    hi - lo > tol || (m - mean).abs() > tol
                })
            });
            if varies {
                pixel_grid(col, row, s, &value).0
            } else {
                mean
            }
        })
        .collect();
    Image {
        width: w,
        height: h,
        data,
    }
}

/// Separable Gaussian blur with σ in pixels (edges clamped).
pub fn blur(img: &Image<f64>, sigma_px: f64) -> Image<f64> {
    if sigma_px <= 0.0 {
        return img.clone();
    }
    let r = (3.0 * sigma_px).ceil() as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let ksum: f64 = k.iter().sum();
    let (w, h) = (img.width as i64, img.height as i64);
    let pass = |src: &[f64], horizontal: bool| -> Vec<f64> {
        (0..w * h)
            .map(|p| {
                let (x, y) = (p % w, p / w);
                (-r..=r)
                    .map(|i| {
                        let (xx, yy) = if horizontal {
                            ((x + i).clamp(0, w - 1), y)
                        } else {
                            (x, (y + i).clamp(0, h - 1))
                        };
                        src[(yy * w + xx) as usize] * k[(i + r) as usize]
                    })
                    .sum::<f64>()
                    / ksum
            })
            .collect()
    };
    let tmp = pass(&img.data, true);
    Image {
        width: img.width,
        height: img.height,
        data: pass(&tmp, false),
    }
}

/// Linear radiometric calibration of the raw counts: `counts = gain · L + offset`, spanning
/// −40 … 150 °C over the ADC range.
pub fn calibration(bits: u32) -> (f64, f64) {
    let (lo, hi) = (band_radiance(233.15), band_radiance(423.15));
    let gain = (f64::from((1u32 << bits) - 1)) / (hi - lo);
    (gain, -gain * lo)
}

/// Blur, NETD noise (σ in kelvin, converted with dL/dT at the ambient radiance) and quantisation
/// to `bits`-bit counts.
pub fn thermal_counts(
    radiance: &Image<f64>,
    sensor: &Sensor,
    ambient_k: f64,
    rng: &mut impl Rng,
) -> Image<u16> {
    let blurred = blur(radiance, sensor.blur_px);
    let dl_dt = band_radiance(ambient_k + 0.5) - band_radiance(ambient_k - 0.5);
    let noise = Normal::new(0.0, (sensor.netd_mk * 1e-3 * dl_dt).max(1e-300)).expect("finite σ");
    let (gain, offset) = calibration(sensor.bits);
    let max = f64::from((1u32 << sensor.bits) - 1);
    let data = blurred
        .data
        .iter()
        .map(|&l| {
            let n = if sensor.netd_mk > 0.0 {
                noise.sample(rng)
            } else {
                0.0
            };
            ((l + n) * gain + offset).round().clamp(0.0, max) as u16
        })
        .collect();
    Image {
        width: radiance.width,
        height: radiance.height,
        data,
    }
}

/// Per depth-camera pixel: the nearest surface's depth along +Z (m), its incidence cosine, and
/// what it is.
pub struct DepthRender {
    /// Depth along +Z, m (NaN: nothing within range).
    pub z_m: Image<f64>,
    /// |cos| between the ray and the surface normal.
    pub cos: Image<f64>,
    /// Surface per pixel.
    pub surface: Vec<Option<Surface>>,
}

/// Casts one ray per depth-camera pixel.
pub fn render_depth(world: &World, camera: &PinholeCamera) -> DepthRender {
    let hits: Vec<_> = (0..camera.width * camera.height)
        .into_par_iter()
        .map(|p| {
            let ray: Ray<f64> = camera.pixel_ray(p % camera.width, p / camera.width);
            world
                .hit(&ray)
                .map(|h| (h.t_m * ray.dir.z, h.normal.dot(&ray.dir).abs(), h.surface))
        })
        .collect();
    let (w, h) = (camera.width, camera.height);
    DepthRender {
        z_m: Image {
            width: w,
            height: h,
            data: hits.iter().map(|x| x.map_or(f64::NAN, |x| x.0)).collect(),
        },
        cos: Image {
            width: w,
            height: h,
            data: hits.iter().map(|x| x.map_or(0.0, |x| x.1)).collect(),
        },
        surface: hits.iter().map(|x| x.map(|x| x.2)).collect(),
    }
}

/// 16-bit millimetre depth with range noise (σ ∝ z²), grazing-angle dropouts and holes at
/// depth discontinuities; 0 = no data. Range 0.1–10 m.
pub fn depth_counts(r: &DepthRender, sensor: &Sensor, rng: &mut impl Rng) -> Image<u16> {
    let (w, h) = (r.z_m.width as i64, r.z_m.height as i64);
    let z = &r.z_m.data;
    let mut out = Vec::with_capacity(z.len());
    for p in 0..(w * h) {
        let zi = z[p as usize];
        if !zi.is_finite()
            || !(0.1..10.0).contains(&zi)
            || r.cos.data[p as usize] < sensor.depth_grazing_cos
        {
            out.push(0);
            continue;
        }
        let (x, y) = (p % w, p / w);
        let edge = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            nx >= 0 && ny >= 0 && nx < w && ny < h && {
                let zn = z[(ny * w + nx) as usize];
                !zn.is_finite() || (zn - zi).abs() > 0.03
            }
        });
        if edge && rng.random_bool(sensor.depth_edge_hole.clamp(0.0, 1.0)) {
            out.push(0);
            continue;
        }
        let sigma = sensor.depth_noise_per_m2 * zi * zi;
        let noisy = if sigma > 0.0 {
            zi + Normal::new(0.0, sigma).expect("σ > 0").sample(rng)
        } else {
            zi
        };
        out.push((noisy * 1000.0).round().clamp(1.0, 65535.0) as u16);
    }
    Image {
        width: r.z_m.width,
        height: r.z_m.height,
        data: out,
    }
}

/// Simple shaded RGB (head-light Lambert) of the depth view.
pub fn shaded_rgb(world: &World, camera: &PinholeCamera) -> image::RgbImage {
    let px: Vec<[u8; 3]> = (0..camera.width * camera.height)
        .into_par_iter()
        .map(|p| {
            let ray: Ray<f64> = camera.pixel_ray(p % camera.width, p / camera.width);
            match world.hit(&ray) {
                None => [40, 40, 48],
                Some(h) => {
                    let albedo = match h.surface {
                        Surface::Object(_) => Vector3::new(0.92, 0.9, 0.86),
                        Surface::Person { .. } => Vector3::new(0.85, 0.65, 0.55),
                        Surface::Table => Vector3::new(0.55, 0.38, 0.22),
                        Surface::Heat(_) => Vector3::new(0.9, 0.2, 0.1),
                    };
                    let shade = 0.25 + 0.75 * h.normal.dot(&ray.dir).abs();
                    (albedo * shade * 255.0)
                        .map(|c| c.clamp(0.0, 255.0) as u8)
                        .into()
                }
            }
        })
        .collect();
    image::RgbImage::from_raw(
        camera.width,
        camera.height,
        px.into_iter().flatten().collect(),
    )
    .expect("sizes match")
}

#[cfg(test)]
mod tests {
    use super::*;
    fn camera() -> PinholeCamera {
        PinholeCamera::from_fov(40, 30, 0.9).expect("valid camera")
    }

    /// A small "reflection": a disc of radius 2.3 px with a 0.3-px-wide arm attached, over a
    /// smooth ramp (a mirror's incidence-dependent radiance).
    fn scene(u: f64, v: f64) -> f64 {
        let (du, dv) = (u - 17.3, v - 13.6);
        let disc = du * du + dv * dv < 2.3 * 2.3;
        let arm = (0.0..6.0).contains(&du) && (dv - 0.4 * du - 1.1).abs() < 0.15;
        let ramp = 1e-4 * u + 2e-5 * v;
        ramp + if disc || arm { 1.0 } else { 0.0 }
    }

    #[test]
    fn adaptive_matches_the_full_grid_within_tol_and_probes_flat_pixels() {
        let cam = camera();
        let tol = 1e-3;
        let full = supersampled(&cam, 8, scene);
        let probe = supersampled(&cam, PROBE, scene);
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let adaptive = supersampled_adaptive(&cam, 8, tol, |u, v| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            scene(u, v)
        });
        let worst = |a: &Image<f64>| {
            a.data
                .iter()
                .zip(&full.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
        };
        assert!(
            worst(&adaptive) <= tol,
            "adaptive off by {}",
            worst(&adaptive)
        );
        // The probe's grid alone is far off at the edges and on the arm: the test can tell.
        assert!(worst(&probe) > 0.05, "probe off by only {}", worst(&probe));
        let n = calls.into_inner();
        let pixels = (cam.width * cam.height) as usize;
        let probes = pixels * (PROBE * PROBE) as usize;
        assert!(
            n < probes + pixels * 64 / 4,
            "{n} samples for {pixels} pixels"
        );
        assert!(n > probes + 64 * 20, "{n} samples: too few pixels refined");
    }

    #[test]
    fn adaptive_at_or_below_the_probe_is_the_plain_grid() {
        let cam = camera();
        for s in 1..=PROBE {
            let a = supersampled_adaptive(&cam, s, 0.0, scene);
            assert_eq!(a.data, supersampled(&cam, s, scene).data);
        }
    }
}
