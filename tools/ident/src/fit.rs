//! Least-squares fitting of the static friction models (CV, SCV, SCV code form) to (ṡ, τ_F) data.
//!
//! What it is: [`fit`] with two solvers over any [`StaticFriction`] model, using the model's analytic
//! Jacobian:
//! - [`Method::Lm`] (default): Levenberg–Marquardt with Marquardt diagonal scaling on
//!   log-parameters `p = exp(u)` (so every parameter stays > 0, which is each model's domain; `ka = ∞`
//!   is not reachable by fitting). It is written here instead of using the `levenberg-marquardt`
//!   crate because that crate materialises the N×P Jacobian and QR-factorises it every iteration
//!   (48 MB and O(N·P²) with pivoting for 10⁶ samples × 6 parameters); with P ≤ 6 the normal
//!   equations `JᵀJ` (P×P) and `Jᵀr` can be accumulated in one streaming, rayon-parallel pass, which
//!   is what keeps a 10⁶-sample fit well under a second. Conditioning is handled by the Marquardt
//!   scaling and by solving in log-space; a few coarse starts on a 5 000-sample subsample pick the
//!   basin (in parallel), the best converges on a ≤ 100 000-sample subsample, then 1–2 steps polish it
//!   on all samples. Each pass evaluates τ and ∂τ/∂p together ([`Fittable::value_jacobian`]), and LM
//!   stops as soon as the decrease its own linear model predicts is below `rel_tol` (no wasted data
//!   passes on rejected steps near the optimum).
//!
//!   The pass itself is vectorised by hand-shaped code, not a crate: samples go through
//!   [`Fittable::value_jacobian_lanes`] in groups of [`LANES`], with branch-free [`exp_lanes`] /
//!   [`ln_lanes`] (`frictionless::fastmath`, ≈ 1 ulp from libm, tested there) written one loop per operation so LLVM emits AVX2, and
//!   JᵀJ/Jᵀr accumulated lane-wise; chunk sums are added in chunk order (bit-identical for any
//!   thread count). Measurements and the alternatives tried are in `docs/decisions.md`
//!   ("Identification"); `cargo bench -p frictionless-ident --bench fit` re-runs them.
//!
//!   Bounds ([`FitBounds`], defaults physically motivated, overridable by `frictl fit` flags): the
//!   unbounded least-squares optimum runs away on real/simulated data (ka → 1e8 turns tanh into a
//!   sign function, so velocity noise near 0 switches the compensation by ±2·kc; vs → 1e-10 with a
//!   tiny α and ks = 400·kc is a spike no controller should follow). LM therefore works on
//!   `z = ln p` with box bounds, except that ks (fs) is parametrised as `ln(ks/kc)` so
//!   `ks ≤ ks_max_ratio·kc` is a box bound too; every constraint is then a box in z, enforced by a
//!   projected LM with an active set (a parameter at a bound whose gradient pushes outward is held
//!   fixed for that iteration; the trial step is projected onto the box). Cost per iteration is
//!   unchanged (same single data pass). kc, kv, ks ≥ 0 stay enforced by the log parametrisation
//!   (floor 1e-12).
//! - [`Method::Adam`]: the paper/authors' procedure for parity — full-batch Adam on softplus
//!   parameters (lr 0.01, 3000 epochs, L1 or MSE loss).
//! - [`sliding_quadrant_mask`]: the authors' sample selection (|ṡ| > 0.03 rad/s and ṡ·τ_F > 0).
//! - [`fit_from_starts`]: [`fit`] with starts of the caller's besides the model's own; the SCV fit of
//!   `frictl fit scv` (data-derived bounds, the CV fallback) is [`crate::scv_fit`].
//!
//! What it is not: a fitter for history (PINN) models, or a robust/weighted regression.

use frictionless::fastmath::{exp_lanes, ln_lanes};
use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Largest number of parameters of a static model (SCV).
const MAX_P: usize = 6;

/// Fitting errors.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    /// Velocity and torque columns differ in length.
    #[error("velocity has {v} samples but torque has {tau}")]
    Length {
        /// Velocity samples.
        v: usize,
        /// Torque samples.
        tau: usize,
    },
    /// Not enough samples for the number of parameters.
    #[error("{got} samples selected, need at least {need} to fit {model}")]
    TooFew {
        /// Model name.
        model: &'static str,
        /// Selected samples.
        got: usize,
        /// Required.
        need: usize,
    },
    /// A sample is not finite.
    #[error("sample {index} is not finite (v = {v}, tau = {tau})")]
    NonFinite {
        /// Index.
        index: usize,
        /// Velocity.
        v: f64,
        /// Torque.
        tau: f64,
    },
    /// The bounds are not a valid box (`0 < lo ≤ hi`, not NaN).
    #[error("invalid fit bounds: {0}")]
    Bounds(String),
    /// The result is outside the model's domain.
    #[error("fit of {model} ended outside the parameter domain: {msg}")]
    Domain {
        /// Model name.
        model: &'static str,
        /// Reason.
        msg: String,
    },
}

/// Solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Projected Levenberg–Marquardt on log-parameters within the bounds (least squares).
    Lm,
    /// Full-batch Adam on softplus parameters (the paper's procedure).
    Adam,
}

/// Loss of the Adam solver (LM is always least squares).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Loss {
    /// Mean squared error (paper).
    Mse,
    /// Mean absolute error (authors' code).
    L1,
}

frictionless::named_enum!(Method, "solver", [Lm = "lm", Adam = "adam"]);
frictionless::named_enum!(Loss, "loss", [Mse = "mse", L1 = "l1"]);

/// Floor/ceiling of the parameters that have no physical bound other than positivity (kc, kv, ks/kc).
const P_MIN: f64 = 1e-12;
const P_MAX: f64 = 1e12;

/// Physical bounds on the fitted parameters, enforced by both solvers.
///
/// Defaults: `ka ≤ 200 s/rad` — tanh(ka·v) reaches 0.76 at v = 1/ka, so 200 s/rad means the smooth
/// sign still spans ≥ 5 mrad/s, the order of the velocity noise/resolution; a steeper one only
/// follows label noise and makes the closed-loop compensation chatter. `vs ∈ [1e-3, 10] rad/s` and
/// `α ∈ [0.2, 5]` keep the Stribeck term a hump over a velocity band the data can resolve;
/// `ks ≤ 10·kc` rejects the spikes that a few stick samples produce.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitBounds {
    /// Smallest ka [s/rad].
    pub ka_min: f64,
    /// Largest ka [s/rad].
    pub ka_max: f64,
    /// Smallest Stribeck velocity vs [rad/s].
    pub vs_min: f64,
    /// Largest Stribeck velocity vs [rad/s].
    pub vs_max: f64,
    /// Smallest Stribeck exponent α.
    pub alpha_min: f64,
    /// Largest Stribeck exponent α.
    pub alpha_max: f64,
    /// Largest ks/kc (fs/fc for the code form).
    pub ks_max_ratio: f64,
    /// Largest Coulomb level kc (fc) [Nm] (SCV, SCV code form; absent in files written before:
    /// unbounded).
    #[serde(default = "unbounded_kc")]
    pub kc_max_nm: f64,
}

fn unbounded_kc() -> f64 {
    P_MAX
}

impl Default for FitBounds {
    fn default() -> Self {
        Self {
            ka_min: 1e-3,
            ka_max: 200.0,
            vs_min: 1e-3,
            vs_max: 10.0,
            alpha_min: 0.2,
            alpha_max: 5.0,
            ks_max_ratio: 10.0,
            kc_max_nm: P_MAX,
        }
    }
}

impl FitBounds {
    /// Bounds that only keep the parameters in the models' domain (the pre-bounds behaviour).
    pub const UNBOUNDED: FitBounds = FitBounds {
        ka_min: P_MIN,
        ka_max: P_MAX,
        vs_min: P_MIN,
        vs_max: P_MAX,
        alpha_min: P_MIN,
        alpha_max: P_MAX,
        ks_max_ratio: P_MAX,
        kc_max_nm: P_MAX,
    };

    /// Checks `0 < lo ≤ hi` for each pair and `ks_max_ratio > 0` (∞ allowed as an upper bound).
    pub fn validate(&self) -> Result<(), FitError> {
        for (name, lo, hi) in [
            ("ka", self.ka_min, self.ka_max),
            ("vs", self.vs_min, self.vs_max),
            ("alpha", self.alpha_min, self.alpha_max),
            ("ks/kc", P_MIN, self.ks_max_ratio),
            ("kc", P_MIN, self.kc_max_nm),
        ] {
            if !(lo > 0.0 && lo.is_finite() && hi >= lo) {
                return Err(FitError::Bounds(format!(
                    "{name} range [{lo}, {hi}] (need 0 < min ≤ max, min finite)"
                )));
            }
        }
        Ok(())
    }
}

/// Fitting options.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FitOptions {
    /// Solver.
    pub method: Method,
    /// LM: maximum iterations of the refinement on all samples.
    pub max_iter: usize,
    /// LM: stop when the relative cost decrease of an accepted step is below this.
    pub rel_tol: f64,
    /// Adam: learning rate.
    pub adam_lr: f64,
    /// Adam: epochs (full-batch steps).
    pub adam_epochs: usize,
    /// Adam: loss.
    pub adam_loss: Loss,
    /// Parameter bounds (both solvers).
    pub bounds: FitBounds,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            method: Method::Lm,
            max_iter: 200,
            rel_tol: 1e-10,
            adam_lr: 0.01,
            adam_epochs: 3000,
            adam_loss: Loss::L1,
            bounds: FitBounds::default(),
        }
    }
}

/// Result of a fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FitResult<M> {
    /// The fitted model.
    pub model: M,
    /// RMSE on the fitted samples [Nm].
    pub rmse_nm: f64,
    /// Mean absolute error on the fitted samples [Nm].
    pub mae_nm: f64,
    /// Number of samples fitted.
    pub n_samples: usize,
    /// Iterations (LM refinement) or epochs (Adam).
    pub iterations: usize,
    /// Parameters that ended on a bound, e.g. `"ka=max"`, `"ks/kc=max"` (empty: interior optimum).
    pub at_bounds: Vec<String>,
}

/// The authors' sliding-data selection: `|ṡ| > v_min_rad_s` and `ṡ·τ_F > 0` (1st/3rd quadrant).
pub fn sliding_quadrant_mask(v_rad_s: &[f64], tau_nm: &[f64], v_min_rad_s: f64) -> Vec<bool> {
    v_rad_s
        .iter()
        .zip(tau_nm)
        .map(|(&v, &t)| v.abs() > v_min_rad_s && v * t > 0.0)
        .collect()
}

/// Keeps the samples where `mask` is true.
pub fn select(x: &[f64], mask: &[bool]) -> Vec<f64> {
    x.iter()
        .zip(mask)
        .filter_map(|(&v, &m)| m.then_some(v))
        .collect()
}

/// Least-squares Coulomb + viscous guess `τ ≈ kc·sign(v) + kv·v` (both clamped ≥ 1e-3).
fn coulomb_viscous_guess(v: &[f64], tau: &[f64]) -> (f64, f64) {
    let (mut s11, mut s12, mut s22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&x, &y) in v.iter().zip(tau) {
        let sg = if x > 0.0 {
            1.0
        } else if x < 0.0 {
            -1.0
        } else {
            0.0
        };
        s11 += sg * sg;
        s12 += sg * x;
        s22 += x * x;
        b1 += sg * y;
        b2 += x * y;
    }
    let det = s11 * s22 - s12 * s12;
    if det.abs() < 1e-300 {
        return (1.0, 1.0);
    }
    let kc = (b1 * s22 - b2 * s12) / det;
    let kv = (s11 * b2 - s12 * b1) / det;
    (kc.max(1e-3), kv.max(1e-3))
}

/// Models that can be fitted: they provide starting points from the data.
pub trait Fittable: StaticFriction + Serialize + Send + Sync {
    /// A few starting points derived from the data (the fitter tries all and keeps the best).
    fn starts(v: &[f64], tau: &[f64]) -> Vec<Self>;

    /// `(lo, hi)` of each parameter in [`StaticFriction::PARAM_NAMES`] order; for the child of
    /// [`Fittable::RATIO`] the bounds are on `p[child] / p[parent]`.
    fn bounds(b: &FitBounds) -> Vec<(f64, f64)>;

    /// `(child, parent)`: the child is fitted as the ratio child/parent (ks/kc), so that an upper
    /// bound on the ratio is a box bound.
    const RATIO: Option<(usize, usize)> = None;

    /// τ(v) and ∂τ/∂p in one call. The default calls [`StaticFriction::torque_nm`] and
    /// [`StaticFriction::jacobian`]; the models override it to share the transcendental functions
    /// (tanh/sech² from one `expm1`, |v/vs|^α from one `ln` and one `exp`), which is most of the cost
    /// of an LM pass over 10⁶ samples. Must agree with the two separate calls (tested).
    #[inline]
    fn value_jacobian(&self, v: f64) -> (f64, Self::ParamVec) {
        (self.torque_nm(v), self.jacobian(v))
    }

    /// [`Fittable::value_jacobian`] for [`LANES`] velocities at once: `tau[l]` and `jac[k][l]`
    /// (`k <` [`StaticFriction::N_PARAMS`]; the other rows are left as they are). The default calls
    /// `value_jacobian` per lane; CV and SCV override it with branch-free lane loops over the
    /// vector-friendly [`exp_lanes`]/[`ln_lanes`], which LLVM turns into SIMD code (the scalar libm
    /// calls were ~60 % of an LM pass). Agrees with `value_jacobian` to a few ulp (tested).
    #[inline]
    fn value_jacobian_lanes(&self, v: &Lanes, tau: &mut Lanes, jac: &mut [Lanes; MAX_P]) {
        for l in 0..LANES {
            let (t, j) = self.value_jacobian(v[l]);
            tau[l] = t;
            for (k, jk) in j.as_ref().iter().enumerate() {
                jac[k][l] = *jk;
            }
        }
    }
}

/// Samples per group of the vectorised LM pass (two AVX2 registers of f64).
pub const LANES: usize = 8;

/// One value per lane of a sample group.
pub type Lanes = [f64; LANES];

/// `[f64; LANES]` whose lane `l` is the expression: one loop per operation, the shape LLVM reliably
/// turns into SIMD (a multi-statement loop body over lanes stayed scalar: measured 215 instructions
/// per sample in the SCV pass against 75 in this form).
macro_rules! lanes {
    (|$l:ident| $e:expr) => {{
        let mut o = [0.0f64; LANES];
        for $l in 0..LANES {
            o[$l] = $e;
        }
        o
    }};
}

/// tanh(ka·v) and ∂/∂ka = v·sech²(ka·v) per lane (finite ka), as [`tanh_dka`] but from
/// e^{−2|x|} − 1 instead of `expm1` (absolute error ~1e-16, which is what a least-squares sum sees).
#[inline(always)]
fn tanh_dka_lanes(ka: f64, v: &Lanes) -> (Lanes, Lanes) {
    let a = lanes!(|l| -2.0 * (ka * v[l]).abs());
    let e2 = exp_lanes(&a);
    let m = lanes!(|l| e2[l] - 1.0);
    let d = lanes!(|l| 2.0 + m[l]);
    let t = lanes!(|l| (-m[l] / d[l]).copysign(ka * v[l]));
    let d_ka = lanes!(|l| v[l] * 4.0 * e2[l] / (d[l] * d[l]));
    (t, d_ka)
}

/// tanh(ka·v) and ∂/∂ka = v·sech²(ka·v) from one `expm1` (accurate in the tails and near 0);
/// `ka = +∞` means sign(v) with derivative 0.
#[inline]
fn tanh_dka(ka: f64, v: f64) -> (f64, f64) {
    if ka == f64::INFINITY {
        let s = if v == 0.0 { 0.0 } else { v.signum() };
        return (s, 0.0);
    }
    let x = ka * v;
    let m = (-2.0 * x.abs()).exp_m1(); // e^{−2|x|} − 1 ∈ (−1, 0]
    let e2 = 1.0 + m;
    let t = (-m / (2.0 + m)).copysign(x);
    let d = 2.0 + m;
    (t, v * 4.0 * e2 / (d * d))
}

impl Fittable for CvParams {
    fn starts(v: &[f64], tau: &[f64]) -> Vec<Self> {
        let (kc, kv) = coulomb_viscous_guess(v, tau);
        [3.0, 20.0, 100.0]
            .iter()
            .map(|&ka| CvParams { kc, ka, kv })
            .collect()
    }

    fn bounds(b: &FitBounds) -> Vec<(f64, f64)> {
        vec![(P_MIN, P_MAX), (b.ka_min, b.ka_max), (P_MIN, P_MAX)]
    }

    #[inline]
    fn value_jacobian(&self, v: f64) -> (f64, [f64; 3]) {
        let (t, dt_dka) = tanh_dka(self.ka, v);
        (self.kc * t + self.kv * v, [t, self.kc * dt_dka, v])
    }

    #[inline]
    fn value_jacobian_lanes(&self, v: &Lanes, tau: &mut Lanes, jac: &mut [Lanes; MAX_P]) {
        if !self.ka.is_finite() {
            for l in 0..LANES {
                let (t, j) = self.value_jacobian(v[l]);
                tau[l] = t;
                for k in 0..3 {
                    jac[k][l] = j[k];
                }
            }
            return;
        }
        let (t, dt_dka) = tanh_dka_lanes(self.ka, v);
        *tau = lanes!(|l| self.kc * t[l] + self.kv * v[l]);
        jac[0] = t;
        jac[1] = lanes!(|l| self.kc * dt_dka[l]);
        jac[2] = *v;
    }
}

impl Fittable for ScvParams {
    fn starts(v: &[f64], tau: &[f64]) -> Vec<Self> {
        let (kc, kv) = coulomb_viscous_guess(v, tau);
        let mut out = Vec::new();
        for &ka in &[5.0, 30.0] {
            for &vs in &[0.05, 0.3, 2.0] {
                for &alpha in &[0.7, 1.5] {
                    out.push(ScvParams {
                        kc,
                        ka,
                        kv,
                        ks: 1.5 * kc,
                        vs,
                        alpha,
                    });
                }
            }
        }
        out
    }

    fn bounds(b: &FitBounds) -> Vec<(f64, f64)> {
        vec![
            (P_MIN, b.kc_max_nm),
            (b.ka_min, b.ka_max),
            (P_MIN, P_MAX),
            (P_MIN, b.ks_max_ratio),
            (b.vs_min, b.vs_max),
            (b.alpha_min, b.alpha_max),
        ]
    }

    const RATIO: Option<(usize, usize)> = Some((3, 0));

    #[inline]
    fn value_jacobian(&self, v: f64) -> (f64, [f64; 6]) {
        let (t, dt_dka) = tanh_dka(self.ka, v);
        let dks = self.ks - self.kc;
        // e = exp(−p), p = u^α = exp(α·ln u), u = |v|/vs; ∂e/∂vs = e·α·p/vs, ∂e/∂α = −e·p·ln u,
        // both exactly 0 where e·p = 0 (v = 0, or e underflowed), as in `ScvParams::jacobian`.
        let u = v.abs() / self.vs;
        let (e, de_dvs, de_dalpha) = if u == 0.0 {
            (1.0, 0.0, 0.0)
        } else {
            let lu = u.ln();
            let p = (self.alpha * lu).exp();
            let e = (-p).exp();
            let ep = e * p;
            if ep == 0.0 || !ep.is_finite() {
                (e, 0.0, 0.0)
            } else {
                (e, ep * self.alpha / self.vs, -ep * lu)
            }
        };
        let level = self.kc + dks * e;
        (
            self.kv * v + level * t,
            [
                t * (1.0 - e),
                level * dt_dka,
                v,
                e * t,
                dks * t * de_dvs,
                dks * t * de_dalpha,
            ],
        )
    }

    #[inline]
    fn value_jacobian_lanes(&self, v: &Lanes, tau: &mut Lanes, jac: &mut [Lanes; MAX_P]) {
        let vs_ok = self.vs > 0.0 && self.vs.is_finite();
        if !self.ka.is_finite() || !vs_ok {
            for l in 0..LANES {
                let (t, j) = self.value_jacobian(v[l]);
                tau[l] = t;
                for k in 0..6 {
                    jac[k][l] = j[k];
                }
            }
            return;
        }
        let (t, dt_dka) = tanh_dka_lanes(self.ka, v);
        let dks = self.ks - self.kc;
        // As `value_jacobian`: u = |v|/vs, p = exp(α·ln u), e = exp(−p); v = 0 lanes are computed on
        // a dummy u and then given e = 1 and zero derivatives.
        let u = lanes!(|l| (v[l].abs() / self.vs).max(f64::MIN_POSITIVE));
        let lu = ln_lanes(&u);
        let p = exp_lanes(&lanes!(|l| self.alpha * lu[l]));
        let e = exp_lanes(&lanes!(|l| -p[l]));
        let ep = lanes!(|l| e[l] * p[l]);
        // 1 where e·p carries a derivative (v ≠ 0, e·p ≠ 0 and finite), else 0.
        let live = lanes!(
            |l| if v[l] != 0.0 && ep[l] != 0.0 && ep[l].abs() < f64::INFINITY {
                1.0
            } else {
                0.0
            }
        );
        let e = lanes!(|l| if v[l] == 0.0 { 1.0 } else { e[l] });
        let de_dvs = lanes!(|l| if live[l] != 0.0 {
            ep[l] * self.alpha / self.vs
        } else {
            0.0
        });
        let de_dalpha = lanes!(|l| if live[l] != 0.0 { -ep[l] * lu[l] } else { 0.0 });
        let level = lanes!(|l| self.kc + dks * e[l]);
        *tau = lanes!(|l| self.kv * v[l] + level[l] * t[l]);
        jac[0] = lanes!(|l| t[l] * (1.0 - e[l]));
        jac[1] = lanes!(|l| level[l] * dt_dka[l]);
        jac[2] = *v;
        jac[3] = lanes!(|l| e[l] * t[l]);
        jac[4] = lanes!(|l| dks * t[l] * de_dvs[l]);
        jac[5] = lanes!(|l| dks * t[l] * de_dalpha[l]);
    }
}

impl Fittable for ScvCodeParams {
    fn starts(v: &[f64], tau: &[f64]) -> Vec<Self> {
        let (kc, kv) = coulomb_viscous_guess(v, tau);
        [0.02, 0.1, 0.5, 2.0]
            .iter()
            .map(|&vs| ScvCodeParams {
                fc: kc,
                fs: 1.5 * kc,
                fv: kv,
                vs,
            })
            .collect()
    }

    fn bounds(b: &FitBounds) -> Vec<(f64, f64)> {
        vec![
            (P_MIN, b.kc_max_nm),
            (P_MIN, b.ks_max_ratio),
            (P_MIN, P_MAX),
            (b.vs_min, b.vs_max),
        ]
    }

    const RATIO: Option<(usize, usize)> = Some((1, 0));
}

/// Fit coordinates z of a model: `ln p`, except `ln(p[child]/p[parent])` for [`Fittable::RATIO`].
fn to_z<M: Fittable>(m: &M) -> Vec<f64> {
    let p = m.params();
    let p = p.as_ref();
    let mut z: Vec<f64> = p.iter().map(|x| x.max(1e-300).ln()).collect();
    if let Some((c, q)) = M::RATIO {
        z[c] -= z[q];
    }
    z
}

/// The model at fit coordinates z (inverse of [`to_z`]; exponents clamped to ±40 for safety, wider
/// than any finite default bound).
fn from_z<M: Fittable>(z: &[f64]) -> M {
    let mut w = z.to_vec();
    if let Some((c, q)) = M::RATIO {
        w[c] += w[q];
    }
    let p: Vec<f64> = w.iter().map(|x| x.clamp(-40.0, 40.0).exp()).collect();
    with_params::<M>(&p)
}

/// The bounds as a box in z: (ln lo, ln hi).
fn z_box<M: Fittable>(b: &FitBounds) -> (Vec<f64>, Vec<f64>) {
    M::bounds(b).iter().map(|&(l, h)| (l.ln(), h.ln())).unzip()
}

fn project(z: &mut [f64], lo: &[f64], hi: &[f64]) {
    for ((x, &l), &h) in z.iter_mut().zip(lo).zip(hi) {
        *x = x.max(l).min(h);
    }
}

/// The model moved into the bounds (parent first, then the ratio child relative to it).
pub fn project_into_bounds<M: Fittable>(m: &M, b: &FitBounds) -> M {
    let (lo, hi) = z_box::<M>(b);
    let mut z = to_z(m);
    project(&mut z, &lo, &hi);
    from_z(&z)
}

/// Parameters of `m` on (within 1e-9 relative of) a bound, as `"name=min"`/`"name=max"`
/// (`"ks/kc=max"` for the ratio). The positivity floor/ceiling of kc, kv, ks are not listed.
pub fn active_bounds<M: Fittable>(m: &M, b: &FitBounds) -> Vec<String> {
    let z = to_z(m);
    let mut out = Vec::new();
    for (k, (&(l, h), &zk)) in M::bounds(b).iter().zip(&z).enumerate() {
        let name = match M::RATIO {
            Some((c, q)) if c == k => format!("{}/{}", M::PARAM_NAMES[c], M::PARAM_NAMES[q]),
            _ => M::PARAM_NAMES[k].to_string(),
        };
        if l > P_MIN && zk <= l.ln() + 1e-9 {
            out.push(format!("{name}=min"));
        }
        if h < P_MAX && zk >= h.ln() - 1e-9 {
            out.push(format!("{name}=max"));
        }
    }
    out
}

fn check_data(v: &[f64], tau: &[f64], name: &'static str, n_params: usize) -> Result<(), FitError> {
    if v.len() != tau.len() {
        return Err(FitError::Length {
            v: v.len(),
            tau: tau.len(),
        });
    }
    if let Some(index) = v
        .iter()
        .zip(tau)
        .position(|(a, b)| !a.is_finite() || !b.is_finite())
    {
        return Err(FitError::NonFinite {
            index,
            v: v[index],
            tau: tau[index],
        });
    }
    let need = 2 * n_params;
    if v.len() < need {
        return Err(FitError::TooFew {
            model: name,
            got: v.len(),
            need,
        });
    }
    Ok(())
}

/// Fits model `M` to samples `(v_rad_s, tau_nm)` (already selected, e.g. by
/// [`sliding_quadrant_mask`]).
pub fn fit<M: Fittable>(
    v_rad_s: &[f64],
    tau_nm: &[f64],
    opts: &FitOptions,
) -> Result<FitResult<M>, FitError> {
    fit_from_starts(v_rad_s, tau_nm, opts, &[])
}

/// [`fit`] that also tries `extra_starts` (besides [`Fittable::starts`]); each start is first moved
/// into the bounds.
pub fn fit_from_starts<M: Fittable>(
    v_rad_s: &[f64],
    tau_nm: &[f64],
    opts: &FitOptions,
    extra_starts: &[M],
) -> Result<FitResult<M>, FitError> {
    check_data(v_rad_s, tau_nm, M::NAME, M::N_PARAMS)?;
    opts.bounds.validate()?;
    let (lo, hi) = z_box::<M>(&opts.bounds);
    let starts: Vec<M> = M::starts(v_rad_s, tau_nm)
        .iter()
        .chain(extra_starts)
        .map(|s| project_into_bounds(s, &opts.bounds))
        .collect();
    let (model, iterations, last_pass) = match opts.method {
        Method::Lm => {
            // Coarse: each start on a strided subsample of ≤ 5 000 samples, 20 iterations.
            let stride = (v_rad_s.len() / 5_000).max(1);
            let vs: Vec<f64> = v_rad_s.iter().step_by(stride).copied().collect();
            let ts: Vec<f64> = tau_nm.iter().step_by(stride).copied().collect();
            let best = starts
                .par_iter()
                .map(|s| lm(s, &vs, &ts, 20, 1e-9, &lo, &hi))
                .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
                .map(|(m, _, _)| m)
                .unwrap_or(starts[0]);
            // Medium: ≤ 100 000 samples converge fully; the full-data pass then only polishes
            // (relative tolerance ≥ 1e-7: the subsample optimum is within the statistical error of
            // the full one, so 1–2 Gauss–Newton steps suffice and each costs a full data pass).
            let stride = (v_rad_s.len() / 100_000).max(1);
            let (best, polish_tol) = if stride > 1 {
                let vm: Vec<f64> = v_rad_s.iter().step_by(stride).copied().collect();
                let tm: Vec<f64> = tau_nm.iter().step_by(stride).copied().collect();
                (
                    lm(&best, &vm, &tm, opts.max_iter, opts.rel_tol, &lo, &hi).0,
                    opts.rel_tol.max(1e-7),
                )
            } else {
                (best, opts.rel_tol)
            };
            let (m, pass, it) = lm(&best, v_rad_s, tau_nm, opts.max_iter, polish_tol, &lo, &hi);
            (m, it, Some(pass))
        }
        Method::Adam => {
            let best = starts
                .iter()
                .map(|s| {
                    let m = adam(s, v_rad_s, tau_nm, opts);
                    let c = cost(&m, v_rad_s, tau_nm);
                    (m, c)
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(m, _)| m)
                .unwrap_or(starts[0]);
            (best, opts.adam_epochs, None)
        }
    };
    model.validate().map_err(|e| FitError::Domain {
        model: M::NAME,
        msg: e.to_string(),
    })?;
    // LM's last data pass already has Σr² and Σ|r| of the returned model (no extra pass).
    let (rmse_nm, mae_nm) = match last_pass {
        Some(p) => {
            let n = v_rad_s.len() as f64;
            ((2.0 * p.cost / n).sqrt(), p.abs_sum / n)
        }
        None => errors(&model, v_rad_s, tau_nm),
    };
    let at_bounds = active_bounds(&model, &opts.bounds);
    Ok(FitResult {
        model,
        rmse_nm,
        mae_nm,
        n_samples: v_rad_s.len(),
        iterations,
        at_bounds,
    })
}

/// RMSE and MAE of a model on samples [Nm].
pub fn errors<M: StaticFriction + Sync>(m: &M, v: &[f64], tau: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let (s2, s1) = v
        .par_iter()
        .zip(tau.par_iter())
        .map(|(&x, &y)| {
            let e = m.torque_nm(x) - y;
            (e * e, e.abs())
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = v.len() as f64;
    ((s2 / n).sqrt(), s1 / n)
}

fn cost<M: StaticFriction + Sync>(m: &M, v: &[f64], tau: &[f64]) -> f64 {
    let (r, _) = errors(m, v, tau);
    r * r * v.len() as f64 * 0.5
}

/// Samples per parallel chunk of an LM pass. Fixed, and the chunk sums are added in chunk order, so a
/// pass gives the same bits whatever the thread count or scheduling.
const PASS_CHUNK: usize = 4096;

/// Sums of one LM data pass, in fit coordinates z ([`to_z`]).
#[derive(Clone, Copy, Debug)]
struct Pass {
    /// ½Σr² [Nm²].
    cost: f64,
    /// Σ|r| [Nm].
    abs_sum: f64,
    /// JᵀJ, row-major P×P, upper triangle filled.
    jtj: [f64; MAX_P * MAX_P],
    /// Jᵀr.
    jtr: [f64; MAX_P],
}

impl Pass {
    const ZERO: Pass = Pass {
        cost: 0.0,
        abs_sum: 0.0,
        jtj: [0.0; MAX_P * MAX_P],
        jtr: [0.0; MAX_P],
    };

    fn add(&mut self, o: &Pass) {
        self.cost += o.cost;
        self.abs_sum += o.abs_sum;
        for (a, b) in self.jtj.iter_mut().zip(&o.jtj) {
            *a += b;
        }
        for (a, b) in self.jtr.iter_mut().zip(&o.jtr) {
            *a += b;
        }
    }
}

/// Lane-wise accumulators of one chunk: packed upper triangle of JᵀJ, Jᵀr, ½r², |r|.
struct LaneSums {
    jtj: [Lanes; MAX_P * (MAX_P + 1) / 2],
    jtr: [Lanes; MAX_P],
    cost: Lanes,
    abs: Lanes,
}

impl LaneSums {
    /// Adds one group of LANES samples; `mask[l] = 0` removes lane l (padding of the last group).
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // indexed lane loops: the shape LLVM vectorises
    fn add_group<M: Fittable>(
        &mut self,
        m: &M,
        p: &[f64; MAX_P],
        v: &Lanes,
        y: &Lanes,
        mask: Option<&Lanes>,
    ) {
        let np = M::N_PARAMS;
        let mut t = [0.0; LANES];
        let mut j = [[0.0; LANES]; MAX_P];
        m.value_jacobian_lanes(v, &mut t, &mut j);
        let mut r = [0.0; LANES];
        for l in 0..LANES {
            r[l] = t[l] - y[l];
        }
        if let Some(w) = mask {
            for l in 0..LANES {
                r[l] *= w[l];
            }
        }
        for k in 0..np {
            // Chain rule for p = exp(u): ∂τ/∂u = ∂τ/∂p · p.
            let pk = p[k];
            for jl in &mut j[k] {
                *jl *= pk;
            }
            if let Some(w) = mask {
                for (jl, wl) in j[k].iter_mut().zip(w) {
                    *jl *= wl;
                }
            }
        }
        if let Some((c, q)) = M::RATIO {
            // p_c = exp(z_q + z_c): z_q moves both the parent and the child.
            for l in 0..LANES {
                j[q][l] += j[c][l];
            }
        }
        for l in 0..LANES {
            self.cost[l] += 0.5 * r[l] * r[l];
            self.abs[l] += r[l].abs();
        }
        let mut idx = 0;
        for a in 0..np {
            for l in 0..LANES {
                self.jtr[a][l] += j[a][l] * r[l];
            }
            for b in a..np {
                for l in 0..LANES {
                    self.jtj[idx][l] += j[a][l] * j[b][l];
                }
                idx += 1;
            }
        }
    }
}

/// One chunk of an LM pass: groups of LANES samples through [`Fittable::value_jacobian_lanes`], the
/// last group padded and masked; lanes summed in a fixed order at the end.
fn pass_chunk<M: Fittable>(m: &M, p: &[f64; MAX_P], v: &[f64], y: &[f64]) -> Pass {
    let np = M::N_PARAMS;
    let mut acc = LaneSums {
        jtj: [[0.0; LANES]; MAX_P * (MAX_P + 1) / 2],
        jtr: [[0.0; LANES]; MAX_P],
        cost: [0.0; LANES],
        abs: [0.0; LANES],
    };
    let (vg, yg) = (v.chunks_exact(LANES), y.chunks_exact(LANES));
    let (vr, yr) = (vg.remainder(), yg.remainder());
    for (vc, yc) in vg.zip(yg) {
        let vc: &Lanes = vc.try_into().expect("chunks_exact gives LANES values");
        let yc: &Lanes = yc.try_into().expect("chunks_exact gives LANES values");
        acc.add_group(m, p, vc, yc, None);
    }
    if !vr.is_empty() {
        let (mut vp, mut yp, mut w) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
        vp[..vr.len()].copy_from_slice(vr);
        yp[..yr.len()].copy_from_slice(yr);
        w[..vr.len()].fill(1.0);
        acc.add_group(m, p, &vp, &yp, Some(&w));
    }
    let sum = |x: &Lanes| x.iter().sum::<f64>();
    let mut out = Pass::ZERO;
    out.cost = sum(&acc.cost);
    out.abs_sum = sum(&acc.abs);
    let mut idx = 0;
    for a in 0..np {
        out.jtr[a] = sum(&acc.jtr[a]);
        for b in a..np {
            out.jtj[a * MAX_P + b] = sum(&acc.jtj[idx]);
            idx += 1;
        }
    }
    out
}

/// Cost ½Σr², Σ|r|, and in fit coordinates z ([`to_z`]): JᵀJ (row-major P×P) and Jᵀr, in one
/// parallel, deterministic pass.
fn normal_equations<M: Fittable>(m: &M, v: &[f64], tau: &[f64]) -> Pass {
    let mut p = [0.0; MAX_P];
    p[..M::N_PARAMS].copy_from_slice(m.params().as_ref());
    let chunks: Vec<Pass> = v
        .par_chunks(PASS_CHUNK)
        .zip(tau.par_chunks(PASS_CHUNK))
        .map(|(vc, tc)| pass_chunk(m, &p, vc, tc))
        .collect();
    let mut total = Pass::ZERO;
    for c in &chunks {
        total.add(c);
    }
    total
}

fn with_params<M: StaticFriction>(p: &[f64]) -> M {
    let mut pv = M::ParamVec::default();
    pv.as_mut().copy_from_slice(p);
    M::from_params_unchecked(&pv)
}

/// Projected Levenberg–Marquardt in fit coordinates z within the box `[lo, hi]`; returns (model,
/// its data pass (cost, Σ|r|, …), accepted iterations).
fn lm<M: Fittable>(
    start: &M,
    v: &[f64],
    tau: &[f64],
    max_iter: usize,
    rel_tol: f64,
    lo: &[f64],
    hi: &[f64],
) -> (M, Pass, usize) {
    let np = M::N_PARAMS;
    let mut z = to_z(start);
    project(&mut z, lo, hi);
    let mut m: M = from_z(&z);
    let mut pass = normal_equations(&m, v, tau);
    let (mut c, mut jtj, mut jtr) = (pass.cost, pass.jtj, pass.jtr);
    let mut lambda = 1e-3;
    let mut iters = 0;
    for _ in 0..max_iter {
        let a = DMatrix::from_fn(np, np, |i, j| {
            let (lo, hi) = if i <= j { (i, j) } else { (j, i) };
            jtj[lo * MAX_P + hi]
        });
        let g = DVector::from_fn(np, |i, _| -jtr[i]);
        // Active set: a coordinate on a bound whose descent direction points out of the box is held.
        let free: Vec<bool> = (0..np)
            .map(|i| !((z[i] <= lo[i] && g[i] < 0.0) || (z[i] >= hi[i] && g[i] > 0.0)))
            .collect();
        if !free.iter().any(|&f| f) {
            break;
        }
        let gf = DVector::from_fn(np, |i, _| if free[i] { g[i] } else { 0.0 });
        let mut improved = false;
        while lambda < 1e12 {
            let mut aa = a.clone();
            for i in 0..np {
                if free[i] {
                    // Marquardt scaling, with a floor so a parameter with no influence stays put.
                    aa[(i, i)] += lambda * a[(i, i)].max(1e-12);
                } else {
                    for k in 0..np {
                        aa[(i, k)] = 0.0;
                        aa[(k, i)] = 0.0;
                    }
                    aa[(i, i)] = 1.0;
                }
            }
            let Some(chol) = aa.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let du = chol.solve(&gf);
            let mut zn: Vec<f64> = z.iter().zip(du.iter()).map(|(a, b)| a + b).collect();
            project(&mut zn, lo, hi);
            let d = DVector::from_fn(np, |i, _| zn[i] - z[i]);
            // Decrease predicted by the Gauss–Newton model for the projected step,
            // −(Jᵀr)ᵀ·d − ½·dᵀ·JᵀJ·d: when even that is below rel_tol·c the step cannot matter — stop
            // without another data pass (near the optimum, rejected steps would otherwise cost a full
            // pass each while λ grows). A projected step the model says cannot decrease the cost is
            // shortened (λ up) without a data pass.
            let ad = &a * &d;
            let predicted = g.dot(&d) - 0.5 * d.dot(&ad);
            if predicted.is_finite() && predicted >= 0.0 && predicted < rel_tol * c {
                return (m, pass, iters);
            }
            if d.iter().all(|x| *x == 0.0) || (predicted.is_finite() && predicted < 0.0) {
                lambda *= 4.0;
                continue;
            }
            let mn: M = from_z(&zn);
            let pass_n = normal_equations(&mn, v, tau);
            let (cn, jtjn, jtrn) = (pass_n.cost, pass_n.jtj, pass_n.jtr);
            if cn.is_finite() && cn < c {
                let rel = (c - cn) / c.max(1e-300);
                z = zn;
                m = mn;
                c = cn;
                jtj = jtjn;
                jtr = jtrn;
                pass = pass_n;
                lambda = (lambda / 3.0).max(1e-12);
                improved = true;
                iters += 1;
                if rel < rel_tol {
                    return (m, pass, iters);
                }
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (m, pass, iters)
}

fn softplus(x: f64) -> f64 {
    if x > 30.0 { x } else { x.exp().ln_1p() }
}

fn softplus_inv(y: f64) -> f64 {
    let y = y.max(1e-8);
    if y > 30.0 { y } else { y.exp_m1().ln() }
}

/// Full-batch Adam on softplus parameters (β = 0.9, 0.999, ε = 1e-8), projected onto the bounds
/// after each step.
fn adam<M: Fittable>(start: &M, v: &[f64], tau: &[f64], opts: &FitOptions) -> M {
    let np = M::N_PARAMS;
    let mut u: Vec<f64> = start
        .params()
        .as_ref()
        .iter()
        .map(|&p| softplus_inv(p))
        .collect();
    let (mut m1, mut m2) = (vec![0.0; np], vec![0.0; np]);
    let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8);
    let n = v.len() as f64;
    let l1 = opts.adam_loss == Loss::L1;
    for t in 1..=opts.adam_epochs {
        let p: Vec<f64> = u.iter().map(|&x| softplus(x)).collect();
        let m = with_params::<M>(&p);
        let grad_p = v
            .par_chunks(4096)
            .zip(tau.par_chunks(4096))
            .map(|(vc, tc)| {
                let mut g = [0.0; MAX_P];
                for (&x, &y) in vc.iter().zip(tc) {
                    let (tau, j) = m.value_jacobian(x);
                    let r = tau - y;
                    let w = if l1 { r.signum() } else { 2.0 * r };
                    for (gk, jk) in g.iter_mut().zip(j.as_ref()) {
                        *gk += w * jk;
                    }
                }
                g
            })
            .reduce(
                || [0.0; MAX_P],
                |mut a, b| {
                    for k in 0..MAX_P {
                        a[k] += b[k];
                    }
                    a
                },
            );
        for k in 0..np {
            // d softplus(u)/du = sigmoid(u).
            let g = grad_p[k] / n / (1.0 + (-u[k]).exp());
            m1[k] = b1 * m1[k] + (1.0 - b1) * g;
            m2[k] = b2 * m2[k] + (1.0 - b2) * g * g;
            let mh = m1[k] / (1.0 - b1.powi(t as i32));
            let vh = m2[k] / (1.0 - b2.powi(t as i32));
            u[k] -= opts.adam_lr * mh / (vh.sqrt() + eps);
        }
        // Keep the iterate inside the bounds (write back only what the projection moved).
        let p: Vec<f64> = u.iter().map(|&x| softplus(x)).collect();
        let pb = project_into_bounds(&with_params::<M>(&p), &opts.bounds).params();
        for k in 0..np {
            if (pb.as_ref()[k] - p[k]).abs() > 1e-12 * p[k].abs() {
                u[k] = softplus_inv(pb.as_ref()[k]);
            }
        }
    }
    let p: Vec<f64> = u.iter().map(|&x| softplus(x)).collect();
    with_params::<M>(&p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sliding_mask_selects_first_and_third_quadrant_above_threshold() {
        let v = [0.5, -0.5, 0.5, -0.5, 0.01, -0.02, 0.031, 0.0];
        let t = [1.0, -1.0, -1.0, 1.0, 1.0, -1.0, 0.1, 1.0];
        let m = sliding_quadrant_mask(&v, &t, 0.03);
        assert_eq!(m, [true, true, false, false, false, false, true, false]);
        assert_eq!(select(&v, &m), [0.5, -0.5, 0.031]);
    }

    fn agree<M: Fittable>(m: &M) {
        for &v in &[
            0.0, 1e-12, -1e-9, 1e-4, -0.003, 0.02, -0.1, 0.5, -1.3, 4.0, -30.0, 1e3, -1e6,
        ] {
            let (t, j) = m.value_jacobian(v);
            let (t0, j0) = (m.torque_nm(v), m.jacobian(v));
            assert!(
                (t - t0).abs() <= 1e-12 * (1.0 + t0.abs()),
                "{} at v = {v}: {t} vs {t0}",
                M::NAME
            );
            for (k, (a, b)) in j.as_ref().iter().zip(j0.as_ref()).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-10 * (1.0 + b.abs()),
                    "{} d/d{} at v = {v}: {a} vs {b}",
                    M::NAME,
                    M::PARAM_NAMES[k]
                );
            }
        }
    }

    #[test]
    fn fused_value_jacobian_matches_the_model() {
        use frictionless::friction::paper;
        agree(&paper::CV_KNEE);
        agree(&paper::CV_ANKLE_ROLL);
        agree(&paper::SCV_KNEE);
        agree(&paper::SCV_ANKLE_ROLL);
        agree(&ScvParams {
            ka: f64::INFINITY,
            ..paper::SCV_KNEE
        });
        agree(&ScvCodeParams {
            fc: 1.0,
            fs: 3.0,
            fv: 0.5,
            vs: 0.1,
        });
    }

    fn lanes_agree<M: Fittable>(m: &M) {
        let vs = [
            0.0, 1e-12, -1e-9, 1e-4, -0.003, 0.02, -0.1, 0.5, -1.3, 4.0, -30.0, 1e3, -1e6, 0.07,
            -0.0, 2e-5,
        ];
        for g in vs.chunks_exact(LANES) {
            let g: &Lanes = g.try_into().unwrap();
            let mut t = [0.0; LANES];
            let mut j = [[f64::NAN; LANES]; MAX_P];
            m.value_jacobian_lanes(g, &mut t, &mut j);
            for l in 0..LANES {
                let (t0, j0) = m.value_jacobian(g[l]);
                assert!(
                    (t[l] - t0).abs() <= 1e-13 * (1.0 + t0.abs()),
                    "{} at v = {}: {} vs {t0}",
                    M::NAME,
                    g[l],
                    t[l]
                );
                for (k, b) in j0.as_ref().iter().enumerate() {
                    assert!(
                        (j[k][l] - b).abs() <= 1e-12 * (1.0 + b.abs()),
                        "{} d/d{} at v = {}: {} vs {b}",
                        M::NAME,
                        M::PARAM_NAMES[k],
                        g[l],
                        j[k][l]
                    );
                }
            }
        }
    }

    #[test]
    fn lane_value_jacobian_matches_the_scalar_one() {
        use frictionless::friction::paper;
        lanes_agree(&paper::CV_KNEE);
        lanes_agree(&paper::CV_ANKLE_ROLL);
        lanes_agree(&paper::SCV_KNEE);
        lanes_agree(&paper::SCV_ANKLE_ROLL);
        lanes_agree(&ScvParams {
            ka: f64::INFINITY,
            ..paper::SCV_KNEE
        });
        lanes_agree(&ScvParams {
            alpha: 0.3,
            vs: 1e-3,
            ..paper::SCV_ANKLE_ROLL
        });
        lanes_agree(&ScvCodeParams {
            fc: 1.0,
            fs: 3.0,
            fv: 0.5,
            vs: 0.1,
        });
    }

    /// The scalar definition of one LM pass (libm, sequential).
    #[allow(clippy::needless_range_loop)]
    fn pass_scalar<M: Fittable>(m: &M, v: &[f64], tau: &[f64]) -> Pass {
        let np = M::N_PARAMS;
        let p = m.params();
        let mut out = Pass::ZERO;
        for (&x, &y) in v.iter().zip(tau) {
            let (t, jp) = m.value_jacobian(x);
            let r = t - y;
            let mut j = [0.0; MAX_P];
            for k in 0..np {
                j[k] = jp.as_ref()[k] * p.as_ref()[k];
            }
            if let Some((c, q)) = M::RATIO {
                j[q] += j[c];
            }
            out.cost += 0.5 * r * r;
            out.abs_sum += r.abs();
            for a in 0..np {
                out.jtr[a] += j[a] * r;
                for b in a..np {
                    out.jtj[a * MAX_P + b] += j[a] * j[b];
                }
            }
        }
        out
    }

    fn pass_agrees<M: Fittable>(m: &M, n: usize) {
        let mut s = 7u64;
        let mut u = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let v: Vec<f64> = (0..n).map(|_| (u() - 0.5) * 3.0).collect();
        let tau: Vec<f64> = v
            .iter()
            .map(|&x| m.torque_nm(x) + (u() - 0.5) * 0.2)
            .collect();
        // A model away from the data's optimum, so residuals and gradients are not tiny.
        let mut q = m.params();
        for x in q.as_mut() {
            *x *= 1.1;
        }
        let m = with_params::<M>(q.as_ref());
        let want = pass_scalar(&m, &v, &tau);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| normal_equations(&m, &v, &tau))
        };
        let (one, three) = (run(1), run(3));
        let close = |a: f64, b: f64, what: &str| {
            assert!(
                (a - b).abs() <= 1e-11 * b.abs().max(1e-300),
                "{} n = {n} {what}: {a} vs {b}",
                M::NAME
            )
        };
        close(one.cost, want.cost, "cost");
        close(one.abs_sum, want.abs_sum, "abs");
        for k in 0..MAX_P {
            close(one.jtr[k], want.jtr[k], "Jtr");
        }
        for a in 0..M::N_PARAMS {
            for b in a..M::N_PARAMS {
                close(one.jtj[a * MAX_P + b], want.jtj[a * MAX_P + b], "JtJ");
            }
        }
        // Deterministic: identical bits on 1 and 3 threads.
        assert_eq!(one.cost.to_bits(), three.cost.to_bits());
        assert_eq!(one.jtj.map(f64::to_bits), three.jtj.map(f64::to_bits));
        assert_eq!(one.jtr.map(f64::to_bits), three.jtr.map(f64::to_bits));
    }

    #[test]
    fn lane_pass_matches_the_scalar_sums_and_is_deterministic() {
        use frictionless::friction::paper;
        // Lengths: fewer than one group, a partial last group, several chunks with a partial one.
        for n in [5, 8 * 37 + 3, PASS_CHUNK * 3 + 11] {
            pass_agrees(&paper::CV_ANKLE_ROLL, n);
            pass_agrees(&paper::SCV_ANKLE_ROLL, n);
            pass_agrees(
                &ScvCodeParams {
                    fc: 1.0,
                    fs: 3.0,
                    fv: 0.5,
                    vs: 0.1,
                },
                n,
            );
        }
    }

    #[test]
    fn bad_data_is_an_error() {
        let o = FitOptions::default();
        assert!(matches!(
            fit::<CvParams>(&[1.0, 2.0], &[1.0], &o),
            Err(FitError::Length { v: 2, tau: 1 })
        ));
        assert!(matches!(
            fit::<CvParams>(&[1.0; 3], &[1.0; 3], &o),
            Err(FitError::TooFew {
                got: 3,
                need: 6,
                ..
            })
        ));
        assert!(matches!(
            fit::<CvParams>(&[1.0, f64::NAN, 1.0, 1.0, 1.0, 1.0], &[1.0; 6], &o),
            Err(FitError::NonFinite { index: 1, .. })
        ));
    }
}
