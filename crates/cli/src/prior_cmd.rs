//! `irmirror train-pose-prior`: train the pose VAE and write its weights, figures and a picture.

use crate::output::save_png;
use anyhow::{Context, Result};
use irmirror_body::mocap::MocapSet;
use irmirror_body::prior::PosePrior;
use irmirror_body::prior::train::{TrainConfig, train};
use irmirror_body::{BodyModel, Phenotype, Pose};
use std::path::Path;

/// Trains (on `real_poses` as well, when given) and writes `out` (safetensors), `out` with
/// `.json` (figures) and `.png` (samples).
pub fn run(out: &Path, real_poses: Option<&Path>, cfg: TrainConfig, progress: bool) -> Result<()> {
    let model = BodyModel::builtin()?;
    // Checked by `train` (empty, another skeleton, the benchmark's persons).
    let real = real_poses
        .map(|p| -> Result<MocapSet> {
            let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            Ok(MocapSet::from_bytes(&bytes, &p.display().to_string())?)
        })
        .transpose()?;
    let bar = if progress {
        indicatif::ProgressBar::new(cfg.steps as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "training pose prior {bar:40} {pos}/{len} loss {msg} {elapsed}",
        )
        .expect("valid template"),
    );
    let (vae, report) = train(&model, &cfg, real.as_ref(), |step, loss| {
        bar.set_position(step as u64);
        bar.set_message(format!("{loss:.4}"));
    })
    .with_context(|| match real_poses {
        Some(p) => format!("training the pose prior with --real-poses {}", p.display()),
        None => "training the pose prior".to_string(),
    })?;
    bar.finish_and_clear();
    let tmp = out.with_extension("safetensors.partial");
    vae.save(&tmp)?;
    std::fs::rename(&tmp, out).with_context(|| format!("cannot write {}", out.display()))?;
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(out.with_extension("json"), &json)
        .with_context(|| format!("cannot write {}", out.with_extension("json").display()))?;
    let prior = PosePrior::load_f32(out)?;
    save_png(
        &sample_grid(&model, &prior, cfg.seed, 4, 6)?,
        &out.with_extension("png"),
    )?;
    println!("{json}");
    println!(
        "wrote {}, {}, {}",
        out.display(),
        out.with_extension("json").display(),
        out.with_extension("png").display()
    );
    Ok(())
}

/// A `rows × cols` grid of front silhouettes of random prior samples (mean adult shape).
pub fn sample_grid(
    model: &BodyModel,
    prior: &PosePrior,
    seed: u64,
    rows: u32,
    cols: u32,
) -> Result<image::RgbImage> {
    let size = 160;
    let shaped = model.shaped_phenotype::<f64>(&Phenotype::default())?;
    let mut rng = irmirror_geom::rng::seeded(seed, 77);
    let mut sheet =
        image::RgbImage::from_pixel(size * cols, size * rows, image::Rgb([255, 255, 255]));
    for k in 0..rows * cols {
        let z: Vec<f64> = (0..irmirror_body::prior::LATENT)
            .map(|_| rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng))
            .collect();
        let mut pose = Pose {
            rotations: prior.decode(&z)?,
            translation: shaped.joint_heads[0],
        };
        pose.rotations[0] = irmirror_geom::nalgebra::Matrix3::identity();
        let mesh = model.mesh(&model.pose(&shaped, &pose)?);
        let img =
            irmirror_geom::raster::render_orthographic(&mesh, &crate::output::view_front(), size);
        image::imageops::replace(
            &mut sheet,
            &img,
            i64::from(size * (k % cols)),
            i64::from(size * (k / cols)),
        );
    }
    Ok(sheet)
}
