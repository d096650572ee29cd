//! # `frictionless-experiment`: the paper's closed-loop experiments on the virtual joints
//!
//! Crate table: `tools/experiment`; depends on `frictionless-sim` (plant presets),
//! `frictionless-acquire`, `frictionless-eval` (figure fonts) and `frictiond-config` (the daemon's
//! config schema, to write frictiond's config); used by `frictl` (`experiment`, `demo`, `robot run`).
//!
//! What this crate **is**: the high-level computed-torque controller ([`controller`]) as a real
//! process role — it reads `JointStates` over shared memory and publishes `TorqueRequest` (and
//! `SimDisturbance`) in lockstep with the virtual plant (`frictl sim serve`) and `frictiond`, both
//! started as child processes per trial ([`session`], [`run`]); metrics ([`metrics`]), the
//! minimum-K_p bisection ([`search`]), the three experiments of the paper (`track`, `min-kp`,
//! `disturbance`, in [`suite`]) and their tables, JSON and plots ([`report`]); the `oracle`
//! diagnostic ([`oracle`]: compensation with the plant's true friction — a bound, not a model); the
//! same experiments on the coupled six-joint leg with the whole-leg computed-torque controller
//! ([`leg`]: [`leg::run_leg_suite`], through the same run loop with [`rig::Rig::Leg`]); and
//! [`replay`], recorded datasets played through `frictiond` as deployed (`frictl replay`).
//!
//! What it is **not**: no physics (that is [`frictionless_sim`] in the plant process), no friction model
//! evaluation (that is `frictiond`); this process only controls, disturbs and measures.
//!
//! ## Example: the frictiond config of one experiment run, through the daemon's schema
//! ```
//! use std::path::Path;
//! use frictionless::friction::CvParams;
//! use frictionless_shm_types::IpcConfig;
//! use frictionless_experiment::session::{DaemonJoint, FrictionModel, Mode, daemon_config, shipped_kfc};
//!
//! // The virtual knee (gear ratio and k_t from its plant preset) compensated by a fitted CV model.
//! let knee = DaemonJoint {
//!     name: "l_knee".into(),
//!     index: 0,
//!     gear_ratio: -100.0,
//!     kt_nm_per_a: 0.157,
//!     model: FrictionModel::Cv(CvParams { kc: 8.1, ka: 50.84, kv: 5.55 }),
//!     delta_theta_offset_motor_rad: None,
//!     kfc: None, // the shipped config/ankle_knee.toml value
//!     lpf: None,
//! };
//! let ipc = IpcConfig::new(Some(Path::new("/tmp/frictl-run")), "run0");
//! // Pure: builds frictiond-config's typed `RawConfig`, starts nothing.
//! let raw = daemon_config(&ipc, Mode::Lockstep, &[knee], false)?;
//!
//! // What `frictl experiment` writes for frictiond is `toml::to_string` of it, and frictiond's
//! // own validation accepts it.
//! let text = toml::to_string(&raw)?;
//! let cfg = frictiond_config::parse(Path::new("/tmp/frictl-run/frictiond.toml"), &text)?;
//! let j = &cfg.raw.joint[0];
//! assert_eq!(j.kfc, shipped_kfc("l_knee"));
//! assert_eq!(j.kfc, 0.85);
//! assert_eq!(j.friction_model, frictiond_config::ModelKind::Cv);
//! assert_eq!(cfg.raw.loop_.trigger, frictiond_config::Trigger::Lockstep);
//! assert!(matches!(cfg.models[0], frictiond_config::ModelSpec::Cv(p) if p.kc == 8.1));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod controller;
pub mod leg;
pub mod metrics;
pub mod onpolicy;
pub mod oracle;
pub mod replay;
pub mod report;
pub mod rig;
pub mod run;
pub mod search;
pub mod session;
pub mod suite;

use std::path::PathBuf;
use std::time::Duration;

/// Why an experiment, its processes or its reports failed. Messages name the file, service, joint or
/// process and the cause.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// An I/O operation without more context (writing a report line, polling a child).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A plant preset or `--set` override is not acceptable.
    #[error(transparent)]
    Param(#[from] frictionless_sim::params::ParamError),
    /// Opening an iceoryx2 node or service failed.
    #[error(transparent)]
    Shm(#[from] frictionless_shm_types::ShmError),
    /// Receiving from an iceoryx2 port failed.
    #[error(transparent)]
    ShmIo(#[from] frictionless_shm_types::IoError),
    /// Publishing a payload failed.
    #[error("publish {payload}")]
    Publish {
        /// The payload type, e.g. `TorqueRequest`.
        payload: &'static str,
        /// The port's error.
        #[source]
        source: frictionless_shm_types::IoError,
    },
    /// SIGINT / SIGTERM arrived.
    #[error("interrupted")]
    Interrupted,
    /// A K_p search range that is empty or not positive.
    #[error("K_p range [{lo}, {hi}]: need 0 < lo < hi")]
    KpRange {
        /// Lower end.
        lo: f64,
        /// Upper end.
        hi: f64,
    },
    /// The oracle's τ̂_F low-pass cannot be designed.
    #[error("oracle τ̂_F low-pass")]
    OracleLpf(#[source] frictionless::filter::FilterError),
    /// An oracle joint without the plant's `SimTruth`.
    #[error("the oracle needs the plant's SimTruth, and the plant published none")]
    OracleNoTruth,
    /// The oracle's `SimTruth` is not the one of the state it answers.
    #[error("oracle: SimTruth seq {truth_seq} does not match JointStates seq {state_seq}")]
    OracleSeq {
        /// `SimTruth::seq`.
        truth_seq: u64,
        /// `JointStates::seq`.
        state_seq: u64,
    },
    /// The oracle outside lockstep or with the raw friction.
    #[error(
        "the oracle runs in lockstep only, with the shipped law (it pairs each request with the \
         SimTruth of the state it answers)"
    )]
    OracleMode,
    /// A joint index that is not a joint of the plant (0 = knee, 1 = ankle_roll for the single
    /// joints; 0–5 for the leg).
    #[error(
        "joint index {0} is not a joint of the plant (single joints: 0 = knee, 1 = ankle_roll)"
    )]
    JointIndex(usize),
    /// A leg trial that does not plan every joint exactly once.
    #[error("a leg trial plans each of the leg's {0} joints exactly once")]
    LegPlan(usize),
    /// A tested joint name that is not a joint of the leg.
    #[error("`{0}` is not a joint of the leg (config/presets/leg.toml)")]
    LegJoint(String),
    /// A leg model list of the wrong length.
    #[error("leg model `{label}`: {got} models for {expected} leg joints")]
    LegModels {
        /// The model's label.
        label: String,
        /// Models given.
        got: usize,
        /// Joints of the leg.
        expected: usize,
    },
    /// A frictiond config given as a leg compensation does not load.
    #[error("frictiond config {}", .path.display())]
    DaemonConfig {
        /// The config file.
        path: PathBuf,
        /// Why.
        #[source]
        source: Box<frictiond_config::ConfigError>,
    },
    /// A leg compensation config none of whose joints is a joint of the leg (it would compensate
    /// nothing under its label).
    #[error(
        "frictiond config {}: none of its joints ({joints}) is a joint of the leg ({leg}); it would run no compensation",
        .path.display()
    )]
    LegConfigNoJoint {
        /// The config file.
        path: PathBuf,
        /// Its joint names, comma separated.
        joints: String,
        /// The leg's joint names, comma separated.
        leg: String,
    },
    /// A leg compensation config with a model the experiments do not compare.
    #[error("frictiond config {}: joint `{joint}` runs LuGre; the leg experiments compare none, CV, SCV and PINN", .path.display())]
    LegModelKind {
        /// The config file.
        path: PathBuf,
        /// The joint.
        joint: String,
    },
    /// The leg's URDF or dynamics failed.
    #[error(transparent)]
    Leg(#[from] frictionless_sim::LegError),
    /// The controller's rigid-body model failed.
    #[error("whole-leg controller")]
    Dynamics(#[from] frictionless_dynamics::DynamicsError),
    /// A child died during the run.
    #[error("after the run")]
    AfterRun(#[source] Box<ExperimentError>),
    /// The plant stopped publishing.
    #[error(
        "no new JointStates for 10 s after seq {last_seq}; plant log:\n{plant_log}\nfrictiond log:\n{frictiond_log}"
    )]
    NoStates {
        /// The last state seen.
        last_seq: u64,
        /// Last lines of the plant's log.
        plant_log: String,
        /// Last lines of frictiond's log.
        frictiond_log: String,
    },
    /// `std::env::current_exe` failed.
    #[error("cannot find the running executable")]
    CurrentExe(#[source] std::io::Error),
    /// `$FRICTIOND` does not name a file.
    #[error("$FRICTIOND = {} is not a file", .0.display())]
    FrictiondEnv(PathBuf),
    /// No `frictiond` next to `frictl` nor on `PATH`.
    #[error(
        "cannot find the `frictiond` executable (looked next to {} and on PATH; build it with \
         `cargo build -p frictiond` or set FRICTIOND=/path/to/frictiond)",
        .frictl.display()
    )]
    NoFrictiond {
        /// The `frictl` executable.
        frictl: PathBuf,
    },
    /// Cargo could not be started.
    #[error("cannot run {}", .cargo.display())]
    RunCargo {
        /// The cargo executable.
        cargo: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// `cargo build -p frictiond` failed.
    #[error(
        "building frictiond failed ({status}); build it with `cargo build --profile {profile} -p \
         frictiond` or set FRICTIOND=/path/to/frictiond"
    )]
    CargoBuild {
        /// Cargo's exit status.
        status: std::process::ExitStatus,
        /// The cargo profile.
        profile: String,
    },
    /// Cargo succeeded but the binary is not where expected.
    #[error("cargo built frictiond but {} does not exist", .0.display())]
    CargoNoBinary(PathBuf),
    /// The embedded `config/ankle_knee.toml` does not parse.
    #[error("config/ankle_knee.toml does not parse")]
    ShippedConfig(#[source] toml::de::Error),
    /// The embedded `config/ankle_knee.toml` has no such joint.
    #[error("config/ankle_knee.toml: no [[joint]] named `{0}`")]
    ShippedJoint(String),
    /// A PINN model path cannot be made absolute.
    #[error("PINN file {}", .path.display())]
    PinnPath {
        /// The model file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A run's IPC config without a private root path.
    #[error("a run needs its own iceoryx2 root path")]
    NoRootPath,
    /// The frictiond config does not serialise.
    #[error("cannot serialise the frictiond config")]
    SerializeConfig(#[source] toml::ser::Error),
    /// Creating a file or directory failed.
    #[error("cannot create {}", .path.display())]
    Create {
        /// The file or directory.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Writing a file failed.
    #[error("cannot write {}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Drawing a figure failed.
    #[error("plot {}: {reason}", .path.display())]
    Plot {
        /// The PNG file.
        path: PathBuf,
        /// The plotting backend's error.
        reason: String,
    },
    /// Registering a signal handler failed.
    #[error("cannot register signal {sig}")]
    Signal {
        /// The signal number.
        sig: i32,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Creating the run's private directory failed.
    #[error("cannot create run directory {}", .path.display())]
    RunDir {
        /// The directory.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A child process could not be started.
    #[error("cannot start {name} ({program:?})")]
    Spawn {
        /// `plant` or `frictiond`.
        name: &'static str,
        /// The executable.
        program: std::ffi::OsString,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A child process exited.
    #[error("{name} exited ({status}); its log:\n{log}")]
    Exited {
        /// `plant` or `frictiond`.
        name: &'static str,
        /// Its exit status.
        status: std::process::ExitStatus,
        /// Last lines of its log.
        log: String,
    },
    /// A child process did not report ready in time.
    #[error("{name} did not become ready within {timeout:?}; its log:\n{log}")]
    NotReady {
        /// `plant` or `frictiond`.
        name: String,
        /// How long it was given.
        timeout: Duration,
        /// Last lines of its log.
        log: String,
    },
}
