//! Random hyper-parameter search over the paper's ranges (`frictl search`), parallel and resumable.
//!
//! What it **is**: [`SearchSpace`] (the authors' W&B sweep ranges, `docs/method.md` §7.1: batch
//! 3000–5000, hidden 150–300 each, lr 1e-5–1e-3 log-uniform, H 3–30, λ 0.1–0.5, dropout 0.01–0.1),
//! [`draw`] (trial `k`'s hyper-parameters, a pure function of the search seed and `k`, so a resumed
//! search draws what an uninterrupted one would, in any order), and [`run_search`]: the datasets are
//! loaded and split once (one chunk split for all trials, independent of H, so validation RMSEs are
//! comparable), `parallel` worker threads take trials from a queue, each trial trains with
//! `threads_total / parallel` threads and writes `DIR/trials/trial_NNNN.fwt` (+ `.train.json`), and
//! appends one JSON line to `DIR/results.jsonl` when it finishes, `"failed"` with the reason when it
//! failed (a full disk, a diverged run). A restart with `resume` skips the trials recorded `ok` in
//! that file and runs the failed ones again. One search at a time owns `DIR`: an exclusive `flock`
//! on `DIR/.search.lock` (released by the kernel when the holder dies, SIGKILL included) refuses a
//! second search or `finish` there; [`run_trials`] workers share it with each other only. At the end `DIR/results.json` and `DIR/results.csv` list every trial
//! sorted by validation RMSE (failed trials last) and the best model is copied to `DIR/best.fwt`
//! (+ `DIR/best.train.json`). `DIR/search.json` records the search settings; a resume with different
//! settings is refused.
//!
//! Models are selected on validation RMSE only; the test RMSE is reported, never used to choose.
//!
//! An external scheduler (a Ray cluster, a Slurm array, several shells) runs chosen trials with
//! [`run_trials`] and publishes the tables with [`finish`]: the directory layout is the same, so a
//! search started by [`run_search`] can be continued by trials run elsewhere and the other way round.
//! Each result is appended as one `write(2)` of one line to a file opened with `O_APPEND`, so several
//! processes on one machine (one local file system) may share `DIR`; a trial recorded twice (a retried
//! task) counts once, an `ok` record winning over a `failed` one. The recorded settings are compared by
//! content: dataset and SCV paths may differ between machines when their SHA-256 match.
//!
//! What it is **not**: no Bayesian or early-pruning search strategy, no scheduler of its own across
//! machines (that is the cluster engine's job, see `docs/cluster.md`).

use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
use frictionless::mlp::StorageDtype;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::TrainConfig;
use super::data::{DeltaThetaOffset, Split, SplitSpec};
use super::pipeline::{self, Job, PipelineError, ScvPrior, Sources};
use super::rng;

/// Inclusive ranges of the random search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchSpace {
    /// Batch size, uniform integer.
    pub batch: (usize, usize),
    /// Width of each of the two hidden layers, uniform integer.
    pub hidden: (usize, usize),
    /// Learning rate, log-uniform.
    pub lr: (f32, f32),
    /// History length H, uniform integer.
    pub history: (usize, usize),
    /// λ, uniform.
    pub lambda: (f32, f32),
    /// Dropout, uniform.
    pub dropout: (f32, f32),
}

impl Default for SearchSpace {
    /// The authors' sweep (`config_training_wandb.yaml`).
    fn default() -> Self {
        Self {
            batch: (3000, 5000),
            hidden: (150, 300),
            lr: (1e-5, 1e-3),
            history: (3, 30),
            lambda: (0.1, 0.5),
            dropout: (0.01, 0.1),
        }
    }
}

/// A range of a [`SearchSpace`] the trainer would refuse ([`SearchSpace::validate`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RangeError {
    /// The range: `batch`, `hidden`, `lr`, `history`, `lambda` or `dropout` (`frictl search
    /// --hidden-range`, a robot file's `search.hidden`).
    pub range: &'static str,
    /// Its MIN and MAX as given, `MIN,MAX`.
    pub value: String,
    /// Why it is refused.
    pub why: String,
}

impl SearchSpace {
    /// Refuses, before any trial runs, a range the trainer would refuse at either end (so no trial
    /// can fail on its draw): MIN ≤ MAX, and the trainer's own checks
    /// ([`TrainConfig::validate`], [`FeatureSpec::validate`]) on both ends of every range.
    pub fn validate(&self, features: FeatureSet, temperature: bool) -> Result<(), RangeError> {
        // Each range's ends are tried on the paper's defaults, so a refusal names its own range.
        let d = Self::default();
        let base = TrainConfig {
            hidden: vec![d.hidden.0; 2],
            dropout: d.dropout.0,
            lambda: d.lambda.0,
            lr: d.lr.0,
            batch_size: d.batch.0,
            epochs: 1,
            seed: 0,
            threads: 1,
            patience: None,
            abort_loss: None,
        };
        let usage = |range: &'static str,
                     lo: &dyn std::fmt::Display,
                     hi: &dyn std::fmt::Display,
                     why: String| RangeError {
            range,
            value: format!("{lo},{hi}"),
            why,
        };
        type Set = fn(&mut TrainConfig, f64);
        // (option, MIN and MAX as the user wrote them, as numbers, the setter)
        let text =
            |a: &dyn std::fmt::Display, b: &dyn std::fmt::Display| [a.to_string(), b.to_string()];
        let ranges: [(&'static str, [String; 2], [f64; 2], Set); 5] = [
            (
                "batch",
                text(&self.batch.0, &self.batch.1),
                [self.batch.0 as f64, self.batch.1 as f64],
                |c, v| c.batch_size = v as usize,
            ),
            (
                "hidden",
                text(&self.hidden.0, &self.hidden.1),
                [self.hidden.0 as f64, self.hidden.1 as f64],
                |c, v| c.hidden = vec![v as usize; 2],
            ),
            (
                "lr",
                text(&self.lr.0, &self.lr.1),
                [self.lr.0 as f64, self.lr.1 as f64],
                |c, v| c.lr = v as f32,
            ),
            (
                "lambda",
                text(&self.lambda.0, &self.lambda.1),
                [self.lambda.0 as f64, self.lambda.1 as f64],
                |c, v| c.lambda = v as f32,
            ),
            (
                "dropout",
                text(&self.dropout.0, &self.dropout.1),
                [self.dropout.0 as f64, self.dropout.1 as f64],
                |c, v| c.dropout = v as f32,
            ),
        ];
        for (flag, [lo, hi], ends, set) in ranges {
            if ends[0].partial_cmp(&ends[1]).is_none_or(|o| o.is_gt()) {
                return Err(usage(
                    flag,
                    &lo,
                    &hi,
                    "expected MIN,MAX with MIN ≤ MAX".into(),
                ));
            }
            for (v, shown) in ends.into_iter().zip([&lo, &hi]) {
                let mut c = base.clone();
                set(&mut c, v);
                c.validate().map_err(|e| {
                    usage(flag, &lo, &hi, format!("the trainer refuses {shown}: {e}"))
                })?;
            }
        }
        let (h0, h1) = self.history;
        if h0 > h1 {
            return Err(usage(
                "history",
                &h0,
                &h1,
                "expected MIN,MAX with MIN ≤ MAX".into(),
            ));
        }
        for history in [h0, h1] {
            FeatureSpec {
                set: features,
                history,
                temperature,
            }
            .validate()
            .map_err(|e| usage("history", &h0, &h1, format!("H = {history}: {e}")))?;
        }
        Ok(())
    }
}

/// The hyper-parameters of one trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialParams {
    /// Trial index (0-based).
    pub trial: usize,
    /// Training seed of the trial (init, shuffles, dropout).
    pub seed: u64,
    /// Batch size.
    pub batch_size: usize,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Learning rate.
    pub lr: f32,
    /// History length H.
    pub history: usize,
    /// λ.
    pub lambda: f32,
    /// Dropout.
    pub dropout: f32,
}

/// Trial `trial`'s hyper-parameters: a pure function of `(space, seed, trial)`.
pub fn draw(space: &SearchSpace, seed: u64, trial: usize) -> TrialParams {
    let mut g = ChaCha8Rng::seed_from_u64(rng::derive(seed, &[rng::tag::SEARCH, trial as u64]));
    let (l0, l1) = ((space.lr.0 as f64).ln(), (space.lr.1 as f64).ln());
    TrialParams {
        trial,
        seed: rng::derive(seed, &[rng::tag::SEARCH, trial as u64, 1]) >> 11,
        batch_size: g.random_range(space.batch.0..=space.batch.1),
        hidden: vec![
            g.random_range(space.hidden.0..=space.hidden.1),
            g.random_range(space.hidden.0..=space.hidden.1),
        ],
        lr: g.random_range(l0..=l1).exp() as f32,
        history: g.random_range(space.history.0..=space.history.1),
        lambda: g.random_range(space.lambda.0..=space.lambda.1),
        dropout: g.random_range(space.dropout.0..=space.dropout.1),
    }
}

/// The outcome of one trial (one line of `results.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialResult {
    /// Its hyper-parameters.
    pub params: TrialParams,
    /// `"ok"` or `"failed"`.
    pub status: String,
    /// Why it failed.
    pub error: Option<String>,
    /// Validation RMSE of the stored model \[Nm\] (the selection criterion).
    pub val_rmse_nm: Option<f64>,
    /// Test RMSE \[Nm\] (reported only).
    pub test_rmse_nm: Option<f64>,
    /// Training RMSE \[Nm\].
    pub train_rmse_nm: Option<f64>,
    /// Epoch of the stored weights.
    pub best_epoch: Option<usize>,
    /// Epochs run.
    pub epochs_run: usize,
    /// Wall time \[s\].
    pub seconds: f64,
    /// Model file, relative to the search directory.
    pub model: Option<String>,
    /// Inference time of the stored model on this CPU, hot (the same input over and over, caches
    /// warm) \[µs per call\], on the kernel frictiond runs; absent in older results.
    #[serde(default)]
    pub hot_us: Option<f64>,
    /// Inference time after evicting the caches (a large buffer touched before each call) \[µs\].
    #[serde(default)]
    pub cold_us: Option<f64>,
}

/// Hot and cold inference time \[µs per call\] of `file` on the kernel frictiond runs
/// ([`frictionless::kernel::Mlp`], its stored dtype, the fastest path of this CPU). Hot: the median
/// over 7 rounds of the mean of 2 000 calls on one input; cold: the median of 31 single calls, each
/// after writing a 16 MiB buffer (larger than the caches of the machines this targets). `None` if
/// the model cannot run on the kernel. Informative: other processes on the machine add noise.
pub fn inference_us(file: &frictionless::weights::ModelFile) -> Option<(f64, f64)> {
    use std::hint::black_box;
    let mut mlp = frictionless::kernel::Mlp::new(&file.mlp, file.dtype).ok()?;
    let x = file.mlp.norm.mean.clone();
    for _ in 0..200 {
        black_box(mlp.forward(black_box(&x)));
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    const CALLS: usize = 2000;
    let hot = median(
        (0..7)
            .map(|_| {
                let t = Instant::now();
                for _ in 0..CALLS {
                    black_box(mlp.forward(black_box(&x)));
                }
                t.elapsed().as_secs_f64() * 1e6 / CALLS as f64
            })
            .collect(),
    );
    let mut evict = vec![0u8; 16 << 20];
    let cold = median(
        (0..31u8)
            .map(|k| {
                for line in evict.chunks_mut(64) {
                    line[0] = line[0].wrapping_add(k);
                }
                black_box(&evict);
                let t = Instant::now();
                black_box(mlp.forward(black_box(&x)));
                t.elapsed().as_secs_f64() * 1e6
            })
            .collect(),
    );
    Some((hot, cold))
}

/// The ok trials with a finite validation RMSE and hot time that no other such trial dominates (at
/// most as slow and at most as inaccurate, better in one), fastest first.
pub fn pareto_front(results: &[TrialResult]) -> Vec<&TrialResult> {
    let point = |r: &TrialResult| match (r.status.as_str(), r.val_rmse_nm, r.hot_us) {
        ("ok", Some(e), Some(t)) if e.is_finite() && t.is_finite() => Some((e, t)),
        _ => None,
    };
    let pts: Vec<(&TrialResult, (f64, f64))> = results
        .iter()
        .filter_map(|r| point(r).map(|p| (r, p)))
        .collect();
    let mut front: Vec<(&TrialResult, (f64, f64))> = pts
        .iter()
        .filter(|(_, (e, t))| {
            !pts.iter()
                .any(|(_, (e2, t2))| e2 <= e && t2 <= t && (e2 < e || t2 < t))
        })
        .copied()
        .collect();
    front.sort_by(|a, b| a.1.1.total_cmp(&b.1.1).then(a.1.0.total_cmp(&b.1.0)));
    front.into_iter().map(|(r, _)| r).collect()
}

/// The cheapest trial (lowest hot time, then lowest validation RMSE) whose validation RMSE is at most
/// `max_rmse_ratio` × the best validation RMSE of the timed ok trials; `None` without such trials.
pub fn cheapest_within(results: &[TrialResult], max_rmse_ratio: f64) -> Option<&TrialResult> {
    let front = pareto_front(results);
    let best = front
        .iter()
        .filter_map(|r| r.val_rmse_nm)
        .min_by(f64::total_cmp)?;
    // The front is sorted fastest first; its first member within the bound is the cheapest of all
    // trials within it (a dominated trial is never cheaper at equal or better accuracy).
    front
        .into_iter()
        .find(|r| r.val_rmse_nm.is_some_and(|e| e <= max_rmse_ratio * best))
}

/// Searches saved before the Δθ-offset option latched at every chunk start.
fn chunk_latch() -> DeltaThetaOffset {
    DeltaThetaOffset::Chunk
}

/// Everything a search needs besides the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchSettings {
    /// Ranges.
    pub space: SearchSpace,
    /// Search seed (split and trial draws).
    pub seed: u64,
    /// Epochs per trial.
    pub epochs: usize,
    /// Feature set.
    pub features: FeatureSet,
    /// Motor temperature appended.
    pub temperature: bool,
    /// Warm-up policy.
    pub warmup: WarmupPolicy,
    /// Where Δθ is latched (searches saved before this option latched per chunk).
    #[serde(default = "chunk_latch")]
    pub delta_theta_offset: DeltaThetaOffset,
    /// Storage dtype.
    pub dtype: StorageDtype,
    /// Early stopping patience.
    pub patience: Option<usize>,
    /// Split.
    pub split: SplitSpec,
    /// Dataset paths.
    pub datasets: Vec<String>,
    /// SHA-256 of the datasets (hex, as in the `.fwt`).
    pub dataset_sha256: String,
    /// SCV JSON path.
    pub scv: String,
    /// SHA-256 of the SCV JSON file (hex). When both the recorded and the current settings have it and
    /// they match, the SCV path may differ (the same search on another machine).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scv_sha256: Option<String>,
}

/// How to run a search.
#[derive(Clone, Debug)]
pub struct SearchRun {
    /// Output directory.
    pub dir: PathBuf,
    /// Total number of trials (trials `0..trials`).
    pub trials: usize,
    /// Trials trained at the same time.
    pub parallel: usize,
    /// Threads over all trials (each trial gets `threads_total / parallel`, ≥ 1).
    pub threads_total: usize,
    /// Continue the search in `dir`.
    pub resume: bool,
}

/// Why a search failed (a failing trial is recorded, not an error).
#[derive(Debug, thiserror::Error)]
pub enum SearchError {
    /// Loading or splitting the data failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// A file in the search directory could not be read or written.
    #[error("{path}: {detail}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// A resume with settings that differ from the ones recorded.
    #[error(
        "--resume: {path} was made with {key} = {recorded}, this run has {given}; use another --out directory"
    )]
    Settings {
        /// `search.json`.
        path: PathBuf,
        /// The differing setting.
        key: String,
        /// Recorded value.
        recorded: String,
        /// This run's value.
        given: String,
    },
    /// Invalid options.
    #[error("{0}")]
    Usage(String),
}

/// The lock file of a search directory (its content: the last holder's PID).
pub const LOCK_FILE: &str = ".search.lock";

/// Takes `dir`'s lock (`flock` on `DIR/.search.lock`, held until the returned file is dropped or
/// the process ends in any way, SIGKILL included): `exclusive` for a whole search ([`run_search`],
/// [`finish`]), shared for [`run_trials`] (several schedulers' workers may share a directory, but
/// not with a running search or a `finish`). Refused, naming the holder's PID, when another
/// process holds it in a conflicting way.
fn lock_dir(dir: &Path, exclusive: bool) -> Result<std::fs::File, SearchError> {
    use std::io::{Seek, Write};
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join(LOCK_FILE);
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .map_err(|e| ferr(&path, format!("cannot open the lock file: {e}")))?;
    let taken = if exclusive {
        f.try_lock()
    } else {
        f.try_lock_shared()
    };
    match taken {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            let holder = holder.trim();
            return Err(ferr(
                dir,
                format!(
                    "another `frictl search` (pid {}) is using this directory (it holds {}); wait \
                     for it to end or use another --out",
                    if holder.is_empty() { "unknown" } else { holder },
                    path.display()
                ),
            ));
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(ferr(&path, format!("cannot lock: {e}")));
        }
    }
    if exclusive {
        f.set_len(0)
            .and_then(|()| f.rewind())
            .and_then(|()| writeln!(f, "{}", std::process::id()))
            .map_err(|e| ferr(&path, format!("cannot write: {e}")))?;
    }
    Ok(f)
}

/// Whether `done` holds an `ok` record of trial `k` (a trial recorded only as failed runs again).
fn has_ok(done: &[TrialResult], k: usize) -> bool {
    done.iter().any(|r| r.params.trial == k && r.status == "ok")
}

fn ferr(path: &Path, detail: impl std::fmt::Display) -> SearchError {
    SearchError::File {
        path: path.to_path_buf(),
        detail: detail.to_string(),
    }
}

/// Reads `results.jsonl` (missing file: empty). A torn last line (crash mid-write) is ignored.
pub fn read_results(path: &Path) -> Result<Vec<TrialResult>, SearchError> {
    let text = match frictionless::regular_file::read_to_string(path, u64::MAX) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(ferr(path, format!("cannot read: {e}"))),
    };
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut out = Vec::with_capacity(lines.len());
    for (i, l) in lines.iter().enumerate() {
        match serde_json::from_str::<TrialResult>(l) {
            Ok(r) => out.push(r),
            Err(_) if i + 1 == lines.len() && !text.ends_with('\n') => {}
            Err(e) => return Err(ferr(path, format!("line {}: {e}", i + 1))),
        }
    }
    Ok(out)
}

fn compare_settings(
    path: &Path,
    rec: &SearchSettings,
    now: &SearchSettings,
) -> Result<(), SearchError> {
    let a = serde_json::to_value(rec).map_err(|e| ferr(path, e))?;
    let b = serde_json::to_value(now).map_err(|e| ferr(path, e))?;
    // Paths name the content only on one machine; the hashes name it everywhere.
    let same_scv = rec.scv_sha256.is_some() && rec.scv_sha256 == now.scv_sha256;
    if let (Some(a), Some(b)) = (a.as_object(), b.as_object()) {
        for (k, va) in a {
            let one_scv_hash = rec.scv_sha256.is_none() || now.scv_sha256.is_none();
            if k == "datasets" || (k == "scv_sha256" && one_scv_hash) || (k == "scv" && same_scv) {
                continue;
            }
            let vb = b.get(k).cloned().unwrap_or(serde_json::Value::Null);
            if *va != vb {
                return Err(SearchError::Settings {
                    path: path.to_path_buf(),
                    key: k.clone(),
                    recorded: va.to_string(),
                    given: vb.to_string(),
                });
            }
        }
    }
    Ok(())
}

/// Sorts by validation RMSE (ok trials first, ascending; then failed ones by trial index).
pub fn rank(results: &mut [TrialResult]) {
    results.sort_by(|a, b| {
        let key = |r: &TrialResult| match (r.status.as_str(), r.val_rmse_nm) {
            ("ok", Some(v)) if v.is_finite() => (0, v),
            _ => (1, 0.0),
        };
        let (ka, kb) = (key(a), key(b));
        ka.0.cmp(&kb.0)
            .then(ka.1.total_cmp(&kb.1))
            .then(a.params.trial.cmp(&b.params.trial))
    });
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

fn write_tables(dir: &Path, ranked: &[TrialResult]) -> Result<(), SearchError> {
    let jp = dir.join("results.json");
    let json = serde_json::to_string_pretty(ranked).map_err(|e| ferr(&jp, e))?;
    frictionless::output_file::write(&jp, json)
        .map_err(|e| ferr(&jp, format!("cannot write: {e}")))?;
    let cp = dir.join("results.csv");
    let mut w = csv::Writer::from_writer(
        frictionless::output_file::AtomicFile::create(&cp)
            .map_err(|e| ferr(&cp, format!("cannot write: {e}")))?,
    );
    let io = |e: csv::Error| ferr(&cp, e);
    w.write_record([
        "rank",
        "trial",
        "status",
        "val_rmse_nm",
        "test_rmse_nm",
        "train_rmse_nm",
        "best_epoch",
        "epochs_run",
        "batch_size",
        "hidden0",
        "hidden1",
        "lr",
        "history",
        "lambda",
        "dropout",
        "seed",
        "seconds",
        "model",
        "error",
        "hot_us",
        "cold_us",
    ])
    .map_err(io)?;
    for (i, r) in ranked.iter().enumerate() {
        let p = &r.params;
        w.write_record([
            (i + 1).to_string(),
            p.trial.to_string(),
            r.status.clone(),
            opt(r.val_rmse_nm),
            opt(r.test_rmse_nm),
            opt(r.train_rmse_nm),
            r.best_epoch.map_or(String::new(), |e| e.to_string()),
            r.epochs_run.to_string(),
            p.batch_size.to_string(),
            p.hidden.first().map_or(String::new(), |h| h.to_string()),
            p.hidden.get(1).map_or(String::new(), |h| h.to_string()),
            p.lr.to_string(),
            p.history.to_string(),
            p.lambda.to_string(),
            p.dropout.to_string(),
            p.seed.to_string(),
            format!("{:.3}", r.seconds),
            r.model.clone().unwrap_or_default(),
            r.error.clone().unwrap_or_default(),
            opt(r.hot_us),
            opt(r.cold_us),
        ])
        .map_err(io)?;
    }
    w.into_inner()
        .map_err(|e| ferr(&cp, format!("cannot write: {}", e.error())))?
        .commit()
        .map_err(|e| ferr(&cp, format!("cannot write: {e}")))
}

/// Copies `src` to `dst` through [`frictionless::output_file`] (atomic; never over a device or
/// through a symlink).
fn copy_file(src: &Path, dst: &Path) -> Result<(), SearchError> {
    let bytes = frictionless::regular_file::read(src, u64::MAX)
        .map_err(|e| ferr(src, format!("cannot read: {e}")))?;
    frictionless::output_file::write(dst, bytes)
        .map_err(|e| ferr(dst, format!("cannot write: {e}")))
}

#[allow(clippy::too_many_arguments)]
fn run_trial(
    dir: &Path,
    sources: &Sources,
    scv: &ScvPrior,
    split: &Split,
    settings: &SearchSettings,
    params: &TrialParams,
    threads: usize,
) -> TrialResult {
    let started = Instant::now();
    let rel = format!("trials/trial_{:04}.fwt", params.trial);
    let model_path = dir.join(&rel);
    let spec = FeatureSpec {
        set: settings.features,
        history: params.history,
        temperature: settings.temperature,
    };
    let job = Job {
        spec,
        warmup: settings.warmup,
        delta_theta_offset: settings.delta_theta_offset,
        config: TrainConfig {
            hidden: params.hidden.clone(),
            dropout: params.dropout,
            lambda: params.lambda,
            lr: params.lr,
            batch_size: params.batch_size,
            epochs: settings.epochs,
            seed: params.seed,
            threads,
            patience: settings.patience,
            abort_loss: Some(1000.0),
        },
        dtype: settings.dtype,
        checkpoint: None,
        checkpoint_every: 1,
        resume: false,
        init: None,
    };
    let result = (|| -> Result<pipeline::Trained, PipelineError> {
        let prepared = pipeline::prepare(
            sources,
            scv,
            split,
            &spec,
            settings.warmup,
            settings.delta_theta_offset,
        )?;
        let mut trained = pipeline::train_model(
            sources,
            scv,
            split,
            &settings.split,
            &prepared,
            &job,
            |_| ControlFlow::Continue(()),
        )?;
        pipeline::write_outputs(
            &mut trained,
            &model_path,
            &pipeline::default_report_path(&model_path),
        )?;
        Ok(trained)
    })();
    match result {
        Ok(t) => {
            let (hot_us, cold_us) = inference_us(&t.model).unzip();
            TrialResult {
                params: params.clone(),
                status: "ok".into(),
                error: None,
                val_rmse_nm: t.report.rmse_nm.val,
                test_rmse_nm: t.report.rmse_nm.test,
                train_rmse_nm: t.report.rmse_nm.train,
                best_epoch: Some(t.report.best_epoch),
                epochs_run: t.report.epochs.len(),
                seconds: started.elapsed().as_secs_f64(),
                model: Some(rel),
                hot_us,
                cold_us,
            }
        }
        Err(e) => TrialResult {
            params: params.clone(),
            status: "failed".into(),
            error: Some(e.to_string()),
            val_rmse_nm: None,
            test_rmse_nm: None,
            train_rmse_nm: None,
            best_epoch: None,
            epochs_run: 0,
            seconds: started.elapsed().as_secs_f64(),
            model: None,
            hot_us: None,
            cold_us: None,
        },
    }
}

/// Runs (or resumes) a search; `on_trial` is called after each finished trial (from worker threads).
/// Returns every trial of `0..run.trials` found or run, ranked.
pub fn run_search(
    sources: &Sources,
    scv: &ScvPrior,
    settings: &SearchSettings,
    run: &SearchRun,
    on_trial: impl Fn(&TrialResult) + Sync,
) -> Result<Vec<TrialResult>, SearchError> {
    if run.parallel == 0 || run.trials == 0 {
        return Err(SearchError::Usage(format!(
            "--trials = {} and --parallel = {} must be ≥ 1",
            run.trials, run.parallel
        )));
    }
    if settings.split.val_frac <= 0.0 {
        return Err(SearchError::Usage(format!(
            "--val-frac = {}: the search selects on validation RMSE and needs a validation set",
            settings.split.val_frac
        )));
    }
    let dir = &run.dir;
    std::fs::create_dir_all(dir.join("trials"))
        .map_err(|e| ferr(&dir.join("trials"), format!("cannot create: {e}")))?;
    let _lock = lock_dir(dir, true)?;
    let settings_path = dir.join("search.json");
    let results_path = dir.join("results.jsonl");
    let done = if run.resume {
        match frictionless::regular_file::read_text(&settings_path) {
            Ok(t) => {
                let rec: SearchSettings =
                    serde_json::from_str(&t).map_err(|e| ferr(&settings_path, e))?;
                compare_settings(&settings_path, &rec, settings)?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(ferr(&settings_path, format!("cannot read: {e}"))),
        }
        read_results(&results_path)?
    } else {
        if read_results(&results_path)?.iter().any(|_| true) {
            return Err(ferr(
                &results_path,
                "holds finished trials: pass --resume to continue this search, or use another --out",
            ));
        }
        Vec::new()
    };
    let json = serde_json::to_string_pretty(settings).map_err(|e| ferr(&settings_path, e))?;
    frictionless::output_file::write(&settings_path, json)
        .map_err(|e| ferr(&settings_path, format!("cannot write: {e}")))?;
    let split = pipeline::split_for(sources, &settings.split)?;
    let pending: Vec<TrialParams> = (0..run.trials)
        .filter(|k| !has_ok(&done, *k))
        .map(|k| draw(&settings.space, settings.seed, k))
        .collect();
    let file = frictionless::output_file::open_append(&results_path)
        .map_err(|e| ferr(&results_path, format!("cannot open: {e}")))?;
    let sink = Mutex::new((file, None::<SearchError>));
    let next = AtomicUsize::new(0);
    let threads = (run.threads_total / run.parallel).max(1);
    let finished = Mutex::new(Vec::new());
    std::thread::scope(|sc| {
        for _ in 0..run.parallel.min(pending.len()) {
            sc.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(p) = pending.get(i) else { break };
                    let r = run_trial(dir, sources, scv, &split, settings, p, threads);
                    {
                        let mut g = sink.lock().unwrap_or_else(|e| e.into_inner());
                        let line = serde_json::to_string(&r).unwrap_or_default() + "\n";
                        if let Err(e) = g.0.write_all(line.as_bytes()).and_then(|_| g.0.flush()) {
                            g.1 = Some(ferr(&results_path, format!("cannot append: {e}")));
                        }
                    }
                    on_trial(&r);
                    finished.lock().unwrap_or_else(|e| e.into_inner()).push(r);
                }
            });
        }
    });
    let (_, write_err) = sink.into_inner().unwrap_or_else(|e| e.into_inner());
    if let Some(e) = write_err {
        return Err(e);
    }
    let all: Vec<TrialResult> = done
        .into_iter()
        .chain(finished.into_inner().unwrap_or_else(|e| e.into_inner()))
        .filter(|r| r.params.trial < run.trials)
        .collect();
    publish(dir, all)
}

/// One record per trial: an `ok` record wins over a `failed` one, a later record over an earlier one
/// of the same status (a trial run twice, e.g. a retried cluster task).
pub fn dedup(results: Vec<TrialResult>) -> Vec<TrialResult> {
    let mut by_trial: std::collections::BTreeMap<usize, TrialResult> = Default::default();
    for r in results {
        let keep_old = by_trial
            .get(&r.params.trial)
            .is_some_and(|old| old.status == "ok" && r.status != "ok");
        if !keep_old {
            by_trial.insert(r.params.trial, r);
        }
    }
    by_trial.into_values().collect()
}

/// Ranks `all` (after [`dedup`]), writes `results.json` / `results.csv` and copies the best model to
/// `best.fwt` (+ `best.train.json`).
fn publish(dir: &Path, all: Vec<TrialResult>) -> Result<Vec<TrialResult>, SearchError> {
    let mut all = dedup(all);
    rank(&mut all);
    write_tables(dir, &all)?;
    if let Some(best) = all.first().filter(|r| r.status == "ok")
        && let Some(m) = &best.model
    {
        let src = dir.join(m);
        let dst = dir.join("best.fwt");
        copy_file(&src, &dst)?;
        let rsrc = pipeline::default_report_path(&src);
        let rdst = dir.join("best.train.json");
        copy_file(&rsrc, &rdst)?;
    }
    Ok(all)
}

/// Copies the trial [`cheapest_within`] picks to `DIR/pick.fwt` (+ `DIR/pick.train.json`) and
/// returns it; `None` (nothing written) when no ok trial was timed.
pub fn publish_pick(
    dir: &Path,
    all: &[TrialResult],
    max_rmse_ratio: f64,
) -> Result<Option<TrialResult>, SearchError> {
    if !(max_rmse_ratio.is_finite() && max_rmse_ratio >= 1.0) {
        return Err(SearchError::Usage(format!(
            "--max-rmse-ratio {max_rmse_ratio}: must be finite and ≥ 1"
        )));
    }
    let Some(pick) = cheapest_within(all, max_rmse_ratio) else {
        return Ok(None);
    };
    if let Some(m) = &pick.model {
        let src = dir.join(m);
        for (from, to) in [
            (src.clone(), dir.join("pick.fwt")),
            (
                pipeline::default_report_path(&src),
                dir.join("pick.train.json"),
            ),
        ] {
            std::fs::copy(&from, &to)
                .map_err(|e| ferr(&to, format!("cannot copy {}: {e}", from.display())))?;
        }
    }
    Ok(Some(pick.clone()))
}

/// `DIR/search.json`: written when absent (exclusive create, so concurrent starters agree on one),
/// else compared with `settings` (paths may differ where the hashes match).
fn claim_settings(dir: &Path, settings: &SearchSettings) -> Result<(), SearchError> {
    let path = dir.join("search.json");
    let json = serde_json::to_string_pretty(settings).map_err(|e| ferr(&path, e))?;
    let tmp = dir.join(format!(".search.json.{}", std::process::id()));
    std::fs::write(&tmp, &json).map_err(|e| ferr(&tmp, format!("cannot write: {e}")))?;
    // link(2) fails if search.json exists: whoever links first defines the search. File systems
    // without hard links get an exclusive create instead (a concurrent reader may then see it empty).
    let linked = match std::fs::hard_link(&tmp, &path) {
        Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .and_then(|mut f| f.write_all(json.as_bytes())),
        other => other,
    };
    let _ = std::fs::remove_file(&tmp);
    match linked {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            let text = frictionless::regular_file::read_text(&path)
                .map_err(|e| ferr(&path, format!("cannot read: {e}")))?;
            let rec: SearchSettings = serde_json::from_str(&text).map_err(|e| ferr(&path, e))?;
            compare_settings(&path, &rec, settings)
        }
        Err(e) => Err(ferr(&path, format!("cannot create: {e}"))),
    }
}

/// Appends one result to `results.jsonl`: the file opened with `O_APPEND` and the line written by
/// one `write(2)`, so lines of concurrent writers on one file system never interleave.
pub fn append_result(path: &Path, r: &TrialResult) -> Result<(), SearchError> {
    let line = serde_json::to_string(r).map_err(|e| ferr(path, e))? + "\n";
    let mut f = frictionless::output_file::open_append(path)
        .map_err(|e| ferr(path, format!("cannot open: {e}")))?;
    match f.write(line.as_bytes()) {
        Ok(n) if n == line.len() => Ok(()),
        Ok(n) => Err(ferr(
            path,
            format!("short append ({n} of {} bytes)", line.len()),
        )),
        Err(e) => Err(ferr(path, format!("cannot append: {e}"))),
    }
}

/// Runs exactly the trials `trials` of the search in `dir` (the entry point of an external
/// scheduler): `search.json` is written if absent, else must match `settings`; trials recorded `ok`
/// in `results.jsonl` are skipped (failed ones run again); each finished trial is appended as it ends, one after the other, each
/// with `threads` threads. Writes no tables (see [`finish`]). Returns the trials run.
pub fn run_trials(
    sources: &Sources,
    scv: &ScvPrior,
    settings: &SearchSettings,
    dir: &Path,
    trials: &[usize],
    threads: usize,
    on_trial: impl Fn(&TrialResult),
) -> Result<Vec<TrialResult>, SearchError> {
    if settings.split.val_frac <= 0.0 {
        return Err(SearchError::Usage(format!(
            "--val-frac = {}: the search selects on validation RMSE and needs a validation set",
            settings.split.val_frac
        )));
    }
    std::fs::create_dir_all(dir.join("trials"))
        .map_err(|e| ferr(&dir.join("trials"), format!("cannot create: {e}")))?;
    let _lock = lock_dir(dir, false)?;
    claim_settings(dir, settings)?;
    let results_path = dir.join("results.jsonl");
    let done = read_results(&results_path)?;
    let split = pipeline::split_for(sources, &settings.split)?;
    let mut ran = Vec::new();
    for &k in trials {
        if has_ok(&done, k) || ran.iter().any(|r: &TrialResult| r.params.trial == k) {
            continue;
        }
        let p = draw(&settings.space, settings.seed, k);
        let r = run_trial(dir, sources, scv, &split, settings, &p, threads.max(1));
        append_result(&results_path, &r)?;
        on_trial(&r);
        ran.push(r);
    }
    Ok(ran)
}

/// Publishes the tables of whatever `dir/results.jsonl` holds (trials `< trials` when given):
/// `results.json`, `results.csv`, `best.fwt` (+ `best.train.json`), as [`run_search`] does at its end.
pub fn finish(dir: &Path, trials: Option<usize>) -> Result<Vec<TrialResult>, SearchError> {
    let results_path = dir.join("results.jsonl");
    if !results_path.is_file() {
        return Err(ferr(&results_path, "no such file: not a search directory"));
    }
    let _lock = lock_dir(dir, true)?;
    let all = read_results(&results_path)?
        .into_iter()
        .filter(|r| trials.is_none_or(|n| r.params.trial < n))
        .collect();
    publish(dir, all)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_stay_in_the_paper_ranges_and_depend_only_on_seed_and_index() {
        let sp = SearchSpace::default();
        let mut lrs = Vec::new();
        for k in 0..500 {
            let p = draw(&sp, 11, k);
            assert!((3000..=5000).contains(&p.batch_size));
            assert!(p.hidden.iter().all(|h| (150..=300).contains(h)));
            assert!((1e-5..=1e-3).contains(&p.lr), "lr {}", p.lr);
            assert!((3..=30).contains(&p.history));
            assert!((0.1..=0.5).contains(&p.lambda));
            assert!((0.01..=0.1).contains(&p.dropout));
            assert_eq!(p, draw(&sp, 11, k), "pure function of (seed, index)");
            lrs.push(p.lr.log10());
        }
        // Log-uniform: about half the draws below 1e-4 (the log-midpoint).
        let below = lrs.iter().filter(|&&l| l < -4.0).count();
        assert!((200..300).contains(&below), "{below} of 500 below 1e-4");
        assert_ne!(draw(&sp, 11, 0), draw(&sp, 12, 0));
    }

    fn timed(trial: usize, status: &str, rmse: f64, us: f64) -> TrialResult {
        TrialResult {
            params: draw(&SearchSpace::default(), 0, trial),
            status: status.into(),
            error: None,
            val_rmse_nm: Some(rmse),
            test_rmse_nm: None,
            train_rmse_nm: None,
            best_epoch: None,
            epochs_run: 1,
            seconds: 0.0,
            model: None,
            hot_us: Some(us),
            cold_us: None,
        }
    }

    #[test]
    fn pareto_front_keeps_only_non_dominated_trials_fastest_first() {
        let r = vec![
            timed(0, "ok", 0.10, 3.0),      // most accurate, slowest
            timed(1, "ok", 0.12, 1.0),      // front
            timed(2, "ok", 0.12, 1.5),      // dominated by 1 (same RMSE, slower)
            timed(3, "ok", 0.20, 0.3),      // fastest
            timed(4, "ok", 0.25, 0.5),      // dominated by 3
            timed(5, "failed", 0.01, 0.01), // failed: never on the front
            timed(6, "ok", f64::NAN, 0.1),
        ];
        let front: Vec<usize> = pareto_front(&r).iter().map(|t| t.params.trial).collect();
        assert_eq!(front, vec![3, 1, 0]);
        // Equal points do not dominate each other.
        let tie = vec![timed(0, "ok", 0.1, 1.0), timed(1, "ok", 0.1, 1.0)];
        assert_eq!(pareto_front(&tie).len(), 2);
    }

    #[test]
    fn cheapest_within_picks_the_fastest_trial_inside_the_ratio() {
        let r = vec![
            timed(0, "ok", 0.100, 3.0),
            timed(1, "ok", 0.104, 1.0),
            timed(2, "ok", 0.104, 1.2),
            timed(3, "ok", 0.110, 0.3),
        ];
        assert_eq!(cheapest_within(&r, 1.05).unwrap().params.trial, 1);
        assert_eq!(cheapest_within(&r, 1.0).unwrap().params.trial, 0);
        assert_eq!(cheapest_within(&r, 1.2).unwrap().params.trial, 3);
        assert!(cheapest_within(&[], 1.05).is_none());
        let mut untimed = r.clone();
        untimed.iter_mut().for_each(|t| t.hot_us = None);
        assert!(cheapest_within(&untimed, 1.05).is_none());
    }

    #[test]
    fn rank_puts_best_validation_first_and_failures_last() {
        let mk = |trial, status: &str, v: Option<f64>| TrialResult {
            params: draw(&SearchSpace::default(), 0, trial),
            status: status.into(),
            error: None,
            val_rmse_nm: v,
            test_rmse_nm: None,
            train_rmse_nm: None,
            best_epoch: None,
            epochs_run: 0,
            seconds: 0.0,
            model: None,
            hot_us: None,
            cold_us: None,
        };
        let mut r = vec![
            mk(0, "failed", None),
            mk(1, "ok", Some(0.5)),
            mk(2, "ok", Some(0.2)),
            mk(3, "ok", Some(f64::NAN)),
        ];
        rank(&mut r);
        let order: Vec<usize> = r.iter().map(|t| t.params.trial).collect();
        assert_eq!(order, vec![2, 1, 0, 3]);
    }

    fn settings(datasets: &str, scv: &str, scv_sha: Option<&str>, epochs: usize) -> SearchSettings {
        let mut v: serde_json::Value = serde_json::from_str(
            r#"{"space": {"batch": [256, 512], "hidden": [8, 16], "lr": [1e-05, 0.001],
            "history": [3, 8], "lambda": [0.1, 0.5], "dropout": [0.01, 0.1]}, "seed": 3,
            "epochs": 2, "features": "delta_theta_joint_vel", "temperature": false,
            "warmup": "hold_zero", "delta_theta_offset": "run", "dtype": "f32", "patience": null,
            "split": {"val_frac": 0.15, "test_frac": 0.15, "seed": 3, "test_chunks": null},
            "datasets": [], "dataset_sha256": "ab", "scv": ""}"#,
        )
        .unwrap();
        v["datasets"] = serde_json::json!([datasets]);
        v["scv"] = scv.into();
        v["epochs"] = epochs.into();
        if let Some(h) = scv_sha {
            v["scv_sha256"] = h.into();
        }
        serde_json::from_value(v).unwrap()
    }

    #[test]
    fn settings_compare_by_content_where_hashes_are_recorded() {
        let p = Path::new("search.json");
        let here = settings("/a/ds.csv", "/a/scv.json", Some("11"), 2);
        // Same content elsewhere: accepted.
        compare_settings(
            p,
            &here,
            &settings("/b/ds.csv", "/b/scv.json", Some("11"), 2),
        )
        .unwrap();
        // Another SCV content, or any other setting: refused, naming the key.
        let e = compare_settings(
            p,
            &here,
            &settings("/a/ds.csv", "/a/scv.json", Some("22"), 2),
        );
        assert!(e.unwrap_err().to_string().contains("scv_sha256"));
        let e = compare_settings(
            p,
            &here,
            &settings("/a/ds.csv", "/a/scv.json", Some("11"), 3),
        );
        assert!(e.unwrap_err().to_string().contains("epochs"));
        // A search recorded without the SCV hash still compares the SCV path.
        let old = settings("/a/ds.csv", "/a/scv.json", None, 2);
        compare_settings(p, &old, &here).unwrap();
        let e = compare_settings(
            p,
            &old,
            &settings("/b/ds.csv", "/b/scv.json", Some("11"), 2),
        );
        assert!(e.unwrap_err().to_string().contains("scv"));
    }

    #[test]
    fn dedup_keeps_one_record_per_trial_an_ok_one_first() {
        let mk = |trial, status: &str, v: Option<f64>| TrialResult {
            params: draw(&SearchSpace::default(), 0, trial),
            status: status.into(),
            error: None,
            val_rmse_nm: v,
            test_rmse_nm: None,
            train_rmse_nm: None,
            best_epoch: None,
            epochs_run: 0,
            seconds: 0.0,
            model: None,
            hot_us: None,
            cold_us: None,
        };
        let d = dedup(vec![
            mk(1, "ok", Some(0.5)),
            mk(0, "failed", None),
            mk(1, "failed", None),
            mk(0, "ok", Some(0.3)),
            mk(2, "ok", Some(0.4)),
            mk(2, "ok", Some(0.6)),
        ]);
        let got: Vec<(usize, &str, Option<f64>)> = d
            .iter()
            .map(|r| (r.params.trial, r.status.as_str(), r.val_rmse_nm))
            .collect();
        assert_eq!(
            got,
            [
                (0, "ok", Some(0.3)),
                (1, "ok", Some(0.5)),
                (2, "ok", Some(0.6))
            ]
        );
    }
}
