//! `frictiond` with six joints against the coupled leg, through real processes: `frictl sim serve
//! --preset leg --lockstep` (the plant), `frictiond` in lockstep with one SCV per joint (the
//! nominal steady-state friction of each joint's drive parameters, 25 °C), and the test process as
//! the controller (a PD per joint on its own reference, τ_des in a `TorqueRequest` answering each
//! state). The daemon cannot tell the leg from six single joints: the same payloads.
//!
//! Checks: every command carries all six joints; each joint moves; per joint, the friction the
//! daemon added (τ̂_F = i_ref·k_t·r − τ_des, with kfc = 1 and no clip) tracks the plant's true
//! friction τ_F of the same state while the joint moves (correlation and RMSE bounds).
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use frictionless_experiment::session::Binaries;
use frictionless_shm_types::sim::SimTruth;
use frictionless_shm_types::{
    FLAG_CURRENT_SATURATED, Inbox, Ipc, JointStates, MotorCurrentCommand, Outbox, TorqueRequest,
    monotonic_ns,
};
use frictionless_sim::{LegParams, PlantParams};

use crate::plant_common::{Plant, Scratch};

const TICKS: u64 = 3000;

/// The daemon's `[[joint]]` of leg joint `k`: its drive's constants and the SCV of its nominal
/// steady-state friction (motor side + LuGre at 25 °C, no ripple, no load term).
fn joint_section(k: usize, p: &PlantParams) -> String {
    format!(
        r#"
[[joint]]
name = "{name}"
index = {k}
gear_ratio = {r:?}
kt = {kt:?}
max_curr = {imax:?}
kfc = 1.0
max_output_friction = 200.0
friction_model = "coulomb_viscous_stribeck"
kc = {kc:?}
ka = 50.0
kv = {kv:?}
ks = {ks:?}
vs = {vs:?}
alpha = {alpha:?}
"#,
        name = p.joint,
        r = p.gear_ratio_signed,
        kt = p.kt_nm_per_a,
        imax = p.i_max_a,
        kc = p.f_c0_nm + p.f_cm_nm,
        kv = p.sigma2m_nms_per_rad + p.sigma2j_nms_per_rad,
        ks = p.f_s0_nm + p.f_cm_nm,
        vs = p.v_s_rad_s,
        alpha = p.stribeck_exponent,
    )
}

/// Reference of joint `j` at `t_s`: its own frequency and amplitude, starting at rest at 0 and
/// staying inside the joint's limits (the knee bends, negative).
fn reference(j: usize, t_s: f64) -> (f64, f64) {
    const AMP: [f64; 6] = [0.25, 0.2, 0.25, -0.3, 0.2, 0.15];
    let w = std::f64::consts::TAU * (0.5 + 0.1 * j as f64);
    (
        AMP[j] * (1.0 - (w * t_s).cos()),
        AMP[j] * w * (w * t_s).sin(),
    )
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (s / n as f64).sqrt()
}

/// Waits for the newest message of an inbox accepted by a predicate.
macro_rules! wait_for {
    ($inbox:expr, $what:expr, $ok:expr) => {{
        let end = Instant::now() + Duration::from_secs(20);
        loop {
            if let Some(m) = $inbox.latest().unwrap()
                && $ok(&m)
            {
                break m;
            }
            assert!(Instant::now() < end, "no {}", $what);
            let _ = $inbox.wait(Duration::from_millis(20));
        }
    }};
}

#[test]
fn frictiond_six_scv_joints_track_the_legs_true_friction_in_lockstep() {
    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond next to frictl (cargo build --workspace --bins)");
    let leg = LegParams::preset().unwrap();
    let joints = &leg.joints;
    let n = joints.len();
    assert_eq!(n, 6);

    let s = Scratch::new("legfd");
    let mut plant = Plant::spawn(
        &s,
        &[
            "--preset",
            "leg",
            "--lockstep",
            "--lockstep-subscribers",
            "2",
            "--seed",
            "3",
            "--duration-s",
            &format!("{}", TICKS as f64 * 1e-3),
        ],
    );
    // The controller's ports: inboxes before the request outbox.
    let ipc = Ipc::open(&s.config(), "leg_controller").unwrap();
    let states: Inbox<JointStates> = ipc.joint_states().unwrap().inbox().unwrap();
    let truth: Inbox<SimTruth> = ipc.sim_truth().unwrap().inbox().unwrap();
    let commands: Inbox<MotorCurrentCommand> =
        ipc.motor_current_command().unwrap().inbox().unwrap();
    let requests: Outbox<TorqueRequest> = ipc.torque_request().unwrap().outbox().unwrap();

    let mut cfg = format!(
        "[backend]\nkind = \"shm\"\nservice_prefix = \"{}\"\nroot_path = \"{}\"\n\n\
         [loop]\nperiod_us = 1000\nstatus_every_ticks = 100\nready_after_ticks = 5\n\
         trigger = \"lockstep\"\nlockstep_wait_request = true\nlockstep_timeout_ms = 20000\n\n\
         [safety]\nstale_after_ticks = 20\non_stale = \"zero\"\n",
        s.prefix,
        s.root().display()
    );
    for (k, p) in joints.iter().enumerate() {
        cfg.push_str(&joint_section(k, p));
    }
    let cfg_path = s.out().join("frictiond.toml");
    std::fs::create_dir_all(s.out()).unwrap();
    std::fs::write(&cfg_path, &cfg).unwrap();
    let log_path = s.out().join("frictiond.log");
    let mut daemon = Command::new(&bins.frictiond)
        .arg("--config")
        .arg(&cfg_path)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log_path).unwrap())
        .spawn()
        .expect("spawn frictiond");

    let tau_max: Vec<f64> = joints
        .iter()
        .map(|p| p.i_max_a * p.kt_nm_per_a * p.gear_ratio_signed.abs())
        .collect();
    // Per joint: (τ̂_F, τ_F,true) while moving, and how far it moved.
    let mut pairs: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); n];
    let mut moved = vec![0.0f64; n];
    let mut saturated = vec![0usize; n];
    let mut s0 = [0.0; 6];
    for k in 1..=TICKS {
        let st = wait_for!(states, "joint state", |m: &JointStates| m.seq >= k);
        assert_eq!(st.seq, k, "lockstep states one by one");
        let tr = wait_for!(truth, "sim truth", |m: &SimTruth| m.seq >= k);
        assert_eq!(tr.seq, k);
        assert_eq!(st.n_joints, 6);
        if k == 1 {
            s0[..n].copy_from_slice(&st.s_rad[..n]);
        }
        let t = (k - 1) as f64 * 1e-3;
        let mut rq = TorqueRequest::zeroed();
        rq.seq = k;
        rq.stamp_ns = monotonic_ns();
        rq.state_seq = k;
        rq.n_joints = n as u32;
        rq.enable_mask = (1 << n) - 1;
        for j in 0..n {
            let (q_ref, qd_ref) = reference(j, t);
            let kp = 2.0 * tau_max[j];
            let kd = 0.1 * kp;
            rq.tau_des_nm[j] =
                kp * (q_ref - (st.s_rad[j] - s0[j])) + kd * (qd_ref - st.sdot_rad_s[j]);
        }
        requests.publish(&rq).unwrap();
        let c = wait_for!(commands, "command", |m: &MotorCurrentCommand| m.state_seq
            >= k);
        assert_eq!(c.state_seq, k, "one command per state");
        assert_eq!(c.valid_mask, (1 << n) - 1, "every joint commanded: {c:?}");
        for (j, p) in joints.iter().enumerate() {
            moved[j] = moved[j].max((st.s_rad[j] - s0[j]).abs());
            if c.flags[j] & FLAG_CURRENT_SATURATED != 0 {
                saturated[j] += 1;
                continue;
            }
            if tr.sdot_true_rad_s[j].abs() > 0.05 && t > 0.5 {
                let hat = c.i_ref_a[j] * p.kt_nm_per_a * p.gear_ratio_signed - rq.tau_des_nm[j];
                pairs[j].0.push(hat);
                pairs[j].1.push(tr.tau_f_true_nm[j]);
            }
        }
    }
    let status = plant.wait_exit(Duration::from_secs(30));
    assert!(status.success(), "plant: {status:?}");
    // SAFETY: plain kill(2) on our own child.
    unsafe { libc::kill(daemon.id() as i32, libc::SIGTERM) };
    let st = daemon.wait().unwrap();
    let log = std::fs::read_to_string(&log_path).unwrap_or_default();
    assert!(st.success(), "frictiond: {st:?}\n{log}");

    for (j, p) in joints.iter().enumerate() {
        let (hat, truth) = &pairs[j];
        let r = corr(hat, truth);
        let err = rms(hat.iter().zip(truth).map(|(a, b)| a - b));
        let scale = rms(truth.iter().copied());
        eprintln!(
            "{:14} moved {:.3} rad, {} moving rows, {} saturated: corr(τ̂_F, τ_F) {r:.3}, \
             RMSE {err:.3} Nm (true τ_F RMS {scale:.3} Nm)",
            p.joint,
            moved[j],
            hat.len(),
            saturated[j]
        );
    }
    for (j, p) in joints.iter().enumerate() {
        let (hat, truth) = &pairs[j];
        assert!(moved[j] > 0.05, "{} moved only {} rad", p.joint, moved[j]);
        assert!(
            hat.len() > (TICKS as usize) / 4,
            "{}: only {} moving rows",
            p.joint,
            hat.len()
        );
        let r = corr(hat, truth);
        let err = rms(hat.iter().zip(truth).map(|(a, b)| a - b));
        let scale = rms(truth.iter().copied());
        assert!(r > 0.95, "{}: corr {r}", p.joint);
        assert!(err < 0.15 * scale, "{}: RMSE {err} vs RMS {scale}", p.joint);
    }
}
