//! The tick benches' joints: paper-size PINNs (the ankle-roll network of the paper,
//! `[Δθ ×20, ṡ ×20]` → 268 → 215 → 1, seeded random weights) or SCV models, the ergoCub law, and
//! changing inputs. Shared by `tick.rs` (criterion, hot loop) and `tick_paced.rs` (1 kHz pacing).

#![allow(dead_code)] // each bench uses its part

use frictiond::config::OnStale;
use frictiond::params::{JointRt, ModelSlots, OodRt, Params};
use frictiond::rt::{Inputs, Latest};
use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
use frictionless::filter::CausalButterworth;
use frictionless::friction::ScvParams;
use frictionless::law::{Gains, JointLaw};
use frictionless::mlp::StorageDtype;
use frictionless::model::{JointModel, PinnEstimator};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{JointStates, TorqueRequest};

pub const R: f64 = -160.0;
pub const H: usize = 20;

/// The weights of joint `seed`'s network (`[Δθ ×20, ṡ ×20]` → 268 → 215 → 1, He-uniform, identity
/// normalisation).
pub fn paper_weights(seed: u64) -> frictionless::mlp::MlpWeights {
    let spec = RandomMlpSpec {
        weights: WeightInit::HeUniform,
        norm: NormInit::Identity,
        ..RandomMlpSpec::new(&[2 * H, 268, 215, 1])
    };
    seeded_mlp(&spec, seed).expect("valid bench net")
}

/// Joint `seed`'s paper-size network as a model file stored as `dtype`.
pub fn paper_file(seed: u64, dtype: StorageDtype) -> ModelFile {
    let features = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: H,
        temperature: false,
    };
    let mlp = paper_weights(seed);
    debug_assert_eq!(mlp.n_inputs(), features.n_inputs());
    ModelFile {
        meta: ModelMeta {
            joint_name: format!("j{seed}"),
            gear_ratio: GearRatio::new(R).unwrap(),
            kt_nm_per_a: 0.0665,
            features,
            scv: None,
            training: TrainingMeta::unknown("tick bench", 0),
        },
        dtype,
        mlp,
    }
}

/// A PINN estimator of `file`, stored as `dtype`.
pub fn pinn_of(file: &ModelFile, dtype: StorageDtype) -> JointModel {
    let file = ModelFile {
        dtype,
        ..file.clone()
    };
    JointModel::Pinn(Box::new(
        PinnEstimator::from_model_file(&file, WarmupPolicy::HoldZero).unwrap(),
    ))
}

pub fn paper_pinn(seed: u64, dtype: StorageDtype) -> JointModel {
    pinn_of(&paper_file(seed, dtype), dtype)
}

pub fn scv() -> JointModel {
    JointModel::Scv(ScvParams {
        kc: 1.0005,
        ka: 2.78,
        kv: 0.29,
        ks: 6.0,
        vs: 0.13,
        alpha: 0.6,
    })
}

/// `n` joints with distinct models (PINNs stored as `dtype`, or SCV when `None`), the ergoCub law
/// (clip, kfc, 2nd-order LPF, clamp), split for `rt_threads` RT threads.
pub fn params(n: usize, pinn: Option<StorageDtype>, rt_threads: u8) -> Box<Params> {
    params_with(n, rt_threads, |k| match pinn {
        Some(dtype) => paper_pinn(k as u64, dtype),
        None => scv(),
    })
}

/// `n` joints whose models are `model(k)`, the ergoCub law, split for `rt_threads` RT threads.
pub fn params_with(n: usize, rt_threads: u8, model: impl Fn(usize) -> JointModel) -> Box<Params> {
    let gains = Gains {
        kt_nm_per_a: 0.0665,
        gear_ratio: R,
        kfc: 0.7,
        kp: 0.0,
        ki: 0.0,
        max_curr_a: 3.0,
        max_output_friction_nm: 8.0,
        joint_velocity_threshold_rad_s: 0.05,
        dt_s: 1e-3,
        speed_limit: None,
    };
    let joints = (0..n)
        .map(|k| JointRt {
            index: k,
            model: model(k),
            law: JointLaw::new(
                gains,
                Some(CausalButterworth::design(2, 30.0, 1000.0).unwrap()),
            ),
            ood: OodRt::off(),
            compensation: true,
            slots: ModelSlots::new(Vec::new()),
            model_switched: false,
        })
        .collect();
    let mut p = Box::new(Params {
        generation: 0,
        joints,
        stale_after_ticks: 20,
        on_stale: OnStale::Zero,
        configured_mask: if n == 64 { u64::MAX } else { (1u64 << n) - 1 },
        split: n,
        helper_mask: 0,
    });
    p.split_threads(rt_threads);
    p
}

pub fn inputs(n: usize) -> Inputs {
    let mut st = JointStates::zeroed();
    st.n_joints = n as u32;
    let mut rq = TorqueRequest::zeroed();
    rq.n_joints = n as u32;
    rq.enable_mask = (1u64 << n) - 1;
    for k in 0..n {
        let x = k as f64 * 0.1;
        st.s_rad[k] = 0.2 * x.sin();
        st.sdot_rad_s[k] = 0.4 * x.cos();
        st.theta_motor_rad[k] = R * st.s_rad[k] + 0.01;
        st.omega_motor_rad_s[k] = R * st.sdot_rad_s[k];
        rq.tau_des_nm[k] = x.sin();
    }
    Inputs {
        states: Latest {
            value: st,
            have: true,
            new_at_tick: 0,
        },
        request: Latest {
            value: rq,
            have: true,
            new_at_tick: 0,
        },
    }
}
