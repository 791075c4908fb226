//! `irmirror score`: a reconstruction's figures against a simulated capture's truth, from the
//! files alone (`params.json` and `fitted_mask.png` of the result, `truth/` of the capture).

use anyhow::{Context, Result, bail};
use irmirror_body::prior::PosePrior;
use irmirror_body::{BodyModel, PosedBody};
use irmirror_capture::image_io::read_mask;
use irmirror_eval::truth::similarity;
use irmirror_eval::{Scored, Truth};
use irmirror_geom::Similarity3;
use irmirror_geom::nalgebra::Vector3;
use irmirror_recon::human::{HumanState, posed_body};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
struct ParamsFile {
    objects: Vec<ObjectFile>,
    human: HumanFile,
}

#[derive(Deserialize)]
struct ObjectFile {
    depth_from_object: PoseFile,
}

#[derive(Deserialize)]
struct PoseFile {
    rotation: [[f64; 3]; 3],
    translation_m: [f64; 3],
    scale_m: f64,
}

#[derive(Deserialize)]
struct HumanFile {
    hypotheses: Vec<HypothesisFile>,
}

#[derive(Deserialize)]
struct HypothesisFile {
    translation_m: [f64; 3],
    root_rotvec_rad: [f64; 3],
    height: f64,
    /// Absent in results written before the build was configurable: the mean adult's.
    #[serde(default)]
    build: irmirror_body::Phenotype,
    latent: Vec<f64>,
    /// Absent in results without a pose residual.
    #[serde(default)]
    residual: Vec<f64>,
    loss: f64,
}

/// The reported hypotheses of a result (loss and posed body, best first), its fitted objects'
/// placements and the best hypothesis' reflection mask, read back from its files.
pub struct ResultFiles {
    /// `(loss, body)` per hypothesis.
    pub hypotheses: Vec<(f64, PosedBody<f64>)>,
    /// Fitted object placements.
    pub objects: Vec<Similarity3<f64>>,
    /// The best hypothesis' reflection (thermal pixels, row-major).
    pub mask: Vec<bool>,
}

/// Reads a result directory written by `reconstruct` or `demo`.
pub fn read_result(dir: &Path, model: &BodyModel, prior: &PosePrior) -> Result<ResultFiles> {
    let params_path = dir.join("params.json");
    let text = std::fs::read_to_string(&params_path).with_context(|| {
        format!(
            "cannot read {}: is {} a result of `irmirror reconstruct` (stage full)?",
            params_path.display(),
            dir.display()
        )
    })?;
    let params: ParamsFile = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a result's parameters", params_path.display()))?;
    let objects = params
        .objects
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let d = &o.depth_from_object;
            similarity(&d.rotation, d.translation_m, d.scale_m)
                .map_err(|e| anyhow::anyhow!("{}: object {k}: {e}", params_path.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut hypotheses = Vec::new();
    for (k, h) in params.human.hypotheses.iter().enumerate() {
        let finite = h
            .translation_m
            .iter()
            .chain(&h.root_rotvec_rad)
            .chain(&h.latent)
            .chain(&h.residual)
            .chain([&h.height])
            .chain(h.build.values().iter())
            .all(|x| x.is_finite());
        if !finite {
            bail!(
                "{}: hypothesis {k} has a non-finite parameter",
                params_path.display()
            );
        }
        let st = HumanState {
            translation: Vector3::from(h.translation_m),
            rotation: irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(
                h.root_rotvec_rad,
            )),
            height: h.height,
            build: h.build,
            latent: h.latent.clone(),
            residual: h.residual.clone(),
        };
        let body = posed_body(model, prior, &st)
            .with_context(|| format!("{}: hypothesis {k}", params_path.display()))?;
        hypotheses.push((h.loss, body));
    }
    if hypotheses.is_empty() {
        bail!(
            "{}: the result reports no hypothesis",
            params_path.display()
        );
    }
    let mask_path = dir.join("fitted_mask.png");
    if !mask_path.is_file() {
        bail!(
            "{} is missing (results written before `irmirror score` existed lack it): run `irmirror reconstruct` again",
            mask_path.display()
        );
    }
    let mask = read_mask(&mask_path)?.data;
    Ok(ResultFiles {
        hypotheses,
        objects,
        mask,
    })
}

/// Scores `result` against the truth of `capture`; prints the table and writes `json` if given.
pub fn run(result: &Path, capture: &Path, json: Option<&Path>) -> Result<Scored> {
    if !Truth::exists(capture) {
        bail!(
            "{} has no truth/body.json: only captures written by `irmirror simulate` (or `demo`) carry a truth to score against",
            capture.display()
        );
    }
    let model = BodyModel::builtin()?;
    let prior = PosePrior::builtin_f64()?;
    let truth = Truth::load(capture, &model)?;
    let files = read_result(result, &model, &prior)?;
    let scored = irmirror_eval::score(&truth, &files.hypotheses, &files.mask, &files.objects)
        .with_context(|| format!("scoring {} against {}", result.display(), capture.display()))?;
    if let Some(path) = json {
        crate::output::write_file_atomic(
            path,
            "--json",
            &[result, capture],
            &serde_json::to_string_pretty(&scored)?,
        )?;
    }
    print!("{}", scored.text());
    Ok(scored)
}
