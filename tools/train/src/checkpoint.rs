//! Checkpoints of a training run: the complete state (weights, Adam moments and step count, epoch,
//! best-on-validation weights, normalisation, history, RNG position) in one safetensors file, so that a
//! resumed run continues exactly as an uninterrupted one.
//!
//! Tensors: `params`, `adam_m`, `adam_v`, `norm_mean`, `norm_scale` (f32), `best_params` (f32, when a
//! best exists) and `history` (f64, `[epochs, 6]`: epoch, train loss, val loss, val RMSE, seconds,
//! is-best; NaN for absent values). Metadata key [`STATE_KEY`] holds a JSON [`State`]; floats that
//! decide the run are stored as bit patterns so no decimal round trip can change them. The RNG needs no
//! stored stream: every draw is keyed by (seed, epoch, step), which the state holds. The data are not
//! stored: a SHA-256 fingerprint of them is, and resuming with different data is refused.
//!
//! This is not the deployable model format (`.fwt`, `frictionless::weights`).

use std::collections::HashMap;
use std::path::Path;

use frictionless::mlp::Normalisation;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};

use super::{
    Adam, Best, Dataset, EpochReport, Layout, TrainConfig, TrainError, Trainer, check_config,
    fingerprint,
};

/// Metadata key holding the JSON state.
pub const STATE_KEY: &str = "frictionless.train_checkpoint";
/// Format version written and accepted.
const VERSION: u32 = 1;

/// The scalar part of a checkpoint.
#[derive(Serialize, Deserialize)]
struct State {
    version: u32,
    config: TrainConfig,
    /// Bit patterns of `dropout`, `lambda`, `lr` (authoritative over the decimal copies in `config`).
    config_f32_bits: [u32; 3],
    abort_loss_bits: Option<u32>,
    sizes: Vec<usize>,
    adam_t: u64,
    epochs_done: usize,
    best_epoch: Option<usize>,
    best_val_rmse_bits: Option<u64>,
    since_best: usize,
    fingerprint: String,
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn err(path: &Path, detail: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        detail: detail.to_string(),
    }
}

fn opt(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

fn unopt(v: f64) -> Option<f64> {
    (!v.is_nan()).then_some(v)
}

impl Trainer {
    /// Writes the complete run state to `path` (via a temporary file and a rename).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        let c = &self.cfg;
        let state = State {
            version: VERSION,
            config: c.clone(),
            config_f32_bits: [c.dropout.to_bits(), c.lambda.to_bits(), c.lr.to_bits()],
            abort_loss_bits: c.abort_loss.map(f32::to_bits),
            sizes: self.layout.sizes.clone(),
            adam_t: self.adam.t,
            epochs_done: self.epochs_done,
            best_epoch: self.best.as_ref().map(|b| b.epoch),
            best_val_rmse_bits: self.best.as_ref().map(|b| b.val_rmse_nm.to_bits()),
            since_best: self.since_best,
            fingerprint: self.fingerprint.clone(),
        };
        let hist: Vec<f64> = self
            .history
            .iter()
            .flat_map(|h| {
                [
                    h.epoch as f64,
                    h.train_loss,
                    opt(h.val_loss),
                    opt(h.val_rmse_nm),
                    h.seconds,
                    f64::from(u8::from(h.is_best)),
                ]
            })
            .collect();
        let n = self.layout.n_params;
        let mut blobs: Vec<(&str, Dtype, Vec<usize>, Vec<u8>)> = vec![
            ("params", Dtype::F32, vec![n], f32_bytes(&self.params)),
            ("adam_m", Dtype::F32, vec![n], f32_bytes(&self.adam.m)),
            ("adam_v", Dtype::F32, vec![n], f32_bytes(&self.adam.v)),
            (
                "norm_mean",
                Dtype::F32,
                vec![self.norm.mean.len()],
                f32_bytes(&self.norm.mean),
            ),
            (
                "norm_scale",
                Dtype::F32,
                vec![self.norm.scale.len()],
                f32_bytes(&self.norm.scale),
            ),
            (
                "history",
                Dtype::F64,
                vec![self.history.len(), 6],
                f64_bytes(&hist),
            ),
        ];
        if let Some(b) = &self.best {
            blobs.push(("best_params", Dtype::F32, vec![n], f32_bytes(&b.params)));
        }
        let views = blobs
            .iter()
            .map(|(name, dt, shape, bytes)| {
                Ok((*name, TensorView::new(*dt, shape.clone(), bytes)?))
            })
            .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
            .map_err(|e| err(path, e))?;
        let json = serde_json::to_string(&state).map_err(|e| err(path, e))?;
        let meta = HashMap::from([(STATE_KEY.to_string(), json)]);
        let bytes = safetensors::serialize(views, Some(meta)).map_err(|e| err(path, e))?;
        // Atomic, never over a device or through a symlink; errors name `path`, never the
        // temporary file beside it.
        frictionless::output_file::write(path, &bytes)
            .map_err(|e| err(path, format!("cannot write: {e}")))
    }

    /// Restores a run saved by [`Trainer::save_checkpoint`]. `train` and `val` must be the same data
    /// as in the original run (checked by fingerprint). Training continues with [`Trainer::train`].
    pub fn resume(
        path: &Path,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
    ) -> Result<Self, TrainError> {
        let bytes = frictionless::regular_file::read(path, u64::MAX)
            .map_err(|e| err(path, format!("cannot read: {e}")))?;
        let st = SafeTensors::deserialize(&bytes).map_err(|e| err(path, e))?;
        let state = read_state(path, &bytes)?;
        let mut cfg = state.config;
        cfg.dropout = f32::from_bits(state.config_f32_bits[0]);
        cfg.lambda = f32::from_bits(state.config_f32_bits[1]);
        cfg.lr = f32::from_bits(state.config_f32_bits[2]);
        cfg.abort_loss = state.abort_loss_bits.map(f32::from_bits);
        check_config(&cfg).map_err(|e| err(path, e))?;
        check_data(path, &state.sizes, &state.fingerprint, &cfg, train, val)?;
        let layout = Layout::new(&state.sizes);
        let f32s = |name: &str, len: usize| f32_tensor(&st, path, name, len);
        let n = layout.n_params;
        let params = f32s("params", n)?;
        let adam = Adam {
            m: f32s("adam_m", n)?,
            v: f32s("adam_v", n)?,
            t: state.adam_t,
        };
        let norm = Normalisation {
            mean: f32s("norm_mean", train.n_inputs)?,
            scale: f32s("norm_scale", train.n_inputs)?,
        };
        if let Some(i) = norm
            .scale
            .iter()
            .position(|s| !(s.is_finite() && *s != 0.0))
        {
            return Err(err(
                path,
                format!(
                    "norm_scale[{i}] = {} is not a finite non-zero number",
                    norm.scale[i]
                ),
            ));
        }
        let best = match (state.best_epoch, state.best_val_rmse_bits) {
            (Some(epoch), Some(bits)) => Some(Best {
                params: f32s("best_params", n)?,
                val_rmse_nm: f64::from_bits(bits),
                epoch,
            }),
            _ => None,
        };
        let history = read_history(&st, path)?;
        let mut t = Trainer::assemble(cfg, layout, norm, train, val, params, adam)?;
        t.epochs_done = state.epochs_done;
        t.best = best;
        t.since_best = state.since_best;
        t.history = history;
        Ok(t)
    }
}

/// The JSON state from the metadata, checked to be of this build's format version.
fn read_state(path: &Path, bytes: &[u8]) -> Result<State, TrainError> {
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| err(path, e))?;
    let json = meta
        .metadata()
        .as_ref()
        .and_then(|m| m.get(STATE_KEY))
        .ok_or_else(|| {
            err(
                path,
                format!("no metadata key {STATE_KEY:?}: not a training checkpoint"),
            )
        })?;
    let state: State = serde_json::from_str(json).map_err(|e| err(path, format!("state: {e}")))?;
    if state.version != VERSION {
        return Err(err(
            path,
            format!("version {} (this build reads {VERSION})", state.version),
        ));
    }
    Ok(state)
}

/// The given data are valid and are the checkpointed run's: the stored layer `sizes` follow from
/// `cfg` and the data's input count, and the data's fingerprint is `fingerprint_stored`.
fn check_data(
    path: &Path,
    sizes: &[usize],
    fingerprint_stored: &str,
    cfg: &TrainConfig,
    train: &Dataset<'_>,
    val: Option<&Dataset<'_>>,
) -> Result<(), TrainError> {
    train.validate("train")?;
    if let Some(v) = val {
        v.validate("validation")?;
    }
    let mut want_sizes = vec![train.n_inputs];
    want_sizes.extend(&cfg.hidden);
    want_sizes.push(1);
    if sizes.first() != want_sizes.first() {
        return Err(err(
            path,
            format!(
                "n_inputs = {:?} in the checkpoint, the given data have n_inputs = {}",
                sizes.first(),
                train.n_inputs
            ),
        ));
    }
    if sizes != want_sizes {
        return Err(err(
            path,
            format!(
                "layer sizes {:?} do not match config/data {:?}",
                sizes, want_sizes
            ),
        ));
    }
    if fingerprint(train, val) != fingerprint_stored {
        return Err(err(
            path,
            "the given training/validation data differ from the checkpointed run's (SHA-256 fingerprint mismatch)",
        ));
    }
    Ok(())
}

/// The F32 tensor `name` of length `len`.
fn f32_tensor(
    st: &SafeTensors<'_>,
    path: &Path,
    name: &str,
    len: usize,
) -> Result<Vec<f32>, TrainError> {
    let t = st
        .tensor(name)
        .map_err(|e| err(path, format!("tensor {name}: {e}")))?;
    if t.dtype() != Dtype::F32 || t.shape() != [len] {
        return Err(err(
            path,
            format!(
                "tensor {name}: {:?} {:?}, expected F32 [{len}]",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    Ok(t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// The `history` tensor (F64 `[epochs, 6]`) as epoch reports.
fn read_history(st: &SafeTensors<'_>, path: &Path) -> Result<Vec<EpochReport>, TrainError> {
    let h = st
        .tensor("history")
        .map_err(|e| err(path, format!("tensor history: {e}")))?;
    if h.dtype() != Dtype::F64 || h.shape().len() != 2 || h.shape()[1] != 6 {
        return Err(err(
            path,
            format!(
                "tensor history: {:?} {:?}, expected F64 [n, 6]",
                h.dtype(),
                h.shape()
            ),
        ));
    }
    let hv: Vec<f64> = h
        .data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8-byte chunk")))
        .collect();
    Ok(hv
        .chunks_exact(6)
        .map(|r| EpochReport {
            epoch: r[0] as usize,
            train_loss: r[1],
            val_loss: unopt(r[2]),
            val_rmse_nm: unopt(r[3]),
            seconds: r[4],
            is_best: r[5] != 0.0,
        })
        .collect())
}
