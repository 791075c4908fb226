//! Fitting a prior's shape *and* its placement to depth points (stage 1 with a learned prior,
//! issue 7): the latent `z` and the similarity `depth_from_object` (R, t, s) together, by Adam
//! through the network with candle's reverse mode.
//!
//! Loss, lengths in units of `unit_m` (the object's size, so one schedule fits a mug and a car):
//! * surface points: Huber of the metric signed distance `s · f(z, Rᵀ(p − t)/s)`;
//! * free-space points (in front of the surface, or on rays that saw past the object): hinge
//!   `max(0, −d)`; the same, weighted `w_support`, on points just below the support plane;
//! * the object stands upright: `w_up ‖R ŷ − n‖²` when the support-plane normal `n` is known;
//! * DeepSDF's latent prior `λ ‖z‖²`, and an optional log-normal prior on the scale.
//!
//! The rotation is `R₀ (I + [δ]×)` with δ re-zeroed after every step (the exact rotation
//! `R₀ exp([δ]×)` is folded into `R₀`), so the gradient in δ is exact at δ = 0.
//! Schedule: `latent_steps` steps on the latent alone (the placement comes from the caller's
//! coarse fit), then `steps` steps on everything; learning rates decay by cosine to 5 %.

use crate::SdfError;
use crate::net::{self, SdfNet};
use crate::var_adam::VarAdam;
use candle_core::{DType, Device, Tensor, Var};
use irmirror_geom::Similarity3;
use irmirror_geom::optim::CosineDecay;
use irmirror_geom::rotation::axis_angle_to_matrix;
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Settings of [`fit_placed`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlacedFitConfig {
    /// Steps on the latent alone (placement frozen).
    pub latent_steps: usize,
    /// Steps on latent and placement together.
    pub steps: usize,
    /// Initial learning rates: latent, rotation (rad), translation and log-scale (in `unit_m`).
    pub lr_latent: f64,
    /// See `lr_latent`.
    pub lr_rotation: f64,
    /// See `lr_latent`.
    pub lr_translation: f64,
    /// See `lr_latent`.
    pub lr_scale: f64,
    /// Latent prior weight λ.
    pub latent_reg: f64,
    /// Huber width of the surface term, in `unit_m`.
    pub huber: f64,
    /// Weight of the free-space hinge.
    pub w_free: f64,
    /// Weight of the support-plane hinge (its points are few and the underside's only evidence).
    pub w_support: f64,
    /// Weight of the upright prior.
    pub w_up: f64,
    /// Surface, free-space and inside points drawn per step (each; all when fewer). 256: the
    /// stage-1 bench's figures are those of 512 within noise, 30 % faster.
    pub batch: usize,
    /// Seed of the draws.
    pub seed: u64,
}

impl Default for PlacedFitConfig {
    fn default() -> Self {
        Self {
            latent_steps: 60,
            steps: 120,
            lr_latent: 5e-3,
            lr_rotation: 0.01,
            lr_translation: 0.01,
            lr_scale: 0.01,
            latent_reg: 1e-4,
            huber: 0.03,
            w_free: 1.0,
            w_support: 10.0,
            w_up: 0.3,
            batch: 256,
            seed: 0,
        }
    }
}

/// What the fit sees (depth frame, metres).
#[derive(Clone, Copy, Debug)]
pub struct PlacedObservation<'a> {
    /// Observed surface points.
    pub surface: &'a [Vector3<f64>],
    /// Points known to be outside the object.
    pub free: &'a [Vector3<f64>],
    /// Points known to be inside the object.
    pub inside: &'a [Vector3<f64>],
    /// Points outside the object used in every step (not drawn): a grid just below the support
    /// plane under the footprint, so the unseen underside does not go through the table.
    pub support: &'a [Vector3<f64>],
    /// Unit normal of the support plane (the object's +Y), when known.
    pub up: Option<Vector3<f64>>,
    /// Length unit of the loss, metres (the object's size).
    pub unit_m: f64,
    /// Log-normal prior on the scale: `(ln s̄, σ)`.
    pub scale_prior: Option<(f64, f64)>,
}

/// The fitted shape and placement.
#[derive(Clone, Debug)]
pub struct PlacedFit {
    /// Latent code.
    pub latent: Vec<f64>,
    /// Normalised object frame → depth frame.
    pub depth_from_object: Similarity3<f64>,
    /// Final loss over all points.
    pub loss: f64,
    /// Loss of every step (on that step's draw).
    pub curve: Vec<f64>,
}

/// The optimised variables, as candle tensors of one dtype.
struct Vars {
    z: Var,
    delta: Var,
    tau: Var,
    log_s: Var,
}

/// Everything constant during one loss evaluation.
struct Frame<'a> {
    net: &'a [(Tensor, Tensor)],
    r0: Matrix3<f64>,
    t0: Vector3<f64>,
    s0: f64,
    obs: &'a PlacedObservation<'a>,
    cfg: &'a PlacedFitConfig,
    dtype: DType,
}

fn tensor(v: Vec<f64>, shape: &[usize], dtype: DType) -> candle_core::Result<Tensor> {
    Tensor::from_vec(v, shape, &Device::Cpu)?.to_dtype(dtype)
}

impl Frame<'_> {
    /// The loss (a scalar tensor) on the given surface, free, inside and support points.
    fn loss(
        &self,
        v: &Vars,
        surface: &[Vector3<f64>],
        free: &[Vector3<f64>],
        inside: &[Vector3<f64>],
        support: &[Vector3<f64>],
    ) -> candle_core::Result<Tensor> {
        let dt = self.dtype;
        let u = self.obs.unit_m;
        let l = v.z.as_tensor().dim(1)?;
        // M = R₀ (I + [δ]×); q = (p − t)ᵀ M / s (rows).
        let gens: Vec<f64> = (0..3)
            .flat_map(|k| {
                let mut e = Vector3::zeros();
                e[k] = 1.0;
                let g = e.cross_matrix();
                (0..9).map(move |i| g[(i / 3, i % 3)])
            })
            .collect();
        let skew = v
            .delta
            .as_tensor()
            .matmul(&tensor(gens, &[3, 9], dt)?)?
            .reshape((3, 3))?;
        let r0 = tensor(
            (0..9).map(|i| self.r0[(i / 3, i % 3)]).collect(),
            &[3, 3],
            dt,
        )?;
        let m = (&r0 + r0.matmul(&skew)?)?;
        let t = (tensor(self.t0.as_slice().to_vec(), &[1, 3], dt)?
            + v.tau.as_tensor().affine(u, 0.0)?)?;
        let s = v.log_s.as_tensor().exp()?.affine(self.s0, 0.0)?; // [1, 1]
        let (n_s, n_f, n_i, n_u) = (surface.len(), free.len(), inside.len(), support.len());
        let pts: Vec<f64> = surface
            .iter()
            .chain(free)
            .chain(inside)
            .chain(support)
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        let n = pts.len() / 3;
        let p = tensor(pts, &[n, 3], dt)?;
        let q = p.broadcast_sub(&t)?.matmul(&m)?.broadcast_div(&s)?;
        let x = Tensor::cat(&[&v.z.as_tensor().broadcast_as((n, l))?, &q], 1)?;
        let d = net::forward(self.net, &x)?
            .broadcast_mul(&s.squeeze(1)?)?
            .affine(1.0 / u, 0.0)?;
        let h = self.cfg.huber;
        let mut total = {
            let a = d.narrow(0, 0, n_s)?.abs()?;
            let c = a.clamp(0.0, h)?;
            (c.sqr()?.affine(0.5 / h, 0.0)? + (a - c)?)?.mean_all()?
        };
        if n_f > 0 {
            let hinge = d.narrow(0, n_s, n_f)?.neg()?.relu()?.mean_all()?;
            total = (total + hinge.affine(self.cfg.w_free, 0.0)?)?;
        }
        if n_i > 0 {
            let hinge = d.narrow(0, n_s + n_f, n_i)?.relu()?.mean_all()?;
            total = (total + hinge.affine(self.cfg.w_free, 0.0)?)?;
        }
        if n_u > 0 {
            let hinge = d
                .narrow(0, n_s + n_f + n_i, n_u)?
                .neg()?
                .relu()?
                .mean_all()?;
            total = (total + hinge.affine(self.cfg.w_support, 0.0)?)?;
        }
        if let Some(up) = self.obs.up {
            let ey = tensor(vec![0.0, 1.0, 0.0], &[3, 1], dt)?;
            let dev = (m.matmul(&ey)? - tensor(up.as_slice().to_vec(), &[3, 1], dt)?)?;
            total = (total + dev.sqr()?.sum_all()?.affine(self.cfg.w_up, 0.0)?)?;
        }
        if let Some((mean, sigma)) = self.obs.scale_prior {
            let z = v
                .log_s
                .as_tensor()
                .affine(1.0, self.s0.ln() - mean)?
                .affine(1.0 / sigma, 0.0)?;
            total = (total + z.sqr()?.sum_all()?.affine(1e-3, 0.0)?)?;
        }
        total
            + v.z
                .as_tensor()
                .sqr()?
                .sum_all()?
                .affine(self.cfg.latent_reg, 0.0)?
    }
}

fn scalar(t: &Tensor) -> candle_core::Result<f64> {
    t.to_dtype(DType::F64)?.to_scalar::<f64>()
}

fn vars(latent: &[f64], dtype: DType) -> candle_core::Result<Vars> {
    let l = latent.len();
    Ok(Vars {
        z: Var::from_tensor(&tensor(latent.to_vec(), &[1, l], dtype)?)?,
        delta: Var::from_tensor(&tensor(vec![0.0; 3], &[1, 3], dtype)?)?,
        tau: Var::from_tensor(&tensor(vec![0.0; 3], &[1, 3], dtype)?)?,
        log_s: Var::from_tensor(&tensor(vec![0.0], &[1, 1], dtype)?)?,
    })
}

fn check(
    net: &SdfNet,
    obs: &PlacedObservation,
    init: &Similarity3<f64>,
    latent: &[f64],
) -> Result<(), SdfError> {
    if obs.surface.is_empty() {
        return Err(SdfError::Invalid(
            "fitting a placed shape needs surface points".into(),
        ));
    }
    if obs
        .surface
        .iter()
        .chain(obs.free)
        .chain(obs.inside)
        .chain(obs.support)
        .any(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(SdfError::Invalid(
            "fitting a placed shape: a point is not finite".into(),
        ));
    }
    if !(obs.unit_m > 0.0 && init.scale > 0.0 && init.translation.iter().all(|v| v.is_finite())) {
        return Err(SdfError::Invalid(
            "fitting a placed shape: the unit and the initial scale must be positive".into(),
        ));
    }
    if latent.len() != net.latent_dim {
        return Err(SdfError::Invalid(format!(
            "latent of length {}, expected {}",
            latent.len(),
            net.latent_dim
        )));
    }
    Ok(())
}

/// Fits latent and placement of `net`'s shape to `obs`, from `init` (normalised object frame →
/// depth frame) and `latent` (e.g. the prior's mean latent).
pub fn fit_placed(
    net: &SdfNet,
    obs: &PlacedObservation,
    init: &Similarity3<f64>,
    latent: &[f64],
    cfg: &PlacedFitConfig,
) -> Result<PlacedFit, SdfError> {
    check(net, obs, init, latent)?;
    let dt = DType::F32;
    let layers = net.tensors(&Device::Cpu)?;
    let v = vars(latent, dt)?;
    // (group, part of the placement: frozen during the latent-only steps)
    let mut groups = [
        (VarAdam::new(&v.z, cfg.lr_latent), false),
        (VarAdam::new(&v.delta, cfg.lr_rotation), true),
        (VarAdam::new(&v.tau, cfg.lr_translation), true),
        (VarAdam::new(&v.log_s, cfg.lr_scale), true),
    ];
    let schedule = CosineDecay { floor: 0.05 };
    let mut frame = Frame {
        net: &layers,
        r0: init.rotation,
        t0: init.translation,
        s0: init.scale,
        obs,
        cfg,
        dtype: dt,
    };
    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 13);
    let draw = |pts: &[Vector3<f64>], rng: &mut irmirror_geom::rng::Rng| -> Vec<Vector3<f64>> {
        if pts.len() <= cfg.batch {
            pts.to_vec()
        } else {
            (0..cfg.batch)
                .map(|_| pts[rng.random_range(0..pts.len())])
                .collect()
        }
    };
    let total = cfg.latent_steps + cfg.steps;
    let mut curve = Vec::with_capacity(total);
    for step in 0..total {
        let joint = step >= cfg.latent_steps;
        let (k, n) = if joint {
            (step - cfg.latent_steps, cfg.steps)
        } else {
            (step, cfg.latent_steps)
        };
        let decay = schedule.at_step(k, n);
        let (surface, free, inside) = (
            draw(obs.surface, &mut rng),
            draw(obs.free, &mut rng),
            draw(obs.inside, &mut rng),
        );
        let loss = frame.loss(&v, &surface, &free, &inside, obs.support)?;
        let value = scalar(&loss)?;
        if !value.is_finite() {
            return Err(SdfError::Invalid(format!(
                "placed-shape fit diverged at step {step}"
            )));
        }
        curve.push(value);
        let grads = loss.backward()?;
        for (group, placement) in &mut groups {
            if *placement && !joint {
                continue;
            }
            group.step(&grads, decay)?;
        }
        // Fold the rotation step into R₀.
        let d = v
            .delta
            .as_tensor()
            .to_dtype(DType::F64)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        frame.r0 *= axis_angle_to_matrix(&Vector3::new(d[0], d[1], d[2]));
        v.delta.set(&tensor(vec![0.0; 3], &[1, 3], dt)?)?;
    }
    let loss = scalar(&frame.loss(&v, obs.surface, obs.free, obs.inside, obs.support)?)?;
    let z =
        v.z.as_tensor()
            .to_dtype(DType::F64)?
            .flatten_all()?
            .to_vec1::<f64>()?;
    let tau = v
        .tau
        .as_tensor()
        .to_dtype(DType::F64)?
        .flatten_all()?
        .to_vec1::<f64>()?;
    let log_s = scalar(&v.log_s.as_tensor().flatten_all()?.get(0)?)?;
    let depth_from_object = Similarity3 {
        rotation: frame.r0,
        translation: frame.t0 + Vector3::new(tau[0], tau[1], tau[2]) * obs.unit_m,
        scale: frame.s0 * log_s.exp(),
    };
    Ok(PlacedFit {
        latent: z,
        depth_from_object,
        loss,
        curve,
    })
}

/// A placement relative to the initial similarity: rotation `R₀ exp([δ]×)`, translation
/// `t₀ + τ · unit_m`, scale `s₀ · exp(log_s)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlacementOffset {
    /// Rotation vector δ, rad.
    pub delta: Vector3<f64>,
    /// Translation τ, in units of `unit_m`.
    pub tau: Vector3<f64>,
    /// ln of the scale factor.
    pub log_s: f64,
}

/// The loss and its gradient in f64 at `(latent, δ = 0, τ, ln s/s₀)` — what [`fit_placed`]
/// descends, for gradient checks: `[∂z…, ∂δ (3), ∂τ (3), ∂ln s]`.
pub fn loss_and_gradient(
    net: &SdfNet,
    obs: &PlacedObservation,
    init: &Similarity3<f64>,
    latent: &[f64],
    offset: &PlacementOffset,
    cfg: &PlacedFitConfig,
) -> Result<(f64, Vec<f64>), SdfError> {
    let PlacementOffset { delta, tau, log_s } = *offset;
    check(net, obs, init, latent)?;
    let dt = DType::F64;
    let layers: Vec<(Tensor, Tensor)> = net
        .tensors(&Device::Cpu)?
        .into_iter()
        .map(|(w, b)| Ok((w.to_dtype(dt)?, b.to_dtype(dt)?)))
        .collect::<candle_core::Result<_>>()?;
    let v = vars(latent, dt)?;
    v.delta
        .set(&tensor(delta.as_slice().to_vec(), &[1, 3], dt)?)?;
    v.tau.set(&tensor(tau.as_slice().to_vec(), &[1, 3], dt)?)?;
    v.log_s.set(&tensor(vec![log_s], &[1, 1], dt)?)?;
    let frame = Frame {
        net: &layers,
        r0: init.rotation,
        t0: init.translation,
        s0: init.scale,
        obs,
        cfg,
        dtype: dt,
    };
    let loss = frame.loss(&v, obs.surface, obs.free, obs.inside, obs.support)?;
    let grads = loss.backward()?;
    let mut g = Vec::new();
    for var in [&v.z, &v.delta, &v.tau, &v.log_s] {
        let gt = grads
            .get(var.as_tensor())
            .ok_or_else(|| SdfError::Invalid("no gradient".into()))?;
        g.extend(gt.flatten_all()?.to_vec1::<f64>()?);
    }
    Ok((scalar(&loss)?, g))
}
