//! `frictl fit cv|scv|scv-code|lugre DATASET.csv` — fit a friction model to a preprocessed dataset
//! and print/write it as a `[[joint]]` TOML snippet in the daemon's config format, and as JSON
//! ([`FitFile`], the one fit report; `docs/fitting.md` documents its keys).
//!
//! The static models are fitted per sample ([`frictionless_ident::fit`]); the SCV by
//! [`frictionless_ident::scv_fit`] (the low-speed rows in, bounds from the data, and the CV with
//! ks = kc when the SCV does not beat it on a validation block of the rows). LuGre is identified from
//! the time series ([`frictionless_ident::lugre_fit`]): the Stribeck curve from the sliding rows,
//! then the bristle stiffness σ0 and damping σ1 by simulating the bristle state over the dataset's
//! chunks, then all seven together (`--no-joint-refinement` skips this); `--sigma0` / `--sigma1`
//! hold one at a given value instead.
//!
//! Every model is also scored on held-out data (`--test-run` runs of the dataset, `--test-dataset`
//! files) on the same rows: valid, past `--warmup-travel-rad` of travel in their chunk.

use anyhow::Context;
use frictiond_config::ModelKind;
use frictionless::friction::{CvParams, ScvCodeParams, ScvParams};
use frictionless::lugre::LugreParams;
use frictionless_dataset::Dataset;
use frictionless_dataset::fit_file::FittedModel;
use frictionless_ident::fit::{
    FitBounds, FitError, FitOptions, FitResult, Fittable, Method, fit, select,
    sliding_quadrant_mask,
};
use frictionless_ident::lugre_fit::{
    LugreFitOptions, LugreSeries, LugreStage, fit_lugre, lugre_errors, static_errors, time_segments,
};
use frictionless_ident::scv_fit::{ScvFit, ScvFitInput, ScvValidation, fit_scv_guarded};
use serde::{Deserialize, Serialize};

pub use frictl_cli::fit::*;

/// Runs `frictl fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    check_args(&args)?;
    let ds = Dataset::read_csv(&args.dataset)?;
    let target = target_column(&ds, &args.dataset, args.truth)?;
    let mut mask = ds.valid.clone();
    let held_runs = held_out_runs(&args, &ds, &mut mask)?;
    // The rows the fit may use (before the sliding selection) and the held-out data.
    let use_rows = mask.clone();
    let mut held_out = held_runs;
    for p in &args.test_datasets {
        let t = Dataset::read_csv(p).with_context(|| format!("--test-dataset {}", p.display()))?;
        let target = target_column(&t, p, args.truth)?;
        held_out.push(HeldOutData {
            source: p.display().to_string(),
            rows: t.valid.clone(),
            target: Some(target),
            ds: Some(t),
        });
    }
    if args.sliding_quadrants {
        for (m, s) in
            mask.iter_mut()
                .zip(sliding_quadrant_mask(&ds.sdot_rad_s, &target, args.v_min))
        {
            *m &= s;
        }
    }
    let v = select(&ds.sdot_rad_s, &mask);
    let t = select(&target, &mask);
    // The fit numbers the selected samples; errors name the dataset's CSV line instead (one line
    // per sample after the header line).
    let rows: Vec<usize> = mask
        .iter()
        .enumerate()
        .filter_map(|(i, &m)| m.then_some(i))
        .collect();
    let at_line = |e: FitError| -> anyhow::Error {
        match e {
            FitError::NonFinite { index, v, tau } => {
                let row = rows.get(index).copied().unwrap_or(index);
                anyhow::anyhow!(
                    "{}: line {}: sample not finite (sdot_rad_s = {v}, {} = {tau})",
                    args.dataset.display(),
                    row + 2,
                    if args.truth {
                        "tau_f_true_nm"
                    } else {
                        "tau_f_label_nm"
                    }
                )
            }
            e => anyhow::Error::new(e),
        }
    };
    let opts = fit_options(&args);
    let started = std::time::Instant::now();
    let ctx = Ctx {
        ds: &ds,
        target: &target,
        held_out: &held_out,
        args: &args,
    };
    let summary = match args.model.0 {
        ModelKind::Cv => ctx
            .static_summary(fit::<CvParams>(&v, &t, &opts).map_err(at_line)?, |params| {
                FittedModel::Cv { params }
            })?,
        ModelKind::Scv => ctx.scv_summary(&use_rows, &mask, &opts)?,
        ModelKind::ScvCode => ctx.static_summary(
            fit::<ScvCodeParams>(&v, &t, &opts).map_err(at_line)?,
            |params| FittedModel::ScvCode { params },
        )?,
        ModelKind::Lugre => ctx.lugre_summary(&use_rows, &mask, opts)?,
        kind @ (ModelKind::None | ModelKind::Pinn) => {
            anyhow::bail!("frictl fit: {kind} is not a model `frictl fit` fits")
        }
    };
    let (toml, json) = report(summary, &args)?;
    eprintln!(
        "frictl fit: {} of {} samples selected, fitted in {:.3} s",
        json.n_samples,
        ds.len(),
        started.elapsed().as_secs_f64()
    );
    for h in &json.held_out {
        eprintln!(
            "frictl fit: held-out {}: RMSE {:.4} Nm on {} rows",
            h.source, h.rmse_nm, h.rows
        );
    }
    write_outputs(&args, &toml, &json)
}

/// Refuses an output that would overwrite an input and the out-of-range σ and warm-up options, before
/// any work.
fn check_args(args: &Args) -> anyhow::Result<()> {
    let outputs: Vec<&std::path::Path> = [&args.toml, &args.json]
        .into_iter()
        .flatten()
        .map(|p| p.as_path())
        .collect();
    let mut inputs: Vec<std::path::PathBuf> =
        vec![args.dataset.clone(), args.dataset.with_extension("json")];
    for t in &args.test_datasets {
        inputs.push(t.clone());
        inputs.push(t.with_extension("json"));
    }
    let input_refs: Vec<&std::path::Path> = inputs.iter().map(|p| p.as_path()).collect();
    super::check_outputs(&input_refs, &outputs)?;
    if let Some(s0) = args.sigma0 {
        anyhow::ensure!(
            s0.is_finite() && s0 > 0.0,
            "--sigma0 {s0}: must be finite and > 0"
        );
    }
    if let Some(s1) = args.sigma1 {
        anyhow::ensure!(
            s1.is_finite() && s1 >= 0.0,
            "--sigma1 {s1}: must be finite and ≥ 0"
        );
    }
    anyhow::ensure!(
        args.warmup_travel_rad.is_finite() && args.warmup_travel_rad >= 0.0,
        "--warmup-travel-rad {}: must be finite and ≥ 0",
        args.warmup_travel_rad
    );
    Ok(())
}

/// The runs `--test-run` names, held out of the fit (their chunks cleared in `mask`) and scored.
fn held_out_runs(args: &Args, ds: &Dataset, mask: &mut [bool]) -> anyhow::Result<Vec<HeldOutData>> {
    let mut held_runs = Vec::new();
    if !args.test_runs.is_empty() {
        let side: Option<frictionless_dataset::DatasetSidecar> =
            frictionless::regular_file::read_text(&args.dataset.with_extension("json"))
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok());
        let runs = frictionless_dataset::dataset_runs(&args.dataset, side.as_ref(), ds);
        let mut held = Vec::new();
        for name in &args.test_runs {
            let run = runs.iter().find(|r| &r.name == name).with_context(|| {
                let known: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
                format!(
                    "--test-run {name}: {} has no run of that name (runs: {})",
                    args.dataset.display(),
                    known.join(", ")
                )
            })?;
            held.extend(run.chunks.iter().copied());
        }
        for (m, c) in mask.iter_mut().zip(&ds.chunk) {
            *m &= !held.contains(c);
        }
        let rows: Vec<bool> = ds
            .valid
            .iter()
            .zip(&ds.chunk)
            .map(|(&v, c)| v && held.contains(c))
            .collect();
        held_runs.push(HeldOutData {
            source: format!(
                "{} runs {}",
                args.dataset.display(),
                args.test_runs.join(",")
            ),
            ds: None,
            target: None,
            rows,
        });
    }
    Ok(held_runs)
}

/// The parameter bounds from the command line (the others at their defaults).
fn fit_bounds(args: &Args) -> FitBounds {
    FitBounds {
        ka_min: args.ka_min,
        ka_max: args.ka_max,
        vs_min: args.vs_min,
        vs_max: args.vs_max,
        alpha_min: args.alpha_min,
        alpha_max: args.alpha_max,
        ks_max_ratio: args.ks_max_ratio,
        ..FitBounds::default()
    }
}

/// The solver's options from the command line (bounds, method, Adam's loss, epochs and rate).
fn fit_options(args: &Args) -> FitOptions {
    let bounds = fit_bounds(args);
    FitOptions {
        method: args.method,
        adam_loss: args.loss,
        adam_epochs: args.epochs,
        adam_lr: args.lr,
        bounds,
        ..FitOptions::default()
    }
}

/// Prints the TOML and writes the `--toml` and `--json` files.
fn write_outputs(args: &Args, toml: &str, json: &impl Serialize) -> anyhow::Result<()> {
    println!("{toml}");
    if let Some(p) = &args.toml {
        frictionless::output_file::write(p, toml)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(p) = &args.json {
        frictionless::output_file::write(p, serde_json::to_string_pretty(json)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

/// The fit target of a dataset: the label, or with `--truth` the simulator's column.
fn target_column(ds: &Dataset, path: &std::path::Path, truth: bool) -> anyhow::Result<Vec<f64>> {
    if truth {
        ds.tau_f_true_nm
            .clone()
            .with_context(|| format!("--truth: {} has no tau_f_true_nm column", path.display()))
    } else {
        Ok(ds.tau_f_label_nm.clone())
    }
}

/// Held-out rows: of the fitted dataset (`ds`, `target` = `None`) or of a `--test-dataset`.
struct HeldOutData {
    source: String,
    ds: Option<Dataset>,
    target: Option<Vec<f64>>,
    rows: Vec<bool>,
}

/// What a fit hands to [`report`].
struct Summary {
    fitted: FittedModel,
    param_names: Vec<String>,
    rmse_fitted_nm: f64,
    mae_fitted_nm: f64,
    rmse_valid_nm: f64,
    n_samples: usize,
    iterations: usize,
    at_bounds: Vec<String>,
    held_out: Vec<HeldOutScore>,
    lugre: Option<LugreReport>,
    /// The bounds the fit used when the data narrowed the flags' (SCV).
    bounds: Option<FitBounds>,
    scv: Option<ScvReport>,
}

/// A model's (RMSE, MAE, rows) on a series.
type Scorer<'s> = dyn Fn(&LugreSeries) -> anyhow::Result<(f64, f64, usize)> + 's;

/// The fitted dataset, its target and the held-out data.
struct Ctx<'a> {
    ds: &'a Dataset,
    target: &'a [f64],
    held_out: &'a [HeldOutData],
    args: &'a Args,
}

/// A dataset's rows as a time series (`rows` enter the error).
fn series_of<'a>(
    ds: &'a Dataset,
    target: &'a [f64],
    rows: &'a [bool],
    sliding: &'a [bool],
    segment: &'a [u32],
    dt_s: f64,
) -> LugreSeries<'a> {
    LugreSeries {
        v_rad_s: &ds.sdot_rad_s,
        tau_nm: target,
        segment,
        use_row: rows,
        sliding,
        dt_s,
    }
}

impl Ctx<'_> {
    /// Scores a model on each held-out data set: `score(series)` gives (RMSE, MAE, rows).
    fn held_out_scores(&self, score: &Scorer) -> anyhow::Result<Vec<HeldOutScore>> {
        let mut out = Vec::new();
        for h in self.held_out {
            let ds = h.ds.as_ref().unwrap_or(self.ds);
            let target = h.target.as_deref().unwrap_or(self.target);
            let (dt, seg) = time_segments(&ds.time_s, &ds.chunk)
                .map_err(|e| anyhow::anyhow!("held-out {}: time column: {e}", h.source))?;
            let series = series_of(ds, target, &h.rows, &h.rows, &seg, dt);
            let (rmse_nm, mae_nm, rows) =
                score(&series).with_context(|| format!("held-out {}", h.source))?;
            out.push(HeldOutScore {
                source: h.source.clone(),
                rows,
                rmse_nm,
                mae_nm,
            });
        }
        Ok(out)
    }

    fn static_summary<M: Fittable>(
        &self,
        r: FitResult<M>,
        tagged: impl Fn(M) -> FittedModel,
    ) -> anyhow::Result<Summary> {
        let (rmse_valid, _) = frictionless_ident::fit::errors(
            &r.model,
            &select(&self.ds.sdot_rad_s, &self.ds.valid),
            &select(self.target, &self.ds.valid),
        );
        let warmup = self.args.warmup_travel_rad;
        let model = r.model;
        let held_out = self.held_out_scores(&|s| Ok(static_errors(&model, s, warmup)?))?;
        Ok(Summary {
            fitted: tagged(r.model),
            param_names: M::PARAM_NAMES.iter().map(|n| (*n).to_owned()).collect(),
            rmse_fitted_nm: r.rmse_nm,
            mae_fitted_nm: r.mae_nm,
            rmse_valid_nm: rmse_valid,
            n_samples: r.n_samples,
            iterations: r.iterations,
            at_bounds: r.at_bounds,
            held_out,
            lugre: None,
            bounds: None,
            scv: None,
        })
    }

    /// The SCV ([`fit_scv_guarded`]): `use_rows` are the rows it may use, `cv_rows` (within them)
    /// the CV's selection; the SCV fits the sliding rows down to `--stribeck-v-min`.
    fn scv_summary(
        &self,
        use_rows: &[bool],
        cv_rows: &[bool],
        opts: &FitOptions,
    ) -> anyhow::Result<Summary> {
        let a = self.args;
        anyhow::ensure!(
            a.stribeck_v_min.is_finite() && a.stribeck_v_min >= 0.0,
            "--stribeck-v-min {}: must be finite and ≥ 0",
            a.stribeck_v_min
        );
        let scv_mask: Vec<bool> = if a.sliding_quadrants {
            sliding_quadrant_mask(&self.ds.sdot_rad_s, self.target, a.stribeck_v_min)
        } else {
            vec![true; self.ds.len()]
        };
        let v = select(&self.ds.sdot_rad_s, use_rows);
        let t = select(self.target, use_rows);
        let scv_rows = select_bool(&scv_mask, use_rows);
        let cv_rows = select_bool(cv_rows, use_rows);
        let input = ScvFitInput {
            v_rad_s: &v,
            tau_nm: &t,
            scv_rows: &scv_rows,
            cv_rows: &cv_rows,
            low_speed_rad_s: a.v_min,
            validation_fraction: a.validation_fraction,
        };
        let f: ScvFit = fit_scv_guarded(&input, opts)
            .map_err(|e| anyhow::anyhow!("{}: frictl fit scv: {e}", a.dataset.display()))?;
        match &f.fallback {
            Some(why) => eprintln!("frictl fit scv: {why}"),
            None => eprintln!(
                "frictl fit scv: validation block ({} rows): RMSE SCV {:.4} Nm < CV {:.4} Nm",
                f.validation.rows,
                f.validation.scv_rmse_nm.unwrap_or(f64::NAN),
                f.validation.cv_rmse_nm
            ),
        }
        let mut s = self.static_summary(f.result, |params| FittedModel::Scv { params })?;
        s.bounds = Some(f.bounds);
        s.scv = Some(ScvReport {
            validation: f.validation,
            fallback: f.fallback,
            cv: f.cv.model,
        });
        Ok(s)
    }

    /// LuGre from the time series: `use_rows` may enter the cost, `sliding` (within them) give the
    /// Stribeck curve.
    fn lugre_summary(
        &self,
        use_rows: &[bool],
        sliding: &[bool],
        static_fit: FitOptions,
    ) -> anyhow::Result<Summary> {
        let a = self.args;
        let (dt_s, seg) = time_segments(&self.ds.time_s, &self.ds.chunk)
            .map_err(|e| anyhow::anyhow!("{}: time column: {e}", a.dataset.display()))?;
        let series = series_of(self.ds, self.target, use_rows, sliding, &seg, dt_s);
        let opts = LugreFitOptions {
            static_fit,
            warmup_travel_rad: a.warmup_travel_rad,
            max_evals_joint: if a.no_joint_refinement {
                0
            } else {
                LugreFitOptions::default().max_evals_joint
            },
            sigma0_fixed: a.sigma0,
            sigma1_fixed: a.sigma1,
            ..LugreFitOptions::default()
        };
        let r = fit_lugre(&series, &opts)
            .map_err(|e| anyhow::anyhow!("{}: frictl fit lugre: {e}", a.dataset.display()))?;
        let valid = series_of(self.ds, self.target, &self.ds.valid, sliding, &seg, dt_s);
        let (rmse_valid, _, _) = lugre_errors(&r.params, &valid, a.warmup_travel_rad)?;
        let params = r.params;
        let held_out =
            self.held_out_scores(&|s| Ok(lugre_errors(&params, s, a.warmup_travel_rad)?))?;
        if !r.static_fit.at_bounds.is_empty() {
            eprintln!(
                "frictl fit lugre: Stribeck stage parameters on a bound: {}",
                r.static_fit.at_bounds.join(", ")
            );
        }
        let sf = r.static_fit.model;
        Ok(Summary {
            fitted: FittedModel::Lugre { params },
            param_names: LugreParams::PARAM_NAMES
                .iter()
                .map(|n| (*n).to_owned())
                .collect(),
            rmse_fitted_nm: r.rmse_nm,
            mae_fitted_nm: r.mae_nm,
            rmse_valid_nm: rmse_valid,
            n_samples: r.n_samples,
            iterations: r.stages.iter().map(|s| s.evaluations).sum(),
            at_bounds: r.at_bounds,
            held_out,
            bounds: None,
            scv: None,
            lugre: Some(LugreReport {
                dt_s,
                warmup_travel_rad: a.warmup_travel_rad,
                stribeck_fit: sf,
                stribeck_rmse_nm: r.static_fit.rmse_nm,
                stribeck_at_bounds: r.static_fit.at_bounds,
                stages: r.stages,
                held: [("sigma0", a.sigma0), ("sigma1", a.sigma1)]
                    .into_iter()
                    .filter(|(_, v)| v.is_some())
                    .map(|(n, _)| n.to_owned())
                    .collect(),
            }),
        })
    }
}

/// Daemon `[[joint]]` keys for a fitted model (SCV code form = SCV with ka = inf, alpha = 2).
pub(crate) fn daemon_keys(m: &FittedModel) -> Vec<(&'static str, f64)> {
    if let FittedModel::Lugre { params: l } = m {
        return vec![
            ("kc", l.kc),
            ("kv", l.kv),
            ("ks", l.ks),
            ("vs", l.vs),
            ("alpha", l.alpha),
            ("sigma0", l.sigma0),
            ("sigma1", l.sigma1),
        ];
    }
    if let FittedModel::Cv { params: c } = m {
        vec![("kc", c.kc), ("kv", c.kv), ("ka", c.ka)]
    } else {
        let s = m.to_scv();
        vec![
            ("kc", s.kc),
            ("kv", s.kv),
            ("ka", s.ka),
            ("ks", s.ks),
            ("vs", s.vs),
            ("alpha", s.alpha),
        ]
    }
}

/// The unit of a fitted parameter, by its name in any model's list.
fn param_unit(name: &str) -> &'static str {
    match name {
        "kc" | "ks" | "fc" | "fs" => "Nm",
        "kv" | "fv" | "sigma1" => "Nm·s/rad",
        "ka" => "s/rad",
        "vs" => "rad/s",
        "sigma0" => "Nm/rad",
        _ => "1",
    }
}

fn toml_f64(v: f64) -> String {
    if v == f64::INFINITY {
        "inf".into()
    } else {
        format!("{v:e}")
    }
}

fn report(r: Summary, args: &Args) -> anyhow::Result<(String, FitFile)> {
    if !r.at_bounds.is_empty() {
        eprintln!(
            "frictl fit: parameters on a bound: {} (the unbounded optimum lies outside; see --help for the bound flags)",
            r.at_bounds.join(", ")
        );
    }
    let fitted = r.fitted;
    if let FittedModel::Lugre { params } = &fitted {
        params
            .validate()
            .map_err(|e| anyhow::anyhow!("frictl fit lugre: fitted {e}"))?;
    }
    // The serialised name is a quoted string, valid TOML.
    let model_name = serde_json::to_value(FitFile::daemon_name(&fitted))?;
    let mut s = format!(
        "# frictl fit {} ({:?}) on {}: {} samples, RMSE {:.4} Nm on the fitted samples, {:.4} Nm on all valid samples\n",
        fitted.tag(),
        args.method,
        args.dataset.display(),
        r.n_samples,
        r.rmse_fitted_nm,
        r.rmse_valid_nm
    );
    for h in &r.held_out {
        s += &format!(
            "# held-out {}: RMSE {:.4} Nm on {} rows\n",
            h.source, h.rmse_nm, h.rows
        );
    }
    if !r.at_bounds.is_empty() {
        s += &format!("# on a bound: {}\n", r.at_bounds.join(", "));
    }
    s += &format!("[[joint]]\nfriction_model = {model_name}\n");
    for (k, v) in daemon_keys(&fitted) {
        s += &format!("{k} = {}\n", toml_f64(v));
    }
    let json = FitFile {
        fitted,
        method: args.method,
        param_units: r
            .param_names
            .iter()
            .map(|n| param_unit(n).to_owned())
            .collect(),
        param_names: r.param_names,
        daemon_friction_model: fitted.kind().daemon_kind(),
        rmse_fitted_nm: r.rmse_fitted_nm,
        mae_fitted_nm: r.mae_fitted_nm,
        rmse_valid_nm: r.rmse_valid_nm,
        n_samples: r.n_samples,
        iterations: r.iterations,
        bounds: r.bounds.unwrap_or_else(|| fit_bounds(args)),
        at_bounds: r.at_bounds,
        sliding_quadrants: args.sliding_quadrants,
        v_min_rad_s: args.v_min,
        dataset: args.dataset.display().to_string(),
        held_out: r.held_out,
        lugre: r.lugre,
        scv: r.scv,
    };
    Ok((s, json))
}

/// The error of a fitted model on one held-out data set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOutScore {
    /// The data: `DATASET runs NAMES` (`--test-run`) or a `--test-dataset` path.
    pub source: String,
    /// Rows scored (valid, past the warm-up travel of their chunk).
    pub rows: usize,
    /// RMSE [Nm].
    pub rmse_nm: f64,
    /// MAE [Nm].
    pub mae_nm: f64,
}

/// How the SCV fit decided between the SCV and the CV ([`fit_scv_guarded`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScvReport {
    /// The validation block: both models' RMSE there.
    pub validation: ScvValidation,
    /// Why the SCV is the CV (`ks = kc`); absent when the SCV was better on the validation block.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback: Option<String>,
    /// The CV fitted on the CV's rows (the SCV's fallback).
    pub cv: CvParams,
}

/// `x` where `mask` is true.
fn select_bool(x: &[bool], mask: &[bool]) -> Vec<bool> {
    x.iter()
        .zip(mask)
        .filter_map(|(&v, &m)| m.then_some(v))
        .collect()
}

/// How a LuGre fit got its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LugreReport {
    /// The row step the bristle state was integrated at [s].
    pub dt_s: f64,
    /// Travel from a chunk's start before its rows entered the cost [rad].
    pub warmup_travel_rad: f64,
    /// Stage 1: the static SCV fit to the sliding rows (its ka is not part of LuGre).
    pub stribeck_fit: ScvParams,
    /// Its RMSE on the sliding rows [Nm].
    pub stribeck_rmse_nm: f64,
    /// Its parameters on a bound.
    pub stribeck_at_bounds: Vec<String>,
    /// RMSE after each stage on the cost rows.
    pub stages: Vec<LugreStage>,
    /// Parameters held at a given value (`--sigma0`, `--sigma1`), not identified.
    pub held: Vec<String>,
}

/// The whole JSON `frictl fit --json` writes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitFile {
    /// `model` and `params`.
    #[serde(flatten)]
    pub fitted: FittedModel,
    /// Solver.
    pub method: Method,
    /// Parameter names in the fitter's order.
    pub param_names: Vec<String>,
    /// The unit of each parameter, in `param_names` order (absent in files written before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub param_units: Vec<String>,
    /// The daemon's `friction_model` for the snippet.
    #[serde(with = "frictiond_config::friction_model_name")]
    pub daemon_friction_model: ModelKind,
    /// RMSE on the fitted (selected) samples [Nm].
    pub rmse_fitted_nm: f64,
    /// MAE on the fitted samples [Nm].
    pub mae_fitted_nm: f64,
    /// RMSE on all valid samples [Nm].
    pub rmse_valid_nm: f64,
    /// Fitted samples.
    pub n_samples: usize,
    /// Solver iterations.
    pub iterations: usize,
    /// Parameter bounds the solver enforced.
    pub bounds: FitBounds,
    /// Parameters that ended on a bound.
    pub at_bounds: Vec<String>,
    /// Whether only sliding 1st/3rd-quadrant samples were fitted.
    pub sliding_quadrants: bool,
    /// Velocity threshold of that selection [rad/s].
    pub v_min_rad_s: f64,
    /// The dataset CSV.
    pub dataset: String,
    /// The error on each held-out data set (`--test-run`, `--test-dataset`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_out: Vec<HeldOutScore>,
    /// LuGre: the stages of the identification.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lugre: Option<LugreReport>,
    /// SCV: the validation block and the fallback to the CV.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scv: Option<ScvReport>,
}

impl FitFile {
    /// The daemon's `friction_model` value for `fitted` (the code form runs as SCV with ka = ∞,
    /// α = 2), serialisable as the config writes it.
    fn daemon_name(fitted: &FittedModel) -> DaemonName {
        DaemonName(fitted.kind().daemon_kind())
    }
}

/// A `friction_model` value, serialised as the config writes it.
#[derive(Serialize)]
struct DaemonName(#[serde(with = "frictiond_config::friction_model_name")] ModelKind);

#[cfg(test)]
mod tests {
    use super::*;

    /// A file as `frictl fit scv --json` wrote it.
    const WRITTEN_BEFORE: &str = r#"{
  "model": "Scv",
  "method": "lm",
  "params": {"kc": 1.0005, "ka": 2.78, "kv": 0.29, "ks": 6.0, "vs": 0.13, "alpha": 0.6},
  "param_names": ["kc", "ka", "kv", "ks", "vs", "alpha"],
  "daemon_friction_model": "coulomb_viscous_stribeck",
  "rmse_fitted_nm": 0.5, "mae_fitted_nm": 0.4, "rmse_valid_nm": 0.6,
  "n_samples": 1000, "iterations": 12,
  "bounds": {"ka_min": 0.1, "ka_max": 200.0, "vs_min": 0.001, "vs_max": 10.0, "alpha_min": 0.2,
             "alpha_max": 5.0, "ks_max_ratio": 10.0},
  "at_bounds": [],
  "sliding_quadrants": true,
  "v_min_rad_s": 0.03,
  "dataset": "d.csv"
}"#;

    #[test]
    fn files_written_before_read_and_round_trip() {
        let f: FitFile = serde_json::from_str(WRITTEN_BEFORE).unwrap();
        assert_eq!(f.fitted.tag(), "Scv");
        assert_eq!(f.method, Method::Lm);
        assert_eq!(f.daemon_friction_model, ModelKind::Scv);
        assert_eq!(f.fitted.to_scv().alpha, 0.6);
        let again: FitFile = serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
        assert_eq!(again, f);
        // The written JSON keeps the keys (and tag) it had.
        let v: serde_json::Value = serde_json::to_value(&f).unwrap();
        let old: serde_json::Value = serde_json::from_str(WRITTEN_BEFORE).unwrap();
        let keys =
            |v: &serde_json::Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
        let (mut a, mut b) = (keys(&v), keys(&old));
        a.sort();
        b.sort();
        assert_eq!(a, b);
        assert_eq!(v["model"], "Scv");
    }
}
