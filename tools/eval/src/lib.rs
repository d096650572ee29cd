//! # `frictionless-eval`: evaluation of friction models on held-out datasets (`frictl eval`)
//!
//! Crate table: `tools/eval`; depends on `frictionless-dataset`, `frictionless-train` (the Δθ offset
//! policy of training) and `frictiond-config` (model files as the daemon reads them); used by `frictl`
//! (`eval`, `convert`, `demo`, `robot run`) and `frictionless-experiment`.
//!
//! What it is:
//! - [`ModelSpec`]: the models to compare — none (τ̂ = 0), CV and SCV from the JSON of
//!   `frictl fit … --json`, and PINNs from `.fwt` files;
//! - [`predict`]: every model's τ̂_F for every row of a [`Dataset`], produced **the way the daemon
//!   produces it**: one [`JointModel`] per chunk, `reset` at the chunk's first row (which latches the
//!   Δθ offset as [`EvalOptions::delta_theta_offset`] says — by default once per dataset, as
//!   `train::data::build_inputs` does by default and as a daemon configured with that offset does), then
//!   `estimate` row by row (a PINN goes through `frictionless::features::History` and the kernel
//!   `Mlp`). Chunks run in parallel (rayon), each on its own copy of the model;
//! - [`Metrics`] / [`evaluate`]: RMSE [Nm] against the label τ_F (and against the simulator's true
//!   friction when the dataset has `tau_f_true_nm`) on all evaluated rows, on sliding rows
//!   (|ṡ| > `v_sliding_rad_s`, default 0.03 rad/s) and on stick rows (the rest);
//! - [`runs`]: the breakdown per run and per |ṡ| band, with rows outside the training range (s or ṡ
//!   beyond what the training runs covered) counted and scored apart;
//! - [`Report`]: the JSON written by `frictl eval --json` (schema below), read by `frictl demo`;
//! - [`drift`]: the drift monitor (`--drift`): residual per band and temperature bin on a new log
//!   against the model's reference, input-range coverage, and a `retrain` / `ok` verdict;
//! - [`plot`]: the PNG figures (plotters, bitmap backend);
//! - [`job`]: one whole evaluation (`frictl eval`) as a call: files in, report and figures out.
//!
//! Which rows are evaluated: rows with `valid = 1`, in the selected chunks (all; the held-out runs of
//! `--test-run` / `--test-dataset`, the other runs then being the training runs; and/or a PINN's test
//! split with `--test-only`), where every PINN's history is ready under the warm-up policy (with
//! `hold_zero` the first H−1 rows of each chunk are skipped for **all** models, so every model is
//! scored on the same rows). Rows where any model's output is not finite are skipped and counted.
//!
//! ## Report JSON (`frictionless-eval-v1`)
//! ```text
//! format             "frictionless-eval-v1"
//! producer           "frictl <version>"
//! v_sliding_rad_s    sliding threshold on |ṡ| [rad/s]
//! test_only          bool
//! warmup             "hold_zero" | "zero_pad"
//! datasets[]         {path, joint, rows, evaluated, sliding, stick, skipped_non_finite,
//!                     has_truth, label_std_nm, models {NAME: METRICS}}
//! models             {NAME: METRICS}   pooled over all datasets (what `frictl demo` reads)
//! order[]            model names in the order given (none, cv, scv, pinn…)
//! band_edges_rad_s[] |ṡ| band edges; band j = [edges[j], edges[j+1]), the last one open
//! training_range     {source "datasets" | "train_report", range {s_rad [lo, hi], sdot_rad_s [lo, hi],
//!                     rows}} or null: rows with s or ṡ outside it are extrapolation
//! per_run[]          {dataset, run, source, evaluated, extrapolated, extrapolated_share,
//!                     models {NAME: {rmse_all, rmse_sliding, rmse_stick, rmse_inside, rmse_outside,
//!                     rmse_true_all, rmse_true_inside, rmse_true_outside}}, bands[] (as per_band)}
//! per_band[]         {lo_rad_s, hi_rad_s | null, n, models {NAME: {rmse, rmse_true}}}, all runs pooled
//! drift              only with --drift (a [`drift::DriftReport`], added next to [`Report`]'s keys):
//!                     {rule, options {temperature_bin_c, min_samples, rmse_ratio, mean_ratio,
//!                     floor_nm, max_out_of_range, range_margin}, verdict ("retrain" | "ok" | "unchecked" |
//!                     "no_reference"), extrapolating, models[] {model, new PROFILE, reference_source
//!                     ("reference_datasets" | "train_report:val|train" | "fwt:val_rmse_nm|test_rmse_nm"
//!                     | null), reference PROFILE | null, coverage {rows, out_of_range,
//!                     out_of_range_share, margin} | null, checks[] {what, new STATS, reference STATS,
//!                     reference_bin ("same" | "all"), rmse_limit_nm, mean_shift_limit_nm, fired},
//!                     unchecked[], verdict, extrapolating, reasons[]}} — see [`drift`]
//! PROFILE            {band_edges_rad_s[], temperature_bin_c, all STATS, bands[] {lo_rad_s, hi_rad_s |
//!                     null, STATS…}, temperature[] {lo_c, hi_c, STATS…}}
//! STATS              {n, mean_residual_nm, mean_along_motion_nm (residual·sign(ṡ)), rmse_nm}:
//!                     residual = label − τ̂_F [Nm], null over zero rows
//! METRICS            {rmse_all, rmse_sliding, rmse_stick,                 vs the label [Nm]
//!                     rmse_true_all, rmse_true_sliding, rmse_true_stick,  vs the truth [Nm] or null
//!                     mae_all, n_samples, n_sliding, n_stick}
//! ```
//! Model names: `none`, `cv`, `scv`, and `pinn` (one PINN) or `pinn:<file stem>` (several).
//! An RMSE over zero rows is `null`.
//!
//! What it is not: training, fitting or closed-loop testing (see `frictl train`, `frictl fit`,
//! `frictl experiment`). It never changes a model: the PINN is run exactly as stored.

#![warn(missing_docs)]

pub mod drift;
pub mod job;
pub mod plot;
pub mod runs;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use frictionless::features::WarmupPolicy;
use frictionless::model::{FrictionModel, JointModel, PinnEstimator};
use frictionless::weights::ModelFile;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use frictionless_dataset::Dataset;
use frictionless_train::data::DeltaThetaOffset;

/// Report format tag.
pub const REPORT_FORMAT: &str = "frictionless-eval-v1";

/// Evaluation errors (each names the file or key involved).
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file could not be read.
    #[error("{path}: {msg}")]
    Io {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A static-model JSON is not usable.
    #[error("{path}: {msg}")]
    StaticModel {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A PINN model cannot be built.
    #[error("{path}: {msg}")]
    Pinn {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A dataset's columns have different lengths.
    #[error("dataset column `{column}` has {got} values, `time_s` has {expected}")]
    ColumnLength {
        /// Column.
        column: &'static str,
        /// Its length.
        got: usize,
        /// Expected length.
        expected: usize,
    },
    /// The train report is not usable for `--test-only`.
    #[error("train report {path}: {msg}")]
    TrainReport {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A dataset cannot be read, or a model cannot be run on it.
    #[error("{path}: {msg}")]
    Dataset {
        /// The dataset (or the model on the dataset).
        path: String,
        /// Reason.
        msg: String,
    },
    /// The selection of rows, runs or chunks to score is empty or names what does not exist.
    #[error("{0}")]
    Selection(String),
    /// A held-out run named by the caller is no run of any dataset.
    #[error("held-out run {name}: no dataset has a run of that name (runs: {known})")]
    UnknownRun {
        /// The name given.
        name: String,
        /// The runs there are, comma separated.
        known: String,
    },
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
    /// An option is out of range.
    #[error("{key} = {value}: {reason}")]
    Option {
        /// Option name.
        key: &'static str,
        /// Value.
        value: String,
        /// Requirement.
        reason: &'static str,
    },
}

/// One model to evaluate.
#[derive(Clone, Debug)]
pub struct ModelSpec {
    /// Name in the table and the report (`none`, `cv`, `scv`, `pinn…`).
    pub name: String,
    /// The estimator (cloned per chunk; reset at each chunk start).
    pub model: JointModel,
    /// History length H of a PINN (None for static models).
    pub pinn_history: Option<usize>,
}

impl ModelSpec {
    /// τ̂ = 0.
    pub fn none() -> Self {
        Self {
            name: "none".into(),
            model: JointModel::default(),
            pinn_history: None,
        }
    }

    /// A model read from a fit file (static or LuGre) under `name`.
    pub fn static_model(name: &str, model: JointModel) -> Self {
        Self {
            name: name.into(),
            model,
            pinn_history: None,
        }
    }

    /// A PINN from a model file, with the daemon's warm-up policy.
    pub fn pinn(name: &str, file: &ModelFile, warmup: WarmupPolicy) -> Result<Self, EvalError> {
        let est = PinnEstimator::from_model_file(file, warmup).map_err(|e| EvalError::Pinn {
            path: name.into(),
            msg: e.to_string(),
        })?;
        Ok(Self {
            name: name.into(),
            model: JointModel::from(est),
            pinn_history: Some(file.meta.features.history),
        })
    }

    /// Whether this is a static (history- and state-free) model ([`ModelKind::is_static`]); static
    /// models are also drawn as curves.
    ///
    /// [`ModelKind::is_static`]: frictionless::model::ModelKind::is_static
    pub fn is_static(&self) -> bool {
        use frictionless::model::FrictionModel;
        self.model.kind().is_static()
    }
}

/// Reads a static model from the JSON of `frictl fit cv|scv|scv-code --json`
/// ([`frictionless_dataset::fit_file::FittedModel`]: a `model` tag and `params`).
pub fn load_static_model(path: &Path) -> Result<JointModel, EvalError> {
    use frictionless_dataset::fit_file::{FitFileError, FittedModel};
    let p = path.display().to_string();
    match FittedModel::read(path) {
        Ok(m) => Ok(m.joint_model()),
        Err(FitFileError::Read { source, .. }) => Err(EvalError::Io {
            path: p,
            msg: source.to_string(),
        }),
        Err(FitFileError::Parse { message, .. }) => Err(EvalError::StaticModel {
            path: p,
            msg: format!(
                "not a fit of `frictl fit --json` (keys `model` = {} and `params`): {message}",
                frictionless_dataset::fit_file::fit_tags()
            ),
        }),
    }
}

/// Checks that every column has `time_s`'s length.
pub fn check_lengths(ds: &Dataset) -> Result<(), EvalError> {
    match ds.mismatched_column() {
        Some((column, got)) => Err(EvalError::ColumnLength {
            column,
            got,
            expected: ds.len(),
        }),
        None => Ok(()),
    }
}

/// `[start, end)` row ranges of the dataset's chunks (a new range wherever `chunk` changes).
pub fn chunk_ranges(ds: &Dataset) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..ds.chunk.len() {
        if ds.chunk[k] != ds.chunk[k - 1] {
            out.push((start, k));
            start = k;
        }
    }
    if !ds.chunk.is_empty() {
        out.push((start, ds.chunk.len()));
    }
    out
}

/// τ̂_F [Nm] of `model` for every row: chunk by chunk, reset at each chunk's first row (a PINN's
/// Δθ latched as `offset` says, like `train::data::build_inputs`), then one `estimate` per row in
/// time order (warm-up rows of a `hold_zero` PINN give 0, as in the daemon). Chunks run in
/// parallel, each on a clone of the model.
pub fn predict(ds: &Dataset, model: &JointModel, offset: DeltaThetaOffset) -> Vec<f64> {
    let ranges = chunk_ranges(ds);
    let parts: Vec<Vec<f64>> = ranges
        .par_iter()
        .map(|&(a, b)| {
            let mut m = model.clone();
            m.reset(&offset.latch_sample(ds, a));
            (a..b).map(|k| m.estimate(&ds.joint_sample(k))).collect()
        })
        .collect();
    parts.concat()
}

/// Rows whose history is complete for a PINN of history `h` under `warmup` (all rows for `None`).
pub fn ready_mask(ds: &Dataset, history: Option<usize>, warmup: WarmupPolicy) -> Vec<bool> {
    let mut out = vec![true; ds.len()];
    let Some(h) = history else {
        return out;
    };
    for (a, b) in chunk_ranges(ds) {
        for (i, o) in out[a..b].iter_mut().enumerate() {
            *o = warmup.is_ready(i + 1, h);
        }
    }
    out
}

/// Error statistics of one model on one set of rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// RMSE vs the label on all evaluated rows [Nm].
    pub rmse_all: Option<f64>,
    /// RMSE vs the label on sliding rows (|ṡ| > threshold) [Nm].
    pub rmse_sliding: Option<f64>,
    /// RMSE vs the label on stick rows [Nm].
    pub rmse_stick: Option<f64>,
    /// RMSE vs the simulator's true friction on all rows [Nm] (None without truth).
    pub rmse_true_all: Option<f64>,
    /// RMSE vs the true friction on sliding rows [Nm].
    pub rmse_true_sliding: Option<f64>,
    /// RMSE vs the true friction on stick rows [Nm].
    pub rmse_true_stick: Option<f64>,
    /// Mean absolute error vs the label on all rows [Nm].
    pub mae_all: Option<f64>,
    /// Rows evaluated.
    pub n_samples: usize,
    /// Sliding rows.
    pub n_sliding: usize,
    /// Stick rows.
    pub n_stick: usize,
}

/// Running sums of squared errors (label and truth) split into sliding and stick rows.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorSums {
    /// Σe² vs label on sliding rows.
    pub sliding_sq: f64,
    /// Σe² vs label on stick rows.
    pub stick_sq: f64,
    /// Σ|e| vs label on all rows.
    pub abs: f64,
    /// Σe² vs truth on sliding rows.
    pub true_sliding_sq: f64,
    /// Σe² vs truth on stick rows.
    pub true_stick_sq: f64,
    /// Sliding rows.
    pub n_sliding: usize,
    /// Stick rows.
    pub n_stick: usize,
    /// Whether truth was available (for every row added).
    pub has_truth: bool,
}

impl ErrorSums {
    /// Adds another set of sums (pooling datasets). Truth stays available only if both had it.
    pub fn merge(&mut self, o: &ErrorSums) {
        let first = self.n_sliding + self.n_stick == 0;
        self.sliding_sq += o.sliding_sq;
        self.stick_sq += o.stick_sq;
        self.abs += o.abs;
        self.true_sliding_sq += o.true_sliding_sq;
        self.true_stick_sq += o.true_stick_sq;
        self.n_sliding += o.n_sliding;
        self.n_stick += o.n_stick;
        self.has_truth = if first {
            o.has_truth
        } else {
            self.has_truth && o.has_truth
        };
    }

    /// The RMSEs (None over zero rows, or without truth).
    pub fn metrics(&self) -> Metrics {
        let rms = |s: f64, n: usize| (n > 0).then(|| (s / n as f64).sqrt());
        let n = self.n_sliding + self.n_stick;
        let t = |v: Option<f64>| if self.has_truth { v } else { None };
        Metrics {
            rmse_all: rms(self.sliding_sq + self.stick_sq, n),
            rmse_sliding: rms(self.sliding_sq, self.n_sliding),
            rmse_stick: rms(self.stick_sq, self.n_stick),
            rmse_true_all: t(rms(self.true_sliding_sq + self.true_stick_sq, n)),
            rmse_true_sliding: t(rms(self.true_sliding_sq, self.n_sliding)),
            rmse_true_stick: t(rms(self.true_stick_sq, self.n_stick)),
            mae_all: (n > 0).then(|| self.abs / n as f64),
            n_samples: n,
            n_sliding: self.n_sliding,
            n_stick: self.n_stick,
        }
    }
}

/// Squared-error sums of prediction `pred` on the rows where `mask` is true.
pub fn error_sums(ds: &Dataset, pred: &[f64], mask: &[bool], v_sliding_rad_s: f64) -> ErrorSums {
    let mut s = ErrorSums {
        has_truth: ds.tau_f_true_nm.is_some(),
        ..ErrorSums::default()
    };
    for k in 0..ds.len() {
        if !mask[k] {
            continue;
        }
        let e = pred[k] - ds.tau_f_label_nm[k];
        let et = ds.tau_f_true_nm.as_ref().map_or(0.0, |t| pred[k] - t[k]);
        s.abs += e.abs();
        if ds.sdot_rad_s[k].abs() > v_sliding_rad_s {
            s.sliding_sq += e * e;
            s.true_sliding_sq += et * et;
            s.n_sliding += 1;
        } else {
            s.stick_sq += e * e;
            s.true_stick_sq += et * et;
            s.n_stick += 1;
        }
    }
    s
}

/// Evaluation settings.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalOptions {
    /// Sliding threshold on |ṡ| [rad/s] (authors: 0.03).
    pub v_sliding_rad_s: f64,
    /// PINN warm-up policy (as configured in the daemon).
    pub warmup: WarmupPolicy,
    /// Where a PINN's Δθ offset is latched (as in training; default once per dataset).
    pub delta_theta_offset: DeltaThetaOffset,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            v_sliding_rad_s: 0.03,
            warmup: WarmupPolicy::HoldZero,
            delta_theta_offset: DeltaThetaOffset::Run,
        }
    }
}

/// One dataset's evaluation: predictions per model (kept for the plots) and the statistics.
#[derive(Clone, Debug)]
pub struct DatasetEval {
    /// Dataset path (as given).
    pub path: String,
    /// Rows evaluated (common to every model).
    pub mask: Vec<bool>,
    /// Predictions, one vector per model in [`ModelSpec`] order.
    pub predictions: Vec<Vec<f64>>,
    /// Error sums per model.
    pub sums: Vec<ErrorSums>,
    /// Rows skipped because a model's output was not finite.
    pub skipped_non_finite: usize,
}

/// Runs every model on `ds` and scores them on the common rows (`valid`, in `chunk_filter` if
/// given, every PINN ready, every output finite).
pub fn evaluate(
    path: &str,
    ds: &Dataset,
    models: &[ModelSpec],
    chunk_filter: Option<&BTreeSet<u32>>,
    opts: &EvalOptions,
) -> Result<DatasetEval, EvalError> {
    check_lengths(ds)?;
    if !(opts.v_sliding_rad_s.is_finite() && opts.v_sliding_rad_s >= 0.0) {
        return Err(EvalError::Option {
            key: "--v-sliding",
            value: opts.v_sliding_rad_s.to_string(),
            reason: "must be finite and >= 0",
        });
    }
    let predictions: Vec<Vec<f64>> = models
        .iter()
        .map(|m| predict(ds, &m.model, opts.delta_theta_offset))
        .collect();
    let mut mask: Vec<bool> = (0..ds.len())
        .map(|k| {
            ds.valid[k]
                && ds.tau_f_label_nm[k].is_finite()
                && chunk_filter.is_none_or(|c| c.contains(&ds.chunk[k]))
                && ds.tau_f_true_nm.as_ref().is_none_or(|t| t[k].is_finite())
        })
        .collect();
    for m in models {
        if m.pinn_history.is_some() {
            for (o, r) in mask
                .iter_mut()
                .zip(ready_mask(ds, m.pinn_history, opts.warmup))
            {
                *o &= r;
            }
        }
    }
    let mut skipped_non_finite = 0;
    for (k, o) in mask.iter_mut().enumerate() {
        if *o && predictions.iter().any(|p| !p[k].is_finite()) {
            *o = false;
            skipped_non_finite += 1;
        }
    }
    let sums = predictions
        .iter()
        .map(|p| error_sums(ds, p, &mask, opts.v_sliding_rad_s))
        .collect();
    Ok(DatasetEval {
        path: path.into(),
        mask,
        predictions,
        sums,
        skipped_non_finite,
    })
}

/// One dataset's entry in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetReport {
    /// Dataset path.
    pub path: String,
    /// Joint name (from the dataset sidecar, "" if none).
    pub joint: String,
    /// Rows in the file.
    pub rows: usize,
    /// Rows evaluated.
    pub evaluated: usize,
    /// Sliding rows evaluated.
    pub sliding: usize,
    /// Stick rows evaluated.
    pub stick: usize,
    /// Rows dropped because a model output was not finite.
    pub skipped_non_finite: usize,
    /// Whether the dataset has the simulator's true friction.
    pub has_truth: bool,
    /// Standard deviation of the label on the evaluated rows [Nm] (the scale of the problem).
    pub label_std_nm: Option<f64>,
    /// Metrics per model.
    pub models: BTreeMap<String, Metrics>,
}

/// The `frictl eval --json` report (schema in the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// `frictionless-eval-v1`.
    pub format: String,
    /// `frictl <version>`.
    pub producer: String,
    /// Sliding threshold [rad/s].
    pub v_sliding_rad_s: f64,
    /// Whether only PINN test-split chunks were used.
    pub test_only: bool,
    /// PINN warm-up policy.
    pub warmup: WarmupPolicy,
    /// Per-dataset results.
    pub datasets: Vec<DatasetReport>,
    /// Pooled results per model.
    pub models: BTreeMap<String, Metrics>,
    /// Model names in the order given.
    pub order: Vec<String>,
    /// |ṡ| band edges [rad/s] of `per_band` and `per_run[].bands` (the last band is open).
    #[serde(default)]
    pub band_edges_rad_s: Vec<f64>,
    /// The training range rows are checked against (None: no extrapolation flags).
    #[serde(default)]
    pub training_range: Option<TrainingRange>,
    /// Per run of every evaluated dataset (runs without a scored row left out).
    #[serde(default)]
    pub per_run: Vec<runs::RunReport>,
    /// Per |ṡ| band, pooled over every scored row.
    #[serde(default)]
    pub per_band: Vec<runs::BandReport>,
}

/// Where the training range came from, and the range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingRange {
    /// `"datasets"` (the training runs given to eval) or `"train_report"` (its `training_range`).
    pub source: String,
    /// The range.
    pub range: frictionless_dataset::MotionRange,
}

/// Adds `per_run`, `per_band`, the band edges and the training range to a report.
/// `parts[i]` = the runs and extrapolation mask of evaluation `evals[i]`.
pub fn add_breakdown(
    report: &mut Report,
    models: &[ModelSpec],
    evals: &[(DatasetEval, &Dataset, String)],
    parts: &[(Vec<frictionless_dataset::RunInfo>, Vec<bool>)],
    edges: &[f64],
    training_range: Option<TrainingRange>,
    v_sliding_rad_s: f64,
) {
    let with_range = training_range.is_some();
    let mut pooled: Vec<runs::Sums> = vec![runs::Sums::default(); edges.len()];
    for ((ev, ds, _), (run_list, extrap)) in evals.iter().zip(parts) {
        for r in runs::breakdown(ds, ev, run_list, extrap, edges, v_sliding_rad_s) {
            for (p, b) in pooled.iter_mut().zip(&r.bands) {
                p.merge(b);
            }
            report
                .per_run
                .push(runs::run_report(models, edges, &r, with_range));
        }
    }
    report.per_band = runs::band_reports(models, edges, &pooled);
    report.band_edges_rad_s = edges.to_vec();
    report.training_range = training_range;
}

/// Standard deviation of the label on the masked rows.
pub fn label_std(ds: &Dataset, mask: &[bool]) -> Option<f64> {
    let v: Vec<f64> = (0..ds.len())
        .filter(|&k| mask[k])
        .map(|k| ds.tau_f_label_nm[k])
        .collect();
    if v.len() < 2 {
        return None;
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    Some((v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt())
}

/// Builds the report from per-dataset evaluations (`joints[i]` = the joint of dataset i).
pub fn build_report(
    models: &[ModelSpec],
    evals: &[(DatasetEval, &Dataset, String)],
    opts: &EvalOptions,
    test_only: bool,
) -> Report {
    let mut pooled = vec![ErrorSums::default(); models.len()];
    let mut datasets = Vec::new();
    for (ev, ds, joint) in evals {
        let mut per = BTreeMap::new();
        for (i, m) in models.iter().enumerate() {
            per.insert(m.name.clone(), ev.sums[i].metrics());
            pooled[i].merge(&ev.sums[i]);
        }
        let first = ev.sums.first().map(ErrorSums::metrics).unwrap_or_default();
        datasets.push(DatasetReport {
            path: ev.path.clone(),
            joint: joint.clone(),
            rows: ds.len(),
            evaluated: first.n_samples,
            sliding: first.n_sliding,
            stick: first.n_stick,
            skipped_non_finite: ev.skipped_non_finite,
            has_truth: ds.tau_f_true_nm.is_some(),
            label_std_nm: label_std(ds, &ev.mask),
            models: per,
        });
    }
    Report {
        format: REPORT_FORMAT.into(),
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        v_sliding_rad_s: opts.v_sliding_rad_s,
        test_only,
        warmup: opts.warmup,
        datasets,
        models: models
            .iter()
            .zip(&pooled)
            .map(|(m, s)| (m.name.clone(), s.metrics()))
            .collect(),
        order: models.iter().map(|m| m.name.clone()).collect(),
        band_edges_rad_s: Vec::new(),
        training_range: None,
        per_run: Vec::new(),
        per_band: Vec::new(),
    }
}

/// What the per-run table's inside/outside columns mean: the training range they are relative to, or
/// that there is none (the columns are then empty).
fn per_run_header(range: Option<&TrainingRange>) -> String {
    match range {
        Some(t) => format!(
            "inside/outside = s and sdot inside/outside the training range ({}): s [{:.4}, {:.4}] rad, sdot [{:.4}, {:.4}] rad/s",
            t.source, t.range.s_rad[0], t.range.s_rad[1], t.range.sdot_rad_s[0], t.range.sdot_rad_s[1]
        ),
        None => "no training range given (the training runs or a train report): no extrapolation flags, inside/outside empty".into(),
    }
}

/// Formats the report as a text table (pooled, then per dataset when there are several).
pub fn format_table(r: &Report) -> String {
    fn f(v: Option<f64>) -> String {
        v.map_or_else(|| "-".into(), |x| format!("{x:.4}"))
    }
    let mut s = String::new();
    let table = |s: &mut String, title: &str, models: &BTreeMap<String, Metrics>| {
        s.push_str(&format!(
            "{title}\n{:<22} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
            "model", "all", "sliding", "stick", "true_all", "true_sl", "true_st", "n"
        ));
        for name in &r.order {
            if let Some(m) = models.get(name) {
                s.push_str(&format!(
                    "{:<22} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
                    name,
                    f(m.rmse_all),
                    f(m.rmse_sliding),
                    f(m.rmse_stick),
                    f(m.rmse_true_all),
                    f(m.rmse_true_sliding),
                    f(m.rmse_true_stick),
                    m.n_samples
                ));
            }
        }
    };
    table(
        &mut s,
        &format!(
            "RMSE [Nm] vs label (and vs true friction), sliding = |sdot| > {} rad/s",
            r.v_sliding_rad_s
        ),
        &r.models,
    );
    if r.datasets.len() > 1 {
        for d in &r.datasets {
            table(&mut s, &format!("\n{} ({})", d.path, d.joint), &d.models);
        }
    }
    if !r.per_run.is_empty() {
        s.push_str(&format!(
            "\nPer run: RMSE [Nm] vs label; {}\n{:<22} {:<22} {:>8} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
            per_run_header(r.training_range.as_ref()),
            "run", "model", "n", "extrap", "all", "sliding", "stick", "inside", "outside"
        ));
        for run in &r.per_run {
            let share = run
                .extrapolated_share
                .map_or_else(|| "-".into(), |x| format!("{:.1}%", 100.0 * x));
            for name in &r.order {
                if let Some(m) = run.models.get(name) {
                    s.push_str(&format!(
                        "{:<22} {:<22} {:>8} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
                        run.run,
                        name,
                        run.evaluated,
                        share,
                        f(m.rmse_all),
                        f(m.rmse_sliding),
                        f(m.rmse_stick),
                        f(m.rmse_inside),
                        f(m.rmse_outside)
                    ));
                }
            }
        }
    }
    if !r.per_band.is_empty() {
        s.push_str("\nPer |sdot| band [rad/s]: RMSE [Nm] vs label, all runs\n");
        s.push_str(&format!("{:<16} {:>8}", "band", "n"));
        for name in &r.order {
            s.push_str(&format!(" {name:>12}"));
        }
        s.push('\n');
        for b in &r.per_band {
            let hi = b.hi_rad_s.map_or_else(|| "inf".into(), |h| h.to_string());
            s.push_str(&format!(
                "{:<16} {:>8}",
                format!("[{}, {hi})", b.lo_rad_s),
                b.n
            ));
            for name in &r.order {
                let v = b.models.get(name).and_then(|m| m.rmse);
                s.push_str(&format!(" {:>12}", f(v)));
            }
            s.push('\n');
        }
    }
    s
}

/// Chunks of each evaluated dataset that a train report marks as its test split.
///
/// Reads `split.test[]` = `{dataset, chunk}` (dataset = index into the report's `datasets[]`) and maps
/// each report dataset to an evaluated one by SHA-256 of the CSV (`datasets[].sha256`), falling back
/// to the path. Tolerant of extra keys; an error names what is missing.
pub fn test_chunks_from_report(
    report_path: &Path,
    dataset_paths: &[PathBuf],
) -> Result<Vec<BTreeSet<u32>>, EvalError> {
    let p = report_path.display().to_string();
    let err = |msg: String| EvalError::TrainReport {
        path: p.clone(),
        msg,
    };
    let text = frictionless::regular_file::read_text(report_path).map_err(|e| EvalError::Io {
        path: p.clone(),
        msg: e.to_string(),
    })?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| err(format!("not JSON: {e}")))?;
    let test = v
        .pointer("/split/test")
        .and_then(serde_json::Value::as_array)
        .ok_or_else(|| err("key `split.test` missing or not an array".into()))?;
    let rep_ds = v
        .get("datasets")
        .and_then(serde_json::Value::as_array)
        .cloned()
        .unwrap_or_default();
    let mut hashes = Vec::new();
    for d in dataset_paths {
        hashes.push(
            frictionless_dataset::file_sha256_hex(d).map_err(|e| EvalError::Io {
                path: d.display().to_string(),
                msg: e.to_string(),
            })?,
        );
    }
    // Report dataset index → evaluated dataset index.
    let map: Vec<Option<usize>> = rep_ds
        .iter()
        .map(|rd| {
            let sha = rd.get("sha256").and_then(serde_json::Value::as_str);
            let path = rd.get("path").and_then(serde_json::Value::as_str);
            hashes
                .iter()
                .position(|h| Some(h.as_str()) == sha)
                .or_else(|| {
                    dataset_paths
                        .iter()
                        .position(|d| Some(d.display().to_string().as_str()) == path)
                })
        })
        .collect();
    let mut out = vec![BTreeSet::new(); dataset_paths.len()];
    for t in test {
        let di = t
            .get("dataset")
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| err(format!("split.test entry {t}: key `dataset` missing")))?;
        let ch = t
            .get("chunk")
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| err(format!("split.test entry {t}: key `chunk` missing")))?;
        if let Some(Some(e)) = map.get(di as usize) {
            out[*e].insert(ch as u32);
        }
    }
    if out.iter().all(BTreeSet::is_empty) {
        return Err(err(
            "no test chunk of the report belongs to a dataset given with --dataset (matched by sha256, then path)".into(),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_per_run_header_says_which_training_range_or_that_there_is_none() {
        let none = per_run_header(None);
        assert!(none.starts_with("no training range given"), "{none}");
        assert!(!none.contains("the no training range"), "{none}");
        let t = TrainingRange {
            source: "datasets".into(),
            range: frictionless_dataset::MotionRange {
                s_rad: [-0.5, 0.5],
                sdot_rad_s: [-2.0, 2.0],
                rows: 10,
            },
        };
        let some = per_run_header(Some(&t));
        assert!(
            some.starts_with(
                "inside/outside = s and sdot inside/outside the training range (datasets)"
            ),
            "{some}"
        );
    }

    fn ds(n: usize) -> Dataset {
        Dataset {
            time_s: (0..n).map(|k| k as f64 * 1e-3).collect(),
            chunk: (0..n).map(|k| (k / 10) as u32).collect(),
            source_chunk: vec![0; n],
            active: vec![true; n],
            valid: vec![true; n],
            s_rad: vec![0.0; n],
            sdot_rad_s: (0..n).map(|k| if k % 2 == 0 { 0.5 } else { 0.0 }).collect(),
            sddot_rad_s2: vec![0.0; n],
            theta_motor_rad: vec![0.0; n],
            delta_theta_motor_rad: vec![0.0; n],
            omega_motor_rad_s: vec![0.0; n],
            i_meas_a: vec![0.0; n],
            i_filt_a: vec![0.0; n],
            tau_id_nm: vec![0.0; n],
            tau_f_label_nm: (0..n).map(|k| if k % 2 == 0 { 2.0 } else { 1.0 }).collect(),
            temperature_c: vec![f64::NAN; n],
            tau_f_true_nm: None,
            phi_ddot_rad_s2: None,
        }
    }

    #[test]
    fn none_model_rmse_splits_sliding_and_stick() {
        let d = ds(40);
        let ev = evaluate("x", &d, &[ModelSpec::none()], None, &EvalOptions::default()).unwrap();
        let m = ev.sums[0].metrics();
        assert_eq!((m.n_sliding, m.n_stick), (20, 20));
        assert!((m.rmse_sliding.unwrap() - 2.0).abs() < 1e-12);
        assert!((m.rmse_stick.unwrap() - 1.0).abs() < 1e-12);
        assert!((m.rmse_all.unwrap() - 2.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(m.rmse_true_all, None);
    }

    #[test]
    fn chunk_filter_and_ready_mask() {
        let d = ds(40);
        let keep: BTreeSet<u32> = [1, 3].into();
        let ev = evaluate(
            "x",
            &d,
            &[ModelSpec::none()],
            Some(&keep),
            &EvalOptions::default(),
        )
        .unwrap();
        assert_eq!(ev.sums[0].metrics().n_samples, 20);
        let r = ready_mask(&d, Some(4), WarmupPolicy::HoldZero);
        assert_eq!(r.iter().filter(|x| **x).count(), 4 * 7);
        assert!(!r[10] && !r[12] && r[13]);
        assert_eq!(chunk_ranges(&d), [(0, 10), (10, 20), (20, 30), (30, 40)]);
    }
}
