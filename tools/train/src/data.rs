//! Training samples from preprocessed datasets: input windows built exactly as the daemon builds them,
//! and the split of whole chunks into training, validation and test sets.
//!
//! What it **is**:
//! - [`build_inputs`]: every sample's input vector, produced by feeding the dataset's rows one by one
//!   into a [`frictionless::features::History`] — the same code `frictiond` runs each tick through
//!   `PinnEstimator::estimate` — so the offline and online inputs cannot differ. The history is
//!   cleared at the first row of every chunk (a chunk is one contiguous stream; chunks are separated
//!   by gaps or protocol blocks); the Δθ offset is latched there as [`DeltaThetaOffset`] says: by
//!   default once per dataset at its first row (`Run`, the authors' once-per-file convention, equal to
//!   the dataset column `delta_theta_motor_rad`), or at each chunk start (`Chunk`, what the daemon does
//!   when it re-latches at every enable), or a fixed calibrated offset.
//!   A row becomes a sample when it is `valid`, the history is ready under the [`WarmupPolicy`]
//!   (`hold_zero`: H samples of the same chunk; `zero_pad`: ≥ 1, older slots 0) and every input value
//!   and the label are finite. So no window ever straddles two chunks.
//! - [`ChunkKey`] (dataset index, chunk id) and [`split_chunks`]: train/validation/test chosen as whole
//!   chunks by a seeded shuffle (or explicit test chunks), never by overlapping windows (the authors'
//!   leak, `docs/method.md` §7).
//! - [`Block`], [`cut_chunk`] and [`with_blocks`]: a recording with too few chunks for the requested
//!   sets (one long robot log is one chunk) is cut into contiguous time blocks, which are then split
//!   like chunks. Each block is a chunk of its own (the history restarts there) and every block but
//!   the first of its chunk begins with [`BLOCK_GAP_ROWS`] rows that are never samples, so no window
//!   and no sample adjacent to a window of another block crosses a block boundary.
//! - [`select`]: gathers one set's inputs and both targets (label, SCV prior of the newest ṡ).
//!
//! What it is **not**: no file reading (see `super::pipeline`), no filtering or labelling (that is
//! `ident::preprocess`), no training.

use std::collections::BTreeSet;
use std::fmt;
use std::str::FromStr;

use frictionless::features::{
    FeatureError, FeatureSpec, History, JointSample, MAX_HISTORY, WarmupPolicy,
};
use frictionless::friction::{ScvParams, StaticFriction};
use frictionless::units::GearRatio;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::rng;
use frictionless_dataset::Dataset;

/// Why samples or a split could not be built.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The feature spec is not usable (e.g. H out of range).
    #[error("feature spec: {0}")]
    Features(#[from] FeatureError),
    /// The dataset's columns have different lengths.
    #[error("dataset column `{column}` has {got} values, `time_s` has {expected}")]
    ColumnLength {
        /// Column name.
        column: &'static str,
        /// Its length.
        got: usize,
        /// Length of `time_s`.
        expected: usize,
    },
    /// A split option is out of range or leaves a set empty.
    #[error("{key} = {value}: {reason}")]
    Split {
        /// The option, e.g. `--val-frac`.
        key: &'static str,
        /// Its value, formatted.
        value: String,
        /// What is wrong.
        reason: String,
    },
    /// A chunk key could not be parsed.
    #[error("chunk `{0}`: expected CHUNK or DATASET:CHUNK (non-negative integers)")]
    ChunkKey(String),
    /// The fractions leave the training set without a chunk.
    #[error(
        "--val-frac = {val_frac}: with {test} test chunk(s) and {val} validation chunk(s) no training \
         chunk is left of the {n} chunk(s) with samples{hint}"
    )]
    NoTrainingChunk {
        /// `--val-frac`.
        val_frac: f64,
        /// Test chunks chosen.
        test: usize,
        /// Validation chunks chosen.
        val: usize,
        /// Chunks split.
        n: usize,
        /// What to do instead (empty, or starting with "; ").
        hint: String,
    },
}

/// The samples of one dataset: row-major inputs and where each sample comes from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Windows {
    /// Raw (un-normalised) inputs, row-major `n_samples × n_inputs`, layout of [`FeatureSpec`].
    pub x: Vec<f32>,
    /// Inputs per sample (`spec.n_inputs()`).
    pub n_inputs: usize,
    /// Dataset row of each sample (the newest sample of its window; the target row).
    pub rows: Vec<usize>,
    /// Dataset `chunk` of each sample.
    pub chunk: Vec<u32>,
    /// Valid, ready rows skipped because an input or the label was not finite (e.g. NaN temperature).
    pub skipped_non_finite: usize,
}

impl Windows {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Inputs of sample `i`.
    pub fn input(&self, i: usize) -> &[f32] {
        &self.x[i * self.n_inputs..(i + 1) * self.n_inputs]
    }
}
fn check_lengths(ds: &Dataset) -> Result<(), DataError> {
    match ds.mismatched_column() {
        Some((column, got)) => Err(DataError::ColumnLength {
            column,
            got,
            expected: ds.len(),
        }),
        None => Ok(()),
    }
}

/// Where the Δθ offset θ_off (Δθ = r·s − (θ − θ_off), motor rad) is taken when windows are built.
///
/// Δθ is a deflection relative to the latch instant. Latched at a chunk start, Δθ = 0 there whatever
/// torque the transmission holds (stiction wind-up left by the previous block, gravity), so the same
/// Δθ means different friction torques in different chunks; latched once per recording it is the
/// deflection relative to the (torque-free, for the virtual joints) start of the run in every chunk.
/// The network can only read stiction from Δθ in the second case, which is why `Run` is the default
/// (measured: see `frictl train --help`, `--delta-theta-offset`). The daemon must then be configured
/// with the same offset (`[[joint]] delta_theta_offset_motor_rad`, the value in the train report),
/// not re-latch at enable.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeltaThetaOffset {
    /// Latched once at the first row of each dataset (one recording), kept across its chunks: the
    /// authors' convention (`theta -= theta[0] − s_motor[0]` once per file).
    #[default]
    Run,
    /// Latched at the first row of every chunk (what the daemon does when it re-latches at each
    /// enable).
    Chunk,
    /// A fixed, calibrated θ_off \[motor rad\] for every chunk (0: the absolute deflection of
    /// encoders that read θ = r·φ).
    Fixed(f64),
}

impl fmt::Display for DeltaThetaOffset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Run => f.write_str("run"),
            Self::Chunk => f.write_str("chunk"),
            Self::Fixed(v) => write!(f, "{v}"),
        }
    }
}

impl FromStr for DeltaThetaOffset {
    type Err = String;
    /// `run`, `chunk` or a finite number (a fixed θ_off in motor rad).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "run" => Ok(Self::Run),
            "chunk" => Ok(Self::Chunk),
            t => match t.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(Self::Fixed(v)),
                _ => Err(format!(
                    "`{s}`: expected `run`, `chunk` or a finite θ_off in motor rad"
                )),
            },
        }
    }
}

impl DeltaThetaOffset {
    /// The sample to pass to `History::reset` / `FrictionModel::reset` at the first row `k` of a
    /// chunk of `ds` so that the latched offset follows this policy (`reset` latches
    /// θ_off = θ − r·s of the sample it is given).
    pub fn latch_sample(self, ds: &Dataset, k: usize) -> JointSample {
        match self {
            Self::Run => ds.joint_sample(0),
            Self::Chunk => ds.joint_sample(k),
            Self::Fixed(off) => JointSample {
                s_rad: 0.0,
                theta_motor_rad: off,
                ..ds.joint_sample(k)
            },
        }
    }

    /// The θ_off \[motor rad\] this policy latches for a whole dataset, if it is one value
    /// (`Run`: θ₀ − r·s₀ of the first row; `Fixed`: the value; `Chunk`: `None`).
    pub fn offset_for(self, ds: &Dataset, gear_ratio: GearRatio) -> Option<f64> {
        match self {
            Self::Run if !ds.is_empty() => {
                Some(ds.theta_motor_rad[0] - gear_ratio.get() * ds.s_rad[0])
            }
            Self::Fixed(v) => Some(v),
            _ => None,
        }
    }
}

/// Builds every sample's input vector through [`History`], resetting the history at the first row of
/// each chunk and latching Δθ there as `offset` says. See the module doc for which rows become samples.
pub fn build_inputs(
    ds: &Dataset,
    spec: &FeatureSpec,
    gear_ratio: GearRatio,
    warmup: WarmupPolicy,
    offset: DeltaThetaOffset,
) -> Result<Windows, DataError> {
    check_lengths(ds)?;
    let mut hist = History::new(*spec, gear_ratio)?;
    let n_inputs = spec.n_inputs();
    let mut buf = vec![0f32; n_inputs];
    let mut w = Windows {
        n_inputs,
        ..Windows::default()
    };
    let valid_rows = ds.valid.iter().filter(|v| **v).count();
    w.x.reserve(valid_rows * n_inputs);
    w.rows.reserve(valid_rows);
    w.chunk.reserve(valid_rows);
    for k in 0..ds.len() {
        let sample = ds.joint_sample(k);
        if k == 0 || ds.chunk[k] != ds.chunk[k - 1] {
            hist.reset(&offset.latch_sample(ds, k));
        }
        hist.push(&sample);
        if !ds.valid[k] || !hist.is_ready(warmup) {
            continue;
        }
        hist.fill(&mut buf)?;
        if !ds.tau_f_label_nm[k].is_finite() || buf.iter().any(|v| !v.is_finite()) {
            w.skipped_non_finite += 1;
            continue;
        }
        w.x.extend_from_slice(&buf);
        w.rows.push(k);
        w.chunk.push(ds.chunk[k]);
    }
    Ok(w)
}

/// A chunk of one of several datasets: the unit of the split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ChunkKey {
    /// Index of the dataset in the order given (`--dataset` order).
    pub dataset: u32,
    /// The dataset's `chunk` id.
    pub chunk: u32,
}

impl fmt::Display for ChunkKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.dataset, self.chunk)
    }
}

impl FromStr for ChunkKey {
    type Err = DataError;
    /// `"7"` (dataset 0, chunk 7) or `"1:7"` (dataset 1, chunk 7).
    fn from_str(s: &str) -> Result<Self, DataError> {
        let bad = || DataError::ChunkKey(s.to_owned());
        let t = s.trim();
        let (d, c) = t.split_once(':').unwrap_or(("0", t));
        Ok(Self {
            dataset: d.trim().parse().map_err(|_| bad())?,
            chunk: c.trim().parse().map_err(|_| bad())?,
        })
    }
}

/// How to split chunks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SplitSpec {
    /// Fraction of chunks for validation, in [0, 1).
    pub val_frac: f64,
    /// Fraction of chunks for the test set, in [0, 1) (ignored when `test_chunks` is given).
    pub test_frac: f64,
    /// Seed of the shuffle.
    pub seed: u64,
    /// Explicit test chunks (`--test-chunks`).
    pub test_chunks: Option<Vec<ChunkKey>>,
}

/// Disjoint sets of chunks (each sorted).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    /// Training chunks.
    pub train: Vec<ChunkKey>,
    /// Validation chunks.
    pub val: Vec<ChunkKey>,
    /// Test chunks (never used for training or model selection).
    pub test: Vec<ChunkKey>,
    /// The time blocks chunks were cut into (empty when the split is by the datasets' own chunks):
    /// a block's [`Block::key`] is its key in the three sets; [`with_blocks`] relabels a dataset so.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blocks: Vec<Block>,
}

impl Split {
    /// Which set a chunk belongs to.
    pub fn set_of(&self, key: ChunkKey) -> Option<SetKind> {
        if self.train.binary_search(&key).is_ok() {
            Some(SetKind::Train)
        } else if self.val.binary_search(&key).is_ok() {
            Some(SetKind::Val)
        } else if self.test.binary_search(&key).is_ok() {
            Some(SetKind::Test)
        } else {
            None
        }
    }

    /// Valid rows of `key` in `ds` (the dataset `key.dataset` names): a block's rows after its
    /// gap, or the rows of the dataset's chunk `key.chunk`.
    pub fn valid_rows(&self, key: ChunkKey, ds: &Dataset) -> usize {
        match self.blocks.iter().find(|b| b.key == key) {
            Some(b) => ds
                .valid
                .get(b.start_row + b.gap_rows..b.end_row)
                .unwrap_or(&[])
                .iter()
                .filter(|v| **v)
                .count(),
            None => ds
                .chunk
                .iter()
                .zip(&ds.valid)
                .filter(|(c, v)| **c == key.chunk && **v)
                .count(),
        }
    }

    /// The chunks of one set.
    pub fn chunks(&self, kind: SetKind) -> &[ChunkKey] {
        match kind {
            SetKind::Train => &self.train,
            SetKind::Val => &self.val,
            SetKind::Test => &self.test,
        }
    }
}

/// One of the three sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SetKind {
    /// Training.
    Train,
    /// Validation (model selection, early stopping).
    Val,
    /// Held-out test.
    Test,
}

impl SetKind {
    /// `"train"`, `"val"`, `"test"`.
    pub fn name(self) -> &'static str {
        match self {
            SetKind::Train => "train",
            SetKind::Val => "val",
            SetKind::Test => "test",
        }
    }
}

/// Rows at the start of every block but the first of a cut chunk that are never samples (the gap
/// between blocks): the longest history the core accepts, so it is at least H for every model.
pub const BLOCK_GAP_ROWS: usize = MAX_HISTORY;

/// Fewest rows a block is cut to (with samples, after its gap).
pub const MIN_BLOCK_ROWS: usize = 8 * MAX_HISTORY;

/// How many blocks the chunks of a recording are cut into in all (the granularity of the fractions:
/// 5 %), fewer when a chunk is too short for blocks of [`MIN_BLOCK_ROWS`].
pub const BLOCKS_PER_SPLIT: usize = 20;

/// A contiguous time block of one chunk of one dataset: the unit of the split when the datasets have
/// too few chunks for the requested sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Block {
    /// Its key in the sets of the split: the dataset, and a chunk id the dataset does not use.
    pub key: ChunkKey,
    /// The dataset's `chunk` it was cut from.
    pub chunk: u32,
    /// First dataset row (the first row of the gap when there is one).
    pub start_row: usize,
    /// One past the last dataset row.
    pub end_row: usize,
    /// Leading rows that are never samples (0 for the first block of a chunk, else
    /// [`BLOCK_GAP_ROWS`]).
    pub gap_rows: usize,
}

/// Cuts chunk `chunk` of `ds` (dataset index `dataset`) into `n_blocks` blocks of equal row count,
/// keyed `first_id`, `first_id + 1`, …; empty when the chunk's rows are not contiguous, or when
/// `n_blocks < 2` or the blocks would be shorter than [`MIN_BLOCK_ROWS`] after their gap.
pub fn cut_chunk(
    ds: &Dataset,
    dataset: u32,
    chunk: u32,
    n_blocks: usize,
    first_id: u32,
) -> Vec<Block> {
    let Some(a) = ds.chunk.iter().position(|&c| c == chunk) else {
        return Vec::new();
    };
    let b = ds.chunk[a..]
        .iter()
        .position(|&c| c != chunk)
        .map_or(ds.len(), |e| a + e);
    let len = b - a;
    if n_blocks < 2
        || ds.chunk[b..].contains(&chunk)
        || len / n_blocks < MIN_BLOCK_ROWS + BLOCK_GAP_ROWS
    {
        return Vec::new();
    }
    (0..n_blocks)
        .map(|i| Block {
            key: ChunkKey {
                dataset,
                chunk: first_id + i as u32,
            },
            chunk,
            start_row: a + i * len / n_blocks,
            end_row: a + (i + 1) * len / n_blocks,
            gap_rows: if i == 0 { 0 } else { BLOCK_GAP_ROWS },
        })
        .collect()
}

/// `ds` (dataset index `dataset`) with each of its blocks as a chunk of its own: the rows of a block
/// get the block's chunk id and its gap rows are not `valid`. Blocks of other datasets are ignored.
pub fn with_blocks(ds: &Dataset, dataset: u32, blocks: &[Block]) -> Dataset {
    let mut out = ds.clone();
    for b in blocks.iter().filter(|b| b.key.dataset == dataset) {
        let end = b.end_row.min(out.len());
        for k in b.start_row.min(end)..end {
            out.chunk[k] = b.key.chunk;
        }
        for k in b.start_row.min(end)..(b.start_row + b.gap_rows).min(end) {
            out.valid[k] = false;
        }
    }
    out
}

fn n_for(frac: f64, n: usize) -> usize {
    if frac <= 0.0 {
        0
    } else {
        ((frac * n as f64).round() as usize).max(1)
    }
}

fn check_frac(key: &'static str, v: f64) -> Result<(), DataError> {
    if (0.0..1.0).contains(&v) {
        Ok(())
    } else {
        Err(DataError::Split {
            key,
            value: v.to_string(),
            reason: "must be in [0, 1)".into(),
        })
    }
}

/// Splits the given chunks (duplicates ignored) into train/validation/test by a seeded shuffle.
///
/// With `f > 0` a set gets `max(1, round(f·n))` of the `n` chunks; explicit test chunks must exist.
/// Errors when the training set would be empty.
pub fn split_chunks(all: &[ChunkKey], spec: &SplitSpec) -> Result<Split, DataError> {
    check_frac("--val-frac", spec.val_frac)?;
    check_frac("--test-frac", spec.test_frac)?;
    let keys: BTreeSet<ChunkKey> = all.iter().copied().collect();
    let n = keys.len();
    let mut rest: Vec<ChunkKey> = keys.iter().copied().collect();
    let mut rng = ChaCha8Rng::seed_from_u64(rng::derive(spec.seed, &[rng::tag::SPLIT, n as u64]));
    let mut test = match &spec.test_chunks {
        Some(t) => {
            let mut t: Vec<ChunkKey> = t
                .iter()
                .copied()
                .collect::<BTreeSet<_>>()
                .into_iter()
                .collect();
            if let Some(missing) = t.iter().find(|k| !keys.contains(k)) {
                return Err(DataError::Split {
                    key: "--test-chunks",
                    value: missing.to_string(),
                    reason: format!(
                        "no such chunk with samples (DATASET:CHUNK; the datasets have {n} chunks)"
                    ),
                });
            }
            rest.retain(|k| !t.contains(k));
            rest.shuffle(&mut rng);
            t.sort();
            t
        }
        None => {
            rest.shuffle(&mut rng);
            let n_test = n_for(spec.test_frac, n).min(rest.len());
            rest.drain(..n_test).collect()
        }
    };
    let n_val = n_for(spec.val_frac, n).min(rest.len());
    let mut val: Vec<ChunkKey> = rest.drain(..n_val).collect();
    if rest.is_empty() {
        return Err(DataError::NoTrainingChunk {
            val_frac: spec.val_frac,
            test: test.len(),
            val: val.len(),
            n,
            hint: String::new(),
        });
    }
    rest.sort();
    val.sort();
    test.sort();
    Ok(Split {
        train: rest,
        val,
        test,
        blocks: Vec::new(),
    })
}

/// One set's arrays, ready for [`super::Dataset`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SetData {
    /// Raw inputs, row-major.
    pub x: Vec<f32>,
    /// Label τ_F per sample \[Nm\].
    pub y_label_nm: Vec<f32>,
    /// SCV prior τ_F,SCV(ṡ of the target row) per sample \[Nm\].
    pub y_scv_nm: Vec<f32>,
    /// Inputs per sample.
    pub n_inputs: usize,
    /// (dataset index, dataset row) of each sample.
    pub rows: Vec<(u32, usize)>,
}

impl SetData {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y_label_nm.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.y_label_nm.is_empty()
    }

    /// The trainer's borrowed view.
    pub fn view(&self) -> super::Dataset<'_> {
        super::Dataset {
            x: &self.x,
            y_label_nm: &self.y_label_nm,
            y_scv_nm: &self.y_scv_nm,
            n_inputs: self.n_inputs,
        }
    }
}

/// Gathers the samples whose chunk is in `chunks` from the windows of several datasets
/// (`sources[i] = (dataset i, its windows)`), with the label and the SCV prior as targets.
pub fn select(sources: &[(&Dataset, &Windows)], chunks: &[ChunkKey], scv: &ScvParams) -> SetData {
    let n_inputs = sources.first().map_or(0, |(_, w)| w.n_inputs);
    let mut out = SetData {
        n_inputs,
        ..SetData::default()
    };
    for (d, (ds, w)) in sources.iter().enumerate() {
        for (i, (&row, &chunk)) in w.rows.iter().zip(&w.chunk).enumerate() {
            let key = ChunkKey {
                dataset: d as u32,
                chunk,
            };
            if chunks.binary_search(&key).is_err() {
                continue;
            }
            out.x.extend_from_slice(w.input(i));
            out.y_label_nm.push(ds.tau_f_label_nm[row] as f32);
            out.y_scv_nm.push(scv.torque_nm(ds.sdot_rad_s[row]) as f32);
            out.rows.push((d as u32, row));
        }
    }
    out
}

/// Every chunk key that has at least one sample.
pub fn chunks_with_samples(windows: &[&Windows]) -> Vec<ChunkKey> {
    let set: BTreeSet<ChunkKey> = windows
        .iter()
        .enumerate()
        .flat_map(|(d, w)| {
            w.chunk.iter().map(move |&chunk| ChunkKey {
                dataset: d as u32,
                chunk,
            })
        })
        .collect();
    set.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless::features::FeatureSet;

    /// `n` chunks spread over two datasets, sorted.
    fn keys(n: u32) -> Vec<ChunkKey> {
        let mut k: Vec<ChunkKey> = (0..n)
            .map(|c| ChunkKey {
                dataset: c % 2,
                chunk: c,
            })
            .collect();
        k.sort();
        k
    }

    #[test]
    fn chunk_key_parses_both_forms() {
        assert_eq!(
            "7".parse::<ChunkKey>().unwrap(),
            ChunkKey {
                dataset: 0,
                chunk: 7
            }
        );
        assert_eq!(
            " 1:3 ".parse::<ChunkKey>().unwrap(),
            ChunkKey {
                dataset: 1,
                chunk: 3
            }
        );
        assert!("x".parse::<ChunkKey>().is_err());
        assert!("1:-2".parse::<ChunkKey>().is_err());
    }

    #[test]
    fn split_is_a_seeded_partition() {
        let all = keys(20);
        let spec = SplitSpec {
            val_frac: 0.15,
            test_frac: 0.15,
            seed: 3,
            test_chunks: None,
        };
        let s = split_chunks(&all, &spec).unwrap();
        assert_eq!((s.val.len(), s.test.len(), s.train.len()), (3, 3, 14));
        let mut union: Vec<ChunkKey> = [&s.train[..], &s.val, &s.test].concat();
        union.sort();
        assert_eq!(union, all, "every chunk in exactly one set");
        assert_eq!(
            s,
            split_chunks(&all, &spec).unwrap(),
            "same seed, same split"
        );
        let other = split_chunks(&all, &SplitSpec { seed: 4, ..spec }).unwrap();
        assert_ne!(s.test, other.test, "the seed changes the split");
    }

    #[test]
    fn explicit_test_chunks_and_errors() {
        let all = keys(6);
        let t = vec![all[1], all[4]];
        assert!(t[0] < t[1]);
        let s = split_chunks(
            &all,
            &SplitSpec {
                val_frac: 0.2,
                test_frac: 0.0,
                seed: 0,
                test_chunks: Some(t.clone()),
            },
        )
        .unwrap();
        assert_eq!(s.test, t);
        assert_eq!(s.val.len(), 1);
        assert!(!s.train.iter().chain(&s.val).any(|k| t.contains(k)));
        let missing = split_chunks(
            &all,
            &SplitSpec {
                val_frac: 0.2,
                test_frac: 0.0,
                seed: 0,
                test_chunks: Some(vec![ChunkKey {
                    dataset: 0,
                    chunk: 99,
                }]),
            },
        )
        .unwrap_err();
        assert!(
            missing.to_string().contains("--test-chunks = 0:99"),
            "{missing}"
        );
        let empty = split_chunks(
            &all[..2],
            &SplitSpec {
                val_frac: 0.15,
                test_frac: 0.15,
                seed: 0,
                test_chunks: None,
            },
        )
        .unwrap_err();
        assert!(empty.to_string().contains("no training chunk"), "{empty}");
        let bad = split_chunks(
            &all,
            &SplitSpec {
                val_frac: 1.5,
                test_frac: 0.0,
                seed: 0,
                test_chunks: None,
            },
        )
        .unwrap_err();
        assert!(bad.to_string().starts_with("--val-frac = 1.5"), "{bad}");
    }

    #[test]
    fn a_long_chunk_is_cut_into_blocks_with_a_gap_before_each_but_the_first() {
        let n = 5 * (MIN_BLOCK_ROWS + BLOCK_GAP_ROWS) + 17;
        let mut ds = toy_dataset();
        let pad = |v: &mut Vec<f64>| v.resize(n, 0.5);
        ds.time_s = (0..n).map(|k| k as f64 * 1e-3).collect();
        // Chunk 3 is rows 10.., chunk 1 the first ten rows.
        ds.chunk = (0..n).map(|k| if k < 10 { 1 } else { 3 }).collect();
        ds.source_chunk = vec![0; n];
        ds.active = vec![true; n];
        ds.valid = vec![true; n];
        for v in [
            &mut ds.s_rad,
            &mut ds.sdot_rad_s,
            &mut ds.sddot_rad_s2,
            &mut ds.theta_motor_rad,
            &mut ds.delta_theta_motor_rad,
            &mut ds.omega_motor_rad_s,
            &mut ds.i_meas_a,
            &mut ds.i_filt_a,
            &mut ds.tau_id_nm,
            &mut ds.tau_f_label_nm,
            &mut ds.temperature_c,
        ] {
            pad(v);
        }
        let blocks = cut_chunk(&ds, 2, 3, 5, 4);
        assert_eq!(blocks.len(), 5);
        assert_eq!(blocks[0].start_row, 10);
        assert_eq!(blocks[4].end_row, n);
        for (i, b) in blocks.iter().enumerate() {
            assert_eq!(
                b.key,
                ChunkKey {
                    dataset: 2,
                    chunk: 4 + i as u32
                }
            );
            assert_eq!(b.chunk, 3);
            assert_eq!(b.gap_rows, if i == 0 { 0 } else { BLOCK_GAP_ROWS });
            assert!(b.end_row - b.start_row >= MIN_BLOCK_ROWS + b.gap_rows);
            if i > 0 {
                assert_eq!(b.start_row, blocks[i - 1].end_row, "blocks tile the chunk");
            }
        }
        // Too many blocks for the chunk, one block, an absent chunk: no cut.
        assert!(cut_chunk(&ds, 2, 3, 6, 4).is_empty());
        assert!(cut_chunk(&ds, 2, 3, 1, 4).is_empty());
        assert!(cut_chunk(&ds, 2, 9, 2, 4).is_empty());
        let cut = with_blocks(&ds, 2, &blocks);
        assert!(
            cut.chunk[..10].iter().all(|&c| c == 1),
            "other chunks unchanged"
        );
        for b in &blocks {
            assert!(
                cut.chunk[b.start_row..b.end_row]
                    .iter()
                    .all(|&c| c == b.key.chunk)
            );
            assert!(
                !cut.valid[b.start_row..b.start_row + b.gap_rows]
                    .iter()
                    .any(|&v| v)
            );
            assert!(
                cut.valid[b.start_row + b.gap_rows..b.end_row]
                    .iter()
                    .all(|&v| v)
            );
        }
        // A block's valid rows are its rows after the gap; a chunk key counts the chunk's rows.
        let split = Split {
            train: vec![blocks[1].key],
            val: vec![],
            test: vec![],
            blocks: blocks.clone(),
        };
        assert_eq!(
            split.valid_rows(blocks[1].key, &ds),
            blocks[1].end_row - blocks[1].start_row - BLOCK_GAP_ROWS
        );
        assert_eq!(
            split.valid_rows(
                ChunkKey {
                    dataset: 2,
                    chunk: 1
                },
                &ds
            ),
            10
        );
        let other = with_blocks(&ds, 0, &blocks);
        assert!(
            other.chunk == ds.chunk && other.valid == ds.valid,
            "blocks of another dataset change nothing"
        );
        // Every window of a block's samples lies inside the block, after its gap.
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: MAX_HISTORY,
            temperature: false,
        };
        let w = build_inputs(
            &cut,
            &spec,
            GearRatio::new(1.0).unwrap(),
            WarmupPolicy::HoldZero,
            DeltaThetaOffset::Run,
        )
        .unwrap();
        for (&row, &chunk) in w.rows.iter().zip(&w.chunk) {
            if let Some(b) = blocks.iter().find(|b| b.key.chunk == chunk) {
                assert!(row + 1 >= b.start_row + MAX_HISTORY && row < b.end_row);
                assert!(row >= b.start_row + b.gap_rows);
            }
        }
    }

    fn toy_dataset() -> Dataset {
        // Two chunks of 6 rows, row 2 invalid.
        let n = 12;
        let mut ds = Dataset {
            time_s: (0..n).map(|k| k as f64 * 1e-3).collect(),
            chunk: (0..n).map(|k| (k / 6) as u32).collect(),
            source_chunk: vec![0; n],
            active: vec![true; n],
            valid: (0..n).map(|k| k != 2).collect(),
            s_rad: (0..n).map(|k| 0.01 * k as f64).collect(),
            sdot_rad_s: (0..n).map(|k| 0.5 - 0.1 * k as f64).collect(),
            sddot_rad_s2: vec![0.0; n],
            theta_motor_rad: (0..n).map(|k| 5.0 + 0.3 * k as f64).collect(),
            delta_theta_motor_rad: vec![0.0; n],
            omega_motor_rad_s: vec![0.0; n],
            i_meas_a: vec![0.0; n],
            i_filt_a: vec![0.0; n],
            tau_id_nm: vec![0.0; n],
            tau_f_label_nm: (0..n).map(|k| k as f64).collect(),
            temperature_c: vec![f64::NAN; n],
            tau_f_true_nm: None,
            phi_ddot_rad_s2: None,
        };
        ds.delta_theta_motor_rad = ds.s_rad.clone();
        ds
    }

    #[test]
    fn windows_by_hand_for_each_delta_theta_latch() {
        let ds = toy_dataset();
        let r = -2.0;
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 3,
            temperature: false,
        };
        let gr = GearRatio::new(r).unwrap();
        let run_off = ds.theta_motor_rad[0] - r * ds.s_rad[0];
        for latch in [
            DeltaThetaOffset::Chunk,
            DeltaThetaOffset::Run,
            DeltaThetaOffset::Fixed(1.25),
        ] {
            let w = build_inputs(&ds, &spec, gr, WarmupPolicy::HoldZero, latch).unwrap();
            // Rows 2..6 and 8..12 have 3 predecessors-in-chunk (incl. themselves); row 2 is invalid.
            assert_eq!(w.rows, vec![3, 4, 5, 8, 9, 10, 11]);
            assert_eq!(w.chunk, vec![0, 0, 0, 1, 1, 1, 1]);
            for (i, &row) in w.rows.iter().enumerate() {
                let start = if row < 6 { 0 } else { 6 };
                let off = match latch {
                    DeltaThetaOffset::Chunk => ds.theta_motor_rad[start] - r * ds.s_rad[start],
                    DeltaThetaOffset::Run => run_off,
                    DeltaThetaOffset::Fixed(v) => v,
                };
                let x = w.input(i);
                for j in 0..3 {
                    let k = row + j - 2;
                    assert!(
                        k >= start,
                        "window of row {row} reaches into the previous chunk"
                    );
                    let dtheta = r * ds.s_rad[k] - (ds.theta_motor_rad[k] - off);
                    assert!(
                        (x[j] as f64 - dtheta).abs() < 1e-5,
                        "{latch}: Δθ of row {row}, slot {j}"
                    );
                    assert!((x[3 + j] as f64 - ds.sdot_rad_s[k]).abs() < 1e-6);
                }
            }
        }
        assert_eq!(DeltaThetaOffset::Run.offset_for(&ds, gr), Some(run_off));
        assert_eq!(DeltaThetaOffset::Chunk.offset_for(&ds, gr), None);
        assert_eq!("run".parse::<DeltaThetaOffset>(), Ok(DeltaThetaOffset::Run));
        assert_eq!(
            "chunk".parse::<DeltaThetaOffset>(),
            Ok(DeltaThetaOffset::Chunk)
        );
        assert_eq!(
            "-0.5".parse::<DeltaThetaOffset>(),
            Ok(DeltaThetaOffset::Fixed(-0.5))
        );
        assert!("inf".parse::<DeltaThetaOffset>().is_err());
        assert!("runs".parse::<DeltaThetaOffset>().is_err());
        // Zero padding: samples from the first row of each chunk on, missing slots 0.
        let z = build_inputs(
            &ds,
            &spec,
            gr,
            WarmupPolicy::ZeroPad,
            DeltaThetaOffset::Chunk,
        )
        .unwrap();
        assert_eq!(z.rows, vec![0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11]);
        let first_of_chunk1 = z.rows.iter().position(|&r| r == 6).unwrap();
        let want = [0.0, 0.0, 0.0, 0.0, 0.0, ds.sdot_rad_s[6] as f32];
        for (got, want) in z.input(first_of_chunk1).iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "padded window {got} vs {want}");
        }
        // A NaN temperature slot makes every sample non-finite.
        let t = build_inputs(
            &ds,
            &FeatureSpec {
                temperature: true,
                ..spec
            },
            gr,
            WarmupPolicy::HoldZero,
            DeltaThetaOffset::Chunk,
        )
        .unwrap();
        assert!(t.is_empty());
        assert_eq!(t.skipped_non_finite, 7);
    }

    #[test]
    fn select_gathers_targets_of_the_chosen_chunks() {
        let ds = toy_dataset();
        let spec = FeatureSpec {
            set: FeatureSet::MotorVelJointVel,
            history: 2,
            temperature: false,
        };
        let w = build_inputs(
            &ds,
            &spec,
            GearRatio::new(1.0).unwrap(),
            WarmupPolicy::HoldZero,
            DeltaThetaOffset::Run,
        )
        .unwrap();
        let scv = ScvParams {
            kc: 1.0,
            ka: 10.0,
            kv: 0.5,
            ks: 1.5,
            vs: 0.1,
            alpha: 2.0,
        };
        let set = select(
            &[(&ds, &w)],
            &[ChunkKey {
                dataset: 0,
                chunk: 1,
            }],
            &scv,
        );
        assert_eq!(set.rows, vec![(0, 7), (0, 8), (0, 9), (0, 10), (0, 11)]);
        for (i, &(_, row)) in set.rows.iter().enumerate() {
            assert_eq!(set.y_label_nm[i], row as f32);
            assert_eq!(set.y_scv_nm[i], scv.torque_nm(ds.sdot_rad_s[row]) as f32);
        }
        assert_eq!(
            chunks_with_samples(&[&w]),
            vec![
                ChunkKey {
                    dataset: 0,
                    chunk: 0
                },
                ChunkKey {
                    dataset: 0,
                    chunk: 1
                }
            ]
        );
    }
}
