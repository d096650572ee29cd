//! Arguments of `frictl import`.

use super::train::Features;
use frictionless::mlp::StorageDtype;
use std::path::PathBuf;

/// Source format.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// ONNX (PyTorch export: Gemm/MatMul+Add/Relu chain).
    Onnx,
    /// safetensors (PyTorch nn.Sequential state dict).
    Safetensors,
}

/// Weight storage precision.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// IEEE binary32.
    F32,
    /// IEEE binary16.
    F16,
    /// bfloat16.
    Bf16,
    /// int8 hidden-layer weights, per-output-channel scales (output layer f32).
    Int8,
    /// 14-bit fixed-point hidden-layer weights in int16, per-output-channel scales (output layer
    /// f32).
    Int16,
}

impl From<Dtype> for StorageDtype {
    fn from(d: Dtype) -> Self {
        match d {
            Dtype::F32 => StorageDtype::F32,
            Dtype::F16 => StorageDtype::F16,
            Dtype::Bf16 => StorageDtype::Bf16,
            Dtype::Int8 => StorageDtype::Int8,
            Dtype::Int16 => StorageDtype::Int16,
        }
    }
}

/// Arguments of `frictl import onnx|safetensors`.
#[derive(clap::Args, Debug)]
pub struct ModelArgs {
    /// The ONNX or safetensors file.
    pub input: PathBuf,
    /// The `.fwt` file to write.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// Input feature set (required unless the file carries `frictionless.features` metadata).
    #[arg(long)]
    pub features: Option<Features>,
    /// The last input is the motor temperature [°C].
    #[arg(long)]
    pub temperature: bool,
    /// History length H (samples per block); inferred from the input width when omitted.
    #[arg(long)]
    pub history: Option<usize>,
    /// Joint name, e.g. l_ankle_roll.
    #[arg(long)]
    pub joint: Option<String>,
    /// Signed gear ratio r (motor angle per joint angle), e.g. -160.
    #[arg(long, allow_hyphen_values = true)]
    pub gear_ratio: Option<f64>,
    /// Torque constant k_t [Nm/A] the training labels used.
    #[arg(long)]
    pub kt: Option<f64>,
    /// Weight storage precision of the written file.
    #[arg(long, value_enum, default_value = "f32")]
    pub dtype: Dtype,
    /// Training range of the inputs: one `MIN:MAX` per feature block in input order, then one for
    /// the temperature with `--temperature`, in the inputs' units (e.g. `-0.05:0.05,-2:2`).
    /// Omitted: the file stores no range and frictiond never flags the model out of range.
    #[arg(long, allow_hyphen_values = true)]
    pub input_range: Option<String>,
}
