//! Evaluation across runs: RMSE per run (a recording, usually one source file) and per velocity band,
//! with the rows outside the training range counted apart.
//!
//! What it is: [`breakdown`] splits the rows an evaluation scored ([`super::DatasetEval::mask`]) by run
//! ([`frictionless_dataset::RunInfo`]: the dataset sidecar's runs, or the whole file as one run) and by
//! |ṡ| band ([`DEFAULT_BAND_EDGES_RAD_S`] or `--band-edges`: band j is `edges[j] ≤ |ṡ| < edges[j+1]`, the
//! last one open), and, given the training range ([`MotionRange`]: s and ṡ over the training runs' valid
//! rows), scores rows inside and outside it separately; [`RunReport`] / [`BandReport`] are the
//! `per_run[]` / `per_band[]` entries of the eval report.
//!
//! What it is not: prediction or the main metrics (see [`super::evaluate`]), or the banding itself
//! (`frictionless_dataset::bands`, shared with the drift monitor and the trainer).

use std::collections::BTreeMap;

use frictionless_dataset::{Dataset, MotionRange, RunInfo};
use serde::{Deserialize, Serialize};

use super::{DatasetEval, EvalError, ModelSpec};

pub use frictionless_dataset::bands::{DEFAULT_BAND_EDGES_RAD_S, band_of};

/// Checks band edges: at least one, finite, ≥ 0 and strictly increasing.
pub fn check_band_edges(edges: &[f64]) -> Result<(), EvalError> {
    let ok = !edges.is_empty()
        && edges.iter().all(|e| e.is_finite() && *e >= 0.0)
        && edges.windows(2).all(|w| w[0] < w[1]);
    if ok {
        Ok(())
    } else {
        Err(EvalError::Option {
            key: "--band-edges",
            value: format!("{edges:?}"),
            reason: "needs at least one edge, finite, >= 0 and strictly increasing",
        })
    }
}

/// Rows where s or ṡ lies outside `range` (every row false without a range).
pub fn extrapolated_mask(ds: &Dataset, range: Option<&MotionRange>) -> Vec<bool> {
    (0..ds.len())
        .map(|k| range.is_some_and(|r| !r.contains(ds.s_rad[k], ds.sdot_rad_s[k])))
        .collect()
}

/// Squared-error sums per model over a set of rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sums {
    /// Rows.
    pub n: usize,
    /// Σ (τ̂ − label)² per model.
    pub sq: Vec<f64>,
    /// Σ (τ̂ − truth)² per model (zeros without truth).
    pub true_sq: Vec<f64>,
    /// Whether every row added had the simulator's truth.
    pub has_truth: bool,
}

impl Sums {
    fn new(n_models: usize, has_truth: bool) -> Self {
        Self {
            n: 0,
            sq: vec![0.0; n_models],
            true_sq: vec![0.0; n_models],
            has_truth,
        }
    }

    fn add(&mut self, ds: &Dataset, ev: &DatasetEval, k: usize) {
        self.n += 1;
        for (i, p) in ev.predictions.iter().enumerate() {
            let e = p[k] - ds.tau_f_label_nm[k];
            self.sq[i] += e * e;
            if let Some(t) = &ds.tau_f_true_nm {
                let et = p[k] - t[k];
                self.true_sq[i] += et * et;
            }
        }
    }

    /// Adds another set's sums (same models).
    pub fn merge(&mut self, o: &Self) {
        if self.sq.is_empty() {
            *self = o.clone();
            return;
        }
        self.n += o.n;
        for i in 0..self.sq.len().min(o.sq.len()) {
            self.sq[i] += o.sq[i];
            self.true_sq[i] += o.true_sq[i];
        }
        self.has_truth &= o.has_truth;
    }

    /// RMSE of model `i` vs the label (None over zero rows).
    pub fn rmse(&self, i: usize) -> Option<f64> {
        (self.n > 0).then(|| (self.sq[i] / self.n as f64).sqrt())
    }

    /// RMSE of model `i` vs the truth (None over zero rows or without truth).
    pub fn rmse_true(&self, i: usize) -> Option<f64> {
        (self.n > 0 && self.has_truth).then(|| (self.true_sq[i] / self.n as f64).sqrt())
    }
}

/// One run's sums.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSums {
    /// Dataset path.
    pub dataset: String,
    /// The run.
    pub run: RunInfo,
    /// Every scored row.
    pub all: Sums,
    /// Sliding rows (|ṡ| > the sliding threshold).
    pub sliding: Sums,
    /// Stick rows.
    pub stick: Sums,
    /// Rows inside the training range.
    pub inside: Sums,
    /// Rows outside it.
    pub outside: Sums,
    /// Per |ṡ| band.
    pub bands: Vec<Sums>,
}

/// Splits `ev`'s scored rows of `ds` by run, sliding/stick, inside/outside (`extrapolated[k]`) and band.
/// Runs with no scored row are left out.
pub fn breakdown(
    ds: &Dataset,
    ev: &DatasetEval,
    runs: &[RunInfo],
    extrapolated: &[bool],
    edges: &[f64],
    v_sliding_rad_s: f64,
) -> Vec<RunSums> {
    let m = ev.predictions.len();
    let truth = ds.tau_f_true_nm.is_some();
    let mut out = Vec::new();
    for run in runs {
        let mut r = RunSums {
            dataset: ev.path.clone(),
            run: run.clone(),
            all: Sums::new(m, truth),
            sliding: Sums::new(m, truth),
            stick: Sums::new(m, truth),
            inside: Sums::new(m, truth),
            outside: Sums::new(m, truth),
            bands: vec![Sums::new(m, truth); edges.len()],
        };
        for (k, &outside) in extrapolated.iter().enumerate().take(ds.len()) {
            if !ev.mask[k] || !run.chunks.contains(&ds.chunk[k]) {
                continue;
            }
            r.all.add(ds, ev, k);
            if ds.sdot_rad_s[k].abs() > v_sliding_rad_s {
                r.sliding.add(ds, ev, k);
            } else {
                r.stick.add(ds, ev, k);
            }
            if outside {
                r.outside.add(ds, ev, k);
            } else {
                r.inside.add(ds, ev, k);
            }
            if let Some(b) = band_of(edges, ds.sdot_rad_s[k]) {
                r.bands[b].add(ds, ev, k);
            }
        }
        if r.all.n > 0 {
            out.push(r);
        }
    }
    out
}

/// One model's numbers on one run [Nm] (None over zero rows; the `_true` ones also without truth).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMetrics {
    /// Every scored row, vs the label.
    pub rmse_all: Option<f64>,
    /// Sliding rows.
    pub rmse_sliding: Option<f64>,
    /// Stick rows.
    pub rmse_stick: Option<f64>,
    /// Rows inside the training range.
    pub rmse_inside: Option<f64>,
    /// Rows outside the training range (extrapolation).
    pub rmse_outside: Option<f64>,
    /// Every scored row, vs the truth.
    pub rmse_true_all: Option<f64>,
    /// Inside, vs the truth.
    pub rmse_true_inside: Option<f64>,
    /// Outside, vs the truth.
    pub rmse_true_outside: Option<f64>,
}

/// One model's numbers in one band [Nm].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BandMetrics {
    /// vs the label.
    pub rmse: Option<f64>,
    /// vs the truth.
    pub rmse_true: Option<f64>,
}

/// One |ṡ| band: `lo_rad_s ≤ |ṡ| < hi_rad_s` (`hi_rad_s` null = unbounded).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandReport {
    /// Lower edge [rad/s].
    pub lo_rad_s: f64,
    /// Upper edge [rad/s] (None for the last band).
    pub hi_rad_s: Option<f64>,
    /// Scored rows in the band.
    pub n: usize,
    /// Metrics per model.
    pub models: BTreeMap<String, BandMetrics>,
}

/// One run's entry (`per_run[]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Dataset path.
    pub dataset: String,
    /// Run name.
    pub run: String,
    /// The run's source file as recorded.
    pub source: String,
    /// Scored rows.
    pub evaluated: usize,
    /// Scored rows outside the training range (None without a training range).
    pub extrapolated: Option<usize>,
    /// `extrapolated / evaluated`.
    pub extrapolated_share: Option<f64>,
    /// Metrics per model.
    pub models: BTreeMap<String, RunMetrics>,
    /// Per |ṡ| band.
    pub bands: Vec<BandReport>,
}

/// Band entries from per-band sums.
pub fn band_reports(models: &[ModelSpec], edges: &[f64], bands: &[Sums]) -> Vec<BandReport> {
    bands
        .iter()
        .enumerate()
        .map(|(j, s)| BandReport {
            lo_rad_s: edges[j],
            hi_rad_s: edges.get(j + 1).copied(),
            n: s.n,
            models: models
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    (
                        m.name.clone(),
                        BandMetrics {
                            rmse: s.rmse(i),
                            rmse_true: s.rmse_true(i),
                        },
                    )
                })
                .collect(),
        })
        .collect()
}

/// A run's entry; `with_range` = whether a training range was known.
pub fn run_report(models: &[ModelSpec], edges: &[f64], r: &RunSums, with_range: bool) -> RunReport {
    let out = |v: Option<f64>| if with_range { v } else { None };
    RunReport {
        dataset: r.dataset.clone(),
        run: r.run.name.clone(),
        source: r.run.source.clone(),
        evaluated: r.all.n,
        extrapolated: with_range.then_some(r.outside.n),
        extrapolated_share: (with_range && r.all.n > 0)
            .then(|| r.outside.n as f64 / r.all.n as f64),
        models: models
            .iter()
            .enumerate()
            .map(|(i, m)| {
                (
                    m.name.clone(),
                    RunMetrics {
                        rmse_all: r.all.rmse(i),
                        rmse_sliding: r.sliding.rmse(i),
                        rmse_stick: r.stick.rmse(i),
                        rmse_inside: out(r.inside.rmse(i)),
                        rmse_outside: out(r.outside.rmse(i)),
                        rmse_true_all: r.all.rmse_true(i),
                        rmse_true_inside: out(r.inside.rmse_true(i)),
                        rmse_true_outside: out(r.outside.rmse_true(i)),
                    },
                )
            })
            .collect(),
        bands: band_reports(models, edges, &r.bands),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_edges_are_checked() {
        let e = DEFAULT_BAND_EDGES_RAD_S;
        assert!(check_band_edges(&e).is_ok());
        assert!(check_band_edges(&[]).is_err());
        assert!(check_band_edges(&[0.0, 0.1, 0.1]).is_err());
        assert!(check_band_edges(&[-1.0, 0.1]).is_err());
        assert!(check_band_edges(&[0.0, f64::INFINITY]).is_err());
    }
}
