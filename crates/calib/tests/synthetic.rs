//! `capture calibrate`'s solve on checkerboard views rendered by the simulator with a known rig:
//! the goals are the focal length within 0.5 % and the extrinsic within 2 mm / 0.2°.

use irmirror_calib::{Board, ViewPair, calibrate, find_board};
use irmirror_capture::Image;
use irmirror_geom::rotation::matrix_to_axis_angle;
use irmirror_sim::ThermalPreset;
use irmirror_sim::board::{CheckerBoard, Rig, grey_view, poses, thermal_view};

fn run(
    preset: ThermalPreset,
    views: usize,
    seed: u64,
) -> (Rig, irmirror_calib::Calibration, usize) {
    let rig = Rig::preset(preset);
    let cb = CheckerBoard::default();
    let board = Board {
        cols: cb.cols,
        rows: cb.rows,
        square_m: cb.square_m,
    };
    let mut rng = irmirror_geom::rng::seeded(seed, 0);
    let mut pairs = Vec::new();
    let mut missed = 0;
    for (k, pose) in poses(&rig, &cb, views, &mut rng).iter().enumerate() {
        let t = thermal_view(&rig, &cb, pose, &mut rng).map(f64::from);
        let g: Image<f64> = grey_view(&rig, &cb, pose, &mut rng).map(f64::from);
        match (find_board(&t, &board), find_board(&g, &board)) {
            (Ok(thermal), Ok(depth)) => pairs.push(ViewPair {
                name: format!("{k:02}"),
                thermal,
                depth,
            }),
            (a, b) => {
                eprintln!("view {k}: thermal {:?} / grey {:?}", a.err(), b.err());
                missed += 1
            }
        }
    }
    let cal = calibrate(
        &pairs,
        &board,
        (rig.thermal.width, rig.thermal.height),
        &rig.depth,
    )
    .expect("calibrates");
    (rig, cal, missed)
}

fn errors(rig: &Rig, cal: &irmirror_calib::Calibration) -> (f64, f64, f64) {
    let f_err = ((cal.thermal.fx / rig.thermal.fx - 1.0).abs())
        .max((cal.thermal.fy / rig.thermal.fy - 1.0).abs());
    let t_err = (cal.depth_from_thermal.translation - rig.depth_from_thermal.translation).norm();
    let r_err = matrix_to_axis_angle(
        &(cal.depth_from_thermal.rotation * rig.depth_from_thermal.rotation.transpose()),
    )
    .norm()
    .to_degrees();
    (f_err, t_err, r_err)
}

/// Calibrates twelve views of `preset`'s rig and holds it to the goals.
fn check(preset: ThermalPreset, seed: u64) {
    let (rig, cal, missed) = run(preset, 12, seed);
    let (f, t, r) = errors(&rig, &cal);
    eprintln!(
        "{preset:?}: missed {missed}, focal {:.3} %, principal point ({:+.2}, {:+.2}) px, extrinsic {:.2} mm / {:.3}°, RMS {:.3} / {:.3} px",
        100.0 * f,
        cal.thermal.cx - rig.thermal.cx,
        cal.thermal.cy - rig.thermal.cy,
        1e3 * t,
        r,
        cal.rms_thermal_px,
        cal.rms_depth_px
    );
    assert!(missed <= 2, "{missed} views missed");
    assert!(f < 0.005, "focal length off by {:.3} %", 100.0 * f);
    assert!(
        t < 0.002 && r < 0.2,
        "extrinsic off by {:.2} mm / {r:.3}°",
        1e3 * t
    );
    assert!(
        cal.rms_thermal_px < 0.3 && cal.rms_depth_px < 0.3,
        "{cal:?}"
    );
    let px = f64::from(rig.thermal.width) / 200.0;
    assert!(
        (cal.thermal.cx - rig.thermal.cx).abs() < px
            && (cal.thermal.cy - rig.thermal.cy).abs() < px
    );
}

#[test]
fn a_boson_rig_is_recovered_from_twelve_views() {
    check(ThermalPreset::Boson, 1);
}

#[test]
fn a_lepton_rig_is_recovered_from_twelve_views() {
    check(ThermalPreset::Lepton, 2);
}
