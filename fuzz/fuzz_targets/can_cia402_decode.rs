//! Fuzz target: arbitrary bytes into the CANopen / CiA 402 decoders
//! (`frictionless_drives::can::cia402`): NMT, heartbeat, SYNC, SDO request and response, EMCY, a
//! PDO of a mapping taken from the input, the statusword decode and the controlword state machine.
//!
//! Never panics, also on frames that break the `WireFrame` invariants. Round trips on valid frames:
//! a decoded message re-encodes to the same id and the same bytes (SDO: the bytes the protocol
//! defines — an expedited transfer's unused bytes and a "size not indicated" upload are normalised,
//! so those are compared through a second decode); a PDO decodes to values that re-encode to the
//! same payload. The state machine never leaves the eight states.
#![no_main]

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::cia402::*;
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

fn decode_all(f: &WireFrame) {
    let _ = decode_nmt(f);
    let _ = decode_heartbeat(f);
    let _ = decode_sync(f);
    let _ = decode_sdo_request(f);
    let _ = decode_sdo_response(f, false);
    let _ = decode_sdo_response(f, true);
    let _ = decode_emcy(f);
    let _ = classify(f.id);
}

fn check_round_trips(f: &WireFrame) {
    if let Ok((cmd, node)) = decode_nmt(f) {
        assert_eq!(encode_nmt(cmd, node).ok(), Some(*f));
    }
    if let Ok((node, st)) = decode_heartbeat(f) {
        let g = encode_heartbeat(node, st).unwrap();
        assert_eq!((g.id, g.data[0]), (f.id, f.data[0] & 0x7F));
    }
    if let Ok(c) = decode_sync(f) {
        assert_eq!(encode_sync(c), *f);
    }
    if let Ok((node, e)) = decode_emcy(f) {
        assert_eq!(encode_emcy(node, &e).ok(), Some(*f));
    }
    if let Ok((node, r)) = decode_sdo_request(f) {
        let g = encode_sdo_request(node, &r).unwrap();
        assert_eq!(g.id, f.id);
        assert_eq!(decode_sdo_request(&g).ok(), Some((node, r)));
    }
    for seg in [false, true] {
        if let Ok((node, r)) = decode_sdo_response(f, seg) {
            let g = encode_sdo_response(node, &r).unwrap();
            assert_eq!(g.id, f.id);
            assert_eq!(decode_sdo_response(&g, seg).ok(), Some((node, r)));
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let raw = raw_frame(data);
    decode_all(&raw);
    let len = (raw.len as usize).min(8);
    if !raw.rtr
        && let Ok(f) = WireFrame::data_frame(raw.id & 0x7FF, false, &raw.data[..len])
    {
        check_round_trips(&f);
        // A mapping from the input: up to 8 entries of 8/16/32 bits.
        let n = usize::from(data.get(13).copied().unwrap_or(0) % 9);
        let entries: Vec<PdoEntry> = (0..n)
            .map(|k| {
                let b = data.get(14 + k).copied().unwrap_or(0);
                PdoEntry::new(0x6000 + u16::from(b), 0, [8, 16, 32][usize::from(b % 3)])
            })
            .collect();
        if let Ok(map) = PdoMap::new(&entries) {
            let mut out = [0u32; PDO_MAX_ENTRIES];
            if decode_pdo(&f, &map, &mut out).is_ok() {
                let vals: Vec<i64> = out[..map.entries().len()]
                    .iter()
                    .map(|&v| i64::from(v))
                    .collect();
                assert_eq!(encode_pdo(f.id, &map, &vals).ok(), Some(f));
            }
        }
    }
    // The 402 state machine over the input's words: always one of the states; statuswords of the
    // states decode to themselves.
    let mut s = DriveState::SwitchOnDisabled;
    let mut en = Enabler::new(data.first().is_some_and(|b| b & 1 != 0), 3);
    for w in data.chunks(2) {
        let word = u16::from_le_bytes([w[0], w.get(1).copied().unwrap_or(0)]);
        let _ = decode_statusword(word);
        s = apply_controlword(s, word, word & 0x80 != 0, word & 0x100 != 0);
        assert_eq!(decode_statusword(s.statusword()), Some(s));
        let goal = [Goal::Enabled, Goal::QuickStop, Goal::Disabled][usize::from(w[0] % 3)];
        let c = en.next(decode_statusword(word), goal);
        assert!(
            matches!(c, 0x00 | 0x02 | 0x06 | 0x07 | 0x0F | 0x80),
            "{c:#x}"
        );
    }
    let _ = TorqueScale::new(
        u32::from_le_bytes([raw.data[0], raw.data[1], raw.data[2], raw.data[3]]),
        3000,
    )
    .map(|t| {
        t.permille(f64::from(f32::from_le_bytes([
            raw.data[4],
            raw.data[5],
            raw.data[6],
            raw.data[7],
        ])))
    });
});
