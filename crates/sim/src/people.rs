//! Seeded random people for the presets, the demo and `body sample`: adult phenotypes and poses
//! from the procedural pose set's activity templates (`irmirror_body::prior::generator`).

use irmirror_body::prior::generator::PoseGenerator;
use irmirror_body::{BodyModel, Phenotype};
use rand::Rng;

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

/// A pose from a random activity template (joint noise, limits), root rotation zero.
pub fn random_pose(model: &BodyModel, rng: &mut impl Rng) -> (String, Vec<[f64; 3]>) {
    let (name, r) = PoseGenerator::new(model).sample(rng);
    (name.to_string(), r)
}

/// A named template pose (see `irmirror_body::prior::generator::TEMPLATES`), or the A-pose.
pub fn named(model: &BodyModel, name: &str, rng: &mut impl Rng) -> Vec<[f64; 3]> {
    PoseGenerator::new(model)
        .template(name, rng)
        .unwrap_or_else(|| vec![[0.0; 3]; model.n_joints()])
}
