//! Keypoints as sparse convex combinations of posed vertices, and the VJP.

use irmirror_geom::Real;
use nalgebra::Vector3;

/// `kp_k = Σ w · v` over the regressor entries of keypoint k.
pub fn regress<T: Real>(
    kp: &[u8],
    vertex: &[u32],
    weight: &[f64],
    vertices: &[Vector3<T>],
    out: &mut [Vector3<T>],
) {
    out.iter_mut().for_each(|o| *o = Vector3::zeros());
    for ((&k, &v), &w) in kp.iter().zip(vertex).zip(weight) {
        out[k as usize] += vertices[v as usize] * T::of(w);
    }
}

/// VJP of [`regress`]: accumulates `∂L/∂vertices` from `d_kp`.
pub fn regress_vjp<T: Real>(
    kp: &[u8],
    vertex: &[u32],
    weight: &[f64],
    d_kp: &[Vector3<T>],
    d_vertices: &mut [Vector3<T>],
) {
    for ((&k, &v), &w) in kp.iter().zip(vertex).zip(weight) {
        d_vertices[v as usize] += d_kp[k as usize] * T::of(w);
    }
}
