//! Out of the training range, end to end: a `.fwt` with a stored input range (ṡ ∈ [−1, 1] rad/s),
//! `frictiond` in lockstep with two PINN joints on that file — joint 0 `ood = "static"` (a CV
//! fallback, 20 ms ramp), joint 1 `ood = "flag"` — and the test process as the plant. A run whose
//! velocity leaves the range: both joints carry `FLAG_OUT_OF_RANGE` and are counted in
//! `DaemonStatus::out_of_range_ticks`; joint 0's current ramps to the static law's value and stays
//! there, joint 1 keeps the PINN's; back in range, joint 0 ramps back to the PINN.

use crate::daemon_support::*;
use frictionless::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use frictionless::mlp::StorageDtype;
use frictionless::model::{FrictionModel, PinnEstimator};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{InputRange, ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{FLAG_OUT_OF_RANGE, JointStates, MotorCurrentCommand, TorqueRequest};

const R: f64 = -100.0;
const KT: f64 = 0.157;
const KFC: f64 = 0.8;
const MAX_I: f64 = 50.0;
const H: usize = 10;
const KC: f64 = 1.2;
const KA: f64 = 30.0;
const KV: f64 = 0.9;
/// Ticks of the 20 ms ramp at 1 ms.
const RAMP_TICKS: u64 = 20;

fn model_file() -> ModelFile {
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
    let mut training = TrainingMeta::unknown("daemon_ood test", 0);
    training.input_range = Some(InputRange {
        blocks: [[-50.0, 50.0], [-1.0, 1.0], [0.0, 0.0]],
        temperature: [0.0, 0.0],
    });
    ModelFile {
        meta: ModelMeta {
            joint_name: "knee".into(),
            gear_ratio: GearRatio::new(R).unwrap(),
            kt_nm_per_a: KT,
            features,
            scv: None,
            training,
        },
        dtype: StorageDtype::F32,
        mlp: seeded_mlp(&mlp, 3).unwrap(),
    }
}

fn config() -> String {
    let joint = |name: &str, index: usize, ood: &str| {
        format!(
            r#"
[[joint]]
name = "{name}"
index = {index}
gear_ratio = {R:?}
kt = {KT:?}
max_curr = {MAX_I:?}
kfc = {KFC:?}
friction_model = "pinn"
model = "m.fwt"
model_for = "knee"
warmup = "zero_pad"
ood_margin = 0.0
ood_ramp_ms = 20.0
{ood}
"#
        )
    };
    format!(
        "{LOCKSTEP_LOOP_AND_SAFETY}{}{}",
        joint(
            "knee",
            0,
            &format!("ood = \"static\"\nkc = {KC:?}\nka = {KA:?}\nkv = {KV:?}")
        ),
        joint("knee_flag", 1, "ood = \"flag\""),
    )
}

/// Phases: in range (ticks 0–59), out of range (60–119, ṡ ≈ 2 rad/s), in range again (120–199).
fn out_of_range_phase(k: u64) -> bool {
    (60..120).contains(&k)
}

fn sample(k: u64) -> JointSample {
    let t = k as f64 * 1e-3;
    let sdot = if out_of_range_phase(k) {
        2.0 + 0.2 * (9.0 * t).sin()
    } else {
        0.5 * (3.0 * t).cos()
    };
    let s = 0.2 * (3.0 * t).sin();
    JointSample {
        s_rad: s,
        sdot_rad_s: sdot,
        theta_motor_rad: R * s + 0.02 * (7.0 * t).sin() + 1.5,
        omega_motor_rad_s: R * sdot,
        temperature_c: 40.0,
    }
}

fn tau_des(k: u64) -> f64 {
    1.5 * (k as f64 * 0.01).sin()
}

fn one_step(plant: &mut Plant, k: u64) -> MotorCurrentCommand {
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
    let s = plant.publish_state(&js);
    plant.publish_request(&rq, s);
    let c = plant
        .command_for(s, T)
        .unwrap_or_else(|| panic!("no command for state {s}"));
    assert_eq!(c.state_seq, s, "one command per state");
    c
}

fn current(k: u64, f: f64) -> f64 {
    current_ref(
        tau_des(k),
        f,
        sample(k).sdot_rad_s,
        0.0,
        f64::INFINITY,
        KFC,
        KT,
        R,
        MAX_I,
    )
}

#[test]
fn leaving_the_training_range_switches_to_the_static_model_and_counts() {
    let env = TestEnv::new("ood");
    let path = env.dir.join("m.fwt");
    frictionless::weights::write_file(&path, &model_file()).unwrap();
    let cfg = env.write_config(&config());
    let _d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);

    let f = frictionless::weights::read_file(&path).unwrap();
    let mut pinn = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
    // The blend weight as the daemon steps it: period / ramp per tick, clamped to [0, 1].
    let step = 1e-3 / (20.0 * 1e-3);
    let mut w = 0.0f64;
    let (mut n_ood, mut at_static, mut at_pinn_after) = (0u64, 0u64, 0u64);
    let total = 200u64;
    for k in 0..total {
        let c = one_step(&mut plant, k);
        let x = sample(k);
        if k == 0 {
            pinn.reset(&x);
        }
        let pinn_nm = pinn.estimate(&x);
        let ood = out_of_range_phase(k);
        w = if ood {
            (w + step).min(1.0)
        } else {
            (w - step).max(0.0)
        };
        let static_nm = cv_ref(KC, KA, KV, x.sdot_rad_s);
        let blended = if w <= 0.0 {
            pinn_nm
        } else if w >= 1.0 {
            static_nm
        } else {
            (1.0 - w) * pinn_nm + w * static_nm
        };
        for j in 0..2 {
            assert_eq!(
                c.flags[j] & FLAG_OUT_OF_RANGE != 0,
                ood,
                "tick {k} joint {j}: flags {:#x}",
                c.flags[j]
            );
        }
        // Joint 0 follows the blend; joint 1 (flag only) keeps the PINN.
        let want0 = current(k, blended);
        assert!(
            (c.i_ref_a[0] - want0).abs() <= 1e-6,
            "tick {k}: joint 0 {} A vs {want0} A (w = {w})",
            c.i_ref_a[0]
        );
        let want1 = current(k, pinn_nm);
        assert!(
            (c.i_ref_a[1] - want1).abs() <= 1e-6,
            "tick {k}: joint 1 {} A vs {want1} A",
            c.i_ref_a[1]
        );
        n_ood += u64::from(ood);
        if ood && k >= 60 + RAMP_TICKS {
            // After the ramp: exactly the static law's value (and not the PINN's).
            assert!((c.i_ref_a[0] - current(k, static_nm)).abs() <= 1e-6);
            assert!(
                (c.i_ref_a[0] - want1).abs() > 1e-4,
                "tick {k}: PINN ≈ static"
            );
            at_static += 1;
        }
        if k >= 120 + RAMP_TICKS {
            assert!(
                (c.i_ref_a[0] - want1).abs() <= 1e-6,
                "tick {k}: back to PINN"
            );
            at_pinn_after += 1;
        }
        if k == 60 {
            // The first out-of-range tick is one ramp step, not a switch.
            let full = current(k, static_nm);
            let d_step = (c.i_ref_a[0] - want1).abs();
            assert!(
                d_step < 0.1 * (full - want1).abs() + 1e-9,
                "no current step"
            );
        }
    }
    assert_eq!((at_static, at_pinn_after), (40, 60));
    assert_eq!(n_ood, 60);
    let s = plant.status_until(None, T, |s| s.ticks >= total);
    assert_eq!(s.ticks, total);
    assert_eq!(&s.out_of_range_ticks[..3], &[n_ood, n_ood, 0]);
}
