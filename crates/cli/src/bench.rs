//! `irmirror bench …`: performance tables (performance claims live here, not in tests).

use anyhow::Result;
use clap::Subcommand;
use irmirror_body::{BodyGrad, BodyModel, OutputGrads, Phenotype, Pose};
use irmirror_geom::nalgebra::Vector3;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `irmirror bench`.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Reflection renderer: one forward + backward of the soft-IoU loss on the reference scene,
    /// dense (every reflected ray × every triangle) and fast (BVH-culled), in one run.
    Render {
        /// The benchmark scene (JSON with its masks beside it; default: the reference scene
        /// shipped in the repository's assets/bench/, see BENCHMARKS.md).
        #[arg(long, default_value_os_t = crate::output::shipped("assets/bench/scene_sphere160.json"))]
        scene: PathBuf,
        /// Timed repetitions of the fast path (the median is reported).
        #[arg(long, default_value_t = 50)]
        reps: usize,
        /// Skip the dense baseline (it takes seconds).
        #[arg(long)]
        no_dense: bool,
        /// Culling thresholds ε to time, comma-separated (relative influence below which far
        /// triangles are skipped); each is compared with the one dense run.
        #[arg(long, value_delimiter = ',', default_values_t = [1e-4, 1e-7])]
        epsilon: Vec<f64>,
        /// How triangles form a ray's occupancy: `product` (SoftRas, the scene's definition) or
        /// `silhouette` (distance to the silhouette, what stage 2 uses).
        #[arg(long, value_enum, default_value_t = AggregationArg::Product)]
        aggregation: AggregationArg,
    },
    /// Stage 1 (support plane, segmentation, object fits) against the simulator's truth: one
    /// row per object and the median / 90th percentile / max per category.
    Objects {
        /// Capture regime (tabletop-wide: the scenes of the README's stage-1 table).
        #[arg(
            long,
            visible_alias = "preset",
            value_enum,
            default_value = "tabletop-wide"
        )]
        regime: irmirror_sim::presets::Regime,
        /// Seeds 0..N (N ≥ 1).
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// Ignore the capture's object masks and segment the depth image instead.
        #[arg(long)]
        segment: bool,
        /// Shape families of the simulated objects; several (comma-separated, e.g.
        /// `family,unseen`) run the same seeds once per set and summarise each apart: the
        /// learned priors in family (`family`) and out of family (`unseen`).
        #[arg(long, value_enum, value_delimiter = ',', default_value = "simple")]
        shapes: Vec<irmirror_sim::presets::Shapes>,
        /// The prior stage 1 fits: the two-parameter family, or then the learned DeepSDF prior.
        #[arg(long, value_enum, default_value = "simple")]
        prior: PriorArg,
        /// Re-reflect large objects' rays off the depth data (the `[mirror]` refinement, its
        /// defaults) before measuring the reflected-ray angle.
        #[arg(long)]
        mirror: bool,
    },
    /// The person's reflection size per capture regime (ideal sensor): median, 10th and 90th
    /// percentiles over seeds, and a histogram PNG.
    ///
    /// Example: irmirror bench regimes --seeds 50 --png regimes.png
    Regimes {
        /// Seeds first..first + N.
        #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// The first seed.
        #[arg(long, default_value_t = 0)]
        first: u64,
        /// Histogram image to write.
        #[arg(long, default_value = "regimes.png")]
        png: PathBuf,
    },
    /// Body model: shape, forward (FK + LBS + keypoints) and backward, in f32.
    Body {
        /// Timed repetitions per row (the median is reported).
        #[arg(long, default_value_t = 200)]
        reps: usize,
    },
}

/// Stage 1's shape prior.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum PriorArg {
    /// The renderer's two-parameter family of the category.
    Simple,
    /// The family fit, then the learned DeepSDF prior's latent and placement.
    Learned,
}

impl From<PriorArg> for irmirror_recon::objects::ObjectPrior {
    fn from(p: PriorArg) -> Self {
        match p {
            PriorArg::Simple => Self::Simple,
            PriorArg::Learned => Self::Learned,
        }
    }
}

pub(crate) fn median_ms(mut f: impl FnMut(), reps: usize) -> f64 {
    f(); // warm-up
    let mut t: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// Runs a benchmark.
pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::Render {
            scene,
            reps,
            no_dense,
            epsilon,
            aggregation,
        } => crate::bench_render::run(&scene, reps, no_dense, &epsilon, aggregation.into()),
        BenchCommand::Objects {
            regime,
            seeds,
            segment,
            shapes,
            prior,
            mirror,
        } => crate::bench_objects::run(&crate::bench_objects::Settings {
            regime,
            shape_sets: &shapes,
            prior: prior.into(),
            seeds,
            segment,
            mirror: mirror.then(|| irmirror_recon::depth_mirror::DepthMirror {
                enabled: true,
                ..Default::default()
            }),
        }),
        BenchCommand::Regimes { seeds, first, png } => {
            crate::bench_regimes::run(first, seeds, &png)
        }
        BenchCommand::Body { reps } => {
            let model = BodyModel::builtin()?;
            let z: Vec<f32> = model
                .shape_coefficients(&Phenotype::default())?
                .iter()
                .map(|&x| x as f32)
                .collect();
            let mut shaped = model.shaped(&z)?;
            let rot: Vec<[f32; 3]> = (0..model.n_joints())
                .map(|c| [0.1 * (c % 3) as f32, -0.05, 0.07])
                .collect();
            let pose = Pose::from_axis_angles(&rot, Vector3::new(0.0, 0.0, 1.0));
            let mut posed = model.posed_buffers();
            let gv = vec![Vector3::new(0.1f32, -0.2, 0.3); model.n_vertices()];
            let mut grad = BodyGrad {
                rotations: vec![],
                translation: Vector3::zeros(),
                shape: vec![],
            };
            let shape_ms = median_ms(|| shaped = model.shaped(&z).expect("valid z"), reps);
            let fwd_ms = median_ms(
                || {
                    model
                        .pose_into(&shaped, &pose, &mut posed)
                        .expect("valid pose")
                },
                reps,
            );
            let bwd_ms = median_ms(
                || {
                    model.backward(
                        &shaped,
                        &pose,
                        &mut posed,
                        OutputGrads {
                            vertices: Some(&gv),
                            ..Default::default()
                        },
                        &mut grad,
                    )
                },
                reps,
            );
            println!(
                "body model: {} vertices, {} joints, {} influences, shape rank {}, {} threads, f32, median of {reps}",
                model.n_vertices(),
                model.n_joints(),
                model.asset.influences,
                model.rank(),
                rayon::current_num_threads()
            );
            println!("| step | ms |\n|---|---|");
            println!("| shape (phenotype coefficients → rest mesh + joints) | {shape_ms:.3} |");
            println!("| forward (FK + LBS + keypoints) | {fwd_ms:.3} |");
            println!("| backward (keypoints, LBS, FK, shape VJPs) | {bwd_ms:.3} |");
            Ok(())
        }
    }
}

/// `--aggregation` of `bench render`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AggregationArg {
    /// SoftRas' product over triangles.
    Product,
    /// Distance to the silhouette.
    Silhouette,
}

impl From<AggregationArg> for irmirror_render::Aggregation {
    fn from(a: AggregationArg) -> Self {
        match a {
            AggregationArg::Product => Self::Product,
            AggregationArg::Silhouette => Self::Silhouette,
        }
    }
}
