//! The label pipeline of [`crate::preprocess::preprocess_joints`] on a log read in blocks: the
//! log is never held whole. Samples arrive in blocks ([`StreamLabeller::push`]); each chunk's grid
//! is labelled in windows of `window` grid samples, each extended by `lead` samples before and
//! `trail` after so that the smoother and the zero-phase filter see what they see on the whole
//! chunk ([`margins`]: derived from the Kalman and Butterworth settings); only the window's rows are
//! kept. The rows of every joint are taken as they come ([`StreamLabeller::take_rows`]) and equal
//! the whole-log result to rounding (the margins are set for a relative 1e-13).
//!
//! The ripple step ([`crate::ripple`]) is refused here: it fits the whole log at once.
//!
//! Memory: the raw samples from the current window's lead margin on, at most `window + lead +
//! trail` grid samples per labelling step, plus the block being pushed ([`StreamStats`] records
//! the largest counts).

use frictionless::filter::Butterworth;
use frictionless_dataset::{Dataset, LabelSource};
use frictionless_dynamics::Workspace;

use crate::kalman;
use crate::preprocess::{PreprocessConfig, PreprocessError};
use crate::signals::{Dynamics, JointLabel, Labeller, RunJoints, RunSignals, SignalsSummary};
use crate::whole_body::JointStates;

/// Relative tolerance the margins are derived for.
pub const SETTLE_TOL: f64 = 1e-13;

/// Samples a windowed label needs before (`lead`) and after (`trail`) a window to equal the whole
/// chunk's, for one joint's settings: the Kalman smoother's ([`kalman::settle_samples`]) and the
/// zero-phase Butterworth's (pad length plus the samples after which its impulse response has
/// fallen below [`SETTLE_TOL`] of its peak), whichever is longer.
pub fn margins(cfg: &PreprocessConfig) -> Result<(usize, usize), PreprocessError> {
    let dt = 1.0 / cfg.fs_hz;
    let (kl, kt) = kalman::settle_samples(&cfg.kalman, dt, SETTLE_TOL)?;
    let bw = Butterworth::lowpass(cfg.butter_order, cfg.butter_cutoff_hz, cfg.fs_hz)?;
    const CAP: usize = 1 << 22;
    let mut impulse = vec![0.0; 1024];
    impulse[0] = 1.0;
    let mut zi = vec![[0.0; 2]; bw.sos.len()];
    let (mut peak, mut last, mut k) = (0.0f64, 0usize, 0usize);
    let mut quiet = 0usize;
    // The response in blocks until a whole block stays below the tolerance.
    while k < CAP {
        let h = frictionless::filter::sosfilt(&bw.sos, &impulse, &mut zi);
        impulse.iter_mut().for_each(|x| *x = 0.0);
        let mut loud = false;
        for (i, v) in h.iter().enumerate() {
            peak = peak.max(v.abs());
            if v.abs() > SETTLE_TOL * peak {
                last = k + i + 1;
                loud = true;
            }
        }
        k += h.len();
        quiet = if loud { 0 } else { quiet + 1 };
        if quiet >= 2 {
            break;
        }
    }
    if k >= CAP {
        return Err(PreprocessError::Config {
            name: "butter_cutoff_hz",
            value: cfg.butter_cutoff_hz,
            requirement: "a filter whose response settles within 2^22 samples",
        });
    }
    let b = bw.padlen() + last;
    Ok((kl.max(b), kt.max(b)))
}

/// What a streaming run held at most.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StreamStats {
    /// Grid samples per window.
    pub window: usize,
    /// Margin before a window [grid samples].
    pub lead: usize,
    /// Margin after a window [grid samples].
    pub trail: usize,
    /// Most grid samples labelled in one step (≤ window + lead + trail).
    pub max_grid_samples: usize,
    /// Most raw samples held at once (the current window's, its margins' and the pushed block's).
    pub max_raw_samples: usize,
    /// Labelling steps.
    pub steps: usize,
}

/// The open chunk: its first time, its raw samples already dropped, grid samples already labelled.
#[derive(Clone, Copy, Debug, Default)]
struct Open {
    t0: Option<f64>,
    drained: usize,
    emitted: usize,
}

/// A streaming labeller of several joints ([`crate::preprocess::preprocess_joints`]'s semantics).
pub struct StreamLabeller<'a> {
    joints: Vec<JointLabel>,
    dynamics: Dynamics<'a>,
    labellers: Vec<Labeller<'a>>,
    wanted: Vec<usize>,
    ws: Option<Workspace>,
    dt: f64,
    gap_s: f64,
    kalman: kalman::KalmanConfig,
    stats: StreamStats,
    /// The current run's raw samples, one per labelled joint (same clock).
    buf: Vec<RunSignals>,
    state: Option<JointStates>,
    /// Which series the first block had (every later block must have the same).
    layout: Option<Vec<bool>>,
    open: Open,
    scan_from: usize,
    runs: usize,
}

fn bad(msg: String) -> PreprocessError {
    PreprocessError::Sidecar {
        path: "imported signals".into(),
        msg,
    }
}

fn series(s: &RunSignals) -> [&Option<Vec<f64>>; 10] {
    [
        &s.s_rad,
        &s.sdot_rad_s,
        &s.sddot_rad_s2,
        &s.theta_motor_rad,
        &s.omega_motor_rad_s,
        &s.current_a,
        &s.tau_joint_nm,
        &s.tau_motor_nm,
        &s.tau_f_nm,
        &s.temperature_c,
    ]
}

fn series_mut(s: &mut RunSignals) -> [&mut Option<Vec<f64>>; 10] {
    [
        &mut s.s_rad,
        &mut s.sdot_rad_s,
        &mut s.sddot_rad_s2,
        &mut s.theta_motor_rad,
        &mut s.omega_motor_rad_s,
        &mut s.current_a,
        &mut s.tau_joint_nm,
        &mut s.tau_motor_nm,
        &mut s.tau_f_nm,
        &mut s.temperature_c,
    ]
}

/// Every series of a joint state, for appending and draining alike.
fn state_series_mut(st: &mut JointStates) -> Vec<&mut Vec<f64>> {
    let mut out: Vec<&mut Vec<f64>> = Vec::new();
    out.extend(st.q.iter_mut());
    out.extend(st.qdot.iter_mut().flatten());
    out.extend(st.qddot.iter_mut().flatten());
    if let Some(b) = st.base_quat_xyzw.as_mut() {
        out.extend(b.iter_mut());
    }
    for w in &mut st.wrenches {
        out.extend(w.series.iter_mut());
    }
    out
}

fn state_series(st: &JointStates) -> Vec<&Vec<f64>> {
    let mut out: Vec<&Vec<f64>> = Vec::new();
    out.extend(st.q.iter());
    out.extend(st.qdot.iter().flatten());
    out.extend(st.qddot.iter().flatten());
    if let Some(b) = st.base_quat_xyzw.as_ref() {
        out.extend(b.iter());
    }
    for w in &st.wrenches {
        out.extend(w.series.iter());
    }
    out
}

fn layout_of(block: &RunJoints<'_>) -> Vec<bool> {
    let mut v: Vec<bool> = block
        .signals
        .iter()
        .flat_map(|s| series(s).map(Option::is_some))
        .collect();
    v.push(block.state.is_some());
    if let Some(st) = block.state {
        v.extend(st.qdot.iter().map(Option::is_some));
        v.extend(st.qddot.iter().map(Option::is_some));
        v.push(st.base_quat_xyzw.is_some());
        v.extend(st.wrenches.iter().map(|_| true));
    }
    v
}

impl<'a> StreamLabeller<'a> {
    /// A labeller of `joints` with `dynamics` in windows of `window` grid samples (at least the
    /// larger margin; smaller values are raised to it).
    pub fn new(
        joints: &[JointLabel],
        dynamics: Dynamics<'a>,
        window: usize,
    ) -> Result<Self, PreprocessError> {
        let Some(first) = joints.first() else {
            return Err(PreprocessError::Empty);
        };
        if matches!(dynamics, Dynamics::Link(_)) && joints.len() > 1 {
            return Err(bad(
                "the single-joint view labels one joint; several joints need the whole body".into(),
            ));
        }
        let (mut lead, mut trail) = (0, 0);
        for jl in joints {
            jl.cfg.validate()?;
            if jl.cfg.ripple != crate::preprocess::Ripple::Off {
                return Err(PreprocessError::Settings(format!(
                    "joint `{}`: ripple {} fits the whole log at once and cannot run windowed; \
                     label without the window (the whole log in memory) or without the ripple step",
                    jl.joint,
                    jl.cfg.ripple.name()
                )));
            }
            let (l, t) = margins(&jl.cfg)?;
            lead = lead.max(l);
            trail = trail.max(t);
        }
        let (wanted, ws) = match dynamics {
            Dynamics::WholeBody(b) => (
                joints
                    .iter()
                    .filter(|jl| jl.label.source == LabelSource::Current)
                    .map(|jl| b.robot().joint_index(&jl.joint))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|e| bad(e.to_string()))?,
                Some(Workspace::new(b.robot())),
            ),
            _ => (Vec::new(), None),
        };
        Ok(Self {
            joints: joints.to_vec(),
            dynamics,
            labellers: Vec::new(),
            wanted,
            ws,
            dt: 1.0 / first.cfg.fs_hz,
            gap_s: first.cfg.gap_s,
            kalman: first.cfg.kalman,
            stats: StreamStats {
                window: window.max(lead).max(trail).max(1),
                lead,
                trail,
                ..StreamStats::default()
            },
            buf: Vec::new(),
            state: None,
            layout: None,
            open: Open::default(),
            scan_from: 1,
            runs: 0,
        })
    }

    /// The window and margins, and the largest counts so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Appends a block of consecutive samples of the current run (the first block starts a run):
    /// one [`RunSignals`] per labelled joint on one clock, and the whole-body state on that clock
    /// when the dynamics need it. Every block of every run must have the same signals.
    pub fn push(&mut self, block: &RunJoints<'_>) -> Result<(), PreprocessError> {
        let layout = layout_of(block);
        match &self.layout {
            None => self.layout = Some(layout),
            Some(l) if *l != layout => {
                return Err(bad(format!(
                    "run {}: a block has other signals than the first block",
                    self.runs
                )));
            }
            Some(_) => {}
        }
        if block.signals.len() != self.joints.len() {
            return Err(bad(format!(
                "a block has signals of {} joints, {} are labelled",
                block.signals.len(),
                self.joints.len()
            )));
        }
        let lead = block.signals[0];
        let n = lead.time_s.len();
        for (j, s) in block.signals.iter().enumerate() {
            if s.time_s != lead.time_s {
                return Err(bad(format!(
                    "run {}: joints `{}` and `{}` are not on one clock",
                    self.runs, self.joints[0].joint, self.joints[j].joint
                )));
            }
            for x in series(s).into_iter().flatten() {
                if x.len() != n {
                    return Err(bad(format!(
                        "run {}: joint `{}` has a series of {} samples in a block of {n}",
                        self.runs,
                        self.joints[j].joint,
                        x.len()
                    )));
                }
            }
        }
        if let Some(st) = block.state {
            st.check(n)
                .map_err(|msg| bad(format!("run {}: {msg}", self.runs)))?;
        }
        // Time order across the block edge and inside it.
        let before = self.buf.first().and_then(|b| b.time_s.last().copied());
        let base = self.buf.first().map_or(0, |b| b.time_s.len());
        let mut prev = before;
        for (k, &t) in lead.time_s.iter().enumerate() {
            if let Some(p) = prev
                && (t.is_nan() || t < p)
            {
                return Err(PreprocessError::Time {
                    index: base + k,
                    prev: p,
                    next: t,
                });
            }
            prev = Some(t);
        }
        // Append.
        if self.buf.is_empty() {
            self.buf = block
                .signals
                .iter()
                .map(|s| {
                    let mut e = RunSignals::default();
                    for (d, src) in series_mut(&mut e).into_iter().zip(series(s)) {
                        *d = src.as_ref().map(|_| Vec::new());
                    }
                    e
                })
                .collect();
            self.state = block.state.map(|st| JointStates {
                names: st.names.clone(),
                q: vec![Vec::new(); st.q.len()],
                qdot: st
                    .qdot
                    .iter()
                    .map(|x| x.as_ref().map(|_| Vec::new()))
                    .collect(),
                qddot: st
                    .qddot
                    .iter()
                    .map(|x| x.as_ref().map(|_| Vec::new()))
                    .collect(),
                base_quat_xyzw: st.base_quat_xyzw.as_ref().map(|_| Default::default()),
                base_frame: st.base_frame.clone(),
                wrenches: st
                    .wrenches
                    .iter()
                    .map(|w| crate::whole_body::FrameWrench {
                        frame: w.frame.clone(),
                        series: Default::default(),
                    })
                    .collect(),
            });
        }
        for (d, s) in self.buf.iter_mut().zip(&block.signals) {
            d.time_s.extend_from_slice(&s.time_s);
            if s.chunk.len() == n {
                d.chunk.extend_from_slice(&s.chunk);
            } else {
                d.chunk.extend(std::iter::repeat_n(0, n));
            }
            for (dv, sv) in series_mut(d).into_iter().zip(series(s)) {
                if let (Some(dv), Some(sv)) = (dv.as_mut(), sv) {
                    dv.extend_from_slice(sv);
                }
            }
        }
        if let (Some(d), Some(s)) = (self.state.as_mut(), block.state) {
            for (dv, sv) in state_series_mut(d).into_iter().zip(state_series(s)) {
                dv.extend_from_slice(sv);
            }
        }
        let held = self.buf[0].time_s.len();
        self.stats.max_raw_samples = self.stats.max_raw_samples.max(held);
        self.process(false)
    }

    /// Ends the current run: its last chunk is labelled.
    pub fn end_run(&mut self) -> Result<(), PreprocessError> {
        self.process(true)?;
        if !self.labellers.is_empty() {
            for l in &mut self.labellers {
                l.end_run();
            }
        }
        self.buf.clear();
        self.state = None;
        self.open = Open::default();
        self.scan_from = 1;
        self.runs += 1;
        Ok(())
    }

    /// The rows labelled since the last call, one dataset per joint (in the joints' order).
    pub fn take_rows(&mut self) -> Vec<Dataset> {
        self.labellers
            .iter_mut()
            .map(|l| std::mem::take(&mut l.ds))
            .collect()
    }

    /// The rows not yet taken and each joint's summary, after the last run ([`Self::end_run`]).
    pub fn finish(self) -> Result<(Vec<(Dataset, SignalsSummary)>, StreamStats), PreprocessError> {
        if self.labellers.is_empty() {
            return Err(PreprocessError::Empty);
        }
        let stats = self.stats;
        let out = self
            .labellers
            .into_iter()
            .map(Labeller::finish)
            .collect::<Result<_, _>>()?;
        Ok((out, stats))
    }

    /// Labels what the buffer allows: closed chunks whole, the open one window by window.
    fn process(&mut self, last: bool) -> Result<(), PreprocessError> {
        loop {
            let Some(lead) = self.buf.first() else {
                return Ok(());
            };
            let n = lead.time_s.len();
            if n == 0 {
                return Ok(());
            }
            if self.labellers.is_empty() {
                if n < 2 && !last {
                    return Ok(());
                }
                self.make_labellers()?;
            }
            let (t, c) = (&self.buf[0].time_s, &self.buf[0].chunk);
            let gap = self.gap_s;
            let end =
                (self.scan_from.max(1)..n).find(|&k| c[k] != c[k - 1] || t[k] - t[k - 1] > gap);
            match end {
                Some(e) => {
                    self.close_chunk(e)?;
                }
                None if last => {
                    self.close_chunk(n)?;
                    return Ok(());
                }
                None => {
                    self.scan_from = n;
                    return self.advance();
                }
            }
        }
    }

    fn make_labellers(&mut self) -> Result<(), PreprocessError> {
        let link = match self.dynamics {
            Dynamics::Link(l) => Some(l),
            _ => None,
        };
        let has_id = !matches!(self.dynamics, Dynamics::None);
        for (j, jl) in self.joints.iter().enumerate() {
            self.labellers.push(Labeller::new(
                &[&self.buf[j]],
                &jl.label,
                link,
                has_id,
                &jl.cfg,
            )?);
        }
        Ok(())
    }

    /// Grid samples of the open chunk up to time `t_last`, the chunk starting at `t0`.
    fn grid_len(&self, t0: f64, t_last: f64) -> usize {
        ((t_last - t0) / self.dt + 1e-9).floor() as usize + 1
    }

    /// Labels the open chunk's full windows whose trailing margin the buffer covers.
    fn advance(&mut self) -> Result<(), PreprocessError> {
        let n_raw = self.buf[0].time_s.len();
        let t0 = *self.open.t0.get_or_insert(self.buf[0].time_s[0]);
        let avail = self.grid_len(t0, self.buf[0].time_s[n_raw - 1]);
        let StreamStats {
            window,
            lead,
            trail,
            ..
        } = self.stats;
        while self.open.emitted + window + trail <= avail {
            let e = self.open.emitted;
            // The raw samples held now: each step drops those before the next lead margin.
            let held = self.buf[0].time_s.len();
            self.segment(
                t0,
                e.saturating_sub(lead),
                e + window + trail,
                e..e + window,
                held,
            )?;
            self.open.emitted = e + window;
            // Drop the raw samples before the next step's lead margin (keep the one bracketing it).
            let g0 = self.open.emitted.saturating_sub(lead);
            let tq0 = t0 + g0 as f64 * self.dt;
            let t = &self.buf[0].time_s;
            let r = t.partition_point(|&x| x <= tq0).saturating_sub(1);
            if r > 0 {
                self.drain(r);
                self.open.drained += r;
            }
        }
        Ok(())
    }

    /// Labels the rest of the chunk that ends before raw sample `e`, then drops its samples.
    fn close_chunk(&mut self, e: usize) -> Result<(), PreprocessError> {
        let t = &self.buf[0].time_s;
        let t0 = *self.open.t0.get_or_insert(t[0]);
        let total = self.open.drained + e;
        let t_last = t[e - 1];
        if total < 2 || t_last <= t0 {
            for l in &mut self.labellers {
                l.sum.dropped_single_sample_chunks += 1;
            }
        } else {
            let n = self.grid_len(t0, t_last);
            let StreamStats {
                window,
                lead,
                trail,
                ..
            } = self.stats;
            while self.open.emitted < n {
                let s = self.open.emitted;
                let w_end = if n - s > window { s + window } else { n };
                self.segment(
                    t0,
                    s.saturating_sub(lead),
                    (w_end + trail).min(n),
                    s..w_end,
                    e,
                )?;
                self.open.emitted = w_end;
            }
            for l in &mut self.labellers {
                l.end_chunk();
            }
        }
        self.drain(e);
        self.open = Open::default();
        self.scan_from = 1;
        Ok(())
    }

    /// Labels grid samples `g0..g1` of the open chunk (raw samples before `raw_end`) and keeps the
    /// rows `keep`.
    fn segment(
        &mut self,
        t0: f64,
        g0: usize,
        g1: usize,
        keep: std::ops::Range<usize>,
        raw_end: usize,
    ) -> Result<(), PreprocessError> {
        let dt = self.dt;
        let tq: Vec<f64> = (g0..g1).map(|k| t0 + k as f64 * dt).collect();
        let t = &self.buf[0].time_s[..raw_end];
        let a = t.partition_point(|&x| x <= tq[0]).saturating_sub(1);
        let last = tq[tq.len() - 1];
        let b = (t.partition_point(|&x| x < last) + 1).min(raw_end);
        self.stats.max_grid_samples = self.stats.max_grid_samples.max(tq.len());
        self.stats.steps += 1;
        let taus = match (self.dynamics, self.ws.as_mut()) {
            (Dynamics::WholeBody(body), Some(ws)) if !self.wanted.is_empty() => {
                let Some(st) = self.state.as_ref() else {
                    return Err(bad(format!(
                        "run {}: the whole-body label needs the joint positions",
                        self.runs
                    )));
                };
                let signals: Vec<&RunSignals> = self.buf.iter().collect();
                let tracks = body.tracks(st, &self.joints, &signals)?;
                Some(body.chunk_tau(
                    ws,
                    &tracks,
                    &self.buf[0].time_s,
                    a,
                    b,
                    &tq,
                    &self.kalman,
                    dt,
                    &self.wanted,
                )?)
            }
            _ => None,
        };
        let rows = (keep.start - g0)..(keep.end - g0);
        let mut w = 0;
        for (j, l) in self.labellers.iter_mut().enumerate() {
            let tau = if self.joints[j].label.source == LabelSource::Current {
                let x = taus.as_ref().map(|t| t[w].as_slice());
                w += 1;
                x
            } else {
                None
            };
            let run = &self.buf[j];
            l.chunk(run, &run.chunk, a, b, &tq, tau, rows.clone())?;
        }
        Ok(())
    }

    /// Drops the first `r` raw samples.
    fn drain(&mut self, r: usize) {
        for s in &mut self.buf {
            s.time_s.drain(..r);
            s.chunk.drain(..r);
            for x in series_mut(s).into_iter().flatten() {
                x.drain(..r);
            }
        }
        if let Some(st) = self.state.as_mut() {
            for x in state_series_mut(st) {
                x.drain(..r);
            }
        }
        self.scan_from = self.scan_from.saturating_sub(r).max(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preprocess::{LabelFilter, SignalsLabel, WholeBody, preprocess_joints};

    /// A two-run log of two moving leg joints: jittered sampling, chunk-id changes, a time gap, a
    /// chunk too short for the filter and a single-sample chunk, all at places that fall inside
    /// windows and across window edges.
    fn log() -> Vec<(Vec<RunSignals>, JointStates)> {
        let mut out = Vec::new();
        for run in 0..2 {
            let mut t = Vec::new();
            let mut chunk = Vec::new();
            let mut now = 0.25 * f64::from(run);
            let mut k = 0u64;
            while t.len() < 9000 + 1500 * run as usize {
                let i = t.len();
                // Chunk ids change at 2 345 and 7 010; a 0.4 s gap at 5 000; a 10-sample chunk
                // at 6 000 (shorter than the filter's pad) and a single-sample chunk at 8 000.
                let id = match i {
                    0..2345 => 0,
                    2345..6000 => 1,
                    6000..6010 => 2,
                    6010..7010 => 3,
                    7010..8000 => 4,
                    8000 => 5,
                    _ => 6,
                };
                if i == 5000 {
                    now += 0.4;
                }
                k = k
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                now += 1e-3 * (0.9 + 0.2 * ((k >> 40) as f64 / f64::from(1u32 << 24)));
                t.push(now);
                chunk.push(id);
            }
            let w = std::f64::consts::TAU * 0.7;
            let knee: Vec<f64> = t.iter().map(|t| -0.8 + 0.3 * (w * t).sin()).collect();
            let hip: Vec<f64> = t.iter().map(|t| 0.2 * (1.7 * w * t).cos()).collect();
            let ankle: Vec<f64> = t.iter().map(|t| 0.1 * (2.3 * w * t).sin()).collect();
            let sig = |s: &[f64], phase: f64| RunSignals {
                time_s: t.clone(),
                chunk: chunk.clone(),
                s_rad: Some(s.to_vec()),
                theta_motor_rad: Some(s.iter().map(|x| 100.0 * x + 0.01).collect()),
                current_a: Some(t.iter().map(|t| 0.5 * (3.0 * t + phase).sin()).collect()),
                temperature_c: Some(vec![30.0; t.len()]),
                ..RunSignals::default()
            };
            let signals = vec![sig(&knee, 0.0), sig(&hip, 1.0)];
            let n = t.len();
            let mut st = JointStates::with_names(
                vec![
                    "l_knee".into(),
                    "l_hip_pitch".into(),
                    "l_ankle_pitch".into(),
                ],
                &[],
                &[],
                n,
            );
            st.q = vec![knee, hip, ankle];
            out.push((signals, st));
        }
        out
    }

    fn joints(label_filter: LabelFilter) -> Vec<JointLabel> {
        ["l_knee", "l_hip_pitch"]
            .iter()
            .map(|j| JointLabel {
                joint: j.to_string(),
                label: SignalsLabel {
                    source: LabelSource::Current,
                    gear_ratio_signed: Some(100.0),
                    kt_nm_per_a: Some(0.1),
                },
                cfg: PreprocessConfig {
                    label_filter,
                    ..PreprocessConfig::for_joint(j)
                },
            })
            .collect()
    }

    fn slice(s: &RunSignals, r: std::ops::Range<usize>) -> RunSignals {
        let mut o = RunSignals {
            time_s: s.time_s[r.clone()].to_vec(),
            chunk: s.chunk[r.clone()].to_vec(),
            ..RunSignals::default()
        };
        for (d, x) in series_mut(&mut o).into_iter().zip(series(s)) {
            *d = x.as_ref().map(|x| x[r.clone()].to_vec());
        }
        o
    }

    fn slice_state(st: &JointStates, r: std::ops::Range<usize>) -> JointStates {
        let mut o = st.clone();
        for x in state_series_mut(&mut o) {
            *x = x[r.clone()].to_vec();
        }
        o
    }

    fn append(to: &mut Dataset, from: Dataset) {
        macro_rules! cat {
            ($($f:ident),*) => { $( to.$f.extend(from.$f); )* };
        }
        cat!(
            time_s,
            chunk,
            source_chunk,
            active,
            valid,
            s_rad,
            sdot_rad_s,
            sddot_rad_s2,
            theta_motor_rad,
            delta_theta_motor_rad,
            omega_motor_rad_s,
            i_meas_a,
            i_filt_a,
            tau_id_nm,
            tau_f_label_nm,
            temperature_c
        );
    }

    fn same(name: &str, a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len(), "{name}: row count");
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-9,
                "{name} row {k}: whole {x}, streamed {y}"
            );
        }
    }

    #[test]
    fn streamed_label_equals_the_whole_log_with_bounded_memory() {
        streamed_equals_whole(LabelFilter::Separate);
    }

    #[test]
    fn streamed_matched_label_equals_the_whole_log() {
        streamed_equals_whole(LabelFilter::Matched);
    }

    /// The ripple step fits the whole log: a windowed run refuses it before reading anything.
    #[test]
    fn the_ripple_step_is_refused_windowed() {
        let body = WholeBody::new(
            frictionless_dynamics::virtual_leg().unwrap(),
            Default::default(),
        )
        .unwrap();
        let mut joints = joints(LabelFilter::Matched);
        joints[1].cfg.ripple = crate::preprocess::Ripple::WaveGenerator;
        let e = StreamLabeller::new(&joints, Dynamics::WholeBody(&body), 4096)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("l_hip_pitch") && e.contains("whole log"), "{e}");
    }

    fn streamed_equals_whole(label_filter: LabelFilter) {
        let body = WholeBody::new(
            frictionless_dynamics::virtual_leg().unwrap(),
            Default::default(),
        )
        .unwrap();
        let log = log();
        let joints = joints(label_filter);
        let dynamics = Dynamics::WholeBody(&body);
        let runs: Vec<RunJoints<'_>> = log
            .iter()
            .map(|(s, st)| RunJoints {
                signals: s.iter().collect(),
                state: Some(st),
            })
            .collect();
        let whole = preprocess_joints(&runs, &joints, dynamics).unwrap();

        let window = 700;
        let mut sl = StreamLabeller::new(&joints, dynamics, window).unwrap();
        let StreamStats { lead, trail, .. } = sl.stats();
        assert!(lead > 0 && trail > 0, "margins {lead}, {trail}");
        let mut got: Vec<Dataset> = vec![Dataset::default(); joints.len()];
        // 1 600 rows hold two windows: a push that labels several windows in one call.
        let blocks = [1usize, 37, 250, 3, 511, 1600];
        let mut biggest = 0;
        for (signals, st) in &log {
            let n = signals[0].time_s.len();
            let (mut a, mut b) = (0, 0);
            while a < n {
                let e = (a + blocks[b % blocks.len()]).min(n);
                biggest = biggest.max(e - a);
                b += 1;
                let sig: Vec<RunSignals> = signals.iter().map(|s| slice(s, a..e)).collect();
                let state = slice_state(st, a..e);
                sl.push(&RunJoints {
                    signals: sig.iter().collect(),
                    state: Some(&state),
                })
                .unwrap();
                for (g, d) in got.iter_mut().zip(sl.take_rows()) {
                    append(g, d);
                }
                a = e;
            }
            sl.end_run().unwrap();
        }
        let (rest, stats) = sl.finish().unwrap();
        for (j, ((g, (d, sum_s)), (w, sum_w))) in got.iter_mut().zip(rest).zip(&whole).enumerate() {
            append(g, d);
            let name = &joints[j].joint;
            assert_eq!(g.chunk, w.chunk, "{name}: chunk ids");
            assert_eq!(g.source_chunk, w.source_chunk, "{name}: source chunks");
            assert_eq!(g.valid, w.valid, "{name}: valid flags");
            let invalid = w.valid.iter().filter(|v| !**v).count();
            assert!(invalid > 0, "{name}: the log drops rows");
            assert_eq!(
                sum_w.dropped.total(),
                invalid,
                "{name}: each dropped row once"
            );
            same("time_s", &w.time_s, &g.time_s);
            same("sdot_rad_s", &w.sdot_rad_s, &g.sdot_rad_s);
            same("sddot_rad_s2", &w.sddot_rad_s2, &g.sddot_rad_s2);
            same(
                "delta_theta",
                &w.delta_theta_motor_rad,
                &g.delta_theta_motor_rad,
            );
            same("i_filt_a", &w.i_filt_a, &g.i_filt_a);
            same("tau_id_nm", &w.tau_id_nm, &g.tau_id_nm);
            same("tau_f_label_nm", &w.tau_f_label_nm, &g.tau_f_label_nm);
            assert_eq!(sum_s, *sum_w, "{name}: summary");
        }
        let (w0, _) = &whole[0];
        assert!(w0.len() > 10 * window, "the log is long against the window");
        // The short chunk is in the log (both runs); the matched label runs no Butterworth on it.
        let short = if label_filter == LabelFilter::Separate {
            2
        } else {
            0
        };
        assert_eq!(whole[0].1.short_chunks, short, "{label_filter:?}");
        assert_eq!(whole[0].1.dropped_single_sample_chunks, 2);
        // Bounded memory: one step labels at most window + margins grid samples, and the raw
        // samples held are those of one step (sampling ≥ 0.9 ms on a 1 ms grid) plus a block.
        assert!(stats.steps >= w0.len() / window, "{stats:?}");
        assert!(stats.max_grid_samples <= window + lead + trail, "{stats:?}");
        let per_step = ((window + lead + trail) as f64 / 0.9).ceil() as usize + 2;
        assert!(stats.max_raw_samples <= per_step + biggest, "{stats:?}");
    }
}
