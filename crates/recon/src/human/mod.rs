//! Stage 2 (paper §3.4–3.5, DESIGN.md §1): the person, from the reflection mask, with the
//! objects fixed.
//!
//! Parameters per hypothesis: root translation `t` (depth frame, m), root rotation
//! `R = exp(ω) B` (`B` the initial orientation), the body's height (Anny's phenotype `height`
//! slider, the other phenotype values at the mean adult: [`shaped_body`]), the pose latent `z`
//! (32, the pose prior) and, beyond the paper, a per-joint **pose residual** `δ` (3 × 35: each
//! body joint's decoded rotation turned by `exp(δ_j)` on its own axes, with a Gaussian prior
//! `w_residual ‖δ‖²`, optionally weaker on a large reflection: `residual_ref_px`; refinement
//! only, the search moves the latent alone). The prior's latent
//! cannot state a pose it was not trained on: on the tuning set its encoding of the true pose
//! put the body 4–12 cm off per vertex and doubled the true body's data term (bowls median
//! 0.15 → 0.37), while the exact pose on the mean adult's proportions stayed within 10 % of
//! it — the proportions cost little, the latent much. Loss: a data term — by default the
//! thermal rise itself ([`radiometric`]: per ray, object reflectance × the met body region's
//! contrast × soft occupancy, against the observed rise; beyond the paper), or the paper's
//! `1 − soft IoU` between the soft occupancy of sampled reflected rays and the observed mask —
//! plus `w_prior ‖z‖²`, the residual's prior, an upright prior, a height prior and — where the
//! floor is known (below a table, or the ground a car stands on) — the body's lowest
//! point on it. The floor and the height together fix what the silhouette alone cannot: a
//! taller person farther away casts the same mirror image as a shorter one nearer. Gradients:
//! occupancy backward → vertices → body backward → rotations, shape → the residual's and the
//! pose prior's VJPs and the phenotype's (piecewise-linear) shape map (all analytic; see the
//! crates' FD tests).
//!
//! * **Edge sampling.** The refinement's fixed batch (`refine_rays`, for a tabletop-sized
//!   capture) draws each
//!   stratum's rays with probability ∝ `(1 − α) + α exp(−e/τ)` at the curriculum's final
//!   `edge_mix` and `edge_tau_px[1]`, importance-weighted: the same loss, estimated with more of
//!   the rays that decide the outline. Ablated: a uniform stratified batch. With
//!   `refine_rays` = 0 (the paper's refinement), each iteration draws `rays_per_iteration` rays without replacement with
//!   weight `(1 − α) + α exp(−e/τ)`, `e` the pixel distance to the mask's edge; α grows from 0 to
//!   `edge_mix` and τ shrinks from `edge_tau_px[0]` to `[1]` over the iterations (curriculum).
//!   Ablated: uniform draws of the same count. With the mask's data term the draws are made
//!   among the **active set** only (`active_margin_m`): the mask's rays and those passing within
//!   that margin of the body, refreshed every `active_every` steps, at most `max_ray_fraction`
//!   of them. The other rays have occupancy ≈ 0 and target 0 and add nothing to the soft IoU,
//!   yet were 98 % of a draw on a car door (a 2,500-pixel reflection among 150,000 object
//!   pixels: ≈ 50 mask rays per step).
//! * **σ annealing.** The occupancy blur shrinks geometrically from `sigma_m2[0]` to `[1]`.
//! * **Global search, then refinement** ([`search`]): candidates over the full circle of facing
//!   directions × distances along the mask's reflected rays × pose-prior modes, scored cheaply
//!   and halved; the survivors and their front/back flips are refined fully. The best by final
//!   full-ray loss is kept; the `top_k` distinct ones are reported, the best one's front/back
//!   partner among them.

mod bank;
mod edge;
mod facing;
mod grid;
mod limbs;
mod observe;
mod polish;
mod problem;
pub mod radiometric;
mod raster;
mod refine;
mod retrieve;
mod scratch;
pub mod search;
mod unseen;

pub use edge::edge_distance;
pub use problem::{Draw, FullEval};
pub use scratch::Scratch;

pub use observe::{Rise, Selection};
pub use refine::Stratified;
pub use retrieve::RetrievalConfig;
pub use search::{SearchConfig, fit_human, flipped};

use crate::ReconError;
use irmirror_body::prior::PosePrior;
use irmirror_body::{BodyModel, Phenotype};
use irmirror_capture::Image;
use irmirror_render::occupancy::Aggregation;
use irmirror_render::reflect::ReflectedRays;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Anny's `height` slider of the mean adult (the default phenotype, ≈ 1.69 m; male adults
/// average ≈ 0.39, female ≈ 0.35).
pub const HEIGHT_MEAN: f64 = 0.37;

/// Stage-2 settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HumanConfig {
    /// Hypotheses refined fully (the global search's survivors and their front/back flips).
    pub inits: usize,
    /// Adam steps per refined hypothesis.
    pub iterations: usize,
    /// Rays drawn per step, at most `max_ray_fraction` of them.
    pub rays_per_iteration: usize,
    /// Largest fraction of all rays drawn per step (edge sampling needs a choice to make).
    pub max_ray_fraction: f64,
    /// Rays of the refinement's fixed batch (stratified, edge-focused when `edge_sampling` is
    /// on, importance-weighted: [`HumanProblem::focused_batch`]) when the reflection has at
    /// most half as many pixels and the capture not many more ([`HumanProblem::refine_sample`]);
    /// else, and with 0, fresh draws every step (edge sampling's curriculum, the paper's
    /// refinement).
    pub refine_rays: usize,
    /// Margin of the active set, m: with the mask's data term, each step draws only among the
    /// mask's rays and those passing within this distance of the body (the others add
    /// nothing to the soft IoU); 0 draws among all rays.
    pub active_margin_m: f64,
    /// Steps between refreshes of the active set.
    pub active_every: usize,
    /// Edge sampling on/off (ablation switch).
    pub edge_sampling: bool,
    /// Final weight α of the edge term.
    pub edge_mix: f64,
    /// Edge length scale τ at the start and the end, pixels.
    pub edge_tau_px: [f64; 2],
    /// Occupancy σ at the start and the end, m².
    pub sigma_m2: [f64; 2],
    /// Learning rates: translation (m), rotation (rad), height slider, latent.
    pub lr_translation: f64,
    /// See `lr_translation`.
    pub lr_rotation: f64,
    /// See `lr_translation`; 0 keeps the height at the prior's mean (the mean adult).
    pub lr_height: f64,
    /// See `lr_translation`.
    pub lr_latent: f64,
    /// Learning rate of the per-joint pose residual (rad): rotations beyond the prior's
    /// latent, which cannot state every pose (its encoding of the benchmark's poses is 4–12 cm
    /// off per vertex). 0: the latent alone, as the paper.
    pub lr_residual: f64,
    /// The share of the learning rates the refinement runs at on its fixed batch
    /// (`refine_rays`; the search's rounds and the refinement on fresh draws run at the full
    /// rates).
    pub refine_lr_scale: f64,
    /// Weight of `‖z‖²`.
    pub w_prior: f64,
    /// Weight of the residual's prior `Σ ‖δ_j‖²` (rad²).
    pub w_residual: f64,
    /// When > 0, on a reflection of `n` > `residual_ref_px` pixels with rays the residual's
    /// prior weighs `w_residual × residual_ref_px / n` ([`HumanProblem::prior_weighted`]).
    /// Off (0) by default: at 500 it helped the tuning cars and not the held-out ones
    /// (EXPERIMENTS.md, "Tenth run").
    pub residual_ref_px: f64,
    /// Weight of the upright prior `1 − (R ẑ)·n` (people stand on the support plane's side:
    /// Anny's up should follow the plane normal; the pose bends the body, not the root).
    pub w_upright: f64,
    /// Weight of the facing prior `1 − cos θ`, θ the angle about the up axis between the
    /// body's front and the direction from its root to the objects' centre, where the person
    /// is taken to face the objects ([`HumanProblem::faces_objects`]: a tabletop — people
    /// whose reflection a bowl or mug shows are at the table, turned towards it more or less;
    /// not by a car, where pedestrians walk any way); 0 switches it off. A soft prior: it
    /// costs a person turned 90° away `w`, turned around `2w`, so it decides between
    /// hypotheses the data term leaves level (a silhouette's front/back twins) and no more.
    /// Default 0.02 (chosen before measuring, about the data term's front/back differences of
    /// 0.01–0.03): on 48 held-out mugs per-vertex −0.068 ± 0.047 m, 2-D keypoints −0.059 ±
    /// 0.040, facing within 30° 15 → 25; on 48 bowls −0.033 ± 0.032 m, −0.024 ± 0.028, 25 → 31
    /// (EXPERIMENTS.md, "Fifty-second run").
    pub w_facing: f64,
    /// Weight of the floor prior `((h_min − 0) / σ)²`, `h_min` the height of the body's lowest
    /// vertex above the floor (people stand, sit or kneel on it); 0 switches it off.
    pub w_floor: f64,
    /// σ of the floor prior, metres.
    pub floor_sigma_m: f64,
    /// Height of a table above the floor, metres, when the support plane is a table (objects
    /// that are not cars): the floor is this far below it (EN 527 desks: 0.72–0.76 m).
    pub table_height_m: f64,
    /// Prior on the height slider: mean and σ (adult stature σ ≈ 7 cm ≈ 0.06 of the slider).
    pub height_prior: [f64; 2],
    /// Weight of the height prior `((h − mean) / σ)²`.
    pub w_height: f64,
    /// The person's build: Anny's phenotype sliders other than the height (its `height` is not
    /// used: the fit's slider starts at `height_prior`'s mean). Not fitted; the mean adult's by
    /// default. `eval --variants true-shape` gives each capture's true build (an oracle that
    /// measures what the fixed build costs the person).
    pub build: Phenotype,
    /// Range of the initial root distances along the mean reflected ray (log-spaced), metres.
    pub init_distance_m: [f64; 2],
    /// The global search before refinement.
    pub search: SearchConfig,
    /// The virtual-view pose retrieval at the search's survivors ([`retrieve`]).
    pub retrieval: RetrievalConfig,
    /// Distinct hypotheses reported.
    pub top_k: usize,
    /// The activity template ([`irmirror_body::prior::generator::TEMPLATES`]) the body parts
    /// no ray sees are reported in ([`unseen`]; default "stand"); empty: as the refinement
    /// left them. On 24 held-out bowls 2-D keypoints −0.056 ± 0.025 (22 better, 1 worse),
    /// per-vertex −0.010 ± 0.008 m; mugs, cars and the hard view level (EXPERIMENTS.md,
    /// "Thirty-first run").
    pub unseen_pose: String,
    /// How far the data term (all rays) may rise when a part takes `unseen_pose`'s
    /// configuration, summed over the parts that take it.
    pub unseen_tolerance: f64,
    /// How the body's triangles form a ray's occupancy (`irmirror_render::occupancy` docs).
    pub aggregation: Aggregation,
    /// The radiometric data term ([`radiometric`]).
    pub radiometric: radiometric::RadiometricConfig,
}

impl HumanConfig {
    /// Refuses settings no fit can run with (a `--config` TOML is user input): a learning
    /// rate, the active set's margin or the polish's rate share negative or not finite, a
    /// blur not positive, a retrieval raster that is not a raster.
    pub fn check(&self) -> Result<(), crate::ReconError> {
        let at_least_zero = [
            ("lr_translation", self.lr_translation),
            ("lr_rotation", self.lr_rotation),
            ("lr_height", self.lr_height),
            ("lr_latent", self.lr_latent),
            ("lr_residual", self.lr_residual),
            ("w_residual", self.w_residual),
            ("w_facing", self.w_facing),
            ("residual_ref_px", self.residual_ref_px),
            ("active_margin_m", self.active_margin_m),
            ("refine_lr_scale", self.refine_lr_scale),
            ("search.yaw_polish_deg", self.search.yaw_polish_deg),
            ("search.place_polish_frac", self.search.place_polish_frac),
            ("unseen_tolerance", self.unseen_tolerance),
            (
                "radiometric.polish_lr_scale",
                self.radiometric.polish_lr_scale,
            ),
        ];
        for (name, v) in at_least_zero {
            if !(v.is_finite() && v >= 0.0) {
                return Err(crate::ReconError::Config(format!(
                    "[human] {name} = {v}: must be a finite number ≥ 0"
                )));
            }
        }
        if self.search.place_polish_frac >= 1.0 {
            return Err(crate::ReconError::Config(format!(
                "[human] search.place_polish_frac = {}: must be below 1 (a move of the whole \
                 distance puts the person on the mirror)",
                self.search.place_polish_frac
            )));
        }
        let templates = irmirror_body::prior::generator::TEMPLATES;
        if !self.unseen_pose.is_empty() && !templates.contains(&self.unseen_pose.as_str()) {
            return Err(crate::ReconError::Config(format!(
                "[human] unseen_pose = {:?}: not an activity template (one of {templates:?}, or \"\" \
                 for none)",
                self.unseen_pose
            )));
        }
        if let Some(v) = self.sigma_m2.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
            return Err(crate::ReconError::Config(format!(
                "[human] sigma_m2 holds {v}: the blur must be a finite number > 0 (m²)"
            )));
        }
        self.retrieval.check()
    }

    /// The same settings with every learning rate scaled by `k`.
    fn lr_scaled(&self, k: f64) -> HumanConfig {
        HumanConfig {
            lr_translation: self.lr_translation * k,
            lr_rotation: self.lr_rotation * k,
            lr_height: self.lr_height * k,
            lr_latent: self.lr_latent * k,
            lr_residual: self.lr_residual * k,
            ..self.clone()
        }
    }

    /// Edge sampling's weight α and length τ (pixels) at `progress` ∈ [0, 1] of a run: α from
    /// 0 to `edge_mix`, τ from `edge_tau_px[0]` to `edge_tau_px[1]`; (0, 1) with it off.
    pub fn edge_schedule(&self, progress: f64) -> (f64, f64) {
        if self.edge_sampling {
            let [t0, t1] = self.edge_tau_px;
            (self.edge_mix * progress, t0 + (t1 - t0) * progress)
        } else {
            (0.0, 1.0)
        }
    }

    /// The fixed-batch refinement's settings: the learning rates scaled by `refine_lr_scale`.
    pub fn refinement(&self) -> HumanConfig {
        self.lr_scaled(self.refine_lr_scale)
    }

    /// The thermal polish's settings: `radiometric.polish_iterations` steps at the final blur,
    /// the learning rates scaled by `radiometric.polish_lr_scale`.
    pub fn polish(&self) -> HumanConfig {
        HumanConfig {
            iterations: self.radiometric.polish_iterations,
            sigma_m2: [self.sigma_m2[1]; 2],
            ..self.lr_scaled(self.radiometric.polish_lr_scale)
        }
    }
}

impl Default for HumanConfig {
    fn default() -> Self {
        Self {
            inits: 6,
            iterations: 150,
            rays_per_iteration: 3000,
            max_ray_fraction: 0.5,
            refine_rays: 3000,
            active_margin_m: 0.25,
            active_every: 10,
            edge_sampling: true,
            edge_mix: 0.9,
            edge_tau_px: [6.0, 1.5],
            sigma_m2: [3e-4, 1e-5],
            lr_translation: 0.04,
            lr_rotation: 0.06,
            lr_height: 0.01,
            lr_latent: 0.08,
            lr_residual: 0.02,
            refine_lr_scale: 0.5,
            w_prior: 2e-3,
            w_residual: 0.1,
            residual_ref_px: 0.0,
            w_upright: 0.05,
            w_facing: 0.02,
            w_floor: 0.01,
            floor_sigma_m: 0.05,
            table_height_m: 0.75,
            height_prior: [HEIGHT_MEAN, 0.06],
            w_height: 2e-3,
            build: Phenotype::default(),
            init_distance_m: [0.7, 8.0],
            search: SearchConfig::default(),
            retrieval: RetrievalConfig::default(),
            top_k: 3,
            unseen_pose: "stand".into(),
            unseen_tolerance: 0.002,
            aggregation: Aggregation::Silhouette,
            radiometric: radiometric::RadiometricConfig::default(),
        }
    }
}

/// One fitted hypothesis.
#[derive(Clone, Debug, Serialize)]
pub struct Hypothesis {
    /// Which initialisation it came from.
    pub init: usize,
    /// Root joint position, depth frame, metres.
    pub translation_m: [f64; 3],
    /// Root rotation (Anny frame → depth frame) as a rotation vector, radians.
    pub root_rotvec_rad: [f64; 3],
    /// Anny's phenotype height slider (see [`HEIGHT_MEAN`]).
    pub height: f64,
    /// The build: the phenotype's other sliders ([`HumanConfig::build`]; its `height` unused).
    pub build: Phenotype,
    /// Stature of the fitted body standing straight (the phenotype's rest mesh), metres.
    pub stature_m: f64,
    /// Pose latent.
    pub latent: Vec<f64>,
    /// Per-joint residual rotations beyond the latent's decoding ([`HumanState::residual`]);
    /// empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub residual: Vec<f64>,
    /// Final loss on all rays at the final σ.
    pub loss: f64,
    /// Its data term alone (`1 − soft IoU`, or the radiometric term).
    pub data_loss: f64,
    /// Soft IoU on all rays at the final σ.
    pub soft_iou: f64,
    /// The radiometric scalars fitted at the end (when that data term is on).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radiometry: Option<FittedRadiometry>,
    /// The data term (all rays) with the head's face and hair turned front to back
    /// ([`radiometric::Radiometry::head_turned`]); below `data_loss` when the thermal image
    /// puts this body's face on the other side of its head. `None` for the mask's data term.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_turned_data_loss: Option<f64>,
    /// Loss per step (on that step's sampled rays).
    #[serde(skip)]
    pub loss_curve: Vec<f64>,
}

/// Stage-2 result.
#[derive(Clone, Debug, Serialize)]
pub struct HumanFit {
    /// Best hypothesis first, then its front/back partner (the best turned > 135° from it,
    /// when one was refined), then distinct others (root > 25 cm apart or facing > 45° apart)
    /// by loss, `top_k` in all. Ranked as refined: each one's fields (loss included) are its
    /// state's after the unseen parts' reset (`unseen_pose`), which moves the priors, so a
    /// later hypothesis may show the lower loss.
    pub hypotheses: Vec<Hypothesis>,
    /// Candidates scored by the global search.
    pub candidates: usize,
    /// Initialisations that diverged (non-finite loss) and were dropped.
    pub diverged: usize,
    /// Reflected rays (object pixels) and mask pixels among them.
    pub rays: usize,
    /// Mask pixels with a ray.
    pub mask_rays: usize,
    /// The data term fitted: "radiometric", "mask", or "mask (fallback: why)".
    pub data_term: String,
}

/// What the radiometric fit says of the scene's materials: each object's reflectance and each
/// body region's surface temperature.
#[derive(Clone, Debug, Serialize)]
pub struct FittedRadiometry {
    /// LWIR reflectance per object (stage-1 order).
    pub reflectance: Vec<f64>,
    /// Surface temperature per region, °C.
    pub temperature_c: RegionValues,
    /// The rise predicted for this body, summed over the pixels per region, K·px
    /// ([`HumanProblem::region_rise`]): which parts of the body the reflection shows — with
    /// clothing alone, front and back look alike.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rise_k_px: Option<RegionValues>,
}

/// One value per body region.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct RegionValues {
    /// Clothing.
    pub clothing: f64,
    /// Bare skin other than the face.
    pub skin: f64,
    /// The face.
    pub face: f64,
    /// Hair on the scalp.
    pub hair: f64,
}

impl FittedRadiometry {
    /// From the fitted scalars.
    pub fn new(r: &radiometric::Radiometry, s: &radiometric::Scalars) -> Self {
        Self {
            reflectance: s.reflectance.clone(),
            temperature_c: irmirror_body::Region::ALL
                .map(|g| r.temperature_c(g, s.contrast[g.index()]))
                .into(),
            rise_k_px: None,
        }
    }
}

impl From<[f64; radiometric::REGIONS]> for RegionValues {
    /// From `Region::ALL`'s order.
    fn from([clothing, skin, face, hair]: [f64; radiometric::REGIONS]) -> Self {
        Self {
            clothing,
            skin,
            face,
            hair,
        }
    }
}

/// Everything a fit needs that does not change between hypotheses.
#[derive(Clone, Copy)]
pub struct HumanProblem<'a> {
    /// The body model.
    pub model: &'a BodyModel,
    /// The pose prior.
    pub prior: &'a PosePrior,
    /// Reflected rays of the object pixels (depth frame).
    pub rays: &'a ReflectedRays<f64>,
    /// Thermal-pixel reflection mask.
    pub mask: &'a Image<bool>,
    /// Support-plane normal (up), depth frame.
    pub up: Vector3<f64>,
    /// Centre of the objects, depth frame (the person faces it, roughly).
    pub objects_centre: Vector3<f64>,
    /// Whether the person is taken to face the objects' centre ([`HumanConfig::w_facing`]):
    /// true on a tabletop, false by a car.
    pub faces_objects: bool,
    /// The floor the person stands on, when known.
    pub floor: Option<Floor>,
    /// The thermal rise per ray for the radiometric data term (`None`: the mask only).
    pub radiometry: Option<&'a radiometric::Radiometry>,
    /// The person's build ([`HumanConfig::build`]); every state of the problem has it.
    pub build: Phenotype,
}

/// A horizontal floor: height of `p` above it = `up · p − offset_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// Unit up, depth frame.
    pub up: Vector3<f64>,
    /// `up · p` on the floor, metres.
    pub offset_m: f64,
}

impl Floor {
    /// Height of `p` (depth frame) above the floor, metres.
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.up.dot(p) - self.offset_m
    }
}

/// A rotation taking Anny's +Z (up) to `up` and Anny's front (−Y) towards `facing` (projected
/// onto the plane).
pub fn upright_facing(up: &Vector3<f64>, facing: &Vector3<f64>) -> Matrix3<f64> {
    let z = up.normalize();
    let mut f = facing - z * z.dot(facing);
    if f.norm() < 1e-9 {
        f = if z.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        f -= z * z.dot(&f);
    }
    let front = f.normalize();
    // Columns: images of Anny's X, Y, Z. Anny's −Y is the front, so Y ↦ −front; X = Y × Z.
    let y = -front;
    let x = y.cross(&z);
    Matrix3::from_columns(&[x, y, z])
}

/// The phenotype stage 2 fits: a build (by default the mean adult, not the shape basis'
/// origin, coefficients 0, a 1.84 m body) with the given height slider.
pub fn phenotype(build: &Phenotype, height: f64) -> Phenotype {
    Phenotype { height, ..*build }
}

/// The rest body of a build with a height slider.
pub fn shaped_body(
    model: &BodyModel,
    build: &Phenotype,
    height: f64,
) -> Result<irmirror_body::ShapedBody<f64>, ReconError> {
    model
        .shaped_phenotype::<f64>(&phenotype(build, height))
        .map_err(ReconError::from)
}

/// The posed body of a stage-2 state, depth frame.
pub fn posed_body(
    model: &BodyModel,
    prior: &PosePrior,
    st: &HumanState,
) -> Result<irmirror_body::PosedBody<f64>, ReconError> {
    let shaped = shaped_body(model, &st.build, st.height)?;
    Ok(model.pose(
        &shaped,
        &irmirror_body::Pose {
            rotations: joint_rotations(prior, st)?,
            translation: st.translation,
        },
    )?)
}

/// A state's 36 joint rotations: the root's, then each body joint's decoding of the latent
/// turned by its residual on the right, `D_j exp(δ_j)` (a turn about the joint's own axes).
pub fn joint_rotations(
    prior: &PosePrior,
    st: &HumanState,
) -> Result<Vec<Matrix3<f64>>, ReconError> {
    let mut rotations = prior.decode(&st.latent)?;
    rotations[0] = st.rotation;
    compose_residual(&mut rotations[1..], &st.residual)?;
    Ok(rotations)
}

/// The pose residual that turns the decoding of `latent` into the body joints of `rotvecs`
/// (36 rotation vectors, root first; the root's is not used): `δ_j = log(D_jᵀ R_j)`.
pub fn residual_to(
    prior: &PosePrior,
    latent: &[f64],
    rotvecs: &[[f64; 3]],
) -> Result<Vec<f64>, ReconError> {
    use irmirror_geom::rotation::{axis_angle_to_matrix, matrix_to_axis_angle};
    let decoded = prior.decode(latent)?;
    if rotvecs.len() != decoded.len() {
        return Err(ReconError::Config(format!(
            "{} joint rotations, expected {}",
            rotvecs.len(),
            decoded.len()
        )));
    }
    Ok(decoded[1..]
        .iter()
        .zip(&rotvecs[1..])
        .flat_map(|(d, r)| {
            let w =
                matrix_to_axis_angle(&(d.transpose() * axis_angle_to_matrix(&Vector3::from(*r))));
            [w.x, w.y, w.z]
        })
        .collect())
}

/// Turns each body joint's rotation by its residual, `D_j ← D_j exp(δ_j)` (`residual` empty:
/// none).
pub(crate) fn compose_residual(
    body: &mut [Matrix3<f64>],
    residual: &[f64],
) -> Result<(), ReconError> {
    if residual.is_empty() {
        return Ok(());
    }
    if residual.len() != 3 * body.len() || residual.iter().any(|x| !x.is_finite()) {
        return Err(ReconError::Config(format!(
            "a pose residual holds {} values (expected {} finite ones, 3 per body joint)",
            residual.len(),
            3 * body.len()
        )));
    }
    for (d, w) in body.iter_mut().zip(residual.chunks_exact(3)) {
        *d *= irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::new(w[0], w[1], w[2]));
    }
    Ok(())
}

/// Stature of a rest body (top minus bottom along Anny's up, +Z), metres.
pub fn stature_m(shaped: &irmirror_body::ShapedBody<f64>) -> f64 {
    let (lo, hi) = shaped
        .vertices
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v.z), hi.max(v.z))
        });
    hi - lo
}

/// Where [`HumanProblem::loss_grad`] evaluates: root translation `t` (depth frame, m), root
/// rotation `exp(ω) base` (Anny → depth; the gradient is taken in ω at the given value), height
/// slider, pose latent, pose residual. The gradient's layout is the same: `t` (3), `ω` (3),
/// height (1), latent, residual (when not empty).
#[derive(Clone, Copy, Debug)]
pub struct Tangent<'a> {
    /// Root position, depth frame, m.
    pub translation: &'a Vector3<f64>,
    /// Rotation vector applied on the left of `base`, rad.
    pub omega: &'a Vector3<f64>,
    /// Base root rotation, Anny → depth.
    pub base: &'a Matrix3<f64>,
    /// Height slider.
    pub height: f64,
    /// Pose latent.
    pub latent: &'a [f64],
    /// Pose residual ([`HumanState::residual`]; empty: none, and no gradient for it).
    pub residual: &'a [f64],
}

/// The rays a loss evaluation sees: reflected rays, their 0/1 targets, and the blur.
#[derive(Clone, Copy, Debug)]
pub struct Batch<'a> {
    /// Reflected rays, depth frame.
    pub rays: &'a ReflectedRays<f64>,
    /// Target per ray (1: in the reflection mask).
    pub target: &'a [f64],
    /// Weight per ray in the soft IoU (importance weights of a stratified sample); `None`: 1.
    pub weight: Option<&'a [f64]>,
    /// The observed thermal rise for the radiometric term (`None`: the mask's term).
    pub rise: Option<Rise<'a>>,
    /// Occupancy blur σ, m².
    pub sigma_m2: f64,
}

/// The state of one hypothesis.
#[derive(Clone, Debug)]
pub struct HumanState {
    /// Root position, depth frame, m.
    pub translation: Vector3<f64>,
    /// Root rotation, Anny → depth.
    pub rotation: Matrix3<f64>,
    /// Height slider (see [`HEIGHT_MEAN`]).
    pub height: f64,
    /// The build (phenotype sliders but the height, [`HumanConfig::build`]).
    pub build: Phenotype,
    /// Pose latent.
    pub latent: Vec<f64>,
    /// Per-joint residual rotations beyond the prior's decoding (rotation vectors, rad, 3 per
    /// body joint in the rig's order, root excluded; empty: none). See
    /// [`HumanConfig::lr_residual`].
    pub residual: Vec<f64>,
}

/// Parameters per hypothesis before the latent: translation (3), rotation (3), height (1).
pub const ROOT_PARAMS: usize = 7;

/// Parameters of a pose residual: 3 per body joint.
pub const RESIDUAL_PARAMS: usize = 3 * irmirror_body::prior::JOINTS;
