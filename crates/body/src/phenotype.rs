//! Phenotype → blendshape coefficients, exactly as Anny (ANNY_SPEC.md §6.3).
//!
//! | parameter | range | meaning |
//! |---|---|---|
//! | `gender` | [0, 1] | 0 male … 1 female (reversed w.r.t. MakeHuman) |
//! | `age` | [2/3, 1] in the adult asset | 2/3 ≈ 16 y (young) … 0.83 ≈ 64 y … 1 ≈ 110 y (old) |
//! | `muscle` | [0, 1] | min, average (0.5), max |
//! | `weight` | [0, 1] | min, average (0.5), max |
//! | `height` | [0, 1] | min … max target; 0.5 is tall (1.90 m male); adult means ≈ 0.39 male, 0.35 female |
//! | `proportions` | [0, 1] | 0 ideal … 1 uncommon |
//!
//! Race is fixed at 1/3 each. None of these is differentiable in the optimiser: the shape
//! coefficients `z` (see [`crate::BodyModel::shape_coefficients`]) are.

use crate::{BodyAsset, BodyError};
use serde::{Deserialize, Serialize};

/// Names of the shape variables, in factor-table order.
pub const VARIABLES: [&str; 7] = [
    "gender",
    "age",
    "muscle",
    "weight",
    "height",
    "proportions",
    "race",
];

/// Anny's phenotype parameters, each in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Phenotype {
    /// 0 = male, 1 = female.
    pub gender: f64,
    /// Anny age; adults are [2/3, 1].
    pub age: f64,
    /// Muscle tone.
    pub muscle: f64,
    /// Body mass.
    pub weight: f64,
    /// Height slider (0.5 is tall).
    pub height: f64,
    /// 0 ideal … 1 uncommon proportions.
    pub proportions: f64,
}

impl Default for Phenotype {
    /// A mid-aged (≈ 40 y), androgynous adult of average build and ≈ 1.7 m.
    fn default() -> Self {
        Self {
            gender: 0.5,
            age: 0.8,
            muscle: 0.5,
            weight: 0.5,
            height: 0.37,
            proportions: 0.5,
        }
    }
}

impl Phenotype {
    /// The six values in factor-table order.
    pub fn values(&self) -> [f64; 6] {
        [
            self.gender,
            self.age,
            self.muscle,
            self.weight,
            self.height,
            self.proportions,
        ]
    }

    /// Builds a phenotype from the six values in factor-table order.
    pub fn from_values(v: [f64; 6]) -> Self {
        Self {
            gender: v[0],
            age: v[1],
            muscle: v[2],
            weight: v[3],
            height: v[4],
            proportions: v[5],
        }
    }

    /// Checks every value is finite, in [0, 1] and inside the asset's anchor range.
    pub fn validate(&self, asset: &BodyAsset) -> Result<(), BodyError> {
        self.validate_with(&asset.meta.anchors)
    }

    /// [`Self::validate`] against explicit anchors (one list per variable).
    pub fn validate_with(&self, anchors: &[Vec<f64>]) -> Result<(), BodyError> {
        for (k, x) in self.values().into_iter().enumerate() {
            let field = format!("phenotype.{}", VARIABLES[k]);
            if !x.is_finite() || !(0.0..=1.0).contains(&x) {
                return Err(BodyError::param(field, format!("{x} is outside [0, 1]")));
            }
            let a = &anchors[k];
            let (lo, hi) = (a[0], a[a.len() - 1]);
            if x < lo - 1e-12 || x > hi + 1e-12 {
                return Err(BodyError::param(
                    field,
                    format!(
                        "{x} is outside this asset's range [{lo:.4}, {hi:.4}] (the shipped asset covers adults)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The blendshape coefficients `c_b = Π_var w_var[anchor]` (after [`Self::validate`]).
    pub fn coefficients(&self, asset: &BodyAsset) -> Result<Vec<f64>, BodyError> {
        self.coefficients_with(&asset.meta.anchors, &asset.shape_factor_table)
    }

    /// [`Self::coefficients`] for explicit anchors and factor table.
    pub fn coefficients_with(
        &self,
        anchors: &[Vec<f64>],
        table: &[[i8; 7]],
    ) -> Result<Vec<f64>, BodyError> {
        self.validate_with(anchors)?;
        let weights: Vec<Vec<f64>> = self
            .values()
            .iter()
            .enumerate()
            .map(|(k, &x)| anchor_weights(x, &anchors[k]))
            .collect();
        Ok(table
            .iter()
            .map(|row| {
                row.iter()
                    .enumerate()
                    .filter(|(_, a)| **a >= 0)
                    .fold(1.0, |c, (k, &a)| {
                        // Race weights are fixed at 1/3 each.
                        c * if k == 6 {
                            1.0 / 3.0
                        } else {
                            weights[k][a as usize]
                        }
                    })
            })
            .collect())
    }
}

/// Piecewise-linear interpolation weights of `x` over `anchors` (clamped), as Anny.
pub fn anchor_weights(x: f64, anchors: &[f64]) -> Vec<f64> {
    let n = anchors.len();
    let mut w = vec![0.0; n];
    if n == 1 {
        w[0] = 1.0;
        return w;
    }
    let x = x.clamp(anchors[0], anchors[n - 1]);
    let i = anchors
        .iter()
        .position(|&a| a >= x)
        .unwrap_or(n - 1)
        .clamp(1, n - 1);
    let t = (x - anchors[i - 1]) / (anchors[i] - anchors[i - 1]);
    w[i - 1] = 1.0 - t;
    w[i] = t;
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchor_weights_interpolate_and_clamp() {
        let a = [0.0, 0.5, 1.0];
        assert_eq!(anchor_weights(0.25, &a), vec![0.5, 0.5, 0.0]);
        assert_eq!(anchor_weights(1.0, &a), vec![0.0, 0.0, 1.0]);
        assert_eq!(anchor_weights(-3.0, &a), vec![1.0, 0.0, 0.0]);
        let age = [2.0 / 3.0, 1.0];
        let w = anchor_weights(0.75, &age);
        assert!((w[0] - 0.75).abs() < 1e-12 && (w[1] - 0.25).abs() < 1e-12);
        assert_eq!(anchor_weights(2.0 / 3.0, &age), vec![1.0, 0.0]);
    }
}
