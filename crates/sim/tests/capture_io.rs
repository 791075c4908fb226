//! The capture format: the loader round-trips what the simulator writes, and rejects broken
//! captures with clear errors (never a panic), without touching the directory.

mod common;

use common::{model, small_scene, tmpdir};
use irmirror_capture::Capture;
use irmirror_capture::planck::temperature_of;
use irmirror_sim::simulate;
use std::path::{Path, PathBuf};

fn write_capture(name: &str) -> PathBuf {
    let dir = tmpdir(name);
    let sim = simulate(model(), &small_scene(), 1).unwrap();
    sim.write(model(), &dir, 1).unwrap();
    dir
}

fn listing(dir: &Path) -> Vec<(PathBuf, u64, std::time::SystemTime)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let m = e.metadata().unwrap();
        if m.is_dir() {
            out.extend(listing(&e.path()));
        } else {
            out.push((e.path(), m.len(), m.modified().unwrap()));
        }
    }
    out.sort();
    out
}

#[test]
fn loader_round_trips_the_simulator() {
    let dir = write_capture("roundtrip");
    let before = listing(&dir);
    let sim = simulate(model(), &small_scene(), 1).unwrap();
    let cap = Capture::load(&dir).unwrap();
    assert_eq!(
        listing(&dir),
        before,
        "loading modified the capture directory"
    );
    assert_eq!(cap.objects.len(), 2);
    assert_eq!(cap.objects[0].category, irmirror_geom::Category::Bowl);
    assert_eq!(cap.thermal_background_k.len(), 1);
    // Ideal sensor: the loaded temperatures equal the rendered ones up to the 16-bit ADC step.
    for (k, l) in cap.thermal_k.data.iter().zip(&sim.radiance.0.data) {
        assert!(
            (k - temperature_of(*l)).abs() < 0.01,
            "{k} vs {}",
            temperature_of(*l)
        );
    }
    for (d, raw) in cap.depth_m.data.iter().zip(&sim.depth.data) {
        if *raw == 0 {
            assert!(d.is_nan());
        } else {
            assert!((f64::from(*d) - f64::from(*raw) * 1e-3).abs() < 1e-6);
        }
    }
    assert_eq!(
        cap.objects[0].mask.as_ref().unwrap().data,
        sim.masks[0].data
    );

    // The same frame as centikelvin in a 16-bit TIFF, and as raw counts with Planck constants.
    let ck: Vec<u16> = cap
        .thermal_k
        .data
        .iter()
        .map(|k| (k * 100.0).round() as u16)
        .collect();
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(160, 120, ck).unwrap();
    img.save(dir.join("thermal_ck.tiff")).unwrap();
    let (r, b, f, o) = (300_000.0, 1400.0, 1.0, 100.0);
    let raw: Vec<u16> = cap
        .thermal_k
        .data
        .iter()
        .map(|t| (r / ((b / t).exp() - f) + o).round() as u16)
        .collect();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(160, 120, raw)
        .unwrap()
        .save(dir.join("thermal_raw.png"))
        .unwrap();
    for (file, units) in [
        ("thermal_ck.tiff", "kind = \"centikelvin\""),
        (
            "thermal_raw.png",
            "kind = \"counts-planck\"\nr = 300000.0\nb = 1400.0\nf = 1.0\no = 100.0",
        ),
    ] {
        let t = std::fs::read_to_string(dir.join("capture.toml")).unwrap();
        let head = t
            .split("[thermal.units]")
            .next()
            .unwrap()
            .replace("file = \"thermal.png\"", &format!("file = \"{file}\""))
            .replace("background = [\"thermal_background.png\"]", "");
        let rest = t.split("[thermal.units]").nth(1).unwrap();
        let after = &rest[rest.find("\n[").unwrap()..];
        std::fs::write(
            dir.join("capture.toml"),
            format!("{head}[thermal.units]\n{units}\n{after}"),
        )
        .unwrap();
        let c2 = Capture::load(&dir).unwrap();
        for (a, b) in c2.thermal_k.data.iter().zip(&cap.thermal_k.data) {
            assert!((a - b).abs() < 0.02, "{file}: {a} vs {b}");
        }
        std::fs::write(dir.join("capture.toml"), t).unwrap();
    }
    std::fs::remove_dir_all(&dir).ok();
}

fn edit_toml(dir: &Path, f: impl Fn(String) -> String) {
    let p = dir.join("capture.toml");
    let t = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, f(t)).unwrap();
}

fn write_npy_f64(path: &Path, h: usize, w: usize, data: &[f64]) {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({h}, {w}), }}");
    while (10 + header.len() + 1) % 16 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(header.len() as u16).to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    data.iter()
        .for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    std::fs::write(path, b).unwrap();
}

#[test]
fn broken_captures_give_clear_errors() {
    let base = write_capture("broken-base");
    type Breaker = Box<dyn Fn(&Path)>;
    let cases: Vec<(&str, Breaker, &str)> = vec![
        (
            "no capture.toml",
            Box::new(|d| std::fs::remove_file(d.join("capture.toml")).unwrap()),
            "capture directory",
        ),
        (
            "toml syntax",
            Box::new(|d| std::fs::write(d.join("capture.toml"), "format = [").unwrap()),
            "capture.toml",
        ),
        (
            "unknown key",
            Box::new(|d| edit_toml(d, |t| format!("colour = 3\n{t}"))),
            "unknown field",
        ),
        (
            "missing field",
            Box::new(|d| edit_toml(d, |t| t.replacen("fx = ", "fx_typo = ", 1))),
            "fx",
        ),
        (
            "format tag",
            Box::new(|d| edit_toml(d, |t| t.replace("irmirror-capture-1", "irmirror-capture-9"))),
            "format",
        ),
        (
            "negative focal length",
            Box::new(|d| edit_toml(d, |t| t.replacen("fx = ", "fx = -", 1))),
            "focal lengths must be positive",
        ),
        (
            "principal point",
            Box::new(|d| edit_toml(d, |t| t.replacen("cx = ", "cx = 9", 1))),
            "principal point",
        ),
        (
            "not a rotation",
            Box::new(|d| {
                edit_toml(d, |t| {
                    t.replace("rotation = [[1.0, 0.0, 0.0]", "rotation = [[2.0, 0.0, 0.0]")
                })
            }),
            "not a rotation",
        ),
        (
            "depth missing",
            Box::new(|d| std::fs::remove_file(d.join("depth.png")).unwrap()),
            "depth.png",
        ),
        (
            "depth truncated",
            Box::new(|d| {
                let b = std::fs::read(d.join("depth.png")).unwrap();
                std::fs::write(d.join("depth.png"), &b[..b.len() / 2]).unwrap();
            }),
            "cannot decode",
        ),
        (
            "8-bit depth",
            Box::new(|d| {
                image::GrayImage::new(80, 60)
                    .save(d.join("depth.png"))
                    .unwrap()
            }),
            "16-bit",
        ),
        (
            "depth size",
            Box::new(|d| {
                image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(
                    10,
                    10,
                    image::Luma([900]),
                )
                .save(d.join("depth.png"))
                .unwrap()
            }),
            "is 10×10",
        ),
        (
            "depth all zero",
            Box::new(|d| {
                image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(80, 60)
                    .save(d.join("depth.png"))
                    .unwrap()
            }),
            "no valid pixel",
        ),
        (
            "thermal size",
            Box::new(|d| {
                image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(
                    80,
                    60,
                    image::Luma([5000]),
                )
                .save(d.join("thermal.png"))
                .unwrap()
            }),
            "thermal camera",
        ),
        (
            "NaN in .npy",
            Box::new(|d| {
                let mut v = vec![295.0; 160 * 120];
                v[100] = f64::NAN;
                write_npy_f64(&d.join("thermal.npy"), 120, 160, &v);
                edit_toml(d, |t| {
                    t.replace("file = \"thermal.png\"", "file = \"thermal.npy\"")
                        .replace("background = [\"thermal_background.png\"]", "")
                        .replace("kind = \"counts-linear\"", "kind = \"kelvin\"")
                        .lines()
                        .filter(|l| !l.starts_with("gain") && !l.starts_with("offset"))
                        .collect::<Vec<_>>()
                        .join("\n")
                });
            }),
            "not finite",
        ),
        (
            "°C read as kelvin",
            Box::new(|d| {
                write_npy_f64(&d.join("thermal.npy"), 120, 160, &vec![22.0; 160 * 120]);
                edit_toml(d, |t| {
                    t.replace("file = \"thermal.png\"", "file = \"thermal.npy\"")
                        .replace("background = [\"thermal_background.png\"]", "")
                        .replace("kind = \"counts-linear\"", "kind = \"kelvin\"")
                        .lines()
                        .filter(|l| !l.starts_with("gain") && !l.starts_with("offset"))
                        .collect::<Vec<_>>()
                        .join("\n")
                });
            }),
            "check `thermal.units`",
        ),
        (
            "empty mask",
            Box::new(|d| {
                image::GrayImage::new(80, 60)
                    .save(d.join("masks/object_0.png"))
                    .unwrap()
            }),
            "empty",
        ),
        (
            "unknown category",
            Box::new(|d| {
                edit_toml(d, |t| {
                    t.replacen("category = \"bowl\"", "category = \"teapot\"", 1)
                })
            }),
            "unknown variant `teapot`, expected one of `bowl`",
        ),
        (
            "mask outside the capture",
            Box::new(|d| edit_toml(d, |t| t.replace("masks/object_0.png", "../object_0.png"))),
            "inside the capture directory",
        ),
        (
            "zero depth units",
            Box::new(|d| edit_toml(d, |t| t.replace("units_m = 0.001", "units_m = 0.0"))),
            "units_m",
        ),
        (
            "zero IMU up",
            Box::new(|d| {
                edit_toml(d, |t| {
                    t.lines()
                        .map(|l| {
                            if l.starts_with("up = ") {
                                "up = [0.0, 0.0, 0.0]"
                            } else {
                                l
                            }
                        })
                        .collect::<Vec<_>>()
                        .join("\n")
                })
            }),
            "depth.up",
        ),
        (
            "negative gain",
            Box::new(|d| edit_toml(d, |t| t.replacen("gain = ", "gain = -", 1))),
            "gain",
        ),
        (
            "no objects",
            Box::new(|d| edit_toml(d, |t| t.split("[[object]]").next().unwrap().to_string())),
            "no objects",
        ),
        (
            "background missing",
            Box::new(|d| std::fs::remove_file(d.join("thermal_background.png")).unwrap()),
            "thermal_background.png",
        ),
        (
            "an extra camera of 4e9 × 4e9 pixels",
            Box::new(|d| {
                edit_toml(d, |t| {
                    t + "\n[[extra_camera]]\nname = \"huge\"\nwidth = 4000000000\n\
                         height = 4000000000\nfx = 1000.0\nfy = 1000.0\ncx = 2000000000.0\n\
                         cy = 2000000000.0\n[extra_camera.depth_from_camera]\n\
                         rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n\
                         translation_m = [0.0, 0.0, 0.0]\n"
                })
            }),
            "exceeds 16384",
        ),
        (
            "a negative point spread",
            Box::new(|d| {
                edit_toml(d, |t| {
                    t.lines()
                        .filter(|l| !l.starts_with("psf_sigma_px"))
                        .collect::<Vec<_>>()
                        .join("\n")
                        .replace(
                            "[thermal_camera]\n",
                            "[thermal_camera]\npsf_sigma_px = -1.0\n",
                        )
                })
            }),
            "thermal_camera.psf_sigma_px",
        ),
        (
            "rgb wrong size",
            Box::new(|d| image::RgbImage::new(5, 5).save(d.join("rgb.png")).unwrap()),
            "rgb.png",
        ),
    ];
    assert!(cases.len() >= 15);
    for (name, breaker, expect) in cases {
        let dir = tmpdir(&format!("broken-{}", name.replace(' ', "_")));
        copy_dir(&base, &dir);
        breaker(&dir);
        let result = std::panic::catch_unwind(|| Capture::load(&dir));
        let err = match result {
            Ok(Ok(_)) => panic!("{name}: the broken capture loaded"),
            Ok(Err(e)) => e.to_string(),
            Err(_) => panic!("{name}: the loader panicked"),
        };
        assert!(
            err.contains(expect),
            "{name}: `{err}` does not mention `{expect}`"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
    std::fs::remove_dir_all(&base).ok();
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.metadata().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}
