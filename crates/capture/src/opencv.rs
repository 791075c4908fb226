//! Camera intrinsics in OpenCV's `FileStorage` layout (what `cv::calibrateCamera` users save, and
//! ROS' `camera_info` YAML): `image_width`, `image_height` and a 3×3 `camera_matrix` (also `K`
//! or `cameraMatrix`) with `data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]`, as JSON or YAML.
//!
//! OpenCV puts pixel centres at integer coordinates; ours are at +0.5, so `cx, cy` gain half a
//! pixel on the way in and lose it on the way out. The YAML is read by a small dedicated reader:
//! OpenCV writes a `%YAML:1.0` directive and `!!opencv-matrix` tags that general YAML parsers
//! reject.

use crate::CaptureError;
use irmirror_geom::PinholeCamera;
use std::path::Path;

/// Names OpenCV, ROS and common scripts give the camera matrix.
const MATRIX_KEYS: [&str; 4] = ["camera_matrix", "K", "cameraMatrix", "intrinsic_matrix"];
/// Names of the distortion coefficients.
const DISTORTION_KEYS: [&str; 3] = ["distortion_coefficients", "D", "dist_coeffs"];

/// Intrinsics read from an OpenCV file, and whether it states a non-zero lens distortion (the
/// capture format is pinhole: such images must be undistorted first).
#[derive(Clone, Debug, PartialEq)]
pub struct OpenCvCamera {
    /// The intrinsics, in our pixel convention.
    pub camera: PinholeCamera,
    /// Largest |coefficient| of the distortion, 0 when none is stated.
    pub distortion: f64,
}

/// Reads `image_width`, `image_height` and the camera matrix from a `.json`, `.yaml` or `.yml`
/// file.
pub fn read_intrinsics(path: &Path) -> Result<OpenCvCamera, CaptureError> {
    let fail = |r: String| CaptureError::file(path, r);
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    let is_json = text.trim_start().starts_with('{');
    let (w, h, m, d) = if is_json {
        let v: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| fail(format!("not valid JSON: {e}")))?;
        let num = |k: &str| v.get(k).and_then(serde_json::Value::as_f64);
        let data = |keys: &[&str]| -> Option<Vec<f64>> {
            keys.iter().find_map(|k| {
                let m = v.get(*k)?;
                let arr = m.get("data").unwrap_or(m);
                let flat: Vec<f64> = match arr.as_array()? {
                    rows if rows.iter().all(|r| r.is_array()) => rows
                        .iter()
                        .flat_map(|r| r.as_array().into_iter().flatten())
                        .filter_map(serde_json::Value::as_f64)
                        .collect(),
                    vals => vals.iter().filter_map(serde_json::Value::as_f64).collect(),
                };
                Some(flat)
            })
        };
        (
            num("image_width").or_else(|| num("width")),
            num("image_height").or_else(|| num("height")),
            data(&MATRIX_KEYS),
            data(&DISTORTION_KEYS),
        )
    } else {
        let y = YamlLite::new(&text);
        (
            y.number("image_width").or_else(|| y.number("width")),
            y.number("image_height").or_else(|| y.number("height")),
            MATRIX_KEYS.iter().find_map(|k| y.matrix(k)),
            DISTORTION_KEYS.iter().find_map(|k| y.matrix(k)),
        )
    };
    let (Some(w), Some(h)) = (w, h) else {
        return Err(fail(
            "no `image_width` / `image_height` (OpenCV FileStorage layout expected)".into(),
        ));
    };
    let Some(m) = m else {
        return Err(fail(format!(
            "no camera matrix (looked for {})",
            MATRIX_KEYS.join(", ")
        )));
    };
    if m.len() != 9 {
        return Err(fail(format!(
            "the camera matrix has {} numbers, not 9",
            m.len()
        )));
    }
    if m[1].abs() > 1e-6 * m[0].abs() || m[3] != 0.0 || m[6] != 0.0 || m[7] != 0.0 || m[8] != 1.0 {
        return Err(fail(format!(
            "the camera matrix {m:?} is not [fx, 0, cx, 0, fy, cy, 0, 0, 1] (skew is not supported)"
        )));
    }
    if !(w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0) {
        return Err(fail(format!(
            "image size {w} × {h} is not a positive integer size"
        )));
    }
    let camera = PinholeCamera {
        width: w as u32,
        height: h as u32,
        fx: m[0],
        fy: m[4],
        cx: m[2] + 0.5,
        cy: m[5] + 0.5,
    };
    camera
        .validate()
        .map_err(|e| fail(format!("impossible intrinsics: {e}")))?;
    let distortion = d
        .unwrap_or_default()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    Ok(OpenCvCamera { camera, distortion })
}

/// `camera` in OpenCV's JSON layout (pixel centres at integers), no distortion.
pub fn intrinsics_json(camera: &PinholeCamera) -> String {
    let v = serde_json::json!({
        "image_width": camera.width,
        "image_height": camera.height,
        "camera_matrix": {
            "type_id": "opencv-matrix", "rows": 3, "cols": 3, "dt": "d",
            "data": [camera.fx, 0.0, camera.cx - 0.5, 0.0, camera.fy, camera.cy - 0.5, 0.0, 0.0, 1.0],
        },
        "distortion_coefficients": {
            "type_id": "opencv-matrix", "rows": 1, "cols": 5, "dt": "d",
            "data": [0.0, 0.0, 0.0, 0.0, 0.0],
        },
    });
    serde_json::to_string_pretty(&v).unwrap_or_default() + "\n"
}

/// The subset of YAML OpenCV and ROS write: top-level `key: value` and matrices whose `data:`
/// list may span lines.
struct YamlLite<'a> {
    text: &'a str,
}

impl<'a> YamlLite<'a> {
    fn new(text: &'a str) -> Self {
        Self { text }
    }

    /// The text after the top-level `key:` and the lines indented under it.
    fn block(&self, key: &str) -> Option<String> {
        let mut lines = self.text.lines();
        let prefix = format!("{key}:");
        let first = lines.find(|l| l.starts_with(&prefix))?;
        let mut out = first[prefix.len()..].to_string();
        for l in lines {
            if !l.starts_with([' ', '\t']) && !l.trim().is_empty() {
                break;
            }
            out.push('\n');
            out.push_str(l);
        }
        Some(out)
    }

    fn number(&self, key: &str) -> Option<f64> {
        self.block(key)?.lines().next()?.trim().parse().ok()
    }

    fn matrix(&self, key: &str) -> Option<Vec<f64>> {
        let b = self.block(key)?;
        let start = b.find('[')?;
        let end = start + b[start..].find(']')?;
        b[start + 1..end]
            .split(',')
            .map(|s| s.trim())
            .filter(|s| !s.is_empty())
            .map(|s| s.parse().ok())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("irmirror-opencv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn reads_opencv_yaml_ros_yaml_and_json_alike() {
        let yaml = "%YAML:1.0\n---\nimage_width: 640\nimage_height: 512\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 6.8617e+02, 0., 3.195e+02,\n       0., 6.8617e+02, 2.555e+02, 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ -0.1, 0.01, 0., 0., 0. ]\n";
        let ros = "image_width: 640\nimage_height: 512\ncamera_name: boson\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [686.17, 0, 319.5, 0, 686.17, 255.5, 0, 0, 1]\n";
        let a = read_intrinsics(&write("a.yaml", yaml)).unwrap();
        let b = read_intrinsics(&write("b.yaml", ros)).unwrap();
        let want = PinholeCamera {
            width: 640,
            height: 512,
            fx: 686.17,
            fy: 686.17,
            cx: 320.0,
            cy: 256.0,
        };
        assert_eq!(a.camera, want);
        assert_eq!(a.distortion, 0.1);
        assert_eq!(b.camera, want);
        assert_eq!(b.distortion, 0.0);
        let json = read_intrinsics(&write("c.json", &intrinsics_json(&want))).unwrap();
        assert_eq!(json.camera, want);
    }

    #[test]
    fn bad_intrinsics_files_name_what_is_wrong() {
        let cases = [
            ("n.yaml", "image_width: 640\n", "image_height"),
            (
                "m.yaml",
                "image_width: 640\nimage_height: 480\n",
                "no camera matrix",
            ),
            (
                "s.json",
                r#"{"image_width": 4, "image_height": 4, "K": [1, 0.5, 2, 0, 1, 2, 0, 0, 1]}"#,
                "skew",
            ),
            (
                "z.json",
                r#"{"image_width": 4, "image_height": 4, "K": [0, 0, 2, 0, 1, 2, 0, 0, 1]}"#,
                "impossible",
            ),
            ("j.json", "{ not json", "not valid JSON"),
        ];
        for (name, text, want) in cases {
            let e = read_intrinsics(&write(name, text)).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains(name), "{name}: {e}");
        }
    }
}
