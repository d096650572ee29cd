//! The controller of `benches/soak.sh`: answers every `JointStates` from the plant (`frictl sim
//! serve`) with a `TorqueRequest` (both joints enabled, a PD law tracking a slow sine), so frictiond
//! runs its full model + law path every tick for the whole soak. Not a benchmark of its own.
//!
//! Environment: `FLD_SOAK_PREFIX`, `FLD_SOAK_ROOT` (iceoryx2 service prefix and root path, as in the
//! daemon's `[backend]`), `FLD_SOAK_JOINTS` (default 2). Without `FLD_SOAK_PREFIX` (e.g. `cargo
//! bench` over every bench) it does nothing. SIGTERM ends it; it prints the requests sent.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use frictionless_shm_types::{Ipc, IpcConfig, TorqueRequest, monotonic_ns};

fn main() {
    let Ok(prefix) = std::env::var("FLD_SOAK_PREFIX") else {
        eprintln!(
            "soak_controller: FLD_SOAK_PREFIX unset, nothing to do (used by benches/soak.sh)"
        );
        return;
    };
    let root = std::env::var("FLD_SOAK_ROOT").ok();
    let n_joints: usize = std::env::var("FLD_SOAK_JOINTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2)
        .clamp(1, 64);
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, stop.clone()).expect("signal handler");
    }
    let cfg = IpcConfig::new(root.as_deref().map(Path::new), &prefix);
    let ipc = Ipc::open(&cfg, "soak_controller").expect("iceoryx2 node");
    let states = ipc.joint_states().unwrap().inbox().unwrap();
    let request = ipc.torque_request().unwrap().outbox().unwrap();
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = n_joints as u32;
    rq.enable_mask = if n_joints == 64 {
        u64::MAX
    } else {
        (1u64 << n_joints) - 1
    };
    // A gentle PD around a 0.2 Hz, 0.3 rad sine: the joints move through both velocity signs.
    let (kp_nm_rad, kd_nm_s_rad) = (40.0, 2.0);
    let mut last_seq = 0u64;
    let mut sent = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let Ok(Some(js)) = states.wait_latest(Duration::from_millis(20)) else {
            continue;
        };
        if js.seq == last_seq {
            continue;
        }
        last_seq = js.seq;
        let t_s = js.seq as f64 * 1e-3;
        for j in 0..n_joints {
            let w = 2.0 * std::f64::consts::PI * 0.2;
            let s_ref = 0.3 * (w * t_s + j as f64).sin();
            let sdot_ref = 0.3 * w * (w * t_s + j as f64).cos();
            let (s, sdot) = (js.s_rad[j], js.sdot_rad_s[j]);
            rq.tau_des_nm[j] = if s.is_finite() && sdot.is_finite() {
                kp_nm_rad * (s_ref - s) + kd_nm_s_rad * (sdot_ref - sdot)
            } else {
                0.0
            };
        }
        rq.seq = js.seq;
        rq.state_seq = js.seq;
        rq.stamp_ns = monotonic_ns();
        if request.publish(&rq).is_ok() {
            sent += 1;
        }
    }
    eprintln!("soak_controller: {sent} requests");
}
