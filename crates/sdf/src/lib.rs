//! Object shape priors (DESIGN.md §2, issue 4): DeepSDF auto-decoders trained by our own command
//! on procedural shape families and on user meshes, instead of ShapeNet.
//!
//! ```text
//! families (bowl, mug, car; analytic, documented parameters)
//!    └─ isosurface ─► watertight unit-sphere mesh ─┐
//! user meshes (OBJ / PLY / STL) ─ normalise ───────┴─► mesh_sdf: near-surface + uniform samples,
//!                                                      sign by generalised winding number
//!    └─► train: auto-decoder (latent ⊕ point → SDF), clamped L1 + latent prior, Adam
//!    └─► SdfNet (frozen weights): SDF value + gradient per point (the renderer's `Sdf`), batched;
//!        infer: latent from SDF samples or from surface + free-space points; mesh extraction
//!    └─► placed: latent and similarity fitted together to depth points (stage 1, learned prior)
//! ```
//!
//! Object frame (shared with `irmirror_render::shapes`): **+Y up**, **+X front** (car nose, mug
//! handle), the surface inside the unit sphere. Candle stays inside `net`, `train` and `infer`.

pub mod families;
pub mod infer;
pub mod mesh_io;
pub mod mesh_sdf;
pub mod net;
pub mod placed;
pub mod quality;
mod shared;
pub mod train;
pub mod unseen;
mod var_adam;

pub use families::{Category, FamilyShape};
pub use mesh_sdf::{MeshSdf, SdfSamples};
pub use net::{LatentSdf, SdfNet};
pub use unseen::UnseenShape;

/// Errors of the shape priors.
#[derive(Debug, thiserror::Error)]
pub enum SdfError {
    /// A tensor operation failed.
    #[error("shape prior: {0}")]
    Candle(#[from] candle_core::Error),
    /// A mesh could not be read or is unusable.
    #[error("mesh {path}: {reason}")]
    Mesh {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A weights file is not a shape prior of this architecture.
    #[error("shape prior weights {path}: {reason}")]
    Weights {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A category without a learned prior (a sphere).
    #[error("no learned prior for the category `{0}` (there are priors for bowl, mug and car)")]
    NoPrior(Category),
    /// Invalid arguments (empty sample set, wrong latent length …).
    #[error("{0}")]
    Invalid(String),
}
