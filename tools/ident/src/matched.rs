//! The matched `current` label: the current through the same smoother as the positions.
//!
//! The label τ_F = r·k_t·i − J·φ̈ − τ_ID(q, q̇, q̈) subtracts terms that change together: when the
//! current steps, the accelerations step with it and the friction between them does not. The
//! authors' pipeline filters each term its own way (the current through the zero-phase
//! Butterworth, q̈ and φ̈ from the Kalman smoother); where the two responses differ, a step of the
//! current leaves a spike and a ringing in the label that the friction never had, and the spike
//! grows with the inertia the step accelerates.
//!
//! The matched label ([`crate::preprocess::LabelFilter::Matched`]) gives the current the
//! smoother's own response: the smoother is linear, and its acceleration estimate of a sequence
//! whose second difference is the current ([`smoothed_current`]) is the current through exactly
//! the filter that turns the positions' second differences into q̈ and φ̈. Every term of the label
//! then sees one filter (up to M(q) varying within the smoother's window), and the label is the
//! friction through that filter plus the sensors' noise through it. A sample whose smoother window
//! holds a sample the limits reject mixes that sample's dynamics into its label, so such rows are
//! rejected too ([`reach_samples`], [`within_reach`]).
//!
//! What it is not: a filter for the models' input columns (those stay the smoother's ṡ, s̈).

use crate::kalman::{self, KalmanConfig, KalmanError};

/// The current through the smoother's acceleration response: the smoothed acceleration of the
/// sequence c with c[0] = c[1] = 0 and c[k+1] − 2·c[k] + c[k−1] = dt²·i[k] [same unit as `i`].
/// The smoother's acceleration output ignores the integration constants (a line) once it has
/// settled, so the result does not depend on where the sequence starts.
pub fn smoothed_current(
    cfg: &KalmanConfig,
    dt_s: f64,
    current: &[f64],
) -> Result<Vec<f64>, KalmanError> {
    let n = current.len();
    let mut c = vec![0.0; n];
    let dt2 = dt_s * dt_s;
    for k in 1..n.saturating_sub(1) {
        c[k + 1] = 2.0 * c[k] - c[k - 1] + dt2 * current[k];
    }
    // The last sample has no second difference of its own: it repeats the one before, as the
    // smoother's last acceleration does.
    Ok(kalman::smooth(cfg, dt_s, &c)?.acc_rad_s2)
}

/// Half-width of the smoother's acceleration response [samples]: the smallest w such that the
/// samples within w of an acceleration impulse hold 90 % of the response's absolute weight.
pub fn reach_samples(cfg: &KalmanConfig, dt_s: f64) -> Result<usize, KalmanError> {
    let (lead, trail) = kalman::settle_samples(cfg, dt_s, 1e-6)?;
    let half = lead.max(trail).clamp(16, 200_000);
    let n = 2 * half + 1;
    let mut impulse = vec![0.0; n];
    impulse[half] = 1.0;
    let h = smoothed_current(cfg, dt_s, &impulse)?;
    let total: f64 = h.iter().map(|v| v.abs()).sum();
    let mut inside = h[half].abs();
    let mut w = 0;
    while inside < 0.9 * total && w < half {
        w += 1;
        inside += h[half - w].abs() + h[half + w].abs();
    }
    Ok(w)
}

/// `ok[k]` and every sample within `reach` of it: a row whose smoother window holds a rejected
/// sample is rejected too.
pub fn within_reach(ok: &[bool], reach: usize) -> Vec<bool> {
    let n = ok.len();
    // prefix[k]: rejected samples before k
    let mut prefix = vec![0usize; n + 1];
    for k in 0..n {
        prefix[k + 1] = prefix[k] + usize::from(!ok[k]);
    }
    (0..n)
        .map(|k| {
            let lo = k.saturating_sub(reach);
            let hi = (k + reach + 1).min(n);
            prefix[hi] == prefix[lo]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn positions_of(acc: &[f64], dt: f64) -> Vec<f64> {
        let mut x = vec![0.0; acc.len()];
        for k in 1..acc.len() - 1 {
            x[k + 1] = 2.0 * x[k] - x[k - 1] + dt * dt * acc[k];
        }
        x
    }

    #[test]
    fn the_current_gets_the_accelerations_response_and_a_line_does_not_matter() {
        let dt = 1e-3;
        let cfg = KalmanConfig::knee();
        // A current with a step and a sine; positions whose second difference is the same signal
        // (plus a line, which a position has and the current's sequence does not).
        let i: Vec<f64> = (0..3000)
            .map(|k| {
                let t = k as f64 * dt;
                (if k >= 1500 { 1.0 } else { -0.5 })
                    + 0.3 * (2.0 * std::f64::consts::PI * 3.0 * t).sin()
            })
            .collect();
        let x: Vec<f64> = positions_of(&i, dt)
            .iter()
            .enumerate()
            .map(|(k, v)| v + 0.7 + 0.2 * k as f64 * dt)
            .collect();
        let acc = kalman::smooth(&cfg, dt, &x).unwrap().acc_rad_s2;
        let ic = smoothed_current(&cfg, dt, &i).unwrap();
        let (lead, trail) = kalman::settle_samples(&cfg, dt, 1e-9).unwrap();
        let mut worst = 0.0f64;
        for k in lead.min(1000)..3000 - trail.min(1000) {
            worst = worst.max((acc[k] - ic[k]).abs());
        }
        assert!(
            worst < 1e-5,
            "the current and the acceleration differ by {worst}"
        );
        // The response is a low-pass: the step is spread out, not passed through.
        assert!((ic[1499] - i[1499]).abs() > 0.1 && (ic[1500] - i[1500]).abs() > 0.1);
        assert!(
            (ic[2500] - i[2500]).abs() < 0.05,
            "settled away from the step"
        );
    }

    #[test]
    fn reach_grows_as_the_smoother_slows() {
        let dt = 1e-3;
        let fast = KalmanConfig {
            q: [1e-5, 1e-4, 1e6],
            ..KalmanConfig::knee()
        };
        let (w_knee, w_fast) = (
            reach_samples(&KalmanConfig::knee(), dt).unwrap(),
            reach_samples(&fast, dt).unwrap(),
        );
        assert!(w_fast >= 1 && w_fast < w_knee, "{w_fast} against {w_knee}");
        assert!(w_knee < 200, "{w_knee}");
    }

    #[test]
    fn within_reach_rejects_the_neighbours_of_a_rejected_row() {
        let ok = [true, true, true, false, true, true, true, true];
        assert_eq!(
            within_reach(&ok, 2),
            [true, false, false, false, false, false, true, true]
        );
        assert_eq!(within_reach(&ok, 0), ok);
        assert!(within_reach(&[], 3).is_empty());
    }
}
