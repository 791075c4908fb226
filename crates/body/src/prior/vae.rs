//! The pose VAE (a VPoser-like prior): encoder and decoder MLPs over the 35 body-joint rotations
//! (6-D each), latent 32, decoded through Gram–Schmidt to rotation matrices. Candle tensors stay
//! inside this module; the rest of irmirror sees plain arrays.
//!
//! | tensor | shape | meaning |
//! |---|---|---|
//! | `enc{1,2,3}.{weight,bias}` | 512×210, 512×512, 64×512 | encoder (SiLU); the last layer gives μ (32) and log σ² (32) |
//! | `dec{1,2,3}.{weight,bias}` | 512×32, 512×512, 210×512 | decoder (SiLU), 6-D per joint |
//!
//! Rotations are world-aligned rest-axis joint rotations of bones 1…35 (the root's global
//! rotation is optimised separately).

use candle_core::{D, DType, Device, Tensor, Var};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use std::collections::HashMap;
use std::path::Path;

/// Latent dimension.
pub const LATENT: usize = 32;
/// Hidden width.
pub const HIDDEN: usize = 512;
/// Joints modelled (all but the root).
pub const JOINTS: usize = 35;

/// Errors of the prior (wrapping candle's).
#[derive(Debug, thiserror::Error)]
pub enum PriorError {
    /// A tensor operation failed (shape mismatch, I/O …).
    #[error("pose prior: {0}")]
    Candle(#[from] candle_core::Error),
    /// The body model or a pose set failed (the training figures pose the body).
    #[error("pose prior: {0}")]
    Body(#[from] crate::BodyError),
    /// The real poses given to training cannot be trained on.
    #[error("real poses: {0}")]
    RealPoses(String),
    /// The weights file is not a pose prior.
    #[error("pose prior weights {path}: {reason}")]
    Weights {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

const LAYERS: [(&str, usize, usize); 6] = [
    ("enc1", 6 * JOINTS, HIDDEN),
    ("enc2", HIDDEN, HIDDEN),
    ("enc3", HIDDEN, 2 * LATENT),
    ("dec1", LATENT, HIDDEN),
    ("dec2", HIDDEN, HIDDEN),
    ("dec3", HIDDEN, 6 * JOINTS),
];

/// The network: one weight and bias variable per layer.
pub struct PoseVae {
    vars: HashMap<String, Var>,
    device: Device,
    /// Weights enter computations detached (inference): decoding a plain latent then records
    /// no autodiff graph.
    frozen: bool,
}

impl PoseVae {
    /// A freshly initialised network (He-uniform weights, zero biases) from `rng`.
    pub fn new(rng: &mut impl Rng) -> Result<Self, PriorError> {
        let device = Device::Cpu;
        let mut vars = HashMap::new();
        for (name, fan_in, fan_out) in LAYERS {
            let bound = (6.0 / fan_in as f64).sqrt();
            let w: Vec<f32> = (0..fan_in * fan_out)
                .map(|_| rng.random_range(-bound..bound) as f32)
                .collect();
            vars.insert(
                format!("{name}.weight"),
                Var::from_tensor(&Tensor::from_vec(w, (fan_out, fan_in), &device)?)?,
            );
            vars.insert(
                format!("{name}.bias"),
                Var::from_tensor(&Tensor::zeros(fan_out, DType::F32, &device)?)?,
            );
        }
        Ok(Self {
            vars,
            device,
            frozen: false,
        })
    }

    /// Loads weights (safetensors), checking every tensor's shape; `dtype` F32 or F64.
    pub fn load(path: &Path, dtype: DType) -> Result<Self, PriorError> {
        let device = Device::Cpu;
        let bad = |r: String| PriorError::Weights {
            path: path.display().to_string(),
            reason: r,
        };
        let tensors =
            candle_core::safetensors::load(path, &device).map_err(|e| bad(e.to_string()))?;
        Self::from_tensors(tensors, dtype).map_err(|e| bad(e.to_string()))
    }

    /// From a name → tensor map (e.g. weights compiled into the binary).
    pub fn from_tensors(
        tensors: HashMap<String, Tensor>,
        dtype: DType,
    ) -> Result<Self, PriorError> {
        let device = Device::Cpu;
        let mut vars = HashMap::new();
        for (name, fan_in, fan_out) in LAYERS {
            for (suffix, shape) in [("weight", vec![fan_out, fan_in]), ("bias", vec![fan_out])] {
                let key = format!("{name}.{suffix}");
                let t = tensors
                    .get(&key)
                    .ok_or_else(|| candle_core::Error::Msg(format!("missing tensor `{key}`")))?;
                if t.dims() != shape.as_slice() {
                    return Err(candle_core::Error::Msg(format!(
                        "tensor `{key}` has shape {:?}, expected {shape:?}",
                        t.dims()
                    ))
                    .into());
                }
                vars.insert(key, Var::from_tensor(&t.to_dtype(dtype)?)?);
            }
        }
        Ok(Self {
            vars,
            device,
            frozen: false,
        })
    }

    /// Writes the weights (f32 safetensors).
    pub fn save(&self, path: &Path) -> Result<(), PriorError> {
        let map: HashMap<String, Tensor> = self
            .vars
            .iter()
            .map(|(k, v)| Ok((k.clone(), v.as_tensor().to_dtype(DType::F32)?)))
            .collect::<Result<_, candle_core::Error>>()?;
        candle_core::safetensors::save(&map, path)?;
        Ok(())
    }

    /// All trainable variables.
    pub fn vars(&self) -> Vec<Var> {
        let mut keys: Vec<&String> = self.vars.keys().collect();
        keys.sort();
        keys.into_iter().map(|k| self.vars[k].clone()).collect()
    }

    /// The variables' current values (copies), by name.
    pub fn vars_map(&self) -> Result<HashMap<String, Tensor>, candle_core::Error> {
        self.vars
            .iter()
            .map(|(k, v)| Ok((k.clone(), v.as_tensor().copy()?)))
            .collect()
    }

    /// The device (CPU).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The dtype of the weights.
    pub fn dtype(&self) -> DType {
        self.vars["enc1.weight"].dtype()
    }

    fn layer(&self, name: &str, x: &Tensor) -> Result<Tensor, candle_core::Error> {
        let w = self.vars[&format!("{name}.weight")].as_tensor();
        let b = self.vars[&format!("{name}.bias")].as_tensor();
        if self.frozen {
            x.matmul(&w.detach().t()?)?.broadcast_add(&b.detach())
        } else {
            x.matmul(&w.t()?)?.broadcast_add(b)
        }
    }

    /// The weight `(out, in)` and bias `(out)` of a layer (`enc1` … `dec3`).
    pub fn layer_weights(&self, name: &str) -> Result<(Tensor, Tensor), candle_core::Error> {
        let get = |k: String| {
            self.vars
                .get(&k)
                .map(|v| v.as_tensor().detach())
                .ok_or_else(|| candle_core::Error::Msg(format!("no layer `{name}`")))
        };
        Ok((get(format!("{name}.weight"))?, get(format!("{name}.bias"))?))
    }

    /// The same network for inference: weights no longer tracked by autodiff.
    pub fn frozen(mut self) -> Self {
        self.frozen = true;
        self
    }

    /// Encoder: `(B, 210)` 6-D poses → `(μ, log σ²)`, each `(B, 32)`.
    pub fn encode(&self, x: &Tensor) -> Result<(Tensor, Tensor), candle_core::Error> {
        let h = self.layer("enc1", x)?.silu()?;
        let h = self.layer("enc2", &h)?.silu()?;
        let out = self.layer("enc3", &h)?;
        Ok((out.narrow(1, 0, LATENT)?, out.narrow(1, LATENT, LATENT)?))
    }

    /// Decoder: `(B, 32)` latents → `(B, 35, 3, 3)` rotation matrices.
    pub fn decode(&self, z: &Tensor) -> Result<Tensor, candle_core::Error> {
        let h = self.layer("dec1", z)?.silu()?;
        let h = self.layer("dec2", &h)?.silu()?;
        let six = self.layer("dec3", &h)?;
        sixd_to_matrix(&six.reshape((z.dim(0)?, JOINTS, 6))?)
    }

    /// A `(B, 32)` tensor of standard-normal samples from `rng`.
    pub fn normal(&self, rng: &mut impl Rng, b: usize) -> Result<Tensor, candle_core::Error> {
        let v: Vec<f64> = (0..b * LATENT)
            .map(|_| StandardNormal.sample(rng))
            .collect();
        Tensor::from_vec(v, (b, LATENT), &self.device)?.to_dtype(self.dtype())
    }
}

/// Gram–Schmidt on `(…, 6)` → `(…, 3, 3)` with the two 6-D columns as the first two columns
/// (same convention as `irmirror_geom::rotation::sixd_to_matrix`).
pub fn sixd_to_matrix(x: &Tensor) -> Result<Tensor, candle_core::Error> {
    let eps = 1e-8;
    let a1 = x.narrow(D::Minus1, 0, 3)?;
    let a2 = x.narrow(D::Minus1, 3, 3)?;
    let norm = |v: &Tensor| -> Result<Tensor, candle_core::Error> {
        v.sqr()?.sum_keepdim(D::Minus1)?.affine(1.0, eps)?.sqrt()
    };
    let b1 = a1.broadcast_div(&norm(&a1)?)?;
    let dot = (&b1 * &a2)?.sum_keepdim(D::Minus1)?;
    let u = (&a2 - b1.broadcast_mul(&dot)?)?;
    let b2 = u.broadcast_div(&norm(&u)?)?;
    let c = |v: &Tensor, i: usize| v.narrow(D::Minus1, i, 1);
    let (x1, y1, z1) = (c(&b1, 0)?, c(&b1, 1)?, c(&b1, 2)?);
    let (x2, y2, z2) = (c(&b2, 0)?, c(&b2, 1)?, c(&b2, 2)?);
    let b3 = Tensor::cat(
        &[
            ((&y1 * &z2)? - (&z1 * &y2)?)?,
            ((&z1 * &x2)? - (&x1 * &z2)?)?,
            ((&x1 * &y2)? - (&y1 * &x2)?)?,
        ],
        D::Minus1,
    )?;
    // Columns b1, b2, b3: stack on the last axis then the matrix is [row][col].
    Tensor::stack(&[b1, b2, b3], D::Minus1)
}
