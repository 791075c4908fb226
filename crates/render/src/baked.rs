//! A field sampled once on a grid and interpolated: what stage 2 traces in place of a learned
//! prior's network. Every reflected ray of a car costs a few dozen field values and a gradient;
//! the network costs ≈ 140k flops a value (44k values and gradients per second on 2 cores), so
//! a 640×512 frame of a car took minutes. Sampled once (batched) on a grid and interpolated by
//! cubic convolution, a value costs 64 multiply–adds.
//!
//! Interpolation: Keys' cubic convolution (a = −½) along each axis, a tensor product: it passes
//! through the samples, reproduces every polynomial of degree ≤ 2 exactly (so its error is
//! O(h³), its gradient's O(h²)) and its gradient is continuous (normals do not jump at cell
//! faces, as trilinear ones do).

use crate::sdf::Sdf;
use nalgebra::Vector3;
use std::sync::Arc;

/// A field on a grid of `n + 3` nodes per axis spanning the cube `[−R, R]³` (`R` its bounding
/// radius) with one node beyond each face (the cubic stencil's reach); outside the cube the
/// original field answers.
pub struct BakedSdf {
    /// The original field (queried outside the grid's cube only).
    inner: Arc<dyn Sdf>,
    /// The cube's half-size (the inner field's bounding radius).
    radius: f64,
    /// Node spacing, `2R / n`.
    h: f64,
    /// Nodes per axis (`n + 3`).
    nodes: usize,
    /// Samples, x fastest, then y, then z.
    values: Vec<f32>,
    /// Within this distance of the surface (by the grid's value) the original field answers
    /// (values and gradients): the grid only speeds the march towards it. `None`: the grid
    /// answers everywhere in its cube.
    band: Option<f64>,
}

impl BakedSdf {
    /// Samples `inner` at the grid's nodes with `eval` (a batch of object-frame points → their
    /// values, e.g. a network's batched forward pass); `cells` (≥ 2) cells per axis across the
    /// bounding cube. Fails with `eval`'s error, or when it returns the wrong number of values
    /// or a non-finite one.
    pub fn bake<E>(
        inner: Arc<dyn Sdf>,
        cells: usize,
        eval: impl FnOnce(&[Vector3<f64>]) -> Result<Vec<f64>, E>,
    ) -> Result<Self, String>
    where
        E: std::fmt::Display,
    {
        let cells = cells.max(2);
        let radius = inner.bounding_radius();
        let h = 2.0 * radius / cells as f64;
        let nodes = cells + 3;
        let at = |k: usize| -radius + (k as f64 - 1.0) * h;
        let points: Vec<Vector3<f64>> = (0..nodes * nodes * nodes)
            .map(|i| {
                Vector3::new(
                    at(i % nodes),
                    at(i / nodes % nodes),
                    at(i / (nodes * nodes)),
                )
            })
            .collect();
        let values = eval(&points).map_err(|e| e.to_string())?;
        if values.len() != points.len() || values.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "baking a field: {} values for {} nodes (finite: {})",
                values.len(),
                points.len(),
                values.iter().all(|v| v.is_finite())
            ));
        }
        Ok(Self {
            inner,
            radius,
            h,
            nodes,
            values: values.into_iter().map(|v| v as f32).collect(),
            band: None,
        })
    }

    /// The original field answers within `band` of the surface (by the grid's value), the grid
    /// beyond it. The traced surface and its normals are then the original field's exactly
    /// wherever `band` exceeds the grid's interpolation error (the sign of the grid's value
    /// beyond the band is the field's): a thin wall that bends within a cell keeps its normals,
    /// and a march still crosses empty space at the grid's cost.
    pub fn with_band(mut self, band: f64) -> Self {
        self.band = Some(band);
        self
    }

    /// The largest difference between the grid and `values` (the original field's, e.g. from a
    /// batched pass) at `points`: what a band must exceed.
    pub fn max_error(&self, points: &[Vector3<f64>], values: &[f64]) -> f64 {
        points
            .iter()
            .zip(values)
            .filter_map(|(p, v)| self.sample::<false>(p).map(|(f, _)| (f - v).abs()))
            .fold(0.0, f64::max)
    }

    /// The points halfway between nodes (cell centres) where the grid's value is within `near` of
    /// zero: where its interpolation error near the surface is largest.
    pub fn cell_centres_near_surface(&self, near: f64) -> Vec<Vector3<f64>> {
        let cells = self.nodes - 3;
        let at = |k: usize| -self.radius + (k as f64 + 0.5) * self.h;
        (0..cells * cells * cells)
            .map(|i| {
                Vector3::new(
                    at(i % cells),
                    at(i / cells % cells),
                    at(i / (cells * cells)),
                )
            })
            .filter(|p| self.sample::<false>(p).is_some_and(|(f, _)| f.abs() < near))
            .collect()
    }

    /// Value and gradient at `p` (object frame); `None` outside the grid's cube.
    pub fn value_grad(&self, p: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        self.sample::<true>(p)
    }

    /// [`Self::value_grad`] with the gradient only when `GRAD` (zero otherwise): the march asks
    /// for values alone, and the gradient's sums would double its cost.
    #[inline]
    fn sample<const GRAD: bool>(&self, p: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        // Per axis: the stencil's first node and the weights (and their derivatives) of its
        // four nodes.
        let mut first = [0usize; 3];
        let (mut w, mut dw) = ([[0.0; 4]; 3], [[0.0; 4]; 3]);
        for a in 0..3 {
            let u = (p[a] + self.radius) / self.h + 1.0;
            if !(u >= 1.0 && u <= (self.nodes - 2) as f64) {
                return None;
            }
            // The last cell's far face belongs to that cell.
            let i = (u.floor() as usize).min(self.nodes - 3);
            let t = u - i as f64;
            first[a] = i - 1;
            (w[a], dw[a]) = keys(t);
        }
        let n = self.nodes;
        let (mut f, mut g) = (0.0, Vector3::zeros());
        for (c, (wz, dwz)) in w[2].iter().zip(&dw[2]).enumerate() {
            for (b, (wy, dwy)) in w[1].iter().zip(&dw[1]).enumerate() {
                let row = ((first[2] + c) * n + first[1] + b) * n + first[0];
                let v = &self.values[row..row + 4];
                let (mut sx, mut dsx) = (0.0, 0.0);
                for k in 0..4 {
                    sx += w[0][k] * f64::from(v[k]);
                    if GRAD {
                        dsx += dw[0][k] * f64::from(v[k]);
                    }
                }
                f += wz * wy * sx;
                if GRAD {
                    g += Vector3::new(wz * wy * dsx, wz * dwy * sx, dwz * wy * sx);
                }
            }
        }
        Some((f, g / self.h))
    }
}

/// Keys' cubic convolution weights (a = −½) of the nodes at −1, 0, 1, 2 for a point `t ∈ [0, 1]`
/// past node 0, and their derivatives in `t`.
fn keys(t: f64) -> ([f64; 4], [f64; 4]) {
    let (t2, t3) = (t * t, t * t * t);
    (
        [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ],
        [
            0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
            0.5 * (9.0 * t2 - 10.0 * t),
            0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
            0.5 * (3.0 * t2 - 2.0 * t),
        ],
    )
}

impl BakedSdf {
    /// The grid's value (and, with `GRAD`, gradient) where it answers: inside its cube, beyond
    /// the band.
    fn grid<const GRAD: bool>(&self, p: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        self.sample::<GRAD>(p)
            .filter(|(f, _)| self.band.is_none_or(|b| f.abs() > b))
    }
}

impl Sdf for BakedSdf {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.grid::<false>(p)
            .map_or_else(|| self.inner.distance(p), |(f, _)| f)
    }
    fn gradient(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.grid::<true>(p)
            .map_or_else(|| self.inner.gradient(p), |(_, g)| g)
    }
    fn bounding_radius(&self) -> f64 {
        self.radius
    }
    fn max_step(&self) -> f64 {
        self.inner.max_step()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::Sphere;
    use crate::sphere_trace::march;

    /// A quadratic "field" (not a distance): cubic convolution reproduces it exactly.
    struct Quadratic;
    impl Sdf for Quadratic {
        fn distance(&self, p: &Vector3<f64>) -> f64 {
            0.3 * p.x * p.x - 0.7 * p.y * p.z + 0.2 * p.z * p.z + 0.5 * p.x - p.y + 0.1
        }
        fn bounding_radius(&self) -> f64 {
            0.8
        }
    }

    fn baked(inner: Arc<dyn Sdf>, cells: usize) -> BakedSdf {
        let f = inner.clone();
        BakedSdf::bake(inner, cells, |ps| {
            Ok::<_, String>(ps.iter().map(|p| f.distance(p)).collect())
        })
        .unwrap()
    }

    #[test]
    fn quadratics_are_reproduced_with_their_gradients() {
        let b = baked(Arc::new(Quadratic), 7);
        let mut rng = irmirror_geom::rng::seeded(3, 0);
        for _ in 0..500 {
            use rand::Rng;
            let p = Vector3::from_fn(|_, _| rng.random_range(-0.8..=0.8));
            let (f, g) = b.value_grad(&p).expect("inside the cube");
            // f32 samples: ≈ 1e-7 of the values.
            assert!((f - Quadratic.distance(&p)).abs() < 1e-6, "{p:?}");
            let exact = Quadratic.gradient(&p);
            assert!((g - exact).norm() < 1e-5, "{p:?}: {g:?} vs {exact:?}");
        }
        // Outside the cube the field itself answers.
        let far = Vector3::new(0.9, 0.0, 0.0);
        assert!(b.value_grad(&far).is_none());
        assert_eq!(b.distance(&far), Quadratic.distance(&far));
    }

    /// A sphere (not a quadratic: its error is the interpolation's): traced hits and normals of
    /// the baked field against the exact ones, and both errors fall as the cell shrinks (≈ 5×
    /// and 4× per halving).
    #[test]
    fn a_baked_sphere_is_traced_where_the_sphere_is() {
        let sphere = Sphere { radius: 0.6 };
        let err = |cells: usize| {
            let b = baked(Arc::new(sphere), cells);
            let (mut hit, mut angle) = (0.0f64, 0.0f64);
            for k in 0..200 {
                // Rays from a ring outside, aimed at points inside the sphere.
                let a = k as f64 * 0.61;
                let o = Vector3::new(2.0 * a.cos(), 0.3 * a.sin(), 2.0 * a.sin());
                let target = Vector3::new(0.3 * (3.0 * a).sin(), 0.25 * a.cos(), 0.0);
                let r = (target - o).normalize();
                let t = march(&b, &o, &r, 1e-9, 500).expect("hits");
                let p = o + r * t;
                hit = hit.max((p.norm() - 0.6).abs());
                angle = angle.max(b.gradient(&p).normalize().angle(&p.normalize()));
            }
            (hit, angle.to_degrees())
        };
        // Measured: hits 3.1e-5 → 6.4e-6 (radius 0.6), normals 0.17° → 0.040°.
        let (coarse, fine) = (err(16), err(32));
        assert!(fine.0 < 1e-5 && fine.1 < 0.05, "{fine:?}");
        assert!(
            coarse.0 > 3.0 * fine.0 && coarse.1 > 3.0 * fine.1,
            "{coarse:?} → {fine:?}"
        );
    }

    /// The interpolant's own gradient against central differences of its values (a sphere:
    /// not reproduced exactly, so this checks the derivative weights, not the field).
    #[test]
    fn gradient_matches_finite_differences() {
        let b = baked(Arc::new(Sphere { radius: 0.6 }), 12);
        let mut rng = irmirror_geom::rng::seeded(4, 0);
        for _ in 0..300 {
            use rand::Rng;
            let p = Vector3::from_fn(|_, _| rng.random_range(-0.55..=0.55));
            let g = b.gradient(&p);
            let h = 1e-6;
            let fd = Vector3::from_fn(|k, _| {
                let e = Vector3::from_fn(|i, _| if i == k { h } else { 0.0 });
                (b.distance(&(p + e)) - b.distance(&(p - e))) / (2.0 * h)
            });
            assert!((g - fd).norm() < 1e-6, "{p:?}: {g:?} vs {fd:?}");
        }
    }

    /// With a band, the original field answers within it (values and gradients exactly) and the
    /// grid beyond it; the grid's error at cell centres bounds what a band must exceed.
    #[test]
    fn within_its_band_the_original_field_answers() {
        let sphere = Sphere { radius: 0.6 };
        let b = baked(Arc::new(sphere), 12);
        let probe = b.cell_centres_near_surface(0.1);
        assert!(!probe.is_empty());
        assert!(probe.iter().all(|p| (p.norm() - 0.6).abs() < 0.2));
        let exact: Vec<f64> = probe.iter().map(|p| sphere.distance(p)).collect();
        let err = b.max_error(&probe, &exact);
        assert!(err > 0.0 && err < 1e-2, "{err}");
        let banded = baked(Arc::new(sphere), 12).with_band(2.0 * err);
        let near = Vector3::new(0.0, 0.6 + err, 0.0);
        assert_eq!(banded.distance(&near), sphere.distance(&near));
        assert_eq!(banded.gradient(&near), sphere.gradient(&near));
        let far = Vector3::new(0.1, 0.2, 0.1);
        assert_eq!(banded.distance(&far), b.distance(&far));
        assert_ne!(banded.distance(&far), sphere.distance(&far));
    }

    #[test]
    fn a_failing_or_short_sampler_is_an_error() {
        let s: Arc<dyn Sdf> = Arc::new(Sphere { radius: 0.5 });
        assert!(BakedSdf::bake(s.clone(), 4, |_| Err::<Vec<f64>, _>("no device")).is_err());
        assert!(BakedSdf::bake(s.clone(), 4, |_| Ok::<_, String>(vec![0.0; 3])).is_err());
        assert!(BakedSdf::bake(s, 4, |ps| Ok::<_, String>(vec![f64::NAN; ps.len()])).is_err());
    }
}
