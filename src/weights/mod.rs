//! The `.fwt` weight file: fixed-size, versioned, self-describing, CRC-32C protected.
//!
//! (skeleton — reader and writer are filled in by the weight-format work; the types are the contract)

use crate::features::FeatureSpec;
use crate::friction::ScvParams;
use crate::mlp::{MlpWeights, StorageDtype};
use crate::units::GearRatio;

/// Which velocity/current signals the model was trained on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalFiltering {
    /// Not recorded (e.g. imported from ONNX).
    Unknown,
    /// Causal (forward-only) filters, as the daemon sees at run time.
    Causal,
    /// Zero-phase / smoothed (non-causal) filters, as the authors trained.
    NonCausal,
}

/// Provenance and quality of a trained model.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingMeta {
    /// SHA-256 of the training dataset (all zeros if unknown).
    pub dataset_sha256: [u8; 32],
    /// Validation RMSE [Nm] (NaN if unknown).
    pub val_rmse_nm: f32,
    /// Test RMSE [Nm] (NaN if unknown).
    pub test_rmse_nm: f32,
    /// Creation time, seconds since the Unix epoch.
    pub created_unix_s: u64,
    /// Tool and version that wrote the file, e.g. "frictl 0.1.0" (≤ 31 bytes).
    pub tool_version: String,
    /// Signals the model was trained on.
    pub filtering: SignalFiltering,
}

/// Everything about a model besides its weights.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelMeta {
    /// Joint name, e.g. "l_ankle_roll" (≤ 63 bytes UTF-8).
    pub joint_name: String,
    /// Signed gear ratio used for Δθ and the current.
    pub gear_ratio: GearRatio,
    /// Torque constant [Nm/A] the labels were computed with.
    pub kt_nm_per_a: f64,
    /// Input features, their order and history.
    pub features: FeatureSpec,
    /// The SCV prior used in the physics loss, if any.
    pub scv: Option<ScvParams>,
    /// Provenance.
    pub training: TrainingMeta,
}

/// A complete model file in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    /// Metadata.
    pub meta: ModelMeta,
    /// Storage precision of the weights.
    pub dtype: StorageDtype,
    /// The network (values already rounded to `dtype` when read from a file).
    pub mlp: MlpWeights,
}
