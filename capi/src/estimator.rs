//! The per-joint friction estimator: PINN (from a model) or CV / SCV, one sample per tick.
//!
//! It is `frictionless::model::JointModel`, the enum frictiond's RT tick holds: creation allocates
//! once (a PINN copies its network); [`fl_estimator_estimate`], [`fl_estimator_reset`],
//! [`fl_estimator_is_ready`] and [`fl_estimator_fix_delta_theta_offset`] never allocate, lock or
//! panic. One thread at a time per estimator.

use fl_core::features::{JointSample, WarmupPolicy};
use fl_core::friction::{CvParams, ScvParams};
use fl_core::model::{FrictionModel, JointModel, PinnEstimator};

use crate::friction::{fl_cv_params, fl_scv_params, validated};
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
