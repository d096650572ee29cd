//! Feature sets, history buffers, warm-up and the Δθ offset latch.
//!
//! What this module **is**: the definition of a network's input vector and the allocation-free machinery
//! that builds it tick by tick.
//! - [`FeatureSet`] names the per-tick signals (blocks) and their order; [`Feature`] is one signal with
//!   its unit; [`FeatureSpec`] adds the history length H and the optional temperature slot;
//!   [`Signal`] is a field of [`JointSample`] a feature reads ([`FeatureSet::required_signals`]), so a
//!   dataset or a backend that lacks one can be refused by name.
//! - Names: one spelling, hyphenated (`joint-pos-joint-vel`, `delta-theta`), printed everywhere
//!   (`Display`, serde, the tools); [`FeatureSet::parse`] / [`Feature::parse`] (and `FromStr`, serde)
//!   also accept the underscore spelling (`joint_pos_joint_vel`) so older files and commands keep
//!   working.
//! - Layout (block-major, oldest → newest, f32, as the authors train):
//!   `x[b·H + j] = feature_b(t − (H−1) + j)`, `j = H−1` is the newest sample; with temperature, one
//!   motor temperature [°C] (of the newest sample) follows the last block at `x[n_blocks·H]`.
//! - [`DeltaThetaLatch`]: Δθ = r·s − (θ − θ_off) [motor rad] with the offset θ_off = θ − r·s latched
//!   explicitly (Δθ = 0 at the latch instant), r the signed gear ratio.
//! - [`History`]: a fixed-capacity ring buffer per joint (inline arrays, no heap at all), `push` one
//!   [`JointSample`] per tick, `fill` the input vector into a caller-provided slice.
//! - [`WarmupPolicy`]: what to do while fewer than H samples have arrived.
//!
//! What it is **not**: no filtering of the signals (velocities arrive already estimated), no inference,
//! no I/O. Values are computed in f64 and stored as f32 (the network's precision), so a large motor
//! angle loses no precision in the Δθ subtraction.

use std::fmt;
use std::str::FromStr;

use crate::units::GearRatio;

/// Largest supported history length H (samples per block).
pub const MAX_HISTORY: usize = 64;

/// Largest number of blocks of any [`FeatureSet`] (the size of [`History`]'s inline storage).
pub const MAX_BLOCKS: usize = 3;

/// Which per-tick signals a network consumes, in block order. Each block holds `H` samples, oldest
/// first; the optional motor temperature comes last as one value.
///
/// Serialised (and printed) hyphenated, e.g. `"joint-pos-joint-vel"`; the underscore spelling is
/// accepted when reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FeatureSet {
    /// `[Δθ ×H, ṡ ×H]` with Δθ = r·s − θ [motor rad] (offset latched) and ṡ [rad/s] — the paper's
    /// (the authors' input type 1).
    #[serde(alias = "delta_theta_joint_vel")]
    DeltaThetaJointVel,
    /// `[ω_m ×H, ṡ ×H]` motor velocity [motor rad/s] and joint velocity [rad/s] — ergoCub since
    /// Oct 2024 (the authors' input type 2).
    #[serde(alias = "motor_vel_joint_vel")]
    MotorVelJointVel,
    /// `[s ×H, θ ×H]` joint position [rad] and motor position [motor rad] — the June 2024 ergoCub model.
    #[serde(alias = "joint_pos_motor_pos")]
    JointPosMotorPos,
    /// `[s ×H, ṡ ×H]` joint position [rad] and joint velocity [rad/s] — for robots without a motor
    /// encoder (torque-sensed arms).
    #[serde(alias = "joint_pos_joint_vel")]
    JointPosJointVel,
    /// `[ṡ ×H]` joint velocity [rad/s] only — for robots without a motor encoder.
    #[serde(alias = "joint_vel")]
    JointVel,
    /// `[Δθ ×H, ω_m ×H, ṡ ×H]` — the authors' input type 3.
    #[serde(alias = "delta_theta_motor_vel_joint_vel")]
    DeltaThetaMotorVelJointVel,
    /// `[Δθ ×H, s ×H, ṡ ×H]` — the authors' input type 4.
    #[serde(alias = "delta_theta_joint_pos_joint_vel")]
    DeltaThetaJointPosJointVel,
}

/// One per-tick signal (one block of the input vector).
///
/// Serialised (and printed) hyphenated, e.g. `"delta-theta"`; the underscore spelling is accepted
/// when reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Feature {
    /// Δθ = r·s − (θ − θ_off) [motor rad]: transmission deflection relative to the latch instant.
    #[serde(rename = "delta-theta", alias = "delta_theta")]
    DeltaThetaMotorRad,
    /// Joint velocity ṡ [rad/s].
    #[serde(rename = "joint-vel", alias = "joint_vel")]
    JointVelRadS,
    /// Motor velocity ω_m [motor rad/s].
    #[serde(rename = "motor-vel", alias = "motor_vel")]
    MotorVelRadS,
    /// Joint position s [rad].
    #[serde(rename = "joint-pos", alias = "joint_pos")]
    JointPosRad,
    /// Motor position θ [motor rad] (raw, no offset).
    #[serde(rename = "motor-pos", alias = "motor_pos")]
    MotorPosRad,
}

/// A field of [`JointSample`] (and the dataset column of the same name) that features read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum Signal {
    /// Joint position s [rad] (`s_rad`).
    #[serde(rename = "s_rad")]
    JointPosRad,
    /// Joint velocity ṡ [rad/s] (`sdot_rad_s`).
    #[serde(rename = "sdot_rad_s")]
    JointVelRadS,
    /// Motor position θ [motor rad] (`theta_motor_rad`).
    #[serde(rename = "theta_motor_rad")]
    MotorPosRad,
    /// Motor velocity ω_m [motor rad/s] (`omega_motor_rad_s`).
    #[serde(rename = "omega_motor_rad_s")]
    MotorVelRadS,
    /// Motor temperature [°C] (`temperature_c`).
    #[serde(rename = "temperature_c")]
    TemperatureC,
}

impl Signal {
    /// Every signal, in [`JointSample`] field order.
    pub const ALL: [Signal; 5] = [
        Signal::JointPosRad,
        Signal::JointVelRadS,
        Signal::MotorPosRad,
        Signal::MotorVelRadS,
        Signal::TemperatureC,
    ];

    /// The [`JointSample`] field name, which is also the dataset CSV column, e.g. `"theta_motor_rad"`.
    pub fn field(self) -> &'static str {
        match self {
            Signal::JointPosRad => "s_rad",
            Signal::JointVelRadS => "sdot_rad_s",
            Signal::MotorPosRad => "theta_motor_rad",
            Signal::MotorVelRadS => "omega_motor_rad_s",
            Signal::TemperatureC => "temperature_c",
        }
    }

    /// Unit of the values, e.g. `"motor rad/s"`.
    pub fn unit(self) -> &'static str {
        match self {
            Signal::JointPosRad => "rad",
            Signal::JointVelRadS => "rad/s",
            Signal::MotorPosRad => "motor rad",
            Signal::MotorVelRadS => "motor rad/s",
            Signal::TemperatureC => "degC",
        }
    }

    /// The value of this field in `sample`.
    #[inline]
    pub fn value(self, sample: &JointSample) -> f64 {
        match self {
            Signal::JointPosRad => sample.s_rad,
            Signal::JointVelRadS => sample.sdot_rad_s,
            Signal::MotorPosRad => sample.theta_motor_rad,
            Signal::MotorVelRadS => sample.omega_motor_rad_s,
            Signal::TemperatureC => sample.temperature_c,
        }
    }
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.field())
    }
}

/// A name that is not a known [`FeatureSet`] or [`Feature`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} `{name}`; expected one of: {expected}")]
pub struct UnknownName {
    /// `"feature set"` or `"feature"`.
    pub what: &'static str,
    /// The name given.
    pub name: String,
    /// The accepted names (hyphenated), comma separated.
    pub expected: String,
}

/// `name` trimmed, with `_` read as `-` (the accepted alias spelling).
fn canonical(name: &str) -> String {
    name.trim().replace('_', "-")
}

impl Feature {
    /// Every feature, in code order.
    pub const ALL: [Feature; 5] = [
        Feature::DeltaThetaMotorRad,
        Feature::JointVelRadS,
        Feature::MotorVelRadS,
        Feature::JointPosRad,
        Feature::MotorPosRad,
    ];

    /// Hyphenated name, e.g. `"delta-theta"` (metadata, `inspect`, input labels).
    pub fn name(self) -> &'static str {
        match self {
            Feature::DeltaThetaMotorRad => "delta-theta",
            Feature::JointVelRadS => "joint-vel",
            Feature::MotorVelRadS => "motor-vel",
            Feature::JointPosRad => "joint-pos",
            Feature::MotorPosRad => "motor-pos",
        }
    }

    /// Unit of the values, e.g. `"motor rad"`, `"rad/s"`.
    pub fn unit(self) -> &'static str {
        match self {
            Feature::DeltaThetaMotorRad | Feature::MotorPosRad => "motor rad",
            Feature::JointVelRadS => "rad/s",
            Feature::MotorVelRadS => "motor rad/s",
            Feature::JointPosRad => "rad",
        }
    }

    /// The feature named `name` (hyphenated, or the underscore alias such as `"delta_theta"`).
    pub fn parse(name: &str) -> Result<Feature, UnknownName> {
        let c = canonical(name);
        Feature::ALL
            .into_iter()
            .find(|f| f.name() == c)
            .ok_or_else(|| UnknownName {
                what: "feature",
                name: name.to_owned(),
                expected: Feature::ALL.map(Feature::name).join(", "),
            })
    }

    /// The [`JointSample`] fields this feature is computed from.
    pub fn signals(self) -> &'static [Signal] {
        match self {
            Feature::DeltaThetaMotorRad => &[Signal::JointPosRad, Signal::MotorPosRad],
            Feature::JointVelRadS => &[Signal::JointVelRadS],
            Feature::MotorVelRadS => &[Signal::MotorVelRadS],
            Feature::JointPosRad => &[Signal::JointPosRad],
            Feature::MotorPosRad => &[Signal::MotorPosRad],
        }
    }
}

impl FromStr for Feature {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, UnknownName> {
        Feature::parse(s)
    }
}

impl fmt::Display for Feature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} [{}]", self.name(), self.unit())
    }
}

impl FeatureSet {
    /// Every feature set.
    pub const ALL: [FeatureSet; 7] = [
        FeatureSet::DeltaThetaJointVel,
        FeatureSet::MotorVelJointVel,
        FeatureSet::JointPosMotorPos,
        FeatureSet::JointPosJointVel,
        FeatureSet::JointVel,
        FeatureSet::DeltaThetaMotorVelJointVel,
        FeatureSet::DeltaThetaJointPosJointVel,
    ];

    /// The blocks, in input-vector order.
    pub fn blocks(self) -> &'static [Feature] {
        use Feature::*;
        match self {
            FeatureSet::DeltaThetaJointVel => &[DeltaThetaMotorRad, JointVelRadS],
            FeatureSet::MotorVelJointVel => &[MotorVelRadS, JointVelRadS],
            FeatureSet::JointPosMotorPos => &[JointPosRad, MotorPosRad],
            FeatureSet::JointPosJointVel => &[JointPosRad, JointVelRadS],
            FeatureSet::JointVel => &[JointVelRadS],
            FeatureSet::DeltaThetaMotorVelJointVel => {
                &[DeltaThetaMotorRad, MotorVelRadS, JointVelRadS]
            }
            FeatureSet::DeltaThetaJointPosJointVel => {
                &[DeltaThetaMotorRad, JointPosRad, JointVelRadS]
            }
        }
    }

    /// The unit of each block, in order, e.g. `["motor rad", "rad/s"]` (each block's
    /// [`Feature::unit`]).
    pub fn units(self) -> impl ExactSizeIterator<Item = &'static str> {
        self.blocks().iter().map(|f| f.unit())
    }

    /// The set whose blocks are exactly `blocks` (in order), if any.
    pub fn from_blocks(blocks: &[Feature]) -> Option<FeatureSet> {
        FeatureSet::ALL.into_iter().find(|s| s.blocks() == blocks)
    }

    /// Number of blocks (each H long).
    pub fn n_blocks(self) -> usize {
        self.blocks().len()
    }

    /// Whether the set uses Δθ, i.e. depends on the latched offset.
    pub fn uses_delta_theta(self) -> bool {
        self.blocks().contains(&Feature::DeltaThetaMotorRad)
    }

    /// The [`JointSample`] fields (dataset columns) the blocks are computed from, in [`Signal`]
    /// order, each once. Temperature is not among them: it depends on [`FeatureSpec::temperature`]
    /// (see [`FeatureSpec::required_signals`]).
    pub fn required_signals(self) -> &'static [Signal] {
        use Signal::*;
        match self {
            FeatureSet::DeltaThetaJointVel => &[JointPosRad, JointVelRadS, MotorPosRad],
            FeatureSet::MotorVelJointVel => &[JointVelRadS, MotorVelRadS],
            FeatureSet::JointPosMotorPos => &[JointPosRad, MotorPosRad],
            FeatureSet::JointPosJointVel => &[JointPosRad, JointVelRadS],
            FeatureSet::JointVel => &[JointVelRadS],
            FeatureSet::DeltaThetaMotorVelJointVel => {
                &[JointPosRad, JointVelRadS, MotorPosRad, MotorVelRadS]
            }
            FeatureSet::DeltaThetaJointPosJointVel => &[JointPosRad, JointVelRadS, MotorPosRad],
        }
    }

    /// Whether a block reads `signal`.
    pub fn needs(self, signal: Signal) -> bool {
        self.required_signals().contains(&signal)
    }

    /// Hyphenated name, e.g. `"joint-pos-joint-vel"` (as serde writes it).
    pub fn name(self) -> &'static str {
        match self {
            FeatureSet::DeltaThetaJointVel => "delta-theta-joint-vel",
            FeatureSet::MotorVelJointVel => "motor-vel-joint-vel",
            FeatureSet::JointPosMotorPos => "joint-pos-motor-pos",
            FeatureSet::JointPosJointVel => "joint-pos-joint-vel",
            FeatureSet::JointVel => "joint-vel",
            FeatureSet::DeltaThetaMotorVelJointVel => "delta-theta-motor-vel-joint-vel",
            FeatureSet::DeltaThetaJointPosJointVel => "delta-theta-joint-pos-joint-vel",
        }
    }

    /// The underscore spelling [`FeatureSet::parse`] also accepts, e.g. `"joint_pos_joint_vel"`
    /// (older files and command lines); never printed.
    pub fn underscore_alias(self) -> &'static str {
        match self {
            FeatureSet::DeltaThetaJointVel => "delta_theta_joint_vel",
            FeatureSet::MotorVelJointVel => "motor_vel_joint_vel",
            FeatureSet::JointPosMotorPos => "joint_pos_motor_pos",
            FeatureSet::JointPosJointVel => "joint_pos_joint_vel",
            FeatureSet::JointVel => "joint_vel",
            FeatureSet::DeltaThetaMotorVelJointVel => "delta_theta_motor_vel_joint_vel",
            FeatureSet::DeltaThetaJointPosJointVel => "delta_theta_joint_pos_joint_vel",
        }
    }

    /// One-line description with the block layout, e.g. `"[s ×H, ṡ ×H] (no motor encoder)"` (help
    /// texts).
    pub fn description(self) -> &'static str {
        match self {
            FeatureSet::DeltaThetaJointVel => "[Δθ ×H, ṡ ×H], the paper's (authors' input type 1)",
            FeatureSet::MotorVelJointVel => "[ω_m ×H, ṡ ×H] (authors' input type 2)",
            FeatureSet::JointPosMotorPos => "[s ×H, θ ×H], the June 2024 ergoCub model",
            FeatureSet::JointPosJointVel => "[s ×H, ṡ ×H], needs no motor encoder",
            FeatureSet::JointVel => "[ṡ ×H], needs no motor encoder",
            FeatureSet::DeltaThetaMotorVelJointVel => {
                "[Δθ ×H, ω_m ×H, ṡ ×H] (authors' input type 3)"
            }
            FeatureSet::DeltaThetaJointPosJointVel => "[Δθ ×H, s ×H, ṡ ×H] (authors' input type 4)",
        }
    }

    /// The set named `name`: the hyphenated name, or its underscore alias (`"joint_pos_motor_pos"`).
    pub fn parse(name: &str) -> Result<FeatureSet, UnknownName> {
        let c = canonical(name);
        FeatureSet::ALL
            .into_iter()
            .find(|s| s.name() == c)
            .ok_or_else(|| UnknownName {
                what: "feature set",
                name: name.to_owned(),
                expected: FeatureSet::ALL.map(FeatureSet::name).join(", "),
            })
    }
}

impl FromStr for FeatureSet {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, UnknownName> {
        FeatureSet::parse(s)
    }
}

impl fmt::Display for FeatureSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a feature spec or an input buffer is not acceptable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FeatureError {
    /// H outside `1..=MAX_HISTORY`.
    #[error("feature history length H = {history} is outside 1..={max}")]
    History {
        /// The H given.
        history: usize,
        /// [`MAX_HISTORY`].
        max: usize,
    },
    /// An input buffer of the wrong length.
    #[error("input buffer has {got} values, the feature spec {spec} needs {expected}")]
    Length {
        /// Its length.
        got: usize,
        /// `FeatureSpec::n_inputs()`.
        expected: usize,
        /// The spec, rendered.
        spec: String,
    },
}

/// A feature set with its history length and whether motor temperature [°C] is appended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct FeatureSpec {
    /// Signals and their order.
    pub set: FeatureSet,
    /// History length H (samples per block, ≥ 1).
    pub history: usize,
    /// Whether one motor-temperature value [°C] follows the blocks.
    pub temperature: bool,
}

/// What one position of the input vector holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputSlot {
    /// A history value.
    History {
        /// The signal.
        feature: Feature,
        /// Block index b.
        block: usize,
        /// How many ticks old: 0 is the newest sample (j = H−1), H−1 the oldest (j = 0).
        age_ticks: usize,
    },
    /// The motor temperature [°C] of the newest sample.
    TemperatureC,
}

impl InputSlot {
    /// Unit of the value.
    pub fn unit(self) -> &'static str {
        match self {
            InputSlot::History { feature, .. } => feature.unit(),
            InputSlot::TemperatureC => "degC",
        }
    }
}

impl fmt::Display for InputSlot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            InputSlot::History {
                feature,
                age_ticks: 0,
                ..
            } => {
                write!(f, "{}[t] ({})", feature.name(), feature.unit())
            }
            InputSlot::History {
                feature, age_ticks, ..
            } => {
                write!(f, "{}[t-{age_ticks}] ({})", feature.name(), feature.unit())
            }
            InputSlot::TemperatureC => f.write_str("motor_temperature (degC)"),
        }
    }
}

impl fmt::Display for FeatureSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} H={}", self.set, self.history)?;
        if self.temperature {
            f.write_str(" +temperature")?;
        }
        Ok(())
    }
}

impl FeatureSpec {
    /// Length of the input vector: n_blocks·H (+1 with temperature).
    pub fn n_inputs(&self) -> usize {
        self.set.n_blocks() * self.history + usize::from(self.temperature)
    }

    /// The [`JointSample`] fields (dataset columns) this spec reads: the set's
    /// ([`FeatureSet::required_signals`]), then [`Signal::TemperatureC`] with temperature.
    pub fn required_signals(&self) -> impl Iterator<Item = Signal> + use<> {
        let temperature = self.temperature.then_some(Signal::TemperatureC);
        self.set
            .required_signals()
            .iter()
            .copied()
            .chain(temperature)
    }

    /// The first required signal of `sample` that is not finite, if any (a NaN motor angle is fine
    /// for `joint-vel`, not for `delta-theta-joint-vel`).
    pub fn first_non_finite(&self, sample: &JointSample) -> Option<Signal> {
        self.required_signals()
            .find(|s| !s.value(sample).is_finite())
    }

    /// Checks `1 ≤ H ≤ MAX_HISTORY`.
    pub fn validate(&self) -> Result<(), FeatureError> {
        if (1..=MAX_HISTORY).contains(&self.history) {
            Ok(())
        } else {
            Err(FeatureError::History {
                history: self.history,
                max: MAX_HISTORY,
            })
        }
    }

    /// Index of block `block`'s value `age_ticks` old (0 = newest), if both are in range.
    pub fn index(&self, block: usize, age_ticks: usize) -> Option<usize> {
        (block < self.set.n_blocks() && age_ticks < self.history)
            .then(|| block * self.history + (self.history - 1 - age_ticks))
    }

    /// Index of the temperature slot, if the spec has one.
    pub fn temperature_index(&self) -> Option<usize> {
        self.temperature.then(|| self.set.n_blocks() * self.history)
    }

    /// What input `i` holds, or `None` past the end (or for H = 0).
    pub fn slot(&self, i: usize) -> Option<InputSlot> {
        let h = self.history;
        if h == 0 {
            return None;
        }
        let blocks = self.set.blocks();
        let b = i / h;
        if let Some(&feature) = blocks.get(b) {
            Some(InputSlot::History {
                feature,
                block: b,
                age_ticks: h - 1 - (i % h),
            })
        } else if Some(i) == self.temperature_index() {
            Some(InputSlot::TemperatureC)
        } else {
            None
        }
    }

    /// One label per input, e.g. `"delta_theta[t-3] (motor rad)"` (allocates; for tools).
    pub fn input_labels(&self) -> Vec<String> {
        (0..self.n_inputs())
            .filter_map(|i| self.slot(i))
            .map(|s| s.to_string())
            .collect()
    }
}

/// One tick of joint/motor state, as the estimators consume it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointSample {
    /// Joint position s [rad].
    pub s_rad: f64,
    /// Joint velocity ṡ [rad/s].
    pub sdot_rad_s: f64,
    /// Motor position θ [motor rad].
    pub theta_motor_rad: f64,
    /// Motor velocity ω_m [motor rad/s].
    pub omega_motor_rad_s: f64,
    /// Motor temperature [°C] (NaN when the joint has no sensor).
    pub temperature_c: f64,
}

/// The Δθ offset latch: Δθ = r·s − (θ − θ_off) [motor rad], θ_off = θ − r·s taken at [`Self::latch`].
///
/// Δθ is therefore 0 at the latch instant and afterwards measures the change of transmission deflection
/// (flexspline wind-up) since then. The training pipeline latches once at the first sample of each log
/// file; the daemon latches at enable (bumpless start). Before any latch the offset is 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeltaThetaLatch {
    gear_ratio: GearRatio,
    theta_off_motor_rad: f64,
    latched: bool,
}

impl DeltaThetaLatch {
    /// A latch for signed gear ratio `r`, not latched yet (offset 0).
    pub fn new(gear_ratio: GearRatio) -> Self {
        Self {
            gear_ratio,
            theta_off_motor_rad: 0.0,
            latched: false,
        }
    }

    /// Stores θ_off = θ − r·s so that Δθ is 0 for this (s, θ).
    pub fn latch(&mut self, s_rad: f64, theta_motor_rad: f64) {
        self.theta_off_motor_rad =
            theta_motor_rad - self.gear_ratio.motor_rad_from_joint_rad(s_rad);
        self.latched = true;
    }

    /// Sets θ_off [motor rad] explicitly (a calibrated encoder offset: with θ_off = θ − r·s taken
    /// where the transmission carries no torque, Δθ is the absolute deflection), and marks it latched.
    pub fn set_offset(&mut self, theta_off_motor_rad: f64) {
        self.theta_off_motor_rad = theta_off_motor_rad;
        self.latched = true;
    }

    /// Δθ = r·s − (θ − θ_off) [motor rad].
    #[inline]
    pub fn delta_theta_motor_rad(&self, s_rad: f64, theta_motor_rad: f64) -> f64 {
        self.gear_ratio.motor_rad_from_joint_rad(s_rad)
            - (theta_motor_rad - self.theta_off_motor_rad)
    }

    /// The latched offset θ_off [motor rad] (0 before the first latch).
    pub fn offset_motor_rad(&self) -> f64 {
        self.theta_off_motor_rad
    }

    /// Whether [`Self::latch`] has been called.
    pub fn is_latched(&self) -> bool {
        self.latched
    }

    /// The signed gear ratio.
    pub fn gear_ratio(&self) -> GearRatio {
        self.gear_ratio
    }
}

/// Whether `sample` can give a Δθ offset (s and θ finite).
#[inline]
fn latchable(sample: &JointSample) -> bool {
    sample.s_rad.is_finite() && sample.theta_motor_rad.is_finite()
}

/// What a PINN estimator does while fewer than H samples have been pushed since the last reset.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum WarmupPolicy {
    /// Infer at once; missing older samples read as 0 (and so does the temperature before the first
    /// sample). Sensible for deflection/velocity features, which are ≈ 0 at a bumpless enable.
    ZeroPad,
    /// Output 0 ("not ready") until H samples have arrived — the BLF device's behaviour after each
    /// torque-mode entry. The default: no compensation is the safe side.
    #[default]
    HoldZero,
}

impl WarmupPolicy {
    /// Whether a history holding `len` samples out of `history` may be used for inference.
    #[inline]
    pub fn is_ready(self, len: usize, history: usize) -> bool {
        match self {
            WarmupPolicy::ZeroPad => len >= 1,
            WarmupPolicy::HoldZero => len >= history,
        }
    }
}

/// Per-joint fixed-capacity history of the features of a [`FeatureSpec`].
///
/// All storage is inline (`MAX_BLOCKS × MAX_HISTORY` f32, ~0.5 KiB): no heap, ever. [`History::push`],
/// [`History::push_or_hold`] and [`History::fill`] are O(H) copies and never allocate or panic. A
/// real-time estimator pushes with `push_or_hold`, which keeps a sample with a non-finite input out
/// of the window (the last finite sample is held in its place).
///
/// Δθ uses the embedded [`DeltaThetaLatch`]; if it was never latched, the first pushed sample latches
/// it (as the training pipeline does at the first sample of a file). [`History::reset`] clears and
/// latches explicitly; [`History::clear`] keeps the latch.
///
/// With a fixed offset ([`History::fix_delta_theta_offset`], a calibrated θ_off) `reset` clears the
/// samples but does **not** re-latch: Δθ then measures the absolute transmission deflection at every
/// enable, which is what a network trained with one offset per recording has learnt. Re-latching at
/// each enable (the default) makes Δθ = 0 whatever torque the transmission holds at that instant
/// (stiction wind-up, gravity), so a network that reads friction from the absolute deflection is
/// shifted by that torque for the whole run.
#[derive(Clone, Debug)]
pub struct History {
    spec: FeatureSpec,
    latch: DeltaThetaLatch,
    /// Whether the latch offset is a fixed calibration (never re-latched by `reset`).
    fixed_offset: bool,
    buf: [[f32; MAX_HISTORY]; MAX_BLOCKS],
    /// Ring index of the next write, in `0..H`.
    head: usize,
    /// Valid samples, `0..=H`.
    len: usize,
    /// Temperature of the newest sample [°C] (0 when empty).
    temperature_c: f32,
}

impl History {
    /// An empty history for `spec` (validated) and signed gear ratio `gear_ratio`.
    pub fn new(spec: FeatureSpec, gear_ratio: GearRatio) -> Result<Self, FeatureError> {
        spec.validate()?;
        Ok(Self {
            spec,
            latch: DeltaThetaLatch::new(gear_ratio),
            fixed_offset: false,
            buf: [[0.0; MAX_HISTORY]; MAX_BLOCKS],
            head: 0,
            len: 0,
            temperature_c: 0.0,
        })
    }

    /// The feature spec.
    pub fn spec(&self) -> &FeatureSpec {
        &self.spec
    }

    /// The Δθ latch.
    pub fn latch(&self) -> &DeltaThetaLatch {
        &self.latch
    }

    /// Number of samples held (≤ H).
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no sample is held.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether H samples are held.
    #[inline]
    pub fn is_full(&self) -> bool {
        self.len == self.spec.history
    }

    /// Whether inference may run under `policy`.
    #[inline]
    pub fn is_ready(&self, policy: WarmupPolicy) -> bool {
        policy.is_ready(self.len, self.spec.history)
    }

    /// Forgets all samples (the latch is kept).
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.temperature_c = 0.0;
        for b in &mut self.buf {
            b.fill(0.0);
        }
    }

    /// Clears and latches the Δθ offset at `sample` (Δθ = 0 there) — unless the offset is fixed
    /// ([`Self::fix_delta_theta_offset`]), then it only clears. Does not push the sample.
    ///
    /// A sample whose s or θ is not finite cannot give an offset: the latch is then released and
    /// taken again at the first pushed sample (with [`Self::push_or_hold`]: the first one whose s and
    /// θ are finite), so one bad sample at an enable cannot leave Δθ NaN until the next one.
    pub fn reset(&mut self, sample: &JointSample) {
        self.clear();
        if !self.fixed_offset {
            if latchable(sample) {
                self.latch.latch(sample.s_rad, sample.theta_motor_rad);
            } else {
                self.latch.latched = false;
            }
        }
    }

    /// Fixes the Δθ offset θ_off [motor rad] (Δθ = r·s − (θ − θ_off)) for the life of this history:
    /// later [`Self::reset`]s keep it. `None` returns to latching at every reset (and at the first
    /// push if never latched); the current offset stays until the next reset.
    pub fn fix_delta_theta_offset(&mut self, theta_off_motor_rad: Option<f64>) {
        match theta_off_motor_rad {
            Some(off) => {
                self.latch.set_offset(off);
                self.fixed_offset = true;
            }
            None => self.fixed_offset = false,
        }
    }

    /// The fixed Δθ offset [motor rad], if one was set with [`Self::fix_delta_theta_offset`].
    pub fn fixed_delta_theta_offset(&self) -> Option<f64> {
        self.fixed_offset.then(|| self.latch.offset_motor_rad())
    }

    /// Value of `feature` for `sample` with the current latch [unit of the feature].
    #[inline]
    pub fn feature_value(&self, feature: Feature, sample: &JointSample) -> f64 {
        match feature {
            Feature::DeltaThetaMotorRad => self
                .latch
                .delta_theta_motor_rad(sample.s_rad, sample.theta_motor_rad),
            Feature::JointVelRadS => sample.sdot_rad_s,
            Feature::MotorVelRadS => sample.omega_motor_rad_s,
            Feature::JointPosRad => sample.s_rad,
            Feature::MotorPosRad => sample.theta_motor_rad,
        }
    }

    /// Appends one tick as it is (a non-finite value included: [`Self::fill`] then passes it on),
    /// dropping the oldest sample when full. For offline windows that are skipped when an input is
    /// not finite; a real-time estimator uses [`Self::push_or_hold`].
    #[inline]
    pub fn push(&mut self, sample: &JointSample) {
        if !self.latch.is_latched() {
            self.latch.latch(sample.s_rad, sample.theta_motor_rad);
        }
        let mut values = [0f32; MAX_BLOCKS];
        for (v, &feature) in values.iter_mut().zip(self.spec.set.blocks()) {
            *v = self.feature_value(feature, sample) as f32;
        }
        self.append(&values, sample.temperature_c as f32);
    }

    /// Appends one tick if every value the spec reads from `sample` is finite (each feature as the
    /// f32 the network sees, so a finite value beyond f32's range counts as ±∞, and the temperature
    /// if the spec takes it) and returns `true`. Otherwise the sample never enters the history: the
    /// newest held sample is repeated in its place (a zero-order hold for the missing tick, so the
    /// window keeps one sample per tick and the warm-up advances as usual) and `false` comes back;
    /// an empty history stays empty. The next finite sample is appended as usual, so a bad sample
    /// costs the tick it arrived on, not the H ticks it would take to leave the window.
    ///
    /// Δθ is latched (if it is not) only from a sample whose s and θ are finite.
    /// Allocation-free, cannot panic.
    #[inline]
    pub fn push_or_hold(&mut self, sample: &JointSample) -> bool {
        if !self.latch.is_latched() && latchable(sample) {
            self.latch.latch(sample.s_rad, sample.theta_motor_rad);
        }
        let mut values = [0f32; MAX_BLOCKS];
        let mut finite = true;
        for (v, &feature) in values.iter_mut().zip(self.spec.set.blocks()) {
            *v = self.feature_value(feature, sample) as f32;
            finite &= v.is_finite();
        }
        let temperature_c = sample.temperature_c as f32;
        finite &= !self.spec.temperature || temperature_c.is_finite();
        if finite {
            self.append(&values, temperature_c);
        } else if self.len > 0 {
            let h = self.spec.history;
            let newest = if self.head == 0 { h - 1 } else { self.head - 1 };
            for (v, ring) in values.iter_mut().zip(&self.buf) {
                *v = ring[newest];
            }
            self.append(&values, self.temperature_c);
        }
        finite
    }

    /// Writes one tick's feature values (block order) and temperature at the ring head.
    #[inline]
    fn append(&mut self, values: &[f32; MAX_BLOCKS], temperature_c: f32) {
        let head = self.head;
        for (ring, &v) in self.buf.iter_mut().zip(values) {
            ring[head] = v;
        }
        let h = self.spec.history;
        self.head = if head + 1 == h { 0 } else { head + 1 };
        if self.len < h {
            self.len += 1;
        }
        self.temperature_c = temperature_c;
    }

    /// Writes the input vector (layout in the module doc; zero-padded for missing old samples) into
    /// `out`, which must have exactly `spec().n_inputs()` values. Never allocates.
    #[inline]
    pub fn fill(&self, out: &mut [f32]) -> Result<(), FeatureError> {
        let h = self.spec.history;
        let n_blocks = self.spec.set.n_blocks();
        if out.len() != self.spec.n_inputs() {
            return Err(FeatureError::Length {
                got: out.len(),
                expected: self.spec.n_inputs(),
                spec: self.spec.to_string(),
            });
        }
        let len = self.len;
        let missing = h - len;
        // Oldest valid sample's ring index; the valid samples run from there, wrapping at H.
        let start = (self.head + h - len) % h;
        let first = (h - start).min(len);
        for (ring, block) in self.buf.iter().zip(out.chunks_exact_mut(h)).take(n_blocks) {
            let (pad, data) = block.split_at_mut(missing);
            pad.fill(0.0);
            let (a, b) = data.split_at_mut(first);
            a.copy_from_slice(&ring[start..start + first]);
            b.copy_from_slice(&ring[..len - first]);
        }
        if let Some(t) = self.spec.temperature_index() {
            out[t] = self.temperature_c;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn r(v: f64) -> GearRatio {
        GearRatio::new(v).unwrap()
    }

    fn sample(k: usize) -> JointSample {
        let k = k as f64;
        JointSample {
            s_rad: 0.1 + 0.01 * k,
            sdot_rad_s: -0.5 + 0.125 * k,
            theta_motor_rad: 3.0 - 2.0 * k,
            omega_motor_rad_s: 10.0 + k,
            temperature_c: 30.0 + k,
        }
    }

    fn spec(set: FeatureSet, history: usize, temperature: bool) -> FeatureSpec {
        FeatureSpec {
            set,
            history,
            temperature,
        }
    }

    fn filled(h: &History) -> Vec<f32> {
        let mut x = vec![f32::NAN; h.spec().n_inputs()];
        h.fill(&mut x).unwrap();
        x
    }

    #[test]
    fn layout_by_hand_for_each_set() {
        // Five samples pushed, H = 3: the window holds samples 2, 3, 4 (oldest first).
        let gr = r(2.0);
        // Δθ offset latched at sample 0: θ_off = θ0 − r·s0 = 3.0 − 0.2 = 2.8.
        // Δθ_k = r·s_k − (θ_k − 2.8) = 0.2 + 0.02k − 3 + 2k + 2.8 = 2.02·k.
        let dtheta = |k: f32| 2.02 * k;
        // Per block, the window's values (samples 2, 3, 4).
        let dth = [dtheta(2.0), dtheta(3.0), dtheta(4.0)];
        let sdot = [-0.25, -0.125, 0.0];
        let omega = [12.0, 13.0, 14.0];
        let s = [0.12, 0.13, 0.14];
        let theta = [-1.0, -3.0, -5.0];
        let cases: [(FeatureSet, &[[f32; 3]]); 7] = [
            (FeatureSet::DeltaThetaJointVel, &[dth, sdot]),
            (FeatureSet::MotorVelJointVel, &[omega, sdot]),
            (FeatureSet::JointPosMotorPos, &[s, theta]),
            (FeatureSet::JointPosJointVel, &[s, sdot]),
            (FeatureSet::JointVel, &[sdot]),
            (FeatureSet::DeltaThetaMotorVelJointVel, &[dth, omega, sdot]),
            (FeatureSet::DeltaThetaJointPosJointVel, &[dth, s, sdot]),
        ];
        assert_eq!(cases.len(), FeatureSet::ALL.len(), "every set by hand");
        for (set, blocks) in cases {
            let want: Vec<f32> = blocks.iter().flatten().copied().collect();
            for temperature in [false, true] {
                let sp = spec(set, 3, temperature);
                let mut h = History::new(sp, gr).unwrap();
                for k in 0..5 {
                    h.push(&sample(k));
                }
                let x = filled(&h);
                assert_eq!(x.len(), 3 * blocks.len() + usize::from(temperature));
                for (i, (got, want)) in x.iter().zip(&want).enumerate() {
                    assert!(
                        (got - want).abs() < 1e-5,
                        "{set} x[{i}] = {got}, want {want}"
                    );
                    // The slot description agrees: block i / 3, age 2 − i % 3.
                    assert_eq!(
                        sp.slot(i),
                        Some(InputSlot::History {
                            feature: set.blocks()[i / 3],
                            block: i / 3,
                            age_ticks: 2 - i % 3
                        })
                    );
                }
                if temperature {
                    assert_eq!(
                        x[3 * blocks.len()],
                        34.0,
                        "temperature slot holds the newest sample's"
                    );
                    assert_eq!(sp.slot(3 * blocks.len()), Some(InputSlot::TemperatureC));
                }
            }
        }
    }

    #[test]
    fn wrap_around_keeps_oldest_first() {
        let mut h = History::new(spec(FeatureSet::MotorVelJointVel, 4, false), r(1.0)).unwrap();
        for k in 0..4 {
            h.push(&sample(k));
        }
        assert!(h.is_full());
        assert_eq!(&filled(&h)[..4], &[10.0, 11.0, 12.0, 13.0]);
        for k in 4..11 {
            h.push(&sample(k));
            let x = filled(&h);
            let want: Vec<f32> = (k - 3..=k).map(|j| 10.0 + j as f32).collect();
            assert_eq!(&x[..4], &want[..], "after pushing sample {k}");
            assert_eq!(h.len(), 4);
        }
    }

    #[test]
    fn latch_zeroes_delta_theta_then_tracks_deflection() {
        for ratio in [-160.0, 100.0] {
            let gr = r(ratio);
            let mut h = History::new(spec(FeatureSet::DeltaThetaJointVel, 2, false), gr).unwrap();
            // Arbitrary absolute encoder offset between motor and joint.
            let s0 = 0.3;
            let th0 = ratio * s0 + 1234.5;
            let enable = JointSample {
                s_rad: s0,
                theta_motor_rad: th0,
                ..Default::default()
            };
            h.reset(&enable);
            h.push(&enable);
            assert_eq!(
                filled(&h)[1],
                0.0,
                "Δθ is 0 at the latch instant (r = {ratio})"
            );
            // Rigid motion: θ follows r·s exactly → Δθ stays 0.
            let rigid = JointSample {
                s_rad: s0 + 0.1,
                theta_motor_rad: th0 + ratio * 0.1,
                ..enable
            };
            h.push(&rigid);
            assert!(filled(&h)[1].abs() < 1e-9, "rigid motion keeps Δθ at 0");
            // Wind-up: the motor lags by 0.5 motor rad → Δθ = r·s − θ grows by +0.5.
            let lag = JointSample {
                theta_motor_rad: rigid.theta_motor_rad - 0.5,
                ..rigid
            };
            h.push(&lag);
            assert!(
                (filled(&h)[1] - 0.5).abs() < 1e-9,
                "Δθ tracks deflection (r = {ratio})"
            );
            // Sign of r: a joint motion with the motor stalled gives Δθ = r·Δs.
            let stalled = JointSample {
                s_rad: s0 + 0.01,
                theta_motor_rad: th0,
                ..enable
            };
            h.push(&stalled);
            let d = filled(&h)[1] as f64;
            assert!(
                (d - ratio * 0.01).abs() < 1e-4,
                "Δθ = {d}, want r·Δs = {}",
                ratio * 0.01
            );
            assert_eq!(d.signum(), ratio.signum());
        }
    }

    #[test]
    fn first_push_latches_when_never_latched_and_clear_keeps_latch() {
        let mut h =
            History::new(spec(FeatureSet::DeltaThetaJointVel, 3, false), r(-160.0)).unwrap();
        assert!(!h.latch().is_latched());
        h.push(&sample(0));
        assert!(h.latch().is_latched());
        let off = h.latch().offset_motor_rad();
        assert_eq!(off, sample(0).theta_motor_rad - (-160.0) * sample(0).s_rad);
        h.clear();
        assert!(h.is_empty());
        assert_eq!(filled(&h), vec![0.0; 6]);
        h.push(&sample(3));
        assert_eq!(h.latch().offset_motor_rad(), off, "clear keeps the latch");
    }

    #[test]
    fn fixed_offset_survives_reset_and_gives_absolute_deflection() {
        let ratio = -160.0;
        let mut h = History::new(spec(FeatureSet::DeltaThetaJointVel, 2, false), r(ratio)).unwrap();
        h.fix_delta_theta_offset(Some(0.0));
        assert_eq!(h.fixed_delta_theta_offset(), Some(0.0));
        // Enable while the transmission is wound up: the motor leads the joint by 0.05 motor rad.
        let wound = JointSample {
            s_rad: 0.2,
            theta_motor_rad: ratio * 0.2 + 0.05,
            ..Default::default()
        };
        h.reset(&wound);
        h.push(&wound);
        let d = filled(&h)[1] as f64;
        assert!(
            (d - (-0.05)).abs() < 1e-5,
            "fixed offset: Δθ = r·s − θ = −0.05 at enable, got {d}"
        );
        assert_eq!(h.latch().offset_motor_rad(), 0.0, "reset kept the offset");
        // Back to latching at reset: Δθ = 0 at the next enable.
        h.fix_delta_theta_offset(None);
        assert_eq!(h.fixed_delta_theta_offset(), None);
        h.reset(&wound);
        h.push(&wound);
        assert_eq!(filled(&h)[1], 0.0);
    }

    #[test]
    fn warm_up_policies() {
        let sp = spec(FeatureSet::MotorVelJointVel, 3, true);
        let mut h = History::new(sp, r(1.0)).unwrap();
        assert!(!h.is_ready(WarmupPolicy::ZeroPad));
        assert!(!h.is_ready(WarmupPolicy::HoldZero));
        h.push(&sample(0));
        assert!(h.is_ready(WarmupPolicy::ZeroPad));
        assert!(!h.is_ready(WarmupPolicy::HoldZero));
        // Zero padding: missing old samples are 0, present ones at the newest end.
        assert_eq!(filled(&h), vec![0.0, 0.0, 10.0, 0.0, 0.0, -0.5, 30.0]);
        h.push(&sample(1));
        assert!(!h.is_ready(WarmupPolicy::HoldZero));
        assert_eq!(filled(&h), vec![0.0, 10.0, 11.0, 0.0, -0.5, -0.375, 31.0]);
        h.push(&sample(2));
        assert!(h.is_ready(WarmupPolicy::HoldZero));
        assert_eq!(WarmupPolicy::default(), WarmupPolicy::HoldZero);
        assert_eq!(
            serde_json::to_string(&WarmupPolicy::ZeroPad).unwrap(),
            "\"zero_pad\""
        );
        assert_eq!(
            serde_json::from_str::<WarmupPolicy>("\"hold_zero\"").unwrap(),
            WarmupPolicy::HoldZero
        );
    }

    #[test]
    fn nan_temperature_is_passed_through() {
        let mut h = History::new(spec(FeatureSet::MotorVelJointVel, 1, true), r(1.0)).unwrap();
        h.push(&JointSample {
            temperature_c: f64::NAN,
            ..sample(0)
        });
        assert!(
            filled(&h)[2].is_nan(),
            "no sensor → NaN input → NaN output the caller zeroes"
        );
    }

    #[test]
    fn fill_checks_length_and_validate_checks_history() {
        let h = History::new(spec(FeatureSet::DeltaThetaJointVel, 5, true), r(1.0)).unwrap();
        let mut short = [0.0f32; 10];
        let e = h.fill(&mut short).unwrap_err();
        assert_eq!(
            e,
            FeatureError::Length {
                got: 10,
                expected: 11,
                spec: "delta-theta-joint-vel H=5 +temperature".into()
            }
        );
        for bad in [0, MAX_HISTORY + 1] {
            let s = spec(FeatureSet::DeltaThetaJointVel, bad, false);
            assert!(
                matches!(s.validate(), Err(FeatureError::History { history, .. }) if history == bad)
            );
            assert!(History::new(s, r(1.0)).is_err());
        }
        spec(FeatureSet::DeltaThetaJointVel, MAX_HISTORY, true)
            .validate()
            .unwrap();
    }

    #[test]
    fn slots_and_labels() {
        let s = spec(FeatureSet::DeltaThetaJointVel, 3, true);
        assert_eq!(s.n_inputs(), 7);
        assert_eq!(
            s.slot(0),
            Some(InputSlot::History {
                feature: Feature::DeltaThetaMotorRad,
                block: 0,
                age_ticks: 2
            })
        );
        assert_eq!(
            s.slot(5),
            Some(InputSlot::History {
                feature: Feature::JointVelRadS,
                block: 1,
                age_ticks: 0
            })
        );
        assert_eq!(s.slot(6), Some(InputSlot::TemperatureC));
        assert_eq!(s.slot(7), None);
        assert_eq!(s.index(1, 0), Some(5));
        assert_eq!(s.index(0, 2), Some(0));
        assert_eq!(s.index(2, 0), None);
        let labels = s.input_labels();
        assert_eq!(labels.len(), 7);
        assert_eq!(labels[2], "delta-theta[t] (motor rad)");
        assert_eq!(labels[3], "joint-vel[t-2] (rad/s)");
        assert_eq!(s.slot(6).unwrap().unit(), "degC");
        for set in FeatureSet::ALL {
            let name = serde_json::to_string(&set).unwrap();
            assert_eq!(name, format!("\"{set}\""), "Display matches serde");
        }
    }

    #[test]
    fn names_parse_with_both_spellings_and_print_hyphenated() {
        for set in FeatureSet::ALL {
            assert_eq!(FeatureSet::parse(set.name()), Ok(set));
            let snake = set.name().replace('-', "_");
            assert_eq!(set.underscore_alias(), snake);
            assert_eq!(snake.parse::<FeatureSet>(), Ok(set), "alias {snake}");
            assert_eq!(set.to_string(), set.name());
            assert!(!set.name().contains('_'));
            assert_eq!(
                serde_json::from_str::<FeatureSet>(&format!("\"{snake}\"")).unwrap(),
                set,
                "serde alias {snake}"
            );
            assert_eq!(FeatureSet::from_blocks(set.blocks()), Some(set));
            assert!(set.n_blocks() <= MAX_BLOCKS);
        }
        for f in Feature::ALL {
            assert_eq!(Feature::parse(f.name()), Ok(f));
            assert_eq!(f.name().replace('-', "_").parse::<Feature>(), Ok(f));
            assert_eq!(
                serde_json::to_string(&f).unwrap(),
                format!("\"{}\"", f.name())
            );
        }
        assert_eq!(FeatureSet::parse("joint-vel"), Ok(FeatureSet::JointVel));
        assert_eq!(
            FeatureSet::JointPosJointVel.units().collect::<Vec<_>>(),
            ["rad", "rad/s"]
        );
        assert_eq!(
            FeatureSet::parse("delta_theta_motor_vel_joint_vel"),
            Ok(FeatureSet::DeltaThetaMotorVelJointVel)
        );
        let e = FeatureSet::parse("joint-torque").unwrap_err();
        assert!(
            e.to_string().contains("joint-torque") && e.to_string().contains("joint-pos-joint-vel")
        );
        assert!(Feature::parse("velocity").is_err());
    }

    #[test]
    fn required_signals_are_what_the_blocks_read() {
        for set in FeatureSet::ALL {
            let mut from_blocks: Vec<Signal> = set
                .blocks()
                .iter()
                .flat_map(|f| f.signals().iter().copied())
                .collect();
            from_blocks.sort();
            from_blocks.dedup();
            assert_eq!(set.required_signals(), &from_blocks[..], "{set}");
            // A sample with every other field NaN still fills a finite input vector.
            for temperature in [false, true] {
                let sp = spec(set, 2, temperature);
                let mut smp = JointSample {
                    s_rad: f64::NAN,
                    sdot_rad_s: f64::NAN,
                    theta_motor_rad: f64::NAN,
                    omega_motor_rad_s: f64::NAN,
                    temperature_c: f64::NAN,
                };
                assert_eq!(sp.first_non_finite(&smp), sp.required_signals().next());
                let full = sample(1);
                for sig in sp.required_signals() {
                    match sig {
                        Signal::JointPosRad => smp.s_rad = full.s_rad,
                        Signal::JointVelRadS => smp.sdot_rad_s = full.sdot_rad_s,
                        Signal::MotorPosRad => smp.theta_motor_rad = full.theta_motor_rad,
                        Signal::MotorVelRadS => smp.omega_motor_rad_s = full.omega_motor_rad_s,
                        Signal::TemperatureC => smp.temperature_c = full.temperature_c,
                    }
                }
                assert_eq!(sp.first_non_finite(&smp), None);
                let mut h = History::new(sp, r(-100.0)).unwrap();
                h.push(&smp);
                h.push(&smp);
                assert!(filled(&h).iter().all(|v| v.is_finite()), "{sp}");
            }
        }
        assert_eq!(
            FeatureSet::JointVel.required_signals(),
            &[Signal::JointVelRadS]
        );
        assert!(!FeatureSet::JointPosJointVel.needs(Signal::MotorPosRad));
        assert!(FeatureSet::DeltaThetaJointPosJointVel.needs(Signal::MotorPosRad));
    }

    fn any_set() -> impl Strategy<Value = FeatureSet> {
        prop::sample::select(FeatureSet::ALL.to_vec())
    }

    fn any_sample() -> impl Strategy<Value = JointSample> {
        (
            -3.0..3.0f64,
            -5.0..5.0f64,
            -500.0..500.0f64,
            -800.0..800.0f64,
            20.0..80.0f64,
        )
            .prop_map(
                |(s_rad, sdot_rad_s, theta_motor_rad, omega_motor_rad_s, temperature_c)| {
                    JointSample {
                        s_rad,
                        sdot_rad_s,
                        theta_motor_rad,
                        omega_motor_rad_s,
                        temperature_c,
                    }
                },
            )
    }

    proptest! {
        /// The ring buffer against a naive model: keep every sample, take the last H, zero-pad.
        #[test]
        fn fill_matches_naive_window(
            set in any_set(),
            history in 1..=MAX_HISTORY,
            temperature in any::<bool>(),
            ratio in prop::sample::select(vec![-160.0, -100.0, 100.0, 160.0, 1.5]),
            samples in prop::collection::vec(any_sample(), 1..200),
            clear_at in prop::option::of(0usize..200),
        ) {
            let sp = spec(set, history, temperature);
            let mut h = History::new(sp, r(ratio)).unwrap();
            let mut kept: Vec<JointSample> = Vec::new();
            let theta_off = samples[0].theta_motor_rad - ratio * samples[0].s_rad;
            for (k, smp) in samples.iter().enumerate() {
                if clear_at == Some(k) {
                    h.clear();
                    kept.clear();
                }
                h.push(smp);
                kept.push(*smp);
                prop_assert_eq!(h.len(), kept.len().min(history));
            }
            let mut want = vec![0.0f32; sp.n_inputs()];
            let window = &kept[kept.len().saturating_sub(history)..];
            let pad = history - window.len();
            for (b, f) in set.blocks().iter().enumerate() {
                for (j, smp) in window.iter().enumerate() {
                    let v = match f {
                        Feature::DeltaThetaMotorRad => {
                            ratio * smp.s_rad - (smp.theta_motor_rad - theta_off)
                        }
                        Feature::JointVelRadS => smp.sdot_rad_s,
                        Feature::MotorVelRadS => smp.omega_motor_rad_s,
                        Feature::JointPosRad => smp.s_rad,
                        Feature::MotorPosRad => smp.theta_motor_rad,
                    };
                    want[b * history + pad + j] = v as f32;
                }
            }
            if temperature {
                want[set.n_blocks() * history] = kept.last().unwrap().temperature_c as f32;
            }
            prop_assert_eq!(filled(&h), want);
        }
    }
}
