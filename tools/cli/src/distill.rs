//! Arguments of `frictl distill`.

use super::train::{HeldOut, Warmup};
use frictionless::mlp::StorageDtype;
use frictionless_train::data::DeltaThetaOffset;
use frictionless_train::distill::{self};
use std::path::PathBuf;

/// `--probe-kind`: how probes are drawn ([`distill::ProbeKind`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ProbeKindArg {
    /// Every input alone, uniform inside its range.
    Uniform,
    /// Each feature block the history of a smooth signal inside its range.
    Trajectory,
}

impl From<ProbeKindArg> for distill::ProbeKind {
    fn from(k: ProbeKindArg) -> Self {
        match k {
            ProbeKindArg::Uniform => distill::ProbeKind::Uniform,
            ProbeKindArg::Trajectory => distill::ProbeKind::Trajectory,
        }
    }
}

/// `--init`: where the student's training starts ([`distill::StudentInit`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StudentInitArg {
    /// A fresh random initialisation.
    Fresh,
    /// The teacher pruned to `--hidden` (same depth, each layer at most as wide), each following
    /// layer refitted by least squares to the teacher's values.
    Prune,
}

impl From<StudentInitArg> for distill::StudentInit {
    fn from(k: StudentInitArg) -> Self {
        match k {
            StudentInitArg::Fresh => distill::StudentInit::Fresh,
            StudentInitArg::Prune => distill::StudentInit::Prune,
        }
    }
}

/// Storage dtype of the student.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StudentDtype {
    /// IEEE binary32.
    F32,
    /// IEEE binary16.
    F16,
    /// bfloat16.
    Bf16,
    /// int8 hidden-layer weights per output channel (output layer f32).
    Int8,
    /// 14-bit fixed-point hidden-layer weights in int16 (output layer f32).
    Int16,
}

impl From<StudentDtype> for StorageDtype {
    fn from(d: StudentDtype) -> Self {
        match d {
            StudentDtype::F32 => StorageDtype::F32,
            StudentDtype::F16 => StorageDtype::F16,
            StudentDtype::Bf16 => StorageDtype::Bf16,
            StudentDtype::Int8 => StorageDtype::Int8,
            StudentDtype::Int16 => StorageDtype::Int16,
        }
    }
}

/// Arguments of `frictl distill`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The teacher model (.fwt).
    pub teacher: PathBuf,
    /// Preprocessed dataset CSV (repeatable; its `.json` sidecar must exist).
    #[arg(
        long = "dataset",
        required_unless_present = "probes_only",
        conflicts_with = "probes_only"
    )]
    pub datasets: Vec<PathBuf>,
    /// Distil without data: this many training probes inside the teacher's stored input range (and a
    /// quarter as many for validation and for the gate), gated by `--max-rmse-nm`.
    #[arg(long, value_name = "N", value_parser = crate::count::probes)]
    pub probes_only: Option<usize>,
    /// The gate of `--probes-only`: the student's output RMSE against the teacher on the gate probes
    /// must be ≤ this [Nm].
    #[arg(long, default_value_t = 0.02, requires = "probes_only")]
    pub max_rmse_nm: f64,
    /// The student model to write (.fwt); nothing is written when the gate fails.
    #[arg(short = 'o', long)]
    pub out: PathBuf,
    /// The student's hidden layer widths, comma separated.
    #[arg(long, value_delimiter = ',', default_values_t = [32usize, 32])]
    pub hidden: Vec<usize>,
    /// Storage dtype of the student.
    #[arg(long, value_enum, default_value_t = StudentDtype::F32)]
    pub dtype: StudentDtype,
    /// Epochs.
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Batch size.
    #[arg(long, default_value_t = 512)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 2e-3)]
    pub lr: f32,
    /// Weight λ of the SCV term of the loss (0 when the teacher has no SCV prior).
    #[arg(long, default_value_t = 0.01)]
    pub lambda: f32,
    /// Weight of the teacher's output in the target of the dataset rows, in [0, 1] (the label gets
    /// 1 minus it).
    #[arg(long, default_value_t = 0.5)]
    pub teacher_weight: f32,
    /// Probe inputs drawn inside the teacher's input range (default: a quarter of the training rows).
    #[arg(long, value_parser = crate::count::probes)]
    pub probes: Option<usize>,
    /// How probes are drawn inside the teacher's input range: `uniform` (each input alone) or
    /// `trajectory` (each feature block the history of a smooth signal, as the daemon feeds it;
    /// a probe-only gate then also reports the uniform figure).
    #[arg(long, value_enum, default_value_t = ProbeKindArg::Uniform)]
    pub probe_kind: ProbeKindArg,
    /// Decay the learning rate along a half cosine from --lr to this over the epochs (default:
    /// constant --lr).
    #[arg(long)]
    pub lr_final: Option<f32>,
    /// Where the student starts: `fresh` (random) or `prune` (the teacher's strongest units, the
    /// layers after them refitted to the teacher: keeps the teacher's function across its whole input
    /// range; needs the teacher's depth and widths no larger than its).
    #[arg(long, value_enum, default_value_t = StudentInitArg::Fresh)]
    pub init: StudentInitArg,
    /// The student's history length H: it reads the newest H samples of each of the teacher's
    /// feature blocks (default: the teacher's H; at most it). Fewer inputs, a smaller first layer.
    #[arg(long)]
    pub history: Option<usize>,
    /// Seed of the initialisation, shuffles and probes (and of the split with --test-frac).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The gate: the student's held-out RMSE, overall and per |ṡ| band, must be ≤ this × the teacher's.
    #[arg(long, default_value_t = 1.05)]
    pub max_rmse_ratio: f64,
    /// |ṡ| bands with fewer held-out rows are reported but not gated.
    #[arg(long, default_value_t = 100)]
    pub min_band_samples: usize,
    /// Fraction of chunks for validation (default: the teacher report's, else 0.15).
    #[arg(long)]
    pub val_frac: Option<f64>,
    /// Fraction of chunks held out for the gate (default: the teacher report's, else 0.15).
    #[arg(long)]
    pub test_frac: Option<f64>,
    /// Explicit test chunks, comma separated: CHUNK (first dataset) or DATASET:CHUNK.
    #[arg(long, value_delimiter = ',')]
    pub test_chunks: Option<Vec<String>>,
    /// Whole runs held out as the test set.
    #[command(flatten)]
    pub held_out: HeldOut,
    /// The teacher's training report (default: TEACHER with extension `.train.json`, if present).
    #[arg(long)]
    pub teacher_report: Option<PathBuf>,
    /// Warm-up policy (default: the teacher report's, else hold-zero).
    #[arg(long, value_enum)]
    pub warmup: Option<Warmup>,
    /// Where the Δθ offset is latched: `run`, `chunk` or a fixed θ_off (default: the teacher
    /// report's, else `run`).
    #[arg(long, allow_hyphen_values = true)]
    pub delta_theta_offset: Option<DeltaThetaOffset>,
    /// Trainer threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No per-epoch lines.
    #[arg(long)]
    pub quiet: bool,
}
