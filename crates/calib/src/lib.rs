//! Calibrating a thermal camera against an RGB-D camera from views of a checkerboard seen by
//! both: the thermal intrinsics and `depth_from_thermal` (README, "Real captures";
//! docs/real-captures.md).
//!
//! Corners come from `chess-corners` (ChESS X-junctions, sub-pixel) and are labelled into a grid
//! by `calib-targets-chessboard`; the solve is ours ([`solve`]): normalised-DLT homographies,
//! Zhang's closed form for the thermal intrinsics, board poses from the homographies, then one
//! bundle adjustment of the thermal intrinsics, the extrinsic and every board pose against the
//! corners in both images, with the depth camera's intrinsics fixed (they come with the RGB-D
//! camera, for the image registered to its depth). Pinhole model: undistort first where the
//! lens needs it (the capture format has no distortion terms).

pub mod detect;
pub mod solve;

use irmirror_geom::{PinholeCamera, Rigid3};
use solve::{Intrinsics, PairedView, RigProblem, RigState};

pub use detect::{Detection, Miss, find_board};

/// A checkerboard: its inner corners and square size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Board {
    /// Inner corners along one side (squares − 1).
    pub cols: u32,
    /// Inner corners along the other side.
    pub rows: u32,
    /// Side of a square, metres.
    pub square_m: f64,
}

impl Board {
    /// The inner corners in the board frame (z = 0), metres, for a `cols × rows` labelling,
    /// row-major.
    pub fn points(cols: u32, rows: u32, square_m: f64) -> Vec<[f64; 2]> {
        (0..rows)
            .flat_map(|v| {
                (0..cols).map(move |u| [square_m * f64::from(u), square_m * f64::from(v)])
            })
            .collect()
    }
}

/// What can go wrong.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// Too few views in which both cameras see the whole board.
    #[error(
        "the board was found in both images of {usable} view(s); calibration needs at least {MIN_VIEWS} (vary tilt and distance; see docs/real-captures.md)"
    )]
    TooFewViews {
        /// Views usable.
        usable: usize,
    },
    /// The two cameras labelled the board with different sizes (one of them held portrait?).
    #[error("view {view}: the thermal image shows a {t:?} grid, the depth camera's a {d:?} grid")]
    Inconsistent {
        /// View name.
        view: String,
        /// Thermal grid (cols, rows).
        t: (u32, u32),
        /// Depth-camera grid.
        d: (u32, u32),
    },
    /// The solve failed (degenerate views: all parallel to the image, or one view only).
    #[error("the calibration is degenerate: {0} (tilt the board in different directions)")]
    Degenerate(String),
}

/// Fewest views accepted (Zhang's closed form needs three; four leave a residual to judge).
pub const MIN_VIEWS: usize = 4;

/// One view: a name for messages and the two detections.
#[derive(Clone, Debug)]
pub struct ViewPair {
    /// Name (the file stem shared by both images).
    pub name: String,
    /// Corners in the thermal image.
    pub thermal: Detection,
    /// Corners in the depth camera's image.
    pub depth: Detection,
}

/// The calibration and how well it fits.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The thermal camera's intrinsics (its image size as given).
    pub thermal: PinholeCamera,
    /// Thermal frame → depth frame.
    pub depth_from_thermal: Rigid3<f64>,
    /// RMS reprojection error over all thermal corners, pixels.
    pub rms_thermal_px: f64,
    /// RMS reprojection error over all depth-image corners, pixels.
    pub rms_depth_px: f64,
    /// Per view: (name, thermal RMS, depth RMS), pixels.
    pub per_view: Vec<(String, f64, f64)>,
    /// One-σ uncertainties of fx, fy, cx, cy (pixels), then of the extrinsic's rotation
    /// (radians, about the depth frame's axes) and translation (metres).
    pub std_devs: Vec<f64>,
}

/// Calibrates from views in which both cameras found the board. `thermal_size` is the thermal
/// image's (width, height); `depth_camera` the RGB-D camera's intrinsics.
pub fn calibrate(
    views: &[ViewPair],
    board: &Board,
    thermal_size: (u32, u32),
    depth_camera: &PinholeCamera,
) -> Result<Calibration, CalibError> {
    if views.len() < MIN_VIEWS {
        return Err(CalibError::TooFewViews {
            usable: views.len(),
        });
    }
    let (cols, rows) = (views[0].thermal.cols, views[0].thermal.rows);
    for v in views {
        let (t, d) = (
            (v.thermal.cols, v.thermal.rows),
            (v.depth.cols, v.depth.rows),
        );
        if t != d || t != (cols, rows) {
            return Err(CalibError::Inconsistent {
                view: v.name.clone(),
                t,
                d,
            });
        }
    }
    let pts = Board::points(cols, rows, board.square_m);
    let degenerate = |what: &str| CalibError::Degenerate(what.to_string());
    let homs = |px: &dyn Fn(&ViewPair) -> &Vec<[f64; 2]>| {
        views
            .iter()
            .map(|v| solve::homography(&pts, px(v)))
            .collect::<Option<Vec<_>>>()
    };
    let ht = homs(&|v| &v.thermal.pixels).ok_or_else(|| degenerate("a thermal homography"))?;
    let hd = homs(&|v| &v.depth.pixels).ok_or_else(|| degenerate("a depth homography"))?;
    let paired: Vec<PairedView> = views
        .iter()
        .map(|v| PairedView {
            thermal: v.thermal.pixels.clone(),
            depth: v.depth.pixels.clone(),
        })
        .collect();

    // 1. Thermal intrinsics: Zhang, then a thermal-only bundle adjustment.
    let k0: Intrinsics = solve::zhang(&ht).ok_or_else(|| degenerate("Zhang's closed form"))?;
    let thermal_poses = ht
        .iter()
        .map(|h| solve::pose_from_homography(&k0, h))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| degenerate("a thermal board pose"))?;
    let kd = solve::intrinsics_of(depth_camera);
    let mut only = RigState {
        thermal: k0,
        depth_from_thermal: Rigid3::identity(),
        depth_from_board: thermal_poses,
    };
    RigProblem {
        board: &pts,
        views: &paired,
        depth: kd,
        use_depth: false,
    }
    .refine(&mut only);

    // 2. Board poses in the depth camera; the extrinsic as the mean of the per-view ones.
    let depth_poses = hd
        .iter()
        .map(|h| solve::pose_from_homography(&kd, h))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| degenerate("a depth board pose"))?;
    let per_view_ext: Vec<Rigid3<f64>> = depth_poses
        .iter()
        .zip(&only.depth_from_board)
        .map(|(d, t)| *d * t.inverse())
        .collect();

    // 3. Everything together.
    let mut s = RigState {
        thermal: only.thermal,
        depth_from_thermal: solve::mean_rigid(&per_view_ext),
        depth_from_board: depth_poses,
    };
    let prob = RigProblem {
        board: &pts,
        views: &paired,
        depth: kd,
        use_depth: true,
    };
    prob.refine(&mut s);

    let mut r = vec![0.0; prob.residuals()];
    prob.eval(&s, &mut r, None);
    let per_point = 4 * pts.len();
    let rms = |vals: &mut dyn Iterator<Item = f64>| {
        let (mut sum, mut n) = (0.0f64, 0.0f64);
        for v in vals {
            sum += v * v;
            n += 1.0;
        }
        (sum / n.max(1.0)).sqrt() * std::f64::consts::SQRT_2
    };
    // Rows per view: for each corner 2 thermal then 2 depth.
    let split = |chunk: &[f64], thermal: bool| -> Vec<f64> {
        chunk
            .chunks(4)
            .flat_map(|c| if thermal { [c[0], c[1]] } else { [c[2], c[3]] })
            .collect()
    };
    let per_view = views
        .iter()
        .zip(r.chunks(per_point))
        .map(|(v, c)| {
            (
                v.name.clone(),
                rms(&mut split(c, true).into_iter()),
                rms(&mut split(c, false).into_iter()),
            )
        })
        .collect();
    let all_t: Vec<f64> = r.chunks(per_point).flat_map(|c| split(c, true)).collect();
    let all_d: Vec<f64> = r.chunks(per_point).flat_map(|c| split(c, false)).collect();
    let [fx, fy, cx, cy] = s.thermal;
    let finite = s
        .depth_from_thermal
        .translation
        .iter()
        .all(|v| v.is_finite());
    if !(fx > 0.0 && fy > 0.0 && finite) {
        return Err(degenerate("non-positive focal lengths"));
    }
    let thermal = PinholeCamera {
        width: thermal_size.0,
        height: thermal_size.1,
        fx,
        fy,
        cx,
        cy,
    };
    thermal
        .validate()
        .map_err(|e| degenerate(&format!("the thermal intrinsics: {e}")))?;
    Ok(Calibration {
        thermal,
        std_devs: prob.std_devs(&s, 10),
        depth_from_thermal: s.depth_from_thermal,
        rms_thermal_px: rms(&mut all_t.into_iter()),
        rms_depth_px: rms(&mut all_d.into_iter()),
        per_view,
    })
}
