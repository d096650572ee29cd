//! Fuzz target: arbitrary bytes into the ODrive "CAN Simple" decoder
//! (`frictionless_drives::can::odrive`).
//!
//! Never panics, also on frames that break the `WireFrame` invariants. Round trips on valid frames:
//! a decoded message re-encodes to the same id, the same RTR flag, and the same bytes over the length
//! both frames have (the decoder accepts longer frames than the encoder emits; a short Heartbeat's
//! missing status bytes decode as 0); a message with a non-finite float is refused by the encoder
//! (`NonFinite`), never silently sent. `can_id`/`split_id` are inverse on every 11-bit id.
#![no_main]

use frictionless_drives::can::odrive::{self, OdriveMsg};
use frictionless_drives::can::{CanCodecError, WireFrame};
use libfuzzer_sys::fuzz_target;

fn raw_frame(data: &[u8]) -> WireFrame {
    let g = |i: usize| data.get(i).copied().unwrap_or(0);
    let mut d = [0u8; 8];
    for (k, x) in d.iter_mut().enumerate() {
        *x = g(4 + k);
    }
    WireFrame {
        id: u32::from_le_bytes([g(1), g(2), g(3), g(12)]),
        extended: g(0) & 1 != 0,
        rtr: g(0) & 2 != 0,
        len: g(0) >> 4,
        data: d,
    }
}

fn has_non_finite(m: &OdriveMsg) -> bool {
    match *m {
        OdriveMsg::SetInputTorque { torque_nm } => !torque_nm.is_finite(),
        OdriveMsg::EncoderEstimates { pos_rev, vel_rev_s } => {
            !(pos_rev.is_finite() && vel_rev_s.is_finite())
        }
        OdriveMsg::Iq {
            iq_setpoint_a,
            iq_measured_a,
        } => !(iq_setpoint_a.is_finite() && iq_measured_a.is_finite()),
        _ => false,
    }
}

fn check_round_trip(f: &WireFrame) {
    let Ok((node, msg)) = odrive::decode(f) else {
        return;
    };
    assert_eq!(odrive::can_id(node, msg.cmd_id()).ok(), Some(f.id));
    match odrive::encode(node, &msg) {
        Ok(g) => {
            assert!(!has_non_finite(&msg));
            assert_eq!(g.id, f.id);
            assert!(!g.extended);
            assert_eq!(g.rtr, f.rtr);
            if f.rtr {
                assert!(matches!(msg, OdriveMsg::Request { .. }));
            } else {
                let n = (g.len.min(f.len)) as usize;
                assert_eq!(&g.data[..n], &f.data[..n], "{msg:?}");
                // Bytes the encoder emits beyond what the frame had decode from zeros.
                assert!(g.data[n..g.len as usize].iter().all(|&b| b == 0), "{msg:?}");
                assert_eq!(odrive::decode(&g).ok(), Some((node, msg)));
            }
        }
        Err(e) => {
            assert!(has_non_finite(&msg), "{msg:?} refused: {e}");
            assert!(matches!(e, CanCodecError::NonFinite { .. }));
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let raw = raw_frame(data);
    let _ = odrive::decode(&raw);
    let len = (raw.len as usize).min(8);
    let valid = if raw.rtr {
        WireFrame::remote(raw.id & 0x7FF, false, len as u8)
    } else {
        WireFrame::data_frame(raw.id & 0x7FF, false, &raw.data[..len])
    };
    if let Ok(f) = valid {
        check_round_trip(&f);
    }
    let id = raw.id & 0x7FF;
    let (node, cmd) = odrive::split_id(id);
    assert_eq!(odrive::can_id(node, cmd).ok(), Some(id));
    // Encoding with arbitrary node / command ids must refuse out-of-range ones, never panic.
    let node = data.get(13).copied().unwrap_or(0);
    let msg = OdriveMsg::SetInputTorque {
        torque_nm: f32::from_le_bytes([raw.data[0], raw.data[1], raw.data[2], raw.data[3]]),
    };
    match odrive::encode(node, &msg) {
        Ok(g) => assert!(node <= odrive::NODE_MAX && g.id >> 5 == node as u32),
        Err(_) => assert!(node > odrive::NODE_MAX || has_non_finite(&msg)),
    }
    let _ = odrive::encode(
        node,
        &OdriveMsg::Request {
            cmd: data.get(14).copied().unwrap_or(0),
        },
    );
});
