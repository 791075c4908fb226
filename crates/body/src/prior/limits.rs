//! Joint limits for the 35 body joints (all but the root), as boxes on the rotation-vector
//! components in the **world-aligned rest axes** the pose uses (Anny frame: +X the person's
//! left, +Y the person's back, +Z up; rest = A-pose).
//!
//! Signs: a positive X rotation swings a hanging limb backward and tips an upright segment
//! forward; a positive Y rotation swings a hanging limb towards the person's right and tips an
//! upright segment to the left; Z turns about the vertical. Left-side ranges are given;
//! right-side ranges are their mirror images (`(x, y, z) → (x, −y, −z)`).
//!
//! Ranges follow the AAOS / Greene & Heckman normal active ranges of motion ("The Clinical
//! Measurement of Joint Motion", AAOS 1994): hip flexion 120°, extension 30°, abduction 45°,
//! adduction 30°, rotation 45°; knee flexion 135°; ankle dorsiflexion 20°, plantarflexion 50°;
//! shoulder flexion 180°, extension 60°, abduction 180°, rotation ≈ 70–90°; elbow flexion 150°;
//! forearm pronation/supination 80°; wrist flexion/extension 70–80°, deviation 20–30°;
//! thoracolumbar flexion 80°, extension 25°, lateral bending 35°, rotation 45° (split over the 5
//! spine bones); cervical flexion/extension 45°, lateral bending 45°, rotation 60° (split over
//! neck01–03 and head). Twist bones (`…02`) and the small girdle bones (pelvis, clavicle,
//! shoulder01) get small ranges. Shoulder ranges are shifted by the A-pose's 42° of rest
//! abduction. World-aligned boxes approximate anatomical, bone-local axes: exact for legs and
//! spine at rest, approximate for arms.

use crate::BodyModel;

/// `[lo, hi]` in degrees for the X, Y and Z components.
pub type Box3 = [[f64; 2]; 3];

/// Limits of the left-side and midline bones, degrees (`None`: the root, unconstrained).
fn left_or_mid(name: &str) -> Option<Box3> {
    let b = |x: [f64; 2], y: [f64; 2], z: [f64; 2]| Some([x, y, z]);
    let small = |a: f64| Some([[-a, a], [-a, a], [-a, a]]);
    let base = name.trim_end_matches(".L").trim_end_matches(".R");
    match base {
        "root" => None,
        "pelvis" => small(5.0),
        "upperleg01" => b([-120.0, 30.0], [-45.0, 30.0], [-45.0, 45.0]),
        "upperleg02" | "lowerleg02" => b([-5.0, 5.0], [-5.0, 5.0], [-15.0, 15.0]),
        "lowerleg01" => b([0.0, 135.0], [-5.0, 5.0], [-10.0, 10.0]),
        "foot" => b([-20.0, 50.0], [-25.0, 25.0], [-20.0, 20.0]),
        "spine05" | "spine04" | "spine03" | "spine02" | "spine01" => {
            b([-5.0, 16.0], [-7.0, 7.0], [-9.0, 9.0])
        }
        "neck01" | "neck02" | "neck03" => b([-15.0, 15.0], [-15.0, 15.0], [-20.0, 20.0]),
        "head" => b([-15.0, 15.0], [-10.0, 10.0], [-15.0, 15.0]),
        "clavicle" => b([-15.0, 15.0], [-15.0, 15.0], [-10.0, 10.0]),
        "shoulder01" => small(10.0),
        "upperarm01" => b([-150.0, 50.0], [-130.0, 40.0], [-70.0, 70.0]),
        "upperarm02" => b([-5.0, 5.0], [-5.0, 5.0], [-20.0, 20.0]),
        "lowerarm01" => b([-140.0, 10.0], [-5.0, 5.0], [-40.0, 40.0]),
        "lowerarm02" => b([-5.0, 5.0], [-5.0, 5.0], [-45.0, 45.0]),
        "wrist" => b([-70.0, 70.0], [-25.0, 25.0], [-10.0, 10.0]),
        _ => small(5.0),
    }
}

/// Per-joint limits in radians for the model's bones (index 0, the root, is unconstrained).
#[derive(Clone, Debug)]
pub struct JointLimits {
    /// `[lo, hi]` radians per component; `None` for the root.
    pub boxes: Vec<Option<Box3>>,
}

impl JointLimits {
    /// The limits of `model`'s skeleton.
    pub fn for_model(model: &BodyModel) -> Self {
        let boxes = model
            .asset
            .meta
            .bone_names
            .iter()
            .map(|n| {
                left_or_mid(n).map(|mut bx| {
                    if n.ends_with(".R") {
                        // Mirror: y and z negate.
                        for k in 1..3 {
                            bx[k] = [-bx[k][1], -bx[k][0]];
                        }
                    }
                    bx.map(|r| r.map(f64::to_radians))
                })
            })
            .collect();
        Self { boxes }
    }

    /// Clamps rotation vectors into the limits.
    pub fn clamp(&self, rotvecs: &mut [[f64; 3]]) {
        for (w, b) in rotvecs.iter_mut().zip(&self.boxes) {
            if let Some(b) = b {
                for k in 0..3 {
                    w[k] = w[k].clamp(b[k][0], b[k][1]);
                }
            }
        }
    }

    /// Per joint, the largest excess (radians) of a component beyond its limit (0 inside; the
    /// root is never outside).
    pub fn joint_violations(&self, rotvecs: &[[f64; 3]]) -> Vec<f64> {
        rotvecs
            .iter()
            .zip(&self.boxes)
            .map(|(w, b)| {
                b.map_or(0.0, |b| {
                    (0..3)
                        .map(|k| (b[k][0] - w[k]).max(w[k] - b[k][1]).max(0.0))
                        .fold(0.0, f64::max)
                })
            })
            .collect()
    }

    /// The largest excess (radians) of any component beyond its limit (0 inside).
    pub fn violation(&self, rotvecs: &[[f64; 3]]) -> f64 {
        rotvecs
            .iter()
            .zip(&self.boxes)
            .filter_map(|(w, b)| {
                b.map(|b| {
                    (0..3)
                        .map(|k| (b[k][0] - w[k]).max(w[k] - b[k][1]).max(0.0))
                        .fold(0.0, f64::max)
                })
            })
            .fold(0.0, f64::max)
    }
}
