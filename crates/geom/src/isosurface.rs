//! Triangle meshes of implicit surfaces `f(p) = 0` by marching tetrahedra on a regular grid
//! (six tetrahedra per cell: no case tables, no ambiguous cases). Triangles are oriented so
//! their normals point towards increasing `f` (outward for a signed distance).

use crate::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::collections::HashMap;

/// The six tetrahedra of a cube (corner indices, bit i of a corner = +1 along axis i), all
/// sharing the main diagonal 0–7.
const TETS: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 3, 2, 7],
    [0, 2, 6, 7],
    [0, 6, 4, 7],
    [0, 4, 5, 7],
    [0, 5, 1, 7],
];

/// Extracts the zero level set of `f` inside the box `[lo, hi]` with `n` cells per axis.
pub fn isosurface(
    f: impl Fn(&Vector3<f64>) -> f64 + Sync,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
    n: usize,
) -> TriMesh {
    let n = n.max(2);
    let step = (hi - lo) / n as f64;
    let np = n + 1;
    let point = |i: usize, j: usize, k: usize| {
        lo + Vector3::new(i as f64 * step.x, j as f64 * step.y, k as f64 * step.z)
    };
    let values: Vec<f64> = (0..np * np * np)
        .into_par_iter()
        .map(|g| f(&point(g % np, (g / np) % np, g / (np * np))))
        .collect();
    isosurface_grid(&values, lo, hi, n)
}

/// The grid points at which [`isosurface_grid`] expects values, x fastest, then y, then z.
pub fn grid_points(lo: Vector3<f64>, hi: Vector3<f64>, n: usize) -> Vec<Vector3<f64>> {
    let n = n.max(2);
    let np = n + 1;
    let step = (hi - lo) / n as f64;
    (0..np * np * np)
        .map(|g| {
            lo + Vector3::new(
                (g % np) as f64 * step.x,
                ((g / np) % np) as f64 * step.y,
                (g / (np * np)) as f64 * step.z,
            )
        })
        .collect()
}

/// Like [`isosurface`], from field values already computed at [`grid_points`] (e.g. by a batched
/// network evaluation).
pub fn isosurface_grid(values: &[f64], lo: Vector3<f64>, hi: Vector3<f64>, n: usize) -> TriMesh {
    let n = n.max(2);
    let step = (hi - lo) / n as f64;
    let np = n + 1;
    assert_eq!(values.len(), np * np * np, "one value per grid point");
    let idx = |i: usize, j: usize, k: usize| (k * np + j) * np + i;
    let point = |i: usize, j: usize, k: usize| {
        lo + Vector3::new(i as f64 * step.x, j as f64 * step.y, k as f64 * step.z)
    };
    let mut mesh = TriMesh::default();
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let corner = |c: usize| (i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                for tet in TETS {
                    let g: [usize; 4] = tet.map(|c| {
                        let (a, b, cc) = corner(c);
                        idx(a, b, cc)
                    });
                    let p: [Vector3<f64>; 4] = tet.map(|c| {
                        let (a, b, cc) = corner(c);
                        point(a, b, cc)
                    });
                    let inside: Vec<usize> = (0..4).filter(|&q| values[g[q]] < 0.0).collect();
                    let outside: Vec<usize> = (0..4).filter(|&q| values[g[q]] >= 0.0).collect();
                    if inside.is_empty() || outside.is_empty() {
                        continue;
                    }
                    // Gradient of the linear interpolant over the tetrahedron, to orient faces.
                    let m = nalgebra::Matrix3::from_rows(&[
                        (p[1] - p[0]).transpose(),
                        (p[2] - p[0]).transpose(),
                        (p[3] - p[0]).transpose(),
                    ]);
                    let dv = Vector3::new(
                        values[g[1]] - values[g[0]],
                        values[g[2]] - values[g[0]],
                        values[g[3]] - values[g[0]],
                    );
                    let grad = m
                        .try_inverse()
                        .map(|mi| mi * dv)
                        .unwrap_or_else(Vector3::zeros);
                    let emit = |mesh: &mut TriMesh, tri: [u32; 3]| {
                        let v =
                            tri.map(|t| Vector3::from(mesh.vertices[t as usize].map(f64::from)));
                        let nrm = (v[1] - v[0]).cross(&(v[2] - v[0]));
                        if nrm.norm_squared() == 0.0 {
                            return;
                        }
                        mesh.triangles.push(if nrm.dot(&grad) >= 0.0 {
                            tri
                        } else {
                            [tri[0], tri[2], tri[1]]
                        });
                    };
                    // The vertex on tetrahedron edge (a, b), shared with every cell that has it.
                    let mut ev = |a: usize, b: usize, mesh: &mut TriMesh| -> u32 {
                        *edge_vertex
                            .entry((g[a].min(g[b]), g[a].max(g[b])))
                            .or_insert_with(|| {
                                let (va, vb) = (values[g[a]], values[g[b]]);
                                let t = if va == vb { 0.5 } else { va / (va - vb) };
                                let q = p[a] + (p[b] - p[a]) * t;
                                mesh.vertices.push([q.x as f32, q.y as f32, q.z as f32]);
                                (mesh.vertices.len() - 1) as u32
                            })
                    };
                    match inside.len() {
                        1 | 3 => {
                            let (lone, others) = if inside.len() == 1 {
                                (inside[0], outside.clone())
                            } else {
                                (outside[0], inside.clone())
                            };
                            let t = [0, 1, 2].map(|q| ev(lone, others[q], &mut mesh));
                            emit(&mut mesh, t);
                        }
                        _ => {
                            let (a, b, c, d) = (inside[0], inside[1], outside[0], outside[1]);
                            let v0 = ev(a, c, &mut mesh);
                            let v1 = ev(a, d, &mut mesh);
                            let v2 = ev(b, d, &mut mesh);
                            let v3 = ev(b, c, &mut mesh);
                            emit(&mut mesh, [v0, v1, v2]);
                            emit(&mut mesh, [v0, v2, v3]);
                        }
                    }
                }
            }
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_mesh_is_closed_outward_and_on_the_surface() {
        let r = 0.7;
        let m = isosurface(
            |p| p.norm() - r,
            Vector3::repeat(-1.0),
            Vector3::repeat(1.0),
            24,
        );
        let vol = m.signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        assert!((vol / exact - 1.0).abs() < 0.03, "volume {vol} vs {exact}");
        for v in &m.vertices {
            let d = (v.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>()).sqrt() - r;
            assert!(d.abs() < 0.01, "{d}");
        }
        // Closed: every edge is shared by exactly two triangles.
        let mut edges = HashMap::new();
        for t in &m.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&c| c == 2));
    }
}
