//! The friction-label pipeline: acquisition log → labelled dataset (paper §2–§4.3; reference
//! `docs/simulator.md` §5).
//!
//! Steps: split the log into chunks (chunk-id change or time gap > `gap_s`), resample each chunk to
//! `fs_hz` by linear interpolation, zero-phase Butterworth low-pass of the current (`sosfiltfilt`),
//! Kalman + RTS smoother on s for ṡ and s̈, τ_ID = I(s)·s̈ + c(s, ṡ) + g(s) from the single-joint link
//! dynamics (other joints fixed), label τ_F = r·k_t·i_f − τ_ID with the **signed** r, Δθ = r·s − θ
//! with the offset latched once at the first sample of the run, and the sample filters (|s̈|, |ṡ|,
//! |i_f|, |τ_F| limits).
//!
//! `causal = true` makes the ṡ and s̈ **columns** (what a model reads) come from the forward-only
//! Kalman filter, as the daemon sees them; the label and the sample filters always use the
//! non-causal estimates, because the label is an offline target and a causal label only adds the lag
//! mismatch of two different causal filters (current vs. s̈) to it.
//!
//! ## Label accuracy (simulator, `tools/acquire/tests/ident_label.rs`)
//! label − τ_F,true = J_eq·φ̈ + r·k_t·(i_f − i) − I_L·(ŝ̈ − s̈), i.e. the reflected motor inertia the
//! paper neglects, current noise after the filter, and the smoother's acceleration error. On the
//! virtual joints the J_eq·φ̈ term dominates; it is **not** a pipeline defect and it is kept by
//! default (the authors' label; the network can learn it from the ṡ history, and the motor must
//! supply it anyway). `subtract_reflected_inertia_kgm2` (ablation, `--subtract-reflected-inertia
//! sidecar`) removes J_eq·φ̂̈ with φ̂̈ the smoothed acceleration of θ/r from the **motor** encoder —
//! the physically right term (φ̈, not s̈: they differ by the flexspline oscillation).
//! `label_filter` ([`LabelFilter`], `--label-filter`): the authors' `separate` filters (the
//! Butterworth on the current, the smoother on the positions) or `matched` ([`crate::matched`]: the
//! current through the smoother's own acceleration response, so that a step of the current, which
//! steps the accelerations with it, leaves no spike in the label).
//! `ripple` ([`Ripple`], `--ripple`): with the matched label, `wave-generator` identifies the
//! drive's friction ripple at twice the motor angle and adds back what the smoother removed of it
//! ([`crate::ripple`]; the log is labelled a second time for the fit).
//! Kalman tuning: the authors' knee P/Q/R are the default; `--kalman-q/-r` changes it. The measured
//! label errors behind these choices are in `docs/decisions.md` ("Identification").
//! Link model: `frictl preprocess --link auto` (default) uses the simulator's own link model when the
//! log's sidecar has one, so a simulated log is labelled with the dynamics that produced it.
//!
//! Imported robot logs ([`RunSignals`], from `frictionless-logs`) go through [`preprocess_signals`]:
//! the same chunk split, resampler, Butterworth and smoother, with absent signals as NaN columns and
//! the label from current, a joint torque sensor or a given column.
//!
//! What it is not: a reader of robot log files (`frictionless-logs`), or windowing into network
//! inputs (the trainer builds windows inside chunks from [`Dataset::chunk`]).

use serde::{Deserialize, Serialize};

use super::kalman::{self, KalmanConfig, KalmanError};
use super::matched;
use frictionless::filter::{Butterworth, FilterError};
use frictionless_dataset::Dataset;
pub use frictionless_dataset::{DropReason, DroppedRows};
use frictionless_sim::link::LinkDynamics;

pub use super::signals::{
    Dynamics, JointLabel, RunJoints, RunSignals, SignalsLabel, SignalsSummary, preprocess_joints,
    preprocess_signals, required_signals,
};
pub use super::whole_body::{FrameWrench, JointStates, StatePlan, WholeBody, gravity_text};

/// Pipeline errors.
#[derive(Debug, thiserror::Error)]
pub enum PreprocessError {
    /// A required log column is missing.
    #[error("log {path}: required column `{column}` is missing")]
    MissingColumn {
        /// Log path.
        path: String,
        /// Column.
        column: &'static str,
    },
    /// Sidecar problem.
    #[error("sidecar {path}: {msg}")]
    Sidecar {
        /// Sidecar path.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A configuration value is out of range.
    #[error("preprocess setting `{name}` = {value} is invalid: {requirement}")]
    Config {
        /// Setting.
        name: &'static str,
        /// Value.
        value: f64,
        /// Requirement.
        requirement: &'static str,
    },
    /// The log has no usable samples.
    #[error("the log has no samples")]
    Empty,
    /// Time is not increasing.
    #[error("time_s decreases at sample {index} ({prev} -> {next})")]
    Time {
        /// Sample index.
        index: usize,
        /// Previous time.
        prev: f64,
        /// Next time.
        next: f64,
    },
    /// Filter design error.
    #[error(transparent)]
    Filter(#[from] FilterError),
    /// Kalman error.
    #[error(transparent)]
    Kalman(#[from] KalmanError),
    /// Dataset I/O.
    #[error(transparent)]
    Dataset(#[from] frictionless_dataset::DatasetError),
    /// Settings that cannot work together, or a step the log lacks a signal for.
    #[error("preprocess settings: {0}")]
    Settings(String),
}

/// Per-sample limits (samples beyond any limit get `valid = 0`). Authors' defaults: 10 rad/s²,
/// 10 rad/s; current and friction limits are per joint (knee 5–10 A / 100 Nm, ankle roll 10 A / 15 Nm).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleLimits {
    /// |s̈| limit [rad/s²].
    pub joint_acc_limit_rad_s2: f64,
    /// |ṡ| limit [rad/s].
    pub joint_vel_limit_rad_s: f64,
    /// |i_f| limit [A].
    pub im_limit_a: f64,
    /// |τ_F| limit [Nm].
    pub tauf_limit_nm: f64,
}

impl SampleLimits {
    /// The authors' limits for a joint name (ankle roll: 10 A, 15 Nm; else 10 A, 100 Nm).
    pub fn for_joint(joint: &str) -> Self {
        let ankle_roll = joint.contains("ankle_roll");
        Self {
            joint_acc_limit_rad_s2: 10.0,
            joint_vel_limit_rad_s: 10.0,
            im_limit_a: 10.0,
            tauf_limit_nm: if ankle_roll { 15.0 } else { 100.0 },
        }
    }

    /// The first limit a row fails, in [`DroppedRows`]'s order (`None`: within every limit). A
    /// limit on an absent quantity (a NaN acceleration or current) does not reject the row; a
    /// label or velocity that is not finite does.
    pub fn first_failed(
        &self,
        acc_rad_s2: f64,
        vel_rad_s: f64,
        current_a: f64,
        tau_f_nm: f64,
    ) -> Option<DropReason> {
        let beyond = |x: f64, lim: f64| !x.is_nan() && x.abs() >= lim;
        if !(tau_f_nm.is_finite() && vel_rad_s.is_finite()) {
            Some(DropReason::NonFinite)
        } else if beyond(acc_rad_s2, self.joint_acc_limit_rad_s2) {
            Some(DropReason::JointAcc)
        } else if beyond(vel_rad_s, self.joint_vel_limit_rad_s) {
            Some(DropReason::JointVel)
        } else if beyond(current_a, self.im_limit_a) {
            Some(DropReason::Current)
        } else if beyond(tau_f_nm, self.tauf_limit_nm) {
            Some(DropReason::TauF)
        } else {
            None
        }
    }

    /// One line naming every non-zero count of `dropped` (rows of a dataset of `rows`) with the
    /// command-line flag and the value of the limit behind it, e.g. `dropped 902 of 60000 rows: 902
    /// |s̈| ≥ --joint-acc-limit 10 rad/s²`; `None` when no row is dropped.
    pub fn dropped_rows_line(&self, dropped: &DroppedRows, rows: usize) -> Option<String> {
        let total = dropped.total();
        if total == 0 {
            return None;
        }
        let parts: Vec<String> = DropReason::ALL
            .iter()
            .filter(|r| dropped.get(**r) > 0)
            .map(|&r| {
                let n = dropped.get(r);
                match r {
                    DropReason::ShortChunk => {
                        format!("{n} in chunks too short for the zero-phase filter")
                    }
                    DropReason::NonFinite => format!("{n} with a non-finite label or ṡ"),
                    DropReason::JointAcc => format!(
                        "{n} |s̈| ≥ --joint-acc-limit {} rad/s²",
                        self.joint_acc_limit_rad_s2
                    ),
                    DropReason::JointVel => format!(
                        "{n} |ṡ| ≥ --joint-vel-limit {} rad/s",
                        self.joint_vel_limit_rad_s
                    ),
                    DropReason::Current => format!("{n} |i_f| ≥ --im-limit {} A", self.im_limit_a),
                    DropReason::TauF => {
                        format!("{n} |τ_F| ≥ --tauf-limit {} Nm", self.tauf_limit_nm)
                    }
                    DropReason::NearInvalid => format!(
                        "{n} within the matched smoother's reach of a dropped row \
                         (--label-filter matched)"
                    ),
                }
            })
            .collect();
        Some(format!(
            "dropped {total} of {rows} rows: {}",
            parts.join(", ")
        ))
    }
}

/// Counts one row in `dropped`: `chunk_ok` whether its chunk could be filtered, `own` the first
/// limit it fails ([`SampleLimits::first_failed`]), `within` whether it is valid after the matched
/// smoother's reach ([`matched::within_reach`]). A valid row is not counted.
pub(crate) fn count_row(
    dropped: &mut DroppedRows,
    chunk_ok: bool,
    own: Option<DropReason>,
    within: bool,
) {
    match (chunk_ok, own) {
        (false, _) => dropped.count(DropReason::ShortChunk),
        (true, Some(r)) => dropped.count(r),
        (true, None) if !within => dropped.count(DropReason::NearInvalid),
        (true, None) => {}
    }
}

/// Pipeline settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PreprocessConfig {
    /// Output sample rate [Hz] (authors: 1 kHz).
    pub fs_hz: f64,
    /// A time gap larger than this starts a new chunk [s] (authors: 1 s).
    pub gap_s: f64,
    /// Butterworth order (authors: 5).
    pub butter_order: usize,
    /// Butterworth cut-off [Hz] (authors: 100 Hz = 0.1·fs).
    pub butter_cutoff_hz: f64,
    /// Causal ṡ/s̈ columns (forward KF, what the daemon sees) instead of the RTS smoother's; the
    /// label always uses the non-causal estimates (module doc).
    pub causal: bool,
    /// Kalman configuration.
    pub kalman: KalmanConfig,
    /// Sample limits.
    pub limits: SampleLimits,
    /// Ablation: subtract `J·φ̂̈` from the label with this J [kg·m²] (0 = off, the paper's label);
    /// φ̂̈ is the smoothed acceleration of θ/r (motor encoder reflected to the joint).
    pub subtract_reflected_inertia_kgm2: f64,
    /// How the `current` label's current is filtered (default: the authors'
    /// [`LabelFilter::Separate`]).
    #[serde(default)]
    pub label_filter: LabelFilter,
    /// Whether the matched label gets the wave generator's friction ripple back
    /// ([`crate::ripple`]; default off).
    #[serde(default)]
    pub ripple: Ripple,
}

/// The ripple step of the matched `current` label ([`crate::ripple`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Ripple {
    /// No ripple step.
    #[default]
    Off,
    /// Identify the friction ripple at twice the motor angle and add back what the smoother
    /// removed of it (needs the motor position and the matched label).
    WaveGenerator,
}

impl Ripple {
    /// Every setting, in the order of [`Self::name`]'s documentation.
    pub const ALL: [Self; 2] = [Self::Off, Self::WaveGenerator];

    /// The name on the command line and in files (`off`, `wave-generator`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::WaveGenerator => "wave-generator",
        }
    }

    /// Parses [`Self::name`].
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// How the current of the `current` label τ_F = r·k_t·i − J·φ̈ − τ_ID(q, q̇, q̈) is filtered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelFilter {
    /// The authors': the current through the zero-phase Butterworth, q̇, q̈ and φ̈ from the Kalman
    /// smoother (each term its own filter).
    #[default]
    Separate,
    /// The current through the Kalman smoother's own acceleration response, so that every term
    /// sees the same filter; rows whose smoother window holds a rejected sample are rejected
    /// ([`crate::matched`]).
    Matched,
}

impl LabelFilter {
    /// Every filter, in the order of [`Self::name`]'s documentation.
    pub const ALL: [Self; 2] = [Self::Separate, Self::Matched];

    /// The name on the command line and in files (`separate`, `matched`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Separate => "separate",
            Self::Matched => "matched",
        }
    }

    /// Parses [`Self::name`].
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

impl PreprocessConfig {
    /// The authors' settings for a joint.
    pub fn for_joint(joint: &str) -> Self {
        Self {
            fs_hz: 1000.0,
            gap_s: 1.0,
            butter_order: 5,
            butter_cutoff_hz: 100.0,
            causal: false,
            kalman: KalmanConfig::knee(),
            limits: SampleLimits::for_joint(joint),
            subtract_reflected_inertia_kgm2: 0.0,
            label_filter: LabelFilter::Separate,
            ripple: Ripple::Off,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), PreprocessError> {
        let bad = |name, value, requirement| {
            Err(PreprocessError::Config {
                name,
                value,
                requirement,
            })
        };
        if !(self.fs_hz.is_finite() && self.fs_hz > 0.0) {
            return bad("fs_hz", self.fs_hz, "finite and > 0");
        }
        if self.gap_s.is_nan() || self.gap_s <= 0.0 {
            return bad("gap_s", self.gap_s, "> 0");
        }
        if !self.subtract_reflected_inertia_kgm2.is_finite() {
            return bad(
                "subtract_reflected_inertia_kgm2",
                self.subtract_reflected_inertia_kgm2,
                "finite",
            );
        }
        if self.ripple != Ripple::Off && self.label_filter != LabelFilter::Matched {
            return Err(PreprocessError::Settings(format!(
                "ripple {} needs the matched label (label filter `matched`, not `{}`): only there \
                 does every term of the label see the smoother whose loss the step adds back",
                self.ripple.name(),
                self.label_filter.name()
            )));
        }
        Ok(())
    }
}

/// An acquisition log in memory (columns of the `frictl acquire` CSV).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawLog {
    /// Time [s].
    pub time_s: Vec<f64>,
    /// Chunk id.
    pub chunk: Vec<u32>,
    /// Active flag (all true if the log has no `active` column).
    pub active: Vec<bool>,
    /// Joint position [rad].
    pub s_rad: Vec<f64>,
    /// Motor position [motor rad].
    pub theta_motor_rad: Vec<f64>,
    /// Motor velocity [motor rad/s].
    pub omega_motor_rad_s: Vec<f64>,
    /// Measured current [A].
    pub i_meas_a: Vec<f64>,
    /// Temperature [°C] (NaN if absent).
    pub temperature_c: Vec<f64>,
    /// True friction (simulated logs).
    pub tau_f_true_nm: Option<Vec<f64>>,
    /// True reflected motor acceleration (simulated logs).
    pub phi_ddot_rad_s2: Option<Vec<f64>>,
}

/// What the pipeline needs from the log's JSON sidecar.
#[derive(Clone, Debug, PartialEq)]
pub struct LogMeta {
    /// Joint name.
    pub joint: String,
    /// Signed gear ratio.
    pub gear_ratio_signed: f64,
    /// Torque constant [Nm/A].
    pub kt_nm_per_a: f64,
    /// The simulator's link model, if the log is simulated.
    pub plant_link: Option<frictionless_sim::params::LinkModel>,
    /// The simulator's reflected motor inertia r²·J_m [kg·m²], if simulated.
    pub j_eq_kgm2: Option<f64>,
}

impl RawLog {
    /// Reads a log CSV by column name.
    pub fn read_csv(path: &std::path::Path) -> Result<Self, PreprocessError> {
        let mut cols = frictionless_dataset::read_columns(path)?;
        let p = path.display().to_string();
        let mut take = |c: &'static str| {
            cols.remove(c).ok_or(PreprocessError::MissingColumn {
                path: p.clone(),
                column: c,
            })
        };
        let time_s = take("time_s")?;
        let n = time_s.len();
        Ok(Self {
            chunk: take("chunk")?.into_iter().map(|x| x as u32).collect(),
            s_rad: take("s_rad")?,
            theta_motor_rad: take("theta_motor_rad")?,
            omega_motor_rad_s: take("omega_motor_rad_s")?,
            i_meas_a: take("i_meas_a")?,
            active: take("active")
                .map(|v| v.into_iter().map(|x| x != 0.0).collect())
                .unwrap_or_else(|_| vec![true; n]),
            temperature_c: take("temperature_c").unwrap_or_else(|_| vec![f64::NAN; n]),
            tau_f_true_nm: take("tau_f_true_nm").ok(),
            phi_ddot_rad_s2: take("phi_ddot").ok(),
            time_s,
        })
    }
}

impl LogMeta {
    /// Reads the sidecar JSON (`gear_ratio_signed`, `kt_nm_per_a`, `joint`, optional `plant`).
    pub fn read_json(path: &std::path::Path) -> Result<Self, PreprocessError> {
        let p = path.display().to_string();
        let err = |msg: String| PreprocessError::Sidecar {
            path: p.clone(),
            msg,
        };
        let text = frictionless::regular_file::read_text(path).map_err(|e| err(e.to_string()))?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
        let num = |k: &str| {
            v.get(k)
                .and_then(serde_json::Value::as_f64)
                .ok_or_else(|| err(format!("key `{k}` missing or not a number")))
        };
        let gear_ratio_signed = num("gear_ratio_signed")?;
        let kt_nm_per_a = num("kt_nm_per_a")?;
        if gear_ratio_signed == 0.0 || !gear_ratio_signed.is_finite() {
            return Err(err(format!(
                "gear_ratio_signed = {gear_ratio_signed} must be finite and non-zero"
            )));
        }
        if !(kt_nm_per_a.is_finite() && kt_nm_per_a > 0.0) {
            return Err(err(format!(
                "kt_nm_per_a = {kt_nm_per_a} must be finite and > 0"
            )));
        }
        let plant = v.get("plant").filter(|x| !x.is_null());
        let plant_link = match plant.and_then(|p| p.get("link")) {
            Some(l) => Some(
                serde_json::from_value(l.clone()).map_err(|e| err(format!("plant.link: {e}")))?,
            ),
            None => None,
        };
        let j_eq_kgm2 = plant
            .and_then(|p| p.get("j_motor_kgm2"))
            .and_then(serde_json::Value::as_f64)
            .map(|jm| jm * gear_ratio_signed * gear_ratio_signed);
        Ok(Self {
            joint: v
                .get("joint")
                .and_then(serde_json::Value::as_str)
                .unwrap_or("")
                .to_owned(),
            gear_ratio_signed,
            kt_nm_per_a,
            plant_link,
            j_eq_kgm2,
        })
    }
}

/// Summary of a run of the pipeline (goes into the dataset sidecar).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PreprocessSummary {
    /// Chunks after splitting.
    pub chunks: usize,
    /// Chunks too short for the zero-phase filter (their samples are invalid).
    pub short_chunks: usize,
    /// The invalid rows, by reason.
    pub dropped: DroppedRows,
    /// Δθ offset r·s₀ − θ₀ [motor rad].
    pub delta_theta_offset_motor_rad: f64,
    /// The ripple step's fit ([`Ripple::WaveGenerator`]; `None`: off, or too few rows to fit).
    pub ripple: Option<crate::ripple::RippleFit>,
}

/// Splits sample indices into `[start, end)` ranges at chunk-id changes and gaps > `gap_s`.
pub fn split_chunks(time_s: &[f64], chunk: &[u32], gap_s: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..time_s.len() {
        if chunk[k] != chunk[k - 1] || time_s[k] - time_s[k - 1] > gap_s {
            out.push((start, k));
            start = k;
        }
    }
    if !time_s.is_empty() {
        out.push((start, time_s.len()));
    }
    out
}

/// Linear interpolation of `(t, y)` (t increasing) at `tq`; clamps at the ends.
pub(crate) fn interp(t: &[f64], y: &[f64], tq: &[f64]) -> Vec<f64> {
    let mut j = 0;
    tq.iter()
        .map(|&q| {
            while j + 2 < t.len() && t[j + 1] < q {
                j += 1;
            }
            if t.len() == 1 || q <= t[0] {
                return y[0];
            }
            let (t0, t1) = (t[j], t[j + 1]);
            if q >= t1 {
                return y[j + 1];
            }
            let w = if t1 > t0 { (q - t0) / (t1 - t0) } else { 1.0 };
            y[j] + w * (y[j + 1] - y[j])
        })
        .collect()
}

/// Nearest-previous index of `tq` in `t`.
fn previous_index(t: &[f64], tq: &[f64]) -> Vec<usize> {
    let mut j = 0;
    tq.iter()
        .map(|&q| {
            while j + 1 < t.len() && t[j + 1] <= q + 1e-12 {
                j += 1;
            }
            j
        })
        .collect()
}

/// Runs the pipeline on a log with the given link dynamics.
pub fn preprocess(
    log: &RawLog,
    meta: &LogMeta,
    link: &dyn LinkDynamics,
    cfg: &PreprocessConfig,
) -> Result<(Dataset, PreprocessSummary), PreprocessError> {
    preprocess_impl(log, meta, Dynamics::Link(link), None, cfg)
}

/// [`preprocess`] with the whole-body τ_ID: `state` holds the positions of the log's other joints
/// (same clock as `log`); the log's own joint (`meta.joint`) comes from `s_rad` when the state
/// lacks it.
pub fn preprocess_whole_body(
    log: &RawLog,
    meta: &LogMeta,
    body: &WholeBody,
    state: &JointStates,
    cfg: &PreprocessConfig,
) -> Result<(Dataset, PreprocessSummary), PreprocessError> {
    preprocess_impl(log, meta, Dynamics::WholeBody(body), Some(state), cfg)
}

/// The label, then the ripple step when `cfg` asks for it (the log labelled a second time with the
/// fit's settings, [`crate::ripple::correct`]).
fn preprocess_impl(
    log: &RawLog,
    meta: &LogMeta,
    dynamics: Dynamics<'_>,
    state: Option<&JointStates>,
    cfg: &PreprocessConfig,
) -> Result<(Dataset, PreprocessSummary), PreprocessError> {
    let (mut ds, mut summary) = label_log(log, meta, dynamics, state, cfg)?;
    if cfg.ripple == Ripple::WaveGenerator {
        let (wide, _) = label_log(
            log,
            meta,
            dynamics,
            state,
            &crate::ripple::fit_settings(cfg),
        )?;
        summary.ripple = crate::ripple::correct(&mut ds, &wide, cfg)?;
    }
    Ok((ds, summary))
}

fn label_log(
    log: &RawLog,
    meta: &LogMeta,
    dynamics: Dynamics<'_>,
    state: Option<&JointStates>,
    cfg: &PreprocessConfig,
) -> Result<(Dataset, PreprocessSummary), PreprocessError> {
    cfg.validate()?;
    if log.time_s.is_empty() {
        return Err(PreprocessError::Empty);
    }
    for k in 1..log.time_s.len() {
        if log.time_s[k].is_nan() || log.time_s[k] < log.time_s[k - 1] {
            return Err(PreprocessError::Time {
                index: k,
                prev: log.time_s[k - 1],
                next: log.time_s[k],
            });
        }
    }
    let bw = Butterworth::lowpass(cfg.butter_order, cfg.butter_cutoff_hz, cfg.fs_hz)?;
    let dt = 1.0 / cfg.fs_hz;
    let r = meta.gear_ratio_signed;
    let mut ds = Dataset::default();
    let has_truth = log.tau_f_true_nm.is_some() && log.phi_ddot_rad_s2.is_some();
    let mut truth_f = Vec::new();
    let mut truth_a = Vec::new();
    let mut summary = PreprocessSummary::default();
    let mut offset: Option<f64> = None;
    let matched = cfg.label_filter == LabelFilter::Matched;
    let reach = if matched {
        matched::reach_samples(&cfg.kalman, dt)?
    } else {
        0
    };
    let mut body = match (dynamics, state) {
        (Dynamics::WholeBody(b), Some(st)) => {
            st.check(log.time_s.len())
                .map_err(|msg| PreprocessError::Sidecar {
                    path: "joint state".into(),
                    msg,
                })?;
            let labelled = [super::whole_body::Labelled {
                joint: meta.joint.clone(),
                q: Some(&log.s_rad),
                qd: None,
                qdd: None,
            }];
            let index =
                b.robot()
                    .joint_index(&meta.joint)
                    .map_err(|e| PreprocessError::Sidecar {
                        path: "log sidecar".into(),
                        msg: e.to_string(),
                    })?;
            Some((
                b,
                b.tracks_of(st, &labelled)?,
                frictionless_dynamics::Workspace::new(b.robot()),
                index,
            ))
        }
        _ => None,
    };
    let link = match dynamics {
        Dynamics::Link(l) => Some(l),
        _ => None,
    };
    if link.is_none() && body.is_none() {
        return Err(PreprocessError::Sidecar {
            path: "log".into(),
            msg: "no link dynamics and no whole-body state for tau_ID".into(),
        });
    }
    for (ci, (a, b)) in split_chunks(&log.time_s, &log.chunk, cfg.gap_s)
        .into_iter()
        .enumerate()
    {
        let t = &log.time_s[a..b];
        let n = ((t[t.len() - 1] - t[0]) / dt + 1e-9).floor() as usize + 1;
        let tq: Vec<f64> = (0..n).map(|k| t[0] + k as f64 * dt).collect();
        let li = |y: &[f64]| interp(t, &y[a..b], &tq);
        let s = li(&log.s_rad);
        let theta = li(&log.theta_motor_rad);
        let omega = li(&log.omega_motor_rad_s);
        let im = li(&log.i_meas_a);
        let temp = li(&log.temperature_c);
        let prev = previous_index(t, &tq);
        let mut chunk_ok = true;
        // The label is an offline target, so it always uses the best (non-causal) estimates: the
        // zero-phase current and the RTS-smoothed s̈. `causal` only changes the ṡ/s̈ columns the
        // models read (the daemon's forward KF), never the label — a causal label would add the
        // lag mismatch of two different causal filters (current vs. s̈) to the target.
        let i_f = if matched {
            matched::smoothed_current(&cfg.kalman, dt, &im)?
        } else {
            match bw.filtfilt(&im) {
                Ok(y) => y,
                Err(FilterError::TooShort { .. }) => {
                    chunk_ok = false;
                    summary.short_chunks += 1;
                    im.clone()
                }
                Err(e) => return Err(e.into()),
            }
        };
        let est = kalman::smooth(&cfg.kalman, dt, &s)?;
        let feat = if cfg.causal {
            kalman::filter(&cfg.kalman, dt, &s)?
        } else {
            est.clone()
        };
        // Reflected motor acceleration φ̈ (θ/r through the same smoother), when subtracted.
        let phi_ddot = if cfg.subtract_reflected_inertia_kgm2 != 0.0 {
            let phi: Vec<f64> = theta.iter().map(|t| t / r).collect();
            kalman::smooth(&cfg.kalman, dt, &phi)?.acc_rad_s2
        } else {
            vec![0.0; n]
        };
        let off = *offset.get_or_insert(r * s[0] - theta[0]);
        let whole = match &mut body {
            Some((bd, tracks, ws, index)) => Some(
                bd.chunk_tau(
                    ws,
                    tracks,
                    &log.time_s,
                    a,
                    b,
                    &tq,
                    &cfg.kalman,
                    dt,
                    &[*index],
                )?
                .remove(0),
            ),
            None => None,
        };
        let l = &cfg.limits;
        let (mut tau_ids, mut tau_fs, mut fails) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for k in 0..n {
            let (sk, vk, ak) = (s[k], est.vel_rad_s[k], est.acc_rad_s2[k]);
            let tau_id = match (&whole, link) {
                (Some(w), _) => w[k],
                (None, Some(link)) => {
                    link.inertia_kgm2(sk) * ak
                        + link.velocity_torque_nm(sk, vk)
                        + link.gravity_nm(sk)
                }
                (None, None) => f64::NAN,
            };
            let tau_f = r * meta.kt_nm_per_a * i_f[k]
                - tau_id
                - cfg.subtract_reflected_inertia_kgm2 * phi_ddot[k];
            fails.push(l.first_failed(ak, vk, i_f[k], tau_f));
            tau_ids.push(tau_id);
            tau_fs.push(tau_f);
        }
        let ok: Vec<bool> = fails.iter().map(Option::is_none).collect();
        let within = matched::within_reach(&ok, reach);
        for k in 0..n {
            let sk = s[k];
            let (tau_id, tau_f) = (tau_ids[k], tau_fs[k]);
            let valid = chunk_ok && within[k];
            count_row(&mut summary.dropped, chunk_ok, fails[k], within[k]);
            ds.time_s.push(tq[k]);
            ds.chunk.push(ci as u32);
            ds.source_chunk.push(log.chunk[a + prev[k]]);
            ds.active.push(log.active[a + prev[k]]);
            ds.valid.push(valid);
            ds.s_rad.push(sk);
            ds.sdot_rad_s.push(feat.vel_rad_s[k]);
            ds.sddot_rad_s2.push(feat.acc_rad_s2[k]);
            ds.theta_motor_rad.push(theta[k]);
            ds.delta_theta_motor_rad.push(r * sk - theta[k] - off);
            ds.omega_motor_rad_s.push(omega[k]);
            ds.i_meas_a.push(im[k]);
            ds.i_filt_a.push(i_f[k]);
            ds.tau_id_nm.push(tau_id);
            ds.tau_f_label_nm.push(tau_f);
            ds.temperature_c.push(temp[k]);
        }
        if let (true, Some(tf), Some(pa)) = (has_truth, &log.tau_f_true_nm, &log.phi_ddot_rad_s2) {
            truth_f.extend(li(tf));
            truth_a.extend(li(pa));
        }
        summary.chunks += 1;
    }
    if has_truth {
        ds.tau_f_true_nm = Some(truth_f);
        ds.phi_ddot_rad_s2 = Some(truth_a);
    }
    summary.delta_theta_offset_motor_rad = offset.unwrap_or(0.0);
    Ok((ds, summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_split_on_id_and_gap() {
        let t = [0.0, 0.001, 0.002, 1.5, 1.501, 1.502, 1.503];
        let c = [0, 0, 1, 1, 1, 1, 2];
        assert_eq!(split_chunks(&t, &c, 1.0), [(0, 2), (2, 3), (3, 6), (6, 7)]);
    }

    #[test]
    fn interpolation_is_linear_and_exact_on_lines() {
        let t = [0.0, 0.002, 0.004, 0.006];
        let y = [1.0, 3.0, 5.0, 7.0];
        let tq: Vec<f64> = (0..7).map(|k| k as f64 * 0.001).collect();
        let v = interp(&t, &y, &tq);
        for (q, v) in tq.iter().zip(&v) {
            assert!((v - (1.0 + 1000.0 * q)).abs() < 1e-12);
        }
        assert_eq!(previous_index(&t, &tq), [0, 0, 1, 1, 2, 2, 3]);
    }

    #[test]
    fn imported_signals_resample_jittered_time_and_split_on_gaps() {
        // A 0.5 Hz sine sampled every 2–3 ms (deterministic jitter), with a 0.5 s gap at 2 s.
        let mut t = Vec::new();
        let mut x = 0.0;
        let mut k = 0u64;
        while x < 4.0 {
            if !(2.0..2.5).contains(&x) {
                t.push(x);
            }
            k += 1;
            x += 0.002 + 0.001 * ((k * 7919) % 11) as f64 / 10.0;
        }
        let s: Vec<f64> = t.iter().map(|t| (std::f64::consts::PI * t).sin()).collect();
        let f: Vec<f64> = t
            .iter()
            .map(|t| 2.0 * (std::f64::consts::PI * t).cos())
            .collect();
        let run = RunSignals {
            chunk: vec![0; t.len()],
            s_rad: Some(s),
            tau_f_nm: Some(f),
            time_s: t,
            ..RunSignals::default()
        };
        let label = SignalsLabel {
            source: frictionless_dataset::LabelSource::Given,
            gear_ratio_signed: None,
            kt_nm_per_a: None,
        };
        let mut cfg = PreprocessConfig::for_joint("j");
        cfg.gap_s = 0.1;
        let (ds, sum) = preprocess_signals(&[run.clone(), run], &label, None, &cfg).unwrap();
        assert_eq!(sum.run_chunks, [vec![0, 1], vec![2, 3]]);
        for k in 0..ds.len() {
            let tk = ds.time_s[k];
            let truth = (std::f64::consts::PI * tk).sin();
            // Linear interpolation error of a sine over ≤ 3 ms: ≤ π²·(3e-3)²/8 ≈ 1.1e-5.
            assert!((ds.s_rad[k] - truth).abs() < 2e-5, "t = {tk}");
            assert!(
                !(2.0..2.5).contains(&tk) || (tk - 2.0).abs() < 0.004 || (tk - 2.5).abs() < 0.004
            );
            if k > 0 && ds.chunk[k] == ds.chunk[k - 1] {
                assert!((ds.time_s[k] - ds.time_s[k - 1] - 1e-3).abs() < 1e-9);
            }
        }
        assert!(ds.theta_motor_rad.iter().all(|v| v.is_nan()));
        assert!(sum.absent_columns.contains(&"theta_motor_rad"));
        assert!(sum.absent_columns.contains(&"tau_id_nm"));
        let valid = ds.valid.iter().filter(|v| **v).count();
        assert!(valid > ds.len() * 9 / 10, "{valid} of {}", ds.len());
    }

    #[test]
    fn every_dropped_row_is_counted_once_under_its_first_reason() {
        // 2 s at 1 kHz with the label, ṡ and s̈ given (no filter: every chunk is long enough).
        let n = 2000;
        let mut v = vec![0.5; n];
        let mut acc = vec![0.0; n];
        let mut f = vec![1.0; n];
        // 37 rows over the |s̈| limit (10 rad/s²), 5 of them also over the |ṡ| limit: |s̈| first.
        acc[100..137].fill(12.0);
        v[100..105].fill(-11.0);
        // 3 rows over the |ṡ| limit alone, 4 over the |τ_F| limit (100 Nm), 1 without a label.
        v[500..503].fill(11.0);
        f[900..904].fill(-150.0);
        f[1500] = f64::NAN;
        let run = RunSignals {
            time_s: (0..n).map(|k| k as f64 * 1e-3).collect(),
            chunk: vec![0; n],
            sdot_rad_s: Some(v),
            sddot_rad_s2: Some(acc),
            tau_f_nm: Some(f),
            ..RunSignals::default()
        };
        let label = SignalsLabel {
            source: frictionless_dataset::LabelSource::Given,
            gear_ratio_signed: None,
            kt_nm_per_a: None,
        };
        let cfg = PreprocessConfig::for_joint("j");
        let (ds, sum) = preprocess_signals(&[run], &label, None, &cfg).unwrap();
        assert_eq!(ds.len(), n);
        let d = sum.dropped;
        assert_eq!(
            d,
            DroppedRows {
                joint_acc: 37,
                joint_vel: 3,
                tau_f: 4,
                non_finite: 1,
                ..DroppedRows::default()
            }
        );
        assert_eq!(d.total(), ds.valid.iter().filter(|v| !**v).count());
        let line = cfg.limits.dropped_rows_line(&d, ds.len()).unwrap();
        assert_eq!(
            line,
            "dropped 45 of 2000 rows: 1 with a non-finite label or ṡ, 37 |s̈| ≥ --joint-acc-limit \
             10 rad/s², 3 |ṡ| ≥ --joint-vel-limit 10 rad/s, 4 |τ_F| ≥ --tauf-limit 100 Nm"
        );
        assert_eq!(
            cfg.limits
                .dropped_rows_line(&DroppedRows::default(), ds.len()),
            None
        );
    }

    #[test]
    fn a_row_is_counted_short_chunk_then_own_limit_then_near_invalid() {
        let mut d = DroppedRows::default();
        count_row(&mut d, false, Some(DropReason::JointAcc), false);
        count_row(&mut d, true, Some(DropReason::Current), false);
        count_row(&mut d, true, None, false);
        count_row(&mut d, true, None, true);
        assert_eq!(
            d,
            DroppedRows {
                short_chunk: 1,
                current: 1,
                near_invalid: 1,
                ..DroppedRows::default()
            }
        );
        let l = SampleLimits::for_joint("knee");
        assert_eq!(
            l.first_failed(10.0, 0.0, 0.0, 0.0),
            Some(DropReason::JointAcc)
        );
        assert_eq!(l.first_failed(f64::NAN, 0.0, f64::NAN, 0.0), None);
        assert_eq!(
            l.first_failed(0.0, 0.0, -10.0, 0.0),
            Some(DropReason::Current)
        );
        assert_eq!(
            l.first_failed(0.0, f64::NAN, 0.0, 0.0),
            Some(DropReason::NonFinite)
        );
    }

    #[test]
    fn imported_signals_name_what_a_label_lacks() {
        let run = RunSignals {
            time_s: vec![0.0, 0.001, 0.002],
            chunk: vec![0; 3],
            s_rad: Some(vec![0.0; 3]),
            ..RunSignals::default()
        };
        let cfg = PreprocessConfig::for_joint("j");
        let given = SignalsLabel {
            source: frictionless_dataset::LabelSource::Given,
            gear_ratio_signed: None,
            kt_nm_per_a: None,
        };
        let e = preprocess_signals(std::slice::from_ref(&run), &given, None, &cfg).unwrap_err();
        assert!(e.to_string().contains("tau_f"), "{e}");
        let ts = SignalsLabel {
            source: frictionless_dataset::LabelSource::TorqueSensor,
            ..given
        };
        let e = preprocess_signals(&[run], &ts, None, &cfg).unwrap_err();
        assert!(e.to_string().contains("tau_joint"), "{e}");
    }

    #[test]
    fn torque_sensor_label_is_motor_minus_joint_torque() {
        let n = 2000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
        let v: Vec<f64> = t.iter().map(|t| 0.5 + 0.1 * t).collect();
        let run = RunSignals {
            chunk: vec![0; n],
            sdot_rad_s: Some(v),
            tau_joint_nm: Some(vec![1.0; n]),
            current_a: Some(vec![-0.5; n]),
            time_s: t,
            ..RunSignals::default()
        };
        let cfg = PreprocessConfig::for_joint("j");
        let mut label = SignalsLabel {
            source: frictionless_dataset::LabelSource::TorqueSensor,
            gear_ratio_signed: Some(-100.0),
            kt_nm_per_a: Some(0.1),
        };
        // τ_motor = r·k_t·i = −100·0.1·(−0.5) = 5 Nm; label 5 − 1 = 4 Nm.
        let (ds, sum) = preprocess_signals(std::slice::from_ref(&run), &label, None, &cfg).unwrap();
        assert!(ds.tau_f_label_nm.iter().all(|f| (f - 4.0).abs() < 1e-9));
        assert!(sum.absent_columns.contains(&"s_rad"));
        assert!(!sum.absent_columns.contains(&"i_filt_a"));
        // A given motor-side torque takes precedence over r·k_t·i.
        let with_motor = RunSignals {
            tau_motor_nm: Some(vec![2.5; run.time_s.len()]),
            ..run.clone()
        };
        let (ds, _) = preprocess_signals(&[with_motor], &label, None, &cfg).unwrap();
        assert!(ds.tau_f_label_nm.iter().all(|f| (f - 1.5).abs() < 1e-9));
        // Without a gear ratio r·k_t·i cannot be formed: an error naming the setting.
        label.gear_ratio_signed = None;
        let e = preprocess_signals(&[run], &label, None, &cfg).unwrap_err();
        assert!(e.to_string().contains("gear_ratio_signed"), "{e}");
    }

    /// A 1 kHz knee run (s, current) of `secs` seconds, and the whole-body state of the same clock
    /// with the knee and, optionally, a moving hip.
    fn knee_run(secs: f64, hip_moves: bool) -> (RunSignals, JointStates) {
        let n = (secs * 1000.0) as usize;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let w = std::f64::consts::TAU * 0.5;
        let s: Vec<f64> = t.iter().map(|t| -0.8 + 0.3 * (w * t).sin()).collect();
        let hip: Vec<f64> = t
            .iter()
            .map(|t| {
                if hip_moves {
                    0.3 * (2.0 * w * t).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let run = RunSignals {
            chunk: vec![0; n],
            s_rad: Some(s.clone()),
            current_a: Some(t.iter().map(|t| 0.5 * (3.0 * t).sin()).collect()),
            time_s: t,
            ..RunSignals::default()
        };
        let mut st = JointStates::with_names(
            vec![
                "l_knee".into(),
                "l_hip_pitch".into(),
                "no_such_joint".into(),
            ],
            &[],
            &[],
            n,
        );
        st.q = vec![s, hip, vec![0.0; n]];
        (run, st)
    }

    #[test]
    fn whole_body_equals_the_single_joint_view_when_the_others_are_still() {
        use frictionless_sim::params::LinkModel;
        let (run, st) = knee_run(4.0, false);
        let held: std::collections::BTreeMap<String, f64> = [
            ("torso_pitch".to_string(), 0.2),
            ("r_knee".to_string(), -0.4),
        ]
        .into();
        let label = SignalsLabel {
            source: frictionless_dataset::LabelSource::Current,
            gear_ratio_signed: Some(100.0),
            kt_nm_per_a: Some(0.1),
        };
        let cfg = PreprocessConfig::for_joint("l_knee");
        let link = frictionless_sim::link::link_from_model(&LinkModel::Urdf {
            urdf: "virtual_leg".into(),
            joint: "l_knee".into(),
            other_joints_rad: held.clone(),
            gravity_m_s2: None,
        })
        .unwrap();
        let (single, _) = preprocess_signals(
            std::slice::from_ref(&run),
            &label,
            Some(link.as_ref()),
            &cfg,
        )
        .unwrap();
        let body = WholeBody::new(frictionless_dynamics::virtual_leg().unwrap(), held).unwrap();
        let joints = [JointLabel {
            joint: "l_knee".into(),
            label,
            cfg,
        }];
        let runs = [RunJoints {
            signals: vec![&run],
            state: Some(&st),
        }];
        let (whole, sum) = preprocess_joints(&runs, &joints, Dynamics::WholeBody(&body))
            .unwrap()
            .remove(0);
        assert_eq!(whole.len(), single.len());
        for k in 0..whole.len() {
            assert!(
                (whole.tau_id_nm[k] - single.tau_id_nm[k]).abs() < 1e-9,
                "k = {k}: {} vs {}",
                whole.tau_id_nm[k],
                single.tau_id_nm[k]
            );
        }
        assert!(
            sum.derivations
                .iter()
                .any(|d| d.contains("whole-body RNEA"))
        );
        // The plan names where each joint comes from.
        let plan = body.plan(&st.names, &["l_knee".to_string()], None);
        assert!(plan.from_log.contains(&"l_hip_pitch".to_string()));
        assert_eq!(plan.held.get("torso_pitch"), Some(&0.2));
        assert!(plan.held_at_zero.contains(&"r_hip_pitch".to_string()));
        assert_eq!(plan.not_in_urdf, ["no_such_joint"]);

        // A moving hip changes the knee's torque; the single-joint view cannot see it.
        let (run2, st2) = knee_run(4.0, true);
        let runs = [RunJoints {
            signals: vec![&run2],
            state: Some(&st2),
        }];
        let (moving, _) = preprocess_joints(&runs, &joints, Dynamics::WholeBody(&body))
            .unwrap()
            .remove(0);
        let d2: f64 = (0..moving.len())
            .map(|k| (moving.tau_id_nm[k] - single.tau_id_nm[k]).powi(2))
            .sum::<f64>()
            / moving.len() as f64;
        assert!(
            d2.sqrt() > 0.1,
            "hip motion changes the knee's tau_ID: {}",
            d2.sqrt()
        );
    }

    #[test]
    fn a_state_on_another_clock_is_an_error_naming_the_joint() {
        let (run, mut st) = knee_run(1.0, true);
        st.q[1].truncate(500);
        let body = WholeBody::new(
            frictionless_dynamics::virtual_leg().unwrap(),
            Default::default(),
        )
        .unwrap();
        let joints = [JointLabel {
            joint: "l_knee".into(),
            label: SignalsLabel {
                source: frictionless_dataset::LabelSource::Current,
                gear_ratio_signed: Some(100.0),
                kt_nm_per_a: Some(0.1),
            },
            cfg: PreprocessConfig::for_joint("l_knee"),
        }];
        let runs = [RunJoints {
            signals: vec![&run],
            state: Some(&st),
        }];
        let e = preprocess_joints(&runs, &joints, Dynamics::WholeBody(&body))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("l_hip_pitch") && e.contains("mismatched time bases"),
            "{e}"
        );
        // A held joint the URDF lacks is refused.
        let e = WholeBody::new(
            frictionless_dynamics::virtual_leg().unwrap(),
            [("elbow".to_string(), 0.0)].into(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("elbow"), "{e}");
    }
}
