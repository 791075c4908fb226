//! Stage 2 on simulated captures.

use irmirror_body::BodyModel;
use irmirror_body::prior::PosePrior;
use irmirror_capture::Capture;
use irmirror_recon::pipeline::{Quiet, ReconConfig, reconstruct};
use irmirror_sim::presets::{Preset, preset_scene};
use irmirror_sim::scene::{SceneFile, ThermalPreset};
use irmirror_sim::simulate;
use std::sync::OnceLock;

fn model() -> &'static BodyModel {
    static M: OnceLock<BodyModel> = OnceLock::new();
    M.get_or_init(|| BodyModel::builtin().unwrap())
}

fn prior() -> &'static PosePrior {
    static P: OnceLock<PosePrior> = OnceLock::new();
    P.get_or_init(|| PosePrior::builtin(candle_core::DType::F64).unwrap())
}

fn scene(seed: u64, is_car: bool) -> SceneFile {
    let p = if is_car { Preset::Car } else { Preset::Tabletop };
    let t = if std::env::var("BOSON").is_ok() { ThermalPreset::Boson } else { ThermalPreset::Lepton };
    preset_scene(model(), p, t, seed).unwrap()
}

#[test]
#[ignore = "exploration"]
fn explore() {
    for (seed, is_car) in [(0, false), (1, false), (2, false), (0, true), (1, true)] {
        let sc = scene(seed, is_car);
        let dir = std::env::temp_dir().join(format!("irmirror-human-{}-{seed}-{is_car}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        let sim = simulate(model(), &sc, seed).unwrap();
        sim.write(model(), &dir, seed).unwrap();
        let cap = Capture::load(&dir).unwrap();
        let t0 = std::time::Instant::now();
        let r = reconstruct(&cap, model(), prior(), &ReconConfig::default(), seed, &Quiet);
        let dt = t0.elapsed().as_secs_f64();
        match r {
            Ok(r) => {
                let root = sim.body.joints[0];
                {
                    use irmirror_recon::human::*;
                    let rv = &sc.person.rotvec_rad;
                    let r0 = sim.body.depth_from_anny.rotation * irmirror_geom::rotation::axis_angle_to_matrix(&nalgebra::Vector3::from(rv[0]));
                    let truth = HumanState { translation: root, rotation: r0, latent: prior().encode(rv).unwrap() };
                    let placed = r.objects.placed();
                    let centre = placed[0].depth_from_object.translation;
                    let pb = HumanProblem { model: model(), prior: prior(), rays: &r.rays, mask: &r.pre.mask, up: r.objects.plane.n(), objects_centre: centre };
                    let cfg = HumanConfig::default();
                    eprintln!("  truth loss {:?}", pb.full_loss(&truth, 1e-4, cfg.w_prior, cfg.w_upright).unwrap());
                    let ed = edge_distance(&r.pre.mask);
                    let (st, curve) = pb.run(&truth, &cfg, &ed, 1).unwrap().unwrap();
                    eprintln!("  from truth: loss {:?} root err {:.3} curve {:.3?}", pb.full_loss(&st, 1e-4, cfg.w_prior, cfg.w_upright).unwrap(), (st.translation - root).norm(), curve.iter().step_by(20).collect::<Vec<_>>());
                    let true_objs: Vec<irmirror_render::sdf::PlacedSdf> = sc.objects.iter().zip(&sim.object_poses).map(|(o, p)| irmirror_render::sdf::PlacedSdf { sdf: o.shape.sdf(), depth_from_object: *p }).collect();
                    let rays = irmirror_render::reflect::reflect_camera(&cap.thermal_camera, &cap.depth_from_thermal, &true_objs, &Default::default(), irmirror_render::reflect::Normals::Raw);
                    let rays = irmirror_recon::pipeline::unblocked(&rays, &true_objs, &r.objects.plane, &Default::default());
                    let pb2 = HumanProblem { rays: &rays, mask: &sim.reflection_mask, ..pb };
                    eprintln!("  truth loss with true objects and mask {:?}", pb2.full_loss(&truth, 1e-4, cfg.w_prior, cfg.w_upright).unwrap());
                    let iou_of = |verts: &[nalgebra::Vector3<f64>]| {
                        let rr = irmirror_render::occupancy::SoftRenderer::new(verts, &model().asset.faces);
                        let hm = irmirror_render::hard::hard_mask(&rays, rr.bvh(), verts, &model().asset.faces);
                        let img = hm;
                        let tm = &sim.reflection_mask;
                        let inter = tm.data.iter().zip(&img).filter(|(a, b)| **a && **b).count();
                        let uni = tm.data.iter().zip(&img).filter(|(a, b)| **a || **b).count();
                        (inter, uni)
                    };
                    let simv: Vec<nalgebra::Vector3<f64>> = sim.body.mesh.vertices.iter().map(|v| nalgebra::Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)).collect();
                    eprintln!("  hard IoU sim mesh {:?}", iou_of(&simv));
                    let shaped = model().shaped::<f64>(&vec![0.0; model().rank()]).unwrap();
                    let posed = model().pose(&shaped, &pb.pose(&truth).unwrap()).unwrap();
                    eprintln!("  hard IoU truth-state mean-shape mesh {:?}", iou_of(&posed.vertices));
                    let shaped2 = model().shaped::<f64>(&sim.body.z).unwrap();
                    let posed2 = model().pose(&shaped2, &pb.pose(&truth).unwrap()).unwrap();
                    eprintln!("  hard IoU truth-state true-shape mesh {:?}", iou_of(&posed2.vertices));
                    // True mask IoU vs stage-0 mask.
                    let tm = &sim.reflection_mask;
                    let inter = tm.data.iter().zip(&r.pre.mask.data).filter(|(a, b)| **a && **b).count();
                    let uni = tm.data.iter().zip(&r.pre.mask.data).filter(|(a, b)| **a || **b).count();
                    eprintln!("  stage0 mask IoU {inter}/{uni}");
                }
                for h in &r.human.hypotheses {
                    let t = nalgebra::Vector3::from(h.translation_m);
                    eprintln!("seed {seed} car {is_car}: init {} loss {:.3} iou {:.3} root err {:.3} m (dist {:.2}) rays {} mask {} {dt:.1}s", h.init, h.loss, h.soft_iou, (t - root).norm(), root.norm(), r.human.rays, r.human.mask_rays);
                }
            }
            Err(e) => eprintln!("seed {seed} car {is_car}: {e}"),
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
