//! `irmirror bench objects`: stage 1 against the simulator's truth over many seeds (issue 7's
//! figure): translation, up-axis and (for mugs, whose handle breaks the symmetry) full rotation
//! error, scale error, the wall of family bowls and mugs, Chamfer distance to the true mesh, a
//! car's near side, the reflected-ray angle between fit and truth over the object's thermal
//! pixels (what stage 2 sees of stage 1), and time per object.
//!
//! Position and size are those of the surfaces, not of the frames (a learned prior's frame is
//! its own, and its latent can absorb a little scale): translation is the distance between the
//! centres of the fitted and the true mesh's bounding boxes (each in its object's axes), scale
//! the ratio of their half-diagonals.
//!
//! A mug's rotation about its axis is observable only through its handle: the full-rotation
//! figure is summarised over the mugs whose handle the depth camera saw (≥ [`HANDLE_SEEN_PX`]
//! mask pixels on the handle side of the true cup) and the rest are counted apart.

use crate::simulate_cmd::regime_scene;
use anyhow::{Context, Result};
use irmirror_body::BodyModel;
use irmirror_capture::{Capture, Image};
use irmirror_geom::TriMesh;
use irmirror_geom::nalgebra::Vector3;
use irmirror_geom::{Category, PinholeCamera, Rigid3, Similarity3};
use irmirror_recon::depth_mirror::DepthMirror;
use irmirror_recon::objects::{ObjectPrior, Stage1Config, reconstruct_objects};
use irmirror_render::reflect::{Normals, ReflectedRays, reflect_camera};
use irmirror_render::sdf::PlacedSdf;
use irmirror_render::shapes::Shape;
use irmirror_render::sphere_trace::TraceParams;
use irmirror_sim::presets::Regime;
use irmirror_sim::presets::Shapes;
use irmirror_sim::scene::ObjectShape;
use std::time::Instant;

/// One fitted object against its truth.
struct Row {
    seed: u64,
    shapes: Shapes,
    category: Category,
    translation_mm: f64,
    up_deg: f64,
    /// Full rotation error; `None` for bodies of revolution (bowls).
    rotation_deg: Option<f64>,
    /// Mugs: depth pixels on the true handle, and whether that counts as seen.
    handle_px: usize,
    handle_seen: bool,
    scale_pct: f64,
    /// Bowls and mugs of the two-parameter family: the fitted wall against the true one, % (the
    /// lip that mirrors a person beside the object hangs on it; the depth camera barely sees
    /// it). `None` for other shapes.
    wall_pct: Option<f64>,
    chamfer_mm2: f64,
    /// Cars: [`near_side_mm`].
    side_mm: Option<f64>,
    /// [`ray_angles_deg`]'s median over the object's pixels; `None` when no pixel meets it in
    /// both the fit and the truth.
    ray_deg: Option<f64>,
    /// The same over the pixels of the person's reflection (the simulator's mask): where stage
    /// 2 looks.
    reflection_ray_deg: Option<f64>,
    time_s: f64,
}

/// Relative wall error (%) of a family bowl or mug.
fn wall_error(fit: &Shape, truth: &ObjectShape) -> Option<f64> {
    match (fit, truth) {
        (Shape::Bowl { wall, .. }, ObjectShape::Simple(Shape::Bowl { wall: w, .. }))
        | (Shape::Mug { wall, .. }, ObjectShape::Simple(Shape::Mug { wall: w, .. })) => {
            Some((wall / w - 1.0).abs() * 100.0)
        }
        _ => None,
    }
}

/// Centre (depth frame) and half-diagonal (metres) of a depth-frame mesh's bounding box in the
/// axes of `frame` (an object frame): robust to the holes marching leaves in thin walls.
fn box_in_frame(m: &TriMesh, frame: &Similarity3<f64>) -> (Vector3<f64>, f64) {
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for v in &m.vertices {
        let q = frame.rotation.tr_mul(&Vector3::from(v.map(f64::from)));
        lo = lo.inf(&q);
        hi = hi.sup(&q);
    }
    (frame.rotation * (lo + hi) / 2.0, (hi - lo).norm() / 2.0)
}

/// A car's side toward the camera (issue 21's "across its length"): how far the fitted surface's
/// outermost point on that side lies from the true one's along the true car's lateral axis
/// (object Z), mm. The far side, the length and the roof are mostly unseen from beside a car;
/// the side that mirrors the person is seen.
fn near_side_mm(fit_mesh: &TriMesh, true_mesh: &TriMesh, truth: &Similarity3<f64>) -> f64 {
    let axis = truth.rotation * Vector3::z();
    let extent = |m: &TriMesh| {
        m.vertices
            .iter()
            .map(|v| Vector3::from(v.map(f64::from)).dot(&axis))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
                (lo.min(z), hi.max(z))
            })
    };
    let ((flo, fhi), (tlo, thi)) = (extent(fit_mesh), extent(true_mesh));
    // The camera sits at the depth frame's origin (lateral coordinate 0).
    let near_is_low = tlo + thi > 0.0;
    1e3 * if near_is_low {
        (flo - tlo).abs()
    } else {
        (fhi - thi).abs()
    }
}

/// Mask pixels on the handle side of the true cup for a mug's handle to count as seen. A
/// handle is 2–3 depth pixels thick: on the simple-shape tabletop set, fits with 3–12 such
/// pixels found the handle's side (7 of 8), fits with 0–1 did not (5 of 5).
const HANDLE_SEEN_PX: usize = 3;

/// What stage 2 sees of stage 1: per true object, over the thermal pixels whose centre ray
/// meets it and meets a fitted object, the angle between the two reflected rays (degrees; both
/// with the smoothed normals stage 2 uses). A person 3 m away moves by 5 cm per 1°.
/// `refine` acts on the fitted rays first (the depth mirror, or nothing). With each angle,
/// whether its pixel lies in `reflection` (the person's reflection, when given).
fn ray_angles_deg(
    (camera, depth_from_camera): (&PinholeCamera, &Rigid3<f64>),
    fitted: &[PlacedSdf],
    truth: &[PlacedSdf],
    reflection: Option<&Image<bool>>,
    refine: impl FnOnce(&mut ReflectedRays<f64>),
) -> Vec<Vec<(f64, bool)>> {
    let rays = |objects: &[PlacedSdf]| {
        reflect_camera(
            camera,
            depth_from_camera,
            objects,
            &TraceParams::default(),
            Normals::Smoothed,
        )
    };
    let (mut fit, tru) = (rays(fitted), rays(truth));
    refine(&mut fit);
    let mut at = vec![usize::MAX; (fit.width * fit.height) as usize];
    for (i, &p) in fit.pixel.iter().enumerate() {
        at[p as usize] = i;
    }
    let mut out = vec![Vec::new(); truth.len()];
    for (j, &p) in tru.pixel.iter().enumerate() {
        let i = at[p as usize];
        if i != usize::MAX {
            // atan2 of sine and cosine: acos loses the small angles to rounding.
            let (a, b) = (fit.dir[i], tru.dir[j]);
            let angle = a.cross(&b).norm().atan2(a.dot(&b));
            let seen = reflection.is_some_and(|m| m.data[p as usize]);
            out[tru.object[j] as usize].push((angle.to_degrees(), seen));
        }
    }
    out
}

/// Depth pixels of `mask` whose points lie on the handle of a true mug (`truth`: object →
/// depth frame, `true_mesh` in the depth frame). Both mug families put the handle on the
/// object's +X side in the z = 0 plane, the cup's axis along +Y (but not always through the
/// origin: a family shape is centred on its bounding box). The cup's widest radius is half the
/// mesh's Z extent, its axis that far in from the −X extreme; a point more than 5 % beyond
/// that radius on +X is the handle's.
fn handle_pixels(
    capture: &Capture,
    mask: &irmirror_capture::Image<bool>,
    truth: &Similarity3<f64>,
    true_mesh: &TriMesh,
) -> usize {
    let local = |p: &Vector3<f64>| truth.inverse_transform_point(p);
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for v in &true_mesh.vertices {
        let q = local(&Vector3::from(v.map(f64::from)));
        lo = lo.inf(&q);
        hi = hi.sup(&q);
    }
    let radius = (hi.z - lo.z) / 2.0;
    let axis_x = lo.x + radius;
    let (w, depth) = (mask.width, &capture.depth_m);
    mask.data
        .iter()
        .enumerate()
        .filter(|&(i, &m)| m && depth.data[i].is_finite() && depth.data[i] > 0.0)
        .filter(|&(i, _)| {
            let p = capture.depth_camera.unproject(
                (i as u32 % w) as f64 + 0.5,
                (i as u32 / w) as f64 + 0.5,
                f64::from(depth.data[i]),
            );
            local(&p).x - axis_x > 1.05 * radius
        })
        .count()
}

/// Translation (mm), up-axis (°), full rotation (°) and scale (%) errors.
fn errors(
    fit: &Similarity3<f64>,
    fit_mesh: &TriMesh,
    truth: &Similarity3<f64>,
    true_mesh: &TriMesh,
) -> (f64, f64, f64, f64) {
    let ((cf, rf), (ct, rt)) = (box_in_frame(fit_mesh, fit), box_in_frame(true_mesh, truth));
    let up = (fit.rotation * Vector3::y())
        .angle(&(truth.rotation * Vector3::y()))
        .to_degrees();
    let d = fit.rotation * truth.rotation.transpose();
    let full = ((d.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees();
    (
        (cf - ct).norm() * 1e3,
        up,
        full,
        (rf / rt - 1.0).abs() * 100.0,
    )
}

/// What `bench objects` runs (the CLI's options).
pub struct Settings<'a> {
    pub regime: Regime,
    pub shape_sets: &'a [Shapes],
    pub prior: ObjectPrior,
    pub seeds: u64,
    /// Segment the depth image instead of using the capture's masks.
    pub segment: bool,
    /// Re-reflect large objects' rays off the depth data (`[mirror]`) before the ray angle.
    pub mirror: Option<DepthMirror>,
}

/// Simulates `seeds` captures of `regime` (objects from `shape_sets`), runs stage 1 with
/// `prior` on each (masks as the capture gives them, or segmentation with `segment`), prints
/// one row per object and a summary per category.
pub fn run(s: &Settings) -> Result<()> {
    let Settings {
        regime,
        shape_sets,
        prior,
        seeds,
        segment,
        ref mirror,
    } = *s;
    let mut shape_sets = shape_sets.to_vec();
    shape_sets.dedup();
    let model = BodyModel::builtin()?;
    let mut cfg = Stage1Config::default();
    cfg.fit.prior = prior;
    let scratch =
        std::env::temp_dir().join(format!("irmirror-bench-objects-{}", std::process::id()));
    let bar = indicatif::ProgressBar::new(seeds * shape_sets.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "bench objects {bar:40} {pos}/{len} captures {elapsed}/{eta}",
        )
        .expect("valid template"),
    );
    let mut rows = Vec::new();
    for (&shapes, seed) in shape_sets
        .iter()
        .flat_map(|s| (0..seeds).map(move |seed| (s, seed)))
    {
        let scene = regime_scene(&model, regime, shapes, seed)?;
        let sim = irmirror_sim::simulate(&model, &scene, seed)?;
        let dir = scratch.join(format!("{seed}"));
        sim.write(&model, &dir, seed)?;
        let mut capture = Capture::load(&dir).context("the simulated capture does not load")?;
        let handles: Vec<usize> = capture
            .objects
            .iter()
            .zip(sim.object_poses.iter().zip(&sim.object_meshes))
            .map(|(o, (truth, mesh))| match (&o.mask, o.category) {
                (Some(m), Category::Mug) => handle_pixels(&capture, m, truth, mesh),
                _ => 0,
            })
            .collect();
        if segment {
            capture.objects.iter_mut().for_each(|o| o.mask = None);
        }
        let t0 = Instant::now();
        let objects = reconstruct_objects(&capture, &cfg, seed)
            .with_context(|| format!("seed {seed}: stage 1"))?;
        let time_s = t0.elapsed().as_secs_f64() / objects.objects.len() as f64;
        let true_world = irmirror_sim::world::World::new(&model, &scene, None)?;
        let scales: Vec<f64> = objects
            .objects
            .iter()
            .map(|o| o.depth_from_object.scale)
            .collect();
        let angles = ray_angles_deg(
            (&capture.thermal_camera, &capture.depth_from_thermal),
            &objects.placed(),
            &true_world.objects,
            Some(&sim.reflection_mask),
            |rays| {
                if let Some(m) = mirror {
                    irmirror_recon::depth_mirror::refine(
                        rays,
                        &capture.depth_m,
                        &capture.depth_camera,
                        &capture.depth_from_thermal.translation,
                        &scales,
                        m,
                    );
                }
            },
        );
        for (k, (truth, true_mesh)) in sim.object_poses.iter().zip(&sim.object_meshes).enumerate() {
            // Segmented objects come largest first: pair each true object with the nearest fit.
            let fit = if segment {
                objects
                    .objects
                    .iter()
                    .min_by(|a, b| {
                        (a.depth_from_object.translation - truth.translation)
                            .norm()
                            .total_cmp(
                                &(b.depth_from_object.translation - truth.translation).norm(),
                            )
                    })
                    .expect("at least one object")
            } else {
                &objects.objects[k]
            };
            let category = scene.objects[k].shape.category();
            let fit_mesh = irmirror_eval::views::object_mesh(fit)?;
            let (t, up, full, s) = errors(&fit.depth_from_object, &fit_mesh, truth, true_mesh);
            rows.push(Row {
                seed,
                shapes,
                category,
                translation_mm: t,
                up_deg: up,
                rotation_deg: (category == Category::Mug).then_some(full),
                handle_seen: handles[k] >= HANDLE_SEEN_PX,
                handle_px: handles[k],
                scale_pct: s,
                wall_pct: wall_error(&fit.shape, &scene.objects[k].shape),
                chamfer_mm2: irmirror_sdf::quality::chamfer(&fit_mesh, true_mesh, 5000, 0) * 1e6,
                side_mm: (category == Category::Car)
                    .then(|| near_side_mm(&fit_mesh, true_mesh, truth)),
                ray_deg: (!angles[k].is_empty())
                    .then(|| median(angles[k].iter().map(|a| a.0).collect())),
                reflection_ray_deg: {
                    let on: Vec<f64> = angles[k].iter().filter(|a| a.1).map(|a| a.0).collect();
                    (!on.is_empty()).then(|| median(on))
                },
                time_s,
            });
        }
        std::fs::remove_dir_all(&dir).ok();
        bar.inc(1);
    }
    bar.finish_and_clear();
    std::fs::remove_dir_all(&scratch).ok();
    println!(
        "stage 1 ({prior:?} prior) on the {regime} regime ({} shapes), seeds 0–{}, {} objects, masks {}, ray angle {}, {} threads",
        shape_sets
            .iter()
            .map(|s| format!("{s:?}"))
            .collect::<Vec<_>>()
            .join(" and "),
        seeds.saturating_sub(1),
        rows.len(),
        if segment { "segmented" } else { "given" },
        match mirror {
            Some(m) => format!(
                "with the mirror from the depth data (window ±{} of the size)",
                m.radius_rel
            ),
            None => "of the fit's mirror".into(),
        },
        rayon::current_num_threads()
    );
    println!(
        "\n| seed | shapes | object | translation (mm) | up axis (°) | rotation (°) (handle pixels) | scale (%) | wall (%) | Chamfer (mm²) | car side (mm) | ray angle (°) | on the reflection (°) | time per object (s) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in &rows {
        let rot = r.rotation_deg.map_or("–".to_string(), |x| {
            if r.handle_seen {
                format!("{x:.1} ({} px)", r.handle_px)
            } else {
                format!("{x:.1} (hidden: {} px)", r.handle_px)
            }
        });
        let wall = r.wall_pct.map_or("–".to_string(), |w| format!("{w:.0}"));
        let side = r.side_mm.map_or("–".to_string(), |w| format!("{w:.1}"));
        let ray = r.ray_deg.map_or("–".to_string(), |w| format!("{w:.3}"));
        let on = r
            .reflection_ray_deg
            .map_or("–".to_string(), |w| format!("{w:.3}"));
        println!(
            "| {} | {} | {} | {:.1} | {:.2} | {rot} | {:.1} | {wall} | {:.2} | {side} | {ray} | {on} | {:.2} |",
            r.seed,
            set_name(r.shapes),
            r.category,
            r.translation_mm,
            r.up_deg,
            r.scale_pct,
            r.chamfer_mm2,
            r.time_s
        );
    }
    println!(
        "\nmedian / 90th percentile / max (goals: ≤ 5 mm, ≤ 3°, ≤ 3 %, ≤ 2 s per object); mug rotation over the mugs whose handle was seen\n"
    );
    println!(
        "| object | shapes | n | translation (mm) | up axis (°) | rotation (°) | scale (%) | wall (%) | Chamfer (mm²) | car side (mm) | ray angle (°) | on the reflection (°) | time per object (s) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut groups: Vec<(Category, usize)> = rows
        .iter()
        .map(|r| {
            let set = shape_sets.iter().position(|s| *s == r.shapes);
            (r.category, set.expect("a run set"))
        })
        .collect();
    groups.sort();
    groups.dedup();
    for (c, set) in groups {
        let sel: Vec<&Row> = rows
            .iter()
            .filter(|r| r.category == c && r.shapes == shape_sets[set])
            .collect();
        let col = |f: &dyn Fn(&Row) -> Option<f64>| {
            let v: Vec<f64> = sel.iter().filter_map(|r| f(r)).collect();
            if v.is_empty() {
                "–".to_string()
            } else {
                stats(v)
            }
        };
        println!(
            "| {c} | {} | {}{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            set_name(shape_sets[set]),
            sel.len(),
            match sel
                .iter()
                .filter(|r| r.rotation_deg.is_some() && !r.handle_seen)
                .count()
            {
                0 => String::new(),
                hidden => format!(" ({hidden} handle hidden)"),
            },
            col(&|r| Some(r.translation_mm)),
            col(&|r| Some(r.up_deg)),
            col(&|r| r.rotation_deg.filter(|_| r.handle_seen)),
            col(&|r| Some(r.scale_pct)),
            col(&|r| r.wall_pct),
            col(&|r| Some(r.chamfer_mm2)),
            col(&|r| r.side_mm),
            col(&|r| r.ray_deg),
            col(&|r| r.reflection_ray_deg),
            col(&|r| Some(r.time_s)),
        );
    }
    Ok(())
}

/// How a shape set stands to the learned priors.
fn set_name(s: Shapes) -> &'static str {
    match s {
        Shapes::Simple => "two-parameter",
        Shapes::Family => "in family",
        Shapes::Unseen => "out of family",
    }
}

/// The upper median.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// "median / 90th percentile / max".
fn stats(mut v: Vec<f64>) -> String {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    let f = |x: f64| {
        if x < 10.0 {
            format!("{x:.2}")
        } else {
            format!("{x:.1}")
        }
    };
    format!("{} / {} / {}", f(q(0.5)), f(q(0.9)), f(v[v.len() - 1]))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_near_side_is_the_one_toward_the_camera() {
        use irmirror_geom::nalgebra::Vector3;
        // A unit cube 2 m in front of the camera along the object's lateral axis (Z turned
        // to the depth frame's X), and a fit 5 mm deeper and 30 mm wider on the far side.
        let frame = irmirror_geom::Similarity3 {
            rotation: irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::new(
                0.0,
                std::f64::consts::FRAC_PI_2,
                0.0,
            )),
            translation: Vector3::zeros(),
            scale: 1.0,
        };
        let placed = |near: f64, far: f64| {
            let mut m = irmirror_geom::mesh::unit_cube();
            m.map_vertices(|v| {
                let z = if v[2] < 0.5 { 2.0 + near } else { 3.0 + far };
                (frame.rotation * Vector3::new(f64::from(v[0]), f64::from(v[1]), z))
                    .map(|x| x as f32)
                    .into()
            });
            m
        };
        let side = super::near_side_mm(&placed(0.005, 0.03), &placed(0.0, 0.0), &frame);
        assert!((side - 5.0).abs() < 1e-3, "{side}");
        // Seen from the other side (the car behind the camera), the other face is near.
        let (a, b) = (placed(-5.005, -4.97), placed(-5.0, -5.0));
        let side = super::near_side_mm(&a, &b, &frame);
        assert!((side - 30.0).abs() < 1e-3, "{side}");
    }

    #[test]
    fn box_in_a_rotated_frame() {
        use irmirror_geom::nalgebra::{Matrix3, Vector3};
        let mut cube = irmirror_geom::mesh::unit_cube();
        let frame = irmirror_geom::Similarity3 {
            rotation: irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::new(0.3, -0.5, 0.2)),
            translation: Vector3::new(1.0, 2.0, 3.0),
            scale: 2.0,
        };
        // The cube [0, 1]³ in the frame's axes, shifted by (1, 2, 3).
        cube.map_vertices(|v| {
            (frame.rotation * Vector3::from(v.map(f64::from)) + frame.translation)
                .map(|x| x as f32)
                .into()
        });
        let (c, r) = super::box_in_frame(&cube, &frame);
        assert!(
            (c - (frame.rotation * Vector3::repeat(0.5) + frame.translation)).norm() < 1e-5,
            "{c}"
        );
        assert!((r - 3f64.sqrt() / 2.0).abs() < 1e-5, "{r}");
        // In the camera's axes the same cube's box is larger.
        let (_, r_axis) = super::box_in_frame(
            &cube,
            &irmirror_geom::Similarity3 {
                rotation: Matrix3::identity(),
                ..frame
            },
        );
        assert!(r_axis > r + 0.05);
    }

    /// A flat mirror turned by δ turns a reflected ray in the plane of the turn by 2δ: a car's
    /// door filling the view, the fit turned 0.5° about the vertical, reads ≈ 1.0°; the truth
    /// against itself 0.
    #[test]
    fn a_door_turned_by_half_a_degree_reflects_one_degree_off() {
        use super::{PinholeCamera, PlacedSdf, Rigid3, Shape, Similarity3, Vector3};
        use irmirror_geom::rotation::axis_angle_to_matrix;
        let car = |yaw_deg: f64| PlacedSdf {
            sdf: Shape::Car {
                cabin: 0.5,
                height: 0.3,
            }
            .sdf(),
            depth_from_object: Similarity3::new(
                axis_angle_to_matrix(&Vector3::new(0.0, yaw_deg.to_radians(), 0.0)),
                Vector3::zeros(),
                2.0,
            )
            .unwrap(),
        };
        let camera = PinholeCamera {
            width: 32,
            height: 24,
            fx: 120.0,
            fy: 120.0,
            cx: 16.0,
            cy: 12.0,
        };
        // Looking along −Z (a half turn about Y) at the door's middle, 2.2 m from it.
        let pose = Rigid3::new(
            axis_angle_to_matrix(&Vector3::new(0.0, std::f64::consts::PI, 0.0)),
            Vector3::new(0.0, -0.26, 3.0),
        )
        .unwrap();
        let same = super::ray_angles_deg((&camera, &pose), &[car(0.0)], &[car(0.0)], None, |_| {});
        assert_eq!(same[0].len(), 32 * 24, "every pixel sees the door");
        assert!(same[0].iter().all(|a| a.0 < 1e-9 && !a.1), "{:?}", same[0]);
        let turned =
            super::ray_angles_deg((&camera, &pose), &[car(0.5)], &[car(0.0)], None, |_| {});
        let m = super::median(turned[0].iter().map(|a| a.0).collect());
        // Rays off the plane of the turn turn a little less (measured 0.989°).
        assert!((m - 1.0).abs() < 0.02, "median {m}°");
    }

    #[test]
    fn stats_are_order_statistics() {
        assert_eq!(super::stats(vec![3.0, 1.0, 2.0]), "2.00 / 3.00 / 3.00");
        assert_eq!(
            super::stats((1..=11).map(f64::from).rev().collect()),
            "6.00 / 10.0 / 11.0"
        );
    }
}
