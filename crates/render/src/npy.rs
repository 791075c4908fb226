//! Reading 2-D masks and images from `.npy` (uint8, bool, float32, float64; C order).

use crate::RenderError;
use std::path::Path;

/// A row-major `[height, width]` array as f64, with its shape.
pub fn read_2d(path: &Path) -> Result<(usize, usize, Vec<f64>), RenderError> {
    let fail = |r: String| RenderError::File {
        path: path.into(),
        reason: r,
    };
    let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    let npy =
        npyz::NpyFile::new(bytes.as_slice()).map_err(|e| fail(format!("not a .npy file: {e}")))?;
    if npy.order() != npyz::Order::C {
        return Err(fail("Fortran-ordered arrays are not supported".into()));
    }
    let shape = npy.shape().to_vec();
    let [h, w] = shape[..] else {
        return Err(fail(format!("expected a 2-D array, got shape {shape:?}")));
    };
    let descr = npy.dtype().descr().trim_matches('\'').to_string();
    let io = |e: std::io::Error| fail(format!("truncated or corrupt data: {e}"));
    let data: Vec<f64> = match descr.as_str() {
        "|u1" => npy
            .into_vec::<u8>()
            .map_err(io)?
            .into_iter()
            .map(f64::from)
            .collect(),
        "|b1" => npy
            .into_vec::<bool>()
            .map_err(io)?
            .into_iter()
            .map(|b| if b { 1.0 } else { 0.0 })
            .collect(),
        "<f4" => npy
            .into_vec::<f32>()
            .map_err(io)?
            .into_iter()
            .map(f64::from)
            .collect(),
        "<f8" => npy.into_vec::<f64>().map_err(io)?,
        d => {
            return Err(fail(format!(
                "unsupported dtype {d} (use uint8, bool, float32 or float64)"
            )));
        }
    };
    if data.len() as u64 != h * w {
        return Err(fail(format!("{} values for shape {h}×{w}", data.len())));
    }
    if data.iter().any(|x| !x.is_finite()) {
        return Err(fail("contains NaN or infinite values".into()));
    }
    Ok((h as usize, w as usize, data))
}
