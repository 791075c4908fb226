//! Stage 1 (paper §3.5 "3D object reconstruction", DESIGN.md §1): per object, the similarity
//! `depth_from_object` (R, t, s) and the shape parameters of its category's prior, fitted to the
//! depth points inside its mask.
//!
//! The prior is the procedural family of [`irmirror_render::shapes`] (2 parameters per
//! category); with [`ObjectPrior::Learned`] the category's learned DeepSDF prior then takes over
//! from that fit ([`fit_learned`]: latent and placement together).
//!
//! Loss (all distances in units of the initial object size `s₀`, so one schedule fits a mug and
//! a car):
//! * `L_depth` — two forms. Rendered: a subsample of the depth pixels' camera rays is
//!   sphere-traced into the current object and the hit distance compared with the measured one
//!   (Huber, i.e. L1 beyond 3 mm), differentiated by the implicit function theorem at the hit
//!   (`dt/dθ = −(∂F/∂θ)/(∇F·r)`); grazing rays are skipped. Point form: Huber of the signed
//!   distance of every observed point (zero exactly when the surface passes through the measured
//!   depth; smooth where rays miss the current object, so it pulls from afar). The rendered form
//!   removed a 2–3 mm bias of the point form alone (20 seeds: bowl translation median 2.4 →
//!   0.3 mm, mug scale max 11 → 1.6 %; `irmirror bench objects`). Its weight is 0.3: at 1 the
//!   car's door (mean point residual 2.6 mm, the depth noise at 1.5–2.5 m) fitted worse across
//!   its length (≤ 9 → 28 mm over 4 seeds);
//! * `L_mask` — free space: points just in front of the observed surface, and points along the
//!   rays of a ring of pixels around the mask (where the depth camera saw past the object), must
//!   lie outside (hinge on `−d`): this is what keeps the silhouette from growing;
//! * `L_prior` — the object stands upright on the support plane: `‖R ŷ − n‖²` and the base's
//!   height above the plane squared; for categories whose size the view cannot fix (a car's
//!   side fills the image), a log-normal prior on the metric size.
//!
//! Optimiser: Adam on (rotation tangent δ, t, log s, shape u ∈ [0,1]²), learning rates decaying
//! by cosine to 5 %, `iterations` steps from each restart (yaws evenly spread about the plane
//! normal; eight for a mug, whose handle's side is otherwise often missed) × two starting
//! proportions, each run's best iterate kept, the best run kept. Rotation and translation
//! gradients are analytic (chain rule through the SDF gradient); shape gradients are central
//! differences (2 parameters).

use crate::ReconError;
use crate::morphology::dilate;
use crate::plane::Plane;
use irmirror_capture::Image;
use irmirror_geom::TriMesh;
use irmirror_geom::rotation::axis_angle_to_matrix;
use irmirror_geom::{PinholeCamera, Similarity3};
use irmirror_render::sdf::{PlacedSdf, Sdf};
use irmirror_render::shapes::Shape;
use irmirror_sdf::placed::{PlacedFitConfig, PlacedObservation, fit_placed};
use irmirror_sdf::{Category, LatentSdf, SdfNet};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A category's shape family: parameters mapped from the unit box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Family {
    /// [`Shape::Sphere`] (no parameters).
    Sphere,
    /// [`Shape::Bowl`]: `cut ∈ [−0.6, 0.3]`, `wall ∈ [0.02, 0.12]`.
    Bowl,
    /// [`Shape::Mug`]: `aspect ∈ [0.6, 1.6]`, `wall ∈ [0.04, 0.2]`.
    Mug,
    /// [`Shape::Car`]: `cabin ∈ [0.4, 0.75]`, `height ∈ [0.22, 0.42]`.
    Car,
}

impl Family {
    /// Categories with a prior.
    pub const KNOWN: [&'static str; 4] = ["bowl", "mug", "car", "sphere"];

    /// The family of a capture category.
    pub fn of(category: &str) -> Result<Self, ReconError> {
        match category {
            "bowl" => Ok(Self::Bowl),
            "mug" | "cup" => Ok(Self::Mug),
            "car" => Ok(Self::Car),
            "sphere" | "ball" => Ok(Self::Sphere),
            other => Err(ReconError::UnknownCategory {
                category: other.into(),
                known: Self::KNOWN.join(", "),
            }),
        }
    }

    fn ranges(self) -> &'static [(f64, f64)] {
        match self {
            Self::Sphere => &[],
            Self::Bowl => &[(-0.6, 0.3), (0.02, 0.12)],
            Self::Mug => &[(0.6, 1.6), (0.04, 0.2)],
            Self::Car => &[(0.4, 0.75), (0.22, 0.42)],
        }
    }

    /// Number of shape parameters.
    pub fn dims(self) -> usize {
        self.ranges().len()
    }

    /// The shape for unit-box parameters `u` (clamped).
    pub fn shape(self, u: &[f64]) -> Shape {
        let p: Vec<f64> = self
            .ranges()
            .iter()
            .zip(u)
            .map(|(&(lo, hi), &x)| lo + (hi - lo) * x.clamp(0.0, 1.0))
            .collect();
        match self {
            Self::Sphere => Shape::Sphere,
            Self::Bowl => Shape::Bowl {
                cut: p[0],
                wall: p[1],
            },
            Self::Mug => Shape::Mug {
                aspect: p[0],
                wall: p[1],
            },
            Self::Car => Shape::Car {
                cabin: p[0],
                height: p[1],
            },
        }
    }

    /// The category's typical metric size as `(ln scale, σ of ln scale)`, where known and
    /// needed: a car seen from its side fills the depth image, so nothing in the data fixes its
    /// length, and proportions trade against scale (measured: 21–30 % too small, 5–7° reflected-
    /// ray error without it). Passenger cars are 4.0–5.0 m long (σ ≈ 10 %), the unit car 1.9.
    /// Mugs and bowls are seen whole and need none.
    fn size_prior(self) -> Option<(f64, f64)> {
        match self {
            Self::Car => Some(((CAR_LENGTH_M / 1.9f64).ln(), 0.1)),
            _ => None,
        }
    }

    /// Yaw restarts: none for a body of revolution, front/back for a car, `restarts` for a mug.
    fn yaws(self, restarts: u32) -> Vec<f64> {
        let n = match self {
            Self::Sphere | Self::Bowl => 1,
            Self::Car => restarts.clamp(1, 2),
            Self::Mug => restarts.max(1),
        };
        (0..n)
            .map(|k| std::f64::consts::TAU * k as f64 / n as f64)
            .collect()
    }
}

/// Typical passenger-car length, metres (the centre of the car size prior).
pub const CAR_LENGTH_M: f64 = 4.5;

/// Stage-1 settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectConfig {
    /// Adam steps per restart.
    pub iterations: u32,
    /// Yaw restarts for shapes that are not bodies of revolution (a mug uses all; a car two).
    pub restarts: u32,
    /// Surface points used (evenly subsampled).
    pub max_points: usize,
    /// Initial learning rates: rotation (rad), translation and log-scale (in s₀), shape (unit box).
    pub lr_rotation: f64,
    /// See `lr_rotation`.
    pub lr_translation: f64,
    /// See `lr_rotation`.
    pub lr_scale: f64,
    /// See `lr_rotation`.
    pub lr_shape: f64,
    /// Huber width of `L_depth`, metres.
    pub huber_m: f64,
    /// Weights of `L_mask` and `L_prior`.
    pub w_free: f64,
    /// See `w_free`.
    pub w_plane: f64,
    /// Ring of pixels around the mask that must be free space, pixels.
    pub ring_px: u32,
    /// Weight of the category size prior (per σ², see `Family::size_prior`).
    pub w_size: f64,
    /// Weight of the rendered-depth term (sphere-traced depth against the measured depth).
    pub w_depth: f64,
    /// Camera rays rendered for it (evenly subsampled from the surface points).
    pub depth_rays: usize,
    /// Which prior is fitted: the two-parameter family alone, or then the learned DeepSDF prior.
    pub prior: ObjectPrior,
    /// The learned prior's fit (latent and placement together, from the family fit).
    pub learned: PlacedFitConfig,
}

/// The shape prior stage 1 fits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectPrior {
    /// The renderer's two-parameter family of the category ([`Family`]).
    #[default]
    Simple,
    /// The family fit, then the category's learned DeepSDF prior (`assets/object_priors`):
    /// its latent and the placement fitted together ([`irmirror_sdf::placed`]). Spheres keep
    /// the family fit.
    Learned,
}

impl Default for ObjectConfig {
    fn default() -> Self {
        Self {
            iterations: 160,
            restarts: 8,
            max_points: 800,
            lr_rotation: 0.05,
            lr_translation: 0.04,
            lr_scale: 0.04,
            lr_shape: 0.05,
            huber_m: 0.003,
            w_free: 1.0,
            w_plane: 0.3,
            ring_px: 3,
            w_size: 1e-3,
            w_depth: 0.3,
            depth_rays: 200,
            prior: ObjectPrior::Simple,
            learned: PlacedFitConfig::default(),
        }
    }
}

/// One fitted object.
#[derive(Clone, Debug, Serialize)]
pub struct FittedObject {
    /// Category (from the capture, or the best-fitting family).
    pub category: String,
    /// Fitted shape and parameters.
    pub shape: Shape,
    /// Object frame → depth frame (rotation, translation in metres, scale in metres per unit).
    #[serde(serialize_with = "ser_sim")]
    pub depth_from_object: Similarity3<f64>,
    /// Loss of the kept state (the best iterate of the best restart).
    pub loss: f64,
    /// Mean |signed distance| of the observed surface points to the fitted surface, metres.
    pub mean_surface_error_m: f64,
    /// Observed points used.
    pub points: usize,
    /// Loss after every iteration of the kept restart.
    #[serde(skip)]
    pub loss_curve: Vec<f64>,
    /// The learned prior's shape when it was fitted: `depth_from_object` then places the prior's
    /// normalised frame, and `shape` is the family fit it started from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learned: Option<LearnedShape>,
}

/// A fitted shape of a learned prior.
#[derive(Clone, Debug, Serialize)]
pub struct LearnedShape {
    /// The prior's latent code.
    pub latent: Vec<f64>,
    /// Lowest object-frame y of the surface.
    pub base_y: f64,
    /// The prior.
    #[serde(skip)]
    pub net: Arc<SdfNet>,
    /// The field of `latent`.
    #[serde(skip)]
    pub sdf: Arc<LatentSdf>,
}

fn ser_sim<S: serde::Serializer>(s: &Similarity3<f64>, ser: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeStruct;
    let r = s.rotation;
    let mut st = ser.serialize_struct("Similarity", 3)?;
    st.serialize_field(
        "rotation",
        &[
            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
        ],
    )?;
    st.serialize_field(
        "translation_m",
        &[s.translation.x, s.translation.y, s.translation.z],
    )?;
    st.serialize_field("scale_m", &s.scale)?;
    st.end()
}

impl FittedObject {
    /// The object as a renderer SDF.
    pub fn placed(&self) -> PlacedSdf {
        match &self.learned {
            Some(l) => PlacedSdf {
                sdf: l.sdf.clone(),
                depth_from_object: self.depth_from_object,
            },
            None => PlacedSdf {
                sdf: self.shape.sdf(),
                depth_from_object: self.depth_from_object,
            },
        }
    }

    /// Lowest object-frame y of the fitted surface.
    pub fn base_y(&self) -> f64 {
        self.learned
            .as_ref()
            .map_or_else(|| self.shape.base_y(), |l| l.base_y)
    }

    /// The fitted surface as a mesh in the depth frame, `resolution` cells across the object
    /// (a learned shape: batched network evaluation, pieces of ≥ 0.5 % of the largest one's volume).
    pub fn mesh(&self, resolution: usize) -> Result<TriMesh, ReconError> {
        let s = &self.depth_from_object;
        let mut m = match &self.learned {
            Some(l) => irmirror_sdf::quality::extract_mesh(&l.net, &l.latent, resolution)?
                .main_components(irmirror_sdf::quality::MAIN_PART_FRACTION),
            None => family_mesh(&self.shape, resolution),
        };
        m.map_vertices(|v| {
            s.transform_point(&Vector3::from(v.map(f64::from)))
                .map(|x| x as f32)
                .into()
        });
        Ok(m)
    }
}

/// A family shape's surface in its object frame, `resolution` cells across.
fn family_mesh(shape: &Shape, resolution: usize) -> TriMesh {
    let sdf = shape.sdf();
    let r = sdf.bounding_radius() * 1.05;
    irmirror_geom::isosurface::isosurface(
        |p| sdf.distance(p),
        -Vector3::repeat(r),
        Vector3::repeat(r),
        resolution,
    )
}

/// What one object's fit sees (depth frame, metres).
#[derive(Clone, Debug, Default)]
pub struct ObjectObservation {
    /// Observed surface points.
    pub surface: Vec<Vector3<f64>>,
    /// Points that must be outside the object (in front of the surface, or on rays that saw past
    /// it).
    pub free: Vec<Vector3<f64>>,
}

/// Lifts a depth-pixel mask to the observation of one object.
pub fn observe(
    depth_m: &Image<f32>,
    camera: &PinholeCamera,
    mask: &Image<bool>,
    cfg: &ObjectConfig,
) -> Result<ObjectObservation, ReconError> {
    let (w, h) = (depth_m.width, depth_m.height);
    let valid = |i: usize| depth_m.data[i].is_finite() && depth_m.data[i] > 0.0;
    let idx: Vec<usize> = (0..(w * h) as usize)
        .filter(|&i| mask.data[i] && valid(i))
        .collect();
    if idx.len() < 10 {
        return Err(ReconError::EmptyObject { pixels: idx.len() });
    }
    let stride = idx.len().div_ceil(cfg.max_points).max(1);
    let point = |i: usize| {
        camera.unproject(
            (i as u32 % w) as f64 + 0.5,
            (i as u32 / w) as f64 + 0.5,
            f64::from(depth_m.data[i]),
        )
    };
    let surface: Vec<Vector3<f64>> = idx.iter().step_by(stride).map(|&i| point(i)).collect();
    let zs: Vec<f64> = surface.iter().map(|p| p.z).collect();
    let (zmin, zmax) = zs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
    let extent = (zmax - zmin).max(0.02);
    let mut free = Vec::new();
    // In front of the surface by 5 % of the object's depth extent, along the camera ray.
    for p in &surface {
        free.push(p * (1.0 - 0.05 * extent / p.z));
    }
    // The ring: the camera saw past (or missed) the object there.
    let ring = dilate(mask, cfg.ring_px);
    let ring_idx: Vec<usize> = (0..(w * h) as usize)
        .filter(|&i| ring.data[i] && !mask.data[i])
        .collect();
    let ring_stride = ring_idx.len().div_ceil(cfg.max_points / 2).max(1);
    for &i in ring_idx.iter().step_by(ring_stride) {
        let far = if valid(i) {
            f64::from(depth_m.data[i]) - 0.02 * extent
        } else {
            zmax + extent
        };
        for k in 0..RING_SAMPLES {
            let z = zmin - 0.25 * extent
                + (zmax - zmin + 0.5 * extent) * k as f64 / (RING_SAMPLES - 1) as f64;
            if z < far {
                free.push(camera.unproject(
                    (i as u32 % w) as f64 + 0.5,
                    (i as u32 / w) as f64 + 0.5,
                    z,
                ));
            }
        }
    }
    Ok(ObjectObservation { surface, free })
}

/// Free-space samples along each ring ray (dense enough not to fall through a thin wall into a
/// cavity).
const RING_SAMPLES: usize = 12;

/// Parameters of one restart.
#[derive(Clone, Copy, Debug)]
struct State {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
    log_scale: f64,
    u: [f64; 2],
}

impl State {
    fn sim(&self) -> Similarity3<f64> {
        Similarity3 {
            rotation: self.rotation,
            translation: self.translation,
            scale: self.log_scale.exp(),
        }
    }
}

/// Loss and gradient: (δ, t, log s) analytic; shape by central differences.
struct Problem<'a> {
    family: Family,
    obs: &'a ObjectObservation,
    plane: &'a Plane,
    s0: f64,
    cfg: &'a ObjectConfig,
}

struct Grad {
    rot: Vector3<f64>,
    t: Vector3<f64>,
    log_s: f64,
}

impl Problem<'_> {
    fn loss(&self, st: &State, sdf: &dyn Sdf, base_y: f64, mut grad: Option<&mut Grad>) -> f64 {
        let (r, t, s) = (st.rotation, st.translation, st.log_scale.exp());
        let inv = 1.0 / self.s0;
        let hub = self.cfg.huber_m * inv;
        let mut loss = 0.0;
        let mut acc =
            |p: &Vector3<f64>, weight: f64, surface: bool, grad: &mut Option<&mut Grad>| {
                let q = r.tr_mul(&(p - t)) / s;
                let dq = sdf.distance(&q);
                let d = s * dq * inv;
                // Value and derivative of the per-point term in d.
                let (f, df) = if surface {
                    if d.abs() <= hub {
                        (0.5 * d * d / hub, d / hub)
                    } else {
                        (d.abs() - 0.5 * hub, d.signum())
                    }
                } else if d < 0.0 {
                    (-d, -1.0)
                } else {
                    (0.0, 0.0)
                };
                loss += weight * f;
                if let Some(g) = grad.as_deref_mut()
                    && df != 0.0
                {
                    let gq = sdf.gradient(&q);
                    let u = r * gq; // ∂(s·sdf)/∂p, depth frame
                    let c = weight * df * inv;
                    g.t -= u * c;
                    g.log_s += c * s * (dq - gq.dot(&q));
                    g.rot += u.cross(&(p - t)) * c;
                }
            };
        let ws = 1.0 / self.obs.surface.len() as f64;
        for p in &self.obs.surface {
            acc(p, ws, true, &mut grad);
        }
        if !self.obs.free.is_empty() {
            let wf = self.cfg.w_free / self.obs.free.len() as f64;
            for p in &self.obs.free {
                acc(p, wf, false, &mut grad);
            }
        }
        // Rendered depth: each sampled camera ray (from the depth camera's centre, the origin)
        // is sphere-traced into the current object and its hit distance compared with the
        // measured one. Gradient by the implicit function theorem: with F(x; θ) = s·sdf(q) = 0 at
        // the hit x = t·r, dt/dθ = −(∂F/∂θ) / (∇ₓF · r).
        if self.cfg.w_depth > 0.0 && self.cfg.depth_rays > 0 {
            let stride = self.obs.surface.len().div_ceil(self.cfg.depth_rays).max(1);
            let wd = self.cfg.w_depth * stride as f64 / self.obs.surface.len() as f64;
            let camera = r.tr_mul(&(-t)) / s; // the depth camera's centre, object frame
            for p in self.obs.surface.iter().step_by(stride) {
                let (t_meas, ray) = (p.norm(), p.normalize());
                let Some(t_obj) = render_depth(sdf, &camera, &r.tr_mul(&ray)) else {
                    continue;
                };
                let (t_hit, x) = (t_obj * s, ray * (t_obj * s));
                let q = r.tr_mul(&(x - t)) / s;
                let gq = sdf.gradient(&q);
                let u = r * gq;
                let cos = u.dot(&ray);
                // Grazing rays: the hit distance is ill-conditioned there; the free-space term
                // owns the silhouette.
                if cos > -GRAZING_COS {
                    continue;
                }
                let e = (t_hit - t_meas) * inv;
                let (f, df) = if e.abs() <= hub {
                    (0.5 * e * e / hub, e / hub)
                } else {
                    (e.abs() - 0.5 * hub, e.signum())
                };
                loss += wd * f;
                if let Some(g) = grad.as_deref_mut() {
                    // dL/dθ = wd · f'(e) / s₀ · dt/dθ, dt/dθ = −(∂F/∂θ)/cos.
                    let c = -wd * df * inv / cos;
                    g.t -= u * c;
                    g.log_s += c * s * (sdf.distance(&q) - gq.dot(&q));
                    g.rot += u.cross(&(x - t)) * c;
                }
            }
        }
        // Upright on the plane.
        let n = self.plane.n();
        let up = r * Vector3::y();
        let e_up = up - n;
        let wp = self.cfg.w_plane;
        loss += wp * e_up.norm_squared();
        let base = r * Vector3::new(0.0, base_y, 0.0) * s;
        let e_base = if self.plane.found {
            (n.dot(&(t + base)) - self.plane.offset_m) * inv
        } else {
            0.0
        };
        loss += wp * e_base * e_base;
        // Size prior: ½ w ((ln s − μ)/σ)².
        let size = self
            .family
            .size_prior()
            .map(|(mean, sigma)| ((st.log_scale - mean) / sigma, sigma));
        if let Some((e, _)) = size {
            loss += 0.5 * self.cfg.w_size * e * e;
        }
        if let Some(g) = grad {
            if let Some((e, sigma)) = size {
                g.log_s += self.cfg.w_size * e / sigma;
            }
            g.rot += up.cross(&(e_up * 2.0)) * wp;
            let c = 2.0 * wp * e_base * inv;
            g.t += n * c;
            g.log_s += c * n.dot(&base);
            g.rot += base.cross(&n) * c;
        }
        loss
    }

    fn eval(&self, st: &State, grad: Option<&mut Grad>) -> f64 {
        let shape = self.family.shape(&st.u);
        self.loss(st, shape.sdf().as_ref(), shape.base_y(), grad)
    }

    fn run(&self, init: State) -> (State, f64, Vec<f64>) {
        let mut st = init;
        let n_u = self.family.dims();
        let mut m = [0.0; 9];
        let mut v = [0.0; 9];
        let (b1, b2) = (0.9f64, 0.999f64);
        let lrs = [
            self.cfg.lr_rotation,
            self.cfg.lr_rotation,
            self.cfg.lr_rotation,
            self.cfg.lr_translation * self.s0,
            self.cfg.lr_translation * self.s0,
            self.cfg.lr_translation * self.s0,
            self.cfg.lr_scale,
            self.cfg.lr_shape,
            self.cfg.lr_shape,
        ];
        let mut curve = Vec::with_capacity(self.cfg.iterations as usize);
        let iters = self.cfg.iterations.max(1);
        // The best iterate is kept: the loss is not smooth (rays enter and leave the rendered
        // set, a handle passes behind the body) and Adam's first steps can leave a good start for
        // a worse basin (measured: from the true pose, to 18–36× its loss on 2 of 4 mugs).
        let mut best = (f64::INFINITY, st);
        for it in 0..iters {
            let mut g = Grad {
                rot: Vector3::zeros(),
                t: Vector3::zeros(),
                log_s: 0.0,
            };
            let loss = self.eval(&st, Some(&mut g));
            curve.push(loss);
            if loss < best.0 {
                best = (loss, st);
            }
            let mut flat = [
                g.rot.x, g.rot.y, g.rot.z, g.t.x, g.t.y, g.t.z, g.log_s, 0.0, 0.0,
            ];
            for k in 0..n_u {
                let h = 1e-3;
                let (mut a, mut b) = (st, st);
                a.u[k] = (a.u[k] + h).min(1.0);
                b.u[k] = (b.u[k] - h).max(0.0);
                flat[7 + k] =
                    (self.eval(&a, None) - self.eval(&b, None)) / (a.u[k] - b.u[k]).max(1e-12);
            }
            let schedule =
                0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * it as f64 / iters as f64).cos());
            let mut step = [0.0; 9];
            for k in 0..9 {
                m[k] = b1 * m[k] + (1.0 - b1) * flat[k];
                v[k] = b2 * v[k] + (1.0 - b2) * flat[k] * flat[k];
                let mh = m[k] / (1.0 - b1.powi(it as i32 + 1));
                let vh = v[k] / (1.0 - b2.powi(it as i32 + 1));
                step[k] = lrs[k] * schedule * mh / (vh.sqrt() + 1e-12);
            }
            // Left perturbation R ← exp(−step) R (the gradient was taken w.r.t. it).
            st.rotation =
                axis_angle_to_matrix(&Vector3::new(-step[0], -step[1], -step[2])) * st.rotation;
            st.translation -= Vector3::new(step[3], step[4], step[5]);
            st.log_scale -= step[6];
            for k in 0..n_u {
                st.u[k] = (st.u[k] - step[7 + k]).clamp(0.0, 1.0);
            }
        }
        let final_loss = self.eval(&st, None);
        curve.push(final_loss);
        if final_loss <= best.0 {
            best = (final_loss, st);
        }
        (best.1, best.0, curve)
    }
}

/// A rotation taking +Y to `n`, then turned by `yaw` about `n`.
fn upright(n: &Vector3<f64>, yaw: f64) -> Matrix3<f64> {
    let y = n.normalize();
    let helper = if y.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let x = (helper - y * helper.dot(&y)).normalize();
    let z = x.cross(&y);
    let base = Matrix3::from_columns(&[x, y, z]);
    base * axis_angle_to_matrix(&Vector3::new(0.0, yaw, 0.0))
}

/// Rays meeting the surface at a normal-incidence cosine below this are not rendered.
const GRAZING_COS: f64 = 0.2;

/// Sphere-traces the unit ray `d` from `o` (both in the object frame) into `sdf`: the hit
/// distance (object units), or `None` on a miss. Marches to 1e-7 object units (a depth error
/// far below the sensor's), 200 steps at most.
fn render_depth(sdf: &dyn Sdf, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    let radius = sdf.bounding_radius();
    let b = o.dot(d);
    let disc = b * b - (o.norm_squared() - radius * radius);
    if disc < 0.0 {
        return None;
    }
    let (mut t, t_exit) = ((-b - disc.sqrt()).max(0.0), -b + disc.sqrt());
    for _ in 0..200 {
        let dist = sdf.distance(&(o + d * t));
        if dist.abs() < 1e-7 {
            return Some(t);
        }
        t += dist;
        if t > t_exit {
            return None;
        }
    }
    None
}

/// Fits one object of `family` to `obs`, standing on `plane`.
pub fn fit_family(
    family: Family,
    obs: &ObjectObservation,
    plane: &Plane,
    cfg: &ObjectConfig,
) -> FittedObject {
    let n = plane.n();
    let centroid =
        obs.surface.iter().fold(Vector3::zeros(), |a, p| a + p) / obs.surface.len() as f64;
    // Size from the spread of the points across the plane.
    let horizontal = |p: &Vector3<f64>| {
        let d = p - centroid;
        (d - n * n.dot(&d)).norm()
    };
    let mut spread: Vec<f64> = obs.surface.iter().map(horizontal).collect();
    spread.sort_by(f64::total_cmp);
    let r95 = spread[(spread.len() as f64 * 0.95) as usize].max(1e-3);
    // A category with a size prior starts at its typical size: a car's side overflows the
    // image, so the spread of its points says little (starting at half size, before the IMU
    // up, the fit stayed 6–20 % small).
    let s0 = match family.size_prior() {
        Some((mean, _)) => mean.exp(),
        None => r95 / 0.85,
    };
    let problem = Problem {
        family,
        obs,
        plane,
        s0,
        cfg,
    };
    // Restarts: yaws × a low and a high first shape parameter (proportions trade against
    // scale, a local minimum the fit does not leave on its own).
    let firsts: &[f64] = if family.dims() > 0 {
        &[0.25, 0.75]
    } else {
        &[0.5]
    };
    let inits: Vec<State> = family
        .yaws(cfg.restarts)
        .into_iter()
        .flat_map(|yaw| firsts.iter().map(move |&u0| (yaw, u0)))
        .map(|(yaw, u0)| {
            let rotation = upright(&n, yaw);
            let u = [u0, 0.5];
            let shape = family.shape(&u);
            // Centre over the centroid, base on the plane.
            let over = if plane.found {
                centroid - n * plane.height(&centroid)
            } else {
                centroid - n * s0 * shape.base_y().abs()
            };
            let mut translation = over - rotation * Vector3::new(0.0, shape.base_y(), 0.0) * s0;
            // The points are the near side of the object: push it away from the camera
            // (across the plane) until their centroid is on its surface, not inside it — a
            // car centred on its door starts with its near half in front of the camera's
            // view of the door (sphere tracing from the inside: each step moves by |d|).
            let sdf = shape.sdf();
            let away = (centroid - n * n.dot(&centroid))
                .try_normalize(1e-9)
                .unwrap_or_else(Vector3::z);
            for _ in 0..64 {
                let d = s0 * sdf.distance(&(rotation.tr_mul(&(centroid - translation)) / s0));
                if d >= -1e-3 * s0 {
                    break;
                }
                translation += away * -d;
            }
            State {
                rotation,
                translation,
                log_scale: s0.ln(),
                u,
            }
        })
        .collect();
    let runs: Vec<(State, f64, Vec<f64>)> = inits.into_par_iter().map(|s| problem.run(s)).collect();
    for (k, (st, loss, _)) in runs.iter().enumerate() {
        let x = st.rotation * Vector3::x();
        tracing::debug!(
            "{family:?} restart {k}: loss {loss:.4e}, object +X {:.3} {:.3} {:.3}, scale {:.4} m",
            x.x,
            x.y,
            x.z,
            st.log_scale.exp()
        );
    }
    let (st, loss, curve) = runs
        .into_iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("at least one restart");
    let shape = family.shape(&st.u);
    let sim = st.sim();
    let placed = PlacedSdf {
        sdf: shape.sdf(),
        depth_from_object: sim,
    };
    let mean = obs
        .surface
        .iter()
        .map(|p| placed.distance(p).abs())
        .sum::<f64>()
        / obs.surface.len() as f64;
    FittedObject {
        category: shape.category().into(),
        shape,
        depth_from_object: sim,
        loss,
        mean_surface_error_m: mean,
        points: obs.surface.len(),
        loss_curve: curve,
        learned: None,
    }
}

/// Points just behind the observed surface along the camera rays (inside any wall): 1.5 % of
/// the object's size, ≈ 1–1.5 mm on a mug or a bowl, thinner than their walls.
const INSIDE_DEPTH: f64 = 0.015;
/// Support-plane free-space points: a grid this many per side under the footprint…
const SUPPORT_GRID: usize = 16;
/// …this far below the plane, in units of the object's size (`unit_m`).
const SUPPORT_DEPTH: f64 = 0.02;

/// The learned prior's fit from a family fit (`fit`): the family shape's bounding box gives
/// the prior's normalised frame (centre, half-diagonal 0.9), the mean latent the shape; then
/// latent and placement are fitted together, with a grid just below the support plane under the
/// footprint kept outside (when a plane was found). Spheres are returned unchanged.
pub fn fit_learned(
    fit: FittedObject,
    obs: &ObjectObservation,
    plane: &Plane,
    cfg: &ObjectConfig,
    seed: u64,
) -> Result<FittedObject, ReconError> {
    let category = match fit.shape {
        Shape::Sphere => return Ok(fit),
        Shape::Bowl { .. } => Category::Bowl,
        Shape::Mug { .. } => Category::Mug,
        Shape::Car { .. } => Category::Car,
    };
    let net = SdfNet::builtin(category)?;
    let (lo, hi) = family_mesh(&fit.shape, 48).bounds().ok_or_else(|| {
        irmirror_sdf::SdfError::Invalid(format!(
            "the fitted {} has no surface to place the learned prior on",
            category.name()
        ))
    })?;
    let (lo, hi) = (
        Vector3::from(lo.map(f64::from)),
        Vector3::from(hi.map(f64::from)),
    );
    let s = &fit.depth_from_object;
    let k = (hi - lo).norm() / 2.0 / irmirror_sdf::families::NORMALISED_RADIUS;
    let init = Similarity3 {
        rotation: s.rotation,
        translation: s.transform_point(&((lo + hi) / 2.0)),
        scale: s.scale * k,
    };
    let unit = s.scale;
    let inside: Vec<Vector3<f64>> = obs
        .surface
        .iter()
        .map(|p| p + p.normalize() * INSIDE_DEPTH * unit)
        .collect();
    let scale_prior = Family::of(category.name())?
        .size_prior()
        .map(|_| (init.scale.ln(), 0.1));
    // The underside is never seen: without the table the latent may push it through the plane.
    // A grid just below the plane under the (slightly widened) footprint is free space.
    let mut support = Vec::new();
    if plane.found {
        let (n, g) = (plane.n(), SUPPORT_GRID);
        for i in 0..g {
            for j in 0..g {
                let f = |k: usize, a: f64, b: f64| {
                    a + (b - a) * (-0.1 + 1.2 * (k as f64 + 0.5) / g as f64)
                };
                let p = s.transform_point(&Vector3::new(f(i, lo.x, hi.x), lo.y, f(j, lo.z, hi.z)));
                support.push(p - n * (plane.height(&p) + SUPPORT_DEPTH * unit));
            }
        }
    }
    let observation = PlacedObservation {
        surface: &obs.surface,
        free: &obs.free,
        inside: &inside,
        support: &support,
        up: Some(plane.n()),
        unit_m: unit,
        scale_prior,
    };
    let placed = fit_placed(
        &net,
        &observation,
        &init,
        &net.mean_latent(),
        &PlacedFitConfig {
            seed,
            ..cfg.learned
        },
    )?;
    let field = Arc::new(net.shape(&placed.latent)?);
    let mesh = irmirror_sdf::quality::extract_mesh(&net, &placed.latent, 40)?
        .main_components(irmirror_sdf::quality::MAIN_PART_FRACTION);
    let base_y = mesh
        .vertices
        .iter()
        .map(|v| f64::from(v[1]))
        .fold(f64::INFINITY, f64::min);
    let d = placed.depth_from_object;
    let mean = obs
        .surface
        .iter()
        .map(|p| (d.scale * field.value_grad(&d.inverse_transform_point(p)).0).abs())
        .sum::<f64>()
        / obs.surface.len() as f64;
    let mut curve = fit.loss_curve;
    curve.extend(&placed.curve);
    Ok(FittedObject {
        depth_from_object: d,
        loss: placed.loss,
        mean_surface_error_m: mean,
        loss_curve: curve,
        learned: Some(LearnedShape {
            latent: placed.latent,
            base_y,
            net,
            sdf: field,
        }),
        ..fit
    })
}

/// Stage-1 settings (plane, segmentation, fit).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Stage1Config {
    /// Support-plane RANSAC.
    pub plane: crate::plane::PlaneConfig,
    /// Segmentation of objects without masks.
    pub segment: crate::segment::SegmentConfig,
    /// Per-object fit.
    pub fit: ObjectConfig,
}

/// Stage-1 products.
#[derive(Clone, Debug)]
pub struct Objects {
    /// The support plane.
    pub plane: Plane,
    /// Fitted objects, in the capture's object order.
    pub objects: Vec<FittedObject>,
    /// The depth-pixel mask each object was fitted to.
    pub masks: Vec<Image<bool>>,
    /// Which masks came from segmentation (rather than the capture).
    pub segmented: Vec<bool>,
}

impl Objects {
    /// The fitted objects as renderer SDFs.
    pub fn placed(&self) -> Vec<PlacedSdf> {
        self.objects.iter().map(FittedObject::placed).collect()
    }
}

/// Stage 1 on a loaded capture: support plane, masks (given or segmented), one fit per object.
pub fn reconstruct_objects(
    capture: &irmirror_capture::Capture,
    cfg: &Stage1Config,
    seed: u64,
) -> Result<Objects, ReconError> {
    let depth = &capture.depth_m;
    let cam = &capture.depth_camera;
    let points = crate::segment::depth_points(depth, cam);
    let families: Vec<Family> = capture
        .objects
        .iter()
        .map(|o| Family::of(&o.category))
        .collect::<Result<_, _>>()?;
    let mut given = vec![false; points.len()];
    for o in &capture.objects {
        if let Some(m) = &o.mask {
            for (g, &b) in given.iter_mut().zip(&m.data) {
                *g |= b;
            }
        }
    }
    let candidates: Vec<Vector3<f64>> = points
        .iter()
        .zip(&given)
        .filter_map(|(p, &g)| if g { None } else { *p })
        .collect();
    let stride = candidates.len().div_ceil(20_000).max(1);
    let sub: Vec<Vector3<f64>> = candidates.into_iter().step_by(stride).collect();
    let mut rng = irmirror_geom::rng::seeded(seed, 11);
    let plane = crate::plane::fit_plane(&sub, capture.up.as_ref(), &cfg.plane, &mut rng)
        .unwrap_or_else(|| Plane::up_only(capture.up.unwrap_or(-Vector3::y())));

    // Masks: given, or the largest clusters above the plane for the objects without one.
    let missing = capture.objects.iter().filter(|o| o.mask.is_none()).count();
    if missing > 0 && !plane.found {
        return Err(ReconError::NoSupportPlane);
    }
    // (mask, the cluster it was split from), largest first.
    let mut clusters: Vec<(Image<bool>, usize)> = if missing > 0 {
        crate::segment::segment(
            &points,
            depth.width,
            depth.height,
            &plane,
            &given,
            &cfg.segment,
        )
        .into_iter()
        .enumerate()
        .map(|(g, m)| (m, g))
        .collect()
    } else {
        vec![]
    };
    // Touching objects join into one cluster: split the largest until there are enough (or
    // none can be split).
    while clusters.len() < missing
        && let Some((a, b)) = clusters
            .first()
            .and_then(|(c, _)| crate::segment::split(&points, c, &plane, &cfg.segment))
    {
        let (_, g) = clusters.remove(0);
        clusters.extend([(a, g), (b, g)]);
        clusters
            .sort_by_cached_key(|(m, _)| std::cmp::Reverse(m.data.iter().filter(|&&v| v).count()));
    }
    if clusters.len() < missing {
        return Err(ReconError::Segmentation {
            wanted: missing,
            found: clusters.len(),
        });
    }
    let mut clusters = clusters.into_iter();
    // Per capture object: its mask, and for segmented ones the cluster it came from.
    let (mut masks, groups): (Vec<Image<bool>>, Vec<Option<usize>>) = capture
        .objects
        .iter()
        .map(|o| match &o.mask {
            Some(m) => (m.clone(), None),
            None => {
                let (m, g) = clusters
                    .next()
                    .expect("one cluster per object without a mask");
                (m, Some(g))
            }
        })
        .unzip();
    let segmented: Vec<bool> = groups.iter().map(Option::is_some).collect();
    // Segmented clusters come largest first, not in capture order: give each cluster the
    // family (among the mask-less objects' categories) that fits it best.
    let mut options: Vec<Family> = Vec::new();
    for (_, f) in capture
        .objects
        .iter()
        .zip(&families)
        .filter(|(o, _)| o.mask.is_none())
    {
        if !options.contains(f) {
            options.push(*f);
        }
    }
    let mut objects = Vec::with_capacity(masks.len());
    let mut observations = Vec::with_capacity(masks.len());
    for (k, mask) in masks.iter().enumerate() {
        let obs = observe(depth, cam, mask, &cfg.fit)?;
        let fit = if segmented[k] {
            options
                .iter()
                .map(|f| fit_family(*f, &obs, &plane, &cfg.fit))
                .min_by(|a, b| a.loss.total_cmp(&b.loss))
                .expect("one option")
        } else {
            fit_family(families[k], &obs, &plane, &cfg.fit)
        };
        objects.push(fit);
        observations.push(obs);
    }
    // Objects split from one cluster: the split's straight cut is only a first guess. Give every
    // point of the cluster to the fitted surface nearest to it, and refit on those masks.
    let mut split_from: Vec<usize> = groups.iter().flatten().copied().collect();
    split_from.sort_unstable();
    split_from.dedup();
    for g in split_from {
        let members: Vec<usize> = (0..masks.len()).filter(|&j| groups[j] == Some(g)).collect();
        if members.len() < 2 {
            continue;
        }
        let placed: Vec<PlacedSdf> = members.iter().map(|&j| objects[j].placed()).collect();
        let mut new: Vec<Image<bool>> = members
            .iter()
            .map(|_| Image::filled(depth.width, depth.height, false))
            .collect();
        for i in 0..points.len() {
            if let Some(p) = points[i]
                && members.iter().any(|&j| masks[j].data[i])
            {
                let best = (0..members.len())
                    .min_by(|&a, &b| {
                        placed[a]
                            .distance(&p)
                            .abs()
                            .total_cmp(&placed[b].distance(&p).abs())
                    })
                    .expect("members");
                new[best].data[i] = true;
            }
        }
        for (&j, m) in members.iter().zip(new) {
            let Ok(obs) = observe(depth, cam, &m, &cfg.fit) else {
                continue;
            };
            objects[j] = fit_family(Family::of(&objects[j].category)?, &obs, &plane, &cfg.fit);
            observations[j] = obs;
            masks[j] = m;
        }
    }
    // The learned prior starts from the final family fits (after any split).
    if cfg.fit.prior == ObjectPrior::Learned {
        objects = objects
            .into_iter()
            .zip(&observations)
            .enumerate()
            .map(|(k, (o, obs))| fit_learned(o, obs, &plane, &cfg.fit, seed.wrapping_add(k as u64)))
            .collect::<Result<_, _>>()?;
    }
    Ok(Objects {
        plane,
        objects,
        masks,
        segmented,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The analytic rotation (left tangent), translation and log-scale gradients of the stage-1
    /// loss against central differences, on a mug seen from one side with free-space points and
    /// the plane terms active; and the same geometry fitted as a (tiny) car, so the car size
    /// prior is active too.
    #[test]
    fn pose_gradients_match_finite_differences() {
        for family in [Family::Mug, Family::Car] {
            pose_gradients_for(family);
        }
    }

    /// Rendered depth of a placed unit sphere against the closed-form ray–sphere intersection,
    /// for rays hitting it (centre, off-centre) and missing it.
    #[test]
    fn rendered_depth_is_the_ray_sphere_intersection() {
        let st = State {
            rotation: axis_angle_to_matrix(&Vector3::new(0.3, -0.2, 0.5)),
            translation: Vector3::new(0.05, -0.02, 0.8),
            log_scale: 0.1f64.ln(),
            u: [0.0; 2],
        };
        let sdf = Family::Sphere.shape(&[]).sdf();
        let s = st.log_scale.exp();
        let camera = st.rotation.tr_mul(&(-st.translation)) / s;
        for (k, target) in [
            Vector3::new(0.05, -0.02, 0.8),
            Vector3::new(0.12, 0.03, 0.8),
            Vector3::new(-0.2, 0.0, 0.8),
        ]
        .iter()
        .enumerate()
        {
            let ray = target.normalize();
            let (c, r) = (st.translation, 0.1);
            let b = ray.dot(&c);
            let disc = b * b - (c.norm_squared() - r * r);
            let got = render_depth(sdf.as_ref(), &camera, &st.rotation.tr_mul(&ray));
            if disc < 0.0 {
                assert!(
                    got.is_none(),
                    "ray {k} misses the sphere but rendered {got:?}"
                );
            } else {
                let t = got.unwrap_or_else(|| panic!("ray {k} hits the sphere")) * s;
                assert!(
                    (t - (b - disc.sqrt())).abs() < 1e-7 && ((ray * t - c).norm() - r).abs() < 1e-7,
                    "ray {k}: t {t}, closed form {}",
                    b - disc.sqrt()
                );
            }
        }
    }

    fn pose_gradients_for(family: Family) {
        let truth = State {
            rotation: upright(&Vector3::new(0.1, -0.9, -0.3).normalize(), 0.7),
            translation: Vector3::new(0.02, 0.1, 0.7),
            log_scale: 0.07f64.ln(),
            u: [0.4, 0.6],
        };
        let placed = PlacedSdf {
            sdf: family.shape(&truth.u).sdf(),
            depth_from_object: truth.sim(),
        };
        // Surface points by projecting a grid onto the surface; free points 1 cm out along −z.
        let mut surface = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                let mut p = truth.translation
                    + Vector3::new(-0.06 + 0.011 * i as f64, -0.06 + 0.011 * j as f64, -0.08);
                for _ in 0..40 {
                    p -= placed.normal(&p) * placed.distance(&p);
                }
                if placed.distance(&p).abs() < 1e-6 {
                    surface.push(p);
                }
            }
        }
        let free = surface
            .iter()
            .map(|p| p - Vector3::new(0.0, 0.0, 0.01))
            .collect();
        let obs = ObjectObservation { surface, free };
        let plane = Plane {
            normal: Vector3::new(0.1, -0.9, -0.3).normalize().into(),
            offset_m: -0.2,
            inlier_fraction: 1.0,
            found: true,
        };
        // The rendered-depth term at full weight, so its gradient is a large part of the check.
        let cfg = ObjectConfig {
            w_depth: 1.0,
            ..ObjectConfig::default()
        };
        let problem = Problem {
            family,
            obs: &obs,
            plane: &plane,
            s0: 0.07,
            cfg: &cfg,
        };
        // Evaluate away from the optimum so every term is active.
        let st = State {
            rotation: axis_angle_to_matrix(&Vector3::new(0.05, -0.04, 0.03)) * truth.rotation,
            translation: truth.translation + Vector3::new(0.004, -0.003, 0.005),
            log_scale: truth.log_scale + 0.05,
            u: truth.u,
        };
        let mut g = Grad {
            rot: Vector3::zeros(),
            t: Vector3::zeros(),
            log_s: 0.0,
        };
        let total = problem.eval(&st, Some(&mut g));
        // The rendered-depth term is active: most sampled rays hit and are not grazing.
        let no_depth = ObjectConfig {
            w_depth: 0.0,
            ..cfg
        };
        let without = Problem {
            cfg: &no_depth,
            ..problem
        };
        let (sdf, s) = (family.shape(&st.u).sdf(), st.log_scale.exp());
        let camera = st.rotation.tr_mul(&(-st.translation)) / s;
        let hits = obs
            .surface
            .iter()
            .filter(|p| {
                render_depth(sdf.as_ref(), &camera, &st.rotation.tr_mul(&p.normalize())).is_some()
            })
            .count();
        let mut g0 = Grad {
            rot: Vector3::zeros(),
            t: Vector3::zeros(),
            log_s: 0.0,
        };
        let base = without.eval(&st, Some(&mut g0));
        let share = ((g.t - g0.t).norm() + (g.rot - g0.rot).norm()) / (g.t.norm() + g.rot.norm());
        eprintln!(
            "{family:?}: {hits} of {} rays hit; L_depth {:.3e} of {total:.3e}; its share of the gradient {share:.2}",
            obs.surface.len(),
            total - base
        );
        assert!(
            hits > obs.surface.len() / 2 && total - base > 0.005 * total && share > 0.1,
            "{hits} rays hit; L_depth {} of {total}, gradient share {share}",
            total - base
        );
        let analytic = [g.rot.x, g.rot.y, g.rot.z, g.t.x, g.t.y, g.t.z, g.log_s];
        assert!(
            obs.surface.len() > 50 && analytic.iter().all(|a| a.abs() > 1e-3),
            "{} points, gradient {analytic:?}",
            obs.surface.len()
        );
        let h = 1e-6;
        for (k, a) in analytic.iter().enumerate() {
            let shifted = |sign: f64| {
                let mut s = st;
                match k {
                    0..3 => {
                        let mut w = Vector3::zeros();
                        w[k] = sign * h;
                        s.rotation = axis_angle_to_matrix(&w) * s.rotation;
                    }
                    3..6 => s.translation[k - 3] += sign * h,
                    _ => s.log_scale += sign * h,
                }
                problem.eval(&s, None)
            };
            let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
            assert!(
                (fd - a).abs() <= 1e-4 * a.abs().max(1e-2),
                "parameter {k}: analytic {a}, central difference {fd}"
            );
        }
    }
}
