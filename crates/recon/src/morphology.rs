//! Binary morphology with a square structuring element, and edge extraction.

use irmirror_capture::Image;

fn filter(img: &Image<bool>, radius: u32, any: bool) -> Image<bool> {
    if radius == 0 {
        return img.clone();
    }
    let (w, h, r) = (img.width as i64, img.height as i64, i64::from(radius));
    let data = (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            let mut hit = !any;
            'outer: for dy in -r..=r {
                for dx in -r..=r {
                    let (nx, ny) = (x + dx, y + dy);
                    // Outside the image counts as background for dilation and erosion alike.
                    let v =
                        nx >= 0 && ny >= 0 && nx < w && ny < h && img.data[(ny * w + nx) as usize];
                    if any && v {
                        hit = true;
                        break 'outer;
                    }
                    if !any && !v {
                        hit = false;
                        break 'outer;
                    }
                }
            }
            hit
        })
        .collect();
    Image {
        width: img.width,
        height: img.height,
        data,
    }
}

/// Dilation: a pixel is set if any pixel within `radius` (Chebyshev) is.
pub fn dilate(img: &Image<bool>, radius: u32) -> Image<bool> {
    filter(img, radius, true)
}

/// Erosion: a pixel stays set if every pixel within `radius` is set.
pub fn erode(img: &Image<bool>, radius: u32) -> Image<bool> {
    filter(img, radius, false)
}

/// Opening (erode, dilate): removes specks smaller than the element.
pub fn open(img: &Image<bool>, radius: u32) -> Image<bool> {
    dilate(&erode(img, radius), radius)
}

/// Closing (dilate, erode): fills holes smaller than the element.
pub fn close(img: &Image<bool>, radius: u32) -> Image<bool> {
    erode(&dilate(img, radius), radius)
}

/// Removes 8-connected components with fewer than `min_pixels` pixels.
pub fn remove_small_components(img: &Image<bool>, min_pixels: usize) -> Image<bool> {
    let (w, h) = (img.width as i64, img.height as i64);
    let mut out = img.clone();
    let mut seen = vec![false; img.data.len()];
    let mut stack = Vec::new();
    let mut comp = Vec::new();
    for start in 0..img.data.len() {
        if !img.data[start] || seen[start] {
            continue;
        }
        comp.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(p) = stack.pop() {
            comp.push(p);
            let (x, y) = (p as i64 % w, p as i64 / w);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx >= 0 && ny >= 0 && nx < w && ny < h {
                        let q = (ny * w + nx) as usize;
                        if img.data[q] && !seen[q] {
                            seen[q] = true;
                            stack.push(q);
                        }
                    }
                }
            }
        }
        if comp.len() < min_pixels {
            comp.iter().for_each(|&p| out.data[p] = false);
        }
    }
    out
}

/// Mask pixels with a 4-neighbour outside the mask (or at the image border).
pub fn edges(img: &Image<bool>) -> Image<bool> {
    let (w, h) = (img.width as i64, img.height as i64);
    let at = |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h && img.data[(y * w + x) as usize];
    let data = (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            at(x, y) && !(at(x + 1, y) && at(x - 1, y) && at(x, y + 1) && at(x, y - 1))
        })
        .collect();
    Image {
        width: img.width,
        height: img.height,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(rows: &[&str]) -> Image<bool> {
        Image {
            width: rows[0].len() as u32,
            height: rows.len() as u32,
            data: rows
                .iter()
                .flat_map(|r| r.chars().map(|c| c == '#'))
                .collect(),
        }
    }

    #[test]
    fn opening_removes_specks_and_closing_fills_holes() {
        let a = img(&["......", ".###..", ".###.#", ".###..", "......"]);
        let o = open(&a, 1);
        assert_eq!(o, img(&["......", ".###..", ".###..", ".###..", "......"]));
        let b = img(&["#####", "##.##", "#####"]);
        // The hole is filled.
        assert!(close(&b, 1).data[7]);
        let specks = img(&["#.....", "...##.", "...##.", "#....."]);
        assert_eq!(
            remove_small_components(&specks, 2),
            img(&["......", "...##.", "...##.", "......"])
        );
        let e = edges(&img(&["...", ".#.", "..."]));
        assert_eq!(e.data.iter().filter(|x| **x).count(), 1);
        let full = img(&["###", "###", "###"]);
        assert_eq!(edges(&full).data.iter().filter(|x| **x).count(), 8);
    }
}
