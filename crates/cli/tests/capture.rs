//! `irmirror capture calibrate | import | boards`: a simulated rig calibrated through the CLI,
//! a FLIR radiometric JPEG imported into a capture that reconstruction reads, and the refusals.

mod common;

use common::{irmirror, read_tree, stderr, tmp};
use irmirror_capture::flir;
use irmirror_capture::{Capture, Image, RigFile};
use irmirror_geom::rotation::matrix_to_axis_angle;
use std::path::Path;

fn shipped_flir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/flir/exiftool_FLIR_i7.jpg")
}

fn rig(path: &Path) -> RigFile {
    toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Boards → calibrate recovers the simulated rig within the goals (focal 0.5 %,
/// extrinsic 2 mm / 0.2°) and leaves the image directory as it was.
#[test]
fn a_simulated_rig_is_calibrated_through_the_cli() {
    let dir = tmp("boards");
    let o = irmirror(&[
        "capture",
        "boards",
        "--out",
        dir.to_str().unwrap(),
        "--views",
        "12",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = read_tree(&dir);
    let out = tmp("rig.toml");
    let args = |out: &Path| {
        vec![
            "capture".to_string(),
            "calibrate".into(),
            dir.to_str().unwrap().into(),
            "--board".into(),
            "7x5".into(),
            "--square-mm".into(),
            "35".into(),
            "--depth-camera".into(),
            dir.join("depth_camera.json").to_str().unwrap().into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ]
    };
    let run = |a: Vec<String>| irmirror(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let o = run(args(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    let (got, truth) = (rig(&out), rig(&dir.join("truth.toml")));
    let (g, t) = (&got.thermal_camera, &truth.thermal_camera);
    assert!(
        (g.intrinsics.fx / t.intrinsics.fx - 1.0).abs() < 0.005,
        "{g:?}"
    );
    assert!(
        (g.intrinsics.fy / t.intrinsics.fy - 1.0).abs() < 0.005,
        "{g:?}"
    );
    let (ge, te) = (
        g.depth_from_thermal.to_rigid().unwrap(),
        t.depth_from_thermal.to_rigid().unwrap(),
    );
    let dt = (ge.translation - te.translation).norm();
    let dr = matrix_to_axis_angle(&(ge.rotation * te.rotation.transpose()))
        .norm()
        .to_degrees();
    assert!(dt < 0.002 && dr < 0.2, "{dt} m, {dr}°");
    let fit = got.fit.unwrap();
    assert!(fit.views >= 10 && fit.rms_thermal_px < 0.5, "{fit:?}");
    // Through OpenCV's JSON and back (serde_json reads floats to within an ulp).
    let (a, b) = (got.depth_camera, truth.depth_camera);
    assert!(
        (a.width, a.height) == (b.width, b.height)
            && (a.fx - b.fx).abs() < 1e-9
            && (a.cx - b.cx).abs() < 1e-9
    );
    assert_eq!(read_tree(&dir), before, "the input directory was modified");

    // --out inside the input: refused, nothing written.
    let o = run(args(&dir.join("rig.toml")));
    assert!(
        !o.status.success() && stderr(&o).contains("inside the input"),
        "{}",
        stderr(&o)
    );
    assert_eq!(read_tree(&dir), before);
}

#[test]
fn calibration_inputs_that_cannot_work_are_refused_naming_the_file() {
    let dir = tmp("blank-boards");
    std::fs::create_dir_all(&dir).unwrap();
    let cam = irmirror_geom::PinholeCamera::from_fov(64, 48, 1.2).unwrap();
    std::fs::write(
        dir.join("depth.json"),
        irmirror_capture::opencv::intrinsics_json(&cam),
    )
    .unwrap();
    let grey = |w: u32, h: u32| Image {
        width: w,
        height: h,
        data: vec![100u8; (w * h) as usize],
    };
    for k in 0..4 {
        irmirror_capture::write_gray8_png(&grey(80, 60), &dir.join(format!("thermal_{k}.png")))
            .unwrap();
        irmirror_capture::write_gray8_png(&grey(64, 48), &dir.join(format!("rgb_{k}.png")))
            .unwrap();
    }
    let out = tmp("never.toml");
    let call = |extra: &[&str]| {
        let mut a = vec![
            "capture",
            "calibrate",
            dir.to_str().unwrap(),
            "--square-mm",
            "30",
        ];
        a.extend_from_slice(extra);
        irmirror(&a)
    };
    let depth = dir.join("depth.json");
    let o = call(&[
        "--depth-camera",
        depth.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("0 of 4 pairs") && e.contains("checkerboard not found"),
        "{e}"
    );
    assert!(!out.exists());
    // Thermal images of different sizes.
    irmirror_capture::write_gray8_png(&grey(81, 60), &dir.join("thermal_3.png")).unwrap();
    let o = call(&[
        "--depth-camera",
        depth.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        stderr(&o).contains("thermal_3.png") && stderr(&o).contains("one camera"),
        "{}",
        stderr(&o)
    );
    // A bad board and a missing intrinsics file.
    let o = call(&[
        "--depth-camera",
        depth.to_str().unwrap(),
        "--board",
        "7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stderr(&o).contains("COLSxROWS"), "{}", stderr(&o));
    let o = call(&[
        "--depth-camera",
        "/nonexistent/depth.json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        stderr(&o).contains("/nonexistent/depth.json"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

/// A simulated capture's thermal frame re-expressed as a FLIR i7's raw counts (the real file's
/// Planck constants) goes through `capture import`; the imported capture reads the same
/// temperatures, and stage 0 runs on it and draws the depth edges over the thermal frame.
#[test]
fn a_flir_jpeg_is_imported_into_a_capture_reconstruction_reads() {
    let sim = tmp("import-sim");
    let o = irmirror(&[
        "simulate",
        "--regime",
        "tabletop-wide",
        "--seed",
        "4",
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cap = Capture::load(&sim).unwrap();
    let base = std::fs::read(shipped_flir()).unwrap();
    let info = flir::camera_info_record(&base).unwrap();
    let planck = flir::parse(
        &flir::build(
            &base,
            &info,
            &Image {
                width: 1,
                height: 1,
                data: vec![12000],
            },
        )
        .unwrap(),
    )
    .unwrap()
    .planck;
    let to_jpeg = |k: &Image<f64>| {
        let raw = k.map(|t| planck.raw_of(t).round() as u16);
        flir::build(&base, &info, &raw).unwrap()
    };
    let work = tmp("import-in");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::write(work.join("IR_0002.jpg"), to_jpeg(&cap.thermal_k)).unwrap();
    std::fs::write(
        work.join("IR_0001.jpg"),
        to_jpeg(&cap.thermal_background_k[0]),
    )
    .unwrap();
    let rig = RigFile {
        depth_camera: cap.file.depth_camera,
        thermal_camera: cap.file.thermal_camera.clone(),
        fit: None,
    };
    std::fs::write(work.join("rig.toml"), toml::to_string(&rig).unwrap()).unwrap();
    std::fs::copy(sim.join("depth.png"), work.join("depth.png")).unwrap();
    std::fs::copy(sim.join("masks/object_0.png"), work.join("mask0.png")).ok();
    let before = read_tree(&work);
    let out = tmp("imported");
    let p = |n: &str| work.join(n).to_str().unwrap().to_string();
    let mut args: Vec<String> = [
        "capture",
        "import",
        "--thermal",
        &p("IR_0002.jpg"),
        "--background",
        &p("IR_0001.jpg"),
        "--depth",
        &p("depth.png"),
        "--rig",
        &p("rig.toml"),
        "--out",
        out.to_str().unwrap(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for o in &cap.file.objects {
        args.extend(["--object".to_string(), o.category.to_string()]);
    }
    let o = irmirror(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_tree(&work), before, "the inputs were modified");
    let imported = Capture::load(&out).unwrap();
    let worst = imported
        .thermal_k
        .data
        .iter()
        .zip(&cap.thermal_k.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.02, "temperatures differ by up to {worst} K");
    let text = std::fs::read_to_string(out.join("capture.toml")).unwrap();
    assert!(
        text.contains("counts-planck") && text.contains("FLIR_i7"),
        "{text}"
    );

    let res = tmp("imported-pre");
    let o = irmirror(&[
        "reconstruct",
        out.to_str().unwrap(),
        "--stage",
        "preprocess",
        "--out",
        res.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let overlay = image::open(res.join("debug/depth_edges_on_thermal.png"))
        .unwrap()
        .into_rgb8();
    let red = overlay
        .pixels()
        .filter(|p| p[0] == 255 && p[1] == 40)
        .count();
    assert!(red > 50, "{red} depth-edge pixels drawn");
}

#[test]
fn import_refuses_files_it_cannot_use_and_writes_nothing() {
    let work = tmp("import-bad");
    std::fs::create_dir_all(&work).unwrap();
    let cam = |w, h| irmirror_geom::PinholeCamera::from_fov(w, h, 1.0).unwrap();
    let rig = RigFile {
        depth_camera: cam(32, 24),
        thermal_camera: irmirror_capture::ThermalCameraSpec {
            intrinsics: cam(120, 120),
            depth_from_thermal: irmirror_geom::transform::RigidFile::from_rigid(
                &irmirror_geom::Rigid3::<f64>::identity(),
            ),
            psf_sigma_px: None,
        },
        fit: None,
    };
    std::fs::write(work.join("rig.toml"), toml::to_string(&rig).unwrap()).unwrap();
    irmirror_capture::write_gray16_png(
        &Image {
            width: 30,
            height: 24,
            data: vec![900u16; 720],
        },
        &work.join("depth.png"),
    )
    .unwrap();
    let base = std::fs::read(shipped_flir()).unwrap();
    let info = flir::camera_info_record(&base).unwrap();
    let good = flir::build(
        &base,
        &info,
        &Image {
            width: 120,
            height: 120,
            data: vec![12500; 14400],
        },
    )
    .unwrap();
    std::fs::write(work.join("good.jpg"), good).unwrap();
    let out = tmp("import-bad-out");
    let call = |thermal: &Path, object: &str| {
        irmirror(&[
            "capture",
            "import",
            "--thermal",
            thermal.to_str().unwrap(),
            "--depth",
            work.join("depth.png").to_str().unwrap(),
            "--rig",
            work.join("rig.toml").to_str().unwrap(),
            "--object",
            object,
            "--out",
            out.to_str().unwrap(),
        ])
    };
    // The real sample: its raw frame was stripped.
    let o = call(&shipped_flir(), "bowl");
    assert!(
        stderr(&o).contains("exiftool_FLIR_i7.jpg") && stderr(&o).contains("stripped"),
        "{}",
        stderr(&o)
    );
    // A PNG is not a radiometric JPEG.
    let o = call(&work.join("depth.png"), "bowl");
    assert!(
        stderr(&o).contains("depth.png") && stderr(&o).contains("not a JPEG"),
        "{}",
        stderr(&o)
    );
    // The depth image is 30×24, the rig's depth camera 32×24.
    let o = call(&work.join("good.jpg"), "bowl");
    assert!(
        stderr(&o).contains("depth.png") && stderr(&o).contains("32×24"),
        "{}",
        stderr(&o)
    );
    let o = call(&work.join("good.jpg"), "teapot");
    assert!(
        !o.status.success() && stderr(&o).contains("teapot"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // With a depth image of the rig's size: a background of another frame size, and an RGB
    // image that is not the depth camera's size.
    let depth32 = work.join("depth32.png");
    irmirror_capture::write_gray16_png(
        &Image {
            width: 32,
            height: 24,
            data: vec![900u16; 768],
        },
        &depth32,
    )
    .unwrap();
    let small = Image {
        width: 60,
        height: 60,
        data: vec![12500u16; 3600],
    };
    std::fs::write(
        work.join("bg.jpg"),
        flir::build(&base, &info, &small).unwrap(),
    )
    .unwrap();
    image::RgbImage::new(30, 24)
        .save(work.join("rgb.png"))
        .unwrap();
    // `capture import` of good.jpg into `out` with the given depth image and further flags.
    let (good, rig) = (work.join("good.jpg"), work.join("rig.toml"));
    let import = |depth: &Path, extra: &[&str]| {
        let mut args = vec![
            "capture",
            "import",
            "--thermal",
            good.to_str().unwrap(),
            "--depth",
            depth.to_str().unwrap(),
            "--rig",
            rig.to_str().unwrap(),
            "--object",
            "bowl",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        irmirror(&args)
    };
    let o = import(
        &depth32,
        &["--background", work.join("bg.jpg").to_str().unwrap()],
    );
    assert!(
        stderr(&o).contains("bg.jpg") && stderr(&o).contains("differ"),
        "{}",
        stderr(&o)
    );
    let o = import(&depth32, &["--rgb", work.join("rgb.png").to_str().unwrap()]);
    assert!(
        stderr(&o).contains("rgb.png") && stderr(&o).contains("32×24"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // The same depth image with this capture's own intrinsics (another resolution mode).
    let own = irmirror_geom::PinholeCamera::from_fov(30, 24, 1.0).unwrap();
    std::fs::write(
        work.join("depth30.json"),
        irmirror_capture::opencv::intrinsics_json(&own),
    )
    .unwrap();
    let o = import(
        &work.join("depth.png"),
        &[
            "--depth-camera",
            work.join("depth30.json").to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(Capture::load(&out).unwrap().depth_camera.width, 30);
}
