//! Arguments of `frictl search`.

use super::train::{Dtype, Features, Warmup};
use frictionless_train::data::DeltaThetaOffset;
use std::path::PathBuf;

/// `frictl search`: a search, or one of its subcommands.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Cli {
    /// `finish DIR`: publish the tables of a search run by trials elsewhere.
    #[command(subcommand)]
    pub action: Option<Action>,
    /// The search.
    #[command(flatten)]
    pub search: Option<Args>,
}

/// Arguments of `frictl search`.
#[derive(clap::Args, Debug, Clone, serde::Serialize)]
pub struct Args {
    /// Preprocessed dataset CSV (repeatable; its `.json` sidecar must exist).
    #[arg(long = "dataset", required = true)]
    pub datasets: Vec<PathBuf>,
    /// Fitted static model JSON from `frictl fit … --json` (the physics prior).
    #[arg(long)]
    pub scv: PathBuf,
    /// Number of trials (trial indices 0..N).
    #[arg(long, value_parser = crate::count::trials)]
    pub trials: usize,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Trials trained at the same time (each gets --threads / --parallel threads).
    #[arg(long, default_value_t = 2)]
    pub parallel: usize,
    /// Threads over all parallel trials (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Epochs per trial (the authors' sweep: 350).
    #[arg(long, default_value_t = 350)]
    pub epochs: usize,
    /// Search seed: the split and every trial's hyper-parameters and training seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Continue the search in --out (skips trials recorded ok in results.jsonl, runs the failed ones
    /// again; --trials may grow).
    #[arg(long)]
    pub resume: bool,
    /// Input feature set.
    #[arg(long, value_enum, default_value_t = Features::DEFAULT)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub features: Features,
    /// Append the motor temperature as one more input.
    #[arg(long)]
    pub temperature: bool,
    /// Fraction of chunks for validation (the selection criterion).
    #[arg(long, default_value_t = 0.15)]
    pub val_frac: f64,
    /// Fraction of chunks for the test set (ignored with --test-chunks).
    #[arg(long, default_value_t = 0.15)]
    pub test_frac: f64,
    /// Explicit test chunks, comma separated: CHUNK or DATASET:CHUNK.
    #[arg(long, value_delimiter = ',')]
    pub test_chunks: Option<Vec<String>>,
    /// Hold out a whole run as the test set (repeatable): a run name of a dataset's sidecar (`runs`),
    /// or the file stem of a dataset without runs. Adds to --test-chunks; --test-frac is then ignored.
    #[arg(long = "test-run", value_name = "NAME")]
    pub test_runs: Vec<String>,
    /// A dataset used only as test set (repeatable): loaded like --dataset, every chunk held out.
    #[arg(long = "test-dataset", value_name = "FILE")]
    pub test_datasets: Vec<PathBuf>,
    /// Warm-up policy.
    #[arg(long, value_enum, default_value_t = Warmup::HoldZero)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub warmup: Warmup,
    /// Where the Δθ offset is latched: `run` (once per dataset), `chunk` (every chunk start) or a
    /// fixed θ_off in motor rad (see `frictl train --help`).
    #[arg(long, default_value = "run", allow_hyphen_values = true)]
    #[serde(serialize_with = "super::stage::as_display")]
    pub delta_theta_offset: DeltaThetaOffset,
    /// Storage dtype of the models.
    #[arg(long, value_enum, default_value_t = Dtype::F32)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub dtype: Dtype,
    /// Stop a trial after N epochs without a better validation RMSE.
    #[arg(long)]
    pub max_epochs_without_improvement: Option<usize>,
    /// No per-trial lines.
    #[arg(long)]
    pub quiet: bool,
    /// Run exactly these trials (comma separated indices < --trials) into --out, one after the other,
    /// each with --threads threads; appends to --out's results.jsonl (shared safely by several
    /// processes on one file system), skips trials recorded ok there, writes no tables (`frictl search
    /// finish`). --out's search.json, when present, must match these settings.
    #[arg(long, value_delimiter = ',', value_name = "K,K,…")]
    pub only_trials: Option<Vec<usize>>,
    /// Search range of the batch size, MIN,MAX (default: the paper's 3000,5000).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub batch_range: Option<Vec<usize>>,
    /// Search range of each hidden width, MIN,MAX (default 150,300).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub hidden_range: Option<Vec<usize>>,
    /// Search range of the learning rate (log-uniform), MIN,MAX (default 1e-5,1e-3).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub lr_range: Option<Vec<f32>>,
    /// Search range of the history length H, MIN,MAX (default 3,30).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub history_range: Option<Vec<usize>>,
    /// Search range of λ, MIN,MAX (default 0.1,0.5).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub lambda_range: Option<Vec<f32>>,
    /// Search range of the dropout, MIN,MAX (default 0.01,0.1).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX")]
    pub dropout_range: Option<Vec<f32>>,
    /// Pick (DIR/pick.fwt) the fastest trial (hot µs on this CPU) whose validation RMSE is within
    /// this × the best.
    #[arg(long, default_value_t = 1.05)]
    pub max_rmse_ratio: f64,
}

/// `frictl search` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Write results.json, results.csv and best.fwt from whatever DIR/results.jsonl holds.
    Finish {
        /// The search directory.
        dir: PathBuf,
        /// Only trials 0..N (default: every trial recorded).
        #[arg(long, value_parser = crate::count::trials)]
        trials: Option<usize>,
        /// Pick (pick.fwt) the fastest trial within this × the best validation RMSE.
        #[arg(long, default_value_t = 1.05)]
        max_rmse_ratio: f64,
    },
}
