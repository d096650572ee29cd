//! `frictiond` with `[backend] kind = "can"` on the host, without kernel CAN: the daemon inherits one
//! end of a `socketpair(AF_UNIX, SOCK_SEQPACKET)` as `interface = "fd:10"` and opens it as a real
//! `socketcan::CanSocket`; the test holds the other end and emulates two MIT drives, and is the
//! controller over shared memory. The same scenarios run on a real vcan in `vcan_daemon.rs`.
//! Also: `frictiond --check` refusing an overloaded bus and bad `[[bus]]` keys with the numbers, and a
//! PINN whose inputs the drives cannot supply (joint values derived from the motor encoder, no
//! temperature).

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::process::Command;
use std::time::Duration;

use crate::can_support::*;
use crate::daemon_support::{Plant, TestEnv, frictiond_bin, repo_root};
use frictionless_drives::can::mit::MitSpecial;
use frictionless_shm_types::{BusKind, CAN_DETAIL_ERROR_PASSIVE};
use socketcan::{CanErrorFrame, CanFrame, CanSocket, Socket};

const T: Duration = Duration::from_secs(20);

fn dup(s: &CanSocket) -> CanSocket {
    // SAFETY: F_DUPFD_CLOEXEC on a descriptor we own returns a new descriptor we then own.
    let fd = unsafe { libc::fcntl(s.as_raw_fd(), libc::F_DUPFD_CLOEXEC, 3) };
    assert!(fd >= 0);
    // SAFETY: fd is new and owned by nobody else.
    CanSocket::from(unsafe { OwnedFd::from_raw_fd(fd) })
}

#[test]
fn can_daemon_over_socketpair_follows_the_law_and_fails_safe() {
    let env = TestEnv::new("canpair");
    let cfg = write_can_config(&env, &mit_body(&format!("fd:{CHILD_FD}"), 1000));
    let (test_end, daemon_end) = socketpair();
    let injector = dup(&test_end);
    let v_motor = [-30.0, 12.0];
    let emu = MitEmulator::start(test_end, v_motor);
    let mut d = start_daemon(&cfg, Some(&daemon_end), &[]);
    drop(daemon_end);
    let mut plant = Plant::open(&env.ipc, "controller");
    plant.wait_for_daemon(T);

    closed_loop_scenario(&mut plant, &emu, v_motor);

    // Error frames (as a controller would report them) reach DaemonStatus.bus.
    let bus_off = CanErrorFrame::new_error(0x40, &[]).unwrap();
    let passive = CanErrorFrame::new_error(0x04, &[0, 0x20]).unwrap();
    for f in [bus_off, passive, passive] {
        injector.write_frame(&CanFrame::Error(f)).unwrap();
    }
    let rq = request([0.0, 0.0]);
    let s = plant.status_until(None, T, |s| s.bus.error_reports >= 3);
    assert_eq!(
        (
            s.bus.error_reports,
            s.bus.link_down,
            s.bus.detail[CAN_DETAIL_ERROR_PASSIVE]
        ),
        (3, 1, 2)
    );
    assert!(
        s.bus.tx_messages > 0 && s.bus.rx_messages > 0,
        "{:?}",
        s.bus
    );
    assert_eq!(s.bus.bus_kind(), Some(BusKind::Can), "{:?}", s.bus);
    drive_until(&mut plant, &rq, T, |c| {
        c.i_ref_a[0] == 0.0 || c.i_ref_a[0] != 0.0
    });

    // Numbers, not asserts: wake-up to published command as the daemon measures it.
    let s = plant.status_until(None, T, |s| s.compute.total > 0);
    println!(
        "bench: frictiond CAN tick on host (2 MIT joints, socketpair): mean {:.1} us, p99 <= {:.1} us, max {:.1} us over {} ticks",
        s.compute.mean_ns() / 1e3,
        s.compute.quantile_upper_ns(0.99) as f64 / 1e3,
        s.compute.max_ns as f64 / 1e3,
        s.compute.total
    );

    // SIGTERM: zero currents, then the drives leave motor mode.
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    for id in [1, 2] {
        let l = emu.log(id);
        assert_eq!(l.specials.last(), Some(&MitSpecial::ExitMotorMode), "{l:?}");
        assert!(l.last_t.abs() <= t_tol(id), "{l:?}");
    }
}

#[test]
fn can_rt_thread_allocates_nothing_over_socketpair() {
    // At 1 kHz (a faster loop would exceed the 1 Mbit/s budget of two MIT drives and be refused).
    const READY_AFTER: u64 = 2_000;
    const TICKS: u64 = 10_000;
    let env = TestEnv::new("canalloc");
    let body = mit_body(&format!("fd:{CHILD_FD}"), 1000)
        .replace(
            "ready_after_ticks = 10",
            &format!("ready_after_ticks = {READY_AFTER}"),
        )
        .replace("status_every_ticks = 10", "status_every_ticks = 1000")
        .replace("stale_after_ticks = 20", "stale_after_ticks = 60000")
        .replace(
            "feedback_timeout_ticks = 10",
            "feedback_timeout_ticks = 100000",
        );
    let cfg = write_can_config(&env, &body);
    let (test_end, daemon_end) = socketpair();
    let emu = MitEmulator::start(test_end, [-30.0, 12.0]);
    let report = env.dir.join("alloc_report.txt");
    let mut d = start_daemon(
        &cfg,
        Some(&daemon_end),
        &[("FRICTIOND_ALLOC_REPORT", report.to_str().unwrap())],
    );
    drop(daemon_end);
    let mut plant = Plant::open(&env.ipc, "controller");
    plant.wait_for_daemon(T);
    let t0 = std::time::Instant::now();
    let mut k = 0u64;
    let mut connected_early = None;
    loop {
        k += 1;
        let x = (k as f64 * 0.05).sin();
        let mut rq = request([3.0 * x, -1.5 * x]);
        rq.enable_mask = if k % 50 < 45 { 0b11 } else { 0b01 };
        plant.seq += 1;
        rq.seq = plant.seq;
        rq.stamp_ns = frictionless_shm_types::monotonic_ns();
        plant.request.publish(&rq).unwrap();
        std::thread::sleep(Duration::from_millis(1));
        if let Some(s) = plant.status.latest().unwrap() {
            connected_early.get_or_insert(s.ticks < READY_AFTER);
            if s.ticks >= READY_AFTER + TICKS {
                break;
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "too slow");
        assert!(d.alive());
    }
    assert_eq!(connected_early, Some(true), "raise ready_after_ticks");
    assert!(emu.log(1).commands > TICKS, "{:?}", emu.log(1));
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    let text = std::fs::read_to_string(&report).expect("allocation report");
    let get = |key: &str| -> u64 {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| panic!("{key} missing in {text}"))
            .parse()
            .unwrap()
    };
    let (ticks, allocs, exempt) = (
        get("rt_counted_ticks"),
        get("rt_allocations"),
        get("rt_exempt_allocations"),
    );
    eprintln!("CAN backend RT thread: {allocs} allocations, {exempt} exempt over {ticks} ticks");
    assert!(ticks >= TICKS);
    assert_eq!(allocs, 0, "{text}");
    assert!(exempt <= ticks + ticks / 1000 + 10, "{exempt} over {ticks}");
}

fn check(env: &TestEnv, body: &str) -> (bool, String) {
    let cfg = write_can_config(env, body);
    let out = Command::new(frictiond_bin())
        .arg("--config")
        .arg(&cfg)
        .arg("--check")
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

#[test]
fn can_check_refuses_an_overloaded_bus_and_names_bad_keys() {
    let env = TestEnv::new("cancheck");
    let good = mit_body("can0", 1000);
    let (ok, text) = check(&env, &good);
    assert!(ok, "{text}");
    // 2 MIT joints at 4 kHz on 1 Mbit/s: 2 × 250 bits × 4000 = 200 %.
    let (ok, text) = check(&env, &good.replace("period_us = 1000", "period_us = 250"));
    assert!(!ok);
    for needle in [
        "bus[0].max_load",
        "16000 frames/s",
        "250 bits",
        "200.0 %",
        "limit 70.0 %",
    ] {
        assert!(text.contains(needle), "{needle}: {text}");
    }
    let (ok, text) = check(&env, &good.replacen("node_id = 2", "node_id = 1", 1));
    assert!(
        !ok && text.contains("bus[0].joint[1].node_id") && text.contains("duplicate"),
        "{text}"
    );
    let (ok, text) = check(&env, &good.replacen("t_max = 1", "t_max = 0.5", 1));
    assert!(
        !ok && text.contains("bus[0].joint[0].t_max") && text.contains("0.5"),
        "{text}"
    );
}

/// A random `.fwt` for the hip (r = HIP_R, k_t = HIP_KT) with the given inputs.
fn hip_model(env: &TestEnv, spec: frictionless::features::FeatureSpec) -> std::path::PathBuf {
    use frictionless::random::{RandomMlpSpec, seeded_mlp};
    use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
    let path = env
        .dir
        .join(format!("hip_{}_{}.fwt", spec.set, spec.temperature));
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: "hip".into(),
            gear_ratio: frictionless::units::GearRatio::new(HIP_R).unwrap(),
            kt_nm_per_a: HIP_KT,
            features: spec,
            scv: None,
            training: TrainingMeta::unknown("can_backend test", 0),
        },
        dtype: frictionless::mlp::StorageDtype::F32,
        mlp: seeded_mlp(&RandomMlpSpec::new(&[spec.n_inputs(), 4, 1]), 3).unwrap(),
    };
    frictionless::weights::write_file(&path, &file).unwrap();
    path
}

#[test]
fn can_check_refuses_models_the_drives_cannot_feed() {
    use frictionless::features::{FeatureSet, FeatureSpec};
    let env = TestEnv::new("canfeat");
    let good = mit_body("can0", 1000);
    let hip_none = "max_curr = 4.0\nfriction_model = \"none\"";
    assert!(good.contains(hip_none));
    let with = |set: FeatureSet, temperature: bool| {
        let spec = FeatureSpec {
            set,
            history: 4,
            temperature,
        };
        let m = hip_model(&env, spec);
        check(
            &env,
            &good.replacen(
                hip_none,
                &format!(
                    "max_curr = 4.0\nfriction_model = \"pinn\"\nmodel = \"{}\"",
                    m.display()
                ),
                1,
            ),
        )
    };
    for set in [
        FeatureSet::JointVel,
        FeatureSet::JointPosJointVel,
        FeatureSet::MotorVelJointVel,
    ] {
        let (ok, text) = with(set, false);
        assert!(ok, "{set}: {text}");
    }
    let (ok, text) = with(FeatureSet::DeltaThetaJointVel, false);
    assert!(!ok);
    for needle in [
        "joint[1].model",
        "joint hip",
        "`delta-theta-joint-vel`",
        "`s_rad`",
        "protocol = \"mit\"",
    ] {
        assert!(text.contains(needle), "{needle}: {text}");
    }
    let (ok, text) = with(FeatureSet::JointVel, true);
    assert!(
        !ok && text.contains("`temperature_c`") && text.contains("`joint-vel`"),
        "{text}"
    );
}

#[test]
fn can_example_configs_validate() {
    let root = repo_root();
    for name in [
        "config/can_mit.toml",
        "config/can_odrive.toml",
        "config/can_cia402.toml",
    ] {
        let out = Command::new(frictiond_bin())
            .arg("--config")
            .arg(root.join(name))
            .arg("--check")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{name}: {text}");
        assert!(
            text.contains("l_knee") && text.contains("l_ankle_roll"),
            "{text}"
        );
    }
}

#[test]
fn can_reload_of_values_fixed_at_open_is_refused_naming_them() {
    let env = TestEnv::new("canhup");
    let body = mit_body(&format!("fd:{CHILD_FD}"), 1000);
    let cfg = write_can_config(&env, &body);
    let (test_end, daemon_end) = socketpair();
    let v_motor = [-30.0, 12.0];
    let emu = MitEmulator::start(test_end, v_motor);
    let mut d = start_daemon(&cfg, Some(&daemon_end), &[]);
    drop(daemon_end);
    let mut plant = Plant::open(&env.ipc, "controller");
    plant.wait_for_daemon(T);
    // The hip asks for 6 A: clamped at its max_curr = 4 A.
    let tau = [3.0, 30.0];
    let want = expected_currents(tau, v_motor);
    assert_eq!(want[1], 4.0);
    let rq = request(tau);
    drive_until(&mut plant, &rq, T, |c| {
        (c.i_ref_a[0] - want[0]).abs() < 1e-9
    });

    // kt 0.157 → 0.18 (the CAN unit conversion), a raised max_curr (the CAN clamp), another node id.
    let changed = body
        .replacen(&format!("kt = {KNEE_KT}"), "kt = 0.18", 1)
        .replacen("max_curr = 4.0", "max_curr = 6.0", 1)
        .replacen(
            "feedback_timeout_ticks = 10",
            "feedback_timeout_ticks = 12",
            1,
        );
    assert_ne!(changed, body);
    write_can_config(&env, &changed);
    d.signal(libc::SIGHUP);
    for _ in 0..300 {
        drive_until(&mut plant, &rq, T, |_| true);
    }
    // What the law commands and what reaches the drives agree: knee motor torque = kt·i with one
    // kt, hip current = the law's (clamped) current.
    let t0 = std::time::Instant::now();
    loop {
        let c = drive_until(&mut plant, &rq, T, |_| true);
        let (k, h) = (emu.log(1), emu.log(2));
        let knee_ok = (k.last_t - KNEE_KT * want[0]).abs() <= t_tol(1)
            && (c.i_ref_a[0] - want[0]).abs() < 1e-9;
        let hip_ok = (h.last_t - c.i_ref_a[1]).abs() <= t_tol(2) && c.i_ref_a[1] == 4.0;
        if knee_ok && hip_ok {
            break;
        }
        assert!(
            t0.elapsed() < T,
            "half-applied reload: law knee {} A (want {}), wire knee {} Nm (want {}); law hip {} A, wire hip {} A",
            c.i_ref_a[0],
            want[0],
            k.last_t,
            KNEE_KT * want[0],
            c.i_ref_a[1],
            h.last_t
        );
    }
    let s = plant.status_until(None, T, |_| true);
    assert_eq!(s.generation, 0, "the reload was refused");

    // Values the backend does not hold still reload: kc only.
    let only_law = body.replace(
        &format!("kc = {}", KNEE_CV.0),
        &format!("kc = {}", KNEE_CV.0 * 0.5),
    );
    assert_ne!(only_law, body);
    write_can_config(&env, &only_law);
    d.signal(libc::SIGHUP);
    let s = plant.status_until(None, T, |s| s.generation == 1);
    assert_eq!(s.generation, 1);

    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    for needle in [
        "needs a restart",
        "knee",
        "kt 0.157 → 0.18",
        "hip",
        "max_curr 4 → 6",
        "feedback_timeout_ticks 10 → 12",
    ] {
        assert!(log.contains(needle), "{needle}: {log}");
    }
    assert!(
        !log.contains("reloaded") || log.matches("reloaded").count() == 1,
        "{log}"
    );
}

#[test]
fn can_sighup_applies_kfc_and_refuses_kt_node_id_gear_ratio_over_socketpair() {
    // The scenario `vcan_daemon_sighup_applies_kfc_and_refuses_kt_node_id_gear_ratio` runs on vcan.
    let env = TestEnv::new("canhup2");
    let body = mit_body(&format!("fd:{CHILD_FD}"), 1000);
    let cfg = write_can_config(&env, &body);
    let (test_end, daemon_end) = socketpair();
    let v_motor = [-30.0, 12.0];
    let emu = MitEmulator::start(test_end, v_motor);
    let mut d = start_daemon(&cfg, Some(&daemon_end), &[]);
    drop(daemon_end);
    let mut plant = Plant::open(&env.ipc, "controller");
    sighup_scenario(&env, &body, &mut d, &mut plant, &emu, v_motor);
}
