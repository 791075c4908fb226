//! Soft occupancy: gradients against finite differences (f64), culled vs dense, limits and
//! invariances, and the benchmark scene's hard mask.

use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_render::hard::hard_mask;
use irmirror_render::{
    Aggregation, Culling, OccupancyGrad, OccupancyParams, ReflectedRays, SoftRenderer,
    soft_iou_loss,
};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

type V = Vector3<f64>;

/// A small random scene: a bumpy closed-ish blob of triangles near z = 1 and a 12×10 "image" of
/// rays from around the origin towards it (one ray per pixel; a few pixels without rays).
fn scene(seed: u64) -> (Vec<V>, Vec<[u32; 3]>, ReflectedRays<f64>, Vec<f64>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (nx, ny) = (5, 4);
    let mut verts = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            verts.push(V::new(
                i as f64 * 0.03 - 0.075 + rng.random_range(-0.004..0.004),
                j as f64 * 0.03 - 0.06 + rng.random_range(-0.004..0.004),
                1.0 + rng.random_range(-0.02..0.02),
            ));
        }
    }
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let a = (j * (nx + 1) + i) as u32;
            let (b, c, d) = (a + 1, a + (nx as u32 + 1), a + nx as u32 + 2);
            tris.push([a, b, d]);
            tris.push([a, d, c]);
        }
    }
    let (w, h) = (12u32, 10u32);
    let mut rays = ReflectedRays {
        width: w,
        height: h,
        ..Default::default()
    };
    for p in 0..w * h {
        if p % 17 == 5 {
            continue; // pixels whose camera ray missed the object
        }
        let (x, y) = ((p % w) as f64, (p / w) as f64);
        let o = V::new(
            rng.random_range(-0.01..0.01),
            rng.random_range(-0.01..0.01),
            0.0,
        );
        let aim = V::new((x - 5.5) * 0.02 + 0.0031, (y - 4.5) * 0.02 + 0.0017, 1.0);
        rays.pixel.push(p);
        rays.object.push(0);
        rays.origin.push(o);
        rays.dir.push((aim - o).normalize());
        rays.normal.push(V::z());
    }
    let target: Vec<f64> = (0..w * h)
        .map(|p| {
            if (p % w) > 3 && (p % w) < 10 && (p / w) > 2 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    (verts, tris, rays, target)
}

fn loss(
    verts: &[V],
    tris: &[[u32; 3]],
    rays: &ReflectedRays<f64>,
    target: &[f64],
    p: &OccupancyParams,
    c: Culling,
) -> f64 {
    let r = SoftRenderer::new(verts, tris);
    let occ = r.forward(rays, p, c);
    soft_iou_loss(rays, &occ.value, target, &mut Vec::new())
}

fn loss_and_grad(
    verts: &[V],
    tris: &[[u32; 3]],
    rays: &ReflectedRays<f64>,
    target: &[f64],
    p: &OccupancyParams,
    c: Culling,
) -> (f64, OccupancyGrad<f64>, Vec<f64>) {
    let mut r = SoftRenderer::new(verts, tris);
    let occ = r.forward(rays, p, c);
    let mut d = Vec::new();
    let l = soft_iou_loss(rays, &occ.value, target, &mut d);
    let mut g = OccupancyGrad::default();
    r.backward(rays, &occ, &d, p, c, &mut g);
    (l, g, occ.value)
}

#[test]
fn gradients_match_finite_differences() {
    // σ = (1 cm)² against 3 cm triangles: D is neither saturated nor negligible for most pairs;
    // rays are jittered off edges and vertices, so the closest-point maps are smooth here.
    for (aggregation, culling) in [
        (Aggregation::Product, Culling::Dense),
        (Aggregation::Product, Culling::Bvh),
        (Aggregation::Silhouette, Culling::Dense),
        (Aggregation::Silhouette, Culling::Bvh),
    ] {
        let p = OccupancyParams {
            sigma_m2: 1e-4,
            epsilon: 1e-4,
            aggregation,
        };
        let (verts, tris, rays, target) = scene(1);
        let (l0, g, _) = loss_and_grad(&verts, &tris, &rays, &target, &p, culling);
        assert!(l0 > 0.05 && l0 < 0.95, "loss {l0}");
        let h = 1e-7;
        let mut checked = 0;
        for vi in (0..verts.len()).step_by(3) {
            for k in 0..3 {
                let (mut vp, mut vm) = (verts.clone(), verts.clone());
                vp[vi][k] += h;
                vm[vi][k] -= h;
                let fd = (loss(&vp, &tris, &rays, &target, &p, culling)
                    - loss(&vm, &tris, &rays, &target, &p, culling))
                    / (2.0 * h);
                assert!(
                    (fd - g.vertices[vi][k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "{aggregation:?} {culling:?} vertex {vi}[{k}]: fd {fd} vs {}",
                    g.vertices[vi][k]
                );
                checked += usize::from(fd.abs() > 1e-3);
            }
        }
        assert!(
            checked > 10,
            "{aggregation:?}: too few vertices with a visible gradient ({checked})"
        );
        for i in (0..rays.len()).step_by(7) {
            for k in 0..3 {
                let (mut rp, mut rm) = (rays.clone(), rays.clone());
                rp.origin[i][k] += h;
                rm.origin[i][k] -= h;
                let fd = (loss(&verts, &tris, &rp, &target, &p, culling)
                    - loss(&verts, &tris, &rm, &target, &p, culling))
                    / (2.0 * h);
                assert!(
                    (fd - g.origin[i][k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "origin {i}[{k}]: fd {fd} vs {}",
                    g.origin[i][k]
                );
                let (mut rp, mut rm) = (rays.clone(), rays.clone());
                rp.dir[i][k] += h;
                rm.dir[i][k] -= h;
                let fd = (loss(&verts, &tris, &rp, &target, &p, culling)
                    - loss(&verts, &tris, &rm, &target, &p, culling))
                    / (2.0 * h);
                assert!(
                    (fd - g.dir[i][k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "dir {i}[{k}]: fd {fd} vs {}",
                    g.dir[i][k]
                );
            }
        }
    }
}

#[test]
fn culled_equals_dense_on_random_scenes() {
    for seed in 0..8 {
        let (verts, tris, rays, target) = scene(seed);
        // ε = 1e-7: the culled pairs' total influence is then far below the 1e-5 tolerance.
        let p = OccupancyParams {
            sigma_m2: 4e-5,
            epsilon: 1e-7,
            ..Default::default()
        };
        let (ld, gd, id) = loss_and_grad(&verts, &tris, &rays, &target, &p, Culling::Dense);
        let (lc, gc, ic) = loss_and_grad(&verts, &tris, &rays, &target, &p, Culling::Bvh);
        assert!((ld - lc).abs() < 1e-5, "seed {seed}: loss {ld} vs {lc}");
        let max = gd.vertices.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for (a, b) in gd.vertices.iter().zip(&gc.vertices) {
            assert!(
                (a - b).amax() <= 1e-5 * max.max(1.0),
                "seed {seed}: {a:?} vs {b:?}"
            );
        }
        for (a, b) in id.iter().zip(&ic) {
            assert!((a - b).abs() < 1e-5);
        }
        // With the default ε = 1e-4 every ray's occupancy is within (culled pairs) × ε.
        let p4 = OccupancyParams {
            sigma_m2: 4e-5,
            epsilon: 1e-4,
            ..Default::default()
        };
        let (_, _, id4) = loss_and_grad(&verts, &tris, &rays, &target, &p4, Culling::Dense);
        let (_, _, ic4) = loss_and_grad(&verts, &tris, &rays, &target, &p4, Culling::Bvh);
        for (a, b) in id4.iter().zip(&ic4) {
            assert!((a - b).abs() <= tris.len() as f64 * 1e-4 && b <= a);
        }
        // The silhouette form visits the same elements either way (the cull radius bounds its
        // distances in both): identical.
        let ps = OccupancyParams {
            aggregation: Aggregation::Silhouette,
            ..p4
        };
        let (ld, gd, id) = loss_and_grad(&verts, &tris, &rays, &target, &ps, Culling::Dense);
        let (lc, gc, ic) = loss_and_grad(&verts, &tris, &rays, &target, &ps, Culling::Bvh);
        assert_eq!((ld, id), (lc, ic), "seed {seed}");
        for (a, b) in gd.vertices.iter().zip(&gc.vertices) {
            assert!(
                (a - b).amax() <= 1e-12 * (1.0 + a.amax()),
                "seed {seed}: {a:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn occupancy_is_a_probability_and_tends_to_the_hard_mask() {
    let (verts, tris, rays, _) = scene(3);
    for aggregation in [Aggregation::Product, Aggregation::Silhouette] {
        for sigma in [1e-2, 1e-4, 1e-6] {
            let r = SoftRenderer::new(&verts, &tris);
            let occ = r.forward(
                &rays,
                &OccupancyParams {
                    sigma_m2: sigma,
                    epsilon: 1e-4,
                    aggregation,
                },
                Culling::Bvh,
            );
            assert!(occ.value.iter().all(|&v| (0.0..=1.0).contains(&v)));
        }
        let r = SoftRenderer::new(&verts, &tris);
        let hard = hard_mask(&rays, r.bvh(), &verts, &tris);
        let occ = r.forward(
            &rays,
            &OccupancyParams {
                sigma_m2: 1e-10,
                epsilon: 1e-4,
                aggregation,
            },
            Culling::Bvh,
        );
        let mut n_hit = 0;
        for (i, &v) in occ.value.iter().enumerate() {
            let h = hard[rays.pixel[i] as usize];
            n_hit += usize::from(h);
            assert!(
                (v - if h { 1.0 } else { 0.0 }).abs() < 1e-3,
                "{aggregation:?} ray {i}: soft {v}, hard {h}"
            );
        }
        assert!(n_hit > 10 && n_hit < rays.len() - 10);
    }
}

/// A closed UV sphere (`rings` latitude bands, `segments` longitudes; a vertex ring on the
/// equator when `rings` is even).
fn uv_sphere(centre: V, radius: f64, rings: u32, segments: u32) -> (Vec<V>, Vec<[u32; 3]>) {
    let mut v = vec![centre + V::new(0.0, 0.0, -radius)];
    for i in 1..rings {
        let th =
            std::f64::consts::PI * f64::from(i) / f64::from(rings) - std::f64::consts::FRAC_PI_2;
        for j in 0..segments {
            let ph = std::f64::consts::TAU * f64::from(j) / f64::from(segments);
            v.push(centre + V::new(th.cos() * ph.cos(), th.cos() * ph.sin(), th.sin()) * radius);
        }
    }
    v.push(centre + V::new(0.0, 0.0, radius));
    let top = v.len() as u32 - 1;
    let at = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut t = Vec::new();
    for j in 0..segments {
        t.push([0, at(1, j + 1), at(1, j)]);
        t.push([top, at(rings - 1, j), at(rings - 1, j + 1)]);
        for i in 1..rings - 1 {
            t.push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            t.push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    (v, t)
}

/// Rays along +z from z = −2 through `(x, y)`.
fn parallel_rays(xy: &[(f64, f64)]) -> ReflectedRays<f64> {
    let mut rays = ReflectedRays {
        width: xy.len() as u32,
        height: 1,
        ..Default::default()
    };
    for (p, &(x, y)) in xy.iter().enumerate() {
        rays.pixel.push(p as u32);
        rays.object.push(0);
        rays.origin.push(V::new(x, y, -2.0));
        rays.dir.push(V::z());
        rays.normal.push(V::z());
    }
    rays
}

/// Closed form: parallel rays past a UV sphere seen along its axis. Its silhouette is the
/// equator polygon; on the bisector of an equator edge (distance `h = R cos(π/n)` from the axis)
/// the distance of a ray at radius ρ to the silhouette is |ρ − h|, so the silhouette occupancy
/// is exactly `sigmoid(sign(h − ρ) (ρ − h)²/σ)`: 0.5 on the silhouette. SoftRas' product is
/// above 0.5 outside it (the two faces at the edge both count), and dips inside near edges.
#[test]
fn silhouette_occupancy_is_half_on_a_spheres_outline() {
    let (radius, n) = (0.3, 48u32);
    let (verts, tris) = uv_sphere(V::new(0.0, 0.0, 1.0), radius, 24, n);
    let r = SoftRenderer::new(&verts, &tris);
    let sigma = 1e-4;
    let h = radius * (std::f64::consts::PI / f64::from(n)).cos();
    let phi = std::f64::consts::PI / f64::from(n); // bisector of the edge from segment 0 to 1
    let rho: Vec<f64> = (-30..=30)
        .map(|k| h + f64::from(k) * 1e-3 + 1.3e-5)
        .collect();
    let rays = parallel_rays(
        &rho.iter()
            .map(|&p| (p * phi.cos(), p * phi.sin()))
            .collect::<Vec<_>>(),
    );
    let sil = r.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: sigma,
            epsilon: 1e-7,
            aggregation: Aggregation::Silhouette,
        },
        Culling::Bvh,
    );
    let prod = r.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: sigma,
            epsilon: 1e-7,
            aggregation: Aggregation::Product,
        },
        Culling::Bvh,
    );
    for (k, &p) in rho.iter().enumerate() {
        let x = if p < h {
            (p - h).powi(2) / sigma
        } else {
            -(p - h).powi(2) / sigma
        };
        let expect = 1.0 / (1.0 + (-x).exp());
        assert!(
            (sil.value[k] - expect).abs() < 1e-9,
            "ρ − h = {:.4}: {} vs {expect}",
            p - h,
            sil.value[k]
        );
    }
    // Half a σ^½ outside: the silhouette form is below 0.5 (0.44), the product above it.
    let k = rho
        .iter()
        .position(|&p| p > h + 0.5 * sigma.sqrt())
        .unwrap();
    assert!(
        sil.value[k] < 0.45 && prod.value[k] > 0.55,
        "silhouette {} product {}",
        sil.value[k],
        prod.value[k]
    );
    // Inside, across the mesh's edges and vertices: saturated.
    let inner: Vec<(f64, f64)> = (0..200)
        .map(|k| {
            let (a, p) = (f64::from(k) * 0.0731, 0.2 * f64::from(k) / 200.0);
            (p * a.cos(), p * a.sin())
        })
        .collect();
    let rays = parallel_rays(&inner);
    let sil = r.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: sigma,
            epsilon: 1e-7,
            aggregation: Aggregation::Silhouette,
        },
        Culling::Bvh,
    );
    let prod = r.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: sigma,
            epsilon: 1e-7,
            aggregation: Aggregation::Product,
        },
        Culling::Bvh,
    );
    let min = |v: &[f64]| v.iter().copied().fold(1.0, f64::min);
    assert!(
        min(&sil.value) > 1.0 - 1e-6,
        "silhouette inside: {}",
        min(&sil.value)
    );
    assert!(
        min(&prod.value) < 0.99,
        "the product's dip near edges is expected: {}",
        min(&prod.value)
    );
}

/// A contour behind another part of the mesh is not the silhouette: rays past the outline of a
/// small sphere in front of a large one still hit the large one, and stay saturated.
#[test]
fn hidden_contours_do_not_count() {
    let (mut verts, mut tris) = uv_sphere(V::new(0.0, 0.0, 1.0), 0.3, 24, 48);
    let (v2, t2) = uv_sphere(V::new(0.05, 0.0, 0.5), 0.1, 16, 32);
    let off = verts.len() as u32;
    verts.extend(v2);
    tris.extend(t2.iter().map(|t| t.map(|i| i + off)));
    let r = SoftRenderer::new(&verts, &tris);
    // Around the small sphere's outline, ±1 cm (σ^½).
    let xy: Vec<(f64, f64)> = (0..120)
        .map(|k| {
            let a = f64::from(k) * 0.0523 + 0.01;
            let p = 0.1 + 0.01 * ((f64::from(k) * 0.37).sin());
            (0.05 + p * a.cos(), p * a.sin())
        })
        .collect();
    let rays = parallel_rays(&xy);
    let occ = r.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: 1e-4,
            epsilon: 1e-7,
            aggregation: Aggregation::Silhouette,
        },
        Culling::Bvh,
    );
    let min = occ.value.iter().copied().fold(1.0, f64::min);
    assert!(
        min > 1.0 - 1e-6,
        "a hidden contour lowered the occupancy to {min}"
    );
    // The same rays with the large sphere gone see the small one's silhouette.
    let small = SoftRenderer::new(
        &verts[off as usize..],
        &tris[tris.len() - (tris.len() - 2 * 48 * 23)..]
            .iter()
            .map(|t| t.map(|i| i - off))
            .collect::<Vec<_>>(),
    );
    let occ = small.forward(
        &rays,
        &OccupancyParams {
            sigma_m2: 1e-4,
            epsilon: 1e-7,
            aggregation: Aggregation::Silhouette,
        },
        Culling::Bvh,
    );
    assert!(occ.value.iter().any(|&v| v < 0.4) && occ.value.iter().any(|&v| v > 0.6 && v < 0.999));
}

/// The hitting rays' contour search skips BVH subtrees whose faces (and their neighbours) all
/// face one way along the ray: on two overlapping closed spheres, bumped and then moved (so the
/// normal boxes are refitted, not built), random rays in every direction get exactly the
/// occupancy and the silhouette element that visiting every triangle gives, and the hitting
/// rays visit a small fraction of the triangles within the cull radius (a deep one: none).
#[test]
fn contour_free_subtrees_are_skipped_without_changing_the_silhouette() {
    let (mut verts, mut tris) = uv_sphere(V::new(0.0, 0.0, 1.0), 0.3, 24, 48);
    let (v2, t2) = uv_sphere(V::new(0.05, 0.0, 0.75), 0.12, 16, 32);
    let off = verts.len() as u32;
    verts.extend(v2);
    tris.extend(t2.iter().map(|t| t.map(|i| i + off)));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let built: Vec<V> = verts
        .iter()
        .map(|v| v + (v - V::new(0.0, 0.0, 1.0)) * rng.random_range(-0.01..0.01))
        .collect();
    let rot = axis_angle_to_matrix(&V::new(0.3, -0.5, 0.2));
    let moved: Vec<V> = built
        .iter()
        .map(|v| rot * (v - V::new(0.0, 0.0, 1.0)) + V::new(0.02, -0.03, 1.05))
        .collect();
    let mut r = SoftRenderer::new(&built, &tris);
    r.set_vertices(&moved);
    let mut rays = parallel_rays(&[]);
    for p in 0..400u32 {
        let d = V::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        let aim = V::new(0.02, -0.03, 1.05)
            + V::new(
                rng.random_range(-0.35..0.35),
                rng.random_range(-0.35..0.35),
                rng.random_range(-0.35..0.35),
            );
        rays.pixel.push(p);
        rays.object.push(0);
        rays.origin.push(aim - d * 2.0);
        rays.dir.push(d);
        rays.normal.push(V::z());
    }
    rays.width = 400;
    let p = OccupancyParams {
        sigma_m2: 3e-4,
        epsilon: 1e-7,
        aggregation: Aggregation::Silhouette,
    };
    let pruned = r.forward(&rays, &p, Culling::Bvh);
    let dense = r.forward(&rays, &p, Culling::Dense);
    assert_eq!(pruned.value, dense.value);
    // The same distance to the same kind of element (equidistant ones may swap: a shared vertex).
    let key = |n: &Option<irmirror_render::occupancy::Nearest<f64>>| {
        n.map(|n| (n.pair.pierced, n.pair.d2))
    };
    for (a, b) in pruned.nearest.iter().zip(&dense.nearest) {
        assert_eq!(key(a), key(b));
    }
    // Visits of the hitting rays against a plain query of the cull radius.
    let hard = hard_mask(&rays, r.bvh(), r.vertices(), r.triangles());
    let (mut visited, mut plain, mut hits, mut deep_zero) = (0u64, 0u64, 0, 0);
    for i in 0..rays.len() {
        if !hard[i] {
            continue;
        }
        hits += 1;
        visited += u64::from(pruned.pairs_per_ray[i]);
        let mut n = 0u64;
        r.bvh().for_each_near_ray(
            &rays.origin[i],
            &irmirror_render::bvh::inverse_dir(&rays.dir[i]),
            p.cull_d2().sqrt(),
            |_| n += 1,
        );
        plain += n;
        if pruned.nearest[i].is_none() && pruned.pairs_per_ray[i] == 0 {
            deep_zero += 1;
        }
    }
    assert!(hits > 100, "{hits} hitting rays");
    assert!(
        (visited as f64) < 0.2 * plain as f64 && deep_zero > 10,
        "{visited} triangles visited, {plain} within the cull radius, {deep_zero} of {hits} rays visited none"
    );
}

#[test]
fn rigid_motion_of_mesh_and_rays_leaves_occupancy_unchanged() {
    let (verts, tris, rays, _) = scene(4);
    for p in [
        OccupancyParams::default(),
        OccupancyParams {
            aggregation: Aggregation::Silhouette,
            ..Default::default()
        },
    ] {
        let base = SoftRenderer::new(&verts, &tris)
            .forward(&rays, &p, Culling::Bvh)
            .value;
        let rot = axis_angle_to_matrix(&V::new(0.4, -1.2, 0.3));
        let t = V::new(1.0, -2.0, 0.5);
        let moved: Vec<V> = verts.iter().map(|v| rot * v + t).collect();
        let mut mrays = rays.clone();
        mrays.origin.iter_mut().for_each(|o| *o = rot * *o + t);
        mrays.dir.iter_mut().for_each(|d| *d = rot * *d);
        let after = SoftRenderer::new(&moved, &tris)
            .forward(&mrays, &p, Culling::Bvh)
            .value;
        for (a, b) in base.iter().zip(&after) {
            assert!((a - b).abs() < 1e-9);
        }
    }
}

#[test]
fn refit_after_moving_vertices_matches_a_rebuild() {
    let (verts, tris, rays, target) = scene(5);
    let p = OccupancyParams::default();
    let moved: Vec<V> = verts
        .iter()
        .map(|v| v + V::new(0.02, -0.01, 0.05))
        .collect();
    let mut r = SoftRenderer::new(&verts, &tris);
    r.set_vertices(&moved);
    let refit = r.forward(&rays, &p, Culling::Bvh).value;
    let fresh = SoftRenderer::new(&moved, &tris)
        .forward(&rays, &p, Culling::Bvh)
        .value;
    assert_eq!(refit, fresh);
    let _ = target;
}

#[test]
fn degenerate_triangles_and_grazing_rays_stay_finite() {
    let verts = vec![
        V::new(0.0, 0.0, 1.0),
        V::new(0.0, 0.0, 1.0),
        V::new(0.0, 0.0, 1.0),
        V::new(0.1, 0.0, 1.0),
        V::new(0.2, 0.0, 1.0),
    ];
    let tris = vec![[0, 1, 2], [0, 3, 4], [1, 3, 4]];
    let mut rays = ReflectedRays {
        width: 2,
        height: 1,
        ..Default::default()
    };
    for (p, o, d) in [
        (0u32, V::new(-1.0, 0.0, 1.0), V::new(1.0, 0.0, 0.0)),
        (1, V::new(0.05, 0.0, 0.0), V::new(0.0, 0.0, 1.0)),
    ] {
        rays.pixel.push(p);
        rays.object.push(0);
        rays.origin.push(o);
        rays.dir.push(d);
        rays.normal.push(V::z());
    }
    for p in [
        OccupancyParams::default(),
        OccupancyParams {
            aggregation: Aggregation::Silhouette,
            ..Default::default()
        },
    ] {
        let (l, g, v) = loss_and_grad(&verts, &tris, &rays, &[1.0, 0.0], &p, Culling::Bvh);
        assert!(l.is_finite() && v.iter().all(|x| x.is_finite()));
        assert!(
            g.vertices
                .iter()
                .chain(&g.origin)
                .chain(&g.dir)
                .all(|x| x.iter().all(|c| c.is_finite()))
        );
    }
}

/// The weighted soft IoU: its gradient against central differences (f64), and a weight of 2
/// equals the element counted twice (what importance weights of a stratified sample rely on).
#[test]
fn weighted_soft_iou_gradient_and_duplication() {
    use irmirror_render::soft_iou_weighted;
    let v = [0.9, 0.2, 0.6, 0.05, 0.7];
    let t = [1.0, 0.0, 1.0, 0.0, 0.0];
    let w = [1.0, 3.0, 0.5, 2.0, 1.5];
    let f = |v: &[f64]| soft_iou_weighted(v, |i| t[i], |i| w[i], 0.3, &mut Vec::new()).0;
    let mut d = Vec::new();
    let (l, _) = soft_iou_weighted(&v, |i| t[i], |i| w[i], 0.3, &mut d);
    assert!(l > 0.1 && l < 0.9);
    for k in 0..v.len() {
        let (mut p, mut m) = (v, v);
        p[k] += 1e-6;
        m[k] -= 1e-6;
        let fd = (f(&p) - f(&m)) / 2e-6;
        assert!((fd - d[k]).abs() < 1e-8, "element {k}: {fd} vs {}", d[k]);
    }
    // Weight 2 on element 1 = element 1 listed twice with weight 1.
    let v2 = [0.9f64, 0.2, 0.2, 0.6];
    let t2 = [1.0, 0.0, 0.0, 1.0];
    let w2 = [1.0, 2.0, 0.0, 1.0];
    let a = soft_iou_weighted(&v2[..], |i| t2[i], |i| w2[i], 0.0, &mut Vec::new()).1;
    let b = irmirror_render::soft_iou(&v2[..], |i| t2[i], 0.0, &mut Vec::new()).1;
    assert!((a - b).abs() < 1e-12, "{a} vs {b}");
}
