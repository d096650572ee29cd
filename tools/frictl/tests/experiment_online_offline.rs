//! The PINN online (frictiond in the closed loop, through real processes) against offline (the same
//! weight file through `frictionless::model::PinnEstimator` in this process) on the **same** inputs.
//!
//! A lockstep sine-tracking trial on both virtual joints runs with a PINN file in frictiond and the
//! raw friction law (`kfc = 1`, no clip, no LPF, so the published τ̂_F is the network output). The
//! experiment records every `JointStates` the daemon consumed (s, ṡ, θ, ω as published by the plant)
//! and the daemon's τ̂_F (row k holds the output for state k − 1). Replaying the recorded states
//! through a fresh estimator — enable (reset) at the first state, one `estimate` per state — must
//! give the daemon's numbers to f32 rounding, for both Δθ conventions: the offset fixed at 0
//! (absolute deflection, `--pinn-latch absolute`) and latched at enable. The two conventions must
//! also give different inputs where the knee starts gravity-loaded (Δθ ≠ 0 at enable).
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use frictionless::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use frictionless::mlp::StorageDtype;
use frictionless::model::{FrictionModel, PinnEstimator};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_experiment::controller::Reference;
use frictionless_experiment::rig::JointSetup;
use frictionless_experiment::run::{JointPlan, JointTrace, TrialSpec, run_trial};
use frictionless_experiment::session::{Binaries, FrictionModel as Fm, Mode};

/// A small ReLU network whose normalisation is sized to the joint's signals (so the output moves
/// with Δθ and ṡ instead of sitting in one ReLU region).
pub(crate) fn model_file(joint: &str, ratio: f64, kt: f64, seed: u64) -> ModelFile {
    let spec = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: 8,
        temperature: false,
    };
    let n_in = spec.n_inputs();
    let mut mlp = seeded_mlp(
        &RandomMlpSpec {
            sizes: vec![n_in, 24, 16, 1],
            weights: WeightInit::Uniform { amp: 0.4 },
            bias: -0.1..0.1,
            norm: NormInit::Identity,
        },
        seed,
    )
    .unwrap();
    // Δθ block scaled by ~0.05 motor rad (≈ 2–3 Nm of wind-up), ṡ block by 0.3 rad/s.
    mlp.norm.scale = (0..n_in)
        .map(|i| if i < spec.history { 0.05 } else { 0.3 })
        .collect();
    ModelFile {
        meta: ModelMeta {
            joint_name: joint.into(),
            gear_ratio: GearRatio::new(ratio).unwrap(),
            kt_nm_per_a: kt,
            features: spec,
            scv: None,
            training: TrainingMeta::unknown("test", 0),
        },
        dtype: StorageDtype::F32,
        mlp,
    }
}

/// Offline replay of a trace: enable at row 0, one estimate per recorded state.
pub(crate) fn replay(file: &ModelFile, offset: Option<f64>, tr: &JointTrace) -> (Vec<f64>, f32) {
    let mut est = PinnEstimator::from_model_file(file, WarmupPolicy::ZeroPad).unwrap();
    est.fix_delta_theta_offset(offset);
    let mut out = Vec::with_capacity(tr.t_s.len());
    let mut first_dtheta = f32::NAN;
    for k in 0..tr.t_s.len() {
        let s = JointSample {
            s_rad: tr.s_rad[k],
            sdot_rad_s: tr.sdot_rad_s[k],
            theta_motor_rad: tr.theta_motor_rad[k],
            omega_motor_rad_s: tr.omega_motor_rad_s[k],
            temperature_c: f64::NAN,
        };
        if k == 0 {
            est.reset(&s);
        }
        out.push(est.estimate(&s));
        if k == 0 {
            // the newest Δθ of the first window
            first_dtheta = est.last_input()[file.meta.features.history - 1];
        }
    }
    (out, first_dtheta)
}

#[test]
fn daemon_pinn_output_equals_offline_inference_on_the_recorded_states() {
    let bins = Binaries::with_frictl(env!("CARGO_BIN_EXE_frictl").into())
        .expect("frictiond next to frictl: cargo build --workspace --bins");
    let setups = JointSetup::both(&[]).unwrap();
    let dir = crate::util::scratch("frictl_online_offline");
    std::fs::create_dir_all(&dir).unwrap();
    let mut files = vec![];
    for (i, s) in setups.iter().enumerate() {
        let f = model_file(
            &s.params.joint,
            s.params.gear_ratio_signed,
            s.params.kt_nm_per_a,
            11 + i as u64,
        );
        let path = dir.join(format!("{}.fwt", s.params.joint));
        frictionless::weights::write_file(&path, &f).unwrap();
        files.push((f, path));
    }
    let mut first_dtheta_knee = vec![];
    for offset in [Some(0.0), None] {
        let plans = [
            (0usize, 300.0, -0.8, 0.4, 0.2),
            (1usize, 14000.0, 0.0, 0.15, 0.25),
        ]
        .map(|(index, kp, centre, amp, f)| JointPlan {
            index,
            kp_per_s2: kp,
            reference: Reference::Sine {
                centre_rad: centre,
                amplitude_rad: amp,
                freq_hz: f,
            },
            pulse: None,
            model: Fm::Pinn(files[index].1.clone()),
        });
        let spec = TrialSpec {
            mode: Mode::Lockstep,
            duration_s: 1.5,
            joints: plans.to_vec(),
            seed: 3,
            sets: vec![],
            pinn_delta_theta_offset_motor_rad: vec![offset; 2],
            raw_friction: true,
            kfc: vec![],
        };
        let trace = run_trial(&bins, &setups, &spec).expect("closed-loop trial");
        for tr in &trace.joints {
            let n = tr.t_s.len();
            assert!(n > 1000, "{}: only {n} ticks recorded", tr.name);
            let (off, first_dtheta) = replay(&files[tr.index].0, offset, tr);
            if tr.index == 0 {
                first_dtheta_knee.push(first_dtheta);
            }
            let mut worst = 0.0f64;
            let mut spread = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 1..n {
                let online = tr.tau_f_hat_nm[k];
                let offline = off[k - 1];
                assert!(online.is_finite(), "{} row {k}: no daemon output", tr.name);
                worst = worst.max((online - offline).abs());
                spread = (spread.0.min(offline), spread.1.max(offline));
            }
            println!(
                "{} offset {offset:?}: max |online − offline| = {worst:.3e} Nm over {} ticks, \
                 offline τ̂_F in [{:.3}, {:.3}] Nm",
                tr.name,
                n - 1,
                spread.0,
                spread.1
            );
            assert!(
                spread.1 - spread.0 > 0.05,
                "{}: the network output hardly moves ({:?}); the comparison would be vacuous",
                tr.name,
                spread
            );
            assert!(
                worst <= 1e-5 * (1.0 + spread.0.abs().max(spread.1.abs())),
                "{} offset {offset:?}: daemon τ̂_F differs from offline inference by {worst:.3e} Nm",
                tr.name
            );
        }
    }
    // The knee starts at −1.2 rad holding ~15 Nm of gravity in the flexspline: absolute Δθ is far
    // from 0 there, the enable latch makes it exactly 0.
    assert!(
        first_dtheta_knee[0].abs() > 0.05,
        "absolute Δθ at the gravity-loaded knee start: {}",
        first_dtheta_knee[0]
    );
    assert_eq!(first_dtheta_knee[1], 0.0, "enable latch: Δθ = 0 at enable");
    let _ = std::fs::remove_dir_all(&dir);
}
