//! The label pipeline for imported robot signals ([`RunSignals`], from `frictionless-logs`):
//! several joints of one log in one pass ([`preprocess_joints`]), the per-joint labeller (current,
//! torque-sensor or given label) and the chunk loop shared by the whole-log and the windowed
//! (streaming) runs. The chunk split, resampler and filters are [`super::preprocess`]'s.

use super::kalman;
use super::matched;
use super::preprocess::{
    LabelFilter, PreprocessConfig, PreprocessError, Ripple, interp, split_chunks,
};
use super::whole_body::{JointStates, WholeBody};
use frictionless::filter::{Butterworth, FilterError};
use frictionless_dataset::Dataset;
use frictionless_sim::link::LinkDynamics;

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
    /// The invalid rows, by reason.
    pub dropped: crate::preprocess::DroppedRows,
    /// Chunks with a single sample, dropped.
    pub dropped_single_sample_chunks: usize,
    /// Dataset columns that are NaN in every row (no source signal).
    pub absent_columns: Vec<&'static str>,
    /// How each derived quantity was obtained (e.g. `sdot_rad_s: Kalman smoother on s`).
    pub derivations: Vec<String>,
    /// The ripple step's fit ([`crate::preprocess::Ripple::WaveGenerator`]; `None`: off, or too
    /// few rows to fit).
    pub ripple: Option<crate::ripple::RippleFit>,
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
pub(crate) struct Labeller<'a> {
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
    pub(crate) ds: Dataset,
    pub(crate) sum: SignalsSummary,
    chunk_id: u32,
    offset: Option<f64>,
    run_chunks: Vec<u32>,
    /// Rows labelled so far (the dataset may have been drained by a streaming run).
    rows: usize,
    /// [`matched::reach_samples`] of the smoother (0 unless the label is matched).
    reach: usize,
}

fn missing(column: &'static str) -> PreprocessError {
    PreprocessError::MissingColumn {
        path: "imported signals".into(),
        column,
    }
}

impl<'a> Labeller<'a> {
    /// `has_id`: τ_ID is available (a link or the whole body) for the `current` label.
    pub(crate) fn new(
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
        if cfg.ripple == Ripple::WaveGenerator {
            if label.source != L::Current {
                return Err(PreprocessError::Settings(format!(
                    "ripple {} corrects the `current` label, not the {:?} label",
                    cfg.ripple.name(),
                    label.source
                )));
            }
            if !has_theta {
                return Err(missing("theta (the ripple step's angle is the motor's)"));
            }
        }
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
        let reach = if cfg.label_filter == LabelFilter::Matched && label.source == L::Current {
            matched::reach_samples(&cfg.kalman, 1.0 / cfg.fs_hz)?
        } else {
            0
        };
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
            rows: 0,
            reach,
        })
    }

    /// The `current` label with [`LabelFilter::Matched`].
    fn matched_current(&self) -> bool {
        self.cfg.label_filter == LabelFilter::Matched
            && self.label.source == frictionless_dataset::LabelSource::Current
    }

    /// Labels samples `a..b` of `run` on the grid `tq` and appends the rows `keep` of `tq` to the
    /// dataset; `tau_id`: the whole-body τ_ID on `tq`. The chunk's id advances at
    /// [`Self::end_chunk`] (a chunk may be labelled in several overlapping segments).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn chunk(
        &mut self,
        run: &RunSignals,
        chunk_col: &[u32],
        a: usize,
        b: usize,
        tq: &[f64],
        tau_id_given: Option<&[f64]>,
        keep: std::ops::Range<usize>,
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
        // The matched `current` label gives the current the smoother's response (crate::matched).
        let i_f = match im.as_deref() {
            Some(i) if self.matched_current() => {
                Some(matched::smoothed_current(&cfg.kalman, dt, i)?)
            }
            other => other.map(&mut lowpass).transpose()?,
        };
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
        debug_assert!(keep.end <= n);
        // Labels and limits of every grid row (a matched label's row is valid only when its
        // smoother window, which reaches beyond `keep`, holds no rejected row).
        let reach = self.reach;
        let rows = if reach > 0 {
            keep.start.saturating_sub(reach)..(keep.end + reach).min(n)
        } else {
            keep.clone()
        };
        let mut labels = Vec::with_capacity(rows.len());
        let mut fails = Vec::with_capacity(rows.len());
        for k in rows.clone() {
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
            fails.push(l.first_failed(ak, vk, ifk, tau_f));
            labels.push((tau_id, tau_f, ifk));
        }
        let ok: Vec<bool> = fails.iter().map(Option::is_none).collect();
        let within = matched::within_reach(&ok, reach);
        let ds = &mut self.ds;
        self.rows += keep.len();
        for k in keep {
            let j = k - rows.start;
            let (tau_id, tau_f, ifk) = labels[j];
            let valid = chunk_ok && within[j];
            crate::preprocess::count_row(&mut self.sum.dropped, chunk_ok, fails[j], within[j]);
            let sk = s.as_ref().map_or(f64::NAN, |s| s[k]);
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
        Ok(())
    }

    /// Closes a chunk: the next rows belong to the next chunk id.
    pub(crate) fn end_chunk(&mut self) {
        self.run_chunks.push(self.chunk_id);
        self.chunk_id += 1;
    }

    /// Closes a run (its Δθ offset and chunk list).
    pub(crate) fn end_run(&mut self) {
        self.sum
            .delta_theta_offsets_motor_rad
            .push(self.offset.take().unwrap_or(f64::NAN));
        self.sum
            .run_chunks
            .push(std::mem::take(&mut self.run_chunks));
    }

    pub(crate) fn finish(mut self) -> Result<(Dataset, SignalsSummary), PreprocessError> {
        use frictionless_dataset::LabelSource as L;
        if self.rows == 0 {
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
/// A joint whose settings ask for the ripple step gets it ([`crate::ripple::correct`]; the joints
/// are labelled a second time with the fit's settings).
pub fn preprocess_joints(
    runs: &[RunJoints<'_>],
    joints: &[JointLabel],
    dynamics: Dynamics<'_>,
) -> Result<Vec<(Dataset, SignalsSummary)>, PreprocessError> {
    let mut out = label_joints(runs, joints, dynamics)?;
    if joints.iter().any(|j| j.cfg.ripple == Ripple::WaveGenerator) {
        let wide_joints: Vec<JointLabel> = joints
            .iter()
            .map(|j| JointLabel {
                cfg: crate::ripple::fit_settings(&j.cfg),
                ..j.clone()
            })
            .collect();
        let wide = label_joints(runs, &wide_joints, dynamics)?;
        for ((jl, (ds, sum)), (w, _)) in joints.iter().zip(&mut out).zip(&wide) {
            if jl.cfg.ripple != Ripple::WaveGenerator {
                continue;
            }
            sum.ripple = crate::ripple::correct(ds, w, &jl.cfg).map_err(|e| match e {
                PreprocessError::Settings(m) => {
                    PreprocessError::Settings(format!("joint `{}`: {m}", jl.joint))
                }
                e => e,
            })?;
            sum.derivations.push(sum.ripple.map_or_else(
                || {
                    "tau_f_label_nm: wave-generator ripple not identified (too few sliding rows)"
                        .into()
                },
                |r| r.describe(),
            ));
        }
    }
    Ok(out)
}

fn label_joints(
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
                l.chunk(run.signals[j], &chunk_col, a, b, &tq, tau, 0..tq.len())?;
                l.end_chunk();
            }
        }
        for l in &mut labellers {
            l.end_run();
        }
    }
    labellers.into_iter().map(Labeller::finish).collect()
}
