//! Proves, with a counting global allocator, that the core's per-tick calls perform no heap
//! allocation after construction: `FrictionModel::estimate` (and `reset`) on every `JointModel`
//! variant, and `kernel::Mlp::forward` on every kernel path × storage dtype (also on a wrong input
//! length).
//!
//! Its own test binary (see `Cargo.toml`): the `#[global_allocator]` applies to the whole binary.
//! The counter is thread-local (const-initialised, no destructor, so reading it never allocates), so
//! allocations made by the test harness on other threads cannot disturb the count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use frictionless::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use frictionless::friction::{ScvCodeParams, paper};
use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, StorageDtype};
use frictionless::model::{FrictionModel, JointModel, NoFriction, PinnEstimator};
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};

struct Counting;

thread_local! {
    static ALLOCS: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; only adds a thread-local counter increment.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocs() -> usize {
    ALLOCS.with(|c| c.get())
}

/// A deterministic MLP (no RNG needed): sizes as the paper's ankle-roll net, 40 → 268 → 215 → 1.
fn mlp(sizes: &[usize]) -> MlpWeights {
    let layers = sizes
        .windows(2)
        .enumerate()
        .map(|(k, w)| DenseLayer {
            n_in: w[0],
            n_out: w[1],
            weight: (0..w[0] * w[1])
                .map(|i| ((i * 7919 + k) % 201) as f32 / 1000.0 - 0.1)
                .collect(),
            bias: (0..w[1]).map(|i| (i % 5) as f32 * 0.01).collect(),
            activation: if k + 2 == sizes.len() {
                Activation::Identity
            } else {
                Activation::Relu
            },
        })
        .collect();
    MlpWeights {
        norm: Normalisation::identity(sizes[0]),
        layers,
    }
}

fn pinn(set: FeatureSet, history: usize, temperature: bool, warmup: WarmupPolicy) -> JointModel {
    let features = FeatureSpec {
        set,
        history,
        temperature,
    };
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: "l_ankle_roll".into(),
            gear_ratio: GearRatio::new(-160.0).unwrap(),
            kt_nm_per_a: 0.0665,
            features,
            scv: Some(paper::SCV_ANKLE_ROLL),
            training: TrainingMeta::unknown("alloc test", 0),
        },
        dtype: StorageDtype::F32,
        mlp: mlp(&[features.n_inputs(), 268, 215, 1]),
    };
    PinnEstimator::from_model_file(&file, warmup)
        .unwrap()
        .into()
}

fn sample(k: usize) -> JointSample {
    let t = k as f64 * 1e-3;
    JointSample {
        s_rad: 0.2 * (2.0 * t).sin(),
        sdot_rad_s: 0.4 * (2.0 * t).cos(),
        theta_motor_rad: -32.0 * (2.0 * t).sin() + 3.0,
        omega_motor_rad_s: -64.0 * (2.0 * t).cos(),
        temperature_c: 40.0,
    }
}

#[test]
fn out_of_range_check_never_allocates() {
    let JointModel::Pinn(template) = pinn(
        FeatureSet::DeltaThetaMotorVelJointVel,
        20,
        true,
        WarmupPolicy::ZeroPad,
    ) else {
        unreachable!()
    };
    // The same model with a range the samples leave part of the time (ṡ ∈ [−0.2, 0.2] of ±0.4).
    let mut meta = template.meta().clone();
    meta.training.input_range = Some(frictionless::weights::InputRange {
        blocks: [[-100.0, 100.0], [-100.0, 100.0], [-0.2, 0.2]],
        temperature: [0.0, 50.0],
    });
    let file = ModelFile {
        mlp: mlp(&[meta.features.n_inputs(), 268, 215, 1]),
        meta,
        dtype: StorageDtype::F32,
    };
    let mut p = PinnEstimator::from_model_file(&file, WarmupPolicy::ZeroPad).unwrap();
    let before = allocs();
    let mut out = 0usize;
    for k in 0..10_000 {
        let x = sample(k);
        p.estimate(&x);
        out += usize::from(p.out_of_range(&x, 0.05));
    }
    let n = allocs() - before;
    assert_eq!(n, 0, "estimate + out_of_range allocated {n} times");
    assert!(
        (2_000..8_000).contains(&out),
        "{out} of 10 000 out of range"
    );
}

#[test]
fn estimate_never_allocates_on_any_variant() {
    let mut models: Vec<(&str, JointModel)> = vec![
        ("none", JointModel::None(NoFriction)),
        ("cv", paper::CV_ANKLE_ROLL.into()),
        ("scv", paper::SCV_KNEE.into()),
        (
            "scv_code",
            ScvCodeParams {
                fc: 0.24,
                fs: 0.46,
                fv: 0.77,
                vs: 0.0198,
            }
            .into(),
        ),
        (
            "pinn dtheta H20 hold_zero",
            pinn(
                FeatureSet::DeltaThetaJointVel,
                20,
                false,
                WarmupPolicy::HoldZero,
            ),
        ),
        (
            "pinn motor_vel H25 +T zero_pad",
            pinn(
                FeatureSet::MotorVelJointVel,
                25,
                true,
                WarmupPolicy::ZeroPad,
            ),
        ),
        (
            "pinn pos H64 zero_pad",
            pinn(
                FeatureSet::JointPosMotorPos,
                64,
                false,
                WarmupPolicy::ZeroPad,
            ),
        ),
        (
            "pinn dtheta/omega/sdot H20 +T hold_zero (3 blocks)",
            pinn(
                FeatureSet::DeltaThetaMotorVelJointVel,
                20,
                true,
                WarmupPolicy::HoldZero,
            ),
        ),
        (
            "pinn joint_vel H30 zero_pad (1 block)",
            pinn(FeatureSet::JointVel, 30, false, WarmupPolicy::ZeroPad),
        ),
    ];
    for (name, m) in &mut models {
        let before = allocs();
        let mut acc = 0.0;
        let mut nonzero = 0usize;
        let t0 = std::time::Instant::now();
        for k in 0..10_000 {
            if k % 2_500 == 0 {
                m.reset(&sample(k));
            }
            let mut x = sample(k);
            if k % 1_000 == 500 {
                // A bad sample: held out of the history (the hold path runs too).
                x.sdot_rad_s = f64::NAN;
                x.theta_motor_rad = f64::INFINITY;
            }
            let y = m.estimate(&x);
            if y.is_finite() {
                acc += y;
                nonzero += usize::from(y != 0.0);
            }
        }
        let dt = t0.elapsed();
        let n = allocs() - before;
        // Report only (no timing assert): debug-profile cost per tick.
        println!(
            "{name}: {n} allocations, {:.0} ns/tick (sum {acc:.3})",
            dt.as_nanos() as f64 / 1e4
        );
        assert_eq!(
            n, 0,
            "{name}: estimate/reset allocated {n} times in 10 000 ticks"
        );
        if *name != "none" {
            assert!(
                nonzero > 9_000,
                "{name}: the model really ran ({nonzero} non-zero outputs)"
            );
        }
    }
    // The counter itself works: a Vec allocation is seen.
    let before = allocs();
    let v = std::hint::black_box(vec![1u8; 16]);
    assert!(allocs() > before, "counting allocator is active");
    drop(v);
}

#[test]
fn kernel_forward_never_allocates_on_any_path_or_dtype() {
    let w = mlp(&[50, 450, 210, 280, 1]);
    let x: Vec<f32> = (0..50).map(|i| (i % 7) as f32 * 0.1 - 0.3).collect();
    let bad = vec![0.0f32; 49];
    for dtype in StorageDtype::ALL {
        for path in KernelPath::available() {
            let mut m = Mlp::new(&w, dtype).unwrap().with_path(path).unwrap();
            let before = allocs();
            let mut sum = 0f32;
            for _ in 0..100 {
                sum += m.forward(&x);
            }
            let nan = m.forward(&bad);
            let after = allocs();
            assert!(sum.is_finite() && nan.is_nan());
            assert_eq!(after - before, 0, "{dtype:?} {path}: forward allocated");
        }
    }
    // The counter itself works: building a kernel allocates.
    let before = allocs();
    let m = Mlp::new(&w, StorageDtype::F32).unwrap();
    assert!(allocs() > before);
    drop(m);
}
