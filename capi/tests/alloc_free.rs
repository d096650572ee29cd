//! Proves, with a counting global allocator, that the C entry points a real-time loop calls never
//! allocate after creation: `fl_estimator_estimate`, `fl_estimator_reset`, `fl_estimator_is_ready`,
//! `fl_estimator_fix_delta_theta_offset` (PINN, CV, SCV), `fl_law_step`, `fl_law_feed_forward_only`,
//! `fl_law_reset`, `fl_model_describe`, `fl_model_feature_block` — including their failure paths
//! (NULL arguments), which report through the thread-local last-error buffer.
//!
//! Its own test binary (see `Cargo.toml`): the `#[global_allocator]` applies to the whole binary.
//! The counter is thread-local, so allocations by the test harness on other threads do not count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::ptr;

use fl_core::features::{FeatureSet, FeatureSpec};
use fl_core::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, StorageDtype};
use fl_core::units::GearRatio;
use fl_core::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless::*;

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

/// A deterministic paper-size network (40 → 268 → 215 → 1) as `.fwt` bytes.
fn model_bytes(dtype: StorageDtype) -> Vec<u8> {
    let sizes = [41usize, 268, 215, 1];
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
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: "l_ankle_roll".into(),
            gear_ratio: GearRatio::new(-160.0).unwrap(),
            kt_nm_per_a: 0.0665,
            features: FeatureSpec {
                set: FeatureSet::DeltaThetaJointVel,
                history: 20,
                temperature: true,
            },
            scv: None,
            training: TrainingMeta::unknown("capi alloc test", 0),
        },
        dtype,
        mlp: MlpWeights {
            norm: Normalisation::identity(sizes[0]),
            layers,
        },
    };
    fl_core::weights::to_bytes(&file).unwrap()
}

fn sample(k: usize) -> fl_joint_sample {
    let t = k as f64 * 1e-3;
    fl_joint_sample {
        s_rad: 0.2 * (3.0 * t).sin(),
        sdot_rad_s: 0.6 * (3.0 * t).cos(),
        theta_motor_rad: -32.0 * (3.0 * t).sin() + 7.0,
        omega_motor_rad_s: -96.0 * (3.0 * t).cos(),
        temperature_c: 35.0,
    }
}

#[test]
fn per_tick_entry_points_do_not_allocate() {
    // SAFETY (whole test): every pointer passed is either NULL on purpose or to a live local or a
    // live handle created here, and handles are freed once at the end.
    unsafe {
        let mut estimators = Vec::new();
        let mut models = Vec::new();
        for dtype in [StorageDtype::F32, StorageDtype::F16, StorageDtype::Bf16] {
            let bytes = model_bytes(dtype);
            let mut m = ptr::null_mut();
            assert_eq!(
                fl_model_from_bytes(bytes.as_ptr(), bytes.len(), &mut m),
                fl_status::Ok
            );
            for warmup in [FL_WARMUP_HOLD_ZERO, FL_WARMUP_ZERO_PAD] {
                let mut e = ptr::null_mut();
                assert_eq!(fl_estimator_create(m, warmup, &mut e), fl_status::Ok);
                estimators.push(e);
            }
            models.push(m);
        }
        let mut e = ptr::null_mut();
        let cv = fl_cv_params {
            kc: 1.2,
            ka: 10.53,
            kv: 0.24,
        };
        assert_eq!(fl_estimator_create_cv(&cv, &mut e), fl_status::Ok);
        estimators.push(e);
        let scv = fl_scv_params {
            kc: 1.0,
            ka: 2.78,
            kv: 0.29,
            ks: 6.0,
            vs: 0.13,
            alpha: 0.6,
        };
        assert_eq!(fl_estimator_create_scv(&scv, &mut e), fl_status::Ok);
        estimators.push(e);
        let mut law = ptr::null_mut();
        let params = fl_law_params {
            kt_nm_per_a: 0.0665,
            gear_ratio: -160.0,
            kfc: 0.85,
            kp: 0.1,
            ki: 2.0,
            max_curr_a: 3.0,
            max_output_friction_nm: 8.0,
            joint_velocity_threshold_rad_s: 0.0,
            dt_s: 1e-3,
            bwfilter_enabled: true,
            bwfilter_order: 2,
            bwfilter_cutoff_hz: 20.0,
            speed_limit_enabled: true,
            rated_motor_speed_rad_s: 100.0,
            no_load_motor_speed_rad_s: 400.0,
            current_safety_factor: 0.9,
        };
        assert_eq!(fl_law_create(&params, &mut law), fl_status::Ok);
        // Touch the thread-local error buffer once (its first use on a thread is free too, but
        // this keeps the count about the calls alone).
        let _ = fl_last_error();

        let before = allocs();
        let mut sum = 0.0;
        let mut nonzero = 0usize;
        for k in 0..200 {
            let mut s = sample(k);
            if k == 120 {
                // A bad sample: the estimators hold it out of their history.
                s.sdot_rad_s = f64::NAN;
            }
            for (j, &e) in estimators.iter().enumerate() {
                if k == 50 {
                    assert_eq!(fl_estimator_reset(e, &s), fl_status::Ok);
                    let fixed = j % 2 == 0;
                    assert_eq!(
                        fl_estimator_fix_delta_theta_offset(e, fixed, 7.0),
                        fl_status::Ok
                    );
                }
                let mut y = f64::NAN;
                assert_eq!(fl_estimator_estimate(e, &s, &mut y), fl_status::Ok);
                let mut ready = false;
                assert_eq!(fl_estimator_is_ready(e, &mut ready), fl_status::Ok);
                let mut o = fl_law_output::default();
                let x = fl_law_input {
                    tau_des_nm: 1.0,
                    friction_nm: y,
                    sdot_rad_s: s.sdot_rad_s,
                    tau_meas_nm: 0.5,
                };
                assert_eq!(fl_law_step(law, &x, &mut o), fl_status::Ok);
                sum += o.i_a;
                nonzero += usize::from(y != 0.0);
            }
            let mut o = fl_law_output::default();
            assert_eq!(fl_law_feed_forward_only(law, 2.0, &mut o), fl_status::Ok);
            if k == 100 {
                assert_eq!(fl_law_reset(law), fl_status::Ok);
            }
            // Failure paths report without allocating.
            let mut y = 0.0;
            assert_eq!(
                fl_estimator_estimate(ptr::null_mut(), &s, &mut y),
                fl_status::NullPointer
            );
            assert_eq!(
                fl_law_step(law, ptr::null(), ptr::null_mut()),
                fl_status::NullPointer
            );
            let mut info = std::mem::MaybeUninit::<fl_model_info>::uninit();
            assert_eq!(
                fl_model_describe(models[0], info.as_mut_ptr()),
                fl_status::Ok
            );
            let mut blk = std::mem::MaybeUninit::<fl_feature_block>::uninit();
            assert_eq!(
                fl_model_feature_block(models[0], 1, blk.as_mut_ptr()),
                fl_status::Ok
            );
        }
        let used = allocs() - before;
        assert_eq!(
            used, 0,
            "the per-tick C entry points allocated {used} times"
        );
        assert!(sum.is_finite());
        assert!(nonzero > 1000, "the estimators produced output ({nonzero})");

        for e in estimators {
            fl_estimator_free(e);
        }
        fl_law_free(law);
        for m in models {
            fl_model_free(m);
        }
    }
}
