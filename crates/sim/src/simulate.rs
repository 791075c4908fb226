//! Rendering a scene into a capture directory.

use crate::SimError;
use crate::scene::SceneFile;
use crate::sensor::{
    calibration, depth_counts, render_depth, shaded_rgb, thermal_counts, thermal_radiance,
};
use crate::world::{PlacedBody, SURFACE_OFFSET_M, Surface, World, place_body};
use irmirror_body::BodyModel;
use irmirror_capture::format::{
    CaptureFile, DepthSpec, ObjectSpec, RgbSpec, ThermalCameraSpec, ThermalSpec, ThermalUnits,
};
use irmirror_capture::planck::{ZERO_C_K, band_radiance, temperature_of};
use irmirror_capture::{FORMAT, Image, write_gray8_png, write_gray16_png};
use irmirror_geom::transform::RigidFile;
use irmirror_geom::{Ray, Rigid3, Similarity3, TriMesh};
use irmirror_render::reflect::reflect;
use nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;

/// Figures of a simulated capture.
#[derive(Clone, Debug, Serialize)]
pub struct SimReport {
    /// Thermal pixels whose mirror reflection (pixel-centre ray) shows the person.
    pub reflection_pixels: usize,
    /// Largest rise of apparent temperature over the background frame inside those pixels
    /// (noise-free), K.
    pub reflection_contrast_k: f64,
    /// Mean rise inside those pixels (noise-free), K.
    pub reflection_mean_rise_k: f64,
    /// Thermal pixels covered by objects.
    pub object_pixels: usize,
    /// Is the person directly visible in the thermal or depth camera?
    pub person_directly_visible: bool,
}

/// Everything rendered for one scene.
pub struct Simulation {
    /// The scene.
    pub scene: SceneFile,
    /// The placed body.
    pub body: PlacedBody,
    /// Raw thermal counts with the person.
    pub thermal: Image<u16>,
    /// Raw thermal counts without the person.
    pub background: Image<u16>,
    /// Noise-free radiance with and without the person (W m⁻² sr⁻¹).
    pub radiance: (Image<f64>, Image<f64>),
    /// Truth: thermal pixels whose reflection shows the person.
    pub reflection_mask: Image<bool>,
    /// Truth: thermal pixels whose pixel-centre ray hits an object.
    pub thermal_object_pixels: Image<bool>,
    /// Depth, 16-bit mm.
    pub depth: Image<u16>,
    /// Shaded RGB of the depth view.
    pub rgb: image::RgbImage,
    /// Visible object masks in depth pixels.
    pub masks: Vec<Image<bool>>,
    /// Object meshes, depth frame.
    pub object_meshes: Vec<TriMesh>,
    /// Object placements, depth frame.
    pub object_poses: Vec<Similarity3<f64>>,
    /// The IMU's unit "up" in the depth frame (world +Z with the sensor's tilt error).
    pub imu_up: Vector3<f64>,
    /// Shaded view of the person from the third camera, and its keypoints there (pixels).
    pub third_view: (image::RgbImage, Vec<Option<(f64, f64)>>),
    /// Figures.
    pub report: SimReport,
}

fn rigid(f: &RigidFile, what: &str) -> Result<Rigid3<f64>, SimError> {
    f.to_rigid()
        .map_err(|e| SimError::Scene(format!("{what}: {e}")))
}

/// Thermal pixels whose pixel-centre ray reflects off an object onto the person (the truth
/// reflection mask), the pixels that see an object at all, and whether any sees the person
/// directly.
fn reflection_truth(
    world: &World,
    camera: &irmirror_geom::PinholeCamera,
    depth_from_thermal: &Rigid3<f64>,
) -> (Vec<bool>, Vec<bool>, bool) {
    use rayon::prelude::*;
    let per_pixel: Vec<(bool, bool, bool)> = (0..camera.width * camera.height)
        .into_par_iter()
        .map(|p| {
            let ray = depth_from_thermal
                .transform_ray(&camera.pixel_ray::<f64>(p % camera.width, p / camera.width));
            match world.hit(&ray) {
                Some(h) if matches!(h.surface, Surface::Object(_)) => {
                    let r = Ray {
                        origin: h.point + h.normal * SURFACE_OFFSET_M,
                        dir: reflect(&ray.dir, &h.normal).normalize(),
                    };
                    (
                        matches!(
                            world.hit(&r).map(|x| x.surface),
                            Some(Surface::Person { .. })
                        ),
                        true,
                        false,
                    )
                }
                Some(h) => (false, false, matches!(h.surface, Surface::Person { .. })),
                None => (false, false, false),
            }
        })
        .collect();
    (
        per_pixel.iter().map(|x| x.0).collect(),
        per_pixel.iter().map(|x| x.1).collect(),
        per_pixel.iter().any(|x| x.2),
    )
}

/// How many thermal pixels show the person by reflection (cheap: no thermal rendering).
pub fn reflection_pixels(model: &BodyModel, scene: &SceneFile) -> Result<usize, SimError> {
    Ok(reflection_probe(model, scene)?.pixels)
}

/// What a scene shows of the person, without rendering radiance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Probe {
    /// Thermal pixels that see the person by reflection (pixel-centre rays).
    pub pixels: usize,
    /// Whether the thermal or the depth camera sees the person directly.
    pub directly_visible: bool,
}

/// The scene's reflection size, and whether either camera sees the person directly.
pub fn reflection_probe(model: &BodyModel, scene: &SceneFile) -> Result<Probe, SimError> {
    let depth_from_world = rigid(
        &scene.depth_camera.world_from_camera,
        "depth_camera.world_from_camera",
    )?
    .inverse();
    let body = place_body(model, scene, &depth_from_world)?;
    let with = World::new(model, scene, Some(&body))?;
    let dft = rigid(
        &scene.thermal_camera.depth_from_thermal,
        "thermal_camera.depth_from_thermal",
    )?;
    let (mask, _, thermal_sees) = reflection_truth(&with, &scene.thermal_camera.intrinsics, &dft);
    let (_, _, depth_sees) =
        reflection_truth(&with, &scene.depth_camera.intrinsics, &Rigid3::identity());
    Ok(Probe {
        pixels: mask.iter().filter(|&&m| m).count(),
        directly_visible: thermal_sees || depth_sees,
    })
}

/// Renders `scene` (noise drawn from `seed`).
pub fn simulate(model: &BodyModel, scene: &SceneFile, seed: u64) -> Result<Simulation, SimError> {
    for (name, cam) in [
        ("depth_camera", &scene.depth_camera.intrinsics),
        ("thermal_camera", &scene.thermal_camera.intrinsics),
        ("third_camera", &scene.third_camera.intrinsics),
    ] {
        cam.validate()
            .map_err(|e| SimError::Scene(format!("{name}: {e}")))?;
    }
    if scene.objects.is_empty() {
        return Err(SimError::Scene(
            "objects: a capture needs at least one reflecting object".into(),
        ));
    }
    if scene.sensor.supersample == 0 || !(1..=16).contains(&scene.sensor.bits) {
        return Err(SimError::Scene(
            "sensor: supersample must be ≥ 1 and bits in 1..=16".into(),
        ));
    }
    let world_from_depth = rigid(
        &scene.depth_camera.world_from_camera,
        "depth_camera.world_from_camera",
    )?;
    let depth_from_world = world_from_depth.inverse();
    let depth_from_thermal = rigid(
        &scene.thermal_camera.depth_from_thermal,
        "thermal_camera.depth_from_thermal",
    )?;
    let depth_from_third = depth_from_world
        * rigid(
            &scene.third_camera.world_from_camera,
            "third_camera.world_from_camera",
        )?;
    let body = place_body(model, scene, &depth_from_world)?;
    let with = World::new(model, scene, Some(&body))?;
    let without = World::new(model, scene, None)?;
    let tcam = scene.thermal_camera.intrinsics;
    let s = &scene.sensor;
    let ambient_k = scene.ambient_c + ZERO_C_K;
    // A pixel whose neighbourhood is flat to within a tenth of a millikelvin keeps the 4 × 4
    // probe: far below any sensor's NETD, and it spares most of the car door's rays (6.8 s
    // instead of 21.7 s for car seed 7).
    let tol = 1e-4 * (band_radiance(ambient_k + 0.5) - band_radiance(ambient_k - 0.5));
    let rad_with = thermal_radiance(&with, &tcam, &depth_from_thermal, s.supersample, tol);
    let rad_without = thermal_radiance(&without, &tcam, &depth_from_thermal, s.supersample, tol);
    let mut rng = irmirror_geom::rng::seeded(seed, 1);
    let thermal = thermal_counts(&rad_with, s, ambient_k, &mut rng);
    let mut rng_bg = irmirror_geom::rng::seeded(seed, 2);
    let background = thermal_counts(&rad_without, s, ambient_k, &mut rng_bg);

    // Truth reflection mask (pixel-centre rays, first mirror bounce) and direct visibility.
    let (mask, on_objects, mut direct) = reflection_truth(&with, &tcam, &depth_from_thermal);
    let object_pixels = on_objects.iter().filter(|o| **o).count();
    let thermal_object_pixels = Image {
        width: tcam.width,
        height: tcam.height,
        data: on_objects,
    };
    let rises: Vec<f64> = mask
        .iter()
        .enumerate()
        .filter(|(_, m)| **m)
        .map(|(p, _)| temperature_of(rad_with.data[p]) - temperature_of(rad_without.data[p]))
        .collect();
    let reflection_mask = Image {
        width: tcam.width,
        height: tcam.height,
        data: mask,
    };

    let dcam = scene.depth_camera.intrinsics;
    let dr = render_depth(&with, &dcam);
    direct |= dr
        .surface
        .iter()
        .any(|s| matches!(s, Some(Surface::Person { .. })));
    let mut rng_d = irmirror_geom::rng::seeded(seed, 3);
    let depth = depth_counts(&dr, s, &mut rng_d);
    let masks = (0..scene.objects.len())
        .map(|k| Image {
            width: dcam.width,
            height: dcam.height,
            data: dr
                .surface
                .iter()
                .map(|s| *s == Some(Surface::Object(k)))
                .collect(),
        })
        .collect();
    let rgb = shaded_rgb(&with, &dcam);

    let object_meshes = with
        .objects
        .iter()
        .map(|o| {
            let r = o.sdf.bounding_radius() * 1.05;
            let mut m = irmirror_geom::isosurface::isosurface(
                |p| o.sdf.distance(p),
                Vector3::repeat(-r),
                Vector3::repeat(r),
                64,
            );
            m.map_vertices(|v| {
                let p = o
                    .depth_from_object
                    .transform_point(&Vector3::from(v.map(f64::from)));
                [p.x as f32, p.y as f32, p.z as f32]
            });
            m
        })
        .collect();
    let object_poses = with.objects.iter().map(|o| o.depth_from_object).collect();
    let imu_up = {
        use rand_distr::{Distribution, Normal};
        let up = depth_from_world.rotation * Vector3::z();
        let mut rng_u = irmirror_geom::rng::seeded(seed, 4);
        let sigma = s.imu_up_noise_deg.max(0.0).to_radians();
        let tilt = if sigma > 0.0 {
            let n = Normal::new(0.0, sigma).expect("σ > 0");
            Vector3::new(
                n.sample(&mut rng_u),
                n.sample(&mut rng_u),
                n.sample(&mut rng_u),
            )
        } else {
            Vector3::zeros()
        };
        irmirror_geom::rotation::axis_angle_to_matrix(&(tilt - up * up.dot(&tilt))) * up
    };

    // Third view: shaded person (and scene) with the keypoints projected.
    let third_cam = scene.third_camera.intrinsics;
    let third_img = {
        let px: Vec<u8> = (0..third_cam.width * third_cam.height)
            .flat_map(|p| {
                let ray = depth_from_third.transform_ray(
                    &third_cam.pixel_ray::<f64>(p % third_cam.width, p / third_cam.width),
                );
                // Each surface its own colour (objects blue, as in irmirror's views), Lambert
                // shaded from the eye.
                match with.hit(&ray) {
                    Some(h) => {
                        let albedo: [f64; 3] = match h.surface {
                            Surface::Person { .. } => [250.0, 200.0, 175.0],
                            Surface::Object(_) => [90.0, 140.0, 230.0],
                            Surface::Table => [150.0, 130.0, 110.0],
                            Surface::Heat(_) => [230.0, 60.0, 40.0],
                        };
                        let shade = 0.3 + 0.7 * h.normal.dot(&ray.dir).abs();
                        albedo.map(|c| (c * shade).clamp(0.0, 255.0) as u8)
                    }
                    None => [235, 235, 240],
                }
            })
            .collect();
        image::RgbImage::from_raw(third_cam.width, third_cam.height, px).expect("sizes match")
    };
    let third_from_depth = depth_from_third.inverse();
    let kp2d = body
        .keypoints
        .iter()
        .map(|k| third_cam.project(&third_from_depth.transform_point(k)))
        .collect();

    let report = SimReport {
        reflection_pixels: rises.len(),
        reflection_contrast_k: rises.iter().copied().fold(0.0, f64::max),
        reflection_mean_rise_k: if rises.is_empty() {
            0.0
        } else {
            rises.iter().sum::<f64>() / rises.len() as f64
        },
        object_pixels,
        person_directly_visible: direct,
    };
    Ok(Simulation {
        scene: scene.clone(),
        body,
        thermal,
        background,
        radiance: (rad_with, rad_without),
        reflection_mask,
        thermal_object_pixels,
        depth,
        rgb,
        masks,
        object_meshes,
        object_poses,
        imu_up,
        third_view: (third_img, kp2d),
        report,
    })
}

impl Simulation {
    /// Writes the capture into `dir` (which must exist and be empty) with `truth/`.
    pub fn write(&self, model: &BodyModel, dir: &Path, seed: u64) -> Result<(), SimError> {
        let werr = |p: &Path, e: String| SimError::Write {
            path: p.to_path_buf(),
            reason: e,
        };
        let mk = |p: &Path| std::fs::create_dir_all(p).map_err(|e| werr(p, e.to_string()));
        mk(&dir.join("masks"))?;
        mk(&dir.join("truth/objects"))?;
        write_gray16_png(&self.depth, &dir.join("depth.png"))?;
        write_gray16_png(&self.thermal, &dir.join("thermal.png"))?;
        write_gray16_png(&self.background, &dir.join("thermal_background.png"))?;
        self.rgb
            .save(dir.join("rgb.png"))
            .map_err(|e| werr(&dir.join("rgb.png"), e.to_string()))?;
        let mut objects = Vec::new();
        for (k, (m, o)) in self.masks.iter().zip(&self.scene.objects).enumerate() {
            let mask = if m.data.iter().any(|&b| b) {
                let name = format!("masks/object_{k}.png");
                write_gray8_png(&m.map(|b| if b { 255 } else { 0 }), &dir.join(&name))?;
                Some(name)
            } else {
                None
            };
            objects.push(ObjectSpec {
                category: o.shape.category(),
                mask,
            });
        }
        let (gain, offset) = calibration(self.scene.sensor.bits);
        let capture = CaptureFile {
            format: FORMAT.into(),
            depth_camera: self.scene.depth_camera.intrinsics,
            depth: DepthSpec {
                file: "depth.png".into(),
                units_m: 0.001,
                up: Some(self.imu_up.into()),
            },
            thermal_camera: ThermalCameraSpec {
                intrinsics: self.scene.thermal_camera.intrinsics,
                depth_from_thermal: self.scene.thermal_camera.depth_from_thermal.clone(),
                // The sensor's blur is what the camera's datasheet would state.
                psf_sigma_px: (self.scene.sensor.blur_px > 0.0)
                    .then_some(self.scene.sensor.blur_px),
            },
            thermal: ThermalSpec {
                file: "thermal.png".into(),
                units: ThermalUnits::CountsLinear { gain, offset },
                background: vec!["thermal_background.png".into()],
            },
            rgb: Some(RgbSpec {
                file: "rgb.png".into(),
            }),
            objects,
            extra_cameras: vec![],
            description: format!(
                "irmirror simulate, seed {seed}, irmirror {}",
                env!("CARGO_PKG_VERSION")
            ),
        };
        let toml_text = toml::to_string(&capture).map_err(|e| werr(dir, e.to_string()))?;
        std::fs::write(dir.join("capture.toml"), toml_text)
            .map_err(|e| werr(&dir.join("capture.toml"), e.to_string()))?;

        // truth/
        let t = dir.join("truth");
        let scene_text = toml::to_string(&self.scene).map_err(|e| werr(&t, e.to_string()))?;
        std::fs::write(t.join("scene.toml"), scene_text).map_err(|e| werr(&t, e.to_string()))?;
        self.body
            .mesh
            .write(&t.join("body.ply"))
            .map_err(|e| werr(&t, e.to_string()))?;
        let v3 = |v: &Vector3<f64>| [v.x, v.y, v.z];
        let body_json = serde_json::json!({
            "frame": "depth camera (OpenCV axes), metres",
            "phenotype": self.scene.person.phenotype,
            "shape_coefficients": self.body.z,
            "rotvec_rad": self.scene.person.rotvec_rad,
            "pose_name": self.scene.person.pose_name,
            "anny_root_translation_m": v3(&self.body.anny_translation),
            "depth_from_anny": RigidFile::from_rigid(&self.body.depth_from_anny),
            "joints_m": model.asset.meta.bone_names.iter().zip(&self.body.joints).map(|(n, p)| (n.clone(), serde_json::json!(v3(p)))).collect::<serde_json::Map<_, _>>(),
            "keypoints_m": model.asset.meta.keypoint_labels.iter().zip(&self.body.keypoints).map(|(n, p)| (n.clone(), serde_json::json!(v3(p)))).collect::<serde_json::Map<_, _>>(),
        });
        let js = |v: &serde_json::Value| serde_json::to_string_pretty(v).expect("json serialises");
        std::fs::write(t.join("body.json"), js(&body_json)).map_err(|e| werr(&t, e.to_string()))?;
        let mut objs = Vec::new();
        for (k, (m, pose)) in self
            .object_meshes
            .iter()
            .zip(&self.object_poses)
            .enumerate()
        {
            m.write(&t.join(format!("objects/object_{k}.ply")))
                .map_err(|e| werr(&t, e.to_string()))?;
            let o = &self.scene.objects[k];
            objs.push(serde_json::json!({
                "shape": o.shape, "emissivity": o.emissivity, "temp_c": o.temp_c,
                "depth_from_object": {"rotation": RigidFile::from_rigid(&Rigid3 { rotation: pose.rotation, translation: pose.translation }).rotation,
                                      "translation_m": v3(&pose.translation), "scale_m": pose.scale},
                "mesh": format!("objects/object_{k}.ply"),
            }));
        }
        std::fs::write(t.join("objects.json"), js(&serde_json::json!(objs)))
            .map_err(|e| werr(&t, e.to_string()))?;
        let third = serde_json::json!({
            "intrinsics": self.scene.third_camera.intrinsics,
            "world_from_camera": self.scene.third_camera.world_from_camera,
            "depth_from_camera": RigidFile::from_rigid(&(rigid(&self.scene.depth_camera.world_from_camera, "")?.inverse() * rigid(&self.scene.third_camera.world_from_camera, "")?)),
            "keypoints_px": model.asset.meta.keypoint_labels.iter().zip(&self.third_view.1).map(|(n, p)| (n.clone(), serde_json::json!(p.map(|(u, v)| [u, v])))).collect::<serde_json::Map<_, _>>(),
            "image": "third_view.png",
        });
        std::fs::write(t.join("third_camera.json"), js(&third))
            .map_err(|e| werr(&t, e.to_string()))?;
        self.third_view
            .0
            .save(t.join("third_view.png"))
            .map_err(|e| werr(&t, e.to_string()))?;
        write_gray8_png(
            &self.reflection_mask.map(|b| if b { 255 } else { 0 }),
            &t.join("reflection_mask.png"),
        )?;
        std::fs::write(t.join("stats.json"), js(&serde_json::json!(self.report)))
            .map_err(|e| werr(&t, e.to_string()))?;

        // preview/: images for people (not part of the format; the loader ignores them).
        let pv = dir.join("preview");
        mk(&pv)?;
        let (rw, rb) = &self.radiance;
        // The recorded frame (counts, noise included) stretched on the objects, where the
        // reflections are, not on the whole room.
        write_gray8_png(
            &irmirror_capture::image_io::stretch_percentiles(
                &self.thermal.map(f64::from),
                &self.thermal_object_pixels,
            ),
            &pv.join("thermal.png"),
        )?;
        let stretch = |v: f64, lo: f64, hi: f64| {
            ((v - lo) / (hi - lo).max(1e-9) * 255.0).clamp(0.0, 255.0) as u8
        };
        // The band radiance's difference, not the kelvin rise: over a scene's few kelvin the
        // two are proportional within a few per cent (dL/dT barely changes), the image is
        // stretched to its maximum either way, and inverting the band integral per pixel was
        // three quarters of writing a 640×512 capture (2.2 of 3.0 s).
        let rise: Vec<f64> = rw.data.iter().zip(&rb.data).map(|(a, b)| a - b).collect();
        let max_rise = rise.iter().copied().fold(0.0, f64::max);
        let rise_img = Image {
            width: rw.width,
            height: rw.height,
            data: rise.iter().map(|&v| stretch(v, 0.0, max_rise)).collect(),
        };
        write_gray8_png(&rise_img, &pv.join("person_minus_background.png"))?;
        Ok(())
    }
}
