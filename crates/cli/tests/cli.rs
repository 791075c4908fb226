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

/// `eval --limit 1 --full-only` with stage 2 cut to a few steps, plus `args`, into a fresh
/// directory: its output and the result directory.
fn cheap_eval(name: &str, args: &[&str]) -> (std::process::Output, std::path::PathBuf) {
    let dir = tmp(name);
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("cheap.toml");
    std::fs::write(
        &cfg,
        "[human]\ninits = 2\niterations = 2\n[human.search]\nyaw_bins = 2\ndistances = 1\npose_modes = [\"stand\"]\nkeep_scored = 2\nrounds = 1\nfirst_steps = 1\n[human.radiometric]\npolish_iterations = 2\n",
    )
    .unwrap();
    let out = dir.join("out");
    let mut all = vec![
        "eval",
        "--limit",
        "1",
        "--full-only",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    (irmirror(&all), out)
}

/// `eval --basin`: four starts per capture, offset and turned as asked, reported per start and
/// in the table; with a two-step refinement the ends stay about the offset away from the truth
/// (the starts sit on the objects→person line, not at the truth). Bad values: a clear error.
#[test]
fn eval_probes_the_refinement_basin() {
    let (o, out) = cheap_eval(
        "eval-basin",
        &["--cell", "tabletop-wide", "--basin", "0.2,20"],
    );
    let dir = out.parent().unwrap().to_path_buf();
    assert!(o.status.success(), "{}", stderr(&o));
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let basin = results["captures"][0]["diagnosis"]["basin"]
        .as_array()
        .unwrap();
    assert_eq!(basin.len(), 4);
    let mut signs = Vec::new();
    for b in basin {
        let (d, a) = (
            b["offset_m"].as_f64().unwrap(),
            b["turn_deg"].as_f64().unwrap(),
        );
        assert!(
            (d.abs() - 0.2).abs() < 1e-12 && (a.abs() - 20.0).abs() < 1e-12,
            "{b}"
        );
        signs.push((d > 0.0, a > 0.0));
        let root = b["root_error_m"].as_f64().unwrap();
        assert!(
            (root - 0.2).abs() < 0.1,
            "two steps moved the root to {root} m: {b}"
        );
        assert!(b["data_loss"].as_f64().unwrap().is_finite());
    }
    signs.sort();
    signs.dedup();
    assert_eq!(signs.len(), 4, "every sign pair once: {basin:?}");
    let record = std::fs::read_to_string(out.join("run.toml")).unwrap();
    assert!(
        record.contains("[basin]") && record.contains("offset_m = 0.2"),
        "{record}"
    );
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("| tabletop-wide | 1 | stand | 4 (±0.20 m, ±20°) |"),
        "{table}"
    );
    for (arg, needle) in [
        ("--basin=0.3", "METRES,DEGREES"),
        ("--basin=-1,30", "≥ 0"),
        ("--basin=0.3,200", "[0, 180]"),
    ] {
        let bad = dir.join("bad");
        let o = irmirror(&["eval", "--full-only", arg, "--out", bad.to_str().unwrap()]);
        assert!(
            !o.status.success() && stderr(&o).contains(needle),
            "{arg}: {}",
            stderr(&o)
        );
        assert!(!bad.exists());
    }
}

/// `eval --variants full,true-objects --basin 0,0 --basin-poses …`: the oracle run sees the
/// simulator's objects (its own table, paired with the fit), and the basin probe starts from
/// the true root and facing with the poses asked, in turn; an unknown pose is a clear error.
#[test]
fn eval_runs_the_true_objects_oracle_and_chosen_basin_poses() {
    let (o, out) = cheap_eval(
        "eval-oracle",
        &[
            "--cell",
            "tabletop-bowl",
            "--variants",
            "full,true-objects",
            "--basin",
            "0,0",
            "--basin-poses",
            "walk,truth-latent",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let c = &results["captures"][0];
    for v in ["full", "true-objects"] {
        assert!(c["variants"][v]["eval"]["root_error_m"].is_f64(), "{c}");
    }
    let poses: Vec<&str> = c["diagnosis"]["basin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["pose"].as_str().unwrap())
        .collect();
    assert_eq!(poses, ["walk", "truth-latent", "walk", "truth-latent"]);
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    for row in [
        "within 15 cm and 30°, true objects / fitted objects",
        "| tabletop-bowl | 1 | walk | 2 (±0.00 m, ±0°) |",
        "| tabletop-bowl | 1 | truth-latent | 2 (±0.00 m, ±0°) |",
    ] {
        assert!(table.contains(row), "{row}: {table}");
    }
    let bad = out.parent().unwrap().join("bad");
    let o = irmirror(&[
        "eval",
        "--basin",
        "0,0",
        "--basin-poses",
        "moonwalk",
        "--out",
        bad.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("truth-latent"),
        "{}",
        stderr(&o)
    );
    assert!(!bad.exists());
}

/// `eval --shapes family`: the captures' objects come from the learned priors' families, the
/// run record says so, and the diagnosis traces the true (procedural) objects too: the truth's
/// data term through them and stage 1's mirror on the mask are measured, not left out.
#[test]
fn eval_simulates_family_shapes_and_diagnoses_their_mirror() {
    let (o, out) = cheap_eval(
        "eval-family",
        &[
            "--cell",
            "tabletop-mug",
            "--shapes",
            "family",
            "--variants",
            "full,true-objects",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let record = std::fs::read_to_string(out.join("run.toml")).unwrap();
    assert!(record.contains("shapes = \"family\""), "{record}");
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let d = &results["captures"][0]["diagnosis"];
    let through_truth = d["truth_loss_true_objects"].as_f64().unwrap();
    let angle = d["mask_ray_angle_deg"].as_f64().unwrap();
    assert!(
        through_truth.is_finite() && (0.0..180.0).contains(&angle),
        "{d}"
    );
    // The oracle has no fitted counterpart of a family shape: a recorded error, not a run.
    let oracle = &results["captures"][0]["variants"]["true-objects"];
    assert!(
        oracle["eval"].is_null() && oracle["error"].as_str().unwrap().contains("two-parameter"),
        "{oracle}"
    );
}

#[test]
fn eval_writes_table_results_and_report() {
    // One capture per cell, full model only (the whole quick set is the ignored test below).
    let out = tmp("eval");
    let o = irmirror(&[
        "eval",
        "--preset",
        "quick",
        "--limit",
        "1",
        "--full-only",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    for row in [
        "| 2-D keypoints, normalised | tabletop-bowl | 1 |",
        "| 3-D keypoints, normalised | tabletop-mug | 1 |",
        "| root error (m) | car | 1 |",
        "| mean per-vertex error (m) | tabletop-wide | 1 |",
        "| cell | n | success | search failure | information / model failure | of the search failures, reachable by our model | full model failed |",
        "| true facing among the hypotheses |",
    ] {
        assert!(table.contains(row), "{table}");
    }
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let caps = results["captures"].as_array().unwrap();
    assert_eq!(caps.len(), 4);
    for c in caps {
        assert_eq!(c["variants"].as_object().unwrap().len(), 1);
        // The random baseline sits at the true root.
        assert!(c["random"][0]["root_error_m"].as_f64().unwrap() < 1e-6);
        // Every capture is diagnosed: the truth's loss through the fitted objects is a loss
        // (the thermal term is 0 at the noise and 1 for "nobody there", unbounded beyond).
        let truth = c["diagnosis"]["truth_loss"].as_f64().unwrap();
        assert!(truth.is_finite() && truth > -1.0, "{c}");
        let id = c["id"].as_str().unwrap();
        assert!(out.join(format!("captures/{id}/overlay.png")).is_file());
        assert!(out.join(format!("captures/{id}/third.png")).is_file());
    }
    assert_eq!(caps[0]["thermal_width"], 640);
    assert_eq!(caps[3]["thermal_width"], 160);
    assert!(
        std::fs::read_to_string(out.join("report.html"))
            .unwrap()
            .contains("captures/car_00/third.png")
    );
    assert!(out.join("run.toml").is_file());
    assert!(!out.join("scratch").exists());

    // The ablations run on the first captures of a cell: three, the paper's mask term and the
    // full model.
    let abl = tmp("eval-ablations");
    let o = irmirror(&[
        "eval",
        "--cell",
        "tabletop-wide",
        "--limit",
        "1",
        "--out",
        abl.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(abl.join("results.json")).unwrap()).unwrap();
    assert_eq!(
        results["captures"][0]["variants"]
            .as_object()
            .unwrap()
            .len(),
        5
    );

    // A cell the benchmark does not have, or --limit 0: a clear error, nothing written.
    let bad = tmp("eval-teapot");
    for (args, needle) in [
        (
            vec!["--cell", "teapot"],
            "invalid value 'teapot' for '--cell",
        ),
        (vec!["--limit", "0"], "--limit"),
    ] {
        let mut all = vec!["eval", "--full-only", "--out", bad.to_str().unwrap()];
        all.extend(args);
        let o = irmirror(&all);
        assert!(
            !o.status.success() && stderr(&o).contains(needle),
            "{needle}: {}",
            stderr(&o)
        );
        assert!(!bad.exists());
    }
    // An --out that cannot be written: a clear error naming it, before any work.
    let o = irmirror(&["eval", "--full-only", "--out", "/proc/irmirror-eval/out"]);
    assert!(
        !o.status.success() && stderr(&o).contains("/proc/irmirror-eval"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&abl).ok();
}

#[test]
#[ignore = "slow: the whole quick benchmark (32 captures, ≈ 20 min on 2 cores)"]
fn eval_quick_set_runs() {
    let out = tmp("eval-quick");
    let o = irmirror(&["eval", "--preset", "quick", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}
