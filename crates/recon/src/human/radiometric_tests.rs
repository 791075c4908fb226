//! Tests of the radiometric term (`radiometric.rs`).

use super::*;
use rand::{Rng, SeedableRng};

/// The default settings with every region's own deviation on.
fn spread() -> RadiometricConfig {
    RadiometricConfig {
        region_spread: [true; REGIONS],
        ..RadiometricConfig::default()
    }
}

/// A small synthetic problem: two objects, every region, pixels of 1–4 rays of their own
/// and one of their neighbour's, rises drawn from known scalars.
struct Synthetic {
    rad: Radiometry,
    occ: Vec<f64>,
    region: Vec<[f64; REGIONS]>,
    truth: Scalars,
}

impl Synthetic {
    /// The term's input with per-pixel `rise` and `weight`, per-ray `occ` and `mix`.
    fn input<'a>(
        &'a self,
        occ: &'a [f64],
        mix: &'a [[f64; REGIONS]],
        rise: &'a [f64],
        weight: Option<&'a [f64]>,
        share: f64,
    ) -> TermInput<'a> {
        TermInput {
            occ,
            mix,
            rise: Rise {
                rise_k: rise,
                weight,
                ..self.rad.rise()
            },
            share,
        }
    }
}

/// One-hot shares, every fifth ray on a border between two regions.
fn mix_of(i: usize) -> [f64; REGIONS] {
    let mut m = [0.0; REGIONS];
    if i.is_multiple_of(5) {
        m[i % 4] = 0.7;
        m[(i + 1) % 4] = 0.3;
    } else {
        m[i % 4] = 1.0;
    }
    m
}

/// The synthetic truth's regions' own deviations, K.
const DEVIATIONS: [f64; REGIONS] = [0.6, -0.4, 0.3, -0.7];

fn synthetic(noise: f64) -> Synthetic {
    synthetic_with(noise, DEVIATIONS)
}

fn synthetic_with(noise: f64, dev: [f64; REGIONS]) -> Synthetic {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let pixels = 250;
    // Pixel p's own rays (1–4 of a 4-node footprint), then the previous pixel's first ray
    // through a point spread: rays shared by two pixels.
    let mut own = vec![0u32];
    for p in 0..pixels {
        own.push(own[p] + 1 + (p % 4) as u32);
    }
    let n = own[pixels] as usize;
    let (mut starts, mut entries) = (vec![0u32], Vec::new());
    for p in 0..pixels {
        entries.extend((own[p]..own[p + 1]).map(|i| (i, 0.2)));
        if p > 0 {
            entries.push((own[p - 1], 0.1));
        }
        starts.push(entries.len() as u32);
    }
    let contrast_at = [[7.5, 0.7], [10.5, 0.8], [11.5, 0.8], [8.5, 0.75]];
    let offset_k = 1.2;
    let truth = Scalars {
        reflectance: vec![0.09, 0.06],
        offset_k,
        region_offset_k: dev,
        contrast: std::array::from_fn(|r| {
            contrast_at[r][0] + contrast_at[r][1] * (offset_k + dev[r])
        }),
    };
    let occ: Vec<f64> = (0..n)
        .map(|i| {
            if i % 3 == 0 {
                0.0
            } else {
                rng.random_range(0.0..1.0)
            }
        })
        .collect();
    let region: Vec<[f64; REGIONS]> = (0..n).map(mix_of).collect();
    let object: Vec<u16> = (0..pixels).map(|p| (p / 7 % 2) as u16).collect();
    let rise: Vec<f64> = (0..pixels)
        .map(|p| {
            let covered: f64 = entries[starts[p] as usize..starts[p + 1] as usize]
                .iter()
                .map(|&(i, w)| {
                    let i = i as usize;
                    let c: f64 = region[i]
                        .iter()
                        .zip(&truth.contrast)
                        .map(|(b, c)| b * c)
                        .sum();
                    w * c * occ[i]
                })
                .sum();
            truth.reflectance[object[p] as usize] * covered + noise * rng.random_range(-1.0..1.0)
        })
        .collect();
    let rad = Radiometry {
        pixel: (0..pixels as u32).collect(),
        rise_k: rise,
        object,
        starts,
        entries,
        noise_k: 0.05,
        ambient_k: 295.0,
        objects: 2,
        contrast_at,
        vertex_region: vec![],
        triangle_region: vec![],
    };
    Synthetic {
        rad,
        occ,
        region,
        truth,
    }
}

/// `∂D/∂o` and `∂D/∂β` at fixed scalars against central differences (f64), with Huber's
/// linear branch active on some rays.
#[test]
fn loss_gradient_matches_finite_differences() {
    let sy = synthetic(0.02);
    let (rad, occ, region) = (&sy.rad, &sy.occ, &sy.region);
    let rise = &rad.rise_k;
    let cfg = RadiometricConfig::default();
    let weight: Vec<f64> = (0..rise.len())
        .map(|p| 1.0 + (p % 5) as f64 * 0.3)
        .collect();
    // Scalars off the truth: large residuals reach Huber's linear branch.
    let s = Scalars {
        reflectance: vec![0.2, 0.005],
        offset_k: -2.0,
        region_offset_k: [0.5, -0.5, 0.0, 1.0],
        contrast: [6.0, 9.0, 14.0, 5.0],
    };
    let input = |o: &[f64], mix: &[[f64; REGIONS]]| -> f64 {
        rad.loss(&sy.input(o, mix, rise, Some(&weight), 0.4), &cfg, &s, None)
    };
    let (mut d, mut dm) = (Vec::new(), Vec::new());
    let t = sy.input(occ, region, rise, Some(&weight), 0.4);
    let l = rad.loss(&t, &cfg, &s, Some((&mut d, &mut dm)));
    assert!((l - input(occ, region)).abs() < 1e-15);
    let linear = (0..t.pixels())
        .filter(|&p| {
            let pred = s.reflectance[t.object(p)] * t.covered(p, &s.contrast);
            ((rise[p] - pred) / rad.noise_k).abs() > cfg.huber_sigmas
        })
        .count();
    assert!(linear > 10, "only {linear} pixels on Huber's linear branch");
    let dmax = d.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    for i in (0..occ.len()).step_by(7) {
        let h = 1e-6;
        let (mut p, mut m) = (occ.clone(), occ.clone());
        p[i] += h;
        m[i] -= h;
        let fd = (input(&p, region) - input(&m, region)) / (2.0 * h);
        assert!(
            (fd - d[i]).abs() <= 1e-6 * dmax,
            "ray {i}: {fd} vs {}",
            d[i]
        );
        for r in 0..REGIONS {
            let (mut p, mut m) = (region.clone(), region.clone());
            p[i][r] += h;
            m[i][r] -= h;
            let fd = (input(occ, &p) - input(occ, &m)) / (2.0 * h);
            assert!(
                (fd - dm[i][r]).abs() <= 1e-6 * dmax.max(1e-3),
                "ray {i} region {r}: {fd} vs {}",
                dm[i][r]
            );
        }
    }
}

/// The solve finds the scalars that made the data (noise-free, the priors weak against 250
/// pixels, some rays mixing two regions): the products `g·c` — each region at its own
/// temperature — and at its result no scalar can be moved to lower the objective it
/// minimises.
#[test]
fn scalar_solve_recovers_the_truth_and_is_stationary() {
    let sy = synthetic(0.0);
    let (rad, truth) = (&sy.rad, &sy.truth);
    let cfg = spread();
    let t = sy.input(&sy.occ, &sy.region, &rad.rise_k, None, 1e-3);
    // The product g·c is what the data fix; the priors fix the split. Compare products.
    let mut s = rad.prior_scalars(&cfg);
    rad.solve_scalars(&t, &cfg, &mut s, 200);
    assert_products(&s, truth, 2e-3);
    // Stationary: the objective (the loss' numerator) does not drop when a scalar moves.
    let l0 = rad.loss(&t, &cfg, &s, None);
    for k in 0..2 + 1 + REGIONS {
        for step in [1e-4, -1e-4] {
            let mut m = s.clone();
            match k {
                0 | 1 => m.reflectance[k] *= 1.0 + step,
                2 => m.offset_k += step,
                _ => m.region_offset_k[k - 3] += step,
            }
            m.contrast = rad.contrast_of(m.offset_k, &m.region_offset_k);
            assert!(rad.loss(&t, &cfg, &m, None) >= l0 - 1e-12, "scalar {k}");
        }
    }
    // Twelve sweeps (stage 2 runs 20) land on the converged objective (`D` ≈ 0 here, the
    // data being noise-free: within 1e-6 of its scale, 1).
    let mut s12 = rad.prior_scalars(&cfg);
    rad.solve_scalars(&t, &cfg, &mut s12, 12);
    let l12 = rad.loss(&t, &cfg, &s12, None);
    assert!((l12 - l0).abs() < 1e-6, "12 sweeps: {l12} vs {l0}");
}

/// `g·c` of every object and region within `rel` of the truth's.
fn assert_products(s: &Scalars, truth: &Scalars, rel: f64) {
    for k in 0..2 {
        for r in 0..REGIONS {
            let (got, want) = (
                s.reflectance[k] * s.contrast[r],
                truth.reflectance[k] * truth.contrast[r],
            );
            assert!(
                (got - want).abs() < rel * want,
                "object {k} region {r}: {got} vs {want}"
            );
        }
    }
}

/// Without the regions' own deviations (`region_spread` off, the default) on data made with
/// none, the common offset is found too: it moves every contrast by a few % per kelvin, so it
/// trades with the reflectance along a shallow valley — known to ± 0.15 K here; the deviations
/// stay 0. With them on, data whose regions deviate are fitted better than by the common offset
/// alone, and with the body's regions alone in between.
#[test]
fn common_offset_alone_and_with_the_regions_deviations() {
    let sy = synthetic_with(0.0, [0.0; REGIONS]);
    let (rad, truth) = (&sy.rad, &sy.truth);
    let off = RadiometricConfig {
        region_spread: [false; REGIONS],
        ..spread()
    };
    let t = sy.input(&sy.occ, &sy.region, &rad.rise_k, None, 1e-3);
    let mut s = rad.prior_scalars(&off);
    rad.solve_scalars(&t, &off, &mut s, 200);
    assert_products(&s, truth, 2e-3);
    assert!((s.offset_k - truth.offset_k).abs() < 0.15, "{}", s.offset_k);
    assert_eq!(s.region_offset_k, [0.0; REGIONS]);
    // Twelve sweeps land on the converged objective, as before the deviations existed.
    let l0 = rad.loss(&t, &off, &s, None);
    let mut s12 = rad.prior_scalars(&off);
    rad.solve_scalars(&t, &off, &mut s12, 12);
    let l12 = rad.loss(&t, &off, &s12, None);
    assert!((l12 - l0).abs() < 1e-6, "12 sweeps: {l12} vs {l0}");
    let sy = synthetic(0.0);
    let t = sy.input(&sy.occ, &sy.region, &sy.rad.rise_k, None, 1e-3);
    let loss = |cfg: &RadiometricConfig| {
        let mut s = sy.rad.prior_scalars(cfg);
        sy.rad.solve_scalars(&t, cfg, &mut s, 20);
        sy.rad.loss(&t, cfg, &s, None)
    };
    let (common, own) = (loss(&off), loss(&spread()));
    let at_truth = sy.rad.loss(&t, &spread(), &sy.truth, None);
    assert!(
        own <= at_truth + 1e-9 && common > own + 1e-4,
        "{common} vs {own}"
    );
    // The body's regions alone: the head's stay at the common offset, the fit in between.
    let body = RadiometricConfig {
        region_spread: [true, true, false, false],
        ..spread()
    };
    let mut s = sy.rad.prior_scalars(&body);
    sy.rad.solve_scalars(&t, &body, &mut s, 20);
    assert_eq!(s.region_offset_k[2..], [0.0; 2]);
    let partial = sy.rad.loss(&t, &body, &s, None);
    assert!(
        common > partial + 1e-5 && partial >= own - 1e-9,
        "{partial}"
    );
}

/// Where the mirror shows nothing but the body is placed, the solve stops at the bounds: the
/// person cools by at most the offset's bound and each region to its range's floor, no object
/// stops reflecting.
#[test]
fn scalars_stay_within_their_bounds() {
    let sy = synthetic(0.0);
    let rad = &sy.rad;
    let cfg = spread();
    let zero = vec![0.0; rad.rise_k.len()];
    let t = sy.input(&sy.occ, &sy.region, &zero, None, 1e-3);
    let mut s = rad.prior_scalars(&cfg);
    rad.solve_scalars(&t, &cfg, &mut s, 20);
    assert_eq!(s.offset_k, -cfg.offset_bound_k);
    let low = region_spread_k().map(|[_, half]| -half);
    assert_eq!(s.region_offset_k, low);
    assert_eq!(s.contrast, rad.contrast_of(-cfg.offset_bound_k, &low));
    let [gm, gs] = cfg.reflectance_prior;
    for g in &s.reflectance {
        assert!(
            (g - (gm - cfg.reflectance_bound_sigmas * gs)).abs() < 1e-12,
            "{g}"
        );
    }
}

/// The noise floor: ½ without a threshold, a little less with one (the linear branch grows
/// slower), and the sample mean of ψ over Gaussian draws agrees.
#[test]
fn noise_floor_is_the_mean_huber_score_of_unit_noise() {
    assert!((huber_noise_mean(1e3) - 0.5).abs() < 1e-9);
    let m = huber_noise_mean(3.0);
    assert!(m < 0.5 && m > 0.49, "{m}");
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let n = 200_000;
    let sample: f64 = (0..n)
        .map(|_| {
            huber(
                rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng),
                3.0,
            )
            .0
        })
        .sum::<f64>()
        / n as f64;
    assert!((sample - m).abs() < 5e-3, "{sample} vs {m}");
}

/// Huber's ψ: quadratic inside, linear outside, continuous with a continuous slope.
#[test]
fn huber_is_continuous_at_its_threshold() {
    let d = 3.0;
    let (a, da) = huber(d - 1e-9, d);
    let (b, db) = huber(d + 1e-9, d);
    assert!((a - b).abs() < 1e-8 && (da - db).abs() < 1e-8);
    assert_eq!(huber(-1.0, d), (0.5, -1.0));
    assert_eq!(huber(-5.0, d).1, -3.0);
}

/// Known temperatures recentre the regions: each region's contrast at offset 0 becomes that
/// temperature's (`contrast_k`), 1.5 K warmer than its range's centre rises more than the
/// centre, and the slope in the offset stays about the region's emissivity (a kelvin of offset
/// ≈ ε kelvin of apparent rise).
#[test]
fn known_temperatures_recentre_the_regions() {
    use irmirror_capture::planck::ZERO_C_K;
    let rad = synthetic(0.0).rad;
    let centre = |r: Region| {
        let [lo, hi] = r.thermal().temp_c;
        (lo + hi) / 2.0
    };
    let at_centres = rad.clone().centred_at(Region::ALL.map(centre));
    let warmer = rad.clone().centred_at(Region::ALL.map(|r| centre(r) + 1.5));
    for r in Region::ALL {
        let th = r.thermal();
        let [a, b] = warmer.contrast_at[r.index()];
        let want = contrast_k(ZERO_C_K + centre(r) + 1.5, th.emissivity, rad.ambient_k);
        assert!((a - want).abs() < 1e-12, "{r:?}: {a} against {want}");
        let a0 = at_centres.contrast_at[r.index()][0];
        assert!(a > a0 + th.emissivity, "{r:?}: {a0} → {a}");
        assert!(
            b > 0.8 * th.emissivity && b < 1.3 * th.emissivity,
            "{r:?}: slope {b}"
        );
    }
}

/// The per-region parts of the prediction add up to it, and each is what that region's
/// contrast contributes: the whole prediction less the one with that contrast at zero.
#[test]
fn region_rise_splits_the_prediction_by_region() {
    let sy = synthetic(0.02);
    let t = sy.input(&sy.occ, &sy.region, &sy.rad.rise_k, None, 1.0);
    let s = &sy.truth;
    let total = |s: &Scalars| sy.rad.predict(&t, s).sum::<f64>();
    let parts = sy.rad.region_rise(&t, s);
    let whole = total(s);
    assert!(whole > 1.0, "{whole}");
    assert!((parts.iter().sum::<f64>() - whole).abs() < 1e-9 * whole);
    for r in 0..REGIONS {
        let mut without = s.clone();
        without.contrast[r] = 0.0;
        let want = whole - total(&without);
        assert!(
            want > 1e-3 * whole,
            "region {r} unseen in the synthetic data"
        );
        assert!(
            (parts[r] - want).abs() < 1e-9 * whole,
            "region {r}: {} vs {want}",
            parts[r]
        );
    }
}
