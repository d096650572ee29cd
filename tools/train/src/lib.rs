//! # `frictionless-train`: the PINN training engine (hand-written MLP trainer)
//!
//! Crate table: `tools/train`; depends on `frictionless` and `frictionless-dataset` (gemm, rayon,
//! safetensors for checkpoints; no iceoryx2, no plotters); used by `frictl` (`train`, `search`, `eval`).
//!
//! Trains the paper's friction network — `n_in → 1–4 hidden ReLU layers (dropout after each) → 1`
//! linear output — on in-memory arrays, with the physics-informed loss
//! `L = (1 − λ)·MSE(τ̂, τ_F label) + λ·MSE(τ̂, τ_F,SCV)`, where `τ_F,SCV` is a per-sample target the caller
//! precomputes from the fitted SCV model. Adam (torch defaults and bias correction), mean/IQR input
//! normalisation fitted on the training split, U(±1/√fan_in) init like torch, best-on-validation weights,
//! optional early stopping, per-epoch reports through a callback, and checkpoint/resume that reproduces
//! an uninterrupted run bit for bit. The result is a [`frictionless::mlp::MlpWeights`] (PyTorch order,
//! normalisation included) ready for `frictionless::weights::write_file`.
//!
//! **Why hand-written, not a framework:** the model and loss are fixed, so the trainer is about eight
//! GEMM calls per step plus a few fused elementwise passes. The GEMMs are the well-exercised `gemm`
//! crate (the kernel under candle and burn); only the glue is ours. The comparison with PyTorch, burn
//! and candle that led here is in `docs/decisions.md` (Training); current speed in
//! `docs/performance.md`.
//!
//! **Determinism:** one seed drives everything through counter-based streams (see `rng`), the
//! elementwise passes use fixed row chunks, reductions run in a fixed order and `gemm` splits work only
//! over output tiles, so the same seed and data give bit-identical weights.
//!
//! Around the engine: [`data`] builds input windows through the daemon's own `History` and splits
//! whole chunks into train/validation/test; [`pipeline`] reads datasets and the SCV fit, runs the
//! trainer and builds the `.fwt` and the JSON report (`frictl train`); [`search`] is the parallel,
//! resumable random search (`frictl search`); [`distill`] trains a smaller student on a teacher
//! (`frictl distill`), from scratch or from the teacher narrowed by [`prune`]. The engine itself does **not** read files or fit the SCV
//! model. Entry points: [`Trainer::new`] / [`Trainer::resume`], [`Trainer::train`],
//! [`Trainer::save_checkpoint`], [`Predictor`] and [`rmse`].
//!
//! ## Example: train a small network on synthetic friction data, run it on the core's kernel
//! ```
//! use std::ops::ControlFlow;
//! use frictionless::kernel::Mlp;
//! use frictionless::mlp::StorageDtype;
//! use frictionless_train::{TrainConfig, Trainer, rmse, synthetic};
//!
//! // Rows of 4 velocities + 4 current-like values (H = 4); label = SCV + history terms + noise.
//! let train = synthetic::friction_task(2_000, 4, 1);
//! let val = synthetic::friction_task(500, 4, 2);
//! let cfg = TrainConfig {
//!     hidden: vec![16, 16],
//!     dropout: 0.0,
//!     lambda: 0.1, // weight of the SCV prior in the loss
//!     lr: 3e-3,
//!     batch_size: 128,
//!     epochs: 15,
//!     threads: 1,
//!     ..TrainConfig::default()
//! };
//! let mut trainer = Trainer::new(cfg, &train.dataset(), Some(&val.dataset()))?;
//! let out = trainer.train(|_epoch| ControlFlow::Continue(()))?;
//! let first = out.history[0].val_rmse_nm.expect("validation data given");
//! let best = out.best_val_rmse_nm.expect("validation data given");
//! assert!(best < 0.7 * first, "validation RMSE {first} → {best} Nm");
//!
//! // The result (normalisation included) runs on the kernel frictiond uses.
//! let mut mlp = Mlp::new(&out.weights, StorageDtype::F32)?;
//! let pred: Vec<f32> = val.x.chunks(val.n_inputs).map(|row| mlp.forward(row)).collect();
//! assert!((rmse(&pred, &val.y_label_nm) - best).abs() < 1e-3 * best.max(1e-3));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

mod checkpoint;
pub mod data;
pub mod distill;
mod eval;
mod net;
mod norm;
pub mod pipeline;
pub mod prune;
mod rng;
pub mod search;
pub mod synthetic;

pub use eval::{PredictError, Predictor, rmse};
pub use norm::{MIN_IQR, fit_normalisation};

use std::ops::{ControlFlow, Range};
use std::path::PathBuf;
use std::time::Instant;

use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, limits};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use net::{Dropout, Layout, Workspace};

/// Hyper-parameters of a training run (paper Table II names in the docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Hidden layer widths, 1 to 4 layers (paper ankle roll: `[268, 215]`).
    pub hidden: Vec<usize>,
    /// Dropout probability after each hidden layer, in [0, 1) (paper: 0.07).
    pub dropout: f32,
    /// Weight λ of the SCV term of the loss, in [0, 1] (paper: 0.164).
    pub lambda: f32,
    /// Adam learning rate (paper: 7.6e-4).
    pub lr: f32,
    /// Rows per step (paper: 4316). The last batch of an epoch may be smaller.
    pub batch_size: usize,
    /// Total epochs (paper: 350).
    pub epochs: usize,
    /// Seed of every random draw (init, shuffles, dropout).
    pub seed: u64,
    /// Worker threads of the trainer's own rayon pool (GEMMs and elementwise passes), ≥ 1.
    pub threads: usize,
    /// Stop after this many epochs without a better validation RMSE (`None`: run all epochs).
    pub patience: Option<usize>,
    /// Abort when an epoch's training loss exceeds this (the authors use 1000); `None`: never.
    pub abort_loss: Option<f32>,
}

impl Default for TrainConfig {
    /// The paper's ankle-roll run (Table II) on 2 threads, seed 0.
    fn default() -> Self {
        Self {
            hidden: vec![268, 215],
            dropout: 0.07,
            lambda: 0.164,
            lr: 7.6e-4,
            batch_size: 4316,
            epochs: 350,
            seed: 0,
            threads: 2,
            patience: None,
            abort_loss: Some(1000.0),
        }
    }
}

/// Borrowed training or validation data: row-major raw features and the two per-sample targets.
#[derive(Clone, Copy, Debug)]
pub struct Dataset<'a> {
    /// Raw (un-normalised) features, row-major `n_rows × n_inputs`.
    pub x: &'a [f32],
    /// Friction label τ_F per row, joint side, Nm.
    pub y_label_nm: &'a [f32],
    /// SCV prior τ_F,SCV per row (evaluated by the caller on the row's joint velocity), Nm.
    pub y_scv_nm: &'a [f32],
    /// Features per row.
    pub n_inputs: usize,
}

impl Dataset<'_> {
    /// Number of rows (valid only after [`Dataset::validate`]).
    pub fn n_rows(&self) -> usize {
        self.y_label_nm.len()
    }

    /// Checks lengths and finiteness; `name` ("train", "validation") goes into the error.
    pub fn validate(&self, name: &'static str) -> Result<(), TrainError> {
        let n = self.y_label_nm.len();
        if self.n_inputs == 0 || self.n_inputs > limits::MAX_INPUTS {
            return Err(TrainError::Config(format!(
                "n_inputs = {} is outside 1..={}",
                self.n_inputs,
                limits::MAX_INPUTS
            )));
        }
        if n == 0 {
            return Err(TrainError::Data {
                set: name,
                what: "y_label_nm".into(),
                detail: "no rows".into(),
            });
        }
        let len_err = |what: &str, got: usize, want: usize| TrainError::Data {
            set: name,
            what: what.into(),
            detail: format!("has {got} values, expected {want}"),
        };
        if self.x.len() != n * self.n_inputs {
            return Err(len_err("x", self.x.len(), n * self.n_inputs));
        }
        if self.y_scv_nm.len() != n {
            return Err(len_err("y_scv_nm", self.y_scv_nm.len(), n));
        }
        for (what, v) in [
            ("x", self.x),
            ("y_label_nm", self.y_label_nm),
            ("y_scv_nm", self.y_scv_nm),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(TrainError::Data {
                    set: name,
                    what: what.into(),
                    detail: format!("value {} at index {i} is not finite", v[i]),
                });
            }
        }
        Ok(())
    }
}

/// Why training could not start, continue or finish.
#[derive(Debug, Error)]
pub enum TrainError {
    /// A hyper-parameter is out of range.
    #[error("invalid training configuration: {0}")]
    Config(String),
    /// A data array is malformed.
    #[error("{set} data, {what}: {detail}")]
    Data {
        /// "train" or "validation".
        set: &'static str,
        /// Which array.
        what: String,
        /// What is wrong.
        detail: String,
    },
    /// The loss exceeded the abort threshold or became non-finite.
    #[error("training diverged at epoch {epoch}: loss {loss}")]
    Diverged {
        /// 1-based epoch.
        epoch: usize,
        /// The offending loss.
        loss: f64,
    },
    /// The rayon pool could not be built.
    #[error("cannot start {threads} training threads: {source}")]
    Threads {
        /// Requested threads.
        threads: usize,
        /// Cause.
        source: rayon::ThreadPoolBuildError,
    },
    /// The starting model of a continued run (`Trainer::from_init`) has another architecture
    /// than the run asks for.
    #[error("the initial model is {init}, this run is {run}: continue with the same architecture")]
    InitArchitecture {
        /// The initial model's architecture, e.g. `60 inputs, hidden [128, 128], 1 output`.
        init: String,
        /// The run's architecture in the same form.
        run: String,
    },
    /// A checkpoint file could not be read or written.
    #[error("checkpoint {path}: {detail}")]
    Checkpoint {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
}

/// What one epoch did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochReport {
    /// 1-based epoch number.
    pub epoch: usize,
    /// Mean training loss over the epoch's rows (training mode: dropout on), Nm².
    pub train_loss: f64,
    /// Loss on the validation set in eval mode, Nm² (`None` without validation data).
    pub val_loss: Option<f64>,
    /// RMSE against the validation label in eval mode, Nm.
    pub val_rmse_nm: Option<f64>,
    /// Whether these weights are the best so far (always true without validation data).
    pub is_best: bool,
    /// Wall time of the epoch including validation, s (informative only).
    pub seconds: f64,
}

/// The result of [`Trainer::train`].
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    /// The best-on-validation weights (the last ones without validation data), normalisation included.
    pub weights: MlpWeights,
    /// 1-based epoch the weights come from (0 if no epoch ran).
    pub best_epoch: usize,
    /// Their validation RMSE, Nm.
    pub best_val_rmse_nm: Option<f64>,
    /// Every epoch's report so far, resumed runs included.
    pub history: Vec<EpochReport>,
    /// Whether early stopping ended the run.
    pub stopped_early: bool,
    /// Whether the callback stopped the run (it can be resumed from a checkpoint).
    pub interrupted: bool,
}

/// Normalised copy of a dataset.
struct Prepared {
    x: Vec<f32>,
    y: Vec<f32>,
    s: Vec<f32>,
    n_inputs: usize,
}

impl Prepared {
    fn new(d: &Dataset<'_>, norm: &Normalisation) -> Self {
        let n_in = d.n_inputs;
        let mut x = d.x.to_vec();
        for row in x.chunks_exact_mut(n_in) {
            for ((v, m), s) in row.iter_mut().zip(&norm.mean).zip(&norm.scale) {
                *v = (*v - m) / s;
            }
        }
        Self {
            x,
            y: d.y_label_nm.to_vec(),
            s: d.y_scv_nm.to_vec(),
            n_inputs: n_in,
        }
    }
    fn n_rows(&self) -> usize {
        self.y.len()
    }
}

/// Best-on-validation bookkeeping.
#[derive(Clone, Debug, PartialEq)]
struct Best {
    params: Vec<f32>,
    val_rmse_nm: f64,
    epoch: usize,
}

/// Adam state.
#[derive(Clone, Debug, PartialEq)]
struct Adam {
    m: Vec<f32>,
    v: Vec<f32>,
    /// Steps taken so far (also the key of each step's dropout stream).
    t: u64,
}

const BETA1: f32 = 0.9;
const BETA2: f32 = 0.999;
const ADAM_EPS: f32 = 1e-8;

/// A training run in progress: parameters, optimiser state, data and preallocated buffers.
pub struct Trainer {
    cfg: TrainConfig,
    layout: Layout,
    norm: Normalisation,
    train: Prepared,
    val: Option<Prepared>,
    fingerprint: String,
    params: Vec<f32>,
    grads: Vec<f32>,
    adam: Adam,
    epochs_done: usize,
    best: Option<Best>,
    since_best: usize,
    history: Vec<EpochReport>,
    ws: Workspace,
    perm: Vec<usize>,
    pool: std::sync::Arc<rayon::ThreadPool>,
    /// Cosine decay of the learning rate to this value over the epochs (`None`: constant).
    lr_final: Option<f32>,
    /// The learning rate of the running epoch.
    epoch_lr: f32,
}

impl TrainConfig {
    /// Refuses what the trainer would refuse (widths, dropout, λ, lr, batch, epochs, threads), without
    /// data: a pipeline or a search checks its settings with it before the first run starts.
    pub fn validate(&self) -> Result<(), TrainError> {
        check_config(self)
    }
}

fn check_config(cfg: &TrainConfig) -> Result<(), TrainError> {
    let bad = |m: String| Err(TrainError::Config(m));
    if cfg.hidden.is_empty() || cfg.hidden.len() > limits::MAX_HIDDEN_LAYERS {
        return bad(format!(
            "hidden = {:?}: need 1..={} hidden layers",
            cfg.hidden,
            limits::MAX_HIDDEN_LAYERS
        ));
    }
    if let Some(w) = cfg
        .hidden
        .iter()
        .find(|&&w| w == 0 || w > limits::MAX_WIDTH)
    {
        return bad(format!(
            "hidden width {w} is outside 1..={}",
            limits::MAX_WIDTH
        ));
    }
    if !(0.0..1.0).contains(&cfg.dropout) {
        return bad(format!("dropout = {} is outside [0, 1)", cfg.dropout));
    }
    if !(0.0..=1.0).contains(&cfg.lambda) {
        return bad(format!("lambda = {} is outside [0, 1]", cfg.lambda));
    }
    if !(cfg.lr.is_finite() && cfg.lr > 0.0) {
        return bad(format!("lr = {} must be finite and positive", cfg.lr));
    }
    if cfg.batch_size == 0 {
        return bad("batch_size = 0".into());
    }
    if cfg.epochs == 0 {
        return bad("epochs = 0: at least one epoch (an untrained network is not a model)".into());
    }
    if cfg.threads == 0 {
        return bad("threads = 0".into());
    }
    Ok(())
}

/// The configuration, the training data and the validation data (same inputs per row).
fn check_inputs(
    cfg: &TrainConfig,
    train: &Dataset<'_>,
    val: Option<&Dataset<'_>>,
) -> Result<(), TrainError> {
    check_config(cfg)?;
    train.validate("train")?;
    if let Some(v) = val {
        v.validate("validation")?;
        if v.n_inputs != train.n_inputs {
            return Err(TrainError::Data {
                set: "validation",
                what: "n_inputs".into(),
                detail: format!(
                    "{} features per row, training data has {}",
                    v.n_inputs, train.n_inputs
                ),
            });
        }
    }
    Ok(())
}

/// SHA-256 over the raw bytes of the data the run is tied to (checked on resume).
fn fingerprint(train: &Dataset<'_>, val: Option<&Dataset<'_>>) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for d in std::iter::once(train).chain(val) {
        h.update((d.n_inputs as u64).to_le_bytes());
        h.update((d.n_rows() as u64).to_le_bytes());
        for v in [d.x, d.y_label_nm, d.y_scv_nm] {
            for chunk in v.chunks(4096) {
                let bytes: Vec<u8> = chunk.iter().flat_map(|f| f.to_le_bytes()).collect();
                h.update(&bytes);
            }
        }
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

impl Trainer {
    /// Starts a run: validates config and data, fits the normalisation on `train`, initialises the
    /// weights from `cfg.seed` and allocates every buffer.
    pub fn new(
        cfg: TrainConfig,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
    ) -> Result<Self, TrainError> {
        check_inputs(&cfg, train, val)?;
        let norm = fit_normalisation(train.x, train.n_inputs);
        Self::fresh(cfg, norm, train, val)
    }

    /// Starts a fresh run (weights initialised from `cfg.seed`) with the given input normalisation
    /// instead of one fitted on `train` (distillation: the student keeps its teacher's). Refuses a
    /// normalisation of the wrong length or with a non-finite or zero value.
    pub fn with_normalisation(
        cfg: TrainConfig,
        norm: Normalisation,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
    ) -> Result<Self, TrainError> {
        check_inputs(&cfg, train, val)?;
        let ok = norm.mean.len() == train.n_inputs
            && norm.scale.len() == train.n_inputs
            && norm.mean.iter().all(|v| v.is_finite())
            && norm.scale.iter().all(|v| v.is_finite() && *v != 0.0);
        if !ok {
            return Err(TrainError::Config(format!(
                "the given normalisation has {} means and {} scales (finite, scales non-zero \
                 required) for {} inputs",
                norm.mean.len(),
                norm.scale.len(),
                train.n_inputs
            )));
        }
        Self::fresh(cfg, norm, train, val)
    }

    /// A fresh run with input normalisation `norm`: weights initialised from `cfg.seed`, Adam
    /// state zero.
    fn fresh(
        cfg: TrainConfig,
        norm: Normalisation,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
    ) -> Result<Self, TrainError> {
        let mut sizes = vec![train.n_inputs];
        sizes.extend(&cfg.hidden);
        sizes.push(1);
        let layout = Layout::new(&sizes);
        let params = init_params(&layout, cfg.seed);
        let n = layout.n_params;
        Self::assemble(
            cfg,
            layout,
            norm,
            train,
            val,
            params,
            Adam {
                m: vec![0.0; n],
                v: vec![0.0; n],
                t: 0,
            },
        )
    }

    /// Starts a run that continues from `init` (a model trained before, e.g. on part of this data):
    /// its weights are the starting point and its input normalisation is kept (not refitted on
    /// `train`), so the network starts out computing exactly what `init` computes. The optimiser
    /// state starts afresh. `init` must have `train.n_inputs` inputs, the hidden widths
    /// `cfg.hidden` (ReLU) and one linear output; otherwise [`TrainError::InitArchitecture`] names
    /// both architectures.
    pub fn from_init(
        cfg: TrainConfig,
        init: &MlpWeights,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
    ) -> Result<Self, TrainError> {
        check_inputs(&cfg, train, val)?;
        let mut sizes = vec![train.n_inputs];
        sizes.extend(&cfg.hidden);
        sizes.push(1);
        let describe = |s: &[usize]| {
            format!(
                "{} inputs, hidden {:?}, {} output",
                s.first().copied().unwrap_or(0),
                &s[1..s.len().saturating_sub(1)],
                s.last().copied().unwrap_or(0)
            )
        };
        let mut init_sizes = vec![init.layers.first().map_or(0, |l| l.n_in)];
        init_sizes.extend(init.layers.iter().map(|l| l.n_out));
        let activations_ok = init.layers.iter().enumerate().all(|(k, l)| {
            l.activation
                == if k + 1 == init.layers.len() {
                    Activation::Identity
                } else {
                    Activation::Relu
                }
        });
        let shapes_ok = init
            .layers
            .iter()
            .all(|l| l.weight.len() == l.n_in * l.n_out && l.bias.len() == l.n_out)
            && init.layers.windows(2).all(|w| w[0].n_out == w[1].n_in)
            && init.norm.mean.len() == train.n_inputs
            && init.norm.scale.len() == train.n_inputs;
        if init_sizes != sizes || !activations_ok || !shapes_ok {
            return Err(TrainError::InitArchitecture {
                init: if activations_ok {
                    describe(&init_sizes)
                } else {
                    format!(
                        "{} (not ReLU hidden layers with a linear output)",
                        describe(&init_sizes)
                    )
                },
                run: describe(&sizes),
            });
        }
        let layout = Layout::new(&sizes);
        let mut params = vec![0f32; layout.n_params];
        for (k, l) in init.layers.iter().enumerate() {
            params[layout.w_off[k]..layout.w_off[k] + l.weight.len()].copy_from_slice(&l.weight);
            params[layout.b_off[k]..layout.b_off[k] + l.bias.len()].copy_from_slice(&l.bias);
        }
        let n = layout.n_params;
        Self::assemble(
            cfg,
            layout,
            init.norm.clone(),
            train,
            val,
            params,
            Adam {
                m: vec![0.0; n],
                v: vec![0.0; n],
                t: 0,
            },
        )
    }

    fn assemble(
        cfg: TrainConfig,
        layout: Layout,
        norm: Normalisation,
        train: &Dataset<'_>,
        val: Option<&Dataset<'_>>,
        params: Vec<f32>,
        adam: Adam,
    ) -> Result<Self, TrainError> {
        let pool = std::sync::Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(cfg.threads)
                .build()
                .map_err(|source| TrainError::Threads {
                    threads: cfg.threads,
                    source,
                })?,
        );
        let cap = cfg
            .batch_size
            .min(train.n_rows().max(val.map_or(0, |v| v.n_rows())));
        Ok(Self {
            ws: Workspace::new(&layout, cap),
            grads: vec![0.0; layout.n_params],
            perm: (0..train.n_rows()).collect(),
            train: Prepared::new(train, &norm),
            val: val.map(|v| Prepared::new(v, &norm)),
            fingerprint: fingerprint(train, val),
            cfg,
            layout,
            norm,
            params,
            adam,
            epochs_done: 0,
            best: None,
            since_best: 0,
            history: Vec::new(),
            pool,
            lr_final: None,
            epoch_lr: f32::NAN,
        })
    }

    /// Decays the learning rate from the configured one to `lr_final` along a half cosine over the
    /// run's epochs (epoch 1 at the configured rate, the last at `lr_final`). Not stored in
    /// checkpoints: a resumed run is constant-rate unless this is called again.
    pub fn set_cosine_decay(&mut self, lr_final: f32) -> Result<(), TrainError> {
        if !(lr_final.is_finite() && lr_final > 0.0 && lr_final <= self.cfg.lr) {
            return Err(TrainError::Config(format!(
                "final learning rate {lr_final}: must be finite, positive and at most lr = {}",
                self.cfg.lr
            )));
        }
        self.lr_final = Some(lr_final);
        Ok(())
    }

    /// The learning rate of 1-based `epoch` (the configured one, or its cosine decay).
    pub fn lr_of_epoch(&self, epoch: usize) -> f32 {
        match self.lr_final {
            None => self.cfg.lr,
            Some(end) => {
                let span = self.cfg.epochs.saturating_sub(1).max(1) as f64;
                let x = ((epoch.saturating_sub(1)) as f64 / span).min(1.0);
                let c = 0.5 * (1.0 + (std::f64::consts::PI * x).cos());
                (f64::from(end) + (f64::from(self.cfg.lr) - f64::from(end)) * c) as f32
            }
        }
    }

    /// The run's configuration.
    pub fn config(&self) -> &TrainConfig {
        &self.cfg
    }

    /// Epochs completed so far.
    pub fn epochs_done(&self) -> usize {
        self.epochs_done
    }

    /// The fitted input normalisation.
    pub fn normalisation(&self) -> &Normalisation {
        &self.norm
    }

    /// Changes the total number of epochs (e.g. to extend a resumed run).
    pub fn set_epochs(&mut self, epochs: usize) {
        self.cfg.epochs = epochs;
    }

    /// The current parameters, flat, PyTorch `state_dict` order (W0, b0, W1, b1, …).
    pub fn params(&self) -> &[f32] {
        &self.params
    }

    /// Mutable access to the flat parameters (diagnostics such as the gradient check).
    pub fn params_mut(&mut self) -> &mut [f32] {
        &mut self.params
    }

    /// Name and range of each tensor in the flat parameter vector (`"0.weight"`, `"0.bias"`, …).
    pub fn param_tensors(&self) -> Vec<(String, Range<usize>)> {
        let l = &self.layout;
        (0..l.n_layers())
            .flat_map(|k| {
                [
                    (
                        format!("{k}.weight"),
                        l.w_off[k]..l.w_off[k] + l.n_in(k) * l.n_out(k),
                    ),
                    (format!("{k}.bias"), l.b_off[k]..l.b_off[k] + l.n_out(k)),
                ]
            })
            .collect()
    }

    /// The current weights as an [`MlpWeights`] (eval mode, normalisation included).
    pub fn weights(&self) -> MlpWeights {
        self.to_weights(&self.params)
    }

    /// The best-on-validation weights so far (the current ones without validation data or epochs).
    pub fn best_weights(&self) -> MlpWeights {
        self.to_weights(self.best.as_ref().map_or(&self.params, |b| &b.params))
    }

    fn to_weights(&self, p: &[f32]) -> MlpWeights {
        let l = &self.layout;
        let layers = (0..l.n_layers())
            .map(|k| DenseLayer {
                n_in: l.n_in(k),
                n_out: l.n_out(k),
                weight: l.weight(p, k).to_vec(),
                bias: l.bias(p, k).to_vec(),
                activation: if k + 1 == l.n_layers() {
                    Activation::Identity
                } else {
                    Activation::Relu
                },
            })
            .collect();
        MlpWeights {
            norm: self.norm.clone(),
            layers,
        }
    }

    /// Every epoch's report so far.
    pub fn history(&self) -> &[EpochReport] {
        &self.history
    }

    /// Loss and its exact gradient (flat, like [`Trainer::params`]) on the given training rows,
    /// eval mode (no dropout). For the gradient check; does not change the optimiser state.
    pub fn loss_and_gradient(&mut self, rows: &[usize]) -> Result<(f64, Vec<f32>), TrainError> {
        if rows.is_empty() || rows.len() > self.ws.cap {
            return Err(TrainError::Config(format!(
                "{} rows, expected 1..={}",
                rows.len(),
                self.ws.cap
            )));
        }
        if let Some(&r) = rows.iter().find(|&&r| r >= self.train.n_rows()) {
            return Err(TrainError::Config(format!(
                "row {r} is outside the {} training rows",
                self.train.n_rows()
            )));
        }
        let pool = self.pool.clone();
        let loss = pool.install(|| {
            gather(&self.train, rows, &mut self.ws.x);
            self.loss_grad_step(rows, None)
        });
        Ok((loss, self.grads.clone()))
    }

    /// Forward + loss + backward on the rows already gathered into `ws.x`; returns the batch loss.
    fn loss_grad_step(&mut self, rows: &[usize], dropout: Option<Dropout>) -> f64 {
        let (threads, lambda, n) = (self.cfg.threads, self.cfg.lambda, rows.len());
        net::forward(
            &self.layout,
            &self.params,
            &mut self.ws,
            n,
            dropout,
            threads,
        );
        let last = self.layout.n_layers() - 1;
        let y_hat = &self.ws.act[last][..n];
        let dy = &mut self.ws.delta[last][..n];
        let mut loss = 0f64;
        let scale = 2.0 / n as f32;
        for (i, &r) in rows.iter().enumerate() {
            let (e_label, e_scv) = (y_hat[i] - self.train.y[r], y_hat[i] - self.train.s[r]);
            loss += (1.0 - lambda as f64) * (e_label as f64).powi(2)
                + lambda as f64 * (e_scv as f64).powi(2);
            dy[i] = scale * ((1.0 - lambda) * e_label + lambda * e_scv);
        }
        net::backward(
            &self.layout,
            &self.params,
            &mut self.grads,
            &mut self.ws,
            n,
            dropout,
            threads,
        );
        loss / n as f64
    }

    /// One Adam step with the gradient in `self.grads` (torch's formulation, bias-corrected).
    fn adam_step(&mut self) {
        self.adam.t += 1;
        let t = self.adam.t as i32;
        let bc1 = 1.0 - (BETA1 as f64).powi(t);
        let bc2_sqrt = (1.0 - (BETA2 as f64).powi(t)).sqrt();
        let step_size = (self.epoch_lr as f64 / bc1) as f32;
        let bc2_sqrt = bc2_sqrt as f32;
        for (((p, &g), m), v) in self
            .params
            .iter_mut()
            .zip(&self.grads)
            .zip(&mut self.adam.m)
            .zip(&mut self.adam.v)
        {
            *m = BETA1 * *m + (1.0 - BETA1) * g;
            *v = BETA2 * *v + (1.0 - BETA2) * g * g;
            *p -= step_size * *m / (v.sqrt() / bc2_sqrt + ADAM_EPS);
        }
    }

    /// Runs one epoch (shuffle, all batches, validation) and returns its report.
    pub fn run_epoch(&mut self) -> Result<EpochReport, TrainError> {
        let start = Instant::now();
        let epoch = self.epochs_done + 1;
        self.epoch_lr = self.lr_of_epoch(epoch);
        // The permutation depends only on (seed, epoch): identity, then a seeded shuffle.
        for (i, p) in self.perm.iter_mut().enumerate() {
            *p = i;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(rng::derive(
            self.cfg.seed,
            &[rng::tag::SHUFFLE, epoch as u64],
        ));
        self.perm.shuffle(&mut rng);
        let perm = std::mem::take(&mut self.perm);
        let mut sum = 0f64;
        let pool = self.pool.clone();
        pool.install(|| {
            for rows in perm.chunks(self.ws.cap) {
                gather(&self.train, rows, &mut self.ws.x);
                let key = rng::derive(self.cfg.seed, &[rng::tag::DROPOUT, self.adam.t]);
                let dropout = Dropout::new(self.cfg.dropout, key);
                sum += self.loss_grad_step(rows, dropout) * rows.len() as f64;
                self.adam_step();
            }
        });
        self.perm = perm;
        let train_loss = sum / self.train.n_rows() as f64;
        if !train_loss.is_finite() || self.cfg.abort_loss.is_some_and(|a| train_loss > a as f64) {
            return Err(TrainError::Diverged {
                epoch,
                loss: train_loss,
            });
        }
        let val = self.validation_metrics();
        let is_best = match (val, &self.best) {
            (None, _) => true,
            (Some((_, rmse)), None) => rmse.is_finite(),
            (Some((_, rmse)), Some(b)) => rmse < b.val_rmse_nm,
        };
        if is_best {
            self.since_best = 0;
            if let Some((_, rmse)) = val {
                match &mut self.best {
                    Some(b) => {
                        b.params.copy_from_slice(&self.params);
                        b.val_rmse_nm = rmse;
                        b.epoch = epoch;
                    }
                    None => {
                        self.best = Some(Best {
                            params: self.params.clone(),
                            val_rmse_nm: rmse,
                            epoch,
                        })
                    }
                }
            }
        } else {
            self.since_best += 1;
        }
        self.epochs_done = epoch;
        let report = EpochReport {
            epoch,
            train_loss,
            val_loss: val.map(|v| v.0),
            val_rmse_nm: val.map(|v| v.1),
            is_best,
            seconds: start.elapsed().as_secs_f64(),
        };
        self.history.push(report.clone());
        Ok(report)
    }

    /// (loss, RMSE vs label) on the validation set in eval mode.
    fn validation_metrics(&mut self) -> Option<(f64, f64)> {
        let val = self.val.as_ref()?;
        let lambda = self.cfg.lambda as f64;
        let (mut loss, mut sq) = (0f64, 0f64);
        self.pool.install(|| {
            for start in (0..val.n_rows()).step_by(self.ws.cap) {
                let n = self.ws.cap.min(val.n_rows() - start);
                let ni = val.n_inputs;
                self.ws.x[..n * ni].copy_from_slice(&val.x[start * ni..(start + n) * ni]);
                net::forward(
                    &self.layout,
                    &self.params,
                    &mut self.ws,
                    n,
                    None,
                    self.cfg.threads,
                );
                let y_hat = &self.ws.act[self.layout.n_layers() - 1][..n];
                for (i, &p) in y_hat.iter().enumerate() {
                    let (el, es) = ((p - val.y[start + i]) as f64, (p - val.s[start + i]) as f64);
                    sq += el * el;
                    loss += (1.0 - lambda) * el * el + lambda * es * es;
                }
            }
        });
        let n = val.n_rows() as f64;
        Some((loss / n, (sq / n).sqrt()))
    }

    /// Runs the remaining epochs, calling `on_epoch` after each (return `ControlFlow::Break(())` to stop;
    /// the run can then be checkpointed and resumed). Stops early after `patience` epochs without a
    /// better validation RMSE.
    pub fn train(
        &mut self,
        mut on_epoch: impl FnMut(&EpochReport) -> ControlFlow<()>,
    ) -> Result<TrainOutcome, TrainError> {
        let (mut stopped_early, mut interrupted) = (false, false);
        while self.epochs_done < self.cfg.epochs {
            if self.val.is_some() && self.cfg.patience.is_some_and(|p| self.since_best >= p) {
                stopped_early = true;
                break;
            }
            let report = self.run_epoch()?;
            if on_epoch(&report).is_break() {
                interrupted = true;
                break;
            }
        }
        if !interrupted
            && self.val.is_some()
            && self.cfg.patience.is_some_and(|p| self.since_best >= p)
        {
            stopped_early = self.epochs_done < self.cfg.epochs || stopped_early;
        }
        Ok(TrainOutcome {
            weights: self.best_weights(),
            best_epoch: self.best.as_ref().map_or(self.epochs_done, |b| b.epoch),
            best_val_rmse_nm: self.best.as_ref().map(|b| b.val_rmse_nm),
            history: self.history.clone(),
            stopped_early,
            interrupted,
        })
    }

    /// Eval-mode predictions of the current weights for raw row-major features `x` (`n_rows × n_inputs`),
    /// batched through the trainer's GEMM path.
    pub fn predict(&mut self, x: &[f32]) -> Result<Vec<f32>, TrainError> {
        let ni = self.layout.sizes[0];
        if !x.len().is_multiple_of(ni) {
            return Err(TrainError::Data {
                set: "prediction",
                what: "x".into(),
                detail: format!("{} values is not a multiple of {ni} inputs", x.len()),
            });
        }
        let n_rows = x.len() / ni;
        let mut out = Vec::with_capacity(n_rows);
        let cap = self.ws.cap;
        self.pool.install(|| {
            for start in (0..n_rows).step_by(cap) {
                let n = cap.min(n_rows - start);
                for (dst, src) in self.ws.x[..n * ni]
                    .chunks_exact_mut(ni)
                    .zip(x[start * ni..(start + n) * ni].chunks_exact(ni))
                {
                    for (((d, &s), m), sc) in dst
                        .iter_mut()
                        .zip(src)
                        .zip(&self.norm.mean)
                        .zip(&self.norm.scale)
                    {
                        *d = (s - m) / sc;
                    }
                }
                net::forward(
                    &self.layout,
                    &self.params,
                    &mut self.ws,
                    n,
                    None,
                    self.cfg.threads,
                );
                out.extend_from_slice(&self.ws.act[self.layout.n_layers() - 1][..n]);
            }
        });
        Ok(out)
    }
}

/// Copies the given normalised training rows into the batch buffer.
fn gather(data: &Prepared, rows: &[usize], dst: &mut [f32]) {
    let ni = data.n_inputs;
    for (d, &r) in dst.chunks_exact_mut(ni).zip(rows) {
        d.copy_from_slice(&data.x[r * ni..(r + 1) * ni]);
    }
}

/// U(±1/√fan_in) for every weight and bias (torch's `nn.Linear` default), from one seeded stream.
fn init_params(layout: &Layout, seed: u64) -> Vec<f32> {
    use rand::Rng;
    let mut rng = ChaCha8Rng::seed_from_u64(rng::derive(seed, &[rng::tag::INIT]));
    let mut p = vec![0f32; layout.n_params];
    for l in 0..layout.n_layers() {
        let bound = 1.0 / (layout.n_in(l) as f32).sqrt();
        let end = layout.b_off[l] + layout.n_out(l);
        for v in &mut p[layout.w_off[l]..end] {
            *v = rng.random_range(-bound..bound);
        }
    }
    p
}
