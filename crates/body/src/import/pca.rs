//! The shape basis: centred SVD over the anchor-grid corners (ANNY_SPEC.md §12 step 7).

use nalgebra::DMatrix;

/// A linear shape space `state = S0 + mean + z · basis`, `z = c · projection − offset`.
pub struct ShapeSpace {
    /// Mean offset state μ (S).
    pub mean: Vec<f64>,
    /// r×S orthonormal rows E.
    pub basis: DMatrix<f64>,
    /// B×r, `P = D Eᵀ`.
    pub projection: DMatrix<f64>,
    /// r, `z0 = μ Eᵀ`.
    pub offset: Vec<f64>,
    /// Rank above 1e-9 of the largest singular value.
    pub numerical_rank: usize,
    /// Largest absolute residual over the corners at the kept rank, m.
    pub corner_residual_m: f64,
}

impl ShapeSpace {
    /// Kept rank r.
    pub fn rank(&self) -> usize {
        self.basis.nrows()
    }
}

/// Fits the basis. `d`: B×S blendshape states; `corners`: N×B coefficients.
pub fn fit(d: &DMatrix<f64>, corners: &DMatrix<f64>, rank: Option<usize>) -> ShapeSpace {
    let y = corners * d;
    let n = y.nrows() as f64;
    let mean: Vec<f64> = (0..y.ncols()).map(|k| y.column(k).sum() / n).collect();
    let mut yc = y.clone();
    for (k, m) in mean.iter().enumerate() {
        yc.column_mut(k).add_scalar_mut(-m);
    }
    // SVD of the (narrow) transpose: its left singular vectors are the basis rows.
    let svd = yc.transpose().svd(true, false);
    let u = svd.u.expect("requested U");
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let s0 = svd.singular_values[order[0]];
    let numerical_rank = order
        .iter()
        .filter(|&&i| svd.singular_values[i] > 1e-9 * s0)
        .count();
    let r = rank.unwrap_or(numerical_rank).min(numerical_rank).max(1);
    let mut basis = DMatrix::zeros(r, y.ncols());
    for (row, &i) in order[..r].iter().enumerate() {
        let col = u.column(i);
        // Fix the sign so that conversions are reproducible: largest entry positive.
        let imax = col.iamax();
        let sign = if col[imax] < 0.0 { -1.0 } else { 1.0 };
        basis.row_mut(row).copy_from(&(col.transpose() * sign));
    }
    let projection = d * basis.transpose();
    let mean_row = DMatrix::from_row_slice(1, mean.len(), &mean);
    let offset: Vec<f64> = (&mean_row * basis.transpose()).iter().copied().collect();
    let recon = (&yc * basis.transpose()) * &basis;
    let corner_residual_m = (recon - yc).abs().max();
    ShapeSpace {
        mean,
        basis,
        projection,
        offset,
        numerical_rank,
        corner_residual_m,
    }
}
