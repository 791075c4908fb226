//! Fitting a prior's shape *and* its placement to depth points (stage 1 with a learned prior,
//! issue 7): the latent `z` and the similarity `depth_from_object` (R, t, s) together, by Adam
//! through the network: its f32 forward and reverse by hand (`shared.rs`), the loss and its chain
//! rule to the placement in f64 here. [`loss_and_gradient`] computes the same loss by candle's
//! reverse mode in f64 (what the fit used until session 49, 2.5× slower per object): the
//! reference the hand-written gradient is tested against.
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
use crate::shared::{Activation, SharedLatentNet};
use candle_core::{DType, Device, Tensor, Var};
use irmirror_geom::Similarity3;
use irmirror_geom::optim::{Adam, AdamParams, CosineDecay};
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
/// depth frame) and `latent` (e.g. the prior's mean latent). The network runs in f32 with the
/// hand-written reverse pass of [`SharedLatentNet`]; the loss and its chain rule to the
/// placement in f64 ([`hand_loss`]; [`loss_and_gradient`], candle's reverse mode, is the
/// reference its test compares with).
pub fn fit_placed(
    net: &SdfNet,
    obs: &PlacedObservation,
    init: &Similarity3<f64>,
    latent: &[f64],
    cfg: &PlacedFitConfig,
) -> Result<PlacedFit, SdfError> {
    check(net, obs, init, latent)?;
    let split = SharedLatentNet::<f32>::new(net);
    let l = latent.len();
    // One Adam per group, each counting its own steps (the placement's start when it is
    // released); ε = 1e-8 as candle's AdamW, which this fit used before.
    let params = AdamParams {
        eps: 1e-8,
        ..AdamParams::default()
    };
    let rates = [
        cfg.lr_latent,
        cfg.lr_rotation,
        cfg.lr_translation,
        cfg.lr_scale,
    ];
    let sizes = [l, 3, 3, 1];
    let mut adams = sizes.map(|n| Adam::new(n, params));
    let lrs: Vec<Vec<f64>> = sizes
        .iter()
        .zip(&rates)
        .map(|(&n, &r)| vec![r; n])
        .collect();
    let mut state = HandState::at(init, latent);
    let schedule = CosineDecay { floor: 0.05 };
    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 13);
    let draw = |pts: &[Vector3<f64>], rng: &mut irmirror_geom::rng::Rng| draw(pts, cfg.batch, rng);
    let total = cfg.latent_steps + cfg.steps;
    let mut curve = Vec::with_capacity(total);
    let mut step_buf = vec![0.0; l];
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
        let sets = [&surface[..], &free[..], &inside[..], obs.support];
        let (value, grad) = hand_loss(&split, obs, cfg, &state, sets, true);
        if !value.is_finite() {
            return Err(SdfError::Invalid(format!(
                "placed-shape fit diverged at step {step}"
            )));
        }
        curve.push(value);
        let grad = grad.expect("asked for");
        let mut offset = 0;
        for (g, (adam, (&size, lr))) in adams.iter_mut().zip(sizes.iter().zip(&lrs)).enumerate() {
            let part = &grad[offset..offset + size];
            offset += size;
            if g > 0 && !joint {
                continue;
            }
            let st = &mut step_buf[..size];
            adam.step(part, lr, decay, st);
            match g {
                0 => state.z.iter_mut().zip(st.iter()).for_each(|(z, s)| *z -= s),
                // δ ← −step, folded into R₀ (δ is zero again at the next step).
                1 => state.r0 *= axis_angle_to_matrix(&-Vector3::new(st[0], st[1], st[2])),
                2 => state.tau -= Vector3::new(st[0], st[1], st[2]),
                _ => state.log_s -= st[0],
            }
        }
    }
    let sets = [obs.surface, obs.free, obs.inside, obs.support];
    let (loss, _) = hand_loss(&split, obs, cfg, &state, sets, false);
    let depth_from_object = Similarity3 {
        rotation: state.r0,
        translation: state.t0 + state.tau * obs.unit_m,
        scale: state.s0 * state.log_s.exp(),
    };
    Ok(PlacedFit {
        latent: state.z,
        depth_from_object,
        loss,
        curve,
    })
}

/// `batch` points drawn from `pts` with replacement, or all of them when there are no more.
fn draw(
    pts: &[Vector3<f64>],
    batch: usize,
    rng: &mut irmirror_geom::rng::Rng,
) -> Vec<Vector3<f64>> {
    if pts.len() <= batch {
        pts.to_vec()
    } else {
        (0..batch)
            .map(|_| pts[rng.random_range(0..pts.len())])
            .collect()
    }
}

/// Of `candidates` (latents, e.g. the prior's mean and its training codes), the index of the one
/// whose shape at `init` scores the lowest loss on one draw of `cfg.batch` points of each set
/// (value only, no gradient; stream 14 of `cfg.seed`, so the fit's own draws are unchanged).
/// Why: the fit descends from one latent, and the mean latent lies far from some members of a
/// family (a shallow bowl from the mean's deep one) — the placement is the caller's either way,
/// since every training shape was normalised to the same box.
pub fn best_start(
    net: &SdfNet,
    obs: &PlacedObservation,
    init: &Similarity3<f64>,
    candidates: &[Vec<f64>],
    cfg: &PlacedFitConfig,
) -> Result<usize, SdfError> {
    let Some(first) = candidates.first() else {
        return Err(SdfError::Invalid(
            "no candidate latent to start from".into(),
        ));
    };
    check(net, obs, init, first)?;
    if let Some(z) = candidates.iter().find(|z| z.len() != net.latent_dim) {
        return Err(SdfError::Invalid(format!(
            "latent of length {}, expected {}",
            z.len(),
            net.latent_dim
        )));
    }
    let split = SharedLatentNet::<f32>::new(net);
    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 14);
    let mut draw = |pts: &[Vector3<f64>]| draw(pts, cfg.batch, &mut rng);
    let (surface, free, inside) = (draw(obs.surface), draw(obs.free), draw(obs.inside));
    let sets = [&surface[..], &free[..], &inside[..], obs.support];
    let losses: Vec<f64> = candidates
        .iter()
        .map(|z| hand_loss(&split, obs, cfg, &HandState::at(init, z), sets, false).0)
        .collect();
    Ok((0..losses.len())
        .min_by(|&a, &b| losses[a].total_cmp(&losses[b]))
        .unwrap_or(0))
}

/// The fit's variables at `δ = 0`: rotation `R₀`, translation `t₀ + τ · unit_m`, scale
/// `s₀ · exp(log_s)`, latent `z`.
struct HandState {
    r0: Matrix3<f64>,
    t0: Vector3<f64>,
    s0: f64,
    z: Vec<f64>,
    tau: Vector3<f64>,
    log_s: f64,
}

impl HandState {
    /// The start: `init`'s placement, no offset, latent `z`.
    fn at(init: &Similarity3<f64>, z: &[f64]) -> Self {
        Self {
            r0: init.rotation,
            t0: init.translation,
            s0: init.scale,
            z: z.to_vec(),
            tau: Vector3::zeros(),
            log_s: 0.0,
        }
    }
}

/// The loss [`loss_and_gradient`] computes, at `δ = 0`, on the point sets `[surface, free,
/// inside, support]`, and (with `want`) its gradient `[∂z…, ∂δ (3), ∂τ (3), ∂ln s]`. With
/// `q = R₀ᵀ (p − t) / s` (`M = R₀ (I + [δ]×)` at δ = 0) and `d = s f(z, q) / u`:
/// `∂q/∂δ = [q]×`, `∂q/∂τ = −R₀ᵀ u / s`, `∂d/∂ln s = d − (s/u) ∇f · q`.
fn hand_loss<T: Activation>(
    net: &SharedLatentNet<T>,
    obs: &PlacedObservation,
    cfg: &PlacedFitConfig,
    st: &HandState,
    sets: [&[Vector3<f64>]; 4],
    want: bool,
) -> (f64, Option<Vec<f64>>) {
    let u = obs.unit_m;
    let (t, s) = (st.t0 + st.tau * u, st.s0 * st.log_s.exp());
    let q: Vec<Vector3<f64>> = sets
        .iter()
        .flat_map(|set| set.iter())
        .map(|p| st.r0.tr_mul(&(p - t)) / s)
        .collect();
    let (f, pass) = net.forward(&st.z, &q, want);
    let d: Vec<f64> = f.iter().map(|f| s * f / u).collect();
    // ∂L/∂d per point, and the loss, set by set.
    let mut gd = vec![0.0; d.len()];
    let mut loss = 0.0;
    let mut start = 0;
    let h = cfg.huber;
    for (k, set) in sets.iter().enumerate() {
        let n = set.len();
        let range = start..start + n;
        start += n;
        if n == 0 {
            continue;
        }
        let inv = 1.0 / n as f64;
        for i in range {
            let di = d[i];
            let (value, slope) = match k {
                // Huber: ½ c²/h + (|d| − c), c = min(|d|, h).
                0 => {
                    let (a, c) = (di.abs(), di.abs().min(h));
                    (0.5 * c * c / h + (a - c), di.signum() * c / h)
                }
                1 if di < 0.0 => (-di * cfg.w_free, -cfg.w_free),
                2 if di > 0.0 => (di * cfg.w_free, cfg.w_free),
                3 if di < 0.0 => (-di * cfg.w_support, -cfg.w_support),
                _ => (0.0, 0.0),
            };
            loss += value * inv;
            gd[i] = slope * inv;
        }
    }
    let y = Vector3::y();
    let mut g_delta = Vector3::zeros();
    let mut g_log_s = 0.0;
    if let Some(up) = obs.up {
        let e = st.r0 * y - up;
        loss += cfg.w_up * e.norm_squared();
        g_delta += y.cross(&st.r0.tr_mul(&e)) * (2.0 * cfg.w_up);
    }
    if let Some((mean, sigma)) = obs.scale_prior {
        let zs = (st.log_s + st.s0.ln() - mean) / sigma;
        loss += 1e-3 * zs * zs;
        g_log_s += 2e-3 * zs / sigma;
    }
    loss += cfg.latent_reg * st.z.iter().map(|v| v * v).sum::<f64>();
    let Some(pass) = pass else {
        return (loss, None);
    };
    let gf: Vec<f64> = gd.iter().map(|g| g * s / u).collect();
    let (gq, gz_net) = net.backward(&pass, &gf);
    let mut g_tau_obj = Vector3::zeros();
    for i in 0..q.len() {
        g_delta += gq[i].cross(&q[i]);
        g_tau_obj += gq[i];
        g_log_s += gd[i] * d[i] - gq[i].dot(&q[i]);
    }
    let g_tau = st.r0 * g_tau_obj * (-u / s);
    let mut grad: Vec<f64> = gz_net
        .iter()
        .zip(&st.z)
        .map(|(g, z)| g + 2.0 * cfg.latent_reg * z)
        .collect();
    grad.extend(g_delta.iter());
    grad.extend(g_tau.iter());
    grad.push(g_log_s);
    (loss, Some(grad))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::families::{Category, FamilyShape};

    /// The hand-written loss and gradient (the fit's) against candle's reverse mode of the same
    /// loss in f64 (`loss_and_gradient`, itself FD-tested in `tests/placed.rs`), against central
    /// differences, and in f32 (what the fit runs) within f32's rounding — with every term
    /// active: Huber in both branches, the hinges on, the up and scale priors off their minima.
    #[test]
    fn hand_gradient_matches_candle_and_finite_differences() {
        let net = SdfNet::builtin(Category::Mug).expect("shipped prior");
        let shape = FamilyShape::sample(Category::Mug, &mut irmirror_geom::rng::seeded(4, 77))
            .expect("a mug");
        let mesh = shape.mesh(24);
        let truth = Similarity3 {
            rotation: axis_angle_to_matrix(&Vector3::new(-1.7, 0.4, 0.2)),
            translation: Vector3::new(0.03, -0.01, 0.5),
            scale: 0.08,
        };
        let surface: Vec<Vector3<f64>> = mesh
            .vertices
            .iter()
            .step_by(5)
            .map(|v| truth.transform_point(&Vector3::new(v[0], v[1], v[2]).map(f64::from)))
            .collect();
        let c = truth.translation;
        let free: Vec<Vector3<f64>> = surface.iter().map(|p| c + (p - c) * 1.05).collect();
        let inside: Vec<Vector3<f64>> = surface.iter().map(|p| c + (p - c) * 0.9).collect();
        let support: Vec<Vector3<f64>> = (0..25)
            .map(|i| c + Vector3::new((i % 5) as f64 - 2.0, -1.0, (i / 5) as f64 - 2.0) * 0.02)
            .collect();
        let obs = PlacedObservation {
            surface: &surface,
            free: &free,
            inside: &inside,
            support: &support,
            up: Some(Vector3::new(0.1, -0.95, -0.2).normalize()),
            unit_m: 0.08,
            scale_prior: Some((0.08f64.ln(), 0.1)),
        };
        let init = Similarity3 {
            rotation: truth.rotation * axis_angle_to_matrix(&Vector3::new(0.08, -0.05, 0.1)),
            translation: truth.translation + Vector3::new(0.004, -0.003, 0.002),
            scale: 0.085,
        };
        let z: Vec<f64> = net
            .mean_latent()
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.02 * (i as f64 * 0.7).sin())
            .collect();
        let (tau, log_s) = (Vector3::new(0.02, 0.01, -0.03), 0.04);
        let cfg = PlacedFitConfig::default();
        let state = |z: &[f64], tau: Vector3<f64>, log_s: f64, r0: Matrix3<f64>| HandState {
            r0,
            t0: init.translation,
            s0: init.scale,
            z: z.to_vec(),
            tau,
            log_s,
        };
        let sets = [&surface[..], &free[..], &inside[..], &support[..]];
        let split = SharedLatentNet::<f64>::new(&net);
        let st = state(&z, tau, log_s, init.rotation);
        let (loss, grad) = hand_loss(&split, &obs, &cfg, &st, sets, true);
        let grad = grad.expect("asked for");
        let offset = PlacementOffset {
            delta: Vector3::zeros(),
            tau,
            log_s,
        };
        let (ref_loss, ref_grad) =
            loss_and_gradient(&net, &obs, &init, &z, &offset, &cfg).expect("reference");
        assert!(
            (loss - ref_loss).abs() < 1e-10,
            "loss {loss} for {ref_loss}"
        );
        let scale = ref_grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (k, (g, r)) in grad.iter().zip(&ref_grad).enumerate() {
            assert!((g - r).abs() < 1e-9 * scale, "∂{k}: {g} for {r}");
        }
        // Central differences: the latent, δ (as R₀ exp([h e_k]×), equal to first order), τ, ln s.
        let l = z.len();
        let eval = |st: &HandState| hand_loss(&split, &obs, &cfg, st, sets, false).0;
        let h = 1e-6;
        for k in [0, 7, l, l + 1, l + 2, l + 3, l + 5, l + 6] {
            let moved = |sign: f64| {
                let (mut z2, mut tau2, mut r0) = (z.clone(), tau, init.rotation);
                let mut ls2 = log_s;
                match k {
                    k if k < l => z2[k] += sign * h,
                    k if k < l + 3 => {
                        let mut e = Vector3::zeros();
                        e[k - l] = sign * h;
                        r0 *= axis_angle_to_matrix(&e);
                    }
                    k if k < l + 6 => tau2[k - l - 3] += sign * h,
                    _ => ls2 += sign * h,
                }
                eval(&state(&z2, tau2, ls2, r0))
            };
            let fd = (moved(1.0) - moved(-1.0)) / (2.0 * h);
            assert!(
                (fd - grad[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "∂{k}: {} for {fd}",
                grad[k]
            );
        }
        // f32 (the fit's network): the same within its rounding.
        let split32 = SharedLatentNet::<f32>::new(&net);
        let (loss32, grad32) = hand_loss(&split32, &obs, &cfg, &st, sets, true);
        assert!(
            (loss32 - loss).abs() < 1e-5 * loss.abs().max(1.0),
            "f32 loss {loss32}"
        );
        for (k, (g, r)) in grad32.expect("asked for").iter().zip(&grad).enumerate() {
            assert!((g - r).abs() < 1e-3 * scale, "f32 ∂{k}: {g} for {r}");
        }
    }
}
