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
        let rms = (pts.iter().map(|p| (p - &mean).norm_squared()).sum::<f64>() / pts.len() as f64).sqrt();
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
    Some(a.iter().zip(b).map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).powi(2)).sum::<f64>().sqrt()).sum::<f64>() / a.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts() -> Vec<Vec<f64>> {
        vec![vec![0.0, 0.0, 0.0], vec![1.0, 0.0, 0.0], vec![0.0, 2.0, 0.0], vec![0.0, 0.0, 3.0]]
    }

    #[test]
    fn identity_and_similar_copies_score_zero() {
        let a = pts();
        assert_eq!(normalised_distance(&a, &a), Some(0.0));
        let scaled: Vec<Vec<f64>> = a.iter().map(|p| p.iter().map(|x| 2.5 * x + 7.0).collect()).collect();
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
        assert_eq!(normalised_distance(&[vec![1.0], vec![1.0]], &[vec![1.0], vec![2.0]]), None, "degenerate set");
    }
}
