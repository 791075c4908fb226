//! Synthetic captures with ground truth (DESIGN.md §4, §6): a scene (objects, table, person,
//! heat sources, room) rendered radiometrically to an LWIR thermal frame and a background frame
//! without the person, a depth image with sensor artefacts, shaded RGB and object masks, written
//! in the capture format; `truth/` holds what only evaluation may read.
//!
//! ```text
//!  SceneFile (preset + seed, or a file) ─► World (depth frame: SDF objects, posed body BVH, table)
//!     thermal: per sub-pixel ray, ε B(T) + (1 − ε) L(reflected ray), Planck 8–14 µm ─► blur ─► NETD ─► 14-bit
//!     depth: nearest hit z ─► noise ∝ z², grazing dropouts, edge holes ─► 16-bit mm
//!  ─► capture.toml, depth.png, thermal.png, thermal_background.png, rgb.png, masks/, truth/
//! ```

pub mod board;
pub mod people;
pub mod presets;
pub mod scene;
pub mod sensor;
pub use irmirror_render::shapes;
pub mod simulate;
pub mod world;

pub use scene::{SceneFile, Sensor, ThermalPreset};
pub use simulate::{SimReport, Simulation, simulate};

/// Errors of the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// An impossible scene.
    #[error("scene: {0}")]
    Scene(String),
    /// The body model refused a parameter.
    #[error(transparent)]
    Body(#[from] irmirror_body::BodyError),
    /// Writing failed.
    #[error(transparent)]
    Capture(#[from] irmirror_capture::CaptureError),
    /// Writing failed.
    #[error("{path}: {reason}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        reason: String,
    },
}
