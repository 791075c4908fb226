//! The failure diagnosis of a capture's full-model fit: the true body and every reported
//! hypothesis scored by stage 2's data term through the fitted (and the true) objects.

use super::run::Prepared;
use crate::EvalError;
use crate::score::{facing_error_deg, vertex_error};
use irmirror_recon::human::{Draw, HumanProblem, HumanState, edge_distance, posed_body};
use irmirror_recon::objects::{FittedObject, Objects};
use irmirror_recon::pipeline::{
    BodyPriors, ReconConfig, Reconstruction, human_problem, radiometry, reflected_rays,
};
use irmirror_sim::scene::ObjectShape;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// What a capture's full-model fit says about why it is off (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FailureClass {
    /// The best hypothesis is within [`SUCCESS_ROOT_M`] and [`SUCCESS_FACING_DEG`] of the truth.
    Success,
    /// Off, and the true body scores a lower loss than the fit: the optimiser did not find what
    /// its loss prefers.
    Search,
    /// Off, yet the fit scores at least as low as the truth: the observation (or the model) does
    /// not tell them apart.
    Information,
}

impl FailureClass {
    /// Every class, in the table's column order.
    pub const ALL: [FailureClass; 3] = [
        FailureClass::Success,
        FailureClass::Search,
        FailureClass::Information,
    ];

    /// The column heading.
    pub fn heading(self) -> &'static str {
        match self {
            FailureClass::Success => "success",
            FailureClass::Search => "search failure",
            FailureClass::Information => "information / model failure",
        }
    }
}

/// A fit within this root distance of the truth…
pub const SUCCESS_ROOT_M: f64 = 0.15;
/// …and this facing angle is a success.
pub const SUCCESS_FACING_DEG: f64 = 30.0;

/// The full model's fit against the true body, both scored by stage 2's data term (the
/// radiometric term, or `1 − soft IoU` when that is off; all rays at the final σ) through the
/// *fitted* objects.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// The true body mesh's data term.
    pub truth_loss: f64,
    /// The true body's data term through the *true* objects (rays traced against the
    /// simulator's shapes; `None` for shapes stage 1 cannot represent): low here but high through
    /// the fitted objects means stage 1's mirror, not the optimiser or the observation, is off.
    #[serde(default)]
    pub truth_loss_true_objects: Option<f64>,
    /// Every reported hypothesis' data term, best first.
    pub hypothesis_losses: Vec<f64>,
    /// Root error of every reported hypothesis, m.
    pub hypothesis_root_errors_m: Vec<f64>,
    /// Root error of the hypothesis nearest the truth, m.
    pub nearest_root_error_m: f64,
    /// Facing error of every reported hypothesis, degrees (`None`: keypoints degenerate).
    #[serde(default)]
    pub hypothesis_facing_errors_deg: Vec<Option<f64>>,
    /// Mean per-vertex error of the best-by-loss hypothesis among those facing the right way
    /// (within [`SUCCESS_FACING_DEG`]), m; `None` when no reported hypothesis does.
    #[serde(default)]
    pub right_facing_vertex_error_m: Option<f64>,
    /// Our model refined from the truth (true root position and rotation, the true height
    /// slider, the prior's encoding of the true pose; the full stage-2 schedule): its data term.
    /// Lower than the fit's: the search missed a basin our model can reach (a true search
    /// failure); not lower while the true mesh is: our model (pose prior, mean-adult
    /// proportions) cannot represent what the true mesh explains.
    #[serde(default)]
    pub truth_start_loss: Option<f64>,
    /// Root error after that refinement, m.
    #[serde(default)]
    pub truth_start_root_error_m: Option<f64>,
    /// Our model *at* the truth, before any step (the true height slider, the pose prior's
    /// encoding of the true pose, mean-adult proportions, the root placed by the rigid motion
    /// that best aligns it onto the true mesh): its data term. What the pose prior and the mean
    /// adult can state of this person.
    #[serde(default)]
    pub model_truth_loss: Option<f64>,
    /// The same state's mean per-vertex error against the true body, m: the floor the pose
    /// prior (and the mean adult's proportions) put under any fit's per-vertex error.
    #[serde(default)]
    pub model_truth_vertex_error_m: Option<f64>,
    /// The true body turned 180° about the up axis through its root, scored by the data term:
    /// not above `truth_loss` means the capture cannot tell the truth from its front/back flip.
    #[serde(default)]
    pub truth_flip_loss: Option<f64>,
    /// The true body and its flip scored by the paper's mask term (`1 − soft IoU`): what a binary
    /// silhouette says about front and back on the same capture.
    #[serde(default)]
    pub truth_mask_losses: Option<[f64; 2]>,
    /// The class.
    pub class: FailureClass,
}

impl Diagnosis {
    /// Classifies from the best hypothesis' root and facing errors and the losses.
    pub fn classify(
        truth_loss: f64,
        best_loss: f64,
        root_error_m: f64,
        facing_error_deg: Option<f64>,
    ) -> FailureClass {
        let facing_ok = facing_error_deg.is_none_or(|f| f <= SUCCESS_FACING_DEG);
        if root_error_m <= SUCCESS_ROOT_M && facing_ok {
            FailureClass::Success
        } else if truth_loss < best_loss {
            FailureClass::Search
        } else {
            FailureClass::Information
        }
    }
}

/// The full model's failure diagnosis: the true body and every reported hypothesis scored by
/// stage 2's data term through the fitted objects.
pub(super) fn diagnose(
    p: &Prepared,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Diagnosis, EvalError> {
    let BodyPriors { model, prior } = priors;
    let hcfg = cfg.human_settings();
    let (rad, _) = radiometry(&rec.pre, &rec.rays, model, &hcfg)?;
    let problem = HumanProblem {
        model,
        prior,
        rays: &rec.rays,
        mask: &rec.pre.mask,
        up: rec.objects.ground.n(),
        objects_centre: Vector3::zeros(),
        floor: None,
        radiometry: rad.as_ref(),
    };
    let truth: Vec<Vector3<f64>> = p
        .sim
        .body
        .mesh
        .vertices
        .iter()
        .map(|v| Vector3::from(v.map(f64::from)))
        .collect();
    let (truth_loss, _) = problem.mesh_data_loss(&truth, &hcfg);
    // The truth turned around (180° about its up axis through the root).
    let root = p.sim.body.joints[0];
    let up = p.sim.body.depth_from_anny.rotation * Vector3::z();
    let turn = irmirror_geom::rotation::axis_angle_to_matrix(&(up * std::f64::consts::PI));
    let flipped: Vec<Vector3<f64>> = truth.iter().map(|v| root + turn * (v - root)).collect();
    let truth_flip_loss = Some(problem.mesh_data_loss(&flipped, &hcfg).0);
    let mut mask_cfg = hcfg.clone();
    mask_cfg.radiometric.enabled = false;
    let truth_mask_losses = Some([
        problem.mesh_data_loss(&truth, &mask_cfg).0,
        problem.mesh_data_loss(&flipped, &mask_cfg).0,
    ]);
    let truth_loss_true_objects = match true_objects(p, &rec.objects) {
        Some(objects) => {
            let rays = reflected_rays(&p.capture, &objects, &rec.pre.mask, cfg);
            let (rad, _) = radiometry(&rec.pre, &rays, model, &hcfg)?;
            let through_truth = HumanProblem {
                rays: &rays,
                radiometry: rad.as_ref(),
                ..problem
            };
            Some(through_truth.mesh_data_loss(&truth, &hcfg).0)
        }
        None => None,
    };
    let hypothesis_losses: Vec<f64> = rec.human.hypotheses.iter().map(|h| h.data_loss).collect();
    let true_root = p.sim.body.joints[0];
    let bodies = rec
        .states
        .iter()
        .map(|st| posed_body(model, prior, st))
        .collect::<Result<Vec<_>, _>>()?;
    let hypothesis_root_errors_m: Vec<f64> = bodies
        .iter()
        .map(|b| (b.joints[0] - true_root).norm())
        .collect();
    let hypothesis_facing_errors_deg: Vec<Option<f64>> = bodies
        .iter()
        .map(|b| facing_error_deg(&b.keypoints, &p.sim.body.keypoints))
        .collect();
    let right_facing_vertex_error_m = bodies
        .iter()
        .zip(&hypothesis_facing_errors_deg)
        .find(|(_, f)| f.is_some_and(|f| f <= SUCCESS_FACING_DEG))
        .and_then(|(b, _)| vertex_error(&b.vertices, &p.sim.body.mesh.vertices));
    let truth_state = model_truth(p, priors, &truth)?;
    let (truth_start_loss, truth_start_root_error_m) =
        refine_from_truth(&truth_state, true_root, priors, rec, (seed, cfg))?
            .map_or((None, None), |(l, e)| (Some(l), Some(e)));
    let at_truth = posed_body(model, prior, &truth_state)?;
    let model_truth_loss = Some(problem.mesh_data_loss(&at_truth.vertices, &hcfg).0);
    let model_truth_vertex_error_m = vertex_error(&at_truth.vertices, &p.sim.body.mesh.vertices);
    let class = Diagnosis::classify(
        truth_loss,
        hypothesis_losses[0],
        hypothesis_root_errors_m[0],
        hypothesis_facing_errors_deg[0],
    );
    Ok(Diagnosis {
        truth_loss,
        truth_loss_true_objects,
        nearest_root_error_m: hypothesis_root_errors_m
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min),
        hypothesis_losses,
        hypothesis_root_errors_m,
        hypothesis_facing_errors_deg,
        right_facing_vertex_error_m,
        truth_start_loss,
        truth_start_root_error_m,
        model_truth_loss,
        model_truth_vertex_error_m,
        truth_flip_loss,
        truth_mask_losses,
        class,
    })
}

/// Stage 2's refinement started at the truth (as our model can state it): its data term and
/// root error; `None` when it diverged.
fn refine_from_truth(
    truth: &HumanState,
    true_root: Vector3<f64>,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Option<(f64, f64)>, EvalError> {
    let hcfg = cfg.human_settings();
    let (rad, _) = radiometry(&rec.pre, &rec.rays, priors.model, &hcfg)?;
    let problem = human_problem(
        priors,
        &rec.rays,
        &rec.pre.mask,
        &rec.objects,
        &hcfg,
        rad.as_ref(),
    );
    let edge = edge_distance(&rec.pre.mask);
    let Some((end, _)) = problem.run(truth, &hcfg, Draw::Edge(&edge), seed)? else {
        return Ok(None);
    };
    let data = problem.full_eval(&end, &hcfg)?.data;
    Ok(Some((data, (end.translation - true_root).norm())))
}

/// The truth as stage 2's model states it: the true height slider, the pose prior's encoding of
/// the true pose (mean-adult proportions otherwise), and the root placed by the rigid motion
/// that best aligns that body onto the true mesh `truth` (from the true root position and
/// rotation): a fit finds the root's place and rotation, so a prior whose encoding tilts the
/// whole body is not charged for the tilt.
fn model_truth(
    p: &Prepared,
    priors: BodyPriors<'_>,
    truth: &[Vector3<f64>],
) -> Result<HumanState, EvalError> {
    let person = &p.scene.person;
    let at_root = HumanState {
        translation: p.sim.body.joints[0],
        rotation: p.sim.body.depth_from_anny.rotation
            * irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(person.rotvec_rad[0])),
        height: person.phenotype.height,
        latent: priors.prior.encode(&person.rotvec_rad)?,
    };
    let ours = posed_body(priors.model, priors.prior, &at_root)?.vertices;
    // Vertices are root rotation × rest-relative offsets + root, so a rigid motion of every
    // vertex is the same motion of the root.
    Ok(
        match irmirror_geom::Similarity3::umeyama(&ours, truth, false) {
            Some(a) => HumanState {
                translation: a.transform_point(&at_root.translation),
                rotation: a.rotation * at_root.rotation,
                ..at_root
            },
            None => at_root,
        },
    )
}

/// The simulator's objects as stage-1 results (same ground and masks as `fitted`), when every
/// one is a two-parameter shape stage 1 can represent.
fn true_objects(p: &Prepared, fitted: &Objects) -> Option<Objects> {
    let objects = p
        .scene
        .objects
        .iter()
        .zip(&p.sim.object_poses)
        .map(|(o, pose)| match o.shape {
            ObjectShape::Simple(shape) => Some(FittedObject {
                category: shape.category(),
                shape,
                depth_from_object: *pose,
                loss: 0.0,
                mean_surface_error_m: 0.0,
                points: 0,
                loss_curve: vec![],
                learned: None,
            }),
            ObjectShape::Family(_) => None,
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Objects {
        objects,
        ..fitted.clone()
    })
}
