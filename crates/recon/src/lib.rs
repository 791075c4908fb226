//! Reconstruction (DESIGN.md §1): stage 0 (thermal preprocessing), stage 1 (the objects: support
//! plane, segmentation, per-object fits with the procedural families or the learned priors) and
//! stage 2 (the person from the reflection). `recon` never depends on `sim`: ground truth cannot
//! leak into reconstruction (the simulator is a dev-dependency for tests only).
//!
//! ```text
//!  Capture ─preprocess─► reflection mask + edges
//!  depth ─plane / segment─► object masks ─objects─► FittedObject per object (+ Ground)
//!  objects + thermal camera ─pipeline::reflected_rays─► ReflectedRays
//!  ReflectedRays × body (pose prior, soft occupancy) ─human─► hypotheses, best first
//! ```

pub mod depth_mirror;
pub mod human;
pub mod morphology;
pub mod objects;
pub mod pipeline;
pub mod plane;
pub mod preprocess;
pub mod segment;

pub use preprocess::{PreprocessConfig, Preprocessed, Threshold, preprocess};

/// Errors of reconstruction.
#[derive(Debug, thiserror::Error)]
pub enum ReconError {
    /// The capture has no usable object pixels in the thermal view.
    #[error(
        "no object pixel of the capture falls inside the thermal image: check the masks and depth_from_thermal"
    )]
    NoObjectPixels,
    /// An object mask covers (almost) no valid depth.
    #[error("an object mask covers only {pixels} pixels with valid depth (at least 10 are needed)")]
    EmptyObject {
        /// Valid pixels found.
        pixels: usize,
    },
    /// No near-horizontal plane under the objects.
    #[error(
        "no support plane (table or ground) found in the depth image: segmentation needs one to find objects without masks; give masks"
    )]
    NoSupportPlane,
    /// Fewer clusters than objects without masks.
    #[error(
        "segmentation found {found} object clusters above the support plane but the capture lists {wanted} objects without masks; give masks"
    )]
    Segmentation {
        /// Objects without masks.
        wanted: usize,
        /// Clusters found.
        found: usize,
    },
    /// No pixel of the reflection mask lies on a fitted object.
    #[error(
        "no pixel of the reflection mask lies on a fitted object, so no reflected ray can see the person; check the object fit (stage 1) and depth_from_thermal"
    )]
    NoMaskRays,
    /// The reflection mask covers (nearly) every object pixel: no edge to fit a person to.
    #[error(
        "the reflection mask covers {percent:.0} % of the object pixels (at most {max_percent:.0} % can be a person's reflection): the objects are warmer than their background frame, or the threshold is too low; check the background frames and [preprocess] threshold"
    )]
    MaskCoversObjects {
        /// Object pixels (with a reflected ray) in the mask, %.
        percent: f64,
        /// The largest share accepted, %.
        max_percent: f64,
    },
    /// Every run of a fit diverged (non-finite loss or gradient): a failed result, never a
    /// silently kept last finite state.
    #[error("the {stage} diverged in all {runs} runs (non-finite loss or gradient)")]
    Diverged {
        /// Which fit (`object fit`, `human fit`).
        stage: &'static str,
        /// Runs (restarts, initialisations) tried.
        runs: usize,
    },
    /// The body model refused a parameter.
    #[error("body model: {0}")]
    Body(#[from] irmirror_body::BodyError),
    /// The pose prior failed.
    #[error("pose prior: {0}")]
    PosePrior(#[from] irmirror_body::prior::PriorError),
    /// A learned object prior failed (its weights, or its fit diverged).
    #[error("object prior: {0}")]
    ObjectPrior(#[from] irmirror_sdf::SdfError),
    /// A setting that cannot be used (named in the message).
    #[error("settings: {0}")]
    Config(String),
    /// No pixel on an object is warmer than the background by the threshold.
    #[error(
        "no reflection: no object pixel is warmer than its background by {threshold_k:.3} K (largest rise {max_rise_k:.3} K)"
    )]
    NoReflection {
        /// The threshold used, K.
        threshold_k: f64,
        /// The largest rise found on an object, K.
        max_rise_k: f64,
    },
}
