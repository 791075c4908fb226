//! The differentiable thermal-reflection renderer (paper §3.4, DESIGN.md §1 stage 2 and §7).
//!
//! ```text
//!  camera pixel ─ray─► SDF objects (sdf) ─sphere_trace─► surface point + normal
//!        ─(smoothing over a ring on the surface)─► reflect ─► ReflectedRays (once per capture)
//!  ReflectedRays × body mesh ─occupancy (BVH-culled)─► I_i ─soft_iou_loss─► L
//!  ∂L/∂I ─occupancy backward─► ∂L/∂(vertices, ray origins, ray directions)
//!  ReflectedRays × mesh ─hard─► binary reflection mask (simulator, reports)
//! ```
//!
//! All frames are the depth camera's (metres). Kernels are generic over `f32`/`f64` so the
//! gradient tests run in f64.

pub mod baked;
pub mod bench_scene;
pub mod bvh;
pub mod distance;
pub mod hard;
pub mod npy;
pub mod occupancy;
pub mod reflect;
pub mod sdf;
pub mod shapes;
pub mod sphere_trace;

pub use bvh::Bvh;
pub use occupancy::{
    Aggregation, Culling, Nearest, Occupancy, OccupancyGrad, OccupancyParams, SoftRenderer,
    soft_iou, soft_iou_loss, soft_iou_weighted,
};
pub use reflect::{Normals, ReflectedRays, reflect_camera, reflect_camera_at};
pub use sdf::{Bowl, Capsule, PlacedSdf, RoundedCylinder, Sdf, Sphere};
pub use sphere_trace::{SurfaceMethod, TraceParams};

/// Errors of the render crate (file loading; rendering itself cannot fail).
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A file could not be read or parsed.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
}
