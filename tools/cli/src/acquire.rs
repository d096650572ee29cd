//! Arguments of `frictl acquire`.

use std::path::PathBuf;

/// Which sensors the log holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Sensor {
    /// The robot's log for `frictl preprocess`: joint and motor encoders, current (ergoCub).
    MotorEncoder,
    /// A torque-sensed arm's log for `frictl import csv`: q, dq, current, joint torque sensor
    /// (`[plant.torque_sensor]`), no motor encoder; plus the true friction.
    Torque,
}

/// Arguments of `frictl acquire`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Built-in preset (`knee`, `ankle_roll`) or a preset TOML file (tables `plant` and `protocol`);
    /// or `leg`: every joint of the coupled ergoCub left leg excited at once, each with the knee's
    /// protocol scaled to the joint (`--set protocol.KEY=VALUE` changes the protocol of every
    /// joint, `--set l_knee:plant.KEY=VALUE` one joint's drive), one log with every joint's
    /// columns; with `--live-shm` every joint of a `frictl sim serve --preset leg` plant is driven
    /// at once (all bits valid in each command).
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
    /// Base name of the files (default `<joint>_seed<seed>`, live `<joint>_live`): NAME.csv and
    /// NAME.json.
    #[arg(long)]
    pub name: Option<String>,
    /// Acquire live from a plant over iceoryx2 shared memory (e.g. `frictl sim serve`) instead of
    /// the offline simulator. This process drives the joint's current directly, as on the robot:
    /// it publishes `<prefix>/motor_current_command` (only --joint-index valid; the plant gives
    /// other joints 0 A) answering each `<prefix>/joint_states` sample with its seq, so frictiond
    /// must NOT run on the same prefix. Works against a real-time (1 kHz) or a --lockstep plant.
    /// --preset still supplies the protocol and the controllers' nominal model (signed r, k_t,
    /// J_eq, link, i_max). The CSV has no truth columns; the sidecar says `source = "live-shm"`.
    #[arg(long)]
    pub live_shm: bool,
    /// Live: service-name prefix.
    #[arg(long, default_value = "frictionless")]
    pub prefix: String,
    /// Live: iceoryx2 root directory; default: iceoryx2's.
    #[arg(long)]
    pub root_path: Option<PathBuf>,
    /// Live: payload index of the joint to excite (the j-th preset of `frictl sim serve --preset`).
    #[arg(long, default_value_t = 0)]
    pub joint_index: usize,
    /// Live: wait this long for the first joint state [s].
    #[arg(long, default_value_t = 10.0)]
    pub connect_timeout_s: f64,
    /// Live: fail if the next joint state does not arrive within this time [ms].
    #[arg(long, default_value_t = 1000)]
    pub state_timeout_ms: u64,
    /// The sensors logged (`torque`: offline only).
    #[arg(long, value_enum, default_value_t = Sensor::MotorEncoder, conflicts_with = "live_shm")]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub sensor: Sensor,
    /// `--sensor torque`: log period [ms], a whole number of plant samples (e.g. 2 for a 500 Hz log).
    #[arg(long, default_value_t = 1.0)]
    pub log_period_ms: f64,
    /// `--sensor torque`: timestamp jitter, uniform in ±this [ms] (below half the log period).
    #[arg(long, default_value_t = 0.0)]
    pub jitter_ms: f64,
}
