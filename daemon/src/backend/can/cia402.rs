//! The CiA 402 side of the CAN backend: a drive's start-up over SDO (set-up time, blocking with
//! time-outs) and its per-tick runtime ([`Co`]: TPDO / EMCY / heartbeat decode, the controlword
//! sequencing, the RPDO) — allocation-free after start-up.
//!
//! Start-up of one node, each step checked (an SDO abort is reported with its code, meaning and the
//! object; a time-out names the step):
//! 1. wait for its boot-up or a heartbeat ([`BOOT_WAIT`]), then NMT enter pre-operational;
//! 2. 0x1017 producer heartbeat time = `heartbeat_ms`;
//! 3. 0x6502 supported modes must include the mode (skipped when the drive has no 0x6502);
//!    0x6060 = mode, then 0x6061 must report it;
//! 4. the scales not in the config: 0x6076 rated torque, 0x6072 max torque, 0x608F:01/02 encoder
//!    resolution; the max torque must cover the joint's `max_curr` (or the drive would clamp);
//! 5. the PDO mapping (RPDO1, TPDO1, TPDO2 [, TPDO3]) written in the CiA 301 order — COB-ID invalid,
//!    transmission type, mapping count 0, entries, count, COB-ID valid — and read back; TPDO3 / TPDO4
//!    are disabled when unused (a drive without them may abort: tolerated);
//! 6. NMT start.

use std::time::{Duration, Instant};

use frictionless_drives::can::WireFrame;
pub use frictionless_drives::can::cia402::Goal;
use frictionless_drives::can::cia402::{
    self as co, AngleScale, CobKind, DriveState, Emcy, Enabler, NmtCommand, NmtState, PdoMap,
    SdoAddr, SdoRequest, SdoResponse, TorqueScale, abort, obj,
};
use frictionless_shm_types::JointStates;
use socketcan::{CanFrame, CanSocket, Socket};

use super::BackendError;
use crate::config::{Cia402Drive, ResolvedDrive};

/// How long start-up waits for a node's boot-up or heartbeat.
pub const BOOT_WAIT: Duration = Duration::from_secs(3);
/// SDO response time-out per request (python canopen's client uses 0.3 s).
pub const SDO_TIMEOUT: Duration = Duration::from_millis(500);
/// Quick-stop cycles (RPDO quick stop + SYNC, 1 ms apart) sent before NMT stop at exit.
pub const STOP_CYCLES: usize = 3;
/// Cycles between fault-reset attempts (when the config allows them).
pub const FAULT_RESET_EVERY: u32 = 100;

/// Runtime state of one CiA 402 drive (all `Copy` data; no heap).
#[derive(Debug, Clone, Copy)]
pub struct Co {
    /// Node id.
    pub node: u8,
    /// Torque scale (rated torque, max torque).
    pub torque: TorqueScale,
    /// Motor encoder scale.
    pub pos: AngleScale,
    /// Motor rad/s per 0x606C unit.
    pub vel_rad_s: f64,
    /// Joint-side encoder scale, when mapped.
    pub joint_enc: Option<AngleScale>,
    /// °C per temperature unit, when mapped.
    pub temp_unit_c: Option<f64>,
    layout: co::Layout,
    rpdo1: u32,
    enabler: Enabler,
    /// Last reported 402 state.
    pub state: Option<DriveState>,
    /// Consecutive statuswords reporting operation enabled (bumpless enable: 0 torque until 2).
    enabled_seen: u32,
    /// Tick of the last heartbeat.
    pub last_hb_tick: Option<u64>,
    /// Heartbeat timeout [ticks].
    pub hb_timeout_ticks: u64,
    /// NMT state of the last heartbeat.
    pub nmt: Option<NmtState>,
    /// An EMCY other than "error reset" is active (cleared by an error-reset EMCY).
    pub emcy_active: bool,
    /// Last EMCY error code.
    pub last_emcy: u16,
    /// Target last sent [‰].
    pub last_target: i16,
}

fn fail(interface: &str, node: u8, message: String) -> BackendError {
    BackendError::Cia402Startup {
        interface: interface.to_owned(),
        node,
        message,
    }
}

/// A blocking SDO client on the bus socket (start-up only).
struct Sdo<'a> {
    sock: &'a CanSocket,
    interface: &'a str,
    node: u8,
}

impl Sdo<'_> {
    fn send(&self, f: WireFrame) -> Result<(), BackendError> {
        let frame = CanFrame::try_from(f)
            .map_err(|e| fail(self.interface, self.node, format!("encoding: {e}")))?;
        let deadline = Instant::now() + SDO_TIMEOUT;
        loop {
            match self.sock.write_frame(&frame) {
                Ok(()) => return Ok(()),
                Err(e) if super::is_full_or_empty(&e) && Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(e) => {
                    return Err(fail(self.interface, self.node, format!("sending: {e}")));
                }
            }
        }
    }

    /// The next frame of this node's SDO server (others are skipped), within [`SDO_TIMEOUT`].
    fn response(&self, addr: SdoAddr, what: &str) -> Result<SdoResponse, BackendError> {
        let deadline = Instant::now() + SDO_TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(fail(
                    self.interface,
                    self.node,
                    format!(
                        "no SDO response within {} ms {what} {addr}",
                        SDO_TIMEOUT.as_millis()
                    ),
                ));
            }
            let Ok(f) = self.sock.read_frame_timeout(left) else {
                continue;
            };
            let Ok(w) = WireFrame::try_from(&f) else {
                continue;
            };
            if co::classify(w.id) != CobKind::SdoResponse(self.node) {
                continue;
            }
            let Ok((_, r)) = co::decode_sdo_response(&w, false) else {
                return Err(fail(
                    self.interface,
                    self.node,
                    format!(
                        "undecodable SDO response {:02X?} {what} {addr}",
                        w.payload()
                    ),
                ));
            };
            return Ok(r);
        }
    }

    fn abort_error(&self, what: &str, addr: SdoAddr, code: u32) -> BackendError {
        fail(
            self.interface,
            self.node,
            format!(
                "SDO abort {code:#010X} ({}) {what} {addr}",
                co::abort_text(code)
            ),
        )
    }

    /// Expedited upload: the value (little-endian, ≤ 4 bytes) or the abort code.
    fn read_raw(&self, addr: SdoAddr) -> Result<Result<u32, u32>, BackendError> {
        self.send(
            co::encode_sdo_request(self.node, &SdoRequest::Upload { addr })
                .map_err(|e| fail(self.interface, self.node, e.to_string()))?,
        )?;
        match self.response(addr, "reading")? {
            SdoResponse::Upload { addr: a, data, .. } if a == addr => {
                Ok(Ok(u32::from_le_bytes(data)))
            }
            SdoResponse::Abort { addr: a, code } if a == addr => Ok(Err(code)),
            other => Err(fail(
                self.interface,
                self.node,
                format!("unexpected SDO response {other:?} reading {addr}"),
            )),
        }
    }

    fn read(&self, addr: SdoAddr) -> Result<u32, BackendError> {
        self.read_raw(addr)?
            .map_err(|code| self.abort_error("reading", addr, code))
    }

    fn write_raw(
        &self,
        addr: SdoAddr,
        value: u32,
        len: u8,
    ) -> Result<Result<(), u32>, BackendError> {
        let req = co::sdo_download(addr, value, len)
            .map_err(|e| fail(self.interface, self.node, e.to_string()))?;
        self.send(
            co::encode_sdo_request(self.node, &req)
                .map_err(|e| fail(self.interface, self.node, e.to_string()))?,
        )?;
        match self.response(addr, "writing")? {
            SdoResponse::DownloadAck { addr: a } if a == addr => Ok(Ok(())),
            SdoResponse::Abort { addr: a, code } if a == addr => Ok(Err(code)),
            other => Err(fail(
                self.interface,
                self.node,
                format!("unexpected SDO response {other:?} writing {addr}"),
            )),
        }
    }

    fn write(&self, addr: SdoAddr, value: u32, len: u8) -> Result<(), BackendError> {
        self.write_raw(addr, value, len)?
            .map_err(|code| self.abort_error(&format!("writing {value:#X} to"), addr, code))
    }

    /// Writes a PDO's communication and mapping parameters (CiA 301 order) and reads them back.
    fn map_pdo(
        &self,
        comm: u16,
        map_index: u16,
        cob_id: u32,
        transmission: u8,
        map: &PdoMap,
    ) -> Result<(), BackendError> {
        let cob = SdoAddr::new(comm, 1);
        self.write(cob, cob_id | co::COB_ID_INVALID, 4)?;
        self.write(SdoAddr::new(comm, 2), u32::from(transmission), 1)?;
        self.write(SdoAddr::new(map_index, 0), 0, 1)?;
        for (k, e) in map.entries().iter().enumerate() {
            self.write(SdoAddr::new(map_index, k as u8 + 1), e.to_mapping(), 4)?;
        }
        self.write(SdoAddr::new(map_index, 0), map.entries().len() as u32, 1)?;
        self.write(cob, cob_id, 4)?;
        // Read back what the drive now uses.
        let n = self.read(SdoAddr::new(map_index, 0))? & 0xFF;
        let mismatch = |what: String| {
            fail(
                self.interface,
                self.node,
                format!("PDO mapping {map_index:#06X} read back differs: {what}"),
            )
        };
        if n as usize != map.entries().len() {
            return Err(mismatch(format!(
                "{n} entries, wrote {}",
                map.entries().len()
            )));
        }
        for (k, e) in map.entries().iter().enumerate() {
            let got = self.read(SdoAddr::new(map_index, k as u8 + 1))?;
            if got != e.to_mapping() {
                return Err(mismatch(format!(
                    "entry {} = {got:#010X}, wrote {:#010X}",
                    k + 1,
                    e.to_mapping()
                )));
            }
        }
        let got = self.read(cob)?;
        if got & co::COB_ID_INVALID != 0 || got & 0x7FF != cob_id {
            return Err(mismatch(format!(
                "COB-ID {got:#010X}, wrote {cob_id:#X} (valid)"
            )));
        }
        Ok(())
    }

    /// Disables a PDO (COB-ID bit 31); a drive without it may abort (tolerated).
    fn disable_pdo(&self, comm: u16, cob_id: u32) -> Result<(), BackendError> {
        match self.write_raw(SdoAddr::new(comm, 1), cob_id | co::COB_ID_INVALID, 4)? {
            Ok(()) | Err(abort::NO_OBJECT | abort::NO_SUB) => Ok(()),
            Err(code) => Err(self.abort_error("disabling", SdoAddr::new(comm, 1), code)),
        }
    }
}

fn send_now(sock: &CanSocket, f: WireFrame) {
    if let Ok(frame) = CanFrame::try_from(f) {
        let _ = sock.write_frame(&frame);
    }
}

/// Waits for node `node`'s boot-up or heartbeat (start-up only).
fn wait_alive(sock: &CanSocket, interface: &str, node: u8) -> Result<(), BackendError> {
    let deadline = Instant::now() + BOOT_WAIT;
    let want = CobKind::Heartbeat(node);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(fail(
                interface,
                node,
                format!(
                    "no boot-up or heartbeat (id {:#X}) within {} s",
                    0x700 + u32::from(node),
                    BOOT_WAIT.as_secs()
                ),
            ));
        }
        if let Ok(f) = sock.read_frame_timeout(left)
            && let Ok(w) = WireFrame::try_from(&f)
            && co::classify(w.id) == want
            && co::decode_heartbeat(&w).is_ok()
        {
            return Ok(());
        }
    }
}

/// Configures drive `d` (steps 1–5 of the module doc; the NMT start is [`start_all`]'s).
pub fn configure(
    sock: &CanSocket,
    interface: &str,
    d: &ResolvedDrive,
    period_us: u64,
) -> Result<Co, BackendError> {
    let x = d
        .cia402
        .ok_or_else(|| fail(interface, d.node_id as u8, "no [bus.joint.cia402]".into()))?;
    let node = d.node_id as u8;
    wait_alive(sock, interface, node)?;
    send_now(
        sock,
        co::encode_nmt(NmtCommand::PreOperational, node)
            .map_err(|e| fail(interface, node, e.to_string()))?,
    );
    let sdo = Sdo {
        sock,
        interface,
        node,
    };
    sdo.write(
        SdoAddr::new(obj::PRODUCER_HEARTBEAT, 0),
        u32::from(x.cfg.heartbeat_ms),
        2,
    )?;
    set_mode(&sdo, x.op_mode)?;
    let torque = torque_scale(&sdo, &x, d)?;
    let pos = angle_scale(&sdo, &x)?;
    map_layout(&sdo, &x.layout)?;
    let id = |base: u32| base + u32::from(node);
    let joint_enc = x
        .cfg
        .joint_encoder
        .and_then(|o| o.counts_per_rev)
        .map(AngleScale::new)
        .transpose()
        .map_err(|e| fail(interface, node, format!("joint encoder: {e}")))?;
    let hb_ticks = (u64::from(x.heartbeat_timeout_ms) * 1000).div_ceil(period_us.max(1));
    Ok(Co {
        node,
        torque,
        pos,
        vel_rad_s: x.cfg.velocity_unit_rad_s.unwrap_or(0.0),
        joint_enc,
        temp_unit_c: x.cfg.temperature.and_then(|t| t.unit_c),
        layout: x.layout,
        rpdo1: id(0x200),
        enabler: Enabler::new(x.cfg.fault_reset, FAULT_RESET_EVERY),
        state: None,
        enabled_seen: 0,
        last_hb_tick: None,
        hb_timeout_ticks: hb_ticks.max(1),
        nmt: None,
        emcy_active: false,
        last_emcy: 0,
        last_target: 0,
    })
}

/// Checks the drive supports `op_mode` (0x6502, where it has one), writes it (0x6060) and waits until
/// the drive reports it (0x6061).
fn set_mode(sdo: &Sdo<'_>, op_mode: i8) -> Result<(), BackendError> {
    let (interface, node) = (sdo.interface, sdo.node);
    let supported = SdoAddr::new(obj::SUPPORTED_MODES, 0);
    match sdo.read_raw(supported)? {
        Ok(bits) => {
            let bit = co::mode::supported_bit(op_mode).unwrap_or(0);
            if bits & bit == 0 {
                return Err(fail(
                    interface,
                    node,
                    format!(
                        "0x6502 supported modes {bits:#010X} lack mode {} (bit {:#X})",
                        op_mode, bit
                    ),
                ));
            }
        }
        Err(abort::NO_OBJECT) => {}
        Err(code) => return Err(sdo.abort_error("reading", supported, code)),
    }
    sdo.write(
        SdoAddr::new(obj::MODES_OF_OPERATION, 0),
        u32::from(op_mode as u8),
        1,
    )?;
    let display = SdoAddr::new(obj::MODES_DISPLAY, 0);
    let deadline = Instant::now() + SDO_TIMEOUT;
    loop {
        let m = sdo.read(display)? as u8 as i8;
        if m == op_mode {
            break;
        }
        if Instant::now() >= deadline {
            return Err(fail(
                interface,
                node,
                format!("0x6061 reports mode {m} after writing 0x6060 = {}", op_mode),
            ));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

/// The drive's torque scale: 0x6076 rated torque and 0x6072 max torque, from the config or read by
/// SDO; refused when the joint's current clamp exceeds the max torque (the drive would clamp
/// silently).
fn torque_scale(
    sdo: &Sdo<'_>,
    x: &Cia402Drive,
    d: &ResolvedDrive,
) -> Result<TorqueScale, BackendError> {
    let (interface, node) = (sdo.interface, sdo.node);
    let rated = match x.cfg.rated_torque_mnm {
        Some(v) => v,
        None => sdo.read(SdoAddr::new(obj::RATED_TORQUE, 0))?,
    };
    let max = match x.cfg.max_torque_permille {
        Some(v) => v,
        None => sdo.read(SdoAddr::new(obj::MAX_TORQUE, 0))? as u16,
    };
    let torque = TorqueScale::new(rated, max).map_err(|e| {
        fail(
            interface,
            node,
            format!("0x6076 = {rated} mNm / 0x6072 = {max} ‰: {e}"),
        )
    })?;
    let max_cmd = d.units.command_from_current(d.max_curr_a).abs();
    if max_cmd > torque.max_nm() * (1.0 + 1e-12) {
        return Err(fail(
            interface,
            node,
            format!(
                "max torque {} Nm (0x6072 = {max} ‰ of 0x6076 = {rated} mNm) is below the joint's kt·max_curr = {max_cmd} Nm (the drive would clamp silently)",
                torque.max_nm()
            ),
        ));
    }
    Ok(torque)
}

/// The motor encoder's scale: increments per motor revolution from the config, else 0x608F read by
/// SDO.
fn angle_scale(sdo: &Sdo<'_>, x: &Cia402Drive) -> Result<AngleScale, BackendError> {
    let (interface, node) = (sdo.interface, sdo.node);
    let counts = match x.cfg.counts_per_rev {
        Some(c) => c,
        None => {
            let inc = sdo.read(SdoAddr::new(obj::ENCODER_RESOLUTION, 1))?;
            let revs = sdo.read(SdoAddr::new(obj::ENCODER_RESOLUTION, 2))?;
            if revs == 0 {
                return Err(fail(
                    interface,
                    node,
                    "0x608F:02 motor revolutions = 0".into(),
                ));
            }
            f64::from(inc) / f64::from(revs)
        }
    };
    AngleScale::new(counts).map_err(|e| fail(interface, node, format!("encoder resolution: {e}")))
}

/// Writes the PDO mapping of `l` (RPDO1, TPDO1–2, TPDO3 where mapped; TPDO4 and an unmapped TPDO3
/// disabled), each verified by reading it back.
fn map_layout(sdo: &Sdo<'_>, l: &co::Layout) -> Result<(), BackendError> {
    let id = |base: u32| base + u32::from(sdo.node);
    sdo.map_pdo(obj::RPDO_COMM, obj::RPDO_MAP, id(0x200), 1, &l.rpdo1)?;
    sdo.map_pdo(obj::TPDO_COMM, obj::TPDO_MAP, id(0x180), 1, &l.tpdo1)?;
    sdo.map_pdo(
        obj::TPDO_COMM + 1,
        obj::TPDO_MAP + 1,
        id(0x280),
        1,
        &l.tpdo2,
    )?;
    match &l.tpdo3 {
        Some(m) => sdo.map_pdo(
            obj::TPDO_COMM + 2,
            obj::TPDO_MAP + 2,
            id(0x380),
            l.tpdo3_every,
            m,
        )?,
        None => sdo.disable_pdo(obj::TPDO_COMM + 2, id(0x380))?,
    }
    sdo.disable_pdo(obj::TPDO_COMM + 3, id(0x480))?;
    Ok(())
}

/// NMT start of every configured node on the bus (after all are configured).
pub fn start_all(sock: &CanSocket, nodes: impl Iterator<Item = u8>) {
    for n in nodes {
        if let Ok(f) = co::encode_nmt(NmtCommand::Start, n) {
            send_now(sock, f);
        }
    }
}

impl Co {
    /// Decodes a frame of this node into the joint's slot `k` of `st`. Returns `(owned, feedback,
    /// emcy)`: whether the frame was this node's, whether it was position feedback (TPDO1), and
    /// whether it was an EMCY with an error code.
    #[inline]
    pub fn accept(
        &mut self,
        f: &WireFrame,
        tick: u64,
        st: &mut JointStates,
        k: usize,
        gear_ratio: f64,
        kt: f64,
    ) -> (bool, bool, bool) {
        let mut raw = [0u32; co::PDO_MAX_ENTRIES];
        match co::classify(f.id) {
            CobKind::Tpdo(1, n) if n == self.node => {
                if co::decode_pdo(f, &self.layout.tpdo1, &mut raw).is_err() {
                    return (false, false, false);
                }
                self.state = co::decode_statusword(raw[0] as u16);
                self.enabled_seen = if self.state == Some(DriveState::OperationEnabled) {
                    self.enabled_seen.saturating_add(1)
                } else {
                    0
                };
                let theta = self.pos.rad(f64::from(co::sign_extend(raw[1], 32)));
                st.theta_motor_rad[k] = theta;
                if self.joint_enc.is_none() {
                    st.s_rad[k] = theta / gear_ratio;
                }
                let nm = self.torque.motor_nm(co::sign_extend(raw[2], 16));
                st.current_a[k] = nm / kt;
                (true, true, false)
            }
            CobKind::Tpdo(2, n) if n == self.node => {
                if co::decode_pdo(f, &self.layout.tpdo2, &mut raw).is_err() {
                    return (false, false, false);
                }
                let omega = f64::from(co::sign_extend(raw[0], 32)) * self.vel_rad_s;
                st.omega_motor_rad_s[k] = omega;
                st.sdot_rad_s[k] = omega / gear_ratio;
                if let (Some(j), Some(e)) = (self.joint_enc, self.layout.tpdo2.entries().get(1)) {
                    st.s_rad[k] = j.rad(f64::from(co::sign_extend(raw[1], e.bits)));
                }
                (true, false, false)
            }
            CobKind::Tpdo(3, n) if n == self.node => {
                let (Some(m), Some(u)) = (self.layout.tpdo3, self.temp_unit_c) else {
                    return (false, false, false);
                };
                if co::decode_pdo(f, &m, &mut raw).is_err() {
                    return (false, false, false);
                }
                st.temperature_c[k] = f64::from(co::sign_extend(raw[0], m.entries()[0].bits)) * u;
                (true, false, false)
            }
            CobKind::Emcy(n) if n == self.node => {
                let Ok((_, e)) = co::decode_emcy(f) else {
                    return (false, false, false);
                };
                let Emcy { code, .. } = e;
                self.emcy_active = code != 0;
                if code != 0 {
                    self.last_emcy = code;
                }
                (true, false, code != 0)
            }
            CobKind::Heartbeat(n) if n == self.node => {
                let Ok((_, s)) = co::decode_heartbeat(f) else {
                    return (false, false, false);
                };
                self.nmt = Some(s);
                self.last_hb_tick = Some(tick);
                (true, false, false)
            }
            _ => (false, false, false),
        }
    }

    /// Whether the heartbeat is missing (never seen, or older than the timeout).
    #[inline]
    pub fn heartbeat_stale(&self, tick: u64) -> bool {
        self.last_hb_tick
            .is_none_or(|t| tick.saturating_sub(t) > self.hb_timeout_ticks)
    }

    /// Whether the drive is faulted for the daemon: an active EMCY, a 402 fault (reaction), or an
    /// NMT state other than operational.
    #[inline]
    pub fn faulted(&self) -> bool {
        self.emcy_active
            || matches!(
                self.state,
                Some(DriveState::Fault | DriveState::FaultReactionActive)
            )
            || self.nmt.is_some_and(|s| s != NmtState::Operational)
    }

    /// The RPDO1 of this cycle for motor torque `motor_nm` (0 unless the drive reported operation
    /// enabled in the last two statuswords: bumpless enable), with the controlword of `goal`.
    #[inline]
    pub fn rpdo(&mut self, motor_nm: f64, goal: Goal) -> Option<WireFrame> {
        let word = self.enabler.next(self.state, goal);
        let target = if goal == Goal::Enabled
            && word == co::cw::ENABLE_OPERATION
            && self.enabled_seen >= 2
        {
            self.torque.permille(motor_nm).map_or(0, |(pm, _)| pm)
        } else {
            0
        };
        self.last_target = target;
        co::encode_pdo(
            self.rpdo1,
            &self.layout.rpdo1,
            &[i64::from(word), i64::from(target)],
        )
        .ok()
    }
}

/// The ids a CiA 402 bus decodes for `node`: EMCY, TPDO1–3, SDO response, heartbeat.
pub fn owned_ids(node: u32) -> [u32; 6] {
    [0x080, 0x180, 0x280, 0x380, 0x580, 0x700].map(|b| b + node)
}
