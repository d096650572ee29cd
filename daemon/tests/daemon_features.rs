//! Feature sets for robots without a motor encoder, end to end through real processes: `frictiond`
//! runs a `joint-pos-joint-vel` and a `joint-vel` PINN (`.fwt` written by the test) in lockstep while
//! the test, as the plant, publishes NaN motor angle, motor velocity and temperature (a torque-sensed
//! arm). Offline, the test builds the input vectors of the recorded states with the core's `History`
//! (the layout the `.fwt` header names) and runs the real `frictl predict` on them; the daemon's
//! current on every tick must be the control law applied to that τ̂_F (1e-9 A, as `daemon_pinn`).
//! The `frictl` binary is the one `tests/run.sh` builds next to `frictiond` (the test is
//! `#[ignore]`d; `tests/run.sh` runs it with `--include-ignored`).
//!
//! A LuGre joint needs the joint velocity alone: on the same torque-sensed samples its current must be
//! the law applied to the core's `LugreEstimator` run offline over those samples (what `frictl eval`'s
//! `predict` does: reset at the enable edge, one estimate per sample), re-enabled midway (the
//! bristle state restarts at 0).

use std::io::Write;
use std::path::Path;
use std::process::Command;

use crate::daemon_support::*;
use frictionless::features::{FeatureSet, FeatureSpec, History, JointSample};
use frictionless::mlp::StorageDtype;
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{
    FLAG_NON_FINITE, FLAG_STALE, FLAG_WARMING_UP, JointStates, MotorCurrentCommand, TorqueRequest,
};

const R: f64 = 100.0;
const KT: f64 = 0.12;
const KFC: f64 = 0.9;
const MAX_I: f64 = 50.0;
const H: usize = 8;
const SETS: [FeatureSet; 2] = [FeatureSet::JointPosJointVel, FeatureSet::JointVel];
const NAMES: [&str; 2] = ["arm_pos_vel", "arm_vel"];

/// A random network for joint `name` with the inputs of `set` (H samples per block).
fn model_file(name: &str, set: FeatureSet, seed: u64) -> ModelFile {
    let features = FeatureSpec {
        set,
        history: H,
        temperature: false,
    };
    let mlp = RandomMlpSpec {
        sizes: vec![features.n_inputs(), 16, 1],
        weights: WeightInit::Uniform { amp: 0.7 },
        bias: -0.2..0.2,
        norm: NormInit::Identity,
    };
    ModelFile {
        meta: ModelMeta {
            joint_name: name.into(),
            gear_ratio: GearRatio::new(R).unwrap(),
            kt_nm_per_a: KT,
            features,
            scv: None,
            training: TrainingMeta::unknown("daemon_features test", 0),
        },
        dtype: StorageDtype::F32,
        mlp: seeded_mlp(&mlp, seed).unwrap(),
    }
}

fn config() -> String {
    let mut c = String::from(LOCKSTEP_LOOP_AND_SAFETY);
    for (k, (name, set)) in NAMES.iter().zip(SETS).enumerate() {
        c.push_str(&format!(
            r#"
[[joint]]
name = "{name}"
index = {k}
gear_ratio = {R:?}
kt = {KT:?}
max_curr = {MAX_I:?}
kfc = {KFC:?}
friction_model = "pinn"
model = "{set}.fwt"
warmup = "hold_zero"
"#
        ));
    }
    c
}

/// Joint motion at step `k`; no motor encoder, no temperature sensor.
fn sample(k: u64) -> JointSample {
    let t = k as f64 * 1e-3;
    JointSample {
        s_rad: 0.4 * (2.5 * t).sin() + 0.05 * (11.0 * t).sin(),
        sdot_rad_s: 1.0 * (2.5 * t).cos() + 0.55 * (11.0 * t).cos(),
        theta_motor_rad: f64::NAN,
        omega_motor_rad_s: f64::NAN,
        temperature_c: f64::NAN,
    }
}

fn tau_des(k: u64) -> f64 {
    1.2 * (k as f64 * 0.013).sin()
}

fn step(plant: &mut Plant, k: u64) -> MotorCurrentCommand {
    step_masked(plant, k, 0b11)
}

fn step_masked(plant: &mut Plant, k: u64, enable_mask: u64) -> MotorCurrentCommand {
    let x = sample(k);
    let mut js = JointStates::zeroed();
    js.n_joints = 2;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 2;
    rq.enable_mask = enable_mask;
    for j in 0..2 {
        js.s_rad[j] = x.s_rad;
        js.sdot_rad_s[j] = x.sdot_rad_s;
        js.theta_motor_rad[j] = x.theta_motor_rad;
        js.omega_motor_rad_s[j] = x.omega_motor_rad_s;
        js.temperature_c[j] = x.temperature_c;
        rq.tau_des_nm[j] = tau_des(k);
    }
    let s = plant.publish_state(&js);
    plant.publish_request(&rq, s);
    let c = plant
        .command_for(s, T)
        .unwrap_or_else(|| panic!("no command for state {s}"));
    assert_eq!(c.state_seq, s, "one command per state");
    c
}

/// `frictl predict MODEL --input CSV` on `rows`: one τ̂_F [Nm] per row.
fn predict(frictl: &Path, model: &Path, csv: &Path, rows: &[Vec<f32>]) -> Vec<f32> {
    let mut f = std::fs::File::create(csv).unwrap();
    for r in rows {
        let line: Vec<String> = r.iter().map(|v| v.to_string()).collect();
        writeln!(f, "{}", line.join(",")).unwrap();
    }
    drop(f);
    let out = Command::new(frictl)
        .arg("predict")
        .arg(model)
        .arg("--input")
        .arg(csv)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "frictl predict: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| l.trim().parse::<f32>().unwrap())
        .collect()
}

#[test]
#[ignore = "needs the frictl binary beside frictiond: bash tests/run.sh"]
fn joint_pos_joint_vel_and_joint_vel_models_equal_frictl_predict_without_motor_encoder() {
    let frictl = frictl_bin();
    let env = TestEnv::new("features");
    let mut models = Vec::new();
    for (k, (name, set)) in NAMES.iter().zip(SETS).enumerate() {
        let path = env.dir.join(format!("{set}.fwt"));
        let f = model_file(name, set, 7 + k as u64);
        frictionless::weights::write_file(&path, &f).unwrap();
        models.push((path, f.meta.features));
    }
    let cfg = env.write_config(&config());
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);

    const TICKS: u64 = 200;
    let commands: Vec<MotorCurrentCommand> = (0..TICKS).map(|k| step(&mut plant, k)).collect();
    d.signal(libc::SIGTERM);
    let (status, log) = d.wait_exit(T);
    assert!(status.success(), "{log}");

    for (j, (path, spec)) in models.iter().enumerate() {
        // Offline: the inputs the header's layout gives for the recorded states (the history is
        // reset at the enable edge, tick 0, as the daemon does), then the real `frictl predict`.
        let mut h = History::new(*spec, GearRatio::new(R).unwrap()).unwrap();
        h.reset(&sample(0));
        let mut rows = Vec::new();
        let mut full_from = None;
        for k in 0..TICKS {
            h.push(&sample(k));
            if h.is_full() {
                full_from.get_or_insert(k);
                let mut x = vec![0f32; spec.n_inputs()];
                h.fill(&mut x).unwrap();
                assert!(x.iter().all(|v| v.is_finite()), "NaN θ, ω, T are not read");
                rows.push(x);
            }
        }
        let full_from = full_from.unwrap();
        assert_eq!(full_from, H as u64 - 1);
        let csv = env.dir.join(format!("inputs_{j}.csv"));
        let tau_f = predict(&frictl, path, &csv, &rows);
        assert_eq!(tau_f.len(), rows.len());

        let mut beyond_feed_forward = 0;
        for (k, c) in commands.iter().enumerate() {
            let k = k as u64;
            let x = sample(k);
            let warming = k < full_from;
            // hold_zero: no friction until H samples; then the network's τ̂_F, as predicted offline.
            let f = if warming {
                0.0
            } else {
                f64::from(tau_f[(k - full_from) as usize])
            };
            let want = current_ref(
                tau_des(k),
                f,
                x.sdot_rad_s,
                0.0,
                f64::INFINITY,
                KFC,
                KT,
                R,
                MAX_I,
            );
            assert!(
                (c.i_ref_a[j] - want).abs() <= 1e-9,
                "{} tick {k}: daemon {} A, frictl predict gives {want} A",
                spec.set,
                c.i_ref_a[j]
            );
            assert_eq!(
                c.flags[j] & FLAG_WARMING_UP != 0,
                warming,
                "{} tick {k}",
                spec.set
            );
            assert_eq!(
                c.flags[j] & (FLAG_STALE | FLAG_NON_FINITE),
                0,
                "{} tick {k}",
                spec.set
            );
            let ff = tau_des(k) / (KT * R);
            beyond_feed_forward += usize::from((c.i_ref_a[j] - ff).abs() > 1e-4);
        }
        assert!(
            beyond_feed_forward > 150,
            "{}: the network contributed on only {beyond_feed_forward} of {TICKS} ticks",
            spec.set
        );
    }
}

/// Two LuGre joints (stiff and soft bristles) in lockstep; joint 1 is disabled for ticks 80..100.
#[test]
fn lugre_joints_equal_the_offline_estimator_and_restart_at_enable() {
    use frictionless::lugre::{LugreEstimator, LugreParams};
    use frictionless::model::{FrictionModel, JointModel};
    let params = [
        LugreParams {
            kc: 0.8,
            kv: 0.3,
            ks: 1.3,
            vs: 0.08,
            alpha: 1.2,
            sigma0: 4.0e3,
            sigma1: 2.0,
        },
        LugreParams {
            kc: 0.5,
            kv: 0.1,
            ks: 0.9,
            vs: 0.2,
            alpha: 2.0,
            sigma0: 50.0,
            sigma1: 0.5,
        },
    ];
    let env = TestEnv::new("lugre");
    let mut c = String::from(LOCKSTEP_LOOP_AND_SAFETY);
    for (k, p) in params.iter().enumerate() {
        c.push_str(&format!(
            r#"
[[joint]]
name = "lugre_{k}"
index = {k}
gear_ratio = {R:?}
kt = {KT:?}
max_curr = {MAX_I:?}
kfc = {KFC:?}
friction_model = "lugre"
kc = {:?}
kv = {:?}
ks = {:?}
vs = {:?}
alpha = {:?}
sigma0 = {:?}
sigma1 = {:?}
"#,
            p.kc, p.kv, p.ks, p.vs, p.alpha, p.sigma0, p.sigma1
        ));
    }
    let cfg = env.write_config(&c);
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);

    const TICKS: u64 = 200;
    let enabled = |j: usize, k: u64| j == 0 || !(80..100).contains(&k);
    let mask = |k: u64| (0..2).fold(0u64, |m, j| m | u64::from(enabled(j, k)) << j);
    let commands: Vec<MotorCurrentCommand> = (0..TICKS)
        .map(|k| step_masked(&mut plant, k, mask(k)))
        .collect();
    d.signal(libc::SIGTERM);
    let (status, log) = d.wait_exit(T);
    assert!(status.success(), "{log}");

    for (j, p) in params.iter().enumerate() {
        // Offline, as `predict`: reset at each enable edge, one estimate per enabled sample.
        let mut m = JointModel::from(LugreEstimator::new(*p, 1e-3).unwrap());
        let mut was_enabled = false;
        let mut beyond_feed_forward = 0;
        for (k, c) in commands.iter().enumerate() {
            let k = k as u64;
            let x = sample(k);
            if !enabled(j, k) {
                was_enabled = false;
                continue;
            }
            if !was_enabled {
                m.reset(&x);
                was_enabled = true;
            }
            let f = m.estimate(&x);
            let want = current_ref(
                tau_des(k),
                f,
                x.sdot_rad_s,
                0.0,
                f64::INFINITY,
                KFC,
                KT,
                R,
                MAX_I,
            );
            assert!(
                (c.i_ref_a[j] - want).abs() <= 1e-9,
                "joint {j} tick {k}: daemon {} A, offline LuGre gives {want} A",
                c.i_ref_a[j]
            );
            assert_eq!(c.flags[j] & (FLAG_STALE | FLAG_NON_FINITE), 0, "tick {k}");
            let ff = tau_des(k) / (KT * R);
            beyond_feed_forward += usize::from((c.i_ref_a[j] - ff).abs() > 1e-4);
        }
        assert!(
            beyond_feed_forward > 150,
            "joint {j}: LuGre contributed on only {beyond_feed_forward} ticks"
        );
    }
}
