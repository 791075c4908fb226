//! FLIR radiometric JPEGs: the raw sensor frame and its Planck constants, from the FFF record
//! stream FLIR cameras (E-, T-, i-series, FLIR One, Duo) store in the JPEG's `APP1 "FLIR"`
//! segments. Layout as documented by ExifTool (`Image::ExifTool::FLIR`):
//!
//! * APP1 segments whose payload starts `"FLIR\0"`, then a version byte, the chunk's index and
//!   the last index; the chunks' remaining bytes, in index order, form one FFF stream;
//! * FFF header: `"FFF\0"` (or `"AFF\0"`), creator (16 bytes), version (u32 at 0x14), the record
//!   directory's offset (u32 at 0x18) and entry count (u32 at 0x1c), big-endian in the files we
//!   know (little-endian is detected by the version);
//! * 32-byte directory entries: record type (u16), subtype, version, index, offset and length
//!   (u32 each) from the FFF start. Type 1 = raw data, 0x20 = camera info;
//! * raw data: a byte-order word (2), width and height (u16), then at 0x20 either a 16-bit PNG
//!   whose samples FLIR stores byte-swapped, or `width · height` u16 in the record's order;
//! * camera info: emissivity (f32 at 32), reflected apparent temperature (K, 40), atmospheric
//!   temperature (44), Planck R1 (88), B (92), F (96), the camera model (string at 212), Planck
//!   O (i32 at 776), R2 (f32 at 780), raw value median and range (u16 at 824, 828).
//!
//! The object signal `S = R1 / (R2 (exp(B / T) − F)) − O` relates raw counts to the apparent
//! (black-body) temperature `T = B / ln(R1 / (R2 (raw + O)) + F)`, which is the capture format's
//! `counts-planck` units with `r = R1 / R2` and `o = −O`.

use crate::{CaptureError, Image, ThermalUnits};
use std::path::Path;

/// FLIR's Planck constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Planck {
    /// R1.
    pub r1: f64,
    /// R2.
    pub r2: f64,
    /// B, K.
    pub b: f64,
    /// F.
    pub f: f64,
    /// O, counts.
    pub o: f64,
}

impl Planck {
    /// The apparent (emissivity 1) temperature of raw counts, K.
    pub fn apparent_k(&self, raw: f64) -> f64 {
        self.b / (self.r1 / (self.r2 * (raw + self.o)) + self.f).ln()
    }

    /// Raw counts of a black body at `t_k`.
    pub fn raw_of(&self, t_k: f64) -> f64 {
        self.r1 / (self.r2 * ((self.b / t_k).exp() - self.f)) - self.o
    }

    /// The temperature of a grey body of emissivity `e` reflecting surroundings at
    /// `reflected_k`, as FLIR's software reports it (no atmosphere): the raw signal minus the
    /// reflected part, divided by `e`. Not what a mirror's reflection needs: that is the
    /// apparent temperature.
    pub fn object_k(&self, raw: f64, emissivity: f64, reflected_k: f64) -> f64 {
        let refl = self.raw_of(reflected_k);
        self.apparent_k((raw - (1.0 - emissivity) * refl) / emissivity)
    }

    /// The capture format's units for these constants.
    pub fn units(&self) -> ThermalUnits {
        ThermalUnits::CountsPlanck {
            r: self.r1 / self.r2,
            b: self.b,
            f: self.f,
            o: -self.o,
        }
    }
}

/// What a FLIR radiometric JPEG holds that a capture needs, and what it states about itself.
#[derive(Clone, Debug)]
pub struct FlirImage {
    /// The raw sensor frame.
    pub raw: Image<u16>,
    /// The Planck constants.
    pub planck: Planck,
    /// The emissivity set in the camera (for the camera's own readout; not applied here).
    pub emissivity: f64,
    /// Reflected apparent temperature set in the camera, K.
    pub reflected_k: f64,
    /// Atmospheric temperature set in the camera, K.
    pub atmosphere_k: f64,
    /// Camera model string.
    pub camera_model: String,
    /// The camera's median raw value and the raw range of the frame (camera info).
    pub raw_median_range: (u16, u16),
}

/// The FFF stream and its records.
struct Fff<'a> {
    bytes: &'a [u8],
    big_endian: bool,
}

fn u16_at(b: &[u8], o: usize, big: bool) -> Option<u16> {
    let s: [u8; 2] = b.get(o..o + 2)?.try_into().ok()?;
    Some(if big {
        u16::from_be_bytes(s)
    } else {
        u16::from_le_bytes(s)
    })
}

fn u32_at(b: &[u8], o: usize, big: bool) -> Option<u32> {
    let s: [u8; 4] = b.get(o..o + 4)?.try_into().ok()?;
    Some(if big {
        u32::from_be_bytes(s)
    } else {
        u32::from_le_bytes(s)
    })
}

fn f32_at(b: &[u8], o: usize, big: bool) -> Option<f64> {
    u32_at(b, o, big).map(|v| f64::from(f32::from_bits(v)))
}

/// The FFF stream reassembled from the JPEG's `APP1 "FLIR"` segments.
pub fn fff_stream(jpeg: &[u8]) -> Result<Vec<u8>, String> {
    if jpeg.get(0..2) != Some(&[0xFF, 0xD8]) {
        return Err("not a JPEG file (no start-of-image marker)".into());
    }
    let mut chunks: Vec<(u8, Vec<u8>)> = Vec::new();
    let mut i = 2;
    while i + 4 <= jpeg.len() {
        if jpeg[i] != 0xFF {
            return Err(format!("corrupt JPEG: no marker at byte {i}"));
        }
        let marker = jpeg[i + 1];
        if marker == 0xD8 || marker == 0x01 || (0xD0..=0xD7).contains(&marker) {
            i += 2;
            continue;
        }
        if marker == 0xDA || marker == 0xD9 {
            break; // image data follows: no more metadata segments
        }
        let len = usize::from(u16::from_be_bytes([jpeg[i + 2], jpeg[i + 3]]));
        let end = i + 2 + len;
        if len < 2 || end > jpeg.len() {
            return Err(format!(
                "truncated JPEG: segment at byte {i} runs past the end"
            ));
        }
        let payload = &jpeg[i + 4..end];
        if marker == 0xE1 && payload.len() >= 8 && &payload[..5] == b"FLIR\0" {
            chunks.push((payload[6], payload[8..].to_vec()));
        }
        i = end;
    }
    if chunks.is_empty() {
        return Err(
            "no FLIR radiometric data (no APP1 \"FLIR\" segment): not a radiometric FLIR JPEG, or the file was re-saved by software that drops it".into(),
        );
    }
    chunks.sort_by_key(|c| c.0);
    Ok(chunks.into_iter().flat_map(|c| c.1).collect())
}

impl<'a> Fff<'a> {
    fn new(bytes: &'a [u8]) -> Result<Self, String> {
        if bytes.len() < 0x40 || !(bytes.starts_with(b"FFF\0") || bytes.starts_with(b"AFF\0")) {
            return Err("the FLIR segments do not hold an FFF record stream".into());
        }
        let version_be = u32_at(bytes, 0x14, true).unwrap_or(0);
        let big_endian = (100..200).contains(&version_be);
        if !big_endian && !(100..200).contains(&u32_at(bytes, 0x14, false).unwrap_or(0)) {
            return Err(format!(
                "unknown FFF version {version_be:#x} (expected 100–199)"
            ));
        }
        Ok(Self { bytes, big_endian })
    }

    /// The first record of `kind`.
    fn record(&self, kind: u16) -> Option<&'a [u8]> {
        let big = self.big_endian;
        let dir = u32_at(self.bytes, 0x18, big)? as usize;
        let n = u32_at(self.bytes, 0x1c, big)? as usize;
        (0..n.min(4096)).find_map(|k| {
            let e = dir + 32 * k;
            if u16_at(self.bytes, e, big)? != kind {
                return None;
            }
            let off = u32_at(self.bytes, e + 12, big)? as usize;
            let len = u32_at(self.bytes, e + 16, big)? as usize;
            self.bytes.get(off..off.checked_add(len)?)
        })
    }
}

/// A record's byte order: its first word is 2 in the record's own order.
fn record_big_endian(rec: &[u8]) -> bool {
    u16_at(rec, 0, false) != Some(2)
}

/// Parses a FLIR radiometric JPEG already in memory.
pub fn parse(jpeg: &[u8]) -> Result<FlirImage, String> {
    let stream = fff_stream(jpeg)?;
    let fff = Fff::new(&stream)?;
    let info = fff
        .record(0x20)
        .ok_or("the FFF stream has no camera-info record (no Planck constants)")?;
    let big = record_big_endian(info);
    let f = |o: usize| f32_at(info, o, big).ok_or(format!("camera info truncated at {o}"));
    let o_raw = u32_at(info, 776, big).ok_or("camera info truncated at 776")? as i32;
    let planck = Planck {
        r1: f(88)?,
        b: f(92)?,
        f: f(96)?,
        o: f64::from(o_raw),
        r2: f(780)?,
    };
    if !(planck.r1 > 0.0 && planck.r2 > 0.0 && planck.b > 0.0 && planck.f.is_finite()) {
        return Err(format!(
            "implausible Planck constants {planck:?} in the camera-info record"
        ));
    }
    let camera_model = info
        .get(212..244)
        .map(|s| {
            String::from_utf8_lossy(s)
                .trim_end_matches('\0')
                .split('\0')
                .next()
                .unwrap_or("")
                .to_string()
        })
        .unwrap_or_default();
    let raw_rec = fff
        .record(1)
        .ok_or("the FFF stream has no raw-data record: the file holds no radiometric frame")?;
    let rbig = record_big_endian(raw_rec);
    let (w, h) = (
        u16_at(raw_rec, 2, rbig).ok_or("raw-data record truncated")?,
        u16_at(raw_rec, 4, rbig).ok_or("raw-data record truncated")?,
    );
    if w == 0 || h == 0 {
        return Err("the raw-data record states an empty frame".into());
    }
    let data = raw_rec.get(0x20..).ok_or("raw-data record truncated")?;
    let (w, h) = (u32::from(w), u32::from(h));
    let pixels = if data.starts_with(b"\x89PNG") {
        let img = image::load_from_memory_with_format(data, image::ImageFormat::Png)
            .map_err(|e| format!("the raw frame's PNG does not decode: {e}"))?;
        match img {
            image::DynamicImage::ImageLuma16(g) if (g.width(), g.height()) == (w, h) => {
                // FLIR writes the samples little-endian into the (big-endian) PNG.
                g.into_raw().into_iter().map(u16::swap_bytes).collect()
            }
            other => {
                return Err(format!(
                    "the raw frame is a {}×{} {:?} PNG, not the {w}×{h} 16-bit frame its header states (was the raw data stripped from this file?)",
                    other.width(),
                    other.height(),
                    other.color()
                ));
            }
        }
    } else {
        let n = (w * h) as usize;
        let bytes = data.get(..2 * n).ok_or(format!(
            "the raw frame holds {} bytes, not the {} of a {w}×{h} 16-bit frame",
            data.len(),
            2 * n
        ))?;
        bytes
            .chunks_exact(2)
            .map(|c| {
                if rbig {
                    u16::from_be_bytes([c[0], c[1]])
                } else {
                    u16::from_le_bytes([c[0], c[1]])
                }
            })
            .collect()
    };
    Ok(FlirImage {
        raw: Image {
            width: w,
            height: h,
            data: pixels,
        },
        planck,
        emissivity: f(32)?,
        reflected_k: f(40)?,
        atmosphere_k: f(44)?,
        camera_model,
        raw_median_range: (
            u16_at(info, 824, big).unwrap_or(0),
            u16_at(info, 828, big).unwrap_or(0),
        ),
    })
}

/// Reads a FLIR radiometric JPEG, naming the file in every error.
pub fn read(path: &Path) -> Result<FlirImage, CaptureError> {
    let bytes = std::fs::read(path).map_err(|e| CaptureError::file(path, e.to_string()))?;
    parse(&bytes).map_err(|r| CaptureError::file(path, r))
}

/// Builds a radiometric JPEG by the layout above: `base`'s JPEG with its FLIR segments replaced
/// by an FFF stream holding `camera_info` (a camera-info record, e.g. from a real file) and
/// `raw` as a byte-swapped 16-bit PNG, split into APP1 chunks of at most 65,000 bytes. No
/// registry package ships a FLIR file whose raw frame was left in (ExifTool's sample strips it),
/// so this is how the reader and `capture import` are tested on a complete file.
pub fn build(base: &[u8], camera_info: &[u8], raw: &Image<u16>) -> Result<Vec<u8>, String> {
    let mut png = Vec::new();
    let swapped: Vec<u16> = raw.data.iter().map(|v| v.swap_bytes()).collect();
    let buf =
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(raw.width, raw.height, swapped)
            .ok_or("raw frame size")?;
    buf.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    let w16 = |v: u32| -> Result<[u8; 2], String> {
        u16::try_from(v)
            .map(u16::to_le_bytes)
            .map_err(|_| "frame too large".into())
    };
    let mut raw_rec = vec![0u8; 0x20];
    raw_rec[0..2].copy_from_slice(&2u16.to_le_bytes());
    raw_rec[2..4].copy_from_slice(&w16(raw.width)?);
    raw_rec[4..6].copy_from_slice(&w16(raw.height)?);
    raw_rec.extend_from_slice(&png);
    let dir_off = 0x40usize;
    let data_off = dir_off + 2 * 32;
    let mut fff = vec![0u8; data_off];
    fff[0..4].copy_from_slice(b"FFF\0");
    fff[0x14..0x18].copy_from_slice(&100u32.to_be_bytes());
    fff[0x18..0x1c].copy_from_slice(&(dir_off as u32).to_be_bytes());
    fff[0x1c..0x20].copy_from_slice(&2u32.to_be_bytes());
    let mut off = data_off;
    for (k, (kind, rec)) in [(1u16, &raw_rec[..]), (0x20u16, camera_info)]
        .iter()
        .enumerate()
    {
        let e = dir_off + 32 * k;
        fff[e..e + 2].copy_from_slice(&kind.to_be_bytes());
        fff[e + 12..e + 16].copy_from_slice(&(off as u32).to_be_bytes());
        fff[e + 16..e + 20].copy_from_slice(&(rec.len() as u32).to_be_bytes());
        off += rec.len();
    }
    fff.extend_from_slice(&raw_rec);
    fff.extend_from_slice(camera_info);
    let chunks: Vec<&[u8]> = fff.chunks(65_000).collect();
    let last = u8::try_from(chunks.len() - 1).map_err(|_| "frame too large")?;
    let mut out = vec![0xFF, 0xD8];
    for (k, c) in chunks.iter().enumerate() {
        let len = u16::try_from(c.len() + 2 + 8).map_err(|_| "chunk too large")?;
        out.extend_from_slice(&[0xFF, 0xE1]);
        out.extend_from_slice(&len.to_be_bytes());
        out.extend_from_slice(b"FLIR\0\x01");
        out.push(k as u8);
        out.push(last);
        out.extend_from_slice(c);
    }
    // Copy the base's other segments and image data.
    let mut i = 2;
    while i + 4 <= base.len() && base[i] == 0xFF {
        let marker = base[i + 1];
        if marker == 0xDA {
            break;
        }
        let len = usize::from(u16::from_be_bytes([base[i + 2], base[i + 3]]));
        let end = (i + 2 + len).min(base.len());
        let flir = marker == 0xE1 && base.get(i + 4..i + 9) == Some(b"FLIR\0");
        if !flir {
            out.extend_from_slice(&base[i..end]);
        }
        i = end;
    }
    out.extend_from_slice(base.get(i..).unwrap_or(&[]));
    Ok(out)
}

/// The camera-info record of a FLIR JPEG (to [`build`] another file with its constants).
pub fn camera_info_record(jpeg: &[u8]) -> Result<Vec<u8>, String> {
    let stream = fff_stream(jpeg)?;
    let fff = Fff::new(&stream)?;
    fff.record(0x20)
        .map(<[u8]>::to_vec)
        .ok_or_else(|| "no camera-info record".into())
}
