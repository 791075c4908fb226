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

/// Mean band radiance over `s × s` sub-pixel rays per pixel of `camera` (placed by
/// `depth_from_camera`).
pub fn thermal_radiance(
    world: &World,
    camera: &PinholeCamera,
    depth_from_camera: &Rigid3<f64>,
    supersample: u32,
) -> Image<f64> {
    supersampled(camera, supersample, |u, v| {
        let ray = depth_from_camera.transform_ray(&camera.ray_at::<f64>(u, v));
        world.radiance(&ray, BOUNCES)
    })
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
        .map(|p| {
            let (col, row) = (p % w, p / w);
            let mut sum = 0.0;
            for a in 0..s {
                for b in 0..s {
                    let u = f64::from(col) + (f64::from(a) + 0.5) / f64::from(s);
                    let v = f64::from(row) + (f64::from(b) + 0.5) / f64::from(s);
                    sum += value(u, v);
                }
            }
            sum / f64::from(s * s)
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
