//! The demo's report.html opened in a real browser (headless Chromium): it renders, every image
//! loads, no script fails, and the 3-D view draws. `.ci/run` installs Debian's `chromium` and
//! sets `IRMIRROR_REQUIRE_BROWSER=1`, so there the test cannot pass without a browser; elsewhere
//! a machine without Chromium prints a note and skips.

use std::path::{Path, PathBuf};
use std::process::Command;

fn chromium() -> Option<PathBuf> {
    if let Ok(p) = std::env::var("IRMIRROR_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Runs headless Chromium on `page` with `extra` arguments; returns stdout.
fn browse(browser: &Path, profile: &Path, page: &Path, extra: &[&str]) -> String {
    let url = format!("file://{}", page.display());
    let o = Command::new("timeout")
        .arg("180")
        .arg(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            // WebGL without a GPU: Chromium's software rasteriser.
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--virtual-time-budget=15000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(&url)
        .output()
        .expect("chromium runs");
    assert!(
        o.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The integer value of `name="…"` in `dom`.
fn attribute(dom: &str, name: &str) -> Option<u64> {
    let at = dom.find(&format!("{name}=\""))? + name.len() + 2;
    dom[at..].split('"').next()?.parse().ok()
}

#[test]
fn report_renders_in_a_browser() {
    let Some(browser) = chromium() else {
        assert!(
            std::env::var("IRMIRROR_REQUIRE_BROWSER").is_err(),
            "IRMIRROR_REQUIRE_BROWSER is set but no Chromium was found"
        );
        eprintln!("note: no Chromium on this machine; the report's browser test is skipped");
        return;
    };
    let dir = std::env::temp_dir().join(format!("irmirror-browser-{}", std::process::id()));
    let out = dir.join("demo");
    std::fs::create_dir_all(&dir).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_irmirror"))
        .args(["demo", "-q", "--seed", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = out.join("report.html");
    let profile = dir.join("profile");

    // The page after its scripts ran: the report records what it saw on its root element.
    let dom = browse(&browser, &profile, &report, &["--dump-dom"]);
    assert_eq!(attribute(&dom, "data-errors"), Some(0), "script errors");
    assert_eq!(
        attribute(&dom, "data-broken-images"),
        Some(0),
        "images that did not load"
    );
    assert!(
        attribute(&dom, "data-images").is_some_and(|n| n >= 10),
        "too few images"
    );
    let drawn = attribute(&dom, "data-drawn-pixels").expect("the 3-D view did not draw");
    assert!(drawn > 2_000, "the 3-D view coloured only {drawn} pixels");
    // Every part of the scene is listed for toggling.
    for part in [
        "person, best hypothesis",
        "true person (simulator)",
        "thermal camera",
    ] {
        assert!(dom.contains(part), "the 3-D view does not list {part}");
    }

    // A screenshot of the top of the page is not blank: many colours, much non-white.
    let shot = dir.join("shot.png");
    browse(
        &browser,
        &profile,
        &report,
        &[
            "--window-size=1200,2400",
            &format!("--screenshot={}", shot.display()),
        ],
    );
    let img = image::open(&shot).expect("a screenshot").to_rgb8();
    let mut colours = std::collections::HashSet::new();
    let mut inked = 0usize;
    for p in img.pixels() {
        colours.insert(p.0);
        if p.0.iter().any(|c| *c < 200) {
            inked += 1;
        }
    }
    let frac = inked as f64 / (img.width() * img.height()) as f64;
    assert!(
        colours.len() > 200 && frac > 0.05,
        "blank-looking screenshot: {} colours, {:.1} % inked",
        colours.len(),
        100.0 * frac
    );
    std::fs::remove_dir_all(&dir).ok();
}
