//! `frictl search` — random hyper-parameter search over the paper's ranges, trials in parallel on the
//! cores, resumable; writes a results table (CSV + JSON, sorted by validation RMSE) and `best.fwt`.
//! The machinery and the directory layout are documented in `frictionless_train::search`; this module only
//! parses arguments and reports progress.
//!
//! For an external scheduler (the Ray driver in `python/ray/`, a Slurm array): `--only-trials 3,7`
//! runs exactly those trials into `--out` (appending to the shared `results.jsonl`, no tables), and
//! `frictl search finish DIR` writes the tables and `best.fwt` from whatever the directory holds.

use std::sync::atomic::{AtomicUsize, Ordering};

use frictionless::features::WarmupPolicy;
use frictionless_train::data::SplitSpec;
use frictionless_train::pipeline;
use frictionless_train::search::{
    SearchRun, SearchSettings, SearchSpace, TrialResult, finish, pareto_front, publish_pick,
    run_search, run_trials,
};
use sha2::Digest;

use super::train::{HeldOut, cores};

pub use frictl_cli::search::*;

/// Runs `frictl search` or its subcommand.
pub fn run_cli(cli: Cli) -> anyhow::Result<()> {
    match (cli.action, cli.search) {
        (
            Some(Action::Finish {
                dir,
                trials,
                max_rmse_ratio,
            }),
            _,
        ) => {
            check_ratio(max_rmse_ratio)?;
            let all = finish(&dir, trials)?;
            println!(
                "frictl search finish: {} trial(s), {} ok; results in {} (results.csv, results.json)",
                all.len(),
                all.iter().filter(|r| r.status == "ok").count(),
                dir.display()
            );
            print_best(&all, &dir);
            print_pick(&all, &dir, max_rmse_ratio)
        }
        (None, Some(args)) => run(args),
        (None, None) => anyhow::bail!("frictl search: no arguments (see --help)"),
    }
}

/// The search space of `args`: the paper's ranges, each replaced where a `--*-range` is given.
fn space(args: &Args) -> anyhow::Result<SearchSpace> {
    fn pair<T: Copy + PartialOrd + std::fmt::Debug>(
        name: &str,
        v: &Option<Vec<T>>,
        default: (T, T),
    ) -> anyhow::Result<(T, T)> {
        match v.as_deref() {
            None => Ok(default),
            Some([a, b]) if a <= b => Ok((*a, *b)),
            Some(other) => {
                anyhow::bail!("--{name}-range {other:?}: expected MIN,MAX with MIN ≤ MAX")
            }
        }
    }
    let d = SearchSpace::default();
    let sp = SearchSpace {
        batch: pair("batch", &args.batch_range, d.batch)?,
        hidden: pair("hidden", &args.hidden_range, d.hidden)?,
        lr: pair("lr", &args.lr_range, d.lr)?,
        history: pair("history", &args.history_range, d.history)?,
        lambda: pair("lambda", &args.lambda_range, d.lambda)?,
        dropout: pair("dropout", &args.dropout_range, d.dropout)?,
    };
    // Both ends of every range through the trainer's own checks: no trial fails on its draw.
    sp.validate(args.features.into(), args.temperature)
        .map_err(|e| anyhow::anyhow!("--{}-range {}: {}", e.range, e.value, e.why))?;
    Ok(sp)
}

/// One progress line of a finished trial.
fn trial_line(n: usize, r: &TrialResult) {
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

/// Prints the best trial of a ranked list.
fn print_best(all: &[TrialResult], dir: &std::path::Path) {
    if let Some(b) = all.first().filter(|r| r.status == "ok") {
        println!(
            "best: trial {} val RMSE {:.4} Nm (test {}) -> {}",
            b.params.trial,
            b.val_rmse_nm.unwrap_or(f64::NAN),
            b.test_rmse_nm
                .map_or("-".to_string(), |t| format!("{t:.4} Nm")),
            dir.join("best.fwt").display()
        );
    }
}

/// Prints the Pareto front (validation RMSE vs hot µs) and writes the pick (`DIR/pick.fwt`).
fn print_pick(all: &[TrialResult], dir: &std::path::Path, ratio: f64) -> anyhow::Result<()> {
    let front = pareto_front(all);
    if front.is_empty() {
        println!("no timed trial: no Pareto front, no pick");
        return Ok(());
    }
    println!("Pareto front (validation RMSE vs inference time on this CPU, fastest first):");
    println!(
        "{:>6} {:>12} {:>9} {:>9} {:>14} {:>3}",
        "trial", "val RMSE Nm", "hot µs", "cold µs", "hidden", "H"
    );
    for r in &front {
        println!(
            "{:>6} {:>12.5} {:>9.3} {:>9.2} {:>14} {:>3}",
            r.params.trial,
            r.val_rmse_nm.unwrap_or(f64::NAN),
            r.hot_us.unwrap_or(f64::NAN),
            r.cold_us.unwrap_or(f64::NAN),
            format!("{:?}", r.params.hidden),
            r.params.history
        );
    }
    if let Some(p) = publish_pick(dir, all, ratio)? {
        println!(
            "pick (fastest within {ratio}× the best validation RMSE): trial {} val RMSE {:.5} Nm, \
             hot {:.3} µs, hidden {:?}, H {} -> {}",
            p.params.trial,
            p.val_rmse_nm.unwrap_or(f64::NAN),
            p.hot_us.unwrap_or(f64::NAN),
            p.params.hidden,
            p.params.history,
            dir.join("pick.fwt").display()
        );
    }
    Ok(())
}

/// `--max-rmse-ratio`, checked before any trial runs.
fn check_ratio(ratio: f64) -> anyhow::Result<()> {
    anyhow::ensure!(
        ratio.is_finite() && ratio >= 1.0,
        "--max-rmse-ratio {ratio}: must be finite and ≥ 1"
    );
    Ok(())
}

/// The error of a search whose trials `all` include failed ones (the tables list them; `--resume`
/// runs them again); `Ok` when every trial is `ok`.
fn failed_trials(all: &[TrialResult], resume: &str) -> anyhow::Result<()> {
    let failed: Vec<&TrialResult> = all.iter().filter(|r| r.status != "ok").collect();
    if let Some(first) = failed.first() {
        anyhow::bail!(
            "{} of {} trial(s) failed (trial {}: {}); they are recorded as failed and {resume} runs \
             them again",
            failed.len(),
            all.len(),
            first.params.trial,
            first.error.as_deref().unwrap_or("no reason recorded")
        );
    }
    Ok(())
}

/// Runs `frictl search`.
pub fn run(args: Args) -> anyhow::Result<()> {
    check_ratio(args.max_rmse_ratio)?;
    let space = space(&args)?;
    let scv_bytes =
        frictionless::regular_file::read(&args.scv, frictionless::regular_file::MAX_TEXT_BYTES)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", args.scv.display()))?;
    // Not a flattened `HeldOut`: clap reports a flattened `Option<Args>` (see `Cli`) as absent when
    // it holds a nested flatten, so the two options are spelled out here.
    let held_out = HeldOut {
        test_runs: args.test_runs.clone(),
        test_datasets: args.test_datasets.clone(),
    };
    let datasets = held_out.all_datasets(&args.datasets)?;
    let sources = pipeline::load_sources(&datasets)?;
    frictl_cli::train::distinct_contents(&sources, args.datasets.len())?;
    let scv = pipeline::load_scv(&args.scv)?;
    let settings = SearchSettings {
        space,
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
            test_chunks: held_out.test_chunks(&sources, &args.test_chunks, args.datasets.len())?,
        },
        datasets: datasets.iter().map(|p| p.display().to_string()).collect(),
        dataset_sha256: sources
            .dataset_sha256
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect(),
        scv: args.scv.display().to_string(),
        scv_sha256: Some(
            sha2::Sha256::digest(&scv_bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect(),
        ),
    };
    let threads_total = args.threads.unwrap_or_else(cores);
    if let Some(only) = &args.only_trials {
        if let Some(k) = only.iter().find(|k| **k >= args.trials) {
            anyhow::bail!("--only-trials {k}: not below --trials {}", args.trials);
        }
        let count = AtomicUsize::new(0);
        let ran = run_trials(
            &sources,
            &scv,
            &settings,
            &args.out,
            only,
            threads_total,
            |r| {
                let n = count.fetch_add(1, Ordering::Relaxed) + 1;
                if !args.quiet {
                    trial_line(n, r);
                }
            },
        )?;
        if !args.quiet {
            println!(
                "frictl search: {} of {} requested trial(s) run into {} (`frictl search finish` writes the tables)",
                ran.len(),
                only.len(),
                args.out.display()
            );
        }
        return failed_trials(&ran, "the same --only-trials");
    }
    let run = SearchRun {
        dir: args.out.clone(),
        trials: args.trials,
        parallel: args.parallel,
        threads_total,
        resume: args.resume,
    };
    let count = AtomicUsize::new(0);
    let quiet = args.quiet;
    let started = std::time::Instant::now();
    let all = run_search(&sources, &scv, &settings, &run, |r| {
        let n = count.fetch_add(1, Ordering::Relaxed) + 1;
        if !quiet {
            trial_line(n, r);
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
        print_best(&all, &args.out);
    }
    if quiet {
        publish_pick(&args.out, &all, args.max_rmse_ratio)?;
    } else {
        print_pick(&all, &args.out, args.max_rmse_ratio)?;
    }
    failed_trials(&all, "`--resume`")
}
