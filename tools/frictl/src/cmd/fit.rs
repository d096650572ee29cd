//! `frictl fit cv|scv|scv-code|lugre DATASET.csv` — fit a friction model to a preprocessed dataset
//! and print/write it as a `[[joint]]` TOML snippet in the daemon's config format, and as JSON
//! ([`FitFile`]).
//!
//! LuGre's static parameters (kc, kv, ks, vs, alpha) are those of the SCV fit (its smooth-sign ka is
//! dropped: the bristle state replaces it); the bristle stiffness σ0 and damping σ1 are given
//! (`--sigma0`, default kc / 1 mrad: the Coulomb level is reached at 1 mrad of joint-side
//! pre-sliding deflection; `--sigma1`, default 0).

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
use serde::{Deserialize, Serialize};

pub use frictl_cli::fit::*;

/// Runs `frictl fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let outputs: Vec<&std::path::Path> = [&args.toml, &args.json]
        .into_iter()
        .flatten()
        .map(|p| p.as_path())
        .collect();
    super::check_outputs(
        &[&args.dataset, &args.dataset.with_extension("json")],
        &outputs,
    )?;
    if let Some(s0) = args.sigma0 {
        anyhow::ensure!(
            s0.is_finite() && s0 > 0.0,
            "--sigma0 {s0}: must be finite and > 0"
        );
    }
    anyhow::ensure!(
        args.sigma1.is_finite() && args.sigma1 >= 0.0,
        "--sigma1 {}: must be finite and ≥ 0",
        args.sigma1
    );
    let ds = Dataset::read_csv(&args.dataset)?;
    let target = if args.truth {
        ds.tau_f_true_nm
            .clone()
            .context("--truth: the dataset has no tau_f_true_nm column")?
    } else {
        ds.tau_f_label_nm.clone()
    };
    let mut mask = ds.valid.clone();
    if !args.test_runs.is_empty() {
        let side: Option<frictionless_dataset::DatasetSidecar> =
            frictionless::regular_file::read_text(&args.dataset.with_extension("json"))
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok());
        let runs = frictionless_dataset::dataset_runs(&args.dataset, side.as_ref(), &ds);
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
    let opts = FitOptions {
        method: args.method,
        adam_loss: args.loss,
        adam_epochs: args.epochs,
        adam_lr: args.lr,
        bounds: FitBounds {
            ka_min: args.ka_min,
            ka_max: args.ka_max,
            vs_min: args.vs_min,
            vs_max: args.vs_max,
            alpha_min: args.alpha_min,
            alpha_max: args.alpha_max,
            ks_max_ratio: args.ks_max_ratio,
        },
        ..FitOptions::default()
    };
    let started = std::time::Instant::now();
    let (toml, json) = match args.model.0 {
        ModelKind::Cv => report(
            fit::<CvParams>(&v, &t, &opts).map_err(at_line)?,
            |params| FittedModel::Cv { params },
            &ds,
            &target,
            &args,
        ),
        ModelKind::Scv => report(
            fit::<ScvParams>(&v, &t, &opts).map_err(at_line)?,
            |params| FittedModel::Scv { params },
            &ds,
            &target,
            &args,
        ),
        ModelKind::ScvCode => report(
            fit::<ScvCodeParams>(&v, &t, &opts).map_err(at_line)?,
            |params| FittedModel::ScvCode { params },
            &ds,
            &target,
            &args,
        ),
        ModelKind::Lugre => {
            let (sigma0, sigma1) = (args.sigma0, args.sigma1);
            report(
                fit::<ScvParams>(&v, &t, &opts).map_err(at_line)?,
                move |s: ScvParams| FittedModel::Lugre {
                    params: LugreParams {
                        kc: s.kc,
                        kv: s.kv,
                        ks: s.ks,
                        vs: s.vs,
                        alpha: s.alpha,
                        sigma0: sigma0.unwrap_or(s.kc / 1e-3),
                        sigma1,
                    },
                },
                &ds,
                &target,
                &args,
            )
        }
        kind @ (ModelKind::None | ModelKind::Pinn) => {
            anyhow::bail!("frictl fit: {kind} is not a model `frictl fit` fits")
        }
    }?;
    eprintln!(
        "frictl fit: {} of {} samples selected, fitted in {:.3} s",
        v.len(),
        ds.len(),
        started.elapsed().as_secs_f64()
    );
    println!("{toml}");
    if let Some(p) = &args.toml {
        frictionless::output_file::write(p, &toml)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(p) = &args.json {
        frictionless::output_file::write(p, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
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

fn toml_f64(v: f64) -> String {
    if v == f64::INFINITY {
        "inf".into()
    } else {
        format!("{v:e}")
    }
}

fn report<M: Fittable>(
    r: FitResult<M>,
    tagged: impl Fn(M) -> FittedModel,
    ds: &Dataset,
    target: &[f64],
    args: &Args,
) -> anyhow::Result<(String, FitFile)> {
    if !r.at_bounds.is_empty() {
        eprintln!(
            "frictl fit: parameters on a bound: {} (the unbounded optimum lies outside; see --help for the bound flags)",
            r.at_bounds.join(", ")
        );
    }
    let (rmse_valid, _) = frictionless_ident::fit::errors(
        &r.model,
        &select(&ds.sdot_rad_s, &ds.valid),
        &select(target, &ds.valid),
    );
    let fitted = tagged(r.model);
    if let FittedModel::Lugre { params } = &fitted {
        params
            .validate()
            .map_err(|e| anyhow::anyhow!("frictl fit lugre: fitted {e}"))?;
    }
    // The serialised name is a quoted string, valid TOML.
    let model_name = serde_json::to_value(FitFile::daemon_name(&fitted))?;
    let mut s = format!(
        "# frictl fit {} ({:?}) on {}: {} samples, RMSE {:.4} Nm on the fitted samples, {:.4} Nm on all valid samples\n[[joint]]\nfriction_model = {model_name}\n",
        fitted.tag(),
        args.method,
        args.dataset.display(),
        r.n_samples,
        r.rmse_nm,
        rmse_valid
    );
    for (k, v) in daemon_keys(&fitted) {
        s += &format!("{k} = {}\n", toml_f64(v));
    }
    let json = FitFile {
        fitted,
        method: args.method,
        param_names: match fitted {
            FittedModel::Lugre { .. } => LugreParams::PARAM_NAMES.as_slice(),
            _ => M::PARAM_NAMES,
        }
        .iter()
        .map(|n| (*n).to_owned())
        .collect(),
        daemon_friction_model: fitted.kind().daemon_kind(),
        rmse_fitted_nm: r.rmse_nm,
        mae_fitted_nm: r.mae_nm,
        rmse_valid_nm: rmse_valid,
        n_samples: r.n_samples,
        iterations: r.iterations,
        bounds: FitBounds {
            ka_min: args.ka_min,
            ka_max: args.ka_max,
            vs_min: args.vs_min,
            vs_max: args.vs_max,
            alpha_min: args.alpha_min,
            alpha_max: args.alpha_max,
            ks_max_ratio: args.ks_max_ratio,
        },
        at_bounds: r.at_bounds.clone(),
        sliding_quadrants: args.sliding_quadrants,
        v_min_rad_s: args.v_min,
        dataset: args.dataset.display().to_string(),
    };
    Ok((s, json))
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
