//! Arguments of `frictl robot`.

use std::path::PathBuf;

/// Arguments of `frictl robot`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// The `frictl robot` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Run every joint's pipeline and write one frictiond config and the report.
    Run(RunArgs),
    /// Print the plan (joint directories, inputs, search arguments) as JSON for an external driver.
    Plan(PlanArgs),
}

/// `frictl robot run`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// The robot file.
    pub robot: PathBuf,
    /// Output directory (created).
    #[arg(long, default_value = "robot-out")]
    pub out: PathBuf,
    /// Only these joints (repeatable; default: all). Skips the config and the report unless every
    /// joint is selected.
    #[arg(long = "joint")]
    pub joints: Vec<String>,
    /// Stop after this stage of each joint: `data`, `fit`, `search` (or train), `eval`, `export`.
    #[arg(long, value_enum)]
    pub until: Option<Until>,
}

/// `frictl robot plan`.
#[derive(clap::Args, Debug)]
pub struct PlanArgs {
    /// The robot file.
    pub robot: PathBuf,
    /// Output directory the plan's relative paths refer to.
    #[arg(long, default_value = "robot-out")]
    pub out: PathBuf,
}

/// The last stage `--until` runs.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
// The variants are the stages of `--until`'s help; doc comments would become per-value help text.
#[allow(missing_docs)]
pub enum Until {
    Data,
    Fit,
    Search,
    Eval,
    Export,
}
