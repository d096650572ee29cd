//! Classic CAN bus-load arithmetic (worst-case bit stuffing), used to refuse configs over a limit.
//!
//! Frame length in bits (Davis et al., "Controller Area Network (CAN) schedulability analysis",
//! 2007): `C = g + 8n + 13 + ⌊(g + 8n − 1)/4⌋` with `g = 34` (11-bit id) or `54` (29-bit id), `n`
//! data bytes. `g + 8n` bits (SOF … CRC) are subject to stuffing; 13 = CRC delimiter, ACK slot and
//! delimiter, EOF (7), interframe space (3). 8 data bytes, standard id: 111 bits unstuffed, 135 worst case.
//!
//! CANopen / CiA 402 adds one SYNC per bus and cycle ([`cia402_sync_bits`], 55 bits worst case) to
//! the per-node PDOs ([`cia402_bits_per_node_tick`]).
//!
//! Not here: CAN FD, error frames, arbitration delays.

/// Worst-case bits on the wire of one classic frame with `data_len` (0..=8, clamped) bytes.
pub const fn frame_bits_worst(data_len: u8, extended: bool) -> u32 {
    let n = if data_len > 8 { 8 } else { data_len } as u32;
    let g = if extended { 54 } else { 34 };
    g + 8 * n + 13 + (g + 8 * n - 1) / 4
}

/// Bits without stuffing (the best case).
pub const fn frame_bits_unstuffed(data_len: u8, extended: bool) -> u32 {
    let n = if data_len > 8 { 8 } else { data_len } as u32;
    (if extended { 54 } else { 34 }) + 8 * n + 13
}

/// Worst-case bits per joint per tick of MIT mode: one 8-byte command + one 6-byte reply.
pub const fn mit_bits_per_joint_tick() -> u32 {
    frame_bits_worst(8, false) + frame_bits_worst(6, false)
}

/// Worst-case bits per joint per tick of ODrive torque control: Set_Input_Torque (4 bytes) +
/// Get_Encoder_Estimates (8) + Get_Iq (8), all cyclic at the loop rate.
pub const fn odrive_bits_per_joint_tick() -> u32 {
    frame_bits_worst(4, false) + 2 * frame_bits_worst(8, false)
}

/// Worst-case bits of a CANopen SYNC without counter (0 data bytes), once per bus and cycle.
pub const fn cia402_sync_bits() -> u32 {
    frame_bits_worst(0, false)
}

/// Worst-case bits one CiA 402 node puts on the bus per SYNC cycle: its RPDO(s) of `rpdo_bytes`
/// data bytes and its TPDOs of `tpdo_bytes`, each TPDO `(bytes, every)` sent on every `every`-th
/// SYNC (transmission type 1..=240; 0 counts as 1), the fraction rounded up to a whole bit.
pub fn cia402_bits_per_node_tick(rpdo_bytes: &[u8], tpdo_bytes: &[(u8, u8)]) -> u32 {
    let r: u32 = rpdo_bytes.iter().map(|&n| frame_bits_worst(n, false)).sum();
    let t: u32 = tpdo_bytes
        .iter()
        .map(|&(n, every)| frame_bits_worst(n, false).div_ceil(u32::from(every.max(1))))
        .sum();
    r + t
}

/// Worst-case bits per node and cycle of the project's default CiA 402 layout: RPDO1 4 bytes
/// (controlword + target torque or torque offset), TPDO1 8 bytes (statusword, position, torque),
/// TPDO2 8 bytes (velocity, joint-side encoder): 95 + 135 + 135 = 365.
pub const fn cia402_default_bits_per_node_tick() -> u32 {
    frame_bits_worst(4, false) + 2 * frame_bits_worst(8, false)
}

/// Bus load (fraction of the bitrate, 1.0 = saturated) of `n_joints` joints each putting
/// `bits_per_joint_tick` bits on the bus per tick at `rate_hz`, on a `bitrate_bps` bus.
pub fn load_fraction(
    n_joints: u32,
    bits_per_joint_tick: u32,
    rate_hz: f64,
    bitrate_bps: f64,
) -> f64 {
    n_joints as f64 * bits_per_joint_tick as f64 * rate_hz / bitrate_bps
}

/// Bus load of `bits_per_tick` bits per tick in all (per-bus frames such as SYNC included).
pub fn load_fraction_bits(bits_per_tick: u64, rate_hz: f64, bitrate_bps: f64) -> f64 {
    bits_per_tick as f64 * rate_hz / bitrate_bps
}

/// Largest number of joints whose load stays ≤ `limit` (e.g. 0.75).
pub fn max_joints(bits_per_joint_tick: u32, rate_hz: f64, bitrate_bps: f64, limit: f64) -> u32 {
    let per_joint = load_fraction(1, bits_per_joint_tick, rate_hz, bitrate_bps);
    if per_joint.is_nan() || limit.is_nan() || per_joint <= 0.0 || limit <= 0.0 {
        return 0;
    }
    // Small epsilon so an exact fit (e.g. 0.75 / 0.25) is not lost to rounding.
    ((limit / per_joint) + 1e-9).floor().min(u32::MAX as f64) as u32
}

/// Error of [`check_load`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "CAN bus load {load:.3} of {n_joints} joints at {rate_hz} Hz on {bitrate_bps} bit/s exceeds the limit {limit:.3}"
)]
pub struct BusLoadError {
    /// Computed load fraction.
    pub load: f64,
    /// Limit fraction.
    pub limit: f64,
    /// Joints on the bus.
    pub n_joints: u32,
    /// Loop rate [Hz].
    pub rate_hz: f64,
    /// Bitrate [bit/s].
    pub bitrate_bps: f64,
}

/// Returns the load, or an error naming it when it exceeds `limit` (or is not finite).
pub fn check_load(
    n_joints: u32,
    bits_per_joint_tick: u32,
    rate_hz: f64,
    bitrate_bps: f64,
    limit: f64,
) -> Result<f64, BusLoadError> {
    let load = load_fraction(n_joints, bits_per_joint_tick, rate_hz, bitrate_bps);
    if load.is_finite() && load <= limit {
        Ok(load)
    } else {
        Err(BusLoadError {
            load,
            limit,
            n_joints,
            rate_hz,
            bitrate_bps,
        })
    }
}
