//! Arguments of `frictl export`.

use std::path::PathBuf;

/// Target format.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// ONNX (Gemm/Relu chain, opset 13).
    Onnx,
    /// safetensors (PyTorch nn.Sequential state dict).
    Safetensors,
}

/// How the ONNX export writes the input normalisation.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Norm {
    /// Sub(mean) then Div(scale): the exact f32 statistics.
    SubDiv,
    /// One diagonal Gemm (w = 1/scale, b = −mean/scale), as the authors' exporter.
    DiagonalGemm,
}

/// Arguments of `frictl export`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Target format.
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub format: Format,
    /// The `.fwt` weight file.
    pub input: PathBuf,
    /// The file to write.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// ONNX only: how to write the normalisation.
    #[arg(long, value_enum, default_value = "sub-div")]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub norm: Norm,
}
