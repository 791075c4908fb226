//! A cheap self-penetration test for poses: capsules around limb and torso segments of the
//! posed skeleton (mean adult shape), checked pairwise for overlap.

use crate::fk;
use crate::{BodyModel, ShapedBody};
use irmirror_geom::rotation::axis_angle_to_matrix;
use nalgebra::{Matrix3, Vector3};

/// Capsules: (from bone, to bone's head — or the bone's own tail when `None`), radius m.
const CAPSULES: [(&str, Option<&str>, f64); 9] = [
    ("upperleg01.L", Some("lowerleg01.L"), 0.065),
    ("lowerleg01.L", Some("foot.L"), 0.045),
    ("upperleg01.R", Some("lowerleg01.R"), 0.065),
    ("lowerleg01.R", Some("foot.R"), 0.045),
    ("upperarm01.L", Some("lowerarm01.L"), 0.04),
    ("lowerarm01.L", Some("wrist.L"), 0.035),
    ("upperarm01.R", Some("lowerarm01.R"), 0.04),
    ("lowerarm01.R", Some("wrist.R"), 0.035),
    ("spine04", Some("neck01"), 0.11),
];

/// Pairs that must not overlap (indices into `CAPSULES`): legs with each other, arms with the
/// torso and the legs, forearms with each other.
const PAIRS: [(usize, usize); 14] = [
    (0, 2),
    (1, 3),
    (0, 3),
    (1, 2),
    (5, 8),
    (7, 8),
    (5, 0),
    (7, 2),
    (5, 1),
    (7, 3),
    (5, 7),
    (4, 8),
    (6, 8),
    (5, 6),
];

/// Capsule-overlap tester for one skeleton.
pub struct PenetrationTest {
    capsules: Vec<(usize, usize, f64)>,
    shaped: ShapedBody<f64>,
    parents: Vec<i32>,
}

/// Closest distance between segments `p0–p1` and `q0–q1` (Ericson §5.1.9).
fn segment_distance(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> f64 {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    let (s, t);
    if a <= 1e-12 && e <= 1e-12 {
        return r.norm();
    }
    if a <= 1e-12 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= 1e-12 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut ss = if denom > 1e-12 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut tt = (b * ss + f) / e;
            if tt < 0.0 {
                tt = 0.0;
                ss = (-c / a).clamp(0.0, 1.0);
            } else if tt > 1.0 {
                tt = 1.0;
                ss = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = ss;
            t = tt;
        }
    }
    ((p0 + d1 * s) - (q0 + d2 * t)).norm()
}

impl PenetrationTest {
    /// For `model` at its mean shape.
    pub fn new(model: &BodyModel) -> Self {
        let idx = |n: &str| model.joint_index(n).expect("body bone");
        let capsules = CAPSULES
            .iter()
            .map(|(a, b, r)| (idx(a), idx(b.expect("segment end")), *r))
            .collect();
        let shaped = model
            .shaped(&vec![0.0; model.rank()])
            .expect("zero shape is valid");
        Self {
            capsules,
            shaped,
            parents: model.asset.parents.clone(),
        }
    }

    /// True if two capsules that should stay apart overlap by more than 20 % of their radii.
    pub fn penetrates(&self, rotvecs: &[[f64; 3]]) -> bool {
        let rot: Vec<Matrix3<f64>> = rotvecs
            .iter()
            .map(|w| axis_angle_to_matrix(&Vector3::from(*w)))
            .collect();
        let n = rot.len();
        let (mut g, mut t) = (vec![Matrix3::identity(); n], vec![Vector3::zeros(); n]);
        fk::forward(
            &self.parents,
            &self.shaped.joint_heads,
            &rot,
            &Vector3::zeros(),
            &mut g,
            &mut t,
        );
        PAIRS.iter().any(|&(i, j)| {
            let (a0, a1, ra) = self.capsules[i];
            let (b0, b1, rb) = self.capsules[j];
            segment_distance(&t[a0], &t[a1], &t[b0], &t[b1]) < 0.8 * (ra + rb)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_closed_forms() {
        let v = Vector3::new;
        assert!(
            (segment_distance(
                &v(0.0, 0.0, 0.0),
                &v(1.0, 0.0, 0.0),
                &v(0.5, 1.0, 0.0),
                &v(0.5, 2.0, 0.0)
            ) - 1.0)
                .abs()
                < 1e-12
        );
        assert!(
            (segment_distance(
                &v(0.0, 0.0, 0.0),
                &v(1.0, 0.0, 0.0),
                &v(0.5, -1.0, 1.0),
                &v(0.5, 1.0, 1.0)
            ) - 1.0)
                .abs()
                < 1e-12
        );
        assert!(
            (segment_distance(
                &v(0.0, 0.0, 0.0),
                &v(1.0, 0.0, 0.0),
                &v(2.0, 0.0, 0.0),
                &v(3.0, 0.0, 0.0)
            ) - 1.0)
                .abs()
                < 1e-12
        );
    }
}
