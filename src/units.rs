//! Units and sign conventions.
//!
//! Everything in this crate is SI. Joint-side angles are radians, motor-side angles are *motor* radians
//! (θ = r·s for a rigid transmission). The gear ratio is signed: its sign says whether the motor turns
//! the same way as the joint. It is a float, never truncated to an integer.

use std::fmt;

/// Signed gear ratio r, motor angle per joint angle (θ = r·s for a rigid drive), e.g. −160.0.
///
/// Construct with [`GearRatio::new`], which refuses zero, NaN and infinities.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "f64", into = "f64")]
pub struct GearRatio(f64);

/// Error returned for an invalid gear ratio.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("gear ratio must be finite and non-zero (|r| >= 1e-6), got {0}")]
pub struct InvalidGearRatio(pub f64);

impl GearRatio {
    /// A signed gear ratio; errors for zero, |r| < 1e-6, NaN or ±∞.
    pub fn new(r: f64) -> Result<Self, InvalidGearRatio> {
        if r.is_finite() && r.abs() >= 1e-6 {
            Ok(Self(r))
        } else {
            Err(InvalidGearRatio(r))
        }
    }
    /// The signed value r.
    #[inline]
    pub fn get(self) -> f64 {
        self.0
    }
    /// Motor-side angle of a rigid drive for a joint angle: r·s [motor rad].
    #[inline]
    pub fn motor_rad_from_joint_rad(self, s_rad: f64) -> f64 {
        self.0 * s_rad
    }
    /// Joint-side torque produced by motor current `i_a` through torque constant `kt`: r·kt·i [Nm].
    #[inline]
    pub fn joint_torque_nm(self, kt_nm_per_a: f64, i_a: f64) -> f64 {
        self.0 * kt_nm_per_a * i_a
    }
    /// Motor current that produces joint torque `tau_nm`: τ/(kt·r) [A].
    #[inline]
    pub fn current_a_for_joint_torque(self, kt_nm_per_a: f64, tau_nm: f64) -> f64 {
        tau_nm / (kt_nm_per_a * self.0)
    }
}

impl TryFrom<f64> for GearRatio {
    type Error = InvalidGearRatio;
    fn try_from(v: f64) -> Result<Self, Self::Error> {
        Self::new(v)
    }
}

impl From<GearRatio> for f64 {
    fn from(r: GearRatio) -> f64 {
        r.0
    }
}

impl fmt::Display for GearRatio {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_zero_and_nan() {
        assert!(GearRatio::new(0.0).is_err());
        assert!(GearRatio::new(f64::NAN).is_err());
        assert!(GearRatio::new(f64::INFINITY).is_err());
        assert_eq!(GearRatio::new(-160.0).unwrap().get(), -160.0);
    }

    #[test]
    fn torque_current_round_trip_keeps_sign() {
        let r = GearRatio::new(-160.0).unwrap();
        let kt = 0.0665;
        let i = r.current_a_for_joint_torque(kt, 2.0);
        assert!(i < 0.0, "negative ratio flips the current sign");
        assert!((r.joint_torque_nm(kt, i) - 2.0).abs() < 1e-12);
    }
}
