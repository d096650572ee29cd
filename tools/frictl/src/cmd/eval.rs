//! `frictl eval` — RMSE of none / CV / SCV / LuGre / PINN models on held-out datasets, a printed table, a JSON
//! report and PNG figures; with `--drift`, the drift monitor on a new log (`frictionless_eval::drift`). See
//! `frictionless_eval` for the method, the rows evaluated and the JSON schema; the run itself is
//! `frictionless_eval::job`.

use std::path::PathBuf;

use anyhow::Context;
use frictionless::features::WarmupPolicy;
use frictionless_eval::job::{self, EvalJob};
use frictionless_eval::{self as eval, EvalOptions};

pub use frictionless_eval::job::check_pinn_on_dataset;
pub use frictl_cli::eval::*;

/// Runs `frictl eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    if let Some(json) = &args.json {
        let data: Vec<&PathBuf> = args.datasets.iter().chain(&args.test_datasets).collect();
        let sidecars: Vec<PathBuf> = data.iter().map(|d| d.with_extension("json")).collect();
        let reports: Vec<PathBuf> = args
            .pinns
            .iter()
            .map(|p| frictionless_train::pipeline::default_report_path(p))
            .collect();
        let mut inputs: Vec<&std::path::Path> = data.iter().map(|p| p.as_path()).collect();
        inputs.extend(sidecars.iter().map(PathBuf::as_path));
        inputs.extend(args.pinns.iter().map(PathBuf::as_path));
        inputs.extend(reports.iter().map(PathBuf::as_path));
        inputs.extend(
            [&args.cv, &args.scv, &args.lugre, &args.train_report]
                .into_iter()
                .flatten()
                .map(PathBuf::as_path),
        );
        super::check_outputs(&inputs, &[json])?;
    }
    let drift = args.drift.then(|| args.drift_options()).transpose()?;
    let job = EvalJob {
        datasets: args.datasets.clone(),
        test_datasets: args.test_datasets.clone(),
        test_runs: args.test_runs.clone(),
        cv: args.cv.clone(),
        scv: args.scv.clone(),
        lugre: args.lugre.clone(),
        pinns: args.pinns.clone(),
        train_report: args.train_report.clone(),
        test_only: args.test_only,
        band_edges: args.band_edges.clone(),
        options: EvalOptions {
            v_sliding_rad_s: args.v_sliding,
            warmup: match args.warmup {
                Warmup::HoldZero => WarmupPolicy::HoldZero,
                Warmup::ZeroPad => WarmupPolicy::ZeroPad,
            },
            delta_theta_offset: args.delta_theta_offset,
        },
        drift,
        references: args.references.clone(),
        figures_dir: args.out.clone(),
        plot_chunk: args.plot_chunk,
    };
    let out = job::run(&job).map_err(|e| match e {
        eval::EvalError::UnknownRun { name, known } => {
            anyhow::anyhow!("--test-run {name}: no dataset has a run of that name (runs: {known})")
        }
        e => e.into(),
    })?;
    for w in &out.warnings {
        eprintln!("frictl eval: warning: {w}");
    }
    print!("{}", eval::format_table(&out.report));
    if let Some(d) = &out.drift {
        print!("{}", eval::drift::format_drift(d));
    }
    if let Some(p) = &args.json {
        frictionless::output_file::write(p, serde_json::to_string_pretty(&out.json)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(why) = &out.unchecked {
        anyhow::bail!(
            "--drift: nothing was checked, no verdict ({why}); lower --drift-min-samples or score more rows"
        );
    }
    for f in &out.figures {
        eprintln!("frictl eval: wrote {}", f.display());
    }
    eprintln!(
        "frictl eval: {} model(s) on {} dataset(s) in {:.2} s",
        out.counts.0,
        out.counts.1,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
