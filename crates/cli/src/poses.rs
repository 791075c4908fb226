//! Named poses and seeded random bodies for the demo and `body sample`.
//!
//! Rotations are rotation vectors in world-aligned rest axes (Anny frame: Z up, −Y front,
//! +X model's left). A positive angle about +X swings a hanging limb backward; about +Y, it
//! lowers the left arm and raises the right one. These are stand-ins until the pose prior lands.

use irmirror_body::{BodyModel, Phenotype};
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// Names accepted by [`named`].
pub const NAMES: [&str; 5] = ["a-pose", "t-pose", "walk", "wave", "arms-up"];

/// Rotation vectors for a named pose (identity = the rest A-pose).
pub fn named(model: &BodyModel, name: &str) -> Vec<[f64; 3]> {
    let mut r = vec![[0.0; 3]; model.n_joints()];
    let mut set = |bone: &str, w: [f64; 3]| {
        if let Some(i) = model.joint_index(bone) {
            r[i] = w;
        }
    };
    match name {
        "t-pose" => {
            set("upperarm01.L", [0.0, -0.84, 0.0]);
            set("upperarm01.R", [0.0, 0.84, 0.0]);
        }
        "walk" => {
            set("upperleg01.L", [-0.45, 0.0, 0.0]);
            set("lowerleg01.L", [0.15, 0.0, 0.0]);
            set("upperleg01.R", [0.3, 0.0, 0.0]);
            set("lowerleg01.R", [0.6, 0.0, 0.0]);
            set("upperarm01.L", [0.35, 0.0, 0.0]);
            set("upperarm01.R", [-0.35, 0.0, 0.0]);
            set("lowerarm01.R", [-0.4, 0.0, 0.0]);
        }
        "wave" => {
            set("upperarm01.R", [0.0, 1.9, 0.0]);
            set("lowerarm01.R", [0.0, 0.0, -0.9]);
            set("spine03", [0.0, 0.08, 0.0]);
        }
        "arms-up" => {
            set("upperarm01.L", [0.0, -2.3, 0.0]);
            set("upperarm01.R", [0.0, 2.3, 0.0]);
        }
        _ => {}
    }
    r
}

/// A random adult phenotype.
pub fn random_phenotype(rng: &mut impl Rng) -> Phenotype {
    Phenotype {
        gender: rng.random_range(0.0..=1.0),
        age: rng.random_range(0.68..=0.95),
        muscle: rng.random_range(0.2..=0.8),
        weight: rng.random_range(0.2..=0.8),
        height: rng.random_range(0.25..=0.5),
        proportions: rng.random_range(0.0..=1.0),
    }
}

/// A named pose with Gaussian joint noise (σ = `sigma_rad`) and a random heading about Z.
pub fn random_pose(model: &BodyModel, rng: &mut impl Rng, sigma_rad: f64) -> (String, Vec<[f64; 3]>) {
    let name = NAMES[rng.random_range(0..NAMES.len())];
    let mut r = named(model, name);
    let noise = Normal::new(0.0, sigma_rad).expect("positive sigma");
    for w in r.iter_mut().skip(1) {
        for x in w.iter_mut() {
            *x += noise.sample(rng);
        }
    }
    r[0] = [0.0, 0.0, rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)];
    (name.to_string(), r)
}
