//! Geometry basics shared by every irmirror crate.
//!
//! ```text
//!  pixel (col+0.5, row+0.5) ──PinholeCamera::ray──► Ray (camera frame) ──a_from_b──► Ray (depth frame)
//!  TriMesh ──ply / obj / gltf──► files          TriMesh ──raster──► depth / silhouette preview
//!  axis-angle / 6-D ──rotation──► 3×3 rotation (+ vector–Jacobian products)
//! ```
//!
//! Conventions (DESIGN.md §3): the reconstruction frame is the depth camera's, OpenCV axes
//! (+X right, +Y down, +Z forward), metres. Transforms are named `a_from_b`, so
//! `depth_from_thermal * p_thermal` is a point in the depth frame. Pixel (col i, row j) has its
//! centre at (i + 0.5, j + 0.5).
//!
//! The small shared types that STYLE.md puts in a `core` crate (transforms, rays, seeded RNG,
//! float trait) live here while they stay tiny.

pub mod camera;
pub mod category;
pub mod error;
pub mod gltf;
pub mod isosurface;
pub mod mesh;
pub mod obj;
pub mod optim;
pub mod ply;
pub mod raster;
pub mod ray;
pub mod real;
pub mod rng;
pub mod rotation;
pub mod transform;

pub use camera::PinholeCamera;
pub use category::{CAR_LENGTH_M, Category};
pub use error::GeomError;
pub use mesh::TriMesh;
pub use ray::Ray;
pub use real::Real;
pub use transform::{Rigid3, Similarity3};

/// Re-exported so downstream crates name the same matrix types.
pub use nalgebra;
