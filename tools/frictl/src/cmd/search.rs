//! `frictl search` — random hyper-parameter search over the paper's ranges, trials in parallel on the
//! cores, resumable; writes a results table (CSV + JSON, sorted by validation RMSE) and `best.fwt`.
//! The machinery and the directory layout are documented in `frictionless_train::search`; this module only
//! parses arguments and reports progress.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use frictionless::features::WarmupPolicy;
use frictionless_train::data::{DeltaThetaOffset, SplitSpec};
use frictionless_train::pipeline;
use frictionless_train::search::{SearchRun, SearchSettings, SearchSpace, run_search};

use super::train::{Dtype, Features, HeldOut, Warmup, cores};

/// Arguments of `frictl search`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Preprocessed dataset CSV (repeatable; its `.json` sidecar must exist).
    #[arg(long = "dataset", required = true)]
    pub datasets: Vec<PathBuf>,
    /// Fitted static model JSON from `frictl fit … --json` (the physics prior).
    #[arg(long)]
    pub scv: PathBuf,
    /// Number of trials (trial indices 0..N).
    #[arg(long)]
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
    /// Continue the search in --out (skips trials already in results.jsonl; --trials may grow).
    #[arg(long)]
    pub resume: bool,
    /// Input feature set.
    #[arg(long, value_enum, default_value_t = Features::DeltaThetaJointVel)]
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
    #[command(flatten)]
    pub held_out: HeldOut,
    /// Warm-up policy.
    #[arg(long, value_enum, default_value_t = Warmup::HoldZero)]
    pub warmup: Warmup,
    /// Where the Δθ offset is latched: `run` (once per dataset), `chunk` (every chunk start) or a
    /// fixed θ_off in motor rad (see `frictl train --help`).
    #[arg(long, default_value = "run", allow_hyphen_values = true)]
    pub delta_theta_offset: DeltaThetaOffset,
    /// Storage dtype of the models.
    #[arg(long, value_enum, default_value_t = Dtype::F32)]
    pub dtype: Dtype,
    /// Stop a trial after N epochs without a better validation RMSE.
    #[arg(long)]
    pub max_epochs_without_improvement: Option<usize>,
    /// No per-trial lines.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `frictl search`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let datasets = args.held_out.all_datasets(&args.datasets);
    let sources = pipeline::load_sources(&datasets)?;
    let scv = pipeline::load_scv(&args.scv)?;
    let settings = SearchSettings {
        space: SearchSpace::default(),
        seed: args.seed,
        epochs: args.epochs,
        features: args.features.into(),
        temperature: args.temperature,
        warmup: WarmupPolicy::from(args.warmup),
        delta_theta_offset: args.delta_theta_offset,
        dtype: args.dtype.into(),
        patience: args.max_epochs_without_improvement,
        split: SplitSpec {
            val_frac: args.val_frac,
            test_frac: args.test_frac,
            seed: args.seed,
            test_chunks: args.held_out.test_chunks(
                &sources,
                &args.test_chunks,
                args.datasets.len(),
            )?,
        },
        datasets: datasets.iter().map(|p| p.display().to_string()).collect(),
        dataset_sha256: sources
            .dataset_sha256
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect(),
        scv: args.scv.display().to_string(),
    };
    let run = SearchRun {
        dir: args.out.clone(),
        trials: args.trials,
        parallel: args.parallel,
        threads_total: args.threads.unwrap_or_else(cores),
        resume: args.resume,
    };
    let count = AtomicUsize::new(0);
    let quiet = args.quiet;
    let started = std::time::Instant::now();
    let all = run_search(&sources, &scv, &settings, &run, |r| {
        let n = count.fetch_add(1, Ordering::Relaxed) + 1;
        if !quiet {
            let p = &r.params;
            let res = match (&r.status[..], r.val_rmse_nm) {
                ("ok", Some(v)) => format!("val RMSE {v:.4} Nm"),
                _ => format!("failed: {}", r.error.as_deref().unwrap_or("?")),
            };
            eprintln!(
                "[{n}] trial {:4}: batch {} hidden {:?} lr {:.2e} H {} λ {:.3} dropout {:.3} → {res} ({:.1} s)",
                p.trial, p.batch_size, p.hidden, p.lr, p.history, p.lambda, p.dropout, r.seconds
            );
        }
    })?;
    if !quiet {
        let ran = count.load(Ordering::Relaxed);
        println!(
            "frictl search: {ran} trial(s) run, {} in total, {:.1} s; results in {} (results.csv, results.json)",
            all.len(),
            started.elapsed().as_secs_f64(),
            args.out.display()
        );
        if let Some(b) = all.first().filter(|r| r.status == "ok") {
            println!(
                "best: trial {} val RMSE {:.4} Nm (test {}) -> {}",
                b.params.trial,
                b.val_rmse_nm.unwrap_or(f64::NAN),
                b.test_rmse_nm
                    .map_or("-".to_string(), |t| format!("{t:.4} Nm")),
                args.out.join("best.fwt").display()
            );
        }
    }
    Ok(())
}
