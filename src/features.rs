//! Feature sets, history buffers, warm-up and the Δθ offset latch.
//!
//! (skeleton — filled in by the friction/features work)

/// Which per-tick signals a network consumes, in block order. Each block holds `H` samples, oldest
/// first; the optional motor temperature comes last as one value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeatureSet {
    /// `[Δθ ×H, ṡ ×H]` with Δθ = r·s − θ [motor rad] (offset latched) and ṡ [rad/s] — the paper's.
    DeltaThetaJointVel,
    /// `[ω_m ×H, ṡ ×H]` motor velocity [motor rad/s] and joint velocity [rad/s] — ergoCub since Oct 2024.
    MotorVelJointVel,
    /// `[s ×H, θ ×H]` joint position [rad] and motor position [motor rad] — the June 2024 ergoCub model.
    JointPosMotorPos,
}

/// A feature set with its history length and whether motor temperature [°C] is appended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct FeatureSpec {
    /// Signals and their order.
    pub set: FeatureSet,
    /// History length H (samples per block, ≥ 1).
    pub history: usize,
    /// Whether one motor-temperature value [°C] follows the blocks.
    pub temperature: bool,
}

impl FeatureSpec {
    /// Length of the input vector: 2·H (+1 with temperature).
    pub fn n_inputs(&self) -> usize {
        2 * self.history + usize::from(self.temperature)
    }
}

/// One tick of joint/motor state, as the estimators consume it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointSample {
    /// Joint position s [rad].
    pub s_rad: f64,
    /// Joint velocity ṡ [rad/s].
    pub sdot_rad_s: f64,
    /// Motor position θ [motor rad].
    pub theta_motor_rad: f64,
    /// Motor velocity ω_m [motor rad/s].
    pub omega_motor_rad_s: f64,
    /// Motor temperature [°C] (NaN when the joint has no sensor).
    pub temperature_c: f64,
}
