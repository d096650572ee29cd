//! Static joint-side friction models: Coulomb–viscous (CV) and Stribeck–Coulomb–viscous (SCV).
//!
//! Velocity `v` is the joint velocity ṡ in rad/s; friction is joint-side torque in Nm, with the sign
//! of the motion (it is what the motor must add to move the joint).
//!
//! What this module **is**: the three closed-form models of the paper (§8 of the reference notes) —
//! [`CvParams`] (CV), [`ScvParams`] (SCV, paper form, `ka = +∞` meaning a true `sign()`) and
//! [`ScvCodeParams`] (SCV in the authors' training-code form, `ka → ∞`, `α = 2`) — with their values,
//! analytic parameter Jacobians (finite everywhere, including at `v = 0`), slice evaluation and
//! parameter validation, all behind the [`StaticFriction`] trait so that one generic least-squares
//! fitter can fit any of them. [`paper`] holds the published Table I values.
//!
//! What it is **not**: no fitting (that lives in the tools), no state, no history, no units other than
//! SI joint-side rad/s and Nm.

use std::fmt::Debug;

/// Why a friction parameter set (or a slice handed to a friction model) is not acceptable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrictionParamError {
    /// One parameter is out of its domain.
    #[error("{model} parameter `{name}` = {value} is invalid: it must be {requirement}")]
    Invalid {
        /// Model name, e.g. "SCV".
        model: &'static str,
        /// Parameter name, e.g. "vs".
        name: &'static str,
        /// The offending value.
        value: f64,
        /// What the value must satisfy, e.g. "finite and > 0".
        requirement: &'static str,
    },
    /// A parameter vector of the wrong length.
    #[error("{model} takes {expected} parameters {names:?}, got {got}")]
    Count {
        /// Model name.
        model: &'static str,
        /// Number of parameters the model has.
        expected: usize,
        /// Their names, in order.
        names: &'static [&'static str],
        /// Length of the vector given.
        got: usize,
    },
    /// Input and output slices do not fit together.
    #[error("slice length mismatch: `{what}` has {got} values, expected {expected}")]
    Length {
        /// Which slice.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The length it must have.
        expected: usize,
    },
}

/// A static (memoryless) friction model τ_F(ṡ) with a fixed-length parameter vector.
///
/// Everything a generic least-squares fitter needs: value, parameter Jacobian, the parameter vector
/// and the way back, and validation. Parameters are ordered as in [`StaticFriction::PARAM_NAMES`].
pub trait StaticFriction: Copy + Debug + Sized {
    /// Short model name used in error messages, e.g. "CV".
    const NAME: &'static str;
    /// Number of parameters.
    const N_PARAMS: usize;
    /// Parameter names, in vector order.
    const PARAM_NAMES: &'static [&'static str];
    /// A fixed-size parameter (or Jacobian) vector, `[f64; N_PARAMS]`.
    type ParamVec: Copy + Debug + Default + AsRef<[f64]> + AsMut<[f64]>;

    /// Joint-side friction torque [Nm] at joint velocity `v_rad_s` [rad/s].
    fn torque_nm(&self, v_rad_s: f64) -> f64;

    /// ∂τ/∂p at `v_rad_s`, one entry per parameter in [`StaticFriction::PARAM_NAMES`] order.
    /// Finite for every finite `v_rad_s` and valid parameters (0 where a term vanishes, e.g. at v = 0).
    fn jacobian(&self, v_rad_s: f64) -> Self::ParamVec;

    /// The parameter vector.
    fn params(&self) -> Self::ParamVec;

    /// Builds the model from a parameter vector without checking the domain (only the length is fixed
    /// by the type). For optimisers that handle constraints themselves; evaluation outside the domain
    /// may give NaN.
    fn from_params_unchecked(p: &Self::ParamVec) -> Self;

    /// Checks every parameter; the error names the first bad one.
    fn validate(&self) -> Result<(), FrictionParamError>;

    /// Builds and validates the model from a parameter slice of length [`StaticFriction::N_PARAMS`].
    fn from_params(p: &[f64]) -> Result<Self, FrictionParamError> {
        let mut v = Self::ParamVec::default();
        if p.len() != v.as_ref().len() {
            return Err(FrictionParamError::Count {
                model: Self::NAME,
                expected: Self::N_PARAMS,
                names: Self::PARAM_NAMES,
                got: p.len(),
            });
        }
        v.as_mut().copy_from_slice(p);
        let m = Self::from_params_unchecked(&v);
        m.validate()?;
        Ok(m)
    }

    /// Evaluates [`StaticFriction::torque_nm`] for every velocity of `v_rad_s` into `out_nm`
    /// (same length, else an error and `out_nm` untouched).
    fn eval_slice(&self, v_rad_s: &[f64], out_nm: &mut [f64]) -> Result<(), FrictionParamError> {
        if out_nm.len() != v_rad_s.len() {
            return Err(FrictionParamError::Length {
                what: "out",
                got: out_nm.len(),
                expected: v_rad_s.len(),
            });
        }
        for (o, &v) in out_nm.iter_mut().zip(v_rad_s) {
            *o = self.torque_nm(v);
        }
        Ok(())
    }

    /// Row-major Jacobian of a whole data set: `out[k·N_PARAMS + p] = ∂τ(v_k)/∂p`.
    /// `out.len()` must be `v_rad_s.len() · N_PARAMS`.
    fn jacobian_slice(&self, v_rad_s: &[f64], out: &mut [f64]) -> Result<(), FrictionParamError> {
        let n = Self::N_PARAMS;
        if out.len() != v_rad_s.len() * n {
            return Err(FrictionParamError::Length {
                what: "jacobian out",
                got: out.len(),
                expected: v_rad_s.len() * n,
            });
        }
        for (row, &v) in out.chunks_exact_mut(n).zip(v_rad_s) {
            row.copy_from_slice(self.jacobian(v).as_ref());
        }
        Ok(())
    }
}

/// `tanh(ka·v)` and its derivative with respect to `ka`, `v·sech²(ka·v)`.
/// `ka = +∞` means `sign(v)` (0 at v = 0) with a zero derivative.
#[inline]
fn smooth_sign(ka: f64, v: f64) -> (f64, f64) {
    if ka == f64::INFINITY {
        (sign0(v), 0.0)
    } else {
        let x = ka * v;
        // sech² as 1/cosh² keeps full relative precision in the tails (1 − tanh² would cancel);
        // cosh overflows to +∞ for |x| > ~710, giving an exact 0.
        let c = x.cosh();
        (x.tanh(), v / (c * c))
    }
}

/// sign(v) with sign(0) = 0 (NaN propagates).
#[inline]
fn sign0(v: f64) -> f64 {
    if v == 0.0 { 0.0 } else { v.signum() }
}

fn check(
    model: &'static str,
    name: &'static str,
    value: f64,
    ok: bool,
    requirement: &'static str,
) -> Result<(), FrictionParamError> {
    if ok {
        Ok(())
    } else {
        Err(FrictionParamError::Invalid {
            model,
            name,
            value,
            requirement,
        })
    }
}

fn check_nonneg(model: &'static str, name: &'static str, v: f64) -> Result<(), FrictionParamError> {
    check(model, name, v, v.is_finite() && v >= 0.0, "finite and >= 0")
}

fn check_pos(model: &'static str, name: &'static str, v: f64) -> Result<(), FrictionParamError> {
    check(model, name, v, v.is_finite() && v > 0.0, "finite and > 0")
}

fn check_ka(model: &'static str, v: f64) -> Result<(), FrictionParamError> {
    check(
        model,
        "ka",
        v,
        v > 0.0 && !v.is_nan(),
        "> 0 (+inf means sign())",
    )
}

/// Coulomb–viscous: τ = kc·tanh(ka·v) + kv·v.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CvParams {
    /// Coulomb level kc [Nm].
    pub kc: f64,
    /// Smooth-sign steepness ka [s/rad].
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad].
    pub kv: f64,
}

impl StaticFriction for CvParams {
    const NAME: &'static str = "CV";
    const N_PARAMS: usize = 3;
    const PARAM_NAMES: &'static [&'static str] = &["kc", "ka", "kv"];
    type ParamVec = [f64; 3];

    #[inline]
    fn torque_nm(&self, v_rad_s: f64) -> f64 {
        let (t, _) = smooth_sign(self.ka, v_rad_s);
        self.kc * t + self.kv * v_rad_s
    }

    fn jacobian(&self, v: f64) -> [f64; 3] {
        let (t, dt_dka) = smooth_sign(self.ka, v);
        [t, self.kc * dt_dka, v]
    }

    fn params(&self) -> [f64; 3] {
        [self.kc, self.ka, self.kv]
    }

    fn from_params_unchecked(p: &[f64; 3]) -> Self {
        Self {
            kc: p[0],
            ka: p[1],
            kv: p[2],
        }
    }

    fn validate(&self) -> Result<(), FrictionParamError> {
        check_nonneg(Self::NAME, "kc", self.kc)?;
        check_ka(Self::NAME, self.ka)?;
        check_nonneg(Self::NAME, "kv", self.kv)
    }
}

/// Stribeck–Coulomb–viscous, paper form:
/// τ = kv·v + kc·tanh(ka·v) + (ks − kc)·exp(−|v/vs|^α)·tanh(ka·v).
///
/// `ka = f64::INFINITY` replaces tanh(ka·v) by sign(v) (sign(0) = 0); with `alpha = 2` this is exactly
/// the authors' code form ([`ScvCodeParams`], see the `From` conversion).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScvParams {
    /// Coulomb level kc [Nm].
    pub kc: f64,
    /// Smooth-sign steepness ka [s/rad].
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad].
    pub kv: f64,
    /// Breakaway (static) friction ks [Nm].
    pub ks: f64,
    /// Stribeck velocity vs [rad/s].
    pub vs: f64,
    /// Stribeck shape exponent α [-].
    pub alpha: f64,
}

impl ScvParams {
    /// The Stribeck factor exp(−|v/vs|^α) and p = |v/vs|^α.
    #[inline]
    fn stribeck(&self, v: f64) -> (f64, f64) {
        let p = (v.abs() / self.vs).powf(self.alpha);
        ((-p).exp(), p)
    }
}

impl StaticFriction for ScvParams {
    const NAME: &'static str = "SCV";
    const N_PARAMS: usize = 6;
    const PARAM_NAMES: &'static [&'static str] = &["kc", "ka", "kv", "ks", "vs", "alpha"];
    type ParamVec = [f64; 6];

    #[inline]
    fn torque_nm(&self, v_rad_s: f64) -> f64 {
        let (t, _) = smooth_sign(self.ka, v_rad_s);
        let (e, _) = self.stribeck(v_rad_s);
        self.kv * v_rad_s + (self.kc + (self.ks - self.kc) * e) * t
    }

    fn jacobian(&self, v: f64) -> [f64; 6] {
        let (t, dt_dka) = smooth_sign(self.ka, v);
        let (e, p) = self.stribeck(v);
        let dks = self.ks - self.kc;
        // ∂/∂vs and ∂/∂α of e = exp(−p), p = u^α, u = |v|/vs:
        //   ∂e/∂vs = e·α·p/vs,  ∂e/∂α = −e·p·ln u.
        // Both vanish where e·p = 0 (v = 0 gives p = 0 and ln u = −∞; huge u gives e = 0, p maybe ∞),
        // so they are set to exactly 0 there instead of evaluating 0·∞.
        let ep = e * p;
        let (de_dvs, de_dalpha) = if ep == 0.0 || !ep.is_finite() {
            (0.0, 0.0)
        } else {
            let u = v.abs() / self.vs;
            (ep * self.alpha / self.vs, -ep * u.ln())
        };
        [
            t * (1.0 - e),
            (self.kc + dks * e) * dt_dka,
            v,
            e * t,
            dks * t * de_dvs,
            dks * t * de_dalpha,
        ]
    }

    fn params(&self) -> [f64; 6] {
        [self.kc, self.ka, self.kv, self.ks, self.vs, self.alpha]
    }

    fn from_params_unchecked(p: &[f64; 6]) -> Self {
        Self {
            kc: p[0],
            ka: p[1],
            kv: p[2],
            ks: p[3],
            vs: p[4],
            alpha: p[5],
        }
    }

    fn validate(&self) -> Result<(), FrictionParamError> {
        check_nonneg(Self::NAME, "kc", self.kc)?;
        check_ka(Self::NAME, self.ka)?;
        check_nonneg(Self::NAME, "kv", self.kv)?;
        check_nonneg(Self::NAME, "ks", self.ks)?;
        check_pos(Self::NAME, "vs", self.vs)?;
        check_pos(Self::NAME, "alpha", self.alpha)
    }
}

/// Stribeck–Coulomb–viscous, the authors' training-code form (ka → ∞, α = 2):
/// τ = (Fc + (Fs − Fc)·exp(−(v/Vs)²))·sign(v) + Fv·v.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScvCodeParams {
    /// Coulomb level Fc [Nm].
    pub fc: f64,
    /// Static level Fs [Nm].
    pub fs: f64,
    /// Viscous Fv [Nm·s/rad].
    pub fv: f64,
    /// Stribeck velocity Vs [rad/s].
    pub vs: f64,
}

impl StaticFriction for ScvCodeParams {
    const NAME: &'static str = "SCV (code form)";
    const N_PARAMS: usize = 4;
    const PARAM_NAMES: &'static [&'static str] = &["fc", "fs", "fv", "vs"];
    type ParamVec = [f64; 4];

    #[inline]
    fn torque_nm(&self, v_rad_s: f64) -> f64 {
        let q = v_rad_s / self.vs;
        let e = (-(q * q)).exp();
        (self.fc + (self.fs - self.fc) * e) * sign0(v_rad_s) + self.fv * v_rad_s
    }

    fn jacobian(&self, v: f64) -> [f64; 4] {
        let sg = sign0(v);
        let q = v / self.vs;
        let q2 = q * q;
        let e = (-q2).exp();
        // ∂e/∂vs = e·2q²/vs; exactly 0 where e·q² = 0 (v = 0 or e underflowed).
        let eq2 = e * q2;
        let de_dvs = if eq2 == 0.0 || !eq2.is_finite() {
            0.0
        } else {
            2.0 * eq2 / self.vs
        };
        [(1.0 - e) * sg, e * sg, v, (self.fs - self.fc) * sg * de_dvs]
    }

    fn params(&self) -> [f64; 4] {
        [self.fc, self.fs, self.fv, self.vs]
    }

    fn from_params_unchecked(p: &[f64; 4]) -> Self {
        Self {
            fc: p[0],
            fs: p[1],
            fv: p[2],
            vs: p[3],
        }
    }

    fn validate(&self) -> Result<(), FrictionParamError> {
        check_nonneg(Self::NAME, "fc", self.fc)?;
        check_nonneg(Self::NAME, "fs", self.fs)?;
        check_nonneg(Self::NAME, "fv", self.fv)?;
        check_pos(Self::NAME, "vs", self.vs)
    }
}

impl From<ScvCodeParams> for ScvParams {
    /// The same model in paper form: `ka = +∞` (sign), `α = 2`.
    fn from(c: ScvCodeParams) -> Self {
        Self {
            kc: c.fc,
            ka: f64::INFINITY,
            kv: c.fv,
            ks: c.fs,
            vs: c.vs,
            alpha: 2.0,
        }
    }
}

/// Published values, Table I of the Humanoids 2024 paper (ergoCub; fitted with Adam on MSE).
pub mod paper {
    use super::{CvParams, ScvParams};

    /// CV, ankle roll.
    pub const CV_ANKLE_ROLL: CvParams = CvParams {
        kc: 1.2,
        ka: 10.53,
        kv: 0.24,
    };
    /// SCV, ankle roll.
    pub const SCV_ANKLE_ROLL: ScvParams = ScvParams {
        kc: 1.0005,
        ka: 2.78,
        kv: 0.29,
        ks: 6.0,
        vs: 0.13,
        alpha: 0.6,
    };
    /// CV, knee.
    pub const CV_KNEE: CvParams = CvParams {
        kc: 8.1,
        ka: 50.84,
        kv: 5.55,
    };
    /// SCV, knee.
    pub const SCV_KNEE: ScvParams = ScvParams {
        kc: 5.0,
        ka: 16.95,
        kv: 5.34,
        ks: 9.7,
        vs: 5.4,
        alpha: 0.5,
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Central finite difference of τ(v) with respect to each parameter.
    fn fd_jacobian<M: StaticFriction>(m: &M, v: f64) -> Vec<f64> {
        let p0 = m.params();
        (0..M::N_PARAMS)
            .map(|k| {
                let h = 1e-6 * p0.as_ref()[k].abs().max(1e-3);
                let mut hi = p0;
                let mut lo = p0;
                hi.as_mut()[k] += h;
                lo.as_mut()[k] -= h;
                let thi = M::from_params_unchecked(&hi).torque_nm(v);
                let tlo = M::from_params_unchecked(&lo).torque_nm(v);
                (thi - tlo) / (2.0 * h)
            })
            .collect()
    }

    fn assert_jacobian_matches_fd<M: StaticFriction>(m: &M, v: f64) {
        let an = m.jacobian(v);
        let fd = fd_jacobian(m, v);
        for (k, (a, f)) in an.as_ref().iter().zip(&fd).enumerate() {
            assert!(
                a.is_finite(),
                "{} d/d{} not finite at v={v}: {a}",
                M::NAME,
                M::PARAM_NAMES[k]
            );
            let tol = 1e-5 * (1.0 + a.abs().max(f.abs()));
            assert!(
                (a - f).abs() <= tol,
                "{} d/d{} at v={v}: analytic {a}, finite difference {f}, model {m:?}",
                M::NAME,
                M::PARAM_NAMES[k]
            );
        }
    }

    fn cv() -> impl Strategy<Value = CvParams> {
        (0.0..10.0f64, 0.5..60.0f64, 0.0..6.0f64).prop_map(|(kc, ka, kv)| CvParams { kc, ka, kv })
    }

    fn scv() -> impl Strategy<Value = ScvParams> {
        (
            0.0..10.0f64,
            0.5..60.0f64,
            0.0..6.0f64,
            0.0..12.0f64,
            0.01..6.0f64,
            0.3..3.0f64,
        )
            .prop_map(|(kc, ka, kv, ks, vs, alpha)| ScvParams {
                kc,
                ka,
                kv,
                ks,
                vs,
                alpha,
            })
    }

    fn code() -> impl Strategy<Value = ScvCodeParams> {
        (0.0..2.0f64, 0.0..3.0f64, 0.0..2.0f64, 0.003..0.5f64)
            .prop_map(|(fc, fs, fv, vs)| ScvCodeParams { fc, fs, fv, vs })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn cv_jacobian_matches_finite_differences(m in cv(), v in -3.0..3.0f64) {
            assert_jacobian_matches_fd(&m, v);
        }

        #[test]
        fn scv_jacobian_matches_finite_differences(m in scv(), v in -3.0..3.0f64) {
            assert_jacobian_matches_fd(&m, v);
        }

        #[test]
        fn code_jacobian_matches_finite_differences(m in code(), v in -1.0..1.0f64) {
            // Away from 0 (sign() is not differentiable in v, but the test differentiates in p,
            // which is smooth for v ≠ 0; v = 0 is covered by its own test).
            prop_assume!(v.abs() > 1e-9);
            assert_jacobian_matches_fd(&m, v);
        }

        #[test]
        fn all_models_are_odd(c in cv(), s in scv(), k in code(), v in -5.0..5.0f64) {
            prop_assert_eq!(c.torque_nm(-v), -c.torque_nm(v));
            prop_assert_eq!(s.torque_nm(-v), -s.torque_nm(v));
            prop_assert_eq!(k.torque_nm(-v), -k.torque_nm(v));
        }

        #[test]
        fn infinite_ka_alpha_2_equals_code_form(k in code(), v in -1.0..1.0f64) {
            let paper = ScvParams::from(k);
            let (a, b) = (paper.torque_nm(v), k.torque_nm(v));
            prop_assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
            // and a large finite ka converges to the same value away from v = 0
            prop_assume!(v.abs() > 1e-3);
            let steep = ScvParams { ka: 1e6, ..paper };
            prop_assert!((steep.torque_nm(v) - b).abs() <= 1e-9 * (1.0 + b.abs()));
        }

        #[test]
        fn params_round_trip(s in scv()) {
            prop_assert_eq!(ScvParams::from_params(&s.params()).unwrap(), s);
        }
    }

    #[test]
    fn jacobians_are_finite_and_sensible_at_zero_velocity() {
        let s = paper::SCV_ANKLE_ROLL;
        let j = s.jacobian(0.0);
        // tanh(0) = 0 kills every Coulomb/Stribeck term; ∂/∂ka = kc·v·sech² = 0 too.
        assert_eq!(j, [0.0; 6]);
        let inf = ScvParams {
            ka: f64::INFINITY,
            ..s
        };
        assert_eq!(inf.jacobian(0.0), [0.0; 6]);
        assert_eq!(inf.torque_nm(0.0), 0.0);
        let c = ScvCodeParams {
            fc: 0.24,
            fs: 0.46,
            fv: 0.77,
            vs: 0.0198,
        };
        assert_eq!(c.jacobian(0.0), [0.0; 4]);
        assert_eq!(c.torque_nm(0.0), 0.0);
        // Tiny v with a large exponent: p underflows, no 0·ln(0) NaN.
        let j = ScvParams { alpha: 3.0, ..s }.jacobian(1e-200);
        assert!(j.iter().all(|x| x.is_finite()), "{j:?}");
        // Huge v: the Stribeck factor underflows, no 0·∞ NaN.
        let j = ScvParams { vs: 1e-300, ..s }.jacobian(1e10);
        assert!(j.iter().all(|x| x.is_finite()), "{j:?}");
        let j = ScvCodeParams { vs: 1e-300, ..c }.jacobian(1e10);
        assert!(j.iter().all(|x| x.is_finite()), "{j:?}");
    }

    #[test]
    fn values_by_hand() {
        // CV at v = 0.1 with ka = 10: tanh(1) = 0.7615941559557649.
        let m = CvParams {
            kc: 2.0,
            ka: 10.0,
            kv: 0.5,
        };
        assert!((m.torque_nm(0.1) - (2.0 * 0.761_594_155_955_764_9 + 0.05)).abs() < 1e-14);
        // SCV at v = vs with α = 1: exp(−1) = 0.36787944117144233; ka = ∞ → sign = 1.
        let s = ScvParams {
            kc: 1.0,
            ka: f64::INFINITY,
            kv: 2.0,
            ks: 3.0,
            vs: 0.5,
            alpha: 1.0,
        };
        let want = 2.0 * 0.5 + 1.0 + (3.0 - 1.0) * 0.367_879_441_171_442_33;
        assert!((s.torque_nm(0.5) - want).abs() < 1e-14);
        assert!((s.torque_nm(-0.5) + want).abs() < 1e-14);
        // Code form at v = −2·Vs: exp(−4) = 0.018315638888734179.
        let c = ScvCodeParams {
            fc: 0.5,
            fs: 1.5,
            fv: 0.25,
            vs: 0.1,
        };
        let want = -(0.5 + 1.0 * 0.018_315_638_888_734_18) - 0.25 * 0.2;
        assert!((c.torque_nm(-0.2) - want).abs() < 1e-14);
        // Breakaway: just off zero the SCV approaches ks·sign (ka = ∞).
        assert!((s.torque_nm(1e-12) - 3.0).abs() < 1e-9);
    }

    #[test]
    fn eval_slice_matches_pointwise_and_checks_lengths() {
        let s = paper::SCV_KNEE;
        let v: Vec<f64> = (-20..=20).map(|k| k as f64 * 0.37).collect();
        let mut out = vec![0.0; v.len()];
        s.eval_slice(&v, &mut out).unwrap();
        for (vi, oi) in v.iter().zip(&out) {
            assert_eq!(*oi, s.torque_nm(*vi));
        }
        let mut short = vec![0.0; 3];
        assert!(matches!(
            s.eval_slice(&v, &mut short),
            Err(FrictionParamError::Length { .. })
        ));
        let mut jac = vec![0.0; v.len() * 6];
        s.jacobian_slice(&v, &mut jac).unwrap();
        assert_eq!(&jac[6 * 7..6 * 8], &s.jacobian(v[7])[..]);
        assert!(s.jacobian_slice(&v, &mut out).is_err());
    }

    #[test]
    fn validation_names_the_parameter() {
        for p in [paper::CV_ANKLE_ROLL, paper::CV_KNEE] {
            p.validate().unwrap();
        }
        for p in [paper::SCV_ANKLE_ROLL, paper::SCV_KNEE] {
            p.validate().unwrap();
        }
        let bad = |e: FrictionParamError, want: &str| match e {
            FrictionParamError::Invalid { name, .. } => assert_eq!(name, want),
            other => panic!("expected Invalid({want}), got {other:?}"),
        };
        bad(CvParams::from_params(&[1.0, 0.0, 1.0]).unwrap_err(), "ka");
        bad(CvParams::from_params(&[-1.0, 1.0, 1.0]).unwrap_err(), "kc");
        bad(
            CvParams::from_params(&[1.0, 1.0, f64::NAN]).unwrap_err(),
            "kv",
        );
        let s = paper::SCV_KNEE;
        bad(ScvParams { vs: 0.0, ..s }.validate().unwrap_err(), "vs");
        bad(
            ScvParams { alpha: -0.5, ..s }.validate().unwrap_err(),
            "alpha",
        );
        bad(
            ScvParams {
                ks: f64::INFINITY,
                ..s
            }
            .validate()
            .unwrap_err(),
            "ks",
        );
        bad(
            ScvParams { ka: f64::NAN, ..s }.validate().unwrap_err(),
            "ka",
        );
        ScvParams {
            ka: f64::INFINITY,
            ..s
        }
        .validate()
        .unwrap();
        bad(
            ScvCodeParams {
                fc: 0.1,
                fs: 0.2,
                fv: 0.3,
                vs: -1.0,
            }
            .validate()
            .unwrap_err(),
            "vs",
        );
        let e = ScvParams::from_params(&[1.0; 5]).unwrap_err();
        assert!(matches!(
            e,
            FrictionParamError::Count {
                expected: 6,
                got: 5,
                ..
            }
        ));
        assert!(e.to_string().contains("alpha"), "{e}");
        let msg = ScvParams { vs: 0.0, ..s }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(msg.contains("vs") && msg.contains('0'), "{msg}");
    }
}
