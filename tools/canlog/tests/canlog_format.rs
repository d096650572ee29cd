//! candump -L parser/writer tests on a handwritten log, typed errors naming the line, replay pacing.

use frictionless_canlog::{self as canlog, CanLogError, LogFrame};

/// Handwritten after `doc/CanDumpLogFormat.md`: standard, extended, empty, RTR with and without
/// DLC, raw-DLC escape, FD with BRS.
const LOG: &str = "\
(1436509052.249713) vcan0 044#2A366C2BBA
(1436509052.449847) vcan0 0F6#7ADFE07BD2
(1436509052.650004) vcan1 1F4C7B5A#0011223344556677
(1436509052.850150) vcan0 123#
(1436509053.050300) vcan0 123#R
(1436509053.250450) vcan0 7FF#R8
(1436509053.450600) vcan0 333#1122334455667788_E
(1436509053.650750) vcan0 12345678##1000102030405060708090A0B
";

#[test]
fn handwritten_log_parses_and_writes_back_identically() {
    let entries = canlog::parse_log(LOG.as_bytes(), "<test>").unwrap();
    assert_eq!(entries.len(), 8);
    assert_eq!(entries[0].stamp_us, 1_436_509_052_249_713);
    assert_eq!(entries[2].iface, "vcan1");
    match &entries[0].frame {
        LogFrame::Can { frame, len8_dlc } => {
            assert_eq!((frame.id, frame.extended, frame.rtr), (0x044, false, false));
            assert_eq!(frame.payload(), &[0x2A, 0x36, 0x6C, 0x2B, 0xBA]);
            assert_eq!(*len8_dlc, None);
        }
        f => panic!("{f:?}"),
    }
    match &entries[2].frame {
        LogFrame::Can { frame, .. } => assert!(frame.extended && frame.id == 0x1F4C_7B5A),
        f => panic!("{f:?}"),
    }
    match &entries[5].frame {
        LogFrame::Can { frame, .. } => assert!(frame.rtr && frame.len == 8 && frame.id == 0x7FF),
        f => panic!("{f:?}"),
    }
    match &entries[6].frame {
        LogFrame::Can { len8_dlc, .. } => assert_eq!(*len8_dlc, Some(0xE)),
        f => panic!("{f:?}"),
    }
    match &entries[7].frame {
        LogFrame::Fd(fd) => {
            assert_eq!((fd.id, fd.extended, fd.flags), (0x1234_5678, true, 1));
            assert_eq!(fd.data.len(), 12);
            assert_eq!(fd.data[11], 0x0B);
        }
        f => panic!("{f:?}"),
    }
    let mut out = Vec::new();
    for e in &entries {
        canlog::write_entry(&mut out, e).unwrap();
    }
    assert_eq!(String::from_utf8(out).unwrap(), LOG);
}

#[test]
fn errors_name_the_line_and_text() {
    let cases = [
        ("(1.000000) vcan0 123#112", "odd number"),
        ("(1.00000) vcan0 123#11", "6 digits"),
        ("1.000000 vcan0 123#11", "parentheses"),
        ("(1.000000) vcan0 1234#11", "hex digits"),
        ("(1.000000) vcan0 800#11", "out of range"),
        ("(1.000000) vcan0 123#112233445566778899", "> 8"),
        ("(1.000000) vcan0 123##0112233445566778899", "FD length"),
        ("(1.000000) vcan0 123#RZ", "remote DLC"),
        ("(1.000000) vcan0", "expected"),
        ("(1.000000) vcan0 12G#11", "bad hex id"),
        ("(1.000000) vcan0 123#11_E", "8 data bytes"),
    ];
    for (bad, what) in cases {
        let text = format!("(0.000001) vcan0 001#00\n\n{bad}\n");
        let err = canlog::parse_log(text.as_bytes(), "x.log").unwrap_err();
        match &err {
            CanLogError::Parse { line, text, .. } => {
                assert_eq!(*line, 3, "{err}");
                assert_eq!(text, bad);
            }
            e => panic!("{e}"),
        }
        let msg = err.to_string();
        assert!(msg.contains("x.log: line 3"), "{msg}");
        assert!(msg.contains(what), "`{bad}` → {msg}");
    }
}

#[test]
fn missing_file_error_names_it() {
    let e = canlog::read_log(std::path::Path::new("/nonexistent/dir/a.log")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/dir/a.log"), "{e}");
}

#[test]
fn replay_paces_by_timestamps_and_loops() {
    // 5 frames 20 ms apart at speed 2 → frame k due k·10 ms after the first.
    let text: String = (0..5)
        .map(|k| format!("(100.{:06}) vcan0 001#{k:02X}\n", k * 20_000))
        .collect();
    let entries = canlog::parse_log(text.as_bytes(), "<t>").unwrap();
    // The schedule, with a recording clock (no wall-clock timing in tests).
    let mut deadlines = Vec::new();
    let mut seen = Vec::new();
    let n = canlog::replay_scheduled(
        &entries,
        2.0,
        2,
        |offset| deadlines.push(offset.as_micros()),
        |i, _| {
            seen.push(i);
            Ok::<(), ()>(())
        },
    )
    .unwrap();
    assert_eq!(n, 10);
    assert_eq!(seen, [0, 1, 2, 3, 4, 0, 1, 2, 3, 4]);
    // Frame k at k·10 ms; the second loop starts one gap (10 ms) after the last frame (40 ms).
    let want: Vec<u128> = (0..10u128).map(|k| k * 10_000).collect();
    assert_eq!(deadlines, want);
    // The real-clock wrapper sends the same frames in the same order.
    let mut real = Vec::new();
    canlog::replay(&entries, 1000.0, 1, |i, _| {
        real.push(i);
        Ok::<(), ()>(())
    })
    .unwrap();
    assert_eq!(real, [0, 1, 2, 3, 4]);
    // A failing sender stops the replay with its error.
    let r = canlog::replay(
        &entries,
        100.0,
        0,
        |i, _| if i == 2 { Err(i) } else { Ok(()) },
    );
    assert_eq!(r, Err(2));
}
