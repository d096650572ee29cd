//! The wave generator's friction ripple in the matched `current` label.
//!
//! A harmonic drive's wave generator pushes the flexspline into two lobes, so the meshing friction
//! varies twice per motor revolution: τ_F carries a ripple a·σ·sin 2θ + b·σ·cos 2θ on its Coulomb
//! level (θ the motor angle [motor rad], σ the sign of the motion). At the speeds a protocol reaches
//! its frequency 2·|θ̇|/2π is hundreds of hertz, above the label smoother's band: the matched label
//! ([`crate::matched`]) is the friction through the smoother's response H, so it keeps the slow
//! friction and loses most of the ripple.
//!
//! The ripple's shape is known from the motor encoder, so its two amplitudes can be identified from
//! the log and what H removed, a·(x_s − H·x_s) + b·(x_c − H·x_c) with x_s = σ·sin 2θ and
//! x_c = σ·cos 2θ, added back to every row's label ([`correct`]). The fit ([`fit`]):
//! - reads a second matched label of the same log, with a smoother [`FIT_Q_ACC_FACTOR`] times as
//!   wide ([`fit_settings`]): it passes the ripple the label's smoother misses, and its extra noise
//!   averages out over the rows; the rows are the label's valid ones;
//! - regresses that label on H_fit·x_s and H_fit·x_c within sliding segments: runs of rows sliding
//!   one way faster than [`SLIDING_RAD_S`], without their first and last rows within the fit
//!   smoother's reach (at a start, a stop or a reversal the friction's own step would meet the
//!   regressors' σ step), each with a polynomial in time of degree [`DETREND_DEGREE`] projected out
//!   of the label and of both regressors (the slow friction: Stribeck, viscous, thermal, load);
//! - is kept only when the first and the second half of those rows agree (their amplitudes differ
//!   by less than the whole fit's amplitude); otherwise the label is left as it is and the summary
//!   says so.
//!
//! Where the ripple is slow the smoother passes it (x − H·x ≈ 0) and the correction vanishes; a
//! drive without ripple gets amplitudes of the noise's size. Every chunk is one uniform grid; a
//! chunk without a motor angle gets no correction.
//!
//! What it is not: a model of the ripple for the online models (their inputs hold no motor angle),
//! a correction of the `separate` filters' label (whose terms do not share one response), or a
//! windowed (streaming) step: the fit needs the whole log.

use serde::{Deserialize, Serialize};

use crate::kalman::KalmanConfig;
use crate::matched::{reach_samples, smoothed_current};
use crate::preprocess::{PreprocessConfig, PreprocessError, Ripple};
use frictionless_dataset::Dataset;

/// Width of the smoothed motion sign σ(ṡ) = tanh(ṡ / width) of the regressors [rad/s].
pub const SIGN_WIDTH_RAD_S: f64 = 0.01;

/// The fit's rows slide one way faster than this, every row of their segment [rad/s].
pub const SLIDING_RAD_S: f64 = 0.03;

/// Factor on the label smoother's acceleration process noise for the fit's label.
pub const FIT_Q_ACC_FACTOR: f64 = 100.0;

/// Fewest rows a fit needs.
pub const MIN_FIT_ROWS: usize = 200;

/// What [`fit`] identified and [`correct`] did.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RippleFit {
    /// Amplitude a of σ·sin 2θ [Nm].
    pub sin_nm: f64,
    /// Amplitude b of σ·cos 2θ [Nm].
    pub cos_nm: f64,
    /// Rows of the fit.
    pub rows: usize,
    /// |(a, b)₁ − (a, b)₂| of the fits on the first and the second half of the rows [Nm].
    pub halves_disagree_nm: f64,
    /// Whether the halves agreed and the label was corrected.
    pub applied: bool,
    /// RMS of the correction added to the valid rows' labels [Nm] (0 when not applied).
    pub correction_rms_nm: f64,
}

impl RippleFit {
    /// Amplitude |(a, b)| [Nm].
    pub fn amplitude_nm(&self) -> f64 {
        self.sin_nm.hypot(self.cos_nm)
    }

    /// One line for a summary.
    pub fn describe(&self) -> String {
        if self.applied {
            format!(
                "tau_f_label_nm: + wave-generator ripple (a = {:.4}, b = {:.4} Nm on sigma*sin/cos \
                 2*theta, from {} rows; correction RMS {:.4} Nm)",
                self.sin_nm, self.cos_nm, self.rows, self.correction_rms_nm
            )
        } else {
            format!(
                "tau_f_label_nm: wave-generator ripple not identified (a = {:.4}, b = {:.4} Nm from \
                 {} rows; the halves disagree by {:.4} Nm): label left matched only",
                self.sin_nm, self.cos_nm, self.rows, self.halves_disagree_nm
            )
        }
    }
}

/// The settings of the fit's label: `cfg` with the smoother's acceleration process noise times
/// [`FIT_Q_ACC_FACTOR`] and no ripple step.
pub fn fit_settings(cfg: &PreprocessConfig) -> PreprocessConfig {
    let mut wide = cfg.clone();
    wide.kalman.q[2] *= FIT_Q_ACC_FACTOR;
    wide.ripple = Ripple::Off;
    wide
}

/// Checks that a dataset can take the ripple step (a motor angle somewhere).
fn check(ds: &Dataset) -> Result<(), PreprocessError> {
    if ds.theta_motor_rad.iter().any(|t| t.is_finite()) {
        Ok(())
    } else {
        Err(PreprocessError::Settings(
            "ripple wave-generator: the log has no motor position (theta); the ripple's angle is \
             the motor's"
                .into(),
        ))
    }
}

/// The chunks of a dataset, as `[start, end)` row ranges.
fn chunks(ds: &Dataset) -> Vec<(usize, usize)> {
    let n = ds.len();
    let mut out = Vec::new();
    let mut a = 0;
    while a < n {
        let mut b = a + 1;
        while b < n && ds.chunk[b] == ds.chunk[a] {
            b += 1;
        }
        out.push((a, b));
        a = b;
    }
    out
}

/// x_s and x_c of rows `a..b`, or `None` when a row has no motor angle or ṡ (or an angle whose
/// double is not finite: its sine is not a number).
fn regressors(ds: &Dataset, a: usize, b: usize) -> Option<[Vec<f64>; 2]> {
    if !(a..b).all(|k| (2.0 * ds.theta_motor_rad[k]).is_finite() && ds.sdot_rad_s[k].is_finite()) {
        return None;
    }
    let (mut xs, mut xc) = (Vec::with_capacity(b - a), Vec::with_capacity(b - a));
    for k in a..b {
        let sigma = (ds.sdot_rad_s[k] / SIGN_WIDTH_RAD_S).tanh();
        let (s, c) = (2.0 * ds.theta_motor_rad[k]).sin_cos();
        xs.push(sigma * s);
        xc.push(sigma * c);
    }
    Some([xs, xc])
}

/// Least squares of `y` on two columns (rows `(y, p, q)`); `None` when singular.
fn solve2(rows: &[(f64, f64, f64)]) -> Option<(f64, f64)> {
    let mut ata = nalgebra::Matrix2::<f64>::zeros();
    let mut aty = nalgebra::Vector2::<f64>::zeros();
    for &(y, p, q) in rows {
        let x = nalgebra::Vector2::new(p, q);
        ata += x * x.transpose();
        aty += x * y;
    }
    let beta = ata.cholesky()?.solve(&aty);
    (beta[0].is_finite() && beta[1].is_finite()).then_some((beta[0], beta[1]))
}

/// Identifies the ripple's amplitudes from `wide`, a matched label with [`fit_settings`], on the
/// rows `valid` marks (the label's own valid rows: the wide smoother's noisy s̈ would fail the
/// acceleration limit where the label's does not) (module docs); `None` when fewer than
/// [`MIN_FIT_ROWS`] rows qualify. The result is not yet applied.
pub fn fit(
    wide: &Dataset,
    valid: &[bool],
    wide_kalman: &KalmanConfig,
    fs_hz: f64,
) -> Result<Option<RippleFit>, PreprocessError> {
    check(wide)?;
    if valid.len() != wide.len() {
        return Err(PreprocessError::Settings(format!(
            "ripple wave-generator: {} valid flags for a label of {} rows",
            valid.len(),
            wide.len()
        )));
    }
    let rows = segment_rows(wide, valid, wide_kalman, fs_hz)?;
    if rows.len() < MIN_FIT_ROWS {
        return Ok(None);
    }
    let half = rows.len() / 2;
    let (Some(all), Some(first), Some(second)) =
        (solve2(&rows), solve2(&rows[..half]), solve2(&rows[half..]))
    else {
        return Ok(None);
    };
    let halves_disagree_nm = (first.0 - second.0).hypot(first.1 - second.1);
    Ok(Some(RippleFit {
        sin_nm: all.0,
        cos_nm: all.1,
        rows: rows.len(),
        halves_disagree_nm,
        applied: halves_disagree_nm < all.0.hypot(all.1),
        correction_rms_nm: 0.0,
    }))
}

/// Projects out a polynomial of degree `DETREND_DEGREE` in time from `y` (in place).
fn detrend(y: &mut [f64]) {
    const D: usize = DETREND_DEGREE + 1;
    let n = y.len();
    let basis = |i: usize| -> [f64; D] {
        let t = 2.0 * i as f64 / (n - 1).max(1) as f64 - 1.0;
        let mut b = [1.0; D];
        for d in 1..D {
            b[d] = b[d - 1] * t;
        }
        b
    };
    let mut ata = nalgebra::SMatrix::<f64, D, D>::zeros();
    let mut atb = nalgebra::SVector::<f64, D>::zeros();
    for (i, v) in y.iter().enumerate() {
        let b = nalgebra::SVector::<f64, D>::from(basis(i));
        ata += b * b.transpose();
        atb += b * *v;
    }
    let Some(c) = ata.cholesky().map(|c| c.solve(&atb)) else {
        return;
    };
    for (i, v) in y.iter_mut().enumerate() {
        let b = nalgebra::SVector::<f64, D>::from(basis(i));
        *v -= b.dot(&c);
    }
}

/// Degree of the polynomial in time removed from each sliding segment.
pub const DETREND_DEGREE: usize = 2;

/// Fewest rows of a sliding segment the fit uses (after its edges are dropped).
pub const MIN_SEGMENT_ROWS: usize = 16;

/// The fit's rows: (label, H·x_s, H·x_c) of every sliding segment of `wide` (rows `valid`, active,
/// with a finite label, sliding one way faster than [`SLIDING_RAD_S`]), its first and last rows
/// within the smoother's reach dropped (where the label holds the segment's start or stop) and a
/// polynomial in time projected out of each of the three ([`detrend`]: the slow friction).
fn segment_rows(
    wide: &Dataset,
    valid: &[bool],
    wide_kalman: &KalmanConfig,
    fs_hz: f64,
) -> Result<Vec<(f64, f64, f64)>, PreprocessError> {
    let dt = 1.0 / fs_hz;
    let edge = reach_samples(wide_kalman, dt)?.max(3);
    let mut rows = Vec::new();
    for (a, b) in chunks(wide) {
        let Some(x) = regressors(wide, a, b) else {
            continue;
        };
        let hs = smoothed_current(wide_kalman, dt, &x[0])?;
        let hc = smoothed_current(wide_kalman, dt, &x[1])?;
        let sliding = |k: usize, sign: f64| {
            valid[k]
                && wide.active[k]
                && wide.tau_f_label_nm[k].is_finite()
                && sign * wide.sdot_rad_s[k] > SLIDING_RAD_S
        };
        let mut k = a;
        while k < b {
            let sign = wide.sdot_rad_s[k].signum();
            if !sliding(k, sign) {
                k += 1;
                continue;
            }
            let mut e = k;
            while e < b && sliding(e, sign) {
                e += 1;
            }
            let (s0, s1) = (k + edge, e.saturating_sub(edge));
            if s1 > s0 && s1 - s0 >= MIN_SEGMENT_ROWS {
                let mut l: Vec<f64> = wide.tau_f_label_nm[s0..s1].to_vec();
                let mut ps: Vec<f64> = hs[s0 - a..s1 - a].to_vec();
                let mut pc: Vec<f64> = hc[s0 - a..s1 - a].to_vec();
                detrend(&mut l);
                detrend(&mut ps);
                detrend(&mut pc);
                rows.extend((0..l.len()).map(|i| (l[i], ps[i], pc[i])));
            }
            k = e;
        }
    }
    Ok(rows)
}

/// Adds what the smoother `kalman` removed of the identified ripple to `ds`'s label (when
/// `ripple.applied`), and records the correction's RMS over the valid rows.
pub fn apply(
    ds: &mut Dataset,
    kalman: &KalmanConfig,
    fs_hz: f64,
    ripple: &mut RippleFit,
) -> Result<(), PreprocessError> {
    if !ripple.applied {
        return Ok(());
    }
    check(ds)?;
    let dt = 1.0 / fs_hz;
    let (mut e2, mut m) = (0.0, 0usize);
    for (a, b) in chunks(ds) {
        let Some(x) = regressors(ds, a, b) else {
            continue;
        };
        let hs = smoothed_current(kalman, dt, &x[0])?;
        let hc = smoothed_current(kalman, dt, &x[1])?;
        for k in a..b {
            let i = k - a;
            let c = ripple.sin_nm * (x[0][i] - hs[i]) + ripple.cos_nm * (x[1][i] - hc[i]);
            ds.tau_f_label_nm[k] += c;
            if ds.valid[k] && ds.active[k] {
                e2 += c * c;
                m += 1;
            }
        }
    }
    ripple.correction_rms_nm = (e2 / m.max(1) as f64).sqrt();
    Ok(())
}

/// The ripple step of a label: [`fit`] on `wide` (the same log labelled with [`fit_settings`] of
/// `cfg`), then [`apply`] to `ds` (labelled with `cfg`, matched). `None`: too few rows to fit.
pub fn correct(
    ds: &mut Dataset,
    wide: &Dataset,
    cfg: &PreprocessConfig,
) -> Result<Option<RippleFit>, PreprocessError> {
    if wide.len() != ds.len() {
        return Err(PreprocessError::Settings(format!(
            "ripple wave-generator: the fit's label has {} rows, the label {}",
            wide.len(),
            ds.len()
        )));
    }
    let Some(mut r) = fit(wide, &ds.valid, &fit_settings(cfg).kalman, cfg.fs_hz)? else {
        return Ok(None);
    };
    apply(ds, &cfg.kalman, cfg.fs_hz, &mut r)?;
    Ok(Some(r))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk whose label is a slow friction plus the ripple through the label's smoother H, as a
    /// matched label holds it: the ripple's amplitudes come back from a wide-smoother label of the
    /// same friction, and the corrected label equals the friction with the whole ripple.
    fn synthetic(
        ripple: (f64, f64),
        noise_nm: f64,
    ) -> (Dataset, Dataset, Vec<f64>, PreprocessConfig) {
        let mut cfg = PreprocessConfig::for_joint("j");
        cfg.label_filter = crate::preprocess::LabelFilter::Matched;
        cfg.ripple = Ripple::WaveGenerator;
        let n = 20_000;
        let dt = 1.0 / cfg.fs_hz;
        let mut ds = Dataset::default();
        let mut truth = Vec::with_capacity(n);
        let mut theta = 0.0;
        let mut rng = 12345u64;
        for k in 0..n {
            let t = k as f64 * dt;
            // sweeps ±3 rad/s at 0.2 Hz, r = 100 (motor angle integrates 100·ṡ)
            let v = 3.0 * (2.0 * std::f64::consts::PI * 0.2 * t).sin();
            theta += 100.0 * v * dt;
            let sigma = (v / SIGN_WIDTH_RAD_S).tanh();
            let (s2, c2) = (2.0 * theta).sin_cos();
            truth.push(2.0 * sigma + 0.5 * v + ripple.0 * sigma * s2 + ripple.1 * sigma * c2);
            ds.time_s.push(t);
            ds.chunk.push(0);
            ds.active.push(true);
            ds.valid.push(true);
            ds.sdot_rad_s.push(v);
            ds.theta_motor_rad.push(theta);
            // xorshift noise, uniform ±noise
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            ds.tau_f_true_nm = None;
            ds.tau_f_label_nm
                .push(noise_nm * ((rng % 2001) as f64 / 1000.0 - 1.0));
        }
        let mut wide = ds.clone();
        let h = smoothed_current(&cfg.kalman, dt, &truth).unwrap();
        let hw = smoothed_current(&fit_settings(&cfg).kalman, dt, &truth).unwrap();
        for k in 0..n {
            wide.tau_f_label_nm[k] += hw[k];
            ds.tau_f_label_nm[k] += h[k];
        }
        (ds, wide, truth, cfg)
    }

    /// label − truth RMS on the rows sliding faster than 0.5 rad/s (the smoothed reversals are
    /// the label's other error), past the smoother's first and last second.
    fn rms_error(ds: &Dataset, truth: &[f64]) -> f64 {
        let rows: Vec<usize> = (1000..ds.len() - 1000)
            .filter(|&k| ds.sdot_rad_s[k].abs() > 0.5)
            .collect();
        let e2: f64 = rows
            .iter()
            .map(|&k| (ds.tau_f_label_nm[k] - truth[k]).powi(2))
            .sum();
        (e2 / rows.len() as f64).sqrt()
    }

    #[test]
    fn the_ripple_comes_back_and_the_label_gets_it_whole() {
        let (mut ds, wide, truth, cfg) = synthetic((0.06, -0.04), 0.02);
        let before = rms_error(&ds, &truth);
        let r = correct(&mut ds, &wide, &cfg).unwrap().unwrap();
        let after = rms_error(&ds, &truth);
        eprintln!("{r:?}: label − truth RMS {before:.4} → {after:.4} Nm");
        assert!(r.applied, "{r:?}");
        assert!(
            (r.sin_nm - 0.06).abs() < 0.01 && (r.cos_nm + 0.04).abs() < 0.01,
            "{r:?}"
        );
        assert!(after < 0.5 * before, "label − truth RMS {before} → {after}");
    }

    #[test]
    fn a_drive_without_ripple_keeps_its_label() {
        let (mut ds, wide, truth, cfg) = synthetic((0.0, 0.0), 0.02);
        let before = rms_error(&ds, &truth);
        let r = correct(&mut ds, &wide, &cfg).unwrap().unwrap();
        assert!(r.amplitude_nm() < 0.01, "{r:?}");
        let after = rms_error(&ds, &truth);
        assert!(
            after < before + 0.005,
            "label − truth RMS {before} → {after}"
        );
    }

    #[test]
    fn a_log_without_motor_angle_is_refused() {
        let (mut ds, mut wide, _, cfg) = synthetic((0.06, 0.0), 0.0);
        for t in ds
            .theta_motor_rad
            .iter_mut()
            .chain(&mut wide.theta_motor_rad)
        {
            *t = f64::NAN;
        }
        let e = correct(&mut ds, &wide, &cfg).unwrap_err().to_string();
        assert!(e.contains("motor position"), "{e}");
    }
}
