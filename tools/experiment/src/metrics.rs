//! Metrics of a recorded trial: tracking RMSE, friction-estimate error, disturbance return.
//!
//! What this module **is**: pure functions over a [`JointTrace`]. Positions are the measured
//! (encoder-quantised, 2.4e-5 rad) joint angles, i.e. what a robot log would show.
//!
//! What it is **not**: no I/O, no decisions about pass/fail thresholds beyond [`TrackCriterion`].

use super::run::{JointTrace, Pulse};

/// RMS of `f(i)` over the indices `idx`; NaN terms are skipped; NaN if none is left.
fn rms_over(idx: impl Iterator<Item = usize>, f: impl Fn(usize) -> f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for i in idx {
        let v = f(i);
        if v.is_finite() {
            sum += v * v;
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// Reads a metric written by serde_json, which stores NaN and ±∞ as `null`: `null` reads as NaN.
pub(crate) fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Tracking and friction-estimate metrics of one joint's trace.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct TrackMetrics {
    /// RMSE of s_d − s over the evaluation window [rad].
    #[serde(deserialize_with = "null_as_nan")]
    pub rmse_rad: f64,
    /// Max |s_d − s| over the window [rad].
    #[serde(deserialize_with = "null_as_nan")]
    pub max_abs_err_rad: f64,
    /// RMS of τ_des over the window [Nm].
    #[serde(deserialize_with = "null_as_nan")]
    pub tau_des_rms_nm: f64,
    /// RMSE of the model's own estimate τ̂_F/kfc against the true friction [Nm] (NaN for `none`).
    #[serde(deserialize_with = "null_as_nan")]
    pub friction_est_rmse_nm: f64,
    /// RMS of the friction left uncompensated, τ_F − τ̂_F [Nm] (for `none`: RMS of τ_F).
    #[serde(deserialize_with = "null_as_nan")]
    pub residual_friction_rms_nm: f64,
    /// RMS of the true friction [Nm].
    #[serde(deserialize_with = "null_as_nan")]
    pub friction_true_rms_nm: f64,
    /// Samples in the window.
    pub n: usize,
}

impl TrackMetrics {
    /// [`TrackMetrics::friction_est_rmse_nm`] when there is one (`None` for a joint without a
    /// friction estimate, whose value is not finite).
    pub fn friction_estimate_rmse_nm(&self) -> Option<f64> {
        Some(self.friction_est_rmse_nm).filter(|v| v.is_finite())
    }
}

/// The window `[from_s, to_s)` as indices.
fn window(tr: &JointTrace, from_s: f64, to_s: f64) -> Vec<usize> {
    (0..tr.t_s.len())
        .filter(|&i| tr.t_s[i] >= from_s && tr.t_s[i] < to_s)
        .collect()
}

/// Tracking metrics over `from_s ≤ t < to_s`.
pub fn track(tr: &JointTrace, from_s: f64, to_s: f64) -> TrackMetrics {
    let w = window(tr, from_s, to_s);
    let err = |i: usize| tr.s_des_rad[i] - tr.s_rad[i];
    let max_abs_err_rad = w.iter().map(|&i| err(i).abs()).fold(0.0, f64::max);
    let friction_est_rmse_nm = if tr.kfc > 0.0 {
        rms_over(w.iter().copied(), |i| {
            tr.tau_f_hat_nm[i] / tr.kfc - tr.tau_f_true_nm[i]
        })
    } else {
        f64::NAN
    };
    TrackMetrics {
        rmse_rad: rms_over(w.iter().copied(), err),
        max_abs_err_rad,
        tau_des_rms_nm: rms_over(w.iter().copied(), |i| tr.tau_des_nm[i]),
        friction_est_rmse_nm,
        residual_friction_rms_nm: rms_over(w.iter().copied(), |i| {
            let hat = if tr.kfc > 0.0 {
                tr.tau_f_hat_nm[i]
            } else {
                0.0
            };
            tr.tau_f_true_nm[i] - hat
        }),
        friction_true_rms_nm: rms_over(w.iter().copied(), |i| tr.tau_f_true_nm[i]),
        n: w.len(),
    }
}

/// The pass criterion of the minimum-K_p search: tracking RMSE ≤ `frac_of_amplitude` × amplitude,
/// evaluated after the first `skip_periods` periods.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackCriterion {
    /// Allowed RMSE as a fraction of the sine amplitude.
    pub frac_of_amplitude: f64,
    /// Periods excluded from the evaluation (start-up transient).
    pub skip_periods: f64,
}

impl TrackCriterion {
    /// The RMSE threshold [rad] for a sine of amplitude `amplitude_rad`.
    pub fn threshold_rad(&self, amplitude_rad: f64) -> f64 {
        self.frac_of_amplitude * amplitude_rad
    }
}

/// Disturbance-rejection metrics of one joint.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct DisturbanceMetrics {
    /// RMSE of s − s_hold from the release to the end of the trial [rad] (the paper's metric).
    #[serde(deserialize_with = "null_as_nan")]
    pub rmse_after_release_rad: f64,
    /// Largest |s − s_hold| while the pulse acted or after [rad].
    #[serde(deserialize_with = "null_as_nan")]
    pub max_deflection_rad: f64,
    /// |s − s_hold| at the end of the trial [rad].
    #[serde(deserialize_with = "null_as_nan")]
    pub final_offset_rad: f64,
}

/// Disturbance metrics for a trace holding `s_hold_rad` with `pulse`.
pub fn disturbance(tr: &JointTrace, s_hold_rad: f64, pulse: &Pulse) -> DisturbanceMetrics {
    let after = window(tr, pulse.end_s(), f64::INFINITY);
    let dev = |i: usize| tr.s_rad[i] - s_hold_rad;
    let from_pulse = window(tr, pulse.start_s, f64::INFINITY);
    DisturbanceMetrics {
        rmse_after_release_rad: rms_over(after.iter().copied(), dev),
        max_deflection_rad: from_pulse.iter().map(|&i| dev(i).abs()).fold(0.0, f64::max),
        final_offset_rad: after.last().map_or(f64::NAN, |&i| dev(i).abs()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(n: usize, f: impl Fn(f64) -> (f64, f64)) -> JointTrace {
        let mut tr = JointTrace {
            kfc: 0.5,
            ..JointTrace::default()
        };
        for i in 0..n {
            let t = i as f64 * 1e-3;
            let (sd, s) = f(t);
            tr.t_s.push(t);
            tr.s_des_rad.push(sd);
            tr.s_rad.push(s);
            tr.tau_des_nm.push(2.0);
            tr.tau_f_hat_nm.push(1.0);
            tr.tau_f_true_nm.push(3.0);
        }
        tr
    }

    #[test]
    fn track_metrics_of_a_constant_offset_after_the_skip() {
        // error 0.5 before t = 1 s, 0.1 after
        let tr = trace(3000, |t| (1.0, if t < 1.0 { 0.5 } else { 0.9 }));
        let m = track(&tr, 1.0, f64::INFINITY);
        assert_eq!(m.n, 2000);
        assert!((m.rmse_rad - 0.1).abs() < 1e-12);
        assert!((m.max_abs_err_rad - 0.1).abs() < 1e-12);
        assert!((m.tau_des_rms_nm - 2.0).abs() < 1e-12);
        // τ̂/kfc = 2 vs 3 → 1; residual 3 − 1 = 2
        assert!((m.friction_est_rmse_nm - 1.0).abs() < 1e-12);
        assert!((m.residual_friction_rms_nm - 2.0).abs() < 1e-12);
    }

    #[test]
    fn disturbance_metrics_measure_after_release() {
        let pulse = Pulse {
            start_s: 1.0,
            duration_s: 1.0,
            torque_nm: 5.0,
        };
        // pushed to 0.3 during the pulse, then stays at 0.2
        let tr = trace(4000, |t| {
            let s = if t < 1.0 {
                0.0
            } else if t < 2.0 {
                0.3
            } else {
                0.2
            };
            (0.0, s)
        });
        let m = disturbance(&tr, 0.0, &pulse);
        assert!((m.rmse_after_release_rad - 0.2).abs() < 1e-12);
        assert!((m.max_deflection_rad - 0.3).abs() < 1e-12);
        assert!((m.final_offset_rad - 0.2).abs() < 1e-12);
    }
}
