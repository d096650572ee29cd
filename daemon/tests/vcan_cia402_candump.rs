//! A candump record / replay of a CiA 402 session on a real kernel vcan (`#[ignore]`d on the host;
//! run in the CAN VM by `tests/canvm/run.sh`): `frictiond` (`protocol = "cia402"`) drives the
//! emulated drive of `frictl sim serve --backend can --protocol cia402` while
//! `frictionless_canlog::record` writes every frame of vcan0 to a candump log. The log is then
//! - decoded: the start-up SDO writes (CST, the TPDO2 mapping), the statusword states of TPDO1
//!   (switch on disabled → ready → switched on → operation enabled, then the quick stop), torque in
//!   RPDO1 only while enabled, NMT start first and NMT stop last;
//! - replayed whole onto vcan1: the same frames arrive in the same order;
//! - replayed master side only (NMT, SYNC, SDO requests, RPDO1) into a fresh emulated drive on vcan0:
//!   its TPDO1 statuswords go through the same state sequence as in the recorded session.

use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::can_support::{LogTail, cia402_knee_body, start_daemon, write_can_config};
use crate::daemon_support::{Plant, TestEnv, frictl_path};
use frictionless_canlog::{self as canlog, LogEntry, LogFrame};
use frictionless_drives::can::WireFrame;
use frictionless_drives::can::cia402::{self as co, DriveState, SdoAddr, SdoRequest};
use frictionless_shm_types::{FLAG_FAULT, FLAG_STALE, TorqueRequest};
use socketcan::{CanSocket, Socket, SocketOptions};

const T: Duration = Duration::from_secs(60);

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn serve() -> Killed {
    Killed(
        Command::new(frictl_path())
            .args(["sim", "serve", "--backend", "can", "--protocol", "cia402"])
            .args(["--bus", "vcan0", "--preset", "knee", "--node-ids", "1"])
            .args(["--initial-pose-rad", "0", "--duration-s", "100"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn frictl sim serve"),
    )
}

fn classic(entries: &[LogEntry]) -> Vec<WireFrame> {
    entries
        .iter()
        .map(|e| match &e.frame {
            LogFrame::Can { frame, .. } => *frame,
            LogFrame::Fd(_) => panic!("FD frame in a classic session"),
        })
        .collect()
}

/// The states TPDO1 (0x181: statusword, position, torque) reports, consecutive repeats removed.
fn states(frames: &[WireFrame]) -> Vec<DriveState> {
    let mut out: Vec<DriveState> = Vec::new();
    for f in frames.iter().filter(|f| f.id == 0x181 && f.len == 8) {
        let sw = u16::from_le_bytes([f.data[0], f.data[1]]);
        if let Some(s) = co::decode_statusword(sw)
            && out.last() != Some(&s)
        {
            out.push(s);
        }
    }
    out
}

/// Records vcan0 in a thread until the returned flag is set.
fn recorder() -> (Arc<AtomicBool>, std::thread::JoinHandle<Vec<u8>>) {
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let h = std::thread::spawn(move || {
        let mut out = Vec::new();
        canlog::record(
            "vcan0",
            &mut out,
            0,
            Some(Duration::from_secs(120)),
            &|| s2.load(Ordering::Relaxed),
        )
        .expect("record vcan0");
        out
    });
    (stop, h)
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_cia402_candump_record_and_replay_of_a_frictiond_session() {
    let env = TestEnv::new("vcancodump");
    let cfg = write_can_config(&env, &cia402_knee_body(1000));
    let (rec_stop, rec) = recorder();
    std::thread::sleep(Duration::from_millis(200));
    // frictiond waits for the drive's boot-up; the drive boots at its first tick.
    let mut d = start_daemon(&cfg, None, &[]);
    let tail = LogTail::take(&mut d);
    let drive = serve();
    let mut plant = Plant::open(&env.ipc, "controller");
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 1;
    rq.enable_mask = 1;
    let t0 = Instant::now();
    let mut good = 0;
    let mut last = None;
    // Drive until the joint ran 50 commands with a current and no fault (in the VM the test process
    // is not always scheduled in time: commands for a stale request, 0 A, are not counted).
    while good < 50 {
        plant.seq += 1;
        rq.seq = plant.seq;
        rq.stamp_ns = frictionless_shm_types::monotonic_ns();
        rq.tau_des_nm[0] = 10.0 * (t0.elapsed().as_secs_f64() * 3.0).sin();
        if plant.ipc.daemon_status().unwrap().publisher_count() > 0 {
            plant.request.publish(&rq).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
        if let Some(c) = plant.cmd.latest().unwrap() {
            if c.valid_mask == 1
                && c.flags[0] & (FLAG_FAULT | FLAG_STALE) == 0
                && c.i_ref_a[0] != 0.0
            {
                good += 1;
            }
            last = Some((c.valid_mask, c.flags[0], c.i_ref_a[0]));
        }
        assert!(
            t0.elapsed() < 2 * T,
            "the session did not run within {:?} ({good} good commands; last valid mask, \
             flags, current: {last:?}; status: {:?}):\n{}",
            2 * T,
            plant.status.latest().unwrap().map(|s| (
                s.ticks,
                s.bus.stale_feedback_mask,
                s.joint_flags[0]
            )),
            tail.text()
        );
    }
    d.signal(libc::SIGTERM);
    let (st, _) = d.wait_exit(T);
    let log = tail.finish();
    assert!(st.success(), "{log}");
    std::thread::sleep(Duration::from_millis(200));
    drop(drive);
    rec_stop.store(true, Ordering::Relaxed);
    let text = rec.join().unwrap();
    let entries = canlog::parse_log(std::io::Cursor::new(&text), "<recorded>").unwrap();
    let frames = classic(&entries);

    // 1. What the log says about the session.
    let sdo_writes: Vec<(SdoAddr, u32)> = frames
        .iter()
        .filter(|f| f.id == 0x601)
        .filter_map(|f| match co::decode_sdo_request(f).ok()?.1 {
            SdoRequest::Download { addr, data, .. } => Some((addr, u32::from_le_bytes(data))),
            _ => None,
        })
        .collect();
    assert!(
        sdo_writes.contains(&(SdoAddr::new(0x6060, 0), 10)),
        "CST: {sdo_writes:x?}"
    );
    assert!(
        sdo_writes.contains(&(SdoAddr::new(0x1A01, 2), 0x60E4_0120)),
        "joint encoder in TPDO2: {sdo_writes:x?}"
    );
    let recorded = states(&frames);
    let seq = [
        DriveState::SwitchOnDisabled,
        DriveState::ReadyToSwitchOn,
        DriveState::SwitchedOn,
        DriveState::OperationEnabled,
    ];
    assert!(recorded.starts_with(&seq), "{recorded:?}");
    assert!(
        recorded.len() > seq.len() && recorded.last() != Some(&DriveState::OperationEnabled),
        "the quick stop at exit left operation enabled: {recorded:?}"
    );
    let nmt: Vec<[u8; 2]> = frames
        .iter()
        .filter(|f| f.id == 0 && f.len == 2)
        .map(|f| [f.data[0], f.data[1]])
        .collect();
    assert_eq!(nmt.last(), Some(&[0x02, 0x01]), "NMT stop last: {nmt:x?}");
    assert!(nmt.contains(&[0x01, 0x01]), "NMT start: {nmt:x?}");
    let torques: Vec<i16> = frames
        .iter()
        .filter(|f| f.id == 0x201 && f.len == 4)
        .map(|f| i16::from_le_bytes([f.data[2], f.data[3]]))
        .collect();
    assert!(torques.iter().any(|&t| t != 0), "torque was commanded");
    assert_eq!(torques.last(), Some(&0), "0 torque at the end");
    let syncs = frames.iter().filter(|f| f.id == 0x080).count();
    assert!(syncs >= 50, "{syncs} SYNCs");

    // 2. The whole log onto vcan1: the same frames, in order (read while the replay runs).
    let cap = CanSocket::open("vcan1").unwrap();
    let _ = cap.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 16 << 20);
    let want = frames.len();
    let capture = std::thread::spawn(move || {
        let mut got = Vec::with_capacity(want);
        while got.len() < want {
            match cap.read_frame_timeout(Duration::from_secs(5)) {
                Ok(f) => got.push(WireFrame::try_from(&f).unwrap()),
                Err(_) => break,
            }
        }
        got
    });
    // At 4× the recorded pace (the comparison is of frames and order).
    let n = canlog::replay_to_iface(&entries, Some("vcan1"), 4.0, 1).unwrap();
    assert_eq!(n as usize, entries.len());
    let got = capture.join().unwrap();
    assert_eq!(got.len(), frames.len(), "replayed frames that arrived");
    assert!(got == frames, "the replay differs from the recording");

    // 3. The master's frames into a fresh drive: the same state sequence.
    let sniff = CanSocket::open("vcan0").unwrap();
    let _ = sniff.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 16 << 20);
    let drive = serve();
    let t0 = Instant::now();
    loop {
        let f = sniff
            .read_frame_timeout(T)
            .expect("the fresh drive's boot-up");
        let w = WireFrame::try_from(&f).unwrap();
        if w.id == 0x701 && w.len == 1 && w.data[0] == 0 {
            break;
        }
        assert!(t0.elapsed() < T, "no boot-up");
    }
    let master: Vec<LogEntry> = entries
        .iter()
        .filter(|e| {
            matches!(&e.frame, LogFrame::Can { frame, .. }
                if matches!(frame.id, 0x000 | 0x080 | 0x201 | 0x601))
        })
        .cloned()
        .collect();
    let sniffer_stop = Arc::new(AtomicBool::new(false));
    let s2 = sniffer_stop.clone();
    let sniffer = std::thread::spawn(move || {
        let mut seen = Vec::new();
        while !s2.load(Ordering::Relaxed) {
            if let Ok(f) = sniff.read_frame_timeout(Duration::from_millis(50))
                && let Ok(w) = WireFrame::try_from(&f)
            {
                seen.push(w);
            }
        }
        seen
    });
    // At 2× the recorded pace: the drive acts on the order of the frames (RPDO before SYNC).
    canlog::replay_to_iface(&master, Some("vcan0"), 2.0, 1).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    sniffer_stop.store(true, Ordering::Relaxed);
    let seen = sniffer.join().unwrap();
    drop(drive);
    let replayed = states(&seen);
    assert_eq!(replayed, recorded, "state sequence of the replay");
}
