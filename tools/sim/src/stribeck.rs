//! Tabulated Stribeck shape s(u) = exp(−u^δ) for the simulator's fast path.
//!
//! What it is: [`StribeckTable`], built once per plant for its fixed exponent δ, which replaces the
//! `ln → exp → exp` chain of `exp(−exp(δ·ln u))` on the physics step's dependency chain by one table
//! load and a cubic. The table is indexed by the bits of u: the binary exponent and the top
//! [`MANTISSA_BITS`] mantissa bits select a cell, so cells are uniform within each binade and shrink
//! geometrically towards 0, where u^δ has an unbounded slope for δ < 1 (the cubic's error on a cell
//! [a, 2a) scales like a^δ). The position t ∈ [0, 1) inside the cell is the remaining mantissa bits,
//! exact. Each cell holds the cubic Hermite interpolant through the values and exact derivatives
//! (f′ = −δ·u^(δ−1)·f, libm at build time) at its two ends, in monomial form.
//!
//! Coverage: u ∈ [2^[`LOWEST_EXPONENT`], 2^e_top) with 2^e_top ≥ u_cut = 40^(1/δ) (where
//! u^δ ≥ 40 and s < 4.3e-18; above the table s is 0). Below the table
//! (|ṡ| < v_s·2⁻²⁰, the stick phase) [`StribeckTable::shape`] falls back to the inlined
//! `exp(−powf(u, δ))`.
//!
//! Error bound (checked densely against libm by the tests below for δ ∈ {0.5, 0.7, 1.3, 2}):
//! |s_table(u) − exp(−u^δ)| ≤ 1e-12 absolute for u ≥ 0 — s ≤ 1 multiplies F_s − F_c, so the friction
//! level is off by ≤ 1e-12·(F_s − F_c) Nm. Measured maxima: 5.0e-14 (δ = 0.5), 8.3e-14 (δ = 0.7, the
//! ankle), 2.6e-13 (δ = 1.3), 8.5e-13 (δ = 2). The bound is absolute, not relative: where s itself is
//! tiny (large u) the cubic's relative error grows, but there (F_s − F_c)·s is negligible in g_ss.
//!
//! What it is not: used on the reference path (libm every step), nor for δ = 1 (a single inlined exp
//! is already as short as a lookup there).

use frictionless::fastmath;

/// Mantissa bits of u that select the cell inside a binade (2^9 = 512 cells per binade).
pub const MANTISSA_BITS: u32 = 9;
/// Binary exponent of the table's lower end: u < 2^−20 uses the inlined powf + exp.
pub const LOWEST_EXPONENT: i32 = -20;
/// u^δ above which s is taken as 0 (exp(−40) = 4.2e-18).
pub const CUT_EXPONENT_VALUE: f64 = 40.0;
/// Largest table accepted (binades); exponents δ so small that u_cut needs more fall back to powf.
const MAX_BINADES: i32 = 64;

/// exp(−u^δ) over u ≥ 0 by per-cell cubics (see the module documentation for layout and bound).
#[derive(Clone, Debug)]
pub struct StribeckTable {
    delta: f64,
    /// Biased exponent bits of 2^LOWEST_EXPONENT shifted to the cell index scale.
    index_offset: u64,
    /// 2^LOWEST_EXPONENT.
    u_lo: f64,
    /// 2^e_top: s = 0 at and above.
    u_top: f64,
    /// Per cell: c0 + c1·t + c2·t² + c3·t³, t ∈ [0, 1).
    cells: Vec<[f64; 4]>,
}

/// exp(−u^δ) and its derivative with libm.
fn shape_and_slope(u: f64, delta: f64) -> (f64, f64) {
    let ud = u.powf(delta);
    let f = (-ud).exp();
    let df = if u > 0.0 { -delta * ud / u * f } else { 0.0 };
    (f, df)
}

impl StribeckTable {
    /// The table for exponent `delta` (> 0, finite), or `None` when it would need more than
    /// 64 binades (δ < ≈ 0.13) — the caller then keeps `exp(−powf(u, δ))`.
    pub fn new(delta: f64) -> Option<Self> {
        if !(delta.is_finite() && delta > 0.0) {
            return None;
        }
        let u_cut = CUT_EXPONENT_VALUE.powf(1.0 / delta);
        let e_top = u_cut.log2().ceil() as i32;
        let binades = e_top - LOWEST_EXPONENT;
        if binades <= 0 || binades > MAX_BINADES {
            return None;
        }
        let per_binade = 1usize << MANTISSA_BITS;
        let mut cells = Vec::with_capacity(binades as usize * per_binade);
        for e in LOWEST_EXPONENT..e_top {
            let scale = 2f64.powi(e);
            let h = scale / per_binade as f64;
            for k in 0..per_binade {
                let a = scale + k as f64 * h;
                let b = a + h;
                let (f0, s0) = shape_and_slope(a, delta);
                let (f1, s1) = shape_and_slope(b, delta);
                let (d0, d1) = (s0 * h, s1 * h);
                cells.push([
                    f0,
                    d0,
                    3.0 * (f1 - f0) - 2.0 * d0 - d1,
                    2.0 * (f0 - f1) + d0 + d1,
                ]);
            }
        }
        let u_lo = 2f64.powi(LOWEST_EXPONENT);
        Some(Self {
            delta,
            index_offset: u_lo.to_bits() >> (52 - MANTISSA_BITS),
            u_lo,
            u_top: 2f64.powi(e_top),
            cells,
        })
    }

    /// The exponent δ the table was built for.
    pub fn delta(&self) -> f64 {
        self.delta
    }

    /// exp(−u^δ) for u ≥ 0 (NaN or negative u: unspecified but no panic).
    #[inline(always)]
    pub fn shape(&self, u: f64) -> f64 {
        if u >= self.u_top {
            return 0.0;
        }
        if u.is_nan() || u < self.u_lo {
            // stick phase (and NaN): the inlined kernels, as before the table
            return fastmath::exp_in_range(-fastmath::powf(u.max(0.0), self.delta));
        }
        let bits = u.to_bits();
        let idx = ((bits >> (52 - MANTISSA_BITS)) - self.index_offset) as usize;
        // remaining mantissa bits as t ∈ [0, 1), exact: 1.t − 1
        const MANT: u64 = (1u64 << 52) - 1;
        let t = f64::from_bits(((bits << MANTISSA_BITS) & MANT) | 1f64.to_bits()) - 1.0;
        let Some(c) = self.cells.get(idx) else {
            return 0.0; // unreachable for u < u_top; no panic on the RT path
        };
        let t2 = t * t;
        c[3].mul_add(t, c[2]).mul_add(t2, c[1].mul_add(t, c[0]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Max |table − libm| over a dense sweep: uniform in u up to past the cut, and geometric from
    /// 1e-30 (below the table) up, with points at and between cell ends.
    fn max_error(delta: f64) -> (f64, f64) {
        let tab = StribeckTable::new(delta).expect("table");
        let u_cut = CUT_EXPONENT_VALUE.powf(1.0 / delta);
        let uniform = (0..=2_000_000).map(move |i| i as f64 * (1.2 * u_cut) / 2_000_000.0);
        let geometric = (0..=400_000).map(|i| 1e-30 * 1.0002f64.powi(i)); // up to ≈ 4e4
        let mut worst = (0.0, 0.0);
        for u in uniform.chain(geometric) {
            let exact = (-u.powf(delta)).exp();
            let err = (tab.shape(u) - exact).abs();
            if err > worst.0 {
                worst = (err, u);
            }
        }
        worst
    }

    #[test]
    fn table_is_within_1e12_of_libm() {
        for delta in [0.5, 0.7, 1.3, 2.0] {
            let (err, at) = max_error(delta);
            eprintln!("δ = {delta}: max |table − libm| = {err:.3e} at u = {at:.6}");
            assert!(
                err <= 1e-12,
                "δ = {delta}: |table − libm| = {err:e} at u = {at}"
            );
        }
    }

    #[test]
    fn table_hits_the_ends_and_is_monotone() {
        let tab = StribeckTable::new(0.7).expect("table");
        assert_eq!(tab.shape(0.0), 1.0);
        assert_eq!(tab.shape(1e6), 0.0);
        let mut prev = 1.0;
        for i in 0..200_000 {
            let s = tab.shape(i as f64 * 1e-3);
            assert!(s <= prev + 1e-15, "not monotone at u = {}", i as f64 * 1e-3);
            prev = s;
        }
    }

    #[test]
    fn rejects_bad_exponents() {
        assert!(StribeckTable::new(0.0).is_none());
        assert!(StribeckTable::new(f64::NAN).is_none());
        assert!(StribeckTable::new(0.05).is_none());
    }
}
