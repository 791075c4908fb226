//! Pose retrieval in the reflection's virtual view.
//!
//! Ranking the pose bank by the data term (one forward pass at the survivor's root) does not
//! find the training pose nearest the person's: held-out bowls at the exact true root and
//! facing, a start in that pose ends at 0.14 m per vertex, the data term's best of every
//! source pose at 0.20 m (EXPERIMENTS.md, "Twenty-second run"). The data term is sharp: a pose
//! whose outline is right but sits a few centimetres off scores like a wrong one. Retrieval
//! compares outlines with a tolerance instead. Each object's reflected rays are cut with the plane
//! through the state's root facing that object — the person as the object sees them, a
//! virtual view, whatever the mirror's curvature — and each candidate body is projected from
//! the object's centre onto the same plane and rasterised. A candidate is scored by a
//! truncated chamfer distance: each mask ray's distance to the silhouette plus each other
//! ray's distance to the silhouette's outside, per mask ray, at the best of a few small
//! shifts in the plane.
//!
//! Measured (8 held-out bowls at the exact true root and facing, EXPERIMENTS.md "Twenty-third
//! run"): the first pick ends the refinement at 0.27 m per vertex, the mean of the best 30 at 0.19
//! m ("stand" 0.30, the nearest source pose 0.16). It finds a better pose at a known facing,
//! not the facing: at the search's survivors it is off.

use super::bank::PoseMode;
use super::raster::{Distances, ceil_i, floor_i};
use super::{HumanProblem, HumanState};
use crate::ReconError;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

/// Retrieval's raster and tolerance (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetrievalConfig {
    /// Raster cell in the plane, m.
    pub cell_m: f64,
    /// Half the raster's width and height about the root, m.
    pub half_width_m: f64,
    /// Shifts tried in the plane: ± this, m, in steps of `shift_step_m`.
    pub shift_m: f64,
    /// The shifts' step, m (rounded to whole cells).
    pub shift_step_m: f64,
    /// A ray's distance counts up to this, m.
    pub truncate_m: f64,
    /// Each survivor of the search takes the pose retrieved at its root and facing
    /// ([`HumanProblem::retrieval_swap`]; its front/back partner is that state turned) before
    /// the refinement. Off: on 24 held-out bowls with `mean_of = 30` root median 0.148 →
    /// 0.092 m but per-vertex +0.049 ± 0.055 m (paired), successes 10 → 9; retrieving the
    /// partners' poses too, +0.071 ± 0.059 m, successes 7 (EXPERIMENTS.md, "Twenty-third run").
    /// Retried since: held-out bowls per-vertex +0.049 ± 0.046 m, successes 10 → 8; tuning
    /// bowls root median 0.101 → 0.121 m (EXPERIMENTS.md, "Thirty-seventh run"); after the
    /// judge turned the survivors (`facing = true`): tuning bowls root +0.030 ± 0.032 m,
    /// held-out successes 10 → 8 (EXPERIMENTS.md, "Thirty-eighth run").
    pub survivors: bool,
    /// The most rays outside the mask scored per object (evenly strided).
    pub max_empty_rays: usize,
    /// The start [`HumanProblem::retrieved_start`] gives: the mean of the best `mean_of`
    /// candidates' latents and roots (1: the best alone). Where many poses explain the
    /// outline about equally well, their mean is nearer the person than any one of them.
    pub mean_of: usize,
    /// The thermal facing judge ([`HumanProblem::thermal_facing`]): each survivor of the
    /// search turned to its silhouette twin when the twin's thermal residual is lower, and the
    /// refined hypotheses ranked with the best by loss the judge does not turn first. Off: on 24
    /// held-out bowls the fits turned ≥ 120° fall 5 → 3 and the root median 0.148 → 0.097 m,
    /// but facing within 30° stays 13, per-vertex −0.011 ± 0.033 m (paired), and stage 2
    /// takes several times as long (EXPERIMENTS.md, "Twenty-fourth run"); on 12 held-out cars,
    /// where the judge picks the true facing at the truth on 8 and on the fits' hypotheses on 14 of
    /// 25, facing within 30° 9 → 4 (EXPERIMENTS.md, "Twenty-fifth run"). Retried at the judge's
    /// cost since: tuning bowls' successes 9 → 13, held-out bowls' 10 → 10 (facing within 30° 11 →
    /// 13), the tuning hard view's 4 → 0, stage 2 1.25–2× as long (EXPERIMENTS.md, "Thirty-sixth
    /// run"). Off, the judge still acts where the reflection shows no head
    /// (`facing_head_share`).
    pub facing: bool,
    /// The judge compares the best of this many outline-ranked poses per facing. 10 against
    /// 30: held-out mugs facing within 30° 8 → 11, per-vertex −0.044 ± 0.072 m (paired),
    /// successes 4 → 3; tuning mugs 11 → 12; held-out bowls 1 of 24 changed (better), cars
    /// and the hard view identical; the slowest of BENCHMARKS' six frames 12.4 → 10.9 s
    /// (EXPERIMENTS.md, "Thirty-fourth run").
    pub facing_top: usize,
    /// The judge draws its poses from this many source poses, spread by farthest-point
    /// sampling in joint-rotation space (0: the whole bank, 729). Fewer are cheaper and lose
    /// held-out mugs' successes: 365 or 486, 4 → 1 of 24 (EXPERIMENTS.md, "Thirty-fourth run").
    pub facing_bank: usize,
    /// With `facing` on, the judge turns the search's survivors too (off: it ranks the
    /// refined hypotheses only — the survivors' front/back flips are refined either way; on
    /// 24 held-out bowls facing within 30° 14 (13 with the survivors turned), but root median
    /// 0.151 m (0.097) and per-vertex −0.004 ± 0.029 m against no judge: the survivors' turn
    /// is where its gain comes from; EXPERIMENTS.md, "Twenty-fifth run").
    pub facing_survivors: bool,
    /// The judge abstains (keeps a state) where its silhouette twin faces less than this many
    /// degrees away from it (0: it always judges). At 120 on 12 held-out cars facing within
    /// 30° 4 → 7 of 12 (none: 9), and on 24 bowls the judge's gain gone (EXPERIMENTS.md,
    /// "Twenty-fifth run").
    pub facing_min_turn_deg: f64,
    /// With `facing` off, the judge still acts where the reflection shows no head: where the
    /// face and hair make less than this share of the rise the radiometric model predicts for
    /// every survivor of the search (for the ranking: every refined hypothesis); 0: never. A
    /// mug on a table sees a band of the torso: the true body's face and hair make ≥ 5 % of its
    /// rise on 4 of 24 held-out mugs (bowls 21, the hard view 24, cars 22), and where they make
    /// less the data term tells the true body from its outline twin on 5 of 20 (where they
    /// make more: 41 of 45 bowls, 20 of 24 hard-view captures) — there the judge's
    /// outline-tolerant comparison is the only front/back cue left. Where it acts, a frame took
    /// 1.6–2× as long (EXPERIMENTS.md, "Thirty-third run"; cheaper since, "Thirty-fourth run").
    /// Re-measured off on 48 held-out mugs: accuracy level (per-vertex +0.013 ± 0.034 m),
    /// facing within 30° 15 → 12, a mug frame ≈ 40 % shorter (EXPERIMENTS.md, "Forty-ninth run").
    pub facing_head_share: f64,
    /// The ranking judgement ([`HumanProblem::facing_first`]) judges at most this many of the
    /// refined hypotheses, best by loss first (0: every one). Each judgement retrieves the
    /// bank twice (≈ 1 s on a 640 × 512 mug; held-out mug 16 judges four). At 2 on 48
    /// held-out mugs 7 changed, level (per-vertex −0.010 ± 0.015 m, facing within 30° 15 →
    /// 16; EXPERIMENTS.md, "Fifty-first run").
    pub facing_rank_max: usize,
}

impl Default for RetrievalConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.02,
            half_width_m: 1.3,
            shift_m: 0.08,
            shift_step_m: 0.04,
            truncate_m: 0.15,
            survivors: false,
            max_empty_rays: 3000,
            mean_of: 1,
            facing: false,
            facing_top: 10,
            facing_bank: 0,
            facing_survivors: true,
            facing_min_turn_deg: 0.0,
            facing_head_share: 0.05,
            facing_rank_max: 0,
        }
    }
}

impl RetrievalConfig {
    /// The judge's bank size ([`Self::facing_bank`]; 0: all).
    pub(super) fn judge_bank(&self) -> usize {
        if self.facing_bank == 0 {
            usize::MAX
        } else {
            self.facing_bank
        }
    }

    /// Refuses a raster no retrieval can use: a length not a finite number > 0 (the shift's
    /// range ≥ 0), or more than 1,000 cells a side.
    pub fn check(&self) -> Result<(), ReconError> {
        let lengths = [
            ("cell_m", self.cell_m),
            ("half_width_m", self.half_width_m),
            ("shift_step_m", self.shift_step_m),
            ("truncate_m", self.truncate_m),
        ];
        for (name, v) in lengths {
            if !(v.is_finite() && v > 0.0) {
                return Err(ReconError::Config(format!(
                    "[human.retrieval] {name} = {v}: must be a finite number > 0 (m)"
                )));
            }
        }
        if !(self.shift_m.is_finite() && self.shift_m >= 0.0) {
            return Err(ReconError::Config(format!(
                "[human.retrieval] shift_m = {}: must be a finite number ≥ 0 (m)",
                self.shift_m
            )));
        }
        if !(0.0..=180.0).contains(&self.facing_min_turn_deg) {
            return Err(ReconError::Config(format!(
                "[human.retrieval] facing_min_turn_deg = {}: must lie in 0–180 (degrees)",
                self.facing_min_turn_deg
            )));
        }
        if !(0.0..=1.0).contains(&self.facing_head_share) {
            return Err(ReconError::Config(format!(
                "[human.retrieval] facing_head_share = {}: must lie in 0–1",
                self.facing_head_share
            )));
        }
        if side(self) > 1000 {
            return Err(ReconError::Config(format!(
                "[human.retrieval] {} cells a side (2 × half_width_m / cell_m): at most 1000",
                side(self)
            )));
        }
        Ok(())
    }
}

/// One object's virtual view of the plane through the root (module docs).
pub(super) struct View {
    pub(super) centre: Vector3<f64>,
    pub(super) axis: Vector3<f64>,
    /// The plane's axes in cells per metre: `e_u / cell_m`, `e_v / cell_m`.
    to_u: Vector3<f64>,
    to_v: Vector3<f64>,
    /// The raster coordinates of the centre's foot on the plane (the root, up to rounding):
    /// `((centre − root) · e + half_width_m) / cell_m` per axis.
    offset: (f64, f64),
    /// The root's distance along the axis from the centre: `(root − centre) · axis`.
    depth: f64,
    /// Raster cells of the mask rays' plane points.
    pub(super) mask: Vec<(i32, i32)>,
    /// The mask rays themselves (indices among the problem's rays), as `mask`.
    pub(super) mask_ray: Vec<usize>,
    /// Raster cells of the other rays' plane points.
    empty: Vec<(i32, i32)>,
}

impl View {
    /// `p`'s raster cell in the plane, projected from the centre (`None`: behind the centre).
    /// The point on the plane is `centre + (p − centre) s` with `s = depth / along`, so its
    /// raster coordinates are `s (p − centre) · to + offset`: one division a vertex.
    #[inline]
    fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        let d = p - self.centre;
        let along = d.dot(&self.axis);
        if along < 1e-3 {
            return None;
        }
        let s = self.depth / along;
        Some((
            s * d.dot(&self.to_u) + self.offset.0,
            s * d.dot(&self.to_v) + self.offset.1,
        ))
    }
}

/// Cells per side of the raster.
pub(super) fn side(cfg: &RetrievalConfig) -> usize {
    (2.0 * cfg.half_width_m / cfg.cell_m).ceil() as usize
}

impl HumanProblem<'_> {
    /// Each object's virtual view of the plane through `root` (module docs); objects with no
    /// mask ray in the raster are left out.
    pub(super) fn views(&self, root: &Vector3<f64>, cfg: &RetrievalConfig) -> Vec<View> {
        let up = self.up.normalize();
        let objects = self.rays.object.iter().copied().max().map_or(0, |m| m + 1);
        let n = side(cfg) as i32;
        (0..objects)
            .filter_map(|k| {
                let rays: Vec<usize> = (0..self.rays.len())
                    .filter(|&i| self.rays.object[i] == k)
                    .collect();
                if rays.is_empty() {
                    return None;
                }
                let centre = rays
                    .iter()
                    .map(|&i| self.rays.origin[i])
                    .sum::<Vector3<f64>>()
                    / rays.len() as f64;
                let axis = (root - centre).try_normalize(1e-9)?;
                let e_v = (up - axis * axis.dot(&up)).try_normalize(1e-9)?;
                let e_u = e_v.cross(&axis);
                let mut view = View {
                    centre,
                    axis,
                    to_u: e_u / cfg.cell_m,
                    to_v: e_v / cfg.cell_m,
                    offset: (
                        ((centre - root).dot(&e_u) + cfg.half_width_m) / cfg.cell_m,
                        ((centre - root).dot(&e_v) + cfg.half_width_m) / cfg.cell_m,
                    ),
                    depth: (root - centre).dot(&axis),
                    mask: Vec::new(),
                    mask_ray: Vec::new(),
                    empty: Vec::new(),
                };
                let mut empty = Vec::new();
                for &i in &rays {
                    let (o, d) = (self.rays.origin[i], self.rays.dir[i]);
                    let den = d.dot(&axis);
                    if den < 0.1 {
                        continue;
                    }
                    let t = (root - o).dot(&axis) / den;
                    let q = o + d * t - root;
                    let c = (
                        ((q.dot(&e_u) + cfg.half_width_m) / cfg.cell_m).floor() as i32,
                        ((q.dot(&e_v) + cfg.half_width_m) / cfg.cell_m).floor() as i32,
                    );
                    if c.0 < 0 || c.1 < 0 || c.0 >= n || c.1 >= n {
                        continue;
                    }
                    if self.mask.data[self.rays.pixel[i] as usize] {
                        view.mask.push(c);
                        view.mask_ray.push(i);
                    } else {
                        empty.push(c);
                    }
                }
                let stride = empty.len().div_ceil(cfg.max_empty_rays.max(1)).max(1);
                view.empty = empty.into_iter().step_by(stride).collect();
                (!view.mask.is_empty()).then_some(view)
            })
            .collect()
    }

    /// The silhouette of `vertices` in `view`'s raster: every cell whose centre a projected
    /// triangle covers.
    fn silhouette(
        &self,
        vertices: &[Vector3<f64>],
        view: &View,
        cfg: &RetrievalConfig,
    ) -> Vec<bool> {
        let n = side(cfg);
        let mut sil = vec![false; n * n];
        self.cover(vertices, view, cfg, |_, cell| sil[cell] = true);
        sil
    }

    /// Calls `f(triangle, cell)` for every raster cell whose centre a projected triangle of
    /// `vertices` covers.
    pub(super) fn cover(
        &self,
        vertices: &[Vector3<f64>],
        view: &View,
        cfg: &RetrievalConfig,
        mut f: impl FnMut(usize, usize),
    ) {
        let n = side(cfg) as i64;
        let last = (n - 1) as i32;
        let cell = |x: i64| x.clamp(-1, n) as i32;
        // Per vertex: its raster point, and the first and last cell whose centre (`x + 0.5`)
        // lies at or beyond it (`ceil(u − 0.5)`) and at or before it (`floor(u − 0.5)`), each
        // way, clamped to one cell off the raster. All are monotone, so a triangle's cell
        // range is the min / max over its corners: made once per vertex, not per triangle (a
        // body's triangles mostly cover no cell centre), kept apart from the points so that
        // the triangles' rejection reads 16 bytes a corner.
        let mut at = Vec::with_capacity(vertices.len());
        let mut span = Vec::with_capacity(vertices.len());
        for v in vertices {
            let p = view.project(v);
            span.push(p.map_or([0, -1, 0, -1], |(u, w)| {
                [
                    cell(ceil_i(u - 0.5)),
                    cell(floor_i(u - 0.5)),
                    cell(ceil_i(w - 0.5)),
                    cell(floor_i(w - 0.5)),
                ]
            }));
            at.push(p);
        }
        // The triangles whose cell range is not empty, listed without a branch: which of them
        // cover a centre is as good as random, and a mispredicted branch a triangle cost more
        // than the test. The few listed make their range again below (cheaper than writing
        // every triangle's range here).
        let faces = &self.model.asset.faces;
        let mut hit = vec![0u32; faces.len()];
        let mut m = 0;
        for (t, face) in faces.iter().enumerate() {
            let [a, b, c] = face.map(|i| span[i as usize]);
            let x0 = a[0].min(b[0]).min(c[0]).max(0);
            let x1 = a[1].max(b[1]).max(c[1]).min(last);
            let y0 = a[2].min(b[2]).min(c[2]).max(0);
            let y1 = a[3].max(b[3]).max(c[3]).min(last);
            hit[m] = t as u32; // m ≤ t: in bounds
            m += usize::from((x0 <= x1) & (y0 <= y1));
        }
        for &t in &hit[..m] {
            let (t, face) = (t as usize, &faces[t as usize]);
            let [a, b, c] = face.map(|i| span[i as usize]);
            let x0 = a[0].min(b[0]).min(c[0]).max(0);
            let x1 = a[1].max(b[1]).max(c[1]).min(last);
            let y0 = a[2].min(b[2]).min(c[2]).max(0);
            let y1 = a[3].max(b[3]).max(c[3]).min(last);
            // A corner behind the view's centre: the triangle is not drawn.
            let [Some(a), Some(b), Some(c)] = face.map(|i| at[i as usize]) else {
                continue;
            };
            let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            if area.abs() < 1e-12 {
                continue;
            }
            let edge = |p: (f64, f64), q: (f64, f64), x: f64, y: f64| {
                ((q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0)) * area.signum()
            };
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                    if edge(a, b, px, py) >= 0.0
                        && edge(b, c, px, py) >= 0.0
                        && edge(c, a, px, py) >= 0.0
                    {
                        f(t, y as usize * n as usize + x as usize);
                    }
                }
            }
        }
    }

    /// The retrieval score of body `vertices` (depth frame) in `views` (module docs): per view,
    /// the truncated chamfer per mask ray at its best shift, summed over the views; lower is
    /// better.
    fn retrieval_score(
        &self,
        vertices: &[Vector3<f64>],
        views: &[View],
        cfg: &RetrievalConfig,
    ) -> f64 {
        views
            .iter()
            .map(|view| self.view_score(vertices, view, cfg).0)
            .sum()
    }

    /// One view's share of [`Self::retrieval_score`] and the shift (cells) it was taken at.
    pub(super) fn view_score(
        &self,
        vertices: &[Vector3<f64>],
        view: &View,
        cfg: &RetrievalConfig,
    ) -> (f64, (i32, i32)) {
        self.view_score_below(vertices, view, cfg, f64::INFINITY)
            .unwrap_or((f64::INFINITY, (0, 0)))
    }

    /// [`Self::view_score`] where it may lie below `bound`, `None` where it surely does not: a
    /// retrieval of the best few cuts a pose as soon as it cannot be among them, and most of a
    /// bank's poses fail the bound within a shift's first sums (the terms are ≥ 0, so a partial
    /// sum above it settles the shift; the sums that finish are added in the same order, so
    /// the score is the same bit for bit).
    fn view_score_below(
        &self,
        vertices: &[Vector3<f64>],
        view: &View,
        cfg: &RetrievalConfig,
        bound: f64,
    ) -> Option<(f64, (i32, i32))> {
        let n = side(cfg);
        let step = ((cfg.shift_step_m / cfg.cell_m).round() as i32).max(1);
        let reach = (cfg.shift_m / cfg.cell_m / f64::from(step)).round() as i32;
        let cap = cfg.truncate_m / cfg.cell_m;
        let dist = Distances::new(&self.silhouette(vertices, view, cfg), n, cap);
        // Only the rays outside the mask that some shift brings into the silhouette's box can
        // spill.
        let r = reach * step;
        let near: Vec<(i32, i32)> = view
            .empty
            .iter()
            .copied()
            .filter(|&(x, y)| dist.out.near(x, y, r))
            .collect();
        // The bound in the sums' units, a hair loose: a score within rounding of it is
        // finished, and the caller's own comparison decides.
        let scale = view.mask.len() as f64 / cfg.cell_m;
        let mut best = (bound.max(0.0) * scale * (1.0 + 1e-9) + 1e-300, None);
        for du in (-reach..=reach).map(|k| k * step) {
            for dv in (-reach..=reach).map(|k| k * step) {
                // The window lies on the raster: off it, no body is there.
                let mut miss = 0.0;
                for &(x, y) in &view.mask {
                    miss += dist.to_sil(x + du, y + dv);
                    if miss > best.0 {
                        break;
                    }
                }
                if miss >= best.0 {
                    // The spill is ≥ 0: this shift cannot win.
                    continue;
                }
                let mut spill = 0.0;
                for &(x, y) in &near {
                    spill += dist.to_out(x + du, y + dv);
                    if miss + spill >= best.0 {
                        break;
                    }
                }
                if miss + spill < best.0 {
                    best = (miss + spill, Some((du, dv)));
                }
            }
        }
        best.1
            .map(|shift| (best.0 * cfg.cell_m / view.mask.len() as f64, shift))
    }

    /// `st` tried in every pose of `bank` (its root and facing kept, the feet moved to the
    /// floor when known: [`Self::in_mode`]), ranked by the retrieval score (module docs): the
    /// bank's indices of the best `keep` (all: `usize::MAX`), best first, with their scores —
    /// ties in the bank's order.
    ///
    /// Exact, and cheaper for a small `keep`: a pose whose views scored so far already sum
    /// above the worst of the best `keep` complete scores seen is not scored further (its own
    /// is higher still, and that worst only falls), so which poses are cut depends on the
    /// workers' timing but the answer does not.
    pub(super) fn retrieve(
        &self,
        st: &HumanState,
        bank: &[PoseMode],
        cfg: &RetrievalConfig,
        keep: usize,
    ) -> Result<Vec<(usize, f64)>, ReconError> {
        let views = self.views(&st.translation, cfg);
        if views.is_empty() {
            return Ok(Vec::new());
        }
        let keep = keep.max(1);
        let shaped = super::shaped_body(self.model, &st.build, st.height)?;
        let best = Mutex::new(BinaryHeap::with_capacity(keep.min(bank.len()) + 1));
        let bar = AtomicU64::new(f64::INFINITY.to_bits());
        // One posing buffer per worker: a body's buffers are megabytes.
        bank.par_iter().enumerate().try_for_each_init(
            || self.model.posed_buffers(),
            |body, (i, mode)| -> Result<(), ReconError> {
                let mut rotations = mode.rotations.clone();
                rotations[0] = st.rotation;
                let pose = irmirror_body::Pose {
                    rotations,
                    translation: self.mode_root(st, mode),
                };
                self.model.pose_surface_into(&shaped, &pose, body)?;
                let mut score = 0.0;
                for view in &views {
                    let cut = f64::from_bits(bar.load(AtomicOrdering::Relaxed));
                    match self.view_score_below(&body.vertices, view, cfg, cut - score) {
                        Some((s, _)) => score += s,
                        None => return Ok(()),
                    }
                    if score > f64::from_bits(bar.load(AtomicOrdering::Relaxed)) {
                        return Ok(());
                    }
                }
                let mut heap = best.lock().unwrap_or_else(|e| e.into_inner());
                heap.push(Scored(score, i));
                if heap.len() > keep {
                    heap.pop();
                }
                if heap.len() == keep
                    && let Some(worst) = heap.peek()
                {
                    bar.store(worst.0.to_bits(), AtomicOrdering::Relaxed);
                }
                Ok(())
            },
        )?;
        Ok(best
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .into_sorted_vec()
            .into_iter()
            .map(|Scored(score, i)| (i, score))
            .collect())
    }

    /// State `st`'s body on the already shaped `shaped` (the retrieval poses hundreds of
    /// bodies of one height: the shape is made once).
    pub(super) fn posed_with(
        &self,
        shaped: &irmirror_body::ShapedBody<f64>,
        st: &HumanState,
    ) -> Result<irmirror_body::PosedBody<f64>, ReconError> {
        Ok(self.model.pose(
            shaped,
            &irmirror_body::Pose {
                rotations: super::joint_rotations(self.prior, st)?,
                translation: st.translation,
            },
        )?)
    }

    /// The retrieval score of any body `vertices` (depth frame) in the views through `root`
    /// (`None`: no view sees the mask).
    pub fn retrieval_score_at(
        &self,
        root: &Vector3<f64>,
        vertices: &[Vector3<f64>],
        cfg: &RetrievalConfig,
    ) -> Option<f64> {
        let views = self.views(root, cfg);
        (!views.is_empty()).then(|| self.retrieval_score(vertices, &views, cfg))
    }

    /// `st` in every source pose ([`Self::source_poses`], its feet on the floor when known),
    /// with its retrieval score, best first, the best `keep` of them (all: `usize::MAX`);
    /// empty when no view sees the mask.
    pub fn retrieval_candidates(
        &self,
        st: &HumanState,
        cfg: &RetrievalConfig,
        keep: usize,
    ) -> Result<Vec<(HumanState, f64)>, ReconError> {
        let bank = self.pose_bank(usize::MAX, st.height)?;
        self.candidates_in(st, &bank, cfg, keep)
    }

    /// [`Self::retrieval_candidates`] among the poses of `bank`, the best `keep` of them.
    pub(super) fn candidates_in(
        &self,
        st: &HumanState,
        bank: &[PoseMode],
        cfg: &RetrievalConfig,
        keep: usize,
    ) -> Result<Vec<(HumanState, f64)>, ReconError> {
        Ok(self
            .retrieve(st, bank, cfg, keep)?
            .into_iter()
            .map(|(i, score)| (self.in_mode(st, &bank[i]), score))
            .collect())
    }

    /// `st` in the pose the retrieval ranks first among the prior's source poses, or the mean
    /// of the best `mean_of` (latents and roots); `st` when nothing is seen.
    pub fn retrieved_start(
        &self,
        st: &HumanState,
        cfg: &RetrievalConfig,
    ) -> Result<HumanState, ReconError> {
        let cands = self.retrieval_candidates(st, cfg, cfg.mean_of.max(1))?;
        Ok(mean_state(st, &cands, cfg.mean_of))
    }

    /// Each survivor in its retrieved pose ([`Self::retrieved_start`]) when `survivors` is on.
    pub fn retrieval_swap(
        &self,
        survivors: Vec<HumanState>,
        cfg: &RetrievalConfig,
    ) -> Result<Vec<HumanState>, ReconError> {
        let Some(first) = survivors.first().filter(|_| cfg.survivors) else {
            return Ok(survivors);
        };
        let t0 = std::time::Instant::now();
        let bank = self.pose_bank(usize::MAX, first.height)?;
        let out = survivors
            .iter()
            .map(|st| {
                Ok(mean_state(
                    st,
                    &self.candidates_in(st, &bank, cfg, cfg.mean_of)?,
                    cfg.mean_of,
                ))
            })
            .collect::<Result<_, ReconError>>()?;
        tracing::debug!(
            "pose retrieval: {} survivors, {:.2} s",
            survivors.len(),
            t0.elapsed().as_secs_f64()
        );
        Ok(out)
    }
}

/// A scored pose in the retrieval's running best: ordered by score, then by its index in the
/// bank (the order a stable sort of the bank by score gives).
struct Scored(f64, usize);

impl PartialEq for Scored {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Scored {}

impl PartialOrd for Scored {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Scored {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

/// The mean of the best `mean_of` of `cands` (sorted, best first): latents and roots; `st`
/// when there are none.
fn mean_state(st: &HumanState, cands: &[(HumanState, f64)], mean_of: usize) -> HumanState {
    let best = &cands[..mean_of.max(1).min(cands.len())];
    let Some((first, _)) = best.first() else {
        return st.clone();
    };
    let k = best.len() as f64;
    let mut out = first.clone();
    out.translation = best
        .iter()
        .map(|(s, _)| s.translation)
        .sum::<Vector3<f64>>()
        / k;
    for (j, z) in out.latent.iter_mut().enumerate() {
        *z = best.iter().map(|(s, _)| s.latent[j]).sum::<f64>() / k;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A raster that is not one is refused with the field's name.
    #[test]
    fn a_bad_raster_is_refused() {
        assert!(RetrievalConfig::default().check().is_ok());
        for (cfg, field) in [
            (
                RetrievalConfig {
                    cell_m: 0.0,
                    ..Default::default()
                },
                "cell_m",
            ),
            (
                RetrievalConfig {
                    truncate_m: f64::NAN,
                    ..Default::default()
                },
                "truncate_m",
            ),
            (
                RetrievalConfig {
                    shift_m: -1.0,
                    ..Default::default()
                },
                "shift_m",
            ),
            (
                RetrievalConfig {
                    facing_head_share: f64::NAN,
                    ..Default::default()
                },
                "facing_head_share",
            ),
            (
                RetrievalConfig {
                    cell_m: 1e-4,
                    ..Default::default()
                },
                "cells a side",
            ),
            (
                RetrievalConfig {
                    facing_min_turn_deg: f64::NAN,
                    ..Default::default()
                },
                "facing_min_turn_deg",
            ),
        ] {
            let e = cfg.check().unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
        }
    }
}
