//! Distances between a half-line and a triangle, and their gradients — the geometric kernel of
//! soft occupancy (SoftRas-style, extended from screen-space points to 3-D rays).
//!
//! Every function returns the squared distance together with the closest points' parameters;
//! by the envelope theorem the gradient of the minimum w.r.t. the ray and the vertices is the
//! gradient of `|P − Q|²` with those parameters held fixed (the parameter domains, `s ≥ 0` on the
//! ray and the simplex/edge on the triangle, do not move). [`PairDistance::grad`] turns that into
//! `∂d²/∂(o, r, v0, v1, v2)`.

use irmirror_geom::Real;
use nalgebra::Vector3;

/// Closest pair between a half-line `o + s r` (`s ≥ 0`) and a triangle or its boundary.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairDistance<T: Real> {
    /// Squared distance, m².
    pub d2: T,
    /// Ray parameter of the closest point on the half-line (m along `r` if `r` is unit).
    pub s: T,
    /// Barycentric weights of the closest point on the triangle (sum 1).
    pub bary: [T; 3],
    /// True if Möller–Trumbore finds the half-line piercing the triangle (`t > 0`); then `d2`
    /// is the squared distance to the triangle's boundary (its three edges).
    pub pierced: bool,
}

/// `∂d²/∂(origin, direction, v0, v1, v2)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairGrad<T: Real> {
    /// `∂d²/∂o`.
    pub origin: Vector3<T>,
    /// `∂d²/∂r` (the direction taken as a free vector).
    pub dir: Vector3<T>,
    /// `∂d²/∂v_k`.
    pub vertices: [Vector3<T>; 3],
}

impl<T: Real> PairDistance<T> {
    /// The gradient of `d2`.
    pub fn grad(&self, o: &Vector3<T>, r: &Vector3<T>, v: &[Vector3<T>; 3]) -> PairGrad<T> {
        let p = o + r * self.s;
        let q = v[0] * self.bary[0] + v[1] * self.bary[1] + v[2] * self.bary[2];
        let two_diff = (p - q) * (T::one() + T::one());
        PairGrad {
            origin: two_diff,
            dir: two_diff * self.s,
            vertices: [
                -two_diff * self.bary[0],
                -two_diff * self.bary[1],
                -two_diff * self.bary[2],
            ],
        }
    }
}

/// Möller–Trumbore: the ray parameter `t > 0` where `o + t r` crosses the triangle, if any.
pub fn ray_triangle<T: Real>(o: &Vector3<T>, r: &Vector3<T>, v: &[Vector3<T>; 3]) -> Option<T> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let pvec = r.cross(&e2);
    let det = e1.dot(&pvec);
    // Parallel (or degenerate) triangles are never pierced; their edges still count.
    if det.abs() <= T::eps() * (e1.norm_squared() + e2.norm_squared()) {
        return None;
    }
    let inv = T::one() / det;
    let tvec = o - v[0];
    let u = tvec.dot(&pvec) * inv;
    if u < T::zero() || u > T::one() {
        return None;
    }
    let qvec = tvec.cross(&e1);
    let w = r.dot(&qvec) * inv;
    if w < T::zero() || u + w > T::one() {
        return None;
    }
    let t = e2.dot(&qvec) * inv;
    (t > T::zero()).then_some(t)
}

/// Closest points between segment `a + u (b − a)`, `u ∈ [0, 1]`, and half-line `o + s r`,
/// `s ≥ 0` (Ericson, *Real-Time Collision Detection* §5.1.9, one side unbounded).
/// Returns `(d², u, s)`.
pub fn segment_ray<T: Real>(
    a: &Vector3<T>,
    b: &Vector3<T>,
    o: &Vector3<T>,
    r: &Vector3<T>,
) -> (T, T, T) {
    let (zero, one) = (T::zero(), T::one());
    let d1 = b - a; // segment
    let w = a - o;
    let aa = d1.dot(&d1);
    let ee = r.dot(r);
    let f = r.dot(&w);
    let (u, s);
    if aa <= T::eps() * T::eps() {
        u = zero;
        s = (f / ee).max(zero);
    } else {
        let c = d1.dot(&w);
        let bb = d1.dot(r);
        let denom = aa * ee - bb * bb;
        let mut uu = if denom > T::eps() * aa * ee {
            ((bb * f - c * ee) / denom).clamp(zero, one)
        } else {
            zero
        };
        let mut ss = (bb * uu + f) / ee;
        if ss < zero {
            ss = zero;
            uu = (-c / aa).clamp(zero, one);
        }
        u = uu;
        s = ss;
    }
    let diff = a + d1 * u - (o + r * s);
    (diff.norm_squared(), u, s)
}

/// Closest point of triangle `v` to point `p` (Ericson §5.1.5): `(d², barycentrics)`.
pub fn point_triangle<T: Real>(p: &Vector3<T>, v: &[Vector3<T>; 3]) -> (T, [T; 3]) {
    let (zero, one) = (T::zero(), T::one());
    let (a, b, c) = (v[0], v[1], v[2]);
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    let bary = if d1 <= zero && d2 <= zero {
        [one, zero, zero]
    } else {
        let bp = p - b;
        let d3 = ab.dot(&bp);
        let d4 = ac.dot(&bp);
        if d3 >= zero && d4 <= d3 {
            [zero, one, zero]
        } else {
            let vc = d1 * d4 - d3 * d2;
            if vc <= zero && d1 >= zero && d3 <= zero {
                let t = d1 / (d1 - d3);
                [one - t, t, zero]
            } else {
                let cp = p - c;
                let d5 = ab.dot(&cp);
                let d6 = ac.dot(&cp);
                if d6 >= zero && d5 <= d6 {
                    [zero, zero, one]
                } else {
                    let vb = d5 * d2 - d1 * d6;
                    if vb <= zero && d2 >= zero && d6 <= zero {
                        let t = d2 / (d2 - d6);
                        [one - t, zero, t]
                    } else {
                        let va = d3 * d6 - d5 * d4;
                        if va <= zero && (d4 - d3) >= zero && (d5 - d6) >= zero {
                            let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
                            [zero, one - t, t]
                        } else {
                            let denom = va + vb + vc;
                            if denom.abs() <= T::eps() {
                                // Degenerate (zero-area) triangle: fall back to its edges.
                                return closest_on_edges_to_point(p, v);
                            }
                            let inv = one / denom;
                            let (bv, cv) = (vb * inv, vc * inv);
                            [one - bv - cv, bv, cv]
                        }
                    }
                }
            }
        }
    };
    let q = a * bary[0] + b * bary[1] + c * bary[2];
    ((p - q).norm_squared(), bary)
}

fn closest_on_edges_to_point<T: Real>(p: &Vector3<T>, v: &[Vector3<T>; 3]) -> (T, [T; 3]) {
    let mut best = (
        T::max_value().unwrap_or(T::one()),
        [T::one(), T::zero(), T::zero()],
    );
    for k in 0..3 {
        let (a, b) = (v[k], v[(k + 1) % 3]);
        let e = b - a;
        let len2 = e.norm_squared();
        let u = if len2 > T::zero() {
            ((p - a).dot(&e) / len2).clamp(T::zero(), T::one())
        } else {
            T::zero()
        };
        let d2 = (a + e * u - p).norm_squared();
        if d2 < best.0 {
            let mut bary = [T::zero(); 3];
            bary[k] = T::one() - u;
            bary[(k + 1) % 3] = u;
            best = (d2, bary);
        }
    }
    best
}

/// The SoftRas distance between half-line `o + s r` and triangle `v`: to the triangle when not
/// pierced, to its boundary when pierced (so that occupancy rises towards 1 inside).
pub fn ray_triangle_distance<T: Real>(
    o: &Vector3<T>,
    r: &Vector3<T>,
    v: &[Vector3<T>; 3],
) -> PairDistance<T> {
    let pierced = ray_triangle(o, r, v).is_some();
    // Edges (both cases).
    let mut best = PairDistance {
        d2: T::max_value().unwrap_or(T::one()),
        s: T::zero(),
        bary: [T::zero(); 3],
        pierced,
    };
    for k in 0..3 {
        let (a, b) = (v[k], v[(k + 1) % 3]);
        let (d2, u, s) = segment_ray(&a, &b, o, r);
        if d2 < best.d2 {
            let mut bary = [T::zero(); 3];
            bary[k] = T::one() - u;
            bary[(k + 1) % 3] += u;
            best = PairDistance {
                d2,
                s,
                bary,
                pierced,
            };
        }
    }
    if !pierced {
        // The ray's origin may be closest to the triangle's interior.
        let (d2, bary) = point_triangle(o, v);
        if d2 < best.d2 {
            best = PairDistance {
                d2,
                s: T::zero(),
                bary,
                pierced,
            };
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    /// Brute force: minimise over a fine grid of ray parameters and barycentrics.
    fn brute(
        o: &Vector3<f64>,
        r: &Vector3<f64>,
        tri: &[Vector3<f64>; 3],
        boundary_only: bool,
    ) -> f64 {
        let n = 200;
        let mut best = f64::MAX;
        let pts: Vec<Vector3<f64>> = if boundary_only {
            (0..3)
                .flat_map(|k| (0..=n).map(move |i| (k, i as f64 / n as f64)))
                .map(|(k, u)| tri[k] * (1.0 - u) + tri[(k + 1) % 3] * u)
                .collect()
        } else {
            (0..=n)
                .flat_map(|i| (0..=n - i).map(move |j| (i, j)))
                .map(|(i, j)| {
                    let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                    tri[0] * (1.0 - a - b) + tri[1] * a + tri[2] * b
                })
                .collect()
        };
        for q in pts {
            // Exact closest point on the half-line to q.
            let s = (q - o).dot(r).max(0.0) / r.norm_squared();
            best = best.min((o + r * s - q).norm_squared());
        }
        best
    }

    #[test]
    fn distances_match_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut pierced_seen = 0;
        for _ in 0..200 {
            let tri = [0, 1, 2].map(|_| {
                v(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.3..0.3),
                )
            });
            let o = v(
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
                rng.random_range(-2.0..2.0),
            );
            // Aim near the triangle so that about half the rays pierce it.
            let aim = (tri[0] + tri[1] + tri[2]) / 3.0
                + v(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    0.0,
                );
            let r = (aim - o).normalize();
            let pd = ray_triangle_distance(&o, &r, &tri);
            pierced_seen += usize::from(pd.pierced);
            let b = brute(&o, &r, &tri, pd.pierced);
            // The grid over-estimates the minimum by O((edge/n)²); our value must not exceed it
            // and must be close.
            assert!(pd.d2 <= b + 1e-12, "{} > brute {}", pd.d2, b);
            assert!(
                b - pd.d2 < 2e-3 * (1.0 + b.sqrt()),
                "{} vs brute {}",
                pd.d2,
                b
            );
        }
        assert!(
            pierced_seen > 40,
            "the sample should contain pierced triangles"
        );
    }

    #[test]
    fn piercing_follows_moller_trumbore() {
        let tri = [v(0.0, 0.0, 1.0), v(1.0, 0.0, 1.0), v(0.0, 1.0, 1.0)];
        let r = v(0.0, 0.0, 1.0);
        assert!((ray_triangle(&v(0.2, 0.2, 0.0), &r, &tri).unwrap() - 1.0).abs() < 1e-15);
        assert_eq!(
            ray_triangle(&v(0.2, 0.2, 2.0), &r, &tri),
            None,
            "behind the origin"
        );
        assert_eq!(ray_triangle(&v(0.8, 0.8, 0.0), &r, &tri), None);
        // Pierced at (0.2, 0.2): the nearest edges are x = 0 and y = 0, both 0.2 away.
        let pd = ray_triangle_distance(&v(0.2, 0.2, 0.0), &r, &tri);
        assert!(pd.pierced && (pd.d2 - 0.04).abs() < 1e-12);
        // Not pierced, the origin right above the interior, ray pointing away.
        let pd = ray_triangle_distance(&v(0.2, 0.2, 1.5), &r, &tri);
        assert!(!pd.pierced && (pd.d2 - 0.25).abs() < 1e-12 && pd.s == 0.0);
    }

    fn check_grad(o: Vector3<f64>, r: Vector3<f64>, tri: [Vector3<f64>; 3]) {
        let pd = ray_triangle_distance(&o, &r, &tri);
        let g = pd.grad(&o, &r, &tri);
        let h = 1e-7;
        let f = |o: Vector3<f64>, r: Vector3<f64>, t: [Vector3<f64>; 3]| {
            ray_triangle_distance(&o, &r, &t).d2
        };
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let fd_o = (f(o + e, r, tri) - f(o - e, r, tri)) / (2.0 * h);
            let fd_r = (f(o, r + e, tri) - f(o, r - e, tri)) / (2.0 * h);
            assert!(
                (fd_o - g.origin[k]).abs() < 1e-6,
                "origin {k}: {fd_o} vs {}",
                g.origin[k]
            );
            assert!(
                (fd_r - g.dir[k]).abs() < 1e-6,
                "dir {k}: {fd_r} vs {}",
                g.dir[k]
            );
            for j in 0..3 {
                let (mut tp, mut tm) = (tri, tri);
                tp[j] += e;
                tm[j] -= e;
                let fd = (f(o, r, tp) - f(o, r, tm)) / (2.0 * h);
                assert!(
                    (fd - g.vertices[j][k]).abs() < 1e-6,
                    "vertex {j}[{k}]: {fd} vs {}",
                    g.vertices[j][k]
                );
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        let tri = [v(0.0, 0.0, 1.0), v(1.0, 0.1, 1.2), v(0.1, 0.9, 0.8)];
        // Pierced (closest point on an edge interior, ray interior): smooth there.
        check_grad(v(0.3, 0.25, 0.0), v(0.05, -0.02, 1.0).normalize(), tri);
        // Passing beside an edge.
        check_grad(v(-0.3, 0.4, 0.0), v(0.1, 0.05, 1.0).normalize(), tri);
        // Closest to a vertex.
        check_grad(v(1.4, -0.3, 0.0), v(0.0, 0.02, 1.0).normalize(), tri);
        // Origin closest to the interior (ray pointing away).
        check_grad(v(0.3, 0.3, 1.6), v(0.1, 0.0, 1.0).normalize(), tri);
        // Grazing: ray almost parallel to the triangle plane, just above it.
        check_grad(
            v(-0.5, 0.3, 0.95),
            v(1.0, 0.01, 0.02).normalize(),
            [v(0.0, 0.0, 0.9), v(1.0, 0.0, 0.9), v(0.0, 1.0, 0.9)],
        );
    }

    #[test]
    fn degenerate_triangles_give_finite_values() {
        let o = v(0.1, 0.2, -1.0);
        let r = v(0.0, 0.0, 1.0);
        for tri in [
            [v(0.0, 0.0, 0.0); 3],
            [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(2.0, 0.0, 0.0)],
        ] {
            let pd = ray_triangle_distance(&o, &r, &tri);
            assert!(pd.d2.is_finite() && !pd.pierced);
            let g = pd.grad(&o, &r, &tri);
            assert!(
                g.vertices
                    .iter()
                    .chain([&g.origin, &g.dir])
                    .all(|x| x.iter().all(|c| c.is_finite()))
            );
        }
        // A ray parallel to the segment.
        let (d2, _, _) = segment_ray(&v(0.0, 1.0, 0.0), &v(0.0, 1.0, 1.0), &v(0.0, 0.0, 0.0), &r);
        assert!((d2 - 1.0).abs() < 1e-12);
    }
}
