//! The virtual view's raster ([`super::retrieve`]): distance transforms of a silhouette, kept
//! on a window about it, and cell rounding without the library call.

/// `x.floor()` as an integer, without the library call (exact for |x| < 2⁶³; saturates beyond,
/// far off any raster).
pub(super) fn floor_i(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from(t as f64 > x)
}

/// `x.ceil()` as an integer ([`floor_i`]'s twin).
pub(super) fn ceil_i(x: f64) -> i64 {
    let t = x as i64;
    t + i64::from((t as f64) < x)
}

/// Squared Euclidean distance transform of one line (Felzenszwalb & Huttenlocher).
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let mut k = 0;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        loop {
            let p = v[k];
            let s = ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
            if s <= z[k] && k > 0 {
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
    }
    k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        *out = (q as f64 - p as f64).powi(2) + f[p];
    }
}

/// Distance (cells) from every cell of a `w`×`h` raster (rows of `w`) to the nearest cell
/// where `seed` is true (large where there is none).
fn distance_to(seed: &[bool], w: usize, h: usize) -> Vec<f64> {
    const FAR: f64 = 1e12;
    let mut g: Vec<f64> = seed.iter().map(|&s| if s { 0.0 } else { FAR }).collect();
    let m = w.max(h);
    let (mut d, mut v, mut z) = (vec![0.0; m], vec![0; m], vec![0.0; m + 1]);
    let mut line = vec![0.0; m];
    for row in 0..h {
        line[..w].copy_from_slice(&g[row * w..(row + 1) * w]);
        // A row without a seed is its own transform (every cell FAR + 0).
        if line[..w].iter().all(|&x| x == FAR) {
            continue;
        }
        edt_1d(&line[..w], &mut d[..w], &mut v, &mut z);
        g[row * w..(row + 1) * w].copy_from_slice(&d[..w]);
    }
    for col in 0..w {
        for (r, l) in line[..h].iter_mut().enumerate() {
            *l = g[r * w + col];
        }
        edt_1d(&line[..h], &mut d[..h], &mut v, &mut z);
        for (r, x) in d[..h].iter().enumerate() {
            g[r * w + col] = x.sqrt();
        }
    }
    g
}

/// A silhouette's two distance maps (cells), truncated at `cap`, kept only on the window
/// about it where they can differ from their far values: `cap` to the silhouette and 0 to its
/// outside (the window reaches `cap` + 1 cells beyond the silhouette, so both are exact).
pub(super) struct Distances {
    pub(super) x0: i32,
    pub(super) y0: i32,
    pub(super) w: i32,
    pub(super) h: i32,
    to_sil: Vec<f64>,
    to_out: Vec<f64>,
    cap: f64,
}

impl Distances {
    pub(super) fn new(sil: &[bool], n: usize, cap: f64) -> Self {
        let (mut lo, mut hi) = ((n, n), (0, 0));
        for (c, _) in sil.iter().enumerate().filter(|(_, s)| **s) {
            let (x, y) = (c % n, c / n);
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        if lo.0 > hi.0 {
            return Self {
                x0: 0,
                y0: 0,
                w: 0,
                h: 0,
                to_sil: Vec::new(),
                to_out: Vec::new(),
                cap,
            };
        }
        let margin = cap.ceil() as usize + 1;
        let (x0, y0) = (lo.0.saturating_sub(margin), lo.1.saturating_sub(margin));
        let (x1, y1) = ((hi.0 + margin).min(n - 1), (hi.1 + margin).min(n - 1));
        let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
        let crop: Vec<bool> = (y0..=y1)
            .flat_map(|y| sil[y * n + x0..=y * n + x1].iter().copied())
            .collect();
        let outside: Vec<bool> = crop.iter().map(|s| !s).collect();
        Self {
            x0: x0 as i32,
            y0: y0 as i32,
            w: w as i32,
            h: h as i32,
            // Truncated once here: the shifts' loop reads each cell many times.
            to_sil: distance_to(&crop, w, h)
                .into_iter()
                .map(|d| d.min(cap))
                .collect(),
            to_out: distance_to(&outside, w, h)
                .into_iter()
                .map(|d| d.min(cap))
                .collect(),
            cap,
        }
    }

    /// The window's index of raster cell `(x, y)`, if it lies in the window.
    fn index(&self, x: i32, y: i32) -> Option<usize> {
        let (u, v) = (x - self.x0, y - self.y0);
        (u >= 0 && v >= 0 && u < self.w && v < self.h).then(|| (v * self.w + u) as usize)
    }

    /// Distance to the silhouette, truncated (a cell beyond the window: `cap`).
    pub(super) fn to_sil(&self, x: i32, y: i32) -> f64 {
        self.index(x, y).map_or(self.cap, |i| self.to_sil[i])
    }

    /// Distance to the silhouette's outside, truncated (a cell beyond the window: 0).
    pub(super) fn to_out(&self, x: i32, y: i32) -> f64 {
        self.index(x, y).map_or(0.0, |i| self.to_out[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rounding without the library call is the library's, on both sides of zero, on
    /// whole and half cells and next to them.
    #[test]
    fn cell_rounding_is_the_librarys() {
        for k in -400..=400 {
            let x = f64::from(k) * 0.25;
            for v in [x, x.next_up(), x.next_down(), x + 1e-9, x - 1e-9] {
                assert_eq!(floor_i(v), v.floor() as i64, "floor {v}");
                assert_eq!(ceil_i(v), v.ceil() as i64, "ceil {v}");
            }
        }
        assert_eq!(floor_i(1e30), i64::MAX);
        assert_eq!(ceil_i(-1e30), i64::MIN);
    }

    /// The transform's distances are the brute-force Euclidean ones.
    #[test]
    fn the_distance_transform_is_euclidean() {
        let (w, h) = (9, 6);
        let seeds = [(1usize, 1usize), (7, 2), (4, 5)];
        let mut seed = vec![false; w * h];
        for &(x, y) in &seeds {
            seed[y * w + x] = true;
        }
        let d = distance_to(&seed, w, h);
        for y in 0..h {
            for x in 0..w {
                let want = seeds
                    .iter()
                    .map(|&(a, b)| {
                        ((x as f64 - a as f64).powi(2) + (y as f64 - b as f64).powi(2)).sqrt()
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (d[y * w + x] - want).abs() < 1e-9,
                    "{x},{y}: {} vs {want}",
                    d[y * w + x]
                );
            }
        }
    }

    /// The window the distances are kept on changes none of them: an L-shaped silhouette,
    /// one arm on the raster's edge, against both transforms of the whole raster.
    #[test]
    fn the_windowed_distances_equal_the_whole_rasters() {
        let (n, cap) = (40, 7.5);
        let mut sil = vec![false; n * n];
        for y in 0..n {
            for x in 0..n {
                sil[y * n + x] = ((10..16).contains(&x) && (12..30).contains(&y))
                    || ((24..30).contains(&y) && x < 16);
            }
        }
        let outside: Vec<bool> = sil.iter().map(|s| !s).collect();
        let (to_sil, to_out) = (distance_to(&sil, n, n), distance_to(&outside, n, n));
        let d = Distances::new(&sil, n, cap);
        assert!(
            d.w < n as i32 && d.h < n as i32,
            "the window is the whole raster"
        );
        for y in 0..n {
            for x in 0..n {
                let c = y * n + x;
                assert_eq!(d.to_sil(x as i32, y as i32), to_sil[c].min(cap), "{x},{y}");
                assert_eq!(d.to_out(x as i32, y as i32), to_out[c].min(cap), "{x},{y}");
            }
        }
        let none = Distances::new(&vec![false; n * n], n, cap);
        assert_eq!((none.to_sil(3, 4), none.to_out(3, 4)), (cap, 0.0));
    }
}
