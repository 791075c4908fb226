//! Band radiance of a black body over the LWIR band (8–14 µm) by Planck's law, and its inverse.
//! Kelvin inside; radiance in W m⁻² sr⁻¹.

/// Lower band edge, m.
pub const BAND_LO_M: f64 = 8e-6;
/// Upper band edge, m.
pub const BAND_HI_M: f64 = 14e-6;
/// 0 °C in kelvin.
pub const ZERO_C_K: f64 = 273.15;

const H: f64 = 6.626_070_15e-34;
const C: f64 = 299_792_458.0;
const KB: f64 = 1.380_649e-23;

/// Spectral radiance `B_λ(T)`, W m⁻² sr⁻¹ m⁻¹.
fn spectral(lambda_m: f64, temp_k: f64) -> f64 {
    2.0 * H * C * C / lambda_m.powi(5) / ((H * C / (lambda_m * KB * temp_k)).exp_m1())
}

/// ∫ B_λ(T) dλ over 8–14 µm (composite Simpson, 256 intervals: error < 1e-9 relative).
pub fn band_radiance(temp_k: f64) -> f64 {
    if temp_k <= 0.0 {
        return 0.0;
    }
    let n = 256;
    let h = (BAND_HI_M - BAND_LO_M) / n as f64;
    let mut s = spectral(BAND_LO_M, temp_k) + spectral(BAND_HI_M, temp_k);
    for i in 1..n {
        s += spectral(BAND_LO_M + i as f64 * h, temp_k) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// Table of `band_radiance` every 0.1 K over 100–700 K for fast inversion.
fn table() -> &'static [f64] {
    static T: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        (0..=6000)
            .map(|i| band_radiance(100.0 + 0.1 * f64::from(i)))
            .collect()
    })
}

/// The temperature whose band radiance is `radiance` (apparent or brightness temperature), K.
/// Table lookup with one Newton step inside 100–700 K (error < 1e-7 K); Newton's method outside;
/// non-positive radiance gives 0 K.
pub fn temperature_of(radiance: f64) -> f64 {
    if radiance <= 0.0 {
        return 0.0;
    }
    let tab = table();
    if radiance > tab[0] && radiance < tab[tab.len() - 1] {
        let i = tab
            .partition_point(|&l| l < radiance)
            .clamp(1, tab.len() - 1);
        let (l0, l1) = (tab[i - 1], tab[i]);
        let t0 = 100.0 + 0.1 * (i - 1) as f64;
        let t = t0 + 0.1 * (radiance - l0) / (l1 - l0);
        let dl = (l1 - l0) / 0.1;
        return t - (band_radiance(t) - radiance) / dl;
    }
    let mut t = 300.0;
    for _ in 0..50 {
        let l = band_radiance(t);
        let dl = (band_radiance(t + 0.01) - band_radiance(t - 0.01)) / 0.02;
        let step = (l - radiance) / dl;
        t = (t - step).clamp(t * 0.5, t * 2.0);
        if step.abs() < 1e-9 {
            break;
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_radiance_matches_design_numbers() {
        // DESIGN.md §6: 49.4 at 20 °C, 51.0 at 22 °C, 61.1 at 34 °C, 63.8 at 37 °C (W m⁻² sr⁻¹).
        for (c, expect) in [(20.0, 49.4), (22.0, 51.0), (34.0, 61.1), (37.0, 63.8)] {
            let l = band_radiance(c + ZERO_C_K);
            assert!((l / expect - 1.0).abs() < 0.01, "{c} °C: {l} vs {expect}");
        }
        let slope = (band_radiance(22.5 + ZERO_C_K) - band_radiance(21.5 + ZERO_C_K)) / 1.0;
        assert!((slope - 0.80).abs() < 0.02, "dL/dT at 22 °C = {slope}");
    }

    #[test]
    fn inverse_round_trips() {
        for t in [50.0, 250.0, 295.15, 310.0, 310.03, 400.0, 900.0] {
            assert!((temperature_of(band_radiance(t)) - t).abs() < 1e-6, "{t}");
        }
        assert_eq!(temperature_of(0.0), 0.0);
    }
}
