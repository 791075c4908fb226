//! The optimiser every hand-written-gradient fit uses (stage 1's family fit, the learned
//! prior's placed fit, stage 2), and the learning-rate schedule every fit and training loop
//! uses.
//!
//! * [`Adam`] (Kingma & Ba 2015) over a flat `f64` parameter vector with one learning rate per
//!   parameter, so groups (rotation, translation, scale, shape, latent) each get their own. It
//!   returns the step and leaves applying it to the caller: parameters such as a rotation are
//!   updated on their manifold (`R ← exp(−δ) R`), not by subtraction.
//! * [`CosineDecay`]: the learning-rate factor `floor + (1 − floor) · ½ (1 + cos πp)` at progress
//!   `p ∈ [0, 1]`.
//! * [`levenberg_marquardt`]: small dense nonlinear least squares with a caller-supplied
//!   Jacobian and retraction (camera calibration's bundle adjustment).
//!
//! The candle training loops of the shipped priors (`irmirror-sdf::train`,
//! `irmirror-body::prior::train`) step their tensors with candle's `AdamW` (weight decay 0: Adam)
//! under this schedule: the shipped weights are byte-for-byte what their commands make, and they
//! were made with it.

/// Adam's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// Decay of the first moment.
    pub beta1: f64,
    /// Decay of the second moment.
    pub beta2: f64,
    /// Added to `√v̂` (sets the smallest gradient scale that still takes a full step).
    pub eps: f64,
}

impl Default for AdamParams {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-10,
        }
    }
}

/// Adam state over a flat parameter vector.
#[derive(Clone, Debug)]
pub struct Adam {
    params: AdamParams,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    /// Fresh state (moments zero) for `n` parameters.
    pub fn new(n: usize, params: AdamParams) -> Self {
        Self {
            params,
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.m.len()
    }

    /// Whether there are no parameters.
    pub fn is_empty(&self) -> bool {
        self.m.is_empty()
    }

    /// Updates the moments with `grad` and writes the step `lr[k] · scale · m̂ / (√v̂ + ε)` into
    /// `step` (to be subtracted). `lr` holds one rate per parameter; `scale` is the schedule's
    /// factor. All slices have [`Adam::len`] elements.
    pub fn step(&mut self, grad: &[f64], lr: &[f64], scale: f64, step: &mut [f64]) {
        assert!(
            grad.len() == self.len() && lr.len() == self.len() && step.len() == self.len(),
            "Adam::step: slices of {}, {}, {} for {} parameters",
            grad.len(),
            lr.len(),
            step.len(),
            self.len()
        );
        self.t += 1;
        let AdamParams { beta1, beta2, eps } = self.params;
        let (c1, c2) = (1.0 - beta1.powi(self.t), 1.0 - beta2.powi(self.t));
        for k in 0..grad.len() {
            let g = grad[k];
            self.m[k] = beta1 * self.m[k] + (1.0 - beta1) * g;
            self.v[k] = beta2 * self.v[k] + (1.0 - beta2) * g * g;
            let (mh, vh) = (self.m[k] / c1, self.v[k] / c2);
            step[k] = lr[k] * scale * mh / (vh.sqrt() + eps);
        }
    }
}

/// Cosine learning-rate decay from 1 to `floor`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CosineDecay {
    /// The factor at the end, as a fraction of the initial rate.
    pub floor: f64,
}

impl CosineDecay {
    /// The factor at `progress ∈ [0, 1]` (1 at 0, `floor` at 1).
    pub fn at(&self, progress: f64) -> f64 {
        self.of_angle(std::f64::consts::PI * progress)
    }

    /// The factor before step `step` of `steps` (1 at the first step; `floor` is reached one
    /// step after the last).
    pub fn at_step(&self, step: usize, steps: usize) -> f64 {
        self.of_angle(std::f64::consts::PI * step as f64 / steps.max(1) as f64)
    }

    fn of_angle(&self, angle_rad: f64) -> f64 {
        self.floor + (1.0 - self.floor) * 0.5 * (1.0 + angle_rad.cos())
    }
}

/// Settings of [`levenberg_marquardt`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmParams {
    /// Most iterations (accepted or rejected steps).
    pub max_iterations: usize,
    /// Initial damping, relative to the mean diagonal of `JᵀJ`.
    pub initial_damping: f64,
    /// Stop when a step lowers the cost by less than this fraction.
    pub relative_tolerance: f64,
}

impl Default for LmParams {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            initial_damping: 1e-3,
            relative_tolerance: 1e-12,
        }
    }
}

/// What [`levenberg_marquardt`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmReport {
    /// ½‖r‖² at the start.
    pub initial_cost: f64,
    /// ½‖r‖² at the end.
    pub final_cost: f64,
    /// Iterations run.
    pub iterations: usize,
}

/// Minimises `½‖r(x)‖²` by Levenberg–Marquardt (Marquardt's diagonal scaling) over a state the
/// caller owns. `eval(state, r, j)` fills the `m` residuals and, when `j` is given, the
/// row-major `m × n` Jacobian with respect to the local increment; `retract(state, δ)` returns
/// the state moved by the increment `δ` (so rotations stay on their manifold). Dense normal
/// equations: meant for at most a few hundred parameters.
pub fn levenberg_marquardt<S: Clone>(
    state: &mut S,
    n: usize,
    m: usize,
    params: LmParams,
    eval: impl Fn(&S, &mut [f64], Option<&mut [f64]>),
    retract: impl Fn(&S, &[f64]) -> S,
) -> LmReport {
    use nalgebra::{DMatrix, DVector};
    let (mut r, mut j) = (vec![0.0; m], vec![0.0; m * n]);
    let cost = |r: &[f64]| 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    eval(state, &mut r, Some(&mut j));
    let initial_cost = cost(&r);
    let mut current = initial_cost;
    let mut lambda = f64::NAN;
    let mut trial_r = vec![0.0; m];
    let mut iterations = 0;
    while iterations < params.max_iterations {
        iterations += 1;
        let jm = DMatrix::from_row_slice(m, n, &j);
        let jtj = jm.transpose() * &jm;
        let g = jm.transpose() * DVector::from_column_slice(&r);
        if lambda.is_nan() {
            lambda = params.initial_damping * (jtj.trace() / n.max(1) as f64).max(1e-300);
        }
        let mut a = jtj.clone();
        for k in 0..n {
            a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
        }
        let Some(chol) = a.cholesky() else {
            lambda *= 10.0;
            continue;
        };
        let delta = -chol.solve(&g);
        let trial = retract(state, delta.as_slice());
        eval(&trial, &mut trial_r, None);
        let c = cost(&trial_r);
        if c.is_finite() && c < current {
            let gain = (current - c) / current.max(1e-300);
            *state = trial;
            current = c;
            eval(state, &mut r, Some(&mut j));
            lambda = (lambda / 3.0).max(1e-15);
            if gain < params.relative_tolerance {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    LmReport {
        initial_cost,
        final_cost: current,
        iterations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levenberg_marquardt_fits_an_exponential_from_far_away() {
        // y = a · exp(b · t) sampled without noise; start at (1, 0).
        let (a, b) = (2.5, -1.3);
        let ts: Vec<f64> = (0..20).map(|i| i as f64 * 0.2).collect();
        let ys: Vec<f64> = ts.iter().map(|t| a * (b * t).exp()).collect();
        let mut x = [1.0, 0.0];
        let rep = levenberg_marquardt(
            &mut x,
            2,
            ts.len(),
            LmParams::default(),
            |x, r, j| {
                for (i, t) in ts.iter().enumerate() {
                    let e = (x[1] * t).exp();
                    r[i] = x[0] * e - ys[i];
                }
                if let Some(j) = j {
                    for (i, t) in ts.iter().enumerate() {
                        let e = (x[1] * t).exp();
                        j[2 * i] = e;
                        j[2 * i + 1] = x[0] * t * e;
                    }
                }
            },
            |x, d| [x[0] + d[0], x[1] + d[1]],
        );
        assert!(
            (x[0] - a).abs() < 1e-8 && (x[1] - b).abs() < 1e-8,
            "{x:?} {rep:?}"
        );
        assert!(rep.final_cost < 1e-16 && rep.initial_cost > 1.0, "{rep:?}");
    }

    #[test]
    fn adam_minimises_a_quadratic_with_group_rates() {
        // f = ½ Σ a_k (x_k − c_k)², badly scaled: Adam's steps are scale-free.
        let (a, c) = ([100.0, 1.0, 0.01], [1.0, -2.0, 3.0]);
        let mut x = [0.0; 3];
        let mut adam = Adam::new(3, AdamParams::default());
        let (mut g, mut s) = ([0.0; 3], [0.0; 3]);
        let schedule = CosineDecay { floor: 0.01 };
        for it in 0..2000 {
            for k in 0..3 {
                g[k] = a[k] * (x[k] - c[k]);
            }
            adam.step(&g, &[0.05, 0.05, 0.1], schedule.at_step(it, 2000), &mut s);
            for k in 0..3 {
                x[k] -= s[k];
            }
        }
        for k in 0..3 {
            assert!((x[k] - c[k]).abs() < 1e-3, "x = {x:?}");
        }
    }

    #[test]
    fn the_first_step_has_the_learning_rate_as_its_size() {
        // m̂ = g, v̂ = g² after one step: the step is lr · sign(g) (up to ε).
        let mut adam = Adam::new(2, AdamParams::default());
        let mut s = [0.0; 2];
        adam.step(&[3.0, -1e-3], &[0.1, 0.2], 0.5, &mut s);
        assert!(
            (s[0] - 0.05).abs() < 1e-9 && (s[1] + 0.1).abs() < 1e-6,
            "{s:?}"
        );
    }

    #[test]
    fn cosine_decay_ends_at_its_floor() {
        let d = CosineDecay { floor: 0.05 };
        assert_eq!(d.at(0.0), 1.0);
        assert!((d.at(1.0) - 0.05).abs() < 1e-15);
        assert!((d.at(0.5) - 0.525).abs() < 1e-15);
        assert_eq!(d.at_step(0, 10), 1.0);
        assert_eq!(
            d.at_step(5, 10),
            d.of_angle(std::f64::consts::PI * 5.0 / 10.0)
        );
        // The floor's complement is exact for the floors in use, so the factor matches the
        // literal forms it replaced (`0.05 + 0.95 · …`, `0.1 + 0.9 · …`).
        assert_eq!(1.0 - 0.05, 0.95);
        assert_eq!(1.0 - 0.1, 0.9);
    }
}
