//! [`WireFrame`]: a classic CAN 2.0 frame as plain data (id, extended flag, RTR flag, length, 8 bytes).
//!
//! It keeps the codecs independent of socket libraries. It is **not** a CAN FD frame and carries no
//! timestamp. With the `socketcan` feature: `TryFrom<WireFrame> for socketcan::CanFrame` and
//! `TryFrom<&socketcan::CanFrame> for WireFrame` (error frames are refused).

use super::CanCodecError;

/// Largest 11-bit (standard) id.
pub const SFF_MAX: u32 = 0x7FF;
/// Largest 29-bit (extended) id.
pub const EFF_MAX: u32 = 0x1FFF_FFFF;

/// A classic CAN frame. Invariants (upheld by the constructors, checked by [`WireFrame::validate`]):
/// `id ≤ 0x7FF` unless `extended`, `id ≤ 0x1FFFFFFF`, `len ≤ 8`, bytes beyond `len` are 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct WireFrame {
    /// Arbitration id (11 or 29 bit).
    pub id: u32,
    /// 29-bit extended id.
    pub extended: bool,
    /// Remote transmission request (no data on the wire; `len` is the requested DLC).
    pub rtr: bool,
    /// Data length code 0..=8.
    pub len: u8,
    /// Payload; bytes `len..8` are zero.
    pub data: [u8; 8],
}

impl WireFrame {
    /// A data frame with a standard (11-bit) id.
    pub fn standard(id: u32, data: &[u8]) -> Result<Self, CanCodecError> {
        Self::data_frame(id, false, data)
    }

    /// A data frame with an extended (29-bit) id.
    pub fn extended(id: u32, data: &[u8]) -> Result<Self, CanCodecError> {
        Self::data_frame(id, true, data)
    }

    /// A data frame.
    pub fn data_frame(id: u32, extended: bool, data: &[u8]) -> Result<Self, CanCodecError> {
        check_id(id, extended)?;
        if data.len() > 8 {
            return Err(CanCodecError::DataTooLong { len: data.len() });
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Ok(Self {
            id,
            extended,
            rtr: false,
            len: data.len() as u8,
            data: d,
        })
    }

    /// A remote (RTR) frame requesting `dlc` bytes.
    pub fn remote(id: u32, extended: bool, dlc: u8) -> Result<Self, CanCodecError> {
        check_id(id, extended)?;
        if dlc > 8 {
            return Err(CanCodecError::DataTooLong { len: dlc as usize });
        }
        Ok(Self {
            id,
            extended,
            rtr: true,
            len: dlc,
            data: [0; 8],
        })
    }

    /// The payload (`len` bytes; empty for RTR frames).
    pub fn payload(&self) -> &[u8] {
        if self.rtr {
            &[]
        } else {
            &self.data[..(self.len.min(8) as usize)]
        }
    }

    /// Checks the invariants (useful for frames built field by field).
    pub fn validate(&self) -> Result<(), CanCodecError> {
        check_id(self.id, self.extended)?;
        if self.len > 8 {
            return Err(CanCodecError::DataTooLong {
                len: self.len as usize,
            });
        }
        Ok(())
    }
}

fn check_id(id: u32, extended: bool) -> Result<(), CanCodecError> {
    let max = if extended { EFF_MAX } else { SFF_MAX };
    if id > max {
        Err(CanCodecError::IdOutOfRange { id, extended })
    } else {
        Ok(())
    }
}

#[cfg(feature = "socketcan")]
mod sc {
    use super::*;
    use socketcan::{CanFrame, EmbeddedFrame, ExtendedId, Frame, Id, StandardId};

    impl TryFrom<WireFrame> for CanFrame {
        type Error = CanCodecError;
        fn try_from(f: WireFrame) -> Result<Self, CanCodecError> {
            f.validate()?;
            let id: Id = if f.extended {
                ExtendedId::new(f.id)
                    .ok_or(CanCodecError::IdOutOfRange {
                        id: f.id,
                        extended: true,
                    })?
                    .into()
            } else {
                StandardId::new(f.id as u16)
                    .ok_or(CanCodecError::IdOutOfRange {
                        id: f.id,
                        extended: false,
                    })?
                    .into()
            };
            let frame = if f.rtr {
                CanFrame::new_remote(id, f.len as usize)
            } else {
                CanFrame::new(id, f.payload())
            };
            frame.ok_or(CanCodecError::DataTooLong {
                len: f.len as usize,
            })
        }
    }

    impl TryFrom<&CanFrame> for WireFrame {
        type Error = CanCodecError;
        /// Refuses error frames (reported as [`CanCodecError::WrongIdKind`] on the raw id word).
        fn try_from(f: &CanFrame) -> Result<Self, CanCodecError> {
            match f {
                CanFrame::Error(e) => Err(CanCodecError::WrongIdKind {
                    id: e.id_word(),
                    extended: e.is_extended(),
                }),
                CanFrame::Remote(r) => {
                    WireFrame::remote(r.raw_id(), r.is_extended(), r.dlc() as u8)
                }
                CanFrame::Data(d) => WireFrame::data_frame(d.raw_id(), d.is_extended(), d.data()),
            }
        }
    }
}
