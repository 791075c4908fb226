//! Stage 1 (paper §3.5 "3D object reconstruction", DESIGN.md §1): per object, the similarity
//! `depth_from_object` (R, t, s) and the shape parameters of its category's prior, fitted to the
//! depth points inside its mask.
//!
//! The prior is the procedural family of [`irmirror_render::shapes`] (2 parameters per
//! category); with [`ObjectPrior::Learned`] the category's learned DeepSDF prior then takes over
//! from that fit ([`fit_learned`]: latent and placement together).
//!
//! Loss (all distances in units of the initial object size `s₀`, so one schedule fits a mug and
//! a car):
//! * `L_depth` — two forms. Rendered: a subsample of the depth pixels' camera rays is
//!   sphere-traced into the current object and the hit distance compared with the measured one
//!   (Huber, i.e. L1 beyond 3 mm), differentiated by the implicit function theorem at the hit
//!   (`dt/dθ = −(∂F/∂θ)/(∇F·r)`); grazing rays are skipped. Point form: Huber of the signed
//!   distance of every observed point (zero exactly when the surface passes through the measured
//!   depth; smooth where rays miss the current object, so it pulls from afar). The rendered form
//!   removed a 2–3 mm bias of the point form alone (20 seeds: bowl translation median 2.4 →
//!   0.3 mm, mug scale max 11 → 1.6 %; `irmirror bench objects`). Its weight is 0.3: at 1 the
//!   car's door (mean point residual 2.6 mm, the depth noise at 1.5–2.5 m) fitted worse across
//!   its length (≤ 9 → 28 mm over 4 seeds);
//! * `L_mask` — free space: points just in front of the observed surface, and points along the
//!   rays of a ring of pixels around the mask (where the depth camera saw past the object), must
//!   lie outside (one-sided Huber of `d`, as `L_depth`'s point form): this is what keeps the
//!   silhouette from growing;
//! * `L_prior` — the object stands upright on the support plane: `‖R ŷ − n‖²` and the base's
//!   height above the plane squared; for categories whose size the view cannot fix (a car's
//!   side fills the image), a log-normal prior on the metric size.
//!
//! Optimiser: Adam on (rotation tangent δ, t, log s, shape u ∈ [0,1]²), learning rates decaying
//! by cosine to 5 %, `iterations` steps from each restart (yaws evenly spread about the plane
//! normal; eight for a mug, whose handle's side is otherwise often missed) × starting shapes
//! (two proportions; a bowl three walls as well), each run's best iterate kept. Then every run
//! is polished by Levenberg–Marquardt on the same loss written as residuals (`polish_iterations`
//! steps; its Jacobian as below) and the best run kept:
//! the depth camera barely sees a bowl's wall, so the loss is nearly flat along wall ↔ cut ↔
//! scale, where Adam's per-coordinate steps wander and stop wherever the schedule ends
//! (held-out bowls fitted 1.5–2× too thick, their lips mirroring the person up to 52 cm off;
//! with the polish 0.040 / 0.070 / 0.060 / 0.064 for 0.042 / 0.070 / 0.059 / 0.063). A mug gets
//! up to three more restarts (then polished too), each turned so that its handle points at the
//! depth points one of the three best runs' cup leaves unexplained (a 2 mm handle tube a few
//! pixels wide has no gradient towards points 20° away, so all eight yaws can miss it; from the
//! best run alone, a tuning-set mug stayed 24 % too large). Rotation and translation gradients
//! are analytic (chain rule through the SDF gradient). Adam takes the 2 shape parameters'
//! by central differences of the whole loss, one parameter per step in turn (both every step
//! re-traced every rendered ray four times, two thirds of stage 1's time); the polish's
//! Jacobian by the chain rule through per-point differences of the SDF (`loss::ShapeDiff`; at a
//! rendered ray's hit by the implicit function theorem), which misses the rendered depth's
//! jumps across a rim — the wall's evidence Adam needs from afar, not the polish near a
//! minimum (measured in README, "Stage 1's shape gradient"). A mug also gets one restart from
//! the best run with its height set to the observed top's (`fit::height_restart`).
//!
//! Files: [`family`] (shape families), [`observation`] (what a fit sees), [`loss`] (the loss,
//! its gradient and its residuals), [`fit`] (Adam restarts, the polish; the learned prior),
//! [`stage`] (the driver).

mod family;
mod fit;
mod loss;
mod observation;
mod restart;
mod silhouette;
mod stage;

pub use family::Family;
pub use fit::{fit_family, fit_learned};
pub use observation::{ObjectObservation, observe};
pub use stage::reconstruct_objects;

use crate::ReconError;
use crate::plane::Ground;
use family::family_mesh;
use irmirror_capture::Image;
use irmirror_geom::{Category, Similarity3, TriMesh};
use irmirror_render::sdf::PlacedSdf;
use irmirror_render::shapes::Shape;
use irmirror_sdf::placed::PlacedFitConfig;
use irmirror_sdf::{LatentSdf, SdfNet};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Stage-1 settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectConfig {
    /// Adam steps per restart.
    pub iterations: u32,
    /// Levenberg–Marquardt steps (accepted or rejected) polishing each restart after Adam;
    /// 0 turns the polish off.
    pub polish_iterations: u32,
    /// Yaw restarts for shapes that are not bodies of revolution (a mug uses all; a car two).
    pub restarts: u32,
    /// Surface points used (evenly subsampled).
    pub max_points: usize,
    /// Initial learning rates: rotation (rad), translation and log-scale (in s₀), shape (unit box).
    pub lr_rotation: f64,
    /// See `lr_rotation`.
    pub lr_translation: f64,
    /// See `lr_rotation`.
    pub lr_scale: f64,
    /// See `lr_rotation`.
    pub lr_shape: f64,
    /// Huber width of `L_depth`, metres.
    pub huber_m: f64,
    /// Weights of `L_mask` and `L_prior`.
    pub w_free: f64,
    /// See `w_free`.
    pub w_plane: f64,
    /// Ring of pixels around the mask that must be free space, pixels. 8: a mug started too
    /// large (its handle widens the points' spread) grew 2–3 cm taller than the truth, past a
    /// 3-pixel ring, where nothing said the camera saw the table behind it (measured: with 3,
    /// 2 of 9 tuning-set mugs ≥ 40 % off in wall, scale +17–24 %; with 8 none over 9 %; 16
    /// samples too sparsely).
    pub ring_px: u32,
    /// The run kept is the one with the fewest outline errors (mask pixels its rendered outline
    /// misses, ring pixels it stands in front of) among the runs within this fraction of the
    /// lowest loss; 0 keeps the lowest loss.
    pub outline_tolerance: f64,
    /// Weight of the category size prior (per σ², see `Family::size_prior`).
    pub w_size: f64,
    /// Weight of the rendered-depth term (sphere-traced depth against the measured depth).
    pub w_depth: f64,
    /// Camera rays rendered for it (evenly subsampled from the surface points).
    pub depth_rays: usize,
    /// Which prior is fitted: the two-parameter family alone, or then the learned DeepSDF prior.
    pub prior: ObjectPrior,
    /// The learned prior's fit (latent and placement together, from the family fit).
    pub learned: PlacedFitConfig,
    /// Training codes of the learned prior screened, with its mean latent, for the fit's start
    /// (`irmirror_sdf::placed::best_start`; 0: the mean latent alone).
    pub latent_starts: usize,
}

/// The shape prior stage 1 fits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectPrior {
    /// The renderer's two-parameter family of the category ([`Family`]).
    #[default]
    Simple,
    /// The family fit, then the category's learned DeepSDF prior (`assets/object_priors`):
    /// its latent and the placement fitted together ([`irmirror_sdf::placed`]). Spheres keep
    /// the family fit.
    Learned,
}

impl Default for ObjectConfig {
    fn default() -> Self {
        Self {
            iterations: 160,
            polish_iterations: 30,
            restarts: 8,
            max_points: 800,
            lr_rotation: 0.05,
            lr_translation: 0.04,
            lr_scale: 0.04,
            lr_shape: 0.05,
            huber_m: 0.003,
            w_free: 1.0,
            w_plane: 0.3,
            ring_px: 8,
            outline_tolerance: 0.25,
            w_size: 1e-3,
            w_depth: 0.3,
            depth_rays: 200,
            prior: ObjectPrior::Simple,
            learned: PlacedFitConfig::default(),
            latent_starts: 64,
        }
    }
}

/// One fitted object.
#[derive(Clone, Debug, Serialize)]
pub struct FittedObject {
    /// Category (from the capture, or the best-fitting family).
    pub category: Category,
    /// Fitted shape and parameters.
    pub shape: Shape,
    /// Object frame → depth frame (rotation, translation in metres, scale in metres per unit).
    #[serde(serialize_with = "ser_sim")]
    pub depth_from_object: Similarity3<f64>,
    /// Loss of the kept state (the best iterate of the best restart).
    pub loss: f64,
    /// Mean |signed distance| of the observed surface points to the fitted surface, metres.
    pub mean_surface_error_m: f64,
    /// Observed points used.
    pub points: usize,
    /// Loss after every iteration of the kept restart.
    #[serde(skip)]
    pub loss_curve: Vec<f64>,
    /// The learned prior's shape when it was fitted: `depth_from_object` then places the prior's
    /// normalised frame, and `shape` is the family fit it started from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learned: Option<LearnedShape>,
}

/// A fitted shape of a learned prior.
#[derive(Clone, Serialize)]
pub struct LearnedShape {
    /// The prior's latent code.
    pub latent: Vec<f64>,
    /// Lowest object-frame y of the surface.
    pub base_y: f64,
    /// The prior.
    #[serde(skip)]
    pub net: Arc<SdfNet>,
    /// The field of `latent`.
    #[serde(skip)]
    pub sdf: Arc<LatentSdf>,
    /// What the renderer traces, made on first use ([`LearnedShape::traced`]).
    #[serde(skip)]
    pub traced: Arc<std::sync::OnceLock<Arc<dyn irmirror_render::sdf::Sdf>>>,
}

impl LearnedShape {
    /// The field the renderer traces, sampled on first use (stage 2; not stage 1's fit, whose
    /// time it would add to): every fitted field is traced over a whole frame (a car: ≈ 10⁶
    /// rays, each a few dozen values), so a car through its baked copy (`fit::BAKE_CELLS`; its
    /// panels lose 0.11° of normal to it, median), a bowl or mug through a grid that only
    /// speeds the march (`fit::BAND_CELLS`; their thin walls bend within a cell, ≈ 1° at 96³),
    /// the network answering near the surface. If sampling fails, the network itself (logged).
    pub fn traced(&self, category: Category) -> Arc<dyn irmirror_render::sdf::Sdf> {
        self.traced
            .get_or_init(|| {
                let baked = if category == Category::Car {
                    self.sdf.baked(fit::BAKE_CELLS)
                } else {
                    self.sdf.baked_banded(fit::BAND_CELLS)
                };
                match baked {
                    Ok(b) => Arc::new(b),
                    Err(e) => {
                        tracing::warn!("tracing the {category} prior's network itself: {e}");
                        self.sdf.clone()
                    }
                }
            })
            .clone()
    }
}

impl std::fmt::Debug for LearnedShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LearnedShape")
            .field("latent", &self.latent)
            .field("base_y", &self.base_y)
            .finish_non_exhaustive()
    }
}

fn ser_sim<S: serde::Serializer>(s: &Similarity3<f64>, ser: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeStruct;
    let r = s.rotation;
    let mut st = ser.serialize_struct("Similarity", 3)?;
    st.serialize_field(
        "rotation",
        &[
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ],
    )?;
    st.serialize_field(
        "translation_m",
        &[s.translation.x, s.translation.y, s.translation.z],
    )?;
    st.serialize_field("scale_m", &s.scale)?;
    st.end()
}

impl FittedObject {
    /// The object as a renderer SDF.
    pub fn placed(&self) -> PlacedSdf {
        match &self.learned {
            Some(l) => PlacedSdf {
                sdf: l.traced(self.category),
                depth_from_object: self.depth_from_object,
            },
            None => PlacedSdf {
                sdf: self.shape.sdf(),
                depth_from_object: self.depth_from_object,
            },
        }
    }

    /// Lowest object-frame y of the fitted surface.
    pub fn base_y(&self) -> f64 {
        self.learned
            .as_ref()
            .map_or_else(|| self.shape.base_y(), |l| l.base_y)
    }

    /// The fitted surface as a mesh in the depth frame, `resolution` cells across the object
    /// (a learned shape: batched network evaluation, pieces of ≥ 0.5 % of the largest one's volume).
    pub fn mesh(&self, resolution: usize) -> Result<TriMesh, ReconError> {
        let s = &self.depth_from_object;
        let mut m = match &self.learned {
            Some(l) => irmirror_sdf::quality::extract_mesh(&l.net, &l.latent, resolution)?
                .main_components(irmirror_sdf::quality::MAIN_PART_FRACTION),
            None => family_mesh(&self.shape, resolution),
        };
        m.map_vertices(|v| {
            s.transform_point(&Vector3::from(v.map(f64::from)))
                .map(|x| x as f32)
                .into()
        });
        Ok(m)
    }
}

/// Stage-1 settings (plane, segmentation, fit).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Stage1Config {
    /// Support-plane RANSAC.
    pub plane: crate::plane::PlaneConfig,
    /// Segmentation of objects without masks.
    pub segment: crate::segment::SegmentConfig,
    /// Per-object fit.
    pub fit: ObjectConfig,
}

/// Stage-1 products.
#[derive(Clone, Debug)]
pub struct Objects {
    /// Up, and the support plane where one was found.
    pub ground: Ground,
    /// Fitted objects, in the capture's object order.
    pub objects: Vec<FittedObject>,
    /// The depth-pixel mask each object was fitted to.
    pub masks: Vec<Image<bool>>,
    /// Which masks came from segmentation (rather than the capture).
    pub segmented: Vec<bool>,
}

impl Objects {
    /// The fitted objects as renderer SDFs.
    pub fn placed(&self) -> Vec<PlacedSdf> {
        self.objects.iter().map(FittedObject::placed).collect()
    }
}
