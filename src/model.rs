//! none / CV / SCV / PINN / LuGre behind one trait.
//!
//! What this module **is**: the per-joint friction estimator the daemon calls once per tick.
//! [`FrictionModel`] is the common interface (`reset` at enable, `estimate` per tick); [`JointModel`]
//! is the enum the real-time path holds, dispatching by `match` (no vtable, no allocation). Static
//! models ([`CvParams`], [`ScvParams`], [`ScvCodeParams`]) use the joint velocity only;
//! [`PinnEstimator`] keeps a [`History`] of its features and runs the [`crate::kernel::Mlp`]. Its Δθ
//! offset is latched at every `reset` (enable) unless fixed with
//! [`PinnEstimator::fix_delta_theta_offset`] (a calibrated offset, kept across enables).
//!
//! A sample with a non-finite model input gives a NaN estimate on that tick and leaves no trace:
//! a PINN holds its last finite sample in the history in its place
//! ([`History::push_or_hold`]), so the next finite sample gives a finite estimate again.
//!
//! What it is **not**: no clamping, gating, gain (`kfc`) or filtering of the estimate — those
//! belong to the control law, which zeroes a non-finite estimate (0 A on that tick).
//! Construction allocates (a PINN copies its weights and metadata); `estimate` and `reset` never do.

use std::fmt;
use std::str::FromStr;

use crate::features::{FeatureError, FeatureSpec, History, JointSample, WarmupPolicy};
use crate::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction};
use crate::kernel::Mlp;
use crate::lugre::LugreEstimator;
use crate::mlp::MlpShapeError;
use crate::weights::{ModelFile, ModelMeta};

/// Every kind of friction model, listed once: the CLI name, the daemon's `friction_model` name, the
/// status ABI code and the fit-file tag all derive from this enum (adding a model starts here).
///
/// The discriminant is the code in `DaemonStatus::model_kind` (the shared-memory ABI): never reorder
/// or reuse one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ModelKind {
    /// No compensation (τ̂_F = 0).
    None = 0,
    /// Coulomb–viscous.
    Cv = 1,
    /// Stribeck–Coulomb–viscous, paper form.
    Scv = 2,
    /// Stribeck–Coulomb–viscous, the authors' code form (sign(), α = 2).
    ScvCode = 3,
    /// Physics-informed neural network.
    Pinn = 4,
    /// LuGre: the SCV Stribeck curve plus a bristle state (pre-sliding stiffness and damping).
    Lugre = 5,
}

impl ModelKind {
    /// Every kind, in code order.
    pub const ALL: [ModelKind; 6] = [
        ModelKind::None,
        ModelKind::Cv,
        ModelKind::Scv,
        ModelKind::ScvCode,
        ModelKind::Pinn,
        ModelKind::Lugre,
    ];

    /// Short name (CLI choice, status display): `"none"`, `"cv"`, `"scv"`, `"scv-code"`, `"pinn"`.
    pub const fn name(self) -> &'static str {
        match self {
            ModelKind::None => "none",
            ModelKind::Cv => "cv",
            ModelKind::Scv => "scv",
            ModelKind::ScvCode => "scv-code",
            ModelKind::Pinn => "pinn",
            ModelKind::Lugre => "lugre",
        }
    }

    /// One line describing the model (CLI help).
    pub const fn description(self) -> &'static str {
        match self {
            ModelKind::None => "no compensation (0 Nm)",
            ModelKind::Cv => "Coulomb–viscous τ = kc·tanh(ka·v) + kv·v",
            ModelKind::Scv => "Stribeck–Coulomb–viscous (paper form, kc, ka, kv, ks, vs, alpha)",
            ModelKind::ScvCode => "the authors' code form (sign(), α = 2): fc, fs, fv, vs",
            ModelKind::Pinn => "physics-informed neural network (`.fwt`)",
            ModelKind::Lugre => {
                "LuGre: the SCV Stribeck curve (kc, kv, ks, vs, alpha) plus bristle sigma0, sigma1"
            }
        }
    }

    /// Whether the model is a function of the current joint velocity alone (no history, no state),
    /// so that its curve τ(ṡ) describes it.
    pub const fn is_static(self) -> bool {
        matches!(
            self,
            ModelKind::None | ModelKind::Cv | ModelKind::Scv | ModelKind::ScvCode
        )
    }

    /// The status ABI code (`DaemonStatus::model_kind`).
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The kind of a status ABI code; `None` for a code no kind has.
    pub fn from_code(code: u8) -> Option<ModelKind> {
        ModelKind::ALL.into_iter().find(|k| k.code() == code)
    }

    /// The `model` tag of a fit file (`frictl fit --json`): `"Cv"`, `"Scv"`, `"ScvCode"`, `"Lugre"`; `None` for
    /// a kind `frictl fit` does not fit.
    pub const fn fit_tag(self) -> Option<&'static str> {
        match self {
            ModelKind::Cv => Some("Cv"),
            ModelKind::Scv => Some("Scv"),
            ModelKind::ScvCode => Some("ScvCode"),
            ModelKind::Lugre => Some("Lugre"),
            ModelKind::None | ModelKind::Pinn => None,
        }
    }

    /// The kind with fit-file tag `tag`.
    pub fn from_fit_tag(tag: &str) -> Option<ModelKind> {
        ModelKind::ALL
            .into_iter()
            .find(|k| k.fit_tag() == Some(tag))
    }

    /// The daemon config's `friction_model` name (the ergoCub names), `None` for a kind the daemon
    /// runs under another kind's name (the SCV code form runs as SCV with ka = ∞, α = 2).
    pub const fn config_name(self) -> Option<&'static str> {
        match self {
            ModelKind::None => Some("none"),
            ModelKind::Cv => Some("coulomb_viscous"),
            ModelKind::Scv => Some("coulomb_viscous_stribeck"),
            ModelKind::ScvCode => None,
            ModelKind::Pinn => Some("pinn"),
            ModelKind::Lugre => Some("lugre"),
        }
    }

    /// The kind a config's `friction_model` names: its [`ModelKind::config_name`] or, as a short
    /// form, its [`ModelKind::name`].
    pub fn from_config_name(s: &str) -> Option<ModelKind> {
        ModelKind::ALL
            .into_iter()
            .filter(|k| k.config_name().is_some())
            .find(|k| k.config_name() == Some(s) || k.name() == s)
    }

    /// The kind the daemon runs a model of this kind as (itself, or SCV for the SCV code form).
    pub const fn daemon_kind(self) -> ModelKind {
        match self {
            ModelKind::ScvCode => ModelKind::Scv,
            k => k,
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown model-kind name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown friction model kind `{0}` (expected one of: {names})", names = kind_names())]
pub struct UnknownModelKind(pub String);

fn kind_names() -> String {
    ModelKind::ALL.map(ModelKind::name).join(", ")
}

impl FromStr for ModelKind {
    type Err = UnknownModelKind;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ModelKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownModelKind(s.to_string()))
    }
}

/// A per-joint friction estimator.
pub trait FrictionModel {
    /// The model family.
    fn kind(&self) -> ModelKind;
    /// Called on enable (bumpless): clears history, latches Δθ offset at this sample (a sample
    /// with a non-finite s or θ leaves it to the first finite one).
    fn reset(&mut self, sample: &JointSample);
    /// One tick: push the sample, return τ̂_F [Nm, joint side]. Never allocates, never panics.
    /// Returns 0.0 while a HoldZero PINN warms up. Returns NaN on a tick whose model inputs are not
    /// all finite (the caller zeroes it); that sample does not reach later ticks (a PINN holds its
    /// last finite sample in the history instead), so the next finite sample gives a finite estimate.
    fn estimate(&mut self, sample: &JointSample) -> f64;
    /// Whether the next `estimate` comes from the model rather than a warm-up 0. Static models: always.
    fn is_ready(&self) -> bool {
        true
    }
}

/// No friction compensation: always 0 Nm.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoFriction;

impl FrictionModel for NoFriction {
    fn kind(&self) -> ModelKind {
        ModelKind::None
    }
    fn reset(&mut self, _sample: &JointSample) {}
    #[inline]
    fn estimate(&mut self, _sample: &JointSample) -> f64 {
        0.0
    }
}

/// The static models: τ̂_F = τ(ṡ) of their [`StaticFriction`] curve, no state.
macro_rules! static_friction_model {
    ($($ty:ty => $kind:expr),+ $(,)?) => {$(
        impl FrictionModel for $ty {
            fn kind(&self) -> ModelKind {
                $kind
            }
            fn reset(&mut self, _sample: &JointSample) {}
            #[inline]
            fn estimate(&mut self, sample: &JointSample) -> f64 {
                self.torque_nm(sample.sdot_rad_s)
            }
        }
    )+};
}

static_friction_model!(
    CvParams => ModelKind::Cv,
    ScvParams => ModelKind::Scv,
    ScvCodeParams => ModelKind::ScvCode,
);

/// Why a PINN estimator cannot be built from a model file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The feature spec is invalid (e.g. H out of range).
    #[error("model for joint `{joint}`: {source}")]
    Features {
        /// Joint name from the metadata.
        joint: String,
        /// The feature error.
        #[source]
        source: FeatureError,
    },
    /// The metadata's feature spec and the network disagree on the input width.
    #[error(
        "model for joint `{joint}`: feature spec {spec} needs {expected} inputs but the network takes {got}"
    )]
    InputCount {
        /// Joint name.
        joint: String,
        /// The spec, rendered.
        spec: String,
        /// `FeatureSpec::n_inputs()`.
        expected: usize,
        /// `MlpWeights::n_inputs()`.
        got: usize,
    },
    /// The network is not acceptable to the kernel.
    #[error("model for joint `{joint}`: network: {source}")]
    Network {
        /// Joint name.
        joint: String,
        /// The shape error.
        #[source]
        source: MlpShapeError,
    },
}

/// The PINN friction estimator of one joint: feature history + MLP kernel + warm-up policy.
///
/// Built once (allocates); [`FrictionModel::estimate`] pushes the sample into the history, builds the
/// input vector into a preallocated buffer and runs one inference, without allocating. A sample with
/// a non-finite input is held out of the history ([`History::push_or_hold`]) and its tick's estimate
/// is NaN.
#[derive(Clone, Debug)]
pub struct PinnEstimator {
    mlp: Mlp,
    history: History,
    warmup: WarmupPolicy,
    x: Box<[f32]>,
    meta: ModelMeta,
}

impl PinnEstimator {
    /// Builds the estimator from a model file: checks the feature spec, that it matches the network's
    /// input width, and lays the network out for the kernel (in the file's storage dtype).
    pub fn from_model_file(f: &ModelFile, warmup: WarmupPolicy) -> Result<Self, ModelError> {
        let joint = || f.meta.joint_name.clone();
        let spec: FeatureSpec = f.meta.features;
        let history =
            History::new(spec, f.meta.gear_ratio).map_err(|source| ModelError::Features {
                joint: joint(),
                source,
            })?;
        if spec.n_inputs() != f.mlp.n_inputs() {
            return Err(ModelError::InputCount {
                joint: joint(),
                spec: spec.to_string(),
                expected: spec.n_inputs(),
                got: f.mlp.n_inputs(),
            });
        }
        let mlp = Mlp::new(&f.mlp, f.dtype).map_err(|source| ModelError::Network {
            joint: joint(),
            source,
        })?;
        Ok(Self {
            mlp,
            history,
            warmup,
            x: vec![0.0; spec.n_inputs()].into_boxed_slice(),
            meta: f.meta.clone(),
        })
    }

    /// The model's metadata (a copy taken at construction).
    pub fn meta(&self) -> &ModelMeta {
        &self.meta
    }

    /// Whether the history allows inference under the warm-up policy.
    pub fn is_ready(&self) -> bool {
        self.history.is_ready(self.warmup)
    }

    /// The warm-up policy.
    pub fn warmup(&self) -> WarmupPolicy {
        self.warmup
    }

    /// The feature history.
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The input vector of the last inference (zeros before the first one).
    pub fn last_input(&self) -> &[f32] {
        &self.x
    }

    /// Whether `sample`'s model inputs lie outside the training range stored in the model file,
    /// each range widened on both sides by `margin` times its width (see
    /// [`crate::weights::InputRange::within`]). Each feature block is judged on `sample` alone (the
    /// newest value; older history samples were judged when they were newest), with the current Δθ
    /// latch, and the temperature if the model takes it. A model without a stored range is never out
    /// of range. Allocation-free; a non-finite input counts as out of range.
    #[inline]
    pub fn out_of_range(&self, sample: &JointSample, margin: f32) -> bool {
        use crate::weights::InputRange;
        let Some(r) = &self.meta.training.input_range else {
            return false;
        };
        let spec = self.history.spec();
        for (&feature, range) in spec.set.blocks().iter().zip(&r.blocks) {
            let v = self.history.feature_value(feature, sample) as f32;
            if !InputRange::within(*range, v, margin) {
                return true;
            }
        }
        spec.temperature && !InputRange::within(r.temperature, sample.temperature_c as f32, margin)
    }

    /// Fixes the Δθ offset θ_off [motor rad] so [`FrictionModel::reset`] (enable) no longer
    /// re-latches it (see [`History::fix_delta_theta_offset`]); `None` restores latching at enable.
    /// Use the offset the training data were recorded with (e.g. 0 for the virtual joints, whose
    /// encoders read θ = r·φ: Δθ is then the absolute deflection, as in a log latched once at a
    /// torque-free start).
    pub fn fix_delta_theta_offset(&mut self, theta_off_motor_rad: Option<f64>) {
        self.history.fix_delta_theta_offset(theta_off_motor_rad);
    }

    /// Brings the network's weights towards the core ([`Mlp::prefetch`]) so the next
    /// [`FrictionModel::estimate`] does not wait for memory; for the idle part of a real-time period.
    /// Allocation-free; changes no result.
    #[inline]
    pub fn prefetch(&self) {
        self.mlp.prefetch();
    }

    /// Bytes of weight storage one inference streams ([`Mlp::weight_bytes`]).
    pub fn weight_bytes(&self) -> usize {
        self.mlp.weight_bytes()
    }
}

impl FrictionModel for PinnEstimator {
    fn kind(&self) -> ModelKind {
        ModelKind::Pinn
    }

    fn reset(&mut self, sample: &JointSample) {
        self.history.reset(sample);
    }

    #[inline]
    fn estimate(&mut self, sample: &JointSample) -> f64 {
        if !self.history.push_or_hold(sample) {
            // Not in the history (the last finite sample was held in its place): this tick only.
            return f64::NAN;
        }
        if !self.history.is_ready(self.warmup) {
            return 0.0;
        }
        // `x` was sized from the same spec as the history, so `fill` cannot fail; NaN if it ever did.
        if self.history.fill(&mut self.x).is_err() {
            return f64::NAN;
        }
        f64::from(self.mlp.forward(&self.x))
    }

    fn is_ready(&self) -> bool {
        PinnEstimator::is_ready(self)
    }
}

/// The friction model of one joint, enum-dispatched for the real-time path.
#[derive(Clone, Debug)]
pub enum JointModel {
    /// No compensation.
    None(NoFriction),
    /// Coulomb–viscous.
    Cv(CvParams),
    /// Stribeck–Coulomb–viscous, paper form.
    Scv(ScvParams),
    /// Stribeck–Coulomb–viscous, the authors' code form.
    ScvCode(ScvCodeParams),
    /// PINN (boxed: it is large and holds the network).
    Pinn(Box<PinnEstimator>),
    /// LuGre (bristle state reset at enable, integrated once per tick).
    Lugre(LugreEstimator),
}

impl JointModel {
    /// Prefetches the model's network weights ([`PinnEstimator::prefetch`]); a no-op for the static
    /// models (CV, SCV, none), which have no weights to stream.
    #[inline]
    pub fn prefetch(&self) {
        if let JointModel::Pinn(p) = self {
            p.prefetch();
        }
    }

    /// Bytes of network weights one estimate streams (0 for the static models).
    pub fn weight_bytes(&self) -> usize {
        match self {
            JointModel::Pinn(p) => p.weight_bytes(),
            _ => 0,
        }
    }
}

impl Default for JointModel {
    fn default() -> Self {
        JointModel::None(NoFriction)
    }
}

impl From<CvParams> for JointModel {
    fn from(p: CvParams) -> Self {
        JointModel::Cv(p)
    }
}

impl From<ScvParams> for JointModel {
    fn from(p: ScvParams) -> Self {
        JointModel::Scv(p)
    }
}

impl From<ScvCodeParams> for JointModel {
    fn from(p: ScvCodeParams) -> Self {
        JointModel::ScvCode(p)
    }
}

impl From<LugreEstimator> for JointModel {
    fn from(p: LugreEstimator) -> Self {
        JointModel::Lugre(p)
    }
}

impl FrictionModel for LugreEstimator {
    fn kind(&self) -> ModelKind {
        ModelKind::Lugre
    }
    fn reset(&mut self, _sample: &JointSample) {
        self.reset_state();
    }
    #[inline]
    fn estimate(&mut self, sample: &JointSample) -> f64 {
        self.step(sample.sdot_rad_s)
    }
}

impl From<PinnEstimator> for JointModel {
    fn from(p: PinnEstimator) -> Self {
        JointModel::Pinn(Box::new(p))
    }
}

impl FrictionModel for JointModel {
    #[inline]
    fn kind(&self) -> ModelKind {
        match self {
            JointModel::None(m) => m.kind(),
            JointModel::Cv(m) => m.kind(),
            JointModel::Scv(m) => m.kind(),
            JointModel::ScvCode(m) => m.kind(),
            JointModel::Pinn(m) => m.kind(),
            JointModel::Lugre(m) => m.kind(),
        }
    }

    #[inline]
    fn reset(&mut self, sample: &JointSample) {
        match self {
            JointModel::None(m) => m.reset(sample),
            JointModel::Cv(m) => m.reset(sample),
            JointModel::Scv(m) => m.reset(sample),
            JointModel::ScvCode(m) => m.reset(sample),
            JointModel::Pinn(m) => m.reset(sample),
            JointModel::Lugre(m) => m.reset(sample),
        }
    }

    #[inline]
    fn estimate(&mut self, sample: &JointSample) -> f64 {
        match self {
            JointModel::None(m) => m.estimate(sample),
            JointModel::Cv(m) => m.estimate(sample),
            JointModel::Scv(m) => m.estimate(sample),
            JointModel::ScvCode(m) => m.estimate(sample),
            JointModel::Pinn(m) => m.estimate(sample),
            JointModel::Lugre(m) => m.estimate(sample),
        }
    }

    #[inline]
    fn is_ready(&self) -> bool {
        match self {
            JointModel::Pinn(m) => PinnEstimator::is_ready(m),
            _ => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::FeatureSet;
    use crate::friction::paper;
    use crate::mlp::StorageDtype;
    use crate::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
    use crate::units::GearRatio;
    use crate::weights::TrainingMeta;

    fn model_file(spec: FeatureSpec, ratio: f64, seed: u64) -> ModelFile {
        let mlp = RandomMlpSpec {
            sizes: vec![spec.n_inputs(), 16, 8, 1],
            weights: WeightInit::Uniform { amp: 0.5 },
            bias: -0.2..0.2,
            norm: NormInit::Uniform {
                mean: -1.0..1.0,
                scale: 0.5..3.0,
            },
        };
        ModelFile {
            meta: ModelMeta {
                joint_name: "l_ankle_roll".into(),
                gear_ratio: GearRatio::new(ratio).unwrap(),
                kt_nm_per_a: 0.0665,
                features: spec,
                scv: None,
                training: TrainingMeta::unknown("test", 0),
            },
            dtype: StorageDtype::F32,
            mlp: seeded_mlp(&mlp, seed).unwrap(),
        }
    }

    fn sample(k: usize) -> JointSample {
        let t = k as f64 * 1e-3;
        JointSample {
            s_rad: 0.2 * (3.0 * t).sin(),
            sdot_rad_s: 0.6 * (3.0 * t).cos(),
            theta_motor_rad: -160.0 * 0.2 * (3.0 * t).sin() + 7.0 + 0.3 * (5.0 * t).sin(),
            omega_motor_rad_s: -96.0 * (3.0 * t).cos(),
            temperature_c: 35.0 + t,
        }
    }

    /// The input vector built from scratch for `window` (oldest first), zero-padded to H.
    fn hand_built(
        spec: FeatureSpec,
        ratio: f64,
        theta_off: f64,
        window: &[JointSample],
    ) -> Vec<f32> {
        assert_eq!(spec.set, FeatureSet::DeltaThetaJointVel);
        let h = spec.history;
        let mut x = vec![0.0f32; spec.n_inputs()];
        let pad = h - window.len();
        for (j, s) in window.iter().enumerate() {
            x[pad + j] = (ratio * s.s_rad - (s.theta_motor_rad - theta_off)) as f32;
            x[h + pad + j] = s.sdot_rad_s as f32;
        }
        if spec.temperature {
            x[2 * h] = window.last().map_or(0.0, |s| s.temperature_c as f32);
        }
        x
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-4 * (1.0 + b.abs())
    }

    #[test]
    fn out_of_range_judges_each_block_and_the_temperature_of_the_newest_sample() {
        let spec = FeatureSpec {
            set: FeatureSet::MotorVelJointVel,
            history: 3,
            temperature: true,
        };
        let mut f = model_file(spec, -160.0, 5);
        let s = |omega: f64, sdot: f64, t: f64| JointSample {
            s_rad: 0.0,
            sdot_rad_s: sdot,
            theta_motor_rad: 0.0,
            omega_motor_rad_s: omega,
            temperature_c: t,
        };
        // No stored range: never out of range.
        let mut p = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        p.estimate(&s(1e6, 1e6, 1e6));
        assert!(!p.out_of_range(&s(1e6, 1e6, 1e6), 0.0));
        f.meta.training.input_range = Some(crate::weights::InputRange {
            blocks: [[-100.0, 100.0], [-0.5, 0.5], [0.0, 0.0]],
            temperature: [20.0, 40.0],
        });
        let p = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        assert!(!p.out_of_range(&s(90.0, 0.4, 30.0), 0.0));
        assert!(p.out_of_range(&s(101.0, 0.4, 30.0), 0.0), "motor velocity");
        assert!(p.out_of_range(&s(90.0, -0.6, 30.0), 0.0), "joint velocity");
        assert!(
            !p.out_of_range(&s(90.0, -0.6, 30.0), 0.25),
            "within the margin"
        );
        assert!(p.out_of_range(&s(90.0, 0.4, 41.0), 0.0), "temperature");
        assert!(p.out_of_range(&s(f64::NAN, 0.4, 30.0), 0.0), "NaN");
    }

    #[test]
    fn pinn_equals_reference_forward_on_hand_built_history() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 6,
            temperature: true,
        };
        let f = model_file(spec, -160.0, 1);
        let mut est = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        assert_eq!(est.kind(), ModelKind::Pinn);
        let enable = sample(0);
        est.reset(&enable);
        let theta_off = enable.theta_motor_rad - (-160.0) * enable.s_rad;
        let mut seen = Vec::new();
        let mut nonzero = 0;
        for k in 0..40 {
            let s = sample(k * 37);
            seen.push(s);
            let y = est.estimate(&s);
            let window = &seen[seen.len().saturating_sub(6)..];
            let x = hand_built(spec, -160.0, theta_off, window);
            assert_eq!(est.last_input(), &x[..], "tick {k}: input vector");
            let want = f64::from(f.mlp.forward_reference(&x)[0]);
            assert!(close(y, want), "tick {k}: estimate {y}, reference {want}");
            nonzero += usize::from(y != 0.0);
        }
        assert!(nonzero > 30, "a random network gives non-zero outputs");
        assert_eq!(est.meta().joint_name, f.meta.joint_name);
        assert_eq!(est.meta().features, spec);
    }

    /// A sample with a non-finite model input (NaN, ±∞, or a finite value beyond f32's range)
    /// costs its own tick only: NaN on that tick, then the window holds the last finite sample in
    /// its place and the next finite sample gives that window's (finite) estimate.
    #[test]
    fn a_non_finite_sample_costs_only_its_own_tick() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 6,
            temperature: true,
        };
        let f = model_file(spec, -160.0, 4);
        type Corrupt = (&'static str, fn(&mut JointSample));
        let bad: [Corrupt; 5] = [
            ("NaN joint velocity", |s| s.sdot_rad_s = f64::NAN),
            ("+inf motor angle", |s| s.theta_motor_rad = f64::INFINITY),
            ("NaN joint angle", |s| s.s_rad = f64::NAN),
            ("NaN temperature", |s| s.temperature_c = f64::NAN),
            ("joint velocity beyond f32", |s| s.sdot_rad_s = 1e39),
        ];
        for (what, spoil) in bad {
            let mut est = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
            let enable = sample(0);
            est.reset(&enable);
            let theta_off = enable.theta_motor_rad - (-160.0) * enable.s_rad;
            // The window as a clean history sees it: the held sample repeats the one before.
            let mut seen: Vec<JointSample> = Vec::new();
            for k in 0..20 {
                let mut s = sample(k * 37);
                if k == 9 || k == 14 {
                    spoil(&mut s);
                    let y = est.estimate(&s);
                    assert!(y.is_nan(), "{what}, tick {k}: {y} (the caller zeroes it)");
                    seen.push(*seen.last().unwrap());
                    continue;
                }
                seen.push(s);
                let y = est.estimate(&s);
                let window = &seen[seen.len().saturating_sub(6)..];
                let x = hand_built(spec, -160.0, theta_off, window);
                assert_eq!(est.last_input(), &x[..], "{what}, tick {k}: input vector");
                let want = f64::from(f.mlp.forward_reference(&x)[0]);
                assert!(
                    y.is_finite() && close(y, want),
                    "{what}, tick {k}: estimate {y}, reference {want}"
                );
            }
        }
    }

    /// An enable on a sample with a non-finite s or θ cannot latch Δθ: the first finite sample
    /// does, and the estimate from then on is finite (not NaN until the next enable).
    #[test]
    fn an_enable_on_a_non_finite_sample_latches_at_the_first_finite_one() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 3,
            temperature: false,
        };
        let f = model_file(spec, -160.0, 6);
        let mut est = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        let mut enable = sample(5);
        enable.theta_motor_rad = f64::NAN;
        est.reset(&enable);
        assert!(est.estimate(&enable).is_nan(), "the bad tick itself");
        assert!(est.history().is_empty(), "nothing to hold yet: stays empty");
        let first = sample(6);
        let y = est.estimate(&first);
        let theta_off = first.theta_motor_rad - (-160.0) * first.s_rad;
        assert!(
            (est.history().latch().offset_motor_rad() - theta_off).abs() < 1e-9,
            "latched at the first finite sample"
        );
        let x = hand_built(spec, -160.0, theta_off, &[first]);
        assert_eq!(est.last_input(), &x[..]);
        assert!(y.is_finite() && close(y, f64::from(f.mlp.forward_reference(&x)[0])));
        for k in 7..20 {
            assert!(est.estimate(&sample(k)).is_finite(), "tick {k}");
        }
    }

    #[test]
    fn hold_zero_outputs_zero_for_h_minus_1_ticks() {
        let spec = FeatureSpec {
            set: FeatureSet::MotorVelJointVel,
            history: 5,
            temperature: false,
        };
        let f = model_file(spec, 100.0, 2);
        let mut est =
            JointModel::from(PinnEstimator::from_model_file(&f, WarmupPolicy::HoldZero).unwrap());
        for round in 0..2 {
            est.reset(&sample(100 * round));
            for k in 0..4 {
                assert!(!est.is_ready());
                assert_eq!(
                    est.estimate(&sample(100 * round + k)),
                    0.0,
                    "round {round} tick {k}"
                );
            }
            let y = est.estimate(&sample(100 * round + 4));
            assert!(est.is_ready());
            let mut x = Vec::new();
            for blk in 0..2 {
                for k in 0..5 {
                    let s = sample(100 * round + k);
                    x.push(if blk == 0 {
                        s.omega_motor_rad_s
                    } else {
                        s.sdot_rad_s
                    } as f32);
                }
            }
            let want = f64::from(f.mlp.forward_reference(&x)[0]);
            assert!(
                want != 0.0 && close(y, want),
                "round {round}: {y} vs {want}"
            );
        }
    }

    #[test]
    fn reset_clears_history_and_latches_delta_theta() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 3,
            temperature: false,
        };
        let f = model_file(spec, -160.0, 3);
        let mut est = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        for k in 0..10 {
            est.estimate(&sample(k * 50));
        }
        assert!(est.history().is_full());
        let enable = sample(777);
        est.reset(&enable);
        assert!(est.history().is_empty());
        let off = est.history().latch().offset_motor_rad();
        assert!((off - (enable.theta_motor_rad + 160.0 * enable.s_rad)).abs() < 1e-12);
        // Holding still at the enable pose: Δθ block is all zero, older samples are zero-padded.
        let y = est.estimate(&enable);
        let x = [0.0, 0.0, 0.0, 0.0, 0.0, enable.sdot_rad_s as f32];
        assert_eq!(est.last_input(), &x);
        assert!(close(y, f64::from(f.mlp.forward_reference(&x)[0])));
    }

    #[test]
    fn fixed_offset_is_kept_across_enables() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 3,
            temperature: false,
        };
        let f = model_file(spec, -160.0, 4);
        let mut est = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap();
        // θ_off = 7 motor rad, the constant part of `sample`'s motor angle.
        est.fix_delta_theta_offset(Some(7.0));
        for enable_at in [100, 333] {
            let enable = sample(enable_at);
            est.reset(&enable);
            let y = est.estimate(&enable);
            let x = hand_built(spec, -160.0, 7.0, &[enable]);
            assert_eq!(est.last_input(), &x[..], "enable at sample {enable_at}");
            assert!(
                x[2] != 0.0,
                "the wound-up sample has Δθ ≠ 0 with a fixed offset"
            );
            assert!(close(y, f64::from(f.mlp.forward_reference(&x)[0])));
        }
        // Back to latching at enable: Δθ = 0 at the enable sample.
        est.fix_delta_theta_offset(None);
        let enable = sample(500);
        est.reset(&enable);
        est.estimate(&enable);
        assert_eq!(est.last_input()[2], 0.0);
    }
    #[test]
    fn static_models_equal_friction_values() {
        let mut models: Vec<JointModel> = vec![
            paper::CV_KNEE.into(),
            paper::SCV_ANKLE_ROLL.into(),
            ScvCodeParams {
                fc: 0.24,
                fs: 0.46,
                fv: 0.77,
                vs: 0.0198,
            }
            .into(),
            JointModel::default(),
        ];
        let kinds: Vec<ModelKind> = models.iter().map(|m| m.kind()).collect();
        assert_eq!(
            kinds,
            [
                ModelKind::Cv,
                ModelKind::Scv,
                ModelKind::ScvCode,
                ModelKind::None
            ]
        );
        for k in 0..200 {
            let s = JointSample {
                sdot_rad_s: (k as f64 - 100.0) * 0.013,
                ..sample(k)
            };
            let v = s.sdot_rad_s;
            assert_eq!(models[0].estimate(&s), paper::CV_KNEE.torque_nm(v));
            assert_eq!(models[1].estimate(&s), paper::SCV_ANKLE_ROLL.torque_nm(v));
            if let JointModel::ScvCode(p) = models[2] {
                assert_eq!(models[2].estimate(&s), p.torque_nm(v));
            }
            assert_eq!(models[3].estimate(&s), 0.0);
            for m in &mut models {
                m.reset(&s);
                assert!(m.is_ready());
            }
        }
    }

    #[test]
    fn from_model_file_rejects_mismatches() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 4,
            temperature: false,
        };
        let mut f = model_file(spec, -160.0, 4);
        f.meta.features.temperature = true;
        let e = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap_err();
        assert!(
            matches!(
                e,
                ModelError::InputCount {
                    expected: 9,
                    got: 8,
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("l_ankle_roll"), "{e}");
        let mut f = model_file(spec, -160.0, 4);
        f.meta.features.history = 0;
        let e = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap_err();
        assert!(matches!(e, ModelError::Features { .. }), "{e:?}");
        let mut f = model_file(spec, -160.0, 4);
        f.mlp.layers[1].bias[0] = f32::NAN;
        let e = PinnEstimator::from_model_file(&f, WarmupPolicy::ZeroPad).unwrap_err();
        assert!(matches!(e, ModelError::Network { .. }), "{e:?}");
    }

    #[test]
    fn model_kind_names_codes_and_tags() {
        for (i, k) in ModelKind::ALL.into_iter().enumerate() {
            assert_eq!(k.to_string().parse::<ModelKind>().unwrap(), k);
            assert_eq!(usize::from(k.code()), i, "codes in list order");
            assert_eq!(ModelKind::from_code(k.code()), Some(k));
            if let Some(tag) = k.fit_tag() {
                assert_eq!(ModelKind::from_fit_tag(tag), Some(k));
            }
            if let Some(name) = k.config_name() {
                assert_eq!(ModelKind::from_config_name(name), Some(k));
                assert_eq!(ModelKind::from_config_name(k.name()), Some(k));
            }
            assert!(
                k.daemon_kind().config_name().is_some(),
                "{k} runs as a config kind"
            );
        }
        // The strings files and configs already use.
        let tags: Vec<_> = ModelKind::ALL.iter().filter_map(|k| k.fit_tag()).collect();
        assert_eq!(tags, ["Cv", "Scv", "ScvCode", "Lugre"]);
        assert_eq!(
            ModelKind::from_config_name("coulomb_viscous_stribeck"),
            Some(ModelKind::Scv)
        );
        assert_eq!(ModelKind::from_config_name("scv-code"), None);
        assert_eq!(ModelKind::from_code(200), None);
        assert!("stribeck".parse::<ModelKind>().is_err());
    }
}
