//! [`Cia402Node`]: a socket-free emulated CiA 402 drive (the slave side), for the plant's
//! `frictl sim serve --backend can --protocol cia402` and for tests of the master.
//!
//! What it **is**: a fixed object dictionary ([`Cia402Node::new`] lists it), the NMT slave (boot-up, pre-operational,
//! operational, stopped; PDOs only when operational, SDO in pre-operational and operational), an SDO
//! server (expedited download and upload, segmented upload of 0x1008; everything else aborts with
//! the CiA 301 code), PDOs that follow the mapping the master wrote into the dictionary (RPDOs
//! applied at the next SYNC, TPDOs of transmission type 1..=240 sent on every n-th SYNC), the 402
//! state machine driven by the controlword ([`super::cia402::apply_controlword`]), EMCY on a
//! fault ([`Cia402Node::inject_fault`]) and its reset, and the heartbeat from 0x1017.
//!
//! What it is **not**: no plant, no clock (the caller calls [`Cia402Node::tick_ms`] every ms and
//! supplies the feedback with [`Cia402Node::set_feedback`]), no position / velocity loop (in CSP /
//! CSV only the torque offset 0x60B2 acts), no LSS, no block transfers. Allocation-free.

use super::cia402::{
    self as co, CobKind, DriveState, Emcy, NmtCommand, NmtState, PdoEntry, PdoMap, SdoAddr,
    SdoRequest, SdoResponse, abort, obj,
};
use super::{CanCodecError, WireFrame};

/// Entries of the object dictionary.
const OD_SIZE: usize = 160;

/// The device name served by 0x1008 (segmented upload).
pub const DEVICE_NAME: &[u8] = b"frictionless emulated CiA 402 joint";

/// Temperature object of the emulated drive (Synapticon's 0x2031:01, INTEGER32 m°C).
pub const TEMPERATURE: SdoAddr = SdoAddr::new(0x2031, 1);

/// Manufacturer-specific test object of the emulation (UNSIGNED16, writable): writing a non-zero
/// EMCY error code faults the drive as [`Cia402Node::inject_fault`] does (the SDO acknowledge, then
/// the EMCY), so a master on the bus can exercise its fault handling.
pub const SIMULATE_FAULT: SdoAddr = SdoAddr::new(0x2F00, 0);

/// CiA 301 data types of the dictionary's entries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum DataType {
    /// UNSIGNED8.
    #[default]
    Unsigned8,
    /// UNSIGNED16.
    Unsigned16,
    /// UNSIGNED32.
    Unsigned32,
    /// INTEGER8.
    Integer8,
    /// INTEGER16.
    Integer16,
    /// INTEGER32.
    Integer32,
}

impl DataType {
    /// The CiA 301 data type index (an EDS file's `DataType`).
    pub const fn code(self) -> u16 {
        match self {
            Self::Integer8 => 0x0002,
            Self::Integer16 => 0x0003,
            Self::Integer32 => 0x0004,
            Self::Unsigned8 => 0x0005,
            Self::Unsigned16 => 0x0006,
            Self::Unsigned32 => 0x0007,
        }
    }

    /// Size [bytes].
    pub const fn bytes(self) -> u8 {
        match self {
            Self::Unsigned8 | Self::Integer8 => 1,
            Self::Unsigned16 | Self::Integer16 => 2,
            Self::Unsigned32 | Self::Integer32 => 4,
        }
    }

    /// Whether the type is signed (two's complement).
    pub const fn signed(self) -> bool {
        matches!(self, Self::Integer8 | Self::Integer16 | Self::Integer32)
    }
}

/// One entry of the object dictionary (everything but the device name 0x1008, a
/// VISIBLE_STRING [`DEVICE_NAME`] served by segmented upload).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Object {
    /// Index and sub-index.
    pub addr: SdoAddr,
    /// Data type.
    pub data_type: DataType,
    /// Writable by SDO (`rw`); otherwise read-only.
    pub writable: bool,
    /// Raw value (the low [`DataType::bytes`] bytes; signed values in two's complement).
    pub value: u32,
}

/// Frames a call produced (at most 8).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Out {
    frames: [WireFrame; 8],
    n: usize,
}

impl Out {
    fn push(&mut self, f: Result<WireFrame, CanCodecError>) {
        if let Ok(f) = f
            && self.n < self.frames.len()
        {
            self.frames[self.n] = f;
            self.n += 1;
        }
    }

    /// The frames, in the order to send them.
    pub fn frames(&self) -> &[WireFrame] {
        &self.frames[..self.n]
    }
}

/// Parameters of the emulated drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeParams {
    /// Node id 1..=127.
    pub node: u8,
    /// 0x6076 motor rated torque [mNm].
    pub rated_torque_mnm: u32,
    /// 0x6072 max torque [‰].
    pub max_torque_permille: u16,
    /// 0x608F:01 encoder increments (per 0x608F:02 = 1 revolution).
    pub counts_per_rev: u32,
}

/// One emulated CiA 402 drive.
#[derive(Debug, Clone)]
pub struct Cia402Node {
    node: u8,
    od: [Object; OD_SIZE],
    n_od: usize,
    nmt: NmtState,
    state: DriveState,
    last_cw: u16,
    pending_rpdo: [Option<WireFrame>; 4],
    sync_count: u32,
    ms: u64,
    last_hb_ms: u64,
    segment: Option<(usize, bool)>,
    emcy_code: u16,
    pending_emcy: Option<WireFrame>,
    /// Errors of PDOs received with the wrong length (EMCY 0x8210 is sent for them).
    pub pdo_length_errors: u64,
}

impl Cia402Node {
    /// A drive in NMT "initialising": [`Cia402Node::boot`] sends the boot-up. Its dictionary:
    /// 0x1000, 0x1001, 0x1008, 0x1017 (0 = no heartbeat until written), 0x1018:01–04, RPDO1–4 and
    /// TPDO1–4 communication (sub 1 COB-ID, sub 2 type; pre-defined ids, RPDO1 / TPDO1–2 valid) and
    /// mapping parameters (sub 0–8; defaults RPDO1 = 0x6040 + 0x6071, TPDO1 = 0x6041 + 0x6064 +
    /// 0x6077, TPDO2 = 0x606C + 0x60E4:01), 0x603F, 0x6040, 0x6041, 0x605A (2), 0x6060, 0x6061,
    /// 0x6064, 0x606C, 0x6071, 0x6072, 0x6076, 0x6077, 0x608F:01/02, 0x60B2, 0x60E4:01, 0x2031:01
    /// (temperature, m°C), 0x2F00 ([`SIMULATE_FAULT`]), 0x6502 (CSP, CSV, CST); every record's
    /// sub 0 holds its highest sub-index. `config/cia402_frictionless.eds` describes the same
    /// dictionary (a test keeps them equal).
    pub fn new(p: &NodeParams) -> Result<Self, CanCodecError> {
        let n = u32::from(p.node);
        co::node_id(0, p.node)?;
        let mut me = Self {
            node: p.node,
            od: [Object::default(); OD_SIZE],
            n_od: 0,
            nmt: NmtState::BootUp,
            state: DriveState::NotReadyToSwitchOn,
            last_cw: 0,
            pending_rpdo: [None; 4],
            sync_count: 0,
            ms: 0,
            last_hb_ms: 0,
            segment: None,
            emcy_code: 0,
            pending_emcy: None,
            pdo_length_errors: 0,
        };
        let mut add = |index: u16, sub: u8, data_type: DataType, writable: bool, value: u32| {
            me.od[me.n_od] = Object {
                addr: SdoAddr::new(index, sub),
                data_type,
                writable,
                value,
            };
            me.n_od += 1;
        };
        use DataType::{Integer8 as I8, Integer16 as I16, Integer32 as I32};
        use DataType::{Unsigned8 as U8, Unsigned16 as U16, Unsigned32 as U32};
        add(obj::DEVICE_TYPE, 0, U32, false, 0x0002_0192);
        add(obj::ERROR_REGISTER, 0, U8, false, 0);
        add(obj::PRODUCER_HEARTBEAT, 0, U16, true, 0);
        add(obj::IDENTITY, 0, U8, false, 4);
        add(obj::IDENTITY, 1, U32, false, 0);
        add(obj::IDENTITY, 2, U32, false, 0x402);
        add(obj::IDENTITY, 3, U32, false, 1);
        add(obj::IDENTITY, 4, U32, false, n);
        let defaults: [[u32; 3]; 4] = [
            [0x6040_0010, 0x6071_0010, 0],
            [0x6041_0010, 0x6064_0020, 0x6077_0010],
            [0x606C_0020, 0x60E4_0120, 0],
            [0, 0, 0],
        ];
        // Communication (sub 1 COB-ID, sub 2 transmission type) and mapping parameters of RPDO1–4
        // and TPDO1–4.
        for (comm, map, ids, valid) in [
            (obj::RPDO_COMM, obj::RPDO_MAP, co::cob::RPDO, 1u16),
            (obj::TPDO_COMM, obj::TPDO_MAP, co::cob::TPDO, 2),
        ] {
            for k in 0..4u16 {
                let flag = if k < valid { 0 } else { co::COB_ID_INVALID };
                add(comm + k, 0, U8, false, 2);
                add(comm + k, 1, U32, true, flag | (ids[usize::from(k)] + n));
                add(comm + k, 2, U8, true, 1);
                let def = match (comm, k) {
                    (obj::RPDO_COMM, 0) => defaults[0],
                    (obj::TPDO_COMM, 0) => defaults[1],
                    (obj::TPDO_COMM, 1) => defaults[2],
                    _ => defaults[3],
                };
                let entries = def.iter().filter(|&&v| v != 0).count() as u32;
                add(map + k, 0, U8, true, entries);
                for s in 1..=8u8 {
                    let v = *def.get(usize::from(s - 1)).unwrap_or(&0);
                    add(map + k, s, U32, true, v);
                }
            }
        }
        add(obj::ERROR_CODE, 0, U16, false, 0);
        add(obj::CONTROLWORD, 0, U16, true, 0);
        add(obj::STATUSWORD, 0, U16, false, 0);
        add(obj::QUICK_STOP_OPTION, 0, I16, true, 2);
        add(obj::MODES_OF_OPERATION, 0, I8, true, 0);
        add(obj::MODES_DISPLAY, 0, I8, false, 0);
        add(obj::POSITION_ACTUAL, 0, I32, false, 0);
        add(obj::VELOCITY_ACTUAL, 0, I32, false, 0);
        add(obj::TARGET_TORQUE, 0, I16, true, 0);
        let max = u32::from(p.max_torque_permille);
        add(obj::MAX_TORQUE, 0, U16, true, max);
        add(obj::RATED_TORQUE, 0, U32, true, p.rated_torque_mnm);
        add(obj::TORQUE_ACTUAL, 0, I16, false, 0);
        add(obj::ENCODER_RESOLUTION, 0, U8, false, 2);
        add(obj::ENCODER_RESOLUTION, 1, U32, true, p.counts_per_rev);
        add(obj::ENCODER_RESOLUTION, 2, U32, true, 1);
        add(obj::TORQUE_OFFSET, 0, I16, true, 0);
        add(obj::ADDITIONAL_POSITION, 0, U8, false, 1);
        add(obj::ADDITIONAL_POSITION, 1, I32, false, 0);
        add(TEMPERATURE.index, 0, U8, false, 1);
        add(TEMPERATURE.index, TEMPERATURE.sub, I32, false, 0);
        add(SIMULATE_FAULT.index, SIMULATE_FAULT.sub, U16, true, 0);
        let modes = (1 << 7) | (1 << 8) | (1 << 9);
        add(obj::SUPPORTED_MODES, 0, U32, false, modes);
        me.refresh_statusword();
        Ok(me)
    }

    /// The object dictionary, in index order of creation (see [`Cia402Node::new`]).
    pub fn objects(&self) -> &[Object] {
        &self.od[..self.n_od]
    }

    fn find(&self, a: SdoAddr) -> Option<usize> {
        self.od[..self.n_od].iter().position(|e| e.addr == a)
    }

    /// The raw value of an object (`None`: not in the dictionary).
    pub fn get(&self, index: u16, sub: u8) -> Option<u32> {
        self.find(SdoAddr::new(index, sub))
            .map(|k| self.od[k].value)
    }

    fn set(&mut self, index: u16, sub: u8, value: u32) {
        if let Some(k) = self.find(SdoAddr::new(index, sub)) {
            let len = self.od[k].data_type.bytes();
            let mask = if len >= 4 {
                u32::MAX
            } else {
                (1u32 << (8 * len)) - 1
            };
            self.od[k].value = value & mask;
        }
    }

    /// Node id.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// NMT state.
    pub fn nmt(&self) -> NmtState {
        self.nmt
    }

    /// 402 state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Mode of operation (0x6061).
    pub fn mode(&self) -> i8 {
        self.get(obj::MODES_DISPLAY, 0).unwrap_or(0) as u8 as i8
    }

    /// The torque the drive applies [‰ of rated]: in operation enabled, CST: 0x6071 + 0x60B2,
    /// CSP / CSV: 0x60B2 (no position / velocity loop emulated); clamped to ±0x6072; otherwise 0.
    pub fn applied_torque_permille(&self) -> i32 {
        if self.state != DriveState::OperationEnabled {
            return 0;
        }
        let off = i32::from(self.get(obj::TORQUE_OFFSET, 0).unwrap_or(0) as u16 as i16);
        let target = i32::from(self.get(obj::TARGET_TORQUE, 0).unwrap_or(0) as u16 as i16);
        let t = match self.mode() {
            co::mode::CST => target + off,
            co::mode::CSP | co::mode::CSV => off,
            _ => 0,
        };
        let max = self.get(obj::MAX_TORQUE, 0).unwrap_or(0) as i32;
        t.clamp(-max, max)
    }

    /// Rated torque [mNm] (0x6076).
    pub fn rated_torque_mnm(&self) -> u32 {
        self.get(obj::RATED_TORQUE, 0).unwrap_or(0)
    }

    /// The measured values the next TPDOs carry: motor position [increments], velocity [units of
    /// 0x606C], torque [‰], joint-side position [increments], temperature [m°C].
    pub fn set_feedback(
        &mut self,
        pos: i32,
        vel: i32,
        torque_pm: i16,
        joint_pos: i32,
        temp_mc: i32,
    ) {
        self.set(obj::POSITION_ACTUAL, 0, pos as u32);
        self.set(obj::VELOCITY_ACTUAL, 0, vel as u32);
        self.set(obj::TORQUE_ACTUAL, 0, torque_pm as u16 as u32);
        self.set(obj::ADDITIONAL_POSITION, 1, joint_pos as u32);
        self.set(TEMPERATURE.index, TEMPERATURE.sub, temp_mc as u32);
    }

    fn refresh_statusword(&mut self) {
        let mut sw = self.state.statusword() | 0x0200; // bit 9 remote
        if self.state == DriveState::OperationEnabled {
            sw |= 0x1000; // cyclic modes: the drive follows the command value
        }
        self.set(obj::STATUSWORD, 0, u32::from(sw));
    }

    /// Applies a controlword; returns the EMCY "error reset" frame when it cleared a fault.
    fn apply_controlword(&mut self, cw: u16) -> Option<WireFrame> {
        let edge = cw & co::cw::FAULT_RESET != 0 && self.last_cw & co::cw::FAULT_RESET == 0;
        self.last_cw = cw;
        let stays = matches!(
            self.get(obj::QUICK_STOP_OPTION, 0).unwrap_or(2) as u16 as i16,
            5..=8
        );
        let before = self.state;
        self.state = co::apply_controlword(self.state, cw, edge, stays);
        self.refresh_statusword();
        if before == DriveState::Fault && self.state != DriveState::Fault {
            self.emcy_code = 0;
            self.set(obj::ERROR_CODE, 0, 0);
            self.set(obj::ERROR_REGISTER, 0, 0);
            return co::encode_emcy(self.node, &Emcy::default()).ok();
        }
        None
    }

    /// The boot-up frame; the node enters pre-operational (the 402 state goes to switch on
    /// disabled).
    pub fn boot(&mut self) -> Result<WireFrame, CanCodecError> {
        self.nmt = NmtState::PreOperational;
        self.state = DriveState::SwitchOnDisabled;
        self.refresh_statusword();
        self.last_hb_ms = self.ms;
        co::encode_heartbeat(self.node, NmtState::BootUp)
    }

    /// A drive fault with EMCY `code`: fault reaction, then fault (0x603F = code, 0x1001 bit 0).
    /// Returns the EMCY frame.
    pub fn inject_fault(&mut self, code: u16) -> Result<WireFrame, CanCodecError> {
        self.state = DriveState::Fault;
        self.emcy_code = code;
        self.set(obj::ERROR_CODE, 0, u32::from(code));
        self.set(obj::ERROR_REGISTER, 0, 1);
        self.refresh_statusword();
        co::encode_emcy(
            self.node,
            &Emcy {
                code,
                register: 1,
                manufacturer: [0; 5],
            },
        )
    }

    /// Advances the clock 1 ms; the heartbeat when due (0x1017 > 0, not initialising).
    pub fn tick_ms(&mut self) -> Out {
        self.ms += 1;
        let mut out = Out::default();
        let period = u64::from(self.get(obj::PRODUCER_HEARTBEAT, 0).unwrap_or(0));
        if period > 0 && self.nmt != NmtState::BootUp && self.ms - self.last_hb_ms >= period {
            self.last_hb_ms = self.ms;
            out.push(co::encode_heartbeat(self.node, self.nmt));
        }
        out
    }

    fn map(&self, map_index: u16) -> Option<PdoMap> {
        let n = self.get(map_index, 0)? as usize;
        let mut e = [PdoEntry::default(); co::PDO_MAX_ENTRIES];
        for (k, slot) in e.iter_mut().enumerate().take(n.min(co::PDO_MAX_ENTRIES)) {
            *slot = PdoEntry::from_mapping(self.get(map_index, k as u8 + 1)?);
        }
        PdoMap::new(&e[..n.min(co::PDO_MAX_ENTRIES)]).ok()
    }

    fn object_len(&self, e: &PdoEntry) -> Option<u8> {
        self.find(SdoAddr::new(e.index, e.sub))
            .map(|k| self.od[k].data_type.bytes())
    }

    /// Handles a received frame; returns the frames to send.
    pub fn on_frame(&mut self, f: &WireFrame) -> Out {
        let mut out = Out::default();
        if f.extended || f.rtr {
            return out;
        }
        match co::classify(f.id) {
            CobKind::Nmt => {
                if let Ok((cmd, target)) = co::decode_nmt(f)
                    && (target == 0 || target == self.node)
                {
                    match cmd {
                        NmtCommand::Start => self.nmt = NmtState::Operational,
                        NmtCommand::Stop => self.nmt = NmtState::Stopped,
                        NmtCommand::PreOperational => self.nmt = NmtState::PreOperational,
                        NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                            out.push(self.boot());
                        }
                    }
                }
            }
            CobKind::Sync if self.nmt == NmtState::Operational => self.on_sync(&mut out),
            CobKind::SdoRequest(n) if n == self.node => {
                if matches!(self.nmt, NmtState::PreOperational | NmtState::Operational)
                    && let Some(r) = self.on_sdo(f)
                {
                    out.push(co::encode_sdo_response(self.node, &r));
                    if let Some(e) = self.pending_emcy.take() {
                        out.push(Ok(e));
                    }
                }
            }
            CobKind::Rpdo(k, n) if n == self.node && self.nmt == NmtState::Operational => {
                let comm = self
                    .get(obj::RPDO_COMM + u16::from(k - 1), 1)
                    .unwrap_or(co::COB_ID_INVALID);
                if comm & co::COB_ID_INVALID == 0 && comm & 0x7FF == f.id {
                    let ty = self.get(obj::RPDO_COMM + u16::from(k - 1), 2).unwrap_or(1);
                    if ty <= 240 {
                        self.pending_rpdo[usize::from(k - 1)] = Some(*f);
                    } else {
                        self.apply_rpdo(k, f, &mut out);
                    }
                }
            }
            _ => {}
        }
        out
    }

    fn apply_rpdo(&mut self, k: u8, f: &WireFrame, out: &mut Out) {
        let Some(map) = self.map(obj::RPDO_MAP + u16::from(k - 1)) else {
            return;
        };
        let mut raw = [0u32; co::PDO_MAX_ENTRIES];
        if co::decode_pdo(f, &map, &mut raw).is_err() {
            self.pdo_length_errors += 1;
            out.push(co::encode_emcy(
                self.node,
                &Emcy {
                    code: 0x8210,
                    register: 0x10,
                    manufacturer: [0; 5],
                },
            ));
            return;
        }
        for (e, v) in map.entries().iter().zip(raw) {
            if e.index == obj::CONTROLWORD && e.sub == 0 {
                self.set(obj::CONTROLWORD, 0, v);
                if let Some(f) = self.apply_controlword(v as u16) {
                    out.push(Ok(f));
                }
            } else {
                self.set(e.index, e.sub, v);
            }
        }
    }

    fn on_sync(&mut self, out: &mut Out) {
        self.sync_count = self.sync_count.wrapping_add(1);
        for k in 0..4u8 {
            if let Some(f) = self.pending_rpdo[usize::from(k)].take() {
                self.apply_rpdo(k + 1, &f, out);
            }
        }
        // Automatic transitions: a quick stop that does not stay ends in switch on disabled.
        if self.state == DriveState::QuickStopActive {
            let _ = self.apply_controlword(self.last_cw);
        }
        for k in 0..4u16 {
            let comm = self
                .get(obj::TPDO_COMM + k, 1)
                .unwrap_or(co::COB_ID_INVALID);
            let ty = self.get(obj::TPDO_COMM + k, 2).unwrap_or(0);
            if comm & co::COB_ID_INVALID != 0 || !(1..=240).contains(&ty) {
                continue;
            }
            if !self.sync_count.is_multiple_of(ty) {
                continue;
            }
            let Some(map) = self.map(obj::TPDO_MAP + k) else {
                continue;
            };
            let mut vals = [0i64; co::PDO_MAX_ENTRIES];
            for (v, e) in vals.iter_mut().zip(map.entries()) {
                let raw = self.get(e.index, e.sub).unwrap_or(0);
                *v = i64::from(
                    raw & if e.bits >= 32 {
                        u32::MAX
                    } else {
                        (1 << e.bits) - 1
                    },
                );
            }
            out.push(co::encode_pdo(
                comm & 0x7FF,
                &map,
                &vals[..map.entries().len()],
            ));
        }
    }

    fn on_sdo(&mut self, f: &WireFrame) -> Option<SdoResponse> {
        let Ok((_, req)) = co::decode_sdo_request(f) else {
            self.segment = None;
            let addr = SdoAddr::new(u16::from_le_bytes([f.data[1], f.data[2]]), f.data[3]);
            return Some(SdoResponse::Abort {
                addr,
                code: abort::UNKNOWN_COMMAND,
            });
        };
        match req {
            SdoRequest::Upload { addr } if addr == SdoAddr::new(obj::DEVICE_NAME, 0) => {
                self.segment = Some((0, false));
                Some(SdoResponse::UploadSegmented {
                    addr,
                    size: Some(DEVICE_NAME.len() as u32),
                })
            }
            SdoRequest::UploadSegment { toggle } => {
                let Some((at, t)) = self.segment else {
                    return Some(SdoResponse::Abort {
                        addr: SdoAddr::default(),
                        code: abort::UNKNOWN_COMMAND,
                    });
                };
                if toggle != t {
                    self.segment = None;
                    return Some(SdoResponse::Abort {
                        addr: SdoAddr::new(obj::DEVICE_NAME, 0),
                        code: abort::TOGGLE,
                    });
                }
                let end = (at + 7).min(DEVICE_NAME.len());
                let mut data = [0u8; 7];
                data[..end - at].copy_from_slice(&DEVICE_NAME[at..end]);
                let last = end == DEVICE_NAME.len();
                self.segment = if last { None } else { Some((end, !t)) };
                Some(SdoResponse::UploadSegment {
                    toggle,
                    data,
                    len: (end - at) as u8,
                    last,
                })
            }
            SdoRequest::Upload { addr } => {
                self.segment = None;
                let Some(k) = self.find(addr) else {
                    return Some(self.missing(addr));
                };
                let e = self.od[k];
                Some(SdoResponse::Upload {
                    addr,
                    data: e.value.to_le_bytes(),
                    len: e.data_type.bytes(),
                })
            }
            SdoRequest::Download { addr, data, len } => {
                self.segment = None;
                let Some(k) = self.find(addr) else {
                    return Some(self.missing(addr));
                };
                let e = self.od[k];
                if !e.writable {
                    return Some(SdoResponse::Abort {
                        addr,
                        code: abort::READ_ONLY,
                    });
                }
                if len != e.data_type.bytes() {
                    return Some(SdoResponse::Abort {
                        addr,
                        code: abort::LENGTH_MISMATCH,
                    });
                }
                let v = u32::from_le_bytes(data);
                if let Some(code) = self.refuse_write(addr, v) {
                    return Some(SdoResponse::Abort { addr, code });
                }
                self.set(addr.index, addr.sub, v);
                match addr.index {
                    // An "error reset" EMCY of an SDO-written fault reset is not sent (one frame
                    // per request); the statusword shows the reset.
                    obj::CONTROLWORD => {
                        let _ = self.apply_controlword(v as u16);
                    }
                    obj::MODES_OF_OPERATION => self.set(obj::MODES_DISPLAY, 0, v),
                    i if i == SIMULATE_FAULT.index && v != 0 => {
                        self.pending_emcy = self.inject_fault(v as u16).ok();
                    }
                    _ => {}
                }
                Some(SdoResponse::DownloadAck { addr })
            }
            SdoRequest::Abort { .. } => {
                self.segment = None;
                None
            }
        }
    }

    fn missing(&self, addr: SdoAddr) -> SdoResponse {
        let code = if self.od[..self.n_od]
            .iter()
            .any(|e| e.addr.index == addr.index)
        {
            abort::NO_SUB
        } else {
            abort::NO_OBJECT
        };
        SdoResponse::Abort { addr, code }
    }

    /// CiA 301 / 402 checks of a write: PDO parameters only while the PDO is invalid (COB-ID
    /// bit 31) and mapping entries only while sub 0 is 0; mapped objects must exist with the
    /// mapped length and total ≤ 64 bits; modes other than CSP / CSV / CST are out of range.
    fn refuse_write(&self, addr: SdoAddr, v: u32) -> Option<u32> {
        let i = addr.index;
        let is_map = (obj::RPDO_MAP..obj::RPDO_MAP + 4).contains(&i)
            || (obj::TPDO_MAP..obj::TPDO_MAP + 4).contains(&i);
        let is_comm = (obj::RPDO_COMM..obj::RPDO_COMM + 4).contains(&i)
            || (obj::TPDO_COMM..obj::TPDO_COMM + 4).contains(&i);
        if is_map {
            let comm = i - 0x200;
            let valid = self.get(comm, 1).unwrap_or(0) & co::COB_ID_INVALID == 0;
            if valid {
                return Some(abort::DEVICE_STATE);
            }
            if addr.sub == 0 {
                let mut bits = 0u32;
                for s in 1..=v.min(8) as u8 {
                    let e = PdoEntry::from_mapping(self.get(i, s).unwrap_or(0));
                    match self.object_len(&e) {
                        Some(len) if u32::from(len) * 8 == u32::from(e.bits) => {
                            bits += u32::from(e.bits);
                        }
                        _ => return Some(abort::NOT_MAPPABLE),
                    }
                }
                if v > 8 || bits > 64 {
                    return Some(abort::PDO_TOO_LONG);
                }
            } else if self.get(i, 0).unwrap_or(0) != 0 {
                return Some(abort::DEVICE_STATE);
            }
        }
        if is_comm && addr.sub == 2 {
            let valid = self.get(i, 1).unwrap_or(0) & co::COB_ID_INVALID == 0;
            if valid {
                return Some(abort::DEVICE_STATE);
            }
        }
        if i == obj::MODES_OF_OPERATION
            && !matches!(
                v as u8 as i8,
                0 | co::mode::CSP | co::mode::CSV | co::mode::CST
            )
        {
            return Some(abort::RANGE);
        }
        None
    }

    /// The last EMCY code (0 after a reset).
    pub fn emcy_code(&self) -> u16 {
        self.emcy_code
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node() -> Cia402Node {
        Cia402Node::new(&NodeParams {
            node: 3,
            rated_torque_mnm: 500,
            max_torque_permille: 2000,
            counts_per_rev: 4096,
        })
        .unwrap()
    }

    fn sdo(n: &mut Cia402Node, r: SdoRequest) -> SdoResponse {
        let f = co::encode_sdo_request(3, &r).unwrap();
        let out = n.on_frame(&f);
        let (_, resp) = co::decode_sdo_response(
            &out.frames()[0],
            matches!(r, SdoRequest::UploadSegment { .. }),
        )
        .unwrap();
        resp
    }

    #[test]
    fn sdo_server_reads_writes_aborts_and_segments() {
        let mut n = node();
        n.boot().unwrap();
        let rated = sdo(
            &mut n,
            SdoRequest::Upload {
                addr: SdoAddr::new(0x6076, 0),
            },
        );
        assert!(
            matches!(rated, SdoResponse::Upload { data, len: 4, .. } if u32::from_le_bytes(data) == 500)
        );
        let ro = sdo(
            &mut n,
            co::sdo_download(SdoAddr::new(0x6041, 0), 1, 2).unwrap(),
        );
        assert!(matches!(
            ro,
            SdoResponse::Abort {
                code: abort::READ_ONLY,
                ..
            }
        ));
        let len = sdo(
            &mut n,
            co::sdo_download(SdoAddr::new(0x6040, 0), 6, 4).unwrap(),
        );
        assert!(matches!(
            len,
            SdoResponse::Abort {
                code: abort::LENGTH_MISMATCH,
                ..
            }
        ));
        let none = sdo(
            &mut n,
            SdoRequest::Upload {
                addr: SdoAddr::new(0x7000, 0),
            },
        );
        assert!(matches!(
            none,
            SdoResponse::Abort {
                code: abort::NO_OBJECT,
                ..
            }
        ));
        let mode = sdo(
            &mut n,
            co::sdo_download(SdoAddr::new(0x6060, 0), 4, 1).unwrap(),
        );
        assert!(matches!(
            mode,
            SdoResponse::Abort {
                code: abort::RANGE,
                ..
            }
        ));
        // Mapping a valid PDO is refused (CiA 301: invalidate first).
        let busy = sdo(
            &mut n,
            co::sdo_download(SdoAddr::new(0x1A00, 0), 0, 1).unwrap(),
        );
        assert!(matches!(
            busy,
            SdoResponse::Abort {
                code: abort::DEVICE_STATE,
                ..
            }
        ));
        // 0x1008 by segmented upload.
        let init = sdo(
            &mut n,
            SdoRequest::Upload {
                addr: SdoAddr::new(0x1008, 0),
            },
        );
        assert!(matches!(
            init,
            SdoResponse::UploadSegmented { size: Some(35), .. }
        ));
        let mut name = Vec::new();
        let mut toggle = false;
        loop {
            let SdoResponse::UploadSegment {
                data, len, last, ..
            } = sdo(&mut n, SdoRequest::UploadSegment { toggle })
            else {
                panic!("not a segment");
            };
            name.extend_from_slice(&data[..usize::from(len)]);
            toggle = !toggle;
            if last {
                break;
            }
        }
        assert_eq!(name, DEVICE_NAME);
    }

    #[test]
    fn sync_driven_pdos_and_the_state_machine() {
        let mut n = node();
        n.boot().unwrap();
        n.on_frame(&co::encode_nmt(NmtCommand::Start, 0).unwrap());
        assert_eq!(n.nmt(), NmtState::Operational);
        n.on_frame(
            &co::encode_sdo_request(
                3,
                &co::sdo_download(SdoAddr::new(0x6060, 0), 10, 1).unwrap(),
            )
            .unwrap(),
        );
        assert_eq!(n.mode(), 10);
        n.set_feedback(1234, -5, 40, 77, 36_500);
        let rmap = n.map(0x1600).unwrap();
        for (cw, want) in [
            (0x06, DriveState::ReadyToSwitchOn),
            (0x07, DriveState::SwitchedOn),
            (0x0F, DriveState::OperationEnabled),
        ] {
            let f = co::encode_pdo(0x203, &rmap, &[cw, 300]).unwrap();
            assert!(n.on_frame(&f).frames().is_empty());
            // Applied at the SYNC, which also sends TPDO1 and TPDO2.
            let out = n.on_frame(&co::encode_sync(None));
            assert_eq!(n.state(), want);
            assert_eq!(out.frames().len(), 2);
            assert_eq!(out.frames()[0].id, 0x183);
            assert_eq!(out.frames()[1].id, 0x283);
            let mut raw = [0u32; 8];
            co::decode_pdo(&out.frames()[0], &n.map(0x1A00).unwrap(), &mut raw).unwrap();
            assert_eq!(co::decode_statusword(raw[0] as u16), Some(want));
            assert_eq!((raw[1], raw[2]), (1234, 40));
        }
        assert_eq!(n.applied_torque_permille(), 300);
        // A fault: EMCY, torque off; a reset edge clears it.
        let e = n.inject_fault(0x4310).unwrap();
        assert_eq!(co::decode_emcy(&e).unwrap().1.code, 0x4310);
        assert_eq!(n.applied_torque_permille(), 0);
        n.on_frame(&co::encode_pdo(0x203, &rmap, &[0x00, 0]).unwrap());
        n.on_frame(&co::encode_sync(None));
        n.on_frame(&co::encode_pdo(0x203, &rmap, &[0x80, 0]).unwrap());
        let out = n.on_frame(&co::encode_sync(None));
        assert_eq!(n.state(), DriveState::SwitchOnDisabled);
        assert_eq!(
            co::decode_emcy(&out.frames()[0]).unwrap().1,
            Emcy::default(),
            "error reset"
        );
        assert_eq!(n.emcy_code(), 0);
        // Heartbeat from 0x1017.
        n.on_frame(
            &co::encode_sdo_request(
                3,
                &co::sdo_download(SdoAddr::new(0x1017, 0), 10, 2).unwrap(),
            )
            .unwrap(),
        );
        let beats: usize = (0..30).map(|_| n.tick_ms().frames().len()).sum();
        assert_eq!(beats, 3);
        // A wrong-length RPDO: EMCY 0x8210 at the SYNC.
        n.on_frame(&WireFrame::standard(0x203, &[0x0F]).unwrap());
        let out = n.on_frame(&co::encode_sync(None));
        assert!(out.frames().iter().any(|f| f.id == 0x83));
        assert_eq!(n.pdo_length_errors, 1);
    }

    #[test]
    fn simulate_fault_object_faults_the_drive_with_an_emcy() {
        let mut n = node();
        n.boot().unwrap();
        let req = co::sdo_download(SIMULATE_FAULT, 0x2310, 2).unwrap();
        let out = n.on_frame(&co::encode_sdo_request(3, &req).unwrap());
        assert_eq!(out.frames().len(), 2, "{out:?}");
        assert!(matches!(
            co::decode_sdo_response(&out.frames()[0], false).unwrap().1,
            SdoResponse::DownloadAck { addr } if addr == SIMULATE_FAULT
        ));
        let (node, e) = co::decode_emcy(&out.frames()[1]).unwrap();
        assert_eq!((node, e.code, e.register), (3, 0x2310, 1));
        assert_eq!(n.state(), DriveState::Fault);
        assert_eq!(n.get(obj::ERROR_CODE, 0), Some(0x2310));
        // Writing 0 does nothing.
        let mut m = self::node();
        m.boot().unwrap();
        let req = co::sdo_download(SIMULATE_FAULT, 0, 2).unwrap();
        assert_eq!(
            m.on_frame(&co::encode_sdo_request(3, &req).unwrap())
                .frames()
                .len(),
            1
        );
        assert_eq!(m.state(), DriveState::SwitchOnDisabled);
    }
}
