//! Beyond the paper: stage 2's radiometric data term — the thermal rise itself, not a binary
//! mask.
//!
//! **Observation model.** A reflected ray `i` that the person covers with soft occupancy `o_i`
//! shows, instead of the room, the body region `r(i)` it meets; pixel `p` integrates the rays
//! of its footprint through the optics' point spread:
//!
//! ```text
//! ŷ_p = g_k(p) · Σ_i W_pi · o_i · c_r(i),    c_r = ε_r (B(T_r) − B(T_amb)) / B'(T_amb)
//! ```
//!
//! `W` the observation operator: each pixel is sampled by `n × n` rays (the box's midpoint
//! grid, 2 × 2 to 4 × 4 as `footprint_max_rays` allows, `pipeline::footprint_offsets`; a
//! node that misses the objects shows the room) and their mean is convolved with the
//! capture's Gaussian point spread (`thermal_camera.psf_sigma_px`), so a pixel half covered
//! rises half as much and a thin limb spreads into its neighbours (reflections over
//! `footprint_max_mask_px`: one ray per pixel, `W` = 1). `g_k` the LWIR reflectance
//! (1 − emissivity) of the object under most of the pixel's weight, `T_r` the region's surface
//! temperature (face, hair, bare skin, clothing: `irmirror_body::regions`), `ε_r` its
//! emissivity, `B` the band radiance and `T_amb` the room the mirror shows without the person (the background frames' median apparent
//! temperature on the objects). The rise is linear in radiance, so dividing by `B'` turns
//! radiance into apparent kelvin to first order (≤ 2 % over a 1 K rise).
//!
//! **Unknowns.** What the data cannot give alone: each object's reflectance `g_k` and the
//! person's temperatures. The regions' temperatures are not free: each is the centre of its
//! cited range (`irmirror_body::regions::THERMAL`) plus one common offset `Δ` (prior N(0, 1 K),
//! bounded ±2.5 K) plus, optionally, its own deviation `δ_r` within the range (prior the range's
//! uniform σ, bounded by its half-width; [`RadiometricConfig::region_spread`], off by default), so
//! `c_r ≈ a_r + b_r (Δ + δ_r)`. Fitting one free temperature per region was tried first and let
//! a body turned around explain a face as 33 °C hair and a misplaced arm as skin at room
//! temperature (tuning set: the best-by-loss hypothesis faced the wrong way in most tabletop
//! captures); with the regions tied to their ranges, the face stays warmer than the hair on
//! the back of a head — the front/back cue. `g_k` has a prior for glazed ceramic and car paint
//! ([`RadiometricConfig::reflectance_prior`]) and bounds. All are solved inside every loss
//! evaluation: Huber IRLS rounds, each by block coordinates — golden section over `Δ` with the
//! reflectances in closed form at each `Δ`, then the deviations (a bounded 4 × 4 quadratic).
//!
//! **Loss.** `D = [Σ_p w_p ψ((y_p − ŷ_p)/σ) + f P − F] / [Σ_p w_p ψ(y_p/σ) − F]`: Huber `ψ`
//! (quadratic within `huber_sigmas`), `σ` the rise's noise (stage 0's robust estimate), `w_p`
//! the batch's importance weights, `P` the priors' `½ Σ ((x − x̄)/s)²` over `g_k`, `Δ` and
//! `δ_r`, `f` the batch's share of all pixels (a sample weighs the priors as the full set would),
//! `F = E ψ(noise) Σ w` what noise alone scores. `D` = 1 for "nobody there" and ≈ 0 for a fit
//! down to the noise, like `1 − IoU`, so the body's priors keep their weight against it.
//!
//! **Gradient.** The scalars minimise the numerator, so the gradient holds them fixed (envelope
//! theorem). It flows back through `W` (a ray feeds several pixels) to the occupancies and
//! through the region shares `β` of each ray's hit point (the hit point's barycentric weights
//! move with its triangle: `problem.rs`, `mix_backward`). Which triangle a ray hits first
//! jumps where one body part passes behind another and has no gradient.

use super::observe::Rise;
use crate::ReconError;
use crate::preprocess::Preprocessed;
use irmirror_body::Region;
use irmirror_body::regions::{head_regions, triangle_regions, vertex_regions};
use irmirror_capture::planck::band_radiance;
use irmirror_render::reflect::ReflectedRays;
use serde::{Deserialize, Serialize};

/// Regions, in `Region::ALL` order.
pub const REGIONS: usize = 4;

/// Settings of the radiometric data term.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RadiometricConfig {
    /// Fit the thermal rise (true) or the binary mask (the paper's mode; `--ablate radiometric`).
    pub enabled: bool,
    /// Prior on each object's LWIR reflectance: mean and σ. Glazed ceramic (emissivity
    /// 0.90–0.92) and car paint (0.92–0.94) reflect 6–10 % (e.g. the emissivity tables of
    /// Optris' and FLIR's thermography guides); polished metal would need its own.
    pub reflectance_prior: [f64; 2],
    /// σ of the person's common temperature offset from the regions' range centres, K.
    pub offset_sigma_k: f64,
    /// Bound of that offset, K; the reflectances stay within the prior's mean ±
    /// `reflectance_bound_sigmas` σ. A body part where the mirror shows nothing cannot be
    /// explained away as skin at room temperature, nor a mug as a mirror that reflects nothing.
    pub offset_bound_k: f64,
    /// See `offset_bound_k`.
    pub reflectance_bound_sigmas: f64,
    /// Per region (`Region::ALL`'s order: clothing, bare skin, face, hair): its temperature
    /// also deviates from the common offset on its own, anywhere in its cited range (prior σ
    /// the range's uniform σ, half-width / √3; bounded by the half-width; the face stays at
    /// least 1.5 K warmer than the hair). Off by default: on held-out captures (session 84,
    /// EXPERIMENTS.md "Forty-sixth run") every region on placed the hard view's 30-mK captures
    /// nearer (root −0.046 ± 0.039 m, as near as told the true temperatures) but faced fewer
    /// fits the right way (within 30°: hard view 26 → 23 of 60, mugs 9 → 6 of 24), the other
    /// cells' roots within their noise.
    pub region_spread: [bool; REGIONS],
    /// Huber threshold of the residuals, in noise σ.
    pub huber_sigmas: f64,
    /// Steps of the thermal rise after a search and refinement on the mask (0: the rise from
    /// the search's rounds on). 0 on 24 held-out bowls: refined from the truth 0.141 → 0.116 m
    /// per vertex, the fit −0.029 ± 0.073 m (paired), stage 2 ≈ 1.8× as long; on the held-out
    /// hard view root −0.056 ± 0.046 m but facing within 30° 13 → 6 (EXPERIMENTS.md,
    /// "Thirty-ninth run").
    pub polish_iterations: usize,
    /// On a reflection of at most this many pixels (with rays), the rise pass
    /// ([`super::HumanProblem::rise_pass`]): a second search fits the rise throughout, the
    /// mask's gives the side. 0: never. 50 (default) on the held-out hard view (Lepton-like,
    /// 12–47 pixels): root median 0.199 → 0.162 m (paired −0.044 ± 0.039 m), facing within 30°
    /// 13 → 12 of 24; on the paper-like tabletops' ten captures that small (14–69 pixels) a
    /// bowl went 0.20 → 1.77 m and a mug 0.11 → 0.68 m off without the guard
    /// (`rise_pass_max_move_m`), with it one bowl 0.04 → 0.27 m and the cells' medians
    /// unchanged (EXPERIMENTS.md, "Fortieth run").
    pub rise_pass_max_mask_px: usize,
    /// The rise pass's states are reported only when its first lies within this distance of
    /// the mask search's winner (m; 0: always; default 0.5): the mask's search finds the
    /// basin, the rise places the person in it.
    pub rise_pass_max_move_m: f64,
    /// The rise pass reports first its best hypothesis on the mask search winner's side
    /// (facing within 90° of it) rather than its best by loss: the mask's search with its
    /// polish chose front or back. Off (default): on the held-out hard view, with the rise on
    /// a 4 × 4 footprint of a simulator that integrates each pixel, the rise's own best faced
    /// right more often (EXPERIMENTS.md, "Forty-eighth run").
    pub rise_pass_side: bool,
    /// Refined hypotheses that take the polish: the best this many by the rise before it, and
    /// the best one's front/back partner (the pair the rise is there to tell apart); the others
    /// are ranked on the rise as they stand. 0: every hypothesis.
    pub polish_best: usize,
    /// The polish's learning rates as a share of the refinement's (it starts from a converged
    /// state: full rates kick it out of its basin in the first steps).
    pub polish_lr_scale: f64,
    /// Rays of the polish's one fixed batch (every mask pixel's, up to half of them, and a
    /// uniform sample of the others, importance-weighted: an unbiased estimate of the loss the
    /// hypotheses are ranked on); 0: every ray. Each step drawing afresh by edge sampling made
    /// the polish a random walk on an edge-weighted loss: from the truth itself, 40 such steps
    /// raised the rise's data term on 3 of 8 tuning bowls (one 0.198 → 0.323), while the same
    /// steps on every ray lowered it on all 8. A sample, not every ray: the demo capture's
    /// 42,657 rays made the polish of two hypotheses about 6 s (tuning bowls, 8,000 against
    /// every ray: fits' data term median 0.177 / 0.170, per-vertex 0.30 / 0.30 m).
    pub polish_rays: usize,
    /// Integrate each pixel's footprint (`n × n` rays through the pixel's box, their mean
    /// convolved with the capture's point spread; [`crate::pipeline::footprint_offsets`])
    /// rather than one ray at its centre, when the reflection mask has at most this many pixels
    /// (0: never). A pixel half covered by the reflection rises half as much: on a 20-pixel
    /// reflection the edges are most of what the image says, on a 4,000-pixel one a few per
    /// cent, for n² times the rays (a car door's 150,000 object pixels at 2 × 2 would take
    /// 1 GB).
    pub footprint_max_mask_px: usize,
    /// Rays the footprint may take: its grid is the finest `n × n` (2 ≤ n ≤ 4) whose rays over
    /// every pixel near an object stay within this (2 × 2 when none does): a 160 × 120
    /// tabletop (≈ 3,000 such pixels) gets 4 × 4, a 160 × 120 car door (≈ 16,000) 3 × 3.
    pub footprint_max_rays: usize,
    /// Grids finer than 2 × 2 only on a reflection mask of at most this many pixels (0: on
    /// any). Boson tabletops with few pixels near the objects (half of them) get 3 × 3 or 4 × 4;
    /// at 50 (2 × 2 but for the hard view's 10–50 pixels) such a frame takes ≈ 0.8× as long,
    /// 48 held-out mugs were level and 48 bowls leaned worse (per-vertex +0.018 ± 0.027 m, 2-D
    /// +0.018 ± 0.026; EXPERIMENTS.md, "Fiftieth run"): off by default.
    pub footprint_fine_max_mask_px: usize,
    /// The person's surface temperature per region when known (°C; clothing, bare skin, face,
    /// hair: `Region::ALL`'s order): the common offset is fitted about these instead of the
    /// cited ranges' centres. `eval --variants true-radiometry` gives the simulator's (an
    /// oracle: it measures what the regions' unknown temperatures cost the person).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region_temperatures_c: Option<[f64; REGIONS]>,
}

impl Default for RadiometricConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            reflectance_prior: [0.08, 0.02],
            offset_sigma_k: 1.0,
            offset_bound_k: 2.5,
            reflectance_bound_sigmas: 2.0,
            region_spread: [false; REGIONS],
            huber_sigmas: 3.0,
            polish_iterations: 40,
            rise_pass_max_mask_px: 50,
            rise_pass_max_move_m: 0.5,
            rise_pass_side: false,
            polish_best: 1,
            polish_lr_scale: 0.25,
            polish_rays: 8000,
            footprint_max_mask_px: 1000,
            footprint_max_rays: 200_000,
            footprint_fine_max_mask_px: 0,
            region_temperatures_c: None,
        }
    }
}

/// What the radiometric term knows of a capture (stage 0) and of the body's regions.
#[derive(Clone, Debug)]
pub struct Radiometry {
    /// Pixels the term scores (row-major image index): those the rays sample and, with a
    /// point spread, their neighbours within its reach.
    pub pixel: Vec<u32>,
    /// Observed rise per scored pixel, K.
    pub rise_k: Vec<f64>,
    /// The object whose reflectance a pixel's prediction takes (that of most of its weight).
    pub object: Vec<u16>,
    /// Pixel `p`'s prediction weighs the rays `entries[starts[p]..starts[p + 1]]`.
    pub starts: Vec<u32>,
    /// `(ray among the problem's rays, weight)`: the observation operator, point spread ×
    /// footprint sampling (the weights of a pixel far from the objects' edges sum to 1).
    pub entries: Vec<(u32, f64)>,
    /// Noise σ of the rise, K.
    pub noise_k: f64,
    /// Apparent temperature of the room in the mirrors, K.
    pub ambient_k: f64,
    /// Objects (rays' `object` indices are below it).
    pub objects: usize,
    /// Per region: `c_r` at the centre of its temperature range and `∂c_r/∂Δ`, K and K/K:
    /// `c_r(Δ) ≈ a_r + b_r Δ` for the person's common offset `Δ`.
    pub contrast_at: [[f64; 2]; REGIONS],
    /// Per body vertex: its region.
    pub vertex_region: Vec<Region>,
    /// Per body triangle: its region.
    pub triangle_region: Vec<Region>,
}

/// `dB/dT`, band radiance per kelvin (central difference; `B` is smooth).
fn band_slope(temp_k: f64) -> f64 {
    band_radiance(temp_k + 0.5) - band_radiance(temp_k - 0.5)
}

/// `c = ε (B(T) − B(T_amb)) / B'(T_amb)`: the apparent-temperature rise (K) of a pixel whose
/// mirror (reflectance 1) shows, instead of the room at `ambient_k`, a surface at `temp_k` with
/// emissivity `emissivity` (which also reflects the room).
pub fn contrast_k(temp_k: f64, emissivity: f64, ambient_k: f64) -> f64 {
    emissivity * (band_radiance(temp_k) - band_radiance(ambient_k)) / band_slope(ambient_k)
}

/// Region `r`'s contrast at `temp_c` (°C) and its slope in the common offset: `[a_r, b_r]`.
fn contrast_at(r: Region, temp_c: f64, ambient_k: f64) -> [f64; 2] {
    let th = r.thermal();
    let t = irmirror_capture::planck::ZERO_C_K + temp_c;
    [
        contrast_k(t, th.emissivity, ambient_k),
        th.emissivity * band_slope(t) / band_slope(ambient_k),
    ]
}

impl Radiometry {
    /// From stage 0's rise and background; an error when the capture has no background frames
    /// (the room's temperature is then unknown: the caller falls back to the mask, and says so).
    pub fn new(
        pre: &Preprocessed,
        rays: &ReflectedRays<f64>,
        model: &irmirror_body::BodyModel,
    ) -> Result<Self, ReconError> {
        let ambient_k = pre.background_k.ok_or_else(|| {
            ReconError::Config(
                "the radiometric fit needs background frames (`thermal.background` in \
                 capture.toml) to know the room the mirrors show"
                    .into(),
            )
        })?;
        if !(pre.noise_k.is_finite() && ambient_k.is_finite()) {
            return Err(ReconError::Config(
                "the thermal rise's noise or background is not finite".into(),
            ));
        }
        let vertex_region = vertex_regions(model)?;
        let triangle_region = triangle_regions(&vertex_region, &model.asset.faces);
        let contrast_at = Region::ALL.map(|r| {
            let [lo, hi] = r.thermal().temp_c;
            contrast_at(r, (lo + hi) / 2.0, ambient_k)
        });
        let op = super::observe::observation_operator(rays, pre.psf_sigma_px);
        Ok(Self {
            rise_k: op
                .pixel
                .iter()
                .map(|&p| pre.rise_k.data[p as usize])
                .collect(),
            pixel: op.pixel,
            object: op.object,
            starts: op.starts,
            entries: op.entries,
            // A floor: a noiseless capture would make every residual infinitely certain.
            noise_k: pre.noise_k.max(1e-3),
            ambient_k,
            objects: rays
                .object
                .iter()
                .map(|&k| k as usize + 1)
                .max()
                .unwrap_or(1),
            contrast_at,
            vertex_region,
            triangle_region,
        })
    }

    /// The same observations with the head's face and hair turned front to back
    /// ([`head_regions`]): a fitted body's data term under these against its own says
    /// which way the thermal image puts its head, whatever its outline.
    pub fn head_turned(&self, model: &irmirror_body::BodyModel) -> Result<Self, ReconError> {
        let vertex_region = head_regions(model, true)?;
        Ok(Self {
            triangle_region: triangle_regions(&vertex_region, &model.asset.faces),
            vertex_region,
            ..self.clone()
        })
    }

    /// The same observations with the regions' temperatures centred at `temps_c` (°C, in
    /// `Region::ALL`'s order) instead of their cited ranges' centres.
    pub fn centred_at(mut self, temps_c: [f64; REGIONS]) -> Self {
        for (r, t) in Region::ALL.into_iter().zip(temps_c) {
            self.contrast_at[r.index()] = contrast_at(r, t, self.ambient_k);
        }
        self
    }

    /// The surface temperature (°C) of region `r` whose fitted contrast is `c` (inverse of the
    /// model's `c_r`).
    pub fn temperature_c(&self, r: Region, c: f64) -> f64 {
        let l =
            band_radiance(self.ambient_k) + c * band_slope(self.ambient_k) / r.thermal().emissivity;
        irmirror_capture::planck::temperature_of(l.max(1e-12)) - irmirror_capture::planck::ZERO_C_K
    }
}

/// The fitted scalars: reflectance per object and the person's temperature offset, and the
/// contrast per region (K) that offset gives.
#[derive(Clone, Debug, PartialEq)]
pub struct Scalars {
    /// `g_k` per object.
    pub reflectance: Vec<f64>,
    /// `Δ`, K: every region's temperature is its range's centre + `Δ` + its own deviation.
    pub offset_k: f64,
    /// `δ_r`, K: each region's own deviation (0 without
    /// [`RadiometricConfig::region_spread`]).
    pub region_offset_k: [f64; REGIONS],
    /// `c_r = a_r + b_r (Δ + δ_r)` per region, K.
    pub contrast: [f64; REGIONS],
}

/// One batch's inputs to the term: per ray, and per pixel.
pub struct TermInput<'a> {
    /// Occupancy per ray.
    pub occ: &'a [f64],
    /// The regions' shares `β` at the point each ray meets (barycentric weights of the met
    /// triangle's vertex labels: continuous across region borders; sum 1).
    pub mix: &'a [[f64; REGIONS]],
    /// The pixels.
    pub rise: Rise<'a>,
    /// Share of all pixels this batch stands for (scales the priors).
    pub share: f64,
}

impl TermInput<'_> {
    /// Pixels.
    fn pixels(&self) -> usize {
        self.rise.rise_k.len()
    }

    /// Pixel `p`'s entries.
    fn entries(&self, p: usize) -> &[(u32, f64)] {
        &self.rise.entries[self.rise.starts[p] as usize..self.rise.starts[p + 1] as usize]
    }

    /// Pixel `p`'s importance weight.
    fn weight(&self, p: usize) -> f64 {
        self.rise.weight.map_or(1.0, |w| w[p])
    }

    /// Pixel `p`'s object.
    fn object(&self, p: usize) -> usize {
        self.rise.object[p] as usize
    }

    /// Pixel `p`'s `Σ_e w_e o_e β_e`: its covered share of each region.
    fn covered_by_region(&self, p: usize) -> [f64; REGIONS] {
        let mut m = [0.0; REGIONS];
        for &(i, w) in self.entries(p) {
            let i = i as usize;
            for (mr, b) in m.iter_mut().zip(&self.mix[i]) {
                *mr += w * self.occ[i] * b;
            }
        }
        m
    }

    /// Pixel `p`'s `Σ_e w_e o_e (β_e · v)` for per-region values `v`: its covered share
    /// weighted by `v` (the prediction for `v` = the contrasts, before reflectance).
    fn covered(&self, p: usize, v: &[f64; REGIONS]) -> f64 {
        self.entries(p)
            .iter()
            .map(|&(i, w)| {
                let i = i as usize;
                w * self.occ[i] * self.mix[i].iter().zip(v).map(|(b, c)| b * c).sum::<f64>()
            })
            .sum()
    }
}

/// Golden-section steps of the offset per IRLS round: the range (±2.5 K) shrinks to 1e-5 K.
const GOLDEN_STEPS: usize = 28;

/// The offset in `[−bound, bound]` minimising `f` (unimodal): golden section, then the bounds
/// themselves, where the minimum may sit and which the section only approaches.
fn golden_offset(bound: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (-bound, bound);
    let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..GOLDEN_STEPS {
        if f1 <= f2 {
            (hi, x2, f2) = (x2, x1, f1);
            x1 = hi - phi * (hi - lo);
            f1 = f(x1);
        } else {
            (lo, x1, f1) = (x1, x2, f2);
            x2 = lo + phi * (hi - lo);
            f2 = f(x2);
        }
    }
    [0.5 * (lo + hi), -bound, bound]
        .into_iter()
        .map(|d| (f(d), d))
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map_or(0.0, |(_, d)| d)
}

/// Per IRLS round, alternations of the offset's section and the regions' deviations.
const BLOCK_ROUNDS: usize = 3;

/// Coordinate-descent rounds of the regions' deviations (4 unknowns).
const DEVIATION_ROUNDS: usize = 12;

/// Per region: the prior σ and the bound of its own deviation from the common offset, K — a
/// temperature drawn anywhere in the cited range (`irmirror_body::regions::THERMAL`): the
/// uniform's σ (half-width / √3) and the half-width.
fn region_spread_k() -> [[f64; 2]; REGIONS] {
    Region::ALL.map(|r| {
        let [lo, hi] = r.thermal().temp_c;
        let half = 0.5 * (hi - lo);
        [half / 3f64.sqrt(), half]
    })
}

/// `a · b`.
#[inline]
fn dot(a: &[f64; REGIONS], b: &[f64; REGIONS]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// One object's weighted moments of its pixels' region shares `m` and rises `y`.
#[derive(Clone, Debug, Default)]
struct Moments {
    /// `Σ a m mᵀ`.
    s: [[f64; REGIONS]; REGIONS],
    /// `Σ a y m`.
    r: [f64; REGIONS],
    /// `Σ a y²`.
    yy: f64,
}

impl Moments {
    /// Adds a pixel of weight `a`.
    fn add(&mut self, a: f64, m: &[f64; REGIONS], y: f64) {
        for i in 0..REGIONS {
            self.r[i] += a * y * m[i];
            for j in 0..REGIONS {
                self.s[i][j] += a * m[i] * m[j];
            }
        }
        self.yy += a * y * y;
    }

    /// `[Σ a x_a², Σ a x_a x_b, Σ a x_b², Σ a y x_a, Σ a y x_b, Σ a y²]` for `x_a = m·ca`,
    /// `x_b = m·cb`.
    fn profile_sums(&self, ca: &[f64; REGIONS], cb: &[f64; REGIONS]) -> [f64; 6] {
        let quad = |u: &[f64; REGIONS], v: &[f64; REGIONS]| -> f64 {
            (0..REGIONS)
                .map(|i| u[i] * (0..REGIONS).map(|j| self.s[i][j] * v[j]).sum::<f64>())
                .sum()
        };
        [
            quad(ca, ca),
            quad(ca, cb),
            quad(cb, cb),
            dot(&self.r, ca),
            dot(&self.r, cb),
            self.yy,
        ]
    }
}

/// The loss' denominator is at least this share of the "nobody" score (a capture whose rise is
/// all noise is normalised by its noise, not by zero).
const MIN_SIGNAL_SHARE: f64 = 0.05;

/// `E ψ(z)` for `z ~ N(0, 1)`: Huber's ψ at threshold `delta` averaged over unit noise
/// (Simpson's rule over ±10; ½ without the threshold).
fn huber_noise_mean(delta: f64) -> f64 {
    let n = 2000;
    let (a, h) = (-10.0, 20.0 / n as f64);
    let f = |z: f64| huber(z, delta).0 * (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let mut sum = f(a) + f(-a);
    for k in 1..n {
        sum += f(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * h / 3.0
}

/// Huber's ψ and ψ'.
#[inline]
fn huber(r: f64, delta: f64) -> (f64, f64) {
    if r.abs() <= delta {
        (0.5 * r * r, r)
    } else {
        (delta * (r.abs() - 0.5 * delta), delta * r.signum())
    }
}

impl Radiometry {
    /// The priors' means: where the closed-form solve starts.
    pub fn prior_scalars(&self, cfg: &RadiometricConfig) -> Scalars {
        Scalars {
            reflectance: vec![cfg.reflectance_prior[0]; self.objects],
            offset_k: 0.0,
            region_offset_k: [0.0; REGIONS],
            contrast: self.contrast_at.map(|[a, _]| a),
        }
    }

    /// The regions' contrasts at common offset `d` and own deviations `dev`.
    fn contrast_of(&self, d: f64, dev: &[f64; REGIONS]) -> [f64; REGIONS] {
        std::array::from_fn(|r| {
            let [a, b] = self.contrast_at[r];
            a + b * (d + dev[r])
        })
    }

    /// `P(g, c)`, the priors' `½ Σ ((x − x̄)/s)²`.
    fn prior_penalty(&self, s: &Scalars, cfg: &RadiometricConfig) -> f64 {
        let [gm, gs] = cfg.reflectance_prior;
        let g: f64 = s
            .reflectance
            .iter()
            .map(|g| 0.5 * ((g - gm) / gs).powi(2))
            .sum();
        let dev: f64 = s
            .region_offset_k
            .iter()
            .zip(region_spread_k())
            .map(|(x, [sd, _])| 0.5 * (x / sd).powi(2))
            .sum();
        g + 0.5 * (s.offset_k / cfg.offset_sigma_k).powi(2) + dev
    }

    /// Solves for the scalars: `sweeps` rounds of Huber's IRLS weights, each minimising the
    /// weighted least squares by block coordinates: the common offset by golden section on its
    /// bounded range with the reflectances in closed form at each offset (the problem's profile
    /// in `Δ`: `g` and `Δ` trade along a shallow valley that alternating updates walk slowly),
    /// then, with [`RadiometricConfig::region_spread`], the regions' own deviations `δ` at those
    /// reflectances and offset (a box-bounded 4 × 4 quadratic, exact by coordinate descent).
    pub fn solve_scalars(
        &self,
        input: &TermInput<'_>,
        cfg: &RadiometricConfig,
        s: &mut Scalars,
        sweeps: usize,
    ) {
        let inv_var = 1.0 / (self.noise_k * self.noise_k);
        let delta = cfg.huber_sigmas;
        let n = input.pixels();
        let [gm, gs] = cfg.reflectance_prior;
        let b = cfg.reflectance_bound_sigmas * gs;
        let (g_lo, g_hi) = ((gm - b).max(1e-3), gm + b);
        let (p_g, p_d) = (
            input.share / (gs * gs),
            input.share / (cfg.offset_sigma_k * cfg.offset_sigma_k),
        );
        let spread = region_spread_k();
        let p_r = spread.map(|[sd, _]| input.share / (sd * sd));
        let spreads = cfg.region_spread.contains(&true);
        let ca = self.contrast_at.map(|[a, _]| a);
        let cb = self.contrast_at.map(|[_, b]| b);
        // Per pixel: its covered footprint's share of each region (the prediction before
        // reflectance is its dot product with the contrasts) — or, with the common offset
        // alone, that share weighted by `a` and by `b` (the prediction is their combination at
        // Δ) — and the object. The moments would serve both, but summed in another order: the
        // common offset keeps its own sums so that the default reproduces, to the digit, the
        // fits every published figure was measured with (stage 2 follows last bits).
        let m: Vec<[f64; REGIONS]> = if spreads {
            (0..n).map(|p| input.covered_by_region(p)).collect()
        } else {
            Vec::new()
        };
        let (ma, mb): (Vec<f64>, Vec<f64>) = if spreads {
            (Vec::new(), Vec::new())
        } else {
            (0..n)
                .map(|p| (input.covered(p, &ca), input.covered(p, &cb)))
                .unzip()
        };
        let obj: Vec<usize> = (0..n).map(|p| input.object(p)).collect();
        let mut a = vec![0.0; n];
        let mut g = s.reflectance.clone();
        // Per object, the weighted sums that make the least squares a quadratic in (g, Δ): with
        // x = m_a + m_b Δ, Σ a x rise, Σ a x² and Σ a rise² give every offset's profile in
        // O(objects). With the deviations, the weighted moments `Σ a m mᵀ`, `Σ a y m`, `Σ a y²`
        // give those sums for any contrasts in O(objects · 16): neither the golden section's
        // 30 profiles nor the deviations' solve pass over the pixels.
        let mut sums = vec![[0.0; 6]; self.objects];
        let mut mom = vec![Moments::default(); self.objects];
        // The weighted least squares at offset `d` with the best reflectances (written to `g`).
        let profile = |d: f64, sums: &[[f64; 6]], g: &mut [f64]| -> f64 {
            let mut f = 0.0;
            for (k, [aa, ab, bb, ra, rb, rr]) in sums.iter().enumerate() {
                let num = ra + rb * d;
                let den = aa + 2.0 * ab * d + bb * d * d;
                g[k] = ((num + p_g * gm) / (den + p_g)).clamp(g_lo, g_hi);
                f += rr - 2.0 * g[k] * num + g[k] * g[k] * den;
            }
            let pg: f64 = g.iter().map(|x| p_g * (x - gm) * (x - gm)).sum();
            0.5 * (f + pg + p_d * d * d)
        };
        let blocks = if spreads { BLOCK_ROUNDS } else { 1 };
        for _ in 0..sweeps {
            // IRLS weight of each pixel at the current scalars (1 inside Huber's threshold).
            for (p, ap) in a.iter_mut().enumerate() {
                let covered = if spreads {
                    dot(&m[p], &s.contrast)
                } else {
                    ma[p] + mb[p] * s.offset_k
                };
                let r = (input.rise.rise_k[p] - s.reflectance[obj[p]] * covered) / self.noise_k;
                *ap = input.weight(p)
                    * inv_var
                    * if r.abs() <= delta {
                        1.0
                    } else {
                        delta / r.abs()
                    };
            }
            if spreads {
                mom.iter_mut().for_each(|t| *t = Moments::default());
                for p in 0..n {
                    mom[obj[p]].add(a[p], &m[p], input.rise.rise_k[p]);
                }
            } else {
                sums.iter_mut().for_each(|t| *t = [0.0; 6]);
                for p in 0..n {
                    let (w, x, y, r) = (a[p], ma[p], mb[p], input.rise.rise_k[p]);
                    let t = &mut sums[obj[p]];
                    t[0] += w * x * x;
                    t[1] += w * x * y;
                    t[2] += w * y * y;
                    t[3] += w * r * x;
                    t[4] += w * r * y;
                    t[5] += w * r * r;
                }
            }
            for _ in 0..blocks {
                if spreads {
                    // x = m·a' + Δ m·b, a' the contrasts at zero offset with the deviations.
                    let ca = self.contrast_of(0.0, &s.region_offset_k);
                    for (t, m) in sums.iter_mut().zip(&mom) {
                        *t = m.profile_sums(&ca, &cb);
                    }
                }
                let d = golden_offset(cfg.offset_bound_k, |d| profile(d, &sums, &mut g));
                profile(d, &sums, &mut g);
                s.offset_k = d;
                s.reflectance.copy_from_slice(&g);
                if spreads {
                    s.region_offset_k =
                        self.region_deviations(&mom, s, (&p_r, &spread), &cfg.region_spread);
                }
                s.contrast = self.contrast_of(d, &s.region_offset_k);
            }
        }
    }

    /// The regions' deviations `δ` minimising the weighted least squares plus their priors at
    /// fixed reflectances and common offset: `(Σ_k g_k² B S_k B + P) δ = Σ_k g_k B (R_k − g_k
    /// S_k c₀)`, `c₀` the contrasts at the offset alone, `B` their slopes, within the bounds
    /// (coordinate descent is exact for a box-bounded positive definite quadratic; a region no
    /// pixel shows keeps its prior's 0, one not `free` stays where it is).
    fn region_deviations(
        &self,
        mom: &[Moments],
        s: &Scalars,
        (p_r, spread): (&[f64; REGIONS], &[[f64; 2]; REGIONS]),
        free: &[bool; REGIONS],
    ) -> [f64; REGIONS] {
        let c0 = self.contrast_of(s.offset_k, &[0.0; REGIONS]);
        let bs = self.contrast_at.map(|[_, b]| b);
        let mut h = [[0.0; REGIONS]; REGIONS];
        let mut rhs = [0.0; REGIONS];
        for (t, g) in mom.iter().zip(&s.reflectance) {
            for r in 0..REGIONS {
                let sc: f64 = (0..REGIONS).map(|q| t.s[r][q] * c0[q]).sum();
                rhs[r] += g * bs[r] * (t.r[r] - g * sc);
                for q in 0..REGIONS {
                    h[r][q] += g * g * bs[r] * t.s[r][q] * bs[q];
                }
            }
        }
        for r in 0..REGIONS {
            h[r][r] += p_r[r];
        }
        let mut x = s.region_offset_k;
        for _ in 0..DEVIATION_ROUNDS {
            for r in (0..REGIONS).filter(|&r| free[r]) {
                let off: f64 = (0..REGIONS)
                    .filter(|&q| q != r)
                    .map(|q| h[r][q] * x[q])
                    .sum();
                let bound = spread[r][1];
                x[r] = ((rhs[r] - off) / h[r][r]).clamp(-bound, bound);
            }
        }
        x
    }

    /// The predicted rise per pixel of `input` at scalars `s`.
    pub fn predict<'a>(
        &'a self,
        input: &'a TermInput<'_>,
        s: &'a Scalars,
    ) -> impl Iterator<Item = f64> + 'a {
        (0..input.pixels()).map(|p| s.reflectance[input.object(p)] * input.covered(p, &s.contrast))
    }

    /// [`Self::predict`] summed over `input`'s pixels per region, K·px: the parts add up to
    /// the whole prediction.
    pub fn region_rise(&self, input: &TermInput<'_>, s: &Scalars) -> [f64; REGIONS] {
        let mut out = [0.0; REGIONS];
        for p in 0..input.pixels() {
            let g = s.reflectance[input.object(p)];
            for &(i, w) in input.entries(p) {
                let i = i as usize;
                for (r, o) in out.iter_mut().enumerate() {
                    *o += g * w * input.occ[i] * input.mix[i][r] * s.contrast[r];
                }
            }
        }
        out
    }

    /// `D` at fixed scalars; with `grad`, writes `∂D/∂o_i` and `∂D/∂β_i` there (per ray of the
    /// batch).
    pub fn loss(
        &self,
        input: &TermInput<'_>,
        cfg: &RadiometricConfig,
        s: &Scalars,
        grad: Option<(&mut Vec<f64>, &mut Vec<[f64; REGIONS]>)>,
    ) -> f64 {
        let delta = cfg.huber_sigmas;
        let sigma = self.noise_k;
        let n = input.pixels();
        // What noise alone scores (E ψ(z), z ~ N(0, 1), per unit weight), removed from both
        // sides: on a car door 150,000 pixels of noise would otherwise bury 2,000 of signal,
        // and the priors of the body would outweigh the data.
        let floor = huber_noise_mean(delta) * (0..n).map(|p| input.weight(p)).sum::<f64>();
        let nobody = (0..n)
            .map(|p| input.weight(p) * huber(input.rise.rise_k[p] / sigma, delta).0)
            .sum::<f64>();
        let norm = (nobody - floor).max(MIN_SIGNAL_SHARE * nobody).max(1e-12);
        let mut data = 0.0;
        let mut grad = grad;
        if let Some((d_occ, d_mix)) = grad.as_mut() {
            d_occ.clear();
            d_occ.resize(input.occ.len(), 0.0);
            d_mix.clear();
            d_mix.resize(input.occ.len(), [0.0; REGIONS]);
        }
        for p in 0..n {
            let g = s.reflectance[input.object(p)];
            let pred = g * input.covered(p, &s.contrast);
            let (psi, dpsi) = huber((input.rise.rise_k[p] - pred) / sigma, delta);
            data += input.weight(p) * psi;
            if let Some((d_occ, d_mix)) = grad.as_mut() {
                // ∂D/∂ŷ_p, times ∂ŷ_p/∂(o_e, β_e); ŷ_p = g Σ_e w_e o_e (β_e · c).
                let dy = -input.weight(p) * dpsi / sigma / norm * g;
                for &(i, w) in input.entries(p) {
                    let i = i as usize;
                    let c: f64 = input.mix[i]
                        .iter()
                        .zip(&s.contrast)
                        .map(|(b, c)| b * c)
                        .sum();
                    d_occ[i] += dy * w * c;
                    for r in 0..REGIONS {
                        d_mix[i][r] += dy * w * input.occ[i] * s.contrast[r];
                    }
                }
            }
        }
        (data + input.share * self.prior_penalty(s, cfg) - floor) / norm
    }
}

#[cfg(test)]
#[path = "radiometric_tests.rs"]
mod tests;
