//! A minimal 1 kHz plant for `benches/lateness.sh`: publishes `JointStates` and a `TorqueRequest`
//! (two enabled joints, slowly varying values) on absolute CLOCK_MONOTONIC deadlines, so the
//! daemon under measurement runs its full compute path. Not a simulator (that is `frictl sim`).
//!
//! Environment: `FLD_PLANT_PREFIX`, `FLD_PLANT_ROOT` (iceoryx2 service prefix and root path, as in
//! the daemon's `[backend]`), `FLD_PLANT_SECONDS` (default 10), `FLD_PLANT_JOINTS` (default 2; 32 for
//! `config/stress32.toml`). Without `FLD_PLANT_PREFIX` (e.g.
//! `cargo bench` over every bench) it does nothing. SIGTERM ends it cleanly (ports dropped, no stale
//! shared-memory files).

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use frictionless_shm_types::{Ipc, IpcConfig, JointStates, TorqueRequest, monotonic_ns};
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_nanosleep};

fn main() {
    let Ok(prefix) = std::env::var("FLD_PLANT_PREFIX") else {
        eprintln!(
            "lateness_plant: FLD_PLANT_PREFIX unset, nothing to do (used by benches/lateness.sh)"
        );
        return;
    };
    let root = std::env::var("FLD_PLANT_ROOT").ok();
    let seconds: f64 = std::env::var("FLD_PLANT_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, stop.clone()).expect("signal handler");
    }
    let n_joints: usize = std::env::var("FLD_PLANT_JOINTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2)
        .clamp(1, 64);
    let cfg = IpcConfig::new(root.as_deref().map(Path::new), &prefix);
    let ipc = Ipc::open(&cfg, "lateness_plant").expect("iceoryx2 node");
    let states = ipc.joint_states().unwrap().outbox().unwrap();
    let request = ipc.torque_request().unwrap().outbox().unwrap();
    let mut js = JointStates::zeroed();
    js.n_joints = n_joints as u32;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = n_joints as u32;
    rq.enable_mask = if n_joints == 64 {
        u64::MAX
    } else {
        (1u64 << n_joints) - 1
    };
    let period = 1_000_000u64;
    let start = monotonic_ns();
    let end = start + (seconds * 1e9) as u64;
    let mut deadline = start + period;
    let mut k = 0u64;
    while deadline < end && !stop.load(Ordering::Relaxed) {
        let ts = TimeSpec::new(
            (deadline / 1_000_000_000) as _,
            (deadline % 1_000_000_000) as _,
        );
        while let Err(nix::errno::Errno::EINTR) = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &ts,
        ) {}
        k += 1;
        let t = k as f64 * 1e-3;
        for j in 0..n_joints {
            js.s_rad[j] = 0.3 * (2.0 * t).sin();
            js.sdot_rad_s[j] = 0.6 * (2.0 * t).cos();
            js.theta_motor_rad[j] = -100.0 * js.s_rad[j];
            js.omega_motor_rad_s[j] = -100.0 * js.sdot_rad_s[j];
            rq.tau_des_nm[j] = (0.5 * t).sin();
        }
        let now = monotonic_ns();
        js.seq = k;
        js.stamp_ns = now;
        rq.seq = k;
        rq.state_seq = k;
        rq.stamp_ns = now;
        let _ = request.publish(&rq);
        let _ = states.publish(&js);
        deadline += period;
    }
    eprintln!("lateness_plant: published {k} states");
}
