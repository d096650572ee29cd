//! Identification of the LuGre model (Stribeck curve, bristle stiffness σ0 and damping σ1) from a
//! friction time series.
//!
//! What it is: [`fit_lugre`] in three stages over a [`LugreSeries`] (velocity, friction target,
//! segment ids, which rows enter the cost):
//! 1. the Stribeck curve (kc, kv = σ2, ks, vs, α) from the steady sliding rows alone, by the static
//!    SCV fit ([`crate::fit::fit`]; its smooth sign's ka is dropped: the bristle state replaces it);
//! 2. σ0 and σ1 with the curve held: the bristle state z is simulated over every segment with the
//!    core's one LuGre implementation ([`frictionless::lugre::LugreEstimator`], exact exponential
//!    step at the series' `dt_s`, z = 0 at each segment start) and the RMSE of its τ̂_F against the
//!    target on the cost rows is minimised (pre-sliding and velocity reversals carry σ0 and σ1);
//! 3. optionally, all seven parameters together from stage 2's result.
//!
//! Rows of a segment enter the cost only after the joint has travelled `warmup_travel_rad` from the
//! segment's start: the simulated z starts at 0, the plant's does not.
//!
//! The minimiser is a Nelder–Mead simplex on log-parameters inside a box, written here (≈ 60
//! lines) rather than taken from a crate: the cost is a sequential simulation with no analytic
//! gradient, there are 2 or 7 parameters, and the workspace has no optimisation crate to reuse (the
//! static fits' LM in [`crate::fit`] needs a per-sample Jacobian of a static model).
//!
//! What it is not: a fit of the simulator's extras (ripple, temperature, load-dependent Coulomb):
//! those stay in the residual.

use crate::fit::{FitError, FitOptions, FitResult, fit};
use frictionless::friction::{ScvParams, StaticFriction};
use frictionless::lugre::{LugreEstimator, LugreParams};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A friction time series: rows at a fixed step, in segments (the bristle state restarts at 0 at the
/// start of each).
#[derive(Clone, Copy, Debug)]
pub struct LugreSeries<'a> {
    /// Joint velocity per row [rad/s].
    pub v_rad_s: &'a [f64],
    /// Friction target per row [Nm].
    pub tau_nm: &'a [f64],
    /// Segment id per row: a new segment starts where the id changes.
    pub segment: &'a [u32],
    /// Rows that may enter the cost (valid, not held out).
    pub use_row: &'a [bool],
    /// Steady sliding rows for stage 1 (e.g. [`crate::fit::sliding_quadrant_mask`] within `use_row`).
    pub sliding: &'a [bool],
    /// Row step [s].
    pub dt_s: f64,
}

/// Options of [`fit_lugre`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LugreFitOptions {
    /// Options of stage 1's static SCV fit.
    pub static_fit: FitOptions,
    /// Travel from a segment's start before its rows enter the cost [rad].
    pub warmup_travel_rad: f64,
    /// Cost evaluations (simulations) of stage 2.
    pub max_evals_dynamic: usize,
    /// Cost evaluations of stage 3 (0: no joint refinement).
    pub max_evals_joint: usize,
    /// Hold σ0 at this value [Nm/rad] instead of identifying it.
    pub sigma0_fixed: Option<f64>,
    /// Hold σ1 at this value [Nm·s/rad] instead of identifying it.
    pub sigma1_fixed: Option<f64>,
}

impl Default for LugreFitOptions {
    fn default() -> Self {
        Self {
            static_fit: FitOptions::default(),
            warmup_travel_rad: 0.01,
            max_evals_dynamic: 300,
            max_evals_joint: 1500,
            sigma0_fixed: None,
            sigma1_fixed: None,
        }
    }
}

/// RMSE after one stage of [`fit_lugre`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LugreStage {
    /// `"stribeck"` (stage 1, σ0 and σ1 at their start), `"bristle"` (stage 2) or `"joint"` (stage 3).
    pub stage: String,
    /// RMSE of the simulated τ̂_F on the cost rows [Nm].
    pub rmse_nm: f64,
    /// Cost evaluations the stage used.
    pub evaluations: usize,
}

/// Result of [`fit_lugre`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LugreFitResult {
    /// The identified parameters.
    pub params: LugreParams,
    /// RMSE of the simulated τ̂_F on the cost rows [Nm].
    pub rmse_nm: f64,
    /// Mean absolute error on the cost rows [Nm].
    pub mae_nm: f64,
    /// Rows in the cost.
    pub n_samples: usize,
    /// Stage 1's static fit (its model is the Stribeck curve's start).
    pub static_fit: FitResult<ScvParams>,
    /// The stages in order.
    pub stages: Vec<LugreStage>,
    /// Parameters that ended on a bound of the dynamic stages, e.g. `"sigma1=min"`.
    pub at_bounds: Vec<String>,
}

/// Box of the dynamic stages, per parameter in [`LugreParams::PARAM_NAMES`] order [its unit].
///
/// σ0 ∈ [kc/0.1 rad, kc/1 µrad] (pre-sliding deflection at the Coulomb level between 1 µrad and
/// 0.1 rad), σ1 ∈ [1e-6·σ0·1 s, σ0·1 s]; the Stribeck parameters within the static fit's bounds
/// (vs, α, ks/kc) or a factor 10 of stage 1 (kc, kv).
fn bounds(s: &ScvParams, o: &FitOptions) -> [(f64, f64); 7] {
    let b = &o.bounds;
    let kc = s.kc.max(1e-9);
    [
        (kc / 10.0, kc * 10.0),
        ((s.kv / 10.0).max(1e-9), (s.kv * 10.0).max(1e-6)),
        (
            (s.ks / 10.0).max(1e-9),
            (b.ks_max_ratio * kc * 10.0).max(1e-6),
        ),
        (b.vs_min, b.vs_max),
        (b.alpha_min, b.alpha_max),
        (kc / 0.1, kc / 1e-6),
        (kc / 0.1 * 1e-6, kc / 1e-6),
    ]
}

fn to_params(p: &[f64; 7]) -> LugreParams {
    LugreParams {
        kc: p[0],
        kv: p[1],
        ks: p[2],
        vs: p[3],
        alpha: p[4],
        sigma0: p[5],
        sigma1: p[6],
    }
}

fn from_params(l: &LugreParams) -> [f64; 7] {
    [l.kc, l.kv, l.ks, l.vs, l.alpha, l.sigma0, l.sigma1]
}

/// Why a LuGre fit or evaluation failed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LugreFitError {
    /// The columns differ in length.
    #[error("LuGre series: {what} has {got} rows, the velocity {want}")]
    Length {
        /// The column.
        what: &'static str,
        /// Its rows.
        got: usize,
        /// The velocity's rows.
        want: usize,
    },
    /// The step is not finite and > 0.
    #[error("LuGre series: dt_s = {0} must be finite and > 0")]
    Step(f64),
    /// No row enters the cost after the warm-up.
    #[error("LuGre series: no row enters the cost (none used, or none after {0} rad of travel)")]
    NoRows(f64),
    /// Stage 1's static fit failed.
    #[error("LuGre stage 1 (Stribeck curve): {0}")]
    Static(#[from] FitError),
    /// The parameters are out of the model's domain.
    #[error("{0}")]
    Params(#[from] frictionless::lugre::LugreParamError),
}

fn check(s: &LugreSeries) -> Result<(), LugreFitError> {
    let want = s.v_rad_s.len();
    for (what, got) in [
        ("tau_nm", s.tau_nm.len()),
        ("segment", s.segment.len()),
        ("use_row", s.use_row.len()),
        ("sliding", s.sliding.len()),
    ] {
        if got != want {
            return Err(LugreFitError::Length { what, got, want });
        }
    }
    if !(s.dt_s.is_finite() && s.dt_s > 0.0) {
        return Err(LugreFitError::Step(s.dt_s));
    }
    Ok(())
}

/// Row ranges of the segments: a new one where the id changes or the velocity is not finite (that
/// row is left out).
fn segments(s: &LugreSeries) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for i in 0..s.v_rad_s.len() {
        let ok = s.v_rad_s[i].is_finite();
        let new = i == 0 || s.segment[i] != s.segment[i - 1];
        if let Some(a) = start
            && (new || !ok)
        {
            out.push((a, i));
            start = None;
        }
        if ok && start.is_none() {
            start = Some(i);
        }
    }
    if let Some(a) = start {
        out.push((a, s.v_rad_s.len()));
    }
    out
}

/// Which rows enter the cost: `use_row`, a finite target, and past the warm-up travel of their
/// segment.
#[allow(clippy::needless_range_loop)] // one index into four columns
fn cost_rows(s: &LugreSeries, segs: &[(usize, usize)], warmup_travel_rad: f64) -> Vec<bool> {
    let mut out = vec![false; s.v_rad_s.len()];
    for &(a, b) in segs {
        let mut travel = 0.0;
        for i in a..b {
            travel += s.v_rad_s[i].abs() * s.dt_s;
            out[i] = travel >= warmup_travel_rad && s.use_row[i] && s.tau_nm[i].is_finite();
        }
    }
    out
}

#[allow(clippy::needless_range_loop)] // one index into three columns
/// (Σr², Σ|r|, n) of the simulated τ̂_F on the cost rows; segments in parallel, summed in order.
fn sums(
    p: &LugreParams,
    s: &LugreSeries,
    segs: &[(usize, usize)],
    rows: &[bool],
) -> (f64, f64, usize) {
    let parts: Vec<(f64, f64, usize)> = segs
        .par_iter()
        .map(|&(a, b)| {
            let Ok(mut e) = LugreEstimator::new(*p, s.dt_s) else {
                return (f64::INFINITY, f64::INFINITY, 0);
            };
            let (mut s2, mut s1, mut n) = (0.0, 0.0, 0);
            for i in a..b {
                let t = e.step(s.v_rad_s[i]);
                if rows[i] {
                    let r = t - s.tau_nm[i];
                    s2 += r * r;
                    s1 += r.abs();
                    n += 1;
                }
            }
            (s2, s1, n)
        })
        .collect();
    parts
        .iter()
        .fold((0.0, 0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2))
}

/// RMSE and MAE [Nm] and the number of rows of LuGre `params` simulated over `series` (rows
/// `use_row` with a finite target after `warmup_travel_rad`, as in the fit): the held-out error.
pub fn lugre_errors(
    params: &LugreParams,
    series: &LugreSeries,
    warmup_travel_rad: f64,
) -> Result<(f64, f64, usize), LugreFitError> {
    check(series)?;
    params.validate()?;
    let segs = segments(series);
    let rows = cost_rows(series, &segs, warmup_travel_rad);
    let (s2, s1, n) = sums(params, series, &segs, &rows);
    if n == 0 {
        return Err(LugreFitError::NoRows(warmup_travel_rad));
    }
    Ok(((s2 / n as f64).sqrt(), s1 / n as f64, n))
}

/// RMSE and MAE [Nm] and the number of rows of a static model over `series`, on the rows
/// [`lugre_errors`] scores: the same held-out rows for every model.
pub fn static_errors<M: StaticFriction + Sync>(
    model: &M,
    series: &LugreSeries,
    warmup_travel_rad: f64,
) -> Result<(f64, f64, usize), LugreFitError> {
    check(series)?;
    let segs = segments(series);
    let rows = cost_rows(series, &segs, warmup_travel_rad);
    let (mut s2, mut s1, mut n) = (0.0, 0.0, 0);
    for (i, _) in rows.iter().enumerate().filter(|(_, r)| **r) {
        let r = model.torque_nm(series.v_rad_s[i]) - series.tau_nm[i];
        s2 += r * r;
        s1 += r.abs();
        n += 1;
    }
    if n == 0 {
        return Err(LugreFitError::NoRows(warmup_travel_rad));
    }
    Ok(((s2 / n as f64).sqrt(), s1 / n as f64, n))
}

/// The row step [s] and segment ids of a time column split into chunks: the step is the median of
/// the positive time differences within chunks, and a new segment starts where the chunk changes or
/// the time step differs from it by more than 1 %.
///
/// # Errors
/// [`LugreFitError::Length`] for columns of different lengths, [`LugreFitError::Step`] when no two
/// consecutive rows of a chunk have increasing times.
pub fn time_segments(time_s: &[f64], chunk: &[u32]) -> Result<(f64, Vec<u32>), LugreFitError> {
    if chunk.len() != time_s.len() {
        return Err(LugreFitError::Length {
            what: "chunk",
            got: chunk.len(),
            want: time_s.len(),
        });
    }
    let mut d: Vec<f64> = (1..time_s.len())
        .filter(|&i| chunk[i] == chunk[i - 1])
        .map(|i| time_s[i] - time_s[i - 1])
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    if d.is_empty() {
        return Err(LugreFitError::Step(f64::NAN));
    }
    d.sort_by(f64::total_cmp);
    let dt = d[d.len() / 2];
    let mut seg = Vec::with_capacity(time_s.len());
    let mut id = 0u32;
    for i in 0..time_s.len() {
        if i > 0
            && (chunk[i] != chunk[i - 1]
                || (time_s[i] - time_s[i - 1] - dt).abs().is_nan()
                || (time_s[i] - time_s[i - 1] - dt).abs() > 0.01 * dt)
        {
            id += 1;
        }
        seg.push(id);
    }
    Ok((dt, seg))
}

/// Nelder–Mead on `x` within `[lo, hi]` (each trial point clamped into the box), at most `max_evals`
/// evaluations of `f`; returns (best x, its value, evaluations).
fn nelder_mead(
    f: &dyn Fn(&[f64]) -> f64,
    x0: &[f64],
    step: &[f64],
    lo: &[f64],
    hi: &[f64],
    max_evals: usize,
) -> (Vec<f64>, f64, usize) {
    let n = x0.len();
    let clamp = |x: &mut Vec<f64>| {
        for k in 0..n {
            x[k] = x[k].clamp(lo[k], hi[k]);
        }
    };
    let evals = std::cell::Cell::new(0usize);
    let eval = |x: &[f64]| {
        evals.set(evals.get() + 1);
        let v = f(x);
        if v.is_finite() { v } else { f64::INFINITY }
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    let mut x = x0.to_vec();
    clamp(&mut x);
    simplex.push((x.clone(), eval(&x)));
    for k in 0..n {
        let mut y = x.clone();
        y[k] += step[k];
        if y[k] > hi[k] {
            y[k] = x[k] - step[k];
        }
        clamp(&mut y);
        let fy = eval(&y);
        simplex.push((y, fy));
    }
    while evals.get() < max_evals {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, worst) = (simplex[0].1, simplex[n].1);
        let spread = (0..n)
            .map(|k| {
                simplex
                    .iter()
                    .map(|p| (p.0[k] - simplex[0].0[k]).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        if (worst - best).abs() <= 1e-10 * best.abs().max(1e-300) || spread < 1e-7 {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|k| simplex[..n].iter().map(|p| p.0[k]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            let mut y: Vec<f64> = (0..n)
                .map(|k| centroid[k] + t * (simplex[n].0[k] - centroid[k]))
                .collect();
            clamp(&mut y);
            y
        };
        let xr = along(-1.0);
        let fr = eval(&xr);
        if fr < simplex[0].1 {
            let xe = along(-2.0);
            let fe = eval(&xe);
            simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (xr, fr);
        } else {
            let xc = if fr < simplex[n].1 {
                along(-0.5)
            } else {
                along(0.5)
            };
            let fc = eval(&xc);
            if fc < fr.min(simplex[n].1) {
                simplex[n] = (xc, fc);
            } else {
                // Shrink towards the best point.
                let b = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    let mut y: Vec<f64> = (0..n).map(|k| b[k] + 0.5 * (p.0[k] - b[k])).collect();
                    clamp(&mut y);
                    let fy = eval(&y);
                    *p = (y, fy);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (x, fx) = simplex.swap_remove(0);
    (x, fx, evals.get())
}

/// Stage 1: the SCV (Stribeck) fit on the steady sliding rows of `series`.
fn stribeck_stage(
    series: &LugreSeries,
    opts: &LugreFitOptions,
) -> Result<FitResult<ScvParams>, LugreFitError> {
    let slide: Vec<bool> = series
        .sliding
        .iter()
        .zip(series.use_row)
        .map(|(&a, &b)| a && b)
        .collect();
    let v = crate::fit::select(series.v_rad_s, &slide);
    let t = crate::fit::select(series.tau_nm, &slide);
    Ok(fit(&v, &t, &opts.static_fit)?)
}

/// The fitted parameters (from index `first_fitted` on, not `held`) at a bound of `bx`, as
/// `NAME=min|max`.
fn at_bounds(
    params: &LugreParams,
    bx: &[(f64, f64); 7],
    held: &[bool; 7],
    first_fitted: usize,
) -> Vec<String> {
    let names = LugreParams::PARAM_NAMES;
    let mut out = Vec::new();
    for (k, &x) in from_params(params).iter().enumerate().skip(first_fitted) {
        if held[k] {
            continue;
        }
        if x <= bx[k].0 * (1.0 + 1e-6) {
            out.push(format!("{}=min", names[k]));
        }
        if x >= bx[k].1 * (1.0 - 1e-6) {
            out.push(format!("{}=max", names[k]));
        }
    }
    out
}

/// Identifies LuGre from `series` in the three stages of the module documentation.
///
/// # Errors
/// Mismatched columns, a bad step, no cost rows, or a failed stage-1 static fit.
pub fn fit_lugre(
    series: &LugreSeries,
    opts: &LugreFitOptions,
) -> Result<LugreFitResult, LugreFitError> {
    check(series)?;
    let segs = segments(series);
    let rows = cost_rows(series, &segs, opts.warmup_travel_rad);
    if !rows.iter().any(|&r| r) {
        return Err(LugreFitError::NoRows(opts.warmup_travel_rad));
    }
    // Stage 1: the Stribeck curve from the steady sliding rows.
    let static_fit = stribeck_stage(series, opts)?;
    let s = static_fit.model;
    let mut bx = bounds(&s, &opts.static_fit);
    let mut p = [
        s.kc,
        s.kv,
        s.ks,
        s.vs,
        s.alpha,
        s.kc / 1e-3,
        s.kc / 1e-3 * 1e-3,
    ];
    let mut held = [false; 7];
    for (k, v) in [(5, opts.sigma0_fixed), (6, opts.sigma1_fixed)] {
        if let Some(v) = v {
            bx[k] = (v, v);
            held[k] = true;
        }
    }
    for (k, x) in p.iter_mut().enumerate() {
        *x = x.clamp(bx[k].0, bx[k].1);
    }
    let rmse_of = |p: &[f64; 7]| -> f64 {
        let (s2, _, n) = sums(&to_params(p), series, &segs, &rows);
        if n == 0 {
            f64::INFINITY
        } else {
            (s2 / n as f64).sqrt()
        }
    };
    // The simplex runs on ln p of the free coordinates `free`; the others stay at `base`.
    let minimise = |base: &[f64; 7], free: &[usize], step: f64, max_evals: usize| {
        let lo: Vec<f64> = free.iter().map(|&k| bx[k].0.ln()).collect();
        let hi: Vec<f64> = free.iter().map(|&k| bx[k].1.ln()).collect();
        let x0: Vec<f64> = free.iter().map(|&k| base[k].ln()).collect();
        let put = |x: &[f64]| {
            let mut q = *base;
            for (j, &k) in free.iter().enumerate() {
                q[k] = x[j].exp();
            }
            q
        };
        let (x, c, e) = nelder_mead(
            &|x: &[f64]| rmse_of(&put(x)),
            &x0,
            &vec![step; free.len()],
            &lo,
            &hi,
            max_evals,
        );
        (put(&x), c, e)
    };
    let mut stages = vec![LugreStage {
        stage: "stribeck".into(),
        rmse_nm: rmse_of(&p),
        evaluations: 1,
    }];
    // Stage 2: σ0, σ1 from a coarse grid (deflection at kc of 10 µrad … 10 mrad, σ1/σ0 of
    // 0.1 ms … 100 ms), then the simplex from the best grid point.
    let free_dyn: Vec<usize> = (5..7).filter(|&k| !held[k]).collect();
    let mut best = (f64::INFINITY, p);
    let mut evals = 0;
    for defl in [1e-5, 1e-4, 1e-3, 1e-2] {
        for ratio_s in [1e-4, 1e-3, 1e-2, 1e-1] {
            let mut q = p;
            if !held[5] {
                q[5] = (s.kc / defl).clamp(bx[5].0, bx[5].1);
            }
            if !held[6] {
                q[6] = (q[5] * ratio_s).clamp(bx[6].0, bx[6].1);
            }
            let c = rmse_of(&q);
            evals += 1;
            if c < best.0 {
                best = (c, q);
            }
        }
    }
    let (mut c2, mut p2) = (best.0, best.1);
    if !free_dyn.is_empty() {
        let (q, c, e) = minimise(&best.1, &free_dyn, 1.0, opts.max_evals_dynamic);
        evals += e;
        if c < c2 {
            (p2, c2) = (q, c);
        }
    }
    p = p2;
    stages.push(LugreStage {
        stage: "bristle".into(),
        rmse_nm: c2,
        evaluations: evals,
    });
    // Stage 3: every free parameter together.
    if opts.max_evals_joint > 0 {
        let free: Vec<usize> = (0..7).filter(|&k| !held[k]).collect();
        let (q, c3, e3) = minimise(&p, &free, 0.1, opts.max_evals_joint);
        if c3 < c2 {
            p = q;
        }
        stages.push(LugreStage {
            stage: "joint".into(),
            rmse_nm: c3.min(c2),
            evaluations: e3,
        });
    }
    let params = to_params(&p);
    params.validate()?;
    let (s2, s1, n) = sums(&params, series, &segs, &rows);
    // Stage 3 moved every parameter; otherwise only σ0 and σ1 (index 5 on) were fitted here.
    let first_fitted = if opts.max_evals_joint > 0 { 0 } else { 5 };
    let at_bounds = at_bounds(&params, &bx, &held, first_fitted);
    Ok(LugreFitResult {
        params,
        rmse_nm: (s2 / n as f64).sqrt(),
        mae_nm: s1 / n as f64,
        n_samples: n,
        static_fit,
        stages,
        at_bounds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_split_on_id_changes_and_non_finite_velocity() {
        let v = [0.1, 0.1, f64::NAN, 0.1, 0.1, 0.1];
        let seg = [0, 0, 0, 0, 1, 1];
        let t = [0.0; 6];
        let b = [true; 6];
        let s = LugreSeries {
            v_rad_s: &v,
            tau_nm: &t,
            segment: &seg,
            use_row: &b,
            sliding: &b,
            dt_s: 1e-3,
        };
        assert_eq!(segments(&s), [(0, 2), (3, 4), (4, 6)]);
    }

    #[test]
    fn nelder_mead_finds_a_quadratic_minimum_inside_the_box_and_stops_on_its_edge() {
        let f = |x: &[f64]| (x[0] - 1.0).powi(2) + 10.0 * (x[1] + 2.0).powi(2);
        let (x, fx, _) = nelder_mead(&f, &[0.0, 0.0], &[1.0, 1.0], &[-5.0; 2], &[5.0; 2], 2000);
        assert!(
            (x[0] - 1.0).abs() < 1e-3 && (x[1] + 2.0).abs() < 1e-3,
            "{x:?}"
        );
        assert!(fx < 1e-6);
        let (x, _, _) = nelder_mead(&f, &[0.0, 0.0], &[1.0, 1.0], &[-5.0, -1.0], &[5.0; 2], 2000);
        assert!((x[1] + 1.0).abs() < 1e-9, "held on the bound: {x:?}");
    }
}
