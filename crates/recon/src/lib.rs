//! Reconstruction (DESIGN.md §1). Built so far: stage 0, thermal preprocessing. Stages 1 (objects)
//! and 2 (human) follow with the object priors. `recon` never depends on `sim`: ground truth cannot
//! leak into reconstruction (the simulator is a dev-dependency for tests only).
//!
//! ```text
//!  Capture ─► thermal rise over background (frames, or a local median) ─► object pixels in the
//!  thermal view (depth + masks projected through depth_from_thermal) ─► threshold (Otsu, floored
//!  at 4 σ of the noise) ─► open/close ─► reflection mask + edge map
//! ```

pub mod morphology;
pub mod preprocess;

pub use preprocess::{PreprocessConfig, Preprocessed, Threshold, preprocess};

/// Errors of reconstruction.
#[derive(Debug, thiserror::Error)]
pub enum ReconError {
    /// The capture has no usable object pixels in the thermal view.
    #[error("no object pixel of the capture falls inside the thermal image: check the masks and depth_from_thermal")]
    NoObjectPixels,
    /// No pixel on an object is warmer than the background by the threshold.
    #[error("no reflection: no object pixel is warmer than its background by {threshold_k:.3} K (largest rise {max_rise_k:.3} K)")]
    NoReflection {
        /// The threshold used, K.
        threshold_k: f64,
        /// The largest rise found on an object, K.
        max_rise_k: f64,
    },
}
