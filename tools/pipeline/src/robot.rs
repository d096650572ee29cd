//! The robot-level pipeline description (`frictl robot run ROBOT.toml`): one TOML file listing every
//! joint (a simulator preset, `frictl acquire` logs, the robot's own logs or preprocessed datasets;
//! the URDF joint name, the signed gear ratio, k_t, the feature set, the daemon's per-joint limits)
//! and the search space shared by all. Every key: `docs/robot-file.md`.
//!
//! What this module **is**: the typed schema ([`RobotFile`], `deny_unknown_fields` everywhere),
//! [`load`] / [`parse`] with [`RobotError`] naming the file, the key and the value, and the checks
//! serde cannot express (unique names, exactly one data source per joint, ranges ordered).
//!
//! What it is **not**: it runs nothing; the pipeline ([`crate::robot_run`]) turns a joint into
//! `frictl` stages, and the Ray driver (`python/ray/frictl_ray.py`) reads the same plan.
//!
//! ```toml
//! [search]                      # trials = 0: one `frictl train` with [train] instead
//! trials = 4
//! epochs = 2
//! hidden = [8, 16]              # every range MIN, MAX (defaults: the paper's)
//!
//! [[joint]]
//! name = "l_knee"               # URDF joint name, the name frictiond and the model carry
//! preset = "knee"               # or logs = [...] (`frictl acquire` logs), datasets = [...]
//!                               # (preprocessed) or the robot's own logs ([import] below)
//! gear_ratio = -100.0           # signed
//! kt_nm_per_a = 0.157
//! max_curr_a = 5.0
//! features = "delta-theta-joint-vel"  # any of the core's feature sets (default the paper's)
//! motor_encoder = "incremental" # or "absolute" (default): does θ keep its zero across power-ups
//! temperature = false           # the motor temperature as one more input
//!
//! [import]                      # the robot's own logs, for every joint without another source
//! format = "csv"                # csv | mat | mcap: `frictl import FORMAT`
//! logs = ["walk.csv"]           # one recording or many (one run each); test_logs = [...] held out
//! column = { time = "t", s = "q_{joint}", current = "i_{joint}" }  # any other key: an import option
//! ```

use std::path::{Path, PathBuf};

use frictionless::features::FeatureSet;
use serde::{Deserialize, Serialize};

/// Why a robot file is refused.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not TOML of this schema (toml names the key and shows the value).
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// toml's message (line, key, what was expected).
        message: String,
    },
    /// A value serde accepted but the pipeline cannot use.
    #[error("{path}: {key} = {value}: {requirement}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted key, e.g. `joint[1].gear_ratio`.
        key: String,
        /// The value as written.
        value: String,
        /// What it must be.
        requirement: String,
    },
}

/// The whole file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFile {
    /// `[robot]`: name and seed.
    #[serde(default)]
    pub robot: RobotSection,
    /// `[acquire]`: settings of the simulator acquisition for `preset` joints.
    #[serde(default)]
    pub acquire: AcquireSection,
    /// `[search]`: the random search (every joint).
    #[serde(default)]
    pub search: SearchSection,
    /// `[train]`: the fixed hyper-parameters when `search.trials = 0`.
    #[serde(default)]
    pub train: TrainSection,
    /// `[import]`: the robot's own logs, the data of every joint that names no other source (a
    /// joint's own `import` table extends it).
    #[serde(default)]
    pub import: Option<ImportSection>,
    /// `[[joint]]`, in payload-index order.
    pub joint: Vec<JointSection>,
}

/// `[import]` and a joint's `import`: the robot's own logs, labelled by `frictl import FORMAT` with
/// the joint's name, gear ratio and k_t and the robot's URDF.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ImportSection {
    /// The logs' format: `csv`, `mat` (the YARP robot logger's MATLAB v7.3) or `mcap` (ROS 2).
    #[serde(default)]
    pub format: Option<LogFormat>,
    /// The training recordings (relative to this file), one run each: one recording is enough.
    #[serde(default)]
    pub logs: Vec<PathBuf>,
    /// Held-out recordings for the evaluation (none: the test blocks of `logs`' split).
    #[serde(default)]
    pub test_logs: Vec<PathBuf>,
    /// Every other key is a `frictl import FORMAT` option by its long name (`_` or `-`): a string
    /// or number is its value, `true` the bare flag, an array one flag per element and a table one
    /// `KEY=VALUE` flag per entry (`column = { time = "t" }` is `--column time=t`). `urdf` is
    /// relative to this file (default: `[robot] urdf`).
    #[serde(flatten)]
    pub options: toml::Table,
}

pub use frictl_cli::import_log::LogFormat;

/// The `frictl import` options a robot file sets itself, from the joint: not keys of `import`.
const IMPORT_SET_BY_THE_FILE: [&str; 6] = ["joint", "joints", "out", "o", "gear-ratio", "kt"];

impl ImportSection {
    /// This section with `over`'s keys on top (a joint's table over `[import]`): options key by
    /// key, and its logs (with their held-out logs) when it names any. A table of another format
    /// stands alone: the options of one importer are not another's.
    fn extended_by(&self, over: &ImportSection) -> ImportSection {
        if over.format.is_some() && over.format != self.format {
            return over.clone();
        }
        let mut options = self.options.clone();
        options.extend(over.options.clone());
        let (logs, test_logs) = if over.logs.is_empty() {
            (self.logs.clone(), self.test_logs.clone())
        } else {
            (over.logs.clone(), over.test_logs.clone())
        };
        ImportSection {
            format: over.format.or(self.format),
            logs,
            test_logs,
            options,
        }
    }

    /// The options as `frictl import` words (`--column`, `time=t`, …), keys in file order; a
    /// value no flag can take is refused as (key, value, requirement).
    pub fn option_words(&self) -> Result<Vec<String>, (String, String, String)> {
        let mut words = vec![];
        for (key, value) in &self.options {
            let flag = key.replace('_', "-");
            let refuse = |v: &dyn std::fmt::Debug, why: &str| {
                (key.clone(), format!("{v:?}"), why.to_owned())
            };
            if IMPORT_SET_BY_THE_FILE.contains(&flag.as_str()) {
                return Err(refuse(
                    value,
                    "set by the robot file (the joint's name, gear_ratio and kt_nm_per_a, the output)",
                ));
            }
            if flag.is_empty() || !flag.chars().all(|c| c.is_ascii_alphanumeric() || c == '-') {
                return Err(refuse(key, "a `frictl import` option's long name"));
            }
            let scalar = |v: &toml::Value| match v {
                toml::Value::String(s) => Some(s.clone()),
                toml::Value::Integer(i) => Some(i.to_string()),
                toml::Value::Float(f) => Some(f.to_string()),
                _ => None,
            };
            let scalar_or =
                |v: &toml::Value| scalar(v).ok_or_else(|| refuse(v, "a string or a number"));
            match value {
                toml::Value::Boolean(true) => words.push(format!("--{flag}")),
                toml::Value::Boolean(false) => {}
                toml::Value::Array(items) => {
                    for v in items {
                        words.push(format!("--{flag}={}", scalar_or(v)?));
                    }
                }
                toml::Value::Table(t) => {
                    for (k, v) in t {
                        words.push(format!("--{flag}={k}={}", scalar_or(v)?));
                    }
                }
                v => words.push(format!("--{flag}={}", scalar_or(v)?)),
            }
        }
        Ok(words)
    }
}

/// `[robot]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// Name (report title).
    #[serde(default = "default_robot_name")]
    pub name: String,
    /// Seed: acquisition (the test run uses seed + 100), split, search draws, training.
    #[serde(default)]
    pub seed: u64,
    /// URDF for preprocessing raw `logs` (relative to this file); absent: link from the log sidecar.
    #[serde(default)]
    pub urdf: Option<PathBuf>,
    /// A directory every Ray worker sees (relative to this file): datasets are exchanged there by
    /// SHA-256 instead of through Ray's object store. Ignored by `frictl robot run`.
    #[serde(default)]
    pub shared_dir: Option<PathBuf>,
}

fn default_robot_name() -> String {
    "robot".into()
}

impl Default for RobotSection {
    fn default() -> Self {
        Self {
            name: default_robot_name(),
            seed: 0,
            urdf: None,
            shared_dir: None,
        }
    }
}

/// `[acquire]`: `frictl acquire --set` overrides.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AcquireSection {
    /// Overrides of the training acquisition (`KEY=VALUE`, e.g. `protocol.n_starts=1`).
    #[serde(default)]
    pub set: Vec<String>,
    /// Overrides of the held-out tracking test acquisition (after the ones that keep only the
    /// tracking test part of the protocol).
    #[serde(default)]
    pub test_set: Vec<String>,
}

/// `[search]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SearchSection {
    /// Trials per joint; 0 = train once with `[train]`.
    #[serde(default = "default_trials")]
    pub trials: usize,
    /// Epochs per trial.
    #[serde(default = "default_epochs")]
    pub epochs: usize,
    /// Threads per trial (1 makes trials reproducible across machines).
    #[serde(default = "one")]
    pub threads_per_trial: usize,
    /// Trials at the same time in `frictl robot run`.
    #[serde(default = "one")]
    pub parallel: usize,
    /// Validation fraction (the selection criterion).
    #[serde(default = "default_frac")]
    pub val_frac: f64,
    /// Test fraction (reported only).
    #[serde(default = "default_frac")]
    pub test_frac: f64,
    /// Early stopping patience \[epochs\].
    #[serde(default)]
    pub patience: Option<usize>,
    /// Batch size range.
    #[serde(default)]
    pub batch: Option<[usize; 2]>,
    /// Hidden width range.
    #[serde(default)]
    pub hidden: Option<[usize; 2]>,
    /// Learning-rate range (log-uniform).
    #[serde(default)]
    pub lr: Option<[f32; 2]>,
    /// History length range.
    #[serde(default)]
    pub history: Option<[usize; 2]>,
    /// λ range.
    #[serde(default)]
    pub lambda: Option<[f32; 2]>,
    /// Dropout range.
    #[serde(default)]
    pub dropout: Option<[f32; 2]>,
    /// Run the search's pick instead of its best trial: the fastest trial (hot µs on this CPU, the
    /// kernel frictiond runs) whose validation RMSE is within `max_rmse_ratio` × the best.
    #[serde(default)]
    pub pick: bool,
    /// The pick's bound on the validation RMSE, as a multiple of the best trial's.
    #[serde(default = "default_max_rmse_ratio")]
    pub max_rmse_ratio: f64,
}

fn default_max_rmse_ratio() -> f64 {
    1.05
}

fn default_trials() -> usize {
    100
}
fn default_epochs() -> usize {
    350
}
fn one() -> usize {
    1
}
fn default_frac() -> f64 {
    0.15
}

impl Default for SearchSection {
    fn default() -> Self {
        Self {
            trials: default_trials(),
            epochs: default_epochs(),
            threads_per_trial: 1,
            parallel: 1,
            val_frac: default_frac(),
            test_frac: default_frac(),
            patience: None,
            batch: None,
            hidden: None,
            lr: None,
            history: None,
            lambda: None,
            dropout: None,
            pick: false,
            max_rmse_ratio: default_max_rmse_ratio(),
        }
    }
}

/// `[train]` (`frictl train`'s defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainSection {
    /// Hidden widths.
    #[serde(default = "default_hidden")]
    pub hidden: Vec<usize>,
    /// History length H.
    #[serde(default = "default_history")]
    pub history: usize,
    /// Epochs.
    #[serde(default = "default_train_epochs")]
    pub epochs: usize,
    /// Batch size.
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// Learning rate.
    #[serde(default = "default_lr")]
    pub lr: f32,
    /// λ.
    #[serde(default = "default_lambda")]
    pub lambda: f32,
    /// Dropout.
    #[serde(default)]
    pub dropout: f32,
}

fn default_hidden() -> Vec<usize> {
    vec![128, 128]
}
fn default_history() -> usize {
    30
}
fn default_train_epochs() -> usize {
    10
}
fn default_batch() -> usize {
    512
}
fn default_lr() -> f32 {
    1e-3
}
fn default_lambda() -> f32 {
    0.01
}

impl Default for TrainSection {
    fn default() -> Self {
        Self {
            hidden: default_hidden(),
            history: default_history(),
            epochs: default_train_epochs(),
            batch: default_batch(),
            lr: default_lr(),
            lambda: default_lambda(),
            dropout: 0.0,
        }
    }
}

fn default_features() -> FeatureSet {
    FeatureSet::DeltaThetaJointVel
}

/// frictiond's τ̂_F low-pass of one joint.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LpfSection {
    /// Butterworth order.
    pub order: usize,
    /// Cut-off \[Hz\].
    pub cutoff_hz: f64,
}

/// One `[[joint]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSection {
    /// URDF joint name (the model and frictiond carry it; must match the data's sidecars).
    pub name: String,
    /// A simulator preset (`knee`, `ankle_roll`): acquired with `frictl acquire`.
    #[serde(default)]
    pub preset: Option<String>,
    /// Raw logs (relative to this file), labelled with `frictl preprocess`.
    #[serde(default)]
    pub logs: Vec<PathBuf>,
    /// Held-out raw logs for the evaluation.
    #[serde(default)]
    pub test_logs: Vec<PathBuf>,
    /// Preprocessed dataset CSVs (their `.json` sidecars next to them).
    #[serde(default)]
    pub datasets: Vec<PathBuf>,
    /// Held-out preprocessed datasets for the evaluation.
    #[serde(default)]
    pub test_datasets: Vec<PathBuf>,
    /// Signed gear ratio r (motor angle per joint angle); checked against the data.
    pub gear_ratio: f64,
    /// Torque constant k_t [Nm/A] of the labels; checked against the data.
    pub kt_nm_per_a: f64,
    /// Input feature set: any of the core's [`FeatureSet`]s by its name (`frictl train --features`;
    /// default the paper's `delta-theta-joint-vel`). A joint without a motor encoder (a torque-sensed
    /// arm) takes `joint-pos-joint-vel` or `joint-vel`.
    #[serde(default = "default_features")]
    pub features: FeatureSet,
    /// Append the motor temperature [°C] as one more input (`frictl train --temperature`; the data
    /// must have a temperature column).
    #[serde(default)]
    pub temperature: bool,
    /// The motor encoder's kind, as frictiond's `[[joint]] motor_encoder`: `absolute` (default; one
    /// zero at every power-up, the train report's Δθ offset is configured) or `incremental` (a new
    /// zero at every power-up: a Δθ model is trained latched per chunk and frictiond latches at every
    /// enable).
    #[serde(default)]
    pub motor_encoder: frictiond_config::MotorEncoder,
    /// frictiond's current clamp \[A\].
    pub max_curr_a: f64,
    /// frictiond's friction compensation gain.
    #[serde(default = "default_kfc")]
    pub kfc: f64,
    /// frictiond's friction clip \[Nm\] (absent: none).
    #[serde(default)]
    pub max_output_friction_nm: Option<f64>,
    /// frictiond's τ̂_F low-pass (absent: none).
    #[serde(default)]
    pub lpf: Option<LpfSection>,
    /// Further `frictl preprocess` arguments for this joint's logs.
    #[serde(default)]
    pub preprocess_args: Vec<String>,
    /// The robot's own logs for this joint: `[import]`'s keys with this table's on top. After
    /// [`parse`], the import every joint without another source takes (`[import]` itself when the
    /// joint has no table).
    #[serde(default)]
    pub import: Option<ImportSection>,
}

fn default_kfc() -> f64 {
    1.0
}

/// Where a joint's data comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataSource {
    /// `preset`.
    Preset,
    /// `logs`.
    Logs,
    /// `datasets`.
    Datasets,
    /// `import` (the joint's own or `[import]`).
    Import,
}

impl JointSection {
    /// The one data source of this joint (checked by [`parse`]).
    pub fn source(&self) -> DataSource {
        if self.preset.is_some() {
            DataSource::Preset
        } else if !self.logs.is_empty() {
            DataSource::Logs
        } else if self.import.is_some() {
            DataSource::Import
        } else {
            DataSource::Datasets
        }
    }
}

/// Reads and checks a robot file; relative paths in it are made absolute, relative to its
/// directory (the current directory for a bare file name such as `robot.toml`): the stages run in
/// the output directory, so a path left relative would be looked up there.
pub fn load(path: &Path) -> Result<RobotFile, RobotError> {
    let text = frictionless::regular_file::read_text(path).map_err(|source| RobotError::Read {
        path: path.to_owned(),
        source,
    })?;
    let mut file = parse(path, &text)?;
    let absolute = std::path::absolute(path).map_err(|source| RobotError::Read {
        path: path.to_owned(),
        source,
    })?;
    let base = absolute.parent().unwrap_or(Path::new("/")).to_owned();
    let rebase = |p: &mut PathBuf| {
        if p.is_relative() {
            *p = base.join(&*p);
        }
    };
    for j in &mut file.joint {
        for p in j
            .logs
            .iter_mut()
            .chain(&mut j.test_logs)
            .chain(&mut j.datasets)
            .chain(&mut j.test_datasets)
        {
            rebase(p);
        }
        if let Some(imp) = &mut j.import {
            for p in imp.logs.iter_mut().chain(&mut imp.test_logs) {
                rebase(p);
            }
            if let Some(toml::Value::String(u)) = imp.options.get_mut("urdf") {
                let mut p = PathBuf::from(&*u);
                rebase(&mut p);
                *u = p.display().to_string();
            }
        }
    }
    if let Some(imp) = &mut file.import {
        for p in imp.logs.iter_mut().chain(&mut imp.test_logs) {
            rebase(p);
        }
    }
    if let Some(u) = &mut file.robot.urdf {
        rebase(u);
    }
    if let Some(d) = &mut file.robot.shared_dir {
        rebase(d);
    }
    Ok(file)
}

/// Parses and checks the text of a robot file (`path` names it in errors; paths are left as written).
pub fn parse(path: &Path, text: &str) -> Result<RobotFile, RobotError> {
    let mut file: RobotFile = toml::from_str(text).map_err(|e| RobotError::Parse {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    let bad = |key: String, value: String, req: &str| RobotError::Invalid {
        path: path.to_owned(),
        key,
        value,
        requirement: req.to_owned(),
    };
    if file.joint.is_empty() {
        return Err(bad("joint".into(), "[]".into(), "at least one [[joint]]"));
    }
    check_search(&file, &bad)?;
    check_train(&file, &bad)?;
    check_joints(&file, &bad)?;
    resolve_imports(&mut file, &bad)?;
    Ok(file)
}

/// Gives every joint without another source `[import]` (extended by its own table) and checks each
/// import: a format, at least one log, options that are `frictl import` flags.
fn resolve_imports(file: &mut RobotFile, bad: &Bad) -> Result<(), RobotError> {
    let robot = file.import.clone();
    if let Some(r) = &robot {
        check_import("import", r, bad, false)?;
    }
    for (i, j) in file.joint.iter_mut().enumerate() {
        let other = j.preset.is_some() || !j.logs.is_empty() || !j.datasets.is_empty();
        if other {
            continue;
        }
        j.import = match (&robot, &j.import) {
            (Some(r), Some(own)) => Some(r.extended_by(own)),
            (Some(r), None) => Some(r.clone()),
            (None, own) => own.clone(),
        };
        if let Some(imp) = &j.import {
            check_import(&format!("joint[{i}].import"), imp, bad, true)?;
        }
    }
    Ok(())
}

/// One import section (`complete`: as a joint uses it, so it needs a format and logs).
fn check_import(
    at: &str,
    imp: &ImportSection,
    bad: &Bad,
    complete: bool,
) -> Result<(), RobotError> {
    imp.option_words()
        .map_err(|(key, value, why)| bad(format!("{at}.{key}"), value, &why))?;
    if complete && imp.format.is_none() {
        return Err(bad(
            format!("{at}.format"),
            "(none)".into(),
            "csv, mat or mcap (here or in [import])",
        ));
    }
    if complete && imp.logs.is_empty() {
        return Err(bad(
            format!("{at}.logs"),
            "[]".into(),
            "at least one log (here or in [import])",
        ));
    }
    Ok(())
}

/// A refusal of one key: (key, value, requirement) → the error naming the file.
type Bad<'a> = dyn Fn(String, String, &str) -> RobotError + 'a;

/// `[search]`: its ranges, counts and ratio, and the trainer's own checks of both ends of every
/// range for every joint's inputs.
fn check_search(file: &RobotFile, bad: &Bad) -> Result<(), RobotError> {
    let s = &file.search;
    for (key, lo, hi) in [
        (
            "batch",
            s.batch.map(|r| r[0] as f64),
            s.batch.map(|r| r[1] as f64),
        ),
        (
            "hidden",
            s.hidden.map(|r| r[0] as f64),
            s.hidden.map(|r| r[1] as f64),
        ),
        ("lr", s.lr.map(|r| r[0] as f64), s.lr.map(|r| r[1] as f64)),
        (
            "history",
            s.history.map(|r| r[0] as f64),
            s.history.map(|r| r[1] as f64),
        ),
        (
            "lambda",
            s.lambda.map(|r| r[0] as f64),
            s.lambda.map(|r| r[1] as f64),
        ),
        (
            "dropout",
            s.dropout.map(|r| r[0] as f64),
            s.dropout.map(|r| r[1] as f64),
        ),
    ] {
        if let (Some(lo), Some(hi)) = (lo, hi)
            && !(lo <= hi && lo >= 0.0 && (key == "lambda" || key == "dropout" || lo > 0.0))
        {
            return Err(bad(
                format!("search.{key}"),
                format!("[{lo}, {hi}]"),
                "[MIN, MAX] with 0 < MIN ≤ MAX (0 ≤ MIN for lambda and dropout)",
            ));
        }
    }
    if s.trials > frictl_cli::count::MAX_TRIALS {
        return Err(bad(
            "search.trials".into(),
            s.trials.to_string(),
            &format!(
                "at most {} (`frictl search --trials`'s bound)",
                frictl_cli::count::MAX_TRIALS
            ),
        ));
    }
    if s.epochs == 0 || s.threads_per_trial == 0 || s.parallel == 0 {
        return Err(bad(
            "search".into(),
            format!(
                "epochs {}, threads_per_trial {}, parallel {}",
                s.epochs, s.threads_per_trial, s.parallel
            ),
            "each ≥ 1",
        ));
    }
    if !(s.max_rmse_ratio.is_finite() && s.max_rmse_ratio >= 1.0) {
        return Err(bad(
            "search.max_rmse_ratio".into(),
            s.max_rmse_ratio.to_string(),
            "finite and ≥ 1 (a multiple of the best validation RMSE)",
        ));
    }
    check_search_space(file, bad)?;
    if s.pick && s.trials == 0 {
        return Err(bad(
            "search.pick".into(),
            "true".into(),
            "needs a search (trials ≥ 1): with trials = 0 the joint is trained once",
        ));
    }
    if s.trials > 0 && s.val_frac <= 0.0 {
        return Err(bad(
            "search.val_frac".into(),
            s.val_frac.to_string(),
            "> 0 (the search selects on validation RMSE)",
        ));
    }
    Ok(())
}

/// `[search]`'s ranges as the trainer checks them, for every joint's inputs.
fn check_search_space(file: &RobotFile, bad: &Bad) -> Result<(), RobotError> {
    let s = &file.search;
    // The trainer's own checks, before any stage: both ends of every search range, and `[train]`
    // key by key (before: history 0, hidden [0] or lr −1 failed at the train stage, naming the
    // child's flag).
    let d = frictionless_train::search::SearchSpace::default();
    let space = frictionless_train::search::SearchSpace {
        batch: s.batch.map_or(d.batch, |r| (r[0], r[1])),
        hidden: s.hidden.map_or(d.hidden, |r| (r[0], r[1])),
        lr: s.lr.map_or(d.lr, |r| (r[0], r[1])),
        history: s.history.map_or(d.history, |r| (r[0], r[1])),
        lambda: s.lambda.map_or(d.lambda, |r| (r[0], r[1])),
        dropout: s.dropout.map_or(d.dropout, |r| (r[0], r[1])),
    };
    if s.trials > 0 {
        for j in &file.joint {
            space.validate(j.features, j.temperature).map_err(|e| {
                bad(
                    format!("search.{}", e.range),
                    format!("[{}]", e.value.replace(',', ", ")),
                    &e.why,
                )
            })?;
        }
    }
    Ok(())
}

/// `[train]` key by key with the trainer's own checks, and its history with every joint's inputs.
fn check_train(file: &RobotFile, bad: &Bad) -> Result<(), RobotError> {
    let t = &file.train;
    let base = frictionless_train::TrainConfig {
        hidden: vec![8],
        dropout: 0.0,
        lambda: 0.0,
        lr: 1e-3,
        batch_size: 1,
        epochs: 1,
        seed: 0,
        threads: 1,
        patience: None,
        abort_loss: None,
    };
    let train_keys = [
        (
            "hidden",
            format!("{:?}", t.hidden),
            frictionless_train::TrainConfig {
                hidden: t.hidden.clone(),
                ..base.clone()
            },
        ),
        (
            "epochs",
            t.epochs.to_string(),
            frictionless_train::TrainConfig {
                epochs: t.epochs,
                ..base.clone()
            },
        ),
        (
            "batch",
            t.batch.to_string(),
            frictionless_train::TrainConfig {
                batch_size: t.batch,
                ..base.clone()
            },
        ),
        (
            "lr",
            t.lr.to_string(),
            frictionless_train::TrainConfig {
                lr: t.lr,
                ..base.clone()
            },
        ),
        (
            "lambda",
            t.lambda.to_string(),
            frictionless_train::TrainConfig {
                lambda: t.lambda,
                ..base.clone()
            },
        ),
        (
            "dropout",
            t.dropout.to_string(),
            frictionless_train::TrainConfig {
                dropout: t.dropout,
                ..base.clone()
            },
        ),
    ];
    for (key, value, cfg) in train_keys {
        cfg.validate()
            .map_err(|e| bad(format!("train.{key}"), value, &e.to_string()))?;
    }
    for j in &file.joint {
        frictionless::features::FeatureSpec {
            set: j.features,
            history: t.history,
            temperature: j.temperature,
        }
        .validate()
        .map_err(|e| {
            bad(
                "train.history".into(),
                t.history.to_string(),
                &e.to_string(),
            )
        })?;
    }
    Ok(())
}

/// Every `[[joint]]`: a usable, unique name, exactly one data source, and the drive's constants.
fn check_joints(file: &RobotFile, bad: &Bad) -> Result<(), RobotError> {
    for (i, j) in file.joint.iter().enumerate() {
        let key = |k: &str| format!("joint[{i}].{k}");
        if j.name.is_empty() || j.name.contains(['/', '\\']) || j.name.starts_with('.') {
            return Err(bad(
                key("name"),
                format!("{:?}", j.name),
                "a non-empty joint name usable as a directory name",
            ));
        }
        if file.joint[..i].iter().any(|o| o.name == j.name) {
            return Err(bad(key("name"), format!("{:?}", j.name), "unique"));
        }
        let sources = usize::from(j.preset.is_some())
            + usize::from(!j.logs.is_empty())
            + usize::from(!j.datasets.is_empty());
        let import = j.import.is_some() || file.import.is_some();
        if sources > 1 || sources == 0 && !import || sources == 1 && j.import.is_some() {
            return Err(bad(
                key("preset/logs/datasets/import"),
                format!("{} given", sources + usize::from(j.import.is_some())),
                "exactly one of preset, logs, datasets, import (or none, with an [import] section)",
            ));
        }
        if !j.test_logs.is_empty() && j.logs.is_empty() {
            return Err(bad(
                key("test_logs"),
                format!("{:?}", j.test_logs),
                "only with logs",
            ));
        }
        if !j.test_datasets.is_empty() && j.datasets.is_empty() {
            return Err(bad(
                key("test_datasets"),
                format!("{:?}", j.test_datasets),
                "only with datasets",
            ));
        }
        if !(j.gear_ratio.is_finite() && j.gear_ratio != 0.0) {
            return Err(bad(
                key("gear_ratio"),
                j.gear_ratio.to_string(),
                "finite and non-zero (signed)",
            ));
        }
        for (k, v) in [("kt_nm_per_a", j.kt_nm_per_a), ("max_curr_a", j.max_curr_a)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(key(k), v.to_string(), "finite and > 0"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[search]
trials = 4
epochs = 2
hidden = [8, 16]

[[joint]]
name = "l_knee"
preset = "knee"
gear_ratio = -100.0
kt_nm_per_a = 0.157
max_curr_a = 5.0

[[joint]]
name = "l_ankle_roll"
datasets = ["data/a.csv"]
gear_ratio = -160.0
kt_nm_per_a = 0.066
max_curr_a = 3.0
features = "motor-vel-joint-vel"
"#;

    #[test]
    fn a_good_file_parses_with_defaults() {
        let f = parse(Path::new("r.toml"), GOOD).unwrap();
        assert_eq!(f.joint.len(), 2);
        assert_eq!(f.search.trials, 4);
        assert_eq!(f.search.hidden, Some([8, 16]));
        assert_eq!(f.search.batch, None);
        assert_eq!(f.joint[0].source(), DataSource::Preset);
        assert_eq!(f.joint[1].source(), DataSource::Datasets);
        assert_eq!(f.joint[1].features, FeatureSet::MotorVelJointVel);
        assert!(!f.joint[1].temperature);
        assert_eq!(f.joint[0].kfc, 1.0);
        assert_eq!(f.robot.seed, 0);
    }

    #[test]
    fn errors_name_the_file_the_key_and_the_value() {
        let e = |text: &str| {
            parse(Path::new("robot.toml"), text)
                .unwrap_err()
                .to_string()
        };
        let msg = e(&GOOD.replace("max_curr_a = 5.0", "max_curr_a = 5.0\nmax_cur = 1"));
        assert!(msg.starts_with("robot.toml: "), "{msg}");
        assert!(msg.contains("max_cur"), "{msg}");
        let msg = e(&GOOD.replace("gear_ratio = -160.0", "gear_ratio = 0.0"));
        assert!(msg.contains("joint[1].gear_ratio = 0"), "{msg}");
        let msg = e(&GOOD.replace("hidden = [8, 16]", "hidden = [16, 8]"));
        assert!(msg.contains("search.hidden = [16, 8]"), "{msg}");
        let msg = e(&GOOD.replace("name = \"l_ankle_roll\"", "name = \"l_knee\""));
        assert!(msg.contains("joint[1].name = \"l_knee\": unique"), "{msg}");
        let msg = e(&GOOD.replace("preset = \"knee\"", "preset = \"knee\"\nlogs = [\"x.csv\"]"));
        assert!(
            msg.contains("joint[0].preset/logs/datasets/import = 2 given"),
            "{msg}"
        );
        let msg = e(&GOOD.replace("\"motor-vel-joint-vel\"", "\"velocity\""));
        assert!(msg.contains("velocity"), "{msg}");
    }

    #[test]
    fn train_and_search_values_the_trainer_refuses_are_named_by_their_key() {
        // Before: these passed `robot plan` and failed at the train stage, naming the child's flag.
        let e = |text: &str| {
            parse(Path::new("robot.toml"), text)
                .unwrap_err()
                .to_string()
        };
        let with_train = |t: &str| format!("[train]\n{t}\n{GOOD}");
        for (text, says) in [
            ("history = 0", "train.history = 0"),
            ("history = 65", "train.history = 65"),
            ("hidden = [0]", "train.hidden = [0]"),
            ("hidden = [8, 5000]", "train.hidden = [8, 5000]"),
            ("lr = -1.0", "train.lr = -1"),
            ("dropout = 1.0", "train.dropout = 1"),
            ("lambda = 2.0", "train.lambda = 2"),
            ("epochs = 0", "train.epochs = 0"),
            ("batch = 0", "train.batch = 0"),
        ] {
            let msg = e(&with_train(text));
            assert!(msg.contains(says), "{text}: {msg}");
        }
        for (from, to, says) in [
            (
                "hidden = [8, 16]",
                "hidden = [8, 2000]",
                "search.hidden = [8, 2000]",
            ),
            (
                "hidden = [8, 16]",
                "history = [3, 65]",
                "search.history = [3, 65]",
            ),
            (
                "hidden = [8, 16]",
                "dropout = [0.1, 1.5]",
                "search.dropout = [0.1, 1.5]",
            ),
            (
                "trials = 4",
                "trials = 100000000000",
                "search.trials = 100000000000",
            ),
        ] {
            let msg = e(&GOOD.replace(from, to));
            assert!(msg.contains(says), "{to}: {msg}");
        }
    }

    #[test]
    fn the_search_pick_needs_a_search_and_a_ratio_of_at_least_one() {
        let f = parse(Path::new("r.toml"), GOOD).unwrap();
        assert!(!f.search.pick, "the best trial by default");
        assert_eq!(f.search.max_rmse_ratio, 1.05);
        let with = |extra: &str| GOOD.replace("trials = 4", &format!("trials = 4\n{extra}"));
        let f = parse(
            Path::new("r.toml"),
            &with("pick = true\nmax_rmse_ratio = 1.2"),
        )
        .unwrap();
        assert!(f.search.pick);
        assert_eq!(f.search.max_rmse_ratio, 1.2);
        let e = |text: &str| {
            parse(Path::new("robot.toml"), text)
                .unwrap_err()
                .to_string()
        };
        let msg = e(&with("max_rmse_ratio = 0.9"));
        assert!(msg.contains("search.max_rmse_ratio = 0.9"), "{msg}");
        let msg = e(&with("max_rmse_ratio = nan"));
        assert!(msg.contains("search.max_rmse_ratio = NaN"), "{msg}");
        let msg = e(&GOOD.replace("trials = 4", "trials = 0\npick = true"));
        assert!(
            msg.contains("search.pick = true") && msg.contains("trials"),
            "{msg}"
        );
    }

    #[test]
    fn load_makes_paths_relative_to_the_file() {
        let dir = std::env::temp_dir().join(format!("frictl-robot-load-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("robot.toml");
        std::fs::write(&p, GOOD).unwrap();
        let f = load(&p).unwrap();
        assert_eq!(f.joint[1].datasets, vec![dir.join("data/a.csv")]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The complete example of `docs/robot-file.md`.
    fn doc_example() -> (&'static str, &'static str) {
        let doc = include_str!("../../../docs/robot-file.md");
        let example = doc
            .split("## A complete example")
            .nth(1)
            .and_then(|t| t.split("```toml\n").nth(1))
            .and_then(|t| t.split("```").next())
            .expect("docs/robot-file.md has a complete example in a toml block");
        (doc, example)
    }

    /// The doc's table of one section: the text from its `## ` heading to the next.
    fn doc_section<'a>(doc: &'a str, heading: &str) -> &'a str {
        let at = doc
            .find(&format!("\n## {heading}"))
            .unwrap_or_else(|| panic!("docs/robot-file.md has no `## {heading}` heading"));
        let rest = &doc[at + 4..];
        &rest[..rest.find("\n## ").unwrap_or(rest.len())]
    }

    #[test]
    fn every_key_of_the_schema_is_in_the_reference_and_its_example_parses() {
        let (doc, example) = doc_example();
        let file = parse(Path::new("docs/robot-file.md"), example).unwrap();
        // Written back, the parsed example holds every key its sections have (it sets them all).
        let back = toml::Value::try_from(&file).unwrap();
        let options: Vec<&String> = file.import.as_ref().unwrap().options.keys().collect();
        let mut keys: Vec<(&str, String)> = vec![];
        for (section, heading) in [
            ("robot", "`[robot]`"),
            ("acquire", "`[acquire]`"),
            ("search", "`[search]`"),
            ("train", "`[train]`"),
            ("import", "`[import]`"),
        ] {
            for k in back[section].as_table().unwrap().keys() {
                if section != "import" || !options.contains(&k) {
                    keys.push((heading, k.clone()));
                }
            }
        }
        for j in back["joint"].as_array().unwrap() {
            for k in j.as_table().unwrap().keys() {
                keys.push(("`[[joint]]`", k.clone()));
            }
        }
        for top in back.as_table().unwrap().keys() {
            assert!(
                ["robot", "acquire", "search", "train", "import", "joint"].contains(&top.as_str()),
                "a section the test does not know: [{top}]"
            );
        }
        assert!(keys.len() > 40, "{keys:?}");
        for (heading, k) in keys {
            assert!(
                doc_section(doc, heading).contains(&format!("| `{k}` |")),
                "docs/robot-file.md: {heading} has no row for `{k}`"
            );
        }
        // The example's sources as the reference says: the robot's [import] for a joint without a
        // source, its own import table on top for the ankle, the others untouched.
        let src: Vec<DataSource> = file.joint.iter().map(|j| j.source()).collect();
        use DataSource::*;
        assert_eq!(src, [Import, Import, Preset, Logs, Datasets]);
        let ankle = file.joint[1].import.as_ref().unwrap();
        assert_eq!(ankle.format, Some(LogFormat::Csv));
        assert_eq!(ankle.logs, [PathBuf::from("ankle_only.csv")]);
        assert!(
            ankle.test_logs.is_empty(),
            "its own logs come without [import]'s test logs"
        );
        let words = ankle.option_words().unwrap();
        for w in [
            "--column=time=t_ms",
            "--unit=s=deg",
            "--label=current",
            "--negate=current",
        ] {
            assert!(words.contains(&w.to_owned()), "{w} in {words:?}");
        }
        assert!(file.joint[2].import.is_none());
    }

    #[test]
    fn import_keys_the_file_sets_or_no_flag_takes_are_refused_by_key() {
        let with = |import: &str| {
            format!(
                "{import}\n[[joint]]\nname = \"k\"\ngear_ratio = 100.0\nkt_nm_per_a = 0.1\nmax_curr_a = 1.0\n"
            )
        };
        let refused = |text: String, key: &str| {
            let e = parse(Path::new("r.toml"), &text).unwrap_err().to_string();
            assert!(e.contains("r.toml") && e.contains(key), "{key}: {e}");
            e
        };
        let e = refused(
            with("[import]\nformat = \"csv\"\nlogs = [\"a.csv\"]\ngear_ratio = 3"),
            "import.gear_ratio",
        );
        assert!(e.contains("set by the robot file"), "{e}");
        refused(
            with("[import]\nformat = \"csv\"\nlogs = [\"a.csv\"]\nkt = 3"),
            "import.kt",
        );
        refused(
            with("[import]\nformat = \"csv\"\nlogs = [\"a.csv\"]\ncolumn = { time = [1] }"),
            "import.column",
        );
        refused(
            with("[import]\nlogs = [\"a.csv\"]"),
            "joint[0].import.format",
        );
        refused(with("[import]\nformat = \"csv\""), "joint[0].import.logs");
        let e = parse(
            Path::new("r.toml"),
            &with("[import]\nformat = \"xls\"\nlogs = [\"a\"]"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("xls"), "{e}");
        // A joint's own import beside another source is two sources.
        refused(
            "[[joint]]\nname = \"k\"\npreset = \"knee\"\nimport = { format = \"csv\", logs = [\"a\"] }\n\
             gear_ratio = 100.0\nkt_nm_per_a = 0.1\nmax_curr_a = 1.0\n"
                .into(),
            "preset/logs/datasets/import",
        );
        // No source and no [import]: refused as before.
        refused(with(""), "preset/logs/datasets/import");
    }

    #[test]
    fn load_makes_import_paths_relative_to_the_file() {
        let dir = std::env::temp_dir().join(format!("frictl-robot-import-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("r.toml");
        std::fs::write(
            &p,
            "[import]\nformat = \"mcap\"\nlogs = [\"bags/a.mcap\"]\nurdf = \"u/leg.urdf\"\n\
             [[joint]]\nname = \"k\"\ngear_ratio = 100.0\nkt_nm_per_a = 0.1\nmax_curr_a = 1.0\n",
        )
        .unwrap();
        let f = load(&p).unwrap();
        let imp = f.joint[0].import.as_ref().unwrap();
        assert_eq!(imp.logs, [dir.join("bags/a.mcap")]);
        assert_eq!(
            imp.options["urdf"].as_str(),
            Some(dir.join("u/leg.urdf").to_str().unwrap())
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
