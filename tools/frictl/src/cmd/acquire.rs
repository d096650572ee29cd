//! `frictl acquire` — run the excitation protocol and log a dataset (CSV + JSON sidecar).
//!
//! Offline against the simulator (default: fast, truth columns included), or live against a plant
//! over shared memory (`--live-shm`: [`frictionless_plant::shm::LiveJoint`], e.g. `frictl sim serve`),
//! through the same `frictionless_acquire::JointIo` seam and the same controllers.
//!
//! `--sensor torque` (offline only) logs the joint as a torque-sensed arm would: joint position and
//! velocity, current, a joint torque sensor at the output flange and no motor encoder
//! (`frictionless_acquire::arm_log`), optionally at `--log-period-ms` with `--jitter-ms` timestamp
//! jitter — a CSV for `frictl import csv`, not for `frictl preprocess`.

use std::io::IsTerminal;
use std::time::Duration;

use anyhow::Context;
use frictionless_acquire::arm_log::{ArmLog, ArmLogOptions, arm_columns};
use frictionless_acquire::log::{
    CsvLog, LiveInfo, SOURCE_LIVE_SHM, SOURCE_OFFLINE_SIM, Sidecar, columns,
};
use frictionless_acquire::protocol::run as run_protocol;
use frictionless_acquire::protocol::{AcquireError, ControllerModel, schedule_duration_s};
use frictionless_acquire::{ProtocolConfig, run_offline, schedule};
use frictionless_sim::PlantParams;
use frictionless_sim::params::load_table;

pub use frictl_cli::acquire::*;

/// Runs `frictl acquire`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.preset == frictionless_plant::LEG_PRESET {
        return run_leg(&args);
    }
    frictionless_sim::params::check_set_joints(&args.sets, &[args.preset.as_str()])?;
    let table = load_table(&args.preset, args.params.as_deref(), &args.sets)?;
    let plant_params = PlantParams::from_table(&table)?;
    let protocol = ProtocolConfig::from_table(&table)?;
    let blocks = schedule(&protocol);
    anyhow::ensure!(!blocks.is_empty(), "the protocol has no enabled blocks");

    let name = log_name(&args, &plant_params.joint);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let csv_path = args.out.join(format!("{name}.csv"));
    let json_path = args.out.join(format!("{name}.json"));

    let period_s = plant_params.sample_period_s();
    let total = (schedule_duration_s(&blocks) / period_s).round() as u64;
    // The controllers' link model (live runs; offline runs build their own): fail before any I/O.
    let link = frictionless_sim::link::link_from_model(&plant_params.link)?;

    let with_truth = !args.live_shm;
    let torque = args.sensor == Sensor::Torque;
    let every = log_every(&args, period_s)?;
    let mut log = open_log(&args, &plant_params, &csv_path, every, with_truth)?;
    let bar = progress_bar(total);
    let started = std::time::Instant::now();
    let mut n = 0u64;
    let mut sink = |row: &frictionless_acquire::LogRow| -> Result<(), AcquireError> {
        n += 1;
        if n.is_multiple_of(if args.live_shm { 100 } else { 10_000 }) {
            bar.set_position(n);
        }
        log.write(row)
    };

    let mut t0 = None;
    let mut live_info = None;
    let summary = if args.live_shm {
        let (summary, info) = acquire_live(
            &args,
            &plant_params,
            link.as_ref(),
            &protocol,
            &blocks,
            &mut sink,
        )?;
        live_info = Some(info);
        summary
    } else {
        let run = run_offline(&plant_params, &protocol, &blocks, args.seed, &mut sink)?;
        t0 = Some(run.initial_temperature_c);
        run.summary
    };
    bar.finish_and_clear();
    let rows = log.rows(summary.samples);
    // Committed with its sidecar, the sidecar last (below).
    let csv_out = log.finish()?;
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
        simulated: !args.live_shm,
        source: if args.live_shm {
            SOURCE_LIVE_SHM
        } else {
            SOURCE_OFFLINE_SIM
        },
        live: live_info,
        seed: (!args.live_shm).then_some(args.seed),
        initial_temperature_c: t0,
        preset: &args.preset,
        plant: Some(&plant_params),
        protocol: &protocol,
        csv: &csv_name,
        columns: if torque {
            arm_columns(plant_params.sensors.temperature_sensor)
        } else {
            columns(with_truth)
        },
        chunks: &blocks,
        summary: &summary,
    };
    commit_log(csv_out, &csv_path, &json_path, &sidecar)?;
    report_done(&summary, torque.then_some(rows), elapsed, &csv_path);
    Ok(())
}

/// `--name`, or `JOINT_live` / `JOINT_seedN`.
fn log_name(args: &Args, joint: &str) -> String {
    args.name.clone().unwrap_or_else(|| {
        if args.live_shm {
            format!("{joint}_live")
        } else {
            format!("{joint}_seed{}", args.seed)
        }
    })
}

/// Plant samples per logged row (`--log-period-ms`, only with `--sensor torque`): a whole number
/// ≥ 1 of plant samples of `period_s`.
fn log_every(args: &Args, period_s: f64) -> anyhow::Result<f64> {
    anyhow::ensure!(
        args.sensor == Sensor::Torque || (args.log_period_ms == 1.0 && args.jitter_ms == 0.0),
        "--log-period-ms and --jitter-ms need --sensor torque"
    );
    let every = args.log_period_ms * 1e-3 / period_s;
    anyhow::ensure!(
        every.is_finite() && every >= 1.0 && (every - every.round()).abs() < 1e-9,
        "--log-period-ms {}: must be a whole number (>= 1) of plant samples of {} ms",
        args.log_period_ms,
        period_s * 1e3
    );
    Ok(every)
}

/// The console line of a finished single-joint acquisition (`arm_rows`: the rows of a
/// torque-sensed arm log).
fn report_done(
    summary: &frictionless_acquire::RunSummary,
    arm_rows: Option<u64>,
    elapsed_s: f64,
    csv_path: &std::path::Path,
) {
    eprintln!(
        "frictl acquire: {} samples{} ({:.1} simulated min, {} chunks, {} active, {} guard holds) in {:.2} s -> {}",
        summary.samples,
        arm_rows.map_or(String::new(), |rows| format!(
            ", {rows} rows (torque-sensed arm log)"
        )),
        summary.duration_s / 60.0,
        summary.chunks,
        summary.active_samples,
        summary.latches.len(),
        elapsed_s,
        csv_path.display()
    );
}

/// The log `csv_path` (not yet committed): a torque-sensed arm's every `every` plant samples with
/// `--sensor torque`, else the robot's (with the truth column when `with_truth`).
fn open_log(
    args: &Args,
    plant_params: &PlantParams,
    csv_path: &std::path::Path,
    every: f64,
    with_truth: bool,
) -> anyhow::Result<Log<frictionless::output_file::AtomicFile>> {
    let period_s = plant_params.sample_period_s();
    let writer = frictionless::output_file::AtomicFile::create(csv_path)
        .with_context(|| format!("cannot create {}", csv_path.display()))?;
    Ok(if args.sensor == Sensor::Torque {
        Log::Arm(Box::new(ArmLog::new(
            writer,
            ArmLogOptions {
                every_samples: every.round() as u32,
                jitter_s: args.jitter_ms * 1e-3,
                sample_period_s: period_s,
                with_temperature: plant_params.sensors.temperature_sensor,
                sensor: plant_params.torque_sensor.clone(),
                seed: args.seed,
            },
        )?))
    } else {
        Log::Robot(CsvLog::new(writer, with_truth)?)
    })
}

/// A progress bar of `total` samples on a terminal, hidden otherwise.
fn progress_bar(total: u64) -> indicatif::ProgressBar {
    let bar = if std::io::stderr().is_terminal() {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} samples ({eta} left)")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

/// Connects to the plant on `--prefix`/`--root-path` as joint `joint_index` (sample period
/// `period_s`), with `--connect-timeout-s` and `--state-timeout-ms`; Ctrl-C stops it.
fn connect_live(
    args: &Args,
    joint_index: usize,
    period_s: f64,
) -> anyhow::Result<frictionless_plant::shm::LiveJoint<'_>> {
    let stop = frictionless_plant::install_stop_flag()?;
    anyhow::ensure!(
        args.connect_timeout_s.is_finite() && args.connect_timeout_s > 0.0,
        "--connect-timeout-s must be > 0, got {}",
        args.connect_timeout_s
    );
    let cfg = frictionless_shm_types::IpcConfig::new(args.root_path.as_deref(), &args.prefix);
    Ok(frictionless_plant::shm::LiveJoint::connect(
        &cfg,
        joint_index,
        period_s,
        Duration::from_secs_f64(args.connect_timeout_s),
        Duration::from_millis(args.state_timeout_ms),
        stop,
    )?)
}

/// The sidecar's record of a live run through `joint` (joint `joint_index`).
fn live_info(
    args: &Args,
    joint: &frictionless_plant::shm::LiveJoint,
    joint_index: usize,
) -> LiveInfo {
    LiveInfo {
        prefix: args.prefix.clone(),
        root_path: args.root_path.as_ref().map(|p| p.display().to_string()),
        joint_index,
        first_seq: joint.first_seq(),
        states_received: joint.states_received,
        states_skipped: joint.states_skipped,
        plant_publishes_sim_truth: joint.plant_publishes_sim_truth,
    }
}

/// `--live-shm`: the protocol run through a plant served on shared memory; the joint is left at
/// 0 A whatever happens.
fn acquire_live(
    args: &Args,
    plant_params: &PlantParams,
    link: &dyn frictionless_sim::link::LinkDynamics,
    protocol: &ProtocolConfig,
    blocks: &[frictionless_acquire::protocol::Block],
    sink: &mut dyn FnMut(&frictionless_acquire::LogRow) -> Result<(), AcquireError>,
) -> anyhow::Result<(frictionless_acquire::RunSummary, LiveInfo)> {
    let mut joint = connect_live(args, args.joint_index, plant_params.sample_period_s())?;
    let model = ControllerModel::nominal(plant_params, link);
    let result = run_protocol(&mut joint, &model, protocol, blocks, sink);
    // Leave the joint at 0 A whatever happened (the plant also zeroes after its timeout).
    let released = joint.release();
    let info = live_info(args, &joint, args.joint_index);
    let summary = result?;
    released?;
    Ok((summary, info))
}

/// The log being written: the robot's (motor encoder) or a torque-sensed arm's.
enum Log<W: std::io::Write> {
    Robot(CsvLog<W>),
    Arm(Box<ArmLog<W>>),
}

impl<W: std::io::Write> Log<W> {
    fn write(&mut self, row: &frictionless_acquire::LogRow) -> Result<(), AcquireError> {
        match self {
            Log::Robot(l) => l.write(row),
            Log::Arm(l) => l.write(row),
        }
    }

    /// Rows in the file (`samples` for the robot log: one per sample).
    fn rows(&self, samples: u64) -> u64 {
        match self {
            Log::Robot(_) => samples,
            Log::Arm(l) => l.rows(),
        }
    }

    fn finish(self) -> Result<W, AcquireError> {
        match self {
            Log::Robot(l) => l.finish(),
            Log::Arm(l) => l.finish(),
        }
    }
}

/// Per-joint columns of the leg log: (name template with `{joint}`, unit, description).
const LEG_COLUMNS: &[(&str, &str, &str)] = &[
    (
        "q_{joint}",
        "rad",
        "joint position (joint encoder, quantised)",
    ),
    (
        "qd_{joint}",
        "rad/s",
        "controller's filtered encoder-difference joint velocity",
    ),
    (
        "theta_{joint}",
        "rad",
        "motor position (motor encoder, motor side)",
    ),
    ("omega_{joint}", "rad/s", "motor velocity (motor side)"),
    (
        "i_ref_{joint}",
        "A",
        "current reference applied during the next period",
    ),
    ("i_{joint}", "A", "measured motor current"),
    (
        "temperature_{joint}",
        "degC",
        "motor temperature (NaN: no sensor)",
    ),
    ("chunk_{joint}", "-", "the joint's protocol block"),
    (
        "active_{joint}",
        "-",
        "1 = excitation sample of the joint's block",
    ),
    (
        "tau_f_true_{joint}",
        "Nm",
        "simulator truth: total joint friction (motor side + LuGre)",
    ),
];

/// The leg log's sidecar (`<name>.json`).
#[derive(serde::Serialize)]
struct LegSidecar<'a> {
    format: &'static str,
    producer: String,
    preset: &'static str,
    source: &'static str,
    /// Live runs: the connection facts (`joint_index` 0: every joint from 0 is driven).
    live: Option<LiveInfo>,
    seed: Option<u64>,
    sample_period_s: f64,
    csv: String,
    /// The leg's joints in column order, with the constants a label needs.
    joints: Vec<LegSidecarJoint<'a>>,
    /// Per-joint columns (`{joint}` replaced by each joint name) after `time_s`.
    columns: Vec<serde_json::Value>,
    /// How to label every joint from the whole leg's state.
    import_example: String,
}

#[derive(serde::Serialize)]
struct LegSidecarJoint<'a> {
    joint: &'a str,
    gear_ratio_signed: f64,
    kt_nm_per_a: f64,
    j_eq_kgm2: f64,
    protocol: &'a ProtocolConfig,
    summary: &'a frictionless_acquire::RunSummary,
}

/// `frictl acquire --preset leg`: every leg joint excited at once (offline), one CSV with every
/// joint's columns and a JSON sidecar.
fn run_leg(args: &Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.sensor == Sensor::MotorEncoder,
        "--preset leg: --sensor torque is a single-joint log"
    );
    anyhow::ensure!(
        args.params.is_none(),
        "--preset leg: --params applies to single-joint presets; use --set JOINT:plant.KEY=VALUE"
    );
    let (protocol_sets, plant_sets): (Vec<String>, Vec<String>) = args
        .sets
        .iter()
        .cloned()
        .partition(|s| s.starts_with("protocol."));
    let leg = frictionless_sim::LegParams::from_toml_str(
        frictionless_sim::leg::LEG_PRESET_TOML,
        "<preset leg>",
        &plant_sets,
    )?;
    let protocols = frictionless_acquire::leg::leg_protocols(&leg, &protocol_sets)?;
    let name = args.name.clone().unwrap_or_else(|| {
        if args.live_shm {
            "leg_live".to_owned()
        } else {
            format!("leg_seed{}", args.seed)
        }
    });
    // Live: no truth column (the process only sees what a robot reports).
    let columns: Vec<&(&str, &str, &str)> = LEG_COLUMNS
        .iter()
        .filter(|c| !(args.live_shm && c.0.starts_with("tau_f_true")))
        .collect();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let csv_path = args.out.join(format!("{name}.csv"));
    let json_path = args.out.join(format!("{name}.json"));
    let names: Vec<&str> = leg.joints.iter().map(|p| p.joint.as_str()).collect();
    let mut out = std::io::BufWriter::with_capacity(
        1 << 20,
        frictionless::output_file::AtomicFile::create(&csv_path)
            .with_context(|| format!("cannot create {}", csv_path.display()))?,
    );
    std::io::Write::write_all(&mut out, leg_csv_header(&columns, &names).as_bytes())
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    let started = std::time::Instant::now();
    let mut line = String::new();
    let mut samples = 0u64;
    let n_fields = columns.len();
    let mut sink = |rows: &[frictionless_acquire::leg::LegRow]| -> Result<(), AcquireError> {
        leg_csv_line(&mut line, rows, n_fields);
        line.push('\n');
        samples += 1;
        std::io::Write::write_all(&mut out, line.as_bytes())
            .map_err(|e| AcquireError::Sink(e.to_string()))
    };
    let (summaries, live_info) = if args.live_shm {
        let (summaries, info) = acquire_leg_live(args, &leg, &protocols, &mut sink)?;
        (summaries, Some(info))
    } else {
        let summaries = frictionless_acquire::leg::run_leg_offline_with_velocity(
            &leg, &protocols, args.seed, &mut sink,
        )?;
        (summaries, None)
    };
    let csv_out = out
        .into_inner()
        .map_err(|e| anyhow::anyhow!("cannot write {}: {}", csv_path.display(), e.error()))?;
    let period_s = leg.joints[0].sample_period_s();
    let sidecar = LegSidecar {
        live: live_info,
        seed: (!args.live_shm).then_some(args.seed),
        ..LegSidecar::new(&name, &leg, &protocols, &summaries, &columns, args.live_shm)
    };
    commit_log(csv_out, &csv_path, &json_path, &sidecar)?;
    eprintln!(
        "frictl acquire: leg, {} joints excited at once, {samples} samples ({:.1} simulated min, {} guard holds) in {:.2} s -> {}",
        names.len(),
        samples as f64 * period_s / 60.0,
        summaries.iter().map(|s| s.latches.len()).sum::<usize>(),
        started.elapsed().as_secs_f64(),
        csv_path.display()
    );
    Ok(())
}

/// The leg log's header line: `time_s`, then each column of `columns` for every joint of `names`.
fn leg_csv_header(columns: &[&(&str, &str, &str)], names: &[&str]) -> String {
    let mut header = String::from("time_s");
    for (col, _, _) in columns {
        for j in names {
            header.push(',');
            header.push_str(&col.replace("{joint}", j));
        }
    }
    header.push('\n');
    header
}

impl<'a> LegSidecar<'a> {
    /// The sidecar of the leg log `name`.csv (`live`: recorded through shared memory; the live
    /// details and the seed are the caller's).
    fn new(
        name: &str,
        leg: &'a frictionless_sim::LegParams,
        protocols: &'a [ProtocolConfig],
        summaries: &'a [frictionless_acquire::RunSummary],
        columns: &[&(&str, &str, &str)],
        live: bool,
    ) -> Self {
        LegSidecar {
            format: "frictionless-acquire-leg-v1",
            producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
            preset: frictionless_plant::LEG_PRESET,
            source: if live {
                SOURCE_LIVE_SHM
            } else {
                SOURCE_OFFLINE_SIM
            },
            live: None,
            seed: None,
            sample_period_s: leg.joints[0].sample_period_s(),
            csv: format!("{name}.csv"),
            joints: leg
                .joints
                .iter()
                .zip(protocols)
                .zip(summaries)
                .map(|((p, c), s)| LegSidecarJoint {
                    joint: &p.joint,
                    gear_ratio_signed: p.gear_ratio_signed,
                    kt_nm_per_a: p.kt_nm_per_a,
                    j_eq_kgm2: p.j_eq_kgm2(),
                    protocol: c,
                    summary: s,
                })
                .collect(),
            columns: std::iter::once(serde_json::json!({"name": "time_s", "unit": "s",
            "description": "simulated time"}))
            .chain(
                columns
                    .iter()
                    .map(|(n, u, d)| serde_json::json!({"name": n, "unit": u, "description": d})),
            )
            .collect(),
            import_example: leg_import_example(name, leg),
        }
    }
}

/// One line of the leg's CSV log (without the newline): the time, then each of the first
/// `n_fields` fields of [`LEG_COLUMNS`] for every joint of `rows`, in shortest round-trip form of
/// their significant digits.
fn leg_csv_line(line: &mut String, rows: &[frictionless_acquire::leg::LegRow], n_fields: usize) {
    use std::fmt::Write as _;
    line.clear();
    let num = |line: &mut String, v: f64| {
        let _ = write!(line, ",{}", frictionless_acquire::log::round_significant(v));
    };
    let _ = write!(
        line,
        "{}",
        frictionless_acquire::log::round_significant(rows[0].row.meas.time_s)
    );
    let fields: [fn(&frictionless_acquire::leg::LegRow) -> f64; 10] = [
        |r| r.row.meas.s_rad,
        |r| r.sdot_rad_s,
        |r| r.row.meas.theta_motor_rad,
        |r| r.row.meas.omega_motor_rad_s,
        |r| r.row.i_ref_a,
        |r| r.row.meas.i_meas_a,
        |r| r.row.meas.temperature_c,
        |r| f64::from(r.row.chunk),
        |r| f64::from(u8::from(r.row.active)),
        |r| r.row.truth.map_or(f64::NAN, |t| t.tau_f_nm),
    ];
    for f in &fields[..n_fields] {
        for r in rows {
            num(line, f(r));
        }
    }
}

/// `--preset leg --live-shm`: the leg excited through a plant served on shared memory
/// (`frictl sim serve --preset leg`); every joint is left at 0 A whatever happens.
fn acquire_leg_live(
    args: &Args,
    leg: &frictionless_sim::LegParams,
    protocols: &[ProtocolConfig],
    sink: &mut dyn FnMut(&[frictionless_acquire::leg::LegRow]) -> Result<(), AcquireError>,
) -> anyhow::Result<(Vec<frictionless_acquire::RunSummary>, LiveInfo)> {
    let mut robot = connect_live(args, 0, leg.joints[0].sample_period_s())?;
    anyhow::ensure!(
        robot.n_joints() == leg.joints.len(),
        "--preset leg --live-shm: the plant on `{}` publishes {} joint(s), the leg has {} \
         (serve it with `frictl sim serve --preset leg`)",
        args.prefix,
        robot.n_joints(),
        leg.joints.len()
    );
    let result = frictionless_acquire::leg::run_leg(&mut robot, leg, protocols, sink);
    // Leave every joint at 0 A whatever happened (the plant also zeroes after its timeout).
    let released = robot.release_all(leg.joints.len());
    let info = live_info(args, &robot, 0);
    let summaries = result?;
    released?;
    Ok((summaries, info))
}

/// The `frictl import csv` command that labels the leg log `name`.csv.
fn leg_import_example(name: &str, leg: &frictionless_sim::LegParams) -> String {
    let urdf = frictionless_sim::leg::ERGOCUB_URDF_PATH;
    let mut example = format!(
        "frictl import csv {name}.csv --joints all --label current --column time=time_s \
         --column s=q_{{joint}} --column current=i_{{joint}} --column theta=theta_{{joint}} \
         --column omega=omega_{{joint}} --positions 'q_{{joint}}' --urdf {urdf}"
    );
    for p in &leg.joints {
        let _ = std::fmt::Write::write_fmt(
            &mut example,
            format_args!(
                " --gear-ratio {}={} --kt {}={}",
                p.joint, p.gear_ratio_signed, p.joint, p.kt_nm_per_a
            ),
        );
    }
    example.push_str(" -o 'ds_{joint}.csv'");
    example
}

/// Writes the sidecar JSON and commits the CSV log and it as a pair (the sidecar last, so a log
/// without its sidecar never looks complete).
fn commit_log<T: serde::Serialize>(
    csv_out: frictionless::output_file::AtomicFile,
    csv_path: &std::path::Path,
    json_path: &std::path::Path,
    sidecar: &T,
) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(sidecar)?;
    let mut side_out = frictionless::output_file::AtomicFile::create(json_path)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    std::io::Write::write_all(&mut side_out, json.as_bytes())
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    frictionless::output_file::commit_with_marker(vec![csv_out], side_out).with_context(|| {
        format!(
            "cannot write {} and {}",
            csv_path.display(),
            json_path.display()
        )
    })
}
