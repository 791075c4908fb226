//! The runtime body: shape → FK → LBS → keypoints, and the backward pass through all of it.
//!
//! | parameter | unit | frame | differentiable |
//! |---|---|---|---|
//! | `Pose::rotations[0]` (global rotation) | rotation matrix | Anny world axes | yes (`BodyGrad::rotations[0]`) |
//! | `Pose::rotations[c]`, c ≥ 1 | rotation matrix, world-aligned rest axes | — | yes |
//! | `Pose::translation` (root joint position) | m | output frame | yes |
//! | shape coefficients `z` | — (orthonormal basis, m per unit) | — | yes (`BodyGrad::shape`) |
//! | `Phenotype` | [0, 1] | — | no (maps to `z`) |
//!
//! Outputs (vertices, joints, keypoints) are in metres in the frame of `translation`; with
//! identity rotations and `translation = rest root joint` they equal the shaped rest body
//! (Z up, −Y front). Rotation parameterisations (axis-angle, 6-D) chain onto `∂L/∂R` with
//! `irmirror_geom::rotation`.

use crate::lbs::LbsScratch;
use crate::shape::ShapedBody;
use crate::{BodyAsset, BodyError, Phenotype, fk, keypoints, lbs, shape};
use irmirror_geom::rotation::{axis_angle_to_matrix, axis_angle_to_matrix_vjp, rot_y};
use irmirror_geom::{Real, TriMesh};
use nalgebra::{Matrix3, Vector3};

/// The body model over one asset.
#[derive(Clone, Debug)]
pub struct BodyModel {
    /// The asset.
    pub asset: BodyAsset,
    /// Skin weights renormalised in f64 (the file's f32 rows sum to 1 only within 1e-7; these
    /// make the zero pose reproduce the rest mesh to f64 rounding).
    skin_weights: Vec<f64>,
    /// Keypoint weights renormalised per keypoint in f64.
    keypoint_weights: Vec<f64>,
}

/// Joint rotations and root translation.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose<T: Real> {
    /// One rotation per bone; index 0 is the global rotation about the root joint.
    pub rotations: Vec<Matrix3<T>>,
    /// Posed root-joint position, metres.
    pub translation: Vector3<T>,
}

impl<T: Real> Pose<T> {
    /// Identity rotations, root at the origin.
    pub fn identity(n_joints: usize) -> Self {
        Self {
            rotations: vec![Matrix3::identity(); n_joints],
            translation: Vector3::zeros(),
        }
    }

    /// From rotation vectors (axis · angle, radians), one per bone.
    pub fn from_axis_angles(rotvecs: &[[T; 3]], translation: Vector3<T>) -> Self {
        Self {
            rotations: rotvecs
                .iter()
                .map(|w| axis_angle_to_matrix(&Vector3::from(*w)))
                .collect(),
            translation,
        }
    }

    /// Checks the length against the model and that every value is finite.
    pub fn validate(&self, n_joints: usize) -> Result<(), BodyError> {
        if self.rotations.len() != n_joints {
            return Err(BodyError::param(
                "pose.rotations",
                format!(
                    "{} rotations given, the body has {n_joints} joints",
                    self.rotations.len()
                ),
            ));
        }
        if self
            .rotations
            .iter()
            .flat_map(|r| r.iter())
            .chain(self.translation.iter())
            .any(|x| !x.is_finite())
        {
            return Err(BodyError::param("pose", "non-finite value"));
        }
        Ok(())
    }
}

/// Posed outputs plus the FK state the backward pass reuses; allocate once, reuse per frame.
#[derive(Clone, Debug)]
pub struct PosedBody<T: Real> {
    /// Posed vertices, m.
    pub vertices: Vec<Vector3<T>>,
    /// Posed joint positions, m.
    pub joints: Vec<Vector3<T>>,
    /// Posed keypoints (COCO-17 + 6 foot points), m.
    pub keypoints: Vec<Vector3<T>>,
    /// World rotation of each joint, `G_c`.
    pub world_rotations: Vec<Matrix3<T>>,
    skin_offsets: Vec<Vector3<T>>,
    // Backward scratch.
    d_vertices: Vec<Vector3<T>>,
    d_rest: Vec<Vector3<T>>,
    d_a: Vec<Matrix3<T>>,
    d_b: Vec<Vector3<T>>,
    d_t: Vec<Vector3<T>>,
    d_heads: Vec<Vector3<T>>,
    lbs: LbsScratch<T>,
}

impl<T: Real> PosedBody<T> {
    /// After [`BodyModel::backward`] or [`BodyModel::backward_pose`]: the loss's derivative as
    /// the rest body moves along `dir` ([`crate::shape::direction_into`]: `∂L/∂z · dz` for the
    /// `dz` it was made from; bone tails do not affect posing).
    pub fn rest_grad_along(&self, dir: &ShapedBody<T>) -> T {
        let dot = |d: &[Vector3<T>], v: &[Vector3<T>]| {
            d.iter().zip(v).fold(T::zero(), |s, (a, b)| s + a.dot(b))
        };
        dot(&self.d_rest, &dir.vertices) + dot(&self.d_heads, &dir.joint_heads)
    }
}

/// Gradients of a scalar loss w.r.t. the body parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyGrad<T: Real> {
    /// `∂L/∂R_c` per joint (3×3; chain to axis-angle or 6-D with `irmirror_geom::rotation`).
    pub rotations: Vec<Matrix3<T>>,
    /// `∂L/∂translation`.
    pub translation: Vector3<T>,
    /// `∂L/∂z`.
    pub shape: Vec<T>,
}

impl<T: Real> BodyGrad<T> {
    /// Gradients w.r.t. rotation vectors `w_c` (the pose given by [`Pose::from_axis_angles`]).
    pub fn axis_angle(&self, rotvecs: &[[T; 3]]) -> Vec<[T; 3]> {
        rotvecs
            .iter()
            .zip(&self.rotations)
            .map(|(w, g)| axis_angle_to_matrix_vjp(&Vector3::from(*w), g).into())
            .collect()
    }
}

/// Upstream gradients on the outputs (any may be absent).
#[derive(Clone, Copy, Debug, Default)]
pub struct OutputGrads<'a, T: Real> {
    /// `∂L/∂vertices`.
    pub vertices: Option<&'a [Vector3<T>]>,
    /// `∂L/∂joints`.
    pub joints: Option<&'a [Vector3<T>]>,
    /// `∂L/∂keypoints`.
    pub keypoints: Option<&'a [Vector3<T>]>,
}

impl BodyModel {
    /// Wraps an asset.
    pub fn new(asset: BodyAsset) -> Self {
        let k = asset.influences;
        let mut skin_weights: Vec<f64> = asset.skin_weights.iter().map(|&w| f64::from(w)).collect();
        for row in skin_weights.chunks_exact_mut(k) {
            let s: f64 = row.iter().sum();
            row.iter_mut().for_each(|w| *w /= s);
        }
        let mut sums = vec![0.0f64; asset.meta.keypoint_labels.len()];
        for (&kp, &w) in asset.coco_kp_index.iter().zip(&asset.coco_weight) {
            sums[kp as usize] += f64::from(w);
        }
        let keypoint_weights = asset
            .coco_kp_index
            .iter()
            .zip(&asset.coco_weight)
            .map(|(&kp, &w)| f64::from(w) / sums[kp as usize])
            .collect();
        Self {
            asset,
            skin_weights,
            keypoint_weights,
        }
    }

    /// The model of the asset compiled into the binary.
    pub fn builtin() -> Result<Self, BodyError> {
        Ok(Self::new(BodyAsset::builtin()?))
    }

    /// Vertices V.
    pub fn n_vertices(&self) -> usize {
        self.asset.n_vertices()
    }
    /// Joints J.
    pub fn n_joints(&self) -> usize {
        self.asset.n_joints()
    }
    /// Keypoints.
    pub fn n_keypoints(&self) -> usize {
        self.asset.meta.keypoint_labels.len()
    }
    /// Shape rank r.
    pub fn rank(&self) -> usize {
        self.asset.rank()
    }

    /// Shape coefficients `z = c(phenotype) · P − z0`.
    pub fn shape_coefficients(&self, phenotype: &Phenotype) -> Result<Vec<f64>, BodyError> {
        let c = phenotype.coefficients(&self.asset)?;
        let r = self.rank();
        let mut z: Vec<f64> = self
            .asset
            .shape_offset
            .iter()
            .map(|&o| -f64::from(o))
            .collect();
        for (b, cb) in c.iter().enumerate().filter(|(_, cb)| **cb != 0.0) {
            for i in 0..r {
                z[i] += cb * f64::from(self.asset.shape_projection[b * r + i]);
            }
        }
        Ok(z)
    }

    /// The rest body for shape coefficients `z`.
    pub fn shaped<T: Real>(&self, z: &[T]) -> Result<ShapedBody<T>, BodyError> {
        if z.len() != self.rank() {
            return Err(BodyError::param(
                "shape",
                format!(
                    "{} coefficients given, the asset has rank {}",
                    z.len(),
                    self.rank()
                ),
            ));
        }
        if z.iter().any(|x| !x.is_finite()) {
            return Err(BodyError::param("shape", "non-finite coefficient"));
        }
        let mut out = ShapedBody {
            z: vec![],
            vertices: vec![],
            joint_heads: vec![],
            joint_tails: vec![],
        };
        shape::shape_into(&self.asset, z, &mut out);
        Ok(out)
    }

    /// The skinning inputs of a shaped body.
    fn skin<'a, T: Real>(&'a self, shaped: &'a ShapedBody<T>) -> lbs::Skin<'a, T> {
        lbs::Skin {
            rest: &shaped.vertices,
            indices: &self.asset.skin_indices,
            weights: &self.skin_weights,
            influences: self.asset.influences,
        }
    }

    /// The rest body of a phenotype.
    pub fn shaped_phenotype<T: Real>(
        &self,
        phenotype: &Phenotype,
    ) -> Result<ShapedBody<T>, BodyError> {
        let z: Vec<T> = self
            .shape_coefficients(phenotype)?
            .into_iter()
            .map(T::of)
            .collect();
        self.shaped(&z)
    }

    /// Blender rest frames `R_c = A(head→tail) · Ry(roll)`, root = I (ANNY_SPEC.md §4.2): the
    /// columns are the bone's local axes, local Y along the bone.
    pub fn rest_frames<T: Real>(&self, shaped: &ShapedBody<T>) -> Vec<Matrix3<T>> {
        (0..self.n_joints())
            .map(|c| {
                if c == 0 {
                    return Matrix3::identity();
                }
                let y = (shaped.joint_tails[c] - shaped.joint_heads[c]).normalize();
                let axis = y.cross(&Vector3::y());
                let (s, cos) = (axis.norm(), y.dot(&Vector3::y()));
                let a = if s.to_f64() < 1e-12 {
                    if cos > T::zero() {
                        Matrix3::identity()
                    } else {
                        Matrix3::from_diagonal(&Vector3::new(T::one(), -T::one(), -T::one()))
                    }
                } else {
                    axis_angle_to_matrix(&(axis * (-s.atan2(cos) / s)))
                };
                a * rot_y(T::of(f64::from(self.asset.bone_roll[c])))
            })
            .collect()
    }

    /// Buffers for posing this model (allocate once per body and reuse).
    pub fn posed_buffers<T: Real>(&self) -> PosedBody<T> {
        let (v, j) = (self.n_vertices(), self.n_joints());
        PosedBody {
            vertices: vec![Vector3::zeros(); v],
            joints: vec![Vector3::zeros(); j],
            keypoints: vec![Vector3::zeros(); self.n_keypoints()],
            world_rotations: vec![Matrix3::identity(); j],
            skin_offsets: vec![Vector3::zeros(); j],
            d_vertices: vec![Vector3::zeros(); v],
            d_rest: vec![Vector3::zeros(); v],
            d_a: vec![Matrix3::zeros(); j],
            d_b: vec![Vector3::zeros(); j],
            d_t: vec![Vector3::zeros(); j],
            d_heads: vec![Vector3::zeros(); j],
            lbs: LbsScratch::new(v, j),
        }
    }

    /// Poses `shaped` into `out` (no allocation).
    pub fn pose_into<T: Real>(
        &self,
        shaped: &ShapedBody<T>,
        pose: &Pose<T>,
        out: &mut PosedBody<T>,
    ) -> Result<(), BodyError> {
        self.pose_surface_into(shaped, pose, out)?;
        keypoints::regress(
            &self.asset.coco_kp_index,
            &self.asset.coco_vertex_index,
            &self.keypoint_weights,
            &out.vertices,
            &mut out.keypoints,
        );
        Ok(())
    }

    /// [`Self::pose_into`] without the keypoints (`out.keypoints` are left as they were): for
    /// a caller that draws only the surface of many bodies (the pose retrieval).
    pub fn pose_surface_into<T: Real>(
        &self,
        shaped: &ShapedBody<T>,
        pose: &Pose<T>,
        out: &mut PosedBody<T>,
    ) -> Result<(), BodyError> {
        pose.validate(self.n_joints())?;
        let a = &self.asset;
        fk::forward(
            &a.parents,
            &shaped.joint_heads,
            &pose.rotations,
            &pose.translation,
            &mut out.world_rotations,
            &mut out.joints,
        );
        fk::skinning_offsets(
            &shaped.joint_heads,
            &out.world_rotations,
            &out.joints,
            &mut out.skin_offsets,
        );
        lbs::forward(
            &self.skin(shaped),
            &out.world_rotations,
            &out.skin_offsets,
            &mut out.vertices,
        );
        Ok(())
    }

    /// Poses `shaped`, allocating the outputs.
    pub fn pose<T: Real>(
        &self,
        shaped: &ShapedBody<T>,
        pose: &Pose<T>,
    ) -> Result<PosedBody<T>, BodyError> {
        let mut out = self.posed_buffers();
        self.pose_into(shaped, pose, &mut out)?;
        Ok(out)
    }

    /// Backward pass after [`Self::pose_into`] with the same `shaped` and `pose`: gradients of a
    /// loss whose output gradients are `grads`, written into `out` (no allocation once `out`
    /// has the right lengths).
    pub fn backward<T: Real>(
        &self,
        shaped: &ShapedBody<T>,
        pose: &Pose<T>,
        posed: &mut PosedBody<T>,
        grads: OutputGrads<'_, T>,
        out: &mut BodyGrad<T>,
    ) {
        self.backward_pose(shaped, pose, posed, grads, out);
        out.shape.resize(self.rank(), T::zero());
        shape::shape_vjp(&self.asset, &posed.d_rest, &posed.d_heads, &mut out.shape);
    }

    /// [`Self::backward`] but for `∂L/∂z` (`out.shape` is left as it was): the rotations' and
    /// translation's gradients, and in `posed` the rest body's, which
    /// [`PosedBody::rest_grad_along`] reads along a shape direction — for a caller that fits
    /// one phenotype slider, the 32 coefficients' VJP (the whole shape basis) is not needed.
    pub fn backward_pose<T: Real>(
        &self,
        shaped: &ShapedBody<T>,
        pose: &Pose<T>,
        posed: &mut PosedBody<T>,
        grads: OutputGrads<'_, T>,
        out: &mut BodyGrad<T>,
    ) {
        let a = &self.asset;
        out.rotations.resize(self.n_joints(), Matrix3::zeros());
        match grads.vertices {
            Some(d) => posed.d_vertices.copy_from_slice(d),
            None => posed
                .d_vertices
                .iter_mut()
                .for_each(|x| *x = Vector3::zeros()),
        }
        if let Some(dk) = grads.keypoints {
            keypoints::regress_vjp(
                &a.coco_kp_index,
                &a.coco_vertex_index,
                &self.keypoint_weights,
                dk,
                &mut posed.d_vertices,
            );
        }
        lbs::forward_vjp(
            &self.skin(shaped),
            &posed.world_rotations,
            &posed.d_vertices,
            lbs::LbsGrad {
                a: &mut posed.d_a,
                b: &mut posed.d_b,
                rest: &mut posed.d_rest,
            },
            &mut posed.lbs,
        );
        match grads.joints {
            Some(d) => posed.d_t.copy_from_slice(d),
            None => posed.d_t.iter_mut().for_each(|x| *x = Vector3::zeros()),
        }
        posed.d_heads.iter_mut().for_each(|x| *x = Vector3::zeros());
        // d_a now holds ∂L/∂G (A = G); fold in the offsets b = t − G h.
        fk::skinning_offsets_vjp(
            &shaped.joint_heads,
            &posed.world_rotations,
            &posed.d_b,
            &mut posed.d_a,
            &mut posed.d_t,
            &mut posed.d_heads,
        );
        out.translation = fk::forward_vjp(
            &fk::Skeleton {
                parents: &a.parents,
                heads: &shaped.joint_heads,
            },
            &pose.rotations,
            &posed.world_rotations,
            fk::FkGrad {
                g: &mut posed.d_a,
                t: &mut posed.d_t,
                rotations: &mut out.rotations,
                heads: &mut posed.d_heads,
            },
        );
    }

    /// The posed mesh as an `f32` triangle mesh (frame of the pose's translation).
    pub fn mesh<T: Real>(&self, posed: &PosedBody<T>) -> TriMesh {
        TriMesh {
            vertices: posed
                .vertices
                .iter()
                .map(|v| {
                    [
                        v.x.to_f64() as f32,
                        v.y.to_f64() as f32,
                        v.z.to_f64() as f32,
                    ]
                })
                .collect(),
            triangles: self.asset.faces.clone(),
        }
    }

    /// Index of a bone by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.asset.meta.bone_names.iter().position(|n| n == name)
    }

    /// For each bone, its left/right counterpart (itself for midline bones).
    pub fn mirror_joints(&self) -> Vec<usize> {
        let names = &self.asset.meta.bone_names;
        names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let other = if let Some(s) = n.strip_suffix(".L") {
                    format!("{s}.R")
                } else if let Some(s) = n.strip_suffix(".R") {
                    format!("{s}.L")
                } else {
                    return i;
                };
                names.iter().position(|m| *m == other).unwrap_or(i)
            })
            .collect()
    }
}

/// A rotation vector mirrored through the body's sagittal plane (x → −x): `(wx, −wy, −wz)`.
pub fn mirror_axis_angle<T: Real>(w: [T; 3]) -> [T; 3] {
    [w[0], -w[1], -w[2]]
}
