//! Rotation parameterisations and their vector–Jacobian products (VJPs).
//!
//! | input | shape | convention |
//! |---|---|---|
//! | axis-angle (rotation vector) | 3 | axis · angle, radians; `R = exp([w]×)` (Rodrigues) |
//! | 6-D (Zhou et al. 2019) | 6 | the first two *columns* of R before Gram–Schmidt: `(a1, a2)` |
//!
//! Each forward has its VJP beside it: given `g = ∂L/∂R` (3×3) it returns `∂L/∂input`. Both are
//! finite at the singular points (zero angle; zero or parallel 6-D columns).

use crate::Real;
use nalgebra::{Matrix3, Vector3, Vector6};

/// Below this angle (radians) the Rodrigues coefficients use their Taylor series.
const SMALL_ANGLE: f64 = 0.05;

/// `[w]×`, the cross-product matrix: `[w]× v = w × v`.
#[inline]
pub fn skew<T: Real>(w: &Vector3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(z, -w.z, w.y, w.z, z, -w.x, -w.y, w.x, z)
}

/// Rodrigues coefficients `(a, b, a'/θ, b'/θ)` of `R = I + a K + b K²`, `K = [w]×`, where
/// `a = sinθ/θ`, `b = (1 − cosθ)/θ²`, and the primes are derivatives in θ.
fn rodrigues_coefficients<T: Real>(theta2: T) -> (T, T, T, T) {
    let theta = theta2.sqrt();
    if theta.to_f64() < SMALL_ANGLE {
        let t2 = theta2;
        let t4 = t2 * t2;
        let c = |x: f64| T::of(x);
        (
            T::one() - t2 / c(6.0) + t4 / c(120.0),
            c(0.5) - t2 / c(24.0) + t4 / c(720.0),
            c(-1.0 / 3.0) + t2 / c(30.0) - t4 / c(840.0),
            c(-1.0 / 12.0) + t2 / c(180.0) - t4 / c(6720.0),
        )
    } else {
        let (s, co) = (theta.sin(), theta.cos());
        let a = s / theta;
        let b = (T::one() - co) / theta2;
        let da = (theta * co - s) / (theta2 * theta);
        let db = (theta * s - (T::one() + T::one()) * (T::one() - co)) / (theta2 * theta2);
        (a, b, da, db)
    }
}

/// Rotation matrix of a rotation vector (axis · angle, radians).
pub fn axis_angle_to_matrix<T: Real>(w: &Vector3<T>) -> Matrix3<T> {
    let (a, b, _, _) = rodrigues_coefficients(w.norm_squared());
    let k = skew(w);
    Matrix3::identity() + k * a + k * k * b
}

/// VJP of [`axis_angle_to_matrix`]: `∂L/∂w` from `g = ∂L/∂R`.
pub fn axis_angle_to_matrix_vjp<T: Real>(w: &Vector3<T>, g: &Matrix3<T>) -> Vector3<T> {
    let (a, b, ca, cb) = rodrigues_coefficients(w.norm_squared());
    let k = skew(w);
    let k2 = k * k;
    // ⟨g, ∂R/∂w_i⟩ = ca w_i ⟨g,K⟩ + a ⟨g,E_i⟩ + cb w_i ⟨g,K²⟩ + b ⟨g, E_i K + K E_i⟩.
    let gk = g.dot(&k);
    let gk2 = g.dot(&k2);
    // ⟨g, E_i M⟩ = ⟨E_iᵀ g, M⟩ … summed, ⟨g, E_i K + K E_i⟩ = ⟨g Kᵀ + Kᵀ g, E_i⟩.
    let m = g * a + (g * k.transpose() + k.transpose() * g) * b;
    let mut out = Vector3::zeros();
    for i in 0..3 {
        let mut e = Vector3::zeros();
        e[i] = T::one();
        out[i] = w[i] * (ca * gk + cb * gk2) + m.dot(&skew(&e));
    }
    out
}

/// Rotation vector of a rotation matrix (inverse of [`axis_angle_to_matrix`], angle in [0, π]).
pub fn matrix_to_axis_angle<T: Real>(r: &Matrix3<T>) -> Vector3<T> {
    let two = T::one() + T::one();
    let cos = ((r.trace() - T::one()) / two).clamp(-T::one(), T::one());
    let theta = cos.acos();
    let v = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    );
    if theta.to_f64() < 1e-6 {
        return v / two;
    }
    if std::f64::consts::PI - theta.to_f64() < 1e-3 {
        // Near π the antisymmetric part vanishes: take the axis from the symmetric part.
        let s = (r + r.transpose()) / two - Matrix3::identity() * cos;
        let (mut best, mut norm) = (0, T::zero());
        for c in 0..3 {
            let n = s.column(c).norm();
            if n > norm {
                (best, norm) = (c, n);
            }
        }
        let mut axis: Vector3<T> = s.column(best).into_owned() / norm;
        if axis.dot(&v) < T::zero() {
            axis = -axis;
        }
        return axis * theta;
    }
    v * (theta / (two * theta.sin()))
}

/// Rotation matrix of a 6-D rotation `(a1, a2)` (first two columns before Gram–Schmidt).
pub fn sixd_to_matrix<T: Real>(x: &Vector6<T>) -> Matrix3<T> {
    let (b1, b2, b3, ..) = sixd_parts(x);
    Matrix3::from_columns(&[b1, b2, b3])
}

/// Intermediates of the 6-D map: `(b1, b2, b3, n1, n2, a2)`.
#[allow(clippy::type_complexity)]
fn sixd_parts<T: Real>(x: &Vector6<T>) -> (Vector3<T>, Vector3<T>, Vector3<T>, T, T, Vector3<T>) {
    // A tiny floor keeps degenerate inputs (zero or parallel columns) finite.
    let tiny = T::eps() * T::eps();
    let a1 = Vector3::new(x[0], x[1], x[2]);
    let a2 = Vector3::new(x[3], x[4], x[5]);
    let n1 = (a1.norm_squared() + tiny).sqrt();
    let b1 = a1 / n1;
    let u = a2 - b1 * b1.dot(&a2);
    let n2 = (u.norm_squared() + tiny).sqrt();
    let b2 = u / n2;
    (b1, b2, b1.cross(&b2), n1, n2, a2)
}

/// VJP of [`sixd_to_matrix`]: `∂L/∂x` from `g = ∂L/∂R`.
pub fn sixd_to_matrix_vjp<T: Real>(x: &Vector6<T>, g: &Matrix3<T>) -> Vector6<T> {
    let (b1, b2, _b3, n1, n2, a2) = sixd_parts(x);
    let mut gb1: Vector3<T> = g.column(0).into_owned();
    let mut gb2: Vector3<T> = g.column(1).into_owned();
    let gb3: Vector3<T> = g.column(2).into_owned();
    // b3 = b1 × b2.
    gb1 += b2.cross(&gb3);
    gb2 += gb3.cross(&b1);
    // b2 = u / |u|.
    let gu = (gb2 - b2 * b2.dot(&gb2)) / n2;
    // u = a2 − (b1·a2) b1.
    let ga2 = gu - b1 * b1.dot(&gu);
    gb1 -= gu * b1.dot(&a2) + a2 * b1.dot(&gu);
    // b1 = a1 / |a1|.
    let ga1 = (gb1 - b1 * b1.dot(&gb1)) / n1;
    Vector6::new(ga1.x, ga1.y, ga1.z, ga2.x, ga2.y, ga2.z)
}

/// The 6-D representation of a rotation matrix (its first two columns).
pub fn matrix_to_sixd<T: Real>(r: &Matrix3<T>) -> Vector6<T> {
    Vector6::new(
        r[(0, 0)],
        r[(1, 0)],
        r[(2, 0)],
        r[(0, 1)],
        r[(1, 1)],
        r[(2, 1)],
    )
}

/// Elementary rotation about +Y (used for Blender bone roll): `[[c,0,s],[0,1,0],[−s,0,c]]`.
pub fn rot_y<T: Real>(angle: T) -> Matrix3<T> {
    let (s, c) = (angle.sin(), angle.cos());
    let (z, o) = (T::zero(), T::one());
    Matrix3::new(c, z, s, z, o, z, -s, z, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central-difference check of a VJP: ⟨g, ∂R/∂x_i⟩ against (L(x+h) − L(x−h)) / 2h.
    fn fd_check<const N: usize>(
        f: impl Fn(&[f64; N]) -> Matrix3<f64>,
        vjp: impl Fn(&[f64; N], &Matrix3<f64>) -> [f64; N],
        x: [f64; N],
        tol: f64,
    ) {
        let g = Matrix3::new(0.3, -1.2, 0.7, 0.25, 0.9, -0.4, 1.1, -0.6, 0.15);
        let analytic = vjp(&x, &g);
        let h = 1e-6;
        for i in 0..N {
            let (mut xp, mut xm) = (x, x);
            xp[i] += h;
            xm[i] -= h;
            let fd = (f(&xp).dot(&g) - f(&xm).dot(&g)) / (2.0 * h);
            assert!(
                (fd - analytic[i]).abs() < tol * (1.0 + fd.abs()),
                "component {i}: fd {fd} vs analytic {}",
                analytic[i]
            );
        }
    }

    fn aa(x: &[f64; 3]) -> Matrix3<f64> {
        axis_angle_to_matrix(&Vector3::from(*x))
    }
    fn aa_vjp(x: &[f64; 3], g: &Matrix3<f64>) -> [f64; 3] {
        axis_angle_to_matrix_vjp(&Vector3::from(*x), g).into()
    }

    #[test]
    fn axis_angle_vjp_matches_finite_differences() {
        // Generic angles, one just above and one just below the Taylor switch (both branches are
        // smooth there), and a tiny angle (the θ → 0 limit).
        for x in [
            [0.3, -0.8, 1.1],
            [0.03, 0.03, -0.028],
            [0.02, -0.03, 0.01],
            [1e-7, 0.0, -2e-7],
            [2.9, 0.4, -0.2],
        ] {
            fd_check(aa, aa_vjp, x, 1e-7);
        }
    }

    #[test]
    fn axis_angle_is_a_rotation_and_round_trips() {
        for x in [
            [0.3, -0.8, 1.1],
            [1e-9, 0.0, 0.0],
            [0.0, 3.1, 0.0],
            [0.04, 0.0, 0.0],
            [0.0, 0.0, 0.0],
        ] {
            let w: Vector3<f64> = Vector3::from(x);
            let r = axis_angle_to_matrix(&w);
            assert!((r.transpose() * r - Matrix3::identity()).abs().max() < 1e-14);
            assert!((r.determinant() - 1.0).abs() < 1e-14);
            assert!((matrix_to_axis_angle(&r) - w).norm() < 1e-7, "{x:?}");
        }
        // Closed form: a quarter turn about Z takes X to Y.
        let r = axis_angle_to_matrix(&Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2));
        assert!((r * Vector3::x() - Vector3::y()).norm() < 1e-15);
    }

    fn sd(x: &[f64; 6]) -> Matrix3<f64> {
        sixd_to_matrix(&Vector6::from_row_slice(x))
    }
    fn sd_vjp(x: &[f64; 6], g: &Matrix3<f64>) -> [f64; 6] {
        let v = sixd_to_matrix_vjp(&Vector6::from_row_slice(x), g);
        std::array::from_fn(|i| v[i])
    }

    #[test]
    fn sixd_vjp_matches_finite_differences() {
        // Generic, non-orthogonal, non-unit columns (a smooth point of Gram–Schmidt).
        fd_check(sd, sd_vjp, [1.2, 0.3, -0.4, 0.2, 0.9, 0.5], 1e-7);
        fd_check(sd, sd_vjp, [0.1, -2.0, 0.3, 1.5, 0.2, 0.1], 1e-7);
    }

    #[test]
    fn sixd_degenerate_inputs_stay_finite() {
        let g = Matrix3::from_element(1.0);
        for x in [[0.0; 6], [1.0, 0.0, 0.0, 2.0, 0.0, 0.0]] {
            let v: Vector6<f64> = Vector6::from_row_slice(&x);
            assert!(sixd_to_matrix::<f64>(&v).iter().all(|a| a.is_finite()));
            assert!(
                sixd_to_matrix_vjp::<f64>(&v, &g)
                    .iter()
                    .all(|a| a.is_finite())
            );
        }
        let r = axis_angle_to_matrix(&Vector3::new(0.4, -1.0, 0.2));
        assert!((sixd_to_matrix(&matrix_to_sixd(&r)) - r).abs().max() < 1e-14);
    }
}
