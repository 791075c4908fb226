//! Which way a person faces, from the thermal values in the reflection's virtual view.
//!
//! A binary silhouette barely tells a person facing the mirror from one facing away: the body
//! reflected front to back through its root (its silhouette twin) casts the same outline.
//! The thermal image does not: a face is warmer than the hair on the back of a head, and a
//! bare forearm in front of the torso shows where one behind it is hidden. The data term
//! holds that cue, but only where the pose is nearly right: a fit's misplaced head and arms
//! drown it (EXPERIMENTS.md, "Twenty-fourth run"). So the facing is judged as the retrieval
//! ([`super::retrieve`]) judges a pose — in the virtual view, with a tolerance: at a state's
//! root and facing, and at its twin's, the source poses whose outlines fit best are drawn with
//! their body regions (the nearest surface along the view's axis in each 2 cm cell), each
//! region at its temperature prior's centre, blurred over 3 × 3 cells; each mask ray's
//! observed rise is compared with the drawn contrast at its cell (at the outline's best shift)
//! by the residual of the best gain, over the observed rise's energy. The lower of the two
//! facings' best residuals wins.
//!
//! Where it acts ([`HumanProblem::judge_acts`]): everywhere with `[human.retrieval] facing`;
//! by default only where the reflection shows no head. Where a face or the back of a head shows,
//! the data term tells front from back itself (the truth beats its outline twin on 41 of 45
//! such held-out bowls) and the judge's turns gained nothing on bowls and cost the hard view and
//! the cars; where the mirror sees a band of clothing (a mug), the data term cannot (5 of 20)
//! and the judge turned the mugs' facing right more often on both the tuning and the held-out
//! set (EXPERIMENTS.md, "Thirty-third run").

use super::bank::PoseMode;
use super::radiometric::Radiometry;
use super::retrieve::{RetrievalConfig, View, side};
use super::{HumanConfig, HumanProblem, HumanState, Hypothesis};
use crate::ReconError;
use irmirror_body::Region;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::collections::HashMap;

impl HumanProblem<'_> {
    /// The thermal residual of body `vertices` in `views` (module docs): `Σ (o − a p)² / Σ o²`
    /// over the mask rays of every view, `a ≥ 0` fitted per view.
    fn thermal_residual(
        &self,
        vertices: &[Vector3<f64>],
        views: &[View],
        cfg: &RetrievalConfig,
        (rad, observed): (&Radiometry, &HashMap<u32, f64>),
    ) -> f64 {
        let n = side(cfg);
        let centroid: Vec<Vector3<f64>> = self
            .model
            .asset
            .faces
            .iter()
            .map(|f| {
                f.iter()
                    .map(|&i| vertices[i as usize])
                    .sum::<Vector3<f64>>()
                    / 3.0
            })
            .collect();
        let (mut res, mut energy) = (0.0, 0.0);
        for view in views {
            let (_, (du, dv)) = self.view_score(vertices, view, cfg);
            // The nearest triangle per cell, seen from the view's centre.
            let mut near = vec![(f64::INFINITY, usize::MAX); n * n];
            let dist: Vec<f64> = centroid
                .iter()
                .map(|c| (c - view.centre).dot(&view.axis))
                .collect();
            self.cover(vertices, view, cfg, |t, cell| {
                if dist[t] < near[cell].0 {
                    near[cell] = (dist[t], t);
                }
            });
            let drawn: Vec<f64> = near
                .iter()
                .map(|&(_, t)| {
                    if t == usize::MAX {
                        0.0
                    } else {
                        rad.contrast_at[rad.triangle_region[t].index()][0]
                    }
                })
                .collect();
            let at = |x: i32, y: i32| {
                let mut s = 0.0;
                for (ox, oy) in (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))) {
                    let (cx, cy) = (x + ox, y + oy);
                    if cx >= 0 && cy >= 0 && (cx as usize) < n && (cy as usize) < n {
                        s += drawn[cy as usize * n + cx as usize];
                    }
                }
                s / 9.0
            };
            let (op, pp, oo) = view
                .mask
                .iter()
                .zip(&view.mask_ray)
                .filter_map(|(&(x, y), &i)| {
                    let o = *observed.get(&self.rays.pixel[i])?;
                    Some((o, at(x + du, y + dv)))
                })
                .fold((0.0, 0.0, 0.0), |(a, b, c), (o, p)| {
                    (a + o * p, b + p * p, c + o * o)
                });
            let gain = if pp > 0.0 { (op / pp).max(0.0) } else { 0.0 };
            res += oo - 2.0 * gain * op + gain * gain * pp;
            energy += oo;
        }
        if energy > 0.0 {
            res / energy
        } else {
            f64::INFINITY
        }
    }

    /// [`Self::thermal_residual`] of any body `vertices` in the views through `root` (`None`:
    /// no radiometric observations, or no view sees the mask).
    pub fn thermal_residual_at(
        &self,
        root: &Vector3<f64>,
        vertices: &[Vector3<f64>],
        cfg: &RetrievalConfig,
    ) -> Option<f64> {
        let rad = self.radiometry?;
        let observed = observed_rise(rad);
        let views = self.views(root, cfg);
        (!views.is_empty()).then(|| self.thermal_residual(vertices, &views, cfg, (rad, &observed)))
    }

    /// The thermal judge of `st`'s facing (module docs): the best thermal residual among the
    /// `top` source poses whose outlines fit best at `st`'s root and facing, and the same at
    /// its silhouette twin's ([`Self::twin`]). `None` without the radiometric observations or
    /// a view that sees the mask.
    pub fn thermal_facing(
        &self,
        st: &HumanState,
        cfg: &RetrievalConfig,
        top: usize,
    ) -> Result<Option<[f64; 2]>, ReconError> {
        self.thermal_facing_in(st, &self.pose_bank(cfg.judge_bank(), st.height)?, cfg, top)
    }

    /// [`Self::thermal_facing`] among the poses of `bank` (the source poses at `st`'s height:
    /// a caller judging many states makes it once).
    fn thermal_facing_in(
        &self,
        st: &HumanState,
        bank: &[PoseMode],
        cfg: &RetrievalConfig,
        top: usize,
    ) -> Result<Option<[f64; 2]>, ReconError> {
        let Some(rad) = self.radiometry else {
            return Ok(None);
        };
        let observed = observed_rise(rad);
        let views = self.views(&st.translation, cfg);
        if views.is_empty() {
            return Ok(None);
        }
        let shaped = super::shaped_body(self.model, &st.build, st.height)?;
        let mut out = [f64::INFINITY; 2];
        for (k, s) in [st.clone(), self.twin(st)?].iter().enumerate() {
            // Each candidate on its own worker (the minimum does not depend on their order).
            let residuals = self
                .candidates_in(s, bank, cfg, top)?
                .par_iter()
                .map(|(cand, _)| {
                    let body = self.posed_with(&shaped, cand)?;
                    Ok(self.thermal_residual(&body.vertices, &views, cfg, (rad, &observed)))
                })
                .collect::<Result<Vec<f64>, ReconError>>()?;
            out[k] = residuals.into_iter().fold(out[k], f64::min);
        }
        Ok(Some(out))
    }
}

/// The source poses at each height judged so far (a caller judging many states makes each
/// height's once, and the poses' latents and rotations once for all heights).
#[derive(Default)]
struct Banks(Vec<(f64, Vec<PoseMode>)>);

impl Banks {
    fn at(
        &mut self,
        problem: &HumanProblem<'_>,
        height: f64,
        size: usize,
    ) -> Result<&[PoseMode], ReconError> {
        let i = match self.0.iter().position(|(h, _)| *h == height) {
            Some(i) => i,
            None => {
                let bank = match self.0.first() {
                    Some((_, first)) => problem.bank_at(first, height)?,
                    None => problem.pose_bank(size, height)?,
                };
                self.0.push((height, bank));
                self.0.len() - 1
            }
        };
        Ok(&self.0[i].1)
    }
}

/// The observed rise by pixel.
fn observed_rise(rad: &Radiometry) -> HashMap<u32, f64> {
    rad.pixel
        .iter()
        .copied()
        .zip(rad.rise_k.iter().copied())
        .collect()
}

impl HumanProblem<'_> {
    /// Whether the thermal judge acts on a fit whose states (survivors or refined hypotheses)
    /// are `states` (module docs): always with `[human.retrieval] facing` on; otherwise where
    /// none of them shows a head — face and hair under `facing_head_share` of the rise the
    /// radiometric model predicts for each ([`Self::head_share`]).
    fn judge_acts<'s>(
        &self,
        mut states: impl Iterator<Item = &'s HumanState>,
        cfg: &HumanConfig,
    ) -> Result<bool, ReconError> {
        let r = &cfg.retrieval;
        if r.facing {
            return Ok(true);
        }
        if r.facing_head_share <= 0.0 || self.radiometry.is_none() {
            return Ok(false);
        }
        states.try_fold(true, |acts, st| {
            Ok(acts
                && self
                    .head_share(st, cfg)?
                    .is_none_or(|share| share < r.facing_head_share))
        })
    }

    /// The share of the rise the radiometric model predicts for `st` that its face and hair
    /// make (`None`: no radiometric observations, or no predicted rise).
    pub fn head_share(
        &self,
        st: &HumanState,
        cfg: &HumanConfig,
    ) -> Result<Option<f64>, ReconError> {
        let mut c = cfg.clone();
        c.radiometric.enabled = true;
        let body = super::posed_body(self.model, self.prior, st)?;
        Ok(self.region_rise(&body.vertices, &c).and_then(|r| {
            let all: f64 = r.iter().sum();
            let head = r[Region::Face.index()] + r[Region::Hair.index()];
            (all > 0.0).then(|| head / all)
        }))
    }

    /// Where the judge acts ([`Self::judge_acts`] on the survivors): each survivor turned
    /// to its silhouette twin when the thermal judge prefers the twin's facing (the pose is
    /// left to the refinement or the retrieval). A problem without radiometric observations
    /// (the paper's mask mode, `--ablate radiometric`) has no judge: nothing is turned.
    pub(super) fn facing_swap(
        &self,
        survivors: Vec<HumanState>,
        cfg: &HumanConfig,
    ) -> Result<Vec<HumanState>, ReconError> {
        if !(cfg.retrieval.facing_survivors && self.judge_acts(survivors.iter(), cfg)?) {
            return Ok(survivors);
        }
        let t0 = std::time::Instant::now();
        let mut banks = Banks::default();
        let out = survivors
            .into_iter()
            .map(|st| {
                if self.judge_turns(&st, &mut banks, &cfg.retrieval)? == Some(true) {
                    tracing::debug!("facing judge: survivor turned");
                    self.twin(&st)
                } else {
                    Ok(st)
                }
            })
            .collect::<Result<_, ReconError>>()?;
        tracing::debug!("facing judge: {:.2} s", t0.elapsed().as_secs_f64());
        Ok(out)
    }

    /// Where the judge acts ([`Self::judge_acts`] on the hypotheses): the first of the
    /// hypotheses (sorted by loss) the thermal judge keeps is moved to the front
    /// ([`Self::facing_first`]); the order stays when it turns every one judged.
    pub(super) fn facing_rank(
        &self,
        scored: &mut Vec<(Hypothesis, HumanState)>,
        cfg: &HumanConfig,
    ) -> Result<(), ReconError> {
        if !self.judge_acts(scored.iter().map(|(_, st)| st), cfg)? {
            return Ok(());
        }
        let states: Vec<&HumanState> = scored.iter().map(|(_, st)| st).collect();
        if let Some(i) = self.facing_first(&states, &cfg.retrieval)?
            && i > 0
        {
            tracing::debug!("facing judge: hypothesis {i} ranked first");
            let h = scored.remove(i);
            scored.insert(0, h);
        }
        Ok(())
    }

    /// The first of `states` (best first) the thermal judge does not turn to its twin, among
    /// the first `facing_rank_max` (0: all); `None` where it turns every one judged or there is
    /// no judge (no radiometric observations, no view of the mask).
    pub fn facing_first(
        &self,
        states: &[&HumanState],
        cfg: &RetrievalConfig,
    ) -> Result<Option<usize>, ReconError> {
        let mut banks = Banks::default();
        let judged = match cfg.facing_rank_max {
            0 => states.len(),
            k => k.min(states.len()),
        };
        for (i, st) in states.iter().take(judged).enumerate() {
            match self.judge_turns(st, &mut banks, cfg)? {
                Some(true) => continue,
                Some(false) => return Ok(Some(i)),
                None => return Ok(None),
            }
        }
        Ok(None)
    }

    /// Whether the thermal judge turns `st` to its twin (`None`: no judge — no radiometric
    /// observations or no view of the mask). It abstains (keeps `st`) where the twin faces
    /// less than `facing_min_turn_deg` away from `st`: a person seen side-on along the
    /// objects→person line has a twin facing nearly the same way, and front and back are not
    /// what the two differ in.
    fn judge_turns(
        &self,
        st: &HumanState,
        banks: &mut Banks,
        cfg: &RetrievalConfig,
    ) -> Result<Option<bool>, ReconError> {
        if cfg.facing_min_turn_deg > 0.0 {
            let up = self.up.normalize();
            let facing = |s: &HumanState| {
                let f = -(s.rotation * Vector3::y());
                (f - up * up.dot(&f)).try_normalize(1e-9)
            };
            if let (Some(a), Some(b)) = (facing(st), facing(&self.twin(st)?))
                && a.dot(&b).clamp(-1.0, 1.0).acos().to_degrees() < cfg.facing_min_turn_deg
            {
                return Ok(Some(false));
            }
        }
        let bank = banks.at(self, st.height, cfg.judge_bank())?;
        Ok(self
            .thermal_facing_in(st, bank, cfg, cfg.facing_top)?
            .map(|[own, twin]| twin < own))
    }
}
