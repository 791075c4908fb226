//! Motion-capture retargeting and the shipped pose set.

use irmirror_body::mocap::{Bvh, MocapSet, Retarget};
use irmirror_body::{BodyModel, Phenotype, Pose};
use nalgebra::Vector3;
use rand::Rng;

/// Mixamo-like joints, their parents, and the body bone whose head each sits at (the toes and
/// the head's end at the foot's and head's tails).
const JOINTS: [(&str, i32, &str, bool); 22] = [
    ("Hips", -1, "spine05", false),
    ("LeftUpLeg", 0, "upperleg01.L", false),
    ("LeftLeg", 1, "lowerleg01.L", false),
    ("LeftFoot", 2, "foot.L", false),
    ("LeftToe", 3, "foot.L", true),
    ("RightUpLeg", 0, "upperleg01.R", false),
    ("RightLeg", 5, "lowerleg01.R", false),
    ("RightFoot", 6, "foot.R", false),
    ("RightToe", 7, "foot.R", true),
    ("Spine", 0, "spine04", false),
    ("Spine1", 9, "spine03", false),
    ("Spine2", 10, "spine01", false),
    ("Neck", 11, "neck01", false),
    ("Head", 12, "head", false),
    ("LeftShoulder", 11, "clavicle.L", false),
    ("LeftArm", 14, "upperarm01.L", false),
    ("LeftForeArm", 15, "lowerarm01.L", false),
    ("LeftHand", 16, "wrist.L", false),
    ("RightShoulder", 11, "clavicle.R", false),
    ("RightArm", 18, "upperarm01.R", false),
    ("RightForeArm", 19, "lowerarm01.R", false),
    ("RightHand", 20, "wrist.R", false),
];

/// A BVH whose rest skeleton is the body's own joints (so its pelvis frame is the body's) with
/// random joint rotations (root rotation zero, root moved) in each frame.
fn synthetic_bvh(model: &BodyModel, frames: usize) -> String {
    let shaped = model
        .shaped_phenotype::<f64>(&Phenotype::default())
        .unwrap();
    let at = |bone: &str, tail: bool| {
        let j = model.joint_index(bone).unwrap();
        if tail {
            shaped.joint_tails[j]
        } else {
            shaped.joint_heads[j]
        }
    };
    let mut s = String::from("HIERARCHY\n");
    let mut depth = Vec::new();
    for (i, &(name, parent, bone, tail)) in JOINTS.iter().enumerate() {
        while depth.last().is_some_and(|&d| d != parent) {
            depth.pop();
            s += "}\n";
        }
        let off = match parent {
            -1 => at(bone, tail),
            p => at(bone, tail) - at(JOINTS[p as usize].2, JOINTS[p as usize].3),
        } * 100.0;
        let kind = if parent < 0 { "ROOT" } else { "JOINT" };
        let chans = if parent < 0 {
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
        } else {
            "CHANNELS 3 Zrotation Yrotation Xrotation"
        };
        s += &format!(
            "{kind} {name}\n{{\nOFFSET {} {} {}\n{chans}\n",
            off.x, off.y, off.z
        );
        depth.push(i as i32);
    }
    for _ in depth {
        s += "}\n";
    }
    s += &format!("MOTION\nFrames: {frames}\nFrame Time: 0.033333\n");
    let mut rng = irmirror_geom::rng::seeded(3, 0);
    for _ in 0..frames {
        let mut v = vec![12.0, -4.0, 7.0, 0.0, 0.0, 0.0];
        for _ in 1..JOINTS.len() {
            v.extend((0..3).map(|_| rng.random_range(-40.0..40.0)));
        }
        s += &v.iter().map(f64::to_string).collect::<Vec<_>>().join(" ");
        s += "\n";
    }
    s
}

/// Retargeting points every mapped bone of the posed body along its motion-capture segment
/// (1e-9) on a skeleton that shares the body's rest pelvis frame, and a frame with zero
/// rotations gives zero rotations where the rest bones already point along their segments.
#[test]
fn retargeted_bones_point_along_their_segments() {
    let model = BodyModel::builtin().unwrap();
    let shaped = model
        .shaped_phenotype::<f64>(&Phenotype::default())
        .unwrap();
    let bvh = Bvh::parse(&synthetic_bvh(&model, 4), "synthetic").unwrap();
    let r = Retarget::new(&model, &shaped, &bvh).unwrap();
    let seg = |bone: &str| -> (usize, usize) {
        let pairs = [
            ("upperleg01.L", "LeftUpLeg", "LeftLeg"),
            ("lowerleg01.R", "RightLeg", "RightFoot"),
            ("foot.L", "LeftFoot", "LeftToe"),
            ("spine04", "Spine", "Spine1"),
            ("spine01", "Spine2", "Neck"),
            ("neck02", "Neck", "Head"),
            ("clavicle.R", "RightShoulder", "RightArm"),
            ("upperarm01.L", "LeftArm", "LeftForeArm"),
            ("lowerarm02.R", "RightForeArm", "RightHand"),
        ];
        let (_, a, b) = pairs.iter().find(|p| p.0 == bone).unwrap();
        (bvh.joint(a).unwrap(), bvh.joint(b).unwrap())
    };
    let bones = [
        "upperleg01.L",
        "lowerleg01.R",
        "foot.L",
        "spine04",
        "spine01",
        "neck02",
        "clavicle.R",
        "upperarm01.L",
        "lowerarm02.R",
    ];
    for f in 0..bvh.frames.len() {
        let rotvecs = r.frame(&bvh, f).unwrap();
        assert_eq!(rotvecs[0], [0.0; 3], "root stays identity");
        let posed = model
            .pose(&shaped, &Pose::from_axis_angles(&rotvecs, Vector3::zeros()))
            .unwrap();
        let p = bvh.positions(f);
        for bone in bones {
            let c = model.joint_index(bone).unwrap();
            let u = (shaped.joint_tails[c] - shaped.joint_heads[c]).normalize();
            let (a, b) = seg(bone);
            let want = (p[b] - p[a]).normalize();
            let got = posed.world_rotations[c] * u;
            assert!(
                (got - want).norm() < 1e-9,
                "frame {f}, {bone}: {got:?} vs {want:?}"
            );
        }
    }
}

/// The shipped set: 119 poses of 36 bones, root identity, every one upright (head 0.7–1.8 m
/// above the feet: standing, bending or crouching), from the three files named in its
/// provenance.
#[test]
fn shipped_mocap_poses_are_plausible() {
    let model = BodyModel::builtin().unwrap();
    let set = MocapSet::builtin().unwrap();
    assert_eq!(set.poses.len(), 119);
    assert!(set.provenance.contains("MIT") && set.provenance.contains("bvhTools"));
    for f in ["1.bvh", "test2.bvh", "test3.bvh"] {
        assert!(set.sources.iter().any(|s| s.starts_with(f)), "{f}");
    }
    let shaped = model
        .shaped_phenotype::<f64>(&Phenotype::default())
        .unwrap();
    let head = model.joint_index("head").unwrap();
    for (k, rotvecs) in set.poses.iter().enumerate() {
        assert_eq!(rotvecs.len(), 36);
        assert!(rotvecs[0].iter().all(|x| x.abs() < 1e-6));
        let posed = model
            .pose(&shaped, &Pose::from_axis_angles(rotvecs, Vector3::zeros()))
            .unwrap();
        let lowest = posed
            .vertices
            .iter()
            .map(|v| v.z)
            .fold(f64::INFINITY, f64::min);
        let h = posed.joints[head].z - lowest;
        assert!(
            h > 0.7 && h < 1.8,
            "pose {k} ({}): head {h:.2} m above the feet",
            set.sources[k]
        );
    }
    // Round trip through the file format.
    let again = MocapSet::from_bytes(&set.to_bytes().unwrap(), "round trip").unwrap();
    assert_eq!(again.sources, set.sources);
    assert!(
        again
            .poses
            .iter()
            .flatten()
            .zip(set.poses.iter().flatten())
            .all(|(a, b)| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-6))
    );
}

/// A DeepMimic frame (44 values: duration, root position and quaternion, then the joints), all
/// quaternions identity unless given.
fn deepmimic_frame(set: &[(usize, f64)]) -> Vec<f64> {
    let mut v = vec![0.0; 44];
    v[0] = 0.033;
    v[2] = 0.9;
    for k in [4, 8, 12, 16, 21, 25, 30, 35, 39] {
        v[k] = 1.0;
    }
    for &(k, x) in set {
        v[k] = x;
    }
    v
}

/// A DeepMimic motion retargets with the right sides and senses: a bent right knee (−0.8 rad
/// about its Z) sends the body's right shin backwards while the thigh hangs, a bent left elbow
/// (+1.2 rad) sends the forearm forwards, the right hip flexed 40° (a quaternion about Z)
/// lifts the thigh forwards; an upright rest frame leaves the legs hanging straight down.
#[test]
fn deepmimic_motions_retarget_with_the_right_sides_and_senses() {
    let model = BodyModel::builtin().unwrap();
    let shaped = model
        .shaped_phenotype::<f64>(&Phenotype::default())
        .unwrap();
    let half = 20f64.to_radians();
    let frames = [
        deepmimic_frame(&[]),
        deepmimic_frame(&[(20, -0.8), (43, 1.2)]),
        deepmimic_frame(&[(16, half.cos()), (19, half.sin())]),
    ];
    let text = serde_json::json!({ "Loop": "none", "Frames": frames }).to_string();
    let bvh = Bvh::from_deepmimic(&text, "synthetic").unwrap();
    assert_eq!(bvh.up, Some(Vector3::y()));
    let r = Retarget::new(&model, &shaped, &bvh).unwrap();
    let head = |b: &str| shaped.joint_heads[model.joint_index(b).unwrap()];
    let left = head("upperleg01.L") - head("upperleg01.R");
    let up = Vector3::z();
    let forward = left.cross(&up).normalize();
    let dir = |rotvecs: &[[f64; 3]], bone: &str| {
        let c = model.joint_index(bone).unwrap();
        let posed = model
            .pose(&shaped, &Pose::from_axis_angles(rotvecs, Vector3::zeros()))
            .unwrap();
        posed.world_rotations[c] * (shaped.joint_tails[c] - shaped.joint_heads[c]).normalize()
    };
    let rest = r.frame(&bvh, 0).unwrap();
    for bone in ["upperleg01.R", "lowerleg01.L"] {
        assert!(dir(&rest, bone).dot(&up) < -0.99, "{bone} hangs");
    }
    let bent = r.frame(&bvh, 1).unwrap();
    assert!(dir(&bent, "upperleg01.R").dot(&up) < -0.99);
    let shin = dir(&bent, "lowerleg01.R");
    assert!(
        (shin.dot(&forward) + 0.8f64.sin()).abs() < 0.02,
        "shin {shin:?}"
    );
    let forearm = dir(&bent, "lowerarm01.L");
    assert!(forearm.dot(&forward) > 0.8, "forearm {forearm:?}");
    let flexed = r.frame(&bvh, 2).unwrap();
    let thigh = dir(&flexed, "upperleg01.R");
    assert!(
        (thigh.dot(&forward) - 40f64.to_radians().sin()).abs() < 0.02,
        "thigh {thigh:?}"
    );
    assert!(dir(&flexed, "upperleg01.L").dot(&up) < -0.99);
    // Broken motions are refused with a reason.
    for (bad, why) in [
        ("[1, 2]", "not a DeepMimic motion"),
        (r#"{"Frames": []}"#, "no frames"),
        (r#"{"Frames": [[0.1, 0.2]]}"#, "frame 0"),
    ] {
        let e = Bvh::from_deepmimic(bad, "m").unwrap_err().to_string();
        assert!(e.contains(why), "{e}");
    }
    let zero_quat = serde_json::json!({ "Frames": [deepmimic_frame(&[(8, 0.0)])] }).to_string();
    assert!(Bvh::from_deepmimic(&zero_quat, "m").is_err());
}
