//! Runtime parameters built from a validated [`Config`]: everything frictiond's RT thread needs,
//! allocated off-thread and handed over as one `Box<Params>` (the daemon re-exports this module as
//! `frictiond::params`).
//!
//! What this module **is**: construction of per-joint friction estimators and control laws (filter
//! coefficients designed here, not on the RT thread), and the model-file check used by `--check`.
//!
//! What it is **not**: no I/O besides reading model files; nothing here runs on the RT thread except
//! the `#[inline]` estimator calls.

use std::path::PathBuf;

use frictionless::features::{JointSample, WarmupPolicy};
use frictionless::model::{FrictionModel, JointModel, ModelError, NoFriction, PinnEstimator};
use frictionless::weights::WeightError;

use frictionless::filter::{CausalButterworth, FilterError};
use frictionless::law::{Gains, JointLaw};

use crate::{Config, ModelSpec, OnStale, OodMode, StaticFallback, WarmupName};

/// Why the runtime parameters could not be built. Messages name the joint, the file and the cause.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// A `.fwt` model file could not be read.
    #[error("joint {joint}: model {}: {source}", path.display())]
    ReadModel {
        /// Joint name.
        joint: String,
        /// The model file.
        path: PathBuf,
        /// Why reading failed (boxed: keeps `Result<_, ParamsError>` small).
        source: Box<WeightError>,
    },
    /// A model file was read but does not make an estimator.
    #[error("joint {joint}: model {}: {source}", path.display())]
    Model {
        /// Joint name.
        joint: String,
        /// The model file.
        path: PathBuf,
        /// Why the estimator could not be built (boxed: keeps `Result<_, ParamsError>` small).
        source: Box<ModelError>,
    },
    /// A LuGre model cannot integrate at the loop period.
    #[error("joint {joint}: {source}")]
    Lugre {
        /// Joint name.
        joint: String,
        /// The parameter (or period) at fault.
        source: frictionless::lugre::LugreParamError,
    },
    /// The speed-dependent current limit breaks a rule (a validated config never does).
    #[error("joint {joint}: speed_current_limit: {source}")]
    SpeedLimit {
        /// Joint name.
        joint: String,
        /// The rule broken.
        source: frictionless::law::LimitRule,
    },
    /// The τ̂_F low-pass cannot be designed.
    #[error("joint {joint}: lpf: {source}")]
    Lpf {
        /// Joint name.
        joint: String,
        /// The design error.
        source: FilterError,
    },
}

/// The model-file check `--check` runs, defined with the config schema.
pub use crate::check_model_file;

/// Status code of a joint's model (`DaemonStatus::model_kind`): its kind's ABI code.
pub fn kind_code(m: &JointModel) -> u8 {
    m.kind().code()
}

/// Everything the RT loop needs for one joint.
#[derive(Debug)]
pub struct JointRt {
    /// Index into payload arrays.
    pub index: usize,
    /// Friction estimator.
    pub model: JointModel,
    /// Control law and its state.
    pub law: JointLaw,
    /// Out-of-training-range check and blend.
    pub ood: OodRt,
    /// Friction compensation switch (runtime `compensation = on|off`; on when built): off feeds
    /// the law 0 friction while the model keeps running.
    pub compensation: bool,
    /// The joint's other models (runtime `model = NAME`); [`JointRt::model`] is the active one.
    pub slots: ModelSlots,
    /// Set when [`JointRt::switch_model`] made another model active: the RT thread resets it with
    /// the next sample it computes (a fresh history, as at an enable) and clears this.
    pub model_switched: bool,
}

/// The models one joint can run, by slot: 0 its own (`friction_model`, named `default`), then its
/// `[[joint.alternate]]`s in file order, then `none` (no friction) — the order of
/// [`crate::runtime::model_names`]. The active model lives in [`JointRt::model`]; its slot here
/// holds a [`NoFriction`] placeholder. All built off the RT thread; a switch only swaps.
#[derive(Debug)]
pub struct ModelSlots {
    parked: Vec<JointModel>,
    active: usize,
}

impl ModelSlots {
    /// The slots of a joint whose own model is active and whose alternates are `alternates` (in
    /// [`crate::runtime::model_names`]' order); `none` is added.
    pub fn new(alternates: Vec<JointModel>) -> Self {
        let mut parked = Vec::with_capacity(alternates.len() + 2);
        parked.push(JointModel::None(NoFriction));
        parked.extend(alternates);
        parked.push(JointModel::None(NoFriction));
        Self { parked, active: 0 }
    }

    /// The active slot.
    pub fn active(&self) -> usize {
        self.active
    }

    /// Number of slots.
    pub fn len(&self) -> usize {
        self.parked.len()
    }

    /// Whether there are no slots (never: `default` and `none` always exist).
    pub fn is_empty(&self) -> bool {
        self.parked.is_empty()
    }
}

impl JointRt {
    /// Makes slot `slot` the active model (RT thread, at a tick boundary: two swaps, no
    /// allocation); a slot out of range or already active changes nothing. The law's state (filter,
    /// integral) is kept; the new model is reset at the next computed sample
    /// ([`JointRt::model_switched`]) and the out-of-range blend restarts from it.
    #[inline]
    pub fn switch_model(&mut self, slot: usize) {
        let active = self.slots.active;
        if slot == active || slot >= self.slots.parked.len() {
            return;
        }
        std::mem::swap(&mut self.model, &mut self.slots.parked[active]);
        std::mem::swap(&mut self.model, &mut self.slots.parked[slot]);
        self.slots.active = slot;
        self.model_switched = true;
        self.ood.reset();
    }
}

/// One joint's out-of-training-range handling on the RT thread: the check's settings, the static
/// model blended in under `ood = "static"`, and the blend state. Allocation-free.
#[derive(Debug)]
pub struct OodRt {
    /// `[[joint]] ood`.
    pub mode: OodMode,
    /// `[[joint]] ood_margin` [fraction of each range's width].
    pub margin: f32,
    /// The static model (CV or SCV) blended in while out of range; `None` = flag only.
    pub fallback: Option<JointModel>,
    /// Blend weight change per tick (`period / ood_ramp`; 1 = switch at once).
    pub step_per_tick: f64,
    /// Current blend weight of the static model: 0 = the joint's model only, 1 = static only.
    pub weight: f64,
}

impl OodRt {
    /// No check: never out of range.
    pub fn off() -> Self {
        Self {
            mode: OodMode::Off,
            margin: 0.0,
            fallback: None,
            step_per_tick: 1.0,
            weight: 0.0,
        }
    }

    /// Whether `model`'s inputs for `sample` (already pushed by `estimate`) are out of its training
    /// range. Only a PINN with a stored range can be.
    #[inline]
    pub fn out_of_range(&self, model: &JointModel, sample: &JointSample) -> bool {
        match (self.mode, model) {
            (OodMode::Off, _) => false,
            (_, JointModel::Pinn(p)) => p.out_of_range(sample, self.margin),
            _ => false,
        }
    }

    /// The friction estimate to use this tick [Nm]: `model_nm` moved one ramp step towards the
    /// static model's estimate while `out_of_range`, back towards `model_nm` otherwise (without a
    /// static model, `model_nm` unchanged).
    #[inline]
    pub fn blend(&mut self, model_nm: f64, out_of_range: bool, sample: &JointSample) -> f64 {
        let Some(fallback) = self.fallback.as_mut() else {
            return model_nm;
        };
        let target = if out_of_range { 1.0 } else { 0.0 };
        self.weight = if self.weight < target {
            (self.weight + self.step_per_tick).min(target)
        } else {
            (self.weight - self.step_per_tick).max(target)
        };
        if self.weight <= 0.0 {
            return model_nm;
        }
        let static_nm = fallback.estimate(sample);
        if self.weight >= 1.0 {
            static_nm
        } else {
            (1.0 - self.weight) * model_nm + self.weight * static_nm
        }
    }

    /// Enable edge: the blend restarts from the joint's own model.
    #[inline]
    pub fn reset(&mut self) {
        self.weight = 0.0;
    }
}

/// The RT thread's parameter set; swapped atomically (as a `Box`) on reload.
#[derive(Debug)]
pub struct Params {
    /// 0 at start, +1 per reload.
    pub generation: u64,
    /// Joints.
    pub joints: Vec<JointRt>,
    /// Stale threshold [ticks].
    pub stale_after_ticks: u64,
    /// Safe output when state is stale.
    pub on_stale: OnStale,
    /// Bit set of configured joint indices.
    pub configured_mask: u64,
    /// `joints[..split]` are computed by the main RT thread, `joints[split..]` by the helper thread
    /// (`[loop] rt_threads = 2`); `split == joints.len()` with one RT thread. Set by
    /// [`Params::split_threads`].
    pub split: usize,
    /// Bit set of the joint indices in `joints[split..]` (the helper's half); set with `split`.
    pub helper_mask: u64,
}

/// Per-joint cost the split adds to a network's weight bytes (the law, the history, a static model):
/// joints without a network are still spread evenly.
const JOINT_BASE_COST: usize = 1024;

impl Params {
    /// Splits the joints once into the halves the RT threads compute: with `rt_threads = 2`, two
    /// halves balanced by network weight bytes (greedy, heaviest first, ties by index), each kept
    /// in index order, the main thread's half first; with 1, every joint on the main thread.
    /// Reorders `joints` (outputs are written by [`JointRt::index`], so the order changes nothing
    /// else). Off the RT thread.
    pub fn split_threads(&mut self, rt_threads: u8) {
        if rt_threads < 2 || self.joints.len() < 2 {
            self.split = self.joints.len();
            self.helper_mask = 0;
            return;
        }
        let cost = |j: &JointRt| j.model.weight_bytes() + JOINT_BASE_COST;
        let mut order: Vec<usize> = (0..self.joints.len()).collect();
        order.sort_by(|&a, &b| {
            cost(&self.joints[b])
                .cmp(&cost(&self.joints[a]))
                .then(self.joints[a].index.cmp(&self.joints[b].index))
        });
        let mut helper = vec![false; self.joints.len()];
        let (mut main_cost, mut helper_cost) = (0usize, 0usize);
        for k in order {
            if helper_cost < main_cost {
                helper[k] = true;
                helper_cost += cost(&self.joints[k]);
            } else {
                main_cost += cost(&self.joints[k]);
            }
        }
        let mut tagged: Vec<(bool, JointRt)> =
            helper.into_iter().zip(self.joints.drain(..)).collect();
        tagged.sort_by_key(|(h, j)| (*h, j.index));
        self.split = tagged.iter().filter(|(h, _)| !h).count();
        self.joints = tagged.into_iter().map(|(_, j)| j).collect();
        self.helper_mask = self.joints[self.split..]
            .iter()
            .fold(0, |m, j| m | 1u64 << j.index);
    }
}

/// The law's speed-dependent limit of a joint (none when absent).
fn speed_limit(
    j: &crate::JointConfig,
) -> Result<Option<frictionless::law::SpeedCurrentLimit>, ParamsError> {
    let Some(l) = j.speed_current_limit else {
        return Ok(None);
    };
    frictionless::law::SpeedCurrentLimit::new(
        l.rated_motor_speed_rad_s,
        l.no_load_motor_speed_rad_s,
        l.safety_factor,
    )
    .map(Some)
    .map_err(|source| ParamsError::SpeedLimit {
        joint: j.name.clone(),
        source,
    })
}

/// One model of joint `j` (its own, or an alternate's as [`crate::AlternateModel::as_joint`]) and,
/// for a PINN with `ood = "static"`, its static fallback; `who` names the joint in errors.
fn joint_model(
    j: &crate::JointConfig,
    who: &str,
    spec: &ModelSpec,
    dt_s: f64,
) -> Result<(JointModel, Option<JointModel>), ParamsError> {
    let mut fallback = None;
    let model = match spec {
        ModelSpec::None => JointModel::None(NoFriction),
        ModelSpec::Cv(p) => JointModel::Cv(*p),
        ModelSpec::Scv(p) => JointModel::Scv(*p),
        // The bristle state is integrated once per tick, at the loop period.
        ModelSpec::Lugre(p) => {
            JointModel::Lugre(frictionless::lugre::LugreEstimator::new(*p, dt_s).map_err(
                |source| ParamsError::Lugre {
                    joint: who.to_owned(),
                    source,
                },
            )?)
        }
        ModelSpec::Pinn {
            path,
            warmup,
            fallback: fb,
        } => {
            fallback = fb.map(|f| match f {
                StaticFallback::Cv(p) => JointModel::Cv(p),
                StaticFallback::Scv(p) => JointModel::Scv(p),
            });
            let file = frictionless::weights::read_file(path).map_err(|source| {
                ParamsError::ReadModel {
                    joint: who.to_owned(),
                    path: path.clone(),
                    source: Box::new(source),
                }
            })?;
            let policy = match warmup {
                WarmupName::ZeroPad => WarmupPolicy::ZeroPad,
                WarmupName::HoldZero => WarmupPolicy::HoldZero,
            };
            let mut est = PinnEstimator::from_model_file(&file, policy).map_err(|source| {
                ParamsError::Model {
                    joint: who.to_owned(),
                    path: path.clone(),
                    source: Box::new(source),
                }
            })?;
            // A calibrated Δθ offset is kept across enables; without one, Δθ is latched at
            // every enable (see `frictionless::features::History`).
            est.fix_delta_theta_offset(j.delta_theta_offset_motor_rad);
            JointModel::Pinn(Box::new(est))
        }
    };
    Ok((model, fallback))
}

/// Builds the runtime parameters (loads model files, designs filters). Off the RT thread.
pub fn build(cfg: &Config, generation: u64) -> Result<Box<Params>, ParamsError> {
    let dt_s = cfg.raw.loop_.period_us as f64 * 1e-6;
    let fs_hz = 1.0 / dt_s;
    let mut joints = Vec::with_capacity(cfg.raw.joint.len());
    let mut configured_mask = 0u64;
    for ((j, spec), alternates) in cfg.raw.joint.iter().zip(&cfg.models).zip(&cfg.alternates) {
        let (model, fallback) = joint_model(j, &j.name, spec, dt_s)?;
        let mut others = Vec::with_capacity(alternates.len());
        for (a, named) in j.alternate.iter().zip(alternates) {
            let who = format!("{} (alternate {})", j.name, named.name);
            others.push(joint_model(&a.as_joint(j), &who, &named.spec, dt_s)?.0);
        }
        let lpf = match j.lpf {
            Some(l) => Some(
                CausalButterworth::design(l.order, l.cutoff_hz, fs_hz).map_err(|source| {
                    ParamsError::Lpf {
                        joint: j.name.clone(),
                        source,
                    }
                })?,
            ),
            None => None,
        };
        let gains = Gains {
            kt_nm_per_a: j.kt,
            gear_ratio: j.gear_ratio,
            kfc: j.kfc,
            kp: j.kp,
            ki: j.ki,
            max_curr_a: j.max_curr,
            max_output_friction_nm: j.max_output_friction,
            joint_velocity_threshold_rad_s: j.joint_velocity_threshold_rad_s,
            dt_s,
            speed_limit: speed_limit(j)?,
        };
        configured_mask |= 1u64 << j.index;
        let ramp_s = j.ood_ramp_ms * 1e-3;
        let ood = OodRt {
            mode: j.ood,
            margin: j.ood_margin as f32,
            fallback,
            step_per_tick: if ramp_s > dt_s { dt_s / ramp_s } else { 1.0 },
            weight: 0.0,
        };
        joints.push(JointRt {
            index: j.index,
            model,
            law: JointLaw::new(gains, lpf),
            ood,
            compensation: true,
            slots: ModelSlots::new(others),
            model_switched: false,
        });
    }
    let mut p = Box::new(Params {
        generation,
        joints,
        stale_after_ticks: cfg.raw.safety.stale_after_ticks,
        on_stale: cfg.raw.safety.on_stale,
        configured_mask,
        split: 0,
        helper_mask: 0,
    });
    p.split_threads(cfg.raw.loop_.rt_threads);
    Ok(p)
}
