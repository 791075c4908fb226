//! SMPL-like forward kinematics (ANNY_SPEC.md §8.2) and its VJP.
//!
//! `G_0 = D_0`, `t_0 = τ`; for each child c of p: `G_c = G_p D_c`,
//! `t_c = t_p + G_p (h_c − h_p)`. Skinning transforms: `A_c = G_c`, `b_c = t_c − G_c h_c`.
//! `D_c` are rotations in world-aligned rest axes; `t_c` is the posed joint position.

use irmirror_geom::Real;
use nalgebra::{Matrix3, Vector3};

/// Forward kinematics: writes world rotations `g` and joint positions `t` (both length J).
pub fn forward<T: Real>(
    parents: &[i32],
    heads: &[Vector3<T>],
    rotations: &[Matrix3<T>],
    translation: &Vector3<T>,
    g: &mut [Matrix3<T>],
    t: &mut [Vector3<T>],
) {
    g[0] = rotations[0];
    t[0] = *translation;
    for c in 1..parents.len() {
        let p = parents[c] as usize;
        g[c] = g[p] * rotations[c];
        t[c] = t[p] + g[p] * (heads[c] - heads[p]);
    }
}

/// Skinning transforms `(A_c, b_c)` from the FK result; `A_c = G_c`, so only `b` is written.
pub fn skinning_offsets<T: Real>(
    heads: &[Vector3<T>],
    g: &[Matrix3<T>],
    t: &[Vector3<T>],
    b: &mut [Vector3<T>],
) {
    for c in 0..heads.len() {
        b[c] = t[c] - g[c] * heads[c];
    }
}

/// VJP of [`skinning_offsets`]: folds `d_b` into `d_g`, `d_t` and `d_heads` (all accumulated).
pub fn skinning_offsets_vjp<T: Real>(
    heads: &[Vector3<T>],
    g: &[Matrix3<T>],
    d_b: &[Vector3<T>],
    d_g: &mut [Matrix3<T>],
    d_t: &mut [Vector3<T>],
    d_heads: &mut [Vector3<T>],
) {
    for c in 0..heads.len() {
        d_t[c] += d_b[c];
        d_g[c] -= d_b[c] * heads[c].transpose();
        d_heads[c] -= g[c].tr_mul(&d_b[c]);
    }
}

/// A kinematic tree: parent of each joint (children after parents; −1 for the root) and the
/// joints' rest heads, body frame, metres.
#[derive(Clone, Copy, Debug)]
pub struct Skeleton<'a, T: Real> {
    /// Parent joint index, −1 for the root.
    pub parents: &'a [i32],
    /// Rest head of each joint, body frame, metres.
    pub heads: &'a [Vector3<T>],
}

/// The gradients [`forward_vjp`] reads and writes.
#[derive(Debug)]
pub struct FkGrad<'a, T: Real> {
    /// On entry `∂L/∂G` (world rotations); consumed.
    pub g: &'a mut [Matrix3<T>],
    /// On entry `∂L/∂t` (joint positions); consumed.
    pub t: &'a mut [Vector3<T>],
    /// Written: `∂L/∂D` (joint rotations).
    pub rotations: &'a mut [Matrix3<T>],
    /// Accumulated: `∂L/∂h` (rest heads).
    pub heads: &'a mut [Vector3<T>],
}

/// VJP of [`forward`] given its world rotations `g`: consumes `∂L/∂G`, `∂L/∂t` from `grad`,
/// writes `∂L/∂D`, accumulates `∂L/∂h`, and returns `∂L/∂τ`.
pub fn forward_vjp<T: Real>(
    skeleton: &Skeleton<'_, T>,
    rotations: &[Matrix3<T>],
    g: &[Matrix3<T>],
    grad: FkGrad<'_, T>,
) -> Vector3<T> {
    let Skeleton { parents, heads } = *skeleton;
    let FkGrad {
        g: d_g,
        t: d_t,
        rotations: d_rot,
        heads: d_heads,
    } = grad;
    // Children come after parents, so a reverse sweep sees every child before its parent.
    for c in (1..parents.len()).rev() {
        let p = parents[c] as usize;
        let dtc = d_t[c];
        let gp_t_dtc = g[p].tr_mul(&dtc);
        d_t[p] += dtc;
        d_g[p] += dtc * (heads[c] - heads[p]).transpose();
        d_heads[c] += gp_t_dtc;
        d_heads[p] -= gp_t_dtc;
        let dgc = d_g[c];
        d_g[p] += dgc * rotations[c].transpose();
        d_rot[c] = g[p].tr_mul(&dgc);
    }
    d_rot[0] = d_g[0];
    d_t[0]
}
