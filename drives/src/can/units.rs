//! Per-joint unit mapping between the daemon and a drive.
//!
//! The daemon computes a **motor current** i [A]. A drive wants one of ([`CommandUnit`]):
//! current i, motor torque k_t·i [Nm], or joint torque r·k_t·i [Nm] with the **signed** gear ratio r
//! (θ_motor = r·s). Feedback arrives motor side in rad or rev ([`AngleUnit`]) and maps back to the
//! joint side as s = θ/r, ṡ = ω/r.
//!
//! Not here: friction, filtering, saturation limits (the daemon clamps currents before encoding).

use super::CanCodecError;

/// What quantity a drive's command field carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandUnit {
    /// Motor current [A].
    Current,
    /// Motor-side torque [Nm] = k_t·i.
    MotorTorque,
    /// Joint-side torque [Nm] = r·k_t·i.
    JointTorque,
}

/// Unit of the motor-side angle a drive reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AngleUnit {
    /// Radians (MIT mode).
    Rad,
    /// Revolutions (ODrive).
    Rev,
}

impl AngleUnit {
    /// Radians per unit.
    pub fn rad_per_unit(self) -> f64 {
        match self {
            AngleUnit::Rad => 1.0,
            AngleUnit::Rev => core::f64::consts::TAU,
        }
    }
}

/// A joint's mapping. Build with [`JointUnits::new`] (validates).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointUnits {
    /// What the drive's command field carries.
    pub command: CommandUnit,
    /// Motor torque constant k_t [Nm/A] (> 0).
    pub kt_nm_per_a: f64,
    /// Signed gear ratio r: θ_motor = r·s (negative when the drive turns the other way).
    pub gear_ratio: f64,
    /// Unit of the reported motor-side position/velocity.
    pub feedback_angle: AngleUnit,
}

impl JointUnits {
    /// Validated constructor: k_t finite and > 0, r finite and ≠ 0.
    pub fn new(
        command: CommandUnit,
        kt_nm_per_a: f64,
        gear_ratio: f64,
        feedback_angle: AngleUnit,
    ) -> Result<Self, CanCodecError> {
        let u = Self {
            command,
            kt_nm_per_a,
            gear_ratio,
            feedback_angle,
        };
        u.validate()?;
        Ok(u)
    }

    /// Checks k_t and r (for values that came from serde).
    pub fn validate(&self) -> Result<(), CanCodecError> {
        if !(self.kt_nm_per_a.is_finite() && self.kt_nm_per_a > 0.0) {
            return Err(CanCodecError::BadUnitParameter {
                field: "kt_nm_per_a",
                value: self.kt_nm_per_a,
            });
        }
        if !(self.gear_ratio.is_finite() && self.gear_ratio != 0.0) {
            return Err(CanCodecError::BadUnitParameter {
                field: "gear_ratio",
                value: self.gear_ratio,
            });
        }
        Ok(())
    }

    /// Command value for motor current `i_motor_a`: i, k_t·i or r·k_t·i.
    #[inline]
    pub fn command_from_current(&self, i_motor_a: f64) -> f64 {
        match self.command {
            CommandUnit::Current => i_motor_a,
            CommandUnit::MotorTorque => self.kt_nm_per_a * i_motor_a,
            CommandUnit::JointTorque => self.gear_ratio * self.kt_nm_per_a * i_motor_a,
        }
    }

    /// Inverse of [`Self::command_from_current`] (what current a command value means).
    #[inline]
    pub fn current_from_command(&self, value: f64) -> f64 {
        match self.command {
            CommandUnit::Current => value,
            CommandUnit::MotorTorque => value / self.kt_nm_per_a,
            CommandUnit::JointTorque => value / (self.gear_ratio * self.kt_nm_per_a),
        }
    }

    /// Motor angle [motor rad] from the drive's reported position.
    #[inline]
    pub fn motor_rad(&self, reported: f64) -> f64 {
        reported * self.feedback_angle.rad_per_unit()
    }

    /// Joint position s [rad] = θ/r from the drive's reported motor position.
    #[inline]
    pub fn joint_position_rad(&self, reported_pos: f64) -> f64 {
        self.motor_rad(reported_pos) / self.gear_ratio
    }

    /// Joint velocity ṡ [rad/s] = ω/r from the drive's reported motor velocity.
    #[inline]
    pub fn joint_velocity_rad_s(&self, reported_vel: f64) -> f64 {
        self.motor_rad(reported_vel) / self.gear_ratio
    }

    /// Drive-unit motor position for joint position `s_rad` (θ = r·s; for emulators and tests).
    #[inline]
    pub fn reported_from_joint_rad(&self, s_rad: f64) -> f64 {
        self.gear_ratio * s_rad / self.feedback_angle.rad_per_unit()
    }
}
