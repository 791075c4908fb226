//! `reconstruct` and `score` as a user meets them: every stage's files, the input untouched,
//! scoring against a simulated capture's truth, and clear refusals.

mod common;

use common::{irmirror, read_tree, stderr, tmp};

#[test]
fn reconstruct_writes_every_stage_and_fails_cleanly_without_reflection() {
    let cap = tmp("rec-capture");
    let o = irmirror(&[
        "simulate",
        "--preset",
        "car",
        "--out",
        cap.to_str().unwrap(),
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = read_tree(&cap);
    let out = tmp("rec-out");
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--stage",
        "preprocess",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "reflection_mask.png",
        "run.toml",
        "debug/rise.png",
        "debug/object_pixels.png",
        "debug/mask_raw.png",
        "debug/edges.png",
        "debug/depth_edges_on_thermal.png",
    ] {
        assert!(out.join(f).exists(), "missing {f}");
    }
    assert_eq!(read_tree(&cap), before, "reconstruct modified its input");
    // The full pipeline: meshes, parameters, images, report; the input untouched.
    let out2 = tmp("rec-out2");
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
        "--seed",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "body.ply",
        "body.obj",
        "body.glb",
        "params.json",
        "overlay.png",
        "loss_curve.svg",
        "report.html",
        "run.toml",
        "objects/object_0.ply",
        "views/overview.png",
    ] {
        assert!(out2.join(f).exists(), "missing {f}");
    }
    let params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out2.join("params.json")).unwrap()).unwrap();
    assert!(!params["human"]["hypotheses"].as_array().unwrap().is_empty());
    // The thermal fit (the capture has background frames), and each hypothesis says which
    // parts of its body the reflection shows.
    assert_eq!(params["human"]["data_term"], "radiometric");
    for h in params["human"]["hypotheses"].as_array().unwrap() {
        let rise = &h["radiometry"]["rise_k_px"];
        let parts: Vec<f64> = ["clothing", "skin", "face", "hair"]
            .map(|r| rise[r].as_f64().unwrap())
            .into();
        assert!(
            parts.iter().all(|&x| x >= 0.0) && parts.iter().sum::<f64>() > 0.0,
            "{rise}"
        );
    }
    assert_eq!(read_tree(&cap), before, "reconstruct modified its input");
    // A simulated capture carries its truth: reconstruct scored itself, and `score` gives the
    // same figures from the files alone (the body re-posed from params.json).
    let own: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out2.join("eval.json")).unwrap()).unwrap();
    assert!(out2.join("views/third_camera.png").exists() && out2.join("fitted_mask.png").exists());
    let report = std::fs::read_to_string(out2.join("report.html")).unwrap();
    assert!(report.contains("Evaluation against the simulator's truth"));
    let json = tmp("rec-score.json");
    let o = irmirror(&[
        "score",
        out2.to_str().unwrap(),
        "--truth",
        cap.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(
        o.status.success() && String::from_utf8_lossy(&o.stdout).contains("root (pelvis)"),
        "{}",
        stderr(&o)
    );
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in [
        "root_error_m",
        "vertex_error_m",
        "reflection_iou",
        "mpjpe_m",
    ] {
        let (a, b) = (
            own["best"][key].as_f64().unwrap(),
            again["best"][key].as_f64().unwrap(),
        );
        assert!((a - b).abs() < 1e-9, "{key}: {a} vs {b}");
    }
    assert_eq!(
        own["hypotheses"].as_array().unwrap().len(),
        params["human"]["hypotheses"].as_array().unwrap().len()
    );
    std::fs::remove_file(&json).ok();
    // Scoring refuses, with a reason: a directory that is not a result, a capture without
    // truth, a JSON path inside an input (nothing written there).
    let o = irmirror(&[
        "score",
        cap.to_str().unwrap(),
        "--truth",
        cap.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("params.json"),
        "{}",
        stderr(&o)
    );
    let o = irmirror(&[
        "score",
        out2.to_str().unwrap(),
        "--truth",
        out2.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("truth"),
        "{}",
        stderr(&o)
    );
    let inside = out2.join("score.json");
    let o = irmirror(&[
        "score",
        out2.to_str().unwrap(),
        "--truth",
        cap.to_str().unwrap(),
        "--json",
        inside.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("never modified") && !inside.exists(),
        "{}",
        stderr(&o)
    );
    // Stage 1 alone, and an unknown ablation is refused by the parser.
    let out3 = tmp("rec-out3");
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        out3.to_str().unwrap(),
        "--stage",
        "objects",
    ]);
    assert!(
        o.status.success()
            && out3.join("objects/object_0.ply").exists()
            && out3.join("objects.json").exists(),
        "{}",
        stderr(&o)
    );
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        out3.to_str().unwrap(),
        "--ablate",
        "everything",
    ]);
    assert!(!o.status.success() && stderr(&o).contains("--ablate"));
    let bad = tmp("rec-bad.toml");
    let out4 = tmp("rec-out4");
    // A config with an unknown setting, or settings outside their ranges: a clear error
    // naming the setting, no output.
    for (toml, names) in [
        ("[human]\ninits = 4\nbogus = 1\n", "bogus"),
        (
            "[human.radiometric]\nregion_temperatures_c = [30.0, 34.0, 200.0, 28.0]\n",
            "region_temperatures_c",
        ),
        ("[human.build]\nmuscle = 1.5\n", "muscle"),
    ] {
        std::fs::write(&bad, toml).unwrap();
        let o = irmirror(&[
            "reconstruct",
            cap.to_str().unwrap(),
            "--out",
            out4.to_str().unwrap(),
            "--config",
            bad.to_str().unwrap(),
        ]);
        assert!(
            !o.status.success() && stderr(&o).contains(names) && !out4.exists(),
            "{toml}: {}",
            stderr(&o)
        );
    }
    std::fs::remove_file(&bad).ok();
    std::fs::remove_dir_all(&out2).ok();
    std::fs::remove_dir_all(&out3).ok();
    // A truth that does not read leaves the result unscored (with a warning), not unwritten.
    std::fs::write(cap.join("truth/body.json"), "{ not json").unwrap();
    let out5 = tmp("rec-out5");
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        out5.to_str().unwrap(),
    ]);
    assert!(
        o.status.success()
            && String::from_utf8_lossy(&o.stdout)
                .contains("not scored against the capture's truth")
            && out5.join("params.json").exists()
            && !out5.join("eval.json").exists(),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir_all(&out5).ok();
    // A capture whose thermal frame equals its background: no reflection, clear error, no output.
    std::fs::copy(cap.join("thermal_background.png"), cap.join("thermal.png")).unwrap();
    for stage in ["preprocess", "full"] {
        let o = irmirror(&[
            "reconstruct",
            cap.to_str().unwrap(),
            "--out",
            out2.to_str().unwrap(),
            "--stage",
            stage,
        ]);
        assert!(
            !o.status.success() && stderr(&o).contains("no reflection"),
            "{}",
            stderr(&o)
        );
        assert!(!out2.exists());
    }
    // An --out that is not a result is refused before any work: the --out error comes, not
    // the "no reflection" one the pipeline would give, and the user's file stays.
    let precious = tmp("rec-precious");
    std::fs::create_dir_all(&precious).unwrap();
    std::fs::write(precious.join("notes.txt"), "mine").unwrap();
    let o = irmirror(&[
        "reconstruct",
        cap.to_str().unwrap(),
        "--out",
        precious.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success()
            && stderr(&o).contains("not an irmirror result")
            && !stderr(&o).contains("no reflection"),
        "{}",
        stderr(&o)
    );
    assert!(precious.join("notes.txt").exists());
    for d in [cap, out, precious] {
        std::fs::remove_dir_all(d).ok();
    }
}
