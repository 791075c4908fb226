//! `irmirror capture …`: calibrate a real thermal + RGB-D rig, import a real camera's files into
//! a capture, and simulate calibration views to try both on (docs/real-captures.md).

use crate::output::{Staging, write_file_atomic, write_text};
use anyhow::{Context, Result, bail};
use clap::{Subcommand, ValueEnum};
use irmirror_calib::{Board, MIN_VIEWS, ViewPair, find_board};
use irmirror_capture::opencv::{intrinsics_json, read_intrinsics};
use irmirror_capture::{
    Capture, CaptureFile, DepthSpec, FORMAT, ObjectSpec, RgbSpec, RigFile, RigFit,
    ThermalCameraSpec, ThermalSpec, flir, read_gray_any, read_gray16_png, write_gray8_png,
    write_gray16_png,
};
use irmirror_geom::Category;
use irmirror_geom::transform::RigidFile;
use std::path::{Path, PathBuf};

/// Thermal camera class of the simulated rig.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ThermalClass {
    /// Boson-class 640×512, 50°.
    Boson,
    /// Lepton-class 160×120, 57°.
    Lepton,
}

/// Subcommands of `irmirror capture`.
#[derive(Subcommand)]
pub enum CaptureCommand {
    /// Calibrate the thermal camera against the depth camera from checkerboard views.
    ///
    /// DIR holds pairs `thermal_<name>.{png,tif,tiff,npy}` (any units) and `rgb_<name>.png`
    /// (the depth camera's registered colour or IR image) taken at the same moment. Finds the
    /// board's inner corners in both, estimates the thermal intrinsics (Zhang's method, then a
    /// bundle adjustment) and `depth_from_thermal`, prints the reprojection errors per view and
    /// writes rig.toml: capture.toml's [depth_camera] and [thermal_camera] tables.
    ///
    /// Example: irmirror capture calibrate calib/ --board 7x5 --square-mm 35 --depth-camera depth.json --out rig.toml
    Calibrate {
        /// Directory of image pairs (read only).
        dir: PathBuf,
        /// The board's inner corners, COLSxROWS (squares minus one each way).
        #[arg(long, default_value = "7x5")]
        board: String,
        /// Side of one square, millimetres (measure the print).
        #[arg(long)]
        square_mm: f64,
        /// The depth camera's intrinsics: an OpenCV/ROS JSON or YAML file (`image_width`,
        /// `image_height`, `camera_matrix`), as the RGB-D camera's SDK reports them.
        #[arg(long)]
        depth_camera: PathBuf,
        /// Output rig file (TOML).
        #[arg(long, default_value = "rig.toml")]
        out: PathBuf,
    },
    /// Make a capture directory from a real camera's files.
    ///
    /// The thermal frame is a FLIR radiometric JPEG (raw counts and the camera's Planck
    /// constants are kept: `counts-planck` units); the depth a 16-bit PNG with --depth-units-m
    /// metres per count; the cameras come from `capture calibrate`'s rig.toml. The result is
    /// checked by the capture loader before it appears.
    ///
    /// Example: irmirror capture import --thermal IR_0042.jpg --background IR_0041.jpg --depth depth.png --rig rig.toml --object bowl --out my-capture
    Import {
        /// FLIR radiometric JPEG with the person present.
        #[arg(long)]
        thermal: PathBuf,
        /// FLIR radiometric JPEGs of the same scene without the person (recommended).
        #[arg(long)]
        background: Vec<PathBuf>,
        /// 16-bit depth PNG (0 = no measurement), depth-camera size.
        #[arg(long)]
        depth: PathBuf,
        /// Metres per depth count.
        #[arg(long, default_value_t = 0.001)]
        depth_units_m: f64,
        /// Optional 8-bit RGB PNG registered to the depth camera.
        #[arg(long)]
        rgb: Option<PathBuf>,
        /// The rig (from `capture calibrate`, or written by hand in its layout).
        #[arg(long)]
        rig: PathBuf,
        /// The depth camera's intrinsics for this capture (OpenCV/ROS JSON or YAML), when they
        /// differ from the rig's: another resolution mode of the same camera
        /// (`depth_from_thermal` relates the camera frames, so it still holds).
        #[arg(long)]
        depth_camera: Option<PathBuf>,
        /// A reflecting object's category (bowl, mug, car, sphere), optionally with a mask PNG
        /// in depth-camera pixels: `mug` or `mug=mask.png`. Repeat for each object.
        #[arg(long, required = true)]
        object: Vec<String>,
        /// Output capture directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Simulate checkerboard views of a rig with known calibration (to try `calibrate` on).
    ///
    /// Writes thermal_NN.png (16-bit counts; a heated board with foil squares), rgb_NN.png
    /// (the depth camera's grey image), depth_camera.json (OpenCV layout) and truth.toml (the
    /// rig's true calibration, rig.toml's layout).
    ///
    /// Example: irmirror capture boards --out calib --views 15
    Boards {
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Thermal camera class.
        #[arg(long, value_enum, default_value = "boson")]
        thermal: ThermalClass,
        /// Number of views.
        #[arg(long, default_value_t = 15)]
        views: usize,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

/// Runs a `capture` subcommand.
pub fn run(cmd: CaptureCommand) -> Result<()> {
    match cmd {
        CaptureCommand::Calibrate {
            dir,
            board,
            square_mm,
            depth_camera,
            out,
        } => calibrate(&dir, &board, square_mm, &depth_camera, &out),
        CaptureCommand::Import {
            thermal,
            background,
            depth,
            depth_units_m,
            rgb,
            rig,
            depth_camera,
            object,
            out,
        } => import(&ImportArgs {
            thermal: &thermal,
            background: &background,
            depth: &depth,
            depth_units_m,
            rgb: rgb.as_deref(),
            rig: &rig,
            depth_camera: depth_camera.as_deref(),
            objects: &object,
            out: &out,
        }),
        CaptureCommand::Boards {
            out,
            thermal,
            views,
            seed,
        } => boards(&out, thermal, views, seed),
    }
}

fn parse_board(text: &str, square_mm: f64) -> Result<Board> {
    let (c, r) = text
        .split_once(['x', 'X', '×'])
        .with_context(|| format!("--board {text}: expected COLSxROWS, e.g. 7x5"))?;
    let (cols, rows): (u32, u32) = (
        c.trim()
            .parse()
            .with_context(|| format!("--board {text}"))?,
        r.trim()
            .parse()
            .with_context(|| format!("--board {text}"))?,
    );
    if cols < 2 || rows < 2 || cols * rows > 2500 {
        bail!("--board {text}: need at least 2×2 and at most 2500 inner corners");
    }
    if !(square_mm.is_finite() && square_mm > 0.0 && square_mm < 1000.0) {
        bail!("--square-mm {square_mm}: must be a positive size in millimetres");
    }
    Ok(Board {
        cols,
        rows,
        square_m: square_mm * 1e-3,
    })
}

/// `(name, thermal, rgb)` image triples in `dir`.
fn pairs_in(dir: &Path) -> Result<Vec<(String, PathBuf, PathBuf)>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot read the directory", dir.display()))?;
    let mut thermal = std::collections::BTreeMap::new();
    let mut rgb = std::collections::BTreeMap::new();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some((stem, ext)) = name.rsplit_once('.') else {
            continue;
        };
        let ext = ext.to_ascii_lowercase();
        if let Some(k) = stem.strip_prefix("thermal_")
            && ["png", "tif", "tiff", "npy"].contains(&ext.as_str())
        {
            thermal.insert(k.to_string(), e.path());
        } else if let Some(k) = stem.strip_prefix("rgb_")
            && ["png", "jpg", "jpeg"].contains(&ext.as_str())
        {
            rgb.insert(k.to_string(), e.path());
        }
    }
    let out: Vec<_> = thermal
        .into_iter()
        .filter_map(|(k, t)| rgb.get(&k).map(|r| (k, t, r.clone())))
        .collect();
    if out.is_empty() {
        bail!(
            "{}: no image pairs (expected thermal_<name>.png with rgb_<name>.png of the same <name>)",
            dir.display()
        );
    }
    Ok(out)
}

fn calibrate(
    dir: &Path,
    board: &str,
    square_mm: f64,
    depth_camera: &Path,
    out: &Path,
) -> Result<()> {
    let board = parse_board(board, square_mm)?;
    let depth = read_intrinsics(depth_camera)?;
    if depth.distortion > 1e-3 {
        eprintln!(
            "warning: {} states lens distortion up to {:.3}: the capture format is pinhole, so use images the camera's SDK has undistorted (and their intrinsics)",
            depth_camera.display(),
            depth.distortion
        );
    }
    let depth = depth.camera;
    let pairs = pairs_in(dir)?;
    let mut views = Vec::new();
    let mut skipped = Vec::new();
    let mut thermal_size = None;
    for (name, tpath, rpath) in &pairs {
        let t = read_gray_any(tpath)?;
        let r = read_gray_any(rpath)?;
        match thermal_size {
            None => thermal_size = Some((t.width, t.height, tpath.clone())),
            Some((w, h, ref first)) if (w, h) != (t.width, t.height) => bail!(
                "{}: is {}×{}, but {} is {w}×{h}: all thermal images must come from one camera",
                tpath.display(),
                t.width,
                t.height,
                first.display()
            ),
            _ => {}
        }
        if (r.width, r.height) != (depth.width, depth.height) {
            bail!(
                "{}: is {}×{}, but the depth camera ({}) is {}×{}: use the image registered to the depth camera",
                rpath.display(),
                r.width,
                r.height,
                depth_camera.display(),
                depth.width,
                depth.height
            );
        }
        match (find_board(&t, &board), find_board(&r, &board)) {
            (Ok(thermal), Ok(depth)) => views.push(ViewPair {
                name: name.clone(),
                thermal,
                depth,
            }),
            (Err(m), _) => skipped.push(format!("{}: {m}", tpath.display())),
            (_, Err(m)) => skipped.push(format!("{}: {m}", rpath.display())),
        }
    }
    for s in &skipped {
        eprintln!("skipped {s}");
    }
    let Some((tw, th, _)) = thermal_size else {
        bail!("{}: no image pairs", dir.display());
    };
    if views.len() < MIN_VIEWS {
        let first = skipped.first().map(String::as_str).unwrap_or("");
        bail!(
            "{}: the board was found in both images of {} of {} pairs; at least {MIN_VIEWS} are needed. First problem: {first}",
            dir.display(),
            views.len(),
            pairs.len()
        );
    }
    let cal = irmirror_calib::calibrate(&views, &board, (tw, th), &depth)?;
    println!("view        thermal RMS (px)   depth RMS (px)");
    for (n, t, d) in &cal.per_view {
        println!("{n:<12}{t:>10.3}{d:>18.3}");
    }
    let sd = &cal.std_devs;
    let rot_sd = sd[4..7].iter().fold(0.0f64, |a, v| a.max(*v)).to_degrees();
    let tr_sd = sd[7..10].iter().fold(0.0f64, |a, v| a.max(*v)) * 1e3;
    let t = cal.depth_from_thermal.translation;
    println!(
        "thermal: fx {:.2} ± {:.2}, fy {:.2} ± {:.2}, cx {:.2} ± {:.2}, cy {:.2} ± {:.2} px; depth_from_thermal translation ({:.1}, {:.1}, {:.1}) mm ± {tr_sd:.2} mm, rotation ± {rot_sd:.3}°; RMS {:.3} px thermal, {:.3} px depth over {} views",
        cal.thermal.fx,
        sd[0],
        cal.thermal.fy,
        sd[1],
        cal.thermal.cx,
        sd[2],
        cal.thermal.cy,
        sd[3],
        t.x * 1e3,
        t.y * 1e3,
        t.z * 1e3,
        cal.rms_thermal_px,
        cal.rms_depth_px,
        views.len()
    );
    if cal.rms_thermal_px > 1.0 || cal.rms_depth_px > 1.0 {
        eprintln!(
            "warning: reprojection errors above 1 pixel: lens distortion, a bent board or images not taken at the same moment?"
        );
    }
    let rig = RigFile {
        depth_camera: depth,
        thermal_camera: ThermalCameraSpec {
            intrinsics: cal.thermal,
            depth_from_thermal: RigidFile::from_rigid(&cal.depth_from_thermal),
            psf_sigma_px: None,
        },
        fit: Some(RigFit {
            views: views.len(),
            skipped,
            board: format!(
                "{}x{} inner corners, {} mm squares",
                board.cols, board.rows, square_mm
            ),
            rms_thermal_px: cal.rms_thermal_px,
            rms_depth_px: cal.rms_depth_px,
            intrinsics_sd_px: [sd[0], sd[1], sd[2], sd[3]],
            rotation_sd_deg: rot_sd,
            translation_sd_mm: tr_sd,
        }),
    };
    let text = format!(
        "# irmirror capture calibrate {} (irmirror {}). Copy [depth_camera] and [thermal_camera]\n# into a capture.toml, or pass this file to `irmirror capture import --rig`.\n{}",
        dir.display(),
        env!("CARGO_PKG_VERSION"),
        toml::to_string(&rig)?
    );
    write_file_atomic(out, "--out", &[dir], &text)?;
    println!("wrote {}", out.display());
    Ok(())
}

struct ImportArgs<'a> {
    thermal: &'a Path,
    background: &'a [PathBuf],
    depth: &'a Path,
    depth_units_m: f64,
    rgb: Option<&'a Path>,
    rig: &'a Path,
    depth_camera: Option<&'a Path>,
    objects: &'a [String],
    out: &'a Path,
}

fn import(a: &ImportArgs) -> Result<()> {
    let mut objects = Vec::new();
    let mut masks = Vec::new();
    for (k, spec) in a.objects.iter().enumerate() {
        let (cat, mask) = match spec.split_once('=') {
            Some((c, m)) => (c, Some(PathBuf::from(m))),
            None => (spec.as_str(), None),
        };
        let category: Category = cat
            .parse()
            .map_err(|e| anyhow::anyhow!("--object {spec}: {e}"))?;
        let mask_name = mask.as_ref().map(|_| format!("masks/object_{k}.png"));
        if let Some(m) = mask {
            masks.push((m, mask_name.clone().unwrap_or_default()));
        }
        objects.push(ObjectSpec {
            category,
            mask: mask_name,
        });
    }
    let rig_text = std::fs::read_to_string(a.rig)
        .with_context(|| format!("{}: cannot read", a.rig.display()))?;
    let mut rig: RigFile = toml::from_str(&rig_text).with_context(|| {
        format!(
            "{}: not a rig file (capture calibrate's rig.toml)",
            a.rig.display()
        )
    })?;
    if let Some(path) = a.depth_camera {
        let cam = read_intrinsics(path)?;
        if cam.distortion > 1e-3 {
            eprintln!(
                "warning: {} states lens distortion: the depth image must be undistorted (the capture format is pinhole)",
                path.display()
            );
        }
        rig.depth_camera = cam.camera;
    }
    let frame = flir::read(a.thermal)?;
    let tc = &rig.thermal_camera.intrinsics;
    if (frame.raw.width, frame.raw.height) != (tc.width, tc.height) {
        bail!(
            "{}: its raw frame is {}×{}, but the rig's thermal camera ({}) is {}×{}",
            a.thermal.display(),
            frame.raw.width,
            frame.raw.height,
            a.rig.display(),
            tc.width,
            tc.height
        );
    }
    let mut backgrounds = Vec::new();
    for b in a.background {
        let bg = flir::read(b)?;
        if bg.planck != frame.planck
            || bg.raw.width != frame.raw.width
            || bg.raw.height != frame.raw.height
        {
            bail!(
                "{}: its Planck constants or frame size differ from {}: take the background with the same camera and range",
                b.display(),
                a.thermal.display()
            );
        }
        backgrounds.push(bg.raw);
    }
    let depth = read_gray16_png(a.depth)?;
    let dc = &rig.depth_camera;
    if (depth.width, depth.height) != (dc.width, dc.height) {
        bail!(
            "{}: is {}×{}, but the rig's depth camera is {}×{}",
            a.depth.display(),
            depth.width,
            depth.height,
            dc.width,
            dc.height
        );
    }
    let st = Staging::new(a.out, "capture.toml")?;
    write_gray16_png(&frame.raw, &st.path("thermal.png"))?;
    let mut background_names = Vec::new();
    for (k, b) in backgrounds.iter().enumerate() {
        let name = format!("thermal_background_{k}.png");
        write_gray16_png(b, &st.path(&name))?;
        background_names.push(name);
    }
    write_gray16_png(&depth, &st.path("depth.png"))?;
    let rgb = match a.rgb {
        Some(p) => {
            let img = image::open(p).with_context(|| format!("{}: cannot decode", p.display()))?;
            if img.color().channel_count() < 3 || img.color().bytes_per_pixel() > 4 {
                bail!(
                    "{}: expected an 8-bit RGB image, found {:?}",
                    p.display(),
                    img.color()
                );
            }
            if (img.width(), img.height()) != (dc.width, dc.height) {
                bail!(
                    "{}: is {}×{}, but the rig's depth camera is {}×{}: use the colour image registered to depth",
                    p.display(),
                    img.width(),
                    img.height(),
                    dc.width,
                    dc.height
                );
            }
            img.into_rgb8().save(st.path("rgb.png"))?;
            Some(RgbSpec {
                file: "rgb.png".into(),
            })
        }
        None => None,
    };
    if !masks.is_empty() {
        std::fs::create_dir_all(st.path("masks"))?;
    }
    for (src, name) in &masks {
        let m = irmirror_capture::image_io::read_mask(src)?;
        write_gray8_png(&m.map(|b| if b { 255 } else { 0 }), &st.path(name))?;
    }
    let description = format!(
        "irmirror capture import of {} ({}; camera emissivity setting {:.2} and reflected {:.1} °C not applied: a mirror's reflection is read as apparent temperature)",
        a.thermal.display(),
        frame.camera_model,
        frame.emissivity,
        frame.reflected_k - 273.15
    );
    let file = CaptureFile {
        format: FORMAT.into(),
        depth_camera: *dc,
        depth: DepthSpec {
            file: "depth.png".into(),
            units_m: a.depth_units_m,
            up: None,
        },
        thermal_camera: rig.thermal_camera.clone(),
        thermal: ThermalSpec {
            file: "thermal.png".into(),
            units: frame.planck.units(),
            background: background_names,
        },
        rgb,
        objects,
        extra_cameras: vec![],
        description,
    };
    write_text(&st.path("capture.toml"), &toml::to_string(&file)?)?;
    // The loader's checks (units, plausibility, sizes, masks) before the capture appears.
    let staged = st.path("");
    Capture::load(&staged).with_context(|| {
        format!(
            "the imported capture does not load; nothing was written to {}",
            a.out.display()
        )
    })?;
    let dir = st.commit()?;
    let t = flir::Planck::apparent_k(&frame.planck, f64::from(frame.raw_median_range.0));
    println!(
        "wrote {}: {}×{} thermal from a {} (median {:.1} °C apparent), {} background frame(s), {}×{} depth; check it with `irmirror reconstruct {} --stage preprocess` (debug/depth_edges_on_thermal.png)",
        dir.display(),
        frame.raw.width,
        frame.raw.height,
        frame.camera_model,
        t - 273.15,
        backgrounds.len(),
        depth.width,
        depth.height,
        dir.display()
    );
    Ok(())
}

fn boards(out: &Path, thermal: ThermalClass, views: usize, seed: u64) -> Result<()> {
    use irmirror_sim::board::{CheckerBoard, Rig, grey_view, poses, thermal_view};
    if !(MIN_VIEWS..=200).contains(&views) {
        bail!("--views {views}: between {MIN_VIEWS} and 200");
    }
    let preset = match thermal {
        ThermalClass::Boson => irmirror_sim::ThermalPreset::Boson,
        ThermalClass::Lepton => irmirror_sim::ThermalPreset::Lepton,
    };
    let rig = Rig::preset(preset);
    let board = CheckerBoard::default();
    let mut rng = irmirror_geom::rng::seeded(seed, 0);
    let st = Staging::new(out, "truth.toml")?;
    let poses = poses(&rig, &board, views, &mut rng);
    for (k, pose) in poses.iter().enumerate() {
        write_gray16_png(
            &thermal_view(&rig, &board, pose, &mut rng),
            &st.path(&format!("thermal_{k:02}.png")),
        )?;
        write_gray8_png(
            &grey_view(&rig, &board, pose, &mut rng),
            &st.path(&format!("rgb_{k:02}.png")),
        )?;
    }
    write_text(&st.path("depth_camera.json"), &intrinsics_json(&rig.depth))?;
    let truth = RigFile {
        depth_camera: rig.depth,
        thermal_camera: ThermalCameraSpec {
            intrinsics: rig.thermal,
            depth_from_thermal: RigidFile::from_rigid(&rig.depth_from_thermal),
            psf_sigma_px: None,
        },
        fit: None,
    };
    write_text(
        &st.path("truth.toml"),
        &format!(
            "# The simulated rig's true calibration (irmirror capture boards, seed {seed}).\n{}",
            toml::to_string(&truth)?
        ),
    )?;
    let dir = st.commit()?;
    println!(
        "wrote {} views of a {}x{} board ({} mm squares) to {}; try: irmirror capture calibrate {} --board {}x{} --square-mm {} --depth-camera {}/depth_camera.json --out rig.toml",
        poses.len(),
        board.cols,
        board.rows,
        board.square_m * 1e3,
        dir.display(),
        dir.display(),
        board.cols,
        board.rows,
        board.square_m * 1e3,
        dir.display()
    );
    Ok(())
}
