//! Fitting a learned prior's latent and placement together to depth points.

use irmirror_geom::Similarity3;
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_sdf::placed::{
    PlacedFitConfig, PlacedObservation, PlacementOffset, best_start, fit_placed, loss_and_gradient,
};
use irmirror_sdf::{Category, FamilyShape, SdfNet};
use nalgebra::Vector3;

fn prior(cat: Category) -> SdfNet {
    let dir = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../assets/object_priors"
    ));
    SdfNet::load(&dir.join(format!("{}.safetensors", cat.name()))).unwrap()
}

/// A family member placed in a depth frame: its mesh vertices, points 2 % of the size outside
/// along the normals, the true placement.
fn observed(cat: Category, seed: u64) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>, Similarity3<f64>) {
    let shape = FamilyShape::sample(cat, &mut irmirror_geom::rng::seeded(seed, 77)).unwrap();
    let prepared = shape.prepare();
    let mesh = shape.mesh(40);
    let truth = Similarity3 {
        rotation: axis_angle_to_matrix(&Vector3::new(-1.9, 0.3, 0.2)),
        translation: Vector3::new(0.05, -0.02, 0.6),
        scale: 0.1,
    };
    let (mut surface, mut free) = (Vec::new(), Vec::new());
    for v in mesh.vertices.iter().step_by(3) {
        let q = Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
        surface.push(truth.transform_point(&q));
        let n = irmirror_render::sdf::Sdf::gradient(&prepared, &q).normalize();
        free.push(truth.transform_point(&(q + n * 0.02)));
    }
    (surface, free, truth)
}

#[test]
fn placed_fit_gradients_match_finite_differences() {
    let net = prior(Category::Mug);
    let (surface, free, truth) = observed(Category::Mug, 3);
    let (surface, free) = (&surface[..60], &free[..60]);
    let up = truth.rotation * Vector3::y();
    let inside: Vec<Vector3<f64>> = surface
        .iter()
        .map(|p| p + (p - truth.translation).normalize() * -0.001)
        .collect();
    // Off the truth so that every term is active (Huber in both branches, hinges on).
    let init = Similarity3 {
        rotation: truth.rotation * axis_angle_to_matrix(&Vector3::new(0.1, -0.05, 0.08)),
        translation: truth.translation + Vector3::new(0.004, -0.003, 0.002),
        scale: 0.11,
    };
    let z: Vec<f64> = net
        .mean_latent()
        .iter()
        .enumerate()
        .map(|(i, v)| v + 0.01 * ((i as f64) * 0.7).sin())
        .collect();
    let (delta, tau, log_s) = (
        Vector3::new(0.01, -0.02, 0.015),
        Vector3::new(0.02, 0.01, -0.03),
        0.05f64,
    );
    // Support points: a grid in the normalised frame, half inside the shape at this state (the
    // hinge is active there), half outside, placed by the state's own M = R₀ (I + [δ]×).
    let field = std::sync::Arc::new(net.clone()).shape(&z).unwrap();
    let m = init.rotation * (nalgebra::Matrix3::identity() + delta.cross_matrix());
    let (t, s) = (init.translation + tau * 0.1, init.scale * log_s.exp());
    let grid = (0..729).map(|i| {
        Vector3::new((i % 9) as f64, (i / 9 % 9) as f64, (i / 81) as f64) * 0.2
            - Vector3::repeat(0.8)
    });
    let (inner, outer): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) =
        grid.partition(|q| field.value_grad(q).0 < 0.0);
    let support: Vec<Vector3<f64>> = inner
        .iter()
        .take(10)
        .chain(outer.iter().take(10))
        .map(|q| t + m.transpose().try_inverse().unwrap() * q * s)
        .collect();
    assert!(inner.len() >= 10, "the grid should reach inside the mug");
    let obs = PlacedObservation {
        surface,
        free,
        inside: &inside,
        support: &support,
        up: Some((up + Vector3::new(0.05, 0.0, 0.0)).normalize()),
        unit_m: 0.1,
        scale_prior: Some((0.1f64.ln(), 0.1)),
    };
    let cfg = PlacedFitConfig::default();
    let offset = PlacementOffset { delta, tau, log_s };
    let (loss, grad) = loss_and_gradient(&net, &obs, &init, &z, &offset, &cfg).unwrap();
    assert!(loss > 0.0);
    let no_support = loss_and_gradient(
        &net,
        &PlacedObservation {
            support: &[],
            ..obs
        },
        &init,
        &z,
        &offset,
        &cfg,
    )
    .unwrap()
    .0;
    assert!(
        loss > no_support + 1e-4,
        "the support hinge is not active: {loss} vs {no_support}"
    );
    let l = z.len();
    let h = 1e-6;
    for k in (0..l).step_by(5).chain(l..l + 7) {
        let eval = |sign: f64| {
            let (mut z, mut d, mut t, mut s) = (z.clone(), delta, tau, log_s);
            match k {
                k if k < l => z[k] += sign * h,
                k if k < l + 3 => d[k - l] += sign * h,
                k if k < l + 6 => t[k - l - 3] += sign * h,
                _ => s += sign * h,
            }
            let offset = PlacementOffset {
                delta: d,
                tau: t,
                log_s: s,
            };
            loss_and_gradient(&net, &obs, &init, &z, &offset, &cfg)
                .unwrap()
                .0
        };
        let fd = (eval(1.0) - eval(-1.0)) / (2.0 * h);
        assert!(
            (fd - grad[k]).abs() < 1e-6 * (1.0 + fd.abs()),
            "parameter {k}: autodiff {} vs finite differences {fd}",
            grad[k]
        );
    }
    // The placement gradient is not trivially zero.
    assert!(grad[l..].iter().map(|g| g.abs()).sum::<f64>() > 1e-3);
}

#[test]
fn placed_fit_recovers_shape_and_placement_from_a_perturbed_start() {
    // Shapes the prior represents exactly (training latents), seen from every side: the test is
    // about the optimiser; `irmirror bench objects --shapes family --prior learned` measures
    // held-out shapes seen by a depth camera. Several latents: the 9,000-step mug prior's latent
    // space is less smooth than the 3,000-step one's, and from the mean latent the fixed
    // schedule ends close on most shapes but not all (measured on latents 3, 7, 11, 20, 30:
    // latent 3 2.2° off with Chamfer 0.19 mm², latent 7 0.9° with 3.8 mm², the rest within
    // 1° and 1 mm²).
    let net = std::sync::Arc::new(prior(Category::Mug));
    let mut close = 0;
    for index in [3, 7, 11, 20, 30] {
        let z_true = net.train_latents[index].clone();
        let true_shape = net.shape(&z_true).unwrap();
        let mesh = irmirror_sdf::quality::extract_mesh(&net, &z_true, 72).unwrap();
        let truth = Similarity3 {
            rotation: axis_angle_to_matrix(&Vector3::new(-1.9, 0.3, 0.2)),
            translation: Vector3::new(0.05, -0.02, 0.6),
            scale: 0.1,
        };
        let (mut surface, mut free, mut inside) = (Vec::new(), Vec::new(), Vec::new());
        for v in mesh.vertices.iter().step_by(3) {
            let q = Vector3::from(v.map(f64::from));
            let n = true_shape.value_grad(&q).1.normalize();
            surface.push(truth.transform_point(&q));
            free.push(truth.transform_point(&(q + n * 0.02)));
            inside.push(truth.transform_point(&(q - n * 0.005)));
        }
        let up = truth.rotation * Vector3::y();
        let obs = PlacedObservation {
            surface: &surface,
            free: &free,
            inside: &inside,
            support: &[],
            up: Some(up),
            unit_m: truth.scale,
            scale_prior: None,
        };
        // 5 % of the size off, 5° about the up axis, 5 % scale, the mean latent.
        let init = Similarity3 {
            rotation: axis_angle_to_matrix(&(up * 5f64.to_radians())) * truth.rotation,
            translation: truth.translation + Vector3::new(0.004, -0.003, 0.002),
            scale: truth.scale * 1.05,
        };
        let fit = fit_placed(
            &net,
            &obs,
            &init,
            &net.mean_latent(),
            &PlacedFitConfig::default(),
        )
        .unwrap();
        let f = &fit.depth_from_object;
        // A latent can absorb a little scale and shift (the frame is not unique): compare metric
        // surfaces (Chamfer) and the axes, not the frames' origins.
        let fitted = irmirror_sdf::quality::extract_mesh(&net, &fit.latent, 72)
            .unwrap()
            .main_components(irmirror_sdf::quality::MAIN_PART_FRACTION);
        let dr = (((f.rotation * truth.rotation.transpose()).trace() - 1.0) * 0.5)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let shape = net.shape(&fit.latent).unwrap();
        let mean_err = surface
            .iter()
            .map(|p| (shape.value_grad(&f.inverse_transform_point(p)).0 * f.scale).abs())
            .sum::<f64>()
            / surface.len() as f64;
        let in_depth = |m: &irmirror_geom::TriMesh, s: &Similarity3<f64>| {
            let mut m = m.clone();
            m.map_vertices(|v| {
                s.transform_point(&Vector3::from(v.map(f64::from)))
                    .map(|x| x as f32)
                    .into()
            });
            m
        };
        let chamfer_mm2 = irmirror_sdf::quality::chamfer(
            &in_depth(&fitted, f),
            &in_depth(&mesh, &truth),
            4000,
            0,
        ) * 1e6;
        eprintln!(
            "latent {index}: rotation {dr:.2}°, mean surface distance {:.2} mm, Chamfer {chamfer_mm2:.3} mm², loss {:.4} → {:.4}",
            mean_err * 1e3,
            fit.curve[0],
            fit.loss
        );
        assert!(
            fit.loss < 0.1 * fit.curve[0],
            "latent {index}: the loss fell"
        );
        assert!(
            dr < 3.0 && chamfer_mm2 < 5.0 && mean_err < 0.001,
            "latent {index}: {dr}°, Chamfer {chamfer_mm2} mm², surface {mean_err} m on a 0.1 m-unit mug"
        );
        close += usize::from(dr < 1.0 && chamfer_mm2 < 1.0 && mean_err < 0.0005);
    }
    assert!(
        close >= 3,
        "only {close} of 5 shapes recovered to 1° and 1 mm²"
    );
}

#[test]
fn placed_fit_refuses_bad_input_clearly() {
    let net = prior(Category::Bowl);
    let init = Similarity3 {
        rotation: nalgebra::Matrix3::identity(),
        translation: Vector3::new(0.0, 0.0, 0.6),
        scale: 0.1,
    };
    fn obs(surface: &[Vector3<f64>], unit_m: f64) -> PlacedObservation<'_> {
        PlacedObservation {
            surface,
            free: &[],
            inside: &[],
            support: &[],
            up: None,
            unit_m,
            scale_prior: None,
        }
    }
    let cfg = PlacedFitConfig {
        latent_steps: 1,
        steps: 1,
        ..Default::default()
    };
    let z = net.mean_latent();
    let msg = |o: PlacedObservation, z: &[f64]| {
        fit_placed(&net, &o, &init, z, &cfg)
            .unwrap_err()
            .to_string()
    };
    let (good, nan) = (
        [Vector3::new(0.0, 0.0, 0.55)],
        [Vector3::new(f64::NAN, 0.0, 0.5)],
    );
    assert!(msg(obs(&[], 0.1), &z).contains("needs surface points"));
    assert!(msg(obs(&nan, 0.1), &z).contains("not finite"));
    assert!(msg(obs(&good, 0.0), &z).contains("must be positive"));
    assert!(msg(obs(&good, 0.1), &z[..3]).contains("latent of length 3"));
    assert!(fit_placed(&net, &obs(&good, 0.1), &init, &z, &cfg).is_ok());
}

/// The start screening picks the training code whose own surface was observed, among the mean
/// latent and the first 16 codes, wherever that code sits in the list; no candidates, or one of
/// the wrong length, is an error.
#[test]
fn best_start_finds_the_observed_training_shape() {
    let net = prior(Category::Bowl);
    let place = Similarity3 {
        rotation: axis_angle_to_matrix(&Vector3::new(-1.7, 0.2, 0.1)),
        translation: Vector3::new(0.03, 0.02, 0.5),
        scale: 0.08,
    };
    let mut candidates = vec![net.mean_latent()];
    candidates.extend(net.train_latents.iter().take(16).cloned());
    for k in [3, 11] {
        let z = &net.train_latents[k];
        let mesh = irmirror_sdf::quality::extract_mesh(&net, z, 32).unwrap();
        let (mut surface, mut free) = (Vec::new(), Vec::new());
        for v in mesh.vertices.iter().step_by(2) {
            let q = Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            let n = net.eval_full(z, &q).2.normalize();
            surface.push(place.transform_point(&q));
            free.push(place.transform_point(&(q + n * 0.05)));
        }
        let obs = PlacedObservation {
            surface: &surface,
            free: &free,
            inside: &[],
            support: &[],
            up: None,
            unit_m: 0.08,
            scale_prior: None,
        };
        let cfg = PlacedFitConfig::default();
        let best = best_start(&net, &obs, &place, &candidates, &cfg).unwrap();
        assert_eq!(best, k + 1, "code {k}: picked candidate {best}");
        assert!(best_start(&net, &obs, &place, &[], &cfg).is_err());
        let short = vec![candidates[0].clone(), vec![0.0; 3]];
        assert!(best_start(&net, &obs, &place, &short, &cfg).is_err());
    }
}
