//! Constant-acceleration Kalman filter and Rauch–Tung–Striebel smoother on a position signal.
//!
//! What it is: the velocity/acceleration estimator of the label pipeline. State `[pos, vel, acc]`,
//! `A = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]`, `H = [1, 0, 0]`, diagonal `P₀`, `Q` (per step) and
//! scalar `R`; [`KalmanConfig::knee`] holds the authors' knee values (P₀ = Q = diag(1e-5, 1e-4, 1e4),
//! R = 1e-4). [`filter`] is the causal forward pass (what a robot could run online); [`smooth`] adds
//! the RTS backward pass (non-causal, like the authors' unscented Kalman smoother — for a linear
//! model the UKS reduces to this).
//! What it is not: a general state estimator (no variable dt, no outlier rejection).

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Kalman configuration for one joint (diagonals; units rad, rad/s, rad/s²).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KalmanConfig {
    /// Initial covariance diagonal `[rad², (rad/s)², (rad/s²)²]`.
    pub p0: [f64; 3],
    /// Process-noise covariance diagonal per step, same units.
    pub q: [f64; 3],
    /// Measurement-noise variance [rad²].
    pub r: f64,
}

impl KalmanConfig {
    /// The authors' knee configuration: P₀ = Q = diag(1e-5, 1e-4, 1e4), R = 1e-4.
    pub const fn knee() -> Self {
        Self {
            p0: [1e-5, 1e-4, 1e4],
            q: [1e-5, 1e-4, 1e4],
            r: 1e-4,
        }
    }

    /// Checks that every entry is finite and > 0 (the error names the entry and value).
    pub fn validate(&self) -> Result<(), KalmanError> {
        let entries = [
            ("p0[0]", self.p0[0]),
            ("p0[1]", self.p0[1]),
            ("p0[2]", self.p0[2]),
            ("q[0]", self.q[0]),
            ("q[1]", self.q[1]),
            ("q[2]", self.q[2]),
            ("r", self.r),
        ];
        for (name, v) in entries {
            if !(v.is_finite() && v > 0.0) {
                return Err(KalmanError::Config { name, value: v });
            }
        }
        Ok(())
    }
}

impl Default for KalmanConfig {
    fn default() -> Self {
        Self::knee()
    }
}

/// Kalman errors.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum KalmanError {
    /// A configuration entry is not finite and positive.
    #[error("Kalman config `{name}` = {value} is invalid: must be finite and > 0")]
    Config {
        /// Entry name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// The sample period is not finite and positive.
    #[error("Kalman sample period dt = {0} s is invalid: must be finite and > 0")]
    Dt(f64),
    /// A measurement is not finite.
    #[error("position sample {index} = {value} is not finite")]
    NonFinite {
        /// Sample index.
        index: usize,
        /// Value.
        value: f64,
    },
}

/// Estimated trajectories, one entry per input sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Estimates {
    /// Position [rad].
    pub pos_rad: Vec<f64>,
    /// Velocity [rad/s].
    pub vel_rad_s: Vec<f64>,
    /// Acceleration [rad/s²].
    pub acc_rad_s2: Vec<f64>,
}

impl Estimates {
    fn from_states(x: &[Vector3<f64>]) -> Self {
        Self {
            pos_rad: x.iter().map(|v| v[0]).collect(),
            vel_rad_s: x.iter().map(|v| v[1]).collect(),
            acc_rad_s2: x.iter().map(|v| v[2]).collect(),
        }
    }
}

struct Forward {
    /// Filtered (posterior) states.
    xf: Vec<Vector3<f64>>,
    /// Predicted (prior) states; `xp[k]` is the prediction of step k from k−1 (unused at k = 0).
    xp: Vec<Vector3<f64>>,
    /// RTS gains `C_k = P_f[k]·Aᵀ·P_p[k+1]⁻¹` (empty unless requested).
    gains: Vec<Matrix3<f64>>,
}

fn check(cfg: &KalmanConfig, dt_s: f64, y: &[f64]) -> Result<(), KalmanError> {
    cfg.validate()?;
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(KalmanError::Dt(dt_s));
    }
    if let Some((index, &value)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(KalmanError::NonFinite { index, value });
    }
    Ok(())
}

fn forward(cfg: &KalmanConfig, dt_s: f64, y: &[f64], keep_gains: bool) -> Forward {
    let n = y.len();
    let a = Matrix3::new(1.0, dt_s, 0.5 * dt_s * dt_s, 0.0, 1.0, dt_s, 0.0, 0.0, 1.0);
    let q = Matrix3::from_diagonal(&Vector3::from(cfg.q));
    let mut p = Matrix3::from_diagonal(&Vector3::from(cfg.p0));
    let mut x = Vector3::new(y.first().copied().unwrap_or(0.0), 0.0, 0.0);
    let mut out = Forward {
        xf: Vec::with_capacity(n),
        xp: Vec::with_capacity(n),
        gains: Vec::with_capacity(if keep_gains { n.saturating_sub(1) } else { 0 }),
    };
    let mut pf_prev = p;
    for (k, &yk) in y.iter().enumerate() {
        if k > 0 {
            x = a * x;
            p = a * p * a.transpose() + q;
            p = 0.5 * (p + p.transpose());
            if keep_gains {
                // P_p is symmetric positive definite (Q > 0), so the inverse exists.
                let pinv = p.try_inverse().unwrap_or_else(Matrix3::zeros);
                out.gains.push(pf_prev * a.transpose() * pinv);
            }
        }
        out.xp.push(x);
        // Update with H = [1, 0, 0]: S = P₀₀ + R, K = P[:,0] / S.
        let s = p[(0, 0)] + cfg.r;
        let kg = p.column(0) / s;
        let innov = yk - x[0];
        x += kg * innov;
        // Joseph form (I − KH)·P·(I − KH)ᵀ + K·R·Kᵀ keeps P symmetric positive definite.
        let mut ikh = Matrix3::identity();
        ikh.set_column(0, &(Vector3::new(1.0, 0.0, 0.0) - kg));
        p = ikh * p * ikh.transpose() + kg * kg.transpose() * cfg.r;
        pf_prev = p;
        out.xf.push(x);
    }
    out
}

/// Causal forward Kalman filter of position samples `y_rad` taken every `dt_s` seconds.
/// The state starts at `[y₀, 0, 0]` with covariance `P₀`.
pub fn filter(cfg: &KalmanConfig, dt_s: f64, y_rad: &[f64]) -> Result<Estimates, KalmanError> {
    check(cfg, dt_s, y_rad)?;
    Ok(Estimates::from_states(&forward(cfg, dt_s, y_rad, false).xf))
}

/// Forward Kalman filter plus Rauch–Tung–Striebel backward pass (non-causal, zero lag).
pub fn smooth(cfg: &KalmanConfig, dt_s: f64, y_rad: &[f64]) -> Result<Estimates, KalmanError> {
    check(cfg, dt_s, y_rad)?;
    let f = forward(cfg, dt_s, y_rad, true);
    let mut xs = f.xf.clone();
    for k in (0..xs.len().saturating_sub(1)).rev() {
        let next = xs[k + 1];
        xs[k] = f.xf[k] + f.gains[k] * (next - f.xp[k + 1]);
    }
    Ok(Estimates::from_states(&xs))
}

/// Smallest `m` with ‖Mᵐ‖∞ ≤ `tol` (at most `cap`; `None` if it does not decay that far).
pub(crate) fn decay_len(m: &Matrix3<f64>, tol: f64, cap: usize) -> Option<usize> {
    let norm = |x: &Matrix3<f64>| {
        (0..3)
            .map(|i| (0..3).map(|j| x[(i, j)].abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    let mut p = Matrix3::identity();
    for k in 0..=cap {
        if norm(&p) <= tol {
            return Some(k);
        }
        p *= m;
    }
    None
}

/// How many samples the smoother needs to forget where its input starts and ends, to within `tol`
/// (relative): `(lead, trail)`. Derived from the settings alone: `lead` is the number of steps after
/// which the covariance from `P₀` equals the steady one to `tol`, plus the steps after which the
/// steady closed-loop filter `(I − K·H)·A` has forgotten its initial state; `trail` the steps after
/// which the steady RTS gain `C = P·Aᵀ·P⁻` has forgotten the end. Labelling a long signal in
/// windows that overlap by these margins gives the whole signal's estimates (streaming import).
pub fn settle_samples(
    cfg: &KalmanConfig,
    dt_s: f64,
    tol: f64,
) -> Result<(usize, usize), KalmanError> {
    check(cfg, dt_s, &[])?;
    const CAP: usize = 10_000_000;
    let a = Matrix3::new(1.0, dt_s, 0.5 * dt_s * dt_s, 0.0, 1.0, dt_s, 0.0, 0.0, 1.0);
    let q = Matrix3::from_diagonal(&Vector3::from(cfg.q));
    let update = |pp: &Matrix3<f64>| {
        let kg = pp.column(0) / (pp[(0, 0)] + cfg.r);
        let mut ikh = Matrix3::identity();
        ikh.set_column(0, &(Vector3::new(1.0, 0.0, 0.0) - kg));
        (
            ikh * pp * ikh.transpose() + kg * kg.transpose() * cfg.r,
            ikh,
        )
    };
    let predict = |p: &Matrix3<f64>| {
        let pp = a * p * a.transpose() + q;
        0.5 * (pp + pp.transpose())
    };
    let rel = |x: &Matrix3<f64>, y: &Matrix3<f64>| (x - y).abs().max() / y.abs().max();
    // The steady covariance: the Riccati recursion from P₀ until it stops changing.
    let p0 = Matrix3::from_diagonal(&Vector3::from(cfg.p0));
    let mut p = update(&p0).0;
    let mut steps = 0;
    loop {
        let next = update(&predict(&p)).0;
        steps += 1;
        if rel(&next, &p) <= f64::EPSILON || steps > CAP {
            p = next;
            break;
        }
        p = next;
    }
    let p_ss = p;
    let mut p = update(&p0).0;
    let mut m_p = 0;
    while rel(&p, &p_ss) > tol && m_p < steps {
        p = update(&predict(&p)).0;
        m_p += 1;
    }
    let pp_ss = predict(&p_ss);
    let (_, ikh) = update(&pp_ss);
    let closed = ikh * a;
    let gain = p_ss * a.transpose() * pp_ss.try_inverse().unwrap_or_else(Matrix3::zeros);
    let fail = || KalmanError::Config {
        name: "q",
        value: cfg.q[0],
    };
    let m_x = decay_len(&closed, tol, CAP).ok_or_else(fail)?;
    let m_c = decay_len(&gain, tol, CAP).ok_or_else(fail)?;
    Ok((m_p + m_x, m_c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Quantised sine position (18-bit encoder), with its exact derivatives.
    fn sine(n: usize, dt: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (amp, f) = (0.5, 0.5);
        let w = 2.0 * PI * f;
        let q = 2.0 * PI / f64::from(1u32 << 18);
        let t = (0..n).map(|k| k as f64 * dt);
        let y = t
            .clone()
            .map(|t| ((amp * (w * t).sin()) / q).round() * q)
            .collect();
        let v = t.clone().map(|t| amp * w * (w * t).cos()).collect();
        let a = t.map(|t| -amp * w * w * (w * t).sin()).collect();
        (y, v, a)
    }

    fn rms_err(a: &[f64], b: &[f64], skip: usize) -> f64 {
        let n = a.len() - 2 * skip;
        let s: f64 = a[skip..a.len() - skip]
            .iter()
            .zip(&b[skip..b.len() - skip])
            .map(|(x, y)| (x - y).powi(2))
            .sum();
        (s / n as f64).sqrt()
    }

    #[test]
    fn settle_margins_make_a_window_equal_the_whole_signal() {
        let dt = 1e-3;
        let (y, _, _) = sine(6000, dt);
        let cfg = KalmanConfig::knee();
        let (lead, trail) = settle_samples(&cfg, dt, 1e-13).unwrap();
        assert!(
            lead > 0 && trail > 0 && lead < 2000 && trail < 2000,
            "{lead} {trail}"
        );
        let whole = smooth(&cfg, dt, &y).unwrap();
        let (a, b) = (2500, 3500);
        let part = smooth(&cfg, dt, &y[a - lead..b + trail]).unwrap();
        for k in a..b {
            let (w, p) = (whole.acc_rad_s2[k], part.acc_rad_s2[k - a + lead]);
            assert!((w - p).abs() < 1e-9, "sample {k}: {w} vs {p}");
        }
        // Half the margins do not give the same estimates.
        let part = smooth(&cfg, dt, &y[a - lead / 4..b + trail / 4]).unwrap();
        let worst = (a..b)
            .map(|k| (whole.acc_rad_s2[k] - part.acc_rad_s2[k - a + lead / 4]).abs())
            .fold(0.0, f64::max);
        assert!(worst > 1e-9, "{worst}");
    }

    #[test]
    fn sine_velocity_and_acceleration_are_recovered() {
        let dt = 1e-3;
        let (y, v, a) = sine(8000, dt);
        let cfg = KalmanConfig::knee();
        let f = filter(&cfg, dt, &y).unwrap();
        let s = smooth(&cfg, dt, &y).unwrap();
        let (ef_v, es_v) = (
            rms_err(&f.vel_rad_s, &v, 500),
            rms_err(&s.vel_rad_s, &v, 500),
        );
        let (ef_a, es_a) = (
            rms_err(&f.acc_rad_s2, &a, 500),
            rms_err(&s.acc_rad_s2, &a, 500),
        );
        // Peak velocity 1.57 rad/s, peak acceleration 4.9 rad/s².
        assert!(es_v < 0.01, "smoothed velocity RMS error {es_v}");
        assert!(es_a < 0.3, "smoothed acceleration RMS error {es_a}");
        assert!(ef_v < 0.05, "filtered velocity RMS error {ef_v}");
        assert!(ef_a < 2.0, "filtered acceleration RMS error {ef_a}");
        assert!(es_v < ef_v, "smoother {es_v} not better than filter {ef_v}");
        assert!(es_a < ef_a, "smoother {es_a} not better than filter {ef_a}");
    }

    #[test]
    fn filter_is_causal() {
        let dt = 1e-3;
        let (y, _, _) = sine(1000, dt);
        let mut y2 = y.clone();
        for v in &mut y2[600..] {
            *v += 0.1;
        }
        let a = filter(&KalmanConfig::knee(), dt, &y).unwrap();
        let b = filter(&KalmanConfig::knee(), dt, &y2).unwrap();
        assert_eq!(a.vel_rad_s[..600], b.vel_rad_s[..600]);
        assert_ne!(a.vel_rad_s[600], b.vel_rad_s[600]);
        let c = smooth(&KalmanConfig::knee(), dt, &y2).unwrap();
        let d = smooth(&KalmanConfig::knee(), dt, &y).unwrap();
        assert_ne!(c.vel_rad_s[590], d.vel_rad_s[590]);
    }

    #[test]
    fn constant_velocity_ramp_is_exact_in_steady_state() {
        let dt = 2e-3;
        let y: Vec<f64> = (0..3000).map(|k| 0.3 * k as f64 * dt).collect();
        let s = smooth(&KalmanConfig::knee(), dt, &y).unwrap();
        for k in 500..2500 {
            assert!(
                (s.vel_rad_s[k] - 0.3).abs() < 1e-6,
                "{k}: {}",
                s.vel_rad_s[k]
            );
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut c = KalmanConfig::knee();
        c.q[2] = 0.0;
        assert!(matches!(
            filter(&c, 1e-3, &[0.0]),
            Err(KalmanError::Config { name: "q[2]", .. })
        ));
        assert_eq!(
            smooth(&KalmanConfig::knee(), 0.0, &[0.0]),
            Err(KalmanError::Dt(0.0))
        );
        assert!(matches!(
            smooth(&KalmanConfig::knee(), 1e-3, &[0.0, f64::NAN]),
            Err(KalmanError::NonFinite { index: 1, .. })
        ));
        assert_eq!(
            smooth(&KalmanConfig::knee(), 1e-3, &[]).unwrap(),
            Estimates::default()
        );
    }
}
