//! Soft occupancy of reflected half-lines by a triangle mesh, the soft-IoU loss, and the
//! hand-written backward (paper §3.4; `assets/bench/scene_sphere160.json`, `occupancy` block).
//!
//! `x_ij = λ_ij d_ij² / σ`, `D_ij = sigmoid(x_ij)`, `I_i = 1 − Π_j (1 − D_ij)`, with λ = +1 when
//! the half-line pierces triangle j (then d is the distance to the triangle's boundary) and −1
//! otherwise. The product is a sum of logs, `log(1 − D) = −softplus(x)`, so nothing underflows,
//! and the backward uses `∂I/∂x = (1 − I) D` with `1 − I = exp(Σ log(1 − D))`, never a 0·∞.
//!
//! | parameter | unit | frame | differentiable |
//! |---|---|---|---|
//! | mesh vertices | m | depth | yes (`d_vertices`) |
//! | ray origins | m | depth | yes (`d_origin`) |
//! | ray directions (unit) | — | depth | yes (`d_dir`, as free vectors) |
//! | σ | m² | — | no |
//!
//! **Culling** ([`Culling::Bvh`]): a triangle that the half-line does not pierce has influence
//! `D ≤ ε·max` once `d² > ln(1/ε − 1) σ`; the BVH (refitted, not rebuilt, per iteration) is
//! queried with the half-line inflated by that radius, and such far triangles are skipped.
//! Pierced triangles are always inside the query. [`Culling::Dense`] visits every ray × every
//! triangle (the paper's SoftRas extension), for tests and the benchmark ratio.
//!
//! **Aggregation.** [`Aggregation::Product`] is the above (SoftRas). It sums the influence of
//! every nearby triangle, so its soft silhouette crosses 0.5 outside the true one (≈ 1.5 √σ on a
//! body mesh) and inside it dips wherever a ray passes near a mesh edge. [`Aggregation::Silhouette`]
//! uses one distance per ray, to the mesh's silhouette as seen along that ray:
//! `I = sigmoid(±d²/σ)`, + when the half-line hits the mesh. A miss's `d` is its distance to the
//! nearest triangle (that point lies on the silhouette); a hit's is its distance to the nearest
//! *exposed* contour edge — an edge between a face turned towards the ray and one turned away (or
//! a boundary edge) such that the ray moved just past it misses the mesh (a contour behind
//! another part of the body is not the silhouette). `I` is 0.5 exactly on the silhouette and
//! saturates inside; its gradient reaches the one triangle or edge that sets `d`. A miss's
//! nearest triangle is found by a BVH search whose radius shrinks to the best distance so far;
//! a hit tests at most `MAX_EXPOSURE_TESTS` contour edges, nearest first, and counts as
//! saturated beyond them (deep inside, every nearby contour is hidden). A hit's search for
//! contour edges skips every BVH subtree whose faces and their edge neighbours all face one
//! way along the ray (a box per node bounds their unit normals, refitted with the BVH): on a
//! body most of what a ray passes near is such a patch (on the demo capture 338 → 92
//! triangles visited per hitting ray, identical output).
//!
//! **Autodiff.** These gradients are hand-written; an autodiff graph (the pose prior's decoder)
//! takes them through the surrogate `L̃ = Σ V ⊙ stop_grad(∂L/∂V)`, whose gradient w.r.t. the
//! graph's inputs equals the chain rule through the renderer.

use crate::bvh::{Bvh, inverse_dir};
use crate::distance::{PairDistance, ray_triangle, ray_triangle_distance, segment_ray};
use crate::reflect::ReflectedRays;
use irmirror_geom::Real;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Rays per parallel work item.
const RAY_CHUNK: usize = 32;

/// Soft-occupancy settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OccupancyParams {
    /// Blur σ, m² (at the body).
    pub sigma_m2: f64,
    /// Influence `D` below which non-pierced triangles are culled.
    pub epsilon: f64,
    /// How the triangles' influences combine.
    #[serde(default)]
    pub aggregation: Aggregation,
}

/// How a ray's occupancy is formed from the mesh (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Aggregation {
    /// SoftRas: `I = 1 − Π_j (1 − D_ij)` over all triangles.
    #[default]
    Product,
    /// `I = sigmoid(±d²/σ)`, `d` the distance to the silhouette seen along the ray.
    Silhouette,
}

impl Default for OccupancyParams {
    /// σ = 1 cm², ε = 1e-7. The benchmark scene states ε = 1e-4, which bounds each culled
    /// pair's occupancy but not its gradient: `∂D/∂d = D (1 − D) 2d/σ` decays more slowly, and
    /// at 1e-4 the vertex gradient differs from the dense one by 1.4 % of its maximum. At 1e-7
    /// (cull radius 4.0 σ^½ instead of 3.0 σ^½) it differs by 2e-5, for 1.5× the time
    /// (`irmirror bench render`).
    fn default() -> Self {
        Self {
            sigma_m2: 1e-4,
            epsilon: 1e-7,
            aggregation: Aggregation::Product,
        }
    }
}

impl OccupancyParams {
    /// `d²` beyond which a non-pierced triangle is culled: `ln(1/ε − 1) σ`.
    pub fn cull_d2(&self) -> f64 {
        (1.0 / self.epsilon - 1.0).ln() * self.sigma_m2
    }
}

/// Which ray–triangle pairs are visited.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Culling {
    /// Every ray × every triangle.
    Dense,
    /// BVH query with the inflated half-line.
    Bvh,
}

/// Numerically stable `softplus(x) = ln(1 + eˣ)`.
#[inline]
fn softplus<T: Real>(x: T) -> T {
    if x > T::zero() {
        x + (-x).exp().ln_1p()
    } else {
        x.exp().ln_1p()
    }
}

#[inline]
fn sigmoid<T: Real>(x: T) -> T {
    if x >= T::zero() {
        T::one() / (T::one() + (-x).exp())
    } else {
        let e = x.exp();
        e / (T::one() + e)
    }
}

/// The mesh seen by the reflected rays: triangles, a BVH over them, and backward scratch.
/// Build once per mesh topology; call [`SoftRenderer::set_vertices`] each iteration.
pub struct SoftRenderer<T: Real> {
    triangles: Vec<[u32; 3]>,
    vertices: Vec<Vector3<T>>,
    bvh: Bvh<T>,
    /// Per triangle: centroid and bounding radius about it, for a cheap rejection before the
    /// exact distance.
    spheres: Vec<(Vector3<T>, T)>,
    /// Per ray-chunk sparse vertex-gradient contributions, reused across calls.
    contributions: Vec<Vec<(u32, Vector3<T>)>>,
    /// Unit face normals (0 for a degenerate face); only their signs against a ray matter
    /// (contour edges).
    normals: Vec<Vector3<T>>,
    /// Mesh edges: vertices and the (up to two) faces that share them.
    edges: Vec<Edge>,
    /// Per triangle: its three edges (`edges` indices), edge k from vertex k to k + 1.
    tri_edges: Vec<[u32; 3]>,
    /// Per triangle: the box bounding its normal and those of its neighbours across the edges
    /// it owns (below).
    tri_normal_boxes: Vec<(Vector3<T>, Vector3<T>)>,
    /// Per BVH node: a box bounding the unit normals of its triangles and of their neighbours
    /// across the edges they own (the whole cube under a boundary edge). A hitting ray whose
    /// direction has one sign against the whole box has no contour edge in that subtree.
    normal_boxes: Vec<(Vector3<T>, Vector3<T>)>,
}

/// Exposure tests per hitting ray, nearest contour edges first (module docs).
const MAX_EXPOSURE_TESTS: usize = 16;

/// No face (a boundary edge's second side).
const NO_FACE: u32 = u32::MAX;

#[derive(Clone, Copy, Debug)]
struct Edge {
    v: [u32; 2],
    /// The first face that has the edge, and the second (`NO_FACE` on a boundary). A third
    /// face of a non-manifold edge is ignored.
    f: [u32; 2],
}

/// The mesh element that sets a ray's distance under [`Aggregation::Silhouette`].
#[derive(Clone, Copy, Debug)]
pub struct Nearest<T: Real> {
    /// Its vertices (an edge repeats its second vertex with weight 0).
    pub vertices: [u32; 3],
    /// The closest pair; `pierced` is true when the ray hits the mesh (the sign of `x`).
    pub pair: PairDistance<T>,
}

/// Per-ray result of the forward pass.
#[derive(Clone, Debug, Default)]
pub struct Occupancy<T: Real> {
    /// `I_i` per ray.
    pub value: Vec<T>,
    /// `log(1 − I_i) = Σ_j log(1 − D_ij)` per ray (exact where `I` rounds to 1).
    pub log_complement: Vec<T>,
    /// Ray–triangle pairs evaluated per ray (0: the backward skips the ray).
    pub pairs_per_ray: Vec<u32>,
    /// Ray–triangle pairs evaluated in all (for statistics).
    pub pairs: u64,
    /// [`Aggregation::Silhouette`]: per ray, what sets its distance (`None`: nothing within the
    /// cull radius, so `I` is saturated and has no gradient). Empty for `Product`.
    pub nearest: Vec<Option<Nearest<T>>>,
}

/// Gradients of a loss w.r.t. the mesh and the rays.
#[derive(Clone, Debug, Default)]
pub struct OccupancyGrad<T: Real> {
    /// `∂L/∂vertex`, depth frame.
    pub vertices: Vec<Vector3<T>>,
    /// `∂L/∂origin` per ray.
    pub origin: Vec<Vector3<T>>,
    /// `∂L/∂direction` per ray.
    pub dir: Vec<Vector3<T>>,
}

impl<T: Real> SoftRenderer<T> {
    /// A renderer for this topology at these vertex positions (depth frame, metres).
    pub fn new(vertices: &[Vector3<T>], triangles: &[[u32; 3]]) -> Self {
        let mut r = Self {
            triangles: triangles.to_vec(),
            vertices: vertices.to_vec(),
            bvh: Bvh::build(vertices, triangles),
            spheres: vec![(Vector3::zeros(), T::zero()); triangles.len()],
            contributions: Vec::new(),
            normals: vec![Vector3::zeros(); triangles.len()],
            edges: Vec::new(),
            tri_edges: Vec::with_capacity(triangles.len()),
            tri_normal_boxes: vec![(Vector3::zeros(), Vector3::zeros()); triangles.len()],
            normal_boxes: Vec::new(),
        };
        let mut index = std::collections::HashMap::with_capacity(triangles.len() * 3 / 2);
        for (f, tri) in triangles.iter().enumerate() {
            let mut ids = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let id = *index.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    r.edges.push(Edge {
                        v: [a, b],
                        f: [f as u32, NO_FACE],
                    });
                    (r.edges.len() - 1) as u32
                });
                let e = &mut r.edges[id as usize];
                if e.f[0] != f as u32 && e.f[1] == NO_FACE {
                    e.f[1] = f as u32;
                }
                ids[k] = id;
            }
            r.tri_edges.push(ids);
        }
        r.update_spheres();
        r
    }

    /// Moves the vertices (same topology) and refits the BVH.
    pub fn set_vertices(&mut self, vertices: &[Vector3<T>]) {
        self.vertices.copy_from_slice(vertices);
        self.bvh.refit(&self.vertices, &self.triangles);
        self.update_spheres();
    }

    fn update_spheres(&mut self) {
        let (v, t) = (&self.vertices, &self.triangles);
        self.spheres
            .par_iter_mut()
            .zip(self.normals.par_iter_mut())
            .zip(t.par_iter())
            .for_each(|((s, n), tri)| {
                let [a, b, c] = tri.map(|i| v[i as usize]);
                let m = (a + b + c) / T::of(3.0);
                let r2 = (a - m)
                    .norm_squared()
                    .max((b - m).norm_squared())
                    .max((c - m).norm_squared());
                *s = (m, r2.sqrt());
                // Unit length so that the normal boxes below are tight; a degenerate face keeps
                // 0, which makes every box holding it unprunable (n·r = 0 counts as contour).
                let n_raw = (b - a).cross(&(c - a));
                let len = n_raw.norm();
                *n = if len > T::zero() { n_raw / len } else { n_raw };
            });
        let (normals, edges, tri_edges) = (&self.normals, &self.edges, &self.tri_edges);
        self.tri_normal_boxes
            .par_iter_mut()
            .enumerate()
            .for_each(|(t, bx)| {
                let n = normals[t];
                let (mut lo, mut hi) = (n, n);
                for &e in &tri_edges[t] {
                    let edge = edges[e as usize];
                    if edge.f[0] != t as u32 {
                        continue;
                    }
                    if edge.f[1] == NO_FACE {
                        (lo, hi) = (Vector3::repeat(-T::one()), Vector3::repeat(T::one()));
                        break;
                    }
                    let m = normals[edge.f[1] as usize];
                    lo = lo.inf(&m);
                    hi = hi.sup(&m);
                }
                *bx = (lo, hi);
            });
        let tri_boxes = &self.tri_normal_boxes;
        self.bvh
            .refit_node_boxes(&mut self.normal_boxes, |t| tri_boxes[t as usize]);
    }

    /// Whether no contour edge (as [`Self::silhouette_ray`] classifies them along `r`) is owned
    /// by a triangle below BVH node `node`: every normal in its box has one strict sign against
    /// `r` (the box bounds the very normals the classification uses; a margin of a few ulps
    /// covers a different summation order in its dot products).
    #[inline]
    fn contour_free(&self, node: usize, r: &Vector3<T>) -> bool {
        let (lo, hi) = &self.normal_boxes[node];
        let (mut min, mut max) = (T::zero(), T::zero());
        for k in 0..3 {
            let (a, b) = (lo[k] * r[k], hi[k] * r[k]);
            min += a.min(b);
            max += a.max(b);
        }
        let margin = T::eps() * T::of(8.0);
        min > margin || max < -margin
    }

    /// The vertices, depth frame.
    pub fn vertices(&self) -> &[Vector3<T>] {
        &self.vertices
    }

    /// The triangles.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The BVH (shared with the hard renderer).
    pub fn bvh(&self) -> &Bvh<T> {
        &self.bvh
    }

    fn tri(&self, t: u32) -> [Vector3<T>; 3] {
        self.triangles[t as usize].map(|v| self.vertices[v as usize])
    }

    /// Visits the triangles that may lie within `radius` of the half-line (every one for
    /// [`Culling::Dense`]); pierced triangles are always visited. [`Culling::Bvh`] skips the
    /// subtrees `skip(node)` rejects.
    #[inline]
    fn for_each_near(
        &self,
        (o, r): (&Vector3<T>, &Vector3<T>),
        radius: T,
        culling: Culling,
        skip: impl Fn(usize) -> bool,
        mut visit: impl FnMut(u32),
    ) {
        match culling {
            Culling::Dense => (0..self.triangles.len() as u32).for_each(visit),
            Culling::Bvh => {
                self.bvh
                    .for_each_near_ray_pruned(o, &inverse_dir(r), radius, skip, |t| {
                        // A triangle whose bounding sphere is farther than the radius is neither
                        // pierced nor influential.
                        let (c, rho) = self.spheres[t as usize];
                        let s = (c - o).dot(r).max(T::zero());
                        let reach = radius + rho;
                        if (o + r * s - c).norm_squared() <= reach * reach {
                            visit(t);
                        }
                    })
            }
        }
    }

    /// Visits the pairs of one ray that contribute: `f(triangle, pair distance, x)`.
    #[inline]
    fn for_each_pair(
        &self,
        o: &Vector3<T>,
        r: &Vector3<T>,
        p: &OccupancyParams,
        culling: Culling,
        mut f: impl FnMut(u32, &[Vector3<T>; 3], &PairDistance<T>, T),
    ) {
        let inv_sigma = T::of(1.0 / p.sigma_m2);
        let cull = match culling {
            Culling::Dense => T::max_value().unwrap_or(T::one()),
            Culling::Bvh => T::of(p.cull_d2()),
        };
        self.for_each_near(
            (o, r),
            T::of(p.cull_d2()).sqrt(),
            culling,
            |_| false,
            |t| {
                let tri = self.tri(t);
                let pd = ray_triangle_distance(o, r, &tri);
                if pd.pierced || pd.d2 <= cull {
                    let x = if pd.pierced {
                        pd.d2 * inv_sigma
                    } else {
                        -pd.d2 * inv_sigma
                    };
                    f(t, &tri, &pd, x);
                }
            },
        );
    }

    /// Does the half-line hit the mesh? (Stops at the first hit.)
    fn hits(&self, o: &Vector3<T>, r: &Vector3<T>, culling: Culling) -> bool {
        let pierces = |t: u32| ray_triangle(o, r, &self.tri(t)).is_some();
        match culling {
            Culling::Dense => (0..self.triangles.len() as u32).any(pierces),
            Culling::Bvh => self.bvh.any_near_ray(o, &inverse_dir(r), T::zero(), |t| {
                // A triangle whose bounding sphere misses the half-line is not pierced.
                let (c, rho) = self.spheres[t as usize];
                let s = (c - o).dot(r).max(T::zero());
                (o + r * s - c).norm_squared() <= rho * rho && pierces(t)
            }),
        }
    }

    /// [`Aggregation::Silhouette`] for one ray: `(x, what sets it, triangles visited)`.
    /// `cand` is scratch.
    fn silhouette_ray(
        &self,
        o: &Vector3<T>,
        r: &Vector3<T>,
        p: &OccupancyParams,
        culling: Culling,
        cand: &mut Vec<(T, T, T, u32)>,
    ) -> (T, Option<Nearest<T>>, u32) {
        let inv_sigma = T::of(1.0 / p.sigma_m2);
        let cull = T::of(p.cull_d2());
        let mut visited = 0u32;
        if !self.hits(o, r, culling) {
            // The nearest point of the mesh to a missing ray is on its silhouette: a nearest
            // search whose radius shrinks to the best distance so far.
            let mut best: Option<Nearest<T>> = None;
            let mut consider = |t: u32| {
                visited += 1;
                let (c, rho) = self.spheres[t as usize];
                let s = (c - o).dot(r).max(T::zero());
                let bound = ((o + r * s - c).norm() - rho).max(T::zero());
                let best_d2 = best.map_or(cull, |b| b.pair.d2);
                if bound * bound > best_d2 {
                    return best_d2.sqrt();
                }
                let pd = ray_triangle_distance(o, r, &self.tri(t));
                if pd.d2 <= best_d2 {
                    best = Some(Nearest {
                        vertices: self.triangles[t as usize],
                        pair: pd,
                    });
                    return pd.d2.sqrt();
                }
                best_d2.sqrt()
            };
            match culling {
                Culling::Dense => (0..self.triangles.len() as u32).for_each(|t| {
                    consider(t);
                }),
                Culling::Bvh => {
                    self.bvh
                        .for_each_near_ray_shrinking(o, &inverse_dir(r), cull.sqrt(), consider)
                }
            }
            let x = best.map_or(-cull * inv_sigma, |b| -b.pair.d2 * inv_sigma);
            return (x, best, visited);
        }
        // Contour edges near the ray, nearest first; the first exposed one is the silhouette.
        cand.clear();
        // Subtrees without a contour edge along `r` are skipped: on a closed body most of what
        // a deep hitting ray passes near faces it (or away from it) throughout.
        let skip = |node| self.contour_free(node, r);
        self.for_each_near((o, r), cull.sqrt(), culling, skip, |t| {
            visited += 1;
            for &e in &self.tri_edges[t as usize] {
                let edge = self.edges[e as usize];
                // Each edge once: from its first face (both faces are visited when it is near).
                if edge.f[0] != t {
                    continue;
                }
                let contour = edge.f[1] == NO_FACE
                    || self.normals[edge.f[0] as usize].dot(r)
                        * self.normals[edge.f[1] as usize].dot(r)
                        <= T::zero();
                if !contour {
                    continue;
                }
                let [a, b] = edge.v.map(|v| self.vertices[v as usize]);
                let (d2, u, s) = segment_ray(&a, &b, o, r);
                if d2 <= cull {
                    cand.push((d2, u, s, e));
                }
            }
        });
        cand.sort_unstable_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
        // Just past an edge: 1 % of σ^½ beyond it.
        let past = T::of(0.01 * p.sigma_m2.sqrt());
        // Deep inside, every nearby contour is hidden: after a few, call the ray saturated.
        for &(d2, u, s, e) in cand.iter().take(MAX_EXPOSURE_TESTS) {
            let [ia, ib] = self.edges[e as usize].v;
            let (a, b) = (self.vertices[ia as usize], self.vertices[ib as usize]);
            let w = a + (b - a) * u - (o + r * s);
            let w_perp = w - r * w.dot(r);
            let n = w_perp.norm();
            let exposed =
                n <= past * T::of(1e-3) || !self.hits(&(o + w_perp * ((n + past) / n)), r, culling);
            if exposed {
                let pair = PairDistance {
                    d2,
                    s,
                    bary: [T::one() - u, u, T::zero()],
                    pierced: true,
                };
                return (
                    d2 * inv_sigma,
                    Some(Nearest {
                        vertices: [ia, ib, ib],
                        pair,
                    }),
                    visited,
                );
            }
        }
        (cull * inv_sigma, None, visited)
    }

    /// `I_i` for every ray.
    pub fn forward(
        &self,
        rays: &ReflectedRays<T>,
        params: &OccupancyParams,
        culling: Culling,
    ) -> Occupancy<T> {
        if params.aggregation == Aggregation::Silhouette {
            let results: Vec<(T, Option<Nearest<T>>, u32)> = (0..rays.len())
                .into_par_iter()
                .with_min_len(4)
                .map_init(Vec::new, |cand, i| {
                    self.silhouette_ray(&rays.origin[i], &rays.dir[i], params, culling, cand)
                })
                .collect();
            return Occupancy {
                value: results.iter().map(|r| sigmoid(r.0)).collect(),
                log_complement: results.iter().map(|r| -softplus(r.0)).collect(),
                pairs_per_ray: results.iter().map(|r| r.2).collect(),
                pairs: results.iter().map(|r| u64::from(r.2)).sum(),
                nearest: results.iter().map(|r| r.1).collect(),
            };
        }
        let results: Vec<(T, u32)> = (0..rays.len())
            .into_par_iter()
            .with_min_len(4)
            .map(|i| {
                let mut log_c = T::zero();
                let mut n = 0u32;
                self.for_each_pair(
                    &rays.origin[i],
                    &rays.dir[i],
                    params,
                    culling,
                    |_, _, _, x| {
                        log_c -= softplus(x);
                        n += 1;
                    },
                );
                (log_c, n)
            })
            .collect();
        Occupancy {
            value: results.iter().map(|(l, _)| -l.exp_m1()).collect(),
            log_complement: results.iter().map(|(l, _)| *l).collect(),
            pairs_per_ray: results.iter().map(|r| r.1).collect(),
            pairs: results.iter().map(|r| u64::from(r.1)).sum(),
            nearest: Vec::new(),
        }
    }

    /// Backward of [`Self::forward`]: from `d_value = ∂L/∂I_i` to the mesh and ray gradients.
    /// Allocation-free after the first call with the same ray count (the sparse per-chunk
    /// contribution lists keep their capacity).
    pub fn backward(
        &mut self,
        rays: &ReflectedRays<T>,
        occ: &Occupancy<T>,
        d_value: &[T],
        params: &OccupancyParams,
        culling: Culling,
        grad: &mut OccupancyGrad<T>,
    ) {
        let n = rays.len();
        grad.vertices.clear();
        grad.vertices.resize(self.vertices.len(), Vector3::zeros());
        grad.origin.clear();
        grad.origin.resize(n, Vector3::zeros());
        grad.dir.clear();
        grad.dir.resize(n, Vector3::zeros());
        let n_chunks = n.div_ceil(RAY_CHUNK);
        if self.contributions.len() < n_chunks {
            self.contributions.resize_with(n_chunks, Vec::new);
        }
        let inv_sigma = T::of(1.0 / params.sigma_m2);
        let mut contributions = std::mem::take(&mut self.contributions);
        let this = &*self;
        grad.origin
            .par_chunks_mut(RAY_CHUNK)
            .zip(grad.dir.par_chunks_mut(RAY_CHUNK))
            .zip(contributions.par_iter_mut())
            .enumerate()
            .for_each(|(c, ((d_o, d_r), contrib))| {
                contrib.clear();
                for k in 0..d_o.len() {
                    let i = c * RAY_CHUNK + k;
                    let g = d_value[i];
                    if g == T::zero() || occ.pairs_per_ray[i] == 0 {
                        continue;
                    }
                    let (o, r) = (&rays.origin[i], &rays.dir[i]);
                    if params.aggregation == Aggregation::Silhouette {
                        // ∂L/∂x = g I (1 − I); x = ±d²/σ.
                        let Some(Some(near)) = occ.nearest.get(i) else {
                            continue;
                        };
                        let v = occ.value[i];
                        let dx = g * v * (T::one() - v);
                        let dd2 = if near.pair.pierced {
                            dx * inv_sigma
                        } else {
                            -dx * inv_sigma
                        };
                        let tri = near.vertices.map(|k| this.vertices[k as usize]);
                        let pg = near.pair.grad(o, r, &tri);
                        d_o[k] += pg.origin * dd2;
                        d_r[k] += pg.dir * dd2;
                        for (v, gv) in near.vertices.iter().zip(pg.vertices) {
                            contrib.push((*v, gv * dd2));
                        }
                        continue;
                    }
                    // ∂L/∂x_ij = g (1 − I_i) D_ij; x = λ d²/σ.
                    let scale = g * occ.log_complement[i].exp();
                    this.for_each_pair(o, r, params, culling, |t, tri, pd, x| {
                        let dx = scale * sigmoid(x);
                        if dx == T::zero() {
                            return;
                        }
                        let dd2 = if pd.pierced {
                            dx * inv_sigma
                        } else {
                            -dx * inv_sigma
                        };
                        let pg = pd.grad(o, r, tri);
                        d_o[k] += pg.origin * dd2;
                        d_r[k] += pg.dir * dd2;
                        for (v, gv) in this.triangles[t as usize].iter().zip(pg.vertices) {
                            contrib.push((*v, gv * dd2));
                        }
                    });
                }
            });
        for list in &contributions[..n_chunks] {
            for (v, g) in list {
                grad.vertices[*v as usize] += g;
            }
        }
        self.contributions = contributions;
    }
}

/// Soft IoU of occupancies `occupancy[i]` against targets `target(i)`, both in [0, 1]:
/// `IoU = Σ vt / (union_outside + Σ (v + t − vt))`, where `union_outside` is the target mass of
/// pixels no element covers. Returns `(1 − IoU, IoU)` and writes `∂(1 − IoU)/∂v_i` into
/// `d_value`. Two empty masks agree: an empty union gives loss 0, IoU 1 and zero gradients.
/// Stage 2 (targets per sampled ray) and [`soft_iou_loss`] (a target over all pixels) use it.
pub fn soft_iou<T: Real>(
    occupancy: &[T],
    target: impl Fn(usize) -> T,
    union_outside: T,
    d_value: &mut Vec<T>,
) -> (T, T) {
    soft_iou_weighted(occupancy, target, |_| T::one(), union_outside, d_value)
}

/// [`soft_iou`] with a weight per element in both sums: `Σ w vt / (union_outside + Σ w (v + t −
/// vt))`. With importance weights (the inverse of each element's sampling probability) it
/// estimates the IoU over all elements from a stratified sample.
pub fn soft_iou_weighted<T: Real>(
    occupancy: &[T],
    target: impl Fn(usize) -> T,
    weight: impl Fn(usize) -> T,
    union_outside: T,
    d_value: &mut Vec<T>,
) -> (T, T) {
    let (mut inter, mut union) = (T::zero(), union_outside);
    for (i, &v) in occupancy.iter().enumerate() {
        let (t, w) = (target(i), weight(i));
        inter += w * v * t;
        union += w * (v + t - v * t);
    }
    d_value.clear();
    if union <= T::zero() {
        d_value.resize(occupancy.len(), T::zero());
        return (T::zero(), T::one());
    }
    let u2 = union * union;
    d_value.extend((0..occupancy.len()).map(|i| {
        let t = target(i);
        -weight(i) * (t * union - inter * (T::one() - t)) / u2
    }));
    (T::one() - inter / union, inter / union)
}

/// `1 − soft IoU` ([`soft_iou`]) between per-ray occupancy (scattered to pixels; 0 where no
/// ray) and a target mask over all pixels, and `∂L/∂I_i` per ray. One ray per pixel.
pub fn soft_iou_loss<T: Real>(
    rays: &ReflectedRays<T>,
    occupancy: &[T],
    target: &[T],
    d_value: &mut Vec<T>,
) -> T {
    // Pixels without rays: I = 0 there, so only their target adds to the union.
    let all: T = target.iter().fold(T::zero(), |a, &t| a + t);
    let covered: T = rays
        .pixel
        .iter()
        .fold(T::zero(), |a, &p| a + target[p as usize]);
    let target_of = |i: usize| target[rays.pixel[i] as usize];
    soft_iou(occupancy, target_of, all - covered, d_value).0
}
