//! `frictl sim serve --backend can`: the virtual joints answer as motor drives on a SocketCAN bus.
//!
//! What this module **is**:
//! - [`Drive`]: one emulated drive (socket-free, so it is unit-testable): the protocol state machine,
//!   the command timeout, the drive's own torque law and the frames it sends.
//!   - **MIT** (bgkatz mini-cheetah / CubeMars AK "MIT mode"): standard id = node id; special frames
//!     enter/exit motor mode and zero the position; a command (p, v, kp, kd, t_ff) makes the drive
//!     apply τ_m = kp·(p − p_m) + kd·(v − v_m) + t_ff **on the motor side** (p, v motor side in rad,
//!     rad/s; current i = τ_m/k_t). Every decodable frame to the drive is answered at once with a reply
//!     on host id [`MIT_HOST_ID`] carrying the state *before* the new command is applied (as the
//!     firmware does from its RX interrupt): motor id, p_m [rad] relative to the zero, v_m [rad/s],
//!     measured current [A]. Ranges come from the plant parameters ([`mit_ranges`]).
//!   - **ODrive CAN Simple**: Set_Axis_State (CLOSED_LOOP_CONTROL = 8 / IDLE = 1),
//!     Set_Controller_Mode (torque control is the only mode that drives current; the drive starts in
//!     position control like a factory ODrive), Set_Input_Torque [motor Nm], Estop, Clear_Errors;
//!     cyclic Get_Encoder_Estimates [motor rev, rev/s] and Get_Iq [A] every 1 ms tick and Heartbeat
//!     every [`ODRIVE_HEARTBEAT_TICKS`] ms (the `*_rate_ms` settings of a drive tuned for 1 kHz), and
//!     the same messages on RTR request. Every non-RTR message feeds the watchdog.
//!   - **Command timeout** (`command_timeout_ms`, 0 = never): no command for that long → the drive
//!     idles (0 A) like a real drive: MIT leaves motor mode, ODrive goes IDLE with
//!     `AXIS_ERROR_WATCHDOG_TIMER_EXPIRED`. It re-enters on the next enable (MIT enter-motor-mode
//!     frame, ODrive Set_Axis_State 8); commands before that are answered but not applied.
//!   - **CiA 402** over CANopen ([`frictionless_drives::can::cia402_node::Cia402Node`]: object
//!     dictionary, NMT slave, SDO server, SYNC-driven PDOs, EMCY, heartbeat): the drive boots into
//!     pre-operational at start; in operation enabled it applies CST target torque 0x6071 (+ torque
//!     offset 0x60B2; CSP / CSV: only 0x60B2) as motor torque, in ‰ of its rated torque 0x6076 =
//!     k_t·i_max (0x6072 = 1000 ‰). Position 0x6064 in [`CIA402_COUNTS_PER_REV`] increments per motor
//!     revolution, velocity 0x606C in increments/s, torque 0x6077 from the measured current, the
//!     joint-side encoder 0x60E4:01 in [`CIA402_JOINT_COUNTS_PER_REV`] increments per joint
//!     revolution, temperature 0x2031:01 in m°C. No command timeout (the drive's own RPDO or
//!     heartbeat-consumer supervision is not emulated).
//! - [`run`] / [`run_with_stats`] / [`serve_socket`]: the 1 kHz real-time loop on absolute deadlines
//!   (like the shared-memory plant): between ticks it waits on the socket (`ppoll`, ns timeout) and
//!   answers frames as they arrive; every tick it steps each plant 1 ms with the drive's current.
//!   Transmissions go through a small queue: a frame the kernel refuses (`EAGAIN`/`ENOBUFS`) is retried
//!   every 100 µs and dropped (counted) when older than [`TX_MAX_AGE_TICKS`] ticks — never a blocking
//!   write, never a burst (the kernel drops frames silently when a reader falls behind).
//!
//! Signs and units: the plant's current and motor angle are in the robot's convention
//! (θ_m = r_signed·φ, joint torque = r_signed·k_t·i), so the drive's motor torque is k_t·i along θ_m —
//! the daemon's `command_unit = "motor_torque"` with the same k_t and signed gear ratio.
//!
//! What it is **not**: no shared memory (no `SimTruth`, no `SimDisturbance`: use `--backend shm` for
//! those), no lockstep (CAN has no sequence numbers), no CAN FD, no position/velocity control modes.

use std::collections::VecDeque;
use std::io;
use std::os::fd::AsRawFd;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::cia402_node::{self, Cia402Node, NodeParams};
use frictionless_drives::can::mit::{self, MitCommand, MitRanges, MitReply, MitRx, MitSpecial};
use frictionless_drives::can::odrive::{self, OdriveMsg};
use socketcan::{CanFilter, CanFrame, CanSocket, Socket, SocketOptions};

use super::{ServeError, ServedRobot};
use frictionless_sim::{Measurement, PlantParams};

/// Tick period [ns] (1 kHz).
pub const TICK_NS: u64 = 1_000_000;
/// Standard id the MIT drives reply on (bgkatz `CAN_MASTER`); byte 0 of the reply is the motor id.
pub const MIT_HOST_ID: u32 = 0x000;
/// Joint speed the MIT velocity range covers [rad/s joint side]: v range = ±|r|·this.
pub const MIT_JOINT_SPEED_RANGE_RAD_S: f64 = 5.0;
/// Margin on the joint range for the MIT position range: p range = ±ceil(this·|r|·max|s|).
pub const MIT_POSITION_MARGIN: f64 = 1.2;
/// ODrive Heartbeat period [ticks] (the firmware default `heartbeat_rate_ms` = 100).
pub const ODRIVE_HEARTBEAT_TICKS: u64 = 100;
/// ODrive 0.5.x `AXIS_ERROR_WATCHDOG_TIMER_EXPIRED`.
pub const AXIS_ERROR_WATCHDOG_TIMER_EXPIRED: u32 = 0x0000_0800;
/// ODrive 0.5.x `AXIS_ERROR_ESTOP_REQUESTED`.
pub const AXIS_ERROR_ESTOP_REQUESTED: u32 = 0x0000_4000;
/// ODrive control mode POSITION_CONTROL (the factory default).
pub const CONTROL_MODE_POSITION: i32 = 3;
/// A queued frame older than this many ticks is dropped (and counted) instead of sent late.
pub const TX_MAX_AGE_TICKS: u64 = 2;
/// CiA 402 emulated drive: 0x6064 increments per motor revolution (0x608F:01, 0x608F:02 = 1).
pub const CIA402_COUNTS_PER_REV: u32 = 16384;
/// CiA 402 emulated drive: 0x60E4:01 increments per joint revolution.
pub const CIA402_JOINT_COUNTS_PER_REV: f64 = 524_288.0;
/// Frames the transmit queue holds before dropping the oldest.
const TX_QUEUE_CAP: usize = 64;
/// Frames read per drain call at most (bounds the time spent before the next tick).
const RX_BURST_MAX: usize = 256;
/// Behind by more than this many ticks → resynchronise the clock instead of catching up.
const MAX_CATCH_UP_TICKS: u64 = 100;
/// Retry period while the transmit queue is not empty.
const TX_RETRY: Duration = Duration::from_micros(100);

/// The drive protocol spoken on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    /// MIT mini-cheetah / CubeMars AK "MIT mode".
    Mit,
    /// ODrive "CAN Simple".
    Odrive,
    /// CiA 402 over CANopen.
    Cia402,
}

frictionless::named_enum!(
    Protocol,
    "protocol",
    [Mit = "mit", Odrive = "odrive", Cia402 = "cia402"]
);

/// Options of [`run`] (`frictl sim serve --backend can …`).
#[derive(Debug, Clone, PartialEq)]
pub struct CanServeOptions {
    /// SocketCAN interface (`vcan0`, `can0`).
    pub bus: String,
    /// Protocol of every drive on the bus.
    pub protocol: Protocol,
    /// Node id of joint k (`--node-ids`); empty = 1, 2, … in joint order.
    pub node_ids: Vec<u8>,
    /// No command for this long → the drive idles (0 = never) [ms].
    pub command_timeout_ms: u64,
    /// Stop after this long of simulated (= wall) time [s]; `None` = until `stop`.
    pub duration_s: Option<f64>,
}

/// Counters of one [`serve_socket`] run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CanServeStats {
    /// 1 ms plant steps done.
    pub ticks: u64,
    /// Ticks that started more than one period after their deadline.
    pub late_ticks: u64,
    /// Ticks skipped by resynchronising the clock after a long stall.
    pub skipped_ticks: u64,
    /// Frames received for one of our drives.
    pub rx_frames: u64,
    /// Frames received for other ids (only without kernel filters, e.g. on a socketpair).
    pub rx_ignored: u64,
    /// Frames for our ids the protocol codec refused.
    pub rx_decode_errors: u64,
    /// Error frames received.
    pub rx_error_frames: u64,
    /// Frames written.
    pub tx_frames: u64,
    /// Frames dropped (queue full or older than [`TX_MAX_AGE_TICKS`]).
    pub tx_dropped: u64,
    /// Write errors other than a full queue.
    pub tx_errors: u64,
    /// Command timeouts (drive went idle).
    pub command_timeouts: u64,
}

/// The MIT ranges the emulated drive of a joint uses (the daemon's per-joint config must match):
/// p ±ceil(1.2·|r|·max(|s_lo|, |s_hi|)) [motor rad], v ±|r|·5 [motor rad/s], kp 0–500, kd 0–5,
/// t ±k_t·i_max [motor Nm], reply current ±i_max [A].
pub fn mit_ranges(p: &PlantParams) -> MitRanges {
    let r = p.gear_ratio_signed.abs();
    let s_max = p.joint_lo_rad.abs().max(p.joint_hi_rad.abs());
    let p_max = (MIT_POSITION_MARGIN * r * s_max).ceil().max(1.0);
    let v_max = r * MIT_JOINT_SPEED_RANGE_RAD_S;
    let t_max = p.kt_nm_per_a * p.i_max_a;
    MitRanges {
        p_min_rad: -p_max,
        p_max_rad: p_max,
        v_min_rad_s: -v_max,
        v_max_rad_s: v_max,
        kp_min_nm_rad: 0.0,
        kp_max_nm_rad: 500.0,
        kd_min_nm_s_rad: 0.0,
        kd_max_nm_s_rad: 5.0,
        t_min_nm: -t_max,
        t_max_nm: t_max,
        i_min_a: -p.i_max_a,
        i_max_a: p.i_max_a,
    }
}

/// What [`Drive::on_frame`] made of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameOutcome {
    /// Not addressed to this drive.
    NotMine,
    /// Addressed to this drive but not decodable (wrong length, unknown command, …).
    Rejected,
    /// Handled; `reply` is the frame to send back, if any.
    Handled {
        /// The answer (MIT reply, ODrive RTR answer).
        reply: Option<WireFrame>,
    },
    /// Handled by a CiA 402 node; the frames to send (SDO response, TPDOs after a SYNC, EMCY).
    HandledMany(cia402_node::Out),
}

/// One emulated drive. Time is counted in ticks (1 ms).
#[derive(Debug, Clone)]
pub struct Drive {
    protocol: Protocol,
    node: u8,
    ranges: MitRanges,
    kt_nm_per_a: f64,
    i_max_a: f64,
    timeout_ticks: u64,
    enabled: bool,
    mit_cmd: MitCommand,
    odrive_torque_nm: f64,
    control_mode: i32,
    input_mode: i32,
    axis_error: u32,
    last_feed_tick: u64,
    zero_offset_rad: f64,
    i_ref_a: f64,
    timeouts: u64,
    co: Option<Box<Cia402Node>>,
}

impl Drive {
    /// A drive for a joint with parameters `p` on node `node` (idle until enabled).
    /// MIT node ids must be ≠ [`MIT_HOST_ID`]; ODrive node ids ≤ 63.
    pub fn new(
        protocol: Protocol,
        node: u8,
        p: &PlantParams,
        command_timeout_ms: u64,
    ) -> Result<Self, ServeError> {
        match protocol {
            Protocol::Mit if u32::from(node) == MIT_HOST_ID => {
                return Err(ServeError::MitNodeIsHost {
                    node,
                    host: MIT_HOST_ID,
                });
            }
            Protocol::Odrive if node > odrive::NODE_MAX => {
                return Err(ServeError::OdriveNodeRange {
                    node,
                    max: odrive::NODE_MAX,
                });
            }
            Protocol::Cia402 if node == 0 || node > 127 => {
                return Err(ServeError::Cia402NodeRange { node });
            }
            Protocol::Mit | Protocol::Odrive | Protocol::Cia402 => {}
        }
        let co = if protocol == Protocol::Cia402 {
            let rated = (p.kt_nm_per_a * p.i_max_a * 1000.0).round().max(1.0) as u32;
            let n = Cia402Node::new(&NodeParams {
                node,
                rated_torque_mnm: rated,
                max_torque_permille: 1000,
                counts_per_rev: CIA402_COUNTS_PER_REV,
            })
            .map_err(|_| ServeError::Cia402NodeRange { node })?;
            Some(Box::new(n))
        } else {
            None
        };
        let ranges = mit_ranges(p);
        ranges.validate().map_err(|source| ServeError::MitRanges {
            joint: p.joint.clone(),
            source,
        })?;
        Ok(Self {
            protocol,
            node,
            ranges,
            kt_nm_per_a: p.kt_nm_per_a,
            i_max_a: p.i_max_a,
            timeout_ticks: command_timeout_ms,
            enabled: false,
            mit_cmd: MitCommand::default(),
            odrive_torque_nm: 0.0,
            control_mode: CONTROL_MODE_POSITION,
            input_mode: odrive::INPUT_MODE_PASSTHROUGH,
            axis_error: 0,
            last_feed_tick: 0,
            zero_offset_rad: 0.0,
            i_ref_a: 0.0,
            timeouts: 0,
            co,
        })
    }

    /// The CiA 402 node (CiA 402 drives only).
    pub fn cia402(&self) -> Option<&Cia402Node> {
        self.co.as_deref()
    }

    /// Faults a CiA 402 drive with EMCY `code` (returns the EMCY frame; `None` for other protocols).
    pub fn cia402_fault(&mut self, code: u16) -> Option<WireFrame> {
        self.co.as_mut().and_then(|n| n.inject_fault(code).ok())
    }

    /// The kernel filters for the ids this drive receives (CiA 402: its node's ids, and NMT and
    /// SYNC, which are for every node).
    pub fn filters(&self) -> Vec<CanFilter> {
        match self.protocol {
            Protocol::Cia402 => vec![
                CanFilter::new(u32::from(self.node), 0x7F),
                CanFilter::new(0x000, 0x7FF),
                CanFilter::new(0x080, 0x7FF),
            ],
            _ => vec![self.filter()],
        }
    }

    /// Node id.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// The MIT ranges of this drive.
    pub fn ranges(&self) -> &MitRanges {
        &self.ranges
    }

    /// Whether the drive is in motor mode (MIT) / CLOSED_LOOP_CONTROL (ODrive) / operation enabled
    /// (CiA 402).
    pub fn enabled(&self) -> bool {
        self.co.as_deref().map_or(self.enabled, |n| {
            n.state() == frictionless_drives::can::cia402::DriveState::OperationEnabled
        })
    }

    /// ODrive axis error bits (0 for MIT).
    pub fn axis_error(&self) -> u32 {
        self.axis_error
    }

    /// Current reference of the last [`Drive::current_a`] [A].
    pub fn i_ref_a(&self) -> f64 {
        self.i_ref_a
    }

    /// Command timeouts so far.
    pub fn timeouts(&self) -> u64 {
        self.timeouts
    }

    /// The kernel filter for the ids this drive receives.
    pub fn filter(&self) -> CanFilter {
        match self.protocol {
            Protocol::Mit => CanFilter::new(u32::from(self.node), 0x7FF),
            Protocol::Odrive => CanFilter::new(u32::from(self.node) << 5, 0x7E0),
            Protocol::Cia402 => CanFilter::new(u32::from(self.node), 0x7F),
        }
    }

    /// Whether a frame is addressed to this drive.
    pub fn owns(&self, f: &WireFrame) -> bool {
        if f.extended {
            return false;
        }
        match self.protocol {
            Protocol::Mit => f.id == u32::from(self.node),
            Protocol::Odrive => f.id <= 0x7FF && odrive::split_id(f.id).0 == self.node,
            Protocol::Cia402 => {
                use frictionless_drives::can::cia402::{CobKind, classify};
                match classify(f.id) {
                    CobKind::Nmt | CobKind::Sync => true,
                    CobKind::SdoRequest(n) | CobKind::Rpdo(_, n) => n == self.node,
                    _ => false,
                }
            }
        }
    }

    /// Whether a frame goes to every drive on the bus (CiA 402 NMT and SYNC).
    pub fn is_broadcast(&self, f: &WireFrame) -> bool {
        self.protocol == Protocol::Cia402 && !f.extended && (f.id == 0x000 || f.id == 0x080)
    }

    fn on_cia402(&mut self, f: &WireFrame, meas: &Measurement) -> FrameOutcome {
        let Some(n) = self.co.as_deref_mut() else {
            return FrameOutcome::Rejected;
        };
        if f.id == 0x080 {
            // The TPDOs of this SYNC carry the latest measurement.
            let cpr = f64::from(CIA402_COUNTS_PER_REV);
            let counts = |rad: f64, per_rev: f64| {
                (rad * per_rev / std::f64::consts::TAU)
                    .round()
                    .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
            };
            let rated = f64::from(n.rated_torque_mnm()) / 1000.0;
            let pm = (meas.i_meas_a * self.kt_nm_per_a / rated * 1000.0)
                .round()
                .clamp(-32767.0, 32767.0) as i16;
            let temp_mc = (meas.temperature_c * 1000.0)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
            n.set_feedback(
                counts(meas.theta_motor_rad, cpr),
                counts(meas.omega_motor_rad_s, cpr),
                pm,
                counts(meas.s_rad, CIA402_JOINT_COUNTS_PER_REV),
                if meas.temperature_c.is_finite() {
                    temp_mc
                } else {
                    0
                },
            );
        }
        FrameOutcome::HandledMany(n.on_frame(f))
    }

    fn feed(&mut self, tick: u64) {
        self.last_feed_tick = tick;
    }

    /// Handles a received frame at tick `tick`; `meas` is the joint's latest measurement.
    pub fn on_frame(&mut self, f: &WireFrame, meas: &Measurement, tick: u64) -> FrameOutcome {
        if !self.owns(f) {
            return FrameOutcome::NotMine;
        }
        match self.protocol {
            Protocol::Mit => self.on_mit(f, meas, tick),
            Protocol::Odrive => self.on_odrive(f, meas, tick),
            Protocol::Cia402 => self.on_cia402(f, meas),
        }
    }

    fn on_mit(&mut self, f: &WireFrame, meas: &Measurement, tick: u64) -> FrameOutcome {
        let Ok(rx) = mit::decode_command(f, &self.ranges) else {
            return FrameOutcome::Rejected;
        };
        // The reply carries the state before this frame takes effect.
        let reply = self.mit_reply(meas);
        match rx {
            MitRx::Special(MitSpecial::EnterMotorMode) => {
                self.enabled = true;
                self.mit_cmd = MitCommand::default();
                self.feed(tick);
            }
            MitRx::Special(MitSpecial::ExitMotorMode) => {
                self.enabled = false;
                self.mit_cmd = MitCommand::default();
            }
            MitRx::Special(MitSpecial::ZeroPosition) => {
                self.zero_offset_rad = meas.theta_motor_rad;
            }
            MitRx::Command(c) => {
                if self.enabled {
                    self.mit_cmd = c;
                    self.feed(tick);
                }
            }
        }
        FrameOutcome::Handled { reply }
    }

    fn mit_reply(&self, meas: &Measurement) -> Option<WireFrame> {
        let rep = MitReply {
            motor_id: self.node,
            p_rad: meas.theta_motor_rad - self.zero_offset_rad,
            v_rad_s: meas.omega_motor_rad_s,
            i_a: meas.i_meas_a,
        };
        // Out-of-range values saturate (as the firmware's packing does); non-finite ones cannot occur
        // for a validated plant, and a frame that cannot be built is simply not sent.
        mit::encode_reply(MIT_HOST_ID, &rep, &self.ranges)
            .ok()
            .map(|(f, _)| f)
    }

    fn on_odrive(&mut self, f: &WireFrame, meas: &Measurement, tick: u64) -> FrameOutcome {
        let Ok((_, msg)) = odrive::decode(f) else {
            return FrameOutcome::Rejected;
        };
        if !f.rtr {
            self.feed(tick);
        }
        let mut reply = None;
        match msg {
            OdriveMsg::Request { cmd } => {
                reply = match cmd {
                    odrive::cmd::GET_ENCODER_ESTIMATES => self.odrive_encoder(meas),
                    odrive::cmd::GET_IQ => self.odrive_iq(meas),
                    odrive::cmd::HEARTBEAT => self.odrive_heartbeat(),
                    _ => return FrameOutcome::Rejected,
                };
            }
            OdriveMsg::Estop => {
                self.axis_error |= AXIS_ERROR_ESTOP_REQUESTED;
                self.enabled = false;
            }
            OdriveMsg::ClearErrors => self.axis_error = 0,
            OdriveMsg::SetAxisState { requested_state } => match requested_state {
                odrive::AXIS_STATE_CLOSED_LOOP_CONTROL => {
                    // The enable clears an expired watchdog; any other error must be cleared first.
                    self.axis_error &= !AXIS_ERROR_WATCHDOG_TIMER_EXPIRED;
                    if self.axis_error == 0 {
                        self.enabled = true;
                        self.odrive_torque_nm = 0.0;
                    }
                }
                odrive::AXIS_STATE_IDLE => self.enabled = false,
                _ => return FrameOutcome::Rejected,
            },
            OdriveMsg::SetControllerMode {
                control_mode,
                input_mode,
            } => {
                self.control_mode = control_mode;
                self.input_mode = input_mode;
            }
            OdriveMsg::SetInputTorque { torque_nm } => {
                if !torque_nm.is_finite() {
                    return FrameOutcome::Rejected;
                }
                self.odrive_torque_nm = f64::from(torque_nm);
            }
            // Feedback messages from another device with our node id.
            OdriveMsg::Heartbeat { .. }
            | OdriveMsg::EncoderEstimates { .. }
            | OdriveMsg::Iq { .. } => {
                return FrameOutcome::Rejected;
            }
        }
        FrameOutcome::Handled { reply }
    }

    fn odrive_encoder(&self, meas: &Measurement) -> Option<WireFrame> {
        let msg = OdriveMsg::EncoderEstimates {
            pos_rev: (meas.theta_motor_rad / std::f64::consts::TAU) as f32,
            vel_rev_s: (meas.omega_motor_rad_s / std::f64::consts::TAU) as f32,
        };
        odrive::encode(self.node, &msg).ok()
    }

    fn odrive_iq(&self, meas: &Measurement) -> Option<WireFrame> {
        let msg = OdriveMsg::Iq {
            iq_setpoint_a: self.i_ref_a as f32,
            iq_measured_a: meas.i_meas_a as f32,
        };
        odrive::encode(self.node, &msg).ok()
    }

    fn odrive_heartbeat(&self) -> Option<WireFrame> {
        let msg = OdriveMsg::Heartbeat {
            axis_error: self.axis_error,
            axis_state: if self.enabled {
                odrive::AXIS_STATE_CLOSED_LOOP_CONTROL as u8
            } else {
                odrive::AXIS_STATE_IDLE as u8
            },
            status: [0; 3],
        };
        odrive::encode(self.node, &msg).ok()
    }

    /// The current the drive applies during tick `tick` [A] (robot convention), after the command
    /// timeout check; `meas` is the state the drive's own law (MIT kp/kd) acts on.
    pub fn current_a(&mut self, meas: &Measurement, tick: u64) -> f64 {
        if self.enabled
            && self.timeout_ticks > 0
            && tick.saturating_sub(self.last_feed_tick) >= self.timeout_ticks
        {
            self.enabled = false;
            self.timeouts += 1;
            match self.protocol {
                Protocol::Mit => self.mit_cmd = MitCommand::default(),
                Protocol::Odrive => {
                    self.axis_error |= AXIS_ERROR_WATCHDOG_TIMER_EXPIRED;
                    self.odrive_torque_nm = 0.0;
                }
                Protocol::Cia402 => {}
            }
        }
        let tau_motor_nm = if !self.enabled() {
            0.0
        } else {
            match self.protocol {
                Protocol::Mit => {
                    let c = &self.mit_cmd;
                    let p_m = meas.theta_motor_rad - self.zero_offset_rad;
                    c.kp_nm_rad * (c.p_des_rad - p_m)
                        + c.kd_nm_s_rad * (c.v_des_rad_s - meas.omega_motor_rad_s)
                        + c.t_ff_nm
                }
                Protocol::Odrive if self.control_mode == odrive::CONTROL_MODE_TORQUE => {
                    self.odrive_torque_nm
                }
                Protocol::Odrive => 0.0,
                Protocol::Cia402 => self.co.as_deref().map_or(0.0, |n| {
                    f64::from(n.applied_torque_permille()) * f64::from(n.rated_torque_mnm()) / 1e6
                }),
            }
        };
        let i = tau_motor_nm / self.kt_nm_per_a;
        self.i_ref_a = if i.is_finite() {
            i.clamp(-self.i_max_a, self.i_max_a)
        } else {
            0.0
        };
        self.i_ref_a
    }

    /// Frames the drive sends by itself after tick `tick` (ODrive cyclic messages; CiA 402 boot-up
    /// on the first tick, then its heartbeat; none for MIT).
    pub fn cyclic(&mut self, meas: &Measurement, tick: u64, mut out: impl FnMut(WireFrame)) {
        if let Some(n) = self.co.as_deref_mut() {
            if n.nmt() == frictionless_drives::can::cia402::NmtState::BootUp
                && let Ok(f) = n.boot()
            {
                out(f);
            }
            n.tick_ms().frames().iter().for_each(|f| out(*f));
            return;
        }
        if self.protocol != Protocol::Odrive {
            return;
        }
        if let Some(f) = self.odrive_encoder(meas) {
            out(f);
        }
        if let Some(f) = self.odrive_iq(meas) {
            out(f);
        }
        if tick.is_multiple_of(ODRIVE_HEARTBEAT_TICKS)
            && let Some(f) = self.odrive_heartbeat()
        {
            out(f);
        }
    }
}

/// Builds one drive per joint with node ids `opts.node_ids` (default 1, 2, …), checking they are
/// unique and that there is one per joint.
pub fn build_drives(robot: &ServedRobot, opts: &CanServeOptions) -> Result<Vec<Drive>, ServeError> {
    if robot.is_empty() {
        return Err(ServeError::NoJoints);
    }
    let ids: Vec<u8> = if opts.node_ids.is_empty() {
        (1..=robot.len())
            .map(|k| u8::try_from(k).map_err(ServeError::TooManyCanJoints))
            .collect::<Result<_, _>>()?
    } else {
        opts.node_ids.clone()
    };
    if ids.len() != robot.len() {
        return Err(ServeError::NodeIdCount {
            ids: ids.len(),
            joints: robot.len(),
        });
    }
    for (k, id) in ids.iter().enumerate() {
        if ids[..k].contains(id) {
            return Err(ServeError::DuplicateNodeId(*id));
        }
    }
    ids.iter()
        .enumerate()
        .map(|(k, &id)| {
            Drive::new(opts.protocol, id, robot.params(k), opts.command_timeout_ms).map_err(|e| {
                ServeError::Joint {
                    joint: robot.name(k).to_owned(),
                    source: Box::new(e),
                }
            })
        })
        .collect()
}

/// Serves `robot`'s joints as drives on interface `opts.bus` until `stop` is set or `opts.duration_s` has
/// passed (see the module doc).
pub fn run(
    robot: &mut ServedRobot,
    opts: &CanServeOptions,
    stop: &AtomicBool,
) -> Result<(), ServeError> {
    let st = run_with_stats(robot, opts, stop)?;
    tracing::info!(
        "sim serve can: {} ticks ({} late, {} skipped), rx {} (+{} other ids, {} rejected, {} error frames), tx {} ({} dropped, {} errors), {} command timeouts",
        st.ticks,
        st.late_ticks,
        st.skipped_ticks,
        st.rx_frames,
        st.rx_ignored,
        st.rx_decode_errors,
        st.rx_error_frames,
        st.tx_frames,
        st.tx_dropped,
        st.tx_errors,
        st.command_timeouts
    );
    Ok(())
}

/// [`run`], returning the counters.
pub fn run_with_stats(
    robot: &mut ServedRobot,
    opts: &CanServeOptions,
    stop: &AtomicBool,
) -> Result<CanServeStats, ServeError> {
    let drives = build_drives(robot, opts)?;
    let sock = CanSocket::open(&opts.bus).map_err(|source| ServeError::OpenBus {
        bus: opts.bus.clone(),
        source,
    })?;
    let filters: Vec<CanFilter> = drives.iter().flat_map(Drive::filters).collect();
    sock.set_filters(&filters)
        .map_err(|source| ServeError::SetFilters {
            bus: opts.bus.clone(),
            source,
        })?;
    // A larger receive buffer (needs CAP_NET_ADMIN; harmless to fail).
    let _ = sock.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 1 << 20);
    serve_drives(robot, drives, opts, &sock, stop)
}

/// Serves `robot`'s joints on an already opened socket (e.g. one end of a socketpair in tests; no kernel
/// filters are set here, frames for other ids are ignored in software).
pub fn serve_socket(
    robot: &mut ServedRobot,
    opts: &CanServeOptions,
    sock: &CanSocket,
    stop: &AtomicBool,
) -> Result<CanServeStats, ServeError> {
    let drives = build_drives(robot, opts)?;
    serve_drives(robot, drives, opts, sock, stop)
}

/// Waits until `fd` is readable or `timeout` passed (ns resolution; `EINTR` counts as a wake-up).
fn wait_readable(fd: i32, timeout: Duration) -> io::Result<()> {
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as _, // time_t: 64-bit on glibc x86_64 and musl ≥ 1.2
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // ppoll instead of the socketcan timeout helpers: those round sub-millisecond timeouts to 0 or up
    // to a jiffy (reference doc §4.2). SAFETY: `pfd` and `ts` are valid for the duration of the call,
    // nfds = 1 matches, a null sigmask means "keep the current mask".
    let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if rc < 0 {
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
    Ok(())
}

/// The transmit side: a bounded queue in front of a non-blocking socket.
struct Tx {
    queue: VecDeque<(WireFrame, u64)>,
}

impl Tx {
    fn is_full_error(e: &io::Error) -> bool {
        e.kind() == io::ErrorKind::WouldBlock || e.raw_os_error() == Some(libc::ENOBUFS)
    }

    fn write(sock: &CanSocket, f: &WireFrame, st: &mut CanServeStats) -> Result<(), io::Error> {
        match CanFrame::try_from(*f) {
            Ok(cf) => sock.write_frame(&cf).map(|()| st.tx_frames += 1),
            Err(_) => {
                st.tx_errors += 1;
                Ok(())
            }
        }
    }

    /// Sends `f` now, or queues it behind earlier frames.
    fn send(&mut self, sock: &CanSocket, f: WireFrame, tick: u64, st: &mut CanServeStats) {
        if self.queue.is_empty() {
            match Self::write(sock, &f, st) {
                Ok(()) => return,
                Err(e) if Self::is_full_error(&e) => {}
                Err(_) => {
                    st.tx_errors += 1;
                    return;
                }
            }
        }
        if self.queue.len() >= TX_QUEUE_CAP {
            self.queue.pop_front();
            st.tx_dropped += 1;
        }
        self.queue.push_back((f, tick));
    }

    /// Sends queued frames until the kernel refuses one; drops frames that are too old.
    fn flush(&mut self, sock: &CanSocket, tick: u64, st: &mut CanServeStats) {
        while let Some(&(f, t)) = self.queue.front() {
            if tick.saturating_sub(t) > TX_MAX_AGE_TICKS {
                self.queue.pop_front();
                st.tx_dropped += 1;
                continue;
            }
            match Self::write(sock, &f, st) {
                Ok(()) => {
                    self.queue.pop_front();
                }
                Err(e) if Self::is_full_error(&e) => break,
                Err(_) => {
                    self.queue.pop_front();
                    st.tx_errors += 1;
                }
            }
        }
    }
}

/// Reads every pending frame (at most [`RX_BURST_MAX`]) and answers it.
fn drain_rx(
    sock: &CanSocket,
    drives: &mut [Drive],
    meas: &[Measurement],
    tick: u64,
    tx: &mut Tx,
    st: &mut CanServeStats,
) -> Result<(), ServeError> {
    for _ in 0..RX_BURST_MAX {
        let frame = match sock.read_frame() {
            Ok(f) => f,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(()),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(source) => {
                return Err(ServeError::CanSocket {
                    what: "reading from the CAN socket",
                    source,
                });
            }
        };
        let Ok(wf) = WireFrame::try_from(&frame) else {
            st.rx_error_frames += 1;
            continue;
        };
        let mut mine = false;
        for (d, m) in drives.iter_mut().zip(meas) {
            let broadcast = d.is_broadcast(&wf);
            match d.on_frame(&wf, m, tick) {
                FrameOutcome::NotMine => continue,
                FrameOutcome::Rejected => st.rx_decode_errors += 1,
                FrameOutcome::Handled { reply } => {
                    if let Some(r) = reply {
                        tx.send(sock, r, tick, st);
                    }
                }
                FrameOutcome::HandledMany(out) => {
                    for r in out.frames() {
                        tx.send(sock, *r, tick, st);
                    }
                }
            }
            mine = true;
            if !broadcast {
                break;
            }
        }
        if mine {
            st.rx_frames += 1;
        } else {
            st.rx_ignored += 1;
        }
    }
    Ok(())
}

/// Says each drive's joint, protocol, node, MIT ranges and constants.
fn log_drives(robot: &ServedRobot, drives: &[Drive], opts: &CanServeOptions) {
    for (k, d) in drives.iter().enumerate() {
        let r = d.ranges();
        tracing::info!(
            "joint `{}` ({}): {:?} node {} — MIT ranges p ±{} rad, v ±{} rad/s, t ±{:.4} Nm, i ±{} A, kt {} Nm/A, r {}",
            robot.name(k),
            k,
            opts.protocol,
            d.node(),
            r.p_max_rad,
            r.v_max_rad_s,
            r.t_max_nm,
            r.i_max_a,
            robot.params(k).kt_nm_per_a,
            robot.params(k).gear_ratio_signed
        );
    }
}

/// Answers the frames that arrive (and retries the queued replies) until `deadline` or a stop.
#[allow(clippy::too_many_arguments)]
fn answer_until(
    deadline: Instant,
    sock: &CanSocket,
    drives: &mut [Drive],
    meas: &[Measurement],
    tick: u64,
    tx: &mut Tx,
    st: &mut CanServeStats,
    stop: &AtomicBool,
) -> Result<(), ServeError> {
    let fd = sock.as_raw_fd();
    loop {
        tx.flush(sock, tick, st);
        drain_rx(sock, drives, meas, tick, tx, st)?;
        let now = Instant::now();
        if now >= deadline || stop.load(Ordering::Relaxed) {
            break;
        }
        let mut wait = deadline - now;
        if !tx.queue.is_empty() {
            wait = wait.min(TX_RETRY);
        }
        wait_readable(fd, wait).map_err(|source| ServeError::CanSocket {
            what: "waiting on the CAN socket",
            source,
        })?;
    }
    Ok(())
}

/// Each drive's current for this tick into `i_ref_a`; a drive that idles for want of commands
/// is counted and said.
fn drive_currents(
    robot: &ServedRobot,
    drives: &mut [Drive],
    meas: &[Measurement],
    tick: u64,
    opts: &CanServeOptions,
    i_ref_a: &mut [f64],
    st: &mut CanServeStats,
) {
    for (k, (d, m)) in drives.iter_mut().zip(meas).enumerate() {
        let was_enabled = d.enabled();
        i_ref_a[k] = d.current_a(m, tick);
        if was_enabled && !d.enabled() {
            st.command_timeouts += 1;
            tracing::warn!(
                "joint `{}` node {}: no command for {} ms, drive idles",
                robot.name(k),
                d.node(),
                opts.command_timeout_ms
            );
        }
    }
}

fn serve_drives(
    robot: &mut ServedRobot,
    mut drives: Vec<Drive>,
    opts: &CanServeOptions,
    sock: &CanSocket,
    stop: &AtomicBool,
) -> Result<CanServeStats, ServeError> {
    sock.set_nonblocking(true)
        .map_err(|source| ServeError::CanSocket {
            what: "setting the CAN socket non-blocking",
            source,
        })?;
    log_drives(robot, &drives, opts);
    let end_tick = match opts.duration_s {
        Some(d) if d.is_finite() && d >= 0.0 => Some((d * 1e3).round() as u64),
        Some(d) => return Err(ServeError::CanDuration(d)),
        None => None,
    };
    let mut st = CanServeStats::default();
    let mut tx = Tx {
        queue: VecDeque::with_capacity(TX_QUEUE_CAP),
    };
    let mut meas: Vec<Measurement> = (0..robot.len()).map(|k| robot.measurement(k)).collect();
    // The step's inputs, one per joint (no external torque on the CAN plant).
    let mut i_ref_a = vec![0.0; robot.len()];
    let tau_ext_nm = vec![0.0; robot.len()];
    let mut epoch = Instant::now();
    let mut epoch_tick = 0u64;
    let mut tick = 0u64;
    let tick_period = Duration::from_nanos(TICK_NS);
    while !stop.load(Ordering::Relaxed) && end_tick.is_none_or(|e| tick < e) {
        let deadline =
            epoch + tick_period * u32::try_from(tick + 1 - epoch_tick).unwrap_or(u32::MAX);
        // Answer frames as they arrive until the tick's deadline.
        answer_until(
            deadline,
            sock,
            &mut drives,
            &meas,
            tick,
            &mut tx,
            &mut st,
            stop,
        )?;
        // One 1 ms step of every joint at once, each with its drive's current.
        drive_currents(robot, &mut drives, &meas, tick, opts, &mut i_ref_a, &mut st);
        robot.step(&i_ref_a, &tau_ext_nm)?;
        for (k, m) in meas.iter_mut().enumerate() {
            *m = robot.measurement(k);
        }
        tick += 1;
        for (d, m) in drives.iter_mut().zip(&meas) {
            d.cyclic(m, tick, |f| tx.send(sock, f, tick, &mut st));
        }
        st.ticks += 1;
        // Real-time bookkeeping: late ticks catch up; a long stall resynchronises the clock.
        let now = Instant::now();
        if now > deadline + tick_period {
            st.late_ticks += 1;
            let behind = (now - deadline).as_nanos() / u128::from(TICK_NS);
            if behind > u128::from(MAX_CATCH_UP_TICKS) {
                st.skipped_ticks += behind as u64;
                epoch = now;
                epoch_tick = tick;
            }
        }
    }
    tx.flush(sock, tick, &mut st);
    Ok(st)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meas(theta: f64, omega: f64, i: f64) -> Measurement {
        Measurement {
            time_s: 0.0,
            s_rad: 0.0,
            theta_motor_rad: theta,
            omega_motor_rad_s: omega,
            i_meas_a: i,
            temperature_c: f64::NAN,
        }
    }

    fn knee() -> PlantParams {
        PlantParams::preset("knee").unwrap()
    }

    #[test]
    fn mit_ranges_cover_the_joint_range_and_the_current_limit() {
        let p = knee();
        let r = mit_ranges(&p);
        r.validate().unwrap();
        let r_abs = p.gear_ratio_signed.abs();
        for s in [p.joint_lo_rad, p.joint_hi_rad] {
            assert!((r_abs * s).abs() < r.p_max_rad);
        }
        assert!((r.t_max_nm - p.kt_nm_per_a * p.i_max_a).abs() < 1e-12);
        assert_eq!(r.i_max_a, p.i_max_a);
    }

    #[test]
    fn mit_drive_follows_the_law_and_replies_before_applying() {
        let p = knee();
        let mut d = Drive::new(Protocol::Mit, 3, &p, 20).unwrap();
        let r = *d.ranges();
        let m = meas(1.0, -2.0, 0.5);
        // Idle: commands are answered but not applied.
        let cmd = MitCommand {
            p_des_rad: 1.5,
            v_des_rad_s: 0.0,
            kp_nm_rad: 0.4,
            kd_nm_s_rad: 0.01,
            t_ff_nm: 0.1,
        };
        let f = mit::encode_command(3, &cmd, &r).unwrap().0;
        let FrameOutcome::Handled { reply: Some(rep) } = d.on_frame(&f, &m, 0) else {
            panic!("no reply")
        };
        assert_eq!(d.current_a(&m, 0), 0.0);
        let rep = mit::decode_reply(&rep, &r).unwrap();
        assert_eq!(rep.motor_id, 3);
        let s = r.steps();
        assert!((rep.p_rad - 1.0).abs() <= s[0]);
        assert!((rep.v_rad_s + 2.0).abs() <= s[1]);
        assert!((rep.i_a - 0.5).abs() <= s[5]);
        // Enter, command: τ = kp(p − p_m) + kd(v − v_m) + t_ff with the decoded (quantised) command.
        let e = mit::encode_special(3, MitSpecial::EnterMotorMode).unwrap();
        assert!(matches!(
            d.on_frame(&e, &m, 1),
            FrameOutcome::Handled { .. }
        ));
        assert!(d.enabled());
        d.on_frame(&f, &m, 1);
        let MitRx::Command(q) = mit::decode_command(&f, &r).unwrap() else {
            panic!()
        };
        let tau =
            q.kp_nm_rad * (q.p_des_rad - 1.0) + q.kd_nm_s_rad * (q.v_des_rad_s + 2.0) + q.t_ff_nm;
        let i = d.current_a(&m, 2);
        assert!(
            (i - tau / p.kt_nm_per_a).abs() < 1e-12,
            "{i} vs {}",
            tau / p.kt_nm_per_a
        );
        // Zero position: the reply's p is relative to the new zero.
        let z = mit::encode_special(3, MitSpecial::ZeroPosition).unwrap();
        d.on_frame(&z, &m, 2);
        let FrameOutcome::Handled { reply: Some(rep) } = d.on_frame(&f, &meas(1.25, 0.0, 0.0), 2)
        else {
            panic!()
        };
        assert!((mit::decode_reply(&rep, &r).unwrap().p_rad - 0.25).abs() <= s[0]);
        // Another node's frame is not ours; a short frame is rejected.
        let other = mit::encode_command(4, &cmd, &r).unwrap().0;
        assert_eq!(d.on_frame(&other, &m, 2), FrameOutcome::NotMine);
        let short = WireFrame::standard(3, &[1, 2, 3]).unwrap();
        assert_eq!(d.on_frame(&short, &m, 2), FrameOutcome::Rejected);
    }

    #[test]
    fn mit_current_saturates_at_i_max() {
        let p = knee();
        let mut d = Drive::new(Protocol::Mit, 1, &p, 0).unwrap();
        let r = *d.ranges();
        let m = meas(0.0, 0.0, 0.0);
        d.on_frame(
            &mit::encode_special(1, MitSpecial::EnterMotorMode).unwrap(),
            &m,
            0,
        );
        let big = MitCommand {
            p_des_rad: 100.0,
            kp_nm_rad: 100.0,
            ..MitCommand::default()
        };
        d.on_frame(&mit::encode_command(1, &big, &r).unwrap().0, &m, 0);
        assert_eq!(d.current_a(&m, 1), p.i_max_a);
        // Timeout 0 = never: still enabled much later.
        assert_eq!(d.current_a(&m, 1_000_000), p.i_max_a);
    }

    #[test]
    fn mit_timeout_idles_until_the_next_enter() {
        let p = knee();
        let mut d = Drive::new(Protocol::Mit, 1, &p, 20).unwrap();
        let r = *d.ranges();
        let m = meas(0.0, 0.0, 0.0);
        let cmd = mit::encode_command(1, &MitCommand::torque(0.3), &r)
            .unwrap()
            .0;
        d.on_frame(
            &mit::encode_special(1, MitSpecial::EnterMotorMode).unwrap(),
            &m,
            0,
        );
        d.on_frame(&cmd, &m, 0);
        assert!(d.current_a(&m, 19) > 0.0);
        assert_eq!(d.current_a(&m, 20), 0.0);
        assert!(!d.enabled());
        assert_eq!(d.timeouts(), 1);
        d.on_frame(&cmd, &m, 21);
        assert_eq!(d.current_a(&m, 21), 0.0, "commands do not re-enable");
        d.on_frame(
            &mit::encode_special(1, MitSpecial::EnterMotorMode).unwrap(),
            &m,
            22,
        );
        d.on_frame(&cmd, &m, 22);
        assert!(d.current_a(&m, 23) > 0.0);
    }

    fn decode_all(frames: &[WireFrame]) -> Vec<OdriveMsg> {
        frames
            .iter()
            .map(|f| odrive::decode(f).unwrap().1)
            .collect()
    }

    #[test]
    fn odrive_drive_modes_watchdog_and_cyclic_frames() {
        let p = knee();
        let mut d = Drive::new(Protocol::Odrive, 5, &p, 10).unwrap();
        let m = meas(std::f64::consts::TAU, -std::f64::consts::PI, 1.5);
        let enc = |msg: OdriveMsg| odrive::encode(5, &msg).unwrap();
        let torque = enc(OdriveMsg::SetInputTorque { torque_nm: 0.2 });
        // Closed loop but still in position control: no current.
        d.on_frame(
            &enc(OdriveMsg::SetAxisState {
                requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
            }),
            &m,
            0,
        );
        d.on_frame(&torque, &m, 0);
        assert!(d.enabled());
        assert_eq!(d.current_a(&m, 1), 0.0);
        d.on_frame(
            &enc(OdriveMsg::SetControllerMode {
                control_mode: odrive::CONTROL_MODE_TORQUE,
                input_mode: odrive::INPUT_MODE_PASSTHROUGH,
            }),
            &m,
            1,
        );
        d.on_frame(&torque, &m, 1);
        let i = d.current_a(&m, 2);
        assert!((i - 0.2f32 as f64 / p.kt_nm_per_a).abs() < 1e-9);
        // Cyclic frames: encoder + Iq each tick, heartbeat every 100 ticks.
        let mut out = Vec::new();
        d.cyclic(&m, 3, |f| out.push(f));
        let msgs = decode_all(&out);
        assert_eq!(msgs.len(), 2);
        assert_eq!(
            msgs[0],
            OdriveMsg::EncoderEstimates {
                pos_rev: 1.0,
                vel_rev_s: -0.5
            }
        );
        let OdriveMsg::Iq {
            iq_setpoint_a,
            iq_measured_a,
        } = msgs[1]
        else {
            panic!()
        };
        assert!((f64::from(iq_setpoint_a) - i).abs() < 1e-6);
        assert_eq!(iq_measured_a, 1.5);
        out.clear();
        d.cyclic(&m, 100, |f| out.push(f));
        assert_eq!(out.len(), 3);
        // RTR request answered.
        let rtr = odrive::encode(
            5,
            &OdriveMsg::Request {
                cmd: odrive::cmd::HEARTBEAT,
            },
        )
        .unwrap();
        let FrameOutcome::Handled { reply: Some(hb) } = d.on_frame(&rtr, &m, 3) else {
            panic!()
        };
        assert!(matches!(
            odrive::decode(&hb).unwrap().1,
            OdriveMsg::Heartbeat {
                axis_state: 8,
                axis_error: 0,
                ..
            }
        ));
        // Watchdog: 10 ticks without a message → idle with the watchdog error.
        assert!(d.current_a(&m, 10) > 0.0);
        assert_eq!(d.current_a(&m, 11), 0.0);
        assert!(!d.enabled());
        assert_eq!(d.axis_error(), AXIS_ERROR_WATCHDOG_TIMER_EXPIRED);
        d.on_frame(&torque, &m, 12);
        assert_eq!(d.current_a(&m, 12), 0.0, "torque does not re-enable");
        d.on_frame(
            &enc(OdriveMsg::SetAxisState {
                requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
            }),
            &m,
            13,
        );
        d.on_frame(&torque, &m, 13);
        assert!(d.current_a(&m, 14) > 0.0);
        assert_eq!(d.axis_error(), 0);
        // Estop needs Clear_Errors before closed loop again.
        d.on_frame(&enc(OdriveMsg::Estop), &m, 15);
        assert_eq!(d.current_a(&m, 15), 0.0);
        let cl = enc(OdriveMsg::SetAxisState {
            requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
        });
        d.on_frame(&cl, &m, 16);
        assert!(!d.enabled());
        d.on_frame(&enc(OdriveMsg::ClearErrors), &m, 16);
        d.on_frame(&cl, &m, 16);
        assert!(d.enabled());
    }

    #[test]
    fn node_ids_are_checked() {
        let p = knee();
        assert!(Drive::new(Protocol::Mit, 0, &p, 20).is_err());
        assert!(Drive::new(Protocol::Odrive, 64, &p, 20).is_err());
        assert!(Drive::new(Protocol::Odrive, 63, &p, 20).is_ok());
    }

    #[test]
    fn cia402_drive_boots_takes_sdo_and_applies_cst_torque_at_sync() {
        use frictionless_drives::can::cia402::{self as co, DriveState, NmtCommand, SdoAddr};
        let p = PlantParams::preset("knee").unwrap();
        let mut d = Drive::new(Protocol::Cia402, 5, &p, 0).unwrap();
        let m = Measurement {
            time_s: 0.0,
            s_rad: 0.25,
            theta_motor_rad: std::f64::consts::PI,
            omega_motor_rad_s: 1.0,
            i_meas_a: 0.5,
            temperature_c: 40.0,
        };
        let mut sent = Vec::new();
        d.cyclic(&m, 1, |f| sent.push(f));
        assert_eq!(sent[0].id, 0x705, "boot-up");
        assert_eq!(sent[0].data[0], 0);
        let handle = |d: &mut Drive, f: WireFrame| match d.on_frame(&f, &m, 1) {
            FrameOutcome::HandledMany(out) => out.frames().to_vec(),
            other => panic!("{other:?}"),
        };
        let ack = handle(
            &mut d,
            co::encode_sdo_request(
                5,
                &co::sdo_download(SdoAddr::new(0x6060, 0), 10, 1).unwrap(),
            )
            .unwrap(),
        );
        assert_eq!(ack[0].id, 0x585);
        handle(&mut d, co::encode_nmt(NmtCommand::Start, 0).unwrap());
        let rated = (p.kt_nm_per_a * p.i_max_a * 1000.0).round();
        let rmap = co::PdoMap::new(&[
            co::PdoEntry::new(0x6040, 0, 16),
            co::PdoEntry::new(0x6071, 0, 16),
        ])
        .unwrap();
        let mut tpdo1 = Vec::new();
        for cw in [0x06, 0x07, 0x0F] {
            handle(&mut d, co::encode_pdo(0x205, &rmap, &[cw, 500]).unwrap());
            tpdo1 = handle(&mut d, co::encode_sync(None));
        }
        assert!(d.enabled());
        assert_eq!(d.cia402().unwrap().state(), DriveState::OperationEnabled);
        // 500 ‰ of the rated torque k_t·i_max → i_max / 2.
        let i = d.current_a(&m, 2);
        assert!(
            (i - 0.5 * rated / 1000.0 / p.kt_nm_per_a).abs() < 1e-9,
            "{i}"
        );
        // The TPDOs carry the measurement: π rad = half a revolution of 16384 increments.
        let mut raw = [0u32; 8];
        let t1 = co::PdoMap::new(&[
            co::PdoEntry::new(0x6041, 0, 16),
            co::PdoEntry::new(0x6064, 0, 32),
            co::PdoEntry::new(0x6077, 0, 16),
        ])
        .unwrap();
        co::decode_pdo(&tpdo1[0], &t1, &mut raw).unwrap();
        assert_eq!(raw[1], 8192);
        let pm = (0.5 * p.kt_nm_per_a / (rated / 1000.0) * 1000.0).round();
        assert_eq!(co::sign_extend(raw[2], 16), pm as i32);
        // NMT and SYNC go to every drive on the bus.
        assert!(d.is_broadcast(&co::encode_sync(None)));
        assert!(
            !d.owns(
                &co::encode_sdo_request(
                    6,
                    &co::SdoRequest::Upload {
                        addr: SdoAddr::new(0x1000, 0)
                    }
                )
                .unwrap()
            )
        );
        assert!(Drive::new(Protocol::Cia402, 0, &p, 0).is_err());
    }
}
