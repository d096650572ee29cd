//! The virtual joints as CAN motor drives (`frictionless_plant::can`), driven by a test-process "daemon"
//! on a raw CAN socket.
//!
//! - `socketpair_*` (host): the real serve loop over one end of a `socketpair(AF_UNIX, SOCK_SEQPACKET)`
//!   wrapped as a `socketcan::CanSocket` (no kernel CAN needed).
//! - `vcan_*` (ignored on the host; run in the VM by `tests/canvm/run.sh`): the same scenarios on a real
//!   kernel vcan0, a command timeout, a candump-log record/replay, and the per-tick CAN I/O bench
//!   (`vcan_bench_can_io`, prints `bench:` lines, asserts nothing about speed).
//!
//! The "daemon" sends pure torque commands (MIT kp = kd = 0, ODrive Set_Input_Torque) at 1 kHz; the
//! checks are physical: the motor turns in the direction of the commanded motor torque, the reported
//! current is the torque divided by k_t, an idle drive reports no current.

use std::collections::HashMap;
use std::os::fd::{FromRawFd, OwnedFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::mit::{self, MitCommand, MitRanges, MitSpecial};
use frictionless_drives::can::odrive::{self, OdriveMsg};
use frictionless_plant::build_robot;
use frictionless_plant::can::{
    AXIS_ERROR_WATCHDOG_TIMER_EXPIRED, CanServeOptions, CanServeStats, MIT_HOST_ID, Protocol,
    mit_ranges, run_with_stats, serve_socket,
};
use frictionless_sim::PlantParams;
use socketcan::{CanFilter, CanFrame, CanSocket, Socket, SocketOptions};

/// Where the emulator runs.
#[derive(Clone, Copy)]
enum Link {
    /// A socketpair (host).
    Pair,
    /// A vcan interface (VM).
    Vcan(&'static str),
}

struct Emulator {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<CanServeStats, frictionless_plant::ServeError>>>,
}

impl Emulator {
    fn finish(mut self) -> CanServeStats {
        self.stop.store(true, Ordering::Relaxed);
        self.handle
            .take()
            .unwrap()
            .join()
            .expect("emulator thread panicked")
            .expect("emulator failed")
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

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

fn params(preset: &str) -> PlantParams {
    PlantParams::preset(preset).unwrap()
}

/// Starts the drives for `presets` and returns the "daemon" socket (non-blocking).
fn start(
    link: Link,
    presets: &str,
    protocol: Protocol,
    node_ids: &[u8],
    command_timeout_ms: u64,
) -> (CanSocket, Emulator) {
    let mut joints = build_robot(presets, None, &[], 7).unwrap();
    let opts = CanServeOptions {
        bus: match link {
            Link::Pair => "socketpair".into(),
            Link::Vcan(i) => i.into(),
        },
        protocol,
        node_ids: node_ids.to_vec(),
        command_timeout_ms,
        duration_s: Some(60.0),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let (host, handle) = match link {
        Link::Pair => {
            let (host, drive) = pair();
            let h = std::thread::spawn(move || serve_socket(&mut joints, &opts, &drive, &stop2));
            (host, h)
        }
        Link::Vcan(iface) => {
            let host = CanSocket::open(iface).unwrap();
            let filters: Vec<CanFilter> = match protocol {
                Protocol::Mit => vec![CanFilter::new(MIT_HOST_ID, 0x7FF)],
                Protocol::Odrive => node_ids
                    .iter()
                    .map(|&n| CanFilter::new(u32::from(n) << 5, 0x7E0))
                    .collect(),
                Protocol::Cia402 => panic!("this harness speaks MIT and ODrive only"),
            };
            host.set_filters(&filters).unwrap();
            let _ = host.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 4 << 20);
            let h = std::thread::spawn(move || run_with_stats(&mut joints, &opts, &stop2));
            (host, h)
        }
    };
    host.set_nonblocking(true).unwrap();
    (
        host,
        Emulator {
            stop,
            handle: Some(handle),
        },
    )
}

fn send(s: &CanSocket, f: WireFrame) {
    let cf = CanFrame::try_from(f).unwrap();
    // Pacing is the caller's job; a full queue here would be a test-setup problem, so insist.
    s.write_frame_insist(&cf).unwrap();
}

/// Every frame pending on the (non-blocking) socket.
fn drain(s: &CanSocket, out: &mut Vec<WireFrame>) {
    loop {
        match s.read_frame() {
            Ok(f) => {
                if let Ok(w) = WireFrame::try_from(&f) {
                    out.push(w);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => panic!("read: {e}"),
        }
    }
}

/// Sleeps until `t` (absolute deadline).
fn sleep_until(t: Instant) {
    let now = Instant::now();
    if t > now {
        std::thread::sleep(t - now);
    }
}

/// MIT: enter motor mode on every node (repeated until each answered: the emulator may still be
/// opening its socket).
fn mit_enter(host: &CanSocket, nodes: &[u8]) {
    let t0 = Instant::now();
    let mut answered: Vec<bool> = vec![false; nodes.len()];
    let mut got = Vec::new();
    while !answered.iter().all(|&a| a) {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no MIT reply to enter-motor-mode"
        );
        for (k, &n) in nodes.iter().enumerate() {
            if !answered[k] {
                send(
                    host,
                    mit::encode_special(u32::from(n), MitSpecial::EnterMotorMode).unwrap(),
                );
            }
        }
        std::thread::sleep(Duration::from_millis(20));
        got.clear();
        drain(host, &mut got);
        for f in &got {
            if let Some(k) = nodes.iter().position(|&n| f.len >= 1 && f.data[0] == n) {
                answered[k] = true;
            }
        }
    }
}

/// One MIT session: `torques_nm[k]` to node k for `ms` ticks at 1 kHz; returns the decoded replies
/// per node in arrival order.
fn mit_session(
    host: &CanSocket,
    nodes: &[u8],
    ranges: &[MitRanges],
    torques_nm: &[f64],
    ms: u32,
) -> Vec<Vec<mit::MitReply>> {
    let mut replies = vec![Vec::new(); nodes.len()];
    let mut buf = Vec::new();
    let t0 = Instant::now();
    for k in 0..ms {
        for ((&n, r), &t) in nodes.iter().zip(ranges).zip(torques_nm) {
            send(
                host,
                mit::encode_command(u32::from(n), &MitCommand::torque(t), r)
                    .unwrap()
                    .0,
            );
        }
        buf.clear();
        drain(host, &mut buf);
        collect_mit(&buf, nodes, ranges, &mut replies);
        sleep_until(t0 + Duration::from_millis(u64::from(k) + 1));
    }
    // Late replies.
    std::thread::sleep(Duration::from_millis(50));
    buf.clear();
    drain(host, &mut buf);
    collect_mit(&buf, nodes, ranges, &mut replies);
    replies
}

fn collect_mit(
    frames: &[WireFrame],
    nodes: &[u8],
    ranges: &[MitRanges],
    replies: &mut [Vec<mit::MitReply>],
) {
    for f in frames {
        assert_eq!(f.id, MIT_HOST_ID, "unexpected frame {f:?}");
        let node = f.data[0];
        let k = nodes
            .iter()
            .position(|&n| n == node)
            .expect("reply from a known node");
        replies[k].push(mit::decode_reply(f, &ranges[k]).unwrap());
    }
}

fn mean(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    s / n as f64
}

/// Knee (node 1) gets +0.25 motor Nm, ankle roll (node 2) −0.05 motor Nm: each motor turns and
/// reports the current τ/k_t.
fn mit_torque_scenario(link: Link) {
    let nodes = [1u8, 2];
    let (knee, ankle) = (params("knee"), params("ankle_roll"));
    let ranges = [mit_ranges(&knee), mit_ranges(&ankle)];
    let torques = [0.25, -0.05];
    let (host, emu) = start(link, "knee,ankle_roll", Protocol::Mit, &nodes, 500);
    mit_enter(&host, &nodes);
    let replies = mit_session(&host, &nodes, &ranges, &torques, 200);
    let stats = emu.finish();
    for (k, (rep, p)) in replies.iter().zip([&knee, &ankle]).enumerate() {
        assert!(
            rep.len() >= 150,
            "node {}: {} replies to 200 commands",
            nodes[k],
            rep.len()
        );
        let sign = torques[k].signum();
        let dp = rep.last().unwrap().p_rad - rep[0].p_rad;
        let v_end = mean(rep[rep.len() - 20..].iter().map(|r| r.v_rad_s));
        let i_end = mean(rep[rep.len() - 20..].iter().map(|r| r.i_a));
        let i_want = torques[k] / p.kt_nm_per_a;
        assert!(
            dp * sign > 1.0,
            "node {}: motor moved {dp} rad for torque {}",
            nodes[k],
            torques[k]
        );
        assert!(
            v_end * sign > 0.0,
            "node {}: end velocity {v_end}",
            nodes[k]
        );
        assert!(
            (i_end - i_want).abs() < 0.05,
            "node {}: current {i_end} A, want {i_want} A",
            nodes[k]
        );
        // Joint side: s = θ/r moves opposite to θ for the negative gear ratios.
        let ds = dp / p.gear_ratio_signed;
        assert!(ds * sign * p.gear_ratio_signed.signum() > 0.0);
    }
    assert_eq!(stats.rx_decode_errors, 0);
    assert!(stats.tx_frames >= stats.rx_frames - 2, "{stats:?}");
}

/// ODrive: both axes to torque control + closed loop, then Set_Input_Torque at 1 kHz; the cyclic
/// encoder estimates show the motion, Get_Iq the current, the heartbeat the closed-loop state.
fn odrive_torque_scenario(link: Link) {
    let nodes = [3u8, 4];
    let (knee, ankle) = (params("knee"), params("ankle_roll"));
    let torques = [0.25f32, -0.05];
    let (host, emu) = start(link, "knee,ankle_roll", Protocol::Odrive, &nodes, 500);
    let mut buf = Vec::new();
    // Wait for the cyclic stream (the emulator is up).
    let t0 = Instant::now();
    while buf.is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no ODrive cyclic frames"
        );
        std::thread::sleep(Duration::from_millis(10));
        drain(&host, &mut buf);
    }
    for &n in &nodes {
        send(
            &host,
            odrive::encode(
                n,
                &OdriveMsg::SetControllerMode {
                    control_mode: odrive::CONTROL_MODE_TORQUE,
                    input_mode: odrive::INPUT_MODE_PASSTHROUGH,
                },
            )
            .unwrap(),
        );
        send(
            &host,
            odrive::encode(
                n,
                &OdriveMsg::SetAxisState {
                    requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
                },
            )
            .unwrap(),
        );
    }
    buf.clear();
    let t0 = Instant::now();
    for k in 0..250u64 {
        for (&n, &t) in nodes.iter().zip(&torques) {
            send(
                &host,
                odrive::encode(n, &OdriveMsg::SetInputTorque { torque_nm: t }).unwrap(),
            );
        }
        drain(&host, &mut buf);
        sleep_until(t0 + Duration::from_millis(k + 1));
    }
    drain(&host, &mut buf);
    // RTR request for the heartbeat is answered too.
    send(
        &host,
        odrive::encode(
            nodes[0],
            &OdriveMsg::Request {
                cmd: odrive::cmd::HEARTBEAT,
            },
        )
        .unwrap(),
    );
    std::thread::sleep(Duration::from_millis(50));
    drain(&host, &mut buf);
    let stats = emu.finish();
    let mut enc: HashMap<u8, Vec<(f32, f32)>> = HashMap::new();
    let mut iq: HashMap<u8, Vec<f32>> = HashMap::new();
    let mut hb: HashMap<u8, Vec<u8>> = HashMap::new();
    for f in &buf {
        match odrive::decode(f).unwrap() {
            (n, OdriveMsg::EncoderEstimates { pos_rev, vel_rev_s }) => {
                enc.entry(n).or_default().push((pos_rev, vel_rev_s))
            }
            (n, OdriveMsg::Iq { iq_measured_a, .. }) => {
                iq.entry(n).or_default().push(iq_measured_a)
            }
            (n, OdriveMsg::Heartbeat { axis_state, .. }) => {
                hb.entry(n).or_default().push(axis_state)
            }
            other => panic!("unexpected {other:?}"),
        }
    }
    for (k, (&n, p)) in nodes.iter().zip([&knee, &ankle]).enumerate() {
        let e = &enc[&n];
        assert!(e.len() >= 150, "node {n}: {} encoder frames", e.len());
        let sign = f64::from(torques[k]).signum();
        let dpos_rad = f64::from(e.last().unwrap().0 - e[0].0) * std::f64::consts::TAU;
        assert!(dpos_rad * sign > 1.0, "node {n}: moved {dpos_rad} rad");
        let v_end = mean(e[e.len() - 20..].iter().map(|x| f64::from(x.1)));
        assert!(v_end * sign > 0.0, "node {n}: end velocity {v_end} rev/s");
        let q = &iq[&n];
        let i_end = mean(q[q.len() - 20..].iter().map(|&x| f64::from(x)));
        let i_want = f64::from(torques[k]) / p.kt_nm_per_a;
        assert!(
            (i_end - i_want).abs() < 0.05,
            "node {n}: Iq {i_end} A, want {i_want} A"
        );
    }
    let h = &hb[&nodes[0]];
    assert_eq!(
        *h.last().unwrap(),
        odrive::AXIS_STATE_CLOSED_LOOP_CONTROL as u8,
        "heartbeats {h:?}"
    );
    assert_eq!(stats.rx_decode_errors, 0);
}

/// MIT with a 50 ms timeout: commands → current; silence → the drive idles (0 A, commands answered
/// but not applied); enter-motor-mode → current again.
fn mit_timeout_scenario(link: Link) {
    let nodes = [1u8];
    let knee = params("knee");
    let ranges = [mit_ranges(&knee)];
    let i_want = 0.25 / knee.kt_nm_per_a;
    let (host, emu) = start(link, "knee", Protocol::Mit, &nodes, 50);
    mit_enter(&host, &nodes);
    let on = mit_session(&host, &nodes, &ranges, &[0.25], 30);
    let max_on = on[0].iter().map(|r| r.i_a).fold(f64::MIN, f64::max);
    assert!(
        (max_on - i_want).abs() < 0.1,
        "current {max_on} A while commanded, want {i_want}"
    );
    std::thread::sleep(Duration::from_millis(300));
    let idle = mit_session(&host, &nodes, &ranges, &[0.25], 30);
    assert!(idle[0].len() >= 20);
    for r in &idle[0] {
        assert!(r.i_a.abs() < 0.1, "idle drive reports {} A", r.i_a);
    }
    mit_enter(&host, &nodes);
    let again = mit_session(&host, &nodes, &ranges, &[0.25], 30);
    let max_again = again[0].iter().map(|r| r.i_a).fold(f64::MIN, f64::max);
    assert!(
        (max_again - i_want).abs() < 0.1,
        "current {max_again} A after re-enable"
    );
    let stats = emu.finish();
    assert!(stats.command_timeouts >= 1, "{stats:?}");
}

#[test]
fn socketpair_mit_torque_moves_the_joints() {
    mit_torque_scenario(Link::Pair);
}

#[test]
fn socketpair_odrive_torque_moves_the_joints() {
    odrive_torque_scenario(Link::Pair);
}

#[test]
fn socketpair_mit_command_timeout_idles_the_drive() {
    mit_timeout_scenario(Link::Pair);
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_mit_torque_moves_the_joints() {
    mit_torque_scenario(Link::Vcan("vcan0"));
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_odrive_torque_moves_the_joints() {
    odrive_torque_scenario(Link::Vcan("vcan0"));
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_mit_command_timeout_idles_the_drive() {
    mit_timeout_scenario(Link::Vcan("vcan0"));
}

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_odrive_watchdog_idles_the_drive() {
    let nodes = [5u8];
    let knee = params("knee");
    let (host, emu) = start(Link::Vcan("vcan0"), "knee", Protocol::Odrive, &nodes, 50);
    let enc = |m: OdriveMsg| odrive::encode(5, &m).unwrap();
    let mut buf = Vec::new();
    let t0 = Instant::now();
    while buf.is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no ODrive cyclic frames"
        );
        std::thread::sleep(Duration::from_millis(10));
        drain(&host, &mut buf);
    }
    send(
        &host,
        enc(OdriveMsg::SetControllerMode {
            control_mode: odrive::CONTROL_MODE_TORQUE,
            input_mode: odrive::INPUT_MODE_PASSTHROUGH,
        }),
    );
    let closed_loop = enc(OdriveMsg::SetAxisState {
        requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
    });
    send(&host, closed_loop);
    // Beyond the one timeout the silence below causes, a stalled machine (the CAN VM runs under TCG)
    // can starve the watchdog while commands are meant to flow: every gap between two commands, or
    // between the last command and `finish`, longer than half the 50 ms watchdog may add one.
    let mut stalls = 0u64;
    let mut last_cmd = Instant::now();
    let mut paced = |last_cmd: &mut Instant| {
        if last_cmd.elapsed() > Duration::from_millis(25) {
            stalls += 1;
        }
        *last_cmd = Instant::now();
    };
    let torque = enc(OdriveMsg::SetInputTorque { torque_nm: 0.25 });
    for _ in 0..30 {
        paced(&mut last_cmd);
        send(&host, torque);
        std::thread::sleep(Duration::from_millis(1));
    }
    // Silence for 300 ms (> the 50 ms watchdog), then ask for the heartbeat.
    std::thread::sleep(Duration::from_millis(300));
    buf.clear();
    drain(&host, &mut buf);
    send(
        &host,
        enc(OdriveMsg::Request {
            cmd: odrive::cmd::HEARTBEAT,
        }),
    );
    std::thread::sleep(Duration::from_millis(50));
    let mut after = Vec::new();
    drain(&host, &mut after);
    let hb = after
        .iter()
        .filter_map(|f| match odrive::decode(f).unwrap().1 {
            OdriveMsg::Heartbeat {
                axis_error,
                axis_state,
                ..
            } => Some((axis_error, axis_state)),
            _ => None,
        })
        .next_back()
        .expect("heartbeat answered");
    assert_eq!(
        hb.0 & AXIS_ERROR_WATCHDOG_TIMER_EXPIRED,
        AXIS_ERROR_WATCHDOG_TIMER_EXPIRED
    );
    assert_eq!(u32::from(hb.1), odrive::AXIS_STATE_IDLE);
    let iq_idle: Vec<f32> = buf
        .iter()
        .chain(&after)
        .rev()
        .take(40)
        .filter_map(|f| match odrive::decode(f).unwrap().1 {
            OdriveMsg::Iq { iq_setpoint_a, .. } => Some(iq_setpoint_a),
            _ => None,
        })
        .collect();
    assert!(
        !iq_idle.is_empty() && iq_idle.iter().all(|&i| i == 0.0),
        "{iq_idle:?}"
    );
    // Re-enable: current flows again.
    send(&host, closed_loop);
    last_cmd = Instant::now();
    after.clear();
    for _ in 0..30 {
        paced(&mut last_cmd);
        send(&host, torque);
        std::thread::sleep(Duration::from_millis(1));
        drain(&host, &mut after);
    }
    std::thread::sleep(Duration::from_millis(20));
    drain(&host, &mut after);
    let i_want = 0.25f64 / knee.kt_nm_per_a;
    let i_max = after
        .iter()
        .filter_map(|f| match odrive::decode(f).unwrap().1 {
            OdriveMsg::Iq { iq_setpoint_a, .. } => Some(f64::from(iq_setpoint_a)),
            _ => None,
        })
        .fold(f64::MIN, f64::max);
    assert!(
        (i_max - i_want).abs() < 1e-3,
        "Iq setpoint {i_max} after re-enable, want {i_want}"
    );
    paced(&mut last_cmd);
    let stats = emu.finish();
    assert!(
        (1..=1 + stalls).contains(&stats.command_timeouts),
        "{} command timeouts: want the silence's one, plus at most {stalls} from stalls; {stats:?}",
        stats.command_timeouts
    );
}

/// Records a MIT session on vcan0 with `frictionless_canlog::record`, then replays the log onto vcan1
/// and checks the frames arrive identical and in order; finally replays only the commands into a
/// fresh emulator on vcan0, which answers every one.
#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_candump_record_replay_reproduces_the_session() {
    use frictionless_canlog::{self as canlog, LogFrame};
    let nodes = [1u8];
    let knee = params("knee");
    let ranges = [mit_ranges(&knee)];
    let (host, emu) = start(Link::Vcan("vcan0"), "knee", Protocol::Mit, &nodes, 500);
    mit_enter(&host, &nodes);
    // Recorder.
    let rec_stop = Arc::new(AtomicBool::new(false));
    let rs = rec_stop.clone();
    let recorder = std::thread::spawn(move || {
        let mut out = Vec::new();
        canlog::record("vcan0", &mut out, 0, Some(Duration::from_secs(30)), &|| {
            rs.load(Ordering::Relaxed)
        })
        .unwrap();
        out
    });
    std::thread::sleep(Duration::from_millis(200));
    let torques: Vec<f64> = (0..100).map(|k| 0.3 * ((k as f64) * 0.1).sin()).collect();
    let t0 = Instant::now();
    for (k, &t) in torques.iter().enumerate() {
        let f = mit::encode_command(1, &MitCommand::torque(t), &ranges[0])
            .unwrap()
            .0;
        send(&host, f);
        sleep_until(t0 + Duration::from_millis(k as u64 + 1));
    }
    std::thread::sleep(Duration::from_millis(200));
    rec_stop.store(true, Ordering::Relaxed);
    let log = recorder.join().unwrap();
    drop(emu);
    let entries = canlog::parse_log(std::io::Cursor::new(&log), "<recorded>").unwrap();
    let frames: Vec<WireFrame> = entries
        .iter()
        .map(|e| match &e.frame {
            LogFrame::Can { frame, .. } => *frame,
            LogFrame::Fd(_) => panic!("FD frame in a classic session"),
        })
        .collect();
    let cmds: Vec<&WireFrame> = frames.iter().filter(|f| f.id == 1).collect();
    let reps: Vec<&WireFrame> = frames.iter().filter(|f| f.id == MIT_HOST_ID).collect();
    assert_eq!(cmds.len(), 100, "recorded commands");
    for (f, &t) in cmds.iter().zip(&torques) {
        let mit::MitRx::Command(c) = mit::decode_command(f, &ranges[0]).unwrap() else {
            panic!("special frame recorded")
        };
        assert!((c.t_ff_nm - t).abs() <= ranges[0].steps()[4]);
    }
    assert_eq!(reps.len(), 100, "recorded replies");
    // Replay onto vcan1: identical frames, identical order.
    let cap = CanSocket::open("vcan1").unwrap();
    let _ = cap.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 4 << 20);
    let n = canlog::replay_to_iface(&entries, Some("vcan1"), 1.0, 1).unwrap();
    assert_eq!(n as usize, entries.len());
    let mut got = Vec::new();
    while got.len() < frames.len() {
        match cap.read_frame_timeout(Duration::from_secs(2)) {
            Ok(f) => got.push(WireFrame::try_from(&f).unwrap()),
            Err(e) => panic!(
                "replayed frame {} of {} missing: {e}",
                got.len(),
                frames.len()
            ),
        }
    }
    assert_eq!(got, frames);
    // Replay only the commands (plus an enter frame) into a fresh emulator: every one is answered.
    let (host, emu) = start(Link::Vcan("vcan0"), "knee", Protocol::Mit, &nodes, 500);
    mit_enter(&host, &nodes);
    let mut cmd_entries: Vec<canlog::LogEntry> = entries
        .iter()
        .filter(|e| matches!(&e.frame, LogFrame::Can { frame, .. } if frame.id == 1))
        .cloned()
        .collect();
    for e in &mut cmd_entries {
        e.iface = "vcan0".into();
    }
    let mut buf = Vec::new();
    drain(&host, &mut buf);
    buf.clear();
    canlog::replay_to_iface(&cmd_entries, None, 1.0, 1).unwrap();
    std::thread::sleep(Duration::from_millis(100));
    drain(&host, &mut buf);
    assert_eq!(buf.len(), 100, "replies to the replayed commands");
    let stats = emu.finish();
    assert_eq!(stats.rx_decode_errors, 0);
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Per-tick CAN I/O of a daemon with 4 joints on one bus: send 4 commands and drain the pending
/// replies, non-blocking (the emulator runs in this process). Prints `bench:` lines; no asserts on
/// speed.
#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_bench_can_io() {
    for protocol in [Protocol::Mit, Protocol::Odrive] {
        let nodes = [1u8, 2, 3, 4];
        let presets = "knee,ankle_roll,knee,ankle_roll";
        let ranges: Vec<MitRanges> = presets.split(',').map(|p| mit_ranges(&params(p))).collect();
        let (host, emu) = start(Link::Vcan("vcan0"), presets, protocol, &nodes, 500);
        let mut buf = Vec::with_capacity(256);
        match protocol {
            Protocol::Cia402 => panic!("this harness speaks MIT and ODrive only"),
            Protocol::Mit => mit_enter(&host, &nodes),
            Protocol::Odrive => {
                for &n in &nodes {
                    send(
                        &host,
                        odrive::encode(
                            n,
                            &OdriveMsg::SetControllerMode {
                                control_mode: odrive::CONTROL_MODE_TORQUE,
                                input_mode: odrive::INPUT_MODE_PASSTHROUGH,
                            },
                        )
                        .unwrap(),
                    );
                    send(
                        &host,
                        odrive::encode(
                            n,
                            &OdriveMsg::SetAxisState {
                                requested_state: odrive::AXIS_STATE_CLOSED_LOOP_CONTROL,
                            },
                        )
                        .unwrap(),
                    );
                }
            }
        }
        let cmds: Vec<CanFrame> = nodes
            .iter()
            .zip(&ranges)
            .map(|(&n, r)| {
                let f = match protocol {
                    Protocol::Cia402 => panic!("this harness speaks MIT and ODrive only"),
                    Protocol::Mit => {
                        mit::encode_command(u32::from(n), &MitCommand::torque(0.0), r)
                            .unwrap()
                            .0
                    }
                    Protocol::Odrive => {
                        odrive::encode(n, &OdriveMsg::SetInputTorque { torque_nm: 0.0 }).unwrap()
                    }
                };
                CanFrame::try_from(f).unwrap()
            })
            .collect();
        let ticks = 3000u64;
        let mut cost_us = Vec::with_capacity(ticks as usize);
        let (mut sent, mut full, mut received) = (0u64, 0u64, 0u64);
        let t0 = Instant::now();
        for k in 0..ticks {
            let a = Instant::now();
            for c in &cmds {
                match host.write_frame(c) {
                    Ok(()) => sent += 1,
                    Err(_) => full += 1,
                }
            }
            while host.read_frame().is_ok() {
                received += 1;
            }
            cost_us.push(a.elapsed().as_secs_f64() * 1e6);
            sleep_until(t0 + Duration::from_millis(k + 1));
        }
        let wall = t0.elapsed().as_secs_f64();
        drain(&host, &mut buf);
        let stats = emu.finish();
        cost_us.sort_by(f64::total_cmp);
        println!(
            "bench: can_io {:?} 4 joints vcan0: per tick send 4 + drain: p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs ({} ticks in {:.2} s, {} sent, {} refused, {} received)",
            protocol,
            percentile(&cost_us, 0.5),
            percentile(&cost_us, 0.99),
            cost_us.last().unwrap(),
            ticks,
            wall,
            sent,
            full,
            received
        );
        println!(
            "bench: can_io {:?} emulator: {} ticks, {} late, {} skipped, rx {}, tx {}, tx dropped {}",
            protocol,
            stats.ticks,
            stats.late_ticks,
            stats.skipped_ticks,
            stats.rx_frames,
            stats.tx_frames,
            stats.tx_dropped
        );
        assert!(received > 0, "no frames from the emulator");
    }
}

/// The coupled leg (`--preset leg`) as six MIT drives on nodes 1–6: each node answers its own
/// torque commands, reports the current τ/k_t of its joint and its motor turns (every joint is
/// stepped together through the one leg each tick).
#[test]
fn socketpair_mit_leg_six_nodes_answer_and_move() {
    let nodes = [1u8, 2, 3, 4, 5, 6];
    let leg = frictionless_sim::LegParams::preset().unwrap();
    let ranges: Vec<MitRanges> = leg.joints.iter().map(mit_ranges).collect();
    let torques: Vec<f64> = leg
        .joints
        .iter()
        .enumerate()
        .map(|(k, p)| if k % 2 == 0 { 0.4 } else { -0.4 } * p.kt_nm_per_a * p.i_max_a)
        .collect();
    let (host, emu) = start(Link::Pair, "leg", Protocol::Mit, &nodes, 500);
    mit_enter(&host, &nodes);
    let replies = mit_session(&host, &nodes, &ranges, &torques, 200);
    let stats = emu.finish();
    for (k, (rep, p)) in replies.iter().zip(&leg.joints).enumerate() {
        assert!(
            rep.len() >= 150,
            "{}: {} replies to 200 commands",
            p.joint,
            rep.len()
        );
        let dp = rep.last().unwrap().p_rad - rep[0].p_rad;
        let i_end = mean(rep[rep.len() - 20..].iter().map(|r| r.i_a));
        let i_want = torques[k] / p.kt_nm_per_a;
        assert!(dp.abs() > 0.05, "{}: motor moved {dp} rad", p.joint);
        assert!(
            (i_end - i_want).abs() < 0.05 * p.i_max_a,
            "{}: current {i_end} A, want {i_want} A",
            p.joint
        );
    }
    assert_eq!(stats.rx_decode_errors, 0);
}

#[test]
fn bad_options_are_refused_with_the_offending_value() {
    let mut joints = build_robot("knee,ankle_roll", None, &[], 1).unwrap();
    let stop = AtomicBool::new(false);
    let mut opts = CanServeOptions {
        bus: "nosuchcan7".into(),
        protocol: Protocol::Mit,
        node_ids: vec![],
        command_timeout_ms: 20,
        duration_s: Some(0.1),
    };
    let e = anyhow::Error::from(run_with_stats(&mut joints, &opts, &stop).unwrap_err());
    assert!(format!("{e:#}").contains("nosuchcan7"), "{e:#}");
    opts.node_ids = vec![3, 3];
    let e = anyhow::Error::from(run_with_stats(&mut joints, &opts, &stop).unwrap_err());
    assert!(
        format!("{e:#}").contains("node id 3 appears twice"),
        "{e:#}"
    );
    opts.node_ids = vec![3];
    let e = anyhow::Error::from(run_with_stats(&mut joints, &opts, &stop).unwrap_err());
    assert!(format!("{e:#}").contains("1 ids for 2 joints"), "{e:#}");
    opts.node_ids = vec![1, 64];
    opts.protocol = Protocol::Odrive;
    let e = anyhow::Error::from(run_with_stats(&mut joints, &opts, &stop).unwrap_err());
    assert!(format!("{e:#}").contains("64"), "{e:#}");
}

#[test]
fn socketpair_serve_stops_after_the_duration_and_ignores_foreign_ids() {
    let mut joints = build_robot("knee", None, &[], 1).unwrap();
    let opts = CanServeOptions {
        bus: "socketpair".into(),
        protocol: Protocol::Mit,
        node_ids: vec![9],
        command_timeout_ms: 20,
        duration_s: Some(0.2),
    };
    let (host, drive) = pair();
    // A frame for another node and one for ours with a bad length: counted, never answered.
    send(
        &host,
        mit::encode_special(8, MitSpecial::EnterMotorMode).unwrap(),
    );
    send(&host, WireFrame::standard(9, &[1, 2]).unwrap());
    let stop = AtomicBool::new(false);
    let st = serve_socket(&mut joints, &opts, &drive, &stop).unwrap();
    assert_eq!(st.ticks, 200);
    assert_eq!(st.rx_ignored, 1);
    assert_eq!(st.rx_decode_errors, 1);
    assert_eq!(st.tx_frames, 0);
    // The plant advanced 200 ms.
    assert!((joints.measurement(0).time_s - 0.2).abs() < 1e-9);
}
