//! Arguments of `frictl eval`.

use frictionless_eval::drift::DriftOptions;
use frictionless_eval::{self as eval};
use frictionless_train::data::DeltaThetaOffset;
use std::path::PathBuf;

/// PINN warm-up policy (as the daemon is configured).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Warmup {
    /// 0 until H samples have arrived; those rows are skipped for every model.
    HoldZero,
    /// Infer at once with zero-padded history.
    ZeroPad,
}

/// Arguments of `frictl eval`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Dataset CSV from `frictl preprocess` or `frictl import` (repeatable). Every row is scored, unless
    /// --test-run or --test-dataset name held-out runs: then only those are scored, and the other runs
    /// are the training runs whose range of s and ṡ marks extrapolation.
    #[arg(long = "dataset", required_unless_present = "test_datasets")]
    pub datasets: Vec<PathBuf>,
    /// Score only this run (repeatable): a run name of a dataset's sidecar (`runs`), or the file stem
    /// of a dataset without runs. The runs not named are the training runs.
    #[arg(long = "test-run", value_name = "NAME")]
    pub test_runs: Vec<String>,
    /// A held-out dataset, scored as a whole (repeatable); the --dataset files are then the training
    /// runs (not scored).
    #[arg(long = "test-dataset", value_name = "FILE")]
    pub test_datasets: Vec<PathBuf>,
    /// |ṡ| band edges [rad/s], comma separated, increasing (the last band is open).
    #[arg(long, value_delimiter = ',', default_values_t = eval::runs::DEFAULT_BAND_EDGES_RAD_S)]
    pub band_edges: Vec<f64>,
    /// CV model: the JSON of `frictl fit cv --json`.
    #[arg(long)]
    pub cv: Option<PathBuf>,
    /// SCV model: the JSON of `frictl fit scv|scv-code --json`.
    #[arg(long)]
    pub scv: Option<PathBuf>,
    /// LuGre model: the JSON of `frictl fit lugre --json`.
    #[arg(long)]
    pub lugre: Option<PathBuf>,
    /// PINN model file `.fwt` (repeatable).
    #[arg(long = "pinn")]
    pub pinns: Vec<PathBuf>,
    /// Training report of `frictl train --report` (training-curve figure; test split for --test-only;
    /// its training range when no training runs are given).
    #[arg(long)]
    pub train_report: Option<PathBuf>,
    /// Use only the chunks the training report marks as its test split.
    #[arg(long, requires = "train_report")]
    pub test_only: bool,
    /// Directory for the PNG figures (created if missing).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Sliding threshold on |ṡ| [rad/s].
    #[arg(long, default_value_t = 0.03)]
    pub v_sliding: f64,
    /// PINN warm-up policy.
    #[arg(long, value_enum, default_value_t = Warmup::HoldZero)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub warmup: Warmup,
    /// Where a PINN's Δθ offset is latched: `run` (once per dataset), `chunk` (every chunk start) or a
    /// fixed θ_off in motor rad — use the setting the PINN was trained with (its train report).
    #[arg(long, default_value = "run", allow_hyphen_values = true)]
    #[serde(serialize_with = "super::stage::as_display")]
    pub delta_theta_offset: DeltaThetaOffset,
    /// Chunk shown in the time-series and hysteresis figures (default: most sliding rows).
    #[arg(long)]
    pub plot_chunk: Option<u32>,
    /// Drift monitor: each model's residual (label − τ̂_F) on the scored rows per |ṡ| band
    /// (--band-edges) and temperature bin against its reference (--reference, else the train report's
    /// `residual_reference`, else the `.fwt`'s validation RMSE), the PINN's input-range coverage, and a
    /// `retrain` / `ok` verdict (rule: `frictionless_eval::drift`; JSON key `drift`; figure
    /// `drift_<model>.png`).
    #[arg(long)]
    pub drift: bool,
    /// Reference dataset of --drift (repeatable), e.g. the model's training dataset: every valid row
    /// is scored.
    #[arg(long = "reference", value_name = "FILE", requires = "drift")]
    pub references: Vec<PathBuf>,
    /// --drift: fewest rows a band or temperature bin needs to be checked (and a reference bin to be
    /// compared with; else the reference's all rows).
    #[arg(long, default_value_t = DriftOptions::default().min_samples)]
    pub drift_min_samples: usize,
    /// --drift: a check fires when RMSE_new > this × RMSE_ref + --drift-floor.
    #[arg(long, default_value_t = DriftOptions::default().rmse_ratio)]
    pub drift_rmse_ratio: f64,
    /// --drift: … or when the mean residual, or its mean along the motion (residual·sign(ṡ)), moved by
    /// more than this × RMSE_ref + --drift-floor.
    #[arg(long, default_value_t = DriftOptions::default().mean_ratio)]
    pub drift_mean_ratio: f64,
    /// --drift: absolute slack of both limits [Nm].
    #[arg(long, default_value_t = DriftOptions::default().floor_nm)]
    pub drift_floor: f64,
    /// --drift: `extrapolating` above this share (0–1) of rows outside the PINN's input range.
    #[arg(long, default_value_t = DriftOptions::default().max_out_of_range)]
    pub drift_max_out_of_range: f64,
    /// --drift: margin of the input-range test (fraction of each range's width; frictiond's
    /// `ood_margin` default).
    #[arg(long, default_value_t = DriftOptions::default().range_margin)]
    pub drift_range_margin: f64,
    /// --drift: width of the temperature bins [°C].
    #[arg(long, default_value_t = DriftOptions::default().temperature_bin_c)]
    pub drift_temperature_bin: f64,
}

impl Args {
    /// The --drift thresholds, checked.
    pub fn drift_options(&self) -> anyhow::Result<DriftOptions> {
        let o = DriftOptions {
            temperature_bin_c: self.drift_temperature_bin,
            min_samples: self.drift_min_samples,
            rmse_ratio: self.drift_rmse_ratio,
            mean_ratio: self.drift_mean_ratio,
            floor_nm: self.drift_floor,
            max_out_of_range: self.drift_max_out_of_range,
            range_margin: self.drift_range_margin,
        };
        let nonneg = |k: &str, v: f64| {
            anyhow::ensure!(
                v.is_finite() && v >= 0.0,
                "{k} = {v}: must be finite and >= 0"
            );
            Ok(())
        };
        nonneg("--drift-rmse-ratio", o.rmse_ratio)?;
        nonneg("--drift-mean-ratio", o.mean_ratio)?;
        nonneg("--drift-floor", o.floor_nm)?;
        nonneg("--drift-range-margin", o.range_margin)?;
        anyhow::ensure!(
            (0.0..=1.0).contains(&o.max_out_of_range),
            "--drift-max-out-of-range = {}: must be in [0, 1]",
            o.max_out_of_range
        );
        anyhow::ensure!(
            o.temperature_bin_c.is_finite() && o.temperature_bin_c > 0.0,
            "--drift-temperature-bin = {}: must be finite and > 0",
            o.temperature_bin_c
        );
        Ok(o)
    }
}
