//! CiA 402 / CANopen codec tests: byte vectors from real traces and the CiA 301 layouts, round
//! trips (proptest), PDO mapping values, the bus-load numbers of the default layout.

use frictionless_drives::can::busload::*;
use frictionless_drives::can::cia402::*;
use frictionless_drives::can::{CanCodecError, WireFrame};
use proptest::prelude::*;

#[test]
fn sdo_write_of_the_controlword_matches_a_python_canopen_trace() {
    // 0x67F 2B 40 60 00 06 00 00 00 → 0x5FF 60 40 60 00 … (write 0x6040 = 6 to node 0x7F).
    let req = sdo_download(SdoAddr::new(obj::CONTROLWORD, 0), 6, 2).unwrap();
    let f = encode_sdo_request(0x7F, &req).unwrap();
    assert_eq!((f.id, f.len), (0x67F, 8));
    assert_eq!(f.data, [0x2B, 0x40, 0x60, 0x00, 0x06, 0, 0, 0]);
    assert_eq!(decode_sdo_request(&f).unwrap(), (0x7F, req));
    let ack = encode_sdo_response(
        0x7F,
        &SdoResponse::DownloadAck {
            addr: SdoAddr::new(0x6040, 0),
        },
    )
    .unwrap();
    assert_eq!(ack.id, 0x5FF);
    assert_eq!(ack.data, [0x60, 0x40, 0x60, 0x00, 0, 0, 0, 0]);
    assert_eq!(
        decode_sdo_response(&ack, false).unwrap(),
        (
            0x7F,
            SdoResponse::DownloadAck {
                addr: SdoAddr::new(0x6040, 0)
            }
        )
    );
}

#[test]
fn sdo_command_bytes_follow_cia301() {
    let a = SdoAddr::new(0x6060, 0);
    let cmd = |len| {
        encode_sdo_request(1, &sdo_download(a, 10, len).unwrap())
            .unwrap()
            .data[0]
    };
    assert_eq!([cmd(1), cmd(2), cmd(3), cmd(4)], [0x2F, 0x2B, 0x27, 0x23]);
    let up = encode_sdo_request(1, &SdoRequest::Upload { addr: a }).unwrap();
    assert_eq!(up.data, [0x40, 0x60, 0x60, 0, 0, 0, 0, 0]);
    let resp = |len| {
        encode_sdo_response(
            1,
            &SdoResponse::Upload {
                addr: a,
                data: [1, 2, 3, 4],
                len,
            },
        )
        .unwrap()
    };
    assert_eq!(
        [1, 2, 3, 4].map(|n| resp(n).data[0]),
        [0x4F, 0x4B, 0x47, 0x43]
    );
    // Upload response of 0x6076 = 2500 mNm (UNSIGNED32).
    let r = resp(4);
    assert_eq!(r.data, [0x43, 0x60, 0x60, 0x00, 1, 2, 3, 4]);
    // "Size not indicated" expedited upload counts as 4 bytes.
    let mut raw = r;
    raw.data[0] = 0x42;
    assert!(matches!(
        decode_sdo_response(&raw, false).unwrap().1,
        SdoResponse::Upload { len: 4, .. }
    ));
    let abort = encode_sdo_response(
        1,
        &SdoResponse::Abort {
            addr: SdoAddr::new(0x1A00, 1),
            code: abort::NOT_MAPPABLE,
        },
    )
    .unwrap();
    assert_eq!(abort.data, [0x80, 0x00, 0x1A, 0x01, 0x41, 0x00, 0x04, 0x06]);
    assert_eq!(
        abort_text(abort::NOT_MAPPABLE),
        "object cannot be mapped to the PDO"
    );
    assert_eq!(abort_text(0x1234_5678), "unknown abort code");
    // Segmented upload: initiate with size, segments with toggle / unused bytes / last.
    let init = encode_sdo_response(
        1,
        &SdoResponse::UploadSegmented {
            addr: SdoAddr::new(0x1008, 0),
            size: Some(11),
        },
    )
    .unwrap();
    assert_eq!(init.data, [0x41, 0x08, 0x10, 0x00, 11, 0, 0, 0]);
    let seg = encode_sdo_response(
        1,
        &SdoResponse::UploadSegment {
            toggle: true,
            data: *b"402 dr\0",
            len: 4,
            last: true,
        },
    )
    .unwrap();
    // toggle 0x10 | (7 − 4) << 1 | last.
    assert_eq!(seg.data[0], 0x17);
    assert_eq!(
        decode_sdo_response(&seg, true).unwrap().1,
        SdoResponse::UploadSegment {
            toggle: true,
            data: [b'4', b'0', b'2', b' ', 0, 0, 0],
            len: 4,
            last: true
        }
    );
    // Outside a segmented upload scs 0 is refused.
    assert!(decode_sdo_response(&seg, false).is_err());
    let segreq = encode_sdo_request(1, &SdoRequest::UploadSegment { toggle: true }).unwrap();
    assert_eq!(segreq.data[0], 0x70);
    // Segmented / block download requests are not spoken (a server aborts them).
    let mut seg_dl = up;
    seg_dl.data[0] = 0x21;
    assert!(matches!(
        decode_sdo_request(&seg_dl),
        Err(CanCodecError::UnknownCommand { cmd: 0x21, .. })
    ));
    // SDO frames are 8 bytes.
    let short = WireFrame::standard(0x601, &[0x40, 0x60, 0x60]).unwrap();
    assert!(matches!(
        decode_sdo_request(&short),
        Err(CanCodecError::WrongLength { expected: 8, .. })
    ));
    assert!(sdo_download(a, 0, 5).is_err());
}

#[test]
fn nmt_heartbeat_sync_and_emcy_bytes() {
    let f = encode_nmt(NmtCommand::Start, 5).unwrap();
    assert_eq!((f.id, f.payload()), (0, &[0x01, 0x05][..]));
    assert_eq!(decode_nmt(&f).unwrap(), (NmtCommand::Start, 5));
    let all = encode_nmt(NmtCommand::ResetCommunication, 0).unwrap();
    assert_eq!(all.payload(), [0x82, 0]);
    assert!(encode_nmt(NmtCommand::Stop, 128).is_err());
    let hb = encode_heartbeat(5, NmtState::Operational).unwrap();
    assert_eq!((hb.id, hb.payload()), (0x705, &[0x05][..]));
    let boot = WireFrame::standard(0x705, &[0x00]).unwrap();
    assert_eq!(decode_heartbeat(&boot).unwrap(), (5, NmtState::BootUp));
    // The guarding toggle bit is ignored.
    let toggled = WireFrame::standard(0x705, &[0xFF]).unwrap();
    assert_eq!(
        decode_heartbeat(&toggled).unwrap(),
        (5, NmtState::PreOperational)
    );
    assert!(decode_heartbeat(&WireFrame::standard(0x705, &[0x06]).unwrap()).is_err());
    assert_eq!(encode_sync(None).len, 0);
    assert_eq!(decode_sync(&encode_sync(Some(7))).unwrap(), Some(7));
    assert_eq!(decode_sync(&encode_sync(None)).unwrap(), None);
    let e = Emcy {
        code: 0x4310,
        register: 0x08,
        manufacturer: [1, 2, 3, 4, 5],
    };
    let f = encode_emcy(3, &e).unwrap();
    assert_eq!(f.id, 0x83);
    assert_eq!(f.data, [0x10, 0x43, 0x08, 1, 2, 3, 4, 5]);
    assert_eq!(decode_emcy(&f).unwrap(), (3, e));
    assert_eq!(emcy_text(0x4310), "drive over-temperature");
    assert_eq!(emcy_text(0x4399), "temperature");
    assert_eq!(emcy_text(0xFF01), "device specific");
    assert!(decode_emcy(&encode_sync(None)).is_err(), "0x80 is SYNC");
}

#[test]
fn pdo_mapping_values_and_payloads() {
    // Mapping values as in CiA 301 / python canopen.
    assert_eq!(PdoEntry::new(0x6040, 0, 16).to_mapping(), 0x6040_0010);
    assert_eq!(PdoEntry::new(0x60E4, 1, 32).to_mapping(), 0x60E4_0120);
    assert_eq!(
        PdoEntry::from_mapping(0x6064_0020),
        PdoEntry::new(0x6064, 0, 32)
    );
    let tpdo1 = PdoMap::new(&[
        PdoEntry::new(obj::STATUSWORD, 0, 16),
        PdoEntry::new(obj::POSITION_ACTUAL, 0, 32),
        PdoEntry::new(obj::TORQUE_ACTUAL, 0, 16),
    ])
    .unwrap();
    assert_eq!(tpdo1.bytes(), 8);
    let f = encode_pdo(0x185, &tpdo1, &[0x0237, -2, -400]).unwrap();
    assert_eq!(f.data, [0x37, 0x02, 0xFE, 0xFF, 0xFF, 0xFF, 0x70, 0xFE]);
    let mut out = [0u32; 3];
    decode_pdo(&f, &tpdo1, &mut out).unwrap();
    assert_eq!(out, [0x0237, 0xFFFF_FFFE, 0xFE70]);
    assert_eq!(
        (sign_extend(out[1], 32), sign_extend(out[2], 16)),
        (-2, -400)
    );
    // Wrong length, out-of-range values, bad mappings are refused, never truncated.
    let short = WireFrame::standard(0x185, &f.data[..6]).unwrap();
    assert!(matches!(
        decode_pdo(&short, &tpdo1, &mut out),
        Err(CanCodecError::WrongLength {
            expected: 8,
            got: 6,
            ..
        })
    ));
    assert!(encode_pdo(0x185, &tpdo1, &[0x1_0000, 0, 0]).is_err());
    assert!(encode_pdo(0x185, &tpdo1, &[0, 0]).is_err());
    assert!(PdoMap::new(&[PdoEntry::new(0x6064, 0, 12)]).is_err());
    assert!(PdoMap::new(&[PdoEntry::new(0x6064, 0, 32); 3]).is_err());
    assert_eq!(tpdo1.position(obj::TORQUE_ACTUAL, 0), Some(2));
}

#[test]
fn cia402_bus_load_of_the_default_layout() {
    // SYNC 55, RPDO 4 B 95, TPDOs 8 B 135 each (worst-case stuffing, 11-bit ids).
    assert_eq!(cia402_sync_bits(), 55);
    assert_eq!(cia402_default_bits_per_node_tick(), 365);
    assert_eq!(cia402_bits_per_node_tick(&[4], &[(8, 1), (8, 1)]), 365);
    // The reference digest's 8-byte RPDO + two 8-byte TPDOs: 405 per node.
    assert_eq!(cia402_bits_per_node_tick(&[8], &[(8, 1), (8, 1)]), 405);
    // A temperature TPDO every 100 SYNCs adds ⌈95 / 100⌉ = 1 bit.
    assert_eq!(cia402_bits_per_node_tick(&[], &[(4, 100)]), 1);
    // 1 kHz at 1 Mbit/s: two nodes 78.5 %, three 115 %.
    let two = load_fraction_bits(55 + 2 * 365, 1000.0, 1e6);
    assert!((two - 0.785).abs() < 1e-12);
    assert!(load_fraction_bits(55 + 3 * 365, 1000.0, 1e6) > 1.0);
}

proptest! {
    #[test]
    fn sdo_requests_round_trip(node in 1u8..=127, index: u16, sub: u8, value: u32, len in 1u8..=4,
                              toggle: bool, code: u32) {
        let addr = SdoAddr::new(index, sub);
        let mask = if len == 4 { u32::MAX } else { (1u32 << (8 * len)) - 1 };
        let reqs = [
            sdo_download(addr, value & mask, len).unwrap(),
            SdoRequest::Upload { addr },
            SdoRequest::UploadSegment { toggle },
            SdoRequest::Abort { addr, code },
        ];
        for r in reqs {
            let f = encode_sdo_request(node, &r).unwrap();
            prop_assert_eq!(decode_sdo_request(&f).unwrap(), (node, r));
        }
        let resps = [
            SdoResponse::DownloadAck { addr },
            SdoResponse::Upload { addr, data: (value & mask).to_le_bytes(), len },
            SdoResponse::UploadSegmented { addr, size: Some(value) },
            SdoResponse::UploadSegmented { addr, size: None },
            SdoResponse::Abort { addr, code },
        ];
        for r in resps {
            let f = encode_sdo_response(node, &r).unwrap();
            prop_assert_eq!(decode_sdo_response(&f, false).unwrap(), (node, r));
        }
    }

    #[test]
    fn pdos_round_trip(a: i16, b: i32, c: u8, d: i8) {
        let m = PdoMap::new(&[
            PdoEntry::new(0x6071, 0, 16),
            PdoEntry::new(0x6064, 0, 32),
            PdoEntry::new(0x6061, 0, 8),
            PdoEntry::new(0x6060, 0, 8),
        ]).unwrap();
        let f = encode_pdo(0x281, &m, &[a.into(), b.into(), c.into(), d.into()]).unwrap();
        let mut out = [0u32; 4];
        decode_pdo(&f, &m, &mut out).unwrap();
        prop_assert_eq!(sign_extend(out[0], 16), i32::from(a));
        prop_assert_eq!(sign_extend(out[1], 32), b);
        prop_assert_eq!(out[2], u32::from(c));
        prop_assert_eq!(sign_extend(out[3], 8), i32::from(d));
    }

    #[test]
    fn torque_permille_round_trips_within_half_a_step(rated in 1u32..100_000, nm in -100.0f64..100.0) {
        let t = TorqueScale::new(rated, 32767).unwrap();
        let (pm, clamped) = t.permille(nm).unwrap();
        if !clamped {
            prop_assert!((t.motor_nm(pm.into()) - nm).abs() <= 0.5 * t.rated_nm() / 1000.0 + 1e-12);
        } else {
            prop_assert!(pm.unsigned_abs() == 32767);
        }
    }
}
