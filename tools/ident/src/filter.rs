//! Butterworth low-pass filters as second-order sections, applied causally (`sosfilt`) or zero-phase
//! (`sosfiltfilt`), numerically equal to `scipy.signal` (`butter(N, Wn, fs=fs, output='sos')`,
//! `sosfilt`, `sosfilt_zi`, `sosfiltfilt` with the default odd padding).
//!
//! What it is: offline signal processing for the label pipeline (the current is filtered with a
//! 5th-order 100 Hz zero-phase Butterworth at 1 kHz, as the authors do).
//! What it is not: the daemon's real-time LPF (that lives in `frictiond`), nor a general IIR toolbox
//! (only low-pass Butterworth designs are provided).
//!
//! Design, as scipy does it: analogue prototype poles `p_m = −exp(iπm/2N)`, pre-warped cut-off
//! `ω = 4·tan(π·W/2)` with `W = 2·f_c/f_s` (bilinear transform at `fs = 2`), poles scaled by ω, the
//! bilinear map `z = (4 + p)/(4 − p)`, N zeros at −1, gain `ω^N / Π(4 − p)`. Sections follow scipy's
//! `zpk2sos` "nearest" pairing for an all-(−1)-zeros low-pass: for odd N the first section holds the
//! real pole (and a pole at the origin) with two zeros at −1 and all of the gain, the conjugate pole
//! pairs follow from farthest to closest to the unit circle, and the last section of an odd design
//! holds one zero at −1 and one at the origin.

use nalgebra::Complex;

/// Errors of filter design or application.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FilterError {
    /// Order outside 1..=32.
    #[error("Butterworth order {0} is invalid: must be in 1..=32")]
    Order(usize),
    /// Cut-off not strictly between 0 and Nyquist.
    #[error(
        "Butterworth cut-off {cutoff_hz} Hz is invalid for fs = {fs_hz} Hz: must be in (0, fs/2)"
    )]
    Cutoff {
        /// The requested cut-off [Hz].
        cutoff_hz: f64,
        /// The sample rate [Hz].
        fs_hz: f64,
    },
    /// Signal too short for the odd padding of `sosfiltfilt`.
    #[error(
        "signal of {len} samples is too short for sosfiltfilt: needs more than {padlen} (padlen)"
    )]
    TooShort {
        /// Signal length.
        len: usize,
        /// Required pad length (the signal must be longer).
        padlen: usize,
    },
}

/// One biquad section `[b0, b1, b2, a0 = 1, a1, a2]` (scipy's sos row layout).
pub type Sos = [f64; 6];

/// A Butterworth low-pass filter as second-order sections.
#[derive(Clone, Debug, PartialEq)]
pub struct Butterworth {
    /// The sections, scipy's order and layout.
    pub sos: Vec<Sos>,
    /// Order N.
    pub order: usize,
    /// Cut-off [Hz].
    pub cutoff_hz: f64,
    /// Sample rate [Hz].
    pub fs_hz: f64,
}

impl Butterworth {
    /// Designs an order-`order` low-pass with cut-off `cutoff_hz` at sample rate `fs_hz`, like
    /// `scipy.signal.butter(order, cutoff_hz, fs=fs_hz, output='sos')`.
    pub fn lowpass(order: usize, cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        if !(1..=32).contains(&order) {
            return Err(FilterError::Order(order));
        }
        if !(cutoff_hz.is_finite()
            && fs_hz.is_finite()
            && cutoff_hz > 0.0
            && cutoff_hz < fs_hz / 2.0)
        {
            return Err(FilterError::Cutoff { cutoff_hz, fs_hz });
        }
        let n = order;
        let wn = 2.0 * cutoff_hz / fs_hz;
        let fs2 = 4.0; // 2·fs with scipy's normalised fs = 2
        let warped = 2.0 * 2.0 * (std::f64::consts::PI * wn / 2.0).tan();
        // Analogue prototype poles, scaled: p_m = −exp(iπm/2N)·ω, m = −N+1, −N+3, …, N−1.
        let poles_a: Vec<Complex<f64>> = (0..n)
            .map(|j| {
                let m = -(n as f64) + 1.0 + 2.0 * j as f64;
                let th = std::f64::consts::PI * m / (2.0 * n as f64);
                -Complex::new(th.cos(), th.sin()) * warped
            })
            .collect();
        let mut denom = Complex::new(1.0, 0.0);
        for p in &poles_a {
            denom *= Complex::new(fs2, 0.0) - p;
        }
        let k = (Complex::new(warped.powi(n as i32), 0.0) / denom).re;
        let poles_z: Vec<Complex<f64>> = poles_a
            .iter()
            .map(|p| (Complex::new(fs2, 0.0) + p) / (Complex::new(fs2, 0.0) - p))
            .collect();
        // Upper-half-plane poles (one per conjugate pair), and the real pole for odd N.
        let mut pairs: Vec<Complex<f64>> = poles_z.iter().copied().filter(|p| p.im > 0.0).collect();
        // Farthest from the unit circle first, closest last (scipy's section order).
        pairs.sort_by(|a, b| {
            (1.0 - a.norm())
                .abs()
                .total_cmp(&(1.0 - b.norm()).abs())
                .reverse()
        });
        let mut sos = Vec::with_capacity(n.div_ceil(2));
        if n % 2 == 1 {
            // The real pole: exactly −ω/(…) mapped; take the real part of the middle pole.
            let real = poles_z[n / 2].re;
            if n == 1 {
                sos.push([k, k, 0.0, 1.0, -real, 0.0]);
            } else {
                sos.push([k, 2.0 * k, k, 1.0, -real, 0.0]);
            }
            let np = pairs.len();
            for (i, p) in pairs.iter().enumerate() {
                let a = [1.0, -2.0 * p.re, p.norm_sqr()];
                let b = if i + 1 == np {
                    [1.0, 1.0, 0.0]
                } else {
                    [1.0, 2.0, 1.0]
                };
                sos.push([b[0], b[1], b[2], a[0], a[1], a[2]]);
            }
        } else {
            for (i, p) in pairs.iter().enumerate() {
                let g = if i == 0 { k } else { 1.0 };
                sos.push([g, 2.0 * g, g, 1.0, -2.0 * p.re, p.norm_sqr()]);
            }
        }
        Ok(Self {
            sos,
            order,
            cutoff_hz,
            fs_hz,
        })
    }

    /// Causal filtering from rest (`scipy.signal.sosfilt(sos, x)`).
    pub fn filter(&self, x: &[f64]) -> Vec<f64> {
        let mut zi = vec![[0.0; 2]; self.sos.len()];
        sosfilt(&self.sos, x, &mut zi)
    }

    /// Zero-phase filtering (`scipy.signal.sosfiltfilt(sos, x)` with default odd padding).
    pub fn filtfilt(&self, x: &[f64]) -> Result<Vec<f64>, FilterError> {
        sosfiltfilt(&self.sos, x)
    }

    /// scipy's default `sosfiltfilt` pad length for this design; signals must be strictly longer.
    pub fn padlen(&self) -> usize {
        default_padlen(&self.sos)
    }
}

/// One sample through one section in direct form II transposed, updating its state `z`.
#[inline]
fn df2t(s: &Sos, z: &mut [f64; 2], x: f64) -> f64 {
    let [b0, b1, b2, _, a1, a2] = *s;
    let y = b0 * x + z[0];
    z[0] = b1 * x - a1 * y + z[1];
    z[1] = b2 * x - a2 * y;
    y
}

/// Applies the sections in direct form II transposed to `x`, starting from and updating the per-section
/// state `zi` (`zi.len()` must equal `sos.len()`; extra/missing sections are treated as zero state).
pub fn sosfilt(sos: &[Sos], x: &[f64], zi: &mut [[f64; 2]]) -> Vec<f64> {
    let mut y = x.to_vec();
    for (s, z) in sos.iter().zip(zi.iter_mut()) {
        // The state in a local for the inner loop (kept in registers), written back once.
        let mut zl = *z;
        for v in y.iter_mut() {
            *v = df2t(s, &mut zl, *v);
        }
        *z = zl;
    }
    y
}

/// One sample through all sections (the streaming form of [`sosfilt`]), updating `zi`.
pub fn sosfilt_step(sos: &[Sos], x: f64, zi: &mut [[f64; 2]]) -> f64 {
    sos.iter()
        .zip(zi.iter_mut())
        .fold(x, |v, (s, z)| df2t(s, z, v))
}

/// Steady-state initial conditions of each section for a unit step (`scipy.signal.sosfilt_zi`).
pub fn sosfilt_zi(sos: &[Sos]) -> Vec<[f64; 2]> {
    let mut scale = 1.0;
    sos.iter()
        .map(|s| {
            let [b0, b1, b2, _, a1, a2] = *s;
            // lfilter_zi: solve (I − companion(a)ᵀ)·zi = b[1:] − a[1:]·b0.
            let (c0, c1) = (b1 - a1 * b0, b2 - a2 * b0);
            let z0 = (c0 + c1) / (1.0 + a1 + a2);
            let z1 = c1 - a2 * z0;
            let zi = [z0 * scale, z1 * scale];
            scale *= (b0 + b1 + b2) / (1.0 + a1 + a2);
            zi
        })
        .collect()
}

/// scipy's default pad length: `3·(2·n_sections + 1 − min(#b2 == 0, #a2 == 0))`.
pub fn default_padlen(sos: &[Sos]) -> usize {
    let zb = sos.iter().filter(|s| s[2] == 0.0).count();
    let za = sos.iter().filter(|s| s[5] == 0.0).count();
    3 * (2 * sos.len() + 1 - zb.min(za))
}

/// Zero-phase forward–backward filtering with odd extension and `sosfilt_zi` initial conditions,
/// equal to `scipy.signal.sosfiltfilt(sos, x)` (default `padtype='odd'`, default `padlen`).
pub fn sosfiltfilt(sos: &[Sos], x: &[f64]) -> Result<Vec<f64>, FilterError> {
    let edge = default_padlen(sos);
    let n = x.len();
    if n <= edge {
        return Err(FilterError::TooShort {
            len: n,
            padlen: edge,
        });
    }
    // Odd extension: 2·x[0] − x[edge..1], x, 2·x[n−1] − x[n−2..n−2−edge].
    let mut ext = Vec::with_capacity(n + 2 * edge);
    ext.extend((1..=edge).rev().map(|i| 2.0 * x[0] - x[i]));
    ext.extend_from_slice(x);
    ext.extend((1..=edge).map(|i| 2.0 * x[n - 1] - x[n - 1 - i]));
    let zi = sosfilt_zi(sos);
    let x0 = ext[0];
    let mut z: Vec<[f64; 2]> = zi.iter().map(|z| [z[0] * x0, z[1] * x0]).collect();
    let mut y = sosfilt(sos, &ext, &mut z);
    y.reverse();
    let y0 = y[0];
    let mut z: Vec<[f64; 2]> = zi.iter().map(|z| [z[0] * y0, z[1] * y0]).collect();
    let mut y = sosfilt(sos, &y, &mut z);
    y.reverse();
    Ok(y[edge..edge + n].to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_design() {
        assert_eq!(
            Butterworth::lowpass(0, 10.0, 100.0),
            Err(FilterError::Order(0))
        );
        assert!(Butterworth::lowpass(2, 50.0, 100.0).is_err());
        assert!(Butterworth::lowpass(2, f64::NAN, 100.0).is_err());
    }

    #[test]
    fn unit_dc_gain_and_steady_state() {
        for n in 1..=8 {
            let f = Butterworth::lowpass(n, 37.0, 1000.0).unwrap();
            let x = vec![2.5; 400];
            let y = f.filtfilt(&x).unwrap();
            assert!(y.iter().all(|v| (v - 2.5).abs() < 1e-9), "order {n}");
            // Causal from rest converges to the DC value.
            let yc = f.filter(&vec![1.0; 2000]);
            assert!((yc[1999] - 1.0).abs() < 1e-9, "order {n}");
        }
    }

    #[test]
    fn attenuation_at_cutoff_is_3db() {
        // |H(f_c)| = 1/√2 for any Butterworth: measure with a long causal sine run.
        let (fs, fc) = (1000.0, 50.0);
        let f = Butterworth::lowpass(5, fc, fs).unwrap();
        let x: Vec<f64> = (0..20000)
            .map(|k| (2.0 * std::f64::consts::PI * fc * k as f64 / fs).sin())
            .collect();
        let y = f.filter(&x);
        // Amplitude by projection on sin/cos over whole periods (20 samples each).
        let w = 2.0 * std::f64::consts::PI * fc / fs;
        let (mut ps, mut pc) = (0.0, 0.0);
        for (k, v) in y.iter().enumerate().skip(10000) {
            ps += v * (w * k as f64).sin();
            pc += v * (w * k as f64).cos();
        }
        let amp = 2.0 * (ps * ps + pc * pc).sqrt() / 10000.0;
        assert!(
            (amp - std::f64::consts::FRAC_1_SQRT_2).abs() < 2e-3,
            "{amp}"
        );
    }

    #[test]
    fn too_short_is_an_error() {
        let f = Butterworth::lowpass(5, 100.0, 1000.0).unwrap();
        assert_eq!(f.padlen(), 18);
        assert_eq!(
            f.filtfilt(&[0.0; 18]),
            Err(FilterError::TooShort {
                len: 18,
                padlen: 18
            })
        );
        assert!(f.filtfilt(&[0.0; 19]).is_ok());
    }
}
