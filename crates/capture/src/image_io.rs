//! Single-channel images and the PNG/TIFF/`.npy` codecs the format uses.

use crate::CaptureError;
use image::{DynamicImage, ImageBuffer, Luma};
use std::path::Path;

/// A row-major `[height, width]` image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image<T> {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major pixels.
    pub data: Vec<T>,
}

impl<T: Copy> Image<T> {
    /// An image filled with `v`.
    pub fn filled(width: u32, height: u32, v: T) -> Self {
        Self {
            width,
            height,
            data: vec![v; (width * height) as usize],
        }
    }
    /// The pixel at (col, row).
    pub fn at(&self, col: u32, row: u32) -> T {
        self.data[(row * self.width + col) as usize]
    }
    /// Applies `f` to every pixel.
    pub fn map<U>(&self, mut f: impl FnMut(T) -> U) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&x| f(x)).collect(),
        }
    }
}

fn decode(path: &Path) -> Result<DynamicImage, CaptureError> {
    let bytes = std::fs::read(path).map_err(|e| CaptureError::file(path, e.to_string()))?;
    image::load_from_memory(&bytes).map_err(|e| {
        CaptureError::file(
            path,
            format!("cannot decode the image ({e}): truncated or not an image?"),
        )
    })
}

/// Reads a 16-bit single-channel PNG/TIFF; 8-bit and colour images are errors (they cannot
/// hold depth in millimetres or radiometric counts).
pub fn read_gray16_png(path: &Path) -> Result<Image<u16>, CaptureError> {
    match decode(path)? {
        DynamicImage::ImageLuma16(img) => Ok(Image {
            width: img.width(),
            height: img.height(),
            data: img.into_raw(),
        }),
        other => Err(CaptureError::file(
            path,
            format!(
                "expected a 16-bit single-channel image, found {:?}",
                other.color()
            ),
        )),
    }
}

/// Reads a single-channel float image: `.npy` (f32/f64, 2-D, C order) or a 32-bit float TIFF.
pub fn read_float(path: &Path) -> Result<Image<f64>, CaptureError> {
    let fail = |r: String| CaptureError::file(path, r);
    if path.extension().and_then(|e| e.to_str()) == Some("npy") {
        let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
        let npy = npyz::NpyFile::new(bytes.as_slice())
            .map_err(|e| fail(format!("not a .npy file: {e}")))?;
        let shape = npy.shape().to_vec();
        let [h, w] = shape[..] else {
            return Err(fail(format!("expected a 2-D array, got shape {shape:?}")));
        };
        if npy.order() != npyz::Order::C {
            return Err(fail("Fortran-ordered arrays are not supported".into()));
        }
        let descr = npy.dtype().descr().trim_matches('\'').to_string();
        let io = |e: std::io::Error| fail(format!("truncated or corrupt data: {e}"));
        let data: Vec<f64> = match descr.as_str() {
            "<f4" => npy
                .into_vec::<f32>()
                .map_err(io)?
                .into_iter()
                .map(f64::from)
                .collect(),
            "<f8" => npy.into_vec::<f64>().map_err(io)?,
            d => {
                return Err(fail(format!(
                    "unsupported dtype {d}: thermal .npy must be float32 or float64"
                )));
            }
        };
        if data.len() as u64 != h * w {
            return Err(fail("truncated data".into()));
        }
        return Ok(Image {
            width: w as u32,
            height: h as u32,
            data,
        });
    }
    match decode(path)? {
        DynamicImage::ImageLuma16(img) => Ok(Image {
            width: img.width(),
            height: img.height(),
            data: img.into_raw().into_iter().map(f64::from).collect(),
        }),
        DynamicImage::ImageRgb32F(img) => Ok(Image {
            width: img.width(),
            height: img.height(),
            data: img.pixels().map(|p| f64::from(p[0])).collect(),
        }),
        other => Err(CaptureError::file(
            path,
            format!(
                "expected a float or 16-bit single-channel image, found {:?}",
                other.color()
            ),
        )),
    }
}

/// Reads any single image as grey values: `.npy` and float TIFF as [`read_float`], 16-bit
/// grey as counts, 8-bit grey or colour as luma (0–255). For calibration images, whose units do
/// not matter.
pub fn read_gray_any(path: &Path) -> Result<Image<f64>, CaptureError> {
    if path.extension().and_then(|e| e.to_str()) == Some("npy") {
        return read_float(path);
    }
    let img = decode(path)?;
    let (width, height) = (img.width(), img.height());
    let data = match img {
        DynamicImage::ImageLuma16(i) => i.into_raw().into_iter().map(f64::from).collect(),
        DynamicImage::ImageRgb32F(i) => i.pixels().map(|p| f64::from(p[0])).collect(),
        other => other
            .into_luma8()
            .into_raw()
            .into_iter()
            .map(f64::from)
            .collect(),
    };
    Ok(Image {
        width,
        height,
        data,
    })
}

/// `img` as 8-bit grey, stretched between its 1st and 99th percentiles inside `region` (the
/// whole image when the region is empty or has no finite value), so that a reflection a few
/// tenths of a kelvin warm shows against a room tens of kelvin wide. Pixels outside a non-empty
/// region are drawn at a third of their grey, so the region's outline shows. Non-finite pixels
/// are black.
pub fn stretch_percentiles(img: &Image<f64>, region: &Image<bool>) -> Image<u8> {
    let pick = |use_region: bool| -> Vec<f64> {
        img.data
            .iter()
            .zip(&region.data)
            .filter(|(v, r)| (!use_region || **r) && v.is_finite())
            .map(|(v, _)| *v)
            .collect()
    };
    let mut vals = pick(true);
    let dim = !vals.is_empty();
    if vals.is_empty() {
        vals = pick(false);
    }
    vals.sort_by(f64::total_cmp);
    let q = |f: f64| {
        vals.get(((vals.len().max(1) - 1) as f64 * f).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    let (lo, hi) = (q(0.01), q(0.99));
    let span = (hi - lo).max(1e-12);
    let data = img
        .data
        .iter()
        .zip(&region.data)
        .map(|(&v, &inside)| {
            if !v.is_finite() {
                return 0;
            }
            let g = ((v - lo) / span * 255.0).clamp(0.0, 255.0);
            (if dim && !inside { g / 3.0 } else { g }) as u8
        })
        .collect();
    Image {
        width: img.width,
        height: img.height,
        data,
    }
}

/// Reads a mask: any PNG; a pixel is inside where its first channel is non-zero.
pub fn read_mask(path: &Path) -> Result<Image<bool>, CaptureError> {
    let img = decode(path)?.into_luma16();
    Ok(Image {
        width: img.width(),
        height: img.height(),
        data: img.into_raw().into_iter().map(|v| v > 0).collect(),
    })
}

/// Reads an 8-bit RGB image.
pub fn read_rgb(path: &Path) -> Result<(u32, u32), CaptureError> {
    let img = decode(path)?;
    if img.color().bytes_per_pixel() < 3 {
        return Err(CaptureError::file(
            path,
            format!("expected an RGB image, found {:?}", img.color()),
        ));
    }
    Ok((img.width(), img.height()))
}

/// Writes a 16-bit grayscale PNG.
pub fn write_gray16_png(img: &Image<u16>, path: &Path) -> Result<(), CaptureError> {
    let buf: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_raw(img.width, img.height, img.data.clone())
            .ok_or_else(|| CaptureError::file(path, "image size mismatch"))?;
    buf.save(path)
        .map_err(|e| CaptureError::file(path, e.to_string()))
}

/// Writes an 8-bit grayscale PNG.
pub fn write_gray8_png(img: &Image<u8>, path: &Path) -> Result<(), CaptureError> {
    let buf: ImageBuffer<Luma<u8>, Vec<u8>> =
        ImageBuffer::from_raw(img.width, img.height, img.data.clone())
            .ok_or_else(|| CaptureError::file(path, "image size mismatch"))?;
    buf.save(path)
        .map_err(|e| CaptureError::file(path, e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stretch spans the region's values, not the whole frame's: a hot room corner outside
    /// the region saturates instead of squeezing the region into a few grey levels.
    #[test]
    fn stretch_uses_the_region_percentiles() {
        // 100 region pixels from 20.0 to 20.99 K, then 100 pixels of a 60 K heater outside it.
        let mut data: Vec<f64> = (0..100).map(|i| 20.0 + 0.01 * f64::from(i)).collect();
        data.extend(std::iter::repeat_n(60.0, 100));
        let img = Image {
            width: 200,
            height: 1,
            data,
        };
        let region = Image {
            width: 200,
            height: 1,
            data: (0..200).map(|i| i < 100).collect(),
        };
        let g = stretch_percentiles(&img, &region);
        assert_eq!(g.data[0], 0);
        assert_eq!(g.data[50], 128, "{:?}", &g.data[45..55]);
        assert_eq!(g.data[99], 255);
        assert_eq!(g.data[150], 85, "outside the region: a third of its grey");
        // An empty region falls back to the whole image (the heater is then the 99th percentile).
        let none = Image {
            width: 200,
            height: 1,
            data: vec![false; 200],
        };
        let g = stretch_percentiles(&img, &none);
        assert!(g.data[50] < 10 && g.data[150] == 255);
    }
}
