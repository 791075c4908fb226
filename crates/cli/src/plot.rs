//! Plots for reports, as SVG: axes with round ticks and labels, readable at any size.

/// Round tick spacing for a span: 1, 2 or 5 × 10^k giving about `n` ticks.
fn tick_step(span: f64, n: f64) -> f64 {
    let raw = (span / n).max(1e-12);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

/// Loss curves as an SVG plot with labelled axes: the best hypothesis in blue, the others grey,
/// x = optimisation step, y = loss on that step's sampled rays (0 to the largest value).
pub fn loss_svg(curves: &[&[f64]]) -> String {
    let (w, h) = (520.0, 280.0);
    let (left, right, top, bottom) = (60.0, 20.0, 30.0, 45.0);
    let ymax = curves
        .iter()
        .flat_map(|c| c.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(1e-9, f64::max);
    let n = curves.iter().map(|c| c.len()).max().unwrap_or(1).max(2) - 1;
    let ystep = tick_step(ymax, 5.0);
    let ytop = (ymax / ystep).ceil() * ystep;
    let xs = |i: f64| left + i / n as f64 * (w - left - right);
    let ys = |v: f64| h - bottom - v / ytop * (h - top - bottom);
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">
<rect width="{w}" height="{h}" fill="white"/>
"#
    );
    let mut v = 0.0;
    while v <= ytop + 1e-12 {
        s += &format!(
            r##"<line x1="{left}" x2="{}" y1="{y:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>
"##,
            w - right,
            left - 5.0,
            ys(v) + 4.0,
            format_tick(v, ystep),
            y = ys(v)
        );
        v += ystep;
    }
    let xstep = tick_step(n as f64, 6.0).max(1.0);
    let mut i = 0.0;
    while i <= n as f64 + 1e-9 {
        s += &format!(
            r#"<line x1="{x:.1}" x2="{x:.1}" y1="{}" y2="{}" stroke="black"/><text x="{x:.1}" y="{}" text-anchor="middle">{i}</text>
"#,
            h - bottom,
            h - bottom + 4.0,
            h - bottom + 16.0,
            x = xs(i)
        );
        i += xstep;
    }
    s += &format!(
        r#"<line x1="{left}" x2="{}" y1="{b}" y2="{b}" stroke="black"/><line x1="{left}" x2="{left}" y1="{top}" y2="{b}" stroke="black"/>
<text x="{}" y="{}" text-anchor="middle">optimisation step (stage 2 refinement)</text>
<text transform="translate(14,{}) rotate(-90)" text-anchor="middle">loss on the step's rays</text>
"#,
        w - right,
        (left + w - right) / 2.0,
        h - 8.0,
        (top + h - bottom) / 2.0,
        b = h - bottom
    );
    for (k, c) in curves.iter().enumerate().rev() {
        let colour = if k == 0 { "#1f3fc8" } else { "#b4b4b4" };
        let pts: Vec<String> = c
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(i, v)| format!("{:.1},{:.1}", xs(i as f64), ys(*v)))
            .collect();
        s += &format!(
            r#"<polyline fill="none" stroke="{colour}" stroke-width="{}" points="{}"/>
"#,
            if k == 0 { 1.6 } else { 1.0 },
            pts.join(" ")
        );
    }
    s += &format!(
        r##"<line x1="{a}" x2="{b}" y1="14" y2="14" stroke="#1f3fc8" stroke-width="1.6"/><text x="{}" y="18">best hypothesis</text>
<line x1="{c}" x2="{d}" y1="14" y2="14" stroke="#b4b4b4"/><text x="{}" y="18">other hypotheses</text>
</svg>
"##,
        left + 26.0,
        left + 176.0,
        a = left,
        b = left + 22.0,
        c = left + 150.0,
        d = left + 172.0,
    );
    s
}

/// A tick label with as many decimals as the step needs.
fn format_tick(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}
