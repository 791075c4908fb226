//! The virtual view's raster ([`super::retrieve`]): truncated distance transforms of a silhouette,
//! each kept on a window about it, and cell rounding without the library call.

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

/// Distance (cells) from every cell of a `w`×`h` raster (rows of `w`) to the nearest cell
/// where `seed` is true, truncated at `cap` (`cap` where there is none).
///
/// Exact, and cheaper than a full transform because of the truncation: with `k = ⌊cap⌋ + 1`,
/// a squared distance under `k²` comes from a seed fewer than `k` rows and columns away, and
/// one of `k²` or more truncates to `cap` (`k > cap`) whatever it is. So along the rows each
/// cell's squared distance to the nearest seed in its row is found by two scans and clamped
/// at `k²`; down the columns it is the minimum over the rows within `k − 1` of
/// `row value + (row offset)²` — whole numbers, exactly those of a full Euclidean transform
/// wherever they are below `k²` — taken a whole row at a time.
fn distance_to(seed: &[bool], w: usize, h: usize, cap: f64) -> Vec<f64> {
    // (A cap beyond the raster truncates nothing but a raster without a seed.)
    let k = cap.max(0.0).floor().min((w + h) as f64) as usize + 1;
    let far = (k * k) as f64;
    let mut g = vec![far; w * h];
    for (row, out) in seed.chunks_exact(w).zip(g.chunks_exact_mut(w)) {
        let mut last = None;
        for (x, (&s, o)) in row.iter().zip(out.iter_mut()).enumerate() {
            if s {
                last = Some(x);
            }
            if let Some(p) = last {
                *o = far.min(((x - p) * (x - p)) as f64);
            }
        }
        let mut next = None;
        for (x, (&s, o)) in row.iter().zip(out.iter_mut()).enumerate().rev() {
            if s {
                next = Some(x);
            }
            if let Some(p) = next {
                *o = o.min(((p - x) * (p - x)) as f64);
            }
        }
    }
    let mut d = vec![far; w * h];
    for (q, out) in d.chunks_exact_mut(w).enumerate() {
        for r in q.saturating_sub(k - 1)..(q + k).min(h) {
            let step = ((q.abs_diff(r)) * q.abs_diff(r)) as f64;
            for (o, &f) in out.iter_mut().zip(&g[r * w..(r + 1) * w]) {
                *o = o.min(f + step);
            }
        }
        for o in out.iter_mut() {
            *o = if *o >= far { cap } else { o.sqrt().min(cap) };
        }
    }
    d
}

/// A rectangle of raster cells, `w`×`h` from `(x0, y0)`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Window {
    x0: i32,
    y0: i32,
    w: i32,
    h: i32,
}

impl Window {
    const EMPTY: Self = Self {
        x0: 0,
        y0: 0,
        w: 0,
        h: 0,
    };

    /// The box `lo..=hi` grown by `margin` cells each way, clipped to an `n`×`n` raster.
    fn about(lo: (usize, usize), hi: (usize, usize), margin: usize, n: usize) -> Self {
        let (x0, y0) = (lo.0.saturating_sub(margin), lo.1.saturating_sub(margin));
        let (x1, y1) = ((hi.0 + margin).min(n - 1), (hi.1 + margin).min(n - 1));
        Self {
            x0: x0 as i32,
            y0: y0 as i32,
            w: (x1 - x0 + 1) as i32,
            h: (y1 - y0 + 1) as i32,
        }
    }

    /// Whether cell `(x, y)` lies within `r` cells of the window (each axis).
    pub(super) fn near(&self, x: i32, y: i32, r: i32) -> bool {
        x + r >= self.x0 && y + r >= self.y0 && x - r < self.x0 + self.w && y - r < self.y0 + self.h
    }

    /// The window's index of raster cell `(x, y)`, if it lies in the window.
    #[inline]
    fn index(&self, x: i32, y: i32) -> Option<usize> {
        let (u, v) = (x - self.x0, y - self.y0);
        (u >= 0 && v >= 0 && u < self.w && v < self.h).then(|| (v * self.w + u) as usize)
    }

    /// `raster`'s cells (rows of `n`) in the window, mapped by `f`.
    fn crop(&self, raster: &[bool], n: usize, f: impl Fn(bool) -> bool) -> Vec<bool> {
        let (x0, w) = (self.x0 as usize, self.w as usize);
        (self.y0 as usize..(self.y0 + self.h) as usize)
            .flat_map(|y| raster[y * n + x0..y * n + x0 + w].iter().map(|&s| f(s)))
            .collect()
    }

    /// Distances to the cells where `seed` (the window's cells) holds, truncated at `cap`.
    fn distances(&self, seed: &[bool], cap: f64) -> Vec<f64> {
        distance_to(seed, self.w as usize, self.h as usize, cap)
    }
}

/// A silhouette's two distance maps (cells), truncated at `cap`, each kept only on the window
/// where it can differ from its far value: `cap` to the silhouette (the window reaches `cap` +
/// 1 cells beyond the silhouette), 0 to its outside (the silhouette's box and one ring of
/// outside cells: a cell of the box has its nearest outside cell there, clamping any other
/// into the ring brings it nearer). Both are exact.
pub(super) struct Distances {
    /// Where the distance to the silhouette is kept.
    sil: Window,
    /// Where the distance to the outside is kept.
    pub(super) out: Window,
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
                sil: Window::EMPTY,
                out: Window::EMPTY,
                to_sil: Vec::new(),
                to_out: Vec::new(),
                cap,
            };
        }
        let near = Window::about(lo, hi, cap.ceil() as usize + 1, n);
        let inner = Window::about(lo, hi, 1, n);
        Self {
            // Truncated once here: the shifts' loop reads each cell many times.
            to_sil: near.distances(&near.crop(sil, n, |s| s), cap),
            to_out: inner.distances(&inner.crop(sil, n, |s| !s), cap),
            sil: near,
            out: inner,
            cap,
        }
    }

    /// Distance to the silhouette, truncated (a cell beyond its window: `cap`).
    pub(super) fn to_sil(&self, x: i32, y: i32) -> f64 {
        self.sil.index(x, y).map_or(self.cap, |i| self.to_sil[i])
    }

    /// Distance to the silhouette's outside, truncated (a cell beyond its window: 0).
    pub(super) fn to_out(&self, x: i32, y: i32) -> f64 {
        self.out.index(x, y).map_or(0.0, |i| self.to_out[i])
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

    /// The brute-force distance from `(x, y)` to the nearest seed of a `w`-wide raster, truncated.
    fn brute(seed: &[bool], w: usize, (x, y): (usize, usize), cap: f64) -> f64 {
        seed.iter()
            .enumerate()
            .filter(|(_, s)| **s)
            .map(|(c, _)| {
                let (a, b) = ((c % w) as f64, (c / w) as f64);
                ((x as f64 - a).powi(2) + (y as f64 - b).powi(2)).sqrt()
            })
            .fold(f64::INFINITY, f64::min)
            .min(cap)
    }

    /// The truncated transform's distances are the brute-force Euclidean ones, to the bit, at
    /// caps below, on and above whole cells, and far beyond the raster; a raster without a
    /// seed is `cap` everywhere.
    #[test]
    fn the_distance_transform_is_euclidean() {
        let (w, h) = (23, 17);
        let mut rng = irmirror_geom::rng::seeded(5, 0);
        let seed: Vec<bool> = (0..w * h)
            .map(|_| rand::Rng::random::<f64>(&mut rng) < 0.03)
            .collect();
        assert!(seed.iter().filter(|s| **s).count() >= 4);
        for cap in [0.5, 1.0, 2.5, 0.15 / 0.02, 7.5, 9.0, 1e3, 1e20] {
            let d = distance_to(&seed, w, h, cap);
            for y in 0..h {
                for x in 0..w {
                    let want = brute(&seed, w, (x, y), cap);
                    assert_eq!(d[y * w + x], want, "cap {cap}, {x},{y}");
                }
            }
            let none = distance_to(&vec![false; w * h], w, h, cap);
            assert!(none.iter().all(|&d| d == cap), "cap {cap}");
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
        let d = Distances::new(&sil, n, cap);
        assert!(
            d.sil.w < n as i32 && d.sil.h < n as i32 && d.out.w < d.sil.w,
            "the windows are the whole raster"
        );
        for y in 0..n {
            for x in 0..n {
                let (to_sil, to_out) =
                    (brute(&sil, n, (x, y), cap), brute(&outside, n, (x, y), cap));
                assert_eq!(d.to_sil(x as i32, y as i32), to_sil, "{x},{y}");
                assert_eq!(d.to_out(x as i32, y as i32), to_out, "{x},{y}");
            }
        }
        let none = Distances::new(&vec![false; n * n], n, cap);
        assert_eq!((none.to_sil(3, 4), none.to_out(3, 4)), (cap, 0.0));
    }
}
