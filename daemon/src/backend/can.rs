//! SocketCAN backend: motor drives on CAN buses (MIT mini-cheetah / CubeMars, ODrive CAN Simple).
//!
//! What this module **is**: [`CanBackend`]. Per `[[bus]]` one raw classic-CAN socket (socketcan
//! crate), non-blocking, with kernel filters for exactly the ids whose frames we decode (MIT: the
//! reply id `host_id`; ODrive: `node << 5 | {Heartbeat, Get_Encoder_Estimates, Get_Iq}`, standard
//! data frames only) and every error class enabled (`CAN_ERR_MASK`: bus-off, controller problems, …).
//!
//! - [`Backend::read_states`] drains every socket (never blocks, at most [`MAX_FRAMES_PER_TICK`]
//!   frames per bus), decodes feedback with the `frictionless_drives::can` codecs into the joint's
//!   slots of a [`JointStates`] (motor side θ, ω as reported; joint side s = θ/r, ṡ = ω/r with the
//!   signed gear ratio; the current), and applies the **per-joint** freshness rule: a drive silent
//!   for more than `feedback_timeout_ticks` ticks gets its bit in
//!   [`BusCounters::stale_feedback_mask`] and [`FAULT_FEEDBACK_STALE`] in `fault_flags`, so the RT
//!   loop gives that joint the `[safety] on_stale` output (flag `FLAG_STALE`), exactly as a stale
//!   shared-memory state would, while the other joints keep running. An
//!   ODrive heartbeat with an axis error or an axis state other than closed loop sets `FAULT_DRIVE`.
//!   States are returned whenever a feedback frame was decoded or the stale mask changed; when every
//!   drive is silent, nothing new is returned and the loop's whole-state stale rule applies.
//! - [`Backend::publish_command`] encodes every configured joint's current (0 A unless valid and
//!   finite; clamped to ±max_curr) in its `command_unit` and sends one frame per drive (MIT torque
//!   command with kp = kd = 0 — the drive replies to each; ODrive Set_Input_Torque). A full TX queue
//!   (ENOBUFS / EAGAIN) counts `tx_dropped`: never retried, never blocking. The command is mirrored
//!   to shared memory so `frictl record` / `monitor` see what was sent.
//! - Torque requests arrive and status leaves over shared memory as with the shm backend; the
//!   status carries this backend's [`BusCounters`] (filled in here, so the RT loop need not know).
//! - The counters are the bus-neutral [`BusCounters`] tagged [`BusKind::Can`]: frames are its
//!   messages, each `[[bus]]` a link. Error frames count `error_reports`, bus-off (`CAN_ERR_BUSOFF`)
//!   `link_down`, and error-passive (`CAN_ERR_CRTL` with RX/TX passive) the detail slot
//!   [`CAN_DETAIL_ERROR_PASSIVE`]. The RT thread only bumps atomics; a logger thread started
//!   at open logs changes at most once per second (off the RT thread).
//! - Open enters MIT motor mode (`FF…FC`) / ODrive torque control + closed loop; an MIT drive (which
//!   reports no mode, and answers commands in rest mode without applying them) is sent
//!   enter-motor-mode again on every enable edge of its joint, on the first reply after its feedback
//!   was stale (never answered, or fell silent), and while its feedback is stale every
//!   [`REENTER_EVERY_TICKS`]; an ODrive reporting a state other than
//!   closed loop (without axis error) is re-armed at the same rate; drop sends 0 and exits motor
//!   mode / sets the axis idle.
//!
//! - What open fixes (buses, node ids, unit conversion with k_t and the signed gear ratio, MIT
//!   ranges, the `max_curr` clamp) cannot change on SIGHUP: [`reload_conflicts`] lists the
//!   differences and frictiond refuses such a reload naming them (restart to apply).
//!
//! Interfaces named `fd:N` use an inherited, already open CAN socket (e.g. one end of a
//! `socketpair(AF_UNIX, SOCK_SEQPACKET)` in tests); kernel filters are then best effort.
//!
//! What it is **not**: no link configuration (bitrate, txqueuelen, restart-ms: `ip link`), no CAN FD,
//! no control law, no timing. Allocation: none per tick apart from iceoryx2's documented one `Box`
//! per published sample (wrapped in [`alloc_count::exempt`], as in the shm backend).

use std::io::ErrorKind;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use frictionless_drives::can::mit::{self, MitCommand, MitSpecial};
use frictionless_drives::can::odrive::{self, OdriveMsg};
use frictionless_drives::can::{CanCodecError, WireFrame};
use frictionless_shm_types::{
    BusCounters, BusKind, CAN_DETAIL_EMCY, CAN_DETAIL_ERROR_PASSIVE, DaemonStatus, FAULT_DRIVE,
    FAULT_FEEDBACK_STALE, Inbox, IoError, Ipc, JointStates, MotorCurrentCommand, Outbox,
    TorqueRequest, monotonic_ns,
};
use socketcan::{CanFilter, CanFrame, CanSocket, EmbeddedFrame, Socket, SocketOptions};

use super::{Backend, BackendError};
use crate::alloc_count;

mod cia402;
use crate::config::{CanProtocol, Config, ResolvedBus, ResolvedDrive};

/// At most this many frames are read from one bus per tick (a flooded bus cannot stall the tick).
pub const MAX_FRAMES_PER_TICK: usize = 256;

/// A stale MIT drive gets enter-motor-mode (an idle ODrive gets closed-loop) at most this often.
pub const REENTER_EVERY_TICKS: u64 = 100;

// <linux/can/error.h> (kept here so the meaning is explicit; libc has them only in newer versions).
/// Error class: controller problems (details in data[1]).
const CAN_ERR_CRTL: u32 = 0x0000_0004;
/// Error class: bus off.
const CAN_ERR_BUSOFF: u32 = 0x0000_0040;
/// data[1] bit: reached error-passive level on receive.
const CAN_ERR_CRTL_RX_PASSIVE: u8 = 0x10;
/// data[1] bit: reached error-passive level on transmit.
const CAN_ERR_CRTL_TX_PASSIVE: u8 = 0x20;
/// All error classes (`CAN_ERR_MASK`).
const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;
/// Filter-mask bits that make a filter match only standard (not extended) data (not RTR) frames.
const STD_DATA_ONLY: u32 = 0x7FF | libc::CAN_EFF_FLAG | libc::CAN_RTR_FLAG;

/// Bus counters shared with the logger thread (the RT thread only stores).
#[derive(Debug, Default)]
struct SharedCounters {
    error_frames: AtomicU64,
    bus_off: AtomicU64,
    error_passive: AtomicU64,
    tx_dropped: AtomicU64,
    io_errors: AtomicU64,
    stale_mask: AtomicU64,
    emcy: AtomicU64,
    /// Last CiA 402 EMCY: node << 16 | error code.
    last_emcy: AtomicU64,
}

impl SharedCounters {
    fn store(&self, c: &BusCounters) {
        self.error_frames.store(c.error_reports, Ordering::Relaxed);
        self.bus_off.store(c.link_down, Ordering::Relaxed);
        self.error_passive
            .store(c.detail[CAN_DETAIL_ERROR_PASSIVE], Ordering::Relaxed);
        self.tx_dropped.store(c.tx_dropped, Ordering::Relaxed);
        self.io_errors.store(c.io_errors, Ordering::Relaxed);
        self.stale_mask
            .store(c.stale_feedback_mask, Ordering::Relaxed);
        self.emcy
            .store(c.detail[CAN_DETAIL_EMCY], Ordering::Relaxed);
    }

    fn load(&self) -> [u64; 8] {
        [
            self.error_frames.load(Ordering::Relaxed),
            self.bus_off.load(Ordering::Relaxed),
            self.error_passive.load(Ordering::Relaxed),
            self.tx_dropped.load(Ordering::Relaxed),
            self.io_errors.load(Ordering::Relaxed),
            self.stale_mask.load(Ordering::Relaxed),
            self.emcy.load(Ordering::Relaxed),
            self.last_emcy.load(Ordering::Relaxed),
        ]
    }
}

/// One drive's runtime state.
#[derive(Debug)]
struct Drive {
    cfg: ResolvedDrive,
    /// Tick of the last decoded position/velocity feedback (`None`: never).
    last_fb_tick: Option<u64>,
    /// Last tick a (re-)enter sequence was sent.
    last_enter_tick: u64,
    /// ODrive: last heartbeat (axis error, axis state), if any.
    heartbeat: Option<(u32, u8)>,
    /// Whether the last command had this joint valid (enable edges re-enter MIT motor mode).
    was_valid: bool,
    /// Whether the feedback was stale at the previous tick (true before the first reply): an MIT
    /// drive answering again is re-entered at once.
    was_stale: bool,
    /// CiA 402: the drive's CANopen runtime (configured at open).
    co: Option<cia402::Co>,
}

/// One bus: its socket and drives.
#[derive(Debug)]
struct Bus {
    sock: CanSocket,
    protocol: CanProtocol,
    host_id: u32,
    timeout_ticks: u64,
    drives: Vec<Drive>,
}

/// SocketCAN drives (+ shared memory for requests, command mirror and status).
pub struct CanBackend {
    buses: Vec<Bus>,
    states: JointStates,
    status: DaemonStatus,
    counters: BusCounters,
    tick: u64,
    _ipc: Ipc,
    request: Inbox<TorqueRequest>,
    command: Outbox<MotorCurrentCommand>,
    status_out: Outbox<DaemonStatus>,
    shared: Arc<SharedCounters>,
    logger_stop: Arc<AtomicBool>,
    logger: Option<JoinHandle<()>>,
}

/// Whether an I/O error means "queue full / nothing there" (EAGAIN, EWOULDBLOCK, ENOBUFS).
fn is_full_or_empty(e: &std::io::Error) -> bool {
    e.kind() == ErrorKind::WouldBlock || e.raw_os_error() == Some(libc::ENOBUFS)
}

/// Opens the socket of `bus.interface` (a kernel interface, or `fd:N`). Set-up only.
fn open_socket(interface: &str) -> Result<(CanSocket, bool), BackendError> {
    if let Some(n) = interface.strip_prefix("fd:") {
        let fd: i32 = n.parse().map_err(|_| BackendError::FdSpec {
            interface: interface.to_owned(),
        })?;
        // SAFETY: fcntl on an integer fd has no memory effects; it only tells us if it is open.
        if unsafe { libc::fcntl(fd, libc::F_GETFD) } < 0 {
            return Err(BackendError::FdNotOpen {
                interface: interface.to_owned(),
                fd,
                source: std::io::Error::last_os_error(),
            });
        }
        // SAFETY: the descriptor is open and, by the `fd:N` contract, handed to us to own.
        let owned = unsafe { OwnedFd::from_raw_fd(fd) };
        // SAFETY: setting FD_CLOEXEC on a descriptor we own.
        unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) };
        return Ok((CanSocket::from(owned), false));
    }
    let s = CanSocket::open(interface).map_err(|source| BackendError::Open {
        interface: interface.to_owned(),
        source,
    })?;
    Ok((s, true))
}

/// Kernel filters, error frames, non-blocking. `strict`: filter failures are errors (real
/// interfaces); otherwise logged (inherited sockets, e.g. socketpairs, cannot filter).
fn configure_socket(s: &CanSocket, bus: &ResolvedBus, strict: bool) -> Result<(), BackendError> {
    s.set_nonblocking(true)
        .map_err(|source| BackendError::SocketOption {
            interface: bus.interface.clone(),
            what: "set_nonblocking",
            source,
        })?;
    let filters: Vec<CanFilter> = owned_ids(bus)
        .into_iter()
        .map(|id| CanFilter::new(id, STD_DATA_ONLY))
        .collect();
    let res = s
        .set_filters(&filters)
        .and_then(|()| s.set_error_filter(CAN_ERR_MASK));
    match res {
        Ok(()) => {}
        Err(source) if strict => {
            return Err(BackendError::SocketOption {
                interface: bus.interface.clone(),
                what: "setting kernel filters / error mask",
                source,
            });
        }
        Err(e) => tracing::warn!(
            "{}: kernel filters not available ({e}); filtering in user space only",
            bus.interface
        ),
    }
    // A larger receive buffer (best effort; needs CAP_NET_ADMIN): SocketCAN drops silently when full.
    let _ = s.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 1 << 20);
    Ok(())
}

/// The standard ids whose frames this bus decodes (what the kernel filters let through).
pub fn owned_ids(bus: &ResolvedBus) -> Vec<u32> {
    match bus.protocol {
        CanProtocol::Mit => vec![bus.host_id],
        CanProtocol::Cia402 => bus
            .joints
            .iter()
            .flat_map(|d| cia402::owned_ids(d.node_id))
            .collect(),
        CanProtocol::Odrive => bus
            .joints
            .iter()
            .flat_map(|d| {
                [
                    odrive::cmd::HEARTBEAT,
                    odrive::cmd::GET_ENCODER_ESTIMATES,
                    odrive::cmd::GET_IQ,
                ]
                .map(|c| (d.node_id << 5) | u32::from(c))
            })
            .collect(),
    }
}

/// What a reload from `running` to `new` would change that this backend fixed when it opened: the
/// buses (interface, protocol, host id, feedback timeout, bitrate) and per drive the node id, the
/// unit conversion (command unit, k_t, signed gear ratio, feedback angle unit), the MIT ranges and
/// the `max_curr` clamp. Each entry names the bus or joint and the old and new value; empty when
/// nothing differs. frictiond refuses such a reload (a restart applies it) instead of running the
/// law with values the bus does not use.
pub fn reload_conflicts(running: &Config, new: &Config) -> Vec<String> {
    let mut out = Vec::new();
    if running.buses.len() != new.buses.len() {
        out.push(format!(
            "[[bus]] count {} → {}",
            running.buses.len(),
            new.buses.len()
        ));
        return out;
    }
    let name = |cfg: &Config, d: &ResolvedDrive| {
        cfg.raw
            .joint
            .get(d.joint_pos)
            .map(|j| j.name.clone())
            .unwrap_or_else(|| format!("index {}", d.index))
    };
    for (b, (old, new_bus)) in running.buses.iter().zip(&new.buses).enumerate() {
        let mut bus_field = |what: &str, a: String, z: String| {
            if a != z {
                out.push(format!("bus[{b}] {what} {a} → {z}"));
            }
        };
        bus_field(
            "interface",
            format!("{:?}", old.interface),
            format!("{:?}", new_bus.interface),
        );
        bus_field(
            "protocol",
            format!("{:?}", old.protocol),
            format!("{:?}", new_bus.protocol),
        );
        bus_field(
            "host_id",
            old.host_id.to_string(),
            new_bus.host_id.to_string(),
        );
        bus_field(
            "feedback_timeout_ticks",
            old.feedback_timeout_ticks.to_string(),
            new_bus.feedback_timeout_ticks.to_string(),
        );
        bus_field(
            "bitrate",
            old.load.bitrate_bps.to_string(),
            new_bus.load.bitrate_bps.to_string(),
        );
        let old_names: Vec<String> = old.joints.iter().map(|d| name(running, d)).collect();
        let new_names: Vec<String> = new_bus.joints.iter().map(|d| name(new, d)).collect();
        if old_names != new_names {
            out.push(format!("bus[{b}] drives {old_names:?} → {new_names:?}"));
            continue;
        }
        for ((o, n), joint) in old.joints.iter().zip(&new_bus.joints).zip(&old_names) {
            let mut field = |what: &str, a: String, z: String| {
                if a != z {
                    out.push(format!("bus[{b}] joint {joint}: {what} {a} → {z}"));
                }
            };
            field("node_id", o.node_id.to_string(), n.node_id.to_string());
            field("index", o.index.to_string(), n.index.to_string());
            field(
                "command_unit",
                format!("{:?}", o.units.command),
                format!("{:?}", n.units.command),
            );
            field(
                "kt",
                o.units.kt_nm_per_a.to_string(),
                n.units.kt_nm_per_a.to_string(),
            );
            field(
                "gear_ratio",
                o.units.gear_ratio.to_string(),
                n.units.gear_ratio.to_string(),
            );
            field(
                "feedback angle unit",
                format!("{:?}", o.units.feedback_angle),
                format!("{:?}", n.units.feedback_angle),
            );
            if o.reply_units != n.reply_units {
                field(
                    "reply units",
                    format!("{:?}", o.reply_units),
                    format!("{:?}", n.reply_units),
                );
            }
            field("MIT ranges", format!("{:?}", o.mit), format!("{:?}", n.mit));
            field(
                "max_curr",
                o.max_curr_a.to_string(),
                n.max_curr_a.to_string(),
            );
            if o.cia402 != n.cia402 {
                field(
                    "[bus.joint.cia402]",
                    format!("{:?}", o.cia402.map(|x| x.cfg)),
                    format!("{:?}", n.cia402.map(|x| x.cfg)),
                );
            }
        }
    }
    out
}

impl CanBackend {
    /// Opens every configured bus (and the shared-memory ports). Set-up time only.
    pub fn open(cfg: &Config) -> Result<Self, BackendError> {
        let mut socks = Vec::with_capacity(cfg.buses.len());
        for bus in &cfg.buses {
            let (s, strict) = open_socket(&bus.interface)?;
            configure_socket(&s, bus, strict)?;
            socks.push(s);
        }
        Self::with_sockets(cfg, socks)
    }

    /// Like [`Self::open`] with already open sockets, one per `cfg.buses` entry in order (tests
    /// pass socketpair ends). Filters are applied best effort. Sends the enter-mode frames.
    pub fn with_sockets(cfg: &Config, socks: Vec<CanSocket>) -> Result<Self, BackendError> {
        if socks.len() != cfg.buses.len() {
            return Err(BackendError::SocketCount {
                sockets: socks.len(),
                buses: cfg.buses.len(),
            });
        }
        let ipc_cfg = super::shm::ipc_config(cfg);
        match Ipc::cleanup_dead_nodes_for(&ipc_cfg) {
            Ok(n) if n > 0 => tracing::info!("removed resources of {n} dead iceoryx2 node(s)"),
            Ok(_) => {}
            Err(e) => tracing::warn!("dead-node clean-up failed: {e}"),
        }
        let ipc = Ipc::open(&ipc_cfg, "frictiond")?;
        let request = ipc.torque_request().and_then(|c| c.inbox())?;
        let command = ipc.motor_current_command().and_then(|c| c.outbox())?;
        let status_out = ipc.daemon_status().and_then(|c| c.outbox())?;
        let mut states = JointStates::zeroed();
        let mut buses = Vec::with_capacity(socks.len());
        for (bus, sock) in cfg.buses.iter().zip(socks) {
            configure_socket(&sock, bus, false)?;
            let mut drives: Vec<Drive> = bus
                .joints
                .iter()
                .map(|d| {
                    states.n_joints = states.n_joints.max(d.index as u32 + 1);
                    // Until the first feedback frame the joint is stale.
                    states.fault_flags[d.index] = FAULT_FEEDBACK_STALE;
                    states.tau_meas_nm[d.index] = f64::NAN; // no torque sensor on the bus
                    Drive {
                        cfg: *d,
                        last_fb_tick: None,
                        last_enter_tick: 0,
                        heartbeat: None,
                        was_valid: false,
                        was_stale: true,
                        co: None,
                    }
                })
                .collect();
            if bus.protocol == CanProtocol::Cia402 {
                let period_us = cfg.raw.loop_.period_us;
                for d in &mut drives {
                    d.co = Some(cia402::configure(&sock, &bus.interface, &d.cfg, period_us)?);
                }
                cia402::start_all(&sock, drives.iter().map(|d| d.cfg.node_id as u8));
            }
            buses.push(Bus {
                sock,
                protocol: bus.protocol,
                host_id: bus.host_id,
                timeout_ticks: bus.feedback_timeout_ticks,
                drives,
            });
            tracing::info!(
                "CAN bus {} ({:?}): {}",
                bus.interface,
                bus.protocol,
                bus.load
            );
        }
        let shared = Arc::new(SharedCounters::default());
        let logger_stop = Arc::new(AtomicBool::new(false));
        let logger = {
            let shared = shared.clone();
            let stop = logger_stop.clone();
            let names: Vec<String> = cfg.buses.iter().map(|b| b.interface.clone()).collect();
            std::thread::Builder::new()
                .name("frictiond-canlog".into())
                .spawn(move || log_counters(&shared, &stop, &names))
                .map_err(BackendError::LoggerThread)?
        };
        let n_links = buses.len() as u32;
        let mut me = Self {
            buses,
            states,
            status: DaemonStatus::zeroed(),
            counters: BusCounters::new(BusKind::Can, n_links),
            tick: 0,
            _ipc: ipc,
            request,
            command,
            status_out,
            shared,
            logger_stop,
            logger: Some(logger),
        };
        me.counters.stale_feedback_mask = me.configured_mask();
        for b in 0..me.buses.len() {
            for d in 0..me.buses[b].drives.len() {
                me.enter(b, d);
            }
        }
        Ok(me)
    }

    /// Bit set of the joints on any bus.
    fn configured_mask(&self) -> u64 {
        self.buses
            .iter()
            .flat_map(|b| b.drives.iter())
            .fold(0, |m, d| m | 1u64 << d.cfg.index)
    }

    /// Sends a frame, counting the outcome; never blocks or retries.
    #[inline]
    fn send(sock: &CanSocket, counters: &mut BusCounters, f: Result<WireFrame, CanCodecError>) {
        let Ok(Ok(frame)) = f.map(CanFrame::try_from) else {
            counters.io_errors += 1;
            return;
        };
        match sock.write_frame(&frame) {
            Ok(()) => counters.tx_messages += 1,
            Err(e) if is_full_or_empty(&e) => counters.tx_dropped += 1,
            Err(_) => counters.io_errors += 1,
        }
    }

    /// Sends the enter-mode sequence of drive `d` on bus `b`.
    fn enter(&mut self, b: usize, d: usize) {
        let bus = &mut self.buses[b];
        let drive = &mut bus.drives[d];
        drive.last_enter_tick = self.tick;
        let node = drive.cfg.node_id;
        match bus.protocol {
            // Configured and started at open; the controlword sequencing enables it.
            CanProtocol::Cia402 => {}
            CanProtocol::Mit => Self::send(
                &bus.sock,
                &mut self.counters,
                mit::encode_special(node, MitSpecial::EnterMotorMode),
            ),
            CanProtocol::Odrive => {
                let n = node as u8;
                Self::send(
                    &bus.sock,
                    &mut self.counters,
                    odrive::encode(n, &OdriveMsg::SetInputTorque { torque_nm: 0.0 }),
                );
                Self::send(
                    &bus.sock,
                    &mut self.counters,
                    odrive::encode(
                        n,
                        &OdriveMsg::SetControllerMode {
                            control_mode: odrive::CONTROL_MODE_TORQUE,
                            input_mode: odrive::INPUT_MODE_PASSTHROUGH,
                        },
                    ),
                );
                Self::send(
                    &bus.sock,
                    &mut self.counters,
                    odrive::encode(
                        n,
                        &OdriveMsg::SetAxisState {
                            requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
                        },
                    ),
                );
            }
        }
    }

    /// Decodes one received data frame of bus `b` into the states; returns whether it was feedback
    /// we own.
    #[inline]
    fn accept(&mut self, b: usize, f: &WireFrame) -> bool {
        let bus = &mut self.buses[b];
        let st = &mut self.states;
        match bus.protocol {
            CanProtocol::Cia402 => {
                if f.extended || f.rtr {
                    return false;
                }
                let node = f.id & 0x7F;
                let Some(d) = bus.drives.iter_mut().find(|d| d.cfg.node_id == node) else {
                    return false;
                };
                let Some(c) = d.co.as_mut() else {
                    return false;
                };
                let k = d.cfg.index;
                let u = d.cfg.units;
                let (owned, feedback, emcy) =
                    c.accept(f, self.tick, st, k, u.gear_ratio, u.kt_nm_per_a);
                if feedback {
                    d.last_fb_tick = Some(self.tick);
                }
                if emcy {
                    self.counters.detail[CAN_DETAIL_EMCY] += 1;
                    self.shared.last_emcy.store(
                        u64::from(c.node) << 16 | u64::from(c.last_emcy),
                        Ordering::Relaxed,
                    );
                }
                owned
            }
            CanProtocol::Mit => {
                if f.id != bus.host_id || f.extended || f.rtr || f.len < 6 {
                    return false;
                }
                let Some(d) = bus
                    .drives
                    .iter_mut()
                    .find(|d| d.cfg.node_id == u32::from(f.data[0]))
                else {
                    return false;
                };
                let Some(r) = d.cfg.mit else { return false };
                let Ok(rep) = mit::decode_reply(f, &r) else {
                    return false;
                };
                let k = d.cfg.index;
                let u = &d.cfg.units;
                st.theta_motor_rad[k] = u.motor_rad(rep.p_rad);
                st.omega_motor_rad_s[k] = u.motor_rad(rep.v_rad_s);
                st.s_rad[k] = u.joint_position_rad(rep.p_rad);
                st.sdot_rad_s[k] = u.joint_velocity_rad_s(rep.v_rad_s);
                st.current_a[k] = d.cfg.reply_units.current_from_command(rep.i_a);
                d.last_fb_tick = Some(self.tick);
                true
            }
            CanProtocol::Odrive => {
                let Ok((node, msg)) = odrive::decode(f) else {
                    return false;
                };
                let Some(d) = bus
                    .drives
                    .iter_mut()
                    .find(|d| d.cfg.node_id == u32::from(node))
                else {
                    return false;
                };
                let k = d.cfg.index;
                let u = &d.cfg.units;
                match msg {
                    OdriveMsg::EncoderEstimates { pos_rev, vel_rev_s } => {
                        let (p, v) = (f64::from(pos_rev), f64::from(vel_rev_s));
                        st.theta_motor_rad[k] = u.motor_rad(p);
                        st.omega_motor_rad_s[k] = u.motor_rad(v);
                        st.s_rad[k] = u.joint_position_rad(p);
                        st.sdot_rad_s[k] = u.joint_velocity_rad_s(v);
                        d.last_fb_tick = Some(self.tick);
                        true
                    }
                    OdriveMsg::Iq { iq_measured_a, .. } => {
                        st.current_a[k] = f64::from(iq_measured_a);
                        true
                    }
                    OdriveMsg::Heartbeat {
                        axis_error,
                        axis_state,
                        ..
                    } => {
                        d.heartbeat = Some((axis_error, axis_state));
                        true
                    }
                    _ => false,
                }
            }
        }
    }

    /// Counts one error frame by class.
    #[inline]
    fn count_error(&mut self, class: u32, data: &[u8]) {
        let c = &mut self.counters;
        c.error_reports += 1;
        if class & CAN_ERR_BUSOFF != 0 {
            c.link_down += 1;
        }
        if class & CAN_ERR_CRTL != 0
            && data
                .get(1)
                .is_some_and(|&x| x & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE) != 0)
        {
            c.detail[CAN_DETAIL_ERROR_PASSIVE] += 1;
        }
    }

    /// The current bus counters (also in every published status).
    pub fn counters(&self) -> BusCounters {
        self.counters
    }
}

impl Backend for CanBackend {
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError> {
        self.tick += 1;
        let mut any = false;
        for b in 0..self.buses.len() {
            for _ in 0..MAX_FRAMES_PER_TICK {
                let frame = match self.buses[b].sock.read_frame() {
                    Ok(f) => f,
                    Err(e) if is_full_or_empty(&e) => break,
                    Err(_) => {
                        self.counters.io_errors += 1;
                        break;
                    }
                };
                match &frame {
                    CanFrame::Error(e) => {
                        let class = e.error_bits();
                        let mut data = [0u8; 8];
                        let n = e.data().len().min(8);
                        data[..n].copy_from_slice(&e.data()[..n]);
                        self.count_error(class, &data[..n]);
                    }
                    f => {
                        if let Ok(w) = WireFrame::try_from(f)
                            && self.accept(b, &w)
                        {
                            self.counters.rx_messages += 1;
                            any = true;
                        }
                    }
                }
            }
        }
        // Per-joint freshness and drive faults; re-arm silent or idle drives now and then.
        let mut stale = 0u64;
        for b in 0..self.buses.len() {
            for d in 0..self.buses[b].drives.len() {
                let bus = &self.buses[b];
                let drive = &bus.drives[d];
                let k = drive.cfg.index;
                let is_stale = drive
                    .last_fb_tick
                    .is_none_or(|t| self.tick - t > bus.timeout_ticks)
                    || drive.co.is_some_and(|c| c.heartbeat_stale(self.tick));
                let drive_fault = match drive.heartbeat {
                    Some((err, state)) => {
                        err != 0 || u32::from(state) != odrive::AXIS_STATE_CLOSED_LOOP_CONTROL
                    }
                    None => false,
                } || drive.co.is_some_and(|c| c.faulted());
                let mut flags = self.states.fault_flags[k] & !(FAULT_FEEDBACK_STALE | FAULT_DRIVE);
                if is_stale {
                    flags |= FAULT_FEEDBACK_STALE;
                    stale |= 1u64 << k;
                }
                if drive_fault {
                    flags |= FAULT_DRIVE;
                }
                self.states.fault_flags[k] = flags;
                // An MIT drive answers in rest mode too (and ignores torque commands there): one
                // that answers again after silence — it started after our enable edge, or reset —
                // is re-entered at once, not only at the next enable edge.
                let (rearm, answers_again) = match bus.protocol {
                    CanProtocol::Cia402 => (false, false),
                    CanProtocol::Mit => (is_stale, drive.was_stale && !is_stale),
                    CanProtocol::Odrive => (
                        drive.heartbeat.is_some_and(|(err, state)| {
                            err == 0 && u32::from(state) != odrive::AXIS_STATE_CLOSED_LOOP_CONTROL
                        }),
                        false,
                    ),
                };
                self.buses[b].drives[d].was_stale = is_stale;
                let since_enter = self.tick - self.buses[b].drives[d].last_enter_tick;
                if answers_again || (rearm && since_enter >= REENTER_EVERY_TICKS) {
                    self.enter(b, d);
                }
            }
        }
        let mask_changed = stale != self.counters.stale_feedback_mask;
        self.counters.stale_feedback_mask = stale;
        self.shared.store(&self.counters);
        if any || mask_changed {
            self.states.seq += 1;
            self.states.stamp_ns = monotonic_ns();
            Ok(Some(self.states))
        } else {
            Ok(None)
        }
    }

    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError> {
        self.request.latest()
    }

    fn publish_command(&mut self, cmd: &MotorCurrentCommand) -> Result<(), IoError> {
        for bus in &mut self.buses {
            for d in &mut bus.drives {
                let k = d.cfg.index;
                let valid = cmd.is_valid(k);
                // An MIT drive reports no mode: on every enable edge send enter-motor-mode first, so
                // a drive that started after us or idled on a timeout applies the command.
                if valid && !d.was_valid && bus.protocol == CanProtocol::Mit {
                    d.last_enter_tick = self.tick;
                    let enter = mit::encode_special(d.cfg.node_id, MitSpecial::EnterMotorMode);
                    Self::send(&bus.sock, &mut self.counters, enter);
                }
                d.was_valid = valid;
                let i = cmd.i_ref_a[k];
                let i_a = if valid && i.is_finite() {
                    i.clamp(-d.cfg.max_curr_a, d.cfg.max_curr_a)
                } else {
                    0.0
                };
                let value = d.cfg.units.command_from_current(i_a);
                let frame = match bus.protocol {
                    CanProtocol::Cia402 => match d.co.as_mut() {
                        Some(c) => c
                            .rpdo(value, cia402::Goal::Enabled)
                            .ok_or(CanCodecError::NonFinite { field: "rpdo" }),
                        None => Err(CanCodecError::NonFinite { field: "cia402" }),
                    },
                    CanProtocol::Mit => match d.cfg.mit {
                        Some(r) => {
                            mit::encode_command(d.cfg.node_id, &MitCommand::torque(value), &r)
                                .map(|(f, _sat)| f)
                        }
                        None => Err(CanCodecError::NonFinite { field: "mit" }),
                    },
                    CanProtocol::Odrive => odrive::encode(
                        d.cfg.node_id as u8,
                        &OdriveMsg::SetInputTorque {
                            torque_nm: value as f32,
                        },
                    ),
                };
                Self::send(&bus.sock, &mut self.counters, frame);
            }
            // CiA 402: frictiond is the SYNC producer; RPDOs (transmission type 1) apply at it.
            if bus.protocol == CanProtocol::Cia402 {
                Self::send(
                    &bus.sock,
                    &mut self.counters,
                    Ok(frictionless_drives::can::cia402::encode_sync(None)),
                );
            }
        }
        self.shared.store(&self.counters);
        // iceoryx2 0.10 allocates one 48-byte Box per loaned sample (measured; see the shm backend).
        alloc_count::exempt(|| self.command.publish(cmd))
    }

    fn publish_status(&mut self, status: &DaemonStatus) -> Result<(), IoError> {
        self.status = *status;
        self.status.bus = self.counters;
        let s = &self.status;
        alloc_count::exempt(|| self.status_out.publish(s))
    }

    fn wait_input(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        // ppoll on every bus socket in slices of ≤ 200 µs; between slices peek at the request
        // listener: either kind of input wakes the lockstep tick.
        let mut fds = [libc::pollfd {
            fd: -1,
            events: 0,
            revents: 0,
        }; crate::config::MAX_BUSES];
        let n = self.buses.len().min(fds.len());
        for (p, b) in fds.iter_mut().zip(&self.buses) {
            p.fd = b.sock.as_raw_fd();
            p.events = libc::POLLIN;
        }
        let deadline = monotonic_ns().saturating_add(timeout_ns);
        loop {
            let slice = deadline.saturating_sub(monotonic_ns()).min(200_000);
            let ts = libc::timespec {
                tv_sec: 0,
                tv_nsec: slice as _,
            };
            // SAFETY: `fds[..n]` are valid pollfd entries; `ts` outlives the call.
            let rc = unsafe { libc::ppoll(fds.as_mut_ptr(), n as _, &ts, std::ptr::null()) };
            if rc > 0 {
                return Ok(true);
            }
            if self.request.wait(Duration::ZERO)? {
                return Ok(true);
            }
            if monotonic_ns() >= deadline {
                return Ok(false);
            }
        }
    }

    fn bus_counters(&self) -> BusCounters {
        self.counters
    }
}

impl Drop for CanBackend {
    fn drop(&mut self) {
        // CiA 402: quick stop with 0 torque for a few SYNC cycles, then NMT stop.
        for bus in &mut self.buses {
            if bus.protocol != CanProtocol::Cia402 {
                continue;
            }
            for _ in 0..cia402::STOP_CYCLES {
                for d in &mut bus.drives {
                    if let Some(c) = d.co.as_mut() {
                        let f = c.rpdo(0.0, cia402::Goal::QuickStop);
                        Self::send(
                            &bus.sock,
                            &mut self.counters,
                            f.ok_or(CanCodecError::NonFinite { field: "rpdo" }),
                        );
                    }
                }
                Self::send(
                    &bus.sock,
                    &mut self.counters,
                    Ok(frictionless_drives::can::cia402::encode_sync(None)),
                );
                std::thread::sleep(Duration::from_millis(1));
            }
            for d in &bus.drives {
                let stop = frictionless_drives::can::cia402::encode_nmt(
                    frictionless_drives::can::cia402::NmtCommand::Stop,
                    d.cfg.node_id as u8,
                );
                Self::send(&bus.sock, &mut self.counters, stop);
            }
        }
        // Zero torque, then leave motor mode / idle the axis.
        for bus in &self.buses {
            for d in &bus.drives {
                let node = d.cfg.node_id;
                match (bus.protocol, d.cfg.mit) {
                    (CanProtocol::Mit, Some(r)) => {
                        let zero =
                            mit::encode_command(node, &MitCommand::torque(0.0), &r).map(|(f, _)| f);
                        Self::send(&bus.sock, &mut self.counters, zero);
                        let exit = mit::encode_special(node, MitSpecial::ExitMotorMode);
                        Self::send(&bus.sock, &mut self.counters, exit);
                    }
                    (CanProtocol::Mit, None) | (CanProtocol::Cia402, _) => {}
                    (CanProtocol::Odrive, _) => {
                        let n = node as u8;
                        let zero = OdriveMsg::SetInputTorque { torque_nm: 0.0 };
                        Self::send(&bus.sock, &mut self.counters, odrive::encode(n, &zero));
                        let idle = OdriveMsg::SetAxisState {
                            requested_state: odrive::AXIS_STATE_IDLE,
                        };
                        Self::send(&bus.sock, &mut self.counters, odrive::encode(n, &idle));
                    }
                }
            }
        }
        self.logger_stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.logger.take() {
            let _ = h.join();
        }
    }
}

/// The logger thread: logs counter changes at most once per second (never on the RT thread).
fn log_counters(c: &SharedCounters, stop: &AtomicBool, buses: &[String]) {
    let mut last = c.load();
    let mut waited = Duration::ZERO;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        waited += Duration::from_millis(50);
        if waited < Duration::from_secs(1) {
            continue;
        }
        waited = Duration::ZERO;
        let now = c.load();
        if now == last {
            continue;
        }
        let d = |k: usize| now[k].saturating_sub(last[k]);
        if d(0) + d(1) + d(2) > 0 {
            tracing::warn!(
                "CAN {buses:?}: +{} error frames (+{} bus-off, +{} error-passive); totals {} / {} / {}",
                d(0),
                d(1),
                d(2),
                now[0],
                now[1],
                now[2]
            );
        }
        if d(3) + d(4) > 0 {
            tracing::warn!(
                "CAN {buses:?}: +{} frames dropped (TX queue full), +{} socket errors; totals {} / {}",
                d(3),
                d(4),
                now[3],
                now[4]
            );
        }
        if now[6] != last[6] {
            let (node, code) = (now[7] >> 16, (now[7] & 0xFFFF) as u16);
            tracing::warn!(
                "CAN {buses:?}: +{} CiA 402 EMCY (total {}); last: node {node} error code {code:#06X} ({})",
                d(6),
                now[6],
                frictionless_drives::can::cia402::emcy_text(code)
            );
        }
        if now[5] != last[5] {
            tracing::warn!(
                "CAN {buses:?}: joints with stale drive feedback (bit mask) {:#x} (was {:#x})",
                now[5],
                last[5]
            );
        }
        last = now;
    }
}

#[cfg(test)]
mod tests {
    //! The backend's I/O over `socketpair(AF_UNIX, SOCK_SEQPACKET)` sockets wrapped as real
    //! `socketcan::CanSocket`s (one write = one 16-byte datagram, as on AF_CAN): the test holds the
    //! drive end and speaks the protocol with the `frictionless_drives::can` codecs.

    use super::*;
    use frictionless_drives::can::mit::{MitRanges, MitReply, MitRx};
    use frictionless_shm_types::{DaemonStatus, IpcConfig};
    use socketcan::CanErrorFrame;

    pub(super) fn pair() -> (CanSocket, CanSocket) {
        let mut fds = [0; 2];
        // SAFETY: fds is a valid 2-element array; on success both fds are new and owned by us.
        let rc = unsafe {
            libc::socketpair(
                libc::AF_UNIX,
                libc::SOCK_SEQPACKET | libc::SOCK_CLOEXEC,
                0,
                fds.as_mut_ptr(),
            )
        };
        assert_eq!(rc, 0, "socketpair: {}", std::io::Error::last_os_error());
        // SAFETY: the fds were just created and are not owned elsewhere.
        unsafe {
            (
                CanSocket::from(OwnedFd::from_raw_fd(fds[0])),
                CanSocket::from(OwnedFd::from_raw_fd(fds[1])),
            )
        }
    }

    pub(super) struct Env {
        dir: std::path::PathBuf,
        pub(super) cfg: Config,
    }

    impl Drop for Env {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }

    pub(super) fn env(tag: &str, body: &str) -> Env {
        let id = format!("fldcan_{tag}_{}_{}", std::process::id(), monotonic_ns());
        let dir = std::env::temp_dir().join(&id);
        std::fs::create_dir_all(&dir).unwrap();
        let text = format!(
            "[backend]\nkind = \"can\"\nservice_prefix = \"{id}\"\nroot_path = \"{}\"\n{body}",
            dir.display()
        );
        let cfg = crate::config::parse(&dir.join("t.toml"), &text).unwrap();
        Env { dir, cfg }
    }

    const MIT2: &str = r#"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"
[[joint]]
name = "hip"
index = 2
gear_ratio = 50.0
kt = 0.1
max_curr = 4.0
friction_model = "none"
[[bus]]
interface = "vcan0"
bitrate = 1000000
protocol = "mit"
host_id = 0
feedback_timeout_ticks = 3
[[bus.joint]]
joint = "knee"
node_id = 1
command_unit = "motor_torque"
p_max = 12.5
v_max = 65.0
t_max = 1.0
i_max = 40.0
[[bus.joint]]
joint = "hip"
node_id = 2
command_unit = "current"
p_max = 12.5
v_max = 65.0
t_max = 10.0
i_max = 40.0
"#;

    fn recv(s: &CanSocket) -> WireFrame {
        let f = s.read_frame_timeout(Duration::from_secs(5)).unwrap();
        WireFrame::try_from(&f).unwrap()
    }

    fn send(s: &CanSocket, f: WireFrame) {
        s.write_frame(&CanFrame::try_from(f).unwrap()).unwrap();
    }

    fn ranges(t_max: f64) -> MitRanges {
        MitRanges {
            t_min_nm: -t_max,
            t_max_nm: t_max,
            ..MitRanges::MINI_CHEETAH
        }
    }

    fn mit_reply(drive: &CanSocket, id: u8, p: f64, v: f64, i: f64, t_max: f64) {
        let rep = MitReply {
            motor_id: id,
            p_rad: p,
            v_rad_s: v,
            i_a: i,
        };
        send(drive, mit::encode_reply(0, &rep, &ranges(t_max)).unwrap().0);
    }

    /// (motor id, t_ff) of the next command frame.
    fn mit_cmd(drive: &CanSocket) -> (u32, MitRx) {
        let f = recv(drive);
        let t_max = if f.id == 1 { 1.0 } else { 10.0 };
        (f.id, mit::decode_command(&f, &ranges(t_max)).unwrap())
    }

    fn torque(rx: MitRx) -> f64 {
        match rx {
            MitRx::Command(c) => {
                assert_eq!((c.kp_nm_rad, c.kd_nm_s_rad), (0.0, 0.0), "pure torque");
                c.t_ff_nm
            }
            MitRx::Special(s) => panic!("special frame {s:?}"),
        }
    }

    #[test]
    fn mit_feedback_maps_to_joint_side_and_commands_to_the_drive_unit() {
        let e = env("mit", MIT2);
        let (host, drive) = pair();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        // Open enters motor mode on both drives.
        for id in [1, 2] {
            assert_eq!(
                mit_cmd(&drive),
                (id, MitRx::Special(MitSpecial::EnterMotorMode))
            );
        }
        // No feedback yet: nothing new, both joints stale from the start.
        assert!(b.read_states().unwrap().is_none());
        assert_eq!(b.bus_counters().stale_feedback_mask, 0b101);

        mit_reply(&drive, 1, 2.0, -10.0, 3.0, 1.0);
        mit_reply(&drive, 2, -1.0, 5.0, -7.5, 10.0);
        // A frame for a motor we do not drive is ignored.
        mit_reply(&drive, 9, 1.0, 1.0, 1.0, 1.0);
        let st = b.read_states().unwrap().expect("feedback decoded");
        let q = MitRanges::MINI_CHEETAH.steps();
        let near = |a: f64, b: f64, tol: f64| assert!((a - b).abs() <= tol, "{a} vs {b}");
        near(st.theta_motor_rad[0], 2.0, q[0]);
        near(st.s_rad[0], 2.0 / -100.0, q[0] / 100.0);
        near(st.sdot_rad_s[0], -10.0 / -100.0, q[1] / 100.0);
        near(st.omega_motor_rad_s[0], -10.0, q[1]);
        near(st.current_a[0], 3.0, q[5]);
        near(st.s_rad[2], -1.0 / 50.0, q[0] / 50.0);
        near(st.sdot_rad_s[2], 5.0 / 50.0, q[1] / 50.0);
        near(st.current_a[2], -7.5, q[5]);
        assert_eq!((st.fault_flags[0], st.fault_flags[2]), (0, 0));
        assert_eq!(st.n_joints, 3);
        assert!(st.tau_meas_nm[0].is_nan(), "no torque sensor on the bus");
        assert_eq!(b.bus_counters().stale_feedback_mask, 0);
        assert_eq!(b.bus_counters().rx_messages, 2);
        // First replies after silence: enter motor mode again (a drive that answers may be in rest
        // mode — it started after open's frames, or reset).
        for id in [1, 2] {
            assert_eq!(
                mit_cmd(&drive),
                (id, MitRx::Special(MitSpecial::EnterMotorMode))
            );
        }

        // Commands: knee in motor torque kt·i, hip in amperes; invalid, NaN and over-limit cases.
        let mut cmd = MotorCurrentCommand::zeroed();
        cmd.valid_mask = 0b101;
        cmd.i_ref_a[0] = 2.5;
        cmd.i_ref_a[2] = -3.25;
        b.publish_command(&cmd).unwrap();
        // Enable edge: enter motor mode again, then the command, per drive.
        assert_eq!(
            mit_cmd(&drive),
            (1, MitRx::Special(MitSpecial::EnterMotorMode))
        );
        let (id, rx) = mit_cmd(&drive);
        assert_eq!(id, 1);
        near(
            torque(rx),
            0.157 * 2.5,
            ranges(1.0).steps()[4] / 2.0 + 1e-12,
        );
        assert_eq!(
            mit_cmd(&drive),
            (2, MitRx::Special(MitSpecial::EnterMotorMode))
        );
        let (id, rx) = mit_cmd(&drive);
        assert_eq!(id, 2);
        near(torque(rx), -3.25, ranges(10.0).steps()[4] / 2.0 + 1e-12);
        cmd.valid_mask = 0b001;
        cmd.i_ref_a[0] = 99.0; // clamped to max_curr = 5 A → 0.785 Nm
        b.publish_command(&cmd).unwrap();
        near(
            torque(mit_cmd(&drive).1),
            0.157 * 5.0,
            ranges(1.0).steps()[4] / 2.0 + 1e-12,
        );
        near(
            torque(mit_cmd(&drive).1),
            0.0,
            ranges(10.0).steps()[4] / 2.0 + 1e-12,
        );
        cmd.i_ref_a[0] = f64::NAN;
        b.publish_command(&cmd).unwrap();
        near(
            torque(mit_cmd(&drive).1),
            0.0,
            ranges(1.0).steps()[4] / 2.0 + 1e-12,
        );
        let _ = mit_cmd(&drive);
        // Re-enabling the hip is an edge again.
        cmd.valid_mask = 0b101;
        cmd.i_ref_a[0] = 0.0;
        b.publish_command(&cmd).unwrap();
        let _ = mit_cmd(&drive);
        assert_eq!(
            mit_cmd(&drive),
            (2, MitRx::Special(MitSpecial::EnterMotorMode))
        );
        let _ = mit_cmd(&drive);
        assert_eq!(b.bus_counters().tx_messages, 2 + 2 + 2 + 6 + 3);
        drop(b);
        // Drop: zero torque, then exit motor mode, per drive.
        near(torque(mit_cmd(&drive).1), 0.0, 1e-3);
        assert_eq!(
            mit_cmd(&drive),
            (1, MitRx::Special(MitSpecial::ExitMotorMode))
        );
        near(torque(mit_cmd(&drive).1), 0.0, 1e-2);
        assert_eq!(
            mit_cmd(&drive),
            (2, MitRx::Special(MitSpecial::ExitMotorMode))
        );
    }

    #[test]
    fn silent_drive_goes_stale_alone_and_recovers() {
        let e = env("stale", MIT2);
        let (host, drive) = pair();
        drive.set_nonblocking(true).unwrap();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        let mut last = None;
        for tick in 1..=20u32 {
            mit_reply(&drive, 1, 0.1, 0.0, 0.0, 1.0);
            // The hip drive answers only for the first 5 ticks and after tick 15.
            if !(6..=15).contains(&tick) {
                mit_reply(&drive, 2, 0.2, 0.0, 0.0, 10.0);
            }
            let st = b.read_states().unwrap().expect("knee feedback every tick");
            let mask = b.bus_counters().stale_feedback_mask;
            // Timeout 3 ticks: silent since tick 6 → stale from tick 9 (9 − 5 > 3) to tick 15.
            let want_stale = (9..=15).contains(&tick);
            assert_eq!(mask, if want_stale { 0b100 } else { 0 }, "tick {tick}");
            assert_eq!(
                st.fault_flags[2],
                if want_stale { FAULT_FEEDBACK_STALE } else { 0 },
                "tick {tick}"
            );
            assert_eq!(st.fault_flags[0], 0);
            assert!(last.is_none_or(|s| st.seq > s));
            last = Some(st.seq);
        }
    }

    /// Enter-motor-mode frames the drive end has received so far, by motor id (others drained).
    fn enters(drive: &CanSocket) -> Vec<u32> {
        let mut ids = Vec::new();
        while let Ok(f) = drive.read_frame() {
            let w = WireFrame::try_from(&f).unwrap();
            let t_max = if w.id == 1 { 1.0 } else { 10.0 };
            if mit::decode_command(&w, &ranges(t_max))
                == Ok(MitRx::Special(MitSpecial::EnterMotorMode))
            {
                ids.push(w.id);
            }
        }
        ids
    }

    /// The race a closed loop met in the CAN VM: the joint was enabled (edge → enter-motor-mode)
    /// before the drive listened; the drive then answered our torque commands from rest mode, never
    /// applying them. Its first reply — and the first after any silence — re-enters it at once.
    #[test]
    fn mit_drive_answering_after_silence_is_entered_again_at_once() {
        let e = env("late", MIT2);
        let (host, drive) = pair();
        drive.set_nonblocking(true).unwrap();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        let mut cmd = MotorCurrentCommand::zeroed();
        cmd.valid_mask = 0b101;
        cmd.i_ref_a[0] = 1.0;
        // Enabled while nobody answers: open's and the edge's frames go unheard.
        for _ in 0..5 {
            assert!(b.read_states().unwrap().is_none());
            b.publish_command(&cmd).unwrap();
        }
        assert_eq!(enters(&drive), [1, 2, 1, 2], "open, then the enable edge");
        // Only the knee's drive wakes up: it alone is entered, once, on its first reply.
        mit_reply(&drive, 1, 0.0, 0.0, 0.0, 1.0);
        b.read_states().unwrap().expect("knee feedback");
        b.publish_command(&cmd).unwrap();
        assert_eq!(enters(&drive), [1]);
        for _ in 0..3 {
            mit_reply(&drive, 1, 0.0, 0.0, 0.0, 1.0);
            b.read_states().unwrap().expect("knee feedback");
            b.publish_command(&cmd).unwrap();
        }
        assert_eq!(enters(&drive), [0u32; 0], "answering drive: no repeats");
        // Silent past the timeout (3 ticks), then back: entered again on the first reply.
        for _ in 0..5 {
            b.read_states().unwrap();
            b.publish_command(&cmd).unwrap();
        }
        assert_eq!(b.bus_counters().stale_feedback_mask & 1, 1);
        assert_eq!(
            enters(&drive),
            [0u32; 0],
            "re-arm while stale waits REENTER_EVERY_TICKS"
        );
        mit_reply(&drive, 1, 0.0, 0.0, 0.0, 1.0);
        b.read_states().unwrap().expect("knee feedback");
        assert_eq!(b.bus_counters().stale_feedback_mask & 1, 0);
        assert_eq!(enters(&drive), [1]);
    }

    #[test]
    fn error_frames_are_counted_by_class_and_reach_the_status() {
        let e = env("err", MIT2);
        let (host, drive) = pair();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        let bus_off = CanErrorFrame::new_error(CAN_ERR_BUSOFF, &[]).unwrap();
        let passive =
            CanErrorFrame::new_error(CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_TX_PASSIVE]).unwrap();
        let warning = CanErrorFrame::new_error(CAN_ERR_CRTL, &[0, 0x08]).unwrap();
        for f in [bus_off, passive, warning, passive] {
            drive.write_frame(&CanFrame::Error(f)).unwrap();
        }
        assert!(
            b.read_states().unwrap().is_none(),
            "error frames are not feedback"
        );
        let c = b.bus_counters();
        assert_eq!(
            (
                c.error_reports,
                c.link_down,
                c.detail[CAN_DETAIL_ERROR_PASSIVE]
            ),
            (4, 1, 2)
        );
        assert_eq!((c.bus_kind(), c.links), (Some(BusKind::Can), 1));
        // The status carries the counters (the RT loop does not need to know about them).
        let ipc_cfg = IpcConfig {
            root_path: e.cfg.root_path.clone(),
            service_prefix: e.cfg.raw.backend.service_prefix.clone(),
        };
        let ipc = Ipc::open(&ipc_cfg, "test").unwrap();
        let inbox = ipc.daemon_status().unwrap().inbox().unwrap();
        let mut s = DaemonStatus::zeroed();
        s.ticks = 77;
        b.publish_status(&s).unwrap();
        let got = inbox
            .wait_latest(Duration::from_secs(5))
            .unwrap()
            .expect("status");
        assert_eq!(got.ticks, 77);
        assert_eq!((got.bus.error_reports, got.bus.link_down), (4, 1));
        assert_eq!(got.bus.stale_feedback_mask, 0b101);
    }

    #[test]
    fn full_tx_queue_counts_drops_and_never_blocks() {
        let e = env("full", MIT2);
        let (host, drive) = pair();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        let mut cmd = MotorCurrentCommand::zeroed();
        cmd.valid_mask = 0b101;
        // Nobody reads the drive end: the socket buffer fills, then sends fail with EAGAIN.
        for _ in 0..20_000 {
            b.publish_command(&cmd).unwrap();
            if b.bus_counters().tx_dropped > 100 {
                break;
            }
        }
        let c = b.bus_counters();
        assert!(c.tx_dropped > 100, "{c:?}");
        assert!(c.tx_messages > 0);
        assert_eq!(c.io_errors, 0);
        drop(drive);
    }

    const ODRIVE: &str = r#"
[[joint]]
name = "ankle"
index = 1
gear_ratio = -160.0
kt = 0.0665
max_curr = 3.0
friction_model = "none"
[[bus]]
interface = "vcan1"
bitrate = 1000000
protocol = "odrive"
[[bus.joint]]
joint = "ankle"
node_id = 5
command_unit = "joint_torque"
"#;

    #[test]
    fn odrive_feedback_heartbeat_faults_and_joint_torque_commands() {
        let e = env("odrive", ODRIVE);
        let (host, drive) = pair();
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        let dec = |d: &CanSocket| odrive::decode(&recv(d)).unwrap();
        assert_eq!(
            dec(&drive),
            (5, OdriveMsg::SetInputTorque { torque_nm: 0.0 })
        );
        assert!(matches!(
            dec(&drive),
            (
                5,
                OdriveMsg::SetControllerMode {
                    control_mode: 1,
                    input_mode: 1
                }
            )
        ));
        assert_eq!(
            dec(&drive),
            (5, OdriveMsg::SetAxisState { requested_state: 8 })
        );
        let tx = |m: OdriveMsg| send(&drive, odrive::encode(5, &m).unwrap());
        tx(OdriveMsg::EncoderEstimates {
            pos_rev: -8.0,
            vel_rev_s: 1.5,
        });
        tx(OdriveMsg::Iq {
            iq_setpoint_a: 1.0,
            iq_measured_a: 0.75,
        });
        // Another node's frames are not ours.
        send(
            &drive,
            odrive::encode(
                6,
                &OdriveMsg::EncoderEstimates {
                    pos_rev: 1.0,
                    vel_rev_s: 1.0,
                },
            )
            .unwrap(),
        );
        let st = b.read_states().unwrap().unwrap();
        let tau = std::f64::consts::TAU;
        assert!((st.s_rad[1] - (-8.0 * tau / -160.0)).abs() < 1e-9);
        assert!((st.sdot_rad_s[1] - (1.5 * tau / -160.0)).abs() < 1e-9);
        assert!((st.theta_motor_rad[1] - (-8.0 * tau)).abs() < 1e-9);
        assert_eq!(st.current_a[1], 0.75);
        assert_eq!(st.fault_flags[1], 0);
        // Heartbeat with an axis error → drive fault; healthy closed loop → clear.
        tx(OdriveMsg::Heartbeat {
            axis_error: 0x40,
            axis_state: 8,
            status: [0; 3],
        });
        assert_eq!(
            b.read_states().unwrap().unwrap().fault_flags[1],
            FAULT_DRIVE
        );
        tx(OdriveMsg::Heartbeat {
            axis_error: 0,
            axis_state: 8,
            status: [0; 3],
        });
        assert_eq!(b.read_states().unwrap().unwrap().fault_flags[1], 0);
        // Joint torque command: r·kt·i.
        let mut cmd = MotorCurrentCommand::zeroed();
        cmd.valid_mask = 0b10;
        cmd.i_ref_a[1] = 1.25;
        b.publish_command(&cmd).unwrap();
        let (n, m) = dec(&drive);
        assert_eq!(n, 5);
        let OdriveMsg::SetInputTorque { torque_nm } = m else {
            panic!("{m:?}")
        };
        assert!((f64::from(torque_nm) - (-160.0 * 0.0665 * 1.25)).abs() < 1e-4);
        // An idle axis (no error) is re-armed after REENTER_EVERY_TICKS ticks.
        tx(OdriveMsg::Heartbeat {
            axis_error: 0,
            axis_state: 1,
            status: [0; 3],
        });
        drive.set_nonblocking(true).unwrap();
        let mut rearmed = false;
        for _ in 0..=REENTER_EVERY_TICKS {
            let st = b.read_states().unwrap();
            if let Some(st) = st {
                assert_eq!(st.fault_flags[1] & FAULT_DRIVE, FAULT_DRIVE);
            }
            while let Ok(f) = drive.read_frame() {
                let w = WireFrame::try_from(&f).unwrap();
                if odrive::decode(&w).unwrap().1 == (OdriveMsg::SetAxisState { requested_state: 8 })
                {
                    rearmed = true;
                }
            }
        }
        assert!(rearmed, "idle axis was not re-armed");
    }
}

#[cfg(test)]
mod cia402_tests {
    //! The CiA 402 path over a socketpair, against the emulated node of `frictionless-drives`
    //! (`cia402_node`) running in a thread: start-up by SDO, enable, CST torque, EMCY → drive fault
    //! and its reset, heartbeat loss → stale, quick stop and NMT stop at drop.

    use super::*;
    use frictionless_drives::can::cia402::{DriveState, NmtState};
    use frictionless_drives::can::cia402_node::{Cia402Node, NodeParams};
    use std::sync::Mutex;
    use std::sync::atomic::AtomicBool;

    const CIA: &str = r#"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"
[[bus]]
interface = "vcan0"
bitrate = 1000000
protocol = "cia402"
max_load = 0.9
feedback_timeout_ticks = 20
[[bus.joint]]
joint = "knee"
node_id = 3
command_unit = "motor_torque"
[bus.joint.cia402]
fault_reset = true
velocity_unit_rad_s = 0.1
joint_encoder = { index = 0x60E4, sub = 1, bits = 32, counts_per_rev = 8192 }
heartbeat_ms = 10
heartbeat_timeout_ms = 50
"#;

    /// The emulated drive in a thread: answers frames, ticks every ms, sends its heartbeat unless
    /// muted.
    struct Emu {
        node: Arc<Mutex<Cia402Node>>,
        /// An EMCY code to fault the drive with (0 = none), sent by the thread.
        fault: Arc<std::sync::atomic::AtomicU16>,
        mute_heartbeat: Arc<AtomicBool>,
        stop: Arc<AtomicBool>,
        thread: Option<JoinHandle<()>>,
    }

    impl Emu {
        fn start(sock: CanSocket) -> Self {
            let mut n = Cia402Node::new(&NodeParams {
                node: 3,
                rated_torque_mnm: 500,
                max_torque_permille: 2000,
                counts_per_rev: 4096,
            })
            .unwrap();
            n.set_feedback(1024, -5, 40, 2048, 0);
            let node = Arc::new(Mutex::new(n));
            let mute_heartbeat = Arc::new(AtomicBool::new(false));
            let stop = Arc::new(AtomicBool::new(false));
            let fault = Arc::new(std::sync::atomic::AtomicU16::new(0));
            let (n2, m2, s2, f2) = (
                node.clone(),
                mute_heartbeat.clone(),
                stop.clone(),
                fault.clone(),
            );
            let thread = std::thread::spawn(move || {
                let tx = |f: &WireFrame| {
                    let _ = sock.write_frame(&CanFrame::try_from(*f).unwrap());
                };
                let boot = n2.lock().unwrap().boot().unwrap();
                tx(&boot);
                let mut last = std::time::Instant::now();
                while !s2.load(Ordering::Relaxed) {
                    if let Ok(f) = sock.read_frame_timeout(Duration::from_micros(500))
                        && let Ok(w) = WireFrame::try_from(&f)
                    {
                        let out = n2.lock().unwrap().on_frame(&w);
                        out.frames().iter().for_each(tx);
                    }
                    let code = f2.swap(0, Ordering::Relaxed);
                    if code != 0 {
                        let emcy = n2.lock().unwrap().inject_fault(code).unwrap();
                        tx(&emcy);
                    }
                    if last.elapsed() >= Duration::from_millis(1) {
                        last = std::time::Instant::now();
                        let out = n2.lock().unwrap().tick_ms();
                        if !m2.load(Ordering::Relaxed) {
                            out.frames().iter().for_each(tx);
                        }
                    }
                }
            });
            Self {
                node,
                fault,
                mute_heartbeat,
                stop,
                thread: Some(thread),
            }
        }

        fn with<R>(&self, f: impl FnOnce(&mut Cia402Node) -> R) -> R {
            f(&mut self.node.lock().unwrap())
        }
    }

    impl Drop for Emu {
        fn drop(&mut self) {
            self.stop.store(true, Ordering::Relaxed);
            if let Some(t) = self.thread.take() {
                let _ = t.join();
            }
        }
    }

    /// Runs ticks (1 ms apart) until `done` holds, at most `max` ticks; returns the last states.
    fn run_until(
        b: &mut CanBackend,
        cmd: &MotorCurrentCommand,
        max: usize,
        mut done: impl FnMut(&CanBackend, &JointStates) -> bool,
    ) -> JointStates {
        let mut st = JointStates::zeroed();
        for _ in 0..max {
            if let Some(s) = b.read_states().unwrap() {
                st = s;
            }
            b.publish_command(cmd).unwrap();
            if done(b, &st) {
                return st;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        panic!("condition not reached in {max} ticks; last states {st:?}");
    }

    #[test]
    fn cia402_drive_starts_enables_follows_faults_resets_and_stops() {
        let e = super::tests::env("cia402", CIA);
        let (host, drive) = super::tests::pair();
        let emu = Emu::start(drive);
        let mut b = CanBackend::with_sockets(&e.cfg, vec![host]).unwrap();
        // Start-up read the scales by SDO, wrote CST and the mapping, started the node.
        let co = b.buses[0].drives[0].co.unwrap();
        assert_eq!((co.torque.rated_mnm, co.torque.max_permille), (500, 2000));
        assert_eq!(co.pos.counts_per_rev, 4096.0);
        assert_eq!(emu.with(|n| n.mode()), 10);
        assert_eq!(emu.with(|n| n.get(0x1A01, 2)), Some(0x60E4_0120));
        assert_eq!(emu.with(|n| n.get(0x1017, 0)), Some(10));

        // The NMT start reaches the node (it then answers SYNCs).
        let idle = MotorCurrentCommand::zeroed();
        run_until(&mut b, &idle, 2000, |_, _| {
            emu.with(|n| n.nmt() == NmtState::Operational)
        });
        // Enable and command 2 A = 0.314 Nm motor torque = 628 ‰ of 0.5 Nm.
        let mut cmd = MotorCurrentCommand::zeroed();
        cmd.valid_mask = 1;
        cmd.i_ref_a[0] = 2.0;
        run_until(&mut b, &cmd, 2000, |_, _| {
            emu.with(|n| {
                n.state() == DriveState::OperationEnabled && n.applied_torque_permille() == 628
            })
        });
        let st = run_until(&mut b, &cmd, 2000, |b, st| {
            b.counters().stale_feedback_mask == 0 && st.fault_flags[0] == 0 && st.seq > 0
        });
        let near = |a: f64, z: f64| assert!((a - z).abs() < 1e-9, "{a} vs {z}");
        near(st.theta_motor_rad[0], std::f64::consts::FRAC_PI_2); // 1024 / 4096 rev
        near(st.s_rad[0], std::f64::consts::FRAC_PI_2); // joint encoder 2048 / 8192 rev
        near(st.omega_motor_rad_s[0], -0.5);
        near(st.sdot_rad_s[0], 0.005);
        near(st.current_a[0], 0.040 * 0.5 / 0.157);

        // EMCY + fault: the joint is flagged, the EMCY counted; fault_reset = true resets it (edge),
        // the drive's "error reset" EMCY clears the flag, and the drive is enabled again.
        emu.fault.store(0x4310, Ordering::Relaxed);
        let _ = run_until(&mut b, &cmd, 2000, |b, st| {
            st.fault_flags[0] & FAULT_DRIVE != 0 && b.counters().detail[CAN_DETAIL_EMCY] == 1
        });
        assert_eq!(b.buses[0].drives[0].co.unwrap().last_emcy, 0x4310);
        let _ = run_until(&mut b, &cmd, 3000, |_, st| {
            st.fault_flags[0] == 0
                && emu.with(|n| {
                    n.state() == DriveState::OperationEnabled && n.applied_torque_permille() == 628
                })
        });

        // Heartbeat loss: the joint goes stale although its TPDOs still arrive; back when it returns.
        emu.mute_heartbeat.store(true, Ordering::Relaxed);
        let _ = run_until(&mut b, &cmd, 2000, |b, st| {
            b.counters().stale_feedback_mask == 1 && st.fault_flags[0] & FAULT_FEEDBACK_STALE != 0
        });
        emu.mute_heartbeat.store(false, Ordering::Relaxed);
        let _ = run_until(&mut b, &cmd, 2000, |b, _| {
            b.counters().stale_feedback_mask == 0
        });

        // Drop: quick stop with 0 torque (the drive leaves operation enabled), then NMT stop.
        drop(b);
        std::thread::sleep(Duration::from_millis(50));
        emu.with(|n| {
            assert_eq!(n.nmt(), NmtState::Stopped);
            assert_ne!(n.state(), DriveState::OperationEnabled);
            assert_eq!(n.applied_torque_permille(), 0);
        });
    }
}
