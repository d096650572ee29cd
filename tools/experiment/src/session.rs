//! One closed-loop run's processes: the virtual plant and `frictiond` as child processes on a private
//! iceoryx2 root path and service prefix, torn down (and the shared-memory files removed) on drop.
//!
//! What this module **is**: [`Binaries`] (where `frictl` and `frictiond` are), [`DaemonJoint`] /
//! [`daemon_config`] / [`write_daemon_config`] (the per-run `frictiond` config as the daemon's typed
//! schema, `frictiond_config::RawConfig`, with `kfc`, `max_curr`, the friction clip and the LPF taken
//! from the shipped `config/ankle_knee.toml`, written with `toml::to_string`), [`Session`] (spawn plant + daemon,
//! wait until both are connected, kill + wait + remove the temp dir on drop) and [`interrupted`]
//! (Ctrl-C / SIGTERM flag registered with signal-hook, polled by the run loop).
//!
//! What it is **not**: no control loop (see [`super::run`]), no physics, no daemon logic. Children
//! get `PR_SET_PDEATHSIG = SIGTERM`, so they also stop if this process is killed outright.

use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use frictiond_config::{
    BackendConfig, BackendKind, JointConfig, LoopConfig, LpfConfig, ModelKind, OnStale, OodMode,
    RawConfig, SafetyConfig, Trigger, WarmupName, default_ood_margin, default_ood_ramp_ms,
};
use frictionless::friction::{CvParams, ScvParams};
use frictionless_shm_types::IpcConfig;

use super::ExperimentError;

/// Shipped daemon config whose per-joint `kfc`, `max_curr`, `max_output_friction` and `lpf` the
/// experiments use.
pub const ANKLE_KNEE_TOML: &str = include_str!("../../../config/ankle_knee.toml");

/// The plant presets of every experiment, in payload-index order (knee = 0, ankle_roll = 1).
pub const PRESETS: [&str; 2] = ["knee", "ankle_roll"];

/// The two executables a run starts.
#[derive(Clone, Debug)]
pub struct Binaries {
    /// `frictl` (serves the plant: `frictl sim serve`).
    pub frictl: PathBuf,
    /// `frictiond`.
    pub frictiond: PathBuf,
}

impl Binaries {
    /// `frictl` = this executable; `frictiond` = `$FRICTIOND`, else — when this `frictl` was started
    /// by `cargo run` — `frictiond` built by the same cargo into the same target directory and
    /// profile (see [`build_frictiond_with_cargo`]), else next to `frictl` (or one directory up, for
    /// test binaries in `target/*/deps`), else on `PATH`.
    pub fn locate() -> Result<Self, ExperimentError> {
        let me = std::env::current_exe().map_err(ExperimentError::CurrentExe)?;
        if std::env::var_os("FRICTIOND").is_none()
            && let Some(frictiond) = build_frictiond_with_cargo(&me)?
        {
            return Ok(Self {
                frictl: me,
                frictiond,
            });
        }
        Self::with_frictl(me)
    }

    /// As [`Binaries::locate`] with an explicit `frictl` path (tests pass `CARGO_BIN_EXE_frictl`).
    pub fn with_frictl(frictl: PathBuf) -> Result<Self, ExperimentError> {
        if let Some(p) = std::env::var_os("FRICTIOND") {
            let p = PathBuf::from(p);
            if !p.is_file() {
                return Err(ExperimentError::FrictiondEnv(p));
            }
            return Ok(Self {
                frictl,
                frictiond: p,
            });
        }
        let mut candidates = vec![];
        if let Some(dir) = frictl.parent() {
            candidates.push(dir.join("frictiond"));
            if let Some(up) = dir.parent() {
                candidates.push(up.join("frictiond"));
            }
        }
        if let Some(path) = std::env::var_os("PATH") {
            candidates.extend(std::env::split_paths(&path).map(|d| d.join("frictiond")));
        }
        match candidates.iter().find(|p| p.is_file()) {
            Some(p) => Ok(Self {
                frictl,
                frictiond: p.clone(),
            }),
            None => Err(ExperimentError::NoFrictiond { frictl }),
        }
    }
}

/// When this process is the `frictl` binary started by `cargo run` (cargo sets `CARGO` and
/// `CARGO_MANIFEST_DIR` for the programs it runs), builds `frictiond` with that cargo, for the same
/// profile and into the same target directory as this executable, and returns its path; `Ok(None)`
/// otherwise (an installed `frictl`, a test harness).
///
/// This is what makes the README's `cargo run --release -p frictl -- demo` work on a fresh clone:
/// cargo builds only the package it runs, and has no stable way for one package's binary to require
/// another package's binary. Up to date, the build is a no-op of well under a second.
pub fn build_frictiond_with_cargo(me: &Path) -> Result<Option<PathBuf>, ExperimentError> {
    let (Some(cargo), Some(manifest_dir)) = (
        std::env::var_os("CARGO"),
        std::env::var_os("CARGO_MANIFEST_DIR"),
    ) else {
        return Ok(None);
    };
    if me.file_stem().and_then(|s| s.to_str()) != Some("frictl") {
        return Ok(None);
    }
    // `<target>/<profile>/frictl` or, with `--target TRIPLE`, `<target>/<triple>/<profile>/frictl`.
    // Cargo keeps `.cargo-lock` in every profile directory and `.rustc_info.json` in the target
    // directory (CACHEDIR.TAG only when cargo created the directory itself).
    let Some(profile_dir) = me.parent() else {
        return Ok(None);
    };
    if !profile_dir.join(".cargo-lock").exists() {
        return Ok(None);
    }
    let Some(profile) = profile_dir.file_name().and_then(|s| s.to_str()) else {
        return Ok(None);
    };
    let Some(up) = profile_dir.parent() else {
        return Ok(None);
    };
    let is_target_dir =
        |d: &Path| d.join(".rustc_info.json").is_file() || d.join("CACHEDIR.TAG").is_file();
    let (target_dir, triple) = match up.parent() {
        Some(root) if !is_target_dir(up) && is_target_dir(root) => {
            (root.to_path_buf(), up.file_name().map(|t| t.to_owned()))
        }
        _ => (up.to_path_buf(), None),
    };
    // The `dev` profile builds into `debug/`; every other profile into a directory of its name.
    let profile = if profile == "debug" { "dev" } else { profile };
    let manifest = Path::new(&manifest_dir).join("Cargo.toml");
    let mut cmd = Command::new(&cargo);
    // `-p frictl` too, though only frictiond's binary is built: cargo resolves the dependencies'
    // features over every `-p` package, and frictiond's are a subset of frictl's, so the libraries
    // this `cargo run` just built are reused as they are instead of being rebuilt with frictiond's
    // smaller feature set (docs/decisions.md, "one feature resolution per build").
    cmd.args([
        "build",
        "--profile",
        profile,
        "-p",
        "frictl",
        "-p",
        "frictiond",
        "--bin",
        "frictiond",
    ])
    .arg("--manifest-path")
    .arg(&manifest)
    .arg("--target-dir")
    .arg(&target_dir);
    if let Some(t) = &triple {
        cmd.arg("--target").arg(t);
    }
    eprintln!(
        "frictl: building frictiond with cargo (profile {profile}, target dir {})",
        target_dir.display()
    );
    let status = cmd.status().map_err(|source| ExperimentError::RunCargo {
        cargo: PathBuf::from(&cargo),
        source,
    })?;
    if !status.success() {
        return Err(ExperimentError::CargoBuild {
            status,
            profile: profile.to_owned(),
        });
    }
    let built = profile_dir.join("frictiond");
    if !built.is_file() {
        return Err(ExperimentError::CargoNoBinary(built));
    }
    Ok(Some(built))
}

/// The friction model `frictiond` runs for one joint.
#[derive(Clone, Debug, PartialEq)]
pub enum FrictionModel {
    /// No compensation.
    None,
    /// Coulomb–viscous.
    Cv(CvParams),
    /// Stribeck–Coulomb–viscous (paper form).
    Scv(ScvParams),
    /// PINN weight file (`.fwt`).
    Pinn(PathBuf),
    /// Diagnostic bound, not a model a robot can run: frictiond runs `none` for the joint and the
    /// experiment controller adds the law's kfc·τ_F,true (the plant's true friction from `SimTruth`,
    /// with frictiond's clip and LPF) to τ_des — see [`super::oracle`]. Lockstep only.
    Oracle,
}

impl FrictionModel {
    /// Short name for tables: `none`, `CV`, `SCV`, `PINN`.
    pub fn label(&self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Cv(_) => "CV",
            Self::Scv(_) => "SCV",
            Self::Pinn(_) => "PINN",
            Self::Oracle => ORACLE_LABEL,
        }
    }
}

/// Table/JSON label of [`FrictionModel::Oracle`].
pub const ORACLE_LABEL: &str = "oracle (true friction)";

/// The τ̂_F low-pass of a joint's law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lpf {
    /// No `lpf` key: τ̂_F unfiltered.
    Off,
    /// Butterworth low-pass (`lpf = { order, cutoff_hz }`) at the daemon's 1 kHz.
    Butterworth {
        /// Order 1–8.
        order: usize,
        /// −3 dB cut-off [Hz].
        cutoff_hz: f64,
    },
}

impl std::fmt::Display for Lpf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Lpf::Off => write!(f, "off"),
            Lpf::Butterworth { order, cutoff_hz } => {
                write!(f, "Butterworth order {order} at {cutoff_hz} Hz")
            }
        }
    }
}

/// The friction-compensation part of one joint's law as frictiond runs it (the shipped
/// `config/ankle_knee.toml` values with the experiment's overrides): what the oracle must mimic and
/// what the report's configuration line shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawSettings {
    /// kfc.
    pub kfc: f64,
    /// Friction clip ±max_output_friction [Nm] (∞ if absent).
    pub max_output_friction_nm: f64,
    /// Velocity gate of the clip [rad/s].
    pub joint_velocity_threshold_rad_s: f64,
    /// τ̂_F low-pass.
    pub lpf: Lpf,
}

impl LawSettings {
    /// The shipped law of joint `name` with `kfc` / `lpf` overrides (`None` = shipped); the daemon's
    /// defaults for absent keys (kfc 1, no clip, gate 0, no LPF).
    pub fn shipped(
        name: &str,
        kfc: Option<f64>,
        lpf: Option<Lpf>,
    ) -> Result<Self, ExperimentError> {
        let j = shipped_joint(name)?;
        Ok(Self {
            kfc: kfc.unwrap_or(j.kfc),
            max_output_friction_nm: j.max_output_friction,
            joint_velocity_threshold_rad_s: j.joint_velocity_threshold_rad_s,
            lpf: lpf.unwrap_or_else(|| j.lpf.into()),
        })
    }

    /// One line for reports: `kfc 0.7, clip ±8 Nm, τ̂_F LPF Butterworth order 2 at 30 Hz`.
    pub fn describe(&self) -> String {
        format!(
            "kfc {}, clip ±{} Nm, τ̂_F LPF {}",
            self.kfc, self.max_output_friction_nm, self.lpf
        )
    }
}

/// One `[[joint]]` of a per-run daemon config.
#[derive(Clone, Debug)]
pub struct DaemonJoint {
    /// Joint name (the preset's `plant.joint`, e.g. `l_knee`).
    pub name: String,
    /// Payload index.
    pub index: usize,
    /// Signed gear ratio (from the plant preset).
    pub gear_ratio: f64,
    /// Torque constant [Nm/A] (from the plant preset).
    pub kt_nm_per_a: f64,
    /// Friction model.
    pub model: FrictionModel,
    /// For a PINN: the fixed Δθ offset θ_off [motor rad] frictiond keeps across enables
    /// (`delta_theta_offset_motor_rad`); `None` = latch at enable.
    pub delta_theta_offset_motor_rad: Option<f64>,
    /// `kfc` instead of the shipped config's (`None` = shipped).
    pub kfc: Option<f64>,
    /// τ̂_F low-pass instead of the shipped config's (`None` = shipped).
    pub lpf: Option<Lpf>,
}

/// Loop trigger of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// One tick per message through plant → controller → daemon → plant (fast, deterministic).
    Lockstep,
    /// 1 kHz wall clock: the plant on absolute deadlines, the daemon on its clock.
    Realtime,
}

/// The `[[joint]]` of `config/ankle_knee.toml` named `name`, typed by the daemon's schema (not
/// validated: its model paths are relative to `config/`). A joint of the built-in leg
/// (`config/presets/leg.toml`) that the shipped config does not list gets the law of the shipped
/// joint of its drive preset (`knee` → `l_knee`, `ankle_roll` → `l_ankle_roll`) with its own name
/// and its drive's current limit (`plant.i_max_a`) as `max_curr`.
fn shipped_joint(name: &str) -> Result<JointConfig, ExperimentError> {
    let shipped: RawConfig =
        toml::from_str(ANKLE_KNEE_TOML).map_err(ExperimentError::ShippedConfig)?;
    let find = |n: &str| shipped.joint.iter().find(|j| j.name == n).cloned();
    if let Some(j) = find(name) {
        return Ok(j);
    }
    let leg: Option<toml::Table> = frictionless_sim::leg::LEG_PRESET_TOML.parse().ok();
    let leg_joint = leg
        .as_ref()
        .and_then(|t| t.get("joint"))
        .and_then(|t| t.get(name));
    let base = match leg_joint
        .and_then(|t| t.get("preset"))
        .and_then(|p| p.as_str())
    {
        Some("knee") => find("l_knee"),
        Some("ankle_roll") => find("l_ankle_roll"),
        _ => None,
    };
    let mut j = base.ok_or_else(|| ExperimentError::ShippedJoint(name.to_owned()))?;
    j.name = name.to_owned();
    if let Some(i_max) = leg_joint
        .and_then(|t| t.get("plant"))
        .and_then(|t| t.get("i_max_a"))
        .and_then(|v| v.as_float())
    {
        j.max_curr = i_max;
    }
    Ok(j)
}

/// `kfc` of `name` in `config/ankle_knee.toml` (1.0 if absent, the daemon's default).
pub fn shipped_kfc(name: &str) -> f64 {
    shipped_joint(name).map_or(1.0, |j| j.kfc)
}

impl From<Option<LpfConfig>> for Lpf {
    fn from(l: Option<LpfConfig>) -> Self {
        match l {
            None => Lpf::Off,
            Some(LpfConfig { order, cutoff_hz }) => Lpf::Butterworth { order, cutoff_hz },
        }
    }
}

impl From<Lpf> for Option<LpfConfig> {
    fn from(l: Lpf) -> Self {
        match l {
            Lpf::Off => None,
            Lpf::Butterworth { order, cutoff_hz } => Some(LpfConfig { order, cutoff_hz }),
        }
    }
}

/// The `[[joint]]` frictiond runs for `j`: name, index, gear ratio and kt from the plant; `max_curr`,
/// `kfc`, the friction clip, its gate and the LPF from `config/ankle_knee.toml` (with `j`'s `kfc` /
/// `lpf` overrides); the model's keys. With `raw_friction`, only `max_curr` is taken from the shipped
/// joint and `kfc` defaults to 1 (no clip, no LPF, `lpf` override ignored): the daemon's τ̂_F is then
/// the model's output itself (used to check online against offline inference).
pub fn daemon_joint(j: &DaemonJoint, raw_friction: bool) -> Result<JointConfig, ExperimentError> {
    let shipped = shipped_joint(&j.name)?;
    let mut out = JointConfig {
        name: j.name.clone(),
        index: j.index,
        gear_ratio: j.gear_ratio,
        kt: j.kt_nm_per_a,
        max_curr: shipped.max_curr,
        speed_current_limit: None,
        kfc: 1.0,
        kp: 0.0,
        ki: 0.0,
        max_output_friction: f64::INFINITY,
        joint_velocity_threshold_rad_s: 0.0,
        lpf: None,
        friction_model: ModelKind::None,
        kc: None,
        kv: None,
        ka: None,
        ks: None,
        vs: None,
        alpha: None,
        sigma0: None,
        sigma1: None,
        model: None,
        warmup: WarmupName::default(),
        delta_theta_offset_motor_rad: None,
        motor_encoder: frictiond_config::MotorEncoder::Absolute,
        model_for: None,
        ood: OodMode::default(),
        ood_margin: default_ood_margin(),
        ood_ramp_ms: default_ood_ramp_ms(),
        alternate: Vec::new(),
    };
    if !raw_friction {
        out.kfc = shipped.kfc;
        out.max_output_friction = shipped.max_output_friction;
        out.joint_velocity_threshold_rad_s = shipped.joint_velocity_threshold_rad_s;
        out.lpf = j.lpf.map_or(shipped.lpf, Into::into);
    }
    if let Some(kfc) = j.kfc {
        out.kfc = kfc;
    }
    match &j.model {
        // the oracle's compensation is added by the controller to τ_des
        FrictionModel::None | FrictionModel::Oracle => {}
        FrictionModel::Cv(p) => {
            out.friction_model = ModelKind::Cv;
            (out.kc, out.ka, out.kv) = (Some(p.kc), Some(p.ka), Some(p.kv));
        }
        FrictionModel::Scv(p) => {
            out.friction_model = ModelKind::Scv;
            (out.kc, out.ka, out.kv) = (Some(p.kc), Some(p.ka), Some(p.kv));
            (out.ks, out.vs, out.alpha) = (Some(p.ks), Some(p.vs), Some(p.alpha));
        }
        FrictionModel::Pinn(file) => {
            let abs = std::path::absolute(file).map_err(|source| ExperimentError::PinnPath {
                path: file.clone(),
                source,
            })?;
            out.friction_model = ModelKind::Pinn;
            out.model = Some(abs);
            out.warmup = WarmupName::ZeroPad;
            out.delta_theta_offset_motor_rad = j.delta_theta_offset_motor_rad;
        }
    }
    Ok(out)
}

/// The `frictiond` config of one run: 1 kHz, status every tick, the `mode`'s trigger, shared memory on
/// `ipc`, zero output on stale input, and [`daemon_joint`] per joint.
pub fn daemon_config(
    ipc: &IpcConfig,
    mode: Mode,
    joints: &[DaemonJoint],
    raw_friction: bool,
) -> Result<RawConfig, ExperimentError> {
    let root = ipc.root_path.as_ref().ok_or(ExperimentError::NoRootPath)?;
    let (trigger, stale_after_ticks) = match mode {
        // Lockstep runs faster than real time but may pause on a busy machine: a stamp-age staleness
        // of 5 ms would inject random zero-current ticks, so allow 1 s.
        Mode::Lockstep => (Trigger::Lockstep, 1000),
        Mode::Realtime => (Trigger::Clock, 5),
    };
    Ok(RawConfig {
        loop_: LoopConfig {
            period_us: 1000,
            status_every_ticks: 1,
            ready_after_ticks: 1,
            trigger,
            lockstep_wait_request: true,
            lockstep_timeout_ms: 1000,
            ..LoopConfig::default()
        },
        backend: BackendConfig {
            kind: BackendKind::Shm,
            service_prefix: ipc.service_prefix.clone(),
            root_path: Some(root.clone()),
        },
        safety: SafetyConfig {
            stale_after_ticks,
            on_stale: OnStale::Zero,
        },
        joint: joints
            .iter()
            .map(|j| daemon_joint(j, raw_friction))
            .collect::<Result<_, _>>()?,
        bus: Vec::new(),
        control: Default::default(),
    })
}

/// Writes the `frictiond` config of one run ([`daemon_config`]) to `path` and returns its text.
pub fn write_daemon_config(
    path: &Path,
    ipc: &IpcConfig,
    mode: Mode,
    joints: &[DaemonJoint],
    raw_friction: bool,
) -> Result<String, ExperimentError> {
    let cfg = daemon_config(ipc, mode, joints, raw_friction)?;
    let s = format!(
        "# Written by `frictl experiment` for one run.\n{}",
        toml::to_string(&cfg).map_err(ExperimentError::SerializeConfig)?
    );
    frictionless::output_file::write(path, &s).map_err(|source| ExperimentError::Write {
        path: path.to_owned(),
        source,
    })?;
    Ok(s)
}

/// Set by SIGINT / SIGTERM once [`install_signal_flag`] ran.
static INTERRUPT: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Registers SIGINT and SIGTERM to set the interrupt flag (idempotent). The run loop polls
/// [`interrupted`] and returns an error; dropping the [`Session`] then stops the children.
pub fn install_signal_flag() -> Result<(), ExperimentError> {
    if INTERRUPT.get().is_some() {
        return Ok(());
    }
    let flag = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, flag.clone())
            .map_err(|source| ExperimentError::Signal { sig, source })?;
    }
    let _ = INTERRUPT.set(flag);
    Ok(())
}

/// Whether SIGINT / SIGTERM arrived.
pub fn interrupted() -> bool {
    INTERRUPT.get().is_some_and(|f| f.load(Ordering::Relaxed))
}

/// A unique private directory + service prefix for one run.
fn unique_ipc() -> Result<IpcConfig, ExperimentError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let id = format!(
        "flx_{}_{}_{}",
        std::process::id(),
        n,
        frictionless_shm_types::monotonic_ns() % 1_000_000_000
    );
    let root = std::env::temp_dir().join(&id);
    std::fs::create_dir_all(&root).map_err(|source| ExperimentError::RunDir {
        path: root.clone(),
        source,
    })?;
    Ok(IpcConfig::new(Some(&root), &id))
}

/// A started child with its log file.
struct Proc {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

/// What the plant is started with.
#[derive(Clone, Debug)]
pub struct PlantSpec {
    /// Seed.
    pub seed: u64,
    /// The plant server's `--preset` (`knee,ankle_roll` or `leg`).
    pub preset: String,
    /// Initial joint angle per payload index [rad].
    pub initial_pose_rad: Vec<f64>,
    /// `--set KEY=VALUE` overrides passed to every preset.
    pub sets: Vec<String>,
}

/// The processes of one run (see the module doc). Dropping it stops them and removes the run
/// directory (iceoryx2 root path, config, logs).
pub struct Session {
    /// The run's iceoryx2 configuration (unique root path and prefix).
    pub ipc: IpcConfig,
    /// The run directory (= the iceoryx2 root path).
    pub dir: PathBuf,
    procs: Vec<Proc>,
    keep_dir: bool,
}

impl Session {
    /// Creates the run directory and IPC names; starts nothing yet.
    pub fn new() -> Result<Self, ExperimentError> {
        let ipc = unique_ipc()?;
        let dir = ipc.root_path.clone().expect("unique_ipc sets a root");
        Ok(Self {
            ipc,
            dir,
            procs: vec![],
            keep_dir: false,
        })
    }

    /// Keeps the run directory (logs, config) after drop, for debugging.
    pub fn keep_dir(&mut self, keep: bool) {
        self.keep_dir = keep;
    }

    fn spawn(
        &mut self,
        name: &'static str,
        cmd: &mut Command,
    ) -> Result<Arc<AtomicBool>, ExperimentError> {
        let log = self.dir.join(format!("{name}.log"));
        // SAFETY: prctl is async-signal-safe; the closure touches no allocator or lock.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "warn".into()),
            )
            .spawn()
            .map_err(|source| ExperimentError::Spawn {
                name,
                program: cmd.get_program().to_owned(),
                source,
            })?;
        let stderr = child.stderr.take().expect("piped");
        let log_file = frictionless::output_file::create_log(&log).map_err(|source| {
            ExperimentError::Create {
                path: log.clone(),
                source,
            }
        })?;
        let ready = Arc::new(AtomicBool::new(false));
        let ready2 = ready.clone();
        self.procs.push(Proc { name, child, log });
        std::thread::spawn(move || {
            use std::io::Write;
            let mut w = std::io::BufWriter::new(log_file);
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if line.contains("ready") {
                    ready2.store(true, Ordering::Release);
                }
                let _ = writeln!(w, "{line}");
                let _ = w.flush();
            }
        });
        Ok(ready)
    }

    /// Last lines of a child's log, for error messages.
    pub fn log_tail(&self, name: &str) -> String {
        self.procs
            .iter()
            .find(|p| p.name == name)
            .and_then(|p| std::fs::read_to_string(&p.log).ok())
            .map(|s| {
                let lines: Vec<&str> = s.lines().collect();
                lines[lines.len().saturating_sub(15)..].join("\n")
            })
            .unwrap_or_default()
    }

    /// Error if a child has exited.
    pub fn check_alive(&mut self) -> Result<(), ExperimentError> {
        for i in 0..self.procs.len() {
            if let Some(status) = self.procs[i].child.try_wait()? {
                let name = self.procs[i].name;
                // let the stderr reader thread drain the pipe into the log first
                std::thread::sleep(Duration::from_millis(100));
                return Err(ExperimentError::Exited {
                    name,
                    status,
                    log: self.log_tail(name),
                });
            }
        }
        Ok(())
    }

    /// Starts `frictiond` on a config written for this run (see [`write_daemon_config`]) and waits
    /// until it subscribed to the torque requests (`probe` returns the subscriber count).
    pub fn start_daemon(
        &mut self,
        bins: &Binaries,
        mode: Mode,
        joints: &[DaemonJoint],
        raw_friction: bool,
        probe: impl Fn() -> usize,
    ) -> Result<(), ExperimentError> {
        let cfg = self.dir.join("frictiond.toml");
        write_daemon_config(&cfg, &self.ipc, mode, joints, raw_friction)?;
        self.spawn_daemon(bins, &cfg, probe)
    }

    /// Starts `frictiond` on `raw` (written to the run directory; its backend should name this
    /// session's [`Session::ipc`]) and waits until it subscribed to the torque requests (`probe`
    /// returns the subscriber count).
    pub fn start_daemon_config(
        &mut self,
        bins: &Binaries,
        raw: &RawConfig,
        probe: impl Fn() -> usize,
    ) -> Result<(), ExperimentError> {
        let cfg = self.dir.join("frictiond.toml");
        let text = toml::to_string(raw).map_err(ExperimentError::SerializeConfig)?;
        frictionless::output_file::write(&cfg, &text).map_err(|source| ExperimentError::Write {
            path: cfg.clone(),
            source,
        })?;
        self.spawn_daemon(bins, &cfg, probe)
    }

    fn spawn_daemon(
        &mut self,
        bins: &Binaries,
        cfg: &Path,
        probe: impl Fn() -> usize,
    ) -> Result<(), ExperimentError> {
        self.spawn(
            "frictiond",
            Command::new(&bins.frictiond).arg("--config").arg(cfg),
        )?;
        self.wait_until("frictiond", Duration::from_secs(20), || probe() >= 1)
    }

    /// Starts the plant (`frictl sim serve --preset <spec.preset> --backend shm …`) and waits for
    /// its "ready" line.
    pub fn start_plant(
        &mut self,
        bins: &Binaries,
        mode: Mode,
        spec: &PlantSpec,
    ) -> Result<(), ExperimentError> {
        let mut cmd = Command::new(&bins.frictl);
        let pose: Vec<String> = spec.initial_pose_rad.iter().map(f64::to_string).collect();
        cmd.args(["sim", "serve", "--preset", &spec.preset, "--backend", "shm"])
            .arg("--prefix")
            .arg(&self.ipc.service_prefix)
            .arg("--root-path")
            .arg(&self.dir)
            .arg("--seed")
            .arg(spec.seed.to_string())
            // `=` form: the value starts with '-' for negative angles
            .arg(format!("--initial-pose-rad={}", pose.join(",")))
            .arg("--lockstep-subscribers=2");
        if mode == Mode::Lockstep {
            cmd.arg("--lockstep");
        }
        for s in &spec.sets {
            cmd.arg(format!("--set={s}"));
        }
        let flag = self.spawn("plant", &mut cmd)?;
        self.wait_until("plant", Duration::from_secs(20), || {
            flag.load(Ordering::Acquire)
        })
    }

    fn wait_until(
        &mut self,
        name: &str,
        timeout: Duration,
        cond: impl Fn() -> bool,
    ) -> Result<(), ExperimentError> {
        let t0 = Instant::now();
        while !cond() {
            if interrupted() {
                return Err(ExperimentError::Interrupted);
            }
            self.check_alive()?;
            if t0.elapsed() > timeout {
                return Err(ExperimentError::NotReady {
                    name: name.to_owned(),
                    timeout,
                    log: self.log_tail(name),
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Ok(())
    }

    /// Stops every child: SIGTERM, up to 2 s grace, then SIGKILL; always waits (no zombies).
    pub fn stop(&mut self) {
        for p in self.procs.iter_mut().rev() {
            if let Ok(None) = p.child.try_wait() {
                // SAFETY: plain kill(2) on our own child's pid.
                unsafe { libc::kill(p.child.id() as libc::pid_t, libc::SIGTERM) };
            }
        }
        let t0 = Instant::now();
        for p in self.procs.iter_mut().rev() {
            loop {
                match p.child.try_wait() {
                    Ok(Some(_)) | Err(_) => break,
                    Ok(None) if t0.elapsed() > Duration::from_secs(2) => {
                        let _ = p.child.kill();
                        let _ = p.child.wait();
                        break;
                    }
                    Ok(None) => std::thread::sleep(Duration::from_millis(2)),
                }
            }
        }
        self.procs.clear();
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.stop();
        if !self.keep_dir {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(kfc: Option<f64>, lpf: Option<Lpf>, model: FrictionModel) -> DaemonJoint {
        DaemonJoint {
            name: "l_ankle_roll".into(),
            index: 1,
            gear_ratio: -160.0,
            kt_nm_per_a: 0.07,
            model,
            delta_theta_offset_motor_rad: None,
            kfc,
            lpf,
        }
    }

    /// Writes the config of one joint, parses it back with frictiond's validation and checks it is
    /// what [`daemon_config`] intended; returns the joint.
    fn written(kfc: Option<f64>, lpf: Option<Lpf>, model: FrictionModel) -> JointConfig {
        // One directory per call: the tests run in parallel threads and each removes its own.
        static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("loop4_cfg_{}_{call}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ipc = IpcConfig::new(Some(&dir), "t");
        let j = joint(kfc, lpf, model);
        let path = dir.join("f.toml");
        let text =
            write_daemon_config(&path, &ipc, Mode::Lockstep, std::slice::from_ref(&j), false)
                .unwrap();
        let parsed =
            frictiond_config::parse(&path, &text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        let _ = std::fs::remove_dir_all(&dir);
        let intended = daemon_config(&ipc, Mode::Lockstep, &[j], false).unwrap();
        assert_eq!(parsed.raw, intended, "{text}");
        assert_eq!(parsed.raw.backend.service_prefix, ipc.service_prefix);
        assert_eq!(parsed.raw.backend.root_path, ipc.root_path);
        assert_eq!(parsed.raw.loop_.trigger, Trigger::Lockstep);
        parsed.raw.joint.into_iter().next().unwrap()
    }

    #[test]
    fn lpf_and_kfc_overrides_replace_the_shipped_keys() {
        let shipped = written(None, None, FrictionModel::None);
        let law = LawSettings::shipped("l_ankle_roll", None, None).unwrap();
        assert_eq!(shipped.lpf.is_some(), law.lpf != Lpf::Off);
        assert_eq!(shipped.kfc, law.kfc);
        assert_eq!(shipped.kfc, shipped_kfc("l_ankle_roll"));
        assert_eq!(shipped.max_output_friction, law.max_output_friction_nm);
        let off = written(Some(0.95), Some(Lpf::Off), FrictionModel::None);
        assert_eq!(off.lpf, None);
        assert_eq!(off.kfc, 0.95);
        let ten = written(
            None,
            Some(Lpf::Butterworth {
                order: 3,
                cutoff_hz: 10.0,
            }),
            FrictionModel::None,
        );
        assert_eq!(
            ten.lpf,
            Some(LpfConfig {
                order: 3,
                cutoff_hz: 10.0
            })
        );
        assert_eq!(ten.kfc, law.kfc);
        // the oracle's joint runs no model in frictiond
        let oracle = written(None, None, FrictionModel::Oracle);
        assert_eq!(oracle.friction_model, ModelKind::None);
        // LawSettings follows the same overrides
        let l = LawSettings::shipped("l_ankle_roll", Some(0.5), Some(Lpf::Off)).unwrap();
        assert_eq!((l.kfc, l.lpf), (0.5, Lpf::Off));
        assert_eq!(l.max_output_friction_nm, law.max_output_friction_nm);
    }

    #[test]
    fn written_models_carry_their_parameters() {
        let cv = CvParams {
            kc: 1.25,
            ka: 40.0,
            kv: 0.3,
        };
        let j = written(Some(1.0), None, FrictionModel::Cv(cv));
        assert_eq!(j.friction_model, ModelKind::Cv);
        assert_eq!((j.kc, j.ka, j.kv), (Some(1.25), Some(40.0), Some(0.3)));
        assert_eq!(
            (j.ks, j.vs, j.alpha, j.model.as_ref()),
            (None, None, None, None)
        );
        let scv = ScvParams {
            kc: 1.0,
            ka: 3.0,
            kv: 0.29,
            ks: 6.0,
            vs: 0.13,
            alpha: 0.6,
        };
        let j = written(None, None, FrictionModel::Scv(scv));
        assert_eq!(j.friction_model, ModelKind::Scv);
        assert_eq!(
            (j.kc, j.ka, j.kv, j.ks, j.vs, j.alpha),
            (
                Some(1.0),
                Some(3.0),
                Some(0.29),
                Some(6.0),
                Some(0.13),
                Some(0.6)
            )
        );
        // A PINN joint: absolute model path, zero-pad warm-up, the Δθ offset (not validated here:
        // the file does not exist).
        let mut p = joint(None, None, FrictionModel::Pinn("rel/a.fwt".into()));
        p.delta_theta_offset_motor_rad = Some(0.0);
        let ipc = IpcConfig::new(Some(Path::new("/tmp/x")), "t");
        let cfg = daemon_config(&ipc, Mode::Realtime, &[p], true).unwrap();
        let text = toml::to_string(&cfg).unwrap();
        let back: RawConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, cfg);
        let j = &back.joint[0];
        assert_eq!(j.friction_model, ModelKind::Pinn);
        assert!(j.model.as_ref().unwrap().is_absolute());
        assert!(j.model.as_ref().unwrap().ends_with("rel/a.fwt"));
        assert_eq!(j.warmup, WarmupName::ZeroPad);
        assert_eq!(j.delta_theta_offset_motor_rad, Some(0.0));
        // raw friction: kfc 1, no clip, no LPF; max_curr still shipped
        assert_eq!(j.kfc, 1.0);
        assert!(j.max_output_friction.is_infinite());
        assert_eq!(j.lpf, None);
        assert_eq!(j.max_curr, shipped_joint("l_ankle_roll").unwrap().max_curr);
        assert_eq!(back.loop_.trigger, Trigger::Clock);
        assert_eq!(back.safety.stale_after_ticks, 5);
    }
}
