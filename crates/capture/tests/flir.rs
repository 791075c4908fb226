//! The FLIR radiometric JPEG reader on a real camera's file (ExifTool's FLIR i7 sample, shipped
//! in `assets/flir/`) and on complete files built by the published layout.

use irmirror_capture::Image;
use irmirror_capture::flir::{self, Planck};

fn sample() -> Vec<u8> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/flir/exiftool_FLIR_i7.jpg");
    std::fs::read(p).expect("the shipped sample")
}

/// ExifTool's expected output for this file (`t/FLIR_2.out`) lists the constants below; the
/// camera's maker notes give the image's temperature range as 281–308 K, and its camera info the
/// raw median 12582 and range 1980. The Planck conversion at the file's emissivity (0.80) and
/// reflected temperature (20 °C) maps median ∓ range/2 onto that range.
#[test]
fn a_real_cameras_constants_are_read_and_reproduce_its_temperature_range() {
    let e = flir::parse(&sample()).unwrap_err();
    assert!(
        e.contains("8×8") && e.contains("120×120") && e.contains("stripped"),
        "{e}"
    );
    let info = flir::camera_info_record(&sample()).unwrap();
    // The same constants through a complete file built around the real camera-info record.
    let raw = Image {
        width: 120,
        height: 120,
        data: (0..120 * 120).map(|i| 11_592 + (i % 1981) as u16).collect(),
    };
    let img = flir::parse(&flir::build(&sample(), &info, &raw).unwrap()).unwrap();
    let p = img.planck;
    let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * b.abs();
    assert!(close(p.r1, 13799.269, 1e-7) && close(p.b, 1374.5, 1e-9) && close(p.f, 1.35, 1e-7));
    assert!(p.o == -6646.0 && close(p.r2, 0.022241818, 1e-7), "{p:?}");
    assert!(close(img.emissivity, 0.80, 1e-7));
    assert!(close(img.reflected_k, 293.15, 1e-6) && close(img.atmosphere_k, 293.15, 1e-6));
    assert_eq!(img.camera_model, "FLIR_i7");
    assert_eq!(img.raw_median_range, (12582, 1980));
    let (med, range) = (12582.0, 1980.0);
    let lo = p.object_k(med - range / 2.0, img.emissivity, img.reflected_k);
    let hi = p.object_k(med + range / 2.0, img.emissivity, img.reflected_k);
    assert!(
        (lo - 281.0).abs() < 1.0 && (hi - 308.0).abs() < 1.0,
        "{lo} – {hi} K"
    );
    // Apparent temperature and raw counts invert each other.
    for t in [250.0, 293.15, 310.15, 400.0] {
        assert!((p.apparent_k(p.raw_of(t)) - t).abs() < 1e-9);
    }
}

/// A full-size frame (320×240, 3 APP1 chunks) comes back bit for bit, and the capture format's
/// `counts-planck` units give the same temperatures as FLIR's formula.
#[test]
fn a_complete_file_round_trips_across_chunks() {
    let info = flir::camera_info_record(&sample()).unwrap();
    let mut state = 12345u32;
    let raw = Image {
        width: 320,
        height: 240,
        data: (0..320 * 240)
            .map(|_| {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (8000 + (state >> 16) % 9000) as u16
            })
            .collect(),
    };
    let jpeg = flir::build(&sample(), &info, &raw).unwrap();
    assert!(
        flir::fff_stream(&jpeg).unwrap().len() > 2 * 65_000,
        "several chunks"
    );
    let img = flir::parse(&jpeg).unwrap();
    assert_eq!(img.raw, raw);
    let p: Planck = img.planck;
    let irmirror_capture::ThermalUnits::CountsPlanck { r, b, f, o } = p.units() else {
        panic!("counts-planck")
    };
    for c in [8000.0, 12582.0, 16999.0] {
        let ours = b / (r / (c - o) + f).ln();
        assert!((ours - p.apparent_k(c)).abs() < 1e-9);
    }
}

#[test]
fn files_without_radiometric_data_are_refused_with_the_reason() {
    let s = sample();
    // The same JPEG with its FLIR segments removed (what re-saving in an editor does).
    let plain = {
        let info = flir::camera_info_record(&s).unwrap();
        let tiny = Image {
            width: 1,
            height: 1,
            data: vec![0],
        };
        let built = flir::build(&s, &info, &tiny).unwrap();
        // Drop every APP1 "FLIR" segment of the built file.
        let mut out = vec![0xFF, 0xD8];
        let mut i = 2;
        while built[i + 1] != 0xDA {
            let len = usize::from(u16::from_be_bytes([built[i + 2], built[i + 3]]));
            if &built[i + 4..i + 9] != b"FLIR\0" {
                out.extend_from_slice(&built[i..i + 2 + len]);
            }
            i += 2 + len;
        }
        out.extend_from_slice(&built[i..]);
        out
    };
    let cases: [(&[u8], &str); 4] = [
        (&plain, "no FLIR radiometric data"),
        (b"\x89PNG\r\n\x1a\n", "not a JPEG"),
        (&s[..600], "truncated"),
        (b"", "not a JPEG"),
    ];
    for (bytes, want) in cases {
        let e = flir::parse(bytes).unwrap_err();
        assert!(e.contains(want), "{want}: {e}");
    }
}
