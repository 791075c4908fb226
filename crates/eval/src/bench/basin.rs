//! The refinement's basin (`eval --basin`): stage 2's refinement as the fit runs it, started
//! near the truth (moved along the objects→person line and turned, in several poses), and
//! where it ends.

use super::diagnosis::{SUCCESS_FACING_DEG, SUCCESS_ROOT_M, refine_as_fit, with_problem};
use crate::EvalError;
use crate::score::vertex_error;
use irmirror_recon::human::{HumanState, posed_body};
use irmirror_recon::pipeline::{BodyPriors, ReconConfig, Reconstruction};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// How far from the truth the basin probe starts the refinement (`eval --basin`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BasinProbe {
    /// The root moved this far along the horizontal objects→person line (both ways), m.
    pub offset_m: f64,
    /// The body turned this far about the up axis (both ways), degrees.
    pub turn_deg: f64,
    /// The starts' poses, start k the k-th modulo their number (`eval --basin-poses`): a
    /// template of the pose generator (the search's candidates start from "stand", "walk",
    /// "sit"), [`TRUTH_LATENT`], [`TRUTH_TWIN`], [`BANK`] or [`LIMBS`].
    pub poses: Vec<String>,
}

/// A basin-probe start pose: the pose prior's encoding of the true pose without the residual
/// (what the latent alone states of the truth; the residual is left to the refinement).
pub const TRUTH_LATENT: &str = "truth-latent";

/// A basin-probe start turned around: the silhouette twin (`HumanProblem::twin`) of the
/// [`TRUTH_LATENT`] start — the true pose mirrored left to right, the root turned so that a
/// view along the objects→person line sees the same outline — the best start a body facing
/// the other way can have (for a person seen side-on the twin faces nearly the same way). Ending as low as the [`TRUTH_LATENT`] starts means the data term
/// cannot tell the person from one facing away, however well a search does.
pub const TRUTH_TWIN: &str = "truth-twin";

/// A basin start in the search's "stand" pose swapped through the pose bank at the start's
/// root and facing, as the search does at its survivors (`[human.search] pose_bank`, 32 when
/// that is 0).
pub const BANK: &str = "bank";

/// A basin start in the search's "stand" pose changed part by part by the limb search at the
/// start's root and facing, as the search does at its survivors with `[human.search]
/// limb_survivors` > 0.
pub const LIMBS: &str = "limbs";

/// A basin start in the source pose nearest the true one
/// (`HumanProblem::nearest_source_latent`: the pose prior's training poses, their mirror
/// images and the generator's templates): what a perfect retrieval over those poses could
/// start from.
pub const NEAREST_BANK: &str = "nearest-bank";

/// A basin start in the pose the virtual-view retrieval gives at the start's root and facing
/// (`HumanProblem::retrieved_start` with `[human.retrieval]`: the source pose whose outline
/// matches best with a tolerance, not by the data term, or the mean of the best `mean_of`),
/// from the search's "stand" pose.
pub const RETRIEVED: &str = "retrieved";

/// A [`RETRIEVED`] start from the silhouette twin of the true root and facing
/// (`HumanProblem::twin` of the "stand" start there): the pose the retrieval gives a body
/// facing the other way with the same outline. Against [`RETRIEVED`] it asks whether the data
/// term tells front from back when both sides carry a retrieved (not the true) pose.
pub const RETRIEVED_TWIN: &str = "retrieved-twin";

/// `truth-latent~S`: the [`TRUTH_LATENT`] start with independent N(0, S²) noise on every
/// latent coordinate (the prior's latent is N(0, 1)): how close a pose estimate must land for
/// the refinement to reach the true pose's quality. `None`: not such a name.
pub fn noisy_truth_scale(name: &str) -> Option<f64> {
    let s: f64 = name
        .strip_prefix(TRUTH_LATENT)?
        .strip_prefix('~')?
        .parse()
        .ok()?;
    (s.is_finite() && s >= 0.0).then_some(s)
}

impl Default for BasinProbe {
    /// ±35 cm and ±35°: about the spacing of the search's grid (eight yaw bins are 45° apart),
    /// so the starts sit where the search's nearest candidate to the truth can be.
    fn default() -> Self {
        Self {
            offset_m: 0.35,
            turn_deg: 35.0,
            poses: vec!["stand".into()],
        }
    }
}

/// One start of the basin probe and where the refinement ended (`None`: it diverged).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BasinStart {
    /// The start's pose ([`BasinProbe::poses`]).
    #[serde(default = "stand")]
    pub pose: String,
    /// The start's root offset along the objects→person line, m (+: away from the objects).
    pub offset_m: f64,
    /// The start's turn about the up axis, degrees.
    pub turn_deg: f64,
    /// Root distance from the truth at the end, m.
    pub root_error_m: Option<f64>,
    /// Facing difference from the truth at the end (about the up axis), degrees.
    pub facing_error_deg: Option<f64>,
    /// The data term at the end (all rays, final σ).
    pub data_loss: Option<f64>,
    /// Mean per-vertex distance from the true mesh at the end, m.
    #[serde(default)]
    pub vertex_error_m: Option<f64>,
    /// Mean per-vertex distance from the true mesh at the start (after any bank, limb or
    /// retrieval step), m.
    #[serde(default)]
    pub start_vertex_error_m: Option<f64>,
}

/// The basin probe's pose before it could be chosen.
fn stand() -> String {
    "stand".into()
}

impl BasinStart {
    /// Ended within [`SUCCESS_ROOT_M`] and [`SUCCESS_FACING_DEG`] of the truth.
    pub fn closed(&self) -> bool {
        self.root_error_m.is_some_and(|r| r <= SUCCESS_ROOT_M)
            && self
                .facing_error_deg
                .is_some_and(|f| f <= SUCCESS_FACING_DEG)
    }
}

/// The refinement's basin: stage 2's refinement as `fit_human` runs it on each survivor of the
/// search (the mask schedule, then the thermal polish when the capture has one), started from
/// the truth as our model states it with the root moved ±`offset_m` along the horizontal
/// objects→person line (where the size–distance ambiguity and the search's distance grid put
/// the error) and turned ±`turn_deg` — four starts, paired signs both ways — from the search's
/// "stand" template pose and the height prior's mean, as the search's candidates start. How
/// many end within a success's distance of the truth separates "the search does not land near
/// enough" from "the refinement cannot close the gap" in one run, with far less noise than root
/// medians over a cell.
pub(super) fn probe_basin(
    (truth, true_pose, true_vertices): (&HumanState, &[[f64; 3]], &[[f32; 3]]),
    b: &BasinProbe,
    priors: BodyPriors<'_>,
    rec: &Reconstruction,
    (seed, cfg): (u64, &ReconConfig),
) -> Result<Vec<BasinStart>, EvalError> {
    use irmirror_recon::human::search::facing_angle_deg;
    use rayon::prelude::*;
    let hcfg = cfg.human_settings();
    with_problem(priors, rec, &hcfg, |problem, edge| {
        let up = problem.up.normalize();
        let mut line = truth.translation - problem.objects_centre;
        line -= up * up.dot(&line);
        let line = line
            .try_normalize(1e-9)
            .unwrap_or_else(|| up.cross(&Vector3::x()).normalize());
        let generator = irmirror_body::prior::generator::PoseGenerator::new(priors.model);
        // Each pose drawn once (the templates are drawn from ranges), as the search does.
        let mut rng = irmirror_geom::rng::seeded(seed, 21);
        let latents: Vec<Vec<f64>> = b
            .poses
            .iter()
            .map(|name| {
                if name == TRUTH_LATENT || name == TRUTH_TWIN {
                    return Ok(truth.latent.clone());
                }
                if let Some(scale) = noisy_truth_scale(name) {
                    use rand_distr::{Distribution, StandardNormal};
                    return Ok(truth
                        .latent
                        .iter()
                        .map(|z| {
                            let n: f64 = StandardNormal.sample(&mut rng);
                            z + scale * n
                        })
                        .collect());
                }
                if name == NEAREST_BANK {
                    return Ok(problem.nearest_source_latent(true_pose)?);
                }
                let name = if [BANK, LIMBS, RETRIEVED, RETRIEVED_TWIN].contains(&name.as_str()) {
                    "stand"
                } else {
                    name
                };
                let rotvecs = generator.template(name, &mut rng).ok_or_else(|| {
                    irmirror_recon::ReconError::Config(format!(
                        "the pose generator has no {name:?} template"
                    ))
                })?;
                Ok(priors.prior.encode(&rotvecs)?)
            })
            .collect::<Result<_, EvalError>>()?;
        if latents.is_empty() {
            return Err(
                irmirror_recon::ReconError::Config("--basin-poses: no pose given".into()).into(),
            );
        }
        let (d, a) = (b.offset_m, b.turn_deg);
        let starts = [(d, a), (-d, -a), (d, -a), (-d, a)];
        starts
            .par_iter()
            .enumerate()
            .map(|(k, &(offset_m, turn_deg))| {
                let latent = latents[k % latents.len()].clone();
                let pose = b.poses[k % b.poses.len()].clone();
                let mut start = HumanState {
                    translation: truth.translation + line * offset_m,
                    rotation: irmirror_geom::rotation::axis_angle_to_matrix(
                        &(up * turn_deg.to_radians()),
                    ) * truth.rotation,
                    height: hcfg.height_prior[0],
                    build: hcfg.build,
                    latent,
                    residual: Vec::new(),
                };
                if pose == TRUTH_TWIN || pose == RETRIEVED_TWIN {
                    start = problem.twin(&start)?;
                }
                if pose == BANK {
                    let mut scfg = problem.search_config(&problem.prior_weighted(&hcfg));
                    if scfg.search.pose_bank == 0 {
                        scfg.search.pose_bank = 32;
                    }
                    start = problem
                        .bank_swap(vec![start], &scfg, seed.wrapping_add(k as u64))?
                        .remove(0);
                }
                if pose == LIMBS {
                    let mut scfg = problem.search_config(&problem.prior_weighted(&hcfg));
                    scfg.search.limb_survivors = 1;
                    start = problem
                        .limb_swap(vec![start], &scfg, seed.wrapping_add(k as u64))?
                        .remove(0);
                }
                if pose == RETRIEVED || pose == RETRIEVED_TWIN {
                    start = problem.retrieved_start(&start, &hcfg.retrieval)?;
                }
                let start_vertex_error_m = vertex_error(
                    &posed_body(priors.model, priors.prior, &start)?.vertices,
                    true_vertices,
                );
                let end = refine_as_fit(problem, &start, &hcfg, edge, seed.wrapping_add(k as u64))?;
                let Some(end) = end else {
                    return Ok(BasinStart {
                        pose,
                        offset_m,
                        turn_deg,
                        root_error_m: None,
                        facing_error_deg: None,
                        data_loss: None,
                        vertex_error_m: None,
                        start_vertex_error_m,
                    });
                };
                Ok(BasinStart {
                    pose,
                    offset_m,
                    turn_deg,
                    root_error_m: Some((end.translation - truth.translation).norm()),
                    facing_error_deg: Some(facing_angle_deg(&up, &end.rotation, &truth.rotation)),
                    data_loss: Some(problem.full_eval(&end, &hcfg)?.data),
                    vertex_error_m: vertex_error(
                        &posed_body(priors.model, priors.prior, &end)?.vertices,
                        true_vertices,
                    ),
                    start_vertex_error_m,
                })
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `truth-latent~S` names a noise scale S ≥ 0; anything else is not such a start.
    #[test]
    fn noisy_truth_names_parse() {
        assert_eq!(noisy_truth_scale("truth-latent~0.5"), Some(0.5));
        assert_eq!(noisy_truth_scale("truth-latent~0"), Some(0.0));
        for bad in [
            "truth-latent",
            "truth-latent~",
            "truth-latent~-1",
            "truth-latent~x",
            "stand~1",
        ] {
            assert_eq!(noisy_truth_scale(bad), None, "{bad}");
        }
    }
}
