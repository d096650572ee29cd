//! # frictl — the offline half of frictionless
//!
//! What it **is**: one command-line tool for everything that is not the 1 kHz loop: the virtual
//! harmonic-drive joints and their plant process (`sim`), data acquisition with the paper's excitation
//! protocol (`acquire`), URDF rigid-body dynamics (`dynamics`), the label pipeline (`preprocess`),
//! CV/SCV fitting (`fit`), PINN training and hyper-parameter search (`train`, `search`), a whole robot
//! from one TOML file (`robot`; trials on a Ray cluster through `python/ray/frictl_ray.py`), model import,
//! export and inspection (`import`, `export`, `convert`, `inspect`, `predict`), evaluation (`eval`),
//! the paper's closed-loop experiments (`experiment`), live views of a running daemon (`monitor`,
//! `record`), recorded data through the daemon as deployed (`replay`), CAN tools (`can`) and the end-to-end `demo`.
//!
//! What it is **not**: it never links the daemon; it talks to `frictiond` only through the shared-memory
//! ABI in `frictionless-shm-types`, through files and by starting it as a process.

use clap::{Parser, Subcommand};

mod cmd;

/// frictl — friction identification, training and tooling for harmonic-drive joints.
#[derive(Parser, Debug)]
#[command(name = "frictl", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print a weight file's header, shapes, metadata and CRC status.
    Inspect(cmd::inspect::Args),
    /// Import a model (ONNX, safetensors) into a .fwt file, or robot logs (CSV, .mat, MCAP) into a dataset.
    Import(cmd::import::Args),
    /// Export a .fwt weight file to ONNX or safetensors.
    Export(cmd::export::Args),
    /// Re-write a .fwt weight file with another storage precision.
    Convert(cmd::convert::Args),
    /// Run a model on raw input vectors from a CSV file, one output per line.
    Predict(cmd::predict::Args),
    /// Rigid-body dynamics on a URDF (inverse dynamics, mass matrix).
    Dynamics(cmd::dynamics::Args),
    /// The virtual harmonic-drive joints: run offline or serve them as a plant process.
    Sim(cmd::sim::Args),
    /// Run the excitation protocol and log a dataset.
    Acquire(cmd::acquire::Args),
    /// Resample, filter, smooth and label logs into a training dataset.
    Preprocess(cmd::preprocess::Args),
    /// Fit the CV or SCV static friction model.
    Fit(cmd::fit::Args),
    /// Train the physics-informed network.
    Train(cmd::train::Args),
    /// Write a checked frictiond config with one [[joint]] for a fitted model or a PINN.
    Config(cmd::config::Args),
    /// Distil a model into a smaller student, gated on held-out accuracy against the data.
    Distill(cmd::distill::Args),
    /// Random hyper-parameter search over the paper's ranges.
    Search(cmd::search::Cli),
    /// A whole robot from one TOML file: every joint's pipeline, one frictiond config, a report.
    Robot(cmd::robot::Args),
    /// Evaluate none/CV/SCV/PINN on held-out runs.
    Eval(cmd::eval::Args),
    /// Run the paper's closed-loop experiments against the virtual joints.
    Experiment(cmd::experiment::Args),
    /// Live view of a running frictiond.
    Monitor(cmd::monitor::Args),
    /// Get or set a running frictiond's joint values (kfc, limits, compensation switch, ood).
    Ctl(cmd::ctl::Args),
    /// Record states, requests, commands and status from shared memory to CSV.
    Record(cmd::record::Args),
    /// Play recorded datasets through frictiond as deployed: what the daemon would have done.
    Replay(cmd::replay::Args),
    /// CAN bus tools: record and replay candump logs.
    Can(cmd::can::Args),
    /// The whole method end to end on the virtual joints.
    Demo(cmd::demo::Args),
}

/// `FRICTIONLESS_GENERATE_ASSETS=DIR frictl` writes `DIR/man/frictl*.1` (one page per subcommand) and
/// the bash, zsh and fish completions in `DIR/{bash,zsh,fish}/` from [`Cli`] and exits: the Debian
/// package's build runs it (packaging/deb.sh). An environment variable, not a subcommand, so that the
/// pages and completions describe only the real command line.
fn generate_assets(dir: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    use clap::CommandFactory;
    use clap_complete::Shell;
    let cmd = Cli::command();
    let man = dir.join("man");
    std::fs::create_dir_all(&man).with_context(|| format!("creating {}", man.display()))?;
    clap_mangen::generate_to(cmd.clone(), &man)
        .with_context(|| format!("writing man pages to {}", man.display()))?;
    for (shell, sub) in [
        (Shell::Bash, "bash"),
        (Shell::Zsh, "zsh"),
        (Shell::Fish, "fish"),
    ] {
        let out = dir.join(sub);
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        clap_complete::generate_to(shell, &mut cmd.clone(), "frictl", &out)
            .with_context(|| format!("writing {shell} completions to {}", out.display()))?;
    }
    Ok(())
}

/// Log lines (warnings of the served drives, `sim serve --backend can`'s summary) go to stderr;
/// `RUST_LOG` overrides the default (frictl's own info, dependencies' warnings).
fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn,frictl=info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .without_time()
        .init();
}

fn main() -> std::process::ExitCode {
    if let Some(dir) = std::env::var_os("FRICTIONLESS_GENERATE_ASSETS") {
        return match generate_assets(std::path::Path::new(&dir)) {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("frictl: error: {}", frictionless::error_line(e.as_ref()));
                std::process::ExitCode::FAILURE
            }
        };
    }
    let cli = Cli::parse();
    init_logging();
    let result = match cli.command {
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Import(a) => cmd::import::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Convert(a) => cmd::convert::run(a),
        Command::Predict(a) => cmd::predict::run(a),
        Command::Dynamics(a) => cmd::dynamics::run(a),
        Command::Sim(a) => cmd::sim::run(a),
        Command::Acquire(a) => cmd::acquire::run(a),
        Command::Preprocess(a) => cmd::preprocess::run(a),
        Command::Fit(a) => cmd::fit::run(a),
        Command::Train(a) => cmd::train::run(a),
        Command::Config(a) => cmd::config::run(a),
        Command::Distill(a) => cmd::distill::run(a),
        Command::Search(a) => cmd::search::run_cli(a),
        Command::Robot(a) => cmd::robot::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Experiment(a) => cmd::experiment::run(a),
        Command::Monitor(a) => cmd::monitor::run(a),
        Command::Ctl(a) => cmd::ctl::run(a),
        Command::Record(a) => cmd::record::run(a),
        Command::Replay(a) => cmd::replay::run(a),
        Command::Can(a) => cmd::can::run(a),
        Command::Demo(a) => cmd::demo::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("frictl: error: {}", frictionless::error_line(e.as_ref()));
            std::process::ExitCode::FAILURE
        }
    }
}
