//! Writing a reconstruction (DESIGN.md §4): meshes, parameters, overlays, renders, loss curves,
//! and the HTML section that shows them.

use crate::output::{Staging, save_png, write_text};
use crate::scene3d::{Part, camera_mesh, colour, display_mesh};
use anyhow::Result;
use irmirror_body::PosedBody;
use irmirror_capture::{Capture, Image, write_gray8_png};
use irmirror_eval::score::{object_poses, third_view};
use irmirror_eval::views::{Drawn, object_mesh, overlay, reflection_zoom, render_view, stretched};
use irmirror_eval::{Scored, Truth};
use irmirror_geom::nalgebra::Vector3;
use irmirror_geom::{PinholeCamera, Rigid3};
use irmirror_recon::human::posed_body;
use irmirror_recon::pipeline::{BodyPriors, Reconstruction};
use irmirror_recon::preprocess::Preprocessed;
use irmirror_render::bvh::Bvh;
use irmirror_render::hard::hard_mask;

/// Stage 0's files: `reflection_mask.png` and `debug/` (rise, object pixels, raw mask, edges,
/// and the depth image's edges over the thermal frame, to check the calibration). `p` maps a
/// name to its path in the result; `debug/` must exist.
pub fn write_stage0(
    capture: &Capture,
    pre: &Preprocessed,
    p: &dyn Fn(&str) -> std::path::PathBuf,
) -> Result<()> {
    let max = pre.rise_k.data.iter().copied().fold(1e-9, f64::max);
    write_gray8_png(
        &pre.rise_k
            .map(|r| (r / max * 255.0).clamp(0.0, 255.0) as u8),
        &p("debug/rise.png"),
    )?;
    mask_png(&pre.object_pixels, &p("debug/object_pixels.png"))?;
    mask_png(&pre.raw_mask, &p("debug/mask_raw.png"))?;
    mask_png(&pre.edges, &p("debug/edges.png"))?;
    save_png(
        &irmirror_eval::views::depth_edges_on_thermal(
            &capture.thermal_k,
            &capture.depth_m,
            &capture.depth_camera,
            &capture.thermal_camera,
            &capture.depth_from_thermal,
        ),
        &p("debug/depth_edges_on_thermal.png"),
    )?;
    mask_png(&pre.mask, &p("reflection_mask.png"))?;
    Ok(())
}

fn mask_png(img: &Image<bool>, path: &std::path::Path) -> Result<()> {
    write_gray8_png(&img.map(|b| if b { 255 } else { 0 }), path)?;
    Ok(())
}

/// What the writer produced, for the demo's evaluation and summary.
pub struct Written {
    /// The best hypothesis' posed body.
    pub best: PosedBody<f64>,
    /// Every reported hypothesis' loss and posed body, best first.
    pub hypotheses: Vec<(f64, PosedBody<f64>)>,
    /// Fitted reflection (thermal pixels) of the best hypothesis.
    pub fitted_mask: Vec<bool>,
}

/// What a result is written from.
pub struct ResultInputs<'a> {
    /// The capture.
    pub capture: &'a Capture,
    /// The reconstruction.
    pub rec: &'a Reconstruction,
    /// Body model and pose prior.
    pub priors: BodyPriors<'a>,
    /// The settings it ran with.
    pub cfg: &'a irmirror_recon::pipeline::ReconConfig,
    /// The simulator's truth, when the capture has one (drawn in the 3-D scene only).
    pub truth: Option<&'a Truth>,
}

/// Writes the reconstruction into `stage` under `prefix` (e.g. "" or "result/").
pub fn write(stage: &Staging, prefix: &str, inputs: &ResultInputs<'_>) -> Result<Written> {
    let ResultInputs {
        capture,
        rec,
        priors,
        cfg,
        truth,
    } = *inputs;
    let BodyPriors { model, prior } = priors;
    let p = |name: &str| stage.path(&format!("{prefix}{name}"));
    for d in ["debug", "objects", "hypotheses", "views"] {
        std::fs::create_dir_all(p(d))?;
    }
    // Stage 0.
    let pre = &rec.pre;
    write_stage0(capture, pre, &p)?;
    // The thermal frame as a person sees it: stretched on the objects, not on the room.
    save_png(
        &stretched(&capture.thermal_radiance(), &pre.object_pixels),
        &p("thermal_preview.png"),
    )?;
    // Stage 1.
    let mut parts = Vec::new();
    for (k, o) in rec.objects.objects.iter().enumerate() {
        let m = object_mesh(o)?;
        m.write(&p(&format!("objects/object_{k}.ply")))?;
        m.write(&p(&format!("objects/object_{k}.glb")))?;
        mask_png(
            &rec.objects.masks[k],
            &p(&format!("debug/object_{k}_mask.png")),
        )?;
        parts.push(Part {
            name: format!("object {k} ({}), fitted", o.category),
            mesh: display_mesh(&m),
            colour: colour::OBJECT,
            visible: true,
        });
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
        parts.push(Part {
            name: if k == 0 {
                "person, best hypothesis".into()
            } else {
                format!("hypothesis {k}")
            },
            mesh,
            colour: if k == 0 {
                colour::PERSON
            } else {
                colour::OTHER
            },
            visible: k == 0,
        });
        bodies.push(posed);
    }
    for (name, cam, depth_from_cam) in [
        ("depth camera", &capture.depth_camera, &Rigid3::identity()),
        (
            "thermal camera",
            &capture.thermal_camera,
            &capture.depth_from_thermal,
        ),
    ] {
        parts.push(Part {
            name: name.into(),
            mesh: camera_mesh(cam, depth_from_cam, 0.06),
            colour: colour::CAMERA,
            visible: true,
        });
    }
    if let Some(t) = truth {
        parts.push(Part {
            name: "true person (simulator)".into(),
            mesh: t.mesh.clone(),
            colour: colour::TRUTH,
            visible: true,
        });
        for (k, m) in t.object_meshes.iter().enumerate() {
            parts.push(Part {
                name: format!("object {k}, true"),
                mesh: display_mesh(m),
                colour: colour::TRUE_OBJECT,
                visible: false,
            });
        }
    }
    crate::scene3d::write(&stage.path(""), prefix, &parts, &rec.objects.ground.n())?;
    let best = bodies
        .first()
        .cloned()
        .ok_or_else(|| anyhow::anyhow!("no hypothesis"))?;
    let bvh = Bvh::build(&best.vertices, &model.asset.faces);
    let fitted_mask = hard_mask(&rec.rays, &bvh, &best.vertices, &model.asset.faces);
    let (tw, th) = (pre.mask.width, pre.mask.height);
    mask_png(
        &Image {
            width: tw,
            height: th,
            data: fitted_mask.clone(),
        },
        &p("fitted_mask.png"),
    )?;
    save_png(
        &overlay(&pre.rise_k, &pre.mask, &fitted_mask),
        &p("overlay.png"),
    )?;
    save_png(
        &reflection_zoom(&pre.rise_k, &pre.mask, &fitted_mask),
        &p("reflection_zoom.png"),
    )?;
    // The radiometric fit: observed, fitted and residual rise around the reflection.
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
    write_text(&p("loss_curve.svg"), &crate::plot::loss_svg(&curves))?;
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

    // Each hypothesis' body joints as posed (the latent's decoding and the residual), root
    // zero: its rotation is `root_rotvec_rad`.
    let decoded: Vec<Vec<[f64; 3]>> = rec
        .states
        .iter()
        .map(|st| {
            let mut r = irmirror_recon::human::joint_rotations(prior, st)?;
            r[0] = irmirror_geom::nalgebra::Matrix3::identity();
            Ok(r.iter()
                .map(|m| irmirror_geom::rotation::matrix_to_axis_angle(m).into())
                .collect())
        })
        .collect::<Result<_, irmirror_recon::ReconError>>()?;
    let params = serde_json::json!({
        "frame": "depth camera (OpenCV axes: +X right, +Y down, +Z forward), metres",
        "up": rec.objects.ground.up,
        "support_plane": rec.objects.ground.plane,
        "objects": rec.objects.objects,
        "human": {
            "note": "hypotheses[0] is the best by loss as refined (each one's fields are its state's after the parts no ray sees were reset to the stand template, [human] unseen_pose); the others are distinct (root > 25 cm apart or facing > 45° apart), the best one's front/back partner first; compare their losses.",
            "notes": notes(rec),
            "shape": "the build (hypotheses[].build: the mean adult's phenotype unless [human] build names one) with the fitted height slider (hypotheses[].height, stature_m)",
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
    let hypotheses = rec
        .human
        .hypotheses
        .iter()
        .map(|h| h.loss)
        .zip(bodies)
        .collect();
    Ok(Written {
        best,
        hypotheses,
        fitted_mask,
    })
}

/// [`write`], then, when the inputs carry the simulator's truth, the result scored against it:
/// `eval.json` and the evaluation camera's view (`views/third_camera.png`).
pub fn write_scored(
    stage: &Staging,
    prefix: &str,
    inputs: &ResultInputs<'_>,
) -> Result<(Written, Option<Scored>)> {
    let written = write(stage, prefix, inputs)?;
    let Some(truth) = inputs.truth else {
        return Ok((written, None));
    };
    let scored = irmirror_eval::score(
        truth,
        &written.hypotheses,
        &written.fitted_mask,
        &object_poses(&inputs.rec.objects),
    )?;
    write_text(
        &stage.path(&format!("{prefix}eval.json")),
        &serde_json::to_string_pretty(&scored)?,
    )?;
    save_png(
        &third_view(
            truth,
            inputs.priors.model,
            &written.best,
            &inputs.rec.objects,
        ),
        &stage.path(&format!("{prefix}views/third_camera.png")),
    )?;
    Ok((written, Some(scored)))
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

/// Notes that depend on the data: a small reflection, hypotheses that explain it about equally,
/// warm pixels outside the objects (a person or another heat source seen directly).
pub fn notes(rec: &Reconstruction) -> Vec<String> {
    let pre = &rec.pre;
    let mut out = Vec::new();
    let n = pre.mask.data.iter().filter(|m| **m).count();
    if n < SMALL_REFLECTION_PX {
        out.push(format!(
            "The reflection covers only {n} thermal pixels: a small reflection constrains the person only partly, \
             and several placements can explain it (compare the hypotheses below)."
        ));
    }
    let hs = &rec.human.hypotheses;
    if let Some(best) = hs.first() {
        for (k, h) in hs.iter().enumerate().skip(1) {
            // The data term, not the total loss: the unseen parts' reset moves the priors of
            // the reported states (hypotheses are ranked before it), and the data term may be
            // negative (the thermal term's Huber residuals less their noise floor).
            if explains_as_well(h.data_loss, best.data_loss) {
                out.push(format!(
                    "Hypothesis {k} explains the reflection about as well as the best (data term {:.3} against \
                     {:.3}): the data do not decide between them.",
                    h.data_loss, best.data_loss
                ));
            }
        }
    }
    let warm_outside = pre
        .rise_k
        .data
        .iter()
        .zip(&pre.object_pixels.data)
        .filter(|(r, obj)| !**obj && **r > 2.0 * pre.threshold_k)
        .count();
    if warm_outside >= DIRECT_VIEW_PX {
        out.push(format!(
            "{warm_outside} thermal pixels outside the objects are warmer than in the background frame by more than \
             {:.2} K: a person (or another heat source) may be in the thermal camera's direct view. Stage 2 uses only \
             the reflections in the objects.",
            2.0 * pre.threshold_k
        ));
    }
    out
}

/// Whether a data term `d` is within 10 % (of its magnitude, at least 0.005) of the best's.
fn explains_as_well(d: f64, best: f64) -> bool {
    d <= best + (0.1 * best.abs()).max(0.005)
}

/// Fewer reflection pixels than this make a "small reflection" note (the hard regime's 10–25
/// pixels; the paper-like ones reach hundreds).
const SMALL_REFLECTION_PX: usize = 100;

/// Warm pixels outside the objects from which a direct view is noted.
const DIRECT_VIEW_PX: usize = 20;

/// The report section of a reconstruction (paths relative to the report, under `prefix`).
pub fn report_section(prefix: &str, capture: &Capture, rec: &Reconstruction) -> String {
    let mut s = String::from("<h2>Reconstruction</h2>");
    for n in notes(rec) {
        s += &format!("<p class=\"note\">Note: {}</p>", esc(&n));
    }
    s += &format!(
        r#"<figure><img src="{prefix}reflection_zoom.png" height="240"><figcaption>the reflection, enlarged: observed (green) | fitted, best hypothesis (magenta) | both (white where they agree)</figcaption></figure>
"#
    );
    if rec.human.data_term == "radiometric" {
        s += &format!(
            r#"<figure><img src="{prefix}rise_fit.png" height="240"><figcaption>thermal rise around the reflection, best hypothesis: observed | fitted | residual (observed − fitted: red warmer, blue cooler than the fit; ± half the observed peak)</figcaption></figure>
"#
        );
    } else {
        s += &format!(
            "<p>Stage 2 fitted the binary reflection mask: {}.</p>",
            esc(&rec.human.data_term)
        );
    }
    s += &format!(
        r#"<figure><img src="{prefix}thermal_preview.png" width="480"><figcaption>thermal frame, stretched between the 1st and 99th percentiles of the pixels that see an object (the others dimmed)</figcaption></figure>
<figure><img src="{prefix}overlay.png" width="480"><figcaption>whole frame: rise over the background (grey), observed (green) and fitted (magenta) reflection, both (white)</figcaption></figure>
<figure><img src="{prefix}views/overview.png" width="480"><figcaption>fitted objects (blue) and person (orange), seen from beside the scene</figcaption></figure>
{view3d}<figure><img src="{prefix}loss_curve.svg" width="520"><figcaption>stage 2's loss per refinement step, every hypothesis</figcaption></figure>
"#,
        view3d = crate::scene3d::section(prefix)
    );
    for (name, _, _) in &capture.extra_cameras {
        s += &format!(
            r#"<figure><img src="{prefix}views/{name}.png" width="480"><figcaption>fit seen from the capture's camera “{}”</figcaption></figure>"#,
            esc(name)
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

/// Escapes text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The report section of a result scored against the simulator's truth: the figures with their
/// yardsticks, every hypothesis' errors, and the evaluation camera's view (under `prefix`).
pub fn score_section(prefix: &str, scored: &irmirror_eval::Scored) -> String {
    let mut s = String::from(
        "<h2>Evaluation against the simulator's truth</h2>\
         <p>The truth (the capture's <code>truth/</code>) is read only here, never by the reconstruction. \
         Same figures: <code>irmirror score</code>; over many captures: <code>irmirror eval</code>.</p>\
         <table><tr><th>figure</th><th>this result</th><th>yardstick</th></tr>",
    );
    for r in scored.best.rows() {
        s += &format!(
            "<tr><th>{}</th><td>{}</td><td class=\"yard\">{}</td></tr>",
            esc(r.name),
            esc(&r.value),
            esc(r.yardstick)
        );
    }
    s += "</table><p>Every reported hypothesis against the truth:</p>\
          <table><tr><th>#</th><th>loss</th><th>root error</th><th>facing error</th><th>per-vertex error</th></tr>";
    for (k, h) in scored.hypotheses.iter().enumerate() {
        s += &format!(
            "<tr><td>{k}</td><td>{:.3}</td><td>{:.3} m</td><td>{}</td><td>{}</td></tr>",
            h.loss,
            h.root_error_m,
            h.facing_error_deg
                .map_or("n/a".into(), |v| format!("{v:.0}°")),
            h.vertex_error_m
                .map_or("n/a".into(), |v| format!("{v:.3} m"))
        );
    }
    s += &format!(
        "</table><figure><img src=\"{prefix}views/third_camera.png\" width=\"480\"><figcaption>evaluation camera (not an input): \
         fitted person (orange), true person (green), fitted objects (blue)</figcaption></figure>"
    );
    s
}

#[cfg(test)]
mod tests {
    use super::explains_as_well;

    /// Within 10 % of the best's data term (at least 0.005), either sign: a negative best (the
    /// thermal term below its noise floor) is not turned into a tighter bound by a ratio.
    #[test]
    fn near_ties_are_judged_on_the_data_term() {
        assert!(explains_as_well(0.105, 0.1) && !explains_as_well(0.115, 0.1));
        assert!(explains_as_well(-0.095, -0.1) && !explains_as_well(-0.08, -0.1));
        assert!(explains_as_well(0.004, 0.0) && !explains_as_well(0.006, 0.0));
        // A lower data term than the best's (ranked lower through its priors) is a near tie.
        assert!(explains_as_well(0.02, 0.05));
    }
}
