//! Recorded datasets played through `frictiond` itself: "what would the daemon have done on this
//! log" (`frictl replay`).
//!
//! What it **is**: [`replay`] loads the deployed frictiond config as frictiond does (every model
//! file read and checked), changes only how the daemon meets the world — the shared-memory backend
//! on a private iceoryx2 root, the lockstep trigger, no RT settings — and starts the real
//! `frictiond` on it. It then plays the datasets' rows as [`JointStates`], one tick per row, each
//! answered by a [`TorqueRequest`] with τ_des = 0 that enables the replayed joints, and records the
//! daemon's [`MotorCurrentCommand`] of every tick: the estimate the law was given
//! (`tau_f_model_nm`, before kfc, the clip and the filter), the current command and the flags.
//!
//! Every joint is enabled at its dataset's first row, as after a fresh boot: a joint with an
//! incremental motor encoder latches its Δθ there, exactly as on the robot. Where a dataset starts a
//! new chunk (another recording, a gap), the daemon sees one tick with every joint disabled before
//! the chunk's first row, so every joint is enabled again there (a chunk boundary is a re-enable of
//! the whole robot; the rows of every dataset keep their one-to-one ticks).
//!
//! What it is **not**: no second implementation of anything the daemon does (the numbers are the
//! daemon's), no plant and no controller: τ_des is 0, so `current_a` is the compensation command
//! alone, and the torque-feedback terms of the law see τ_meas = 0.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use frictiond_config::{BackendConfig, BackendKind, ConfigError, RawConfig, Trigger};
use frictionless::output_file::{self, AtomicFile};
use frictionless_dataset::{Dataset, DatasetError};
use frictionless_shm_types::{
    FLAG_DISABLED, FLAG_FAULT, FLAG_NON_FINITE, FLAG_OUT_OF_RANGE, FLAG_STALE, FLAG_WARMING_UP,
    Inbox, Ipc, JointStates, MAX_JOINTS, MotorCurrentCommand, Outbox, ShmError, TorqueRequest,
    monotonic_ns,
};
use serde::Serialize;

use crate::ExperimentError;
use crate::session::{Binaries, Session, interrupted};

/// What to replay: the deployed config, a dataset per joint and the output directory.
#[derive(Clone, Debug)]
pub struct ReplayJob {
    /// The frictiond config as deployed on the robot.
    pub config: PathBuf,
    /// `(joint name in the config, dataset CSV)`, one per replayed joint; the datasets are one
    /// recording's (same rows, same times).
    pub datasets: Vec<(String, PathBuf)>,
    /// Output directory: `JOINT.csv` per joint, `replay.json`, `frictiond.replay.toml`.
    pub out: PathBuf,
}

/// One replayed joint's result.
#[derive(Clone, Debug, Serialize)]
pub struct JointReplay {
    /// Joint name (the config's).
    pub joint: String,
    /// Payload index.
    pub index: usize,
    /// The dataset played.
    pub dataset: PathBuf,
    /// The CSV written (one row per dataset row).
    pub csv: PathBuf,
    /// Rows played.
    pub rows: usize,
    /// Rows on which the joint ran its model (not disabled, stale, faulted or non-finite).
    pub model_rows: usize,
    /// Rows flagged out of the training range.
    pub out_of_range_rows: usize,
    /// Rows still warming up (a PINN's history not yet full).
    pub warming_up_rows: usize,
    /// RMSE of `tau_f_hat_nm` against the dataset's label over the rows that are valid, ran the
    /// model and are past the warm-up [Nm] (`None` when no row qualifies).
    pub rmse_vs_label_nm: Option<f64>,
    /// Rows behind [`JointReplay::rmse_vs_label_nm`].
    pub scored_rows: usize,
}

/// The whole replay.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayOutcome {
    /// The config replayed.
    pub config: PathBuf,
    /// Daemon ticks run (rows plus one per chunk boundary).
    pub ticks: u64,
    /// Chunk boundaries at which every joint was enabled again.
    pub reenables: usize,
    /// Wall time of the tick loop [s].
    pub wall_s: f64,
    /// Per joint, in the order given.
    pub joints: Vec<JointReplay>,
}

/// Why a replay could not run or finish.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The config is not one frictiond would start with.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A dataset could not be read.
    #[error("dataset {}", .path.display())]
    Dataset {
        /// The dataset.
        path: PathBuf,
        /// Why.
        #[source]
        source: DatasetError,
    },
    /// Nothing to replay.
    #[error("no dataset given: name one per joint as JOINT=DATASET.csv")]
    NoDatasets,
    /// A dataset names a joint the config does not have.
    #[error("joint `{joint}` is not in {} (its joints: {known})", .config.display())]
    UnknownJoint {
        /// The name given.
        joint: String,
        /// The config.
        config: PathBuf,
        /// The config's joint names.
        known: String,
    },
    /// Two datasets for one joint.
    #[error("joint `{0}` is given two datasets; give one per joint")]
    DuplicateJoint(String),
    /// A dataset without rows.
    #[error("dataset {} has no rows", .0.display())]
    Empty(PathBuf),
    /// The datasets are not one recording.
    #[error(
        "datasets {} and {} are not one recording ({what}): replay plays the joints of one recording side by side, row by row",
        .a.display(), .b.display()
    )]
    NotOneRecording {
        /// The first dataset.
        a: PathBuf,
        /// The other.
        b: PathBuf,
        /// What differs.
        what: String,
    },
    /// The dataset's sample rate is not the daemon's loop rate.
    #[error(
        "dataset {} is sampled every {dt_us:.1} µs, but the config's loop runs every {period_us} µs: frictiond's histories and filters count ticks, so replay needs one row per tick (resample the log, or replay it with a config of its rate)",
        .path.display()
    )]
    Rate {
        /// The dataset.
        path: PathBuf,
        /// Its median row spacing [µs].
        dt_us: f64,
        /// `[loop] period_us`.
        period_us: u64,
    },
    /// An output path is refused or cannot be written.
    #[error("{}", .path.display())]
    Output {
        /// The output.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// An output would replace an input.
    #[error("output {} is also an input of this replay; choose another --out", .0.display())]
    OutputIsInput(PathBuf),
    /// Starting the daemon or the run directory failed.
    #[error(transparent)]
    Session(#[from] ExperimentError),
    /// Shared memory.
    #[error(transparent)]
    Shm(#[from] ShmError),
    /// Publishing to the daemon failed.
    #[error("publish {0}")]
    Publish(&'static str),
    /// The daemon did not answer a tick.
    #[error("frictiond did not answer tick {tick} (row {row}) within {timeout:?}; its log:\n{log}")]
    NoAnswer {
        /// Tick.
        tick: u64,
        /// Dataset row.
        row: usize,
        /// How long it was given.
        timeout: Duration,
        /// frictiond's log tail.
        log: String,
    },
    /// SIGINT / SIGTERM.
    #[error("interrupted")]
    Interrupted,
}

/// How long one tick may take before the daemon counts as unresponsive.
const TICK_TIMEOUT: Duration = Duration::from_secs(10);

/// A joint being replayed.
struct Played {
    joint: String,
    index: usize,
    path: PathBuf,
    data: Dataset,
    /// Per row: (τ̂_F given to the law [Nm], current [A], flags).
    out: Vec<(f64, f64, u32)>,
}

/// The deployed config as replay runs it: the same joints, models, law, safety and control
/// settings, with the shared-memory backend at `ipc`, the lockstep trigger (each tick waits for its
/// state and request) and no RT settings (replay runs anywhere, unprivileged).
pub fn replay_config(
    deployed: &RawConfig,
    config_dir: &Path,
    ipc: &frictionless_shm_types::IpcConfig,
) -> RawConfig {
    let mut raw = deployed.clone();
    raw.make_paths_absolute(config_dir);
    raw.backend = BackendConfig {
        kind: BackendKind::Shm,
        service_prefix: ipc.service_prefix.clone(),
        root_path: ipc.root_path.clone(),
    };
    raw.bus.clear();
    let l = &mut raw.loop_;
    l.trigger = Trigger::Lockstep;
    l.lockstep_wait_request = true;
    l.lockstep_timeout_ms = TICK_TIMEOUT.as_millis() as u64;
    l.ready_after_ticks = 1;
    l.require_rt = false;
    l.cpu = None;
    l.helper_cpu = None;
    l.priority = None;
    l.lock_memory = false;
    l.cpu_dma_latency_us = None;
    raw
}

/// Reads the datasets and checks they are one recording at the loop's rate.
fn read_joints(job: &ReplayJob, raw: &RawConfig) -> Result<Vec<Played>, ReplayError> {
    if job.datasets.is_empty() {
        return Err(ReplayError::NoDatasets);
    }
    let mut seen = BTreeMap::new();
    let mut joints = Vec::with_capacity(job.datasets.len());
    for (name, path) in &job.datasets {
        let Some(j) = raw.joint.iter().find(|j| &j.name == name) else {
            return Err(ReplayError::UnknownJoint {
                joint: name.clone(),
                config: job.config.clone(),
                known: raw
                    .joint
                    .iter()
                    .map(|j| j.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        };
        if seen.insert(name.clone(), ()).is_some() {
            return Err(ReplayError::DuplicateJoint(name.clone()));
        }
        let data = Dataset::read_csv(path).map_err(|source| ReplayError::Dataset {
            path: path.clone(),
            source,
        })?;
        if data.is_empty() {
            return Err(ReplayError::Empty(path.clone()));
        }
        check_rate(path, &data, raw.loop_.period_us)?;
        joints.push(Played {
            joint: name.clone(),
            index: j.index,
            path: path.clone(),
            out: Vec::with_capacity(data.len()),
            data,
        });
    }
    let first = &joints[0];
    for o in &joints[1..] {
        let differ = |what: String| ReplayError::NotOneRecording {
            a: first.path.clone(),
            b: o.path.clone(),
            what,
        };
        if o.data.len() != first.data.len() {
            return Err(differ(format!(
                "{} rows against {}",
                first.data.len(),
                o.data.len()
            )));
        }
        if let Some(k) =
            (0..o.data.len()).find(|&k| (o.data.time_s[k] - first.data.time_s[k]).abs() > 1e-6)
        {
            return Err(differ(format!(
                "row {k} is at {} s against {} s",
                first.data.time_s[k], o.data.time_s[k]
            )));
        }
    }
    Ok(joints)
}

/// The median row spacing of `data` within its chunks must be the loop period (±2 %).
fn check_rate(path: &Path, data: &Dataset, period_us: u64) -> Result<(), ReplayError> {
    let mut dt: Vec<f64> = (1..data.len())
        .filter(|&k| data.chunk[k] == data.chunk[k - 1])
        .map(|k| data.time_s[k] - data.time_s[k - 1])
        .filter(|d| d.is_finite())
        .collect();
    if dt.is_empty() {
        return Ok(());
    }
    let mid = dt.len() / 2;
    let (_, median, _) = dt.select_nth_unstable_by(mid, f64::total_cmp);
    let dt_us = *median * 1e6;
    let period = period_us as f64;
    if (dt_us - period).abs() > 0.02 * period {
        return Err(ReplayError::Rate {
            path: path.to_owned(),
            dt_us,
            period_us,
        });
    }
    Ok(())
}

/// Plays `job` through the `frictiond` of `bins` (see the module doc) and writes its outputs.
pub fn replay(bins: &Binaries, job: &ReplayJob) -> Result<ReplayOutcome, ReplayError> {
    let cfg = frictiond_config::load(&job.config)?;
    let mut joints = read_joints(job, &cfg.raw)?;
    let outputs = output_paths(job, &joints)?;

    let mut session = Session::new()?;
    // `frictiond.toml` alone has the parent "", which `absolute` refuses: that is the cwd.
    let config_dir = job
        .config
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let config_dir = std::path::absolute(config_dir).map_err(|source| ReplayError::Output {
        path: config_dir.to_owned(),
        source,
    })?;
    let raw = replay_config(&cfg.raw, &config_dir, &session.ipc);
    let text = format!(
        "# The frictiond config `frictl replay` ran: {} with the shared-memory backend,\n# the lockstep trigger and no RT settings.\n{}",
        job.config.display(),
        toml::to_string(&raw).map_err(ExperimentError::SerializeConfig)?
    );
    write_text(&outputs.config, &text)?;

    let ipc = Ipc::open(&session.ipc, "frictl_replay")?;
    let rq_chan = ipc.torque_request()?;
    let ports = Ports {
        js_out: ipc.joint_states()?.outbox()?,
        rq_out: rq_chan.outbox()?,
        cmd_in: ipc.motor_current_command()?.inbox()?,
    };
    session.start_daemon_config(bins, &raw, || rq_chan.subscriber_count())?;

    let n_joints = cfg.raw.joint.iter().map(|j| j.index + 1).max().unwrap_or(0);
    let enable_mask = joints.iter().fold(0u64, |m, j| m | (1u64 << j.index));
    let rows = joints[0].data.len();
    let t0 = Instant::now();
    let mut seq = 0u64;
    let mut reenables = 0usize;
    for k in 0..rows {
        if interrupted() {
            return Err(ReplayError::Interrupted);
        }
        let boundary = k > 0
            && joints
                .iter()
                .any(|j| j.data.chunk[k] != j.data.chunk[k - 1]);
        // A chunk boundary: one tick with every joint disabled before the chunk's first row.
        let masks: &[u64] = if boundary {
            &[0, enable_mask]
        } else {
            &[enable_mask]
        };
        reenables += usize::from(boundary);
        let mut cmd = MotorCurrentCommand::zeroed();
        for &mask in masks {
            seq += 1;
            let at = Tick {
                row: k,
                seq,
                n_joints,
                enable_mask: mask,
            };
            cmd = tick(&ports, &mut session, &joints, at)?;
        }
        for j in &mut joints {
            let i = j.index;
            j.out
                .push((cmd.tau_f_model_nm[i], cmd.i_ref_a[i], cmd.flags[i]));
        }
    }
    let wall_s = t0.elapsed().as_secs_f64();
    session.check_alive()?;
    session.stop();

    let mut results = Vec::with_capacity(joints.len());
    for (j, csv) in joints.iter().zip(&outputs.csv) {
        write_joint_csv(csv, j)?;
        results.push(summarise(j, csv));
    }
    let outcome = ReplayOutcome {
        config: job.config.clone(),
        ticks: seq,
        reenables,
        wall_s,
        joints: results,
    };
    let json = serde_json::to_string_pretty(&outcome).map_err(|e| ReplayError::Output {
        path: outputs.json.clone(),
        source: std::io::Error::other(e),
    })?;
    write_text(&outputs.json, &json)?;
    Ok(outcome)
}

/// The files a replay writes.
struct Outputs {
    csv: Vec<PathBuf>,
    json: PathBuf,
    config: PathBuf,
}

/// Creates the output directory and checks every output (a regular file or absent, not an input).
fn output_paths(job: &ReplayJob, joints: &[Played]) -> Result<Outputs, ReplayError> {
    std::fs::create_dir_all(&job.out).map_err(|source| ReplayError::Output {
        path: job.out.clone(),
        source,
    })?;
    let o = Outputs {
        csv: joints
            .iter()
            .map(|j| job.out.join(format!("{}.csv", j.joint)))
            .collect(),
        json: job.out.join("replay.json"),
        config: job.out.join("frictiond.replay.toml"),
    };
    let inputs: Vec<PathBuf> = std::iter::once(job.config.clone())
        .chain(joints.iter().map(|j| j.path.clone()))
        .filter_map(|p| std::fs::canonicalize(p).ok())
        .collect();
    for p in o.csv.iter().chain([&o.json, &o.config]) {
        output_file::check(p).map_err(|source| ReplayError::Output {
            path: p.clone(),
            source,
        })?;
        if std::fs::canonicalize(p).is_ok_and(|c| inputs.contains(&c)) {
            return Err(ReplayError::OutputIsInput(p.clone()));
        }
    }
    Ok(o)
}

/// The replay's ends of the daemon's services.
struct Ports {
    js_out: Outbox<JointStates>,
    rq_out: Outbox<TorqueRequest>,
    cmd_in: Inbox<MotorCurrentCommand>,
}

/// What one tick plays.
#[derive(Clone, Copy)]
struct Tick {
    /// Dataset row.
    row: usize,
    /// The joint states' sequence number.
    seq: u64,
    /// Payload joint count.
    n_joints: usize,
    /// Joints the request enables.
    enable_mask: u64,
}

/// One daemon tick: row `at.row` of every dataset as joint states number `at.seq`, a request
/// enabling `at.enable_mask`, and the daemon's command that answers it.
fn tick(
    ports: &Ports,
    session: &mut Session,
    joints: &[Played],
    at: Tick,
) -> Result<MotorCurrentCommand, ReplayError> {
    let Tick {
        row: k,
        seq,
        n_joints,
        enable_mask,
    } = at;
    let Ports {
        js_out,
        rq_out,
        cmd_in,
    } = ports;
    let mut js = JointStates::zeroed();
    js.seq = seq;
    js.stamp_ns = monotonic_ns();
    js.n_joints = n_joints.min(MAX_JOINTS) as u32;
    for j in joints {
        let (d, i) = (&j.data, j.index);
        js.s_rad[i] = d.s_rad[k];
        js.sdot_rad_s[i] = d.sdot_rad_s[k];
        js.theta_motor_rad[i] = d.theta_motor_rad[k];
        js.omega_motor_rad_s[i] = d.omega_motor_rad_s[k];
        js.current_a[i] = d.i_meas_a[k];
        js.temperature_c[i] = d.temperature_c[k];
    }
    js_out
        .publish(&js)
        .map_err(|_| ReplayError::Publish("JointStates"))?;
    let mut rq = TorqueRequest::zeroed();
    rq.seq = seq;
    rq.stamp_ns = monotonic_ns();
    rq.state_seq = seq;
    rq.enable_mask = enable_mask;
    rq.n_joints = js.n_joints;
    rq_out
        .publish(&rq)
        .map_err(|_| ReplayError::Publish("TorqueRequest"))?;
    let deadline = Instant::now() + TICK_TIMEOUT;
    loop {
        if let Some(c) = cmd_in
            .latest()
            .map_err(|_| ReplayError::Publish("MotorCurrentCommand (receive)"))?
            && c.state_seq == seq
        {
            return Ok(c);
        }
        let now = Instant::now();
        if interrupted() {
            return Err(ReplayError::Interrupted);
        }
        if now >= deadline {
            session.check_alive()?;
            return Err(ReplayError::NoAnswer {
                tick: seq,
                row: k,
                timeout: TICK_TIMEOUT,
                log: session.log_tail("frictiond"),
            });
        }
        let _ = cmd_in.wait((deadline - now).min(Duration::from_millis(20)));
    }
}

/// Bits of a row on which the joint did not run its model.
const OFF_MODEL: u32 = FLAG_DISABLED | FLAG_STALE | FLAG_FAULT | FLAG_NON_FINITE;

fn summarise(j: &Played, csv: &Path) -> JointReplay {
    let d = &j.data;
    let (mut sum, mut scored) = (0.0, 0usize);
    let (mut model_rows, mut ood, mut warm) = (0, 0, 0);
    for (k, &(f, _, flags)) in j.out.iter().enumerate() {
        let on_model = flags & OFF_MODEL == 0;
        model_rows += usize::from(on_model);
        ood += usize::from(flags & FLAG_OUT_OF_RANGE != 0);
        warm += usize::from(flags & FLAG_WARMING_UP != 0);
        let label = d.tau_f_label_nm[k];
        if on_model && flags & FLAG_WARMING_UP == 0 && d.valid[k] && label.is_finite() {
            sum += (f - label) * (f - label);
            scored += 1;
        }
    }
    JointReplay {
        joint: j.joint.clone(),
        index: j.index,
        dataset: j.path.clone(),
        csv: csv.to_owned(),
        rows: d.len(),
        model_rows,
        out_of_range_rows: ood,
        warming_up_rows: warm,
        rmse_vs_label_nm: (scored > 0).then(|| (sum / scored as f64).sqrt()),
        scored_rows: scored,
    }
}

/// The per-joint CSV's columns.
pub const REPLAY_COLUMNS: [&str; 9] = [
    "time_s",
    "chunk",
    "valid",
    "tau_f_label_nm",
    "tau_f_hat_nm",
    "current_a",
    "flags",
    "out_of_range",
    "warming_up",
];

fn write_joint_csv(path: &Path, j: &Played) -> Result<(), ReplayError> {
    let err = |source| ReplayError::Output {
        path: path.to_owned(),
        source,
    };
    let mut f = AtomicFile::create(path).map_err(err)?;
    let d = &j.data;
    writeln!(f, "{}", REPLAY_COLUMNS.join(",")).map_err(err)?;
    let mut line = String::with_capacity(160);
    for (k, &(tau, i, flags)) in j.out.iter().enumerate() {
        // `{}` of an f64 is its shortest round-trip text.
        let _ = writeln!(
            line,
            "{},{},{},{},{},{},{},{},{}",
            d.time_s[k],
            d.chunk[k],
            u8::from(d.valid[k]),
            d.tau_f_label_nm[k],
            tau,
            i,
            flags,
            u8::from(flags & FLAG_OUT_OF_RANGE != 0),
            u8::from(flags & FLAG_WARMING_UP != 0),
        );
        f.write_all(line.as_bytes()).map_err(err)?;
        line.clear();
    }
    f.commit().map_err(err)
}

fn write_text(path: &Path, text: &str) -> Result<(), ReplayError> {
    output_file::write(path, text).map_err(|source| ReplayError::Output {
        path: path.to_owned(),
        source,
    })
}
