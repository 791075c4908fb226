//! The binary as a user meets it: exit codes, messages, determinism, atomic outputs.

use std::path::Path;
use std::process::Command;

mod common;

use common::{irmirror, read_tree, stderr, tmp};

#[test]
fn help_explains_every_command() {
    let o = Command::new(env!("CARGO_BIN_EXE_irmirror"))
        .arg("--help")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    for cmd in ["demo", "body"] {
        assert!(text.contains(cmd), "{text}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_irmirror"))
        .args(["body", "--help"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    for cmd in ["import", "check", "sample"] {
        assert!(text.contains(cmd), "{text}");
    }
    // Every command's help shows how it is called.
    for cmd in [
        "demo",
        "simulate",
        "reconstruct",
        "score",
        "train-pose-prior",
        "eval",
        "train-sdf",
        "body",
        "bench",
        "capture",
        "capture calibrate",
        "capture import",
        "capture boards",
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_irmirror"))
            .args(cmd.split(' ').chain(["--help"]))
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success() && text.contains("Example: irmirror"),
            "{cmd}: {text}"
        );
    }
}

#[test]
fn demo_is_deterministic_and_complete() {
    let (a, b, c) = (tmp("demo-a"), tmp("demo-b"), tmp("demo-c"));
    for (dir, seed) in [(&a, "5"), (&b, "5"), (&c, "6")] {
        let o = irmirror(&["demo", "--out", dir.to_str().unwrap(), "--seed", seed]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (fa, fb, fc) = (read_tree(&a), read_tree(&b), read_tree(&c));
    let names: Vec<&str> = fa.iter().map(|f| f.0.as_str()).collect();
    for f in [
        "body.ply",
        "body.obj",
        "body.glb",
        "params.json",
        "eval.json",
        "overlay.png",
        "loss_curve.svg",
        "views/third_camera.png",
        "views/overview.png",
        "objects/object_0.ply",
        "objects/object_0.glb",
        "hypotheses/body_0.ply",
        "reflection_mask.png",
        "fitted_mask.png",
        "person_truth.glb",
        "person_truth.obj",
        "person_truth.ply",
        "report.html",
        "run.toml",
        "capture/capture.toml",
        "capture/thermal.png",
    ] {
        assert!(names.contains(&f), "missing {f} in {names:?}");
    }
    assert_eq!(fa, fb, "same seed, different output");
    assert_ne!(fa, fc, "different seeds gave identical output");
    // Re-running into an existing result replaces it and leaves no partial directory behind.
    let o = irmirror(&["demo", "--out", a.to_str().unwrap(), "--seed", "6"]);
    assert!(o.status.success());
    assert_eq!(read_tree(&a), fc);
    let parent = a.parent().unwrap();
    let leftovers = std::fs::read_dir(parent).unwrap().filter(|e| {
        let n = e
            .as_ref()
            .unwrap()
            .file_name()
            .to_string_lossy()
            .into_owned();
        n.contains(&format!("irmirror-cli-{}-demo", std::process::id())) && n.contains("partial")
    });
    assert_eq!(leftovers.count(), 0);
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn bad_inputs_fail_cleanly() {
    let vectors =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/body/test_vectors_body36.json");
    let mut cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "body".into(),
                "import".into(),
                "--wheel".into(),
                "/nonexistent.whl".into(),
                "--out".into(),
                tmp("x.safetensors").display().to_string(),
            ],
            "/nonexistent.whl",
        ),
        (
            vec![
                "body".into(),
                "check".into(),
                "--vectors".into(),
                "/nonexistent.json".into(),
            ],
            "/nonexistent.json",
        ),
        (
            vec![
                "body".into(),
                "check".into(),
                "--vectors".into(),
                vectors.display().to_string(),
                "--asset".into(),
                "/nonexistent.safetensors".into(),
            ],
            "nonexistent.safetensors",
        ),
        (
            vec![
                "body".into(),
                "import".into(),
                "--wheel".into(),
                "x.whl".into(),
                "--out".into(),
                "y".into(),
                "--rank".into(),
                "zero".into(),
            ],
            "--rank",
        ),
    ];
    // train-pose-prior: each case's flags after `--out`; the benchmark's own persons are refused
    // as training poses.
    let noisy = tmp("noisy.safetensors").display().to_string();
    let bench_poses = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/poses/mocap_bvhtools.safetensors")
        .display()
        .to_string();
    for (flags, expect) in [
        (
            &["--joint-noise-deg", "90"][..],
            "--joint-noise-deg within 0–45",
        ),
        (
            &["--real-fraction", "0.5"],
            "--real-fraction needs --real-poses",
        ),
        (
            &[
                "--real-poses",
                "/nonexistent.safetensors",
                "--real-fraction",
                "1.5",
            ],
            "--real-fraction must lie within 0–1",
        ),
        (
            &["--real-poses", "/nonexistent.safetensors"],
            "/nonexistent.safetensors",
        ),
        (
            &["--real-poses", bench_poses.as_str()],
            "119 of its poses are the benchmark's persons",
        ),
    ] {
        let args = ["train-pose-prior", "--out", noisy.as_str()]
            .iter()
            .chain(flags)
            .map(|a| a.to_string())
            .collect();
        cases.push((args, expect));
    }
    for (args, expect) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = irmirror(&args);
        assert!(!o.status.success(), "{args:?} succeeded");
        let e = stderr(&o);
        assert!(e.contains("error") && e.contains(expect), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{e}");
    }
    assert!(!tmp("noisy.safetensors").exists());
    // A corrupt asset.
    let bad = tmp("bad.safetensors");
    std::fs::write(&bad, b"\x08\x00\x00\x00\x00\x00\x00\x00{}garbage").unwrap();
    let o = irmirror(&[
        "body",
        "sample",
        "--out",
        tmp("s").to_str().unwrap(),
        "--asset",
        bad.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bad.safetensors"), "{}", stderr(&o));
    assert!(!tmp("s").exists(), "a failed run left an output directory");
    std::fs::remove_file(bad).ok();
    // Motion capture: a missing file, a file that is not BVH, and a DeepMimic motion with a
    // short frame are named; nothing written.
    let not_bvh = tmp("notes.bvh");
    std::fs::write(&not_bvh, "just some text\n").unwrap();
    let short = tmp("short_motion.txt");
    std::fs::write(&short, r#"{"Loop": "none", "Frames": [[0.03, 0, 0.9, 0]]}"#).unwrap();
    let out = tmp("poses.safetensors");
    for (file, expect) in [
        ("/nonexistent.bvh", "/nonexistent.bvh"),
        (not_bvh.to_str().unwrap(), "notes.bvh: not a BVH file"),
        (
            short.to_str().unwrap(),
            "short_motion.txt: frame 0: expected 44 finite values",
        ),
    ] {
        let o = irmirror(&["body", "retarget-bvh", file, "--out", out.to_str().unwrap()]);
        assert!(!o.status.success(), "{file} succeeded");
        let e = stderr(&o);
        assert!(e.contains(expect) && !e.contains("panicked"), "{e}");
        assert!(!out.exists() && !out.with_extension("png").exists());
    }
    std::fs::remove_file(not_bvh).ok();
    std::fs::remove_file(short).ok();
}

#[test]
fn body_check_reports_the_builtin_asset_within_tolerance() {
    let vectors =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/body/test_vectors_body36.json");
    // Without --vectors: the reference vectors the repository ships.
    let o = irmirror(&["body", "check", "--tolerance-m", "5e-4"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("skipped") && out.contains("max error"),
        "{out}"
    );
    let o = irmirror(&[
        "body",
        "check",
        "--vectors",
        vectors.to_str().unwrap(),
        "--tolerance-m",
        "1e-9",
    ]);
    assert!(!o.status.success(), "an impossible tolerance passed");
}

#[test]
fn benches_print_their_tables() {
    // Without --scene: the reference scene the repository ships.
    let o = irmirror(&["bench", "render", "--no-dense", "--reps", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("6980 reflected rays")
            && out.contains("IoU 1.0000")
            && out.contains("| fast, ε = 1e-4"),
        "{out}"
    );
    let o = irmirror(&[
        "bench",
        "render",
        "--scene",
        "/nonexistent/scene.json",
        "--no-dense",
    ]);
    assert!(!o.status.success() && stderr(&o).contains("/nonexistent/scene.json"));
    // Reflection size per regime: one seed each, the table and the histogram.
    let png = tmp("regimes").with_extension("png");
    let o = irmirror(&[
        "bench",
        "regimes",
        "--seeds",
        "1",
        "--png",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    for row in [
        "| tabletop | 640×512 | 1 |",
        "| car | 640×512 | 1 |",
        "| tabletop-wide | 160×120 | 1 |",
    ] {
        assert!(out.contains(row), "{out}");
    }
    assert!(image::open(&png).is_ok());
    std::fs::remove_file(&png).ok();
    let o = irmirror(&["bench", "regimes", "--seeds", "0"]);
    assert!(!o.status.success() && stderr(&o).contains("--seeds"));
    let o = irmirror(&["bench", "body", "--reps", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("| backward"));
    // Stage 1 against the truth: seed 0 of the tabletop preset is a bowl and a mug.
    let o = irmirror(&["bench", "objects", "--seeds", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("| 0 | two-parameter | bowl |")
            && out.contains("| 0 | two-parameter | mug |")
            && out.contains("| mug | two-parameter | 1 |")
            && out.contains("| ray angle (°) |"),
        "{out}"
    );
    // Its mug shows three depth pixels of its handle: counted as seen, so its rotation is summarised.
    assert!(
        out.contains(" (3 px) |") && !out.contains("handle hidden"),
        "{out}"
    );
    let o = irmirror(&["bench", "objects", "--seeds", "0"]);
    assert!(
        !o.status.success() && stderr(&o).contains("--seeds"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn simulate_writes_a_loadable_deterministic_capture() {
    let (a, b) = (tmp("sim-a"), tmp("sim-b"));
    for d in [&a, &b] {
        let o = irmirror(&[
            "simulate",
            "--preset",
            "car",
            "--out",
            d.to_str().unwrap(),
            "--seed",
            "2",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (ta, tb) = (read_tree(&a), read_tree(&b));
    assert_eq!(ta, tb, "same seed, different capture");
    for f in [
        "capture.toml",
        "depth.png",
        "thermal.png",
        "thermal_background.png",
        "rgb.png",
        "truth/body.json",
        "truth/body.ply",
        "truth/scene.toml",
        "truth/third_view.png",
        "truth/stats.json",
        "preview/thermal.png",
    ] {
        assert!(ta.iter().any(|(n, _)| n == f), "missing {f}");
    }
    let cap = irmirror_capture::Capture::load(&a).unwrap();
    assert_eq!(cap.objects[0].category, irmirror_geom::Category::Car);
    // Re-simulating from the written scene reproduces the capture.
    let c = tmp("sim-c");
    let o = irmirror(&[
        "simulate",
        "--scene",
        a.join("truth/scene.toml").to_str().unwrap(),
        "--out",
        c.to_str().unwrap(),
        "--seed",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        read_tree(&c)
            .iter()
            .filter(|(n, _)| n.ends_with(".png"))
            .collect::<Vec<_>>(),
        ta.iter()
            .filter(|(n, _)| n.ends_with(".png"))
            .collect::<Vec<_>>()
    );
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
    // A bad scene file is an error, and leaves no output.
    let bad = tmp("bad-scene.toml");
    std::fs::write(&bad, "ambient_c = \"warm\"\n").unwrap();
    let out = tmp("sim-bad");
    let o = irmirror(&[
        "simulate",
        "--scene",
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("bad-scene.toml"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // --out never replaces a file or a directory that is not an irmirror result.
    let precious = tmp("precious");
    std::fs::create_dir_all(&precious).unwrap();
    std::fs::write(precious.join("thesis.tex"), "do not delete").unwrap();
    let o = irmirror(&["demo", "--out", precious.to_str().unwrap()]);
    assert!(
        !o.status.success() && stderr(&o).contains("not an irmirror result"),
        "{}",
        stderr(&o)
    );
    assert!(precious.join("thesis.tex").exists());
    let o = irmirror(&[
        "simulate",
        "--out",
        precious.join("thesis.tex").to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("not a directory"));
    std::fs::remove_dir_all(&precious).ok();
}

#[test]
fn train_sdf_trains_a_loadable_prior_and_refuses_bad_input() {
    let dir = tmp("train-sdf");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("mug.safetensors");
    let o = irmirror(&[
        "train-sdf",
        "--category",
        "mug",
        "--out",
        out.to_str().unwrap(),
        "--shapes",
        "2",
        "--steps",
        "10",
        "--samples",
        "500",
        "--held-out",
        "0",
        "--width",
        "32",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let net = irmirror_sdf::SdfNet::load(&out).unwrap();
    assert_eq!(
        (net.category, net.width, net.train_latents.len()),
        (irmirror_sdf::Category::Mug, 32, 2)
    );
    assert!(net.metadata["command"].starts_with("irmirror train-sdf --category mug"));
    assert!(out.with_extension("json").is_file());
    // Bad input: clear message, non-zero exit, nothing written.
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::write(meshes.join("broken.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let bad = dir.join("bad.safetensors");
    for (args, needle) in [
        (
            vec!["--category", "chair"],
            "invalid value 'chair' for '--category",
        ),
        (
            vec!["--category", "sphere"],
            "priors are trained for bowl, mug and car",
        ),
        (
            vec!["--category", "mug", "--meshes", meshes.to_str().unwrap()],
            "broken.obj",
        ),
        (
            vec![
                "--category",
                "mug",
                "--meshes",
                dir.join("none").to_str().unwrap(),
            ],
            "cannot list",
        ),
        (vec!["--category", "mug", "--steps", "0"], "--steps"),
    ] {
        let mut all = vec!["train-sdf", "--out", bad.to_str().unwrap()];
        all.extend(args);
        let o = irmirror(&all);
        assert!(!o.status.success());
        assert!(stderr(&o).contains(needle), "{needle}: {}", stderr(&o));
        assert!(!bad.exists());
    }
    let o = irmirror(&[
        "train-sdf",
        "--category",
        "mug",
        "--out",
        dir.join("x.bin").to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains(".safetensors"));
}
