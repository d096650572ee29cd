//! Runtime parameters built from a validated [`Config`]: everything the RT thread needs, allocated
//! off-thread and handed over as one `Box<Params>`.
//!
//! What this module **is**: construction of per-joint friction estimators and control laws (filter
//! coefficients designed here, not on the RT thread), and the model-file check used by `--check`.
//!
//! What it is **not**: no I/O besides reading model files; nothing here runs on the RT thread except
//! the `#[inline]` estimator calls.

use std::path::PathBuf;

use frictionless::features::WarmupPolicy;
use frictionless::model::{JointModel, ModelError, NoFriction, PinnEstimator};
use frictionless::weights::WeightError;
use frictionless_shm_types::model_kind;

use frictionless::filter::{CausalButterworth, FilterError};
use frictionless::law::{Gains, JointLaw};

use crate::config::{Config, ModelSpec, OnStale, WarmupName};

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
pub use crate::config::check_model_file;

/// Status code of a model kind (`frictionless_shm_types::model_kind`).
pub fn kind_code(m: &JointModel) -> u8 {
    match m {
        JointModel::None(_) => model_kind::NONE,
        JointModel::Cv(_) => model_kind::CV,
        JointModel::Scv(_) => model_kind::SCV,
        JointModel::ScvCode(_) => model_kind::SCV_CODE,
        JointModel::Pinn(_) => model_kind::PINN,
    }
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
}

/// Builds the runtime parameters (loads model files, designs filters). Off the RT thread.
pub fn build(cfg: &Config, generation: u64) -> Result<Box<Params>, ParamsError> {
    let dt_s = cfg.raw.loop_.period_us as f64 * 1e-6;
    let fs_hz = 1.0 / dt_s;
    let mut joints = Vec::with_capacity(cfg.raw.joint.len());
    let mut configured_mask = 0u64;
    for (j, spec) in cfg.raw.joint.iter().zip(&cfg.models) {
        let model = match spec {
            ModelSpec::None => JointModel::None(NoFriction),
            ModelSpec::Cv(p) => JointModel::Cv(*p),
            ModelSpec::Scv(p) => JointModel::Scv(*p),
            ModelSpec::Pinn { path, warmup } => {
                let file = frictionless::weights::read_file(path).map_err(|source| {
                    ParamsError::ReadModel {
                        joint: j.name.clone(),
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
                        joint: j.name.clone(),
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
        };
        configured_mask |= 1u64 << j.index;
        joints.push(JointRt {
            index: j.index,
            model,
            law: JointLaw::new(gains, lpf),
        });
    }
    Ok(Box::new(Params {
        generation,
        joints,
        stale_after_ticks: cfg.raw.safety.stale_after_ticks,
        on_stale: cfg.raw.safety.on_stale,
        configured_mask,
    }))
}
