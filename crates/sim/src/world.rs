//! The scene in the depth-camera frame, ready for ray tracing: SDF objects, the posed body
//! mesh (BVH), a table top, heat sources, and the isothermal room around them.

use crate::SimError;
use crate::scene::{SceneFile, yaw};
use irmirror_body::regions::{Region, triangle_regions, vertex_regions};
use irmirror_body::{BodyModel, Pose};
use irmirror_capture::planck::{ZERO_C_K, band_radiance};
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_geom::{Ray, Rigid3, Similarity3, TriMesh};
use irmirror_render::hard::first_hit;
use irmirror_render::sdf::PlacedSdf;
use irmirror_render::sphere_trace::{SurfaceMethod, TraceParams, trace};
use irmirror_render::{Bvh, reflect::reflect};
use nalgebra::Vector3;

/// What a ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Surface {
    /// Reflecting object k.
    Object(usize),
    /// The person.
    Person {
        /// The surface region hit.
        region: Region,
    },
    /// The table top.
    Table,
    /// Heat source k.
    Heat(usize),
}

/// A ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the unit ray, m.
    pub t_m: f64,
    /// What was hit.
    pub surface: Surface,
    /// Point, depth frame.
    pub point: Vector3<f64>,
    /// Unit normal, depth frame (facing the outside of the surface).
    pub normal: Vector3<f64>,
}

/// Per-object radiometry.
#[derive(Clone, Debug)]
pub struct ObjectRadiometry {
    /// LWIR emissivity.
    pub emissivity: f64,
    /// Band radiance of its temperature.
    pub emitted: f64,
}

/// A horizontal table top in the world frame.
#[derive(Clone, Copy, Debug)]
struct TableTop {
    height_m: f64,
    centre_m: [f64; 2],
    half_size_m: [f64; 2],
    emissivity: f64,
    emitted: f64,
}

/// The traced world (depth frame, metres).
pub struct World {
    /// Depth camera → world.
    pub world_from_depth: Rigid3<f64>,
    /// Objects.
    pub objects: Vec<PlacedSdf>,
    /// Their radiometry.
    pub object_radiometry: Vec<ObjectRadiometry>,
    /// Body mesh, depth frame (empty when the person is left out).
    pub body: TriMesh,
    body_vertices: Vec<Vector3<f64>>,
    body_bvh: Bvh<f64>,
    /// Per body triangle: its region.
    body_region: Vec<Region>,
    table: Option<TableTop>,
    heat: Vec<(Vector3<f64>, f64, f64)>,
    /// Room radiance.
    pub ambient: f64,
    /// Per region ([`Region::ALL`] order): emissivity and band radiance of its temperature.
    person: [(f64, f64); 4],
    trace_params: TraceParams,
}

/// Reflected rays start this far (m) off the surface along the normal, beyond the sphere
/// tracer's tolerance, so they do not hit the surface they leave.
pub const SURFACE_OFFSET_M: f64 = 1e-4;

/// The posed body of a scene in the world frame, with per-vertex dominant bone.
pub struct PlacedBody {
    /// Depth-frame vertices.
    pub mesh: TriMesh,
    /// Joints, depth frame.
    pub joints: Vec<Vector3<f64>>,
    /// Keypoints, depth frame.
    pub keypoints: Vec<Vector3<f64>>,
    /// Shape coefficients.
    pub z: Vec<f64>,
    /// Anny frame → depth frame (the body's placement; the pose translation is the rest root).
    pub depth_from_anny: Rigid3<f64>,
    /// The pose translation used (Anny frame).
    pub anny_translation: Vector3<f64>,
}

/// Poses the scene's person and places them in the depth frame.
pub fn place_body(
    model: &BodyModel,
    scene: &SceneFile,
    depth_from_world: &Rigid3<f64>,
) -> Result<PlacedBody, SimError> {
    let p = &scene.person;
    let z = model.shape_coefficients(&p.phenotype)?;
    let shaped = model.shaped::<f64>(&z)?;
    let pose = Pose::from_axis_angles(&p.rotvec_rad, shaped.joint_heads[0]);
    let posed = model.pose(&shaped, &pose)?;
    let floor = posed
        .vertices
        .iter()
        .map(|v| v.z)
        .fold(f64::INFINITY, f64::min);
    // Stand on the floor at (x, y), turned by yaw about world Z (Anny is Z up like the world).
    let world_from_anny = Rigid3 {
        rotation: yaw(p.yaw_rad),
        translation: Vector3::new(p.position_m[0], p.position_m[1], -floor),
    };
    let depth_from_anny = *depth_from_world * world_from_anny;
    let to_depth = |v: &Vector3<f64>| depth_from_anny.transform_point(v);
    let mut mesh = model.mesh(&posed);
    mesh.vertices = posed
        .vertices
        .iter()
        .map(|v| to_depth(v).map(|x| x as f32).into())
        .collect();
    Ok(PlacedBody {
        mesh,
        joints: posed.joints.iter().map(to_depth).collect(),
        keypoints: posed.keypoints.iter().map(to_depth).collect(),
        z,
        depth_from_anny,
        anny_translation: pose.translation,
    })
}

impl World {
    /// Builds the world of `scene`; `with_person = false` leaves the person out (background
    /// frames).
    pub fn new(
        model: &BodyModel,
        scene: &SceneFile,
        body: Option<&PlacedBody>,
    ) -> Result<Self, SimError> {
        let world_from_depth = scene
            .depth_camera
            .world_from_camera
            .to_rigid()
            .map_err(|e| SimError::Scene(format!("depth_camera.world_from_camera: {e}")))?;
        let depth_from_world = world_from_depth.inverse();
        let mut objects = Vec::new();
        let mut object_radiometry = Vec::new();
        // Object frame (+Y up) → world (+Z up): a quarter turn about X, then the yaw.
        let up = axis_angle_to_matrix(&Vector3::new(std::f64::consts::FRAC_PI_2, 0.0, 0.0));
        for (k, o) in scene.objects.iter().enumerate() {
            if !(o.scale_m > 0.0 && (0.0..=1.0).contains(&o.emissivity)) {
                return Err(SimError::Scene(format!(
                    "objects[{k}]: scale must be positive and emissivity in [0, 1]"
                )));
            }
            if let crate::scene::ObjectShape::Unseen(u) = &o.shape {
                u.check()
                    .map_err(|e| SimError::Scene(format!("objects[{k}]: {e}")))?;
            }
            let rot = yaw(o.yaw_rad) * up;
            let base = Vector3::from(o.base_m);
            let world_from_object = Similarity3::new(
                rot,
                base - rot * Vector3::new(0.0, o.shape.base_y(), 0.0) * o.scale_m,
                o.scale_m,
            )
            .map_err(|e| SimError::Scene(format!("objects[{k}]: {e}")))?;
            let depth_from_object = Similarity3 {
                rotation: depth_from_world.rotation,
                translation: depth_from_world.translation,
                scale: 1.0,
            } * world_from_object;
            objects.push(PlacedSdf {
                sdf: o.shape.sdf(),
                depth_from_object,
            });
            object_radiometry.push(ObjectRadiometry {
                emissivity: o.emissivity,
                emitted: band_radiance(o.temp_c + ZERO_C_K),
            });
        }
        let (body_mesh, body_vertices, body_bvh, body_region) = match body {
            Some(b) => {
                let v: Vec<Vector3<f64>> = b
                    .mesh
                    .vertices
                    .iter()
                    .map(|p| Vector3::from(p.map(f64::from)))
                    .collect();
                let bvh = Bvh::build(&v, &b.mesh.triangles);
                let regions = triangle_regions(&vertex_regions(model)?, &b.mesh.triangles);
                (b.mesh.clone(), v, bvh, regions)
            }
            None => (TriMesh::default(), vec![], Bvh::build(&[], &[]), vec![]),
        };
        let p = &scene.person;
        let table = scene.table.as_ref().map(|t| TableTop {
            height_m: t.height_m,
            centre_m: t.centre_m,
            half_size_m: [t.size_m[0] / 2.0, t.size_m[1] / 2.0],
            emissivity: t.emissivity,
            emitted: band_radiance(t.temp_c + ZERO_C_K),
        });
        Ok(Self {
            world_from_depth,
            objects,
            object_radiometry,
            body: body_mesh,
            body_vertices,
            body_bvh,
            body_region,
            table,
            heat: scene
                .heat_sources
                .iter()
                .map(|h| {
                    (
                        depth_from_world.transform_point(&Vector3::from(h.centre_m)),
                        h.radius_m,
                        band_radiance(h.temp_c + ZERO_C_K),
                    )
                })
                .collect(),
            ambient: band_radiance(scene.ambient_c + ZERO_C_K),
            person: Region::ALL.map(|r| {
                let (temp_c, emissivity) = p.region_temperature(r);
                (emissivity, band_radiance(temp_c + ZERO_C_K))
            }),
            trace_params: TraceParams {
                coarse_tol_rel: 1e-5,
                method: SurfaceMethod::SphereTrace { steps: 3 },
                max_iters: 2048,
            },
        })
    }

    /// The nearest surface along a unit ray (depth frame), or `None` (the room).
    pub fn hit(&self, ray: &Ray<f64>) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut consider = |h: Hit| {
            if h.t_m > 1e-6 && best.is_none_or(|b| h.t_m < b.t_m) {
                best = Some(h);
            }
        };
        for (k, o) in self.objects.iter().enumerate() {
            if let Some(h) = trace(o, ray, &self.trace_params) {
                let t = (h.point - ray.origin).dot(&ray.dir);
                consider(Hit {
                    t_m: t,
                    surface: Surface::Object(k),
                    point: h.point,
                    normal: h.normal,
                });
            }
        }
        if let Some((t, tri)) = first_hit(
            &self.body_bvh,
            &self.body_vertices,
            &self.body.triangles,
            &ray.origin,
            &ray.dir,
        ) {
            let [a, b, c] =
                self.body.triangles[tri as usize].map(|v| self.body_vertices[v as usize]);
            let mut n = (b - a).cross(&(c - a)).normalize();
            if n.dot(&ray.dir) > 0.0 {
                n = -n;
            }
            consider(Hit {
                t_m: t,
                surface: Surface::Person {
                    region: self.body_region[tri as usize],
                },
                point: ray.at(t),
                normal: n,
            });
        }
        if let Some(TableTop {
            height_m: h,
            centre_m: c,
            half_size_m: half,
            ..
        }) = self.table
        {
            let o = self.world_from_depth.transform_point(&ray.origin);
            let d = self.world_from_depth.transform_vector(&ray.dir);
            if d.z.abs() > 1e-12 {
                let t = (h - o.z) / d.z;
                let p = o + d * t;
                if t > 0.0 && (p.x - c[0]).abs() <= half[0] && (p.y - c[1]).abs() <= half[1] {
                    let up = self.world_from_depth.rotation.tr_mul(&Vector3::z());
                    consider(Hit {
                        t_m: t,
                        surface: Surface::Table,
                        point: ray.at(t),
                        normal: if up.dot(&ray.dir) < 0.0 { up } else { -up },
                    });
                }
            }
        }
        for (k, (c, r, _)) in self.heat.iter().enumerate() {
            let oc = ray.origin - c;
            let b = oc.dot(&ray.dir);
            let disc = b * b - (oc.norm_squared() - r * r);
            if disc >= 0.0 {
                let t = -b - disc.sqrt();
                let p = ray.at(t);
                consider(Hit {
                    t_m: t,
                    surface: Surface::Heat(k),
                    point: p,
                    normal: (p - c) / *r,
                });
            }
        }
        best
    }

    /// Band radiance arriving along `ray` (W m⁻² sr⁻¹): emission plus mirror reflection for the
    /// objects (`bounces` deep), emission plus the room's reflection for diffuse surfaces.
    pub fn radiance(&self, ray: &Ray<f64>, bounces: u32) -> f64 {
        let Some(h) = self.hit(ray) else {
            return self.ambient;
        };
        let grey = |(e, l): (f64, f64)| e * l + (1.0 - e) * self.ambient;
        match h.surface {
            Surface::Object(k) => {
                let r = &self.object_radiometry[k];
                let reflected = if bounces > 0 {
                    let dir = reflect(&ray.dir, &h.normal).normalize();
                    self.radiance(
                        &Ray {
                            origin: h.point + h.normal * SURFACE_OFFSET_M,
                            dir,
                        },
                        bounces - 1,
                    )
                } else {
                    self.ambient
                };
                r.emissivity * r.emitted + (1.0 - r.emissivity) * reflected
            }
            Surface::Person { region } => grey(self.person[region.index()]),
            Surface::Table => {
                let t = self.table.expect("hit implies a table");
                grey((t.emissivity, t.emitted))
            }
            Surface::Heat(k) => self.heat[k].2,
        }
    }
}
