//! Checkerboard corners in one image: ChESS X-junctions (`chess-corners`) labelled into a grid
//! (`calib-targets-chessboard`), then put in a canonical order so that two cameras of one rig
//! label the same physical corner alike.

use crate::Board;
use calib_targets_chessboard::{ChessboardDetector, ChessboardParams, detect_corners};
use calib_targets_core::{DetectorConfig, GrayImageView};
use irmirror_capture::Image;

/// The board's inner corners found in one image, in the board's canonical order (row-major:
/// `u` fastest), each at its pixel position in our convention (pixel centres at +0.5).
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// Inner corners along the board's canonical `u` axis (the one nearest the image's +x).
    pub cols: u32,
    /// Inner corners along `v`.
    pub rows: u32,
    /// `cols · rows` pixel positions, row-major.
    pub pixels: Vec<[f64; 2]>,
    /// The image upscaling the corner detector needed (1: none).
    pub upscale: u32,
}

/// Why no board was found.
#[derive(Clone, Debug, PartialEq)]
pub enum Miss {
    /// Fewer corners than the board has (partly outside, occluded, too small or blurred).
    Incomplete {
        /// Most corners labelled in any attempt.
        found: usize,
        /// The board's inner corners.
        expected: usize,
    },
    /// The labelled grid is not the board's size.
    WrongSize {
        /// Grid found (cols × rows).
        found: (u32, u32),
    },
    /// The board's edges lie near 45° in the image: which axis is "across" is ambiguous
    /// between the two cameras.
    Ambiguous {
        /// Angle between the nearest board axis and the image's +x, degrees.
        angle_deg: f64,
    },
}

impl std::fmt::Display for Miss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Miss::Incomplete { found, expected } => write!(
                f,
                "checkerboard not found: {found} of its {expected} inner corners labelled (is the whole board in view, sharp, and at least ~8 pixels a square?)"
            ),
            Miss::WrongSize { found } => write!(
                f,
                "a {}×{} grid of corners was found, not the board given with --board",
                found.0, found.1
            ),
            Miss::Ambiguous { angle_deg } => write!(
                f,
                "the board is rolled {angle_deg:.0}° in the image: hold it within ±35° of level so both cameras order its corners alike"
            ),
        }
    }
}

/// Largest roll of the board's axes against the image axes that still orders corners the same
/// in both cameras of a side-by-side rig (45° would be a coin toss).
const MAX_ROLL_DEG: f64 = 35.0;

/// `img` (any units) as 8-bit grey, stretched between its 1st and 99th percentiles: thermal
/// boards span a few kelvin of a 16-bit range.
pub fn to_gray8(img: &Image<f64>) -> Vec<u8> {
    let whole = Image::filled(img.width, img.height, false);
    irmirror_capture::image_io::stretch_percentiles(img, &whole).data
}

/// Finds every inner corner of `board` in `img`, trying the detector at 1×, 2× and 3× upscaling
/// (a Lepton's 160×120 frame needs it).
pub fn find_board(img: &Image<f64>, board: &Board) -> Result<Detection, Miss> {
    let gray = to_gray8(img);
    let view = GrayImageView {
        width: img.width as usize,
        height: img.height as usize,
        data: &gray,
    };
    let expected = (board.cols * board.rows) as usize;
    let mut best = 0;
    let mut last_miss = None;
    for upscale in [1u32, 2, 3] {
        let mut cfg = DetectorConfig::chess_multiscale();
        if upscale > 1 {
            cfg = cfg.with_upscale(chess_corners::UpscaleConfig::Fixed(upscale));
        }
        let corners = detect_corners(&view, &cfg);
        let Ok(detector) = ChessboardDetector::new(ChessboardParams::default()) else {
            continue;
        };
        let Some(det) = detector.detect(&corners) else {
            continue;
        };
        best = best.max(det.corners.len());
        if det.corners.len() != expected {
            continue;
        }
        let labelled: Vec<(i32, i32, [f64; 2])> = det
            .corners
            .iter()
            .map(|c| {
                (
                    c.grid.u,
                    c.grid.v,
                    // The detector's pixel centres are at integers; ours at +0.5.
                    [f64::from(c.position.x) + 0.5, f64::from(c.position.y) + 0.5],
                )
            })
            .collect();
        match canonical(&labelled, board) {
            Ok((cols, rows, pixels)) => {
                return Ok(Detection {
                    cols,
                    rows,
                    pixels,
                    upscale,
                });
            }
            Err(m) => last_miss = Some(m),
        }
    }
    Err(last_miss.unwrap_or(Miss::Incomplete {
        found: best,
        expected,
    }))
}

/// Relabels a complete grid so that `+u` is the board axis nearest the image's +x and `(u, v)`
/// is right-handed in the image (u right, v down), then orders it row-major from (0, 0).
/// Two cameras side by side with the same roll see the same labels; a board facing away is
/// not a case (the board is opaque).
fn canonical(
    labelled: &[(i32, i32, [f64; 2])],
    board: &Board,
) -> Result<(u32, u32, Vec<[f64; 2]>), Miss> {
    use std::collections::HashMap;
    let at: HashMap<(i32, i32), [f64; 2]> = labelled.iter().map(|&(u, v, p)| ((u, v), p)).collect();
    let mean_step = |du: i32, dv: i32| -> [f64; 2] {
        let (mut s, mut n) = ([0.0, 0.0], 0.0f64);
        for (&(u, v), p) in &at {
            if let Some(q) = at.get(&(u + du, v + dv)) {
                s[0] += q[0] - p[0];
                s[1] += q[1] - p[1];
                n += 1.0;
            }
        }
        [s[0] / n.max(1.0), s[1] / n.max(1.0)]
    };
    let du = mean_step(1, 0);
    let mut dv = mean_step(0, 1);
    let mut flip_v = 1;
    if du[0] * dv[1] - du[1] * dv[0] < 0.0 {
        flip_v = -1;
        dv = [-dv[0], -dv[1]];
    }
    // The four label rotations that keep handedness: new +u along du, dv, −du, −dv.
    let cands = [du, dv, [-du[0], -du[1]], [-dv[0], -dv[1]]];
    let cosx = |d: [f64; 2]| d[0] / d[0].hypot(d[1]).max(1e-12);
    let k = (0..4)
        .max_by(|&a, &b| cosx(cands[a]).total_cmp(&cosx(cands[b])))
        .unwrap_or(0);
    let angle_deg = cosx(cands[k]).clamp(-1.0, 1.0).acos().to_degrees();
    if angle_deg > MAX_ROLL_DEG {
        return Err(Miss::Ambiguous { angle_deg });
    }
    let relabel = |u: i32, v: i32| -> (i32, i32) {
        let v = v * flip_v;
        match k {
            0 => (u, v),
            1 => (v, -u),
            2 => (-u, -v),
            _ => (-v, u),
        }
    };
    let moved: Vec<((i32, i32), [f64; 2])> = labelled
        .iter()
        .map(|&(u, v, p)| (relabel(u, v), p))
        .collect();
    let umin = moved.iter().map(|m| m.0.0).min().unwrap_or(0);
    let vmin = moved.iter().map(|m| m.0.1).min().unwrap_or(0);
    let umax = moved.iter().map(|m| m.0.0).max().unwrap_or(0);
    let vmax = moved.iter().map(|m| m.0.1).max().unwrap_or(0);
    let (cols, rows) = ((umax - umin + 1) as u32, (vmax - vmin + 1) as u32);
    let fits = (cols, rows) == (board.cols, board.rows) || (cols, rows) == (board.rows, board.cols);
    if !fits || (cols * rows) as usize != labelled.len() {
        return Err(Miss::WrongSize {
            found: (cols, rows),
        });
    }
    let mut pixels = vec![[f64::NAN; 2]; labelled.len()];
    for ((u, v), p) in moved {
        pixels[((v - vmin) as u32 * cols + (u - umin) as u32) as usize] = p;
    }
    Ok((cols, rows, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(cols: i32, rows: i32, f: impl Fn(i32, i32) -> [f64; 2]) -> Vec<(i32, i32, [f64; 2])> {
        (0..rows)
            .flat_map(|v| (0..cols).map(move |u| (u, v)))
            .map(|(u, v)| (u, v, f(u, v)))
            .collect()
    }

    /// A grid labelled turned, mirrored or shifted by the detector comes out in one order:
    /// corner (0, 0) top left, u to the right.
    #[test]
    fn every_labelling_of_one_board_gives_the_same_order() {
        let board = Board {
            cols: 4,
            rows: 3,
            square_m: 0.03,
        };
        // Image: corner (u, v) at (100 + 20u + 2v, 50 + 20v − 3u): rolled ~9°.
        let truth = |u: i32, v: i32| {
            [
                100.0 + 20.0 * f64::from(u) + 2.0 * f64::from(v),
                50.0 + 20.0 * f64::from(v) - 3.0 * f64::from(u),
            ]
        };
        let want = canonical(&grid(4, 3, truth), &board).unwrap();
        assert_eq!((want.0, want.1), (4, 3));
        assert_eq!(want.2[0], truth(0, 0));
        assert_eq!(want.2[5], truth(1, 1));
        type Relabel = fn(i32, i32) -> (i32, i32);
        let relabels: [Relabel; 5] = [
            |u, v| (v, 3 - u),
            |u, v| (3 - u, 2 - v),
            |u, v| (2 - v, u),
            |u, v| (u + 7, 9 - v),
            |u, v| (v - 4, u + 1),
        ];
        for r in relabels {
            let l: Vec<_> = grid(4, 3, truth)
                .into_iter()
                .map(|(u, v, p)| {
                    let (a, b) = r(u, v);
                    (a, b, p)
                })
                .collect();
            assert_eq!(canonical(&l, &board).unwrap(), want);
        }
    }

    #[test]
    fn a_board_rolled_near_45_degrees_is_refused() {
        let board = Board {
            cols: 4,
            rows: 3,
            square_m: 0.03,
        };
        let rolled = grid(4, 3, |u, v| {
            let (u, v) = (f64::from(u), f64::from(v));
            [100.0 + 14.0 * u - 14.0 * v, 50.0 + 14.0 * u + 14.0 * v]
        });
        assert!(matches!(
            canonical(&rolled, &board),
            Err(Miss::Ambiguous { .. })
        ));
        let small = Board {
            cols: 5,
            rows: 3,
            square_m: 0.03,
        };
        let level = grid(4, 3, |u, v| [10.0 * f64::from(u), 10.0 * f64::from(v)]);
        assert!(matches!(
            canonical(&level, &small),
            Err(Miss::WrongSize { .. })
        ));
    }
}
