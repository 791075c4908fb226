//! Training the pose VAE (`irmirror train-pose-prior`): Adam on `‖R̂ − R‖²_F + β KL`, β annealed
//! from 0 over the first half, batches drawn from a fixed pose set — procedural poses and,
//! optionally, a share of real motion-capture poses (each mirrored with probability ½ and given
//! the same joint noise); deterministic for a seed (weights, data, noise and batches all come
//! from the seeded generator). The figures include encode → decode on the benchmark's persons
//! ([`MocapSet::builtin`], never trained on): the floor the prior puts under any fit.

use super::generator::PoseGenerator;
use super::penetration::PenetrationTest;
use super::{PosePrior, PoseVae, PriorError, features, rotation_angle};
use crate::mocap::MocapSet;
use crate::{BodyModel, Phenotype, Pose};
use candle_core::{DType, Tensor};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use irmirror_geom::Similarity3;
use irmirror_geom::rotation::axis_angle_to_matrix;
use nalgebra::Vector3;
use rand::Rng;
use serde::Serialize;

/// Training settings.
#[derive(Clone, Debug, Serialize)]
pub struct TrainConfig {
    /// Poses in the training set.
    pub poses: usize,
    /// Held-out poses for the figures.
    pub held_out: usize,
    /// Optimiser steps.
    pub steps: usize,
    /// Batch size.
    pub batch: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// Final KL weight.
    pub kl_weight: f64,
    /// Seed.
    pub seed: u64,
    /// Joint noise of the procedural pose set, degrees (σ per rotation-vector component).
    pub joint_noise_deg: f64,
    /// Share of the training set drawn from real motion-capture poses (0 without them).
    pub real_fraction: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            poses: 100_000,
            held_out: 2_000,
            steps: 6_000,
            batch: 256,
            lr: 1e-3,
            kl_weight: 5e-3,
            seed: 0,
            joint_noise_deg: super::generator::JOINT_NOISE_DEG,
            real_fraction: 0.0,
        }
    }
}

/// Figures of a trained prior.
#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    /// The settings.
    pub config: TrainConfig,
    /// Training time, s.
    pub train_s: f64,
    /// Final reconstruction loss (batch mean of Σ‖R̂ − R‖²).
    pub final_reconstruction: f64,
    /// Final KL (batch mean).
    pub final_kl: f64,
    /// Held-out encode → decode error: mean geodesic joint-angle error, degrees.
    pub held_out_joint_error_deg: f64,
    /// Fraction of decoded N(0, I) samples with any joint more than 5° outside its limits.
    pub samples_outside_limits_5deg: f64,
    /// Fraction of decoded samples with any joint outside its limits at all.
    pub samples_outside_limits: f64,
    /// Fraction of (sample, joint) pairs more than 5° outside the joint's limits.
    pub joints_outside_limits_5deg: f64,
    /// Fraction of the training poses whose limb capsules overlap.
    pub training_self_penetration: f64,
    /// Fraction of decoded samples whose limb capsules overlap.
    pub samples_self_penetration: f64,
    /// Real poses the training set drew from (0 without them).
    pub real_poses: usize,
    /// Provenance of the real poses ("" without them).
    pub real_provenance: String,
    /// The benchmark's persons (not trained on) encoded → decoded: mean joint angle, degrees.
    pub benchmark_joint_error_deg: f64,
    /// The same, per-vertex distance on the mean adult (root fixed), metres: median over poses.
    pub benchmark_vertex_error_median_m: f64,
    /// 90th percentile of the above.
    pub benchmark_vertex_error_p90_m: f64,
    /// The same after the best rigid alignment of the decoded body onto the true one: median.
    pub benchmark_aligned_vertex_error_median_m: f64,
    /// 90th percentile of the above.
    pub benchmark_aligned_vertex_error_p90_m: f64,
}

fn matrices(poses: &[Vec<[f64; 3]>]) -> Vec<f64> {
    poses
        .iter()
        .flat_map(|p| {
            p[1..].iter().flat_map(|w| {
                let m = axis_angle_to_matrix(&Vector3::from(*w));
                (0..9).map(move |k| m[(k / 3, k % 3)])
            })
        })
        .collect()
}

/// Encode → decode of each pose: (mean joint angle over the 35 body joints, radians; per-vertex
/// mean distance on the mean adult, metres, with the root fixed and after the best rigid
/// alignment — what a fit that also finds the root's rotation and place is left with).
pub fn round_trip_errors(
    model: &BodyModel,
    prior: &PosePrior,
    poses: &[Vec<[f64; 3]>],
) -> Result<Vec<(f64, f64, f64)>, PriorError> {
    let shaped = model.shaped_phenotype::<f64>(&Phenotype::default())?;
    poses
        .iter()
        .map(|p| {
            let dec = prior.decode(&prior.encode(p)?)?;
            let angle = p[1..]
                .iter()
                .zip(&dec[1..])
                .map(|(w, m)| rotation_angle(&axis_angle_to_matrix(&Vector3::from(*w)), m))
                .sum::<f64>()
                / super::JOINTS as f64;
            let mut truth = Pose::from_axis_angles(p, Vector3::zeros());
            truth.rotations[0] = nalgebra::Matrix3::identity();
            let fit = Pose {
                rotations: dec,
                translation: Vector3::zeros(),
            };
            let a = model.pose(&shaped, &truth)?.vertices;
            let b = model.pose(&shaped, &fit)?.vertices;
            let mean_dist = |b: &[Vector3<f64>]| {
                a.iter().zip(b).map(|(x, y)| (x - y).norm()).sum::<f64>() / a.len() as f64
            };
            let aligned = Similarity3::umeyama(&b, &a, false).map_or(f64::NAN, |s| {
                mean_dist(&b.iter().map(|x| s.transform_point(x)).collect::<Vec<_>>())
            });
            Ok((angle, mean_dist(&b), aligned))
        })
        .collect()
}

/// Refuses a real-pose set training cannot use: empty, posing another skeleton, or holding any
/// of the benchmark's persons ([`MocapSet::builtin`], its held-out truth: a prior trained on
/// them would know the answers).
fn check_real_poses(model: &BodyModel, set: &MocapSet, bench: &MocapSet) -> Result<(), PriorError> {
    let bad = |why: String| Err(PriorError::RealPoses(why));
    if set.poses.is_empty() {
        return bad("no poses".into());
    }
    if let Some(p) = set.poses.iter().find(|p| p.len() != model.n_joints()) {
        return bad(format!(
            "poses of {} bones, the body has {}",
            p.len(),
            model.n_joints()
        ));
    }
    let same = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| x.iter().zip(y).all(|(u, v)| (u - v).abs() < 1e-6))
    };
    let shared = set
        .poses
        .iter()
        .filter(|p| bench.poses.iter().any(|b| same(b, p)))
        .count();
    if shared > 0 {
        return bad(format!(
            "{shared} of its poses are the benchmark's persons (assets/poses/mocap_bvhtools.safetensors); the prior must not train on the benchmark's truth"
        ));
    }
    Ok(())
}

/// Trains a prior on procedural poses and, when `real` is given, a `cfg.real_fraction` share of
/// its poses (refused when empty, of another skeleton, or holding the benchmark's persons);
/// `progress(step, loss)` is called every 50 steps.
pub fn train(
    model: &BodyModel,
    cfg: &TrainConfig,
    real: Option<&MocapSet>,
    mut progress: impl FnMut(usize, f64),
) -> Result<(PoseVae, TrainReport), PriorError> {
    let bench = MocapSet::builtin()?;
    if let Some(set) = real {
        check_real_poses(model, set, &bench)?;
    }
    let poses_gen = PoseGenerator::new(model);
    let mut data_rng = irmirror_geom::rng::seeded(cfg.seed, 1);
    let real_poses = real.map_or(&[][..], |r| &r.poses[..]);
    let n_real = if real_poses.is_empty() {
        0
    } else {
        (cfg.poses as f64 * cfg.real_fraction.clamp(0.0, 1.0)).round() as usize
    };
    let poses: Vec<Vec<[f64; 3]>> = (0..cfg.poses)
        .map(|k| {
            if k < n_real {
                let p = real_poses[k % real_poses.len()].clone();
                poses_gen.perturb(p, &mut data_rng, cfg.joint_noise_deg)
            } else {
                poses_gen
                    .sample_with_noise(&mut data_rng, cfg.joint_noise_deg)
                    .1
            }
        })
        .collect();
    let mut hold_rng = irmirror_geom::rng::seeded(cfg.seed, 2);
    let held: Vec<Vec<[f64; 3]>> = (0..cfg.held_out)
        .map(|_| {
            poses_gen
                .sample_with_noise(&mut hold_rng, cfg.joint_noise_deg)
                .1
        })
        .collect();
    let dev = candle_core::Device::Cpu;
    let x_all = Tensor::from_vec(features(&poses), (cfg.poses, 6 * super::JOINTS), &dev)?
        .to_dtype(DType::F32)?;
    let r_all = Tensor::from_vec(matrices(&poses), (cfg.poses, super::JOINTS, 3, 3), &dev)?
        .to_dtype(DType::F32)?;

    let mut rng = irmirror_geom::rng::seeded(cfg.seed, 3);
    let vae = PoseVae::new(&mut rng)?;
    let mut opt = AdamW::new(
        vae.vars(),
        ParamsAdamW {
            lr: cfg.lr,
            weight_decay: 0.0,
            ..Default::default()
        },
    )?;
    let t0 = std::time::Instant::now();
    let (mut last_rec, mut last_kl) = (0.0, 0.0);
    for step in 0..cfg.steps {
        let idx: Vec<u32> = (0..cfg.batch)
            .map(|_| rng.random_range(0..cfg.poses as u32))
            .collect();
        let idx = Tensor::from_vec(idx, cfg.batch, &dev)?;
        let x = x_all.index_select(&idx, 0)?;
        let r = r_all.index_select(&idx, 0)?;
        let (mu, logvar) = vae.encode(&x)?;
        let eps = vae.normal(&mut rng, cfg.batch)?;
        let z = (&mu + (logvar.affine(0.5, 0.0)?.exp()? * eps)?)?;
        let rec = (vae.decode(&z)? - &r)?
            .sqr()?
            .sum_all()?
            .affine(1.0 / cfg.batch as f64, 0.0)?;
        let kl = ((mu.sqr()? + logvar.exp()?)? - logvar)?
            .affine(1.0, -1.0)?
            .sum_all()?
            .affine(0.5 / cfg.batch as f64, 0.0)?;
        let beta = cfg.kl_weight * (2.0 * step as f64 / cfg.steps as f64).min(1.0);
        let loss = (&rec + kl.affine(beta, 0.0)?)?;
        opt.backward_step(&loss)?;
        if step % 50 == 0 || step + 1 == cfg.steps {
            last_rec = f64::from(rec.to_scalar::<f32>()?);
            last_kl = f64::from(kl.to_scalar::<f32>()?);
            progress(step, last_rec + beta * last_kl);
        }
    }
    let train_s = t0.elapsed().as_secs_f64();

    // Figures.
    let prior = PosePrior::new(PoseVae::from_tensors(vae.vars_map()?, DType::F32)?)?;
    let mut err_sum = 0.0;
    for p in &held {
        let z = prior.encode(p)?;
        let dec = prior.decode(&z)?;
        err_sum += p[1..]
            .iter()
            .zip(&dec[1..])
            .map(|(w, m)| rotation_angle(&axis_angle_to_matrix(&Vector3::from(*w)), m))
            .sum::<f64>()
            / super::JOINTS as f64;
    }
    let pen = PenetrationTest::new(model);
    let n_samples = 2000;
    let mut sample_rng = irmirror_geom::rng::seeded(cfg.seed, 4);
    let (mut out5, mut out0, mut pen_s, mut joints5) = (0, 0, 0, 0);
    for _ in 0..n_samples {
        let z: Vec<f64> = (0..super::LATENT)
            .map(|_| {
                rand_distr::Distribution::<f64>::sample(
                    &rand_distr::StandardNormal,
                    &mut sample_rng,
                )
            })
            .collect();
        let r = prior.decode_axis_angles(&z)?;
        let per_joint = poses_gen.limits.joint_violations(&r);
        joints5 += per_joint.iter().filter(|v| **v > 5f64.to_radians()).count();
        let v = per_joint.iter().copied().fold(0.0, f64::max);
        out5 += usize::from(v > 5f64.to_radians());
        out0 += usize::from(v > 1e-6);
        pen_s += usize::from(pen.penetrates(&r));
    }
    let pen_train = poses
        .iter()
        .take(20_000)
        .filter(|p| pen.penetrates(p))
        .count() as f64
        / poses.len().min(20_000) as f64;
    let trips = round_trip_errors(model, &prior, &bench.poses)?;
    let quantile = |q: f64, pick: fn(&(f64, f64, f64)) -> f64| {
        let mut v: Vec<f64> = trips.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    let report = TrainReport {
        config: cfg.clone(),
        train_s,
        final_reconstruction: last_rec,
        final_kl: last_kl,
        held_out_joint_error_deg: (err_sum / held.len() as f64).to_degrees(),
        samples_outside_limits_5deg: out5 as f64 / n_samples as f64,
        samples_outside_limits: out0 as f64 / n_samples as f64,
        joints_outside_limits_5deg: joints5 as f64 / (n_samples * super::JOINTS) as f64,
        training_self_penetration: pen_train,
        samples_self_penetration: pen_s as f64 / n_samples as f64,
        real_poses: real_poses.len(),
        real_provenance: real.map_or_else(String::new, |r| r.provenance.clone()),
        benchmark_joint_error_deg: (trips.iter().map(|t| t.0).sum::<f64>() / trips.len() as f64)
            .to_degrees(),
        benchmark_vertex_error_median_m: quantile(0.5, |t| t.1),
        benchmark_vertex_error_p90_m: quantile(0.9, |t| t.1),
        benchmark_aligned_vertex_error_median_m: quantile(0.5, |t| t.2),
        benchmark_aligned_vertex_error_p90_m: quantile(0.9, |t| t.2),
    };
    Ok((vae, report))
}
