//! Shared pieces of the `frictiond` CAN-backend tests (`can_backend.rs` on the host over a
//! socketpair, `vcan_daemon.rs` on a real vcan in the CAN VM): the test process emulates MIT drives
//! on a raw `socketcan::CanSocket` (decoding commands and replying with the codecs of
//! `frictionless_drives::can`) and acts as the controller over shared memory, against a spawned
//! `frictiond` with `[backend] kind = "can"`. The scenarios are written once and run over either
//! socket kind.
//!
//! Not a test target itself; `main.rs` includes it with `mod can_support;` (it uses
//! `crate::daemon_support`).

#![allow(dead_code)]

use std::collections::HashMap;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use frictionless_drives::can::WireFrame;
use frictionless_drives::can::mit::{self, MitRanges, MitReply, MitRx, MitSpecial};
use frictionless_shm_types::{FLAG_FAULT, FLAG_STALE, MotorCurrentCommand, TorqueRequest};
use socketcan::{CanFrame, CanSocket, Socket};

use crate::daemon_support::{Daemon, Plant, TestEnv, current_ref, cv_ref, frictiond_bin};

/// Descriptor number the daemon inherits the socketpair end as (`interface = "fd:10"`).
pub const CHILD_FD: i32 = 10;

/// Starts `frictiond --config cfg`; with `inherit = Some(fd)` the child gets `fd` as [`CHILD_FD`].
pub fn start_daemon(cfg: &Path, inherit: Option<&OwnedFd>, envs: &[(&str, &str)]) -> Daemon {
    use std::os::unix::process::CommandExt;
    let mut cmd = Command::new(frictiond_bin());
    cmd.arg("--config")
        .arg(cfg)
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    for (k, v) in envs {
        cmd.env(k, v);
    }
    if let Some(fd) = inherit {
        let raw = fd.as_raw_fd();
        // SAFETY: dup2 is async-signal-safe; it runs in the child between fork and exec and only
        // duplicates a descriptor we own (the copy has FD_CLOEXEC cleared).
        unsafe {
            cmd.pre_exec(move || {
                if libc::dup2(raw, CHILD_FD) < 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    Daemon {
        child: cmd.spawn().expect("spawn frictiond"),
    }
}

/// A socketpair of classic CAN sockets (close-on-exec): (test end, daemon end).
pub fn socketpair() -> (CanSocket, OwnedFd) {
    let mut fds = [0; 2];
    // SAFETY: fds is a valid 2-element array; on success both fds are new and owned by us.
    let rc = unsafe {
        libc::socketpair(
            libc::AF_UNIX,
            libc::SOCK_SEQPACKET | libc::SOCK_CLOEXEC,
            0,
            fds.as_mut_ptr(),
        )
    };
    assert_eq!(rc, 0, "socketpair: {}", std::io::Error::last_os_error());
    // SAFETY: the fds were just created and are not owned elsewhere.
    unsafe {
        (
            CanSocket::from(OwnedFd::from_raw_fd(fds[0])),
            OwnedFd::from_raw_fd(fds[1]),
        )
    }
}

/// Knee (CV friction, r = −100, command in motor torque) and hip (no friction, r = 50, command
/// in amperes) as MIT drives 1 and 2 on one bus; replies on id 0.
pub const KNEE_R: f64 = -100.0;
/// Knee k_t [Nm/A].
pub const KNEE_KT: f64 = 0.157;
/// Hip gear ratio.
pub const HIP_R: f64 = 50.0;
/// Hip k_t [Nm/A].
pub const HIP_KT: f64 = 0.1;
/// Knee CV parameters (kc, ka, kv) and kfc.
pub const KNEE_CV: (f64, f64, f64, f64) = (8.1, 50.84, 5.55, 0.85);
/// Knee t range ±[Nm motor side]; hip ±[A].
pub const T_MAX: [f64; 2] = [1.0, 10.0];

/// The daemon config (without `[backend]`, which [`write_can_config`] adds).
pub fn mit_body(interface: &str, period_us: u64) -> String {
    format!(
        r#"
[loop]
period_us = {period_us}
status_every_ticks = 10
ready_after_ticks = 10

[safety]
stale_after_ticks = 20
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = {KNEE_R}
kt = {KNEE_KT}
max_curr = 5.0
kfc = {kfc}
friction_model = "cv"
kc = {kc}
ka = {ka}
kv = {kv}

[[joint]]
name = "hip"
index = 1
gear_ratio = {HIP_R}
kt = {HIP_KT}
max_curr = 4.0
friction_model = "none"

[[bus]]
interface = "{interface}"
bitrate = 1000000
protocol = "mit"
host_id = 0
feedback_timeout_ticks = 10

[[bus.joint]]
joint = "knee"
node_id = 1
command_unit = "motor_torque"
p_max = 12.5
v_max = 65.0
t_max = {t0}
i_max = 40.0

[[bus.joint]]
joint = "hip"
node_id = 2
command_unit = "current"
p_max = 12.5
v_max = 65.0
t_max = {t1}
i_max = 40.0
"#,
        kc = KNEE_CV.0,
        ka = KNEE_CV.1,
        kv = KNEE_CV.2,
        kfc = KNEE_CV.3,
        t0 = T_MAX[0],
        t1 = T_MAX[1],
    )
}

/// Writes `frictiond.toml` = a CAN `[backend]` for `env` + `body`; returns its path.
pub fn write_can_config(env: &TestEnv, body: &str) -> PathBuf {
    let path = env.dir.join("frictiond.toml");
    let text = format!(
        "[backend]\nkind = \"can\"\nservice_prefix = \"{}\"\nroot_path = \"{}\"\n{body}",
        env.ipc.service_prefix,
        env.ipc.root_path.as_ref().unwrap().display()
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// MIT ranges of drive `id` (1 = knee, 2 = hip).
pub fn ranges(id: u32) -> MitRanges {
    let t = T_MAX[(id as usize) - 1];
    MitRanges {
        p_min_rad: -12.5,
        p_max_rad: 12.5,
        v_min_rad_s: -65.0,
        v_max_rad_s: 65.0,
        kp_min_nm_rad: 0.0,
        kp_max_nm_rad: 500.0,
        kd_min_nm_s_rad: 0.0,
        kd_max_nm_s_rad: 5.0,
        t_min_nm: -t,
        t_max_nm: t,
        i_min_a: -40.0,
        i_max_a: 40.0,
    }
}

/// What a drive sees and how it answers.
#[derive(Debug, Default, Clone)]
pub struct DriveLog {
    /// Commands received (t_ff in the drive's unit).
    pub commands: u64,
    /// Last t_ff.
    pub last_t: f64,
    /// Whether any command had kp or kd ≠ 0.
    pub gains_seen: bool,
    /// Special frames received, in order.
    pub specials: Vec<MitSpecial>,
}

/// State shared between the emulator thread and the test.
#[derive(Debug, Default)]
pub struct EmuState {
    /// Per motor id.
    pub drives: HashMap<u32, DriveLog>,
    /// Motor ids that do not answer.
    pub silent: Vec<u32>,
    /// Reported motor velocity per id [motor rad/s].
    pub v_motor: HashMap<u32, f64>,
    /// Standard data frames seen on ids other than the drives' (1, 2), counted per id.
    pub other_ids: HashMap<u32, u64>,
}

/// MIT drives 1 and 2 emulated on `sock` in a thread: every command is decoded and logged and —
/// unless the motor is silenced — answered (reply id 0) with p = 0.5 rad, the configured v and
/// i = the commanded value.
pub struct MitEmulator {
    /// Shared state.
    pub state: Arc<Mutex<EmuState>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<CanSocket>>,
}

impl MitEmulator {
    /// Starts the emulator on `sock`.
    pub fn start(sock: CanSocket, v_motor: [f64; 2]) -> Self {
        let state = Arc::new(Mutex::new(EmuState::default()));
        {
            let mut s = state.lock().unwrap();
            s.v_motor.insert(1, v_motor[0]);
            s.v_motor.insert(2, v_motor[1]);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let (st, sp) = (state.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            while !sp.load(Ordering::Relaxed) {
                let f = match sock.read_frame_timeout(Duration::from_millis(50)) {
                    Ok(f) => f,
                    Err(_) => continue,
                };
                let Ok(w) = WireFrame::try_from(&f) else {
                    continue;
                };
                if w.extended || w.rtr {
                    continue;
                }
                if !(w.id == 1 || w.id == 2) {
                    *st.lock().unwrap().other_ids.entry(w.id).or_insert(0) += 1;
                    continue;
                }
                let r = ranges(w.id);
                let Ok(rx) = mit::decode_command(&w, &r) else {
                    continue;
                };
                let mut s = st.lock().unwrap();
                let v = s.v_motor[&w.id];
                let silent = s.silent.contains(&w.id);
                let log = s.drives.entry(w.id).or_default();
                let t = match rx {
                    MitRx::Special(x) => {
                        log.specials.push(x);
                        0.0
                    }
                    MitRx::Command(c) => {
                        log.commands += 1;
                        log.last_t = c.t_ff_nm;
                        log.gains_seen |= c.kp_nm_rad != 0.0 || c.kd_nm_s_rad != 0.0;
                        c.t_ff_nm
                    }
                };
                drop(s);
                if !silent {
                    let rep = MitReply {
                        motor_id: w.id as u8,
                        p_rad: 0.5,
                        v_rad_s: v,
                        i_a: t.clamp(-40.0, 40.0),
                    };
                    let (fr, _) = mit::encode_reply(0, &rep, &r).unwrap();
                    // Best effort, as a drive: a full queue drops the reply.
                    let _ = sock.write_frame(&CanFrame::try_from(fr).unwrap());
                }
            }
            sock
        });
        Self {
            state,
            stop,
            thread: Some(thread),
        }
    }

    /// A copy of drive `id`'s log.
    pub fn log(&self, id: u32) -> DriveLog {
        self.state
            .lock()
            .unwrap()
            .drives
            .get(&id)
            .cloned()
            .unwrap_or_default()
    }

    /// How many standard data frames were seen on `id` when it is not a drive's (1, 2).
    pub fn frames_to_other_id(&self, id: u32) -> u64 {
        self.state
            .lock()
            .unwrap()
            .other_ids
            .get(&id)
            .copied()
            .unwrap_or(0)
    }

    /// Silences (or un-silences) motor `id`.
    pub fn set_silent(&self, id: u32, silent: bool) {
        let mut s = self.state.lock().unwrap();
        s.silent.retain(|&x| x != id);
        if silent {
            s.silent.push(id);
        }
    }

    /// Stops the thread and returns the socket.
    pub fn stop(mut self) -> CanSocket {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().unwrap().join().unwrap()
    }
}

impl Drop for MitEmulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The velocity the daemon decodes from a reply carrying `v` (12-bit MIT quantisation), joint side.
pub fn decoded_sdot(v_motor: f64, r: f64) -> f64 {
    let (u, _) = mit::float_to_uint(v_motor, -65.0, 65.0, 12);
    mit::uint_to_float(u, -65.0, 65.0, 12) / r
}

/// The control law's expected currents (knee, hip) for `tau_des` at the motor velocities `v_motor`.
pub fn expected_currents(tau_des: [f64; 2], v_motor: [f64; 2]) -> [f64; 2] {
    expected_currents_kfc(tau_des, v_motor, KNEE_CV.3)
}

/// [`expected_currents`] with the knee's friction compensation fraction `kfc` in place of
/// [`mit_body`]'s.
pub fn expected_currents_kfc(tau_des: [f64; 2], v_motor: [f64; 2], kfc: f64) -> [f64; 2] {
    let (kc, ka, kv, _) = KNEE_CV;
    let sd_knee = decoded_sdot(v_motor[0], KNEE_R);
    let sd_hip = decoded_sdot(v_motor[1], HIP_R);
    [
        current_ref(
            tau_des[0],
            cv_ref(kc, ka, kv, sd_knee),
            sd_knee,
            0.0,
            f64::INFINITY,
            kfc,
            KNEE_KT,
            KNEE_R,
            5.0,
        ),
        current_ref(
            tau_des[1],
            0.0,
            sd_hip,
            0.0,
            f64::INFINITY,
            1.0,
            HIP_KT,
            HIP_R,
            4.0,
        ),
    ]
}

/// Half a quantisation step of the t field of drive `id`, plus float slack.
pub fn t_tol(id: u32) -> f64 {
    ranges(id).steps()[4] / 2.0 + 1e-9
}

/// A torque request enabling both joints.
pub fn request(tau_des: [f64; 2]) -> TorqueRequest {
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 2;
    rq.enable_mask = 0b11;
    rq.tau_des_nm[0] = tau_des[0];
    rq.tau_des_nm[1] = tau_des[1];
    rq
}

/// Publishes `rq` every ms (fresh stamps) until `pred` holds for the mirrored command; panics
/// after `timeout` with the last command.
pub fn drive_until(
    plant: &mut Plant,
    rq: &TorqueRequest,
    timeout: Duration,
    mut pred: impl FnMut(&MotorCurrentCommand) -> bool,
) -> MotorCurrentCommand {
    let t0 = Instant::now();
    let mut last = None;
    while t0.elapsed() < timeout {
        plant.seq += 1;
        let mut r = *rq;
        r.seq = plant.seq;
        r.stamp_ns = frictionless_shm_types::monotonic_ns();
        plant.request.publish(&r).unwrap();
        std::thread::sleep(Duration::from_millis(1));
        if let Some(c) = plant.cmd.latest().unwrap() {
            if pred(&c) {
                return c;
            }
            last = Some(c);
        }
    }
    panic!("no matching command within {timeout:?}; last: {last:?}");
}

/// The closed-loop scenario on an already running daemon whose bus peer is `emu`:
/// 1. commands decode to the control-law currents (mirror exact, CAN frames within quantisation);
/// 2. knee feedback stops → knee gets the `on_stale` output, here 0 A (FLAG_STALE, stale bit in the
///    status) while the hip runs on;
///    feedback resumes → knee back to the law;
/// 3. all feedback stops → every joint 0 A on the wire.
pub fn closed_loop_scenario(plant: &mut Plant, emu: &MitEmulator, v_motor: [f64; 2]) {
    let t = Duration::from_secs(20);
    let tau = [3.0, 1.5];
    let want = expected_currents(tau, v_motor);
    assert!(want[0].abs() > 0.1 && want[1].abs() > 0.1, "{want:?}");
    let rq = request(tau);
    let c = drive_until(plant, &rq, t, |c| {
        c.valid_mask == 0b11
            && (c.i_ref_a[0] - want[0]).abs() < 1e-9
            && (c.i_ref_a[1] - want[1]).abs() < 1e-9
    });
    assert_eq!((c.flags[0] & FLAG_FAULT, c.flags[1] & FLAG_FAULT), (0, 0));
    // What reached the drives: knee motor torque kt·i, hip current i (within quantisation).
    let t0 = Instant::now();
    loop {
        let (k, h) = (emu.log(1), emu.log(2));
        let ok = (k.last_t - KNEE_KT * want[0]).abs() <= t_tol(1)
            && (h.last_t - want[1]).abs() <= t_tol(2);
        if ok {
            assert!(!k.gains_seen && !h.gains_seen, "kp = kd = 0 always");
            assert_eq!(k.specials.first(), Some(&MitSpecial::EnterMotorMode));
            break;
        }
        assert!(t0.elapsed() < t, "drives saw {k:?} / {h:?}, want {want:?}");
        plant.seq += 1;
        let mut r = rq;
        r.seq = plant.seq;
        r.stamp_ns = frictionless_shm_types::monotonic_ns();
        plant.request.publish(&r).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }

    // 2. the knee drive goes silent.
    emu.set_silent(1, true);
    let c = drive_until(plant, &rq, t, |c| c.flags[0] & FLAG_STALE != 0);
    assert_eq!(
        c.flags[0] & FLAG_FAULT,
        0,
        "a silent drive is stale, not faulted"
    );
    assert_eq!(c.i_ref_a[0], 0.0);
    assert!((c.i_ref_a[1] - want[1]).abs() < 1e-9, "hip keeps running");
    let st = plant
        .status
        .wait_latest(t)
        .unwrap()
        .expect("status while knee stale");
    let st = if st.bus.stale_feedback_mask & 1 == 0 {
        // The snapshot may predate the silence: wait for one that has it.
        let t0 = Instant::now();
        loop {
            if let Some(s) = plant.status.wait_latest(Duration::from_millis(50)).unwrap()
                && s.bus.stale_feedback_mask & 1 != 0
            {
                break s;
            }
            assert!(t0.elapsed() < t, "stale bit never reported");
        }
    } else {
        st
    };
    assert_eq!(st.bus.stale_feedback_mask & 0b10, 0);
    // The knee drive still receives commands (it is silent, not deaf): they are 0.
    std::thread::sleep(Duration::from_millis(50));
    assert!(emu.log(1).last_t.abs() <= t_tol(1), "{:?}", emu.log(1));
    emu.set_silent(1, false);
    drive_until(plant, &rq, t, |c| {
        c.flags[0] & (FLAG_FAULT | FLAG_STALE) == 0 && (c.i_ref_a[0] - want[0]).abs() < 1e-9
    });

    // 3. every drive silent: nothing new arrives → the whole-state stale rule (on_stale = zero).
    emu.set_silent(1, true);
    emu.set_silent(2, true);
    let c = drive_until(plant, &rq, t, |c| {
        c.i_ref_a[0] == 0.0 && c.i_ref_a[1] == 0.0
    });
    assert!(c.flags[0] != 0 && c.flags[1] != 0, "{:?}", &c.flags[..2]);
    std::thread::sleep(Duration::from_millis(50));
    assert!(emu.log(1).last_t.abs() <= t_tol(1));
    assert!(emu.log(2).last_t.abs() <= t_tol(2));
    emu.set_silent(1, false);
    emu.set_silent(2, false);
}

/// A running daemon's stderr, read line by line by a thread as it comes, so a test can wait for a
/// log line while the daemon runs. Takes the child's stderr: [`Daemon::wait_exit`] then returns an
/// empty text; [`LogTail::finish`] returns the whole log.
pub struct LogTail {
    text: Arc<Mutex<String>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl LogTail {
    /// Starts reading `d`'s stderr.
    pub fn take(d: &mut Daemon) -> Self {
        use std::io::BufRead;
        let stderr = d.child.stderr.take().expect("the daemon's stderr is piped");
        let text = Arc::new(Mutex::new(String::new()));
        let t = text.clone();
        let thread = std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                let mut s = t.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        Self {
            text,
            thread: Some(thread),
        }
    }

    /// The log so far.
    pub fn text(&self) -> String {
        self.text.lock().unwrap().clone()
    }

    /// Waits until the log holds `needle` `count` times; panics with the log after `timeout`.
    pub fn wait_for(&self, needle: &str, count: usize, timeout: Duration) {
        let t0 = Instant::now();
        while self.text().matches(needle).count() < count {
            assert!(
                t0.elapsed() < timeout,
                "no {count}× `{needle}` in the daemon's log within {timeout:?}:\n{}",
                self.text()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The whole log, once the daemon has exited (its stderr closed).
    pub fn finish(mut self) -> String {
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
        self.text()
    }
}

/// Drives `rq` until the mirrored command has the law's currents `want` and the drives received
/// them: knee motor torque k_t·i (the k_t of [`mit_body`]), hip current i, within quantisation;
/// every drive's command count grows by at least 10 on the way. Panics after `timeout`.
pub fn wire_agrees_with_law(
    plant: &mut Plant,
    emu: &MitEmulator,
    rq: &TorqueRequest,
    want: [f64; 2],
    timeout: Duration,
) {
    let c = drive_until(plant, rq, timeout, |c| {
        c.valid_mask == 0b11
            && (c.i_ref_a[0] - want[0]).abs() < 1e-9
            && (c.i_ref_a[1] - want[1]).abs() < 1e-9
    });
    assert_eq!((c.flags[0] & FLAG_FAULT, c.flags[1] & FLAG_FAULT), (0, 0));
    let before = [emu.log(1).commands, emu.log(2).commands];
    let t0 = Instant::now();
    loop {
        let c = drive_until(plant, rq, timeout, |_| true);
        let (k, h) = (emu.log(1), emu.log(2));
        let law = (c.i_ref_a[0] - want[0]).abs() < 1e-9 && (c.i_ref_a[1] - want[1]).abs() < 1e-9;
        let wire = (k.last_t - KNEE_KT * want[0]).abs() <= t_tol(1)
            && (h.last_t - want[1]).abs() <= t_tol(2);
        if law && wire && k.commands >= before[0] + 10 && h.commands >= before[1] + 10 {
            return;
        }
        assert!(
            t0.elapsed() < timeout,
            "law knee {} A, hip {} A (want {want:?}); wire knee {} Nm (want {}), hip {} A; commands {} / {} since {before:?}",
            c.i_ref_a[0],
            c.i_ref_a[1],
            k.last_t,
            KNEE_KT * want[0],
            h.last_t,
            k.commands,
            h.commands
        );
    }
}

/// SIGHUP on a running CAN daemon `d` started from `body` ([`mit_body`], written with
/// [`write_can_config`] in `env`) whose bus peer is `emu` (motor velocities `v_motor`):
/// 1. kfc 0.85 → 0.4 (the law only): applied as generation 1; the knee current moves to the new
///    law's and the drives receive it;
/// 2. on top of that, the knee's k_t 0.157 → 0.18, node id 1 → 3 and gear ratio −100 → −120 (all
///    fixed when the backend opened): refused, naming each old → new; the daemon runs on as
///    generation 1 (kfc 0.4, the old k_t, node id and r): the law's currents and what drive 1
///    receives agree, and no frame goes to node 3;
/// 3. SIGTERM: a clean exit; exactly one reload was applied.
///
/// Takes the daemon's stderr (see [`LogTail`]); returns its whole log.
pub fn sighup_scenario(
    env: &TestEnv,
    body: &str,
    d: &mut Daemon,
    plant: &mut Plant,
    emu: &MitEmulator,
    v_motor: [f64; 2],
) -> String {
    let t = Duration::from_secs(30);
    let tail = LogTail::take(d);
    plant.wait_for_daemon(t);
    let tau = [3.0, 1.5];
    let rq = request(tau);
    let want_before = expected_currents(tau, v_motor);
    wire_agrees_with_law(plant, emu, &rq, want_before, t);
    assert_eq!(plant.status_until(None, t, |_| true).generation, 0);

    // 1. A law value: applied.
    let kfc = 0.4;
    let applied = body.replacen(&format!("kfc = {}", KNEE_CV.3), &format!("kfc = {kfc}"), 1);
    assert_ne!(applied, body);
    write_can_config(env, &applied);
    d.signal(libc::SIGHUP);
    plant.status_until(None, t, |s| s.generation == 1);
    tail.wait_for("reloaded", 1, t);
    let want = expected_currents_kfc(tau, v_motor, kfc);
    assert!(
        (want[0] - want_before[0]).abs() > 0.1,
        "kfc moves the knee current: {want_before:?} → {want:?}"
    );
    wire_agrees_with_law(plant, emu, &rq, want, t);

    // 2. Values the backend fixed at open: refused, nothing applied.
    let fixed = applied
        .replacen(&format!("kt = {KNEE_KT}"), "kt = 0.18", 1)
        .replacen("node_id = 1\n", "node_id = 3\n", 1)
        .replacen(&format!("gear_ratio = {KNEE_R}"), "gear_ratio = -120", 1);
    assert_eq!(
        fixed.lines().filter(|l| !applied.contains(*l)).count(),
        3,
        "three lines changed:\n{fixed}"
    );
    write_can_config(env, &fixed);
    d.signal(libc::SIGHUP);
    tail.wait_for("needs a restart", 1, t);
    assert!(d.alive(), "frictiond runs on after a refused reload");
    wire_agrees_with_law(plant, emu, &rq, want, t);
    let s = plant.status_until(None, t, |_| true);
    assert_eq!(s.generation, 1, "the refused reload applied nothing");
    assert_eq!(emu.frames_to_other_id(3), 0, "nothing is sent to node 3");

    // 3. Exit.
    d.signal(libc::SIGTERM);
    let (st, _) = d.wait_exit(t);
    let log = tail.finish();
    assert!(st.success(), "{log}");
    for needle in [
        "needs a restart",
        "knee",
        "kt 0.157 → 0.18",
        "node_id 1 → 3",
        "gear_ratio -100 → -120",
    ] {
        assert!(log.contains(needle), "{needle}: {log}");
    }
    assert_eq!(log.matches("reloaded").count(), 1, "{log}");
    log
}

/// An emulated CiA 402 drive (`frictionless_drives::can::cia402_node`) on the test end of a
/// socket, in a thread: boot-up, then it answers every frame and ticks its heartbeat every ms. The
/// motor position follows the applied torque (a unit inertia), so the TPDOs change every cycle.
pub struct Cia402Emu {
    /// The node (lock briefly).
    pub node: Arc<Mutex<frictionless_drives::can::cia402_node::Cia402Node>>,
    /// SYNCs seen.
    pub syncs: Arc<std::sync::atomic::AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Cia402Emu {
    /// Starts node `node` (rated torque 500 mNm, max 2000 ‰, 4096 increments per revolution).
    pub fn start(sock: CanSocket, node: u8) -> Self {
        use frictionless_drives::can::cia402_node::{Cia402Node, NodeParams};
        let n = Cia402Node::new(&NodeParams {
            node,
            rated_torque_mnm: 500,
            max_torque_permille: 2000,
            counts_per_rev: 4096,
        })
        .unwrap();
        let node = Arc::new(Mutex::new(n));
        let stop = Arc::new(AtomicBool::new(false));
        let syncs = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let (n2, s2, c2) = (node.clone(), stop.clone(), syncs.clone());
        let thread = std::thread::spawn(move || {
            let tx = |f: &WireFrame| {
                let _ = sock.write_frame(&CanFrame::try_from(*f).unwrap());
            };
            let boot = n2.lock().unwrap().boot().unwrap();
            tx(&boot);
            let (mut pos, mut vel) = (0.0f64, 0.0f64);
            let mut last = Instant::now();
            while !s2.load(Ordering::Relaxed) {
                if let Ok(f) = sock.read_frame_timeout(Duration::from_micros(500))
                    && let Ok(w) = WireFrame::try_from(&f)
                {
                    let mut n = n2.lock().unwrap();
                    if w.id == 0x80 {
                        c2.fetch_add(1, Ordering::Relaxed);
                        let t = f64::from(n.applied_torque_permille());
                        vel += 1e-3 * t;
                        pos += 1e-3 * vel;
                        n.set_feedback(pos as i32, vel as i32, t as i16, (pos / 100.0) as i32, 0);
                    }
                    let out = n.on_frame(&w);
                    out.frames().iter().for_each(tx);
                }
                if last.elapsed() >= Duration::from_millis(1) {
                    last = Instant::now();
                    let out = n2.lock().unwrap().tick_ms();
                    out.frames().iter().for_each(tx);
                }
            }
        });
        Self {
            node,
            syncs,
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Cia402Emu {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The config body of the knee of `frictl sim serve --preset knee --protocol cia402` on node 1 of
/// vcan0 (k_t, gear ratio, current limit of the preset; 0x6076 / 0x6072 / 0x608F read from the
/// drive), ticking every `period_us`.
pub fn cia402_knee_body(period_us: u64) -> String {
    format!(
        r#"
[loop]
period_us = {period_us}
status_every_ticks = 20
ready_after_ticks = 10

[safety]
stale_after_ticks = 200
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"

[[bus]]
interface = "vcan0"
bitrate = 1000000
protocol = "cia402"
max_load = 0.9
feedback_timeout_ticks = 50

[[bus.joint]]
joint = "knee"
node_id = 1
command_unit = "motor_torque"
[bus.joint.cia402]
mode = "cst"
fault_reset = true
velocity_unit_rad_s = 0.0003834951969714103
joint_encoder = {{ index = 0x60E4, sub = 1, bits = 32, counts_per_rev = 524288 }}
heartbeat_ms = 20
heartbeat_timeout_ms = 300
"#
    )
}
