//! Shared helpers of the `daemon_*` end-to-end tests: a real `frictiond` process, an isolated
//! iceoryx2 root path and service prefix per test, and the test process acting as the plant.
//!
//! Not a test target itself; `main.rs` includes it with `mod daemon_support;`.

#![allow(dead_code)]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use frictionless_shm_types::{
    DaemonStatus, Inbox, Ipc, IpcConfig, JointStates, MotorCurrentCommand, Outbox, TorqueRequest,
    monotonic_ns,
};

/// The `frictiond` binary: `/bin/frictiond` in the CAN VM (`FRICTIONLESS_IN_CANVM`, see
/// `tests/canvm/run.sh`), else the one Cargo built for this test target (`CARGO_BIN_EXE_frictiond`).
pub fn frictiond_bin() -> PathBuf {
    if std::env::var_os("FRICTIONLESS_IN_CANVM").is_some() {
        return PathBuf::from("/bin/frictiond");
    }
    PathBuf::from(env!("CARGO_BIN_EXE_frictiond"))
}

/// The repository root (the workspace; `config/` holds the shipped configs).
pub fn repo_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("daemon/ is inside the workspace")
}

/// Where `frictl` is expected: `/bin/frictl` in the CAN VM, else `target/<profile>/frictl`, next to
/// the test executable's `deps/` directory (another package's binary, so Cargo does not build it for
/// this test target: `tests/run.sh` runs `cargo build --workspace --bins` first). May not exist.
pub fn frictl_path() -> PathBuf {
    if std::env::var_os("FRICTIONLESS_IN_CANVM").is_some() {
        return PathBuf::from("/bin/frictl");
    }
    let exe = std::env::current_exe().expect("current_exe");
    let dir = exe.parent().and_then(Path::parent).expect("target dir");
    dir.join("frictl")
}

/// [`frictl_path`]; panics if it was not built. The tests that need it are `#[ignore]`d
/// (`cargo test -p frictiond` does not build another package's binary); `tests/run.sh` builds the
/// workspace and runs them with `--include-ignored`.
pub fn frictl_bin() -> PathBuf {
    let bin = frictl_path();
    assert!(
        bin.exists(),
        "{} not found: run bash tests/run.sh, or `cargo build -p frictl` first",
        bin.display()
    );
    bin
}

/// A per-test directory, iceoryx2 root path and service prefix; removed on drop.
pub struct TestEnv {
    /// Scratch directory (config files, sockets, reports).
    pub dir: PathBuf,
    /// iceoryx2 settings shared by the daemon and the plant.
    pub ipc: IpcConfig,
}

impl TestEnv {
    /// A fresh environment tagged `tag`.
    pub fn new(tag: &str) -> Self {
        let id = format!(
            "fld_{tag}_{}_{}",
            std::process::id(),
            monotonic_ns() % 1_000_000_000
        );
        let dir = std::env::temp_dir().join(&id);
        std::fs::create_dir_all(dir.join("iox")).unwrap();
        let ipc = IpcConfig::new(Some(&dir.join("iox")), &id);
        Self { dir, ipc }
    }

    /// Writes `frictiond.toml` = `[backend]` for this env + `body`; returns its path.
    pub fn write_config(&self, body: &str) -> PathBuf {
        let path = self.dir.join("frictiond.toml");
        self.write_config_at(&path, body);
        path
    }

    /// Writes a config to `path` (same backend section).
    pub fn write_config_at(&self, path: &Path, body: &str) {
        let text = format!(
            "[backend]\nkind = \"shm\"\nservice_prefix = \"{}\"\nroot_path = \"{}\"\n\n{body}",
            self.ipc.service_prefix,
            self.ipc.root_path.as_ref().unwrap().display()
        );
        std::fs::write(path, text).unwrap();
    }
}

impl Drop for TestEnv {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A running `frictiond`; SIGKILLed on drop if still alive.
pub struct Daemon {
    /// The child.
    pub child: Child,
}

impl Daemon {
    /// Starts `frictiond --config cfg` with extra env vars; stderr is captured.
    pub fn start(cfg: &Path, envs: &[(&str, &str)]) -> Self {
        let mut cmd = Command::new(frictiond_bin());
        cmd.arg("--config")
            .arg(cfg)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        for (k, v) in envs {
            cmd.env(k, v);
        }
        Self {
            child: cmd.spawn().expect("spawn frictiond"),
        }
    }

    /// The PID.
    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    /// Sends a signal.
    pub fn signal(&self, sig: i32) {
        // SAFETY: plain kill(2) on our own child.
        assert_eq!(unsafe { libc::kill(self.pid(), sig) }, 0);
    }

    /// Still running?
    pub fn alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }

    /// Waits up to `timeout` for exit; returns (exit status, stderr text).
    pub fn wait_exit(&mut self, timeout: Duration) -> (std::process::ExitStatus, String) {
        let t0 = Instant::now();
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                let mut s = String::new();
                if let Some(mut e) = self.child.stderr.take() {
                    let _ = e.read_to_string(&mut s);
                }
                return (st, s);
            }
            assert!(
                t0.elapsed() < timeout,
                "frictiond did not exit within {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The test process as the plant: publishes states and requests, reads commands and status.
pub struct Plant {
    /// Node (kept alive).
    pub ipc: Ipc,
    /// JointStates out.
    pub states: Outbox<JointStates>,
    /// TorqueRequest out.
    pub request: Outbox<TorqueRequest>,
    /// Commands in.
    pub cmd: Inbox<MotorCurrentCommand>,
    /// Status in.
    pub status: Inbox<DaemonStatus>,
    /// Next state seq.
    pub seq: u64,
}

impl Plant {
    /// Opens all ports (create in the thread that uses them: ports are !Send).
    pub fn open(ipc: &IpcConfig, name: &str) -> Self {
        let node = Ipc::open(ipc, name).unwrap();
        let states = node.joint_states().unwrap().outbox().unwrap();
        let request = node.torque_request().unwrap().outbox().unwrap();
        let cmd = node.motor_current_command().unwrap().inbox().unwrap();
        let status = node.daemon_status().unwrap().inbox().unwrap();
        Self {
            ipc: node,
            states,
            request,
            cmd,
            status,
            seq: 0,
        }
    }

    /// Publishes `js` and `rq` with fresh stamps and a new seq; returns the state seq.
    pub fn send(&mut self, js: &JointStates, rq: &TorqueRequest) -> u64 {
        self.seq += 1;
        let now = monotonic_ns();
        let mut js = *js;
        js.seq = self.seq;
        js.stamp_ns = now;
        let mut rq = *rq;
        rq.seq = self.seq;
        rq.state_seq = self.seq;
        rq.stamp_ns = now;
        self.request.publish(&rq).unwrap();
        self.states.publish(&js).unwrap();
        self.seq
    }

    /// Lockstep step 1: publishes `js` alone with a fresh stamp and the next seq; returns it.
    pub fn publish_state(&mut self, js: &JointStates) -> u64 {
        self.seq += 1;
        let mut js = *js;
        js.seq = self.seq;
        js.stamp_ns = monotonic_ns();
        self.states.publish(&js).unwrap();
        self.seq
    }

    /// Lockstep step 2: publishes `rq` answering the state `state_seq`.
    pub fn publish_request(&mut self, rq: &TorqueRequest, state_seq: u64) {
        let mut rq = *rq;
        rq.seq = state_seq;
        rq.state_seq = state_seq;
        rq.stamp_ns = monotonic_ns();
        self.request.publish(&rq).unwrap();
    }

    /// Waits until the daemon's ports exist (its status publisher is the last one it opens).
    pub fn wait_for_daemon(&self, timeout: Duration) {
        let ch = self.ipc.daemon_status().unwrap();
        let t0 = Instant::now();
        while ch.publisher_count() == 0 {
            assert!(t0.elapsed() < timeout, "frictiond did not open its ports");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits for the command answering state `seq` (newer ones also end the wait); `None` after
    /// `timeout`.
    pub fn command_for(&mut self, seq: u64, timeout: Duration) -> Option<MotorCurrentCommand> {
        let t0 = Instant::now();
        loop {
            if let Some(c) = self.cmd.latest().unwrap()
                && c.state_seq >= seq
            {
                return Some(c);
            }
            let left = timeout.saturating_sub(t0.elapsed());
            if left.is_zero() {
                return None;
            }
            self.cmd.wait(left.min(Duration::from_millis(5))).unwrap();
        }
    }

    /// Keeps publishing `js`/`rq` every ms until a command answers a state sent in this call and
    /// satisfies `pred`; panics after `timeout`.
    pub fn until(
        &mut self,
        js: &JointStates,
        rq: &TorqueRequest,
        timeout: Duration,
        mut pred: impl FnMut(&MotorCurrentCommand) -> bool,
    ) -> MotorCurrentCommand {
        let t0 = Instant::now();
        let first = self.seq + 1;
        let mut last = None;
        while t0.elapsed() < timeout {
            self.send(js, rq);
            std::thread::sleep(Duration::from_millis(1));
            if let Some(c) = self.cmd.latest().unwrap() {
                if c.state_seq >= first && pred(&c) {
                    return c;
                }
                last = Some(c);
            }
        }
        panic!("no matching command within {timeout:?}; last: {last:?}");
    }

    /// Waits (without publishing) for a command satisfying `pred`.
    pub fn until_silent(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&MotorCurrentCommand) -> bool,
    ) -> MotorCurrentCommand {
        let t0 = Instant::now();
        let mut last = None;
        while t0.elapsed() < timeout {
            if let Some(c) = self.cmd.wait_latest(Duration::from_millis(20)).unwrap() {
                if pred(&c) {
                    return c;
                }
                last = Some(c);
            }
        }
        panic!("no matching command within {timeout:?}; last: {last:?}");
    }

    /// Waits for a status satisfying `pred` (while optionally keeping inputs fresh).
    pub fn status_until(
        &mut self,
        keep_fresh: Option<(&JointStates, &TorqueRequest)>,
        timeout: Duration,
        mut pred: impl FnMut(&DaemonStatus) -> bool,
    ) -> DaemonStatus {
        let t0 = Instant::now();
        let mut last = None;
        while t0.elapsed() < timeout {
            if let Some((js, rq)) = keep_fresh {
                self.send(js, rq);
            }
            std::thread::sleep(Duration::from_millis(1));
            if let Some(s) = self.status.latest().unwrap() {
                if pred(&s) {
                    return s;
                }
                last = Some(s);
            }
        }
        panic!(
            "no matching status within {timeout:?}; last ticks/generation: {:?}",
            last.map(|s| (s.ticks, s.generation))
        );
    }
}

/// Independent reference of the paper's CV model (not the daemon's code).
pub fn cv_ref(kc: f64, ka: f64, kv: f64, v: f64) -> f64 {
    kc * (ka * v).tanh() + kv * v
}

/// Independent reference of the paper's SCV model.
pub fn scv_ref(kc: f64, ka: f64, kv: f64, ks: f64, vs: f64, alpha: f64, v: f64) -> f64 {
    kv * v
        + kc * (ka * v).tanh()
        + (ks - kc) * (-(v / vs).abs().powf(alpha)).exp() * (ka * v).tanh()
}

/// Reference control law (pure feed-forward): clip gated by |ṡ| > gate, kfc, /(kt·r), clamp.
#[allow(clippy::too_many_arguments)]
pub fn current_ref(
    tau_des: f64,
    f: f64,
    v: f64,
    gate: f64,
    max_f: f64,
    kfc: f64,
    kt: f64,
    r: f64,
    max_i: f64,
) -> f64 {
    let f = if v.abs() > gate {
        f.clamp(-max_f, max_f)
    } else {
        f
    };
    ((tau_des + kfc * f) / (kt * r)).clamp(-max_i, max_i)
}

/// Generous bound for anything the tests wait for (no timing asserts).
pub const T: Duration = Duration::from_secs(20);

/// Three joints: none / CV / SCV with different signs, constants and clamps; no LPF so each tick
/// is exact.
pub const THREE_JOINTS: &str = r#"
[loop]
period_us = 1000
status_every_ticks = 10
ready_after_ticks = 10

[safety]
stale_after_ticks = 20
on_stale = "zero"

[[joint]]
name = "plain"
index = 0
gear_ratio = 100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"

[[joint]]
name = "knee_cv"
index = 1
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 6.0
joint_velocity_threshold_rad_s = 0.05
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55

[[joint]]
name = "ankle_scv"
index = 2
gear_ratio = -160.0
kt = 0.0665
max_curr = 3.0
kfc = 0.7
max_output_friction = 8.0
friction_model = "coulomb_viscous_stribeck"
kc = 1.0005
ka = 2.78
kv = 0.29
ks = 6.0
vs = 0.13
alpha = 0.6
"#;

/// Expected currents of [`THREE_JOINTS`] for torques `tau` and joint velocities `v` (references
/// above, not the daemon's code).
pub fn expected(tau: [f64; 3], v: [f64; 3]) -> [f64; 3] {
    [
        current_ref(
            tau[0],
            0.0,
            v[0],
            0.0,
            f64::INFINITY,
            1.0,
            0.157,
            100.0,
            5.0,
        ),
        current_ref(
            tau[1],
            cv_ref(8.1, 50.84, 5.55, v[1]),
            v[1],
            0.05,
            6.0,
            0.85,
            0.157,
            -100.0,
            5.0,
        ),
        current_ref(
            tau[2],
            scv_ref(1.0005, 2.78, 0.29, 6.0, 0.13, 0.6, v[2]),
            v[2],
            0.0,
            8.0,
            0.7,
            0.0665,
            -160.0,
            3.0,
        ),
    ]
}

/// States and a request (all three joints enabled) for [`THREE_JOINTS`].
pub fn inputs(tau: [f64; 3], v: [f64; 3]) -> (JointStates, TorqueRequest) {
    let mut js = JointStates::zeroed();
    js.n_joints = 3;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 3;
    rq.enable_mask = 0b111;
    for k in 0..3 {
        js.sdot_rad_s[k] = v[k];
        js.omega_motor_rad_s[k] = v[k] * 100.0;
        rq.tau_des_nm[k] = tau[k];
    }
    (js, rq)
}

/// Equal to 1e-9 relative (+1e-9 absolute).
pub fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + b.abs())
}

/// The `[loop]` and `[safety]` sections of a lockstep daemon at 1 kHz (ready after 5 ticks, stale
/// after 20, zero current when stale) that the model tests start their configs with.
pub const LOCKSTEP_LOOP_AND_SAFETY: &str = r#"
[loop]
period_us = 1000
status_every_ticks = 5
ready_after_ticks = 5
trigger = "lockstep"
lockstep_wait_request = true
lockstep_timeout_ms = 10000

[safety]
stale_after_ticks = 20
on_stale = "zero"
"#;
