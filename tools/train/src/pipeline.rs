//! The training pipeline behind `frictl train` and `frictl search`: preprocessed datasets and a fitted
//! SCV prior in, a `.fwt` model and a JSON training report out.
//!
//! What it **is**: [`load_sources`] (dataset CSVs + sidecars, checked to agree on joint, signed r, k_t
//! and filtering), [`load_scv`] (the JSON of `frictl fit cv|scv|scv-code --json`), [`split_for`] (the
//! chunk split, independent of H so every search trial sees the same split), [`prepare`] (inputs via
//! [`super::data::build_inputs`], i.e. the daemon's `History`, and targets per set) and [`train_model`]
//! (the [`super::Trainer`] run with periodic checkpoints and resume, the [`ModelFile`] and the
//! [`TrainReport`]).
//!
//! What it is **not**: no argument parsing, no progress display, no printing (the `frictl` commands do
//! that through the epoch callback), and no new numerics (the trainer engine is [`super::Trainer`]).
//!
//! ## Provenance that the `.fwt` cannot hold
//! The `.fwt` header stores features, H, units, signed r, k_t, the SCV prior, one dataset SHA-256,
//! validation/test RMSE, time, tool and filtering. The split, seed and hyper-parameters go into the
//! [`TrainReport`] JSON written next to the model. With several datasets the `.fwt`'s `dataset_sha256`
//! is SHA-256 over the concatenated 32-byte SHA-256 digests of the dataset CSV files, in `--dataset`
//! order (one dataset: the digest of its CSV file itself). A code-form SCV prior (ka = ∞) is stored
//! with ka = `f64::MAX` ([`storable_scv`]), since the `.fwt` requires finite values. `created_unix_s` is `SOURCE_DATE_EPOCH`
//! when that environment variable is set (reproducible builds convention), else the current time.
//!
//! ## The report JSON (`--report`, schema `frictionless-train-report-v1`)
//! ```text
//! format            "frictionless-train-report-v1"
//! producer          "frictl <version>"
//! model             path of the .fwt written ("" if none)
//! joint, gear_ratio_signed, kt_nm_per_a, filtering ("causal" | "non_causal" | "unknown")
//! datasets[]        {path, sha256 (hex), samples, chunks, delta_theta_offset_motor_rad}
//! dataset_sha256    hex, as stored in the .fwt
//! scv               {path, model ("Cv" | "Scv" | "ScvCode"), params {kc, ka, kv, ks, vs, alpha} (paper form)}
//! features          {set (e.g. "joint-vel"), history, temperature};  n_inputs;  warmup ("hold_zero" | "zero_pad")
//! delta_theta_offset "run" | "chunk" | {"fixed": θ_off}: where Δθ was latched (see
//!                   `data::DeltaThetaOffset`); datasets[].delta_theta_offset_motor_rad is the value
//!                   (null per chunk, or when the set has no Δθ block) to configure in the daemon
//! config            {hidden[], dropout, lambda, lr, batch_size, epochs, seed, threads, patience, abort_loss}
//! dtype             "f32" | "f16" | "bf16"
//! split             {spec {val_frac, test_frac, seed, test_chunks}, train[], val[], test[] (each {dataset, chunk}),
//!                    train_samples, val_samples, test_samples, skipped_non_finite,
//!                    blocks[] {key {dataset, chunk}, chunk, start_row, end_row, gap_rows} when a
//!                    recording with too few chunks was cut into time blocks (see [`split_for`]):
//!                    the chunk ids of the sets are then the blocks' keys}
//! epochs[]          {epoch (1-based), train_loss (Nm², dropout on), val_loss (Nm², eval mode) | null,
//!                    val_rmse_nm | null, is_best, seconds}
//! best_epoch, stopped_early, resumed (bool), n_params
//! rmse_nm           {train, val | null, test | null}: the stored (dtype-rounded) model vs the label, Nm
//! scv_rmse_nm       {train, val | null, test | null}: the SCV prior alone vs the label, Nm
//! train_seconds     wall time of the training loop
//! training_range    {s_rad [min, max], sdot_rad_s [min, max], rows}: valid rows of the train and val
//!                   chunks (what `frictl eval` counts as inside the training range)
//! residual_reference {set ("val", or "train" without a validation set), band_edges_rad_s[],
//!                   temperature_bin_c, all STATS, bands[] {lo_rad_s, hi_rad_s | null, STATS…},
//!                   temperature[] {lo_c, hi_c, STATS…}} with STATS = {n, mean_residual_nm,
//!                   mean_along_motion_nm (residual·sign(ṡ)), rmse_nm}: the stored
//!                   model's residual (label − τ̂_F, Nm) per |ṡ| band (the default edges of
//!                   `frictionless_dataset::bands`) and per 5 °C bin — the reference of
//!                   `frictl eval --drift`; absent in older reports
//! ```
//! Losses are `(1 − λ)·MSE(label) + λ·MSE(SCV)` averaged over samples (true Nm², unlike the authors'
//! divide-by-last-batch-size figure).

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use frictionless::features::{FeatureSpec, WarmupPolicy};
use frictionless::friction::{ScvParams, StaticFriction};
use frictionless::mlp::{MlpWeights, StorageDtype};
use frictionless::units::GearRatio;
use frictionless::weights::{
    InputRange, ModelFile, ModelMeta, SignalFiltering, TrainingMeta, WeightError, round_to_dtype,
};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::data::{
    self, ChunkKey, DataError, DeltaThetaOffset, SetData, Split, SplitSpec, Windows,
};
use super::{EpochReport, PredictError, Predictor, TrainConfig, TrainError, Trainer, rmse};
use frictionless_dataset::bands::{
    DEFAULT_BAND_EDGES_RAD_S, DEFAULT_TEMPERATURE_BIN_C, ResidualProfile,
};
use frictionless_dataset::{Dataset, DatasetError, DatasetSidecar, MotionRange};

/// Report format tag.
pub const REPORT_FORMAT: &str = "frictionless-train-report-v1";

/// Why the pipeline failed. Every variant names the file, option or set involved.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A dataset CSV could not be read.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A file could not be read or written.
    #[error("{path}: {detail}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// Datasets disagree on a key that must be common.
    #[error("{key} differs between datasets: {first_value} in {first}, {other_value} in {other}")]
    Mismatch {
        /// Sidecar key.
        key: &'static str,
        /// First dataset.
        first: PathBuf,
        /// Its value.
        first_value: String,
        /// The disagreeing dataset.
        other: PathBuf,
        /// Its value.
        other_value: String,
    },
    /// Building inputs from a dataset failed.
    #[error("{path}: {source}")]
    Inputs {
        /// The dataset.
        path: PathBuf,
        /// Cause.
        #[source]
        source: DataError,
    },
    /// A dataset lacks a column the feature spec reads (absent, or not finite in valid rows).
    #[error("{path}: {source}")]
    InputColumn {
        /// The dataset.
        path: PathBuf,
        /// Which column, and which set needs it.
        #[source]
        source: frictionless_dataset::InputColumnError,
    },
    /// The split options are not usable.
    #[error("split: {0}")]
    Split(DataError),
    /// A set that must have samples has none.
    #[error("the {set} set (chunks {chunks}) has no samples: {why}")]
    EmptySet {
        /// "train", "val" or "test".
        set: &'static str,
        /// Its chunks, `D:C` listed.
        chunks: String,
        /// Likely cause.
        why: String,
    },
    /// A resumed run disagrees with the command line.
    #[error("--resume: checkpoint {path} has {key} = {checkpoint}, the command line says {given}")]
    Resume {
        /// Checkpoint file.
        path: PathBuf,
        /// The option.
        key: &'static str,
        /// Value in the checkpoint.
        checkpoint: String,
        /// Value requested.
        given: String,
    },
    /// `--resume` without `--checkpoint`, or similar.
    #[error("{0}")]
    Usage(String),
    /// The trainer failed.
    #[error(transparent)]
    Train(#[from] TrainError),
    /// Batched prediction failed.
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// The model could not be encoded or written.
    #[error(transparent)]
    Weights(#[from] WeightError),
}

fn file_err(path: &Path, detail: impl std::fmt::Display) -> PipelineError {
    PipelineError::File {
        path: path.to_path_buf(),
        detail: detail.to_string(),
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// One preprocessed dataset with its sidecar.
#[derive(Clone, Debug)]
pub struct Source {
    /// The CSV path as given.
    pub path: PathBuf,
    /// Its columns.
    pub data: Dataset,
    /// Its sidecar (`<csv>.json` → same path with extension `json`).
    pub sidecar: DatasetSidecar,
    /// SHA-256 of the CSV file bytes.
    pub sha256: [u8; 32],
}

/// Every dataset of a run and what they have in common.
#[derive(Clone, Debug)]
pub struct Sources {
    /// The datasets, in `--dataset` order (their index is [`ChunkKey::dataset`]).
    pub list: Vec<Source>,
    /// Joint name (from the sidecars).
    pub joint: String,
    /// Signed gear ratio.
    pub gear_ratio: GearRatio,
    /// Torque constant of the labels [Nm/A].
    pub kt_nm_per_a: f64,
    /// Causal or zero-phase processing (sidecar `settings.causal`).
    pub filtering: SignalFiltering,
    /// The `.fwt` dataset hash (see the module doc).
    pub dataset_sha256: [u8; 32],
}

fn filtering_of(side: &DatasetSidecar) -> SignalFiltering {
    match side.settings.get("causal").and_then(|v| v.as_bool()) {
        Some(true) => SignalFiltering::Causal,
        Some(false) => SignalFiltering::NonCausal,
        None => SignalFiltering::Unknown,
    }
}

/// Reads the datasets and their sidecars and checks that they agree.
pub fn load_sources(paths: &[PathBuf]) -> Result<Sources, PipelineError> {
    if paths.is_empty() {
        return Err(PipelineError::Usage("no --dataset given".into()));
    }
    let list = paths
        .iter()
        .map(|p| load_source(p))
        .collect::<Result<Vec<_>, _>>()?;
    let first = &list[0];
    check_sources_agree(&list)?;
    let side_path = first.path.with_extension("json");
    let gear_ratio = GearRatio::new(first.sidecar.gear_ratio_signed).map_err(|e| {
        file_err(
            &side_path,
            format!(
                "gear_ratio_signed = {}: {e}",
                first.sidecar.gear_ratio_signed
            ),
        )
    })?;
    let kt = first.sidecar.kt_nm_per_a;
    if !(kt.is_finite() && kt > 0.0) {
        return Err(file_err(
            &side_path,
            format!("kt_nm_per_a = {kt}: must be finite and positive"),
        ));
    }
    let dataset_sha256 = if list.len() == 1 {
        list[0].sha256
    } else {
        let mut h = Sha256::new();
        for s in &list {
            h.update(s.sha256);
        }
        h.finalize().into()
    };
    Ok(Sources {
        joint: first.sidecar.joint.clone(),
        gear_ratio,
        kt_nm_per_a: kt,
        filtering: filtering_of(&first.sidecar),
        dataset_sha256,
        list,
    })
}

/// Reads one dataset, its hash and its sidecar (beside it, `.json`); an empty dataset is an error.
fn load_source(path: &Path) -> Result<Source, PipelineError> {
    let sha256 = frictionless_dataset::file_sha256(path)
        .map_err(|e| file_err(path, format!("cannot read: {e}")))?;
    let data = Dataset::read_csv(path)?;
    let side_path = path.with_extension("json");
    let text = frictionless::regular_file::read_text(&side_path).map_err(|e| {
        file_err(
            &side_path,
            format!(
                "cannot read the sidecar of {} (written by `frictl preprocess`): {e}",
                path.display()
            ),
        )
    })?;
    let sidecar: DatasetSidecar =
        serde_json::from_str(&text).map_err(|e| file_err(&side_path, e))?;
    if data.is_empty() {
        return Err(file_err(path, "the dataset has no rows"));
    }
    Ok(Source {
        path: path.to_path_buf(),
        data,
        sidecar,
        sha256,
    })
}

/// Checks that every dataset's sidecar has the first's joint, gear ratio, kt and filtering.
fn check_sources_agree(list: &[Source]) -> Result<(), PipelineError> {
    let first = &list[0];
    for other in &list[1..] {
        let mismatch = |key, a: String, b: String| PipelineError::Mismatch {
            key,
            first: first.path.clone(),
            first_value: a,
            other: other.path.clone(),
            other_value: b,
        };
        let (a, b) = (&first.sidecar, &other.sidecar);
        if a.joint != b.joint {
            return Err(mismatch("joint", a.joint.clone(), b.joint.clone()));
        }
        if a.gear_ratio_signed != b.gear_ratio_signed {
            return Err(mismatch(
                "gear_ratio_signed",
                a.gear_ratio_signed.to_string(),
                b.gear_ratio_signed.to_string(),
            ));
        }
        if a.kt_nm_per_a != b.kt_nm_per_a {
            return Err(mismatch(
                "kt_nm_per_a",
                a.kt_nm_per_a.to_string(),
                b.kt_nm_per_a.to_string(),
            ));
        }
        if filtering_of(a) != filtering_of(b) {
            return Err(mismatch(
                "settings.causal",
                format!("{:?}", filtering_of(a)),
                format!("{:?}", filtering_of(b)),
            ));
        }
    }
    Ok(())
}

/// The SCV prior of the physics loss, from `frictl fit … --json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScvPrior {
    /// The JSON file.
    pub path: PathBuf,
    /// The fitted model as named in the JSON (`Cv`, `Scv`, `ScvCode`).
    pub model: String,
    /// The prior in paper form (CV: ks = kc, so the Stribeck term vanishes; code form: ka = ∞, α = 2).
    pub params: ScvParams,
}

/// Reads the JSON written by `frictl fit cv|scv|scv-code --json`
/// ([`frictionless_dataset::fit_file::FittedModel`]) as an SCV prior ([`FittedModel::to_scv`]).
///
/// [`FittedModel::to_scv`]: frictionless_dataset::fit_file::FittedModel::to_scv
pub fn load_scv(path: &Path) -> Result<ScvPrior, PipelineError> {
    use frictionless_dataset::fit_file::{FitFileError, FittedModel};
    let fitted = FittedModel::read(path).map_err(|e| match e {
        FitFileError::Read { source, .. } => file_err(path, format!("cannot read: {source}")),
        FitFileError::Parse { message, .. } => file_err(
            path,
            format!(
                "not a fit of `frictl fit --json` (keys `model` = {} and `params`): {message}",
                frictionless_dataset::fit_file::fit_tags()
            ),
        ),
    })?;
    let scv = fitted.to_scv();
    scv.validate().map_err(|e| {
        file_err(
            path,
            format!("key `params` for model {:?}: {e}", fitted.tag()),
        )
    })?;
    Ok(ScvPrior {
        path: path.to_path_buf(),
        model: fitted.tag().to_owned(),
        params: scv,
    })
}

/// Every chunk with at least one valid row, over all datasets (independent of H and warm-up).
pub fn chunks_with_valid_rows(sources: &Sources) -> Vec<ChunkKey> {
    let mut keys: Vec<ChunkKey> = sources
        .list
        .iter()
        .enumerate()
        .flat_map(|(d, s)| {
            s.data
                .chunk
                .iter()
                .zip(&s.data.valid)
                .filter(|(_, v)| **v)
                .map(move |(&chunk, _)| ChunkKey {
                    dataset: d as u32,
                    chunk,
                })
        })
        .collect();
    keys.sort();
    keys.dedup();
    keys
}

/// The chunk split for these datasets (the same for every H, so search trials are comparable).
///
/// When the datasets' own chunks are too few for the requested sets (one long recording is one
/// chunk), the chunks that are not explicit test chunks are cut into contiguous time blocks
/// ([`data::cut_chunk`]: [`data::BLOCKS_PER_SPLIT`] in all, a gap of [`data::BLOCK_GAP_ROWS`] rows
/// before each but the first of a chunk) and the blocks are split like chunks; the blocks are in
/// [`Split::blocks`], and [`prepare`] and [`training_range`] read the datasets through them
/// ([`blocked`]). A held-out `--test-dataset` is the test set as it is: no test fraction is
/// carved out of the training recordings then.
pub fn split_for(sources: &Sources, spec: &SplitSpec) -> Result<Split, PipelineError> {
    let mut spec = spec.clone();
    if let Some(t) = &mut spec.test_chunks
        && sources.list.len() > 1
        && let Some(k) = t.iter().find(|k| k.dataset as usize >= sources.list.len())
    {
        return Err(PipelineError::Split(DataError::Split {
            key: "--test-chunks",
            value: k.to_string(),
            reason: format!("there are only {} datasets", sources.list.len()),
        }));
    }
    let chunks = chunks_with_valid_rows(sources);
    if chunks.is_empty() {
        // Not a split problem: there is nothing to split (blaming --val-frac would mislead).
        let per: Vec<String> = sources
            .list
            .iter()
            .map(|s| format!("{}: {} rows, 0 valid", s.path.display(), s.data.len()))
            .collect();
        return Err(PipelineError::File {
            path: sources
                .list
                .first()
                .map(|s| s.path.clone())
                .unwrap_or_default(),
            detail: format!(
                "0 valid rows in every dataset, nothing to train on ({}); a row is invalid when it is outside a chunk long enough to filter, at rest, or has a non-finite value (see the sidecar's import report)",
                per.join("; ")
            ),
        });
    }
    let hint = "; use --val-frac 0 (no validation) and --test-frac 0 (no test set), hold out another \
                recording with --test-dataset, or give a longer recording (a recording with too few \
                chunks is cut into time blocks of at least";
    let too_few = match data::split_chunks(&chunks, &spec) {
        Err(e @ DataError::NoTrainingChunk { .. }) => e,
        other => return other.map_err(PipelineError::Split),
    };
    let held: Vec<ChunkKey> = spec.test_chunks.clone().unwrap_or_default();
    let rest: Vec<ChunkKey> = chunks
        .iter()
        .copied()
        .filter(|k| !held.contains(k))
        .collect();
    let per_chunk = data::BLOCKS_PER_SPLIT.div_ceil(rest.len().max(1));
    let mut blocks = Vec::new();
    for (d, s) in sources.list.iter().enumerate() {
        let mut next_id = s.data.chunk.iter().copied().max().map_or(0, |m| m + 1);
        for k in rest.iter().filter(|k| k.dataset as usize == d) {
            // As many blocks as fit (at least MIN_BLOCK_ROWS each), at most `per_chunk`.
            let n_rows = s.data.chunk.iter().filter(|&&c| c == k.chunk).count();
            let n = per_chunk.min(n_rows / (data::MIN_BLOCK_ROWS + data::BLOCK_GAP_ROWS));
            let cut = data::cut_chunk(&s.data, k.dataset, k.chunk, n, next_id);
            next_id += cut.len() as u32;
            blocks.extend(cut);
        }
    }
    let rows_hint = |e: DataError| match e {
        DataError::NoTrainingChunk {
            val_frac,
            test,
            val,
            n,
            ..
        } => DataError::NoTrainingChunk {
            val_frac,
            test,
            val,
            n,
            hint: format!(
                "{hint} {} rows each, {} rows apart)",
                data::MIN_BLOCK_ROWS,
                data::BLOCK_GAP_ROWS
            ),
        },
        e => e,
    };
    if blocks.is_empty() {
        return Err(PipelineError::Split(rows_hint(too_few)));
    }
    let cut = blocked(sources, &blocks);
    let keys = chunks_with_valid_rows(&cut);
    let mut split = data::split_chunks(&keys, &spec)
        .map_err(rows_hint)
        .map_err(PipelineError::Split)?;
    split.blocks = blocks;
    Ok(split)
}

/// The datasets as the split sees them: each dataset with its [`Split::blocks`] as chunks of their
/// own ([`data::with_blocks`]); borrowed unchanged when there are no blocks.
pub fn blocked<'a>(sources: &'a Sources, blocks: &[data::Block]) -> std::borrow::Cow<'a, Sources> {
    if blocks.is_empty() {
        return std::borrow::Cow::Borrowed(sources);
    }
    let mut out = sources.clone();
    for (d, s) in out.list.iter_mut().enumerate() {
        if blocks.iter().any(|b| b.key.dataset as usize == d) {
            s.data = data::with_blocks(&s.data, d as u32, blocks);
        }
    }
    std::borrow::Cow::Owned(out)
}

/// The chunks (with valid rows) of whole runs held out as the test set: every run named in `test_runs`
/// (matched against each dataset's runs, [`frictionless_dataset::dataset_runs`]: the sidecar's `runs`,
/// or one run named by the file stem) and every chunk of the datasets at indices `test_datasets`.
/// Errors when a name matches no run, or a held-out run has no valid row.
pub fn held_out_chunks(
    sources: &Sources,
    test_runs: &[String],
    test_datasets: &[usize],
) -> Result<Vec<ChunkKey>, PipelineError> {
    let with_rows = chunks_with_valid_rows(sources);
    let mut out = Vec::new();
    let mut known = Vec::new();
    for name in test_runs {
        let mut found = false;
        for (d, s) in sources.list.iter().enumerate() {
            for run in frictionless_dataset::dataset_runs(&s.path, Some(&s.sidecar), &s.data) {
                if &run.name == name {
                    found = true;
                    let before = out.len();
                    out.extend(
                        run.chunks
                            .iter()
                            .map(|&chunk| ChunkKey {
                                dataset: d as u32,
                                chunk,
                            })
                            .filter(|k| with_rows.contains(k)),
                    );
                    if out.len() == before {
                        return Err(PipelineError::Split(DataError::Split {
                            key: "--test-run",
                            value: name.clone(),
                            reason: format!("run {name} of {} has no valid row", s.path.display()),
                        }));
                    }
                }
                if !known.contains(&run.name) {
                    known.push(run.name);
                }
            }
        }
        if !found {
            return Err(PipelineError::Split(DataError::Split {
                key: "--test-run",
                value: name.clone(),
                reason: format!(
                    "no dataset has a run of that name (runs: {})",
                    known.join(", ")
                ),
            }));
        }
    }
    for &d in test_datasets {
        out.extend(with_rows.iter().filter(|k| k.dataset as usize == d));
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// The range of s and ṡ over the valid rows of the training and validation chunks: what the model saw.
pub fn training_range(sources: &Sources, split: &Split) -> MotionRange {
    let sources = blocked(sources, &split.blocks);
    let mut r = MotionRange::default();
    for (d, s) in sources.list.iter().enumerate() {
        let chunks: Vec<u32> = split
            .train
            .iter()
            .chain(&split.val)
            .filter(|k| k.dataset as usize == d)
            .map(|k| k.chunk)
            .collect();
        r.merge(&MotionRange::of_chunks(&s.data, &chunks));
    }
    r
}

/// Inputs and targets of the three sets.
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// Training set.
    pub train: SetData,
    /// Validation set (empty without validation chunks).
    pub val: SetData,
    /// Test set (empty without test chunks).
    pub test: SetData,
    /// Valid rows skipped for non-finite inputs, over all datasets.
    pub skipped_non_finite: usize,
}

fn list_chunks(c: &[ChunkKey]) -> String {
    let v: Vec<String> = c.iter().map(|k| k.to_string()).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(",")
    }
}

/// Refuses a dataset that lacks a column `spec` reads: listed in its sidecar's `absent_columns`, or
/// not finite in a valid row ([`frictionless_dataset::Dataset::check_inputs`]). Columns the spec
/// does not read may be NaN throughout (a torque-sensed arm has no motor angle or current).
pub fn check_inputs(sources: &Sources, spec: &FeatureSpec) -> Result<(), PipelineError> {
    for s in &sources.list {
        s.data
            .check_inputs(spec, &s.sidecar.absent_columns)
            .map_err(|source| PipelineError::InputColumn {
                path: s.path.clone(),
                source,
            })?;
    }
    Ok(())
}

/// Builds the inputs of every dataset through the daemon's `History` and gathers the three sets.
/// Errors if the training set, or a validation/test set with chunks, has no samples.
pub fn prepare(
    sources: &Sources,
    scv: &ScvPrior,
    split: &Split,
    spec: &FeatureSpec,
    warmup: WarmupPolicy,
    offset: DeltaThetaOffset,
) -> Result<Prepared, PipelineError> {
    check_inputs(sources, spec)?;
    let sources = &*blocked(sources, &split.blocks);
    let windows: Vec<Windows> = sources
        .list
        .iter()
        .map(|s| {
            data::build_inputs(&s.data, spec, sources.gear_ratio, warmup, offset).map_err(
                |source| PipelineError::Inputs {
                    path: s.path.clone(),
                    source,
                },
            )
        })
        .collect::<Result<_, _>>()?;
    let pairs: Vec<(&Dataset, &Windows)> =
        sources.list.iter().map(|s| &s.data).zip(&windows).collect();
    let skipped_non_finite = windows.iter().map(|w| w.skipped_non_finite).sum();
    let p = Prepared {
        train: data::select(&pairs, &split.train, &scv.params),
        val: data::select(&pairs, &split.val, &scv.params),
        test: data::select(&pairs, &split.test, &scv.params),
        skipped_non_finite,
    };
    for (set, name) in [(&p.train, "train"), (&p.val, "val"), (&p.test, "test")] {
        let chunks = match name {
            "train" => &split.train,
            "val" => &split.val,
            _ => &split.test,
        };
        if set.is_empty() && (name == "train" || !chunks.is_empty()) {
            return Err(PipelineError::EmptySet {
                set: name,
                chunks: list_chunks(chunks),
                why: format!(
                    "no valid row has a full window under --warmup {} with H = {}{}",
                    serde_json::to_value(warmup)
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_owned))
                        .unwrap_or_default(),
                    spec.history,
                    if skipped_non_finite > 0 {
                        format!(
                            " ({skipped_non_finite} rows had non-finite inputs, e.g. NaN temperature)"
                        )
                    } else {
                        String::new()
                    }
                ),
            });
        }
    }
    Ok(p)
}

/// What to train and how to checkpoint.
#[derive(Clone, Debug)]
pub struct Job {
    /// Inputs.
    pub spec: FeatureSpec,
    /// Warm-up policy (training samples and the daemon's behaviour at enable).
    pub warmup: WarmupPolicy,
    /// Where the Δθ offset was latched when the inputs were built (recorded in the report).
    pub delta_theta_offset: DeltaThetaOffset,
    /// Hyper-parameters.
    pub config: TrainConfig,
    /// Storage precision of the `.fwt`.
    pub dtype: StorageDtype,
    /// Checkpoint file (written every `checkpoint_every` epochs and at the end).
    pub checkpoint: Option<PathBuf>,
    /// Epochs between checkpoints (≥ 1).
    pub checkpoint_every: usize,
    /// Continue from `checkpoint` instead of starting afresh.
    pub resume: bool,
    /// Start from these weights and keep their normalisation ([`Trainer::from_init`]) instead of
    /// a fresh initialisation (`frictl train --init MODEL.fwt`; not with `resume`).
    pub init: Option<MlpWeights>,
}

/// RMSE per set \[Nm\] (`None` for an empty set).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetMetrics {
    /// Training set.
    pub train: Option<f64>,
    /// Validation set.
    pub val: Option<f64>,
    /// Test set.
    pub test: Option<f64>,
}

/// One dataset in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// Path as given.
    pub path: String,
    /// SHA-256 of the CSV (hex).
    pub sha256: String,
    /// Rows.
    pub samples: usize,
    /// Sidecar `chunks`.
    pub chunks: usize,
    /// The Δθ offset θ_off \[motor rad\] the inputs of this dataset were built with (`None` when
    /// latched per chunk, or when the feature set has no Δθ block): the value for the daemon's
    /// `delta_theta_offset_motor_rad`.
    #[serde(default)]
    pub delta_theta_offset_motor_rad: Option<f64>,
}

/// The split in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SplitReport {
    /// How it was chosen.
    pub spec: SplitSpec,
    /// Training chunks.
    pub train: Vec<ChunkKey>,
    /// Validation chunks.
    pub val: Vec<ChunkKey>,
    /// Test chunks.
    pub test: Vec<ChunkKey>,
    /// Samples per set.
    pub train_samples: usize,
    /// Samples per set.
    pub val_samples: usize,
    /// Samples per set.
    pub test_samples: usize,
    /// Valid rows skipped for non-finite inputs.
    pub skipped_non_finite: usize,
    /// The time blocks chunks were cut into ([`Split::blocks`]; absent when the split is by chunks).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blocks: Vec<data::Block>,
}

/// The SCV prior in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScvInfo {
    /// The JSON it came from.
    pub path: String,
    /// Model name in that JSON.
    pub model: String,
    /// Paper-form parameters.
    pub params: ScvParams,
}

/// The training report (schema in the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// [`REPORT_FORMAT`].
    pub format: String,
    /// `frictl <version>`.
    pub producer: String,
    /// The `.fwt` written.
    pub model: String,
    /// Joint name.
    pub joint: String,
    /// Signed gear ratio.
    pub gear_ratio_signed: f64,
    /// Torque constant [Nm/A].
    pub kt_nm_per_a: f64,
    /// Causal or zero-phase training signals.
    pub filtering: SignalFiltering,
    /// The datasets.
    pub datasets: Vec<DatasetInfo>,
    /// Hash stored in the `.fwt` (hex).
    pub dataset_sha256: String,
    /// SCV prior.
    pub scv: ScvInfo,
    /// Feature spec.
    pub features: FeatureSpec,
    /// Inputs per sample.
    pub n_inputs: usize,
    /// Warm-up policy.
    pub warmup: WarmupPolicy,
    /// Where the Δθ offset was latched (`run`, `chunk` or `{"fixed": θ_off}`).
    #[serde(default = "chunk_latch")]
    pub delta_theta_offset: DeltaThetaOffset,
    /// Hyper-parameters.
    pub config: TrainConfig,
    /// Storage dtype.
    pub dtype: StorageDtype,
    /// The split.
    pub split: SplitReport,
    /// Per-epoch losses.
    pub epochs: Vec<EpochReport>,
    /// Epoch of the stored weights.
    pub best_epoch: usize,
    /// Whether early stopping ended the run.
    pub stopped_early: bool,
    /// Whether the run was resumed from a checkpoint.
    pub resumed: bool,
    /// Network parameters.
    pub n_params: usize,
    /// The stored model's RMSE per set \[Nm\].
    pub rmse_nm: SetMetrics,
    /// The SCV prior's RMSE per set \[Nm\].
    pub scv_rmse_nm: SetMetrics,
    /// Training wall time \[s\].
    pub train_seconds: f64,
    /// Range of s and ṡ over the valid rows of the training and validation chunks (`frictl eval`
    /// flags rows outside it as extrapolation); absent in older reports.
    #[serde(default)]
    pub training_range: Option<MotionRange>,
    /// The stored model's residuals per |ṡ| band and temperature bin on the validation set (the
    /// training set without one): the reference of `frictl eval --drift`; absent in older reports.
    #[serde(default)]
    pub residual_reference: Option<ResidualReference>,
}

impl TrainReport {
    /// The Δθ offset frictiond keeps for this PINN (`[[joint]] delta_theta_offset_motor_rad`): the one
    /// its training latched when every dataset was latched with the same value, `None` (frictiond
    /// latches at enable) when training latched per chunk. Datasets latched with different offsets
    /// are an error: frictiond takes one.
    pub fn deployed_offset_rad(&self) -> Result<Option<f64>, String> {
        let offsets: Vec<Option<f64>> = self
            .datasets
            .iter()
            .map(|d| d.delta_theta_offset_motor_rad)
            .collect();
        match offsets.first() {
            Some(Some(v)) if offsets.iter().all(|o| *o == Some(*v)) => Ok(Some(*v)),
            Some(Some(_)) => Err(format!(
                "the datasets were latched with different Δθ offsets ({offsets:?}); frictiond takes one"
            )),
            _ => Ok(None),
        }
    }
}

/// The residual profile a model had at training time (`residual_reference` in the report).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualReference {
    /// `"val"`, or `"train"` when there is no validation set (in-sample: an optimistic reference).
    pub set: String,
    /// The profile (default band edges, default temperature bin width).
    #[serde(flatten)]
    pub profile: ResidualProfile,
}

/// A trained model and its report.
#[derive(Clone, Debug)]
pub struct Trained {
    /// The model, ready for `frictionless::weights::write_file`.
    pub model: ModelFile,
    /// The report (`model` field empty until [`write_outputs`]).
    pub report: TrainReport,
}

/// Reports written before the option existed latched Δθ at every chunk start.
fn chunk_latch() -> DeltaThetaOffset {
    DeltaThetaOffset::Chunk
}

/// The prior as the `.fwt` can store it: the file requires finite values, so the code form's
/// ka = ∞ (sign(v)) is stored as `f64::MAX`, for which tanh(ka·v) = sign(v) for every normal v
/// (ka·v overflows to ±∞, and tanh(0) = 0 = sign(0)).
pub fn storable_scv(p: ScvParams) -> ScvParams {
    ScvParams {
        ka: if p.ka.is_infinite() { f64::MAX } else { p.ka },
        ..p
    }
}

/// `SOURCE_DATE_EPOCH` if set and valid, else now (seconds since the Unix epoch).
pub fn created_unix_s() -> u64 {
    std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs())
        })
}

fn check_resume(path: &Path, have: &TrainConfig, want: &TrainConfig) -> Result<(), PipelineError> {
    let diff = |key, a: String, b: String| {
        if a == b {
            Ok(())
        } else {
            Err(PipelineError::Resume {
                path: path.to_path_buf(),
                key,
                checkpoint: a,
                given: b,
            })
        }
    };
    diff(
        "--hidden",
        format!("{:?}", have.hidden),
        format!("{:?}", want.hidden),
    )?;
    diff(
        "--dropout",
        have.dropout.to_string(),
        want.dropout.to_string(),
    )?;
    diff("--lambda", have.lambda.to_string(), want.lambda.to_string())?;
    diff("--lr", have.lr.to_string(), want.lr.to_string())?;
    diff(
        "--batch",
        have.batch_size.to_string(),
        want.batch_size.to_string(),
    )?;
    diff("--seed", have.seed.to_string(), want.seed.to_string())?;
    diff(
        "--max-epochs-without-improvement",
        format!("{:?}", have.patience),
        format!("{:?}", want.patience),
    )
}

fn set_rmse(
    pred: &mut Predictor,
    set: &SetData,
) -> Result<(Option<f64>, Option<f64>), PipelineError> {
    if set.is_empty() {
        return Ok((None, None));
    }
    let y = pred.predict(&set.x)?;
    Ok((
        Some(rmse(&y, &set.y_label_nm)),
        Some(rmse(&set.y_scv_nm, &set.y_label_nm)),
    ))
}

/// The residual profile of `pred` on `set` (rows mapped back to `sources` for ṡ and T).
fn residual_reference(
    pred: &mut Predictor,
    sources: &Sources,
    set: &SetData,
    name: &str,
) -> Result<Option<ResidualReference>, PipelineError> {
    if set.is_empty() {
        return Ok(None);
    }
    let y = pred.predict(&set.x)?;
    let rows = set
        .rows
        .iter()
        .zip(&y)
        .zip(&set.y_label_nm)
        .map(|((&(d, k), &p), &l)| {
            let ds = &sources.list[d as usize].data;
            (
                ds.sdot_rad_s[k],
                ds.temperature_c[k],
                f64::from(l) - f64::from(p),
            )
        });
    Ok(Some(ResidualReference {
        set: name.into(),
        profile: ResidualProfile::from_rows(
            rows,
            &DEFAULT_BAND_EDGES_RAD_S,
            DEFAULT_TEMPERATURE_BIN_C,
        ),
    }))
}

/// Trains one model on prepared sets: new run or `--resume`, checkpoints every
/// `job.checkpoint_every` epochs and at the end, best-on-validation weights rounded to `job.dtype`,
/// RMSEs of the stored model on every set. `on_epoch` sees every epoch (return `Break` to stop early;
/// the model is then built from the best weights so far).
pub fn train_model(
    sources: &Sources,
    scv: &ScvPrior,
    split: &Split,
    split_spec: &SplitSpec,
    prepared: &Prepared,
    job: &Job,
    mut on_epoch: impl FnMut(&EpochReport) -> ControlFlow<()>,
) -> Result<Trained, PipelineError> {
    let train = prepared.train.view();
    let val_view = prepared.val.view();
    let val = (!prepared.val.is_empty()).then_some(&val_view);
    let mut trainer = start_trainer(job, &train, val)?;
    let started = Instant::now();
    let outcome = train_checkpointed(&mut trainer, job, &mut on_epoch)?;
    let train_seconds = started.elapsed().as_secs_f64();
    let weights = round_to_dtype(&outcome.weights, job.dtype);
    let mut pred = Predictor::new(&weights, job.config.threads)?;
    let (tr, tr_scv) = set_rmse(&mut pred, &prepared.train)?;
    let (va, va_scv) = set_rmse(&mut pred, &prepared.val)?;
    let (te, te_scv) = set_rmse(&mut pred, &prepared.test)?;
    let residual_reference = match residual_reference(&mut pred, sources, &prepared.val, "val")? {
        Some(r) => Some(r),
        None => residual_reference(&mut pred, sources, &prepared.train, "train")?,
    };
    let model = stored_model(sources, scv, prepared, job, weights, va, te);
    let n_params = model
        .mlp
        .layers
        .iter()
        .map(|l| l.weight.len() + l.bias.len())
        .sum();
    let report = TrainReport {
        format: REPORT_FORMAT.into(),
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        model: String::new(),
        joint: sources.joint.clone(),
        gear_ratio_signed: sources.gear_ratio.get(),
        kt_nm_per_a: sources.kt_nm_per_a,
        filtering: sources.filtering,
        datasets: datasets_info(sources, job),
        dataset_sha256: hex(&sources.dataset_sha256),
        scv: ScvInfo {
            path: scv.path.display().to_string(),
            model: scv.model.clone(),
            params: scv.params,
        },
        features: job.spec,
        n_inputs: job.spec.n_inputs(),
        warmup: job.warmup,
        delta_theta_offset: job.delta_theta_offset,
        config: trainer.config().clone(),
        dtype: job.dtype,
        split: SplitReport {
            spec: split_spec.clone(),
            train: split.train.clone(),
            val: split.val.clone(),
            test: split.test.clone(),
            train_samples: prepared.train.len(),
            val_samples: prepared.val.len(),
            test_samples: prepared.test.len(),
            skipped_non_finite: prepared.skipped_non_finite,
            blocks: split.blocks.clone(),
        },
        epochs: outcome.history.clone(),
        best_epoch: outcome.best_epoch,
        stopped_early: outcome.stopped_early,
        resumed: job.resume,
        n_params,
        rmse_nm: SetMetrics {
            train: tr,
            val: va,
            test: te,
        },
        scv_rmse_nm: SetMetrics {
            train: tr_scv,
            val: va_scv,
            test: te_scv,
        },
        train_seconds,
        training_range: Some(training_range(sources, split)),
        residual_reference,
    };
    Ok(Trained { model, report })
}

/// The trainer of `job`: resumed from its checkpoint (`--resume`), started from a model
/// (`--init`) or new.
fn start_trainer(
    job: &Job,
    train: &super::Dataset<'_>,
    val: Option<&super::Dataset<'_>>,
) -> Result<Trainer, PipelineError> {
    if job.resume && job.init.is_some() {
        return Err(PipelineError::Usage(
            "--resume continues a checkpointed run; --init starts a new run from a model: give one"
                .into(),
        ));
    }
    Ok(if job.resume {
        let path = job
            .checkpoint
            .as_deref()
            .ok_or_else(|| PipelineError::Usage("--resume needs --checkpoint FILE".into()))?;
        let mut t = Trainer::resume(path, train, val)?;
        check_resume(path, t.config(), &job.config)?;
        t.set_epochs(job.config.epochs);
        t
    } else if let Some(init) = &job.init {
        Trainer::from_init(job.config.clone(), init, train, val)?
    } else {
        Trainer::new(job.config.clone(), train, val)?
    })
}

/// Trains to the end (or until `on_epoch` breaks), saving a checkpoint every
/// `job.checkpoint_every` epochs and at the end when `job.checkpoint` is set.
fn train_checkpointed(
    trainer: &mut Trainer,
    job: &Job,
    on_epoch: &mut impl FnMut(&EpochReport) -> ControlFlow<()>,
) -> Result<super::TrainOutcome, PipelineError> {
    let ckpt = job.checkpoint.as_deref();
    let every = job.checkpoint_every.max(1);
    let mut user_stop = false;
    Ok(loop {
        let out = trainer.train(|r| {
            if on_epoch(r).is_break() {
                user_stop = true;
                return ControlFlow::Break(());
            }
            if ckpt.is_some() && r.epoch.is_multiple_of(every) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })?;
        if let Some(p) = ckpt {
            trainer.save_checkpoint(p)?;
        }
        if !out.interrupted || user_stop {
            break out;
        }
    })
}

/// The model file of the trained `weights` (already rounded to `job.dtype`), with the joint's
/// constants, the SCV prior, the validation and test RMSEs `va`, `te` [N·m] and the training
/// rows' input range.
fn stored_model(
    sources: &Sources,
    scv: &ScvPrior,
    prepared: &Prepared,
    job: &Job,
    weights: MlpWeights,
    va: Option<f64>,
    te: Option<f64>,
) -> ModelFile {
    let nan = |v: Option<f64>| v.map_or(f32::NAN, |x| x as f32);
    ModelFile {
        meta: ModelMeta {
            joint_name: sources.joint.clone(),
            gear_ratio: sources.gear_ratio,
            kt_nm_per_a: sources.kt_nm_per_a,
            features: job.spec,
            scv: Some(storable_scv(scv.params)),
            training: TrainingMeta {
                dataset_sha256: sources.dataset_sha256,
                val_rmse_nm: nan(va),
                test_rmse_nm: nan(te),
                created_unix_s: created_unix_s(),
                tool_version: format!("frictl {}", env!("CARGO_PKG_VERSION")),
                filtering: sources.filtering,
                // Training rows only: validation and test stay unseen.
                input_range: InputRange::from_rows(
                    &job.spec,
                    prepared
                        .train
                        .x
                        .chunks_exact(prepared.train.n_inputs.max(1)),
                ),
                quant_max_error_nm: None,
                teacher_sha256: None,
            },
        },
        dtype: job.dtype,
        mlp: weights,
    }
}

/// What the report says of each training dataset (the Δθ offset where the features use it).
fn datasets_info(sources: &Sources, job: &Job) -> Vec<DatasetInfo> {
    sources
        .list
        .iter()
        .map(|s| DatasetInfo {
            path: s.path.display().to_string(),
            sha256: hex(&s.sha256),
            samples: s.data.len(),
            chunks: s.sidecar.chunks,
            delta_theta_offset_motor_rad: job
                .spec
                .set
                .uses_delta_theta()
                .then(|| {
                    job.delta_theta_offset
                        .offset_for(&s.data, sources.gear_ratio)
                })
                .flatten(),
        })
        .collect()
}

/// Writes the `.fwt` (atomically) and the report JSON; fills `report.model`.
pub fn write_outputs(
    trained: &mut Trained,
    model_path: &Path,
    report_path: &Path,
) -> Result<(), PipelineError> {
    frictionless::weights::write_file(model_path, &trained.model)?;
    trained.report.model = model_path.display().to_string();
    let json = serde_json::to_string_pretty(&trained.report)
        .map_err(|e| file_err(report_path, format!("cannot encode the report: {e}")))?;
    frictionless::output_file::write(report_path, json)
        .map_err(|e| file_err(report_path, format!("cannot write: {e}")))?;
    Ok(())
}

/// The default report path next to a model: `MODEL.fwt` → `MODEL.train.json`.
pub fn default_report_path(model_path: &Path) -> PathBuf {
    model_path.with_extension("train.json")
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless::friction::ScvCodeParams;

    #[test]
    fn storable_scv_evaluates_like_the_code_form() {
        let code = ScvParams::from(ScvCodeParams {
            fc: 1.2,
            fs: 2.5,
            fv: 0.4,
            vs: 0.2,
        });
        assert!(code.ka.is_infinite());
        let stored = storable_scv(code);
        assert!(stored.ka.is_finite());
        stored.validate().unwrap();
        for v in [-3.0, -0.2, -1e-9, -1e-300, 0.0, 1e-300, 1e-6, 0.05, 2.0] {
            assert_eq!(stored.torque_nm(v), code.torque_nm(v), "v = {v}");
        }
        let finite = ScvParams { ka: 20.0, ..code };
        assert_eq!(storable_scv(finite), finite);
    }
}
