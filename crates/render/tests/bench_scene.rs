//! The reference scene (`assets/bench/scene_sphere160.json`): the traced mirror sphere gives
//! the stated number of reflected rays and the hard renderer reproduces the reference mask.

use irmirror_geom::Rigid3;
use irmirror_render::bench_scene::BenchScene;
use irmirror_render::hard::hard_mask;
use irmirror_render::{Normals, SoftRenderer, SurfaceMethod, TraceParams, reflect_camera};
use std::path::PathBuf;

#[test]
fn hard_mask_reproduces_the_reference() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets/bench/scene_sphere160.json");
    let scene = BenchScene::load(&path).expect("the reference scene ships in assets/bench/");
    let trace = TraceParams {
        coarse_tol_rel: 1e-6,
        method: SurfaceMethod::SphereTrace { steps: 3 },
        max_iters: 4096,
    };
    let rays = reflect_camera(
        &scene.camera,
        &Rigid3::identity(),
        std::slice::from_ref(&scene.sphere),
        &trace,
        Normals::Raw,
    );
    assert_eq!(
        rays.len(),
        6980,
        "the scene states 6,980 camera rays hit the sphere"
    );
    let r = SoftRenderer::new(&scene.vertices, &scene.triangles);
    let hard = hard_mask(&rays, r.bvh(), &scene.vertices, &scene.triangles);
    let reference: Vec<bool> = scene.reference_hard.iter().map(|&x| x > 0.5).collect();
    let inter = hard
        .iter()
        .zip(&reference)
        .filter(|(a, b)| **a && **b)
        .count();
    let union = hard
        .iter()
        .zip(&reference)
        .filter(|(a, b)| **a || **b)
        .count();
    assert_eq!(reference.iter().filter(|x| **x).count(), 146);
    assert!(
        inter as f64 / union as f64 > 0.99,
        "IoU {}",
        inter as f64 / union as f64
    );
}

#[test]
fn bad_scene_files_are_errors() {
    let dir = std::env::temp_dir().join(format!("irmirror-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("scene.json");
    std::fs::write(&p, "{ not json").unwrap();
    assert!(BenchScene::load(&p).is_err());
    let npy = dir.join("m.npy");
    std::fs::write(
        &npy,
        b"\x93NUMPY\x01\x00v\x00{'descr': '|u1', 'fortran_order': False, 'shape': (120, 160), }",
    )
    .unwrap();
    let e = irmirror_render::npy::read_2d(&npy).unwrap_err().to_string();
    assert!(e.contains("m.npy"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
