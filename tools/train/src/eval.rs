//! Batched evaluation of a trained network over a whole dataset (the same GEMM path as training,
//! eval mode), and the RMSE metric.
//!
//! This is for offline evaluation and tools; it is not the real-time inference kernel
//! (`frictionless::kernel::Mlp`), which works one sample at a time without allocation.

use frictionless::mlp::{MlpShapeError, MlpWeights, Normalisation};

use super::TrainError;
use super::net::{self, Layout, Workspace};

/// Rows per GEMM batch.
const EVAL_ROWS: usize = 4096;

/// Batched eval-mode inference for an [`MlpWeights`].
pub struct Predictor {
    layout: Layout,
    params: Vec<f32>,
    norm: Normalisation,
    ws: Workspace,
    threads: usize,
    pool: rayon::ThreadPool,
}

impl Predictor {
    /// Builds a predictor using `threads` worker threads (≥ 1). The weights are validated first.
    pub fn new(weights: &MlpWeights, threads: usize) -> Result<Self, PredictError> {
        weights.validate()?;
        let layout = Layout::new(&weights.sizes());
        let mut params = vec![0f32; layout.n_params];
        for (k, l) in weights.layers.iter().enumerate() {
            params[layout.w_off[k]..layout.w_off[k] + l.weight.len()].copy_from_slice(&l.weight);
            params[layout.b_off[k]..layout.b_off[k] + l.bias.len()].copy_from_slice(&l.bias);
        }
        let threads = threads.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|source| PredictError::Threads(TrainError::Threads { threads, source }))?;
        Ok(Self {
            ws: Workspace::new(&layout, EVAL_ROWS),
            layout,
            params,
            norm: weights.norm.clone(),
            threads,
            pool,
        })
    }

    /// Predictions (Nm) for raw row-major features `x` (`n_rows × n_inputs`).
    pub fn predict(&mut self, x: &[f32]) -> Result<Vec<f32>, PredictError> {
        let ni = self.layout.sizes[0];
        if !x.len().is_multiple_of(ni) {
            return Err(PredictError::Shape {
                values: x.len(),
                n_inputs: ni,
            });
        }
        let n_rows = x.len() / ni;
        let mut out = Vec::with_capacity(n_rows);
        let (layout, params, norm, ws, threads) = (
            &self.layout,
            &self.params,
            &self.norm,
            &mut self.ws,
            self.threads,
        );
        self.pool.install(|| {
            for start in (0..n_rows).step_by(EVAL_ROWS) {
                let n = EVAL_ROWS.min(n_rows - start);
                for (dst, src) in ws.x[..n * ni]
                    .chunks_exact_mut(ni)
                    .zip(x[start * ni..(start + n) * ni].chunks_exact(ni))
                {
                    for (((d, &s), m), sc) in
                        dst.iter_mut().zip(src).zip(&norm.mean).zip(&norm.scale)
                    {
                        *d = (s - m) / sc;
                    }
                }
                net::forward(layout, params, ws, n, None, threads);
                out.extend_from_slice(&ws.act[layout.n_layers() - 1][..n]);
            }
        });
        Ok(out)
    }
}

/// Why batched prediction failed.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    /// The weights are malformed.
    #[error("invalid weights: {0}")]
    Weights(#[from] MlpShapeError),
    /// The input length is not a whole number of rows.
    #[error("{values} input values is not a multiple of {n_inputs} inputs per row")]
    Shape {
        /// Values given.
        values: usize,
        /// Inputs per row.
        n_inputs: usize,
    },
    /// The thread pool could not be built.
    #[error("{0}")]
    Threads(TrainError),
}

/// Root-mean-square error between predictions and targets (f64 accumulation); `NaN` if the lengths
/// differ or both are empty.
pub fn rmse(pred: &[f32], target: &[f32]) -> f64 {
    if pred.len() != target.len() || pred.is_empty() {
        return f64::NAN;
    }
    let sq: f64 = pred
        .iter()
        .zip(target)
        .map(|(&p, &t)| ((p - t) as f64).powi(2))
        .sum();
    (sq / pred.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rmse_by_hand() {
        assert!((rmse(&[1.0, 2.0], &[1.0, 4.0]) - 2f64.sqrt()).abs() < 1e-12);
        assert!(rmse(&[1.0], &[1.0, 2.0]).is_nan());
    }
}
