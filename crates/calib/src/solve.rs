//! The solve: planar homographies (normalised DLT), Zhang's closed-form intrinsics, board poses
//! from homographies, and one bundle adjustment of everything (Levenberg–Marquardt with the
//! analytic Jacobian below, finite-difference tested).

use irmirror_geom::optim::{LmParams, LmReport, levenberg_marquardt};
use irmirror_geom::rotation::{axis_angle_to_matrix, skew};
use irmirror_geom::{PinholeCamera, Rigid3};
use nalgebra::{DMatrix, Matrix3, Vector3};

/// Pinhole intrinsics `[fx, fy, cx, cy]` (pixels, centres at +0.5).
pub type Intrinsics = [f64; 4];

/// `[fx, fy, cx, cy]` of a camera.
pub fn intrinsics_of(c: &PinholeCamera) -> Intrinsics {
    [c.fx, c.fy, c.cx, c.cy]
}

/// Projects a point in the camera frame (None behind the camera).
pub fn project(k: &Intrinsics, p: &Vector3<f64>) -> Option<[f64; 2]> {
    (p.z > 1e-9).then(|| [k[0] * p.x / p.z + k[2], k[1] * p.y / p.z + k[3]])
}

/// The homography `H` with `pixel ~ H · (x, y, 1)` from board points (metres) to pixels,
/// by the normalised DLT (Hartley): both point sets centred and scaled to mean distance √2.
pub fn homography(board: &[[f64; 2]], pixels: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let norm = |pts: &[[f64; 2]]| -> Matrix3<f64> {
        let n = pts.len() as f64;
        let (mx, my) = (
            pts.iter().map(|p| p[0]).sum::<f64>() / n,
            pts.iter().map(|p| p[1]).sum::<f64>() / n,
        );
        let d = pts
            .iter()
            .map(|p| (p[0] - mx).hypot(p[1] - my))
            .sum::<f64>()
            / n;
        let s = std::f64::consts::SQRT_2 / d.max(1e-12);
        Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
    };
    if board.len() < 4 || board.len() != pixels.len() {
        return None;
    }
    let (ta, tb) = (norm(board), norm(pixels));
    let mut a = DMatrix::<f64>::zeros(2 * board.len(), 9);
    for (i, (p, q)) in board.iter().zip(pixels).enumerate() {
        let x = ta * Vector3::new(p[0], p[1], 1.0);
        let y = tb * Vector3::new(q[0], q[1], 1.0);
        let (u, v) = (y.x / y.z, y.y / y.z);
        for k in 0..3 {
            a[(2 * i, 3 + k)] = -x[k];
            a[(2 * i, 6 + k)] = v * x[k];
            a[(2 * i + 1, k)] = x[k];
            a[(2 * i + 1, 6 + k)] = -u * x[k];
        }
    }
    let svd = (a.transpose() * &a).symmetric_eigen();
    let k = svd.eigenvalues.imin();
    let h = svd.eigenvectors.column(k);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let h = tb.try_inverse()? * hn * ta;
    Some(h / h[(2, 2)])
}

/// Zhang's closed form (2000) for `fx, fy, cx, cy` from ≥ 3 homographies, with zero skew
/// imposed as one more equation.
pub fn zhang(hs: &[Matrix3<f64>]) -> Option<Intrinsics> {
    if hs.len() < 3 {
        return None;
    }
    let vij = |h: &Matrix3<f64>, i: usize, j: usize| -> [f64; 6] {
        let (a, b) = (h.column(i), h.column(j));
        [
            a[0] * b[0],
            a[0] * b[1] + a[1] * b[0],
            a[1] * b[1],
            a[2] * b[0] + a[0] * b[2],
            a[2] * b[1] + a[1] * b[2],
            a[2] * b[2],
        ]
    };
    // Scale columns to O(1) so that the equations are balanced.
    let mut rows: Vec<[f64; 6]> = Vec::new();
    for h in hs {
        let h = h / h.column(0).norm().max(1e-300);
        rows.push(vij(&h, 0, 1));
        let (a, b) = (vij(&h, 0, 0), vij(&h, 1, 1));
        rows.push(std::array::from_fn(|k| a[k] - b[k]));
    }
    rows.push([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    let mut a = DMatrix::<f64>::zeros(rows.len(), 6);
    for (i, r) in rows.iter().enumerate() {
        let n = r.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
        for k in 0..6 {
            a[(i, k)] = r[k] / n;
        }
    }
    let e = (a.transpose() * &a).symmetric_eigen();
    let b = e.eigenvectors.column(e.eigenvalues.imin());
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha = (lambda / b11).sqrt();
    let beta = (lambda * b11 / den).sqrt();
    let u0 = -b13 * alpha * alpha / lambda;
    let k = [alpha, beta, u0, v0];
    k.iter().all(|v| v.is_finite()).then_some(k)
}

/// The board's pose in the camera (`camera_from_board`) from its homography and intrinsics:
/// `[r1 r2 t] ∝ K⁻¹ H`, the rotation made orthonormal, the board in front of the camera.
pub fn pose_from_homography(k: &Intrinsics, h: &Matrix3<f64>) -> Option<Rigid3<f64>> {
    let kinv = Matrix3::new(k[0], 0.0, k[2], 0.0, k[1], k[3], 0.0, 0.0, 1.0).try_inverse()?;
    let m = kinv * h;
    let mut s = 1.0 / m.column(0).norm();
    if (m[(2, 2)] * s) < 0.0 {
        s = -s;
    }
    let (r1, r2, t) = (m.column(0) * s, m.column(1) * s, m.column(2) * s);
    let approx = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = approx.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        r = -r;
    }
    Some(Rigid3 {
        rotation: r,
        translation: t,
    })
}

/// One view of the board by both cameras: pixel positions of the same corners.
#[derive(Clone, Debug)]
pub struct PairedView {
    /// Corners in the thermal image.
    pub thermal: Vec<[f64; 2]>,
    /// The same corners in the depth camera's image (registered RGB or IR).
    pub depth: Vec<[f64; 2]>,
}

/// The state of the bundle adjustment.
#[derive(Clone, Debug)]
pub struct RigState {
    /// Thermal intrinsics.
    pub thermal: Intrinsics,
    /// Thermal frame → depth frame.
    pub depth_from_thermal: Rigid3<f64>,
    /// Per view: board frame → depth frame.
    pub depth_from_board: Vec<Rigid3<f64>>,
}

/// The problem: board points, views, fixed depth intrinsics and what is free.
pub struct RigProblem<'a> {
    /// Board points (z = 0), metres, in the views' corner order.
    pub board: &'a [[f64; 2]],
    /// The views.
    pub views: &'a [PairedView],
    /// The depth camera's intrinsics (fixed: they come with the RGB-D camera).
    pub depth: Intrinsics,
    /// Fit the depth image's corners too (off: a thermal-only intrinsics fit, where
    /// `depth_from_board` holds thermal-from-board and `depth_from_thermal` stays the identity).
    pub use_depth: bool,
}

impl RigProblem<'_> {
    /// Number of free parameters of `s`.
    pub fn parameters(&self, s: &RigState) -> usize {
        4 + if self.use_depth { 6 } else { 0 } + 6 * s.depth_from_board.len()
    }

    /// Number of residuals.
    pub fn residuals(&self) -> usize {
        let per = 2 * self.board.len();
        self.views.len() * per * if self.use_depth { 2 } else { 1 }
    }

    /// Residuals (pixels: projected − observed) and, if asked, the row-major Jacobian with
    /// respect to the increment of [`RigProblem::retract`]. Behind-camera points give a large
    /// constant residual and zero rows.
    pub fn eval(&self, s: &RigState, r: &mut [f64], mut jac: Option<&mut [f64]>) {
        let n = self.parameters(s);
        if let Some(j) = jac.as_deref_mut() {
            j.fill(0.0);
        }
        let ext_col = 4;
        let board_col = |v: usize| 4 + if self.use_depth { 6 } else { 0 } + 6 * v;
        let (re, te) = (
            s.depth_from_thermal.rotation,
            s.depth_from_thermal.translation,
        );
        let ret = re.transpose();
        let k = &s.thermal;
        let mut row = 0;
        for (v, view) in self.views.iter().enumerate() {
            let pose = &s.depth_from_board[v];
            for (i, b) in self.board.iter().enumerate() {
                let x = Vector3::new(b[0], b[1], 0.0);
                let rx = pose.rotation * x;
                let q = rx + pose.translation;
                // Thermal residual.
                let w = q - te;
                let p = ret * w;
                let obs = view.thermal[i];
                self.residual_rows(k, &p, obs, r, row, |jp, jrow| {
                    let Some(j) = jac.as_deref_mut() else { return };
                    let jk = [[p.x / p.z, 0.0, 1.0, 0.0], [0.0, p.y / p.z, 0.0, 1.0]];
                    // dP/dω_board = Rᵀe (−[R X]×), dP/dt_board = Rᵀe;
                    // dP/dφ_ext = Rᵀe [q − t_e]×, dP/dδ_ext = −Rᵀe.
                    let a_rot = jp * ret * (-skew(&rx));
                    let a_tr = jp * ret;
                    let e_rot = jp * ret * skew(&w);
                    let e_tr = -(jp * ret);
                    for d in 0..2 {
                        let base = (jrow + d) * n;
                        j[base..base + 4].copy_from_slice(&jk[d]);
                        let bc = board_col(v);
                        for c in 0..3 {
                            j[base + bc + c] = a_rot[(d, c)];
                            j[base + bc + 3 + c] = a_tr[(d, c)];
                            if self.use_depth {
                                j[base + ext_col + c] = e_rot[(d, c)];
                                j[base + ext_col + 3 + c] = e_tr[(d, c)];
                            }
                        }
                    }
                });
                row += 2;
                if self.use_depth {
                    let obs = view.depth[i];
                    self.residual_rows(&self.depth, &q, obs, r, row, |jp, jrow| {
                        let Some(j) = jac.as_deref_mut() else { return };
                        let a_rot = jp * (-skew(&rx));
                        let bc = board_col(v);
                        for d in 0..2 {
                            let base = (jrow + d) * n;
                            for c in 0..3 {
                                j[base + bc + c] = a_rot[(d, c)];
                                j[base + bc + 3 + c] = jp[(d, c)];
                            }
                        }
                    });
                    row += 2;
                }
            }
        }
    }

    fn residual_rows(
        &self,
        k: &Intrinsics,
        p: &Vector3<f64>,
        obs: [f64; 2],
        r: &mut [f64],
        row: usize,
        mut fill: impl FnMut(nalgebra::Matrix2x3<f64>, usize),
    ) {
        match project(k, p) {
            Some(px) => {
                r[row] = px[0] - obs[0];
                r[row + 1] = px[1] - obs[1];
                let (z, z2) = (p.z, p.z * p.z);
                let jp = nalgebra::Matrix2x3::new(
                    k[0] / z,
                    0.0,
                    -k[0] * p.x / z2,
                    0.0,
                    k[1] / z,
                    -k[1] * p.y / z2,
                );
                fill(jp, row);
            }
            None => {
                r[row] = 1e3;
                r[row + 1] = 1e3;
            }
        }
    }

    /// `s` moved by the increment `d`: intrinsics added, rotations `R ← exp(ω) R`,
    /// translations added.
    pub fn retract(&self, s: &RigState, d: &[f64]) -> RigState {
        let step = |t: &Rigid3<f64>, d: &[f64]| Rigid3 {
            rotation: axis_angle_to_matrix(&Vector3::new(d[0], d[1], d[2])) * t.rotation,
            translation: t.translation + Vector3::new(d[3], d[4], d[5]),
        };
        let mut out = s.clone();
        for k in 0..4 {
            out.thermal[k] += d[k];
        }
        let mut c = 4;
        if self.use_depth {
            out.depth_from_thermal = step(&s.depth_from_thermal, &d[4..10]);
            c = 10;
        }
        for (v, pose) in s.depth_from_board.iter().enumerate() {
            out.depth_from_board[v] = step(pose, &d[c + 6 * v..c + 6 * v + 6]);
        }
        out
    }

    /// Refines `s` in place.
    pub fn refine(&self, s: &mut RigState) -> LmReport {
        let (n, m) = (self.parameters(s), self.residuals());
        levenberg_marquardt(
            s,
            n,
            m,
            LmParams {
                max_iterations: 200,
                ..LmParams::default()
            },
            |s, r, j| self.eval(s, r, j),
            |s, d| self.retract(s, d),
        )
    }

    /// Standard deviations of the first `count` parameters (intrinsics, then the extrinsic),
    /// from `σ² (JᵀJ)⁻¹` with σ² the residual variance.
    pub fn std_devs(&self, s: &RigState, count: usize) -> Vec<f64> {
        let (n, m) = (self.parameters(s), self.residuals());
        let (mut r, mut j) = (vec![0.0; m], vec![0.0; m * n]);
        self.eval(s, &mut r, Some(&mut j));
        let jm = DMatrix::from_row_slice(m, n, &j);
        let sigma2 = r.iter().map(|v| v * v).sum::<f64>() / (m.saturating_sub(n)).max(1) as f64;
        match (jm.transpose() * &jm).try_inverse() {
            Some(cov) => (0..count.min(n))
                .map(|k| (cov[(k, k)] * sigma2).max(0.0).sqrt())
                .collect(),
            None => vec![f64::NAN; count.min(n)],
        }
    }
}

/// Rotation mean (chordal: the nearest rotation to the sum) and translation mean.
pub fn mean_rigid(ts: &[Rigid3<f64>]) -> Rigid3<f64> {
    let sum: Matrix3<f64> = ts.iter().map(|t| t.rotation).sum();
    let svd = sum.svd(true, true);
    let mut r = match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => u * vt,
        _ => Matrix3::identity(),
    };
    if r.determinant() < 0.0 {
        r = -r;
    }
    let t = ts.iter().map(|t| t.translation).sum::<Vector3<f64>>() / ts.len().max(1) as f64;
    Rigid3 {
        rotation: r,
        translation: t,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn board() -> Vec<[f64; 2]> {
        (0..4)
            .flat_map(|v| (0..5).map(move |u| [0.03 * f64::from(u), 0.03 * f64::from(v)]))
            .collect()
    }

    fn rig() -> (RigState, Vec<PairedView>, Intrinsics) {
        let kd = [228.0, 229.0, 160.0, 120.0];
        let kt = [580.0, 581.0, 322.0, 255.0];
        let ext = Rigid3 {
            rotation: axis_angle_to_matrix(&Vector3::new(0.01, -0.02, 0.005)),
            translation: Vector3::new(0.04, -0.005, 0.002),
        };
        let poses: Vec<Rigid3<f64>> = [
            (0.3, -0.2, 0.1, 0.8),
            (-0.35, 0.1, -0.1, 0.7),
            (0.1, 0.4, 0.2, 0.9),
        ]
        .iter()
        .map(|&(a, b, c, z)| Rigid3 {
            rotation: axis_angle_to_matrix(&Vector3::new(a, b, c)),
            translation: Vector3::new(-0.06, -0.04, z),
        })
        .collect();
        let b = board();
        let views = poses
            .iter()
            .map(|p| {
                let q: Vec<Vector3<f64>> = b
                    .iter()
                    .map(|x| p.transform_point(&Vector3::new(x[0], x[1], 0.0)))
                    .collect();
                PairedView {
                    thermal: q
                        .iter()
                        .map(|q| project(&kt, &ext.inverse().transform_point(q)).unwrap())
                        .collect(),
                    depth: q.iter().map(|q| project(&kd, q).unwrap()).collect(),
                }
            })
            .collect();
        (
            RigState {
                thermal: kt,
                depth_from_thermal: ext,
                depth_from_board: poses,
            },
            views,
            kd,
        )
    }

    /// The analytic Jacobian against central differences through the retraction, in f64.
    #[test]
    fn jacobian_matches_finite_differences() {
        let (truth, views, kd) = rig();
        let b = board();
        for use_depth in [true, false] {
            let prob = RigProblem {
                board: &b,
                views: &views,
                depth: kd,
                use_depth,
            };
            // Away from the optimum so that every term matters.
            let s = prob.retract(
                &truth,
                &(0..prob.parameters(&truth))
                    .map(|k| 0.01 * ((k as f64 * 1.7).sin()))
                    .collect::<Vec<_>>(),
            );
            let (n, m) = (prob.parameters(&s), prob.residuals());
            let (mut r, mut j) = (vec![0.0; m], vec![0.0; m * n]);
            prob.eval(&s, &mut r, Some(&mut j));
            let h = 1e-6;
            let mut worst = 0.0f64;
            for c in 0..n {
                let mut d = vec![0.0; n];
                d[c] = h;
                let (mut rp, mut rm) = (vec![0.0; m], vec![0.0; m]);
                prob.eval(&prob.retract(&s, &d), &mut rp, None);
                d[c] = -h;
                prob.eval(&prob.retract(&s, &d), &mut rm, None);
                for row in 0..m {
                    let fd = (rp[row] - rm[row]) / (2.0 * h);
                    let err = (fd - j[row * n + c]).abs() / (1.0 + fd.abs());
                    worst = worst.max(err);
                }
            }
            assert!(
                worst < 1e-5,
                "use_depth {use_depth}: worst relative error {worst}"
            );
        }
    }

    /// Exact homographies give Zhang's intrinsics back, and a perturbed state refines to the
    /// truth.
    #[test]
    fn closed_form_and_refinement_recover_a_noise_free_rig() {
        let (truth, views, kd) = rig();
        let b = board();
        let hs: Vec<Matrix3<f64>> = views
            .iter()
            .map(|v| homography(&b, &v.thermal).unwrap())
            .collect();
        let k = zhang(&hs).unwrap();
        for i in 0..4 {
            assert!((k[i] - truth.thermal[i]).abs() < 0.05, "{k:?}");
        }
        let pose = pose_from_homography(&truth.thermal, &hs[0]).unwrap();
        let want = truth.depth_from_thermal.inverse() * truth.depth_from_board[0];
        assert!((pose.translation - want.translation).norm() < 1e-6);
        let prob = RigProblem {
            board: &b,
            views: &views,
            depth: kd,
            use_depth: true,
        };
        let mut s = prob.retract(
            &truth,
            &(0..prob.parameters(&truth))
                .map(|k| if k < 4 { 5.0 } else { 0.01 })
                .collect::<Vec<_>>(),
        );
        let rep = prob.refine(&mut s);
        assert!(rep.final_cost < 1e-14, "{rep:?}");
        assert!(
            (s.depth_from_thermal.translation - truth.depth_from_thermal.translation).norm() < 1e-8
        );
        for i in 0..4 {
            assert!((s.thermal[i] - truth.thermal[i]).abs() < 1e-6);
        }
    }
}
