//! The shared [`Adam`] of `irmirror_geom::optim` applied to a candle variable: one parameter
//! group per variable, with its own learning rate and step count. Latent inference steps with
//! it (the placed fit steps the same `Adam` on its hand-written gradient); gradients come from
//! candle's reverse mode, the moments live in f64.

use crate::SdfError;
use candle_core::backprop::GradStore;
use candle_core::{DType, Device, Tensor, Var};
use irmirror_geom::optim::{Adam, AdamParams};

/// A candle variable stepped by [`Adam`].
pub(crate) struct VarAdam {
    var: Var,
    adam: Adam,
    lr: Vec<f64>,
    step: Vec<f64>,
}

impl VarAdam {
    /// Adam state for `var` at learning rate `lr`.
    pub(crate) fn new(var: &Var, lr: f64) -> Self {
        let n = var.elem_count();
        // ε = 1e-8: the constant of candle's AdamW, which these fits used before.
        let params = AdamParams {
            eps: 1e-8,
            ..AdamParams::default()
        };
        Self {
            var: var.clone(),
            adam: Adam::new(n, params),
            lr: vec![lr; n],
            step: vec![0.0; n],
        }
    }

    /// One step with the learning rate scaled by `decay` (a variable the loss did not reach
    /// gets a zero gradient).
    pub(crate) fn step(&mut self, grads: &GradStore, decay: f64) -> Result<(), SdfError> {
        let flat = |t: &Tensor| t.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>();
        let grad = match grads.get(&self.var) {
            Some(g) => flat(g)?,
            None => vec![0.0; self.step.len()],
        };
        self.adam.step(&grad, &self.lr, decay, &mut self.step);
        let value: Vec<f64> = flat(self.var.as_tensor())?
            .iter()
            .zip(&self.step)
            .map(|(x, s)| x - s)
            .collect();
        let t =
            Tensor::from_vec(value, self.var.shape(), &Device::Cpu)?.to_dtype(self.var.dtype())?;
        self.var.set(&t)?;
        Ok(())
    }
}
