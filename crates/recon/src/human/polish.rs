//! Polishes of the refined hypotheses: the best few by the full loss each given another
//! chance — a different pose part by part ([`HumanProblem::limb_polish`]), a different yaw
//! ([`HumanProblem::yaw_polish`]) or a different distance ([`HumanProblem::place_polish`]) —
//! and replaced only when the new end's full loss is lower.
//!
//! Why a yaw polish: the search places the body in eight yaw bins and the refinement settles
//! a facing to within tens of degrees; with the thermal judge's front/back choice, held-out
//! bowls still ended 30–50° off on about one in five (EXPERIMENTS.md, "Twenty-fourth run"), which
//! the refinement alone does not leave (its basin is narrower than that).
//!
//! Why a place polish: the search's distances are log-spaced 22 % apart and a mirror image
//! barely changes as the person slides along its rays (a taller person farther away looks the
//! same), so the refinement keeps the distance it starts at; on cars, placed at the true root
//! the search's "stand" pose ended at a lower data term than the fits (EXPERIMENTS.md, "Fourteenth
//! run"), whose roots lie along the objects→person line.

use super::limbs::Polished;
use super::problem::FullEval;
use super::search::Refined;
use super::{HumanConfig, HumanProblem, HumanState, Stratified};
use crate::ReconError;
use irmirror_capture::Image;
use nalgebra::{Rotation3, Unit, Vector3};
use rayon::prelude::*;

/// The best `n` refined hypotheses by the full loss, handed to `polish`; each replaced by its
/// polished end where there is one (its loss curve extended, its evaluation dropped).
fn polish_best(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    (n, name): (usize, &str),
    refined: &mut [Option<Refined>],
    polish: impl FnOnce(&[HumanState]) -> Result<Vec<Option<Polished>>, ReconError>,
) -> Result<(), ReconError> {
    let t0 = std::time::Instant::now();
    // The evaluations stay with the hypotheses not polished (the thermal polish and the final
    // scoring read them).
    let evals: Vec<(usize, FullEval)> = refined
        .par_iter()
        .enumerate()
        .filter_map(|(i, r)| r.as_ref().map(|r| (i, r)))
        .map(|(i, r)| Ok((i, r.evaluated(problem, cfg)?)))
        .collect::<Result<_, ReconError>>()?;
    let mut order: Vec<(usize, f64)> = evals.iter().map(|(i, e)| (*i, e.loss)).collect();
    for (i, e) in evals {
        if let Some(r) = refined[i].as_mut() {
            r.eval = Some(e);
        }
    }
    order.sort_by(|a, b| a.1.total_cmp(&b.1));
    order.truncate(n);
    let states: Vec<HumanState> = order
        .iter()
        .map(|&(i, _)| refined[i].as_ref().expect("live").state.clone())
        .collect();
    let better = polish(&states)?;
    for ((i, _), b) in order.into_iter().zip(better) {
        if let (Some(r), Some((state, curve))) = (refined[i].as_mut(), b) {
            r.state = state;
            r.curve.extend(curve);
            r.eval = None;
        }
    }
    tracing::debug!("{name} polish: {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The polishes `cfg.search` asks for (limb, yaw — as [`super::SearchConfig::yaw_polishes`]
/// says —, place: [`polish_best`] each), in that order, on the refined hypotheses;
/// `(edge_dist, sample)` and `seed` as the refinement takes them (`sample`: the fixed batch,
/// when there is one).
pub(super) fn polish_refined(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    (edge_dist, sample): (&Image<f64>, Option<&Stratified>),
    seed: u64,
    refined: &mut [Option<Refined>],
) -> Result<(), ReconError> {
    let s = &cfg.search;
    if s.limb_polish > 0 {
        polish_best(problem, cfg, (s.limb_polish, "limb"), refined, |states| {
            problem.limb_polish(states, cfg, edge_dist, sample, seed)
        })?;
    }
    let yaw = s.yaw_polishes(sample.is_some());
    if yaw > 0 {
        polish_best(problem, cfg, (yaw, "yaw"), refined, |states| {
            problem.yaw_polish(states, cfg, (edge_dist, sample), seed)
        })?;
    }
    if s.place_polish > 0 {
        polish_best(problem, cfg, (s.place_polish, "place"), refined, |states| {
            problem.place_polish(states, cfg, (edge_dist, sample), seed)
        })?;
    }
    Ok(())
}

/// The thermal polish: `polish_iterations` steps on the rise for the best `polish_best` refined
/// hypotheses by the rise (all when 0) and the best one's front/back partner, in parallel;
/// their loss curves extended. A polish that diverges drops its hypothesis.
pub(super) fn polish_rise(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    seed: u64,
    refined: &mut [Option<Refined>],
) -> Result<(), ReconError> {
    let rc = &cfg.radiometric;
    let live: Vec<usize> = (0..refined.len())
        .filter(|&i| refined[i].is_some())
        .collect();
    let chosen: Vec<usize> = if rc.polish_best == 0 {
        live
    } else {
        // Rank on the rise; the evaluations stay with the hypotheses not polished.
        let evals: Vec<FullEval> = live
            .par_iter()
            .map(|&i| refined[i].as_ref().expect("live").evaluated(problem, cfg))
            .collect::<Result<_, ReconError>>()?;
        let mut order: Vec<(usize, f64)> =
            live.iter().zip(&evals).map(|(&i, e)| (i, e.data)).collect();
        for (&i, e) in live.iter().zip(evals) {
            if let Some(r) = refined[i].as_mut() {
                r.eval = Some(e);
            }
        }
        order.sort_by(|a, b| a.1.total_cmp(&b.1));
        let n = rc.polish_best.min(order.len());
        let mut chosen: Vec<usize> = order[..n].iter().map(|o| o.0).collect();
        if let Some(&(best, _)) = order.first() {
            let rot = |i: usize| &refined[i].as_ref().expect("live").state.rotation;
            let partner = order[n..]
                .iter()
                .map(|o| o.0)
                .find(|&i| super::search::front_back(&problem.up, rot(best), rot(i)));
            chosen.extend(partner);
        }
        chosen
    };
    let sample = problem.polish_sample(cfg, seed);
    let polished: Vec<_> = chosen
        .par_iter()
        .map(|&i| {
            let r = refined[i].as_ref().expect("chosen among the refined");
            let end = problem.polish(
                &r.state,
                cfg,
                sample.as_ref(),
                super::search::run_seed(seed, r.init),
            )?;
            Ok((i, end))
        })
        .collect::<Result<_, ReconError>>()?;
    for (i, end) in polished {
        refined[i] = match (refined[i].take(), end) {
            (Some(mut r), Some((state, c))) => {
                r.curve.extend(c);
                r.state = state;
                r.eval = None;
                Some(r)
            }
            _ => None,
        };
    }
    Ok(())
}

impl HumanProblem<'_> {
    /// `st` with its root turned by `deg` degrees about the up axis (through the root).
    pub fn yawed(&self, st: &HumanState, deg: f64) -> HumanState {
        let turn = Rotation3::from_axis_angle(&Unit::new_normalize(self.up), deg.to_radians());
        HumanState {
            rotation: turn.matrix() * st.rotation,
            ..st.clone()
        }
    }

    /// The yaw polish (module docs): each of `states` turned by ± `search.yaw_polish_deg`
    /// ([`Self::neighbour_polish`]).
    pub fn yaw_polish(
        &self,
        states: &[HumanState],
        cfg: &HumanConfig,
        (edge_dist, sample): (&Image<f64>, Option<&Stratified>),
        seed: u64,
    ) -> Result<Vec<Option<Polished>>, ReconError> {
        let deg = cfg.search.yaw_polish_deg;
        self.neighbour_polish(
            states,
            cfg,
            (&[-deg, deg], &|st, d| self.yawed(st, d), "yaw"),
            (edge_dist, sample),
            seed.wrapping_mul(7919).wrapping_add(90_000),
        )
    }

    /// The place polish (module docs): each of `states` moved nearer and farther by
    /// `search.place_polish_frac` of its distance from the mirror ([`Self::slid`],
    /// [`Self::neighbour_polish`]).
    pub fn place_polish(
        &self,
        states: &[HumanState],
        cfg: &HumanConfig,
        (edge_dist, sample): (&Image<f64>, Option<&Stratified>),
        seed: u64,
    ) -> Result<Vec<Option<Polished>>, ReconError> {
        let f = cfg.search.place_polish_frac;
        let from = self.mask_ray_mean()?.0;
        self.neighbour_polish(
            states,
            cfg,
            (&[-f, f], &|st, x| self.slid(st, &from, x), "place"),
            (edge_dist, sample),
            seed.wrapping_mul(7919).wrapping_add(95_000),
        )
    }

    /// `st` moved away from `from` (a point on the mirror) along the line through its root by
    /// `frac` of its distance (nearer for `frac` < 0); with a floor the move is horizontal, so
    /// the feet stay at their height above it.
    pub fn slid(&self, st: &HumanState, from: &Vector3<f64>, frac: f64) -> HumanState {
        let mut step = (st.translation - from) * frac;
        if self.floor.is_some() {
            let up = self.up.normalize();
            step -= up * up.dot(&step);
        }
        HumanState {
            translation: st.translation + step,
            ..st.clone()
        }
    }

    /// Each of `states` moved to `make(state, m)` for every `m` of `moves`, each refined again
    /// as the fit refines a survivor (`(edge_dist, sample)` as the refinement takes them, batch
    /// seeds from `seed`); the lowest end replaces the state when its full loss is below the
    /// state's (`None`: kept as it is).
    #[allow(clippy::type_complexity)]
    fn neighbour_polish(
        &self,
        states: &[HumanState],
        cfg: &HumanConfig,
        (moves, make, name): (
            &[f64],
            &(dyn Fn(&HumanState, f64) -> HumanState + Sync),
            &str,
        ),
        (edge_dist, sample): (&Image<f64>, Option<&Stratified>),
        seed: u64,
    ) -> Result<Vec<Option<Polished>>, ReconError> {
        states
            .iter()
            .enumerate()
            .map(|(k, st)| {
                let own = self.full_eval(st, cfg)?.loss;
                let ends: Vec<Option<(Polished, f64)>> = moves
                    .par_iter()
                    .enumerate()
                    .map(|(j, &m)| {
                        let run_seed = seed.wrapping_add((moves.len() * k + j) as u64);
                        let Some((end, curve)) =
                            self.refine(&make(st, m), cfg, edge_dist, sample, run_seed)?
                        else {
                            return Ok(None);
                        };
                        let loss = self.full_eval(&end, cfg)?.loss;
                        tracing::debug!(
                            "{name} polish {k} ({m:+.2}): full loss {own:.4} → {loss:.4}"
                        );
                        Ok(Some(((end, curve), loss)))
                    })
                    .collect::<Result<_, ReconError>>()?;
                Ok(ends
                    .into_iter()
                    .flatten()
                    .filter(|(_, l)| *l < own)
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(p, _)| p))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `--config` turn the polish cannot take (negative or not a number) is refused by
    /// name; the default is accepted.
    #[test]
    fn a_bad_yaw_turn_is_refused() {
        assert!(HumanConfig::default().check().is_ok());
        for bad in [-5.0, f64::NAN, f64::INFINITY] {
            let mut cfg = HumanConfig::default();
            cfg.search.yaw_polish_deg = bad;
            let e = cfg.check().unwrap_err().to_string();
            assert!(e.contains("search.yaw_polish_deg"), "{e}");
        }
    }

    /// A place move the polish cannot take (negative, the whole distance or more, not a
    /// number) is refused by name.
    #[test]
    fn a_bad_place_move_is_refused() {
        for bad in [-0.1, 1.0, 2.0, f64::NAN] {
            let mut cfg = HumanConfig::default();
            cfg.search.place_polish_frac = bad;
            let e = cfg.check().unwrap_err().to_string();
            assert!(e.contains("search.place_polish_frac"), "{bad}: {e}");
        }
    }
}
