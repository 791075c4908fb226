//! A bounding-volume hierarchy over a triangle mesh whose vertices move every iteration: built
//! once (topology), refitted in O(n) after each vertex update, queried with inflated half-lines.

use irmirror_geom::Real;
use nalgebra::Vector3;

/// Triangles per leaf at most.
const LEAF_SIZE: usize = 4;
/// Traversal stack depth (the tree is balanced by median splits: depth ≈ log2(n / 4) + 1).
const STACK: usize = 64;

#[derive(Clone, Copy, Debug)]
struct Node<T: Real> {
    lo: Vector3<T>,
    hi: Vector3<T>,
    /// Leaf: first index into `order`; inner: index of the left child.
    first: u32,
    /// Leaf: triangle count; inner: 0.
    count: u32,
    /// Inner: index of the right child.
    right: u32,
}

/// The hierarchy. Node 0 is the root; children have larger indices than their parent, so a
/// reverse sweep refits bottom-up.
#[derive(Clone, Debug)]
pub struct Bvh<T: Real> {
    nodes: Vec<Node<T>>,
    /// Triangle indices, leaf ranges point into this.
    order: Vec<u32>,
}

impl<T: Real> Bvh<T> {
    /// Builds over `triangles` of `vertices` (median split on the widest centroid axis).
    pub fn build(vertices: &[Vector3<T>], triangles: &[[u32; 3]]) -> Self {
        let centroids: Vec<Vector3<T>> = triangles
            .iter()
            .map(|t| {
                (vertices[t[0] as usize] + vertices[t[1] as usize] + vertices[t[2] as usize])
                    / T::of(3.0)
            })
            .collect();
        let mut bvh = Self {
            nodes: Vec::with_capacity(2 * triangles.len() / LEAF_SIZE + 1),
            order: (0..triangles.len() as u32).collect(),
        };
        if !triangles.is_empty() {
            bvh.split(0, triangles.len(), &centroids);
            bvh.refit(vertices, triangles);
        }
        bvh
    }

    fn split(&mut self, start: usize, end: usize, centroids: &[Vector3<T>]) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            lo: Vector3::zeros(),
            hi: Vector3::zeros(),
            first: start as u32,
            count: (end - start) as u32,
            right: 0,
        });
        if end - start <= LEAF_SIZE {
            return id;
        }
        let (mut lo, mut hi) = (
            centroids[self.order[start] as usize],
            centroids[self.order[start] as usize],
        );
        for &t in &self.order[start..end] {
            lo = lo.inf(&centroids[t as usize]);
            hi = hi.sup(&centroids[t as usize]);
        }
        let axis = (hi - lo).imax();
        let mid = (start + end) / 2;
        self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            centroids[a as usize][axis]
                .partial_cmp(&centroids[b as usize][axis])
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let left = self.split(start, mid, centroids);
        let right = self.split(mid, end, centroids);
        let node = &mut self.nodes[id as usize];
        node.first = left;
        node.count = 0;
        node.right = right;
        id
    }

    /// Recomputes every box for new vertex positions (same topology).
    pub fn refit(&mut self, vertices: &[Vector3<T>], triangles: &[[u32; 3]]) {
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            let (lo, hi) = if n.count > 0 {
                let mut lo = Vector3::repeat(T::max_value().unwrap_or(T::one()));
                let mut hi = -lo;
                for &t in &self.order[n.first as usize..(n.first + n.count) as usize] {
                    for &v in &triangles[t as usize] {
                        lo = lo.inf(&vertices[v as usize]);
                        hi = hi.sup(&vertices[v as usize]);
                    }
                }
                (lo, hi)
            } else {
                let (l, r) = (self.nodes[n.first as usize], self.nodes[n.right as usize]);
                (l.lo.inf(&r.lo), l.hi.sup(&r.hi))
            };
            self.nodes[i].lo = lo;
            self.nodes[i].hi = hi;
        }
    }

    /// Calls `visit(triangle)` for every triangle whose box, inflated by `radius`, meets the
    /// half-line `o + s r`, `s ≥ 0`. `inv_r` is `1 / r` per component. No allocation.
    pub fn for_each_near_ray(
        &self,
        o: &Vector3<T>,
        inv_r: &Vector3<T>,
        radius: T,
        visit: impl FnMut(u32),
    ) {
        self.for_each_near_ray_pruned(o, inv_r, radius, |_| false, visit);
    }

    /// As [`Self::for_each_near_ray`], but skips every subtree whose node `skip(node)` rejects
    /// (node indices as [`Self::refit_node_boxes`] orders them): a query that knows, from a
    /// per-node summary, that nothing below can matter.
    pub fn for_each_near_ray_pruned(
        &self,
        o: &Vector3<T>,
        inv_r: &Vector3<T>,
        radius: T,
        skip: impl Fn(usize) -> bool,
        mut visit: impl FnMut(u32),
    ) {
        self.walk(o, inv_r, radius, skip, |t| {
            visit(t);
            Some(radius)
        });
    }

    /// Per node, the union of its triangles' boxes `leaf_box(triangle) = (lo, hi)` in any space
    /// (not only positions: the renderer bounds face normals with it), written into `boxes`
    /// (one per node, reused). O(nodes), bottom-up like [`Self::refit`].
    pub fn refit_node_boxes(
        &self,
        boxes: &mut Vec<(Vector3<T>, Vector3<T>)>,
        leaf_box: impl Fn(u32) -> (Vector3<T>, Vector3<T>),
    ) {
        boxes.clear();
        boxes.resize(self.nodes.len(), (Vector3::zeros(), Vector3::zeros()));
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            boxes[i] = if n.count > 0 {
                let mut lo = Vector3::repeat(T::max_value().unwrap_or(T::one()));
                let mut hi = -lo;
                for &t in &self.order[n.first as usize..(n.first + n.count) as usize] {
                    let (l, h) = leaf_box(t);
                    lo = lo.inf(&l);
                    hi = hi.sup(&h);
                }
                (lo, hi)
            } else {
                let (l, r) = (boxes[n.first as usize], boxes[n.right as usize]);
                (l.0.inf(&r.0), l.1.sup(&r.1))
            };
        }
    }

    /// Whether `test(triangle)` holds for any triangle whose box, inflated by `radius`, meets
    /// the half-line (as [`Self::for_each_near_ray`]); stops at the first that does.
    pub fn any_near_ray(
        &self,
        o: &Vector3<T>,
        inv_r: &Vector3<T>,
        radius: T,
        mut test: impl FnMut(u32) -> bool,
    ) -> bool {
        self.walk(
            o,
            inv_r,
            radius,
            |_| false,
            |t| (!test(t)).then_some(radius),
        )
    }

    /// As [`Self::for_each_near_ray`], but `visit` returns the radius from then on (never
    /// larger): a nearest-element search prunes the boxes beyond its best distance so far.
    pub fn for_each_near_ray_shrinking(
        &self,
        o: &Vector3<T>,
        inv_r: &Vector3<T>,
        radius: T,
        mut visit: impl FnMut(u32) -> T,
    ) {
        self.walk(o, inv_r, radius, |_| false, |t| Some(visit(t)));
    }

    /// The traversal every query shares: subtrees `skip` rejects are not entered; `visit`
    /// returns the radius from then on, or `None` to stop (then `true` is returned).
    #[inline]
    fn walk(
        &self,
        o: &Vector3<T>,
        inv_r: &Vector3<T>,
        mut radius: T,
        skip: impl Fn(usize) -> bool,
        mut visit: impl FnMut(u32) -> Option<T>,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = [0u32; STACK];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let n = &self.nodes[stack[top] as usize];
            if !slab_hit(
                &(n.lo.add_scalar(-radius)),
                &(n.hi.add_scalar(radius)),
                o,
                inv_r,
            ) || skip(stack[top] as usize)
            {
                continue;
            }
            if n.count > 0 {
                for &t in &self.order[n.first as usize..(n.first + n.count) as usize] {
                    match visit(t) {
                        Some(r) => radius = r.min(radius),
                        None => return true,
                    }
                }
            } else {
                debug_assert!(top + 2 <= STACK);
                stack[top] = n.right;
                stack[top + 1] = n.first;
                top += 2;
            }
        }
        false
    }
}

/// Does the half-line `o + s r`, `s ≥ 0`, meet the box `[lo, hi]`?
#[inline]
fn slab_hit<T: Real>(lo: &Vector3<T>, hi: &Vector3<T>, o: &Vector3<T>, inv_r: &Vector3<T>) -> bool {
    let mut t0 = T::zero();
    let mut t1 = T::max_value().unwrap_or(T::one());
    for k in 0..3 {
        if inv_r[k].is_finite() {
            let a = (lo[k] - o[k]) * inv_r[k];
            let b = (hi[k] - o[k]) * inv_r[k];
            let (near, far) = if a < b { (a, b) } else { (b, a) };
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return false;
            }
        } else if o[k] < lo[k] || o[k] > hi[k] {
            // Parallel to this slab and outside it.
            return false;
        }
    }
    true
}

/// Component-wise reciprocal of a direction (infinite where a component is zero).
pub fn inverse_dir<T: Real>(r: &Vector3<T>) -> Vector3<T> {
    r.map(|x| T::one() / x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The early-exit query answers what visiting every near triangle would, and stops early:
    /// on a random triangle soup, for random rays and radii, `any_near_ray` with a test is true
    /// exactly when some triangle `for_each_near_ray` visits passes it, and with a test that
    /// always passes it calls it once.
    #[test]
    fn any_near_ray_agrees_with_visiting_every_triangle() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut u = |lo: f64, hi: f64| rng.random_range(lo..hi);
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        for k in 0..300u32 {
            let c = Vector3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
            for _ in 0..3 {
                vertices.push(c + Vector3::new(u(-0.1, 0.1), u(-0.1, 0.1), u(-0.1, 0.1)));
            }
            triangles.push([3 * k, 3 * k + 1, 3 * k + 2]);
        }
        let bvh = Bvh::build(&vertices, &triangles);
        let (mut some, mut none) = (0, 0);
        for _ in 0..200 {
            let o = Vector3::new(u(-2.0, 2.0), u(-2.0, 2.0), -3.0);
            let r = (Vector3::new(u(-1.0, 1.0), u(-1.0, 1.0), 3.0) - o).normalize();
            let radius = u(0.0, 0.05);
            let inv = inverse_dir(&r);
            let test = |t: u32| t.is_multiple_of(7);
            let mut visited = Vec::new();
            bvh.for_each_near_ray(&o, &inv, radius, |t| visited.push(t));
            let expected = visited.iter().any(|&t| test(t));
            assert_eq!(bvh.any_near_ray(&o, &inv, radius, test), expected);
            let mut calls = 0;
            let any = bvh.any_near_ray(&o, &inv, radius, |_| {
                calls += 1;
                true
            });
            assert_eq!(any, !visited.is_empty());
            assert!(calls <= 1);
            if visited.is_empty() {
                none += 1
            } else {
                some += 1
            }
        }
        assert!(
            some > 20 && none > 20,
            "{some} rays near triangles, {none} not"
        );
    }
}
