//! `frictl replay` — recorded datasets played through `frictiond` itself, as deployed.
//!
//! What it **is**: the command line of [`frictionless_experiment::replay`]: parse, run, print one
//! line per joint. What it is **not**: no numbers of its own — every estimate and current is the
//! daemon's.

use std::path::PathBuf;

use anyhow::Context;
use frictionless_experiment::replay::{ReplayJob, replay};
use frictionless_experiment::session::{Binaries, install_signal_flag};

/// `frictl replay --config CONFIG.toml --dataset JOINT=DATASET.csv [--dataset …] --out DIR`.
#[derive(clap::Args, Debug)]
#[command(
    about = "Play recorded datasets through frictiond (the config as deployed, in lockstep over shared memory): what the daemon would have done on this log",
    long_about = "Play recorded datasets through frictiond itself: the config as deployed (its joints, models, law, out-of-range handling), with only the backend (shared memory on a private root), the trigger (lockstep: one tick per dataset row) and the RT settings changed. Every joint is enabled at its dataset's first row, as after a fresh boot, and again at every chunk boundary. Writes DIR/JOINT.csv per joint (time_s, chunk, valid, tau_f_label_nm, tau_f_hat_nm = the estimate the law was given, before kfc, clip and filter, current_a = the command with tau_des = 0, flags, out_of_range, warming_up), DIR/replay.json (per joint: rows, out-of-range rows, RMSE against the label) and DIR/frictiond.replay.toml (the config that ran). frictiond is $FRICTIOND, else next to frictl, else on PATH."
)]
pub struct Args {
    /// The frictiond config as deployed on the robot.
    #[arg(long, value_name = "CONFIG.toml")]
    pub config: PathBuf,
    /// A joint of the config and its dataset (`frictl preprocess` / `frictl import` output);
    /// repeat for every joint to replay. The datasets are one recording's (same rows and times).
    #[arg(long = "dataset", value_name = "JOINT=DATASET.csv", required = true, value_parser = joint_dataset)]
    pub datasets: Vec<(String, PathBuf)>,
    /// Output directory (created).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn joint_dataset(s: &str) -> Result<(String, PathBuf), String> {
    match s.split_once('=') {
        Some((j, p)) if !j.trim().is_empty() && !p.is_empty() => {
            Ok((j.trim().to_owned(), PathBuf::from(p)))
        }
        _ => Err(format!(
            "`{s}`: expected JOINT=DATASET.csv (a joint name of the config, then its dataset)"
        )),
    }
}

/// Runs `frictl replay`.
pub fn run(a: Args) -> anyhow::Result<()> {
    install_signal_flag()?;
    let bins = Binaries::locate()?;
    let job = ReplayJob {
        config: a.config,
        datasets: a.datasets,
        out: a.out,
    };
    let outcome =
        replay(&bins, &job).with_context(|| format!("replay {}", job.config.display()))?;
    println!(
        "replayed {} tick(s) through frictiond in {:.2} s ({} re-enable(s) at chunk boundaries)",
        outcome.ticks, outcome.wall_s, outcome.reenables
    );
    for j in &outcome.joints {
        let rmse = j.rmse_vs_label_nm.map_or("no scored row".to_owned(), |r| {
            format!("{r:.4} Nm RMSE vs label over {} row(s)", j.scored_rows)
        });
        println!(
            "{}: {} row(s), model on {}, out of range {}, warming up {}; {rmse} -> {}",
            j.joint,
            j.rows,
            j.model_rows,
            j.out_of_range_rows,
            j.warming_up_rows,
            j.csv.display()
        );
    }
    Ok(())
}
