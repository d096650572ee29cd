//! PINN friction compensation end to end: a `.fwt` written by the test (`frictionless::weights`),
//! `frictiond` with `friction_model = "pinn"` in lockstep (so the daemon sees exactly the samples
//! the test sends), the test process as the plant. The expected current comes from the control
//! law with τ̂_F from a `frictionless::model::PinnEstimator` fed the same samples in the test.
//! Also: the warm-up flag (both policies), SIGHUP to a new `.fwt` (switch without a lost tick) and
//! to a corrupt one (the running model stays), and one non-finite sample costing its own tick only.

use std::path::Path;
use std::time::Duration;

use crate::daemon_support::*;
use frictionless::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use frictionless::mlp::StorageDtype;
use frictionless::model::{FrictionModel, PinnEstimator};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{
    FLAG_NON_FINITE, FLAG_STALE, FLAG_WARMING_UP, JointStates, MotorCurrentCommand, TorqueRequest,
};

const R: f64 = -100.0;
const KT: f64 = 0.157;
const KFC: f64 = 0.8;
const MAX_I: f64 = 50.0;
const H: usize = 10;

/// A random 2H → 16 → 12 → 1 network with the paper's feature set `[Δθ ×H, ṡ ×H]`.
fn model_file(seed: u64) -> ModelFile {
    let features = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: H,
        temperature: false,
    };
    let mlp = RandomMlpSpec {
        sizes: vec![features.n_inputs(), 16, 12, 1],
        weights: WeightInit::Uniform { amp: 0.6 },
        bias: -0.2..0.2,
        norm: NormInit::Identity,
    };
    ModelFile {
        meta: ModelMeta {
            joint_name: "knee".into(),
            gear_ratio: GearRatio::new(R).unwrap(),
            kt_nm_per_a: KT,
            features,
            scv: None,
            training: TrainingMeta::unknown("daemon_pinn test", 0),
        },
        dtype: StorageDtype::F32,
        mlp: seeded_mlp(&mlp, seed).unwrap(),
    }
}

/// Joint 0: PINN `hold_zero`; joint 1: the same kind of model with `zero_pad`.
fn config(model0: &str, model1: &str) -> String {
    format!(
        r#"{LOCKSTEP_LOOP_AND_SAFETY}
[[joint]]
name = "knee"
index = 0
gear_ratio = {R:?}
kt = {KT:?}
max_curr = {MAX_I:?}
kfc = {KFC:?}
friction_model = "pinn"
model = "{model0}"
warmup = "hold_zero"

[[joint]]
name = "knee_zero_pad"
index = 1
gear_ratio = {R:?}
kt = {KT:?}
max_curr = {MAX_I:?}
kfc = {KFC:?}
friction_model = "pinn"
model = "{model1}"
model_for = "knee"
warmup = "zero_pad"
"#
    )
}

/// Joint motion at step `k`: a sinusoid with a small transmission deflection.
fn sample(k: u64) -> JointSample {
    let t = k as f64 * 1e-3;
    let s = 0.3 * (3.0 * t).sin();
    let sdot = 0.9 * (3.0 * t).cos();
    JointSample {
        s_rad: s,
        sdot_rad_s: sdot,
        theta_motor_rad: R * s + 0.02 * (7.0 * t).sin() + 1.5,
        omega_motor_rad_s: R * sdot + 0.14 * (7.0 * t).cos(),
        temperature_c: 40.0,
    }
}

fn tau_des(k: u64) -> f64 {
    1.5 * (k as f64 * 0.01).sin()
}

fn payloads(k: u64) -> (JointStates, TorqueRequest) {
    let x = sample(k);
    let mut js = JointStates::zeroed();
    js.n_joints = 2;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = 2;
    rq.enable_mask = 0b11;
    for j in 0..2 {
        js.s_rad[j] = x.s_rad;
        js.sdot_rad_s[j] = x.sdot_rad_s;
        js.theta_motor_rad[j] = x.theta_motor_rad;
        js.omega_motor_rad_s[j] = x.omega_motor_rad_s;
        js.temperature_c[j] = x.temperature_c;
        rq.tau_des_nm[j] = tau_des(k);
    }
    (js, rq)
}

/// The test's copy of the daemon's joint: a PinnEstimator reset at the enable edge.
struct RefJoint {
    est: PinnEstimator,
    fresh: bool,
}

impl RefJoint {
    fn new(path: &Path, policy: WarmupPolicy) -> Self {
        let f = frictionless::weights::read_file(path).unwrap();
        Self {
            est: PinnEstimator::from_model_file(&f, policy).unwrap(),
            fresh: true,
        }
    }

    /// (expected current, expected warm-up flag) for this tick.
    fn step(&mut self, x: &JointSample, tau: f64) -> (f64, bool) {
        if self.fresh {
            self.est.reset(x);
            self.fresh = false;
        }
        let f = self.est.estimate(x);
        let warming = !self.est.history().is_full();
        let i = current_ref(tau, f, x.sdot_rad_s, 0.0, f64::INFINITY, KFC, KT, R, MAX_I);
        (i, warming)
    }
}

fn one_step(plant: &mut Plant, k: u64) -> MotorCurrentCommand {
    let (js, rq) = payloads(k);
    let s = plant.publish_state(&js);
    plant.publish_request(&rq, s);
    let c = plant
        .command_for(s, T)
        .unwrap_or_else(|| panic!("no command for state {s}"));
    assert_eq!(c.state_seq, s, "one command per state");
    c
}

fn check(c: &MotorCurrentCommand, j: usize, want: (f64, bool), k: u64) {
    assert!(
        (c.i_ref_a[j] - want.0).abs() <= 1e-9,
        "step {k} joint {j}: {} A vs {} A",
        c.i_ref_a[j],
        want.0
    );
    assert_eq!(
        c.flags[j] & FLAG_WARMING_UP != 0,
        want.1,
        "step {k} joint {j}: warm-up flag {:#x}",
        c.flags[j]
    );
    assert_eq!(c.flags[j] & FLAG_STALE, 0, "step {k} joint {j}");
}

#[test]
fn pinn_currents_warm_up_and_reload() {
    let env = TestEnv::new("pinn");
    let a = env.dir.join("a.fwt");
    let b = env.dir.join("b.fwt");
    frictionless::weights::write_file(&a, &model_file(1)).unwrap();
    frictionless::weights::write_file(&b, &model_file(2)).unwrap();
    let cfg = env.write_config(&config("a.fwt", "a.fwt"));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);

    // 1. Model A: warm-up (flag set, τ̂_F = 0 under hold_zero), then the network's estimate.
    let mut j0 = RefJoint::new(&a, WarmupPolicy::HoldZero);
    let mut j1 = RefJoint::new(&a, WarmupPolicy::ZeroPad);
    let mut warm_seen = [0usize; 2];
    let mut k = 0u64;
    let mut last_seq = None;
    let mut beyond_feed_forward = 0;
    for _ in 0..200 {
        let c = one_step(&mut plant, k);
        let x = sample(k);
        let w0 = j0.step(&x, tau_des(k));
        let w1 = j1.step(&x, tau_des(k));
        check(&c, 0, w0, k);
        check(&c, 1, w1, k);
        warm_seen[0] += usize::from(w0.1);
        warm_seen[1] += usize::from(w1.1);
        // The network's output matters: the current differs from the feed-forward-only one.
        let ff = tau_des(k) / (KT * R);
        beyond_feed_forward += usize::from((c.i_ref_a[0] - ff).abs() > 1e-3);
        if let Some(p) = last_seq {
            assert_eq!(c.seq, p + 1);
        }
        last_seq = Some(c.seq);
        k += 1;
    }
    assert_eq!(
        warm_seen,
        [H - 1, H - 1],
        "flag while the history is not full"
    );
    assert!(
        beyond_feed_forward > 150,
        "PINN contributed on only {beyond_feed_forward} of 200 ticks"
    );
    let s = plant.status_until(None, T, |_| true);
    assert_eq!(s.model_kind[0], frictionless::model::ModelKind::Pinn.code());
    assert_eq!(s.model_kind[1], frictionless::model::ModelKind::Pinn.code());

    // 2. SIGHUP with model B for joint 0: the switch is the tick where the warm-up flag comes
    //    back (every joint gets a bumpless reset on a parameter hand-over); until then model A.
    env.write_config_at(&cfg, &config("b.fwt", "a.fwt"));
    d.signal(libc::SIGHUP);
    let mut switched_at = None;
    for _ in 0..20_000 {
        let c = one_step(&mut plant, k);
        assert_eq!(
            c.seq,
            last_seq.unwrap() + 1,
            "no lost tick across the reload"
        );
        last_seq = Some(c.seq);
        let x = sample(k);
        if switched_at.is_none() && c.flags[0] & FLAG_WARMING_UP != 0 {
            switched_at = Some(k);
            j0 = RefJoint::new(&b, WarmupPolicy::HoldZero);
            j1 = RefJoint::new(&a, WarmupPolicy::ZeroPad);
        }
        check(&c, 0, j0.step(&x, tau_des(k)), k);
        check(&c, 1, j1.step(&x, tau_des(k)), k);
        k += 1;
        if let Some(at) = switched_at
            && k > at + 3 * H as u64
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(switched_at.is_some(), "the reload never took effect");
    let s = plant
        .status_until(None, T, |s| s.generation >= 1)
        .generation;
    assert_eq!(s, 1);

    // 3. SIGHUP with a corrupt file: rejected, model B keeps running (no reset, no warm-up).
    std::fs::write(env.dir.join("c.fwt"), b"FWT but not really a weight file").unwrap();
    env.write_config_at(&cfg, &config("c.fwt", "a.fwt"));
    d.signal(libc::SIGHUP);
    for _ in 0..300 {
        let c = one_step(&mut plant, k);
        let x = sample(k);
        check(&c, 0, j0.step(&x, tau_des(k)), k);
        check(&c, 1, j1.step(&x, tau_des(k)), k);
        k += 1;
        std::thread::sleep(Duration::from_millis(1));
    }
    // Keep ticking until a status from after the rejected reload is out; generation unchanged.
    let mut st = None;
    for _ in 0..50 {
        one_step(&mut plant, k);
        k += 1;
        if let Some(s) = plant.status.latest().unwrap() {
            st = Some(s);
        }
    }
    let st = st.expect("status");
    assert_eq!(st.generation, 1, "a rejected reload keeps the generation");
    d.signal(libc::SIGTERM);
    let (status, log) = d.wait_exit(T);
    assert!(status.success(), "{log}");
    assert!(
        log.contains("reload rejected") && log.contains("c.fwt"),
        "the log names the bad file: {log}"
    );
}

/// One non-finite sample costs the tick it arrives on, not the H ticks it would take to leave the
/// history: joint 0 (hold_zero) gets a NaN ṡ (an input of the model and of the law), joint 1
/// (zero_pad) a NaN θ (an input of the model only, through Δθ), both at tick 30 after the warm-up.
/// On that tick both command 0 A with `FLAG_NON_FINITE`; from the next tick on they command τ_des
/// plus the friction of a history that held the last finite sample in place of the bad one, with
/// no fault flag (the reference joints are fed that held sample, never a NaN).
#[test]
fn one_non_finite_sample_costs_only_its_own_tick_of_torque() {
    const BAD: u64 = 30;
    let env = TestEnv::new("pinnnan");
    let a = env.dir.join("a.fwt");
    frictionless::weights::write_file(&a, &model_file(1)).unwrap();
    let cfg = env.write_config(&config("a.fwt", "a.fwt"));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let mut j0 = RefJoint::new(&a, WarmupPolicy::HoldZero);
    let mut j1 = RefJoint::new(&a, WarmupPolicy::ZeroPad);
    let mut after = Vec::new();
    for k in 0..BAD + 4 * H as u64 {
        let (mut js, rq) = payloads(k);
        if k == BAD {
            js.sdot_rad_s[0] = f64::NAN;
            js.theta_motor_rad[1] = f64::NAN;
        }
        let s = plant.publish_state(&js);
        plant.publish_request(&rq, s);
        let c = plant
            .command_for(s, T)
            .unwrap_or_else(|| panic!("no command for state {s}"));
        // What a clean history holds on the bad tick: the sample before it.
        let x = sample(if k == BAD { k - 1 } else { k });
        let w0 = j0.step(&x, tau_des(k));
        let w1 = j1.step(&x, tau_des(k));
        if k == BAD {
            for j in 0..2 {
                assert_eq!(c.i_ref_a[j], 0.0, "bad tick, joint {j}: 0 A");
                assert_ne!(c.flags[j] & FLAG_NON_FINITE, 0, "bad tick, joint {j}");
            }
            continue;
        }
        for j in 0..2 {
            assert_eq!(
                c.flags[j] & FLAG_NON_FINITE,
                0,
                "tick {k} joint {j}: a clean sample after the bad one is not a fault ({} A)",
                c.i_ref_a[j]
            );
        }
        check(&c, 0, w0, k);
        check(&c, 1, w1, k);
        if k > BAD {
            after.push(c.i_ref_a);
        }
    }
    // τ_des is back at once: the tick after the bad one commands a current, not 0 A.
    assert!(
        after[0].iter().take(2).all(|i| i.abs() > 1e-3),
        "tick {}: {:?}",
        BAD + 1,
        after[0]
    );
    d.signal(libc::SIGTERM);
    let (status, log) = d.wait_exit(T);
    assert!(status.success(), "{log}");
}
