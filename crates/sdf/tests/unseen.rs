//! Out-of-family shapes: closed, outward, on their base, and fields a sphere tracer may trust.

use irmirror_sdf::mesh_io::open_edges;
use irmirror_sdf::unseen::{CarKind, HandleKind, UnseenShape};
use irmirror_sdf::{Category, FamilyShape};
use nalgebra::Vector3;
use rand::Rng;

fn shapes(category: Category, n: u64) -> Vec<UnseenShape> {
    (0..n)
        .map(|seed| {
            let mut rng = irmirror_geom::rng::seeded(seed, 7);
            UnseenShape::sample(category, &mut rng).unwrap()
        })
        .collect()
}

#[test]
fn unseen_meshes_are_closed_outward_and_stand_on_their_base() {
    // IRMIRROR_DUMP_UNSEEN=DIR: write 8 of each as OBJ there, to look at.
    let dump = std::env::var("IRMIRROR_DUMP_UNSEEN").ok();
    for cat in Category::LEARNED {
        for shape in shapes(cat, if dump.is_some() { 8 } else { 4 }) {
            let mesh = shape.mesh(64);
            if let Some(dir) = &dump {
                let n = std::fs::read_dir(dir).map_or(0, |d| d.count());
                mesh.write(&std::path::Path::new(&dir).join(format!("{cat}_{n}.obj")))
                    .unwrap();
            }
            assert_eq!(open_edges(&mesh), 0, "{shape:?}: open edges");
            assert!(mesh.signed_volume() > 0.0, "{shape:?}: inward or empty");
            let prepared = shape.prepare();
            let (lo, hi) = shape.raw_bounds();
            let (c, k) = shape.normalisation();
            let (mut y_min, mut box_lo, mut box_hi) = (
                f64::INFINITY,
                Vector3::repeat(f64::INFINITY),
                -Vector3::repeat(f64::INFINITY),
            );
            for v in &mesh.vertices {
                let p = Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
                assert!(p.norm() < 1.0, "{shape:?}: vertex outside the unit sphere");
                assert!(
                    prepared.distance(&p).abs() < 0.02,
                    "{shape:?}: vertex off the surface by {}",
                    prepared.distance(&p)
                );
                y_min = y_min.min(p.y);
                box_lo = box_lo.inf(&(c + p * k));
                box_hi = box_hi.sup(&(c + p * k));
            }
            // The simulator stands an object on its bounds' bottom: the surface must reach it.
            let cell = 2.0 / 64.0;
            assert!(
                (y_min - (lo.y - c.y) / k).abs() < 1.5 * cell,
                "{shape:?}: lowest vertex {y_min}, base {}",
                (lo.y - c.y) / k
            );
            // The bounds hold the surface, and not much more (the normalisation is honest).
            let slack = (hi - lo).norm() * 0.03;
            for i in 0..3 {
                assert!(
                    box_lo[i] >= lo[i] - slack && box_hi[i] <= hi[i] + slack,
                    "{shape:?}"
                );
                assert!(
                    box_hi[i] - box_lo[i] > 0.8 * (hi[i] - lo[i]),
                    "{shape:?}: axis {i}"
                );
            }
        }
    }
}

#[test]
fn unseen_fields_are_one_lipschitz() {
    let mut rng = irmirror_geom::rng::seeded(3, 0);
    for cat in Category::LEARNED {
        for shape in shapes(cat, 6) {
            let f = shape.prepare();
            let mut worst: f64 = 0.0;
            for _ in 0..4000 {
                let a = Vector3::from_fn(|_, _| rng.random_range(-0.95..0.95));
                let step = Vector3::from_fn(|_, _| rng.random_range(-0.05..0.05));
                let b = a + step;
                worst = worst.max((f.distance(&a) - f.distance(&b)).abs() / step.norm());
            }
            assert!(worst <= 1.0 + 1e-6, "{shape:?}: slope {worst}");
            // …and not so shrunk that tracing crawls.
            assert!(worst > 0.5, "{shape:?}: slope at most {worst}");
        }
    }
}

#[test]
fn the_draws_cover_every_kind_and_round_trip_as_tables() {
    let bowls = shapes(Category::Bowl, 16);
    let mugs = shapes(Category::Mug, 16);
    let cars = shapes(Category::Car, 16);
    let sides = |s: &UnseenShape| matches!(s, UnseenShape::Bowl(b) if b.sides > 0);
    assert!(bowls.iter().any(sides) && !bowls.iter().all(sides));
    for kind in [HandleKind::Loop, HandleKind::Ring] {
        assert!(
            mugs.iter()
                .any(|s| matches!(s, UnseenShape::Mug(m) if m.handle == kind))
        );
    }
    for style in [CarKind::Coupe, CarKind::Van, CarKind::Pickup] {
        assert!(
            cars.iter()
                .any(|s| matches!(s, UnseenShape::Car(c) if c.style == style))
        );
    }
    for s in bowls.iter().chain(&mugs).chain(&cars) {
        s.check().unwrap();
        let json = serde_json::to_string(s).unwrap();
        let back: UnseenShape = serde_json::from_str(&json).unwrap();
        assert_eq!(back.category(), s.category());
        // (serde_json's float parsing may move the last bit.)
        assert!((back.raw_half_size() - s.raw_half_size()).abs() < 1e-12);
        // Not mistaken for a family member, nor a family member for one of these.
        assert!(
            serde_json::from_str::<FamilyShape>(&json).is_err(),
            "{json}"
        );
    }
    let mut rng = irmirror_geom::rng::seeded(0, 1);
    let family = serde_json::to_string(&FamilyShape::sample(Category::Mug, &mut rng).unwrap());
    assert!(serde_json::from_str::<UnseenShape>(&family.unwrap()).is_err());
    assert!(UnseenShape::sample(Category::Sphere, &mut rng).is_err());
    // Out-of-range or non-finite parameters are named.
    if let UnseenShape::Bowl(mut b) = bowls[0] {
        b.sides = 3;
        let err = UnseenShape::Bowl(b).check().unwrap_err().to_string();
        assert!(err.contains("sides = 3"), "{err}");
        (b.sides, b.rim_wall) = (0, f64::NAN);
        let err = UnseenShape::Bowl(b).check().unwrap_err().to_string();
        assert!(err.contains("rim_wall"), "{err}");
    }
}
