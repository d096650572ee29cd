//! `frictl acquire` — run the excitation protocol and log a dataset (CSV + JSON sidecar).
//!
//! Offline against the simulator (the only plant for now); a live plant over shared memory plugs in
//! through `frictl::acquire::JointIo` once the shm ABI exists.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use frictl::acquire::log::{CsvLog, Sidecar, columns};
use frictl::acquire::protocol::run as run_protocol;
use frictl::acquire::protocol::{ControllerModel, SimJoint, schedule_duration_s};
use frictl::acquire::{ProtocolConfig, schedule};
use frictl::sim::params::load_table;
use frictl::sim::{Plant, PlantParams};

/// Arguments of `frictl acquire`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in preset (`knee`, `ankle_roll`) or a preset TOML file (tables `plant` and `protocol`).
    #[arg(long)]
    pub preset: String,
    /// TOML file deep-merged over the preset (same layout).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Override one parameter, e.g. `--set plant.k1_nm_per_rad=2e4 --set protocol.steps.enabled=false`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Simulator seed (initial temperature, current noise).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Base name of the files (default `<joint>_seed<seed>`): NAME.csv and NAME.json.
    #[arg(long)]
    pub name: Option<String>,
}

/// Runs `frictl acquire`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let table = load_table(&args.preset, args.params.as_deref(), &args.sets)?;
    let plant_params = PlantParams::from_table(&table)?;
    let protocol = ProtocolConfig::from_table(&table)?;
    let blocks = schedule(&protocol);
    anyhow::ensure!(!blocks.is_empty(), "the protocol has no enabled blocks");

    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("{}_seed{}", plant_params.joint, args.seed));
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let csv_path = args.out.join(format!("{name}.csv"));
    let json_path = args.out.join(format!("{name}.json"));

    let plant = Plant::from_params(plant_params.clone(), args.seed)?;
    let t0 = plant.state().temperature_c;
    let period_s = plant_params.sample_period_s();
    let total = (schedule_duration_s(&blocks) / period_s).round() as u64;
    let link = frictl::sim::link::link_from_model(&plant_params.link)?;
    let model = ControllerModel {
        gear_ratio_signed: plant_params.gear_ratio_signed,
        kt_nm_per_a: plant_params.kt_nm_per_a,
        j_eq_kgm2: plant_params.j_eq_kgm2(),
        i_max_a: plant_params.i_max_a,
        period_s,
        link: link.as_ref(),
    };
    let mut joint = SimJoint {
        plant,
        tau_ext_nm: 0.0,
    };

    let file = std::fs::File::create(&csv_path)
        .with_context(|| format!("cannot create {}", csv_path.display()))?;
    let mut log = CsvLog::new(std::io::BufWriter::with_capacity(1 << 20, file), true)?;
    let bar = if std::io::stderr().is_terminal() {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} samples ({eta} left)")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let mut n = 0u64;
    let summary = run_protocol(&mut joint, &model, &protocol, &blocks, &mut |row| {
        n += 1;
        if n.is_multiple_of(10_000) {
            bar.set_position(n);
        }
        log.write(row)
    })?;
    bar.finish_and_clear();
    log.finish()?
        .into_inner()
        .map_err(|e| anyhow::anyhow!("cannot flush {}: {}", csv_path.display(), e.error()))?;
    let elapsed = started.elapsed().as_secs_f64();

    let csv_name = csv_path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let sidecar = Sidecar {
        format: "frictionless-acquire-v1",
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        joint: &plant_params.joint,
        gear_ratio_signed: plant_params.gear_ratio_signed,
        kt_nm_per_a: plant_params.kt_nm_per_a,
        sample_period_s: period_s,
        simulated: true,
        seed: Some(args.seed),
        initial_temperature_c: Some(t0),
        preset: &args.preset,
        plant: Some(&plant_params),
        protocol: &protocol,
        csv: &csv_name,
        columns: columns(true),
        chunks: &blocks,
        summary: &summary,
    };
    let json = serde_json::to_string_pretty(&sidecar)?;
    std::fs::write(&json_path, json)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    eprintln!(
        "frictl acquire: {} samples ({:.1} simulated min, {} chunks, {} active, {} guard holds) in {:.2} s -> {}",
        summary.samples,
        summary.duration_s / 60.0,
        summary.chunks,
        summary.active_samples,
        summary.latches.len(),
        elapsed,
        csv_path.display()
    );
    Ok(())
}
