//! The Butterworth low-pass: one design, one per-sample step, the offline helpers.
//!
//! What this module **is**:
//! - [`Butterworth::lowpass`]: the design, numerically equal to
//!   `scipy.signal.butter(N, f_c, fs=f_s, output='sos')` (second-order sections, scipy's order and
//!   layout [`Sos`]). Runs off the RT thread (it uses `tan`/`sin`/`cos`, allocates and may fail).
//! - [`CausalButterworth`]: a designed filter of order ≤ [`MAX_CAUSAL_ORDER`] with its state in fixed
//!   arrays; [`CausalButterworth::step`] is one sample through the sections in transposed direct
//!   form II (DF2T): a handful of multiply-adds, no allocation, no branch on the data. frictiond's
//!   τ̂_F low-pass (through [`crate::law`]) and the tools' per-sample filters run this.
//! - Offline helpers over whole signals, equal to scipy: [`sosfilt`], [`sosfilt_zi`],
//!   [`sosfiltfilt`] (zero-phase, default odd padding, [`default_padlen`]). These return `Vec`s
//!   and are **not** for the RT path.
//!
//! Every path filters a sample with the same DF2T section step, so the causal per-sample filter and
//! [`sosfilt`] give identical results for the same design.
//!
//! Design, as scipy does it: analogue prototype poles `p_m = −exp(iπm/2N)`, pre-warped cut-off
//! `ω = 4·tan(π·W/2)` with `W = 2·f_c/f_s` (bilinear transform at `fs = 2`), poles scaled by ω, the
//! bilinear map `z = (4 + p)/(4 − p)`, N zeros at −1, gain `ω^N / Π(4 − p)`. Sections follow scipy's
//! `zpk2sos` "nearest" pairing for an all-(−1)-zeros low-pass: for odd N the first section holds the
//! real pole (and a pole at the origin) with two zeros at −1 and all of the gain, the conjugate pole
//! pairs follow from farthest to closest to the unit circle, and the last section of an odd design
//! holds one zero at −1 and one at the origin.
//!
//! What it is **not**: no high-pass/band-pass designs, no general IIR toolbox.

/// One second-order section `[b0, b1, b2, a0 = 1, a1, a2]` (scipy's sos row layout).
pub type Sos = [f64; 6];

/// Highest order [`Butterworth::lowpass`] designs.
pub const MAX_ORDER: usize = 32;

/// Highest order of a [`CausalButterworth`] (its sections live in a fixed array).
pub const MAX_CAUSAL_ORDER: usize = 8;

/// Sections of a [`CausalButterworth`].
const MAX_CAUSAL_SECTIONS: usize = MAX_CAUSAL_ORDER.div_ceil(2);

/// Errors of filter design or application.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// Order outside 1..=[`MAX_ORDER`].
    #[error("Butterworth order {0} is invalid: must be in 1..=32")]
    Order(usize),
    /// Order above [`MAX_CAUSAL_ORDER`] for the fixed-size per-sample filter.
    #[error("Butterworth order {0} is too high for the per-sample filter: must be in 1..=8")]
    CausalOrder(usize),
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
    /// Signal too short for the odd padding of [`sosfiltfilt`].
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

/// Just enough complex arithmetic for the design (same operations as `num_complex`, so the
/// coefficients round the same way).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    const fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    fn div(self, o: Self) -> Self {
        let n = o.norm_sqr();
        Self::new(
            (self.re * o.re + self.im * o.im) / n,
            (self.im * o.re - self.re * o.im) / n,
        )
    }
    fn scale(self, k: f64) -> Self {
        Self::new(self.re * k, self.im * k)
    }
    fn norm_sqr(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    fn norm(self) -> f64 {
        self.re.hypot(self.im)
    }
}

/// A Butterworth low-pass design as second-order sections (offline form; see the module doc).
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
    /// Designs an order-`order` low-pass with −3 dB at `cutoff_hz` for sample rate `fs_hz`, like
    /// `scipy.signal.butter(order, cutoff_hz, fs=fs_hz, output='sos')`.
    pub fn lowpass(order: usize, cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        if !(1..=MAX_ORDER).contains(&order) {
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
        let fs2 = Complex::new(4.0, 0.0); // 2·fs with scipy's normalised fs = 2
        let warped = 2.0 * 2.0 * (std::f64::consts::PI * wn / 2.0).tan();
        // Analogue prototype poles, scaled: p_m = −exp(iπm/2N)·ω, m = −N+1, −N+3, …, N−1.
        let poles_a: Vec<Complex> = (0..n)
            .map(|j| {
                let m = -(n as f64) + 1.0 + 2.0 * j as f64;
                let th = std::f64::consts::PI * m / (2.0 * n as f64);
                Complex::new(-th.cos(), -th.sin()).scale(warped)
            })
            .collect();
        let mut denom = Complex::new(1.0, 0.0);
        for p in &poles_a {
            denom = denom.mul(fs2.sub(*p));
        }
        let k = Complex::new(warped.powi(n as i32), 0.0).div(denom).re;
        let poles_z: Vec<Complex> = poles_a
            .iter()
            .map(|p| fs2.add(*p).div(fs2.sub(*p)))
            .collect();
        // Upper-half-plane poles (one per conjugate pair), and the real pole for odd N.
        let mut pairs: Vec<Complex> = poles_z.iter().copied().filter(|p| p.im > 0.0).collect();
        // Farthest from the unit circle first, closest last (scipy's section order).
        pairs.sort_by(|a, b| {
            (1.0 - a.norm())
                .abs()
                .total_cmp(&(1.0 - b.norm()).abs())
                .reverse()
        });
        let mut sos = Vec::with_capacity(n.div_ceil(2));
        if n % 2 == 1 {
            // The real pole: the middle one.
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

    /// Causal filtering of a whole signal from rest (`scipy.signal.sosfilt(sos, x)`). Allocates.
    pub fn filter(&self, x: &[f64]) -> Vec<f64> {
        let mut zi = vec![[0.0; 2]; self.sos.len()];
        sosfilt(&self.sos, x, &mut zi)
    }

    /// Zero-phase filtering (`scipy.signal.sosfiltfilt(sos, x)` with default odd padding). Allocates.
    pub fn filtfilt(&self, x: &[f64]) -> Result<Vec<f64>, FilterError> {
        sosfiltfilt(&self.sos, x)
    }

    /// scipy's default `sosfiltfilt` pad length for this design; signals must be strictly longer.
    pub fn padlen(&self) -> usize {
        default_padlen(&self.sos)
    }
}

/// One sample through one section in transposed direct form II, updating its state `z`. The one
/// section step every filter in this module runs.
#[inline(always)]
fn df2t(s: &Sos, z: &mut [f64; 2], x: f64) -> f64 {
    let [b0, b1, b2, _, a1, a2] = *s;
    let y = b0 * x + z[0];
    z[0] = b1 * x - a1 * y + z[1];
    z[1] = b2 * x - a2 * y;
    y
}

/// Steady-state DF2T state of section `s` for a unit input (`scipy.signal.lfilter_zi`), and the
/// section's DC gain.
#[inline]
fn section_zi(s: &Sos) -> ([f64; 2], f64) {
    let [b0, b1, b2, _, a1, a2] = *s;
    // lfilter_zi: solve (I − companion(a)ᵀ)·zi = b[1:] − a[1:]·b0.
    let (c0, c1) = (b1 - a1 * b0, b2 - a2 * b0);
    let z0 = (c0 + c1) / (1.0 + a1 + a2);
    let z1 = c1 - a2 * z0;
    ([z0, z1], (b0 + b1 + b2) / (1.0 + a1 + a2))
}

/// A Butterworth low-pass of order ≤ [`MAX_CAUSAL_ORDER`] with its state, in fixed-size arrays:
/// `Copy`, no heap, [`step`](Self::step) and [`reset_to`](Self::reset_to) allocation- and panic-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CausalButterworth {
    sos: [Sos; MAX_CAUSAL_SECTIONS],
    z: [[f64; 2]; MAX_CAUSAL_SECTIONS],
    n: usize,
}

impl CausalButterworth {
    /// Designs an order-`order` low-pass ([`Butterworth::lowpass`]) with zero state. Off the RT
    /// thread.
    pub fn design(order: usize, cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        Self::from_design(&Butterworth::lowpass(order, cutoff_hz, fs_hz)?)
    }

    /// The per-sample form of a design, zero state.
    pub fn from_design(d: &Butterworth) -> Result<Self, FilterError> {
        if d.sos.len() > MAX_CAUSAL_SECTIONS {
            return Err(FilterError::CausalOrder(d.order));
        }
        let mut sos = [[0.0; 6]; MAX_CAUSAL_SECTIONS];
        sos[..d.sos.len()].copy_from_slice(&d.sos);
        Ok(Self {
            sos,
            z: [[0.0; 2]; MAX_CAUSAL_SECTIONS],
            n: d.sos.len(),
        })
    }

    /// Filters one sample (equal to [`sosfilt`] of the same design, sample by sample).
    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        let n = self.n.min(MAX_CAUSAL_SECTIONS);
        self.sos[..n]
            .iter()
            .zip(self.z[..n].iter_mut())
            .fold(x, |v, (s, z)| df2t(s, z, v))
    }

    /// Sets the state as if the input had been `x` forever (0 on enable; the held value to avoid
    /// a jump).
    #[inline]
    pub fn reset_to(&mut self, x: f64) {
        let n = self.n.min(MAX_CAUSAL_SECTIONS);
        let mut scale = x;
        for (s, z) in self.sos[..n].iter().zip(self.z[..n].iter_mut()) {
            let (zi, dc) = section_zi(s);
            *z = [zi[0] * scale, zi[1] * scale];
            scale *= dc;
        }
    }
}

/// Applies the sections in transposed direct form II to `x`, starting from and updating the
/// per-section state `zi` (`scipy.signal.sosfilt(sos, x, zi=zi)`; `zi.len()` should equal
/// `sos.len()`: sections without a state entry are skipped). Allocates the output.
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

/// Steady-state initial conditions of each section for a unit step (`scipy.signal.sosfilt_zi`).
/// Allocates.
pub fn sosfilt_zi(sos: &[Sos]) -> Vec<[f64; 2]> {
    let mut scale = 1.0;
    sos.iter()
        .map(|s| {
            let (zi, dc) = section_zi(s);
            let out = [zi[0] * scale, zi[1] * scale];
            scale *= dc;
            out
        })
        .collect()
}

/// scipy's default pad length: `3·(2·n_sections + 1 − min(#b2 == 0, #a2 == 0))`.
pub fn default_padlen(sos: &[Sos]) -> usize {
    let zb = sos.iter().filter(|s| s[2] == 0.0).count();
    let za = sos.iter().filter(|s| s[5] == 0.0).count();
    3 * (2 * sos.len() + 1 - zb.min(za))
}

/// Zero-phase forward–backward filtering with odd extension and [`sosfilt_zi`] initial conditions,
/// equal to `scipy.signal.sosfiltfilt(sos, x)` (default `padtype='odd'`, default `padlen`).
/// Allocates.
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
        assert!(Butterworth::lowpass(33, 10.0, 100.0).is_err());
        assert!(Butterworth::lowpass(2, 50.0, 100.0).is_err());
        assert!(Butterworth::lowpass(2, f64::NAN, 100.0).is_err());
        assert!(Butterworth::lowpass(2, 0.0, 100.0).is_err());
        assert_eq!(
            CausalButterworth::design(9, 10.0, 1000.0),
            Err(FilterError::CausalOrder(9))
        );
        assert!(CausalButterworth::design(8, 10.0, 1000.0).is_ok());
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
    fn rolloff_grows_with_order() {
        // One decade above cut-off: ≈ −20·N dB (bilinear warping makes it slightly steeper).
        let gain_at = |order: usize, f_hz: f64| {
            let mut f = CausalButterworth::design(order, 10.0, 1000.0).unwrap();
            let mut peak: f64 = 0.0;
            for k in 0..20_000 {
                let y = f.step((2.0 * std::f64::consts::PI * f_hz * k as f64 / 1000.0).sin());
                if k > 10_000 {
                    peak = peak.max(y.abs());
                }
            }
            peak
        };
        let (g1, g2, g4) = (gain_at(1, 100.0), gain_at(2, 100.0), gain_at(4, 100.0));
        assert!(g1 < 0.11 && g1 > 0.08, "{g1}");
        assert!(g2 < 0.011, "{g2}");
        assert!(g4 < 2e-4, "{g4}");
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

    #[test]
    fn causal_step_equals_sosfilt_exactly() {
        for order in 1..=8 {
            let d = Butterworth::lowpass(order, 30.0, 1000.0).unwrap();
            let mut c = CausalButterworth::from_design(&d).unwrap();
            let x: Vec<f64> = (0..700)
                .map(|k| (k as f64 * 0.05).sin() + if k > 200 { 1.0 } else { 0.0 })
                .collect();
            let want = d.filter(&x);
            for (xi, w) in x.iter().zip(&want) {
                assert_eq!(c.step(*xi), *w, "order {order}");
            }
        }
    }

    #[test]
    fn reset_to_holds_a_value_without_transient() {
        for order in 1..=8 {
            let mut f = CausalButterworth::design(order, 5.0, 1000.0).unwrap();
            f.reset_to(1.25);
            for _ in 0..100 {
                let y = f.step(1.25);
                assert!((y - 1.25).abs() < 1e-12, "order {order}: {y}");
            }
            f.reset_to(0.0);
            assert_eq!(f.step(0.0), 0.0);
        }
    }

    /// An independent Butterworth design: cookbook biquads per pole pair (Q = 1/(2·sin θ_k)), DC
    /// gain 1 per section, the first-order section last. Different sections and gain split, the
    /// same transfer function: [`CausalButterworth`] must give the same outputs up to rounding.
    fn cookbook_lpf(order: usize, cutoff_hz: f64, fs_hz: f64) -> Vec<Sos> {
        let w0 = 2.0 * std::f64::consts::PI * cutoff_hz / fs_hz;
        let (sw, cw) = w0.sin_cos();
        let mut sos = Vec::new();
        for k in 0..order / 2 {
            let theta = (2 * k + 1) as f64 * std::f64::consts::PI / (2 * order) as f64;
            let q = 1.0 / (2.0 * theta.sin());
            let alpha = sw / (2.0 * q);
            let a0 = 1.0 + alpha;
            sos.push([
                (1.0 - cw) / 2.0 / a0,
                (1.0 - cw) / a0,
                (1.0 - cw) / 2.0 / a0,
                1.0,
                -2.0 * cw / a0,
                (1.0 - alpha) / a0,
            ]);
        }
        if order % 2 == 1 {
            let kk = (std::f64::consts::PI * cutoff_hz / fs_hz).tan();
            sos.push([
                kk / (1.0 + kk),
                kk / (1.0 + kk),
                0.0,
                1.0,
                (kk - 1.0) / (kk + 1.0),
                0.0,
            ]);
        }
        sos
    }

    #[test]
    fn same_outputs_as_an_independent_cookbook_design() {
        let x: Vec<f64> = (0..3000)
            .map(|k| 3.0 * (k as f64 * 0.031).sin() + if k % 500 < 250 { 2.0 } else { -1.5 })
            .collect();
        for (order, fc) in [
            (1, 50.0),
            (2, 30.0),
            (2, 5.0),
            (3, 10.0),
            (4, 100.0),
            (8, 40.0),
        ] {
            let old = cookbook_lpf(order, fc, 1000.0);
            let mut zi = vec![[0.0; 2]; old.len()];
            let want = sosfilt(&old, &x, &mut zi);
            let mut new = CausalButterworth::design(order, fc, 1000.0).unwrap();
            let mut worst: f64 = 0.0;
            for (xi, w) in x.iter().zip(&want) {
                worst = worst.max((new.step(*xi) - w).abs());
            }
            assert!(worst < 1e-10, "order {order} at {fc} Hz: {worst:e}");
        }
    }
}
