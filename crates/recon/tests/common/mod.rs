//! Helpers shared by the stage-2 test binaries (`human`, `pose`, `radiometric`): the body model and
//! prior, simulated car and tabletop captures with the true objects' reflected rays, and the
//! stage-2 problem on them. Each binary uses a subset.
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
        irmirror_recon::pipeline::footprint_rays(cam, &dft, &objs, &trace, normals)
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
