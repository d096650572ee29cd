//! `frictiond-config`: frictiond's TOML configuration — the typed schema, its validation and the
//! resolved per-joint and per-bus parameters.
//!
//! What this crate **is**: one TOML file (`serde` + `toml`, unknown keys are errors) describing the loop
//! (`[loop]`), the I/O backend (`[backend]`), safety behaviour (`[safety]`), the joints
//! (`[[joint]]`, key names after the ergoCub `JointTorqueControlDevice`: `kt`, `kfc`, `kp`, `ki`,
//! `max_curr`, `max_output_friction`, `friction_model`, `kc`, `kv`, `ka`, `ks`, `vs`, `alpha`, `model`;
//! ours: `warmup`, `delta_theta_offset_motor_rad`) and the CAN buses (`[[bus]]`).
//! [`RawConfig`] is the file as written; it is `Serialize` too, so tools write configs with
//! `toml::to_string` instead of formatting TOML by hand. [`load`] / [`parse`] run the validation that
//! `frictiond --check` runs (including reading every model file) and return a [`Config`] or a
//! [`ConfigError`] naming the file, the key and the value.
//!
//! What it is **not**: no model construction or filter design (frictiond's `params`), no IPC, no I/O
//! besides reading the config and model files. Used by `frictiond` and by `frictl`; it depends on
//! neither. Units: SI, joint side; the velocity threshold is in **rad/s** (BLF used deg/s).
//!
//! ## Example: parse, read resolved values, write back with `toml::to_string`
//! ```
//! use std::path::Path;
//! use frictiond_config::{LpfConfig, ModelSpec};
//!
//! // One CV joint: no model file needed. The path only names the file in errors (and resolves
//! // relative model paths); nothing is read.
//! let text = r#"
//! [backend]
//! kind = "shm"
//!
//! [[joint]]
//! name = "knee"
//! index = 0
//! gear_ratio = -100.0   # signed: motor angle = r · joint angle
//! kt = 0.157            # Nm/A
//! max_curr = 5.0        # A
//! friction_model = "coulomb_viscous"
//! kc = 8.1
//! ka = 50.84
//! kv = 5.55
//! "#;
//! let cfg = frictiond_config::parse(Path::new("/etc/frictiond/knee.toml"), text)?;
//! assert_eq!(cfg.period_ns(), 1_000_000, "[loop] defaults to 1 kHz");
//! assert_eq!(cfg.raw.joint[0].kfc, 1.0, "kfc defaults to 1");
//! let ModelSpec::Cv(cv) = &cfg.models[0] else { panic!("coulomb_viscous resolves to CV") };
//! assert_eq!((cv.kc, cv.ka, cv.kv), (8.1, 50.84, 5.55));
//!
//! // Tools write configs through the same types: serialize, edit, re-parse (and re-validate).
//! let mut raw = cfg.raw.clone();
//! raw.joint[0].kfc = 0.85;
//! raw.joint[0].lpf = Some(LpfConfig { order: 2, cutoff_hz: 10.0 });
//! let written = toml::to_string(&raw)?;
//! let back = frictiond_config::parse(Path::new("/tmp/written.toml"), &written)?;
//! assert_eq!(back.raw, raw);
//! assert_eq!(back.models, cfg.models);
//!
//! // Errors name the file, the key and the value.
//! let bad = text.replace("kt = 0.157", "kt = -0.157");
//! let err = frictiond_config::parse(Path::new("/etc/frictiond/knee.toml"), &bad).unwrap_err();
//! assert!(err.to_string().contains("joint[0].kt"), "{err}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use frictionless::features::{FeatureSpec, Signal};
use frictionless_shm_types::MAX_JOINTS;
use frictionless_shm_types::can::busload;
use frictionless_shm_types::can::mit::MitRanges;
pub use frictionless_shm_types::can::units::CommandUnit;
use frictionless_shm_types::can::units::{AngleUnit, JointUnits};
use serde::{Deserialize, Serialize};

/// Why a configuration is not acceptable. Every variant names the file; most name the key and value.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// Config file.
        file: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
    /// TOML syntax, a wrong type or an unknown key.
    #[error("{file}: {message}")]
    Parse {
        /// Config file.
        file: PathBuf,
        /// toml's message (names the key, line and column).
        message: String,
    },
    /// A key holds a value outside its domain.
    #[error("{file}: key `{key}` = {value}: {requirement}")]
    Invalid {
        /// Config file.
        file: PathBuf,
        /// Full key path, e.g. `joint[1].max_curr`.
        key: String,
        /// The offending value as written.
        value: String,
        /// What it must satisfy.
        requirement: String,
    },
    /// A model file is missing or invalid.
    #[error("{file}: key `{key}` = {path:?}: {message}")]
    Model {
        /// Config file.
        file: PathBuf,
        /// Key path, e.g. `joint[0].model`.
        key: String,
        /// Resolved model path.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
}

/// `[loop]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LoopConfig {
    /// Loop period [µs] (1000 = 1 kHz).
    #[serde(default = "default_period_us")]
    pub period_us: u64,
    /// CPU to pin the RT thread to (none = no pinning).
    #[serde(default)]
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority 1–99 for the RT thread (none = SCHED_OTHER).
    #[serde(default)]
    pub priority: Option<i32>,
    /// mlockall(MCL_CURRENT | MCL_FUTURE) before the loop starts.
    #[serde(default)]
    pub lock_memory: bool,
    /// PM QoS CPU wake-up latency bound [µs] written to `/dev/cpu_dma_latency` and held while the
    /// daemon runs (none = leave the idle states alone). `0` keeps idle CPUs out of deep C-states
    /// (in a VM: polling instead of HLT exits), as `cyclictest` does by default. Root only; a
    /// refusal is warned (or fatal with `require_rt`).
    #[serde(default)]
    pub cpu_dma_latency_us: Option<u32>,
    /// If true, refuse to start when SCHED_FIFO / mlockall / affinity are refused; else warn.
    #[serde(default)]
    pub require_rt: bool,
    /// Publish DaemonStatus every this many ticks.
    #[serde(default = "default_status_every")]
    pub status_every_ticks: u64,
    /// READY=1 is sent after this many ticks ran (and were not missed).
    #[serde(default = "default_ready_after")]
    pub ready_after_ticks: u64,
    /// What starts a tick: the clock (absolute 1 kHz deadlines, the robot mode) or the inputs
    /// (lockstep with a simulated plant, for fast deterministic closed-loop runs).
    #[serde(default)]
    pub trigger: Trigger,
    /// Lockstep only: also wait for the [`TorqueRequest`](frictionless_shm_types::TorqueRequest)
    /// whose `state_seq` answers the newest joint state before computing (true when a controller
    /// takes part in the loop).
    #[serde(default = "default_true")]
    pub lockstep_wait_request: bool,
    /// Lockstep only: how long one tick waits for its inputs before it runs anyway with what it
    /// has (stale rules apply) [ms].
    #[serde(default = "default_lockstep_timeout_ms")]
    pub lockstep_timeout_ms: u64,
    /// RT threads computing a tick: 1, or 2 (the joints are split once at load into two halves
    /// balanced by network weight bytes; a helper thread computes the second half and the main RT
    /// thread joins it before publishing).
    #[serde(default = "default_rt_threads")]
    pub rt_threads: u8,
    /// With `rt_threads = 2`: CPU to pin the helper thread to (none = no pinning). Same rules as
    /// `cpu`, and not the same CPU as `cpu`.
    #[serde(default)]
    pub helper_cpu: Option<usize>,
    /// Cache warming of each RT thread's network weights in the idle part of the period.
    #[serde(default)]
    pub prefetch: Prefetch,
    /// `prefetch = "lead"`: wake this long before each deadline to prefetch [µs] (< `period_us`).
    #[serde(default = "default_prefetch_lead_us")]
    pub prefetch_lead_us: u64,
}

/// When the RT threads walk their networks' weights into cache (`[loop] prefetch`).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Prefetch {
    /// Never.
    #[default]
    Off,
    /// Right after publishing a tick.
    After,
    /// `prefetch_lead_us` before the next deadline (clock trigger; under lockstep, as `after`).
    Lead,
}

fn default_rt_threads() -> u8 {
    1
}
fn default_prefetch_lead_us() -> u64 {
    200
}

/// What starts a tick.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Trigger {
    /// Absolute CLOCK_MONOTONIC deadlines every `period_us` (the real-time mode).
    #[default]
    Clock,
    /// One tick per new joint state (and request, see `lockstep_wait_request`); no sleeping.
    Lockstep,
}

fn default_true() -> bool {
    true
}
fn default_lockstep_timeout_ms() -> u64 {
    1000
}

fn default_period_us() -> u64 {
    1000
}
fn default_status_every() -> u64 {
    100
}
fn default_ready_after() -> u64 {
    50
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            period_us: default_period_us(),
            cpu: None,
            priority: None,
            lock_memory: false,
            cpu_dma_latency_us: None,
            require_rt: false,
            status_every_ticks: default_status_every(),
            ready_after_ticks: default_ready_after(),
            trigger: Trigger::Clock,
            lockstep_wait_request: true,
            lockstep_timeout_ms: default_lockstep_timeout_ms(),
            rt_threads: default_rt_threads(),
            helper_cpu: None,
            prefetch: Prefetch::Off,
            prefetch_lead_us: default_prefetch_lead_us(),
        }
    }
}

/// Which I/O backend the loop uses.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// iceoryx2 shared memory (`frictionless-shm-types` services).
    Shm,
    /// SocketCAN drives (`[[bus]]` sections); requests, command mirror and status over shm.
    Can,
}

/// `[backend]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BackendConfig {
    /// Backend kind.
    pub kind: BackendKind,
    /// Service-name prefix (`<prefix>/joint_states`, …).
    #[serde(default = "default_prefix")]
    pub service_prefix: String,
    /// iceoryx2 root path (relative paths are relative to the config file); none = iceoryx2 default.
    #[serde(default)]
    pub root_path: Option<PathBuf>,
}

fn default_prefix() -> String {
    "frictionless".to_owned()
}

/// What to output for enabled joints when joint-state input is stale.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum OnStale {
    /// 0 A on every joint.
    Zero,
    /// Drop the friction estimate and the torque feedback (they need fresh state) and convert the
    /// last τ_des statically: i = τ_des/(kt·r), clamped. A stale *torque request* always gives 0 A.
    StaticModel,
}

/// `[safety]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SafetyConfig {
    /// Inputs older than this many periods (no new sample, or stamp too old) are stale.
    #[serde(default = "default_stale")]
    pub stale_after_ticks: u64,
    /// Output while joint states are stale.
    #[serde(default = "default_on_stale")]
    pub on_stale: OnStale,
}

fn default_stale() -> u64 {
    5
}
fn default_on_stale() -> OnStale {
    OnStale::Zero
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            stale_after_ticks: default_stale(),
            on_stale: default_on_stale(),
        }
    }
}

/// Butterworth low-pass on τ̂_F.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LpfConfig {
    /// Filter order 1–8.
    pub order: usize,
    /// Cut-off frequency [Hz], below Nyquist.
    pub cutoff_hz: f64,
}

/// Friction model names (the ergoCub names and short forms).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub enum FrictionModelName {
    /// No friction compensation.
    #[serde(rename = "none")]
    None,
    /// Coulomb–viscous.
    #[serde(rename = "coulomb_viscous", alias = "cv")]
    CoulombViscous,
    /// Stribeck–Coulomb–viscous.
    #[serde(rename = "coulomb_viscous_stribeck", alias = "scv")]
    CoulombViscousStribeck,
    /// PINN from a `.fwt` file.
    #[serde(rename = "pinn")]
    Pinn,
}

/// PINN warm-up policy while the history is not yet full.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum WarmupName {
    /// Infer on zero-padded history from the first tick.
    ZeroPad,
    /// Output 0 friction until the history is full (the safe default, as the BLF device).
    #[default]
    HoldZero,
}

/// What a joint does while its model's inputs are out of the model's training range.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum OodMode {
    /// Not checked: never flagged, never counted.
    Off,
    /// Flagged (`FLAG_OUT_OF_RANGE`) and counted in `DaemonStatus::out_of_range_ticks`; the model's
    /// estimate is used unchanged. A model without a stored range is never out of range.
    #[default]
    Flag,
    /// Flagged and counted, and the estimate blends (over `ood_ramp_ms`) to the joint's static
    /// model (`kc`, `ka`, `kv` = CV; plus `ks`, `vs`, `alpha` = SCV) while out of range, and back
    /// when in range. PINN joints only, with a model that stores its training input range.
    Static,
}

/// One `[[joint]]` as written.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    /// Joint name (unique).
    pub name: String,
    /// Index into the payload arrays (0–63, unique).
    pub index: usize,
    /// Signed gear ratio r (motor angle per joint angle), non-zero.
    pub gear_ratio: f64,
    /// Torque constant kt [Nm/A], motor side, > 0 (the same calibration as used for training!).
    pub kt: f64,
    /// Current clamp ±max_curr [A], > 0.
    pub max_curr: f64,
    /// Friction compensation gain kfc (0 disables compensation), 0–2.
    #[serde(default = "one")]
    pub kfc: f64,
    /// Proportional gain on the torque error [-] (0 = pure feed-forward).
    #[serde(default)]
    pub kp: f64,
    /// Integral gain on the torque error [1/s].
    #[serde(default)]
    pub ki: f64,
    /// Friction clip ±max_output_friction [Nm], applied only while |ṡ| > the threshold.
    #[serde(default = "infinite")]
    pub max_output_friction: f64,
    /// The velocity gate of the friction clip [rad/s] (≥ 0).
    #[serde(default)]
    pub joint_velocity_threshold_rad_s: f64,
    /// Butterworth LPF on τ̂_F (none = unfiltered).
    #[serde(default)]
    pub lpf: Option<LpfConfig>,
    /// Friction model.
    pub friction_model: FrictionModelName,
    /// Coulomb level [Nm].
    #[serde(default)]
    pub kc: Option<f64>,
    /// Viscous coefficient [Nm·s/rad].
    #[serde(default)]
    pub kv: Option<f64>,
    /// Smooth-sign steepness [s/rad]; `inf` = sign().
    #[serde(default)]
    pub ka: Option<f64>,
    /// Breakaway friction [Nm] (SCV).
    #[serde(default)]
    pub ks: Option<f64>,
    /// Stribeck velocity [rad/s] (SCV).
    #[serde(default)]
    pub vs: Option<f64>,
    /// Stribeck exponent (SCV).
    #[serde(default)]
    pub alpha: Option<f64>,
    /// `.fwt` model file for `pinn`, relative to the config file.
    #[serde(default)]
    pub model: Option<PathBuf>,
    /// The joint name recorded in `model` when this joint deliberately runs another joint's network
    /// (a template): the model check then compares the file's name with this instead of `name`, and
    /// does not compare k_t. Unset: the model must be this joint's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_for: Option<String>,
    /// PINN warm-up policy.
    #[serde(default)]
    pub warmup: WarmupName,
    /// PINN Δθ offset θ_off [motor rad] (Δθ = r·s − (θ − θ_off)): a fixed encoder calibration, kept
    /// across enables. Absent: latched at every enable (Δθ = 0 there). Set it to the offset the
    /// training logs were latched with (0 for the virtual joints).
    #[serde(default)]
    pub delta_theta_offset_motor_rad: Option<f64>,
    /// Out-of-training-range handling (PINN joints): `off`, `flag` (default) or `static`.
    #[serde(default)]
    pub ood: OodMode,
    /// Margin of the range check [fraction of each training range's width on either side, 0–10]:
    /// 0.1 (default) accepts inputs up to 10 % of the range's width beyond its ends.
    #[serde(default = "default_ood_margin")]
    pub ood_margin: f64,
    /// Duration of the blend between the PINN and the static model under `ood = "static"` [ms,
    /// 0–1000; 0 = switch at once]. Default 20.
    #[serde(default = "default_ood_ramp_ms")]
    pub ood_ramp_ms: f64,
}

fn one() -> f64 {
    1.0
}
/// Default [`JointConfig::ood_margin`].
pub fn default_ood_margin() -> f64 {
    0.1
}
/// Default [`JointConfig::ood_ramp_ms`].
pub fn default_ood_ramp_ms() -> f64 {
    20.0
}
fn infinite() -> f64 {
    f64::INFINITY
}

/// The whole file as written.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    /// `[loop]`.
    #[serde(default, rename = "loop")]
    pub loop_: LoopConfig,
    /// `[backend]`.
    pub backend: BackendConfig,
    /// `[safety]`.
    #[serde(default)]
    pub safety: SafetyConfig,
    /// `[[joint]]`.
    #[serde(default)]
    pub joint: Vec<JointConfig>,
    /// `[[bus]]`: CAN buses (required, ≥ 1, with `[backend] kind = "can"`; forbidden otherwise).
    #[serde(default)]
    pub bus: Vec<BusConfig>,
}

/// Largest number of `[[bus]]` sections (sockets polled per tick).
pub const MAX_BUSES: usize = 8;

/// Motor-drive protocol of one bus.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum CanProtocol {
    /// MIT mini-cheetah / CubeMars AK "MIT mode": one 8-byte command, one 6-byte reply per tick.
    Mit,
    /// ODrive CAN Simple: Set_Input_Torque per tick; cyclic Get_Encoder_Estimates, Get_Iq, Heartbeat.
    Odrive,
}

/// One `[[bus]]`: a SocketCAN interface with the drives on it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BusConfig {
    /// SocketCAN interface name (`can0`, `vcan0`), or `fd:N`: an already open CAN socket inherited
    /// as file descriptor N (kernel filters are then best effort; used by tests over a socketpair).
    pub interface: String,
    /// Nominal bitrate [bit/s], for the bus-load budget (the daemon does not configure the link).
    pub bitrate: u64,
    /// Protocol of every drive on this bus.
    pub protocol: CanProtocol,
    /// Largest allowed worst-case bus load (fraction, 0 < max_load ≤ 1).
    #[serde(default = "default_max_load")]
    pub max_load: f64,
    /// A joint whose drive sent no feedback for more than this many ticks is stale (0 A, flagged).
    #[serde(default = "default_feedback_timeout")]
    pub feedback_timeout_ticks: u64,
    /// MIT only: the standard id the drives reply on (the firmware's CAN master id; byte 0 of the
    /// reply names the motor).
    #[serde(default)]
    pub host_id: u32,
    /// The drives on this bus (`[[bus.joint]]`, or `joints = [...]`).
    #[serde(alias = "joints")]
    pub joint: Vec<BusJointConfig>,
}

fn default_max_load() -> f64 {
    0.7
}
fn default_feedback_timeout() -> u64 {
    5
}

/// One `[[bus.joint]]`: which `[[joint]]` a drive moves, its node id and units.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BusJointConfig {
    /// Name of a `[[joint]]`.
    pub joint: String,
    /// Drive id: MIT motor id (standard id of its commands, 1–255, also byte 0 of its replies);
    /// ODrive node id (0–63).
    pub node_id: u32,
    /// What the drive's command field carries: motor current, motor torque k_t·i or joint torque
    /// r·k_t·i (signed r).
    pub command_unit: CommandUnit,
    /// MIT: position range ±p_max [motor rad].
    #[serde(default)]
    pub p_max: Option<f64>,
    /// MIT: velocity range ±v_max [motor rad/s].
    #[serde(default)]
    pub v_max: Option<f64>,
    /// MIT: feed-forward range ±t_max, in `command_unit` (A, or Nm motor/joint side).
    #[serde(default)]
    pub t_max: Option<f64>,
    /// MIT: reply current-field range ±i_max, in `reply_unit`.
    #[serde(default)]
    pub i_max: Option<f64>,
    /// MIT: position-gain range 0..kp_max [Nm/rad] (we always send kp = 0; default 500).
    #[serde(default)]
    pub kp_max: Option<f64>,
    /// MIT: damping-gain range 0..kd_max [Nm·s/rad] (we always send kd = 0; default 5).
    #[serde(default)]
    pub kd_max: Option<f64>,
    /// MIT: what the reply's third field carries (bgkatz: current; CubeMars AK: torque). Default
    /// `current`.
    #[serde(default)]
    pub reply_unit: Option<CommandUnit>,
}

/// Validated friction model parameters of one joint.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelSpec {
    /// No compensation.
    None,
    /// CV.
    Cv(frictionless::friction::CvParams),
    /// SCV (paper form).
    Scv(frictionless::friction::ScvParams),
    /// PINN loaded from a file (resolved path); the file was read and validated by [`load`].
    Pinn {
        /// Resolved path.
        path: PathBuf,
        /// Warm-up policy.
        warmup: WarmupName,
        /// The static model blended in while out of the training range (`ood = "static"`).
        fallback: Option<StaticFallback>,
    },
}

/// The static model a PINN joint falls back to under `ood = "static"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StaticFallback {
    /// CV (`kc`, `ka`, `kv`).
    Cv(frictionless::friction::CvParams),
    /// SCV, paper form (`kc`, `ka`, `kv`, `ks`, `vs`, `alpha`).
    Scv(frictionless::friction::ScvParams),
}

/// A validated configuration.
#[derive(Debug, Clone)]
pub struct Config {
    /// The config file it came from.
    pub file: PathBuf,
    /// As written (validated).
    pub raw: RawConfig,
    /// Resolved model per joint, same order as `raw.joint`.
    pub models: Vec<ModelSpec>,
    /// Resolved iceoryx2 root path.
    pub root_path: Option<PathBuf>,
    /// Resolved `[[bus]]` sections (empty unless `[backend] kind = "can"`).
    pub buses: Vec<ResolvedBus>,
}

/// A validated `[[bus]]` with its drives resolved against the `[[joint]]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedBus {
    /// Interface name or `fd:N`.
    pub interface: String,
    /// Protocol.
    pub protocol: CanProtocol,
    /// MIT reply id.
    pub host_id: u32,
    /// Per-joint feedback timeout [ticks].
    pub feedback_timeout_ticks: u64,
    /// Drives, in config order.
    pub joints: Vec<ResolvedDrive>,
    /// The bus-load budget computed at load time.
    pub load: BusLoad,
}

/// One drive on a bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvedDrive {
    /// Position of the joint in `raw.joint` (and `models`).
    pub joint_pos: usize,
    /// Payload index of the joint (`[[joint]] index`).
    pub index: usize,
    /// Motor id (MIT) or node id (ODrive).
    pub node_id: u32,
    /// Command mapping (current → what the drive wants) and feedback angle unit.
    pub units: JointUnits,
    /// MIT: how to read the reply's third field back as a current (ODrive: Iq is a current).
    pub reply_units: JointUnits,
    /// MIT fixed-point ranges (ODrive: `None`).
    pub mit: Option<MitRanges>,
    /// Current clamp of the joint [A] (`[[joint]] max_curr`).
    pub max_curr_a: f64,
}

/// Worst-case bus load of one bus from the config.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusLoad {
    /// Drives on the bus.
    pub n_joints: u32,
    /// Frames per second on the bus (commands and feedback).
    pub frames_per_s: f64,
    /// Worst-case bits (with stuffing) of the frames one joint puts on the bus per tick.
    pub bits_per_joint_tick: u32,
    /// Frames per joint per tick.
    pub frames_per_joint_tick: u32,
    /// Bitrate [bit/s].
    pub bitrate_bps: u64,
    /// Load fraction (1 = saturated).
    pub load: f64,
    /// Configured limit fraction.
    pub limit: f64,
}

impl std::fmt::Display for BusLoad {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} joint(s): {:.0} frames/s, {} bits per joint and tick in {} frame(s) (worst-case stuffing), load {:.1} % of {} bit/s (limit {:.1} %)",
            self.n_joints,
            self.frames_per_s,
            self.bits_per_joint_tick,
            self.frames_per_joint_tick,
            100.0 * self.load,
            self.bitrate_bps,
            100.0 * self.limit
        )
    }
}

/// One line per bus for `frictiond --check` (empty without buses).
pub fn bus_summary(cfg: &Config) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    for (b, bus) in cfg.buses.iter().enumerate() {
        let _ = writeln!(
            s,
            "  bus[{b}] {} ({:?}): {}",
            bus.interface, bus.protocol, bus.load
        );
        for d in &bus.joints {
            let _ = writeln!(
                s,
                "    joint[{}] {} node {} command {:?}",
                d.index, cfg.raw.joint[d.joint_pos].name, d.node_id, d.units.command
            );
        }
    }
    s
}

impl Config {
    /// Loop period [ns].
    pub fn period_ns(&self) -> u64 {
        self.raw.loop_.period_us * 1000
    }
}

struct Checker<'a> {
    file: &'a Path,
}

impl Checker<'_> {
    fn fail(&self, key: String, value: impl std::fmt::Display, req: &str) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_path_buf(),
            key,
            value: value.to_string(),
            requirement: req.to_owned(),
        }
    }
    fn finite_pos(&self, key: String, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, v, "must be finite and > 0"))
        }
    }
    fn nonneg(&self, key: String, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, v, "must be finite and >= 0"))
        }
    }
}

/// Relative tolerance of the k_t comparison between a `.fwt` header and `[[joint]] kt`.
pub const KT_REL_TOLERANCE: f64 = 1e-6;

/// Reads and checks a `.fwt` model against its `[[joint]]`. Error text names the problem and both
/// values; the caller adds file and key.
///
/// The read accepts regular files only and runs the core's finite-output probe
/// ([`frictionless::weights::read_file`]). Then the model must match the joint: always the gear
/// ratio (sign and value, relative 1e-9: Δθ = r·s − θ), and the joint it was trained for: the file's
/// joint name must be the `[[joint]]`'s `name` and its k_t the joint's `kt` (relative
/// [`KT_REL_TOLERANCE`]: the labels were computed with it). A joint that deliberately runs another
/// joint's network (a template, as in `config/stress32.toml`) says so with `model_for = "<name in the
/// file>"`: the file's name is then compared with that, and k_t is not compared (the model's scale is
/// the other joint's). A file with an empty joint name (provenance unknown, e.g. an ONNX import without
/// `--joint`) is checked on the gear ratio and k_t only.
pub fn check_model_file(path: &Path, joint: &JointConfig) -> Result<(), String> {
    check_model(path, joint).map(|_| ())
}

/// What [`check_model`] learnt of a model file.
struct CheckedModel {
    /// The model's input features.
    features: FeatureSpec,
    /// Whether the file stores its training input range (the out-of-range check needs it).
    has_input_range: bool,
}

/// [`check_model_file`], returning what the rest of the config check needs of the model.
fn check_model(path: &Path, joint: &JointConfig) -> Result<CheckedModel, String> {
    let m = frictionless::weights::read_file(path).map_err(|e| e.to_string())?;
    let checked = CheckedModel {
        features: m.meta.features,
        has_input_range: m.meta.training.input_range.is_some(),
    };
    let r = m.meta.gear_ratio.get();
    let gear_ratio = joint.gear_ratio;
    if (r - gear_ratio).abs() > 1e-9 * gear_ratio.abs() {
        return Err(format!(
            "model was trained with gear_ratio {r}, config says {gear_ratio} (sign and value must match)"
        ));
    }
    let name = &m.meta.joint_name;
    if let Some(model_for) = &joint.model_for {
        if name != model_for {
            return Err(format!(
                "model is for joint {name:?}, config says model_for = {model_for:?}"
            ));
        }
        return Ok(checked);
    }
    let kt = m.meta.kt_nm_per_a;
    // Both are finite: the file's k_t is validated by the reader, the config's before this call.
    if (kt - joint.kt).abs() > KT_REL_TOLERANCE * joint.kt.abs() {
        return Err(format!(
            "model was trained with kt {kt} Nm/A, config says kt = {} Nm/A (the labels depend on it; must match within a relative {KT_REL_TOLERANCE:e}; a joint that runs another joint's model says so with model_for)",
            joint.kt
        ));
    }
    if !name.is_empty() && *name != joint.name {
        return Err(format!(
            "model is for joint {name:?}, config says name = {:?} (to run another joint's model, set model_for = {name:?})",
            joint.name
        ));
    }
    Ok(checked)
}

/// Where the daemon's value of one [`JointStates`](frictionless_shm_types::JointStates) field comes
/// from, for a joint on a given backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalSupply {
    /// Written by the shared-memory publisher (the robot's own software): whatever it measures; a
    /// field it does not have is NaN there, which the config cannot know.
    Publisher,
    /// Measured by the drive and decoded from its feedback frames.
    Measured,
    /// Computed from another measured field of the same drive (s = θ/r, ṡ = ω/r with the signed
    /// gear ratio r: the drive has only a motor-side encoder, so the transmission is taken as rigid).
    DerivedFrom(Signal),
    /// Not supplied: NaN in every tick.
    Absent,
}

impl std::fmt::Display for SignalSupply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SignalSupply::Publisher => f.write_str("written by the shared-memory publisher"),
            SignalSupply::Measured => f.write_str("measured by the drive"),
            SignalSupply::DerivedFrom(from) => {
                write!(f, "derived from `{from}` (rigid transmission)")
            }
            SignalSupply::Absent => f.write_str("not supplied"),
        }
    }
}

/// What `backend` (and, for CAN, the bus's `protocol`) supplies for `signal`. Both CAN protocols
/// report motor-side position and velocity only (MIT reply: p, v, i; ODrive Get_Encoder_Estimates:
/// pos, vel in motor rev) and no temperature the daemon decodes.
pub fn signal_supply(
    backend: BackendKind,
    protocol: Option<CanProtocol>,
    signal: Signal,
) -> SignalSupply {
    match (backend, protocol) {
        (BackendKind::Shm, _) | (BackendKind::Can, None) => SignalSupply::Publisher,
        (BackendKind::Can, Some(CanProtocol::Mit | CanProtocol::Odrive)) => match signal {
            Signal::MotorPosRad | Signal::MotorVelRadS => SignalSupply::Measured,
            Signal::JointPosRad => SignalSupply::DerivedFrom(Signal::MotorPosRad),
            Signal::JointVelRadS => SignalSupply::DerivedFrom(Signal::MotorVelRadS),
            Signal::TemperatureC => SignalSupply::Absent,
        },
    }
}

/// Checks that the backend can supply every input of a PINN joint's model: each field the feature
/// spec reads must be supplied, and Δθ = r·s − θ needs a joint position that is not derived from the
/// motor encoder (derived, Δθ is the latched constant and carries no deflection). Returns the
/// message naming joint, set and field.
pub fn check_model_inputs(
    joint: &str,
    spec: &FeatureSpec,
    backend: BackendKind,
    protocol: Option<CanProtocol>,
) -> Result<(), String> {
    let where_ = match (backend, protocol) {
        (BackendKind::Can, Some(CanProtocol::Mit)) => "the can backend (protocol = \"mit\")",
        (BackendKind::Can, Some(CanProtocol::Odrive)) => "the can backend (protocol = \"odrive\")",
        (BackendKind::Can, None) => "the can backend",
        (BackendKind::Shm, _) => "the shm backend",
    };
    for signal in spec.required_signals() {
        if signal_supply(backend, protocol, signal) == SignalSupply::Absent {
            return Err(format!(
                "joint {joint}: feature set `{}` ({spec}) needs `{signal}`, which {where_} does not supply",
                spec.set
            ));
        }
    }
    if spec.set.uses_delta_theta()
        && let SignalSupply::DerivedFrom(from) =
            signal_supply(backend, protocol, Signal::JointPosRad)
    {
        return Err(format!(
            "joint {joint}: feature set `{}` ({spec}) needs `s_rad` from a joint-side encoder for Δθ = r·s − θ, but {where_} derives `s_rad` from `{from}` (s = θ/r): Δθ would be constant; use a set without Δθ (e.g. motor-vel-joint-vel, joint-pos-joint-vel)",
            spec.set
        ));
    }
    Ok(())
}

/// The online CPUs as the kernel lists them in `/sys/devices/system/cpu/online` (none when the file
/// cannot be read or parsed, e.g. without `/sys`).
fn online_cpus() -> Option<Vec<std::ops::RangeInclusive<usize>>> {
    parse_cpu_list(&std::fs::read_to_string("/sys/devices/system/cpu/online").ok()?)
}

/// Parses a kernel CPU list such as `0-3,6,8-9`.
fn parse_cpu_list(text: &str) -> Option<Vec<std::ops::RangeInclusive<usize>>> {
    let mut out = Vec::new();
    for part in text.trim().split(',') {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        let (a, b) = (a.parse().ok()?, b.parse().ok()?);
        if a > b {
            return None;
        }
        out.push(a..=b);
    }
    Some(out)
}

/// Longest run of ticks `ready_after_ticks` and `stale_after_ticks` may span [s].
pub const MAX_TICK_SPAN_S: u64 = 60;

/// `cpu`-like keys: below `CPU_SETSIZE` and in the machine's online set.
fn check_cpu(c: &Checker<'_>, key: &str, cpu: usize) -> Result<(), ConfigError> {
    let setsize = libc::CPU_SETSIZE as usize;
    if cpu >= setsize {
        return Err(c.fail(
            key.into(),
            cpu,
            &format!("must be below CPU_SETSIZE ({setsize}) and an online CPU"),
        ));
    }
    if let Some(online) = online_cpus()
        && !online.iter().any(|r| r.contains(&cpu))
    {
        let list: Vec<String> = online
            .iter()
            .map(|r| {
                if r.start() == r.end() {
                    r.start().to_string()
                } else {
                    format!("{}-{}", r.start(), r.end())
                }
            })
            .collect();
        return Err(c.fail(
            key.into(),
            cpu,
            &format!(
                "must be an online CPU (online: {}, /sys/devices/system/cpu/online)",
                list.join(",")
            ),
        ));
    }
    Ok(())
}

/// Reads, parses and validates `path`, including every model file. Touches no IPC.
pub fn load(path: &Path) -> Result<Config, ConfigError> {
    let text = frictionless::regular_file::read_text(path).map_err(|source| ConfigError::Read {
        file: path.to_path_buf(),
        source,
    })?;
    parse(path, &text)
}

/// Parses and validates `text` as if read from `path` (relative model paths resolve against its
/// directory).
pub fn parse(path: &Path, text: &str) -> Result<Config, ConfigError> {
    let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
        file: path.to_path_buf(),
        message: e.to_string().trim_end().replace('\n', " | "),
    })?;
    let c = Checker { file: path };
    let base = path.parent().unwrap_or(Path::new("."));

    let l = &raw.loop_;
    if !(20..=1_000_000).contains(&l.period_us) {
        return Err(c.fail("loop.period_us".into(), l.period_us, "must be 20..=1000000"));
    }
    if let Some(p) = l.priority
        && !(1..=99).contains(&p)
    {
        return Err(c.fail("loop.priority".into(), p, "must be 1..=99 (SCHED_FIFO)"));
    }
    if let Some(us) = l.cpu_dma_latency_us
        && us > i32::MAX as u32
    {
        return Err(c.fail(
            "loop.cpu_dma_latency_us".into(),
            us,
            "must fit the kernel's s32 PM QoS value (0..=2147483647)",
        ));
    }
    if let Some(cpu) = l.cpu {
        check_cpu(&c, "loop.cpu", cpu)?;
    }
    if !(1..=2).contains(&l.rt_threads) {
        return Err(c.fail(
            "loop.rt_threads".into(),
            l.rt_threads,
            "must be 1 or 2 (RT threads computing a tick)",
        ));
    }
    if let Some(cpu) = l.helper_cpu {
        if l.rt_threads != 2 {
            return Err(c.fail(
                "loop.helper_cpu".into(),
                cpu,
                "only with rt_threads = 2 (there is no helper thread to pin)",
            ));
        }
        check_cpu(&c, "loop.helper_cpu", cpu)?;
        if l.cpu == Some(cpu) {
            return Err(c.fail(
                "loop.helper_cpu".into(),
                cpu,
                "must differ from loop.cpu (the main RT thread waits for the helper; on one CPU at the same SCHED_FIFO priority it would never run)",
            ));
        }
    }
    if l.prefetch == Prefetch::Lead && !(1..l.period_us).contains(&l.prefetch_lead_us) {
        return Err(c.fail(
            "loop.prefetch_lead_us".into(),
            l.prefetch_lead_us,
            &format!(
                "must be 1..{} (below period_us) with prefetch = \"lead\"",
                l.period_us
            ),
        ));
    }
    let max_ticks = MAX_TICK_SPAN_S * 1_000_000 / l.period_us;
    if l.ready_after_ticks > max_ticks {
        return Err(c.fail(
            "loop.ready_after_ticks".into(),
            l.ready_after_ticks,
            &format!(
                "must be <= {max_ticks} ({MAX_TICK_SPAN_S} s at period_us = {})",
                l.period_us
            ),
        ));
    }
    if raw.safety.stale_after_ticks > max_ticks {
        return Err(c.fail(
            "safety.stale_after_ticks".into(),
            raw.safety.stale_after_ticks,
            &format!(
                "must be <= {max_ticks} ({MAX_TICK_SPAN_S} s at period_us = {})",
                l.period_us
            ),
        ));
    }
    if l.status_every_ticks == 0 {
        return Err(c.fail("loop.status_every_ticks".into(), 0, "must be >= 1"));
    }
    if raw.safety.stale_after_ticks == 0 {
        return Err(c.fail("safety.stale_after_ticks".into(), 0, "must be >= 1"));
    }
    if raw.backend.service_prefix.is_empty() || raw.backend.service_prefix.contains('\0') {
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{:?}", raw.backend.service_prefix),
            "must be non-empty without NUL",
        ));
    }
    let prefix = &raw.backend.service_prefix;
    let max_prefix = frictionless_shm_types::MAX_SERVICE_PREFIX_BYTES;
    if prefix.len() > max_prefix {
        let head: String = prefix.chars().take(32).collect();
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{head:?}… ({} bytes)", prefix.len()),
            &format!(
                "must be at most {max_prefix} bytes (iceoryx2 service names are at most 255 bytes, and `/motor_current_command` is appended)"
            ),
        ));
    }
    if prefix.starts_with("iox2://") {
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{prefix:?}"),
            "must not start with `iox2://` (reserved by iceoryx2)",
        ));
    }
    if let Some(root) = &raw.backend.root_path {
        let resolved = base.join(root);
        if let Ok(m) = std::fs::metadata(&resolved)
            && !m.is_dir()
        {
            return Err(c.fail(
                "backend.root_path".into(),
                resolved.display(),
                "exists and is not a directory (iceoryx2 creates its files under it)",
            ));
        }
    }
    if raw.joint.is_empty() {
        return Err(c.fail("joint".into(), "[]", "at least one [[joint]] is required"));
    }
    if raw.joint.len() > MAX_JOINTS {
        return Err(c.fail(
            "joint".into(),
            raw.joint.len(),
            &format!("at most {MAX_JOINTS} joints"),
        ));
    }
    let fs_hz = 1e6 / l.period_us as f64;
    let mut models = Vec::with_capacity(raw.joint.len());
    let mut pinn_features = Vec::with_capacity(raw.joint.len());
    for (k, j) in raw.joint.iter().enumerate() {
        let key = |name: &str| format!("joint[{k}].{name}");
        if j.name.is_empty() {
            return Err(c.fail(key("name"), "\"\"", "must be non-empty"));
        }
        if raw.joint[..k].iter().any(|o| o.name == j.name) {
            return Err(c.fail(key("name"), &j.name, "duplicate joint name"));
        }
        if j.index >= MAX_JOINTS {
            return Err(c.fail(key("index"), j.index, &format!("must be < {MAX_JOINTS}")));
        }
        if raw.joint[..k].iter().any(|o| o.index == j.index) {
            return Err(c.fail(key("index"), j.index, "duplicate joint index"));
        }
        if frictionless::units::GearRatio::new(j.gear_ratio).is_err() {
            return Err(c.fail(
                key("gear_ratio"),
                j.gear_ratio,
                "must be finite and non-zero",
            ));
        }
        c.finite_pos(key("kt"), j.kt)?;
        c.finite_pos(key("max_curr"), j.max_curr)?;
        if !(j.kfc.is_finite() && (0.0..=2.0).contains(&j.kfc)) {
            return Err(c.fail(key("kfc"), j.kfc, "must be in [0, 2]"));
        }
        c.nonneg(key("kp"), j.kp)?;
        c.nonneg(key("ki"), j.ki)?;
        if j.max_output_friction.is_nan() || j.max_output_friction <= 0.0 {
            return Err(c.fail(
                key("max_output_friction"),
                j.max_output_friction,
                "must be > 0",
            ));
        }
        c.nonneg(
            key("joint_velocity_threshold_rad_s"),
            j.joint_velocity_threshold_rad_s,
        )?;
        if let Some(off) = j.delta_theta_offset_motor_rad
            && !off.is_finite()
        {
            return Err(c.fail(key("delta_theta_offset_motor_rad"), off, "must be finite"));
        }
        if let Some(lpf) = j.lpf {
            if !(1..=8).contains(&lpf.order) {
                return Err(c.fail(key("lpf.order"), lpf.order, "must be 1..=8"));
            }
            if !(lpf.cutoff_hz.is_finite() && lpf.cutoff_hz > 0.0 && lpf.cutoff_hz < 0.5 * fs_hz) {
                return Err(c.fail(
                    key("lpf.cutoff_hz"),
                    lpf.cutoff_hz,
                    &format!("must be > 0 and below Nyquist ({} Hz)", 0.5 * fs_hz),
                ));
            }
        }
        if !(j.ood_margin.is_finite() && (0.0..=10.0).contains(&j.ood_margin)) {
            return Err(c.fail(key("ood_margin"), j.ood_margin, "must be in [0, 10]"));
        }
        if !(j.ood_ramp_ms.is_finite() && (0.0..=1000.0).contains(&j.ood_ramp_ms)) {
            return Err(c.fail(key("ood_ramp_ms"), j.ood_ramp_ms, "must be in [0, 1000] ms"));
        }
        if j.ood == OodMode::Static && j.friction_model != FrictionModelName::Pinn {
            return Err(c.fail(
                key("ood"),
                "\"static\"",
                "only a PINN joint can fall back to a static model",
            ));
        }
        let (model, features) = model_spec(&c, base, k, j)?;
        models.push(model);
        pinn_features.push(features);
    }
    let buses = resolve_buses(&c, &raw, fs_hz)?;
    // Every PINN's inputs must be suppliable by the joint's backend (and, on CAN, its bus protocol).
    for (k, (j, features)) in raw.joint.iter().zip(&pinn_features).enumerate() {
        let Some(spec) = features else { continue };
        let protocol = buses
            .iter()
            .find(|b| b.joints.iter().any(|d| d.index == j.index))
            .map(|b| b.protocol);
        if let Err(message) = check_model_inputs(&j.name, spec, raw.backend.kind, protocol) {
            let Some(ModelSpec::Pinn { path, .. }) = models.get(k) else {
                continue;
            };
            return Err(ConfigError::Model {
                file: c.file.to_path_buf(),
                key: format!("joint[{k}].model"),
                path: path.clone(),
                message,
            });
        }
    }
    let root_path = raw.backend.root_path.as_ref().map(|p| base.join(p));
    Ok(Config {
        file: path.to_path_buf(),
        raw,
        models,
        root_path,
        buses,
    })
}

/// Validates `[[bus]]` against `[backend] kind` and the joints; computes every bus's load. The steps:
/// the section count ([`check_bus_sections`]), per bus its own keys ([`check_bus`]), per drive its
/// resolution against `[[joint]]` ([`resolve_drive`]), the bus-load budget ([`bus_load`]) and finally
/// that every joint sits on exactly one bus.
fn resolve_buses(
    c: &Checker,
    raw: &RawConfig,
    rate_hz: f64,
) -> Result<Vec<ResolvedBus>, ConfigError> {
    if !check_bus_sections(c, raw)? {
        return Ok(Vec::new());
    }
    // Where each `[[joint]]` sits: (bus, position on the bus).
    let mut on_bus: Vec<Option<(usize, usize)>> = vec![None; raw.joint.len()];
    let mut out = Vec::with_capacity(raw.bus.len());
    for (b, bus) in raw.bus.iter().enumerate() {
        check_bus(c, b, bus)?;
        let mut drives = Vec::with_capacity(bus.joint.len());
        for k in 0..bus.joint.len() {
            drives.push(resolve_drive(c, raw, b, k, &mut on_bus)?);
        }
        let load = bus_load(c, b, bus, drives.len(), rate_hz)?;
        out.push(ResolvedBus {
            interface: bus.interface.clone(),
            protocol: bus.protocol,
            host_id: bus.host_id,
            feedback_timeout_ticks: bus.feedback_timeout_ticks,
            joints: drives,
            load,
        });
    }
    if let Some(pos) = on_bus.iter().position(Option::is_none) {
        return Err(c.fail(
            format!("joint[{pos}].name"),
            format!("{:?}", raw.joint[pos].name),
            "with [backend] kind = \"can\" every [[joint]] must be on exactly one [[bus]]",
        ));
    }
    Ok(out)
}

/// `[[bus]]` sections are required (1..=[`MAX_BUSES`]) with `[backend] kind = "can"` and forbidden
/// otherwise. Returns whether there are buses to resolve.
fn check_bus_sections(c: &Checker, raw: &RawConfig) -> Result<bool, ConfigError> {
    if raw.backend.kind != BackendKind::Can {
        if !raw.bus.is_empty() {
            return Err(c.fail(
                "bus".into(),
                format!("{} section(s)", raw.bus.len()),
                "[[bus]] is only valid with [backend] kind = \"can\"",
            ));
        }
        return Ok(false);
    }
    if raw.bus.is_empty() {
        return Err(c.fail(
            "bus".into(),
            "[]",
            "[backend] kind = \"can\" needs at least one [[bus]]",
        ));
    }
    if raw.bus.len() > MAX_BUSES {
        return Err(c.fail(
            "bus".into(),
            raw.bus.len(),
            &format!("at most {MAX_BUSES} buses"),
        ));
    }
    Ok(true)
}

/// The keys of `bus[b]` itself (interface, bitrate, load limit, timeout, host id).
fn check_bus(c: &Checker, b: usize, bus: &BusConfig) -> Result<(), ConfigError> {
    let key = |name: &str| format!("bus[{b}].{name}");
    check_interface(c, &key("interface"), &bus.interface)?;
    if bus.bitrate == 0 {
        return Err(c.fail(key("bitrate"), 0, "must be > 0 [bit/s]"));
    }
    if !(bus.max_load.is_finite() && bus.max_load > 0.0 && bus.max_load <= 1.0) {
        return Err(c.fail(key("max_load"), bus.max_load, "must be in (0, 1]"));
    }
    if bus.feedback_timeout_ticks == 0 {
        return Err(c.fail(key("feedback_timeout_ticks"), 0, "must be >= 1"));
    }
    if bus.joint.is_empty() {
        return Err(c.fail(key("joint"), "[]", "a bus needs at least one [[bus.joint]]"));
    }
    match bus.protocol {
        CanProtocol::Mit => {
            if bus.host_id > frictionless_shm_types::can::frame::SFF_MAX {
                return Err(c.fail(
                    key("host_id"),
                    bus.host_id,
                    "must be a standard id 0..=2047",
                ));
            }
        }
        CanProtocol::Odrive => {
            if bus.host_id != 0 {
                return Err(c.fail(
                    key("host_id"),
                    bus.host_id,
                    "only used by protocol = \"mit\"",
                ));
            }
        }
    }
    Ok(())
}

/// Resolves `bus[b].joint[k]` against the `[[joint]]` table (recording it in `on_bus`): the joint it
/// names, its node id, its units and the protocol's ranges.
fn resolve_drive(
    c: &Checker,
    raw: &RawConfig,
    b: usize,
    k: usize,
    on_bus: &mut [Option<(usize, usize)>],
) -> Result<ResolvedDrive, ConfigError> {
    let bus = &raw.bus[b];
    let bj = &bus.joint[k];
    let key = |name: &str| format!("bus[{b}].joint[{k}].{name}");
    let Some(pos) = raw.joint.iter().position(|j| j.name == bj.joint) else {
        return Err(c.fail(
            key("joint"),
            format!("{:?}", bj.joint),
            "no [[joint]] has this name",
        ));
    };
    if let Some((ob, ok)) = on_bus[pos] {
        return Err(c.fail(
            key("joint"),
            format!("{:?}", bj.joint),
            &format!("joint is already on bus[{ob}].joint[{ok}] (each joint on exactly one bus)"),
        ));
    }
    on_bus[pos] = Some((b, k));
    if bus.joint[..k].iter().any(|o| o.node_id == bj.node_id) {
        return Err(c.fail(key("node_id"), bj.node_id, "duplicate node id on this bus"));
    }
    let j = &raw.joint[pos];
    if j.kp != 0.0 || j.ki != 0.0 {
        return Err(c.fail(
            format!("joint[{pos}].kp"),
            format!("kp = {}, ki = {}", j.kp, j.ki),
            "joints on a CAN bus have no joint-torque measurement: kp and ki must be 0",
        ));
    }
    let angle = match bus.protocol {
        CanProtocol::Mit => AngleUnit::Rad,
        CanProtocol::Odrive => AngleUnit::Rev,
    };
    let units = JointUnits::new(bj.command_unit, j.kt, j.gear_ratio, angle)
        .map_err(|e| c.fail(format!("joint[{pos}]"), &j.name, &e.to_string()))?;
    let (mit, reply_units) = match bus.protocol {
        CanProtocol::Odrive => (None, odrive_drive(c, &key, bj, units)?),
        CanProtocol::Mit => {
            let (ranges, reply) = mit_drive(c, &key, b, bus, bj, j, units)?;
            (Some(ranges), reply)
        }
    };
    Ok(ResolvedDrive {
        joint_pos: pos,
        index: j.index,
        node_id: bj.node_id,
        units,
        reply_units,
        mit,
        max_curr_a: j.max_curr,
    })
}

/// ODrive drive keys: node id 0..=63, no MIT keys. Returns the reply units (Iq is a current).
fn odrive_drive(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    bj: &BusJointConfig,
    units: JointUnits,
) -> Result<JointUnits, ConfigError> {
    if bj.node_id > u32::from(frictionless_shm_types::can::odrive::NODE_MAX) {
        return Err(c.fail(key("node_id"), bj.node_id, "ODrive node ids are 0..=63"));
    }
    let mit_keys = [
        ("p_max", bj.p_max.is_some()),
        ("v_max", bj.v_max.is_some()),
        ("t_max", bj.t_max.is_some()),
        ("i_max", bj.i_max.is_some()),
        ("kp_max", bj.kp_max.is_some()),
        ("kd_max", bj.kd_max.is_some()),
        ("reply_unit", bj.reply_unit.is_some()),
    ];
    for (n, set) in mit_keys {
        if set {
            return Err(c.fail(key(n), "<set>", "only used by protocol = \"mit\""));
        }
    }
    Ok(JointUnits {
        command: CommandUnit::Current,
        ..units
    })
}

/// MIT drive keys: motor id 1..=255 (not the host id), the fixed-point ranges, and a feed-forward
/// range wide enough for the joint's current clamp. Returns the ranges and the reply units.
fn mit_drive(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    b: usize,
    bus: &BusConfig,
    bj: &BusJointConfig,
    j: &JointConfig,
    units: JointUnits,
) -> Result<(MitRanges, JointUnits), ConfigError> {
    if !(1..=255).contains(&bj.node_id) {
        return Err(c.fail(
            key("node_id"),
            bj.node_id,
            "MIT motor ids are 1..=255 (byte 0 of the reply)",
        ));
    }
    if bj.node_id == bus.host_id {
        return Err(c.fail(
            key("node_id"),
            bj.node_id,
            &format!("equals bus[{b}].host_id"),
        ));
    }
    let need = |n: &str, v: Option<f64>| -> Result<f64, ConfigError> {
        let v = v.ok_or_else(|| c.fail(key(n), "<missing>", "required by protocol = \"mit\""))?;
        c.finite_pos(key(n), v)?;
        Ok(v)
    };
    let p = need("p_max", bj.p_max)?;
    let v = need("v_max", bj.v_max)?;
    let t = need("t_max", bj.t_max)?;
    let i = need("i_max", bj.i_max)?;
    let kp = need("kp_max", bj.kp_max.or(Some(500.0)))?;
    let kd = need("kd_max", bj.kd_max.or(Some(5.0)))?;
    let ranges = MitRanges {
        p_min_rad: -p,
        p_max_rad: p,
        v_min_rad_s: -v,
        v_max_rad_s: v,
        kp_min_nm_rad: 0.0,
        kp_max_nm_rad: kp,
        kd_min_nm_s_rad: 0.0,
        kd_max_nm_s_rad: kd,
        t_min_nm: -t,
        t_max_nm: t,
        i_min_a: -i,
        i_max_a: i,
    };
    // The largest command the law can produce must be representable on the wire.
    let max_cmd = units.command_from_current(j.max_curr).abs();
    if max_cmd > t * (1.0 + 1e-12) {
        return Err(c.fail(
            key("t_max"),
            t,
            &format!(
                "joint {:?} max_curr = {} A is {max_cmd} in command_unit {:?}: t_max must cover it (the drive would clamp silently)",
                j.name, j.max_curr, bj.command_unit
            ),
        ));
    }
    let reply = JointUnits {
        command: bj.reply_unit.unwrap_or(CommandUnit::Current),
        ..units
    };
    Ok((ranges, reply))
}

/// The worst-case load of `bus[b]` with `n_drives` drives at `rate_hz`; refused above `max_load`.
fn bus_load(
    c: &Checker,
    b: usize,
    bus: &BusConfig,
    n_drives: usize,
    rate_hz: f64,
) -> Result<BusLoad, ConfigError> {
    let (bits, frames) = match bus.protocol {
        CanProtocol::Mit => (busload::mit_bits_per_joint_tick(), 2),
        CanProtocol::Odrive => (busload::odrive_bits_per_joint_tick(), 3),
    };
    // At most MAX_JOINTS drives (each joint on one bus).
    let n = n_drives as u32;
    let load = BusLoad {
        n_joints: n,
        frames_per_s: f64::from(n * frames) * rate_hz,
        bits_per_joint_tick: bits,
        frames_per_joint_tick: frames,
        bitrate_bps: bus.bitrate,
        load: busload::load_fraction(n, bits, rate_hz, bus.bitrate as f64),
        limit: bus.max_load,
    };
    if busload::check_load(n, bits, rate_hz, bus.bitrate as f64, bus.max_load).is_err() {
        return Err(c.fail(
            format!("bus[{b}].max_load"),
            bus.max_load,
            &format!(
                "bus {} over its load limit at {rate_hz} Hz: {load}",
                bus.interface
            ),
        ));
    }
    Ok(load)
}

/// Linux `IFNAMSIZ`: interface names are at most 15 bytes plus the NUL.
const IFNAMSIZ: usize = 16;

/// An interface name the kernel accepts (1–15 bytes, no '/', NUL or whitespace) or `fd:N`.
fn check_interface(c: &Checker, key: &str, name: &str) -> Result<(), ConfigError> {
    if let Some(n) = name.strip_prefix("fd:") {
        return match n.parse::<i32>() {
            Ok(fd) if fd >= 3 => Ok(()),
            _ => Err(c.fail(
                key.into(),
                format!("{name:?}"),
                "fd:N needs an inherited descriptor N >= 3",
            )),
        };
    }
    let ok = !name.is_empty()
        && name.len() < IFNAMSIZ
        && !name
            .bytes()
            .any(|b| b == b'/' || b == 0 || b.is_ascii_whitespace());
    if ok {
        Ok(())
    } else {
        Err(c.fail(
            key.into(),
            format!("{name:?}"),
            "must be a network interface name (1-15 bytes) or fd:N",
        ))
    }
}

/// The joint's resolved model, and for a PINN the model file's input features.
fn model_spec(
    c: &Checker,
    base: &Path,
    k: usize,
    j: &JointConfig,
) -> Result<(ModelSpec, Option<FeatureSpec>), ConfigError> {
    use frictionless::friction::{CvParams, ScvParams, StaticFriction};
    let key = |name: &str| format!("joint[{k}].{name}");
    let need = |name: &str, v: Option<f64>| -> Result<f64, ConfigError> {
        v.ok_or_else(|| {
            c.fail(
                key(name),
                "<missing>",
                &format!("required by friction_model = {:?}", j.friction_model),
            )
        })
    };
    let forbid = |names: &[(&str, bool)]| -> Result<(), ConfigError> {
        for (n, present) in names {
            if *present {
                return Err(c.fail(
                    key(n),
                    "<set>",
                    &format!("not used by friction_model = {:?}", j.friction_model),
                ));
            }
        }
        Ok(())
    };
    let param_err = |e: frictionless::friction::FrictionParamError| match e {
        frictionless::friction::FrictionParamError::Invalid {
            name,
            value,
            requirement,
            ..
        } => c.fail(key(name), value, requirement),
        other => c.fail(key("friction_model"), "?", &other.to_string()),
    };
    match j.friction_model {
        FrictionModelName::None => {
            forbid(&[
                ("kc", j.kc.is_some()),
                ("kv", j.kv.is_some()),
                ("ka", j.ka.is_some()),
                ("ks", j.ks.is_some()),
                ("vs", j.vs.is_some()),
                ("alpha", j.alpha.is_some()),
                ("model", j.model.is_some()),
            ])?;
            Ok((ModelSpec::None, None))
        }
        FrictionModelName::CoulombViscous => {
            forbid(&[
                ("ks", j.ks.is_some()),
                ("vs", j.vs.is_some()),
                ("alpha", j.alpha.is_some()),
                ("model", j.model.is_some()),
            ])?;
            let p = CvParams {
                kc: need("kc", j.kc)?,
                ka: need("ka", j.ka)?,
                kv: need("kv", j.kv)?,
            };
            p.validate().map_err(param_err)?;
            Ok((ModelSpec::Cv(p), None))
        }
        FrictionModelName::CoulombViscousStribeck => {
            forbid(&[("model", j.model.is_some())])?;
            let p = ScvParams {
                kc: need("kc", j.kc)?,
                ka: need("ka", j.ka)?,
                kv: need("kv", j.kv)?,
                ks: need("ks", j.ks)?,
                vs: need("vs", j.vs)?,
                alpha: need("alpha", j.alpha)?,
            };
            p.validate().map_err(param_err)?;
            Ok((ModelSpec::Scv(p), None))
        }
        FrictionModelName::Pinn => {
            let fallback = if j.ood == OodMode::Static {
                // The static model: kc, ka, kv (CV) and, if any of ks, vs, alpha is given, all
                // three (SCV).
                let need_static = |name: &str, v: Option<f64>| {
                    v.ok_or_else(|| {
                        c.fail(
                            key(name),
                            "<missing>",
                            "required by ood = \"static\" (the static model of a PINN joint)",
                        )
                    })
                };
                let (kc, ka, kv) = (
                    need_static("kc", j.kc)?,
                    need_static("ka", j.ka)?,
                    need_static("kv", j.kv)?,
                );
                Some(if j.ks.is_some() || j.vs.is_some() || j.alpha.is_some() {
                    let p = ScvParams {
                        kc,
                        ka,
                        kv,
                        ks: need_static("ks", j.ks)?,
                        vs: need_static("vs", j.vs)?,
                        alpha: need_static("alpha", j.alpha)?,
                    };
                    p.validate().map_err(param_err)?;
                    StaticFallback::Scv(p)
                } else {
                    let p = CvParams { kc, ka, kv };
                    p.validate().map_err(param_err)?;
                    StaticFallback::Cv(p)
                })
            } else {
                forbid(&[
                    ("kc", j.kc.is_some()),
                    ("kv", j.kv.is_some()),
                    ("ka", j.ka.is_some()),
                    ("ks", j.ks.is_some()),
                    ("vs", j.vs.is_some()),
                    ("alpha", j.alpha.is_some()),
                ])?;
                None
            };
            let rel = j.model.as_ref().ok_or_else(|| {
                c.fail(
                    key("model"),
                    "<missing>",
                    "required by friction_model = \"pinn\"",
                )
            })?;
            let path = base.join(rel);
            let checked = check_model(&path, j).map_err(|message| ConfigError::Model {
                file: c.file.to_path_buf(),
                key: key("model"),
                path: path.clone(),
                message,
            })?;
            if fallback.is_some() && !checked.has_input_range {
                return Err(c.fail(
                    key("ood"),
                    "\"static\"",
                    &format!(
                        "needs a model that stores its training input range, and {} stores none: the out-of-range check never fires, so the static fallback could never engage (use ood = \"flag\" or \"off\", or a model trained with a recorded input range)",
                        path.display()
                    ),
                ));
            }
            let features = checked.features;
            Ok((
                ModelSpec::Pinn {
                    path,
                    warmup: j.warmup,
                    fallback,
                },
                Some(features),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[loop]
period_us = 1000
[backend]
kind = "shm"
service_prefix = "t"
[safety]
stale_after_ticks = 3
on_stale = "static_model"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 25.0
joint_velocity_threshold_rad_s = 0.01
lpf = { order = 2, cutoff_hz = 10.0 }
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55
[[joint]]
name = "ankle"
index = 3
gear_ratio = 160
kt = 0.0665
max_curr = 3.0
friction_model = "coulomb_viscous_stribeck"
kc = 1.0005
ka = 2.78
kv = 0.29
ks = 6.0
vs = 0.13
alpha = 0.6
"#;

    fn p(text: &str) -> Result<Config, ConfigError> {
        parse(Path::new("/etc/x/test.toml"), text)
    }

    #[test]
    fn good_config_parses_with_aliases_and_defaults() {
        let c = p(GOOD).unwrap();
        assert_eq!(c.raw.joint.len(), 2);
        assert_eq!(c.period_ns(), 1_000_000);
        assert_eq!(c.raw.safety.on_stale, OnStale::StaticModel);
        assert!(matches!(c.models[0], ModelSpec::Cv(p) if p.kc == 8.1));
        assert!(matches!(c.models[1], ModelSpec::Scv(p) if p.alpha == 0.6));
        // defaults
        assert_eq!(c.raw.joint[1].kfc, 1.0);
        assert_eq!(c.raw.joint[1].kp, 0.0);
        assert!(c.raw.joint[1].max_output_friction.is_infinite());
        assert_eq!(c.raw.loop_.cpu_dma_latency_us, None, "PM QoS is opt-in");
        let c = p(&GOOD.replace(
            "period_us = 1000",
            "period_us = 1000\ncpu_dma_latency_us = 0",
        ))
        .unwrap();
        assert_eq!(c.raw.loop_.cpu_dma_latency_us, Some(0));
    }

    #[test]
    fn unknown_key_is_an_error_naming_it() {
        let e = p(&GOOD.replace("kfc = 0.85", "kfc = 0.85\nbwfilter_enabled = true"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bwfilter_enabled") && e.contains("test.toml"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_name_file_key_and_value() {
        let cases = [
            (
                "max_curr = 5.0",
                "max_curr = -5.0",
                "joint[0].max_curr",
                "-5",
            ),
            (
                "gear_ratio = 160",
                "gear_ratio = 0",
                "joint[1].gear_ratio",
                "0",
            ),
            ("index = 3", "index = 0", "joint[1].index", "0"),
            ("index = 3", "index = 64", "joint[1].index", "64"),
            (
                "cutoff_hz = 10.0",
                "cutoff_hz = 600.0",
                "joint[0].lpf.cutoff_hz",
                "600",
            ),
            ("vs = 0.13", "vs = 0.0", "joint[1].vs", "0"),
            ("kfc = 0.85", "kfc = 3.0", "joint[0].kfc", "3"),
            ("period_us = 1000", "period_us = 5", "loop.period_us", "5"),
            (
                "period_us = 1000",
                "period_us = 1000\ncpu_dma_latency_us = 3000000000",
                "loop.cpu_dma_latency_us",
                "3000000000",
            ),
            (
                "stale_after_ticks = 3",
                "stale_after_ticks = 0",
                "safety.stale_after_ticks",
                "0",
            ),
        ];
        for (from, to, key, val) in cases {
            let e = p(&GOOD.replace(from, to)).unwrap_err().to_string();
            assert!(
                e.contains("test.toml") && e.contains(key) && e.contains(val),
                "{from} → {to}: {e}"
            );
        }
    }

    #[test]
    fn missing_and_misplaced_model_parameters_are_errors() {
        let e = p(&GOOD.replace("kv = 5.55\n", "")).unwrap_err().to_string();
        assert!(e.contains("joint[0].kv") && e.contains("missing"), "{e}");
        let e = p(&GOOD.replace("ka = 50.84", "ka = 50.84\nks = 1.0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("joint[0].ks"), "{e}");
        let e = p(&GOOD.replace("friction_model = \"cv\"", "friction_model = \"bogus\""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
    }

    #[test]
    fn pinn_without_file_reports_resolved_path() {
        let text = GOOD.replace(
            "friction_model = \"cv\"\nkc = 8.1\nka = 50.84\nkv = 5.55",
            "friction_model = \"pinn\"\nmodel = \"models/knee.fwt\"",
        );
        let e = p(&text).unwrap_err().to_string();
        assert!(
            e.contains("joint[0].model") && e.contains("/etc/x/models/knee.fwt"),
            "{e}"
        );
    }

    const CAN: &str = r#"
[backend]
kind = "can"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"
[[joint]]
name = "ankle"
index = 1
gear_ratio = 160.0
kt = 0.0665
max_curr = 3.0
friction_model = "none"
[[bus]]
interface = "vcan0"
bitrate = 1000000
protocol = "mit"
[[bus.joint]]
joint = "knee"
node_id = 1
command_unit = "motor_torque"
p_max = 12.5
v_max = 65.0
t_max = 18.0
i_max = 40.0
[[bus]]
interface = "can1"
bitrate = 1000000
protocol = "odrive"
max_load = 0.5
joints = [{ joint = "ankle", node_id = 3, command_unit = "joint_torque" }]
"#;

    #[test]
    fn can_config_resolves_buses_units_and_load() {
        let c = p(CAN).unwrap();
        assert_eq!(c.buses.len(), 2);
        let mit = &c.buses[0];
        assert_eq!(
            (mit.protocol, mit.host_id, mit.feedback_timeout_ticks),
            (CanProtocol::Mit, 0, 5)
        );
        let d = mit.joints[0];
        assert_eq!(
            (d.index, d.node_id, d.units.command),
            (0, 1, CommandUnit::MotorTorque)
        );
        assert_eq!(d.mit.unwrap().t_min_nm, -18.0);
        assert_eq!(d.units.gear_ratio, -100.0);
        // 1 joint × 1 kHz × (135 + 115 worst-case bits: 8- and 6-byte frames) on 1 Mbit/s.
        assert!((mit.load.load - 0.25).abs() < 1e-12, "{}", mit.load.load);
        assert_eq!(mit.load.frames_per_s, 2000.0);
        let od = &c.buses[1];
        assert_eq!(od.joints[0].units.feedback_angle, AngleUnit::Rev);
        assert_eq!(od.joints[0].units.command, CommandUnit::JointTorque);
        assert_eq!(od.load.limit, 0.5);
        let s = bus_summary(&c);
        assert!(
            s.contains("bus[0] vcan0") && s.contains("25.0 %") && s.contains("bus[1] can1"),
            "{s}"
        );
    }

    #[test]
    fn can_config_errors_name_key_and_value() {
        let cases = [
            ("node_id = 1", "node_id = 0", "bus[0].joint[0].node_id", "0"),
            (
                "node_id = 3",
                "node_id = 64",
                "bus[1].joint[0].node_id",
                "64",
            ),
            (
                "t_max = 18.0",
                "t_max = 0.5",
                "bus[0].joint[0].t_max",
                "0.5",
            ),
            ("i_max = 40.0\n", "", "bus[0].joint[0].i_max", "<missing>"),
            (
                "joint = \"ankle\"",
                "joint = \"knee\"",
                "bus[1].joint[0].joint",
                "knee",
            ),
            (
                "joint = \"ankle\"",
                "joint = \"elbow\"",
                "bus[1].joint[0].joint",
                "elbow",
            ),
            (
                "interface = \"can1\"",
                "interface = \"a/b\"",
                "bus[1].interface",
                "a/b",
            ),
            (
                "interface = \"can1\"",
                "interface = \"fd:x\"",
                "bus[1].interface",
                "fd:x",
            ),
            ("max_load = 0.5", "max_load = 1.5", "bus[1].max_load", "1.5"),
            (
                "bitrate = 1000000\nprotocol = \"odrive\"",
                "bitrate = 0\nprotocol = \"odrive\"",
                "bus[1].bitrate",
                "0",
            ),
            (
                "node_id = 3, command_unit",
                "node_id = 3, p_max = 1.0, command_unit",
                "bus[1].joint[0].p_max",
                "<set>",
            ),
            ("kind = \"can\"", "kind = \"shm\"", "bus", "2 section(s)"),
            (
                "max_curr = 5.0",
                "max_curr = 5.0\nkp = 0.5",
                "joint[0].kp",
                "kp = 0.5",
            ),
        ];
        for (from, to, key, val) in cases {
            assert!(CAN.contains(from), "{from}");
            let e = p(&CAN.replacen(from, to, 1)).unwrap_err().to_string();
            assert!(
                e.contains("test.toml") && e.contains(&format!("`{key}`")) && e.contains(val),
                "{from} → {to}: {e}"
            );
        }
        // Every joint on exactly one bus.
        let e = p(&CAN.replace(
            "joints = [{ joint = \"ankle\", node_id = 3, command_unit = \"joint_torque\" }]",
            "joints = []",
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("bus[1].joint"), "{e}");
        let cut = CAN.find("[[bus]]\ninterface = \"can1\"").unwrap();
        let e = p(&CAN[..cut]).unwrap_err().to_string();
        assert!(
            e.contains("joint[1].name") && e.contains("exactly one"),
            "{e}"
        );
        let cut = CAN.find("[[bus]]").unwrap();
        let e = p(&CAN[..cut]).unwrap_err().to_string();
        assert!(
            e.contains("`bus`") && e.contains("at least one [[bus]]"),
            "{e}"
        );
    }

    fn mit_joints(n: usize, max_load: f64) -> String {
        let mut text = String::from("[backend]\nkind = \"can\"\n");
        for k in 0..n {
            text += &format!(
                "[[joint]]\nname = \"j{k}\"\nindex = {k}\ngear_ratio = 100.0\nkt = 0.1\nmax_curr = 5.0\nfriction_model = \"none\"\n"
            );
        }
        text += &format!(
            "[[bus]]\ninterface = \"can0\"\nbitrate = 1000000\nprotocol = \"mit\"\nmax_load = {max_load}\n"
        );
        for k in 0..n {
            text += &format!(
                "[[bus.joint]]\njoint = \"j{k}\"\nnode_id = {}\ncommand_unit = \"current\"\np_max = 12.5\nv_max = 65.0\nt_max = 5.0\ni_max = 40.0\n",
                k + 1
            );
        }
        text
    }

    #[test]
    fn bus_over_its_load_limit_is_refused_with_the_numbers() {
        // Four MIT joints at 1 kHz on 1 Mbit/s: 4 × (135 + 115) bits = 100 % > 70 %.
        let e = p(&mit_joints(4, 0.7)).unwrap_err().to_string();
        for needle in [
            "bus[0].max_load",
            "8000 frames/s",
            "250 bits",
            "100.0 %",
            "limit 70.0 %",
            "1000000 bit/s",
        ] {
            assert!(e.contains(needle), "{needle}: {e}");
        }
        // Three fit a 75 % limit exactly; not a 74 % one.
        let c = p(&mit_joints(3, 0.75)).unwrap();
        assert!((c.buses[0].load.load - 0.75).abs() < 1e-12);
        let e = p(&mit_joints(3, 0.74)).unwrap_err().to_string();
        assert!(e.contains("75.0 %"), "{e}");
    }

    fn assert_refused(text: &str, key: &str, val: &str) {
        let e = p(text).unwrap_err().to_string();
        assert!(
            e.contains("test.toml") && e.contains(&format!("`{key}`")) && e.contains(val),
            "{key} = {val}: {e}"
        );
    }

    /// Issue 14 #5: a CPU outside the online set (or beyond CPU_SETSIZE) is refused by `--check`.
    #[test]
    fn cpu_outside_the_online_set_is_refused() {
        let with_cpu = |cpu: usize| {
            GOOD.replace(
                "period_us = 1000",
                &format!("period_us = 1000\ncpu = {cpu}"),
            )
        };
        assert_refused(&with_cpu(1024), "loop.cpu", "1024");
        assert_refused(&with_cpu(usize::MAX), "loop.cpu", &usize::MAX.to_string());
        let online = online_cpus().expect("/sys/devices/system/cpu/online is readable here");
        let last = online.iter().map(|r| *r.end()).max().unwrap();
        p(&with_cpu(*online[0].start())).unwrap();
        if last + 1 < libc::CPU_SETSIZE as usize {
            assert_refused(&with_cpu(last + 1), "loop.cpu", &(last + 1).to_string());
        }
    }

    #[test]
    fn rt_threads_helper_cpu_and_prefetch_are_checked() {
        let with =
            |extra: &str| GOOD.replace("period_us = 1000", &format!("period_us = 1000\n{extra}"));
        let c = p(&with("")).unwrap();
        assert_eq!(
            (
                c.raw.loop_.rt_threads,
                c.raw.loop_.helper_cpu,
                c.raw.loop_.prefetch
            ),
            (1, None, Prefetch::Off),
            "one RT thread, no prefetch by default"
        );
        let c = p(&with(
            "rt_threads = 2\nprefetch = \"lead\"\nprefetch_lead_us = 150",
        ))
        .unwrap();
        assert_eq!(
            (
                c.raw.loop_.rt_threads,
                c.raw.loop_.prefetch,
                c.raw.loop_.prefetch_lead_us
            ),
            (2, Prefetch::Lead, 150)
        );
        assert_eq!(
            p(&with("prefetch = \"after\"")).unwrap().raw.loop_.prefetch,
            Prefetch::After
        );
        for bad in [0, 3] {
            assert_refused(
                &with(&format!("rt_threads = {bad}")),
                "loop.rt_threads",
                &bad.to_string(),
            );
        }
        let e = p(&with("prefetch = \"sometimes\""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("prefetch") && e.contains("sometimes"), "{e}");
        assert_refused(
            &with("prefetch = \"lead\"\nprefetch_lead_us = 1000"),
            "loop.prefetch_lead_us",
            "1000",
        );
        assert_refused(
            &with("prefetch = \"lead\"\nprefetch_lead_us = 0"),
            "loop.prefetch_lead_us",
            "0",
        );
        // The lead is only checked when it is used.
        p(&with("prefetch_lead_us = 5000")).unwrap();
        let online = online_cpus().expect("/sys/devices/system/cpu/online is readable here");
        let first = *online[0].start();
        let last = online.iter().map(|r| *r.end()).max().unwrap();
        assert_refused(
            &with(&format!("helper_cpu = {first}")),
            "loop.helper_cpu",
            &first.to_string(),
        );
        p(&with(&format!("rt_threads = 2\nhelper_cpu = {first}"))).unwrap();
        assert_refused(
            &with(&format!(
                "rt_threads = 2\ncpu = {first}\nhelper_cpu = {first}"
            )),
            "loop.helper_cpu",
            &first.to_string(),
        );
        assert_refused(
            &with("rt_threads = 2\nhelper_cpu = 1024"),
            "loop.helper_cpu",
            "1024",
        );
        if last + 1 < libc::CPU_SETSIZE as usize {
            assert_refused(
                &with(&format!("rt_threads = 2\nhelper_cpu = {}", last + 1)),
                "loop.helper_cpu",
                &(last + 1).to_string(),
            );
        }
    }

    #[test]
    fn cpu_lists_parse_as_the_kernel_writes_them() {
        assert_eq!(parse_cpu_list("0-3\n"), Some(vec![0..=3]));
        assert_eq!(parse_cpu_list("0,2-3,7"), Some(vec![0..=0, 2..=3, 7..=7]));
        assert_eq!(parse_cpu_list(""), None);
        assert_eq!(parse_cpu_list("x"), None);
        assert_eq!(parse_cpu_list("3-1"), None);
    }

    /// Issue 14 #10: values `--check` accepted but the start refused, or that switch a protection off.
    #[test]
    fn start_time_failures_and_unbounded_tick_counts_are_refused() {
        let long = "p".repeat(4000);
        assert_refused(
            &GOOD.replace(
                "service_prefix = \"t\"",
                &format!("service_prefix = \"{long}\""),
            ),
            "backend.service_prefix",
            "4000 bytes",
        );
        let max = "p".repeat(frictionless_shm_types::MAX_SERVICE_PREFIX_BYTES);
        p(&GOOD.replace(
            "service_prefix = \"t\"",
            &format!("service_prefix = \"{max}\""),
        ))
        .unwrap();
        assert_refused(
            &GOOD.replace("service_prefix = \"t\"", "service_prefix = \"iox2://x\""),
            "backend.service_prefix",
            "iox2://x",
        );
        let file = concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml");
        assert_refused(
            &GOOD.replace(
                "service_prefix = \"t\"",
                &format!("service_prefix = \"t\"\nroot_path = \"{file}\""),
            ),
            "backend.root_path",
            "Cargo.toml",
        );
        // A directory, or a path not created yet, is fine.
        let dir = env!("CARGO_MANIFEST_DIR");
        p(&GOOD.replace(
            "service_prefix = \"t\"",
            &format!("service_prefix = \"t\"\nroot_path = \"{dir}\""),
        ))
        .unwrap();
        p(&GOOD.replace(
            "service_prefix = \"t\"",
            "service_prefix = \"t\"\nroot_path = \"/nonexistent/iox\"",
        ))
        .unwrap();
        let u64max = u64::MAX.to_string();
        assert_refused(
            &GOOD.replace(
                "stale_after_ticks = 3",
                &format!("stale_after_ticks = {u64max}"),
            ),
            "safety.stale_after_ticks",
            &u64max,
        );
        assert_refused(
            &GOOD.replace(
                "period_us = 1000",
                &format!("period_us = 1000\nready_after_ticks = {u64max}"),
            ),
            "loop.ready_after_ticks",
            &u64max,
        );
        // 60 s at 1 kHz is the largest; at 10 kHz (period 100 µs) 600000 ticks.
        p(&GOOD.replace("stale_after_ticks = 3", "stale_after_ticks = 60000")).unwrap();
        assert_refused(
            &GOOD.replace("stale_after_ticks = 3", "stale_after_ticks = 60001"),
            "safety.stale_after_ticks",
            "60001",
        );
        p(&GOOD.replace(
            "period_us = 1000",
            "period_us = 100\nready_after_ticks = 600000",
        ))
        .unwrap();
    }

    fn shipped_model() -> String {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/models/stress32_paper_f16_r-100.fwt"
        )
        .to_owned()
    }

    fn pinn_joint(name: &str, kt: f64, model: &str) -> String {
        format!(
            "[[joint]]\nname = \"{name}\"\nindex = {}\ngear_ratio = -100.0\nkt = {kt:?}\nmax_curr = 5.0\nfriction_model = \"pinn\"\nmodel = \"{model}\"\n",
            name.len()
        )
    }

    /// `ood = "static"` needs the joint's static model (CV, or SCV with all three Stribeck keys), a
    /// PINN and a model that stores its training input range; the margin and the ramp are
    /// range-checked; without `ood` a PINN joint flags only and still refuses static-model keys.
    #[test]
    fn out_of_range_settings_are_typed_and_checked() {
        let spec = FeatureSpec {
            set: frictionless::features::FeatureSet::DeltaThetaJointVel,
            history: 3,
            temperature: false,
        };
        let m = joint_model_with_range("knee", -100.0, 0.157, spec, true);
        // A model without a stored range (the shipped ones): the check never fires, so a static
        // fallback could never engage; refused naming the key, the value and why. `flag` (the
        // default) is accepted: it just never flags.
        let unranged = joint_model("knee", -100.0, 0.157, spec);
        let plain = format!(
            "[backend]\nkind = \"shm\"\n{}",
            pinn_joint("knee", 0.157, unranged.to_str().unwrap())
        );
        p(&plain).unwrap();
        p(&format!("{plain}ood = \"flag\"\n")).unwrap();
        let e = p(&format!(
            "{plain}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n"
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("joint[0].ood")
                && e.contains("static")
                && e.contains("input range")
                && e.contains(unranged.to_str().unwrap()),
            "{e}"
        );
        let e = p(&format!(
            "[backend]\nkind = \"shm\"\n{}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n",
            pinn_joint("stress32_r-100", 0.156977705, &shipped_model())
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("joint[0].ood") && e.contains("input range"),
            "{e}"
        );
        let base = format!(
            "[backend]\nkind = \"shm\"\n{}",
            pinn_joint("knee", 0.157, m.to_str().unwrap())
        );
        let c = p(&base).unwrap();
        assert_eq!(c.raw.joint[0].ood, OodMode::Flag);
        assert_eq!(c.raw.joint[0].ood_margin, 0.1);
        assert_eq!(c.raw.joint[0].ood_ramp_ms, 20.0);
        assert!(matches!(
            c.models[0],
            ModelSpec::Pinn { fallback: None, .. }
        ));
        // No static model configured: refused at --check, naming the missing key.
        let e = p(&format!("{base}ood = \"static\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("joint[0].kc") && e.contains("ood"), "{e}");
        let cv = format!("{base}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n");
        let c = p(&cv).unwrap();
        assert!(matches!(
            c.models[0],
            ModelSpec::Pinn {
                fallback: Some(StaticFallback::Cv(cv)),
                ..
            } if cv.kc == 1.0
        ));
        let scv = format!("{cv}ks = 1.5\nvs = 0.1\nalpha = 1.0\n");
        assert!(matches!(
            p(&scv).unwrap().models[0],
            ModelSpec::Pinn {
                fallback: Some(StaticFallback::Scv(_)),
                ..
            }
        ));
        // Half an SCV is refused; static keys without `ood = "static"` too.
        let e = p(&format!("{cv}ks = 1.5\n")).unwrap_err().to_string();
        assert!(e.contains("joint[0].vs"), "{e}");
        let e = p(&format!("{base}kc = 1.0\n")).unwrap_err().to_string();
        assert!(e.contains("joint[0].kc"), "{e}");
        for (key, bad) in [
            ("ood_margin", "-0.1"),
            ("ood_margin", "nan"),
            ("ood_ramp_ms", "5000.0"),
        ] {
            let e = p(&format!("{cv}{key} = {bad}\n")).unwrap_err().to_string();
            assert!(e.contains(&format!("joint[0].{key}")), "{e}");
        }
        let e = p(&format!("{base}ood = \"sometimes\"\n"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sometimes") || e.contains("unknown variant"),
            "{e}"
        );
        // A static-model joint cannot fall back to itself.
        let e = p(&GOOD.replacen("kv = 5.55", "kv = 5.55\nood = \"static\"", 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("joint[0].ood"), "{e}");
    }

    /// Issue 14 #7: a model recorded for another joint, or another k_t, is refused naming both values.
    #[test]
    fn model_for_another_joint_or_kt_is_refused() {
        let m = shipped_model();
        let head = "[backend]\nkind = \"shm\"\n";
        // The file records joint "stress32_r-100", gear ratio -100, k_t 0.156977705.
        p(&format!(
            "{head}{}",
            pinn_joint("stress32_r-100", 0.156977705, &m)
        ))
        .unwrap();
        let e = p(&format!("{head}{}", pinn_joint("l_knee", 0.156977705, &m)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("joint[0].model")
                && e.contains("\"stress32_r-100\"")
                && e.contains("\"l_knee\""),
            "{e}"
        );
        let e = p(&format!("{head}{}", pinn_joint("stress32_r-100", 0.18, &m)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("joint[0].model") && e.contains("0.156977705") && e.contains("0.18"),
            "{e}"
        );
        // Sharing a file does not lift the check: a joint that runs another joint's network must say
        // so with model_for (a template, as in config/stress32.toml).
        let other = format!(
            "{head}{}{}",
            pinn_joint("stress32_r-100", 0.156977705, &m),
            pinn_joint("bb", 0.066468037, &m)
        );
        let e = p(&other).unwrap_err().to_string();
        assert!(
            e.contains("joint[1].model") && e.contains("model_for"),
            "{e}"
        );
        let template = other.replacen(
            "name = \"bb\"",
            "name = \"bb\"\nmodel_for = \"stress32_r-100\"",
            1,
        );
        p(&template).unwrap();
        // model_for must name what the file records, and the gear ratio is still compared.
        let e = p(&template.replacen("model_for = \"stress32_r-100\"", "model_for = \"x\"", 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("joint[1].model") && e.contains("\"x\""), "{e}");
        let e = p(&template.replacen("gear_ratio = -100.0", "gear_ratio = 100.0", 1))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("joint[0].model") && e.contains("gear_ratio"),
            "{e}"
        );
    }

    /// A random `.fwt` for joint `name` (gear ratio `r`, k_t `kt`) with the given inputs, in a
    /// scratch dir.
    fn joint_model(name: &str, r: f64, kt: f64, spec: FeatureSpec) -> PathBuf {
        joint_model_with_range(name, r, kt, spec, false)
    }

    /// A random model for `name`; with `range`, it stores a training input range.
    fn joint_model_with_range(
        name: &str,
        r: f64,
        kt: f64,
        spec: FeatureSpec,
        range: bool,
    ) -> PathBuf {
        use frictionless::random::{RandomMlpSpec, seeded_mlp};
        use frictionless::weights::{InputRange, ModelFile, ModelMeta, TrainingMeta};
        let dir =
            std::env::temp_dir().join(format!("frictiond_config_inputs_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!(
            "{name}_{}_{}{}.fwt",
            spec.set,
            spec.temperature,
            if range { "_ranged" } else { "" }
        ));
        let mut training = TrainingMeta::unknown("config test", 0);
        if range {
            let mut blocks = [[0.0; 2]; frictionless::weights::layout::RANGE_BLOCKS];
            for b in blocks.iter_mut().take(spec.set.n_blocks()) {
                *b = [-1.0, 1.0];
            }
            training.input_range = Some(InputRange {
                blocks,
                temperature: if spec.temperature {
                    [20.0, 40.0]
                } else {
                    [0.0, 0.0]
                },
            });
        }
        let file = ModelFile {
            meta: ModelMeta {
                joint_name: name.into(),
                gear_ratio: frictionless::units::GearRatio::new(r).unwrap(),
                kt_nm_per_a: kt,
                features: spec,
                scv: None,
                training,
            },
            dtype: frictionless::mlp::StorageDtype::F32,
            mlp: seeded_mlp(&RandomMlpSpec::new(&[spec.n_inputs(), 4, 1]), 1).unwrap(),
        };
        frictionless::weights::write_file(&path, &file).unwrap();
        path
    }

    /// Issue 13: a PINN whose inputs the backend cannot supply is refused at load (`--check`,
    /// reload) naming joint, set and field: both CAN protocols report motor-side values only (joint
    /// values derived, so Δθ carries nothing) and no temperature; shm takes what the publisher writes.
    #[test]
    fn models_whose_inputs_the_backend_cannot_supply_are_refused() {
        use frictionless::features::FeatureSet;
        // CAN: knee (joint 0) on the MIT bus, ankle (joint 1) on the ODrive bus.
        let can_pinn = |model: &Path, k: usize| {
            let none = "friction_model = \"none\"";
            let pinn = format!("friction_model = \"pinn\"\nmodel = \"{}\"", model.display());
            let mut parts: Vec<&str> = CAN.split(none).collect();
            let tail = parts.split_off(k + 1);
            format!("{}{pinn}{}", parts.join(none), tail.join(none))
        };
        for set in FeatureSet::ALL {
            for temperature in [false, true] {
                let spec = FeatureSpec {
                    set,
                    history: 3,
                    temperature,
                };
                let m = joint_model("knee", -100.0, 0.157, spec);
                let ankle = joint_model("ankle", 160.0, 0.0665, spec);
                let shm = format!(
                    "[backend]\nkind = \"shm\"\n{}",
                    pinn_joint("knee", 0.157, m.to_str().unwrap())
                );
                p(&shm).unwrap_or_else(|e| panic!("shm runs {spec}: {e}"));
                for (k, model, name, protocol) in
                    [(0, &m, "knee", "mit"), (1, &ankle, "ankle", "odrive")]
                {
                    let r = p(&can_pinn(model, k));
                    let why = format!("{spec} on {protocol}");
                    if set.uses_delta_theta() || temperature {
                        let e = r.expect_err(&why).to_string();
                        // A missing field is reported before the derived joint position.
                        let field = if temperature {
                            "`temperature_c`"
                        } else {
                            "`s_rad`"
                        };
                        assert!(
                            e.contains(&format!("joint[{k}].model"))
                                && e.contains(&format!("joint {name}"))
                                && e.contains(&format!("`{set}`"))
                                && e.contains(field)
                                && e.contains(protocol),
                            "{why}: {e}"
                        );
                    } else {
                        r.unwrap_or_else(|e| panic!("{why}: {e}"));
                    }
                }
            }
        }
        assert_eq!(
            signal_supply(
                BackendKind::Can,
                Some(CanProtocol::Odrive),
                Signal::JointVelRadS
            ),
            SignalSupply::DerivedFrom(Signal::MotorVelRadS)
        );
        assert_eq!(
            signal_supply(
                BackendKind::Can,
                Some(CanProtocol::Mit),
                Signal::MotorPosRad
            ),
            SignalSupply::Measured
        );
        assert_eq!(
            signal_supply(BackendKind::Shm, None, Signal::TemperatureC),
            SignalSupply::Publisher
        );
    }
}
