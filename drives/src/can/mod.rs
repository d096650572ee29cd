//! # CAN motor-drive wire formats
//!
//! What this module **is**: pure, allocation-free encoders/decoders of the CAN frames spoken by motor
//! drives, shared by `frictiond` (sends commands, decodes feedback), the plant's drive emulator and
//! the candump tools:
//! - [`frame`]: [`WireFrame`], a classic CAN frame independent of any socket library (conversions to and
//!   from `socketcan::CanFrame` behind the default feature `socketcan`).
//! - [`mit`]: MIT mini-cheetah / CubeMars AK "MIT mode" (bit-packed fixed point, big-endian).
//! - [`odrive`]: ODrive "CAN Simple" (id = node << 5 | cmd, little-endian `f32`).
//! - [`cia402`]: CANopen (NMT, SYNC, SDO, EMCY, heartbeat, PDOs) and the CiA 402 drive profile
//!   (statusword / controlword state machine, ‰-of-rated torque and increment units).
//! - [`cia402_node`]: a socket-free emulated CiA 402 drive (object dictionary, NMT slave, SDO server,
//!   SYNC-driven PDOs, EMCY, heartbeat) for the plant and for tests of the master.
//! - [`units`]: per-joint mapping between the daemon's motor current [A] and what a drive expects
//!   (current, motor torque or joint torque), and motor-side feedback back to the joint side.
//! - [`busload`]: bits per classic frame with worst-case bit stuffing and the bus load of a config.
//!
//! What it is **not**: no sockets, no threads, no timing; errors are `Copy` values without heap data
//! so the RT loop can construct and match them.

pub mod busload;
pub mod cia402;
pub mod cia402_node;
pub mod frame;
pub mod mit;
pub mod odrive;
pub mod units;

pub use frame::WireFrame;
use units::AngleUnit;

/// The drive protocols of a CAN bus (`[[bus]] protocol` in frictiond's config: `"mit"`, `"odrive"`,
/// `"cia402"`).
/// A new protocol is one module beside [`mit`] and [`odrive`] plus one variant here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CanProtocol {
    /// MIT mini-cheetah / CubeMars AK "MIT mode": one 8-byte command, one 6-byte reply per tick.
    Mit,
    /// ODrive CAN Simple: Set_Input_Torque per tick; cyclic Get_Encoder_Estimates, Get_Iq, Heartbeat.
    Odrive,
    /// CiA 402 over CANopen: SYNC per cycle from the master, RPDO controlword + target torque (or
    /// torque offset), TPDOs statusword / position / torque and velocity / joint-side encoder.
    Cia402,
}

impl CanProtocol {
    /// Every protocol, in declaration order.
    pub const ALL: [CanProtocol; 3] = [CanProtocol::Mit, CanProtocol::Odrive, CanProtocol::Cia402];

    /// The config name (`"mit"`, `"odrive"`, `"cia402"`).
    pub fn name(self) -> &'static str {
        match self {
            CanProtocol::Mit => "mit",
            CanProtocol::Odrive => "odrive",
            CanProtocol::Cia402 => "cia402",
        }
    }

    /// Unit of the motor-side position and velocity the drive reports (CiA 402: increments and
    /// velocity units, converted to rad by the per-drive scales before this unit applies).
    pub fn feedback_angle(self) -> AngleUnit {
        match self {
            CanProtocol::Mit | CanProtocol::Cia402 => AngleUnit::Rad,
            CanProtocol::Odrive => AngleUnit::Rev,
        }
    }

    /// Worst-case bits one joint puts on the bus per tick ([`busload`]; CiA 402: the default layout,
    /// the config computes a drive's own from its mapping).
    pub fn bits_per_joint_tick(self) -> u32 {
        match self {
            CanProtocol::Mit => busload::mit_bits_per_joint_tick(),
            CanProtocol::Odrive => busload::odrive_bits_per_joint_tick(),
            CanProtocol::Cia402 => busload::cia402_default_bits_per_node_tick(),
        }
    }

    /// Worst-case bits the bus carries per tick besides the joints' frames (CiA 402: the SYNC).
    pub fn bits_per_bus_tick(self) -> u32 {
        match self {
            CanProtocol::Mit | CanProtocol::Odrive => 0,
            CanProtocol::Cia402 => busload::cia402_sync_bits(),
        }
    }

    /// Frames one joint puts on the bus per tick (commands and cyclic feedback).
    pub fn frames_per_joint_tick(self) -> u32 {
        match self {
            CanProtocol::Mit => 2,
            CanProtocol::Odrive | CanProtocol::Cia402 => 3,
        }
    }
}

/// Error of a CAN codec. `Copy`, no heap data (RT-safe).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CanCodecError {
    /// A frame carried the wrong number of data bytes.
    #[error("CAN frame id {id:#x}: expected {expected} data bytes, got {got}")]
    WrongLength {
        /// Frame id.
        id: u32,
        /// Required length.
        expected: u8,
        /// Actual length.
        got: u8,
    },
    /// A CAN id does not fit 11 bits (standard) or 29 bits (extended).
    #[error("CAN id {id:#x} out of range (extended = {extended})")]
    IdOutOfRange {
        /// The id.
        id: u32,
        /// Whether it was meant as an extended id.
        extended: bool,
    },
    /// More than 8 data bytes for a classic frame.
    #[error("classic CAN frame data length {len} > 8")]
    DataTooLong {
        /// The length asked for.
        len: usize,
    },
    /// An extended-id frame where the protocol uses standard ids (or the reverse).
    #[error("CAN frame id {id:#x}: extended = {extended} not valid for this protocol")]
    WrongIdKind {
        /// Frame id.
        id: u32,
        /// Its extended flag.
        extended: bool,
    },
    /// A remote (RTR) frame where a data frame was expected (or the reverse).
    #[error("CAN frame id {id:#x}: rtr = {rtr} not valid for this message")]
    WrongRtr {
        /// Frame id.
        id: u32,
        /// Its RTR flag.
        rtr: bool,
    },
    /// A value to encode is NaN or infinite.
    #[error("non-finite value for field `{field}`")]
    NonFinite {
        /// Field name.
        field: &'static str,
    },
    /// A range in a configuration is empty, inverted or not finite.
    #[error("bad range for `{field}`: [{min}, {max}] (need finite min < max)")]
    BadRange {
        /// Field name.
        field: &'static str,
        /// Lower end.
        min: f64,
        /// Upper end.
        max: f64,
    },
    /// A node / motor id outside the protocol's range.
    #[error("node id {node} out of range 0..={max}")]
    NodeOutOfRange {
        /// The node id.
        node: u32,
        /// Largest valid node id.
        max: u32,
    },
    /// A command id this codec does not know.
    #[error("unknown command id {cmd:#x} (frame id {id:#x})")]
    UnknownCommand {
        /// Frame id.
        id: u32,
        /// Command id.
        cmd: u8,
    },
    /// A unit conversion parameter (k_t, gear ratio) is zero or not finite.
    #[error("bad unit parameter `{field}` = {value}")]
    BadUnitParameter {
        /// Parameter name.
        field: &'static str,
        /// Its value.
        value: f64,
    },
}
