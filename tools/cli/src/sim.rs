//! Arguments of `frictl sim`.

use frictionless_plant::can::Protocol;
use std::path::PathBuf;

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
    /// Serve the joints as a plant process (iceoryx2 or SocketCAN) for frictiond and experiments.
    ///
    /// `--backend shm`: publishes `<prefix>/joint_states` and `<prefix>/sim_truth` (same seq),
    /// applies the newest `<prefix>/motor_current_command` (joint j gets i_ref_a[j] when bit j of
    /// valid_mask is set, else 0 A; a command is held for --command-timeout-ms, then 0 A) and the
    /// newest `<prefix>/sim_disturbance` (external joint torque, held until replaced). Joint j of
    /// every payload is the j-th name of --preset. JointStates carries the emulated sensors
    /// (quantised encoders, noisy current, temperature or NaN) and as s_dot the same causal
    /// filtered encoder-difference velocity frictl acquire uses (cut-off
    /// protocol.velocity_filter_hz); tau_meas_nm is NaN. seq starts at 1 at simulated time 0.
    ///
    /// Real time (default): 1 kHz on absolute CLOCK_MONOTONIC deadlines. --lockstep: no sleeping;
    /// after publishing state k the plant waits for the command with state_seq = k (up to
    /// --lockstep-timeout-ms, then a warning and the hold/zero rule in simulated time), steps 1 ms
    /// and publishes k+1; before state 1 it waits for a command publisher and
    /// --lockstep-subscribers joint-state subscribers.
    ///
    /// Prints "ready" on stderr once the services are open and a one-line summary at exit
    /// (SIGINT/SIGTERM or --duration-s). Removes dead iceoryx2 nodes under the root at start.
    ///
    /// `--backend can`: the joints answer as motor drives on --bus (MIT, ODrive or CiA 402 protocol,
    /// node ids --node-ids).
    Serve(Box<ServeArgs>),
}

/// Transport of `frictl sim serve`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// iceoryx2 shared memory (`frictionless-shm-types` services).
    Shm,
    /// SocketCAN motor drives.
    Can,
}

/// Arguments of `frictl sim serve`.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Comma-separated presets or preset files, one joint each: joint j = the j-th name
    /// (e.g. `knee,ankle_roll`: knee = 0, ankle_roll = 1); or `leg` alone: the six joints of the
    /// ergoCub left leg coupled through one rigid-body model (config/presets/leg.toml), joint j =
    /// the leg's j-th joint (l_hip_pitch … l_ankle_roll), `--set l_knee:plant.KEY=VALUE`.
    #[arg(long, default_value = "knee,ankle_roll")]
    pub preset: String,
    /// TOML file deep-merged over every preset (same layout).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Override one parameter of every preset, e.g. `--set plant.sigma0_nm_per_rad=3e4`, or of one
    /// joint: `--set ankle_roll:plant.t0_min_c=30`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Seed; joint j uses seed + j (initial temperature, current noise).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Transport.
    #[arg(long, value_enum, default_value_t = Backend::Shm)]
    pub backend: Backend,
    /// shm: service-name prefix (`<prefix>/joint_states`, …).
    #[arg(long, default_value = "frictionless")]
    pub prefix: String,
    /// shm: iceoryx2 root directory; default: iceoryx2's.
    #[arg(long)]
    pub root_path: Option<PathBuf>,
    /// shm: advance one 1 ms tick per answering command instead of running in real time.
    #[arg(long)]
    pub lockstep: bool,
    /// shm, lockstep: wait this long for the command answering a state [ms].
    #[arg(long, default_value_t = 1000)]
    pub lockstep_timeout_ms: u64,
    /// shm, lockstep: joint-state subscribers to wait for before publishing state 1.
    #[arg(long, default_value_t = 1)]
    pub lockstep_subscribers: usize,
    /// Hold a command at most this long, then 0 A [ms] (simulated ms in lockstep).
    #[arg(long, default_value_t = 20)]
    pub command_timeout_ms: u64,
    /// Stop after this much simulated time [s] (default: until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Initial joint angles [rad], one per joint, comma-separated (at rest, gravity held by the
    /// flexspline); default: each preset's plant.initial_s_rad.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub initial_pose_rad: Vec<f64>,
    /// can: SocketCAN interface.
    #[arg(long, default_value = "vcan0")]
    pub bus: String,
    /// can: motor protocol.
    #[arg(
        long,
        value_parser = crate::stage::named::<Protocol>(Protocol::NAMES),
        default_value_t = Protocol::Mit
    )]
    pub protocol: Protocol,
    /// can: node id per joint, comma-separated (default 1, 2, …).
    #[arg(long, value_delimiter = ',')]
    pub node_ids: Vec<u8>,
}
