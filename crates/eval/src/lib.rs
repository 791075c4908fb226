//! Evaluation (DESIGN.md §5): how a reconstruction compares with the simulator's truth, and the
//! Table-1 benchmark. The CLI's `demo`, `eval` and `bench objects` are thin layers over it.
//!
//! ```text
//!  Simulation (truth) + reconstructed body/objects ─score─► Evaluation (root error, keypoints,
//!      MPJPE, PA-MPJPE, reflection IoU, object errors)          ▲ metrics (normalised distance …)
//!  benchmark set ─sim::presets::benchmark_scene─► capture ─recon stages 0–2 × variants─┘
//!      ─► Report ─► table.md, results.json, report.html          (output: staged result dirs)
//! ```
//!
//! `views` draws what a report shows (overlays, third-camera renders); `output` writes result
//! directories that appear only when complete. `recon` never depends on this crate or on `sim`.

pub mod bench;
pub mod metrics;
pub mod output;
pub mod score;
pub mod truth;
pub mod views;

pub use score::{Evaluation, Scored, evaluate, score};
pub use truth::Truth;

/// Errors of evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file or directory could not be written or replaced.
    #[error("{path}: {reason}")]
    Output {
        /// The file or directory.
        path: std::path::PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] irmirror_sim::SimError),
    /// A simulated capture did not load.
    #[error(transparent)]
    Capture(#[from] irmirror_capture::CaptureError),
    /// Reconstruction failed where the benchmark cannot count it as a failed result.
    #[error(transparent)]
    Recon(#[from] irmirror_recon::ReconError),
    /// The body model failed.
    #[error(transparent)]
    Body(#[from] irmirror_body::BodyError),
    /// The pose prior failed.
    #[error(transparent)]
    Prior(#[from] irmirror_body::prior::PriorError),
    /// A camera transform is not rigid.
    #[error(transparent)]
    Geom(#[from] irmirror_geom::GeomError),
    /// A file of a result or of a capture's truth that is missing or malformed.
    #[error("{path}: {reason}")]
    Input {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A benchmark selection that selects nothing.
    #[error("{0}")]
    Selection(String),
    /// Serialising a report failed.
    #[error("cannot serialise the report: {0}")]
    Serialise(String),
}
