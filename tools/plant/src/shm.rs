//! `frictl sim serve --backend shm`: the virtual joints as a plant process over iceoryx2, and the
//! matching live client used by `frictl acquire --live-shm`.
//!
//! What this module **is**:
//! - [`run`]: the plant side. Every 1 ms tick it applies the newest [`MotorCurrentCommand`] (joint
//!   `j` gets `i_ref_a[j]` when bit `j` of `valid_mask` is set, else 0 A like an idle drive; a
//!   command is held for `command_timeout_ms`, then every joint gets 0 A) and the newest
//!   [`SimDisturbance`] (`tau_ext_nm[j]` as external joint torque, held until replaced), steps
//!   the physics 1 ms and publishes [`JointStates`] and [`SimTruth`] with the same `seq`.
//!   Two clocks (see the preamble's lockstep protocol):
//!   - *real time*: absolute 1 kHz CLOCK_MONOTONIC deadlines (`clock_nanosleep` with
//!     `TIMER_ABSTIME`, as `frictiond` does); late wake-ups skip whole periods (counted, no catch-up
//!     burst); the hold timeout is measured in wall time;
//!   - *lockstep*: no sleeping; after publishing state `k` the plant waits (up to
//!     `lockstep_timeout_ms`) for the command with `state_seq == k`, then steps. On timeout it logs a
//!     warning and applies the hold/zero rule with the timeout measured in simulated ticks.
//!     Before the first state it waits until a command publisher and `lockstep_min_subscribers`
//!     joint-state subscribers are connected, so nobody misses state 1 (clients must open their
//!     `JointStates` inbox *before* their `MotorCurrentCommand` outbox, as `frictiond` does).
//! - [`LiveJoint`]: the controller side of one joint as an [`frictionless_acquire::JointIo`]: it answers
//!   each received state with a command carrying `state_seq`, then waits for the next state. The
//!   same code works against a real-time or a lockstep plant.
//!
//! Published fields: `s_rad`, `theta_motor_rad`, `omega_motor_rad_s`, `current_a`,
//! `temperature_c` are the plant's emulated sensors ([`frictionless_sim::Measurement`]: quantised
//! encoders, noisy current, NaN temperature without a sensor). `sdot_rad_s` is what a drive reports:
//! the causal [`VelocityEstimator`] of `frictl acquire` (filtered joint-encoder difference, cut-off
//! `protocol.velocity_filter_hz` of the preset) — never the true velocity. `tau_meas_nm` is NaN (no
//! joint torque sensor). `seq` starts at 1 (the initial state, simulated time 0) and grows by one per
//! simulated millisecond.
//!
//! What it is **not**: no physics ([`frictionless_sim`]), no control law, no signal handling (the caller
//! passes a stop flag; see [`super::install_stop_flag`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use frictionless_shm_types::sim::{SimDisturbance, SimTruth};
use frictionless_shm_types::{
    Channel, Inbox, Ipc, IpcConfig, JointStates, MAX_JOINTS, MotorCurrentCommand, Outbox,
    monotonic_ns,
};

use super::{ServeError, ServedRobot};
use frictionless_acquire::leg::LegIo;
use frictionless_acquire::protocol::{AcquireError, JointIo, VelocityEstimator};
use frictionless_sim::{Measurement, Truth};

/// Cut-off of the reported joint velocity when no per-joint value is given [Hz] (the presets' value).
pub const DEFAULT_VELOCITY_FILTER_HZ: f64 = 100.0;

/// iceoryx2 node name of the plant process.
pub const PLANT_NODE_NAME: &str = "frictl_sim_serve";

/// iceoryx2 node name of the live acquisition client.
pub const ACQUIRE_NODE_NAME: &str = "frictl_acquire";

/// Options of the shared-memory plant.
#[derive(Clone, Debug)]
pub struct ShmServeOptions {
    /// iceoryx2 root path and service prefix.
    pub ipc: IpcConfig,
    /// Lockstep (one tick per command, no sleeping) instead of real time.
    pub lockstep: bool,
    /// Lockstep: how long to wait for the command answering a state [ms].
    pub lockstep_timeout_ms: u64,
    /// Lockstep: joint-state subscribers to wait for before publishing the first state.
    pub lockstep_min_subscribers: usize,
    /// A command is applied for at most this long after it arrived, then 0 A [ms] (wall time in
    /// real time, simulated time in lockstep).
    pub command_timeout_ms: u64,
    /// Stop after this much simulated time [s] (`None` = until the stop flag).
    pub duration_s: Option<f64>,
    /// Initial joint angles [rad] per joint (at rest, flexspline wound to hold gravity); empty =
    /// each preset's `initial_s_rad`.
    pub initial_pose_rad: Vec<f64>,
    /// Cut-off of the reported joint velocity per joint [Hz]; missing entries use
    /// [`DEFAULT_VELOCITY_FILTER_HZ`].
    pub velocity_filter_hz: Vec<f64>,
}

impl ShmServeOptions {
    /// Real-time defaults for `ipc`: command timeout 20 ms, lockstep timeout 1000 ms, one subscriber.
    pub fn new(ipc: IpcConfig) -> Self {
        Self {
            ipc,
            lockstep: false,
            lockstep_timeout_ms: 1000,
            lockstep_min_subscribers: 1,
            command_timeout_ms: 20,
            duration_s: None,
            initial_pose_rad: Vec::new(),
            velocity_filter_hz: Vec::new(),
        }
    }
}

/// What a plant run did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ServeSummary {
    /// Physics ticks (1 ms each) stepped.
    pub ticks: u64,
    /// Commands taken in (the newest of each poll; any `state_seq`).
    pub commands_received: u64,
    /// Ticks without a fresh command: lockstep — the answer to the state timed out; real time — no
    /// new command arrived since the previous tick.
    pub commands_missed: u64,
    /// Ticks in which the hold timeout (or no command at all) forced 0 A on every joint.
    pub zero_current_ticks: u64,
    /// Real time: deadlines missed (whole periods skipped).
    pub missed_deadlines: u64,
    /// Wall-clock duration of the loop [s].
    pub wall_s: f64,
}

impl ServeSummary {
    /// Simulated time [s].
    pub fn sim_time_s(&self) -> f64 {
        self.ticks as f64 * 1e-3
    }

    /// Ticks per wall-clock second.
    pub fn ticks_per_s(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.ticks as f64 / self.wall_s
        } else {
            0.0
        }
    }
}

impl std::fmt::Display for ServeSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ticks ({:.3} s simulated) in {:.3} s wall ({:.0} ticks/s); {} commands received, \
             {} ticks without a fresh command, {} ticks at 0 A by timeout, {} missed deadlines",
            self.ticks,
            self.sim_time_s(),
            self.wall_s,
            self.ticks_per_s(),
            self.commands_received,
            self.commands_missed,
            self.zero_current_ticks,
            self.missed_deadlines
        )
    }
}

/// Control period of the served plant [s]; every preset samples at 1 kHz.
const PERIOD_S: f64 = 1e-3;
const PERIOD_NS: u64 = 1_000_000;

/// The plant's ports.
struct PlantPorts {
    states_ch: Channel<JointStates>,
    states: Outbox<JointStates>,
    truth: Outbox<SimTruth>,
    commands_ch: Channel<MotorCurrentCommand>,
    commands: Inbox<MotorCurrentCommand>,
    disturbance: Inbox<SimDisturbance>,
}

/// Per-joint loop state.
struct JointLoop {
    vel: VelocityEstimator,
    meas: Measurement,
    truth: Truth,
    i_applied_a: f64,
    tau_ext_nm: f64,
}

/// Runs the plant over shared memory until `stop` is set or `opts.duration_s` of simulated time
/// has passed. Prints "ready" to stderr once the services are open and a one-line summary at exit.
pub fn run(
    robot: &mut ServedRobot,
    opts: &ShmServeOptions,
    stop: &AtomicBool,
) -> Result<ServeSummary, ServeError> {
    if robot.is_empty() {
        return Err(ServeError::NoJoints);
    }
    if robot.len() > MAX_JOINTS {
        return Err(ServeError::TooManyJoints {
            n: robot.len(),
            max: MAX_JOINTS,
        });
    }
    if let Some(d) = opts.duration_s
        && !(d.is_finite() && d >= 0.0)
    {
        return Err(ServeError::ShmDuration(d));
    }
    for index in 0..robot.len() {
        let p = robot.params(index).sample_period_s();
        if (p - PERIOD_S).abs() >= 1e-12 || p.is_nan() {
            return Err(ServeError::SamplePeriod {
                index,
                joint: robot.name(index).to_owned(),
                period_s: p,
            });
        }
    }
    if !opts.initial_pose_rad.is_empty() {
        robot.reset_at_rest(&opts.initial_pose_rad)?;
    }

    // Clean up what crashed processes left under this root, then open our node and ports. The
    // command inbox is created before the state outbox so a client never sees states without us
    // listening to its answers.
    let cleaned = Ipc::cleanup_dead_nodes_for(&opts.ipc).unwrap_or(0);
    if cleaned > 0 {
        eprintln!("frictl sim serve: removed {cleaned} dead iceoryx2 node(s)");
    }
    let ipc = Ipc::open(&opts.ipc, PLANT_NODE_NAME).map_err(ServeError::OpenNode)?;
    let commands_ch = ipc.motor_current_command()?;
    let commands = commands_ch.inbox()?;
    let disturbance = ipc.sim_disturbance()?.inbox()?;
    let states_ch = ipc.joint_states()?;
    let states = states_ch.outbox()?;
    let truth = ipc.sim_truth()?.outbox()?;
    let ports = PlantPorts {
        states_ch,
        states,
        truth,
        commands_ch,
        commands,
        disturbance,
    };
    eprintln!(
        "frictl sim serve: ready ({} joint(s){} on `{}/…`, {})",
        robot.len(),
        if robot.is_leg() {
            " coupled through the leg"
        } else {
            ""
        },
        opts.ipc.service_prefix,
        if opts.lockstep {
            "lockstep"
        } else {
            "real time"
        }
    );

    let mut loops: Vec<JointLoop> = (0..robot.len())
        .map(|k| {
            let meas = robot.measurement(k);
            let f_c = opts
                .velocity_filter_hz
                .get(k)
                .copied()
                .unwrap_or(DEFAULT_VELOCITY_FILTER_HZ);
            JointLoop {
                vel: VelocityEstimator::new(f_c, PERIOD_S, meas.s_rad),
                meas,
                truth: robot.truth(k),
                i_applied_a: 0.0,
                tau_ext_nm: 0.0,
            }
        })
        .collect();

    if opts.lockstep && !wait_for_peers(&ports, opts.lockstep_min_subscribers, stop) {
        return Ok(ServeSummary::default());
    }
    let summary = serve_loop(robot, &mut loops, &ports, opts, stop)?;
    eprintln!("frictl sim serve: {summary}");
    Ok(summary)
}

/// Lockstep: waits until a command publisher and `min_subscribers` state subscribers exist.
/// Returns false when stopped first.
fn wait_for_peers(ports: &PlantPorts, min_subscribers: usize, stop: &AtomicBool) -> bool {
    let mut said = false;
    let t0 = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if ports.commands_ch.publisher_count() >= 1
            && ports.states_ch.subscriber_count() >= min_subscribers
        {
            return true;
        }
        if !said && t0.elapsed() > Duration::from_secs(2) {
            eprintln!(
                "frictl sim serve: lockstep: waiting for a `{}` publisher and {min_subscribers} \
                 `{}` subscriber(s)",
                ports.commands_ch.name(),
                ports.states_ch.name()
            );
            said = true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    false
}

/// The newest command and when it arrived (ns in real time, tick in lockstep).
struct HeldCommand {
    cmd: Option<MotorCurrentCommand>,
    at: u64,
}

fn io_err(what: &'static str, source: frictionless_shm_types::IoError) -> ServeError {
    ServeError::Io { what, source }
}

fn serve_loop(
    robot: &mut ServedRobot,
    loops: &mut [JointLoop],
    ports: &PlantPorts,
    opts: &ShmServeOptions,
    stop: &AtomicBool,
) -> Result<ServeSummary, ServeError> {
    let max_ticks = opts
        .duration_s
        .map(|d| (d / PERIOD_S).round() as u64)
        .unwrap_or(u64::MAX);
    let mut summary = ServeSummary::default();
    let mut held = HeldCommand { cmd: None, at: 0 };
    let timeout_ns = opts.command_timeout_ms.saturating_mul(1_000_000);
    let mut seq = 1u64;
    // The step's inputs, one per joint (allocated once, before the loop).
    let mut i_ref_a = vec![0.0; loops.len()];
    let mut tau_ext_nm = vec![0.0; loops.len()];
    let started = Instant::now();
    publish(loops, ports, seq)?;
    let mut deadline = monotonic_ns() + PERIOD_NS;

    while summary.ticks < max_ticks && !stop.load(Ordering::Relaxed) {
        // 1. the command for this tick
        let Some(fresh) =
            receive_command(ports, opts, seq, deadline, stop, &mut summary, &mut held)?
        else {
            break;
        };
        if !fresh {
            summary.commands_missed += 1;
        }
        let expired = if opts.lockstep {
            summary.ticks.saturating_sub(held.at) >= opts.command_timeout_ms
        } else {
            monotonic_ns().saturating_sub(held.at) > timeout_ns
        };
        let cmd = match (held.cmd, expired && !fresh) {
            (Some(c), false) => Some(c),
            _ => None,
        };
        if cmd.is_none() {
            summary.zero_current_ticks += 1;
        }
        // 2. disturbance (newest, held)
        take_disturbance(ports, loops)?;
        // 3. physics: every joint at once
        step_joints(robot, loops, cmd, &mut i_ref_a, &mut tau_ext_nm)?;
        summary.ticks += 1;
        seq += 1;
        // 4. publish
        publish(loops, ports, seq)?;
        if !opts.lockstep {
            deadline += PERIOD_NS;
            let now = monotonic_ns();
            if now >= deadline {
                let skipped = (now - deadline) / PERIOD_NS + 1;
                summary.missed_deadlines += skipped;
                deadline += skipped * PERIOD_NS;
            }
        }
    }
    summary.wall_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// Step 1 of a tick: takes this tick's command into `held` (lockstep: the answer to state `seq`,
/// waited for; real time: the newest, at `deadline`). `Some(fresh)`: whether one came; `None`:
/// stopped while waiting.
fn receive_command(
    ports: &PlantPorts,
    opts: &ShmServeOptions,
    seq: u64,
    deadline: u64,
    stop: &AtomicBool,
    summary: &mut ServeSummary,
    held: &mut HeldCommand,
) -> Result<Option<bool>, ServeError> {
    let lockstep_timeout = Duration::from_millis(opts.lockstep_timeout_ms);
    Ok(Some(if opts.lockstep {
        match wait_answer(ports, seq, lockstep_timeout, stop, summary)? {
            Some(c) => {
                *held = HeldCommand {
                    cmd: Some(c),
                    at: summary.ticks,
                };
                true
            }
            None if stop.load(Ordering::Relaxed) => return Ok(None),
            None => {
                if summary.commands_missed < 5 || summary.commands_missed.is_multiple_of(1000) {
                    eprintln!(
                        "frictl sim serve: warning: lockstep: no command for state {seq} \
                         within {} ms; holding the last one up to {} ms, then 0 A",
                        opts.lockstep_timeout_ms, opts.command_timeout_ms
                    );
                }
                false
            }
        }
    } else {
        frictionless_shm_types::sleep_until_ns(deadline);
        match ports
            .commands
            .latest()
            .map_err(|e| io_err("receiving commands", e))?
        {
            Some(c) => {
                summary.commands_received += 1;
                *held = HeldCommand {
                    cmd: Some(c),
                    at: monotonic_ns(),
                };
                true
            }
            None => false,
        }
    }))
}

/// Step 2 of a tick: the newest disturbance, if one came, is held by every joint (a non-finite
/// or missing value as 0).
fn take_disturbance(ports: &PlantPorts, loops: &mut [JointLoop]) -> Result<(), ServeError> {
    if let Some(d) = ports
        .disturbance
        .latest()
        .map_err(|e| io_err("receiving disturbances", e))?
    {
        for (j, l) in loops.iter_mut().enumerate() {
            let tau = if j < d.n_joints as usize {
                d.tau_ext_nm[j]
            } else {
                0.0
            };
            l.tau_ext_nm = if tau.is_finite() { tau } else { 0.0 };
        }
    }
    Ok(())
}

/// Step 3 of a tick: every joint's current (the command's, clamped to ±i_max; else 0 A) and
/// disturbance into the step's inputs `i_ref_a`, `tau_ext_nm`; one physics step; the joints'
/// new measurements.
fn step_joints(
    robot: &mut ServedRobot,
    loops: &mut [JointLoop],
    cmd: Option<MotorCurrentCommand>,
    i_ref_a: &mut [f64],
    tau_ext_nm: &mut [f64],
) -> Result<(), ServeError> {
    for (j, l) in loops.iter_mut().enumerate() {
        let i_ref = match cmd {
            Some(c) if c.is_valid(j) && c.i_ref_a[j].is_finite() => c.i_ref_a[j],
            _ => 0.0,
        };
        let i_max = robot.params(j).i_max_a;
        l.i_applied_a = i_ref.clamp(-i_max, i_max);
        i_ref_a[j] = l.i_applied_a;
        tau_ext_nm[j] = l.tau_ext_nm;
    }
    robot.step(i_ref_a, tau_ext_nm)?;
    for (j, l) in loops.iter_mut().enumerate() {
        l.meas = robot.measurement(j);
        l.truth = robot.truth(j);
        l.vel.update(l.meas.s_rad);
    }
    Ok(())
}

/// Lockstep: waits for the command answering state `seq`. Older answers are counted and dropped.
fn wait_answer(
    ports: &PlantPorts,
    seq: u64,
    timeout: Duration,
    stop: &AtomicBool,
    summary: &mut ServeSummary,
) -> Result<Option<MotorCurrentCommand>, ServeError> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(c) = ports
            .commands
            .latest()
            .map_err(|e| io_err("receiving commands", e))?
        {
            summary.commands_received += 1;
            if c.state_seq >= seq {
                return Ok(Some(c));
            }
        }
        let now = Instant::now();
        if now >= deadline || stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        // Bounded waits so the stop flag is seen within 20 ms. A failed wait is a signal
        // interrupting it (EINTR; SIGTERM sets the stop flag): retry after a short pause.
        if ports
            .commands
            .wait((deadline - now).min(Duration::from_millis(20)))
            .is_err()
        {
            std::thread::sleep(Duration::from_micros(100));
        }
    }
}

fn publish(loops: &[JointLoop], ports: &PlantPorts, seq: u64) -> Result<(), ServeError> {
    let n = loops.len();
    let stamp = monotonic_ns();
    ports
        .states
        .publish_with(|s: &mut JointStates| {
            s.seq = seq;
            s.stamp_ns = stamp;
            s.n_joints = n as u32;
            for (j, l) in loops.iter().enumerate() {
                s.s_rad[j] = l.meas.s_rad;
                s.sdot_rad_s[j] = l.vel.velocity_rad_s();
                s.theta_motor_rad[j] = l.meas.theta_motor_rad;
                s.omega_motor_rad_s[j] = l.meas.omega_motor_rad_s;
                s.current_a[j] = l.meas.i_meas_a;
                s.tau_meas_nm[j] = f64::NAN;
                s.temperature_c[j] = l.meas.temperature_c;
                s.fault_flags[j] = 0;
            }
        })
        .map_err(|e| io_err("publishing joint states", e))?;
    ports
        .truth
        .publish_with(|t: &mut SimTruth| {
            t.seq = seq;
            t.stamp_ns = stamp;
            t.sim_time_s = loops.first().map_or(0.0, |l| l.meas.time_s);
            t.n_joints = n as u32;
            for (j, l) in loops.iter().enumerate() {
                t.tau_f_true_nm[j] = l.truth.tau_f_nm;
                t.tau_ext_nm[j] = l.tau_ext_nm;
                t.s_true_rad[j] = l.truth.state.s_rad;
                t.sdot_true_rad_s[j] = l.truth.state.s_dot_rad_s;
                t.current_true_a[j] = l.truth.state.i_a;
                t.i_applied_a[j] = l.i_applied_a;
                t.phi_ddot_rad_s2[j] = l.truth.phi_ddot_rad_s2;
            }
        })
        .map_err(|e| io_err("publishing sim truth", e))?;
    Ok(())
}

/// Why the live client stopped or failed.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// No joint state arrived in time.
    #[error(
        "no `{service}` state within {timeout_ms} ms (is `frictl sim serve` running on this prefix?)"
    )]
    NoState {
        /// The state service.
        service: String,
        /// The timeout [ms].
        timeout_ms: u64,
    },
    /// The plant publishes fewer joints than the chosen index.
    #[error("--joint-index {index}: the plant on `{service}` publishes {n_joints} joint(s)")]
    JointIndex {
        /// The requested joint.
        index: usize,
        /// The state service.
        service: String,
        /// Joints in the received state.
        n_joints: u32,
    },
    /// The stop flag was set (SIGINT/SIGTERM).
    #[error("stopped by a signal")]
    Stopped,
    /// An iceoryx2 send or receive failed.
    #[error("{what} on `{service}` failed: {why}")]
    Io {
        /// The operation.
        what: &'static str,
        /// The service.
        service: String,
        /// iceoryx2's error.
        why: String,
    },
}

/// One joint of a plant over shared memory, driven in current mode by this process: the
/// acquisition side of `frictl acquire --live-shm`. It plays the daemon's role (publishes
/// [`MotorCurrentCommand`] with only this joint's bit valid: the plant gives every other joint
/// 0 A), so `frictiond` must not run on the same prefix.
///
/// Each [`JointIo::exchange`] publishes the command answering the newest state (`state_seq`,
/// `state_stamp_ns`) and waits for a newer state. [`Measurement::time_s`] is
/// `(seq − first seq) · period`: the plant's simulated time when the first state seen is seq 1.
pub struct LiveJoint<'a> {
    states: Inbox<JointStates>,
    commands: Outbox<MotorCurrentCommand>,
    // Dropped last: the node owns the ports' resources.
    ipc: Ipc,
    joint_index: usize,
    period_s: f64,
    state_timeout: Duration,
    stop: &'a AtomicBool,
    last: JointStates,
    first_seq: u64,
    meas: Measurement,
    cmd_seq: u64,
    /// States received.
    pub states_received: u64,
    /// States skipped (gaps in `seq`, e.g. a slow client against a real-time plant).
    pub states_skipped: u64,
    /// Whether a `SimTruth` publisher was connected at start (the plant is a simulator).
    pub plant_publishes_sim_truth: bool,
}

impl<'a> LiveJoint<'a> {
    /// Connects to the services of `cfg` and waits up to `connect_timeout` for the first state.
    /// `state_timeout` bounds every later wait for the next state.
    pub fn connect(
        cfg: &IpcConfig,
        joint_index: usize,
        period_s: f64,
        connect_timeout: Duration,
        state_timeout: Duration,
        stop: &'a AtomicBool,
    ) -> Result<Self, ServeError> {
        if joint_index >= MAX_JOINTS {
            return Err(ServeError::JointIndexRange {
                index: joint_index,
                max: MAX_JOINTS - 1,
            });
        }
        let _ = Ipc::cleanup_dead_nodes_for(cfg);
        let ipc = Ipc::open(cfg, ACQUIRE_NODE_NAME).map_err(ServeError::OpenNode)?;
        // Inbox before outbox: a lockstep plant starts once it sees our command publisher.
        let states = ipc.joint_states()?.inbox()?;
        let commands = ipc.motor_current_command()?.outbox()?;
        let mut me = Self {
            states,
            commands,
            ipc,
            joint_index,
            period_s,
            state_timeout,
            stop,
            last: JointStates::zeroed(),
            first_seq: 0,
            meas: Measurement {
                time_s: 0.0,
                s_rad: 0.0,
                theta_motor_rad: 0.0,
                omega_motor_rad_s: 0.0,
                i_meas_a: 0.0,
                temperature_c: f64::NAN,
            },
            cmd_seq: 0,
            states_received: 0,
            states_skipped: 0,
            plant_publishes_sim_truth: false,
        };
        let first = me.next_state(0, connect_timeout)?;
        if joint_index >= first.n_joints as usize {
            return Err(LiveError::JointIndex {
                index: joint_index,
                service: me.states.name().to_owned(),
                n_joints: first.n_joints,
            }
            .into());
        }
        me.first_seq = first.seq;
        me.accept(first);
        me.plant_publishes_sim_truth = me.ipc.sim_truth()?.publisher_count() > 0;
        Ok(me)
    }

    /// Waits for a state with `seq > after`.
    fn next_state(&mut self, after: u64, timeout: Duration) -> Result<JointStates, LiveError> {
        let deadline = Instant::now() + timeout;
        let io =
            |what: &'static str, name: &str, e: frictionless_shm_types::IoError| LiveError::Io {
                what,
                service: name.to_owned(),
                why: e.to_string(),
            };
        loop {
            if let Some(s) = self
                .states
                .latest()
                .map_err(|e| io("receive", self.states.name(), e))?
                && s.seq > after
            {
                return Ok(s);
            }
            if self.stop.load(Ordering::Relaxed) {
                return Err(LiveError::Stopped);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(LiveError::NoState {
                    service: self.states.name().to_owned(),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            // A failed wait is a signal interrupting it (EINTR): the loop re-checks the stop flag.
            if self
                .states
                .wait((deadline - now).min(Duration::from_millis(20)))
                .is_err()
            {
                std::thread::sleep(Duration::from_micros(100));
            }
        }
    }

    fn accept(&mut self, s: JointStates) {
        let j = self.joint_index;
        if self.states_received > 0 {
            self.states_skipped += s.seq.saturating_sub(self.last.seq + 1);
        }
        self.states_received += 1;
        self.meas = Measurement {
            time_s: (s.seq - self.first_seq) as f64 * self.period_s,
            s_rad: s.s_rad[j],
            theta_motor_rad: s.theta_motor_rad[j],
            omega_motor_rad_s: s.omega_motor_rad_s[j],
            i_meas_a: s.current_a[j],
            temperature_c: s.temperature_c[j],
        };
        self.last = s;
    }

    /// Publishes a command for this joint answering the newest state.
    fn send(&mut self, i_ref_a: f64) -> Result<(), LiveError> {
        self.cmd_seq += 1;
        let (j, last) = (self.joint_index, &self.last);
        let seq = self.cmd_seq;
        self.commands
            .publish_with(|c: &mut MotorCurrentCommand| {
                c.seq = seq;
                c.stamp_ns = monotonic_ns();
                c.state_stamp_ns = last.stamp_ns;
                c.state_seq = last.seq;
                c.valid_mask = 1u64 << j;
                c.n_joints = last.n_joints;
                c.i_ref_a[j] = i_ref_a;
            })
            .map_err(|e| LiveError::Io {
                what: "publish",
                service: self.commands.name().to_owned(),
                why: e.to_string(),
            })
    }

    /// Publishes a command answering the newest state with `i_ref_a[k]` for joints 0, 1, … (each
    /// bit valid): the whole robot driven by this process.
    fn send_all(&mut self, i_ref_a: &[f64]) -> Result<(), LiveError> {
        self.cmd_seq += 1;
        let last = &self.last;
        let seq = self.cmd_seq;
        self.commands
            .publish_with(|c: &mut MotorCurrentCommand| {
                c.seq = seq;
                c.stamp_ns = monotonic_ns();
                c.state_stamp_ns = last.stamp_ns;
                c.state_seq = last.seq;
                c.valid_mask = 0;
                c.n_joints = last.n_joints;
                for (j, &i) in i_ref_a.iter().enumerate().take(MAX_JOINTS) {
                    c.valid_mask |= 1u64 << j;
                    c.i_ref_a[j] = i;
                }
            })
            .map_err(|e| LiveError::Io {
                what: "publish",
                service: self.commands.name().to_owned(),
                why: e.to_string(),
            })
    }

    /// Sends 0 A to the first `n` joints (answering the newest state): call when a whole-robot
    /// run is done or aborting.
    pub fn release_all(&mut self, n: usize) -> Result<(), ServeError> {
        self.send_all(&vec![0.0; n.min(MAX_JOINTS)])?;
        Ok(())
    }

    /// Joints in the newest state.
    pub fn n_joints(&self) -> usize {
        self.last.n_joints as usize
    }

    /// Sends 0 A for this joint (answering the newest state): call when done or aborting.
    pub fn release(&mut self) -> Result<(), ServeError> {
        self.send(0.0)?;
        Ok(())
    }

    /// `seq` of the first state (time 0).
    pub fn first_seq(&self) -> u64 {
        self.first_seq
    }

    /// The newest raw state.
    pub fn last_state(&self) -> &JointStates {
        &self.last
    }
}

impl JointIo for LiveJoint<'_> {
    fn measurement(&self) -> Measurement {
        self.meas
    }

    fn exchange(&mut self, i_ref_a: f64) -> Result<Measurement, AcquireError> {
        let fail = |t: f64, e: LiveError| AcquireError::Io {
            time_s: t,
            why: e.to_string(),
        };
        let t = self.meas.time_s;
        self.send(i_ref_a).map_err(|e| fail(t, e))?;
        let s = self
            .next_state(self.last.seq, self.state_timeout)
            .map_err(|e| fail(t, e))?;
        self.accept(s);
        Ok(self.meas)
    }

    fn truth(&self) -> Option<Truth> {
        None
    }
}

/// The whole robot of the plant, driven by this process: joint k of every payload (`frictl
/// acquire --preset leg --live-shm`). [`LegIo::exchange`] publishes one command with every
/// joint's current (all bits valid) answering the newest state and waits for the next state; the
/// measurements' time is that of [`LiveJoint`].
impl LegIo for LiveJoint<'_> {
    fn measurement(&self, k: usize) -> Measurement {
        let s = &self.last;
        Measurement {
            time_s: self.meas.time_s,
            s_rad: s.s_rad[k],
            theta_motor_rad: s.theta_motor_rad[k],
            omega_motor_rad_s: s.omega_motor_rad_s[k],
            i_meas_a: s.current_a[k],
            temperature_c: s.temperature_c[k],
        }
    }

    fn truth(&self, _k: usize) -> Option<Truth> {
        None
    }

    fn exchange(&mut self, i_ref_a: &[f64]) -> Result<(), AcquireError> {
        let t = self.meas.time_s;
        let fail = |e: LiveError| AcquireError::Io {
            time_s: t,
            why: e.to_string(),
        };
        self.send_all(i_ref_a).map_err(fail)?;
        let s = self
            .next_state(self.last.seq, self.state_timeout)
            .map_err(fail)?;
        self.accept(s);
        Ok(())
    }
}
