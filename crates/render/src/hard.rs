//! Hard (binary) reflection rendering: does each reflected half-line hit the mesh? Exact
//! Möller–Trumbore through the same BVH as the soft renderer (radius 0 queries).

use crate::bvh::{Bvh, inverse_dir};
use crate::distance::ray_triangle;
use crate::reflect::ReflectedRays;
use irmirror_geom::Real;
use nalgebra::Vector3;
use rayon::prelude::*;

/// The nearest hit of a half-line: `(t, triangle)`.
pub fn first_hit<T: Real>(
    bvh: &Bvh<T>,
    vertices: &[Vector3<T>],
    triangles: &[[u32; 3]],
    o: &Vector3<T>,
    r: &Vector3<T>,
) -> Option<(T, u32)> {
    let mut best: Option<(T, u32)> = None;
    bvh.for_each_near_ray(o, &inverse_dir(r), T::zero(), |t| {
        let tri = triangles[t as usize].map(|v| vertices[v as usize]);
        if let Some(s) = ray_triangle(o, r, &tri)
            && best.is_none_or(|(b, _)| s < b)
        {
            best = Some((s, t));
        }
    });
    best
}

/// A `width × height` mask (row-major): true where the pixel's reflected ray hits the mesh.
pub fn hard_mask<T: Real>(
    rays: &ReflectedRays<T>,
    bvh: &Bvh<T>,
    vertices: &[Vector3<T>],
    triangles: &[[u32; 3]],
) -> Vec<bool> {
    let hits: Vec<bool> = (0..rays.len())
        .into_par_iter()
        .map(|i| first_hit(bvh, vertices, triangles, &rays.origin[i], &rays.dir[i]).is_some())
        .collect();
    let mut mask = vec![false; (rays.width * rays.height) as usize];
    for (i, h) in hits.into_iter().enumerate() {
        mask[rays.pixel[i] as usize] = h;
    }
    mask
}
