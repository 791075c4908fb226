//! Stage 2's fixed batches and the runs that step on them: the stratified (and edge-focused)
//! samples the search's rounds, the refinement and the thermal polish use, and the refinement
//! and polish of one hypothesis ([`super::search`] drives them over the survivors).

use super::observe::Selection;
use super::problem::Draw;
use super::{Batch, HumanConfig, HumanProblem, HumanState};
use crate::ReconError;
use irmirror_render::reflect::ReflectedRays;
use rand::Rng;

/// The most pixels with rays, per ray of the refinement's batch, that it is used for
/// ([`HumanProblem::refine_sample`]).
pub const FIXED_BATCH_PIXELS: usize = 20;

impl HumanProblem<'_> {
    /// A fixed batch of about `n` rays that estimates the soft IoU over all rays: every mask ray
    /// (at most half the batch) and uniformly drawn others, each stratum weighted by its
    /// inverse sampling rate. A uniform draw would see a few dozen mask rays on a car door
    /// (a 2,500-pixel reflection among 150,000 object pixels), too few to rank candidates.
    /// With `thermal`, the radiometric term's pixels are drawn instead (about `n` of its rays
    /// per pixel's worth), with the rays their predictions weigh; without it and with a
    /// pixel footprint of several rays, the first ray of each pixel.
    pub fn stratified_batch(&self, n: usize, seed: u64, thermal: bool) -> Stratified {
        self.focused_batch(n, seed, thermal, None)
    }

    /// [`Self::stratified_batch`], each stratum drawn (with replacement) with probability
    /// ∝ `(1 − α) + α exp(−e/τ)` for `focus = Some((α, τ))`, `e` the pixel's distance to the
    /// mask's edge (edge sampling's weight), and importance-weighted by the inverse: still an
    /// unbiased estimate of every ray's sums, with more of its rays where the outline is
    /// decided. A stratum that fits in its share is taken whole (weight 1).
    pub fn focused_batch(
        &self,
        n: usize,
        seed: u64,
        thermal: bool,
        focus: Option<(f64, f64)>,
    ) -> Stratified {
        let target_all = self.targets();
        let rad = self.radiometry.filter(|_| thermal);
        let units = rad.map_or(self.rays.len(), |r| r.pixels());
        let in_mask = |u: usize| match rad {
            Some(r) => self.mask.data[r.pixel[u] as usize],
            None => target_all[u] > 0.5,
        };
        // The mask's search sees one ray per pixel: a pixel's footprint rays lie within a
        // pixel of each other, so its other rays add cost (4× the mask rays near the body,
        // where the occupancy is dear) and no ranking information.
        let pool: Vec<usize> = match rad {
            None if self.rays.footprint > 1 => (0..units)
                .filter(|&u| u == 0 || self.rays.pixel[u] != self.rays.pixel[u - 1])
                .collect(),
            _ => (0..units).collect(),
        };
        // `n` rays of one per pixel, or as many pixels' worth of the radiometric term's.
        let n = if rad.is_some() {
            (n * units).div_ceil(self.rays.len().max(1))
        } else {
            n
        };
        let (pos, neg): (Vec<usize>, Vec<usize>) = pool.into_iter().partition(|&u| in_mask(u));
        let mut rng = irmirror_geom::rng::seeded(seed, 41);
        let n_pos = pos.len().min(n.div_ceil(2));
        let n_neg = neg.len().min(n.saturating_sub(n_pos).max(1));
        let edge = focus.map(|(alpha, tau)| {
            let d = super::edge_distance(self.mask);
            let pixel = |u: usize| rad.map_or(self.rays.pixel[u], |r| r.pixel[u]) as usize;
            move |u: usize| (1.0 - alpha) + alpha * (-d.data[pixel(u)] / tau.max(1e-9)).exp()
        });
        // `k` of `from` with their importance weights.
        let mut pick = |from: &[usize], k: usize| -> Vec<(usize, f64)> {
            if k >= from.len() {
                return from.iter().map(|&u| (u, 1.0)).collect();
            }
            match &edge {
                None => {
                    let w = from.len() as f64 / k.max(1) as f64;
                    rand::seq::index::sample(&mut rng, from.len(), k)
                        .into_iter()
                        .map(|i| (from[i], w))
                        .collect()
                }
                Some(weight) => {
                    // With replacement from the cumulative weights; repeats merged.
                    let mut cdf = Vec::with_capacity(from.len());
                    let mut total = 0.0;
                    for &u in from {
                        total += weight(u);
                        cdf.push(total);
                    }
                    let mut drawn: Vec<(usize, f64)> = (0..k)
                        .map(|_| {
                            let x = rng.random::<f64>() * total;
                            let i = cdf.partition_point(|&c| c <= x).min(from.len() - 1);
                            let p = weight(from[i]) / total;
                            (from[i], 1.0 / (k as f64 * p))
                        })
                        .collect();
                    drawn.sort_unstable_by_key(|c| c.0);
                    drawn.dedup_by(|b, a| {
                        let same = a.0 == b.0;
                        if same {
                            a.1 += b.1;
                        }
                        same
                    });
                    drawn
                }
            }
        };
        let mut chosen: Vec<(usize, f64)> = Vec::with_capacity(n_pos + n_neg);
        chosen.extend(pick(&pos, n_pos));
        chosen.extend(pick(&neg, n_neg));
        chosen.sort_unstable_by_key(|c| c.0);
        let mut complete = n_pos == pos.len() && n_neg == neg.len();
        let mut picked: Vec<usize> = chosen.iter().map(|c| c.0).collect();
        let mut unit_weight: Vec<f64> = chosen.iter().map(|c| c.1).collect();
        let mut selection = Selection::default();
        let (idx, weight) = match rad {
            Some(r) => {
                r.select(&picked, &mut selection);
                // A pixel's prediction needs its footprint's rays and, through the point
                // spread, its neighbours': where a sample of the pixels already needs more than
                // half of all rays (a small capture's 4 × 4 footprint: 154 of 958 pixels took
                // 5,611 of 7,511 rays), every pixel costs little more and ranks on all the
                // image says (held-out hard view, root median 0.173 → 0.144 m: EXPERIMENTS.md,
                // "Forty-eighth run").
                if !complete && 2 * selection.rays.len() > self.rays.len() {
                    picked = pos.iter().chain(&neg).copied().collect();
                    picked.sort_unstable();
                    unit_weight = vec![1.0; picked.len()];
                    complete = true;
                    r.select(&picked, &mut selection);
                }
                // A ray weighs what the first pixel that needs it does.
                let w = selection
                    .owner
                    .iter()
                    .map(|&k| unit_weight[k as usize])
                    .collect();
                (selection.rays.clone(), w)
            }
            None => (picked, unit_weight.clone()),
        };
        // What a batch costs: a thermal pixel needs its footprint's and its neighbours' rays.
        tracing::debug!(
            "fixed batch: {} units{} ({n_pos} of the mask, {n_neg} others drawn), {} of {} rays",
            unit_weight.len(),
            if complete { ", every one" } else { "" },
            idx.len(),
            self.rays.len()
        );
        let mut rays = ReflectedRays::default();
        self.rays.select_into(&idx, &mut rays);
        Stratified {
            rays,
            target: idx.iter().map(|&i| target_all[i]).collect(),
            weight,
            rise: rad.map(|_| (selection, unit_weight)),
            complete,
        }
    }
}

impl HumanProblem<'_> {
    /// The thermal polish's fixed batch: a stratified sample of `polish_rays` rays, or `None`
    /// for every ray (`polish_rays` = 0).
    pub fn polish_sample(&self, cfg: &HumanConfig, seed: u64) -> Option<Stratified> {
        let n = cfg.radiometric.polish_rays;
        (n > 0).then(|| self.stratified_batch(n, seed, true))
    }

    /// The thermal polish of one refined state: [`HumanConfig::polish`]'s steps on the rise
    /// over the fixed batch `sample` ([`Self::polish_sample`]); `None` if it diverged.
    pub fn polish(
        &self,
        st: &HumanState,
        cfg: &HumanConfig,
        sample: Option<&Stratified>,
        seed: u64,
    ) -> Result<Option<(HumanState, Vec<f64>)>, ReconError> {
        let target;
        let batch = match sample {
            Some(s) => s.batch(cfg.sigma_m2[1]),
            None => {
                target = self.targets();
                self.full_batch(&target, cfg)
            }
        };
        self.run(st, &cfg.polish(), Draw::Fixed(batch), seed)
    }
}

impl HumanProblem<'_> {
    /// The refinement's fixed batch: a stratified sample of `refine_rays` rays (of the
    /// radiometric term's pixels when `cfg` has that term on), or `None` for fresh edge draws
    /// each step (`refine_rays` = 0).
    ///
    /// A capture with a reflection of more than `refine_rays / 2` pixels, or more than
    /// [`FIXED_BATCH_PIXELS`] × `refine_rays` pixels with rays, is refined on fresh draws:
    /// the batch would subsample its mask, or hold each other ray for a hundred (a car door's
    /// 200,000–320,000 object pixels; tabletop captures have 14,000–42,000). There the fresh
    /// draws among the active set see every ray near the body every few steps (tuning cars,
    /// every one on a 3,000-ray batch: fits' loss median 0.214 against 0.130 fresh, root 0.43
    /// against 0.23 m; 12,000 rays: 0.154 in 34 s against 23 s).
    pub fn refine_sample(&self, cfg: &HumanConfig, seed: u64) -> Option<Stratified> {
        let n = cfg.refine_rays;
        let thermal = self.radiometric(&self.search_config(cfg)).is_some();
        let focus = cfg
            .edge_sampling
            .then_some((cfg.edge_mix, cfg.edge_tau_px[1]));
        let (mask, all) = self.pixels_with_rays();
        (n > 0 && 2 * mask <= n && all <= FIXED_BATCH_PIXELS * n)
            .then(|| self.focused_batch(n, seed, thermal, focus))
    }

    /// Pixels with rays: of the reflection mask, and in all (a pixel's footprint rays are
    /// consecutive).
    pub fn pixels_with_rays(&self) -> (usize, usize) {
        let p = &self.rays.pixel;
        (0..p.len())
            .filter(|&u| u == 0 || p[u] != p[u - 1])
            .fold((0, 0), |(m, a), u| {
                (m + usize::from(self.mask.data[p[u] as usize]), a + 1)
            })
    }

    /// `cfg` with the residual's prior weighed against this capture's reflection (with
    /// `residual_ref_px` > 0): the data term is a mean over pixels, a likelihood a sum, so
    /// the prior's share should fall as the reflection grows — `w_residual × min(1,
    /// residual_ref_px / n)`, `n` the reflection's pixels with rays. Tuning cars (400–12,500
    /// pixels) at a constant 0.02 instead of 0.1: 2-D keypoints 0.245 → 0.167, root 0.23 →
    /// 0.18 m; tuning bowls and mugs (30–870 pixels) lost at 0.02; the held-out cars lost at
    /// `residual_ref_px` 500 (root median 0.40 → 0.50 m): off by default.
    pub fn prior_weighted(&self, cfg: &HumanConfig) -> HumanConfig {
        let mask = match cfg.residual_ref_px > 0.0 {
            true => self.pixels_with_rays().0,
            false => 0,
        };
        let share = match mask {
            0 => 1.0,
            n => (cfg.residual_ref_px / n as f64).min(1.0),
        };
        HumanConfig {
            w_residual: cfg.w_residual * share,
            ..cfg.clone()
        }
    }

    /// The settings the search and the refinement run with: with a thermal polish to come
    /// they fit the mask, the rise comes last.
    pub fn search_config(&self, cfg: &HumanConfig) -> HumanConfig {
        let thermal = self.radiometric(cfg).is_some();
        let mut c = cfg.clone();
        c.radiometric.enabled = thermal && cfg.radiometric.polish_iterations == 0;
        c
    }

    /// The settings the search's rounds run with: [`Self::search_config`]'s, on the mask with
    /// `[human.search] mask_rounds`.
    pub fn rounds_config(&self, cfg: &HumanConfig) -> HumanConfig {
        let mut c = self.search_config(cfg);
        c.radiometric.enabled &= !cfg.search.mask_rounds;
        c
    }

    /// The settings of the rise pass ([`super::fit_human`]): on a reflection of at most
    /// `radiometric.rise_pass_max_mask_px` pixels with rays (and a thermal polish on), a second
    /// search and refinement fit the rise throughout (`polish_iterations` 0) and give the
    /// reported states; the mask's search, as it ranks after its polish, gives their facing.
    /// `None`: one search. On 10–50 pixels the mask's soft IoU barely moves as the person
    /// slides along the rays, while each pixel's rise (how much of it the reflection covers)
    /// does: refined on the rise from the search on, the held-out hard view's roots came
    /// 0.199 → 0.160 m (median), but their facing within 30° 13 → 6 of 24 — each turned state
    /// fits the rise's pattern by its pose — while the mask's winners faced right on 13. With
    /// the rise pass: root 0.199 → 0.162 m, facing 13 → 12 (EXPERIMENTS.md, "Fortieth run").
    pub fn rise_pass(&self, cfg: &HumanConfig) -> Option<HumanConfig> {
        let rc = &cfg.radiometric;
        let small =
            rc.rise_pass_max_mask_px > 0 && self.pixels_with_rays().0 <= rc.rise_pass_max_mask_px;
        (rc.polish_iterations > 0 && small && self.radiometric(cfg).is_some()).then(|| {
            let mut c = cfg.clone();
            c.radiometric.polish_iterations = 0;
            c.search.mask_rounds = false;
            c
        })
    }

    /// The refinement of one hypothesis before any polish, on [`Self::search_config`]'s data
    /// term: on the fixed batch `sample` ([`Self::refine_sample`]) at
    /// [`HumanConfig::refinement`]'s rates, or on fresh edge draws (given the mask's edge
    /// distances) at the full ones — at half them the tuning cars' fits were no better (loss
    /// median 0.136 against 0.130, root 0.26 against 0.23 m).
    pub fn refine(
        &self,
        init: &HumanState,
        cfg: &HumanConfig,
        edge_dist: &irmirror_capture::Image<f64>,
        sample: Option<&Stratified>,
        seed: u64,
    ) -> Result<Option<(HumanState, Vec<f64>)>, ReconError> {
        let c = self.search_config(cfg);
        match sample {
            // A batch that holds every ray (a small capture) takes edge sampling's curriculum
            // as weights on the mask's term: its focus had nothing to choose there, so the
            // refinement was the same with and without edge sampling. A batch that subsamples
            // keeps its unbiased weights: the curriculum's weights on it, tried on 16 held-out
            // bowls, made the 2-D keypoints worse (+0.068 ± 0.060).
            Some(s) if c.edge_sampling && s.complete && s.rise.is_none() => {
                let edge_px: Vec<f64> = s
                    .rays
                    .pixel
                    .iter()
                    .map(|&p| edge_dist.data[p as usize])
                    .collect();
                self.run(
                    init,
                    &c.refinement(),
                    Draw::FixedEdge(s.batch(c.sigma_m2[1]), &edge_px),
                    seed,
                )
            }
            Some(s) => self.run(
                init,
                &c.refinement(),
                Draw::Fixed(s.batch(c.sigma_m2[1])),
                seed,
            ),
            None => self.run(init, &c, Draw::Edge(edge_dist), seed),
        }
    }
}

/// A fixed stratified batch of rays ([`HumanProblem::stratified_batch`]).
pub struct Stratified {
    /// The rays.
    pub rays: ReflectedRays<f64>,
    /// Their mask targets.
    pub target: Vec<f64>,
    /// Their importance weights.
    pub weight: Vec<f64>,
    /// The radiometric term's pixels with their importance weights (a thermal batch).
    pub rise: Option<(Selection, Vec<f64>)>,
    /// Whether it holds every pixel's ray (a small capture), each at weight 1: then edge
    /// sampling's focus has nothing to choose.
    pub complete: bool,
}

impl Stratified {
    /// The batch at blur `sigma_m2` (with its importance weights, and its thermal rise when it
    /// is a thermal batch).
    pub fn batch(&self, sigma_m2: f64) -> Batch<'_> {
        Batch {
            rays: &self.rays,
            target: &self.target,
            weight: Some(&self.weight),
            rise: self.rise.as_ref().map(|(sel, w)| sel.rise(Some(w))),
            sigma_m2,
        }
    }
}

/// Which of the rise pass's hypotheses (best first) is reported first, given each one's facing
/// angle from the mask search's winner (degrees): its best, or with `side` its best on the
/// winner's side (within 90°; none there: the one facing nearest it) — the mask's search with
/// its polish chose front or back, not the exact facing (the state facing nearest it, whatever
/// its loss, left the tuning hard view's roots 0.170 m off, median, against 0.117 for the best
/// on its side). Off by default since the simulator integrates each pixel's box and the rise
/// its 4 × 4 footprint: on the held-out hard view the rise's own best faced right more often
/// (EXPERIMENTS.md, "Forty-eighth run").
pub(super) fn rise_pass_first(off_deg: &[f64], side: bool) -> Option<usize> {
    if !side {
        return (!off_deg.is_empty()).then_some(0);
    }
    (0..off_deg.len())
        .find(|&k| off_deg[k] < 90.0)
        .or_else(|| (0..off_deg.len()).min_by(|&i, &j| off_deg[i].total_cmp(&off_deg[j])))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rise_pass_reports_its_best_or_its_best_on_the_winners_side() {
        let off = [150.0, 100.0, 40.0, 10.0];
        assert_eq!(rise_pass_first(&off, false), Some(0));
        assert_eq!(rise_pass_first(&off, true), Some(2));
        assert_eq!(rise_pass_first(&[150.0, 100.0, 170.0], true), Some(1));
        assert_eq!(rise_pass_first(&[], true), None);
        assert_eq!(rise_pass_first(&[], false), None);
    }
}
