//! State → command latency across processes: this process publishes a `JointStates` (and the
//! `TorqueRequest` answering it), a real `frictiond` (the binary of this package) computes and
//! publishes the `MotorCurrentCommand`, this process wakes on it (iceoryx2 listener, blocking).
//! Measured from just before the state is published to the wake-up with the answering command.
//!
//! - `lockstep` trigger: the daemon wakes on the inputs — pure IPC + compute latency (one round
//!   trip of two event wake-ups);
//! - `clock` trigger: the daemon ticks at 1 kHz on its own phase and this process publishes every
//!   997 µs, sweeping every phase — the realistic latency (uniform 0–1 period + IPC + compute).
//!
//! Prints p50/p99/p99.9/max [µs]; no asserts. `FRICTIOND_LATENCY_N` samples per trigger (default
//! 20 000 lockstep, a quarter of that with the clock). Run: `cargo bench -p frictiond --bench latency`.
//! The daemon config is the shared fixture `config/bench_two_joint.toml` (joints, `[safety]`) plus this
//! run's `[backend]` and `[loop]`.

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use frictionless_shm_types::{Ipc, IpcConfig, JointStates, TorqueRequest, monotonic_ns};

/// The shared two-joint fixture (`config/bench_two_joint.toml`), up to its per-run marker.
const FIXTURE: &str = include_str!("../../config/bench_two_joint.toml");
/// The marker line after which the fixture's own `[backend]`/`[loop]` start.
const PER_RUN_MARKER: &str = "# ---- per-run sections";

/// The bench's `[loop]` (`TRIGGER` replaced per run).
const LOOP: &str = r#"
[loop]
period_us = 1000
status_every_ticks = 100
ready_after_ticks = 10
trigger = "TRIGGER"
lockstep_wait_request = true
lockstep_timeout_ms = 5000
"#;

/// The fixture's joints and `[safety]`, this run's `[backend]` and `[loop]`.
fn config_text(prefix: &str, iox: &Path, trigger: &str) -> String {
    let (joints, _) = FIXTURE
        .split_once(PER_RUN_MARKER)
        .expect("config/bench_two_joint.toml lost its per-run marker line");
    format!(
        "{joints}\n[backend]\nkind = \"shm\"\nservice_prefix = \"{prefix}\"\nroot_path = \"{}\"\n{}",
        iox.display(),
        LOOP.replace("TRIGGER", trigger)
    )
}

fn quantile(sorted: &[u64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i] as f64 / 1e3
}

fn run(trigger: &str, n: usize, dir: &Path) {
    let prefix = format!("fld_lat_{trigger}_{}", std::process::id());
    let iox = dir.join(format!("iox_{trigger}"));
    std::fs::create_dir_all(&iox).unwrap();
    let cfg_path = dir.join(format!("{trigger}.toml"));
    std::fs::write(&cfg_path, config_text(&prefix, &iox, trigger)).unwrap();
    let mut daemon = Command::new(env!("CARGO_BIN_EXE_frictiond"))
        .arg("--config")
        .arg(&cfg_path)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn frictiond");
    let ipc = Ipc::open(&IpcConfig::new(Some(&iox), &prefix), "latency_bench").unwrap();
    let states = ipc.joint_states().unwrap().outbox().unwrap();
    let request = ipc.torque_request().unwrap().outbox().unwrap();
    let cmd = ipc.motor_current_command().unwrap().inbox().unwrap();
    let status_ch = ipc.daemon_status().unwrap();
    let t0 = Instant::now();
    while status_ch.publisher_count() == 0 {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "frictiond did not start"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut js = JointStates::zeroed();
    js.n_joints = 2;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 2;
    rq.enable_mask = 0b11;
    let warmup = 1000usize;
    let total = n + warmup;
    let mut lat = Vec::with_capacity(n);
    let mut publish = |k: u64| -> u64 {
        let x = k as f64 * 1e-3;
        js.sdot_rad_s[0] = x.sin();
        js.sdot_rad_s[1] = x.cos();
        rq.tau_des_nm[0] = x.cos();
        let t_pub = monotonic_ns();
        js.seq = k;
        js.stamp_ns = t_pub;
        rq.seq = k;
        rq.state_seq = k;
        rq.stamp_ns = t_pub;
        states.publish(&js).unwrap();
        request.publish(&rq).unwrap();
        t_pub
    };
    let lost = if trigger == "lockstep" {
        // Ping-pong: publish state k, wait for the command answering it (50 ms: counted as lost).
        let mut lost = 0u64;
        for k in 1..=total as u64 {
            let t_pub = publish(k);
            let give_up = t_pub + 50_000_000;
            let got = loop {
                if let Some(c) = cmd.latest().unwrap()
                    && c.state_seq >= k
                {
                    break Some(monotonic_ns());
                }
                let now = monotonic_ns();
                if now >= give_up {
                    break None;
                }
                cmd.wait(Duration::from_nanos((give_up - now).min(5_000_000)))
                    .unwrap();
            };
            match got {
                Some(t) if k > warmup as u64 => lat.push(t - t_pub),
                Some(_) => {}
                None => lost += 1,
            }
        }
        lost
    } else {
        // A publisher thread with its own node publishes on absolute 997 µs deadlines (never
        // waiting for answers — that would lock the phase to just after the daemon's tick — and
        // sweeping every phase of the daemon's 1 ms grid); this thread times each state's first
        // answering command. States superseded before the daemon's next tick are never answered
        // (counted as lost).
        let t_pub: Arc<Vec<AtomicU64>> = Arc::new((0..=total).map(|_| AtomicU64::new(0)).collect());
        let published = Arc::new(AtomicUsize::new(0));
        let publisher = {
            let (t_pub, published) = (t_pub.clone(), published.clone());
            let (iox, prefix) = (iox.clone(), prefix.clone());
            std::thread::spawn(move || {
                let ipc = Ipc::open(&IpcConfig::new(Some(&iox), &prefix), "latency_pub").unwrap();
                let states = ipc.joint_states().unwrap().outbox().unwrap();
                let request = ipc.torque_request().unwrap().outbox().unwrap();
                let mut js = JointStates::zeroed();
                js.n_joints = 2;
                let mut rq = TorqueRequest::zeroed();
                rq.n_joints = 2;
                rq.enable_mask = 0b11;
                let period = 997_000u64;
                let mut next = monotonic_ns() + period;
                for k in 1..=total {
                    frictionless_shm_types::sleep_until_ns(next);
                    next += period;
                    let now = monotonic_ns();
                    js.seq = k as u64;
                    js.stamp_ns = now;
                    js.sdot_rad_s[0] = (k as f64 * 1e-3).sin();
                    rq.seq = k as u64;
                    rq.state_seq = k as u64;
                    rq.stamp_ns = now;
                    t_pub[k].store(now, Ordering::Release);
                    published.store(k, Ordering::Release);
                    states.publish(&js).unwrap();
                    request.publish(&rq).unwrap();
                }
            })
        };
        let mut answered = vec![false; total + 1];
        let mut last_seen = monotonic_ns();
        loop {
            if let Some(c) = cmd.latest().unwrap() {
                let t = monotonic_ns();
                let s = c.state_seq as usize;
                if (1..=total).contains(&s) && !answered[s] {
                    answered[s] = true;
                    last_seen = t;
                    if s > warmup {
                        lat.push(t - t_pub[s].load(Ordering::Acquire));
                    }
                }
            }
            let done = published.load(Ordering::Acquire) == total;
            if done && (answered[total] || monotonic_ns() > last_seen + 50_000_000) {
                break;
            }
            cmd.wait(Duration::from_millis(5)).unwrap();
        }
        publisher.join().unwrap();
        answered[warmup + 1..].iter().filter(|a| !**a).count() as u64
    };
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(daemon.id() as i32, libc::SIGTERM) };
    let _ = daemon.wait();
    lat.sort_unstable();
    println!(
        "state→command latency, {trigger:<8} trigger: n={:<6} p50 {:>7.1} µs  p99 {:>7.1} µs  p99.9 {:>7.1} µs  max {:>8.1} µs  (lost {lost})",
        lat.len(),
        quantile(&lat, 0.5),
        quantile(&lat, 0.99),
        quantile(&lat, 0.999),
        lat.last().map_or(f64::NAN, |&m| m as f64 / 1e3),
    );
}

fn main() {
    // `cargo test` runs benches once with `--test`... harness = false gets the raw args: keep the
    // smoke run short.
    let smoke = std::env::args().all(|a| a != "--bench");
    let n: usize = std::env::var("FRICTIOND_LATENCY_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if smoke { 200 } else { 20_000 });
    let dir = std::env::temp_dir().join(format!("fld_latency_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    run("lockstep", n, &dir);
    run("clock", (n / 4).max(100), &dir);
    let _ = std::fs::remove_dir_all(&dir);
}
