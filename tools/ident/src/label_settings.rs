//! The labelling settings a caller gives over a joint's defaults: resampling, the Butterworth
//! filter, the Kalman smoother, the sample limits, the label filter and the ripple step.
//!
//! What this module **is**: [`LabelSettings`], a plain value (no argument parser) that
//! [`LabelSettings::apply`] writes into a [`PreprocessConfig`] made for the joint, so per-joint
//! defaults (the ankle roll's τ_F limit) stay where no value is given.
//!
//! What it is **not**: the chunk gap, the joint and the reflected inertia, which each caller sets
//! itself (their defaults differ by log format).

use crate::kalman::KalmanConfig;
use crate::preprocess::{LabelFilter, PreprocessConfig, Ripple};

/// The settings [`LabelSettings::apply`] writes into a joint's [`PreprocessConfig`].
#[derive(Clone, Debug, PartialEq)]
pub struct LabelSettings {
    /// Output sample rate [Hz].
    pub fs_hz: f64,
    /// Butterworth order for the current.
    pub butter_order: usize,
    /// Butterworth cut-off [Hz].
    pub butter_cutoff_hz: f64,
    /// Causal ṡ/s̈ columns (the forward Kalman filter) instead of the smoother's.
    pub causal: bool,
    /// The Kalman smoother's P₀, Q and R.
    pub kalman: KalmanConfig,
    /// |s̈| limit [rad/s²].
    pub joint_acc_limit_rad_s2: f64,
    /// |ṡ| limit [rad/s].
    pub joint_vel_limit_rad_s: f64,
    /// |i_f| limit [A] (`None`: the joint's default).
    pub im_limit_a: Option<f64>,
    /// |τ_F| limit [Nm] (`None`: the joint's default).
    pub tauf_limit_nm: Option<f64>,
    /// How the current label's current is filtered.
    pub label_filter: LabelFilter,
    /// The matched label's ripple step.
    pub ripple: Ripple,
}

impl LabelSettings {
    /// Writes these settings into `cfg` (made by [`PreprocessConfig::for_joint`]).
    pub fn apply(&self, cfg: &mut PreprocessConfig) {
        cfg.fs_hz = self.fs_hz;
        cfg.butter_order = self.butter_order;
        cfg.butter_cutoff_hz = self.butter_cutoff_hz;
        cfg.causal = self.causal;
        cfg.kalman = self.kalman;
        cfg.limits.joint_acc_limit_rad_s2 = self.joint_acc_limit_rad_s2;
        cfg.limits.joint_vel_limit_rad_s = self.joint_vel_limit_rad_s;
        if let Some(v) = self.im_limit_a {
            cfg.limits.im_limit_a = v;
        }
        if let Some(v) = self.tauf_limit_nm {
            cfg.limits.tauf_limit_nm = v;
        }
        cfg.label_filter = self.label_filter;
        cfg.ripple = self.ripple;
    }
}
