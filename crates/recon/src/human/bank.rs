//! The pose bank: the search's survivors tried in many poses.
//!
//! The search's grid places and turns the body in three pose modes; its rounds then move the
//! pose by gradient steps, which stay in the basin of the mode they started from. Placed at the
//! true root and facing, refinement from a template ended at twice the data term it reached
//! from the prior's encoding of the true pose (held-out bowls: 0.34–0.36 against 0.18,
//! EXPERIMENTS.md "Fourteenth run"): the pose's local minima, not the place, held the bowls' fits.
//! So each survivor is also tried in `pose_bank` poses spread over what the prior was trained on —
//! the real poses of `assets/poses/mocap_deepmimic.safetensors` and their mirror images, and the
//! activity templates (never the benchmark's persons) — chosen by farthest-point sampling in
//! joint-rotation space. Each is scored at the survivor's root and facing (its feet moved to the
//! floor when the floor is known) with one forward pass; the best `bank_keep` per survivor take
//! the last round's steps, and the best of them replaces the survivor if its loss after those
//! steps is lower than the survivor's (held-out figures: EXPERIMENTS.md, "Fifteenth run").

use super::{HumanConfig, HumanProblem, HumanState};
use crate::ReconError;
use irmirror_body::prior::generator::{PoseGenerator, TEMPLATES};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// A pose to start from: its latent and its root's height above its lowest vertex, standing
/// upright (where the root goes when the feet are on the floor).
#[derive(Clone, Debug)]
pub(super) struct PoseMode {
    pub latent: Vec<f64>,
    pub root_height: f64,
    /// The latent's decoded joint rotations, root identity: the retrieval poses every mode
    /// at every state it judges, so each is decoded once.
    pub rotations: Vec<Matrix3<f64>>,
}

/// Squared distance of two poses: the sum over body joints of their rotation vectors'.
fn pose_distance2(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .skip(1)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>())
        .sum()
}

/// Greedy farthest-point sampling: `n` indices of `poses`, from the first on.
pub(super) fn farthest_points(poses: &[Vec<[f64; 3]>], n: usize) -> Vec<usize> {
    let mut chosen = Vec::with_capacity(n.min(poses.len()));
    if poses.is_empty() || n == 0 {
        return chosen;
    }
    chosen.push(0);
    let mut nearest: Vec<f64> = poses.iter().map(|p| pose_distance2(p, &poses[0])).collect();
    while chosen.len() < n.min(poses.len()) {
        let (far, _) = nearest
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .expect("not empty");
        chosen.push(far);
        for (d, p) in nearest.iter_mut().zip(poses) {
            *d = d.min(pose_distance2(p, &poses[far]));
        }
    }
    chosen
}

/// `cfg` (as the search runs) for the last halving round's steps: what a survivor swapped into
/// another pose takes, as the survivors had.
pub(super) fn last_round(cfg: &HumanConfig) -> HumanConfig {
    let s = &cfg.search;
    HumanConfig {
        iterations: s.first_steps << s.rounds.saturating_sub(1),
        sigma_m2: s.round_sigma_m2,
        lr_residual: 0.0,
        ..cfg.clone()
    }
}

impl HumanProblem<'_> {
    /// The mode of one pose (rotation vectors, root ignored) of the rest body `shaped`
    /// ([`super::shaped_body`] of the problem's build at the height slider in question).
    pub(super) fn pose_mode(
        &self,
        rotvecs: &[[f64; 3]],
        shaped: &irmirror_body::ShapedBody<f64>,
    ) -> Result<PoseMode, ReconError> {
        self.pose_mode_into(rotvecs, shaped, &mut self.model.posed_buffers())
    }

    /// [`Self::pose_mode`], the surface posed into `body` (a caller making many reuses it).
    fn pose_mode_into(
        &self,
        rotvecs: &[[f64; 3]],
        shaped: &irmirror_body::ShapedBody<f64>,
        body: &mut irmirror_body::PosedBody<f64>,
    ) -> Result<PoseMode, ReconError> {
        let latent = self.prior.encode(rotvecs)?;
        let mut rotations = self.prior.decode(&latent)?;
        // Anny's own frame is Z up: the identity root stands upright.
        rotations[0] = Matrix3::identity();
        self.mode_at(latent, rotations, shaped, body)
    }

    /// The mode of a decoded pose (`rotations`, root identity) on the rest body `shaped`: its
    /// root's height above the lowest vertex measured, the surface posed into `body`.
    fn mode_at(
        &self,
        latent: Vec<f64>,
        rotations: Vec<Matrix3<f64>>,
        shaped: &irmirror_body::ShapedBody<f64>,
        body: &mut irmirror_body::PosedBody<f64>,
    ) -> Result<PoseMode, ReconError> {
        let pose = irmirror_body::Pose {
            rotations,
            translation: Vector3::zeros(),
        };
        self.model.pose_surface_into(shaped, &pose, body)?;
        let lowest = body
            .vertices
            .iter()
            .map(|v| v.z)
            .fold(f64::INFINITY, f64::min);
        Ok(PoseMode {
            latent,
            root_height: -lowest,
            rotations: pose.rotations,
        })
    }

    /// `bank`'s poses (made at any height) at `height`: only the root's height differs.
    pub(super) fn bank_at(
        &self,
        bank: &[PoseMode],
        height: f64,
    ) -> Result<Vec<PoseMode>, ReconError> {
        let shaped = super::shaped_body(self.model, &self.build, height)?;
        bank.par_iter()
            .map_init(
                || self.model.posed_buffers(),
                |body, m| self.mode_at(m.latent.clone(), m.rotations.clone(), &shaped, body),
            )
            .collect()
    }

    /// What the bank and the limb search choose from: the activity templates (one draw each,
    /// deterministic), then the prior's real training poses and their mirror images.
    pub(super) fn source_poses(&self) -> Result<Vec<Vec<[f64; 3]>>, ReconError> {
        let generator = PoseGenerator::new(self.model);
        let mut rng = irmirror_geom::rng::seeded(0, 43);
        let mut poses: Vec<Vec<[f64; 3]>> = TEMPLATES
            .iter()
            .filter_map(|name| generator.template(name, &mut rng))
            .collect();
        for p in irmirror_body::mocap::MocapSet::prior_training()?.poses {
            poses.push(generator.mirrored(&p));
            poses.push(p);
        }
        Ok(poses)
    }

    /// The prior's encoding of the source pose ([`Self::source_poses`]) nearest `rotvecs` in
    /// joint-rotation space: the best start a retrieval over the poses the prior was trained
    /// on could give (the basin probe's `nearest-bank` oracle).
    pub fn nearest_source_latent(&self, rotvecs: &[[f64; 3]]) -> Result<Vec<f64>, ReconError> {
        let poses = self.source_poses()?;
        let nearest = poses
            .iter()
            .min_by(|a, b| pose_distance2(a, rotvecs).total_cmp(&pose_distance2(b, rotvecs)))
            .ok_or_else(|| ReconError::Config("no source poses".into()))?;
        Ok(self.prior.encode(nearest)?)
    }

    /// `n` poses spread over the prior's training poses (module docs; `usize::MAX`: all of
    /// them), deterministic.
    pub(super) fn pose_bank(&self, n: usize, height: f64) -> Result<Vec<PoseMode>, ReconError> {
        let poses = self.source_poses()?;
        let shaped = super::shaped_body(self.model, &self.build, height)?;
        farthest_points(&poses, n)
            .into_par_iter()
            .map_init(
                || self.model.posed_buffers(),
                |body, i| self.pose_mode_into(&poses[i], &shaped, body),
            )
            .collect()
    }

    /// `st` in pose `mode`: the residual dropped, the feet moved to the floor when it is known.
    pub(super) fn in_mode(&self, st: &HumanState, mode: &PoseMode) -> HumanState {
        HumanState {
            translation: self.mode_root(st, mode),
            latent: mode.latent.clone(),
            residual: Vec::new(),
            ..st.clone()
        }
    }

    /// The root of `st` in pose `mode` ([`Self::in_mode`]).
    pub(super) fn mode_root(&self, st: &HumanState, mode: &PoseMode) -> Vector3<f64> {
        match self.floor {
            Some(f) => st.translation + f.up * (mode.root_height - f.height(&st.translation)),
            None => st.translation,
        }
    }

    /// Each survivor tried in the bank's poses (module docs); the survivors, each replaced by
    /// a better-scoring pose when one was found. `cfg` as the search runs
    /// ([`Self::search_config`]).
    pub fn bank_swap(
        &self,
        survivors: Vec<HumanState>,
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let s = &cfg.search;
        if s.pose_bank == 0 || s.bank_keep == 0 || survivors.is_empty() {
            return Ok(survivors);
        }
        let t0 = std::time::Instant::now();
        let bank = self.pose_bank(s.pose_bank, cfg.height_prior[0])?;
        let n_tried = match s.bank_survivors {
            0 => survivors.len(),
            n => n.min(survivors.len()),
        };
        if s.bank_rounds > 0 {
            return self.bank_halving(survivors, n_tried, &bank, cfg, seed);
        }
        let thermal = self.radiometric(cfg).is_some();
        let sample = self.stratified_batch(s.score_rays, seed, thermal);
        let batch = sample.batch(s.round_sigma_m2[1]);
        // Survivor i's trials are the i-th run of `bank.len()` states.
        let tried: Vec<HumanState> = survivors[..n_tried]
            .iter()
            .flat_map(|st| bank.iter().map(move |m| self.in_mode(st, m)))
            .collect();
        let own = self.score_states(survivors[..n_tried].to_vec(), &batch, cfg)?;
        let mut starts: Vec<(usize, HumanState)> = Vec::new();
        let mut screened = self.score_states(tried, &batch, cfg)?.into_iter();
        for i in 0..n_tried {
            let mut mine: Vec<(f64, HumanState)> = screened
                .by_ref()
                .take(bank.len())
                .filter(|(l, _)| l.is_finite())
                .collect();
            mine.sort_by(|a, b| a.0.total_cmp(&b.0));
            starts.extend(mine.into_iter().take(s.bank_keep).map(|(_, st)| (i, st)));
        }
        // The last round's steps, as the survivors had.
        let steps_cfg = last_round(cfg);
        let ends: Vec<(usize, f64, HumanState)> = starts
            .par_iter()
            .enumerate()
            .map(|(k, (i, st))| {
                let run_seed = seed.wrapping_mul(7919).wrapping_add(50_000 + k as u64);
                let Some((end, _)) =
                    self.run(st, &steps_cfg, super::Draw::Fixed(batch), run_seed)?
                else {
                    return Ok(None);
                };
                let mut ws = self.scratch()?;
                let (loss, _) = self.score(&mut ws, &end, &batch, cfg)?;
                Ok(loss.is_finite().then_some((*i, loss, end)))
            })
            .collect::<Result<Vec<_>, ReconError>>()?
            .into_iter()
            .flatten()
            .collect();
        let mut out = survivors;
        let mut best: Vec<f64> = own.iter().map(|o| o.0).collect();
        let mut swapped = vec![false; n_tried];
        for (i, loss, end) in ends {
            if loss < best[i] || !best[i].is_finite() {
                best[i] = loss;
                out[i] = end;
                swapped[i] = true;
            }
        }
        tracing::debug!(
            "pose bank: {} poses × {n_tried} survivors, {} swapped, {:.2} s",
            bank.len(),
            swapped.iter().filter(|&&b| b).count(),
            t0.elapsed().as_secs_f64()
        );
        Ok(out)
    }

    /// [`HumanProblem::bank_swap`] by successive halving (`bank_rounds` > 0): each of the
    /// first `n_tried` survivors and its bank poses go through the search's halving, screened
    /// to `bank_keep << bank_rounds`; the best at the end takes the survivor's place.
    fn bank_halving(
        &self,
        survivors: Vec<HumanState>,
        n_tried: usize,
        bank: &[PoseMode],
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let s = &cfg.search;
        let t0 = std::time::Instant::now();
        let halving = HumanConfig {
            search: super::search::SearchConfig {
                keep_scored: s.bank_keep.max(1) << s.bank_rounds,
                rounds: s.bank_rounds,
                ..s.clone()
            },
            ..cfg.clone()
        };
        let mut out = survivors;
        for (i, st) in out.iter_mut().take(n_tried).enumerate() {
            let mut tried: Vec<HumanState> = vec![st.clone()];
            tried.extend(bank.iter().map(|m| self.in_mode(st, m)));
            let run_seed = seed.wrapping_mul(7919).wrapping_add(60_000 + i as u64);
            if let Some(best) = self.halve(tried, &halving, run_seed)?.into_iter().next() {
                *st = best;
            }
        }
        tracing::debug!(
            "pose bank by halving: {} poses × {n_tried} survivors, {:.2} s",
            bank.len(),
            t0.elapsed().as_secs_f64()
        );
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Farthest-point sampling takes the first pose, then the one farthest from it, then the
    /// one farthest from both — never a near-duplicate while a distinct pose is left.
    #[test]
    fn farthest_points_spread_over_the_poses() {
        let pose = |x: f64| vec![[0.0; 3], [x, 0.0, 0.0]];
        let poses = [pose(0.0), pose(0.01), pose(1.0), pose(0.5), pose(0.99)];
        assert_eq!(farthest_points(&poses, 3), vec![0, 2, 3]);
        assert_eq!(farthest_points(&poses, 9).len(), 5);
        assert!(farthest_points(&poses, 0).is_empty());
    }
}
