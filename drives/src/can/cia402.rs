//! CANopen (CiA 301) services and the CiA 402 drive profile, as frames over [`WireFrame`].
//!
//! What this module **is** — both directions of every service, so frictiond (the master) and an
//! emulated drive (the slave) share one codec:
//! - **COB-IDs** of the pre-defined connection set ([`cob`], [`classify`]): NMT 0x000, SYNC 0x080,
//!   EMCY 0x080 + node, TPDO1..4 0x180/0x280/0x380/0x480 + node, RPDO1..4 0x200/0x300/0x400/0x500
//!   + node, SDO response 0x580 + node, SDO request 0x600 + node, heartbeat / boot-up 0x700 + node.
//! - **NMT** commands ([`NmtCommand`], 2 bytes `[command, node]`, node 0 = all) and the NMT state of a
//!   heartbeat / boot-up frame ([`NmtState`], 1 byte; bit 7, the guarding toggle, is ignored).
//! - **SYNC** without data or with the 1-byte counter (0x1019 ≥ 2).
//! - **SDO** expedited download and upload, segmented upload (for identity strings, 0x1008…) and
//!   abort, client and server side ([`SdoRequest`], [`SdoResponse`]; always 8 bytes
//!   `[command, index lo, index hi, sub, d0..d3]`); expedited downloads always carry the size bits.
//!   [`abort_text`] names the CiA 301 abort codes. Segmented and block download are not here.
//! - **EMCY** ([`Emcy`]: error code, error register 0x1001, 5 manufacturer bytes; code 0 = error
//!   reset) and [`emcy_text`] for the code families.
//! - **PDOs** for a mapping ([`PdoMap`] of [`PdoEntry`] = `index << 16 | sub << 8 | bits`, whole
//!   bytes of 8, 16 or 32 bits, at most 64 bits): [`encode_pdo`] / [`decode_pdo`], little-endian.
//! - **CiA 402**: the statusword decode ([`DriveState`], [`decode_statusword`]), the controlword
//!   commands ([`cw`]), the master's enable / quick-stop / fault-reset sequencing ([`Enabler`]) and
//!   the drive's side of the state machine ([`apply_controlword`]), the modes ([`mode`]) and the
//!   object indices ([`obj`]).
//! - **Units** ([`TorqueScale`], [`AngleScale`]): per mille of the rated torque 0x6076 [mNm] ↔ Nm,
//!   increments ↔ rad; the scales are always given (config or SDO read), never assumed.
//!
//! Sources: CiA 301 / 402 as implemented by python `canopen` 2.4.1 (`nmt.py`, `sdo/`, `emcy.py`,
//! `pdo/base.py`, `profiles/p402.py`), CANopenNode and ros2_canopen; `docs/can-cia402.md` restates
//! what the project relies on.
//!
//! What it is **not**: no sockets, no timing (SDO time-outs, heartbeat supervision and SYNC
//! production are the caller's), no object dictionary, no CAN FD, no LSS.

use super::{CanCodecError, WireFrame};

/// Largest CANopen node id.
pub const NODE_MAX: u8 = 127;

/// COB-ID bases of the pre-defined connection set (add the node id where the service has one).
pub mod cob {
    /// NMT command (master → all).
    pub const NMT: u32 = 0x000;
    /// SYNC.
    pub const SYNC: u32 = 0x080;
    /// EMCY base (+ node).
    pub const EMCY: u32 = 0x080;
    /// TIME stamp.
    pub const TIME: u32 = 0x100;
    /// TPDO1..4 bases (drive → master), + node.
    pub const TPDO: [u32; 4] = [0x180, 0x280, 0x380, 0x480];
    /// RPDO1..4 bases (master → drive), + node.
    pub const RPDO: [u32; 4] = [0x200, 0x300, 0x400, 0x500];
    /// SDO server → client (response) base, + node.
    pub const SDO_TX: u32 = 0x580;
    /// SDO client → server (request) base, + node.
    pub const SDO_RX: u32 = 0x600;
    /// NMT error control (heartbeat, boot-up) base, + node.
    pub const HEARTBEAT: u32 = 0x700;
}

/// What a standard 11-bit id is in the pre-defined connection set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CobKind {
    /// NMT command.
    Nmt,
    /// SYNC.
    Sync,
    /// TIME.
    Time,
    /// EMCY of a node.
    Emcy(u8),
    /// TPDO `n` (1..=4) of a node.
    Tpdo(u8, u8),
    /// RPDO `n` (1..=4) of a node.
    Rpdo(u8, u8),
    /// SDO response of a node (server → client).
    SdoResponse(u8),
    /// SDO request to a node (client → server).
    SdoRequest(u8),
    /// Heartbeat / boot-up of a node.
    Heartbeat(u8),
    /// Not in the pre-defined set (node 0 of a per-node service, or an id above 0x77F).
    Other,
}

/// Classifies a standard id (ids above 0x7FF are [`CobKind::Other`]).
pub fn classify(id: u32) -> CobKind {
    if id > 0x7FF {
        return CobKind::Other;
    }
    let node = (id & 0x7F) as u8;
    match (id >> 7, node) {
        (0, 0) => CobKind::Nmt,
        (1, 0) => CobKind::Sync,
        (2, 0) => CobKind::Time,
        (_, 0) => CobKind::Other,
        (1, n) => CobKind::Emcy(n),
        (3, n) => CobKind::Tpdo(1, n),
        (4, n) => CobKind::Rpdo(1, n),
        (5, n) => CobKind::Tpdo(2, n),
        (6, n) => CobKind::Rpdo(2, n),
        (7, n) => CobKind::Tpdo(3, n),
        (8, n) => CobKind::Rpdo(3, n),
        (9, n) => CobKind::Tpdo(4, n),
        (10, n) => CobKind::Rpdo(4, n),
        (11, n) => CobKind::SdoResponse(n),
        (12, n) => CobKind::SdoRequest(n),
        (14, n) => CobKind::Heartbeat(n),
        _ => CobKind::Other,
    }
}

fn check_node(node: u8) -> Result<u32, CanCodecError> {
    if node == 0 || node > NODE_MAX {
        Err(CanCodecError::NodeOutOfRange {
            node: u32::from(node),
            max: u32::from(NODE_MAX),
        })
    } else {
        Ok(u32::from(node))
    }
}

/// The id `base + node` for node 1..=127.
pub fn node_id(base: u32, node: u8) -> Result<u32, CanCodecError> {
    Ok(base + check_node(node)?)
}

/// TPDO `n` (1..=4) id of `node`.
pub fn tpdo_id(n: u8, node: u8) -> Result<u32, CanCodecError> {
    pdo_base(&cob::TPDO, n).and_then(|b| node_id(b, node))
}

/// RPDO `n` (1..=4) id of `node`.
pub fn rpdo_id(n: u8, node: u8) -> Result<u32, CanCodecError> {
    pdo_base(&cob::RPDO, n).and_then(|b| node_id(b, node))
}

fn pdo_base(bases: &[u32; 4], n: u8) -> Result<u32, CanCodecError> {
    match n {
        1..=4 => Ok(bases[usize::from(n - 1)]),
        _ => Err(CanCodecError::UnknownCommand {
            id: bases[0],
            cmd: n,
        }),
    }
}

fn standard_data(f: &WireFrame) -> Result<(), CanCodecError> {
    if f.extended {
        return Err(CanCodecError::WrongIdKind {
            id: f.id,
            extended: true,
        });
    }
    if f.id > super::frame::SFF_MAX {
        return Err(CanCodecError::IdOutOfRange {
            id: f.id,
            extended: false,
        });
    }
    if f.rtr {
        return Err(CanCodecError::WrongRtr {
            id: f.id,
            rtr: true,
        });
    }
    if f.len > 8 {
        return Err(CanCodecError::DataTooLong {
            len: usize::from(f.len),
        });
    }
    Ok(())
}

fn exact_len(f: &WireFrame, n: u8) -> Result<(), CanCodecError> {
    if f.len != n {
        Err(CanCodecError::WrongLength {
            id: f.id,
            expected: n,
            got: f.len,
        })
    } else {
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// NMT, heartbeat, SYNC

/// NMT commands (byte 0 of a frame on id 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// Start remote node → Operational.
    Start = 0x01,
    /// Stop remote node → Stopped.
    Stop = 0x02,
    /// Enter pre-operational.
    PreOperational = 0x80,
    /// Reset node (→ boot-up → pre-operational).
    ResetNode = 0x81,
    /// Reset communication (→ boot-up → pre-operational).
    ResetCommunication = 0x82,
}

impl NmtCommand {
    /// The command of a byte.
    pub fn from_byte(b: u8) -> Option<Self> {
        Some(match b {
            0x01 => Self::Start,
            0x02 => Self::Stop,
            0x80 => Self::PreOperational,
            0x81 => Self::ResetNode,
            0x82 => Self::ResetCommunication,
            _ => return None,
        })
    }
}

/// NMT command to `node` (0 = every node).
pub fn encode_nmt(cmd: NmtCommand, node: u8) -> Result<WireFrame, CanCodecError> {
    if node > NODE_MAX {
        return Err(CanCodecError::NodeOutOfRange {
            node: u32::from(node),
            max: u32::from(NODE_MAX),
        });
    }
    WireFrame::standard(cob::NMT, &[cmd as u8, node])
}

/// (command, node; 0 = all) of an NMT frame.
pub fn decode_nmt(f: &WireFrame) -> Result<(NmtCommand, u8), CanCodecError> {
    standard_data(f)?;
    if f.id != cob::NMT {
        return Err(CanCodecError::UnknownCommand {
            id: f.id,
            cmd: f.data[0],
        });
    }
    exact_len(f, 2)?;
    let cmd = NmtCommand::from_byte(f.data[0]).ok_or(CanCodecError::UnknownCommand {
        id: f.id,
        cmd: f.data[0],
    })?;
    if f.data[1] > NODE_MAX {
        return Err(CanCodecError::NodeOutOfRange {
            node: u32::from(f.data[1]),
            max: u32::from(NODE_MAX),
        });
    }
    Ok((cmd, f.data[1]))
}

/// The NMT state a heartbeat reports (boot-up = the one frame sent on entering pre-operational).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    /// Boot-up (0x00).
    BootUp = 0x00,
    /// Stopped (0x04).
    Stopped = 0x04,
    /// Operational (0x05).
    Operational = 0x05,
    /// Pre-operational (0x7F).
    PreOperational = 0x7F,
}

impl NmtState {
    /// The state of a heartbeat byte (bit 7, the node-guarding toggle, masked off).
    pub fn from_byte(b: u8) -> Option<Self> {
        Some(match b & 0x7F {
            0x00 => Self::BootUp,
            0x04 => Self::Stopped,
            0x05 => Self::Operational,
            0x7F => Self::PreOperational,
            _ => return None,
        })
    }
}

/// Heartbeat (or boot-up, `NmtState::BootUp`) of `node`.
pub fn encode_heartbeat(node: u8, state: NmtState) -> Result<WireFrame, CanCodecError> {
    WireFrame::standard(node_id(cob::HEARTBEAT, node)?, &[state as u8])
}

/// (node, state) of a heartbeat / boot-up frame.
pub fn decode_heartbeat(f: &WireFrame) -> Result<(u8, NmtState), CanCodecError> {
    standard_data(f)?;
    let CobKind::Heartbeat(node) = classify(f.id) else {
        return Err(CanCodecError::UnknownCommand {
            id: f.id,
            cmd: f.data[0],
        });
    };
    exact_len(f, 1)?;
    let state = NmtState::from_byte(f.data[0]).ok_or(CanCodecError::UnknownCommand {
        id: f.id,
        cmd: f.data[0],
    })?;
    Ok((node, state))
}

/// SYNC without data (`None`) or with the counter (1..=240 when 0x1019 ≥ 2).
pub fn encode_sync(counter: Option<u8>) -> WireFrame {
    let mut f = WireFrame {
        id: cob::SYNC,
        ..WireFrame::default()
    };
    if let Some(c) = counter {
        f.len = 1;
        f.data[0] = c;
    }
    f
}

/// The counter of a SYNC frame (`None`: no counter).
pub fn decode_sync(f: &WireFrame) -> Result<Option<u8>, CanCodecError> {
    standard_data(f)?;
    if f.id != cob::SYNC {
        return Err(CanCodecError::UnknownCommand { id: f.id, cmd: 0 });
    }
    match f.len {
        0 => Ok(None),
        1 => Ok(Some(f.data[0])),
        got => Err(CanCodecError::WrongLength {
            id: f.id,
            expected: 1,
            got,
        }),
    }
}

// ---------------------------------------------------------------------------------------------
// SDO

/// An object dictionary address (index, sub-index).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct SdoAddr {
    /// Index (0x1000..=0xFFFF).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
}

impl SdoAddr {
    /// `index:sub`.
    pub const fn new(index: u16, sub: u8) -> Self {
        Self { index, sub }
    }
}

impl std::fmt::Display for SdoAddr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#06X}:{:02X}", self.index, self.sub)
    }
}

/// Client → server SDO frames this codec speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoRequest {
    /// Expedited download of `len` (1..=4) bytes.
    Download {
        /// Object.
        addr: SdoAddr,
        /// Data (bytes beyond `len` are 0).
        data: [u8; 4],
        /// 1..=4.
        len: u8,
    },
    /// Initiate upload.
    Upload {
        /// Object.
        addr: SdoAddr,
    },
    /// Upload segment request with the toggle bit.
    UploadSegment {
        /// Toggle (starts at false).
        toggle: bool,
    },
    /// Abort.
    Abort {
        /// Object.
        addr: SdoAddr,
        /// Abort code.
        code: u32,
    },
}

/// Server → client SDO frames this codec speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoResponse {
    /// Download acknowledged.
    DownloadAck {
        /// Object.
        addr: SdoAddr,
    },
    /// Expedited upload of `len` (1..=4) bytes (`len` 4 when the server gave no size).
    Upload {
        /// Object.
        addr: SdoAddr,
        /// Data.
        data: [u8; 4],
        /// 1..=4.
        len: u8,
    },
    /// Initiate a segmented upload (`size`: total bytes, when indicated).
    UploadSegmented {
        /// Object.
        addr: SdoAddr,
        /// Total size, if indicated.
        size: Option<u32>,
    },
    /// One upload segment of `len` (0..=7) bytes.
    UploadSegment {
        /// Toggle bit (matches the request's).
        toggle: bool,
        /// Data.
        data: [u8; 7],
        /// 0..=7.
        len: u8,
        /// Last segment.
        last: bool,
    },
    /// Abort.
    Abort {
        /// Object.
        addr: SdoAddr,
        /// Abort code.
        code: u32,
    },
}

/// Expedited download request of a `len`-byte value (little-endian, size bits always set).
pub fn sdo_download(addr: SdoAddr, value: u32, len: u8) -> Result<SdoRequest, CanCodecError> {
    if !(1..=4).contains(&len) {
        return Err(CanCodecError::DataTooLong {
            len: usize::from(len),
        });
    }
    let mut data = [0u8; 4];
    data[..usize::from(len)].copy_from_slice(&value.to_le_bytes()[..usize::from(len)]);
    Ok(SdoRequest::Download { addr, data, len })
}

fn addr_bytes(b: &mut [u8; 8], a: SdoAddr) {
    b[1..3].copy_from_slice(&a.index.to_le_bytes());
    b[3] = a.sub;
}

fn addr_of(b: &[u8; 8]) -> SdoAddr {
    SdoAddr::new(u16::from_le_bytes([b[1], b[2]]), b[3])
}

fn u32_at(b: &[u8; 8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Encodes a request to the SDO server of `node` (id 0x600 + node, 8 bytes).
pub fn encode_sdo_request(node: u8, r: &SdoRequest) -> Result<WireFrame, CanCodecError> {
    let id = node_id(cob::SDO_RX, node)?;
    let mut b = [0u8; 8];
    match *r {
        SdoRequest::Download { addr, data, len } => {
            if !(1..=4).contains(&len) {
                return Err(CanCodecError::DataTooLong {
                    len: usize::from(len),
                });
            }
            // ccs 1, n = 4 − len unused bytes, e = 1, s = 1.
            b[0] = 0x20 | ((4 - len) << 2) | 0x03;
            addr_bytes(&mut b, addr);
            b[4..4 + usize::from(len)].copy_from_slice(&data[..usize::from(len)]);
        }
        SdoRequest::Upload { addr } => {
            b[0] = 0x40;
            addr_bytes(&mut b, addr);
        }
        SdoRequest::UploadSegment { toggle } => b[0] = 0x60 | (u8::from(toggle) << 4),
        SdoRequest::Abort { addr, code } => {
            b[0] = 0x80;
            addr_bytes(&mut b, addr);
            b[4..].copy_from_slice(&code.to_le_bytes());
        }
    }
    WireFrame::standard(id, &b)
}

/// (node, request) of a frame to an SDO server; other client commands (segmented / block download)
/// are [`CanCodecError::UnknownCommand`] (a server answers them with abort 0x05040001).
pub fn decode_sdo_request(f: &WireFrame) -> Result<(u8, SdoRequest), CanCodecError> {
    standard_data(f)?;
    let CobKind::SdoRequest(node) = classify(f.id) else {
        return Err(CanCodecError::UnknownCommand {
            id: f.id,
            cmd: f.data[0],
        });
    };
    exact_len(f, 8)?;
    let b = &f.data;
    let cmd = b[0];
    let unknown = CanCodecError::UnknownCommand { id: f.id, cmd };
    let r = match cmd >> 5 {
        // Initiate download: expedited only.
        1 => {
            if cmd & 0x02 == 0 {
                return Err(unknown);
            }
            let len = if cmd & 0x01 != 0 {
                4 - ((cmd >> 2) & 0x03)
            } else {
                4
            };
            let mut data = [0u8; 4];
            data[..usize::from(len)].copy_from_slice(&b[4..4 + usize::from(len)]);
            SdoRequest::Download {
                addr: addr_of(b),
                data,
                len,
            }
        }
        2 => SdoRequest::Upload { addr: addr_of(b) },
        3 => SdoRequest::UploadSegment {
            toggle: cmd & 0x10 != 0,
        },
        4 => SdoRequest::Abort {
            addr: addr_of(b),
            code: u32_at(b, 4),
        },
        _ => return Err(unknown),
    };
    Ok((node, r))
}

/// Encodes a response of the SDO server of `node` (id 0x580 + node, 8 bytes).
pub fn encode_sdo_response(node: u8, r: &SdoResponse) -> Result<WireFrame, CanCodecError> {
    let id = node_id(cob::SDO_TX, node)?;
    let mut b = [0u8; 8];
    match *r {
        SdoResponse::DownloadAck { addr } => {
            b[0] = 0x60;
            addr_bytes(&mut b, addr);
        }
        SdoResponse::Upload { addr, data, len } => {
            if !(1..=4).contains(&len) {
                return Err(CanCodecError::DataTooLong {
                    len: usize::from(len),
                });
            }
            b[0] = 0x40 | ((4 - len) << 2) | 0x03;
            addr_bytes(&mut b, addr);
            b[4..4 + usize::from(len)].copy_from_slice(&data[..usize::from(len)]);
        }
        SdoResponse::UploadSegmented { addr, size } => {
            b[0] = 0x40 | u8::from(size.is_some());
            addr_bytes(&mut b, addr);
            b[4..].copy_from_slice(&size.unwrap_or(0).to_le_bytes());
        }
        SdoResponse::UploadSegment {
            toggle,
            data,
            len,
            last,
        } => {
            if len > 7 {
                return Err(CanCodecError::DataTooLong {
                    len: usize::from(len),
                });
            }
            b[0] = (u8::from(toggle) << 4) | ((7 - len) << 1) | u8::from(last);
            b[1..1 + usize::from(len)].copy_from_slice(&data[..usize::from(len)]);
        }
        SdoResponse::Abort { addr, code } => {
            b[0] = 0x80;
            addr_bytes(&mut b, addr);
            b[4..].copy_from_slice(&code.to_le_bytes());
        }
    }
    WireFrame::standard(id, &b)
}

/// (node, response) of a frame from an SDO server. A segment is told from an initiate response by
/// the request it answers, so the caller says whether a segmented upload is under way
/// (`in_segment`): then scs 0 is a segment, otherwise it is refused.
pub fn decode_sdo_response(
    f: &WireFrame,
    in_segment: bool,
) -> Result<(u8, SdoResponse), CanCodecError> {
    standard_data(f)?;
    let CobKind::SdoResponse(node) = classify(f.id) else {
        return Err(CanCodecError::UnknownCommand {
            id: f.id,
            cmd: f.data[0],
        });
    };
    exact_len(f, 8)?;
    let b = &f.data;
    let cmd = b[0];
    let unknown = CanCodecError::UnknownCommand { id: f.id, cmd };
    let r = match cmd >> 5 {
        0 if in_segment => {
            let len = 7 - ((cmd >> 1) & 0x07);
            let mut data = [0u8; 7];
            data[..usize::from(len)].copy_from_slice(&b[1..1 + usize::from(len)]);
            SdoResponse::UploadSegment {
                toggle: cmd & 0x10 != 0,
                data,
                len,
                last: cmd & 0x01 != 0,
            }
        }
        2 => {
            let addr = addr_of(b);
            if cmd & 0x02 != 0 {
                let len = if cmd & 0x01 != 0 {
                    4 - ((cmd >> 2) & 0x03)
                } else {
                    4
                };
                let mut data = [0u8; 4];
                data[..usize::from(len)].copy_from_slice(&b[4..4 + usize::from(len)]);
                SdoResponse::Upload { addr, data, len }
            } else {
                SdoResponse::UploadSegmented {
                    addr,
                    size: (cmd & 0x01 != 0).then(|| u32_at(b, 4)),
                }
            }
        }
        3 => SdoResponse::DownloadAck { addr: addr_of(b) },
        4 => SdoResponse::Abort {
            addr: addr_of(b),
            code: u32_at(b, 4),
        },
        _ => return Err(unknown),
    };
    Ok((node, r))
}

/// CiA 301 SDO abort codes this project produces or reports by name.
pub mod abort {
    /// Toggle bit not alternated.
    pub const TOGGLE: u32 = 0x0503_0000;
    /// SDO protocol timed out.
    pub const TIMEOUT: u32 = 0x0504_0000;
    /// Client/server command specifier not valid or unknown.
    pub const UNKNOWN_COMMAND: u32 = 0x0504_0001;
    /// Unsupported access to an object.
    pub const UNSUPPORTED_ACCESS: u32 = 0x0601_0000;
    /// Attempt to read a write-only object.
    pub const WRITE_ONLY: u32 = 0x0601_0001;
    /// Attempt to write a read-only object.
    pub const READ_ONLY: u32 = 0x0601_0002;
    /// Object does not exist in the object dictionary.
    pub const NO_OBJECT: u32 = 0x0602_0000;
    /// Object cannot be mapped to the PDO.
    pub const NOT_MAPPABLE: u32 = 0x0604_0041;
    /// The number and length of the objects to be mapped would exceed the PDO length.
    pub const PDO_TOO_LONG: u32 = 0x0604_0042;
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH_MISMATCH: u32 = 0x0607_0010;
    /// Sub-index does not exist.
    pub const NO_SUB: u32 = 0x0609_0011;
    /// Value range of parameter exceeded (only for write access).
    pub const RANGE: u32 = 0x0609_0030;
    /// Resource not available.
    pub const NOT_AVAILABLE: u32 = 0x060A_0023;
    /// General error.
    pub const GENERAL: u32 = 0x0800_0000;
    /// Data cannot be transferred or stored because of the present device state.
    pub const DEVICE_STATE: u32 = 0x0800_0022;
}

/// The CiA 301 meaning of an SDO abort code (`"unknown abort code"` for others).
pub fn abort_text(code: u32) -> &'static str {
    match code {
        0x0503_0000 => "toggle bit not alternated",
        0x0504_0000 => "SDO protocol timed out",
        0x0504_0001 => "client/server command specifier not valid or unknown",
        0x0504_0002 => "invalid block size",
        0x0504_0003 => "invalid sequence number",
        0x0504_0004 => "CRC error",
        0x0504_0005 => "out of memory",
        0x0601_0000 => "unsupported access to an object",
        0x0601_0001 => "attempt to read a write-only object",
        0x0601_0002 => "attempt to write a read-only object",
        0x0602_0000 => "object does not exist in the object dictionary",
        0x0604_0041 => "object cannot be mapped to the PDO",
        0x0604_0042 => "the objects to be mapped would exceed the PDO length",
        0x0604_0043 => "general parameter incompatibility",
        0x0604_0047 => "general internal incompatibility in the device",
        0x0606_0000 => "access failed due to a hardware error",
        0x0607_0010 => "data type does not match, length of service parameter does not match",
        0x0607_0012 => "data type does not match, length of service parameter too high",
        0x0607_0013 => "data type does not match, length of service parameter too low",
        0x0609_0011 => "sub-index does not exist",
        0x0609_0030 => "value range of parameter exceeded",
        0x0609_0031 => "value of parameter written too high",
        0x0609_0032 => "value of parameter written too low",
        0x0609_0036 => "maximum value is less than minimum value",
        0x060A_0023 => "resource not available",
        0x0800_0000 => "general error",
        0x0800_0020 => "data cannot be transferred or stored to the application",
        0x0800_0021 => "data cannot be transferred or stored because of local control",
        0x0800_0022 => "data cannot be transferred or stored because of the present device state",
        0x0800_0023 => "object dictionary dynamic generation fails or no object dictionary",
        0x0800_0024 => "no data available",
        _ => "unknown abort code",
    }
}

// ---------------------------------------------------------------------------------------------
// EMCY

/// An emergency message (COB-ID 0x80 + node, 8 bytes; 0x80 alone is SYNC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Emcy {
    /// Error code (0x0000 = error reset / no error).
    pub code: u16,
    /// Error register (a copy of 0x1001).
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub manufacturer: [u8; 5],
}

impl Emcy {
    /// Whether this is the "error reset / no error" message.
    pub fn is_reset(&self) -> bool {
        self.code == 0
    }
}

/// EMCY of `node`.
pub fn encode_emcy(node: u8, e: &Emcy) -> Result<WireFrame, CanCodecError> {
    let mut b = [0u8; 8];
    b[..2].copy_from_slice(&e.code.to_le_bytes());
    b[2] = e.register;
    b[3..].copy_from_slice(&e.manufacturer);
    WireFrame::standard(node_id(cob::EMCY, node)?, &b)
}

/// (node, EMCY). Frames shorter than 8 bytes are refused (CiA 301 fixes the length).
pub fn decode_emcy(f: &WireFrame) -> Result<(u8, Emcy), CanCodecError> {
    standard_data(f)?;
    let CobKind::Emcy(node) = classify(f.id) else {
        return Err(CanCodecError::UnknownCommand {
            id: f.id,
            cmd: f.data[0],
        });
    };
    exact_len(f, 8)?;
    let b = &f.data;
    Ok((
        node,
        Emcy {
            code: u16::from_le_bytes([b[0], b[1]]),
            register: b[2],
            manufacturer: [b[3], b[4], b[5], b[6], b[7]],
        },
    ))
}

/// The family (or, for the common CiA 301 / 402 codes, the meaning) of an EMCY error code.
pub fn emcy_text(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x2310 => "continuous over-current",
        0x2350 => "I²t fault",
        0x3210 => "DC-link over-voltage",
        0x3220 => "DC-link under-voltage",
        0x4210 => "device over-temperature",
        0x4310 => "drive over-temperature",
        0x7121 => "motor blocked",
        0x7300 => "sensor",
        0x8110 => "CAN overrun",
        0x8120 => "CAN error passive",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus-off",
        0x8210 => "PDO not processed due to length error",
        0x8240 => "unexpected SYNC data length",
        0x8250 => "RPDO timeout",
        0x8311 => "excess torque",
        0x8611 => "following error",
        _ => match code >> 12 {
            0x1 => "generic error",
            0x2 => "current",
            0x3 => "voltage",
            0x4 => "temperature",
            0x5 => "device hardware",
            0x6 => "device software",
            0x7 => "additional modules",
            0x8 => "monitoring",
            0x9 => "external error",
            0xF if code >> 8 == 0xFF => "device specific",
            _ => "unknown error code",
        },
    }
}

// ---------------------------------------------------------------------------------------------
// PDOs

/// One mapped object: `index << 16 | sub << 8 | bits` in a mapping parameter (0x16xx / 0x1Axx).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct PdoEntry {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Length in bits: 8, 16 or 32.
    pub bits: u8,
}

impl PdoEntry {
    /// An entry (unchecked; [`PdoMap::new`] checks the length).
    pub const fn new(index: u16, sub: u8, bits: u8) -> Self {
        Self { index, sub, bits }
    }

    /// The mapping value `index << 16 | sub << 8 | bits`.
    pub const fn to_mapping(self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | self.bits as u32
    }

    /// The entry of a mapping value.
    pub const fn from_mapping(v: u32) -> Self {
        Self {
            index: (v >> 16) as u16,
            sub: (v >> 8) as u8,
            bits: v as u8,
        }
    }

    /// Bytes on the wire.
    pub const fn bytes(self) -> u8 {
        self.bits / 8
    }
}

/// Largest number of entries of one PDO (CiA 301: sub 1..8 at 8 bits each).
pub const PDO_MAX_ENTRIES: usize = 8;

/// A PDO mapping: up to 8 entries of 8, 16 or 32 bits, at most 64 bits in all. `Copy`, no heap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PdoMap {
    entries: [PdoEntry; PDO_MAX_ENTRIES],
    n: u8,
}

impl PdoMap {
    /// A checked mapping (`BadUnitParameter` names what is wrong: `pdo entry bits` with the bits of
    /// the first entry that is not 8/16/32, `pdo length bits` with the total over 64, `pdo entries`
    /// with the count over 8).
    pub fn new(entries: &[PdoEntry]) -> Result<Self, CanCodecError> {
        if entries.len() > PDO_MAX_ENTRIES {
            return Err(CanCodecError::BadUnitParameter {
                field: "pdo entries",
                value: entries.len() as f64,
            });
        }
        let mut total = 0u32;
        for e in entries {
            if !matches!(e.bits, 8 | 16 | 32) {
                return Err(CanCodecError::BadUnitParameter {
                    field: "pdo entry bits",
                    value: f64::from(e.bits),
                });
            }
            total += u32::from(e.bits);
        }
        if total > 64 {
            return Err(CanCodecError::BadUnitParameter {
                field: "pdo length bits",
                value: f64::from(total),
            });
        }
        let mut m = Self::default();
        m.entries[..entries.len()].copy_from_slice(entries);
        m.n = entries.len() as u8;
        Ok(m)
    }

    /// The entries, in order.
    pub fn entries(&self) -> &[PdoEntry] {
        &self.entries[..usize::from(self.n)]
    }

    /// Data bytes of the PDO.
    pub fn bytes(&self) -> u8 {
        self.entries().iter().map(|e| e.bytes()).sum()
    }

    /// Position of the entry for `index:sub`, if mapped.
    pub fn position(&self, index: u16, sub: u8) -> Option<usize> {
        self.entries()
            .iter()
            .position(|e| e.index == index && e.sub == sub)
    }
}

/// Encodes `values` (one per entry, in order) as the PDO on `cob_id`. A value must fit its entry as
/// a signed or an unsigned number of that many bits (-2^(b−1) ..= 2^b − 1), else
/// `BadUnitParameter { field: "pdo value", .. }`; never truncated.
pub fn encode_pdo(cob_id: u32, map: &PdoMap, values: &[i64]) -> Result<WireFrame, CanCodecError> {
    if values.len() != map.entries().len() {
        return Err(CanCodecError::WrongLength {
            id: cob_id,
            expected: map.n,
            got: values.len().min(255) as u8,
        });
    }
    let mut b = [0u8; 8];
    let mut at = 0usize;
    for (e, &v) in map.entries().iter().zip(values) {
        let bits = u32::from(e.bits);
        let lo = -(1i64 << (bits - 1));
        let hi = (1i64 << bits) - 1;
        if v < lo || v > hi {
            return Err(CanCodecError::BadUnitParameter {
                field: "pdo value",
                value: v as f64,
            });
        }
        let n = usize::from(e.bytes());
        b[at..at + n].copy_from_slice(&v.to_le_bytes()[..n]);
        at += n;
    }
    WireFrame::standard(cob_id, &b[..at])
}

/// Decodes a PDO into `out` (one raw unsigned value per entry; [`sign_extend`] for signed
/// objects). The frame must be exactly the mapping's length (CiA 301: a drive reports a length
/// mismatch with EMCY 0x8210; the master refuses the frame).
pub fn decode_pdo(f: &WireFrame, map: &PdoMap, out: &mut [u32]) -> Result<(), CanCodecError> {
    standard_data(f)?;
    exact_len(f, map.bytes())?;
    if out.len() < map.entries().len() {
        return Err(CanCodecError::WrongLength {
            id: f.id,
            expected: map.n,
            got: out.len().min(255) as u8,
        });
    }
    let mut at = 0usize;
    for (e, o) in map.entries().iter().zip(out.iter_mut()) {
        let n = usize::from(e.bytes());
        let mut w = [0u8; 4];
        w[..n].copy_from_slice(&f.data[at..at + n]);
        *o = u32::from_le_bytes(w);
        at += n;
    }
    Ok(())
}

/// The signed value of the low `bits` (8, 16 or 32) bits of `raw`.
pub const fn sign_extend(raw: u32, bits: u8) -> i32 {
    match bits {
        8 => raw as u8 as i8 as i32,
        16 => raw as u16 as i16 as i32,
        _ => raw as i32,
    }
}

/// PDO transmission type "synchronous, every SYNC" (sub 2 of 0x14xx / 0x18xx).
pub const TRANSMISSION_SYNC_EVERY: u8 = 1;
/// COB-ID bit 31: PDO not valid.
pub const COB_ID_INVALID: u32 = 1 << 31;
/// COB-ID bit 30 (TPDO): no RTR allowed.
pub const COB_ID_NO_RTR: u32 = 1 << 30;

/// The PDO layout frictiond maps on a CiA 402 drive (all synchronous, transmission type 1 unless
/// noted): RPDO1 = controlword 0x6040 + target torque 0x6071 (CST) or torque offset 0x60B2;
/// TPDO1 = statusword 0x6041 + position actual 0x6064 + torque actual 0x6077 (8 bytes);
/// TPDO2 = velocity actual 0x606C [+ the joint-side encoder]; TPDO3 (optional) = the temperature
/// object, every `tpdo3_every` SYNCs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// RPDO1 mapping.
    pub rpdo1: PdoMap,
    /// TPDO1 mapping.
    pub tpdo1: PdoMap,
    /// TPDO2 mapping.
    pub tpdo2: PdoMap,
    /// TPDO3 mapping (temperature), if any.
    pub tpdo3: Option<PdoMap>,
    /// TPDO3 transmission type (every n-th SYNC, 1..=240).
    pub tpdo3_every: u8,
}

impl Layout {
    /// The layout for a drive (`torque_offset`: 0x60B2 instead of 0x6071).
    pub fn new(
        torque_offset: bool,
        joint_encoder: Option<PdoEntry>,
        temperature: Option<PdoEntry>,
        tpdo3_every: u8,
    ) -> Result<Self, CanCodecError> {
        let target = if torque_offset {
            obj::TORQUE_OFFSET
        } else {
            obj::TARGET_TORQUE
        };
        let rpdo1 = PdoMap::new(&[
            PdoEntry::new(obj::CONTROLWORD, 0, 16),
            PdoEntry::new(target, 0, 16),
        ])?;
        let tpdo1 = PdoMap::new(&[
            PdoEntry::new(obj::STATUSWORD, 0, 16),
            PdoEntry::new(obj::POSITION_ACTUAL, 0, 32),
            PdoEntry::new(obj::TORQUE_ACTUAL, 0, 16),
        ])?;
        let vel = PdoEntry::new(obj::VELOCITY_ACTUAL, 0, 32);
        let tpdo2 = match joint_encoder {
            Some(e) => PdoMap::new(&[vel, e])?,
            None => PdoMap::new(&[vel])?,
        };
        let tpdo3 = temperature.map(|t| PdoMap::new(&[t])).transpose()?;
        if !(1..=240).contains(&tpdo3_every) {
            return Err(CanCodecError::BadUnitParameter {
                field: "temperature_every",
                value: f64::from(tpdo3_every),
            });
        }
        Ok(Self {
            rpdo1,
            tpdo1,
            tpdo2,
            tpdo3,
            tpdo3_every,
        })
    }

    /// Worst-case bits per SYNC cycle of this layout (without the SYNC itself).
    pub fn bits_per_tick(&self) -> u32 {
        let mut t = [(self.tpdo1.bytes(), 1), (self.tpdo2.bytes(), 1), (0, 1)];
        let n = match self.tpdo3 {
            Some(m) => {
                t[2] = (m.bytes(), self.tpdo3_every);
                3
            }
            None => 2,
        };
        super::busload::cia402_bits_per_node_tick(&[self.rpdo1.bytes()], &t[..n])
    }

    /// Frames per cycle (RPDO1, TPDO1, TPDO2; TPDO3 counted when sent every cycle).
    pub fn frames_per_tick(&self) -> u32 {
        3 + u32::from(self.tpdo3.is_some() && self.tpdo3_every == 1)
    }
}

// ---------------------------------------------------------------------------------------------
// CiA 402

/// Object indices used by this project (sub 0 unless noted).
pub mod obj {
    /// Device type.
    pub const DEVICE_TYPE: u16 = 0x1000;
    /// Error register.
    pub const ERROR_REGISTER: u16 = 0x1001;
    /// Manufacturer device name (string).
    pub const DEVICE_NAME: u16 = 0x1008;
    /// COB-ID SYNC.
    pub const COB_ID_SYNC: u16 = 0x1005;
    /// Communication cycle period [µs].
    pub const CYCLE_PERIOD: u16 = 0x1006;
    /// Consumer heartbeat time (ARRAY of UNSIGNED32).
    pub const CONSUMER_HEARTBEAT: u16 = 0x1016;
    /// Producer heartbeat time [ms].
    pub const PRODUCER_HEARTBEAT: u16 = 0x1017;
    /// Identity (sub 1 vendor, 2 product, 3 revision, 4 serial).
    pub const IDENTITY: u16 = 0x1018;
    /// RPDO1 communication parameter (RPDOn: + n − 1).
    pub const RPDO_COMM: u16 = 0x1400;
    /// RPDO1 mapping (RPDOn: + n − 1).
    pub const RPDO_MAP: u16 = 0x1600;
    /// TPDO1 communication parameter.
    pub const TPDO_COMM: u16 = 0x1800;
    /// TPDO1 mapping.
    pub const TPDO_MAP: u16 = 0x1A00;
    /// Error code (last fault).
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword (UNSIGNED16).
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword (UNSIGNED16).
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code (INTEGER16).
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Modes of operation (INTEGER8).
    pub const MODES_OF_OPERATION: u16 = 0x6060;
    /// Modes of operation display (INTEGER8).
    pub const MODES_DISPLAY: u16 = 0x6061;
    /// Position actual value (INTEGER32, increments).
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Velocity actual value (INTEGER32, velocity units).
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    /// Target torque (INTEGER16, ‰ of rated torque).
    pub const TARGET_TORQUE: u16 = 0x6071;
    /// Max torque (UNSIGNED16, ‰ of rated torque).
    pub const MAX_TORQUE: u16 = 0x6072;
    /// Motor rated torque (UNSIGNED32, mNm).
    pub const RATED_TORQUE: u16 = 0x6076;
    /// Torque actual value (INTEGER16, ‰ of rated torque).
    pub const TORQUE_ACTUAL: u16 = 0x6077;
    /// Position encoder resolution (sub 1 increments, sub 2 motor revolutions; UNSIGNED32).
    pub const ENCODER_RESOLUTION: u16 = 0x608F;
    /// Torque offset (INTEGER16, ‰ of rated torque).
    pub const TORQUE_OFFSET: u16 = 0x60B2;
    /// Additional position actual value (sub 1 = second encoder; INTEGER32).
    pub const ADDITIONAL_POSITION: u16 = 0x60E4;
    /// Supported drive modes (UNSIGNED32 bit map).
    pub const SUPPORTED_MODES: u16 = 0x6502;
}

/// Modes of operation (0x6060 / 0x6061) this project uses.
pub mod mode {
    /// Cyclic synchronous position.
    pub const CSP: i8 = 8;
    /// Cyclic synchronous velocity.
    pub const CSV: i8 = 9;
    /// Cyclic synchronous torque.
    pub const CST: i8 = 10;

    /// The 0x6502 bit of a mode 1..=10 (`None` for others).
    pub const fn supported_bit(mode: i8) -> Option<u32> {
        if mode >= 1 && mode <= 10 {
            Some(1 << (mode - 1))
        } else {
            None
        }
    }
}

/// Controlword 0x6040 commands.
pub mod cw {
    /// Disable voltage (→ switch on disabled).
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop (bit 2 = 0 with enable voltage).
    pub const QUICK_STOP: u16 = 0x0002;
    /// Shutdown (→ ready to switch on).
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on (→ switched on); also disable operation.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation (→ operation enabled).
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Fault reset (bit 7; acts on its rising edge).
    pub const FAULT_RESET: u16 = 0x0080;
}

/// The CiA 402 power state machine's states (statusword 0x6041).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Not ready to switch on.
    NotReadyToSwitchOn,
    /// Switch on disabled.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on.
    SwitchedOn,
    /// Operation enabled (the drive follows the target).
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

impl DriveState {
    /// The statusword bits of this state (bits 0–3, 5, 6; bit 4 voltage enabled where the state has
    /// it). What an emulated drive reports.
    pub const fn statusword(self) -> u16 {
        match self {
            DriveState::NotReadyToSwitchOn => 0x0000,
            DriveState::SwitchOnDisabled => 0x0040,
            DriveState::ReadyToSwitchOn => 0x0021,
            DriveState::SwitchedOn => 0x0033,
            DriveState::OperationEnabled => 0x0037,
            DriveState::QuickStopActive => 0x0017,
            DriveState::FaultReactionActive => 0x001F,
            DriveState::Fault => 0x0008,
        }
    }

    /// Name as CiA 402 (and python canopen's `state`) spells it.
    pub const fn name(self) -> &'static str {
        match self {
            DriveState::NotReadyToSwitchOn => "NOT READY TO SWITCH ON",
            DriveState::SwitchOnDisabled => "SWITCH ON DISABLED",
            DriveState::ReadyToSwitchOn => "READY TO SWITCH ON",
            DriveState::SwitchedOn => "SWITCHED ON",
            DriveState::OperationEnabled => "OPERATION ENABLED",
            DriveState::QuickStopActive => "QUICK STOP ACTIVE",
            DriveState::FaultReactionActive => "FAULT REACTION ACTIVE",
            DriveState::Fault => "FAULT",
        }
    }
}

/// The state a statusword reports (`None`: a bit pattern of no state).
pub const fn decode_statusword(sw: u16) -> Option<DriveState> {
    let m4f = sw & 0x4F;
    let m6f = sw & 0x6F;
    if m4f == 0x00 {
        Some(DriveState::NotReadyToSwitchOn)
    } else if m4f == 0x40 {
        Some(DriveState::SwitchOnDisabled)
    } else if m6f == 0x21 {
        Some(DriveState::ReadyToSwitchOn)
    } else if m6f == 0x23 {
        Some(DriveState::SwitchedOn)
    } else if m6f == 0x27 {
        Some(DriveState::OperationEnabled)
    } else if m6f == 0x07 {
        Some(DriveState::QuickStopActive)
    } else if m4f == 0x0F {
        Some(DriveState::FaultReactionActive)
    } else if m4f == 0x08 {
        Some(DriveState::Fault)
    } else {
        None
    }
}

/// The drive's side: the state after controlword `cw` in state `s` (transitions 2–12, 15, 16 of
/// CiA 402). `fault_reset_edge`: bit 7 rose since the previous controlword. `quick_stop_stays`:
/// quick stop option code 5..=8 (stay in quick stop active; 0x605A = 0..=4 ends in switch on
/// disabled). Fault reaction and faults themselves are the drive's (not a controlword's) doing.
pub const fn apply_controlword(
    s: DriveState,
    cw: u16,
    fault_reset_edge: bool,
    quick_stop_stays: bool,
) -> DriveState {
    use DriveState::*;
    let disable_voltage = cw & 0x0082 == 0x0000;
    let quick_stop = cw & 0x0086 == 0x0002;
    let shutdown = cw & 0x0087 == 0x0006;
    let switch_on = cw & 0x008F == 0x0007;
    let enable = cw & 0x008F == 0x000F;
    match s {
        NotReadyToSwitchOn => SwitchOnDisabled,
        FaultReactionActive => Fault,
        Fault => {
            if fault_reset_edge {
                SwitchOnDisabled
            } else {
                Fault
            }
        }
        SwitchOnDisabled => {
            if shutdown {
                ReadyToSwitchOn
            } else {
                SwitchOnDisabled
            }
        }
        ReadyToSwitchOn => {
            if disable_voltage || quick_stop {
                SwitchOnDisabled
            } else if switch_on {
                SwitchedOn
            } else if enable {
                // 3 + 4 in one step, as drives (and python canopen's LocalNode examples) accept.
                OperationEnabled
            } else {
                ReadyToSwitchOn
            }
        }
        SwitchedOn => {
            if disable_voltage || quick_stop {
                SwitchOnDisabled
            } else if shutdown {
                ReadyToSwitchOn
            } else if enable {
                OperationEnabled
            } else {
                SwitchedOn
            }
        }
        OperationEnabled => {
            if disable_voltage {
                SwitchOnDisabled
            } else if quick_stop {
                QuickStopActive
            } else if shutdown {
                ReadyToSwitchOn
            } else if switch_on {
                SwitchedOn
            } else {
                OperationEnabled
            }
        }
        QuickStopActive => {
            if disable_voltage || !quick_stop_stays {
                SwitchOnDisabled
            } else if enable {
                OperationEnabled
            } else {
                QuickStopActive
            }
        }
    }
}

/// What the master wants of a drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Goal {
    /// Operation enabled (the joint is commanded).
    Enabled,
    /// Quick stop (stop, SIGTERM, a fault of the daemon): quick stop from operation enabled, disable
    /// voltage from the other states.
    QuickStop,
    /// Voltage disabled.
    Disabled,
}

/// The master's controlword sequencing, one step per cycle (allocation-free, `Copy`): the enable
/// path switch on disabled → ready → switched on → operation enabled (one transition per
/// statusword seen), quick stop, and fault reset — only when `fault_reset_allowed`, as a 0 → 1
/// edge of bit 7 (one cycle 0x0000, the next 0x0080), at most once per `reset_every` cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Enabler {
    /// Whether a fault may be reset by the master.
    pub fault_reset_allowed: bool,
    /// Cycles between fault-reset attempts (≥ 2).
    pub reset_every: u32,
    since_reset: u32,
    last_cw: u16,
}

impl Enabler {
    /// A sequencer; `reset_every` is raised to 2 (the edge needs two cycles).
    pub const fn new(fault_reset_allowed: bool, reset_every: u32) -> Self {
        Self {
            fault_reset_allowed,
            reset_every: if reset_every < 2 { 2 } else { reset_every },
            since_reset: u32::MAX,
            last_cw: Self::NOTHING_SENT,
        }
    }

    /// [`Enabler::last`] before the first [`Enabler::next`] (no controlword sent yet).
    pub const NOTHING_SENT: u16 = 0xFFFF;

    /// The controlword last returned by [`Enabler::next`] ([`Enabler::NOTHING_SENT`] before).
    pub const fn last(&self) -> u16 {
        self.last_cw
    }

    /// The controlword for this cycle given the drive's last reported state (`None`: unknown, no
    /// statusword yet or an invalid pattern).
    pub fn next(&mut self, state: Option<DriveState>, goal: Goal) -> u16 {
        use DriveState::*;
        self.since_reset = self.since_reset.saturating_add(1);
        let word = match (state, goal) {
            (None, _) | (Some(NotReadyToSwitchOn | FaultReactionActive), _) => cw::DISABLE_VOLTAGE,
            (Some(Fault), _) => {
                if self.fault_reset_allowed
                    && goal == Goal::Enabled
                    && self.since_reset >= self.reset_every
                    && self.last_cw == cw::DISABLE_VOLTAGE
                {
                    self.since_reset = 0;
                    cw::FAULT_RESET
                } else {
                    cw::DISABLE_VOLTAGE
                }
            }
            (Some(_), Goal::Disabled) => cw::DISABLE_VOLTAGE,
            (Some(OperationEnabled | QuickStopActive), Goal::QuickStop) => cw::QUICK_STOP,
            (Some(_), Goal::QuickStop) => cw::DISABLE_VOLTAGE,
            (Some(SwitchOnDisabled), Goal::Enabled) => cw::SHUTDOWN,
            (Some(ReadyToSwitchOn), Goal::Enabled) => cw::SWITCH_ON,
            (Some(SwitchedOn | OperationEnabled), Goal::Enabled) => cw::ENABLE_OPERATION,
            // Quick stop active with an option code that stays there: disable voltage, then the
            // enable path from switch on disabled.
            (Some(QuickStopActive), Goal::Enabled) => cw::DISABLE_VOLTAGE,
        };
        self.last_cw = word;
        word
    }
}

// ---------------------------------------------------------------------------------------------
// Units

/// Per mille of the motor rated torque 0x6076 ↔ motor torque [Nm].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueScale {
    /// Motor rated torque [mNm] (0x6076), > 0.
    pub rated_mnm: u32,
    /// Max torque [‰ of rated] (0x6072): commands are clamped to ±this (and to the INT16 range).
    pub max_permille: u16,
}

impl TorqueScale {
    /// Checked scale: `rated_mnm` > 0, `max_permille` > 0.
    pub fn new(rated_mnm: u32, max_permille: u16) -> Result<Self, CanCodecError> {
        if rated_mnm == 0 {
            return Err(CanCodecError::BadUnitParameter {
                field: "rated_torque_mnm",
                value: 0.0,
            });
        }
        if max_permille == 0 {
            return Err(CanCodecError::BadUnitParameter {
                field: "max_torque_permille",
                value: 0.0,
            });
        }
        Ok(Self {
            rated_mnm,
            max_permille,
        })
    }

    /// Motor rated torque [Nm].
    pub fn rated_nm(&self) -> f64 {
        f64::from(self.rated_mnm) / 1000.0
    }

    /// The largest motor torque a command can carry [Nm].
    pub fn max_nm(&self) -> f64 {
        self.motor_nm(i32::from(self.max_permille.min(i16::MAX as u16)))
    }

    /// ‰ for a motor torque, rounded, clamped to ±`max_permille` (and the INT16 range); the bool
    /// says whether it was clamped. Non-finite torques are refused.
    pub fn permille(&self, motor_nm: f64) -> Result<(i16, bool), CanCodecError> {
        if !motor_nm.is_finite() {
            return Err(CanCodecError::NonFinite { field: "torque" });
        }
        let lim = f64::from(self.max_permille.min(i16::MAX as u16));
        let x = (motor_nm * 1_000_000.0 / f64::from(self.rated_mnm)).round();
        let c = x.clamp(-lim, lim);
        Ok((c as i16, c != x))
    }

    /// Motor torque [Nm] of a ‰ value.
    pub fn motor_nm(&self, permille: i32) -> f64 {
        f64::from(permille) * f64::from(self.rated_mnm) / 1_000_000.0
    }
}

/// Increments ↔ radians: `counts_per_rev` increments per revolution of the shaft the encoder reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngleScale {
    /// Increments per revolution (> 0).
    pub counts_per_rev: f64,
}

impl AngleScale {
    /// Checked scale (finite, > 0).
    pub fn new(counts_per_rev: f64) -> Result<Self, CanCodecError> {
        if !(counts_per_rev.is_finite() && counts_per_rev > 0.0) {
            return Err(CanCodecError::BadUnitParameter {
                field: "counts_per_rev",
                value: counts_per_rev,
            });
        }
        Ok(Self { counts_per_rev })
    }

    /// Radians of `counts` increments.
    pub fn rad(&self, counts: f64) -> f64 {
        counts * core::f64::consts::TAU / self.counts_per_rev
    }

    /// Increments of `rad` radians (not rounded).
    pub fn counts(&self, rad: f64) -> f64 {
        rad * self.counts_per_rev / core::f64::consts::TAU
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classify_the_predefined_set() {
        assert_eq!(classify(0x000), CobKind::Nmt);
        assert_eq!(classify(0x080), CobKind::Sync);
        assert_eq!(classify(0x085), CobKind::Emcy(5));
        assert_eq!(classify(0x185), CobKind::Tpdo(1, 5));
        assert_eq!(classify(0x2FF), CobKind::Tpdo(2, 0x7F));
        assert_eq!(classify(0x205), CobKind::Rpdo(1, 5));
        assert_eq!(classify(0x585), CobKind::SdoResponse(5));
        assert_eq!(classify(0x605), CobKind::SdoRequest(5));
        assert_eq!(classify(0x705), CobKind::Heartbeat(5));
        assert_eq!(classify(0x180), CobKind::Other);
        assert_eq!(classify(0x800), CobKind::Other);
        for n in 1..=4u8 {
            assert_eq!(classify(tpdo_id(n, 9).unwrap()), CobKind::Tpdo(n, 9));
            assert_eq!(classify(rpdo_id(n, 9).unwrap()), CobKind::Rpdo(n, 9));
        }
        assert!(tpdo_id(5, 1).is_err());
        assert!(rpdo_id(1, 0).is_err());
        assert!(rpdo_id(1, 128).is_err());
    }

    #[test]
    fn statusword_patterns_and_drive_statuswords_agree() {
        use DriveState::*;
        for s in [
            NotReadyToSwitchOn,
            SwitchOnDisabled,
            ReadyToSwitchOn,
            SwitchedOn,
            OperationEnabled,
            QuickStopActive,
            FaultReactionActive,
            Fault,
        ] {
            assert_eq!(decode_statusword(s.statusword()), Some(s), "{s:?}");
            // Warning, remote, target reached and manufacturer bits do not change the state.
            assert_eq!(decode_statusword(s.statusword() | 0xFF80), Some(s), "{s:?}");
        }
        // python canopen's trace values.
        assert_eq!(decode_statusword(0x0250), Some(SwitchOnDisabled));
        assert_eq!(decode_statusword(0x0237), Some(OperationEnabled));
        assert_eq!(decode_statusword(0x0001), None);
    }

    #[test]
    fn enabler_walks_the_path_one_transition_per_statusword() {
        let mut e = Enabler::new(false, 10);
        let mut s = DriveState::SwitchOnDisabled;
        let mut words = Vec::new();
        for _ in 0..5 {
            let w = e.next(Some(s), Goal::Enabled);
            words.push(w);
            s = apply_controlword(s, w, false, false);
        }
        assert_eq!(words, [0x06, 0x07, 0x0F, 0x0F, 0x0F]);
        assert_eq!(s, DriveState::OperationEnabled);
        let w = e.next(Some(s), Goal::QuickStop);
        assert_eq!(w, cw::QUICK_STOP);
        let q = apply_controlword(s, w, false, false);
        assert_eq!(q, DriveState::QuickStopActive);
        // Option codes 0..=4: the stop ends in switch on disabled; 5..=8 stay until enabled again.
        assert_eq!(
            apply_controlword(q, w, false, false),
            DriveState::SwitchOnDisabled
        );
        assert_eq!(
            apply_controlword(q, w, false, true),
            DriveState::QuickStopActive
        );
        assert_eq!(
            apply_controlword(q, cw::ENABLE_OPERATION, false, true),
            DriveState::OperationEnabled
        );
        assert_eq!(e.next(None, Goal::Enabled), cw::DISABLE_VOLTAGE);
    }

    #[test]
    fn fault_reset_is_an_edge_and_only_when_allowed() {
        let mut no = Enabler::new(false, 4);
        for _ in 0..20 {
            assert_eq!(
                no.next(Some(DriveState::Fault), Goal::Enabled),
                cw::DISABLE_VOLTAGE
            );
        }
        let mut yes = Enabler::new(true, 4);
        let words: Vec<u16> = (0..9)
            .map(|_| yes.next(Some(DriveState::Fault), Goal::Enabled))
            .collect();
        // First cycle 0x0000 (a 0 before the edge), then 0x0080, then 0x0000 until 4 cycles passed.
        assert_eq!(words, [0, 0x80, 0, 0, 0, 0x80, 0, 0, 0]);
        // A quick stop goal never resets a fault.
        let mut q = Enabler::new(true, 2);
        for _ in 0..5 {
            assert_eq!(q.next(Some(DriveState::Fault), Goal::QuickStop), 0);
        }
        assert_eq!(
            apply_controlword(DriveState::Fault, 0x80, true, false),
            DriveState::SwitchOnDisabled
        );
        assert_eq!(
            apply_controlword(DriveState::Fault, 0x80, false, false),
            DriveState::Fault
        );
    }

    #[test]
    fn layout_bits() {
        let l = Layout::new(false, None, None, 100).unwrap();
        assert_eq!(
            (l.rpdo1.bytes(), l.tpdo1.bytes(), l.tpdo2.bytes()),
            (4, 8, 4)
        );
        assert_eq!(l.bits_per_tick(), 95 + 135 + 95);
        let enc = PdoEntry::new(obj::ADDITIONAL_POSITION, 1, 32);
        let temp = PdoEntry::new(0x2031, 1, 32);
        let l = Layout::new(true, Some(enc), Some(temp), 100).unwrap();
        assert_eq!(l.rpdo1.entries()[1].index, obj::TORQUE_OFFSET);
        assert_eq!(l.bits_per_tick(), 95 + 135 + 135 + 1);
        assert!(Layout::new(false, None, Some(temp), 0).is_err());
        assert!(Layout::new(false, Some(PdoEntry::new(0x60E4, 1, 12)), None, 1).is_err());
    }

    #[test]
    fn torque_scale_rounds_and_clamps() {
        let t = TorqueScale::new(2500, 3000).unwrap(); // 2.5 Nm rated, max 300 %
        assert_eq!(t.permille(1.0).unwrap(), (400, false));
        assert_eq!(t.permille(-0.00125).unwrap(), (-1, false)); // −0.5 ‰ rounds away from 0
        assert_eq!(t.permille(100.0).unwrap(), (3000, true));
        assert_eq!(t.motor_nm(-400), -1.0);
        assert!((t.max_nm() - 7.5).abs() < 1e-12);
        assert!(t.permille(f64::NAN).is_err());
        assert!(TorqueScale::new(0, 1000).is_err());
        let a = AngleScale::new(4096.0).unwrap();
        assert!((a.rad(1024.0) - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(AngleScale::new(0.0).is_err());
    }
}
