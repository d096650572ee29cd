//! Arguments of `frictl train`.

use frictionless::features::{FeatureSet, WarmupPolicy};
use frictionless::mlp::StorageDtype;
use frictionless_train::data::{ChunkKey, DeltaThetaOffset};
use frictionless_train::pipeline::{self};
use std::path::PathBuf;

/// A feature set on the command line (`--features` of `train`, `search` and `import onnx`): the
/// core's [`FeatureSet`] with its hyphenated name; the underscore spelling is accepted as an alias
/// (hidden from the help). Names and help come from the core, so they exist once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Features(pub FeatureSet);

impl Features {
    /// The paper's `[Δθ ×H, ṡ ×H]`, the default of `train` and `search`.
    pub const DEFAULT: Features = Features(FeatureSet::DeltaThetaJointVel);
}

static FEATURE_VARIANTS: std::sync::LazyLock<Vec<Features>> =
    std::sync::LazyLock::new(|| FeatureSet::ALL.into_iter().map(Features).collect());

impl clap::ValueEnum for Features {
    fn value_variants<'a>() -> &'a [Self] {
        &FEATURE_VARIANTS
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        let set = self.0;
        Some(
            clap::builder::PossibleValue::new(set.name())
                .alias(set.underscore_alias())
                .help(set.description()),
        )
    }
}

impl From<Features> for FeatureSet {
    fn from(f: Features) -> Self {
        f.0
    }
}

/// Warm-up policy (which samples are training samples, and what the daemon does after enable).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Warmup {
    /// Only samples with H predecessors in their chunk (the daemon outputs 0 until then).
    HoldZero,
    /// Samples from the first of each chunk on, missing history zero-padded.
    ZeroPad,
}

impl From<Warmup> for WarmupPolicy {
    fn from(w: Warmup) -> Self {
        match w {
            Warmup::HoldZero => WarmupPolicy::HoldZero,
            Warmup::ZeroPad => WarmupPolicy::ZeroPad,
        }
    }
}

/// The motor encoder's kind (`--motor-encoder`), as frictiond's `[[joint]] motor_encoder`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MotorEncoder {
    /// The same zero at every power-up: Δθ latched as `--delta-theta-offset` says (default once per
    /// dataset), and frictiond is configured with the report's offset.
    Absolute,
    /// A new zero at every power-up: Δθ latched at every chunk start, as frictiond latches it at
    /// every enable (no offset to configure; `--delta-theta-offset` is refused).
    Incremental,
}

impl MotorEncoder {
    /// Where Δθ is latched for this encoder, given `--delta-theta-offset` (ignored when
    /// incremental: clap refuses both together).
    pub fn latch(self, given: DeltaThetaOffset) -> DeltaThetaOffset {
        match self {
            Self::Absolute => given,
            Self::Incremental => DeltaThetaOffset::Chunk,
        }
    }
}

/// Storage precision of the weights in the `.fwt`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Dtype {
    /// IEEE binary32.
    F32,
    /// IEEE binary16.
    F16,
    /// bfloat16.
    Bf16,
}

impl From<Dtype> for StorageDtype {
    fn from(d: Dtype) -> Self {
        match d {
            Dtype::F32 => StorageDtype::F32,
            Dtype::F16 => StorageDtype::F16,
            Dtype::Bf16 => StorageDtype::Bf16,
        }
    }
}

/// Arguments of `frictl train`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Preprocessed dataset CSV from `frictl preprocess` (repeatable; its `.json` sidecar must exist).
    #[arg(long = "dataset", required = true)]
    pub datasets: Vec<PathBuf>,
    /// Fitted static model, the JSON of `frictl fit scv|scv-code|cv --json` (the physics prior).
    #[arg(long)]
    pub scv: PathBuf,
    /// Output model file (.fwt).
    #[arg(long)]
    pub out: PathBuf,
    /// Input feature set.
    #[arg(long, value_enum, default_value_t = Features::DEFAULT)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub features: Features,
    /// History length H (samples per feature block; paper: 20–22; 30 was clearly better on the
    /// virtual knee, see the module doc).
    #[arg(long, default_value_t = 30)]
    pub history: usize,
    /// Append the motor temperature [°C] as one more input.
    #[arg(long)]
    pub temperature: bool,
    /// Hidden layer widths, comma separated (paper ankle roll: 268,215).
    #[arg(long, value_delimiter = ',', default_values_t = [128usize, 128])]
    pub hidden: Vec<usize>,
    /// Dropout probability after each hidden layer (paper: 0.07; it cost accuracy here, see the module doc).
    #[arg(long, default_value_t = 0.0)]
    pub dropout: f32,
    /// Epochs (paper: 350).
    #[arg(long, default_value_t = 10)]
    pub epochs: usize,
    /// Batch size (paper: 4316; 512 gives 8× the Adam steps per epoch, which is what a short run needs).
    #[arg(long, default_value_t = 512)]
    pub batch: usize,
    /// Adam learning rate (paper: 7.6e-4).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f32,
    /// Weight λ of the SCV term of the loss (paper: 0.164; the SCV term pulls stick predictions
    /// towards SCV's ≈ 0, see the module doc).
    #[arg(long, default_value_t = 0.01)]
    pub lambda: f32,
    /// Seed of the split, the initialisation, the shuffles and dropout.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fraction of chunks for validation.
    #[arg(long, default_value_t = 0.15)]
    pub val_frac: f64,
    /// Fraction of chunks for the held-out test set (ignored with --test-chunks).
    #[arg(long, default_value_t = 0.15)]
    pub test_frac: f64,
    /// Explicit test chunks, comma separated: CHUNK (first dataset) or DATASET:CHUNK.
    #[arg(long, value_delimiter = ',')]
    pub test_chunks: Option<Vec<String>>,
    /// Whole runs held out as the test set.
    #[command(flatten)]
    #[serde(flatten)]
    pub held_out: HeldOut,
    /// Warm-up policy.
    #[arg(long, value_enum, default_value_t = Warmup::HoldZero)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub warmup: Warmup,
    /// Where the Δθ offset is latched: `run` (once, at the first row of each dataset: the authors'
    /// convention; Δθ keeps the stiction wind-up across chunks), `chunk` (at every chunk start, as a
    /// daemon that re-latches at each enable), or a fixed θ_off in motor rad. Configure the daemon's
    /// `delta_theta_offset_motor_rad` with the value the report lists per dataset.
    #[arg(long, default_value = "run", allow_hyphen_values = true)]
    #[serde(serialize_with = "super::stage::as_display")]
    pub delta_theta_offset: DeltaThetaOffset,
    /// The motor encoder's kind: `absolute` (the same zero at every power-up) or `incremental` (a
    /// new zero at every power-up: Δθ is latched at every chunk start, as frictiond latches it at
    /// every enable, so the model needs no offset from this log; with `delta-theta-*` features this
    /// is what a robot with incremental motor encoders must use). Not with --delta-theta-offset.
    #[arg(long, value_enum, default_value_t = MotorEncoder::Absolute, conflicts_with = "delta_theta_offset")]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub motor_encoder: MotorEncoder,
    /// Storage dtype of the weights.
    #[arg(long, value_enum, default_value_t = Dtype::F32)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub dtype: Dtype,
    /// Checkpoint file (complete run state), written every --checkpoint-every epochs and at the end.
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Epochs between checkpoints.
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: usize,
    /// Continue the run saved in --checkpoint (same data and hyper-parameters; --epochs may grow).
    #[arg(long)]
    pub resume: bool,
    /// Continue from this model (`.fwt`): its weights are the starting point and its input
    /// normalisation is kept, the optimiser starts afresh (e.g. a DAgger round: the old model on the
    /// union of its data and new on-policy runs). It must have this run's features, history,
    /// temperature input and hidden widths; a different architecture is refused, naming both.
    #[arg(long, value_name = "MODEL.fwt", conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    /// Training report JSON (default: the model path with extension `.train.json`).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Stop after N epochs without a better validation RMSE.
    #[arg(long)]
    pub max_epochs_without_improvement: Option<usize>,
    /// Trainer threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar or summary.
    #[arg(long)]
    pub quiet: bool,
}

/// Whole runs held out as the test set (`frictl train` and `frictl search`); validation is then drawn
/// from the remaining (training) runs only.
#[derive(clap::Args, Debug, Default, Clone, serde::Serialize)]
pub struct HeldOut {
    /// Hold out a whole run as the test set (repeatable): a run name of a dataset's sidecar (`runs`),
    /// or the file stem of a dataset without runs. Adds to --test-chunks; --test-frac is then ignored.
    #[arg(long = "test-run", value_name = "NAME")]
    pub test_runs: Vec<String>,
    /// A dataset used only as test set (repeatable): loaded like --dataset, every chunk held out.
    #[arg(long = "test-dataset", value_name = "FILE")]
    pub test_datasets: Vec<PathBuf>,
}

impl HeldOut {
    /// `--dataset` files followed by the `--test-dataset` files (the order of the loaded sources).
    /// Refuses one file named twice (by device and inode, whatever the spelling): a repeated
    /// `--dataset` would count its rows twice, a `--test-dataset` that is also a `--dataset` would
    /// test on training rows. [`distinct_contents`] refuses copies once the files are read.
    pub fn all_datasets(&self, datasets: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
        use std::os::unix::fs::MetadataExt;
        let id = |p: &PathBuf| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
        let all: Vec<(&str, &PathBuf)> = datasets
            .iter()
            .map(|p| ("--dataset", p))
            .chain(self.test_datasets.iter().map(|p| ("--test-dataset", p)))
            .collect();
        for (k, (flag, p)) in all.iter().enumerate() {
            let Some(i) = id(p) else { continue };
            if let Some((first_flag, first)) = all[..k].iter().find(|(_, q)| id(q) == Some(i)) {
                anyhow::bail!("{}", twice(flag, p, first_flag, first));
            }
        }
        Ok(all.into_iter().map(|(_, p)| p.clone()).collect())
    }

    /// The test chunks: `--test-chunks` plus every chunk of the held-out runs and test datasets
    /// (`None` when none of the three is given). `n_train_datasets` = number of `--dataset` files.
    pub fn test_chunks(
        &self,
        sources: &pipeline::Sources,
        test_chunks: &Option<Vec<String>>,
        n_train_datasets: usize,
    ) -> anyhow::Result<Option<Vec<ChunkKey>>> {
        let explicit = parse_chunks(test_chunks)?;
        if self.test_runs.is_empty() && self.test_datasets.is_empty() {
            return Ok(explicit);
        }
        let test_ds: Vec<usize> = (n_train_datasets..sources.list.len()).collect();
        let mut keys = pipeline::held_out_chunks(sources, &self.test_runs, &test_ds)?;
        keys.extend(explicit.unwrap_or_default());
        keys.sort();
        keys.dedup();
        Ok(Some(keys))
    }
}

/// The message for a dataset given twice: `flag path` is `first_flag first`.
fn twice(flag: &str, path: &std::path::Path, first_flag: &str, first: &std::path::Path) -> String {
    let why = if flag == first_flag {
        "its rows would count twice"
    } else {
        "the held-out rows would be training rows"
    };
    format!(
        "{flag} {}: is the same data as {first_flag} {}; {why} (give each dataset once)",
        path.display(),
        first.display()
    )
}

/// Refuses two loaded datasets with the same content (SHA-256), e.g. a copy given as
/// `--test-dataset` of a `--dataset`; `n_train_datasets` = number of `--dataset` files (the rest are
/// `--test-dataset`s).
pub fn distinct_contents(
    sources: &pipeline::Sources,
    n_train_datasets: usize,
) -> anyhow::Result<()> {
    let flag = |k: usize| {
        if k < n_train_datasets {
            "--dataset"
        } else {
            "--test-dataset"
        }
    };
    for (k, s) in sources.list.iter().enumerate() {
        if let Some(j) = sources.list[..k].iter().position(|t| t.sha256 == s.sha256) {
            anyhow::bail!(
                "{}",
                twice(flag(k), &s.path, flag(j), &sources.list[j].path)
            );
        }
    }
    Ok(())
}

/// Number of cores available to this process (≥ 1).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Parses `--test-chunks` values.
pub fn parse_chunks(v: &Option<Vec<String>>) -> anyhow::Result<Option<Vec<ChunkKey>>> {
    v.as_ref()
        .map(|list| {
            list.iter()
                .map(|s| {
                    s.parse::<ChunkKey>()
                        .map_err(|e| anyhow::anyhow!("--test-chunks: {e}"))
                })
                .collect()
        })
        .transpose()
}
