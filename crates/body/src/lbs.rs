//! Linear blend skinning and its VJP, parallel over vertices, allocation-free.
//!
//! `v'_i = Σ_k w_ik (A_{j_ik} v_i + b_{j_ik})`.

use irmirror_geom::Real;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Vertices per parallel work item.
pub const CHUNK: usize = 1024;

/// Per-chunk gradient accumulators, preallocated once per body so a backward pass allocates
/// nothing.
#[derive(Clone, Debug)]
pub struct LbsScratch<T: Real> {
    chunks: Vec<Vec<(Matrix3<T>, Vector3<T>)>>,
}

impl<T: Real> LbsScratch<T> {
    /// Scratch for `n_vertices` vertices and `n_joints` joints.
    pub fn new(n_vertices: usize, n_joints: usize) -> Self {
        let n = n_vertices.div_ceil(CHUNK);
        Self {
            chunks: vec![vec![(Matrix3::zeros(), Vector3::zeros()); n_joints]; n],
        }
    }
}

/// The skinned mesh: what [`forward`] and [`forward_vjp`] share.
#[derive(Clone, Copy, Debug)]
pub struct Skin<'a, T: Real> {
    /// Rest vertices, body frame, metres.
    pub rest: &'a [Vector3<T>],
    /// Joint of each influence, `influences` per vertex.
    pub indices: &'a [u8],
    /// Weight of each influence (0: unused slot).
    pub weights: &'a [f64],
    /// Influences per vertex.
    pub influences: usize,
}

/// Gradients [`forward_vjp`] writes: `∂L/∂A`, `∂L/∂b` per joint and `∂L/∂rest` per vertex.
#[derive(Debug)]
pub struct LbsGrad<'a, T: Real> {
    /// `∂L/∂A_j`.
    pub a: &'a mut [Matrix3<T>],
    /// `∂L/∂b_j`.
    pub b: &'a mut [Vector3<T>],
    /// `∂L/∂v_i` of the rest vertices.
    pub rest: &'a mut [Vector3<T>],
}

/// Skins `skin.rest` into `out` with the joint transforms `(a, b)`.
pub fn forward<T: Real>(
    skin: &Skin<'_, T>,
    a: &[Matrix3<T>],
    b: &[Vector3<T>],
    out: &mut [Vector3<T>],
) {
    let Skin {
        rest,
        indices,
        weights,
        influences: k,
    } = *skin;
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(ci, chunk)| {
            let base = ci * CHUNK;
            for (o, v) in chunk.iter_mut().enumerate() {
                let i = base + o;
                let p = rest[i];
                let mut acc = Vector3::zeros();
                for s in 0..k {
                    let w = weights[i * k + s];
                    if w == 0.0 {
                        continue;
                    }
                    let j = indices[i * k + s] as usize;
                    acc += (a[j] * p + b[j]) * T::of(w);
                }
                *v = acc;
            }
        });
}

/// VJP of [`forward`]: from `d_out` writes `∂L/∂A`, `∂L/∂b` and `∂L/∂rest` into `grad`.
pub fn forward_vjp<T: Real>(
    skin: &Skin<'_, T>,
    a: &[Matrix3<T>],
    d_out: &[Vector3<T>],
    grad: LbsGrad<'_, T>,
    scratch: &mut LbsScratch<T>,
) {
    let Skin {
        rest,
        indices,
        weights,
        influences: k,
    } = *skin;
    let LbsGrad {
        a: d_a,
        b: d_b,
        rest: d_rest,
    } = grad;
    d_rest
        .par_chunks_mut(CHUNK)
        .zip(scratch.chunks.par_iter_mut())
        .enumerate()
        .for_each(|(ci, (d_rest_chunk, acc))| {
            acc.iter_mut()
                .for_each(|e| *e = (Matrix3::zeros(), Vector3::zeros()));
            let base = ci * CHUNK;
            for (o, dr) in d_rest_chunk.iter_mut().enumerate() {
                let i = base + o;
                let (p, g) = (rest[i], d_out[i]);
                let mut d = Vector3::zeros();
                for s in 0..k {
                    let w = weights[i * k + s];
                    if w == 0.0 {
                        continue;
                    }
                    let j = indices[i * k + s] as usize;
                    let wg = g * T::of(w);
                    acc[j].0 += wg * p.transpose();
                    acc[j].1 += wg;
                    d += a[j].tr_mul(&wg);
                }
                *dr = d;
            }
        });
    d_a.iter_mut().for_each(|m| *m = Matrix3::zeros());
    d_b.iter_mut().for_each(|v| *v = Vector3::zeros());
    for acc in &scratch.chunks {
        for (j, (m, v)) in acc.iter().enumerate() {
            d_a[j] += m;
            d_b[j] += v;
        }
    }
}
