//! Latent inference with a frozen prior (DeepSDF's shape completion): Adam on the latent alone,
//! from the mean training latent, with the Gaussian latent prior `λ ‖z‖²`.
//!
//! * from SDF samples: clamped L1 between the field and the samples' distances;
//! * from surface points and free-space points (what a depth camera gives, as stage 1 needs):
//!   `|f|` at the surface points plus a hinge `max(0, −f)` at points known to be outside.

use crate::SdfError;
use crate::mesh_sdf::SdfSamples;
use crate::net::{self, SdfNet};
use crate::var_adam::VarAdam;
use candle_core::{Device, Tensor, Var};
use irmirror_geom::optim::CosineDecay;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Inference settings.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct InferConfig {
    /// Adam steps.
    pub steps: usize,
    /// Learning rate (cosine decay to 5 %).
    pub lr: f64,
    /// Latent prior weight λ.
    pub latent_reg: f64,
    /// Points per step (random subset; all when fewer).
    pub batch: usize,
    /// Seed of the subsets.
    pub seed: u64,
}

impl Default for InferConfig {
    fn default() -> Self {
        Self {
            steps: 300,
            lr: 5e-3,
            latent_reg: 1e-4,
            batch: 2048,
            seed: 0,
        }
    }
}

/// The inferred latent and the final data term.
#[derive(Clone, Debug)]
pub struct Inferred {
    /// Latent code.
    pub latent: Vec<f64>,
    /// Final data loss (mean, normalised units).
    pub loss: f64,
}

enum Target<'a> {
    Samples(&'a SdfSamples),
    Surface {
        surface: &'a [[f32; 3]],
        free: &'a [[f32; 3]],
    },
}

fn run(net: &SdfNet, target: Target, cfg: &InferConfig) -> Result<Inferred, SdfError> {
    let dev = Device::Cpu;
    let layers = net.tensors(&dev)?;
    let l = net.latent_dim;
    let z0: Vec<f32> = net.mean_latent().iter().map(|v| *v as f32).collect();
    let z = Var::from_tensor(&Tensor::from_vec(z0, (1, l), &dev)?)?;
    let mut opt = VarAdam::new(&z, cfg.lr);
    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 11);
    let (n_all, n_surface) = match &target {
        Target::Samples(s) => (s.points.len(), s.points.len()),
        Target::Surface { surface, free } => (surface.len() + free.len(), surface.len()),
    };
    let point = |i: usize| -> [f32; 3] {
        match &target {
            Target::Samples(s) => s.points[i],
            Target::Surface { surface, free } => {
                if i < surface.len() {
                    surface[i]
                } else {
                    free[i - surface.len()]
                }
            }
        }
    };
    let mut last = f64::NAN;
    for step in 0..cfg.steps {
        let decay = CosineDecay { floor: 0.05 }.at_step(step, cfg.steps);
        let pick: Vec<usize> = if n_all <= cfg.batch {
            (0..n_all).collect()
        } else {
            (0..cfg.batch).map(|_| rng.random_range(0..n_all)).collect()
        };
        let pts: Vec<f32> = pick.iter().flat_map(|&i| point(i)).collect();
        let m = pick.len();
        let p = Tensor::from_vec(pts, (m, 3), &dev)?;
        let x = Tensor::cat(&[&z.as_tensor().broadcast_as((m, l))?, &p], 1)?;
        let f = net::forward(&layers, &x)?;
        let data = match &target {
            Target::Samples(s) => {
                let t: Vec<f32> = pick
                    .iter()
                    .map(|&i| s.sdf[i].clamp(-net::CLAMP as f32, net::CLAMP as f32))
                    .collect();
                (f.clamp(-net::CLAMP as f32, net::CLAMP as f32)? - Tensor::from_vec(t, m, &dev)?)?
                    .abs()?
                    .mean_all()?
            }
            Target::Surface { .. } => {
                // Surface points: |f|; free-space points: max(0, −f).
                let is_surface: Vec<f32> = pick
                    .iter()
                    .map(|&i| if i < n_surface { 1.0 } else { 0.0 })
                    .collect();
                let s = Tensor::from_vec(is_surface, m, &dev)?;
                let surf = (f.abs()? * &s)?;
                let free = (f.neg()?.relu()? * s.affine(-1.0, 1.0)?)?;
                (surf + free)?.mean_all()?
            }
        };
        let loss = (&data
            + z.as_tensor()
                .sqr()?
                .sum_all()?
                .affine(cfg.latent_reg, 0.0)?)?;
        opt.step(&loss.backward()?, decay)?;
        last = f64::from(data.to_scalar::<f32>()?);
        if !last.is_finite() {
            return Err(SdfError::Invalid(format!(
                "latent inference diverged at step {step}"
            )));
        }
    }
    let latent = z
        .as_tensor()
        .flatten_all()?
        .to_vec1::<f32>()?
        .into_iter()
        .map(f64::from)
        .collect();
    Ok(Inferred { latent, loss: last })
}

/// Infers a latent from SDF samples (normalised frame).
pub fn from_samples(
    net: &SdfNet,
    samples: &SdfSamples,
    cfg: &InferConfig,
) -> Result<Inferred, SdfError> {
    if samples.points.is_empty() || samples.points.len() != samples.sdf.len() {
        return Err(SdfError::Invalid(
            "latent inference needs a non-empty, consistent sample set".into(),
        ));
    }
    if samples
        .points
        .iter()
        .flatten()
        .chain(&samples.sdf)
        .any(|v| !v.is_finite())
    {
        return Err(SdfError::Invalid(
            "latent inference: a sample is not finite".into(),
        ));
    }
    run(net, Target::Samples(samples), cfg)
}

/// Infers a latent from surface points and points known to lie outside (normalised frame).
pub fn from_surface(
    net: &SdfNet,
    surface: &[[f32; 3]],
    free: &[[f32; 3]],
    cfg: &InferConfig,
) -> Result<Inferred, SdfError> {
    if surface.is_empty() {
        return Err(SdfError::Invalid(
            "latent inference needs surface points".into(),
        ));
    }
    if surface.iter().chain(free).flatten().any(|v| !v.is_finite()) {
        return Err(SdfError::Invalid(
            "latent inference: a point is not finite".into(),
        ));
    }
    run(net, Target::Surface { surface, free }, cfg)
}
