//! The drift monitor of `frictl eval --drift`: how far the friction in a new log has moved from what a
//! model was trained on, and whether to retrain.
//!
//! What it is: for every evaluated model but `none`, the residual (label − τ̂_F) on the scored rows
//! of the new log as a [`ResidualProfile`] (n, mean, RMSE over all rows, per |ṡ| band — the eval's
//! `--band-edges`, the one banding of `frictionless_dataset::bands` — and per temperature bin when the
//! log has a temperature), the same numbers on the model's **reference** data, the share of rows whose
//! inputs lie outside a PINN's stored training range (`InputRange` of the `.fwt`, judged as frictiond
//! judges it: [`frictionless::model::PinnEstimator::out_of_range`] with a margin), and a verdict.
//!
//! The reference, first available of:
//! 1. `reference_datasets`: the datasets of `--reference` (e.g. the training dataset), evaluated the
//!    same way (every valid row whose history is ready);
//! 2. `train_report:<set>`: the `residual_reference` a `frictl train --report` stored (validation
//!    set, or the training set without one) — one PINN only; its bands are used only if its edges equal
//!    `--band-edges`, its temperature bins only if their width equals `--drift-temperature-bin`;
//! 3. `fwt`: the validation (else test) RMSE in the `.fwt` training metadata — one number, no mean, no
//!    bands: only the all-rows RMSE is checked.
//!
//! The rule ([`DriftOptions`]; thresholds are flags). Each check compares a set of new rows with a
//! reference set: all rows with all rows; each |ṡ| band with the reference's same band (the error level
//! depends on the velocity: a band the reference has fewer than `min_samples` rows in is listed as
//! `unchecked`, not compared); each temperature bin with the reference's same bin if that has ≥
//! `min_samples` rows, else with the reference's all rows (a hotter log has no same bin; its velocity
//! mix is that of the whole log). A check is made when the new set has ≥ `min_samples` rows, and it
//! fires when
//! `RMSE_new > rmse_ratio · RMSE_ref + floor_nm`, or when the mean residual or the mean residual along
//! the motion (residual·sign(ṡ): a Coulomb or viscous change cancels in the plain mean over both
//! directions, not in this one) moved by more than `mean_ratio · RMSE_ref + floor_nm`. The verdict is `retrain` if any check
//! fires, `ok` if none does, `unchecked` if no check had enough rows (`frictl eval --drift` then
//! fails: nothing was checked), `no_reference` without a reference; `extrapolating` is set when more than
//! `max_out_of_range` of the scored rows are out of the PINN's input range.
//!
//! Online, frictiond cannot know the true friction (no label), so the residual part is offline only;
//! the coverage part is online: frictiond counts out-of-range ticks per joint
//! (`DaemonStatus::out_of_range_ticks`, shown by `frictl monitor`) with the same range and margin.
//!
//! What it is not: prediction (that is [`super::evaluate`]) or a retraining.

use serde::{Deserialize, Serialize};

use frictionless::model::{FrictionModel, JointModel};
use frictionless_dataset::Dataset;
use frictionless_dataset::bands::{ResidualProfile, ResidualStats};
use frictionless_train::data::DeltaThetaOffset;

use super::{DatasetEval, chunk_ranges};

/// Thresholds and settings of the drift verdict (the `--drift-*` flags).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftOptions {
    /// Width of the temperature bins [°C].
    pub temperature_bin_c: f64,
    /// Fewest rows a new set (and a reference band or bin) needs to be checked.
    pub min_samples: usize,
    /// A check fires when RMSE_new > `rmse_ratio`·RMSE_ref + `floor_nm`.
    pub rmse_ratio: f64,
    /// … or when the mean residual (or the mean along the motion) moved by more than
    /// `mean_ratio`·RMSE_ref + `floor_nm`.
    pub mean_ratio: f64,
    /// Absolute slack of both limits [Nm].
    pub floor_nm: f64,
    /// `extrapolating` when more than this share of the scored rows is out of the input range.
    pub max_out_of_range: f64,
    /// Margin of the input-range test (fraction of each range's width, as frictiond's `ood_margin`).
    pub range_margin: f64,
}

impl Default for DriftOptions {
    fn default() -> Self {
        Self {
            temperature_bin_c: frictionless_dataset::bands::DEFAULT_TEMPERATURE_BIN_C,
            min_samples: 500,
            rmse_ratio: 1.5,
            mean_ratio: 0.5,
            floor_nm: 0.02,
            max_out_of_range: 0.05,
            range_margin: frictiond_config::default_ood_margin(),
        }
    }
}

/// A model's reference: where it came from and the profile.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// `reference_datasets`, `train_report:<set>` or `fwt`.
    pub source: String,
    /// The profile (from `fwt`: only `all.rmse_nm`, no bands).
    pub profile: ResidualProfile,
}

/// Input-range coverage of a PINN on the scored rows.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// Scored rows.
    pub rows: usize,
    /// Scored rows whose inputs are outside the stored training range (widened by the margin).
    pub out_of_range: usize,
    /// `out_of_range / rows`.
    pub out_of_range_share: f64,
    /// Margin used.
    pub margin: f64,
}

/// One comparison of new rows with reference rows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// `all`, `band [lo, hi)` (rad/s) or `temperature [lo, hi)` (°C).
    pub what: String,
    /// The new rows' statistics.
    pub new: ResidualStats,
    /// The reference statistics compared with.
    pub reference: ResidualStats,
    /// `same` (the reference's same band or bin, or all rows for the all-rows check) or `all` (a
    /// temperature bin compared with the reference's all rows, its own bin being too thin).
    pub reference_bin: String,
    /// RMSE limit [Nm].
    pub rmse_limit_nm: f64,
    /// Mean-shift limit [Nm].
    pub mean_shift_limit_nm: f64,
    /// Whether the check fired.
    pub fired: bool,
}

/// The drift of one model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelDrift {
    /// Model name (as in the eval report).
    pub model: String,
    /// The new log's residual profile.
    pub new: ResidualProfile,
    /// Where the reference came from (null without one).
    pub reference_source: Option<String>,
    /// The reference profile (null without one).
    pub reference: Option<ResidualProfile>,
    /// Input-range coverage (PINNs with a stored range only).
    pub coverage: Option<Coverage>,
    /// Every check made.
    pub checks: Vec<Check>,
    /// Bands with enough new rows that could not be compared (the reference's band too thin).
    pub unchecked: Vec<String>,
    /// `retrain`, `ok`, `unchecked` (a reference, but no check had enough rows) or `no_reference`.
    pub verdict: String,
    /// More than `max_out_of_range` of the rows outside the input range.
    pub extrapolating: bool,
    /// The fired checks and the coverage, in words.
    pub reasons: Vec<String>,
}

/// The `drift` key of the eval report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftReport {
    /// The rule, in words.
    pub rule: String,
    /// The thresholds.
    pub options: DriftOptions,
    /// `retrain` if any model's verdict is `retrain`, else `unchecked` if any model had nothing
    /// checked, else `ok` if any is `ok`, else `no_reference`.
    pub verdict: String,
    /// Whether any model is extrapolating.
    pub extrapolating: bool,
    /// Per model (every model but `none`).
    pub models: Vec<ModelDrift>,
}

/// (ṡ, T, label − τ̂) of model `i` on the scored rows of every evaluation.
pub fn residual_rows<'a>(
    evals: &'a [(&'a DatasetEval, &'a Dataset)],
    i: usize,
) -> impl Iterator<Item = (f64, f64, f64)> + 'a {
    evals.iter().flat_map(move |(ev, ds)| {
        (0..ds.len()).filter(|&k| ev.mask[k]).map(move |k| {
            (
                ds.sdot_rad_s[k],
                ds.temperature_c[k],
                ds.tau_f_label_nm[k] - ev.predictions[i][k],
            )
        })
    })
}

/// Rows of `ds` whose inputs are outside the PINN's stored range (widened by `margin`); None for a
/// model that is not a PINN or has no stored range. Run as [`super::predict`] runs it: per chunk,
/// reset with the Δθ latch of `offset`, then one `estimate` per row.
pub fn out_of_range_mask(
    ds: &Dataset,
    model: &JointModel,
    offset: DeltaThetaOffset,
    margin: f64,
) -> Option<Vec<bool>> {
    let JointModel::Pinn(p) = model else {
        return None;
    };
    p.meta().training.input_range?;
    let mut out = vec![false; ds.len()];
    for (a, b) in chunk_ranges(ds) {
        let mut m = p.clone();
        m.reset(&offset.latch_sample(ds, a));
        for (k, o) in out.iter_mut().enumerate().take(b).skip(a) {
            let s = ds.joint_sample(k);
            m.estimate(&s);
            *o = m.out_of_range(&s, margin as f32);
        }
    }
    Some(out)
}

/// The reference stored in a `.fwt`: its validation RMSE, else its test RMSE (None if neither).
pub fn fwt_reference(file: &frictionless::weights::ModelFile) -> Option<Reference> {
    let t = &file.meta.training;
    let (v, set) = if t.val_rmse_nm.is_finite() {
        (t.val_rmse_nm, "val")
    } else if t.test_rmse_nm.is_finite() {
        (t.test_rmse_nm, "test")
    } else {
        return None;
    };
    Some(Reference {
        source: format!("fwt:{set}_rmse_nm"),
        profile: ResidualProfile {
            all: ResidualStats {
                n: 0,
                mean_residual_nm: None,
                mean_along_motion_nm: None,
                rmse_nm: Some(f64::from(v)),
            },
            ..ResidualProfile::default()
        },
    })
}

/// A train report's `residual_reference`, restricted to what matches `edges` and the bin width.
pub fn train_report_reference(
    report: &serde_json::Value,
    edges: &[f64],
    temperature_bin_c: f64,
) -> Option<Reference> {
    let r: frictionless_train::pipeline::ResidualReference =
        serde_json::from_value(report.get("residual_reference")?.clone()).ok()?;
    let mut profile = r.profile;
    if profile.band_edges_rad_s != edges {
        profile.bands.clear();
    }
    if (profile.temperature_bin_c - temperature_bin_c).abs() > 1e-12 {
        profile.temperature.clear();
    }
    Some(Reference {
        source: format!("train_report:{}", r.set),
        profile,
    })
}

fn hi_text(hi: Option<f64>) -> String {
    hi.map_or_else(|| "inf".into(), |h| h.to_string())
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.4}"))
}

/// Compares `new` with the reference `same` (its same band or bin) if that has ≥ `min_samples` rows,
/// else with `fallback` (the reference's all rows) if given; None when `new` is too thin or there is
/// nothing to compare with.
fn check(
    what: String,
    new: &ResidualStats,
    same: Option<&ResidualStats>,
    fallback: Option<&ResidualStats>,
    o: &DriftOptions,
) -> Option<Check> {
    if new.n < o.min_samples {
        return None;
    }
    let (reference, bin) = match (same, fallback) {
        (Some(s), _) if s.n >= o.min_samples && s.rmse_nm.is_some() => (*s, "same"),
        (_, Some(a)) => (*a, "all"),
        _ => return None,
    };
    let rmse_ref = reference.rmse_nm?;
    let rmse_limit_nm = o.rmse_ratio * rmse_ref + o.floor_nm;
    let mean_shift_limit_nm = o.mean_ratio * rmse_ref + o.floor_nm;
    let rmse_fired = new.rmse_nm.is_some_and(|r| r > rmse_limit_nm);
    let shifted = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() > mean_shift_limit_nm,
        _ => false,
    };
    let mean_fired = shifted(new.mean_residual_nm, reference.mean_residual_nm)
        || shifted(new.mean_along_motion_nm, reference.mean_along_motion_nm);
    Some(Check {
        what,
        new: *new,
        reference,
        reference_bin: bin.into(),
        rmse_limit_nm,
        mean_shift_limit_nm,
        fired: rmse_fired || mean_fired,
    })
}

/// The drift of one model from its new-log profile, its reference and its coverage.
pub fn model_drift(
    model: &str,
    new: ResidualProfile,
    reference: Option<Reference>,
    coverage: Option<Coverage>,
    o: &DriftOptions,
) -> ModelDrift {
    let (checks, unchecked) = match &reference {
        Some(r) => reference_checks(&new, &r.profile, o),
        None => (Vec::new(), Vec::new()),
    };
    let mut reasons: Vec<String> = checks.iter().filter(|c| c.fired).map(fired_text).collect();
    let extrapolating = coverage.is_some_and(|c| c.out_of_range_share > o.max_out_of_range);
    if let Some(c) = coverage.filter(|_| extrapolating) {
        reasons.push(format!(
            "{:.1} % of the rows ({} of {}) are outside the model's training input range (margin {}), limit {:.1} %",
            100.0 * c.out_of_range_share,
            c.out_of_range,
            c.rows,
            c.margin,
            100.0 * o.max_out_of_range
        ));
    }
    let verdict = if reference.is_none() {
        "no_reference"
    } else if checks.iter().any(|c| c.fired) {
        "retrain"
    } else if checks.is_empty() {
        // Nothing was compared: "ok" would claim a check that was never made.
        reasons.push(format!(
            "nothing checked: the new log has {} scored rows (all-rows check needs >= {}), and no |sdot| band or temperature bin has >= {} rows with a reference to compare",
            new.all.n, o.min_samples, o.min_samples
        ));
        "unchecked"
    } else {
        "ok"
    };
    ModelDrift {
        model: model.into(),
        new,
        reference_source: reference.as_ref().map(|r| r.source.clone()),
        reference: reference.map(|r| r.profile),
        coverage,
        checks,
        unchecked,
        verdict: verdict.into(),
        extrapolating,
        reasons,
    }
}

/// The checks of the new-log profile `new` against the reference profile `rp` (all rows, each
/// velocity band, each temperature bin), and the bands left unchecked for want of reference rows.
fn reference_checks(
    new: &ResidualProfile,
    rp: &ResidualProfile,
    o: &DriftOptions,
) -> (Vec<Check>, Vec<String>) {
    let mut checks = Vec::new();
    let mut unchecked = Vec::new();
    let mut all = check("all".into(), &new.all, None, Some(&rp.all), o);
    if let Some(c) = &mut all {
        c.reference_bin = "same".into();
    }
    checks.extend(all);
    // A velocity band only against the same band: the error level depends on the velocity.
    for (j, b) in new.bands.iter().enumerate() {
        let what = format!("band [{}, {}) rad/s", b.lo_rad_s, hi_text(b.hi_rad_s));
        let same = rp.bands.get(j).map(|x| &x.stats);
        match check(what.clone(), &b.stats, same, None, o) {
            Some(c) => checks.push(c),
            None if b.stats.n >= o.min_samples => unchecked.push(format!(
                "{what}: {} new rows, but the reference has {} (< {}): not compared",
                b.stats.n,
                same.map_or(0, |s| s.n),
                o.min_samples
            )),
            None => {}
        }
    }
    // A temperature bin against the same bin, else all rows (a hotter log has no same bin, and
    // its velocity mix is the log's, like the reference's all rows). Not against the `.fwt`'s
    // single RMSE (no rows behind it).
    if rp.all.n > 0 {
        for t in &new.temperature {
            checks.extend(check(
                format!("temperature [{}, {}) °C", t.lo_c, t.hi_c),
                &t.stats,
                rp.temperature_bin(t.lo_c),
                Some(&rp.all),
                o,
            ));
        }
    }
    (checks, unchecked)
}

/// A fired check in words: its rows, RMSE against the limit and mean shifts.
fn fired_text(c: &Check) -> String {
    format!(
        "{}: n {}, RMSE {} vs limit {:.4} (ref {} on {} rows, {}), mean {} vs ref {}, mean along the motion {} vs ref {} (limit ±{:.4})",
        c.what,
        c.new.n,
        fmt_opt(c.new.rmse_nm),
        c.rmse_limit_nm,
        fmt_opt(c.reference.rmse_nm),
        c.reference.n,
        if c.reference_bin == "same" {
            "same bin"
        } else {
            "all rows"
        },
        fmt_opt(c.new.mean_residual_nm),
        fmt_opt(c.reference.mean_residual_nm),
        fmt_opt(c.new.mean_along_motion_nm),
        fmt_opt(c.reference.mean_along_motion_nm),
        c.mean_shift_limit_nm
    )
}

/// The rule in words (the `rule` key).
pub fn rule_text(o: &DriftOptions) -> String {
    format!(
        "checks (each with >= {} new rows): all rows vs all rows; each |sdot| band vs the reference's same band if that has >= {} rows (else unchecked); each {} °C temperature bin vs the same bin if that has >= {} rows, else the reference's all rows; a check fires when RMSE_new > {}·RMSE_ref + {} Nm, or when the mean residual or the mean of residual·sign(sdot) moved by more than {}·RMSE_ref + {} Nm (residual = label - prediction); retrain if any fires; extrapolating if > {} % of rows are outside the .fwt input range (margin {})",
        o.min_samples,
        o.min_samples,
        o.temperature_bin_c,
        o.min_samples,
        o.rmse_ratio,
        o.floor_nm,
        o.mean_ratio,
        o.floor_nm,
        100.0 * o.max_out_of_range,
        o.range_margin
    )
}

/// Assembles the `drift` key from the per-model results.
pub fn report(models: Vec<ModelDrift>, o: &DriftOptions) -> DriftReport {
    let verdict = if models.iter().any(|m| m.verdict == "retrain") {
        "retrain"
    } else if models.iter().any(|m| m.verdict == "unchecked") {
        "unchecked"
    } else if models.iter().any(|m| m.verdict == "ok") {
        "ok"
    } else {
        "no_reference"
    };
    DriftReport {
        rule: rule_text(o),
        options: *o,
        verdict: verdict.into(),
        extrapolating: models.iter().any(|m| m.extrapolating),
        models,
    }
}

/// The drift section of the text output.
pub fn format_drift(d: &DriftReport) -> String {
    let mut s = format!(
        "\nDrift (residual = label - prediction, Nm): verdict {}{}\nrule: {}\n",
        d.verdict,
        if d.extrapolating {
            ", extrapolating"
        } else {
            ""
        },
        d.rule
    );
    for m in &d.models {
        s.push_str(&format!(
            "\n{}: {}{}; reference: {}\n",
            m.model,
            m.verdict,
            if m.extrapolating {
                ", extrapolating"
            } else {
                ""
            },
            m.reference_source.as_deref().unwrap_or("none")
        ));
        if let Some(c) = &m.coverage {
            s.push_str(&format!(
                "  out of the training input range: {} of {} rows ({:.2} %, margin {})\n",
                c.out_of_range,
                c.rows,
                100.0 * c.out_of_range_share,
                c.margin
            ));
        }
        s.push_str(&format!(
            "  {:<28} {:>8} {:>9} {:>9} {:>9} {:>8} {:>9} {:>9} {:>9} {:>6}\n",
            "rows",
            "n",
            "mean",
            "along",
            "rmse",
            "ref n",
            "ref mean",
            "ref along",
            "ref rmse",
            "fired"
        ));
        for c in &m.checks {
            s.push_str(&format!(
                "  {:<28} {:>8} {:>9} {:>9} {:>9} {:>8} {:>9} {:>9} {:>9} {:>6}\n",
                c.what,
                c.new.n,
                fmt_opt(c.new.mean_residual_nm),
                fmt_opt(c.new.mean_along_motion_nm),
                fmt_opt(c.new.rmse_nm),
                if c.reference_bin == "same" {
                    c.reference.n.to_string()
                } else {
                    format!("{}*", c.reference.n)
                },
                fmt_opt(c.reference.mean_residual_nm),
                fmt_opt(c.reference.mean_along_motion_nm),
                fmt_opt(c.reference.rmse_nm),
                if c.fired { "yes" } else { "no" }
            ));
        }
        for r in &m.reasons {
            s.push_str(&format!("  - {r}\n"));
        }
        for r in &m.unchecked {
            s.push_str(&format!("  ? {r}\n"));
        }
    }
    s.push_str("  (* = compared with the reference's all rows: its own temperature bin is too thin; ? = not compared)\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(rows: &[(f64, f64, f64)]) -> ResidualProfile {
        ResidualProfile::from_rows(rows.iter().copied(), &[0.0, 0.1], 5.0)
    }

    fn rows(n: usize, sdot: f64, t: f64, mean: f64, amp: f64) -> Vec<(f64, f64, f64)> {
        (0..n)
            .map(|k| (sdot, t, mean + if k % 2 == 0 { amp } else { -amp }))
            .collect()
    }

    fn opts() -> DriftOptions {
        DriftOptions {
            min_samples: 10,
            ..DriftOptions::default()
        }
    }

    #[test]
    fn same_residuals_are_ok_and_a_shifted_band_fires() {
        let mut r = rows(100, 0.05, 30.0, 0.0, 0.2);
        r.extend(rows(100, 0.5, 30.0, 0.0, 0.2));
        let reference = Reference {
            source: "reference_datasets".into(),
            profile: profile(&r),
        };
        let same = model_drift("m", profile(&r), Some(reference.clone()), None, &opts());
        assert_eq!(same.verdict, "ok");
        assert!(same.checks.iter().all(|c| !c.fired));
        // all + 2 bands + 1 temperature bin.
        assert_eq!(same.checks.len(), 4);

        // The fast band's friction grew by 0.3 Nm: a mean shift beyond 0.5·0.2 + 0.02.
        let mut shifted = rows(100, 0.05, 30.0, 0.0, 0.2);
        shifted.extend(rows(100, 0.5, 30.0, 0.3, 0.2));
        let d = model_drift(
            "m",
            profile(&shifted),
            Some(reference.clone()),
            None,
            &opts(),
        );
        assert_eq!(d.verdict, "retrain");
        let fired: Vec<&str> = d
            .checks
            .iter()
            .filter(|c| c.fired)
            .map(|c| c.what.as_str())
            .collect();
        assert!(fired.contains(&"band [0.1, inf) rad/s"), "{fired:?}");
        assert!(!fired.contains(&"band [0, 0.1) rad/s"), "{fired:?}");

        // A hotter log: its temperature bin is missing in the reference, compared with all rows.
        let hot = rows(100, 0.5, 52.0, 0.0, 0.25);
        let d = model_drift("m", profile(&hot), Some(reference.clone()), None, &opts());
        let t = d
            .checks
            .iter()
            .find(|c| c.what.starts_with("temperature"))
            .unwrap();
        assert_eq!(t.reference_bin, "all");
        assert!(!t.fired, "0.25 Nm RMSE is within 1.5·0.2 + 0.02");

        // A Coulomb increase: +0.3 Nm along the motion in both directions. The plain mean stays 0,
        // the mean along the motion moves.
        let mut coulomb = rows(100, 0.05, 30.0, 0.0, 0.2);
        coulomb.extend((0..100).map(|k| {
            let dir = if k % 4 < 2 { 1.0 } else { -1.0 };
            (
                0.5 * dir,
                30.0,
                dir * 0.3 + if k % 2 == 0 { 0.2 } else { -0.2 },
            )
        }));
        let d = model_drift(
            "m",
            profile(&coulomb),
            Some(reference.clone()),
            None,
            &opts(),
        );
        let fast = d
            .checks
            .iter()
            .find(|c| c.what == "band [0.1, inf) rad/s")
            .unwrap();
        assert!(fast.new.mean_residual_nm.unwrap().abs() < 1e-12);
        assert!((fast.new.mean_along_motion_nm.unwrap() - 0.3).abs() < 1e-12);
        assert!(fast.fired && d.verdict == "retrain");

        // A band the reference barely has is not compared (its error level is unknown).
        let slow_only = Reference {
            source: "reference_datasets".into(),
            profile: profile(&rows(100, 0.05, 30.0, 0.0, 0.2)),
        };
        let d = model_drift("m", profile(&r), Some(slow_only), None, &opts());
        assert!(d.checks.iter().all(|c| c.what != "band [0.1, inf) rad/s"));
        assert_eq!(d.unchecked.len(), 1, "{:?}", d.unchecked);
        assert!(d.unchecked[0].starts_with("band [0.1, inf) rad/s"));
    }

    #[test]
    fn fwt_reference_checks_all_rows_only_and_thin_sets_are_not_checked() {
        let reference = Reference {
            source: "fwt:val_rmse_nm".into(),
            profile: ResidualProfile {
                all: ResidualStats {
                    n: 0,
                    mean_residual_nm: None,
                    mean_along_motion_nm: None,
                    rmse_nm: Some(0.1),
                },
                ..ResidualProfile::default()
            },
        };
        let d = model_drift(
            "m",
            profile(&rows(100, 0.5, f64::NAN, 0.0, 0.5)),
            Some(reference),
            None,
            &opts(),
        );
        assert_eq!(d.checks.len(), 1);
        assert!(d.checks[0].fired && d.verdict == "retrain");

        let none = model_drift(
            "m",
            profile(&rows(5, 0.5, f64::NAN, 9.0, 0.0)),
            None,
            None,
            &opts(),
        );
        assert_eq!(none.verdict, "no_reference");
        assert!(none.checks.is_empty());
        let cov = Coverage {
            rows: 100,
            out_of_range: 6,
            out_of_range_share: 0.06,
            margin: 0.1,
        };
        let d = model_drift(
            "m",
            profile(&rows(5, 0.5, f64::NAN, 9.0, 0.0)),
            None,
            Some(cov),
            &opts(),
        );
        assert!(d.extrapolating && d.reasons.len() == 1);
        let r = report(vec![none, d], &opts());
        assert_eq!(
            (r.verdict.as_str(), r.extrapolating),
            ("no_reference", true)
        );
    }
}
