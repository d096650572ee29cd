//! Payloads of the virtual plant (`frictl sim serve`): diagnostics out, disturbances in.
//!
//! What this module **is**: two extra `#[repr(C)]` payloads that only the simulator speaks —
//! [`SimTruth`] (the true friction and internal state behind each [`crate::JointStates`] sample, for
//! experiments that compare τ̂_F with the truth) and [`SimDisturbance`] (external joint torques the
//! plant applies, for the paper's disturbance-rejection test). A real robot never publishes them.
//!
//! What it is **not**: no model inputs. `frictiond` never reads these services.

use iceoryx2::prelude::ZeroCopySend;

use crate::MAX_JOINTS;

/// True plant quantities behind the [`crate::JointStates`] sample with the same `seq`.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::SimTruth_v2")]
pub struct SimTruth {
    /// Equal to the `seq` of the [`crate::JointStates`] published with it.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] of publication.
    pub stamp_ns: u64,
    /// Simulated time [s] of the sample.
    pub sim_time_s: f64,
    /// Number of valid joints.
    pub n_joints: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// True joint-side friction τ_F = τ_Fm + τ_Fj over the last physics step [Nm].
    pub tau_f_true_nm: [f64; MAX_JOINTS],
    /// External joint torque applied during the last step [Nm].
    pub tau_ext_nm: [f64; MAX_JOINTS],
    /// True (unquantised) joint angle s [rad].
    pub s_true_rad: [f64; MAX_JOINTS],
    /// True joint velocity ṡ [rad/s].
    pub sdot_true_rad_s: [f64; MAX_JOINTS],
    /// Actual motor current after the current-loop lag (robot convention) [A].
    pub current_true_a: [f64; MAX_JOINTS],
    /// Current reference the plant applied during the last step [A] (after hold/timeout rules).
    pub i_applied_a: [f64; MAX_JOINTS],
    /// True motor acceleration reflected to the joint φ̈ [rad/s²] (the `phi_ddot` column of a
    /// simulated acquisition log).
    pub phi_ddot_rad_s2: [f64; MAX_JOINTS],
}

impl SimTruth {
    /// All zeros.
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            sim_time_s: 0.0,
            n_joints: 0,
            reserved: 0,
            tau_f_true_nm: [0.0; MAX_JOINTS],
            tau_ext_nm: [0.0; MAX_JOINTS],
            s_true_rad: [0.0; MAX_JOINTS],
            sdot_true_rad_s: [0.0; MAX_JOINTS],
            current_true_a: [0.0; MAX_JOINTS],
            i_applied_a: [0.0; MAX_JOINTS],
            phi_ddot_rad_s2: [0.0; MAX_JOINTS],
        }
    }
}

impl Default for SimTruth {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// External joint torques for the virtual plant (experiment → plant). The newest value is applied
/// until replaced; publish zeros to release.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("frictionless::SimDisturbance_v1")]
pub struct SimDisturbance {
    /// Sequence number, +1 per message.
    pub seq: u64,
    /// CLOCK_MONOTONIC time [ns] of the request.
    pub stamp_ns: u64,
    /// Number of valid joints.
    pub n_joints: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// External torque on the joint output [Nm] (positive = increases s).
    pub tau_ext_nm: [f64; MAX_JOINTS],
}

impl SimDisturbance {
    /// All zeros.
    pub const fn zeroed() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            n_joints: 0,
            reserved: 0,
            tau_ext_nm: [0.0; MAX_JOINTS],
        }
    }
}

impl Default for SimDisturbance {
    fn default() -> Self {
        Self::zeroed()
    }
}
