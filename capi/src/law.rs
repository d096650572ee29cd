//! The per-joint control law, `frictionless::law::JointLaw` — the law frictiond runs every tick:
//!
//! ```text
//! f     = clamp(f, ±max_output_friction_nm)  only if |ṡ| > joint_velocity_threshold_rad_s
//! τ̂_F   = kfc·f (0 if kfc ≤ 0), then the Butterworth LPF if enabled
//! i     = (τ_des + kp·(τ_des − τ_meas) + ki·∫(τ_des − τ_meas) + τ̂_F) / (kt·r)    (signed r)
//! i     = clamp(i, ±I_lim);  any NaN/±∞ → i = 0 and the state reset
//! I_lim = max_curr_a, or with `speed_limit_enabled` the torque–speed curve at |ω_m| = |r·ṡ|:
//!         sf·max_curr_a up to rated_motor_speed_rad_s, linear to 0 at no_load_motor_speed_rad_s
//! ```
//! Field names are the BLF device's `TORQUE_CURRENT_PARAMS` keys (`kt`, `kfc`, `kp`, `ki`,
//! `max_curr`, `max_output_friction`, `joint_velocity_threshold`, `bwfilter_*`) with their SI unit
//! appended (the device's threshold is in deg/s, this one in rad/s). Creation designs the filter
//! (not real-time); [`fl_law_step`], [`fl_law_feed_forward_only`] and [`fl_law_reset`] never
//! allocate, lock or panic. One thread at a time per law.

use fl_core::filter::CausalButterworth;
use fl_core::law::{Gains, JointLaw, LawInput, LawOutput, SpeedCurrentLimit};

use crate::{Fail, arg, arg_mut, fl_status, guard};

/// Bit of `fl_law_output::flags`: the friction estimate was clipped (velocity gate open).
pub const FL_LAW_FRICTION_CLIPPED: u32 = 1;
/// Bit of `fl_law_output::flags`: the current was clamped to ±I_lim (max_curr_a or the speed
/// limit).
pub const FL_LAW_CURRENT_SATURATED: u32 = 2;
/// Bit of `fl_law_output::flags`: a non-finite input or intermediate; the output is 0 A and the
/// law's state was reset.
pub const FL_LAW_NON_FINITE: u32 = 4;

/// Constant gains and limits of one joint's law.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_law_params {
    /// Torque constant kt [Nm/A], finite and > 0.
    pub kt_nm_per_a: f64,
    /// Signed gear ratio r (motor angle = r · joint angle), finite and non-zero.
    pub gear_ratio: f64,
    /// Friction compensation gain kfc (≤ 0 disables compensation).
    pub kfc: f64,
    /// Proportional gain on the torque error, finite.
    pub kp: f64,
    /// Integral gain on the torque error [1/s], finite and ≥ 0.
    pub ki: f64,
    /// Current clamp [A], finite and > 0.
    pub max_curr_a: f64,
    /// Friction clip [Nm], ≥ 0 (+∞: never clipped).
    pub max_output_friction_nm: f64,
    /// Velocity gate of the clip [rad/s], finite and ≥ 0 (the BLF default 0: clip unless ṡ = 0).
    pub joint_velocity_threshold_rad_s: f64,
    /// Tick period [s], finite and > 0 (the integral's dt and the filter's sample time).
    pub dt_s: f64,
    /// Whether τ̂_F goes through a Butterworth low-pass.
    pub bwfilter_enabled: bool,
    /// Low-pass order, 1..=8 (read only when enabled).
    pub bwfilter_order: u32,
    /// Low-pass cut-off [Hz], in (0, 1/(2·dt_s)) (read only when enabled).
    pub bwfilter_cutoff_hz: f64,
    /// Whether the current limit depends on the motor speed |ω_m| = |r·ṡ| (false: ±max_curr_a).
    pub speed_limit_enabled: bool,
    /// Rated motor speed [rad/s], finite and > 0: the limit is `current_safety_factor ·
    /// max_curr_a` up to it (read only when enabled).
    pub rated_motor_speed_rad_s: f64,
    /// No-load motor speed [rad/s], finite and > rated: the limit falls linearly to 0 A here
    /// (read only when enabled).
    pub no_load_motor_speed_rad_s: f64,
    /// Safety factor on `max_curr_a`, in (0, 1] (read only when enabled).
    pub current_safety_factor: f64,
}

/// One tick's inputs.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_law_input {
    /// Desired joint torque τ_des [Nm].
    pub tau_des_nm: f64,
    /// Raw friction estimate f [Nm, joint side] (from `fl_estimator_estimate`).
    pub friction_nm: f64,
    /// Measured joint velocity ṡ [rad/s] (the clip gate).
    pub sdot_rad_s: f64,
    /// Measured joint torque τ_meas [Nm]; read only when kp or ki is non-zero.
    pub tau_meas_nm: f64,
}

/// One tick's result.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_law_output {
    /// Motor current command [A], finite, within ±I_lim (≤ max_curr_a).
    pub i_a: f64,
    /// Friction compensation applied, τ̂_F [Nm] (after clip, kfc, filter).
    pub tau_f_hat_nm: f64,
    /// `FL_LAW_*` bits.
    pub flags: u32,
}

impl From<LawOutput> for fl_law_output {
    #[inline]
    fn from(o: LawOutput) -> Self {
        let f = o.flags;
        fl_law_output {
            i_a: o.i_a,
            tau_f_hat_nm: o.tau_f_hat_nm,
            flags: (if f.friction_clipped {
                FL_LAW_FRICTION_CLIPPED
            } else {
                0
            }) | (if f.current_saturated {
                FL_LAW_CURRENT_SATURATED
            } else {
                0
            }) | (if f.non_finite { FL_LAW_NON_FINITE } else { 0 }),
        }
    }
}

/// One joint's law with its state (filter, integral). Opaque; one thread at a time.
pub struct fl_law {
    law: JointLaw,
}

fn check(ok: bool, message: &'static str) -> Result<(), Fail> {
    if ok {
        Ok(())
    } else {
        Err(Fail::fixed(fl_status::InvalidArgument, message))
    }
}

fn build(p: &fl_law_params) -> Result<JointLaw, Fail> {
    let fin = |v: f64| v.is_finite();
    check(
        fin(p.kt_nm_per_a) && p.kt_nm_per_a > 0.0,
        "fl_law_create: `kt_nm_per_a` must be finite and > 0",
    )?;
    check(
        fin(p.gear_ratio) && p.gear_ratio != 0.0,
        "fl_law_create: `gear_ratio` must be finite and non-zero (signed)",
    )?;
    check(fin(p.kfc), "fl_law_create: `kfc` must be finite")?;
    check(fin(p.kp), "fl_law_create: `kp` must be finite")?;
    check(
        fin(p.ki) && p.ki >= 0.0,
        "fl_law_create: `ki` must be finite and >= 0",
    )?;
    check(
        fin(p.max_curr_a) && p.max_curr_a > 0.0,
        "fl_law_create: `max_curr_a` must be finite and > 0",
    )?;
    check(
        p.max_output_friction_nm >= 0.0,
        "fl_law_create: `max_output_friction_nm` must be >= 0 (+inf: no clip)",
    )?;
    check(
        fin(p.joint_velocity_threshold_rad_s) && p.joint_velocity_threshold_rad_s >= 0.0,
        "fl_law_create: `joint_velocity_threshold_rad_s` must be finite and >= 0",
    )?;
    check(
        fin(p.dt_s) && p.dt_s > 0.0,
        "fl_law_create: `dt_s` must be finite and > 0",
    )?;
    let lpf = if p.bwfilter_enabled {
        let f = CausalButterworth::design(
            p.bwfilter_order as usize,
            p.bwfilter_cutoff_hz,
            1.0 / p.dt_s,
        )
        .map_err(|e| {
            Fail::owned(
                fl_status::InvalidArgument,
                format!("fl_law_create: low-pass: {e}"),
            )
        })?;
        Some(f)
    } else {
        None
    };
    let speed_limit = if p.speed_limit_enabled {
        let l = SpeedCurrentLimit::new(
            p.rated_motor_speed_rad_s,
            p.no_load_motor_speed_rad_s,
            p.current_safety_factor,
        )
        .map_err(|rule| {
            // The C field of the core's `safety_factor` is `current_safety_factor`.
            let field = match rule.field {
                "safety_factor" => "current_safety_factor",
                f => f,
            };
            Fail::owned(
                fl_status::InvalidArgument,
                format!("fl_law_create: `{field}` {}", rule.rule),
            )
        })?;
        Some(l)
    } else {
        None
    };
    let gains = Gains {
        kt_nm_per_a: p.kt_nm_per_a,
        gear_ratio: p.gear_ratio,
        kfc: p.kfc,
        kp: p.kp,
        ki: p.ki,
        max_curr_a: p.max_curr_a,
        max_output_friction_nm: p.max_output_friction_nm,
        joint_velocity_threshold_rad_s: p.joint_velocity_threshold_rad_s,
        dt_s: p.dt_s,
        speed_limit,
    };
    Ok(JointLaw::new(gains, lpf))
}

/// Creates a law from `params` (checked; `FL_STATUS_INVALID_ARGUMENT` names the bad field) and
/// stores it in `*out`. Designs the low-pass: call off the real-time thread. Free with
/// [`fl_law_free`].
///
/// # Safety
/// `params` is NULL or readable; `out` is NULL or points to writable storage.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_law_create(
    params: *const fl_law_params,
    out: *mut *mut fl_law,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_law_create: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_law_create: `out` is NULL") }?;
        let law = build(p)?;
        *out = Box::into_raw(Box::new(fl_law { law }));
        Ok(())
    })
}

/// Frees a law. Does nothing for NULL.
///
/// # Safety
/// `law` is NULL or a live law handle, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_law_free(law: *mut fl_law) {
    if !law.is_null() {
        let _ = std::panic::catch_unwind(|| {
            // SAFETY: a live handle comes from `Box::into_raw` in this module.
            drop(unsafe { Box::from_raw(law) });
        });
    }
}

/// Bumpless enable / after a fault: clears the filter (to 0) and the integral. Reset the joint's
/// estimator at the same tick. Allocation-free.
///
/// # Safety
/// `law` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_law_reset(law: *mut fl_law) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        unsafe { arg_mut(law, "fl_law_reset: `law` is NULL") }?
            .law
            .reset();
        Ok(())
    })
}

/// One tick of the law. Allocation-free.
///
/// # Safety
/// `law` is NULL or a live handle; `input` is NULL or readable; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_law_step(
    law: *mut fl_law,
    input: *const fl_law_input,
    out: *mut fl_law_output,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let l = unsafe { arg_mut(law, "fl_law_step: `law` is NULL") }?;
        // SAFETY: caller contract.
        let x = unsafe { arg(input, "fl_law_step: `input` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_law_step: `out` is NULL") }?;
        *out = l
            .law
            .step(&LawInput {
                tau_des_nm: x.tau_des_nm,
                friction_nm: x.friction_nm,
                sdot_rad_s: x.sdot_rad_s,
                tau_meas_nm: x.tau_meas_nm,
            })
            .into();
        Ok(())
    })
}

/// The stale-input output: i = τ_des/(kt·r), clamped; no friction, no feedback (the state is kept).
/// Allocation-free.
///
/// # Safety
/// `law` is NULL or a live handle; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_law_feed_forward_only(
    law: *mut fl_law,
    tau_des_nm: f64,
    out: *mut fl_law_output,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let l = unsafe { arg_mut(law, "fl_law_feed_forward_only: `law` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(out, "fl_law_feed_forward_only: `out` is NULL") }?;
        *out = l.law.feed_forward_only(tau_des_nm).into();
        Ok(())
    })
}
