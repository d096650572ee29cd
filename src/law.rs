//! The per-joint torque-to-current control law with friction compensation (pure, allocation-free).
//!
//! What this module **is**: the law of the BLF `JointTorqueControlDevice` (see `docs/`), with its
//! known defects fixed, as a small state machine per joint ([`JointLaw`]) that frictiond's RT tick
//! calls once per tick and per joint, and that the tools' experiment oracle runs on the true
//! friction:
//!
//! ```text
//! f     = friction model output (caller)                        [Nm]
//! f     = clamp(f, ±max_output_friction)   only if |ṡ| > joint_velocity_threshold_rad_s
//! τ̂_F   = kfc·f  (0 if kfc ≤ 0);  τ̂_F ← Butterworth LPF(τ̂_F)  (if configured)
//! e_int += (τ_des − τ_meas)·dt     (only when ki > 0; anti-windup: ki·|e_int| ≤ max_curr·|kt·r|)
//! i     = (τ_des + kp·(τ_des − τ_meas) + ki·e_int + τ̂_F) / (kt·r)       (signed r)
//! i     = clamp(i, ±I_lim(|ω_m|));   any NaN/±∞ on the way → i = 0 and the joint's state is reset
//! ```
//! The current limit `I_lim` is `max_curr` (the constant clamp), or with a [`SpeedCurrentLimit`]
//! the drive's torque–speed curve in the **motor** speed |ω_m| = |r·ṡ| [rad/s]:
//!
//! ```text
//! I_lim(|ω_m|) = sf·max_curr                                   |ω_m| ≤ ω_rated
//!              = sf·max_curr·(ω_no_load − |ω_m|)/(ω_no_load − ω_rated)   ω_rated < |ω_m| < ω_no_load
//!              = 0                                             |ω_m| ≥ ω_no_load
//! ```
//! (sf = safety factor in (0, 1]; the BLF `PositionToCurrentController`'s limit).
//! [`JointLaw::reset`] is the bumpless-enable hook (filter and integral cleared; the caller also
//! resets the friction model). What happened on a tick (clip, saturation, non-finite) comes back as
//! [`LawFlags`]; frictiond maps them to its ABI's `FLAG_*` bits.
//!
//! [`JointLaw::step`], [`JointLaw::feed_forward_only`] and [`JointLaw::reset`] allocate nothing,
//! take no lock and cannot panic. The low-pass is designed off the RT thread
//! ([`CausalButterworth::design`]).
//!
//! What it is **not**: no friction model (the caller passes `f`), no I/O, no time keeping, no ABI.

use crate::filter::CausalButterworth;

/// What happened during one tick of the law.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LawFlags {
    /// The friction estimate was clipped to ±max_output_friction (velocity gate open).
    pub friction_clipped: bool,
    /// The current was clamped to ±I_lim (max_curr, or the speed-dependent limit).
    pub current_saturated: bool,
    /// A non-finite input or intermediate: the output is 0 and the state was reset.
    pub non_finite: bool,
}

impl LawFlags {
    /// No event.
    pub const NONE: Self = Self {
        friction_clipped: false,
        current_saturated: false,
        non_finite: false,
    };
}

/// Constant per-joint gains and limits of the law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Torque constant kt [Nm/A], > 0.
    pub kt_nm_per_a: f64,
    /// Signed gear ratio r (motor angle per joint angle), non-zero.
    pub gear_ratio: f64,
    /// Friction compensation gain kfc.
    pub kfc: f64,
    /// Proportional gain on the torque error.
    pub kp: f64,
    /// Integral gain on the torque error [1/s].
    pub ki: f64,
    /// Current clamp [A], > 0.
    pub max_curr_a: f64,
    /// Friction clip [Nm] (may be +∞).
    pub max_output_friction_nm: f64,
    /// Velocity gate of the friction clip [rad/s].
    pub joint_velocity_threshold_rad_s: f64,
    /// Tick period [s] (for the integral).
    pub dt_s: f64,
    /// Speed-dependent current limit (none = the constant clamp ±max_curr).
    pub speed_limit: Option<SpeedCurrentLimit>,
}

impl Gains {
    /// Whether the law needs a measured torque (kp or ki non-zero).
    pub fn uses_torque_feedback(&self) -> bool {
        self.kp != 0.0 || self.ki != 0.0
    }

    /// The current limit I_lim [A] at joint velocity ṡ [rad/s]: `max_curr_a`, or the
    /// [`SpeedCurrentLimit`] curve at the motor speed |r·ṡ|. ≥ 0 for a finite ṡ.
    #[inline]
    pub fn current_limit_a(&self, sdot_rad_s: f64) -> f64 {
        match &self.speed_limit {
            None => self.max_curr_a,
            Some(l) => l.limit_a(self.max_curr_a, (self.gear_ratio * sdot_rad_s).abs()),
        }
    }
}

/// A rule of [`SpeedCurrentLimit::new`] that its values break: the field and what it must satisfy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LimitRule {
    /// The field at fault (`rated_motor_speed_rad_s`, `no_load_motor_speed_rad_s`, `safety_factor`).
    pub field: &'static str,
    /// What it must satisfy.
    pub rule: &'static str,
}

impl std::fmt::Display for LimitRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}` {}", self.field, self.rule)
    }
}

impl std::error::Error for LimitRule {}

/// The drive's torque–speed curve as a current limit: `safety_factor · max_curr` up to the rated
/// motor speed, then linear to 0 A at the no-load motor speed, 0 A beyond. Speeds are of the
/// **motor** shaft (|ω_m| = |r·ṡ|, as motor data sheets give them) in rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedCurrentLimit {
    rated_motor_speed_rad_s: f64,
    no_load_motor_speed_rad_s: f64,
    safety_factor: f64,
}

impl SpeedCurrentLimit {
    /// Checks the rules: `0 < rated < no_load`, both finite; `safety_factor` in (0, 1].
    pub fn new(
        rated_motor_speed_rad_s: f64,
        no_load_motor_speed_rad_s: f64,
        safety_factor: f64,
    ) -> Result<Self, LimitRule> {
        if !(rated_motor_speed_rad_s.is_finite() && rated_motor_speed_rad_s > 0.0) {
            return Err(LimitRule {
                field: "rated_motor_speed_rad_s",
                rule: "must be finite and > 0",
            });
        }
        if !(no_load_motor_speed_rad_s.is_finite()
            && no_load_motor_speed_rad_s > rated_motor_speed_rad_s)
        {
            return Err(LimitRule {
                field: "no_load_motor_speed_rad_s",
                rule: "must be finite and > rated_motor_speed_rad_s",
            });
        }
        if !(safety_factor > 0.0 && safety_factor <= 1.0) {
            return Err(LimitRule {
                field: "safety_factor",
                rule: "must be in (0, 1]",
            });
        }
        Ok(Self {
            rated_motor_speed_rad_s,
            no_load_motor_speed_rad_s,
            safety_factor,
        })
    }

    /// Rated motor speed [rad/s]: the end of the flat part.
    pub fn rated_motor_speed_rad_s(&self) -> f64 {
        self.rated_motor_speed_rad_s
    }

    /// No-load motor speed [rad/s]: where the limit reaches 0 A.
    pub fn no_load_motor_speed_rad_s(&self) -> f64 {
        self.no_load_motor_speed_rad_s
    }

    /// Safety factor in (0, 1] on `max_curr`.
    pub fn safety_factor(&self) -> f64 {
        self.safety_factor
    }

    /// The limit [A] for a clamp `max_curr_a` at motor speed |ω_m| = `motor_speed_abs_rad_s` (≥ 0).
    /// A NaN speed gives 0 A.
    #[inline]
    pub fn limit_a(&self, max_curr_a: f64, motor_speed_abs_rad_s: f64) -> f64 {
        let top = self.safety_factor * max_curr_a;
        let w = motor_speed_abs_rad_s;
        if w <= self.rated_motor_speed_rad_s {
            top
        } else if w < self.no_load_motor_speed_rad_s {
            top * (self.no_load_motor_speed_rad_s - w)
                / (self.no_load_motor_speed_rad_s - self.rated_motor_speed_rad_s)
        } else {
            // At and beyond the no-load speed, and for a NaN speed.
            0.0
        }
    }
}

/// One tick's inputs for one joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawInput {
    /// Desired joint torque τ_des [Nm].
    pub tau_des_nm: f64,
    /// Raw friction model output f [Nm] (joint side, sign of motion).
    pub friction_nm: f64,
    /// Measured joint velocity ṡ [rad/s] (for the clip gate).
    pub sdot_rad_s: f64,
    /// Measured joint torque τ_meas [Nm]; only read when kp or ki are non-zero.
    pub tau_meas_nm: f64,
}

/// One tick's result for one joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawOutput {
    /// Commanded motor current [A], finite and within ±I_lim (≤ max_curr).
    pub i_a: f64,
    /// Friction compensation actually applied, τ̂_F [Nm] (after clip, kfc, filter).
    pub tau_f_hat_nm: f64,
    /// What happened on this tick.
    pub flags: LawFlags,
}

/// The law with its per-joint state (LPF, torque-error integral).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLaw {
    /// Gains and limits.
    pub gains: Gains,
    lpf: Option<CausalButterworth>,
    e_int_nm_s: f64,
    /// Last finite ṡ a [`JointLaw::step`] saw [rad/s]: the speed the stale-state output limits at.
    last_sdot_rad_s: f64,
}

/// Friction after the velocity-gated clip: `(f, clipped)`.
#[inline]
pub fn gated_clip(f_nm: f64, sdot_rad_s: f64, g: &Gains) -> (f64, bool) {
    if sdot_rad_s.abs() > g.joint_velocity_threshold_rad_s && f_nm.abs() > g.max_output_friction_nm
    {
        (
            f_nm.clamp(-g.max_output_friction_nm, g.max_output_friction_nm),
            true,
        )
    } else {
        (f_nm, false)
    }
}

/// Clamps a current to ±max: `(i, saturated)`.
#[inline]
pub fn clamp_current(i_a: f64, max_curr_a: f64) -> (f64, bool) {
    if i_a > max_curr_a {
        (max_curr_a, true)
    } else if i_a < -max_curr_a {
        (-max_curr_a, true)
    } else {
        (i_a, false)
    }
}

impl JointLaw {
    /// A law with an optional pre-designed LPF (design it off the RT thread).
    pub fn new(gains: Gains, lpf: Option<CausalButterworth>) -> Self {
        Self {
            gains,
            lpf,
            e_int_nm_s: 0.0,
            last_sdot_rad_s: 0.0,
        }
    }

    /// Bumpless enable / after a fault: clears the filter (to 0) and the integral.
    pub fn reset(&mut self) {
        if let Some(f) = &mut self.lpf {
            f.reset_to(0.0);
        }
        self.e_int_nm_s = 0.0;
    }

    /// The torque-error integral [Nm·s].
    pub fn integral_nm_s(&self) -> f64 {
        self.e_int_nm_s
    }

    /// One tick of the law.
    #[inline]
    pub fn step(&mut self, x: &LawInput) -> LawOutput {
        let g = self.gains;
        let feedback = g.uses_torque_feedback();
        let inputs_finite = x.tau_des_nm.is_finite()
            && x.friction_nm.is_finite()
            && x.sdot_rad_s.is_finite()
            && (!feedback || x.tau_meas_nm.is_finite());
        if !inputs_finite {
            return self.non_finite();
        }
        self.last_sdot_rad_s = x.sdot_rad_s;
        let mut flags = LawFlags::NONE;
        let (f, clipped) = gated_clip(x.friction_nm, x.sdot_rad_s, &g);
        flags.friction_clipped = clipped;
        let mut tau_f = if g.kfc > 0.0 { g.kfc * f } else { 0.0 };
        if let Some(lpf) = &mut self.lpf {
            tau_f = lpf.step(tau_f);
        }
        let mut fb = 0.0;
        if feedback {
            let e = x.tau_des_nm - x.tau_meas_nm;
            if g.ki > 0.0 {
                // Anti-windup: the integral alone never asks for more than max_curr.
                let lim = g.max_curr_a * (g.kt_nm_per_a * g.gear_ratio).abs() / g.ki;
                self.e_int_nm_s = (self.e_int_nm_s + e * g.dt_s).clamp(-lim, lim);
            }
            fb = g.kp * e + g.ki * self.e_int_nm_s;
        }
        let i = (x.tau_des_nm + fb + tau_f) / (g.kt_nm_per_a * g.gear_ratio);
        if !i.is_finite() || !tau_f.is_finite() {
            return self.non_finite();
        }
        let (i, sat) = clamp_current(i, g.current_limit_a(x.sdot_rad_s));
        flags.current_saturated = sat;
        LawOutput {
            i_a: i,
            tau_f_hat_nm: tau_f,
            flags,
        }
    }

    /// Static output (stale state): i = τ_des/(kt·r), clamped; no friction, no feedback. The
    /// speed-dependent limit is taken at the last finite ṡ a [`JointLaw::step`] saw (0 before any).
    #[inline]
    pub fn feed_forward_only(&mut self, tau_des_nm: f64) -> LawOutput {
        let g = self.gains;
        let i = tau_des_nm / (g.kt_nm_per_a * g.gear_ratio);
        if !i.is_finite() {
            return self.non_finite();
        }
        let (i, sat) = clamp_current(i, g.current_limit_a(self.last_sdot_rad_s));
        LawOutput {
            i_a: i,
            tau_f_hat_nm: 0.0,
            flags: LawFlags {
                current_saturated: sat,
                ..LawFlags::NONE
            },
        }
    }

    fn non_finite(&mut self) -> LawOutput {
        // NaN must not stay inside the filter or the integral: start clean next tick.
        self.reset();
        LawOutput {
            i_a: 0.0,
            tau_f_hat_nm: 0.0,
            flags: LawFlags {
                non_finite: true,
                ..LawFlags::NONE
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gains() -> Gains {
        Gains {
            kt_nm_per_a: 0.0665,
            gear_ratio: -160.0,
            kfc: 0.7,
            kp: 0.0,
            ki: 0.0,
            max_curr_a: 3.0,
            max_output_friction_nm: 8.0,
            joint_velocity_threshold_rad_s: 0.05,
            dt_s: 1e-3,
            speed_limit: None,
        }
    }

    fn input(tau_des: f64, f: f64, sdot: f64) -> LawInput {
        LawInput {
            tau_des_nm: tau_des,
            friction_nm: f,
            sdot_rad_s: sdot,
            tau_meas_nm: f64::NAN,
        }
    }

    #[test]
    fn feed_forward_with_friction_uses_signed_ratio() {
        let mut law = JointLaw::new(gains(), None);
        let out = law.step(&input(2.0, 1.5, 0.3));
        let want = (2.0 + 0.7 * 1.5) / (0.0665 * -160.0);
        assert!((out.i_a - want).abs() < 1e-12, "{} vs {want}", out.i_a);
        assert!(out.i_a < 0.0, "negative ratio flips the current");
        assert!((out.tau_f_hat_nm - 1.05).abs() < 1e-12);
        assert_eq!(out.flags, LawFlags::NONE);
        // The torque produced, r·kt·i, equals τ_des + τ̂_F.
        assert!((-160.0 * 0.0665 * out.i_a - 3.05).abs() < 1e-12);
    }

    #[test]
    fn friction_clip_is_gated_by_velocity() {
        let mut law = JointLaw::new(gains(), None);
        // Above the gate: clipped to 8 Nm before kfc.
        let out = law.step(&input(0.0, 20.0, 0.5));
        assert!((out.tau_f_hat_nm - 0.7 * 8.0).abs() < 1e-12);
        assert!(out.flags.friction_clipped);
        // Below the gate: not clipped (BLF behaviour), the current clamp still bounds the output.
        let out = law.step(&input(0.0, 20.0, 0.01));
        assert!((out.tau_f_hat_nm - 14.0).abs() < 1e-12);
        assert!(!out.flags.friction_clipped);
        // Negative side.
        let out = law.step(&input(0.0, -20.0, -0.5));
        assert!((out.tau_f_hat_nm + 5.6).abs() < 1e-12);
    }

    #[test]
    fn kfc_zero_disables_compensation() {
        let mut law = JointLaw::new(
            Gains {
                kfc: 0.0,
                ..gains()
            },
            None,
        );
        let out = law.step(&input(1.0, 5.0, 1.0));
        assert_eq!(out.tau_f_hat_nm, 0.0);
        assert!((out.i_a - 1.0 / (0.0665 * -160.0)).abs() < 1e-12);
    }

    #[test]
    fn current_is_clamped_both_ways() {
        let mut law = JointLaw::new(gains(), None);
        let out = law.step(&input(100.0, 0.0, 0.0));
        assert_eq!(out.i_a, -3.0);
        assert!(out.flags.current_saturated);
        let out = law.step(&input(-100.0, 0.0, 0.0));
        assert_eq!(out.i_a, 3.0);
    }

    #[test]
    fn non_finite_inputs_give_zero_and_do_not_poison_the_filter() {
        let lpf = CausalButterworth::design(2, 10.0, 1000.0).unwrap();
        let mut law = JointLaw::new(gains(), Some(lpf));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for x in [
                input(bad, 1.0, 0.1),
                input(1.0, bad, 0.1),
                input(1.0, 1.0, bad),
            ] {
                let out = law.step(&x);
                assert_eq!(out.i_a, 0.0);
                assert!(out.flags.non_finite);
            }
        }
        let out = law.step(&input(1.0, 1.0, 0.1));
        assert!(out.i_a.is_finite() && out.i_a != 0.0 && out.flags == LawFlags::NONE);
        // NaN τ_meas is fine without feedback, fatal with it.
        let mut fb = JointLaw::new(Gains { kp: 1.0, ..gains() }, None);
        assert!(fb.step(&input(1.0, 0.0, 0.0)).flags.non_finite);
        // A huge (finite) value still clamps, not NaN.
        let out = law.step(&input(1e308, 1e308, 1.0));
        assert!(out.i_a.abs() <= 3.0);
    }

    #[test]
    fn lpf_smooths_and_reset_is_bumpless() {
        let lpf = CausalButterworth::design(2, 5.0, 1000.0).unwrap();
        let mut law = JointLaw::new(gains(), Some(lpf));
        let first = law.step(&input(0.0, 2.0, 1.0));
        assert!(
            first.tau_f_hat_nm.abs() < 0.1 * 1.4,
            "filtered step starts small"
        );
        let mut last = first;
        for _ in 0..3000 {
            last = law.step(&input(0.0, 2.0, 1.0));
        }
        assert!((last.tau_f_hat_nm - 1.4).abs() < 1e-6);
        law.reset();
        let after = law.step(&input(0.0, 2.0, 1.0));
        assert!((after.tau_f_hat_nm - first.tau_f_hat_nm).abs() < 1e-12);
    }

    #[test]
    fn pi_on_torque_error_with_anti_windup() {
        let g = Gains {
            kp: 0.5,
            ki: 10.0,
            kfc: 0.0,
            ..gains()
        };
        let mut law = JointLaw::new(g, None);
        let x = LawInput {
            tau_des_nm: 1.0,
            friction_nm: 0.0,
            sdot_rad_s: 0.0,
            tau_meas_nm: 0.6,
        };
        let out = law.step(&x);
        let e = 0.4;
        let want = (1.0 + 0.5 * e + 10.0 * e * 1e-3) / (0.0665 * -160.0);
        assert!((out.i_a - want).abs() < 1e-12, "{} vs {want}", out.i_a);
        for _ in 0..1_000_000 {
            law.step(&x);
        }
        let lim = 3.0 * (0.0665 * 160.0) / 10.0;
        assert!(
            (law.integral_nm_s() - lim).abs() < 1e-9,
            "{}",
            law.integral_nm_s()
        );
        law.reset();
        assert_eq!(law.integral_nm_s(), 0.0);
    }

    #[test]
    fn feed_forward_only_ignores_friction() {
        let mut law = JointLaw::new(gains(), None);
        let out = law.feed_forward_only(1.0);
        assert!((out.i_a - 1.0 / (0.0665 * -160.0)).abs() < 1e-12);
        assert_eq!(out.tau_f_hat_nm, 0.0);
        assert_eq!(law.feed_forward_only(f64::NAN).i_a, 0.0);
    }

    /// r = −160, max_curr 3 A, sf 0.5: 1.5 A up to 100 rad/s at the motor (0.625 rad/s at the
    /// joint), 0 A from 300 rad/s (1.875 rad/s).
    fn limited() -> Gains {
        Gains {
            speed_limit: Some(SpeedCurrentLimit::new(100.0, 300.0, 0.5).unwrap()),
            ..gains()
        }
    }

    #[test]
    fn speed_limit_at_the_knee_points() {
        let g = limited();
        let lim = |sdot: f64| g.current_limit_a(sdot);
        // Flat part, both directions of motion, up to and at the rated speed.
        assert_eq!(lim(0.0), 1.5);
        assert_eq!(lim(0.3), 1.5);
        assert_eq!(lim(100.0 / 160.0), 1.5);
        assert_eq!(lim(-100.0 / 160.0), 1.5);
        // Half-way down the slope: 200 rad/s at the motor.
        assert!((lim(200.0 / 160.0) - 0.75).abs() < 1e-12);
        assert!((lim(-200.0 / 160.0) - 0.75).abs() < 1e-12);
        // Just past the knee: continuous.
        assert!((lim(100.0001 / 160.0) - 1.5).abs() < 1e-5);
        assert!(lim(100.0001 / 160.0) < 1.5);
        // At and beyond the no-load speed: 0 A.
        assert_eq!(lim(300.0 / 160.0), 0.0);
        assert_eq!(lim(10.0), 0.0);
        assert_eq!(lim(f64::NAN), 0.0);
        // Without a speed limit: the constant clamp at every speed.
        assert_eq!(gains().current_limit_a(100.0), 3.0);
    }

    #[test]
    fn step_clamps_to_the_speed_limit_and_flags_it() {
        let mut law = JointLaw::new(limited(), None);
        // A 100 Nm request wants far more than any limit; the sign follows r < 0.
        for (sdot, want) in [(0.0, 1.5), (200.0 / 160.0, 0.75), (2.0, 0.0)] {
            let out = law.step(&input(100.0, 0.0, sdot));
            assert!(
                (out.i_a + want).abs() < 1e-12,
                "ṡ {sdot}: {} vs -{want}",
                out.i_a
            );
            assert!(out.flags.current_saturated);
        }
        // Within the limit: unchanged, not flagged.
        let out = law.step(&input(1.0, 0.0, 200.0 / 160.0));
        assert!((out.i_a - 1.0 / (0.0665 * -160.0)).abs() < 1e-12);
        assert!(!out.flags.current_saturated);
        // The stale-state output limits at the last speed a step saw (here 0.75 A).
        let out = law.feed_forward_only(100.0);
        assert!((out.i_a + 0.75).abs() < 1e-12, "{}", out.i_a);
        assert!(out.flags.current_saturated);
    }

    #[test]
    fn speed_limit_rules_name_the_field() {
        let field = |r: f64, n: f64, f: f64| SpeedCurrentLimit::new(r, n, f).unwrap_err().field;
        assert_eq!(field(0.0, 300.0, 1.0), "rated_motor_speed_rad_s");
        assert_eq!(field(f64::NAN, 300.0, 1.0), "rated_motor_speed_rad_s");
        assert_eq!(field(f64::INFINITY, 300.0, 1.0), "rated_motor_speed_rad_s");
        assert_eq!(field(100.0, 100.0, 1.0), "no_load_motor_speed_rad_s");
        assert_eq!(
            field(100.0, f64::INFINITY, 1.0),
            "no_load_motor_speed_rad_s"
        );
        assert_eq!(field(100.0, 300.0, 0.0), "safety_factor");
        assert_eq!(field(100.0, 300.0, 1.01), "safety_factor");
        assert_eq!(field(100.0, 300.0, f64::NAN), "safety_factor");
        assert!(SpeedCurrentLimit::new(100.0, 300.0, 1.0).is_ok());
    }
}
