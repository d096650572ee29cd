//! The excitation protocol: block schedule, controllers, guards, and the run loop over a [`JointIo`].
//!
//! What it is: [`schedule`] turns a [`ProtocolConfig`] into a list of [`Block`]s (each its own chunk:
//! every sine frequency, ramp, step and tracking (A, f) pair, for each starting pose), and [`run`] plays
//! them at 1 kHz: a position-controlled re-centring to the block's start before every block, the block
//! itself (open-loop current, or closed-loop sine tracking), and the guards — if s comes within the
//! margin of a range limit, or |i_meas| reaches the safety current, the joint is held in position control
//! until the block ends and those samples are marked inactive.
//!
//! The seam to the hardware is [`JointIo`]: the offline simulator implements it here
//! ([`SimJoint`]); a live plant over shared memory implements it in
//! `serve::shm::LiveJoint` in `frictl`. Controllers only see [`Measurement`]s (quantised encoders,
//! noisy current), never the simulator's truth. [`VelocityEstimator`] is the causal joint velocity
//! both the controllers and the served plant's `JointStates::sdot_rad_s` use.
//!
//! What it is not: file output ([`crate::log`]) or a label pipeline.

use serde::Serialize;

use crate::config::{HoldingCurrent, ProtocolConfig};
use frictionless_sim::PlantParams;
use frictionless_sim::link::LinkDynamics;
use frictionless_sim::plant::{Measurement, Plant, Truth};

/// Errors while running the protocol.
#[derive(Debug, thiserror::Error)]
pub enum AcquireError {
    /// The joint I/O failed (live plants; the simulator never fails).
    #[error("joint I/O failed at t = {time_s} s: {why}")]
    Io {
        /// Time of the failure [s].
        time_s: f64,
        /// Description.
        why: String,
    },
    /// The sink (log writer) failed.
    #[error("writing the log failed: {0}")]
    Sink(String),
}

/// One control period of a joint: the seam between the protocol and a plant (simulated or live).
pub trait JointIo {
    /// The latest measurement (before any command: the initial one).
    fn measurement(&self) -> Measurement;
    /// Applies `i_ref_a` (robot convention) for one control period and returns the next measurement.
    fn exchange(&mut self, i_ref_a: f64) -> Result<Measurement, AcquireError>;
    /// The truth behind the latest measurement, if the plant is simulated.
    fn truth(&self) -> Option<Truth>;
}

/// The offline simulator as a [`JointIo`], with an optional external torque.
pub struct SimJoint<L: LinkDynamics> {
    /// The plant.
    pub plant: Plant<L>,
    /// External joint torque applied during every period [Nm].
    pub tau_ext_nm: f64,
}

impl<L: LinkDynamics> JointIo for SimJoint<L> {
    fn measurement(&self) -> Measurement {
        self.plant.measurement()
    }
    fn exchange(&mut self, i_ref_a: f64) -> Result<Measurement, AcquireError> {
        Ok(self.plant.step(i_ref_a, self.tau_ext_nm).meas)
    }
    fn truth(&self) -> Option<Truth> {
        Some(self.plant.truth())
    }
}

/// What the controller knows about the joint (nominal model, robot conventions).
pub struct ControllerModel<'a> {
    /// Signed gear ratio.
    pub gear_ratio_signed: f64,
    /// Torque constant [Nm/A].
    pub kt_nm_per_a: f64,
    /// Reflected motor inertia J_eq [kg·m²].
    pub j_eq_kgm2: f64,
    /// Current saturation [A].
    pub i_max_a: f64,
    /// Control period [s].
    pub period_s: f64,
    /// Link inertia and gravity.
    pub link: &'a dyn LinkDynamics,
}

impl<'a> ControllerModel<'a> {
    /// The nominal model of a simulated joint: its signed gear ratio, k_t, reflected motor inertia,
    /// current saturation and sample period from `params`, with `link` (built from `params.link`,
    /// e.g. by [`frictionless_sim::link::link_from_model`]).
    pub fn nominal(params: &PlantParams, link: &'a dyn LinkDynamics) -> Self {
        Self {
            gear_ratio_signed: params.gear_ratio_signed,
            kt_nm_per_a: params.kt_nm_per_a,
            j_eq_kgm2: params.j_eq_kgm2(),
            i_max_a: params.i_max_a,
            period_s: params.sample_period_s(),
            link,
        }
    }

    fn current_for_torque(&self, tau_nm: f64) -> f64 {
        tau_nm / (self.gear_ratio_signed * self.kt_nm_per_a)
    }
    /// i_ref for a commanded joint acceleration with gravity feed-forward, clipped at ±i_max.
    fn current_for_accel(&self, s_rad: f64, s_ddot_cmd: f64) -> f64 {
        let inertia = self.link.inertia_kgm2(s_rad) + self.j_eq_kgm2;
        self.current_for_torque(s_ddot_cmd * inertia + self.link.gravity_nm(s_rad))
            .clamp(-self.i_max_a, self.i_max_a)
    }
}

/// What a block does after its re-centring.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum BlockKind {
    /// i₀ + A·sin(2πft) for `cycles` periods.
    Sine {
        /// Amplitude A (scaled) [A].
        amplitude_a: f64,
        /// Frequency [Hz].
        frequency_hz: f64,
        /// Periods.
        cycles: f64,
    },
    /// i₀ + slope·t until |Δi| = max (slope signed).
    Ramp {
        /// Signed slope (scaled) [A/s].
        slope_a_per_s: f64,
        /// Final |Δi| (scaled) [A].
        max_increment_a: f64,
    },
    /// i₀ + L for `hold_s`, then i₀ for `rest_s`.
    Step {
        /// Level L (scaled) [A].
        level_a: f64,
        /// Hold time [s].
        hold_s: f64,
        /// Rest time [s].
        rest_s: f64,
    },
    /// Closed-loop sine tracking s_d = c + A·sin(2πft).
    Tracking {
        /// Tracking set name.
        set: String,
        /// Amplitude [rad].
        amplitude_rad: f64,
        /// Frequency [Hz].
        frequency_hz: f64,
        /// K_p [1/s²].
        kp_per_s2: f64,
        /// Periods.
        cycles: f64,
    },
}

/// One block of the protocol: one chunk of the log.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Block {
    /// Chunk id (0, 1, … in play order).
    pub chunk: u32,
    /// Re-centring target [rad] (the starting pose; the centre for tracking).
    pub start_rad: f64,
    /// Re-centring duration [s].
    pub recentre_s: f64,
    /// The excitation.
    #[serde(flatten)]
    pub kind: BlockKind,
}

impl Block {
    /// Duration of the excitation part (after re-centring) [s].
    pub fn excitation_s(&self) -> f64 {
        match self.kind {
            BlockKind::Sine {
                frequency_hz,
                cycles,
                ..
            }
            | BlockKind::Tracking {
                frequency_hz,
                cycles,
                ..
            } => cycles / frequency_hz,
            BlockKind::Ramp {
                slope_a_per_s,
                max_increment_a,
            } => max_increment_a / slope_a_per_s.abs(),
            BlockKind::Step { hold_s, rest_s, .. } => hold_s + rest_s,
        }
    }
}

/// The protocol's blocks in play order: for each start, sines (amplitude low → high, frequencies as
/// configured), ramps (each slope up then down), steps; then every enabled tracking set.
pub fn schedule(cfg: &ProtocolConfig) -> Vec<Block> {
    let sc = cfg.current_scale;
    let mut kinds: Vec<(f64, BlockKind)> = Vec::new();
    for start in cfg.starts_rad() {
        if cfg.sines.enabled {
            for a in cfg.sines.amplitudes_a() {
                for &f in &cfg.sines.frequencies_hz {
                    kinds.push((
                        start,
                        BlockKind::Sine {
                            amplitude_a: a * sc,
                            frequency_hz: f,
                            cycles: cfg.sines.cycles,
                        },
                    ));
                }
            }
        }
        if cfg.ramps.enabled {
            for &slope in &cfg.ramps.slopes_a_per_s {
                for sign in [1.0, -1.0] {
                    kinds.push((
                        start,
                        BlockKind::Ramp {
                            slope_a_per_s: sign * slope * sc,
                            max_increment_a: cfg.ramps.max_increment_a * sc,
                        },
                    ));
                }
            }
        }
        if cfg.steps.enabled {
            for &l in &cfg.steps.levels_a {
                kinds.push((
                    start,
                    BlockKind::Step {
                        level_a: l * sc,
                        hold_s: cfg.steps.hold_s,
                        rest_s: cfg.steps.rest_s,
                    },
                ));
            }
        }
    }
    for (name, t) in cfg.tracking.iter().filter(|(_, t)| t.enabled) {
        for &a in &t.amplitudes_rad {
            for &f in &t.frequencies_hz {
                kinds.push((
                    t.centre_rad,
                    BlockKind::Tracking {
                        set: name.clone(),
                        amplitude_rad: a,
                        frequency_hz: f,
                        kp_per_s2: t.kp_per_s2,
                        cycles: t.cycles,
                    },
                ));
            }
        }
    }
    kinds
        .into_iter()
        .enumerate()
        .map(|(n, (start_rad, kind))| Block {
            chunk: n as u32,
            start_rad,
            recentre_s: cfg.recentre_s,
            kind,
        })
        .collect()
}

/// Simulated duration of a schedule at a control period [s].
pub fn schedule_duration_s(blocks: &[Block]) -> f64 {
    blocks.iter().map(|b| b.recentre_s + b.excitation_s()).sum()
}

/// What the controller is doing in a sample (the `mode` column).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Mode {
    /// Position-controlled re-centring before a block (inactive).
    Recentre = 0,
    /// Open-loop current excitation (active).
    Current = 1,
    /// Position hold after a guard tripped (inactive).
    Hold = 2,
    /// Closed-loop sine tracking (active).
    Tracking = 3,
}

/// Why a hold was latched.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LatchReason {
    /// s came within the margin of a range limit.
    PositionLimit,
    /// |i_meas| reached the safety current.
    Current,
}

/// A guard event.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Latch {
    /// Chunk in which it happened.
    pub chunk: u32,
    /// Time of the first held sample [s].
    pub time_s: f64,
    /// Why.
    pub reason: LatchReason,
    /// Measured position at the latch [rad].
    pub s_rad: f64,
}

/// One logged 1 kHz sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogRow {
    /// Chunk id.
    pub chunk: u32,
    /// Whether the sample belongs to the excitation (not re-centring, not held).
    pub active: bool,
    /// Controller mode.
    pub mode: Mode,
    /// The measurement at this instant.
    pub meas: Measurement,
    /// The current reference computed from it and applied during the next period [A].
    pub i_ref_a: f64,
    /// The simulator's truth at this instant (None for live plants).
    pub truth: Option<Truth>,
}

/// Summary of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RunSummary {
    /// Samples logged.
    pub samples: u64,
    /// Active samples.
    pub active_samples: u64,
    /// Chunks played.
    pub chunks: u32,
    /// Guard events.
    pub latches: Vec<Latch>,
    /// Simulated duration [s].
    pub duration_s: f64,
}

/// Causal joint-velocity estimator: the encoder difference (s_k − s_{k−1})/T through a first-order
/// low-pass filter with cut-off `cutoff_hz` (exact discretisation, α = 1 − e^{−2π·f_c·T}). The
/// protocol's controllers use it, and `frictl sim serve` uses the same estimator to fill
/// `JointStates::sdot_rad_s`, as a robot's drive reports a filtered encoder velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocityEstimator {
    alpha: f64,
    period_s: f64,
    last_s: f64,
    v: f64,
}

impl VelocityEstimator {
    /// An estimator at rest (ṡ = 0) at position `s0_rad`, sampled every `period_s`.
    pub fn new(cutoff_hz: f64, period_s: f64, s0_rad: f64) -> Self {
        Self {
            alpha: 1.0 - (-std::f64::consts::TAU * cutoff_hz * period_s).exp(),
            period_s,
            last_s: s0_rad,
            v: 0.0,
        }
    }

    /// Feeds the next position sample [rad] and returns the velocity estimate [rad/s].
    pub fn update(&mut self, s_rad: f64) -> f64 {
        let raw = (s_rad - self.last_s) / self.period_s;
        self.last_s = s_rad;
        self.v += self.alpha * (raw - self.v);
        self.v
    }

    /// The latest estimate [rad/s].
    pub fn velocity_rad_s(&self) -> f64 {
        self.v
    }
}

/// Plays `blocks` on `io`, handing every 1 kHz sample to `sink` in order.
pub fn run(
    io: &mut dyn JointIo,
    model: &ControllerModel<'_>,
    cfg: &ProtocolConfig,
    blocks: &[Block],
    sink: &mut dyn FnMut(&LogRow) -> Result<(), AcquireError>,
) -> Result<RunSummary, AcquireError> {
    let mut runner = JointRunner::new(model, cfg, blocks, io.measurement().s_rad);
    while !runner.finished() {
        let row = runner.next(io.measurement(), io.truth());
        sink(&row)?;
        io.exchange(row.i_ref_a)?;
    }
    Ok(runner.into_summary())
}

/// The protocol of one joint as a sample-by-sample state machine: [`run`] drives one joint with
/// it; a multi-joint plant drives one runner per joint, all stepped together (every joint excited
/// at once, each with its own schedule, guards and controller).
pub struct JointRunner<'m, 'a> {
    model: &'m ControllerModel<'a>,
    cfg: &'m ProtocolConfig,
    blocks: &'m [Block],
    vel: VelocityEstimator,
    lim_lo: f64,
    lim_hi: f64,
    block: usize,
    k: u64,
    n_rec: u64,
    n_exc: u64,
    i0: f64,
    centre: f64,
    hold_at: Option<f64>,
    /// After the last block: the position held [rad].
    park_at: Option<f64>,
    summary: RunSummary,
}

impl<'m, 'a> JointRunner<'m, 'a> {
    /// A runner at the start of `blocks`, the joint at rest at `s0_rad`.
    pub fn new(
        model: &'m ControllerModel<'a>,
        cfg: &'m ProtocolConfig,
        blocks: &'m [Block],
        s0_rad: f64,
    ) -> Self {
        let margin = cfg.limit_margin_deg.to_radians();
        let mut me = Self {
            model,
            cfg,
            blocks,
            vel: VelocityEstimator::new(cfg.velocity_filter_hz, model.period_s, s0_rad),
            lim_lo: cfg.range_lo_rad + margin,
            lim_hi: cfg.range_hi_rad - margin,
            block: 0,
            k: 0,
            n_rec: 0,
            n_exc: 0,
            i0: 0.0,
            centre: 0.0,
            hold_at: None,
            park_at: None,
            summary: RunSummary::default(),
        };
        me.enter_block();
        me
    }

    /// Starts block `self.block` (blocks without samples are counted and skipped).
    fn enter_block(&mut self) {
        let ts = self.model.period_s;
        while let Some(b) = self.blocks.get(self.block) {
            self.summary.chunks += 1;
            self.n_rec = (b.recentre_s / ts).round() as u64;
            self.n_exc = (b.excitation_s() / ts).round() as u64;
            self.i0 = 0.0;
            self.centre = b.start_rad;
            self.hold_at = None;
            self.k = 0;
            if self.n_rec + self.n_exc > 0 {
                return;
            }
            self.block += 1;
        }
    }

    /// The controller's joint velocity estimate after the latest [`JointRunner::next`] [rad/s].
    pub fn velocity_rad_s(&self) -> f64 {
        self.vel.velocity_rad_s()
    }

    /// Whether every block has been played.
    pub fn finished(&self) -> bool {
        self.block >= self.blocks.len()
    }

    /// What has been played so far ([`RunSummary::duration_s`] filled in).
    pub fn summary(&self) -> RunSummary {
        let mut s = self.summary.clone();
        s.duration_s = s.samples as f64 * self.model.period_s;
        s
    }

    /// The summary of the whole run.
    pub fn into_summary(self) -> RunSummary {
        self.summary()
    }

    fn position_current(&self, s: f64, v: f64, tgt: f64) -> f64 {
        let acc = self.cfg.position_kp_per_s2 * (tgt - s) - self.cfg.position_kd_per_s * v;
        self.model.current_for_accel(s, acc)
    }

    /// After the last block: the row holding the joint at its first position since (inactive,
    /// [`Mode::Hold`], the last chunk).
    fn park_row(&mut self, meas: Measurement, truth: Option<Truth>, v: f64) -> LogRow {
        let s = meas.s_rad;
        let park = *self.park_at.get_or_insert(s);
        let i_ref = self
            .position_current(s, v, park)
            .clamp(-self.model.i_max_a, self.model.i_max_a);
        LogRow {
            chunk: self.blocks.last().map_or(0, |b| b.chunk),
            active: false,
            mode: Mode::Hold,
            meas,
            i_ref_a: i_ref,
            truth,
        }
    }

    /// The excitation's base current at position `s` [A]: the gravity's, or none.
    fn holding_current_a(&self, s: f64) -> f64 {
        let model = self.model;
        match self.cfg.holding_current {
            HoldingCurrent::Gravity => model.current_for_torque(model.link.gravity_nm(s)),
            HoldingCurrent::Zero => 0.0,
        }
    }

    /// Why the excitation must stop and hold at `meas`: a position limit, or the safety current.
    fn latch_reason(&self, meas: &Measurement) -> Option<LatchReason> {
        let s = meas.s_rad;
        if s <= self.lim_lo || s >= self.lim_hi {
            Some(LatchReason::PositionLimit)
        } else if meas.i_meas_a.abs() >= self.cfg.max_safety_current_a {
            Some(LatchReason::Current)
        } else {
            None
        }
    }

    /// The mode and current [A] of the excitation `kind` at `t` [s] into it, at position `s`
    /// [rad] and velocity `v` [rad/s].
    fn excitation(&self, kind: &BlockKind, s: f64, v: f64, t: f64) -> (Mode, f64) {
        let model = self.model;
        let i0 = self.i0;
        match kind {
            BlockKind::Sine {
                amplitude_a,
                frequency_hz,
                ..
            } => (
                Mode::Current,
                i0 + amplitude_a * (std::f64::consts::TAU * frequency_hz * t).sin(),
            ),
            BlockKind::Ramp {
                slope_a_per_s,
                max_increment_a,
            } => (
                Mode::Current,
                i0 + (slope_a_per_s * t).clamp(-max_increment_a, *max_increment_a),
            ),
            BlockKind::Step {
                level_a, hold_s, ..
            } => (Mode::Current, if t < *hold_s { i0 + level_a } else { i0 }),
            BlockKind::Tracking {
                amplitude_rad,
                frequency_hz,
                kp_per_s2,
                ..
            } => {
                // Centred on the position reached by the re-centring (stiction can leave
                // it short of the target): no error step, hence no current kick, at t = 0.
                let s_d =
                    self.centre + amplitude_rad * (std::f64::consts::TAU * frequency_hz * t).sin();
                let acc = kp_per_s2 * (s_d - s) - 2.0 * kp_per_s2.sqrt() * v;
                (Mode::Tracking, model.current_for_accel(s, acc))
            }
        }
    }

    /// The sample at `meas`: the controller's current for the next period and the log row. After
    /// the last block the joint holds its last position (rows inactive, [`Mode::Hold`], the last
    /// chunk), not counted in the summary.
    pub fn next(&mut self, meas: Measurement, truth: Option<Truth>) -> LogRow {
        let v = self.vel.update(meas.s_rad);
        let s = meas.s_rad;
        let Some(block) = self.blocks.get(self.block) else {
            return self.park_row(meas, truth, v);
        };
        let model = self.model;
        let (k, n_rec) = (self.k, self.n_rec);
        let (mode, i_ref) = if k < n_rec {
            (Mode::Recentre, self.position_current(s, v, block.start_rad))
        } else {
            if k == n_rec {
                self.centre = s;
                self.i0 = self.holding_current_a(s);
            }
            if self.hold_at.is_none()
                && let Some(reason) = self.latch_reason(&meas)
            {
                self.hold_at = Some(s);
                self.summary.latches.push(Latch {
                    chunk: block.chunk,
                    time_s: meas.time_s,
                    reason,
                    s_rad: s,
                });
            }
            let t = (k - n_rec) as f64 * model.period_s;
            match self.hold_at {
                Some(h) => (Mode::Hold, self.position_current(s, v, h)),
                None => self.excitation(&block.kind, s, v, t),
            }
        };
        let i_ref = i_ref.clamp(-model.i_max_a, model.i_max_a);
        let row = LogRow {
            chunk: block.chunk,
            active: matches!(mode, Mode::Current | Mode::Tracking),
            mode,
            meas,
            i_ref_a: i_ref,
            truth,
        };
        self.summary.samples += 1;
        self.summary.active_samples += u64::from(row.active);
        self.k += 1;
        if self.k >= self.n_rec + self.n_exc {
            self.block += 1;
            self.enter_block();
        }
        row
    }
}

#[cfg(test)]
mod tests {
    use super::VelocityEstimator;

    #[test]
    fn velocity_estimator_is_causal_and_converges_to_the_slope() {
        let ts = 1e-3;
        let mut v = VelocityEstimator::new(100.0, ts, 0.5);
        // At rest: zero.
        for _ in 0..10 {
            assert_eq!(v.update(0.5), 0.0);
        }
        // A ramp of 2 rad/s starting now: the estimate rises monotonically towards 2 rad/s.
        let mut last = 0.0;
        for k in 1..=200 {
            let e = v.update(0.5 + 2.0 * ts * k as f64);
            assert!(e >= last - 1e-12 && e <= 2.0 + 1e-9, "k {k}: {e}");
            last = e;
        }
        assert!((last - 2.0).abs() < 1e-6, "{last}");
        assert_eq!(v.velocity_rad_s(), last);
        // First-order response: one sample after a step of the raw difference it moved by α.
        let mut w = VelocityEstimator::new(100.0, ts, 0.0);
        let alpha = 1.0 - (-std::f64::consts::TAU * 100.0 * ts).exp();
        let e = w.update(1e-3);
        assert!((e - alpha * 1.0).abs() < 1e-12, "{e} vs {alpha}");
    }
}
