//! `irmirror bench regimes`: the person's reflection size per capture regime over many seeds
//! (ideal sensor), as a table and a histogram PNG.

use anyhow::Result;
use image::{Rgb, RgbImage};
use irmirror_body::BodyModel;
use irmirror_sim::presets::{Regime, Shapes, regime_scene};
use irmirror_sim::{Sensor, simulate::reflection_pixels};
use std::path::Path;

/// The `q`-quantile of sorted values (nearest rank).
fn quantile(sorted: &[usize], q: f64) -> usize {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Reflection pixels of every regime's scene for seeds `first..first + n`.
pub fn measure(model: &BodyModel, first: u64, n: u64) -> Result<Vec<(Regime, Vec<usize>)>> {
    let bar = indicatif::ProgressBar::new(n * Regime::ALL.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "bench regimes {bar:40} {pos}/{len} {msg} {elapsed}",
        )
        .expect("valid template"),
    );
    let mut out = Vec::new();
    for regime in Regime::ALL {
        bar.set_message(regime.name());
        let mut px = Vec::new();
        for seed in first..first + n {
            let mut scene = regime_scene(model, regime, Shapes::Simple, seed)?;
            scene.sensor = Sensor::ideal();
            px.push(reflection_pixels(model, &scene)?);
            bar.inc(1);
        }
        out.push((regime, px));
    }
    bar.finish_and_clear();
    Ok(out)
}

/// Prints the table and writes the histogram (one row of bars per regime; bins of the base-2
/// logarithm of the pixel count, 0 px in the first bin; a grey line at 150 px).
pub fn run(first: u64, n: u64, png: &Path) -> Result<()> {
    let model = BodyModel::builtin()?;
    let data = measure(&model, first, n)?;
    println!(
        "reflection of the person, thermal pixels (ideal sensor), seeds {first}–{}:\n",
        first + n - 1
    );
    println!(
        "| regime | thermal camera | n | median | 10th pct | 90th pct | min | max | ≥ 150 px |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (regime, px) in &data {
        let mut s = px.clone();
        s.sort_unstable();
        let cam = regime.thermal().camera();
        println!(
            "| {regime} | {}×{} | {} | {} | {} | {} | {} | {} | {:.0} % |",
            cam.width,
            cam.height,
            s.len(),
            quantile(&s, 0.5),
            quantile(&s, 0.1),
            quantile(&s, 0.9),
            s[0],
            s[s.len() - 1],
            100.0 * s.iter().filter(|&&p| p >= 150).count() as f64 / s.len() as f64
        );
    }
    histogram(&data).save(png)?;
    println!("\nwrote {}", png.display());
    Ok(())
}

/// Bins: 0 px, then [2^k, 2^(k+1)) for k = 0..14.
const BINS: usize = 16;

fn bin(px: usize) -> usize {
    if px == 0 {
        0
    } else {
        (1 + px.ilog2() as usize).min(BINS - 1)
    }
}

fn histogram(data: &[(Regime, Vec<usize>)]) -> RgbImage {
    let (bw, row_h, m) = (24u32, 90u32, 10u32);
    let (w, h) = (2 * m + bw * BINS as u32, m + row_h * data.len() as u32);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let colours = [[40, 110, 200], [220, 120, 30], [120, 120, 120]];
    for (r, (_, px)) in data.iter().enumerate() {
        let mut counts = [0usize; BINS];
        px.iter().for_each(|&p| counts[bin(p)] += 1);
        let top = counts.iter().copied().max().unwrap_or(1).max(1);
        let base = m + row_h * (r as u32 + 1) - 4;
        for (b, &c) in counts.iter().enumerate() {
            let bar_h = ((row_h - 14) as f64 * c as f64 / top as f64) as u32;
            for x in m + b as u32 * bw + 2..m + (b as u32 + 1) * bw - 2 {
                for y in base - bar_h..base {
                    img.put_pixel(x, y, Rgb(colours[r % colours.len()]));
                }
            }
        }
        // Axis, and a grey line at 150 px (inside bin 8: [128, 256)).
        for x in m..w - m {
            img.put_pixel(x, base, Rgb([0, 0, 0]));
        }
        let x150 = m + 8 * bw + ((150.0f64.log2() - 7.0) * bw as f64) as u32;
        for y in base - row_h + 14..base {
            img.put_pixel(x150, y, Rgb([150, 150, 150]));
        }
    }
    img
}
