//! End-to-end tests of `frictiond` with real processes: the test process is the plant (publishes
//! JointStates/TorqueRequest, reads MotorCurrentCommand/DaemonStatus) against a spawned daemon. Each
//! test uses its own iceoryx2 root path and service prefix. No timing asserts beyond generous bounds.

use std::time::Duration;

use crate::daemon_support::*;
use frictionless_shm_types::{FLAG_CURRENT_SATURATED, FLAG_NON_FINITE, FLAG_STALE};

#[test]
fn currents_follow_the_control_law_joint_by_joint() {
    let env = TestEnv::new("law");
    let cfg = env.write_config(THREE_JOINTS);
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    let cases = [
        // moderate torques, mixed velocities (CV clip active on the knee: |f| > 6 above the gate)
        ([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]),
        // below the knee's velocity gate: no clip
        ([-1.0, 0.0, 0.0], [0.0, 0.01, 0.001]),
        // huge torque: clamps on every joint
        ([500.0, -500.0, 500.0], [1.0, -1.0, 1.0]),
    ];
    for (tau, v) in cases {
        let (js, rq) = inputs(tau, v);
        let want = expected(tau, v);
        let c = plant.until(&js, &rq, T, |c| {
            (0..3).all(|k| close(c.i_ref_a[k], want[k]))
        });
        assert_eq!(c.valid_mask, 0b111);
        assert_eq!(c.n_joints, 3);
        for k in 0..3 {
            assert_eq!(c.flags[k] & FLAG_STALE, 0);
        }
    }
    // The clamp case is flagged.
    let (js, rq) = inputs([500.0, -500.0, 500.0], [1.0, -1.0, 1.0]);
    let c = plant.until(&js, &rq, T, |c| c.flags[0] & FLAG_CURRENT_SATURATED != 0);
    assert_eq!(c.i_ref_a[0], 5.0);
    assert_eq!(
        c.i_ref_a[2], -3.0,
        "negative ratio: +τ → −i, clamped at 3 A"
    );
    // Disabling a joint gives 0 A and clears its valid bit.
    let (js, mut rq) = inputs([1.0, 1.0, 1.0], [0.1, 0.1, 0.1]);
    rq.enable_mask = 0b101;
    let c = plant.until(&js, &rq, T, |c| c.valid_mask == 0b101);
    assert_eq!(c.i_ref_a[1], 0.0);
    assert!(d.alive());
}

#[test]
fn non_finite_or_huge_input_on_one_joint_zeroes_only_that_joint() {
    let env = TestEnv::new("nan");
    let cfg = env.write_config(THREE_JOINTS);
    let _d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    let good_tau = [1.0, 1.0, 0.5];
    let good_v = [0.2, 0.2, 0.2];
    let want = expected(good_tau, good_v);
    for (k, field) in [(1usize, "sdot"), (2, "tau"), (0, "tau")] {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let (mut js, mut rq) = inputs(good_tau, good_v);
            if field == "sdot" {
                js.sdot_rad_s[k] = bad;
            } else {
                rq.tau_des_nm[k] = bad;
            }
            let c = plant.until(&js, &rq, T, |c| c.flags[k] & FLAG_NON_FINITE != 0);
            assert_eq!(c.i_ref_a[k], 0.0, "joint {k} {field}={bad}");
            for o in (0..3).filter(|&o| o != k) {
                assert!(
                    close(c.i_ref_a[o], want[o]),
                    "joint {o} disturbed by joint {k}: {} vs {}",
                    c.i_ref_a[o],
                    want[o]
                );
            }
        }
    }
    // Huge but finite: clamped, not zeroed; others unaffected.
    let (mut js, mut rq) = inputs(good_tau, good_v);
    rq.tau_des_nm[1] = 1e300;
    js.sdot_rad_s[2] = 1e300;
    let c = plant.until(&js, &rq, T, |c| c.flags[1] & FLAG_CURRENT_SATURATED != 0);
    assert_eq!(c.i_ref_a[1], -5.0);
    assert!(c.i_ref_a[2].abs() <= 3.0 && c.i_ref_a[2].is_finite());
    assert!(close(c.i_ref_a[0], want[0]));
    // Recovery: all good again.
    let (js, rq) = inputs(good_tau, good_v);
    plant.until(&js, &rq, T, |c| {
        (0..3).all(|k| close(c.i_ref_a[k], want[k]))
    });
}

#[test]
fn stale_input_gives_the_safe_output_and_recovers() {
    for on_stale in ["zero", "static_model"] {
        let env = TestEnv::new("stale");
        let cfg = env.write_config(
            &THREE_JOINTS.replace("on_stale = \"zero\"", &format!("on_stale = \"{on_stale}\"")),
        );
        let mut d = Daemon::start(&cfg, &[]);
        let mut plant = Plant::open(&env.ipc, "plant");
        let tau = [2.0, 1.0, 0.5];
        let v = [0.3, 0.4, -0.2];
        let (js, rq) = inputs(tau, v);
        let want = expected(tau, v);
        plant.until(&js, &rq, T, |c| {
            (0..3).all(|k| close(c.i_ref_a[k], want[k]))
        });
        // Keep the torque request fresh, stop the joint states.
        let t0 = std::time::Instant::now();
        let mut seen_stale = None;
        while t0.elapsed() < T {
            let mut r = rq;
            r.seq += 1;
            r.stamp_ns = frictionless_shm_types::monotonic_ns();
            plant.request.publish(&r).unwrap();
            std::thread::sleep(Duration::from_millis(1));
            if let Some(c) = plant.cmd.latest().unwrap()
                && (0..3).all(|k| c.flags[k] & FLAG_STALE != 0)
            {
                seen_stale = Some(c);
                break;
            }
        }
        let c = seen_stale.expect("stale output within the bound");
        for k in 0..3 {
            let safe = match on_stale {
                "zero" => 0.0,
                _ => current_ref(
                    tau[k],
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    0.0,
                    [0.157, 0.157, 0.0665][k],
                    [100.0, -100.0, -160.0][k],
                    [5.0, 5.0, 3.0][k],
                ),
            };
            assert!(
                close(c.i_ref_a[k], safe),
                "{on_stale} joint {k}: {}",
                c.i_ref_a[k]
            );
        }
        // Recovery as soon as fresh states arrive.
        plant.until(&js, &rq, T, |c| {
            (0..3).all(|k| close(c.i_ref_a[k], want[k]) && c.flags[k] & FLAG_STALE == 0)
        });
        assert!(d.alive());
        // Request stale too (controller gone): 0 A whatever the policy.
        let c = plant.until_silent(T, |c| c.flags[0] & FLAG_STALE != 0);
        assert_eq!(&c.i_ref_a[..3], &[0.0; 3]);
    }
}

#[test]
fn sigterm_publishes_zero_currents_and_exits_zero() {
    let env = TestEnv::new("term");
    let cfg = env.write_config(THREE_JOINTS);
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    let (js, rq) = inputs([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    plant.until(&js, &rq, T, |c| c.i_ref_a[0] != 0.0);
    d.signal(libc::SIGTERM);
    let c = plant.until_silent(T, |c| c.valid_mask == 0b111 && c.i_ref_a[..3] == [0.0; 3]);
    assert_eq!(
        c.valid_mask, 0b111,
        "zero is a valid command for every joint"
    );
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "exit status {st:?}; log:\n{log}");
}

#[test]
fn sighup_switches_to_a_valid_model_and_keeps_the_old_on_a_corrupt_one() {
    sighup_switch("hup", THREE_JOINTS);
}

/// The same with `rt_threads = 2`: the knee (joint 1) is the helper thread's joint, so the new
/// parameters reach the helper through the same hand-over.
#[test]
fn sighup_switches_models_with_two_rt_threads() {
    let base = THREE_JOINTS.replace("[loop]\n", "[loop]\nrt_threads = 2\n");
    assert_ne!(base, THREE_JOINTS);
    sighup_switch("hup2", &base);
}

fn sighup_switch(tag: &str, base: &str) {
    let env = TestEnv::new(tag);
    let cfg = env.write_config(base);
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    let tau = [0.0, 0.0, 0.0];
    let v = [0.3, 0.3, 0.3];
    let (js, rq) = inputs(tau, v);
    let old = expected(tau, v);
    plant.until(&js, &rq, T, |c| close(c.i_ref_a[1], old[1]));

    // A valid new model for the knee: CV with kc = 2.
    env.write_config_at(&cfg, &base.replace("kc = 8.1", "kc = 2.0"));
    d.signal(libc::SIGHUP);
    let new1 = current_ref(
        0.0,
        cv_ref(2.0, 50.84, 5.55, 0.3),
        0.3,
        0.05,
        6.0,
        0.85,
        0.157,
        -100.0,
        5.0,
    );
    assert!(!close(new1, old[1]));
    plant.until(&js, &rq, T, |c| close(c.i_ref_a[1], new1));
    let s = plant.status_until(Some((&js, &rq)), T, |s| s.generation == 1);
    assert_eq!(s.generation, 1);

    // A corrupt model file: the reload is rejected, the running model stays.
    std::fs::write(env.dir.join("bad.fwt"), b"this is not a weight file").unwrap();
    env.write_config_at(
        &cfg,
        &base.replace(
            "friction_model = \"cv\"\nkc = 8.1\nka = 50.84\nkv = 5.55",
            "friction_model = \"pinn\"\nmodel = \"bad.fwt\"",
        ),
    );
    d.signal(libc::SIGHUP);
    // Also a syntactically broken file.
    std::thread::sleep(Duration::from_millis(300));
    std::fs::write(&cfg, "[[joint]\nname = ").unwrap();
    d.signal(libc::SIGHUP);
    std::thread::sleep(Duration::from_millis(300));
    for _ in 0..3 {
        let c = plant.until(&js, &rq, T, |_| true);
        assert!(
            close(c.i_ref_a[1], new1),
            "kept the running model: {}",
            c.i_ref_a[1]
        );
    }
    let s = plant.status_until(Some((&js, &rq)), T, |_| true);
    assert_eq!(
        s.generation, 1,
        "rejected reloads do not bump the generation"
    );
    assert!(d.alive());
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    assert!(log.contains("reload rejected"), "{log}");
    assert!(log.contains("bad.fwt"), "the log names the bad file: {log}");
}

#[test]
fn notify_socket_sees_ready_watchdog_reloading_ready_stopping_in_order() {
    use std::os::unix::net::UnixDatagram;
    let env = TestEnv::new("sdn");
    let cfg = env.write_config(THREE_JOINTS);
    let sock_path = env.dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let mut d = Daemon::start(
        &cfg,
        &[
            ("NOTIFY_SOCKET", sock_path.to_str().unwrap()),
            ("WATCHDOG_USEC", "200000"),
        ],
    );
    let mut plant = Plant::open(&env.ipc, "plant");
    let (js, rq) = inputs([0.0; 3], [0.0; 3]);
    let mut seen: Vec<String> = Vec::new();
    let recv_until = |want: &str, seen: &mut Vec<String>, plant: &mut Plant| {
        let t0 = std::time::Instant::now();
        let mut buf = [0u8; 4096];
        while t0.elapsed() < T {
            plant.send(&js, &rq);
            if let Ok(n) = sock.recv(&mut buf) {
                let msg = String::from_utf8_lossy(&buf[..n]).to_string();
                seen.push(msg.clone());
                if msg.lines().any(|l| l == want || l.starts_with(want)) {
                    return msg;
                }
            }
        }
        panic!("{want} not received; seen {seen:?}");
    };
    recv_until("READY=1", &mut seen, &mut plant);
    recv_until("WATCHDOG=1", &mut seen, &mut plant);
    d.signal(libc::SIGHUP);
    let m = recv_until("RELOADING=1", &mut seen, &mut plant);
    assert!(m.contains("MONOTONIC_USEC="), "{m}");
    recv_until("READY=1", &mut seen, &mut plant);
    d.signal(libc::SIGTERM);
    recv_until("STOPPING=1", &mut seen, &mut plant);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    // Order check over everything seen: READY < WATCHDOG < RELOADING < READY < STOPPING.
    let pos = |pat: &str, from: usize| {
        seen.iter()
            .enumerate()
            .skip(from)
            .find(|(_, m)| m.contains(pat))
            .map(|(i, _)| i)
            .unwrap_or_else(|| panic!("{pat} after {from} missing in {seen:?}"))
    };
    let a = pos("READY=1", 0);
    let b = pos("WATCHDOG=1", a);
    let c = pos("RELOADING=1", b);
    let e = pos("READY=1", c);
    pos("STOPPING=1", e);
}

#[test]
fn check_mode_validates_without_ipc() {
    let env = TestEnv::new("check");
    let cfg = env.write_config(THREE_JOINTS);
    let out = std::process::Command::new(frictiond_bin())
        .args(["--check", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("knee_cv") && text.contains("ankle_scv") && text.contains("r=-160"),
        "{text}"
    );
    // No iceoryx2 files were created.
    let iox = env.ipc.root_path.clone().unwrap();
    assert_eq!(
        std::fs::read_dir(&iox).unwrap().count(),
        0,
        "--check touched IPC"
    );
    // A bad value: non-zero exit, message names file, key and value.
    env.write_config_at(
        &cfg,
        &THREE_JOINTS.replace("max_curr = 3.0", "max_curr = -3.0"),
    );
    let out = std::process::Command::new(frictiond_bin())
        .args(["--check", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("frictiond.toml") && err.contains("joint[2].max_curr") && err.contains("-3"),
        "{err}"
    );
}

#[test]
fn shipped_configs_pass_check() {
    let root = repo_root();
    for name in [
        "config/ankle_knee.toml",
        "config/stress32.toml",
        "config/bench_two_joint.toml",
    ] {
        let out = std::process::Command::new(frictiond_bin())
            .args(["--check", "--config"])
            .arg(root.join(name))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// Child plant process for [`plant_killed_with_sigkill_and_restarted_daemon_keeps_running`]:
/// publishes fixed states and requests every ms until killed. Does nothing unless spawned by it.
#[test]
#[ignore = "helper: the child plant process, spawned by another test"]
fn child_plant_process() {
    let (Ok(prefix), Ok(root)) = (
        std::env::var("FLD_CHILD_PREFIX"),
        std::env::var("FLD_CHILD_ROOT"),
    ) else {
        return;
    };
    let ipc = frictionless_shm_types::IpcConfig::new(Some(std::path::Path::new(&root)), &prefix);
    let node = frictionless_shm_types::Ipc::open(&ipc, "child_plant").unwrap();
    let states = node.joint_states().unwrap().outbox().unwrap();
    let request = node.torque_request().unwrap().outbox().unwrap();
    let (mut js, mut rq) = inputs([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    for seq in 1.. {
        let now = frictionless_shm_types::monotonic_ns();
        js.seq = seq;
        js.stamp_ns = now;
        rq.seq = seq;
        rq.stamp_ns = now;
        request.publish(&rq).unwrap();
        states.publish(&js).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn plant_killed_with_sigkill_and_restarted_daemon_keeps_running() {
    let env = TestEnv::new("kill");
    let cfg = env.write_config(THREE_JOINTS);
    let mut d = Daemon::start(&cfg, &[]);
    let spawn_child = || {
        std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                // The libtest name of `child_plant_process` in this binary (module path, no crate).
                "daemon_e2e::child_plant_process",
                "--ignored",
                "--test-threads=1",
            ])
            .env("FLD_CHILD_PREFIX", &env.ipc.service_prefix)
            .env("FLD_CHILD_ROOT", env.ipc.root_path.as_ref().unwrap())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let node = frictionless_shm_types::Ipc::open(&env.ipc, "observer").unwrap();
    let cmd = node.motor_current_command().unwrap().inbox().unwrap();
    let want = expected([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    let wait_for = |pred: &dyn Fn(&frictionless_shm_types::MotorCurrentCommand) -> bool| {
        let t0 = std::time::Instant::now();
        while t0.elapsed() < T {
            if let Some(c) = cmd.wait_latest(Duration::from_millis(20)).unwrap()
                && pred(&c)
            {
                return c;
            }
        }
        panic!("no matching command within {T:?}");
    };
    for round in 0..2 {
        let mut child = spawn_child();
        let c = wait_for(&|c| c.flags[0] & FLAG_STALE == 0 && close(c.i_ref_a[1], want[1]));
        assert!(c.state_seq > 0, "round {round}");
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        let c = wait_for(&|c| (0..3).all(|k| c.flags[k] & FLAG_STALE != 0));
        assert_eq!(&c.i_ref_a[..3], &[0.0; 3], "round {round}");
        assert!(
            d.alive(),
            "daemon survived the plant's SIGKILL (round {round})"
        );
    }
    // After the second kill a third plant still connects (dead publishers were cleaned up).
    let mut child = spawn_child();
    wait_for(&|c| c.flags[0] & FLAG_STALE == 0 && close(c.i_ref_a[2], want[2]));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(d.alive());
}
