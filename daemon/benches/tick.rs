//! Compute cost of one RT tick ([`frictiond::rt::compute`]: per joint model estimate + control law)
//! for 1, 15 (ergoCub legs + torso) and 32 joints of paper-size PINNs — the ankle-roll network of
//! the paper, `[Δθ ×20, ṡ ×20]` → 268 → 215 → 1 (the paper), random weights, stored as f32,
//! f16 and bf16 (the `.fwt` storage dtypes: 32 distinct f32 networks are 8.9 MB of weights, more
//! than this machine's caches; half precision halves the bytes streamed per tick) — and, for
//! reference, the same joint counts with the SCV model. Numbers for the README; no asserts.
//! Run: `cargo bench -p frictiond --bench tick` (filter e.g. `-- 'tick/pinn.*/32'`).

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use frictiond::config::OnStale;
use frictiond::params::{JointRt, OodRt, Params};
use frictiond::rt::{Freshness, Inputs, Latest, compute};
use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
use frictionless::filter::CausalButterworth;
use frictionless::friction::ScvParams;
use frictionless::law::{Gains, JointLaw};
use frictionless::mlp::StorageDtype;
use frictionless::model::{JointModel, PinnEstimator};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_shm_types::{JointStates, MAX_JOINTS, MotorCurrentCommand, TorqueRequest};

const R: f64 = -160.0;
const H: usize = 20;

fn paper_pinn(seed: u64, dtype: StorageDtype) -> JointModel {
    let features = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: H,
        temperature: false,
    };
    let spec = RandomMlpSpec {
        weights: WeightInit::HeUniform,
        norm: NormInit::Identity,
        ..RandomMlpSpec::new(&[features.n_inputs(), 268, 215, 1])
    };
    let mlp = seeded_mlp(&spec, seed).expect("valid bench net");
    let file = ModelFile {
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
    };
    JointModel::Pinn(Box::new(
        PinnEstimator::from_model_file(&file, WarmupPolicy::HoldZero).unwrap(),
    ))
}

fn scv() -> JointModel {
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
/// (clip, kfc, 2nd-order LPF, clamp).
fn params(n: usize, pinn: Option<StorageDtype>) -> Box<Params> {
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
    };
    let joints = (0..n)
        .map(|k| JointRt {
            index: k,
            model: match pinn {
                Some(dtype) => paper_pinn(k as u64, dtype),
                None => scv(),
            },
            law: JointLaw::new(
                gains,
                Some(CausalButterworth::design(2, 30.0, 1000.0).unwrap()),
            ),
            ood: OodRt::off(),
        })
        .collect();
    Box::new(Params {
        generation: 0,
        joints,
        stale_after_ticks: 20,
        on_stale: OnStale::Zero,
        configured_mask: if n == 64 { u64::MAX } else { (1u64 << n) - 1 },
        split: n,
        helper_mask: 0,
    })
}

fn inputs(n: usize) -> Inputs {
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

fn tick(c: &mut Criterion) {
    let fresh = Freshness {
        state_stale: false,
        request_stale: false,
    };
    let mut g = c.benchmark_group("tick");
    for (label, pinn) in [
        ("pinn_40x268x215_f32", Some(StorageDtype::F32)),
        ("pinn_40x268x215_f16", Some(StorageDtype::F16)),
        ("pinn_40x268x215_bf16", Some(StorageDtype::Bf16)),
        ("scv", None),
    ] {
        for n in [1usize, 15, 32] {
            let mut p = params(n, pinn);
            let mut inp = inputs(n);
            let mut cmd = MotorCurrentCommand::zeroed();
            let mut tau_f = [0.0; MAX_JOINTS];
            let mut prev = 0u64;
            // Past warm-up, so every tick runs every network.
            for _ in 0..H + 1 {
                compute(&mut p, &inp, fresh, &mut prev, &mut cmd, &mut tau_f);
            }
            let mut k = 0u64;
            g.bench_with_input(BenchmarkId::new(label, n), &n, |b, &n| {
                b.iter(|| {
                    // A changing sample (as on the robot) so nothing is hoisted out of the loop.
                    k += 1;
                    inp.states.value.sdot_rad_s[n - 1] = 0.4 + (k % 100) as f64 * 1e-3;
                    compute(
                        &mut p,
                        black_box(&inp),
                        fresh,
                        &mut prev,
                        &mut cmd,
                        &mut tau_f,
                    );
                    black_box(&cmd);
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, tick);
criterion_main!(benches);
