//! A procedural pose set: activity templates with correlated parameters plus noise, clamped to
//! the joint limits. Rotation vectors in world-aligned rest axes (see `limits.rs` for the signs).
//!
//! | template | what varies |
//! |---|---|
//! | `stand` | relaxed arms (0–40° towards the body), small sway |
//! | `a-pose`, `t-pose` | the rest pose; arms horizontal |
//! | `walk`, `run` | gait phase φ: hips ±A sin φ, knees flex in swing, arms counter-swing, elbows bent (run: larger A, 90° elbows, forward lean) |
//! | `reach` | one arm raised forward 60–150°, elbow 0–40°, torso twist towards it |
//! | `point` | one arm forward at 70–110°, straight elbow |
//! | `wave` | one arm raised sideways 100–150°, elbow bent 40–110°, wrist swing |
//! | `arms-up` | both arms raised sideways 110–130° |
//! | `hands-on-hips` | elbows 80–110°, arms slightly out and back |
//! | `bend` | spine flexion 8–16° per segment, hips 10–60° |
//! | `squat` | hips 70–115°, knees 80–130°, ankles dorsiflexed, arms forward |
//! | `lunge` | front hip 60–90° / knee 70–100°, back hip extended, back knee 40–90° |
//! | `sit` | hips 80–100°, knees 80–100°, forearms forward |
//! | `kneel` | hips 0–30°, knees 110–135°, ankles plantarflexed |
//! | `turn` | spine and neck axial rotation to one side |
//! | `look` | neck and head turned/tilted |
//!
//! Asymmetric templates are mirrored left/right at random; all get Gaussian joint noise (σ 5°).

use super::limits::JointLimits;
use crate::BodyModel;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// The joint noise of [`PoseGenerator::sample`], degrees (σ per rotation-vector component).
pub const JOINT_NOISE_DEG: f64 = 5.0;

/// The template names.
pub const TEMPLATES: [&str; 17] = [
    "stand",
    "a-pose",
    "t-pose",
    "walk",
    "run",
    "reach",
    "point",
    "wave",
    "arms-up",
    "hands-on-hips",
    "bend",
    "squat",
    "lunge",
    "sit",
    "kneel",
    "turn",
    "look",
];

/// Draws poses (rotation vectors, root = identity) for one body model.
pub struct PoseGenerator {
    index: std::collections::HashMap<String, usize>,
    mirror: Vec<usize>,
    n: usize,
    /// The limits every pose is clamped to.
    pub limits: JointLimits,
}

impl PoseGenerator {
    /// A generator for `model`'s skeleton.
    pub fn new(model: &BodyModel) -> Self {
        let names = &model.asset.meta.bone_names;
        Self {
            index: names
                .iter()
                .enumerate()
                .map(|(i, n)| (n.clone(), i))
                .collect(),
            mirror: model.mirror_joints(),
            n: names.len(),
            limits: JointLimits::for_model(model),
        }
    }

    /// One pose from a named template (see [`TEMPLATES`]); `None` for an unknown name.
    pub fn template(&self, name: &str, rng: &mut impl Rng) -> Option<Vec<[f64; 3]>> {
        let mut r = vec![[0.0f64; 3]; self.n];
        let mut set = |bone: &str, deg: [f64; 3]| {
            if let Some(&i) = self.index.get(bone) {
                r[i] = deg.map(f64::to_radians);
            }
        };
        let mut u = |lo: f64, hi: f64| rng.random_range(lo..=hi);
        match name {
            "a-pose" => {}
            "stand" => {
                let a = u(0.0, 40.0);
                set("upperarm01.L", [u(-10.0, 10.0), a, 0.0]);
                set("upperarm01.R", [u(-10.0, 10.0), -a - u(-5.0, 5.0), 0.0]);
                set("lowerarm01.L", [u(-20.0, 0.0), 0.0, 0.0]);
                set("lowerarm01.R", [u(-20.0, 0.0), 0.0, 0.0]);
                set("spine04", [u(-3.0, 3.0), u(-3.0, 3.0), 0.0]);
            }
            "t-pose" => {
                set("upperarm01.L", [0.0, -48.0, 0.0]);
                set("upperarm01.R", [0.0, 48.0, 0.0]);
            }
            "walk" | "run" => {
                let run = name == "run";
                let phase = u(0.0, std::f64::consts::TAU);
                let amp = if run { u(30.0, 50.0) } else { u(15.0, 30.0) };
                let (s, c) = (phase.sin(), phase.cos());
                set("upperleg01.L", [-amp * s, 0.0, 0.0]);
                set("upperleg01.R", [amp * s, 0.0, 0.0]);
                let knee = if run { 90.0 } else { 50.0 };
                set("lowerleg01.L", [knee * c.max(0.0) + 5.0, 0.0, 0.0]);
                set("lowerleg01.R", [knee * (-c).max(0.0) + 5.0, 0.0, 0.0]);
                set("foot.L", [-10.0 * s, 0.0, 0.0]);
                set("foot.R", [10.0 * s, 0.0, 0.0]);
                set("upperarm01.L", [0.7 * amp * s, 30.0, 0.0]);
                set("upperarm01.R", [-0.7 * amp * s, -30.0, 0.0]);
                let elbow = if run { -90.0 } else { -20.0 };
                set("lowerarm01.L", [elbow, 0.0, 0.0]);
                set("lowerarm01.R", [elbow, 0.0, 0.0]);
                set("spine04", [if run { 10.0 } else { 2.0 }, 0.0, 5.0 * s]);
            }
            "reach" => {
                let up = u(60.0, 150.0);
                set("upperarm01.L", [-up, u(-20.0, 20.0), u(-30.0, 30.0)]);
                set("lowerarm01.L", [-u(0.0, 40.0), 0.0, 0.0]);
                set("spine03", [u(0.0, 8.0), 0.0, u(0.0, 9.0)]);
                set("spine02", [u(0.0, 8.0), 0.0, u(0.0, 9.0)]);
                set("clavicle.L", [0.0, u(-15.0, 0.0), 0.0]);
            }
            "point" => {
                set(
                    "upperarm01.L",
                    [-u(70.0, 110.0), u(-10.0, 10.0), u(-20.0, 20.0)],
                );
                set("lowerarm01.L", [u(-10.0, 0.0), 0.0, 0.0]);
                set("neck03", [0.0, 0.0, u(0.0, 20.0)]);
            }
            "wave" => {
                set("upperarm01.L", [u(-30.0, 0.0), -u(100.0, 130.0), 0.0]);
                set("lowerarm01.L", [-u(40.0, 110.0), 0.0, u(-30.0, 30.0)]);
                set("wrist.L", [0.0, u(-25.0, 25.0), 0.0]);
            }
            "arms-up" => {
                let a = u(110.0, 130.0);
                set("upperarm01.L", [u(-20.0, 0.0), -a, 0.0]);
                set("upperarm01.R", [u(-20.0, 0.0), a, 0.0]);
                set("lowerarm01.L", [-u(0.0, 30.0), 0.0, 0.0]);
                set("lowerarm01.R", [-u(0.0, 30.0), 0.0, 0.0]);
            }
            "hands-on-hips" => {
                set(
                    "upperarm01.L",
                    [u(10.0, 30.0), u(-20.0, 0.0), u(30.0, 60.0)],
                );
                set(
                    "upperarm01.R",
                    [u(10.0, 30.0), u(0.0, 20.0), -u(30.0, 60.0)],
                );
                set("lowerarm01.L", [-u(80.0, 110.0), 0.0, 0.0]);
                set("lowerarm01.R", [-u(80.0, 110.0), 0.0, 0.0]);
            }
            "bend" => {
                for s in ["spine05", "spine04", "spine03", "spine02", "spine01"] {
                    set(s, [u(8.0, 16.0), 0.0, u(-3.0, 3.0)]);
                }
                let hip = u(10.0, 60.0);
                set("upperleg01.L", [-hip, 0.0, 0.0]);
                set("upperleg01.R", [-hip, 0.0, 0.0]);
                set("upperarm01.L", [-u(20.0, 60.0), 20.0, 0.0]);
                set("upperarm01.R", [-u(20.0, 60.0), -20.0, 0.0]);
            }
            "squat" => {
                let (hip, knee) = (u(70.0, 115.0), u(80.0, 130.0));
                for side in ["L", "R"] {
                    let sy = if side == "L" { 1.0 } else { -1.0 };
                    set(&format!("upperleg01.{side}"), [-hip, -10.0 * sy, 10.0 * sy]);
                    set(&format!("lowerleg01.{side}"), [knee, 0.0, 0.0]);
                    set(&format!("foot.{side}"), [-u(5.0, 20.0), 0.0, 0.0]);
                    set(
                        &format!("upperarm01.{side}"),
                        [-u(50.0, 90.0), 20.0 * sy, 0.0],
                    );
                }
                set("spine04", [u(5.0, 15.0), 0.0, 0.0]);
            }
            "lunge" => {
                set("upperleg01.L", [-u(60.0, 90.0), 0.0, 0.0]);
                set("lowerleg01.L", [u(70.0, 100.0), 0.0, 0.0]);
                set("upperleg01.R", [u(10.0, 30.0), 0.0, 0.0]);
                set("lowerleg01.R", [u(40.0, 90.0), 0.0, 0.0]);
                set("foot.R", [u(10.0, 40.0), 0.0, 0.0]);
            }
            "sit" => {
                let hip = u(80.0, 100.0);
                for side in ["L", "R"] {
                    set(&format!("upperleg01.{side}"), [-hip, 0.0, 0.0]);
                    set(&format!("lowerleg01.{side}"), [u(80.0, 100.0), 0.0, 0.0]);
                    set(&format!("lowerarm01.{side}"), [-u(40.0, 80.0), 0.0, 0.0]);
                }
                set("spine05", [u(-5.0, 10.0), 0.0, 0.0]);
            }
            "kneel" => {
                for side in ["L", "R"] {
                    set(&format!("upperleg01.{side}"), [-u(0.0, 30.0), 0.0, 0.0]);
                    set(&format!("lowerleg01.{side}"), [u(110.0, 135.0), 0.0, 0.0]);
                    set(&format!("foot.{side}"), [u(20.0, 50.0), 0.0, 0.0]);
                }
            }
            "turn" => {
                let t = u(3.0, 9.0);
                for s in ["spine04", "spine03", "spine02", "spine01"] {
                    set(s, [0.0, 0.0, t]);
                }
                set("neck02", [0.0, 0.0, u(0.0, 20.0)]);
            }
            "look" => {
                let (x, y, z) = (u(-15.0, 15.0), u(-10.0, 10.0), u(-20.0, 20.0));
                for s in ["neck01", "neck02", "neck03"] {
                    set(s, [x, y, z]);
                }
                set("head", [x, y, z]);
            }
            _ => return None,
        }
        Some(r)
    }

    /// A random pose: a random template, mirrored left/right with probability ½, plus joint
    /// noise (σ [`JOINT_NOISE_DEG`]), clamped to the limits. Returns the template name too.
    pub fn sample(&self, rng: &mut impl Rng) -> (&'static str, Vec<[f64; 3]>) {
        self.sample_with_noise(rng, JOINT_NOISE_DEG)
    }

    /// [`Self::sample`] with Gaussian joint noise of σ `noise_deg` per rotation-vector
    /// component (0: the templates' own spread only).
    pub fn sample_with_noise(
        &self,
        rng: &mut impl Rng,
        noise_deg: f64,
    ) -> (&'static str, Vec<[f64; 3]>) {
        let name = TEMPLATES[rng.random_range(0..TEMPLATES.len())];
        let r = self.template(name, rng).expect("known template");
        (name, self.perturb(r, rng, noise_deg))
    }

    /// A pose (rotation vectors, root identity) mirrored left/right: each joint takes its
    /// mirror joint's rotation reflected in the body's sagittal (Y–Z) plane.
    pub fn mirrored(&self, r: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.n)
            .map(|i| {
                let w = r[self.mirror[i]];
                [w[0], -w[1], -w[2]]
            })
            .collect()
    }

    /// A pose (rotation vectors, any source: a template, motion capture) mirrored left/right
    /// with probability ½, plus Gaussian joint noise of σ `noise_deg` per rotation-vector
    /// component, root identity, clamped to the limits: what the training set holds.
    pub fn perturb(
        &self,
        mut r: Vec<[f64; 3]>,
        rng: &mut impl Rng,
        noise_deg: f64,
    ) -> Vec<[f64; 3]> {
        if rng.random_bool(0.5) {
            r = self.mirrored(&r);
        }
        let noise = Normal::new(0.0, noise_deg.max(0.0).to_radians()).expect("σ ≥ 0");
        for w in r.iter_mut().skip(1) {
            for x in w.iter_mut() {
                *x += noise.sample(rng);
            }
        }
        r[0] = [0.0; 3];
        self.limits.clamp(&mut r);
        r
    }
}
