//! Arguments of `frictl fit`.

use frictiond_config::ModelKind;
use frictionless_ident::fit::{FitBounds, Loss, Method};
use std::path::PathBuf;

/// Model to fit: a kind of the core's list that has a fit-file tag ([`ModelKind::fit_tag`]); the
/// CLI choice is its [`ModelKind::name`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FitModel(pub ModelKind);

/// The fittable kinds, in list order.
const FIT_MODELS: [FitModel; 4] = {
    let mut out = [FitModel(ModelKind::None); 4];
    let mut n = 0;
    let mut k = 0;
    while k < ModelKind::ALL.len() {
        if ModelKind::ALL[k].fit_tag().is_some() {
            out[n] = FitModel(ModelKind::ALL[k]);
            n += 1;
        }
        k += 1;
    }
    assert!(
        n == out.len(),
        "FIT_MODELS has one entry per kind with a fit tag"
    );
    out
};

impl clap::ValueEnum for FitModel {
    fn value_variants<'a>() -> &'a [Self] {
        &FIT_MODELS
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.0.name()).help(self.0.description()))
    }
}

/// Arguments of `frictl fit`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Model.
    #[arg(value_enum)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub model: FitModel,
    /// Dataset CSV from `frictl preprocess`.
    pub dataset: PathBuf,
    /// Solver.
    #[arg(long, value_parser = super::stage::named::<Method>(Method::NAMES), default_value_t = Method::Lm)]
    #[serde(serialize_with = "super::stage::as_name")]
    pub method: Method,
    /// Adam loss (`--method adam`).
    #[arg(long, value_parser = super::stage::named::<Loss>(Loss::NAMES), default_value_t = Loss::L1)]
    #[serde(serialize_with = "super::stage::as_name")]
    pub loss: Loss,
    /// Adam epochs.
    #[arg(long, default_value_t = 3000)]
    pub epochs: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 0.01)]
    pub lr: f64,
    /// Fit only sliding 1st/3rd-quadrant samples (|ṡ| > --v-min and ṡ·τ_F > 0), the authors' choice.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub sliding_quadrants: bool,
    /// Velocity threshold of the sliding selection [rad/s].
    #[arg(long, default_value_t = 0.03)]
    pub v_min: f64,
    /// SCV: the sliding rows down to this |ṡ| are fitted [rad/s] (the Stribeck region below
    /// `--v-min`; `--v-min` is the SCV's low-speed threshold and the CV's selection).
    #[arg(long, default_value_t = 0.003)]
    pub stribeck_v_min: f64,
    /// SCV: share of the rows, at their end, held out as the validation block; the SCV is kept only
    /// if it beats the CV there, else it is the CV (ks = kc).
    #[arg(long, default_value_t = 0.2)]
    pub validation_fraction: f64,
    /// Use the simulator truth column instead of the label (diagnostics).
    #[arg(long)]
    pub truth: bool,
    /// Upper bound of ka [s/rad]: tanh(ka·v) must saturate over a velocity band ≥ 1/ka, comparable to
    /// the velocity noise/resolution (200 s/rad ↔ 5 mrad/s); a steeper smooth sign only fits label
    /// noise and makes the compensation chatter ±kc around v = 0.
    #[arg(long, default_value_t = FitBounds::default().ka_max)]
    pub ka_max: f64,
    /// Lower bound of ka [s/rad].
    #[arg(long, default_value_t = FitBounds::default().ka_min)]
    pub ka_min: f64,
    /// Lower bound of the Stribeck velocity vs [rad/s] (SCV, SCV code form).
    #[arg(long, default_value_t = FitBounds::default().vs_min)]
    pub vs_min: f64,
    /// Upper bound of the Stribeck velocity vs [rad/s].
    #[arg(long, default_value_t = FitBounds::default().vs_max)]
    pub vs_max: f64,
    /// Lower bound of the Stribeck exponent α (SCV).
    #[arg(long, default_value_t = FitBounds::default().alpha_min)]
    pub alpha_min: f64,
    /// Upper bound of the Stribeck exponent α.
    #[arg(long, default_value_t = FitBounds::default().alpha_max)]
    pub alpha_max: f64,
    /// Upper bound of ks/kc (fs/fc for the code form).
    #[arg(long, default_value_t = FitBounds::default().ks_max_ratio)]
    pub ks_max_ratio: f64,
    /// LuGre: hold the bristle stiffness σ0 [Nm/rad] at this value instead of identifying it.
    #[arg(long)]
    pub sigma0: Option<f64>,
    /// LuGre: hold the bristle damping σ1 [Nm·s/rad] at this value instead of identifying it.
    #[arg(long)]
    pub sigma1: Option<f64>,
    /// LuGre: no joint refinement of all seven parameters after the Stribeck and bristle stages.
    #[arg(long)]
    pub no_joint_refinement: bool,
    /// Travel from a chunk's start before its rows enter the time-series error [rad] (the LuGre
    /// fit's cost and every model's held-out RMSE): the simulated bristle state starts at 0, the
    /// joint's does not.
    #[arg(long, default_value_t = 0.01)]
    pub warmup_travel_rad: f64,
    /// A held-out dataset (repeatable): the fit reports its RMSE on each one's valid rows.
    #[arg(long = "test-dataset", value_name = "CSV")]
    pub test_datasets: Vec<PathBuf>,
    /// Write the TOML snippet here.
    #[arg(long)]
    pub toml: Option<PathBuf>,
    /// Write the JSON result here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Leave out a run held out for testing (repeatable): a run name of the dataset's sidecar
    /// (`runs`), or its file stem for a dataset without runs — as `frictl train --test-run`.
    #[arg(long = "test-run", value_name = "NAME")]
    pub test_runs: Vec<String>,
}
