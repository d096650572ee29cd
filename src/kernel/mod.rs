//! Allocation-free single-sample MLP inference.
//!
//! (skeleton — a straightforward implementation that defines the API; the blocked, dispatched kernel
//! replaces its internals)

use crate::mlp::{MlpShapeError, MlpWeights, StorageDtype};

/// An MLP laid out for inference. Built once (allocates), then [`Mlp::forward`] never allocates.
#[derive(Clone, Debug)]
pub struct Mlp {
    w: MlpWeights,
    dtype: StorageDtype,
    a: Vec<f32>,
    b: Vec<f32>,
}

impl Mlp {
    /// Lays out `w` for inference with the given storage precision.
    pub fn new(w: &MlpWeights, dtype: StorageDtype) -> Result<Self, MlpShapeError> {
        w.validate()?;
        let m = w.sizes().into_iter().max().unwrap_or(1);
        Ok(Self { w: w.clone(), dtype, a: vec![0.0; m], b: vec![0.0; m] })
    }
    /// Number of raw inputs.
    pub fn n_inputs(&self) -> usize {
        self.w.n_inputs()
    }
    /// Storage precision.
    pub fn dtype(&self) -> StorageDtype {
        self.dtype
    }
    /// One inference on a raw (un-normalised) input; `x.len()` must equal [`Mlp::n_inputs`].
    /// Returns the single output (joint-side friction, Nm).
    pub fn forward(&mut self, x: &[f32]) -> f32 {
        let n = self.w.n_inputs();
        for i in 0..n {
            self.a[i] = (x[i] - self.w.norm.mean[i]) / self.w.norm.scale[i];
        }
        for l in &self.w.layers {
            for o in 0..l.n_out {
                let mut acc = l.bias[o];
                for i in 0..l.n_in {
                    acc += l.weight[o * l.n_in + i] * self.a[i];
                }
                self.b[o] = if l.activation == crate::mlp::Activation::Relu { acc.max(0.0) } else { acc };
            }
            std::mem::swap(&mut self.a, &mut self.b);
        }
        self.a[0]
    }
}
