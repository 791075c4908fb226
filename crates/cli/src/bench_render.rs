//! `irmirror bench render`: the renderer benchmark of DESIGN.md §7 — one forward + backward of
//! the soft-IoU loss on `scene_sphere160.json`, fast (BVH-culled) and dense, in one run.

use anyhow::{Result, bail};
use irmirror_geom::Rigid3;
use irmirror_geom::nalgebra::Vector3;
use irmirror_render::bench_scene::BenchScene;
use irmirror_render::hard::hard_mask;
use irmirror_render::{
    Aggregation, Culling, Normals, OccupancyGrad, OccupancyParams, ReflectedRays, SoftRenderer,
    SurfaceMethod, TraceParams, reflect_camera, soft_iou_loss,
};
use std::path::Path;
use std::time::Instant;

/// Peak resident memory of this process (VmHWM), bytes, if the OS reports it.
fn peak_rss() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace()
        .nth(1)?
        .parse::<u64>()
        .ok()
        .map(|kb| kb * 1024)
}

/// Resets the peak-RSS counter (Linux `clear_refs` 5); false where not permitted.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

struct PassResult {
    loss: f64,
    grad: Vec<Vector3<f32>>,
    pairs: u64,
    /// Milliseconds: refit, forward (+ loss), backward.
    split_ms: [f64; 3],
}

/// One optimisation step's rendering work: refit to the vertices, forward, loss, backward.
fn pass(
    renderer: &mut SoftRenderer<f32>,
    vertices: &[Vector3<f32>],
    rays: &ReflectedRays<f32>,
    target: &[f32],
    params: &OccupancyParams,
    culling: Culling,
    (grad, d): (&mut OccupancyGrad<f32>, &mut Vec<f32>),
) -> PassResult {
    let t0 = Instant::now();
    renderer.set_vertices(vertices);
    let t1 = Instant::now();
    let occ = renderer.forward(rays, params, culling);
    let loss = soft_iou_loss(rays, &occ.value, target, d);
    let t2 = Instant::now();
    renderer.backward(rays, &occ, d, params, culling, grad);
    let t3 = Instant::now();
    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
    PassResult {
        loss: f64::from(loss),
        grad: grad.vertices.clone(),
        pairs: occ.pairs,
        split_ms: [ms(t0, t1), ms(t1, t2), ms(t2, t3)],
    }
}

/// Runs the benchmark and prints its tables.
pub fn run(
    path: &Path,
    reps: usize,
    no_dense: bool,
    epsilons: &[f64],
    aggregation: Aggregation,
) -> Result<()> {
    if let Some(e) = epsilons.iter().find(|e| !(**e > 0.0 && **e < 0.5)) {
        bail!("--epsilon must be in (0, 0.5), got {e}");
    }
    let mut scene = BenchScene::load(path)?;
    scene.occupancy.aggregation = aggregation;
    // The scene's reflector is an exact sphere: trace it to 1e-6 of its radius.
    let trace = TraceParams {
        coarse_tol_rel: 1e-6,
        method: SurfaceMethod::SphereTrace { steps: 3 },
        max_iters: 4096,
    };
    let t0 = Instant::now();
    let rays = reflect_camera(
        &scene.camera,
        &Rigid3::identity(),
        std::slice::from_ref(&scene.sphere),
        &trace,
        Normals::Raw,
    )
    .cast::<f32>();
    let rays_ms = t0.elapsed().as_secs_f64() * 1e3;
    let verts: Vec<Vector3<f32>> = scene.vertices.iter().map(|v| v.map(|x| x as f32)).collect();
    let target: Vec<f32> = scene.target.iter().map(|&x| x as f32).collect();

    let t0 = Instant::now();
    let mut fast = SoftRenderer::new(&verts, &scene.triangles);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let hard = hard_mask(&rays, fast.bvh(), &verts, &scene.triangles);
    let (mut inter, mut union) = (0usize, 0usize);
    for (h, r) in hard.iter().zip(&scene.reference_hard) {
        let r = *r > 0.5;
        inter += usize::from(*h && r);
        union += usize::from(*h || r);
    }
    println!(
        "scene {}: {}×{} camera, {} reflected rays ({rays_ms:.1} ms to trace), {} triangles, σ = {} m², {aggregation:?} aggregation, {} threads, f32",
        path.display(),
        scene.camera.width,
        scene.camera.height,
        rays.len(),
        scene.triangles.len(),
        scene.occupancy.sigma_m2,
        rayon::current_num_threads()
    );
    println!(
        "hard mask vs reference: IoU {:.4} ({} vs {} pixels)",
        if union > 0 {
            inter as f64 / union as f64
        } else {
            1.0
        },
        hard.iter().filter(|h| **h).count(),
        scene.reference_hard.iter().filter(|r| **r > 0.5).count()
    );
    println!();
    println!("| path | forward + backward | pairs evaluated | peak RSS growth | loss |");
    println!("|---|---|---|---|---|");
    let reset = reset_peak_rss();
    let mb = |a: Option<u64>, b: Option<u64>| match (a, b, reset) {
        (Some(a), Some(b), true) => format!("{:.1} MB", b.saturating_sub(a) as f64 / 1e6),
        (_, Some(b), _) => format!("(process peak {:.0} MB)", b as f64 / 1e6),
        _ => "n/a".into(),
    };
    let (mut grad, mut d) = (OccupancyGrad::default(), Vec::new());
    let mut fast_results = Vec::new();
    for &epsilon in epsilons {
        let params = OccupancyParams {
            epsilon,
            ..scene.occupancy
        };
        pass(
            &mut fast,
            &verts,
            &rays,
            &target,
            &params,
            Culling::Bvh,
            (&mut grad, &mut d),
        ); // warm-up
        reset_peak_rss();
        let rss0 = peak_rss();
        let mut times = Vec::with_capacity(reps);
        let mut last = None;
        for _ in 0..reps.max(1) {
            let t = Instant::now();
            let r = pass(
                &mut fast,
                &verts,
                &rays,
                &target,
                &params,
                Culling::Bvh,
                (&mut grad, &mut d),
            );
            times.push(t.elapsed().as_secs_f64() * 1e3);
            last = Some(r);
        }
        let peak = peak_rss();
        times.sort_by(f64::total_cmp);
        let ms = times[times.len() / 2];
        let r = last.expect("at least one repetition");
        println!(
            "| fast, ε = {epsilon:.0e} (BVH refit + culled query; build {build_ms:.1} ms once) | {ms:.2} ms (median of {}; refit {:.2}, forward {:.2}, backward {:.2}) | {} | {} | {:.6} |",
            times.len(),
            r.split_ms[0],
            r.split_ms[1],
            r.split_ms[2],
            r.pairs,
            mb(rss0, peak),
            r.loss
        );
        fast_results.push((epsilon, ms, r));
    }
    if no_dense {
        return Ok(());
    }
    reset_peak_rss();
    let rss1 = peak_rss();
    let mut dense = SoftRenderer::new(&verts, &scene.triangles);
    let t = Instant::now();
    let dense_res = pass(
        &mut dense,
        &verts,
        &rays,
        &target,
        &scene.occupancy,
        Culling::Dense,
        (&mut grad, &mut d),
    );
    let dense_ms = t.elapsed().as_secs_f64() * 1e3;
    println!(
        "| dense (every ray × every triangle) | {dense_ms:.0} ms | {} | {} | {:.6} |",
        dense_res.pairs,
        mb(rss1, peak_rss()),
        dense_res.loss
    );
    let gmax = dense_res
        .grad
        .iter()
        .map(|g| g.amax())
        .fold(0.0f32, f32::max);
    println!();
    println!(
        "| ε | speed-up vs dense | loss rel. difference | vertex gradient: max difference / max of dense |"
    );
    println!("|---|---|---|---|");
    for (epsilon, ms, r) in &fast_results {
        let gdiff = dense_res
            .grad
            .iter()
            .zip(&r.grad)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0f32, f32::max);
        println!(
            "| {epsilon:.0e} | {:.0}× | {:.2e} | {:.2e} |",
            dense_ms / ms,
            (r.loss - dense_res.loss).abs() / dense_res.loss.abs().max(1e-30),
            f64::from(gdiff / gmax.max(1e-30))
        );
    }
    Ok(())
}
