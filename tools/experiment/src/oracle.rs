//! The oracle: friction compensation with the plant's *true* friction — a diagnostic **bound**, not a
//! model a robot can run (no robot measures its own friction torque).
//!
//! What this module **is**: [`OracleCompensation`], frictiond's per-joint law
//! ([`frictionless::law::JointLaw`], the same code frictiond runs: velocity-gated clip to
//! ±max_output_friction, ×kfc, optional Butterworth low-pass, state cleared at enable) fed with
//! τ_F,true instead of a model output, reading back the compensation τ̂_F it applies. In an
//! `oracle` trial frictiond runs `friction_model = "none"` for the joint, and the experiment
//! controller adds this term to τ_des for the request that answers `JointStates` seq k, using
//! `SimTruth` seq k (the true friction of the plant's last physics step, the one that produced state
//! k) and the measured ṡ of state k for the clip gate. With frictiond's feed-forward law
//! (`kp = ki = 0`: i = (τ_des + τ̂_F)/(k_t·r)) that is exactly the current a perfect estimator inside
//! frictiond at tick k would command — same kfc, clip and LPF — so the oracle's minimum K_p is what
//! the control structure (kfc, K_d, the controller's M) allows with a perfect friction estimate. If a
//! model's minimum K_p is close to the oracle's, the estimator is not what limits it.
//!
//! What it is **not**: no estimator, no I/O; lockstep only (in real time the controller could not
//! pair a request with the truth of the state it answers).

use frictionless::filter::CausalButterworth;
use frictionless::law::{Gains, JointLaw, LawInput};

use super::ExperimentError;
use super::session::{LawSettings, Lpf};

/// Daemon tick rate [Hz] (the experiments' `period_us = 1000`).
const FS_HZ: f64 = 1000.0;

/// frictiond's compensation law applied to the true friction (see the module doc).
#[derive(Clone, Debug)]
pub struct OracleCompensation {
    settings: LawSettings,
    law: JointLaw,
}

impl OracleCompensation {
    /// The compensation of a joint whose law is `settings` (filter state zero, as after an enable).
    pub fn new(settings: LawSettings) -> Result<Self, ExperimentError> {
        let lpf = match settings.lpf {
            Lpf::Off => None,
            Lpf::Butterworth { order, cutoff_hz } => Some(
                CausalButterworth::design(order, cutoff_hz, FS_HZ)
                    .map_err(ExperimentError::OracleLpf)?,
            ),
        };
        // Only τ̂_F is read back: unit kt·r, no torque feedback and no current clamp, so the current
        // path neither saturates nor flags anything.
        let gains = Gains {
            kt_nm_per_a: 1.0,
            gear_ratio: 1.0,
            kfc: settings.kfc,
            kp: 0.0,
            ki: 0.0,
            max_curr_a: f64::INFINITY,
            max_output_friction_nm: settings.max_output_friction_nm,
            joint_velocity_threshold_rad_s: settings.joint_velocity_threshold_rad_s,
            dt_s: 1.0 / FS_HZ,
            speed_limit: None,
        };
        Ok(Self {
            settings,
            law: JointLaw::new(gains, lpf),
        })
    }

    /// The law it mimics.
    pub fn law(&self) -> &LawSettings {
        &self.settings
    }

    /// One tick: the term [Nm] to add to τ_des for true friction `tau_f_true_nm` and measured joint
    /// velocity `sdot_rad_s` (the clip gate). Non-finite input gives 0 and clears the filter, as
    /// frictiond does.
    pub fn step(&mut self, tau_f_true_nm: f64, sdot_rad_s: f64) -> f64 {
        self.law
            .step(&LawInput {
                tau_des_nm: 0.0,
                friction_nm: tau_f_true_nm,
                sdot_rad_s,
                tau_meas_nm: 0.0,
            })
            .tau_f_hat_nm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn law(kfc: f64, clip: f64, lpf: Lpf) -> LawSettings {
        LawSettings {
            kfc,
            max_output_friction_nm: clip,
            joint_velocity_threshold_rad_s: 0.01,
            lpf,
        }
    }

    #[test]
    fn unfiltered_is_kfc_times_clipped_truth_with_the_velocity_gate() {
        let mut o = OracleCompensation::new(law(0.7, 2.0, Lpf::Off)).unwrap();
        assert_eq!(o.step(1.5, 0.3), 0.7 * 1.5);
        // moving: clipped to ±2 before kfc
        assert_eq!(o.step(-3.0, 0.3), 0.7 * -2.0);
        // below the gate: not clipped
        assert_eq!(o.step(-3.0, 0.001), 0.7 * -3.0);
        assert_eq!(o.step(f64::NAN, 0.3), 0.0);
    }

    #[test]
    fn filtered_matches_scipy_design_run_as_a_whole_signal() {
        let l = law(
            0.85,
            f64::INFINITY,
            Lpf::Butterworth {
                order: 2,
                cutoff_hz: 30.0,
            },
        );
        let mut o = OracleCompensation::new(l).unwrap();
        let x: Vec<f64> = (0..500)
            .map(|k| (k as f64 * 0.05).sin() + if k > 200 { 1.0 } else { 0.0 })
            .collect();
        let ours: Vec<f64> = x.iter().map(|&v| o.step(v, 1.0)).collect();
        let scaled: Vec<f64> = x.iter().map(|v| 0.85 * v).collect();
        let reference = frictionless::filter::Butterworth::lowpass(2, 30.0, 1000.0)
            .unwrap()
            .filter(&scaled);
        for (a, b) in ours.iter().zip(&reference) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // a low-pass: the step at k = 200 is not passed through at once
        assert!((ours[201] - ours[200]).abs() < 0.85 * 0.5);
    }
}
