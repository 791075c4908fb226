//! Fitting one object: Adam from several restarts (yaws × starting proportions) on the loss of
//! [`super::loss`], each run's best iterate kept, the best run kept; then, with the learned prior,
//! its latent and placement from the family fit ([`fit_learned`]).

use super::family::{Family, family_mesh};
use super::loss::{Grad, Problem, State};
use super::observation::ObjectObservation;
use super::restart::{HANDLE_RESTARTS, away_restart, handle_restart, height_restart};
use super::silhouette::outline_errors;
use super::{FittedObject, LearnedShape, ObjectConfig};
use crate::ReconError;
use crate::plane::Ground;
use irmirror_geom::Similarity3;
use irmirror_geom::optim::{Adam, AdamParams, CosineDecay, LmParams, levenberg_marquardt};
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_render::sdf::PlacedSdf;
use irmirror_render::shapes::Shape;
use irmirror_sdf::SdfNet;
use irmirror_sdf::placed::{PlacedFitConfig, PlacedObservation, fit_placed};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use std::sync::Arc;

impl Problem<'_> {
    /// Adam from `init`: the best iterate, its loss and the loss curve; `None` when the loss or
    /// its gradient stops being finite.
    fn run(&self, init: State) -> Option<(State, f64, Vec<f64>)> {
        let mut st = init;
        let n_u = self.family.dims();
        let lr_t = self.cfg.lr_translation * self.s0;
        let (lr_r, lr_s, lr_u) = (self.cfg.lr_rotation, self.cfg.lr_scale, self.cfg.lr_shape);
        // Groups: rotation tangent (3), translation (3), log scale, shape (2).
        let lrs = [lr_r, lr_r, lr_r, lr_t, lr_t, lr_t, lr_s, lr_u, lr_u];
        let mut adam = Adam::new(
            9,
            AdamParams {
                eps: 1e-12,
                ..AdamParams::default()
            },
        );
        let schedule = CosineDecay { floor: 0.05 };
        let mut curve = Vec::with_capacity(self.cfg.iterations as usize);
        let iters = self.cfg.iterations.max(1) as usize;
        // The best iterate is kept: the loss is not smooth (rays enter and leave the rendered
        // set, a handle passes behind the body) and Adam's first steps can leave a good start for
        // a worse basin (measured: from the true pose, to 18–36× its loss on 2 of 4 mugs).
        let mut best = (f64::INFINITY, st);
        let mut step = [0.0; 9];
        let mut shape_grad = [0.0; 2];
        for it in 0..iters {
            let mut g = Grad::default();
            let loss = self.eval_pose(&st, &mut g);
            // The shape parameters' gradient by central differences of the whole loss, one
            // parameter per step in turn (the other's from its last turn; all at the first
            // step). Not by the chain rule ([`Problem::eval`]): that misses the rendered depth's
            // jumps where a ray's hit crosses a rim, and a rim's width is how the depth camera
            // sees a wall (measured: a held-out mug's wall 0.073 for 0.120, and a 10-pixel
            // reflection then fell off the fitted mug). In turn rather than both every step:
            // each difference re-traces every rendered ray twice, and two of them were two
            // thirds of stage 1's time.
            for (k, grad) in shape_grad.iter_mut().enumerate().take(n_u) {
                if it == 0 || k == it % n_u {
                    *grad = self.shape_difference(&st, k);
                }
            }
            let flat = [
                g.rot.x,
                g.rot.y,
                g.rot.z,
                g.t.x,
                g.t.y,
                g.t.z,
                g.log_s,
                shape_grad[0],
                shape_grad[1],
            ];
            if !loss.is_finite() || flat.iter().any(|x| !x.is_finite()) {
                tracing::warn!(
                    "{:?} fit diverged at iteration {it} (loss {loss})",
                    self.family
                );
                return None;
            }
            curve.push(loss);
            if loss < best.0 {
                best = (loss, st);
            }
            adam.step(&flat, &lrs, schedule.at_step(it, iters), &mut step);
            // Left perturbation R ← exp(−step) R (the gradient was taken w.r.t. it).
            st.rotation =
                axis_angle_to_matrix(&Vector3::new(-step[0], -step[1], -step[2])) * st.rotation;
            st.translation -= Vector3::new(step[3], step[4], step[5]);
            st.log_scale -= step[6];
            for k in 0..n_u {
                st.u[k] = (st.u[k] - step[7 + k]).clamp(0.0, 1.0);
            }
        }
        let final_loss = self.eval(&st, None);
        curve.push(final_loss);
        if final_loss <= best.0 {
            best = (final_loss, st);
        }
        Some((best.1, best.0, curve))
    }
}

impl Problem<'_> {
    /// ∂loss/∂u_k by a central difference of the whole loss (step 1e-3, one-sided at a bound).
    fn shape_difference(&self, st: &State, k: usize) -> f64 {
        let h = 1e-3;
        let (mut a, mut b) = (*st, *st);
        a.u[k] = (a.u[k] + h).min(1.0);
        b.u[k] = (b.u[k] - h).max(0.0);
        (self.eval(&a, None) - self.eval(&b, None)) / (a.u[k] - b.u[k]).max(1e-12)
    }

    /// Levenberg–Marquardt from `st` on the loss's residual form (its full Jacobian, see
    /// [`Problem::residuals`]): the polish after Adam. Adam steps every
    /// coordinate at its own rate, so it wanders along the loss's nearly flat directions (a
    /// bowl's wall trades against its cut and scale) and stops wherever its schedule ends; a
    /// curvature-aware step walks down them (measured on a held-out bowl: Adam ended at the
    /// wall's upper bound, 2× the true wall, with 4× the loss of the true shape). Returns the
    /// state and its loss (the caller keeps it only when lower than `st`'s).
    fn polish(&self, st: State) -> (State, f64) {
        let n = 7 + self.family.dims();
        let m = self.residual_count();
        let retract = |s: &State, d: &[f64]| {
            let mut out = *s;
            out.rotation = axis_angle_to_matrix(&Vector3::new(d[0], d[1], d[2])) * s.rotation;
            out.translation += Vector3::new(d[3], d[4], d[5]) * self.s0;
            out.log_scale += d[6];
            for k in 0..n - 7 {
                out.u[k] = (s.u[k] + d[7 + k]).clamp(0.0, 1.0);
            }
            out
        };
        let eval = |s: &State, r: &mut [f64], j: Option<&mut [f64]>| self.residuals(s, r, j);
        let mut out = st;
        let report = levenberg_marquardt(
            &mut out,
            n,
            m,
            LmParams {
                max_iterations: self.cfg.polish_iterations as usize,
                initial_damping: 1e-2,
                relative_tolerance: 1e-6,
            },
            eval,
            retract,
        );
        (out, report.final_cost)
    }
}

/// A rotation taking +Y to `n`, then turned by `yaw` about `n`.
pub(super) fn upright(n: &Vector3<f64>, yaw: f64) -> Matrix3<f64> {
    let y = n.normalize();
    let helper = if y.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let x = (helper - y * helper.dot(&y)).normalize();
    let z = x.cross(&y);
    let base = Matrix3::from_columns(&[x, y, z]);
    base * axis_angle_to_matrix(&Vector3::new(0.0, yaw, 0.0))
}

/// Fits one object of `family` to `obs`, standing on the `ground`'s support plane where one was
/// found (upright along its up otherwise). Fails only when every restart diverges.
pub fn fit_family(
    family: Family,
    obs: &ObjectObservation,
    ground: &Ground,
    cfg: &ObjectConfig,
) -> Result<FittedObject, ReconError> {
    let n = ground.n();
    let centroid =
        obs.surface.iter().fold(Vector3::zeros(), |a, p| a + p) / obs.surface.len() as f64;
    // Size from the spread of the points across the plane.
    let horizontal = |p: &Vector3<f64>| {
        let d = p - centroid;
        (d - n * n.dot(&d)).norm()
    };
    let mut spread: Vec<f64> = obs.surface.iter().map(horizontal).collect();
    spread.sort_by(f64::total_cmp);
    let r95 = spread[(spread.len() as f64 * 0.95) as usize].max(1e-3);
    // A category with a size prior starts at its typical size: a car's side overflows the
    // image, so the spread of its points says little (starting at half size, before the IMU
    // up, the fit stayed 6–20 % small).
    let s0 = match family.size_prior() {
        Some((mean, _)) => mean.exp(),
        None => r95 / 0.85,
    };
    let problem = Problem {
        family,
        obs,
        ground,
        s0,
        cfg,
    };
    let starts = family.shape_starts();
    let inits: Vec<State> = family
        .yaws(cfg.restarts)
        .into_iter()
        .flat_map(|yaw| starts.iter().map(move |&u| (yaw, u)))
        .map(|(yaw, u)| {
            let rotation = upright(&n, yaw);
            let shape = family.shape(&u);
            // Centre over the centroid, base on the plane.
            let over = match &ground.plane {
                Some(plane) => centroid - n * plane.height(&centroid),
                None => centroid - n * s0 * shape.base_y().abs(),
            };
            let mut translation = over - rotation * Vector3::new(0.0, shape.base_y(), 0.0) * s0;
            // The points are the near side of the object: push it away from the camera
            // (across the plane) until their centroid is on its surface, not inside it — a
            // car centred on its door starts with its near half in front of the camera's
            // view of the door (sphere tracing from the inside: each step moves by |d|).
            let sdf = shape.sdf();
            let away = (centroid - n * n.dot(&centroid))
                .try_normalize(1e-9)
                .unwrap_or_else(Vector3::z);
            for _ in 0..64 {
                let d = s0 * sdf.distance(&(rotation.tr_mul(&(centroid - translation)) / s0));
                if d >= -1e-3 * s0 {
                    break;
                }
                translation += away * -d;
            }
            State {
                rotation,
                translation,
                log_scale: s0.ln(),
                u,
            }
        })
        .collect();
    let restarts = inits.len();
    let mut runs: Vec<(State, f64, Vec<f64>)> = inits
        .into_par_iter()
        .filter_map(|s| problem.run(s))
        .collect();
    for (k, (st, loss, _)) in runs.iter().enumerate() {
        let x = st.rotation * Vector3::x();
        tracing::debug!(
            "{family:?} restart {k}: loss {loss:.4e}, object +X {:.3} {:.3} {:.3}, scale {:.4} m",
            x.x,
            x.y,
            x.z,
            st.log_scale.exp()
        );
    }
    let polish = |run: &mut (State, f64, Vec<f64>)| {
        if cfg.polish_iterations > 0 {
            let (polished, l) = problem.polish(run.0);
            if l < run.1 {
                (run.0, run.1) = (polished, l);
            }
            run.2.push(run.1);
        }
    };
    runs.par_iter_mut().for_each(polish);
    // A mug's handle restarts, from each of the three best polished runs (from the best alone,
    // a tuning-set mug stayed 24 % too large); the lowest loss then decides: with them, the
    // handle side wins (seed 15 of the tabletop-wide regime: 156.7° → 0.3°).
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|&a, &b| runs[a].1.total_cmp(&runs[b].1));
    // And one restart from the best run with its height set to the observed top's (below).
    let extras: Vec<State> = order
        .iter()
        .take(HANDLE_RESTARTS)
        .filter_map(|&k| handle_restart(family, &runs[k].0, obs))
        .chain(
            order
                .first()
                .and_then(|&k| height_restart(family, &runs[k].0, obs, ground)),
        )
        .collect();
    let extra_runs: Vec<_> = extras
        .into_par_iter()
        .filter_map(|s| {
            let mut run = problem.run(s)?;
            polish(&mut run);
            Some(run)
        })
        .collect();
    runs.extend(extra_runs);
    let mut pick = pick_run(family, &runs, obs, cfg.outline_tolerance);
    // A hidden handle: the same mug with its handle straight away from the camera, kept when
    // it fits as well (see `restart::away_restart`).
    if let Some(k) = pick
        && cfg.outline_tolerance > 0.0
        && let Some(s) = away_restart(family, &runs[k].0, obs)
        && let Some(mut run) = problem.run(s)
    {
        polish(&mut run);
        let x = run.0.rotation * Vector3::x();
        tracing::debug!(
            "{family:?} hidden handle turned away: loss {:.4e} against {:.4e}, object +X {:.3} {:.3} {:.3}",
            run.1,
            runs[k].1,
            x.x,
            x.y,
            x.z
        );
        if run.1 <= runs[k].1 * (1.0 + cfg.outline_tolerance)
            && run_outline_errors(family, &run.0, obs)
                <= run_outline_errors(family, &runs[k].0, obs)
        {
            runs.push(run);
            pick = Some(runs.len() - 1);
        }
    }
    let (st, loss, curve) = pick
        .map(|k| runs.swap_remove(k))
        .ok_or(ReconError::Diverged {
            stage: "object fit",
            runs: restarts,
        })?;
    let shape = family.shape(&st.u);
    let sim = st.sim();
    let placed = PlacedSdf {
        sdf: shape.sdf(),
        depth_from_object: sim,
    };
    let mean = obs
        .surface
        .iter()
        .map(|p| placed.distance(p).abs())
        .sum::<f64>()
        / obs.surface.len() as f64;
    Ok(FittedObject {
        category: shape.category(),
        shape,
        depth_from_object: sim,
        loss,
        mean_surface_error_m: mean,
        points: obs.surface.len(),
        loss_curve: curve,
        learned: None,
    })
}

/// The run kept: the fewest outline errors ([`outline_errors`]) among the runs within
/// `tolerance` (relative) of the lowest loss, the lower loss between equals. Restarts that
/// differ in a mug's yaw end within a few per cent of each other when its handle is hidden or
/// shows in a few pixels (tabletop family seed 21: 0.3 % between handles turned 126°; seed 26:
/// 0.9 % between handles turned 174°), and the loss's ring samples miss a handle standing out
/// of the mask by a few pixels where the counted outline does not.
fn pick_run(
    family: Family,
    runs: &[(State, f64, Vec<f64>)],
    obs: &ObjectObservation,
    tolerance: f64,
) -> Option<usize> {
    let best = runs.iter().map(|r| r.1).min_by(f64::total_cmp)?;
    let near: Vec<usize> = (0..runs.len())
        .filter(|&k| runs[k].1 <= best * (1.0 + tolerance.max(0.0)))
        .collect();
    let count = tolerance > 0.0 && near.len() > 1;
    let scored: Vec<(usize, usize)> = near
        .par_iter()
        .map(|&k| {
            let errors = if count {
                run_outline_errors(family, &runs[k].0, obs)
            } else {
                0
            };
            (k, errors)
        })
        .collect();
    for &(k, errors) in &scored {
        let x = runs[k].0.rotation * Vector3::x();
        tracing::debug!(
            "{family:?} run {k}: loss {:.4e}, outline errors {errors} of {}, object +X {:.3} {:.3} {:.3}",
            runs[k].1,
            obs.silhouette.len(),
            x.x,
            x.y,
            x.z,
        );
    }
    scored
        .into_iter()
        .min_by(|a, b| a.1.cmp(&b.1).then(runs[a.0].1.total_cmp(&runs[b.0].1)))
        .map(|(k, _)| k)
}

/// A ring ray may meet the fit this far in front of the seen surface (object units): a few
/// depth-noise widths at the mugs' 0.4–0.6 m.
const OUTLINE_IN_FRONT: f64 = 0.03;

/// [`outline_errors`] of the run at `st`.
fn run_outline_errors(family: Family, st: &State, obs: &ObjectObservation) -> usize {
    outline_errors(
        &*family.shape(&st.u).sdf(),
        &st.sim(),
        &obs.silhouette,
        OUTLINE_IN_FRONT * st.log_scale.exp(),
    )
}

/// Points just behind the observed surface along the camera rays (inside any wall): 1.5 % of
/// the object's size, ≈ 1–1.5 mm on a mug or a bowl, thinner than their walls.
const INSIDE_DEPTH: f64 = 0.015;
/// Support-plane free-space points: a grid this many per side under the footprint…
const SUPPORT_GRID: usize = 16;
/// …this far below the plane, in units of the object's size (`unit_m`).
const SUPPORT_DEPTH: f64 = 0.02;
/// Cells per axis of a fitted car's baked field (`LatentSdf::baked`; ≈ 4.6 s to sample on 2
/// cores): normals 0.11° from the 27,000-step prior's (median, p99 1.2°; 128 cells 0.07° / 0.59°
/// in ≈ 11 s; on the 9,000-step prior 96 cells gave 0.07°).
pub const BAKE_CELLS: usize = 96;
/// Cells per axis of a fitted bowl's or mug's grid, which only speeds the march: within a band
/// about the surface the network answers (`LatentSdf::baked_banded`).
pub const BAND_CELLS: usize = 48;

/// The learned prior's fit from a family fit (`fit`): the family shape's bounding box gives
/// the prior's normalised frame (centre, half-diagonal 0.9), the screened start the shape; then
/// latent and placement are fitted together, with a grid just below the support plane under the
/// footprint kept outside (when a plane was found). Spheres are returned unchanged.
pub fn fit_learned(
    fit: FittedObject,
    obs: &ObjectObservation,
    ground: &Ground,
    cfg: &ObjectConfig,
    seed: u64,
) -> Result<FittedObject, ReconError> {
    let category = match fit.shape {
        Shape::Sphere => return Ok(fit),
        Shape::Bowl { .. } | Shape::Mug { .. } | Shape::Car { .. } => fit.shape.category(),
    };
    let net = SdfNet::builtin(category)?;
    let (lo, hi) = family_mesh(&fit.shape, 48).bounds().ok_or_else(|| {
        irmirror_sdf::SdfError::Invalid(format!(
            "the fitted {} has no surface to place the learned prior on",
            category.name()
        ))
    })?;
    let (lo, hi) = (
        Vector3::from(lo.map(f64::from)),
        Vector3::from(hi.map(f64::from)),
    );
    let s = &fit.depth_from_object;
    let k = (hi - lo).norm() / 2.0 / irmirror_sdf::families::NORMALISED_RADIUS;
    let init = Similarity3 {
        rotation: s.rotation,
        translation: s.transform_point(&((lo + hi) / 2.0)),
        scale: s.scale * k,
    };
    let unit = s.scale;
    let inside: Vec<Vector3<f64>> = obs
        .surface
        .iter()
        .map(|p| p + p.normalize() * INSIDE_DEPTH * unit)
        .collect();
    let scale_prior = Family::of(category)
        .size_prior()
        .map(|_| (init.scale.ln(), 0.1));
    // The underside is never seen: without the table the latent may push it through the plane.
    // A grid just below the plane under the (slightly widened) footprint is free space.
    let mut support = Vec::new();
    if let Some(plane) = &ground.plane {
        let (n, g) = (plane.n(), SUPPORT_GRID);
        for i in 0..g {
            for j in 0..g {
                let f = |k: usize, a: f64, b: f64| {
                    a + (b - a) * (-0.1 + 1.2 * (k as f64 + 0.5) / g as f64)
                };
                let p = s.transform_point(&Vector3::new(f(i, lo.x, hi.x), lo.y, f(j, lo.z, hi.z)));
                support.push(p - n * (plane.height(&p) + SUPPORT_DEPTH * unit));
            }
        }
    }
    let observation = PlacedObservation {
        surface: &obs.surface,
        free: &obs.free,
        inside: &inside,
        support: &support,
        up: Some(ground.n()),
        unit_m: unit,
        scale_prior,
    };
    let placed_cfg = PlacedFitConfig {
        seed,
        ..cfg.learned
    };
    // The start: the prior's mean latent or, with `latent_starts`, whichever of it and the
    // training codes scores lowest where the family fit put the shape.
    let mut starts = vec![net.mean_latent()];
    starts.extend(net.train_latents.iter().take(cfg.latent_starts).cloned());
    let start = irmirror_sdf::placed::best_start(&net, &observation, &init, &starts, &placed_cfg)?;
    let placed = fit_placed(&net, &observation, &init, &starts[start], &placed_cfg)?;
    let field = Arc::new(net.shape(&placed.latent)?);
    let mesh = irmirror_sdf::quality::extract_mesh(&net, &placed.latent, 40)?
        .main_components(irmirror_sdf::quality::MAIN_PART_FRACTION);
    let base_y = mesh
        .vertices
        .iter()
        .map(|v| f64::from(v[1]))
        .fold(f64::INFINITY, f64::min);
    let d = placed.depth_from_object;
    let local: Vec<Vector3<f64>> = obs
        .surface
        .iter()
        .map(|p| d.inverse_transform_point(p))
        .collect();
    let mean = net
        .eval_batch(&placed.latent, &local)?
        .iter()
        .map(|f| (d.scale * f).abs())
        .sum::<f64>()
        / obs.surface.len() as f64;
    let mut curve = fit.loss_curve;
    curve.extend(&placed.curve);
    Ok(FittedObject {
        depth_from_object: d,
        loss: placed.loss,
        mean_surface_error_m: mean,
        loss_curve: curve,
        learned: Some(LearnedShape {
            latent: placed.latent,
            base_y,
            net,
            sdf: field,
            traced: Arc::default(),
        }),
        ..fit
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::silhouette::SilhouetteRay;
    use std::f64::consts::PI;

    /// Two runs of a mug seen from the side, near-tied in loss: the truth, whose handle stands
    /// out of the cup's outline to one side, and the same mug turned half round, whose handle
    /// stands out on the other side (missing the truth's handle pixels, in front of the wall
    /// behind). The truth is kept though its loss is 1 % higher; with a tolerance of 0 the lower
    /// loss is.
    #[test]
    fn pick_run_keeps_the_matching_outline() {
        let n = -Vector3::y();
        let state = |yaw: f64| State {
            rotation: upright(&n, yaw),
            translation: Vector3::new(0.0, 0.0, 0.5),
            log_scale: 0.05f64.ln(),
            u: [0.5, 0.5],
        };
        let truth = state(0.0);
        // The handle (+X) across the view.
        assert!((truth.rotation * Vector3::x()).z.abs() < 1e-9);
        let sdf = Family::Mug.shape(&truth.u).sdf();
        let sim = truth.sim();
        let camera = sim.inverse_transform_point(&Vector3::zeros());
        // A 160 × 120 view at 400 px focal length (the mug ≈ 40 px wide), a wall at z = 1 m.
        let silhouette: Vec<SilhouetteRay> = (0..160 * 120)
            .map(|i| {
                let dir = Vector3::new((i % 160) as f64 - 79.5, (i / 160) as f64 - 59.5, 400.0)
                    .normalize();
                let hit = crate::objects::silhouette::render_depth(
                    &*sdf,
                    &camera,
                    &sim.rotation.tr_mul(&dir),
                );
                SilhouetteRay {
                    dir,
                    seen_m: Some(hit.map_or(1.0 / dir.z, |t| t * sim.scale)),
                    inside: hit.is_some(),
                }
            })
            .collect();
        let obs = ObjectObservation {
            silhouette,
            ..Default::default()
        };
        let errors = |st: &State| run_outline_errors(Family::Mug, st, &obs);
        assert_eq!(errors(&truth), 0);
        assert!(errors(&state(PI)) > 20, "{}", errors(&state(PI)));
        let runs = vec![(truth, 1.0, Vec::new()), (state(PI), 0.99, Vec::new())];
        assert_eq!(pick_run(Family::Mug, &runs, &obs, 0.1), Some(0));
        assert_eq!(pick_run(Family::Mug, &runs, &obs, 0.0), Some(1));
        // Beyond the tolerance, the loss decides.
        let runs = vec![(truth, 1.2, Vec::new()), (state(PI), 1.0, Vec::new())];
        assert_eq!(pick_run(Family::Mug, &runs, &obs, 0.1), Some(1));
    }
}
