//! Arguments of `frictl preprocess`.

use frictionless_ident::kalman::KalmanConfig;
use frictionless_ident::label_settings::LabelSettings;
use frictionless_ident::preprocess::{LabelFilter, PreprocessConfig, Ripple};
use std::path::PathBuf;

/// Source of the link dynamics for τ_ID.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LinkSource {
    /// The sidecar's simulator link model if present and no `--urdf` given, else the URDF.
    Auto,
    /// The URDF (`--urdf`, default `virtual_leg`).
    Urdf,
    /// The simulator's link model from the sidecar (`plant.link`); an error if absent.
    Sidecar,
}

/// The label pipeline's settings shared by `frictl preprocess` and `frictl import csv|mat|mcap`
/// (everything but the chunk gap, whose default differs).
#[derive(clap::Args, Debug, Clone, serde::Serialize)]
pub struct PipelineArgs {
    /// Causal ṡ/s̈ columns (forward Kalman filter, what the daemon sees) for training on causal
    /// signals; the label itself always uses the zero-phase current and the RTS smoother.
    #[arg(long)]
    pub causal: bool,
    /// Butterworth order for the current.
    #[arg(long, default_value_t = 5)]
    pub butter_order: usize,
    /// Butterworth cut-off [Hz].
    #[arg(long, default_value_t = 100.0)]
    pub butter_cutoff_hz: f64,
    /// Output sample rate [Hz].
    #[arg(long, default_value_t = 1000.0)]
    pub fs_hz: f64,
    /// Kalman P₀ diagonal (pos, vel, acc).
    #[arg(long, num_args = 3, value_delimiter = ',', default_values_t = [1e-5, 1e-4, 1e4])]
    pub kalman_p0: Vec<f64>,
    /// Kalman Q diagonal per step (pos, vel, acc).
    #[arg(long, num_args = 3, value_delimiter = ',', default_values_t = [1e-5, 1e-4, 1e4])]
    pub kalman_q: Vec<f64>,
    /// Kalman measurement variance R [rad²].
    #[arg(long, default_value_t = 1e-4)]
    pub kalman_r: f64,
    /// |s̈| limit [rad/s²].
    #[arg(long, default_value_t = 10.0)]
    pub joint_acc_limit: f64,
    /// |ṡ| limit [rad/s].
    #[arg(long, default_value_t = 10.0)]
    pub joint_vel_limit: f64,
    /// |i_f| limit [A] (default 10).
    #[arg(long)]
    pub im_limit: Option<f64>,
    /// |τ_F| limit [Nm] (default: 15 for ankle roll joints, else 100).
    #[arg(long)]
    pub tauf_limit: Option<f64>,
    /// How the `current` label's current is filtered: `separate` (the authors': the Butterworth
    /// above, while q̈ and φ̈ come from the Kalman smoother) or `matched` (the current through the
    /// smoother's own acceleration response, so that a step of the current leaves no spike in the
    /// label; a row whose smoother window holds a rejected sample is rejected too).
    #[arg(long, default_value = "separate", value_parser = label_filter_parser())]
    pub label_filter: LabelFilter,
    /// The matched label's ripple step: `off`, or `wave-generator` (identify the drive's friction
    /// ripple at twice the motor angle from the log and add back what the smoother removed of it;
    /// needs `--label-filter matched`, the motor position and the whole log in memory).
    #[arg(long, default_value = "off", value_parser = ripple_parser())]
    pub ripple: Ripple,
    /// Magnitude of gravity along −z of the world (the fixed base's) frame [m/s²] in τ_ID from a
    /// URDF, whole-body or single-joint view; recorded in the sidecar (`gravity_m_s2` in the
    /// settings) [default: standard gravity, 9.80665].
    #[arg(long, value_name = "G", value_parser = parse_gravity_m_s2)]
    pub gravity_m_s2: Option<f64>,
}

/// Largest `--gravity-m-s2` [m/s²]: three times the Earth's (a larger value is a unit or typing
/// mistake).
pub const MAX_GRAVITY_M_S2: f64 = 30.0;

/// `--gravity-m-s2`'s parser: a finite number in [0, [`MAX_GRAVITY_M_S2`]] (clap names the flag
/// and the value in its error).
fn parse_gravity_m_s2(text: &str) -> Result<f64, String> {
    let g: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a number [m/s²]"))?;
    if !(g.is_finite() && (0.0..=MAX_GRAVITY_M_S2).contains(&g)) {
        return Err(format!(
            "{g} m/s² is outside [0, {MAX_GRAVITY_M_S2}] m/s² (the magnitude of gravity; Earth's \
             is 9.80665)"
        ));
    }
    Ok(g)
}

/// `--ripple`'s parser: the names of [`Ripple::ALL`].
fn ripple_parser() -> impl clap::builder::TypedValueParser<Value = Ripple> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Ripple::ALL.map(Ripple::name))
        .try_map(|name| Ripple::parse(&name).ok_or(format!("unknown ripple step {name:?}")))
}

/// `--label-filter`'s parser: the names of [`LabelFilter::ALL`].
fn label_filter_parser() -> impl clap::builder::TypedValueParser<Value = LabelFilter> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(LabelFilter::ALL.map(LabelFilter::name))
        .try_map(|name| LabelFilter::parse(&name).ok_or(format!("unknown label filter {name:?}")))
}

impl PipelineArgs {
    /// The settings as the labeller takes them.
    pub fn label_settings(&self) -> LabelSettings {
        LabelSettings {
            fs_hz: self.fs_hz,
            butter_order: self.butter_order,
            butter_cutoff_hz: self.butter_cutoff_hz,
            causal: self.causal,
            kalman: KalmanConfig {
                p0: [self.kalman_p0[0], self.kalman_p0[1], self.kalman_p0[2]],
                q: [self.kalman_q[0], self.kalman_q[1], self.kalman_q[2]],
                r: self.kalman_r,
            },
            joint_acc_limit_rad_s2: self.joint_acc_limit,
            joint_vel_limit_rad_s: self.joint_vel_limit,
            im_limit_a: self.im_limit,
            tauf_limit_nm: self.tauf_limit,
            label_filter: self.label_filter,
            ripple: self.ripple,
        }
    }

    /// Writes these settings into `cfg`.
    pub fn apply(&self, cfg: &mut PreprocessConfig) {
        self.label_settings().apply(cfg);
    }
}

/// Arguments of `frictl preprocess`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Acquisition log CSV (its sidecar is the same path with `.json`).
    pub log: PathBuf,
    /// Output dataset CSV (its sidecar is written next to it with `.json`).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Resampling, filter, smoother and sample-limit settings.
    #[command(flatten)]
    #[serde(flatten)]
    pub pipeline: PipelineArgs,
    /// Which link dynamics give τ_ID. `auto` (default): the simulator's own link model when the
    /// sidecar has one (`plant.link`, i.e. a simulated log) and no `--urdf` is given — the label is
    /// then computed with exactly the dynamics that produced the data — else the URDF.
    #[arg(long, value_enum, default_value_t = LinkSource::Auto)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub link: LinkSource,
    /// URDF for inverse dynamics (default `virtual_leg` = the project's `config/urdf/virtual_leg.urdf`).
    #[arg(long)]
    pub urdf: Option<String>,
    /// Joint name in the URDF (default: the sidecar's `joint`).
    #[arg(long)]
    pub joint: Option<String>,
    /// Position of another URDF joint, held fixed [rad] (repeatable; absent joints are 0).
    #[arg(long = "fixed-joint", value_name = "NAME=RAD")]
    pub fixed_joints: Vec<String>,
    /// Whole-body τ_ID: the log's columns of the other joints' positions, a template with `{joint}`
    /// replaced by each URDF joint name (e.g. `q_{joint}`); the log's own joint comes from `s_rad`.
    /// Implies the URDF (`--urdf`, `--fixed-joint`; joints neither logged nor fixed are held at 0).
    #[arg(long, value_name = "TEMPLATE")]
    pub positions: Option<String>,
    /// Velocity column template for `--positions` (absent: the Kalman smoother).
    #[arg(long, value_name = "TEMPLATE", requires = "positions")]
    pub velocities: Option<String>,
    /// Acceleration column template for `--positions`.
    #[arg(long, value_name = "TEMPLATE", requires = "positions")]
    pub accelerations: Option<String>,
    /// Same as `--link sidecar` (kept for existing scripts).
    #[arg(long)]
    pub link_from_sidecar: bool,
    /// Time gap that starts a new chunk [s].
    #[arg(long, default_value_t = 1.0)]
    pub gap_s: f64,
    /// Ablation: subtract J·φ̈ (φ̈ from the motor encoder θ/r) from the label with this J [kg·m²];
    /// `sidecar` = the simulator's r²·J_m.
    #[arg(long)]
    pub subtract_reflected_inertia: Option<String>,
}
