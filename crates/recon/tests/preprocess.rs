//! Stage 0 on simulated captures: exact recovery without noise, IoU ≥ 0.9 at NETD 50 mK, a
//! clear error when there is no reflection; and the mask's reflected rays past the table's edge.

use irmirror_body::BodyModel;
use irmirror_body::prior::generator::PoseGenerator;
use irmirror_capture::{Capture, Image};
use irmirror_recon::{PreprocessConfig, ReconError, Threshold, preprocess};
use irmirror_sim::scene::{SceneFile, Sensor, ThermalPreset, car};
use irmirror_sim::simulate;
use std::path::PathBuf;
use std::sync::OnceLock;

fn model() -> &'static BodyModel {
    static M: OnceLock<BodyModel> = OnceLock::new();
    M.get_or_init(|| BodyModel::builtin().unwrap())
}

fn car_scene(seed: u64, sensor: Sensor) -> SceneFile {
    let mut rng = irmirror_geom::rng::seeded(seed, 0);
    let (name, pose) = PoseGenerator::new(model()).sample(&mut rng);
    let mut s = car(
        &mut rng,
        (name.to_string(), pose),
        irmirror_body::Phenotype::default(),
        ThermalPreset::Lepton,
    );
    s.sensor = sensor;
    s
}

fn capture(name: &str, scene: &SceneFile, seed: u64) -> (Capture, Image<bool>, PathBuf) {
    let dir = std::env::temp_dir().join(format!("irmirror-recon-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let sim = simulate(model(), scene, seed).unwrap();
    sim.write(model(), &dir, seed).unwrap();
    (Capture::load(&dir).unwrap(), sim.reflection_mask, dir)
}

fn iou(a: &Image<bool>, b: &Image<bool>) -> (usize, usize) {
    let inter = a
        .data
        .iter()
        .zip(&b.data)
        .filter(|(x, y)| **x && **y)
        .count();
    let union = a
        .data
        .iter()
        .zip(&b.data)
        .filter(|(x, y)| **x || **y)
        .count();
    (inter, union)
}

#[test]
fn noise_free_mask_is_recovered_exactly() {
    let (cap, truth, dir) = capture("clean", &car_scene(1, Sensor::ideal()), 1);
    let cfg = PreprocessConfig {
        threshold: Threshold::DeltaK(0.01),
        open_px: 0,
        close_px: 0,
        min_region_px: 0,
        ..Default::default()
    };
    let p = preprocess(&cap, &cfg).unwrap();
    let (inter, union) = iou(&p.mask, &truth);
    assert!(union > 50);
    assert_eq!(
        inter,
        union,
        "mask differs from the truth in {} pixels",
        union - inter
    );
    // Edges are a subset of the mask.
    assert!(p.edges.data.iter().zip(&p.mask.data).all(|(e, m)| !e || *m));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn mask_at_netd_50mk_has_iou_above_0_9() {
    // NETD 50 mK and 14-bit counts on pixel-centre rays: the noise alone. (With 2×2 supersampling
    // and 0.5 px optics blur, partly covered pixels around thin limbs also cross the threshold and
    // the IoU against the pixel-centre truth drops to ≈ 0.6–0.8; see the issue note.)
    let sensor = Sensor {
        supersample: 1,
        blur_px: 0.0,
        ..Sensor::default()
    };
    for seed in [1, 2, 3] {
        let (cap, truth, dir) = capture(
            &format!("noisy{seed}"),
            &car_scene(seed, sensor.clone()),
            seed,
        );
        let p = preprocess(&cap, &PreprocessConfig::default()).unwrap();
        let (inter, union) = iou(&p.mask, &truth);
        let v = inter as f64 / union as f64;
        let mut tr: Vec<f64> = p
            .rise_k
            .data
            .iter()
            .zip(&truth.data)
            .filter(|(_, t)| **t)
            .map(|(r, _)| *r)
            .collect();
        tr.sort_by(f64::total_cmp);
        let q = |f: f64| tr[((tr.len() - 1) as f64 * f) as usize];
        let fp = p
            .mask
            .data
            .iter()
            .zip(&truth.data)
            .filter(|(m, t)| **m && !**t)
            .count();
        let fnn = p
            .mask
            .data
            .iter()
            .zip(&truth.data)
            .filter(|(m, t)| !**m && **t)
            .count();
        let onobj = truth
            .data
            .iter()
            .zip(&p.object_pixels.data)
            .filter(|(t, o)| **t && !**o)
            .count();
        assert!(
            v >= 0.9,
            "seed {seed}: IoU {v:.3} ({inter}/{union}), fp {fp} fn {fnn} truth-not-on-object {onobj}, threshold {:.3} K, noise {:.3} K, truth rise q10 {:.3} q50 {:.3} q90 {:.3}",
            p.threshold_k,
            p.noise_k,
            q(0.1),
            q(0.5),
            q(0.9)
        );
        std::fs::remove_dir_all(dir).ok();
    }
}

#[test]
fn a_capture_without_reflection_is_reported() {
    let mut s = car_scene(4, Sensor::default());
    s.person.skin_c = s.ambient_c;
    s.person.clothing_c = s.ambient_c;
    let (cap, _, dir) = capture("none", &s, 4);
    match preprocess(&cap, &PreprocessConfig::default()) {
        Err(e @ ReconError::NoReflection { .. }) => {
            assert!(e.to_string().contains("no reflection"))
        }
        Err(e) => panic!("expected NoReflection, got {e}"),
        Ok(p) => panic!(
            "expected NoReflection, got a mask of {} pixels (threshold {:.3} K)",
            p.mask.data.iter().filter(|m| **m).count(),
            p.threshold_k
        ),
    }
    std::fs::remove_dir_all(dir).ok();
}

/// Random byte flips in capture.toml and in the images never panic: the loader and stage 0
/// either accept the damaged capture or say what is wrong (400 deterministic mutations, spread
/// over the TOML and every PNG: 1–8 random bytes flipped, or 1–3 digits of the TOML changed).
#[test]
fn random_byte_flips_never_panic() {
    use rand::{Rng, SeedableRng};
    let (_, _, dir) = capture("flips", &car_scene(6, Sensor::default()), 6);
    let mut files = vec![dir.join("capture.toml")];
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "png") {
            files.push(p);
        }
    }
    assert!(files.len() >= 3, "{files:?}");
    let originals: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let (mut loaded, mut refused) = (0, 0);
    for trial in 0..400 {
        let k = trial % files.len();
        let mut bytes = originals[k].clone();
        if k == 0 && trial % 2 == 0 {
            // Numbers changed but the TOML still parses: sizes, focal lengths, units, poses.
            let digits: Vec<usize> = (0..bytes.len())
                .filter(|&i| bytes[i].is_ascii_digit())
                .collect();
            for _ in 0..rng.random_range(1..=3) {
                let i = digits[rng.random_range(0..digits.len())];
                bytes[i] = b'0' + rng.random_range(0..10u8);
            }
        } else {
            for _ in 0..rng.random_range(1..=8) {
                let i = rng.random_range(0..bytes.len());
                bytes[i] ^= rng.random_range(1..=255u8);
            }
        }
        std::fs::write(&files[k], &bytes).unwrap();
        let outcome = std::panic::catch_unwind(|| match Capture::load(&dir) {
            Ok(c) => {
                let _ = preprocess(&c, &PreprocessConfig::default());
                true
            }
            Err(e) => {
                assert!(!e.to_string().is_empty());
                false
            }
        });
        match outcome {
            Ok(true) => loaded += 1,
            Ok(false) => refused += 1,
            Err(_) => panic!(
                "trial {trial}: flipping bytes of {} panicked",
                files[k].display()
            ),
        }
        std::fs::write(&files[k], &originals[k]).unwrap();
    }
    // Both outcomes occur: the mutations reach the parsers, not only comments or padding.
    assert!(
        refused > 50 && loaded > 10,
        "{loaded} loaded, {refused} refused"
    );
    std::fs::remove_dir_all(dir).ok();
}

/// A paper-like tabletop mug whose reflection shows the person past the table's near edge
/// (the tuning set's first mug, seed 21000): its pixels' reflected rays meet the support plane
/// 0.4–0.5 m out, below the depth camera's view, where the simulated table has ended. With the
/// plane taken as known only where the depth camera sees it, the reflection's pixels keep their
/// rays; with the plane blocking everywhere within reach (before session 70) none did, and the
/// true person scored "nobody there".
#[test]
fn a_reflection_past_the_tables_edge_keeps_its_rays() {
    use irmirror_recon::pipeline::{
        FootprintBudget, ReconConfig, footprint_rays, reflected_rays, unblocked,
    };
    use irmirror_recon::pipeline::{PlaneOccluder, SeenPlane};
    use irmirror_sim::presets::{Cell, Shapes, benchmark_scene};
    let (scene, _) =
        benchmark_scene(model(), Cell::TabletopMug, Shapes::Simple, 21000, 30.0, 0).unwrap();
    let (cap, _, dir) = capture("table-edge", &scene, 21000);
    let cfg = ReconConfig::default();
    let pre = preprocess(&cap, &cfg.preprocess).unwrap();
    let objects = irmirror_recon::objects::reconstruct_objects(&cap, &cfg.objects, 0).unwrap();
    let plane = objects.ground.plane.expect("the table is seen");
    let with_rays = |pixels: &[u32]| {
        let mut has = vec![false; pre.mask.data.len()];
        pixels.iter().for_each(|&p| has[p as usize] = true);
        pre.mask
            .data
            .iter()
            .zip(&has)
            .filter(|(m, h)| **m && **h)
            .count()
    };
    let mask_px = pre.mask.data.iter().filter(|&&m| m).count();
    let kept = with_rays(&reflected_rays(&cap, &objects, &pre.mask, &cfg).pixel);
    let placed = objects.placed();
    let (trace, normals) = cfg.rays_settings();
    let all = footprint_rays(
        &cap.thermal_camera,
        &cap.depth_from_thermal,
        &placed,
        &trace,
        normals,
        FootprintBudget::new(&cfg.human_settings().radiometric, mask_px),
    );
    let blind = PlaneOccluder {
        plane: &plane,
        seen: None,
    };
    let before = with_rays(&unblocked(&all, &placed, Some(&blind), &trace).pixel);
    // Seen, the table still blocks the rays that meet it in view.
    let seen = PlaneOccluder {
        plane: &plane,
        seen: Some(SeenPlane {
            depth_m: &cap.depth_m,
            camera: &cap.depth_camera,
            mask: &pre.mask,
        }),
    };
    let with_seen = unblocked(&all, &placed, Some(&seen), &trace);
    assert!(
        mask_px >= 20 && kept * 10 >= mask_px * 9 && before * 5 <= mask_px,
        "{mask_px} mask pixels: {kept} keep a ray, {before} before"
    );
    let no_plane = unblocked(&all, &placed, None, &trace);
    assert!(
        with_seen.len() < no_plane.len(),
        "the table still blocks where it is seen"
    );
    std::fs::remove_dir_all(dir).ok();
}
