//! Proves that `frictiond`'s RT thread performs no heap allocation over ≥ 100 000 ticks after READY
//! (besides iceoryx2's documented one-`Box`-per-published-sample, counted separately as "exempt").
//!
//! The daemon's counting global allocator is activated by `FRICTIOND_ALLOC_REPORT=<file>`; the
//! report is written at exit. The loop runs at a 50 µs period so 100 000 ticks take seconds.
//! Scope: steady state. A new peer connecting (e.g. `frictl monitor` attaching) makes iceoryx2 set up
//! connection state on the RT thread; that is not covered by this claim. Joint 2 is a small PINN
//! whose stored training range its velocity leaves and re-enters, with `ood = "static"`: the range
//! check, the counter and the blend run too. Joint 3 is a LuGre joint, re-enabled every 500 steps
//! (its bristle state reset) and integrated every tick.

use std::time::Duration;

use crate::daemon_support::*;
use frictionless::features::{FeatureSet, FeatureSpec};
use frictionless::mlp::StorageDtype;
use frictionless::random::{RandomMlpSpec, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{InputRange, ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{JointStates, TorqueRequest};

/// A 2·4 → 8 → 1 `[Δθ, ṡ]` network trained (so its file says) on ṡ ∈ [−1, 1] rad/s.
fn ranged_pinn() -> ModelFile {
    let features = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: 4,
        temperature: false,
    };
    let mut training = TrainingMeta::unknown("daemon_alloc test", 0);
    training.input_range = Some(InputRange {
        blocks: [[-1.0, 1.0], [-1.0, 1.0], [0.0, 0.0]],
        temperature: [0.0, 0.0],
    });
    ModelFile {
        meta: ModelMeta {
            joint_name: "hip".into(),
            gear_ratio: GearRatio::new(-100.0).unwrap(),
            kt_nm_per_a: 0.1,
            features,
            scv: None,
            training,
        },
        dtype: StorageDtype::F32,
        mlp: seeded_mlp(&RandomMlpSpec::new(&[8, 8, 1]), 5).unwrap(),
    }
}

#[test]
fn rt_thread_allocates_nothing_over_100k_ticks_after_ready() {
    alloc_run("alloc", "");
}

/// The same with `rt_threads = 2` (the helper thread computes part of the joints and counts its
/// allocations into the same report) and lead prefetching on both threads.
#[test]
fn rt_and_helper_threads_allocate_nothing_over_100k_ticks_after_ready() {
    alloc_run(
        "alloc2",
        "rt_threads = 2\nprefetch = \"lead\"\nprefetch_lead_us = 20\n",
    );
}

fn alloc_run(tag: &str, extra_loop: &str) {
    const READY_AFTER: u64 = 20_000;
    const TICKS: u64 = 100_000;
    let env = TestEnv::new(tag);
    frictionless::weights::write_file(&env.dir.join("hip.fwt"), &ranged_pinn()).unwrap();
    let cfg = env.write_config(&format!(
        "[loop]\nperiod_us = 50\nstatus_every_ticks = 1000\nready_after_ticks = 20000\n{extra_loop}{}",
        r#"

[safety]
stale_after_ticks = 100000
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 25.0
lpf = { order = 2, cutoff_hz = 30.0 }
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55

[[joint.alternate]]
name = "cv_b"
friction_model = "cv"
kc = 4.0
ka = 20.0
kv = 2.0

[[joint]]
name = "ankle"
index = 1
gear_ratio = -160.0
kt = 0.0665
max_curr = 3.0
kfc = 0.7
friction_model = "scv"
kc = 1.0005
ka = 2.78
kv = 0.29
ks = 6.0
vs = 0.13
alpha = 0.6

[[joint]]
name = "hip"
index = 2
gear_ratio = -100.0
kt = 0.1
max_curr = 5.0
friction_model = "pinn"
model = "hip.fwt"
warmup = "zero_pad"
delta_theta_offset_motor_rad = 0.0
ood = "static"
kc = 0.5
ka = 20.0
kv = 0.3
ks = 0.8
vs = 0.1
alpha = 1.0

[[joint.alternate]]
name = "hip_b"
friction_model = "pinn"
model = "hip.fwt"
warmup = "hold_zero"

[[joint]]
name = "wrist"
index = 3
gear_ratio = 100.0
kt = 0.1
max_curr = 5.0
friction_model = "lugre"
kc = 0.4
kv = 0.2
ks = 0.7
vs = 0.1
alpha = 1.0
sigma0 = 2000.0
sigma1 = 1.0
"#
    ));
    let report = env.dir.join("alloc_report.txt");
    let latency = env.dir.join("latency_report.txt");
    let mut d = Daemon::start(
        &cfg,
        &[
            ("FRICTIOND_ALLOC_REPORT", report.to_str().unwrap()),
            ("FRICTIOND_LATENCY_REPORT", latency.to_str().unwrap()),
        ],
    );
    let mut plant = Plant::open(&env.ipc, "plant");
    // Runtime sets arrive all along (kfc, the compensation switch and model switches among the
    // preloaded models — a PINN, its PINN alternate, none — between every two steps):
    // checked by the supervisor, applied by the RT thread at its tick boundaries.
    // Not waited for: the plant must connect before counting starts (below).
    let ctl_node = frictionless_shm_types::Ipc::open(&env.ipc, "ctl").unwrap();
    let ctl = ctl_node.control_client().unwrap();
    let mut sets = 0u64;
    let mut js = JointStates::zeroed();
    js.n_joints = 4;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 4;
    rq.enable_mask = 0b1111;
    let mut k = 0u64;
    let t0 = std::time::Instant::now();
    // Peers must connect before counting starts: iceoryx2 sets up per-connection state (allocating)
    // the first time a port sees a new peer. Steady state is what the test measures.
    let mut connected_early = None;
    let mut ood_seen = 0u64;
    loop {
        // Changing inputs so every code path (enable, filter, clamp) runs.
        k += 1;
        let x = (k as f64 * 0.01).sin();
        js.sdot_rad_s[0] = x;
        js.sdot_rad_s[1] = -x;
        js.sdot_rad_s[2] = 2.0 * x; // out of the PINN's training range while |x| > 0.5
        js.sdot_rad_s[3] = 0.5 * x; // LuGre: through zero (pre-sliding) and sliding
        rq.tau_des_nm[0] = 30.0 * x;
        rq.tau_des_nm[1] = 2.0 * x;
        rq.tau_des_nm[2] = x;
        rq.tau_des_nm[3] = 0.5 * x;
        // The ankle and the LuGre wrist are re-enabled every 500 steps (their reset on enable).
        rq.enable_mask = if k % 500 < 450 { 0b1111 } else { 0b0101 };
        plant.send(&js, &rq);
        let (joint, key, value) = match k % 8 {
            0 => ("knee", "kfc", "0.5"),
            1 => ("knee", "kfc", "0.85"),
            2 => ("ankle", "compensation", "off"),
            3 => ("ankle", "compensation", "on"),
            4 => ("hip", "model", "hip_b"),
            5 => ("hip", "model", "none"),
            6 => ("hip", "model", "default"),
            _ if k % 16 < 8 => ("knee", "model", "cv_b"),
            _ => ("knee", "model", "default"),
        };
        let req = frictionless_shm_types::control::ControlRequest::set(joint, key, value).unwrap();
        match ctl.call(&req, T) {
            Ok(r) => {
                assert_eq!(r.status, 0, "{}", r.message());
                sets += 1;
            }
            // Before the daemon's control server is up a request finds no server at once.
            Err(e) if sets == 0 => assert!(e.to_string().contains("no server"), "{e}"),
            Err(e) => panic!("after {sets} sets: {e}"),
        }
        std::thread::sleep(Duration::from_millis(1));
        if let Some(s) = plant.status.latest().unwrap() {
            ood_seen = ood_seen.max(s.out_of_range_ticks[2]);
            connected_early.get_or_insert(s.ticks < READY_AFTER);
            if s.ticks >= READY_AFTER + TICKS + 1_000 {
                break;
            }
        }
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "the daemon did not reach {TICKS} ticks in 300 s"
        );
        assert!(d.alive());
    }
    assert_eq!(
        connected_early,
        Some(true),
        "the plant connected only after counting began; raise ready_after_ticks"
    );
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(Duration::from_secs(20));
    assert!(st.success(), "{log}");
    let text = std::fs::read_to_string(&report).expect("allocation report written at exit");
    let get = |key: &str| -> u64 {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| panic!("{key} missing in {text}"))
            .parse()
            .unwrap()
    };
    let ticks = get("rt_counted_ticks");
    let allocs = get("rt_allocations");
    let exempt = get("rt_exempt_allocations");
    eprintln!(
        "RT thread: {allocs} allocations, {exempt} exempt (iceoryx2 loan) over {ticks} ticks"
    );
    assert!(ticks >= TICKS, "only {ticks} ticks counted");
    assert!(sets >= 100, "only {sets} runtime sets");
    let applied = get("rt_control_applied");
    assert_eq!(
        applied, sets,
        "every runtime set was applied by the RT thread"
    );
    assert_eq!(get("rt_control_dropped"), 0);
    assert_eq!(allocs, 0, "RT-thread allocations after READY: {text}");
    let lat = std::fs::read_to_string(&latency).expect("latency report written at exit");
    if extra_loop.contains("rt_threads = 2") {
        assert!(lat.contains("rt_threads=2\n"), "{lat}");
        let jobs: u64 = lat
            .lines()
            .find_map(|l| l.strip_prefix("helper_jobs="))
            .unwrap_or_else(|| panic!("helper_jobs missing: {lat}"))
            .parse()
            .unwrap();
        // At a 50 µs period on a loaded machine the helper is often still busy (late ticks get no
        // job, and with other processes on the CPUs most ticks are late): require jobs by the
        // thousand, not a share of the ticks.
        eprintln!("helper: {jobs} jobs over {ticks} counted ticks + {READY_AFTER} before");
        assert!(jobs >= TICKS / 20, "the helper ran only {jobs} jobs: {lat}");
    } else {
        assert!(lat.contains("rt_threads=1\n"), "{lat}");
    }
    assert!(
        ood_seen > 1_000,
        "the range check ran: {ood_seen} out-of-range ticks"
    );
    // The exemption is exactly iceoryx2's one allocation per published sample, nothing more:
    // at most one per command + one per status.
    assert!(
        exempt <= ticks + ticks / 1000 + 10,
        "{exempt} exempt over {ticks} ticks"
    );
}

/// The CAN backend with a CiA 402 drive (emulated, over a socketpair): TPDO / heartbeat decode,
/// the controlword sequencing, RPDO and SYNC every tick allocate nothing on the RT thread.
#[test]
fn rt_thread_allocates_nothing_with_a_cia402_drive() {
    use crate::can_support::{CHILD_FD, Cia402Emu, socketpair, start_daemon, write_can_config};
    const READY_AFTER: u64 = 2_000;
    const TICKS: u64 = 10_000;
    let env = TestEnv::new("alloc_cia402");
    let cfg = write_can_config(
        &env,
        &format!(
            r#"
[loop]
period_us = 1000
status_every_ticks = 100
ready_after_ticks = {READY_AFTER}
[safety]
stale_after_ticks = 50
on_stale = "zero"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55
[[bus]]
interface = "fd:{CHILD_FD}"
bitrate = 1000000
protocol = "cia402"
max_load = 0.9
feedback_timeout_ticks = 20
[[bus.joint]]
joint = "knee"
node_id = 4
command_unit = "motor_torque"
[bus.joint.cia402]
fault_reset = true
velocity_unit_rad_s = 0.0015339807878856412
joint_encoder = {{ index = 0x60E4, sub = 1, bits = 32, counts_per_rev = 40960 }}
heartbeat_ms = 10
"#
        ),
    );
    let (test_end, daemon_end) = socketpair();
    let emu = Cia402Emu::start(test_end, 4);
    let report = env.dir.join("alloc_report.txt");
    let mut d = start_daemon(
        &cfg,
        Some(&daemon_end),
        &[("FRICTIOND_ALLOC_REPORT", report.to_str().unwrap())],
    );
    drop(daemon_end);
    let mut plant = Plant::open(&env.ipc, "controller");
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 1;
    rq.enable_mask = 1;
    let t0 = std::time::Instant::now();
    let mut k = 0u64;
    let mut enabled_seen = false;
    loop {
        k += 1;
        rq.tau_des_nm[0] = 5.0 * (k as f64 * 0.01).sin();
        plant.seq += 1;
        rq.seq = plant.seq;
        plant.request.publish(&rq).unwrap();
        std::thread::sleep(Duration::from_millis(1));
        enabled_seen |= emu.node.lock().unwrap().state()
            == frictionless_drives::can::cia402::DriveState::OperationEnabled;
        if let Some(s) = plant.status.latest().unwrap()
            && s.ticks >= READY_AFTER + TICKS
        {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the daemon did not reach {TICKS} ticks in 120 s"
        );
        if !d.alive() {
            let (st, log) = d.wait_exit(Duration::from_secs(5));
            panic!("frictiond exited ({st}): {log}");
        }
    }
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(Duration::from_secs(20));
    assert!(st.success(), "{log}");
    assert!(
        enabled_seen,
        "the drive never reached operation enabled: {log}"
    );
    assert!(emu.syncs.load(std::sync::atomic::Ordering::Relaxed) > TICKS);
    let text = std::fs::read_to_string(&report).expect("allocation report written at exit");
    let get = |key: &str| -> u64 {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| panic!("{key} missing in {text}"))
            .parse()
            .unwrap()
    };
    let (ticks, allocs) = (get("rt_counted_ticks"), get("rt_allocations"));
    eprintln!("CiA 402: {allocs} RT-thread allocations over {ticks} ticks");
    assert!(ticks >= TICKS, "only {ticks} ticks counted");
    assert_eq!(allocs, 0, "RT-thread allocations after READY: {text}");
    // SIGTERM: quick stop, then NMT stop.
    let n = emu.node.lock().unwrap();
    assert_eq!(n.nmt(), frictionless_drives::can::cia402::NmtState::Stopped);
    assert_ne!(
        n.state(),
        frictionless_drives::can::cia402::DriveState::OperationEnabled
    );
}
