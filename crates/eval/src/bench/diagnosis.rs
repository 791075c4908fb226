//! The failure diagnosis of a capture's full-model fit: the true body and every reported
//! hypothesis scored by stage 2's data term through the fitted (and the true) objects.

use super::basin::{BasinProbe, BasinStart, probe_basin};
use super::run::Prepared;
use crate::EvalError;
use crate::score::{facing_error_deg, vertex_error};
use irmirror_recon::human::{HumanProblem, HumanState, edge_distance, posed_body};
use irmirror_recon::pipeline::{
    BodyPriors, ReconConfig, Reconstruction, human_problem, radiometry, reflected_rays_through,
};
use irmirror_render::ReflectedRays;
use irmirror_render::sdf::PlacedSdf;
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
    /// simulator's shapes, whichever set they come from; `None` in results written before
    /// 2026-12-01 for shapes outside the two-parameter family): low here but high through the
    /// fitted objects means stage 1's mirror, not the optimiser or the observation, is off.
    #[serde(default)]
    pub truth_loss_true_objects: Option<f64>,
    /// Stage 1's mirror where it matters: over the reflection mask's pixels, the median angle
    /// between the reflected ray through the fitted objects and through the true ones, degrees
    /// (`None` as for `truth_loss_true_objects`).
    #[serde(default)]
    pub mask_ray_angle_deg: Option<f64>,
    /// The same rays' median distance apart where each passes the true root, m: how far the
    /// fitted mirror moves what a mask pixel sees at the person.
    #[serde(default)]
    pub mask_ray_offset_m: Option<f64>,
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
    /// slider, the prior's encoding of the true pose with the exact residual when the fit has
    /// one; the refinement as the fit runs it on a survivor of the search): its data term.
    /// Lower than the fit's: the search missed a basin our model can reach (a true search
    /// failure); not lower while the true mesh is: our model (pose prior, mean-adult
    /// proportions) cannot represent what the true mesh explains.
    #[serde(default)]
    pub truth_start_loss: Option<f64>,
    /// Root error after that refinement, m.
    #[serde(default)]
    pub truth_start_root_error_m: Option<f64>,
    /// Mean per-vertex error after that refinement, m: what a search that found the truth's
    /// basin would report — the ceiling of any search for this loss and body model.
    #[serde(default)]
    pub truth_start_vertex_error_m: Option<f64>,
    /// Facing error after that refinement, degrees (`None`: keypoints degenerate).
    #[serde(default)]
    pub truth_start_facing_error_deg: Option<f64>,
    /// Our model *at* the truth, before any step (the true height slider, the pose prior's
    /// encoding of the true pose — with the exact residual when the fit has one —, mean-adult
    /// proportions, the root placed by the rigid motion that best aligns it onto the true
    /// mesh): its data term. What our body model can state of this person.
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
    /// The true body's outline twin ([`HumanProblem::outline_twin_mesh`]: front and back
    /// swapped along the mirror's lines of sight, the outline kept) scored by the data term and
    /// by the mask term: how much the thermal values alone say about front and back at the true
    /// pose (the mask term should barely move).
    #[serde(default)]
    pub truth_outline_twin_losses: Option<[f64; 2]>,
    /// Per reported hypothesis: `[data term, its outline twin's data term, mask term, its
    /// outline twin's mask term]` — whether a fit's own pose, turned front to back with its
    /// outline kept, explains the thermal image better.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hypothesis_outline_twin_losses: Vec<[f64; 4]>,
    /// The thermal facing judge's residual (`HumanProblem::thermal_residual_at`) of the true
    /// body and of its outline twin: what the virtual view's thermal raster says at the true
    /// pose.
    #[serde(default)]
    pub truth_thermal_residuals: Option<[f64; 2]>,
    /// The thermal facing judge (`HumanProblem::thermal_facing`, best 30 outlines) at our
    /// model's truth state and at its silhouette twin.
    #[serde(default)]
    pub truth_thermal_facing: Option<[f64; 2]>,
    /// The same at each reported hypothesis: `[own facing, twin's]`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hypothesis_thermal_facing: Vec<Option<[f64; 2]>>,
    /// The rise the radiometric model predicts for the true body, summed per region (K·px;
    /// clothing, bare skin, face, hair: `HumanProblem::region_rise`): which parts of the person
    /// the reflection shows — with clothing alone, front and back look alike.
    #[serde(default)]
    pub truth_region_rise_k_px: Option<[f64; 4]>,
    /// The same for the best hypothesis.
    #[serde(default)]
    pub best_region_rise_k_px: Option<[f64; 4]>,
    /// The class.
    pub class: FailureClass,
    /// The refinement's basin (`eval --basin`): the production refinement started near the
    /// truth, one entry per start; empty when not probed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub basin: Vec<BasinStart>,
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
    basin: Option<&BasinProbe>,
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
        // The data terms alone are compared here.
        faces_objects: false,
        floor: None,
        radiometry: rad.as_ref(),
        build: hcfg.build,
    };
    let truth = p.truth.vertices();
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
    let centred = human_problem(
        priors,
        &rec.rays,
        &rec.pre.mask,
        &rec.objects,
        &hcfg,
        rad.as_ref(),
    );
    let outline_twin = |vertices: &[Vector3<f64>], root: &Vector3<f64>| {
        let twin = centred.outline_twin_mesh(vertices, root);
        [
            problem.mesh_data_loss(vertices, &hcfg).0,
            problem.mesh_data_loss(&twin, &hcfg).0,
            problem.mesh_data_loss(vertices, &mask_cfg).0,
            problem.mesh_data_loss(&twin, &mask_cfg).0,
        ]
    };
    let truth_outline_twin_losses = {
        let l = outline_twin(&truth, &root);
        Some([l[1], l[3]])
    };
    let truth_thermal_residuals = centred
        .thermal_residual_at(&root, &truth, &hcfg.retrieval)
        .zip(centred.thermal_residual_at(
            &root,
            &centred.outline_twin_mesh(&truth, &root),
            &hcfg.retrieval,
        ))
        .map(|(a, b)| [a, b]);
    let (truth_loss_true_objects, mirror) = {
        let rays = reflected_rays_through(
            &p.capture,
            &true_objects(p),
            rec.objects.ground.plane.as_ref(),
            &rec.pre.mask,
            cfg,
        );
        let (rad, _) = radiometry(&rec.pre, &rays, model, &hcfg)?;
        let through_truth = HumanProblem {
            rays: &rays,
            radiometry: rad.as_ref(),
            ..problem
        };
        let mirror = mirror_error(&rec.rays, &rays, &rec.pre.mask, &p.sim.body.joints[0]);
        (Some(through_truth.mesh_data_loss(&truth, &hcfg).0), mirror)
    };
    let (mask_ray_angle_deg, mask_ray_offset_m) = mirror.unzip();
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
    let hypothesis_outline_twin_losses: Vec<[f64; 4]> = bodies
        .iter()
        .map(|b| outline_twin(&b.vertices, &b.joints[0]))
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
    let truth_state = model_truth(p, priors, &truth, (&hcfg.build, hcfg.lr_residual > 0.0))?;
    let truth_thermal_facing = centred.thermal_facing(&truth_state, &hcfg.retrieval, 30)?;
    let hypothesis_thermal_facing = rec
        .states
        .iter()
        .map(|st| centred.thermal_facing(st, &hcfg.retrieval, 30))
        .collect::<Result<Vec<_>, _>>()?;
    let from_truth = ceiling_from(&truth_state, p, priors, rec, (seed, cfg))?;
    let truth_start_loss = from_truth.as_ref().map(|c| c.loss);
    let truth_start_root_error_m = from_truth.as_ref().map(|c| c.root_error_m);
    let truth_start_vertex_error_m = from_truth.as_ref().and_then(|c| c.vertex_error_m);
    let truth_start_facing_error_deg = from_truth.as_ref().and_then(|c| c.facing_error_deg);
    let basin = match basin {
        Some(b) => probe_basin(
            (
                &truth_state,
                &p.scene.person.rotvec_rad,
                &p.sim.body.mesh.vertices,
            ),
            b,
            priors,
            rec,
            (seed, cfg),
        )?,
        None => Vec::new(),
    };
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
        mask_ray_angle_deg,
        mask_ray_offset_m,
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
        truth_start_vertex_error_m,
        truth_start_facing_error_deg,
        model_truth_loss,
        model_truth_vertex_error_m,
        truth_flip_loss,
        truth_mask_losses,
        truth_outline_twin_losses,
        hypothesis_outline_twin_losses,
        truth_thermal_residuals,
        truth_thermal_facing,
        hypothesis_thermal_facing,
        truth_region_rise_k_px: problem.region_rise(&truth, &hcfg),
        best_region_rise_k_px: bodies
            .first()
            .and_then(|b| problem.region_rise(&b.vertices, &hcfg)),
        class,
        basin,
    })
}

/// Median over the mask's pixels seen through both ray sets (each pixel's first ray): the angle
/// between the fitted and the true reflected ray (degrees), and how far apart they pass `root`
/// (each ray's point nearest it, m). `None` when no mask pixel has both.
fn mirror_error(
    fitted: &ReflectedRays<f64>,
    truth: &ReflectedRays<f64>,
    mask: &irmirror_capture::Image<bool>,
    root: &Vector3<f64>,
) -> Option<(f64, f64)> {
    let first = |r: &ReflectedRays<f64>| {
        let mut m = std::collections::HashMap::with_capacity(r.len());
        for i in 0..r.len() {
            m.entry(r.pixel[i]).or_insert(i);
        }
        m
    };
    let (f, t) = (first(fitted), first(truth));
    let near = |r: &ReflectedRays<f64>, i: usize| {
        let (o, d) = (r.origin[i], r.dir[i]);
        o + d * (root - o).dot(&d).max(0.0)
    };
    let (mut angle, mut offset): (Vec<f64>, Vec<f64>) = f
        .iter()
        .filter(|(px, _)| mask.data[**px as usize])
        .filter_map(|(px, &i)| {
            let j = *t.get(px)?;
            let cos = fitted.dir[i].dot(&truth.dir[j]).clamp(-1.0, 1.0);
            Some((
                cos.acos().to_degrees(),
                (near(fitted, i) - near(truth, j)).norm(),
            ))
        })
        .unzip();
    if angle.is_empty() {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Some((median(&mut angle), median(&mut offset)))
}

/// Our model refined from the truth as the fit refines a survivor (a search's ceiling): the
/// end state's data term and errors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ceiling {
    /// The end state's data term.
    pub loss: f64,
    /// Its root error, m.
    pub root_error_m: f64,
    /// Its mean per-vertex error, m.
    pub vertex_error_m: Option<f64>,
    /// Its facing error, degrees.
    pub facing_error_deg: Option<f64>,
}

/// The ceiling ([`Ceiling`]) of stage 2 as `cfg` and `rec` pose it (an oracle variant's own
/// settings and objects): from the truth as our model states it with `cfg`'s build; `None`
/// when the refinement diverged.
pub(super) fn ceiling(
    p: &Prepared,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Option<Ceiling>, EvalError> {
    let hcfg = cfg.human_settings();
    let truth = p.truth.vertices();
    let start = model_truth(p, priors, &truth, (&hcfg.build, hcfg.lr_residual > 0.0))?;
    ceiling_from(&start, p, priors, rec, (seed, cfg))
}

/// [`ceiling`] from `start`.
fn ceiling_from(
    start: &HumanState,
    p: &Prepared,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Option<Ceiling>, EvalError> {
    let Some((end, loss)) = refine_from_truth(start, priors, rec, (seed, cfg))? else {
        return Ok(None);
    };
    let body = posed_body(priors.model, priors.prior, &end)?;
    Ok(Some(Ceiling {
        loss,
        root_error_m: (end.translation - p.sim.body.joints[0]).norm(),
        vertex_error_m: vertex_error(&body.vertices, &p.sim.body.mesh.vertices),
        facing_error_deg: facing_error_deg(&body.keypoints, &p.sim.body.keypoints),
    }))
}

/// Stage 2's refinement started at the truth (as our model can state it): the state it ends
/// at and that state's data term; `None` when it diverged.
fn refine_from_truth(
    truth: &HumanState,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Option<(HumanState, f64)>, EvalError> {
    let hcfg = cfg.human_settings();
    with_problem(priors, rec, &hcfg, |problem, edge| {
        let Some(end) = refine_as_fit(problem, truth, &hcfg, edge, seed)? else {
            return Ok(None);
        };
        let data = problem.full_eval(&end, &hcfg)?.data;
        Ok(Some((end, data)))
    })
}

/// Stage 2's refinement of one start as `fit_human` runs it on each survivor of the search
/// whose states it reports: the mask's schedule when a thermal polish follows (the rise
/// throughout otherwise, and in the rise pass of a small reflection — even where its guard
/// then reports the mask pass's states), then the polish on the rise when the capture has one.
/// `None`: it diverged.
pub(super) fn refine_as_fit(
    problem: &HumanProblem<'_>,
    start: &HumanState,
    hcfg: &irmirror_recon::human::HumanConfig,
    edge: &irmirror_capture::Image<f64>,
    seed: u64,
) -> Result<Option<HumanState>, EvalError> {
    let hcfg = &problem.prior_weighted(hcfg);
    let hcfg = &problem.rise_pass(hcfg).unwrap_or_else(|| hcfg.clone());
    let thermal = problem.radiometric(hcfg).is_some();
    let polish = thermal && hcfg.radiometric.polish_iterations > 0;
    let sample = problem.refine_sample(hcfg, seed);
    let mut end = problem
        .refine(start, hcfg, edge, sample.as_ref(), seed)?
        .map(|(st, _)| st);
    if polish && let Some(mid) = end {
        let sample = problem.polish_sample(hcfg, seed);
        end = problem
            .polish(&mid, hcfg, sample.as_ref(), seed)?
            .map(|(st, _)| st);
    }
    Ok(end)
}

/// Runs `f` on stage 2's problem as the fit poses it for this reconstruction (its radiometry
/// with `hcfg`) and the mask's edge distances.
pub(super) fn with_problem<R>(
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    hcfg: &irmirror_recon::human::HumanConfig,
    f: impl FnOnce(&HumanProblem<'_>, &irmirror_capture::Image<f64>) -> Result<R, EvalError>,
) -> Result<R, EvalError> {
    let (rad, _) = radiometry(&rec.pre, &rec.rays, priors.model, hcfg)?;
    let problem = human_problem(
        priors,
        &rec.rays,
        &rec.pre.mask,
        &rec.objects,
        hcfg,
        rad.as_ref(),
    );
    f(&problem, &edge_distance(&rec.pre.mask))
}

/// The truth as stage 2's model states it: the true height slider, the pose prior's encoding of
/// the true pose — with a pose residual (`residual`), each body joint's rotation from that
/// decoding to the true one, so the pose is exact — the fit's build otherwise, and the
/// root placed by the rigid motion that best aligns that body onto the true mesh `truth` (from
/// the true root position and rotation): a fit finds the root's place and rotation, so a prior
/// whose encoding tilts the whole body is not charged for the tilt.
fn model_truth(
    p: &Prepared,
    priors: BodyPriors<'_>,
    truth: &[Vector3<f64>],
    (build, residual): (&irmirror_body::Phenotype, bool),
) -> Result<HumanState, EvalError> {
    let person = &p.scene.person;
    let latent = priors.prior.encode(&person.rotvec_rad)?;
    let residual = if residual {
        irmirror_recon::human::residual_to(priors.prior, &latent, &person.rotvec_rad)?
    } else {
        Vec::new()
    };
    let at_root = HumanState {
        translation: p.sim.body.joints[0],
        rotation: p.sim.body.depth_from_anny.rotation
            * irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(person.rotvec_rad[0])),
        height: person.phenotype.height,
        build: *build,
        latent,
        residual,
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

/// The simulator's objects, placed as it traced them (any shape set).
fn true_objects(p: &Prepared) -> Vec<PlacedSdf> {
    p.scene
        .objects
        .iter()
        .zip(&p.sim.object_poses)
        .map(|(o, pose)| PlacedSdf {
            sdf: o.shape.sdf(),
            depth_from_object: *pose,
        })
        .collect()
}
