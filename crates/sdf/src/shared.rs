//! The network for many points that share one latent — the placed fit's inner loop — forward
//! and reverse by hand on nalgebra's matrix products (matrixmultiply's kernels), points in
//! parallel chunks.
//!
//! Why not candle's reverse mode, which the fit used before: on the fit's 1,000 points a step
//! is a few dozen small tensor operations, each allocating its output and dispatching to a
//! thread pool, and their reverse; measured (session 49, 2 cores) about 12 ms a step for ≈ 0.2
//! GFLOP of products. Here a shared latent's columns of the two layers that read the input
//! become a bias every point shares (the input is the point's 3 coordinates, not 35 values),
//! SiLU's derivative is kept from the forward pass, and the reverse computes only the inputs'
//! gradients — the weights are frozen.
//!
//! Layout: activations are `W × n` (a column per point). Layer `k`'s pre-activation
//! `A_k = W_k X_k + b_k`; the reverse, with `G = ∂L/∂A`, is `∂L/∂X_k = W_kᵀ G_k`.

use crate::net::SdfNet;
use irmirror_geom::Real;
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

/// Points per parallel chunk (a chunk's activations, `4 × W × 128` values, stay in cache).
const CHUNK: usize = 128;

/// The frozen network, split and transposed for a shared latent, in `T`.
pub(crate) struct SharedLatentNet<T: Real> {
    latent_dim: usize,
    /// Layer 0's point columns `W × 3`, its latent columns `W × L` (f64: used once per call).
    w0p: DMatrix<T>,
    w0p_t: DMatrix<T>,
    w0z: DMatrix<f64>,
    b0: DVector<f64>,
    w1: DMatrix<T>,
    w1_t: DMatrix<T>,
    b1: DVector<T>,
    /// The skip layer's hidden and point columns `W × (W + 3)`, its latent columns `W × L`.
    w2hp: DMatrix<T>,
    w2hp_t: DMatrix<T>,
    w2z: DMatrix<f64>,
    b2: DVector<f64>,
    w3: DMatrix<T>,
    w3_t: DMatrix<T>,
    b3: DVector<T>,
    /// The output row, as a column `W`.
    w4: DVector<T>,
    b4: T,
}

/// What the reverse pass needs of one chunk's forward pass: SiLU's derivative at each hidden
/// layer's pre-activation (`W × n`).
struct ChunkPass<T: Real> {
    slope: [DMatrix<T>; 4],
}

/// A forward pass over many points, kept for [`SharedLatentNet::backward`].
pub(crate) struct Pass<T: Real> {
    chunks: Vec<ChunkPass<T>>,
}

/// SiLU `a ← silu(a + b)` over one column of pre-activations (`b` the biases), and with
/// `slope` its derivative. f64 (the tests' reference) calls `exp`; f32 (the fit) uses a
/// polynomial `exp` the compiler vectorises — scalar `expf` was a third of the fit's time.
pub(crate) trait Activation: Real {
    /// See the trait.
    fn silu_column(a: &mut [Self], b: &[Self], slope: Option<&mut [Self]>);
}

impl Activation for f64 {
    fn silu_column(a: &mut [f64], b: &[f64], slope: Option<&mut [f64]>) {
        let f = |x: f64| {
            let s = 1.0 / (1.0 + (-x).exp());
            (x * s, s * (1.0 + x * (1.0 - s)))
        };
        match slope {
            Some(d) => {
                for ((a, b), d) in a.iter_mut().zip(b).zip(d) {
                    (*a, *d) = f(*a + b);
                }
            }
            None => a.iter_mut().zip(b).for_each(|(a, b)| *a = f(*a + b).0),
        }
    }
}

/// `e^x` in f32 within 2 ulp on [−87, 87] (clamped there: SiLU needs no more), branch-free:
/// `x = n ln 2 + r`, `|r| ≤ ln 2 / 2`, Taylor to degree 7 of `e^r` (truncation < 1e-8
/// relative), the power of two built in the exponent bits.
#[inline(always)]
fn exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 in two parts: n · LN2_HI is exact for |n| < 2⁸.
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding and subtracting 1.5 · 2²³ rounds to the nearest integer.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 87.0);
    let t = x * LOG2E + ROUND;
    let n = t - ROUND;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r / 5040.0))))));
    // n itself sits in t's low mantissa bits: integer arithmetic only (an `as` cast would
    // saturate element by element and keep the loop from vectorising).
    let biased = t.to_bits().wrapping_sub(ROUND.to_bits()).wrapping_add(127);
    p * f32::from_bits(biased << 23)
}

impl Activation for f32 {
    fn silu_column(a: &mut [f32], b: &[f32], slope: Option<&mut [f32]>) {
        match slope {
            Some(d) => {
                for ((a, b), d) in a.iter_mut().zip(b).zip(d) {
                    let x = *a + b;
                    let s = 1.0 / (1.0 + exp_f32(-x));
                    *a = x * s;
                    *d = s * (1.0 + x * (1.0 - s));
                }
            }
            None => {
                for (a, b) in a.iter_mut().zip(b) {
                    let x = *a + b;
                    *a = x / (1.0 + exp_f32(-x));
                }
            }
        }
    }
}

impl<T: Activation> SharedLatentNet<T> {
    /// The layers of `net`.
    pub(crate) fn new(net: &SdfNet) -> Self {
        let (l, w) = (net.latent_dim, net.width);
        let layer = |k: usize| {
            let (wk, bk) = &net.weights[k];
            let cols = wk.len() / bk.len();
            (DMatrix::from_row_slice(bk.len(), cols, wk), bk)
        };
        let cast = |m: &DMatrix<f64>| m.map(T::of);
        let (m0, b0) = layer(0);
        let (m1, b1) = layer(1);
        let (m2, b2) = layer(2);
        let (m3, b3) = layer(3);
        let (m4, b4) = layer(4);
        let w0p = cast(&m0.columns(l, 3).into_owned());
        let mut w2hp = DMatrix::zeros(w, w + 3);
        w2hp.columns_mut(0, w).copy_from(&m2.columns(0, w));
        w2hp.columns_mut(w, 3).copy_from(&m2.columns(w + l, 3));
        let w2hp = cast(&w2hp);
        let (w1, w3) = (cast(&m1), cast(&m3));
        Self {
            latent_dim: l,
            w0p_t: w0p.transpose(),
            w0p,
            w0z: m0.columns(0, l).into_owned(),
            b0: DVector::from_column_slice(b0),
            w1_t: w1.transpose(),
            w1,
            b1: DVector::from_iterator(w, b1.iter().map(|v| T::of(*v))),
            w2hp_t: w2hp.transpose(),
            w2hp,
            w2z: m2.columns(w, l).into_owned(),
            b2: DVector::from_column_slice(b2),
            w3_t: w3.transpose(),
            w3,
            b3: DVector::from_iterator(w, b3.iter().map(|v| T::of(*v))),
            w4: DVector::from_iterator(w, m4.row(0).iter().map(|v| T::of(*v))),
            b4: T::of(b4[0]),
        }
    }

    /// The latent's share of layers 0 and 2: `b + W_z z`.
    fn shared_biases(&self, z: &[f64]) -> (DVector<T>, DVector<T>) {
        assert_eq!(z.len(), self.latent_dim, "latent length");
        let z = DVector::from_column_slice(z);
        (
            (&self.b0 + &self.w0z * &z).map(T::of),
            (&self.b2 + &self.w2z * &z).map(T::of),
        )
    }

    /// `f(z, q_i)` for every point; with `keep`, the pass [`Self::backward`] needs.
    pub(crate) fn forward(
        &self,
        z: &[f64],
        q: &[Vector3<f64>],
        keep: bool,
    ) -> (Vec<f64>, Option<Pass<T>>) {
        let (c0, c2) = self.shared_biases(z);
        let results: Vec<(Vec<f64>, Option<ChunkPass<T>>)> = q
            .par_chunks(CHUNK)
            .map(|pts| self.forward_chunk(&c0, &c2, pts, keep))
            .collect();
        let values = results
            .iter()
            .flat_map(|(v, _)| v.iter().copied())
            .collect();
        let pass = keep.then(|| Pass {
            chunks: results.into_iter().filter_map(|(_, c)| c).collect(),
        });
        (values, pass)
    }

    fn forward_chunk(
        &self,
        c0: &DVector<T>,
        c2: &DVector<T>,
        pts: &[Vector3<f64>],
        keep: bool,
    ) -> (Vec<f64>, Option<ChunkPass<T>>) {
        let n = pts.len();
        let w = self.w1.nrows();
        let q = DMatrix::from_fn(3, n, |r, c| T::of(pts[c][r]));
        // A = W X + b (bias per row), then H = silu(A) in place; with `keep`, slope = silu'(A).
        let layer = |wk: &DMatrix<T>, x: &DMatrix<T>, b: &DVector<T>| {
            let mut a = DMatrix::zeros(w, n);
            a.gemm(T::one(), wk, x, T::zero());
            let mut slope = DMatrix::zeros(if keep { w } else { 0 }, n);
            let (b, mut cols) = (b.as_slice(), slope.as_mut_slice().chunks_exact_mut(w));
            for col in a.as_mut_slice().chunks_exact_mut(w) {
                T::silu_column(col, b, cols.next());
            }
            (a, slope)
        };
        let (h0, s0) = layer(&self.w0p, &q, c0);
        let (h1, s1) = layer(&self.w1, &h0, &self.b1);
        let mut x2 = DMatrix::zeros(w + 3, n);
        x2.rows_mut(0, w).copy_from(&h1);
        x2.rows_mut(w, 3).copy_from(&q);
        let (h2, s2) = layer(&self.w2hp, &x2, c2);
        let (h3, s3) = layer(&self.w3, &h2, &self.b3);
        let out = h3.tr_mul(&self.w4);
        let values = out.iter().map(|v| (*v + self.b4).to_f64()).collect();
        let pass = keep.then_some(ChunkPass {
            slope: [s0, s1, s2, s3],
        });
        (values, pass)
    }

    /// Given `∂L/∂f_i` per point (in the order of the forward pass), `∂L/∂q_i` per point and
    /// `∂L/∂z`.
    pub(crate) fn backward(&self, pass: &Pass<T>, grad: &[f64]) -> (Vec<Vector3<f64>>, Vec<f64>) {
        assert_eq!(
            grad.len().div_ceil(CHUNK),
            pass.chunks.len(),
            "one gradient per point of the forward pass"
        );
        let parts: Vec<(Vec<Vector3<f64>>, DVector<f64>)> = pass
            .chunks
            .par_iter()
            .zip(grad.par_chunks(CHUNK))
            .map(|(chunk, g)| self.backward_chunk(chunk, g))
            .collect();
        let mut gz = DVector::zeros(self.latent_dim);
        let mut gq = Vec::with_capacity(grad.len());
        for (g, z) in parts {
            gq.extend(g);
            gz += z;
        }
        (gq, gz.as_slice().to_vec())
    }

    fn backward_chunk(&self, c: &ChunkPass<T>, grad: &[f64]) -> (Vec<Vector3<f64>>, DVector<f64>) {
        let (n, w) = (grad.len(), self.w1.nrows());
        let [s0, s1, s2, s3] = &c.slope;
        // G3 = (w4 gᵀ) ⊙ silu'(A3).
        let g3 = DMatrix::from_fn(w, n, |r, col| self.w4[r] * T::of(grad[col]) * s3[(r, col)]);
        let back = |wt: &DMatrix<T>, g: &DMatrix<T>| {
            let mut x = DMatrix::zeros(wt.nrows(), n);
            x.gemm(T::one(), wt, g, T::zero());
            x
        };
        let g2 = back(&self.w3_t, &g3).component_mul(s2);
        let x2 = back(&self.w2hp_t, &g2);
        let g1 = x2.rows(0, w).component_mul(s1);
        let g0 = back(&self.w1_t, &g1).component_mul(s0);
        let gq = back(&self.w0p_t, &g0) + x2.rows(w, 3);
        let row_sums = |g: &DMatrix<T>| {
            DVector::from_iterator(w, g.row_iter().map(|r| r.iter().map(|v| v.to_f64()).sum()))
        };
        let gz = self.w0z.tr_mul(&row_sums(&g0)) + self.w2z.tr_mul(&row_sums(&g2));
        let gq = (0..n)
            .map(|col| Vector3::from_fn(|r, _| gq[(r, col)].to_f64()))
            .collect();
        (gq, gz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::families::Category;
    use crate::net::SdfNet;

    /// Values and both gradients of the split network against the frozen network's own
    /// single-point evaluation (f64, its reverse pass FD-tested in `net`), and the reverse pass
    /// against central differences of the forward.
    #[test]
    fn shared_latent_pass_matches_the_network() {
        let net = SdfNet::builtin(Category::Mug).expect("shipped prior");
        let split = SharedLatentNet::<f64>::new(&net);
        let z: Vec<f64> = net.train_latents[3].clone();
        // 300 points: more than two chunks, the last one partial.
        let q: Vec<Vector3<f64>> = (0..300)
            .map(|i| {
                let t = i as f64 * 0.37;
                Vector3::new(0.6 * t.sin(), 0.5 * (1.3 * t).cos(), 0.4 * (0.7 * t).sin())
            })
            .collect();
        let (values, pass) = split.forward(&z, &q, true);
        let shape = net.shape(&z).expect("latent");
        for (p, v) in q.iter().zip(&values) {
            let (f, _) = shape.value_grad(p);
            assert!((f - v).abs() < 1e-12, "value {v} for {f} at {p:?}");
        }
        // L = Σ a_i f_i: ∂L/∂q_i = a_i ∇f(q_i); ∂L/∂z by central differences.
        let a: Vec<f64> = (0..q.len())
            .map(|i| ((i * 7 % 11) as f64 - 5.0) / 5.0)
            .collect();
        let (gq, gz) = split.backward(&pass.expect("kept"), &a);
        for ((p, g), ai) in q.iter().zip(&gq).zip(&a) {
            let (_, grad) = shape.value_grad(p);
            assert!(
                (g - grad * *ai).norm() < 1e-10,
                "∂q {g:?} for {:?}",
                grad * *ai
            );
        }
        let loss = |z: &[f64]| -> f64 {
            let (v, _) = split.forward(z, &q, false);
            v.iter().zip(&a).map(|(v, a)| v * a).sum()
        };
        for k in [0, 5, 31] {
            let h = 1e-6;
            let (mut zp, mut zm) = (z.clone(), z.clone());
            zp[k] += h;
            zm[k] -= h;
            let fd = (loss(&zp) - loss(&zm)) / (2.0 * h);
            assert!(
                (fd - gz[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "∂z{k} {} for {fd}",
                gz[k]
            );
        }
    }
}

#[cfg(test)]
mod exp_tests {
    use super::*;

    /// The polynomial `exp` within 2 ulp of f64's over SiLU's range, and f32's SiLU and slope
    /// against f64's.
    #[test]
    fn fast_exp_and_silu_match_f64() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -87.0 + 174.0 * f64::from(i) / 200_000.0;
            let (fast, exact) = (f64::from(exp_f32(x as f32)), (x as f32 as f64).exp());
            worst = worst.max(((fast - exact) / exact).abs());
        }
        assert!(
            worst < 2.0 * f64::from(f32::EPSILON),
            "relative error {worst:e}"
        );
        let xs: Vec<f64> = (0..=400).map(|i| -20.0 + 0.1 * f64::from(i)).collect();
        let (mut a64, mut d64) = (xs.clone(), vec![0.0; xs.len()]);
        f64::silu_column(&mut a64, &vec![0.0; xs.len()], Some(&mut d64));
        let mut a32: Vec<f32> = xs.iter().map(|x| *x as f32).collect();
        let mut d32 = vec![0.0f32; xs.len()];
        f32::silu_column(&mut a32, &vec![0.0; xs.len()], Some(&mut d32));
        let mut plain: Vec<f32> = xs.iter().map(|x| *x as f32).collect();
        f32::silu_column(&mut plain, &vec![0.0; xs.len()], None);
        for k in 0..xs.len() {
            let tol = 1e-6 * (1.0 + a64[k].abs());
            assert!(
                (f64::from(a32[k]) - a64[k]).abs() < tol,
                "silu({}) {}",
                xs[k],
                a32[k]
            );
            assert!(
                (f64::from(plain[k]) - a64[k]).abs() < tol,
                "silu({})",
                xs[k]
            );
            assert!(
                (f64::from(d32[k]) - d64[k]).abs() < 1e-6,
                "silu'({}) {}",
                xs[k],
                d32[k]
            );
        }
    }
}
