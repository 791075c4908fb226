//! Radiometric closed forms and agreement with the renderer.

mod common;

use common::{model, small_scene};
use irmirror_capture::planck::{ZERO_C_K, band_radiance, temperature_of};
use irmirror_geom::Rigid3;
use irmirror_render::hard::hard_mask;
use irmirror_render::{Bvh, Normals, SurfaceMethod, TraceParams, reflect_camera};
use irmirror_sim::simulate;
use irmirror_sim::world::{World, place_body};
use nalgebra::Vector3;

#[test]
fn isothermal_enclosure_renders_uniform_whatever_the_emissivity() {
    // Kirchhoff: inside an enclosure at one temperature every surface looks like a black body at
    // that temperature, ε B(T) + (1 − ε) B(T) = B(T), for any ε.
    for e in [0.05, 0.5, 0.91] {
        let mut s = small_scene();
        s.person.skin_c = 22.0;
        s.person.clothing_c = 22.0;
        for o in &mut s.objects {
            o.emissivity = e;
        }
        s.table.as_mut().unwrap().emissivity = 1.0 - e;
        let sim = simulate(model(), &s, 0).unwrap();
        let b = band_radiance(22.0 + ZERO_C_K);
        for &l in &sim.radiance.0.data {
            assert!((l / b - 1.0).abs() < 1e-12, "ε = {e}: {l} vs {b}");
        }
    }
    // …and a hot person breaks the uniformity (the test can fail).
    let sim = simulate(model(), &small_scene(), 0).unwrap();
    assert!(sim.report.reflection_pixels > 0 && sim.report.reflection_contrast_k > 0.3);
}

#[test]
fn perfect_mirror_shows_the_person_where_the_hard_renderer_says() {
    // One convex mirror and no table: nothing but the body can stop a reflected ray, which is
    // the hard renderer's model too.
    let mut s = small_scene();
    s.table = None;
    s.objects = vec![irmirror_sim::scene::SceneObject {
        shape: irmirror_sim::shapes::Shape::Sphere.into(),
        base_m: [0.0, -0.05, 0.75],
        yaw_rad: 0.0,
        scale_m: 0.12,
        emissivity: 0.0,
        temp_c: 22.0,
    }];
    let m = model();
    let sim = simulate(m, &s, 0).unwrap();
    // The renderer's view: reflected rays of the thermal camera and the hard mask of the body.
    let world_from_depth = s.depth_camera.world_from_camera.to_rigid().unwrap();
    let body = place_body(m, &s, &world_from_depth.inverse()).unwrap();
    let world = World::new(m, &s, Some(&body)).unwrap();
    let dft: Rigid3<f64> = s.thermal_camera.depth_from_thermal.to_rigid().unwrap();
    let tight = TraceParams {
        coarse_tol_rel: 1e-5,
        method: SurfaceMethod::SphereTrace { steps: 3 },
        max_iters: 2048,
    };
    let rays = reflect_camera(
        &s.thermal_camera.intrinsics,
        &dft,
        &world.objects,
        &tight,
        Normals::Raw,
    );
    let verts: Vec<Vector3<f64>> = body
        .mesh
        .vertices
        .iter()
        .map(|v| Vector3::from(v.map(f64::from)))
        .collect();
    let hard = hard_mask(
        &rays,
        &Bvh::build(&verts, &body.mesh.triangles),
        &verts,
        &body.mesh.triangles,
    );
    // Hot pixels: a perfect mirror shows the body's temperature (≥ 29 °C) there, the room elsewhere.
    let hot: Vec<bool> = sim
        .radiance
        .0
        .data
        .iter()
        .map(|&l| temperature_of(l) > 27.0 + ZERO_C_K)
        .collect();
    let on_object: Vec<bool> = (0..hot.len())
        .map(|p| rays.pixel.contains(&(p as u32)))
        .collect();
    let (mut inter, mut union) = (0, 0);
    for p in 0..hot.len() {
        if on_object[p] {
            inter += usize::from(hot[p] && hard[p]);
            union += usize::from(hot[p] || hard[p]);
        }
    }
    assert!(union > 5, "the person should be reflected");
    // Only pixels whose reflected ray grazes the body's silhouette may differ.
    let nh = (0..hot.len()).filter(|&p| on_object[p] && hot[p]).count();
    let nr = (0..hot.len()).filter(|&p| on_object[p] && hard[p]).count();
    assert!(
        inter as f64 / union as f64 > 0.95,
        "IoU {inter}/{union}, hot {nh}, hard {nr}, sim mask {}",
        sim.report.reflection_pixels
    );
}

#[test]
fn same_seed_same_capture_and_noise_follows_netd() {
    let mut s = small_scene();
    s.sensor.netd_mk = 50.0;
    let a = simulate(model(), &s, 3).unwrap();
    let b = simulate(model(), &s, 3).unwrap();
    assert_eq!(a.thermal, b.thermal);
    assert_eq!(a.depth, b.depth);
    let c = simulate(model(), &s, 4).unwrap();
    assert_ne!(a.thermal, c.thermal);
    // The background frame's noise: std of counts ≈ NETD · gain · dL/dT.
    let (gain, _) = irmirror_sim::sensor::calibration(s.sensor.bits);
    let dl = band_radiance(22.5 + ZERO_C_K) - band_radiance(21.5 + ZERO_C_K);
    let expect = 0.05 * dl * gain;
    let ideal: Vec<f64> = a.radiance.1.data.iter().map(|l| l * gain).collect();
    let (_, offset) = irmirror_sim::sensor::calibration(s.sensor.bits);
    let resid: Vec<f64> = a
        .background
        .data
        .iter()
        .zip(&ideal)
        .map(|(c, i)| f64::from(*c) - offset - i)
        .collect();
    let sd = (resid.iter().map(|r| r * r).sum::<f64>() / resid.len() as f64).sqrt();
    assert!(
        (sd / expect - 1.0).abs() < 0.15,
        "noise σ {sd} counts vs NETD {expect}"
    );
}

/// Family and out-of-family shapes in a scene file: they round-trip through TOML next to the
/// simple shapes, stand on their base, and a shape that is neither is a clear error.
#[test]
fn family_shapes_round_trip_and_bad_shapes_are_named() {
    use irmirror_sim::scene::ObjectShape;
    let mut text = String::new();
    for unseen in [false, true] {
        let mut s = small_scene();
        let mut rng = irmirror_geom::rng::seeded(4, 2000);
        let (family, scale) = s.objects[1]
            .shape
            .replaced(s.objects[1].scale_m, unseen, &mut rng)
            .unwrap();
        assert!(
            matches!(
                (unseen, family),
                (false, ObjectShape::Family(_)) | (true, ObjectShape::Unseen(_))
            ) && family.category() == irmirror_geom::Category::Mug
        );
        s.objects[1].shape = family;
        s.objects[1].scale_m = scale;
        text = toml::to_string(&s).unwrap();
        let back: irmirror_sim::SceneFile = toml::from_str(&text).unwrap();
        assert_eq!(back, s, "simple and family shapes survive TOML");
        // The base point is on the surface.
        let sdf = family.sdf();
        assert!(sdf.distance(&Vector3::new(0.0, family.base_y(), 0.0)).abs() < 0.02);
        // An out-of-family parameter outside its range is refused, naming object and field.
        if let ObjectShape::Unseen(irmirror_sdf::UnseenShape::Mug(mut m)) = family {
            m.strap_reach = 5.0;
            s.objects[1].shape = ObjectShape::Unseen(irmirror_sdf::UnseenShape::Mug(m));
            let err = World::new(model(), &s, None).err().unwrap().to_string();
            assert!(
                err.contains("objects[1]") && err.contains("strap_reach"),
                "{err}"
            );
        }
    }
    // A bowl with parameters of neither kind.
    let bad = text.replacen("cut = ", "depthh = ", 1);
    let err = toml::from_str::<irmirror_sim::SceneFile>(&bad)
        .unwrap_err()
        .to_string();
    assert!(err.contains("an object shape"), "{err}");
}

/// The benchmark's persons wear motion-capture poses (not the pose prior's templates), drawn
/// reproducibly: the same cell and seed give the same scene, and the pose is one of the shipped
/// set's.
#[test]
fn benchmark_persons_wear_motion_capture_poses() {
    use irmirror_sim::presets::{Cell, Shapes, benchmark_scene};
    use irmirror_sim::scene::ObjectShape;
    let model = common::model();
    let set = irmirror_body::mocap::MocapSet::builtin().unwrap();
    let cases = [
        (Cell::TabletopBowl, Shapes::Simple, 5),
        (Cell::Car, Shapes::Simple, 6),
        (Cell::TabletopMug, Shapes::Family, 7),
    ];
    for (cell, shapes, seed) in cases {
        let (a, attempt) = benchmark_scene(model, cell, shapes, seed, 50.0, 0).unwrap();
        let (b, _) = benchmark_scene(model, cell, shapes, seed, 50.0, 0).unwrap();
        assert_eq!(a.person.rotvec_rad, b.person.rotvec_rad);
        // The cell's objects, from the families asked for.
        assert!(
            a.objects
                .iter()
                .all(|o| cell.category().is_none_or(|c| o.shape.category() == c)
                    && matches!(
                        (&o.shape, shapes),
                        (ObjectShape::Simple(_), Shapes::Simple)
                            | (ObjectShape::Family(_), Shapes::Family)
                    ))
        );
        let source = a
            .person
            .pose_name
            .strip_prefix("mocap ")
            .expect("a mocap pose");
        let k = set.sources.iter().position(|s| s == source).unwrap();
        assert_eq!(
            a.person.rotvec_rad, set.poses[k],
            "{cell} seed {seed} draw {attempt}"
        );
    }
}
