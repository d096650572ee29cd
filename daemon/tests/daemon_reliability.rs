//! Faults between processes: a second daemon on the same service prefix, reloads that
//! change the loop period, a FIFO as config or model path, stale-input logging. Real `frictiond`
//! processes against the test process as the plant; each test has its own iceoryx2 root and prefix.

use std::path::Path;
use std::time::{Duration, Instant};

use crate::daemon_support::*;

/// [`THREE_JOINTS`] with a 30 Hz low-pass on the knee (its step response depends on the period the
/// filter was designed for), the lockstep trigger (one tick per state: deterministic sequences) and
/// `period_us`.
fn lpf_lockstep(period_us: u64) -> String {
    THREE_JOINTS
        .replace(
            "[loop]\nperiod_us = 1000\n",
            &format!(
                "[loop]\nperiod_us = {period_us}\ntrigger = \"lockstep\"\nlockstep_timeout_ms = 60000\n"
            ),
        )
        .replace(
            "joint_velocity_threshold_rad_s = 0.05\nfriction_model = \"cv\"",
            "joint_velocity_threshold_rad_s = 0.05\nlpf = { order = 2, cutoff_hz = 30.0 }\nfriction_model = \"cv\"",
        )
}

/// Lockstep: `idle` ticks with the knee disabled (a pending parameter hand-over happens there),
/// then the knee's current over `n` ticks after its enable edge (filter reset to 0: a step response).
fn knee_step_response(plant: &mut Plant, idle: usize, n: usize) -> Vec<f64> {
    let (js, mut rq) = inputs([0.0; 3], [0.3; 3]);
    rq.enable_mask = 0b101;
    for _ in 0..idle {
        let k = plant.publish_state(&js);
        plant.publish_request(&rq, k);
        plant
            .command_for(k, T)
            .expect("command while the knee is off");
    }
    rq.enable_mask = 0b111;
    (0..n)
        .map(|_| {
            let k = plant.publish_state(&js);
            plant.publish_request(&rq, k);
            plant.command_for(k, T).expect("command").i_ref_a[1]
        })
        .collect()
}

#[test]
fn reload_with_a_new_period_keeps_the_running_period_and_warns_every_time() {
    let env = TestEnv::new("period");
    let cfg = env.write_config(&lpf_lockstep(1000));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let before = knee_step_response(&mut plant, 5, 15);
    assert!(
        before[0].abs() < before[14].abs(),
        "a filtered step rises: {before:?}"
    );

    // The same joints with a 4 ms period: the loop keeps running at 1 ms, so must the filters.
    env.write_config_at(&cfg, &lpf_lockstep(4000));
    for reload in 1..=2u64 {
        d.signal(libc::SIGHUP);
        // Keep ticking (knee off) until the status shows the new generation.
        let (js, mut rq) = inputs([0.0; 3], [0.3; 3]);
        rq.enable_mask = 0b101;
        let t0 = Instant::now();
        loop {
            let k = plant.publish_state(&js);
            plant.publish_request(&rq, k);
            plant.command_for(k, T).expect("command");
            if let Some(s) = plant.status.latest().unwrap()
                && s.generation == reload
            {
                break;
            }
            assert!(t0.elapsed() < T, "reload {reload} not applied");
            std::thread::sleep(Duration::from_millis(2));
        }
        let after = knee_step_response(&mut plant, 1, 15);
        for (t, (a, b)) in before.iter().zip(&after).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * a.abs().max(1e-9),
                "reload {reload}, tick {t} after enable: {b} vs {a} before (filter designed for another period)\n{before:?}\n{after:?}"
            );
        }
    }
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    let warnings = log.matches("need a restart").count();
    assert_eq!(
        warnings, 2,
        "each reload with a changed [loop] warns (compared against the running config):\n{log}"
    );
}

#[test]
fn second_daemon_on_the_same_prefix_refuses_to_start_naming_the_first_pid() {
    let env = TestEnv::new("twice");
    let cfg = env.write_config(THREE_JOINTS);
    let mut first = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (js, rq) = inputs([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    let want = expected([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    plant.until(&js, &rq, T, |c| close(c.i_ref_a[1], want[1]));

    let mut second = Daemon::start(&cfg, &[]);
    // Give the second one time to come up (or refuse) while the plant keeps publishing.
    let t0 = Instant::now();
    while second.alive() && t0.elapsed() < Duration::from_secs(5) {
        plant.send(&js, &rq);
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(
        !second.alive(),
        "a second frictiond on the same prefix is still running: both would command the motors"
    );
    let (st, log) = second.wait_exit(T);
    assert!(!st.success(), "{log}");
    assert!(
        log.contains(&format!("{:?}", env.ipc.service_prefix)),
        "names the prefix: {log}"
    );
    assert!(
        log.contains(&format!("PID {}", first.pid())),
        "names the first daemon's PID: {log}"
    );
    // The first one is unaffected and keeps commanding; its command sequence only moves forward.
    assert!(first.alive());
    let mut last = 0;
    for _ in 0..50 {
        let c = plant.until(&js, &rq, T, |_| true);
        assert!(
            c.seq > last,
            "command seq went backwards: {} after {last}",
            c.seq
        );
        last = c.seq;
        assert!(close(c.i_ref_a[1], want[1]));
    }
    // After the first one stops, a new one starts on the same prefix (the lock dies with its holder).
    first.signal(libc::SIGTERM);
    let (st, log) = first.wait_exit(T);
    assert!(st.success(), "{log}");
    let mut third = Daemon::start(&cfg, &[]);
    plant.until(&js, &rq, T, |c| close(c.i_ref_a[1], want[1]));
    assert!(third.alive());
}

/// Makes a FIFO at `path`.
fn mkfifo(path: &std::path::Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

#[test]
fn sighup_with_a_fifo_as_model_or_config_keeps_sigterm_prompt_and_ends_at_zero_amps() {
    for what in ["model", "config"] {
        let env = TestEnv::new("fifo");
        let cfg = env.write_config(THREE_JOINTS);
        let mut d = Daemon::start(&cfg, &[]);
        let mut plant = Plant::open(&env.ipc, "plant");
        let (js, rq) = inputs([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
        plant.until(&js, &rq, T, |c| c.i_ref_a[0] != 0.0);
        let fifo = env.dir.join("fifo");
        mkfifo(&fifo);
        if what == "model" {
            env.write_config_at(
                &cfg,
                &THREE_JOINTS.replace(
                    "friction_model = \"cv\"\nkc = 8.1\nka = 50.84\nkv = 5.55",
                    "friction_model = \"pinn\"\nmodel = \"fifo\"",
                ),
            );
        } else {
            std::fs::remove_file(&cfg).unwrap();
            std::fs::rename(&fifo, &cfg).unwrap();
        }
        d.signal(libc::SIGHUP);
        // The reload refuses the FIFO before reading it (config or model); the loop runs on and
        // SIGTERM ends it.
        for _ in 0..20 {
            plant.send(&js, &rq);
            std::thread::sleep(Duration::from_millis(5));
        }
        d.signal(libc::SIGTERM);
        let t0 = Instant::now();
        while d.alive() && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(
            !d.alive(),
            "{what} FIFO: SIGTERM not handled (supervisor blocked in the reload)"
        );
        let (st, log) = d.wait_exit(T);
        assert!(st.success(), "{what}: {st:?}\n{log}");
        let c = plant.cmd.latest().unwrap().expect("a command");
        assert_eq!(c.i_ref_a[..3], [0.0; 3], "{what}: last command 0 A");
        assert!(
            log.contains("FIFO"),
            "{what}: the refusal names the file type: {log}"
        );
    }
}

/// `frictiond --config PATH --check` with a FIFO or a device as the config: refused at once, naming
/// the path and what it is (before, a FIFO blocked the start forever).
#[test]
fn a_config_that_is_a_fifo_or_a_device_is_refused_at_start() {
    let env = TestEnv::new("fifo-start");
    let fifo = env.dir.join("frictiond.toml");
    mkfifo(&fifo);
    for (path, what) in [
        (fifo.as_path(), "FIFO"),
        (Path::new("/dev/zero"), "character device"),
    ] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_frictiond"))
            .arg("--config")
            .arg(path)
            .arg("--check")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // A hang detector, not a timing assert: the refusal needs no I/O at all.
        let t0 = Instant::now();
        while child.try_wait().unwrap().is_none() && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
        if child.try_wait().unwrap().is_none() {
            child.kill().unwrap();
            panic!("frictiond --config {} --check hung", path.display());
        }
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(
            err.contains(&*path.to_string_lossy()) && err.contains(what),
            "{}: {err}",
            path.display()
        );
    }
}

#[test]
fn stale_input_is_logged_on_entry_and_recovery_rate_limited() {
    let env = TestEnv::new("stalelog");
    let cfg = env.write_config(THREE_JOINTS);
    let mut d = Daemon::start(&cfg, &[]);
    let started = Instant::now();
    let mut plant = Plant::open(&env.ipc, "plant");
    let (js, rq) = inputs([2.0, 1.0, 0.5], [0.3, 0.4, -0.2]);
    // Several stale episodes: fresh, then silent well past stale_after_ticks (20 ms).
    for _ in 0..4 {
        plant.until(&js, &rq, T, |c| {
            c.flags[0] & frictionless_shm_types::FLAG_STALE == 0
        });
        for _ in 0..100 {
            plant.send(&js, &rq);
            std::thread::sleep(Duration::from_millis(1));
        }
        plant.until_silent(T, |c| c.flags[0] & frictionless_shm_types::FLAG_STALE != 0);
        std::thread::sleep(Duration::from_millis(100));
    }
    plant.until(&js, &rq, T, |c| {
        c.flags[0] & frictionless_shm_types::FLAG_STALE == 0
    });
    std::thread::sleep(Duration::from_millis(200));
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    let entries = log.matches("input stale").count();
    let recoveries = log.matches("input fresh again").count();
    assert!(entries >= 1, "stale entry logged:\n{log}");
    assert!(recoveries >= 1, "recovery logged:\n{log}");
    // Five entries and five recoveries (the start, stale until the plant's first sample, is the
    // first entry), usually within two seconds: at most one line of each per 10 s window.
    let windows = 1 + started.elapsed().as_secs() as usize / 10;
    assert!(
        entries <= windows,
        "entries rate-limited ({windows} windows):\n{log}"
    );
    assert!(
        recoveries <= windows,
        "recoveries rate-limited ({windows} windows):\n{log}"
    );
}
