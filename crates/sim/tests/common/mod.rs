//! Small scenes shared by the simulator tests.
#![allow(dead_code)]

use irmirror_body::{BodyModel, Phenotype};
use irmirror_geom::transform::RigidFile;
use irmirror_geom::{PinholeCamera, Rigid3};
use irmirror_sim::scene::{
    Person, PlacedCamera, SceneFile, SceneObject, Sensor, Table, ThermalCamera, look_at,
};
use irmirror_sim::shapes::Shape;
use nalgebra::{Matrix3, Vector3};
use std::sync::OnceLock;

pub fn model() -> &'static BodyModel {
    static M: OnceLock<BodyModel> = OnceLock::new();
    M.get_or_init(|| BodyModel::builtin().unwrap())
}

/// A bowl and a mug on a table, a person behind the camera, small cameras, ideal sensor.
pub fn small_scene() -> SceneFile {
    let eye = Vector3::new(0.0, 0.45, 1.3);
    let cam = |w, h, fov: f64| PinholeCamera::from_fov(w, h, fov.to_radians()).unwrap();
    SceneFile {
        ambient_c: 22.0,
        depth_camera: PlacedCamera {
            intrinsics: cam(80, 60, 70.0),
            world_from_camera: RigidFile::from_rigid(&look_at(eye, Vector3::new(0.0, -0.05, 0.75))),
        },
        thermal_camera: ThermalCamera {
            intrinsics: cam(160, 120, 57.0),
            depth_from_thermal: RigidFile::from_rigid(&Rigid3 {
                rotation: Matrix3::identity(),
                translation: Vector3::new(0.04, 0.0, 0.0),
            }),
        },
        third_camera: PlacedCamera {
            intrinsics: cam(64, 48, 60.0),
            world_from_camera: RigidFile::from_rigid(&look_at(
                Vector3::new(2.5, 0.0, 1.4),
                Vector3::new(0.0, 1.2, 0.9),
            )),
        },
        table: Some(Table {
            height_m: 0.75,
            centre_m: [0.0, 0.0],
            size_m: [1.4, 0.9],
            temp_c: 22.0,
            emissivity: 0.93,
        }),
        objects: vec![
            SceneObject {
                shape: Shape::Bowl {
                    cut: 0.0,
                    wall: 0.06,
                }
                .into(),
                base_m: [0.08, -0.05, 0.75],
                yaw_rad: 0.0,
                scale_m: 0.11,
                emissivity: 0.91,
                temp_c: 22.0,
            },
            SceneObject {
                shape: Shape::Mug {
                    aspect: 1.1,
                    wall: 0.1,
                }
                .into(),
                base_m: [-0.15, -0.02, 0.75],
                yaw_rad: 0.5,
                scale_m: 0.07,
                emissivity: 0.91,
                temp_c: 22.0,
            },
        ],
        person: Person {
            phenotype: Phenotype::default(),
            rotvec_rad: vec![[0.0; 3]; 36],
            pose_name: "a-pose".into(),
            position_m: [0.1, 1.0],
            yaw_rad: 0.0,
            skin_c: 34.0,
            clothing_c: 30.0,
            face_c: None,
            hair_c: None,
        },
        heat_sources: vec![],
        sensor: Sensor::ideal(),
    }
}

pub fn tmpdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("irmirror-sim-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}
