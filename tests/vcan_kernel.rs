//! Real-kernel SocketCAN smoke tests: run only inside the CAN VM (`tests/canvm/run.sh`), where vcan0 and
//! vcan1 exist. On the host they are `#[ignore]`d because this machine's kernel has no CAN at all.
//!
//! They check the kernel facts the CAN backend relies on: classic frames round-trip on vcan with
//! `recv_own_msgs`, kernel ID filters deliver only the IDs we own, non-blocking reads say WouldBlock,
//! and error frames can be enabled.

use socketcan::{
    CanFilter, CanFrame, CanSocket, EmbeddedFrame, Frame, Socket, SocketOptions, StandardId,
};
use std::io::ErrorKind;

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new(StandardId::new(id).expect("11-bit id"), data).expect("<= 8 bytes")
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_two_sockets_round_trip() {
    let tx = CanSocket::open("vcan0").expect("open vcan0");
    let rx = CanSocket::open("vcan0").expect("open vcan0");
    rx.set_nonblocking(true).unwrap();
    for k in 0..200u16 {
        let f = frame(0x100 + (k % 16), &k.to_le_bytes());
        tx.write_frame(&f).unwrap();
        let got = loop {
            match rx.read_frame() {
                Ok(g) => break g,
                Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::yield_now(),
                Err(e) => panic!("read: {e}"),
            }
        };
        assert_eq!(got.raw_id(), 0x100 + u32::from(k % 16));
        assert_eq!(got.data(), &k.to_le_bytes());
    }
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_kernel_filter_delivers_only_owned_ids() {
    let tx = CanSocket::open("vcan1").expect("open vcan1");
    let rx = CanSocket::open("vcan1").expect("open vcan1");
    rx.set_filters(&[CanFilter::new(0x300, 0x7F0)]).unwrap();
    rx.set_nonblocking(true).unwrap();
    for id in [0x200u16, 0x305, 0x400, 0x30F, 0x310] {
        tx.write_frame(&frame(id, &[1, 2, 3])).unwrap();
    }
    std::thread::sleep(std::time::Duration::from_millis(50));
    let mut ids = Vec::new();
    loop {
        match rx.read_frame() {
            Ok(f) => ids.push(f.raw_id()),
            Err(e) if e.kind() == ErrorKind::WouldBlock => break,
            Err(e) => panic!("read: {e}"),
        }
    }
    assert_eq!(ids, vec![0x305, 0x30F]);
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_error_frames_can_be_enabled() {
    let s = CanSocket::open("vcan0").expect("open vcan0");
    s.set_error_filter_accept_all().expect("CAN_RAW_ERR_FILTER");
    s.set_nonblocking(true).unwrap();
    // vcan never raises bus errors, so nothing may arrive: a read must say WouldBlock, not fail.
    match s.read_frame() {
        Err(e) => assert_eq!(e.kind(), ErrorKind::WouldBlock),
        Ok(f) => panic!("unexpected frame {:x}", f.raw_id()),
    }
}
