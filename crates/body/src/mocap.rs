//! Real human poses: BVH motion capture retargeted to the body's 36 bones.
//!
//! The benchmark's persons should not come from the pose prior's own training generator, or the
//! truth is always in the prior's distribution. [`Bvh::parse`] reads a BVH file (hierarchy,
//! Euler channels in any order, end sites); [`Retarget`] turns one frame into the body's
//! rotations by matching bone *directions*: the heading frame (the capture's vertical, and the
//! hips' left-right axis made horizontal) is mapped onto the body's (+Z up; the root stays
//! identity and the scene chooses the heading), then, parents first, each mapped bone is turned
//! by the smallest
//! rotation that points it along its motion-capture segment (twist about a bone is not
//! observable from joint positions and stays the parent's). Unmapped bones (`pelvis.L/R`,
//! `shoulder01`, `wrist`, `head`) follow their parents. DeepMimic motion clips are read as such
//! a skeleton too ([`Bvh::from_deepmimic`]). The shipped sets (`assets/poses/`, see its README)
//! are what `irmirror body retarget-bvh` makes from the `bvhTools` package's files (the
//! benchmark's persons) and from pybullet's DeepMimic clips (the pose prior's real poses).

use crate::{BodyError, BodyModel, ShapedBody};
use irmirror_geom::rotation::{axis_angle_to_matrix, matrix_to_axis_angle};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// One rotation channel's axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Channel {
    PosX,
    PosY,
    PosZ,
    RotX,
    RotY,
    RotZ,
}

/// A parsed BVH file.
#[derive(Clone, Debug)]
pub struct Bvh {
    /// Joint names (end sites excluded), parents first.
    pub names: Vec<String>,
    /// Parent joint index, −1 for the root.
    pub parents: Vec<i32>,
    offsets: Vec<Vector3<f64>>,
    channels: Vec<Vec<Channel>>,
    /// Frames: every joint's channel values, in file order.
    pub frames: Vec<Vec<f64>>,
    /// The vertical when the format states it (DeepMimic: +Y); `None`: [`Retarget`] takes the
    /// coordinate axis nearest the mean hips → neck.
    pub up: Option<Vector3<f64>>,
}

fn bad(origin: &str, reason: impl Into<String>) -> BodyError {
    BodyError::asset(origin, reason)
}

impl Bvh {
    /// Parses BVH text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, BodyError> {
        let mut tok = text.split_whitespace().peekable();
        let mut out = Bvh {
            names: vec![],
            parents: vec![],
            offsets: vec![],
            channels: vec![],
            frames: vec![],
            up: None,
        };
        if tok.next() != Some("HIERARCHY") {
            return Err(bad(origin, "not a BVH file (no HIERARCHY)"));
        }
        // Stack of open joints (`None` for an end site).
        let mut stack: Vec<Option<usize>> = Vec::new();
        let num = |t: Option<&str>| -> Result<f64, BodyError> {
            t.and_then(|s| s.parse::<f64>().ok())
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(origin, "expected a number in the hierarchy"))
        };
        loop {
            match tok.next() {
                Some("ROOT") | Some("JOINT") => {
                    let name = tok
                        .next()
                        .ok_or_else(|| bad(origin, "joint without a name"))?;
                    let parent = stack
                        .iter()
                        .rev()
                        .flatten()
                        .next()
                        .map_or(-1, |&p| p as i32);
                    if parent < 0 && !out.names.is_empty() {
                        return Err(bad(origin, "more than one ROOT"));
                    }
                    out.names.push(name.to_string());
                    out.parents.push(parent);
                    out.offsets.push(Vector3::zeros());
                    out.channels.push(vec![]);
                    stack.push(Some(out.names.len() - 1));
                }
                Some("End") => {
                    tok.next(); // "Site"
                    stack.push(None);
                }
                Some("{") => {}
                Some("}") => {
                    stack.pop();
                }
                Some("OFFSET") => {
                    let o = Vector3::new(num(tok.next())?, num(tok.next())?, num(tok.next())?);
                    if let Some(Some(j)) = stack.last() {
                        out.offsets[*j] = o;
                    }
                }
                Some("CHANNELS") => {
                    let n = num(tok.next())? as usize;
                    let j = stack
                        .last()
                        .copied()
                        .flatten()
                        .ok_or_else(|| bad(origin, "CHANNELS outside a joint"))?;
                    for _ in 0..n {
                        let c = match tok.next() {
                            Some("Xposition") => Channel::PosX,
                            Some("Yposition") => Channel::PosY,
                            Some("Zposition") => Channel::PosZ,
                            Some("Xrotation") => Channel::RotX,
                            Some("Yrotation") => Channel::RotY,
                            Some("Zrotation") => Channel::RotZ,
                            other => {
                                return Err(bad(origin, format!("unknown channel {other:?}")));
                            }
                        };
                        out.channels[j].push(c);
                    }
                }
                Some("MOTION") => break,
                Some(other) => return Err(bad(origin, format!("unexpected {other:?}"))),
                None => return Err(bad(origin, "no MOTION section")),
            }
        }
        if out.names.is_empty() {
            return Err(bad(origin, "no joints"));
        }
        if tok.next() != Some("Frames:") {
            return Err(bad(origin, "expected 'Frames:'"));
        }
        let n_frames = num(tok.next())? as usize;
        if (tok.next(), tok.next()) != (Some("Frame"), Some("Time:")) {
            return Err(bad(origin, "expected 'Frame Time:'"));
        }
        num(tok.next())?;
        let per_frame: usize = out.channels.iter().map(Vec::len).sum();
        let values: Vec<f64> = tok
            .map(|s| s.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad(origin, "a frame value is not a number"))?;
        if values.len() != n_frames * per_frame || values.iter().any(|x| !x.is_finite()) {
            return Err(bad(
                origin,
                format!(
                    "{} values for {n_frames} frames × {per_frame} channels",
                    values.len()
                ),
            ));
        }
        out.frames = values.chunks(per_frame).map(<[f64]>::to_vec).collect();
        Ok(out)
    }

    /// Reads a DeepMimic motion (`{"Frames": [[…44 values…], …]}`: duration, root position,
    /// then per joint a quaternion `w x y z` or, for knees and elbows, one angle about the local
    /// Z axis; the `humanoid3d` character, Y up, X forward, +Z to its right) as a skeleton with
    /// Mixamo-like names, so [`Retarget`] maps it like any BVH. The character's offsets are from
    /// its URDF (`pybullet_data/humanoid/humanoid.urdf`, which is 4× scale); only segment
    /// *directions* matter to the retargeting. It has no clavicles, spine segments or wrists:
    /// the clavicles point straight across the chest, the whole spine above the waist joint
    /// follows the chest, and the hands the forearms.
    pub fn from_deepmimic(text: &str, origin: &str) -> Result<Self, BodyError> {
        #[derive(serde::Deserialize)]
        struct Motion {
            #[serde(rename = "Frames")]
            frames: Vec<Vec<f64>>,
        }
        /// Where a joint's rotation comes from in a DeepMimic frame.
        enum Src {
            Root,
            Quat(usize),
            Hinge(usize),
            Fixed,
        }
        use Src::{Fixed, Hinge, Quat, Root};
        #[rustfmt::skip]
        let joints: [(&str, i32, [f64; 3], Src); 22] = [
            ("Hips", -1, [0.0, 0.0, 0.0], Root),
            ("Spine", 0, [0.0, 0.236151, 0.0], Quat(8)), // the chest joint (waist)
            ("Spine1", 1, [0.0, 0.075, 0.0], Fixed),
            ("Spine2", 2, [0.0, 0.075, 0.0], Fixed),
            ("Neck", 3, [0.0, 0.073894, 0.0], Quat(12)),
            ("Head", 4, [0.0, 0.2, 0.0], Fixed),
            ("RightShoulder", 3, [-0.02405, 0.0935, 0.0], Fixed),
            ("RightArm", 6, [0.0, 0.0, 0.18311], Quat(25)),
            ("RightForeArm", 7, [0.0, -0.274788, 0.0], Hinge(29)),
            ("RightHand", 8, [0.0, -0.258947, 0.0], Fixed),
            ("LeftShoulder", 3, [-0.02405, 0.0935, 0.0], Fixed),
            ("LeftArm", 10, [0.0, 0.0, -0.18311], Quat(39)),
            ("LeftForeArm", 11, [0.0, -0.274788, 0.0], Hinge(43)),
            ("LeftHand", 12, [0.0, -0.258947, 0.0], Fixed),
            ("RightUpLeg", 0, [0.0, 0.0, 0.084887], Quat(16)),
            ("RightLeg", 14, [0.0, -0.421546, 0.0], Hinge(20)),
            ("RightFoot", 15, [0.0, -0.40987, 0.0], Quat(21)),
            ("RightToe", 16, [0.13, -0.045, 0.0], Fixed),
            ("LeftUpLeg", 0, [0.0, 0.0, -0.084887], Quat(30)),
            ("LeftLeg", 18, [0.0, -0.421546, 0.0], Hinge(34)),
            ("LeftFoot", 19, [0.0, -0.40987, 0.0], Quat(35)),
            ("LeftToe", 20, [0.13, -0.045, 0.0], Fixed),
        ];
        const WIDTH: usize = 44;
        let motion: Motion = serde_json::from_str(text)
            .map_err(|e| bad(origin, format!("not a DeepMimic motion: {e}")))?;
        if motion.frames.is_empty() {
            return Err(bad(origin, "no frames"));
        }
        // Z-Y-X Euler channels compose to R = Rz Ry Rx, which `euler_angles` inverts.
        let zyx = |q: &[f64]| -> Option<[f64; 3]> {
            let q = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
            let q = nalgebra::UnitQuaternion::try_new(q, 1e-6)?;
            let (roll, pitch, yaw) = q.euler_angles();
            Some([yaw.to_degrees(), pitch.to_degrees(), roll.to_degrees()])
        };
        let mut frames = Vec::with_capacity(motion.frames.len());
        for (f, v) in motion.frames.iter().enumerate() {
            let broken = || bad(origin, format!("frame {f}: expected {WIDTH} finite values"));
            if v.len() != WIDTH || v.iter().any(|x| !x.is_finite()) {
                return Err(broken());
            }
            let mut out = Vec::with_capacity(3 + 3 * joints.len());
            for (_, _, _, src) in &joints {
                match *src {
                    Root => {
                        out.extend_from_slice(&v[1..4]);
                        out.extend(zyx(&v[4..8]).ok_or_else(broken)?);
                    }
                    Quat(k) => out.extend(zyx(&v[k..k + 4]).ok_or_else(broken)?),
                    Hinge(k) => out.push(v[k].to_degrees()),
                    Fixed => {}
                }
            }
            frames.push(out);
        }
        use Channel::{PosX, PosY, PosZ, RotX, RotY, RotZ};
        Ok(Bvh {
            names: joints.iter().map(|j| j.0.to_string()).collect(),
            parents: joints.iter().map(|j| j.1).collect(),
            offsets: joints.iter().map(|j| Vector3::from(j.2)).collect(),
            channels: joints
                .iter()
                .map(|j| match j.3 {
                    Root => vec![PosX, PosY, PosZ, RotZ, RotY, RotX],
                    Quat(_) => vec![RotZ, RotY, RotX],
                    Hinge(_) => vec![RotZ],
                    Fixed => vec![],
                })
                .collect(),
            frames,
            up: Some(Vector3::y()),
        })
    }

    /// Index of a joint by name.
    pub fn joint(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// World positions of every joint in frame `f` (the file's units and axes).
    pub fn positions(&self, f: usize) -> Vec<Vector3<f64>> {
        let values = &self.frames[f];
        let n = self.names.len();
        let (mut rot, mut pos) = (vec![Matrix3::identity(); n], vec![Vector3::zeros(); n]);
        let mut k = 0;
        for j in 0..n {
            let (mut local_r, mut local_t) = (Matrix3::identity(), self.offsets[j]);
            for &c in &self.channels[j] {
                let v = values[k];
                k += 1;
                let axis = match c {
                    Channel::PosX => {
                        local_t.x += v;
                        continue;
                    }
                    Channel::PosY => {
                        local_t.y += v;
                        continue;
                    }
                    Channel::PosZ => {
                        local_t.z += v;
                        continue;
                    }
                    Channel::RotX => Vector3::x(),
                    Channel::RotY => Vector3::y(),
                    Channel::RotZ => Vector3::z(),
                };
                // Channels compose in the order listed (intrinsic rotations).
                local_r *= axis_angle_to_matrix(&(axis * v.to_radians()));
            }
            match self.parents[j] {
                p if p < 0 => {
                    rot[j] = local_r;
                    pos[j] = local_t;
                }
                p => {
                    let p = p as usize;
                    pos[j] = pos[p] + rot[p] * local_t;
                    rot[j] = rot[p] * local_r;
                }
            }
        }
        pos
    }
}

/// Which motion-capture joints the body's bones follow: `(bone, from, to)`, the bone pointing
/// along `from → to`. Two naming schemes: Mixamo/MotionBuilder-like (`Hips`, `LeftUpLeg`, …) and
/// Blender Rigify-like (`pelvis`, `thigh.L`, …).
const MAPS: [&[(&str, &str, &str)]; 2] = [
    &[
        ("upperleg01.L", "LeftUpLeg", "LeftLeg"),
        ("upperleg02.L", "LeftUpLeg", "LeftLeg"),
        ("lowerleg01.L", "LeftLeg", "LeftFoot"),
        ("lowerleg02.L", "LeftLeg", "LeftFoot"),
        ("foot.L", "LeftFoot", "LeftToe"),
        ("upperleg01.R", "RightUpLeg", "RightLeg"),
        ("upperleg02.R", "RightUpLeg", "RightLeg"),
        ("lowerleg01.R", "RightLeg", "RightFoot"),
        ("lowerleg02.R", "RightLeg", "RightFoot"),
        ("foot.R", "RightFoot", "RightToe"),
        ("spine05", "Hips", "Spine"),
        ("spine04", "Spine", "Spine1"),
        ("spine03", "Spine1", "Spine2"),
        ("spine02", "Spine1", "Spine2"),
        ("spine01", "Spine2", "Neck"),
        ("neck01", "Neck", "Head"),
        ("neck02", "Neck", "Head"),
        ("neck03", "Neck", "Head"),
        ("clavicle.L", "LeftShoulder", "LeftArm"),
        ("upperarm01.L", "LeftArm", "LeftForeArm"),
        ("upperarm02.L", "LeftArm", "LeftForeArm"),
        ("lowerarm01.L", "LeftForeArm", "LeftHand"),
        ("lowerarm02.L", "LeftForeArm", "LeftHand"),
        ("clavicle.R", "RightShoulder", "RightArm"),
        ("upperarm01.R", "RightArm", "RightForeArm"),
        ("upperarm02.R", "RightArm", "RightForeArm"),
        ("lowerarm01.R", "RightForeArm", "RightHand"),
        ("lowerarm02.R", "RightForeArm", "RightHand"),
    ],
    &[
        ("upperleg01.L", "thigh.L", "shin.L"),
        ("upperleg02.L", "thigh.L", "shin.L"),
        ("lowerleg01.L", "shin.L", "foot.L"),
        ("lowerleg02.L", "shin.L", "foot.L"),
        ("upperleg01.R", "thigh.R", "shin.R"),
        ("upperleg02.R", "thigh.R", "shin.R"),
        ("lowerleg01.R", "shin.R", "foot.R"),
        ("lowerleg02.R", "shin.R", "foot.R"),
        ("spine05", "pelvis", "spine"),
        ("spine04", "spine", "spine.001"),
        ("spine03", "spine", "spine.001"),
        ("spine02", "spine", "spine.001"),
        ("spine01", "spine.001", "neck"),
        ("neck01", "neck", "face"),
        ("neck02", "neck", "face"),
        ("neck03", "neck", "face"),
        ("clavicle.L", "shoulder.L", "upper_arm.L"),
        ("upperarm01.L", "upper_arm.L", "forearm.L"),
        ("upperarm02.L", "upper_arm.L", "forearm.L"),
        ("clavicle.R", "shoulder.R", "upper_arm.R"),
        ("upperarm01.R", "upper_arm.R", "forearm.R"),
        ("upperarm02.R", "upper_arm.R", "forearm.R"),
    ],
];

/// The heading frame (columns: across to the left, forward, up) from the vertical `up` and the
/// two hip joints; `None` when degenerate.
fn heading_frame(
    up: &Vector3<f64>,
    left: Vector3<f64>,
    right: Vector3<f64>,
) -> Option<Matrix3<f64>> {
    let across = left - right;
    let x = (across - up * up.dot(&across)).try_normalize(1e-9)?;
    Some(Matrix3::from_columns(&[x, up.cross(&x), *up]))
}

/// The smallest rotation taking unit `a` to unit `b` (nalgebra's; for opposite vectors, which
/// it leaves undefined, half a turn about an axis normal to `a`).
fn swing(a: &Vector3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
    Rotation3::rotation_between(a, b).map_or_else(
        || {
            let n = if a.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            axis_angle_to_matrix(&(a.cross(&n).normalize() * std::f64::consts::PI))
        },
        Rotation3::into_inner,
    )
}

/// A retargeting of one BVH skeleton to a body model.
pub struct Retarget {
    /// Per body bone: the motion-capture segment it follows.
    segments: Vec<Option<(usize, usize)>>,
    /// Rest bone directions of the body (world-aligned, unit).
    rest_dirs: Vec<Vector3<f64>>,
    /// The body's rest heading frame (its up is +Z).
    rest_heading: Matrix3<f64>,
    /// The motion capture's vertical: the coordinate axis nearest the mean hips → neck.
    up: Vector3<f64>,
    /// Motion-capture hip joints: left, right.
    hips: [usize; 2],
    parents: Vec<i32>,
}

impl Retarget {
    /// Matches `bvh`'s joint names to `model`'s bones (rest shape `shaped`).
    pub fn new(model: &BodyModel, shaped: &ShapedBody<f64>, bvh: &Bvh) -> Result<Self, BodyError> {
        let map = MAPS
            .iter()
            .find(|m| m.iter().all(|(_, a, b)| bvh.joint(a).is_some() && bvh.joint(b).is_some()))
            .ok_or_else(|| {
                bad(
                    "BVH",
                    "joint names match neither the Mixamo-like (Hips, LeftUpLeg, …) nor the Rigify-like (pelvis, thigh.L, …) skeleton",
                )
            })?;
        let mut segments = vec![None; model.n_joints()];
        for (bone, a, b) in map.iter() {
            let c = model
                .joint_index(bone)
                .ok_or_else(|| bad("body model", format!("no bone {bone}")))?;
            segments[c] = Some((bvh.joint(a).unwrap_or(0), bvh.joint(b).unwrap_or(0)));
        }
        let rest_dirs = (0..model.n_joints())
            .map(|c| {
                (shaped.joint_tails[c] - shaped.joint_heads[c])
                    .try_normalize(1e-12)
                    .unwrap_or_else(Vector3::z)
            })
            .collect();
        let head = |name: &str| -> Result<Vector3<f64>, BodyError> {
            model
                .joint_index(name)
                .map(|j| shaped.joint_heads[j])
                .ok_or_else(|| bad("body model", format!("no bone {name}")))
        };
        let rest_heading =
            heading_frame(&Vector3::z(), head("upperleg01.L")?, head("upperleg01.R")?)
                .ok_or_else(|| bad("body model", "degenerate rest hips"))?;
        let seg = |bone: &str| -> (usize, usize) {
            model
                .joint_index(bone)
                .and_then(|j| segments[j])
                .unwrap_or((0, 0))
        };
        let (pelvis, neck) = (seg("spine05").0, seg("spine01").1);
        let up = bvh.up.unwrap_or_else(|| {
            let mean_up = (0..bvh.frames.len())
                .step_by(10)
                .map(|f| {
                    let p = bvh.positions(f);
                    (p[neck] - p[pelvis])
                        .try_normalize(1e-9)
                        .unwrap_or_default()
                })
                .fold(Vector3::zeros(), |a, d| a + d);
            [Vector3::x(), Vector3::y(), Vector3::z()]
                .into_iter()
                .flat_map(|a| [a, -a])
                .max_by(|a, b| a.dot(&mean_up).total_cmp(&b.dot(&mean_up)))
                .expect("six axes")
        });
        let hips = [seg("upperleg01.L").0, seg("upperleg01.R").0];
        Ok(Self {
            segments,
            rest_dirs,
            rest_heading,
            up,
            hips,
            parents: model.asset.parents.clone(),
        })
    }

    /// The body's rotation vectors (root identity) for frame `f` of `bvh`; `None` when the
    /// frame's hips are degenerate.
    pub fn frame(&self, bvh: &Bvh, f: usize) -> Option<Vec<[f64; 3]>> {
        let p = bvh.positions(f);
        let [l, r] = self.hips.map(|j| p[j]);
        // Motion-capture world → the body's rest frame, through the heading frames (up kept,
        // so a lean stays a lean).
        let to_body = self.rest_heading * heading_frame(&self.up, l, r)?.transpose();
        let j = self.parents.len();
        let mut g = vec![Matrix3::identity(); j];
        let mut out = vec![[0.0; 3]; j];
        for c in 1..j {
            let gp = g[self.parents[c] as usize];
            g[c] = match self.segments[c] {
                Some((a, b)) => match (to_body * (p[b] - p[a])).try_normalize(1e-9) {
                    Some(v) => swing(&(gp * self.rest_dirs[c]), &v) * gp,
                    None => gp,
                },
                None => gp,
            };
            // FK: G_c = G_p D_c.
            out[c] = matrix_to_axis_angle(&(gp.transpose() * g[c])).into();
        }
        Some(out)
    }
}

/// Retargeted poses with their provenance: what `irmirror body retarget-bvh` writes and the
/// benchmark draws its persons from.
#[derive(Clone, Debug, PartialEq)]
pub struct MocapSet {
    /// Per pose, the body's rotation vectors (root identity), radians.
    pub poses: Vec<Vec<[f64; 3]>>,
    /// Where each pose came from: `<file>:<frame>`.
    pub sources: Vec<String>,
    /// Provenance (source package, licence, the command that made the set).
    pub provenance: String,
}

/// The shipped set (see `assets/poses/README.md`).
const BUILTIN: &[u8] = include_bytes!("../../../assets/poses/mocap_bvhtools.safetensors");

/// The pose prior's real training poses (DeepMimic clips; `assets/poses/README.md`).
const PRIOR_TRAINING: &[u8] = include_bytes!("../../../assets/poses/mocap_deepmimic.safetensors");

impl MocapSet {
    /// The shipped set: the benchmark's persons.
    pub fn builtin() -> Result<Self, BodyError> {
        Self::from_bytes(BUILTIN, "built-in motion-capture poses")
    }

    /// The pose prior's real training poses (another source than [`Self::builtin`]: never
    /// the benchmark's persons).
    pub fn prior_training() -> Result<Self, BodyError> {
        Self::from_bytes(PRIOR_TRAINING, "built-in pose-prior training poses")
    }

    /// Serialises to safetensors: `rotvecs` (N × J × 3, f32), metadata `sources` (JSON list) and
    /// `provenance`.
    pub fn to_bytes(&self) -> Result<Vec<u8>, BodyError> {
        let j = self.poses.first().map_or(0, Vec::len);
        let flat: Vec<f32> = self
            .poses
            .iter()
            .flatten()
            .flatten()
            .map(|&x| x as f32)
            .collect();
        let data = bytemuck::cast_slice::<f32, u8>(&flat).to_vec();
        let view = safetensors::tensor::TensorView::new(
            safetensors::Dtype::F32,
            vec![self.poses.len(), j, 3],
            &data,
        )
        .map_err(|e| bad("(writing)", e.to_string()))?;
        let header = std::collections::HashMap::from([
            (
                "sources".to_string(),
                serde_json::to_string(&self.sources).expect("strings serialise"),
            ),
            ("provenance".to_string(), self.provenance.clone()),
        ]);
        safetensors::serialize(vec![("rotvecs".to_string(), view)], Some(header))
            .map_err(|e| bad("(writing)", e.to_string()))
    }

    /// Reads what [`Self::to_bytes`] wrote.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, BodyError> {
        let st = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| bad(origin, format!("not a safetensors file: {e}")))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(origin, e.to_string()))?;
        let meta = header.metadata().clone().unwrap_or_default();
        let sources: Vec<String> = meta
            .get("sources")
            .and_then(|s| serde_json::from_str(s).ok())
            .ok_or_else(|| bad(origin, "no `sources` metadata"))?;
        let t = st
            .tensor("rotvecs")
            .map_err(|e| bad(origin, format!("rotvecs: {e}")))?;
        let shape = t.shape().to_vec();
        if t.dtype() != safetensors::Dtype::F32 || shape.len() != 3 || shape[2] != 3 {
            return Err(bad(origin, "rotvecs must be N × J × 3 f32"));
        }
        if shape[0] != sources.len() || shape[0] == 0 {
            return Err(bad(origin, "rotvecs and sources disagree, or no poses"));
        }
        let vals: Vec<f32> = bytemuck::pod_collect_to_vec(t.data());
        if vals.iter().any(|x| !x.is_finite()) {
            return Err(bad(origin, "non-finite rotation"));
        }
        let poses = vals
            .chunks(shape[1] * 3)
            .map(|p| {
                p.chunks(3)
                    .map(|r| [f64::from(r[0]), f64::from(r[1]), f64::from(r[2])])
                    .collect()
            })
            .collect();
        Ok(Self {
            poses,
            sources,
            provenance: meta.get("provenance").cloned().unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TINY: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.033333
1 2 3 0 0 0 0 0 0
0 0 0 90 0 0 0 0 90
";

    /// Positions of a two-joint chain against hand-computed ones (intrinsic Z-Y-X channels).
    #[test]
    fn bvh_positions_follow_the_channels() {
        let b = Bvh::parse(TINY, "tiny").unwrap();
        assert_eq!(b.names, ["Hips", "Arm"]);
        assert_eq!(b.parents, [-1, 0]);
        let p0 = b.positions(0);
        assert!((p0[0] - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
        assert!((p0[1] - Vector3::new(11.0, 2.0, 3.0)).norm() < 1e-12);
        // Root turned 90° about Z: the arm's offset (10, 0, 0) goes to (0, 10, 0).
        let p1 = b.positions(1);
        assert!(
            (p1[1] - Vector3::new(0.0, 10.0, 0.0)).norm() < 1e-9,
            "{p1:?}"
        );
    }

    /// Broken files are refused with a reason.
    #[test]
    fn bad_bvh_is_refused() {
        assert!(Bvh::parse("hello", "x").is_err());
        let short = TINY.replace("0 0 0 90 0 0 0 0 90\n", "");
        assert!(
            Bvh::parse(&short, "x")
                .unwrap_err()
                .to_string()
                .contains("frames")
        );
        assert!(
            Bvh::parse(
                &TINY.replace(
                    "Zrotation Yrotation Xrotation\n    End",
                    "Wrotation Yrotation Xrotation\n    End"
                ),
                "x"
            )
            .is_err()
        );
    }

    /// The swing maps one direction onto another and is a rotation.
    #[test]
    fn swing_is_the_smallest_rotation() {
        let a = Vector3::new(1.0, 2.0, -0.5).normalize();
        for b in [Vector3::new(-0.3, 0.1, 0.9).normalize(), a, -a] {
            let r = swing(&a, &b);
            assert!((r * a - b).norm() < 1e-9);
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-9);
        }
    }
}
