//! A labelled dataset written with its sidecar: the CSV and `DATASET.json` (provenance, the
//! pipeline's settings, the column docs) committed together, the sidecar last, so a dataset without
//! a complete sidecar is never left looking complete. `frictl preprocess` and the leg demo write
//! their current-labelled datasets through [`write_dataset`].
//!
//! What it is not: the label pipeline ([`crate::preprocess`]) or the dataset format
//! (`frictionless-dataset`).

use std::path::{Path, PathBuf};

use frictionless::output_file::{AtomicFile, commit_with_marker};
use frictionless_dataset::{ColumnDocOwned, Dataset, DatasetError, DatasetSidecar, LabelSource};

use crate::preprocess::{LogMeta, PreprocessSummary};

/// Why a labelled dataset could not be written (nothing is left looking complete).
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// A file could not be created or written.
    #[error("cannot write {}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
    /// The dataset's CSV could not be written.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The sidecar does not serialise.
    #[error("dataset sidecar: {0}")]
    Json(serde_json::Error),
    /// No row is valid with a finite label: such a dataset would look complete and hold nothing
    /// to fit or train on, so nothing is written.
    #[error(
        "{}: not written: none of its {samples} samples is valid with a finite label ({valid} \
         marked valid, {nan_label} of those with a non-finite label; {short_chunks} of {chunks} \
         chunks too short to filter)",
        path.display()
    )]
    NoValidRows {
        /// The dataset CSV that was not written.
        path: PathBuf,
        /// Samples of the dataset.
        samples: usize,
        /// Samples marked valid.
        valid: usize,
        /// Valid samples whose `tau_f_label_nm` is not finite.
        nan_label: usize,
        /// Chunks of the log.
        chunks: usize,
        /// Chunks too short to filter.
        short_chunks: usize,
    },
    /// The CSV and its sidecar could not be committed.
    #[error("cannot write {} and {}", csv.display(), sidecar.display())]
    Commit {
        /// The dataset CSV.
        csv: PathBuf,
        /// Its sidecar.
        sidecar: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
}

/// Where a labelled dataset comes from, for its sidecar.
pub struct Provenance<'a> {
    /// The source log as given.
    pub input_log: String,
    /// SHA-256 of the source log (hex).
    pub input_sha256: String,
    /// The log's joint constants.
    pub meta: &'a LogMeta,
    /// Output sample rate \[Hz\].
    pub fs_hz: f64,
    /// The pipeline's settings.
    pub settings: serde_json::Value,
    /// The link dynamics of τ_ID (description).
    pub dynamics: String,
}

/// Writes a current-labelled dataset `ds` to `out` and its sidecar (`out` with `.json`) together:
/// the sidecar last, so a dataset without a complete sidecar is never left looking complete. A
/// dataset without a valid row of finite label is refused ([`WriteError::NoValidRows`]) and
/// nothing is written.
pub fn write_dataset(
    out: &Path,
    ds: &Dataset,
    summary: &PreprocessSummary,
    from: &Provenance<'_>,
) -> Result<(), WriteError> {
    let valid = ds.valid.iter().filter(|v| **v).count();
    let nan_label = ds
        .valid
        .iter()
        .zip(&ds.tau_f_label_nm)
        .filter(|(v, f)| **v && !f.is_finite())
        .count();
    if valid == nan_label {
        return Err(WriteError::NoValidRows {
            path: out.to_path_buf(),
            samples: ds.len(),
            valid,
            nan_label,
            chunks: summary.chunks,
            short_chunks: summary.short_chunks,
        });
    }
    let mut csv_out = AtomicFile::create(out).map_err(|source| WriteError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    ds.write_csv_to(&mut csv_out, out)?;
    let side = DatasetSidecar {
        format: "frictionless-dataset-v1".into(),
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        input_log: from.input_log.clone(),
        input_sha256: from.input_sha256.clone(),
        joint: from.meta.joint.clone(),
        gear_ratio_signed: from.meta.gear_ratio_signed,
        kt_nm_per_a: from.meta.kt_nm_per_a,
        fs_hz: from.fs_hz,
        settings: from.settings.clone(),
        dynamics: from.dynamics.clone(),
        delta_theta_offset_motor_rad: summary.delta_theta_offset_motor_rad,
        samples: ds.len(),
        valid_samples: ds.valid.iter().filter(|v| **v).count(),
        chunks: summary.chunks,
        short_chunks: summary.short_chunks,
        dropped_rows: summary.dropped,
        columns: ds.columns().iter().map(ColumnDocOwned::from).collect(),
        label: LabelSource::Current,
        runs: Vec::new(),
        absent_columns: Vec::new(),
    };
    let side_path = out.with_extension("json");
    let io = |source| WriteError::Io {
        path: side_path.clone(),
        source,
    };
    let mut side_out = AtomicFile::create(&side_path).map_err(io)?;
    let json = serde_json::to_string_pretty(&side).map_err(WriteError::Json)?;
    std::io::Write::write_all(&mut side_out, json.as_bytes()).map_err(io)?;
    commit_with_marker(vec![csv_out], side_out).map_err(|source| WriteError::Commit {
        csv: out.to_path_buf(),
        sidecar: side_path.clone(),
        source,
    })
}
