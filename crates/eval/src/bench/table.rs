//! The benchmark's Markdown tables (Table 1 per cell, failures, diagnosis counts, the
//! refinement's basin, objects) and its HTML report.

use super::{CaptureResult, Diagnosis, FailureClass, RANDOM_DRAWS, Report, Variant};
use crate::metrics::mean_ci95;
use crate::score::Evaluation;
use irmirror_sim::presets::Cell;

/// The metric rows of the table: name and accessor.
type Metric = (&'static str, fn(&Evaluation) -> Option<f64>);
const METRICS: [Metric; 8] = [
    ("2-D keypoints, normalised", |e| e.keypoints_2d_normalised),
    ("3-D keypoints, normalised", |e| e.keypoints_3d_normalised),
    ("root error (m)", |e| Some(e.root_error_m)),
    ("MPJPE (m)", |e| e.mpjpe_m),
    ("PA-MPJPE (m)", |e| e.pa_mpjpe_m),
    ("mean per-vertex error (m)", |e| e.vertex_error_m),
    ("facing error (°)", |e| e.facing_error_deg),
    ("reflection IoU", |e| Some(e.reflection_iou)),
];

/// Mean ± 95 % interval; with the count when it differs from the row's `n` (ablation columns
/// run on a subset).
fn cell(values: &[f64], n: usize) -> String {
    let m = match mean_ci95(values) {
        Some((m, h)) => format!("{m:.3} ± {h:.3}"),
        None => "n/a".into(),
    };
    if values.len() == n || values.is_empty() {
        m
    } else {
        format!("{m} (n = {})", values.len())
    }
}

/// The captures of one cell.
fn of_cell(r: &Report, c: Cell) -> Vec<&CaptureResult> {
    r.captures.iter().filter(|x| x.cell == c).collect()
}

/// Table 1's layout per cell (rows metric × cell; columns the ablations, the full model and
/// Random), then failures, the failure diagnosis counts, and the objects.
pub fn markdown_table(r: &Report) -> String {
    let mut s = String::from("| metric | cell | n |");
    for v in Variant::ALL {
        s.push_str(&format!(" {} |", v.heading()));
    }
    s.push_str(" random |\n|---|---|---|");
    s.push_str(&"---|".repeat(Variant::ALL.len() + 1));
    s.push('\n');
    for (metric, get) in METRICS {
        for c in Cell::ALL {
            let caps = of_cell(r, c);
            if caps.is_empty() {
                continue;
            }
            let n = caps.len();
            s.push_str(&format!("| {metric} | {c} | {n} |"));
            for variant in Variant::ALL {
                let v: Vec<f64> = caps
                    .iter()
                    .filter_map(|x| {
                        x.variants
                            .get(&variant)
                            .and_then(|y| y.eval.as_ref())
                            .and_then(get)
                    })
                    .collect();
                s.push_str(&format!(" {} |", cell(&v, n)));
            }
            // Random: the per-capture mean over draws, then the mean over captures.
            let v: Vec<f64> = caps
                .iter()
                .filter_map(|x| {
                    let d: Vec<f64> = x.random.iter().filter_map(get).collect();
                    (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
                })
                .collect();
            s.push_str(&format!(" {} |\n", cell(&v, n)));
        }
    }
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        s.push_str(&format!(
            "| failed reconstructions | {c} | {} |",
            caps.len()
        ));
        for variant in Variant::ALL {
            let ran: Vec<&&CaptureResult> = caps
                .iter()
                .filter(|x| x.variants.contains_key(&variant))
                .collect();
            // A variant left out (`--full-only`) did not fail: it did not run.
            if ran.is_empty() {
                s.push_str(" – |");
            } else {
                let failed = ran
                    .iter()
                    .filter(|x| x.variants[&variant].eval.is_none())
                    .count();
                s.push_str(&format!(" {failed} of {} |", ran.len()));
            }
        }
        s.push_str(" – |\n");
    }
    s.push_str(&diagnosis_table(r));
    s.push_str(&hypotheses_table(r));
    s.push_str(&reflection_table(r));
    s.push_str(&radiometric_table(r));
    s.push_str(&ablations_table(r));
    s.push_str(&true_objects_table(r));
    s.push_str(&paired_table(
        r,
        (Variant::TrueShape, "true shape"),
        (Variant::Full, "fitted shape"),
    ));
    s.push_str(&paired_table(
        r,
        (Variant::TrueHeight, "true height"),
        (Variant::Full, "height prior"),
    ));
    s.push_str(&paired_table(
        r,
        (Variant::TrueBuild, "true build"),
        (Variant::Full, "mean build"),
    ));
    s.push_str(&paired_table(
        r,
        (Variant::TrueRadiometry, "true temperatures"),
        (Variant::Full, "cited ranges"),
    ));
    s.push_str(&basin_table(r));
    s.push_str(&objects_table(r));
    s
}

/// The refinement's basin per cell (`eval --basin`; empty when no capture was probed): how many
/// starts near the truth the refinement brought back within a success's distance, and the
/// medians at their ends next to the fit's own data term.
pub fn basin_table(r: &Report) -> String {
    if !r
        .captures
        .iter()
        .any(|c| c.diagnosis.as_ref().is_some_and(|d| !d.basin.is_empty()))
    {
        return String::new();
    }
    let mut s = String::from(
        "\n| cell | captures probed | start pose | starts (offset, turn) | ended within 15 cm and 30° | diverged | root error at the end, median (m) | facing within 30° at the end | data term at the end, median | the fit's data term, median | the truth's data term, median | per-vertex at the end, median (m) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in Cell::ALL {
        let ds: Vec<&Diagnosis> = of_cell(r, c)
            .iter()
            .filter_map(|x| x.diagnosis.as_ref())
            .filter(|d| !d.basin.is_empty())
            .collect();
        // One row per start pose, in the order the probe used them.
        let mut poses: Vec<&str> = Vec::new();
        for b in ds.iter().flat_map(|d| &d.basin) {
            if !poses.contains(&b.pose.as_str()) {
                poses.push(&b.pose);
            }
        }
        let fit: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.hypothesis_losses.first().copied())
            .collect();
        let truth: Vec<f64> = ds.iter().map(|d| d.truth_loss).collect();
        for pose in poses {
            let starts: Vec<&super::BasinStart> = ds
                .iter()
                .flat_map(|d| &d.basin)
                .filter(|b| b.pose == pose)
                .collect();
            let Some(first) = starts.first() else {
                continue;
            };
            let n = starts.len();
            let closed = starts.iter().filter(|b| b.closed()).count();
            let diverged = starts.iter().filter(|b| b.root_error_m.is_none()).count();
            let root: Vec<f64> = starts.iter().filter_map(|b| b.root_error_m).collect();
            let facing = starts
                .iter()
                .filter(|b| {
                    b.facing_error_deg
                        .is_some_and(|f| f <= super::SUCCESS_FACING_DEG)
                })
                .count();
            let data: Vec<f64> = starts.iter().filter_map(|b| b.data_loss).collect();
            let vertex: Vec<f64> = starts.iter().filter_map(|b| b.vertex_error_m).collect();
            s.push_str(&format!(
                "| {c} | {} | {pose} | {n} (±{:.2} m, ±{:.0}°) | {closed} of {n} | {diverged} | {} | {facing} of {n} | {} | {} | {} | {} |\n",
                ds.len(),
                first.offset_m.abs(),
                first.turn_deg.abs(),
                median(&root),
                median(&data),
                median(&fit),
                median(&truth),
                median(&vertex),
            ));
        }
    }
    s
}

/// Counts of the full model's failure classes per cell.
pub fn diagnosis_table(r: &Report) -> String {
    let mut s = String::from("\n| cell | n |");
    for k in FailureClass::ALL {
        s.push_str(&format!(" {} |", k.heading()));
    }
    s.push_str(" of the search failures, reachable by our model | full model failed | data term, median: fit / truth / truth through the true objects / our model refined from the truth | the truth beats its front/back flip: data term / mask; its outline twin (data term); the thermal judge at the truth right | stage 1's mirror on the mask, median: reflected-ray angle (°) / offset at the person (m) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        s.push_str(&format!("| {c} | {} |", caps.len()));
        for k in FailureClass::ALL {
            let n = caps
                .iter()
                .filter(|x| x.diagnosis.as_ref().is_some_and(|d| d.class == k))
                .count();
            s.push_str(&format!(" {n} |"));
        }
        let failed = caps.iter().filter(|x| x.diagnosis.is_none()).count();
        let ds: Vec<&Diagnosis> = caps.iter().filter_map(|x| x.diagnosis.as_ref()).collect();
        // A search failure our model can reach: refined from the truth, it beats the fit.
        let reachable = ds
            .iter()
            .filter(|d| {
                d.class == FailureClass::Search
                    && d.truth_start_loss
                        .zip(d.hypothesis_losses.first())
                        .is_some_and(|(t, f)| t < *f)
            })
            .count();
        let started: Vec<f64> = ds.iter().filter_map(|d| d.truth_start_loss).collect();
        let fit: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.hypothesis_losses.first().copied())
            .collect();
        let truth: Vec<f64> = ds.iter().map(|d| d.truth_loss).collect();
        let through: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.truth_loss_true_objects)
            .collect();
        // Front/back told apart by the data: the truth scores below its flip.
        let beats = ds
            .iter()
            .filter(|d| d.truth_flip_loss.is_some_and(|f| d.truth_loss < f))
            .count();
        let beats_mask = ds
            .iter()
            .filter(|d| d.truth_mask_losses.is_some_and(|[t, f]| t < f))
            .count();
        let scored = ds.iter().filter(|d| d.truth_flip_loss.is_some()).count();
        // The thermal values alone: the outline twin (same outline, front and back swapped),
        // and the thermal judge at the true root and facing.
        let beats_twin = ds
            .iter()
            .filter(|d| {
                d.truth_outline_twin_losses
                    .is_some_and(|[t, _]| d.truth_loss < t)
            })
            .count();
        let twins = ds
            .iter()
            .filter(|d| d.truth_outline_twin_losses.is_some())
            .count();
        let judged = ds
            .iter()
            .filter(|d| d.truth_thermal_facing.is_some())
            .count();
        let judge = ds
            .iter()
            .filter(|d| d.truth_thermal_facing.is_some_and(|[own, twin]| own < twin))
            .count();
        let angle: Vec<f64> = ds.iter().filter_map(|d| d.mask_ray_angle_deg).collect();
        let offset: Vec<f64> = ds.iter().filter_map(|d| d.mask_ray_offset_m).collect();
        s.push_str(&format!(
            " {reachable} | {failed} | {} / {} / {} / {} | {beats} / {beats_mask} of {scored}; {beats_twin} of {twins}; {judge} of {judged} | {} / {} |\n",
            median(&fit),
            median(&truth),
            median(&through),
            median(&started),
            median(&angle),
            median(&offset),
        ));
    }
    s
}

/// The full model's medians and its hypotheses per cell (issue 25's figures): root error, root
/// error over the person's distance, the true facing (± 30°) among the reported hypotheses, and
/// the mean per-vertex error of the best hypothesis facing the right way and of the best by loss;
/// our model at the truth, and refined from it (a search's ceiling: root and per-vertex error,
/// how often it still faces within 30°).
pub fn hypotheses_table(r: &Report) -> String {
    let mut s = String::from(
        "\n| cell | n | root error, median (m) | root error / distance, median (%) | true facing among the hypotheses | per-vertex error, best right-facing hypothesis, median (m) | per-vertex error, best by loss, median (m) | 2-D keypoints, median | stage 2 time, median (s) | our model at the truth: per-vertex error / data term, median (m / –) | our model refined from the truth (a search's ceiling): root / per-vertex error, median (m); facing within 30° |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        let evals: Vec<(&Evaluation, f64)> = caps
            .iter()
            .filter_map(|x| {
                let v = x.variants.get(&Variant::Full)?;
                Some((v.eval.as_ref()?, v.time_s))
            })
            .collect();
        let pick = |f: fn(&Evaluation) -> Option<f64>| -> Vec<f64> {
            evals.iter().filter_map(|(e, _)| f(e)).collect()
        };
        let ds: Vec<&Diagnosis> = caps.iter().filter_map(|x| x.diagnosis.as_ref()).collect();
        let found = ds
            .iter()
            .filter(|d| {
                d.hypothesis_facing_errors_deg
                    .iter()
                    .any(|f| f.is_some_and(|f| f <= super::SUCCESS_FACING_DEG))
            })
            .count();
        let right: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.right_facing_vertex_error_m)
            .collect();
        let times: Vec<f64> = evals.iter().map(|(_, t)| *t).collect();
        let floor: Vec<f64> = ds
            .iter()
            .filter_map(|d| d.model_truth_vertex_error_m)
            .collect();
        let floor_loss: Vec<f64> = ds.iter().filter_map(|d| d.model_truth_loss).collect();
        let of = |f: fn(&Diagnosis) -> Option<f64>| -> Vec<f64> {
            ds.iter().filter_map(|d| f(d)).collect()
        };
        let ceil_root = of(|d| d.truth_start_root_error_m);
        let ceil_vertex = of(|d| d.truth_start_vertex_error_m);
        let ceil_facing = of(|d| d.truth_start_facing_error_deg);
        let ceil_right = ceil_facing
            .iter()
            .filter(|&&f| f <= super::SUCCESS_FACING_DEG)
            .count();
        s.push_str(&format!(
            "| {c} | {} | {} | {} | {found} of {} | {} (n = {}) | {} | {} | {} | {} / {} | {} / {}; {ceil_right} of {} |\n",
            caps.len(),
            median(&pick(|e| Some(e.root_error_m))),
            median(&pick(|e| Some(
                100.0 * e.root_error_m / e.person_distance_m
            ))),
            ds.len(),
            median(&right),
            right.len(),
            median(&pick(|e| e.vertex_error_m)),
            median(&pick(|e| e.keypoints_2d_normalised)),
            median(&times),
            median(&floor),
            median(&floor_loss),
            median(&ceil_root),
            median(&ceil_vertex),
            ceil_facing.len(),
        ));
    }
    s
}

/// What the reflection shows of the person, per cell: the shares of the rise the radiometric
/// model predicts for the true body (and for the best hypothesis) by region, medians, and in
/// how many captures the truth's face or bare skin carries a tenth of it — the thermal
/// front/back cue; with clothing alone a body and its outline twin look alike.
pub fn reflection_table(r: &Report) -> String {
    let mut s = String::from(
        "\n| cell | n | the truth's predicted rise by region: clothing / bare skin / face / hair, median share (%) | captures where the truth's face / bare skin is ≥ 10 % of it | the best hypothesis': clothing / bare skin / face / hair (%) |\n|---|---|---|---|---|\n",
    );
    let shares = |v: &[f64; 4]| -> Option<[f64; 4]> {
        let total: f64 = v.iter().sum();
        (total > 0.0).then(|| v.map(|x| 100.0 * x / total))
    };
    let col = |rows: &[[f64; 4]]| -> String {
        (0..4)
            .map(|k| median(&rows.iter().map(|x| x[k]).collect::<Vec<_>>()))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    for c in Cell::ALL {
        let ds: Vec<&Diagnosis> = of_cell(r, c)
            .iter()
            .filter_map(|x| x.diagnosis.as_ref())
            .collect();
        let truth: Vec<[f64; 4]> = ds
            .iter()
            .filter_map(|d| d.truth_region_rise_k_px.as_ref().and_then(shares))
            .collect();
        if truth.is_empty() {
            continue;
        }
        let best: Vec<[f64; 4]> = ds
            .iter()
            .filter_map(|d| d.best_region_rise_k_px.as_ref().and_then(shares))
            .collect();
        let seen = |k: usize| truth.iter().filter(|x| x[k] >= 10.0).count();
        s.push_str(&format!(
            "| {c} | {} | {} | {} / {} of {} | {} |\n",
            truth.len(),
            col(&truth),
            seen(2),
            seen(1),
            truth.len(),
            col(&best),
        ));
    }
    s
}

/// The thermal rise against the paper's binary mask on the same captures (the captures where
/// both ran).
pub fn radiometric_table(r: &Report) -> String {
    paired_table(
        r,
        (Variant::Full, "radiometric"),
        (Variant::NoRadiometric, "mask"),
    )
}

/// Each of the other ablations (edge sampling, sphere tracing, smoothing) against the full
/// model on the captures where both ran: Table 1's ablation columns run on a subset, so
/// their means are over other captures than the full model's; the paired differences say
/// whether an ablation is worse (issue 25 item 4).
pub fn ablations_table(r: &Report) -> String {
    [
        (Variant::NoEdgeSampling, "w/o edge sampling"),
        (Variant::NoSphereTracing, "w/o sphere tracing"),
        (Variant::NoSmoothing, "w/o smoothing"),
    ]
    .into_iter()
    .map(|ablated| paired_table(r, ablated, (Variant::Full, "full")))
    .collect()
}

/// Stage 2 through the simulator's objects against stage 1's (`--variants full,true-objects`):
/// what a perfect mirror would give the person, on the same captures.
pub fn true_objects_table(r: &Report) -> String {
    paired_table(
        r,
        (Variant::TrueObjects, "true objects"),
        (Variant::Full, "fitted objects"),
    )
}

/// Two variants on the same captures (those where both ran; empty when none): the
/// best-by-loss hypothesis' facing within 30°, successes (within 15 cm and 30°), root and
/// per-vertex medians, and the paired per-vertex and 2-D keypoint differences (a − b), each
/// the mean with its 95 % interval; for an oracle `a`, each one's ceiling (our model refined
/// from the truth: root and per-vertex medians).
fn paired_table(r: &Report, (a, a_name): (Variant, &str), (b, b_name): (Variant, &str)) -> String {
    let oracle = a.on_request_only();
    let mut s = format!(
        "\n| cell | n (both ran) | facing within 30°, {a_name} | facing within 30°, {b_name} | within 15 cm and 30°, {a_name} / {b_name} | root error median (m), {a_name} / {b_name} | per-vertex error median (m), {a_name} / {b_name} | per-vertex error, {a_name} − {b_name}, mean (m) | 2-D keypoints, {a_name} − {b_name}, mean |{}\n|---|---|---|---|---|---|---|---|---|{}\n",
        if oracle {
            format!(" refined from the truth: root / per-vertex median (m), {a_name}; {b_name} |")
        } else {
            String::new()
        },
        if oracle { "---|" } else { "" },
    );
    let mut any = false;
    for c in Cell::ALL {
        let pairs: Vec<(&Evaluation, &Evaluation)> = of_cell(r, c)
            .iter()
            .filter_map(|x| {
                let get = |v| x.variants.get(&v).and_then(|y| y.eval.as_ref());
                Some((get(a)?, get(b)?))
            })
            .collect();
        if pairs.is_empty() {
            continue;
        }
        any = true;
        let (va, vb): (Vec<&Evaluation>, Vec<&Evaluation>) = pairs.iter().copied().unzip();
        let facing_ok = |e: &Evaluation| {
            e.facing_error_deg
                .is_some_and(|f| f <= super::SUCCESS_FACING_DEG)
        };
        let facing = |v: &[&Evaluation]| v.iter().filter(|e| facing_ok(e)).count();
        let success = |v: &[&Evaluation]| {
            v.iter()
                .filter(|e| facing_ok(e) && e.root_error_m <= super::SUCCESS_ROOT_M)
                .count()
        };
        let col = |v: &[&Evaluation], f: fn(&Evaluation) -> Option<f64>| {
            median(&v.iter().filter_map(|e| f(e)).collect::<Vec<_>>())
        };
        let diff = |f: fn(&Evaluation) -> Option<f64>| -> Vec<f64> {
            pairs
                .iter()
                .filter_map(|(x, y)| Some(f(x)? - f(y)?))
                .collect()
        };
        let vertex = diff(|e| e.vertex_error_m);
        let keypoints = diff(|e| e.keypoints_2d_normalised);
        let n = pairs.len();
        let ceilings = if oracle {
            let both = || {
                of_cell(r, c).into_iter().filter(|x| {
                    [a, b]
                        .iter()
                        .all(|v| x.variants.get(v).is_some_and(|y| y.eval.is_some()))
                })
            };
            let own: Vec<&super::Ceiling> = both()
                .filter_map(|x| x.variants.get(&a)?.ceiling.as_ref())
                .collect();
            let full: Vec<&Diagnosis> = both().filter_map(|x| x.diagnosis.as_ref()).collect();
            format!(
                " {} / {}; {} / {} |",
                median(&own.iter().map(|c| c.root_error_m).collect::<Vec<_>>()),
                median(
                    &own.iter()
                        .filter_map(|c| c.vertex_error_m)
                        .collect::<Vec<_>>()
                ),
                median(
                    &full
                        .iter()
                        .filter_map(|d| d.truth_start_root_error_m)
                        .collect::<Vec<_>>()
                ),
                median(
                    &full
                        .iter()
                        .filter_map(|d| d.truth_start_vertex_error_m)
                        .collect::<Vec<_>>()
                ),
            )
        } else {
            String::new()
        };
        s.push_str(&format!(
            "| {c} | {n} | {} of {n} | {} of {n} | {} / {} | {} / {} | {} / {} | {} | {} |{ceilings}\n",
            facing(&va),
            facing(&vb),
            success(&va),
            success(&vb),
            col(&va, |e| Some(e.root_error_m)),
            col(&vb, |e| Some(e.root_error_m)),
            col(&va, |e| e.vertex_error_m),
            col(&vb, |e| e.vertex_error_m),
            cell(&vertex, vertex.len()),
            cell(&keypoints, keypoints.len()),
        ));
    }
    if any { s } else { String::new() }
}

/// The median to 3 decimals, or "–".
fn median(v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => "–".into(),
        n => format!("{:.3}", s[n / 2]),
    }
}

/// Stage-1 figures and times per cell.
fn objects_table(r: &Report) -> String {
    let mut s = String::from(
        "\n| cell | objects: translation error (mm) | scale error (%) | Chamfer (mm²) | stage 0–1 time (s) | stage 2 time, full model (s) |\n|---|---|---|---|---|---|\n",
    );
    for c in Cell::ALL {
        let caps = of_cell(r, c);
        if caps.is_empty() {
            continue;
        }
        let full = |x: &&CaptureResult| x.variants.get(&Variant::Full).cloned();
        let evals: Vec<Evaluation> = caps
            .iter()
            .filter_map(full)
            .filter_map(|v| v.eval)
            .collect();
        let t: Vec<f64> = evals
            .iter()
            .flat_map(|e| e.object_translation_error_m.iter().map(|x| x * 1e3))
            .collect();
        let sc: Vec<f64> = evals
            .iter()
            .flat_map(|e| e.object_scale_error_pct.iter().copied())
            .collect();
        let ch: Vec<f64> = caps
            .iter()
            .flat_map(|x| x.object_chamfer_mm2.iter().copied())
            .collect();
        let t1: Vec<f64> = caps.iter().map(|x| x.objects_time_s).collect();
        let t2: Vec<f64> = caps.iter().filter_map(full).map(|v| v.time_s).collect();
        let cells = [&t, &sc, &ch, &t1, &t2].map(|v| cell(v, v.len()));
        s.push_str(&format!("| {c} | {} |\n", cells.join(" | ")));
    }
    s
}

pub(super) fn html(r: &Report, table: &str) -> String {
    let mut rows = String::new();
    for c in &r.captures {
        let full = c.variants.get(&Variant::Full).and_then(|v| v.eval.as_ref());
        let f = |x: Option<f64>| x.map_or("n/a".into(), |v| format!("{v:.3}"));
        let diag = c.diagnosis.as_ref().map_or("failed".to_string(), |d| {
            format!(
                "{} (truth {:.3}, fit {:.3})",
                d.class.heading(),
                d.truth_loss,
                d.hypothesis_losses.first().copied().unwrap_or(f64::NAN)
            )
        });
        rows.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td><img src=\"captures/{}/overlay.png\" width=\"160\"></td><td><img src=\"captures/{}/third.png\" width=\"160\"></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            c.id,
            c.reflection_pixels,
            c.person_distance_m,
            c.id,
            c.id,
            f(full.and_then(|e| e.keypoints_2d_normalised)),
            f(full.map(|e| e.root_error_m)),
            f(full.and_then(|e| e.vertex_error_m)),
            diag,
        ));
    }
    let table_html: String = table
        .lines()
        .filter(|l| l.starts_with('|') && !l.starts_with("|---"))
        .map(|l| {
            format!(
                "<tr>{}</tr>\n",
                l.trim_matches('|')
                    .split('|')
                    .map(|c| format!("<td>{}</td>", c.trim()))
                    .collect::<String>()
            )
        })
        .collect();
    format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>irmirror eval ({:?})</title>\
         <style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}td{{padding:2px 8px;border-bottom:1px solid #ddd}}</style></head><body>\
         <h1>irmirror eval — {} captures</h1>\
         <p>Synthetic captures (simulator): cells tabletop-bowl, tabletop-mug and car are the paper-like regimes (Boson-class 640×512, 50°), tabletop-wide the hard one (Lepton-class 160×120, 57°); means with 95 % intervals (Student t). \
         Random: {RANDOM_DRAWS} pose-prior samples per capture at the true root position and orientation. \
         Overlay: observed reflection green, fitted magenta, both white. Third view: fitted body orange, truth green.</p>\
         <table>{table_html}</table><h2>Per capture (full model)</h2>\
         <table><tr><th>capture</th><th>reflection px</th><th>distance (m)</th><th>observed vs fitted</th><th>third camera</th><th>2-D</th><th>root error (m)</th><th>per-vertex error (m)</th><th>diagnosis (data term: truth, fit)</th></tr>{rows}</table></body></html>",
        r.set,
        r.captures.len()
    )
}
