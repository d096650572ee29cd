//! # frictionless-shm-types — the ABI between processes
//!
//! What this crate **is**: the `#[repr(C)]`, [`ZeroCopySend`] iceoryx2 payloads exchanged by `frictiond`,
//! the virtual plant (`frictl sim serve`), `frictl monitor`/`record` and the end-to-end tests, plus
//! the *only* functions that open the corresponding services, so every process agrees on names,
//! payload types and QoS (in iceoryx2 the creator's QoS wins and a mismatch makes `open` fail).
//!
//! - [`JointStates`] plant → daemon, [`TorqueRequest`] controller → daemon (with the `state_seq` it answers),
//!   [`MotorCurrentCommand`] daemon → plant, [`DaemonStatus`] daemon → monitors.
//! - Every pub/sub service `<prefix>/<name>` is paired with an event service of the same name; a
//!   publisher notifies after each send so blocking consumers can wake up ([`Outbox::publish`]).
//! - [`IpcConfig`] (root path + service prefix) isolates tests and deployments from each other.
//! - [`monotonic_ns`]: CLOCK_MONOTONIC in ns, the clock of every `stamp_ns`.
//! - [`Histogram`]: the fixed-bucket (log2 µs) latency histogram carried in [`DaemonStatus`].
//!
//! What it is **not**: no control logic, no threads, no signal handling (nodes are created with
//! [`SignalHandlingMode::Disabled`]; the owning process handles signals itself).
//!
//! Layout rules: fixed capacity [`MAX_JOINTS`] plus a count `n_joints`; joint `j` is element `j` of
//! every per-joint array; masks are `u64` bit sets (bit `j` = joint `j`). Type names are explicit and
//! versioned (`frictionless::JointStates_v1`): change the layout ⇒ bump the version.
//!
//! The drive protocols spoken on a field bus (MIT mode, ODrive CAN Simple, CiA 402) are not here: they live in
//! `frictionless-drives`, beside this crate.
//!
//! ## Example: a status snapshot's latency histogram
//! ```
//! use frictionless_shm_types::{BusCounters, BusKind, CAN_DETAIL_ERROR_PASSIVE, DaemonStatus};
//!
//! let mut status = DaemonStatus::zeroed();
//! status.compute.record(12_000); // 12 µs
//! assert_eq!(status.compute.quantile_upper_ns(0.99), 12_000);
//! // The backend tags its counters; a zeroed status names none.
//! assert_eq!(status.bus.bus_kind(), Some(BusKind::None));
//! status.bus = BusCounters::new(BusKind::Can, 2);
//! status.bus.detail[CAN_DETAIL_ERROR_PASSIVE] = 3;
//! assert_eq!(
//!     status.bus.named_detail().collect::<Vec<_>>(),
//!     [("error_passive", 3), ("emcy", 0)]
//! );
//! ```

#![warn(missing_docs)]

use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::time::Duration;

use iceoryx2::node::NodeState;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe as ps_factory};

pub mod control;
pub mod sim;

/// Compile-time joint capacity of every payload.
pub const MAX_JOINTS: usize = 64;

/// Number of buckets of a [`Histogram`].
pub const HIST_BUCKETS: usize = 32;

/// Per-joint fault flag in [`JointStates::fault_flags`]: the drive reports a hardware fault.
pub const FAULT_DRIVE: u32 = 1 << 0;

/// Per-joint fault flag in [`JointStates::fault_flags`]: the joint's drive sent no feedback within its
/// timeout (set by field-bus backends; the daemon outputs 0 A for that joint only).
pub const FAULT_FEEDBACK_STALE: u32 = 1 << 1;

/// Per-joint flag in [`MotorCurrentCommand::flags`] / [`DaemonStatus::joint_flags`]: the current was
/// clamped to ±max_curr.
pub const FLAG_CURRENT_SATURATED: u32 = 1 << 0;
/// Per-joint flag: the friction estimate was clipped to ±max_output_friction.
pub const FLAG_FRICTION_CLIPPED: u32 = 1 << 1;
/// Per-joint flag: a non-finite value appeared (input or result) and the output was forced to 0 A.
pub const FLAG_NON_FINITE: u32 = 1 << 2;
/// Per-joint flag: inputs were stale and the configured safe output was used.
pub const FLAG_STALE: u32 = 1 << 3;
/// Per-joint flag: the joint is not enabled (output 0 A, not valid).
pub const FLAG_DISABLED: u32 = 1 << 4;
/// Per-joint flag: the plant reported a drive fault for this joint (output 0 A).
pub const FLAG_FAULT: u32 = 1 << 5;
/// Per-joint flag: the friction model is warming up (history not yet full).
pub const FLAG_WARMING_UP: u32 = 1 << 6;
/// Per-joint flag: the newest sample's model inputs lie outside the model's training range (widened
/// by the joint's `ood_margin`); under `ood = "static"` the estimate blends to the static model.
pub const FLAG_OUT_OF_RANGE: u32 = 1 << 7;

/// Daemon-wide flag in [`DaemonStatus::flags`]: the loop runs with SCHED_FIFO.
pub const STATUS_SCHED_FIFO: u32 = 1 << 0;
/// Daemon-wide flag: memory is locked (mlockall).
pub const STATUS_MEMORY_LOCKED: u32 = 1 << 1;
/// Daemon-wide flag: the loop thread is pinned to a CPU.
pub const STATUS_CPU_PINNED: u32 = 1 << 2;
/// Daemon-wide flag: no joint state received yet or state stale.
pub const STATUS_INPUT_STALE: u32 = 1 << 3;
/// Daemon-wide flag: the daemon is stopping and publishes zero currents.
pub const STATUS_STOPPING: u32 = 1 << 4;

/// Joint and motor state of every joint at one instant (plant → daemon, 1 kHz).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::JointStates_v1")]
pub struct JointStates {
    /// Sequence number, +1 per message of one publisher.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] at which the state was sampled.
    pub stamp_ns: u64,
    /// Number of valid joints (≤ [`MAX_JOINTS`]).
    pub n_joints: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Joint position s [rad].
    pub s_rad: [f64; MAX_JOINTS],
    /// Joint velocity ṡ [rad/s].
    pub sdot_rad_s: [f64; MAX_JOINTS],
    /// Motor position θ [motor rad] (motor side, before the gear).
    pub theta_motor_rad: [f64; MAX_JOINTS],
    /// Motor velocity ω_m [motor rad/s].
    pub omega_motor_rad_s: [f64; MAX_JOINTS],
    /// Measured motor current [A].
    pub current_a: [f64; MAX_JOINTS],
    /// Measured (or estimated) joint torque τ_meas [Nm]; NaN when unavailable.
    pub tau_meas_nm: [f64; MAX_JOINTS],
    /// Motor temperature [°C]; NaN when the joint has no sensor.
    pub temperature_c: [f64; MAX_JOINTS],
    /// Fault flags per joint ([`FAULT_DRIVE`], …); 0 = healthy.
    pub fault_flags: [u32; MAX_JOINTS],
}

impl JointStates {
    /// All zeros (temperature NaN = "no sensor", τ_meas NaN = "unavailable").
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            n_joints: 0,
            reserved: 0,
            s_rad: [0.0; MAX_JOINTS],
            sdot_rad_s: [0.0; MAX_JOINTS],
            theta_motor_rad: [0.0; MAX_JOINTS],
            omega_motor_rad_s: [0.0; MAX_JOINTS],
            current_a: [0.0; MAX_JOINTS],
            tau_meas_nm: [f64::NAN; MAX_JOINTS],
            temperature_c: [f64::NAN; MAX_JOINTS],
            fault_flags: [0; MAX_JOINTS],
        }
    }
}

impl Default for JointStates {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// Desired joint torques and which joints the daemon drives (controller → daemon).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::TorqueRequest_v2")]
pub struct TorqueRequest {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] at which the request was made.
    pub stamp_ns: u64,
    /// `seq` of the [`JointStates`] this request was computed from (0 = not tied to a state).
    /// A daemon in lockstep (`[loop] trigger = "lockstep"`) waits for the request answering the
    /// state it is about to process.
    pub state_seq: u64,
    /// Bit `j` set = joint `j` is in torque mode and driven by the daemon ("hijacked").
    pub enable_mask: u64,
    /// Number of valid joints (≤ [`MAX_JOINTS`]).
    pub n_joints: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Desired joint torque τ_des [Nm], joint side.
    pub tau_des_nm: [f64; MAX_JOINTS],
}

impl TorqueRequest {
    /// All zeros, nothing enabled.
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            state_seq: 0,
            enable_mask: 0,
            n_joints: 0,
            reserved: 0,
            tau_des_nm: [0.0; MAX_JOINTS],
        }
    }

    /// Whether joint `j` is enabled (false for `j ≥ 64`).
    #[inline]
    pub fn is_enabled(&self, j: usize) -> bool {
        j < MAX_JOINTS && self.enable_mask & (1u64 << j) != 0
    }
}

impl Default for TorqueRequest {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// Motor current references (daemon → plant/drives).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::MotorCurrentCommand_v2")]
pub struct MotorCurrentCommand {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] at which the command was computed.
    pub stamp_ns: u64,
    /// `stamp_ns` of the [`JointStates`] this command answers (0 when none was received yet).
    pub state_stamp_ns: u64,
    /// `seq` of that [`JointStates`].
    pub state_seq: u64,
    /// Bit `j` set = `i_ref_a[j]` is a valid command for joint `j`.
    pub valid_mask: u64,
    /// Number of joints configured in the daemon.
    pub n_joints: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Motor current reference [A] (already clamped to ±max_curr, finite).
    pub i_ref_a: [f64; MAX_JOINTS],
    /// Per-joint flags ([`FLAG_CURRENT_SATURATED`], …).
    pub flags: [u32; MAX_JOINTS],
    /// The friction estimate the control law was given this tick [Nm]: the model's output (under
    /// `ood = "static"`, blended towards the static model while [`FLAG_OUT_OF_RANGE`]), before kfc,
    /// the friction clip and the filter; also while runtime compensation is off. 0 for a joint that
    /// did not run its model this tick (disabled, stale, fault). `frictl replay` records it.
    pub tau_f_model_nm: [f64; MAX_JOINTS],
}

impl MotorCurrentCommand {
    /// All zeros, nothing valid.
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            state_stamp_ns: 0,
            state_seq: 0,
            valid_mask: 0,
            n_joints: 0,
            reserved: 0,
            i_ref_a: [0.0; MAX_JOINTS],
            flags: [0; MAX_JOINTS],
            tau_f_model_nm: [0.0; MAX_JOINTS],
        }
    }

    /// Whether `i_ref_a[j]` is valid.
    #[inline]
    pub fn is_valid(&self, j: usize) -> bool {
        j < MAX_JOINTS && self.valid_mask & (1u64 << j) != 0
    }
}

impl Default for MotorCurrentCommand {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// Fixed-bucket latency histogram: bucket 0 counts values < 1 µs, bucket `k ≥ 1` counts values in
/// `[2^(k−1), 2^k)` µs, the last bucket everything above. No allocation, O(1) record.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::Histogram_v1")]
pub struct Histogram {
    /// Counts per bucket.
    pub counts: [u64; HIST_BUCKETS],
    /// Number of recorded values.
    pub total: u64,
    /// Largest recorded value [ns].
    pub max_ns: u64,
    /// Sum of recorded values [ns] (saturating), for the mean.
    pub sum_ns: u64,
}

impl Histogram {
    /// An empty histogram.
    pub const fn new() -> Self {
        Self {
            counts: [0; HIST_BUCKETS],
            total: 0,
            max_ns: 0,
            sum_ns: 0,
        }
    }

    /// Bucket index of a value in ns.
    #[inline]
    pub fn bucket_of(ns: u64) -> usize {
        let us = ns / 1000;
        let k = (u64::BITS - us.leading_zeros()) as usize;
        k.min(HIST_BUCKETS - 1)
    }

    /// Upper edge of bucket `k` [ns] (`u64::MAX` for the last).
    pub fn bucket_upper_ns(k: usize) -> u64 {
        if k + 1 >= HIST_BUCKETS {
            u64::MAX
        } else {
            (1u64 << k) * 1000
        }
    }

    /// Records one value [ns].
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.counts[Self::bucket_of(ns)] += 1;
        self.total += 1;
        self.sum_ns = self.sum_ns.saturating_add(ns);
        if ns > self.max_ns {
            self.max_ns = ns;
        }
    }

    /// Upper bound [ns] of the quantile `q` in [0, 1] (the upper edge of the bucket holding it,
    /// capped by the maximum); 0 when empty.
    pub fn quantile_upper_ns(&self, q: f64) -> u64 {
        if self.total == 0 {
            return 0;
        }
        let want = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (k, c) in self.counts.iter().enumerate() {
            acc += c;
            if acc >= want {
                return Self::bucket_upper_ns(k).min(self.max_ns);
            }
        }
        self.max_ns
    }

    /// Mean [ns]; 0 when empty.
    pub fn mean_ns(&self) -> f64 {
        if self.total == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.total as f64
        }
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

/// Daemon health snapshot (daemon → monitors, ≈ 10–100 Hz).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::DaemonStatus_v5")]
pub struct DaemonStatus {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] of the snapshot.
    pub stamp_ns: u64,
    /// Loop ticks since start.
    pub ticks: u64,
    /// Ticks whose wake-up came a whole period or more after its deadline (periods skipped).
    pub missed_deadlines: u64,
    /// Ticks in which joint-state input was stale.
    pub stale_ticks: u64,
    /// Parameter generation: 0 at start, +1 per successful reload (SIGHUP).
    pub generation: u64,
    /// Age [ns] of the newest joint state at the last tick (`u64::MAX` = none yet).
    pub input_age_ns: u64,
    /// Loop period [ns].
    pub period_ns: u64,
    /// Daemon-wide flags ([`STATUS_SCHED_FIFO`], …).
    pub flags: u32,
    /// Number of configured joints.
    pub n_joints: u32,
    /// Wake-up lateness against the absolute deadline.
    pub lateness: Histogram,
    /// Compute time per tick (wake-up to command sent).
    pub compute: Histogram,
    /// Age of the joint state used, at the time it was used.
    pub input_age: Histogram,
    /// Friction estimate τ̂_F [Nm] after clip, kfc and filter, per joint.
    pub tau_f_hat_nm: [f64; MAX_JOINTS],
    /// Last commanded current [A] per joint.
    pub i_ref_a: [f64; MAX_JOINTS],
    /// Per-joint flags of the last tick ([`FLAG_CURRENT_SATURATED`], …).
    pub joint_flags: [u32; MAX_JOINTS],
    /// Model kind per joint: the code of the core's `frictionless::model::ModelKind`
    /// (`ModelKind::code`, `ModelKind::from_code`; 0 = none).
    pub model_kind: [u8; MAX_JOINTS],
    /// I/O-link counters of the backend, summed over its links (filled by the backend).
    pub bus: BusCounters,
    /// Ticks since start in which the joint's model inputs were out of its training range
    /// ([`FLAG_OUT_OF_RANGE`]), per joint.
    pub out_of_range_ticks: [u64; MAX_JOINTS],
    /// Runtime changes (`<prefix>/control` sets) applied by the RT thread since start.
    pub control_applied: u64,
    /// Runtime changes dropped since start because a reload replaced the parameters they were
    /// checked against.
    pub control_dropped: u64,
}

/// Which backend filled a [`BusCounters`] (its `kind` field, [`BusKind::code`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BusKind {
    /// No backend has filled the counters (a zeroed status).
    None = 0,
    /// iceoryx2 shared memory: messages are samples of the daemon's services.
    Shm = 1,
    /// SocketCAN: messages are classic CAN frames.
    Can = 2,
}

/// [`BusCounters::detail`] slot of a CAN backend: error-passive and warning events
/// (`CAN_ERR_CRTL` passive bits).
pub const CAN_DETAIL_ERROR_PASSIVE: usize = 0;
/// [`BusCounters::detail`] slot of a CAN backend: CANopen EMCY messages received (error codes other
/// than "error reset"; CiA 402 drives).
pub const CAN_DETAIL_EMCY: usize = 1;

impl BusKind {
    /// Every kind, in code order.
    pub const ALL: [BusKind; 3] = [BusKind::None, BusKind::Shm, BusKind::Can];

    /// The code carried in [`BusCounters::kind`].
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The kind of a code; `None` for a code no kind has.
    pub fn from_code(code: u32) -> Option<BusKind> {
        Self::ALL.into_iter().find(|k| k.code() == code)
    }

    /// Short name (`"none"`, `"shm"`, `"can"`), as `[backend] kind` spells it.
    pub const fn name(self) -> &'static str {
        match self {
            BusKind::None => "none",
            BusKind::Shm => "shm",
            BusKind::Can => "can",
        }
    }

    /// Names of the used [`BusCounters::detail`] slots of this kind, in slot order (the rest are 0).
    pub const fn detail_names(self) -> &'static [&'static str] {
        match self {
            BusKind::None | BusKind::Shm => &[],
            BusKind::Can => &["error_passive", "emcy"],
        }
    }
}

/// Number of backend-specific [`BusCounters::detail`] slots.
pub const BUS_DETAIL_SLOTS: usize = 4;

/// Health counters of the daemon's I/O links since start, summed over its links; the same fields
/// for every backend (what a "message" and a "link" are depends on [`BusCounters::kind`]), plus
/// backend-specific `detail` slots named by [`BusKind::detail_names`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("frictionless::BusCounters_v2")]
pub struct BusCounters {
    /// [`BusKind::code`] of the backend that filled these (0 = none).
    pub kind: u32,
    /// Number of links summed (CAN buses; 1 for shared memory).
    pub links: u32,
    /// Messages received and accepted (CAN: frames with ids we own; shm: new states and requests).
    pub rx_messages: u64,
    /// Messages sent (CAN: frames; shm: commands and status snapshots).
    pub tx_messages: u64,
    /// Sends dropped without blocking the tick (CAN: queue full, ENOBUFS/EAGAIN; shm: loan failed).
    pub tx_dropped: u64,
    /// Error reports received from the link (CAN: error frames, `CAN_ERR_FLAG`).
    pub error_reports: u64,
    /// Link-down events (CAN: bus-off, `CAN_ERR_BUSOFF`).
    pub link_down: u64,
    /// Other read or write errors.
    pub io_errors: u64,
    /// Joints whose feedback was stale at the last tick (bit set), per the `[safety]` rule.
    pub stale_feedback_mask: u64,
    /// Backend-specific counters; slot `k` is named by `BusKind::detail_names()[k]`.
    pub detail: [u64; BUS_DETAIL_SLOTS],
}

impl BusCounters {
    /// All zeros (kind [`BusKind::None`]).
    pub const fn zeroed() -> Self {
        Self {
            kind: 0,
            links: 0,
            rx_messages: 0,
            tx_messages: 0,
            tx_dropped: 0,
            error_reports: 0,
            link_down: 0,
            io_errors: 0,
            stale_feedback_mask: 0,
            detail: [0; BUS_DETAIL_SLOTS],
        }
    }

    /// Zeros, tagged with `kind` and `links`.
    pub const fn new(kind: BusKind, links: u32) -> Self {
        let mut c = Self::zeroed();
        c.kind = kind.code();
        c.links = links;
        c
    }

    /// The kind of backend that filled these (`None` for an unknown code).
    pub fn bus_kind(&self) -> Option<BusKind> {
        BusKind::from_code(self.kind)
    }

    /// The used detail slots with their names.
    pub fn named_detail(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        let names = self.bus_kind().map_or(&[][..], BusKind::detail_names);
        names.iter().copied().zip(self.detail)
    }
}

impl DaemonStatus {
    /// All zeros.
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            ticks: 0,
            missed_deadlines: 0,
            stale_ticks: 0,
            generation: 0,
            input_age_ns: u64::MAX,
            period_ns: 0,
            flags: 0,
            n_joints: 0,
            lateness: Histogram::new(),
            compute: Histogram::new(),
            input_age: Histogram::new(),
            tau_f_hat_nm: [0.0; MAX_JOINTS],
            i_ref_a: [0.0; MAX_JOINTS],
            joint_flags: [0; MAX_JOINTS],
            model_kind: [0; MAX_JOINTS],
            bus: BusCounters::zeroed(),
            out_of_range_ticks: [0; MAX_JOINTS],
            control_applied: 0,
            control_dropped: 0,
        }
    }
}

impl Default for DaemonStatus {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// CLOCK_MONOTONIC now [ns] (the clock of every `stamp_ns`). Never allocates.
#[inline]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `deadline_ns` (the clock of [`monotonic_ns`]),
/// retrying on EINTR: `clock_nanosleep` with `TIMER_ABSTIME`, so a late wake-up never shifts later
/// deadlines. Returns at once when the deadline has passed. Never allocates.
#[inline]
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as _,
        tv_nsec: (deadline_ns % 1_000_000_000) as _,
    };
    // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be null with TIMER_ABSTIME.
    while unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    } == libc::EINTR
    {}
}

/// Why opening or using an IPC resource failed. Messages name the service and the cause.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// A name (service, node, path) is not acceptable to iceoryx2.
    #[error("invalid {what} `{value}`: {reason}")]
    InvalidName {
        /// Which kind of name.
        what: &'static str,
        /// The offending value.
        value: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// An iceoryx2 operation failed.
    #[error("iceoryx2: {op} `{service}` failed: {reason}")]
    Ipc {
        /// The operation, e.g. "open pub/sub service".
        op: &'static str,
        /// The service name (or node name).
        service: String,
        /// iceoryx2's error.
        reason: String,
    },
}

/// Where and under which names the services live. Each deployment / test uses its own.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IpcConfig {
    /// iceoryx2 root directory for node/service files; `None` = iceoryx2's default (system temp dir).
    pub root_path: Option<PathBuf>,
    /// Service name prefix, e.g. `frictionless` → `frictionless/joint_states`.
    pub service_prefix: String,
}

impl Default for IpcConfig {
    fn default() -> Self {
        Self {
            root_path: None,
            service_prefix: "frictionless".to_owned(),
        }
    }
}

/// The four services. `name()` is the suffix after `<prefix>/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind {
    /// [`JointStates`].
    JointStates,
    /// [`TorqueRequest`].
    TorqueRequest,
    /// [`MotorCurrentCommand`].
    MotorCurrentCommand,
    /// [`DaemonStatus`].
    DaemonStatus,
    /// [`sim::SimTruth`] (virtual plant diagnostics).
    SimTruth,
    /// [`sim::SimDisturbance`] (external torques into the virtual plant).
    SimDisturbance,
}

impl ServiceKind {
    /// The service-name suffix.
    pub fn name(self) -> &'static str {
        match self {
            Self::JointStates => "joint_states",
            Self::TorqueRequest => "torque_request",
            Self::MotorCurrentCommand => "motor_current_command",
            Self::DaemonStatus => "daemon_status",
            Self::SimTruth => "sim_truth",
            Self::SimDisturbance => "sim_disturbance",
        }
    }
}

/// Longest service prefix in bytes: iceoryx2 0.10 refuses service names longer than
/// `iceoryx2::constants::MAX_SERVICE_NAME_LENGTH` (255 bytes, `ServiceNameError::ExceedsMaximumLength`),
/// and the longest name built from a prefix is `<prefix>/motor_current_command` (22 bytes after it).
pub const MAX_SERVICE_PREFIX_BYTES: usize =
    iceoryx2::constants::MAX_SERVICE_NAME_LENGTH - "/motor_current_command".len();

impl IpcConfig {
    /// A config with the given root path and prefix.
    pub fn new(root_path: Option<&Path>, service_prefix: &str) -> Self {
        Self {
            root_path: root_path.map(Path::to_path_buf),
            service_prefix: service_prefix.to_owned(),
        }
    }

    /// Full service name `<prefix>/<suffix>`.
    pub fn service_name(&self, kind: ServiceKind) -> String {
        format!("{}/{}", self.service_prefix, kind.name())
    }

    /// The iceoryx2 [`Config`] for this deployment (defaults with the root path set).
    pub fn iceoryx_config(&self) -> Result<Config, ShmError> {
        let mut c = Config::default();
        if let Some(root) = &self.root_path {
            let s = root.to_string_lossy();
            let p =
                iceoryx2::prelude::Path::new(s.as_bytes()).map_err(|e| ShmError::InvalidName {
                    what: "iceoryx2 root path",
                    value: s.to_string(),
                    reason: format!("{e:?}"),
                })?;
            c.global.set_root_path(&p);
        }
        Ok(c)
    }
}

/// Max publishers per service (one live writer plus one being replaced after a crash).
pub const MAX_PUBLISHERS: usize = 2;
/// Max subscribers per service (daemon or plant, monitor, recorder, a test).
pub const MAX_SUBSCRIBERS: usize = 6;
/// Max nodes per service.
pub const MAX_NODES: usize = 16;

/// A process's connection to the services: one iceoryx2 node (signal handling disabled).
///
/// `ipc::Service` ports are `!Send`: create the [`Ipc`] in the thread that uses its ports.
pub struct Ipc {
    node: Node<ipc::Service>,
    config: IpcConfig,
}

impl Debug for Ipc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ipc")
            .field("node", self.node.name())
            .field("config", &self.config)
            .finish()
    }
}

/// A pub/sub service with its paired event service.
pub struct Channel<T: Debug + ZeroCopySend + 'static> {
    name: String,
    pubsub: ps_factory::PortFactory<ipc::Service, T, ()>,
    event: event_factory::PortFactory<ipc::Service>,
}

/// Sending side: a publisher plus a notifier on the paired event service.
pub struct Outbox<T: Debug + ZeroCopySend + 'static> {
    name: String,
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
}

/// Receiving side: a subscriber (latest value) plus a listener on the paired event service.
pub struct Inbox<T: Debug + ZeroCopySend + 'static> {
    name: String,
    subscriber: Subscriber<ipc::Service, T, ()>,
    listener: Listener<ipc::Service>,
}

fn ipc_err(op: &'static str, service: &str, e: impl Debug) -> ShmError {
    ShmError::Ipc {
        op,
        service: service.to_owned(),
        reason: format!("{e:?}"),
    }
}

impl Ipc {
    /// Creates a node named `node_name` (signal handling disabled) for `config`.
    pub fn open(config: &IpcConfig, node_name: &str) -> Result<Self, ShmError> {
        let c = config.iceoryx_config()?;
        let name = NodeName::new(node_name).map_err(|e| ShmError::InvalidName {
            what: "node name",
            value: node_name.to_owned(),
            reason: format!("{e:?}"),
        })?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&c)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| ipc_err("create node", node_name, e))?;
        Ok(Self {
            node,
            config: config.clone(),
        })
    }

    /// The configuration this node was opened with.
    pub fn config(&self) -> &IpcConfig {
        &self.config
    }

    /// Removes resources of dead nodes (crashed processes) under this root path. Returns
    /// (cleaned, failed) counts.
    pub fn cleanup_dead_nodes(&self) -> (u64, u64) {
        let s = self.node.try_cleanup_dead_nodes();
        (s.cleanups, s.failed_cleanups)
    }

    /// Removes resources of dead nodes under `config`'s root path without creating a node.
    pub fn cleanup_dead_nodes_for(config: &IpcConfig) -> Result<usize, ShmError> {
        let c = config.iceoryx_config()?;
        let mut n = 0;
        Node::<ipc::Service>::list(&c, |state| {
            if let NodeState::Dead(view) = state
                && view.try_remove_stale_resources().is_ok()
            {
                n += 1;
            }
            CallbackProgression::Continue
        })
        .map_err(|e| ipc_err("list nodes", "<all>", e))?;
        Ok(n)
    }

    fn channel<T: Debug + ZeroCopySend + 'static>(
        &self,
        kind: ServiceKind,
    ) -> Result<Channel<T>, ShmError> {
        let name = self.config.service_name(kind);
        let sn = ServiceName::new(&name).map_err(|e| ShmError::InvalidName {
            what: "service name",
            value: name.clone(),
            reason: format!("{e:?}"),
        })?;
        let pubsub = self
            .node
            .service_builder(&sn)
            .publish_subscribe::<T>()
            .history_size(1)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(true)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| ipc_err("open pub/sub service", &name, e))?;
        let event = self
            .node
            .service_builder(&sn)
            .event()
            .max_notifiers(MAX_NODES)
            .max_listeners(MAX_NODES)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| ipc_err("open event service", &name, e))?;
        Ok(Channel {
            name,
            pubsub,
            event,
        })
    }

    /// `<prefix>/joint_states`.
    pub fn joint_states(&self) -> Result<Channel<JointStates>, ShmError> {
        self.channel(ServiceKind::JointStates)
    }

    /// `<prefix>/torque_request`.
    pub fn torque_request(&self) -> Result<Channel<TorqueRequest>, ShmError> {
        self.channel(ServiceKind::TorqueRequest)
    }

    /// `<prefix>/motor_current_command`.
    pub fn motor_current_command(&self) -> Result<Channel<MotorCurrentCommand>, ShmError> {
        self.channel(ServiceKind::MotorCurrentCommand)
    }

    /// `<prefix>/daemon_status`.
    pub fn daemon_status(&self) -> Result<Channel<DaemonStatus>, ShmError> {
        self.channel(ServiceKind::DaemonStatus)
    }

    /// `<prefix>/sim_truth` (virtual plant only).
    pub fn sim_truth(&self) -> Result<Channel<sim::SimTruth>, ShmError> {
        self.channel(ServiceKind::SimTruth)
    }

    /// `<prefix>/sim_disturbance` (virtual plant only).
    pub fn sim_disturbance(&self) -> Result<Channel<sim::SimDisturbance>, ShmError> {
        self.channel(ServiceKind::SimDisturbance)
    }
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Channel<T> {
    /// Full service name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Number of subscribers currently connected.
    pub fn subscriber_count(&self) -> usize {
        self.pubsub.dynamic_config().number_of_subscribers()
    }

    /// Number of publishers currently connected.
    pub fn publisher_count(&self) -> usize {
        self.pubsub.dynamic_config().number_of_publishers()
    }

    /// A publisher + notifier.
    pub fn outbox(&self) -> Result<Outbox<T>, ShmError> {
        let publisher = self
            .pubsub
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| ipc_err("create publisher", &self.name, e))?;
        let notifier = self
            .event
            .notifier_builder()
            .create()
            .map_err(|e| ipc_err("create notifier", &self.name, e))?;
        Ok(Outbox {
            name: self.name.clone(),
            publisher,
            notifier,
        })
    }

    /// A subscriber + listener.
    pub fn inbox(&self) -> Result<Inbox<T>, ShmError> {
        let subscriber = self
            .pubsub
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| ipc_err("create subscriber", &self.name, e))?;
        let listener = self
            .event
            .listener_builder()
            .create()
            .map_err(|e| ipc_err("create listener", &self.name, e))?;
        Ok(Inbox {
            name: self.name.clone(),
            subscriber,
            listener,
        })
    }
}

/// Error of a send or receive on the hot path. Carries no heap data (RT-safe to construct).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IoError {
    /// Loaning a sample failed (all loaned or segment exhausted).
    #[error("loan failed")]
    Loan,
    /// Sending failed.
    #[error("send failed")]
    Send,
    /// Notifying failed.
    #[error("notify failed")]
    Notify,
    /// Receiving failed.
    #[error("receive failed")]
    Receive,
    /// Waiting on the listener failed.
    #[error("wait failed")]
    Wait,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Outbox<T> {
    /// Service name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Copies `value` into a loaned shared-memory sample, sends it and notifies listeners.
    ///
    /// Note (measured): iceoryx2 0.10's loan allocates one 48-byte `Box` per sample (freed at send).
    pub fn publish(&self, value: &T) -> Result<(), IoError> {
        let sample = self.publisher.loan_uninit().map_err(|_| IoError::Loan)?;
        sample
            .write_payload(*value)
            .send()
            .map_err(|_| IoError::Send)?;
        self.notifier.notify().map_err(|_| IoError::Notify)?;
        Ok(())
    }

    /// Loans a sample, initialises it with `T::default()`, lets `fill` modify it in place, sends
    /// and notifies.
    pub fn publish_with(&self, fill: impl FnOnce(&mut T)) -> Result<(), IoError>
    where
        T: Default,
    {
        let sample = self.publisher.loan_uninit().map_err(|_| IoError::Loan)?;
        // Initialise first so `fill` gets a valid `&mut T`; T is Copy and a few KB at most.
        let mut sample = sample.write_payload(T::default());
        fill(sample.payload_mut());
        sample.send().map_err(|_| IoError::Send)?;
        self.notifier.notify().map_err(|_| IoError::Notify)?;
        Ok(())
    }
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Inbox<T> {
    /// Service name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Drains everything received and returns the newest value, if any arrived since the last call.
    /// Never allocates, never blocks.
    pub fn latest(&self) -> Result<Option<T>, IoError> {
        let mut newest = None;
        while let Some(s) = self.subscriber.receive().map_err(|_| IoError::Receive)? {
            newest = Some(*s.payload());
        }
        Ok(newest)
    }

    /// Waits up to `timeout` for a notification (returns immediately when one is pending), then
    /// drains all pending notifications. Returns whether any arrived.
    pub fn wait(&self, timeout: Duration) -> Result<bool, IoError> {
        let mut got = false;
        self.listener
            .timed_wait(|_| got = true, timeout)
            .map_err(|_| IoError::Wait)?;
        Ok(got)
    }

    /// Waits (up to `timeout` in total) until a value arrives and returns the newest.
    pub fn wait_latest(&self, timeout: Duration) -> Result<Option<T>, IoError> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(v) = self.latest()? {
                return Ok(Some(v));
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            // Poll at ≤ 5 ms so a missed notification never stalls a consumer.
            self.wait((deadline - now).min(Duration::from_millis(5)))?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_kinds_round_trip_their_codes_and_fit_their_detail_slots() {
        for k in BusKind::ALL {
            assert_eq!(BusKind::from_code(k.code()), Some(k));
            assert!(k.detail_names().len() <= BUS_DETAIL_SLOTS, "{k:?}");
        }
        assert_eq!(BusKind::from_code(99), None);
        assert_eq!(BusCounters::zeroed().bus_kind(), Some(BusKind::None));
        assert_eq!(
            BusKind::Can.detail_names()[CAN_DETAIL_ERROR_PASSIVE],
            "error_passive"
        );
    }

    #[test]
    fn daemon_status_layout_ends_with_the_out_of_range_and_control_counters() {
        use std::mem::{align_of, offset_of, size_of};
        let at = offset_of!(DaemonStatus, out_of_range_ticks);
        assert_eq!(at, offset_of!(DaemonStatus, bus) + size_of::<BusCounters>());
        assert_eq!(at % align_of::<u64>(), 0);
        let control = offset_of!(DaemonStatus, control_applied);
        assert_eq!(control, at + 8 * MAX_JOINTS);
        assert_eq!(offset_of!(DaemonStatus, control_dropped), control + 8);
        assert_eq!(size_of::<DaemonStatus>(), control + 16);
    }

    fn unique_config(tag: &str) -> IpcConfig {
        let id = format!(
            "fl_shm_{tag}_{}_{}",
            std::process::id(),
            monotonic_ns() % 1_000_000_000
        );
        let root = std::env::temp_dir().join(&id);
        std::fs::create_dir_all(&root).unwrap();
        IpcConfig::new(Some(&root), &id)
    }

    /// Sends `value` from one node and receives it in another; returns what arrived.
    fn round_trip<T: Debug + ZeroCopySend + Copy + 'static>(
        cfg: &IpcConfig,
        open: fn(&Ipc) -> Result<Channel<T>, ShmError>,
        value: T,
    ) -> T {
        let a = Ipc::open(cfg, "sender").unwrap();
        let b = Ipc::open(cfg, "receiver").unwrap();
        let tx = open(&a).unwrap().outbox().unwrap();
        let ch_b = open(&b).unwrap();
        let rx = ch_b.inbox().unwrap();
        assert_eq!(ch_b.subscriber_count(), 1);
        assert!(rx.latest().unwrap().is_none(), "nothing sent yet");
        tx.publish(&value).unwrap();
        assert!(
            rx.wait(Duration::from_secs(2)).unwrap(),
            "notification arrives"
        );
        let got = rx.latest().unwrap().expect("sample arrives");
        assert!(rx.latest().unwrap().is_none(), "latest() drains");
        got
    }

    #[test]
    fn every_payload_round_trips_between_two_nodes() {
        let cfg = unique_config("rt");
        let mut js = JointStates::zeroed();
        js.seq = 7;
        js.stamp_ns = monotonic_ns();
        js.n_joints = 3;
        js.s_rad[2] = -0.25;
        js.omega_motor_rad_s[63] = 1e3;
        js.fault_flags[1] = FAULT_DRIVE;
        let got = round_trip(&cfg, Ipc::joint_states, js);
        assert_eq!((got.seq, got.stamp_ns, got.n_joints), (7, js.stamp_ns, 3));
        assert_eq!(got.s_rad[2], -0.25);
        assert_eq!(got.omega_motor_rad_s[63], 1e3);
        assert_eq!(got.fault_flags[1], FAULT_DRIVE);
        assert!(got.temperature_c[0].is_nan());

        let mut tr = TorqueRequest::zeroed();
        tr.enable_mask = 0b101;
        tr.tau_des_nm[2] = 3.5;
        let got = round_trip(&cfg, Ipc::torque_request, tr);
        assert!(got.is_enabled(0) && !got.is_enabled(1) && got.is_enabled(2));
        assert!(!got.is_enabled(64));
        assert_eq!(got.tau_des_nm[2], 3.5);

        let mut mc = MotorCurrentCommand::zeroed();
        mc.valid_mask = 1 << 63;
        mc.i_ref_a[63] = -2.0;
        mc.state_stamp_ns = 99;
        let got = round_trip(&cfg, Ipc::motor_current_command, mc);
        assert!(got.is_valid(63) && !got.is_valid(0));
        assert_eq!((got.i_ref_a[63], got.state_stamp_ns), (-2.0, 99));

        let mut ds = DaemonStatus::zeroed();
        ds.lateness.record(12_345);
        ds.model_kind[5] = 4;
        ds.tau_f_hat_nm[5] = 0.5;
        ds.out_of_range_ticks[63] = 42;
        ds.bus = BusCounters::new(BusKind::Can, 2);
        ds.bus.link_down = 1;
        ds.bus.detail[CAN_DETAIL_ERROR_PASSIVE] = 9;
        let got = round_trip(&cfg, Ipc::daemon_status, ds);
        assert_eq!(got.bus, ds.bus);
        assert_eq!((got.bus.bus_kind(), got.bus.links), (Some(BusKind::Can), 2));
        assert_eq!(got.out_of_range_ticks[63], 42);
        assert_eq!(got.lateness.total, 1);
        assert_eq!(got.lateness.max_ns, 12_345);
        assert_eq!(got.model_kind[5], 4);
        assert_eq!(got.tau_f_hat_nm[5], 0.5);
        let _ = std::fs::remove_dir_all(cfg.root_path.unwrap());
    }

    #[test]
    fn latest_value_semantics_keep_only_the_newest() {
        let cfg = unique_config("lv");
        let a = Ipc::open(&cfg, "a").unwrap();
        let ch = a.torque_request().unwrap();
        let tx = ch.outbox().unwrap();
        let rx = ch.inbox().unwrap();
        for k in 1..=5u64 {
            let mut t = TorqueRequest::zeroed();
            t.seq = k;
            tx.publish(&t).unwrap();
        }
        assert_eq!(rx.latest().unwrap().map(|t| t.seq), Some(5));
        assert_eq!(rx.latest().unwrap().map(|t| t.seq), None);
        drop((tx, rx, ch, a));
        let _ = std::fs::remove_dir_all(cfg.root_path.unwrap());
    }

    #[test]
    fn services_are_isolated_by_prefix() {
        let c1 = unique_config("iso1");
        let c2 = IpcConfig::new(
            c1.root_path.as_deref(),
            &format!("{}_other", c1.service_prefix),
        );
        let a = Ipc::open(&c1, "a").unwrap();
        let b = Ipc::open(&c2, "b").unwrap();
        let tx = a.joint_states().unwrap().outbox().unwrap();
        let rx = b.joint_states().unwrap().inbox().unwrap();
        tx.publish(&JointStates::zeroed()).unwrap();
        assert!(rx.latest().unwrap().is_none());
        drop((tx, rx, a, b));
        let _ = std::fs::remove_dir_all(c1.root_path.unwrap());
    }

    #[test]
    fn histogram_buckets_and_quantiles() {
        assert_eq!(Histogram::bucket_of(0), 0);
        assert_eq!(Histogram::bucket_of(999), 0);
        assert_eq!(Histogram::bucket_of(1_000), 1);
        assert_eq!(Histogram::bucket_of(1_999), 1);
        assert_eq!(Histogram::bucket_of(2_000), 2);
        assert_eq!(Histogram::bucket_of(u64::MAX), HIST_BUCKETS - 1);
        let mut h = Histogram::new();
        assert_eq!(h.quantile_upper_ns(0.99), 0);
        for _ in 0..99 {
            h.record(500);
        }
        h.record(50_000);
        assert_eq!(h.total, 100);
        assert_eq!(h.max_ns, 50_000);
        // 99 % of values are < 1 µs: bucket 0's upper edge.
        assert_eq!(h.quantile_upper_ns(0.99), 1_000);
        // The max lands in [32, 64) µs, capped by max.
        assert_eq!(h.quantile_upper_ns(1.0), 50_000);
        assert!((h.mean_ns() - (99.0 * 500.0 + 50_000.0) / 100.0).abs() < 1e-9);
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        std::thread::sleep(Duration::from_millis(2));
        let b = monotonic_ns();
        assert!(b > a + 1_000_000, "{a} → {b}");
    }

    #[test]
    fn max_service_prefix_fits_every_service_name() {
        let kinds = [
            ServiceKind::JointStates,
            ServiceKind::TorqueRequest,
            ServiceKind::MotorCurrentCommand,
            ServiceKind::DaemonStatus,
            ServiceKind::SimTruth,
            ServiceKind::SimDisturbance,
        ];
        let cfg = IpcConfig::new(None, &"p".repeat(MAX_SERVICE_PREFIX_BYTES));
        for k in kinds {
            let name = cfg.service_name(k);
            assert!(
                iceoryx2::prelude::ServiceName::new(&name).is_ok(),
                "{} bytes",
                name.len()
            );
        }
        let cfg = IpcConfig::new(None, &"p".repeat(MAX_SERVICE_PREFIX_BYTES + 1));
        let name = cfg.service_name(ServiceKind::MotorCurrentCommand);
        assert!(iceoryx2::prelude::ServiceName::new(&name).is_err());
    }

    #[test]
    fn bad_service_prefix_is_an_error_naming_it() {
        let cfg = unique_config("bad");
        let a = Ipc::open(&cfg, "a").unwrap();
        let bad = IpcConfig::new(cfg.root_path.as_deref(), "");
        let b = Ipc::open(&bad, "b").unwrap();
        drop(a);
        // "/joint_states" may be valid for iceoryx2; a NUL byte is not.
        let bad = IpcConfig::new(cfg.root_path.as_deref(), "x\0y");
        let c = Ipc::open(&bad, "c").unwrap();
        match c.joint_states() {
            Err(e) => assert!(e.to_string().contains("x\0y/joint_states"), "{e}"),
            Ok(_) => panic!("NUL in a service name must be refused"),
        }
        drop((b, c));
        let _ = std::fs::remove_dir_all(cfg.root_path.unwrap());
    }
}
