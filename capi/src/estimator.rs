//! The per-joint friction estimator: PINN (from a model), CV / SCV or LuGre, one sample per tick.
//! [`fl_estimator_kind`] says which (the code of the core's `ModelKind`, as in frictiond's status;
//! [`fl_model_kind_name`] names a code).
//!
//! It is `frictionless::model::JointModel`, the enum frictiond's RT tick holds: creation allocates
//! once (a PINN copies its network); [`fl_estimator_estimate`], [`fl_estimator_reset`],
//! [`fl_estimator_is_ready`] and [`fl_estimator_fix_delta_theta_offset`] never allocate, lock or
//! panic. One thread at a time per estimator.

use fl_core::features::{JointSample, WarmupPolicy};
use fl_core::friction::{CvParams, ScvParams};
use fl_core::lugre::LugreEstimator;
use fl_core::model::{FrictionModel, JointModel, ModelKind, PinnEstimator};
use std::ffi::{CString, c_char};
use std::sync::OnceLock;

use crate::friction::{fl_cv_params, fl_lugre_params, fl_scv_params, validated};
use crate::model::fl_model;
use crate::{Fail, arg, arg_mut, fl_status, guard};

/// What a PINN estimator outputs while fewer than H samples arrived since the last reset
/// (`FL_WARMUP_*`).
pub type fl_warmup = u32;
/// Output 0 ("not ready") until H samples have arrived — the BLF device's behaviour. The safe side.
pub const FL_WARMUP_HOLD_ZERO: fl_warmup = 0;
/// Infer at once; missing older samples read as 0.
pub const FL_WARMUP_ZERO_PAD: fl_warmup = 1;

/// One tick of joint and motor state (the estimators' input).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_joint_sample {
    /// Joint position s [rad].
    pub s_rad: f64,
    /// Joint velocity ṡ [rad/s].
    pub sdot_rad_s: f64,
    /// Motor position θ [motor rad] (= r·s plus deflection and offset, r signed).
    pub theta_motor_rad: f64,
    /// Motor velocity ω_m [motor rad/s].
    pub omega_motor_rad_s: f64,
    /// Motor temperature [°C]; NaN when the joint has no sensor (only read by models that use it).
    pub temperature_c: f64,
}

impl From<&fl_joint_sample> for JointSample {
    #[inline]
    fn from(s: &fl_joint_sample) -> Self {
        JointSample {
            s_rad: s.s_rad,
            sdot_rad_s: s.sdot_rad_s,
            theta_motor_rad: s.theta_motor_rad,
            omega_motor_rad_s: s.omega_motor_rad_s,
            temperature_c: s.temperature_c,
        }
    }
}

/// A per-joint friction estimator. Opaque; one thread at a time.
pub struct fl_estimator {
    model: JointModel,
}

fn hand_out(model: JointModel, out: &mut *mut fl_estimator) {
    *out = Box::into_raw(Box::new(fl_estimator { model }));
}

/// Creates a PINN estimator for `model` with warm-up policy `warmup` (`FL_WARMUP_*`) and stores it in
/// `*out`. Allocates once (the network is copied: the model may be freed afterwards); the Δθ offset
/// is latched at every [`fl_estimator_reset`] until fixed with
/// [`fl_estimator_fix_delta_theta_offset`]. Free with [`fl_estimator_free`].
///
/// # Safety
/// `model` is NULL or a live handle; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_create(
    model: *const fl_model,
    warmup: fl_warmup,
    out: *mut *mut fl_estimator,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let m = unsafe { arg(model, "fl_estimator_create: `model` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_estimator_create: `out` is NULL") }?;
        let policy = match warmup {
            FL_WARMUP_HOLD_ZERO => WarmupPolicy::HoldZero,
            FL_WARMUP_ZERO_PAD => WarmupPolicy::ZeroPad,
            _ => {
                return Err(Fail::fixed(
                    fl_status::InvalidArgument,
                    "fl_estimator_create: `warmup` is not one of FL_WARMUP_*",
                ));
            }
        };
        let est = PinnEstimator::from_model_file(&m.file, policy)
            .map_err(|e| Fail::owned(fl_status::Model, fl_core::error_line(&e)))?;
        hand_out(JointModel::Pinn(Box::new(est)), out);
        Ok(())
    })
}

/// Creates a CV estimator (`FL_STATUS_INVALID_ARGUMENT` naming a bad parameter).
///
/// # Safety
/// `params` is NULL or readable; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_create_cv(
    params: *const fl_cv_params,
    out: *mut *mut fl_estimator,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_estimator_create_cv: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_estimator_create_cv: `out` is NULL") }?;
        hand_out(JointModel::Cv(validated(CvParams::from(p))?), out);
        Ok(())
    })
}

/// Creates an SCV (paper form) estimator (`FL_STATUS_INVALID_ARGUMENT` naming a bad parameter).
///
/// # Safety
/// `params` is NULL or readable; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_create_scv(
    params: *const fl_scv_params,
    out: *mut *mut fl_estimator,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_estimator_create_scv: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_estimator_create_scv: `out` is NULL") }?;
        hand_out(JointModel::Scv(validated(ScvParams::from(p))?), out);
        Ok(())
    })
}

/// Creates a LuGre estimator integrating its bristle state once per call with step `dt_s` [s] (the
/// loop period; frictiond's is `1 / [loop] rate_hz`). The state is reset to 0 by
/// [`fl_estimator_reset`]. `FL_STATUS_INVALID_ARGUMENT` naming a bad parameter or step.
///
/// # Safety
/// `params` is NULL or readable; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_create_lugre(
    params: *const fl_lugre_params,
    dt_s: f64,
    out: *mut *mut fl_estimator,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_estimator_create_lugre: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_estimator_create_lugre: `out` is NULL") }?;
        let est = LugreEstimator::new(p.into(), dt_s)
            .map_err(|e| Fail::owned(fl_status::InvalidArgument, e.to_string()))?;
        hand_out(JointModel::Lugre(est), out);
        Ok(())
    })
}

/// The estimator's model kind into `*kind`: the code of the core's `ModelKind` (the codes
/// frictiond's status carries per joint; [`fl_model_kind_name`] names one). Allocation-free.
///
/// # Safety
/// `est` is NULL or a live handle; `kind` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_kind(est: *const fl_estimator, kind: *mut u8) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let e = unsafe { arg(est, "fl_estimator_kind: `est` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(kind, "fl_estimator_kind: `kind` is NULL") }?;
        *out = e.model.kind().code();
        Ok(())
    })
}

/// The short name of model-kind code `code` (`"none"`, `"cv"`, `"scv"`, `"scv-code"`, `"pinn"`,
/// `"lugre"`, … — the core's `ModelKind` list), static and NUL-terminated; NULL for a code no kind
/// has. Iterate `code = 0, 1, …` until NULL to list every kind.
#[unsafe(no_mangle)]
pub extern "C" fn fl_model_kind_name(code: u8) -> *const c_char {
    static NAMES: OnceLock<Vec<(u8, CString)>> = OnceLock::new();
    let names = NAMES.get_or_init(|| {
        ModelKind::ALL
            .iter()
            .filter_map(|k| Some((k.code(), CString::new(k.name()).ok()?)))
            .collect()
    });
    names
        .iter()
        .find(|(c, _)| *c == code)
        .map_or(std::ptr::null(), |(_, n)| n.as_ptr())
}

/// Frees an estimator. Does nothing for NULL.
///
/// # Safety
/// `est` is NULL or a live estimator handle, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_free(est: *mut fl_estimator) {
    if !est.is_null() {
        let _ = std::panic::catch_unwind(|| {
            // SAFETY: a live handle comes from `Box::into_raw` in this module.
            drop(unsafe { Box::from_raw(est) });
        });
    }
}

/// Bumpless enable: clears the history and re-latches the Δθ offset at `sample` (Δθ = 0 there),
/// unless the offset is fixed. Does not push the sample. Static models: nothing to do.
/// Allocation-free.
///
/// # Safety
/// `est` is NULL or a live handle; `sample` is NULL or readable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_reset(
    est: *mut fl_estimator,
    sample: *const fl_joint_sample,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let e = unsafe { arg_mut(est, "fl_estimator_reset: `est` is NULL") }?;
        // SAFETY: caller contract.
        let s = unsafe { arg(sample, "fl_estimator_reset: `sample` is NULL") }?;
        e.model.reset(&JointSample::from(s));
        Ok(())
    })
}

/// One tick: pushes `sample` into the history and writes τ̂_F [Nm, joint side] to `*tau_f_nm` —
/// 0 while a `FL_WARMUP_HOLD_ZERO` PINN warms up; NaN or ±∞ possible for non-finite inputs (the law
/// zeroes them). Allocation-free, lock-free.
///
/// # Safety
/// `est` is NULL or a live handle; `sample` is NULL or readable; `tau_f_nm` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_estimate(
    est: *mut fl_estimator,
    sample: *const fl_joint_sample,
    tau_f_nm: *mut f64,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let e = unsafe { arg_mut(est, "fl_estimator_estimate: `est` is NULL") }?;
        // SAFETY: caller contract.
        let s = unsafe { arg(sample, "fl_estimator_estimate: `sample` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(tau_f_nm, "fl_estimator_estimate: `tau_f_nm` is NULL") }?;
        *out = e.model.estimate(&JointSample::from(s));
        Ok(())
    })
}

/// Whether the history now holds enough samples for the model under the warm-up policy
/// (`FL_WARMUP_HOLD_ZERO`: H samples since the last reset; `FL_WARMUP_ZERO_PAD`: one; static models:
/// always). The estimate that filled the history already came from the model. Allocation-free.
///
/// # Safety
/// `est` is NULL or a live handle; `ready` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_is_ready(
    est: *const fl_estimator,
    ready: *mut bool,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let e = unsafe { arg(est, "fl_estimator_is_ready: `est` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(ready, "fl_estimator_is_ready: `ready` is NULL") }?;
        *out = e.model.is_ready();
        Ok(())
    })
}

/// Fixes the Δθ offset θ_off [motor rad] (`fixed` true: Δθ = r·s − (θ − θ_off) with this offset, kept
/// across resets — a calibrated offset, as frictiond's `delta_theta_offset_motor_rad`), or returns to
/// latching at every reset (`fixed` false; `theta_off_motor_rad` ignored). Static models: nothing to
/// do. `FL_STATUS_INVALID_ARGUMENT` for a non-finite fixed offset. Allocation-free.
///
/// # Safety
/// `est` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_estimator_fix_delta_theta_offset(
    est: *mut fl_estimator,
    fixed: bool,
    theta_off_motor_rad: f64,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let e = unsafe { arg_mut(est, "fl_estimator_fix_delta_theta_offset: `est` is NULL") }?;
        if fixed && !theta_off_motor_rad.is_finite() {
            return Err(Fail::fixed(
                fl_status::InvalidArgument,
                "fl_estimator_fix_delta_theta_offset: `theta_off_motor_rad` is not finite",
            ));
        }
        if let JointModel::Pinn(p) = &mut e.model {
            p.fix_delta_theta_offset(fixed.then_some(theta_off_motor_rad));
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{fl_model_free, fl_model_from_bytes};
    use fl_core::features::{FeatureSet, FeatureSpec};
    use fl_core::mlp::StorageDtype;
    use fl_core::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
    use fl_core::units::GearRatio;
    use fl_core::weights::{ModelFile, ModelMeta, TrainingMeta};
    use std::ptr;

    fn model_bytes(spec: FeatureSpec) -> Vec<u8> {
        let mlp = seeded_mlp(
            &RandomMlpSpec {
                sizes: vec![spec.n_inputs(), 12, 1],
                weights: WeightInit::Uniform { amp: 0.5 },
                bias: -0.2..0.2,
                norm: NormInit::Identity,
            },
            9,
        )
        .unwrap();
        fl_core::weights::to_bytes(&ModelFile {
            meta: ModelMeta {
                joint_name: "knee".into(),
                gear_ratio: GearRatio::new(-100.0).unwrap(),
                kt_nm_per_a: 0.157,
                features: spec,
                scv: None,
                training: TrainingMeta::unknown("capi estimator test", 0),
            },
            dtype: StorageDtype::F32,
            mlp,
        })
        .unwrap()
    }

    fn sample(k: usize) -> fl_joint_sample {
        let t = k as f64 * 1e-3;
        fl_joint_sample {
            s_rad: 0.3 * (3.0 * t).sin(),
            sdot_rad_s: 0.9 * (3.0 * t).cos(),
            theta_motor_rad: -30.0 * (3.0 * t).sin() + 1.5 + 0.02 * (7.0 * t).sin(),
            omega_motor_rad_s: -90.0 * (3.0 * t).cos(),
            temperature_c: 40.0,
        }
    }

    /// One sample with a NaN input gives a NaN estimate on that call only: the next call with a
    /// finite sample is finite (the core holds the last finite sample in the history), for each
    /// input the model reads, under both warm-up policies.
    #[test]
    fn the_estimate_after_a_nan_sample_is_finite_on_the_next_call() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 20,
            temperature: true,
        };
        let bytes = model_bytes(spec);
        let spoilers: [fn(&mut fl_joint_sample); 4] = [
            |s| s.sdot_rad_s = f64::NAN,
            |s| s.theta_motor_rad = f64::NAN,
            |s| s.s_rad = f64::INFINITY,
            |s| s.temperature_c = f64::NAN,
        ];
        // SAFETY (whole test): every pointer is to a live local or a live handle made here, each
        // freed once at the end.
        unsafe {
            let mut m = ptr::null_mut();
            assert_eq!(
                fl_model_from_bytes(bytes.as_ptr(), bytes.len(), &mut m),
                fl_status::Ok
            );
            for warmup in [FL_WARMUP_HOLD_ZERO, FL_WARMUP_ZERO_PAD] {
                for (n, spoil) in spoilers.iter().enumerate() {
                    let mut e = ptr::null_mut();
                    assert_eq!(fl_estimator_create(m, warmup, &mut e), fl_status::Ok);
                    assert_eq!(fl_estimator_reset(e, &sample(0)), fl_status::Ok);
                    let mut y = f64::NAN;
                    for k in 0..60 {
                        let mut s = sample(k);
                        if k == 30 {
                            spoil(&mut s);
                        }
                        assert_eq!(fl_estimator_estimate(e, &s, &mut y), fl_status::Ok);
                        if k == 30 {
                            assert!(
                                y.is_nan(),
                                "warmup {warmup} spoiler {n}: {y} on the bad call"
                            );
                        } else {
                            assert!(y.is_finite(), "warmup {warmup} spoiler {n} call {k}: {y}");
                        }
                    }
                    fl_estimator_free(e);
                }
            }
            fl_model_free(m);
        }
    }

    const LUGRE: fl_lugre_params = fl_lugre_params {
        kc: 1.0,
        kv: 0.3,
        ks: 1.6,
        vs: 0.1,
        alpha: 1.5,
        sigma0: 1.0e4,
        sigma1: 30.0,
    };

    /// A LuGre estimator through the C ABI is the core's `LugreEstimator` tick for tick, reports
    /// the LuGre kind code, and a reset returns its bristle state to 0 (same output as a fresh one).
    #[test]
    fn lugre_estimator_is_the_cores_and_resets_its_state() {
        let mut core = LugreEstimator::new((&LUGRE).into(), 1e-3).unwrap();
        // SAFETY (whole test): every pointer is to a live local or a live handle made here, freed once.
        unsafe {
            let mut e = ptr::null_mut();
            assert_eq!(
                fl_estimator_create_lugre(&LUGRE, 1e-3, &mut e),
                fl_status::Ok
            );
            let mut kind = 0u8;
            assert_eq!(fl_estimator_kind(e, &mut kind), fl_status::Ok);
            assert_eq!(ModelKind::from_code(kind), Some(ModelKind::Lugre));
            assert_eq!(fl_estimator_reset(e, &sample(0)), fl_status::Ok);
            let mut first = Vec::new();
            let mut y = f64::NAN;
            for k in 0..200 {
                assert_eq!(fl_estimator_estimate(e, &sample(k), &mut y), fl_status::Ok);
                assert_eq!(y, core.step(sample(k).sdot_rad_s), "tick {k}");
                first.push(y);
            }
            assert_eq!(fl_estimator_reset(e, &sample(0)), fl_status::Ok);
            for (k, want) in first.iter().enumerate().take(20) {
                assert_eq!(fl_estimator_estimate(e, &sample(k), &mut y), fl_status::Ok);
                assert_eq!(y, *want, "tick {k} after the reset");
            }
            fl_estimator_free(e);
        }
    }

    #[test]
    fn lugre_estimator_refuses_a_bad_parameter_or_step_naming_it() {
        let bad = fl_lugre_params {
            sigma0: -1.0,
            ..LUGRE
        };
        // SAFETY: pointers to live locals; `e` stays NULL on failure.
        unsafe {
            let mut e = ptr::null_mut();
            assert_eq!(
                fl_estimator_create_lugre(&bad, 1e-3, &mut e),
                fl_status::InvalidArgument
            );
            assert!(e.is_null());
            let msg = std::ffi::CStr::from_ptr(crate::fl_last_error()).to_string_lossy();
            assert!(msg.contains("sigma0"), "{msg}");
            assert_eq!(
                fl_estimator_create_lugre(&LUGRE, f64::NAN, &mut e),
                fl_status::InvalidArgument
            );
            assert!(e.is_null());
        }
    }

    /// `fl_model_kind_name` lists exactly the core's kinds, in code order, then NULL.
    #[test]
    fn model_kind_names_are_the_cores_list() {
        let mut names = Vec::new();
        for code in 0..=u8::MAX {
            let p = fl_model_kind_name(code);
            if p.is_null() {
                break;
            }
            // SAFETY: a non-NULL result is a static NUL-terminated string.
            names.push(
                unsafe { std::ffi::CStr::from_ptr(p) }
                    .to_str()
                    .unwrap()
                    .to_owned(),
            );
        }
        let want: Vec<&str> = ModelKind::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(names, want);
        assert!(names.iter().any(|n| n == "lugre"));
        assert!(fl_model_kind_name(u8::MAX).is_null());
    }
}
