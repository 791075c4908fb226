//! Helpers shared by the stage-2 test binaries (`human`, `pose`, `polish`, `radiometric`): the
//! body model and prior, simulated car and tabletop captures with the true objects' reflected
//! rays, the stage-2 problem on them, and a person posed as the prior decodes a pose
//! (`with_posed`). Each binary uses a subset.
#![allow(dead_code)]

use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_render::reflect::ReflectedRays;
use irmirror_sim::presets::{Preset, preset_scene};
use irmirror_sim::scene::{SceneFile, ThermalPreset};
use irmirror_sim::simulate;
use nalgebra::Vector3;
use std::sync::OnceLock;

pub fn model() -> &'static BodyModel {
    static M: OnceLock<BodyModel> = OnceLock::new();
    M.get_or_init(|| BodyModel::builtin().unwrap())
}

pub fn prior() -> &'static PosePrior {
    static P: OnceLock<PosePrior> = OnceLock::new();
    P.get_or_init(|| PosePrior::builtin(candle_core::DType::F64).unwrap())
}

pub fn scene(seed: u64, is_car: bool) -> SceneFile {
    let t = if std::env::var("BOSON").is_ok() {
        ThermalPreset::Boson
    } else {
        ThermalPreset::Lepton
    };
    scene_with(seed, is_car, t)
}

pub fn scene_with(seed: u64, is_car: bool, t: ThermalPreset) -> SceneFile {
    let p = if is_car {
        Preset::Car
    } else {
        Preset::Tabletop
    };
    preset_scene(model(), p, t, seed).unwrap()
}

/// A car capture with the true objects' unoccluded reflected rays (stage 0–1 errors kept out).
pub fn car_capture(seed: u64) -> (SceneFile, irmirror_sim::Simulation, ReflectedRays<f64>) {
    let sc = scene(seed, true);
    let sim = simulate(model(), &sc, seed).unwrap();
    let rays = true_object_rays(&sc, &sim);
    (sc, sim, rays)
}

/// The true objects, placed.
fn true_objects(
    sc: &SceneFile,
    sim: &irmirror_sim::Simulation,
) -> Vec<irmirror_render::sdf::PlacedSdf> {
    sc.objects
        .iter()
        .zip(&sim.object_poses)
        .map(|(o, p)| irmirror_render::sdf::PlacedSdf {
            sdf: o.shape.sdf(),
            depth_from_object: *p,
        })
        .collect()
}

/// The unoccluded reflected rays of the true objects, one per pixel centre.
pub fn true_object_rays(sc: &SceneFile, sim: &irmirror_sim::Simulation) -> ReflectedRays<f64> {
    true_rays(sc, sim, false)
}

/// [`true_object_rays`] sampling each pixel's footprint (4 rays per pixel), as stage 2's
/// radiometric term sees a small reflection.
pub fn true_object_footprint_rays(
    sc: &SceneFile,
    sim: &irmirror_sim::Simulation,
) -> ReflectedRays<f64> {
    true_rays(sc, sim, true)
}

fn true_rays(
    sc: &SceneFile,
    sim: &irmirror_sim::Simulation,
    footprint: bool,
) -> ReflectedRays<f64> {
    let objs = true_objects(sc, sim);
    let dft = sc.thermal_camera.depth_from_thermal.to_rigid().unwrap();
    let (cam, trace, normals) = (
        &sc.thermal_camera.intrinsics,
        Default::default(),
        irmirror_render::reflect::Normals::Raw,
    );
    let all = if footprint {
        irmirror_recon::pipeline::footprint_rays(
            cam,
            &dft,
            &objs,
            &trace,
            normals,
            irmirror_recon::pipeline::FootprintBudget::new(&Default::default(), 0),
        )
    } else {
        irmirror_render::reflect::reflect_camera(cam, &dft, &objs, &trace, normals)
    };
    irmirror_recon::pipeline::unblocked(&all, &objs, None, &Default::default())
}

/// Stage 0's products as a test hands them over: the simulator's reflection mask, every pixel
/// on an object, a 50 mK noise.
pub fn preprocessed(
    sim: &irmirror_sim::Simulation,
    rise_k: irmirror_capture::Image<f64>,
    background_k: Option<f64>,
    psf_sigma_px: f64,
) -> irmirror_recon::preprocess::Preprocessed {
    let (w, h) = (rise_k.width, rise_k.height);
    irmirror_recon::preprocess::Preprocessed {
        rise_k,
        object_pixels: irmirror_capture::Image::filled(w, h, true),
        raw_mask: sim.reflection_mask.clone(),
        mask: sim.reflection_mask.clone(),
        edges: sim.reflection_mask.clone(),
        threshold_k: 0.1,
        noise_k: 0.05,
        background_k,
        psf_sigma_px,
    }
}

/// The true body's vertices (depth frame), in f64.
pub fn true_vertices(sim: &irmirror_sim::Simulation) -> Vec<Vector3<f64>> {
    sim.body
        .mesh
        .vertices
        .iter()
        .map(|v| Vector3::from(v.map(f64::from)))
        .collect()
}

/// The true body (depth frame), its BVH and the region of each triangle.
pub fn true_body(
    sim: &irmirror_sim::Simulation,
) -> (
    Vec<Vector3<f64>>,
    irmirror_render::Bvh<f64>,
    Vec<irmirror_body::Region>,
) {
    use irmirror_body::regions::{triangle_regions, vertex_regions};
    let verts = true_vertices(sim);
    let tris = &model().asset.faces;
    let bvh = irmirror_render::Bvh::build(&verts, tris);
    let regions = triangle_regions(&vertex_regions(model()).unwrap(), tris);
    (verts, bvh, regions)
}

/// Stage 2's problem on a simulated capture: the person seen through `rays`, facing the first
/// object, with `mask` and the floor given.
pub fn problem_for<'a>(
    sim: &irmirror_sim::Simulation,
    rays: &'a ReflectedRays<f64>,
    mask: &'a irmirror_capture::Image<bool>,
    up: Vector3<f64>,
    floor: Option<irmirror_recon::human::Floor>,
) -> irmirror_recon::human::HumanProblem<'a> {
    irmirror_recon::human::HumanProblem {
        model: model(),
        prior: prior(),
        rays,
        mask,
        up,
        objects_centre: sim.object_poses[0].translation,
        faces_objects: false,
        floor,
        radiometry: None,
        build: Default::default(),
    }
}

/// [`problem_for`] with the simulator's reflection mask and the floor under the true body.
pub fn floored_problem<'a>(
    sim: &'a irmirror_sim::Simulation,
    rays: &'a ReflectedRays<f64>,
    up: Vector3<f64>,
) -> irmirror_recon::human::HumanProblem<'a> {
    problem_for(
        sim,
        rays,
        &sim.reflection_mask,
        up,
        Some(true_floor(sim, &up)),
    )
}

/// [`problem_for`] with the simulator's reflection mask, the body's true up and no floor.
pub fn truth_problem<'a>(
    sc: &SceneFile,
    sim: &'a irmirror_sim::Simulation,
    rays: &'a ReflectedRays<f64>,
) -> irmirror_recon::human::HumanProblem<'a> {
    let (_, up) = true_root(sc, sim);
    problem_for(sim, rays, &sim.reflection_mask, up, None)
}

/// The floor under the true body (its lowest vertex on it), as the pipeline finds the ground
/// under a car.
pub fn true_floor(
    sim: &irmirror_sim::Simulation,
    up: &Vector3<f64>,
) -> irmirror_recon::human::Floor {
    let lowest = sim
        .body
        .mesh
        .vertices
        .iter()
        .map(|v| up.dot(&Vector3::from(v.map(f64::from))))
        .fold(f64::INFINITY, f64::min);
    irmirror_recon::human::Floor {
        up: *up,
        offset_m: lowest,
    }
}

/// The true root rotation (Anny → depth) and the body's up, depth frame.
pub fn true_root(
    sc: &SceneFile,
    sim: &irmirror_sim::Simulation,
) -> (nalgebra::Matrix3<f64>, Vector3<f64>) {
    let r = sim.body.depth_from_anny.rotation;
    (
        r * irmirror_geom::rotation::axis_angle_to_matrix(&Vector3::from(sc.person.rotvec_rad[0])),
        r * Vector3::z(),
    )
}

/// Stage 0's products with the thermal rise as it would hand them over: noise-free radiance
/// plus 50 mK of seeded noise (the term subtracts what noise of the stated σ scores), and the
/// simulator's optics (the term convolves the footprints with them).
pub fn thermal_preprocessed(
    sc: &SceneFile,
    sim: &irmirror_sim::Simulation,
) -> irmirror_recon::preprocess::Preprocessed {
    let (with, without) = &sim.radiance;
    let t_of = irmirror_capture::planck::temperature_of;
    let mut rng = <rand::rngs::StdRng as rand::SeedableRng>::seed_from_u64(5);
    let rise = irmirror_capture::Image {
        width: with.width,
        height: with.height,
        data: with
            .data
            .iter()
            .zip(&without.data)
            .map(|(a, b)| {
                let n: f64 =
                    rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                t_of(*a) - t_of(*b) + 0.05 * n
            })
            .collect(),
    };
    preprocessed(
        sim,
        rise,
        Some(sc.ambient_c + irmirror_capture::planck::ZERO_C_K),
        sc.sensor.blur_px,
    )
}

/// Parts of three poses: the kick's legs, a wave's arms, a look's head.
pub fn composite_pose() -> Vec<[f64; 3]> {
    let generator = irmirror_body::prior::generator::PoseGenerator::new(model());
    let mut rng = irmirror_geom::rng::seeded(5, 1);
    let wave = generator.template("wave", &mut rng).unwrap();
    let look = generator.template("look", &mut rng).unwrap();
    let names = &model().asset.meta.bone_names;
    let mut pose = kick();
    for (j, name) in names.iter().enumerate() {
        if name.contains("arm")
            || name.contains("wrist")
            || name.contains("clavicle")
            || name.contains("shoulder")
        {
            pose[j] = wave[j];
        } else if name.starts_with("neck") || name == "head" {
            pose[j] = look[j];
        }
    }
    pose
}

/// A kick from the prior's real training poses.
pub fn kick() -> Vec<[f64; 3]> {
    let set = irmirror_body::mocap::MocapSet::prior_training().unwrap();
    let kicks: Vec<usize> = (0..set.poses.len())
        .filter(|&i| set.sources[i].contains("kick") && !set.sources[i].contains("spin"))
        .collect();
    set.poses[kicks[kicks.len() / 2]].clone()
}

/// Car (`is_car`; else tabletop) seed 1 (Boson) with the person in `pose` as the prior decodes its encoding (so the
/// latent can state it; the mean adult), through its true objects and mask, the floor known:
/// runs `f` on the problem, the start (the true root and facing, the search's "stand" pose)
/// and a state's distance to the truth: the mean angle (degrees) between its decoded body
/// joints and the truth's, and its body's mean per-vertex distance to the true body (m).
pub fn with_posed(
    is_car: bool,
    pose: &[[f64; 3]],
    f: impl FnOnce(
        &irmirror_recon::human::HumanProblem<'_>,
        &irmirror_recon::human::HumanState,
        &dyn Fn(&irmirror_recon::human::HumanState) -> (f64, f64),
    ),
) {
    use irmirror_geom::rotation::axis_angle_to_matrix;
    use irmirror_recon::human::*;
    use irmirror_sim::scene::ThermalPreset;
    let mut sc = scene_with(1, is_car, ThermalPreset::Boson);
    sc.person.phenotype = irmirror_body::Phenotype::default();
    let latent = prior().encode(pose).unwrap();
    for (j, r) in prior().decode(&latent).unwrap().iter().enumerate().skip(1) {
        sc.person.rotvec_rad[j] = irmirror_geom::rotation::matrix_to_axis_angle(r).into();
    }
    let sim = irmirror_sim::simulate(model(), &sc, 1).unwrap();
    let rays = true_object_rays(&sc, &sim);
    let (r0, up) = true_root(&sc, &sim);
    let problem = floored_problem(&sim, &rays, up);
    let generator = irmirror_body::prior::generator::PoseGenerator::new(model());
    let mut rng = irmirror_geom::rng::seeded(0, 1);
    let stand = generator.template("stand", &mut rng).unwrap();
    let start = HumanState {
        translation: sim.body.joints[0],
        rotation: r0,
        height: HEIGHT_MEAN,
        build: Default::default(),
        latent: prior().encode(&stand).unwrap(),
        residual: Vec::new(),
    };
    let angle = |st: &HumanState| {
        let truth = sc.person.rotvec_rad[1..]
            .iter()
            .map(|r| axis_angle_to_matrix(&Vector3::from(*r)));
        let decoded = prior().decode(&st.latent).unwrap();
        let sum: f64 = decoded[1..]
            .iter()
            .zip(truth)
            .map(|(a, b)| ((a.transpose() * b).trace() - 1.0).clamp(-2.0, 2.0) / 2.0)
            .map(|c| c.acos().to_degrees())
            .sum();
        let mean_angle = sum / (decoded.len() - 1) as f64;
        let body = posed_body(model(), prior(), st).unwrap();
        let vertex_m = body
            .vertices
            .iter()
            .zip(&sim.body.mesh.vertices)
            .map(|(a, b)| (a - Vector3::from(b.map(f64::from))).norm())
            .sum::<f64>()
            / body.vertices.len() as f64;
        (mean_angle, vertex_m)
    };
    f(&problem, &start, &angle);
}
