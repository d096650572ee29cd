//! Butterworth low-pass filter for the friction estimate τ̂_F.
//!
//! What this module **is**: an order-1…8 digital Butterworth low-pass as a cascade of second-order
//! sections (plus one first-order section for odd orders), designed with the bilinear transform and
//! frequency pre-warping. [`Butterworth::design`] runs off the RT thread (it uses `tan`/`sin` and may
//! fail); [`Butterworth::step`] is a handful of multiply-adds on fixed-size state: no allocation.
//!
//! Hand-written rather than a crate: the `biquad` crate offers single 2nd-order sections only, and the
//! per-section Butterworth Q values plus fixed-capacity cascade state are what the RT loop needs.
//!
//! What it is **not**: no high-pass/band-pass, no zero-phase filtering.

/// Maximum number of second-order sections (order 8).
const MAX_SECTIONS: usize = 4;

/// One section in transposed direct form II, coefficients normalised by a0.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Section {
    b0: f64,
    b1: f64,
    b2: f64,
    a1: f64,
    a2: f64,
    z1: f64,
    z2: f64,
}

impl Section {
    #[inline]
    fn step(&mut self, x: f64) -> f64 {
        let y = self.b0 * x + self.z1;
        self.z1 = self.b1 * x - self.a1 * y + self.z2;
        self.z2 = self.b2 * x - self.a2 * y;
        y
    }

    /// Sets the state to the steady state for a constant input `x` (DC gain 1).
    fn settle(&mut self, x: f64) {
        // Steady state y = x: z1 = y − b0·x, z2 = b2·x − a2·y.
        self.z2 = self.b2 * x - self.a2 * x;
        self.z1 = x - self.b0 * x;
    }
}

/// A designed Butterworth low-pass with its state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Butterworth {
    sections: [Section; MAX_SECTIONS + 1],
    n: usize,
}

/// Why a filter cannot be designed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// Order outside 1..=8.
    #[error("Butterworth order {0} is outside 1..=8")]
    Order(usize),
    /// Cut-off not in (0, fs/2).
    #[error("cut-off {cutoff_hz} Hz must be > 0 and below Nyquist ({nyquist_hz} Hz)")]
    Cutoff {
        /// Requested cut-off.
        cutoff_hz: f64,
        /// fs/2.
        nyquist_hz: f64,
    },
}

impl Butterworth {
    /// Designs an order-`order` low-pass with −3 dB at `cutoff_hz` for sample rate `fs_hz`.
    pub fn design(order: usize, cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        if !(1..=2 * MAX_SECTIONS).contains(&order) {
            return Err(FilterError::Order(order));
        }
        let nyquist_hz = 0.5 * fs_hz;
        if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyquist_hz) {
            return Err(FilterError::Cutoff {
                cutoff_hz,
                nyquist_hz,
            });
        }
        let w0 = 2.0 * std::f64::consts::PI * cutoff_hz / fs_hz;
        let (sw, cw) = w0.sin_cos();
        let mut sections = [Section::default(); MAX_SECTIONS + 1];
        let mut n = 0;
        for k in 0..order / 2 {
            // Pole-pair Q of an order-N Butterworth: 1/(2·sin((2k+1)π/(2N))).
            let theta = (2 * k + 1) as f64 * std::f64::consts::PI / (2 * order) as f64;
            let q = 1.0 / (2.0 * theta.sin());
            let alpha = sw / (2.0 * q);
            let a0 = 1.0 + alpha;
            sections[n] = Section {
                b0: (1.0 - cw) / 2.0 / a0,
                b1: (1.0 - cw) / a0,
                b2: (1.0 - cw) / 2.0 / a0,
                a1: -2.0 * cw / a0,
                a2: (1.0 - alpha) / a0,
                z1: 0.0,
                z2: 0.0,
            };
            n += 1;
        }
        if order % 2 == 1 {
            let kk = (std::f64::consts::PI * cutoff_hz / fs_hz).tan();
            sections[n] = Section {
                b0: kk / (1.0 + kk),
                b1: kk / (1.0 + kk),
                b2: 0.0,
                a1: (kk - 1.0) / (kk + 1.0),
                a2: 0.0,
                z1: 0.0,
                z2: 0.0,
            };
            n += 1;
        }
        Ok(Self { sections, n })
    }

    /// Filters one sample.
    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        let mut y = x;
        for s in &mut self.sections[..self.n] {
            y = s.step(y);
        }
        y
    }

    /// Resets the state as if the input had been `x` forever (use 0 on enable, the held value to
    /// avoid a jump).
    pub fn reset_to(&mut self, x: f64) {
        for s in &mut self.sections[..self.n] {
            s.settle(x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steady-state amplitude of a unit sine at `f_hz` through the filter.
    fn gain_at(order: usize, fc: f64, fs: f64, f_hz: f64) -> f64 {
        let mut f = Butterworth::design(order, fc, fs).unwrap();
        let n = (fs * 20.0 / fc.min(f_hz)) as usize;
        let mut peak: f64 = 0.0;
        for k in 0..n {
            let y = f.step((2.0 * std::f64::consts::PI * f_hz * k as f64 / fs).sin());
            if k > n / 2 {
                peak = peak.max(y.abs());
            }
        }
        peak
    }

    #[test]
    fn dc_gain_is_one_for_every_order() {
        for order in 1..=8 {
            let mut f = Butterworth::design(order, 10.0, 1000.0).unwrap();
            let mut y = 0.0;
            for _ in 0..5000 {
                y = f.step(2.5);
            }
            assert!((y - 2.5).abs() < 1e-9, "order {order}: {y}");
        }
    }

    #[test]
    fn minus_3db_at_cutoff_and_rolloff_grows_with_order() {
        for order in 1..=6 {
            let g = gain_at(order, 20.0, 1000.0, 20.0);
            assert!(
                (g - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01,
                "order {order}: {g}"
            );
        }
        // One decade above cut-off: ≈ −20·N dB (bilinear warping makes it slightly steeper).
        let g1 = gain_at(1, 10.0, 1000.0, 100.0);
        let g2 = gain_at(2, 10.0, 1000.0, 100.0);
        let g4 = gain_at(4, 10.0, 1000.0, 100.0);
        assert!(g1 < 0.11 && g1 > 0.08, "{g1}");
        assert!(g2 < 0.011, "{g2}");
        assert!(g4 < 2e-4, "{g4}");
    }

    #[test]
    fn reset_to_holds_a_value_without_transient() {
        let mut f = Butterworth::design(3, 5.0, 1000.0).unwrap();
        f.reset_to(1.25);
        for _ in 0..100 {
            let y = f.step(1.25);
            assert!((y - 1.25).abs() < 1e-12, "{y}");
        }
    }

    #[test]
    fn bad_designs_are_refused() {
        assert_eq!(
            Butterworth::design(0, 10.0, 1000.0),
            Err(FilterError::Order(0))
        );
        assert!(Butterworth::design(9, 10.0, 1000.0).is_err());
        assert!(Butterworth::design(2, 500.0, 1000.0).is_err());
        assert!(Butterworth::design(2, f64::NAN, 1000.0).is_err());
        assert!(Butterworth::design(2, 0.0, 1000.0).is_err());
    }
}
