//! Auto-decoder training (`irmirror train-sdf`): one latent per training shape, optimised jointly
//! with the network (DeepSDF): clamped L1 on SDF samples + `λ ‖z‖²`, two Adam optimisers
//! (network, latents), cosine learning-rate decay. Deterministic for a seed: data, initial
//! weights, latents and batches all come from seeded generators; the sample values are
//! computed in parallel but each is a pure function of its point.

use crate::SdfError;
use crate::families::{Category, FamilyShape};
use crate::mesh_sdf::{MeshSdf, SdfSamples};
use crate::net::{self, SdfNet};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use irmirror_geom::TriMesh;
use irmirror_geom::optim::CosineDecay;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Training settings.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrainSdfConfig {
    /// Procedural training shapes (user meshes come on top).
    pub shapes: usize,
    /// SDF samples per shape.
    pub samples_per_shape: usize,
    /// Optimiser steps.
    pub steps: usize,
    /// Shapes per batch.
    pub shapes_per_batch: usize,
    /// Points per shape per batch.
    pub points_per_shape: usize,
    /// Network learning rate (start of the cosine decay).
    pub lr_net: f64,
    /// Latent learning rate.
    pub lr_latent: f64,
    /// Latent prior weight λ.
    pub latent_reg: f64,
    /// Latent dimension.
    pub latent_dim: usize,
    /// Hidden width.
    pub width: usize,
    /// Marching-tetrahedra cells along a procedural shape's longest side.
    pub mesh_resolution: usize,
    /// Seed.
    pub seed: u64,
}

impl Default for TrainSdfConfig {
    fn default() -> Self {
        Self {
            shapes: 64,
            samples_per_shape: 20_000,
            steps: 4_000,
            shapes_per_batch: 16,
            points_per_shape: 512,
            lr_net: 1e-3,
            lr_latent: 2e-3,
            latent_reg: 1e-4,
            latent_dim: net::LATENT,
            width: net::WIDTH,
            mesh_resolution: 112,
            seed: 0,
        }
    }
}

/// Figures of a training run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrainSdfReport {
    /// The settings.
    pub config: TrainSdfConfig,
    /// Training shapes (procedural + user).
    pub training_shapes: usize,
    /// Seconds spent meshing and sampling.
    pub data_s: f64,
    /// Seconds spent training.
    pub train_s: f64,
    /// Clamped L1 over the last 100 steps (mean).
    pub final_l1: f64,
}

/// `n` procedural members of `category` with their meshes, drawn from stream `stream` of `seed`
/// (training and held-out sets use different streams).
pub fn procedural(
    category: Category,
    n: usize,
    seed: u64,
    stream: u64,
    resolution: usize,
) -> Result<Vec<(FamilyShape, TriMesh)>, SdfError> {
    Ok(procedural_params(category, n, seed, stream)?
        .into_iter()
        .map(|s| (s, s.mesh(resolution)))
        .collect())
}

/// The parameters of [`procedural`]'s shapes, without meshing them.
pub fn procedural_params(
    category: Category,
    n: usize,
    seed: u64,
    stream: u64,
) -> Result<Vec<FamilyShape>, SdfError> {
    let mut rng = irmirror_geom::rng::seeded(seed, stream);
    (0..n)
        .map(|_| FamilyShape::sample(category, &mut rng))
        .collect()
}

/// SDF samples for each mesh (`n` per mesh), deterministic for `seed`.
pub fn sample_meshes(meshes: &[&TriMesh], n: usize, seed: u64) -> Vec<SdfSamples> {
    meshes
        .iter()
        .enumerate()
        .map(|(k, m)| {
            MeshSdf::new(m).samples(n, &mut irmirror_geom::rng::seeded(seed, 1000 + k as u64))
        })
        .collect()
}

fn init_layers(
    l: usize,
    w: usize,
    rng: &mut impl Rng,
    dev: &Device,
) -> Result<Vec<(Var, Var)>, SdfError> {
    let shapes = [(w, l + 3), (w, w), (w, w + l + 3), (w, w), (1, w)];
    shapes
        .iter()
        .enumerate()
        .map(|(k, &(o, i))| {
            // He-uniform; the output layer starts small so the first field is near zero.
            let bound = if k == 4 {
                0.1 / (i as f64).sqrt()
            } else {
                (6.0 / i as f64).sqrt()
            };
            let wv: Vec<f32> = (0..o * i)
                .map(|_| rng.random_range(-bound..bound) as f32)
                .collect();
            Ok((
                Var::from_tensor(&Tensor::from_vec(wv, (o, i), dev)?)?,
                Var::from_tensor(&Tensor::zeros(o, DType::F32, dev)?)?,
            ))
        })
        .collect()
}

/// Trains a prior on `data` (one sample set per shape); `progress(step, l1)` every 25 steps.
pub fn train(
    category: Category,
    data: &[SdfSamples],
    cfg: &TrainSdfConfig,
    metadata: BTreeMap<String, String>,
    mut progress: impl FnMut(usize, f64),
) -> Result<(SdfNet, TrainSdfReport), SdfError> {
    if data.is_empty()
        || data
            .iter()
            .any(|d| d.points.is_empty() || d.points.len() != d.sdf.len())
    {
        return Err(SdfError::Invalid(
            "training needs at least one shape with samples".into(),
        ));
    }
    let dev = Device::Cpu;
    let (l, w) = (cfg.latent_dim, cfg.width);
    let n = data.len();
    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 7);
    let layers = init_layers(l, w, &mut rng, &dev)?;
    let normal = Normal::new(0.0, 0.01).expect("valid σ");
    let z0: Vec<f32> = (0..n * l).map(|_| normal.sample(&mut rng) as f32).collect();
    let latents = Var::from_tensor(&Tensor::from_vec(z0, (n, l), &dev)?)?;
    let net_vars: Vec<Var> = layers
        .iter()
        .flat_map(|(a, b)| [a.clone(), b.clone()])
        .collect();
    let mut opt_net = AdamW::new(
        net_vars,
        ParamsAdamW {
            lr: cfg.lr_net,
            weight_decay: 0.0,
            ..Default::default()
        },
    )?;
    let mut opt_lat = AdamW::new(
        vec![latents.clone()],
        ParamsAdamW {
            lr: cfg.lr_latent,
            weight_decay: 0.0,
            ..Default::default()
        },
    )?;
    let per_batch = cfg.shapes_per_batch.min(n).max(1);
    let batch = per_batch * cfg.points_per_shape;
    let t0 = std::time::Instant::now();
    let mut recent = std::collections::VecDeque::with_capacity(101);
    let (mut pts, mut tgt, mut idx) = (
        Vec::with_capacity(batch * 3),
        Vec::with_capacity(batch),
        Vec::with_capacity(batch),
    );
    let mut order: Vec<usize> = (0..n).collect();
    for step in 0..cfg.steps {
        // Cosine decay to 5 % of the start.
        let decay = CosineDecay { floor: 0.05 }.at_step(step, cfg.steps);
        opt_net.set_learning_rate(cfg.lr_net * decay);
        opt_lat.set_learning_rate(cfg.lr_latent * decay);
        // Shapes without replacement (partial Fisher–Yates), points with replacement.
        for k in 0..per_batch {
            let j = rng.random_range(k..n);
            order.swap(k, j);
        }
        pts.clear();
        tgt.clear();
        idx.clear();
        for &s in &order[..per_batch] {
            let d = &data[s];
            for _ in 0..cfg.points_per_shape {
                let i = rng.random_range(0..d.points.len());
                pts.extend_from_slice(&d.points[i]);
                tgt.push(d.sdf[i].clamp(-net::CLAMP as f32, net::CLAMP as f32));
                idx.push(s as u32);
            }
        }
        let p = Tensor::from_slice(&pts, (batch, 3), &dev)?;
        let t = Tensor::from_slice(&tgt, batch, &dev)?;
        let shape_idx = Tensor::from_slice(&idx, batch, &dev)?;
        let z = latents.as_tensor().index_select(&shape_idx, 0)?;
        let x = Tensor::cat(&[&z, &p], 1)?;
        let tensors: Vec<(Tensor, Tensor)> = layers
            .iter()
            .map(|(a, b)| (a.as_tensor().clone(), b.as_tensor().clone()))
            .collect();
        let f = net::forward(&tensors, &x)?.clamp(-net::CLAMP as f32, net::CLAMP as f32)?;
        let l1 = (f - &t)?.abs()?.mean_all()?;
        let reg = z.sqr()?.sum(1)?.mean_all()?.affine(cfg.latent_reg, 0.0)?;
        let loss = (&l1 + reg)?;
        let grads = loss.backward()?;
        opt_net.step(&grads)?;
        opt_lat.step(&grads)?;
        let l1v = f64::from(l1.to_scalar::<f32>()?);
        if !l1v.is_finite() {
            return Err(SdfError::Invalid(format!(
                "training diverged at step {step} (loss {l1v})"
            )));
        }
        recent.push_back(l1v);
        if recent.len() > 100 {
            recent.pop_front();
        }
        if step % 25 == 0 || step + 1 == cfg.steps {
            progress(step, l1v);
        }
    }
    let train_s = t0.elapsed().as_secs_f64();
    let parts: Vec<(Vec<f32>, Vec<f32>)> = layers
        .iter()
        .map(|(a, b)| {
            Ok((
                a.as_tensor().flatten_all()?.to_vec1::<f32>()?,
                b.as_tensor().to_vec1::<f32>()?,
            ))
        })
        .collect::<Result<_, candle_core::Error>>()?;
    let lat: Vec<Vec<f32>> = latents.as_tensor().to_vec2::<f32>()?;
    let net = SdfNet::from_parts(category, l, w, parts, lat, metadata)?;
    let report = TrainSdfReport {
        config: cfg.clone(),
        training_shapes: n,
        data_s: 0.0,
        train_s,
        final_l1: recent.iter().sum::<f64>() / recent.len().max(1) as f64,
    };
    Ok((net, report))
}
