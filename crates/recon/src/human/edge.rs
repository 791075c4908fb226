//! The pixel distance to the reflection mask's edge, which edge sampling weights rays by.

use irmirror_capture::Image;
use rand::Rng;

/// Per-pixel chamfer distance (3-4, in pixels) to the nearest edge of `mask` (inside or out).
pub fn edge_distance(mask: &Image<bool>) -> Image<f64> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let big = 1e9;
    let mut d = vec![big; w * h];
    for y in 0..h {
        for x in 0..w {
            let m = mask.data[y * w + x];
            let edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|&(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    nx >= 0
                        && ny >= 0
                        && nx < w as i64
                        && ny < h as i64
                        && mask.data[ny as usize * w + nx as usize] != m
                });
            if edge {
                d[y * w + x] = 0.0;
            }
        }
    }
    let pass = |d: &mut Vec<f64>, xs: Vec<usize>, ys: Vec<usize>, offs: [(i64, i64, f64); 4]| {
        for &y in &ys {
            for &x in &xs {
                for (dx, dy, c) in offs {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64 {
                        let v = d[ny as usize * w + nx as usize] + c;
                        if v < d[y * w + x] {
                            d[y * w + x] = v;
                        }
                    }
                }
            }
        }
    };
    let (a, b) = (1.0, std::f64::consts::SQRT_2);
    pass(
        &mut d,
        (0..w).collect(),
        (0..h).collect(),
        [(-1, 0, a), (0, -1, a), (-1, -1, b), (1, -1, b)],
    );
    pass(
        &mut d,
        (0..w).rev().collect(),
        (0..h).rev().collect(),
        [(1, 0, a), (0, 1, a), (1, 1, b), (-1, 1, b)],
    );
    Image {
        width: mask.width,
        height: mask.height,
        data: d,
    }
}

/// Largest relative weight error of the rays [`EdgeSampler::draw`] treats as far from the edge.
const FAR_REL: f64 = 1e-3;

/// Edge sampling's draw: `m` of `n` rays without replacement, ray `i` with weight
/// `(1 − α) + α exp(−e_i/τ)` (Efraimidis–Spirakis: the `m` largest keys `ln(u_i) / w_i`).
///
/// `O(band + m)` per draw rather than `O(n)`: rays far from the edge (`α exp(−e/τ)` below
/// [`FAR_REL`] × `(1 − α)`, or below 1e-9 when `α` is near 1) all weigh `1 − α` to within that
/// relative error (a 0.1 % weight is invisible in a draw of thousands; the band is 2–5×
/// smaller than at 1e-9), so their keys are treated as i.i.d.; the largest of them are
/// generated in decreasing order as order statistics of uniforms (`U₍₁₎ = V₁^{1/n}`,
/// `U₍ₖ₊₁₎ = U₍ₖ₎ V^{1/(n−k)}`) and given to a uniform random subset of them, while the band
/// near the edge gets explicit keys. A 640×512 capture has up to 300,000
/// object rays; the plain draw over all of them was a third of stage 2's time.
pub struct EdgeSampler {
    /// Ray indices sorted by edge distance, ascending.
    order: Vec<usize>,
    /// Edge distances in that order.
    e_sorted: Vec<f64>,
    keys: Vec<(f64, usize)>,
}

impl EdgeSampler {
    /// A sampler for rays with edge distances `e` (pixels).
    pub fn new(e: &[f64]) -> Self {
        let mut order: Vec<usize> = (0..e.len()).collect();
        order.sort_by(|&a, &b| e[a].total_cmp(&e[b]).then(a.cmp(&b)));
        let e_sorted = order.iter().map(|&i| e[i]).collect();
        Self {
            order,
            e_sorted,
            keys: Vec::new(),
        }
    }

    /// Writes the drawn ray indices (sorted) into `out`.
    pub fn draw(
        &mut self,
        alpha: f64,
        tau: f64,
        m: usize,
        rng: &mut impl Rng,
        out: &mut Vec<usize>,
    ) {
        let n = self.order.len();
        out.clear();
        if m >= n {
            out.extend(0..n);
            return;
        }
        let w_far = 1.0 - alpha;
        // The band: rays whose edge term is not negligible next to the far weight.
        let band = if alpha > 0.0 {
            let e_cut = tau * (alpha / (FAR_REL * w_far).max(1e-9)).ln().max(0.0);
            self.e_sorted.partition_point(|&e| e < e_cut)
        } else {
            0
        };
        self.keys.clear();
        for k in 0..band {
            let w = w_far + alpha * (-self.e_sorted[k] / tau).exp();
            let u: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
            self.keys.push((u.ln() / w, k));
        }
        self.keys
            .sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        // Merge with the far rays' keys, generated largest first.
        let n_far = if w_far > 1e-12 { n - band } else { 0 };
        let (mut from_band, mut from_far) = (0usize, 0usize);
        let mut log_u = 0.0; // ln U₍ₖ₎ of the far keys so far (U₍₀₎ = 1)
        let next_far = |k: usize, log_u: &mut f64, rng: &mut dyn rand::RngCore| -> f64 {
            let v: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
            *log_u += v.ln() / (n_far - k) as f64;
            *log_u / w_far
        };
        let mut far_key = if n_far > 0 {
            next_far(0, &mut log_u, rng)
        } else {
            f64::NEG_INFINITY
        };
        while from_band + from_far < m {
            let band_key = self.keys.get(from_band).map_or(f64::NEG_INFINITY, |k| k.0);
            if band_key >= far_key && from_band < self.keys.len() {
                out.push(self.order[self.keys[from_band].1]);
                from_band += 1;
            } else if from_far < n_far {
                from_far += 1;
                far_key = if from_far < n_far {
                    next_far(from_far, &mut log_u, rng)
                } else {
                    f64::NEG_INFINITY
                };
            } else {
                break;
            }
        }
        // Which far rays: a uniform subset of the far group.
        if from_far > 0 {
            out.extend(
                rand::seq::index::sample(rng, n_far, from_far)
                    .into_iter()
                    .map(|j| self.order[band + j]),
            );
        }
        out.sort_unstable();
    }
}

/// Edge sampling's curriculum as weights: `base_i · ((1 − α) + α exp(−e_i/τ))` (`base` 1
/// where `None`), what a draw with those probabilities weighs each ray by in expectation.
pub fn curriculum_weights(
    base: Option<&[f64]>,
    edge_px: &[f64],
    alpha: f64,
    tau: f64,
    out: &mut Vec<f64>,
) {
    out.clear();
    out.extend(edge_px.iter().enumerate().map(|(i, e)| {
        base.map_or(1.0, |w| w[i]) * ((1.0 - alpha) + alpha * (-e / tau.max(1e-9)).exp())
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain Efraimidis–Spirakis draw over every ray (what `EdgeSampler` replaces).
    fn plain(e: &[f64], alpha: f64, tau: f64, m: usize, rng: &mut impl Rng) -> Vec<usize> {
        let mut keys: Vec<(f64, usize)> = e
            .iter()
            .enumerate()
            .map(|(i, &e)| {
                let w = (1.0 - alpha) + alpha * (-e / tau).exp();
                let u: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
                (u.ln() / w, i)
            })
            .collect();
        keys.sort_by(|a, b| b.0.total_cmp(&a.0));
        keys.iter().take(m).map(|k| k.1).collect()
    }

    /// Inclusion frequencies of the fast draw match the plain draw's (a band of edge rays and
    /// many far ones; 20,000 draws each), draws are distinct and sorted, and α = 0 is uniform.
    #[test]
    fn edge_sampler_matches_the_plain_draw() {
        let n = 400;
        // 40 rays on or near the edge, the rest far away (e up to 300 px).
        let e: Vec<f64> = (0..n)
            .map(|i| {
                if i < 40 {
                    i as f64 * 0.25
                } else {
                    30.0 + i as f64 * 0.7
                }
            })
            .collect();
        let (m, draws) = (30, 20_000);
        for (alpha, tau) in [(0.9, 1.5), (0.5, 6.0), (0.0, 1.0)] {
            let mut fast = EdgeSampler::new(&e);
            let (mut f_count, mut p_count) = (vec![0u32; n], vec![0u32; n]);
            let mut rng = irmirror_geom::rng::seeded(5, 1);
            let mut out = Vec::new();
            for _ in 0..draws {
                fast.draw(alpha, tau, m, &mut rng, &mut out);
                assert_eq!(out.len(), m);
                assert!(out.windows(2).all(|w| w[0] < w[1]), "sorted, distinct");
                out.iter().for_each(|&i| f_count[i] += 1);
                plain(&e, alpha, tau, m, &mut rng)
                    .iter()
                    .for_each(|&i| p_count[i] += 1);
            }
            // Compare in groups of 10 rays (binomial noise per group ≲ 1 %).
            for g in 0..n / 10 {
                let f: u32 = f_count[g * 10..g * 10 + 10].iter().sum();
                let p: u32 = p_count[g * 10..g * 10 + 10].iter().sum();
                let (f, p) = (f64::from(f) / draws as f64, f64::from(p) / draws as f64);
                let sd = (p.max(0.01) / draws as f64).sqrt() * 10f64.sqrt();
                assert!(
                    (f - p).abs() < 5.0 * sd + 1e-3,
                    "α {alpha}, τ {tau}, rays {}..{}: {f:.4} vs {p:.4}",
                    g * 10,
                    g * 10 + 10
                );
            }
        }
    }

    /// The curriculum's weights: the base weights at α = 0; at α = 0.9, τ = 1.5 px an edge ray
    /// keeps its base weight, one far from the edge a tenth of it, one 1.5 px out 0.1 + 0.9/e;
    /// a missing base counts as 1.
    #[test]
    fn curriculum_weights_follow_the_edge_schedule() {
        let (base, edge) = ([2.0, 3.0, 4.0], [0.0, 1.5, 100.0]);
        let mut w = Vec::new();
        curriculum_weights(Some(&base), &edge, 0.0, 1.5, &mut w);
        assert_eq!(w, base);
        curriculum_weights(Some(&base), &edge, 0.9, 1.5, &mut w);
        let expect = [2.0, 3.0 * (0.1 + 0.9 / std::f64::consts::E), 0.4];
        for (a, b) in w.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        curriculum_weights(None, &edge, 0.9, 1.5, &mut w);
        assert!(
            (w[0] - 1.0).abs() < 1e-12 && (w[2] - 0.1).abs() < 1e-12,
            "{w:?}"
        );
    }
}
