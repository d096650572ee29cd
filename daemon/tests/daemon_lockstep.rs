//! `frictiond` with `[loop] trigger = "lockstep"` against the test process as the plant (real
//! processes, real iceoryx2): one tick per joint state, no sleeping (the protocol in
//! docs/frictiond.md). Each test uses its own iceoryx2 root path and service prefix. No timing
//! asserts; the throughput test prints ticks/s.

use std::time::{Duration, Instant};

use crate::daemon_support::*;
use frictionless_shm_types::{FLAG_STALE, JointStates, TorqueRequest};

/// [`THREE_JOINTS`] with the lockstep trigger. The timeout is long so no tick runs on it while the
/// test drives the loop (a slow CI machine must not turn into spurious timeout ticks).
fn lockstep_config(wait_request: bool, timeout_ms: u64, ready_after: u64) -> String {
    THREE_JOINTS.replace(
        "[loop]\nperiod_us = 1000\nstatus_every_ticks = 10\nready_after_ticks = 10\n",
        &format!(
            "[loop]\nperiod_us = 1000\nstatus_every_ticks = 10\nready_after_ticks = {ready_after}\n\
             trigger = \"lockstep\"\nlockstep_wait_request = {wait_request}\nlockstep_timeout_ms = {timeout_ms}\n"
        ),
    )
}

/// A scripted, changing state/request sequence (covers clip, no clip, clamp, sign changes).
fn script(k: u64) -> ([f64; 3], [f64; 3]) {
    let x = k as f64 * 0.37;
    (
        [3.0 * x.sin(), 40.0 * (0.5 * x).cos(), 2.0 * (0.3 * x).sin()],
        [
            0.5 * x.cos(),
            0.08 * (1.3 * x).sin(),
            -0.4 * (0.7 * x).sin(),
        ],
    )
}

#[test]
fn commands_follow_the_law_one_per_state_with_matching_state_seq() {
    let env = TestEnv::new("lsdet");
    let cfg = env.write_config(&lockstep_config(true, NEVER_MS, 10));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let mut last_cmd_seq = None;
    for _ in 0..300 {
        let (tau, v) = script(plant.seq + 1);
        let (js, rq) = inputs(tau, v);
        let k = plant.publish_state(&js);
        plant.publish_request(&rq, k);
        let c = plant
            .command_for(k, T)
            .unwrap_or_else(|| panic!("no command for state {k}"));
        assert_eq!(c.state_seq, k, "the command answers exactly this state");
        let want = expected(tau, v);
        for (j, &w) in want.iter().enumerate().take(3) {
            assert!(
                close(c.i_ref_a[j], w),
                "state {k} joint {j}: {} vs {}",
                c.i_ref_a[j],
                w
            );
            assert_eq!(c.flags[j] & FLAG_STALE, 0, "state {k} joint {j}");
        }
        assert_eq!(c.valid_mask, 0b111);
        // One tick (one command) per state: the daemon's command seq advances by exactly one.
        if let Some(prev) = last_cmd_seq {
            assert_eq!(c.seq, prev + 1, "extra or missing tick before state {k}");
        }
        last_cmd_seq = Some(c.seq);
    }
    // No deadline in lockstep: no misses, no lateness samples.
    let (tau, v) = script(0);
    let (js, rq) = inputs(tau, v);
    let s = loop {
        let k = plant.publish_state(&js);
        plant.publish_request(&rq, k);
        plant.command_for(k, T).expect("command");
        if let Some(s) = plant.status.latest().unwrap()
            && s.ticks >= 300
        {
            break s;
        }
    };
    assert_eq!(s.missed_deadlines, 0);
    assert_eq!(s.lateness.total, 0, "lateness is not recorded in lockstep");
    assert!(s.compute.total >= 300);
    assert!(d.alive());
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
}

/// Long enough that no tick can run on the lockstep timeout while a test drives the loop, whatever
/// the load (a timeout tick answers the newest state, flagged stale, and would look like a tick
/// released without its request). The timeout path has its own test with a short timeout.
const NEVER_MS: u64 = 3_600_000;

#[test]
fn with_wait_request_no_command_until_the_answering_request_arrives() {
    let env = TestEnv::new("lswait");
    let cfg = env.write_config(&lockstep_config(true, NEVER_MS, 10));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    // On failure: stop the daemon and show its log next to the message.
    let outcome = wait_request_rounds(&mut plant);
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    if let Err(e) = outcome {
        panic!("{e}\n--- frictiond log ---\n{log}");
    }
    assert!(st.success(), "{log}");
}

/// The body of [`with_wait_request_no_command_until_the_answering_request_arrives`]: `Err` names the
/// round, the state and the offending command (with its flags: `FLAG_STALE` would mean a timeout
/// tick).
fn wait_request_rounds(plant: &mut Plant) -> Result<(), String> {
    let (js, rq) = inputs([1.0, 1.0, 1.0], [0.2, 0.2, 0.2]);
    // Prime: one complete step.
    let k = plant.publish_state(&js);
    plant.publish_request(&rq, k);
    let c = plant.command_for(k, T).ok_or("no first command")?;
    if c.state_seq != k {
        return Err(format!("first command answers {} not {k}", c.state_seq));
    }
    for round in 0..5 {
        let k = plant.publish_state(&js);
        // No request yet: nothing answers state k.
        if let Some(c) = plant.command_for(k, Duration::from_millis(200)) {
            return Err(format!(
                "round {round}: a command for state {k} came before its request: {c:?}"
            ));
        }
        // A request answering an older state does not release the tick either.
        plant.publish_request(&rq, k - 1);
        if let Some(c) = plant.command_for(k, Duration::from_millis(200)) {
            return Err(format!(
                "round {round}: a request for state {} released state {k}: {c:?}",
                k - 1
            ));
        }
        // The answering request does, with the request's torques, fresh (not a timeout tick).
        let (_, rq2) = inputs([2.0, -1.0, 0.5], [0.2, 0.2, 0.2]);
        plant.publish_request(&rq2, k);
        let c = plant
            .command_for(k, T)
            .ok_or_else(|| format!("round {round}: no command after the request for {k}"))?;
        let want = expected([2.0, -1.0, 0.5], [0.2, 0.2, 0.2]);
        if c.state_seq != k
            || (0..3).any(|j| !close(c.i_ref_a[j], want[j]) || c.flags[j] & FLAG_STALE != 0)
        {
            return Err(format!(
                "round {round}: command for {k} (want i_ref {want:?}, not stale): {c:?}"
            ));
        }
    }
    Ok(())
}

#[test]
fn without_wait_request_every_state_ticks_and_a_timeout_makes_inputs_stale() {
    let env = TestEnv::new("lsnowait");
    let cfg = env.write_config(&lockstep_config(false, 300, 10));
    let _d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (js, rq) = inputs([1.0, 1.0, 1.0], [0.2, 0.2, 0.2]);
    plant.publish_request(&rq, 0);
    let want = expected([1.0, 1.0, 1.0], [0.2, 0.2, 0.2]);
    for _ in 0..20 {
        let k = plant.publish_state(&js);
        let c = plant.command_for(k, T).expect("a command per state");
        assert_eq!(c.state_seq, k);
        assert!((0..3).all(|j| close(c.i_ref_a[j], want[j])), "{c:?}");
    }
    // The plant goes silent: after lockstep_timeout_ms a tick runs anyway, flagged stale, 0 A.
    let c = plant.until_silent(T, |c| c.flags[0] & FLAG_STALE != 0);
    assert_eq!(&c.i_ref_a[..3], &[0.0; 3]);
    // And recovers on the next state.
    let c = plant.until(&js, &rq, T, |c| c.flags[0] & FLAG_STALE == 0);
    assert!((0..3).all(|j| close(c.i_ref_a[j], want[j])), "{c:?}");
}

#[test]
fn throughput_and_zero_allocations_over_20k_lockstep_ticks() {
    const READY_AFTER: u64 = 1_000;
    const TICKS: u64 = 20_000;
    let env = TestEnv::new("lsthru");
    let cfg = env.write_config(&lockstep_config(true, NEVER_MS, READY_AFTER));
    let report = env.dir.join("alloc.txt");
    let mut d = Daemon::start(
        &cfg,
        &[("FRICTIOND_ALLOC_REPORT", report.to_str().unwrap())],
    );
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (mut js, mut rq): (JointStates, TorqueRequest) = inputs([0.0; 3], [0.0; 3]);
    let mut step = |plant: &mut Plant, k: u64| {
        let (tau, v) = script(k);
        js.sdot_rad_s[..3].copy_from_slice(&v);
        rq.tau_des_nm[..3].copy_from_slice(&tau);
        let s = plant.publish_state(&js);
        plant.publish_request(&rq, s);
        let c = plant.command_for(s, T).expect("command");
        assert_eq!(c.state_seq, s);
    };
    for k in 0..READY_AFTER + 10 {
        step(&mut plant, k);
    }
    let t0 = Instant::now();
    for k in 0..TICKS {
        step(&mut plant, k);
    }
    let dt = t0.elapsed().as_secs_f64();
    eprintln!(
        "lockstep throughput: {TICKS} state→request→command round trips in {dt:.2} s = {:.0} ticks/s ({:.1} µs per tick)",
        TICKS as f64 / dt,
        dt / TICKS as f64 * 1e6
    );
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
    assert!(get("rt_counted_ticks") >= TICKS, "{text}");
    assert_eq!(
        get("rt_allocations"),
        0,
        "lockstep RT-thread allocations: {text}"
    );
}

/// One lockstep run of the scripted sequence (with a NaN velocity, a disabled joint and a fault now
/// and then) against a daemon with `extra` appended to `[loop]`; every command's currents (bits)
/// and flags, in state order.
fn scripted_run(tag: &str, extra: &str) -> Vec<([u64; 3], [u32; 3], u64)> {
    let env = TestEnv::new(tag);
    let cfg = env.write_config(&lockstep_config(true, NEVER_MS, 10).replace(
        "trigger = \"lockstep\"\n",
        &format!("trigger = \"lockstep\"\n{extra}"),
    ));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let mut out = Vec::new();
    for step in 0..400u64 {
        let (tau, v) = script(step);
        let (mut js, mut rq) = inputs(tau, v);
        if step % 37 == 5 {
            js.sdot_rad_s[(step % 3) as usize] = f64::NAN;
        }
        if step % 50 >= 45 {
            rq.enable_mask = 0b101;
        }
        if step % 61 == 7 {
            js.fault_flags[2] = 1;
        }
        let k = plant.publish_state(&js);
        plant.publish_request(&rq, k);
        let c = plant
            .command_for(k, T)
            .unwrap_or_else(|| panic!("{tag}: no command for state {k}"));
        assert_eq!(c.state_seq, k);
        out.push((
            [0, 1, 2].map(|j| c.i_ref_a[j].to_bits()),
            [0, 1, 2].map(|j| c.flags[j]),
            c.valid_mask,
        ));
    }
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    out
}

/// `[loop] rt_threads = 2` (a helper thread computes part of the joints) gives the commands of one
/// RT thread bit for bit, state by state — with and without prefetching.
#[test]
fn two_rt_threads_command_what_one_does_bit_for_bit() {
    let one = scripted_run("rt1", "");
    assert!(
        one.iter()
            .filter(|(i, _, _)| i.iter().any(|&b| f64::from_bits(b) != 0.0))
            .count()
            > 300,
        "the joints were driven"
    );
    for (tag, extra) in [
        ("rt2", "rt_threads = 2\n"),
        ("rt2pf", "rt_threads = 2\nprefetch = \"lead\"\n"),
    ] {
        let two = scripted_run(tag, extra);
        assert_eq!(one.len(), two.len());
        for (k, (a, b)) in one.iter().zip(&two).enumerate() {
            assert_eq!(
                a, b,
                "{tag}: state {k} (currents as bits, flags, valid mask)"
            );
        }
    }
}
