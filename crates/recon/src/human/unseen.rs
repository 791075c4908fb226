//! The body parts no ray sees, reported in a standing configuration.
//!
//! A mirror shows part of the person: a bowl the upper body, a mug a band of the torso, a car
//! door the body from the knees or hips up (EXPERIMENTS.md, "Thirtieth run"). The refinement moves
//! the parts no ray sees only through the pose prior's coupling (one latent for the whole
//! body), so a fit whose upper body matches can report legs in a stride or crouch the person
//! never took. After the refinement each state's body parts ([`super::limbs::body_parts`]:
//! legs, torso, arms, head) are tried one at a time in the `unseen_pose` template's
//! configuration, the root kept; a part keeps it when the data term on all rays rises by no
//! more than `unseen_tolerance` over the refined state's (summed over the parts that take
//! it): where the data cannot tell, the report takes the prior's commonest configuration
//! rather than whatever the coupling left.

use super::limbs::body_parts;
use super::problem::FullEval;
use super::{HumanConfig, HumanProblem, HumanState, residual_to};
use crate::ReconError;
use irmirror_body::prior::generator::PoseGenerator;

impl HumanProblem<'_> {
    /// `st` with its unseen parts in `cfg.unseen_pose` (module docs), its evaluation on all
    /// rays when any part changed, and how many did; `st` itself when `unseen_pose` is empty.
    /// `data`: `st`'s data term on all rays when the caller has it.
    pub fn unseen_reset(
        &self,
        st: &HumanState,
        data: Option<f64>,
        cfg: &HumanConfig,
    ) -> Result<(HumanState, Option<FullEval>, usize), ReconError> {
        if cfg.unseen_pose.is_empty() {
            return Ok((st.clone(), None, 0));
        }
        // The template's one deterministic draw (as the pose bank's).
        let template = PoseGenerator::new(self.model)
            .template(&cfg.unseen_pose, &mut irmirror_geom::rng::seeded(0, 43))
            // `HumanConfig::check` names the templates; this is for a caller that skipped it.
            .ok_or_else(|| {
                ReconError::Config(format!("[human] unseen_pose = {:?}", cfg.unseen_pose))
            })?;
        let asset = &self.model.asset;
        let base = match data {
            Some(d) => d,
            None => self.full_eval(st, cfg)?.data,
        };
        let mut pose = self.folded_pose(st)?;
        let mut best = (st.clone(), None);
        let mut changed = 0;
        for part in body_parts(&asset.meta.bone_names, &asset.parents) {
            let mut tried = pose.clone();
            for &j in &part {
                tried[j] = template[j];
            }
            if tried == pose {
                continue;
            }
            // Re-encoded, the residual folding in what the latent does not state: the seen
            // parts keep their pose exactly.
            let latent = self.prior.encode(&tried)?;
            let trial = HumanState {
                residual: residual_to(self.prior, &latent, &tried)?,
                latent,
                ..best.0.clone()
            };
            let eval = self.full_eval(&trial, cfg)?;
            if eval.data <= base + cfg.unseen_tolerance {
                best = (trial, Some(eval));
                pose = tried;
                changed += 1;
            }
        }
        Ok((best.0, best.1, changed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A template name that is not one, or a negative or NaN tolerance, is refused by name
    /// before any fit runs.
    #[test]
    fn a_bad_unseen_setting_is_refused() {
        let ok = HumanConfig {
            unseen_pose: "stand".into(),
            ..HumanConfig::default()
        };
        assert!(ok.check().is_ok());
        let bad = HumanConfig {
            unseen_pose: "standing".into(),
            ..HumanConfig::default()
        };
        let e = bad.check().unwrap_err().to_string();
        assert!(e.contains("unseen_pose") && e.contains("\"stand\""), "{e}");
        for t in [-0.1, f64::NAN] {
            let bad = HumanConfig {
                unseen_tolerance: t,
                ..ok.clone()
            };
            let e = bad.check().unwrap_err().to_string();
            assert!(e.contains("unseen_tolerance"), "{e}");
        }
    }
}
