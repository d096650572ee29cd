//! ODrive "CAN Simple" codec (`odriverobotics/ODrive`: `docs/can-protocol.rst`, `tools/odrive-cansimple.dbc`).
//!
//! 11-bit id = `node_id << 5 | cmd_id` (node 0–63, cmd 0–31), payloads little-endian. Both directions
//! are covered: the daemon encodes commands and decodes feedback, an emulated drive does the reverse.
//! Requests for cyclic messages are RTR frames ([`OdriveMsg::Request`]). Encoders emit only the bytes
//! a message uses (e.g. 4 for Set_Input_Torque); decoders accept longer frames and ignore the rest.
//!
//! Not here: CANopen, the ODrive Pro's extended messages, timing.

use super::{CanCodecError, WireFrame};

/// Largest node id (6 bits).
pub const NODE_MAX: u8 = 63;

/// Command ids (low 5 bits of the CAN id).
pub mod cmd {
    /// Heartbeat (axis → host).
    pub const HEARTBEAT: u8 = 0x01;
    /// Emergency stop (host → axis).
    pub const ESTOP: u8 = 0x02;
    /// Set_Axis_State (host → axis).
    pub const SET_AXIS_STATE: u8 = 0x07;
    /// Get_Encoder_Estimates (axis → host).
    pub const GET_ENCODER_ESTIMATES: u8 = 0x09;
    /// Set_Controller_Mode (host → axis).
    pub const SET_CONTROLLER_MODE: u8 = 0x0B;
    /// Set_Input_Torque (host → axis).
    pub const SET_INPUT_TORQUE: u8 = 0x0E;
    /// Get_Iq (axis → host).
    pub const GET_IQ: u8 = 0x14;
    /// Clear_Errors (host → axis).
    pub const CLEAR_ERRORS: u8 = 0x18;
}

/// Axis state CLOSED_LOOP_CONTROL (for Set_Axis_State).
pub const AXIS_STATE_CLOSED_LOOP_CONTROL: u32 = 8;
/// Axis state IDLE.
pub const AXIS_STATE_IDLE: u32 = 1;
/// Control mode TORQUE_CONTROL (for Set_Controller_Mode).
pub const CONTROL_MODE_TORQUE: i32 = 1;
/// Input mode PASSTHROUGH.
pub const INPUT_MODE_PASSTHROUGH: i32 = 1;

/// One CAN Simple message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OdriveMsg {
    /// Estop (no payload).
    Estop,
    /// Set_Axis_State: u32 requested state.
    SetAxisState {
        /// Requested axis state (8 = closed loop).
        requested_state: u32,
    },
    /// Set_Controller_Mode: i32 control mode, i32 input mode.
    SetControllerMode {
        /// Control mode (1 = torque).
        control_mode: i32,
        /// Input mode (1 = passthrough).
        input_mode: i32,
    },
    /// Set_Input_Torque: f32 [Nm] (motor side as the drive sees it).
    SetInputTorque {
        /// Torque setpoint [Nm].
        torque_nm: f32,
    },
    /// Clear_Errors (no payload).
    ClearErrors,
    /// Heartbeat: u32 axis error, u8 axis state, three status bytes (firmware dependent).
    Heartbeat {
        /// Axis error bit field.
        axis_error: u32,
        /// Current axis state.
        axis_state: u8,
        /// Bytes 5..8: motor/encoder/controller flags (0.5.x) or procedure result/trajectory done (0.6.x).
        status: [u8; 3],
    },
    /// Get_Encoder_Estimates: f32 position [motor rev], f32 velocity [motor rev/s].
    EncoderEstimates {
        /// Position [motor rev].
        pos_rev: f32,
        /// Velocity [motor rev/s].
        vel_rev_s: f32,
    },
    /// Get_Iq: f32 setpoint [A], f32 measured [A].
    Iq {
        /// Iq setpoint [A].
        iq_setpoint_a: f32,
        /// Iq measured [A].
        iq_measured_a: f32,
    },
    /// An RTR request for message `cmd` (e.g. Get_Encoder_Estimates when not cyclic).
    Request {
        /// Requested command id.
        cmd: u8,
    },
}

impl OdriveMsg {
    /// The command id of this message.
    pub fn cmd_id(&self) -> u8 {
        match self {
            OdriveMsg::Estop => cmd::ESTOP,
            OdriveMsg::SetAxisState { .. } => cmd::SET_AXIS_STATE,
            OdriveMsg::SetControllerMode { .. } => cmd::SET_CONTROLLER_MODE,
            OdriveMsg::SetInputTorque { .. } => cmd::SET_INPUT_TORQUE,
            OdriveMsg::ClearErrors => cmd::CLEAR_ERRORS,
            OdriveMsg::Heartbeat { .. } => cmd::HEARTBEAT,
            OdriveMsg::EncoderEstimates { .. } => cmd::GET_ENCODER_ESTIMATES,
            OdriveMsg::Iq { .. } => cmd::GET_IQ,
            OdriveMsg::Request { cmd } => *cmd,
        }
    }
}

/// `node << 5 | cmd`.
pub fn can_id(node: u8, cmd: u8) -> Result<u32, CanCodecError> {
    if node > NODE_MAX {
        return Err(CanCodecError::NodeOutOfRange {
            node: node as u32,
            max: NODE_MAX as u32,
        });
    }
    if cmd > 0x1F {
        return Err(CanCodecError::UnknownCommand {
            id: (node as u32) << 5,
            cmd,
        });
    }
    Ok((node as u32) << 5 | cmd as u32)
}

/// (node, cmd) of an 11-bit id.
pub fn split_id(id: u32) -> (u8, u8) {
    (((id >> 5) & 0x3F) as u8, (id & 0x1F) as u8)
}

fn f32_ok(x: f32, field: &'static str) -> Result<[u8; 4], CanCodecError> {
    if x.is_finite() {
        Ok(x.to_le_bytes())
    } else {
        Err(CanCodecError::NonFinite { field })
    }
}

/// Encodes `msg` for axis `node`.
pub fn encode(node: u8, msg: &OdriveMsg) -> Result<WireFrame, CanCodecError> {
    let id = can_id(node, msg.cmd_id())?;
    let mut b = [0u8; 8];
    let len = match *msg {
        OdriveMsg::Estop | OdriveMsg::ClearErrors => 0,
        OdriveMsg::SetAxisState { requested_state } => {
            b[..4].copy_from_slice(&requested_state.to_le_bytes());
            4
        }
        OdriveMsg::SetControllerMode {
            control_mode,
            input_mode,
        } => {
            b[..4].copy_from_slice(&control_mode.to_le_bytes());
            b[4..].copy_from_slice(&input_mode.to_le_bytes());
            8
        }
        OdriveMsg::SetInputTorque { torque_nm } => {
            b[..4].copy_from_slice(&f32_ok(torque_nm, "torque_nm")?);
            4
        }
        OdriveMsg::Heartbeat {
            axis_error,
            axis_state,
            status,
        } => {
            b[..4].copy_from_slice(&axis_error.to_le_bytes());
            b[4] = axis_state;
            b[5..].copy_from_slice(&status);
            8
        }
        OdriveMsg::EncoderEstimates { pos_rev, vel_rev_s } => {
            b[..4].copy_from_slice(&f32_ok(pos_rev, "pos_rev")?);
            b[4..].copy_from_slice(&f32_ok(vel_rev_s, "vel_rev_s")?);
            8
        }
        OdriveMsg::Iq {
            iq_setpoint_a,
            iq_measured_a,
        } => {
            b[..4].copy_from_slice(&f32_ok(iq_setpoint_a, "iq_setpoint_a")?);
            b[4..].copy_from_slice(&f32_ok(iq_measured_a, "iq_measured_a")?);
            8
        }
        OdriveMsg::Request { .. } => return WireFrame::remote(id, false, 8),
    };
    WireFrame::standard(id, &b[..len])
}

fn need(f: &WireFrame, n: u8) -> Result<(), CanCodecError> {
    if f.len < n {
        Err(CanCodecError::WrongLength {
            id: f.id,
            expected: n,
            got: f.len,
        })
    } else {
        Ok(())
    }
}

fn u32_at(b: &[u8; 8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Decodes a frame into (node, message). Non-finite floats on the wire decode as they are (NaN stays
/// NaN): the consumer decides; unknown command ids are an error.
pub fn decode(f: &WireFrame) -> Result<(u8, OdriveMsg), CanCodecError> {
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
    let (node, c) = split_id(f.id);
    if f.rtr {
        return Ok((node, OdriveMsg::Request { cmd: c }));
    }
    let b = &f.data;
    let msg = match c {
        cmd::ESTOP => OdriveMsg::Estop,
        cmd::CLEAR_ERRORS => OdriveMsg::ClearErrors,
        cmd::SET_AXIS_STATE => {
            need(f, 4)?;
            OdriveMsg::SetAxisState {
                requested_state: u32_at(b, 0),
            }
        }
        cmd::SET_CONTROLLER_MODE => {
            need(f, 8)?;
            OdriveMsg::SetControllerMode {
                control_mode: u32_at(b, 0) as i32,
                input_mode: u32_at(b, 4) as i32,
            }
        }
        cmd::SET_INPUT_TORQUE => {
            need(f, 4)?;
            OdriveMsg::SetInputTorque {
                torque_nm: f32::from_bits(u32_at(b, 0)),
            }
        }
        cmd::HEARTBEAT => {
            need(f, 5)?;
            OdriveMsg::Heartbeat {
                axis_error: u32_at(b, 0),
                axis_state: b[4],
                status: [b[5], b[6], b[7]],
            }
        }
        cmd::GET_ENCODER_ESTIMATES => {
            need(f, 8)?;
            OdriveMsg::EncoderEstimates {
                pos_rev: f32::from_bits(u32_at(b, 0)),
                vel_rev_s: f32::from_bits(u32_at(b, 4)),
            }
        }
        cmd::GET_IQ => {
            need(f, 8)?;
            OdriveMsg::Iq {
                iq_setpoint_a: f32::from_bits(u32_at(b, 0)),
                iq_measured_a: f32::from_bits(u32_at(b, 4)),
            }
        }
        other => {
            return Err(CanCodecError::UnknownCommand {
                id: f.id,
                cmd: other,
            });
        }
    };
    Ok((node, msg))
}
