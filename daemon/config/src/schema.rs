//! The schema: the file as written ([`RawConfig`] and its sections, serde with unknown keys
//! refused, defaults) and the validated result ([`Config`], [`ModelSpec`], [`ResolvedBus`] with its [`BusLoad`]).

use std::path::{Path, PathBuf};

use frictionless::model::ModelKind;
use frictionless_drives::can::mit::MitRanges;
use frictionless_drives::can::units::{CommandUnit, JointUnits};
use serde::{Deserialize, Serialize};

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

impl BackendKind {
    /// The name a person reads in messages (`shared-memory`, `CAN`).
    pub fn label(self) -> &'static str {
        match self {
            Self::Shm => "shared-memory",
            Self::Can => "CAN",
        }
    }
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

/// `[joint.speed_current_limit]`: the drive's torque–speed curve as a current limit (see
/// `frictionless::law::SpeedCurrentLimit`). Speeds are of the **motor** shaft, |ω_m| = |r·ṡ|.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpeedCurrentLimitConfig {
    /// Rated motor speed [rad/s]: up to it the limit is `safety_factor · max_curr`.
    pub rated_motor_speed_rad_s: f64,
    /// No-load motor speed [rad/s] (> rated): the limit falls linearly to 0 A here.
    pub no_load_motor_speed_rad_s: f64,
    /// Factor on `max_curr` in (0, 1]; default 1.
    #[serde(default = "one")]
    pub safety_factor: f64,
}

/// Serde of a joint's `friction_model` (use with `#[serde(with = "friction_model_name")]`): the
/// core's [`ModelKind`], written as its [`ModelKind::config_name`] (the ergoCub names:
/// `coulomb_viscous`, `coulomb_viscous_stribeck`, …) and read from that or its short
/// [`ModelKind::name`] (`cv`, `scv`, …). A kind without a config name (the SCV code form) is written
/// as the kind the daemon runs it as.
pub mod friction_model_name {
    use frictionless::model::ModelKind;
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes `kind`'s config name.
    pub fn serialize<S: Serializer>(kind: &ModelKind, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(kind.daemon_kind().config_name().unwrap_or("none"))
    }

    /// Reads a config name or short name; the error lists the accepted names.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ModelKind, D::Error> {
        let name = String::deserialize(d)?;
        ModelKind::from_config_name(&name).ok_or_else(|| {
            let known: Vec<String> = ModelKind::ALL
                .into_iter()
                .filter_map(|k| k.config_name().map(|c| format!("{c} ({})", k.name())))
                .collect();
            serde::de::Error::custom(format!(
                "unknown friction_model `{name}`, expected one of: {}",
                known.join(", ")
            ))
        })
    }
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

/// Whether a joint's motor encoder keeps its zero across power-ups.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum MotorEncoder {
    /// The motor angle θ reads the same zero at every power-up (an absolute encoder, or an
    /// incremental one homed to a fixed reference): a calibrated `delta_theta_offset_motor_rad`
    /// holds across boots.
    #[default]
    Absolute,
    /// Each power-up has its own zero: a fixed Δθ offset is wrong after the next boot, so a PINN
    /// joint that reads Δθ latches it at every enable (no `delta_theta_offset_motor_rad`), and its
    /// model is trained latched per chunk (`frictl train --motor-encoder incremental`).
    Incremental,
}

impl MotorEncoder {
    /// `"absolute"` or `"incremental"` (the config and robot-file spelling).
    pub fn name(self) -> &'static str {
        match self {
            Self::Absolute => "absolute",
            Self::Incremental => "incremental",
        }
    }

    /// Whether this is the default (`absolute`), for `skip_serializing_if`.
    pub fn is_default(&self) -> bool {
        *self == Self::Absolute
    }
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
    /// Speed-dependent current limit (none = the constant clamp ±max_curr).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_current_limit: Option<SpeedCurrentLimitConfig>,
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
    /// Friction model ([`friction_model_name`]).
    #[serde(with = "friction_model_name")]
    pub friction_model: ModelKind,
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
    /// Bristle stiffness σ0 [Nm/rad] (LuGre).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma0: Option<f64>,
    /// Bristle damping σ1 [Nm·s/rad] (LuGre).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma1: Option<f64>,
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
    /// The motor encoder's kind (`absolute`, the default, or `incremental`): with `incremental`
    /// a PINN joint reading Δθ may not set `delta_theta_offset_motor_rad`.
    #[serde(default, skip_serializing_if = "MotorEncoder::is_default")]
    pub motor_encoder: MotorEncoder,
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
    /// `[[joint.alternate]]`: further friction models of this joint, loaded and validated with the
    /// file, that a running daemon switches to with `model = NAME` ([`crate::runtime`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alternate: Vec<AlternateModel>,
}

/// The name a running joint's own model (its `friction_model` keys) has among its models.
pub const MODEL_NAME_DEFAULT: &str = "default";
/// The name of "no friction model" among a joint's models (τ̂_F = 0), always available.
pub const MODEL_NAME_NONE: &str = "none";

/// One `[[joint.alternate]]`: a named friction model a running daemon can switch its joint to.
/// The model keys mean what they mean on `[[joint]]` and follow the same rules (checked by the
/// same code, on the joint with its model keys replaced by these, [`AlternateModel::as_joint`]);
/// everything else (gains, limits, filter, `model_for`, Δθ offset, `ood`) is the joint's.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AlternateModel {
    /// The name `model = NAME` selects: 1–63 bytes of `A-Z a-z 0-9 _ - .`, unique in the joint,
    /// not `default` or `none`.
    pub name: String,
    /// Friction model ([`friction_model_name`]).
    #[serde(with = "friction_model_name")]
    pub friction_model: ModelKind,
    /// Coulomb level [Nm].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kc: Option<f64>,
    /// Viscous coefficient [Nm·s/rad].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kv: Option<f64>,
    /// Smooth-sign steepness [s/rad]; `inf` = sign().
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ka: Option<f64>,
    /// Breakaway friction [Nm] (SCV).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ks: Option<f64>,
    /// Stribeck velocity [rad/s] (SCV).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vs: Option<f64>,
    /// Stribeck exponent (SCV).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<f64>,
    /// Bristle stiffness σ0 [Nm/rad] (LuGre).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma0: Option<f64>,
    /// Bristle damping σ1 [Nm·s/rad] (LuGre).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma1: Option<f64>,
    /// `.fwt` model file for `pinn`, relative to the config file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<PathBuf>,
    /// PINN warm-up policy.
    #[serde(default)]
    pub warmup: WarmupName,
}

impl AlternateModel {
    /// `joint` with its model keys replaced by this alternate's and `ood = "off"` (the static
    /// fallback of `ood = "static"` belongs to the joint's own model): what the model rules and
    /// the estimator construction read.
    pub fn as_joint(&self, joint: &JointConfig) -> JointConfig {
        JointConfig {
            friction_model: self.friction_model,
            kc: self.kc,
            kv: self.kv,
            ka: self.ka,
            ks: self.ks,
            vs: self.vs,
            alpha: self.alpha,
            sigma0: self.sigma0,
            sigma1: self.sigma1,
            model: self.model.clone(),
            warmup: self.warmup,
            ood: OodMode::Off,
            alternate: Vec::new(),
            ..joint.clone()
        }
    }
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
    /// `[control]`: runtime control of the running daemon.
    #[serde(default)]
    pub control: ControlConfig,
}

/// `[control]`: the `<prefix>/control` request–response service (`frictl ctl`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// Accept runtime sets (`kfc`, `max_output_friction`, `max_curr`, `compensation`, `ood`);
    /// false: gets only, every set refused. Default true.
    #[serde(default = "default_true")]
    pub writes: bool,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self { writes: true }
    }
}

impl RawConfig {
    /// A config for `joint` over shared memory with the default service prefix `frictionless`,
    /// the iceoryx2 default root, the default loop and safety, no buses (what a pipeline that trained
    /// the models writes for the robot).
    pub fn shm(joint: Vec<JointConfig>) -> Self {
        Self {
            loop_: LoopConfig::default(),
            backend: BackendConfig {
                kind: BackendKind::Shm,
                service_prefix: "frictionless".into(),
                root_path: None,
            },
            safety: SafetyConfig::default(),
            joint,
            bus: Vec::new(),
            control: ControlConfig::default(),
        }
    }

    /// Rewrites every relative path the file holds (the joints' and their alternates' model files,
    /// the iceoryx2 root path) as `base` joined with it, so that the config written to another directory names the
    /// same files (`base` is the directory of the file it was read from, as in [`crate::parse`]).
    pub fn make_paths_absolute(&mut self, base: &Path) {
        let fix = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        if let Some(p) = self.backend.root_path.as_mut() {
            fix(p);
        }
        for j in &mut self.joint {
            let alternates = j.alternate.iter_mut().filter_map(|a| a.model.as_mut());
            for p in j.model.as_mut().into_iter().chain(alternates) {
                fix(p);
            }
        }
    }
}

/// Largest number of `[[bus]]` sections (sockets polled per tick).
pub const MAX_BUSES: usize = 8;

/// Motor-drive protocol of one bus (defined with the codecs, in `frictionless-drives`).
pub use frictionless_drives::can::CanProtocol;

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
    /// CiA 402: the drive's CANopen keys (`[bus.joint.cia402]`; required with `protocol =
    /// "cia402"`, refused otherwise).
    #[serde(default)]
    pub cia402: Option<Cia402Config>,
}

/// How frictiond drives a CiA 402 joint (`[bus.joint.cia402] mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cia402Mode {
    /// Cyclic synchronous torque (0x6060 = 10): the daemon's torque is the target torque 0x6071.
    Cst,
    /// The drive keeps its own position (CSP, 8) or velocity (CSV, 9) loop, commanded by another
    /// master; the daemon's torque is the feed-forward torque offset 0x60B2.
    TorqueOffset,
}

/// The drive's own loop in [`Cia402Mode::TorqueOffset`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cia402DriveLoop {
    /// Cyclic synchronous position (0x6060 = 8).
    Csp,
    /// Cyclic synchronous velocity (0x6060 = 9).
    Csv,
}

/// An extra object a TPDO carries (`{ index = 0x60E4, sub = 1, bits = 32, … }`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cia402Object {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    #[serde(default)]
    pub sub: u8,
    /// Length in bits (8, 16 or 32; signed). Default 32.
    #[serde(default = "default_object_bits")]
    pub bits: u8,
    /// Joint-side encoder: increments per joint revolution (required there, refused for the
    /// temperature).
    #[serde(default)]
    pub counts_per_rev: Option<f64>,
    /// Temperature: °C per unit (e.g. 0.001 for milli-°C; required there, refused for the encoder).
    #[serde(default)]
    pub unit_c: Option<f64>,
}

fn default_object_bits() -> u8 {
    32
}

/// `[bus.joint.cia402]`: the CANopen side of one drive. Scales left out are read by SDO at start-up
/// (rated torque 0x6076, max torque 0x6072, encoder resolution 0x608F); the velocity unit has no
/// standard object and is always given.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cia402Config {
    /// `cst` (default) or `torque_offset`.
    #[serde(default = "default_cia402_mode")]
    pub mode: Cia402Mode,
    /// With `mode = "torque_offset"`: the drive's loop, `csp` or `csv` (required there).
    #[serde(default)]
    pub drive_loop: Option<Cia402DriveLoop>,
    /// Whether frictiond may reset a drive fault (controlword bit 7 edge). Default false: a fault
    /// stays until someone resets it on purpose.
    #[serde(default)]
    pub fault_reset: bool,
    /// Motor rated torque 0x6076 [mNm]; left out: read by SDO.
    #[serde(default)]
    pub rated_torque_mnm: Option<u32>,
    /// Max torque 0x6072 [‰ of rated]; left out: read by SDO.
    #[serde(default)]
    pub max_torque_permille: Option<u16>,
    /// Motor encoder increments per motor revolution (0x6064's unit); left out: read by SDO from
    /// 0x608F (sub 1 increments / sub 2 revolutions).
    #[serde(default)]
    pub counts_per_rev: Option<f64>,
    /// Motor rad/s per unit of 0x606C velocity actual value (vendor-specific: e.g. 2π/60 for rpm,
    /// 2π/counts_per_rev for increments/s). Required.
    #[serde(default)]
    pub velocity_unit_rad_s: Option<f64>,
    /// The joint-side encoder object (e.g. 0x60E4:01) mapped into TPDO2; left out: s = θ/r.
    #[serde(default)]
    pub joint_encoder: Option<Cia402Object>,
    /// The drive temperature object (vendor-specific, e.g. Synapticon 0x2031:01 in m°C) mapped into
    /// TPDO3, sent every `temperature_every` SYNCs.
    #[serde(default)]
    pub temperature: Option<Cia402Object>,
    /// SYNCs between temperature TPDOs (1..=240). Default 100.
    #[serde(default = "default_temperature_every")]
    pub temperature_every: u8,
    /// Heartbeat producer time written to the drive's 0x1017 [ms] (1..=65535). Default 100.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u16,
    /// A drive whose heartbeat is missing this long is stale [ms] (> heartbeat_ms). Default 3 ×
    /// heartbeat_ms.
    #[serde(default)]
    pub heartbeat_timeout_ms: Option<u32>,
}

fn default_cia402_mode() -> Cia402Mode {
    Cia402Mode::Cst
}
fn default_temperature_every() -> u8 {
    100
}
fn default_heartbeat_ms() -> u16 {
    100
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
    /// LuGre (`kc`, `kv`, `ks`, `vs`, `alpha`, `sigma0`, `sigma1`), integrated at the loop period.
    Lugre(frictionless::lugre::LugreParams),
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

/// A validated `[[joint.alternate]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedModel {
    /// Its `name`.
    pub name: String,
    /// Its resolved model.
    pub spec: ModelSpec,
    /// Its kind as the daemon runs it.
    pub kind: ModelKind,
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
    /// Resolved `[[joint.alternate]]`s per joint, same order as `raw.joint` (each in file order).
    pub alternates: Vec<Vec<NamedModel>>,
    /// Resolved iceoryx2 root path.
    pub root_path: Option<PathBuf>,
    /// Resolved `[[bus]]` sections (empty unless `[backend] kind = "can"`).
    pub buses: Vec<ResolvedBus>,
}

/// Worst-case bus load of one bus from the config.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusLoad {
    /// Drives on the bus.
    pub n_joints: u32,
    /// Frames per second on the bus (commands and feedback).
    pub frames_per_s: f64,
    /// Worst-case bits (with stuffing) of the frames one joint puts on the bus per tick (CiA 402:
    /// the largest of the bus's drives).
    pub bits_per_joint_tick: u32,
    /// Worst-case bits per tick of the bus's own frames (CiA 402: the SYNC; 0 for MIT / ODrive).
    pub bits_per_bus_tick: u32,
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
            "{} joint(s): {:.0} frames/s, {} bits per joint and tick in {} frame(s){} (worst-case stuffing), load {:.1} % of {} bit/s (limit {:.1} %)",
            self.n_joints,
            self.frames_per_s,
            self.bits_per_joint_tick,
            self.frames_per_joint_tick,
            if self.bits_per_bus_tick > 0 {
                format!(" + {} bits of SYNC per tick", self.bits_per_bus_tick)
            } else {
                String::new()
            },
            100.0 * self.load,
            self.bitrate_bps,
            100.0 * self.limit
        )
    }
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
    /// CiA 402 drive settings (other protocols: `None`).
    pub cia402: Option<Cia402Drive>,
}

/// A validated `[bus.joint.cia402]`, with its PDO layout and worst-case bits per cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cia402Drive {
    /// As written (validated).
    pub cfg: Cia402Config,
    /// Mode of operation written to 0x6060 (10 CST, 8 CSP, 9 CSV).
    pub op_mode: i8,
    /// Heartbeat timeout [ms].
    pub heartbeat_timeout_ms: u32,
    /// RPDO1 (controlword + target torque or torque offset), TPDO1 (statusword, position, torque),
    /// TPDO2 (velocity [+ joint-side encoder]), TPDO3 (temperature, if any).
    pub layout: frictionless_drives::can::cia402::Layout,
    /// Worst-case bits this drive puts on the bus per cycle.
    pub bits_per_tick: u32,
}

impl Config {
    /// Loop period [ns].
    pub fn period_ns(&self) -> u64 {
        self.raw.loop_.period_us * 1000
    }
}
