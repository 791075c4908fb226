//! The stage-2 loss and its gradient, and one hypothesis' Adam run.

use super::edge::{EdgeSampler, curriculum_weights};
use super::{Batch, HumanConfig, HumanProblem, HumanState, ROOT_PARAMS, Tangent};
use crate::ReconError;
use irmirror_body::Pose;
use irmirror_body::model::OutputGrads;
use irmirror_capture::Image;
use irmirror_geom::optim::{Adam, AdamParams, CosineDecay};
use irmirror_geom::rotation::{axis_angle_to_matrix, axis_angle_to_matrix_vjp};
use irmirror_render::hard::first_hit;
use irmirror_render::occupancy::{
    Culling, Occupancy, OccupancyParams, SoftRenderer, soft_iou_weighted,
};
use irmirror_render::reflect::ReflectedRays;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::observe::Selection;
use super::radiometric::{REGIONS, Radiometry, Scalars, TermInput};
use super::scratch::Scratch;

/// IRLS rounds of the radiometric scalars' solve per loss evaluation (from the priors' means;
/// each round solves its weighted least squares exactly). The gradient holds the scalars at
/// their optimum (envelope theorem): the FD test checks what the rounds leave.
const SCALAR_SWEEPS: usize = 20;

impl HumanProblem<'_> {
    /// The pose of a state (36 rotations; root first).
    pub fn pose(&self, st: &HumanState) -> Result<Pose<f64>, ReconError> {
        Ok(Pose {
            rotations: super::joint_rotations(self.prior, st)?,
            translation: st.translation,
        })
    }

    /// The stage-2 loss of the body at `at` on `batch`, and the soft IoU. With `grad` (length
    /// [`ROOT_PARAMS`] + latent + residual), writes `∂L/∂(t, ω, h, latent, residual)` there.
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
            height,
            latent,
            residual,
        } = *at;
        let Batch { rays, sigma_m2, .. } = *batch;
        let rotation = axis_angle_to_matrix(omega) * base;
        self.set_height(ws, height)?;
        let tape = self.prior.decode_taped(latent)?;
        let mut rotations = tape.rotations.clone();
        // The decoding itself, for the residual's backward.
        let decoded = (!residual.is_empty()).then_some(&tape.rotations);
        rotations[0] = rotation;
        super::compose_residual(&mut rotations[1..], residual)?;
        let pose = Pose {
            rotations,
            translation: *t,
        };
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
        let (l_data, iou, scalars) =
            self.data_term(r, &occ, batch, cfg, &mut ws.meet, &mut ws.d_value);
        ws.scalars = scalars;
        ws.data = l_data;
        let prior: f64 = latent.iter().map(|x| x * x).sum();
        let prior_residual: f64 = residual.iter().map(|x| x * x).sum();
        let up = self.up.normalize();
        let mut loss = l_data
            + cfg.w_prior * prior
            + cfg.w_residual * prior_residual
            + cfg.w_upright * (1.0 - (rotation * Vector3::z()).dot(&up));
        let facing = self.facing_prior(&rotation, t, cfg);
        if let Some((p, _, _)) = facing {
            loss += p;
        }
        let [h_mean, h_sigma] = cfg.height_prior;
        let e_h = (height - h_mean) / h_sigma;
        loss += cfg.w_height * e_h * e_h;
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
        if !ws.meet.hits.is_empty() {
            self.mix_backward(rays, &ws.meet, r.vertices(), &mut ws.occ_grad.vertices);
        }
        let bg = &mut ws.body_grad;
        self.model.backward_pose(
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
        if let Some((_, d_rotation, d_translation)) = facing {
            bg.rotations[0] += d_rotation;
            bg.translation += d_translation;
        }
        let d_omega = axis_angle_to_matrix_vjp(omega, &(bg.rotations[0] * base.transpose()));
        // R_j = D_j exp(δ_j): ∂L/∂δ_j from ∂L/∂exp(δ_j) = D_jᵀ G_j, and ∂L/∂D_j = G_j exp(δ_j)ᵀ.
        let n_lat = latent.len();
        if let Some(decoded) = &decoded {
            let g_res = &mut g[ROOT_PARAMS + n_lat..];
            for (j, w) in residual.chunks_exact(3).enumerate() {
                let w = Vector3::new(w[0], w[1], w[2]);
                let (d, gj) = (&decoded[j + 1], bg.rotations[j + 1]);
                let d_w = axis_angle_to_matrix_vjp(&w, &(d.transpose() * gj))
                    + w * (2.0 * cfg.w_residual);
                g_res[3 * j..3 * j + 3].copy_from_slice(d_w.as_slice());
                bg.rotations[j + 1] = gj * axis_angle_to_matrix(&w).transpose();
            }
        }
        let d_lat = self.prior.vjp_taped(&tape, &bg.rotations)?;
        g[..3].copy_from_slice(bg.translation.as_slice());
        g[3..6].copy_from_slice(d_omega.as_slice());
        g[6] = ws.posed.rest_grad_along(ws.height_direction()) + 2.0 * cfg.w_height * e_h / h_sigma;
        for (k, (gk, dk)) in g[ROOT_PARAMS..].iter_mut().zip(&d_lat).enumerate() {
            *gk = dk + cfg.w_prior * 2.0 * latent[k];
        }
        Ok((loss, iou))
    }

    /// The facing prior of a root at `t` turned by `rotation` ([`HumanConfig::w_facing`]):
    /// `w (1 − cos θ)` with `cos θ = f̂·d̂`, `f = −Π R ŷ` the body's front (Anny's −Y) and
    /// `d = Π (c − t)` the way to the objects' centre `c`, both projected onto the horizontal
    /// plane (`Π = I − n nᵀ`), and its gradients `∂/∂R = w g_f ŷᵀ`, `∂/∂t = w g_d` with
    /// `g_f = (d̂ − cos θ f̂) / |f|`, `g_d = (f̂ − cos θ d̂) / |d|` (both in the plane). `None`
    /// where it is off or undefined (a root above the centre, a body lying along the up axis).
    fn facing_prior(
        &self,
        rotation: &Matrix3<f64>,
        t: &Vector3<f64>,
        cfg: &HumanConfig,
    ) -> Option<(f64, Matrix3<f64>, Vector3<f64>)> {
        if !self.faces_objects || cfg.w_facing <= 0.0 {
            return None;
        }
        let n = self.up.normalize();
        let flat = |v: Vector3<f64>| v - n * n.dot(&v);
        let f = flat(-(rotation * Vector3::y()));
        let d = flat(self.objects_centre - t);
        let (nf, nd) = (f.norm(), d.norm());
        if nf < 1e-9 || nd < 1e-9 {
            return None;
        }
        let (fh, dh) = (f / nf, d / nd);
        let c = fh.dot(&dh);
        let w = cfg.w_facing;
        let g_f = (dh - fh * c) / nf;
        let g_d = (fh - dh * c) / nd;
        Some((w * (1.0 - c), g_f * Vector3::y().transpose() * w, g_d * w))
    }

    /// The data term on `batch` given the occupancy `occ` of `r`'s mesh: `(D, soft IoU,
    /// radiometric scalars)`, `∂D/∂occupancy` in `d_value` and, for the radiometric term, where
    /// each ray meets the body and `∂D/∂β` in `meet`. `D` is `1 − soft IoU`, or the radiometric
    /// term when it is on and the batch carries the rise.
    fn data_term(
        &self,
        r: &SoftRenderer<f64>,
        occ: &Occupancy<f64>,
        batch: &Batch<'_>,
        cfg: &HumanConfig,
        meet: &mut Meet,
        d_value: &mut Vec<f64>,
    ) -> (f64, f64, Option<Scalars>) {
        let Batch {
            rays,
            target,
            weight,
            rise,
            ..
        } = *batch;
        let (l_iou, iou) = soft_iou_weighted(
            &occ.value,
            |i| target[i],
            |i| weight.map_or(1.0, |w| w[i]),
            0.0,
            d_value,
        );
        let (Some(rad), Some(rise)) = (self.radiometric(cfg), rise) else {
            meet.hits.clear();
            return (l_iou, iou, None);
        };
        // The radiometric term replaces the mask's (module `radiometric`).
        let keep = meet.frozen && meet.hits.len() == rays.len();
        meet.hits.resize(rays.len(), RayHit::default());
        let (verts, tris) = (r.vertices(), r.triangles());
        meet.hits.par_iter_mut().enumerate().for_each(|(i, h)| {
            let (o, d) = (&rays.origin[i], &rays.dir[i]);
            if !keep {
                *h = match first_hit(r.bvh(), verts, tris, o, d) {
                    Some((_, t)) => RayHit {
                        tri: t,
                        verts: tris[t as usize],
                        w: [1.0, 0.0, 0.0],
                    },
                    // A miss takes the shares at the nearest point (the silhouette's side),
                    // without a gradient: its occupancy is below ½.
                    None => occ
                        .nearest
                        .get(i)
                        .copied()
                        .flatten()
                        .map_or(RayHit::default(), |n| RayHit {
                            tri: NO_HIT,
                            verts: n.vertices,
                            w: n.pair.bary,
                        }),
                };
            }
            if h.tri != NO_HIT
                && let Some((u, v, _)) = plane_hit(o, d, &h.verts.map(|k| verts[k as usize]))
            {
                h.w = [1.0 - u - v, u, v];
            }
        });
        let vreg = &rad.vertex_region;
        meet.mix.clear();
        meet.mix.extend(meet.hits.iter().map(|h| {
            let mut m = [0.0; REGIONS];
            for (k, w) in h.verts.iter().zip(h.w) {
                m[vreg[*k as usize].index()] += w;
            }
            m
        }));
        let input = TermInput {
            occ: &occ.value,
            mix: &meet.mix,
            rise,
            share: rise
                .weight
                .map_or(rise.rise_k.len() as f64, |w| w.iter().sum::<f64>())
                / rad.pixels().max(1) as f64,
        };
        let mut scalars = rad.prior_scalars(&cfg.radiometric);
        rad.solve_scalars(&input, &cfg.radiometric, &mut scalars, SCALAR_SWEEPS);
        let l = rad.loss(
            &input,
            &cfg.radiometric,
            &scalars,
            Some((d_value, &mut meet.d_mix)),
        );
        (l, iou, Some(scalars))
    }

    /// Adds `∂D/∂vertices` through the shares `β` of the rays that hit a triangle on a region
    /// border (the hit point's barycentric weights move with the triangle).
    fn mix_backward(
        &self,
        rays: &ReflectedRays<f64>,
        meet: &Meet,
        verts: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) {
        let Some(rad) = self.radiometry else { return };
        let vreg = &rad.vertex_region;
        for (i, h) in meet.hits.iter().enumerate() {
            if h.tri == NO_HIT {
                continue;
            }
            let [ra, rb, rc] = h.verts.map(|k| vreg[k as usize].index());
            if ra == rb && ra == rc {
                continue;
            }
            // β = w0 1[a] + u 1[b] + v 1[c], w0 = 1 − u − v.
            let dm = &meet.d_mix[i];
            let (gu, gv) = (dm[rb] - dm[ra], dm[rc] - dm[ra]);
            let tri = h.verts.map(|k| verts[k as usize]);
            let Some((_, _, m)) = plane_hit(&rays.origin[i], &rays.dir[i], &tri) else {
                continue;
            };
            // M (u, v, t) = o − a ⇒ ∂L/∂v_k = −w_k M⁻ᵀ (∂L/∂u, ∂L/∂v, 0).
            let Some(lambda) = m
                .transpose()
                .try_inverse()
                .map(|mi| mi * Vector3::new(gu, gv, 0.0))
            else {
                continue;
            };
            for (k, w) in h.verts.iter().zip(h.w) {
                out[*k as usize] -= lambda * w;
            }
        }
    }

    /// Targets of all rays (1 in the mask).
    pub fn targets(&self) -> Vec<f64> {
        self.rays
            .pixel
            .iter()
            .map(|&p| f64::from(u8::from(self.mask.data[p as usize])))
            .collect()
    }

    /// The data term of any body mesh with the body's topology (depth frame; e.g. the true
    /// body, which the prior need not represent): `(D, soft IoU)` on all rays at the final σ,
    /// as the hypotheses' `data_loss` is scored. The failure diagnosis compares it with the
    /// fit's.
    pub fn mesh_data_loss(&self, vertices: &[Vector3<f64>], cfg: &HumanConfig) -> (f64, f64) {
        let (d, iou, _, _) = self.mesh_eval(vertices, cfg);
        (d, iou)
    }

    /// The thermal rise the radiometric model predicts for every pixel of its rays (K) at
    /// state `st`, with the scalars fitted there: `(pixel index, rise)`; `None` when that term
    /// is off.
    pub fn predicted_rise(
        &self,
        st: &HumanState,
        cfg: &HumanConfig,
    ) -> Result<Option<Vec<(u32, f64)>>, ReconError> {
        let Some(rad) = self.radiometric(cfg) else {
            return Ok(None);
        };
        let posed = super::posed_body(self.model, self.prior, st)?;
        let (_, _, Some(s), (meet, occ)) = self.mesh_eval(&posed.vertices, cfg) else {
            return Ok(None);
        };
        let input = TermInput {
            occ: &occ,
            mix: &meet.mix,
            rise: rad.rise(),
            share: 1.0,
        };
        Ok(Some(
            rad.pixel
                .iter()
                .copied()
                .zip(rad.predict(&input, &s))
                .collect(),
        ))
    }

    /// The rise the radiometric model predicts for a body mesh (its scalars fitted there),
    /// summed over the pixels per region, K·px (`Region::ALL`'s order): which parts of the
    /// body the reflection shows — a face, bare forearms, or clothing alone, where front and
    /// back look alike. `None` when that data term is off.
    pub fn region_rise(
        &self,
        vertices: &[Vector3<f64>],
        cfg: &HumanConfig,
    ) -> Option<[f64; REGIONS]> {
        let rad = self.radiometric(cfg)?;
        let (_, _, s, (meet, occ)) = self.mesh_eval(vertices, cfg);
        let input = TermInput {
            occ: &occ,
            mix: &meet.mix,
            rise: rad.rise(),
            share: 1.0,
        };
        Some(rad.region_rise(&input, &s?))
    }

    /// A body mesh (the model's topology) on every ray at the final σ: the data term, the soft
    /// IoU, the radiometric scalars, and where each ray met the body with its occupancy.
    fn mesh_eval(
        &self,
        vertices: &[Vector3<f64>],
        cfg: &HumanConfig,
    ) -> (f64, f64, Option<Scalars>, (Meet, Vec<f64>)) {
        let renderer = SoftRenderer::new(vertices, &self.model.asset.faces);
        let params = OccupancyParams {
            sigma_m2: cfg.sigma_m2[1],
            aggregation: cfg.aggregation,
            ..OccupancyParams::default()
        };
        let occ = renderer.forward(self.rays, &params, Culling::Bvh);
        let target = self.targets();
        let batch = self.full_batch(&target, cfg);
        let mut meet = Meet::default();
        let (d, iou, scalars) =
            self.data_term(&renderer, &occ, &batch, cfg, &mut meet, &mut Vec::new());
        (d, iou, scalars, (meet, occ.value))
    }

    /// Every ray, with `target` = [`Self::targets`], at the final σ.
    pub(crate) fn full_batch<'b>(&'b self, target: &'b [f64], cfg: &HumanConfig) -> Batch<'b> {
        Batch {
            rays: self.rays,
            target,
            weight: None,
            rise: self.radiometry.map(Radiometry::rise),
            sigma_m2: cfg.sigma_m2[1],
        }
    }

    /// Loss of a state on all rays at the final σ, and its soft IoU.
    pub fn full_loss(&self, st: &HumanState, cfg: &HumanConfig) -> Result<(f64, f64), ReconError> {
        self.full_eval(st, cfg).map(|e| (e.loss, e.soft_iou))
    }

    /// [`Self::full_loss`] with its data term alone and the radiometric scalars fitted there.
    pub fn full_eval(&self, st: &HumanState, cfg: &HumanConfig) -> Result<FullEval, ReconError> {
        let target = self.targets();
        let batch = self.full_batch(&target, cfg);
        let mut ws = self.scratch()?;
        let (loss, soft_iou) = self.score(&mut ws, st, &batch, cfg)?;
        Ok(FullEval {
            loss,
            data: ws.data,
            soft_iou,
            scalars: ws.scalars,
        })
    }

    /// The radiometric observations when that data term is on.
    pub fn radiometric(&self, cfg: &HumanConfig) -> Option<&Radiometry> {
        self.radiometry.filter(|_| cfg.radiometric.enabled)
    }

    /// Loss of a state on `batch`, and its soft IoU (no gradient).
    pub fn score(
        &self,
        ws: &mut Scratch,
        st: &HumanState,
        batch: &Batch<'_>,
        cfg: &HumanConfig,
    ) -> Result<(f64, f64), ReconError> {
        self.set_build(ws, &st.build)?;
        let at = Tangent {
            translation: &st.translation,
            omega: &Vector3::zeros(),
            base: &st.rotation,
            height: st.height,
            latent: &st.latent,
            residual: &st.residual,
        };
        self.loss_grad(ws, &at, batch, cfg, None)
    }

    /// The rays that can meet the body of state `st` or see the mask (ascending indices): a
    /// mask ray, or one whose half-line passes within `margin` (m) of a body triangle's box.
    pub fn active_rays(
        &self,
        st: &HumanState,
        margin: f64,
        out: &mut Vec<usize>,
    ) -> Result<(), ReconError> {
        let body = super::posed_body(self.model, self.prior, st)?;
        let bvh = irmirror_render::bvh::Bvh::build(&body.vertices, &self.model.asset.faces);
        out.clear();
        // Rayon's collect keeps the order: ascending.
        out.par_extend(
            (0..self.rays.len())
                .into_par_iter()
                .with_min_len(4096)
                .filter(|&i| {
                    self.mask.data[self.rays.pixel[i] as usize] || {
                        let inv = irmirror_render::bvh::inverse_dir(&self.rays.dir[i]);
                        bvh.any_near_ray(&self.rays.origin[i], &inv, margin, |_| true)
                    }
                }),
        );
        Ok(())
    }

    /// Runs one hypothesis from `init` for `cfg.iterations` steps on the rays `draw` gives;
    /// returns the final state (on a fixed batch at one blur, the best state evaluated, the
    /// final one included) and the per-step loss, or `None` if it diverged.
    pub fn run(
        &self,
        init: &HumanState,
        cfg: &HumanConfig,
        draw: Draw<'_>,
        seed: u64,
    ) -> Result<Option<(HumanState, Vec<f64>)>, ReconError> {
        let mut ws = self.scratch()?;
        self.set_build(&mut ws, &init.build)?;
        let mut st = init.clone();
        let base = st.rotation;
        let mut omega = Vector3::zeros();
        let n_lat = st.latent.len();
        // The residual is stepped when its rate is on (from zero where a state has none).
        if cfg.lr_residual > 0.0 && st.residual.is_empty() {
            st.residual = vec![0.0; super::RESIDUAL_PARAMS];
        }
        let n_res = st.residual.len();
        let n = ROOT_PARAMS + n_lat + n_res;
        let mut adam = Adam::new(n, AdamParams::default());
        let mut lr = vec![cfg.lr_translation; 3];
        lr.extend([cfg.lr_rotation; 3]);
        lr.push(cfg.lr_height);
        lr.extend(vec![cfg.lr_latent; n_lat]);
        lr.extend(vec![cfg.lr_residual; n_res]);
        let mut rng = irmirror_geom::rng::seeded(seed, 31);
        // What a step draws: the radiometric term's pixels (with every ray their predictions
        // weigh), else rays.
        let rad = self.radiometric(cfg);
        let units = rad.map_or(self.rays.len(), |r| r.pixels());
        let unit_pixel = |u: usize| rad.map_or(self.rays.pixel[u], |r| r.pixel[u]);
        // The active set (mask mode): the mask's rays and those passing within
        // `active_margin_m` of the body, refreshed every `active_every` steps. A ray outside
        // both has occupancy ≈ 0 and target 0, so it adds nothing to the soft IoU's sums nor
        // to its gradient: drawing from the active set alone is the same estimator with more
        // of the rays that carry information (on a car door 2 % of a uniform draw meets the
        // mask).
        let active_on = rad.is_none() && cfg.active_margin_m > 0.0;
        let mut active: Vec<usize> = Vec::new();
        // Edge draws: the sampler (over every unit, or over the active set from its first
        // refresh on) and every ray's target (a fixed batch brings its own).
        let mut edge = match draw {
            Draw::Edge(_) if active_on => Some((EdgeSampler::new(&[]), self.targets())),
            Draw::Edge(edge_dist) => Some((
                EdgeSampler::new(
                    &(0..units)
                        .map(|u| edge_dist.data[unit_pixel(u) as usize])
                        .collect::<Vec<f64>>(),
                ),
                self.targets(),
            )),
            Draw::Fixed(_) | Draw::FixedEdge(..) => None,
        };
        let mut curriculum = Vec::new();
        let (mut sub, mut target, mut idx) = (ReflectedRays::default(), Vec::new(), Vec::new());
        let (mut drawn, mut selection) = (Vec::new(), Selection::default());
        let mut curve = Vec::with_capacity(cfg.iterations);
        let (mut g, mut step) = (vec![0.0; n], vec![0.0; n]);
        // Draw a fraction of the rays even when the budget would take them all: otherwise a
        // small capture sees every ray each step and edge sampling changes nothing. The ray
        // budget in units (the same number with one ray per unit).
        let m = (cfg.rays_per_iteration * units)
            .div_ceil(self.rays.len().max(1))
            .min((units as f64 * cfg.max_ray_fraction).ceil() as usize)
            .max(1);
        let iters = cfg.iterations.max(1);
        // On one fixed batch at one blur every step evaluates the same loss, so the best state
        // evaluated is kept (the polish starts converged: Adam's first steps can raise it).
        let fixed_loss = matches!(draw, Draw::Fixed(_)) && cfg.sigma_m2[0] == cfg.sigma_m2[1];
        let mut best: Option<(f64, HumanState)> = None;
        for it in 0..iters {
            let progress = it as f64 / (iters - 1).max(1) as f64;
            let sigma = cfg.sigma_m2[0] * (cfg.sigma_m2[1] / cfg.sigma_m2[0]).powf(progress);
            let batch = match draw {
                Draw::Fixed(fixed) => Batch {
                    sigma_m2: sigma,
                    ..fixed
                },
                Draw::FixedEdge(fixed, edge_px) => {
                    let (alpha, tau) = cfg.edge_schedule(progress);
                    curriculum_weights(fixed.weight, edge_px, alpha, tau, &mut curriculum);
                    Batch {
                        weight: Some(&curriculum),
                        sigma_m2: sigma,
                        ..fixed
                    }
                }
                Draw::Edge(edge_dist) => {
                    // Draw the rays (weighted sampling without replacement, `EdgeSampler`).
                    let (alpha, tau) = cfg.edge_schedule(progress);
                    if let Some((sampler, target_all)) = edge.as_mut() {
                        match rad {
                            None if active_on => {
                                if it % cfg.active_every.max(1) == 0 {
                                    let now = HumanState {
                                        rotation: axis_angle_to_matrix(&omega) * base,
                                        ..st.clone()
                                    };
                                    self.active_rays(&now, cfg.active_margin_m, &mut active)?;
                                    *sampler = EdgeSampler::new(
                                        &active
                                            .iter()
                                            .map(|&i| edge_dist.data[self.rays.pixel[i] as usize])
                                            .collect::<Vec<f64>>(),
                                    );
                                }
                                let m_active = m
                                    .min((active.len() as f64 * cfg.max_ray_fraction).ceil()
                                        as usize)
                                    .max(1);
                                sampler.draw(alpha, tau, m_active, &mut rng, &mut drawn);
                                idx.clear();
                                idx.extend(drawn.iter().map(|&k| active[k]));
                                idx.sort_unstable();
                            }
                            Some(r) => {
                                sampler.draw(alpha, tau, m, &mut rng, &mut drawn);
                                r.select(&drawn, &mut selection);
                                idx.clone_from(&selection.rays);
                            }
                            None => sampler.draw(alpha, tau, m, &mut rng, &mut idx),
                        }
                        target.clear();
                        target.extend(idx.iter().map(|&i| target_all[i]));
                    }
                    self.rays.select_into(&idx, &mut sub);
                    Batch {
                        rays: &sub,
                        target: &target,
                        weight: None,
                        rise: rad.map(|_| selection.rise(None)),
                        sigma_m2: sigma,
                    }
                }
            };
            let at = Tangent {
                translation: &st.translation,
                omega: &omega,
                base: &base,
                height: st.height,
                latent: &st.latent,
                residual: &st.residual,
            };
            let (loss, _) = self.loss_grad(&mut ws, &at, &batch, cfg, Some(&mut g))?;
            if !loss.is_finite() || g.iter().any(|x| !x.is_finite()) {
                return Ok(None);
            }
            curve.push(loss);
            if fixed_loss && best.as_ref().is_none_or(|(b, _)| loss < *b) {
                let rotation = axis_angle_to_matrix(&omega) * base;
                best = Some((
                    loss,
                    HumanState {
                        rotation,
                        ..st.clone()
                    },
                ));
            }
            adam.step(&g, &lr, 1.0, &mut step);
            // Learning rates decay by cosine to 10 %.
            let decay = CosineDecay { floor: 0.1 }.at(progress);
            st.translation -= Vector3::new(step[0], step[1], step[2]) * decay;
            omega -= Vector3::new(step[3], step[4], step[5]) * decay;
            // The slider is a phenotype value: kept in [0, 1].
            st.height = (st.height - step[6] * decay).clamp(0.0, 1.0);
            for k in 0..n_lat {
                st.latent[k] -= step[ROOT_PARAMS + k] * decay;
            }
            for k in 0..n_res {
                st.residual[k] -= step[ROOT_PARAMS + n_lat + k] * decay;
            }
        }
        st.rotation = axis_angle_to_matrix(&omega) * base;
        if let (Some((b, kept)), Draw::Fixed(batch)) = (best, draw) {
            let batch = Batch {
                sigma_m2: cfg.sigma_m2[1],
                ..batch
            };
            let (last, _) = self.score(&mut ws, &st, &batch, cfg)?;
            if !(last.is_finite() && last <= b) {
                return Ok(Some((kept, curve)));
            }
        }
        Ok(Some((st, curve)))
    }
}

/// Where [`HumanProblem::run`] takes each step's rays from.
#[derive(Clone, Copy, Debug)]
pub enum Draw<'a> {
    /// Drawn afresh each step by edge sampling (or uniformly, when `cfg.edge_sampling` is off),
    /// given each pixel's distance to the mask's edge ([`super::edge_distance`]).
    Edge(&'a Image<f64>),
    /// The same (weighted) batch every step; its σ is replaced by the schedule's.
    Fixed(Batch<'a>),
    /// The same batch every step, its mask weights multiplied by edge sampling's curriculum
    /// at that step ([`curriculum_weights`]; per ray, the pixel distance to the mask's edge):
    /// a fixed batch that holds every ray of a small capture draws nothing, so without these
    /// weights edge sampling would leave its loss as it is.
    FixedEdge(Batch<'a>, &'a [f64]),
}

/// No triangle hit (the ray passes the body).
const NO_HIT: u32 = u32::MAX;

/// Where a ray meets the body: the triangle it hits first ([`NO_HIT`] for a miss) and the
/// barycentric weights of the point over `verts` (a miss: the nearest point's).
#[derive(Clone, Copy, Debug)]
struct RayHit {
    tri: u32,
    verts: [u32; 3],
    w: [f64; 3],
}

impl Default for RayHit {
    fn default() -> Self {
        Self {
            tri: NO_HIT,
            verts: [0; 3],
            w: [1.0, 0.0, 0.0],
        }
    }
}

/// The radiometric term's per-ray buffers.
#[derive(Debug, Default)]
pub(super) struct Meet {
    hits: Vec<RayHit>,
    /// Region shares `β` per ray.
    mix: Vec<[f64; REGIONS]>,
    /// `∂D/∂β` per ray.
    d_mix: Vec<[f64; REGIONS]>,
    /// Keep `hits`' triangles (see [`Scratch::freeze_hits`]).
    pub(super) frozen: bool,
}

/// Where the line `o + t d` crosses the plane of `tri = [a, b, c]`: `(u, v, M)` with
/// `a + u (b − a) + v (c − a) = o + t d` and `M = [b − a, c − a, −d]`; `None` when parallel.
fn plane_hit(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    [a, b, c]: &[Vector3<f64>; 3],
) -> Option<(f64, f64, Matrix3<f64>)> {
    let m = Matrix3::from_columns(&[b - a, c - a, -d]);
    let x = m.try_inverse()? * (o - a);
    Some((x.x, x.y, m))
}

/// A state scored on every ray at the final σ.
#[derive(Clone, Debug)]
pub struct FullEval {
    /// The loss (data term and priors).
    pub loss: f64,
    /// The data term alone.
    pub data: f64,
    /// Soft IoU with the mask.
    pub soft_iou: f64,
    /// The radiometric scalars (when that term is on).
    pub scalars: Option<Scalars>,
}
