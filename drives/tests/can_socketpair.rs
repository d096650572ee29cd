//! The real socketcan I/O path without kernel CAN: `socketpair(AF_UNIX, SOCK_SEQPACKET)` wrapped as
//! `socketcan::CanSocket` (one write = one 16-byte datagram, as on AF_CAN). Encode MIT/ODrive frames,
//! send, receive, decode.

use std::os::fd::{FromRawFd, OwnedFd};
use std::time::Duration;

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::mit::{self, MitCommand, MitRanges, MitReply, MitRx};
use frictionless_drives::can::odrive::{self, OdriveMsg};
use socketcan::{CanFrame, CanSocket, Socket};

fn pair() -> (CanSocket, CanSocket) {
    let mut fds = [0; 2];
    // SAFETY: fds is a valid 2-element array; on success both fds are new and owned by us.
    let rc = unsafe { libc::socketpair(libc::AF_UNIX, libc::SOCK_SEQPACKET, 0, fds.as_mut_ptr()) };
    assert_eq!(rc, 0, "socketpair: {}", std::io::Error::last_os_error());
    // SAFETY: the fds were just created and are not owned elsewhere.
    unsafe {
        (
            CanSocket::from(OwnedFd::from_raw_fd(fds[0])),
            CanSocket::from(OwnedFd::from_raw_fd(fds[1])),
        )
    }
}

fn send(s: &CanSocket, f: WireFrame) {
    s.write_frame(&CanFrame::try_from(f).unwrap()).unwrap();
}

fn recv(s: &CanSocket) -> WireFrame {
    let f = s.read_frame_timeout(Duration::from_secs(5)).unwrap();
    WireFrame::try_from(&f).unwrap()
}

#[test]
fn mit_command_and_reply_over_a_socketpair() {
    let (host, drive) = pair();
    let r = MitRanges::MINI_CHEETAH;
    let emulator = std::thread::spawn(move || {
        // Reply with p = t_ff/2, v = −t_ff, i = t_ff (so the host can check the mapping).
        for _ in 0..20 {
            let f = recv(&drive);
            assert_eq!(f.id, 0x141);
            let MitRx::Command(c) = mit::decode_command(&f, &r).unwrap() else {
                panic!("special frame")
            };
            let rep = MitReply {
                motor_id: 0x41,
                p_rad: c.t_ff_nm / 2.0,
                v_rad_s: -c.t_ff_nm,
                i_a: c.t_ff_nm,
            };
            send(&drive, mit::encode_reply(0x001, &rep, &r).unwrap().0);
        }
    });
    let steps = r.steps();
    for k in 0..20 {
        let t = -9.0 + k as f64 * 0.9;
        let (f, sat) = mit::encode_command(0x141, &MitCommand::torque(t), &r).unwrap();
        assert!(!sat.any());
        send(&host, f);
        let g = recv(&host);
        assert_eq!(g.id, 0x001);
        let rep = mit::decode_reply(&g, &r).unwrap();
        assert_eq!(rep.motor_id, 0x41);
        // t went through two quantisations (command, reply).
        let tol = steps[4] / 2.0 + steps[5] / 2.0 + 1e-9;
        assert!((rep.i_a - t).abs() <= tol, "{} vs {t}", rep.i_a);
        assert!((rep.p_rad - t / 2.0).abs() <= steps[4] / 4.0 + steps[0] / 2.0 + 1e-9);
    }
    emulator.join().unwrap();
}

#[test]
fn odrive_frames_over_a_socketpair() {
    let (host, drive) = pair();
    let msgs = [
        OdriveMsg::SetAxisState {
            requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
        },
        OdriveMsg::SetControllerMode {
            control_mode: odrive::CONTROL_MODE_TORQUE,
            input_mode: odrive::INPUT_MODE_PASSTHROUGH,
        },
        OdriveMsg::SetInputTorque { torque_nm: -0.375 },
        OdriveMsg::Request {
            cmd: odrive::cmd::GET_IQ,
        },
        OdriveMsg::Estop,
    ];
    for m in msgs {
        send(&host, odrive::encode(7, &m).unwrap());
        assert_eq!(odrive::decode(&recv(&drive)).unwrap(), (7, m));
    }
    let fb = OdriveMsg::EncoderEstimates {
        pos_rev: 12.25,
        vel_rev_s: -3.5,
    };
    send(&drive, odrive::encode(7, &fb).unwrap());
    assert_eq!(odrive::decode(&recv(&host)).unwrap(), (7, fb));
}
