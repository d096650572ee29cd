//! The oracle: friction compensation with the plant's *true* friction — a diagnostic **bound**, not a
//! model a robot can run (no robot measures its own friction torque).
//!
//! What this module **is**: [`OracleCompensation`], the friction-compensation part of frictiond's law
//! (`daemon/src/control.rs`: velocity-gated clip to ±max_output_friction, ×kfc, optional Butterworth
//! low-pass, state cleared at enable) applied to τ_F,true instead of a model output. In an
//! `oracle` trial frictiond runs `friction_model = "none"` for the joint, and the experiment
//! controller adds this term to τ_des for the request that answers `JointStates` seq k, using
//! `SimTruth` seq k (the true friction of the plant's last physics step, the one that produced state
//! k) and the measured ṡ of state k for the clip gate. With frictiond's feed-forward law
//! (`kp = ki = 0`: i = (τ_des + τ̂_F)/(k_t·r)) that is exactly the current a perfect estimator inside
//! frictiond at tick k would command — same kfc, clip and LPF — so the oracle's minimum K_p is what
//! the control structure (kfc, K_d, the controller's M) allows with a perfect friction estimate. If a
//! model's minimum K_p is close to the oracle's, the estimator is not what limits it.
//!
//! The low-pass is designed by [`frictionless_ident::filter::Butterworth::lowpass`] (scipy's design; the
//! same bilinear-transform Butterworth with pre-warping as frictiond's, equal up to rounding) and
//! run here one sample at a time in transposed direct form II (tools must not depend on the daemon).
//!
//! What it is **not**: no estimator, no I/O; lockstep only (in real time the controller could not
//! pair a request with the truth of the state it answers).

use super::session::{LawSettings, Lpf};
use frictionless_ident::filter::{Butterworth, Sos, sosfilt_step};

/// Daemon tick rate [Hz] (the experiments' `period_us = 1000`).
const FS_HZ: f64 = 1000.0;

/// frictiond's compensation law applied to the true friction (see the module doc).
#[derive(Clone, Debug)]
pub struct OracleCompensation {
    law: LawSettings,
    sos: Vec<Sos>,
    state: Vec<[f64; 2]>,
}

impl OracleCompensation {
    /// The compensation of a joint whose law is `law` (filter state zero, as after an enable).
    pub fn new(law: LawSettings) -> anyhow::Result<Self> {
        let sos = match law.lpf {
            Lpf::Off => vec![],
            Lpf::Butterworth { order, cutoff_hz } => {
                Butterworth::lowpass(order, cutoff_hz, FS_HZ)
                    .map_err(|e| anyhow::anyhow!("oracle τ̂_F low-pass: {e}"))?
                    .sos
            }
        };
        let state = vec![[0.0; 2]; sos.len()];
        Ok(Self { law, sos, state })
    }

    /// The law it mimics.
    pub fn law(&self) -> &LawSettings {
        &self.law
    }

    /// One tick: the term [Nm] to add to τ_des for true friction `tau_f_true_nm` and measured joint
    /// velocity `sdot_rad_s` (the clip gate). Non-finite input gives 0 and clears the filter, as
    /// frictiond does.
    pub fn step(&mut self, tau_f_true_nm: f64, sdot_rad_s: f64) -> f64 {
        if !(tau_f_true_nm.is_finite() && sdot_rad_s.is_finite()) {
            self.state.iter_mut().for_each(|z| *z = [0.0; 2]);
            return 0.0;
        }
        let g = &self.law;
        let f = if sdot_rad_s.abs() > g.joint_velocity_threshold_rad_s {
            tau_f_true_nm.clamp(-g.max_output_friction_nm, g.max_output_friction_nm)
        } else {
            tau_f_true_nm
        };
        let y = if g.kfc > 0.0 { g.kfc * f } else { 0.0 };
        sosfilt_step(&self.sos, y, &mut self.state)
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
        let reference = Butterworth::lowpass(2, 30.0, 1000.0)
            .unwrap()
            .filter(&scaled);
        for (a, b) in ours.iter().zip(&reference) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // a low-pass: the step at k = 200 is not passed through at once
        assert!((ours[201] - ours[200]).abs() < 0.85 * 0.5);
    }
}
