//! MIT mini-cheetah / CubeMars AK "MIT mode" codec (`bgkatz/motorcontrol`, `Core/Src/can.c`).
//!
//! Fixed point `x_int = round((x − x_min)·(2^bits − 1)/(x_max − x_min))` after clamping `x` to the
//! range (clamping is reported as [`MitSaturation`]); decoding is the exact inverse. The firmware
//! truncates instead of rounding; decoding is identical, rounding halves our quantisation error.
//!
//! **Command** (standard id = motor id, 8 bytes, big-endian bit packing):
//!
//! | byte | 0 | 1 | 2 | 3 | 4 | 5 | 6 | 7 |
//! |---|---|---|---|---|---|---|---|---|
//! | bits | p\[15:8\] | p\[7:0\] | v\[11:4\] | v\[3:0\] kp\[11:8\] | kp\[7:0\] | kd\[11:4\] | kd\[3:0\] t\[11:8\] | t\[7:0\] |
//!
//! **Reply** (id = host id, ≥ 6 bytes): `motor id`, p\[15:8\], p\[7:0\], v\[11:4\], v\[3:0\] i\[11:8\],
//! i\[7:0\]. Special frames `FF×7 FC|FD|FE`: enter motor mode, exit motor mode, zero position.
//! A pure current/torque command is kp = kd = 0, t_ff = τ ([`MitCommand::torque`]).
//!
//! Not here: timing, the drive's command timeout, CubeMars "servo mode" (a different protocol).

use super::{CanCodecError, WireFrame};

/// Per-joint fixed-point ranges of the MIT protocol; they differ per motor model, so they are config.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MitRanges {
    /// Position range lower end [motor rad].
    pub p_min_rad: f64,
    /// Position range upper end [motor rad].
    pub p_max_rad: f64,
    /// Velocity range lower end [motor rad/s].
    pub v_min_rad_s: f64,
    /// Velocity range upper end [motor rad/s].
    pub v_max_rad_s: f64,
    /// Position gain lower end [Nm/rad] (usually 0).
    pub kp_min_nm_rad: f64,
    /// Position gain upper end [Nm/rad].
    pub kp_max_nm_rad: f64,
    /// Damping gain lower end [Nm·s/rad] (usually 0).
    pub kd_min_nm_s_rad: f64,
    /// Damping gain upper end [Nm·s/rad].
    pub kd_max_nm_s_rad: f64,
    /// Feed-forward torque lower end [Nm] (motor side as the drive sees it).
    pub t_min_nm: f64,
    /// Feed-forward torque upper end [Nm].
    pub t_max_nm: f64,
    /// Lower end of the reply's third field. bgkatz firmware: phase current [A] (±I_MAX);
    /// CubeMars AK firmware sends torque [Nm] there: set it to the torque range then.
    pub i_min_a: f64,
    /// Upper end of the reply's third field.
    pub i_max_a: f64,
}

impl MitRanges {
    /// The bgkatz mini-cheetah defaults: P ±12.5 rad, V ±65 rad/s, KP 0–500, KD 0–5, T ±18 Nm, I ±40 A.
    pub const MINI_CHEETAH: MitRanges = MitRanges {
        p_min_rad: -12.5,
        p_max_rad: 12.5,
        v_min_rad_s: -65.0,
        v_max_rad_s: 65.0,
        kp_min_nm_rad: 0.0,
        kp_max_nm_rad: 500.0,
        kd_min_nm_s_rad: 0.0,
        kd_max_nm_s_rad: 5.0,
        t_min_nm: -18.0,
        t_max_nm: 18.0,
        i_min_a: -40.0,
        i_max_a: 40.0,
    };

    /// Checks every range is finite with min < max.
    pub fn validate(&self) -> Result<(), CanCodecError> {
        let pairs = [
            ("p_rad", self.p_min_rad, self.p_max_rad),
            ("v_rad_s", self.v_min_rad_s, self.v_max_rad_s),
            ("kp_nm_rad", self.kp_min_nm_rad, self.kp_max_nm_rad),
            ("kd_nm_s_rad", self.kd_min_nm_s_rad, self.kd_max_nm_s_rad),
            ("t_nm", self.t_min_nm, self.t_max_nm),
            ("i_a", self.i_min_a, self.i_max_a),
        ];
        for (field, min, max) in pairs {
            // `!(min < max)` also catches NaN.
            if !min.is_finite()
                || !max.is_finite()
                || min.partial_cmp(&max) != Some(core::cmp::Ordering::Less)
            {
                return Err(CanCodecError::BadRange { field, min, max });
            }
        }
        Ok(())
    }

    /// Quantisation step of each field: (p, v, kp, kd, t, i).
    pub fn steps(&self) -> [f64; 6] {
        [
            step(self.p_min_rad, self.p_max_rad, 16),
            step(self.v_min_rad_s, self.v_max_rad_s, 12),
            step(self.kp_min_nm_rad, self.kp_max_nm_rad, 12),
            step(self.kd_min_nm_s_rad, self.kd_max_nm_s_rad, 12),
            step(self.t_min_nm, self.t_max_nm, 12),
            step(self.i_min_a, self.i_max_a, 12),
        ]
    }
}

fn step(min: f64, max: f64, bits: u32) -> f64 {
    (max - min) / ((1u32 << bits) - 1) as f64
}

/// Which fields were clamped to their range while encoding (bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MitSaturation(pub u8);

impl MitSaturation {
    /// Position clamped.
    pub const P: u8 = 1 << 0;
    /// Velocity clamped.
    pub const V: u8 = 1 << 1;
    /// kp clamped.
    pub const KP: u8 = 1 << 2;
    /// kd clamped.
    pub const KD: u8 = 1 << 3;
    /// Feed-forward torque clamped (also set when the frame had to be nudged off a special frame).
    pub const T: u8 = 1 << 4;
    /// Reply current clamped.
    pub const I: u8 = 1 << 5;

    /// Whether any field was clamped.
    pub fn any(self) -> bool {
        self.0 != 0
    }

    /// Whether the field bit `flag` was clamped.
    pub fn has(self, flag: u8) -> bool {
        self.0 & flag != 0
    }
}

/// Float → unsigned fixed point with clamping; returns (value, clamped). `x` must be finite.
#[inline]
pub fn float_to_uint(x: f64, min: f64, max: f64, bits: u32) -> (u16, bool) {
    let top = ((1u32 << bits) - 1) as f64;
    let clamped = x.clamp(min, max);
    let u = ((clamped - min) * top / (max - min))
        .round()
        .clamp(0.0, top);
    (u as u16, x < min || x > max)
}

/// Unsigned fixed point → float (exact inverse of [`float_to_uint`] up to the quantisation step).
#[inline]
pub fn uint_to_float(u: u16, min: f64, max: f64, bits: u32) -> f64 {
    let top = ((1u32 << bits) - 1) as f64;
    u as f64 * (max - min) / top + min
}

/// An MIT-mode command: τ = kp·(p_des − p) + kd·(v_des − v) + t_ff, computed by the drive.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MitCommand {
    /// Desired position [motor rad].
    pub p_des_rad: f64,
    /// Desired velocity [motor rad/s].
    pub v_des_rad_s: f64,
    /// Position gain [Nm/rad].
    pub kp_nm_rad: f64,
    /// Damping gain [Nm·s/rad].
    pub kd_nm_s_rad: f64,
    /// Feed-forward torque [Nm].
    pub t_ff_nm: f64,
}

impl MitCommand {
    /// A pure torque command: kp = kd = 0, p = v = 0, t_ff = `t_ff_nm`.
    pub fn torque(t_ff_nm: f64) -> Self {
        Self {
            t_ff_nm,
            ..Self::default()
        }
    }
}

/// The special (mode) frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MitSpecial {
    /// `FF…FC`: enter motor mode.
    EnterMotorMode,
    /// `FF…FD`: exit motor mode.
    ExitMotorMode,
    /// `FF…FE`: set the current position as zero.
    ZeroPosition,
}

impl MitSpecial {
    /// The last byte of the special frame.
    pub fn last_byte(self) -> u8 {
        match self {
            MitSpecial::EnterMotorMode => 0xFC,
            MitSpecial::ExitMotorMode => 0xFD,
            MitSpecial::ZeroPosition => 0xFE,
        }
    }
}

/// What a drive receives on its id: a command or a special frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MitRx {
    /// A motion/torque command.
    Command(MitCommand),
    /// A mode frame.
    Special(MitSpecial),
}

/// A drive's reply (feedback).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MitReply {
    /// Motor id (byte 0).
    pub motor_id: u8,
    /// Position [motor rad].
    pub p_rad: f64,
    /// Velocity [motor rad/s].
    pub v_rad_s: f64,
    /// Third field: current [A] (bgkatz) or torque [Nm] (CubeMars), see [`MitRanges::i_min_a`].
    pub i_a: f64,
}

fn check_std_id(id: u32) -> Result<(), CanCodecError> {
    if id > super::frame::SFF_MAX {
        Err(CanCodecError::IdOutOfRange {
            id,
            extended: false,
        })
    } else {
        Ok(())
    }
}

fn finite(x: f64, field: &'static str) -> Result<f64, CanCodecError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(CanCodecError::NonFinite { field })
    }
}

/// Packs the 8 command bytes (no id checks). Ranges must be valid.
pub fn pack_command(
    cmd: &MitCommand,
    r: &MitRanges,
) -> Result<([u8; 8], MitSaturation), CanCodecError> {
    let (p, sp) = float_to_uint(
        finite(cmd.p_des_rad, "p_des_rad")?,
        r.p_min_rad,
        r.p_max_rad,
        16,
    );
    let (v, sv) = float_to_uint(
        finite(cmd.v_des_rad_s, "v_des_rad_s")?,
        r.v_min_rad_s,
        r.v_max_rad_s,
        12,
    );
    let (kp, skp) = float_to_uint(
        finite(cmd.kp_nm_rad, "kp_nm_rad")?,
        r.kp_min_nm_rad,
        r.kp_max_nm_rad,
        12,
    );
    let (kd, skd) = float_to_uint(
        finite(cmd.kd_nm_s_rad, "kd_nm_s_rad")?,
        r.kd_min_nm_s_rad,
        r.kd_max_nm_s_rad,
        12,
    );
    let (t, st) = float_to_uint(finite(cmd.t_ff_nm, "t_ff_nm")?, r.t_min_nm, r.t_max_nm, 12);
    let mut sat = 0u8;
    for (flag, s) in [
        (MitSaturation::P, sp),
        (MitSaturation::V, sv),
        (MitSaturation::KP, skp),
        (MitSaturation::KD, skd),
        (MitSaturation::T, st),
    ] {
        if s {
            sat |= flag;
        }
    }
    let mut b = [
        (p >> 8) as u8,
        (p & 0xFF) as u8,
        (v >> 4) as u8,
        (((v & 0xF) << 4) | (kp >> 8)) as u8,
        (kp & 0xFF) as u8,
        (kd >> 4) as u8,
        (((kd & 0xF) << 4) | (t >> 8)) as u8,
        (t & 0xFF) as u8,
    ];
    // p, v, kp, kd all at their maximum and t in 0xFFC..=0xFFE would read as a special frame:
    // nudge t one step below 0xFFC so a command is never mistaken for a mode change.
    if b[..7].iter().all(|&x| x == 0xFF) && b[7] >= 0xFC {
        b[7] = 0xFB;
        sat |= MitSaturation::T;
    }
    Ok((b, MitSaturation(sat)))
}

/// Encodes a command for the drive with standard id `motor_id`.
pub fn encode_command(
    motor_id: u32,
    cmd: &MitCommand,
    r: &MitRanges,
) -> Result<(WireFrame, MitSaturation), CanCodecError> {
    check_std_id(motor_id)?;
    r.validate()?;
    let (b, sat) = pack_command(cmd, r)?;
    Ok((WireFrame::standard(motor_id, &b)?, sat))
}

/// Encodes a special (mode) frame for the drive with standard id `motor_id`.
pub fn encode_special(motor_id: u32, s: MitSpecial) -> Result<WireFrame, CanCodecError> {
    check_std_id(motor_id)?;
    let mut b = [0xFFu8; 8];
    b[7] = s.last_byte();
    WireFrame::standard(motor_id, &b)
}

fn check_data_frame(f: &WireFrame) -> Result<(), CanCodecError> {
    if f.extended {
        return Err(CanCodecError::WrongIdKind {
            id: f.id,
            extended: true,
        });
    }
    if f.rtr {
        return Err(CanCodecError::WrongRtr {
            id: f.id,
            rtr: true,
        });
    }
    Ok(())
}

/// Decodes what a drive receives (command or special frame). Needs exactly 8 data bytes.
pub fn decode_command(f: &WireFrame, r: &MitRanges) -> Result<MitRx, CanCodecError> {
    check_data_frame(f)?;
    r.validate()?;
    if f.len != 8 {
        return Err(CanCodecError::WrongLength {
            id: f.id,
            expected: 8,
            got: f.len,
        });
    }
    let b = &f.data;
    if b[..7].iter().all(|&x| x == 0xFF) {
        match b[7] {
            0xFC => return Ok(MitRx::Special(MitSpecial::EnterMotorMode)),
            0xFD => return Ok(MitRx::Special(MitSpecial::ExitMotorMode)),
            0xFE => return Ok(MitRx::Special(MitSpecial::ZeroPosition)),
            _ => {}
        }
    }
    let p = (b[0] as u16) << 8 | b[1] as u16;
    let v = (b[2] as u16) << 4 | (b[3] >> 4) as u16;
    let kp = ((b[3] & 0xF) as u16) << 8 | b[4] as u16;
    let kd = (b[5] as u16) << 4 | (b[6] >> 4) as u16;
    let t = ((b[6] & 0xF) as u16) << 8 | b[7] as u16;
    Ok(MitRx::Command(MitCommand {
        p_des_rad: uint_to_float(p, r.p_min_rad, r.p_max_rad, 16),
        v_des_rad_s: uint_to_float(v, r.v_min_rad_s, r.v_max_rad_s, 12),
        kp_nm_rad: uint_to_float(kp, r.kp_min_nm_rad, r.kp_max_nm_rad, 12),
        kd_nm_s_rad: uint_to_float(kd, r.kd_min_nm_s_rad, r.kd_max_nm_s_rad, 12),
        t_ff_nm: uint_to_float(t, r.t_min_nm, r.t_max_nm, 12),
    }))
}

/// Encodes a drive's reply sent on standard id `host_id` (6 bytes).
pub fn encode_reply(
    host_id: u32,
    reply: &MitReply,
    r: &MitRanges,
) -> Result<(WireFrame, MitSaturation), CanCodecError> {
    check_std_id(host_id)?;
    r.validate()?;
    let (p, sp) = float_to_uint(finite(reply.p_rad, "p_rad")?, r.p_min_rad, r.p_max_rad, 16);
    let (v, sv) = float_to_uint(
        finite(reply.v_rad_s, "v_rad_s")?,
        r.v_min_rad_s,
        r.v_max_rad_s,
        12,
    );
    let (i, si) = float_to_uint(finite(reply.i_a, "i_a")?, r.i_min_a, r.i_max_a, 12);
    let mut sat = 0;
    for (flag, s) in [
        (MitSaturation::P, sp),
        (MitSaturation::V, sv),
        (MitSaturation::I, si),
    ] {
        if s {
            sat |= flag;
        }
    }
    let b = [
        reply.motor_id,
        (p >> 8) as u8,
        (p & 0xFF) as u8,
        (v >> 4) as u8,
        (((v & 0xF) << 4) | (i >> 8)) as u8,
        (i & 0xFF) as u8,
    ];
    Ok((WireFrame::standard(host_id, &b)?, MitSaturation(sat)))
}

/// Decodes a drive's reply. Needs at least 6 data bytes (extra bytes, e.g. CubeMars temperature and
/// error code, are ignored).
pub fn decode_reply(f: &WireFrame, r: &MitRanges) -> Result<MitReply, CanCodecError> {
    check_data_frame(f)?;
    r.validate()?;
    if f.len < 6 {
        return Err(CanCodecError::WrongLength {
            id: f.id,
            expected: 6,
            got: f.len,
        });
    }
    let b = &f.data;
    let p = (b[1] as u16) << 8 | b[2] as u16;
    let v = (b[3] as u16) << 4 | (b[4] >> 4) as u16;
    let i = ((b[4] & 0xF) as u16) << 8 | b[5] as u16;
    Ok(MitReply {
        motor_id: b[0],
        p_rad: uint_to_float(p, r.p_min_rad, r.p_max_rad, 16),
        v_rad_s: uint_to_float(v, r.v_min_rad_s, r.v_max_rad_s, 12),
        i_a: uint_to_float(i, r.i_min_a, r.i_max_a, 12),
    })
}
