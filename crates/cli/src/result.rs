//! Writing a reconstruction (DESIGN.md §4): meshes, parameters, overlays, renders, loss curves,
//! and the HTML section that shows them.

use crate::output::{Staging, save_png, write_text};
use anyhow::Result;
use image::{Rgb, RgbImage};
use irmirror_body::prior::PosePrior;
use irmirror_body::{BodyModel, PosedBody};
use irmirror_capture::{Capture, Image, write_gray8_png};
use irmirror_eval::views::{Drawn, object_mesh, overlay, render_view};
use irmirror_geom::nalgebra::Vector3;
use irmirror_geom::{PinholeCamera, Rigid3};
use irmirror_recon::human::posed_body;
use irmirror_recon::pipeline::Reconstruction;
use irmirror_render::bvh::Bvh;
use irmirror_render::hard::hard_mask;

fn mask_png(img: &Image<bool>, path: &std::path::Path) -> Result<()> {
    write_gray8_png(&img.map(|b| if b { 255 } else { 0 }), path)?;
    Ok(())
}

/// Loss curves (first in black, the others grey), 480×240, y from 0 to the largest value.
pub fn plot_curves(curves: &[&[f64]]) -> RgbImage {
    let (w, h, m) = (480u32, 240u32, 20i64);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let ymax = curves
        .iter()
        .flat_map(|c| c.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(1e-9, f64::max);
    let xmax = curves.iter().map(|c| c.len()).max().unwrap_or(1).max(2) - 1;
    let to_px = |i: usize, v: f64| {
        (
            m + (i as f64 / xmax as f64 * (w as i64 - 2 * m) as f64) as i64,
            h as i64 - m - (v / ymax * (h as i64 - 2 * m) as f64) as i64,
        )
    };
    let mut put = |x: i64, y: i64, c: Rgb<u8>| {
        if x >= 0 && y >= 0 && x < w as i64 && y < h as i64 {
            img.put_pixel(x as u32, y as u32, c);
        }
    };
    for x in m..w as i64 - m {
        put(x, h as i64 - m, Rgb([0, 0, 0]));
    }
    for y in m..h as i64 - m {
        put(m, y, Rgb([0, 0, 0]));
    }
    for (k, c) in curves.iter().enumerate().rev() {
        let col = if k == 0 {
            Rgb([20, 20, 200])
        } else {
            Rgb([180, 180, 180])
        };
        for i in 1..c.len() {
            let ((x0, y0), (x1, y1)) = (to_px(i - 1, c[i - 1]), to_px(i, c[i]));
            let n = (x1 - x0).abs().max((y1 - y0).abs()).max(1);
            for s in 0..=n {
                put(x0 + (x1 - x0) * s / n, y0 + (y1 - y0) * s / n, col);
            }
        }
    }
    img
}

/// What the writer produced, for the demo's evaluation and summary.
pub struct Written {
    /// The best hypothesis' posed body.
    pub best: PosedBody<f64>,
    /// Fitted reflection (thermal pixels) of the best hypothesis.
    pub fitted_mask: Vec<bool>,
}

/// Writes the reconstruction into `stage` under `prefix` (e.g. "" or "result/").
pub fn write(
    stage: &Staging,
    prefix: &str,
    capture: &Capture,
    rec: &Reconstruction,
    model: &BodyModel,
    prior: &PosePrior,
    cfg: &irmirror_recon::pipeline::ReconConfig,
) -> Result<Written> {
    let p = |name: &str| stage.path(&format!("{prefix}{name}"));
    for d in ["debug", "objects", "hypotheses", "views"] {
        std::fs::create_dir_all(p(d))?;
    }
    // Stage 0.
    let pre = &rec.pre;
    let max = pre.rise_k.data.iter().copied().fold(1e-9, f64::max);
    write_gray8_png(
        &pre.rise_k
            .map(|r| (r / max * 255.0).clamp(0.0, 255.0) as u8),
        &p("debug/rise.png"),
    )?;
    mask_png(&pre.object_pixels, &p("debug/object_pixels.png"))?;
    mask_png(&pre.raw_mask, &p("debug/mask_raw.png"))?;
    mask_png(&pre.edges, &p("debug/edges.png"))?;
    mask_png(&pre.mask, &p("reflection_mask.png"))?;
    // Stage 1.
    for (k, o) in rec.objects.objects.iter().enumerate() {
        let m = object_mesh(o)?;
        m.write(&p(&format!("objects/object_{k}.ply")))?;
        m.write(&p(&format!("objects/object_{k}.glb")))?;
        mask_png(
            &rec.objects.masks[k],
            &p(&format!("debug/object_{k}_mask.png")),
        )?;
    }
    // Stage 2.
    let mut bodies = Vec::new();
    for (k, st) in rec.states.iter().enumerate() {
        let posed = posed_body(model, prior, st)?;
        let mesh = model.mesh(&posed);
        if k == 0 {
            for ext in ["ply", "obj", "glb"] {
                mesh.write(&p(&format!("body.{ext}")))?;
            }
        }
        mesh.write(&p(&format!("hypotheses/body_{k}.ply")))?;
        bodies.push(posed);
    }
    let best = bodies
        .first()
        .cloned()
        .ok_or_else(|| anyhow::anyhow!("no hypothesis"))?;
    let bvh = Bvh::build(&best.vertices, &model.asset.faces);
    let fitted_mask = hard_mask(&rec.rays, &bvh, &best.vertices, &model.asset.faces);
    save_png(
        &overlay(&pre.rise_k, &pre.mask, &fitted_mask),
        &p("overlay.png"),
    )?;
    // The radiometric fit: observed, fitted and residual rise around the reflection.
    let priors = irmirror_recon::pipeline::BodyPriors { model, prior };
    if let Some(fitted) = irmirror_recon::pipeline::predicted_rise(rec, priors, cfg)? {
        save_png(
            &irmirror_eval::views::rise_panels(&pre.rise_k, &fitted, &pre.mask),
            &p("rise_fit.png"),
        )?;
    }
    let curves: Vec<&[f64]> = rec
        .human
        .hypotheses
        .iter()
        .map(|h| h.loss_curve.as_slice())
        .collect();
    save_png(&plot_curves(&curves), &p("loss_curve.png"))?;
    let placed = rec.objects.placed();
    let faces = &model.asset.faces;
    for (name, cam, depth_from_cam) in &capture.extra_cameras {
        let img = render_view(
            cam,
            depth_from_cam,
            &[Drawn {
                vertices: &best.vertices,
                triangles: faces,
                colour: [240, 150, 60],
            }],
            &placed,
        );
        save_png(&img, &p(&format!("views/{name}.png")))?;
    }
    // The depth camera's own view, pulled back 1.5 m so the person shows too.
    let centre = placed
        .iter()
        .fold(Vector3::zeros(), |a, o| a + o.depth_from_object.translation)
        / placed.len().max(1) as f64;
    let overview = overview_camera(&rec.objects.ground.n(), &centre, &best);
    let img = render_view(
        &overview.0,
        &overview.1,
        &[Drawn {
            vertices: &best.vertices,
            triangles: faces,
            colour: [240, 150, 60],
        }],
        &placed,
    );
    save_png(&img, &p("views/overview.png"))?;

    let decoded: Vec<Vec<[f64; 3]>> = rec
        .human
        .hypotheses
        .iter()
        .map(|h| prior.decode_axis_angles(&h.latent))
        .collect::<Result<_, _>>()?;
    let params = serde_json::json!({
        "frame": "depth camera (OpenCV axes: +X right, +Y down, +Z forward), metres",
        "up": rec.objects.ground.up,
        "support_plane": rec.objects.ground.plane,
        "objects": rec.objects.objects,
        "human": {
            "note": "The reflection constrains the person only partly: several placements can explain a small reflection. hypotheses[0] is the best by loss; the others are distinct (root > 25 cm apart or facing > 45° apart) and nearly as good when their losses are close.",
            "shape": "the mean adult's phenotype with the fitted height slider (hypotheses[].height, stature_m)",
            "data_term": rec.human.data_term,
            "hypotheses": rec.human.hypotheses,
            "rotvec_rad": decoded,
            "bone_names": model.asset.meta.bone_names,
            "rays": rec.human.rays,
            "mask_rays": rec.human.mask_rays,
            "diverged_initialisations": rec.human.diverged,
        },
    });
    write_text(&p("params.json"), &serde_json::to_string_pretty(&params)?)?;
    Ok(Written { best, fitted_mask })
}

/// A camera beside the scene, level with the support plane, that sees the objects and the
/// fitted person.
fn overview_camera(
    up: &Vector3<f64>,
    objects_centre: &Vector3<f64>,
    body: &PosedBody<f64>,
) -> (PinholeCamera, Rigid3<f64>) {
    let cam = PinholeCamera::from_fov(320, 240, 70f64.to_radians()).expect("valid");
    let root = body.joints[0];
    let target = (root + objects_centre) * 0.5;
    let span = (root - objects_centre).norm();
    // Look along the horizontal perpendicular to the person–objects line.
    let along = root - objects_centre;
    let side = up
        .cross(&along)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::x);
    let eye = target + side * (1.2 * span + 1.5) + up * 0.3;
    let fwd = (target - eye).normalize();
    let right = fwd.cross(up).normalize();
    let down = fwd.cross(&right);
    let rot = irmirror_geom::nalgebra::Matrix3::from_columns(&[right, down, fwd]);
    (
        cam,
        Rigid3 {
            rotation: rot,
            translation: eye,
        },
    )
}

/// The report section of a reconstruction (paths relative to the report, under `prefix`).
pub fn report_section(prefix: &str, capture: &Capture, rec: &Reconstruction) -> String {
    let mut s = String::new();
    s += &format!(
        r#"<h2>Reconstruction</h2>
<figure><img src="{prefix}overlay.png" width="480"><figcaption>reflection: observed (green), fitted (magenta), both (white)</figcaption></figure>
<figure><img src="{prefix}views/overview.png" width="480"><figcaption>fitted objects (blue) and person (orange), seen from beside the scene</figcaption></figure>
<figure><img src="{prefix}loss_curve.png" width="480"><figcaption>loss per step: best hypothesis (blue), others (grey)</figcaption></figure>
"#
    );
    if rec.human.data_term == "radiometric" {
        s += &format!(
            r#"<figure><img src="{prefix}rise_fit.png" width="720"><figcaption>thermal rise around the reflection, best hypothesis: observed | fitted | residual (observed − fitted: red warmer, blue cooler than the fit; ± half the observed peak)</figcaption></figure>
"#
        );
    } else {
        s += &format!(
            "<p>Stage 2 fitted the binary reflection mask: {}.</p>",
            rec.human.data_term
        );
    }
    for (name, _, _) in &capture.extra_cameras {
        s += &format!(
            r#"<figure><img src="{prefix}views/{name}.png" width="480"><figcaption>fit seen from the capture's camera “{name}”</figcaption></figure>"#
        );
    }
    s += "<h3>Objects (stage 1)</h3><table><tr><th>#</th><th>category</th><th>shape</th><th>position (m, depth frame)</th><th>scale (m)</th><th>mean surface error</th><th>mask</th></tr>";
    for (k, o) in rec.objects.objects.iter().enumerate() {
        let t = o.depth_from_object.translation;
        s += &format!(
            "<tr><td>{k}</td><td>{}</td><td>{}</td><td>({:.3}, {:.3}, {:.3})</td><td>{:.3}</td><td>{:.1} mm</td><td>{}</td></tr>",
            o.category,
            o.shape,
            t.x,
            t.y,
            t.z,
            o.depth_from_object.scale,
            o.mean_surface_error_m * 1e3,
            if rec.objects.segmented[k] {
                "segmented"
            } else {
                "given"
            }
        );
    }
    s += "</table>";
    s += &format!(
        "<h3>Person (stage 2)</h3><p>{} reflected rays see past the objects; {} of them are in the reflection mask. \
         The search scored {} candidates (every facing direction, distances along the reflected rays, pose modes) and refined the best; \
         the table lists the distinct hypotheses kept, best first, with the best one's front/back partner (turned ≈ 180°) when one was refined: \
         a silhouette seen in a mirror barely tells a person facing it from one facing away, so compare their losses.</p>\
         <table><tr><th>#</th><th>loss</th><th>soft IoU</th><th>root (m, depth frame)</th><th>distance (m)</th><th>turned from #0 (°)</th><th>stature (m)</th><th>mesh</th></tr>",
        rec.human.rays, rec.human.mask_rays, rec.human.candidates
    );
    let up = rec.objects.ground.n();
    for (k, (h, st)) in rec.human.hypotheses.iter().zip(&rec.states).enumerate() {
        let t = h.translation_m;
        let turned = irmirror_recon::human::search::facing_angle_deg(
            &up,
            &rec.states[0].rotation,
            &st.rotation,
        );
        s += &format!(
            "<tr><td>{k}</td><td>{:.3}</td><td>{:.3}</td><td>({:.2}, {:.2}, {:.2})</td><td>{:.2}</td><td>{turned:.0}</td><td>{:.2}</td><td><a href=\"{prefix}hypotheses/body_{k}.ply\">body_{k}.ply</a></td></tr>",
            h.loss,
            h.soft_iou,
            t[0],
            t[1],
            t[2],
            Vector3::from(t).norm(),
            h.stature_m
        );
    }
    s += "</table>";
    s += &format!(
        "<p>Files: <a href=\"{prefix}body.ply\">body.ply</a> / <a href=\"{prefix}body.obj\">.obj</a> / <a href=\"{prefix}body.glb\">.glb</a>, \
         objects/, <a href=\"{prefix}params.json\">params.json</a>, <a href=\"{prefix}reflection_mask.png\">reflection_mask.png</a>, debug/ (stage-0 intermediates, object masks).</p>"
    );
    s
}
