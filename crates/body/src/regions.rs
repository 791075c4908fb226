//! Surface regions of the body that differ in the long-wave infrared: the face, the
//! hair-covered scalp, other bare skin (neck, forearms, hands, feet) and clothing.
//!
//! A person's face is warmer than the hair on the back of their head, and bare forearms and
//! hands are warmer than clothing; this is what tells, in a thermal reflection, a person facing
//! the mirror from one facing away. The labels depend on the mesh topology only: they are made
//! once from the mean adult's rest body and hold for every shape and pose.
//!
//! * **Bare skin**: vertices whose dominant bone is the neck, a forearm or a wrist (hand); the
//!   rest of the body below the head is **clothing** (shirt, trousers, shoes).
//! * **Face** and **hair** split the head bone's vertices: the face lies in front of the plane
//!   through the ears (perpendicular to the ears→nose direction) by more than
//!   [`FACE_FRONT_M`] and below the hairline ([`HAIRLINE_ABOVE_EYES_M`] above the eyes); every
//!   other head vertex (crown, back and sides) is hair.

use crate::{BodyError, BodyModel, Phenotype, Pose};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// How far in front of the ears' plane the face starts, metres (the cheeks' back edge).
pub const FACE_FRONT_M: f64 = 0.03;
/// Hairline above the eyes, metres (a forehead ≈ 5–6 cm high, eyebrows ≈ 1 cm above the eyes).
pub const HAIRLINE_ABOVE_EYES_M: f64 = 0.06;

/// Bones whose dominant vertices are bare skin (below the head).
const SKIN_BONES: [&str; 9] = [
    "neck01",
    "neck02",
    "neck03",
    "wrist.L",
    "wrist.R",
    "lowerarm01.L",
    "lowerarm02.L",
    "lowerarm01.R",
    "lowerarm02.R",
];

/// A surface region of the body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Region {
    /// Clothing (torso, arms above the elbow, legs, shoes on the feet).
    Clothing,
    /// Bare skin other than the face (neck, forearms, hands).
    Skin,
    /// The face.
    Face,
    /// Hair-covered scalp (crown, back and sides of the head).
    Hair,
}

impl Region {
    /// All regions, in index order.
    pub const ALL: [Region; 4] = [Region::Clothing, Region::Skin, Region::Face, Region::Hair];

    /// Index in [`Region::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

fn missing(what: String) -> BodyError {
    BodyError::Asset {
        origin: "regions".into(),
        reason: format!("{what} is missing"),
    }
}

/// Per-vertex regions of `model`'s mesh.
pub fn vertex_regions(model: &BodyModel) -> Result<Vec<Region>, BodyError> {
    head_regions(model, false)
}

/// Per-vertex regions with, when `turned`, the head's face and hair turned front to back:
/// each head vertex takes the region its mirror image across the head's mid-plane (halfway
/// between its front-most and back-most points, normal to the nose's direction) would have:
/// the regions of a body whose head faces the other way, a face-sized patch on the back of
/// the head. Comparing a fitted body's data term under both asks the thermal image alone
/// which way its head faces.
pub fn head_regions(model: &BodyModel, turned: bool) -> Result<Vec<Region>, BodyError> {
    let shaped = model.shaped_phenotype::<f64>(&Phenotype::default())?;
    let rest = Pose::from_axis_angles(&vec![[0.0; 3]; model.n_joints()], shaped.joint_heads[0]);
    let posed = model.pose(&shaped, &rest)?;
    let kp = |name: &str| -> Result<Vector3<f64>, BodyError> {
        let i = model
            .asset
            .meta
            .keypoint_labels
            .iter()
            .position(|l| l == name)
            .ok_or_else(|| missing(format!("keypoint {name}")))?;
        Ok(posed.keypoints[i])
    };
    let ears = (kp("left_ear")? + kp("right_ear")?) / 2.0;
    let eyes = (kp("left_eye")? + kp("right_eye")?) / 2.0;
    let mut front = kp("nose")? - ears;
    front.z = 0.0;
    let front = front.normalize();
    let bone = |name: &str| {
        model
            .joint_index(name)
            .ok_or_else(|| missing(format!("bone {name}")))
    };
    let head = bone("head")?;
    let skin: Vec<usize> = SKIN_BONES
        .iter()
        .map(|n| bone(n))
        .collect::<Result<_, _>>()?;
    let k = model.asset.influences;
    // The face rule; with the head turned, applied to the vertex's mirror image across the
    // head's mid-plane (depth `2·mid − d`, same height).
    let (head_lo, head_hi) = (0..model.n_vertices())
        .filter(|&i| model.asset.skin_indices[i * k] as usize == head)
        .map(|i| (posed.vertices[i] - ears).dot(&front))
        .fold((f64::MAX, f64::MIN), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let mirror = turned.then_some(head_lo + head_hi);
    Ok((0..model.n_vertices())
        .map(|i| {
            let b = model.asset.skin_indices[i * k] as usize;
            let v = posed.vertices[i];
            if b == head {
                let d = (v - ears).dot(&front);
                let d = mirror.map_or(d, |two_mid| two_mid - d);
                if d > FACE_FRONT_M && v.z < eyes.z + HAIRLINE_ABOVE_EYES_M {
                    Region::Face
                } else {
                    Region::Hair
                }
            } else if skin.contains(&b) {
                Region::Skin
            } else {
                Region::Clothing
            }
        })
        .collect())
}

/// Per-triangle regions: the region at least two of its vertices share (else the first
/// vertex's).
pub fn triangle_regions(vertex: &[Region], triangles: &[[u32; 3]]) -> Vec<Region> {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| vertex[v as usize]);
            if b == c { b } else { a }
        })
        .collect()
}

/// What the long-wave infrared sees of a region: the range of its surface temperature indoors
/// (20–24 °C, a person at rest) and its emissivity. The simulator draws each person's
/// temperatures uniformly in these ranges; stage 2's radiometric fit uses them as priors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegionThermal {
    /// Surface temperature range, °C.
    pub temp_c: [f64; 2],
    /// LWIR emissivity.
    pub emissivity: f64,
}

/// [`RegionThermal`] per region, in [`Region::ALL`] order. Sources:
/// * skin emissivity 0.98 (Steketee 1973, *Phys. Med. Biol.* 18:686, 0.98–0.99 over 2–14 µm);
/// * face 33.5–35.5 °C and other bare skin 31–34.5 °C (extremities are the coolest skin):
///   the ranges of healthy adults at rest in a temperate room reviewed by Ring & Ammer 2012
///   (*Physiol. Meas.* 33:R33) and Fernández-Cuevas et al. 2015 (*Infrared Phys. Technol.*
///   71:28);
/// * clothing 27–31 °C: ISO 7730's clothing-surface temperature `t_cl` (Fanger's relation,
///   `t_cl ≈ 35.7 − 0.028 M − I_cl (R + C)`) for 0.5–1.0 clo, sedentary, 20–24 °C; textile
///   emissivity 0.95 (cotton ≈ 0.95–0.98, ISO 9920's radiative terms assume ≈ 0.95);
/// * hair 28–32 °C, emissivity 0.95: an engineering estimate, not a measurement — the same
///   relation with a hair layer of 0.3–0.7 clo over 34 °C scalp skin, keratin fibres taken to
///   emit like textiles. No published thermogram range for scalp hair was found.
pub const THERMAL: [RegionThermal; 4] = [
    RegionThermal {
        temp_c: [27.0, 31.0],
        emissivity: 0.95,
    },
    RegionThermal {
        temp_c: [31.0, 34.5],
        emissivity: 0.98,
    },
    RegionThermal {
        temp_c: [33.5, 35.5],
        emissivity: 0.98,
    },
    RegionThermal {
        temp_c: [28.0, 32.0],
        emissivity: 0.95,
    },
];

impl Region {
    /// Its [`RegionThermal`].
    pub fn thermal(self) -> RegionThermal {
        THERMAL[self.index()]
    }
}
