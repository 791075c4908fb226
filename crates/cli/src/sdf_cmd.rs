//! `irmirror train-sdf`: train a DeepSDF object prior on procedural shapes (and user meshes),
//! evaluate it on held-out procedural shapes, write the weights with their provenance.

use anyhow::{Context, Result, bail};
use irmirror_sdf::infer::InferConfig;
use irmirror_sdf::train::{TrainSdfConfig, procedural_params, sample_meshes, train};
use irmirror_sdf::{Category, SdfNet, mesh_io};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Options of `train-sdf`.
pub struct Options<'a> {
    /// Category (one with a learned prior).
    pub category: Category,
    /// Extra user meshes.
    pub meshes: Option<&'a Path>,
    /// Output weights.
    pub out: &'a Path,
    /// Training settings.
    pub cfg: TrainSdfConfig,
    /// Held-out shapes for the figures (0: none).
    pub held_out: usize,
}

fn bar(progress: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    let b = if progress {
        indicatif::ProgressBar::new(len)
    } else {
        indicatif::ProgressBar::hidden()
    };
    b.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:40}} {{pos}}/{{len}} {{msg}} {{elapsed}}"
        ))
        .expect("valid template"),
    );
    b
}

/// Runs the command.
pub fn run(o: Options, progress: bool) -> Result<()> {
    let category = o.category;
    if !category.has_learned_prior() {
        bail!("--category {category}: priors are trained for bowl, mug and car");
    }
    if o.cfg.steps == 0 || o.cfg.samples_per_shape < 100 || o.cfg.points_per_shape == 0 {
        bail!("--steps must be positive and --samples at least 100");
    }
    if o.cfg.shapes == 0 && o.meshes.is_none() {
        bail!("nothing to train on: --shapes 0 and no --meshes");
    }
    if o.out.extension().and_then(|e| e.to_str()) != Some("safetensors") {
        bail!(
            "--out must name a .safetensors file, got {}",
            o.out.display()
        );
    }
    // User meshes first: a bad file fails before minutes of work.
    let mut user = Vec::new();
    if let Some(dir) = o.meshes {
        for f in mesh_io::mesh_files(dir)? {
            let mut m = mesh_io::read_mesh(&f)?;
            let open = mesh_io::open_edges(&m);
            if open > 0 {
                tracing::warn!(
                    "{}: not watertight ({open} open edges); its sign comes from the winding number (best effort)",
                    f.display()
                );
            }
            if let Some(w) = mesh_io::size_warning(&m, category.typical_size_m()) {
                tracing::warn!("{}: {w}", f.display());
            }
            mesh_io::normalise(&mut m);
            user.push(m);
        }
    }
    let t0 = std::time::Instant::now();
    let b = bar(progress, o.cfg.shapes as u64, "meshing + sampling");
    let mut data = Vec::new();
    // One shape at a time: bounded memory for the fine procedural meshes.
    for (k, shape) in procedural_params(category, o.cfg.shapes, o.cfg.seed, 1)?
        .into_iter()
        .enumerate()
    {
        let mesh = shape.mesh(o.cfg.mesh_resolution);
        data.extend(sample_meshes(
            &[&mesh],
            o.cfg.samples_per_shape,
            o.cfg.seed.wrapping_add(k as u64),
        ));
        b.inc(1);
    }
    b.finish_and_clear();
    for (k, m) in user.iter().enumerate() {
        data.extend(sample_meshes(
            &[m],
            o.cfg.samples_per_shape,
            o.cfg.seed.wrapping_add(100_000 + k as u64),
        ));
    }
    let data_s = t0.elapsed().as_secs_f64();
    let mut meta = BTreeMap::new();
    meta.insert(
        "command".into(),
        std::iter::once("irmirror".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" "),
    );
    meta.insert("seed".into(), o.cfg.seed.to_string());
    meta.insert("version".into(), env!("CARGO_PKG_VERSION").into());
    meta.insert("licence".into(), "weights: Apache-2.0; training data: irmirror's procedural shape families (no third-party data)".into());
    if !user.is_empty() {
        meta.insert("user_meshes".into(), user.len().to_string());
    }
    let b = bar(
        progress,
        o.cfg.steps as u64,
        &format!("training {} prior", category.name()),
    );
    let (mut net, mut report) = train(category, &data, &o.cfg, meta, |step, l1| {
        b.set_position(step as u64);
        b.set_message(format!("L1 {l1:.4}"));
    })?;
    b.finish_and_clear();
    report.data_s = data_s;
    drop(data);
    net.metadata
        .insert("train_s".into(), format!("{:.0}", report.train_s));
    let mut json = serde_json::json!({ "category": category.name(), "training": report });
    if o.held_out > 0 {
        let b = bar(progress, o.held_out as u64, "held-out figures");
        let shared = Arc::new(net.clone());
        let figs = irmirror_sdf::quality::held_out(
            &shared,
            o.held_out,
            8000,
            o.cfg.seed,
            &InferConfig::default(),
            |k| b.set_position(k as u64),
        )?;
        b.finish_and_clear();
        net.metadata.insert(
            "held_out_chamfer_x1e3".into(),
            format!("{:.3}", figs.chamfer_x1e3_mean),
        );
        json["held_out"] = serde_json::to_value(&figs)?;
    }
    net.save(o.out)?;
    let json_path = o.out.with_extension("json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    // Check what was written loads back.
    SdfNet::load(o.out)?;
    println!("{}", serde_json::to_string_pretty(&json)?);
    println!("wrote {} and {}", o.out.display(), json_path.display());
    Ok(())
}
