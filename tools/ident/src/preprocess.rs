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
use frictionless::filter::{Butterworth, FilterError};
use frictionless_dataset::Dataset;
use frictionless_sim::link::LinkDynamics;

pub use super::whole_body::{JointStates, StatePlan, WholeBody};

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
        }
    }

    fn validate(&self) -> Result<(), PreprocessError> {
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
    /// Δθ offset r·s₀ − θ₀ [motor rad].
    pub delta_theta_offset_motor_rad: f64,
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

fn preprocess_impl(
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
        let i_f = match bw.filtfilt(&im) {
            Ok(y) => y,
            Err(FilterError::TooShort { .. }) => {
                chunk_ok = false;
                summary.short_chunks += 1;
                im.clone()
            }
            Err(e) => return Err(e.into()),
        };
        let est = kalman::smooth(&cfg.kalman, dt, &s)?;
        let feat = if cfg.causal {
            kalman::filter(&cfg.kalman, dt, &s)?
        } else {
            est.clone()
        };
        // Reflected motor acceleration φ̈ (θ/r through the same smoother), only for the ablation.
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
            let l = &cfg.limits;
            let valid = chunk_ok
                && ak.abs() < l.joint_acc_limit_rad_s2
                && vk.abs() < l.joint_vel_limit_rad_s
                && i_f[k].abs() < l.im_limit_a
                && tau_f.abs() < l.tauf_limit_nm;
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

/// One run (one recording, usually one source file) of a robot's signals for one joint, on the
/// source's own clock: the input of [`preprocess_signals`]. Every signal but time is optional; each
/// present one has one value per entry of `time_s`, already in SI units with the project's signs
/// (the importer converts and checks; `frictionless-logs`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunSignals {
    /// Time [s], non-decreasing, finite (any clock; the dataset keeps it).
    pub time_s: Vec<f64>,
    /// Source chunk id per sample (0 when the source has none); a change starts a new chunk.
    pub chunk: Vec<u32>,
    /// Joint position s [rad].
    pub s_rad: Option<Vec<f64>>,
    /// Joint velocity ṡ [rad/s] (absent: from s through the Kalman smoother).
    pub sdot_rad_s: Option<Vec<f64>>,
    /// Joint acceleration s̈ [rad/s²] (absent: from ṡ through the Kalman smoother).
    pub sddot_rad_s2: Option<Vec<f64>>,
    /// Motor position θ [motor rad].
    pub theta_motor_rad: Option<Vec<f64>>,
    /// Motor velocity ω [motor rad/s].
    pub omega_motor_rad_s: Option<Vec<f64>>,
    /// Motor current [A].
    pub current_a: Option<Vec<f64>>,
    /// Joint torque sensor, link side [Nm].
    pub tau_joint_nm: Option<Vec<f64>>,
    /// Commanded or motor-side torque, reflected to the joint [Nm] (torque-sensor label).
    pub tau_motor_nm: Option<Vec<f64>>,
    /// Friction torque given by the source [Nm] (label `given`).
    pub tau_f_nm: Option<Vec<f64>>,
    /// Temperature [°C].
    pub temperature_c: Option<Vec<f64>>,
}

/// Which signals [`preprocess_signals`] needs for a label source, as role names (`s`, `current`, …);
/// a group `a|b` means either.
pub fn required_signals(label: frictionless_dataset::LabelSource) -> &'static [&'static str] {
    use frictionless_dataset::LabelSource as L;
    match label {
        L::Current => &["time", "s", "current"],
        L::TorqueSensor => &["time", "s|sdot", "tau_joint", "tau_motor|current"],
        L::Given => &["time", "s|sdot", "tau_f"],
    }
}

/// Label settings of [`preprocess_signals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalsLabel {
    /// Where the label comes from.
    pub source: frictionless_dataset::LabelSource,
    /// Signed gear ratio r (needed for r·k_t·i and for Δθ = r·s − θ).
    pub gear_ratio_signed: Option<f64>,
    /// Torque constant k_t [Nm/A] (needed for r·k_t·i).
    pub kt_nm_per_a: Option<f64>,
}

/// What [`preprocess_signals`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SignalsSummary {
    /// Dataset chunk ids of each run, in run order.
    pub run_chunks: Vec<Vec<u32>>,
    /// Δθ offset r·s₀ − θ₀ of each run [motor rad] (NaN without s or θ).
    pub delta_theta_offsets_motor_rad: Vec<f64>,
    /// Chunks too short for the zero-phase filter (their samples are invalid).
    pub short_chunks: usize,
    /// Chunks with a single sample, dropped.
    pub dropped_single_sample_chunks: usize,
    /// Dataset columns that are NaN in every row (no source signal).
    pub absent_columns: Vec<&'static str>,
    /// How each derived quantity was obtained (e.g. `sdot_rad_s: Kalman smoother on s`).
    pub derivations: Vec<String>,
}

fn all_or_none<'r>(
    runs: impl IntoIterator<Item = &'r RunSignals>,
    f: impl Fn(&RunSignals) -> bool,
) -> Option<bool> {
    let (mut n, mut yes) = (0usize, 0usize);
    for r in runs {
        n += 1;
        yes += usize::from(f(r));
    }
    if yes == 0 {
        Some(false)
    } else if yes == n {
        Some(true)
    } else {
        None
    }
}

/// Where τ_ID of the `current` label comes from.
#[derive(Clone, Copy)]
pub enum Dynamics<'a> {
    /// No inverse dynamics (labels other than `current`).
    None,
    /// The single-joint view: the labelled joint alone moves, the others are held ([`LinkDynamics`]).
    Link(&'a dyn LinkDynamics),
    /// Whole-body RNEA on every joint of the run's [`JointStates`] ([`WholeBody`]).
    WholeBody(&'a WholeBody),
}

/// One labelled joint of [`preprocess_joints`]: its name (the URDF's, for [`Dynamics::WholeBody`]),
/// label settings and pipeline configuration (its sample limits; the grid, filter and smoother
/// settings of the first joint are used for all).
#[derive(Clone, Debug)]
pub struct JointLabel {
    /// Joint name.
    pub joint: String,
    /// Label settings.
    pub label: SignalsLabel,
    /// Pipeline settings.
    pub cfg: PreprocessConfig,
}

/// One run of [`preprocess_joints`]: the labelled joints' signals in the order of the joint list, all
/// on one clock (same `time_s`), and the whole-body state on that clock when there is one.
#[derive(Clone, Debug)]
pub struct RunJoints<'a> {
    /// One entry per labelled joint.
    pub signals: Vec<&'a RunSignals>,
    /// Every joint the log has ([`Dynamics::WholeBody`] needs it).
    pub state: Option<&'a JointStates>,
}

/// The per-joint half of the pipeline: checks what a label needs, then labels chunk after chunk.
struct Labeller<'a> {
    label: SignalsLabel,
    cfg: PreprocessConfig,
    link: Option<&'a dyn LinkDynamics>,
    has_s: bool,
    has_theta: bool,
    has_omega: bool,
    has_i: bool,
    has_temp: bool,
    rkt: Option<f64>,
    r_dtheta: Option<f64>,
    bw: Butterworth,
    ds: Dataset,
    sum: SignalsSummary,
    chunk_id: u32,
    offset: Option<f64>,
    run_chunks: Vec<u32>,
}

fn missing(column: &'static str) -> PreprocessError {
    PreprocessError::MissingColumn {
        path: "imported signals".into(),
        column,
    }
}

impl<'a> Labeller<'a> {
    /// `has_id`: τ_ID is available (a link or the whole body) for the `current` label.
    fn new(
        runs: &[&RunSignals],
        label: &SignalsLabel,
        link: Option<&'a dyn LinkDynamics>,
        has_id: bool,
        cfg: &PreprocessConfig,
    ) -> Result<Self, PreprocessError> {
        use frictionless_dataset::LabelSource as L;
        cfg.validate()?;
        if runs.is_empty() || runs.iter().all(|r| r.time_s.len() < 2) {
            return Err(PreprocessError::Empty);
        }
        macro_rules! has {
            ($f:ident, $name:literal) => {
                all_or_none(runs.iter().copied(), |r| r.$f.is_some()).ok_or(
                    PreprocessError::Sidecar {
                        path: "imported signals".into(),
                        msg: format!("signal `{}` is present in some runs but not in all", $name),
                    },
                )?
            };
        }
        let has_s = has!(s_rad, "s");
        let has_sdot = has!(sdot_rad_s, "sdot");
        let has_sddot = has!(sddot_rad_s2, "sddot");
        let has_theta = has!(theta_motor_rad, "theta");
        let has_omega = has!(omega_motor_rad_s, "omega");
        let has_i = has!(current_a, "current");
        let has_tj = has!(tau_joint_nm, "tau_joint");
        let has_tm = has!(tau_motor_nm, "tau_motor");
        let has_tf = has!(tau_f_nm, "tau_f");
        let has_temp = has!(temperature_c, "temperature");
        if !has_s && !has_sdot {
            return Err(missing("s (or sdot)"));
        }
        let r_opt = label.gear_ratio_signed;
        let kt_opt = label.kt_nm_per_a;
        let need_r = |what: &'static str| {
            r_opt
                .filter(|r| r.is_finite() && *r != 0.0)
                .ok_or(PreprocessError::Config {
                    name: "gear_ratio_signed",
                    value: r_opt.unwrap_or(f64::NAN),
                    requirement: what,
                })
        };
        let need_kt = |what: &'static str| {
            kt_opt
                .filter(|k| k.is_finite() && *k > 0.0)
                .ok_or(PreprocessError::Config {
                    name: "kt_nm_per_a",
                    value: kt_opt.unwrap_or(f64::NAN),
                    requirement: what,
                })
        };
        // r·k_t for the motor-side torque from current, when the label needs it.
        let rkt = match label.source {
            L::Current => {
                if !has_s {
                    return Err(missing("s"));
                }
                if !has_i {
                    return Err(missing("current"));
                }
                if !has_id {
                    return Err(PreprocessError::Sidecar {
                        path: "imported signals".into(),
                        msg: "the current label needs link dynamics (a URDF joint or a link model)"
                            .into(),
                    });
                }
                Some(
                    need_r("finite and non-zero (the current label needs the signed gear ratio)")?
                        * need_kt("finite and > 0 (the current label needs k_t)")?,
                )
            }
            L::TorqueSensor => {
                if !has_tj {
                    return Err(missing("tau_joint"));
                }
                if has_tm {
                    None
                } else if has_i {
                    Some(
                        need_r(
                            "finite and non-zero (tau_motor = r*kt*current needs the gear ratio)",
                        )? * need_kt("finite and > 0 (tau_motor = r*kt*current needs k_t)")?,
                    )
                } else {
                    return Err(missing("tau_motor (or current)"));
                }
            }
            L::Given => {
                if !has_tf {
                    return Err(missing("tau_f"));
                }
                None
            }
        };
        let r_dtheta = if has_s && has_theta {
            Some(need_r(
                "finite and non-zero (delta theta = r*s - theta needs the gear ratio)",
            )?)
        } else {
            None
        };
        let bw = Butterworth::lowpass(cfg.butter_order, cfg.butter_cutoff_hz, cfg.fs_hz)?;
        let mut sum = SignalsSummary::default();
        let mut derive = |d: &str| sum.derivations.push(d.to_string());
        if !has_sdot {
            derive("sdot_rad_s: Kalman smoother on s (causal filter with `causal`)");
        }
        if !has_sddot {
            derive(if has_sdot {
                "sddot_rad_s2: Kalman smoother on the given sdot"
            } else {
                "sddot_rad_s2: Kalman smoother on s (causal filter with `causal`)"
            });
        }
        if has_i {
            derive("i_filt_a: zero-phase Butterworth of the current");
        }
        if label.source == L::Current && link.is_none() {
            derive(
                "tau_id_nm: whole-body RNEA(q, qdot, qddot) on the URDF, every joint of the log smoothed like s",
            );
        }
        match label.source {
            L::Current => derive("tau_f_label_nm: r*kt*i_filt - tau_id"),
            L::TorqueSensor if has_tm => derive(
                "tau_f_label_nm: tau_motor - tau_joint, both through the zero-phase Butterworth",
            ),
            L::TorqueSensor => derive(
                "tau_f_label_nm: r*kt*i_filt - tau_joint, tau_joint through the zero-phase Butterworth",
            ),
            L::Given => derive("tau_f_label_nm: the given tau_f, interpolated"),
        }
        Ok(Self {
            label: *label,
            cfg: cfg.clone(),
            link,
            has_s,
            has_theta,
            has_omega,
            has_i,
            has_temp,
            rkt,
            r_dtheta,
            bw,
            ds: Dataset::default(),
            sum,
            chunk_id: 0,
            offset: None,
            run_chunks: Vec::new(),
        })
    }

    /// Labels samples `a..b` of `run` on the grid `tq`; `tau_id`: the whole-body τ_ID on `tq`.
    #[allow(clippy::too_many_arguments)]
    fn chunk(
        &mut self,
        run: &RunSignals,
        chunk_col: &[u32],
        a: usize,
        b: usize,
        tq: &[f64],
        tau_id_given: Option<&[f64]>,
    ) -> Result<(), PreprocessError> {
        use frictionless_dataset::LabelSource as L;
        let cfg = &self.cfg;
        let dt = 1.0 / cfg.fs_hz;
        let n = tq.len();
        let t = &run.time_s[a..b];
        let li = |y: &Option<Vec<f64>>| y.as_ref().map(|y| interp(t, &y[a..b], tq));
        let mut chunk_ok = true;
        let bw = &self.bw;
        let mut lowpass = |x: &[f64]| -> Result<Vec<f64>, PreprocessError> {
            match bw.filtfilt(x) {
                Ok(y) => Ok(y),
                Err(FilterError::TooShort { .. }) => {
                    chunk_ok = false;
                    Ok(x.to_vec())
                }
                Err(e) => Err(e.into()),
            }
        };
        let s = li(&run.s_rad);
        let sdot_given = li(&run.sdot_rad_s);
        let sddot_given = li(&run.sddot_rad_s2);
        let theta = li(&run.theta_motor_rad);
        let omega = li(&run.omega_motor_rad_s);
        let im = li(&run.current_a);
        let i_f = im.as_deref().map(&mut lowpass).transpose()?;
        let tj = li(&run.tau_joint_nm)
            .as_deref()
            .map(&mut lowpass)
            .transpose()?;
        let tm = li(&run.tau_motor_nm)
            .as_deref()
            .map(&mut lowpass)
            .transpose()?;
        let tf = li(&run.tau_f_nm);
        let temp = li(&run.temperature_c);
        if !chunk_ok {
            self.sum.short_chunks += 1;
        }
        // Non-causal estimates (label, sample filters) and the columns the models read.
        let (vel_nc, acc_nc, vel_col, acc_col) = match (&s, &sdot_given) {
            (_, Some(v)) => {
                let acc = match &sddot_given {
                    Some(a) => (a.clone(), a.clone()),
                    None => {
                        let e = kalman::smooth(&cfg.kalman, dt, v)?;
                        let c = if cfg.causal {
                            kalman::filter(&cfg.kalman, dt, v)?.vel_rad_s
                        } else {
                            e.vel_rad_s.clone()
                        };
                        (e.vel_rad_s, c)
                    }
                };
                (v.clone(), acc.0, v.clone(), acc.1)
            }
            (Some(s), None) => {
                let e = kalman::smooth(&cfg.kalman, dt, s)?;
                let c = if cfg.causal {
                    kalman::filter(&cfg.kalman, dt, s)?
                } else {
                    e.clone()
                };
                let (acc_nc, acc_col) = match &sddot_given {
                    Some(a) => (a.clone(), a.clone()),
                    None => (e.acc_rad_s2, c.acc_rad_s2),
                };
                (e.vel_rad_s, acc_nc, c.vel_rad_s, acc_col)
            }
            (None, None) => return Err(missing("s (or sdot)")),
        };
        let s0 = s.as_ref().map(|s| s[0]);
        let off = match (self.r_dtheta, s0, &theta) {
            (Some(r), Some(s0), Some(th)) => *self.offset.get_or_insert(r * s0 - th[0]),
            _ => f64::NAN,
        };
        let l = &cfg.limits;
        let ds = &mut self.ds;
        for k in 0..n {
            let sk = s.as_ref().map_or(f64::NAN, |s| s[k]);
            let (vk, ak) = (vel_nc[k], acc_nc[k]);
            let tau_id = match (self.label.source, tau_id_given, self.link) {
                (L::Current, Some(tau), _) => tau[k],
                (L::Current, None, Some(link)) => {
                    link.inertia_kgm2(sk) * ak
                        + link.velocity_torque_nm(sk, vk)
                        + link.gravity_nm(sk)
                }
                _ => f64::NAN,
            };
            let ifk = i_f.as_ref().map_or(f64::NAN, |i| i[k]);
            let tau_f = match self.label.source {
                L::Current => self.rkt.unwrap_or(f64::NAN) * ifk - tau_id,
                L::TorqueSensor => {
                    let motor = match (&tm, self.rkt) {
                        (Some(tm), _) => tm[k],
                        (None, Some(rkt)) => rkt * ifk,
                        (None, None) => f64::NAN,
                    };
                    motor - tj.as_ref().map_or(f64::NAN, |x| x[k])
                }
                L::Given => tf.as_ref().map_or(f64::NAN, |x| x[k]),
            };
            // A limit on an absent quantity (NaN) does not reject the sample.
            let within = |x: f64, lim: f64| x.is_nan() || x.abs() < lim;
            let valid = chunk_ok
                && tau_f.is_finite()
                && vk.is_finite()
                && within(ak, l.joint_acc_limit_rad_s2)
                && within(vk, l.joint_vel_limit_rad_s)
                && within(ifk, l.im_limit_a)
                && tau_f.abs() < l.tauf_limit_nm;
            let at = |x: &Option<Vec<f64>>| x.as_ref().map_or(f64::NAN, |x| x[k]);
            let thk = at(&theta);
            ds.time_s.push(tq[k]);
            ds.chunk.push(self.chunk_id);
            ds.source_chunk.push(chunk_col[a]);
            ds.active.push(true);
            ds.valid.push(valid);
            ds.s_rad.push(sk);
            ds.sdot_rad_s.push(vel_col[k]);
            ds.sddot_rad_s2.push(acc_col[k]);
            ds.theta_motor_rad.push(thk);
            ds.delta_theta_motor_rad
                .push(self.r_dtheta.map_or(f64::NAN, |r| r * sk - thk - off));
            ds.omega_motor_rad_s.push(at(&omega));
            ds.i_meas_a.push(at(&im));
            ds.i_filt_a.push(ifk);
            ds.tau_id_nm.push(tau_id);
            ds.tau_f_label_nm.push(tau_f);
            ds.temperature_c.push(at(&temp));
        }
        self.run_chunks.push(self.chunk_id);
        self.chunk_id += 1;
        Ok(())
    }

    /// Closes a run (its Δθ offset and chunk list).
    fn end_run(&mut self) {
        self.sum
            .delta_theta_offsets_motor_rad
            .push(self.offset.take().unwrap_or(f64::NAN));
        self.sum
            .run_chunks
            .push(std::mem::take(&mut self.run_chunks));
    }

    fn finish(mut self) -> Result<(Dataset, SignalsSummary), PreprocessError> {
        use frictionless_dataset::LabelSource as L;
        if self.ds.is_empty() {
            return Err(PreprocessError::Empty);
        }
        let mut absent = Vec::new();
        if !self.has_s {
            absent.push("s_rad");
        }
        if !self.has_theta {
            absent.push("theta_motor_rad");
        }
        if self.r_dtheta.is_none() {
            absent.push("delta_theta_motor_rad");
        }
        if !self.has_omega {
            absent.push("omega_motor_rad_s");
        }
        if !self.has_i {
            absent.extend(["i_meas_a", "i_filt_a"]);
        }
        if self.label.source != L::Current {
            absent.push("tau_id_nm");
        }
        if !self.has_temp {
            absent.push("temperature_c");
        }
        self.sum.absent_columns = absent;
        Ok((self.ds, self.sum))
    }
}

/// The label pipeline for imported robot signals: every run is split into chunks (source chunk id
/// change or a gap > `cfg.gap_s`), each chunk linearly interpolated onto the uniform `cfg.fs_hz` grid
/// from its first to its last sample (no extrapolation, nothing bridged across a gap), ṡ/s̈ taken as
/// given or from the Kalman smoother (s → ṡ, s̈; a given ṡ → s̈), current and torque signals through the
/// zero-phase Butterworth, then the label of `label.source`:
/// - `current`: r·k_t·i_f − τ_ID (needs `link`, s, current, r and k_t);
/// - `torque-sensor`: τ_motor − τ_joint, with τ_motor the given motor-side torque or r·k_t·i_f;
/// - `given`: the source's τ_F.
///
/// Signals a run lacks become NaN columns listed in [`SignalsSummary::absent_columns`]; a signal
/// must be present in all runs or none. Chunks are numbered across runs. One joint with the
/// single-joint view of the link; [`preprocess_joints`] labels several joints with the whole body.
pub fn preprocess_signals(
    runs: &[RunSignals],
    label: &SignalsLabel,
    link: Option<&dyn LinkDynamics>,
    cfg: &PreprocessConfig,
) -> Result<(Dataset, SignalsSummary), PreprocessError> {
    let joints = [JointLabel {
        joint: String::new(),
        label: *label,
        cfg: cfg.clone(),
    }];
    let runs: Vec<RunJoints<'_>> = runs
        .iter()
        .map(|r| RunJoints {
            signals: vec![r],
            state: None,
        })
        .collect();
    let dynamics = link.map_or(Dynamics::None, Dynamics::Link);
    let mut out = preprocess_joints(&runs, &joints, dynamics)?;
    Ok(out.remove(0))
}

/// The pipeline of [`preprocess_signals`] for several joints of one log in one pass: the runs' chunks
/// and grids are shared, and with [`Dynamics::WholeBody`] one RNEA per grid sample gives τ_ID of every
/// labelled joint (each run needs its [`RunJoints::state`]). One dataset per joint, in `joints` order.
pub fn preprocess_joints(
    runs: &[RunJoints<'_>],
    joints: &[JointLabel],
    dynamics: Dynamics<'_>,
) -> Result<Vec<(Dataset, SignalsSummary)>, PreprocessError> {
    let Some(first) = joints.first() else {
        return Err(PreprocessError::Empty);
    };
    let link = match dynamics {
        Dynamics::Link(l) => Some(l),
        _ => None,
    };
    if link.is_some() && joints.len() > 1 {
        return Err(PreprocessError::Sidecar {
            path: "imported signals".into(),
            msg: "the single-joint view labels one joint; several joints need the whole body"
                .into(),
        });
    }
    let has_id = !matches!(dynamics, Dynamics::None);
    let mut labellers = Vec::with_capacity(joints.len());
    for (j, jl) in joints.iter().enumerate() {
        let mine: Vec<&RunSignals> = runs
            .iter()
            .map(|r| {
                r.signals.get(j).copied().ok_or(PreprocessError::Sidecar {
                    path: "imported signals".into(),
                    msg: format!("a run has no signals for joint `{}`", jl.joint),
                })
            })
            .collect::<Result<_, _>>()?;
        labellers.push(Labeller::new(&mine, &jl.label, link, has_id, &jl.cfg)?);
    }
    let body = match dynamics {
        Dynamics::WholeBody(b) => Some(b),
        _ => None,
    };
    let current = |j: usize| joints[j].label.source == frictionless_dataset::LabelSource::Current;
    let wanted: Vec<usize> = match body {
        Some(b) => joints
            .iter()
            .filter(|jl| jl.label.source == frictionless_dataset::LabelSource::Current)
            .map(|jl| b.robot().joint_index(&jl.joint))
            .collect::<Result<_, _>>()
            .map_err(|e| PreprocessError::Sidecar {
                path: "imported signals".into(),
                msg: e.to_string(),
            })?,
        None => Vec::new(),
    };
    let cfg = &first.cfg;
    let dt = 1.0 / cfg.fs_hz;
    let mut ws = body.map(|b| frictionless_dynamics::Workspace::new(b.robot()));
    for (ri, run) in runs.iter().enumerate() {
        let lead = run.signals[0];
        let n_run = lead.time_s.len();
        for k in 1..n_run {
            if lead.time_s[k].is_nan() || lead.time_s[k] < lead.time_s[k - 1] {
                return Err(PreprocessError::Time {
                    index: k,
                    prev: lead.time_s[k - 1],
                    next: lead.time_s[k],
                });
            }
        }
        for (j, s) in run.signals.iter().enumerate().skip(1) {
            if s.time_s != lead.time_s {
                return Err(PreprocessError::Sidecar {
                    path: "imported signals".into(),
                    msg: format!(
                        "run {ri}: joints `{}` and `{}` are not on one clock ({} and {} samples)",
                        joints[0].joint,
                        joints[j].joint,
                        n_run,
                        s.time_s.len()
                    ),
                });
            }
        }
        let tracks = match (body, run.state) {
            (Some(b), Some(st)) => {
                st.check(n_run).map_err(|msg| PreprocessError::Sidecar {
                    path: "imported signals".into(),
                    msg: format!("run {ri}: {msg}"),
                })?;
                Some(b.tracks(st, joints, &run.signals)?)
            }
            (Some(_), None) if wanted.is_empty() => None,
            (Some(_), None) => {
                return Err(PreprocessError::Sidecar {
                    path: "imported signals".into(),
                    msg: format!("run {ri}: the whole-body label needs the joint positions"),
                });
            }
            _ => None,
        };
        let chunk_col = if lead.chunk.len() == n_run {
            std::borrow::Cow::Borrowed(&lead.chunk[..])
        } else {
            std::borrow::Cow::Owned(vec![0; n_run])
        };
        for (a, b) in split_chunks(&lead.time_s, &chunk_col, cfg.gap_s) {
            let t = &lead.time_s[a..b];
            if b - a < 2 || t[t.len() - 1] <= t[0] {
                for l in &mut labellers {
                    l.sum.dropped_single_sample_chunks += 1;
                }
                continue;
            }
            let n = ((t[t.len() - 1] - t[0]) / dt + 1e-9).floor() as usize + 1;
            let tq: Vec<f64> = (0..n).map(|k| t[0] + k as f64 * dt).collect();
            let taus = match (body, &tracks, ws.as_mut()) {
                (Some(bd), Some(tr), Some(ws)) if !wanted.is_empty() => {
                    Some(bd.chunk_tau(ws, tr, &lead.time_s, a, b, &tq, &cfg.kalman, dt, &wanted)?)
                }
                _ => None,
            };
            let mut w = 0;
            for (j, l) in labellers.iter_mut().enumerate() {
                let tau = if current(j) {
                    let t = taus.as_ref().map(|t| t[w].as_slice());
                    w += 1;
                    t
                } else {
                    None
                };
                l.chunk(run.signals[j], &chunk_col, a, b, &tq, tau)?;
            }
        }
        for l in &mut labellers {
            l.end_run();
        }
    }
    labellers.into_iter().map(Labeller::finish).collect()
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
        let plan = body.plan(&st.names, &["l_knee".to_string()], false);
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
