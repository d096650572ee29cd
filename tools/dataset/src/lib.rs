//! # `frictionless-dataset`: the offline file formats shared by acquisition, labelling and training
//!
//! Crate table: `tools/dataset`, a leaf (serde, csv); used by `frictionless-acquire` (raw log column
//! docs), `frictionless-ident` (writes datasets), `frictionless-train` and `frictl` (read them).
//!
//! What this crate **is**: [`ColumnDoc`] (name, unit and meaning of one CSV column, for the raw
//! acquisition log and the dataset alike), [`Dataset`] (column vectors, one entry per 1 kHz sample),
//! [`DATASET_COLUMNS`] (names, units, meaning), the CSV writer/reader and [`DatasetSidecar`] (what was
//! done to produce it), written by `frictl preprocess` and read by `frictl fit`, the trainer and `eval`;
//! [`fit_file::FittedModel`], the fitted CV/SCV model in the JSON `frictl fit --json` writes and eval,
//! the trainer's SCV prior and the experiments read; [`bands`], the |ṡ| bands, temperature bins and
//! residual statistics per bin that `frictl eval` (per-band RMSE, drift monitor) and `frictl train`
//! (reference residuals in its report) share.
//!
//! What it is **not**: the raw acquisition log writer (`frictionless-acquire`, `acquire::log`) or the
//! label pipeline (`frictionless-ident`, `preprocess`).
//!
//! ## Example: write a dataset CSV and read it back
//! ```
//! use frictionless_dataset::Dataset;
//!
//! // Five 1 kHz samples of a knee (r = −100) sliding at 0.5 rad/s with a CV-like label.
//! let n = 5;
//! let r = -100.0;
//! let time_s: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
//! let s_rad: Vec<f64> = time_s.iter().map(|t| -0.8 + 0.5 * t).collect();
//! let col = |v: f64| vec![v; n];
//! let ds = Dataset {
//!     chunk: vec![0; n],
//!     source_chunk: vec![0; n],
//!     active: vec![true; n],
//!     valid: vec![true; n],
//!     theta_motor_rad: s_rad.iter().map(|s| r * s).collect(),
//!     s_rad,
//!     sdot_rad_s: col(0.5),
//!     sddot_rad_s2: col(0.0),
//!     delta_theta_motor_rad: col(0.0),
//!     omega_motor_rad_s: col(r * 0.5),
//!     i_meas_a: col(-0.61),
//!     i_filt_a: col(-0.6),
//!     tau_id_nm: col(0.1),
//!     tau_f_label_nm: col(8.1 + 5.55 * 0.5),
//!     temperature_c: col(35.0),
//!     tau_f_true_nm: None,
//!     phi_ddot_rad_s2: None,
//!     time_s,
//! };
//! assert_eq!(ds.mismatched_column(), None, "one value per sample in every column");
//!
//! let path = std::env::temp_dir().join(format!("frictionless_dataset_doc_{}.csv", std::process::id()));
//! ds.write_csv(&path)?;
//! let back = Dataset::read_csv(&path);
//! std::fs::remove_file(&path)?;
//! let back = back?;
//! // Shortest round-trip float text: the values come back bit for bit.
//! assert_eq!(back, ds);
//! assert_eq!(back.joint_sample(3).theta_motor_rad, r * (-0.8 + 0.5 * 3e-3));
//! assert_eq!(back.columns().len(), frictionless_dataset::DATASET_COLUMNS.len());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod bands;
pub mod fit_file;

use std::path::Path;

use serde::{Deserialize, Serialize};

/// Documentation of one CSV column.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ColumnDoc {
    /// Header name.
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Meaning.
    pub doc: &'static str,
}

/// Dataset I/O errors (each names the file, and the line/column where relevant).
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// File could not be opened/read/written.
    #[error("{path}: {msg}")]
    Io {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// A required column is missing.
    #[error("{path}: required column `{column}` is missing")]
    MissingColumn {
        /// File.
        path: String,
        /// Column.
        column: &'static str,
    },
    /// A field is not a number.
    #[error("{path}: line {line}, column `{column}`: cannot parse {value:?} as a number")]
    Parse {
        /// File.
        path: String,
        /// 1-based line number.
        line: u64,
        /// Column.
        column: String,
        /// Raw text.
        value: String,
    },
    /// The CSV holds another number of rows than its sidecar records: a file cut short (a write
    /// stopped by a signal or a full disk) or a CSV and sidecar from different imports.
    #[error(
        "{path}: {rows} data rows, but its sidecar {sidecar} records {samples} samples (a file cut short, or a CSV and sidecar of different imports): import the dataset again"
    )]
    RowCount {
        /// Dataset CSV.
        path: String,
        /// Rows read.
        rows: usize,
        /// Sidecar path.
        sidecar: String,
        /// Samples the sidecar records.
        samples: u64,
    },
}

const fn col(name: &'static str, unit: &'static str, doc: &'static str) -> ColumnDoc {
    ColumnDoc { name, unit, doc }
}

/// Columns of a dataset CSV, in file order (`tau_f_true_nm` and `phi_ddot_rad_s2` only when the
/// log had simulator truth).
pub const DATASET_COLUMNS: &[ColumnDoc] = &[
    col(
        "time_s",
        "s",
        "time on the resampled uniform grid (log clock)",
    ),
    col(
        "chunk",
        "-",
        "chunk id after splitting (0, 1, ...); windows must not cross chunks",
    ),
    col("source_chunk", "-", "chunk id in the acquisition log"),
    col(
        "active",
        "0/1",
        "log `active` flag (nearest-previous sample)",
    ),
    col(
        "valid",
        "0/1",
        "1 if the sample passes every sample filter (|sddot|, |sdot|, |i_filt|, |tau_f|) and its chunk could be filtered",
    ),
    col(
        "s_rad",
        "rad",
        "joint position (linear interpolation of the encoder)",
    ),
    col(
        "sdot_rad_s",
        "rad/s",
        "joint velocity, Kalman smoother (or causal KF with --causal; the label always uses the smoother)",
    ),
    col(
        "sddot_rad_s2",
        "rad/s^2",
        "joint acceleration, same estimator",
    ),
    col(
        "theta_motor_rad",
        "motor rad",
        "motor encoder (linear interpolation)",
    ),
    col(
        "delta_theta_motor_rad",
        "motor rad",
        "r_signed*s - theta - (r_signed*s0 - theta0): offset removed once per run",
    ),
    col(
        "omega_motor_rad_s",
        "motor rad/s",
        "motor velocity from the log (linear interpolation)",
    ),
    col("i_meas_a", "A", "measured current (linear interpolation)"),
    col(
        "i_filt_a",
        "A",
        "current after the zero-phase Butterworth low-pass (the label's current)",
    ),
    col(
        "tau_id_nm",
        "Nm",
        "inverse dynamics I(s)*sddot + c(s, sdot) + g(s), other joints fixed",
    ),
    col(
        "tau_f_label_nm",
        "Nm",
        "friction label r_signed*kt*i_filt - tau_id (joint side)",
    ),
    col(
        "temperature_c",
        "degC",
        "temperature (NaN without a sensor)",
    ),
];

/// Truth columns of datasets made from simulated logs (diagnostics only, never model inputs).
pub const DATASET_TRUTH_COLUMNS: &[ColumnDoc] = &[
    col(
        "tau_f_true_nm",
        "Nm",
        "true joint-side friction from the simulator",
    ),
    col(
        "phi_ddot_rad_s2",
        "rad/s^2",
        "true motor acceleration reflected to the joint",
    ),
];

/// A preprocessed dataset as column vectors (all the same length).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Dataset {
    /// Time [s].
    pub time_s: Vec<f64>,
    /// Chunk id after splitting.
    pub chunk: Vec<u32>,
    /// Chunk id of the acquisition log.
    pub source_chunk: Vec<u32>,
    /// Log `active` flag.
    pub active: Vec<bool>,
    /// Sample passes every filter.
    pub valid: Vec<bool>,
    /// Joint position [rad].
    pub s_rad: Vec<f64>,
    /// Joint velocity [rad/s].
    pub sdot_rad_s: Vec<f64>,
    /// Joint acceleration [rad/s²].
    pub sddot_rad_s2: Vec<f64>,
    /// Motor position [motor rad].
    pub theta_motor_rad: Vec<f64>,
    /// Δθ = r·s − θ − offset [motor rad].
    pub delta_theta_motor_rad: Vec<f64>,
    /// Motor velocity [motor rad/s].
    pub omega_motor_rad_s: Vec<f64>,
    /// Measured current [A].
    pub i_meas_a: Vec<f64>,
    /// Filtered current [A].
    pub i_filt_a: Vec<f64>,
    /// Inverse-dynamics torque [Nm].
    pub tau_id_nm: Vec<f64>,
    /// Friction label [Nm].
    pub tau_f_label_nm: Vec<f64>,
    /// Temperature [°C] (NaN without a sensor).
    pub temperature_c: Vec<f64>,
    /// True friction (simulated logs) [Nm].
    pub tau_f_true_nm: Option<Vec<f64>>,
    /// True motor acceleration reflected to the joint (simulated logs) [rad/s²].
    pub phi_ddot_rad_s2: Option<Vec<f64>>,
}

/// The JSON sidecar of a dataset: provenance and every setting used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetSidecar {
    /// Format tag `frictionless-dataset-v1`.
    pub format: String,
    /// Producer (`frictl <version>`).
    pub producer: String,
    /// Input log CSV path as given.
    pub input_log: String,
    /// SHA-256 of the input log CSV (hex).
    pub input_sha256: String,
    /// Joint name.
    pub joint: String,
    /// Signed gear ratio used for the label and Δθ.
    pub gear_ratio_signed: f64,
    /// Torque constant used for the label [Nm/A].
    pub kt_nm_per_a: f64,
    /// Output sample rate [Hz].
    pub fs_hz: f64,
    /// Processing settings.
    pub settings: serde_json::Value,
    /// Link dynamics used for τ_ID (description).
    pub dynamics: String,
    /// Δθ offset removed, r·s₀ − θ₀ [motor rad].
    pub delta_theta_offset_motor_rad: f64,
    /// Number of samples.
    pub samples: usize,
    /// Number of valid samples.
    pub valid_samples: usize,
    /// Number of chunks.
    pub chunks: usize,
    /// Chunks dropped as too short to filter (samples marked invalid).
    pub short_chunks: usize,
    /// The rows marked invalid, by reason (older sidecars: all zero).
    #[serde(default)]
    pub dropped_rows: DroppedRows,
    /// Column documentation, in file order.
    pub columns: Vec<ColumnDocOwned>,
    /// Where the friction label `tau_f_label_nm` comes from (older sidecars: the current label).
    #[serde(default)]
    pub label: LabelSource,
    /// Runs (recordings) in the file, each a set of chunks; empty means the whole file is one run
    /// (see [`dataset_runs`], which takes the chunks from the data, not from the sidecar's count). Evaluation can hold out whole runs.
    #[serde(default)]
    pub runs: Vec<RunInfo>,
    /// Dataset columns the source log did not have: NaN in every row (e.g. `theta_motor_rad` for a
    /// torque-sensed arm without a motor encoder). A feature set that needs one of them is refused.
    #[serde(default)]
    pub absent_columns: Vec<String>,
}

/// Why the label pipeline marks a row invalid (`valid = 0`), in the order [`DroppedRows`] counts
/// them: a row is counted once, under the first of these reasons it has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DropReason {
    /// Its chunk is too short for the zero-phase filter (every row of the chunk).
    ShortChunk,
    /// Its label τ_F or its velocity ṡ is not finite (e.g. no τ_ID for the sample).
    NonFinite,
    /// |s̈| is not below the acceleration limit.
    JointAcc,
    /// |ṡ| is not below the velocity limit.
    JointVel,
    /// |i_f| is not below the current limit.
    Current,
    /// |τ_F| is not below the friction limit.
    TauF,
    /// It passes every limit, but the matched label's smoother window around it holds a row that
    /// fails one (the smoother's reach, `label_filter = matched`).
    NearInvalid,
}

impl DropReason {
    /// Every reason, in counting order.
    pub const ALL: [Self; 7] = [
        Self::ShortChunk,
        Self::NonFinite,
        Self::JointAcc,
        Self::JointVel,
        Self::Current,
        Self::TauF,
        Self::NearInvalid,
    ];
}

/// The rows of a dataset marked invalid, by reason ([`DropReason`]): each invalid row is counted
/// once, under the **first** reason it has in the order of the fields (a row of a short chunk that
/// is also too fast counts as `short_chunk`; one too fast and too accelerated as `joint_acc`), so
/// the fields add up to the invalid rows ([`Self::total`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DroppedRows {
    /// Rows of chunks too short for the zero-phase filter.
    pub short_chunk: usize,
    /// Rows whose label or velocity is not finite.
    pub non_finite: usize,
    /// Rows with |s̈| at or above the acceleration limit.
    pub joint_acc: usize,
    /// Rows with |ṡ| at or above the velocity limit.
    pub joint_vel: usize,
    /// Rows with |i_f| at or above the current limit.
    pub current: usize,
    /// Rows with |τ_F| at or above the friction limit.
    pub tau_f: usize,
    /// Rows within the matched smoother's reach of a row dropped for a limit.
    pub near_invalid: usize,
}

impl DroppedRows {
    /// The count of `reason`.
    pub fn get(&self, reason: DropReason) -> usize {
        match reason {
            DropReason::ShortChunk => self.short_chunk,
            DropReason::NonFinite => self.non_finite,
            DropReason::JointAcc => self.joint_acc,
            DropReason::JointVel => self.joint_vel,
            DropReason::Current => self.current,
            DropReason::TauF => self.tau_f,
            DropReason::NearInvalid => self.near_invalid,
        }
    }

    /// Counts one row dropped for `reason`.
    pub fn count(&mut self, reason: DropReason) {
        let c = match reason {
            DropReason::ShortChunk => &mut self.short_chunk,
            DropReason::NonFinite => &mut self.non_finite,
            DropReason::JointAcc => &mut self.joint_acc,
            DropReason::JointVel => &mut self.joint_vel,
            DropReason::Current => &mut self.current,
            DropReason::TauF => &mut self.tau_f,
            DropReason::NearInvalid => &mut self.near_invalid,
        };
        *c += 1;
    }

    /// Every invalid row (the sum of the reasons).
    pub fn total(&self) -> usize {
        DropReason::ALL.iter().map(|r| self.get(*r)).sum()
    }
}

/// Where a dataset's friction label comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LabelSource {
    /// τ_F = r·k_t·i − τ_ID: motor current through the gearbox minus the link's inverse dynamics
    /// (the paper's label).
    #[default]
    Current,
    /// τ_F = τ_motor − τ_joint: the motor-side torque (r·k_t·i or a commanded torque) minus a joint
    /// torque sensor's link-side reading.
    TorqueSensor,
    /// τ_F given directly by a column of the source log.
    Given,
}

/// One run (a recording, usually one source file) of a dataset: the chunks it holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    /// Run name (by default the source file's stem), unique within the dataset.
    pub name: String,
    /// Source file as given.
    pub source: String,
    /// Dataset chunk ids (values of the `chunk` column) that belong to this run.
    pub chunks: Vec<u32>,
}

/// SHA-256 of a regular file's content, streamed (a multi-GB log is never held in memory; a FIFO or
/// device is refused: [`frictionless::regular_file::open`]). The fingerprint datasets, sidecars,
/// reports and stage stamps record of their inputs.
pub fn file_sha256(path: &Path) -> std::io::Result<[u8; 32]> {
    use sha2::Digest;
    let (mut file, _) = frictionless::regular_file::open(path)?;
    let mut h = sha2::Sha256::new();
    std::io::copy(&mut file, &mut h)?;
    Ok(h.finalize().into())
}

/// [`file_sha256`] as 64 lower-case hex digits.
pub fn file_sha256_hex(path: &Path) -> std::io::Result<String> {
    Ok(file_sha256(path)?
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// The runs of the dataset at `path`: its sidecar's runs, or — a sidecar without runs, or none at all —
/// one run named by the file stem holding every chunk of `data`.
pub fn dataset_runs(path: &Path, sidecar: Option<&DatasetSidecar>, data: &Dataset) -> Vec<RunInfo> {
    let stem = path.file_stem().map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    match sidecar {
        Some(s) if !s.runs.is_empty() => s.runs.clone(),
        _ => {
            let mut chunks: Vec<u32> = data.chunk.clone();
            chunks.sort_unstable();
            chunks.dedup();
            vec![RunInfo {
                name: stem,
                source: sidecar.map_or_else(|| path.display().to_string(), |s| s.input_log.clone()),
                chunks,
            }]
        }
    }
}

/// The range of the model's physical inputs over a set of rows — what a model has seen in training.
/// A row outside it (either coordinate) is an extrapolation. Empty ranges (no rows) contain nothing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionRange {
    /// Joint position s: [min, max] [rad].
    pub s_rad: [f64; 2],
    /// Joint velocity ṡ: [min, max] [rad/s].
    pub sdot_rad_s: [f64; 2],
    /// Rows the range was taken over.
    pub rows: usize,
}

impl Default for MotionRange {
    fn default() -> Self {
        Self {
            s_rad: [f64::INFINITY, f64::NEG_INFINITY],
            sdot_rad_s: [f64::INFINITY, f64::NEG_INFINITY],
            rows: 0,
        }
    }
}

impl MotionRange {
    /// Widens the range by row `k` of `ds` (rows with a non-finite s or ṡ are ignored).
    pub fn add_row(&mut self, ds: &Dataset, k: usize) {
        let (s, v) = (ds.s_rad[k], ds.sdot_rad_s[k]);
        if !(s.is_finite() && v.is_finite()) {
            return;
        }
        self.s_rad = [self.s_rad[0].min(s), self.s_rad[1].max(s)];
        self.sdot_rad_s = [self.sdot_rad_s[0].min(v), self.sdot_rad_s[1].max(v)];
        self.rows += 1;
    }

    /// The range of the valid rows of `ds` whose chunk is in `chunks`.
    pub fn of_chunks(ds: &Dataset, chunks: &[u32]) -> Self {
        let mut r = Self::default();
        for k in 0..ds.len() {
            if ds.valid[k] && chunks.contains(&ds.chunk[k]) {
                r.add_row(ds, k);
            }
        }
        r
    }

    /// The union of two ranges.
    pub fn merge(&mut self, o: &Self) {
        self.s_rad = [self.s_rad[0].min(o.s_rad[0]), self.s_rad[1].max(o.s_rad[1])];
        self.sdot_rad_s = [
            self.sdot_rad_s[0].min(o.sdot_rad_s[0]),
            self.sdot_rad_s[1].max(o.sdot_rad_s[1]),
        ];
        self.rows += o.rows;
    }

    /// Whether position `s_rad` and velocity `sdot_rad_s` both lie inside the range (bounds included).
    pub fn contains(&self, s_rad: f64, sdot_rad_s: f64) -> bool {
        (self.s_rad[0]..=self.s_rad[1]).contains(&s_rad)
            && (self.sdot_rad_s[0]..=self.sdot_rad_s[1]).contains(&sdot_rad_s)
    }
}

/// Owned copy of a [`ColumnDoc`] (for deserialising sidecars).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColumnDocOwned {
    /// Header name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Meaning.
    pub doc: String,
}

impl From<&ColumnDoc> for ColumnDocOwned {
    fn from(c: &ColumnDoc) -> Self {
        Self {
            name: c.name.into(),
            unit: c.unit.into(),
            doc: c.doc.into(),
        }
    }
}

/// Why a dataset cannot feed a model's inputs: a column the feature spec reads is absent or not
/// finite where it would be used. Names the column and the spec (set, H, temperature).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputColumnError {
    /// The sidecar lists the column in `absent_columns` (the source log did not have it).
    #[error(
        "column `{column}` is absent from this dataset (sidecar `absent_columns`), but feature set `{set}` ({spec}) needs it; choose a set that does not read it (e.g. joint-pos-joint-vel or joint-vel without a motor encoder)"
    )]
    Absent {
        /// Dataset column (= `JointSample` field).
        column: &'static str,
        /// The feature set's name.
        set: &'static str,
        /// The whole spec, rendered (`joint-vel H=30 +temperature`).
        spec: String,
    },
    /// The column is NaN or infinite in rows the inputs would be built from.
    #[error(
        "column `{column}` is not finite in {rows} of {used} valid rows (first at row {first_row}), but feature set `{set}` ({spec}) needs it"
    )]
    NonFinite {
        /// Dataset column (= `JointSample` field).
        column: &'static str,
        /// The feature set's name.
        set: &'static str,
        /// The whole spec, rendered.
        spec: String,
        /// Valid rows where it is not finite.
        rows: usize,
        /// Valid rows in the dataset.
        used: usize,
        /// 0-based data row of the first one.
        first_row: usize,
    },
}

impl Dataset {
    /// The values of the column a [`Signal`](frictionless::features::Signal) names.
    pub fn signal_column(&self, signal: frictionless::features::Signal) -> &[f64] {
        use frictionless::features::Signal;
        match signal {
            Signal::JointPosRad => &self.s_rad,
            Signal::JointVelRadS => &self.sdot_rad_s,
            Signal::MotorPosRad => &self.theta_motor_rad,
            Signal::MotorVelRadS => &self.omega_motor_rad_s,
            Signal::TemperatureC => &self.temperature_c,
        }
    }

    /// Checks that every column `spec` reads ([`FeatureSpec::required_signals`]) is present (not in
    /// `absent_columns`, the sidecar's list) and finite in every `valid` row. Columns the spec does
    /// not read are not looked at: a torque-sensed dataset with NaN motor angle, velocity and
    /// current feeds `joint-pos-joint-vel` and `joint-vel`.
    ///
    /// [`FeatureSpec::required_signals`]: frictionless::features::FeatureSpec::required_signals
    pub fn check_inputs(
        &self,
        spec: &frictionless::features::FeatureSpec,
        absent_columns: &[String],
    ) -> Result<(), InputColumnError> {
        let used = self.valid.iter().filter(|v| **v).count();
        for signal in spec.required_signals() {
            let column = signal.field();
            if absent_columns.iter().any(|c| c == column) {
                return Err(InputColumnError::Absent {
                    column,
                    set: spec.set.name(),
                    spec: spec.to_string(),
                });
            }
            let values = self.signal_column(signal);
            let mut bad = self
                .valid
                .iter()
                .zip(values)
                .enumerate()
                .filter(|(_, (v, x))| **v && !x.is_finite())
                .map(|(k, _)| k);
            if let Some(first_row) = bad.next() {
                return Err(InputColumnError::NonFinite {
                    column,
                    set: spec.set.name(),
                    spec: spec.to_string(),
                    rows: 1 + bad.count(),
                    used,
                    first_row,
                });
            }
        }
        Ok(())
    }

    /// The model input sample of row `k` (what `frictiond` would read from `JointStates` at that
    /// instant). Shared by training and evaluation so both feed `History` identically.
    pub fn joint_sample(&self, k: usize) -> frictionless::features::JointSample {
        frictionless::features::JointSample {
            s_rad: self.s_rad[k],
            sdot_rad_s: self.sdot_rad_s[k],
            theta_motor_rad: self.theta_motor_rad[k],
            omega_motor_rad_s: self.omega_motor_rad_s[k],
            temperature_c: self.temperature_c[k],
        }
    }

    /// The first column whose length differs from `time_s`'s, as `(name, length)`; `None` when all
    /// columns (including the optional true friction) have one value per sample.
    pub fn mismatched_column(&self) -> Option<(&'static str, usize)> {
        let n = self.time_s.len();
        let cols: [(&'static str, usize); 11] = [
            ("chunk", self.chunk.len()),
            ("source_chunk", self.source_chunk.len()),
            ("valid", self.valid.len()),
            ("s_rad", self.s_rad.len()),
            ("sdot_rad_s", self.sdot_rad_s.len()),
            ("theta_motor_rad", self.theta_motor_rad.len()),
            ("omega_motor_rad_s", self.omega_motor_rad_s.len()),
            ("temperature_c", self.temperature_c.len()),
            ("tau_f_label_nm", self.tau_f_label_nm.len()),
            ("delta_theta_motor_rad", self.delta_theta_motor_rad.len()),
            (
                "tau_f_true_nm",
                self.tau_f_true_nm.as_ref().map_or(n, Vec::len),
            ),
        ];
        cols.into_iter().find(|&(_, len)| len != n)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The columns of this dataset, in file order.
    pub fn columns(&self) -> Vec<ColumnDoc> {
        let truth = if self.tau_f_true_nm.is_some() {
            DATASET_TRUTH_COLUMNS
        } else {
            &[]
        };
        DATASET_COLUMNS.iter().chain(truth).copied().collect()
    }

    /// Writes the CSV (header + one line per sample, shortest round-trip float text) through
    /// [`frictionless::output_file`]: replaced atomically, never over a device or through a symlink.
    pub fn write_csv(&self, path: &Path) -> Result<(), DatasetError> {
        let io = |e: &dyn std::fmt::Display| DatasetError::Io {
            path: path.display().to_string(),
            msg: e.to_string(),
        };
        let mut f = frictionless::output_file::AtomicFile::create(path).map_err(|e| io(&e))?;
        self.write_csv_to(&mut f, path)?;
        f.commit().map_err(|e| io(&e))
    }

    /// Writes the CSV to `out` (see [`Dataset::write_csv`]); `path` names it in errors. The caller
    /// commits the file (e.g. together with its sidecar).
    pub fn write_csv_to(
        &self,
        out: &mut frictionless::output_file::AtomicFile,
        path: &Path,
    ) -> Result<(), DatasetError> {
        self.write_csv_part_to(out, path, true)
    }

    /// Appends the rows to `out`, after the header when `header` (a dataset written in parts, as
    /// its rows come: the first part with the header, the next ones without).
    pub fn write_csv_part_to(
        &self,
        out: &mut frictionless::output_file::AtomicFile,
        path: &Path,
        header: bool,
    ) -> Result<(), DatasetError> {
        let p = path.display().to_string();
        let io = |e: &dyn std::fmt::Display| DatasetError::Io {
            path: p.clone(),
            msg: e.to_string(),
        };
        let mut w = csv::Writer::from_writer(out);
        if header {
            w.write_record(self.columns().iter().map(|c| c.name))
                .map_err(|e| io(&e))?;
        }
        let mut buf = ryu_like::Buf::default();
        for k in 0..self.len() {
            let b = |x: bool| if x { 1.0 } else { 0.0 };
            let mut row = [
                self.time_s[k],
                f64::from(self.chunk[k]),
                f64::from(self.source_chunk[k]),
                b(self.active[k]),
                b(self.valid[k]),
                self.s_rad[k],
                self.sdot_rad_s[k],
                self.sddot_rad_s2[k],
                self.theta_motor_rad[k],
                self.delta_theta_motor_rad[k],
                self.omega_motor_rad_s[k],
                self.i_meas_a[k],
                self.i_filt_a[k],
                self.tau_id_nm[k],
                self.tau_f_label_nm[k],
                self.temperature_c[k],
                0.0,
                0.0,
            ];
            let mut n = 16;
            if let (Some(t), Some(a)) = (&self.tau_f_true_nm, &self.phi_ddot_rad_s2) {
                row[16] = t[k];
                row[17] = a[k];
                n = 18;
            }
            for v in &row[..n] {
                w.write_field(buf.format(*v)).map_err(|e| io(&e))?;
            }
            w.write_record(None::<&[u8]>).map_err(|e| io(&e))?;
        }
        w.flush().map_err(|e| io(&e))?;
        Ok(())
    }

    /// Reads a dataset CSV by column name (column order is free; the truth columns are optional).
    /// When its sidecar (`PATH.json`) exists and records `samples`, the number of rows must match
    /// ([`DatasetError::RowCount`]): a CSV cut at a line boundary is refused, not read as a shorter
    /// dataset.
    pub fn read_csv(path: &Path) -> Result<Self, DatasetError> {
        let ds = Self::read_csv_columns(path)?;
        let side = path.with_extension("json");
        if let Some(samples) = frictionless::regular_file::read_text(&side)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| v.get("samples").and_then(serde_json::Value::as_u64))
            && samples != ds.len() as u64
        {
            return Err(DatasetError::RowCount {
                path: path.display().to_string(),
                rows: ds.len(),
                sidecar: side.display().to_string(),
                samples,
            });
        }
        Ok(ds)
    }

    fn read_csv_columns(path: &Path) -> Result<Self, DatasetError> {
        let p = path.display().to_string();
        let mut cols = read_columns(path)?;
        let mut take = |name: &'static str| -> Result<Vec<f64>, DatasetError> {
            cols.remove(name).ok_or(DatasetError::MissingColumn {
                path: p.clone(),
                column: name,
            })
        };
        let to_u32 = |v: Vec<f64>| v.into_iter().map(|x| x as u32).collect();
        let to_bool = |v: Vec<f64>| v.into_iter().map(|x| x != 0.0).collect();
        Ok(Self {
            time_s: take("time_s")?,
            chunk: to_u32(take("chunk")?),
            source_chunk: to_u32(take("source_chunk")?),
            active: to_bool(take("active")?),
            valid: to_bool(take("valid")?),
            s_rad: take("s_rad")?,
            sdot_rad_s: take("sdot_rad_s")?,
            sddot_rad_s2: take("sddot_rad_s2")?,
            theta_motor_rad: take("theta_motor_rad")?,
            delta_theta_motor_rad: take("delta_theta_motor_rad")?,
            omega_motor_rad_s: take("omega_motor_rad_s")?,
            i_meas_a: take("i_meas_a")?,
            i_filt_a: take("i_filt_a")?,
            tau_id_nm: take("tau_id_nm")?,
            tau_f_label_nm: take("tau_f_label_nm")?,
            temperature_c: take("temperature_c")?,
            tau_f_true_nm: take("tau_f_true_nm").ok(),
            phi_ddot_rad_s2: take("phi_ddot_rad_s2").ok(),
        })
    }
}

/// Reads every column of a numeric CSV with a header into a map name → values
/// (empty fields and `NaN` become NaN).
pub fn read_columns(
    path: &Path,
) -> Result<std::collections::HashMap<String, Vec<f64>>, DatasetError> {
    let p = path.display().to_string();
    let io = |e: &dyn std::fmt::Display| DatasetError::Io {
        path: p.clone(),
        msg: e.to_string(),
    };
    let (file, _) = frictionless::regular_file::open(path).map_err(|e| io(&e))?;
    let mut r = csv::Reader::from_reader(file);
    let names: Vec<String> = r
        .headers()
        .map_err(|e| io(&e))?
        .iter()
        .map(str::to_owned)
        .collect();
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut rec = csv::StringRecord::new();
    let mut line = 1u64;
    while r.read_record(&mut rec).map_err(|e| io(&e))? {
        line += 1;
        for (j, f) in rec.iter().enumerate().take(names.len()) {
            let t = f.trim();
            let v = if t.is_empty() {
                f64::NAN
            } else {
                t.parse::<f64>().map_err(|_| DatasetError::Parse {
                    path: p.clone(),
                    line,
                    column: names[j].clone(),
                    value: f.to_owned(),
                })?
            };
            data[j].push(v);
        }
        for d in data.iter_mut().skip(rec.len()) {
            d.push(f64::NAN);
        }
    }
    Ok(names.into_iter().zip(data).collect())
}

/// Minimal float formatting into a reusable buffer: shortest round-trip text, positional (std
/// `Display`) for 1e-5 ≤ |v| < 1e16 and 0, else in exponent form (`LowerExp`, e.g. `1.5e-110`), since
/// `Display` writes every leading zero of a tiny value (110 of them for 1e-110).
mod ryu_like {
    use std::fmt::Write;

    #[derive(Default)]
    pub struct Buf(String);

    impl Buf {
        pub fn format(&mut self, v: f64) -> &[u8] {
            self.0.clear();
            let a = v.abs();
            if a == 0.0 || !a.is_finite() || (1e-5..1e16).contains(&a) {
                let _ = write!(self.0, "{v}");
            } else {
                let _ = write!(self.0, "{v:e}");
            }
            self.0.as_bytes()
        }
    }

    #[cfg(test)]
    mod tests {
        use super::Buf;

        #[test]
        fn floats_are_shortest_round_trip_text_without_runs_of_zeros() {
            let mut b = Buf::default();
            for (v, want) in [
                (0.0, "0"),
                (-0.0, "-0"),
                (0.25, "0.25"),
                (1e-5, "0.00001"),
                (1.5e-110, "1.5e-110"),
                (-3.0e-7, "-3e-7"),
                (2.0e20, "2e20"),
                (f64::NAN, "NaN"),
                (f64::INFINITY, "inf"),
            ] {
                let t = std::str::from_utf8(b.format(v)).unwrap().to_owned();
                assert_eq!(t, want, "{v:?}");
                if v.is_finite() {
                    assert_eq!(t.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{t}");
                }
            }
            for k in -320..300 {
                let v = 1.2345678901234567 * 10f64.powi(k);
                let t = std::str::from_utf8(b.format(v)).unwrap().to_owned();
                assert!(t.len() <= 24, "{t}");
                assert_eq!(t.parse::<f64>().unwrap(), v, "{t}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless::features::{FeatureSet, FeatureSpec};

    /// A torque-sensed dataset: no motor encoder, no current, no temperature sensor.
    fn torque_sensed(n: usize) -> Dataset {
        let nan = vec![f64::NAN; n];
        Dataset {
            time_s: (0..n).map(|k| k as f64 * 1e-3).collect(),
            chunk: vec![0; n],
            source_chunk: vec![0; n],
            active: vec![true; n],
            valid: vec![true; n],
            s_rad: (0..n).map(|k| k as f64 * 1e-4).collect(),
            sdot_rad_s: vec![0.1; n],
            sddot_rad_s2: vec![0.0; n],
            theta_motor_rad: nan.clone(),
            delta_theta_motor_rad: nan.clone(),
            omega_motor_rad_s: nan.clone(),
            i_meas_a: nan.clone(),
            i_filt_a: nan.clone(),
            tau_id_nm: vec![0.0; n],
            tau_f_label_nm: vec![0.5; n],
            temperature_c: nan,
            tau_f_true_nm: None,
            phi_ddot_rad_s2: None,
        }
    }

    fn spec(set: FeatureSet, temperature: bool) -> FeatureSpec {
        FeatureSpec {
            set,
            history: 4,
            temperature,
        }
    }

    #[test]
    fn check_inputs_refuses_only_the_columns_a_set_reads() {
        let mut ds = torque_sensed(10);
        let absent: Vec<String> = ["theta_motor_rad", "omega_motor_rad_s", "temperature_c"]
            .map(String::from)
            .to_vec();
        for set in [FeatureSet::JointPosJointVel, FeatureSet::JointVel] {
            ds.check_inputs(&spec(set, false), &absent).unwrap();
            ds.check_inputs(&spec(set, false), &[]).unwrap();
        }
        // Listed absent: named with the set.
        let e = ds
            .check_inputs(&spec(FeatureSet::DeltaThetaJointVel, false), &absent)
            .unwrap_err();
        assert_eq!(
            e,
            InputColumnError::Absent {
                column: "theta_motor_rad",
                set: "delta-theta-joint-vel",
                spec: "delta-theta-joint-vel H=4".into()
            }
        );
        assert!(e.to_string().contains("`theta_motor_rad`"));
        assert!(e.to_string().contains("`delta-theta-joint-vel`"));
        let e = ds
            .check_inputs(&spec(FeatureSet::JointVel, true), &absent)
            .unwrap_err();
        assert!(matches!(
            e,
            InputColumnError::Absent {
                column: "temperature_c",
                set: "joint-vel",
                ..
            }
        ));
        // Not listed, but NaN in valid rows: counted, first row named.
        let e = ds
            .check_inputs(&spec(FeatureSet::MotorVelJointVel, false), &[])
            .unwrap_err();
        assert!(matches!(
            e,
            InputColumnError::NonFinite {
                column: "omega_motor_rad_s",
                rows: 10,
                used: 10,
                first_row: 0,
                ..
            }
        ));
        // A NaN in an invalid row is not used.
        ds.sdot_rad_s[3] = f64::NAN;
        ds.valid[3] = false;
        ds.check_inputs(&spec(FeatureSet::JointVel, false), &[])
            .unwrap();
        ds.valid[3] = true;
        let e = ds
            .check_inputs(&spec(FeatureSet::JointVel, false), &[])
            .unwrap_err();
        assert!(matches!(
            e,
            InputColumnError::NonFinite {
                column: "sdot_rad_s",
                rows: 1,
                first_row: 3,
                ..
            }
        ));
    }
}

#[cfg(test)]
mod run_tests {
    use super::*;

    fn ds(chunks: &[u32], s: &[f64], v: &[f64]) -> Dataset {
        let n = chunks.len();
        Dataset {
            time_s: (0..n).map(|k| k as f64 * 1e-3).collect(),
            chunk: chunks.to_vec(),
            source_chunk: chunks.to_vec(),
            active: vec![true; n],
            valid: vec![true; n],
            s_rad: s.to_vec(),
            sdot_rad_s: v.to_vec(),
            sddot_rad_s2: vec![0.0; n],
            theta_motor_rad: vec![0.0; n],
            delta_theta_motor_rad: vec![0.0; n],
            omega_motor_rad_s: vec![0.0; n],
            i_meas_a: vec![0.0; n],
            i_filt_a: vec![0.0; n],
            tau_id_nm: vec![0.0; n],
            tau_f_label_nm: vec![0.0; n],
            temperature_c: vec![f64::NAN; n],
            tau_f_true_nm: None,
            phi_ddot_rad_s2: None,
        }
    }

    #[test]
    fn runs_default_to_the_file_stem_with_every_chunk() {
        let d = ds(&[2, 2, 0, 5], &[0.0; 4], &[0.0; 4]);
        let runs = dataset_runs(Path::new("/x/slow_run.csv"), None, &d);
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].name, "slow_run");
        assert_eq!(runs[0].chunks, [0, 2, 5]);
    }

    #[test]
    fn input_range_of_chunks_and_contains() {
        let d = ds(
            &[0, 0, 1, 1],
            &[-0.5, 0.2, 3.0, 0.0],
            &[0.1, -0.3, 9.0, f64::NAN],
        );
        let r = MotionRange::of_chunks(&d, &[0]);
        assert_eq!(r.s_rad, [-0.5, 0.2]);
        assert_eq!(r.sdot_rad_s, [-0.3, 0.1]);
        assert_eq!(r.rows, 2);
        assert!(r.contains(0.0, 0.0) && r.contains(0.2, -0.3));
        assert!(!r.contains(0.0, 0.11) && !r.contains(0.21, 0.0));
        let mut all = r;
        all.merge(&MotionRange::of_chunks(&d, &[1]));
        assert_eq!(all.rows, 3, "the NaN row is ignored");
        assert!(all.contains(3.0, 9.0));
        assert!(!MotionRange::default().contains(0.0, 0.0));
    }
}
