//! CDR decoding (XCDR1) of the ROS 2 messages the MCAP importer reads: `sensor_msgs/msg/JointState`,
//! `sensor_msgs/msg/Imu` (the orientation) and `geometry_msgs/msg/WrenchStamped`. Every read is
//! bounds-checked; an error is a message naming what could not be read.
//!
//! Decoded by hand: the messages are a few fields of primitives, strings and sequences, and the
//! serde-based `cdr` crate has had no release since 2021 (see [`crate::mcap_log`]).

/// A decoded `sensor_msgs/msg/JointState`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointState {
    /// `header.stamp` [s since the epoch].
    pub stamp_s: f64,
    /// `header.frame_id`.
    pub frame_id: String,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions [rad].
    pub position: Vec<f64>,
    /// Velocities [rad/s].
    pub velocity: Vec<f64>,
    /// Efforts [Nm].
    pub effort: Vec<f64>,
}

/// CDR cursor (XCDR1, alignment counted from the first byte after the 4-byte encapsulation header).
pub(crate) struct Cdr<'a> {
    buf: &'a [u8],
    pos: usize,
    le: bool,
}

impl<'a> Cdr<'a> {
    /// A cursor after the encapsulation header (little- or big-endian XCDR1).
    pub(crate) fn new(payload: &'a [u8]) -> Result<Self, String> {
        if payload.len() < 4 {
            return Err("message shorter than the CDR header".into());
        }
        let le = match payload[1] {
            0x01 => true,
            0x00 => false,
            k => return Err(format!("unsupported CDR encapsulation kind {k:#04x}")),
        };
        Ok(Self {
            buf: &payload[4..],
            pos: 0,
            le,
        })
    }
    fn align(&mut self, n: usize) -> Result<(), String> {
        let pad = (n - self.pos % n) % n;
        self.take(pad).map(|_| ())
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| {
                format!(
                    "truncated message ({} bytes, needs {})",
                    self.buf.len() + 4,
                    self.pos + n + 4
                )
            })?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        self.align(4)?;
        let b: [u8; 4] = self.take(4)?.try_into().map_err(|_| "u32".to_string())?;
        Ok(if self.le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }
    pub(crate) fn i32(&mut self) -> Result<i32, String> {
        self.u32().map(|v| v as i32)
    }
    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        self.align(8)?;
        let b: [u8; 8] = self.take(8)?.try_into().map_err(|_| "f64".to_string())?;
        Ok(if self.le {
            f64::from_le_bytes(b)
        } else {
            f64::from_be_bytes(b)
        })
    }
    fn count(&mut self, elem_size: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        // Each element needs at least `elem_size` bytes: a corrupt count cannot allocate.
        if n.saturating_mul(elem_size) > self.buf.len() - self.pos.min(self.buf.len()) {
            return Err(format!("sequence length {n} exceeds the message"));
        }
        Ok(n)
    }
    pub(crate) fn string(&mut self) -> Result<String, String> {
        let n = self.count(1)?;
        let b = self.take(n)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }
    fn f64_seq(&mut self) -> Result<Vec<f64>, String> {
        let n = self.count(8)?;
        (0..n).map(|_| self.f64()).collect()
    }
}

/// Decodes a CDR-encoded `sensor_msgs/msg/JointState` (little- or big-endian XCDR1).
pub fn decode_joint_state(payload: &[u8]) -> Result<JointState, String> {
    let mut c = Cdr::new(payload)?;
    let sec = c.i32()?;
    let nsec = c.u32()?;
    let frame_id = c.string()?;
    let n = c.count(4)?;
    let name = (0..n).map(|_| c.string()).collect::<Result<Vec<_>, _>>()?;
    let position = c.f64_seq()?;
    let velocity = c.f64_seq()?;
    let effort = c.f64_seq()?;
    Ok(JointState {
        stamp_s: f64::from(sec) + f64::from(nsec) * 1e-9,
        frame_id,
        name,
        position,
        velocity,
        effort,
    })
}

/// The orientation of a CDR-encoded `sensor_msgs/msg/Imu`: the quaternion `[x, y, z, w]`, or
/// `None` when the message says it has none (`orientation_covariance[0] == -1`, per the message's
/// definition). Only the header, the orientation and its covariance's first element are read.
pub fn decode_imu_orientation(payload: &[u8]) -> Result<Option<[f64; 4]>, String> {
    decode_imu(payload).map(|(_, q)| q)
}

/// [`decode_imu_orientation`] with the message's `header.frame_id` (the frame whose orientation
/// in the world it is, per the message's definition).
pub fn decode_imu(payload: &[u8]) -> Result<(String, Option<[f64; 4]>), String> {
    let mut c = Cdr::new(payload)?;
    c.i32()?; // header.stamp.sec
    c.u32()?; // header.stamp.nanosec
    let frame = c.string()?;
    let q = [c.f64()?, c.f64()?, c.f64()?, c.f64()?];
    let cov0 = c.f64()?;
    Ok((frame, (cov0 != -1.0).then_some(q)))
}

/// Decodes a CDR-encoded `geometry_msgs/msg/WrenchStamped`: `header.frame_id` and `[fx, fy, fz]`
/// [N] then `[mx, my, mz]` [N·m] (the message's force and torque).
pub fn decode_wrench(payload: &[u8]) -> Result<(String, [f64; 6]), String> {
    let mut c = Cdr::new(payload)?;
    c.i32()?; // header.stamp.sec
    c.u32()?; // header.stamp.nanosec
    let frame_id = c.string()?;
    let mut w = [0.0; 6];
    for x in &mut w {
        *x = c.f64()?;
    }
    Ok((frame_id, w))
}
