//! The SCV fit `frictl fit scv` runs: bounds from the data, the low-speed rows in, several starts, and
//! a guard that makes the SCV the CV (`ks = kc`) when it is not better on a held-out time block.
//!
//! What it is: [`fit_scv_guarded`]. The rows are given in time order with two selections: the rows the
//! SCV fits (the sliding quadrants down to a low standstill threshold, so the Stribeck region below
//! the CV's `--v-min` is fitted, not extrapolated) and the rows the CV fits (the CV's own selection).
//! The last [`ScvFitInput::validation_fraction`] of the rows is a validation block: both models are
//! fitted on the rows before it and scored on all of its rows. The SCV is kept only when its RMSE
//! there is lower than the CV's; otherwise (and when the data has too few low-speed rows to show a
//! Stribeck hump) the result is the CV fitted on all its rows with `ks = kc`, which evaluates exactly
//! as that CV, and the reason is returned. The kept SCV is refitted on all its rows.
//!
//! Bounds derived from the data ([`data_bounds`]), inside the caller's [`FitBounds`]: `vs` within the
//! velocity range of the fitted rows, `ka` from the velocity scale (tanh(ka·v) saturates between the
//! 1st and the 99th percentile of |ṡ|), `kc` at most twice the larger of the CV's kc and the 95th
//! percentile of |τ_F| at low speed, `ks/kc` at most 4 × the 99th percentile of |τ_F| at low speed
//! over the CV's kc (the SCV's kc lies below the CV's, which averages the hump in). The model fitted is the model that runs (`ScvParams::torque_nm`, the smooth sign
//! tanh(ka·ṡ)).
//!
//! What it is not: a fit of the SCV code form or LuGre (those use [`crate::fit::fit`] directly).

use crate::fit::{FitBounds, FitError, FitOptions, FitResult, errors, fit, fit_from_starts};
use frictionless::friction::{CvParams, ScvParams};
use serde::{Deserialize, Serialize};

/// Fewest rows below the low-speed threshold for the Stribeck term to be fitted (also at least
/// [`MIN_LOW_SPEED_SHARE`] of the SCV's rows).
pub const MIN_LOW_SPEED_ROWS: usize = 50;
/// Smallest share of the SCV's rows below the low-speed threshold.
pub const MIN_LOW_SPEED_SHARE: f64 = 0.005;

/// What [`fit_scv_guarded`] fits.
#[derive(Clone, Copy, Debug)]
pub struct ScvFitInput<'a> {
    /// ṡ of every row the fit may use, in time order [rad/s].
    pub v_rad_s: &'a [f64],
    /// τ_F of those rows [Nm].
    pub tau_nm: &'a [f64],
    /// The rows the SCV fits.
    pub scv_rows: &'a [bool],
    /// The rows the CV fits (its own selection, e.g. `|ṡ| > --v-min`).
    pub cv_rows: &'a [bool],
    /// Below this |ṡ| a row is a low-speed (Stribeck region) row [rad/s].
    pub low_speed_rad_s: f64,
    /// Share of the rows, at their end, held out as the validation block (0 < x < 1).
    pub validation_fraction: f64,
}

/// The validation block's scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScvValidation {
    /// Rows in the block (all rows of the input past the split).
    pub rows: usize,
    /// The SCV fitted before the block: its RMSE on the block [Nm] (`None`: not fitted).
    pub scv_rmse_nm: Option<f64>,
    /// The CV fitted before the block: its RMSE on the block [Nm].
    pub cv_rmse_nm: f64,
    /// SCV rows below the low-speed threshold (all rows).
    pub low_speed_rows: usize,
    /// The low-speed threshold [rad/s].
    pub low_speed_rad_s: f64,
}

/// The outcome of [`fit_scv_guarded`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScvFit {
    /// The SCV (with `ks = kc` when it fell back to the CV).
    pub result: FitResult<ScvParams>,
    /// The CV fitted on all its rows.
    pub cv: FitResult<CvParams>,
    /// The bounds the SCV was fitted within (the caller's, narrowed by the data).
    pub bounds: FitBounds,
    /// The validation block.
    pub validation: ScvValidation,
    /// Why the SCV is the CV (`None`: the SCV was better on the validation block).
    pub fallback: Option<String>,
}

/// The `q` quantile (0..=1) of `x` (nearest rank; NaN for no values).
fn quantile(mut x: Vec<f64>, q: f64) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    x.sort_by(f64::total_cmp);
    let k = ((x.len() - 1) as f64 * q).round() as usize;
    x[k.min(x.len() - 1)]
}

/// `[lo, hi]` narrowed to `[a, b]` where that leaves a non-empty range; otherwise `[lo, hi]`.
fn narrow(lo: f64, hi: f64, a: f64, b: f64) -> (f64, f64) {
    let (l, h) = (lo.max(a), hi.min(b));
    if l.is_finite() && h.is_finite() && l > 0.0 && l <= h {
        (l, h)
    } else {
        (lo, hi)
    }
}

/// The SCV's bounds for samples `(v, tau)` (the SCV's rows), inside `user`: see the module docs.
/// `kc_cv` is the CV's Coulomb level on the same data; returns the bounds and the kc bound [Nm]
/// (`FitBounds::kc_max_nm` is left as the caller's).
pub fn data_bounds(
    v: &[f64],
    tau: &[f64],
    low_speed_rad_s: f64,
    kc_cv: f64,
    user: &FitBounds,
) -> (FitBounds, f64) {
    let speed: Vec<f64> = v.iter().map(|x| x.abs()).filter(|x| *x > 0.0).collect();
    let v_lo = quantile(speed.clone(), 0.01);
    let v_hi = quantile(speed, 0.99);
    let low: Vec<f64> = v
        .iter()
        .zip(tau)
        .filter(|(x, _)| x.abs() < low_speed_rad_s)
        .map(|(_, t)| t.abs())
        .collect();
    let t95 = quantile(low.clone(), 0.95);
    let t99 = quantile(low, 0.99);
    let mut b = *user;
    (b.vs_min, b.vs_max) = narrow(user.vs_min, user.vs_max, v_lo, v_hi);
    (b.ka_min, b.ka_max) = narrow(user.ka_min, user.ka_max, 0.5 / v_hi, 2.0 / v_lo);
    if t99.is_finite() && kc_cv > 0.0 {
        b.ks_max_ratio = user.ks_max_ratio.min((4.0 * t99 / kc_cv).max(1.0));
    }
    let kc_max = if t95.is_finite() {
        2.0 * kc_cv.max(t95)
    } else {
        2.0 * kc_cv
    };
    (b, kc_max)
}

/// The rows of `x` where `m` is true among the first `end` rows.
fn take(x: &[f64], m: &[bool], end: usize) -> Vec<f64> {
    x[..end]
        .iter()
        .zip(&m[..end])
        .filter_map(|(&a, &k)| k.then_some(a))
        .collect()
}

/// The CV as an SCV: `ks = kc`, so the Stribeck term is exactly 0 (vs, α are then immaterial: 1).
pub fn scv_of_cv(c: &CvParams) -> ScvParams {
    ScvParams {
        kc: c.kc,
        ka: c.ka,
        kv: c.kv,
        ks: c.kc,
        vs: 1.0,
        alpha: 1.0,
    }
}

/// Data-derived SCV starts: the CV's kc, ka, kv with ks/kc ∈ {1.2, 2, 3}, vs on a geometric grid of
/// the bounds and α ∈ {0.7, 1.5}.
fn starts(cv: &CvParams, b: &FitBounds) -> Vec<ScvParams> {
    let mut out = Vec::new();
    let r = (b.vs_max / b.vs_min).max(1.0);
    for ratio in [1.2, 2.0, 3.0] {
        for f in [0.1, 0.4, 0.8] {
            for alpha in [0.7, 1.5] {
                out.push(ScvParams {
                    kc: cv.kc,
                    ka: cv.ka,
                    kv: cv.kv,
                    ks: ratio * cv.kc,
                    vs: b.vs_min * r.powf(f),
                    alpha,
                });
            }
        }
    }
    out
}

/// Fits the SCV as the module docs say.
///
/// # Errors
/// [`FitError`] of the CV or SCV fits (too few rows, non-finite samples, bad bounds), or
/// [`FitError::Length`] when the selections do not match the rows.
pub fn fit_scv_guarded(input: &ScvFitInput, opts: &FitOptions) -> Result<ScvFit, FitError> {
    let n = input.v_rad_s.len();
    for m in [
        input.scv_rows.len(),
        input.cv_rows.len(),
        input.tau_nm.len(),
    ] {
        if m != n {
            return Err(FitError::Length { v: n, tau: m });
        }
    }
    if !(input.validation_fraction > 0.0 && input.validation_fraction < 1.0) {
        return Err(FitError::Bounds(format!(
            "validation fraction {} (need 0 < x < 1)",
            input.validation_fraction
        )));
    }
    let (v, t) = (input.v_rad_s, input.tau_nm);
    let split = ((n as f64) * (1.0 - input.validation_fraction)).round() as usize;
    let cv_all = fit::<CvParams>(&take(v, input.cv_rows, n), &take(t, input.cv_rows, n), opts)?;
    let (sv, st) = (take(v, input.scv_rows, n), take(t, input.scv_rows, n));
    let (v_val, t_val) = (&v[split..], &t[split..]);
    let cv_train = fit::<CvParams>(
        &take(v, input.cv_rows, split),
        &take(t, input.cv_rows, split),
        opts,
    )?;
    let (cv_val, _) = errors(&cv_train.model, v_val, t_val);
    let low_speed_rows = sv
        .iter()
        .filter(|x| x.abs() < input.low_speed_rad_s)
        .count();
    let mut validation = ScvValidation {
        rows: n - split,
        scv_rmse_nm: None,
        cv_rmse_nm: cv_val,
        low_speed_rows,
        low_speed_rad_s: input.low_speed_rad_s,
    };
    let (mut bounds, kc_max) = data_bounds(
        &sv,
        &st,
        input.low_speed_rad_s,
        cv_all.model.kc,
        &opts.bounds,
    );
    let fallback = |reason: String, validation: ScvValidation, bounds: FitBounds| ScvFit {
        result: FitResult {
            model: scv_of_cv(&cv_all.model),
            rmse_nm: cv_all.rmse_nm,
            mae_nm: cv_all.mae_nm,
            n_samples: cv_all.n_samples,
            iterations: cv_all.iterations,
            at_bounds: cv_all.at_bounds.clone(),
        },
        cv: cv_all.clone(),
        bounds,
        validation,
        fallback: Some(reason),
    };
    let need = MIN_LOW_SPEED_ROWS.max((MIN_LOW_SPEED_SHARE * sv.len() as f64).ceil() as usize);
    if low_speed_rows < need {
        return Ok(fallback(
            format!(
                "no Stribeck region in the data: {low_speed_rows} of {} SCV rows below |ṡ| = {} rad/s (need {need}); SCV = CV (ks = kc)",
                sv.len(),
                input.low_speed_rad_s
            ),
            validation,
            opts.bounds,
        ));
    }
    if kc_max.is_finite() && kc_max > 0.0 {
        bounds.kc_max_nm = bounds.kc_max_nm.min(kc_max);
    }
    let o = FitOptions { bounds, ..*opts };
    let train = fit_from_starts::<ScvParams>(
        &take(v, input.scv_rows, split),
        &take(t, input.scv_rows, split),
        &o,
        &starts(&cv_train.model, &bounds),
    )?;
    let (scv_val, _) = errors(&train.model, v_val, t_val);
    validation.scv_rmse_nm = Some(scv_val);
    // NaN on either side falls back too.
    if scv_val.partial_cmp(&cv_val) != Some(std::cmp::Ordering::Less) {
        return Ok(fallback(
            format!(
                "the SCV is not better than the CV on the validation block (last {} rows): RMSE {scv_val:.4} Nm vs {cv_val:.4} Nm; SCV = CV (ks = kc)",
                n - split
            ),
            validation,
            bounds,
        ));
    }
    let mut extra = starts(&cv_all.model, &bounds);
    extra.push(train.model);
    let result = fit_from_starts::<ScvParams>(&sv, &st, &o, &extra)?;
    Ok(ScvFit {
        result,
        cv: cv_all,
        bounds,
        validation,
        fallback: None,
    })
}
