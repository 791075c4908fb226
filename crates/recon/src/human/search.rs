//! Stage 2's global search, then refinement.
//!
//! A mirror image pins the person's direction from the objects well, but not their distance
//! along the reflected rays, their facing (a silhouette seen in a mirror barely tells front
//! from back) or their size. So the fit does not start from one guess:
//!
//! 1. **Candidates** on a grid: `yaw_bins` facing directions over the full circle (relative to
//!    facing the objects) × `distances` root distances log-spaced over `init_distance_m` along
//!    the mask's mean reflected ray (the feet on the floor when it is known) × `pose_modes`
//!    (stand, walk, sit: templates of the pose set, encoded by the prior; the prior's mean,
//!    latent 0, is a half-crouch that fits nobody's silhouette) × `builds` (body builds,
//!    each state's own from then on; default: `[human] build` alone). Default 8 × 12 × 3 =
//!    288 (`grid.rs`).
//! 2. **Screening, then successive halving.** All candidates are scored as they stand (one
//!    forward pass at the blur `screen_sigma_m2`); the best `keep_scored` go on (with
//!    `distinct_cuts`, off by default, the best distinct ones: root > 25 cm or facing > 45°
//!    from every better one kept). Each round
//!    runs them for a few Adam steps (the blur annealed over `round_sigma_m2`),
//!    ranks them and keeps the better half; the rounds double the steps so each costs about the
//!    same. Cheap steps are enough to fall into a basin, not to finish it. Screening, steps and
//!    ranking all use one fixed batch of `score_rays` rays: every mask ray (up to half) and a
//!    uniform sample of the others, importance-weighted ([`HumanProblem::stratified_batch`]).
//!    Screening scores the mask (overlap is what sorts a grid at its blur). With the
//!    radiometric term on ([`super::radiometric`]) and `polish_iterations` > 0 (default 40) the
//!    rounds and the refinement fit the mask too, the best `polish_best` refined hypotheses by
//!    the rise (default 1; 0: all) and the best one's front/back partner then take that many
//!    steps on the thermal rise (at `polish_lr_scale` of the learning rates: they start
//!    converged; on one fixed batch, `polish_rays`: the loss they are ranked on; the best
//!    state a polish evaluates is kept, as every step scores the same loss), and the
//!    final ranking is on the rise — where front and back
//!    differ; with 0 the rounds and the refinement fit the rise throughout (with
//!    `mask_rounds`, the refinement alone).
//! 3. **Survivors**: the best `inits / 2` (with flips; `inits` without) that are distinct
//!    (root > 25 cm or facing > 45° apart, as reported hypotheses) — with `pose_bank` > 0
//!    (off by default) each first tried in the pose bank's poses at its root and facing
//!    ([`super::bank`]: kept in the pose that scores best after the last round's steps), with
//!    `limb_survivors` > 0 (off) changed part by part ([`super::limbs`]) —, and the front/back
//!    flip of each (turned 180° about the up axis through the root; with `twin_flips`, off,
//!    its silhouette twin): both run the refinement's
//!    schedule (σ annealed to `sigma_m2[1]`) and are ranked on all rays. On a reflection of at
//!    most `refine_rays / 2` pixels the refinement steps on one fixed batch of `refine_rays`
//!    rays, edge-focused and importance-weighted ([`HumanProblem::focused_batch`]), at
//!    `refine_lr_scale` of the learning rates: they start in a basin the rounds found. On
//!    fresh edge draws at the full rates (the paper's schedule, `refine_rays` = 0) Adam
//!    random-walked: from the exact truth it raised the rise's data term by more than 0.025
//!    on 4 of 8 tuning bowls (0.111 → 0.188, 0.198 → 0.293, 0.132 → 0.253); on the fixed
//!    batch at half the rates on 1. A larger capture (a car door) keeps the fresh
//!    draws at the full rates ([`HumanProblem::refine_sample`]).
//! 4. **The rise pass**: on a reflection of at most `rise_pass_max_mask_px` pixels (50),
//!    steps 1–3 run again with the rise throughout and their hypotheses are reported, the
//!    best first (with `rise_pass_side`, the best on the first pass's winner's side), unless
//!    it lies more than `rise_pass_max_move_m` (0.5 m) from that winner
//!    ([`HumanProblem::rise_pass`]): the mask's search finds the basin, the rise places the
//!    person in it. Its fixed batches are those of the other passes; on so small a capture
//!    they take every pixel (a sample of its pixels would need most of its rays).

use super::polish::{polish_refined, polish_rise};
use super::problem::{Draw, FullEval};
use super::scratch::Scratch;
use super::{
    Batch, FittedRadiometry, HumanConfig, HumanFit, HumanProblem, HumanState, Hypothesis,
    edge_distance, shaped_body, stature_m, upright_facing,
};
use crate::ReconError;
use irmirror_geom::rotation::{axis_angle_to_matrix, matrix_to_axis_angle};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The largest share of the object pixels a person's reflection can cover: beyond it the mask
/// has no edge left to fit (every pixel a target, any body large enough scores IoU 1).
pub const MAX_MASK_SHARE: f64 = 0.95;

/// The global search's schedule (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SearchConfig {
    /// Facing directions over the full circle.
    pub yaw_bins: usize,
    /// Root distances along the mask's mean reflected ray.
    pub distances: usize,
    /// Pose modes: activity templates of the pose set (`irmirror_body::prior::generator`),
    /// encoded by the prior. People near a car stand or walk; at a table they may sit.
    pub pose_modes: Vec<String>,
    /// Body builds (phenotypes; each state's height slider is fitted on top) the candidates
    /// are made in, each a state's own through the rounds and the refinement; empty (default):
    /// `[human] build` alone. Four (gender 0.2 / 0.8 × weight 0.3 / 0.7) on the 8 tuning cars:
    /// root +0.070 ± 0.150 m, 4 better / 4 worse — the grid's survivors spread over the builds
    /// (EXPERIMENTS.md, "Thirtieth run").
    pub builds: Vec<irmirror_body::Phenotype>,
    /// Candidates kept after scoring the grid as it stands (no steps). 64 (4× the halving's
    /// steps) turned the 8 tuning cars' facing right 5 → 8, but on 24 held-out cars root
    /// +0.065 ± 0.099 m and successes 12 → 6: a wider search finds more wrong states the loss
    /// prefers to the truth (EXPERIMENTS.md, "Thirtieth run").
    pub keep_scored: usize,
    /// Halving rounds.
    pub rounds: usize,
    /// Adam steps of the first round (doubled each round).
    pub first_steps: usize,
    /// Rays of the fixed, stratified batch the rounds step on and rank with.
    pub score_rays: usize,
    /// The blur of the screening pass, m² (the occupancy's cost grows with it: every triangle
    /// within ≈ 3σ of a ray is visited).
    pub screen_sigma_m2: f64,
    /// The blur the rounds anneal from and to (and rank at the second), m².
    pub round_sigma_m2: [f64; 2],
    /// Cut to distinct states (root > 25 cm or facing > 45° apart) at the screening and each
    /// halving, not to the best alone. Off: it found lower losses (held-out fits' data term
    /// lower in every cell) but not nearer people, and the bowls' 2-D keypoints got worse on
    /// both sets (EXPERIMENTS.md, "Tenth run").
    pub distinct_cuts: bool,
    /// Refine each survivor's front/back flip too.
    pub flips: bool,
    /// Poses of the pose bank each survivor is tried in ([`super::bank`]); 0 (default): none.
    /// Off by default: at 32 on the held-out quick set successes went 5 → 7 of 32, but
    /// per-vertex errors moved both ways (10 captures better, 8 worse; the mugs 1 / 5), no
    /// interval excluded 0, on 24 more bowls and 24 cars it gained nothing (successes 10 → 9,
    /// 9 → 7), and a frame took ≈ 10 % longer (EXPERIMENTS.md, "Fifteenth run").
    pub pose_bank: usize,
    /// The bank's best poses per survivor that take the last round's steps.
    pub bank_keep: usize,
    /// The survivors tried in the bank, best first (0: all).
    pub bank_survivors: usize,
    /// 0 (default): the bank's poses screened by one forward pass, the best `bank_keep` take
    /// the last round's steps. N > 0: successive halving over the bank's poses and the
    /// survivor itself, as the search's [`HumanProblem::halve`]: screened to
    /// `bank_keep << N`, then N halving rounds of `first_steps`, doubled each round. Off: on
    /// 8 held-out bowls with every source pose (`pose_bank = 1000, bank_rounds = 4`)
    /// per-vertex median 0.257 → 0.182 m (paired −0.038 ± 0.109), but stage 2 46.8 s
    /// a capture alone (EXPERIMENTS.md, "Twenty-second run").
    pub bank_rounds: usize,
    /// Configurations per body part the limb search tries ([`super::limbs`]).
    pub limb_options: usize,
    /// The limb search's sweeps over the body parts (it stops early when a sweep changes
    /// nothing).
    pub limb_sweeps: usize,
    /// The survivors the limb search starts from, best first; 0 (default): none. Off: on 24
    /// held-out bowls it moved nothing (paired per-vertex +0.004 ± 0.029 m), on 12 cars facing
    /// within 30° went 9 → 6 (EXPERIMENTS.md, "Seventeenth run").
    pub limb_survivors: usize,
    /// The best refined hypotheses (by the full loss) the limb polish tries to better
    /// ([`HumanProblem::limb_polish`]: a limb search at the refined root and facing, then the
    /// refinement again, kept when lower); 0 (default): none. Off: on 24 held-out bowls root
    /// median 0.166 → 0.130 m but per-vertex −0.006 ± 0.023 m, and +10.5 s a frame (EXPERIMENTS.md,
    /// "Seventeenth run").
    pub limb_polish: usize,
    /// The best refined hypotheses (by the full loss) the yaw polish tries to better
    /// ([`HumanProblem::yaw_polish`]: the root turned by ± `yaw_polish_deg` about the up axis,
    /// each refined again, the lowest kept when below the hypothesis); 0: none. Default 2,
    /// where the refinement draws fresh batches (a car door's reflection; on a tabletop's
    /// fixed batch only with `yaw_polish_fixed_batch`): on 24 tuning cars root −0.087 ± 0.052
    /// m (paired; 15 better / 3 worse), per-vertex −0.062 ± 0.039 m (EXPERIMENTS.md,
    /// "Thirty-seventh run").
    pub yaw_polish: usize,
    /// The yaw polish on captures whose refinement steps on one fixed batch too (the
    /// tabletops). Off: there it lowers turned states' losses below the right ones — on 24
    /// held-out bowls per-vertex +0.029 ± 0.050 m, facing within 30° 13 → 9 (EXPERIMENTS.md,
    /// "Twenty-fifth run").
    pub yaw_polish_fixed_batch: bool,
    /// The yaw polish's turn, degrees.
    pub yaw_polish_deg: f64,
    /// The best refined hypotheses (by the full loss) the place polish tries to better
    /// ([`HumanProblem::place_polish`]: the root moved nearer and farther along the line from
    /// the mirror by `place_polish_frac` of its distance, each refined again, the lowest kept
    /// when below the hypothesis); 0 (default): none. At 2 on 24 held-out cars root +0.017 ±
    /// 0.127 m (EXPERIMENTS.md, "Thirtieth run").
    pub place_polish: usize,
    /// The place polish's move, a fraction of the person's distance from the mirror (0–1).
    pub place_polish_frac: f64,
    /// Each survivor's partner is its silhouette twin ([`HumanProblem::twin`]: pose mirrored,
    /// root turned so an orthographic view along the objects→person line is unchanged) rather
    /// than its root turned 180° (`flipped`). Off:
    /// on 24 held-out mugs successes 0 → 4, on 24 bowls 10 → 7 (EXPERIMENTS.md, "Seventeenth run");
    /// retried since (successes): tuning bowls 9 → 11, held-out bowls 10 → 6, tuning mugs
    /// 5 → 4, tuning hard view 4 → 0 (EXPERIMENTS.md, "Thirty-sixth run").
    pub twin_flips: bool,
    /// With the rise throughout (`[human.radiometric] polish_iterations = 0`), the rounds
    /// still fit the mask (one ray per pixel, as before a polish) and the refinement the rise.
    /// Cheaper (a mug frame 1.1× the default's CPU, the rise's rounds 1.35×), but the rise
    /// helps where the rounds choose the basin: 48 held-out mugs at 2 × 2 footprints, per
    /// vertex −0.007 ± 0.048 m with it, −0.051 ± 0.051 m with the rise's rounds (paired vs the
    /// default; EXPERIMENTS.md, "Fifty-first run"). Off by default.
    pub mask_rounds: bool,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            yaw_bins: 8,
            distances: 12,
            pose_modes: ["stand", "walk", "sit"].map(String::from).to_vec(),
            builds: Vec::new(),
            keep_scored: 16,
            rounds: 2,
            first_steps: 8,
            score_rays: 1200,
            screen_sigma_m2: 1e-4,
            round_sigma_m2: [3e-4, 3e-5],
            distinct_cuts: false,
            flips: true,
            pose_bank: 0,
            bank_keep: 2,
            bank_survivors: 0,
            bank_rounds: 0,
            limb_options: 24,
            limb_sweeps: 2,
            limb_survivors: 0,
            limb_polish: 0,
            yaw_polish: 2,
            yaw_polish_fixed_batch: false,
            yaw_polish_deg: 25.0,
            place_polish: 0,
            place_polish_frac: 0.12,
            twin_flips: false,
            mask_rounds: false,
        }
    }
}

impl SearchConfig {
    /// The hypotheses the yaw polish takes: `yaw_polish`, or none where the refinement steps
    /// on a `fixed_batch` and `yaw_polish_fixed_batch` is off.
    pub fn yaw_polishes(&self, fixed_batch: bool) -> usize {
        if fixed_batch && !self.yaw_polish_fixed_batch {
            0
        } else {
            self.yaw_polish
        }
    }
}

/// A rotation of `r` by 180° about `up` (the root stays): the front/back flip.
pub fn flipped(up: &Vector3<f64>, r: &Matrix3<f64>) -> Matrix3<f64> {
    axis_angle_to_matrix(&(up.normalize() * std::f64::consts::PI)) * r
}

/// Two states far enough apart to report both: root > 25 cm apart or facing > 45° apart.
fn distinct(a: &HumanState, b: &HumanState) -> bool {
    let far = (a.translation - b.translation).norm() > 0.25;
    let turned =
        (a.rotation.transpose() * b.rotation).trace() < 1.0 + 2.0 * 45f64.to_radians().cos();
    far || turned
}

/// The indices of the best `want` of `ranked` (best first) that are [`distinct`] from each
/// other (in rank order), then the next best when there are too few distinct ones.
fn best_distinct(ranked: &[HumanState], want: usize) -> Vec<usize> {
    let mut chosen: Vec<usize> = Vec::with_capacity(want);
    for (i, st) in ranked.iter().enumerate() {
        if chosen.len() < want && chosen.iter().all(|&k| distinct(&ranked[k], st)) {
            chosen.push(i);
        }
    }
    for i in 0..ranked.len() {
        if chosen.len() < want && !chosen.contains(&i) {
            chosen.push(i);
        }
    }
    chosen
}

/// The search's cut: the best `keep` of `scored` (sorted best first), or with `distinct`
/// [`best_distinct`]'s — basins, not one basin several times (a grid's neighbours and its pose
/// modes at one place and facing fall into one basin).
fn cut(scored: Vec<(f64, HumanState)>, keep: usize, distinct: bool) -> Vec<HumanState> {
    let states: Vec<HumanState> = scored.into_iter().map(|(_, st)| st).collect();
    if !distinct {
        return states.into_iter().take(keep).collect();
    }
    let chosen = best_distinct(&states, keep);
    let mut states: Vec<Option<HumanState>> = states.into_iter().map(Some).collect();
    chosen
        .into_iter()
        .filter_map(|i| states[i].take())
        .collect()
}

/// Two root rotations facing more than 135° apart: a front/back pair.
pub(super) fn front_back(up: &Vector3<f64>, a: &Matrix3<f64>, b: &Matrix3<f64>) -> bool {
    facing_angle_deg(&up.normalize(), a, b) > 135.0
}

/// Angle between two root rotations' facing (Anny's −Y) about `up`, degrees.
pub fn facing_angle_deg(up: &Vector3<f64>, a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let flat = |r: &Matrix3<f64>| {
        let f = -(r * Vector3::y());
        (f - up * up.dot(&f)).try_normalize(1e-9)
    };
    match (flat(a), flat(b)) {
        (Some(x), Some(y)) => x.dot(&y).clamp(-1.0, 1.0).acos().to_degrees(),
        _ => 0.0,
    }
}

impl HumanProblem<'_> {
    /// Each state's loss on `batch` as it stands (no gradient, no steps), in parallel with one
    /// scratch per thread; the states in their order.
    pub(super) fn score_states(
        &self,
        states: Vec<HumanState>,
        batch: &Batch<'_>,
        cfg: &HumanConfig,
    ) -> Result<Vec<(f64, HumanState)>, ReconError> {
        states
            .into_par_iter()
            .map_init(
                || None::<Scratch>,
                |ws, st| {
                    let ws = match ws {
                        Some(ws) => ws,
                        None => ws.insert(self.scratch()?),
                    };
                    let (loss, _) = self.score(ws, &st, batch, cfg)?;
                    Ok((loss, st))
                },
            )
            .collect()
    }

    /// Successive halving over `candidates` (module docs): the survivors, best first.
    pub(super) fn halve(
        &self,
        candidates: Vec<HumanState>,
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let s = &cfg.search;
        let thermal = self.radiometric(cfg).is_some();
        let sample = self.stratified_batch(s.score_rays, seed, thermal);
        // The rounds rank on the thermal rise when that term is on.
        let batch = sample.batch(s.round_sigma_m2[1]);
        let t0 = std::time::Instant::now();
        // The grid as it stands, at the starting blur: position along the rays and facing
        // decide most of the overlap, so a forward pass sorts out most candidates.
        // The screening pass sees the mask: at its blur, overlap is what sorts the grid (and
        // it is 288 forward passes). On the rise, the rise pass's screening was no better on
        // the held-out hard view (root +0.011 ± 0.021 m against the mask's, paired) and took
        // ≈ 2.5× as long (EXPERIMENTS.md, "Forty-eighth run").
        let coarse = Batch {
            sigma_m2: s.screen_sigma_m2,
            rise: None,
            ..batch
        };
        let mut scored = self.score_states(candidates, &coarse, cfg)?;
        scored.retain(|(l, _)| l.is_finite());
        tracing::debug!("screening: {:.2} s", t0.elapsed().as_secs_f64());
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        trace_states("screen", &scored);
        let mut candidates = cut(scored, s.keep_scored.max(1), s.distinct_cuts);
        for round in 0..s.rounds {
            // The rounds move the prior's poses only: a few steps are to fall into a basin,
            // and the residual's freedom would let a wrong one fit its outline as well.
            let round_cfg = HumanConfig {
                iterations: s.first_steps << round,
                sigma_m2: s.round_sigma_m2,
                lr_residual: 0.0,
                ..cfg.clone()
            };
            let mut scored: Vec<(f64, HumanState)> = candidates
                .par_iter()
                .enumerate()
                .map_init(
                    || None::<Scratch>,
                    |ws, (k, st)| {
                        let run_seed = seed
                            .wrapping_mul(7919)
                            .wrapping_add((round * 10_000 + k) as u64);
                        let Some((end, _)) =
                            self.run(st, &round_cfg, Draw::Fixed(batch), run_seed)?
                        else {
                            return Ok(None);
                        };
                        let ws = match ws {
                            Some(ws) => ws,
                            None => ws.insert(self.scratch()?),
                        };
                        let (loss, _) = self.score(ws, &end, &batch, cfg)?;
                        Ok(loss.is_finite().then_some((loss, end)))
                    },
                )
                .collect::<Result<Vec<_>, ReconError>>()?
                .into_iter()
                .flatten()
                .collect();
            scored.sort_by(|a, b| a.0.total_cmp(&b.0));
            trace_states(&format!("round{round}"), &scored);
            if let Some((best, st)) = scored.first() {
                tracing::debug!(
                    "search round {round} ({:.2} s): {} candidates, best loss {best:.3} at {:.2} m from the objects, turned {:.0}° from facing them",
                    t0.elapsed().as_secs_f64(),
                    scored.len(),
                    (st.translation - self.objects_centre).norm(),
                    facing_angle_deg(
                        &self.up,
                        &st.rotation,
                        &upright_facing(&self.up, &(self.objects_centre - st.translation))
                    )
                );
            }
            let keep = if round + 1 == s.rounds {
                scored.len()
            } else {
                scored.len().div_ceil(2)
            };
            candidates = cut(scored, keep, s.distinct_cuts);
        }
        Ok(candidates)
    }

    /// The hypotheses refined fully: the best distinct survivors of the search and, with
    /// `flips`, the front/back flip of each (`inits` in all).
    pub fn initial_states(
        &self,
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let t0 = std::time::Instant::now();
        let ranked = self.halve(self.candidates(cfg, seed)?, cfg, seed)?;
        tracing::debug!("global search: {:.2} s", t0.elapsed().as_secs_f64());
        let flips = cfg.search.flips;
        let want = if flips {
            cfg.inits.div_ceil(2)
        } else {
            cfg.inits
        }
        .max(1);
        let survivors: Vec<HumanState> = best_distinct(&ranked, want)
            .into_iter()
            .map(|i| ranked[i].clone())
            .collect();
        let survivors = self.bank_swap(survivors, cfg, seed)?;
        let survivors = self.limb_swap(survivors, cfg, seed)?;
        let survivors = self.facing_swap(survivors, cfg)?;
        let survivors = self.retrieval_swap(survivors, &cfg.retrieval)?;
        let mut out = Vec::with_capacity(cfg.inits);
        for st in survivors {
            if flips && out.len() + 1 < cfg.inits.max(2) {
                let f = if cfg.search.twin_flips {
                    self.twin(&st)?
                } else {
                    HumanState {
                        rotation: flipped(&self.up, &st.rotation),
                        ..st.clone()
                    }
                };
                out.push(st);
                out.push(f);
            } else {
                out.push(st);
            }
        }
        Ok(out)
    }
}

/// Logs scored states (trace level): loss, root, facing (Anny's −Y in the depth frame).
fn trace_states(phase: &str, scored: &[(f64, HumanState)]) {
    for (l, st) in scored {
        let f = -(st.rotation * Vector3::y());
        tracing::trace!(
            "cand {phase} {l:.4} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3}",
            st.translation.x,
            st.translation.y,
            st.translation.z,
            f.x,
            f.y,
            f.z
        );
    }
}

/// The seed of survivor `k`'s refinement (and of its polish).
pub(super) fn run_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_mul(1000).wrapping_add(k as u64)
}

/// A refined survivor: its index among the starts, end state, loss curve, and its evaluation
/// on all rays when one was made for that state (the polish's ranking), so the final scoring
/// does not repeat it.
pub(super) struct Refined {
    pub(super) init: usize,
    pub(super) state: HumanState,
    pub(super) curve: Vec<f64>,
    pub(super) eval: Option<FullEval>,
}

impl Refined {
    /// Its evaluation on all rays: the one kept, or made now.
    pub(super) fn evaluated(
        &self,
        problem: &HumanProblem<'_>,
        cfg: &HumanConfig,
    ) -> Result<FullEval, ReconError> {
        match &self.eval {
            Some(e) => Ok(e.clone()),
            None => problem.full_eval(&self.state, cfg),
        }
    }
}

/// Each kept hypothesis' data term with its head's face and hair turned
/// ([`Hypothesis::head_turned_data_loss`]) and its predicted rise per region
/// ([`FittedRadiometry::rise_k_px`]), with the radiometric term.
fn head_cue(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    kept: &mut [(Hypothesis, HumanState)],
) -> Result<(), ReconError> {
    let Some(rad) = problem.radiometric(cfg) else {
        return Ok(());
    };
    let t0 = std::time::Instant::now();
    let turned = rad.head_turned(problem.model)?;
    let turned = HumanProblem {
        radiometry: Some(&turned),
        ..*problem
    };
    for (h, s) in kept.iter_mut() {
        let d = turned.full_eval(s, cfg)?.data;
        tracing::debug!(
            "head cue: data {:.4}, head turned {:.4}, loss {:.4}",
            h.data_loss,
            d,
            h.loss
        );
        h.head_turned_data_loss = Some(d);
        if let Some(r) = h.radiometry.as_mut() {
            let body = super::posed_body(problem.model, problem.prior, s)?;
            r.rise_k_px = problem.region_rise(&body.vertices, cfg).map(Into::into);
        }
    }
    tracing::debug!("head cue: {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// Hypotheses with their states, best first.
type Ranked = Vec<(Hypothesis, HumanState)>;

/// One search and refinement with `cfg` (the mask's, then the thermal polish, or the rise
/// throughout: [`HumanProblem::search_config`]; the rounds on the mask with `mask_rounds`:
/// [`HumanProblem::rounds_config`]): the refined hypotheses best first (by the
/// full loss, then the thermal judge's front/back choice), and how many diverged.
fn ranked(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<(Ranked, usize), ReconError> {
    // With a polish, the search and refinement fit the mask and the thermal rise comes last.
    let thermal = problem.radiometric(cfg).is_some();
    let polish = if thermal {
        cfg.radiometric.polish_iterations
    } else {
        0
    };
    let inits = problem.initial_states(&problem.rounds_config(cfg), seed)?;
    let t0 = std::time::Instant::now();
    let edge_dist = edge_distance(problem.mask);
    let sample = problem.refine_sample(cfg, seed);
    let mut refined: Vec<Option<Refined>> = inits
        .par_iter()
        .enumerate()
        .map(|(k, init)| {
            let r = problem.refine(init, cfg, &edge_dist, sample.as_ref(), run_seed(seed, k))?;
            progress(k);
            Ok(r.map(|(state, curve)| Refined {
                init: k,
                state,
                curve,
                eval: None,
            }))
        })
        .collect::<Result<_, ReconError>>()?;
    polish_refined(
        problem,
        cfg,
        (&edge_dist, sample.as_ref()),
        seed,
        &mut refined,
    )?;
    if polish > 0 {
        tracing::debug!("mask refinement: {:.2} s", t0.elapsed().as_secs_f64());
        polish_rise(problem, cfg, seed, &mut refined)?;
    }
    tracing::debug!("refinement: {:.2} s", t0.elapsed().as_secs_f64());
    let diverged = refined.iter().filter(|r| r.is_none()).count();
    let done: Vec<Refined> = refined.into_iter().flatten().collect();
    if done.is_empty() {
        return Err(ReconError::Diverged {
            stage: "human fit",
            runs: diverged,
        });
    }
    let mut scored: Vec<(Hypothesis, HumanState)> = done
        .into_par_iter()
        .map(|r| {
            let eval = r.evaluated(problem, cfg)?;
            Ok((
                hypothesis(problem, cfg, r.init, &r.state, eval, r.curve)?,
                r.state,
            ))
        })
        .collect::<Result<_, ReconError>>()?;
    scored.sort_by(|a, b| a.0.loss.total_cmp(&b.0.loss));
    problem.facing_rank(&mut scored, cfg)?;
    tracing::debug!("refinement + scoring: {:.2} s", t0.elapsed().as_secs_f64());
    Ok((scored, diverged))
}

/// Fits the person: global search, every survivor refined in parallel, best first, its
/// front/back partner next, distinct top-k. On a small reflection
/// ([`HumanProblem::rise_pass`]) a second search fits the rise throughout and its hypotheses
/// are reported, its best first (with
/// [`super::radiometric::RadiometricConfig::rise_pass_side`], its best on the first search's
/// winner's side).
pub fn fit_human(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<(HumanFit, Vec<HumanState>), ReconError> {
    cfg.check()?;
    let cfg = &problem.prior_weighted(cfg);
    let s = &cfg.search;
    let mut candidates =
        s.yaw_bins.max(1) * s.distances.max(1) * s.pose_modes.len() * s.builds.len().max(1);
    let (mut scored, mut diverged) = ranked(problem, cfg, seed, progress)?;
    if let Some(rise_cfg) = problem.rise_pass(cfg) {
        let (lead, lead_root) = (scored[0].1.rotation, scored[0].1.translation);
        let (mut rise, d) = ranked(problem, &rise_cfg, seed, progress)?;
        let up = problem.up.normalize();
        let off: Vec<f64> = rise
            .iter()
            .map(|(_, st)| facing_angle_deg(&up, &st.rotation, &lead))
            .collect();
        let first = super::refine::rise_pass_first(&off, cfg.radiometric.rise_pass_side);
        let moved = |j: usize| (rise[j].1.translation - lead_root).norm();
        let max_move = cfg.radiometric.rise_pass_max_move_m;
        if let Some(j) = first.filter(|&j| max_move <= 0.0 || moved(j) <= max_move) {
            tracing::debug!(
                "rise pass: its hypothesis {j} first, turned {:.0}° from the mask search's winner, {:.2} m from it",
                off[j],
                moved(j)
            );
            let h = rise.remove(j);
            rise.insert(0, h);
            scored = rise;
        }
        (diverged, candidates) = (diverged + d, 2 * candidates);
    }
    let top_k = cfg.top_k.max(1);
    let mut kept: Vec<(Hypothesis, HumanState)> = Vec::new();
    let mut rest = scored.into_iter();
    if let Some(best) = rest.next() {
        kept.push(best);
    }
    let mut rest: Vec<_> = rest.collect();
    // The best one's front/back partner: what a binary silhouette cannot rule out.
    if top_k > 1
        && let Some(i) = rest
            .iter()
            .position(|(_, s)| front_back(&problem.up, &s.rotation, &kept[0].1.rotation))
    {
        kept.push(rest.remove(i));
    }
    for (h, s) in rest {
        if kept.len() < top_k && kept.iter().all(|(_, k)| distinct(k, &s)) {
            kept.push((h, s));
        }
    }
    // The parts no ray sees, in the template's configuration (ranked as refined: the reset
    // moves the data term by at most its tolerance, the priors by what no ray decides).
    kept.par_iter_mut().try_for_each(|(h, st)| {
        let (reset, eval, changed) = problem.unseen_reset(st, Some(h.data_loss), cfg)?;
        tracing::debug!("hypothesis {}: {changed} unseen parts reset", h.init);
        if let Some(eval) = eval {
            let curve = std::mem::take(&mut h.loss_curve);
            *h = hypothesis(problem, cfg, h.init, &reset, eval, curve)?;
            *st = reset;
        }
        Ok::<(), ReconError>(())
    })?;
    head_cue(problem, cfg, &mut kept)?;
    let mask_rays = problem
        .rays
        .pixel
        .iter()
        .filter(|&&p| problem.mask.data[p as usize])
        .count();
    let (hyps, states): (Vec<Hypothesis>, Vec<HumanState>) = kept.into_iter().unzip();
    Ok((
        HumanFit {
            hypotheses: hyps,
            candidates,
            diverged,
            rays: problem.rays.len(),
            mask_rays,
            data_term: if problem.radiometric(cfg).is_some() {
                "radiometric".into()
            } else {
                "mask".into()
            },
        },
        states,
    ))
}

/// The reported hypothesis of a refined state `st` from start `init`, evaluated on all rays.
fn hypothesis(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    init: usize,
    st: &HumanState,
    eval: FullEval,
    loss_curve: Vec<f64>,
) -> Result<Hypothesis, ReconError> {
    let radiometry = problem
        .radiometric(cfg)
        .zip(eval.scalars.as_ref())
        .map(|(r, s)| FittedRadiometry::new(r, s));
    Ok(Hypothesis {
        init,
        translation_m: st.translation.into(),
        root_rotvec_rad: matrix_to_axis_angle(&st.rotation).into(),
        height: st.height,
        build: st.build,
        stature_m: stature_m(&shaped_body(problem.model, &st.build, st.height)?),
        latent: st.latent.clone(),
        residual: st.residual.clone(),
        loss: eval.loss,
        data_loss: eval.data,
        soft_iou: eval.soft_iou,
        radiometry,
        head_turned_data_loss: None,
        loss_curve,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(x: f64, yaw_deg: f64) -> HumanState {
        HumanState {
            translation: Vector3::new(x, 0.0, 0.0),
            rotation: axis_angle_to_matrix(&(Vector3::z() * yaw_deg.to_radians())),
            height: 0.5,
            build: irmirror_body::Phenotype::default(),
            latent: Vec::new(),
            residual: Vec::new(),
        }
    }

    /// The yaw polish takes its hypotheses where the refinement draws fresh batches, and on a
    /// fixed batch only when asked to.
    #[test]
    fn the_yaw_polish_skips_a_fixed_batch_unless_asked() {
        let mut s = SearchConfig::default();
        assert_eq!((s.yaw_polishes(false), s.yaw_polishes(true)), (2, 0));
        s.yaw_polish_fixed_batch = true;
        assert_eq!((s.yaw_polishes(false), s.yaw_polishes(true)), (2, 2));
        s.yaw_polish = 0;
        assert_eq!((s.yaw_polishes(false), s.yaw_polishes(true)), (0, 0));
    }

    /// The cuts keep one state per basin: neighbours (10 cm, 20° apart) give way to the next
    /// distinct state however far down the ranking it is, and too few basins are filled with
    /// the next best in rank order.
    #[test]
    fn the_cuts_keep_distinct_basins() {
        let ranked = [
            state(0.0, 0.0),
            state(0.1, 0.0),
            state(0.0, 20.0),
            state(1.0, 0.0),
            state(0.0, 180.0),
        ];
        assert_eq!(best_distinct(&ranked, 3), vec![0, 3, 4]);
        assert_eq!(best_distinct(&ranked, 4), vec![0, 3, 4, 1]);
        let scored: Vec<(f64, HumanState)> = ranked
            .iter()
            .enumerate()
            .map(|(i, s)| (i as f64, s.clone()))
            .collect();
        let kept = cut(scored.clone(), 2, true);
        assert_eq!(kept.len(), 2);
        assert_eq!(kept[1].translation, ranked[3].translation);
        assert_eq!(cut(scored, 2, false)[1].translation, ranked[1].translation);
    }
}
