//! Real-kernel SocketCAN tests (ignored on the host; run in the VM by tests/canvm/run.sh, which creates
//! vcan0 and vcan1): the kernel facts the CAN backends rely on — classic frames round-trip between two
//! sockets with non-blocking reads, kernel ID filters deliver only the ids we own, error frames can be
//! enabled (and then a quiet bus reads WouldBlock, not an error) — and codec round trips against a drive
//! emulator thread on vcan0.

use std::io::ErrorKind;
use std::time::Duration;

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::mit::{self, MitCommand, MitRanges, MitReply, MitRx, MitSpecial};
use socketcan::{CanFilter, CanFrame, CanSocket, Socket, SocketOptions};

const IFACE: &str = "vcan0";

fn send(s: &CanSocket, f: WireFrame) {
    s.write_frame_insist(&CanFrame::try_from(f).unwrap())
        .unwrap();
}

fn recv(s: &CanSocket, t: Duration) -> Option<WireFrame> {
    match s.read_frame_timeout(t) {
        Ok(f) => Some(WireFrame::try_from(&f).unwrap()),
        Err(e) if e.kind() == ErrorKind::TimedOut => None,
        Err(e) => panic!("read: {e}"),
    }
}

/// Non-blocking read: `Some(frame)` or `None` on WouldBlock.
fn try_recv(s: &CanSocket) -> Option<WireFrame> {
    match s.read_frame() {
        Ok(f) => Some(WireFrame::try_from(&f).unwrap()),
        Err(e) if e.kind() == ErrorKind::WouldBlock => None,
        Err(e) => panic!("read: {e}"),
    }
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_two_sockets_round_trip_non_blocking() {
    // vcan1, ids 0x100..=0x10F only: independent of the vcan0 tests.
    let tx = CanSocket::open("vcan1").expect("open vcan1");
    let rx = CanSocket::open("vcan1").expect("open vcan1");
    rx.set_filters(&[CanFilter::new(0x100, 0x7F0)]).unwrap();
    rx.set_nonblocking(true).unwrap();
    for k in 0..200u16 {
        let id = 0x100 + u32::from(k % 16);
        send(&tx, WireFrame::standard(id, &k.to_le_bytes()).unwrap());
        let got = loop {
            match try_recv(&rx) {
                Some(g) => break g,
                None => std::thread::yield_now(),
            }
        };
        assert_eq!((got.id, got.payload()), (id, &k.to_le_bytes()[..]));
    }
    assert!(try_recv(&rx).is_none(), "exactly one frame per write");
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_mit_round_trip_with_drive_emulator() {
    let r = MitRanges::MINI_CHEETAH;
    let host = CanSocket::open(IFACE).unwrap();
    host.set_filters(&[CanFilter::new(0x000, 0x7FF)]).unwrap();
    let drive = CanSocket::open(IFACE).unwrap();
    drive.set_filters(&[CanFilter::new(0x011, 0x7FF)]).unwrap();
    let emu = std::thread::spawn(move || {
        let mut enabled = false;
        let mut replies = 0;
        while replies < 50 {
            let f = recv(&drive, Duration::from_secs(5)).expect("command within 5 s");
            match mit::decode_command(&f, &r).unwrap() {
                MitRx::Special(MitSpecial::EnterMotorMode) => enabled = true,
                MitRx::Special(_) => {}
                MitRx::Command(c) => {
                    assert!(enabled, "command before enter-motor-mode");
                    let rep = MitReply {
                        motor_id: 0x11,
                        p_rad: 0.0,
                        v_rad_s: 0.0,
                        i_a: c.t_ff_nm,
                    };
                    send(&drive, mit::encode_reply(0x000, &rep, &r).unwrap().0);
                    replies += 1;
                }
            }
        }
    });
    send(
        &host,
        mit::encode_special(0x11, MitSpecial::EnterMotorMode).unwrap(),
    );
    for k in 0..50 {
        let t = (k as f64 - 25.0) * 0.5;
        send(
            &host,
            mit::encode_command(0x11, &MitCommand::torque(t), &r)
                .unwrap()
                .0,
        );
        let g = recv(&host, Duration::from_secs(5)).expect("reply within 5 s");
        let rep = mit::decode_reply(&g, &r).unwrap();
        assert_eq!(rep.motor_id, 0x11);
        let s = r.steps();
        assert!(
            (rep.i_a - t).abs() <= s[4] / 2.0 + s[5] / 2.0 + 1e-9,
            "{} vs {t}",
            rep.i_a
        );
    }
    emu.join().unwrap();
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_kernel_filter_delivers_only_owned_ids() {
    let rx = CanSocket::open(IFACE).unwrap();
    // Own: MIT reply id 0x000 exactly, and every ODrive message of node 2 (ids 0x40..=0x5F).
    rx.set_filters(&[CanFilter::new(0x000, 0x7FF), CanFilter::new(0x040, 0x7E0)])
        .unwrap();
    let tx = CanSocket::open(IFACE).unwrap();
    let ids = [
        0x000u32, 0x001, 0x03F, 0x040, 0x049, 0x05F, 0x060, 0x141, 0x7FF,
    ];
    for id in ids {
        send(&tx, WireFrame::standard(id, &[id as u8]).unwrap());
    }
    let mut got = Vec::new();
    while let Some(f) = recv(&rx, Duration::from_millis(500)) {
        got.push(f.id);
    }
    assert_eq!(got, [0x000, 0x040, 0x049, 0x05F]);
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_error_frames_can_be_enabled() {
    let rx = CanSocket::open(IFACE).unwrap();
    rx.set_error_filter_accept_all().unwrap();
    rx.set_filters(&[CanFilter::new(0x123, 0x7FF)]).unwrap();
    let tx = CanSocket::open(IFACE).unwrap();
    // Data frames still arrive with the error mask set; the filter still applies.
    send(&tx, WireFrame::standard(0x124, &[2]).unwrap());
    send(&tx, WireFrame::standard(0x123, &[1]).unwrap());
    let f = recv(&rx, Duration::from_secs(2)).expect("data frame");
    assert_eq!((f.id, f.payload()), (0x123, &[1u8][..]));
    assert!(recv(&rx, Duration::from_millis(200)).is_none());
    // vcan never raises bus errors: a non-blocking read of the quiet bus says WouldBlock, not an error.
    rx.set_nonblocking(true).unwrap();
    assert!(try_recv(&rx).is_none());
    rx.set_error_filter_drop_all().unwrap();
}
