//! `frictl sim` — the virtual harmonic-drive joints.
//!
//! `frictl sim run`: an offline open-loop run of a preset with a current profile, logged as CSV (the
//! same columns as `frictl acquire`, truth included). `frictl sim params`: print the merged parameters.
//! `frictl sim serve` (an iceoryx2 plant process) is not built yet: it needs the shared-memory ABI.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use frictl::acquire::log::CsvLog;
use frictl::acquire::protocol::{LogRow, Mode};
use frictl::sim::params::load_table;
use frictl::sim::profile::CurrentProfile;
use frictl::sim::{Plant, PlantParams};

/// Arguments of `frictl sim`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub command: SimCommand,
}

/// Parameter sources shared by the `sim` subcommands.
#[derive(clap::Args, Debug)]
pub struct ParamArgs {
    /// Built-in preset (`knee`, `ankle_roll`) or a preset TOML file.
    #[arg(long)]
    pub preset: String,
    /// TOML file deep-merged over the preset (same layout).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Override one parameter, e.g. `--set plant.sigma0_nm_per_rad=3e4`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// `frictl sim` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum SimCommand {
    /// Offline open-loop run with a current profile; CSV out.
    Run {
        /// Parameters.
        #[command(flatten)]
        params: ParamArgs,
        /// Current profile (robot convention): const:I | sine:A,F[,I0] | step:L,T_ON[,T_OFF] |
        /// ramp:SLOPE[,MAX] | csv:FILE (column i_ref_a at 1 kHz).
        #[arg(long)]
        current_profile: String,
        /// Simulated duration [s].
        #[arg(long, default_value_t = 10.0)]
        duration_s: f64,
        /// Constant external joint torque [Nm].
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        tau_ext_nm: f64,
        /// Seed (initial temperature, current noise).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output CSV file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Print the merged plant + protocol parameters as TOML.
    Params {
        /// Parameters.
        #[command(flatten)]
        params: ParamArgs,
    },
    /// Serve the plant over iceoryx2 (not built yet: needs the shared-memory ABI).
    Serve,
}

/// Runs `frictl sim`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Params { params } => {
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            // Validate before printing, so a bad override fails here too.
            PlantParams::from_table(&table)?;
            frictl::acquire::ProtocolConfig::from_table(&table)?;
            print!("{}", toml::to_string_pretty(&table)?);
            Ok(())
        }
        SimCommand::Serve => {
            anyhow::bail!("`frictl sim serve` is not built yet (it needs the shared-memory ABI)")
        }
        SimCommand::Run {
            params,
            current_profile,
            duration_s,
            tau_ext_nm,
            seed,
            out,
        } => {
            anyhow::ensure!(
                duration_s.is_finite() && duration_s > 0.0,
                "--duration-s must be a positive number, got {duration_s}"
            );
            anyhow::ensure!(tau_ext_nm.is_finite(), "--tau-ext-nm must be finite");
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            let p = PlantParams::from_table(&table)?;
            let period_s = p.sample_period_s();
            let profile = CurrentProfile::parse(&current_profile, period_s)?;
            let mut plant = Plant::from_params(p, seed)?;
            let file = std::fs::File::create(&out)
                .with_context(|| format!("cannot create {}", out.display()))?;
            let mut log = CsvLog::new(std::io::BufWriter::with_capacity(1 << 20, file), true)?;
            let n = (duration_s / period_s).round() as u64;
            let bar = if std::io::stderr().is_terminal() {
                indicatif::ProgressBar::new(n)
            } else {
                indicatif::ProgressBar::hidden()
            };
            for k in 0..n {
                let meas = plant.measurement();
                let i_ref = profile.current_a(meas.time_s);
                log.write(&LogRow {
                    chunk: 0,
                    active: true,
                    mode: Mode::Current,
                    meas,
                    i_ref_a: i_ref,
                    truth: Some(plant.truth()),
                })?;
                plant.step(i_ref, tau_ext_nm);
                if k % 10_000 == 0 {
                    bar.set_position(k);
                }
            }
            bar.finish_and_clear();
            log.finish()?
                .into_inner()
                .map_err(|e| anyhow::anyhow!("cannot flush {}: {}", out.display(), e.error()))?;
            eprintln!("frictl sim run: {n} samples -> {}", out.display());
            Ok(())
        }
    }
}
