//! Evaluation metrics (DESIGN.md §5), shared by `demo` and `eval`.

use nalgebra::DVector;

/// The paper's normalised keypoint distance: each point set (2-D or 3-D, same order) is centred
/// on its mean and divided by its RMS distance from it; the result is the mean Euclidean
/// distance between corresponding normalised points. `None` for fewer than 2 points or a
/// degenerate set.
pub fn normalised_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> Option<f64> {
    if a.len() != b.len() || a.len() < 2 {
        return None;
    }
    let norm = |s: &[Vec<f64>]| -> Option<Vec<DVector<f64>>> {
        let pts: Vec<DVector<f64>> = s.iter().map(|p| DVector::from_vec(p.clone())).collect();
        let mean = pts.iter().fold(DVector::zeros(pts[0].len()), |m, p| m + p) / pts.len() as f64;
        let rms =
            (pts.iter().map(|p| (p - &mean).norm_squared()).sum::<f64>() / pts.len() as f64).sqrt();
        (rms > 1e-12).then(|| pts.iter().map(|p| (p - &mean) / rms).collect())
    };
    let (na, nb) = (norm(a)?, norm(b)?);
    Some(na.iter().zip(&nb).map(|(x, y)| (x - y).norm()).sum::<f64>() / na.len() as f64)
}

/// Mean per-joint position error (same units as the input).
pub fn mpjpe(a: &[Vec<f64>], b: &[Vec<f64>]) -> Option<f64> {
    if a.len() != b.len() || a.is_empty() {
        return None;
    }
    Some(
        a.iter()
            .zip(b)
            .map(|(x, y)| {
                x.iter()
                    .zip(y)
                    .map(|(u, v)| (u - v).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum::<f64>()
            / a.len() as f64,
    )
}

/// MPJPE after the best similarity alignment of `a` onto `b` (Procrustes with scale, Umeyama),
/// 3-D points. `None` for fewer than 3 points or degenerate sets.
pub fn pa_mpjpe(a: &[Vec<f64>], b: &[Vec<f64>]) -> Option<f64> {
    if a.iter().chain(b).any(|p| p.len() != 3) {
        return None;
    }
    let v = |p: &Vec<f64>| nalgebra::Vector3::new(p[0], p[1], p[2]);
    let (va, vb): (Vec<_>, Vec<_>) = (a.iter().map(v).collect(), b.iter().map(v).collect());
    let s = irmirror_geom::transform::Similarity3::umeyama(&va, &vb, true)?;
    let aligned: Vec<Vec<f64>> = va
        .iter()
        .map(|x| {
            let p = s.transform_point(x);
            vec![p.x, p.y, p.z]
        })
        .collect();
    mpjpe(&aligned, b)
}

/// Mean and half-width of the 95 % confidence interval of the mean (Student t; 0 for one value).
pub fn mean_ci95(x: &[f64]) -> Option<(f64, f64)> {
    if x.is_empty() {
        return None;
    }
    let n = x.len();
    let m = x.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return Some((m, 0.0));
    }
    let sd = (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    // Two-sided 97.5 % quantiles of Student's t for 1…30 degrees of freedom, then normal.
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    let t = T.get(n - 2).copied().unwrap_or(1.96);
    Some((m, t * sd / (n as f64).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn procrustes_removes_similarity_and_keeps_shape_differences() {
        let a = pts();
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 1.1);
        let b: Vec<Vec<f64>> = a
            .iter()
            .map(|p| {
                let q = rot * nalgebra::Vector3::new(p[0], p[1], p[2]) * 2.5
                    + nalgebra::Vector3::new(1.0, -2.0, 0.5);
                vec![q.x, q.y, q.z]
            })
            .collect();
        assert!(pa_mpjpe(&a, &b).unwrap() < 1e-9);
        assert!(mpjpe(&a, &b).unwrap() > 0.5);
        // A genuine shape change survives the alignment.
        let mut c = b.clone();
        c[0][0] += 1.0;
        assert!(pa_mpjpe(&a, &c).unwrap() > 0.05);
    }

    #[test]
    fn confidence_interval_of_known_samples() {
        let (m, h) = mean_ci95(&[1.0, 2.0, 3.0]).unwrap();
        assert!((m - 2.0).abs() < 1e-12);
        // sd 1, n 3, t(2) = 4.303.
        assert!((h - 4.303 / 3f64.sqrt()).abs() < 1e-9);
        assert_eq!(mean_ci95(&[5.0]), Some((5.0, 0.0)));
        assert_eq!(mean_ci95(&[]), None);
    }

    fn pts() -> Vec<Vec<f64>> {
        vec![
            vec![0.0, 0.0, 0.0],
            vec![1.0, 0.0, 0.0],
            vec![0.0, 2.0, 0.0],
            vec![0.0, 0.0, 3.0],
        ]
    }

    #[test]
    fn identity_and_similar_copies_score_zero() {
        let a = pts();
        assert_eq!(normalised_distance(&a, &a), Some(0.0));
        let scaled: Vec<Vec<f64>> = a
            .iter()
            .map(|p| p.iter().map(|x| 2.5 * x + 7.0).collect())
            .collect();
        assert!(normalised_distance(&a, &scaled).unwrap() < 1e-12);
        assert!(mpjpe(&a, &scaled).unwrap() > 1.0);
    }

    #[test]
    fn a_known_offset_gives_its_value() {
        // Two points ±1 on x (RMS 1) vs ±1 on y: normalised distance √2 per point.
        let a = vec![vec![-1.0, 0.0], vec![1.0, 0.0]];
        let b = vec![vec![0.0, -1.0], vec![0.0, 1.0]];
        assert!((normalised_distance(&a, &b).unwrap() - 2f64.sqrt()).abs() < 1e-12);
        let c = vec![vec![0.0, 0.0, 0.1], vec![1.0, 0.0, 0.1]];
        let d = vec![vec![0.0, 0.0, 0.0], vec![1.0, 0.0, 0.0]];
        assert!((mpjpe(&c, &d).unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(normalised_distance(&a, &a[..1]), None);
        assert_eq!(
            normalised_distance(&[vec![1.0], vec![1.0]], &[vec![1.0], vec![2.0]]),
            None,
            "degenerate set"
        );
    }
}
