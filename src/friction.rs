//! Static joint-side friction models: Coulomb–viscous (CV) and Stribeck–Coulomb–viscous (SCV).
//!
//! Velocity `v` is the joint velocity ṡ in rad/s; friction is joint-side torque in Nm, with the sign
//! of the motion (it is what the motor must add to move the joint).
//!
//! (skeleton — filled in by the friction/features work)

/// Coulomb–viscous: τ = kc·tanh(ka·v) + kv·v.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CvParams {
    /// Coulomb level kc [Nm].
    pub kc: f64,
    /// Smooth-sign steepness ka [s/rad].
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad].
    pub kv: f64,
}

/// Stribeck–Coulomb–viscous, paper form:
/// τ = kv·v + kc·tanh(ka·v) + (ks − kc)·exp(−|v/vs|^α)·tanh(ka·v).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScvParams {
    /// Coulomb level kc [Nm].
    pub kc: f64,
    /// Smooth-sign steepness ka [s/rad].
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad].
    pub kv: f64,
    /// Breakaway (static) friction ks [Nm].
    pub ks: f64,
    /// Stribeck velocity vs [rad/s].
    pub vs: f64,
    /// Stribeck shape exponent α [-].
    pub alpha: f64,
}

/// Stribeck–Coulomb–viscous, the authors' training-code form (ka → ∞, α = 2):
/// τ = (Fc + (Fs − Fc)·exp(−(v/Vs)²))·sign(v) + Fv·v.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScvCodeParams {
    /// Coulomb level Fc [Nm].
    pub fc: f64,
    /// Static level Fs [Nm].
    pub fs: f64,
    /// Viscous Fv [Nm·s/rad].
    pub fv: f64,
    /// Stribeck velocity Vs [rad/s].
    pub vs: f64,
}
