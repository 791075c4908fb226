//! The pose prior (paper: VPoser): a VAE over the 35 body-joint rotations, trained by
//! `irmirror train-pose-prior` on a procedural, anatomically limited pose set, shipped as
//! `assets/pose_prior/pose_vae.safetensors`.
//!
//! | parameter | unit | differentiable |
//! |---|---|---|
//! | latent `z` (32) | — (prior N(0, I)) | yes: [`PosePrior::decode_vjp`] |
//! | decoded joint rotations 1…35 | rotation matrices, world-aligned rest axes | — |
//!
//! Gradients of an image loss reach `z` by a hand-written VJP of the decoder (three linear
//! layers, SiLU, Gram–Schmidt) in f64: candle's backward of a matmul always forms the weight
//! gradient too (a 512×512 outer product and its accumulation per call), which was most of a
//! stage-2 step. Training uses candle's autodiff. The prior term is `‖z‖²`.

pub mod generator;
pub mod limits;
pub mod penetration;
pub mod train;
pub mod vae;

use candle_core::{DType, Tensor};
use irmirror_geom::rotation::{
    axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_sixd, sixd_to_matrix, sixd_to_matrix_vjp,
};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
pub use vae::{JOINTS, LATENT, PoseVae, PriorError};

/// The shipped weights (see `assets/pose_prior/README.md`).
pub const BUILTIN_WEIGHTS: &[u8] =
    include_bytes!("../../../../assets/pose_prior/pose_vae.safetensors");

/// The prior, ready to decode.
pub struct PosePrior {
    vae: PoseVae,
    /// The decoder's weights and biases in f64 (`dec1`, `dec2`, `dec3`), for the hand-written
    /// VJP (module docs).
    decoder: [(DMatrix<f64>, DVector<f64>); 3],
}

impl PosePrior {
    /// Wraps a network.
    pub fn new(vae: PoseVae) -> Result<Self, PriorError> {
        let layer = |name: &str| -> Result<(DMatrix<f64>, DVector<f64>), PriorError> {
            let (w, b) = vae.layer_weights(name)?;
            let (rows, cols) = w.dims2()?;
            let w = w.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?;
            let b = b.to_dtype(DType::F64)?.to_vec1::<f64>()?;
            Ok((
                DMatrix::from_row_slice(rows, cols, &w),
                DVector::from_vec(b),
            ))
        };
        let decoder = [layer("dec1")?, layer("dec2")?, layer("dec3")?];
        Ok(Self {
            vae: vae.frozen(),
            decoder,
        })
    }

    /// The shipped prior in `dtype` (F32 for use, F64 for gradient tests).
    pub fn builtin(dtype: DType) -> Result<Self, PriorError> {
        let tensors =
            candle_core::safetensors::load_buffer(BUILTIN_WEIGHTS, &candle_core::Device::Cpu)?;
        Self::new(PoseVae::from_tensors(tensors, dtype)?)
    }

    /// The shipped prior in f64 (what stage 2 and evaluation use), without naming candle's
    /// types outside this crate.
    pub fn builtin_f64() -> Result<Self, PriorError> {
        Self::builtin(DType::F64)
    }

    /// A trained prior from a weights file, in f32 (what training and its samples use).
    pub fn load_f32(path: &std::path::Path) -> Result<Self, PriorError> {
        Self::new(PoseVae::load(path, DType::F32)?)
    }

    /// The network.
    pub fn vae(&self) -> &PoseVae {
        &self.vae
    }

    /// Decodes one latent to 36 rotations (index 0, the root, is the identity), in f64 by
    /// the same forward as [`Self::decode_vjp`]: a stage-2 step decodes one latent, which
    /// through candle's tensors (and its thread-count lookup per matmul) cost 3 % of a step.
    pub fn decode(&self, z: &[f64]) -> Result<Vec<Matrix3<f64>>, PriorError> {
        Ok(self.decode_taped(z)?.rotations)
    }

    /// [`Self::decode`], keeping what [`Self::vjp_taped`] needs (one forward per step, not two).
    pub fn decode_taped(&self, z: &[f64]) -> Result<Decoded, PriorError> {
        let [a1, a2, six] = self.decoder_forward(z)?;
        let rotations = std::iter::once(Matrix3::identity())
            .chain(
                six.as_slice()
                    .chunks_exact(6)
                    .map(|x| sixd_to_matrix(&Vector6::from_column_slice(x))),
            )
            .collect();
        Ok(Decoded {
            rotations,
            tape: [a1, a2, six],
        })
    }

    /// The decoder's pre-activations `[a1, a2]` and its 6-D output, f64.
    fn decoder_forward(&self, z: &[f64]) -> Result<[DVector<f64>; 3], PriorError> {
        if z.len() != LATENT || z.iter().any(|x| !x.is_finite()) {
            return Err(candle_core::Error::Msg(format!(
                "the latent must hold {LATENT} finite values, got {}",
                z.len()
            ))
            .into());
        }
        let [(w1, b1), (w2, b2), (w3, b3)] = &self.decoder;
        let a1 = w1 * DVector::from_column_slice(z) + b1;
        let a2 = w2 * silu(&a1) + b2;
        let six = w3 * silu(&a2) + b3;
        Ok([a1, a2, six])
    }

    /// Decodes a batch of latents (one candle call) to 36 rotations each (root = identity): the
    /// optimiser's parallel initialisations.
    pub fn decode_batch(&self, zs: &[Vec<f64>]) -> Result<Vec<Vec<Matrix3<f64>>>, PriorError> {
        if zs
            .iter()
            .any(|z| z.len() != LATENT || z.iter().any(|x| !x.is_finite()))
        {
            return Err(candle_core::Error::Msg(format!(
                "every latent must hold {LATENT} finite values"
            ))
            .into());
        }
        let flat: Vec<f64> = zs.iter().flatten().copied().collect();
        let t = Tensor::from_vec(flat, (zs.len(), LATENT), self.vae.device())?
            .to_dtype(self.vae.dtype())?;
        let r = self
            .vae
            .decode(&t)?
            .to_dtype(DType::F64)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        Ok(r.chunks_exact(9 * JOINTS)
            .map(|one| {
                std::iter::once(Matrix3::identity())
                    .chain(one.chunks_exact(9).map(Matrix3::from_row_slice))
                    .collect()
            })
            .collect())
    }

    /// Decodes one latent to 36 rotation vectors (root zero).
    pub fn decode_axis_angles(&self, z: &[f64]) -> Result<Vec<[f64; 3]>, PriorError> {
        Ok(self
            .decode(z)?
            .iter()
            .map(|m| matrix_to_axis_angle(m).into())
            .collect())
    }

    /// `∂L/∂z` from `∂L/∂R` of the 36 (or 35 body) rotations of [`Self::decode`].
    pub fn decode_vjp(
        &self,
        z: &[f64],
        d_rotations: &[Matrix3<f64>],
    ) -> Result<Vec<f64>, PriorError> {
        self.vjp_taped(&self.decode_taped(z)?, d_rotations)
    }

    /// [`Self::decode_vjp`] at the latent `decoded` came from.
    pub fn vjp_taped(
        &self,
        decoded: &Decoded,
        d_rotations: &[Matrix3<f64>],
    ) -> Result<Vec<f64>, PriorError> {
        let body = match d_rotations.len() {
            36 => &d_rotations[1..],
            35 => d_rotations,
            n => {
                return Err(candle_core::Error::Msg(format!(
                    "{n} rotation gradients, expected 35 or 36"
                ))
                .into());
            }
        };
        let [a1, a2, six] = &decoded.tape;
        let [(w1, _), (w2, _), (w3, _)] = &self.decoder;
        // Back through Gram–Schmidt, then the layers; silu'(x) = s (1 + x (1 − s)).
        let mut g_six = DVector::zeros(six.len());
        for (j, g) in body.iter().enumerate() {
            let x = Vector6::from_column_slice(&six.as_slice()[6 * j..6 * j + 6]);
            g_six
                .rows_mut(6 * j, 6)
                .copy_from(&sixd_to_matrix_vjp(&x, g));
        }
        let dsilu = |a: &DVector<f64>, g: DVector<f64>| {
            g.zip_map(a, |g, x| {
                let s = 1.0 / (1.0 + (-x).exp());
                g * s * (1.0 + x * (1.0 - s))
            })
        };
        let g_a2 = dsilu(a2, w3.tr_mul(&g_six));
        let g_a1 = dsilu(a1, w2.tr_mul(&g_a2));
        Ok(w1.tr_mul(&g_a1).as_slice().to_vec())
    }

    /// The encoder mean for a pose given as 36 rotation vectors (root ignored).
    pub fn encode(&self, rotvecs: &[[f64; 3]]) -> Result<Vec<f64>, PriorError> {
        let x = features(std::slice::from_ref(&rotvecs.to_vec()));
        let t =
            Tensor::from_vec(x, (1, 6 * JOINTS), self.vae.device())?.to_dtype(self.vae.dtype())?;
        let (mu, _) = self.vae.encode(&t)?;
        Ok(mu.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?)
    }
}

/// One latent's decoding and the decoder's intermediates ([`PosePrior::decode_taped`]).
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The 36 rotations (root = identity).
    pub rotations: Vec<Matrix3<f64>>,
    /// The pre-activations `a1`, `a2` and the 6-D output.
    tape: [DVector<f64>; 3],
}

fn silu(a: &DVector<f64>) -> DVector<f64> {
    a.map(|x| x / (1.0 + (-x).exp()))
}

/// The prior loss `‖z‖²` and its gradient `2z`.
pub fn latent_prior(z: &[f64]) -> (f64, Vec<f64>) {
    (
        z.iter().map(|x| x * x).sum(),
        z.iter().map(|x| 2.0 * x).collect(),
    )
}

/// 6-D features (joints 1…35, row-major) of poses given as rotation vectors.
pub fn features(poses: &[Vec<[f64; 3]>]) -> Vec<f64> {
    poses
        .iter()
        .flat_map(|p| {
            p[1..].iter().flat_map(|w| {
                matrix_to_sixd(&axis_angle_to_matrix(&Vector3::from(*w)))
                    .iter()
                    .copied()
                    .collect::<Vec<_>>()
            })
        })
        .collect()
}

/// Geodesic angle between two rotations, radians.
pub fn rotation_angle(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    (((a.transpose() * b).trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
}
