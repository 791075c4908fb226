//! The capture format (DESIGN.md §4): what a real RGB-D + thermal rig, or the simulator, writes
//! and what reconstruction reads.
//!
//! ```text
//! capture/
//!   capture.toml            cameras, calibration, units, objects (CaptureFile)
//!   depth.png               16-bit, depth along +Z in `depth.units_m` per count, 0 = no data
//!   thermal.png|.tiff|.npy  16-bit counts / centikelvin, or float kelvin / °C
//!   thermal_background*.…   optional frames without the person (same units)
//!   rgb.png                 optional, 8-bit RGB registered to the depth camera
//!   masks/*.png             optional object masks in depth-camera pixels (non-zero = object)
//!   truth/                  simulated captures only; read by evaluation, never by reconstruction
//! ```
//!
//! [`Capture::load`] validates everything and names the file and field of every problem; it never
//! writes to the capture directory.

pub mod flir;
pub mod format;
pub mod image_io;
mod load;
pub mod opencv;
pub mod planck;

pub use format::{
    CameraSpec, CaptureFile, DepthSpec, ExtraCamera, FORMAT, ObjectSpec, RgbSpec, RigFile, RigFit,
    ThermalCameraSpec, ThermalSpec, ThermalUnits,
};
pub use image_io::{Image, read_gray_any, read_gray16_png, write_gray8_png, write_gray16_png};
pub use load::{Capture, CapturedObject};

use std::path::PathBuf;

/// Everything that can be wrong with a capture.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// A file that cannot be read.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A field of `capture.toml` with an impossible value.
    #[error("{path}: field `{field}`: {reason}")]
    Field {
        /// The capture file.
        path: PathBuf,
        /// Dotted field name.
        field: String,
        /// What is wrong.
        reason: String,
    },
}

impl CaptureError {
    pub(crate) fn file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Self::File {
            path: path.into(),
            reason: reason.into(),
        }
    }
}
