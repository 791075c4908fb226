//! Stage 2 (paper §3.4–3.5, DESIGN.md §1): the person, from the reflection mask, with the
//! objects fixed.
//!
//! Parameters per hypothesis: root translation `t` (depth frame, m), root rotation
//! `R = exp(ω) B` (`B` the initial orientation), pose latent `z` (32, the pose prior), shape
//! fixed at the mean adult ([`mean_adult`]). Loss: `1 − soft IoU` between the soft occupancy of
//! sampled reflected rays and the observed mask, plus `w_prior ‖z‖²`, an upright prior, and —
//! where the floor is known (below a table, or the ground a car stands on) — the body's lowest
//! point on it. Gradients: occupancy backward → vertices → body backward → rotations → pose
//! prior VJP (all analytic; see the crates' FD tests).
//!
//! * **Edge sampling.** Each iteration draws `rays_per_iteration` rays without replacement with
//!   weight `(1 − α) + α exp(−e/τ)`, `e` the pixel distance to the mask's edge; α grows from 0 to
//!   `edge_mix` and τ shrinks from `edge_tau_px[0]` to `[1]` over the iterations (curriculum).
//!   Ablated: uniform draws of the same count.
//! * **σ annealing.** The occupancy blur shrinks geometrically from `sigma_m2[0]` to `[1]`.
//! * **Initialisations.** `inits` hypotheses, run in parallel: root on the mean reflected ray of
//!   the mask at distances log-spaced over `init_distance_m` (then standing on the floor, when
//!   it is known), upright on the support plane, facing the objects give or take 60°, pose
//!   latent 0 for the first and prior samples (×0.5) for the rest. The best by final full-ray
//!   loss is kept; the `top_k` distinct ones are reported.

use crate::ReconError;
use irmirror_body::model::{BodyGrad, OutputGrads};
use irmirror_body::prior::PosePrior;
use irmirror_body::{BodyModel, Pose};
use irmirror_capture::Image;
use irmirror_geom::optim::{Adam, AdamParams, CosineDecay};
use irmirror_geom::rotation::{
    axis_angle_to_matrix, axis_angle_to_matrix_vjp, matrix_to_axis_angle,
};
use irmirror_render::occupancy::{
    Aggregation, Culling, OccupancyGrad, OccupancyParams, SoftRenderer, soft_iou,
};
use irmirror_render::reflect::ReflectedRays;
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Stage-2 settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HumanConfig {
    /// Random initialisations.
    pub inits: usize,
    /// Adam steps per initialisation.
    pub iterations: usize,
    /// Rays drawn per step (all when fewer).
    pub rays_per_iteration: usize,
    /// Edge sampling on/off (ablation switch).
    pub edge_sampling: bool,
    /// Final weight α of the edge term.
    pub edge_mix: f64,
    /// Edge length scale τ at the start and the end, pixels.
    pub edge_tau_px: [f64; 2],
    /// Occupancy σ at the start and the end, m².
    pub sigma_m2: [f64; 2],
    /// Learning rates: translation (m), rotation (rad), latent.
    pub lr_translation: f64,
    /// See `lr_translation`.
    pub lr_rotation: f64,
    /// See `lr_translation`.
    pub lr_latent: f64,
    /// Weight of `‖z‖²`.
    pub w_prior: f64,
    /// Weight of the upright prior `1 − (R ẑ)·n` (people stand on the support plane's side:
    /// Anny's up should follow the plane normal; the pose bends the body, not the root).
    pub w_upright: f64,
    /// Weight of the floor prior `((h_min − 0) / σ)²`, `h_min` the height of the body's lowest
    /// vertex above the floor (people stand, sit or kneel on it); 0 switches it off.
    pub w_floor: f64,
    /// σ of the floor prior, metres.
    pub floor_sigma_m: f64,
    /// Height of a table above the floor, metres, when the support plane is a table (objects
    /// that are not cars): the floor is this far below it (EN 527 desks: 0.72–0.76 m).
    pub table_height_m: f64,
    /// Range of the initial root distances along the mean reflected ray (log-spaced), metres.
    pub init_distance_m: [f64; 2],
    /// Distinct hypotheses reported.
    pub top_k: usize,
    /// How the body's triangles form a ray's occupancy (`irmirror_render::occupancy` docs).
    pub aggregation: Aggregation,
}

impl Default for HumanConfig {
    fn default() -> Self {
        Self {
            inits: 8,
            iterations: 200,
            rays_per_iteration: 3000,
            edge_sampling: true,
            edge_mix: 0.9,
            edge_tau_px: [6.0, 1.5],
            sigma_m2: [1e-3, 1e-5],
            lr_translation: 0.04,
            lr_rotation: 0.06,
            lr_latent: 0.08,
            w_prior: 2e-3,
            w_upright: 0.05,
            w_floor: 0.01,
            floor_sigma_m: 0.05,
            table_height_m: 0.75,
            init_distance_m: [0.7, 8.0],
            top_k: 3,
            aggregation: Aggregation::Silhouette,
        }
    }
}

/// One fitted hypothesis.
#[derive(Clone, Debug, Serialize)]
pub struct Hypothesis {
    /// Which initialisation it came from.
    pub init: usize,
    /// Root joint position, depth frame, metres.
    pub translation_m: [f64; 3],
    /// Root rotation (Anny frame → depth frame) as a rotation vector, radians.
    pub root_rotvec_rad: [f64; 3],
    /// Pose latent.
    pub latent: Vec<f64>,
    /// Final loss on all rays at the final σ.
    pub loss: f64,
    /// Soft IoU on all rays at the final σ.
    pub soft_iou: f64,
    /// Loss per step (on that step's sampled rays).
    #[serde(skip)]
    pub loss_curve: Vec<f64>,
}

/// Stage-2 result.
#[derive(Clone, Debug, Serialize)]
pub struct HumanFit {
    /// Best hypothesis first, then up to `top_k − 1` distinct others (root > 25 cm apart or
    /// facing > 45° apart), by loss.
    pub hypotheses: Vec<Hypothesis>,
    /// Initialisations that diverged (non-finite loss) and were dropped.
    pub diverged: usize,
    /// Reflected rays (object pixels) and mask pixels among them.
    pub rays: usize,
    /// Mask pixels with a ray.
    pub mask_rays: usize,
}

/// Everything a fit needs that does not change between hypotheses.
pub struct HumanProblem<'a> {
    /// The body model.
    pub model: &'a BodyModel,
    /// The pose prior.
    pub prior: &'a PosePrior,
    /// Reflected rays of the object pixels (depth frame).
    pub rays: &'a ReflectedRays<f64>,
    /// Thermal-pixel reflection mask.
    pub mask: &'a Image<bool>,
    /// Support-plane normal (up), depth frame.
    pub up: Vector3<f64>,
    /// Centre of the objects, depth frame (the person faces it, roughly).
    pub objects_centre: Vector3<f64>,
    /// The floor the person stands on, when known.
    pub floor: Option<Floor>,
}

/// A horizontal floor: height of `p` above it = `up · p − offset_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// Unit up, depth frame.
    pub up: Vector3<f64>,
    /// `up · p` on the floor, metres.
    pub offset_m: f64,
}

impl Floor {
    /// Height of `p` (depth frame) above the floor, metres.
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.up.dot(p) - self.offset_m
    }
}

/// Per-pixel chamfer distance (3-4, in pixels) to the nearest edge of `mask` (inside or out).
pub fn edge_distance(mask: &Image<bool>) -> Image<f64> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let big = 1e9;
    let mut d = vec![big; w * h];
    for y in 0..h {
        for x in 0..w {
            let m = mask.data[y * w + x];
            let edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|&(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    nx >= 0
                        && ny >= 0
                        && nx < w as i64
                        && ny < h as i64
                        && mask.data[ny as usize * w + nx as usize] != m
                });
            if edge {
                d[y * w + x] = 0.0;
            }
        }
    }
    let pass = |d: &mut Vec<f64>, xs: Vec<usize>, ys: Vec<usize>, offs: [(i64, i64, f64); 4]| {
        for &y in &ys {
            for &x in &xs {
                for (dx, dy, c) in offs {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64 {
                        let v = d[ny as usize * w + nx as usize] + c;
                        if v < d[y * w + x] {
                            d[y * w + x] = v;
                        }
                    }
                }
            }
        }
    };
    let (a, b) = (1.0, std::f64::consts::SQRT_2);
    pass(
        &mut d,
        (0..w).collect(),
        (0..h).collect(),
        [(-1, 0, a), (0, -1, a), (-1, -1, b), (1, -1, b)],
    );
    pass(
        &mut d,
        (0..w).rev().collect(),
        (0..h).rev().collect(),
        [(1, 0, a), (0, 1, a), (1, 1, b), (-1, 1, b)],
    );
    Image {
        width: mask.width,
        height: mask.height,
        data: d,
    }
}

/// A rotation taking Anny's +Z (up) to `up` and Anny's front (−Y) towards `facing` (projected
/// onto the plane).
pub fn upright_facing(up: &Vector3<f64>, facing: &Vector3<f64>) -> Matrix3<f64> {
    let z = up.normalize();
    let mut f = facing - z * z.dot(facing);
    if f.norm() < 1e-9 {
        f = if z.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        f -= z * z.dot(&f);
    }
    let front = f.normalize();
    // Columns: images of Anny's X, Y, Z. Anny's −Y is the front, so Y ↦ −front; X = Y × Z.
    let y = -front;
    let x = y.cross(&z);
    Matrix3::from_columns(&[x, y, z])
}

/// The body shape stage 2 fits with: the mean adult (the default phenotype, ≈ 1.69 m), not
/// the shape basis' origin (coefficients 0 are a 1.84 m body: 9 % too tall, which biases the
/// distance of every fit).
pub fn mean_adult(model: &BodyModel) -> Result<irmirror_body::ShapedBody<f64>, ReconError> {
    model
        .shaped_phenotype::<f64>(&irmirror_body::Phenotype::default())
        .map_err(ReconError::from)
}

/// Where [`HumanProblem::loss_grad`] evaluates: root translation `t` (depth frame, m), root
/// rotation `exp(ω) base` (Anny → depth; the gradient is taken in ω at the given value), pose
/// latent.
#[derive(Clone, Copy, Debug)]
pub struct Tangent<'a> {
    /// Root position, depth frame, m.
    pub translation: &'a Vector3<f64>,
    /// Rotation vector applied on the left of `base`, rad.
    pub omega: &'a Vector3<f64>,
    /// Base root rotation, Anny → depth.
    pub base: &'a Matrix3<f64>,
    /// Pose latent.
    pub latent: &'a [f64],
}

/// The rays a loss evaluation sees: reflected rays, their 0/1 targets, and the blur.
#[derive(Clone, Copy, Debug)]
pub struct Batch<'a> {
    /// Reflected rays, depth frame.
    pub rays: &'a ReflectedRays<f64>,
    /// Target per ray (1: in the reflection mask).
    pub target: &'a [f64],
    /// Occupancy blur σ, m².
    pub sigma_m2: f64,
}

/// The state of one hypothesis.
#[derive(Clone, Debug)]
pub struct HumanState {
    /// Root position, depth frame, m.
    pub translation: Vector3<f64>,
    /// Root rotation, Anny → depth.
    pub rotation: Matrix3<f64>,
    /// Pose latent.
    pub latent: Vec<f64>,
}

impl HumanProblem<'_> {
    /// The pose of a state (36 rotations; root first).
    pub fn pose(&self, st: &HumanState) -> Result<Pose<f64>, ReconError> {
        let mut rotations = self.prior.decode(&st.latent)?;
        rotations[0] = st.rotation;
        Ok(Pose {
            rotations,
            translation: st.translation,
        })
    }

    /// Buffers reused across steps (allocation-free after the first step).
    pub fn scratch(&self) -> Result<Scratch, ReconError> {
        let shaped = mean_adult(self.model)?;
        Ok(Scratch {
            shaped,
            posed: self.model.posed_buffers(),
            renderer: None,
            occ_grad: OccupancyGrad::default(),
            body_grad: BodyGrad {
                rotations: vec![],
                translation: Vector3::zeros(),
                shape: vec![],
            },
            d_value: Vec::new(),
        })
    }

    /// The stage-2 loss of the body at `at` on `batch`, and the soft IoU. With `grad` (length
    /// 6 + latent), writes `∂L/∂(t, ω, latent)` there.
    pub fn loss_grad(
        &self,
        ws: &mut Scratch,
        at: &Tangent<'_>,
        batch: &Batch<'_>,
        cfg: &HumanConfig,
        grad: Option<&mut [f64]>,
    ) -> Result<(f64, f64), ReconError> {
        let Tangent {
            translation: t,
            omega,
            base,
            latent,
        } = *at;
        let Batch {
            rays,
            target,
            sigma_m2,
        } = *batch;
        let st = HumanState {
            translation: *t,
            rotation: axis_angle_to_matrix(omega) * base,
            latent: latent.to_vec(),
        };
        let pose = self.pose(&st)?;
        self.model.pose_into(&ws.shaped, &pose, &mut ws.posed)?;
        let r = ws
            .renderer
            .get_or_insert_with(|| SoftRenderer::new(&ws.posed.vertices, &self.model.asset.faces));
        r.set_vertices(&ws.posed.vertices);
        let params = OccupancyParams {
            sigma_m2,
            aggregation: cfg.aggregation,
            ..OccupancyParams::default()
        };
        let occ = r.forward(rays, &params, Culling::Bvh);
        let (l_iou, iou) = soft_iou(&occ.value, |i| target[i], 0.0, &mut ws.d_value);
        let prior: f64 = latent.iter().map(|x| x * x).sum();
        let up = self.up.normalize();
        let mut loss = l_iou
            + cfg.w_prior * prior
            + cfg.w_upright * (1.0 - (st.rotation * Vector3::z()).dot(&up));
        // Floor: the lowest vertex on it (its subgradient goes to that vertex alone).
        let floor = self.floor.filter(|_| cfg.w_floor > 0.0).map(|f| {
            let (k, h) = ws
                .posed
                .vertices
                .iter()
                .enumerate()
                .map(|(k, v)| (k, f.height(v)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("a body has vertices");
            let e = h / cfg.floor_sigma_m;
            loss += cfg.w_floor * e * e;
            (k, f.up * (2.0 * cfg.w_floor * e / cfg.floor_sigma_m))
        });
        let Some(g) = grad else {
            return Ok((loss, iou));
        };
        r.backward(
            rays,
            &occ,
            &ws.d_value,
            &params,
            Culling::Bvh,
            &mut ws.occ_grad,
        );
        if let Some((k, d)) = floor {
            ws.occ_grad.vertices[k] += d;
        }
        let bg = &mut ws.body_grad;
        self.model.backward(
            &ws.shaped,
            &pose,
            &mut ws.posed,
            OutputGrads {
                vertices: Some(&ws.occ_grad.vertices),
                ..Default::default()
            },
            bg,
        );
        // ∂(−w (R ẑ)·n)/∂R = −w n ẑᵀ.
        bg.rotations[0] -= up * Vector3::z().transpose() * cfg.w_upright;
        let d_omega = axis_angle_to_matrix_vjp(omega, &(bg.rotations[0] * base.transpose()));
        let d_lat = self.prior.decode_vjp(latent, &bg.rotations)?;
        g[..3].copy_from_slice(bg.translation.as_slice());
        g[3..6].copy_from_slice(d_omega.as_slice());
        for (k, (gk, dk)) in g[6..].iter_mut().zip(&d_lat).enumerate() {
            *gk = dk + cfg.w_prior * 2.0 * latent[k];
        }
        Ok((loss, iou))
    }

    /// Targets of all rays (1 in the mask).
    pub fn targets(&self) -> Vec<f64> {
        self.rays
            .pixel
            .iter()
            .map(|&p| f64::from(u8::from(self.mask.data[p as usize])))
            .collect()
    }

    /// The data term of any body mesh (depth frame; e.g. the true body, which the prior need not
    /// represent): `(1 − soft IoU, soft IoU)` on all rays at the final σ, as the hypotheses'
    /// `soft_iou` is scored. The failure diagnosis compares it with the fit's.
    pub fn mesh_data_loss(
        &self,
        vertices: &[Vector3<f64>],
        faces: &[[u32; 3]],
        cfg: &HumanConfig,
    ) -> (f64, f64) {
        let mut renderer = SoftRenderer::new(vertices, faces);
        renderer.set_vertices(vertices);
        let params = OccupancyParams {
            sigma_m2: cfg.sigma_m2[1],
            aggregation: cfg.aggregation,
            ..OccupancyParams::default()
        };
        let occ = renderer.forward(self.rays, &params, Culling::Bvh);
        let target = self.targets();
        soft_iou(&occ.value, |i| target[i], 0.0, &mut Vec::new())
    }

    /// Loss of a state on all rays at the final σ, and its soft IoU.
    pub fn full_loss(&self, st: &HumanState, cfg: &HumanConfig) -> Result<(f64, f64), ReconError> {
        let mut ws = self.scratch()?;
        let at = Tangent {
            translation: &st.translation,
            omega: &Vector3::zeros(),
            base: &st.rotation,
            latent: &st.latent,
        };
        let batch = Batch {
            rays: self.rays,
            target: &self.targets(),
            sigma_m2: cfg.sigma_m2[1],
        };
        self.loss_grad(&mut ws, &at, &batch, cfg, None)
    }

    /// Initial states (deterministic for `seed`).
    pub fn initial_states(
        &self,
        cfg: &HumanConfig,
        seed: u64,
    ) -> Result<Vec<HumanState>, ReconError> {
        let mask_rays: Vec<usize> = (0..self.rays.len())
            .filter(|&i| self.mask.data[self.rays.pixel[i] as usize])
            .collect();
        if mask_rays.is_empty() {
            return Err(ReconError::NoMaskRays);
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
        let mut rng = irmirror_geom::rng::seeded(seed, 21);
        let n = cfg.inits.max(1);
        let mut out = Vec::with_capacity(n);
        // Height of the root above the floor for the mean pose standing upright.
        let root_height = match self.floor {
            Some(_) => {
                // Anny's own frame is Z up: the identity root stands upright.
                let st = HumanState {
                    translation: Vector3::zeros(),
                    rotation: Matrix3::identity(),
                    latent: vec![0.0; irmirror_body::prior::LATENT],
                };
                let mut ws = self.scratch()?;
                self.model
                    .pose_into(&ws.shaped, &self.pose(&st)?, &mut ws.posed)?;
                -ws.posed
                    .vertices
                    .iter()
                    .map(|v| v.z)
                    .fold(f64::INFINITY, f64::min)
            }
            None => 0.0,
        };
        let [near, far] = cfg.init_distance_m;
        for k in 0..n {
            // Log-spaced: the mirror image of someone 1 m away and of someone 8 m away differ
            // by as much as those at 4 and 8 m.
            let frac = (k as f64 + rng.random_range(0.2..0.8)) / n as f64;
            let dist = near * (far / near.max(1e-3)).powf(frac);
            let mut p = o + d * dist;
            // With a floor, stand there: the ray passes through the body's column.
            if let Some(f) = self.floor {
                p += f.up * (root_height - f.height(&p));
            }
            let facing = self.objects_centre - p;
            let base = upright_facing(&self.up, &facing);
            let yaw: f64 = rng.random_range(-1.0..1.0);
            let rotation = axis_angle_to_matrix(&(self.up.normalize() * yaw)) * base;
            let latent: Vec<f64> = if k == 0 {
                vec![0.0; irmirror_body::prior::LATENT]
            } else {
                (0..irmirror_body::prior::LATENT)
                    .map(|_| {
                        let x: f64 = StandardNormal.sample(&mut rng);
                        0.5 * x
                    })
                    .collect::<Vec<f64>>()
            };
            out.push(HumanState {
                translation: p,
                rotation,
                latent,
            });
        }
        Ok(out)
    }

    /// Runs one hypothesis from `init`; returns the final state and the per-step loss, or `None`
    /// if it diverged.
    pub fn run(
        &self,
        init: &HumanState,
        cfg: &HumanConfig,
        edge_dist: &Image<f64>,
        seed: u64,
    ) -> Result<Option<(HumanState, Vec<f64>)>, ReconError> {
        let mut ws = self.scratch()?;
        let mut st = init.clone();
        let base = st.rotation;
        let mut omega = Vector3::zeros();
        let n_lat = st.latent.len();
        let mut adam = Adam::new(6 + n_lat, AdamParams::default());
        let mut lr = vec![cfg.lr_translation; 3];
        lr.extend([cfg.lr_rotation; 3]);
        lr.extend(vec![cfg.lr_latent; n_lat]);
        let mut rng = irmirror_geom::rng::seeded(seed, 31);
        let target_all = self.targets();
        let e_all: Vec<f64> = self
            .rays
            .pixel
            .iter()
            .map(|&p| edge_dist.data[p as usize])
            .collect();
        let (mut sub, mut target, mut keys, mut idx) = (
            ReflectedRays::default(),
            Vec::new(),
            Vec::<(f64, usize)>::new(),
            Vec::new(),
        );
        let mut curve = Vec::with_capacity(cfg.iterations);
        let (mut g, mut step) = (vec![0.0; 6 + n_lat], vec![0.0; 6 + n_lat]);
        let iters = cfg.iterations.max(1);
        for it in 0..iters {
            let progress = it as f64 / (iters - 1).max(1) as f64;
            let sigma = cfg.sigma_m2[0] * (cfg.sigma_m2[1] / cfg.sigma_m2[0]).powf(progress);
            // Draw the rays (Efraimidis–Spirakis weighted sampling without replacement).
            let m = cfg.rays_per_iteration.min(self.rays.len());
            let (alpha, tau) = if cfg.edge_sampling {
                (
                    cfg.edge_mix * progress,
                    cfg.edge_tau_px[0] + (cfg.edge_tau_px[1] - cfg.edge_tau_px[0]) * progress,
                )
            } else {
                (0.0, 1.0)
            };
            keys.clear();
            for (i, &e) in e_all.iter().enumerate() {
                let w = (1.0 - alpha) + alpha * (-e / tau).exp();
                let u: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
                keys.push((u.ln() / w, i));
            }
            if m < keys.len() {
                keys.select_nth_unstable_by(m, |a, b| b.0.total_cmp(&a.0));
                keys.truncate(m);
            }
            keys.sort_by_key(|k| k.1);
            idx.clear();
            idx.extend(keys.iter().map(|k| k.1));
            self.rays.select_into(&idx, &mut sub);
            target.clear();
            target.extend(idx.iter().map(|&i| target_all[i]));

            let at = Tangent {
                translation: &st.translation,
                omega: &omega,
                base: &base,
                latent: &st.latent,
            };
            let batch = Batch {
                rays: &sub,
                target: &target,
                sigma_m2: sigma,
            };
            let (loss, _) = self.loss_grad(&mut ws, &at, &batch, cfg, Some(&mut g))?;
            if !loss.is_finite() || g.iter().any(|x| !x.is_finite()) {
                return Ok(None);
            }
            curve.push(loss);
            adam.step(&g, &lr, 1.0, &mut step);
            // Learning rates decay by cosine to 10 %.
            let decay = CosineDecay { floor: 0.1 }.at(progress);
            st.translation -= Vector3::new(step[0], step[1], step[2]) * decay;
            omega -= Vector3::new(step[3], step[4], step[5]) * decay;
            for k in 0..n_lat {
                st.latent[k] -= step[6 + k] * decay;
            }
        }
        st.rotation = axis_angle_to_matrix(&omega) * base;
        Ok(Some((st, curve)))
    }
}

/// Buffers of [`HumanProblem::loss_grad`], reused across steps.
pub struct Scratch {
    shaped: irmirror_body::ShapedBody<f64>,
    posed: irmirror_body::PosedBody<f64>,
    renderer: Option<SoftRenderer<f64>>,
    occ_grad: OccupancyGrad<f64>,
    body_grad: BodyGrad<f64>,
    d_value: Vec<f64>,
}

/// Fits the person: every initialisation in parallel, best first, distinct top-k.
pub fn fit_human(
    problem: &HumanProblem<'_>,
    cfg: &HumanConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<(HumanFit, Vec<HumanState>), ReconError> {
    let inits = problem.initial_states(cfg, seed)?;
    let edge_dist = edge_distance(problem.mask);
    type Run = Option<(usize, HumanState, Vec<f64>)>;
    let results: Vec<Result<Run, ReconError>> = inits
        .par_iter()
        .enumerate()
        .map(|(k, init)| {
            let r = problem.run(
                init,
                cfg,
                &edge_dist,
                seed.wrapping_mul(1000).wrapping_add(k as u64),
            )?;
            progress(k);
            Ok(r.map(|(s, c)| (k, s, c)))
        })
        .collect();
    let mut done = Vec::new();
    let mut diverged = 0;
    for r in results {
        match r? {
            Some(x) => done.push(x),
            None => diverged += 1,
        }
    }
    if done.is_empty() {
        return Err(ReconError::Diverged {
            stage: "human fit",
            runs: diverged,
        });
    }
    let mut scored: Vec<(Hypothesis, HumanState)> = done
        .into_par_iter()
        .map(|(k, st, curve)| {
            let (loss, iou) = problem.full_loss(&st, cfg)?;
            let h = Hypothesis {
                init: k,
                translation_m: st.translation.into(),
                root_rotvec_rad: matrix_to_axis_angle(&st.rotation).into(),
                latent: st.latent.clone(),
                loss,
                soft_iou: iou,
                loss_curve: curve,
            };
            Ok((h, st))
        })
        .collect::<Result<_, ReconError>>()?;
    scored.sort_by(|a, b| a.0.loss.total_cmp(&b.0.loss));
    let mut kept: Vec<(Hypothesis, HumanState)> = Vec::new();
    for (h, s) in scored {
        let distinct = kept.iter().all(|(_, k)| {
            let far = (k.translation - s.translation).norm() > 0.25;
            let turned = (k.rotation.transpose() * s.rotation).trace()
                < 1.0 + 2.0 * 45f64.to_radians().cos();
            far || turned
        });
        if distinct && kept.len() < cfg.top_k.max(1) {
            kept.push((h, s));
        }
    }
    let mask_rays = problem
        .rays
        .pixel
        .iter()
        .filter(|&&p| problem.mask.data[p as usize])
        .count();
    let (hyps, states): (Vec<Hypothesis>, Vec<HumanState>) = kept.into_iter().unzip();
    Ok((
        HumanFit {
            hypotheses: hyps,
            diverged,
            rays: problem.rays.len(),
            mask_rays,
        },
        states,
    ))
}
