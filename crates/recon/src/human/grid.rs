//! The search's candidates: a grid over facing, distance along the mask's reflected rays,
//! pose modes and body builds (module docs of [`super::search`]).

use super::{HumanConfig, HumanProblem, HumanState, upright_facing};
use crate::ReconError;
use irmirror_geom::rotation::axis_angle_to_matrix;
use nalgebra::Vector3;
use rand::Rng;

use super::search::MAX_MASK_SHARE;

impl HumanProblem<'_> {
    /// The mask rays' mean origin and mean direction (unit): where the person is seen from.
    /// An error when the mask has no ray or covers more than [`MAX_MASK_SHARE`] of them.
    pub fn mask_ray_mean(&self) -> Result<(Vector3<f64>, Vector3<f64>), ReconError> {
        let mask_rays: Vec<usize> = (0..self.rays.len())
            .filter(|&i| self.mask.data[self.rays.pixel[i] as usize])
            .collect();
        if mask_rays.is_empty() {
            return Err(ReconError::NoMaskRays);
        }
        let share = mask_rays.len() as f64 / self.rays.len() as f64;
        if share > MAX_MASK_SHARE {
            return Err(ReconError::MaskCoversObjects {
                percent: 100.0 * share,
                max_percent: 100.0 * MAX_MASK_SHARE,
            });
        }
        let o = mask_rays
            .iter()
            .fold(Vector3::zeros(), |a, &i| a + self.rays.origin[i])
            / mask_rays.len() as f64;
        let d = mask_rays
            .iter()
            .fold(Vector3::zeros(), |a, &i| a + self.rays.dir[i])
            .try_normalize(1e-12)
            .ok_or(ReconError::NoMaskRays)?;
        Ok((o, d))
    }

    /// The search's candidates (deterministic for `seed`; module docs).
    pub fn candidates(&self, cfg: &HumanConfig, seed: u64) -> Result<Vec<HumanState>, ReconError> {
        let (o, d) = self.mask_ray_mean()?;
        let s = &cfg.search;
        let height = cfg.height_prior[0];
        let up = self.up.normalize();
        let mut rng = irmirror_geom::rng::seeded(seed, 21);
        let generator = irmirror_body::prior::generator::PoseGenerator::new(self.model);
        let poses: Vec<Vec<[f64; 3]>> = s
            .pose_modes
            .iter()
            .map(|name| {
                generator.template(name, &mut rng).ok_or_else(|| {
                    ReconError::Config(format!(
                        "unknown pose mode {name:?} in [human.search] pose_modes (one of {})",
                        irmirror_body::prior::generator::TEMPLATES.join(", ")
                    ))
                })
            })
            .collect::<Result<_, ReconError>>()?;
        if poses.is_empty() {
            return Err(ReconError::Config(
                "[human.search] pose_modes is empty".to_string(),
            ));
        }
        let builds = if s.builds.is_empty() {
            std::slice::from_ref(&self.build)
        } else {
            &s.builds[..]
        };
        // Each build's modes: how high the root stands above the feet depends on the build.
        let modes: Vec<Vec<super::bank::PoseMode>> = builds
            .iter()
            .map(|b| {
                let shaped = super::shaped_body(self.model, b, height)?;
                poses.iter().map(|p| self.pose_mode(p, &shaped)).collect()
            })
            .collect::<Result<_, ReconError>>()?;
        let [near, far] = cfg.init_distance_m;
        let (nd, ny) = (s.distances.max(1), s.yaw_bins.max(1));
        let mut out = Vec::with_capacity(nd * ny * poses.len() * builds.len());
        for k in 0..nd {
            // Log-spaced: the mirror image of someone 1 m away and of someone 8 m away differ
            // by as much as those at 4 and 8 m.
            let frac = (k as f64 + rng.random_range(0.3..0.7)) / nd as f64;
            let dist = near * (far / near.max(1e-3)).powf(frac);
            let on_ray = o + d * dist;
            let base = upright_facing(&up, &(self.objects_centre - on_ray));
            for j in 0..ny {
                let yaw = std::f64::consts::TAU * j as f64 / ny as f64;
                let rotation = axis_angle_to_matrix(&(up * yaw)) * base;
                for (build, modes) in builds.iter().zip(&modes) {
                    let at = HumanState {
                        translation: on_ray,
                        rotation,
                        height,
                        build: *build,
                        latent: Vec::new(),
                        residual: Vec::new(),
                    };
                    // With a floor, stand there: the ray passes through the body's column.
                    out.extend(modes.iter().map(|m| self.in_mode(&at, m)));
                }
            }
        }
        Ok(out)
    }
}
