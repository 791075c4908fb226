//! Stage 2's per-run buffers ([`Scratch`]) and the body's height: the rest body of a height
//! slider, reshaped on the shape map's linear piece about the mean by an axpy.

use super::problem::Meet;
use super::radiometric::Scalars;
use super::{HumanProblem, phenotype, shaped_body};
use crate::ReconError;
use irmirror_body::Phenotype;
use irmirror_body::model::BodyGrad;
use irmirror_render::occupancy::{OccupancyGrad, SoftRenderer};
use nalgebra::Vector3;

/// Step of the central difference of the phenotype's shape map in the height slider (the map is
/// piecewise linear, so this is exact away from its knots and a subgradient on them).
const HEIGHT_STEP: f64 = 1e-4;

impl HumanProblem<'_> {
    /// Buffers reused across steps (allocation-free after the first step while the height
    /// stays; a new height reshapes the body), holding the problem's build.
    pub fn scratch(&self) -> Result<Scratch, ReconError> {
        let (shaped, mean_piece) = self.mean_piece(&self.build)?;
        // The BVH's topology comes from the rest body, whichever state a scratch sees first, so
        // results do not depend on which thread evaluates which candidate (refits move boxes,
        // never the tree).
        let renderer = Some(SoftRenderer::new(&shaped.vertices, &self.model.asset.faces));
        Ok(Scratch {
            shaped,
            build: self.build,
            height: super::HEIGHT_MEAN,
            off_mean: None,
            mean_piece,
            posed: self.model.posed_buffers(),
            renderer,
            occ_grad: OccupancyGrad::default(),
            body_grad: BodyGrad {
                rotations: vec![],
                translation: Vector3::zeros(),
                shape: vec![],
            },
            d_value: Vec::new(),
            meet: Meet::default(),
            scalars: None,
            data: 0.0,
        })
    }

    /// The rest body of `build` at the mean height, and the shape map's linear piece there.
    fn mean_piece(
        &self,
        build: &Phenotype,
    ) -> Result<(irmirror_body::ShapedBody<f64>, MeanPiece), ReconError> {
        let height = super::HEIGHT_MEAN;
        let shaped = shaped_body(self.model, build, height)?;
        let dz_dheight = self.dz_dheight(build, height)?;
        let mut direction = shaped.clone();
        irmirror_body::shape::direction_into(&self.model.asset, &dz_dheight, &mut direction);
        let piece = MeanPiece {
            dz_dheight,
            shaped: shaped.clone(),
            direction,
        };
        Ok((shaped, piece))
    }

    /// Makes `ws` hold `build` (nothing when it already does): a state's own build, which the
    /// search's build options vary (`search.builds`). The body is reshaped at the next
    /// [`Self::set_height`].
    pub(super) fn set_build(&self, ws: &mut Scratch, build: &Phenotype) -> Result<(), ReconError> {
        if ws.build == *build {
            return Ok(());
        }
        let (shaped, piece) = self.mean_piece(build)?;
        ws.shaped = shaped;
        ws.mean_piece = piece;
        ws.off_mean = None;
        ws.height = super::HEIGHT_MEAN;
        ws.build = *build;
        Ok(())
    }

    /// `∂z/∂h`: the shape coefficients' derivative in the height slider for `build`.
    fn dz_dheight(&self, build: &Phenotype, h: f64) -> Result<Vec<f64>, ReconError> {
        let (lo, hi) = ((h - HEIGHT_STEP).max(0.0), (h + HEIGHT_STEP).min(1.0));
        let zp = self.model.shape_coefficients(&phenotype(build, hi))?;
        let zm = self.model.shape_coefficients(&phenotype(build, lo))?;
        Ok(zp
            .iter()
            .zip(&zm)
            .map(|(p, m)| (p - m) / (hi - lo))
            .collect())
    }

    /// Reshapes `ws` for height slider `h` (nothing when it already holds it). The shape
    /// coefficients are piecewise linear in the slider: on the mean's piece (the fits' heights,
    /// within the prior's 3σ) the body is the mean's plus `h − mean` times its derivative
    /// exactly, an axpy instead of the 32-coefficient basis, which cost ≈ 8 % of a refinement
    /// and its VJP as much again. Anchored at the mean, not the last height, so the body at `h`
    /// does not depend on which states a scratch saw before (determinism).
    pub(super) fn set_height(&self, ws: &mut Scratch, h: f64) -> Result<(), ReconError> {
        if ws.height == h {
            return Ok(());
        }
        let dz = self.dz_dheight(&ws.build, h)?;
        let z = self.model.shape_coefficients(&phenotype(&ws.build, h))?;
        let mean = &ws.mean_piece;
        // The derivative by differences carries rounding of ≈ 1e-12; a knot changes it by O(1).
        let on_mean_piece = dz
            .iter()
            .zip(&mean.dz_dheight)
            .all(|(a, b)| (a - b).abs() <= 1e-9 * (1.0 + b.abs()));
        if on_mean_piece {
            let t = h - super::HEIGHT_MEAN;
            let axpy = |out: &mut [Vector3<f64>], a: &[Vector3<f64>], d: &[Vector3<f64>]| {
                for ((o, a), d) in out.iter_mut().zip(a).zip(d) {
                    *o = a + d * t;
                }
            };
            let (s, a, d) = (&mut ws.shaped, &mean.shaped, &mean.direction);
            axpy(&mut s.vertices, &a.vertices, &d.vertices);
            axpy(&mut s.joint_heads, &a.joint_heads, &d.joint_heads);
            axpy(&mut s.joint_tails, &a.joint_tails, &d.joint_tails);
            s.z = z;
            ws.off_mean = None;
        } else {
            irmirror_body::shape::shape_into(&self.model.asset, &z, &mut ws.shaped);
            let dir = ws.off_mean.get_or_insert_with(|| mean.direction.clone());
            irmirror_body::shape::direction_into(&self.model.asset, &dz, dir);
        }
        ws.height = h;
        Ok(())
    }
}

/// Buffers of [`HumanProblem::loss_grad`], reused across steps.
pub struct Scratch {
    pub(super) shaped: irmirror_body::ShapedBody<f64>,
    /// The build `shaped` was made for (the height slider aside).
    pub(super) build: Phenotype,
    /// The height slider `shaped` was made for.
    pub(super) height: f64,
    /// The rest body's derivative in the slider at `height` when it is off the mean's piece.
    pub(super) off_mean: Option<irmirror_body::ShapedBody<f64>>,
    /// The linear piece of the shape map that holds the mean height.
    pub(super) mean_piece: MeanPiece,
    pub(super) posed: irmirror_body::PosedBody<f64>,
    pub(super) renderer: Option<SoftRenderer<f64>>,
    pub(super) occ_grad: OccupancyGrad<f64>,
    pub(super) body_grad: BodyGrad<f64>,
    pub(super) d_value: Vec<f64>,
    /// Where each batch ray meets the body (radiometric term).
    pub(super) meet: Meet,
    /// The radiometric scalars of the last evaluation (when that term is on).
    pub(super) scalars: Option<Scalars>,
    /// The data term of the last evaluation.
    pub(super) data: f64,
}

/// The shape map's linear piece about [`super::HEIGHT_MEAN`]: its derivative, and the rest
/// body there with its derivative through the shape basis.
pub(super) struct MeanPiece {
    dz_dheight: Vec<f64>,
    shaped: irmirror_body::ShapedBody<f64>,
    direction: irmirror_body::ShapedBody<f64>,
}

impl Scratch {
    /// The rest body's derivative in the height slider at the height it holds.
    pub(super) fn height_direction(&self) -> &irmirror_body::ShapedBody<f64> {
        self.off_mean.as_ref().unwrap_or(&self.mean_piece.direction)
    }

    /// Keeps, from the next evaluation on, the triangle each ray hit at the last one (the hit
    /// point still moves on its plane). Which triangle a ray hits first changes where one body
    /// part passes behind another, a jump without a gradient; with it frozen the radiometric
    /// loss is smooth, which a finite-difference check needs.
    pub fn freeze_hits(&mut self, frozen: bool) {
        self.meet.frozen = frozen;
    }
}
