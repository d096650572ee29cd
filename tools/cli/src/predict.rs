//! Arguments of `frictl predict`.

use std::path::PathBuf;

/// Arguments of `frictl predict`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The model: `.fwt`, `.onnx` or `.safetensors` (chosen by extension).
    pub file: PathBuf,
    /// CSV file, one raw input vector per row, no header.
    #[arg(long)]
    pub input: PathBuf,
}
