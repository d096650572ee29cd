//! Arguments of `frictl convert`.

pub use frictionless_train::distill::probe_inputs;
use std::path::PathBuf;

/// Target precision of `frictl convert`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// IEEE binary32.
    F32,
    /// IEEE binary16.
    F16,
    /// bfloat16.
    Bf16,
    /// int8 hidden-layer weights with per-output-channel scales (output layer f32).
    Int8,
    /// 14-bit fixed-point hidden-layer weights in int16 with per-output-channel scales, 15-bit
    /// activations (output layer f32).
    Int16,
    /// The smallest dtype within the bound: int8, then int16, f16, bf16, f32.
    Auto,
}

/// Arguments of `frictl convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The `.fwt` weight file to read.
    pub input: PathBuf,
    /// The `.fwt` file to write.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// Storage precision of the written file.
    #[arg(long, value_enum)]
    pub dtype: Target,
    /// Largest max |Δτ̂_F| [Nm] against the input model accepted on any kernel path.
    #[arg(long, default_value_t = 0.01)]
    pub max_error_nm: f32,
    /// A dataset CSV whose input rows are added to the probe set.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Number of random probe inputs (inside the training range).
    #[arg(long, default_value_t = 1000, value_parser = crate::count::probes)]
    pub samples: usize,
    /// Seed of the random probe inputs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}
