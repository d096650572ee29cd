//! `frictl sim` — the virtual harmonic-drive joints.
//!
//! `frictl sim run`: an offline open-loop run of a preset with a current profile, logged as CSV (the
//! same columns as `frictl acquire`, truth included). `frictl sim params`: print the merged parameters.
//! `frictl sim serve`: the joints as a plant process — over iceoryx2 (`--backend shm`, real time or
//! lockstep, [`frictionless_plant::shm`]) or as motor drives on SocketCAN (`--backend can`,
//! [`frictionless_plant::can`]).

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use frictionless_acquire::log::CsvLog;
use frictionless_acquire::protocol::{LogRow, Mode};
use frictionless_sim::params::{check_set_joints, load_table};
use frictionless_sim::profile::CurrentProfile;
use frictionless_sim::{Plant, PlantParams};

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
    /// `--backend can`: the joints answer as motor drives on --bus (MIT or ODrive protocol,
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
    #[arg(long, value_enum, default_value_t = frictionless_plant::can::Protocol::Mit)]
    pub protocol: frictionless_plant::can::Protocol,
    /// can: node id per joint, comma-separated (default 1, 2, …).
    #[arg(long, value_delimiter = ',')]
    pub node_ids: Vec<u8>,
}

/// Runs `frictl sim`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Params { params } => {
            check_set_joints(&params.sets, &[params.preset.as_str()])?;
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            // Validate before printing, so a bad override fails here too.
            PlantParams::from_table(&table)?;
            frictionless_acquire::ProtocolConfig::from_table(&table)?;
            print!("{}", toml::to_string_pretty(&table)?);
            Ok(())
        }
        SimCommand::Serve(a) => serve(*a),
        SimCommand::Run {
            params,
            current_profile,
            duration_s,
            tau_ext_nm,
            seed,
            out,
        } => {
            anyhow::ensure!(
                duration_s.is_finite() && duration_s > 0.0,
                "--duration-s must be a positive number, got {duration_s}"
            );
            anyhow::ensure!(tau_ext_nm.is_finite(), "--tau-ext-nm must be finite");
            check_set_joints(&params.sets, &[params.preset.as_str()])?;
            let table = load_table(&params.preset, params.params.as_deref(), &params.sets)?;
            let p = PlantParams::from_table(&table)?;
            let period_s = p.sample_period_s();
            let profile = CurrentProfile::parse(&current_profile, period_s)?;
            let mut plant = Plant::from_params(p, seed)?;
            let file = frictionless::output_file::AtomicFile::create(&out)
                .with_context(|| format!("cannot create {}", out.display()))?;
            let mut log = CsvLog::new(file, true)?;
            let n = (duration_s / period_s).round() as u64;
            let bar = if std::io::stderr().is_terminal() {
                indicatif::ProgressBar::new(n)
            } else {
                indicatif::ProgressBar::hidden()
            };
            for k in 0..n {
                let meas = plant.measurement();
                let i_ref = profile.current_a(meas.time_s);
                log.write(&LogRow {
                    chunk: 0,
                    active: true,
                    mode: Mode::Current,
                    meas,
                    i_ref_a: i_ref,
                    truth: Some(plant.truth()),
                })?;
                plant.step(i_ref, tau_ext_nm);
                if k % 10_000 == 0 {
                    bar.set_position(k);
                }
            }
            bar.finish_and_clear();
            log.finish()?
                .commit()
                .with_context(|| format!("cannot write {}", out.display()))?;
            eprintln!("frictl sim run: {n} samples -> {}", out.display());
            Ok(())
        }
    }
}

/// `frictl sim serve`.
fn serve(a: ServeArgs) -> anyhow::Result<()> {
    let stop = frictionless_plant::install_stop_flag()?;
    let mut robot =
        frictionless_plant::build_robot(&a.preset, a.params.as_deref(), &a.sets, a.seed)?;
    match a.backend {
        Backend::Shm => {
            // The reported velocity uses each preset's protocol.velocity_filter_hz, like acquire
            // (the leg's joints: the presets' common default).
            let mut velocity_filter_hz = Vec::with_capacity(robot.len());
            for k in 0..robot.len() {
                velocity_filter_hz.push(if robot.is_leg() {
                    frictionless_plant::shm::DEFAULT_VELOCITY_FILTER_HZ
                } else {
                    let table = load_table(robot.name(k), a.params.as_deref(), &a.sets)?;
                    frictionless_acquire::ProtocolConfig::from_table(&table)?.velocity_filter_hz
                });
            }
            let opts = frictionless_plant::shm::ShmServeOptions {
                ipc: frictionless_shm_types::IpcConfig::new(a.root_path.as_deref(), &a.prefix),
                lockstep: a.lockstep,
                lockstep_timeout_ms: a.lockstep_timeout_ms,
                lockstep_min_subscribers: a.lockstep_subscribers,
                command_timeout_ms: a.command_timeout_ms,
                duration_s: a.duration_s,
                initial_pose_rad: a.initial_pose_rad,
                velocity_filter_hz,
            };
            frictionless_plant::shm::run(&mut robot, &opts, stop)?;
            Ok(())
        }
        Backend::Can => {
            anyhow::ensure!(
                !a.lockstep,
                "--lockstep is a shared-memory mode; --backend can runs in real time"
            );
            if !a.initial_pose_rad.is_empty() {
                robot.reset_at_rest(&a.initial_pose_rad)?;
            }
            serve_can(&mut robot, &a, stop)
        }
    }
}

/// `frictl sim serve --backend can`: [`frictionless_plant::can::run`].
fn serve_can(
    robot: &mut frictionless_plant::ServedRobot,
    a: &ServeArgs,
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<()> {
    let opts = frictionless_plant::can::CanServeOptions {
        bus: a.bus.clone(),
        protocol: a.protocol,
        node_ids: a.node_ids.clone(),
        command_timeout_ms: a.command_timeout_ms,
        duration_s: a.duration_s,
    };
    Ok(frictionless_plant::can::run(robot, &opts, stop)?)
}
