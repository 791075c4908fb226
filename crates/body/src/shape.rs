//! The linear shape space: `state = mean + Σ_i z_i E_i` over vertices, joint heads and tails,
//! and its VJP w.r.t. the shape coefficients `z`.

use crate::BodyAsset;
use irmirror_geom::Real;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Rest vertices and joints of one body shape (Anny world frame, metres).
#[derive(Clone, Debug)]
pub struct ShapedBody<T: Real> {
    /// Shape coefficients z (length r).
    pub z: Vec<T>,
    /// Rest vertices, V.
    pub vertices: Vec<Vector3<T>>,
    /// Rest joint positions (bone heads), J.
    pub joint_heads: Vec<Vector3<T>>,
    /// Rest bone tails, J (they orient the Blender bone frames only).
    pub joint_tails: Vec<Vector3<T>>,
}

fn v3<T: Real>(p: &[f32; 3]) -> Vector3<T> {
    Vector3::new(
        T::of(f64::from(p[0])),
        T::of(f64::from(p[1])),
        T::of(f64::from(p[2])),
    )
}

/// `mean + Σ_r z_r E_r` per row (`mean` = `None`: the sum alone).
fn apply<T: Real>(mean: Option<&[[f32; 3]]>, basis: &[f32], z: &[T], out: &mut [Vector3<T>]) {
    let n = out.len();
    out.par_iter_mut().enumerate().for_each(|(i, o)| {
        let mut p = mean.map_or_else(Vector3::zeros, |m| v3::<T>(&m[i]));
        for (r, &zr) in z.iter().enumerate() {
            let e = &basis[(r * n + i) * 3..(r * n + i) * 3 + 3];
            p += Vector3::new(
                T::of(f64::from(e[0])),
                T::of(f64::from(e[1])),
                T::of(f64::from(e[2])),
            ) * zr;
        }
        *o = p;
    });
}

/// Fills `out` with the shape of coefficients `z` (length r, checked by the caller).
pub fn shape_into<T: Real>(asset: &BodyAsset, z: &[T], out: &mut ShapedBody<T>) {
    fill(asset, z, true, out);
}

/// Fills `out` with the rest body's derivative along `dz` (length r): `Σ_i dz_i E_i` over
/// vertices, joint heads and tails, without the mean (`out.z` = `dz`). The shape space is
/// linear, so a body whose coefficients move along `dz` moves along this exactly: a fit that
/// changes one phenotype slider, piecewise linear in `z`, reshapes by an axpy instead of the
/// whole basis, and reads that slider's gradient with [`crate::PosedBody::rest_grad_along`].
pub fn direction_into<T: Real>(asset: &BodyAsset, dz: &[T], out: &mut ShapedBody<T>) {
    fill(asset, dz, false, out);
}

fn fill<T: Real>(asset: &BodyAsset, z: &[T], with_mean: bool, out: &mut ShapedBody<T>) {
    out.z.clear();
    out.z.extend_from_slice(z);
    out.vertices.resize(asset.n_vertices(), Vector3::zeros());
    out.joint_heads.resize(asset.n_joints(), Vector3::zeros());
    out.joint_tails.resize(asset.n_joints(), Vector3::zeros());
    apply(
        with_mean.then_some(&asset.mean_vertices[..]),
        &asset.shape_basis_vertices,
        z,
        &mut out.vertices,
    );
    apply(
        with_mean.then_some(&asset.mean_joint_heads[..]),
        &asset.shape_basis_joint_heads,
        z,
        &mut out.joint_heads,
    );
    apply(
        with_mean.then_some(&asset.mean_joint_tails[..]),
        &asset.shape_basis_joint_tails,
        z,
        &mut out.joint_tails,
    );
}

/// VJP: `∂L/∂z_i = Σ_v ∂L/∂v · E_v[i] + Σ_c ∂L/∂h_c · E_h[i]` (tails do not affect posing).
pub fn shape_vjp<T: Real>(
    asset: &BodyAsset,
    d_vertices: &[Vector3<T>],
    d_heads: &[Vector3<T>],
    d_z: &mut [T],
) {
    let (v, j) = (asset.n_vertices(), asset.n_joints());
    d_z.par_iter_mut().enumerate().for_each(|(r, dz)| {
        let dot = |basis: &[f32], n: usize, d: &[Vector3<T>]| {
            let mut s = T::zero();
            for i in 0..n {
                let e = &basis[(r * n + i) * 3..(r * n + i) * 3 + 3];
                s += d[i].x * T::of(f64::from(e[0]))
                    + d[i].y * T::of(f64::from(e[1]))
                    + d[i].z * T::of(f64::from(e[2]));
            }
            s
        };
        *dz = dot(&asset.shape_basis_vertices, v, d_vertices)
            + dot(&asset.shape_basis_joint_heads, j, d_heads);
    });
}
