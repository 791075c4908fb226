//! The limb search: a survivor's pose changed one body part at a time.
//!
//! Placed at the true root and facing, refinements from the search's templates ended at
//! 0.30–0.33 data term on held-out bowls where the prior's encoding of the true pose reached
//! 0.18 (EXPERIMENTS.md, "Sixteenth run"), and the pose bank ([`super::bank`]) tries whole poses: a
//! person's legs, arms and head seldom match one training pose together. So each survivor's pose is
//! changed part by part — left leg, right leg, torso, left arm, right arm, head — each tried in
//! `limb_options` configurations spread (farthest-point sampling, that part's joints alone) over
//! the same source poses as the bank's, the rest kept; a change is kept when it lowers the score
//! (one forward pass per try, the feet moved to the floor when it is known), sweep after sweep
//! (coordinate descent on a discrete set). The pose tried is encoded by the prior, as every pose
//! the search states. The result then takes the last round's steps and replaces the survivor when
//! its loss is lower; or, as a polish of refined hypotheses, the full refinement. Placed at the
//! true root and facing it reaches near the prior's encoding of the true pose; in the pipeline it
//! lowers the loss of whichever facing it is handed and recovered no more people, so both uses are
//! off by default (EXPERIMENTS.md, "Seventeenth run").

use super::bank::farthest_points;
use super::{HumanConfig, HumanProblem, HumanState};
use crate::ReconError;
use rayon::prelude::*;

/// The body parts, each named by the bone its chain starts at; joints not below any of them
/// (the spine) form the torso.
const PART_ROOTS: [&str; 5] = ["pelvis.L", "pelvis.R", "clavicle.L", "clavicle.R", "neck01"];

/// Joint indices of each body part (root joint excluded): the five chains of [`PART_ROOTS`] and
/// the torso, legs first (they move the most of the outline).
pub(super) fn body_parts(names: &[String], parents: &[i32]) -> Vec<Vec<usize>> {
    let mut parts: Vec<Vec<usize>> = vec![Vec::new(); PART_ROOTS.len() + 1];
    for j in 1..names.len() {
        let mut k = j as i32;
        let mut part = PART_ROOTS.len();
        while k > 0 {
            if let Some(p) = PART_ROOTS.iter().position(|r| *r == names[k as usize]) {
                part = p;
                break;
            }
            k = parents[k as usize];
        }
        parts[part].push(j);
    }
    // Order: legs, torso, arms, head.
    let order = [0, 1, 5, 2, 3, 4];
    order
        .iter()
        .map(|&i| std::mem::take(&mut parts[i]))
        .filter(|p| !p.is_empty())
        .collect()
}

/// A polished state and its refinement's loss curve.
pub type Polished = (HumanState, Vec<f64>);

/// One body part's configurations to try: its joints and their rotation vectors per option.
pub(super) struct PartOptions {
    joints: Vec<usize>,
    options: Vec<Vec<[f64; 3]>>,
    /// A leg: it moves the body's lowest point, so the root is moved with it to keep the feet
    /// on the floor (the other parts leave the root's height above the feet as it is).
    moves_feet: bool,
}

impl HumanProblem<'_> {
    /// The pose `st` states (rotation vectors, root zero): the latent's decoding with the
    /// residual folded in.
    pub(super) fn folded_pose(&self, st: &HumanState) -> Result<Vec<[f64; 3]>, ReconError> {
        use irmirror_geom::rotation::matrix_to_axis_angle;
        let rotations = super::joint_rotations(self.prior, st)?;
        Ok(std::iter::once([0.0; 3])
            .chain(
                rotations[1..]
                    .iter()
                    .map(|m| matrix_to_axis_angle(m).into()),
            )
            .collect())
    }

    /// `n` configurations of each body part, spread over the source poses.
    pub(super) fn part_options(&self, n: usize) -> Result<Vec<PartOptions>, ReconError> {
        let poses = self.source_poses()?;
        let asset = &self.model.asset;
        Ok(body_parts(&asset.meta.bone_names, &asset.parents)
            .into_iter()
            .map(|joints| {
                // A dummy root first: the distance skips index 0.
                let sub: Vec<Vec<[f64; 3]>> = poses
                    .iter()
                    .map(|p| {
                        std::iter::once([0.0; 3])
                            .chain(joints.iter().map(|&j| p[j]))
                            .collect()
                    })
                    .collect();
                let options = farthest_points(&sub, n)
                    .into_iter()
                    .map(|i| sub[i][1..].to_vec())
                    .collect();
                let moves_feet = joints
                    .iter()
                    .any(|&j| asset.meta.bone_names[j].starts_with("foot"));
                PartOptions {
                    joints,
                    options,
                    moves_feet,
                }
            })
            .collect())
    }

    /// Coordinate descent over body parts from `st` (module docs): the best state found (no
    /// residual), its score, and whether any part changed. `cfg` as the search runs; `batch`
    /// the rounds' fixed batch.
    pub(super) fn limb_search(
        &self,
        st: &HumanState,
        parts: &[PartOptions],
        sweeps: usize,
        batch: &super::Batch<'_>,
        cfg: &HumanConfig,
    ) -> Result<(f64, HumanState, bool), ReconError> {
        // The tries have no residual, so neither has the state they are measured against.
        let mut pose = self.folded_pose(st)?;
        let start = if st.residual.is_empty() {
            st.clone()
        } else {
            HumanState {
                latent: self.prior.encode(&pose)?,
                residual: Vec::new(),
                ..st.clone()
            }
        };
        let shaped = super::shaped_body(self.model, &st.build, st.height)?;
        let mut ws = self.scratch()?;
        let mut best = (self.score(&mut ws, &start, batch, cfg)?.0, start);
        let mut changed = false;
        for _ in 0..sweeps {
            let mut moved = false;
            for part in parts {
                let tries: Vec<Vec<[f64; 3]>> = part
                    .options
                    .iter()
                    .map(|o| {
                        let mut p = pose.clone();
                        for (&j, r) in part.joints.iter().zip(o) {
                            p[j] = *r;
                        }
                        p
                    })
                    .collect();
                let states = tries
                    .par_iter()
                    .map(|p| {
                        if part.moves_feet {
                            Ok(self.in_mode(&best.1, &self.pose_mode(p, &shaped)?))
                        } else {
                            Ok(HumanState {
                                latent: self.prior.encode(p)?,
                                residual: Vec::new(),
                                ..best.1.clone()
                            })
                        }
                    })
                    .collect::<Result<Vec<_>, ReconError>>()?;
                let scored = self.score_states(states, batch, cfg)?;
                if let Some((i, (loss, state))) = scored
                    .into_iter()
                    .enumerate()
                    .filter(|(_, (l, _))| l.is_finite())
                    .min_by(|a, b| a.1.0.total_cmp(&b.1.0))
                    && (loss < best.0 || !best.0.is_finite())
                {
                    best = (loss, state);
                    pose = tries[i].clone();
                    moved = true;
                }
            }
            changed |= moved;
            if !moved {
                break;
            }
        }
        Ok((best.0, best.1, changed))
    }

    /// Each of the best `limb_survivors` survivors searched part by part (module docs), then
    /// stepped as the last round steps; replaced when that ends lower. `cfg` as the search
    /// runs ([`Self::search_config`]).
    pub fn limb_swap(
        &self,
        survivors: Vec<HumanState>,
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let s = &cfg.search;
        if s.limb_survivors == 0
            || s.limb_options == 0
            || s.limb_sweeps == 0
            || survivors.is_empty()
        {
            return Ok(survivors);
        }
        let t0 = std::time::Instant::now();
        let parts = self.part_options(s.limb_options)?;
        let thermal = self.radiometric(cfg).is_some();
        let sample = self.stratified_batch(s.score_rays, seed, thermal);
        let batch = sample.batch(s.round_sigma_m2[1]);
        let n_tried = s.limb_survivors.min(survivors.len());
        let steps_cfg = super::bank::last_round(cfg);
        let mut out = survivors;
        let mut swapped = 0;
        for (i, st) in out.iter_mut().take(n_tried).enumerate() {
            let mut ws = self.scratch()?;
            let own = self.score(&mut ws, st, &batch, cfg)?.0;
            let (_, found, _) = self.limb_search(st, &parts, s.limb_sweeps, &batch, cfg)?;
            let run_seed = seed.wrapping_mul(7919).wrapping_add(60_000 + i as u64);
            let Some((end, _)) =
                self.run(&found, &steps_cfg, super::Draw::Fixed(batch), run_seed)?
            else {
                continue;
            };
            let (loss, _) = self.score(&mut ws, &end, &batch, cfg)?;
            if loss.is_finite() && (loss < own || !own.is_finite()) {
                *st = end;
                swapped += 1;
            }
        }
        tracing::debug!(
            "limb search: {} parts × {} options × {n_tried} survivors, {swapped} swapped, {:.2} s",
            parts.len(),
            s.limb_options,
            t0.elapsed().as_secs_f64()
        );
        Ok(out)
    }

    /// The limb polish: each of `states` (refined hypotheses) searched part by part at its
    /// refined root and facing, then refined again as [`Self::refine`] does; per state, the
    /// new one and its loss curve when its full loss ([`Self::full_eval`]) is lower, else
    /// `None`. `cfg` as the refinement runs (the limb search runs on the search's settings).
    pub fn limb_polish(
        &self,
        states: &[HumanState],
        cfg: &HumanConfig,
        edge_dist: &irmirror_capture::Image<f64>,
        sample: Option<&super::Stratified>,
        seed: u64,
    ) -> Result<Vec<Option<Polished>>, ReconError> {
        let scfg = self.search_config(cfg);
        let s = &scfg.search;
        let parts = self.part_options(s.limb_options.max(1))?;
        let thermal = self.radiometric(&scfg).is_some();
        let round = self.stratified_batch(s.score_rays, seed, thermal);
        let batch = round.batch(s.round_sigma_m2[1]);
        states
            .iter()
            .enumerate()
            .map(|(k, st)| {
                let own = self.full_eval(st, cfg)?.loss;
                let (_, found, changed) =
                    self.limb_search(st, &parts, s.limb_sweeps.max(1), &batch, &scfg)?;
                if !changed {
                    return Ok(None);
                }
                let run_seed = seed.wrapping_mul(7919).wrapping_add(70_000 + k as u64);
                let Some((end, curve)) = self.refine(&found, cfg, edge_dist, sample, run_seed)?
                else {
                    return Ok(None);
                };
                let loss = self.full_eval(&end, cfg)?.loss;
                tracing::debug!("limb polish {k}: full loss {own:.4} → {loss:.4}");
                Ok((loss < own).then_some((end, curve)))
            })
            .collect()
    }

    /// A body mesh's outline twin as the mirror sees it: each vertex kept on its line of sight
    /// from the reflection's viewpoint (the mean origin of the mask's rays: where on the objects
    /// the person is seen) and moved to the other side of the vertical plane through `root`
    /// across that line (distance `s` along its line → `2 s₀ − s`, `s₀` the plane's). The
    /// outline from the viewpoint stays; front and back change places, the face with the back
    /// of the head and a forearm in front of the torso with one behind it — what a body facing
    /// the other way shows the mirror, in everything but the thermal values and occlusion. Not
    /// a body of the model (the depth flip is not rigid): it asks the data term which way the
    /// given mesh faces at its own pose.
    pub fn outline_twin_mesh(
        &self,
        vertices: &[nalgebra::Vector3<f64>],
        root: &nalgebra::Vector3<f64>,
    ) -> Vec<nalgebra::Vector3<f64>> {
        use nalgebra::Vector3;
        let (mut sum, mut n) = (Vector3::zeros(), 0usize);
        for (i, o) in self.rays.origin.iter().enumerate() {
            if self.mask.data.get(self.rays.pixel[i] as usize) == Some(&true) {
                sum += o;
                n += 1;
            }
        }
        let c = if n > 0 {
            sum / n as f64
        } else {
            self.objects_centre
        };
        let up = self.up.normalize();
        let mut line = root - c;
        line -= up * up.dot(&line);
        let Some(d) = line.try_normalize(1e-9) else {
            return vertices.to_vec();
        };
        let plane = (root - c).dot(&d);
        vertices
            .iter()
            .map(|p| {
                let v = p - c;
                let s = v.norm();
                let along = v.dot(&d);
                if s < 1e-9 || along < 1e-3 * s {
                    return *p;
                }
                let u = v / s;
                let s0 = plane * s / along;
                c + u * (2.0 * s0 - s)
            })
            .collect()
    }

    /// The silhouette twin of `st`: its body reflected through the root in the vertical plane
    /// across the objects→person line — the pose mirrored left/right (re-encoded by the prior;
    /// the residual folded in, then dropped) and the root turned by twice the angle between
    /// that line and the body's left–right axis (180° for a person facing the objects). Seen
    /// orthographically along that line the two cast the same outline; a convex mirror 1 m
    /// away is a wide perspective, though, and the data term sharp (tabletop seed 1: twin
    /// 0.318, truth 0.065, the truth moved 2 cm: 0.211), so the twin is the turned pose's
    /// start, not its equal. The front/back partner [`super::flipped`] turns the root alone,
    /// which keeps the arms and legs on the survivor's sides.
    pub fn twin(&self, st: &HumanState) -> Result<HumanState, ReconError> {
        use nalgebra::{Matrix3, Vector3};
        let up = self.up.normalize();
        let mut line = st.translation - self.objects_centre;
        line -= up * up.dot(&line);
        let Some(d) = line.try_normalize(1e-9) else {
            return Ok(HumanState {
                rotation: super::flipped(&up, &st.rotation),
                ..st.clone()
            });
        };
        let mirrored = irmirror_body::prior::generator::PoseGenerator::new(self.model)
            .mirrored(&self.folded_pose(st)?);
        // The reflection across the plane with normal d, after the body's own left–right one
        // (Anny's X): a proper rotation.
        let reflect = Matrix3::identity() - 2.0 * d * d.transpose();
        let lateral = Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0));
        Ok(HumanState {
            rotation: reflect * st.rotation * lateral,
            latent: self.prior.encode(&mirrored)?,
            residual: Vec::new(),
            ..st.clone()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every body joint but the root lies in exactly one part; each chain holds its bones.
    #[test]
    fn the_parts_cover_the_skeleton_once() {
        let a = irmirror_body::BodyAsset::builtin().expect("body");
        let parts = body_parts(&a.meta.bone_names, &a.parents);
        assert_eq!(parts.len(), 6);
        let mut all: Vec<usize> = parts.concat();
        all.sort_unstable();
        assert_eq!(all, (1..a.parents.len()).collect::<Vec<_>>());
        let name = |j: usize| a.meta.bone_names[j].as_str();
        assert!(parts[0].iter().all(|&j| name(j).ends_with(".L")));
        assert!(parts[0].iter().any(|&j| name(j) == "foot.L"));
        assert!(parts[1].iter().any(|&j| name(j) == "foot.R"));
        assert!(parts[2].iter().all(|&j| name(j).starts_with("spine")));
        assert!(parts[3].iter().any(|&j| name(j) == "wrist.L"));
        assert!(parts[4].iter().any(|&j| name(j) == "wrist.R"));
        assert!(parts[5].iter().any(|&j| name(j) == "head"));
    }
}
