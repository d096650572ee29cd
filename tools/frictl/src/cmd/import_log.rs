//! `frictl import csv|mat|mcap LOG… -o OUT.csv`: robot logs into the dataset format (CSV + JSON
//! sidecar) that `fit`, `train`, `eval` and `search` read.
//!
//! The files are read by `frictionless-logs` (one run per file, SI units, every conversion recorded),
//! then resampled, chunked, filtered and labelled by `frictionless-ident`'s one pipeline
//! (`preprocess_signals`). Formats, roles, units and the minimal columns per label source:
//! `docs/robot-logs.md`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use frictionless_dataset::{ColumnDocOwned, DatasetSidecar, LabelSource, RunInfo};
use frictionless_ident::preprocess::{
    PreprocessConfig, SignalsLabel, preprocess_signals, required_signals,
};
use frictionless_logs::{ImportedRun, Role, csv_log, mcap_log};
use sha2::Digest;

use super::preprocess::{PipelineArgs, urdf_link};

/// Label source on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelArg {
    /// r·k_t·i − τ_ID (needs s, current, --gear-ratio, --kt and the link dynamics: --urdf/--joint).
    Current,
    /// τ_motor − τ_joint (needs tau_joint, and tau_motor or current with --gear-ratio and --kt).
    TorqueSensor,
    /// The log's tau_f column.
    Given,
}

impl From<LabelArg> for LabelSource {
    fn from(l: LabelArg) -> Self {
        match l {
            LabelArg::Current => LabelSource::Current,
            LabelArg::TorqueSensor => LabelSource::TorqueSensor,
            LabelArg::Given => LabelSource::Given,
        }
    }
}

/// Options every log format shares.
#[derive(clap::Args, Debug)]
pub struct CommonArgs {
    /// Output dataset CSV (its sidecar is written next to it with `.json`).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Label source (default: `given` if tau_f is read, else `torque-sensor` if tau_joint is, else
    /// `current`).
    #[arg(long, value_enum)]
    pub label: Option<LabelArg>,
    /// Signed gear ratio r (motor angle per joint angle) for r·k_t·i and Δθ = r·s − θ; recorded in the
    /// sidecar (1 when not given and not needed, marked as a placeholder).
    #[arg(long, allow_negative_numbers = true)]
    pub gear_ratio: Option<f64>,
    /// Torque constant k_t [Nm/A] for r·k_t·i (1 when not given and not needed, as above).
    #[arg(long, allow_negative_numbers = true)]
    pub kt: Option<f64>,
    /// A time gap larger than this starts a new chunk [s] (default 0.1; `.mat`: gaps of the desired
    /// current stream > 1 s).
    #[arg(long, allow_negative_numbers = true)]
    pub gap_s: Option<f64>,
    /// Flip the sign of a role (sign conventions; repeatable), e.g. `--negate tau_f`.
    #[arg(long = "negate", value_name = "ROLE")]
    pub negate: Vec<String>,
    /// URDF for τ_ID of the current label (required by it: a robot log has no default robot).
    #[arg(long)]
    pub urdf: Option<String>,
    /// The joint's name in the URDF when it differs from the log's (default: the log's joint name).
    #[arg(long)]
    pub urdf_joint: Option<String>,
    /// Position of another URDF joint, held fixed [rad] (repeatable; absent joints are 0).
    #[arg(long = "fixed-joint", value_name = "NAME=RAD")]
    pub fixed_joints: Vec<String>,
    /// Resampling, filter, smoother and sample-limit settings.
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

/// Arguments of `frictl import csv`.
#[derive(clap::Args, Debug)]
pub struct CsvArgs {
    /// CSV logs; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name (the dataset's and the URDF's).
    #[arg(long)]
    pub joint: String,
    /// `ROLE=COLUMN` (repeatable). Roles: time, s, sdot, sddot, theta, omega, current, tau_joint,
    /// tau_motor, tau_f, temperature.
    #[arg(long = "column", value_name = "ROLE=COLUMN", required = true)]
    pub columns: Vec<String>,
    /// `ROLE=UNIT` (repeatable; default SI): time s|ms|us, angles rad|deg, velocities
    /// rad/s|deg/s|rpm, accelerations rad/s^2|deg/s^2, current A|mA, torques Nm|mNm, temperature C.
    #[arg(long = "unit", value_name = "ROLE=UNIT")]
    pub units: Vec<String>,
    /// Field delimiter (one character).
    #[arg(long, default_value = ",")]
    pub delimiter: char,
    /// Options every format shares.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Arguments of `frictl import mcap`.
#[derive(clap::Args, Debug)]
pub struct McapArgs {
    /// MCAP bags; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name, matched in every message.
    #[arg(long)]
    pub joint: String,
    /// Topic of the sensor_msgs/msg/JointState messages.
    #[arg(long, default_value = "/joint_states")]
    pub topic: String,
    /// Role of the `effort` field: tau_joint (a joint torque sensor), tau_motor, tau_f, or none.
    #[arg(long, default_value = "tau_joint")]
    pub effort: String,
    /// Options every format shares.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Arguments of `frictl import mat`.
#[derive(clap::Args, Debug)]
pub struct MatArgs {
    /// YARP robot logger `.mat` files; each becomes one run.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Joint name in `elements_names` (default: the one in the desired-current channel).
    #[arg(long)]
    pub joint: Option<String>,
    /// Options every format shares.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// A progress bar on stderr when it is a terminal (hidden otherwise).
fn bar(path: &Path) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(0);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {bytes}/{total_bytes} {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb.set_message(path.display().to_string());
    pb
}

fn read_all(
    files: &[PathBuf],
    mut read: impl FnMut(
        &Path,
        frictionless_logs::Progress,
    ) -> Result<ImportedRun, frictionless_logs::LogsError>,
) -> anyhow::Result<Vec<ImportedRun>> {
    let mut runs = Vec::with_capacity(files.len());
    for f in files {
        let pb = bar(f);
        let mut progress = |done: u64, total: u64| {
            pb.set_length(total);
            pb.set_position(done);
        };
        let run = read(f, &mut progress);
        pb.finish_and_clear();
        runs.push(run?);
    }
    frictionless_logs::unique_run_names(&mut runs);
    Ok(runs)
}

/// Runs `frictl import csv`.
pub fn run_csv(args: CsvArgs) -> anyhow::Result<()> {
    let mut spec = csv_log::CsvSpec::parse(&args.columns, &args.units, &args.common.negate)?;
    anyhow::ensure!(
        args.delimiter.is_ascii(),
        "--delimiter {:?}: must be one ASCII character",
        args.delimiter
    );
    spec.delimiter = args.delimiter as u8;
    check(&args.files, &args.common)?;
    let runs = read_all(&args.files, |p, pr| csv_log::read(p, &spec, pr))?;
    let units = spec.units.clone();
    finish(
        runs,
        &args.files,
        &args.joint,
        "csv",
        0.1,
        Some(&units),
        args.common,
    )
}

/// Runs `frictl import mcap`.
pub fn run_mcap(args: McapArgs) -> anyhow::Result<()> {
    let effort_role = mcap_log::parse_effort(&args.effort)
        .map_err(|e| anyhow::anyhow!("--effort {}: {e}", args.effort))?;
    let negate = args
        .common
        .negate
        .iter()
        .map(|n| Role::parse(n))
        .collect::<Result<Vec<_>, _>>()?;
    let spec = mcap_log::McapSpec {
        topic: args.topic.clone(),
        joint: args.joint.clone(),
        effort_role,
        negate,
    };
    check(&args.files, &args.common)?;
    let runs = read_all(&args.files, |p, pr| mcap_log::read(p, &spec, pr))?;
    finish(
        runs,
        &args.files,
        &args.joint,
        "mcap",
        0.1,
        None,
        args.common,
    )
}

/// Runs `frictl import mat`.
#[cfg(feature = "mat")]
pub fn run_mat(args: MatArgs) -> anyhow::Result<()> {
    use frictionless_logs::mat_log;
    let negate = args
        .common
        .negate
        .iter()
        .map(|n| Role::parse(n))
        .collect::<Result<Vec<_>, _>>()?;
    let spec = mat_log::MatSpec {
        joint: args.joint.clone(),
        negate,
        desired_gap_s: args.common.gap_s.unwrap_or(1.0),
    };
    check(&args.files, &args.common)?;
    let runs = read_all(&args.files, |p, pr| mat_log::read(p, &spec, pr))?;
    let joint = match &args.joint {
        Some(j) => j.clone(),
        None => runs
            .first()
            .and_then(|r| r.report.sources.get("joint").cloned())
            .unwrap_or_default(),
    };
    finish(runs, &args.files, &joint, "mat", 1.0, None, args.common)
}

/// Runs `frictl import mat` (built without the `mat` feature: explains how to get it).
#[cfg(not(feature = "mat"))]
pub fn run_mat(args: MatArgs) -> anyhow::Result<()> {
    let _ = args;
    bail!(
        "this frictl was built without `.mat` support (cargo feature `mat`, which needs the system HDF5 \
         library): install it with `apt install libhdf5-dev`, then rebuild with \
         `cargo install --path tools/frictl --features mat`"
    )
}

fn check(files: &[PathBuf], common: &CommonArgs) -> anyhow::Result<()> {
    // Every number is checked, needed or not: each goes into the sidecar.
    if let Some(r) = common.gear_ratio {
        anyhow::ensure!(
            r.is_finite() && r != 0.0,
            "--gear-ratio {r}: must be finite and non-zero (signed)"
        );
    }
    if let Some(k) = common.kt {
        anyhow::ensure!(
            k.is_finite() && k > 0.0,
            "--kt {k}: must be finite and > 0 [Nm/A] (a current of the other sign convention: \
             --negate current)"
        );
    }
    if let Some(g) = common.gap_s {
        anyhow::ensure!(
            g.is_finite() && g > 0.0,
            "--gap-s {g}: must be finite and > 0 [s]"
        );
    }
    let inputs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    let side = common.out.with_extension("json");
    super::check_outputs(&inputs, &[&common.out, &side])
}

fn finish(
    mut runs: Vec<ImportedRun>,
    files: &[PathBuf],
    joint: &str,
    format: &str,
    default_gap_s: f64,
    units: Option<&[(Role, frictionless_logs::Unit)]>,
    common: CommonArgs,
) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let first = &runs[0].signals;
    let label: LabelSource = match common.label {
        Some(l) => l.into(),
        None if first.tau_f_nm.is_some() => LabelSource::Given,
        None if first.tau_joint_nm.is_some() => LabelSource::TorqueSensor,
        None => LabelSource::Current,
    };
    let has = |role: &str| match role {
        "time" => true,
        "s" => first.s_rad.is_some(),
        "sdot" => first.sdot_rad_s.is_some(),
        "current" => first.current_a.is_some(),
        "tau_joint" => first.tau_joint_nm.is_some(),
        "tau_motor" => first.tau_motor_nm.is_some(),
        "tau_f" => first.tau_f_nm.is_some(),
        _ => false,
    };
    let lacking: Vec<&str> = required_signals(label)
        .iter()
        .copied()
        .filter(|group| !group.split('|').any(has))
        .collect();
    if !lacking.is_empty() {
        let why: Vec<&str> = runs
            .iter()
            .flat_map(|r| &r.report.warnings)
            .map(String::as_str)
            .collect();
        bail!(
            "the {label:?} label needs {} but the log gives none of: {} (pick another --label or map the column){}",
            required_signals(label).join(", "),
            lacking.join(", "),
            if why.is_empty() {
                String::new()
            } else {
                format!("; the reader says: {}", why.join("; "))
            }
        );
    }
    let (link_model, dynamics) = if label == LabelSource::Current {
        // The simulator's virtual leg is the default of `frictl preprocess` (the simulator's own
        // logs) only: a real robot's log labelled with another robot's dynamics would look fine.
        anyhow::ensure!(
            common.urdf.is_some(),
            "the current label needs the robot's link dynamics (τ_ID): pass --urdf ROBOT.urdf (and \
             --urdf-joint if the joint is named differently there); a robot log is never labelled \
             with the simulator's virtual leg"
        );
        let urdf_joint = common.urdf_joint.as_deref().unwrap_or(joint);
        let (m, d) = urdf_link(common.urdf.as_deref(), urdf_joint, &common.fixed_joints)?;
        (Some(m), d)
    } else {
        (
            None,
            "none (the label does not use inverse dynamics)".to_string(),
        )
    };
    let link = link_model
        .as_ref()
        .map(frictionless_sim::link::link_from_model)
        .transpose()?;
    let mut cfg = PreprocessConfig::for_joint(joint);
    cfg.gap_s = common.gap_s.unwrap_or(default_gap_s);
    if format == "mat" {
        // The .mat reader already cut chunks on the desired-current gaps; robot ticks are dense.
        cfg.gap_s = cfg.gap_s.max(1.0);
    }
    common.pipeline.apply(&mut cfg);
    // Units and rates: what a wrong declaration leaves in the numbers, before any work.
    let findings = frictionless_logs::plausibility::check(&runs, cfg.gap_s, units);
    let refused: Vec<&str> = findings
        .iter()
        .filter(|f| f.refuse)
        .map(|f| f.message.as_str())
        .collect();
    if !refused.is_empty() {
        bail!("{}", refused.join("\n"));
    }
    let suspicious: Vec<String> = findings.into_iter().map(|f| f.message).collect();
    // Moved out, not copied: memory stays one copy of the joint's signals plus the dataset.
    let signals: Vec<_> = runs
        .iter_mut()
        .map(|r| std::mem::take(&mut r.signals))
        .collect();
    let lab = SignalsLabel {
        source: label,
        gear_ratio_signed: common.gear_ratio,
        kt_nm_per_a: common.kt,
    };
    let (ds, sum) =
        preprocess_signals(&signals, &lab, link.as_deref(), &cfg).with_context(|| {
            format!(
                "labelling {} ({label:?} label needs: {})",
                files
                    .iter()
                    .map(|f| f.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                required_signals(label).join(", ")
            )
        })?;
    drop(signals);
    let mut warnings = Vec::new();
    if label == LabelSource::Given
        && let Some(w) = frictionless_logs::label_sign_warning(&ds)
    {
        warnings.push(w);
    }
    for r in &runs {
        warnings.extend(
            r.report
                .warnings
                .iter()
                .map(|w| format!("{}: {w}", r.report.source)),
        );
        let nf: u64 = r.report.non_finite.values().sum();
        if nf > 0 {
            warnings.push(format!(
                "{}: {nf} non-finite values dropped ({})",
                r.report.source,
                r.report
                    .non_finite
                    .iter()
                    .map(|(k, v)| format!("{k}: {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if r.report.time_not_increasing > 0 {
            warnings.push(format!(
                "{}: {} rows whose time did not increase dropped",
                r.report.source, r.report.time_not_increasing
            ));
        }
    }
    warnings.extend(suspicious.iter().cloned());
    let valid = ds.valid.iter().filter(|v| **v).count();
    let empty_runs: Vec<String> = runs
        .iter()
        .zip(&sum.run_chunks)
        .filter(|(_, c)| c.is_empty())
        .map(|(r, _)| {
            format!(
                "run {}: {} of {} rows read, 0 chunks",
                r.name, r.report.rows_used, r.report.rows_read
            )
        })
        .collect();
    if valid == 0 || !empty_runs.is_empty() {
        bail!(
            "{} valid samples of {}{}{}",
            valid,
            ds.len(),
            if empty_runs.is_empty() {
                String::new()
            } else {
                format!("; nothing of {}", empty_runs.join(", "))
            },
            if suspicious.is_empty() {
                "; check the units and --gap-s".to_string()
            } else {
                format!("; likely why: {}", suspicious.join("; "))
            }
        );
    }
    let placeholder = |v: Option<f64>| v.unwrap_or(1.0);
    ds.write_csv(&common.out)?;
    let mut hashes = Vec::new();
    for f in files {
        hashes.push(
            frictionless_dataset::file_sha256_hex(f)
                .with_context(|| format!("cannot read {}", f.display()))?,
        );
    }
    let input_sha256 = if hashes.len() == 1 {
        hashes[0].clone()
    } else {
        format!("{:x}", sha2::Sha256::digest(hashes.join("\n").as_bytes()))
    };
    let run_infos: Vec<RunInfo> = runs
        .iter()
        .zip(&sum.run_chunks)
        .map(|(r, c)| RunInfo {
            name: r.name.clone(),
            source: r.report.source.clone(),
            chunks: c.clone(),
        })
        .collect();
    let reports: Vec<_> = runs
        .iter()
        .zip(&hashes)
        .map(|(r, h)| serde_json::json!({ "run": r.name, "sha256": h, "report": r.report }))
        .collect();
    let settings = serde_json::json!({
        "pipeline": cfg,
        "import": {
            "format": format,
            "label": label,
            "gear_ratio_signed": common.gear_ratio.map_or("not given (1 written as a placeholder)".to_string(), |r| r.to_string()),
            "kt_nm_per_a": common.kt.map_or("not given (1 written as a placeholder)".to_string(), |k| k.to_string()),
            "derivations": sum.derivations,
            "dropped_single_sample_chunks": sum.dropped_single_sample_chunks,
            "delta_theta_offsets_motor_rad": sum.delta_theta_offsets_motor_rad.iter().map(|v| if v.is_finite() { serde_json::json!(v) } else { serde_json::Value::Null }).collect::<Vec<_>>(),
            "runs": reports,
            "warnings": warnings,
        }
    });
    let side = DatasetSidecar {
        format: "frictionless-dataset-v1".into(),
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        input_log: files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        input_sha256,
        joint: joint.to_string(),
        gear_ratio_signed: placeholder(common.gear_ratio),
        kt_nm_per_a: placeholder(common.kt),
        fs_hz: cfg.fs_hz,
        settings,
        dynamics,
        delta_theta_offset_motor_rad: sum
            .delta_theta_offsets_motor_rad
            .first()
            .copied()
            .filter(|v| v.is_finite())
            .unwrap_or(0.0),
        samples: ds.len(),
        valid_samples: valid,
        chunks: sum.run_chunks.iter().map(Vec::len).sum(),
        short_chunks: sum.short_chunks,
        columns: ds.columns().iter().map(ColumnDocOwned::from).collect(),
        label,
        runs: run_infos,
        absent_columns: sum.absent_columns.iter().map(|s| s.to_string()).collect(),
    };
    let side_path = common.out.with_extension("json");
    std::fs::write(&side_path, serde_json::to_string_pretty(&side)?)
        .with_context(|| format!("cannot write {}", side_path.display()))?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    for (r, c) in runs.iter().zip(&sum.run_chunks) {
        eprintln!(
            "  run {}: {} of {} rows used, {} chunks",
            r.name,
            r.report.rows_used,
            r.report.rows_read,
            c.len()
        );
    }
    if ds.is_empty() {
        bail!("no samples");
    }
    eprintln!(
        "frictl import {format}: {} runs, {} samples ({valid} valid, {} chunks, {} too short), label {label:?}, absent columns [{}] in {:.2} s -> {}",
        runs.len(),
        ds.len(),
        side.chunks,
        sum.short_chunks,
        side.absent_columns.join(", "),
        started.elapsed().as_secs_f64(),
        common.out.display()
    );
    Ok(())
}
